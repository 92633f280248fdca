"""Batches of files on dask: napari_physeg.batch and ``napari-physeg batch``.

The cluster tests start real dask.distributed worker processes (2, as the
issue asks) on tiny synthetic movies.
"""

import json
import os
import signal
import threading
import time

import numpy as np
import pytest

from napari_physeg import batch, data
from napari_physeg.cli import main
from napari_physeg.core.contour import polygon_mask
from napari_physeg.io import open_stack, read_shapes_csv, write_shapes_csv

tifffile = pytest.importorskip("tifffile")
distributed = pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")


def _iou(contour, mask):
    found = polygon_mask(contour, mask.shape)
    return (found & mask).sum() / (found | mask).sum()


@pytest.fixture(scope="module")
def movie():
    return data.deforming_cell(n_frames=4, shape=(96, 96))


@pytest.fixture
def movies(tmp_path, movie):
    """Three copies of a 4-frame movie (TIFF) and its frame-0 contour."""
    paths = []
    for i in range(3):
        paths.append(tmp_path / f"well{i}.tif")
        tifffile.imwrite(paths[-1], (movie.frames * 1000).astype(np.uint16), photometric="minisblack")
    init = write_shapes_csv(tmp_path / "init.csv", [movie.outlines[0][::6]])
    return paths, init, tmp_path


@pytest.fixture(scope="module")
def client():
    """A local cluster of 2 single-threaded worker processes, shared by the module's tests."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster, set_as_default=False) as c:
        yield c


def test_cli_batch_track_on_two_workers_reports_a_corrupt_file_and_finishes_the_rest(movies, movie, capsys):
    paths, init, tmp = movies
    corrupt = tmp / "corrupt.tif"
    corrupt.write_bytes(b"II*\x00" + b"\x07" * 200)  # a TIFF header and garbage
    out = tmp / "out"
    code = main(["batch", "track", *map(str, paths), str(corrupt), "--init", str(init), "--out", str(out),
                 "--workers", "2"])
    assert code == 1  # a task failed
    table = pd.read_csv(out / "summary.csv")
    assert len(table) == 4 and table["input"].is_unique  # one row per input and object (one object)
    bad = table[table["input"] == str(corrupt)].iloc[0]
    assert bad["status"] == "failed" and "could not read" in bad["error"]
    good = table[table["status"] == "ok"]
    assert len(good) == 3 and (good["tracked"] == 4).all()
    assert good["pid"].nunique() == 2  # both worker processes took tasks
    for _, row in good.iterrows():
        shapes, frames = read_shapes_csv(out / row["contours"], leading=True)
        assert [f[0] for f in frames] == [0, 1, 2, 3]
        assert min(_iou(c, movie.masks[int(f[0])]) for c, f in zip(shapes, frames)) > 0.95
        nodes = pd.read_csv(out / row["tracks"].replace(".parquet", ".csv"))
        assert set(nodes["frame"]) == {0, 1, 2, 3}
    if (out / "summary.parquet").exists() or pytest.importorskip("pyarrow"):
        assert len(pd.read_parquet(out / "summary.parquet")) == 4
    captured = capsys.readouterr()
    assert "corrupt.tif" in captured.err and "3 of 4 rows ok" in captured.out


def test_segment_files_one_row_per_input_frame_and_object(client, movies, movie):
    paths, _, tmp = movies
    inits = [movie.outlines[0][::6], np.array([[2.0, 2.0], [2.0, 9.0], [9.0, 5.0]]) - 50]  # the second is outside
    table = batch.segment_files(paths[:2], inits, tmp / "seg", frames="0:4:2", client=client, progress=False)
    assert len(table) == 2 * 2 * 2
    assert not table.duplicated(["input", "frame", "object"]).any()
    assert set(table["frame"]) == {0, 2}
    ok, failed = table[table["object"] == 0], table[table["object"] == 1]
    assert (ok["status"] == "ok").all() and ok["converged"].all()
    assert (failed["status"] == "failed").all() and failed["error"].str.contains("outside").all()
    for _, row in ok.iterrows():  # the failing object did not lose the other one
        shapes = read_shapes_csv(tmp / "seg" / row["contours"])
        assert _iou(shapes[row["shape"]], movie.masks[row["frame"]]) > 0.95


def test_cli_batch_runs_on_an_existing_scheduler(client, movies, movie, capsys):
    paths, init, tmp = movies
    out = tmp / "seg"
    assert main(["batch", "segment", *map(str, paths[:2]), "--init", str(init), "--out", str(out), "--frames", "3",
                 "--scheduler", client.scheduler.address, "--quiet", "--stiffness", "3000"]) == 0
    table = pd.read_csv(out / "summary.csv")
    assert len(table) == 2 and (table["status"] == "ok").all() and (table["frame"] == 3).all()
    workers = set(client.run(os.getpid).values())
    assert set(table["pid"]) <= workers  # ran on that cluster's workers
    assert json.loads((out / "batch.json").read_text())["options"] == {"stiffness": 3000.0}
    assert "2 of 2 rows ok" in capsys.readouterr().out


def _mtimes(out):
    return {p: p.stat().st_mtime_ns for p in (out / "results").rglob("rows.json")}


def test_a_second_run_resumes_and_other_settings_are_refused(client, movies):
    paths, init, tmp = movies
    out = tmp / "seg"
    first = batch.segment_files(paths, init, out, client=client, progress=False)
    before = _mtimes(out)
    assert len(before) == 3 * 4  # one complete result per input and frame
    redo = sorted(before)[5]
    for f in redo.parent.iterdir():
        f.unlink()
    redo.parent.rmdir()
    second = batch.segment_files(paths, init, out, client=client, progress=False)
    after = _mtimes(out)
    assert {p for p in after if after[p] != before.get(p)} == {redo}  # only the missing one was run again
    cols = ["input", "frame", "object", "status", "area", "contours"]
    pd.testing.assert_frame_equal(first[cols], second[cols])
    with pytest.raises(ValueError, match="other settings.*options"):
        batch.segment_files(paths, init, out, client=client, progress=False, stiffness=5000.0)
    third = batch.segment_files(paths, init, out, client=client, progress=False, stiffness=5000.0, overwrite=True)
    assert (third["status"] == "ok").all() and json.loads((out / "batch.json").read_text())["options"] == \
        {"stiffness": 5000.0}


@pytest.mark.filterwarnings("ignore:Port 8787 is already in use")  # the restarted worker's HTTP server
def test_a_killed_worker_loses_no_result_and_duplicates_none(tmp_path):
    movie = data.deforming_cell(n_frames=10, shape=(96, 96))
    paths = []
    for i in range(6):
        paths.append(tmp_path / f"m{i}.tif")
        tifffile.imwrite(paths[-1], (movie.frames * 1000).astype(np.uint16), photometric="minisblack")
    init = [movie.outlines[0][::6]]
    out = tmp_path / "out"
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=":0") as cluster, \
            distributed.Client(cluster, set_as_default=False) as c:
        done = {}
        run = threading.Thread(target=lambda: done.update(
            table=batch.track_files(paths, init, out, client=c, progress=False)))
        run.start()
        victim, deadline = None, time.monotonic() + 120
        while victim is None and time.monotonic() < deadline:  # one result out, a task running
            busy = [w for w, keys in c.processing().items() if keys]
            if busy and any((out / "results").glob("*/rows.json")):
                victim = busy[0]
            time.sleep(0.02)
        assert victim is not None, "no task ran"
        os.kill(c.run(os.getpid, workers=[victim])[victim], signal.SIGKILL)
        run.join(180)
    table = done["table"]
    assert len(table) == 6 and table["input"].is_unique and (table["status"] == "ok").all()
    assert (table["tracked"] == 10).all()
    results = sorted(p.name for p in (out / "results").iterdir())
    assert len(results) == 6 and not [n for n in results if n.startswith(".")]  # no half result left
    for _, row in table.iterrows():
        shapes, frames = read_shapes_csv(out / row["contours"], leading=True)
        assert [f[0] for f in frames] == list(range(10))  # each frame once


def test_a_task_that_fails_while_writing_leaves_no_result(movies, monkeypatch):
    paths, init, tmp = movies
    out = tmp / "out"
    (out / "results").mkdir(parents=True)
    task = batch._Task("track", str(paths[0]), "m0", str(out), tuple(c.tolist() for c in read_shapes_csv(init)))

    def disk_full(*args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(batch, "write_table", disk_full)
    rows = batch._execute(task)
    assert rows[0]["status"] == "failed" and "No space left" in rows[0]["error"]
    assert list((out / "results").iterdir()) == []  # neither the result nor its temporary folder
    monkeypatch.undo()
    rows = batch._execute(task)
    assert rows[0]["status"] == "ok" and (out / "results" / "m0" / "rows.json").exists()
    assert batch._execute(task) == rows  # complete: read back, not run again


def test_stacks_open_lazily_one_frame_per_chunk(tmp_path, movie):
    zarr = pytest.importorskip("zarr")
    frames = (movie.frames * 1000).astype(np.uint16)
    tifffile.imwrite(tmp_path / "s.tif", frames, compression="zlib", photometric="minisblack")
    z = zarr.open(str(tmp_path / "s.zarr"), mode="w", shape=frames.shape, chunks=(2, 48, 48), dtype=frames.dtype)
    z[:] = frames
    for name in ("s.tif", "s.zarr"):
        with open_stack(tmp_path / name) as stack:
            assert stack.shape == frames.shape and stack.chunks[0] == (1,) * len(frames)
            np.testing.assert_array_equal(np.asarray(stack[2]), frames[2])


@pytest.mark.parametrize("inputs, options, message", [
    ([], ["--workers", "0"], "--workers"),
    ([], ["--workers", "2", "--scheduler", "tcp://x:1"], "not allowed with"),
    ([], ["--init", "{tmp}/nope.csv"], "nope.csv does not exist"),
    (["{tmp}/missing.tif"], [], "missing.tif does not exist"),
    ([], ["--out", "{tmp}/init.csv"], "is a file"),
    ([], ["--stiffness", "-1"], "stiffness"),
    ([], ["--material", "cheese"], "material"),
    ([], ["--scheduler", "nonsense"], "could not reach the dask scheduler"),
])
def test_batch_refuses_bad_arguments_before_any_work(movies, capsys, inputs, options, message):
    paths, init, tmp = movies
    argv = ["batch", "segment", str(paths[0]), *[a.format(tmp=tmp) for a in inputs], "--init", str(init),
            "--out", str(tmp / "out"), *[a.format(tmp=tmp) for a in options or ["--workers", "2"]]]
    before = sorted(p.name for p in tmp.iterdir())
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp.iterdir()) == before  # nothing written


def test_a_batch_leaves_dask_on_its_default_scheduler(client, movies):
    """After a batch, dask in this process computes locally again (no closed client is left the default)."""
    import dask
    import dask.array as da

    paths, init, tmp = movies
    batch.segment_files(paths[:1], init, tmp / "seg", frames="0", client=client, progress=False)
    batch.segment_files(paths[:1], init, tmp / "seg2", frames="0", workers=1, progress=False)
    assert dask.config.get("scheduler", None) is None
    assert int(da.ones(4, chunks=2).sum().compute()) == 4

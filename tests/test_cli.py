"""The batch command line: napari shapes CSV in, segmented contours out."""

import argparse
import functools
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from skimage import io

from napari_physeg import data
from napari_physeg.cli import main
from napari_physeg.core import track
from napari_physeg.core.contour import polygon_mask
from napari_physeg.io import read_shapes_csv, write_shapes_csv


@pytest.fixture
def scene(tmp_path):
    obj = data.ellipse((128, 128), noise=0.05)
    image = tmp_path / "image.tif"
    io.imsave(image, (obj.image * 1000).astype(np.uint16), check_contrast=False)
    init = write_shapes_csv(tmp_path / "init.csv", [obj.init_near])
    return obj, image, init, tmp_path


def test_segment_writes_napari_shapes_csv_and_mask(scene, capsys):
    obj, image, init, tmp = scene
    out, mask = tmp / "out.csv", tmp / "mask.tif"
    assert main(["segment", str(image), "--init", str(init), "--out", str(out), "--mask", str(mask)]) == 0
    (contour,) = read_shapes_csv(out)
    m = polygon_mask(contour, obj.mask.shape)
    assert (m & obj.mask).sum() / (m | obj.mask).sum() > 0.97
    labels = io.imread(mask)
    assert labels.shape == obj.mask.shape and set(np.unique(labels)) == {0, 1}
    assert "converged" in capsys.readouterr().out


def test_shapes_csv_round_trip_matches_napari_columns(tmp_path):
    shapes = [np.array([[1.5, 2.25], [3.0, 4.0], [5.0, 1.0]]), np.array([[0.0, 0.0], [0.0, 9.0], [9.0, 0.0]])]
    path = write_shapes_csv(tmp_path / "s.csv", shapes)
    assert path.read_text().splitlines()[0] == "index,shape-type,vertex-index,axis-0,axis-1"
    back = read_shapes_csv(path)
    assert len(back) == 2 and all(np.array_equal(a, b) for a, b in zip(shapes, back))


def test_a_shapes_csv_with_a_byte_order_mark_is_read_shape_by_shape(tmp_path):
    # Saved by Excel as "CSV UTF-8": the BOM made the header '\ufeffindex', one contour of every vertex.
    shapes = [np.array([[1.5, 2.25], [3.0, 4.0], [5.0, 1.0]]), np.array([[0.0, 0.0], [0.0, 9.0], [9.0, 0.0]])]
    text = write_shapes_csv(tmp_path / "s.csv", shapes).read_text()
    (tmp_path / "bom.csv").write_text(text, encoding="utf-8-sig")
    back = read_shapes_csv(tmp_path / "bom.csv")
    assert len(back) == 2 and all(np.array_equal(a, b) for a, b in zip(shapes, back))
    (tmp_path / "plain-bom.csv").write_text("row,col\n1,2\n3,4\n5,1\n", encoding="utf-8-sig")
    assert np.array_equal(read_shapes_csv(tmp_path / "plain-bom.csv")[0], [[1, 2], [3, 4], [5, 1]])


def test_a_warning_names_the_shape_it_is_about(scene, capsys):
    """Two drawings, the second partly beyond the image: segment()'s clipping warning says which."""
    obj, image, _, tmp = scene
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    beyond = np.column_stack([10 + 20 * np.sin(t), 64 + 20 * np.cos(t)])
    init = write_shapes_csv(tmp / "two.csv", [obj.init_near, beyond])
    main(["segment", str(image), "--init", str(init), "--out", str(tmp / "o.csv")])
    warned = [line for line in capsys.readouterr().err.splitlines() if "outside the image" in line]
    assert len(warned) == 1 and "shape 1: " in warned[0]


def test_nd_shapes_keep_the_last_two_axes_and_plain_tables_work(tmp_path):
    p = tmp_path / "nd.csv"
    p.write_text("index,shape-type,vertex-index,axis-0,axis-1,axis-2\n"
                 "0,polygon,0,4,1,2\n0,polygon,1,4,3,4\n0,polygon,2,4,5,1\n")
    assert np.array_equal(read_shapes_csv(p)[0], [[1, 2], [3, 4], [5, 1]])
    q = tmp_path / "plain.csv"
    q.write_text("row,col\n1,2\n3,4\n5,1\n")
    assert np.array_equal(read_shapes_csv(q)[0], [[1, 2], [3, 4], [5, 1]])
    # A Points layer saved by napari: each point is a click (its frame kept, for a movie's).
    q.write_text("index,axis-0,axis-1,axis-2\n0,3,10,20\n1,3,30,40\n")
    shapes, before = read_shapes_csv(q, leading=True)
    assert [s.tolist() for s in shapes] == [[[10, 20]], [[30, 40]]] and before == [(3.0,), (3.0,)]
    # So is each object of an id,row,col table given one row; a row number (index, Fiji's " ") names none.
    q.write_text("id,row,col\n0,10,20\n1,30,40\n")
    assert [s.tolist() for s in read_shapes_csv(q)] == [[[10, 20]], [[30, 40]]]
    q.write_text("index,row,col\n0,1,2\n1,3,4\n2,5,1\n")
    assert np.array_equal(read_shapes_csv(q)[0], [[1, 2], [3, 4], [5, 1]])
    # Named x, y (col, row): read as (row, col) it lay transposed, or outside a non-square image.
    for header in ("x,y", "X,Y", "col,row"):
        q.write_text(f"{header}\n2,1\n4,3\n1,5\n")
        assert np.array_equal(read_shapes_csv(q)[0], [[1, 2], [3, 4], [5, 1]])


@pytest.mark.parametrize("extra, message", [
    (["--material", "unobtainium"], "or make one with --young, --poisson and --density"),  # not "a Material"
    (["--channel", "1"], "channel"),
])
def test_bad_input_exits_2_with_a_message(scene, capsys, extra, message):
    obj, image, init, tmp = scene
    code = main(["segment", str(image), "--init", str(init), "--out", str(tmp / "o.csv"), *extra])
    assert code == 2 and message in capsys.readouterr().err


def test_empty_contour_file_is_reported(scene, capsys):
    obj, image, init, tmp = scene
    empty = tmp / "empty.csv"
    empty.write_text("")
    assert main(["segment", str(image), "--init", str(empty), "--out", str(tmp / "o.csv")]) == 2
    assert "empty" in capsys.readouterr().err


def test_help_explains_the_command():
    out = subprocess.run([sys.executable, "-m", "napari_physeg.cli", "segment", "--help"],
                         capture_output=True, text=True, check=True).stdout
    for word in ("--init", "--out", "--stiffness", "napari", "copper"):
        assert word in out


@pytest.fixture
def movie_files(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    movie = data.deforming_cell(n_frames=6)
    stack = tmp_path / "movie.tif"
    tifffile.imwrite(stack, (movie.frames * 1000).astype(np.uint16))
    # Drawn on frame 2 of the stack in napari: the frame is axis-0 of the CSV.
    init = write_shapes_csv(tmp_path / "init.csv", [movie.outlines[2][::6] * 1.0 + 0], leading=[(2,)])
    return movie, stack, init, tmp_path


def test_track_writes_contours_per_frame_and_the_tidy_table(movie_files, capsys):
    movie, stack, init, tmp = movie_files
    out = tmp / "tracked"
    assert main(["track", str(stack), "--init", str(init), "--out", str(out)]) == 0
    shapes, frames = read_shapes_csv(out / "contours.csv", leading=True)
    assert [f[0] for f in frames] == list(range(6))
    for (t,), contour in zip(frames, shapes):
        found = polygon_mask(contour, movie.masks[int(t)].shape)
        assert (found & movie.masks[int(t)]).sum() / (found | movie.masks[int(t)]).sum() > 0.97
    table_file = out / "tracks.parquet" if (out / "tracks.parquet").exists() else out / "tracks.csv"
    assert table_file.exists()
    captured = capsys.readouterr()
    assert "object 0: 6 tracked" in captured.out and "object-frames" in captured.err
    # stderr is not a terminal here (a log): whole lines, one each time the bar grows, no carriage returns.
    bars = [line for line in captured.err.splitlines() if line.startswith("[")]
    assert "\r" not in captured.err and len(bars) == 6 and bars[-1].endswith("6/6 object-frames")


def test_track_from_a_points_layers_clicks_as_the_api_does(movie_files, capsys):
    """A Points layer saved by napari, one point in the cell on frame 2: a
    click, tracked as track() tracks the point (an outside tester, session
    69: an id,row,col table of one row per object was one contour through
    them all, and one or two points were refused)."""
    movie, stack, _, tmp = movie_files
    centre = np.argwhere(movie.masks[2]).mean(0)
    clicks = tmp / "points.csv"
    clicks.write_text(f"index,axis-0,axis-1,axis-2\n0,2,{float(centre[0])!r},{float(centre[1])!r}\n")
    out = tmp / "clicked"
    assert main(["track", str(stack), "--init", str(clicks), "--out", str(out)]) == 0
    shapes, _ = read_shapes_csv(out / "contours.csv", leading=True)
    expected = track((movie.frames * 1000).astype(np.uint16), centre[None], start=2)
    assert len(shapes) == 6 and all(np.allclose(a, b) for a, b in zip(shapes, expected.contours[0]))
    assert "object 0: 6 tracked" in capsys.readouterr().out


def test_track_of_some_frames_numbers_the_progress_bar_as_the_stack(movie_files, capsys):
    """With --frames the bar names the stack's frames (it opened the stack a
    second time, before the tracking's own, to learn them)."""
    movie, stack, init, tmp = movie_files
    assert main(["track", str(stack), "--init", str(init), "--out", str(tmp / "t"), "--frames", "2:6:2"]) == 0
    shown = [int(part.split(",")[0]) for part in capsys.readouterr().err.split("] frame ")[1:]]
    assert sorted(set(shown)) == [2, 4]


def test_track_says_why_an_object_was_lost_in_the_stacks_frame_numbers(movie_files, capsys):
    """The cell gone from the stack's frames 4 and 5 (blank), tracked on its
    frames 2, 3, 4 and 5: lost on frames 4 and 5 of the stack, as printed, in
    the warning and in the table's reason column (an outside tester's objects
    were lost for 29 frames with no word of why, session 69)."""
    tifffile = pytest.importorskip("tifffile")
    movie, _, init, tmp = movie_files
    frames = (movie.frames * 1000).astype(np.uint16)
    frames[4:] = np.median(frames[0])
    tifffile.imwrite(tmp / "gone.tif", frames)
    out = tmp / "gone"
    assert main(["track", str(tmp / "gone.tif"), "--init", str(init), "--out", str(out), "--frames", "2:6"]) == 1
    captured = capsys.readouterr()
    assert "object 0: 2 tracked, 2 lost (first lost on frame 4: " in captured.out
    assert "object 0 on frames 4-5: " in captured.err and "The reason column of OUT/tracks.csv says why" in captured.err
    pd = pytest.importorskip("pandas")
    table = pd.read_parquet(out / "tracks.parquet") if (out / "tracks.parquet").exists() else \
        pd.read_csv(out / "tracks.csv", keep_default_na=False)
    lost = table[table["status"] == "lost"]
    assert list(lost["frame"]) == [4, 5] and all(lost["reason"] != "")


def test_track_refuses_contours_drawn_on_several_frames(movie_files, capsys):
    movie, stack, _, tmp = movie_files
    init = write_shapes_csv(tmp / "two.csv", [movie.outlines[0][::6], movie.outlines[3][::6]], leading=[(0,), (3,)])
    assert main(["track", str(stack), "--init", str(init), "--out", str(tmp / "o")]) == 2
    assert "--start" in capsys.readouterr().err


def test_segment_keeps_the_contours_that_converged_when_others_fail(tmp_path, capsys):
    # Shape 1 is drawn on the background (it collapses), frame 1 is blank: every contour was lost, exit 2.
    tifffile = pytest.importorskip("tifffile")
    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[:96, :96]
    image = (((yy - 35) ** 2 + (xx - 35) ** 2 < 12 ** 2) * 150 + 30 + rng.normal(0, 3, yy.shape)).clip(0, 255)
    tifffile.imwrite(tmp_path / "movie.tif", np.stack([image, np.full_like(image, 30)]).astype(np.uint8))
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    init = write_shapes_csv(tmp_path / "init.csv", [np.c_[35 + 18 * np.sin(a), 35 + 18 * np.cos(a)],
                                                     np.c_[72 + 8 * np.sin(a), 72 + 8 * np.cos(a)]])
    out = tmp_path / "out.csv"
    assert main(["segment", str(tmp_path / "movie.tif"), "--frames", "0:2", "--init", str(init), "--out", str(out),
                 "--polarity", "bright"]) == 1
    captured = capsys.readouterr()
    failed = [line for line in captured.err.splitlines() if " failed: " in line]
    assert [line.split(" failed: ")[0] for line in failed] == [
        "napari-physeg: frame 0, shape 1", "napari-physeg: frame 1, shape 0", "napari-physeg: frame 1, shape 1"]
    assert "collapsed to a point" in failed[0] and "constant" in failed[1]
    assert "frame 0, shape 0: " in captured.out and "1 of 4 contours" in captured.out
    (contour,), (lead,) = read_shapes_csv(out, leading=True)
    assert lead == (0.0,) and np.hypot(*(contour - 35).T).mean() == pytest.approx(12, abs=1.5)



def _object_column(path) -> list:
    """The ``object`` of each shape of a shapes CSV (its first vertex's row)."""
    import csv

    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    return [int(r["object"]) for r in rows if r["vertex-index"] == "0"]


def test_contours_csv_names_the_drawing_each_contour_is_of_when_one_failed(tmp_path, capsys):
    """A shape that fails leaves no row, so the shapes' index no longer says
    which drawing a contour is of: the object column does, and napari still
    opens the file as a Shapes layer (it reads only the index, type and axes)."""
    from napari_builtins.io._read import csv_to_layer_data

    rng = np.random.default_rng(1)
    yy, xx = np.mgrid[:96, :96]
    image = ((yy - 35) ** 2 + (xx - 35) ** 2 < 12 ** 2) * 150 + 30 + rng.normal(0, 3, yy.shape)
    pytest.importorskip("tifffile").imwrite(tmp_path / "image.tif", image.clip(0, 255).astype(np.uint8))
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    # Shape 0 is drawn on the background (it collapses), shape 1 around the disk.
    init = write_shapes_csv(tmp_path / "init.csv", [np.c_[72 + 8 * np.sin(a), 72 + 8 * np.cos(a)],
                                                     np.c_[35 + 18 * np.sin(a), 35 + 18 * np.cos(a)]])
    out = tmp_path / "out.csv"
    assert main(["segment", str(tmp_path / "image.tif"), "--init", str(init), "--out", str(out),
                 "--polarity", "bright"]) == 1
    assert "shape 0 failed" in capsys.readouterr().err
    assert _object_column(out) == [1]
    data, meta, kind = csv_to_layer_data(str(out), require_type="shapes")
    assert kind == "shapes" and len(data) == 1 and data[0].shape[1] == 2


def test_track_contours_csv_names_the_object_of_each_contour(movie_files, capsys):
    """Lost object-frames leave no shape: each shape says its object."""
    movie, stack, _, tmp = movie_files
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    on_the_ground = np.c_[12 + 6 * np.sin(a), 12 + 6 * np.cos(a)]
    init = write_shapes_csv(tmp / "two.csv", [on_the_ground, movie.outlines[0][::6]], leading=[(0,), (0,)])
    out = tmp / "tracked"
    assert main(["track", str(stack), "--init", str(init), "--out", str(out)]) == 1  # object 0 is lost
    assert _object_column(out / "contours.csv") == [1] * 6

# --------------------------------------------------------------------------
# napari's shapes CSV: every shape type
# --------------------------------------------------------------------------


def test_ellipse_saved_by_napari_is_read_as_an_ellipse(tmp_path):
    """napari stores an ellipse as the 4 corners of its box; it must come back as the ellipse."""
    from napari.layers import Shapes
    from napari_builtins.io import napari_write_shapes

    layer = Shapes([np.array([[50.0, 60.0], [20.0, 35.0]])], shape_type="ellipse")  # centre, radii
    layer.add_rectangles([np.array([[5.0, 5.0], [15.0, 25.0]])])
    layer.add_polygons([np.array([[1.0, 1.0], [1.0, 8.0], [6.0, 4.0]])])
    layer.add_paths([np.array([[30.0, 30.0], [30.0, 40.0], [40.0, 40.0], [40.0, 30.0]])])
    path = str(tmp_path / "shapes.csv")
    napari_write_shapes(path, layer.data, {"shape_type": layer.shape_type})  # napari's own writer
    assert "ellipse" in open(path).read()
    ellipse, rectangle, polygon, open_path = read_shapes_csv(path)
    assert len(ellipse) > 32  # not the 4 corners
    r, c = (ellipse - [50.0, 60.0]).T
    np.testing.assert_allclose((r / 20.0) ** 2 + (c / 35.0) ** 2, 1.0, atol=1e-6)
    np.testing.assert_allclose(sorted(map(tuple, rectangle)), [(5, 5), (5, 25), (15, 5), (15, 25)])
    np.testing.assert_array_equal(polygon, layer.data[2])
    np.testing.assert_array_equal(open_path, layer.data[3])  # closed by joining its ends
    # and back: napari's own reader takes what we write
    from napari_builtins.io import csv_to_layer_data

    ours = write_shapes_csv(tmp_path / "ours.csv", [ellipse, rectangle], leading=[(3,), (4,)])
    data_back, meta, kind = csv_to_layer_data(str(ours), require_type="shapes")
    assert kind == "shapes" and meta["shape_type"] == ["polygon", "polygon"]
    np.testing.assert_allclose(data_back[0], np.c_[np.full(len(ellipse), 3.0), ellipse])


def test_a_shape_across_frames_or_between_frames_is_refused(tmp_path):
    """Found by an outside probe (session 64): a polygon whose vertices lie on
    frames 0, 1 and 2 was read on frame 0 only, and one at axis-0 = 1.5 was
    tracked from frame 2, both without a word."""
    from napari_physeg.batch import drawn_frame

    lines = ["index,shape-type,vertex-index,axis-0,axis-1,axis-2"]
    lines += [f"0,polygon,{k},{k},{r},{c}" for k, (r, c) in enumerate([(10, 10), (10, 30), (30, 20)])]
    (tmp_path / "across.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"shape 0 has vertices on 3 planes \(leading coordinates \(0\), \(1\)"):
        read_shapes_csv(tmp_path / "across.csv")
    with pytest.raises(ValueError, match="axis-0 = 1.5, between frames"):
        drawn_frame([(1.5,)], "init.csv")
    assert drawn_frame([(2.0,), (2.0,)], "init.csv") == 2 and drawn_frame([(), ()], "init.csv") is None


def test_rotated_and_nd_ellipses_keep_their_axes_and_frame(tmp_path):
    angle = np.deg2rad(30)
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    box = np.array([[-10.0, -25.0], [10.0, -25.0], [10.0, 25.0], [-10.0, 25.0]]) @ rot.T + [40.0, 50.0]
    lines = ["index,shape-type,vertex-index,axis-0,axis-1,axis-2"]
    lines += [f"0,ellipse,{k},7.0,{float(r)!r},{float(c)!r}" for k, (r, c) in enumerate(box)]
    lines += ["1,line,0,7.0,0,0", "1,line,1,7.0,5,5"]
    (tmp_path / "e.csv").write_text("\n".join(lines[:5]) + "\n")
    (ellipse,), (lead,) = read_shapes_csv(tmp_path / "e.csv", leading=True)
    assert lead == (7.0,)
    u, v = ((ellipse - [40.0, 50.0]) @ rot).T  # back in the ellipse's own axes
    np.testing.assert_allclose((u / 10.0) ** 2 + (v / 25.0) ** 2, 1.0, atol=1e-6)
    (tmp_path / "line.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="line"):
        read_shapes_csv(tmp_path / "line.csv")


def test_segment_from_an_ellipse_drawn_in_napari(tmp_path):
    obj = data.ellipse((128, 128), noise=0.05)
    image = tmp_path / "image.tif"
    io.imsave(image, (obj.image * 1000).astype(np.uint16), check_contrast=False)
    rows, cols = np.nonzero(obj.mask)
    centre, radii = [rows.mean(), cols.mean()], [np.ptp(rows) / 2 + 8, np.ptp(cols) / 2 + 8]
    box = [[centre[0] - radii[0], centre[1] - radii[1]], [centre[0] + radii[0], centre[1] - radii[1]],
           [centre[0] + radii[0], centre[1] + radii[1]], [centre[0] - radii[0], centre[1] + radii[1]]]
    init = tmp_path / "init.csv"
    init.write_text("index,shape-type,vertex-index,axis-0,axis-1\n"
                    + "".join(f"0,ellipse,{k},{r},{c}\n" for k, (r, c) in enumerate(box)))
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp_path / "o.csv")]) == 0
    (contour,) = read_shapes_csv(tmp_path / "o.csv")
    m = polygon_mask(contour, obj.mask.shape)
    assert (m & obj.mask).sum() / (m | obj.mask).sum() > 0.97


# --------------------------------------------------------------------------
# Clean failures: exit 2, one line, nothing written, before any work
# --------------------------------------------------------------------------


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if any computation starts."""
    import napari_physeg.core as core

    for name in ("segment", "track", "match", "simulate"):
        @functools.wraps(getattr(core, name))  # the signature stays: the CLI reads its defaults
        def forbidden(*args, **kwargs):
            raise AssertionError("the computation started before the arguments were checked")

        monkeypatch.setattr(core, name, forbidden)


def _bad_outputs(tmp):
    (tmp / "a-file").write_text("")
    return {
        "missing init": (["--init", str(tmp / "missing.csv")], "missing.csv does not exist"),
        "out is init": (["--out", "{init}", "--overwrite"], "also an input"),
        "out exists": (["--out", "{init}x"], "exists: pass --overwrite"),
        "out in a file": (["--out", str(tmp / "a-file" / "o.csv")], "is not a folder"),
        "out folder missing": (["--out", str(tmp / "nowhere" / "o.csv")], "does not exist"),
        "bad material": (["--material", "unobtainium"], "material"),
        "bad polarity": (["--polarity", "grey"], "polarity"),
        "bad contrast": (["--contrast", "phase"], "contrast must be one of"),
        "bad weights": (["--weights", "edges=0"], "every force off"),
        "bad frame": (["--frames", "99"], "frames 0 to"),
        "bad stiffness": (["--stiffness", "abc"], "--stiffness"),
        "bad poisson": (["--poisson", "0.7"], "poisson"),
        "contour outside": (["--init", str(write_shapes_csv(tmp / "far.csv", [[[500, 500], [500, 520], [520, 510]]]))],
                            "wholly outside"),
    }


@pytest.mark.parametrize("case", [
    "missing init", "out is init", "out exists", "out in a file", "out folder missing", "bad material",
    "bad polarity", "bad contrast", "bad weights", "bad frame", "bad stiffness", "bad poisson", "contour outside"])
def test_segment_refuses_bad_input_before_any_work(scene, capsys, no_work, case):
    obj, image, init, tmp = scene
    (tmp / "init.csvx").write_text("kept")
    extra, message = _bad_outputs(tmp)[case]
    extra = [e.format(init=init) for e in extra]
    before = {p.name: p.read_bytes() for p in tmp.iterdir() if p.is_file()}
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp / "o.csv"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert {p.name: p.read_bytes() for p in tmp.iterdir() if p.is_file()} == before  # nothing written


@pytest.mark.parametrize("mask", ["o.csv", "./sub/../o.csv"])
def test_segment_refuses_a_mask_at_the_out_path_before_any_work(scene, capsys, no_work, monkeypatch, mask):
    # --out does not exist yet: the label image replaced the contours CSV, exit 0.
    obj, image, init, tmp = scene
    (tmp / "sub").mkdir()
    before = sorted(p.name for p in tmp.iterdir())
    monkeypatch.chdir(tmp)
    assert main(["segment", str(image), "--init", str(init), "--out", "o.csv", "--mask", mask]) == 2
    err = capsys.readouterr().err
    assert "is the same file as --out" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp.iterdir()) == before  # nothing written


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root may write to a read-only folder")
def test_an_unwritable_out_is_refused_before_any_work(scene, capsys, no_work):
    obj, image, init, tmp = scene
    locked = tmp / "locked"
    locked.mkdir(mode=0o500)
    assert main(["segment", str(image), "--init", str(init), "--out", str(locked / "o.csv")]) == 2
    assert "cannot write" in capsys.readouterr().err


def test_no_traceback_from_the_installed_command(scene):
    obj, image, init, tmp = scene
    run = subprocess.run([sys.executable, "-m", "napari_physeg.cli", "track", str(image), "--init",
                          str(tmp / "missing.csv"), "--out", str(tmp / "out")], capture_output=True, text=True)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "Traceback" not in run.stderr
    assert not (tmp / "out").exists()


@pytest.mark.parametrize("command, swap, message", [
    ("segment", {"--init": "{stack}"}, "cannot read {stack} as a CSV: it is not UTF-8 text (is it the image?"),
    ("track", {"--out": "{tmp}/a-file"}, "{tmp}/a-file exists and is a file: choose another output"),
    ("track", {"--init": "{tmp}/a-folder"}, "--init {tmp}/a-folder is a folder, not a CSV file"),
    ("segment", {"--out": "{tmp}/a-folder"}, "{tmp}/a-folder exists and is a folder: choose another output"),
    ("segment", {"stack": "{tmp}/a-folder"}, "image {tmp}/a-folder is a folder, not an image or a zarr store"),
])
def test_a_wrong_kind_of_file_is_named_and_explained(movie_files, capsys, no_work, command, swap, message):
    # Seen: "'utf-8' codec can't decode byte 0xff", "[Errno 20] Not a directory", "[Errno 21] Is a directory".
    movie, stack, init, tmp = movie_files
    (tmp / "a-file").write_text("")
    (tmp / "a-folder").mkdir()
    names = dict(stack=stack, tmp=tmp)
    given = {"stack": str(stack), "--init": str(init), "--out": str(tmp / "o"),
             **{k: v.format(**names) for k, v in swap.items()}}
    assert main([command, given.pop("stack"), "--frames", "0", *[a for kv in given.items() for a in kv]]) == 2
    err = capsys.readouterr().err
    assert message.format(**names) in err and len(err.strip().splitlines()) == 1 and "Errno" not in err


def test_track_refuses_a_non_empty_out_without_overwrite(movie_files, capsys, no_work):
    movie, stack, init, tmp = movie_files
    (tmp / "tracked").mkdir()
    (tmp / "tracked" / "contours.csv").write_text("mine")
    assert main(["track", str(stack), "--init", str(init), "--out", str(tmp / "tracked")]) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (tmp / "tracked" / "contours.csv").read_text() == "mine"


@pytest.mark.parametrize("name", ["contours.csv", "tracks.csv"])
def test_track_never_replaces_an_input_in_its_out_folder_even_with_overwrite(movie_files, capsys, no_work, name):
    # e.g. --out . next to the drawing saved as contours.csv: the tracking replaced it, exit 0.
    movie, stack, init, tmp = movie_files
    (tmp / "tracked").mkdir()
    drawn = tmp / "tracked" / name
    drawn.write_bytes(init.read_bytes())
    assert main(["track", str(stack), "--init", str(drawn), "--out", str(tmp / "tracked"), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert f"would replace the input {drawn}" in err and len(err.strip().splitlines()) == 1
    assert drawn.read_bytes() == init.read_bytes() and [p.name for p in (tmp / "tracked").iterdir()] == [name]


# --------------------------------------------------------------------------
# Stacks, zarr, frames; match and simulate
# --------------------------------------------------------------------------


def test_segment_a_stack_on_chosen_frames(movie_files):
    movie, stack, _, tmp = movie_files
    init = write_shapes_csv(tmp / "init2d.csv", [movie.outlines[0][::6]])
    out = tmp / "frames.csv"
    assert main(["segment", str(stack), "--init", str(init), "--out", str(out), "--frames", "1:6:2",
                 "--node-spacing", "4", "--mask", str(tmp / "labels.tif")]) == 0
    shapes, frames = read_shapes_csv(out, leading=True)
    assert [f[0] for f in frames] == [1, 3, 5]
    for (t,), contour in zip(frames, shapes):
        found = polygon_mask(contour, movie.masks[int(t)].shape)
        assert (found & movie.masks[int(t)]).sum() / (found | movie.masks[int(t)]).sum() > 0.97
    labels = io.imread(tmp / "labels.tif")
    assert labels.shape == movie.frames.shape and labels[0].max() == 0
    assert [sorted(np.unique(labels[t])) for t in (1, 3, 5)] == [[0, 1]] * 3  # shape 0 is label 1 on every frame


def test_mask_labels_shape_k_as_k_plus_1_on_every_frame_and_when_another_failed(tmp_path, monkeypatch):
    # The labels counted (frame, shape) results: frame 0 held 1, 2, frame 1 held 3, 4, ...
    import napari_physeg.core as core

    tifffile = pytest.importorskip("tifffile")
    frames = np.zeros((3, 40, 60), np.uint8)
    frames[1] = 1  # tells frame 1 to the fake segment
    tifffile.imwrite(tmp_path / "movie.tif", frames, photometric="minisblack")
    boxes = [np.array([[5.0, 5.0], [5.0, 15.0], [15.0, 15.0], [15.0, 5.0]]) + [0, c] for c in (0, 20, 40)]
    init = write_shapes_csv(tmp_path / "init.csv", boxes)

    @functools.wraps(core.segment)
    def fake(image, contour, **options):  # the contour itself; shape 1 fails on frame 1
        if np.asarray(contour)[0, 1] == 25.0 and image[0, 0] == 1:
            raise ValueError("the contour collapsed to a point")
        return type("Result", (), dict(contour=np.asarray(contour), converged=True, steps=1, stop_reason="rest",
                                       timings={"total": 0.0}))

    monkeypatch.setattr(core, "segment", fake)
    assert main(["segment", str(tmp_path / "movie.tif"), "--frames", "0:3", "--init", str(init),
                 "--out", str(tmp_path / "o.csv"), "--mask", str(tmp_path / "labels.tif")]) == 1
    with tifffile.TiffFile(tmp_path / "labels.tif") as tif:  # 3 frames: a stack, not a planar RGB image
        labels = tif.asarray()
        assert "S" not in tif.series[0].axes and labels.shape == (3, 40, 60)
    assert [labels[t, 10, [10, 30, 50]].tolist() for t in range(3)] == [[1, 2, 3], [1, 0, 3], [1, 2, 3]]
    assert main(["segment", str(tmp_path / "movie.tif"), "--frames", "0:3", "--init", str(init),
                 "--out", str(tmp_path / "p.csv"), "--mask", str(tmp_path / "labels.png")]) == 2
    assert not (tmp_path / "p.csv").exists()


def test_track_a_zarr_stack_on_a_range_of_frames(movie_files):
    zarr = pytest.importorskip("zarr")
    movie, _, init, tmp = movie_files
    z = zarr.open(str(tmp / "movie.zarr"), mode="w", shape=movie.frames.shape, chunks=(1, 80, 80), dtype="f4")
    z[:] = movie.frames
    out = tmp / "tracked"
    assert main(["track", str(tmp / "movie.zarr"), "--init", str(init), "--out", str(out), "--frames", "1:5",
                 "--steps-per-frame", "200", "--n-modes", "8"]) == 0
    _, frames = read_shapes_csv(out / "contours.csv", leading=True)
    assert [f[0] for f in frames] == [1, 2, 3, 4]  # the stack's own frame numbers
    table = __import__("pandas").read_csv(out / "tracks.csv")
    assert sorted(set(table["frame"])) == [1, 2, 3, 4] and (table["status"] == "tracked").all()


def test_a_frame_that_cannot_be_read_mid_run_is_named_on_a_line_of_its_own_and_the_frames_done_kept(tmp_path, capsys):
    # The decoder's bare message was glued to the progress bar: "... 2/4 object-framesnapari-physeg: error: Zstd".
    zarr = pytest.importorskip("zarr")
    yy, xx = np.mgrid[:48, :48]
    frame = (((yy - 24) ** 2 + (xx - 24) ** 2 < 10 ** 2) * 200 + 20).astype(np.uint8)
    z = zarr.open(str(tmp_path / "movie.zarr"), mode="w", shape=(4, 48, 48), chunks=(1, 48, 48), dtype="u1")
    z[:] = np.stack([frame] * 4)
    root = tmp_path / "movie.zarr"
    (chunk,) = [p for p in root.rglob("*") if p.relative_to(root).as_posix().startswith(("c/2/0/", "2."))]  # v3, v2
    chunk.write_bytes(b"\x07" * 50)  # frame 2's chunk, corrupt
    a = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    init = write_shapes_csv(tmp_path / "init.csv", [np.c_[24 + 14 * np.sin(a), 24 + 14 * np.cos(a)]])
    assert main(["track", str(tmp_path / "movie.zarr"), "--init", str(init), "--out", str(tmp_path / "t")]) == 1
    lines = capsys.readouterr().err.split("\n")
    said = [line for line in lines if "could not read" in line]
    assert len(said) == 1 and said[0].startswith(f"napari-physeg: warning: could not read frame 2 of {tmp_path}")
    assert "object-frames" in "".join(lines[:lines.index(said[0])])  # the bar was drawn before it
    # What was tracked before the bad frame is kept.
    _, leading = read_shapes_csv(tmp_path / "t" / "contours.csv", leading=True)
    assert [f[0] for f in leading] == [0, 1]


@pytest.mark.parametrize("compression", [None, "zlib"])
def test_a_tiff_cut_short_is_refused_before_any_work(movie_files, capsys, no_work, compression):
    """A compressed TIFF cut short was read as the one image of its first
    page (an outside tester, session 66): "is a single 2-D image"."""
    tifffile = pytest.importorskip("tifffile")
    movie, stack, init, tmp = movie_files
    whole = tmp / "whole.tif"
    tifffile.imwrite(whole, tifffile.imread(stack), compression=compression)
    cut = tmp / "cut.tif"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size * 6 // 10])  # an interrupted copy
    assert main(["track", str(cut), "--init", str(init), "--out", str(tmp / "tracked")]) == 2
    err = capsys.readouterr().err
    assert f"{cut} is cut short" in err and "copy it again" in err and not (tmp / "tracked").exists()


def test_match_of_contours_in_x_y_and_row_col_says_so_on_one_line(tmp_path, capsys):
    a = data.hand_outline("open", n_nodes=67)
    hands = write_shapes_csv(tmp_path / "hands.csv", [a, a[:, ::-1]])
    assert main(["match", str(hands), "--out", str(tmp_path / "pairs.csv")]) == 0  # a warning, not a failure
    warned = [line for line in capsys.readouterr().err.splitlines() if "mirror image" in line]
    assert len(warned) == 1 and warned[0].startswith("napari-physeg: warning: b is a's mirror image")
    assert "swap the columns" in warned[0]


@pytest.mark.parametrize("command", ["match", "simulate"])
def test_a_shape_matched_with_itself_is_refused(tmp_path, capsys, command):
    a, b, _ = data.hand_pair(67, 66)
    hands = write_shapes_csv(tmp_path / "hands.csv", [a, b])
    out = tmp_path / "out.csv"
    assert main([command, str(hands), "--out", str(out), "--a-shape", "1", "--b-shape", "1"]) == 2
    assert "both shape 1" in capsys.readouterr().err and not out.exists()


def test_match_and_simulate_from_one_csv(tmp_path, capsys):
    a, b, truth = data.hand_pair(67, 66)
    hands = write_shapes_csv(tmp_path / "hands.csv", [a, b])
    pairs = tmp_path / "pairs.csv"
    assert main(["match", str(hands), "--out", str(pairs), "--method", "global"]) == 0
    table = np.genfromtxt(pairs, delimiter=",", names=True)
    assert len(table) == 67 and set(table["node_a"].astype(int)) == set(range(67))
    np.testing.assert_allclose(np.c_[table["row_b"], table["col_b"]], b[table["node_b"].astype(int)])
    frames = tmp_path / "frames.csv"
    assert main(["simulate", str(hands), "--out", str(frames), "--n-frames", "4", "--q", "30000"]) == 0
    shapes, lead = read_shapes_csv(frames, leading=True)
    assert [t[0] for t in lead] == [0, 1, 2, 3]
    np.testing.assert_allclose(shapes[0], a)
    assert np.abs(shapes[-1] - b[table["node_b"].astype(int)]).max() > 0  # moved toward b
    assert main(["simulate", str(hands), "--out", str(frames)]) == 2  # exists
    # A custom material, as docs/batch.md says of every command (simulate took none before session 64):
    # a stiffer a keeps more of its shape on the way.
    soft, stiff = tmp_path / "soft.csv", tmp_path / "stiff.csv"
    for out, young in ((soft, "1"), (stiff, "100000")):
        assert main(["simulate", str(hands), "--out", str(out), "--n-frames", "3", "--young", young,
                     "--density", "1000"]) in (0, 1)
    middle = [read_shapes_csv(out)[1] for out in (soft, stiff)]
    assert not np.allclose(*middle)
    assert main(["match", str(hands), "--out", str(pairs), "--overwrite", "--b-shape", "2"]) == 2
    assert "holds 2 shape(s)" in capsys.readouterr().err


def test_a_rectangle_is_matched_and_simulated_along_its_sides_not_by_its_corners(tmp_path, capsys):
    """A rectangle in a shapes CSV is its 4 corners: it was matched, and
    driven, as a quadrilateral (4 nodes of a, the 200 of b mostly unpaired)."""
    from napari_physeg.io import write_shapes_csv as write

    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    ellipse = np.c_[50 + 30 * np.sin(t), 55 + 35 * np.cos(t)]
    box = np.array([[25.0, 25.0], [25.0, 80.0], [85.0, 80.0], [85.0, 25.0]])
    shapes = write(tmp_path / "shapes.csv", [box, ellipse])
    pairs = tmp_path / "pairs.csv"
    assert main(["match", str(shapes), "--out", str(pairs)]) == 0
    table = np.genfromtxt(pairs, delimiter=",", names=True)
    assert len(table) >= 70  # 230 px of outline, a node every 3 px or less
    frames = tmp_path / "frames.csv"
    main(["simulate", str(shapes), "--out", str(frames)])
    last = read_shapes_csv(frames)[-1]
    assert len(last) == len(table) and _outline_distance(ellipse, last).max() < 3.0


def _outline_distance(points, contour):
    """Distance of each point to the closed polyline ``contour`` (finely resampled)."""
    from scipy.spatial import cKDTree

    c = np.asarray(contour, float)
    t = np.linspace(0, 1, 20, endpoint=False)
    dense = (c[:, None] + t[None, :, None] * (np.roll(c, -1, axis=0) - c)[:, None]).reshape(-1, 2)
    return cKDTree(dense).query(np.asarray(points, float))[0]


def test_every_option_of_every_command_is_explained():
    from napari_physeg.cli import build_parser

    def walk(parser, name):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub in action.choices.items():
                    yield from walk(sub, f"{name} {sub_name}")
            elif action.dest != "help":
                assert action.help and len(action.help) > 15, f"{name} {action.option_strings or action.dest}"
                yield name, action

    seen = {(name, a.dest) for name, a in walk(build_parser(), "napari-physeg")}
    for command in ("segment", "track", "batch segment", "batch track"):
        for option in ("material", "stiffness", "polarity", "contrast", "weights", "n_nodes", "frames"):
            assert (f"napari-physeg {command}", option) in seen
    assert ("napari-physeg batch track", "scheduler") in seen and ("napari-physeg match", "method") in seen


@pytest.mark.parametrize("extra, message", [
    (["--frames", "0:2"], "not among --frames"),
    (["--frames", "7"], "frames 0 to 5"),
    (["--start", "1", "--frames", "3:6"], "not among --frames 3:6"),
    (["--steps-per-frame", "0"], "--steps-per-frame"),
    (["--frames", "2,2,3"], "names frame 2 more than once"),
    (["--frames", "4,2,0"], "in the movie's order"),
])
def test_track_refuses_bad_frames_before_any_work(movie_files, capsys, no_work, extra, message):
    movie, stack, init, tmp = movie_files
    assert main(["track", str(stack), "--init", str(init), "--out", str(tmp / "tracked"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (tmp / "tracked").exists()


def test_track_refuses_contours_drawn_beyond_the_last_frame(movie_files, capsys, no_work):
    movie, stack, _, tmp = movie_files
    late = write_shapes_csv(tmp / "late.csv", [movie.outlines[0][::6]], leading=[(20,)])
    assert main(["track", str(stack), "--init", str(late), "--out", str(tmp / "tracked")]) == 2
    assert "drawn on frame 20, not in the stack (frames 0 to 5)" in capsys.readouterr().err


@pytest.mark.parametrize("text, message", [
    ("index,shape-type,vertex-index,axis-0,axis-1\n0,polygon,0,1\n", "comma-separated"),
    ("index,shape-type,vertex-index,axis-0,axis-1\n0,polygon,0,1,2\n0,polygon,1,3\n", "fewer columns"),
    ("index,shape-type,vertex-index,axis-0,axis-1,axis-2\n" +
     "".join(f"0,polygon,{i},nan,{r},{c}\n" for i, (r, c) in enumerate([(1, 2), (9, 3), (5, 8)])), "NaN"),
])
def test_a_malformed_shapes_csv_is_named_and_explained(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_shapes_csv(path, leading=True)


def test_track_refuses_contours_outside_the_movie(movie_files, capsys, no_work):
    movie, stack, _, tmp = movie_files
    far = write_shapes_csv(tmp / "far.csv", [[[500, 500], [500, 520], [520, 510]]])
    assert main(["track", str(stack), "--init", str(far), "--out", str(tmp / "tracked")]) == 2
    assert "wholly outside" in capsys.readouterr().err and not (tmp / "tracked").exists()


def test_options_reach_segment_by_name_and_the_rest_keep_its_defaults(scene, monkeypatch):
    import napari_physeg.core as core

    seen, real = [], core.segment

    @functools.wraps(real)  # its signature: the CLI reads the defaults from it
    def spy(image, init, **options):
        seen.append(options)
        return real(image, init, **options)

    monkeypatch.setattr(core, "segment", spy)
    obj, image, init, tmp = scene
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp / "a.csv")]) == 0
    assert seen[-1] == {}  # nothing given: segment()'s own defaults
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp / "b.csv"), "--material", "copper",
                 "--young", "50", "--density", "2000", "--stiffness", "1e5", "--node-spacing", "4", "--polarity",
                 "bright", "--weights", "edges=0.5,distance=0.5", "--sigma-factor", "1.2", "--max-steps", "400"]) == 0
    options = seen[-1]
    material = options.pop("material")
    assert (material.young, material.density, material.poisson) == (50e6, 2000.0, core.MATERIALS["copper"].poisson)
    from napari_physeg.core.contour import perimeter
    assert options == {"stiffness": 1e5, "n_nodes": round(perimeter(read_shapes_csv(init)[0]) / 4),
                       "polarity": "bright", "forces": ("edges", "distance"),
                       "weights": {"edges": 0.5, "distance": 0.5}, "sigma_factor": 1.2, "max_steps": 400}


@pytest.mark.parametrize("command", ["segment", "track", "batch track"])
@pytest.mark.parametrize("option, value, said", [("--n-nodes", "100000", "'100000' must be <= 5000"),
                                                 ("--node-spacing", "0.01", "'0.01' must be >= 0.5")])
def test_more_nodes_than_segment_takes_are_refused_before_any_work(movie_files, capsys, no_work, command, option,
                                                                   value, said):
    # --n-nodes 100000 (or --node-spacing 0.01) ran for hours: the core takes at most 5000 nodes, the
    # widgets a spacing of 0.5 px or more.
    movie, stack, init, tmp = movie_files
    out = tmp / ("o.csv" if command == "segment" else "out")
    assert main([*command.split(), str(stack), "--init", str(init), "--out", str(out), option, value]) == 2
    err = capsys.readouterr().err
    assert said in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_a_spacing_that_gives_a_large_contour_too_many_nodes_gives_it_the_most_segment_takes():
    from napari_physeg.batch import segment_options_for
    from napari_physeg.core.segmentation import MAX_NODES

    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    big = 2000.0 * np.column_stack([np.sin(t), np.cos(t)])  # 12,566 px around
    assert segment_options_for(big[:100] / 20, {}, 3.0)["n_nodes"] < MAX_NODES  # the normal range: as before
    with pytest.warns(UserWarning, match="a node spacing of 0.5 px gives a contour 12566 px around"):
        assert segment_options_for(big, {}, 0.5)["n_nodes"] == MAX_NODES


def test_a_material_without_stiffness_leaves_the_r_to_segment(scene, monkeypatch):
    # segment() picks the r that suits the material (copper: the paper's 1e6), as the widget shows it.
    import napari_physeg.core as core

    seen, real = [], core.segment

    @functools.wraps(real)
    def spy(image, init, **options):
        seen.append(options)
        return real(image, init, **options)

    monkeypatch.setattr(core, "segment", spy)
    obj, image, init, tmp = scene
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp / "c.csv"), "--material", "copper"]) == 0
    assert seen[-1] == {"material": "copper"}


def test_a_warning_is_one_line_of_the_program_s_own(scene, capsys):
    obj, image, _, tmp = scene
    # Drawn partly beyond the image's left side: clipped to it, with a warning.
    beyond = write_shapes_csv(tmp / "beyond.csv", [obj.init_near - [0.0, obj.init_near[:, 1].min() + 5.0]])
    main(["segment", str(image), "--init", str(beyond), "--out", str(tmp / "o.csv")])
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "outside the image" in line]
    assert len(warned) == 1 and warned[0].startswith("napari-physeg: warning: ")
    assert "UserWarning" not in err and ".py:" not in err


@pytest.mark.parametrize("command", ["segment", "track"])
def test_channel_on_a_grayscale_stack_is_refused(movie_files, capsys, no_work, command):
    movie, stack, init, tmp = movie_files
    out = tmp / ("o.csv" if command == "segment" else "tracked")
    assert main([command, str(stack), "--init", str(init), "--out", str(out), "--channel", "1"]) == 2
    err = capsys.readouterr().err
    h, w = movie.frames.shape[1:]
    assert f"{stack} has no channels (a 6 x {h} x {w} stack): leave out the channel option (--channel)" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


def test_channel_of_an_rgb_image_is_still_read(tmp_path):
    from napari_physeg.io import open_stack

    rgb = np.zeros((20, 30, 3), np.uint8)
    rgb[..., 1] = 9
    io.imsave(tmp_path / "rgb.png", rgb, check_contrast=False)
    with open_stack(tmp_path / "rgb.png", channel=1) as stack:
        assert stack.shape == (1, 20, 30) and int(stack.max()) == 9
    with pytest.raises(ValueError, match="channel must be an integer"):  # was a TypeError from a comparison
        with open_stack(tmp_path / "rgb.png", channel="1"):
            pass


@pytest.mark.parametrize("rows", ["1,1\n5,5\n", "1,1\n5,5\n9,9\n"])
def test_a_table_of_points_on_one_line_is_no_contour(tmp_path, rows):
    """read_shapes_csv's promise (an outside fuzzer, session 67): a shape that
    encloses nothing is refused when read, not later by segment()."""
    from napari_physeg.io import read_shapes_csv

    (tmp_path / "line.csv").write_text("row,col\n" + rows)
    with pytest.raises(ValueError, match="shape 0 of .* encloses nothing"):
        read_shapes_csv(tmp_path / "line.csv")


def test_a_tiff_of_pages_written_one_by_one_is_read_a_frame_at_a_time_and_one_of_mixed_shapes_refused(
        tmp_path, monkeypatch):
    """Found by an outside probe (session 64): a TIFF whose pages are each a
    series of their own (written a page at a time) gave its first page only,
    and the other frames were dropped without a word. Then it was read whole
    on opening (session 66, an outside tester: 1.5 GB to track 3 frames of a
    0.5 GB movie)."""
    tifffile = pytest.importorskip("tifffile")
    from napari_physeg.io import open_stack

    frames = np.arange(5 * 20 * 30, dtype=np.uint16).reshape(5, 20, 30)
    with tifffile.TiffWriter(tmp_path / "pages.tif") as tif:
        for frame in frames:
            tif.write(frame, contiguous=False)
    read, asarray = [], tifffile.TiffPageSeries.asarray  # the pages read, by index
    monkeypatch.setattr(tifffile.TiffPageSeries, "asarray",
                        lambda self, *a, **k: read.append(self.keyframe.index) or asarray(self, *a, **k))
    with open_stack(tmp_path / "pages.tif") as stack:
        np.testing.assert_array_equal(np.asarray(stack[3]), frames[3])
        assert read == [3]
        np.testing.assert_array_equal(np.asarray(stack), frames)
    with tifffile.TiffWriter(tmp_path / "mixed.tif") as tif:
        tif.write(frames[0], contiguous=False)
        tif.write(frames[1, :10], contiguous=False)
    with pytest.raises(ValueError, match="holds 2 images of shapes 20 x 30, 10 x 30, not one stack"):
        with open_stack(tmp_path / "mixed.tif"):
            pass


def test_channel_of_a_hyperstack_and_of_an_rgb_zarr_movie_is_taken(tmp_path, capsys, no_work):
    # Seen: "tcyx.tif has no channels (a 3 x 2 x 20 x 30 stack): leave out --channel", the same for the zarr.
    tifffile, zarr = pytest.importorskip("tifffile"), pytest.importorskip("zarr")
    from napari_physeg.io import open_stack

    tcyx = np.arange(3 * 2 * 20 * 30, dtype=np.uint16).reshape(3, 2, 20, 30)
    tifffile.imwrite(tmp_path / "tcyx.tif", tcyx, imagej=True, metadata={"axes": "TCYX"})
    rgb = zarr.open(str(tmp_path / "rgb.zarr"), mode="w", shape=(3, 20, 30, 3), dtype="u2")
    rgb[:] = np.moveaxis(np.arange(3 * 3 * 20 * 30, dtype=np.uint16).reshape(3, 3, 20, 30), 1, -1)
    for name, c, expected in (("tcyx.tif", 1, tcyx[:, 1]), ("rgb.zarr", 2, rgb[:][..., 2])):
        with open_stack(tmp_path / name, channel=c) as stack:
            np.testing.assert_array_equal(np.asarray(stack), expected)
    init = write_shapes_csv(tmp_path / "init.csv", [[[5, 5], [5, 15], [15, 10]]])
    for name, message in (("tcyx.tif", "has 2 channels (axis C of TCYX, shape 3 x 2 x 20 x 30): choose one with "
                                       "the channel option (--channel): 0 or 1"),
                          ("rgb.zarr", "has 3 channels (RGB(A) samples, the last axis, shape 3 x 20 x 30 x 3): "
                                       "choose one with the channel option (--channel): 0, 1 or 2")):
        assert main(["track", str(tmp_path / name), "--init", str(init), "--out", str(tmp_path / "o")]) == 2
        assert f"{tmp_path / name} {message}" in capsys.readouterr().err
    with pytest.raises(ValueError, match="channel 2 is out of range: .* has 2 channels \\(axis C of TCYX\\)"):
        with open_stack(tmp_path / "tcyx.tif", channel=2):
            pass


def test_track_refuses_a_single_image(scene, capsys, no_work):
    obj, image, init, tmp = scene
    assert main(["track", str(image), "--init", str(init), "--out", str(tmp / "tracked")]) == 2
    err = capsys.readouterr().err
    assert f"{image} is a single 2-D image; track needs a time-lapse (T x H x W)" in err
    assert not (tmp / "tracked").exists()


@pytest.mark.skipif(os.name != "posix", reason="POSIX file modes")
def test_outputs_get_the_mode_open_gives_them(tmp_path):
    pd = pytest.importorskip("pandas")
    from napari_physeg.io import write_table

    old = os.umask(0o027)
    try:
        written = [write_shapes_csv(tmp_path / "s.csv", [[[0, 0], [0, 5], [5, 0]]])]
        written += write_table(pd.DataFrame({"a": [1]}), tmp_path / "t")
    finally:
        os.umask(old)
    assert {oct(p.stat().st_mode & 0o777) for p in written} == {oct(0o640)}
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary file left


def test_a_tiff_cut_within_its_first_pages_gets_one_line(movie_files):
    # tifffile logged "invalid page offset" to stderr, a line before the program's own (in a process of
    # its own: pytest's log capture would take the line).
    movie, stack, init, tmp = movie_files
    cut = tmp / "cut.tif"
    cut.write_bytes(stack.read_bytes()[:3000])
    run = subprocess.run([sys.executable, "-m", "napari_physeg.cli", "track", str(cut), "--init", str(init),
                          "--out", str(tmp / "tracked")], capture_output=True, text=True)
    assert run.returncode == 2 and "is cut short" in run.stderr and run.stderr.count("\n") == 1


def test_out_onto_a_pipe_writes_into_it_and_leaves_it_a_pipe(scene, tmp_path):
    # Renamed over, --out /dev/null (a device) became a plain file, as root.
    import stat
    import threading

    obj, image, init, tmp = scene
    pipe = tmp / "pipe"
    os.mkfifo(pipe)
    got = []
    reader = threading.Thread(target=lambda: got.append(pipe.read_text()))
    reader.start()
    assert main(["segment", str(image), "--init", str(init), "--out", str(pipe)]) == 0  # no --overwrite needed
    reader.join(timeout=30)
    assert stat.S_ISFIFO(os.stat(pipe).st_mode)
    assert got and got[0].startswith("index,shape-type,vertex-index,axis-0,axis-1")


def test_a_row_col_table_of_several_objects_and_closed_contours(tmp_path):
    # An id column named the objects: they were read as one self-crossing contour. A closed contour's
    # repeated first point (find_contours, Fiji) was refused as a repeated node.
    a = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = np.c_[np.sin(a), np.cos(a)]
    first, second = 30 + 8 * ring, 60 + 10 * ring
    rows = [f"{k},{float(r)!r},{float(c)!r}" for k, shape in ((3, first), (1, second)) for r, c in np.vstack([shape, shape[:1]])]
    table = tmp_path / "objects.csv"
    table.write_text("id,row,col\n" + "\n".join(rows) + "\n")
    shapes = read_shapes_csv(table)
    assert len(shapes) == 2 and np.array_equal(shapes[0], first) and np.array_equal(shapes[1], second)
    # Fiji's Results: a row number before X, Y names no object.
    table.write_text(" ,X,Y\n" + "\n".join(f"{i + 1},{float(c)!r},{float(r)!r}" for i, (r, c) in enumerate(first)) + "\n")
    (only,) = read_shapes_csv(table)
    assert np.array_equal(only, first)


def test_a_contour_that_did_not_converge_is_named_on_stderr(scene, capsys, monkeypatch):
    import napari_physeg.core as core

    obj, image, init, tmp = scene
    real = core.segment
    monkeypatch.setattr(core, "segment", functools.wraps(real)(lambda *a, **k: real(*a, **{**k, "max_steps": 1})))
    assert main(["segment", str(image), "--init", str(init), "--out", str(tmp / "o.csv")]) == 1
    err = capsys.readouterr().err
    assert "shape 0 did not converge (max_steps)" in err and (tmp / "o.csv").exists()


@pytest.mark.parametrize("extra, message", [
    (["--sigma-factor", "50"], "--sigma-factor"),
    (["--mask", "labels.jpg"], "name it .tif or .png"),
    (["--out", "contours.tif"], "written as CSV text: name it .csv (--mask writes the label image)"),
])
def test_segment_refuses_options_it_cannot_honour_before_any_work(scene, capsys, no_work, monkeypatch, extra,
                                                                  message):
    # Refused only after the work: each shape failed with segment()'s message; the JPEG after o.csv was written.
    obj, image, init, tmp = scene
    monkeypatch.chdir(tmp)
    before = sorted(p.name for p in tmp.iterdir())
    assert main(["segment", str(image), "--init", str(init), "--out", "o.csv", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp.iterdir()) == before


@pytest.mark.parametrize("text", [
    "# drawn in Fiji\nrow,col\n1,2\n3,4\n5,1\n",  # a comment line
    "row,col,\n1,2,\n3,4,\n5,1,\n",  # a spreadsheet's empty last column
    "row;col\n1,0;2\n3;4,0\n5;1\n",  # ';' between columns, decimal commas
    "Y\tX\n1\t2\n3\t4\n5\t1\n",  # Fiji's tab-separated table
])
def test_tables_as_spreadsheets_and_fiji_write_them(tmp_path, text):
    table = tmp_path / "t.csv"
    table.write_text(text)
    assert np.array_equal(read_shapes_csv(table)[0], [[1, 2], [3, 4], [5, 1]])


_CELLS = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-5, 5).map(str),
                   st.sampled_from(["", " ", "polygon", "ellipse", "line", "index", "axis-0", "shape-type", "row",
                                    "x", "id", "#", "nan", "1e400", "1,5", "a;b"]),
                   st.text(max_size=5))


@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck))
@given(rows=st.lists(st.lists(_CELLS, max_size=7), max_size=12), sep=st.sampled_from([",", ";", "\t"]),
       header=st.sampled_from([None, "index,shape-type,vertex-index,axis-0,axis-1", "row,col", "id,row,col", "x,y"]))
def test_any_table_is_read_or_refused_with_a_reason(tmp_path_factory, rows, sep, header):
    # An index of 1e400 escaped as an OverflowError (a traceback from the command).
    path = tmp_path_factory.mktemp("table") / "t.csv"
    path.write_bytes("\n".join(([header] if header else []) + [sep.join(r) for r in rows]).encode("utf-8",
                                                                                              "surrogatepass"))
    try:
        shapes = read_shapes_csv(path)
    except ValueError:
        return
    assert shapes and all(s.ndim == 2 and s.shape[1] == 2 and np.isfinite(s).all() for s in shapes)


def test_a_zarr_group_is_refused_naming_an_array_in_it(scene, capsys, no_work):
    # An OME-Zarr image is a group: zarr's "Expected 'array'. Got 'group'" said nothing of what to give.
    zarr = pytest.importorskip("zarr")
    obj, image, init, tmp = scene
    group = zarr.open_group(str(tmp / "image.zarr"), mode="w")
    group.create_array("0", shape=(2, 32, 32), dtype="u1")
    assert main(["segment", str(tmp / "image.zarr"), "--init", str(init), "--out", str(tmp / "o.csv")]) == 2
    assert f"give one of them, e.g. {tmp / 'image.zarr' / '0'}" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["match", "simulate"])
def test_match_and_simulate_refuse_an_out_named_as_an_image(tmp_path, capsys, no_work, command):
    t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    pair = write_shapes_csv(tmp_path / "pair.csv", [np.c_[20 + 8 * np.sin(t), 20 + 8 * np.cos(t)],
                                                    np.c_[20 + 10 * np.sin(t), 20 + 6 * np.cos(t)]])
    assert main([command, str(pair), "--out", str(tmp_path / "out.png")]) == 2
    assert "written as CSV text: name it .csv" in capsys.readouterr().err and not (tmp_path / "out.png").exists()


def test_an_empty_path_is_refused_not_read_as_the_current_folder(scene, capsys, no_work, monkeypatch):
    """``--out ""`` (a shell variable left unset) was Path(""), the current
    folder: the contours were written there under its name."""
    obj, image, init, tmp = scene
    monkeypatch.chdir(tmp)
    code = main(["segment", str(image), "--init", str(init), "--out", ""])
    assert code == 2 and "--out: an empty path" in capsys.readouterr().err
    assert main(["segment", "", "--init", str(init), "--out", str(tmp / "o.csv")]) == 2
    assert "image: an empty path" in capsys.readouterr().err
    assert sorted(p.name for p in tmp.iterdir()) == ["image.tif", "init.csv"]


def test_the_core_s_option_names_are_given_as_the_program_s():
    """track()'s advice for an object not found names its own options; the
    program's user is told of its flags instead."""
    from napari_physeg.cli import _in_cli_terms

    told = _in_cli_terms("object 0 was not found on the start frame 0 and is reported lost: no object came to rest "
                         "under its drawing; check that it is drawn around (or inside) one object, or the "
                         "contour's options (max_steps and segment_options of track())")
    assert "(--steps-per-frame, --material or --stiffness)" in told and "track()" not in told

"""The batch command line: napari shapes CSV in, segmented contours out."""

import subprocess
import sys

import numpy as np
import pytest
from skimage import io

from napari_physeg import data
from napari_physeg.cli import main
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


def test_nd_shapes_keep_the_last_two_axes_and_plain_tables_work(tmp_path):
    p = tmp_path / "nd.csv"
    p.write_text("index,shape-type,vertex-index,axis-0,axis-1,axis-2\n"
                 "0,polygon,0,4,1,2\n0,polygon,1,4,3,4\n0,polygon,2,4,5,1\n")
    assert np.array_equal(read_shapes_csv(p)[0], [[1, 2], [3, 4], [5, 1]])
    q = tmp_path / "plain.csv"
    q.write_text("row,col\n1,2\n3,4\n5,1\n")
    assert np.array_equal(read_shapes_csv(q)[0], [[1, 2], [3, 4], [5, 1]])


@pytest.mark.parametrize("extra, message", [
    (["--material", "unobtainium"], "material"),
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


def test_track_refuses_contours_drawn_on_several_frames(movie_files, capsys):
    movie, stack, _, tmp = movie_files
    init = write_shapes_csv(tmp / "two.csv", [movie.outlines[0][::6], movie.outlines[3][::6]], leading=[(0,), (3,)])
    assert main(["track", str(stack), "--init", str(init), "--out", str(tmp / "o")]) == 2
    assert "--start" in capsys.readouterr().err

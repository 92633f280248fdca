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

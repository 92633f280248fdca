"""The plane under an unevenly lit background (core/background.py), and
segmentation and tracking that do not see it."""

import numpy as np
import pytest
from skimage.draw import disk, polygon2mask

from napari_physeg import data
from napari_physeg.core import segment, track
from napari_physeg.core.background import DOME_MIN_SIDE, UNEVEN_LIGHT, background_plane, plane_values

SHAPE = (160, 200)


def spotted(rng, contrast=1.0, noise=0.05):
    """Bright and dark disks (a fifth of the area) on a flat background of 0."""
    image = rng.normal(0.0, noise, SHAPE)
    for k in range(14):
        centre = rng.uniform(15, np.array(SHAPE) - 15)
        image[disk(centre, rng.uniform(6, 12), shape=SHAPE)] = contrast * (1 if k % 2 else -1)
    return image


def tilted(level, slope_row, slope_col):
    rows, cols = np.mgrid[0:SHAPE[0], 0:SHAPE[1]]
    return level + slope_row * rows + slope_col * cols


@pytest.mark.parametrize("seed", range(4))
def test_the_plane_under_objects_of_either_polarity_is_found(seed):
    rng = np.random.default_rng(seed)
    slopes = rng.uniform(-1, 1, 2) * 2.0 / np.array(SHAPE)  # a rise of up to twice the contrast
    plane = background_plane(spotted(rng) + tilted(0.3, *slopes))
    assert plane is not None
    np.testing.assert_allclose(plane_values(plane, (slice(0, SHAPE[0]), slice(0, SHAPE[1]))),
                               tilted(0.3, *slopes), atol=0.02)


def test_an_evenly_lit_image_has_no_plane():
    assert background_plane(spotted(np.random.default_rng(0))) is None


def test_a_slope_is_taken_out_from_a_fifth_of_the_range():
    image = spotted(np.random.default_rng(1))
    value_range = np.subtract(*np.percentile(image, [99, 1]))
    def rise(fraction):  # along the rows, as a fraction of the range
        return tilted(0.0, fraction * value_range / (SHAPE[0] - 1), 0.0)
    assert background_plane(image + rise(0.5 * UNEVEN_LIGHT)) is None
    assert background_plane(image + rise(2.0 * UNEVEN_LIGHT)) is not None


def test_pixels_that_are_not_finite_are_left_out():
    image = spotted(np.random.default_rng(2)) + tilted(0.0, 0.01, 0.0)
    image[:40] = np.nan
    image[50, 50] = np.inf
    plane = background_plane(image)
    np.testing.assert_allclose(plane[1:], [0.01, 0.0], atol=3e-4)
    assert abs(plane[0]) < 0.01
    assert background_plane(np.full((5, 5), np.nan)) is None


def test_plane_values_on_a_window():
    values = plane_values(np.array([1.0, 0.5, -0.25]), (slice(2, 4), slice(10, 13)))
    rows, cols = np.mgrid[2:4, 10:13]
    np.testing.assert_array_equal(values, 1.0 + 0.5 * rows - 0.25 * cols)


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


@pytest.mark.parametrize("rise", [1.0, 3.0])
def test_segmentation_does_not_see_a_slope_of_the_background(rise):
    """The blob on a background that rises across the image by ``rise``
    times its contrast (1) is outlined as on an even one. Without the plane
    taken out, the reading of the drawing took the far bright side of the
    slope for the background."""
    obj = data.blob((128, 128), noise=0.1)
    rows, cols = np.mgrid[0:128, 0:128]
    even = segment(obj.image, obj.init_near).contour
    sloped = segment(obj.image + rise * (rows + cols) / 254, obj.init_near).contour
    assert iou(polygon2mask(obj.mask.shape, sloped), obj.mask) > 0.97
    assert np.abs(sloped - even).max() < 0.2


def test_tracking_does_not_see_a_slope_of_the_background():
    movie = data.deforming_cell(n_frames=6)
    rows, cols = np.mgrid[0:movie.frames.shape[1], 0:movie.frames.shape[2]]
    even = track(movie.frames, movie.init)
    sloped = track(movie.frames + 2.0 * cols / cols.max(), movie.init)
    for a, b, mask in zip(even.contours[0], sloped.contours[0], movie.masks):
        assert iou(polygon2mask(mask.shape, b), mask) > 0.97
        assert np.abs(a - b).max() < 0.2


def domed(level, depth, shape=SHAPE):
    """A vignette: ``level`` in the middle, falling by ``depth`` toward the corners."""
    rows, cols = np.mgrid[0:shape[0], 0:shape[1]]
    r2 = ((rows - (shape[0] - 1) / 2) / shape[0]) ** 2 + ((cols - (shape[1] - 1) / 2) / shape[1]) ** 2
    return level - 2.0 * depth * r2


@pytest.mark.parametrize("seed", range(3))
def test_the_dome_under_a_vignetted_field_is_found(seed):
    rng = np.random.default_rng(seed)
    dome = domed(0.3, 1.0) + tilted(0.0, *(rng.uniform(-0.5, 0.5, 2) / np.array(SHAPE)))
    surface = background_plane(spotted(rng) + dome)
    assert surface is not None and len(surface) == 6
    np.testing.assert_allclose(plane_values(surface, (slice(0, SHAPE[0]), slice(0, SHAPE[1]))), dome, atol=0.03)


def test_a_plane_stays_a_plane_and_small_images_get_no_dome():
    rng = np.random.default_rng(5)
    assert len(background_plane(spotted(rng) + tilted(0.3, 0.01, -0.005))) == 3
    small = (spotted(rng) + domed(0.3, 1.0))[:DOME_MIN_SIDE - 1, :DOME_MIN_SIDE - 1]
    assert background_plane(small) is None or len(background_plane(small)) == 3
    assert len(background_plane(spotted(rng) + domed(0.3, 1.0), curved=False) or ()) != 6


def test_plane_values_of_a_dome_on_a_window():
    values = plane_values(np.array([1.0, 0.5, -0.25, 0.01, -0.02, 0.03]), (slice(2, 4), slice(10, 13)))
    rows, cols = np.mgrid[2:4, 10:13]
    np.testing.assert_allclose(values, 1.0 + 0.5 * rows - 0.25 * cols + 0.01 * rows ** 2 - 0.02 * rows * cols
                               + 0.03 * cols ** 2)


def test_a_bright_disk_over_half_of_the_image_is_no_dome():
    """A disk over half of the image: the plane's biweight lies between its
    two levels, and a dome following the disk rose by 1.6 times the image's
    range, which no background does: no surface is taken out, and a circle
    inside the disk finds it whole (the evenly lit disk's inside read as a
    dark hole, IoU 0.47)."""
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[:512, :512]
    bright = np.hypot(rows - 256.3, cols - 255.8) <= 200
    image = bright + rng.normal(0, 0.05, bright.shape)
    assert background_plane(image) is None
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    circle = np.column_stack([256 + 100 * np.sin(t), 256 + 100 * np.cos(t)])
    found = polygon2mask(bright.shape, segment(image, circle).contour)
    assert (found & bright).sum() / (found | bright).sum() > 0.98

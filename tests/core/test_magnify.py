"""Small objects segmented on a magnified view (core.magnify and segment's use of it)."""

import numpy as np
import pytest
from scipy import ndimage as ndi
from skimage.draw import polygon2mask

from napari_physeg.core import iter_segment, segment
from napari_physeg.core.magnify import (MAX_MAGNIFICATION, MAX_VIEW_PIXELS, SMALL_OBJECT_RADIUS, MagnifiedView,
                                        magnification)


def _iou(contour, mask):
    m = polygon2mask(mask.shape, contour)
    return (m & mask).sum() / (m | mask).sum()


def _circle(centre, radius, n=48):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([centre[0] + radius * np.sin(t), centre[1] + radius * np.cos(t)])


def _disks(centres, radius, shape=(64, 64), noise=0.05, seed=0):
    """Disks rendered as pixel coverage (8 x 8 samples a pixel), blurred by a
    1-px Gaussian, in white noise; and each disk's mask (coverage >= 1/2)."""
    ss = 8
    rows = (np.arange(shape[0] * ss) + 0.5) / ss - 0.5
    cols = (np.arange(shape[1] * ss) + 0.5) / ss - 0.5
    image, masks = np.zeros(shape), []
    for r, c in centres:
        inside = (rows[:, None] - r) ** 2 + (cols[None, :] - c) ** 2 <= radius ** 2
        coverage = inside.reshape(shape[0], ss, shape[1], ss).mean(axis=(1, 3))
        image = np.maximum(image, coverage)
        masks.append(coverage >= 0.5)
    image = ndi.gaussian_filter(image, 1.0) + np.random.default_rng(seed).normal(0, noise, shape)
    return image, masks


def test_small_objects_are_magnified_to_about_the_size_the_method_reads_well():
    assert magnification(SMALL_OBJECT_RADIUS) == 1 and magnification(50.0) == 1
    assert magnification(SMALL_OBJECT_RADIUS / 2) == 2
    assert magnification(0.5) == magnification(0.0) == MAX_MAGNIFICATION
    radii = np.linspace(0.5, 30, 200)
    factors = [magnification(r) for r in radii]
    assert all(a >= b for a, b in zip(factors, factors[1:]))  # smaller objects, more magnified
    # Up to the largest magnification, the object reaches the size the method reads well.
    assert all(r * f >= SMALL_OBJECT_RADIUS for r, f in zip(radii, factors) if f < MAX_MAGNIFICATION)
    # A view that would hold too many pixels is magnified less, or not at all.
    assert magnification(2.0, window_pixels=MAX_VIEW_PIXELS // 9) == 3
    assert magnification(2.0, window_pixels=MAX_VIEW_PIXELS // 4) == 2
    assert magnification(2.0, window_pixels=MAX_VIEW_PIXELS) == 1


@pytest.mark.parametrize("factor", [2, 3])
def test_a_magnified_view_keeps_every_pixel_s_centre_and_value_in_place(factor):
    rng = np.random.default_rng(factor)
    image = rng.normal(size=(40, 50))
    view = MagnifiedView.around(np.array([[10.0, 12.0], [20.0, 30.0]]), image.shape, 5.0, factor)
    r0, c0 = view.window[0].start, view.window[1].start
    rows, cols = np.mgrid[view.window]
    centres = view.inward(np.column_stack([rows.ravel(), cols.ravel()]))
    np.testing.assert_allclose(view.outward(centres), np.column_stack([rows.ravel(), cols.ravel()]), atol=1e-12)
    # A pixel's centre is its block's centre ...
    np.testing.assert_allclose(centres[0], [(factor - 1) / 2] * 2)
    magnified = view.image(image)
    assert magnified.shape == (image[view.window].shape[0] * factor, image[view.window].shape[1] * factor)
    if factor % 2:  # ... a view pixel for an odd factor, where the view holds the pixel's own value
        at = np.rint(centres).astype(int)
        np.testing.assert_allclose(magnified[at[:, 0], at[:, 1]], image[rows, cols].ravel(), atol=1e-12)
    mask = image > 0
    block = view.mask(mask)
    assert block.dtype == bool
    np.testing.assert_array_equal(block[::factor, ::factor], mask[view.window])
    np.testing.assert_array_equal(block[factor - 1::factor, factor - 1::factor], mask[view.window])
    assert (r0, c0) == (5, 7)


def test_a_contour_meets_the_view_s_cut_only_where_the_view_cut_the_image():
    view = MagnifiedView.around(np.array([[0.0, 20.0], [20.0, 40.0]]), (100, 100), 10.0, 2)
    assert view.window == (slice(0, 31), slice(10, 51))  # the top side is the image's
    on_top = _circle((3.0, 30.0), 3.5)  # reaches the image's own top side, within the view
    assert not view.reaches_a_cut(on_top)
    assert view.reaches_a_cut(_circle((26.0, 30.0), 4.0))  # the view's bottom, a cut
    assert view.reaches_a_cut(_circle((15.0, 12.0), 2.0))  # its left side, a cut
    assert not view.reaches_a_cut(_circle((15.0, 30.0), 5.0))


@pytest.mark.parametrize("seed", range(4))
def test_a_small_nucleus_drawn_around_beside_its_touching_twin_ends_on_its_own(seed):
    """Two disks of 4 px radius touching, alike, a circle 1.35 times one of
    them. On the image itself the contour took half the other (IoU 0.77-0.85:
    its few-pixel rings and the depth map that parts touching objects, with
    four integer levels, were as large as the nucleus)."""
    centre = (32.3, 30.1)
    image, (own, _) = _disks([centre, (centre[0], centre[1] + 8.0)], 4.0, seed=seed)
    res = segment(image, _circle(centre, 1.35 * 4.0))
    assert res.converged, res.stop_reason
    assert _iou(res.contour, own) >= 0.85


@pytest.mark.parametrize("seed", range(4))
def test_a_small_object_is_found_as_at_twice_its_size(seed):
    """Scale: three touching disks of 7 px radius, and the image halved
    (pixel areas averaged): from the same drawing, halved, the outline is
    the one found at full size, halved. On the halved image itself the
    contour took in a neighbour (agreement 0.58-0.88)."""
    radius = 7.0
    centres = [(40.3, 44.2), (40.3, 44.2 + 2 * radius), (40.0 + 2 * radius, 48.0)]
    large, masks = _disks(centres, radius, shape=(100, 100), noise=0.05, seed=seed)
    small = large.reshape(50, 2, 50, 2).mean(axis=(1, 3))
    drawing = _circle(centres[0], 1.35 * radius)
    at_size = segment(large, drawing).contour
    halved = segment(small, (drawing + 0.5) / 2 - 0.5).contour
    assert _iou((at_size + 0.5) / 2 - 0.5, polygon2mask(small.shape, halved)) >= 0.9
    truth = masks[0].reshape(50, 2, 50, 2).mean(axis=(1, 3)) >= 0.5
    assert _iou(halved, truth) >= 0.85


def test_a_magnified_segmentation_reports_its_steps_and_result_in_the_image_s_frame():
    centre = (30.6, 25.2)
    image, (own,) = _disks([centre], 5.0, shape=(60, 60), noise=0.02)
    run = iter_segment(image, _circle(centre, 7.0))
    steps = []
    try:
        while True:
            steps.append(next(run))
    except StopIteration as done:
        res = done.value
    assert steps and all(np.all((s.contour > -0.5) & (s.contour < 59.5)) for s in steps)
    for contour in [s.contour for s in steps] + list(res.history) + [res.contour]:
        assert np.hypot(*(contour.mean(axis=0) - centre)) < 2.0
    assert _iou(res.contour, own) >= 0.9
    np.testing.assert_allclose(res.history[-1], res.contour)
    assert res.timings["total"] >= res.timings["evolution"]


def test_magnify_false_segments_on_the_image_itself():
    centre = (30.6, 25.2)
    image, _ = _disks([centre], 3.5, shape=(60, 60), noise=0.02)
    drawing = _circle(centre, 5.0)
    plain, magnified = segment(image, drawing, magnify=False), segment(image, drawing)
    # The magnified view's nodes are a view pixel apart: a finer contour.
    assert len(magnified.contour) > len(plain.contour)


def test_a_huge_drawing_around_a_small_object_is_not_magnified_into_a_huge_view(monkeypatch):
    """A box over most of a 1500 x 1500 image around a disk of 4 px radius:
    a view magnified 3 times would hold 20 million pixels (160 MB). (So
    large a drawing says too little about so small an object for the
    contour to find it, magnified or not: only the view's size is asked.
    The contour spreads to the image's sides: it stalled there, and since
    session 59 it is seen to leak on its way.)"""
    made = []
    image_of = MagnifiedView.image

    def recorded(self, image):
        view = image_of(self, image)
        made.append(view.size)
        return view

    monkeypatch.setattr(MagnifiedView, "image", recorded)
    rows, cols = np.ogrid[:1500, :1500]
    disk = (rows - 750.3) ** 2 + (cols - 750.2) ** 2 <= 16.0
    image = ndi.gaussian_filter(disk.astype(float), 1.0) + np.random.default_rng(0).normal(0, 0.02, disk.shape)
    box = np.array([[20.0, 20.0], [20.0, 1480.0], [1480.0, 1480.0], [1480.0, 20.0]])
    res = segment(image, box)
    assert res.stop_reason in ("converged", "stalled", "leaked")
    assert all(size <= MAX_VIEW_PIXELS for size in made)

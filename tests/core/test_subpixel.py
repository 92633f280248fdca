"""subpixel.polish: exact on area-rendered borders, invariant, bounded, noise-aware."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy import ndimage as ndi
from skimage.draw import polygon2mask

from napari_physeg.core.contour import crosses_itself, resample, signed_area
from napari_physeg.core.subpixel import _solve_cyclic_tridiagonal, level_along, polish

CENTRE, RADIUS = (64.3, 63.6), 30.25


def disc_coverage(shape=(128, 128), centre=CENTRE, radius=RADIUS, factor=15):
    """Fraction of each pixel inside the disc (15 x 15 super-sampling)."""
    h, w = shape
    r = (np.arange(h * factor) + 0.5) / factor - 0.5
    c = (np.arange(w * factor) + 0.5) / factor - 0.5
    inside = (r[:, None] - centre[0]) ** 2 + (c[None, :] - centre[1]) ** 2 <= radius**2
    return inside.reshape(h, factor, w, factor).mean(axis=(1, 3))


def circle(radius, n, centre=CENTRE):
    t = 2 * np.pi * np.arange(n) / n
    return np.column_stack([centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)])


@pytest.fixture(scope="module")
def coverage():
    return disc_coverage()


@pytest.mark.parametrize("n", [3, 4, 9, 200])
def test_cyclic_tridiagonal_solve_matches_a_dense_solve(n):
    rng = np.random.default_rng(n)
    diag, off, rhs = 3 + rng.random(n), rng.random(n), rng.random(n)
    A = np.diag(diag)
    for i in range(n):
        A[i, (i + 1) % n] += off[i]
        A[(i + 1) % n, i] += off[i]
    assert np.allclose(_solve_cyclic_tridiagonal(diag, off, rhs), np.linalg.solve(A, rhs), atol=1e-12)


@pytest.mark.parametrize("start", [-0.8, 0.0, 0.7])
def test_a_polygon_is_fitted_to_an_area_rendered_disc(coverage, start):
    """From 0.8 px inside or 0.7 px outside, the nodes land where the polygon
    encloses the disc's area: on the circle plus the chord correction
    ``s**2 / 12R`` (0.028 px here), to 0.01 px."""
    n = 60
    out = polish(0.3 + 0.4 * coverage, circle(RADIUS + start, n))
    radius = np.linalg.norm(out - CENTRE, axis=1)
    s = 2 * np.pi * RADIUS / n
    assert abs(radius.mean() - (RADIUS + s * s / (12 * RADIUS))) < 0.01
    assert radius.std() < 0.015
    assert abs(signed_area(out) / (np.pi * RADIUS**2) - 1) < 5e-4


def test_on_a_wide_ramp_a_known_level_is_found_wherever_the_contour_starts():
    """On a ramp 8 px wide (a blurred nucleus) the half-level read 2.5-4 px
    either side of the nodes moves with them: from 1 px inside and 0.8 px
    outside the 0.75 level the polish ends 1 px apart. Given the border's
    level, the nodes go to its crossing (r = 28) from either side."""
    r = np.hypot(*(np.indices((128, 128)) - np.array(CENTRE)[:, None, None]))
    ramp = 10.0 + 100.0 * np.clip((34.0 - r) / 8.0, 0.0, 1.0)

    def radius(nodes):
        return np.linalg.norm(nodes - CENTRE, axis=1)

    inside, outside = circle(27.0, 80), circle(28.8, 80)
    assert radius(polish(ramp, outside)).mean() - radius(polish(ramp, inside)).mean() > 0.5
    for start in (inside, outside):
        at_level = radius(polish(ramp, start, level=85.0))
        assert abs(at_level.mean() - 28.0) < 0.05 and at_level.std() < 0.05


@pytest.mark.parametrize("traced", [10.5, 11.0, 12.0])
def test_a_line_polished_at_its_own_level_stays_on_itself(traced):
    """A disk of radius 12 blurred by 3 px, traced on its ramp: at the level
    the polish reads along the line (level_along), the polish finds the line
    itself (a result started from again keeps its place), to 0.01 px; at
    the level read on a copy smoothed by 1 px, as the region force reads
    it, it ended 0.04-0.08 px out, and each run added that."""
    centre = (48.3, 47.6)
    image = ndi.gaussian_filter(disc_coverage((96, 96), centre, 12.0), 3.0)
    line = circle(traced, 60, centre=centre)
    found = np.linalg.norm(polish(image, line, level=level_along(image, line)) - centre, axis=1)
    assert abs(found.mean() - traced) < 0.01 and found.std() < 0.01


def test_polish_is_invariant_to_linear_intensity_changes(coverage):
    nodes = circle(RADIUS + 0.4, 50)
    bright = polish(coverage, nodes, polarity=1)
    assert np.allclose(polish(7.0 + 300.0 * coverage, nodes), bright, atol=1e-9)
    assert np.allclose(polish(1.0 - coverage, nodes, polarity=-1), bright, atol=1e-9)


def test_polish_is_translation_equivariant(coverage):
    nodes = circle(RADIUS - 0.5, 50)
    shifted = np.roll(coverage, (5, -3), axis=(0, 1))
    assert np.allclose(polish(shifted, nodes + [5, -3]), polish(coverage, nodes) + [5, -3], atol=1e-9)


def test_no_border_or_the_wrong_polarity_leaves_the_contour_alone(coverage):
    nodes = circle(RADIUS, 40)
    assert np.array_equal(polish(np.full((128, 128), 0.3), nodes), nodes)
    assert np.array_equal(polish(coverage, nodes, polarity=-1), nodes)


def test_no_node_moves_farther_than_reach(coverage):
    nodes = circle(RADIUS + 4.0, 40)
    out = polish(coverage, nodes)
    assert np.linalg.norm(out - nodes, axis=1).max() <= 1.5 + 1e-9


def test_noise_is_averaged_along_the_contour_without_shrinking_it(coverage):
    """Noise 0.2 x the contrast: alone, the nodes scatter by ~0.15 px;
    averaged along the border (over a length set by the estimated noise) 3x
    less, and the circle keeps its radius."""
    rng = np.random.default_rng(0)
    image = 0.3 + 0.4 * coverage + rng.normal(0.0, 0.2 * 0.4, coverage.shape)
    nodes = circle(RADIUS + 0.3, 60) + rng.normal(0.0, 0.15, (60, 2))
    averaged = np.linalg.norm(polish(image, nodes) - CENTRE, axis=1)
    alone = np.linalg.norm(polish(image, nodes, noise=0.0) - CENTRE, axis=1)
    assert np.abs(averaged - averaged.mean()).mean() < 0.5 * np.abs(alone - alone.mean()).mean()
    assert np.abs(averaged - averaged.mean()).mean() < 0.06
    assert abs(averaged.mean() - alone.mean()) < 0.01


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_polish_never_makes_a_simple_contour_cross_itself(seed):
    """A blurred, noisy star polygon and its outline resampled 1-2.5 px
    apart, each node jittered by up to 0.7 px: each node's move along its
    own normal would, in a sharp concave corner, carry an edge across its
    neighbour's (in about 4 of 10 such cases before the moves were
    untangled). The polished contour is simple whenever it was given one,
    and so it is at a given border level, even one the image never reaches."""
    rng = np.random.default_rng(seed)
    k = rng.integers(5, 9)
    angle, radius = np.sort(rng.uniform(0, 2 * np.pi, k)), rng.uniform(6, 18, k)
    star = np.column_stack([32 + radius * np.sin(angle), 32 + radius * np.cos(angle)])
    image = ndi.gaussian_filter(polygon2mask((64, 64), star).astype(float), rng.uniform(0.5, 1.5))
    image += 0.05 * rng.standard_normal(image.shape)
    nodes = resample(star, spacing=rng.uniform(1, 2.5))
    nodes += rng.uniform(-0.7, 0.7, nodes.shape)
    if crosses_itself(nodes):
        return
    for level in (None, rng.uniform(-0.2, 1.2)):
        out = polish(image, nodes, polarity=1, level=level)
        assert not crosses_itself(out)
        assert np.linalg.norm(out - nodes, axis=1).max() <= 1.5 + 1e-9


def test_nodes_on_the_image_side_end_on_it():
    """A disc cut by the image's right side, in noise (so the polish smooths
    along the contour): the nodes on the side (or within a quarter pixel of
    it) end on it, however the smoothing rounds the corners where the
    contour leaves the side, and those away from the corners land on the
    circle."""
    shape, centre, radius = (128, 100), (64.3, 99.5), 30.25
    rng = np.random.default_rng(1)
    image = 0.3 + 0.4 * disc_coverage(shape, centre, radius) + rng.normal(0.0, 0.2 * 0.4, shape)
    side = shape[1] - 0.5
    arc = circle(radius + 0.3, 120, centre)
    arc = arc[arc[:, 1] < side - 1.0]
    # The contour: the arc inside the image, closed along the side.
    ends = np.array([[centre[0] + radius, side], [centre[0] - radius, side]])
    wall = np.column_stack([np.linspace(ends[1, 0], ends[0, 0], 24)[1:-1], np.full(22, side)])
    arc = arc[np.argsort(np.arctan2(arc[:, 1] - centre[1], arc[:, 0] - centre[0]) % (2 * np.pi))]
    nodes = np.concatenate([arc, wall[::-1] if arc[0, 0] > centre[0] else wall])
    on_side = nodes[:, 1] == side
    out = polish(image, nodes)
    assert np.array_equal(out[on_side], nodes[on_side])
    # A node a tenth of a pixel from the side, where the dynamics may leave it, lies on it too.
    near = nodes.copy()
    near[on_side, 1] -= 0.1
    assert np.array_equal(polish(image, near)[on_side], nodes[on_side])
    away = nodes[:, 1] < side - 8.0  # beyond the corners
    assert np.abs(np.linalg.norm(out[away] - centre, axis=1) - radius).mean() < 0.1

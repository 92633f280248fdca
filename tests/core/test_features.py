"""Tests of napari_physeg.core.features (Shen–Castan edges, chamfer distance, intensity)."""

from dataclasses import FrozenInstanceError

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy import ndimage as ndi
from skimage.segmentation import find_boundaries

from napari_physeg.core.features import (
    FeatureImages,
    chamfer_distance,
    compute_features,
    isef_kernel,
    isef_smooth,
    normalized_intensity,
    shen_castan_edges,
)

# --------------------------------------------------------------------------
# helpers


def square_image(n=96, lo=0.0, hi=1.0, start=30, stop=66):
    """A ``hi`` square on a ``lo`` background, and the square's mask."""
    mask = np.zeros((n, n), dtype=bool)
    mask[start:stop, start + 4 : stop + 4] = True
    return np.where(mask, hi, lo).astype(np.float64), mask


def disc_image(n=96, radius=25.0):
    rr, cc = np.mgrid[:n, :n]
    mask = (rr - n / 2 + 0.3) ** 2 + (cc - n / 2 - 0.2) ** 2 < radius**2
    return mask.astype(np.float64), mask


def border_scores(edges, mask):
    """Score edges against the true border of ``mask``.

    The border is the pixels on both sides of the object/background
    boundary (those with a 4-neighbour of the other class); "within 1 px"
    means in the 3x3 neighbourhood of such a pixel (chessboard distance).
    Returns (fraction of edge pixels within 1 px of the border, largest
    chessboard distance of an edge pixel to the border, fraction of border
    pixels with an edge pixel within 1 px).
    """
    border = find_boundaries(mask, connectivity=1, mode="thick")
    assert edges.any(), "no edges found"
    to_border = ndi.distance_transform_cdt(~border, metric="chessboard")
    to_edge = ndi.distance_transform_cdt(~edges, metric="chessboard")
    return (
        float(np.mean(to_border[edges] <= 1)),
        float(to_border[edges].max()),
        float(np.mean(to_edge[border] <= 1)),
    )


def isef_matrix(n, b):
    """The (n, n) matrix of the 1D ISEF on n samples, built independently of
    the recursive code: a kernel truncated where its tail is < 1e-16 applied
    to the half-sample symmetric extension made by ``np.pad``, repeated as
    often as the kernel needs."""
    radius = int(np.ceil(np.log(1e-16) / np.log(b))) + 1
    kernel = isef_kernel(b, radius)
    source = np.pad(np.arange(n), radius, mode="symmetric")  # padded sample -> real sample
    matrix = np.zeros((n, n))
    for i in range(n):
        np.add.at(matrix[i], source[i : i + 2 * radius + 1], kernel)
    return matrix


def direct_isef(image, b):
    rows, cols = image.shape
    return isef_matrix(rows, b) @ image @ isef_matrix(cols, b).T


# --------------------------------------------------------------------------
# ISEF


def test_isef_kernel_values():
    np.testing.assert_allclose(isef_kernel(0.5, 1), [1 / 6, 1 / 3, 1 / 6])
    k = isef_kernel(0.9, 400)
    assert k.shape == (801,)
    assert k.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_array_equal(k, k[::-1])
    assert np.argmax(k) == 400


@pytest.mark.parametrize("shape", [(1, 9), (6, 4), (37, 23), (50, 80)])
@pytest.mark.parametrize("b", [0.2, 0.5, 0.9, 0.97])
def test_isef_recursive_equals_direct_convolution(shape, b):
    rng = np.random.default_rng(hash(shape) % 2**32)
    image = rng.normal(size=shape) * 10 + 3
    got = isef_smooth(image, b)
    assert got.dtype == np.float64 and got.shape == shape
    np.testing.assert_allclose(got, direct_isef(image, b), rtol=0, atol=1e-10)


def test_isef_accepts_integer_images_and_preserves_constants():
    img = np.full((5, 7), 200, dtype=np.uint8)
    np.testing.assert_allclose(isef_smooth(img), 200.0, rtol=1e-13)


@pytest.mark.parametrize("b", [0, 1, -0.5, 1.5, np.nan, "0.9", True])
def test_isef_rejects_bad_b(b):
    with pytest.raises(ValueError, match="b must"):
        isef_smooth(np.zeros((4, 4)), b)
    with pytest.raises(ValueError, match="b must"):
        isef_kernel(b, 3)


small_images = arrays(
    np.float64,
    st.tuples(st.integers(1, 12), st.integers(1, 12)),
    elements=st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False),
)
b_values = st.floats(0.05, 0.95)


@settings(max_examples=60, deadline=None)
@given(x=small_images, b=b_values, a=st.floats(-10, 10), seed=st.integers(0, 2**16))
def test_isef_properties(x, b, a, seed):
    y = np.random.default_rng(seed).uniform(-1e3, 1e3, size=x.shape)
    sx = isef_smooth(x, b)
    assert np.all(np.isfinite(sx))
    tol = 1e-9 * (1 + np.abs(x).max() + np.abs(y).max()) * (1 + abs(a))
    # Linear.
    np.testing.assert_allclose(
        isef_smooth(a * x + y, b), a * sx + isef_smooth(y, b), atol=tol, rtol=0
    )
    # Mean preserving (the symmetric extension makes every column of the
    # filter matrix sum to 1), and constants are fixed points.
    assert sx.mean() == pytest.approx(x.mean(), abs=tol)
    c = np.full(x.shape, x.flat[0])
    np.testing.assert_allclose(isef_smooth(c, b), c, atol=tol, rtol=0)
    # A weighted mean with positive weights stays within the data's range.
    assert sx.min() >= x.min() - tol and sx.max() <= x.max() + tol


# --------------------------------------------------------------------------
# Shen–Castan edges


@pytest.mark.parametrize(
    "make",
    [
        lambda: square_image(lo=0.0, hi=1.0),
        lambda: square_image(lo=1.0, hi=0.0),  # dark square on bright background
        lambda: disc_image(),
    ],
    ids=["bright-square", "dark-square", "disc"],
)
@pytest.mark.parametrize("sigma", [0.0, 0.1])
def test_edges_lie_on_the_border(make, sigma):
    image, mask = make()
    image = image + sigma * np.random.default_rng(0).normal(size=image.shape)
    edges = shen_castan_edges(image)
    assert edges.dtype == bool and edges.shape == image.shape
    precision, worst, coverage = border_scores(edges, mask)
    assert precision == 1.0, f"edge pixel {worst} px from the border"
    assert coverage >= 0.9


def test_marked_pixel_is_on_the_bright_side():
    image, mask = square_image(lo=0.0, hi=1.0)
    edges = shen_castan_edges(image)
    assert mask[edges].all()  # bright object: its outermost pixels
    edges = shen_castan_edges(1.0 - image)
    assert not mask[edges].any()  # dark object: the background around it
    # ...one pixel outside.
    assert (ndi.distance_transform_edt(~mask)[edges] <= 1.5).all()


@pytest.mark.parametrize("sigma", [0.1, 0.2])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_edges_robust_to_noise_on_a_small_object(sigma, seed):
    """A small disc in a large frame: noise crossings outnumber its border
    pixels ~100 to 1, and those on the flanks of its smoothed edge have a
    sizeable adaptive gradient."""
    rng = np.random.default_rng(seed)
    image, mask = disc_image(n=256, radius=20.0)
    edges = shen_castan_edges(image + sigma * rng.normal(size=image.shape))
    precision, worst, coverage = border_scores(edges, mask)
    if sigma <= 0.1:
        assert precision == 1.0, f"edge pixel {worst} px from the border"
    else:
        assert precision >= 0.98 and worst <= 3
    assert coverage >= 0.95


@pytest.mark.parametrize("sigma", [0.0, 0.02])
def test_weak_side_of_a_border_is_kept(sigma):
    """A bright square on a background ramping up to nearly its level: the
    right side's contrast is 0.15, the left side's 1. The weak side is
    connected to the strong one and above the noise, so it is kept."""
    mask = np.zeros((96, 96), dtype=bool)
    mask[28:68, 28:68] = True
    background = 0.85 * np.mgrid[:96, :96][1] / 95
    image = np.where(mask, 1.0, background)
    image = image + sigma * np.random.default_rng(0).normal(size=image.shape)
    precision, _, coverage = border_scores(shen_castan_edges(image), mask)
    assert precision == 1.0 and coverage >= 0.95


@pytest.mark.parametrize("seed", [0, 1])
def test_thin_protrusion_is_kept(seed):
    """A 6 px wide thumb on a disc: the ISEF flattens it, so its edges are
    several times weaker than the disc's, yet part of the border."""
    rr, cc = np.mgrid[:128, :128]
    mask = (rr - 80) ** 2 + (cc - 64) ** 2 < 25**2
    mask[20:70, 40:46] = True
    image = mask + 0.1 * np.random.default_rng(seed).normal(size=mask.shape)
    precision, _, coverage = border_scores(shen_castan_edges(image), mask)
    assert precision == 1.0 and coverage >= 0.9


@pytest.mark.parametrize("b", [0.5, 0.9])
@pytest.mark.parametrize("window", [3, 7])
def test_pure_noise_has_no_edges(b, window):
    noise = np.random.default_rng(1).normal(size=(128, 128))
    assert not shen_castan_edges(noise, b=b, window=window).any()
    assert not shen_castan_edges(1e-9 * noise + 5.0, b=b, window=window).any()


def test_a_given_noise_level_sets_the_floor():
    """The noise measured beforehand (as segment() does, once for the edges
    and the region model) gives the edges the detector finds measuring it
    itself; a level far above the image's raises the floor over its border."""
    from napari_physeg.core.features import _noise_sigma

    image, _ = square_image()
    image = image + np.random.default_rng(2).normal(0.0, 0.1, image.shape)
    found = shen_castan_edges(image)
    assert found.any()
    assert np.array_equal(shen_castan_edges(image, noise=_noise_sigma(image)), found)
    assert not shen_castan_edges(image, noise=100.0).any()


@pytest.mark.parametrize("step", [1, 16])
def test_rounding_to_levels_is_noise_of_a_step_over_root_12(step):
    """An image rounded to levels ``step`` apart carries a rounding noise of
    step / sqrt(12) (as a uniform error over one step); one whose levels run
    on carries none."""
    from napari_physeg.core.features import _rounding_sigma

    rng = np.random.default_rng(0)
    smooth = rng.normal(100.0, 3.0, (300, 300))
    assert _rounding_sigma(step * np.round(smooth / step)) == pytest.approx(step / np.sqrt(12))
    assert _rounding_sigma(smooth) < 1e-3
    assert _rounding_sigma(np.full((20, 20), 7.0)) == 0.0


@pytest.mark.parametrize("value", [0.0, 3.3, -7, 1e9])
def test_constant_image_has_no_edges(value):
    edges, strength = shen_castan_edges(np.full((40, 50), value), return_strength=True)
    assert not edges.any()
    assert np.all(strength == 0)


def test_edges_invariant_to_scale_and_offset():
    image, _ = square_image()
    image = image + 0.1 * np.random.default_rng(4).normal(size=image.shape)
    ref = shen_castan_edges(image)
    other = shen_castan_edges(1000.0 * image - 250.0)
    assert np.count_nonzero(ref ^ other) <= 0.01 * ref.sum()


def test_edges_independent_of_memory_layout_and_flip_equivariant():
    image, _ = square_image()
    image = image + 0.1 * np.random.default_rng(9).normal(size=image.shape)
    ref = shen_castan_edges(image)
    np.testing.assert_array_equal(shen_castan_edges(np.asfortranarray(image)), ref)
    np.testing.assert_array_equal(shen_castan_edges(image[::-1, ::-1])[::-1, ::-1], ref)
    np.testing.assert_array_equal(
        compute_features(np.asfortranarray(image)).edges, compute_features(image).edges
    )


@pytest.mark.parametrize("window", [3, 7, 17, 31])
def test_strength_is_the_adaptive_gradient(window):
    """At every candidate, |mean of smoothed over BLI=1 - mean over BLI=0| in
    the window (half-sample symmetric extension at the image border),
    computed here pixel by pixel. Windows from 17 hold over 255 pixels."""
    image, _ = disc_image(n=40, radius=12.0)
    image = image + 0.2 * np.random.default_rng(10).normal(size=image.shape)
    _, strength = shen_castan_edges(image, window=window, return_strength=True)
    smoothed = isef_smooth(image)
    bli = smoothed > image
    half = window // 2
    s_pad = np.pad(smoothed, half, mode="symmetric")
    bli_pad = np.pad(bli, half, mode="symmetric")
    rows, cols = np.nonzero(strength)
    assert len(rows) > 50
    for r, c in zip(rows, cols):
        s_win = s_pad[r : r + window, c : c + window]
        b_win = bli_pad[r : r + window, c : c + window]
        expected = abs(s_win[b_win].mean() - s_win[~b_win].mean())
        assert strength[r, c] == pytest.approx(expected, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("window", [3, 15, 17, 31])
def test_edges_with_any_window(window):
    """Windows of 17 and more hold over 255 pixels (the count's dtype changes)."""
    image, mask = square_image()
    assert border_scores(shen_castan_edges(image, window=window), mask)[0] == 1.0


def test_strength_is_zero_off_candidates_and_positive_on_edges():
    image, _ = disc_image()
    edges, strength = shen_castan_edges(image, return_strength=True)
    assert strength.dtype == np.float64 and np.all(strength >= 0)
    assert np.all(strength[edges] > 0)
    assert np.count_nonzero(strength) < 0.2 * strength.size  # only candidates
    # A step of contrast 1 has an adaptive gradient well above 0.1 (b = 0.9).
    assert np.median(strength[edges]) > 0.1


def test_min_length_drops_short_chains():
    image, _ = square_image(n=64, start=20, stop=24)  # a 4x4 square: 12-pixel border
    assert shen_castan_edges(image, min_length=12).any()
    assert not shen_castan_edges(image, min_length=13).any()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"window": 4}, "window"),
        ({"window": 1}, "window"),
        ({"window": 7.0}, "window"),
        ({"high_quantile": 0}, "high_quantile"),
        ({"high_quantile": 1.5}, "high_quantile"),
        ({"low_ratio": 0}, "low_ratio"),
        ({"min_length": 0}, "min_length"),
        ({"b": 1.0}, "b must"),
    ],
)
def test_edge_parameters_are_validated(kwargs, match):
    with pytest.raises(ValueError, match=match):
        shen_castan_edges(np.zeros((8, 8)), **kwargs)
    with pytest.raises(ValueError, match=match):
        compute_features(np.zeros((8, 8)), **kwargs)


@pytest.mark.parametrize("noise", [-0.1, np.nan, np.inf, "0.1", True])
def test_a_bad_noise_level_is_refused(noise):
    with pytest.raises(ValueError, match="noise must be a finite non-negative number"):
        shen_castan_edges(np.zeros((8, 8)), noise=noise)


# --------------------------------------------------------------------------
# chamfer distance


@pytest.mark.parametrize("density", [0.001, 0.02])
def test_chamfer_close_to_euclidean(density):
    edges = np.random.default_rng(5).random((90, 120)) < density
    edges[45, 60] = True
    got = chamfer_distance(edges)
    exact = ndi.distance_transform_edt(~edges)
    assert got.dtype == np.float64
    assert np.all(got[edges] == 0)
    off = ~edges
    # The 5x5 chamfer metric is within ~2 % of the Euclidean distance.
    np.testing.assert_array_less(np.abs(got[off] - exact[off]), 0.025 * exact[off])


def test_chamfer_accepts_float_edge_maps():
    edges = np.zeros((20, 30))
    edges[10, 15] = 1.0
    np.testing.assert_array_equal(chamfer_distance(edges), chamfer_distance(edges > 0))


def test_chamfer_without_edges_is_finite():
    got = chamfer_distance(np.zeros((30, 40), dtype=bool))
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, 50.0)  # the image diagonal


# --------------------------------------------------------------------------
# normalised intensity


def _picture(outliers=True):
    """An 8-bit picture: a ramp, a square, noise and a hot and a dead pixel."""
    rr, cc = np.mgrid[:200, :300]
    pic = 40 + 0.2 * cc + 0.1 * rr
    pic[60:140, 100:200] += 60
    pic += np.random.default_rng(6).normal(0, 4, size=pic.shape)
    pic = np.clip(np.round(pic), 0, 255).astype(np.uint8)
    if outliers:
        pic[5, 5], pic[7, 9] = 255, 0
    return pic


def test_normalized_intensity_same_for_all_dtypes():
    pic = _picture()
    ref = normalized_intensity(pic)
    assert ref.dtype == np.float64 and ref.min() == 0.0 and ref.max() == 1.0
    for version in (pic.astype(np.uint16) * 257, pic / 255.0, pic.astype(np.float32) - 1000):
        np.testing.assert_allclose(normalized_intensity(version), ref, atol=1e-6)


def test_normalized_intensity_is_robust_to_outliers():
    with_outliers = normalized_intensity(_picture())
    clean = normalized_intensity(_picture(outliers=False))
    # Two extreme pixels barely move the 1st and 99th percentiles...
    others = np.ones(clean.shape, dtype=bool)
    others[5, 5] = others[7, 9] = False
    np.testing.assert_allclose(with_outliers[others], clean[others], atol=0.02)
    # ...while a plain min-max would squeeze the picture into ~half the range.
    assert np.mean(with_outliers > 0.5) > 0.2
    assert np.mean(with_outliers == 1.0) < 0.05 and np.mean(with_outliers == 0.0) < 0.05


def test_normalized_intensity_constant_and_small_spot():
    np.testing.assert_array_equal(normalized_intensity(np.full((10, 12), 7.5)), 0.0)
    spot = np.zeros((100, 100), dtype=np.uint16)
    spot[50:52, 50:52] = 1000  # 0.04 % of the pixels: p1 == p99
    out = normalized_intensity(spot)
    assert out.max() == 1.0 and out[50, 50] == 1.0 and out[0, 0] == 0.0


def sparse_spots(bright=True, n_spots=4, radius=3.5, seed=0):
    """Small blurred spots (0.8 over a 0.1 background, noise 0.03) covering
    about a quarter of a percent of a 256 px field; their centres."""
    rng = np.random.default_rng(seed)
    centres = [(60.3, 70.2), (150.7, 180.1), (200.2, 40.6), (100.5, 200.4)][:n_spots]
    rows, cols = np.mgrid[:256, :256]
    image = np.zeros((256, 256))
    for c in centres:
        image[np.hypot(rows - c[0], cols - c[1]) <= radius] = 0.7
    image = ndi.gaussian_filter(image, 1.0) + 0.1 + rng.normal(0, 0.03, image.shape)
    return (image if bright else 1.0 - image), centres


@pytest.mark.parametrize("bright", [True, False])
def test_normalized_intensity_keeps_the_spots_of_a_sparse_field_unclipped(bright):
    """The 99th percentile of a field where spots cover a quarter of a
    percent lies in the background's noise: clipped there, the spots were
    flat plateaus from their blurred rim inwards (0.2 of their own contrast
    up), and the contour ended on the rim's foot. The range now reaches the
    spots: their centres stand above their rims, the ground stays near 0."""
    image, centres = sparse_spots(bright)
    out = normalized_intensity(image)
    level = out if bright else 1.0 - out
    for r, c in np.round(centres).astype(int):
        assert level[r, c] > 0.8 and level[r, c] - level[r, c + 4] > 0.4
    assert np.median(level) < 0.15


def test_normalized_intensity_of_a_crowded_field_is_that_of_its_percentiles():
    """Spots over more than 1 % of the field set the 99th percentile
    themselves: the range is the percentiles', as it always was."""
    image, _ = sparse_spots()
    rows, cols = np.mgrid[:256, :256]
    image[(rows % 24 < 8) & (cols % 24 < 8)] += 0.7  # 11 % of the field
    lo, hi = np.percentile(image[::2, ::2], [1, 99])
    np.testing.assert_allclose(normalized_intensity(image), np.clip((image - lo) / (hi - lo), 0, 1))


# --------------------------------------------------------------------------
# compute_features


def test_compute_features_outputs():
    image, mask = square_image(lo=20, hi=200)
    feats = compute_features(image.astype(np.uint8))
    assert isinstance(feats, FeatureImages)
    for name in ("edges", "distance", "intensity", "smoothed"):
        arr = getattr(feats, name)
        assert arr.dtype == np.float64 and arr.shape == image.shape, name
        assert np.all(np.isfinite(arr)), name
        assert not arr.flags.writeable, name
    assert set(np.unique(feats.edges)) == {0.0, 1.0}
    assert feats.has_edges and feats.shape == image.shape
    np.testing.assert_array_equal(feats.distance, chamfer_distance(feats.edges))
    for name in ("intensity", "smoothed"):
        arr = getattr(feats, name)
        assert arr.min() >= 0.0 and arr.max() <= 1.0
    assert feats.intensity.min() == 0.0 and feats.intensity.max() == 1.0
    # Smoothing keeps the object brighter than the background.
    assert feats.intensity[mask].mean() > feats.intensity[~mask].mean() + 0.3
    assert border_scores(feats.edges > 0, mask)[0] == 1.0
    with pytest.raises(FrozenInstanceError):
        feats.edges = feats.distance


@pytest.mark.parametrize("dtype", [np.uint8, np.float32, np.float64])
def test_compute_features_is_the_composition_of_the_public_functions(dtype):
    """compute_features shares buffers between steps; it must still equal
    the plain composition of the building blocks."""
    image, _ = disc_image()
    image = (image * 150 + 50 + 20 * np.random.default_rng(8).normal(size=image.shape))
    image = np.clip(image, 0, 255).astype(dtype)
    before = image.copy()
    feats = compute_features(image, b=0.8, window=5)
    np.testing.assert_array_equal(image, before)  # input untouched
    norm = normalized_intensity(image)
    smoothed = np.clip(isef_smooth(norm, 0.8), 0, 1)
    edges = shen_castan_edges(norm, b=0.8, window=5)
    np.testing.assert_array_equal(feats.smoothed, smoothed)
    np.testing.assert_array_equal(feats.edges, edges)
    np.testing.assert_array_equal(feats.distance, chamfer_distance(edges))
    np.testing.assert_array_equal(feats.intensity, normalized_intensity(smoothed))


def test_compute_features_dtype_invariant():
    image, _ = square_image()
    noise = 0.05 * np.random.default_rng(7).normal(size=image.shape)
    noisy = np.clip(image * 0.6 + 0.2 + noise, 0, 1)
    as_u8 = np.round(noisy * 255).astype(np.uint8)
    a = compute_features(as_u8)
    b = compute_features(as_u8.astype(np.uint16) * 257)
    c = compute_features(as_u8 / 255.0)
    for other in (b, c):
        np.testing.assert_allclose(other.intensity, a.intensity, atol=1e-9)
        assert np.count_nonzero(other.edges != a.edges) <= 0.01 * a.edges.sum()


def test_compute_features_constant_image():
    feats = compute_features(np.full((30, 40), 12, dtype=np.uint16))
    assert not feats.has_edges
    for name in ("edges", "distance", "intensity", "smoothed"):
        assert np.all(np.isfinite(getattr(feats, name))), name
    np.testing.assert_allclose(feats.distance, 50.0)
    np.testing.assert_array_equal(feats.intensity, 0.0)


def test_compute_features_accepts_bool_and_minimal_images():
    image, mask = square_image()
    feats = compute_features(mask)
    assert border_scores(feats.edges > 0, mask)[0] == 1.0
    compute_features(np.arange(9.0).reshape(3, 3))


@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((20, 30, 3)), r"looks like an RGB image.*rgb2gray.*stain.*rgb2hed"),
        (np.zeros((20, 30, 4), dtype=np.uint8), r"RGBA image.*one\s+channel.*rgb2hed\(image\[\.\.\., :3\]\)"),
        (np.zeros((5, 20, 30)), r"3D stack.*single 2D slice"),
        (np.zeros((20, 30, 1)), r"one channel, last; pass image\[\.\.\., 0\]"),
        (np.zeros(30), r"2D"),
        (np.zeros((2, 3, 4, 5)), r"2D"),
        (np.zeros((0, 10)), r"empty"),
        (np.zeros((2, 10)), r"too small.*3x3"),
        (np.zeros((10, 10), dtype=complex), r"complex"),
        (np.array([["a", "b"], ["c", "d"]]), r"numeric"),
        (np.zeros((10, 10), dtype=object), r"numeric"),
    ],
    ids=["rgb", "rgba", "stack", "channel-last", "1d", "4d", "empty", "tiny", "complex", "str", "object"],
)
def test_compute_features_rejects_bad_images(image, match):
    with pytest.raises(ValueError, match=match):
        compute_features(image)


@pytest.mark.parametrize(
    "bad, match",
    [(np.nan, r"NaN pixels.*nan_to_num"), (np.inf, r"infinite"), (-np.inf, r"infinite")],
)
def test_compute_features_rejects_non_finite(bad, match):
    image = np.ones((10, 10))
    image[3, 4] = bad
    with pytest.raises(ValueError, match=match):
        compute_features(image)


@pytest.mark.parametrize("blur", [0.5, 1.0, 2.0])
def test_spikes_are_taken_out_and_blurred_spots_kept(blur):
    """A hot and a dead pixel (a camera's) are replaced by their neighbours'
    median; the peak of a spot blurred by even half a pixel, which an optical
    image cannot be sharper than, is kept, as is every other pixel."""
    from napari_physeg.core.features import _without_spikes

    rng = np.random.default_rng(1)
    image = 100.0 + rng.normal(0.0, 2.0, (64, 64))
    rr, cc = np.mgrid[:64, :64]
    for centre in ((20.0, 20.0), (40.0, 40.5)):  # on a pixel, and between two
        image += 400.0 * np.exp(-((rr - centre[0]) ** 2 + (cc - centre[1]) ** 2) / (2 * blur**2))
    clean = image.copy()
    image[10, 50], image[50, 10] = 60000.0, 0.0
    out = _without_spikes(image)
    changed = np.argwhere(out != image)
    assert {tuple(p) for p in changed} == {(10, 50), (50, 10)}
    assert abs(out[10, 50] - np.median(clean[9:12, 49:52])) < 10 and abs(out[50, 10] - 100.0) < 10
    assert _without_spikes(clean) is clean

"""Fuzzing segment() on a blob with drawings made inside, around and across it.

Whatever the drawing, the outcome is either a result whose stop reason is
honest (never ``converged`` for a contour that did not reach the object) or a
documented error (ValueError or DivergenceError): never an exception from
deep inside numpy or scipy.
"""

import os
import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings, strategies as st
from scipy import ndimage as ndi
from skimage.draw import polygon2mask

from napari_physeg.core import segment
from napari_physeg.core.dynamics import DivergenceError

SHAPE = (96, 96)
CENTRE = np.array([48.0, 48.0])
RADIUS = 18.0


def _blob(dtype, bright: bool, noise: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rr, cc = np.mgrid[: SHAPE[0], : SHAPE[1]]
    mask = (rr - CENTRE[0]) ** 2 + (cc - CENTRE[1]) ** 2 <= RADIUS**2
    image = np.where(mask, 0.8, 0.2) if bright else np.where(mask, 0.2, 0.8)
    image = image + np.random.default_rng(seed).normal(0, noise, SHAPE)
    if np.issubdtype(dtype, np.integer):
        image = np.clip(image * 200, 0, 255)
    return image.astype(dtype), mask


@st.composite
def drawings(draw):
    """Star-shaped polygons (smooth or spiky, few or hundreds of vertices) inside,
    around or across the blob, some reaching beyond the image."""
    n = draw(st.integers(5, 300))
    scale = draw(st.floats(0.3, 1.8))
    spikiness = draw(st.floats(0.0, 0.4))
    shift = np.array([draw(st.floats(-25, 25)), draw(st.floats(-25, 25))])
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, n)) if n > 12 else np.linspace(0, 2 * np.pi, n, endpoint=False)
    t = np.unique(t)
    radius = RADIUS * scale * (1 + spikiness * rng.uniform(-1, 1, len(t)))
    return CENTRE + shift + np.column_stack([radius * np.sin(t), radius * np.cos(t)])


def _iou(contour, mask):
    region = polygon2mask(mask.shape, contour)
    return (region & mask).sum() / max((region | mask).sum(), 1)


# Found by this test (session 8): a star drawn off the blob's centre, its line and
# centre both on the background, was read as drawn inside the background; the
# contour "converged" on the image's side (IoU 0).
OFF_CENTRE_STAR = np.array([
    [48.59, 98.35], [50.89, 91.69], [52.81, 86.44], [54.48, 88.60], [63.58, 71.86], [67.24, 61.60],
    [39.76, 34.68], [29.38, 40.50], [25.76, 44.87], [23.56, 60.83], [11.23, 59.27], [14.13, 78.22],
    [19.84, 76.37], [24.54, 82.77], [31.94, 90.30], [38.18, 86.72]])


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(init=drawings(), dtype=st.sampled_from([np.uint8, np.uint16, np.float32, np.float64]),
       bright=st.booleans(), noise=st.floats(0.0, 0.1), seed=st.integers(0, 100))
@example(init=OFF_CENTRE_STAR, dtype=np.uint8, bright=False, noise=0.0625, seed=0)
def test_segment_is_honest_or_raises_a_documented_error(init, dtype, bright, noise, seed):
    image, mask = _blob(dtype, bright, noise, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # nodes clipped to the image
        try:
            res = segment(image, init, max_steps=400)
        except (ValueError, DivergenceError) as err:
            assert str(err)  # a message that names the problem
            return
    assert np.all(np.isfinite(res.contour))
    assert res.stop_reason in ("converged", "limited", "stalled", "leaked", "oscillating", "max_steps")
    # A drawing that covers the object must not "converge" elsewhere. (Drawings
    # mostly off the object can still end converged on a part of it: open, issue 9.)
    covers_object = polygon2mask(mask.shape, init)[mask].mean() > 0.5
    if res.converged and covers_object:
        assert _iou(res.contour, mask) >= 0.5, res.stop_reason


@pytest.mark.parametrize("bright", [True, False], ids=["bright disk", "dark disk"])
@pytest.mark.parametrize("centre, radius", [((48, 62), 9), ((36, 56), 8), ((60, 40), 10)])
def test_a_drawing_across_the_object_s_edge_finds_the_whole_object(centre, radius, bright):
    """A small circle mostly on the disk, over its edge, holding a fifth of it:
    read as drawn around an object (its line lies partly on the background),
    its limit cut the disk there and the contour "converged" on that part (IoU
    0.25-0.30, found by fuzzing in session 28). It holds too little of one
    convex body to go around it: the body is the object."""
    image, mask = _blob(np.float64, bright, 0.05, 0)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    res = segment(image, np.column_stack([centre[0] + radius * np.sin(t), centre[1] + radius * np.cos(t)]))
    assert res.converged and _iou(res.contour, mask) > 0.95


@settings(max_examples=15, deadline=None)
@given(size=st.integers(3, 6), seed=st.integers(0, 100))
def test_tiny_images_never_leak_scipy_errors(size, seed):
    image = np.random.default_rng(seed).random((size, size))
    init = np.array([[0.5, 0.5], [0.5, size - 1.5], [size - 1.5, size - 1.5], [size - 1.5, 0.5]])
    try:
        res = segment(image, init, max_steps=100)
    except (ValueError, DivergenceError) as err:
        assert str(err)
        return
    assert np.all(np.isfinite(res.contour))


@settings(max_examples=int(os.environ.get("NAN_FUZZ_EXAMPLES", 30)), deadline=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(init=drawings(), bright=st.booleans(), seed=st.integers(0, 100),
       box=st.tuples(*[st.integers(0, SHAPE[0])] * 4), scattered=st.floats(0.0, 0.3))
def test_nan_pixels_are_kept_out_of_the_contour_or_a_documented_error(init, bright, seed, box, scattered):
    """A NaN block anywhere (a registration's margin, a masked region; all
    of the image, even) and NaN pixels scattered at random: a result whose
    region holds none of them and whose stop reason is honest, or a
    documented error; never a scipy or numpy exception, nor a NaN node."""
    image, mask = _blob(np.float64, bright, 0.05, seed)
    r0, r1, c0, c1 = min(box[:2]), max(box[:2]), min(box[2:]), max(box[2:])
    image[r0:r1, c0:c1] = np.nan
    image[np.random.default_rng(seed).random(SHAPE) < scattered] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # NaN read as no data; nodes clipped to the image
        try:
            res = segment(image, init, max_steps=400)
        except (ValueError, DivergenceError) as err:
            assert str(err)
            return
    assert np.all(np.isfinite(res.contour))
    assert res.stop_reason in ("converged", "limited", "stalled", "leaked", "oscillating", "max_steps")
    # Out of the block, but for the rounding of the polygon's rim. A smooth
    # body whose nodes lie ~2 px apart does not follow the notch a narrower
    # block makes in the object (a 3-px strip poking 11 px into the blob:
    # one pixel in), nor go round each scattered pixel: those fuzz the
    # reading only. (Nor is a contour that did not come to rest on a border,
    # one that spread over the image or wandered on it, drawn round a block.)
    if min(r1 - r0, c1 - c0) >= 6 and res.converged:
        block = np.zeros(SHAPE, bool)
        block[r0:r1, c0:c1] = True
        inner = ndi.binary_erosion(polygon2mask(SHAPE, res.contour), iterations=2)
        assert not (inner & block).any()


@settings(max_examples=40, deadline=None)
@given(radius=st.floats(8, 24), aspect=st.floats(1.0, 1.8), blur_share=st.floats(0.05, 0.3),
       noise=st.floats(0.0, 0.08), bright=st.booleans(), scale=st.floats(1.15, 1.6), seed=st.integers(0, 2**16))
def test_a_result_started_from_again_stays_where_it_settled(radius, aspect, blur_share, noise, bright, scale, seed):
    """Pressing Segment again and again on a result leaves it where it
    settled, however blurred the object's edge. The result of a circle
    around a blurred ellipse, started from again, may move once (a rough
    drawing's reading and a traced line's differ: a dark ellipse blurred by
    its own half-width went 283, 240 px, the ellipse 205); from there two
    more runs keep 0.95 of it and its area within 4 %. (On blurred edges
    each run used to end a little further out: a disk of radius 12 blurred
    by 4 px, traced at half its height, 11.65, 12.19, 12.59, 12.89 px.) The
    blur is up to 0.3 of the ellipse's half-width (1 failure in 300 random
    draws: a tiny ellipse settling toward its truth over three runs):
    blurred more, results swing between readings (a known residual,
    docs/benchmarks.md, session 46)."""
    blur = max(0.5, blur_share * radius / aspect)
    rng = np.random.default_rng(seed)
    rr, cc = np.mgrid[: SHAPE[0], : SHAPE[1]]
    ellipse = ((rr - CENTRE[0]) / radius) ** 2 + ((cc - CENTRE[1]) / (radius / aspect)) ** 2 <= 1
    image = ndi.gaussian_filter(np.where(ellipse, 0.8, 0.2) if bright else np.where(ellipse, 0.2, 0.8), blur)
    image += rng.normal(0, noise, SHAPE)
    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    start = CENTRE + rng.uniform(-2, 2, 2) + scale * radius * np.column_stack([np.sin(t), np.cos(t)])
    first = segment(image, start)
    if not first.converged:
        return
    again = segment(image, first.contour).contour
    contour = again
    for _ in range(2):
        contour = segment(image, contour).contour
    held = polygon2mask(SHAPE, again)
    assert _iou(contour, held) >= 0.95
    assert abs(polygon2mask(SHAPE, contour).sum() / held.sum() - 1) < 0.04


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(init=drawings(), repeats=st.lists(st.integers(0, 10_000), min_size=0, max_size=4), closed=st.booleans())
def test_a_drawings_exact_repeats_change_nothing(init, repeats, closed):
    """Nodes repeated in a row (a mouse that paused) and the first repeated at
    the end (a ring as find_contours writes it) are taken once: the same
    result, or the same error, as the drawing with each node once."""
    image, _ = _blob(np.float64, True, 0.05, 0)
    repeated = init
    for i in sorted({r % len(init) for r in repeats}, reverse=True):
        repeated = np.insert(repeated, i, repeated[i], axis=0)
    if closed:
        repeated = np.vstack([repeated, repeated[:1]])

    def outcome(drawing):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # nodes clipped to the image
            try:
                res = segment(image, drawing, max_steps=60)
            except (ValueError, DivergenceError) as err:
                return type(err), re.sub(r"\d+", "#", str(err))  # (node numbers shift with the repeats)
        return res.stop_reason, res.contour.tobytes()

    assert outcome(repeated) == outcome(init)

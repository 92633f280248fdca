"""Matching that holds on articulated change and node noise (issue 12): the
inner-distance shape context, the search over every start, and the
benchmark's articulated families."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from napari_physeg import data
from napari_physeg.core import match
from napari_physeg.core.inner_distance import inner_distance_context, inner_distances
from napari_physeg.core.matching import _iter_every_start, _search
from napari_physeg.core._drain import drain


def _benchmark_data():
    path = Path(__file__).resolve().parents[2] / "benchmarks" / "matching_data.py"
    spec = importlib.util.spec_from_file_location("matching_data", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def within(partner, truth, nb, tol=1):
    d = np.abs(np.asarray(partner) - np.asarray(truth)) % nb
    d = np.minimum(d, nb - d)
    return float(np.mean((np.asarray(partner) >= 0) & (d <= tol)))


# --------------------------------------------------------------------------
# Inner distances: known answers
# --------------------------------------------------------------------------


def test_inner_distance_of_a_convex_polygon_is_the_euclidean_distance():
    t = 2 * np.pi * np.arange(40) / 40
    ellipse = np.column_stack([30 * np.cos(t), 12 * np.sin(t)])
    D, first = inner_distances(ellipse)
    euclid = np.linalg.norm(ellipse[:, None] - ellipse[None], axis=2)
    assert np.allclose(D, euclid)
    assert np.array_equal(first, np.broadcast_to(np.arange(40), (40, 40)))  # every vertex sees every other


def test_inner_distance_goes_round_the_inner_corner_of_a_u():
    # A U: two prongs 10 wide and 30 tall on a base 10 tall, a gap 10 wide between them.
    u = np.array([[0, 0], [0, 30], [40, 30], [40, 20], [10, 20], [10, 10], [40, 10], [40, 0]], dtype=float)
    D, first = inner_distances(u)
    # Tip of one prong (40, 30) to the tip of the other (40, 0): round the inner
    # corners (10, 20) and (10, 10), not straight across the gap (30).
    expected = np.hypot(30, 10) + 10 + np.hypot(30, 10)
    assert D[2, 7] == pytest.approx(expected)
    assert first[2, 7] == 4  # the path leaves the tip toward the inner corner
    assert D[2, 7] > np.hypot(0, 30) + 1


def test_shape_context_is_invariant_to_translation_rotation_and_scale():
    a = data.hand_outline("open", n_nodes=150)
    th = np.deg2rad(37.0)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    moved = (a - a.mean(0)) @ R.T * 3.7 + np.array([1e6, -2e5])
    # sqrt of the histograms: a bin weight of 1e-12 against 0 is a difference of 1e-6.
    assert np.allclose(inner_distance_context(a), inner_distance_context(moved), atol=1e-4)


def test_shape_context_barely_changes_when_fingers_turn():
    """The articulated hands: fingers turned about their joints. The context of
    each node changes much less than an ordinary (Euclidean) shape context would
    change: compare with the change between unrelated nodes."""
    a, b, truth = data.hand_pair(200, 200, pose_a="spread", pose_b="closed")
    ha, hb = inner_distance_context(a, 200), inner_distance_context(b, 200)
    same = np.sum((ha - hb[truth]) ** 2, axis=1)  # samples are the nodes here
    other = np.sum((ha - np.roll(hb[truth], 25, axis=0)) ** 2, axis=1)
    assert np.median(same) < 0.2 * np.median(other)


# --------------------------------------------------------------------------
# The search over every start
# --------------------------------------------------------------------------


@pytest.mark.parametrize("n", [60, 240])
def test_every_start_is_searched(n):
    """A planted alignment whose start is a third of the contour off the
    uniform-rate guess, and whose rate changes (a part slid): found exactly."""
    rng = np.random.default_rng(1)
    C = rng.uniform(1.0, 2.0, (n, n))
    # Node i of a -> node of b: 3 per step over the first quarter, then slower.
    steps = np.where(np.arange(n) < n // 4, 3, 0)
    steps[n // 4:][: n - 1 - 3 * (n // 4)] = 1
    path = (n // 3 + np.concatenate([[0], np.cumsum(steps[:-1])])) % n
    C[np.arange(n), path] = 0.0
    # Decoys: the uniform-rate diagonal from node 0 is cheap but not free.
    C[np.arange(n), np.arange(n)] = np.minimum(C[np.arange(n), np.arange(n)], 0.3)
    found = drain(_iter_every_start(C, penalty=0.05, gap=np.inf))
    t = np.arange(n) / n
    part, _ = _search("order", C, t, t, arc_weight=0.0, n_starts=2, gap=np.inf, penalty=0.05)
    assert np.array_equal(part, path)
    assert found[0][0] <= found[-1][0]


# --------------------------------------------------------------------------
# The benchmark's articulated families
# --------------------------------------------------------------------------


@pytest.mark.parametrize("reverse", [False, True])
@pytest.mark.parametrize("noise", [0.0, 1.5])
def test_fingers_that_slide_together(reverse, noise):
    md = _benchmark_data()
    a, b, truth = md.sliding_hand_pair(67, 66, seed=21, reverse=reverse)
    if noise:
        a, b = md.noisy(a, noise, 1), md.noisy(b, noise, 2)
    assert within(match(a, b).partner, truth, len(b)) >= 0.85


@pytest.mark.parametrize("seed", [21, 22])
def test_legs_that_swing(seed):
    md = _benchmark_data()
    a, b, truth = md.animal_pair(70, 62, seed=seed)
    a, b = md.noisy(a, 1.0, seed), md.noisy(b, 1.0, seed + 1)
    assert within(match(a, b).partner, truth, len(b)) >= 0.85
    # global is no longer thrown by similar legs (it swapped them: 0.03-0.3 before issue 12).
    assert within(match(a, b, method="global").partner, truth, len(b)) >= 0.7


def test_the_context_term_is_what_holds_the_noisy_sliding_fingers():
    """Ablation as a test: over a few noisy sliding-finger pairs the default
    cost is at least as good as without the context term, and better somewhere."""
    md = _benchmark_data()
    with_ctx, without = [], []
    for seed in (6, 26, 17):
        a, b, truth = md.sliding_hand_pair(61, 66, seed=100 + seed, reverse=bool(seed % 2), scale=55.0)
        a, b = md.noisy(a, 2.0, seed), md.noisy(b, 2.0, seed + 1000)
        with_ctx.append(within(match(a, b).partner, truth, len(b)))
        without.append(within(match(a, b, context_weight=0.0).partner, truth, len(b)))
    assert np.mean(with_ctx) >= np.mean(without)
    assert min(with_ctx) >= 0.85

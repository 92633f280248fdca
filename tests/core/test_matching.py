"""Modal matching: modes, affinity with sign correction, and the three searches.

Ground truth comes from :mod:`napari_physeg.data`: rigid copies of a contour
(the exact answer is known), smooth warps (node i maps to node i) and hand
pairs in different poses (anatomical partners).
"""

import time

import numpy as np
import pytest
from dataclasses import replace
from hypothesis import HealthCheck, given, settings, strategies as st

from napari_physeg import data
from napari_physeg.core import Matching, match
from napari_physeg.core._drain import drain
from napari_physeg.core.contour import resample
from napari_physeg.core.matching import curvature_signature, modal_affinity
from napari_physeg.core.modes import modal_basis, select_modes


# --------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------


def similarity(c, degrees=0.0, scale=1.0, shift=(0.0, 0.0)):
    th = np.deg2rad(degrees)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return np.asarray(c) @ R.T * scale + np.asarray(shift)


def within(partner, truth, nb, tol=1):
    """Fraction of nodes of a whose partner is within ``tol`` nodes (cyclically)
    of the truth; unmatched nodes count as wrong."""
    d = np.abs(np.asarray(partner) - np.asarray(truth)) % nb
    d = np.minimum(d, nb - d)
    return float(np.mean((np.asarray(partner) >= 0) & (d <= tol)))


def is_cyclically_ordered(pairs, nb):
    """True when the partners in b, visited in the cyclic order of a, go round b
    at most once in one direction (no crossed matches). Repeated partners are
    allowed (a node of b shared by neighbours of a)."""
    p = np.asarray(pairs)[np.argsort(np.asarray(pairs)[:, 0]), 1]
    if len(p) < 3:
        return True
    nxt = np.roll(p, -1)
    forward = int(np.sum((nxt - p) % nb))
    backward = int(np.sum((p - nxt) % nb))
    return min(forward, backward) <= nb


def star(n, amps, phases, rotation=0.0):
    """A smooth star-shaped (hence simple) closed contour."""
    t = 2 * np.pi * np.arange(n) / n
    r = 1.0 + sum(a * np.cos((k + 1) * t + p) for k, (a, p) in enumerate(zip(amps, phases)))
    return 50.0 * np.column_stack([r * np.cos(t + rotation), r * np.sin(t + rotation)]) + 100.0


HAND = data.hand_outline("open", n_nodes=67)
BLOB = resample(data.blob((256, 256), seed=1).outline, 100)


# --------------------------------------------------------------------------
# The crossing checker itself
# --------------------------------------------------------------------------


def test_crossing_checker():
    n = 10
    ok = np.column_stack([np.arange(n), (np.arange(n) + 3) % n])
    assert is_cyclically_ordered(ok, n)
    assert is_cyclically_ordered(np.column_stack([np.arange(n), (-np.arange(n)) % n]), n)  # reversed
    shared = np.column_stack([np.arange(n), np.arange(n) // 2])  # many-to-one, in order
    assert is_cyclically_ordered(shared, n)
    crossed = ok.copy()
    crossed[[2, 6], 1] = crossed[[6, 2], 1]
    assert not is_cyclically_ordered(crossed, n)


# --------------------------------------------------------------------------
# Rigid copies: the exact answer
# --------------------------------------------------------------------------

TRANSFORMS = {
    "self": lambda c: (c, np.arange(len(c))),
    "shifted start": lambda c: (np.roll(c, -17, axis=0), (np.arange(len(c)) - 17) % len(c)),
    "reversed": lambda c: (c[::-1], len(c) - 1 - np.arange(len(c))),
    "reversed and shifted": lambda c: (np.roll(c[::-1], 5, axis=0), (len(c) - 1 - np.arange(len(c)) + 5) % len(c)),
    "rotated 30, scaled 1.7, moved": lambda c: (similarity(c, 30, 1.7, (300, -50)), np.arange(len(c))),
    "rotated 60, scaled 0.5": lambda c: (similarity(c, 60, 0.5), np.arange(len(c))),
    "rotated 90, moved": lambda c: (similarity(c, 90, 1.0, (-40, 900)), np.arange(len(c))),
    "rotated 45, shifted start": lambda c: (np.roll(similarity(c, 45), 9, axis=0), (np.arange(len(c)) + 9) % len(c)),
}


@pytest.mark.parametrize("method", ["order", "global"])
@pytest.mark.parametrize("transform", list(TRANSFORMS))
@pytest.mark.parametrize("shape", ["hand", "blob"])
def test_rigid_copies_recovered_exactly(shape, transform, method):
    a = HAND if shape == "hand" else BLOB
    b, truth = TRANSFORMS[transform](a)
    m = match(a, b, method=method)
    assert isinstance(m, Matching)
    assert np.mean(m.partner == truth) >= 0.98
    if method == "order":
        assert is_cyclically_ordered(m.pairs, len(b))


@pytest.mark.parametrize("mirror", [lambda c: c[:, ::-1], lambda c: c * [1, -1], lambda c: similarity(c * [-1, 1], 30)],
                         ids=["(x, y) for (row, col)", "flipped left-right", "flipped, turned and scaled"])
def test_a_mirror_image_is_matched_with_a_warning(mirror):
    """A reflection is no deformation: modal matching cannot follow it and
    pairs the hand's fingers wrongly. Said, not silent (probing, session 27);
    the commonest way to get one is a contour in (x, y) beside one in (row, col)."""
    with pytest.warns(UserWarning, match="mirror image.*swap the columns"):
        match(HAND, mirror(HAND))


@pytest.mark.parametrize("poses", [("open", "closed"), ("spread", "closed"), ("open", "spread")])
def test_a_deformed_hand_is_no_mirror_image(poses, recwarn):
    a, b, _ = data.hand_pair(67, 66, pose_a=poses[0], pose_b=poses[1])
    match(a, b)
    match(a, similarity(b, 90))
    assert not [w for w in recwarn if "mirror" in str(w.message)]


def test_mirror_fit_is_similarity_invariant():
    from napari_physeg.core.matching import mirror_fit

    a, b, _ = data.hand_pair(67, 66, pose_a="open", pose_b="closed")
    fit = mirror_fit(a, b)
    assert fit > 1.0  # a deformation: b fits a better read forward
    assert mirror_fit(a, np.roll(similarity(b, 45), 9, axis=0)) == pytest.approx(fit, rel=0.05)
    assert mirror_fit(a, a) == 1.0 and mirror_fit(a, b[::-1][::-1]) == pytest.approx(fit)
    flipped = (b * [1, -1])[::-1]  # reflected, then positively oriented again
    assert mirror_fit(a, flipped) == pytest.approx(1.0 / fit, rel=0.05)


@pytest.mark.parametrize("roll", [1, 17, 60])
def test_a_balanced_figure_eight_is_matched_to_itself_wherever_its_numbering_starts(roll):
    """Its signed area is zero but for rounding, whose sign followed the
    numbering's start: one copy was reversed and every node paired ~30 nodes
    off (probing, session 27). Without an orientation, the caller's is kept."""
    s = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    a = np.column_stack([40 * np.sin(2 * s), 60 * np.sin(s) + 10 * np.cos(3 * s)])
    truth = (np.arange(120) + roll) % 120
    for method in ("order", "global"):
        with pytest.warns(UserWarning, match="[ab] crosses itself"):  # (said since session 65, matched all the same)
            assert np.mean(match(a, np.roll(a, roll, axis=0), method=method).partner == truth) >= 0.98


def test_contours_in_one_frame_of_reference_are_not_checked_for_reflection(recwarn):
    """Consecutive frames of a movie (displacement_weight > 0, as tracking matches them)."""
    match(HAND, HAND[:, ::-1], displacement_weight=1.0)
    assert not [w for w in recwarn if "mirror" in str(w.message)]


def test_self_match_affinity_zero_on_the_diagonal():
    m = match(HAND, HAND)
    assert np.allclose(np.diag(m.affinity), 0.0, atol=1e-12)
    assert np.all(m.affinity >= 0)
    assert np.array_equal(m.pairs, np.column_stack([np.arange(67), np.arange(67)]))
    assert m.unmatched.size == 0 and m.unmatched_b.size == 0
    assert np.allclose(m.cost, np.diag(m.cost_matrix))


# --------------------------------------------------------------------------
# Near-round real outlines: the coins of skimage.data
# --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def coin_outlines():
    """The outlines of the 24 coins of ``skimage.data.coins()`` (a watershed
    of the Sobel edges from dark and bright markers): near-round shapes,
    whose modes come in near-degenerate pairs and whose clouds of modal
    features are nearly symmetric under a half turn."""
    from scipy import ndimage as ndi
    from skimage import data as skdata, filters, measure, segmentation

    image = skdata.coins()
    markers = np.where(image < 30, 1, 0) + np.where(image > 150, 2, 0)
    coins = ndi.binary_fill_holes(segmentation.watershed(filters.sobel(image), markers) == 2)
    labels = measure.label(coins)
    labels[np.bincount(labels.ravel())[labels] < 100] = 0
    labels = measure.label(labels > 0)
    return [max(measure.find_contours(np.pad(labels == k, 1).astype(float), 0.5), key=len)[:-1] - 1.0
            for k in range(1, labels.max() + 1)]


def _from(outline, n, start):
    """``n`` nodes evenly spaced along ``outline`` from the fraction ``start`` of its length on."""
    closed = np.vstack([outline, outline[:1]])
    length = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    at = (start + np.arange(n) / n) % 1.0 * length[-1]
    return np.column_stack([np.interp(at, length, closed[:, k]) for k in range(2)])


@pytest.mark.parametrize("coin, start", [(0, 0.16), (1, 0.16), (12, 0.16), (15, 0.16), (22, 0.83), (19, 0.16)])
def test_a_coin_matched_to_a_resampled_copy_of_itself_is_not_half_a_turn_off(coin_outlines, coin, start):
    """The same coin outline, its 64 nodes started elsewhere and moved:
    every node's partner is known. The modes' signs chosen from each mode's
    cloud alone matched these half a turn off (accuracy 0); fitted along
    the path the curvature and inner-distance context give, they agree."""
    a = _from(coin_outlines[coin], 64, 0.0)
    b = _from(coin_outlines[coin], 64, start) + [13.0, -7.0]
    truth = np.round(np.arange(64) - start * 64).astype(int) % 64
    for method in ("order", "global"):
        assert within(match(a, b, method=method).partner, truth, 64) >= 0.95


@pytest.mark.parametrize("coin", [3, 10, 22, 23])
def test_a_coin_outline_matched_at_a_third_of_its_node_count_keeps_its_place(coin_outlines, coin):
    """40 nodes against 113 of the same coin outline (a coarse and a fine
    drawing): each partner within one node spacing of the coarse contour."""
    a = _from(coin_outlines[coin], 40, 0.0)
    b = _from(coin_outlines[coin], 113, 0.37) + [5.0, 9.0]
    gap = np.abs(np.arange(40)[:, None] / 40 - (0.37 + np.arange(113)[None] / 113) % 1.0)
    truth = np.minimum(gap, 1 - gap).argmin(axis=1)
    assert within(match(a, b).partner, truth, 113, tol=3) >= 0.9


# --------------------------------------------------------------------------
# Non-rigid: smooth warps and articulated hands
# --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(4))
def test_smooth_warps_of_the_hand(seed):
    a = data.hand_outline("open", n_nodes=100)
    b = data.smooth_warp(similarity(a, 20 * seed, 1.2), amplitude=0.05, seed=seed)
    m = match(a, b)
    acc = within(m.partner, np.arange(100), 100)
    assert acc >= 0.95, acc
    assert is_cyclically_ordered(m.pairs, 100)


def test_hand_open_to_closed_the_papers_case():
    # The paper's experiment: 67 nodes (open hand) against 66 (fingers closed,
    # nearly touching). Measured within one node: order 1.00, global 0.90 (the
    # assignment ignores order, so a few neighbours swap). The asserted levels
    # leave room for small numerical changes, not for a finger matched to the
    # wrong finger (a finger is ~10 nodes wide here, ~15 % of the nodes).
    a, b, truth = data.hand_pair(67, 66, pose_a="open", pose_b="closed")
    acc = {meth: within(match(a, b, method=meth).partner, truth, 66) for meth in ("order", "global")}
    print(f"hand open->closed 67x66 accuracy (within one node): {acc}")
    assert acc["order"] >= 0.95
    assert acc["global"] >= 0.85
    m = match(a, b)
    assert len(m.pairs) == 67 and m.unmatched.size == 0
    assert is_cyclically_ordered(m.pairs, 66)


def test_hand_spread_to_closed_articulated():
    a, b, truth = data.hand_pair(120, 120, pose_a="spread", pose_b="closed")
    acc = within(match(a, b).partner, truth, 120)
    print(f"hand spread->closed 120x120 order accuracy: {acc:.3f}")
    assert acc >= 0.90


def test_detail_pass_pins_the_turned_thumb_of_a_dense_hand():
    # 1000 nodes, 0.9 px apart: without the detail pass the thumb and the palm
    # beside it are matched 2-4 nodes off (accuracy 0.88).
    a, b, truth = data.hand_pair(1000, 1000, pose_a="spread", pose_b="closed")
    m = match(a, b)
    coarse = match(a, b, detail=False)
    acc, acc_coarse = within(m.partner, truth, 1000), within(coarse.partner, truth, 1000)
    print(f"hand spread->closed 1000x1000: detail {acc:.3f}, without {acc_coarse:.3f}")
    assert m.detail_refined and not coarse.detail_refined
    assert acc >= 0.9 and acc >= acc_coarse + 0.04
    assert is_cyclically_ordered(m.pairs, 1000)


@pytest.mark.parametrize("n_a, n_b", [(400, 450), (450, 400), (1000, 700)])
def test_detail_pass_keeps_dense_pairs_of_unequal_counts(n_a, n_b):
    """With unequal counts the detail pass used to gather the skips it needs on
    flat curvature, shifting the nodes between them (0.835 on 400 x 450):
    it now searches b as len(a) evenly spaced nodes."""
    a, b, truth = data.hand_pair(n_a, n_b, pose_a="open", pose_b="closed")
    m = match(a, b)
    assert m.detail_refined
    assert within(m.partner, truth, n_b) >= max(0.95, within(match(a, b, detail=False).partner, truth, n_b))


def test_detail_pass_only_where_the_nodes_resolve_fine_curvature():
    dense = data.hand_outline("open", n_nodes=600, scale=100.0)
    spacing = np.linalg.norm(np.roll(dense, -1, axis=0) - dense, axis=1).mean()
    noisy = dense + np.random.default_rng(0).normal(0.0, 0.3 * spacing, dense.shape)
    assert match(dense, similarity(dense, 30, 1.1)).detail_refined
    assert not match(dense, noisy).detail_refined  # curvature at one spacing is noise there
    assert not match(HAND, HAND).detail_refined  # 67 nodes: the signature already reaches one spacing
    assert not match(dense, dense, method="global").detail_refined


def test_without_sign_correction_matching_degrades():
    # Flip the sign of every other mode of b: the corrected affinity is
    # unchanged, the uncorrected one is not.
    a = data.hand_outline("open", n_nodes=67)
    b = data.smooth_warp(a, amplitude=0.04, seed=3)
    ba, bb = modal_basis(a, n_modes=6, model_nodes=64), modal_basis(b, n_modes=6, model_nodes=64)
    k = min(ba.n_modes, bb.n_modes)
    flip = np.where(np.arange(bb.n_modes) % 2 == 1, -1.0, 1.0)
    flipped = replace(bb, shapes=bb.shapes * flip[None, :, None])
    Z, _ = modal_affinity(ba, bb, k)
    Zf, signs = modal_affinity(ba, flipped, k)
    assert np.allclose(Z, Zf)
    assert np.array_equal(signs, flip[:k] * modal_affinity(ba, bb, k)[1])
    Zraw, _ = modal_affinity(ba, flipped, k, sign_correction=False)
    i = np.arange(67)
    assert np.mean(Zraw[i, i]) > 5 * np.mean(Z[i, i])


# --------------------------------------------------------------------------
# Unequal node counts and the three searches
# --------------------------------------------------------------------------


@pytest.mark.parametrize("n_a, n_b", [(67, 66), (100, 60), (60, 100)])
def test_unequal_counts(n_a, n_b):
    a, b, truth = data.hand_pair(n_a, n_b, pose_a="open", pose_b="spread")
    for method in ("order", "global", "local"):
        m = match(a, b, method=method)
        # Every node of a is either matched once or listed as unmatched.
        assert np.array_equal(np.sort(np.concatenate([m.pairs[:, 0], m.unmatched])), np.arange(n_a))
        assert len(np.unique(m.pairs[:, 0])) == len(m.pairs)
        # Every node of b is either used or listed in unmatched_b.
        assert np.array_equal(np.union1d(m.pairs[:, 1], m.unmatched_b), np.arange(n_b))
        assert np.intersect1d(m.pairs[:, 1], m.unmatched_b).size == 0
        assert m.affinity.shape == (n_a, n_b) and m.cost.shape == (len(m.pairs),)
        if method in ("order", "global"):
            assert m.unmatched.size == 0  # all of a handled
            if n_b > n_a:
                assert m.unmatched_b.size >= n_b - n_a
        if method == "order":
            assert is_cyclically_ordered(m.pairs, n_b)
            assert within(m.partner, truth, n_b) >= 0.9
        if method == "global" and n_b <= n_a:
            assert within(m.partner, truth, n_b) >= 0.9


def test_local_returns_only_mutual_minima():
    a, b, _ = data.hand_pair(67, 66, pose_a="open", pose_b="closed")
    loc = match(a, b, method="local")
    glob = match(a, b, method="global")
    assert not loc.refined
    assert 0 < len(loc.pairs) < min(67, 66) <= len(glob.pairs)
    C = loc.cost_matrix
    for i, j in loc.pairs:
        assert C[i, j] == C[i].min() and C[i, j] == C[:, j].min()
    # ... and every mutual minimum is reported.
    rows, cols = C.argmin(axis=1), C.argmin(axis=0)
    mutual = [(i, rows[i]) for i in range(67) if cols[rows[i]] == i]
    assert len(mutual) == len(loc.pairs)
    # With the curvature and context terms off the cost is the modal affinity itself.
    pure = match(a, b, method="local", curvature_weight=0.0, context_weight=0.0)
    assert np.allclose(pure.cost_matrix, pure.affinity / pure.n_modes)


def test_order_gap_cost_leaves_outliers_unmatched():
    a, b, _ = data.hand_pair(67, 66, pose_a="open", pose_b="closed")
    m = match(a, b, gap_cost=0.0)  # a gap is free: nothing worth matching
    assert len(m.pairs) + len(m.unmatched) == 67
    assert len(m.unmatched) > 0


# --------------------------------------------------------------------------
# Modes
# --------------------------------------------------------------------------


def test_modal_basis_dense_and_sparse_agree():
    from napari_physeg.core import modes as modes_module

    c = data.hand_outline("open", n_nodes=320)  # > DENSE_LIMIT: sparse shift-invert
    sparse = modal_basis(c, n_modes=6)
    old = modes_module.DENSE_LIMIT
    modes_module.DENSE_LIMIT = 10_000
    try:
        dense = modal_basis(c, n_modes=sparse.n_modes)
    finally:
        modes_module.DENSE_LIMIT = old
    assert sparse.n_modes == dense.n_modes
    assert np.allclose(sparse.eigenvalues, dense.eigenvalues, rtol=1e-6)
    # Same modes up to sign: |<phi_sparse, phi_dense>| = 1 for each unit mode.
    overlap = np.abs(np.einsum("mkc,mkc->k", sparse.shapes, dense.shapes))
    assert np.all(overlap > 0.999)


def test_modal_basis_properties():
    b = modal_basis(HAND)
    assert 6 <= b.n_modes <= 12
    assert np.allclose(np.sqrt((b.shapes**2).sum(axis=(0, 2))), 1.0)
    assert np.all(b.eigenvalues > 0) and np.all(np.diff(b.eigenvalues) >= 0)
    assert np.isclose(np.linalg.det(b.axes), 1.0)
    # Canonical frame: centred, unit RMS radius (arc-length weighted).
    assert np.allclose(b.to_canonical(HAND), b.nodes)
    assert np.allclose(b.from_canonical(b.nodes), HAND)
    # Modes rotate with the object: identical in the canonical frame.
    r = modal_basis(similarity(HAND, 73, 2.5, (10, 20)), n_modes=b.n_modes)
    assert np.allclose(r.nodes, b.nodes, atol=1e-9)
    assert np.allclose(r.shapes, b.shapes, atol=1e-6)


def test_select_modes_keeps_near_degenerate_pairs_whole():
    lam = np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 6.01, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0])
    assert select_modes(lam, 6) == 7  # 6 and 6.01 stay together
    assert select_modes(lam, 5) == 5
    assert select_modes(lam) == 7


def test_curvature_signature_is_similarity_invariant_and_signed():
    k = curvature_signature(HAND)
    k2 = curvature_signature(similarity(HAND, 33, 3.0, (5, 5)))
    assert np.allclose(k, k2, atol=1e-9)
    t = 2 * np.pi * np.arange(64) / 64
    circle = np.column_stack([np.cos(t), np.sin(t)]) * 20
    kc = curvature_signature(circle)
    assert np.all(kc > 0) and np.allclose(kc, kc[0])  # convex, uniform


# --------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "a, b, kwargs, pattern",
    [
        (HAND[:2], HAND, {}, r"^a has 2 distinct"),
        (HAND, [[0, 0], [1, 1]], {}, r"^b has 2 distinct"),
        (np.where(np.arange(67)[:, None] == 5, np.nan, HAND), HAND, {}, r"^a contains NaN"),
        (HAND, np.full((10, 2), 3.0), {}, r"^b has 1 distinct"),
        (HAND, np.vstack([HAND, HAND[10:11]]), {}, r"^b has 1 identical node"),
        (np.vstack([HAND, HAND[:1]]), HAND, {}, r"^a repeats its first node at the end"),
        (np.vstack([HAND[:5], HAND[4:]]), HAND, {}, r"^a has repeated consecutive nodes \(nodes 4 and 5"),
        (HAND, HAND[:, :1], {}, r"^b must be an \(N, 2\) array"),
        (HAND, HAND, {"method": "nearest"}, r"^method must be one of"),
        (HAND, HAND, {"method": None}, r"^method must be one of"),
        (HAND, HAND, {"n_modes": 0}, r"^n_modes must be"),
        (HAND, HAND, {"model_nodes": 3}, r"^model_nodes must be"),
        (HAND, HAND, {"curvature_weight": -1}, r"^curvature_weight must be"),
        (HAND, HAND, {"gap_cost": float("nan")}, r"^gap_cost must be"),
        (HAND, HAND, {"detail": "yes"}, r"^detail must be True, False or None"),
        (HAND, HAND, {"method": "global", "detail": True}, r"^the detail pass is part of method='order'"),
    ],
)
def test_bad_input_raises_clear_value_error(a, b, kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        match(a, b, **kwargs)


def test_bad_input_fails_fast():
    big = data.hand_outline("open", n_nodes=2000)
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match="method"):
        match(big, big, method="bogus")
    assert time.perf_counter() - t0 < 0.2


# --------------------------------------------------------------------------
# Properties
# --------------------------------------------------------------------------

shapes = st.builds(
    star,
    n=st.integers(24, 90),
    amps=st.lists(st.floats(-0.12, 0.12), min_size=4, max_size=4),
    phases=st.lists(st.floats(0, 2 * np.pi), min_size=4, max_size=4),
)
# Without rotational symmetry (harmonics 2 and 3 both present): a symmetric
# shape has several equally good correspondences, so invariance of "the"
# matching would be a question of floating-point ties.
_signed = st.one_of(st.floats(0.05, 0.12), st.floats(-0.12, -0.05))
asymmetric_shapes = st.builds(
    star,
    n=st.integers(24, 90),
    amps=st.tuples(st.floats(-0.05, 0.05), _signed, _signed, st.floats(-0.05, 0.05)),
    phases=st.lists(st.floats(0, 2 * np.pi), min_size=4, max_size=4),
)
transforms = st.tuples(st.floats(-180, 180), st.floats(0.2, 5.0), st.floats(-500, 500), st.floats(-500, 500))
prop_settings = settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@prop_settings
@given(a=shapes, b=shapes)
def test_affinity_non_negative_and_finite(a, b):
    m = match(a, b)
    assert m.affinity.shape == (len(a), len(b))
    assert np.all(np.isfinite(m.affinity)) and np.all(m.affinity >= 0)
    assert np.all(np.isfinite(m.cost)) and np.all(m.cost >= 0)
    assert is_cyclically_ordered(m.pairs, len(b))


@prop_settings
@given(a=asymmetric_shapes)
def test_self_match_is_identity(a):
    m = match(a, a)
    assert np.allclose(np.diag(m.affinity), 0.0, atol=1e-12)
    assert np.mean(m.partner == np.arange(len(a))) >= 0.98


@prop_settings
@given(a=asymmetric_shapes, tr=transforms, which=st.sampled_from(["a", "b"]))
def test_matching_invariant_to_similarity_transforms(a, tr, which):
    b = data.smooth_warp(a, amplitude=0.04, seed=1)
    ref = match(a, b).partner
    moved = similarity(a if which == "a" else b, tr[0], tr[1], (tr[2], tr[3]))
    got = match(moved, b).partner if which == "a" else match(a, moved).partner
    assert np.mean(got == ref) >= 0.98


def test_callback_reports_progress_and_stops_the_matching():
    a, b, _ = data.hand_pair(500, 500, pose_a="spread", pose_b="closed")
    seen = []
    m = match(a, b, callback=seen.append)
    assert m.detail_refined and m.stop_reason == "completed"
    # features, each start of the first search, refinement, detail pass
    assert len(seen) >= 4 and seen == sorted(seen) and seen[-1] == 1.0 and 0 < seen[0] < 0.5
    calls = []
    stopped = match(a, b, callback=lambda f: calls.append(f) or len(calls) < 2)
    assert len(calls) == 2  # stopped at once
    assert stopped.stop_reason == "cancelled"
    assert stopped.pairs.shape == (0, 2) and len(stopped.unmatched) == len(a)
    with pytest.raises(ValueError, match="^callback must be callable"):
        match(a, b, callback=3)


def test_iter_match_yields_progress_and_returns_what_match_returns():
    from napari_physeg.core import MatchingProgress, iter_match

    a, b, _ = data.hand_pair(120, 110, pose_a="open", pose_b="closed")
    run = iter_match(a, b, method="order", n_starts=3)
    states = []
    result = drain(run, states.append)
    assert all(isinstance(s, MatchingProgress) for s in states)
    phases = [s.phase for s in states]
    # features (with the coarse search around every start that weighs the modes'
    # hypotheses); the search about the 3 best starts at full resolution; the refinement.
    assert phases[0] == "features" and phases[-1] == "refinement"
    assert set(phases[1:-1]) == {"search"} and len(phases) - 2 >= 3
    fractions = [s.fraction for s in states]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    plain = match(a, b, n_starts=3)
    assert np.array_equal(result.pairs, plain.pairs) and result.stop_reason == "completed"


def test_iter_match_stops_when_sent_true_and_keeps_the_finished_search():
    from napari_physeg.core import iter_match

    a, b, _ = data.hand_pair(120, 110, pose_a="open", pose_b="closed")
    run = iter_match(a, b)
    state = next(run)
    while state.phase != "refinement":
        state = run.send(None)
    # The refinement has finished: stopping now keeps its pairs.
    with pytest.raises(StopIteration) as done:
        run.send(True)
    result = done.value.value
    assert result.stop_reason == "cancelled" and len(result.pairs) == len(a)


def test_iter_match_checks_its_options_at_the_call():
    from napari_physeg.core import iter_match

    with pytest.raises(TypeError, match="methd"):
        iter_match(HAND, HAND, methd="order")
    with pytest.raises(ValueError, match="^method must be one of"):
        iter_match(HAND, HAND, method="nearest")  # before the first next()
    with pytest.raises(TypeError, match="callback"):
        iter_match(HAND, HAND, callback=print)
    with pytest.raises(TypeError, match="methd"):
        match(HAND, HAND, methd="order")


def test_modes_of_a_moved_shape_are_remembered_and_right():
    """Tracking matches each contour twice, rigidly moved: its modes are
    computed once. The remembered modes are those a fresh computation gives,
    read-only, and another shape gets its own."""
    import napari_physeg.core.modes as modes_module

    a, b, _ = data.hand_pair(67, 66)
    angle = 0.7
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    moved = a @ turn.T + [1e3, -250.0]
    modes_module._MODES_CACHE.clear()
    first = modal_basis(a, n_modes=8, model_nodes=32)
    again = modal_basis(moved, n_modes=8, model_nodes=32)
    assert again.shapes.base is first.shapes.base or np.shares_memory(again.shapes, first.shapes)
    with pytest.raises(ValueError):
        again.shapes[0, 0, 0] = 1.0  # shared: nobody may write into it
    modes_module._MODES_CACHE.clear()
    fresh = modal_basis(moved, n_modes=8, model_nodes=32)
    assert np.allclose(fresh.shapes, again.shapes, atol=1e-7)
    assert np.allclose(fresh.eigenvalues, again.eigenvalues, rtol=1e-9)
    other = modal_basis(b, n_modes=8, model_nodes=32)
    assert not np.shares_memory(other.shapes, first.shapes)


def _order_dp_by_enumeration(C, nb, window, repeat, skip, gap):
    """The least total of _order_dp's problem, state by state (row, column, start column):
    node 0 starts in one of the first 2 window + 1 columns; each later node repeats the
    previous column (``repeat``), advances past k columns (``skip`` each) or is left out
    (``gap``, the column kept); the last column lies less than nb after the start, and the
    columns left over count as skipped."""
    na, width = C.shape
    best = {(j, j): C[0, j] for j in range(2 * window + 1)}
    for i in range(1, na):
        nxt = {}
        for (j, s), cost in best.items():
            moves = [(j, cost + repeat + C[i, j]), (j, cost + gap)]
            moves += [(k, cost + skip * (k - j - 1) + C[i, k]) for k in range(j + 1, width)]
            for k, c in moves:
                if c < nxt.get((k, s), np.inf):
                    nxt[(k, s)] = c
        best = nxt
    return min(c + skip * (nb - 1 - (j - s)) for (j, s), c in best.items() if j - s <= nb - 1)


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 7), st.integers(3, 8), st.integers(1, 3), st.sampled_from([np.inf, 0.3, 2.0]),
       st.integers(0, 2**31 - 1))
def test_order_dp_finds_the_least_total(na, nb, window, gap, seed):
    """From one start node, the vectorised order-preserving DP reaches the optimum of its problem,
    found by enumeration, and the path it returns costs that total. (From several starts it keeps
    one per cell, by design: see _order_search.)"""
    from napari_physeg.core.matching import _order_dp

    rng = np.random.default_rng(seed)
    window = min(window, (nb - 1) // 2 or 1)
    C = np.round(rng.random((na, nb + 2 * window)), 2)  # rounded: ties happen
    start = int(rng.integers(0, 2 * window + 1))
    C[0, : 2 * window + 1] = 1e6
    C[0, start] = rng.random()
    repeat, skip = rng.uniform(0.0, 1.0, 2)
    part, total = _order_dp(C, nb, window, repeat, skip, gap)
    assert total == pytest.approx(_order_dp_by_enumeration(C, nb, window, repeat, skip, gap), abs=1e-9)
    assert part[0] == start
    matched = np.flatnonzero(part >= 0)
    cols = part[matched]
    assert np.all(np.diff(cols) >= 0) and cols[-1] - cols[0] <= nb - 1
    # The path's own cost: its costs, a repeat or the nodes of b passed over between matched
    # nodes, a gap per node left out, and the nodes of b left over at the end.
    steps = np.diff(cols)
    cost = (C[matched, cols].sum() + repeat * np.sum(steps == 0) + skip * np.sum(np.maximum(steps - 1, 0))
            + (gap * (na - len(matched)) if len(matched) < na else 0.0) + skip * (nb - 1 - (cols[-1] - cols[0])))
    assert cost == pytest.approx(total, abs=1e-9)

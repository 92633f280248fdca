"""Tests of the synthetic ground-truth generators in :mod:`napari_physeg.data`."""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import numpy as np
import pytest
from scipy import ndimage as ndi
from skimage.draw import polygon2mask
from skimage.morphology import convex_hull_image

from napari_physeg import data

SHAPES = [(256, 256), (512, 512)]
CASES = [
    ("ellipse", {"bright": True}),
    ("ellipse", {"bright": False}),
    ("blob", {}),
    ("blob", {"bright": False, "seed": 3}),
    ("hand", {"pose": "open"}),
    ("hand", {"pose": "closed"}),
    ("hand", {"pose": "spread", "bright": False}),
]
PARAMS = [
    pytest.param(gen, kw, shape, id=f"{gen}-{'-'.join(f'{k}={v}' for k, v in kw.items())}-{shape[0]}")
    for shape in SHAPES
    for gen, kw in CASES
]


@lru_cache(maxsize=None)
def _make(gen, kw_items, shape):
    return getattr(data, gen)(shape, **dict(kw_items))


def make(gen, kw, shape):
    return _make(gen, tuple(sorted(kw.items())), shape)


# --------------------------------------------------------------------------
# Geometry helpers (independent of the module's own helpers)
# --------------------------------------------------------------------------


def shoelace(c):
    r, q = c[:, 0], c[:, 1]
    return 0.5 * float(np.sum(r * np.roll(q, -1) - np.roll(r, -1) * q))


def iou(a, b):
    return (a & b).sum() / (a | b).sum()


def is_simple(contour):
    """True when no two non-adjacent edges of the closed polygon intersect."""
    from scipy.spatial import cKDTree

    p = np.asarray(contour, dtype=float)
    q = np.roll(p, -1, axis=0)
    n = len(p)
    lengths = np.hypot(*(q - p).T)
    # Two segments can only meet if their midpoints are closer than the longest one.
    pairs = cKDTree(0.5 * (p + q)).query_pairs(lengths.max() * 1.001, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    keep = (np.abs(i - j) > 1) & (np.abs(i - j) != n - 1)
    i, j = i[keep], j[keep]

    def orient(a, b, c):
        return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])

    o1, o2 = orient(p[i], q[i], p[j]), orient(p[i], q[i], q[j])
    o3, o4 = orient(p[j], q[j], p[i]), orient(p[j], q[j], q[i])
    return not np.any((o1 * o2 <= 0) & (o3 * o4 <= 0))


def winding_number(contour, point):
    d = contour - point
    ang = np.arctan2(d[:, 1], d[:, 0])
    step = (np.diff(np.append(ang, ang[0])) + np.pi) % (2 * np.pi) - np.pi
    return int(round(step.sum() / (2 * np.pi)))


def encloses_without_touching(contour, mask, clearance):
    """``contour`` surrounds the whole (connected) object without touching it.

    Every node is at least ``clearance`` px from the object's pixel centres and
    nodes are less than ``clearance`` apart, so no edge enters the object's
    pixels; the connected object then lies on one side of the contour, the
    inside one when one of its pixels has winding number 1.
    """
    dist = sample(ndi.distance_transform_edt(~mask), contour)
    assert node_spacing(contour).max() < clearance
    assert dist.min() >= clearance, f"contour comes within {dist.min():.2f} px of the object"
    inner = np.argwhere(ndi.binary_erosion(mask, iterations=2))[0]
    return winding_number(contour, inner) == 1


def polygon_raster(shape, contour):
    """polygon2mask at 256 px, the module's own fast rasteriser (checked against
    polygon2mask in test_polygon_mask) beyond."""
    if max(shape) <= 256:
        return polygon2mask(shape, contour)
    return data._polygon_mask(contour, shape)


def sample(field, pts):
    return ndi.map_coordinates(field, pts.T, order=1, mode="nearest")


def node_spacing(c):
    return np.hypot(*np.diff(np.vstack([c, c[:1]]), axis=0).T)


# --------------------------------------------------------------------------
# Every generator
# --------------------------------------------------------------------------


@pytest.mark.parametrize("gen, kw, shape", PARAMS)
def test_image_and_mask(gen, kw, shape):
    obj = make(gen, kw, shape)
    assert isinstance(obj, data.SyntheticObject)
    assert obj.image.shape == shape and obj.image.dtype == np.float64
    assert np.all(np.isfinite(obj.image))
    m = obj.mask
    assert m.shape == shape and m.dtype == bool
    assert ndi.label(m)[1] == 1, "object is not one 4-connected component"
    assert ndi.label(~m)[1] == 1, "object has holes"
    assert not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any())
    assert m.sum() > 0.02 * m.size


@pytest.mark.parametrize("gen, kw, shape", PARAMS)
def test_outline(gen, kw, shape):
    obj = make(gen, kw, shape)
    out, m = obj.outline, obj.mask
    assert out.ndim == 2 and out.shape[1] == 2 and out.dtype == np.float64
    assert not np.allclose(out[0], out[-1]), "first node repeated"
    spacing = node_spacing(out)
    assert 0.7 < np.median(spacing) < 1.3 and spacing.max() < 2.0
    assert shoelace(out) > 0, "outline not positively oriented"
    # Within 1 px of the pixel border of the mask.
    sd = np.where(m, ndi.distance_transform_edt(m) - 0.5, 0.5 - ndi.distance_transform_edt(~m))
    assert np.abs(sample(sd, out)).max() <= 1.0
    assert iou(polygon_raster(shape, out), m) >= 0.98
    assert is_simple(out)


@pytest.mark.parametrize("gen, kw, shape", PARAMS)
def test_init_near(gen, kw, shape):
    obj = make(gen, kw, shape)
    init, m = obj.init_near, obj.mask
    assert init.ndim == 2 and init.shape[1] == 2
    assert shoelace(init) > 0
    assert node_spacing(init).max() < 2.0
    # Outside the object, at a few pixels from it, enclosing it.
    dist = sample(ndi.distance_transform_edt(~m), init)
    assert dist.max() <= 15.0, "init_near too far from the object"
    assert np.median(dist) == pytest.approx(6.0, abs=1.5)
    assert encloses_without_touching(init, m, clearance=3.0)
    assert is_simple(init)
    # Smooth: no sharp turns between consecutive segments.
    d = np.diff(np.vstack([init[-1:], init, init[:1]]), axis=0)
    ang = np.arctan2(d[:, 1], d[:, 0])
    turn = np.abs((np.diff(ang) + np.pi) % (2 * np.pi) - np.pi)
    assert turn.max() < np.deg2rad(30)


@pytest.mark.parametrize("gen, kw, shape", PARAMS)
def test_init_far(gen, kw, shape):
    obj = make(gen, kw, shape)
    far, m = obj.init_far, obj.mask
    assert shoelace(far) > 0
    h, w = shape
    assert far[:, 0].min() >= 0 and far[:, 0].max() <= h - 1
    assert far[:, 1].min() >= 0 and far[:, 1].max() <= w - 1
    assert encloses_without_touching(far, m, clearance=2.0)
    size = np.ptp(np.argwhere(m), axis=0).max()
    dist = sample(ndi.distance_transform_edt(~m), far)
    assert np.median(dist) >= 0.1 * size, "init_far is not far from the object"
    assert is_simple(far)


@pytest.mark.parametrize("gen, kw, shape", PARAMS)
def test_polarity(gen, kw, shape):
    obj = make(gen, kw, shape)
    inside = obj.image[ndi.binary_erosion(obj.mask, iterations=2)].mean()
    outside = obj.image[~ndi.binary_dilation(obj.mask, iterations=2)].mean()
    if kw.get("bright", True):
        assert inside == pytest.approx(0.7) and outside == pytest.approx(0.3)
    else:
        assert inside == pytest.approx(0.3) and outside == pytest.approx(0.7)
    # Anti-aliased: some intermediate values along the border.
    mid = (obj.image > 0.35) & (obj.image < 0.65)
    assert mid.any()


def test_noise_and_contrast():
    clean = data.ellipse(contrast=0.5)
    noisy = data.ellipse(contrast=0.5, noise=0.2, seed=1)
    assert clean.image.max() == pytest.approx(0.5)
    resid = (noisy.image - clean.image)[~noisy.mask]
    assert resid.std() == pytest.approx(0.2 * 0.5 * 0.4, rel=0.05)
    np.testing.assert_array_equal(noisy.mask, clean.mask)


def test_determinism():
    for f, kw in [(data.ellipse, {"noise": 0.1}), (data.blob, {"noise": 0.1}),
                  (data.hand, {"noise": 0.1, "pose": "closed"})]:
        a, b = f(seed=5, **kw), f(seed=5, **kw)
        for field in ("image", "mask", "outline", "init_near", "init_far"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))
        assert not np.array_equal(a.image, f(seed=6, **kw).image)
    # Different seeds give different blobs.
    assert not np.array_equal(data.blob(seed=1).mask, data.blob(seed=2).mask)


def test_frozen():
    obj = data.ellipse((64, 64))
    with pytest.raises(dataclasses.FrozenInstanceError):
        obj.name = "x"


@pytest.mark.parametrize("seed", range(3))
def test_polygon_mask(seed):
    """The module's scan-line rasteriser agrees with skimage's polygon2mask."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, 40))
    r = rng.uniform(10, 40, 40)
    poly = np.column_stack([50 + r * np.cos(t), 45 + r * np.sin(t)])
    np.testing.assert_array_equal(data._polygon_mask(poly, (90, 100)), polygon2mask((90, 100), poly))
    hand = data.hand_outline("closed", scale=60.0, center=(70.0, 80.0))
    np.testing.assert_array_equal(data._polygon_mask(hand, (150, 160)), polygon2mask((150, 160), hand))


# --------------------------------------------------------------------------
# Ellipse
# --------------------------------------------------------------------------


def test_ellipse_geometry():
    from skimage.draw import ellipse as draw_ellipse

    shape, centre, axes, angle = (200, 240), (90.0, 130.0), (60.0, 35.0), 0.6
    obj = data.ellipse(shape, center=centre, axes=axes, angle=angle)
    ref = np.zeros(shape, bool)
    ref[draw_ellipse(*centre, *axes, shape=shape, rotation=angle)] = True
    assert iou(ref, obj.mask) >= 0.99
    r, c = obj.outline[:, 0] - centre[0], obj.outline[:, 1] - centre[1]
    ca, sa = np.cos(angle), np.sin(angle)
    rho = ((r * ca + c * sa) / axes[0]) ** 2 + ((r * sa - c * ca) / axes[1]) ** 2
    np.testing.assert_allclose(rho, 1.0, atol=1e-3)
    assert obj.mask.sum() == pytest.approx(np.pi * axes[0] * axes[1], rel=0.01)


def test_ellipse_rejects_bad_input():
    with pytest.raises(ValueError):
        data.ellipse(axes=(0, 10))
    with pytest.raises(ValueError):
        data.ellipse(noise=-1)
    with pytest.raises(ValueError):
        data.ellipse((10, 10))


def test_blob_is_irregular():
    m = data.blob().mask
    assert m.sum() / convex_hull_image(m).sum() <= 0.95


# --------------------------------------------------------------------------
# Hand
# --------------------------------------------------------------------------


@pytest.mark.parametrize("pose", ["open", "closed", "spread"])
@pytest.mark.parametrize("shape", SHAPES)
def test_hand_has_five_fingers(pose, shape):
    m = make("hand", {"pose": pose}, shape).mask
    deficiency = convex_hull_image(m) & ~m
    lab, n = ndi.label(deficiency)
    sizes = np.bincount(lab.ravel())[1:]
    min_size = 30 * (shape[0] / 256) ** 2
    assert np.sum(sizes >= min_size) >= 4, "fewer than 4 concavities between fingers"


@pytest.mark.parametrize("shape", SHAPES)
def test_hand_closed_gaps_in_raster(shape):
    """Along the line of closest approach of two adjacent finger axes, the
    rendered image shows at least 2 px of background and the mask is cut."""
    obj = make("hand", {"pose": "closed"}, shape)
    coverage = (obj.image - 0.3) / 0.4
    scale, centre = data._hand_placement(shape)
    base, tip, u, n, w = data._fingers("closed")
    t = np.linspace(0, 1, 401)[:, None]
    for k in range(1, 4):
        ak, bk = base[k] + t * (tip[k] - base[k]), base[k + 1] + t * (tip[k + 1] - base[k + 1])
        d = np.hypot(*(ak[:, None] - bk[None]).transpose(2, 0, 1))
        i, j = np.unravel_index(np.argmin(d), d.shape)
        seg = data._to_rowcol(np.vstack([ak[i], bk[j]]), scale, centre)
        s = np.linspace(0, 1, 1001)[:, None]
        pts = seg[0] + s * (seg[1] - seg[0])
        cov = sample(coverage, pts)
        step = np.hypot(*(seg[1] - seg[0])) / (len(s) - 1)
        assert cov[0] > 0.99 and cov[-1] > 0.99
        assert np.sum(1.0 - cov) * step >= 2.0, f"fingers {k} and {k + 1} nearly touch"
        on_mask = obj.mask[np.round(pts[:, 0]).astype(int), np.round(pts[:, 1]).astype(int)]
        assert not on_mask.all(), f"fingers {k} and {k + 1} touch in the mask"


def test_hand_gaps_by_pose():
    scale, _ = data._hand_placement((256, 256))
    closed = data._finger_gaps("closed") * scale
    assert np.all(closed >= 2.0)
    assert np.all(closed[1:] <= 4.0), "closed fingers should nearly touch"
    for pose in ("open", "spread"):
        assert np.all(data._finger_gaps(pose) * scale >= 6.0)
    # "spread" opens wider than "open": compare the gaps between fingertips.
    def tip_gaps(pose):
        _, tip, _, _, _ = data._fingers(pose)
        return np.hypot(*np.diff(tip, axis=0).T)
    assert np.all(tip_gaps("spread") > tip_gaps("open"))
    assert np.all(tip_gaps("open") > tip_gaps("closed"))


def test_hand_scales_with_shape():
    a = make("hand", {"pose": "open"}, (256, 256)).mask.sum()
    b = make("hand", {"pose": "open"}, (512, 512)).mask.sum()
    assert b / a == pytest.approx(4.0, rel=0.02)
    m = data.hand((200, 320)).mask
    rows, cols = np.nonzero(m)
    assert rows.min() > 10 and rows.max() < 190 and cols.min() > 10 and cols.max() < 310


def test_hand_rejects_unknown_pose():
    with pytest.raises(ValueError, match="pose"):
        data.hand(pose="fist")
    with pytest.raises(ValueError, match="pose"):
        data.hand_outline("fist")


@pytest.mark.parametrize("pose", sorted(data.HAND_POSES))
def test_hand_outline(pose):
    c, s, lab = data.hand_outline(pose, return_param=True)
    assert c.shape[1] == 2 and len(c) >= 256
    assert shoelace(c) > 0 and is_simple(c)
    assert np.all(np.diff(s) > 0) and s[0] == 0.0 and s[-1] < 1.0
    assert set(np.unique(lab)) == {-1, 0, 1, 2, 3, 4}
    # Node 0 is at the bottom centre of the palm.
    np.testing.assert_allclose(c[0], [1.0, 0.0], atol=1e-12)
    assert c[0, 0] >= c[:, 0].max() - 0.01
    # Placement and resampling.
    c1 = data.hand_outline(pose, n_nodes=100)
    c2 = data.hand_outline(pose, n_nodes=100, scale=3.0, center=(10.0, -4.0))
    assert c1.shape == (100, 2)
    np.testing.assert_allclose(c2, 3.0 * c1 + [10.0, -4.0], atol=1e-9)
    # Evenly spaced in arc length: chords equal the arc step on straight
    # parts, and are shorter across the fingertips only.
    arc_step = np.sum(node_spacing(data.hand_outline(pose, n_nodes=20000))) / 100
    assert node_spacing(c1).max() <= arc_step * 1.001
    assert np.median(node_spacing(c1)) >= arc_step * 0.999
    assert node_spacing(c1).min() >= arc_step * 0.5  # across the narrow webs
    # The hand image's outline is this outline, placed.
    scale, centre = data._hand_placement((256, 256))
    placed = data.hand_outline(pose, scale=scale, center=centre)
    m = make("hand", {"pose": pose}, (256, 256)).mask
    assert iou(polygon2mask((256, 256), placed), m) >= 0.99


def test_canonical_parameter_is_anatomical():
    """Fingers are rigid: equal canonical parameters on a finger are the same
    point of the finger in every pose (same offset from the finger's base)."""
    scale = 1.0
    ref = {}
    for pose in data.HAND_POSES:
        c, s, lab = data.hand_outline(pose, n_nodes=2000, scale=scale, return_param=True)
        base, tip, u, n, w = data._fingers(pose)
        xy = np.column_stack([c[:, 1], -c[:, 0]])
        for k in range(5):
            sel = lab == k
            local = np.column_stack([((xy[sel] - base[k]) * u[k]).sum(1), ((xy[sel] - base[k]) * n[k]).sum(1)])
            ref.setdefault(k, []).append((s[sel], local))
    for k, items in ref.items():
        s0, l0 = items[0]
        for s1, l1 in items[1:]:
            inner = (s1 >= s0.min()) & (s1 <= s0.max())
            for dim in range(2):
                np.testing.assert_allclose(np.interp(s1[inner], s0, l0[:, dim]), l1[inner, dim], atol=1e-3)


# --------------------------------------------------------------------------
# hand_pair
# --------------------------------------------------------------------------


def order_preserving(truth, n_b):
    steps = (np.roll(truth, -1) - truth) % n_b
    return steps.sum() == n_b  # one turn, no step backwards


@pytest.mark.parametrize("pose_a, pose_b", [("open", "closed"), ("spread", "closed"),
                                            ("closed", "open"), ("open", "spread")])
def test_hand_pair(pose_a, pose_b):
    a, b, truth = data.hand_pair(pose_a=pose_a, pose_b=pose_b)
    assert a.shape == (67, 2) and b.shape == (66, 2)
    assert truth.shape == (67,) and np.issubdtype(truth.dtype, np.integer)
    assert truth.min() >= 0 and truth.max() < 66
    # Cyclically non-decreasing once rotated to start at its wrap-around.
    drops = np.nonzero(np.diff(truth) < 0)[0]
    assert len(drops) <= 1
    rolled = np.roll(truth, -(drops[0] + 1)) if len(drops) else truth
    assert np.all(np.diff(rolled) >= 0)
    assert order_preserving(truth, 66)
    assert len(np.unique(truth)) >= 0.8 * 66
    # Corresponding nodes lie on the same finger (up to one node at the ends of a finger).
    scale, centre = data._hand_placement((256, 256))
    a2, s_a, lab_a = data.hand_outline(pose_a, n_nodes=67, scale=scale, center=centre, return_param=True)
    b2, s_b, lab_b = data.hand_outline(pose_b, n_nodes=66, scale=scale, center=centre, return_param=True)
    np.testing.assert_array_equal(a2, a)
    np.testing.assert_array_equal(b2, b)
    exact = lab_a == lab_b[truth]
    assert exact.mean() >= 0.9
    # A mismatch only where b has no node close enough on the right piece: a's
    # node is within one node spacing of b of a boundary between the two labels.
    shares = data._piece_shares()
    labels = data._hand_pieces("open")[1]
    tol = np.max(np.diff(np.append(s_b, s_b[0] + 1.0)))
    for i in np.nonzero(~exact)[0]:
        near = []
        for p in range(len(labels)):
            before, after = labels[p - 1], labels[p]
            if {before, after} == {lab_a[i], lab_b[truth[i]]}:
                dist = abs(s_a[i] - shares[p])
                near.append(min(dist, 1.0 - dist))
        assert near and min(near) <= tol, f"node {i} of a maps to another finger"
    # Every finger of a maps to the same finger of b.
    for k in range(5):
        assert np.any((lab_a == k) & (lab_b[truth] == k))


def test_hand_pair_same_pose_is_identity():
    a, b, truth = data.hand_pair(50, 50, pose_a="closed", pose_b="closed")
    np.testing.assert_array_equal(truth, np.arange(50))
    np.testing.assert_allclose(a, b)


def test_hand_pair_tips_correspond():
    """The node of a nearest each fingertip maps near the same fingertip of b."""
    scale, centre = data._hand_placement((256, 256))
    a, b, truth = data.hand_pair(200, 180)
    spacing_b = node_spacing(b).mean()
    _, tip_a, _, _, w = data._fingers("open")
    _, tip_b, _, _, _ = data._fingers("closed")
    for k in range(5):
        ta = data._to_rowcol(tip_a[k:k + 1], scale, centre)[0]
        tb = data._to_rowcol(tip_b[k:k + 1], scale, centre)[0]
        i = np.argmin(np.hypot(*(a - ta).T))
        # node i is about w*scale from the tip centre; its partner must be too.
        assert np.hypot(*(b[truth[i]] - tb)) <= w[k] * scale + spacing_b


# --------------------------------------------------------------------------
# smooth_warp
# --------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_smooth_warp(seed):
    c = data.hand_outline("open", n_nodes=300, scale=80.0, center=(128.0, 128.0))
    size = np.ptp(c, axis=0).max()
    wc = data.smooth_warp(c, amplitude=0.05, seed=seed)
    assert wc.shape == c.shape
    disp = wc - c
    mag = np.hypot(*disp.T)
    assert mag.max() <= 0.05 * size + 1e-9
    assert mag.max() >= 0.01 * size, "warp does nothing"
    # Smooth: neighbouring displacements differ much less than the node spacing.
    ddisp = np.hypot(*np.diff(np.vstack([disp, disp[:1]]), axis=0).T)
    assert np.all(ddisp <= 0.6 * node_spacing(c) + 1e-9)
    # Non-rigid: not explained by a translation.
    assert np.std(disp, axis=0).max() > 0.05 * mag.max()
    assert is_simple(wc)
    np.testing.assert_array_equal(wc, data.smooth_warp(c, amplitude=0.05, seed=seed))


def test_smooth_warp_edge_cases():
    c = data.hand_outline("open", n_nodes=64)
    np.testing.assert_array_equal(data.smooth_warp(c, amplitude=0.0), c)
    assert not np.array_equal(data.smooth_warp(c, seed=0), data.smooth_warp(c, seed=1))
    with pytest.raises(ValueError):
        data.smooth_warp(np.zeros((5, 3)))
    with pytest.raises(ValueError):
        data.smooth_warp(c, amplitude=-0.1)


def test_sample_segmentation():
    image, init = data.sample_segmentation()
    assert image.shape == (256, 256) and image.dtype == np.float64
    obj = data.hand((256, 256), pose="open", noise=0.05)
    np.testing.assert_array_equal(image, obj.image)
    np.testing.assert_array_equal(init, obj.init_near)
    assert encloses_without_touching(init, obj.mask, clearance=3.0)

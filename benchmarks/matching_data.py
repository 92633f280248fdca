"""Contour pairs with a known node correspondence that the package's own data
(``napari_physeg.data``) does not make: articulated families for the matching
benchmark (issue 12).

Every outline is a chain of pieces around a body: *limbs* (a capsule: one
straight side out, a half-circle tip, the other side back) and *via* points,
joined by cubic *webs* whose end tangents follow the pieces they join. Each
piece owns a fixed share of a canonical parameter ``s`` in ``[0, 1)``, and
within a piece ``s`` grows with arc length; the same ``s`` is the same
anatomical point in every pose, so the true partner of a node of ``a`` is the
node of ``b`` with the cyclically nearest ``s`` (as for ``data.hand_pair``).

Families:

* ``sliding_hand_pair``: four fingers whose bases *slide* along the top of the
  palm (parallel fingers, no rotation about a joint) from apart to nearly
  touching, and a thumb; finger lengths, widths and gaps vary with the seed;
  rounded, or square (rectangular fingers, sharp corners).
* ``animal_pair``: a quadruped seen from the side whose four legs, neck and
  tail *swing* about their joints (a walking cycle drawn at random).

Coordinates are ``(row, col)`` pixels, contours positively oriented, closed
implicitly. Pairs that would cross themselves are redrawn.
"""

from __future__ import annotations

import numpy as np

from napari_physeg.core.contour import _crossing_pairs

_DENSE = 60  # samples per piece before resampling


def _unit(angle_deg: float) -> np.ndarray:
    a = np.deg2rad(angle_deg)
    return np.array([np.cos(a), np.sin(a)])


def _limb(base, angle, length, width, square=False):
    """A capsule (or, ``square``, a rectangle) leaving the body at ``base``
    along ``angle`` (degrees): (entry point, entry tangent, exit point, exit
    tangent, [pieces])."""
    d = _unit(angle)
    n = np.array([-d[1], d[0]])  # left of d
    base = np.asarray(base, float)
    t = np.linspace(0.0, 1.0, _DENSE)
    out_side = (base - width * n) + t[:, None] * (length * d)
    phi = np.linspace(-np.pi / 2, np.pi / 2, _DENSE)  # from -n round the tip to +n
    if square:
        tip = base + length * d + width * (np.sin(phi)[:, None] * n)
    else:
        tip = base + length * d + width * (np.cos(phi)[:, None] * d + np.sin(phi)[:, None] * n)
    back_side = (base + width * n + length * d) - t[:, None] * (length * d)
    return base - width * n, d, base + width * n, -d, [out_side, tip, back_side]


def _web(p, tp, q, tq, straight=False):
    """Cubic from ``p`` (leaving along ``tp``) to ``q`` (arriving along ``tq``),
    or the straight segment."""
    k = 0.0 if straight else 0.4 * np.linalg.norm(q - p)
    c1, c2 = p + k * tp, q - k * tq
    t = np.linspace(0.0, 1.0, _DENSE)[:, None]
    return (1 - t) ** 3 * p + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t**2 * c2 + t**3 * q


def _chain(anchors, square=False):
    """Dense outline of a list of anchors (``("limb", base, angle, length,
    width)`` or ``("via", point)``), as a list of pieces; ``square``: square
    limb tips and straight joins (a blocky silhouette)."""
    ends = []
    for anchor in anchors:
        if anchor[0] == "limb":
            ends.append(_limb(*anchor[1:], square=square))
        else:
            ends.append([np.asarray(anchor[1], float), None, np.asarray(anchor[1], float), None, []])
    m = len(ends)
    for k, e in enumerate(ends):  # tangent of a via point: along the chord of its neighbours
        if e[1] is None:
            chord = ends[(k + 1) % m][0] - ends[k - 1][2]
            e[1] = e[3] = chord / np.linalg.norm(chord)
    pieces = []
    for k, e in enumerate(ends):
        pieces.extend(e[4])
        nxt = ends[(k + 1) % m]
        pieces.append(_web(e[2], e[3], nxt[0], nxt[1], straight=square))
    return pieces


def _parametrised(pieces, shares):
    """Dense points and canonical parameter: piece ``k`` spans ``shares[k]``."""
    starts = np.concatenate([[0.0], np.cumsum(shares)[:-1]])
    pts, s = [], []
    for piece, s0, share in zip(pieces, starts, shares):
        seg = np.linalg.norm(np.diff(piece, axis=0), axis=1)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        pts.append(piece[:-1])
        s.append(s0 + share * cum[:-1] / max(cum[-1], 1e-12))
    return np.vstack(pts), np.concatenate(s)


def _shares(pieces):
    lengths = np.array([np.linalg.norm(np.diff(p, axis=0), axis=1).sum() for p in pieces])
    return lengths / lengths.sum()


def _resampled(points, s, n, scale, centre):
    """``n`` nodes evenly spaced in arc length, in (row, col) pixels, and their ``s``."""
    closed = np.vstack([points, points[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    t = np.arange(n) * cum[-1] / n
    xy = np.column_stack([np.interp(t, cum, closed[:, 0]), np.interp(t, cum, closed[:, 1])])
    s_n = np.interp(t, cum, np.concatenate([s, [1.0]]))
    rowcol = np.column_stack([-xy[:, 1], xy[:, 0]]) * scale + np.asarray(centre, float)
    # y up -> rows down mirrors the outline: reverse to keep it positively oriented.
    return rowcol[::-1].copy(), s_n[::-1].copy()


def _truth(s_a, s_b):
    d = np.abs(s_a[:, None] - s_b[None, :])
    return np.argmin(np.minimum(d, 1.0 - d), axis=1).astype(np.intp)


def _crosses(nodes) -> bool:
    return len(_crossing_pairs(nodes)) > 0


def _pair(anchors_a, anchors_b, n_a, n_b, scale, centre, square=False):
    pieces_a, pieces_b = _chain(anchors_a, square), _chain(anchors_b, square)
    shares = _shares(pieces_a)  # the canonical parameter is a's arc length, piece by piece
    pa, sa = _parametrised(pieces_a, shares)
    pb, sb = _parametrised(pieces_b, shares)
    a, s_a = _resampled(pa, sa, n_a, scale, centre)
    b, s_b = _resampled(pb, sb, n_b, scale, centre)
    return a, b, _truth(s_a, s_b)


# --------------------------------------------------------------------------
# Families
# --------------------------------------------------------------------------


def _hand_anchors(bases, lengths, widths, thumb_angle):
    """Palm 1 wide (x in [-0.5, 0.5]) and 1 tall (y in [-1, 0]); fingers up from y = 0."""
    anchors = [("via", (0.0, -1.0)), ("via", (0.42, -0.97)),
               ("limb", (0.52, -0.55), thumb_angle, 0.5, 0.1), ("via", (0.5, -0.08))]
    for x, length, width in sorted(zip(bases, lengths, widths), reverse=True):  # right to left: ccw
        anchors.append(("limb", (x, 0.0), 90.0, length, width))
    anchors += [("via", (-0.5, -0.08)), ("via", (-0.42, -0.97))]
    return anchors


def _finger_bases(widths, gaps):
    """Base x of each finger (left to right) for these gaps, centred on the palm."""
    edges = np.concatenate([[0.0], np.cumsum(2 * np.asarray(widths)[:-1] + np.asarray(gaps))])
    x = edges + np.asarray(widths) - widths[0]
    return x - 0.5 * (x[0] + x[-1])


def sliding_hand_pair(n_a: int = 67, n_b: int = 66, *, seed: int = 0, reverse: bool = False,
                      scale: float = 80.0, centre=(128.0, 128.0), square: bool = False):
    """Fingers that slide together along the palm: ``a`` apart, ``b`` nearly
    touching (``reverse`` swaps them); ``square``: rectangular fingers on a
    palm with sharp corners. Returns ``(a, b, truth)``."""
    rng = np.random.default_rng(seed)
    for _ in range(100):
        lengths = rng.uniform(0.5, 0.9, 4)
        widths = rng.uniform(0.055, 0.075, 4)
        apart = _finger_bases(widths, rng.uniform(0.12, 0.2, 3))
        together = _finger_bases(widths, rng.uniform(0.005, 0.015, 3)) + rng.uniform(-0.15, 0.15)
        thumb = rng.uniform(10.0, 40.0)
        poses = (_hand_anchors(apart, lengths, widths, thumb), _hand_anchors(together, lengths, widths, thumb))
        if reverse:
            poses = poses[::-1]
        a, b, truth = _pair(*poses, n_a, n_b, scale, centre, square)
        if not (_crosses(a) or _crosses(b)):
            return a, b, truth
    raise RuntimeError("no uncrossed hand pair drawn")  # pragma: no cover


def _animal_anchors(legs, neck, tail):
    """A quadruped facing +x: body x in [-1, 1], belly at y = 0, back at y = 0.6."""
    hind1, hind2, front1, front2 = legs
    return [
        ("limb", (-0.8, 0.02), -90.0 + hind1, 0.75, 0.085),
        ("limb", (-0.5, 0.0), -90.0 + hind2, 0.75, 0.085),
        ("via", (0.0, -0.04)),
        ("limb", (0.5, 0.0), -90.0 + front1, 0.7, 0.075),
        ("limb", (0.78, 0.02), -90.0 + front2, 0.7, 0.075),
        ("via", (1.05, 0.3)),
        ("limb", (0.95, 0.62), neck, 0.55, 0.14),
        ("via", (0.3, 0.68)),
        ("via", (-0.5, 0.64)),
        ("limb", (-1.02, 0.5), tail, 0.6, 0.04),
        ("via", (-1.05, 0.2)),
    ]


def animal_pair(n_a: int = 67, n_b: int = 66, *, seed: int = 0, scale: float = 55.0, centre=(128.0, 128.0)):
    """A quadruped whose legs, neck and tail swing between two random poses of
    a walking cycle. Returns ``(a, b, truth)``."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        poses = []
        for _pose in range(2):
            phase = rng.uniform(0, 2 * np.pi)
            # Hind legs swing nearly together, front legs against them (a gallop).
            legs = 40.0 * np.sin(phase + np.array([0.0, 0.6, np.pi, np.pi + 0.6])) + rng.normal(0, 5, 4)
            poses.append(_animal_anchors(legs, rng.uniform(0.0, 90.0), rng.uniform(130.0, 230.0)))
        a, b, truth = _pair(*poses, n_a, n_b, scale, centre)
        if not (_crosses(a) or _crosses(b)):
            return a, b, truth
    raise RuntimeError("no uncrossed animal pair drawn")  # pragma: no cover


def _person_anchors(rng):
    """A person seen from the front: torso x in [-0.3, 0.3], y in [0, 1];
    legs from the hips, arms from the shoulders, head from the neck, each at
    an angle drawn at random."""
    return [  # counter-clockwise, from the left hip
        ("limb", (-0.15, 0.0), rng.uniform(-115, -95), 0.9, 0.1),
        ("via", (0.0, -0.02)),
        ("limb", (0.15, 0.0), rng.uniform(-85, -65), 0.9, 0.1),
        ("via", (0.3, 0.3)),
        ("limb", (0.32, 0.85), rng.uniform(-80, 80), 0.7, 0.07),
        ("via", (0.2, 1.0)),
        ("limb", (0.0, 1.05), 90 + rng.uniform(-20, 20), 0.25, 0.12),
        ("via", (-0.2, 1.0)),
        ("limb", (-0.32, 0.85), rng.uniform(100, 260), 0.7, 0.07),
        ("via", (-0.3, 0.3)),
    ]


def person_pair(n_a: int = 66, n_b: int = 64, *, seed: int = 0, scale: float = 60.0, centre=(128.0, 128.0)):
    """A person whose arms, legs and head turn between two random poses (an
    arm may hang close along the body). Held out: not used to design or
    weigh anything. Returns ``(a, b, truth)``."""
    rng = np.random.default_rng(seed)
    for _ in range(100):
        a, b, truth = _pair(_person_anchors(rng), _person_anchors(rng), n_a, n_b, scale, centre)
        if not (_crosses(a) or _crosses(b)):
            return a, b, truth
    raise RuntimeError("no uncrossed person pair drawn")  # pragma: no cover


def held_out_pairs():
    """(name, family, a, b, truth): a family drawn after the method was fixed."""
    out = []
    for seed in range(12):
        na = 66 + seed % 5
        a, b, truth = person_pair(na, 64, seed=seed)
        name = f"person, seed {seed}, {na} x 64"
        if seed % 2:
            a, b, name = noisy(a, 1.5, seed), noisy(b, 1.5, seed + 1), name + ", node noise 1.5 px"
        out.append((name, "person", a, b, truth))
    return out


def noisy(contour, sigma_px: float, seed: int) -> np.ndarray:
    """``contour`` with Gaussian noise of ``sigma_px`` pixels on every node."""
    return contour + np.random.default_rng(seed).normal(0.0, sigma_px, contour.shape)


def articulated_pairs():
    """(name, family, a, b, truth) for the articulated families of the benchmark."""
    out = []
    for seed in range(4):
        for reverse in (False, True):
            na, nb = (67, 66) if seed % 2 == 0 else (60, 70)
            a, b, truth = sliding_hand_pair(na, nb, seed=seed, reverse=reverse)
            way = "together -> apart" if reverse else "apart -> together"
            out.append((f"sliding fingers {way}, seed {seed}, {na} x {nb}", "sliding fingers", a, b, truth))
    for seed in range(2):
        for reverse in (False, True):
            na, nb = (66, 67) if seed == 0 else (70, 62)
            a, b, truth = sliding_hand_pair(na, nb, seed=30 + seed, reverse=reverse, square=True)
            way = "together -> apart" if reverse else "apart -> together"
            out.append((f"square fingers slide {way}, seed {seed}, {na} x {nb}", "sliding fingers", a, b, truth))
    for seed in range(6):
        na, nb = ((67, 66), (70, 60), (64, 64))[seed % 3]
        a, b, truth = animal_pair(na, nb, seed=seed)
        out.append((f"animal legs swing, seed {seed}, {na} x {nb}", "animal legs", a, b, truth))
    for seed in range(4):
        sigma = (1.0, 1.5, 2.0, 1.5)[seed]
        na, nb = (67, 66) if seed % 2 == 0 else (62, 70)
        a, b, truth = sliding_hand_pair(na, nb, seed=10 + seed, reverse=seed % 2 == 1)
        out.append((f"sliding fingers + node noise {sigma} px, seed {seed}, {na} x {nb}", "node noise",
                    noisy(a, sigma, 100 + seed), noisy(b, sigma, 200 + seed), truth))
        a, b, truth = animal_pair(na, nb, seed=10 + seed)
        out.append((f"animal legs + node noise {sigma} px, seed {seed}, {na} x {nb}", "node noise",
                    noisy(a, sigma, 300 + seed), noisy(b, sigma, 400 + seed), truth))
    return out


# --------------------------------------------------------------------------
# The package's own hand (napari_physeg.data.hand_outline) with sliding fingers
# --------------------------------------------------------------------------


def _package_hand_pieces(base, angles):
    """The pieces of ``data._hand_pieces`` with finger bases and angles given
    (the same construction: capsule fingers, Bezier webs, spline palm sides)."""
    from napari_physeg import data as d

    phi = np.deg2rad(np.asarray(angles, dtype=np.float64))
    u = np.column_stack([np.sin(phi), np.cos(phi)])
    n = np.column_stack([np.cos(phi), -np.sin(phi)])
    w = d._FINGER_WIDTH
    tip = base + d._FINGER_LENGTH[:, None] * u
    pieces = []

    def finger(k, start=None):
        start = base[k] + w[k] * n[k] if start is None else start
        pieces.append(d._line(start, tip[k] + w[k] * n[k]))
        pieces.append(d._arc(tip[k], w[k], n[k], u[k]))
        pieces.append(d._line(tip[k] - w[k] * n[k], base[k] - w[k] * n[k]))

    thumb_inner = base[0] + w[0] * n[0] + d._THUMB_WEB_OFFSET * u[0]
    pieces.append(d._spline(np.vstack([d._PALM_RIGHT, base[4] + w[4] * n[4]]), (1.0, 0.0), u[4]))
    for k in (4, 3, 2, 1):
        finger(k)
        nxt = k - 1
        end = thumb_inner if nxt == 0 else base[nxt] + w[nxt] * n[nxt]
        pieces.append(d._bezier(base[k] - w[k] * n[k], -u[k], end, u[nxt]))
    finger(0, start=thumb_inner)
    pieces.append(d._spline(np.vstack([base[0] - w[0] * n[0], d._PALM_LEFT]), -u[0], (1.0, 0.0)))
    return pieces


def package_hand_sliding_pair(n_a: int = 67, n_b: int = 66, *, gap: float = 0.01, shift: float = 0.0,
                              reverse: bool = False, scale: float = 60.0, centre=(128.0, 128.0)):
    """``data.hand_outline``'s hand, fingers straight (parallel), in ``a`` at
    their own bases and in ``b`` slid along the knuckle line until ``gap``
    (hand units) apart, the group moved by ``shift``. Returns ``(a, b, truth)``."""
    from napari_physeg import data as d

    angles = (-45.0, 0.0, 0.0, 0.0, 0.0)
    base_a = d._FINGER_BASE.copy()
    w = d._FINGER_WIDTH
    base_b = base_a.copy()
    x = np.concatenate([[0.0], np.cumsum(w[1:4] + w[2:5] + gap)])  # index .. pinky, touching but for gap
    base_b[1:, 0] = x - x.mean() + base_a[1:, 0].mean() + shift
    poses = [_package_hand_pieces(base_a, angles), _package_hand_pieces(base_b, angles)]
    if reverse:
        poses = poses[::-1]
    shares = _shares(poses[0])
    pa, sa = _parametrised(poses[0], shares)
    pb, sb = _parametrised(poses[1], shares)
    a, s_a = _resampled(pa, sa, n_a, scale, centre)
    b, s_b = _resampled(pb, sb, n_b, scale, centre)
    return a, b, _truth(s_a, s_b)

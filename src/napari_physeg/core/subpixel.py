"""Sub-pixel polish of a contour that already rests on an object's border.

The dynamic phases of :func:`~napari_physeg.core.segment` leave each node a
few hundredths to a few tenths of a pixel off the border: the forces read
smoothed images (the region force balances where a sigma = 1 px blurred image
crosses the mid-level, which moves inward on a convex border by about
``sigma**2 / 2R`` and carries interpolation error), and under noise every node
settles on its own noisy neighbourhood. :func:`polish` measures the border on
the raw image and fits the polygon to it, in one vectorised pass:

1. **Levels.** The object and background levels are the medians, over the
   contour, of the mean intensity 2.5-4 px inside and outside each node
   (medians: a neighbouring object near a few nodes does not move them).
2. **Border crossings.** Along the normal line through points on every edge
   of the polygon (one per 0.75 px, at most 4 per edge), the intensity
   profile, normalised to ``c`` (1 object, 0 background), is averaged over a
   2.5 px box and the border is where that crosses 1/2. For a straight border this is where the box holds as much
   object as background, i.e. where ``integral (c - step(x - d)) dx``
   vanishes, which is exact for an image rendered as pixel-area coverage,
   or blurred by any symmetric kernel narrower than the box, whatever the
   interpolation between pixels. On a curved border the bias is
   ``variance / 2R`` of the pixel and the bilinear interpolation only
   (1/4 px**2: 0.004 px at R = 30 px), not of a 1 px Gaussian.
3. **Noise.** The image noise (Immerkaer's estimate) relative to the
   object / background contrast sets a smoothing length along the contour
   that grows with its square (averaging ``n`` samples divides a variance by
   ``n``) and is zero on a clean image. The polygon is first smoothed by a
   local quadratic fit (Savitzky-Golay, which keeps the curvature) over that
   length, a frame without the node-to-node jitter; the crossings are
   measured from the frame and their *offsets* averaged over the length:
   offsets from a frame that follows the border vary slowly, so averaging
   them does not shrink curved borders as averaging positions would. Where
   the border bends sharply (fingertips, narrow concavities) both lengths
   are cut to a quarter of the local radius of curvature, so corners keep
   their shape.
4. **Least-squares polygon.** The nodes move along their normals so that the
   polygon's *edges*, not only its nodes, fit the measured crossings in the
   least-squares sense (one cyclic tridiagonal solve): on a convex bend the
   nodes end slightly outside the border, by about ``spacing**2 / 12R``, and
   the chords between them no longer cut the object (the pixels a polygon
   with nodes exactly on the border misses: IoU 0.998 instead of 0.9998 on
   ``data.blob()`` at the default spacing).

A node on the image's side (within a quarter pixel of it) has no border
across it to measure: the side is the border of an object the image cuts,
and the node ends on it.

No node moves more than ``reach`` px: the polish corrects a contour at rest
on the border, it does not search for one.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import solve_banded
from scipy.ndimage import correlate1d, gaussian_filter1d, maximum_filter1d

from .contour import _crossing_pairs, crosses_itself, outward_normals, resample, segment_lengths
from .features import _noise_sigma

__all__ = ["polish", "level_along"]

#: Offsets (px) inside and outside a node where the object and background
#: levels are read: beyond the ~2 px over which a pixel-rendered border,
#: bilinearly interpolated, ramps from one level to the other.
_LEVEL_OFFSETS = np.array([2.5, 3.0, 3.5, 4.0])
#: Border measurements per polygon edge (at t = 0, 1/4, 1/2, 3/4 of it):
#: about one every 0.75 px, at most 4 (edges are ~3 px by default).
_PER_EDGE = 4
_PER_PX = 1 / 0.75
#: Sampling step (px) along the normal lines, and the box the profile is
#: averaged over: 2 * _BOX + 1 samples (2.5 px), wider than the ~2 px ramp
#: of a pixel-rendered, bilinearly interpolated border.
_STEP = 0.5
_BOX = 2
#: Smoothing length along the contour (px) per unit of (noise / contrast)**2:
#: 4 px at a noise of 0.1 times the contrast, 16 px (capped to 12) at 0.2,
#: where one crossing alone is off by ~0.15 px.
_NOISE_LENGTH = 400.0
#: Longest smoothing length (px; ~4 node spacings by default), and the
#: largest fraction of the local radius of curvature.
_MAX_LENGTH = 12.0
_BEND = 0.25


def _bilinear(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``image`` at ``points`` (..., 2), in float64 and
    clamped to the image (cv2.remap, used for the forces, quantises positions
    to 1/32 px: too coarse here; a plain gather beats map_coordinates)."""
    h, w = image.shape
    r = np.clip(points[..., 0], 0.0, h - 1.0)
    c = np.clip(points[..., 1], 0.0, w - 1.0)
    r0 = np.minimum(r.astype(np.intp), max(h - 2, 0))
    c0 = np.minimum(c.astype(np.intp), max(w - 2, 0))
    fr, fc = r - r0, c - c0
    flat = image.ravel()
    i = r0 * w + c0
    dr, dc = (w if h > 1 else 0), (1 if w > 1 else 0)
    top = flat[i] + fc * (flat[i + dc] - flat[i])
    bottom = flat[i + dr] + fc * (flat[i + dr + dc] - flat[i + dr])
    return top + fr * (bottom - top)


def _solve_cyclic_tridiagonal(diag: np.ndarray, off: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve ``A x = rhs`` for the symmetric cyclic tridiagonal ``A`` with
    ``A[i, i] = diag[i]`` and ``A[i, i+1] = A[i+1, i] = off[i]`` (indices
    modulo n, n >= 3), by Sherman-Morrison on a banded solve."""
    n = len(diag)
    gamma = -diag[0]
    corner = off[-1]  # A[n-1, 0]
    ab = np.zeros((3, n))
    ab[0, 1:] = off[:-1]
    ab[1] = diag
    ab[2, :-1] = off[:-1]
    ab[1, 0] -= gamma
    ab[1, -1] -= corner * corner / gamma
    u = np.zeros(n)
    u[0], u[-1] = gamma, corner
    y, z = solve_banded((1, 1), ab, np.column_stack([rhs, u]), check_finite=False).T
    v0, v1 = 1.0, corner / gamma
    return y - z * (v0 * y[0] + v1 * y[-1]) / (1.0 + v0 * z[0] + v1 * z[-1])


def _quadratic_weights(m: int) -> np.ndarray:
    """Savitzky-Golay weights of a quadratic fitted to 2m + 1 evenly spaced
    points, evaluated at the middle one (closed form)."""
    j = np.arange(-m, m + 1)
    return (3.0 * (3 * m * m + 3 * m - 1) - 15.0 * j * j) / ((2 * m + 3) * (2 * m + 1) * (2 * m - 1))


def _smooth(values: np.ndarray, sigma, kind: str = "gauss") -> np.ndarray:
    """Smoothing along a closed contour (axis 0) with a per-sample width
    ``sigma`` (in samples), blended linearly between a ladder of fixed widths
    (0, 1/4, 1/2 and 1 times the largest).

    ``kind="gauss"``: Gaussian of standard deviation sigma;
    ``kind="quadratic"``: local quadratic least squares (Savitzky-Golay) over
    +-2 sigma, which keeps the curvature of a smoothed curve."""
    sigma = np.broadcast_to(np.asarray(sigma, dtype=np.float64), values.shape[:1])
    top = float(sigma.max())
    if top < 0.1:
        return values
    ladder = [0.0] + [top * f for f in (0.25, 0.5, 1.0) if top * f >= 0.1]
    levels = [values]
    for s in ladder[1:]:
        if kind == "gauss":
            levels.append(gaussian_filter1d(values, s, axis=0, mode="wrap", truncate=3.0))
        elif 2 <= round(2 * s) and 2 * round(2 * s) + 1 <= len(values):
            levels.append(correlate1d(values, _quadratic_weights(round(2 * s)), axis=0, mode="wrap"))
        else:  # a quadratic through 3 or fewer points is the points
            levels.append(values)
    pos = np.interp(sigma, ladder, np.arange(len(ladder)))
    k = np.minimum(pos.astype(int), len(ladder) - 2)
    f = (pos - k).reshape((-1,) + (1,) * (values.ndim - 1))
    stack = np.stack(levels)
    rows = np.arange(len(sigma))
    return (1 - f) * stack[k, rows] + f * stack[k + 1, rows]


def _curvature_radius(nodes: np.ndarray, span: int) -> np.ndarray:
    """Local radius of curvature at each node (px): the turning angle between
    the chords to the nodes ``span`` before and after it, per unit length
    (wide chords: node jitter does not pass for curvature), taken as the
    largest over those ``2 span + 1`` nodes so a bend is seen before it starts."""
    span = max(int(span), 1)
    a = nodes - np.roll(nodes, span, axis=0)
    b = np.roll(nodes, -span, axis=0) - nodes
    turn = np.abs(np.arctan2(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0], (a * b).sum(1)))
    length = 0.5 * (np.linalg.norm(a, axis=1) + np.linalg.norm(b, axis=1))
    kappa = maximum_filter1d(turn / np.maximum(length, 1e-12), 2 * span + 1, mode="wrap")
    return 1.0 / np.maximum(kappa, 1e-12)


def level_along(image: np.ndarray, line: np.ndarray) -> float:
    """The level of ``image`` along ``line`` as :func:`polish` reads levels:
    the median, over points 1 px apart, of the profile along each point's
    normal averaged over polish's box. Given as ``level=``, it makes polish
    find its crossings on the line itself; read otherwise (on a smoothed
    copy of the image: the border of a convex object is lowered there) the
    crossings lay a few hundredths of a pixel off, and a result started
    from again and again drifted by that much each time."""
    img = np.asarray(image, dtype=np.float64)
    points = resample(np.asarray(line, dtype=np.float64), spacing=1.0)
    along = np.arange(-_BOX, _BOX + 1) * _STEP
    profiles = _bilinear(img, points[:, None, :] + along[None, :, None] * outward_normals(points)[:, None, :])
    return float(np.median(profiles.mean(1)))


def polish(image: np.ndarray, nodes: np.ndarray, *, polarity: int = 0, noise: float | None = None,
           reach: float = 1.5, level: float | None = None) -> np.ndarray:
    """Move the nodes of a contour resting on a border onto it, sub-pixel.

    Parameters
    ----------
    image : (H, W) ndarray
        The raw grey image (any real dtype; a linear rescaling gives the same
        result).
    nodes : (N, 2) ndarray
        Contour on the border (within ``reach`` px), ``(row, col)``.
    polarity : int, optional
        +1 bright object, -1 dark, 0 unknown. When the measured levels
        contradict a known polarity the contour is returned unchanged.
    noise : float, optional
        Standard deviation of the image noise; estimated from the image when
        None.
    reach : float, optional
        Largest move of a node, and farthest crossing accepted (px).
    level : float, optional
        The border's level, in the image's units, when it is known (that of a
        line traced on it); None for halfway between the levels read 2.5-4 px
        inside and outside the nodes.

    Returns
    -------
    ndarray, shape (N, 2)
        The polished nodes (the input unchanged when the image gives no
        usable border).
    """
    img = np.asarray(image, dtype=np.float64)
    nodes = np.asarray(nodes, dtype=np.float64)
    if len(nodes) < 3:
        return nodes
    levels = _border_levels(img, nodes, polarity, level)
    if levels is None:
        return nodes
    outer, contrast = levels
    spacing = float(segment_lengths(nodes).mean())
    sigma_noise = _noise_sigma(img) if noise is None else float(noise)
    frame, normals, local = _averaging_frame(nodes, spacing, sigma_noise / abs(contrast))
    offsets, weights, lines = _crossings(img, frame, normals, spacing, outer, contrast, reach, local)
    move = frame + _normal_moves(normals, lines, offsets, weights)[:, None] * normals - nodes
    # A node on the image's side (or where the dynamics left it, a few
    # hundredths of a pixel off) has no border across it to measure: the side
    # is its border, and it ends there (the smoothed frame, which rounds the
    # corner where the contour leaves the side, is no place for it).
    on_side, onto_side = _on_image_side(nodes, img.shape)
    move[on_side] = onto_side[on_side] - nodes[on_side]
    dist = np.linalg.norm(move, axis=1)
    move *= np.minimum(1.0, reach / np.maximum(dist, 1e-12))[:, None]
    return nodes + _untangled(nodes, move)


def _border_levels(img: np.ndarray, nodes: np.ndarray, polarity: int, level: float | None):
    """The background's level and the object's contrast over it (object
    minus background) read 2.5-4 px either side of the nodes, the
    background's moved so that its half-contrast is ``level`` if that is
    known; None when they show no border, or one of the other polarity."""
    normals = outward_normals(nodes)
    offs = np.concatenate([-_LEVEL_OFFSETS, _LEVEL_OFFSETS])
    ring = _bilinear(img, nodes[:, None, :] + offs[None, :, None] * normals[:, None, :])
    k = len(_LEVEL_OFFSETS)
    inner = float(np.median(ring[:, :k].mean(1)))
    outer = float(np.median(ring[:, k:].mean(1)))
    contrast = inner - outer
    scale = max(float(np.abs(ring).max()), 1e-300)
    if not abs(contrast) > 1e-9 * scale or (polarity and np.sign(contrast) != np.sign(polarity)):
        return None
    if level is not None:  # the crossings of that level, not of the half-level
        outer = float(level) - 0.5 * contrast
    return outer, contrast


def _averaging_frame(nodes: np.ndarray, spacing: float, rel_noise: float):
    """The curve the border is measured across, its normals, and the length
    (px, per node; None for none) the measures are averaged over along it.

    Averaging along the contour: a length growing with the noise variance
    (``rel_noise``: the noise over the contrast), bounded so that a very noisy
    image is not smoothed into a circle, and cut near sharp bends; the frame
    is the nodes smoothed over it."""
    length = min(_NOISE_LENGTH * rel_noise * rel_noise, _MAX_LENGTH)
    if length <= 0.05 * spacing:
        return nodes, outward_normals(nodes), None
    local = np.minimum(length, _BEND * _curvature_radius(nodes, int(np.ceil(length / spacing))))
    frame = _smooth(nodes, local / spacing, kind="quadratic")
    return frame, outward_normals(frame), local


def _crossings(img, frame, normals, spacing: float, outer: float, contrast: float, reach: float, local):
    """Where the border crosses lines across ``frame`` at samples along each
    of its edges: the offsets (N, n_sub) along the lines, their weights (0
    where none is measured; averaged along ``local`` px if given), and the
    lines' directions (N, n_sub, 2)."""
    n = len(frame)
    n_sub = int(np.clip(np.ceil(spacing * _PER_PX), 1, _PER_EDGE))
    t = np.arange(n_sub) / n_sub
    nxt = np.roll(np.arange(n), -1)
    P = (1 - t)[None, :, None] * frame[:, None, :] + t[None, :, None] * frame[nxt][:, None, :]
    M = (1 - t)[None, :, None] * normals[:, None, :] + t[None, :, None] * normals[nxt][:, None, :]
    M /= np.maximum(np.linalg.norm(M, axis=2, keepdims=True), 1e-12)

    step, box = _STEP, _BOX
    half = int(np.ceil(reach / step)) + box + 1
    x = np.arange(-half, half + 1) * step
    prof = _bilinear(img, P[:, :, None, :] + x[None, None, :, None] * M[:, :, None, :])
    c = (prof.reshape(n * n_sub, -1) - outer) * (1.0 / contrast)  # 1 object, 0 background
    cs = np.concatenate([np.zeros((len(c), 1)), np.cumsum(c, axis=1)], axis=1)
    c = (cs[:, 2 * box + 1:] - cs[:, :-2 * box - 1]) * (1.0 / (2 * box + 1)) - 0.5
    xs = x[box:len(x) - box]
    down = (c[:, :-1] > 0) & (c[:, 1:] <= 0)
    up = (c[:, :-1] <= 0) & (c[:, 1:] > 0)
    cross = xs[:-1] + step * c[:, :-1] / np.where(down | up, c[:, :-1] - c[:, 1:], 1.0)
    # One border inside the window: one more object->background crossing
    # than the reverse; noise can add a back-and-forth pair, whose
    # positions then average with the true crossing.
    net = down.sum(1) - up.sum(1)
    b = np.where(down, cross, 0.0).sum(1) - np.where(up, cross, 0.0).sum(1)
    valid = (net == 1) & (np.abs(b) <= reach)
    b = np.where(valid, b, 0.0)
    w = valid.astype(np.float64)
    if local is not None:
        # Weighted average of the valid offsets; a sample without a crossing
        # takes its neighbours' average, with their weight.
        sums = _smooth(np.column_stack([b * w, w]), np.repeat(local / spacing * n_sub, n_sub))
        b = np.where(sums[:, 1] > 1e-6, sums[:, 0] / np.maximum(sums[:, 1], 1e-6), b)
        w = np.maximum(w, sums[:, 1])
    return b.reshape(n, n_sub), w.reshape(n, n_sub), M


def _normal_moves(normals: np.ndarray, lines: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Each node's move along its normal that best puts the edges through
    the crossings ``b`` (weights ``w``) measured along ``lines``.

    Least squares over the edge samples: moving node i by delta_i along its
    normal moves sample (i, t) by (1-t) delta_i (n_i . m) + t delta_{i+1} (n_{i+1} . m)
    along its line m. A small ridge keeps nodes without data on the frame."""
    n_sub = b.shape[1]
    t = np.arange(n_sub) / n_sub
    nxt = np.roll(np.arange(len(normals)), -1)
    a0 = (1 - t)[None, :] * (normals[:, None, :] * lines).sum(2)
    a1 = t[None, :] * (normals[nxt][:, None, :] * lines).sum(2)
    diag = (w * a0 * a0).sum(1) + np.roll((w * a1 * a1).sum(1), 1) + 1e-3
    off = (w * a0 * a1).sum(1)
    rhs = (w * a0 * b).sum(1) + np.roll((w * a1 * b).sum(1), 1)
    return _solve_cyclic_tridiagonal(diag, off, rhs)


#: A node closer than this (px) to the image's side lies on it.
_SIDE_TOLERANCE = 0.25


def _on_image_side(nodes: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
    """Which nodes lie on the image's side (its pixels' outer edge), and the
    nodes moved onto the side they lie on."""
    low, high = -0.5, np.asarray(shape, dtype=np.float64) - 0.5
    near_low, near_high = nodes < low + _SIDE_TOLERANCE, nodes > high - _SIDE_TOLERANCE
    onto = np.where(near_low, low, np.where(near_high, high, nodes))
    return (near_low | near_high).any(axis=1), onto


#: Times a polish's moves near a crossing are halved before they are dropped.
_UNTANGLE_HALVINGS = 4


def _untangled(nodes: np.ndarray, move: np.ndarray) -> np.ndarray:
    """``move`` with the moves that make the polygon ``nodes`` cross itself shrunk.

    Each node moves along its own normal, up to ``reach``: in a concave
    corner sharper than the nodes are spaced, two such moves can carry an
    edge across its neighbour's. The moves of the nodes of crossing edges,
    and their neighbours', are halved until no edge crosses, or dropped
    after a few halvings (a polish never makes a simple contour cross
    itself: with every move dropped it is the contour it was given).
    """
    if crosses_itself(nodes):
        return move  # it crossed itself before: nothing to keep
    n = len(nodes)
    move = move.copy()
    halvings = 0
    while len(pairs := _crossing_pairs(nodes + move)):
        near = (pairs[:, :, None] + np.arange(-1, 3)[None, None, :]).ravel() % n
        move[near] *= 0.5 if halvings < _UNTANGLE_HALVINGS else 0.0
        halvings += 1
    return move

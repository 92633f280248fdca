"""Modal matching of the nodes of two contours (paper section 3).

Pipeline of :func:`match`:

1. **Modal features.** Each contour is modelled with Sclaroff's element and
   its lowest modes are computed in its own canonical frame (centroid,
   principal axes, unit RMS radius; :mod:`.modes`). Node ``i``'s feature is its
   ``(u, v)`` displacement in each selected mode, times ``sqrt(m)`` so that
   shapes with different node counts are comparable (each mode has unit norm,
   so the mean squared per-node entry is ``1/m``). By default the element is
   built on 64 nodes evenly spaced along each contour (``model_nodes``) and the
   modal displacements are interpolated to the contour's nodes.
2. **Sign correction** (mandatory): an eigenvector is defined only up to its
   sign, independently in the two shapes. For each mode the sign of ``b``'s
   feature is chosen that minimises the symmetric nearest-neighbour distance
   between the two shapes' clouds of ``(u, v)`` rows. Two modes of nearly
   equal frequency (a near-round shape has such pairs) are only defined up to
   a mix of the two: for such a pair the rotation or reflection of ``b``'s
   two modes is chosen the same way, every 15 degrees. When a shape's
   principal axes are ill defined (second moments within 20 %), the frame of
   ``b`` is also searched in steps of 45 degrees.
3. **Affinity** (eq. 12): ``Z_ij = sum_k |u_a,ik - u_b,jk|^2 + |v_a,ik - v_b,jk|^2``
   (0 is a perfect match), returned as :attr:`Matching.affinity`.
4. **Matching cost** ``C = modal_weight * Z / n_modes + curvature_weight * Kc
   + context_weight * H``: low modes vary slowly along the contour, so ``Z``
   alone is coarse; ``Kc`` compares a multi-scale curvature signature; ``H``
   compares inner-distance shape contexts (:mod:`.inner_distance`), which do
   not change when a part turns about its joint or slides along the body,
   where the modes of the whole shape do. All are invariant to translation,
   rotation and scale. For ``global`` the cost is then averaged along its
   diagonals over a ``neighbourhood`` (a quarter of the perimeter), so that a
   node matches where its neighbours do.
5. **Search**: ``local`` (Shapiro & Brady mutual minima), ``global`` (assignment
   with fictitious nodes, Bastos & Tavares 2006) or ``order`` (cyclic
   order-preserving dynamic programming, Oliveira & Tavares 2008). ``order``
   first runs the DP around every start, on a copy of ``C`` coarsened to at
   most 100 nodes per contour, then again at full resolution about the best
   start regions: no start is left untried.
6. **Refinement** (default for ``order``, optional for the others): the drift
   of the pairs along the contour is smoothed and the search runs again with a
   penalty for leaving the smoothed path, which removes node-to-node jitter
   (it helps where one contour has many more nodes; its net gain on the
   benchmark is small).
7. **Detail pass** (``order``, on dense smooth contours): a last search within
   a few node spacings of the path on curvature at 1-4 node spacings, which
   pins articulated parts the coarser terms leave a few nodes off.

Every feature is measured on the positively oriented contours from the node
farthest from the centroid, so the result does not depend on where the
caller's numbering starts or which way it runs. The measured effect of each
stage is in ``docs/benchmarks.md`` (section "Matching"). Coordinates are
``(row, col)``; contours are closed implicitly.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from ._drain import drain
from .contour import resample, rotation_between, rotation_matrix, segment_lengths, signed_area, warn_if_figure_eight
from .inner_distance import inner_distance_context
from .materials import Material, get_material
from ._validation import check_callback, check_contour, check_count, check_number, with_defaults
from .modes import DEGENERACY_TOLERANCE, MAX_AUTO_MODES, ModalBasis, _modal_raw, select_modes, truncate

__all__ = [
    "Matching",
    "MatchingCancelled",
    "MatchingProgress",
    "match",
    "iter_match",
    "modal_affinity",
    "curvature_signature",
    "roughness",
    "METHODS",
]

#: Search methods of :func:`match`.
METHODS = ("local", "global", "order")

#: Curvature signature scales, as fractions of the perimeter (the finest is
#: raised to one node spacing of the coarser contour in :func:`match`).
_CURVATURE_SCALES = (0.0025, 0.005, 0.01, 0.025, 0.06)
#: Smoothing width (fraction of the perimeter) of the refinement pass.
_REFINE_WIDTH = 0.02
#: Weight of the refinement's drift penalty per squared node, relative to the order penalty.
_DRIFT_WEIGHT = 0.1
#: Scales of the detail pass, in node spacings of the coarser contour.
_DETAIL_SCALES = (1.0, 2.0, 4.0)
#: Half-width of the detail pass's band around the previous path, in node spacings.
_DETAIL_BAND = 8.0
#: Pull of the detail pass toward the smoothed previous path on rows where the
#: fine curvature is flat, per squared node of b, relative to its repeat /
#: skip penalty (a third of the refinement's: the curvature decides where it
#: varies, the previous path where it says nothing).
_DETAIL_DRIFT_WEIGHT = 0.03
#: Repeat / skip penalty of the detail pass, relative to its mean cost.
_DETAIL_PENALTY = 0.5
#: Contours with at least this many nodes get the detail pass (below it, the
#: finest signature scale, 1 / min(Na, Nb) of the perimeter, already reaches
#: down to one node spacing).
_DETAIL_MIN_NODES = int(round(1.0 / _CURVATURE_SCALES[0]))
#: Median normal deviation of a node from the chord of its neighbours, in node
#: spacings, above which a contour counts as too rough for the detail pass
#: (measured: <= 0.06 on smooth outlines at 60 to 1000 nodes, 0.2-0.3 with
#: node noise of 0.3 spacing).
_DETAIL_ROUGHNESS = 0.1
#: Half-width of the free start of ``order``, as a fraction of b's node count.
_START_WINDOW = 0.02
#: Nodes per contour of the coarse search over every start (``order``).
_COARSE_NODES = 100
#: Windows of free starts the coarse search tiles b with (one DP each).
_COARSE_WINDOWS = 12
#: Samples of each contour the inner-distance shape context is computed on.
_CONTEXT_SAMPLES = 100
#: Default ``neighbourhood`` of ``global``: the span, as a fraction of the
#: perimeter, over which the cost is averaged along its diagonals.
_GLOBAL_NEIGHBOURHOOD = 0.25
#: Offsets the neighbourhood average samples.
_NEIGHBOURHOOD_TERMS = 9
#: The displacement term's unit is C's typical best pairs, or, when C
#: between the nearest nodes is more than this many times that, C between
#: them over this: the modes of a symmetric shape (an ellipse, a disk) may
#: take opposite signs on two consecutive frames, and C's best pairs then lie
#: half a turn away at almost no cost, where a term in their units vanished
#: (a slowly turning ellipse tracked: every origin half a turn off, normal
#: velocities of 20 px/frame). On the time-lapse nuclei matched in place C
#: between nearest nodes is at most 6 times C's best pairs.
_FLIPPED_MODES = 10.0
#: Anisotropy (minor / major second moment) above which the frame of b is searched.
_ISOTROPIC = 0.8
#: Mixings of a near-degenerate pair of modes tried (see _pair_mixings): a
#: rotation and a reflection every 15 degrees (every 10 was no better).
_MIX_ANGLES = 24
#: The modes' signs and mixes fitted along the shape's own path replace
#: those read from the modes' clouds only when the coarse search's
#: objective with them is at most this share of that with the clouds' (see
#: _matching_cost): coins matched half a turn off gave 0.2-0.3; hands whose
#: clouds were right, 0.91-0.92, where the fit, which follows the shape's
#: path, lost up to 0.026 of the nodes.
_CLEARLY_CHEAPER = 0.8
#: The clouds of modal feature rows are compared on at most this many rows
#: of each contour (see _group_best, _mode_correction).
_JOINT_ROWS = 256


class MatchingCancelled(RuntimeError):
    """Kept importable for older callers; no longer raised.

    A cancelled matching (``callback`` returned False, or ``True`` sent into
    :func:`iter_match`) returns a :class:`Matching` with
    ``stop_reason="cancelled"``, as every other result of the core does.
    """


@dataclass(frozen=True, eq=False)
class Matching:
    """Correspondence between the nodes of two contours.

    Attributes
    ----------
    pairs : ndarray of int, shape (K, 2)
        Row ``k`` matches node ``pairs[k, 0]`` of ``a`` with node ``pairs[k, 1]``
        of ``b``, sorted by the node of ``a``. A node of ``a`` appears at most
        once; a node of ``b`` may appear more than once when ``a`` has more
        nodes (``global`` and ``order``).
    affinity : ndarray of float, shape (Na, Nb)
        Sign-corrected modal affinity ``Z`` (eq. 12); 0 is a perfect match.
    unmatched : ndarray of int
        Nodes of ``a`` without a partner (ascending).
    cost : ndarray of float, shape (K,)
        Matching cost of each pair in the final search: ``cost_matrix`` at
        ``pairs``.
    method : str
        ``"local"``, ``"global"`` or ``"order"``.
    cost_matrix : ndarray of float, shape (Na, Nb)
        The matrix the final search (before the detail pass) minimised:
        ``modal_weight x affinity / n_modes`` plus the curvature and
        inner-distance context terms (averaged over the ``neighbourhood``
        for ``global``), plus the drift penalty after a refinement.
    unmatched_b : ndarray of int
        Nodes of ``b`` that no node of ``a`` is matched to (ascending).
    n_modes : int
        Number of modes in the affinity.
    signs : ndarray of float, shape (n_modes,)
        Sign applied to each mode of ``b`` by the sign correction (for the
        two modes of a near-degenerate pair, which it mixes, the sign of each
        one's own share in its mix).
    frame_rotation : float
        Extra rotation (radians) applied to ``b``'s modal vectors when its
        principal axes are ill defined (0 otherwise).
    refined : bool
        Whether the refinement pass ran.
    detail_refined : bool
        Whether the detail pass ran (see :func:`match`).
    stop_reason : str
        ``"completed"``, or ``"cancelled"`` when stopped by ``callback`` or
        :func:`iter_match`: the pairs are then those of the last finished
        search (none before the first one finished).
    total_cost : float
        Objective of the final search (for ``order`` including the repeat,
        skip and gap penalties).
    basis_a, basis_b : ModalBasis
        The modal bases (``b``'s before the sign correction).
    """

    pairs: np.ndarray
    affinity: np.ndarray
    unmatched: np.ndarray
    cost: np.ndarray
    method: str
    cost_matrix: np.ndarray = field(repr=False)
    unmatched_b: np.ndarray
    n_modes: int
    signs: np.ndarray
    frame_rotation: float
    refined: bool
    total_cost: float
    basis_a: ModalBasis = field(repr=False)
    basis_b: ModalBasis = field(repr=False)
    detail_refined: bool = False
    stop_reason: str = "completed"

    @property
    def partner(self) -> np.ndarray:
        """``partner[i]``: node of ``b`` matched to node ``i`` of ``a``, or -1."""
        out = np.full(self.affinity.shape[0], -1, dtype=np.intp)
        out[self.pairs[:, 0]] = self.pairs[:, 1]
        return out

    def __repr__(self) -> str:
        na, nb = self.affinity.shape
        return (f"Matching(method={self.method!r}, {len(self.pairs)} pairs, {na} x {nb} nodes, "
                f"{len(self.unmatched)} unmatched in a, {len(self.unmatched_b)} unmatched in b, "
                f"n_modes={self.n_modes}, refined={self.refined}, stop_reason={self.stop_reason!r})")


# --------------------------------------------------------------------------
# Contour helpers
# --------------------------------------------------------------------------


def _canonical_order(nodes: np.ndarray) -> np.ndarray:
    """Index map that makes the contour positively oriented and starts it at
    the node farthest from the centroid.

    Every feature of the matching (model nodes, curvature signature, arc
    positions, start candidates) is measured from node 0; starting at a node
    the geometry picks makes the matching independent of where the caller's
    numbering starts and of its direction.
    """
    m = len(nodes)
    # An area that is zero but for rounding (a balanced figure-8) has no
    # orientation: its sign would follow where the numbering starts, and
    # flip one of two copies of a contour. The caller's direction is kept.
    area, scale = signed_area(nodes), float(np.sum(np.ptp(nodes, axis=0))) ** 2
    order = (-np.arange(m)) % m if area < -1e-9 * scale else np.arange(m)
    centred = nodes - nodes.mean(axis=0)
    start = int(np.argmax(np.einsum("ij,ij->i", centred, centred)[order]))
    return np.roll(order, -start)


def _arc_positions(nodes: np.ndarray):
    """Normalised arc-length position of every node (node 0 at 0) and the perimeter."""
    seg = segment_lengths(nodes)
    total = float(seg.sum())
    t = np.concatenate([[0.0], np.cumsum(seg)[:-1]]) / total
    return t, total


def curvature_signature(nodes, scales=_CURVATURE_SCALES, *, saturation: float = 8.0) -> np.ndarray:
    """Multi-scale, bounded, scale-invariant curvature at every node.

    The contour is resampled evenly in arc length, its coordinates are
    differentiated with Gaussian derivative filters in the Fourier domain at
    each scale (a fraction of the perimeter ``L``), and the curvature ``k`` is
    normalised to ``k L / (2 pi)`` (1 on a circle) and compressed with
    ``(2 / pi) arctan(. / saturation)``.

    Parameters
    ----------
    nodes : array_like, shape (m, 2)
        Contour nodes ``(row, col)``, positively oriented (convex parts then
        have positive curvature).
    scales : sequence of float, optional
        Gaussian widths as fractions of the perimeter.
    saturation : float, optional
        Normalised curvature at which the compression reaches half its range.

    Returns
    -------
    ndarray, shape (m, len(scales))
        Values in (-1, 1).
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    t, total = _arc_positions(nodes)
    n = 1024
    while n < 4 * len(nodes):
        n *= 2
    closed_t = np.concatenate([t, [1.0]])
    s = np.arange(n) / n
    z = (np.interp(s, closed_t, np.concatenate([nodes[:, 0], nodes[:1, 0]]))
         + 1j * np.interp(s, closed_t, np.concatenate([nodes[:, 1], nodes[:1, 1]])))
    Zf = np.fft.fft(z)
    omega = 2.0 * np.pi * np.fft.fftfreq(n, d=1.0 / n)  # per unit of normalised arc length
    out = np.empty((len(nodes), len(scales)))
    for k, width in enumerate(scales):
        g = np.exp(-0.5 * (omega * width) ** 2)
        z1 = np.fft.ifft(Zf * (1j * omega) * g)
        z2 = np.fft.ifft(Zf * (1j * omega) ** 2 * g)
        speed = np.maximum(np.abs(z1), 1e-300)
        kappa = np.imag(np.conj(z1) * z2) / speed**3  # 1 / pixel (parametrisation invariant)
        kappa_n = kappa * total / (2.0 * np.pi)  # 1 on a circle
        at_nodes = np.interp(t * n, np.arange(n + 1), np.concatenate([kappa_n, kappa_n[:1]]))
        out[:, k] = (2.0 / np.pi) * np.arctan(at_nodes / saturation)
    return out


def _context_at_nodes(nodes: np.ndarray, t: np.ndarray, n_samples: int) -> np.ndarray:
    """Inner-distance shape context of every node: that of the evenly spaced
    samples (:func:`.inner_distance.inner_distance_context`), linearly
    interpolated in arc length (``t``, node 0 at 0, as the samples)."""
    ctx = inner_distance_context(nodes, n_samples)
    m = len(ctx)
    pos = t * m
    lo = np.floor(pos).astype(np.intp) % m
    w = (pos - np.floor(pos))[:, None]
    return (1.0 - w) * ctx[lo] + w * ctx[(lo + 1) % m]


# --------------------------------------------------------------------------
# Affinity
# --------------------------------------------------------------------------


def _features(basis: ModalBasis, k: int) -> np.ndarray:
    return basis.shapes[:, :k, :] * np.sqrt(basis.n_nodes)


def _cloud_distance(A: np.ndarray, B: np.ndarray, ta: cKDTree, tb: cKDTree) -> float:
    return float(tb.query(A)[0].mean() + ta.query(B)[0].mean())


def _mode_groups(basis_a: ModalBasis, basis_b: ModalBasis, k: int) -> list[tuple[int, ...]]:
    """The first ``k`` modes as single modes and near-degenerate pairs.

    Modes ``j`` and ``j + 1`` form a pair when their gap, in either
    spectrum, is below DEGENERACY_TOLERANCE times its mean gap (as
    :func:`~.modes.select_modes` reads it): each is then an arbitrary
    mixture of the two, which two resamplings of one near-round shape mix
    differently."""
    def gaps(basis):
        g = np.diff(basis.spectrum)
        return g < DEGENERACY_TOLERANCE * max(float(g.mean()), 1e-300)

    close = gaps(basis_a)[: k - 1] | gaps(basis_b)[: k - 1]
    groups, j = [], 0
    while j < k:
        width = 2 if j + 1 < k and close[j] else 1
        groups.append(tuple(range(j, j + width)))
        j += width
    return groups


def _pair_mixings() -> np.ndarray:
    """The (2, 2) mixings tried for a near-degenerate pair (see
    _mode_correction): rotations and reflections every 360 / _MIX_ANGLES
    degrees; row ``i`` gives the new mode ``i`` as a mix of the old two."""
    angles = 2 * np.pi * np.arange(_MIX_ANGLES) / _MIX_ANGLES
    c, s = np.cos(angles), np.sin(angles)
    rotations = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], 1)
    return np.concatenate([rotations, rotations * np.array([1.0, -1.0])[None, :, None]])


def _mixed(q: np.ndarray, features: np.ndarray) -> np.ndarray:
    """Modal features ``(m, modes, 2)`` remixed by ``q``: new mode ``i`` is ``sum_j q[i, j]`` old mode ``j``
    (a sign, for one mode; a rotation or reflection, for a pair)."""
    return np.einsum("pq,mqd->mpd", q, features)


def _group_best(fa: np.ndarray, fb: np.ndarray, cols: list[int]) -> np.ndarray:
    """The correction of ``b``'s modes ``cols`` (a single mode's sign, or a
    pair's mixing, see _pair_mixings) that leaves the two clouds of their
    feature rows closest (symmetric nearest-neighbour distance), on at most
    _JOINT_ROWS rows of each."""
    fa, fb = fa[:: max(1, len(fa) // _JOINT_ROWS)], fb[:: max(1, len(fb) // _JOINT_ROWS)]
    A = fa[:, cols].reshape(len(fa), -1)
    tree_a = cKDTree(A)
    best = None
    for q in (_pair_mixings() if len(cols) == 2 else np.array([[[1.0]], [[-1.0]]])):
        B = _mixed(q, fb[:, cols]).reshape(len(fb), -1)
        distance = _cloud_distance(A, B, tree_a, cKDTree(B))
        if best is None or distance < best[0] - 1e-12:
            best = (distance, q)
    return best[1]


def _mode_correction(fa: np.ndarray, fb: np.ndarray, groups, frames=(0.0,)):
    """``b``'s modal features turned toward ``a``'s without knowing which
    nodes correspond: (corrected features, each mode's sign, frame rotation).

    In each of ``frames`` (rotations of ``b``'s frame), each single mode's
    sign and each near-degenerate pair's mixing is chosen by the clouds of
    its own feature rows (see _group_best); then each mode's half turn (its
    sign) is flipped while that brings the clouds of whole feature rows
    closer: modes chosen one at a time need not agree on one
    correspondence (a mode of a shape nearly symmetric under a half turn has
    a nearly symmetric cloud, and its sign is chosen by chance). The frame
    whose whole rows come closest is kept. A pair's modes report the sign
    of their own share in their mix.
    """
    flat_a = fa.reshape(len(fa), -1)[:: max(1, len(fa) // _JOINT_ROWS)]
    tree_a = cKDTree(flat_a)

    def joint(features):
        flat_b = features.reshape(len(features), -1)[:: max(1, len(features) // _JOINT_ROWS)]
        return _cloud_distance(flat_a, flat_b, tree_a, cKDTree(flat_b))

    best = None
    for theta in frames:
        corrected = _rotate(fb, theta) if theta else fb.copy()
        signs = np.ones(fa.shape[1])
        for group in groups:
            cols = list(group)
            q = _group_best(fa, corrected, cols)
            corrected[:, cols] = _mixed(q, corrected[:, cols])
            signs[cols] = np.where(np.diag(q) < 0, -1.0, 1.0)
        distance = joint(corrected)
        for _ in range(len(groups)):  # each pass flips at least one group, or ends
            flipped = False
            for group in groups:
                cols = list(group)
                corrected[:, cols] *= -1
                trial = joint(corrected)
                if trial < distance - 1e-12:
                    distance, flipped = trial, True
                    signs[cols] *= -1
                else:
                    corrected[:, cols] *= -1
            if not flipped:
                break
        if best is None or distance < best[0] - 1e-12:
            best = (distance, corrected, signs, theta)
    return best[1:]


def _fitted_along(fa: np.ndarray, fb: np.ndarray, basis_a: ModalBasis, basis_b: ModalBasis, groups,
                  partner: np.ndarray):
    """``b``'s modal features turned toward ``a``'s along a correspondence
    (``partner[i]``: the node of ``b`` paired with node ``i`` of ``a``, or
    -1), as (corrected features, each mode's sign, frame rotation; see
    _mode_correction).

    The rotation of ``b``'s canonical frame that brings the paired nodes
    closest is found first (the frames of near-round shapes are ill
    defined), then each single mode's sign and each pair's rotation or
    reflection that brings the paired feature rows closest (orthogonal
    Procrustes, both)."""
    ok = partner >= 0
    theta = rotation_between(basis_b.nodes[partner[ok]], basis_a.nodes[ok])
    turned = _rotate(fb, theta)
    corrected = turned.copy()
    signs = np.ones(fa.shape[1])
    for group in groups:
        cols = list(group)
        u, _, vt = np.linalg.svd(np.einsum("npd,nqd->pq", fa[ok][:, cols], turned[partner[ok]][:, cols]))
        q = u @ vt
        corrected[:, cols] = _mixed(q, turned[:, cols])
        signs[cols] = np.where(np.diag(q) < 0, -1.0, 1.0)
    return corrected, signs, theta


def _rotate(f: np.ndarray, theta: float) -> np.ndarray:
    """Modal features ``f`` (their last axis the ``(u, v)`` displacement) turned by ``theta``."""
    return f @ rotation_matrix(theta).T


#: Rotations of ``b``'s frame tried when the principal axes are ill defined
#: (a half turn is a sign, see _mode_correction).
_FRAME_ROTATIONS = (0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4)


def _pairwise_sq(fa: np.ndarray, fb: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances between the rows of two (n, d) arrays."""
    aa = np.einsum("ij,ij->i", fa, fa)
    bb = np.einsum("ij,ij->i", fb, fb)
    d = aa[:, None] + bb[None, :] - 2.0 * fa @ fb.T
    return np.maximum(d, 0.0)


def modal_affinity(basis_a: ModalBasis, basis_b: ModalBasis, n_modes: int | None = None,
                   *, sign_correction: bool = True):
    """Sign-corrected modal affinity (eq. 12) between two modal bases.

    Parameters
    ----------
    basis_a, basis_b : ModalBasis
        Modal bases of the two shapes (see :func:`~.modes.modal_basis`).
    n_modes : int, optional
        Number of modes used; default the smaller of the two bases' counts.
    sign_correction : bool, optional
        Choose each mode's sign in ``b`` against ``a`` (default). Turning it
        off is only useful to measure what it buys.

    Returns
    -------
    Z : ndarray, shape (Na, Nb)
        ``Z_ij = sum_k |u_a,ik - u_b,jk|^2 + |v_a,ik - v_b,jk|^2`` over the
        selected modes, with modal vectors scaled by ``sqrt(m)`` so that shapes
        with different node counts are comparable. Non-negative; 0 is a
        perfect match.
    signs : ndarray, shape (n_modes,)
        The signs applied to ``b``'s modes.

    Raises
    ------
    ValueError
        If ``n_modes`` exceeds the modes available.
    """
    kmax = min(basis_a.n_modes, basis_b.n_modes)
    k = kmax if n_modes is None else int(n_modes)
    if not 1 <= k <= kmax:
        raise ValueError(f"n_modes must be between 1 and {kmax}, got {n_modes!r}")
    fa, fb = _features(basis_a, k), _features(basis_b, k)
    if sign_correction:
        fb, signs, _ = _mode_correction(fa, fb, _mode_groups(basis_a, basis_b, k))
    else:
        signs = np.ones(k)
    return _pairwise_sq(fa.reshape(len(fa), -1), fb.reshape(len(fb), -1)), signs


# --------------------------------------------------------------------------
# Searches
# --------------------------------------------------------------------------


def _local(C: np.ndarray) -> np.ndarray:
    """Shapiro & Brady: ``i <-> j`` when ``C_ij`` is the minimum of its row and column."""
    rows = np.argmin(C, axis=1)
    cols = np.argmin(C, axis=0)
    i = np.arange(C.shape[0])
    keep = cols[rows] == i
    return np.where(keep, rows, -1)


def _fill_by_neighbours(part: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Bastos & Tavares: a node of ``a`` without a partner gets the node of
    lowest cost among the nodes of ``b`` between the partners of its nearest
    matched neighbours (both inclusive, cyclically)."""
    na, nb = C.shape
    matched = np.flatnonzero(part >= 0)
    if len(matched) == 0:
        return np.argmin(C, axis=1)
    out = part.copy()
    for i in np.flatnonzero(part < 0):
        pos = np.searchsorted(matched, i)
        prev = matched[pos - 1] if pos > 0 else matched[-1]
        nxt = matched[pos] if pos < len(matched) else matched[0]
        lo, hi = part[prev], part[nxt]
        span = (hi - lo) % nb
        if span > nb // 2:  # partners out of order: take the shorter arc the other way
            lo, span = hi, (lo - hi) % nb
        cand = (lo + np.arange(span + 1)) % nb
        out[i] = cand[np.argmin(C[i, cand])]
    return out


def _global(C: np.ndarray, fill: bool = True) -> np.ndarray:
    """Assignment on ``C`` with fictitious nodes padding the smaller shape."""
    na, nb = C.shape
    n = max(na, nb)
    big = np.zeros((n, n))  # fictitious rows / columns cost nothing
    big[:na, :nb] = C
    r, c = linear_sum_assignment(big)
    part = np.full(na, -1, dtype=np.intp)
    real = (r < na) & (c < nb)
    part[r[real]] = c[real]
    if fill and na > nb:
        part = _fill_by_neighbours(part, C)
    return part


def _order_dp(C: np.ndarray, nb: int, window: int, repeat: float, skip: float, gap: float):
    """Order-preserving alignment of all nodes of ``a`` along ``b``.

    ``C`` has ``nb + 2 * window`` columns: ``b``'s nodes from ``window`` before
    the candidate start node to ``window`` after it, once around. Node 0 of
    ``a`` is matched to one of the first ``2 * window + 1`` columns (a free
    start); every later node of ``a`` is matched to the partner of the
    previous one (``repeat``), to a later column (``skip`` for each node of
    ``b`` passed over) or left unmatched (``gap``). The path may not use a
    node of ``b`` twice around: its last column is less than ``nb`` after its
    first, and the nodes left over between the end and the start count as
    skipped.

    Returns
    -------
    part : ndarray of int, shape (na,)
        Column of each node's partner, or -1.
    total : float
    """
    na, width = C.shape
    inf = np.inf
    ks = np.arange(width)
    ramp = skip * ks
    # The choices, written as they are made: the best column before each
    # column j + 1 when advancing to it, and whether each column repeated
    # (else advanced, or with a finite ``gap`` was left unmatched).
    from_adv = np.zeros((na, width), dtype=ks.dtype)
    repeated = np.zeros((na, width), dtype=bool)
    may_gap = np.isfinite(gap)  # the default never leaves a node unmatched: three operations fewer a row
    gapped = np.zeros((na, width), dtype=bool) if may_gap else None
    F = np.full(width, inf)
    F[: 2 * window + 1] = C[0, : 2 * window + 1]
    start = ks.copy()
    adv = np.full(width, inf)
    adv_start = np.empty(width, dtype=start.dtype)
    vals, pm, rep = (np.empty(width) for _ in range(3))
    at_min = np.empty(width, dtype=bool)
    # Each row is a dozen operations on a few dozen columns: their buffers
    # (and views of them) are made once, and every result written in place
    # (numpy's call overhead, not the arithmetic, is most of the time).
    pm_before, ramp_after, adv_after = pm[:-1], ramp[1:], adv[1:]
    for i in range(1, na):
        np.subtract(F, ramp, out=vals)
        np.minimum.accumulate(vals, out=pm)
        arg = from_adv[i]  # the column of the running minimum: its last occurrence
        np.less_equal(vals, pm, out=at_min)
        np.multiply(at_min, ks, out=arg)
        np.maximum.accumulate(arg, out=arg)
        np.add(pm_before, ramp_after, out=adv_after)
        adv_after -= skip
        np.add(F, repeat, out=rep)
        use_rep = np.less(rep, adv, out=repeated[i])
        D = np.where(use_rep, rep, adv)
        D += C[i]
        kept = use_rep  # where the path did not advance
        if may_gap:
            G = F + gap
            use_gap = np.less(G, D, out=gapped[i])
            D[use_gap] = G[use_gap]
            kept = use_rep | use_gap
        F = D
        adv_start[0] = start[0]
        np.take(start, arg[:-1], out=adv_start[1:])
        np.copyto(adv_start, start, where=kept)
        start, adv_start = adv_start, start
    span = ks - start
    end = np.where(span <= nb - 1, F + skip * (nb - 1 - span), inf)
    j = int(np.argmin(end))
    total = float(end[j])
    part = np.full(na, -1, dtype=np.intp)
    for i in range(na - 1, 0, -1):
        if may_gap and gapped[i, j]:
            continue
        part[i] = j
        if not repeated[i, j]:  # advanced (never into column 0, whose advance costs inf)
            j = int(from_adv[i, j - 1]) if j > 0 else 0
    part[0] = j
    return part, total


def _iter_every_start(C: np.ndarray, penalty: float, gap: float):
    """The order-preserving search run around *every* start, on a coarse
    copy of ``C``: yields the fraction done, returns ``(total, part, step)``
    for each window of starts, best first (``part`` indexes the coarse
    copy, whose columns are every ``step``-th node of ``b``).

    ``C`` is sub-sampled to at most :data:`_COARSE_NODES` nodes per contour
    and the DP run once per window of free starts, the windows tiling ``b``.
    Each window's best alignment is scored by the DP's own objective, not by
    a uniform-rate guess (which a part that slid along the body fools), so no
    start region is left untried: the match cannot lock onto a wrong start
    because the right one was never looked at.
    """
    na, nb = C.shape
    step_a, step_b = max(1, -(-na // _COARSE_NODES)), max(1, -(-nb // _COARSE_NODES))
    # Each coarse entry is the cheapest of its block: a narrow valley of
    # the cost (one node wide on a dense contour) cannot fall between samples.
    Cc = np.minimum.reduceat(np.minimum.reduceat(C, np.arange(0, na, step_a), axis=0),
                             np.arange(0, nb, step_b), axis=1)
    ncb = Cc.shape[1]
    window = max(1, min((ncb - 1) // 2, -(-ncb // _COARSE_WINDOWS) // 2))
    centres = range(0, ncb, 2 * window + 1)
    found = []
    for k, centre in enumerate(centres):
        cols = (centre - window + np.arange(ncb + 2 * window)) % ncb
        part, total = _order_dp(Cc[:, cols], ncb, window, penalty, penalty, gap)
        found.append((total, np.where(part >= 0, cols[np.maximum(part, 0)], -1), step_b))
        yield (k + 1) / len(centres)
    found.sort(key=lambda item: item[0])
    return found


def _order_search(C, t_a, t_b, starts, arc_weight, penalty, gap, window):
    """Run the DP around each candidate start node of ``b`` (free within
    ``window`` nodes), yielding after each start the fraction of the starts
    done; return the best (part, total)."""
    na, nb = C.shape
    window = int(min(window, max((nb - 1) // 2, 0)))
    best = (None, np.inf)
    for k, s in enumerate(starts):
        cols = (s - window + np.arange(nb + 2 * window)) % nb
        Cs = C[:, cols]
        if arc_weight > 0:
            tb = (t_b[cols] - t_b[s]) % 1.0
            tb[:window] -= 1.0
            tb[window + nb:] += 1.0
            d = t_a[:, None] - tb[None, :]
            Cs = Cs + arc_weight * d * d
        part, total = _order_dp(Cs, nb, window, penalty, penalty, gap)
        if total < best[1]:
            best = (np.where(part >= 0, cols[np.maximum(part, 0)], -1), total)
        yield (k + 1) / len(starts)
    return best


def _iter_search(method, C, t_a, t_b, *, arc_weight, n_starts, gap, penalty, start=None, coarse=None):
    """One pass of the chosen search on cost ``C``: a generator that yields
    the fraction of the pass done and returns (partners, total). ``coarse``:
    the coarse order search of ``C``, if already run (see _coarse_search)."""
    na, nb = C.shape
    if method == "local":
        part = _local(C)
    elif method == "global":
        part = _global(C)
    else:
        window = max(2, int(np.ceil(_START_WINDOW * nb)))
        if start is not None:
            return (yield from _order_search(C, t_a, t_b, [start], arc_weight, penalty, gap, window))
        share = 0.3  # of the progress: the coarse DPs are small
        found = coarse or (yield from _scale_fractions(_iter_every_start(C, penalty, gap), 0.0, share))
        # Each of the best windows searched again at full resolution, with a
        # narrow free start (+-2 % of b's nodes) about its start node: the DP
        # keeps one start per cell, so a narrow window loses less to it.
        starts = [int(part[np.flatnonzero(part >= 0)[0]]) * step if np.any(part >= 0) else 0
                  for _, part, step in found[:n_starts]]
        return (yield from _scale_fractions(_order_search(C, t_a, t_b, starts, arc_weight, penalty, gap, window),
                                            share, 1.0))
    ok = part >= 0
    yield 1.0
    return part, float(C[ok, part[ok]].sum())


def _scale_fractions(run, lo: float, hi: float):
    """Re-yield a sub-generator's fractions mapped to ``[lo, hi]``; return its value."""
    try:
        fraction = next(run)
        while True:
            yield lo + (hi - lo) * fraction
            fraction = next(run)
    except StopIteration as done:
        return done.value


def _search(method, C, t_a, t_b, **options):
    """:func:`_iter_search` run to its end."""
    return drain(_iter_search(method, C, t_a, t_b, **options))


# --------------------------------------------------------------------------
# Refinement
# --------------------------------------------------------------------------


def _smooth_along(values: np.ndarray, t_src: np.ndarray, t_dst: np.ndarray, width: float) -> np.ndarray:
    """Gaussian (``width`` x perimeter) average along the normalised arc length,
    cyclic, of ``values`` known at ``t_src``, evaluated at ``t_dst``."""
    d = np.abs(t_dst[:, None] - t_src[None, :])
    d = np.minimum(d, 1.0 - d)
    W = np.exp(-0.5 * (d / width) ** 2)
    W /= np.maximum(W.sum(axis=1, keepdims=True), 1e-300)
    return W @ values


def _drift_cost(part: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, width: float, weight: float) -> np.ndarray:
    """Penalty for leaving the smoothed path of a previous matching.

    The drift ``t_b[partner(i)] - t_a[i]`` of the pairs (normalised arc
    length, unwrapped around the contour) is smoothed along ``a`` with a
    Gaussian of ``width`` times the perimeter; the result is ``weight`` times
    the squared distance, in nodes of ``b``, from the smoothed partner
    position. Slow drifts (a finger that turned, a stretched stretch) are
    kept; node-to-node jitter is removed.
    """
    na, nb = len(t_a), len(t_b)
    idx = np.flatnonzero(part >= 0)
    if len(idx) < 3:
        return np.zeros((na, nb))
    tb = t_b[part[idx]]
    step = (np.diff(tb) + 0.5) % 1.0 - 0.5
    drift = tb[0] + np.concatenate([[0.0], np.cumsum(step)]) - t_a[idx]
    drift = (drift - drift[0] + 0.5) % 1.0 - 0.5 + drift[0]
    target = t_a + _smooth_along(drift, t_a[idx], t_a, width)
    d = (t_b[None, :] - target[:, None] + 0.5) % 1.0 - 0.5
    return weight * (d * nb) ** 2


def roughness(nodes: np.ndarray) -> float:
    """Median distance of a node from the chord of its two neighbours, along
    the normal, in mean node spacings (h * curvature / 2 on a smooth curve)."""
    prev, nxt = np.roll(nodes, 1, axis=0), np.roll(nodes, -1, axis=0)
    chord = nxt - prev
    length = np.maximum(np.hypot(chord[:, 0], chord[:, 1]), 1e-300)
    off = nodes - 0.5 * (prev + nxt)
    normal_off = (off[:, 0] * chord[:, 1] - off[:, 1] * chord[:, 0]) / length
    spacing = float(segment_lengths(nodes).mean())
    return float(np.median(np.abs(normal_off)) / max(spacing, 1e-300))


def _band_cost(part: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, half_width: float) -> np.ndarray:
    """0 within ``half_width`` nodes of ``b`` of the path ``part`` (cyclic, in
    arc length), a prohibitive cost outside."""
    d2 = _drift_cost(part, t_a, t_b, 2.0 / len(t_a), 1.0)  # squared distance, nodes of b
    return np.where(d2 <= half_width**2, 0.0, 1e3)


def _pull_where_flat(C, band, part, t_a, t_b, weight):
    """Drift cost toward the smoothed ``part`` (see :func:`_drift_cost`),
    on each row of ``a`` in proportion to how flat ``C`` is within the band.

    Where the fine curvature is flat (straight sides, even arcs) it says
    nothing, and the DP would slide whole sides along or gather there the
    skips of unequal counts: those rows keep to the previous path. Rows where
    it varies (corners, the ends of arcs) are left to the curvature.
    """
    inside = band == 0
    spread = np.where(inside, C, -np.inf).max(axis=1) - np.where(inside, C, np.inf).min(axis=1)
    flat = 1.0 / (1.0 + (spread / (np.median(spread) + 1e-300)) ** 2)
    return flat[:, None] * _drift_cost(part, t_a, t_b, _REFINE_WIDTH, weight)


def _detail_pass(A, B, part, t_a, t_b, opts):
    """Re-align ``part`` within a narrow band using curvature at 1-4 node spacings.

    The signature of :func:`match` stops at 1/400 of the perimeter, about
    2.5 node spacings on a 1000-node contour, because coarser scales are what
    makes the first search robust. On dense contours that leaves the ends of
    straight sides and arcs (where a turned finger meets its web) unresolved,
    and the modal and coarse curvature terms, which see the neighbouring
    pieces change shape, shift whole parts by a few nodes. Searched only
    near the first path, the fine scales pin them.

    When the node counts differ, ``b`` is searched as ``len(a)`` nodes evenly
    spaced along it and the result taken back to its nearest nodes: with one
    node of ``b`` per node of ``a`` the DP has no skips to place, which on
    flat curvature it would gather in a few places, shifting the nodes
    between them.
    """
    na, nb = len(A), len(B)
    B_even = B if nb == na else resample(B, na)
    t_even = t_b if nb == na else np.arange(na) / na
    part_even = part if nb == na else np.where(part >= 0, np.rint(t_b[part] * na).astype(np.intp) % na, -1)
    # One length scale on both shapes: a's node spacing, b's units converted
    # by the ratio of the square roots of the areas (which turning or sliding
    # parts leave alone, unlike the perimeters; it makes the pass
    # independent of either scale).
    ratio = np.sqrt(abs(signed_area(B)) / abs(signed_area(A)))
    perimeter_a, perimeter_b = float(segment_lengths(A).sum()), float(segment_lengths(B_even).sum())
    spacing = max(perimeter_a / na, perimeter_b / na / ratio)
    ka = curvature_signature(A, tuple(m * spacing / perimeter_a for m in _DETAIL_SCALES))
    kb = curvature_signature(B_even, tuple(m * spacing * ratio / perimeter_b for m in _DETAIL_SCALES))
    C = _pairwise_sq(ka, kb) / ka.shape[1]
    penalty = _DETAIL_PENALTY * float(C.mean()) + 1e-12
    band = _band_cost(part_even, t_a, t_even, _DETAIL_BAND * spacing * ratio * na / perimeter_b)
    band = band + _pull_where_flat(C, band, part_even, t_a, t_even, _DETAIL_DRIFT_WEIGHT * penalty)
    start = int(part_even[0]) if part_even[0] >= 0 else None
    found, total = _search("order", C + band, t_a, t_even, **{**opts, "penalty": penalty, "n_starts": 1},
                           start=start)
    if nb != na:
        found = np.where(found >= 0, _nearest_at(t_b, t_even[np.maximum(found, 0)]), -1)
    return found, total


# --------------------------------------------------------------------------
# Public entry point
# --------------------------------------------------------------------------


def _check_method(method) -> str:
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(repr(m) for m in METHODS)}, got {method!r}")
    return method


def _joint_bases(A, B, n_modes, model_nodes, sigma_factor, material):
    """Modal bases of both shapes, truncated to a mode count that cuts neither
    spectrum through a near-degenerate pair (when such a count exists)."""
    n_compute = max(n_modes or 0, MAX_AUTO_MODES) + 4
    ra = _modal_raw(A, n_compute=n_compute, sigma_factor=sigma_factor, material=material,
                    model_nodes=model_nodes, name="a")
    rb = _modal_raw(B, n_compute=n_compute, sigma_factor=sigma_factor, material=material,
                    model_nodes=model_nodes, name="b")
    avail = min(ra.n_modes, rb.n_modes) - 1
    if n_modes is not None and n_modes > avail:
        warnings.warn(f"n_modes={n_modes} is more than the {avail} modes the contours' models have "
                      f"(model_nodes={model_nodes}); {avail} are used. The finest modes follow the nodes' noise: "
                      "6-12 is typical", UserWarning, stacklevel=4)
    k = select_modes(ra.spectrum, n_modes)
    for _ in range(4):
        k2 = select_modes(ra.spectrum, select_modes(rb.spectrum, k))
        if k2 == k:
            break
        k = k2
    k = max(1, min(k, avail))
    return truncate(ra, k), truncate(rb, k), k


def match(a, b, *, method: str = "order", n_modes: int | None = None, model_nodes: int | None = 64,
          sigma_factor: float = 1.0, material: str | Material = "rubber", curvature_weight: float = 8.0,
          arclength_weight: float = 0.0, refine: bool | None = None, sign_correction: bool = True,
          order_penalty: float = 5.0, n_starts: int = 2, gap_cost: float | None = None,
          detail: bool | None = None, displacement_weight: float = 0.0, context_weight: float = 6.0,
          modal_weight: float = 1.0, neighbourhood: float | None = None, callback=None) -> Matching:
    """Match the nodes of contour ``a`` to those of contour ``b`` by modal analysis.

    Parameters
    ----------
    a, b : array_like, shape (Na, 2) and (Nb, 2)
        Closed contours ``(row, col)``, each with at least 3 distinct nodes,
        no NaN, no repeated node. Orientation, start node, position, rotation,
        scale and node count may differ.
    method : {"order", "global", "local"}, optional
        ``order`` (default): cyclic order-preserving dynamic programming
        (Oliveira & Tavares 2008); never crosses matches and matches every
        node of ``a`` (unless ``gap_cost`` is set). ``global``: optimal
        assignment with fictitious nodes for unequal counts, then the nodes of
        ``a`` left to a fictitious partner are matched by neighbourhood and
        affinity (Bastos & Tavares 2006). ``local``: mutual row/column minima
        (Shapiro & Brady 1992), fewer pairs.
    n_modes : int, optional
        Number of modes in the affinity; raised (by at most 3) so that no
        near-degenerate pair is cut. Default: 6 to 12, cut at a spectral gap
        of both shapes.
    model_nodes : int or None, optional
        Number of evenly spaced nodes the element of each shape is built on
        (default 64, close to the paper's 67); the modal displacements are
        interpolated to the contour's nodes. ``None`` builds the element on
        the contour's own nodes (sparse shift-invert eigensolver above 300
        nodes). With the Gaussian width tied to the node spacing, the low
        modes of a model with hundreds of nodes crowd into a nearly flat
        spectrum and change with noise and node count, so matching such
        models is much less reliable (see ``docs/benchmarks.md``).
    sigma_factor : float, optional
        Gaussian width of the element in units of the mean model-node spacing.
    material : str or Material, optional
        Element material (only Poisson's ratio changes the mode shapes).
    curvature_weight : float, optional
        Weight of the curvature term of the matching cost (0: modal affinity
        only).
    arclength_weight : float, optional
        Weight of a normalised arc-length term for ``order``:
        ``arclength_weight * dt^2``, ``dt`` the difference of the nodes'
        arc-length positions counted from the start pair (default 0: it made
        no measurable difference on the benchmark once the order penalties
        were in place).
    refine : bool, optional
        Run the refinement pass (default: True for ``order`` only, so that
        ``global`` and ``local`` are the published searches on ``C``; on the
        benchmark it changed ``order``'s mean accuracy by +0.002 and
        ``global``'s by +0.007 but lowered ``global``'s worst pair).
    sign_correction : bool, optional
        Per-mode sign correction of ``b``'s modes against ``a``'s (default
        True). For measurements only: without it, ``order`` on the modal
        affinity alone fell from 0.74 to 0.45 mean accuracy on the benchmark.
    order_penalty : float, optional
        Cost of each repeated or skipped node of ``b`` in ``order``, in units
        of the median over ``a``'s nodes of their best matching cost (default
        5). It keeps the correspondence locally uniform where the features are
        flat, such as along the straight side of a finger; 0.5 lets the path
        follow the features' noise.
    n_starts : int, optional
        Number of start regions ``order`` searches at full resolution: the
        best of its coarse search around every start, each searched again
        with a free start of +-2 % of ``b``'s nodes.
    gap_cost : float, optional
        Cost of leaving a node of ``a`` unmatched in ``order``, in units of
        the matching cost (default: never).
    detail : bool, optional
        Run the detail pass after the refinement (``order`` only): search
        again within 8 node spacings of the path, on curvature at 1, 2 and 4
        node spacings alone. Default: when both contours have at least 400
        nodes and are smooth at the node scale (:func:`roughness` below
        0.1), where it raised the 1000-node articulated hands of the
        benchmark from 0.72 / 0.90 to 0.90 / 0.96 accuracy; on rough
        contours curvature at one node spacing is noise.
    displacement_weight : float, optional
        For two contours in one frame of reference (consecutive frames of a
        movie): add ``displacement_weight x median_i(min_j C_ij) x (d_ij / s)^2``
        to the cost, ``d_ij`` the distance between the nodes and ``s`` the
        node spacing of ``a`` (the median of ``C`` between nearest nodes over
        10 instead, when that is more: where a symmetric shape's modes took
        opposite signs, ``C``'s best pairs lie half a turn away at almost no
        cost). Modes and curvature are blind to where the
        shapes are, so a near-circular cell that turned a little could be
        matched a quarter turn off; this term (default 0: invariant matching)
        keeps each node near where it was.
    context_weight : float, optional
        Weight of the inner-distance shape context term (0: off). It keeps
        the match on parts that slid or turned (fingers closing together,
        swinging legs) and under node noise: on the benchmark it raised the
        worst articulated family pair of ``order`` from 0.87 to 0.92 and the
        worst of the project's 16 pairs from 0.76 to 0.91 (see
        ``docs/benchmarks.md``). Between consecutive frames of a movie
        (``displacement_weight > 0``) it buys little and costs ~20 ms per
        call on 100-node contours.
    modal_weight : float, optional
        Weight of the modal affinity (eq. 12) in the cost (default 1; 0 only
        to measure what it buys).
    neighbourhood : float, optional
        Fraction of the perimeter over which the cost is averaged along its
        diagonals (a Gaussian of standard deviation a quarter of it) before
        the search. Default 0.25 for ``global`` (it lets the assignment see
        the order of the nodes around each one: without it similar sides of
        a leg or two similar legs are swapped), 0 for the others.
    callback : callable, optional
        ``callback(fraction)`` with the fraction of the work done (0 to 1,
        increasing) after each stage and each start of the ``order`` search;
        return False to stop: the result then has ``stop_reason="cancelled"``
        (see :func:`iter_match`).

    Returns
    -------
    Matching

    Raises
    ------
    ValueError
        For an unknown ``method``, a contour with fewer than 3 nodes, NaN or
        infinite coordinates, identical nodes or all nodes on a line, or an
        invalid option; raised before any heavy work.

    Notes
    -----
    The matching cost is ``C = modal_weight x Z / n_modes + curvature_weight x
    Kc + context_weight x H``, with ``Z`` the sign-corrected modal affinity
    (eq. 12, :attr:`Matching.affinity`), ``Kc`` the mean squared difference of
    the nodes' curvature signatures (:func:`curvature_signature`) and ``H``
    the squared Hellinger distance of their inner-distance shape contexts
    (:func:`.inner_distance.inner_distance_context`). All terms are invariant
    to translation, rotation and scale of either contour. ``order`` charges
    ``order_penalty x median_i(min_j C_ij)`` for each repeated or skipped
    node of ``b``.

    The refinement unwraps the arc-length drift of the pairs, smooths it along
    ``a`` (Gaussian, 2 % of the perimeter) and searches again with
    ``C + 0.1 x penalty x (distance to the smoothed path in nodes of b)^2``.

    Examples
    --------
    >>> from napari_physeg.data import hand_pair
    >>> a, b, truth = hand_pair(67, 66)
    >>> m = match(a, b)
    >>> m.pairs.shape
    (67, 2)
    """
    options = {name: value for name, value in locals().items() if name not in ("a", "b", "callback")}
    check_callback(callback)
    on_progress = None if callback is None else (lambda state: callback(state.fraction))
    _check_outlines(a, b)
    return drain(_run(_prepare(a, b, **options)), on_progress)


def iter_match(a, b, **options):
    """:func:`match` as a generator: it yields :class:`MatchingProgress` after
    each stage of the work and returns (as ``StopIteration.value``) the
    :class:`Matching`.

    Takes the parameters of :func:`match` (but ``callback``), with its
    defaults. Bad input raises at the call, before any heavy work. Send
    ``True`` into the generator to stop it: the result then has
    ``stop_reason="cancelled"`` and the pairs of the last finished search
    (none when the first search had not finished). napari's
    ``thread_worker`` runs it as it is.

    Examples
    --------
    >>> from napari_physeg.data import hand_pair
    >>> a, b, truth = hand_pair(67, 66)
    >>> run = iter_match(a, b)
    >>> next(run).phase
    'features'
    """
    arguments = _match_arguments(a, b, options, "iter_match takes no callback: it yields its progress")
    _check_outlines(a, b)
    return _run(_prepare(**arguments))


def _check_outlines(a, b) -> None:
    """Warn if ``a`` or ``b`` crosses itself as a figure-8 does (see
    contour.warn_if_figure_eight): a user's input, matched all the same.
    (A tracked frame's contours, segmentation results, are not checked.)"""
    for contour, name in ((a, "a"), (b, "b")):
        warn_if_figure_eight(check_contour(contour, name), name, "its partners follow its crossings; match outlines "
                             "that do not cross themselves (a segmentation's result, or a shape drawn again)",
                             stacklevel=4)  # (this, _check_outlines, match, its caller)


def _match_pairs(a, b, **options) -> np.ndarray:
    """:attr:`Matching.pairs` of :func:`match` with these options, and
    nothing else: for callers that read only the pairs (tracking matches
    every contour with the one before), the result's full ``(Na, Nb)``
    affinity and cost matrices, and its unmatched nodes, are not built."""
    return drain(_run(_prepare(**_match_arguments(a, b, options, "_match_pairs takes no callback")), pairs_only=True))


def _match_arguments(a, b, options: dict, no_callback: str) -> dict:
    """The arguments of :func:`match` for ``a``, ``b`` and ``options``,
    with its defaults (a misspelt option fails here), for the callers that
    take no ``callback`` (TypeError ``no_callback`` if one is given)."""
    arguments = with_defaults(match, (a, b), options)
    if arguments.pop("callback") is not None:
        raise TypeError(no_callback)
    return arguments


@dataclass(frozen=True, eq=False)
class _Job:
    """Validated input of one matching: both contours positively oriented."""

    A: np.ndarray
    B: np.ndarray
    pa: np.ndarray  # caller's index of each node of A
    pb: np.ndarray
    method: str
    n_modes: int | None
    model_nodes: int | None
    sigma_factor: float
    material: object
    curvature_weight: float
    arclength_weight: float
    displacement_weight: float
    context_weight: float
    modal_weight: float
    neighbourhood: float
    refine: bool
    detail: bool | None
    sign_correction: bool
    order_penalty: float
    n_starts: int
    gap: float


#: ``b`` is taken for ``a``'s mirror image when its outline's curvature, read
#: backward, fits ``a``'s at most MIRROR_FIT times as far as read forward
#: (see :func:`mirror_fit`). The 38 articulated and held-out pairs of
#: benchmarks/matching.py fit at 0.73 or more (1.2 in the median; nearly
#: symmetric figures near 1); exact mirror images at 0, and the pairs' b
#: reflected at 0.24-1.37: a reflection plus a deformation is told only when
#: the reflection shows most.
MIRROR_FIT = 0.5

#: Samples along each outline and curvature scales (fractions of the
#: perimeter) of that comparison: coarse enough for node noise.
_MIRROR_SAMPLES = 1024
_MIRROR_SCALES = (0.01, 0.025, 0.06)


def mirror_fit(a, b) -> float:
    """How much closer ``b``'s outline is to ``a``'s mirror image than to ``a``.

    Both contours (positively oriented) are resampled evenly and described by
    their multi-scale curvature (:func:`curvature_signature`); ``b``'s
    signature is compared with ``a``'s at every start along the outline,
    read forward and read backward (a reflection reverses the order in
    which an outline's features come). Returns the least root-mean-square
    distance read backward over that read forward: 1 for a symmetric figure,
    below 1 when ``b`` looks like ``a`` reflected, 0 for an exact mirror image.
    """
    sa, sb = (curvature_signature(resample(c, _MIRROR_SAMPLES), _MIRROR_SCALES) for c in (a, b))

    def least_distance(fb):
        # sum over shifts k of |sa(s) - fb(s + k)|^2, by circular correlation
        corr = np.fft.ifft(np.conj(np.fft.fft(sa, axis=0)) * np.fft.fft(fb, axis=0), axis=0).real.sum(axis=1)
        return float(np.sqrt(max(np.sum(sa**2) + np.sum(fb**2) - 2.0 * corr.max(), 0.0) / sa.size))

    forward = least_distance(sb)
    return least_distance(sb[::-1]) / forward if forward > 0 else 1.0


def _warn_if_mirrored(a: np.ndarray, b: np.ndarray) -> None:
    """Warn when ``b`` (both positively oriented) looks like ``a`` reflected (see MIRROR_FIT)."""
    fit = mirror_fit(a, b)
    if fit <= MIRROR_FIT:
        how = ("is a's mirror image (its outline is a's reflected)" if fit < 0.01 else
               f"looks like a's mirror image (its outline fits a's reflection {1 / fit:.1f} times better than a)")
        warnings.warn(
            f"b {how}: the matching follows deformations, not reflections, so its pairs are likely wrong. "
            "If one contour is (x, y) and the other (row, col), swap the columns of one; to match a mirror "
            "image on purpose, flip one contour first (e.g. b * [1, -1])",
            UserWarning, stacklevel=4)


def _checked_neighbourhood(value, method: str) -> float:
    if value is None:
        return _GLOBAL_NEIGHBOURHOOD if method == "global" else 0.0
    value = check_number(value, "neighbourhood")
    if value > 1:
        raise ValueError(f"neighbourhood must be a fraction of the perimeter between 0 and 1, got {value!r}")
    return value


#: The most nodes of a contour that match() takes (as segment() makes at
#: most): its cost matrix holds the two node counts' product (two of 10,000
#: took 55 s), and an outline this long resolves nothing more.
MAX_MATCH_NODES = 5000
#: The most nodes of the element a shape's modes are computed on.
MAX_MODEL_NODES = 1000


def _check_size(contour: np.ndarray, name: str) -> np.ndarray:
    """``contour``, or a ValueError if it has more than MAX_MATCH_NODES nodes."""
    if len(contour) > MAX_MATCH_NODES:
        raise ValueError(f"{name} has {len(contour)} nodes, more than the {MAX_MATCH_NODES} match() takes (its cost "
                         f"grows with the product of the two counts); resample it, e.g. "
                         f"napari_physeg.core.contour.resample({name}, 500)")
    return contour


def _prepare(a, b, *, method, n_modes, model_nodes, sigma_factor, material, curvature_weight, arclength_weight,
             refine, sign_correction, order_penalty, n_starts, gap_cost, detail, displacement_weight,
             context_weight, modal_weight, neighbourhood) -> _Job:
    """Check every argument of :func:`match` (cheap: before any heavy work)."""
    method = _check_method(method)
    a = _check_size(check_contour(a, "a"), "a")
    b = _check_size(check_contour(b, "b"), "b")
    check_number(sigma_factor, "sigma_factor", inclusive=False)
    material = get_material(material)
    model_nodes = check_count(model_nodes, "model_nodes", 8, allow_none=True)
    if model_nodes is not None and model_nodes > MAX_MODEL_NODES:
        raise ValueError(f"model_nodes must be at most {MAX_MODEL_NODES}, got {model_nodes!r}: the element's "
                         "eigenproblem grows with its cube, and the low modes of a model of hundreds of nodes crowd "
                         "into a flat spectrum (64, the default, is typical)")
    if detail is not None and not isinstance(detail, (bool, np.bool_)):
        raise ValueError(f"detail must be True, False or None, got {detail!r}")
    if detail and method != "order":
        raise ValueError(f"the detail pass is part of method='order', not {method!r}")
    # Orient both contours alike (positively); indices are mapped back at the end.
    pa, pb = _canonical_order(a), _canonical_order(b)
    # Centred (each on its own centroid, or both on a's when their relative
    # position matters): features of far-off contours keep their precision.
    displacement_weight = check_number(displacement_weight, "displacement_weight")
    # Two contours in one frame of reference are one object a moment apart
    # (tracking): never reflected, and the check would cost a tenth of a frame.
    if displacement_weight == 0:
        _warn_if_mirrored(a[pa], b[pb])
    centre_a = a.mean(axis=0)
    centre_b = centre_a if displacement_weight > 0 else b.mean(axis=0)
    return _Job(
        A=a[pa] - centre_a, B=b[pb] - centre_b, pa=pa, pb=pb, method=method,
        n_modes=check_count(n_modes, "n_modes", 1, allow_none=True),
        model_nodes=model_nodes,
        sigma_factor=float(sigma_factor), material=material,
        curvature_weight=check_number(curvature_weight, "curvature_weight"),
        arclength_weight=check_number(arclength_weight, "arclength_weight"),
        displacement_weight=displacement_weight,
        context_weight=check_number(context_weight, "context_weight"),
        modal_weight=check_number(modal_weight, "modal_weight"),
        neighbourhood=_checked_neighbourhood(neighbourhood, method),
        refine=method == "order" if refine is None else bool(refine),
        detail=detail, sign_correction=bool(sign_correction),
        order_penalty=check_number(order_penalty, "order_penalty"),
        n_starts=check_count(n_starts, "n_starts", 1),
        gap=np.inf if gap_cost is None else check_number(gap_cost, "gap_cost"),
    )


@dataclass(frozen=True)
class MatchingProgress:
    """What :func:`iter_match` yields after each stage.

    Attributes
    ----------
    fraction : float
        Fraction of the work done, 0 to 1, increasing.
    phase : str
        The stage just finished: ``"features"``, ``"search"`` (after each
        start of the first search), ``"refinement"`` or ``"detail"``.
    """

    fraction: float
    phase: str


def _scaled(run, lo: float, hi: float, phase: str):
    """Re-yield the fractions of a sub-generator as :class:`MatchingProgress`
    between ``lo`` and ``hi``; return the sub-generator's value and whether a
    stop was sent."""
    try:
        fraction = next(run)
        while True:
            if (yield MatchingProgress(float(lo + (hi - lo) * fraction), phase)):
                run.close()
                return None, True
            fraction = run.send(None)
    except StopIteration as done:
        return done.value, False


def _matching_cost(job: _Job, t_a: np.ndarray, t_b: np.ndarray):
    """The cost matrix of the searches and the modal affinity (eq. 12) it
    includes, with what :class:`Matching` reports of them, and the coarse
    order search of that cost if it was run (see _coarse_search).

    Of the hypotheses on the modes' signs and mixes (see _mode_hypotheses),
    the one whose cost the coarse order-preserving search follows most
    cheaply is kept: along the right correspondence the modes agree with
    the shape's own terms, along a wrong one they cannot."""
    A, B = job.A, job.B
    na, nb = len(A), len(B)
    # Modal features with a cut common to both spectra, sign-corrected.
    basis_a, basis_b, k = _joint_bases(A, B, job.n_modes, job.model_nodes, job.sigma_factor, job.material)
    fa, fb = _features(basis_a, k), _features(basis_b, k)
    shape_cost = _shape_cost(job, A, B, t_a, t_b)
    hypotheses = _mode_hypotheses(job, fa, fb, basis_a, basis_b, k, shape_cost)
    scored = []
    for corrected, signs, theta, Z in hypotheses:
        if Z is None:
            Z = _pairwise_sq(fa.reshape(na, -1), corrected.reshape(nb, -1))
        C = _with_displacement(job, job.modal_weight * Z / k + shape_cost, A, B)
        coarse = _coarse_search(job, C) if len(hypotheses) > 1 else None
        # The modes' own reading (the paper's) is kept unless another is clearly cheaper.
        total = (coarse[0][0] if coarse else 0.0) / (_CLEARLY_CHEAPER if scored else 1.0)
        scored.append((total, coarse, C, Z, signs, theta))
    _, coarse, C, Z, signs, theta = min(scored, key=lambda item: item[0])
    if job.neighbourhood > 0:
        C, coarse = _neighbourhood_cost(C, t_a, t_b, job.neighbourhood), None
    return C, Z, k, signs, theta, basis_a, basis_b, coarse


def _mode_hypotheses(job: _Job, fa: np.ndarray, fb: np.ndarray, basis_a: ModalBasis, basis_b: ModalBasis, k: int,
                     shape_cost) -> list:
    """Hypotheses on ``b``'s modes' signs and mixes, each (corrected
    features, each mode's sign, frame rotation, and their squared feature
    distances to ``a``'s if already computed, else None): from the modes' clouds
    alone (see _mode_correction, over rotations of ``b``'s frame when its
    principal axes are ill defined), and, when the cost has the shape's own
    terms (curvature and inner-distance context, which need no sign),
    fitted along the path they give (see _fitted_along). The clouds alone
    matched exact copies of near-round coins and nuclei half a turn off:
    their modes' clouds are nearly symmetric."""
    if not job.sign_correction:
        return [(fb, np.ones(k), 0.0, None)]
    groups = _mode_groups(basis_a, basis_b, k)
    isotropic = max(basis_a.anisotropy, basis_b.anisotropy) > _ISOTROPIC
    clouds = _mode_correction(fa, fb, groups, _FRAME_ROTATIONS if isotropic else (0.0,))
    if not (job.modal_weight > 0 and np.ndim(shape_cost) == 2):
        return [(*clouds, None)]
    # The displacement term scaled as for the cost with the modes: a round
    # shape's curvature and context are flat, and scaled to them alone it
    # vanished.
    Z = _pairwise_sq(fa.reshape(len(fa), -1), clouds[0].reshape(len(fb), -1))
    scale = float(np.median((job.modal_weight * Z / k + shape_cost).min(axis=1)))
    path = _coarse_partners(_coarse_search(job, _with_displacement(job, shape_cost, job.A, job.B, scale)), len(fa))
    return [(*clouds, Z), (*_fitted_along(fa, fb, basis_a, basis_b, groups, path), None)]


def _with_displacement(job: _Job, C: np.ndarray, A: np.ndarray, B: np.ndarray, scale: float | None = None):
    """``C`` plus the displacement term (two contours in one frame of
    reference) in units of ``scale``, by default ``C``'s typical best pairs
    (see _FLIPPED_MODES)."""
    if job.displacement_weight == 0:
        return C
    D = _pairwise_sq(A, B)
    if scale is None:
        nearest = C[np.arange(len(A)), D.argmin(axis=1)]
        scale = max(float(np.median(C.min(axis=1))), float(np.median(nearest)) / _FLIPPED_MODES)
    spacing = float(segment_lengths(A).mean())
    return C + job.displacement_weight * scale * D / spacing**2


def _shape_cost(job: _Job, A: np.ndarray, B: np.ndarray, t_a: np.ndarray, t_b: np.ndarray):
    """The curvature and inner-distance context terms of the matching cost (0 without them)."""
    na, nb = len(A), len(B)
    cost = 0.0
    if job.curvature_weight > 0:
        scales = tuple(sorted({max(sc, 1.0 / min(na, nb)) for sc in _CURVATURE_SCALES}))
        ka = curvature_signature(A, scales)
        kb = curvature_signature(B, scales)
        cost = cost + job.curvature_weight * _pairwise_sq(ka, kb) / ka.shape[1]
    if job.context_weight > 0:
        # 100 samples even on coarser contours: measured, 67 samples (the
        # nodes of the paper's hands) halved the time but lost 0.002 mean
        # accuracy on the articulated families.
        cost = cost + job.context_weight * _pairwise_sq(_context_at_nodes(A, t_a, _CONTEXT_SAMPLES),
                                                        _context_at_nodes(B, t_b, _CONTEXT_SAMPLES))
    return cost


def _order_penalty(job: _Job, C: np.ndarray) -> float:
    """The order search's penalty for a repeated or skipped node, scaled to ``C``."""
    return job.order_penalty * float(np.median(C.min(axis=1))) + 1e-6 * float(np.median(C))


def _coarse_search(job: _Job, C: np.ndarray) -> list:
    """The order-preserving search around every start on ``C`` coarsened
    (see _iter_every_start), its best path first: its objective says how
    cheaply a correspondence follows ``C``."""
    return drain(_iter_every_start(C, _order_penalty(job, C), job.gap))


def _coarse_partners(found: list, n_a: int) -> np.ndarray:
    """The best path of :func:`_coarse_search` as each node of ``a``'s partner (-1: none)."""
    _, part, step = found[0]
    step_a = max(1, -(-n_a // _COARSE_NODES))
    return np.repeat(np.where(part >= 0, part * step, -1), step_a)[:n_a]


def _neighbourhood_cost(C: np.ndarray, t_a: np.ndarray, t_b: np.ndarray, width: float) -> np.ndarray:
    """``C`` averaged along its diagonals: the cost of pairing ``i`` with
    ``j`` becomes the Gaussian-weighted mean of the costs of pairing the
    nodes found the same arc length (fractions ``d`` of the perimeter, ``|d|``
    up to ``width / 2``) before and after them on each contour.

    A node then matches where its whole neighbourhood matches, which an
    assignment without order (``global``) otherwise ignores: it swaps the
    similar sides of a leg, or two similar legs. Parts that slid change the
    rate locally; the Gaussian weighting (standard deviation ``width / 4``)
    lets the nearest neighbours count most.
    """
    offsets = np.linspace(-0.5 * width, 0.5 * width, _NEIGHBOURHOOD_TERMS)
    weights = np.exp(-0.5 * (offsets / (0.25 * width)) ** 2)
    weights /= weights.sum()
    out = np.zeros_like(C)
    for d, w in zip(offsets, weights):
        rows = _nearest_at(t_a, (t_a + d) % 1.0)
        cols = _nearest_at(t_b, (t_b + d) % 1.0)
        out += w * C[np.ix_(rows, cols)]
    return out


def _nearest_at(t: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """Index of the node whose arc position (``t``, ascending from 0) is
    cyclically nearest to each ``wanted`` position."""
    n = len(t)
    after = np.searchsorted(t, wanted) % n
    before = (after - 1) % n
    d_after = (t[after] - wanted) % 1.0
    d_before = (wanted - t[before]) % 1.0
    return np.where(d_after < d_before, after, before)


def _run(job: _Job, pairs_only: bool = False):
    """The stages of :func:`match`, as a generator (see :func:`iter_match`);
    it returns the :class:`Matching`, or with ``pairs_only`` its pairs alone
    (see _match_pairs)."""
    A, B, method = job.A, job.B, job.method
    na, nb = len(A), len(B)
    t_a, _ = _arc_positions(A)
    t_b, _ = _arc_positions(B)

    C, Z, k, signs, theta, basis_a, basis_b, coarse = _matching_cost(job, t_a, t_b)
    detail = job.detail
    if detail is None:
        detail = (method == "order" and min(na, nb) >= _DETAIL_MIN_NODES
                  and max(roughness(A), roughness(B)) < _DETAIL_ROUGHNESS)
    # Progress: the features, then the searches (the first, with its several
    # starts, about three times the work of each later one).
    work = np.cumsum([1.0, 3.0, 1.0 if job.refine else 0.0, 1.0 if detail else 0.0])
    work /= work[-1]

    def result(part, total, final, stop_reason):
        if pairs_only:
            return _pairs(job, part)[0]
        return _result(job, part, total, final, Z, k, signs, theta, basis_a, basis_b, bool(detail), stop_reason)

    empty = np.full(na, -1, dtype=np.intp)
    if (yield MatchingProgress(float(work[0]), "features")):
        return result(empty, np.inf, C, "cancelled")
    penalty = _order_penalty(job, C)
    opts = dict(arc_weight=job.arclength_weight, n_starts=job.n_starts, gap=job.gap, penalty=penalty)
    # Two contours in one frame of reference (displacement_weight > 0, e.g.
    # consecutive frames of a movie): a's first node starts near its nearest
    # node of b, so the search around every start is not needed.
    near = int(np.argmin(_pairwise_sq(A[:1], B)[0])) if job.displacement_weight > 0 else None
    found, stopped = yield from _scaled(_iter_search(method, C, t_a, t_b, start=near, coarse=coarse, **opts),
                                        work[0], work[1], "search")
    if stopped:
        return result(empty, np.inf, C, "cancelled")
    part, total = found
    final = C
    if job.refine:
        final = C + _drift_cost(part, t_a, t_b, _REFINE_WIDTH, _DRIFT_WEIGHT * penalty)
        start = int(part[0]) if part[0] >= 0 else None
        part, total = _search(method, final, t_a, t_b, start=start, **opts)
        if (yield MatchingProgress(float(work[2]), "refinement")):
            return result(part, total, final, "cancelled")
    if detail:
        part, total = _detail_pass(A, B, part, t_a, t_b, opts)
        if (yield MatchingProgress(float(work[3]), "detail")):
            return result(part, total, final, "cancelled")
    return result(part, total, final, "completed")


def _pairs(job, part):
    """The pairs ``part`` gives (partners of the nodes of ``A``, -1: none),
    as ``(a's node, b's node)`` in the caller's numbering, sorted by ``a``'s
    node; and the node of ``A`` of each pair."""
    ia = np.flatnonzero(part >= 0)
    pairs = np.column_stack([job.pa[ia], job.pb[part[ia]]]).astype(np.intp).reshape(-1, 2)
    order = np.argsort(pairs[:, 0], kind="stable")
    return pairs[order], ia[order]


def _result(job, part, total, final, Z, k, signs, theta, basis_a, basis_b, detail, stop_reason) -> Matching:
    """The :class:`Matching` in the caller's node numbering."""
    pa, pb = job.pa, job.pb
    na, nb = len(pa), len(pb)
    pairs, ia = _pairs(job, part)
    cost = final[ia, part[ia]]
    affinity = np.empty((na, nb))
    affinity[np.ix_(pa, pb)] = Z
    cost_matrix = np.empty((na, nb))
    cost_matrix[np.ix_(pa, pb)] = final
    return Matching(
        pairs=pairs,
        affinity=affinity,
        unmatched=np.setdiff1d(np.arange(na), pairs[:, 0]).astype(np.intp),
        cost=cost,
        method=job.method,
        cost_matrix=cost_matrix,
        unmatched_b=np.setdiff1d(np.arange(nb), pairs[:, 1]).astype(np.intp),
        n_modes=int(k),
        signs=signs,
        frame_rotation=float(theta),
        refined=bool(job.refine),
        total_cost=float(total),
        basis_a=basis_a,
        basis_b=basis_b,
        detail_refined=detail,
        stop_reason=stop_reason,
    )

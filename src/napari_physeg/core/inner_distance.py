"""Inner-distance shape context: node features that do not change when parts bend.

The modal signature and the curvature of :mod:`.matching` describe a node by
the shape around it; when a finger slides along the palm or a leg swings,
the low modes of the whole body change and the match can slip by a whole
part. The *inner distance* between two points of a shape is the length of the
shortest path between them that stays inside it (Ling & Jacobs, "Shape
classification using the inner-distance", PAMI 2007). It barely changes when a
part turns about its joint or slides along the body, because the path runs
through the joint. The *inner-distance shape context* (IDSC) of a point is the
histogram of the inner distances and inner angles (the direction in which
each shortest path leaves the point, measured from the contour's tangent) to
all the other points.

Here the histogram is computed on evenly spaced samples of the contour, with
soft (linear) binning so that a node moved by noise moves weight between
neighbouring bins instead of jumping bins, and compared with the Hellinger
distance (Euclidean distance of the square roots), which turns the
comparison of all node pairs into one matrix product. Distances are
normalised by their mean, angles taken from the tangent: the descriptor is
invariant to translation, rotation and scale.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import shortest_path

from .contour import resample

__all__ = ["inner_distances", "inner_distance_context"]

#: Samples of the contour the shortest paths are computed on (Ling & Jacobs
#: use 100): enough to follow fingers and legs, few enough that the
#: visibility graph (samples^2 x samples segment tests) stays cheap.
N_SAMPLES = 100
#: Distance bins: log-spaced edges from 1/8 to 2 times the mean inner distance
#: (the range of Belongie's and Ling & Jacobs' shape contexts).
DISTANCE_EDGES = np.geomspace(0.125, 2.0, 5)
#: Angle bins over the full turn.
N_ANGLES = 8
#: Half-width, in samples, of the chord that defines the tangent at a sample
#: (a chord rather than the neighbours' difference: node noise barely turns it).
_TANGENT_HALF_WIDTH = 2


def _inside(points, polygon):
    """Even-odd test of ``points`` (k, 2) against a closed polygon (m, 2)."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    y, x = points[:, 0:1], points[:, 1:2]
    straddles = (a[None, :, 0] > y) != (b[None, :, 0] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        cross_x = a[None, :, 1] + (y - a[None, :, 0]) * (b[None, :, 1] - a[None, :, 1]) / (b[None, :, 0] - a[None, :, 0])
    return (np.count_nonzero(straddles & (x < cross_x), axis=1) % 2) == 1


def _visibility(polygon):
    """Lengths of the segments between samples that stay inside the polygon
    (``inf`` for the others); neighbours along the contour always see each other.

    A chord ``i-j`` is inside when it crosses no edge ``k-(k+1)`` of the
    polygon properly and its midpoint is inside. The orientation of any three
    vertices is ``X[a, b] + X[b, c] + X[c, a]`` with ``X`` the cross products
    of the (centred) vertices, so every test is a look-up in one m x m table.
    """
    m = len(polygon)
    pts = polygon - polygon.mean(axis=0)
    unit = pts / np.abs(pts).max()
    X = np.outer(unit[:, 0], unit[:, 1]) - np.outer(unit[:, 1], unit[:, 0])  # X[a, b] = a x b
    Xn = np.roll(X, -1, axis=1)  # Xn[a, k] = X[a, k + 1]
    # side[a, k]: orientation of vertex a against edge k (k -> k + 1).
    side = (np.diag(Xn)[None, :] + X - Xn).astype(np.float32)
    i, j = np.triu_indices(m, 2)
    keep = (j - i) != m - 1  # first and last sample are neighbours
    i, j = i[keep], j[keep]
    # Row look-ups, (chords, edges), in single precision: half the memory
    # traffic, and the orientations of vertices of a unit-sized polygon are
    # far above its rounding.
    X32, Xn32 = X.astype(np.float32), Xn.astype(np.float32)
    xij = X32[i, j][:, None]
    # i, j on either side of edge k; k, k + 1 on either side of chord i-j.
    crosses = (side[i] * side[j] < 0) & ((xij + X32[j] - X32[i]) * (xij + Xn32[j] - Xn32[i]) < 0)
    # Edges that share an end with the chord touch it there, not across.
    rows = np.arange(len(i))
    for k in (i, (i - 1) % m, j, (j - 1) % m):
        crosses[rows, k] = False
    visible = ~np.any(crosses, axis=1)
    visible[visible] = _inside(0.5 * (pts[i[visible]] + pts[j[visible]]), pts)
    W = np.full((m, m), np.inf)
    length = np.hypot(*(pts[j] - pts[i]).T)
    W[i[visible], j[visible]] = length[visible]
    nxt = np.roll(np.arange(m), -1)
    W[np.arange(m), nxt] = np.hypot(*(pts[nxt] - pts).T)
    W = np.minimum(W, W.T)
    np.fill_diagonal(W, 0.0)
    return W


def inner_distances(polygon):
    """Inner distances between the vertices of a closed polygon and the first
    step of each shortest path.

    Parameters
    ----------
    polygon : ndarray, shape (m, 2)
        Vertices of a simple closed polygon (a self-crossing one gives the
        shortest paths of its even-odd interior, and along its outline where
        that is empty).

    Returns
    -------
    D : ndarray, shape (m, m)
        Length of the shortest path inside the polygon between each pair of
        vertices (symmetric, 0 on the diagonal).
    first_step : ndarray of int, shape (m, m)
        ``first_step[i, j]``: the vertex the shortest path from ``i`` to ``j``
        goes to first (``j`` itself when ``j`` is visible from ``i``).
    """
    polygon = np.asarray(polygon, dtype=np.float64)
    W = _visibility(polygon)
    graph = np.where(np.isfinite(W), W, 0.0)
    D, pred = shortest_path(graph, method="D", directed=False, return_predecessors=True)
    # pred[j, i] is the vertex before i on the path from j: the first step from i to j.
    first_step = pred.T.copy()
    np.fill_diagonal(first_step, np.arange(len(polygon)))
    return D, first_step


def _soft_bins(values, edges):
    """Linear weights of ``values`` on the bin centres ``edges`` (clamped at the ends):
    lower bin index and the weight of the upper one."""
    pos = np.interp(values, edges, np.arange(len(edges)))
    lower = np.minimum(np.floor(pos).astype(np.intp), len(edges) - 2)
    return lower, pos - lower


def inner_distance_context(nodes, n_samples: int = N_SAMPLES):
    """Square roots of the inner-distance shape contexts of evenly spaced samples.

    Parameters
    ----------
    nodes : ndarray, shape (m, 2)
        A positively oriented closed contour.
    n_samples : int, optional
        Samples evenly spaced in arc length from node 0.

    Returns
    -------
    ndarray, shape (n_samples, len(DISTANCE_EDGES) * N_ANGLES)
        Row ``k``: the square root of the normalised, softly binned histogram
        of (log inner distance / mean, inner angle) from sample ``k`` to all
        the others. The squared Euclidean distance of two rows is the squared
        Hellinger distance of the histograms (0 to 2).
    """
    nodes = np.asarray(nodes, dtype=np.float64)
    # Centred (far-off contours keep their digits) and of unit size: the
    # histograms are of distances over their mean, but the shortest paths'
    # tests are not (a contour in metres, 1e-10 across, found no path).
    centred = nodes - nodes.mean(axis=0)
    samples = resample(centred / max(float(np.sqrt((centred**2).sum(1).mean())), 1e-300), int(n_samples))
    m = len(samples)
    D, first = inner_distances(samples)
    off = ~np.eye(m, dtype=bool)
    D = D / D[off].mean()
    h = _TANGENT_HALF_WIDTH
    tangent = np.roll(samples, -h, axis=0) - np.roll(samples, h, axis=0)
    step = samples[first] - samples[:, None, :]
    angle = (np.arctan2(step[..., 1], step[..., 0]) - np.arctan2(tangent[:, 1], tangent[:, 0])[:, None]) % (2 * np.pi)
    d_lo, d_w = _soft_bins(np.log(np.maximum(D, 1e-12)), np.log(DISTANCE_EDGES))
    a_pos = angle / (2 * np.pi) * N_ANGLES
    a_lo = np.floor(a_pos).astype(np.intp) % N_ANGLES
    a_w = a_pos - np.floor(a_pos)
    nd = len(DISTANCE_EDGES)
    bins = nd * N_ANGLES
    rows = np.broadcast_to(np.arange(m)[:, None] * bins, D.shape)[off]
    d_lo, d_w, a_lo, a_w = d_lo[off], d_w[off], a_lo[off], a_w[off]
    hist = np.zeros(m * bins)
    for dd, wd in ((d_lo, 1.0 - d_w), (d_lo + 1, d_w)):
        for aa, wa in ((a_lo, 1.0 - a_w), ((a_lo + 1) % N_ANGLES, a_w)):
            hist += np.bincount(rows + dd * N_ANGLES + aa, weights=wd * wa, minlength=m * bins)
    return np.sqrt(hist.reshape(m, bins) / (m - 1))

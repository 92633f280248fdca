"""Closed polylines: validation, arc-length resampling, orientation and normals.

A contour is an ``(N, 2)`` float64 array of ``(row, col)`` nodes (napari's and
scikit-image's convention), closed implicitly: the last node connects to the
first, which is not repeated.
"""

from __future__ import annotations

import warnings
from functools import lru_cache

import cv2
import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist, pdist

from ._validation import clicked, node_array

__all__ = [
    "as_contour",
    "signed_area",
    "perimeter",
    "segment_lengths",
    "resample",
    "nodes_for_spacing",
    "crosses_itself",
    "area_centroid",
    "closest_on_polyline",
    "contour_gap",
    "outward_normals",
    "mean_nearest_neighbour_distance",
    "polygon_mask",
    "window_mask",
    "remove_loops",
]


def as_contour(points, *, name: str = "contour", min_nodes: int = 3) -> np.ndarray:
    """Validate ``points`` as a closed contour and return it as float64 ``(N, 2)``.

    A repeated closing node and consecutive duplicate nodes are dropped.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        ``(row, col)`` nodes.
    name : str, optional
        The argument's name, used in error messages.
    min_nodes : int, optional
        The fewest distinct nodes accepted.

    Raises
    ------
    ValueError
        If the array is empty, not ``(N, 2)``, holds NaN or infinite values,
        has fewer than ``min_nodes`` distinct nodes, or encloses no area
        (all nodes on one line).
    """
    arr = node_array(points, name, min_nodes=min_nodes)
    # Drop consecutive duplicates, including a closing node equal to the first.
    keep = np.any(arr != np.roll(arr, -1, axis=0), axis=1)
    if not keep.any():  # every node identical
        keep[0] = True
    arr = arr[keep]
    if len(arr) < min_nodes:
        raise ValueError(
            f"{name} has {len(arr)} distinct node(s); at least {min_nodes} are needed for a closed contour"
        )
    # Centred rank test, not the area: a figure-8 encloses no net area but is
    # no line, and far from the origin the area's products lose every digit.
    singular = np.linalg.svd(arr - arr.mean(axis=0), compute_uv=False)
    if singular[1] <= 1e-9 * singular[0]:
        raise ValueError(f"{name} is degenerate: its nodes lie on one line and enclose no area")
    return np.ascontiguousarray(arr)


def as_drawing(points, *, name: str = "contour") -> np.ndarray:
    """:func:`as_contour` of a person's drawing, where one point is a click
    (a circle of a few pixels about it, see :func:`._validation.clicked`)."""
    return as_contour(clicked(points), name=name)


def signed_area(contour: np.ndarray) -> float:
    """Shoelace area with rows as the first axis; positive when the nodes run
    counter-clockwise in the (row, col) frame."""
    # Measured from the first node: the shoelace sum is translation invariant
    # but its products are not, and far from the origin they would cancel
    # catastrophically (a contour at 1e10 px would get a random sign).
    r, c = contour[:, 0] - contour[0, 0], contour[:, 1] - contour[0, 1]
    # np.roll-free: this runs several times per time step on small arrays.
    return 0.5 * float(r[:-1] @ c[1:] - r[1:] @ c[:-1] + r[-1] * c[0] - r[0] * c[-1])


def positively_oriented(contour) -> np.ndarray:
    """``contour`` as float64 nodes running counter-clockwise in the (row, col)
    frame (positive :func:`signed_area`), reversed if need be."""
    contour = np.asarray(contour, dtype=np.float64)
    if signed_area(contour) < 0:
        contour = contour[::-1]
    return np.ascontiguousarray(contour)


def segment_lengths(contour: np.ndarray) -> np.ndarray:
    """Length of each edge ``i -> i+1`` (the last edge closes the contour)."""
    # Written out rather than np.diff(append=...): this runs every time step.
    edge = np.empty_like(contour, dtype=np.float64)
    edge[:-1] = contour[1:] - contour[:-1]
    edge[-1] = contour[0] - contour[-1]
    return np.hypot(edge[:, 0], edge[:, 1])


def perimeter(contour: np.ndarray) -> float:
    """Length of the closed polyline."""
    return float(segment_lengths(contour).sum())


def nodes_for_spacing(contour, spacing: float) -> int:
    """How many evenly spaced nodes lie ``spacing`` px apart on the closed
    ``contour`` (at least 3): what "node spacing" means everywhere."""
    if not (np.isfinite(spacing) and spacing > 0):
        raise ValueError(f"node spacing must be a positive number of pixels, got {spacing!r}")
    return max(int(round(perimeter(np.asarray(contour, dtype=np.float64)) / float(spacing))), 3)


def resample(contour: np.ndarray, n_nodes: int | None = None, *, spacing: float | None = None) -> np.ndarray:
    """Resample a closed contour to evenly spaced nodes along its arc length.

    Exactly one of ``n_nodes`` and ``spacing`` is used; with ``spacing`` the
    node count is ``round(perimeter / spacing)`` (at least 3). The first node
    is kept in place, so resampling does not rotate the node numbering.
    """
    contour = np.asarray(contour, dtype=np.float64)
    seg = segment_lengths(contour)
    total = seg.sum()
    if n_nodes is None:
        if spacing is None or not spacing > 0:
            raise ValueError("resample needs n_nodes or a positive spacing")
        n_nodes = int(round(total / spacing))
    n_nodes = max(int(n_nodes), 3)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    closed = np.vstack([contour, contour[:1]])
    targets = np.arange(n_nodes) * (total / n_nodes)
    return np.column_stack([np.interp(targets, s, closed[:, k]) for k in range(2)])


def densify(contour: np.ndarray, spacing: float, longest: float) -> np.ndarray:
    """The closed ``contour`` with nodes added, evenly, along each edge
    longer than ``longest`` px, at most ``spacing`` px apart; its own
    vertices are kept (a rectangle keeps its corners) and so is their order."""
    contour = np.asarray(contour, dtype=np.float64)
    lengths = segment_lengths(contour)
    pieces = np.where(lengths > longest, np.ceil(lengths / spacing), 1).astype(int)
    if (pieces == 1).all():
        return contour
    edge = np.roll(contour, -1, axis=0) - contour
    start = np.repeat(np.arange(len(contour)), pieces)
    # Position of each new node along its edge: 0, 1/p, ..., (p-1)/p.
    offset = np.arange(pieces.sum()) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    return contour[start] + (offset / pieces[start])[:, None] * edge[start]


def through_nodes(contour: np.ndarray, per_edge: int) -> np.ndarray:
    """Points of the smooth closed curve through the nodes of ``contour``
    (a periodic cubic spline of the arc length along its edges),
    ``per_edge`` of them along each edge: node ``i`` is point
    ``i * per_edge``. Its edges, unlike the contour's own, lie on the curve
    to within a tiny fraction of a pixel (a chord stays inside a convex curve
    by its sagitta, ``length**2 / (8 * radius)``: 0.25 px for edges of 2.7 px
    about a radius of 3.6 px)."""
    contour = np.asarray(contour, dtype=np.float64)
    s = np.concatenate([[0.0], np.cumsum(np.maximum(segment_lengths(contour), 1e-9))])
    curve = CubicSpline(s, np.vstack([contour, contour[:1]]), bc_type="periodic")
    fractions = np.arange(per_edge) / per_edge
    return curve((s[:-1, None] + fractions * np.diff(s)[:, None]).ravel())


def outward_normals(contour: np.ndarray) -> np.ndarray:
    """Unit normals pointing out of the region the contour encloses.

    The tangent at each node is the chord between its two neighbours (the
    central difference), which keeps the normal well defined at corners.
    """
    tangent = np.concatenate([contour[1:], contour[:1]]) - np.concatenate([contour[-1:], contour[:-1]])
    # Rotating the tangent by -90 degrees points outward for a counter-clockwise contour.
    normal = np.column_stack([tangent[:, 1], -tangent[:, 0]])
    if signed_area(contour) < 0:
        normal = -normal
    norm = np.hypot(normal[:, 0], normal[:, 1])[:, None]
    return normal / np.maximum(norm, 1e-12)


def mean_nearest_neighbour_distance(nodes: np.ndarray) -> float:
    """Mean distance from each node to its nearest other node."""
    dist, _ = cKDTree(nodes).query(nodes, k=2)
    return float(dist[:, 1].mean())


def bounding_window(contour: np.ndarray, shape, margin: float, keep=None) -> tuple[slice, slice]:
    """Rows and columns of an image of ``shape`` within ``margin`` px of
    ``contour``'s bounding box (and covering the window ``keep``, if given)."""
    lo = np.maximum(np.floor(contour.min(0) - margin), 0).astype(int)
    hi = np.minimum(np.ceil(contour.max(0) + margin) + 1, shape).astype(int)
    if keep is not None:
        lo = np.minimum(lo, [keep[0].start, keep[1].start])
        hi = np.maximum(hi, [keep[0].stop, keep[1].stop])
    return slice(int(lo[0]), int(hi[0])), slice(int(lo[1]), int(hi[1]))


def window_mask(contour: np.ndarray, window) -> np.ndarray | None:
    """The mask of ``contour``'s pixels within ``window`` (rows and columns,
    see :func:`bounding_window`), or None for an empty window: objects are
    rasterised around themselves only, as a frame holds many small ones."""
    if window[0].stop <= window[0].start or window[1].stop <= window[1].start:
        return None
    shape = (window[0].stop - window[0].start, window[1].stop - window[1].start)
    return polygon_mask(contour - [window[0].start, window[1].start], shape)


def polygon_mask(contour: np.ndarray, shape) -> np.ndarray:
    """Boolean mask of the pixels whose centres lie inside the contour (even-odd rule).

    The same pixels as ``skimage.draw.polygon2mask``.

    A vectorised scan-line fill: ``O(pixels + crossings)``, unlike
    ``skimage.draw.polygon`` which is ``O(pixels * vertices)``.
    """
    h, w = int(shape[0]), int(shape[1])
    p = np.asarray(contour, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    r0, c0, r1, c1 = p[:, 0], p[:, 1], q[:, 0], q[:, 1]
    lo = np.clip(np.ceil(np.minimum(r0, r1)), 0, h).astype(np.int64)
    hi = np.clip(np.ceil(np.maximum(r0, r1)), 0, h).astype(np.int64)
    count = np.maximum(hi - lo, 0)
    edge = np.repeat(np.arange(len(p)), count)
    rows = lo[edge] + (np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count))
    t = (rows - r0[edge]) / (r1[edge] - r0[edge])
    x = c0[edge] + t * (c1[edge] - c0[edge])
    k = np.clip(np.floor(x).astype(np.int64) + 1, 0, w)
    toggles = np.bincount(rows * (w + 1) + k, minlength=h * (w + 1)).reshape(h, w + 1)
    return (np.cumsum(toggles[:, :w], axis=1) % 2).astype(bool)


#: Up to this many points, pairs within a distance are found among all pairs
#: (scipy's pdist), not by a k-d tree: several times faster at tens of points.
DENSE_PAIRS_MAX_POINTS = 128


# One entry per node count up to DENSE_PAIRS_MAX_POINTS (5.6 MB at most): the
# objects of a movie have as many node counts, and 16 entries thrashed.
@lru_cache(maxsize=DENSE_PAIRS_MAX_POINTS)
def pair_indices(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The indices ``i < j`` of the pairs of ``n`` points, in ``pdist``'s order (read-only)."""
    i, j = np.triu_indices(n, k=1)
    i.setflags(write=False)
    j.setflags(write=False)
    return i, j


def pairs_within(points: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs ``i < j`` of ``points`` at most ``radius`` apart, sorted."""
    if len(points) <= DENSE_PAIRS_MAX_POINTS:
        i, j = pair_indices(len(points))
        close = pdist(points, "sqeuclidean") <= radius * radius
        return i[close], j[close]
    pairs = cKDTree(points).query_pairs(radius, output_type="ndarray")
    i, j = pairs.min(1), pairs.max(1)
    order = np.lexsort((j, i))
    return i[order], j[order]


def _crossing_pairs(contour: np.ndarray) -> np.ndarray:
    """Pairs ``(i, j)``, ``i < j``, of non-adjacent edges that cross, sorted."""
    n = len(contour)
    ahead = np.concatenate([contour[1:], contour[:1]])
    edge = ahead - contour
    # Two edges can only cross if their midpoints are closer than their lengths.
    i, j = pairs_within(0.5 * (contour + ahead), np.sqrt(np.einsum("ij,ij->i", edge, edge).max()) + 1e-9)
    keep = (j - i > 1) & ~((i == 0) & (j == n - 1))
    i, j = i[keep], j[keep]
    # Each edge's ends lie on either side of the other's line (cross products of opposite signs).
    start_i, start_j, edge_i, edge_j = contour[i], contour[j], edge[i], edge[j]
    crosses = (_cross(edge_i, start_j - start_i) * _cross(edge_i, ahead[j] - start_i) < 0) & (
        _cross(edge_j, start_i - start_j) * _cross(edge_j, ahead[i] - start_j) < 0)
    return np.column_stack([i[crosses], j[crosses]])


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The z component of the cross products of the rows of ``u`` and ``v``."""
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def remove_loops(contour: np.ndarray, max_loops: int = 100) -> np.ndarray:
    """Cut the loops a closed contour makes where it crosses itself.

    At each crossing of edges ``i`` and ``j`` the contour splits in two closed
    pieces; the one with the fewer nodes (a loop pinched off in a narrow gap,
    or a twist) is removed and the crossing point joins the rest.
    """
    contour = np.asarray(contour, dtype=np.float64)
    for _ in range(max_loops):
        pairs = _crossing_pairs(contour)
        if not len(pairs) or len(contour) < 6:
            break
        i, j = pairs[np.argmin(np.minimum(pairs[:, 1] - pairs[:, 0], len(contour) - (pairs[:, 1] - pairs[:, 0])))]
        p, r = contour[i], contour[(i + 1) % len(contour)] - contour[i]
        s_, t_ = contour[j], contour[(j + 1) % len(contour)] - contour[j]
        denom = r[0] * t_[1] - r[1] * t_[0]
        u = ((s_[0] - p[0]) * t_[1] - (s_[1] - p[1]) * t_[0]) / denom
        x = p + u * r
        inner = j - i  # nodes i+1..j form one piece, the rest the other
        if inner <= len(contour) - inner:
            contour = np.vstack([contour[: i + 1], x, contour[j + 1:]])
        else:
            contour = np.vstack([x, contour[i + 1: j + 1]])
    return contour


def cut_pinches(contour: np.ndarray, gap: float, max_cuts: int = 100, keep=None) -> np.ndarray:
    """Split a closed contour where two non-neighbouring parts come closer than ``gap``.

    A contour squeezed through a narrow neck (between two touching objects,
    or against the image border) brings nodes of its two sides within a
    fraction of a pixel of each other without crossing: the pieces on either
    side of such a pinch are separate regions. The piece enclosing more of
    the points ``keep`` (if given: where the object is known to be) is kept,
    else the one enclosing the larger area; so is the body of a contour
    folded back on itself (a spike of zero width, as clipping to the image's
    corner makes).
    """
    contour = np.asarray(contour, dtype=np.float64)
    for _ in range(max_cuts):
        n = len(contour)
        if n < 8:
            break
        i, j = pairs_within(contour, gap)
        if not len(i):
            break
        apart = np.minimum(j - i, n - (j - i))
        far = apart >= 2
        if not far.any():
            break
        k = np.flatnonzero(far)[np.argmax(apart[far])]
        i, j = int(i[k]), int(j[k])
        inner, outer = contour[i: j + 1], np.vstack([contour[j:], contour[: i + 1]])
        contour = inner if _holds_more(inner, outer, keep) else outer
    return contour


def _holds_more(a: np.ndarray, b: np.ndarray, points) -> bool:
    """Whether closed contour ``a`` encloses more of ``points`` than ``b``
    (the larger area when they hold as many, or no points are given)."""
    if points is not None and len(points):
        from skimage.measure import points_in_poly

        in_a, in_b = points_in_poly(points, a).sum(), points_in_poly(points, b).sum()
        if in_a != in_b:
            return bool(in_a > in_b)
    return abs(signed_area(a)) >= abs(signed_area(b))


def crosses_itself(contour) -> bool:
    """Whether two non-adjacent edges of the closed ``contour`` cross (it is not a simple polygon)."""
    return len(_crossing_pairs(np.asarray(contour, dtype=np.float64))) > 0


#: A contour whose loops (see loop_share) hold at least this share of what it
#: encloses is a figure-8, not one outline; a lasso that overshoots its start
#: makes a small loop, which is just cut.
FIGURE_EIGHT_SHARE = 0.1


def warn_if_figure_eight(contour, name: str, then: str, stacklevel: int) -> None:
    """Warn, naming ``name``, when ``contour`` is a figure-8 (see
    FIGURE_EIGHT_SHARE): its nodes do not follow one outline, and ``then``
    says what follows for the caller's result. ``stacklevel`` counts from
    this function (segment, match and simulate each point at their caller)."""
    share = loop_share(contour)
    if share >= FIGURE_EIGHT_SHARE:
        warnings.warn(f"{name} crosses itself (a figure-8, a star or a bow-tie: loops that hold {share:.0%} of what "
                      f"it encloses), so its nodes do not follow one outline: {then}", UserWarning,
                      stacklevel=stacklevel)


def loop_share(contour) -> float:
    """The share of what the closed ``contour`` encloses (its pixels, filled
    as napari fills it) that lies in the loops a simple outline cannot keep:
    0 for a simple polygon, about half for a figure-8 of two equal lobes, a
    few hundredths for a lasso that overshoots its start."""
    contour = np.asarray(contour, dtype=np.float64)
    if not crosses_itself(contour):
        return 0.0
    # On a grid of about 100 px across whatever the contour's units.
    scale = 100.0 / max(float(np.ptp(contour, axis=0).max()), 1e-300)
    grid = (contour - contour.min(0)) * scale + 1.0
    # What it encloses: its pixels as napari fills them (even-odd: a
    # figure-8's two lobes), or its signed area (a star's middle, which
    # even-odd leaves out, counts twice), whichever is more.
    enclosed = max(float(polygon_mask(grid, np.ceil(grid.max(0)) + 2).sum()), abs(signed_area(grid)), 1.0)
    # (remove_loops needs a few nodes between crossings: a 4-click bow-tie has none)
    kept = remove_loops(resample(grid, max(len(grid), 64)))
    return float(np.clip(1.0 - abs(signed_area(kept)) / enclosed, 0.0, 1.0))


def closest_on_polyline(points: np.ndarray, curve: np.ndarray, near: np.ndarray, steps=(-1, 0)):
    """The point of the closed polyline ``curve`` closest to each of ``points``,
    and its distance, among the segments that start ``steps`` nodes from the
    node ``near[i]`` of ``curve`` (the first of equally close ones)."""
    # Every candidate segment at once: (steps, points, 2).
    start = (near[None, :] + np.asarray(steps)[:, None]) % len(curve)
    a, d = curve[start], curve[(start + 1) % len(curve)] - curve[start]
    u = np.clip(((points - a) * d).sum(2) / np.maximum((d * d).sum(2), 1e-12), 0.0, 1.0)
    candidates = a + u[..., None] * d
    gaps = candidates - points
    dist = np.hypot(gaps[..., 0], gaps[..., 1])
    best = dist.argmin(0)  # the first of equally close ones
    every = np.arange(len(points))
    return candidates[best, every], dist[best, every]


def depth_inside(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each of ``points``' distance inside the closed ``polygon`` (px; < 0 outside)."""
    xy = np.ascontiguousarray(polygon[:, ::-1], dtype=np.float32)  # OpenCV's (x, y)
    # Python floats (tolist): numpy's scalars cost more than the test itself.
    rows_cols = np.asarray(points, dtype=np.float64).tolist()
    return np.array([cv2.pointPolygonTest(xy, (x, y), True) for y, x in rows_cols])


def nearest_node(points: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """The index of the node nearest to each point."""
    if len(points) * len(nodes) <= DENSE_PAIRS_MAX_POINTS**2:  # all pairs: faster than a k-d tree
        return cdist(points, nodes, "sqeuclidean").argmin(1)
    return cKDTree(nodes).query(points)[1]


def contour_gap(a: np.ndarray, b: np.ndarray) -> float:
    """How far apart two closed contours are as curves, whatever their nodes:
    the largest distance from a node of either to the other's polyline.

    Each node is measured to the two segments about its nearest node of the
    other contour: exact for contours that lie within about a node spacing of
    each other (the use: a contour and itself a few steps later).
    """
    def one_way(points, curve):
        return float(closest_on_polyline(points, curve, nearest_node(points, curve))[1].max())

    return max(one_way(a, b), one_way(b, a))


def area_centroid(contour) -> np.ndarray:
    """Centroid of the region the closed ``contour`` encloses (shoelace
    formula); the mean of the nodes when it encloses no area."""
    contour = np.asarray(contour, dtype=np.float64)
    r, c = contour[:, 0], contour[:, 1]
    # The next node's coordinates (np.roll's, without its overhead: this runs often on small arrays).
    r1, c1 = np.concatenate((r[1:], r[:1])), np.concatenate((c[1:], c[:1]))
    cross = r * c1 - r1 * c
    area = 0.5 * cross.sum()
    if abs(area) < 1e-12:
        return contour.mean(0)
    return np.array([((r + r1) * cross).sum(), ((c + c1) * cross).sum()]) / (6 * area)


def rotation_matrix(angle: float) -> np.ndarray:
    """The rotation by ``angle`` (radians) of ``(row, col)`` column vectors;
    rows of points turn as ``points @ rotation_matrix(angle).T``."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s], [s, c]])


def rotation_between(source: np.ndarray, target: np.ndarray) -> float:
    """The angle of the rotation (about the origin, no reflection: the two
    run the same way) that brings the rows of ``source`` closest to the
    paired rows of ``target`` (least squares, orthogonal Procrustes)."""
    u, _, vt = np.linalg.svd(np.asarray(target, float).T @ np.asarray(source, float))
    turn = u @ np.diag([1.0, np.linalg.det(u @ vt)]) @ vt
    return float(np.arctan2(turn[1, 0], turn[0, 0]))

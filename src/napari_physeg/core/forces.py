"""External forces on the contour's nodes.

Segmentation (paper section 4.1): image features are sampled along the line
through each node orthogonal to the contour (its *normal line*), and each
feature pushes the node along that line:

* **edges** - toward the side of the line that holds more edge pixels; the
  force is the imbalance ``(S+ - S-) / (S+ + S-)`` of the two half-lines'
  edge sums, so it vanishes when the node sits on an edge (the paper's
  "positive / negative half-line" rule, figs. 2-3, made continuous so the
  contour comes to rest instead of chattering across the edge);
* **distance** - down the chamfer distance to the nearest edge: the difference
  of the two half-lines' mean distances divided by the line length, i.e. the
  directional derivative, in [-1, 1]; it reaches any edge however far;
* **intensity** - a region force: the mean over the shortest line (a few
  pixels, whatever the adaptive length) of the signed object-ness ``o = clip(polarity (I - t) / s, -1, 1)`` (``+1`` object,
  ``-1`` background), pushing outward on the object and inward on the
  background, so it balances on the border whether the object is brighter or
  darker than its background.

The line's half-length adapts to each node (paper: "each line has the
necessary length to determine a sufficient force"): it is the node's distance
to the nearest edge plus a margin, bounded, so a node far from the object sees
the edge it must reach while a node on the border looks only at its border.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from functools import cached_property

import cv2
import numpy as np
from scipy import ndimage as ndi

from .contour import outward_normals

__all__ = ["ForceField", "FORCE_NAMES", "normalize_weights"]

FORCE_NAMES = ("edges", "intensity", "distance")
DEFAULT_WEIGHTS = {"edges": 0.4, "intensity": 0.3, "distance": 0.3}


#: The largest weight of a force: the weights scale the forces, which the
#: feature images hold as float32 (a weight of 1e39 overflowed them to NaN).
MAX_WEIGHT = 1e6


def normalize_weights(forces=FORCE_NAMES, weights=None) -> dict[str, float]:
    """Validate the chosen forces and their weights; unnamed weights default."""
    given = forces
    try:
        forces = (forces,) if isinstance(forces, str) else tuple(forces)
    except TypeError:  # None, a number
        forces = ()
    if not forces or any(f not in FORCE_NAMES for f in forces):
        raise ValueError(f"forces must be a non-empty subset of {FORCE_NAMES}, got {given!r}")
    if weights is not None and not isinstance(weights, Mapping):
        raise ValueError(f"weights must be a dict of force name -> weight, e.g. {DEFAULT_WEIGHTS}, got {weights!r}")
    weights = dict(weights or {})
    bad = [k for k in weights if k not in FORCE_NAMES]
    if bad:
        raise ValueError(f"weights has unknown force name(s) {bad}; use {FORCE_NAMES}")
    out = {}
    for name in forces:
        value = weights.get(name, DEFAULT_WEIGHTS[name])
        try:  # a number (numpy's too), not a flag or a text
            w = np.nan if isinstance(value, (bool, np.bool_, str, bytes)) else float(value)
        except (TypeError, ValueError):
            w = np.nan
        if not (np.isfinite(w) and 0 <= w <= MAX_WEIGHT):
            raise ValueError(f"weight of {name!r} must be a number from 0 to {MAX_WEIGHT:g} (only the weights' "
                             f"ratios and stiffness matter), got {value!r}")
        out[name] = w
    if sum(out.values()) <= 0:
        raise ValueError("at least one force weight must be positive")
    return out


@dataclass(frozen=True, eq=False)
class ForceField:
    """Image forces along adaptive normal lines.

    Parameters
    ----------
    edges : ndarray
        Edge map in [0, 1] (1 on an edge).
    distance : ndarray
        Distance of each pixel to the nearest edge (pixels).
    objectness : ndarray
        Signed object-ness in [-1, 1] (+1 inside the object).
    weights : dict
        Weight of each force (``"edges"``, ``"intensity"``, ``"distance"``).
    min_length, max_length : float
        Bounds of a normal line's half-length (pixels).
    n_samples : int
        Samples on each half-line.
    """

    edges: np.ndarray
    distance: np.ndarray
    objectness: np.ndarray
    weights: dict
    min_length: float = 3.0
    max_length: float = 40.0
    n_samples: int = 12

    @classmethod
    def from_features(cls, edges, distance, objectness, weights, **kwargs) -> "ForceField":
        # A 1-px edge is blurred a little so that half-lines sampled every
        # couple of pixels cannot step over it.
        blurred = cv2.GaussianBlur(np.asarray(edges, dtype=np.float32), (0, 0), 1.0,
                                   borderType=cv2.BORDER_REFLECT)
        return cls(
            edges=blurred,
            distance=np.asarray(distance, dtype=np.float32),
            objectness=np.asarray(objectness, dtype=np.float32),
            weights=weights,
            **kwargs,
        )

    def with_weights(self, weights: dict) -> "ForceField":
        """The same images with other weights (shares the sampled stack)."""
        twin = replace(self, weights=dict(weights))
        twin.__dict__["_stack"], twin.__dict__["_padded_stack"] = self._stack, self._padded_stack
        return twin

    @cached_property
    def _stack(self) -> np.ndarray:
        """The three feature images as one 3-channel float32 image, so that a
        single bilinear ``cv2.remap`` samples them all."""
        return np.ascontiguousarray(np.dstack([self.edges, self.distance, self.objectness]).astype(np.float32))

    @cached_property
    def _line_pad(self) -> int:
        """Margin (px) of :attr:`_padded_stack`: the longest normal line of a
        node on the window's border (nodes stay within half a pixel of it)."""
        return int(np.ceil(max(self.max_length, self.min_length))) + 2

    @cached_property
    def _padded_stack(self) -> np.ndarray:
        """:attr:`_stack` with :meth:`_sample_maps`' borders written out
        around it, :attr:`_line_pad` px wide: the normal lines need one
        ``cv2.remap`` where the distance's own border took a second."""
        pad = (self._line_pad,) * 4
        distance = cv2.copyMakeBorder(self._distance32, *pad, cv2.BORDER_REFLECT_101)
        edges = cv2.copyMakeBorder(np.ascontiguousarray(self.edges, dtype=np.float32), *pad,
                                   cv2.BORDER_CONSTANT, value=1.0)
        objectness = cv2.copyMakeBorder(self._objectness32, *pad, cv2.BORDER_CONSTANT, value=-1.0)
        return cv2.merge([edges, distance, objectness])

    def _sample_lines(self, row_map, col_map) -> np.ndarray:
        """:meth:`_sample_maps` for points within :attr:`_line_pad` px of the
        window, as the normal lines of nodes on it are (beyond, the distance
        reads 0: no distance force)."""
        pad = np.float32(self._line_pad)
        return _remap(self._padded_stack, row_map + pad, col_map + pad, cv2.BORDER_CONSTANT, (1.0, 0.0, -1.0, 0.0))

    @cached_property
    def _distance32(self) -> np.ndarray:
        return np.ascontiguousarray(self.distance, dtype=np.float32)

    @cached_property
    def _objectness32(self) -> np.ndarray:
        return np.ascontiguousarray(self.objectness, dtype=np.float32)

    def sample(self, points: np.ndarray) -> np.ndarray:
        """Bilinear samples of (edges, distance, objectness) at ``points`` (..., 2)."""
        row_map, col_map, n = _remap_grid(points)
        return self._sample_maps(row_map, col_map).reshape(-1, 3)[:n].reshape(np.shape(points)[:-1] + (3,))

    def distance_at(self, points: np.ndarray) -> np.ndarray:
        """Bilinear samples of the distance image alone at ``points`` (..., 2)."""
        row_map, col_map, n = _remap_grid(points)
        return self._distance_maps(row_map, col_map).reshape(-1)[:n].reshape(np.shape(points)[:-1])

    # The samplers proper, on cv2.remap's maps: 2D float32 arrays of the
    # points' rows and columns. The normal lines of the nodes are such maps
    # as they are (a node per row, a sample per column).

    def _sample_maps(self, row_map, col_map) -> np.ndarray:
        # The image's border is a wall: an edge, with no object beyond it, so
        # a contour around an object cut by the border rests on the border.
        # (The stack keeps the distance, read again below with its own
        # border: cv2 interpolates 3-channel float images exactly, 2-channel
        # ones in fixed point.)
        out = _remap(self._stack, row_map, col_map, cv2.BORDER_CONSTANT, (1.0, 0.0, -1.0, 0.0))
        out[..., 1] = self._distance_maps(row_map, col_map)
        return out

    def _distance_maps(self, row_map, col_map) -> np.ndarray:
        # Beyond the border the distance to the nearest edge is unknown: it is
        # read as its mirror image inside (about the outermost pixels), so the
        # border neither pulls nor pushes a node by the distance force (the
        # edge and region forces say whether the object ends there).
        return _remap(self._distance32, row_map, col_map, cv2.BORDER_REFLECT_101)

    def _objectness_maps(self, row_map, col_map) -> np.ndarray:
        return _remap(self._objectness32, row_map, col_map, cv2.BORDER_CONSTANT, -1.0)

    @cached_property
    def _region_offsets(self) -> np.ndarray:
        return np.linspace(-self.min_length, self.min_length, 7)

    def _sample_short_lines(self, nodes: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """Samples (N, 7, 3) along each node's shortest normal line (the region force's)."""
        return self._sample_lines(*_line_maps(nodes, normals, self._region_offsets[None, :]))

    def line_lengths(self, nodes: np.ndarray) -> np.ndarray:
        """Adaptive half-length of each node's normal line."""
        # The nodes as maps of one column (runs every step: no folding, as distance_at does).
        d = self._distance_maps(nodes[:, :1].astype(np.float32), nodes[:, 1:].astype(np.float32)).reshape(-1)
        return np.clip(1.25 * d + self.min_length, self.min_length, self.max_length)

    @cached_property
    def _line_fractions(self) -> np.ndarray:
        """Sample positions along a normal line, in half-lengths: -1 ... 0 ... 1."""
        frac = np.arange(1, self.n_samples + 1) / self.n_samples
        return np.concatenate([-frac[::-1], [0.0], frac])

    @cached_property
    def _half_line_sums(self) -> np.ndarray:
        """(2S+1, 2): a search line's samples times this are the sums over its
        outer (+) and inner (-) half-lines (the node's own sample in neither)."""
        S = self.n_samples
        sums = np.zeros((2 * S + 1, 2))
        sums[S + 1:, 0] = sums[:S, 1] = 1.0
        return sums

    @cached_property
    def _line_offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """The search line's fractions (0 on the region line) and the region line's offsets (0 on the search line)."""
        zeros = np.zeros(len(self._region_offsets))
        return (np.concatenate([self._line_fractions, zeros])[None, :],
                np.concatenate([np.zeros_like(self._line_fractions), self._region_offsets])[None, :])

    def __call__(self, nodes: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
        """Dimensionless force on each node, ``(N, 2)``: each feature contributes at
        most its weight. Multiply by the stiffness constant ``r`` (N/m) for newtons.
        """
        if normals is None:
            normals = outward_normals(nodes)
        w = self.weights
        if w.get("edges", 0) <= 0 and w.get("distance", 0) <= 0:
            # The region force alone (the refinement phase): its short lines only.
            region = _nearest_switch(self._objectness_maps(*_line_maps(nodes, normals, self._region_offsets[None, :])))
            region = region.sum(1) / region.shape[1]
            return (w.get("intensity", 0) * region).astype(np.float64)[:, None] * normals
        lengths = self.line_lengths(nodes).astype(np.float64)
        S = self.n_samples
        # (N, 2S+1) search line, then the short region line: scaled fractions, then fixed offsets.
        scaled, fixed = self._line_offsets
        offsets = lengths[:, None] * scaled + fixed
        # One bilinear pass samples the search lines and the short region lines (runs every step).
        samples = self._sample_lines(*_line_maps(nodes, normals, offsets))
        values = samples[:, :2 * S + 1].astype(np.float64)  # (N, 2S+1, 3)
        total = np.zeros(len(nodes))
        if w.get("edges", 0) > 0:
            # An edge counts only where the object-ness falls outward across
            # it (object inside, background outside): the far side of the
            # object seen across it, edges within the background, and the
            # image's border beside background do not pull the node.
            e = values[..., 0] * (_central_difference(values[..., 2]) < -1e-3)
            plus, minus = (e @ self._half_line_sums).T
            total += w["edges"] * (plus - minus) / (plus + minus + 0.1)
        if w.get("distance", 0) > 0:
            plus, minus = (values[..., 1] @ self._half_line_sums).T
            # mean(+) - mean(-) of a linear ramp of slope g is g L (1 + 1/S)
            slope = (plus - minus) / (S * (1 + 1 / S) * lengths)
            total += w["distance"] * np.clip(-slope, -1.0, 1.0)
        if w.get("intensity", 0) > 0:
            # The region force is local: averaged over the shortest line only,
            # so a long search line crossing a thin part of the object (a
            # finger) cannot pull the node through it.
            region = _nearest_switch(samples[:, 2 * S + 1:, 2])
            total += w["intensity"] * (region.sum(1) / region.shape[1])
        return total[:, None] * normals

    def on_border(self, nodes: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
        """Which nodes rest on a feature: the object-ness changes sign within
        the shortest normal line, or an edge lies within a pixel and a half."""
        if normals is None:
            normals = outward_normals(nodes)
        values = self._sample_short_lines(nodes, normals)
        region = values[..., 2]
        crossing = (region.min(1) < 0) & (region.max(1) > 0)
        return crossing | self._edge_near(values)

    def on_edge(self, nodes: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
        """Which nodes have an edge within a pixel and a half along their normal."""
        if normals is None:
            normals = outward_normals(nodes)
        return self._edge_near(self._sample_short_lines(nodes, normals))

    def _edge_near(self, values: np.ndarray) -> np.ndarray:
        return values[:, np.abs(self._region_offsets) <= 1.5, 0].max(1) > 0.3


#: cv2.remap's maps and images must have sides below 2**15 - 1 (SHRT_MAX):
#: longer maps are cut into runs of this many rows, larger images sampled by
#: scipy instead.
_REMAP_ROWS = 2**14


def _nearest_switch(region: np.ndarray) -> np.ndarray:
    """The region line's samples (N, L; the node in the middle) with the
    object met again outward past background (a finger across a slit a few
    pixels wide, a neighbour across a dark gap) read as the deepest
    background before it: otherwise the line's mean pushes a slit's walls
    into it until they pinch and the slit is cut off.

    (Its mirror inward, background past object read as object, kept the far
    side of a thin part from pulling a node through it, but lost crowded
    nuclei when tracked: 3 -> 35 object-frames on identical frames of the
    Data Science Bowl crowd, benchmarks/tracking_warped.py.)
    """
    mid = region.shape[1] // 2
    out = region.copy()
    outward = region[:, mid:]
    deepest = np.minimum.accumulate(outward, axis=1)
    out[:, mid:] = np.where((deepest < 0) & (outward > deepest), deepest, outward)
    return out


def _remap(image: np.ndarray, row_map: np.ndarray, col_map: np.ndarray, border: int, value=0.0) -> np.ndarray:
    """Bilinear samples of ``image`` at the points of the maps (2D float32, of
    fewer than 2**15 columns and any number of rows)."""
    if max(image.shape[:2]) >= 2**15 - 1:  # cv2 wants sides below SHRT_MAX
        return _remap_large(image, row_map, col_map, border, value)
    options = dict(interpolation=cv2.INTER_LINEAR, borderMode=border, borderValue=value)
    if len(row_map) <= _REMAP_ROWS:
        return cv2.remap(image, col_map, row_map, **options)
    return np.concatenate([cv2.remap(image, col_map[i:i + _REMAP_ROWS], row_map[i:i + _REMAP_ROWS], **options)
                           for i in range(0, len(row_map), _REMAP_ROWS)])


def _remap_large(image: np.ndarray, row_map: np.ndarray, col_map: np.ndarray, border: int, value) -> np.ndarray:
    """:func:`_remap` for an image too large for cv2 (a window SHRT_MAX px or
    more across): scipy's linear interpolation, with the same borders."""
    points = np.stack([row_map.ravel(), col_map.ravel()]).astype(np.float64)
    channels = [image] if image.ndim == 2 else [image[..., c] for c in range(image.shape[2])]
    values = np.broadcast_to(np.atleast_1d(np.asarray(value, dtype=np.float64)), (4,))
    sampled = [ndi.map_coordinates(channel, points, order=1, prefilter=False,
                                   mode="mirror" if border == cv2.BORDER_REFLECT_101 else "grid-constant",
                                   cval=float(values[c])).astype(np.float32)
               for c, channel in enumerate(channels)]
    out = np.stack(sampled, axis=-1).reshape(row_map.shape + (len(channels),))
    return out[..., 0] if image.ndim == 2 else out


def _line_maps(nodes: np.ndarray, normals: np.ndarray, offsets: np.ndarray):
    """The row and column maps (N, L) of the points ``offsets`` (N or 1, L)
    px along each node's normal."""
    rows = nodes[:, :1] + offsets * normals[:, :1]
    cols = nodes[:, 1:] + offsets * normals[:, 1:]
    return rows.astype(np.float32), cols.astype(np.float32)


def _remap_grid(points: np.ndarray):
    """``points`` (..., 2) as the row and column maps of ``cv2.remap`` (folded
    into rows of 4096 points), and their number."""
    flat = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    n = len(flat)
    width = min(max(n, 1), 4096)
    rows = -(-n // width)
    maps = np.zeros((2, rows * width), dtype=np.float32)
    maps[:, :n] = flat.T
    row_map, col_map = maps.reshape(2, rows, width)
    return row_map, col_map, n


def _central_difference(values: np.ndarray) -> np.ndarray:
    """``np.gradient(values, axis=1)`` (unit spacing, first-order ends), without its overhead."""
    out = np.empty_like(values)
    out[:, 1:-1] = (values[:, 2:] - values[:, :-2]) / 2.0
    out[:, 0] = values[:, 1] - values[:, 0]
    out[:, -1] = values[:, -1] - values[:, -2]
    return out

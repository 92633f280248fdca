"""Segmentation with a physical deformable contour (paper sections 2 and 4.1).

:func:`segment` turns a rough initial contour into an elastic body (Sclaroff's
element made of a virtual material) and lets image forces drive it, by the
dynamic equilibrium equation ``M U'' + C U' + K U = F``, onto the border of
the object it surrounds or lies inside.
"""

from __future__ import annotations

import time
import warnings
from collections import deque
from dataclasses import dataclass, field, replace
from functools import lru_cache

import cv2
import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import pdist
from skimage.measure import points_in_poly

from .background import background_plane, plane_removed
from .contour import (DENSE_PAIRS_MAX_POINTS, as_contour, bounding_window, contour_gap, crosses_itself,
                      cut_pinches, densify, depth_inside, nearest_node, nodes_for_spacing, outward_normals,
                      pair_indices, pairs_within, perimeter, remove_loops, resample, segment_lengths, signed_area,
                      warn_if_figure_eight, window_mask)
from ._drain import drain
from .dynamics import DivergenceError, ModalIntegrator, NewmarkIntegrator
from .element import coefficient_system, rayleigh_coefficients, reference_frequency_range
from .features import (_as_image, _check_2d, _check_image, _intensity_range, _masked_as_missing, _noise_sigma,
                       _normalize, _rounding_sigma, _without_missing, _without_spikes, chamfer_distance,
                       normalized_intensity, shen_castan_edges)
from .forces import FORCE_NAMES, ForceField, normalize_weights
from .magnify import MagnifiedView, magnification
from .materials import Material, get_material, suggested_stiffness
from .region import (RegionModel, _box_of, _disk, _fill, _least_contrast, _scaled, drawing_levels,
                     drawing_limit, level_beyond_object, object_region, objectness)
from .subpixel import level_along, polish
from .texture import CONTRASTS, told_by_texture, texture_map
from ._validation import (CLICK_RADIUS, check_callback, check_count, check_number, clicked, signature_of,
                          with_defaults)

__all__ = ["segment", "iter_segment", "SegmentationResult", "SegmentationProgress", "FrameFeatures", "region_features"]

#: With ``n_nodes=None`` the nodes are DEFAULT_NODE_SPACING px apart, and
#: at least MIN_NODES and at most MAX_DEFAULT_NODES of them.
DEFAULT_NODE_SPACING = 3.0
MIN_NODES = 24
MAX_DEFAULT_NODES = 1000
#: The most nodes an initial model may have: every step costs about
#: n^2.6 (4000 nodes took 13 s, 8000 81 s; a 0.01-px spacing typed for
#: 1 px, 15,700 nodes on a nucleus, never ended). The widgets and the
#: command line take node spacings of MIN_NODE_SPACING px or more: closer
#: nodes resolve nothing more of the image.
MAX_NODES = 5000
MIN_NODE_SPACING = 0.5

#: Elements of at most this many nodes are held as dense matrices (and
#: factored by Cholesky), larger ones sparse (and factored by SuperLU).
DENSE_MAX_NODES = 100

#: Nodes are redistributed (and the element rebuilt) when an edge of the
#: contour grows past this many target spacings (see also PINCH_GAP).
REMESH_STRETCH = 2.0


def drawing_nodes(contour) -> np.ndarray:
    """A drawn shape's nodes for matching and simulation: its vertices, with
    nodes added along each edge longer than REMESH_STRETCH node spacings.

    The spacing is the contour's median edge, or DEFAULT_NODE_SPACING px (at
    most MAX_DEFAULT_NODES nodes) for one of fewer than MIN_NODES vertices:
    a rectangle's 4 corners, or the few clicks of a polygon, are a drawing,
    and matched and driven as they are they would make a quadrilateral. A
    contour whose nodes are about evenly spaced (an ellipse's polygon, a
    segmentation's result, the paper's 67-node hands) is returned unchanged.
    """
    contour = np.asarray(contour, dtype=np.float64)
    edges = segment_lengths(contour)
    spacing = (float(np.median(edges)) if len(contour) >= MIN_NODES else
               max(DEFAULT_NODE_SPACING, float(edges.sum()) / MAX_DEFAULT_NODES))
    return densify(contour, spacing, REMESH_STRETCH * spacing)


@dataclass(frozen=True)
class SegmentationResult:
    """What :func:`segment` returns.

    Attributes
    ----------
    contour : ndarray, shape (M, 2)
        Final nodes ``(row, col)``.
    steps : int
        Time steps taken.
    converged : bool
        True when the contour came to rest on the object's border (see
        ``stop_reason``).
    stop_reason : str
        ``"converged"`` (at rest, at least 70 % of the nodes on an edge or an
        object/background switch), ``"limited"`` (at rest so, but with
        a fifth of the nodes or more against the drawing where it cuts off a
        part of the object at least 5 px thick, or 70 % only counting those:
        the object runs on beyond the drawing, which is its limit; the
        contour is the part drawn around), ``"stalled"`` (at rest
        elsewhere: nothing in reach pulls it; or on the image's frame, along
        all four sides with 90 % of its nodes; or folded onto itself, less
        than a pixel wide on average, away from the image's sides),
        ``"leaked"`` (along all four sides of the image, which the drawing
        did not reach, or within 3 % of them holding nine tenths of it; over
        more than half of the image along two of its sides, from a drawing
        that held less than a twentieth of that; or, from a drawing read as
        lying inside the object, along the farthest it may reach, 25 times
        the drawing's size, with a tenth of its nodes: nothing told the
        object from its surroundings, and the evolution stops as soon as it
        sees that; or at rest around pixels of ``avoid``, more of its inside
        than not),
        ``"oscillating"`` (it kept moving without progress over 200 steps:
        nothing holds it, e.g. noise or shading without a border),
        ``"max_steps"`` (it kept moving: still travelling, or swinging about
        the border) or ``"cancelled"``. At rest means no node
        strayed more than ``patience * tol`` px over the last ``patience``
        steps, or the area per length and the centroid neither drifted nor
        strayed by more than half a pixel over 15 steps.
    history : tuple of ndarray
        Sub-sampled evolution, first the resampled initial contour, last the
        final one.
    polarity : int
        +1 when the object was taken as brighter than its background, -1
        darker (on its texture, for ``contrast="texture"``: +1 when it
        varies more than its background).
    contrast : str
        What told the object from its background: ``"intensity"`` (its
        level) or ``"texture"`` (its local variation, see segment's
        ``contrast``).
    timings : dict
        Seconds spent on ``"features"``, ``"model"`` (element assembly and
        factorisation), ``"evolution"`` and ``"total"`` (which also counts
        a magnified view's run that gave way to the image's).
    """

    contour: np.ndarray
    steps: int
    converged: bool
    stop_reason: str
    history: tuple
    polarity: int
    timings: dict = field(default_factory=dict)
    contrast: str = "intensity"

    @property
    def n_nodes(self) -> int:
        return len(self.contour)


def _validate_image(image) -> np.ndarray:
    """``image`` as an array, refused unless 2D and at least 2 px on each
    side (its values are checked where the features read them). Checked
    before the drawing is placed on it: an empty image is not a drawing
    that "lies outside the image"; masked pixels hold no data, as NaN ones)."""
    arr = np.asarray(_masked_as_missing(image))
    _check_2d(arr, "image")
    if min(arr.shape) < 2:
        raise ValueError(f"image has shape {arr.shape}: it holds no area for a contour; pass a 2D image at "
                         "least 2 px high and wide")
    return arr


#: Images whose largest magnitude lies beyond this range are scaled into it
#: (by that magnitude: a change of units, which no result depends on): their
#: squares, and their casts to float32, overflow or flush to zero.
WORKING_RANGE = (1e-30, 1e30)


def _in_working_range(image: np.ndarray) -> np.ndarray:
    """``image``, or ``image`` divided by its largest magnitude when that lies
    outside WORKING_RANGE (0-1e308 or 1e-310 images gave NaN errors deep in
    the features, naming an option never passed)."""
    if image.dtype.kind != "f":
        return image
    largest = max(-float(image.min()), float(image.max()))  # (no copy: a tracked frame is read per object)
    if not np.isfinite(largest):
        # Anywhere in the image, not only where the features read it (an
        # infinite pixel away from the drawing passed in silence).
        _check_image(image)
    if largest == 0.0 or WORKING_RANGE[0] <= largest <= WORKING_RANGE[1]:
        return image
    return image.astype(np.float64) / largest


#: A drawing may reach beyond the image (around an object its side cuts), by
#: up to this many times the image's larger side: one beyond is in other
#: units (nanometres, microns) or another image's coordinates, and reading
#: its line would take minutes.
MAX_REACH_BEYOND = 4.0


def check_on_image(init: np.ndarray, shape, name: str = "init") -> None:
    """A ValueError, naming ``name``, when the drawing ``init`` lies wholly
    outside an image of ``shape``, or reaches far beyond it (MAX_REACH_BEYOND)."""
    hi = np.array(shape, dtype=float) - 1.0
    lo_box, hi_box = init.min(0), init.max(0)
    if np.any(hi_box < 0) or np.any(lo_box > hi):
        raise ValueError(
            f"{name} lies wholly outside the image (image shape {tuple(shape)}, contour spans rows "
            f"{lo_box[0]:.1f}..{hi_box[0]:.1f}, cols {lo_box[1]:.1f}..{hi_box[1]:.1f}); "
            "check that the contour and image use the same coordinates"
        )
    beyond = float(np.max(np.maximum(-init, init - hi)))
    if beyond > MAX_REACH_BEYOND * max(shape):
        raise ValueError(
            f"{name} reaches {beyond:.3g} px beyond the image (image shape {tuple(shape)}): check that the contour "
            "is in pixels of this image (not in microns or nanometres, or another image's coordinates), "
            "and draw it on or near the image")


def _clip_to_image(init: np.ndarray, shape, warn: bool = True) -> np.ndarray:
    check_on_image(init, shape)
    hi = np.array(shape, dtype=float) - 1.0
    outside = np.any((init < 0) | (init > hi), axis=1)
    if outside.any():
        if warn:
            warnings.warn(
                f"{outside.sum()} of {len(init)} nodes of init lie outside the image and were clipped to it",
                UserWarning,
                stacklevel=6,  # the caller of segment() (through _set_up, _evolve, drain and segment)
            )
        init = as_contour(np.clip(init, 0.0, hi), name="init (clipped to the image)")
    return init


#: The drawing is read on a window around it when the window covers at most
#: this fraction of the image, else on the whole image (the intensity range
#: the features are normalised to, and the rings the levels are read on).
WINDOW_MAX_FRACTION = 0.5

#: The feature images are computed on a window around the contour when it
#: covers at most this fraction of the image: up to it, the saving beats the
#: cost of the rare re-computation when the contour grows out of its window
#: (an ellipse filling 57 % of a 512² image: 65 -> 48 ms; the real cases
#: alike, their results within 0.11 px).
FORCE_WINDOW_MAX_FRACTION = 0.75

#: Margins, in guard bands (the forces' longest normal line and a margin),
#: of the window the drawing is read on (its object's and background's
#: levels, which rings far around it may tell) and of the window of the
#: feature images around the contour (one guard band, and a quarter more
#: before the contour nears its side and the window grows).
CONTEXT_MARGIN = 2.0
FORCE_MARGIN = 1.25
#: A window that grows around a contour grows by this share of the contour's
#: size more (see _FeatureWindow.follow).
GROWTH_ROOM = 0.25


def _near_window_border(nodes: np.ndarray, window, shape, guard: float) -> bool:
    """True when a node of ``nodes`` (window coordinates) is within ``guard`` px
    of a side of the window that is not a side of the image."""
    rows, cols = window
    h, w = rows.stop - rows.start, cols.stop - cols.start
    lo, hi = nodes.min(0), nodes.max(0)
    return bool((rows.start > 0 and lo[0] < guard) or (cols.start > 0 and lo[1] < guard)
                or (rows.stop < shape[0] and hi[0] > h - 1 - guard)
                or (cols.stop < shape[1] and hi[1] > w - 1 - guard))


#: Edges count only within this many neck widths (see region.object_region)
#: of the object's own region: texture inside it and neighbours' far sides
#: do not hold the contour.
EDGE_GATE = 3.0


def region_features(intensity, edges, drawing, polarity=None, avoid=None, image_sides=(True, True, True, True),
                    noise=None, model=None, *, with_cut: bool = False):
    """Object-ness and edge images for the object the user drew.

    Parameters
    ----------
    intensity : (H, W) ndarray
        Lightly smoothed, normalised intensity.
    edges : (H, W) ndarray
        Edge map of the same window.
    drawing : (N, 2) ndarray
        The initial contour in the window's frame.
    polarity : {None, 1, -1}
        Known polarity, or None to infer it from the drawing.
    avoid : (H, W) ndarray of bool, optional
        Pixels of other objects: background for this one, whatever they
        look like (objects tracked together repel each other).
    image_sides : 4 bools, optional
        Which sides of the window (top, bottom, left, right) are the image's
        own; all by default (the window is the whole image).
    noise : float, optional
        Standard deviation of the noise in ``intensity`` (see
        :func:`~.region.drawing_levels`).
    model : RegionModel, optional
        The drawing's levels when already read (on a larger view of the same
        image, in the units of ``intensity``); ``polarity`` and ``noise`` are
        then not used.
    with_cut : bool, optional
        Also return the object's pixels the drawing's limit cut off its
        region (see :func:`~.region.object_region`), or None.

    Returns
    -------
    signed, edges : ndarray
        Object-ness in [-1, 1] (+1 on the object's own region, -1 on its
        background and on look-alike neighbours), and the edge map gated to a
        band around that region.
    polarity : int
    cut : ndarray of bool or None
        With ``with_cut`` only.
    """
    if model is None:
        model = drawing_levels(intensity, drawing, polarity, noise)
    # No object here that the eye could tell from its background: no region
    # force (edges may still guide the contour) but out of other objects.
    signed = objectness(intensity, model) if model.is_visible else np.zeros(intensity.shape, np.float32)
    # The region is split from its neighbours with their pixels as they look:
    # a neighbour's part that moved beyond its claim is still its own (as
    # background, that part would be a shallow blob the object could take).
    found = object_region(signed, drawing, model, image_sides, level_beyond_object(intensity, model), with_cut=True) \
        if model.is_visible else None
    region, cut = (None, None) if found is None else found
    if avoid is not None:
        signed[avoid] = -1.0
    if region is None:
        if model.is_visible:
            # No object region under the drawing (no object-like pixel
            # there): whatever looks like the object beyond the drawing's
            # limit is not what was drawn (unbounded, a star drawn over the
            # shadow under a clock followed the wall's faint mottling across
            # the image for 1000 steps).
            signed[~drawing_limit(drawing, signed.shape, model)] = -1.0
        return (signed, edges, model.polarity) + ((cut,) if with_cut else ())
    if avoid is not None:
        region &= ~avoid
    signed = np.where(region, np.where(signed > 0, signed, 1.0), np.where(signed > 0, -1.0, signed))
    # Texture inside the object's own region is the object: no edge holds
    # the contour there, and only a rim keeps graded object-ness values (for
    # the sub-pixel balance of the region force). Outside, edges count within
    # a band around the region (neighbours' far sides do not).
    size = np.sqrt(max(np.count_nonzero(region), 1) / np.pi)
    rim = int(np.clip(round(0.1 * size), 1, 3))
    gate = int(np.ceil(EDGE_GATE * rim))
    # Every mask below lies within the gate of the region: they are made on
    # its bounding box and that margin (and a pixel), not on the whole window.
    box = _box_of(region, gate + 1) or (slice(0, region.shape[0]), slice(0, region.shape[1]))  # (others took it all)
    r8 = region[box].view(np.uint8)
    interior = cv2.erode(r8, _disk(rim + 1)).view(bool)
    band = cv2.dilate(r8, _disk(gate)).view(bool) & ~interior
    gated = np.zeros(edges.shape, np.result_type(edges, 0.0))
    gated[box] = np.where(band, edges[box], 0.0)
    edges = gated
    # Where the edge detector found no border (its thresholds follow the
    # strongest edges in view: a dim object among bright ones has none), the
    # region's own outline stands in, so the distance force pulls toward the
    # object and not toward the nearest edge found elsewhere (or the image's side).
    outline = region[box] & ~cv2.erode(r8, _disk(1)).view(bool)
    near_edge = cv2.dilate((edges[box] > 0).view(np.uint8), _disk(rim + 1)).view(bool)
    edges[box][outline & ~near_edge] = 1.0
    signed[box][cv2.erode(r8, _disk(rim)).view(bool)] = 1.0
    return (signed.astype(np.float32), edges, model.polarity) + ((cut,) if with_cut else ())


#: Non-neighbouring nodes closer than this many node spacings pinch the
#: contour: it is split there (see contour.cut_pinches).
PINCH_GAP = 0.35

#: A contour whose area per length and centroid neither drifted by
#: PLATEAU_MOTION px nor strayed by PLATEAU_JITTER px over PLATEAU_STEPS
#: steps has come to rest, even if a few nodes still jitter (see _Plateau).
PLATEAU_MOTION = 0.1
PLATEAU_JITTER = 0.5
PLATEAU_STEPS = 15

#: A contour that keeps moving while its area per length and centroid have
#: not drifted by OSCILLATION_DRIFT px over OSCILLATION_STEPS steps (the means
#: of the window's halves) swings without progress: it stops, "oscillating".
#: The contours of the real-image benchmark come to rest within 120 steps;
#: the longest legitimate runs measured (a contour drawn far around the
#: cameraman, 242 steps; a hand on 512 x 512, 206) drift by 7.7 px or more
#: over any 200 steps until they rest. A click on a bowl of shading and noise
#: swung for 1000 steps (16 s) with a drift of 0.04 px over 100 steps.
OSCILLATION_DRIFT = 0.5
OSCILLATION_STEPS = 200

#: The evolution phase hands over to the refinement phase, and that to the
#: polish (subpixel.polish, which reaches 1.5 px), once at rest within this
#: many times ``tol``. Settling the refinement to ``tol`` itself took half the
#: steps of a tracked frame and moved no IoU of the real-image or synthetic
#: benchmarks by more than 0.03 (0.0001 in the mean).
HANDOVER = 5.0

#: Steps the refinement phase must be still (at most ``patience``): the
#: polish that follows measures the border on the raw image itself, so the
#: refinement need only have brought the nodes within its reach. It settles
#: within a quarter pixel in two steps (median of the real-image cases); the
#: five more steps it took to be seen at rest were a tenth of a segmentation's
#: steps and a fifth of a tracked frame's time, and changed no IoU of the
#: real-image benchmark by more than 0.1 (none in the mean).
REFINEMENT_PATIENCE = 2

#: At rest, the contour is on the object when at least this fraction of its
#: nodes rest on a feature (an edge or an object/background switch).
ON_BORDER_FRACTION = 0.7


#: At most this many points of the object mark it when a pinch parts the contour.
ANCHOR_POINTS = 256


def _anchor(signed: np.ndarray, drawing: np.ndarray) -> np.ndarray:
    """Points (row, col) of the object's own region under the middle of the
    drawing (its half-size copy about its centroid, else the drawing): where
    the user said the object is. Where a pinch parts the contour, the piece
    that holds them is the object, not the larger one (a neighbour that a
    generous drawing took in whole)."""
    for factor in (0.5, 1.0):
        # On the scaled drawing's box: the window may be many times its size.
        scaled = _scaled(drawing, factor)
        box = bounding_window(scaled, signed.shape, 1.0)
        corner = (box[0].start, box[1].start)
        shape = (box[0].stop - corner[0], box[1].stop - corner[1])
        if min(shape) <= 0:
            continue
        points = np.argwhere(_fill(scaled, shape, corner) & (signed[box] > 0)) + corner
        if len(points):
            return points[:: -(-len(points) // ANCHOR_POINTS)].astype(np.float64)
    return np.zeros((0, 2))


def _distance_with_image_border(edges: np.ndarray, signed: np.ndarray, window, shape) -> np.ndarray:
    """Chamfer distance to the nearest edge, the image's own border counting
    as an edge where the object meets it (``signed > 0`` beside it): an
    object cut by the border ends there, and a node on the border does not
    reach across the object for the far side's edge. Beside the background
    the border is no edge: a contour drawn beyond the image, clipped onto
    its border, is not held there."""
    rows, cols = window
    pad = ((int(rows.start == 0), int(rows.stop == shape[0])), (int(cols.start == 0), int(cols.stop == shape[1])))
    framed = np.pad(np.asarray(edges) > 0, pad, constant_values=False)
    inner = np.pad(np.asarray(signed) > 0, pad, mode="edge")
    frame = np.ones(framed.shape, bool)
    frame[pad[0][0]: framed.shape[0] - pad[0][1], pad[1][0]: framed.shape[1] - pad[1][1]] = False
    framed |= frame & inner
    distance = chamfer_distance(framed)
    return distance[pad[0][0]: distance.shape[0] - pad[0][1], pad[1][0]: distance.shape[1] - pad[1][1]]


class _RemeshWatch:
    """Whether the nodes need a remesh: an edge stretched past REMESH_STRETCH
    spacings, or two nodes (neighbours or not) closer than PINCH_GAP spacings,
    where the element would lose resolution or become ill-conditioned.

    Neighbours are tested every step through the edge lengths. Other pairs
    need a k-d tree, built only when one of them may have come within the gap:
    no pair comes closer by more than twice the largest node motion since the
    last tree, so until that motion uses up the clearance (the closest such
    pair's distance minus the gap) the tree would find nothing.
    """

    def __init__(self, spacing: float):
        self.spacing, self.gap = spacing, PINCH_GAP * spacing
        self.forget()

    def forget(self) -> None:
        """The nodes were replaced (remeshed): test them afresh."""
        self.reference, self.clearance = None, -np.inf

    def shift(self, offset: np.ndarray) -> None:
        if self.reference is not None:
            self.reference = self.reference + offset

    def due(self, nodes: np.ndarray) -> bool:
        lengths = segment_lengths(nodes)
        if lengths.max() > REMESH_STRETCH * self.spacing or lengths.min() <= self.gap:
            return True
        if self.reference is not None and len(nodes) == len(self.reference):
            motion = nodes - self.reference
            if 2.0 * np.sqrt((motion * motion).sum(1).max()) < self.clearance:
                return False
        closest = _closest_non_neighbours(nodes)
        self.reference, self.clearance = nodes.copy(), closest - self.gap
        return bool(closest <= self.gap)  # as cKDTree.query_pairs(gap): distances <= gap


@lru_cache(maxsize=DENSE_PAIRS_MAX_POINTS)
def _non_neighbour_pairs(n: int) -> np.ndarray:
    """Which pairs of ``pdist``'s condensed order join two nodes of a closed
    contour of ``n`` nodes that are not neighbours along it."""
    i, j = pair_indices(n)
    return (j - i > 1) & (j - i < n - 1)


def _closest_non_neighbours(nodes: np.ndarray) -> float:
    """The smallest distance between two nodes that are not neighbours along the contour."""
    n = len(nodes)
    if n < 4:
        return np.inf
    if n <= DENSE_PAIRS_MAX_POINTS:
        # Every pair at once: on a contour of tens of nodes this is three
        # times faster than building a k-d tree (it runs up to every step).
        return float(np.sqrt(pdist(nodes, "sqeuclidean")[_non_neighbour_pairs(n)].min()))
    # The 4 nearest of each node hold at most itself and its 2 neighbours.
    distance, index = cKDTree(nodes).query(nodes, k=4)
    offset = (index - np.arange(n)[:, None]) % n
    return float(distance[(offset > 1) & (offset < n - 1)].min())


class _Plateau:
    """Watches the contour's area per length and centroid, step by step.

    At rest (:meth:`reached`): over the last PLATEAU_STEPS steps they have not
    drifted (the means of the window's two halves differ by less than
    PLATEAU_MOTION px) and stayed within PLATEAU_JITTER px (a few nodes may
    still churn where the border meets the image's side, by a fraction of a
    pixel). A contour swinging about its border comes back to where it was,
    so comparing two instants would take it for one at rest; the window's
    range does not.
    """

    def __init__(self):
        self.trace = deque(maxlen=OSCILLATION_STEPS)

    def reached(self, nodes: np.ndarray) -> bool:
        area = signed_area(nodes)
        length = max(perimeter(nodes), 1e-9)
        self.trace.append((area / length, *(nodes.sum(0) / len(nodes))))
        if len(self.trace) <= PLATEAU_STEPS:
            return False
        window = np.array([self.trace[i] for i in range(-PLATEAU_STEPS - 1, 0)])
        return bool(_drift(window) < PLATEAU_MOTION and np.ptp(window, axis=0).max() < PLATEAU_JITTER)

    def swinging(self) -> bool:
        """Whether, over the last OSCILLATION_STEPS steps, the contour made no
        progress (see OSCILLATION_DRIFT)."""
        return len(self.trace) == OSCILLATION_STEPS and _drift(np.array(self.trace)) < OSCILLATION_DRIFT


def _drift(window: np.ndarray) -> float:
    """How far the means of the first and second halves of ``window`` lie apart."""
    half = len(window) // 2
    return float(np.abs(window[half:].mean(0) - window[:half].mean(0)).max())


def _took_the_whole_image(contour: np.ndarray, drawing: np.ndarray, shape) -> bool:
    """Whether ``contour`` runs along all four of the image's sides while
    ``drawing`` (clipped to the image) did not: it spread over the whole
    image, the image's sides holding it where no border of the object did.
    Along them within ALONG_THE_SIDE of the image's extent where it holds
    NEARLY_ALL of the image (see there)."""
    if _sides_met(contour, shape) == 4 and _sides_met(drawing, shape) < 4:
        return True
    return bool(abs(signed_area(contour)) > NEARLY_ALL * shape[0] * shape[1]
                and _sides_along(contour, shape) == 4 and _sides_along(drawing, shape) < 4)


#: A contour that holds more than this share of the image is the image, not
#: an object in it (a disk a few px from each side holds about 0.75 of a
#: square image): on an MSC frame brighter along its top rows, a circle's
#: contour held 98 % of the image 4 px from that side, one cell left out,
#: and said converged (session 74's tester).
NEARLY_ALL = 0.9


#: A contour that holds more than this share of the image, along two of its
#: sides or more, grown from a drawing that held less than 1 / MOST_GROWTH
#: of what it holds, took the ground the image's sides cut, not an object
#: the drawing meant: small phase-contrast cells, half brighter and half
#: darker than the ground, drawn around with a lasso or a circle, read as
#: drawn inside the ground, which the contour then took in (84 % of the
#: image, 50-80 times the drawing, along three of its sides, and
#: 'converged'). Of the 5,700 contours at rest from drawings of
#: benchmarks/real.py, drawings.py and 1,233 runs of outside testers on
#: unseen images, no other holds half its image and 20 times its drawing.
#: (An object may be that large: a disk of half the image, clicked on at
#: its edge, is one; the image's sides do not cut it.)
MOST_OF_THE_IMAGE = 0.5
MOST_GROWTH = 20.0

#: A contour runs along a side of the image when it comes within this share
#: of the image's extent of it: a frame of constant padding (or a
#: registration's margin) may lie between (a phase-contrast field padded
#: with white 7 px wide: a lasso about one cell rested 7-9 px from each
#: side, on the padding's edge, held 93 % of the image and 69 times the
#: lasso, and said converged). A disk of half a square image lies a tenth
#: of its side from each side.
ALONG_THE_SIDE = 0.03


def _sides_along(contour: np.ndarray, shape) -> int:
    """How many of the image's four sides ``contour`` runs along (see ALONG_THE_SIDE)."""
    return _sides_met(contour, shape, max(1.0, ALONG_THE_SIDE * min(shape)))


def _took_most_of_the_image(contour: np.ndarray, drawing: np.ndarray, shape) -> bool:
    """Whether ``contour`` holds more than MOST_OF_THE_IMAGE of the image,
    along two of its sides or more (see ALONG_THE_SIDE), and MOST_GROWTH
    times what ``drawing`` (clipped to the image) holds."""
    area = abs(signed_area(contour))
    return bool(area > MOST_OF_THE_IMAGE * shape[0] * shape[1] and area > MOST_GROWTH * abs(signed_area(drawing))
                and _sides_along(contour, shape) >= 2)


#: A contour with at least this share of its nodes on the image's sides, along
#: all four, rests on the image's frame: where the image ends, not on a
#: border of an object (a circle drawn wholly beyond a 328 x 400 image,
#: clipped to its sides, stayed there and said converged, the horse and the
#: ground it stood on both inside).
ON_FRAME_SHARE = 0.9


def _on_the_image_frame(contour: np.ndarray, shape) -> bool:
    """Whether ``contour`` runs along all four of the image's sides with
    ON_FRAME_SHARE of its nodes on them."""
    low, high = _near_sides(contour, shape)
    return _sides_met(contour, shape) == 4 and float((low | high).any(axis=1).mean()) >= ON_FRAME_SHARE


def _around_others(contour: np.ndarray, avoid: np.ndarray | None) -> bool:
    """Whether most of the pixels inside ``contour`` are ``avoid``'s (other
    objects', or no data). Counted as background, they repel the contour;
    but where they fill the object but for a rim (a nucleus already found,
    and a drawing around it), a closed contour about that rim, held by the
    object's edge, takes them in: tracking, two contours covered the same
    782 px of a nucleus."""
    return _avoided_share(contour, avoid) > 0.5


#: A contour from a drawing read as lying inside its object that rests
#: within this many px of the farthest reach such a drawing is given
#: (region._INSIDE_LIMIT times its size) along at least this share of its
#: nodes off the image's sides was held there by that reach, not by a border.
#: (Of the 2341 contours of benchmarks/real.py, the 7 that came within the
#: reach at all were all leaks, IoU 0.01-0.04, along 2-48 % of their nodes;
#: a circle drawn on the ground between nuclei spread over 200-550 times
#: its area, 15-47 % of it at the reach, and was reported converged.)
AT_REACH_PX = 1.5
AT_REACH_SHARE = 0.1

#: How often (steps) the evolution looks whether its contour has leaked.
LEAK_CHECK_EVERY = 10


def _spread_beyond_the_object(contour, init, drawing, features: _FeatureWindow, field: ForceField, shape) -> bool:
    """Whether ``contour`` (image frame) spread beyond any object the drawing
    meant: over the whole image (see :func:`_took_the_whole_image`, ``init``
    the drawing clipped to the image) or to the farthest reach of a drawing
    read as inside its object (see :func:`_held_by_the_reach`; ``field``
    tells which nodes lie on an edge)."""
    return _took_the_whole_image(contour, init, shape) or _took_most_of_the_image(contour, init, shape) or \
        _held_by_the_reach(contour, drawing, features.model, shape, field, features.origin)


def _held_by_the_reach(contour: np.ndarray, drawing: np.ndarray, model: RegionModel, shape, field: ForceField,
                       origin: np.ndarray) -> bool:
    """Whether ``contour``, grown from a ``drawing`` that ``model`` reads as
    inside its object, rests along the farthest reach such a drawing is
    given: the object's look-alike spread that far (the ground between
    nuclei, for a dim nucleus whose levels the drawing did not tell). The
    image's sides, which hold an object cut by them, are left out, and so
    are the nodes on an edge of ``field`` (whose window starts at
    ``origin``): a border may lie at the reach (a 3-px click at one end of
    a nucleus 38 px long)."""
    if model.drawn_around:
        return False
    low, high = _near_sides(contour, shape)
    off_sides = ~(low | high).any(axis=1)
    if not off_sides.any():
        return False
    at_reach = np.abs(depth_inside(_scaled(drawing, model.reach), contour[off_sides])) <= AT_REACH_PX
    if np.mean(at_reach) < AT_REACH_SHARE:  # (most contours: the edges need not be read)
        return False
    on_edge = field.on_edge(contour - origin)[off_sides]
    return bool(np.mean(at_reach & ~on_edge) >= AT_REACH_SHARE)


def _beyond_the_area(contour: np.ndarray, max_area: float | None) -> bool:
    """Whether ``contour`` encloses more than ``max_area`` px² (None: no bound)."""
    return max_area is not None and abs(signed_area(contour)) > max_area


def _near_sides(contour: np.ndarray, shape, within: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Which of ``contour``'s coordinates lie within ``within`` px of the
    image's low sides (top, left) and of its high ones (bottom, right)."""
    last = np.array(shape, dtype=float) - 1.0
    return contour <= within, contour >= last - within


def _sides_met(contour: np.ndarray, shape, within: float = 1.0) -> int:
    """How many of the image's four sides ``contour`` comes within ``within`` px of."""
    low, high = _near_sides(contour, shape, within)
    return int(low.any(axis=0).sum()) + int(high.any(axis=0).sum())


def _rest_reason(features: _FeatureWindow, nodes: np.ndarray, phase: int = 0) -> str:
    """Why a contour at rest (window frame) stopped: on the object's border,
    partly on the drawing's limit where that cuts the object off, or elsewhere."""
    on_border, on_limit = features.on_border(nodes, phase)
    if (on_border | on_limit).mean() < ON_BORDER_FRACTION:
        return "stalled"
    if on_border.mean() >= ON_BORDER_FRACTION and on_limit.mean() < ON_LIMIT_FRACTION:
        return "converged"
    return "limited"


#: A contour with at least this fraction of its nodes on the drawing's limit,
#: where that cut the object off, lies across the object there: it is
#: limited, even with ON_BORDER_FRACTION of them on its border (a small
#: circle inside a thin cell, across its sides). On the real-image benchmark
#: 36 results said converged with a fifth of their nodes or more on such a
#: limit: IoU 0.54 in the mean, none 0.85 or more (PSC phase-contrast cells,
#: 21: all below 0.5). A tenth caught 69, but also nuclei cut by the image's
#: side at IoU 0.9, 3 to 6 nodes of 35 against a neighbour the drawing cut.
ON_LIMIT_FRACTION = 0.2


#: Where the drawing's limit cut off a part of the object at least
#: 2 CUT_OFF_DEPTH + 1 px thick, the region ends on no border of the object:
#: nodes within CUT_OFF_REACH px of that part rest on the drawing's limit.
#: (Thinner slivers are the ramp of an edge that a line traced on it, or a
#: hasty hand's margin, leaves out: the contour rests on the border there.)
CUT_OFF_DEPTH = 2
CUT_OFF_REACH = 2


def _cut_off_near(cut: np.ndarray | None) -> np.ndarray | None:
    """The pixels (uint8, 1) within CUT_OFF_REACH of the parts of ``cut`` (the
    object's pixels the drawing's limit cut off) thicker than a sliver; None
    when there are none."""
    if cut is None or not cut.any():
        return None
    thick = cv2.morphologyEx(cut.view(np.uint8), cv2.MORPH_OPEN, _disk(CUT_OFF_DEPTH))
    return cv2.dilate(thick, _disk(CUT_OFF_REACH)) if thick.any() else None


#: A drawing fewer pixels across than this is a click: if it collapses, the
#: error says to draw larger.
SMALL_DRAWING = 8.0


def _divergence(steps: int, stiffness: float, repaired: bool = True) -> DivergenceError:
    what = "became numerically singular and could not be repaired" if repaired else "diverged"
    return DivergenceError(
        f"the contour's element {what} at step {steps}; try a finer node spacing (n_nodes) or a smaller "
        f"sigma_factor (stiffness r = {stiffness:g})"
    )


@dataclass(frozen=True)
class SegmentationProgress:
    """What :func:`iter_segment` yields after every time step.

    Attributes
    ----------
    step : int
        Time steps taken so far.
    contour : ndarray, shape (M, 2)
        The current nodes ``(row, col)`` in the image.
    phase : str
        ``"evolution"`` (every image force) or ``"refinement"`` (the region
        force alone settles the nodes, see ``refine``).
    """

    step: int
    contour: np.ndarray
    phase: str


@dataclass(frozen=True, eq=False)
class FrameFeatures:
    """The feature images of a whole image, computed once and shared by
    several segmentations of it (the objects of one frame when tracking).

    Create with :meth:`of`; pass to :func:`segment` as ``features=``.
    """

    edges: np.ndarray
    intensity: np.ndarray  # normalised, lightly smoothed (sigma 1 px), uneven illumination removed
    noise: float | None = None  # standard deviation of the noise in intensity (None: unknown)
    plane: np.ndarray | None = None  # the background's plane in the image's units (see background_plane)
    missing: np.ndarray | None = None  # the image's NaN pixels, no data: no contour enters them (None: none)

    @classmethod
    def of(cls, image, isef_b: float = 0.7) -> FrameFeatures:
        image, missing = _without_missing(_validate_image(image))
        image = _without_spikes(_as_image(_in_working_range(image)))  # (as segment reads it: the plane's units)
        plane = background_plane(image)
        image = plane_removed(image, plane, (slice(0, image.shape[0]), slice(0, image.shape[1])))
        return cls(*_edges_and_intensity(normalized_intensity(image), isef_b), plane=plane, missing=missing)


#: White noise's standard deviation is multiplied by 1 / (2 sqrt(pi) sigma)
#: by a Gaussian of sigma px (here the intensity's, sigma = 1).
_SMOOTHED_NOISE_GAIN = 1.0 / (2.0 * np.sqrt(np.pi))


def _lightly_smoothed(normalised: np.ndarray) -> np.ndarray:
    """The intensity the region force reads: the region force needs the
    border where it is, a light denoising (sigma 1 px), not the strong ISEF
    smoothing used for edge detection."""
    return cv2.GaussianBlur(normalised, (0, 0), 1.0, borderType=cv2.BORDER_REFLECT)


def _edges_and_intensity(normalised, isef_b: float, noise=None, smoothed=None) -> tuple[np.ndarray, np.ndarray, float]:
    """The edge map of a normalised image (Shen-Castan, as
    :func:`~.features.compute_features` finds it), its lightly smoothed
    intensity (see :func:`_lightly_smoothed`, unless given) and the standard
    deviation of the noise there. The noise is measured before the smoothing
    (after it, the measure, a second difference, sees a tenth of it), unless
    given (read on a larger view of the same image)."""
    if noise is None:
        noise = _noise_sigma(normalised)
    if smoothed is None:
        smoothed = _lightly_smoothed(normalised)
    return shen_castan_edges(normalised, b=isef_b, noise=noise), smoothed, _SMOOTHED_NOISE_GAIN * noise


def _shortest_line(signed: np.ndarray) -> float:
    """Half-length of the shortest normal line (the region force's): at most
    the radius of the object's region (``signed > 0``), so that the inward
    half-line of a node on the border of an object a few pixels across
    does not cross it and read the background beyond (it shrank such
    objects to a point)."""
    radius = np.sqrt(np.count_nonzero(signed > 0) / np.pi)
    return float(np.clip(radius, 1.0, ForceField.min_length))  # the field's default on larger objects


class _FeatureWindow:
    """The image forces, computed on a window around the contour.

    The forces read the feature images along normal lines of at most
    ``max_line_length`` px, so a guard band of that width (and a margin)
    around the contour suffices; the window grows when the contour nears its
    border. On a large image with a small object this is most of the cost of
    a segmentation. The drawing is read once, on a wider window: its levels
    and their units (the intensity range the images are normalised to) stay
    those of the start however the window grows.
    """

    def __init__(self, image, drawing, init, *, polarity, weights, max_line_length, isef_b, refine,
                 shared=None, avoid=None, user_drawing=True, image_noise=None, pixel_noise=None, raw_model=None,
                 evenly_lit=False):
        self.image, self.drawing, self.polarity = image, drawing, polarity
        # The noise's standard deviation in the image's units, and the
        # drawing's levels in them, when the image cannot tell them (a
        # magnified view, see _magnified); else measured and read.
        self.image_noise, self.pixel_noise, self.raw_model = image_noise, pixel_noise, raw_model
        self.user_drawing = user_drawing
        self.shared, self.avoid = shared, avoid
        # The plane under the background, read on the whole image (its
        # illumination), taken out of every window (see background.py). A
        # magnified view shows a window of an image with its surface taken
        # out: a plane may remain across the window, not a dome (a window's
        # crowd of objects would read as one).
        self.plane = shared.plane if shared is not None else background_plane(image, curved=not evenly_lit)
        # A magnified view's image was made of the image's own evenly lit
        # window, its spikes already taken out (see evenly_lit).
        self._spiked = not evenly_lit
        self._lit = None  # the last window evenly_lit made, and its image
        self.weights, self.max_line_length, self.isef_b = weights, max_line_length, isef_b
        # A second phase with the region force alone (sub-pixel refinement).
        self.with_refinement = refine and weights.get("intensity", 0) > 0 and len(weights) > 1
        self.guard = float(max_line_length) + 8.0
        self._read_drawing(self._bounded(bounding_window(init, image.shape, CONTEXT_MARGIN * self.guard),
                                         WINDOW_MAX_FRACTION))
        self._compute(self._bounded(bounding_window(init, image.shape, FORCE_MARGIN * self.guard),
                                    FORCE_WINDOW_MAX_FRACTION))

    def evenly_lit(self, window) -> np.ndarray:
        """The image on ``window`` (float64, not to be written to), its spikes
        and the background's plane taken out. The last window's is kept: the
        polish reads the window the forces were computed on."""
        if self._lit is None or self._lit[0] != window:
            image = _as_image(self.image[window])
            self._lit = window, plane_removed(_without_spikes(image) if self._spiked else image, self.plane, window)
        return self._lit[1]

    @property
    def _whole_image(self):
        return slice(0, self.image.shape[0]), slice(0, self.image.shape[1])

    def _bounded(self, window, fraction: float):
        """``window``, or the whole image when ``window`` would cover more
        than ``fraction`` of it."""
        area = (window[0].stop - window[0].start) * (window[1].stop - window[1].start)
        return self._whole_image if area > fraction * self.image.size else window

    def _read_drawing(self, context) -> None:
        """The drawing's levels (see :func:`~.region.drawing_levels`), read on
        ``context``, and the units of every window's feature images: the
        intensity range ``context`` is normalised to and its noise there
        (the frame's own when the features are shared)."""
        if self.shared is not None:
            self.levels, self.noise = None, None
            intensity, noise = self.shared.intensity[context], self.shared.noise
        else:
            sub = self.evenly_lit(context)
            self.levels = _intensity_range(sub, self.pixel_noise)
            normalised = _normalize(sub, levels=self.levels)
            self.noise = _noise_sigma(normalised) if self.image_noise is None else \
                self.image_noise / max(self.levels[1] - self.levels[0], 1e-300)
            intensity = _lightly_smoothed(normalised)
            rounding = _rounding_sigma(self.image[context]) / max(self.levels[1] - self.levels[0], 1e-300)
            noise = max(_SMOOTHED_NOISE_GAIN * self.noise, rounding)
            # The first feature window is often the context (the whole image).
            self._context = context, normalised, intensity
        if np.ptp(intensity) <= 1e-12:
            if context != self._whole_image:  # nothing here: look at the whole image
                return self._read_drawing(self._whole_image)
            raise ValueError("image is constant: there is no object border to segment")
        origin = np.array([context[0].start, context[1].start], dtype=float)
        self.model = drawing_levels(intensity, self.drawing - origin, self.polarity, noise,
                                    user_drawing=self.user_drawing, image_sides=self._image_sides(context))
        if not self.model.is_visible and context != self._whole_image and self.raw_model is None:
            # The rings a drawing inside a large object is read on reach up to
            # 21 times its size, beyond the window: on the window alone, a
            # circle of 0.4 the radius of a 200-px disk read the disk's rim as
            # its background, and the contour stalled where it was drawn.
            return self._read_drawing(self._whole_image)
        if self.raw_model is not None and not self.model.is_visible:
            # A magnified view shows what the image does, and more finely:
            # where its own reading of the drawing sees no object, the
            # image's reading stands (the view's pixel statistics, smoothed
            # by the interpolation, are not the image's).
            # (At the least contrast of one of the view's pixels: the image's
            # levels were not read on the view's many pixels.)
            seen = _in_units(self.raw_model, self.levels, least_contrast=_least_contrast(intensity, noise))
            if seen.is_visible:
                self.model = seen
        self.polarity = self.model.polarity

    def _image_sides(self, window) -> tuple[bool, bool, bool, bool]:
        """Which sides of ``window`` (top, bottom, left, right) are the image's."""
        rows, cols = window
        return rows.start == 0, rows.stop == self.image.shape[0], cols.start == 0, cols.stop == self.image.shape[1]

    def model_in_image_units(self) -> RegionModel:
        """The drawing's levels in the image's units (see _in_units)."""
        return _in_units(self.model, self.levels, inverse=True)

    def _compute(self, window) -> None:
        sub = self.image[window]
        origin = np.array([window[0].start, window[1].start], dtype=float)
        if self.shared is not None:
            edges, intensity, noise = self.shared.edges[window], self.shared.intensity[window], self.shared.noise
        else:
            context, normalised, smoothed = self._context
            if window != context:
                normalised, smoothed = _normalize(self.evenly_lit(window), levels=self.levels), None
            edges, intensity, noise = _edges_and_intensity(normalised, self.isef_b, self.noise, smoothed)
        if not edges.any() and np.ptp(intensity) <= 1e-12 and sub.shape != self.image.shape:
            return self._compute(self._whole_image)  # nothing here: look at the whole image
        avoid = None if self.avoid is None else self.avoid[window]
        image_sides = self._image_sides(window)
        signed, edges, _, cut = region_features(intensity, edges, self.drawing - origin, avoid=avoid,
                                                image_sides=image_sides, model=self.model, with_cut=True)
        # Not for a line traced on the border: drawn with care (or an earlier
        # result), it is the limit meant (a nucleus traced among touching
        # neighbours). Nor for a program's drawing, a tracked frame's: it is
        # drawn again around a contour against its limit (tracking._redrawn).
        traced = self.model.border_level is not None
        self.cut_off = _cut_off_near(cut) if self.user_drawing and not traced else None
        distance = _distance_with_image_border(edges, signed, window, self.image.shape)
        self.anchor = _anchor(signed, self.drawing - origin)
        field = ForceField.from_features(edges, distance, signed, self.weights, max_length=self.max_line_length,
                                         min_length=_shortest_line(signed))
        self.fields = [field]
        if self.with_refinement:
            self.fields.append(field.with_weights({"intensity": sum(self.weights.values())}))
        self.window, self.origin = window, origin
        # Nodes stay within the image's pixel edges.
        self.bounds = np.array(sub.shape, dtype=float) - 0.5

    def on_border(self, nodes: np.ndarray, phase: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Which ``nodes`` (window frame) rest on the object's border (on a
        feature of the phase's forces), and which on the drawing's limit
        where that cut the object off (the region's outline stands in for an
        edge there, but it is the drawing's, not the object's)."""
        on = self.fields[phase].on_border(nodes)
        if self.cut_off is None:
            return on, np.zeros(len(nodes), bool)
        rows, cols = np.clip(np.rint(nodes).astype(int), 0, np.array(self.cut_off.shape) - 1).T
        on_limit = on & (self.cut_off[rows, cols] > 0)
        return on & ~on_limit, on_limit

    def follow(self, nodes: np.ndarray) -> np.ndarray:
        """Grow the window if ``nodes`` (window frame) near its border; the shift of the frame."""
        if not _near_window_border(nodes, self.window, self.image.shape, self.guard):
            return np.zeros(2)
        # Near its border, most lines are shorter than the longest allowed:
        # the window need only hold the lines the nodes now cast (and the margin).
        reach = float(self.fields[0].line_lengths(nodes).max()) + self.guard - self.max_line_length
        if not _near_window_border(nodes, self.window, self.image.shape, reach):
            return np.zeros(2)
        old = self.origin
        # A contour that grows keeps growing: room for a quarter of its size
        # more (a click inside a 400-px disk grew the window 23 times, each
        # a watershed of it, 5 of its 6.5 s).
        room = FORCE_MARGIN * self.guard + GROWTH_ROOM * float(np.ptp(nodes, axis=0).max())
        self._compute(bounding_window(nodes + old, self.image.shape, room, keep=self.window))
        return old - self.origin


def _in_units(model: RegionModel, levels, *, inverse: bool = False, least_contrast: float | None = None
              ) -> RegionModel:
    """``model``'s levels, read in the image's units, in those of an
    intensity normalised from the image's ``levels`` (lo, hi; see
    features._normalize), with its ``least_contrast`` there; or back
    (``inverse``)."""
    lo, hi = levels
    span = max(hi - lo, 1e-300)

    def to(level):
        return None if level is None else (lo + level * span if inverse else (level - lo) / span)

    floor = model.least_contrast * span if inverse else least_contrast
    return replace(model, object_level=to(model.object_level), background_level=to(model.background_level),
                   border_level=to(model.border_level), least_contrast=floor)


def _polished(features: _FeatureWindow, nodes: np.ndarray) -> np.ndarray:
    """``nodes`` (window frame), at rest, polished onto the border measured
    on the raw image (subpixel.polish), but for those the polish would take
    next to or into pixels of ``avoid``: between touching objects with no
    edge between them the raw image's border lies in the other's pixels,
    and the region force's balance, half-way between the two, stands.

    For a drawing traced on the border, each node goes to the nearer (the
    further in) of two readings: the crossing of the line's own level (as
    the polish reads levels, see subpixel.level_along) and that of the
    half-level. The half-level is read 2.5-4 px either side of
    where the contour rests, and on the wide ramps of blurred nuclei it
    moves with it: a result started from again ended a little further out
    each time (+10 % in area over four runs for an isolated nucleus). The
    line's level holds it; the half-level holds in a line traced a pixel or
    two outside the object's edge, at a level low on its ramp.
    """
    image = features.evenly_lit(features.window)

    def polished_at(level):
        return np.clip(polish(image, nodes, polarity=features.polarity, noise=features.image_noise, level=level),
                       -0.5, features.bounds)

    polished = polished_at(None)
    if features.model.border_level is not None:
        on_line = polished_at(level_along(image, features.drawing - features.origin))
        normals = outward_normals(nodes)
        further_in = ((on_line - nodes) * normals).sum(1) < ((polished - nodes) * normals).sum(1)
        polished = np.where(further_in[:, None], on_line, polished)
    if features.avoid is None:
        return polished
    near_others = cv2.dilate(features.avoid[features.window].view(np.uint8), np.ones((3, 3), np.uint8))
    pixel = np.clip(np.rint(polished).astype(int), 0, np.array(near_others.shape) - 1)
    return np.where(near_others[pixel[:, 0], pixel[:, 1]][:, None] > 0, nodes, polished)


class _ElasticBody:
    """Sclaroff's element for the current nodes, its time integrator, and
    the per-node trust region that keeps each step within ``max_step_length``.

    With the incremental reference the current shape is the rest shape at
    every step; with the total reference the initial shape stays the rest
    shape and the integrator keeps its state.
    """

    def __init__(self, nodes, *, spacing, sigma, material, rayleigh, integrator, dt, divergence_limit,
                 reference, max_step_length, tol, grown_spacing=None):
        self.spacing, self.sigma, self.material, self.rayleigh = spacing, sigma, material, rayleigh
        # The spacing a contour that grows may coarsen to (see remesh).
        self.grown_spacing = spacing if grown_spacing is None else max(spacing, grown_spacing)
        self.integrator, self.dt, self.divergence_limit = integrator, dt, divergence_limit
        self.reference, self.max_step_length, self.tol = reference, float(max_step_length), tol
        self.model_time = 0.0
        self.nodes = nodes
        self.rest = nodes.copy()
        # Counts the times the nodes were replaced (a remesh) and their frame shifted.
        self.remeshes, self.shifts = 0, 0
        self.initial_perimeter, self.shrunk = perimeter(nodes), False
        self.remesh_watch = _RemeshWatch(spacing)
        # A contour that grows keeps its spacing up to this many nodes (see remesh).
        self.max_nodes = MODAL_MAX_NODES if integrator == "modal" else max(len(nodes), MAX_DEFAULT_NODES)
        self._build()
        self._reset_caps()

    def _reset_caps(self, fraction: float = 1.0) -> None:
        self.cap = np.full(len(self.nodes), fraction * self.max_step_length)
        self.last_sign = np.zeros(len(self.nodes))

    def _build(self) -> None:
        """Assemble and factor the element for the current nodes."""
        t0 = time.perf_counter()
        try:
            # A small element is faster dense: scipy.sparse's per-call
            # overhead was most of a 45-node build (1 ms) and of each step.
            system = coefficient_system(self.nodes, self.sigma, self.material,
                                        dense=len(self.nodes) <= DENSE_MAX_NODES)
            self.system = system
            M, K = system.M, system.K
            mu, gamma = self.rayleigh
            if self.integrator == "newmark":
                self.sim = NewmarkIntegrator(M, K, mu * M + gamma * K, dt=self.dt,
                                             divergence_limit=self.divergence_limit)
            else:
                self.sim = ModalIntegrator(M, K, mu=mu, gamma=gamma, dt=self.dt,
                                           divergence_limit=self.divergence_limit)
        finally:
            self.model_time += time.perf_counter() - t0

    def _displacement(self, U: np.ndarray) -> np.ndarray:
        return U.reshape(2, -1).T  # (rows..., cols...) as (M, 2)

    def move_under(self, forces: np.ndarray, normals: np.ndarray) -> np.ndarray:
        """The nodes' motion over one time step under ``forces`` (M, 2)."""
        G = self.system.G
        f = forces.T.ravel()  # (rows..., cols...)
        if self.reference == "incremental":
            # The current shape is the rest shape and the body starts the
            # step at rest: one solve of the dynamic equation over dt.
            move = self._displacement(G @ self.sim.from_rest(G @ f))
            self._update_caps(move, normals)
            reach = np.hypot(move[:, 0], move[:, 1])
            return move * np.minimum(1.0, self.cap / np.maximum(reach, 1e-12))[:, None]
        move = self._displacement(G @ self.sim.trial(G @ f)) + self.rest - self.nodes
        self._update_caps(move, normals)
        # Forces on nodes that would move more than their cap are scaled down
        # before the step is taken, so the integrator's state stays consistent.
        for attempt in range(2):
            reach = np.linalg.norm(move, axis=1)
            over = reach > self.cap
            if not over.any():
                break
            scale = np.where(over, self.cap / np.maximum(reach, 1e-12), 1.0)
            f = f * np.concatenate([scale, scale])
            if attempt == 0:
                move = self._displacement(G @ self.sim.trial(G @ f)) + self.rest - self.nodes
        return self._displacement(G @ self.sim.step(G @ f)) + self.rest - self.nodes

    def cap_by_reach(self, field: ForceField) -> None:
        """Start every node's trust cap at its distance to the nearest edge
        (and half a pixel): a node that starts on its border (a contour
        carried over from the previous frame, or one entering refinement)
        needs no 2-px jump to find it, and would overshoot and swing back."""
        reach = field.distance_at(self.nodes) + 0.5
        self.cap = np.clip(reach, 0.25 * self.tol, self.max_step_length)
        self.last_sign = np.zeros(len(self.nodes))

    def _update_caps(self, move, normals) -> None:
        """Per-node trust region (as in Rprop): a node whose motion along its
        normal reverses (it stepped over its equilibrium) halves its cap, one
        that keeps going lets it grow back; so every material comes to rest."""
        sign = np.sign((move * normals).sum(1))
        cap = np.where(sign * self.last_sign < 0, 0.5 * self.cap, np.minimum(1.25 * self.cap, self.max_step_length))
        self.cap, self.last_sign = np.maximum(cap, 0.25 * self.tol), sign

    def remesh(self, nodes: np.ndarray, bounds: np.ndarray, keep=None) -> None:
        """New nodes without pinches, loops or crowded nodes, evenly spaced; a new element.

        Of the pieces a pinch parts, the one holding more of the points
        ``keep`` is kept. Each new node inherits the trust cap of the old node
        nearest to it.
        """
        # Beyond max_nodes the spacing (and the element's width with it)
        # grows: a click with a fine spacing that grows into a large object
        # made thousands of nodes, a dense eigenproblem each for "modal".
        # Before that, a small drawing's spacing (MIN_NODES on it) grows
        # with it up to the one it would be drawn with at its new length: a
        # click grown along a rod kept 200 nodes 0.3 px apart.
        length = perimeter(nodes)
        coarser = max(length / self.max_nodes, min(self.grown_spacing, length / MIN_NODES))
        if coarser > self.spacing:
            self.sigma *= coarser / self.spacing
            self.spacing = coarser
            self.remesh_watch = _RemeshWatch(coarser)
        old, nodes = nodes, _repaired(nodes, bounds, self.spacing, keep)
        nearest = nearest_node(nodes, old)
        cap, last_sign = self.cap[nearest], self.last_sign[nearest]
        self.nodes = self.rest = nodes
        self.remeshes += 1
        self.remesh_watch.forget()
        if not self.collapsed:
            try:
                self._build()
            except (np.linalg.LinAlgError, RuntimeError, ValueError):
                # A contour shrunk to a few nodes at the image's side (or
                # anywhere) whose element is singular has collapsed: the
                # same outcome as one shrunk to a point, not a divergence.
                if perimeter(nodes) >= SHRUNK_PERIMETER * self.initial_perimeter:
                    raise
                self.shrunk = True
        self.cap, self.last_sign = cap, last_sign

    @property
    def collapsed(self) -> bool:
        return self.shrunk or len(self.nodes) < 3 or abs(signed_area(self.nodes)) < 1.0

    def shift(self, offset: np.ndarray) -> None:
        if not offset.any():
            return
        self.shifts += 1
        self.nodes, self.rest = self.nodes + offset, self.rest + offset
        self.remesh_watch.shift(offset)


#: A contour whose element cannot be built at a remesh has collapsed when
#: its length has shrunk below this share of its initial length.
SHRUNK_PERIMETER = 0.25


def _repaired(nodes: np.ndarray, bounds: np.ndarray, spacing: float, keep=None) -> np.ndarray:
    """``nodes`` without pinches, loops or crowded nodes, evenly spaced ``spacing`` apart;
    of the pieces a pinch parts, the one holding more of the points ``keep``."""
    # Clipped first: nodes pushed past a corner of the image meet there.
    fixed = np.clip(nodes, -0.5, bounds)
    gap = PINCH_GAP * spacing
    # Resampling a contour that runs out along the image's side and back
    # puts new nodes on top of each other: cut again until none pinch.
    for _ in range(3):
        fixed = resample(remove_loops(cut_pinches(fixed, gap, keep=keep)), spacing=spacing)
        if len(fixed) < 4 or not len(pairs_within(fixed, gap)[0]):
            break
    distinct = np.linalg.norm(fixed - np.roll(fixed, 1, axis=0), axis=1) > 1e-3 * spacing
    return fixed[distinct] if distinct.sum() >= 3 else fixed


def _new_body(nodes: np.ndarray, bounds: np.ndarray, **options) -> _ElasticBody:
    """The elastic body on ``nodes``, repaired as at a remesh if they make its element singular.

    A drawing partly beyond the image, clipped to it, can run out along the
    image's side and back: nodes on top of each other.
    """
    try:
        return _ElasticBody(nodes, **options)
    except (np.linalg.LinAlgError, RuntimeError, ValueError):
        repaired = _repaired(nodes, bounds, options["spacing"])
    try:
        return _ElasticBody(repaired, **options)
    except (np.linalg.LinAlgError, RuntimeError, ValueError) as err:
        raise ValueError("init gives a singular element even once its overlapping nodes are repaired; draw a "
                         "simple contour that encloses an area of the image") from err


class _RestDetector:
    """At rest: over the last ``patience`` steps no node strayed more than
    ``patience * tol`` px from where it was (it moved less than ``tol`` px per
    step on average, and a node that trembles about its place does not count
    as moving), or the shape reached a plateau (see :class:`_Plateau`).

    Across a remesh, which puts new nodes on about the same curve, the nodes
    cannot be followed one by one: the contours of the window are compared
    as curves instead, each within half that distance of the newest (so
    within it of each other), so a contour remeshed every few steps can
    still be seen at rest. The track restarts when the frame the nodes are
    measured in shifts.
    """

    def __init__(self, tol, patience):
        self.tol, self.patience = tol, int(patience)
        self.track, self.plateau = deque(maxlen=self.patience + 1), _Plateau()
        self.shifts = None

    def at_rest(self, nodes: np.ndarray, shifts: int, remeshes: int) -> bool:
        if shifts != self.shifts:
            self.track.clear()
            self.shifts = shifts
        self.track.append((remeshes, nodes.copy()))
        if len(self.track) > self.patience and self._still():
            return True
        return self.plateau.reached(nodes)

    def _still(self) -> bool:
        reach = self.patience * self.tol
        last = self.track[-1][0]
        same = [nodes for remeshes, nodes in self.track if remeshes == last]  # since the last remesh
        if np.ptp(np.stack(same), axis=0).max() > reach:
            return False
        if len(same) == len(self.track):
            return True
        newest = same[-1]
        return all(contour_gap(nodes, newest) <= 0.5 * reach for remeshes, nodes in self.track if remeshes != last)


#: The element's Gaussian width is at most this many node spacings: wider,
#: each node is tied to nodes beyond its neighbours and the element stiffens
#: past any use (0.75-1.5 is typical).
MAX_SIGMA_FACTOR = 2.0


def _checked_options(material, forces, weights, stiffness, reference, integrator, polarity, max_step_length, tol,
                     max_steps, n_nodes, sigma, sigma_factor, dt=1.0, damping_ratio=1.0, patience=5,
                     max_line_length=40.0, history_every=5, refine=True, magnify=True, contrast="auto"):
    """The material, the force weights and the stiffness (None: the one that
    suits the material), once every option is checked (ValueError naming the bad one)."""
    _check_run_options(dt, damping_ratio, max_steps, patience, max_line_length, history_every, refine, magnify)
    material = get_material(material)
    weights = normalize_weights(forces, weights)
    if stiffness is None:
        stiffness = suggested_stiffness(material)
    try:  # a number (numpy's too), not a flag or a text
        r = np.nan if isinstance(stiffness, (bool, np.bool_, str, bytes)) else float(stiffness)
    except (TypeError, ValueError):
        r = np.nan
    if not (np.isfinite(r) and r > 0):
        raise ValueError(f"stiffness r must be a positive number, got {stiffness!r}")
    if reference not in ("incremental", "total"):
        raise ValueError(f"reference must be 'incremental' or 'total', got {reference!r}")
    if integrator not in ("newmark", "modal"):
        raise ValueError(f"integrator must be 'newmark' or 'modal', got {integrator!r}")
    if polarity not in ("auto", "bright", "dark"):
        raise ValueError(f"polarity must be 'auto', 'bright' or 'dark', got {polarity!r}")
    _check_contrast(contrast)
    check_number(max_step_length, "max_step_length", inclusive=False)
    check_number(tol, "tol", inclusive=False)
    if check_count(n_nodes, "n_nodes", 3, allow_none=True) is not None and n_nodes > MAX_NODES:
        raise ValueError(f"n_nodes must be between 3 and {MAX_NODES}, got {n_nodes!r}: one node every 2-5 px "
                         "is typical (contour.nodes_for_spacing)")
    if sigma is not None:  # (its bound, a multiple of the node spacing, is checked once the nodes are placed)
        check_number(sigma, "sigma (the element's, in px)", inclusive=False)
    if sigma is None and not (isinstance(sigma_factor, (int, float, np.number)) and not isinstance(sigma_factor, bool)
                              and 0 < sigma_factor <= MAX_SIGMA_FACTOR):
        raise ValueError(f"sigma_factor must be above 0 and at most {MAX_SIGMA_FACTOR:g}, got {sigma_factor!r}; "
                         "typical values are 0.75-1.5")
    return material, weights, r


#: The widest range of the time step, the normal lines' half-length and the
#: damping ratio that make sense: beyond them, the numbers overflow or the
#: lines cross the largest images many times (and their cost grows with them).
MAX_DT = 1e6
MAX_LINE_LENGTH = 2000.0
MIN_LINE_LENGTH = 2.0
MAX_DAMPING_RATIO = 100.0


def _check_run_options(dt, damping_ratio, max_steps, patience, max_line_length, history_every, refine, magnify):
    """A ValueError naming the first of these options of segment that is out of its range."""
    check_number(dt, "dt (the time step)", inclusive=False, maximum=MAX_DT)
    check_number(damping_ratio, "damping_ratio", maximum=MAX_DAMPING_RATIO)
    check_count(max_steps, "max_steps", 0)
    check_count(patience, "patience (steps at rest)", 1)
    check_count(history_every, "history_every", 1)
    check_number(max_line_length, "max_line_length (px)", minimum=MIN_LINE_LENGTH, maximum=MAX_LINE_LENGTH)
    for name, flag in (("refine", refine), ("magnify", magnify)):
        if not isinstance(flag, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, got {flag!r}")


def nodes_at_spacing(contour, node_spacing: float) -> int:
    """The node count that puts nodes ``node_spacing`` px apart on
    ``contour``, at most MAX_NODES, with a warning (a sub-pixel typo, 0.01
    for 1, ran for hours; the widgets asked segment for more and failed)."""
    contour = np.asarray(contour, float)
    n_nodes = nodes_for_spacing(contour, node_spacing)
    if n_nodes > MAX_NODES:
        length = perimeter(contour)
        warnings.warn(f"a node spacing of {node_spacing:g} px gives a contour {length:.0f} px around {n_nodes} "
                      f"nodes: it gets {MAX_NODES} ({length / MAX_NODES:.2g} px apart), the most segment takes; "
                      "2-5 px is typical", UserWarning, stacklevel=3)
        n_nodes = MAX_NODES
    return n_nodes


def check_segment_options(**options) -> None:
    """Raise the error :func:`segment` would raise for these options, before
    any image is read: for callers that segment many times (:func:`~.tracking.track`)."""
    arguments = with_defaults(segment, (None, None), options)  # a misspelt option: TypeError
    names = signature_of(_checked_options).parameters
    _checked_options(**{name: arguments[name] for name in names})


#: integrator="modal" solves a dense generalized eigenproblem of 2M x 2M at
#: every remesh, O(M^3): 0.5 s at 650 nodes, ~35 s at 2000 on one core.
MODAL_MAX_NODES = 500


def _initial_nodes(init, n_nodes, sigma, sigma_factor):
    """Evenly spaced nodes on ``init``, their spacing and the element's sigma."""
    length = perimeter(init)
    if n_nodes is None:
        n_nodes = int(np.clip(nodes_for_spacing(init, DEFAULT_NODE_SPACING), MIN_NODES, MAX_DEFAULT_NODES))
    spacing = length / int(n_nodes)
    sigma_used = float(sigma) if sigma is not None else sigma_factor * spacing
    if not (np.isfinite(sigma_used) and 0 < sigma_used <= MAX_SIGMA_FACTOR * spacing):
        raise ValueError(
            f"sigma = {sigma_used!r} must be positive and at most {MAX_SIGMA_FACTOR:g} x the node spacing "
            f"({spacing:.3g} px); "
            "typical values are 0.75-1.5 x the spacing"
        )
    # A jittery freehand line, resampled, can twist over itself: an element
    # on a twist is singular (the "total" reference, which never remeshes,
    # diverged at its first step). The twists are cut as at a remesh.
    nodes = resample(init, int(n_nodes))
    if crosses_itself(nodes):
        nodes = resample(remove_loops(nodes), spacing=spacing)
    return nodes, spacing, sigma_used


def _finer_for_its_size(init, n_nodes, sigma) -> bool:
    """Whether ``init``'s default nodes are closer than DEFAULT_NODE_SPACING
    because it is too small for MIN_NODES of them (a click)."""
    return n_nodes is None and sigma is None and perimeter(init) < MIN_NODES * DEFAULT_NODE_SPACING


def iter_segment(image, init, **options):
    """:func:`segment` as a generator: one :class:`SegmentationProgress` per time step.

    Takes the parameters of :func:`segment` (but ``callback``), with its
    defaults, and returns (as ``StopIteration.value``) its
    :class:`SegmentationResult`. Send
    ``True`` into the generator to stop it after the current step: the result
    then has ``stop_reason="cancelled"``. Bad input raises before the first
    step. napari's ``thread_worker`` runs it as it is.

    Examples
    --------
    >>> from napari_physeg import data
    >>> obj = data.ellipse()
    >>> run = iter_segment(obj.image, obj.init_near)
    >>> first = next(run)
    >>> first.step, first.phase
    (1, 'evolution')
    """
    arguments = _segment_arguments(image, init, options)
    if options.get("callback") is not None:
        raise TypeError("iter_segment takes no callback: it yields its progress")
    return _evolve_read(**arguments)


def _evolve_read(image, init, *, contrast: str, **options):
    """:func:`_evolve` on what tells the object from its background (see
    segment's ``contrast``): the image itself, or its texture. (Not a
    generator of its own: the warnings' stack levels count _evolve's frames.)"""
    _check_contrast(contrast)  # (before the texture is made: the other options are checked in _set_up)
    if contrast == "texture" and options["features"] is not None:
        raise ValueError("contrast='texture' reads its own features: pass features=None")
    if contrast == "auto" and (options["polarity"] != "auto" or options["features"] is not None):
        contrast = "intensity"
    if contrast != "intensity":
        checked = _validate_image(image)  # (the error _set_up would raise, raised first)
        if contrast == "auto":
            contrast = "texture" if _textured(checked, init) else "intensity"
        if contrast == "texture":
            image = texture_map(checked)
    return _evolve(image, init, contrast=contrast, **options)


def _check_contrast(contrast) -> None:
    if contrast not in CONTRASTS:
        raise ValueError(f"contrast must be one of {', '.join(map(repr, CONTRASTS))}, got {contrast!r}")


def _textured(image: np.ndarray, init) -> bool:
    """Whether the object ``init`` marks on ``image`` (validated) is told by
    its texture (see :func:`~.texture.told_by_texture`); False for a bad
    drawing, which the segmentation then names."""
    try:
        from ._validation import check_drawing

        return told_by_texture(image, check_drawing(init, "init"))
    except ValueError:
        return False


def _segment_arguments(image, init, options: dict) -> dict:
    """:func:`segment`'s arguments with every default filled in, but its
    ``callback`` (a misspelt option: TypeError)."""
    arguments = with_defaults(segment, (image, init), options)
    arguments.pop("callback")
    return arguments


def _evolve(
    image,
    init,
    *,
    material: str | Material,
    stiffness: float | None,
    n_nodes: int | None,
    sigma: float | None,
    sigma_factor: float,
    forces,
    weights: dict | None,
    polarity: str,
    contrast: str,
    damping_ratio: float,
    dt: float,
    reference: str,
    integrator: str,
    max_steps: int,
    max_step_length: float,
    tol: float,
    patience: int,
    max_line_length: float,
    isef_b: float,
    refine: bool,
    history_every: int,
    features: FrameFeatures | None,
    avoid,
    magnify: bool,
    start=None,
    warn: bool = True,
    image_noise: float | None = None,
    pixel_noise: float | None = None,
    raw_model: RegionModel | None = None,
    evenly_lit: bool = False,
    max_area: float | None = None,
):
    """The steps of :func:`segment` (see :func:`iter_segment`); every option given.

    ``start`` (optional, (N, 2)): the nodes to start from, when they are not
    the drawing ``init`` itself (see :func:`_segment_from`); the drawing then
    lies around the object, never traced on its border. ``max_area``
    (optional, px²): a contour that encloses more has leaked, and stops. ``warn``: whether
    to warn of the drawing's and the image's flaws (not again on a
    magnified view, see :func:`_magnified`); ``image_noise``,
    ``pixel_noise`` and ``raw_model``: the noise's standard deviation as
    the segmentation reads it and in the pixels, and the drawing's levels
    (the image's units), when the image cannot tell them; ``evenly_lit``:
    whether the image's background surface is already taken out (a
    magnified view's: a plane of its own is still fitted, no dome).
    """
    options = dict(locals())
    t_start = time.perf_counter()
    setup = _set_up(options)
    options["init"] = setup.drawing  # (a click as its circle, in the image's pixels, on a magnified view too)
    features = setup.features
    t_features = time.perf_counter()
    # A user's drawing inside a small object is read as segment() alone reads
    # it, on the magnified view, even where the image's features are shared
    # (a tracking's start frame): at the image's scale a click inside a dim,
    # textured HeLa nucleus took its bright core for the object (IoU 0.30 and
    # 0.36, alone 0.93 and 0.90). The view reads its own features. (Drawings
    # around objects stay on the frame's: magnified, the warped Data Science
    # Bowl movies lost more nuclei, e.g. rotation 10 -> 33 nucleus-frames.)
    # A click is inside its object, however the image's scale reads it: a
    # click in a MitoCheck nucleus 12 px across, read as around a bright
    # speck, ended on 10 of its 142 px (alone 117) and was lost after.
    inside = start is None and (not features.model.drawn_around or _click_sized(setup.drawing))
    view = _magnified_view(features, options) if magnify and (features.shared is None or inside) else None
    if view is not None:
        return (yield from _magnified(view, features, options, t_start))

    body = _body_of(setup, options)
    history = [body.nodes + features.origin]
    stop_reason, steps, settled = yield from _time_loop(body, setup, options, history)
    nodes, stop_reason = _final_nodes(body, setup, stop_reason, settled, steps, contrast)
    if not np.array_equal(history[-1], nodes):
        history.append(nodes.copy())
    t_end = time.perf_counter()
    return SegmentationResult(
        contour=nodes, steps=steps, converged=stop_reason == "converged", stop_reason=stop_reason,
        history=tuple(history), polarity=features.polarity, contrast=contrast,
        timings={"features": t_features - t_start, "model": body.model_time,
                 "evolution": t_end - t_features - body.model_time, "total": t_end - t_start},
    )


@dataclass(frozen=True, eq=False)
class _Setup:
    """What an evolution starts from, every input checked (see :func:`_set_up`)."""

    shape: tuple  # the image's
    drawing: np.ndarray  # as the user made it (partly beyond the image, maybe)
    init: np.ndarray  # the drawing clipped to the image
    first: np.ndarray  # what the nodes start on: init, or the given start
    nodes: np.ndarray
    spacing: float  # the nodes'
    sigma: float  # the element's
    material: Material
    stiffness: float
    features: _FeatureWindow


def _set_up(options: dict) -> _Setup:
    """:func:`_evolve`'s ``options`` checked (ValueError naming the bad one),
    the first nodes laid on the drawing, and the feature window read."""
    o = options
    image, missing = _without_missing(_validate_image(o["image"]))
    image = _in_working_range(image)
    from ._validation import check_contour, check_drawing  # the one validation of segment, match and simulate

    init = check_drawing(o["init"], "init")
    checked = signature_of(_checked_options).parameters
    material, weights, stiffness = _checked_options(**{name: o[name] for name in checked})
    # The drawing as the user made it (partly beyond the image, maybe) tells
    # the object from its background; the clipped one starts the contour.
    drawing, start, warn = init, o["start"], o["warn"]
    if warn:
        # (stacklevel: this, _set_up, _evolve, drain, segment, its caller)
        warn_if_figure_eight(drawing, "init", "the result may hold a part of the object only; draw one outline that "
                             "does not cross itself, around (or inside) the object", stacklevel=6)
    # A click's circle is the package's, not the user's: its nodes beyond the
    # image, clipped, are no news to someone who clicked inside it.
    init = _clip_to_image(init, image.shape, warn and clicked(o["init"]) is o["init"])
    _check_on_data(init, missing)
    first = init if start is None else _clip_to_image(check_contour(start, "start"), image.shape, warn)
    nodes, spacing, sigma = _initial_nodes(first, o["n_nodes"], o["sigma"], o["sigma_factor"])
    if o["integrator"] == "modal" and len(nodes) > MODAL_MAX_NODES:
        raise ValueError(
            f"integrator='modal' with {len(nodes)} nodes would solve a dense {2 * len(nodes)} x {2 * len(nodes)} "
            f"eigenproblem at every remesh (seconds to minutes each); use integrator='newmark' (the same "
            f"equation, sparse) or at most n_nodes={MODAL_MAX_NODES}"
        )
    for name in ("features", "avoid"):
        given = o[name]
        if given is not None and np.shape(getattr(given, "edges", given)) != image.shape:
            raise ValueError(f"{name} must be of the image's shape {image.shape}, got "
                             f"{np.shape(getattr(given, 'edges', given))}")
    avoid = _avoiding_missing(_checked_avoid(o["avoid"], image.shape), missing, o["features"], warn)
    features = _FeatureWindow(image, drawing, init, polarity={"bright": 1, "dark": -1}.get(o["polarity"]),
                              weights=weights, max_line_length=o["max_line_length"], isef_b=o["isef_b"],
                              refine=o["refine"] and o["reference"] == "incremental", shared=o["features"],
                              avoid=None if avoid is None else np.asarray(avoid, dtype=bool),
                              user_drawing=start is None, image_noise=o["image_noise"],
                              pixel_noise=o["pixel_noise"], raw_model=o["raw_model"], evenly_lit=o["evenly_lit"])
    return _Setup(shape=image.shape, drawing=drawing, init=init, first=first, nodes=nodes, spacing=spacing,
                  sigma=sigma, material=material, stiffness=stiffness, features=features)


#: A drawing that encloses more than this share of pixels without data lies
#: off the object: on a registration's NaN margin, a circle came to rest as 3
#: nodes there ("stalled"), or collapsed with an error about ``avoid``.
NO_DATA_SHARE = 0.5


def _check_on_data(init: np.ndarray, missing: np.ndarray | None) -> None:
    """ValueError if ``init`` (clipped to the image) lies mostly on pixels
    that hold no data (``missing``: NaN or masked in the image)."""
    share = _avoided_share(init, missing)
    if share > NO_DATA_SHARE:
        raise ValueError(f"init encloses pixels that hold no data (NaN or masked) for {share:.0%} of its area "
                         f"({missing.mean():.1%} of the image holds none): draw it around an object where the image "
                         "has data")


def _body_of(setup: _Setup, options: dict) -> _ElasticBody:
    """The elastic body on the first nodes (window frame), its material
    damped as ``options`` say, its steps capped by the first force's reach."""
    o, features = options, setup.features
    rayleigh = rayleigh_coefficients(o["damping_ratio"], *reference_frequency_range(setup.spacing, setup.sigma,
                                                                                      setup.material))
    body = _new_body(
        setup.nodes - features.origin, features.bounds, spacing=setup.spacing, sigma=setup.sigma,
        material=setup.material, rayleigh=rayleigh, integrator=o["integrator"], dt=o["dt"],
        divergence_limit=10.0 * float(np.hypot(*setup.shape)), reference=o["reference"],
        max_step_length=o["max_step_length"], tol=o["tol"],
        grown_spacing=DEFAULT_NODE_SPACING if _finer_for_its_size(setup.first, o["n_nodes"], o["sigma"]) else None)
    body.cap_by_reach(features.fields[0])
    return body


def _time_loop(body: _ElasticBody, setup: _Setup, options: dict, history: list):
    """The paper's loop: image forces along the normals, one step of the
    dynamic equilibrium, remesh when the nodes crowd or thin out. Yields a
    :class:`SegmentationProgress` a step (``True`` sent back cancels),
    appends to ``history`` every ``history_every`` steps, and returns the
    stop reason, the steps taken and where the evolution came to rest
    (image frame; None if it had not).

    Phase 0 uses every force; once at rest, a short second phase lets the
    region force alone (sub-pixel: it balances where the lightly smoothed
    intensity crosses the object/background mid-level) settle the nodes that
    edge pixels hold half a pixel off the true border; a geometric polish
    (:func:`_final_nodes`) then ends them on the border of the raw image.
    The evolution need only bring the nodes within reach of the refinement
    (if any), and the refinement within reach of the polish.
    """
    features, o = setup.features, options
    stop_reason, steps = "max_steps", 0
    phase = _first_phase(features, body.nodes, carried=o["start"] is not None)
    rest_tol = o["tol"] * (HANDOVER if len(features.fields) > 1 else 1.0)  # the same in either phase
    rest = _RestDetector(rest_tol, _phase_patience(phase, o["patience"]))
    settled = None
    for steps in range(1, int(o["max_steps"]) + 1):
        body.shift(features.follow(body.nodes))
        _time_step(body, features.fields[phase], setup.stiffness, features.bounds, steps, features.anchor)
        if body.collapsed:
            break
        if steps % max(int(o["history_every"]), 1) == 0:
            history.append(body.nodes + features.origin)
        stop = yield SegmentationProgress(steps, body.nodes + features.origin,
                                          "evolution" if phase == 0 else "refinement")
        if stop:
            stop_reason = "cancelled"
            break
        if steps % LEAK_CHECK_EVERY == 0 and (
                _beyond_the_area(body.nodes, o["max_area"]) or _spread_beyond_the_object(
                    body.nodes + features.origin, setup.init, setup.drawing, features, features.fields[phase],
                    setup.shape)):
            # Stopped at once: a leak crawls on for seconds (a circle on the
            # ground between nuclei, 200-1000 steps) and ends no nearer an object.
            stop_reason = "leaked"
            break
        at_rest = rest.at_rest(body.nodes, body.shifts, body.remeshes)
        if at_rest or rest.plateau.swinging():
            if phase == len(features.fields) - 1:
                stop_reason = _rest_reason(features, body.nodes, phase) if at_rest else "oscillating"
                break
            # An evolution that swings without progress (edges either side of
            # a blurred border pulling in turn) hands over too: the region
            # force alone may settle it.
            phase += 1
            settled = body.nodes + features.origin if at_rest else None
            rest = _RestDetector(rest_tol, _phase_patience(phase, o["patience"]))
            body.cap_by_reach(features.fields[phase])
    return stop_reason, steps, settled


def _final_nodes(body: _ElasticBody, setup: _Setup, stop_reason: str, settled, steps: int,
                 contrast: str) -> tuple[np.ndarray, str]:
    """The result's nodes (image frame) and stop reason once the loop ended
    with ``stop_reason``: what succeeded kept, a converged contour polished
    on the raw image, and a converged one that spread beyond its object
    called leaked."""
    features, nodes = setup.features, body.nodes
    if stop_reason == "oscillating" and settled is not None:
        # The refinement swings about the border that the evolution found: keep that.
        nodes = settled - features.origin
        stop_reason = _rest_reason(features, nodes)
    if stop_reason != "cancelled" and body.collapsed:
        nodes, stop_reason = _before_collapse(features, settled, setup.drawing, steps, contrast)
    if stop_reason in ("converged", "limited") and features.with_refinement:
        # At rest every node is within a few tenths of a pixel of the border,
        # read on smoothed images and each on its own noise: measure the border
        # on the raw image and fit the polygon to it (see subpixel.polish).
        nodes = _polished(features, nodes)
    nodes = nodes + features.origin
    if stop_reason in ("converged", "limited") and (
            _spread_beyond_the_object(nodes, setup.init, setup.drawing, features, features.fields[0], setup.shape)
            or _around_others(nodes, features.avoid)):
        stop_reason = "leaked"
    elif stop_reason in ("converged", "limited") and (_on_the_image_frame(nodes, setup.shape) or
                                                       _folded(nodes, setup.shape)):
        stop_reason = "stalled"
    return nodes, stop_reason


#: A contour whose mean width (twice its area over its length) is less than
#: this many px encloses no object: it folded onto itself. Around the faint
#: rings of a nuclear envelope in noise, contours came to rest as 3 or 4
#: nodes about 2 px, said converged (an outside tester, session 69); the
#: thinnest objects of the benchmarks, rods 4-6 px wide, are several. But
#: the image's side may show a sliver of an object it cuts (2 px of a disk
#: coming into view is followed in).
LEAST_WIDTH = 1.0


def _folded(contour: np.ndarray, shape) -> bool:
    """Whether ``contour``, away from the image's sides, is thinner than LEAST_WIDTH on average."""
    return _thinner_than(contour, LEAST_WIDTH) and _sides_met(contour, shape) == 0


def _thinner_than(contour: np.ndarray, width: float) -> bool:
    """Whether ``contour`` is thinner than ``width`` px on average (twice its area over its length)."""
    return 2.0 * abs(signed_area(contour)) < width * perimeter(contour)


def _checked_avoid(avoid, shape) -> np.ndarray | None:
    """``avoid`` as a boolean mask of the image's ``shape``, or a ValueError
    saying what it must be (a float image passed as avoid was read as
    avoiding everything, and the contour said it collapsed)."""
    if avoid is None:
        return None
    mask = np.asarray(avoid)
    if mask.shape != tuple(shape):
        raise ValueError(f"avoid must be a mask of the image's shape {tuple(shape)}, got shape {mask.shape}")
    if mask.dtype != bool and not (mask.dtype.kind in "iuf" and np.isin(mask, (0, 1)).all()):
        raise ValueError("avoid must be a boolean mask, True on the other objects' pixels; for a labels image "
                         "give labels > 0 (without the object's own label)")
    return mask.astype(bool, copy=False)


def _avoiding_missing(avoid, missing, features: FrameFeatures | None, warn: bool = True):
    """``avoid`` with the pixels that hold no data (``missing``: NaN in the
    image, with a warning if ``warn``; or in the image ``features`` were
    computed on): a contour keeps out of them as out of the image, whose
    side an object they cut takes for its own."""
    if missing is not None and warn:
        warnings.warn(f"{int(missing.sum())} NaN (or masked) pixels of the image ({missing.mean():.1%}) were read "
                      "as no data: the contour keeps out of them", UserWarning,
                      stacklevel=6)  # segment()'s caller (through _set_up, _evolve, drain and segment)
    if features is not None and features.missing is not None:
        missing = features.missing if missing is None else missing | features.missing
    if missing is None:
        return avoid
    return missing if avoid is None else np.asarray(avoid, dtype=bool) | missing


def _object_radius(features: _FeatureWindow, region: np.ndarray) -> float:
    """The object's radius (px; that of the disk of its area) as the drawing
    says it: its own ``region``'s (the feature window's object-like pixels);
    the drawing's when no region stands out. (Not the drawing's when
    smaller: a small circle drawn over a large object's edge, magnified for
    its size, lost a tenth of its IoU on the held-out nuclei, 0.84 -> 0.80.)"""
    area = float(np.count_nonzero(region))
    if area == 0:
        area = abs(signed_area(features.drawing))
    return float(np.sqrt(area / np.pi))


def _click_sized(drawing: np.ndarray) -> bool:
    """Whether ``drawing`` is no larger than twice a click's circle (see
    :data:`~._validation.CLICK_RADIUS`): a click, or a circle of a few pixels."""
    return bool(np.ptp(drawing, axis=0).max() <= 4.0 * CLICK_RADIUS)


@lru_cache(maxsize=None)
def _magnified_noise_gain(factor: int) -> float:
    """The standard deviation of white noise, magnified ``factor`` times (see
    :mod:`.magnify`), as the segmentation reads it (lightly smoothed), over
    that of white noise read so: how much noisier the magnified view is, to
    the segmentation, than its pixels' noise says (interpolation spreads each
    sample over ``factor`` px, which a smoothing of 1 px no longer averages;
    measured on the view itself, Immerkaer's second differences see almost
    none of it, and a circle around a small disk in strong noise came to rest
    on the noise)."""
    noise = np.random.default_rng(0).standard_normal((128, 128))
    view = cv2.resize(noise, None, fx=factor, fy=factor, interpolation=cv2.INTER_LINEAR)
    inner = slice(8 * factor, -8 * factor)
    return float(_lightly_smoothed(view)[inner, inner].std()) / _SMOOTHED_NOISE_GAIN


def _magnified_view(features: _FeatureWindow, options: dict) -> MagnifiedView | None:
    """The magnified view (see :mod:`.magnify`) to segment a small object on,
    or None for an object large enough, or a view too large to be worth its
    cost. The view holds the drawing, the start and the object's region, and
    the windows the segmentation reads around them."""
    region = features.fields[0].objectness > 0
    radius = _object_radius(features, region)
    factor = magnification(radius)
    if factor == 1:
        return None
    shape = np.array(features.image.shape) - 1.0
    points = [np.clip(np.asarray(options["init"], dtype=float), 0, shape), np.argwhere(region) + features.origin]
    if options["start"] is not None:
        points.append(np.clip(np.asarray(options["start"], dtype=float), 0, shape))
    while True:
        # The segmentation reads the drawing within CONTEXT_MARGIN guard bands
        # of it, and guard bands are of the view's pixels.
        margin = CONTEXT_MARGIN * (float(options["max_line_length"]) + 8.0) / factor + 2.0
        view = MagnifiedView.around(np.vstack(points), features.image.shape, margin, factor)
        fitting = magnification(radius, view.pixels)
        if fitting == factor:
            return view if factor > 1 else None
        factor = fitting


def _magnified(view: MagnifiedView, features: _FeatureWindow, options: dict, t_start: float):
    """:func:`_evolve` of a small object on the magnified ``view`` of its
    neighbourhood (see :func:`_magnified_view`), its progress and result
    brought back to the image. If the segmentation fails there, or its
    contour meets the view's cut, the object is segmented on the image
    itself: at once, as the contour on the view will not come back from
    the cut (a click on a rod of a packed colony crawled 440 steps over its
    neighbours on the view, 3.5 s, before the image took over); a click,
    from the contour it grew to on the view."""
    drawing, start, sigma, factor = options["init"], options["start"], options["sigma"], view.factor
    window = features.evenly_lit(view.window)
    noise = _noise_sigma(window)
    inner = {**options, "image": view.magnified(window), "evenly_lit": True,
             "init": view.inward(drawing),
             "start": None if start is None else view.inward(start),
             "avoid": None if features.avoid is None else view.mask(features.avoid),
             "sigma": None if sigma is None else float(sigma) * factor, "magnify": False, "warn": False,
             "max_area": None if options["max_area"] is None else options["max_area"] * factor ** 2,
             "features": None,
             "image_noise": noise * _magnified_noise_gain(factor), "pixel_noise": noise,
             # (Shared features hold no levels in the image's units: the view reads its own.)
             "raw_model": None if features.levels is None else features.model_in_image_units()}
    run, res, cut = _evolve(**inner), None, None
    try:
        state = next(run)
        while not view.reaches_a_cut(contour := view.outward(state.contour)):
            stop = yield SegmentationProgress(state.step, contour, state.phase)
            state = run.send(stop)
        run.close()
        cut = contour
    except StopIteration as done:
        res = done.value
    except (ValueError, DivergenceError):
        pass  # as it would fail on the image itself, or not: see there
    if cut is not None and _click_sized(drawing):
        # A click grown on the view out to its cut may lie in an object
        # larger than the view: on the image, it is read from what it grew
        # to (read there as it was, a click on a bright speck of a large
        # nucleus is drawn around the speck, and ended on it, converged).
        # The object found so holds what the click grew to: a click on
        # shading grew over it, and what it grew to found a piece of it.
        try:
            grown = yield from _evolve(**{**options, "init": cut, "magnify": False, "warn": False})
            if grown.stop_reason == "cancelled" or (grown.converged and points_in_poly(cut, grown.contour).all()):
                return replace(grown, timings={**grown.timings, "total": time.perf_counter() - t_start})
        except (ValueError, DivergenceError):
            pass
    if res is None or (res.stop_reason != "cancelled" and (view.reaches_a_cut(view.outward(res.contour))
                                                          or _encloses_nothing(view.outward(res.contour)))):
        res = yield from _evolve(**{**options, "magnify": False, "warn": False})
    else:
        res = replace(res, contour=view.outward(res.contour), history=tuple(view.outward(h) for h in res.history))
    # The time the view took counts, whichever run the result is from.
    return replace(res, timings={**res.timings, "total": time.perf_counter() - t_start})


def _encloses_nothing(contour: np.ndarray) -> bool:
    """Whether ``contour`` is thinner than half a pixel on average (twice its
    area over its length): a sliver, not an outline."""
    return _thinner_than(contour, 0.5)


def _before_collapse(features: _FeatureWindow, settled, drawing, steps: int, contrast: str):
    """The nodes (window frame) and stop reason a collapsed contour leaves:
    where the evolution came to rest (``settled``, image frame) if it had;
    else a ValueError saying why (``contrast``: what told the object, see
    segment's)."""
    if settled is not None:
        # The refinement lost an object a few pixels across that the evolution
        # had found (the region force's lines cross it): keep what succeeded.
        nodes = settled - features.origin
        return nodes, _rest_reason(features, nodes)
    # Nothing held it: the region force shrinks a contour drawn on a uniform
    # background until it is a point. Say so rather than return it.
    covered = _avoided_share(drawing, features.avoid)
    if covered >= 0.5:
        # (Told to draw closer, the user would look for the fault in the drawing.)
        raise ValueError(f"the contour collapsed to a point after {steps} steps: avoid covers {covered:.0%} of what "
                         "init encloses, and its pixels are background whatever they look like; leave the object out "
                         "of avoid (the other objects' pixels only)")
    across = float(np.ptp(drawing, axis=0).max())
    raise ValueError(
        f"the contour collapsed to a point after {steps} steps: {_what_was_read(features.model)}; draw it around "
        "the object, closer to its border"
        + (f", or, inside it, larger than this {across:.0f}-px click (a few pixels say too little about "
           "the object's level)" if across < SMALL_DRAWING else "")
        + ("" if contrast == "texture" else "; an object told by its grain rather than its level (a cell in "
           "phase contrast or DIC) may be read by its texture: contrast='texture'")
    )


def _what_was_read(model: RegionModel) -> str:
    """How a collapsed contour's drawing was read, for its error: where the
    drawing lay inside the object, its border may well lie within reach,
    only the pixels about it were not at the object's level (an outside
    tester, session 73: "no object border was found within 40 px", said of
    a polygon inside a cell in DIC 9-13 px from its border)."""
    kind = "bright" if model.polarity > 0 else "dark"
    if model.drawn_around:
        return f"read as drawn around a {kind} object, it found none inside"
    return f"read as drawn inside a {kind} object, it found too few of the object's pixels about it to hold on to"


def _avoided_share(drawing: np.ndarray, avoid: np.ndarray | None) -> float:
    """The share of the pixels ``drawing`` encloses that ``avoid`` holds (0 without it)."""
    if avoid is None:
        return 0.0
    box = bounding_window(drawing, avoid.shape, 0.0)
    inside = window_mask(drawing, box)
    return float(avoid[box][inside].mean()) if inside is not None and inside.any() else 0.0


def _phase_patience(phase: int, patience: int) -> int:
    """Steps the contour must be still in ``phase`` (0 the evolution, 1 the refinement)."""
    return int(patience) if phase == 0 else min(int(patience), REFINEMENT_PATIENCE)


def _first_phase(features: _FeatureWindow, nodes: np.ndarray, carried: bool) -> int:
    """The phase a contour starts in: the evolution (0), or the refinement
    (1) for one carried over from a previous frame (see :func:`_segment_from`)
    that already rests on its object's border as a converged one does
    (ON_BORDER_FRACTION of its nodes): bringing it there is the evolution's
    job. On the Cell Tracking Challenge movie this halved the steps of a
    tracked frame and moved the median centroid error by 0.04 px."""
    if carried and len(features.fields) > 1 and features.on_border(nodes)[0].mean() >= ON_BORDER_FRACTION:
        return 1
    return 0


def _time_step(body: _ElasticBody, field: ForceField, stiffness: float, bounds: np.ndarray, step: int,
               keep=None) -> None:
    """Image forces, one step of the dynamic equilibrium, and a remesh if due
    (keeping, where a pinch parts the contour, the piece that holds ``keep``)."""
    normals = outward_normals(body.nodes)
    forces = stiffness * field(body.nodes, normals)
    try:
        move = body.move_under(forces, normals)
    except (DivergenceError, np.linalg.LinAlgError, RuntimeError, ValueError):
        # Image forces are bounded and the scheme unconditionally stable: a
        # blow-up means the element is ill-conditioned (nodes of two parts of
        # the contour nearly touching). Repair it and go on.
        if body.reference != "incremental":
            raise _divergence(step, stiffness, repaired=False) from None
        _remesh(body, body.nodes, bounds, step, stiffness, keep)
        body._reset_caps()
        return
    new_nodes = np.clip(body.nodes + move, -0.5, bounds)
    moved = float(np.abs(new_nodes - body.nodes).max())
    if not np.isfinite(moved) or moved > body.divergence_limit:
        raise _divergence(step, stiffness, repaired=False)
    if body.reference == "incremental" and body.remesh_watch.due(new_nodes):
        _remesh(body, new_nodes, bounds, step, stiffness, keep)
    else:
        body.nodes = new_nodes
        if body.reference == "incremental":
            body.rest = new_nodes


def _remesh(body, nodes, bounds, step, stiffness, keep=None) -> None:
    try:
        body.remesh(nodes, bounds, keep)
    except (np.linalg.LinAlgError, RuntimeError, ValueError) as err:
        raise _divergence(step, stiffness) from err


def segment(
    image,
    init,
    *,
    material: str | Material = "rubber",
    stiffness: float | None = None,
    n_nodes: int | None = None,
    sigma: float | None = None,
    sigma_factor: float = 1.0,
    forces=FORCE_NAMES,
    weights: dict | None = None,
    polarity: str = "auto",
    contrast: str = "auto",
    damping_ratio: float = 1.0,
    dt: float = 1.0,
    reference: str = "incremental",
    integrator: str = "newmark",
    max_steps: int = 1000,
    max_step_length: float = 2.0,
    tol: float = 0.02,
    patience: int = 5,
    max_line_length: float = 40.0,
    isef_b: float = 0.7,
    refine: bool = True,
    history_every: int = 5,
    features: FrameFeatures | None = None,
    avoid=None,
    magnify: bool = True,
    callback=None,
) -> SegmentationResult:
    """Segment the object around (or inside) ``init`` with a physical contour.

    The initial contour is resampled to evenly spaced nodes and modelled as an
    elastic membrane of the chosen virtual material (Sclaroff's isoparametric
    element). External forces from the image (Shen-Castan edges, intensity and
    chamfer distance to the nearest edge, sampled along adaptive normal lines)
    drive it, by the dynamic equilibrium equation ``M U'' + C U' + K U = F``
    integrated with an unconditionally stable scheme, until it rests on the
    object's border.

    Parameters
    ----------
    image : (H, W) array_like
        Grey-level image of any real dtype. RGB images must be reduced to one
        channel first. NaN pixels hold no data (the margin a registration or
        a drift correction leaves): the contour keeps out of them, as out of
        the image, with a warning.
    init : (N, 2) array_like
        Initial contour, ``(row, col)`` nodes, closed without a repeated node,
        ``N >= 3``; or one point (a click), taken as a circle of
        ``CLICK_RADIUS`` (3) px about it. A node repeated in a row, or the
        first repeated at the end (a ring as ``skimage.measure.find_contours``
        writes it), is taken once. Nodes outside the image are clipped to it
        (with a warning).
    material : str or Material, optional
        Virtual material: a preset of :data:`MATERIALS` (``"rubber"``,
        ``"copper"``, ...) or a :class:`Material`.
    stiffness : float, optional
        The paper's stiffness constant ``r`` (N/m): the image force on a node
        is ``r`` times its dimensionless feature force (at most the sum of the
        weights). Stiffer materials need larger ``r``: by default, the one that
        suits ``material`` (:func:`~.materials.suggested_stiffness`: rubber
        2e3, copper 1e6).
    n_nodes : int, optional
        Nodes of the initial model, 3 to ``MAX_NODES`` (5000; default: one
        every ~3 px, 24 to 1000). The
        spacing is then kept as the contour grows or shrinks, up to 1000 nodes
        (or ``n_nodes`` if more; ``MODAL_MAX_NODES`` with the modal
        integrator), beyond which the spacing and ``sigma`` grow.
    sigma : float, optional
        Gaussian width of the element (px). Default ``sigma_factor`` times the
        node spacing.
    sigma_factor : float, optional
        Node interaction relative to the spacing, typically 0.75-1.5.
    forces : sequence of str, optional
        Image forces to use, from ``("edges", "intensity", "distance")``.
    weights : dict, optional
        Weight of each force (defaults 0.4, 0.3, 0.3).
    polarity : {"auto", "bright", "dark"}, optional
        Whether the object is brighter or darker than its background; "auto"
        reads it from ``init`` (its middle, its line and rings outside it),
        drawn around or inside the object (see :mod:`.region`).
    contrast : {"auto", "intensity", "texture"}, optional
        What tells the object from its background: its level
        ("intensity": fluorescence, stains), or its local variation
        ("texture": flat cells in phase contrast or bright field, whose
        bodies lie at the ground's level; the image's local standard
        deviation, :func:`~.texture.texture_map`, is then segmented, and
        ``polarity`` is that of the texture). "auto" reads it from ``init``
        (:func:`~.texture.told_by_texture`); with a ``polarity`` or
        ``features`` given, it is "intensity".
    damping_ratio : float, optional
        Rayleigh damping ratio at the lowest and highest natural frequencies.
    dt : float, optional
        Time step (s).
    reference : {"incremental", "total"}, optional
        "incremental" (default) takes the current shape as the rest shape after
        every step, so the contour keeps moving while image forces act and can
        change its node count; "total" keeps the initial shape as rest shape
        (elastic forces grow with the distance travelled).
    integrator : {"newmark", "modal"}, optional
        Newmark's trapezoidal rule (sparse: linear in the node count), or mode
        superposition (a dense eigenproblem of twice the node count at every
        remesh: at most ``MODAL_MAX_NODES`` nodes).
    max_steps : int, optional
        Upper bound on time steps.
    max_step_length : float, optional
        No node moves more than this (px) in one step: forces on faster nodes
        are scaled down, so the contour cannot jump over a 1-px edge.
    tol, patience : float, int, optional
        At rest when no node strayed more than ``patience * tol`` px from
        where it was over the last ``patience`` steps (less than ``tol`` px
        per step on average; a node trembling in place does not count).
        A phase followed by another (with ``refine``: the evolution, then
        the refinement, before the polish) stops at ``5 * tol``; the
        refinement, which the polish follows, after at most 2 steps.
    max_line_length : float, optional
        Longest half-length of a normal line (px).
    isef_b : float, optional
        Smoothing of the Shen-Castan filter, in (0, 1).
    refine : bool, optional
        After coming to rest, let the region (intensity) force alone settle
        the nodes for sub-pixel accuracy (edge pixels lie up to half a pixel
        off the true border), then polish them onto the border measured on
        the raw image, averaged along the contour as the image noise requires,
        with the polygon's edges fitted to it
        (:func:`~napari_physeg.core.subpixel.polish`; no node moves more than
        1.5 px). Only with the incremental reference, the intensity force,
        and a contour that came to rest.
    history_every : int, optional
        Keep one contour in ``history`` every this many steps.
    features : FrameFeatures, optional
        The image's feature images, computed once (``FrameFeatures.of(image)``)
        for several objects of one image (tracking); ``isef_b`` is then theirs.
    avoid : (H, W) array of bool, optional
        Pixels of other objects, counted as background whatever they look like:
        the contour does not enter them. A contour that ends around them, more
        of its inside theirs than not, has ``stop_reason="leaked"``.
    magnify : bool, optional
        Segment an object smaller than :data:`~.magnify.SMALL_OBJECT_RADIUS`
        (10 px in radius, as its drawing and the image say) on a view of its
        neighbourhood magnified 2-3 times, where the few-pixel scales the
        image is read on are fractions of it (see :mod:`.magnify`); the
        lengths above in px (``max_line_length``, ``max_step_length``,
        ``tol``, ``sigma``) are then the view's. With ``features``, only for
        a drawing inside its object (the view reads its own features; a
        drawing around the object is read on ``features``).
    callback : callable, optional
        ``callback(step, contour)`` after each step; return ``False`` to stop.

    Returns
    -------
    SegmentationResult

    Raises
    ------
    ValueError
        For bad input: a non-2D image, infinite or only NaN pixels, a constant image, a contour
        with fewer than 3 distinct nodes or wholly outside the image, bad
        parameters; and when the contour collapses to a point because no
        object border lies within reach of it.
    DivergenceError
        If the element stays numerically singular after the contour was
        repaired (pinches, loops and crowded nodes cut, nodes resampled), or
        the integration produced non-finite or exploding displacements.

    Notes
    -----
    The feature images are computed on a window around the contour (its
    bounding box plus ``1.25 (max_line_length + 8)`` px) when that window
    covers at most half the image, and on a larger window whenever the
    normal lines the contour's nodes cast (at most ``max_line_length`` px)
    and 8 px reach its border; so a small object in a large image costs about
    what it would cost in a small one.
    The drawing is read once, on its bounding box plus
    ``2 (max_line_length + 8)`` px (or the whole image, likewise).

    Examples
    --------
    >>> from napari_physeg import data
    >>> obj = data.ellipse()
    >>> res = segment(obj.image, obj.init_near)
    >>> res.converged
    True
    """
    options = {name: value for name, value in locals().items() if name not in ("image", "init", "callback")}
    check_callback(callback)
    on_progress = None if callback is None else (lambda state: callback(state.step, state.contour))
    return drain(_evolve_read(image, init, **options), on_progress)


def _segment_from(image, drawing, start, max_area: float | None = None, **options) -> SegmentationResult:
    """:func:`segment` with the object's levels read from ``drawing`` (around
    it: a margin away from ``start``, not a user's drawing, so never read as
    traced on the border, see :func:`~.region.traced_border_level`, nor as
    centred on what it means) and the contour starting from
    ``start``, a contour already near the border: in a time-lapse, the
    previous frame's result where the motion predicts it. Started from the
    drawing, it would first have to travel back the drawing's margin. (Read
    as traced, a margin of 3 px around a blurred nucleus lay on its edge's
    ramp: the contour grew to it, and the tracker lost the nucleus.)
    ``max_area``: see :func:`_evolve`. With ``contrast="texture"``, ``image``
    and ``features`` are already the texture's (see :func:`_evolve_read`)."""
    arguments = _segment_arguments(image, drawing, options)
    arguments["contrast"] = "intensity" if arguments["contrast"] == "auto" else arguments["contrast"]
    return drain(_evolve(**arguments, start=start, max_area=max_area))

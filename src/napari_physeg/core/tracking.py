"""Following objects through a time-lapse (the paper's future work).

:func:`track` segments every object of a movie frame by frame, each frame
starting from the previous result moved by the motion predicted from the
frames before (or by the shift that the objects' looks, or the objects
found first on the frame, show together: a jittering stage), with the
object's levels read
from that contour grown by a margin, a drawing around it, so the physical
contour needs only a few steps, and none of the evolution's when it starts
on the object's border.
A contour that comes to rest against its drawing's limit is drawn around
again (the object moved further than predicted); one that ends with no
pixel where its object was predicted found another object: the object is
lost, and looked for again from its last contour on the next MAX_GAP frames
(a blank or defocused frame). The feature images of a frame are computed
once and shared by all its objects, and each object counts the others'
pixels as background: objects repel each other and never overlap. An
object not found where one segmented before it took pixels has the two
segmented again in the other order (see _give_back).

Once the contours are known, consecutive contours of an object are matched
node to node by the order-preserving modal matching of :func:`.match`, as
QuimP's ECMM maps each membrane point onto the next outline. That gives each
node its origin on the previous contour, its normal displacement
(protrusion > 0, retraction < 0) and an arc position whose origin is carried
from frame to frame by the correspondences; with the curvature these make
the membrane maps (arc position x time) of QuimP's Q-Analysis and of
MorphoDynamics (:meth:`TrackingResult.membrane_map`).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from functools import partial

import cv2
import numpy as np
from scipy import ndimage as ndi
from scipy.spatial import cKDTree
from skimage import registration
from skimage.filters import threshold_otsu
from skimage.segmentation import watershed

from ._drain import drain
from ._validation import check_callback, check_count, check_drawing, signature_of
from .contour import (area_centroid, as_contour, as_drawing, bounding_window, closest_on_polyline, depth_inside,
                      nearest_node, outward_normals, perimeter, positively_oriented, remove_loops, resample,
                      rotation_matrix, signed_area, through_nodes, window_mask)
from .background import plane_removed
from .dynamics import DivergenceError
from .features import _masked_as_missing, _without_missing
from .matching import _match_arguments, _match_pairs, _prepare, match
from .region import _fill, hasty_margin
from .segmentation import FrameFeatures, _segment_from, check_on_image, check_segment_options, segment
from .texture import texture_map, told_by_texture

__all__ = ["track", "iter_track", "TrackingResult", "TrackingProgress", "TRACKED", "LOST", "LEFT"]

TRACKED = "tracked"
LOST = "lost"
LEFT = "left the field of view"

#: A frame's contour whose area changed by more than this factor from the
#: previous frame's is not the same object: the object is lost. But one far
#: smaller that keeps at least 1 / MAX_AREA_CHANGE of the object's signal
#: (its contrast times its area; a fluorophore does not vanish in a frame)
#: is the object condensed: a nucleus entering mitosis gathers its chromatin
#: into a bright body of half its area or less (the real HeLa movie's, at 0.45
#: of their area, kept three quarters of their signal, and were lost), where a
#: contour left on a part of the object, or on a speck where it vanished,
#: keeps only its share of the signal.
MAX_AREA_CHANGE = 2.0

#: One far larger, up to MAX_AREA_CHANGE squared, is the object spread out
#: when it holds about the object's signal: at least 1 / MAX_AREA_CHANGE of
#: it and at most SPREAD_SIGNAL times it. A daughter nucleus decondenses its
#: chromatin over twice its area within a few frames (the real HeLa movie
#: read every 2nd frame: 2.05-2.13 times the area, at 1.08-1.17 times the
#: signal, and lost), where a contour that took in a neighbour as bright
#: holds twice the signal, and one that spread over the ground next to none.
SPREAD_SIGNAL = 1.5

#: A tracked object has divided when its contour shrank to at most
#: DIVIDED_AREA of its area on the frame before, and a body of its looks that
#: no object holds, apart from the contour (not within a pixel of it), lies
#: beside it: a sister of at least SISTER_AREA and at most 1 / SISTER_AREA
#: times its area, the two centred together where the object was, within
#: SISTER_CENTRING of its radius and nearer than the contour alone (a
#: division keeps the mother's matter about where she was, each daughter
#: off to one side; a neighbour beside an object that stayed moves their
#: centre away). Daughters that first appear apart were followed one of them, at
#: half the area, as a nucleus condensing for mitosis (see MAX_AREA_CHANGE),
#: with no word: 21 of the 25 divisions of a Cell Tracking Challenge
#: simulation (an outside tester, session 68). A condensing nucleus has no
#: sister beside it.
DIVIDED_AREA = 0.7
SISTER_AREA = 0.3
SISTER_CENTRING = 0.5

#: Consecutive contours share a frame of reference: the matching cost keeps
#: each node near where it was (see match's ``displacement_weight``).
DISPLACEMENT_WEIGHT = 1.0

#: A tracked frame's contour that rests against the limit its drawing sets
#: (see _against_the_limit) belongs to an object that moved further than
#: predicted: it is segmented again from a drawing around it, up to
#: MAX_REDRAWS times (each reaches up to 16 px further). On the Cell
#: Tracking Challenge movie with every 3rd frame, one redraw followed 11 of
#: the 13 nuclei, three all of them, five no more.
MAX_REDRAWS = 3

#: ... when at least this share of its nodes lie there (a run of nodes: on
#: the faster movies, a share of 0.05 to 0.2 followed the same nuclei).
AT_LIMIT_SHARE = 0.1

#: A contour against the limit of a drawing moved with the object grew
#: there (see _grew_beyond) when, at GREW_SHARE of its nodes there, the
#: image beyond lies GREW_HEIGHT of the object's contrast beyond the
#: midpoint of its levels, and short of it on the frame the drawing was
#: drawn on.
GREW_SHARE = 0.25
GREW_HEIGHT = 0.25

#: An object whose contrast (see _contrast) falls below this fraction of
#: its best within FADE_WINDOW frames has faded: it is lost. Tracked through
#: the confocal nuclei stack of the real-image benchmark as through time,
#: the contours beyond the labels' ends in z (the nuclei's out-of-focus
#: glow) had 0.05-0.27 of their start slice's contrast, 133 of 141 below 0.2;
#: those within them 0.18 or more, 10 of 555 below 0.2 (the nuclei's caps).
#: On the Cell Tracking Challenge movie no track fell below 0.65.
FADED_CONTRAST = 0.2

#: ... within this many frames: an object that leaves the focal plane fades
#: within a few frames, while photobleaching dims a whole movie slowly (the
#: Cell Tracking Challenge movie bleached to 0.15 of its contrast over its 30
#: frames lost 8 of its 13 tracks against the start frame's contrast, none
#: against the best of the last 10 frames; through z, windows of 8-15 slices
#: lost the glow as the start slice did, 5 slices followed it on 60-70 slices).
FADE_WINDOW = 10

#: An object cut by the image's side with less than this fraction of its
#: area when last seen whole has left the field of view.
LEFT_FRACTION = 0.3

#: An object lost (or seen leaving the field of view) on a frame is looked
#: for again, from its last contour, on up to this many frames after (a
#: blank, dropped or defocused frame): one blank frame of the Cell Tracking
#: Challenge movie lost 10 of its 13 tracks for good.
MAX_GAP = 2

#: An object not found on a frame where another, done before it, took at
#: least this share of its area within the drawing it was looked for in
#: has the two segmented again in the other order (see _give_back).
SUSPECT_SHARE = 0.05

#: How far, in the median radius of the objects, the frame's common shift
#: (a jittering stage) is looked for by their appearance (see _stage_shift).
STAGE_SEARCH = 2.0

#: The normalised correlation at which an object's patch on the frame
#: before counts as found again on this one (see _stage_shift).
STAGE_MATCH = 0.5

#: How far, in its radius (4 to 30 px), an object is looked for by its
#: appearance on the next frame, and how well its patch must match there
#: (normalised correlation), for its own motion (see _look_shift).
LOOK_SEARCH = 1.0
LOOK_MATCH = 0.7

#: What an object not found on a frame weighs against one found there, in
#: _give_back's comparison: as much as a contour one radius off its
#: predicted place (see _misfit).
LOST_MISFIT = 1.0

#: A tracked frame's drawing is the last frame's, moved with the object (see
#: _carried), while its nodes all lie at least CARRIED_NEAREST times the
#: margin (see _margin) away from the start, and half of them within
#: CARRIED_MEDIAN times it: a drawing as close as a new one could be, and
#: not much looser. (At 0.75 and 1.5 it was drawn anew so often that the
#: identical frames of the Data Science Bowl movie crept as before.)
CARRIED_NEAREST = 0.5
CARRIED_MEDIAN = 2.0


@dataclass(frozen=True)
class TrackingProgress:
    """What :func:`iter_track` yields for each object of each frame, once
    every object of that frame is done: its contour and status are then
    those of the result.

    Attributes
    ----------
    frame, object : int
        The frame and the object.
    contour : ndarray or None
        Its contour there (None when lost or gone).
    status : str
        :data:`TRACKED`, :data:`LOST` or :data:`LEFT`.
    done, total : int
        Object-frames done and to do.
    """

    frame: int
    object: int
    contour: np.ndarray | None
    status: str
    done: int
    total: int


@dataclass(frozen=True, eq=False)
class TrackingResult:
    """What :func:`track` returns. Lists are indexed ``[object][frame]``.

    Attributes
    ----------
    contours : list of list of (N, 2) ndarray or None
        Object ``k``'s contour at frame ``t`` (positively oriented), None
        where it is lost or gone (never a garbage contour).
    status : list of list of str
        :data:`TRACKED`, :data:`LOST` or :data:`LEFT` (``"left the field of
        view"``); ``"not processed"`` for the frames a cancelled run or a
        frame that could not be used left undone (see ``stop_reason``).
    origin : list of list of (N, 2) ndarray or None
        Where each node of frame ``t`` came from on frame ``t - 1``'s contour
        (NaN at the first frame and after a gap).
    normal_velocity : list of list of (N,) ndarray or None
        Each node's displacement from its origin along its outward normal,
        px/frame (protrusion > 0, retraction < 0; NaN where ``origin`` is).
    curvature : list of list of (N,) ndarray or None
        Signed curvature at each node (1/px; > 0 where the contour is convex).
    arc : list of list of (N,) ndarray or None
        Arc position of each node in [0, 1), from an origin carried from
        frame to frame by the correspondences, along the contour's direction.
    start : int
        The frame the initial contours were drawn on.
    stop_reason : str
        ``"completed"``, ``"cancelled"``, or ``"frame error"``: a frame after
        the start one could not be read or held infinite pixels; the tracking
        stopped there in that direction (the other went on), the frames done
        are kept, and ``warnings`` says which frame and why.
    timings : dict
        Seconds spent on ``"segmentation"``, ``"correspondence"`` and ``"total"``.
    warnings : tuple of str
        What the run also warned of (an object not found on the start frame,
        and why), for callers that show warnings their own way (the widget).
    reason : list of list of str
        Why object ``k`` is lost on frame ``t`` (it faded, what was found
        there is another object, its contour did not come to rest, its
        track ended at a division, ...); ``""`` where it is not lost.
    contrast : list of str
        What told object ``k`` from its background, read on the start frame
        and kept: ``"intensity"`` or ``"texture"`` (see segment's ``contrast``).
    """

    contours: list
    status: list
    origin: list
    normal_velocity: list
    curvature: list
    arc: list
    start: int
    stop_reason: str
    timings: dict = field(default_factory=dict)
    warnings: tuple = ()
    reason: list = field(default_factory=list)
    contrast: list = field(default_factory=list)

    @property
    def n_objects(self) -> int:
        return len(self.contours)

    @property
    def n_frames(self) -> int:
        return len(self.contours[0]) if self.contours else 0

    def _object(self, k) -> int:
        """``k`` as the index of one of the objects, or an IndexError saying how many there are."""
        is_index = isinstance(k, (int, np.integer)) and not isinstance(k, (bool, np.bool_))
        if not (is_index and -self.n_objects <= k < self.n_objects):
            raise IndexError(f"object {k!r} is not one of the {self.n_objects} tracked (0 to {self.n_objects - 1})")
        return int(k)

    def first_lost(self, k: int) -> tuple[int, str] | None:
        """The frame object ``k`` is first lost on, counting from the start
        frame (either way), and why (see ``reason``); None if it never is."""
        k = self._object(k)
        return _first_lost(self.reason[k], self.start) if self.reason else None

    def centroids(self, k: int) -> np.ndarray:
        """``(T, 2)`` area centroids of object ``k`` (NaN where it has no contour)."""
        return np.array([area_centroid(c) if c is not None else (np.nan, np.nan)
                         for c in self.contours[self._object(k)]])

    def membrane_map(self, k: int, quantity: str = "normal_velocity", n_arc: int = 100) -> np.ndarray:
        """Object ``k``'s ``quantity`` as an image, arc position x time.

        Parameters
        ----------
        k : int
            The object.
        quantity : {"normal_velocity", "curvature"}
        n_arc : int
            Columns: arc positions ``0, 1/n_arc, ...`` from the carried origin.

        Returns
        -------
        ndarray, shape (T, n_arc)
            Rows are frames (NaN where the object has no value), as QuimP's
            motility and convexity maps and MorphoDynamics' maps.
        """
        k = self._object(k)
        values = {"normal_velocity": self.normal_velocity, "curvature": self.curvature}
        if quantity not in values:
            raise ValueError(f"quantity must be 'normal_velocity' or 'curvature', got {quantity!r}")
        n_arc = check_count(n_arc, "n_arc", 1)
        grid = np.arange(n_arc) / n_arc
        out = np.full((self.n_frames, n_arc), np.nan)
        for t, (v, s) in enumerate(zip(values[quantity][k], self.arc[k])):
            if v is not None and np.isfinite(v).any():
                order = np.argsort(s)
                ok = np.isfinite(v[order])
                out[t] = np.interp(grid, s[order][ok], v[order][ok], period=1.0)
        return out

    def table(self):
        """A tidy pandas DataFrame, one row per node per frame per object.

        Columns: object, frame, node, row, col, arc, normal_velocity,
        curvature, status, reason. Frames where an object is lost or gone
        have one row with NaN coordinates, its status and why it is lost
        (``reason``). Needs pandas (napari brings it).
        """
        import pandas as pd

        parts = []
        for k in range(self.n_objects):
            for t in range(self.n_frames):
                c = self.contours[k][t]
                why = self.reason[k][t] if self.reason else ""
                if c is None:
                    parts.append(pd.DataFrame(dict(object=[k], frame=[t], node=[-1], row=[np.nan], col=[np.nan],
                                                   arc=[np.nan], normal_velocity=[np.nan], curvature=[np.nan],
                                                   status=[self.status[k][t]], reason=[why])))
                    continue
                n = len(c)
                parts.append(pd.DataFrame(dict(
                    object=np.full(n, k), frame=np.full(n, t), node=np.arange(n), row=c[:, 0], col=c[:, 1],
                    arc=self.arc[k][t], normal_velocity=self.normal_velocity[k][t],
                    curvature=self.curvature[k][t], status=[self.status[k][t]] * n, reason=[why] * n)))
        return pd.concat(parts, ignore_index=True)


def _check_frames(frames):
    shape = getattr(frames, "shape", None)
    if shape is None and not isinstance(frames, (list, tuple)):
        raise ValueError(f"frames must be a (T, H, W) movie (a numpy, dask or zarr array, or a list of 2D frames), "
                         f"got {type(frames).__name__}")
    if shape is None:  # a list of frames
        shapes = [np.shape(frame) for frame in frames]
        if len(set(shapes)) > 1:
            other = next(t for t, s in enumerate(shapes) if s != shapes[0])
            raise ValueError(f"frame {other} has shape {shapes[other]} and frame 0 {shapes[0]}: a movie's frames "
                             "must share one shape (crop or pad them to one)")
        masked = any(np.ma.isMaskedArray(frame) for frame in frames)
        frames = np.ma.stack(frames) if masked else np.asarray(frames)  # (np.asarray drops masks)
        shape = frames.shape
    if len(shape) != 3:
        raise ValueError(f"frames must be a (T, H, W) stack of 2D frames, got shape {tuple(shape)}; "
                         f"{_frames_advice(tuple(shape))}")
    dtype = np.dtype(getattr(frames, "dtype", np.float64))
    if dtype.kind == "c":
        raise ValueError(f"frames have complex dtype {dtype}: pass real frames, e.g. np.abs(frames) or frames.real")
    if dtype.kind not in "biuf":
        raise ValueError(f"frames must have a real numeric dtype, got {dtype}")
    if shape[0] < 1 or min(shape[1:]) < 3:
        raise ValueError(f"frames of shape {tuple(shape)} hold no image to track in")
    return frames, int(shape[0]), tuple(int(s) for s in shape[1:])


def _frames_advice(shape: tuple) -> str:
    """What to pass instead of frames of ``shape`` (not 3D)."""
    if len(shape) == 2:
        return "for one image use segment()"
    if len(shape) == 4 and shape[-1] in (3, 4):
        return "for colour frames pass one channel, e.g. frames[..., 0], or grey frames"
    if len(shape) == 4:  # (T, C, H, W) or (T, Z, H, W), as TIFF stacks come
        return "pass one channel or z plane of each frame, e.g. frames[:, 0], or a projection, frames.max(axis=1)"
    return "pass one (T, H, W) movie at a time"


def _check_inits(inits, frame_shape):
    if not isinstance(inits, (np.ndarray, list, tuple)):
        raise ValueError(f"inits must be one (N, 2) contour or a list of them, got {type(inits).__name__}")
    if _one_contour(inits):
        inits = [inits]
    # As segment() checks its drawing (its error, before any frame is read,
    # rather than the object reported lost on the start frame).
    out = [check_drawing(as_drawing(c, name=f"inits[{k}]"), f"inits[{k}]") for k, c in enumerate(inits)]
    if not out:
        raise ValueError("inits is empty: give one (N, 2) contour per object to track")
    for k, c in enumerate(out):
        check_on_image(c, frame_shape, f"inits[{k}]")
    return out


def _one_contour(inits) -> bool:
    """Whether ``inits`` is a single (N, 2) contour (an array or nested
    lists of numbers), rather than a sequence of contours."""
    try:
        return np.asarray(inits, dtype=float).ndim == 2
    except (TypeError, ValueError):  # ragged: contours of different node counts
        return False


def _grown(contour: np.ndarray, by: float) -> np.ndarray:
    """``contour`` offset outward by ``by`` px (loops that the offset makes in
    concave bends cut): a drawing around the object, as a user's."""
    nodes = resample(contour, spacing=1.5)
    return remove_loops(nodes + by * outward_normals(nodes))


def _predicted(history: list[np.ndarray]) -> np.ndarray:
    """Where the object's motion predicts it on the next frame: its last
    contour moved by its centroid's last displacement (the segmentation's
    start there; the drawing around it, see _drawing_around, reads the
    background)."""
    prev = history[-1]
    shift = area_centroid(prev) - area_centroid(history[-2]) if len(history) > 1 else 0.0
    return prev + shift


def _radius(contour: np.ndarray) -> float:
    """The radius of the disk with ``contour``'s area."""
    return float(np.sqrt(abs(signed_area(contour)) / np.pi))


def _margin(contour: np.ndarray) -> float:
    """How far outside an object's outline ``contour`` a drawing around it lies:
    a fifth of its radius, 3 to 8 px."""
    return float(np.clip(0.2 * _radius(contour), 3.0, 8.0))


def _drawing_around(contour: np.ndarray) -> np.ndarray:
    """A drawing around the object whose outline is about ``contour``: that
    grown by its margin (see _margin), so its line reads the background."""
    return _grown(contour, _margin(contour))


@dataclass(frozen=True)
class _Drawing:
    """A tracked object's drawing: its ``line``, and what the frame it was
    drawn on looked like about it (its intensity on ``patch``, whose first
    pixel was at ``corner``), before the line moved by ``offset`` with the
    object (see _carried)."""

    line: np.ndarray
    patch: np.ndarray
    corner: np.ndarray
    offset: np.ndarray

    @classmethod
    def on(cls, line: np.ndarray, intensity: np.ndarray) -> _Drawing:
        """``line`` drawn on a frame of ``intensity`` (see FrameFeatures):
        its patch reaches past the limit the line sets (see _grew_beyond)."""
        rows, cols = bounding_window(line, intensity.shape, hasty_margin(abs(signed_area(line))) + 4.0)
        # A copy: a view would keep the whole frame alive while the drawing is carried.
        return cls(line, intensity[rows, cols].copy(), np.array([rows.start, cols.start]), np.zeros(2))

    def moved(self, shift: np.ndarray) -> _Drawing:
        """The drawing moved by ``shift`` with its object (its patch stays where it was drawn)."""
        return replace(self, line=self.line + shift, offset=self.offset + shift)

    def looked(self, points: np.ndarray) -> np.ndarray:
        """The intensity of the frame it was drawn on where ``points`` (on
        this frame) were before it moved (NaN outside its patch)."""
        at = np.rint(points - self.offset - self.corner).astype(int)
        inside = np.all((at >= 0) & (at < self.patch.shape), axis=1)
        out = np.full(len(points), np.nan)
        out[inside] = self.patch[at[inside, 0], at[inside, 1]]
        return out


def _at_the_limit(contour: np.ndarray, drawing: np.ndarray) -> np.ndarray:
    """Which nodes of ``contour`` rest against the limit that ``drawing``
    sets to its object (the drawing grown by region.hasty_margin px)."""
    margin = hasty_margin(abs(signed_area(drawing)))
    # Within a pixel and a half of it: the limit is a raster's dilation, and
    # the polish moves the nodes by up to a pixel.
    return -depth_inside(drawing, contour) >= margin - 1.5


def _against_the_limit(contour: np.ndarray, drawing: np.ndarray) -> bool:
    """Whether ``contour`` rests against its ``drawing``'s limit (see
    _at_the_limit) along at least AT_LIMIT_SHARE of its nodes, rather than
    on the object's border."""
    return bool(np.mean(_at_the_limit(contour, drawing)) >= AT_LIMIT_SHARE)


def _redrawn(segment_here, drawing: _Drawing, predicted: np.ndarray, intensity: np.ndarray, by_looks: bool = False):
    """``segment_here(drawing.line, predicted)``, drawn around again (up to
    MAX_REDRAWS times, on the frame of ``intensity``) while the contour
    rests against its drawing's limit: a tracked frame's drawing is a guess,
    and an object that moved further than predicted reaches beyond it. For
    a drawing moved ``by_looks`` (see _carried), only where the object grew
    (see _grew_beyond). The result and the last drawing."""
    res = segment_here(drawing.line, predicted)
    for _ in range(MAX_REDRAWS):
        if not (res.converged and _against_the_limit(res.contour, drawing.line)):
            break
        if by_looks and not _grew_beyond(res.contour, drawing, intensity):
            break
        drawing = _Drawing.on(_drawing_around(res.contour), intensity)
        res = segment_here(drawing.line, res.contour)
    return res, drawing


def _grew_beyond(contour: np.ndarray, drawing: _Drawing, intensity: np.ndarray) -> bool:
    """Whether, where ``contour`` rests against its ``drawing``'s limit, the
    object grew: at GREW_SHARE of its nodes there, the image 2 px beyond
    lies GREW_HEIGHT of the object's contrast beyond the midpoint of its
    levels (inside the contour, on the drawing's line), where the frame the
    drawing was drawn on lay short of it. There it was the background when
    the drawing was drawn around the object; a neighbour the contour
    pressed into was already there (a kidney-shaped nucleus of the Cell
    Tracking Challenge movie turned a lobe out over frames, a pixel a frame;
    on identical frames, nothing grows). ``intensity``: this frame's (see
    FrameFeatures)."""
    at_limit = _at_the_limit(contour, drawing.line)
    if not at_limit.any():
        return False
    beyond = contour[at_limit] + 2.0 * outward_normals(contour)[at_limit]
    box = bounding_window(contour, intensity.shape, 1.0)
    inside = np.argwhere(window_mask(contour, box)) + np.array([box[0].start, box[1].start])
    on_line = resample(drawing.line, spacing=1.0)
    now = _height(*(_sampled(intensity, points) for points in (beyond, inside, on_line)))
    then = _height(*(drawing.looked(points) for points in (beyond, inside, on_line)))
    return bool(np.mean((now > GREW_HEIGHT) & ~(then >= 0)) >= GREW_SHARE)


def _height(values: np.ndarray, inside: np.ndarray, line: np.ndarray) -> np.ndarray:
    """``values`` from the midpoint of the levels ``inside`` and on the
    ``line`` (their medians, NaN ignored), in their contrast: > 0 on the
    inside's side; NaN where unknown."""
    inside, line = inside[np.isfinite(inside)], line[np.isfinite(line)]
    if not (inside.size and line.size) or np.median(inside) == np.median(line):
        return np.full(len(values), np.nan)
    a, b = np.median(inside), np.median(line)
    return (values - 0.5 * (a + b)) / (a - b)


def _sampled(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``image`` at the pixels nearest ``points`` (clipped to it)."""
    rows, cols = (np.clip(np.rint(points[:, i]).astype(int), 0, image.shape[i] - 1) for i in range(2))
    return image[rows, cols]


def _carried(drawing: _Drawing | None, last: np.ndarray, start: np.ndarray, intensity: np.ndarray,
             by_looks: bool = False) -> _Drawing:
    """The drawing to segment from ``start`` in: ``drawing``, that of the
    frame where the object was last seen (as ``last``; the user's on the
    start frame), moved as ``start`` moved from ``last``: always when
    ``start`` is where the object's looks moved it (``by_looks``, see
    _look_shift), else while it still lies around ``start`` as a new one
    would (all of ``start`` at least CARRIED_NEAREST of _drawing_around's
    margin inside it, and half of it within CARRIED_MEDIAN margins); else a
    new one around ``start`` (drawn on the frame of ``intensity``).

    The drawing's line reads the object's background, and its limit keeps
    the contour off what lies beyond, where the object's border is unclear.
    Drawn anew around each frame's contour, on a blurred edge it lay on the
    ramp at a distance the contour itself set: a contour a little inside
    the border read a brighter background, whose mid-level lay further
    inside, frame after frame, and on identical frames the contours crept;
    and against a neighbour in broad contact, whose band the contour took up
    to its limit, a drawing around that contour let it take the next band.
    Moved with the object's looks, the drawing stays what it was to the
    object: on the twenty identical frames of the Data Science Bowl nuclei
    of benchmarks/tracking_warped.py, 7 of 51 contours came below an IoU of
    0.9 with their first (12 with the drawing drawn anew where it no longer
    lay around the contour, 16 of 51 on ten frames drawn anew each frame),
    and over its seven movies identity-switched object-frames went from 162
    to 59 and visible nuclei with no contour from 162 to 64.
    """
    if drawing is None:
        return _Drawing.on(_drawing_around(start), intensity)
    moved = drawing.moved(area_centroid(start) - area_centroid(last))
    margin = _margin(start)
    inside = depth_inside(moved.line, start)
    # Moved by the object's looks, a drawing the contour came close to along
    # a run of nodes is kept (a neighbour it pressed into); one it came
    # close to all round is not (the object grew).
    nearest = np.median(inside) if by_looks else inside.min()
    if nearest >= CARRIED_NEAREST * margin and np.median(inside) <= CARRIED_MEDIAN * margin:
        return moved
    return _Drawing.on(_drawing_around(start), intensity)


def _paint(run: _Run, owner: np.ndarray, contour: np.ndarray | None, value: int, only_free: bool = False) -> None:
    """Set the pixels of ``owner`` inside ``contour`` (if any) to ``value``
    (``only_free``: those no object owns, -1), and grow the box of object
    ``value``'s pixels on the current frame (``run.painted``) to hold them."""
    if contour is None:
        return
    box = bounding_window(contour, owner.shape, 0.0)
    inside = window_mask(contour, box)
    if inside is None:
        return
    if only_free:
        inside &= owner[box] < 0
    owner[box][inside] = value
    if value in run.painted:
        held = run.painted[value]
        box = (slice(min(box[0].start, held[0].start), max(box[0].stop, held[0].stop)),
               slice(min(box[1].start, held[1].start), max(box[1].stop, held[1].stop)))
    run.painted[value] = box


def _unpainted(run: _Run, owner: np.ndarray, k: int) -> None:
    """Give the pixels of ``owner`` that object ``k`` owns back to no object
    (-1). Only ``_paint`` gives an object pixels: they lie in its box (a
    frame holds many small objects, and this ran over the whole frame)."""
    if k in run.painted:
        held = owner[run.painted[k]]
        held[held == k] = -1


def _others(run: _Run, owner: np.ndarray, k: int) -> np.ndarray:
    """The pixels of ``owner`` that objects other than ``k`` own."""
    others = owner >= 0
    if k in run.painted:
        box = run.painted[k]
        others[box] &= owner[box] != k
    return others


#: The pixels next to a node (and its own), where _touches_side looks for missing data.
_NEXT_TO = np.array([(dr, dc) for dr in (-1, 0, 1) for dc in (-1, 0, 1)])


#: A node within this many px of the image's side lies on it: a contour that
#: rests on the side is polished to a few hundredths of a pixel inside it (a
#: nucleus coming in, a sliver 2 px wide 0.08 px from the side, was taken as
#: seen whole, and lost when it showed more of itself the next frame). Half a
#: pixel took nuclei that rest beside the side for cut by it: 3 more lost and
#: 2 fewer followed over the warped Data Science Bowl movies.
ON_SIDE = 0.1


def _touches_side(contour: np.ndarray, shape, missing: np.ndarray | None = None) -> bool:
    """Whether a node of ``contour`` lies on (or beyond) the image's side, or
    next to its ``missing`` pixels (no data: the view ends there too)."""
    if np.any((contour <= ON_SIDE) | (contour >= np.array(shape) - 1.0 - ON_SIDE)):
        return True
    if missing is None or missing.all():  # (a frame of no data at all is a gap, not a side: see _measured)
        return False
    near = np.clip(np.rint(contour).astype(int)[:, None, :] + _NEXT_TO, 0, np.array(shape) - 1)
    return bool(missing[near[..., 0], near[..., 1]].any())


def _judge(contour, previous, predicted, whole_area, shape, missing=None, seen_whole: bool = False,
           condensed: bool = False, spread: bool = False) -> tuple[str, str]:
    """Is ``contour`` the object seen on ``previous`` (and ``predicted`` on
    this frame), or has it gone? Its status, and why where it is not
    tracked. (``missing``: the frame's pixels that hold no data, see
    _touches_side; ``seen_whole``: whether ``whole_area`` is that of a
    contour the image's side did not cut; ``condensed``, ``spread``: whether
    it keeps the object's signal, see MAX_AREA_CHANGE and SPREAD_SIGNAL.)"""
    area, prev_area = abs(signed_area(contour)), abs(signed_area(previous))
    at_side, was_at_side = _touches_side(contour, shape, missing), _touches_side(previous, shape, missing)
    if at_side and area < LEFT_FRACTION * whole_area:
        return LEFT, ""
    # The image's side hides part of an object it cuts: one that moves in
    # shows more of itself (a sliver may become the whole), one that moves
    # out less; neither is a sign of another object. But an object seen
    # whole shows at most that whole (a crowd nucleus of 152 px cut by the
    # side took in a neighbour coming into view, 353 px, reported tracked).
    least = 0.0 if at_side or condensed else prev_area / MAX_AREA_CHANGE
    if not was_at_side:
        most = (MAX_AREA_CHANGE ** 2 if spread else MAX_AREA_CHANGE) * prev_area
    else:
        most = MAX_AREA_CHANGE * max(whole_area, prev_area) if seen_whole else np.inf
    if not least <= area <= most:
        change = area / prev_area if area > prev_area else prev_area / max(area, 1e-12)
        # (Not "another object" flatly: an outside tester's spreading cell and a
        # nucleus rounding up for mitosis were the same object, session 70.)
        return LOST, (f"what was found there is {change:.1f} times {'larger' if area > prev_area else 'smaller'} "
                      f"than the object on the frame before, beyond the {MAX_AREA_CHANGE:g}-fold change tracking "
                      "takes for one object: read as another object or a part of it (an object that spreads or "
                      "rounds up that fast is lost so too)")
    # A contour that holds no pixel of where the object was predicted has
    # found another object (a vanished one's contour is drawn to the next
    # edges within reach), not this one moved.
    if not _overlap(contour, predicted, shape):
        return LOST, "what was found lies wholly off where the object was expected: another object"
    return TRACKED, ""


def _overlap(a: np.ndarray, b: np.ndarray, shape) -> bool:
    """Whether the regions of contours ``a`` and ``b`` share a pixel of an image of ``shape``."""
    return _shared_area(a, b, shape) > 0


def _shared_area(a: np.ndarray, b: np.ndarray, shape) -> int:
    """The pixels of an image of ``shape`` inside both contours ``a`` and ``b``.

    Only where their bounding boxes overlap is rasterised (none, for the
    most): the start frame weighs every pair of drawings, and a window around
    both of two far objects made 400 objects take ten times as long."""
    box = tuple(slice(max(p.start, q.start), min(p.stop, q.stop))
                for p, q in zip(bounding_window(a, shape, 0.0), bounding_window(b, shape, 0.0)))
    in_a, in_b = window_mask(a, box), window_mask(b, box)
    return 0 if in_a is None else int((in_a & in_b).sum())


#: segment()'s own step budget (see _on_the_start_frame).
_SEGMENT_MAX_STEPS = signature_of(segment).parameters["max_steps"].default


def iter_track(frames, inits, *, start: int = 0, max_steps: int = 300, segment_options: dict | None = None,
               match_options: dict | None = None):
    """:func:`track` as a generator: one :class:`TrackingProgress` per object and frame.

    Takes the parameters of :func:`track` (but ``callback``) and returns (as
    ``StopIteration.value``) its :class:`TrackingResult`. Send ``True`` to stop:
    the frames done are kept and the result says ``stop_reason="cancelled"``.
    """
    t_start = time.perf_counter()
    frames, n_frames, frame_shape = _check_frames(frames)
    inits = _check_inits(inits, frame_shape)
    start = _checked_start(start, n_frames)
    options = _checked_segment_options(segment_options, max_steps)
    match_options = _checked_match_options(match_options)
    polarity = options.pop("polarity", "auto")  # then each object's, from its first frame
    contrast = options.pop("contrast", "auto")  # likewise (see _read_by)
    n_obj = len(inits)
    run = _Run(inits=inits, start=start, options=options,
               contours=[[None] * n_frames for _ in range(n_obj)], status=[[None] * n_frames for _ in range(n_obj)],
               seen=[_Seen(polarity, abs(signed_area(c))) for c in inits])
    total, done, stop_reason, said = n_obj * n_frames, 0, "completed", []
    brightness, dimmed = {}, []  # frame -> its brightness (see _brightness); see _faded_as_the_frame_dimmed
    together = []  # see _lost_together
    with_missing, empty = [], []  # the frames with NaN pixels, and those with nothing else
    # Forward from the start frame, then backward from it.
    start_looks = None
    for frame_order in (range(start, n_frames), range(start - 1, -1, -1)):
        step = 1 if frame_order.step > 0 else -1
        before = start_looks
        for t in frame_order:
            try:
                image = _frame(frames, t)
            except ValueError as err:
                if t == start:  # nothing done yet: bad input
                    raise
                # Keep what succeeded: the frames done in this direction (minutes of work) stay.
                said.append(f"{err}: tracking {'forward' if step > 0 else 'backward'} stopped there, the frames "
                            "done are kept (the others are 'not processed')")
                warnings.warn(said[-1], UserWarning, stacklevel=2)
                stop_reason = "frame error"
                break
            image, shared, looks = _frame_features(image, t, t == start, options.get("isef_b", 0.7))
            brightness[t] = _brightness(looks)
            if shared.missing is not None:
                (empty if shared.missing.all() else with_missing).append(t)
            run.stage = np.zeros(2) if before is None else _stage_shift(run, before, looks, t, step)
            run.stages[t] = run.stage
            run.before, run.looks = before, looks
            before = looks
            if t == start:
                start_looks = looks
                _read_by(run, image, contrast, polarity)
            for k in _segment_frame(run, image, shared, t, step):
                done += 1
                stop = yield TrackingProgress(t, k, run.contours[k][t], run.status[k][t], done, total)
                if stop:
                    stop_reason = "cancelled"
                    break
            if stop_reason == "cancelled":
                break
            said += _warn_not_found(run, image) if t == start else _warn_divided(run, t, step)
            if t != start:
                dimmed += _faded_as_the_frame_dimmed(run, t, brightness)
                if (nothing := _nothing_to_find(run, t, image, shared.missing)) is not None:
                    run.nothing_there[t] = nothing
                together += _lost_together(run, t, step, nothing)
        if stop_reason == "cancelled":
            break
    said += _warn_dimmed(dimmed) + _warn_lost_together(together)
    if with_missing:
        said.append(f"NaN (or masked) pixels, read as no data, in {len(with_missing)} of {n_frames} frames "
                    f"(first: frame {min(with_missing)}): the contours keep out of them, and an object that goes "
                    "into them has left the field of view")
        warnings.warn(said[-1], UserWarning, stacklevel=2)
    if empty:
        said.append(f"{len(empty)} frame(s) hold NaN pixels only, no data (first: frame {min(empty)}): every object "
                    "is lost there, and followed again after")
        warnings.warn(said[-1], UserWarning, stacklevel=2)
    reason = _reasons(run)
    said += _warn_lost(run, reason)
    t_segmented = time.perf_counter()
    analysis = _correspondences(run.contours, start, match_options or {})
    t_end = time.perf_counter()
    status = [[s if s is not None else "not processed" for s in row] for row in run.status]
    return TrackingResult(
        contours=run.contours, status=status, **analysis, start=start, stop_reason=stop_reason,
        timings={"segmentation": t_segmented - t_start, "correspondence": t_end - t_segmented,
                 "total": t_end - t_start}, warnings=tuple(said), reason=reason,
        contrast=[seen.contrast for seen in run.seen])


#: Why nothing is found on a frame of no data (see _nothing_to_find); iter_track warns of such frames.
NO_DATA = "frame {t} holds no data (NaN pixels only)"


def _nothing_to_find(run: _Run, t: int, image: np.ndarray, missing) -> str | None:
    """Why the objects lost on frame ``t`` (``image``, its NaN pixels filled;
    ``missing``: those) could be found on it by nothing, if so: it holds
    no data, or one value throughout; None if it shows something, or lost none."""
    if not any(status[t] == LOST for status in run.status):
        return None
    if missing is not None and missing.all():
        return NO_DATA.format(t=t)
    if np.ptp(image) == 0:
        return f"frame {t} holds one value throughout (a dropped frame, or a chunk missing from a zarr store)"
    return None


def _reasons(run: _Run) -> list[list[str]]:
    """Why each object is lost on each frame it is lost on ("" elsewhere):
    as found there (see _Seen.why), else the division that ended its track
    or the frame it went missing on (after MAX_GAP frames it is no longer
    looked for)."""
    out = []
    for k, seen in enumerate(run.seen):
        row = [""] * len(run.status[k])
        for t, status in enumerate(run.status[k]):
            if status != LOST:
                continue
            step = 1 if t > run.start else -1
            ended = _division_before(seen, t, run.start, step)
            if t in run.nothing_there:
                row[t] = run.nothing_there[t]
            elif t in seen.divided:
                row[t] = "it divided here: its two bodies stand apart (see the warnings)"
            elif ended is not None:
                row[t] = f"its track ended where it divided, on frame {ended}"
            elif seen.why.get(t):
                row[t] = seen.why[t]
            else:
                went = t
                while 0 <= went - step < len(row) and run.status[k][went - step] == LOST and went != run.start:
                    went -= step
                row[t] = (f"no longer looked for: lost since frame {went}, more than {MAX_GAP} frames before"
                          if went != t else "not found")
        out.append(row)
    return out


def _first_lost(reason: list[str], start: int) -> tuple[int, str] | None:
    """The frame of one object's ``reason`` row nearest ``start`` where it is
    lost, and why; None if it is lost on none."""
    lost = [t for t, why in enumerate(reason) if why]
    if not lost:
        return None
    t = min(lost, key=lambda frame: abs(frame - start))
    return t, reason[t]


def frame_runs(frames: list[int]) -> str:
    """Frames (sorted) as runs: "frame 5", "frames 5-9, 20"."""
    runs, start = [], frames[0]
    for before, t in zip(frames, frames[1:] + [None]):
        if t != before + 1:
            runs.append(f"{start}" if start == before else f"{start}-{before}")
            start = t
    return ("frame " if len(frames) == 1 else "frames ") + ", ".join(runs)


#: Where the warning of objects lost (see _warn_lost) sends its reader for the rest.
WHY_ON_EACH_FRAME = "TrackingResult.reason (the table's reason column) says why on each frame"

#: How many objects the warning of objects lost (see _warn_lost) names, each with its first loss.
LOST_NAMED = 5


def _warn_lost(run: _Run, reason: list[list[str]]) -> list[str]:
    """One warning naming the objects lost on some frame that no other
    warning named (a division, a frame that lost many, or one that dimmed,
    an object not found on the start frame), and why each was first lost;
    the result's ``reason`` says why on every frame. Returns the message."""
    first = []
    no_data = {t for t, why in run.nothing_there.items() if why == NO_DATA.format(t=t)}  # (warned of apart)
    for k, row in enumerate(reason):
        lost = [t for t, why in enumerate(row) if why and t != run.start]
        if lost and k not in run.warned and not set(lost) <= no_data:
            first.append(f"object {k} on {frame_runs(lost)}: {_first_lost(row, run.start)[1]}")
    if not first:
        return []
    named = "; ".join(first[:LOST_NAMED]) + (f"; and {len(first) - LOST_NAMED} more" if len(first) > LOST_NAMED
                                              else "")
    said = [f"{len(first)} object(s) were lost on some frames. {named}. {WHY_ON_EACH_FRAME}"]
    warnings.warn(said[-1], UserWarning, stacklevel=5)
    return said


#: A frame where at least LOST_TOGETHER_SHARE of the objects followed on the
#: frame before (and at least LOST_TOGETHER_LEAST of them) are lost at once,
#: not as faded nor divided, is named in a warning: the objects moved further
#: between frames than tracking looks (about their own size), or the frame
#: changed. An outside tester's scratch-assay movie, nuclei moving about
#: their spacing between frames, lost 26 of 59 on its second frame, silently.
LOST_TOGETHER_SHARE = 1 / 3
LOST_TOGETHER_LEAST = 3


def _lost_together(run: _Run, t: int, step: int, nothing: str | None) -> list[tuple[int, int, int, bool]]:
    """``[(t, lost, followed, blank)]`` if frame ``t`` lost many of the
    objects followed on the frame before (see LOST_TOGETHER_SHARE), else
    ``[]``; ``blank``: the frame holds one value (``nothing``: see
    _nothing_to_find). A frame without data is warned of on its own."""
    if nothing == NO_DATA.format(t=t):
        return []
    followed = [k for k in range(len(run.inits)) if run.status[k][t - step] == TRACKED]
    lost = [k for k in followed if run.status[k][t] == LOST and t not in run.seen[k].fades
            and t not in run.seen[k].divided]
    if len(lost) < max(LOST_TOGETHER_LEAST, LOST_TOGETHER_SHARE * len(followed)):
        return []
    run.warned.update(lost)
    return [(t, len(lost), len(followed), nothing is not None)]


def _warn_lost_together(frames: list) -> list[str]:
    """The warnings naming the frames where many objects were lost at once
    (see _lost_together): blank ones, then the others."""
    said = []
    blank = sorted(t for t, _, _, flat in frames if flat)
    if blank:
        # (Not "they moved further": a tester's missing zarr chunk, read as zeros, was blamed on motion.)
        said.append(f"frame(s) {', '.join(map(str, blank[:5]))}{' ...' if len(blank) > 5 else ''} hold one value "
                    "throughout (a dropped frame, or a chunk missing from a zarr store, which reads as zeros): the "
                    "objects followed were lost there, and looked for again on the next frames")
    others = sorted((t, lost, followed) for t, lost, followed, flat in frames if not flat)
    if others:
        shown = ", ".join(f"{t} ({lost} of {followed})" for t, lost, followed in others[:5])
        said.append(f"many of the objects followed were lost at once on frame(s) {shown}"
                    f"{' ...' if len(others) > 5 else ''}: they moved further between frames than about their own "
                    "size, or those frames changed (focus, a jump of the stage, a flash). Look at those frames; a "
                    "movie whose objects move that far between frames needs detection and linking (e.g. laptrack) "
                    "rather than contours carried from frame to frame")
    for message in said:
        warnings.warn(message, UserWarning, stacklevel=5)  # track()'s caller (through iter_track, drain and track)
    return said


def _checked_start(start, n_frames: int) -> int:
    """:func:`track`'s ``start``, a frame index (ValueError if it is not one)."""
    if isinstance(start, (bool, np.bool_)) or not isinstance(start, (int, np.integer)) or not 0 <= start < n_frames:
        raise ValueError(f"start must be a frame index (an integer) in [0, {n_frames - 1}], got {start!r}")
    return int(start)


def _checked_segment_options(segment_options: dict | None, max_steps: int) -> dict:
    """:func:`track`'s ``segment_options`` with its ``max_steps``, checked once
    here: a bad option must not pass, frame after frame, for a lost object."""
    options = dict(_mapping(segment_options, "segment_options"))
    options.setdefault("max_steps", check_count(max_steps, "max_steps", 1))
    taken = sorted({"features", "avoid", "callback"} & set(options))
    if taken:
        raise ValueError(f"segment_options cannot set {taken}: track() sets them for each object and frame")
    try:
        check_segment_options(**options)
    except TypeError as err:  # an option segment() does not have
        raise TypeError(f"segment_options: {err}") from None
    return options


def _mapping(options, name: str) -> dict:
    """``options`` (a dict of keyword arguments, or None) as a dict, or a
    ValueError naming ``name``."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"{name} must be a dict of options, e.g. {{'material': 'copper'}}, got {options!r}")
    return options


def _checked_match_options(match_options: dict | None) -> dict:
    """:func:`track`'s ``match_options``, checked before any frame is read (a
    bad one failed only once the frames were segmented, from inside the
    matching): options of :func:`match` but those track() sets."""
    options = dict(_mapping(match_options, "match_options"))
    taken = sorted({"method", "callback"} & set(options))
    if taken:
        raise ValueError(f"match_options cannot set {taken}: track() matches consecutive contours with the "
                         "order-preserving method, without a callback of its own")
    unknown = sorted(set(options) - set(signature_of(match).parameters))
    if unknown:
        raise ValueError(f"match_options has {unknown}, which are not options of match()")
    # match's own checks, with its words, on two small outlines: the job a
    # matching is made of, not the matching (3 ms, where one took 0.1 s).
    turn = np.linspace(0.0, 2.0 * np.pi, 12, endpoint=False)
    circle = np.column_stack([np.sin(turn), np.cos(turn)]) * 10.0
    try:
        _prepare(**_match_arguments(circle, circle * [1.2, 0.9], {**options, "method": "order"}, ""))
    except ValueError as err:
        raise ValueError(f"match_options: {err}") from None
    return options


def _frame_features(image: np.ndarray, t: int, is_start: bool, isef_b: float):
    """Frame ``t`` with its NaN pixels filled, the features its objects share,
    and their looks: the frame with its illumination taken out (a slope of
    the background fixed under moving objects drew their matches toward no
    motion).

    NaN pixels hold no data (a registration's margin): filled once for every
    object, which keeps out of them (see _without_missing); the start frame
    must hold data.
    """
    image, missing = _measured(image)
    if is_start and missing is not None and missing.all():
        raise ValueError(f"the start frame {t} holds NaN pixels only (no data): draw the contours on a "
                         "frame with data and start there")
    shared = replace(FrameFeatures.of(image, isef_b), missing=missing)
    looks = plane_removed(image.astype(np.float64, copy=False), shared.plane,
                          (slice(0, image.shape[0]), slice(0, image.shape[1])))
    return image, shared, looks


def _measured(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """Frame ``image`` with its NaN pixels filled, and where they were (see
    _without_missing). A frame without a measured pixel (a dropped frame
    stored as NaN) is blank: no object is found on it, and each is looked
    for again on the next ones, as after a blank frame."""
    if image.dtype.kind == "f" and np.isnan(image).all():
        return np.zeros(image.shape), np.ones(image.shape, dtype=bool)
    return _without_missing(image)


def _frame(frames, t: int) -> np.ndarray:
    """Frame ``t`` as float64, read now (one frame at a time: dask, zarr); a ValueError naming
    the frame if it cannot be read or holds infinite pixels (NaN ones hold no data, see
    _without_missing)."""
    try:
        image = np.asarray(_masked_as_missing(frames[t]), dtype=np.float64)
    except ValueError:  # already says what (a file reader's, see io.open_stack)
        raise
    except Exception as err:  # noqa: BLE001 - a decoder's or a store's error: one plain sentence
        raise ValueError(f"frame {t} could not be read: {type(err).__name__}: {' '.join(str(err).split())}") from None
    if np.isinf(image).any():
        raise ValueError(f"frame {t} has infinite pixels; clip or replace them before tracking "
                         "(e.g. np.nan_to_num)")
    return image


#: A drawing that holds at least this share of another's area passes over
#: the other's object, or marks the same one (see _settle_first, _warn_not_found).
SAME_DRAWING_SHARE = 0.5


def _warn_not_found(run: _Run, image: np.ndarray) -> list[str]:
    """Warn, naming the likely cause, of each object not found on the start
    frame ``image``: it is reported lost on every frame, which is seldom what
    was meant. Returns the messages."""
    said, shape, blank = [], image.shape, _blank(image)
    order = _segmenting_order(run, run.start, 1)  # (the start frame's: the drawings' areas alone)
    for k, init in enumerate(run.inits):
        if run.status[k][run.start] == TRACKED:
            continue
        # Only an object found before k can have taken what k marks: a
        # generous circle done after a tight one inside it did not (it was
        # blamed for a small cell whose own contour leaked).
        before = order[:order.index(k)]
        within = [j for j in before if run.status[j][run.start] == TRACKED
                  and (_holds(run.inits[j], init, shape) or _holds(init, run.inits[j], shape))]
        if blank:
            why = blank
        elif within:
            # (Not "one within the other": two circles about touching rods overlap so.)
            why = (f"its drawing and that of object {within[0]} overlap by more than half of one of them, so both "
                   f"were taken to mark the same object, which contours that never overlap cannot share; draw "
                   f"each object once, and objects that touch each closely (a polygon or a box about each)")
        else:
            found = run.seen[k].why.get(run.start, "no object came to rest under its drawing")
            why = (f"{found}; check that it is drawn around (or inside) one object, or the contour's options "
                   "(max_steps and segment_options of track())")
        run.seen[k].why[run.start] = f"not found on the start frame: {why}"
        run.warned.add(k)
        said.append(f"object {k} was not found on the start frame {run.start} and is reported lost: {why}")
        warnings.warn(said[-1], UserWarning, stacklevel=5)
    return said


def _blank(image: np.ndarray) -> str | None:
    """Why nothing can be found on ``image`` whatever was drawn (all its
    pixels with data of one value), or None. (A frame without data is refused
    before: see iter_track.)"""
    missing = np.isnan(image)
    known = image[~missing]
    if known.min() == known.max():
        pixels = "every pixel of the frame with data" if missing.any() else "every pixel of the frame"
        return (f"{pixels} is {known.min():g}, so it has no border to follow; check that this is "
                f"the channel meant, and that no conversion of the data type rounded it to one value")
    return None


#: A contour pinched into two bodies, each at least DIVISION_SHARE of its
#: area, by a neck narrower than DIVISION_NECK times the smaller body's
#: diameter, holds two objects: a cell in division (its nucleus' two masses
#: apart, or nearly), or the object and a neighbour it took in. A nucleus'
#: notch or a cell's waist leaves a neck of half its width or more.
DIVISION_SHARE = 0.25
DIVISION_NECK = 0.25
#: On the start frame, a person's drawing around bodies apart has them joined
#: by a bar about a quarter to a third of a body's width (docs/physics.md):
#: a neck narrower than BRIDGED_NECK times the smaller body's diameter there
#: holds two bodies. (A drawing around two disks 6 px apart, in noise, was
#: lost on the next frame without a word at DIVISION_NECK.)
BRIDGED_NECK = 0.4


def _warn_divided(run: _Run, t: int, step: int) -> list[str]:
    """Warn of each object lost on frame ``t`` whose contour on the frame
    done before held two bodies (see :func:`pinched_bodies`), or that was
    pinched in two on ``t`` itself: a division ends a track, which is seldom
    what "lost" alone would tell. Tracking backward (``step`` -1), the two
    bodies came together. Returns the messages."""
    said = []
    for k in range(len(run.inits)):
        if run.status[k][t] != LOST:
            continue
        if t in run.seen[k].divided:
            where = " and ".join(f"({c[0]:.0f}, {c[1]:.0f})" for c in map(area_centroid, run.seen[k].divided[t]))
            what = " divided on frame {t}" if step > 0 else ", tracked backward, was two bodies on frame {t} (two " \
                "that came together)"
            said.append(f"object {k}{what.format(t=t)}: they stand apart at {where}; its track ends there (lost "
                        f"from frame {t} on, in that direction); to follow the two, draw each on frame {t} and "
                        f"track from there (start={t})")
            warnings.warn(said[-1], UserWarning, stacklevel=5)
            run.warned.add(k)
            continue
        # Its contour on the frame done before (t is not the start frame),
        # else the one it parted on this frame: two bodies a pixel or two
        # apart hold the contour between them no longer.
        before, held = run.contours[k][t - step], t - step
        pinch = BRIDGED_NECK if held == run.start else DIVISION_NECK
        bodies = None if before is None else pinched_bodies(before, pinch)
        if bodies is None and t in run.seen[k].parted and run.status[k][t - step] == TRACKED:
            bodies, held = run.seen[k].parted[t], t
        if bodies is None:
            continue
        where = " and ".join(f"({c[0]:.0f}, {c[1]:.0f})" for c in (area_centroid(b) for b in bodies))
        neck = np.linalg.norm(bodies[0][-1] - bodies[0][0])  # the nodes it was cut between
        # Lost on t only: it is looked for again on the next MAX_GAP frames from
        # its last contour, which may find one of the two (it said "lost from t
        # on", and a daughter was then followed as the object).
        what = ("it divided, or took in a neighbour, and is reported lost on frame {t}; a later frame that "
                "shows one body where it was is followed as the object" if step > 0 else
                "the two came together there (two objects that met, or a neighbour it took in), and it is "
                "reported lost on frame {t}; an earlier frame that shows one body where it was is followed "
                "as the object")
        said.append(f"object {k} held two bodies on frame {held} (at {where}, joined by a neck "
                    f"{neck:.1f} px wide): {what.format(t=t)}; to follow the two, draw each on frame {t} "
                    f"and track from there (start={t})")
        warnings.warn(said[-1], UserWarning, stacklevel=5)
        run.warned.add(k)
    return said


#: Objects lost as faded on one frame (at least DIMMED_OBJECTS of them)
#: while the whole frame dimmed below DIMMED_BRIGHTNESS of its brightest
#: within FADE_WINDOW frames are named in a warning: a movie that bleaches
#: or flickers fast loses objects still in view (see FADED_CONTRAST).
DIMMED_OBJECTS = 2
DIMMED_BRIGHTNESS = 0.5

#: The percentiles of a frame whose difference is its brightness (see _brightness).
BRIGHTNESS_PERCENTILES = (0.5, 99.5)


def _brightness(looks: np.ndarray) -> float:
    """The spread of frame ``looks`` (its illumination taken out) between
    BRIGHTNESS_PERCENTILES: photobleaching and a lamp's flicker dim it with
    every object of the frame."""
    low, high = np.percentile(looks, BRIGHTNESS_PERCENTILES)
    return float(high - low)


def _faded_as_the_frame_dimmed(run: _Run, t: int, brightness: dict) -> list[tuple]:
    """``[(t, objects, share)]`` when DIMMED_OBJECTS objects or more were lost
    as faded on frame ``t`` while the frame itself dimmed to ``share`` of its
    brightest within FADE_WINDOW frames (below DIMMED_BRIGHTNESS); else ``[]``."""
    faded = [k for k, seen in enumerate(run.seen) if t in seen.fades and run.status[k][t] == LOST]
    brightest = max(b for frame, b in brightness.items() if abs(frame - t) <= FADE_WINDOW)
    share = brightness[t] / brightest if brightest > 0 else 1.0
    if len(faded) < DIMMED_OBJECTS or share >= DIMMED_BRIGHTNESS:
        return []
    run.warned.update(faded)
    return [(t, faded, share)]


def _warn_dimmed(dimmed: list[tuple]) -> list[str]:
    """One warning for the frames where objects faded out as the whole frame
    dimmed (see _faded_as_the_frame_dimmed): the fade is judged in each
    object's own contrast, so a movie that bleaches fast ends the tracks of
    objects still in view. Returns the message, if any."""
    if not dimmed:
        return []
    objects = sorted({k for _, faded, _ in dimmed for k in faded})
    frames = ", ".join(f"{t} ({share:.2f})" for t, _, share in dimmed[:6]) + (", ..." if len(dimmed) > 6 else "")
    said = [f"{len(objects)} object(s) faded out, and are reported lost, on frames where the whole frame dimmed "
            f"(in brackets, its contrast against the brightest within {FADE_WINDOW} frames): {frames}. If the movie "
            "photobleaches or flickers, even out its frames before tracking (each frame minus its median, over its "
            "99th percentile less its median); if the objects left the focal plane, this is what it shows"]
    warnings.warn(said[-1], UserWarning, stacklevel=5)
    return said


def pinched_bodies(contour: np.ndarray, neck: float = DIVISION_NECK) -> tuple[np.ndarray, np.ndarray] | None:
    """The two bodies of a contour pinched by a narrow neck, or None.

    The contour is cut between the two nodes that are closest in space among
    the pairs that split it into parts of at least :data:`DIVISION_SHARE` of
    its area each; the parts are two bodies when that gap is below ``neck``
    times the smaller part's equivalent diameter.
    """
    c = np.asarray(contour, dtype=np.float64)
    n = len(c)
    if n < 8:
        return None
    # Area of the part i..j (closed by the chord j -> i) from the prefix sums of the shoelace terms.
    cross = c[:, 0] * np.roll(c[:, 1], -1) - np.roll(c[:, 0], -1) * c[:, 1]
    prefix = np.concatenate([[0.0], np.cumsum(cross)])
    i, j = np.triu_indices(n, k=2)
    part = 0.5 * np.abs(prefix[j] - prefix[i] + c[j, 0] * c[i, 1] - c[i, 0] * c[j, 1])
    whole = abs(signed_area(c))
    balanced = (part >= DIVISION_SHARE * whole) & (whole - part >= DIVISION_SHARE * whole)
    if not balanced.any():
        return None
    i, j, part = i[balanced], j[balanced], part[balanced]
    gap = np.linalg.norm(c[i] - c[j], axis=1)
    best = int(np.argmin(gap))
    diameter = 2.0 * np.sqrt(min(part[best], whole - part[best]) / np.pi)
    if gap[best] >= neck * diameter:
        return None
    a, b = int(i[best]), int(j[best])
    return c[a: b + 1], np.vstack([c[b:], c[: a + 1]])


def _segment_frame(run: _Run, image, shared, t: int, step: int):
    """Segment every object on frame ``t``, one after the other (see
    _segmenting_order), each counting the others' pixels as background,
    then take the second looks (see _give_back, _link_lost); a generator of
    the objects once the frame is done. (Yielded as each was first done, an
    object reported lost could be found by the second looks: the progress
    said 'lost', the result 'tracked'.)"""
    # Which object each pixel belongs to, as far as known: the others'
    # contours on this frame once done, else on the frame before.
    owner = np.full(image.shape, -1, dtype=np.int32)
    run.painted = {}
    order = _segmenting_order(run, t, step)
    run.drift = _field_drift(run, t, step)
    for j in reversed(order):  # where claims overlap, the object done first has them
        _paint(run, owner, _claim_before(run, j, t, step), j)
    run.moved = []
    boxes = np.array([np.r_[c.min(0), c.max(0)] for c in run.inits]) if t == run.start else None
    for n, k in enumerate(order):
        if t == run.start:
            _settle_first(run, image, shared, owner, k, order[n + 1:], boxes)
            _drop_second_find(run, owner, k, order[:n], boxes, image.shape)
        else:
            _settle(run, image, shared, owner, t, k, step)
        if run.status[k][t] != TRACKED and t != run.start:
            _give_back(run, image, shared, owner, t, k, step, order[:n])
    if t != run.start:
        # An object lost before the one that took its place was done; one found
        # where another that fits worse than lost took its pixels.
        astray = _astray(run, t, step, order)
        for n, k in enumerate(order):
            others = order[n + 1:] if run.status[k][t] != TRACKED else [i for i in astray if i != k]
            _give_back(run, image, shared, owner, t, k, step, others)
        _link_lost(run, image, shared, owner, t, step)
        _divisions(run, image, shared, owner, t, step)
    yield from order


#: An object just lost is looked for once more when every object of the
#: frame is done: in the blob of object-like pixels that no object holds
#: (see _unclaimed_blob) within this many of its radii of where it was.
LINK_REACH = 3.0
#: ... but not in one that was there on the frame before, object-like and
#: held by no object, along this share of its pixels: another object (an
#: untracked neighbour), not this one moved.
THERE_BEFORE_SHARE = 0.5


def _link_lost(run: _Run, image, shared, owner, t: int, step: int) -> None:
    """The objects lost on frame ``t`` though tracked on the frame before
    segmented once more, each from the unclaimed blob nearest where it was
    and likest it in area (see _unclaimed_blob), as a linker of detections
    would (laptrack's cost on distance; the area as _judge bounds it). A
    blob goes to the object lost within MAX_GAP frames that it costs least,
    or to none: an object that vanished beside one lost before does not
    take its place, and none takes the daughters of one that divided (a
    division, parted on its way, is reported lost). One kept lost if that
    fails too.

    The first looks search one radius about the motion known (a nucleus of a
    real HeLa movie jumped 1.9 radii between its first two frames, and was
    never seen again); a far look by the object's looks alone matched
    neighbours, and a dividing cell's two daughters together.
    """
    # The frame before and its objects as the stage moved them onto this one (see _stage_shift).
    shift = np.rint(run.stage).astype(int)
    before = np.roll(run.before, tuple(shift), axis=(0, 1)) if run.before is not None and shift.any() else run.before
    held_before = [c[t - step] + shift for c in run.contours if c[t - step] is not None]
    bids = []
    for k in range(len(run.inits)):
        last, history = _history(run, k, t, step) if run.status[k][t] == LOST else (None, [])
        if last is None:
            continue
        where = history[-1] + _staged_since(run, last, t, step)
        found = _unclaimed_blob(_seen_as(run, k, t, image, shared)[1].intensity, owner, where,
                                run.seen[k].polarity, before, [where, *held_before])
        if found is not None:
            bids.append((found[0], k, found[1], last == t - step and t not in run.seen[k].parted))
    granted = []
    for _, k, blob, linked in sorted(bids, key=lambda bid: bid[:2]):
        if any(_overlap(blob, other, owner.shape) for other in granted):
            continue
        granted.append(blob)
        if not linked:
            continue
        kept, moved = (run.contours[k][t], run.status[k][t], run.seen[k].copy()), list(run.moved)
        _settle(run, image, shared, owner, t, k, step, handed=blob)
        run.moved = moved
        if run.status[k][t] != TRACKED:
            _unpainted(run, owner, k)
            run.contours[k][t], run.status[k][t], run.seen[k] = kept


def _divisions(run: _Run, image, shared, owner: np.ndarray, t: int, step: int) -> None:
    """End the track of each object that divided on frame ``t`` (see
    DIVIDED_AREA): lost there and on, its two bodies kept for the warning
    (see _warn_divided). Tracking backward, two bodies that came together.
    Not at the image's side, where an object shrinks as it leaves."""
    shape = shared.intensity.shape
    for k in range(len(run.inits)):
        contour, before = run.contours[k][t], run.contours[k][t - step]
        if run.status[k][t] != TRACKED or before is None or \
                abs(signed_area(contour)) > DIVIDED_AREA * abs(signed_area(before)):
            continue
        if _touches_side(contour, shape, shared.missing) or _touches_side(before, shape, shared.missing):
            continue  # the side hides a part of an object it cuts (a nucleus leaving a drifting field: 0.49)
        sister = _sister(_seen_as(run, k, t, image, shared)[1].intensity, owner, contour, before,
                         run.seen[k].polarity)
        if sister is not None:
            run.seen[k].divided[t] = (contour, sister)
            _unpainted(run, owner, k)
            run.contours[k][t], run.status[k][t] = None, LOST


def _sister(intensity: np.ndarray, owner: np.ndarray, contour: np.ndarray, before: np.ndarray, polarity: str):
    """The outline of the sister of ``contour`` on this frame (see
    DIVIDED_AREA; ``before``: the object's contour on the frame before), or None."""
    radius, area = _radius(before), abs(signed_area(contour))
    box = bounding_window(before, intensity.shape, 2.0 * radius)
    corner = np.array([box[0].start, box[1].start])
    shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
    beside = cv2.dilate(_fill(contour, shape, corner).view(np.uint8), np.ones((3, 3), np.uint8)).view(bool)
    like = _object_like(intensity[box], 1.0 if polarity == "bright" else -1.0) & (owner[box] < 0)
    labels, n = ndi.label(like)
    apart = np.setdiff1d(np.arange(1, n + 1), labels[beside])  # (a body that meets the contour is its own)
    if apart.size == 0:
        return None
    sizes = np.bincount(labels.ravel(), minlength=n + 1)[apart]
    centroids = np.array(ndi.center_of_mass(like, labels, apart)) + corner
    was = area_centroid(before)
    together = (area * area_centroid(contour) + sizes[:, None] * centroids) / (area + sizes)[:, None]
    off = np.hypot(*(together - was).T)
    off[(sizes < SISTER_AREA * area) | (sizes > area / SISTER_AREA)] = np.inf
    best = int(np.argmin(off))
    if not off[best] <= min(SISTER_CENTRING * radius, np.hypot(*(area_centroid(contour) - was))):
        return None
    return _outline_of(labels == apart[best], corner)


def _outline_of(blob: np.ndarray, corner) -> np.ndarray:
    """The outer outline (row, col) of the boolean ``blob``, a window whose
    first pixel is pixel ``corner`` of the frame: its longest, if it is in pieces."""
    outlines = cv2.findContours(blob.view(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0]
    return max(outlines, key=len)[:, 0, ::-1].astype(float) + corner


def _object_like(window: np.ndarray, sign: float) -> np.ndarray:
    """The pixels of ``window`` beyond its Otsu level on the object's side
    (``sign``: +1 bright objects, -1 dark ones); none in a flat window."""
    if np.ptp(window) <= 0:
        return np.zeros(window.shape, bool)
    return sign * (window - threshold_otsu(window)) > 0


def _held(contours, box) -> np.ndarray:
    """Which pixels of the window ``box`` (a pair of slices) lie inside any of ``contours``."""
    corner, far = np.array([box[0].start, box[1].start]), np.array([box[0].stop, box[1].stop])
    shape = (box[0].stop - box[0].start, box[1].stop - box[1].start)
    held = np.zeros(shape, bool)
    for contour in contours:
        if np.all(contour.max(0) >= corner) and np.all(contour.min(0) < far):  # (most lie elsewhere)
            held |= _fill(contour, shape, corner)
    return held


def _unclaimed_blob(intensity: np.ndarray, owner: np.ndarray, last: np.ndarray, polarity: str,
                    before: np.ndarray | None = None, held_before=()):
    """The outline of the blob of object-like pixels (beyond the Otsu level
    of the neighbourhood, at the object's ``polarity``) that no object owns,
    whose centroid lies within LINK_REACH radii of ``last``'s, whose area is
    within MAX_AREA_CHANGE of ``last``'s, that was not there on the frame
    ``before`` (object-like there and inside none of ``held_before``, the
    contours on it and the lost object's own, along THERE_BEFORE_SHARE of its
    pixels), and that is nearest and likest in area (the distance in radii
    plus the log of the areas' ratio), with that cost; None if there is none."""
    radius, centre, area = _radius(last), area_centroid(last), abs(signed_area(last))
    reach = LINK_REACH * radius
    box = bounding_window(np.array([centre - reach, centre + reach]), intensity.shape, radius)
    sign = 1.0 if polarity == "bright" else -1.0
    like = _object_like(intensity[box], sign) & (owner[box] < 0)
    labels, n = ndi.label(like)
    if n == 0:
        return None
    index = np.arange(1, n + 1)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)[1:]
    centroids = np.array(ndi.center_of_mass(like, labels, index)) + [box[0].start, box[1].start]
    distance = np.hypot(*(centroids - centre).T)
    cost = distance / radius + np.abs(np.log(np.maximum(sizes, 1) / area))
    cost[(distance > reach) | (sizes < area / MAX_AREA_CHANGE) | (sizes > MAX_AREA_CHANGE * area)] = np.inf
    if before is not None and np.isfinite(cost).any():
        there_before = _object_like(before[box], sign) & ~_held(held_before, box)
        cost[np.asarray(ndi.mean(there_before, labels, index)) >= THERE_BEFORE_SHARE] = np.inf
    best = int(np.argmin(cost))
    if not np.isfinite(cost[best]):
        return None
    outline = _outline_of(labels == best + 1, [box[0].start, box[1].start])
    try:
        return float(cost[best]), as_contour(outline)
    except ValueError:  # a blob too thin to outline
        return None


@dataclass
class _Seen:
    """What is known of an object from the frames done: its polarity, its
    area when last seen whole, and its contrast on the frames where it was tracked."""

    polarity: str
    whole_area: float
    seen_whole: bool = False  # whether whole_area is of a contour the image's side did not cut
    contrasts: dict = field(default_factory=dict)  # frame -> contrast where tracked
    signal: float = np.nan  # contrast times area on its last tracked frame (see MAX_AREA_CHANGE)
    # frame -> the two bodies of a contour pinched on its way to being lost there
    parted: dict = field(default_factory=dict)
    fades: set = field(default_factory=set)  # the frames where it was lost as faded (see faded)
    divided: dict = field(default_factory=dict)  # frame -> its two bodies where it divided (see _divisions)
    drawing: _Drawing | None = None  # the drawing its last tracked frame was segmented in (see _carried)
    why: dict = field(default_factory=dict)  # frame -> why it was not tracked there, as found (see _reasons)
    contrast: str = "intensity"  # what tells it from its background (see _read_by)

    def copy(self) -> _Seen:
        return replace(self, contrasts=dict(self.contrasts), parted=dict(self.parted), fades=set(self.fades),
                       divided=dict(self.divided), why=dict(self.why))

    def faded(self, contrast: float, t: int) -> bool:
        """Whether ``contrast`` on frame ``t`` is below FADED_CONTRAST times
        the object's best within FADE_WINDOW frames of it."""
        near = [c for frame, c in self.contrasts.items() if abs(frame - t) <= FADE_WINDOW and c > 0]
        return bool(near) and contrast < FADED_CONTRAST * max(near)


@dataclass
class _Run:
    """What one track() run knows so far: the drawings on the start frame,
    and per object and frame the contours and statuses found."""

    inits: list
    start: int
    options: dict
    contours: list
    status: list
    seen: list
    moved: list = field(default_factory=list)  # see _common_motion: of the objects done on the current frame
    stage: np.ndarray = field(default_factory=lambda: np.zeros(2))  # see _stage_shift: of the current frame
    stages: dict = field(default_factory=dict)  # frame -> the stage's shift onto it (see _staged_since)
    drift: np.ndarray = field(default_factory=lambda: np.zeros(2))  # see _field_drift: of the current frame
    looks: np.ndarray | None = None  # the current frame, its illumination taken out (see background.plane_removed)
    before: np.ndarray | None = None  # the same of the frame before, in the direction of travel
    painted: dict = field(default_factory=dict)  # see _paint: per object, the box of its pixels on the current frame
    warned: set = field(default_factory=set)  # the objects a warning named lost (see _warn_lost)
    nothing_there: dict = field(default_factory=dict)  # frame -> why nothing is found there (see _nothing_to_find)
    textured: tuple | None = None  # (frame, its texture, the texture's features), for objects told by it (see _seen_as)


def _claim_before(run: _Run, k: int, t: int, step: int) -> np.ndarray | None:
    """Object ``k``'s pixels on frame ``t`` as far as known before it is done:
    its drawing on the start frame, else its contour on the frame before
    moved onto this frame by its own motion if that is steady (see
    _steady_motion), else by the whole field's drift (``run.drift``, see
    _field_drift: the stage's shift, when the stage shook).

    Claimed where it was, a neighbour done first took the band it moved
    into, more of it frame after frame: of two touching nuclei, one ended on
    the other's place. Claimed as the whole field drifted, the same happened
    where the field turns or warps, each part of it moving its own way: on
    the turning and the warped Data Science Bowl movies of
    benchmarks/tracking_warped.py, 37 object-frames lay on another nucleus'
    label and 43 visible nucleus-frames had no contour; claimed by their
    steady motions, 13 and 14."""
    if t == run.start:
        return run.inits[k]
    before = run.contours[k][t - step]
    if before is None:
        return None
    own = None if run.stage.any() else _steady_motion(run.contours[k], t, step)
    return before + (run.drift if own is None else own)


#: An object moves steadily when its last two displacements differ by at
#: most this many px: within a pixel, what differs is the segmentation's
#: noise (its contours on identical frames), not a change of the motion.
STEADY_MOTION = 1.0


def _steady_motion(contours: list, t: int, step: int) -> np.ndarray | None:
    """The last displacement of the area centroid of the object whose
    ``contours`` these are (from frame ``t - 2 step`` to ``t - step``), if
    it is steady: within STEADY_MOTION px of the one before. None if the
    object was not seen on those three frames, or moved unsteadily (a dart,
    a stop, a turn back: there one object's motion is no guess, see
    _field_drift)."""
    past = [contours[t - n * step] if 0 <= t - n * step < len(contours) else None for n in (1, 2, 3)]
    if any(contour is None for contour in past):
        return None
    now, before, earlier = (area_centroid(contour) for contour in past)
    last = now - before
    return last if np.hypot(*(last - (before - earlier))) <= STEADY_MOTION else None


def _field_drift(run: _Run, t: int, step: int) -> np.ndarray:
    """How the whole field moves onto frame ``t``: the stage's shift (see
    _stage_shift), else the motion the objects tracked on the two frames
    before share (see _common_motion), else none. One object's own motion
    is no guess for the others': after a dart the place it predicts is
    often empty, and where it is went to another."""
    if run.stage.any():
        return run.stage
    moved = [area_centroid(c[t - step]) - area_centroid(c[t - 2 * step]) for c in run.contours
             if 0 <= t - 2 * step < len(c) and c[t - step] is not None and c[t - 2 * step] is not None]
    return _common_motion(moved)


def _settle(run: _Run, image, shared, owner, t: int, k: int, step: int, handed=None) -> None:
    """Segment object ``k`` on frame ``t`` (see _one_object) and make its pixels its own in ``owner``."""
    run.contours[k][t], run.status[k][t] = _one_object(run, image, shared, owner, t, k, step, handed)
    _unpainted(run, owner, k)
    _paint(run, owner, run.contours[k][t], k)


def _settle_first(run: _Run, image, shared, owner, k: int, undone, boxes: np.ndarray) -> None:
    """:func:`_settle` on the start frame, where the objects not done yet
    claim their drawings: but not those that hold most of ``k``'s (a
    generous drawing that passes over ``k``, or goes around the object that
    ``k`` marks from inside it), or ``k`` could not reach its object's border.
    ``boxes``: each drawing's (row, col) min and max, so that only drawings
    whose boxes meet ``k``'s are weighed (hundreds of objects make many pairs)."""
    holders = [j for j in _meeting(boxes, k, undone) if _holds(run.inits[j], run.inits[k], image.shape)]
    view = np.where(np.isin(owner, holders), -1, owner) if holders else owner
    _settle(run, image, shared, view, run.start, k, 1)
    swallowed = _swallowed(run, k, [j for j in undone if j not in holders], boxes, image.shape)
    if swallowed:
        view = _parted(run, shared.intensity, view, k, swallowed)
        _settle(run, image, shared, view, run.start, k, 1)
    if view is not owner:
        _unpainted(run, owner, k)
        _paint(run, owner, run.contours[k][run.start], k)
        for j in swallowed:  # their claims, which k's first contour had painted over
            _paint(run, owner, run.inits[j], j, only_free=True)


def _meeting(boxes: np.ndarray, k: int, others) -> np.ndarray:
    """The objects of ``others`` whose drawings' boxes (see _settle_first)
    meet object ``k``'s."""
    others = np.asarray(others, dtype=int)
    meet = np.all(boxes[others, :2] <= boxes[k, 2:], axis=1) & np.all(boxes[k, :2] <= boxes[others, 2:], axis=1)
    return others[meet]


def _swallowed(run: _Run, k: int, candidates, boxes: np.ndarray, shape) -> list[int]:
    """The objects of ``candidates`` (not done yet) whose drawings lie wholly
    inside object ``k``'s contour on the start frame, when ``k`` was drawn
    inside its object (most of its drawing within its contour): ``k``'s
    contour took in the objects they mark. Clicks inside touching nuclei of
    a crowd: the first one done took its neighbour too (nothing parts two
    nuclei that touch along most of their width), and the neighbour, its
    pixels another's, was not found (4 of 49 Data Science Bowl nuclei).
    ``boxes``: as for _settle_first."""
    contour = run.contours[k][run.start]
    if contour is None or not candidates or not _holds(contour, run.inits[k], shape):
        return []
    candidates = np.asarray(candidates, dtype=int)
    low, high = contour.min(0), contour.max(0)
    within = np.all(boxes[candidates, :2] >= low, axis=1) & np.all(boxes[candidates, 2:] <= high, axis=1)
    return [j for j in candidates[within] if np.all(depth_inside(contour, run.inits[j]) > 0)]


def _parted(run: _Run, intensity: np.ndarray, owner: np.ndarray, k: int, swallowed) -> np.ndarray:
    """``owner`` with the pixels of ``k``'s contour on the start frame parted
    between ``k`` and the ``swallowed`` objects whose drawings it holds: a
    watershed of the intensity (the object's polarity up) from each drawing,
    so that each gets the body about its own drawing, parted at the valley
    between them. A copy."""
    box = bounding_window(run.contours[k][run.start], owner.shape, 1.0)
    region = window_mask(run.contours[k][run.start], box)
    markers = np.zeros(region.shape, dtype=np.int32)
    for label, j in enumerate([k, *swallowed], start=1):
        markers[window_mask(run.inits[j], box) & region] = label
    up = 1.0 if run.seen[k].polarity == "bright" else -1.0
    basins = watershed(-up * intensity[box], markers, mask=region)
    parted = owner.copy()
    for label, j in enumerate(swallowed, start=2):
        parted[box][basins == label] = j
    return parted


def _drop_second_find(run: _Run, owner, k: int, done, boxes: np.ndarray, shape) -> None:
    """Object ``k`` on the start frame: if its drawing and that of an object
    found before it are one drawing made twice (each holds most of the
    other), and what ``k`` found lies further from the drawing's centre than
    that object does, it is what the first left over: ``k`` is lost (and
    _warn_not_found says why). A drawing means what lies at its centre.
    (Drawn twice about a nucleus with a dim halo, the second found a 12-px
    crumb of the halo beside the 821-px nucleus, and was reported tracked on
    the start frame.) Drawings that differ, a generous one that passes over a
    neighbour's tight one, are left to the image (and to segment's "leaked": a
    contour around pixels of other objects). ``boxes``: as for _settle_first."""
    contour = run.contours[k][run.start]
    if contour is None or not len(done):
        return
    centre = area_centroid(run.inits[k])
    off = np.hypot(*(area_centroid(contour) - centre))
    for j in _meeting(boxes, k, done):
        first = run.contours[j][run.start]
        if first is None or np.hypot(*(area_centroid(first) - centre)) >= off:
            continue
        if _holds(run.inits[j], run.inits[k], shape) and _holds(run.inits[k], run.inits[j], shape):
            _unpainted(run, owner, k)
            run.contours[k][run.start], run.status[k][run.start] = None, LOST
            return


def _holds(a: np.ndarray, b: np.ndarray, shape) -> bool:
    """Whether drawing ``a`` holds at least SAME_DRAWING_SHARE of drawing ``b``'s area."""
    return _shared_area(a, b, shape) >= SAME_DRAWING_SHARE * max(abs(signed_area(b)), 1.0)


def _history(run: _Run, k: int, t: int, step: int):
    """The frame where object ``k`` was last seen before ``t`` (None if not
    within MAX_GAP frames, nor back in view, see _back_in_view) and its
    contours there and on the frame before in the direction of travel (after
    a gap, the last one only: where it went meanwhile is not known)."""
    last = _last_seen(run.status[k], t, step)
    if last is None:
        last = _back_in_view(run, k, t, step)
    if last is None or _division_before(run.seen[k], t, run.start, step) is not None:
        return None, []
    contours = run.contours[k]
    before = contours[last - step] if last == t - step and 0 <= last - step < len(contours) else None
    return last, [c for c in (before, contours[last]) if c is not None]


def _staged_since(run: _Run, last: int, t: int, step: int) -> np.ndarray:
    """How far the stage moved the field from frame ``last`` to frame ``t``:
    the sum of its shifts onto each frame between (see _stage_shift). An
    object looked for again after a gap moved with every one of them: with
    the last one alone, a nucleus gone out of view on a jittering stage was
    found again on a neighbour (an outside tester, session 73)."""
    return sum((run.stages.get(f, np.zeros(2)) for f in range(last + step, t + step, step)), np.zeros(2))


def _division_before(seen: _Seen, t: int, start: int, step: int) -> int | None:
    """The frame, if any, of a division that ended the object's track before
    frame ``t`` (or on it), going from ``start`` in the direction ``step``: a
    division ends a track from its frame on (see _divisions)."""
    return next((d for d in seen.divided if (t - d) * step >= 0 and (d - start) * step > 0), None)


def _one_object(run: _Run, image, shared, owner, t: int, k: int, step: int, handed=None):
    """Segment object ``k`` on frame ``t`` from where its motion predicts it
    (or from ``handed``, a contour another object found); its contour (or
    None) and status."""
    seen, options = run.seen[k], {**run.options, "contrast": run.seen[k].contrast}
    image, shared = _seen_as(run, k, t, image, shared)
    if t == run.start:
        return _found(image, shared, _others(run, owner, k), t, _Drawing.on(run.inits[k], shared.intensity), None,
                      None, seen, _on_the_start_frame(options))
    last, history = _history(run, k, t, step)
    if last is None:  # lost or out of view for more than MAX_GAP frames: stays so
        return None, run.status[k][t - step]
    look = None
    if handed is None and last == t - step and run.before is not None:
        look = _look_shift(run.before, run.looks, history[-1], around=run.stage)
    looked = [] if look is None else [history[-1] + look]
    stage = _staged_since(run, last, t, step)
    if handed is not None:
        starts = [handed]
    else:
        # Where it was last seen, moved as its own looks moved, if they tell;
        # moved as the stage moved the field, if it did; where its last motion
        # predicts it, moved as the objects done on this frame moved together
        # from theirs, if they did; there; where it was last seen (the motion
        # may overshoot one that stopped or turned back: its drawing then
        # lies mostly on the background).
        predicted = _predicted(history)
        staged = [history[-1] + stage] if stage.any() else []
        starts = looked + staged + [predicted + _common_motion(run.moved), predicted, history[-1]]
    # The last frame's drawing, if it may be carried over (see _carried): not
    # after a gap (the object may be anywhere within reach), nor from the
    # image's side or a margin of no data (as the object moves, the side shows
    # a new part of it, not the same outline moved).
    in_view = last == t - step and not _touches_side(history[-1], image.shape, shared.missing)
    drawing = seen.drawing if in_view else None
    avoid = _others(run, owner, k)
    tried = []
    for start in starts:
        if any(np.allclose(start, other, atol=0.5) for other in tried):
            continue
        tried.append(start)
        by_looks = look is not None and start is starts[0]
        contour, verdict = _found(image, shared, avoid, t, _carried(drawing, history[-1], start, shared.intensity,
                                                                    by_looks), start, history[-1], seen, options,
                                  by_looks)
        if verdict != LOST:
            break
    if verdict == TRACKED and handed is None:
        run.moved.append(area_centroid(contour) - area_centroid(predicted))
    if verdict != TRACKED and last != t - step:
        verdict = run.status[k][last + step]  # not found again: as it went missing
    return contour, verdict


def _on_the_start_frame(options: dict) -> dict:
    """The segment options of the start frame: at least :func:`segment`'s own
    step budget. Its contours start from the user's drawings, as segment()'s
    do, not from the frame before, near the border: a circle about a large,
    faint mesenchymal stem cell of the Cell Tracking Challenge came to rest
    after 333 steps, and with the 300 of a tracked frame the cell was not
    found, nor looked for again."""
    return {**options, "max_steps": max(options["max_steps"], _SEGMENT_MAX_STEPS)}


def _read_by(run: _Run, image: np.ndarray, contrast: str, polarity: str) -> None:
    """What tells each object from its background (see segment's
    ``contrast``), read once from its drawing on the start frame ``image``
    and kept through the movie: an object does not turn from a fluorescent
    body into a textured one between frames."""
    for k, seen in enumerate(run.seen):
        by_texture = contrast == "texture" or (contrast == "auto" and polarity == "auto"
                                               and told_by_texture(image, run.inits[k]))
        seen.contrast = "texture" if by_texture else "intensity"


def _seen_as(run: _Run, k: int, t: int, image, shared):
    """Frame ``t`` (``image``, NaN pixels filled) and its ``shared``
    features as object ``k`` is read on them: for an object told by its
    texture, those of the frame's texture (see :mod:`.texture`), made once
    per frame for all such objects."""
    if run.seen[k].contrast != "texture":
        return image, shared
    if run.textured is None or run.textured[0] != t:
        texture = texture_map(np.where(shared.missing, np.nan, image) if shared.missing is not None else image)
        features = replace(FrameFeatures.of(texture, run.options.get("isef_b", 0.7)), missing=shared.missing)
        run.textured = (t, np.nan_to_num(texture), features)
    return run.textured[1], run.textured[2]


def _common_motion(moved: list) -> np.ndarray:
    """The motion the objects done on a frame share beyond their predictions
    (``moved``: each one's centroid less its predicted centroid), or none
    when fewer than two were found or they did not move together by at
    least a pixel (their median beyond twice their spread about it)."""
    if len(moved) < 2:
        return np.zeros(2)
    moved = np.asarray(moved)
    median = np.median(moved, axis=0)
    spread = np.median(np.hypot(*(moved - median).T))
    size = float(np.hypot(*median))
    return median if size >= 1.0 and size > 2.0 * spread else np.zeros(2)


def _stage_shift(run: _Run, before: np.ndarray, image: np.ndarray, t: int, step: int) -> np.ndarray:
    """The shift of the objects tracked on the frame ``before`` to ``image``
    (frame ``t``), by their looks alone, if they agree on one (see
    _common_motion); else none.

    Each object's patch on the frame before is correlated (normalised) with
    the frame within STAGE_SEARCH median radii of where it was; the sum of
    these maps peaks where the objects' looks moved together (a jittering
    stage), which a neighbour looking alike, or an object that vanished, did
    not. Each object then moves by its own peak near there, if it matches
    well. The motion predicted from the frames before is left out: on a
    jittering stage it adds the last jump to the next.

    A stage that jumps further (a multi-position acquisition that does not
    come back to the same place, a movie not registered) moves the whole
    frame: its shift, read coarsely on the whole frames (see _frame_shift),
    is where the looks are searched too when it lies beyond half that
    reach; the looks must confirm it (the CTC movie on a stage jumping
    +-30 px a frame lost every nucleus at the first jump), and by more
    objects than they confirm a still stage.
    """
    tracked = [k for k in range(len(run.inits)) if run.status[k][t - step] == TRACKED]
    if len(tracked) < 2:
        return np.zeros(2)
    # In the order of their places, not of their listing: the maps' sum must not depend on it.
    last = sorted((run.contours[k][t - step] for k in tracked), key=lambda c: tuple(area_centroid(c)))
    radius = np.median([_radius(c) for c in last])
    reach = int(np.clip(STAGE_SEARCH * radius, 4, 60))
    far, zero = _frame_shift(before, image), np.zeros(2, dtype=int)
    still = _shift_by_looks(before, image, last, reach, zero)
    if still[2] < 2:  # (the searches cross the image's side: a small field) read them where they stay in view
        still = _shift_by_looks(before, image, last, reach, zero, partial=True)
    if np.abs(far).max() > reach / 2:
        # The jump must be confirmed by more objects than the still stage is:
        # alike objects in a row match their neighbours a row's step away.
        jump = _shift_by_looks(before, image, last, reach, far, partial=True)
        if jump[1] > still[1]:
            return jump[0]
    return still[0]


def _shift_by_looks(before, image, contours, reach: int, around: np.ndarray,
                    partial: bool = False) -> tuple[np.ndarray, int, int]:
    """The shift the looks of ``contours`` on the frame ``before`` agree on
    within ``reach`` px of ``around`` on ``image`` (see _stage_shift), or
    none; how many objects' looks confirm it (0 for none); and how many
    were read: those whose search lies wholly in the image or, if
    ``partial``, every one, at the shifts that keep it in view (see
    _full_look_map)."""
    if partial:
        maps = [_full_look_map(before, image, contour, reach, around) for contour in contours]
    else:
        maps = [found[0] for found in (_look_map(before, image, c, reach, around=around) for c in contours)
                if found is not None]
    if len(maps) < 2:
        return np.zeros(2), 0, len(maps)
    with warnings.catch_warnings():  # (shifts no object's patch can take in the image: all NaN)
        warnings.simplefilter("ignore", RuntimeWarning)
        total = np.nansum(maps, axis=0)
    peak = np.array(np.unravel_index(np.argmax(total), total.shape))
    moved, seen = [], 0
    for score in maps:  # each object's own best match within 2 px of the common peak
        near = score[max(peak[0] - 2, 0):peak[0] + 3, max(peak[1] - 2, 0):peak[1] + 3]
        if np.isnan(near).all():
            continue  # out of the view there: it tells nothing
        seen += 1
        best = np.array(np.unravel_index(np.nanargmax(near), near.shape)) + np.maximum(peak - 2, 0)
        if score[tuple(best)] >= STAGE_MATCH:
            moved.append(best - reach + around)
    if 2 * len(moved) <= seen:
        return np.zeros(2), 0, len(maps)
    shift = _common_motion(moved)  # (none where they did not move together: no one confirms a jump then)
    return shift, sum(np.hypot(*(m - shift)) <= AGREED_SHIFT for m in moved), len(maps)


def _full_look_map(before, image, contour, reach: int, around) -> np.ndarray:
    """_look_map's scores of ``contour``'s patch at every shift within
    ``reach`` of ``around``, NaN at the shifts that take it out of the
    image (all of them for a flat patch): near the image's side an
    object's search meets it, and on a small field most of them did, so
    that the stage's jumps went unread (the looks of 2 objects of 6 cannot
    confirm a shift; an outside tester, session 73)."""
    full = np.full((2 * reach + 1, 2 * reach + 1), np.nan, dtype=np.float32)
    found = _look_map(before, image, contour, reach, at_side=True, around=around)
    if found is None:  # (out of the view at every shift, or a flat patch: it confirms nothing)
        return full
    score, first = found
    at = first - (np.asarray(around) - reach)
    full[at[0]:at[0] + score.shape[0], at[1]:at[1] + score.shape[1]] = score
    return full


#: An object's looks confirm the stage's shift when they moved within this
#: many px of it (see _shift_by_looks).
AGREED_SHIFT = 1.5

#: The frames' shift is read on copies binned to at most this many pixels
#: along their longer side (see _frame_shift): a stage's jump moves the whole
#: field, which a few pixels' precision locates for the looks to refine.
FRAME_SHIFT_SIDE = 128


def _frame_shift(before: np.ndarray, image: np.ndarray) -> np.ndarray:
    """How the content of the frame ``before`` moved onto ``image`` as a
    whole (integer px, to the binning's precision): the peak of their phase
    correlation, on copies binned to FRAME_SHIFT_SIDE px (1-2 ms a frame)."""
    factor = max(1, int(np.ceil(max(before.shape) / FRAME_SHIFT_SIDE)))
    size = (max(before.shape[1] // factor, 1), max(before.shape[0] // factor, 1))
    small = [np.nan_to_num(cv2.resize(np.asarray(frame, dtype=np.float64), size, interpolation=cv2.INTER_AREA))
             for frame in (before, image)]
    if not all(np.ptp(frame) > 0 for frame in small):
        # A flat frame (a dropped, blank one) shows no motion; scikit-image
        # would also warn that it cannot measure its error against an empty one.
        return np.zeros(2, int)
    # The shift that registers ``before`` onto ``image`` is how its content moved.
    shift = registration.phase_cross_correlation(small[1], small[0], normalization="phase")[0]
    return (np.round(shift) * factor).astype(int)


def _look_map(before: np.ndarray, image: np.ndarray, contour: np.ndarray, reach: int,
              at_side: bool = False, around=(0, 0)) -> tuple[np.ndarray, np.ndarray] | None:
    """The normalised correlation of ``contour``'s patch on the frame
    ``before`` (its bounding box and 3 px) with ``image`` at every shift of
    up to ``reach`` px from ``around`` (integer px), and the shift of its first value: a
    (2 reach + 1)^2 map from ``around`` - (reach, reach), or, where the search meets
    the image's side, only the shifts that keep the patch in the image, if
    ``at_side`` (else None). None for a flat patch: nothing to match."""
    rows, cols = bounding_window(contour, before.shape, 3.0)
    corner = np.array([rows.start, cols.start])
    lo, hi = corner + around - reach, np.array([rows.stop, cols.stop]) + around + reach
    patch = before[rows, cols].astype(np.float32)
    if patch.std() < 1e-6 * (1 + abs(patch).max()):
        return None
    if np.any(lo < 0) or np.any(hi > image.shape):
        if not at_side:
            return None
        lo, hi = np.maximum(lo, 0), np.minimum(hi, image.shape)
        if np.any(hi - lo < patch.shape):  # no shift searched keeps the patch in the image
            return None
    region = image[lo[0]:hi[0], lo[1]:hi[1]].astype(np.float32)
    return np.nan_to_num(cv2.matchTemplate(region, patch, cv2.TM_CCOEFF_NORMED)), lo - corner


def _look_shift(before: np.ndarray, image: np.ndarray, contour: np.ndarray, around=(0, 0)) -> np.ndarray | None:
    """How the object of ``contour`` on the frame ``before`` moved onto
    ``image`` by its appearance: the best match of its patch (see _look_map)
    within LOOK_SEARCH radii of ``around`` (the stage's shift: an object's
    own motion adds to it), to a fraction of a pixel; None where it cannot
    be told (a flat patch, a best match under LOOK_MATCH, or on the edge of
    the search within the image: it moved further).

    Its contour's motion cannot tell it: where the object's border is
    unclear (a neighbour in broad contact), that contour is partly where
    its drawing limited it, and the drawing drawn around it again let it
    take a band of the neighbour each frame (see _carried).
    """
    reach, around = int(np.clip(LOOK_SEARCH * _radius(contour), 4, 30)), np.rint(around).astype(int)
    found = _look_map(before, image, contour, reach, at_side=True, around=around)
    if found is None:
        return None
    score, first = found
    peak = np.unravel_index(np.argmax(score), score.shape)
    shift = np.array(peak) + first
    if score[peak] < LOOK_MATCH or np.abs(shift - around).max() >= reach:
        return None
    offset = np.zeros(2)
    for axis in range(2):  # the vertex of the parabola through the peak and its two neighbours
        if 0 < peak[axis] < score.shape[axis] - 1:
            step = np.eye(2, dtype=int)[axis]
            a, b, c = score[tuple(peak - step)], score[peak], score[tuple(peak + step)]
            curvature = a - 2 * b + c
            offset[axis] = 0.5 * (a - c) / curvature if curvature < 0 else 0.0
    return shift + np.clip(offset, -0.5, 0.5)


def _segmenting_order(run: _Run, t: int, step: int) -> list[int]:
    """The order in which the objects are segmented on frame ``t``: the
    smaller drawings first, on every frame, whatever order they were listed
    in; after the start frame, those tracked on the frame before ahead of
    those looked for again after a gap (see MAX_GAP).

    Where objects' pixels are contested, the object done first has them, so
    the order must not be the listing's: the warped Data Science Bowl movies
    of benchmarks/tracking_warped.py lost 173 visible nucleus-frames with
    their drawings listed one way and 119 the other way round. A tight
    drawing says more about where its object is than a generous one that
    passes over it, and a band that the object done first takes from a
    touching neighbour is a smaller share of a large neighbour than of a
    small one. The order stays that of the start frame: ordered on each frame
    by the contours' areas on the frame before instead, a dim nucleus of a
    clump (label 169) was lost from the fifth of the identical frames of the
    Data Science Bowl movie. Where one looked for again after a gap went
    while it was not seen is not known: it must not take part of a neighbour
    that moved next to where it was before that neighbour is done.
    """
    drawn = [abs(signed_area(init)) for init in run.inits]
    if t == run.start:
        return sorted(range(len(run.inits)), key=lambda k: drawn[k])
    return sorted(range(len(run.inits)), key=lambda k: (run.status[k][t - step] != TRACKED, drawn[k]))


def _give_back(run: _Run, image, shared, owner, t: int, j: int, step: int, others) -> None:
    """Object ``j`` on frame ``t`` (not found there, or see _astray): if an object ``i`` of
    ``others`` took pixels where ``j`` was looked for, segment the two again,
    ``j`` first (from its prediction, else from what ``i`` found), and keep
    whichever outcome fits their motion better (see _misfit).

    Objects are segmented one after the other, each counting the others'
    pixels as background: a vanished object's drawing takes the part of a
    neighbour that moved toward its place, or the whole of one that darted
    there, and the neighbour, whose pixels are then another's, is lost; or
    an object that jumped further than it can be followed is lost first,
    and one done after it takes its place.
    """
    if not others:
        return
    last, history = _history(run, j, t, step)
    if last is None:
        return
    looked_at = _drawing_around(history[-1] + _staged_since(run, last, t, step))
    least = SUSPECT_SHARE * abs(signed_area(history[-1]))
    moved = list(run.moved)  # the frame's common motion is read off first looks only
    for i in others:
        if run.status[i][t] != TRACKED or _shared_area(run.contours[i][t], looked_at, image.shape) < least:
            continue
        kept = [(run.contours[o][t], run.status[o][t], run.seen[o].copy()) for o in (i, j)]
        misfit = _misfit(run, i, t, step) + _misfit(run, j, t, step)
        for handed in (None, kept[0][0]):
            trial = owner.copy()
            _unpainted(run, trial, i)
            if handed is None:  # as if i came after j: its pixels those of the frame before
                _paint(run, trial, _claim_before(run, i, t, step), i, only_free=True)
            _settle(run, image, shared, trial, t, j, step, handed)
            _settle(run, image, shared, trial, t, i, step)
            run.moved = list(moved)
            # A j found before stays found: an astray i is no reason to lose it.
            j_kept = run.status[j][t] == TRACKED or kept[1][1] != TRACKED
            if j_kept and _misfit(run, i, t, step) + _misfit(run, j, t, step) < misfit:
                owner[...] = trial
                return
            for o, (contour, status, seen) in zip((i, j), kept):
                run.contours[o][t], run.status[o][t], run.seen[o] = contour, status, seen.copy()


def _astray(run: _Run, t: int, step: int, order: list[int]) -> list[int]:
    """The objects whose outcome on frame ``t`` fits what was known of them
    worse than losing them would (see _misfit): a vanished object's contour
    drawn onto part of a neighbour that moved next to where it was, the
    neighbour keeping the rest. In the frame's segmenting ``order``."""
    return [i for i in order if run.status[i][t] == TRACKED and _misfit(run, i, t, step) > LOST_MISFIT]


def _misfit(run: _Run, k: int, t: int, step: int) -> float:
    """How badly object ``k``'s outcome on frame ``t`` fits what was known of
    it: LOST_MISFIT if it is not tracked, else its centroid's distance from
    where it was predicted or last seen, or where the stage's shifts since
    moved it (see _staged_since), in radii of the last contour, plus the log
    of its change of area."""
    if run.status[k][t] != TRACKED:
        return LOST_MISFIT
    seen_on, history = _history(run, k, t, step)
    contour, last = run.contours[k][t], history[-1]
    centre, stage = area_centroid(contour), _staged_since(run, seen_on, t, step)
    where = [area_centroid(last) + stage, area_centroid(_predicted(history)), area_centroid(last)]
    distance = min(np.hypot(*(centre - w)) for w in where) / _radius(last)
    return float(distance + abs(np.log(abs(signed_area(contour)) / abs(signed_area(last)))))


def _found(image, shared, avoid, t, drawing: _Drawing, predicted, previous, seen: _Seen, options,
           by_looks: bool = False):
    """An object segmented on frame ``t`` in ``drawing``, out of the other
    objects' pixels ``avoid`` (``previous``: its last contour, None on the
    start frame, where ``seen`` is filled in; ``by_looks``: see _redrawn);
    its contour (or None) and status."""
    segment_here = partial(_segment_from, image, features=shared, avoid=avoid if avoid.any() else None,
                           polarity=seen.polarity, max_area=_largest_kept(previous, seen, image.shape, shared.missing),
                           **options)
    try:
        with warnings.catch_warnings():
            # A drawing (or a predicted contour) partly beyond the image is
            # expected of an object at its side; segment's warning would not
            # even say which object or frame.
            warnings.filterwarnings("ignore", message=".*lie outside the image", category=UserWarning)
            if previous is None:
                res = segment_here(drawing.line, predicted)
            else:
                res, drawing = _redrawn(segment_here, drawing, predicted, shared.intensity, by_looks)
    except (ValueError, DivergenceError):
        # Not found: gone from the view if it was at the image's side (where
        # it was to start from; its drawing, moved with it, may reach beyond
        # the side while the object lies wholly inside).
        if previous is not None and _touches_side(predicted, image.shape, shared.missing):
            return None, LEFT
        seen.why[t] = "no object where it was looked for (the contour collapsed, or could not be followed)"
        return None, LOST
    # The drawing on the start frame is the user's: what it holds of an object
    # it cuts off (a touching neighbour's blob) is the object to follow.
    if not (res.converged or (previous is None and res.stop_reason == "limited")):
        seen.why[t] = f"the contour did not come to rest on a border there ({res.stop_reason})"
        return None, LOST
    contour = positively_oriented(res.contour)
    if previous is None:
        seen.polarity = "bright" if res.polarity > 0 else "dark"
        seen.whole_area = abs(signed_area(contour))
        seen.seen_whole = not _touches_side(contour, image.shape, shared.missing)
        seen.contrasts[t] = _contrast(image, contour, res.polarity, avoid)
        seen.signal = seen.contrasts[t] * seen.whole_area
        seen.drawing = drawing  # the next frames start from it (see _carried)
        return contour, TRACKED
    contrast, area = _contrast(image, contour, res.polarity, avoid), abs(signed_area(contour))
    signal = contrast * area
    condensed = signal >= seen.signal / MAX_AREA_CHANGE
    verdict, seen.why[t] = _judge(contour, previous, predicted, seen.whole_area, image.shape, shared.missing,
                                  seen.seen_whole, condensed,
                                  spread=condensed and seen.signal > 0 and signal <= SPREAD_SIGNAL * seen.signal)
    if verdict == LOST:
        # Pinched in two on its way (a division, or a neighbour it took in
        # let go), it kept one body: see _warn_divided.
        parted = next((bodies for bodies in map(pinched_bodies, res.history) if bodies is not None), None)
        if parted is not None:
            seen.parted[t] = parted
    # Faded: what is left is the out-of-focus glow of an object that left
    # the focal plane, or the halo of a neighbour.
    if verdict == TRACKED and seen.faded(contrast, t):
        verdict = LOST
        seen.fades.add(t)
        seen.why[t] = (f"it faded, its contrast below {FADED_CONTRAST:g} of its best within {FADE_WINDOW} frames "
                       "(it left the focal plane or bleached, or what is left is a neighbour's halo)")
    if verdict == TRACKED and np.isfinite(contrast):
        seen.contrasts[t], seen.signal = contrast, contrast * area
    if verdict == TRACKED:
        seen.drawing = drawing
    if verdict == TRACKED and not _touches_side(contour, image.shape, shared.missing):
        seen.whole_area, seen.seen_whole = area, True
    return (contour if verdict == TRACKED else None), verdict


#: A tracked frame's segmentation stops (``leaked``) once its contour
#: encloses this many times the object's last area (its whole area, where
#: the image's side cuts it): it spread over the ground, and would crawl on
#: to max_steps (a phase-contrast cell 5 px across, through five
#: segmentations of a frame, 300 steps each: 2.4 s). Not sooner: a contour
#: that spread up to 8 times (HeLa nuclei read every 3rd frame, 2451 and
#: 3498 px² from 422) and rested against its drawing came back to the
#: nucleus when drawn around again (see _redrawn); stopped at 6 times, one
#: was found worse elsewhere and one lost.
LEAK_AREA_FACTOR = 25.0


def _largest_kept(previous, seen: _Seen, shape, missing) -> float | None:
    """The area beyond which a tracked frame's segmentation of an object last
    seen as ``previous`` has leaked (see LEAK_AREA_FACTOR); None on the start
    frame, or where the image's side hid an object never seen whole."""
    if previous is None:
        return None
    area = abs(signed_area(previous))
    if not _touches_side(previous, shape, missing):
        return LEAK_AREA_FACTOR * area
    return LEAK_AREA_FACTOR * max(seen.whole_area, area) if seen.seen_whole else None


def _back_in_view(run: _Run, k: int, t: int, step: int) -> int | None:
    """The frame object ``k`` was last seen on before it left the field of
    view, when the stage's shifts since (see _staged_since) bring its place
    back into view on frame ``t``, 1 - LEFT_FRACTION of its area or more
    within the image; else None.

    Out of view for longer than MAX_GAP frames, an object is no longer
    looked for: nothing says where it went. But when the stage moved the
    field, the object moved with it, and it is looked for where the stage
    brought it, however long it was out (on a stage jittering by +-20 px
    over a field of nuclei, 12 nucleus-frames back in view were said to
    have left it; an outside tester, session 73). An object that crawled
    out of a still field is not looked for again."""
    status = run.status[k]
    last = t - step
    while 0 <= last < len(status) and status[last] == LEFT:
        last -= step
    if not 0 <= last < len(status) or status[last] != TRACKED or last == t - step:
        return None
    shift = _staged_since(run, last, t, step)
    if not shift.any():
        return None
    moved, shape = run.contours[k][last] + shift, np.array(run.looks.shape)
    in_view = np.clip(moved, 0, shape - 1)  # (its part beyond a side laid on that side)
    if abs(signed_area(in_view)) < (1 - LEFT_FRACTION) * abs(signed_area(moved)):
        return None
    return last


def _last_seen(status: list, t: int, step: int) -> int | None:
    """The last frame before ``t`` (in the direction ``step``) where the object
    was tracked, if it has been lost or out of view since for at most MAX_GAP
    frames; else None."""
    for gap in range(MAX_GAP + 1):
        before = t - (gap + 1) * step
        if not 0 <= before < len(status) or status[before] is None:
            return None
        if status[before] == TRACKED:
            return before
    return None


def _contrast(image: np.ndarray, contour: np.ndarray, polarity: int, avoid: np.ndarray) -> float:
    """The object's contrast: the median intensity inside ``contour`` less that
    of a ring 2-4 px outside it (others' pixels, ``avoid``, left out), signed
    by ``polarity``; NaN when either is empty."""
    box = bounding_window(contour, image.shape, 6.0)
    inside = window_mask(contour, box)
    if inside is None or not inside.any():
        return np.nan
    inside = inside.astype(np.uint8)
    ring = cv2.dilate(inside, np.ones((9, 9), np.uint8)) > cv2.dilate(inside, np.ones((3, 3), np.uint8))
    ring &= ~avoid[box]
    if not ring.any():
        return np.nan
    return float(polarity * (np.median(image[box][inside.view(bool)]) - np.median(image[box][ring])))


def _correspondences(contours, start, match_options) -> dict:
    """Origins, normal velocities, curvature and carried arc positions."""
    n_obj, n_frames = len(contours), len(contours[0])
    names = ("origin", "normal_velocity", "curvature", "arc")
    out = {name: [[None] * n_frames for _ in range(n_obj)] for name in names}
    for k in range(n_obj):
        for t in range(n_frames):
            c = contours[k][t]
            if c is None:
                continue
            out["curvature"][k][t] = curvature(c)
            prev = contours[k][t - 1] if t > 0 else None
            if prev is None:
                out["origin"][k][t] = np.full(c.shape, np.nan)
                out["normal_velocity"][k][t] = np.full(len(c), np.nan)
                continue
            origin = node_origins(c, prev, **match_options)
            out["origin"][k][t] = origin
            out["normal_velocity"][k][t] = ((c - origin) * outward_normals(c)).sum(1)
        _carry_arc_origin(contours[k], out["origin"][k], out["arc"][k], start)
    return out


def node_origins(contour: np.ndarray, previous: np.ndarray, **match_options) -> np.ndarray:
    """Where each node of ``contour`` came from on ``previous``.

    The rigid part of the motion (see _body_motion: the outline fit's
    rotation, the area centroid's translation) is found first and undone; then the
    nodes are matched by the order-preserving modal matching (every node of
    ``contour`` gets a partner), with a cost on their remaining
    displacement, as the two contours share a frame of reference. Each
    origin is the point of ``previous``, next to the partner, closest to
    where the rigid motion puts the node back: so a turning cell's nodes
    keep their place along its membrane, and the normal displacement is not
    rounded to the node spacing.
    """
    rotation, shift = _body_motion(contour, previous)
    back = contour @ rotation.T + shift
    # One start region is enough between frames (the displacement term
    # already says where the path starts), and a 32-node element for the
    # modes: between consecutive frames the displacement term decides the
    # fine detail (on the deforming cell both left the errors unchanged and
    # the matching ~30 % faster). No search of the modes' signs: with the
    # rigid motion undone the two shapes share their frame, and their
    # canonical signs agree (errors unchanged, 10 % faster). No refinement
    # pass and no curvature term: the displacement term already keeps the
    # path locally uniform and on its features (together they changed 2 in
    # 1,000 normal velocities of the CTC movie and none of the deforming
    # cell's, and took a third of the matching time).
    options = {"displacement_weight": DISPLACEMENT_WEIGHT, "n_starts": 1, "model_nodes": 32, "context_weight": 0.0,
               "sign_correction": False, "refine": False, "curvature_weight": 0.0,
               **match_options}
    pairs = _match_pairs(back, previous, method="order", **options)
    partner = np.full(len(contour), -1)
    partner[pairs[:, 0]] = pairs[:, 1]
    missing = partner < 0
    if missing.any():  # not expected with method="order": nearest node instead
        partner[missing] = nearest_node(back[missing], previous)
    # On the smooth curve through previous's nodes, not on its edges: on a
    # convex contour those lie inside the curve, and normal velocities came
    # out too far outward (a still circle, its nodes moved along by half a
    # spacing: +0.09 px/frame; the deforming cell's mean +0.010 -> +0.003).
    curve = through_nodes(previous, ORIGIN_SAMPLES)
    steps = np.arange(-2 * ORIGIN_SAMPLES, ORIGIN_SAMPLES)
    return closest_on_polyline(back, curve, partner * ORIGIN_SAMPLES, steps=steps)[0]


def _body_motion(contour: np.ndarray, previous: np.ndarray):
    """Rotation ``R`` and shift ``T`` that carry the body of ``contour`` back
    onto that of ``previous`` (``contour @ R.T + T``): the rotation of the
    outline fit (_rigid_motion), about the area centroids, and the shift that
    puts the area centroid back on the previous one.

    Why not the outline fit's own shift: a local protrusion moves the fit
    and the centroid alike (within 3 %), but deformations spread around an
    elongated body (waves of order 3 and 5) pull the fit 1.4 and 2.2 times
    as far as the centroid; while the shape changes one way that error has
    one sign frame after frame, and every origin slides along the membrane
    with it. On the synthetic deforming cell's true outlines (12 seeds,
    30 frames) points followed through the origins ended 0.34 node spacings
    from their material points in the median (0.71 at the worst, in the
    mean) with the fit's shift, 0.24 (0.63) with the centroid's, 0.16 (0.49)
    with the material points' own rigid motion. The rest is the rotation:
    waves of even order turn an elongated outline's fit as they turn its
    principal axes (those by 0.8 times as much for waves, 1.1 times for
    local bumps), so neither was kept for the other.
    """
    rotation, _ = _rigid_motion(contour, previous)
    return rotation, area_centroid(previous) - area_centroid(contour) @ rotation.T


#: Points per edge of the curve the origins lie on (see node_origins).
ORIGIN_SAMPLES = 4

#: The least weight the angle gets in each step of _rigid_motion, as a share
#: of the most a rotation can move the nodes across the curve (their arms
#: squared): a step turns the body only as far as the fit's gain over that
#: weight. A disk fits at every angle and an ellipse at every half turn:
#: undamped, steps driven by the nodes' noise turned a growing disk by up to
#: 125 degrees between frames (normal velocities of 19 px/frame for 1). A
#: well-defined turn is still found in full, in a few more steps (the
#: deforming cell's drift and normal-velocity errors unchanged, 8 seeds;
#: added to the weight rather than a floor, it took 1.4 times the steps).
ROTATION_DAMPING = 0.2


def _rigid_motion(source: np.ndarray, target: np.ndarray, iterations: int = 30):
    """Rotation ``R`` and shift ``T`` with ``source @ R.T + T`` closest to the
    curve ``target``: iterative closest points, point to line.

    Each node is drawn to the tangent line at its closest point of the target
    (Chen & Medioni's point-to-plane ICP), not to that point: a node may slide
    along the curve at no cost, so a turning outline's rotation is found in
    full (point to point, the closest points of a sampled curve hold the nodes
    back: it found 0.26 of the deforming cell's 0.40 degrees per frame).
    """
    dense = resample(target, spacing=0.5)
    normals = outward_normals(dense)  # their sign does not matter: it cancels in each row of the fit
    tree = cKDTree(dense)
    centre = source.mean(0)
    angle, shift = 0.0, dense.mean(0) - centre
    extent = float(np.abs(source - centre).max())
    for _ in range(iterations):
        rotation = rotation_matrix(angle)
        moved = (source - centre) @ rotation.T + centre + shift
        nearest = tree.query(moved)[1]
        n = normals[nearest]
        arm = moved - centre - shift
        # Linearised in the angle: a node moves by angle * (-arm_y, arm_x).
        jacobian = np.column_stack([arm[:, 0] * n[:, 1] - arm[:, 1] * n[:, 0], n])
        residual = ((dense[nearest] - moved) * n).sum(1)
        normal = jacobian.T @ jacobian
        normal[0, 0] = max(normal[0, 0], ROTATION_DAMPING * (arm ** 2).sum())
        try:  # the normal equations of a 3-parameter fit (lstsq's SVD costs more than the rest of the loop)
            update = np.linalg.solve(normal, jacobian.T @ residual)
        except np.linalg.LinAlgError:  # normals all parallel: the angle is not determined
            update = np.linalg.lstsq(jacobian, residual, rcond=None)[0]
        angle, shift = angle + update[0], shift + update[1:]
        # A thousandth of a pixel over the contour's extent: far below its node spacing.
        if abs(update[0]) * extent < 1e-3 and np.abs(update[1:]).max() < 1e-3:
            break
    rotation = rotation_matrix(angle)
    return rotation, centre + shift - centre @ rotation.T


def curvature(contour: np.ndarray) -> np.ndarray:
    """Signed curvature at each node (1/px), > 0 where a positively oriented
    contour is convex: the turn of the contour over the node and its two
    neighbours, over the arc from the middle of the edge before them to the
    middle of the edge after.

    Over three nodes, not one: the turn at one node is the difference of two
    edges' directions, each a few tenths of a pixel off on a pixelated border,
    over one edge's length; the turns of the middle edges cancel in the sum.
    (On tracked ellipses with a hard edge the error fell from 0.14 to 0.04
    1/px, about a tenth of their curvature; on the synthetic deforming
    cell's from 0.006 to 0.004, where five nodes smoothed its waves.)"""
    before = contour - np.roll(contour, 1, axis=0)
    after = np.roll(contour, -1, axis=0) - contour
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    turn = np.arctan2(cross, (before * after).sum(1))
    edge = np.hypot(*after.T)  # edge i runs from node i to node i + 1
    turns = np.roll(turn, 1) + turn + np.roll(turn, -1)
    arc = np.roll(edge, 1) + edge + 0.5 * (np.roll(edge, 2) + np.roll(edge, -1))
    sign = 1.0 if signed_area(contour) > 0 else -1.0
    return sign * turns / np.maximum(arc, 1e-12)


def _carry_arc_origin(contours, origins, arcs, start) -> None:
    """Arc positions from an origin point that follows the correspondences:
    node 0 on the start frame, then frame to frame in both directions."""
    n = len(contours)
    if contours[start] is None:
        return
    anchor = {start: contours[start][0]}
    last = anchor[start]
    for t in range(start + 1, n):  # forward: the node whose origin is nearest the last anchor
        if contours[t] is None:
            continue
        if t - 1 in anchor and np.isfinite(origins[t]).all():
            last = contours[t][nearest_node(anchor[t - 1][None], origins[t])[0]]
        else:  # after a gap: the node nearest where the anchor was last seen
            last = contours[t][nearest_node(last[None], contours[t])[0]]
        anchor[t] = last
    last = anchor[start]
    for t in range(start - 1, -1, -1):  # backward: the origin of the node nearest the anchor after
        if contours[t] is None:
            continue
        if t + 1 in anchor and np.isfinite(origins[t + 1]).all():
            last = origins[t + 1][nearest_node(anchor[t + 1][None], contours[t + 1])[0]]
        else:
            last = contours[t][nearest_node(last[None], contours[t])[0]]
        anchor[t] = last
    for t, point in anchor.items():
        arcs[t] = _arc_from(contours[t], point)


def _arc_from(contour: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Arc position of each node in [0, 1), counted from the node nearest ``point``."""
    first = int(np.argmin(((contour - point) ** 2).sum(1)))
    seg = np.hypot(*(np.roll(contour, -1, axis=0) - contour).T)
    s = np.concatenate([[0.0], np.cumsum(seg)[:-1]])
    return ((s - s[first]) / max(perimeter(contour), 1e-12)) % 1.0


def track(frames, inits, *, start: int = 0, max_steps: int = 300, segment_options: dict | None = None,
          match_options: dict | None = None, callback=None) -> TrackingResult:
    """Follow objects through a time-lapse with physical contours.

    Parameters
    ----------
    frames : (T, H, W) array_like
        The movie: a numpy array, or a lazy dask or zarr array read one frame
        at a time. NaN pixels hold no data (see :func:`segment`).
    inits : (N, 2) array_like or sequence of them
        One contour per object, drawn on frame ``start`` (around or inside the
        object, as for :func:`segment`; one point is a click there).
    start : int, optional
        The frame the contours were drawn on; tracking runs forward from it
        to the last frame, then backward from it to the first.
    max_steps : int, optional
        Time steps per object and frame (each frame starts from the previous
        result, so a few dozen are usually enough); on the start frame, at
        least :func:`segment`'s own default (it starts from the drawings).
    segment_options : dict, optional
        Further options of :func:`segment` (material, stiffness, ...).
    match_options : dict, optional
        Options of :func:`match` for the node correspondences between frames.
    callback : callable, optional
        ``callback(progress)`` with a :class:`TrackingProgress` after each
        object and frame; return ``False`` to stop (what was done is kept).

    Returns
    -------
    TrackingResult

    Raises
    ------
    ValueError
        For frames that are not a (T, H, W) stack, no or bad contours, a
        start frame outside the movie or a bad ``segment_options`` value
        (before any frame is read); for a frame with infinite pixels (when it
        is read). NaN pixels hold no data (the margin a registration leaves):
        the contours keep out of them, an object that goes into them has left
        the field of view, and ``warnings`` says which frames held some.
    TypeError
        For an option :func:`segment` does not have in ``segment_options``.

    Examples
    --------
    >>> from napari_physeg import data
    >>> movie = data.deforming_cell(n_frames=5)
    >>> tr = track(movie.frames, movie.init)
    >>> tr.status[0]
    ['tracked', 'tracked', 'tracked', 'tracked', 'tracked']
    """
    check_callback(callback)
    run = iter_track(frames, inits, start=start, max_steps=max_steps, segment_options=segment_options,
                     match_options=match_options)
    return drain(run, callback)

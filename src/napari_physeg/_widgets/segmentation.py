"""The segmentation widget: a thin napari front end to :func:`napari_physeg.core.segment`.

Three parts, from the least to the most napari-specific:

* :func:`segment_contours` - a plain generator that segments a list of
  initial contours on a 2D image with the core, yielding
  :class:`SegmentationProgress` (the evolving contour, for a live preview) and
  returning a :class:`SegmentationOutcome`.  It knows nothing about napari or
  Qt; :func:`run_to_completion` drives it synchronously in scripts and tests.
* :func:`prepare_segmentation` - reads an Image and a Shapes layer at the
  viewer's current slice into a :class:`SegmentationJob` (numpy arrays in the
  image's data coordinates), raising :class:`InputError` with a message that
  says how to fix bad input; :func:`result_layer_data` turns an outcome back
  into napari layer data tuples in the image's data coordinates.
* :class:`SegmentationWidget` - a magicgui ``Container`` (a
  :class:`~napari_physeg._widgets._worker.WorkerWidget`) with the parameters,
  a Run and a Cancel button; Run starts :func:`segment_contours` in a
  ``napari.qt.threading.thread_worker`` with a napari progress bar and a live
  preview Shapes layer, so the GUI never freezes.

All physics lives in :mod:`napari_physeg.core`.
"""

import threading
import time
from dataclasses import dataclass, field

import napari
import numpy as np
from magicgui.widgets import (
    CheckBox,
    ComboBox,
    FloatSpinBox,
    Label,
    PushButton,
    SpinBox,
)
from napari.layers import Image, Layer, Points, Shapes
from napari.utils.notifications import show_info, show_warning

from ..core import DivergenceError, iter_segment, segment
from ..core.forces import DEFAULT_WEIGHTS
from ..core.materials import suggested_stiffness
from ._inputs import (
    PREVIEW_COLOR,
    PHYSICS_TIPS,
    PREVIEW_KEY,
    InputError,
    PhysicsControls,
    check_plane_view,
    contour_layer_choices,
    contrast_box,
    core_default,
    image_layer_choices,
    in_widget_terms,
    node_count,
    nothing_drawn,
    off_image,
)
from ._layers import (
    contours_to_labels,
    contours_to_shapes_data,
    PointsAsClicks,
    image_transform_kwargs,
    shapes_to_image_coords,
    slice_index,
)
from ._worker import WorkerWidget, relay, run_to_completion

__all__ = [
    "InputError",
    "SegmentationJob",
    "SegmentationOutcome",
    "SegmentationProgress",
    "SegmentationWidget",
    "prepare_segmentation",
    "result_layer_data",
    "run_to_completion",
    "segment_contours",
    "segment_kwargs",
]

#: Choices of the RGB channel selector.
RGB_CHOOSE = "(choose a channel)"
RGB_CHANNELS = {"grey (luminance)": None, "red": 0, "green": 1, "blue": 2}


# --------------------------------------------------------------------------
# The worker: a plain generator over the core
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class SegmentationProgress:
    """What :func:`segment_contours` yields.

    Attributes
    ----------
    index : int
        Which contour (0-based) is being segmented.
    total : int
        How many contours the run segments.
    step : int
        Time steps taken so far on this contour.
    max_steps : int
        The step budget of this contour.
    contour : (M, 2) float64 ndarray
        Its current nodes ``(row, col)``, image data coordinates of the slice.
    done : bool
        True for the last update of this contour (``contour`` is its result).
    """

    index: int
    total: int
    step: int
    max_steps: int
    contour: np.ndarray
    done: bool = False


@dataclass(frozen=True)
class SegmentationOutcome:
    """What :func:`segment_contours` returns.

    Attributes
    ----------
    results : list of SegmentationResult
        One per contour segmented (fewer when cancelled or some failed).
    cancelled : bool
        The run was stopped by the cancel event.
    error : Exception or None
        The first error, if a contour failed (the others were still run).
    error_index : int or None
        The contour it happened on.
    seconds : float
        Wall time of the run.
    indices : list of int
        Which contour (position in the run) each result is; default
        ``0, 1, ...``.
    failures : list of (int, Exception)
        Every contour that failed, and why.
    """

    results: list
    cancelled: bool = False
    error: Exception | None = None
    error_index: int | None = None
    seconds: float = 0.0
    indices: list = field(default_factory=list)
    failures: list = field(default_factory=list)

    def __post_init__(self):
        if not self.indices:
            self.indices.extend(range(len(self.results)))

    @property
    def ok(self) -> bool:
        return self.error is None and not self.cancelled


def segment_contours(image, contours, kwargs_list, *, cancel: threading.Event | None = None,
                     preview_interval: float = 0.05):
    """Segment each initial contour on a 2D image; a generator for a worker thread.

    The core's :func:`~napari_physeg.core.iter_segment` runs right here, in
    the worker's thread: no helper thread, no queue. Of its steps, at most one
    every ``preview_interval`` seconds is yielded (so the GUI draws previews
    at the pace it can), and once ``cancel`` is set the core is told to stop
    after its current step.

    Parameters
    ----------
    image : (H, W) ndarray
        The 2D image.
    contours : sequence of (N, 2) ndarray
        Initial contours ``(row, col)`` in the image's pixel coordinates.
    kwargs_list : sequence of dict
        Keyword arguments of :func:`segment` for each contour (see
        :func:`segment_kwargs`).
    cancel : threading.Event, optional
        Set it to stop: the current contour stops at its next step and no
        further contour is started.
    preview_interval : float, optional
        Least time (s) between two yielded updates of one contour.

    Yields
    ------
    SegmentationProgress

    Returns
    -------
    SegmentationOutcome
        As the generator's return value (``StopIteration.value``; a worker's
        ``returned`` signal). Errors of the core (``ValueError``,
        ``DivergenceError``) are caught and returned in it, not raised.
    """
    cancel = cancel if cancel is not None else threading.Event()
    t0 = time.perf_counter()
    total = len(contours)
    results, indices, failures = [], [], []

    def outcome(cancelled=False):
        first = failures[0] if failures else (None, None)
        return SegmentationOutcome(results, cancelled=cancelled, error=first[1], error_index=first[0],
                                   seconds=time.perf_counter() - t0, indices=indices, failures=failures)

    try:
        for i, (init, kwargs) in enumerate(zip(contours, kwargs_list)):
            if cancel.is_set():
                return outcome(cancelled=True)
            max_steps = int(kwargs.get("max_steps", 1000))
            try:
                result = yield from relay(
                    iter_segment(image, init, **kwargs), cancel, preview_interval,
                    wrap=lambda state, i=i: SegmentationProgress(i, total, state.step, max_steps, state.contour))
            except Exception as err:  # this contour failed: say why, go on with the others
                failures.append((i, err))
                continue
            if result.stop_reason == "cancelled":
                return outcome(cancelled=True)
            results.append(result)
            indices.append(i)
            yield SegmentationProgress(i, total, max_steps, max_steps, result.contour, done=True)
    except GeneratorExit:  # closed early: napari aborted the worker
        cancel.set()
        raise
    return outcome()


# --------------------------------------------------------------------------
# Layers <-> job
# --------------------------------------------------------------------------


def segment_kwargs(contour, *, material=core_default(segment, "material"),
                   stiffness=None, node_spacing=None, n_nodes=None,
                   sigma_factor=core_default(segment, "sigma_factor"), weights=None,
                   polarity=core_default(segment, "polarity"), contrast=core_default(segment, "contrast"),
                   max_steps=core_default(segment, "max_steps")) -> dict:
    """Keyword arguments of :func:`segment` for one initial contour.

    ``node_spacing`` (px) is turned into a node count for this contour's
    perimeter; ``n_nodes`` is used as is; with neither, the core's default.
    Force weights of 0 leave that force out; with none given, the core's.
    """
    weights = dict(weights) if weights is not None else dict(DEFAULT_WEIGHTS)
    forces = tuple(name for name, w in weights.items() if w > 0)
    if not forces:
        raise InputError("every force weight is 0: give at least one force (edges, intensity or distance) "
                         "a positive weight, e.g. 0.4 / 0.3 / 0.3")
    return {
        "material": material,
        "stiffness": None if stiffness is None else float(stiffness),
        "n_nodes": node_count(contour, node_spacing, n_nodes),
        "sigma_factor": float(sigma_factor),
        "forces": forces,
        "weights": {name: float(weights[name]) for name in forces},
        "polarity": polarity,
        "contrast": contrast,
        "max_steps": int(max_steps),
    }


@dataclass
class SegmentationJob:
    """Everything a run needs, read from the layers in the GUI thread.

    Attributes
    ----------
    image : (H, W) ndarray
        The 2D slice to segment.
    contours : list of (N, 2) float64 ndarray
        Initial contours in its pixel coordinates (clipped to it).
    shape_indices : list of int
        Index of each contour's shape in the Shapes layer.
    leading : tuple of int
        Leading (non-spatial) data coordinates of the slice, ``()`` for 2D.
    image_shape : tuple of int
        Spatial shape of the whole image layer (without an RGB axis).
    transform : dict
        The image layer's transform, for the output layers.
    image_name, shapes_name : str
    warnings : list of str
        Things the user should know (e.g. clipped nodes).
    """

    image: np.ndarray
    contours: list
    shape_indices: list
    leading: tuple
    image_shape: tuple
    transform: dict
    image_name: str
    shapes_name: str
    warnings: list = field(default_factory=list)


def _plane_2d(image_layer, leading, channel: str | None) -> np.ndarray:
    """The 2D plane of ``image_layer`` at ``leading``, as a real float array."""
    data = image_layer.data[0] if image_layer.multiscale else image_layer.data
    if image_layer.rgb:
        if channel is None or channel == RGB_CHOOSE or channel not in RGB_CHANNELS:
            raise InputError(
                f"{image_layer.name!r} is an RGB image: choose which channel to segment in 'RGB channel' "
                "(red, green, blue, or grey for the luminance), or split it into channels "
                "(layer list: right click > Split RGB)"
            )
        plane = np.asarray(data[tuple(leading)])
        k = RGB_CHANNELS[channel]
        if k is None:
            from skimage.color import rgb2gray

            rgb = plane[..., :3]
            if np.issubdtype(rgb.dtype, np.integer):
                rgb = rgb.astype(np.float64) / np.iinfo(rgb.dtype).max
            return rgb2gray(rgb.astype(np.float64))
        return np.asarray(plane[..., k], dtype=np.float64)
    plane = np.asarray(data[tuple(leading)])
    if plane.dtype == bool:
        plane = plane.astype(np.float32)
    if not (np.issubdtype(plane.dtype, np.integer) or np.issubdtype(plane.dtype, np.floating)):
        raise InputError(f"{image_layer.name!r} has pixels of type {plane.dtype}: the segmentation needs a "
                         "real-valued grey-level image")
    return plane


def _checked_layers(image_layer, shapes_layer, world_point):
    """The initial contours' layer (a Points layer read as clicks),
    once both layers are there and of the right kind (InputError saying
    what to do if not)."""
    if image_layer is None:
        raise InputError("no image to segment: open an image (or File > Open Sample > napari-physeg > "
                         "Hand (segmentation)) and select it in 'image'")
    if not isinstance(image_layer, Image):
        raise InputError(f"{getattr(image_layer, 'name', image_layer)!r} is not an Image layer; select an image")
    if shapes_layer is None:
        raise InputError("no initial contours: add a Shapes layer (layer list: 'New shapes layer' button), draw "
                         "a polygon, ellipse or rectangle around (or inside) the object and select it in "
                         "'initial contours'")
    if isinstance(shapes_layer, Points):
        shapes_layer = PointsAsClicks(shapes_layer, world_point)
    if (why := nothing_drawn(shapes_layer, "segment")) is not None:
        raise InputError(why)
    return shapes_layer


def _contours_on_image(sliced, image_shape, shapes_name: str, image_name: str, clicks: bool = False):
    """The contours of the current slice that lie on the image, their shapes'
    indices, and warnings for those partly beyond it (not for ``clicks``,
    whose circles are the package's) or left out (InputError if none is
    left, or one has NaN coordinates). One warning says which shapes lie
    partly beyond the image: 40 circles along its sides gave 40."""
    hi = np.array(image_shape, dtype=float) - 1.0
    contours, indices, warnings, off_images, partly = [], [], [], [], []
    for k, c in zip(sliced.indices, sliced.contours):
        if not np.all(np.isfinite(c)):
            raise InputError(f"shape {k} of {shapes_name!r} has non-finite coordinates (NaN); redraw it")
        outside_image = off_image(c, tuple(image_shape), f"shape {k} of {shapes_name!r} lies outside the image "
                                                         f"{image_name!r}")
        if outside_image:
            off_images.append(outside_image)
            continue
        if np.any((c < 0) | (c > hi)):
            # Passed as drawn: the part beyond the image tells the core where
            # the background is (its copy clipped onto the image would not).
            partly.append(k)
        contours.append(c)
        indices.append(k)
    if not contours:
        raise InputError("; ".join(off_images))
    if partly and not clicks:
        warnings.append(f"shape{'s' if len(partly) > 1 else ''} {', '.join(map(str, partly))} of {shapes_name!r} "
                        "lie partly outside the image: the vertices beyond it were moved onto its border")
    warnings.extend(f"{message}; it was left out" for message in sliced.refused + off_images)
    return contours, indices, warnings


def prepare_segmentation(image_layer, shapes_layer, *, world_point=None, channel: str | None = None,
                         dims_order=None, ndisplay: int = 2) -> SegmentationJob:
    """Read the current 2D slice of ``image_layer`` and the initial contours.

    Parameters
    ----------
    image_layer : napari.layers.Image
    shapes_layer : napari.layers.Shapes
        Initial contours: polygons, lassos, ellipses, rectangles or paths (closed),
        each segmented; only shapes on the current slice are used.
    world_point : sequence of float, optional
        The viewer's current position (``viewer.dims.point``).
    channel : str, optional
        For RGB images: a key of :data:`RGB_CHANNELS`.
    dims_order : sequence of int, optional
        ``viewer.dims.order``: the last two world axes must be the displayed ones.
    ndisplay : int, optional
        ``viewer.dims.ndisplay``.

    Raises
    ------
    InputError
        With a message that says how to fix the input.
    """
    shapes_layer = _checked_layers(image_layer, shapes_layer, world_point)
    ndim = int(image_layer.ndim)
    if ndim < 2:
        raise InputError(f"{image_layer.name!r} is {ndim}D: the segmentation needs a 2D image or a stack of them")
    n_world = len(world_point) if world_point is not None else ndim
    # (A 2D image in the 3D view too: napari cannot show the run's contours
    # on a Shapes layer there, and the preview and results were lost.)
    check_plane_view(n_world, ndisplay, dims_order if ndim > 2 else None)
    data = image_layer.data[0] if image_layer.multiscale else image_layer.data
    shape = tuple(int(s) for s in data.shape[: ndim])
    leading = slice_index(image_layer, world_point if world_point is not None else np.zeros(ndim), shape)
    plane = _plane_2d(image_layer, leading, channel)

    sliced = shapes_to_image_coords(shapes_layer, image_layer, world_point)
    if sliced.refused and not sliced.contours:
        raise InputError("; ".join(sliced.refused))
    if not sliced.contours:
        where = f" (slice {leading})" if leading else ""
        raise InputError(f"no shape of {shapes_layer.name!r} lies on the current slice{where}: draw an initial "
                         f"contour on this slice, or move to a slice with one ({sliced.off_slice} shapes elsewhere)")
    contours, indices, warnings = _contours_on_image(sliced, plane.shape, shapes_layer.name, image_layer.name,
                                                     clicks=isinstance(shapes_layer, PointsAsClicks))
    missing = int(np.isnan(plane).sum()) if plane.dtype.kind == "f" else 0
    if missing:  # said here: the core's warning is not relayed (see relay_warnings)
        warnings.append(f"{missing} NaN pixels of {image_layer.name!r} ({missing / plane.size:.1%}) were read as no "
                        "data: the contours keep out of them")
    return SegmentationJob(
        image=plane,
        contours=contours,
        shape_indices=indices,
        leading=tuple(leading),
        image_shape=shape,
        transform=image_transform_kwargs(image_layer),
        image_name=image_layer.name,
        shapes_name=shapes_layer.name,
        warnings=warnings,
    )


def error_message(outcome: SegmentationOutcome, job: SegmentationJob | None = None) -> str:
    """A user-facing message for a run where contours failed, with what to do
    about it; the shapes segmented all the same are named too."""
    failures = outcome.failures or [(outcome.error_index, outcome.error)]
    messages = [_failure_message(i, err, job) for i, err in failures]
    if outcome.results:
        done = [job.shape_indices[i] if job is not None else i for i in outcome.indices]
        messages.append(f"shape(s) {done} were segmented")
    return "; ".join(messages)


def _failure_message(index, err, job) -> str:
    which = ""
    if index is not None:
        k = job.shape_indices[index] if job is not None else index
        which = f" of shape {k}"
    if job is not None:  # the image may not be the one the user chose (theirs was removed)
        which += f" on {job.image_name!r}"
    if isinstance(err, DivergenceError):
        return f"Segmentation{which} diverged: {in_widget_terms(str(err))}"
    if isinstance(err, ValueError):
        return f"Segmentation{which} failed: {in_widget_terms(str(err))}"
    return (f"Segmentation{which} failed with {type(err).__name__}: {err}. Try other parameters "
            "(e.g. the defaults: rubber, r = 2000) and report this if it persists")


#: Why contours did not reach a border, and what to do, in the order the
#: warnings are given ("{steps}": the steps the first of them took).
_NOT_CONVERGED_ADVICE = {
    "max_steps": "were still moving after {steps} steps: raise 'max steps' (or draw closer to the object)",
    "limited": "came to rest against their drawing where the object runs on beyond it (the drawing is the "
               "object's limit): draw them around all of the object, or keep them as the part you drew around",
    "stalled": "came to rest away from any border (nothing in reach pulled them further): draw them closer "
               "to the object's border, or {r_change} the stiffness r{r_advice}",
    "leaked": "spread far beyond the drawing, over the image (nothing told the object from its surroundings, "
              "or there was no object in the drawing): draw them around the object, closer to its border, or set "
              "'object is' to bright or dark",
    "oscillating": "kept swinging without getting anywhere (no border holds them: noise or shading only): "
                   "draw them around the object, closer to its border",
}


#: A stiffness r this many times the material's suggested one (or more) pulls
#: so hard that the nodes overshoot and their steps are held back: raising it
#: does not help a contour that stalled, lowering it does (rubber at 1e8: IoU
#: 0.64 after 18 steps, at the suggested 2000: 0.997).
R_TOO_HIGH = 10.0


def not_converged_messages(outcome: SegmentationOutcome, job: SegmentationJob, r_ratio: float = 1.0) -> list[str]:
    """One warning per way the contours did not reach a border, with the advice
    that fits it (``r_ratio``: the run's stiffness r over the material's suggested one)."""
    by_reason: dict = {}
    for i, r in zip(outcome.indices, outcome.results):
        if not r.converged:
            by_reason.setdefault(r.stop_reason, []).append((job.shape_indices[i], r.steps))
    too_high = r_ratio >= R_TOO_HIGH
    r_change, r_advice = ("lower", f" ({r_ratio:.3g} times the material's suggested r: forces that strong "
                                   "overshoot, and the steps are held back)") if too_high else ("raise", "")
    return [f"shape(s) {[k for k, _ in runs]} " + advice.format(steps=runs[0][1], r_change=r_change, r_advice=r_advice)
            for reason, advice in _NOT_CONVERGED_ADVICE.items() if (runs := by_reason.get(reason))]


def result_layer_data(outcome: SegmentationOutcome, job: SegmentationJob, *, labels: bool = False,
                      name: str | None = None) -> list:
    """napari layer data tuples for the results of a run.

    A Shapes layer of polygons (float32, in the image's DATA coordinates, on
    the job's slice) with the image's transform, and optionally a Labels layer
    of the image's shape with contour ``k`` filled with label ``k + 1``.
    """
    name = name or f"{job.shapes_name} segmented"
    contours = [r.contour for r in outcome.results]
    features = {
        "shape": np.asarray([job.shape_indices[i] for i in outcome.indices], dtype=int),
        "steps": np.asarray([r.steps for r in outcome.results], dtype=int),
        "converged": np.asarray([r.converged for r in outcome.results], dtype=bool),
        # why each stopped ("leaked": it spread over the image; see the warnings), in the layer's features table
        "stop_reason": np.asarray([r.stop_reason for r in outcome.results], dtype=object),
        "nodes": np.asarray([len(r.contour) for r in outcome.results], dtype=int),
    }
    shapes_meta = {
        "name": name,
        "shape_type": "polygon",
        "edge_color": "cyan",
        "face_color": "transparent",
        "edge_width": 1.0,
        "features": features,
        "metadata": {"napari_physeg": {"image": job.image_name, "slice": job.leading}},
        **job.transform,
    }
    out = [(contours_to_shapes_data(contours, job.leading), shapes_meta, "shapes")]
    if labels:
        mask = contours_to_labels(contours, job.image_shape, job.leading)
        out.append((mask, {"name": f"{name} mask", **job.transform}, "labels"))
    return out


# --------------------------------------------------------------------------
# The widget
# --------------------------------------------------------------------------

_TIPS = {
    **PHYSICS_TIPS,
    "image": "Image layer to segment. On a stack (e.g. T, Y, X) the current 2D slice is segmented.",
    "channel": "Which channel of an RGB image to segment: red, green, blue, or grey (the luminance).",
    "shapes": "Shapes layer with the initial contours: polygons, lassos, ellipses, rectangles or paths drawn "
              "around (or inside) the objects. Each shape on the current slice is segmented. A Points layer "
              "works too: each of its points on the current slice is a click inside one object.",
    "sigma": "Width of the interaction between nodes relative to the node spacing, typically 0.75-1.5 "
             "(max 2). Larger couples more nodes: a smoother, stiffer contour.",
    "w_edges": "Weight of the edge force (Shen-Castan edges pull nodes onto the border), 0-1, typically 0.4. "
               "0 turns the force off.",
    "w_intensity": "Weight of the intensity (region) force (pushes nodes out of the object's intensity, "
                   "in from the background), 0-1, typically 0.3. 0 turns it off.",
    "w_distance": "Weight of the distance force (pulls nodes toward the nearest edge from afar), 0-1, "
                  "typically 0.3. 0 turns it off.",
    "polarity": "Whether the object is brighter or darker than its background; 'auto' reads it from "
                "your drawing (its middle, its line and rings outside it), drawn around or inside the object.",
    "max_steps": "Upper bound on time steps per contour, typically 200-2000; a contour usually comes to "
                 "rest in 20-80 steps, a few hundred when drawn far around a complex outline.",
    "labels": "Also add a Labels layer with each segmented contour filled (label k for shape k).",
    "run": "Segment every shape of 'initial contours' on the current slice, in the background, with a live "
           "preview.",
    "cancel": "Stop the running segmentation; the contours already finished are kept.",
}


#: When the GUI is busy, a finished contour is drawn in the preview at once
#: only if none was drawn for this many seconds; else with the next one shown.
FINISHED_EVERY = 0.25


class SegmentationWidget(WorkerWidget):
    """Segment objects with a physical deformable contour.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers are used (napari passes it when the widget is
        opened from the Plugins or Layers > Segment menu).

    Notes
    -----
    Press Run (or call :meth:`run`): the current 2D slice of the image and the
    initial contours on it are read, then :func:`segment_contours` runs in a
    ``thread_worker``. A temporary "... preview" Shapes layer shows the
    evolving contour, napari's activity dock a progress bar, and Cancel stops
    the run. At the end a Shapes layer "<shapes> segmented" (and optionally a
    Labels layer "<shapes> mask") is added with the image's transform and the
    preview removed. Problems are reported as napari notifications.
    """

    relay_warnings = False  # the drawings' warnings are made here; the core's repeat them

    def __init__(self, viewer: napari.viewer.Viewer):
        super().__init__(viewer)
        self.job: SegmentationJob | None = None
        self.last_outcome: SegmentationOutcome | None = None
        self.preview_layer: Shapes | None = None
        self._finished: dict = {}  # index -> final contour, not yet drawn in the preview
        self.preview_interval = 0.05

        self._image = ComboBox(label="image", choices=self._image_choices, tooltip=_TIPS["image"])
        self._channel = ComboBox(label="RGB channel", choices=[RGB_CHOOSE, *RGB_CHANNELS], value=RGB_CHOOSE,
                                 tooltip=_TIPS["channel"], visible=False)
        self._shapes = ComboBox(label="initial contours", choices=self._shapes_choices, tooltip=_TIPS["shapes"])
        self.physics = PhysicsControls(segment)
        self._r_ratio = 1.0  # the last run's stiffness r over the material's suggested one
        self._sigma = FloatSpinBox(label="σ factor", value=core_default(segment, "sigma_factor"), min=0.1, max=2.0,
                                   step=0.05, tooltip=_TIPS["sigma"])
        self._weights = {name: FloatSpinBox(label=f"{name} weight", value=DEFAULT_WEIGHTS[name], min=0.0, max=1.0,
                                            step=0.05, tooltip=_TIPS[f"w_{name}"]) for name in DEFAULT_WEIGHTS}
        self._polarity = ComboBox(label="object is", choices=["auto", "bright", "dark"],
                                  value=core_default(segment, "polarity"), tooltip=_TIPS["polarity"])
        self._contrast = contrast_box()
        self._max_steps = SpinBox(label="max steps", value=core_default(segment, "max_steps"), min=1, max=100000,
                                  step=100, tooltip=_TIPS["max_steps"])
        self._labels = CheckBox(text="also add Labels mask", value=False, tooltip=_TIPS["labels"])
        self._run_btn = PushButton(text="Run", tooltip=_TIPS["run"])
        self._cancel_btn = PushButton(text="Cancel", tooltip=_TIPS["cancel"], enabled=False)
        self._status = Label(value="")
        self._lay_out([self._image, self._channel, self._shapes, *self.physics.main, self._labels],
                      advanced=[self._polarity, self._contrast, *self.physics.advanced, self._sigma,
                                *self._weights.values(), self._max_steps])
        self._image.changed.connect(self._on_image_changed)
        self._connect_signals()
        self._on_image_changed()

    # ------------------------------------------------------------ choices
    def _image_choices(self, _widget=None):
        return image_layer_choices(self.viewer)

    def _shapes_choices(self, _widget=None):
        return contour_layer_choices(self.viewer)

    def _on_layers_changed(self, event=None):
        try:
            self.reset_choices()
        except RuntimeError:  # the Qt widget is gone (viewer closing)
            return

    def _on_image_changed(self, *_):
        layer = self._image.value
        self._channel.visible = bool(layer is not None and getattr(layer, "rgb", False))

    # ------------------------------------------------------------ state
    def parameters(self) -> dict:
        """The current settings as keyword arguments of :func:`segment_kwargs`."""
        return {
            **self.physics.parameters(),
            "sigma_factor": self._sigma.value,
            "weights": {name: w.value for name, w in self._weights.items()},
            "polarity": self._polarity.value,
            "contrast": self._contrast.value,
            "max_steps": self._max_steps.value,
        }

    # ------------------------------------------------------------ run
    def run(self, *_):
        """Start segmenting the current slice in a background thread.

        Returns the worker, or None when the input is bad (an error
        notification then says why) or a run is already going on.
        """
        if self._running:
            return None
        dims = self.viewer.dims
        try:
            job = prepare_segmentation(
                self._image.value, self._shapes.value, world_point=tuple(dims.point),
                channel=self._channel.value, dims_order=tuple(dims.order), ndisplay=dims.ndisplay,
            )
            params = self.parameters()
            kwargs_list = [segment_kwargs(c, **params) for c in job.contours]
            self._r_ratio = params["stiffness"] / suggested_stiffness(params["material"])
        except ValueError as err:  # InputError, or a bad custom material
            self._fail(str(err))
            return None
        for message in job.warnings:
            show_warning(message)

        self.job = job
        self.last_outcome = None
        self._finished = {}
        # Named after what made it: two runs with other materials are told apart.
        material = kwargs_list[0]["material"]
        self._result_name = f"{job.shapes_name} segmented ({getattr(material, 'name', material)})"
        self._begin(f"Segmenting {len(job.contours)} shape(s)…")

        # Closed paths, not polygons: napari triangulates the faces of polygons
        # (slow without a compiled backend), paths only need their edges.
        preview_meta = {
            "name": f"{job.shapes_name} preview",
            "shape_type": "path",
            "edge_color": PREVIEW_COLOR,
            "face_color": "transparent",
            "edge_width": 1.0,
            "metadata": {PREVIEW_KEY: True},
            **job.transform,
        }
        self.preview_layer = self._add_preview(
            Layer.create(contours_to_shapes_data(job.contours, job.leading, closed=True), preview_meta, "shapes")
        )
        max_steps = kwargs_list[0]["max_steps"]
        total = len(job.contours) * max_steps
        return self._start(total, segment_contours, job.image, job.contours, kwargs_list, cancel=self._cancel,
                           preview_interval=self.preview_interval)

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _note_update(self, update: SegmentationProgress) -> None:
        # A contour's final state is drawn with the next preview shown (see _must_show).
        if update.done:
            self._finished[update.index] = update.contour

    def _must_show(self, update: SegmentationProgress) -> bool:
        # A contour's final state, but the last's (the result layer shows it at
        # once), when no preview was drawn for FINISHED_EVERY seconds. Each one
        # shown rewrites the whole preview layer: shown one by one, 400 nuclei
        # took six times the computation's time.
        return (update.done and update.index + 1 < update.total
                and time.perf_counter() - self._last_draw[0] >= FINISHED_EVERY)

    def _on_yielded(self, update: SegmentationProgress):
        if not self._gui_alive():
            self._on_destroyed()
            return
        value = update.index * update.max_steps + min(update.step, update.max_steps)
        if value <= self._progress_value and not update.done:
            return  # older than one already shown
        self.n_updates += 1
        if not update.done:
            self._status.value = f"Shape {update.index + 1}/{update.total}: step {update.step}"
        layer = self.preview_layer
        if layer is not None and layer in self.viewer.layers and self.job is not None:
            polys = list(layer.data)
            changed = {**self._finished, update.index: update.contour}
            self._finished = {}
            for index, contour in changed.items():
                if index < len(polys):
                    polys[index] = contours_to_shapes_data([contour], self.job.leading, closed=True)[0]
            if self.viewer.dims.ndisplay == 2:  # (napari takes no new data on a Shapes layer in the 3D view)
                layer.data = polys
        self._advance(value)

    def _on_returned(self, outcome: SegmentationOutcome):
        self.last_outcome = outcome
        job = self.job
        if not self._gui_alive():
            return
        if outcome.error is not None and not outcome.results:
            self._fail(error_message(outcome, job))
            return
        if outcome.cancelled and not outcome.results:
            self._status.value = "Cancelled before a contour was finished: no layer added"
            show_info("Segmentation cancelled before a contour was finished: no layer added")
            return
        try:
            preview, self.preview_layer = self.preview_layer, None
            for data, meta, kind in result_layer_data(outcome, job, labels=self._labels.value,
                                                      name=self._result_name):
                self._add_result(data, meta, kind, preview)
        except Exception as err:  # never leave the user with a silent failure
            self._fail(f"Could not add the result layers: {type(err).__name__}: {err}")
            return
        for message in not_converged_messages(outcome, job, self._r_ratio):
            show_warning(message)
        rested = sum(r.converged for r in outcome.results)
        cancelled = f"Cancelled: of {len(job.contours)} shapes, the finished ones kept. " if outcome.cancelled else ""
        textured = sum(r.contrast == "texture" for r in outcome.results)
        self._status.value = (f"{cancelled}Segmented {len(outcome.results)} shape(s) in {outcome.seconds:.2f} s"
                              + (f", {textured} read by their texture" if textured else "")
                              + ("" if rested == len(outcome.results) else
                                 f"; {len(outcome.results) - rested} did not reach a border (see the warnings)"))
        if outcome.error is not None:  # the others were kept; say which failed and why
            self._fail(error_message(outcome, job))

    def _on_errored(self, err: Exception):
        # segment_contours catches the core's errors itself; this is a last resort.
        self.last_outcome = SegmentationOutcome([], error=err)
        self._fail(error_message(self.last_outcome, None))

    def _on_finished(self):
        preview, self.preview_layer = self.preview_layer, None
        super()._on_finished()
        try:
            if preview is not None and preview in self.viewer.layers:
                self.viewer.layers.remove(preview)
        except RuntimeError:  # the viewer was closed during the run
            pass

"""The simulation widget: a thin napari front end to :func:`napari_physeg.core.simulate`.

Three parts, from the least to the most napari-specific:

* :func:`simulate_contours` - a plain generator that (matches the two
  contours with method "order" if no matching is given, then) simulates the
  deformation of ``a`` into ``b`` with the core, yielding
  :class:`SimulationProgress` from the core's callback and returning a
  :class:`SimulationOutcome`. It knows nothing about napari or Qt;
  :func:`run_to_completion` drives it synchronously in scripts and tests.
* :func:`simulation_layer_data` - turns an outcome into napari layer data: a
  Shapes layer with a LEADING TIME AXIS (one polygon per frame, vertices
  ``(t, *leading, row, col)``) so napari's dims slider plays the deformation,
  and optionally a Tracks layer of the node trajectories.
* :class:`SimulationWidget` - a magicgui ``Container`` (a
  :class:`~napari_physeg._widgets._worker.WorkerWidget`); Run starts
  :func:`simulate_contours` in a ``napari.qt.threading.thread_worker`` with a
  napari progress bar and a Cancel button.

The two contours are read with :func:`~napari_physeg._widgets.matching.read_contour_pair`
(in the initial contour's layer coordinates); a matching made by the matching
widget is reused from its layer's ``metadata["matching"]`` when it was
computed for these contours.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from functools import partial

import napari
import numpy as np
from magicgui.widgets import CheckBox, ComboBox, FloatSpinBox, Label, PushButton, SpinBox
from napari.utils.notifications import show_info, show_warning

from ..core import MATERIALS, DivergenceError, iter_match, iter_simulate, match, simulate
from ..core.contour import crosses_itself
from ..core.tracking import frame_runs
from ._inputs import (
    MATCHING_KEY,
    SIMULATION_KEY,
    ContourPair,
    InputError,
    contour_layer_choices,
    core_default,
    follow_matching,
    index_in_range,
    is_matching_layer,
    matching_fits,
    pick_default_b,
    read_contour_pair,
)
from ._layers import contours_to_shapes_data, prepend_axes_transform
from ._worker import WorkerWidget, relay, run_to_completion

__all__ = [
    "COMPUTE_MATCHING",
    "SimulationOutcome",
    "SimulationProgress",
    "SimulationWidget",
    "choose_matching",
    "crossing_frames",
    "frames_table",
    "run_to_completion",
    "simulate_contours",
    "simulation_layer_data",
]

#: Choice of the matching selector that computes a matching (with the chosen method).
COMPUTE_MATCHING = "(compute one)"
#: Method used when no (fitting) matching is given: match()'s default.
DEFAULT_METHOD = core_default(match, "method")
SIMULATE_MAX_STEPS = core_default(simulate, "max_steps")


# --------------------------------------------------------------------------
# The worker: a plain generator over the core
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class SimulationProgress:
    """What :func:`simulate_contours` yields.

    Attributes
    ----------
    stage : str
        ``"matching"`` (computing a matching first) or ``"simulating"``.
    step : int
        Time steps taken so far.
    max_steps : int
        The step budget.
    shape : (Na, 2) ndarray or None
        The current shape (None while matching).
    """

    stage: str
    step: int
    max_steps: int
    shape: np.ndarray | None = None


@dataclass(frozen=True)
class SimulationOutcome:
    """What :func:`simulate_contours` returns.

    Attributes
    ----------
    result : SimulationResult or None
        The core's result (None when cancelled or failed).
    matching : Matching or None
        The matching used.
    matching_computed : bool
        True when it was computed here (method "order"), not given.
    cancelled : bool
        The run was stopped by the cancel event.
    error : Exception or None
        The error that stopped the run.
    seconds : float
        Wall time.
    """

    result: object = None
    matching: object = None
    matching_computed: bool = False
    cancelled: bool = False
    error: Exception | None = None
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.error is None and not self.cancelled and self.result is not None


def simulate_contours(a, b, matching=None, kwargs: dict | None = None, *, cancel: threading.Event | None = None,
                      preview_interval: float = 0.02, method: str = DEFAULT_METHOD):
    """Simulate the deformation of contour ``a`` into ``b``; a generator for a worker thread.

    The core's :func:`~napari_physeg.core.iter_match` (when no matching is
    given) and :func:`~napari_physeg.core.iter_simulate` run right here (see
    :func:`~._worker.relay`): at most one step every ``preview_interval``
    seconds is yielded, and once ``cancel`` is set the core stops at its next
    step.

    Parameters
    ----------
    a, b : (N, 2) ndarray
        Initial and target contours ``(row, col)`` in one coordinate frame.
    matching : Matching, optional
        Correspondences (from :func:`~napari_physeg.core.match` on these very
        contours); computed with ``method`` when None.
    kwargs : dict, optional
        Keyword arguments of :func:`simulate` (``q``, ``material``,
        ``n_frames``, ``max_steps``, ...).
    cancel : threading.Event, optional
        Set it to stop the run.
    preview_interval : float, optional
        Least time (s) between two yielded updates.
    method : str, optional
        Matching method when ``matching`` is None.

    Yields
    ------
    SimulationProgress

    Returns
    -------
    SimulationOutcome
        Errors of the core (``ValueError``, ``DivergenceError``) are returned
        in it, not raised.
    """
    cancel = cancel if cancel is not None else threading.Event()
    kwargs = dict(kwargs or {})
    max_steps = int(kwargs.get("max_steps", SIMULATE_MAX_STEPS))
    t0 = time.perf_counter()
    computed, used = matching is None, matching

    def outcome(**fields):
        return SimulationOutcome(matching=used, matching_computed=computed, seconds=time.perf_counter() - t0,
                                 **fields)

    try:
        if used is None:
            used = yield from relay(iter_match(a, b, method=method), cancel,
                                    wrap=lambda state: SimulationProgress("matching", 0, max_steps))
            if used.stop_reason == "cancelled":
                return outcome(cancelled=True)
        result = yield from relay(iter_simulate(a, b, used, **kwargs), cancel, preview_interval,
                                  wrap=lambda state: SimulationProgress("simulating", state.step, max_steps,
                                                                        state.shape))
    except Exception as err:  # reported to the user by the caller
        return outcome(error=err)
    if result.stop_reason == "cancelled":
        return outcome(cancelled=True)
    return outcome(result=result)


def frames_table(result) -> dict:
    """The frames of a simulation as columns for a CSV file: ``frame``,
    ``node``, ``row``, ``col`` (one row per node and frame) and ``time``
    (simulated seconds)."""
    frames = np.asarray(result.frames, dtype=np.float64)
    n_frames, n_nodes = frames.shape[:2]
    return {"frame": np.repeat(np.arange(n_frames), n_nodes), "node": np.tile(np.arange(n_nodes), n_frames),
            "row": frames[..., 0].ravel(), "col": frames[..., 1].ravel(),
            "time": np.repeat(np.asarray(result.times, dtype=float), n_nodes)}


def crossing_frames(result) -> list[int]:
    """The frames of a simulation whose contour crosses itself."""
    return [t for t, frame in enumerate(result.frames) if crosses_itself(frame)]


def choose_matching(layer, pair: ContourPair, method: str = DEFAULT_METHOD):
    """The Matching stored in ``layer`` if it was computed for ``pair``'s contours.

    Returns ``(matching or None, reason)``: ``reason`` says why a stored
    matching cannot be used (empty when it can, or when no layer is given).
    """
    if layer is None or not is_matching_layer(layer):
        return None, ""
    if matching_fits(layer.metadata, pair.a, pair.b):
        return layer.metadata[MATCHING_KEY], ""
    meta = layer.metadata
    src = f"{meta.get('a_layer', '?')} #{meta.get('a_index', '?')} → {meta.get('b_layer', '?')} " \
          f"#{meta.get('b_index', '?')}"
    return None, (f"the matching in {layer.name!r} was computed for other contours ({src}); a new matching is "
                  f"computed with method {method!r}. To reuse one, match these two contours with the "
                  "matching widget first")


def error_message(err: Exception) -> str:
    """A user-facing message for a failed simulation, with what to do about it."""
    if isinstance(err, DivergenceError):
        return f"Simulation diverged: {err}. Lower q or use the rubber preset"
    if isinstance(err, ValueError):
        return f"Simulation failed: {err}"
    return (f"Simulation failed with {type(err).__name__}: {err}. Try the defaults (rubber, q = 30000 N/m) "
            "and report this if it persists")


# --------------------------------------------------------------------------
# Outcome -> layers
# --------------------------------------------------------------------------


def simulation_layer_data(outcome: SimulationOutcome, pair: ContourPair, *, tracks: bool = False,
                          name: str | None = None, material=None) -> list:
    """napari layer data tuples of a finished simulation.

    * A Shapes layer "<a> → <b> simulation": one polygon per frame, vertices
      ``(t, *leading, row, col)`` (float32) with ``t`` the frame number, so
      that the dims slider of the new leading axis ("frame") plays the
      deformation; the transform is the initial contour's layer's, with an
      identity time axis in front. ``features`` hold ``frame`` and ``time``
      (simulated seconds); ``metadata["simulation"]`` the SimulationResult.
    * With ``tracks``, a Tracks layer "<a> → <b> tracks": one track per node
      (``track_id`` = node, time = frame). napari's tracks have at most 3
      spatial axes, so contours with more than one leading axis get none.
    """
    res = outcome.result
    frames = np.asarray(res.frames, dtype=np.float64)
    n_frames = len(frames)
    # Named after what made them: the material, and the matching's method.
    method = getattr(outcome.matching, "method", None)
    made_by = ", ".join(str(x) for x in (getattr(material, "name", material), method) if x is not None)
    made_by = f" ({made_by})" if made_by else ""
    base = name or f"{pair.a_label} → {pair.b_label}"
    transform = prepend_axes_transform(pair.transform, labels=("frame",))
    polys = [contours_to_shapes_data([f], (float(t), *pair.leading))[0] for t, f in enumerate(frames)]
    meta = {
        "name": f"{base} simulation{made_by}",
        "shape_type": "polygon",
        "edge_color": "orange",
        "face_color": "transparent",
        "edge_width": 1.5,
        "opacity": 1.0,
        "features": {"frame": np.arange(n_frames), "time": np.asarray(res.times, dtype=float)},
        "metadata": {
            SIMULATION_KEY: res,
            "a_layer": pair.a_layer, "a_index": pair.a_index,
            "b_layer": pair.b_layer, "b_index": pair.b_index,
            "matching_method": getattr(outcome.matching, "method", None),
            "matching_computed": outcome.matching_computed,
        },
        **transform,
    }
    out = [(polys, meta, "shapes")]
    if tracks and len(pair.leading) <= 1:
        na = frames.shape[1]
        node = np.repeat(np.arange(na), n_frames)
        t = np.tile(np.arange(n_frames), na)
        lead = np.broadcast_to(np.asarray(pair.leading, dtype=float), (na * n_frames, len(pair.leading)))
        xy = frames.transpose(1, 0, 2).reshape(-1, 2)
        data = np.column_stack([node, t, lead, xy]).astype(np.float64)
        track_meta = {
            "name": f"{base} tracks{made_by}",
            "tail_length": n_frames,
            "head_length": 0,
            "tail_width": 1.5,
            "features": {"node": node},
            "metadata": {SIMULATION_KEY: res},
            **transform,
        }
        out.append((data, track_meta, "tracks"))
    return out


# --------------------------------------------------------------------------
# The widget
# --------------------------------------------------------------------------

_TIPS = {
    "layer_a": "Shapes layer holding the initial contour a (the elastic body that deforms). The result is "
               "drawn in this layer's coordinates.",
    "index_a": "Which shape of the initial layer is contour a (0 = the first shape drawn).",
    "layer_b": "Shapes layer holding the target contour b. May be the same layer as a, with another index.",
    "index_b": "Which shape of the target layer is contour b.",
    "matching": "Node correspondences to use: a layer made by the matching widget (its metadata holds the "
                "matching and its method), or '(compute one)' with the method below. A layer computed for "
                "other contours is not used: a matching is computed instead.",
    "method": "Method of the matching computed when none is chosen (or the chosen one does not fit). 'order' "
              "keeps the nodes' order, so the frames never cross themselves; 'global' and 'local' may.",
    "q": "The paper's global stiffness constant q (N/m) of the forces pulling each node of a toward its "
         "partner on b (eq. 17); the paper uses 30000 N/m. Larger q: a stronger pull, the contour ends closer "
         "to b (stiff materials such as copper need ~1e6-1e8 to reach it). Smaller q: the material's elasticity "
         "wins, the contour stops part way, smoother. Any q > 0 is stable.",
    "material": "Virtual material of the initial contour. Soft (rubber, soft tissue) deforms onto b at "
                "q = 30000 N/m; stiff metals (aluminium, copper, steel) resist and stop short of b unless q is "
                "much larger.",
    "n_frames": "Frames in the output, the first (a) and last (at rest) included, at even intervals of the "
                "path travelled. They become the steps of the 'frame' slider.",
    "max_steps": "Upper bound on time steps; a simulation usually comes to rest in 30-100 steps.",
    "tracks": "Also add a Tracks layer with the trajectory of every node (track = node, time = frame).",
    "run": "Simulate the deformation of a into b in the background and add a Shapes layer with one polygon per "
           "frame on a new leading 'frame' axis.",
    "cancel": "Stop the running simulation; no layer is added.",
    "export": "Save the last simulation's frames as a CSV file: frame, node, row, col, one row per node and "
              "frame.",
}


def _slider_name(dims, axis: int) -> str:
    """How to name the viewer's slider of world ``axis`` to a user: by its
    label, unless that is napari's default, the axis' number counted from
    the end ('-3': no slider shows it), when it is the time slider of a movie
    or the slider of axis ``axis``."""
    label = str(dims.axis_labels[axis])
    if not label.lstrip("-").isdigit():
        return f"the '{label}' slider"
    return "the time slider" if dims.ndim == 3 else f"the slider of axis {axis}"


class SimulationWidget(WorkerWidget):
    """Simulate the deformation of one contour into another (paper section 4.2).

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers are used.

    Notes
    -----
    Press Run (or call :meth:`run`): the two contours are read (in the initial
    contour's layer coordinates), the chosen matching is checked against them,
    and :func:`simulate_contours` runs in a ``thread_worker`` with a napari
    progress bar fed by the core's callback; Cancel stops it. The result is a
    Shapes layer "<a> → <b> simulation" with a leading frame axis (and
    optionally a Tracks layer). Problems are reported as notifications.
    """

    def __init__(self, viewer: napari.viewer.Viewer):
        super().__init__(viewer)
        self.pair: ContourPair | None = None
        self.last_outcome: SimulationOutcome | None = None
        self.output_layers: list = []
        self.preview_interval = 0.02
        self._max_steps_run = 0

        self._layer_a = ComboBox(label="initial a (layer)", choices=self._shapes_choices, tooltip=_TIPS["layer_a"])
        self._index_a = SpinBox(label="shape of a", value=0, min=0, max=100000, tooltip=_TIPS["index_a"])
        self._layer_b = ComboBox(label="target b (layer)", choices=self._shapes_choices, tooltip=_TIPS["layer_b"])
        self._index_b = SpinBox(label="shape of b", value=0, min=0, max=100000, tooltip=_TIPS["index_b"])
        self._matching = ComboBox(label="matching", choices=self._matching_choices, value=COMPUTE_MATCHING,
                                  tooltip=_TIPS["matching"])
        self._method = ComboBox(label="method", choices=["order", "global", "local"], value=DEFAULT_METHOD,
                                tooltip=_TIPS["method"])
        self._matching_info = Label(value="")
        self._q = FloatSpinBox(label="q (N/m)", value=core_default(simulate, "q"), min=1.0, max=1e10, step=1000.0,
                               tooltip=_TIPS["q"])
        self._material = ComboBox(label="material", choices=list(MATERIALS), value=core_default(simulate, "material"),
                                  tooltip=_TIPS["material"])
        self._n_frames = SpinBox(label="frames", value=core_default(simulate, "n_frames"), min=2, max=1000,
                                 tooltip=_TIPS["n_frames"])
        self._max_steps = SpinBox(label="max steps", value=core_default(simulate, "max_steps"), min=1, max=100000,
                                  step=100, tooltip=_TIPS["max_steps"])
        self._tracks = CheckBox(text="also add node Tracks layer", value=False, tooltip=_TIPS["tracks"])
        self._run_btn = PushButton(text="Run", tooltip=_TIPS["run"])
        self._cancel_btn = PushButton(text="Cancel", tooltip=_TIPS["cancel"], enabled=False)
        self._export_btn = PushButton(text="Save CSV…", tooltip=_TIPS["export"], enabled=False)
        self._status = Label(value="")
        self._lay_out([self._layer_a, self._index_a, self._layer_b, self._index_b, self._matching, self._method,
                       self._matching_info, self._q, self._material, self._n_frames],
                      advanced=[self._max_steps, self._tracks], buttons=[self._export_btn])
        self._matching_info.native.setWordWrap(True)
        for layer, index in ((self._layer_a, self._index_a), (self._layer_b, self._index_b)):
            layer.changed.connect(partial(index_in_range, layer, index))
        self._matching.changed.connect(self._follow_matching)
        for w in (self._matching, self._method):
            w.changed.connect(self._show_matching_info)
        self._export_btn.changed.connect(self._ask_export)
        self._connect_signals()
        self._pick_defaults()
        self._select_newest_matching()
        self._show_matching_info()

    # ------------------------------------------------------------ choices
    def _shapes_choices(self, _widget=None):
        return contour_layer_choices(self.viewer)

    def _matching_choices(self, _widget=None):
        layers = [(layer.name, layer) for layer in self.viewer.layers if is_matching_layer(layer)]
        return [(COMPUTE_MATCHING, COMPUTE_MATCHING), *layers]

    def _pick_defaults(self, *_):
        pick_default_b(self._layer_a, self._index_a, self._layer_b, self._index_b, self._shapes_choices())

    def _show_matching_info(self, *_):
        """Say which matching Run will use, and with which method."""
        chosen = self._matching.value
        self._method.visible = chosen == COMPUTE_MATCHING
        if chosen == COMPUTE_MATCHING or chosen is None:
            self._matching_info.value = f"Run computes a matching with method {self._method.value!r}."
        else:
            method = getattr(chosen.metadata.get(MATCHING_KEY), "method", "?")
            self._matching_info.value = f"Run uses the matching in {chosen.name!r} (method {method!r})."

    def _follow_matching(self, *_):
        """a and b are the contours of the matching chosen (it said it ran on
        them while a and b stayed on another layer's, an outside tester)."""
        if self._matching.value not in (None, COMPUTE_MATCHING):
            follow_matching(self._matching.value, self._layer_a, self._index_a, self._layer_b, self._index_b,
                            self._shapes_choices())

    def _select_newest_matching(self):
        layers = [layer for layer in self.viewer.layers if is_matching_layer(layer)]
        if layers:
            self._matching.value = layers[-1]

    def _on_layers_changed(self, event=None):
        try:
            self.reset_choices()
            self._pick_defaults()
            # A matching just made (by the matching widget) is the one to use next.
            value = getattr(event, "value", None) if getattr(event, "type", "") == "inserted" else None
            if value is not None and is_matching_layer(value):
                self._matching.value = value
            self._show_matching_info()
        except RuntimeError:  # the Qt widget is gone (viewer closing)
            return

    # ------------------------------------------------------------ state
    def parameters(self) -> dict:
        """The current settings as keyword arguments of :func:`~napari_physeg.core.simulate`."""
        return {"q": float(self._q.value), "material": self._material.value, "n_frames": int(self._n_frames.value),
                "max_steps": int(self._max_steps.value)}

    # ------------------------------------------------------------ run
    def run(self, *_):
        """Start the simulation in a background thread.

        Returns the worker, or None when the input is bad (an error
        notification then says why) or a run is already going on.
        """
        if self._running:
            return None
        try:
            pair = read_contour_pair(self._layer_a.value, self._index_a.value, self._layer_b.value,
                                     self._index_b.value, world_point=tuple(self.viewer.dims.point),
                                     roles=("a (initial)", "b (target)"))
        except ValueError as err:
            self._fail(str(err))
            return None
        chosen = self._matching.value
        layer = None if chosen == COMPUTE_MATCHING else chosen
        matching, reason = choose_matching(layer, pair, self._method.value)
        if reason:
            show_warning(reason)

        self.pair = pair
        self.last_outcome = None
        self.output_layers = []
        self._export_btn.enabled = False
        method = self._method.value
        self._begin("Simulating…" if matching is not None else f"Matching ({method}), then simulating…")
        params = self.parameters()
        self._max_steps_run = params["max_steps"]
        total = self._max_steps_run
        return self._start(total, simulate_contours, pair.a, pair.b, matching, params, cancel=self._cancel,
                           preview_interval=self.preview_interval, method=method)

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _on_yielded(self, update: SimulationProgress):
        if not self._gui_alive():
            self._on_destroyed()
            return
        self.n_updates += 1
        if update.stage == "matching":
            self._status.value = f"Matching ({self._method.value})…"
            return
        if not self._cancel.is_set():
            self._status.value = f"Step {update.step}"
        self._advance(min(update.step, update.max_steps))

    def _on_returned(self, outcome: SimulationOutcome):
        self.last_outcome = outcome
        pair = self.pair
        if not self._gui_alive():
            return
        if outcome.error is not None:
            self._fail(error_message(outcome.error))
            return
        if outcome.cancelled:
            self._status.value = "Cancelled: no layer added"
            show_info("Simulation cancelled: no layer added")
            return
        self._advance(self._max_steps_run)  # it came to rest before the step budget
        res = outcome.result
        if self._tracks.value and len(pair.leading) > 1:
            show_warning("no Tracks layer: napari's tracks have at most 3 spatial axes and the contours have "
                         f"{len(pair.leading) + 2}")
        axis = self.viewer.dims.ndim - len(pair.leading) - 3  # the world axis the frames play on
        slider = _slider_name(self.viewer.dims, axis) if axis >= 0 else "the 'frame' slider"
        try:
            layer_data = simulation_layer_data(outcome, pair, tracks=self._tracks.value, material=self._material.value)
            for _, meta, _ in layer_data if axis >= 0 else ():
                # An axis the viewer has (a movie's time): it keeps its name, and
                # the frames its step (at scale 1 against a movie's 5 s a frame,
                # the slider went from 30 steps to 146, and the frames between two).
                meta.pop("axis_labels", None)
                meta["scale"] = np.r_[self.viewer.dims.range[axis].step, np.asarray(meta["scale"])[1:]]
            self.output_layers = self._put_results(layer_data)
        except Exception as err:  # never leave the user with a silent failure
            self._fail(f"Could not add the simulation layers: {type(err).__name__}: {err}")
            return
        gap = float(np.linalg.norm(res.frames[-1] - res.targets, axis=1).mean())
        how = "came to rest" if res.converged else "did NOT come to rest"
        method = outcome.matching.method
        via = f"matching computed ({method})" if outcome.matching_computed else f"matching reused ({method})"
        self._export_btn.enabled = True
        self._status.value = (f"{len(res.frames)} frames, {res.steps} steps, {how}; last frame {gap:.2f} px from "
                              f"the targets on b ({via}, {outcome.seconds:.2f} s)")
        show_info(f"Simulation {pair.a_label!r} → {pair.b_label!r}: {self._status.value}. Move {slider} to "
                  "play it")
        if not res.converged:
            show_warning(f"the simulation did not come to rest within max steps ({res.steps}); raise 'max steps'")
        crossing = crossing_frames(res)
        if crossing:
            if method == "order":
                why = ("nodes overtake their neighbours on the way (the 'order' matching keeps their order on a "
                       "and on b, not in between)")
            else:
                why = (f"the {method!r} matching pairs nodes out of their order along the contours. Use a matching "
                       "made with method 'order'")
            last = len(res.frames) - 1
            if last in crossing and (targets := len(np.unique(np.round(res.targets, 6), axis=0))) < len(res.targets):
                # Not on the way: the end, where several nodes share a target.
                why = (f"in the last frame, {len(res.targets)} nodes of a rest on {targets} distinct targets on b, "
                       "several on one, which folds the outline there; give a about as many nodes as b (an "
                       "ellipse drawn with napari's tool has hundreds)")
            show_warning(f"{frame_runs(crossing)} {'crosses itself' if len(crossing) == 1 else 'cross themselves'}: "
                         f"{why}")

    def _on_errored(self, err: Exception):
        # simulate_contours catches the core's errors itself; this is a last resort.
        self.last_outcome = SimulationOutcome(error=err)
        self._fail(error_message(err))

    # ------------------------------------------------------------ export
    export_what = "frames"

    def export_table(self) -> dict:
        """The last simulation's frames as CSV columns (see :func:`frames_table`)."""
        if self.last_outcome is None or not self.last_outcome.ok:
            raise InputError("no simulation to save yet: press Run first")
        return frames_table(self.last_outcome.result)

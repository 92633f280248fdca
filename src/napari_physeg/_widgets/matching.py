"""The matching widget: a thin napari front end to :func:`napari_physeg.core.match`.

Three parts, from the least to the most napari-specific:

* :func:`compute_matching` - a plain function that matches two ``(N, 2)``
  contours with the core and returns a :class:`MatchingOutcome` (errors are
  caught and returned, never raised; a ``threading.Event`` cancels it); it
  runs in a worker thread, a script or a test alike. :func:`match_contours`
  is the same as a generator of progress percentages, for a worker thread.
* :func:`read_contour_pair` - reads shape ``i`` of one Shapes layer and shape
  ``j`` of another (or the same) layer into a :class:`ContourPair`: two
  contours in the data coordinates of the first layer, raising
  :class:`~napari_physeg._widgets.segmentation.InputError` with the fix for bad
  input. :func:`matching_layer_data` turns a matching into a napari layer data
  tuple: one line (or vector) per pair, from ``a`` to ``b``, coloured by the
  pair's matching cost, with the Matching itself in ``metadata["matching"]``
  (the simulation widget reuses it). The simulation widget uses
  :func:`read_contour_pair` too.
* :class:`MatchingWidget` - a magicgui ``Container`` (a
  :class:`~napari_physeg._widgets._worker.WorkerWidget`); Run matches in a
  ``napari.qt.threading.thread_worker`` with a napari progress bar; Cancel
  stops it.

All physics lives in :mod:`napari_physeg.core`.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass

import napari
import numpy as np
from magicgui.widgets import ComboBox, Container, Label, PushButton, SpinBox
from napari.layers import Layer, Shapes, Vectors
from napari.utils import progress
from napari.utils.colormaps import Colormap
from napari.utils.notifications import show_info

from ..core import MatchingCancelled, match
from ._layers import contours_to_shapes_data, image_transform_kwargs, shape_in_layer_coords
from ._worker import WorkerWidget
from .segmentation import PREVIEW_KEY, InputError

__all__ = [
    "COST_COLORMAP",
    "ContourPair",
    "MATCHING_KEY",
    "METHOD_TIPS",
    "MatchingOutcome",
    "MatchingWidget",
    "compute_matching",
    "match_contours",
    "contour_layer_choices",
    "cost_legend_html",
    "is_matching_layer",
    "matching_fits",
    "matching_layer_data",
    "read_contour_pair",
]

#: Key of the Matching in the output layer's metadata.
MATCHING_KEY = "matching"
#: Key in a layer's metadata that marks a simulation output (not a contour input).
SIMULATION_KEY = "simulation"
#: Colours of the match cost, low (good) to high (poor): ColorBrewer's RdYlBu
#: reversed, readable with the common colour-vision deficiencies and on a dark canvas.
COST_COLORMAP = Colormap(["#2c7bb6", "#abd9e9", "#ffffbf", "#fdae61", "#d7191c"], name="physeg match cost")
OUTPUT_LINES = "lines (Shapes)"
OUTPUT_VECTORS = "vectors"

METHOD_TIPS = {
    "order": "order (default): order-preserving dynamic programming around the two contours (Oliveira & "
             "Tavares 2008). Matches never cross and every node of a gets a partner; the most reliable "
             "for outlines of the same object.",
    "global": "global: optimal assignment on the cost matrix with fictitious nodes padding the smaller "
              "contour (Bastos & Tavares 2006); nodes left to a fictitious partner are matched to the best "
              "node between their neighbours' partners. Matches may cross.",
    "local": "local: mutual minima of the affinity (Shapiro & Brady 1992), as in the paper: node i of a and "
             "node j of b match only when each is the other's best. Fewer, surer pairs; the rest are "
             "reported as unmatched (the simulation moves them by eq. 18).",
}


def contour_layer_choices(viewer) -> list:
    """``(name, layer)`` of the Shapes layers that can hold input contours
    (not the outputs of the matching and simulation widgets, nor previews)."""
    skip = {MATCHING_KEY, SIMULATION_KEY, PREVIEW_KEY}
    return [(layer.name, layer) for layer in viewer.layers
            if isinstance(layer, Shapes) and not (set(layer.metadata) & skip)]


def pick_default_b(layer_a, index_a, layer_b, index_b, candidates) -> None:
    """Make a and b two different shapes when the choice is obvious.

    With b's layer equal to a's: another layer for b when a's layer holds a
    single shape, else another index. (magicgui widgets; changed in place.)
    """
    a, b = layer_a.value, layer_b.value
    if a is None or b is not a:
        return
    others = [layer for _, layer in candidates if layer is not a]
    if len(a.data) < 2 and others:
        layer_b.value = others[0]
    elif len(a.data) >= 2 and index_a.value == index_b.value:
        index_b.value = 1 if index_a.value == 0 else 0


class MatchingInputError(InputError):
    """Bad input to the matching (or simulation) widget."""


# --------------------------------------------------------------------------
# Reading two contours
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class ContourPair:
    """Two contours read from Shapes layers, in the first layer's data coordinates.

    Attributes
    ----------
    a, b : (N, 2) float64 ndarray
        ``(row, col)`` contours, closed, no repeated vertex.
    leading : tuple of float
        Leading (non-spatial) data coordinates of ``a`` in its layer (``()`` for 2D).
    transform : dict
        The first layer's transform, for output layers.
    a_layer, b_layer : str
        Names of the source layers.
    a_index, b_index : int
        Indices of the shapes in them.
    a_label, b_label : str
        Short names for output layers: the layer name, plus ``#index`` when
        the layer holds several shapes.
    """

    a: np.ndarray
    b: np.ndarray
    leading: tuple
    transform: dict
    a_layer: str
    a_index: int
    b_layer: str
    b_index: int
    a_label: str
    b_label: str


def _label(layer, index: int) -> str:
    return layer.name if len(layer.data) == 1 else f"{layer.name} #{index}"


def _read_one(layer, index: int, role: str, reference=None, world_point=None):
    if layer is None:
        raise MatchingInputError(
            f"no Shapes layer for contour {role}: open File > Open Sample > napari-physeg > Hand poses "
            "(matching), or draw closed shapes (polygon, ellipse, rectangle) in a Shapes layer and select it "
            f"in '{role}'")
    if not isinstance(layer, Shapes):
        raise MatchingInputError(f"{getattr(layer, 'name', layer)!r} is not a Shapes layer; select the layer "
                                 f"with contour {role}")
    n = len(layer.data)
    if n == 0:
        raise MatchingInputError(f"the Shapes layer {layer.name!r} ({role}) is empty: draw a closed shape "
                                 "(polygon, lasso, ellipse or rectangle) in it, then press Run again")
    if not 0 <= int(index) < n:
        raise MatchingInputError(f"{layer.name!r} has {n} shape(s), numbered 0 to {n - 1}: set the shape index "
                                 f"of {role} to one of them (got {index})")
    try:
        contour, leading = shape_in_layer_coords(layer, int(index), reference, world_point)
    except ValueError as err:
        raise MatchingInputError(f"contour {role}: {err}") from None
    if len(contour) < 3:
        raise MatchingInputError(f"contour {role} (shape {index} of {layer.name!r}) has {len(contour)} distinct "
                                 "vertices: a contour needs at least 3; redraw it as a polygon or ellipse")
    if not np.all(np.isfinite(contour)):
        raise MatchingInputError(f"contour {role} (shape {index} of {layer.name!r}) has non-finite "
                                 "coordinates (NaN); redraw it")
    return contour, leading


def read_contour_pair(layer_a, index_a: int, layer_b, index_b: int, *, world_point=None,
                      roles=("a", "b")) -> ContourPair:
    """Read two closed contours for matching or simulation.

    Both are expressed in the DATA coordinates of ``layer_a`` (``b`` goes
    through world coordinates, so the layers may have different transforms),
    so output layers with ``layer_a``'s transform overlay the inputs.

    Parameters
    ----------
    layer_a, layer_b : napari.layers.Shapes
        May be the same layer (then with different indices).
    index_a, index_b : int
        Which shape of each layer.
    world_point : sequence of float, optional
        The viewer's current position, for world axes a layer lacks.
    roles : tuple of str
        What to call the two contours in messages.

    Raises
    ------
    InputError
        With a message that says how to fix the input: no or empty layer, an
        index out of range, a line or a shape with fewer than 3 vertices, the
        same shape twice.
    """
    ra, rb = roles
    if layer_a is not None and layer_a is layer_b and int(index_a) == int(index_b):
        raise MatchingInputError(
            f"{ra} and {rb} are the same shape (shape {index_a} of {layer_a.name!r}): choose another shape "
            f"index for {rb}, or another layer (e.g. the sample 'Hand poses' gives two outlines)")
    a, leading = _read_one(layer_a, index_a, ra, None, world_point)
    b, _ = _read_one(layer_b, index_b, rb, layer_a, world_point)
    return ContourPair(
        a=a, b=b, leading=leading, transform=image_transform_kwargs(layer_a),
        a_layer=layer_a.name, a_index=int(index_a), b_layer=layer_b.name, b_index=int(index_b),
        a_label=_label(layer_a, index_a), b_label=_label(layer_b, index_b),
    )


# --------------------------------------------------------------------------
# The computation (a worker thread, a script, a test)
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class MatchingOutcome:
    """What :func:`compute_matching` returns.

    Attributes
    ----------
    matching : Matching or None
        The result (None after an error or a cancel).
    error : Exception or None
        The core's error, if any.
    seconds : float
        Wall time.
    cancelled : bool
        The run was stopped by the cancel event.
    """

    matching: object = None
    error: Exception | None = None
    seconds: float = 0.0
    cancelled: bool = False

    @property
    def ok(self) -> bool:
        return self.error is None and not self.cancelled and self.matching is not None


def compute_matching(a, b, *, method: str = "order", n_modes: int | None = None,
                     cancel: threading.Event | None = None, on_progress=None) -> MatchingOutcome:
    """Match contour ``a`` to contour ``b`` with :func:`napari_physeg.core.match`.

    ``n_modes`` of 0 or None chooses the number of modes automatically.
    ``on_progress(fraction)`` (optional) receives the core's progress, 0 to 1;
    setting ``cancel`` stops the core at its next stage. Errors of the core
    are returned in the outcome, not raised.
    """
    t0 = time.perf_counter()

    def callback(fraction):
        if on_progress is not None:
            on_progress(fraction)
        return not (cancel is not None and cancel.is_set())  # False stops the core

    try:
        m = match(a, b, method=method, n_modes=int(n_modes) if n_modes else None, callback=callback)
    except MatchingCancelled:
        return MatchingOutcome(cancelled=True, seconds=time.perf_counter() - t0)
    except Exception as err:  # reported to the user by the caller
        return MatchingOutcome(error=err, seconds=time.perf_counter() - t0)
    return MatchingOutcome(matching=m, seconds=time.perf_counter() - t0)


def match_contours(a, b, *, method: str = "order", n_modes: int | None = None,
                   cancel: threading.Event | None = None):
    """:func:`compute_matching` as a generator for a worker thread.

    The core runs in a helper thread and hands its progress over a queue;
    this generator yields it as whole percentages (so a worker can show it
    and be quit between two of them) and returns the
    :class:`MatchingOutcome`.
    """
    cancel = cancel if cancel is not None else threading.Event()
    updates: queue.SimpleQueue = queue.SimpleQueue()

    def target():
        try:
            outcome = compute_matching(a, b, method=method, n_modes=n_modes, cancel=cancel,
                                       on_progress=lambda f: updates.put(("progress", f)))
        except BaseException as err:  # never lost in this thread
            outcome = MatchingOutcome(error=err)
        updates.put(("done", outcome))

    helper = threading.Thread(target=target, name="napari-physeg match", daemon=True)
    helper.start()
    settled = False
    try:
        while True:
            kind, payload = updates.get()
            if kind == "done":
                settled = True
                return payload
            yield int(round(100 * payload))
    finally:
        if not settled:  # closed early (the worker was aborted): stop the helper as well
            cancel.set()
        helper.join()


def error_message(err: Exception) -> str:
    """A user-facing message for a failed matching, with what to do about it."""
    if isinstance(err, ValueError):
        return f"Matching failed: {err}"
    return (f"Matching failed with {type(err).__name__}: {err}. Try the defaults (method 'order', modes 0) "
            "and report this if it persists")


def matching_summary(m) -> str:
    """How many nodes were matched and how many were not, in words."""
    na, nb = m.affinity.shape
    return (f"{len(m.pairs)} pairs ({m.method}, {m.n_modes} modes): {len(m.pairs)} of {na} nodes of a matched, "
            f"{len(m.unmatched)} unmatched; {len(m.unmatched_b)} of {nb} nodes of b without a partner")


# --------------------------------------------------------------------------
# Matching -> layer
# --------------------------------------------------------------------------


def cost_limits(cost) -> tuple[float, float]:
    """Contrast limits of the cost colours: the range of this matching's costs."""
    cost = np.asarray(cost, dtype=float)
    if cost.size == 0:
        return 0.0, 1.0
    lo, hi = float(cost.min()), float(cost.max())
    if not hi > lo:
        hi = lo + max(abs(lo), 1.0) * 1e-6
    return lo, hi


def matching_layer_data(m, pair: ContourPair, *, kind: str = OUTPUT_LINES, name: str | None = None) -> tuple:
    """A napari layer data tuple of the correspondences of ``m``.

    One line (Shapes, ``kind="lines (Shapes)"``) or arrow (Vectors,
    ``kind="vectors"``) per pair, from node ``pairs[k, 0]`` of ``a`` to node
    ``pairs[k, 1]`` of ``b``, in ``a``'s layer data coordinates (on its slice)
    with that layer's transform. The colour is the pair's matching cost
    (:data:`COST_COLORMAP` over the range of the costs: blue = low = good,
    red = high = poor); ``features`` holds ``node_a``, ``node_b``, ``cost``
    and ``affinity`` (eq. 12). ``metadata["matching"]`` is the Matching, and
    the source layers, shape indices and contours are stored next to it.
    """
    pairs = np.asarray(m.pairs, dtype=int)
    a, b = pair.a[pairs[:, 0]], pair.b[pairs[:, 1]]
    cost = np.asarray(m.cost, dtype=float)
    features = {
        "node_a": pairs[:, 0],
        "node_b": pairs[:, 1],
        "cost": cost,
        "affinity": np.asarray(m.affinity, dtype=float)[pairs[:, 0], pairs[:, 1]],
    }
    metadata = {
        MATCHING_KEY: m,
        "a_layer": pair.a_layer, "a_index": pair.a_index,
        "b_layer": pair.b_layer, "b_index": pair.b_index,
        "a_contour": pair.a.copy(), "b_contour": pair.b.copy(),
        "leading": tuple(pair.leading),
    }
    meta = {
        "name": name or f"{pair.a_label} → {pair.b_label} matching",
        "features": features,
        "edge_color": "cost",
        "edge_colormap": COST_COLORMAP,
        "edge_contrast_limits": cost_limits(cost),
        "edge_width": 1.0,
        "opacity": 1.0,
        "metadata": metadata,
        **pair.transform,
    }
    if kind == OUTPUT_VECTORS:
        lead = np.asarray(pair.leading, dtype=np.float32)
        pos = np.column_stack([np.broadcast_to(lead, (len(a), lead.size)), a]) if lead.size else a
        proj = np.column_stack([np.zeros((len(a), lead.size)), b - a]) if lead.size else b - a
        data = np.stack([pos, proj], axis=1).astype(np.float32)
        return data, {**meta, "length": 1.0, "vector_style": "arrow"}, "vectors"
    lines = contours_to_shapes_data([np.stack([p, q]) for p, q in zip(a, b)], pair.leading)
    return lines, {**meta, "shape_type": "line"}, "shapes"


def is_matching_layer(layer) -> bool:
    """A layer made by :func:`matching_layer_data` (it holds a Matching in its metadata)."""
    return isinstance(layer, (Shapes, Vectors)) and layer.metadata.get(MATCHING_KEY) is not None


def matching_fits(metadata: dict, a, b, atol: float = 1e-3) -> bool:
    """Whether a matching layer's metadata was computed for the contours ``a`` and ``b``."""
    m = metadata.get(MATCHING_KEY)
    ca, cb = metadata.get("a_contour"), metadata.get("b_contour")
    if m is None or ca is None or cb is None:
        return False
    ca, cb = np.asarray(ca), np.asarray(cb)
    a, b = np.asarray(a), np.asarray(b)
    return (ca.shape == a.shape and cb.shape == b.shape and np.asarray(m.affinity).shape == (len(a), len(b))
            and bool(np.allclose(ca, a, atol=atol)) and bool(np.allclose(cb, b, atol=atol)))


def _hex(rgba) -> str:
    r, g, b = (int(round(float(x) * 255)) for x in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def cost_legend_html(lo: float | None = None, hi: float | None = None, n: int = 16) -> str:
    """A colour bar of :data:`COST_COLORMAP` as rich text for a Qt label."""
    colors = COST_COLORMAP.map(np.linspace(0.0, 1.0, n))
    bar = "".join(f'<span style="color:{_hex(c)}">█</span>' for c in colors)
    left = "low cost (good)" if lo is None else f"{lo:.3g} good"
    right = "high cost (poor)" if hi is None else f"{hi:.3g} poor"
    return f"{left} {bar} {right}"


# --------------------------------------------------------------------------
# The widget
# --------------------------------------------------------------------------

_TIPS = {
    "layer_a": "Shapes layer holding contour a (the one whose nodes are matched). Any closed shape: polygon, "
               "lasso, ellipse, rectangle or path. The lines are drawn in this layer's coordinates.",
    "index_a": "Which shape of layer a is contour a (0 = the first shape drawn).",
    "layer_b": "Shapes layer holding contour b (the target). May be the same layer as a, with another shape "
               "index.",
    "index_b": "Which shape of layer b is contour b. With one layer holding both contours, use 0 for a and 1 "
               "for b.",
    "method": "How correspondences are chosen from the cost matrix.\n" + "\n".join(METHOD_TIPS.values()),
    "n_modes": "Number of vibration modes in the modal affinity (eq. 12). 0 = automatic (6 to 12, cut at a gap "
               "of both spectra). Fewer modes: coarser, more robust; more: finer, more sensitive to noise.",
    "output": "Draw the correspondences as a Shapes layer of lines (can be saved as napari's shapes CSV) or "
              "as a Vectors layer of arrows from a to b (lighter for thousands of pairs).",
    "legend": "Colour of each line: its matching cost (modal affinity eq. 12 over the number of modes plus a "
              "curvature-difference term); 0 would be a perfect match. Blue = low cost = a confident match, "
              "red = high cost = doubtful. The scale spans this matching's lowest to highest cost; the values "
              "are in the layer's features (cost, affinity, node_a, node_b).",
    "run": "Match the nodes of a to those of b in the background and add a layer of correspondences.",
    "cancel": "Stop the running matching; no layer is added.",
}


class MatchingWidget(WorkerWidget):
    """Match the nodes of two contours by modal analysis.

    Parameters
    ----------
    viewer : napari.viewer.Viewer
        The viewer whose layers are used (napari passes it when the widget is
        opened from the Plugins or Layers > Register menu).

    Notes
    -----
    Press Run (or call :meth:`run`): the two contours are read (in layer a's
    data coordinates) and :func:`compute_matching` runs in a
    ``thread_worker`` with a napari progress bar (Cancel stops it). A layer
    "<a> → <b> matching" of lines (or vectors) coloured by cost is added, the
    counts of matched and unmatched nodes are shown in the widget and in a
    notification, and the Matching is stored in the layer's
    ``metadata["matching"]`` for the simulation widget.
    """

    def __init__(self, viewer: napari.viewer.Viewer):
        super().__init__(viewer)
        self.pair: ContourPair | None = None
        self.last_outcome: MatchingOutcome | None = None
        self.output_layer = None

        self._layer_a = ComboBox(label="contour a (layer)", choices=self._shapes_choices, tooltip=_TIPS["layer_a"])
        self._index_a = SpinBox(label="shape of a", value=0, min=0, max=100000, tooltip=_TIPS["index_a"])
        self._layer_b = ComboBox(label="contour b (layer)", choices=self._shapes_choices, tooltip=_TIPS["layer_b"])
        self._index_b = SpinBox(label="shape of b", value=0, min=0, max=100000, tooltip=_TIPS["index_b"])
        self._method = ComboBox(label="method", choices=list(METHOD_TIPS), value="order", tooltip=_TIPS["method"])
        self._n_modes = SpinBox(label="modes (0 = auto)", value=0, min=0, max=60, tooltip=_TIPS["n_modes"])
        self._output = ComboBox(label="output as", choices=[OUTPUT_LINES, OUTPUT_VECTORS], value=OUTPUT_LINES,
                                tooltip=_TIPS["output"])
        self._run_btn = PushButton(text="Run", tooltip=_TIPS["run"])
        self._cancel_btn = PushButton(text="Cancel", tooltip=_TIPS["cancel"], enabled=False)
        self._buttons = Container(widgets=[self._run_btn, self._cancel_btn], layout="horizontal", labels=False)
        self._legend = Label(value=cost_legend_html(), tooltip=_TIPS["legend"])
        self._status = Label(value="")
        self.extend([self._layer_a, self._index_a, self._layer_b, self._index_b, self._method, self._n_modes,
                     self._output, self._buttons, self._legend, self._status])
        self._set_item_tooltips()
        self._status.native.setWordWrap(True)  # long reports must not widen the dock

        self._connect_signals()
        self._pick_defaults()

    def _set_item_tooltips(self):
        try:
            from qtpy.QtCore import Qt

            combo = self._method.native
            for i, name in enumerate(METHOD_TIPS):
                combo.setItemData(i, METHOD_TIPS[name], Qt.ItemDataRole.ToolTipRole)
            self._legend.native.setTextFormat(Qt.TextFormat.RichText)
        except Exception:  # pragma: no cover - only decoration
            pass

    # ------------------------------------------------------------ choices
    def _shapes_choices(self, _widget=None):
        return contour_layer_choices(self.viewer)

    def _pick_defaults(self):
        pick_default_b(self._layer_a, self._index_a, self._layer_b, self._index_b, self._shapes_choices())

    def _on_layers_changed(self, event=None):
        try:
            self.reset_choices()
            self._pick_defaults()
        except RuntimeError:  # the Qt widget is gone (viewer closing)
            return

    # ------------------------------------------------------------ state
    def parameters(self) -> dict:
        """The current settings as keyword arguments of :func:`compute_matching`."""
        return {"method": self._method.value, "n_modes": self._n_modes.value or None}

    # ------------------------------------------------------------ run
    def run(self, *_):
        """Start matching in a background thread.

        Returns the worker, or None when the input is bad (an error
        notification then says why) or a run is already going on.
        """
        if self._running:
            return None
        try:
            pair = read_contour_pair(self._layer_a.value, self._index_a.value, self._layer_b.value,
                                     self._index_b.value, world_point=tuple(self.viewer.dims.point))
        except ValueError as err:
            self._fail(str(err))
            return None
        self.pair = pair
        self.last_outcome = None
        self.output_layer = None
        self._begin(f"Matching {len(pair.a)} to {len(pair.b)} nodes…")
        pbar = progress(total=100, desc=f"Matching {pair.a_label!r} to {pair.b_label!r}")
        return self._start(pbar, match_contours, pair.a, pair.b, **self.parameters(), cancel=self._cancel)

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _on_yielded(self, percent: int):
        if not self._gui_alive():
            self._on_destroyed()
            return
        self.n_updates += 1
        self._advance(percent)

    def _on_returned(self, outcome: MatchingOutcome):
        self.last_outcome = outcome
        if not self._gui_alive():
            return
        if outcome.cancelled:
            self._status.value = "Cancelled: no layer added"
            show_info("Matching cancelled: no layer added")
            return
        if outcome.error is not None:
            self._fail(error_message(outcome.error))
            return
        m, pair = outcome.matching, self.pair
        try:
            data, meta, kind = matching_layer_data(m, pair, kind=self._output.value)
            self.output_layer = self.viewer.add_layer(Layer.create(data, meta, kind))
        except Exception as err:  # never leave the user with a silent failure
            self._fail(f"Could not add the matching layer: {type(err).__name__}: {err}")
            return
        lo, hi = cost_limits(m.cost)
        self._legend.value = cost_legend_html(lo, hi)
        na = len(pair.a)
        self._status.value = (f"{len(m.pairs)} of {na} nodes of a matched, {len(m.unmatched)} unmatched "
                              f"({outcome.seconds:.2f} s)")
        show_info(f"Matching {pair.a_label!r} → {pair.b_label!r}: {matching_summary(m)}")

    def _on_errored(self, err: Exception):
        # compute_matching catches the core's errors itself; this is a last resort.
        self.last_outcome = MatchingOutcome(error=err)
        self._fail(error_message(err))

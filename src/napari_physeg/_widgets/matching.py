"""The matching widget: a thin napari front end to :func:`napari_physeg.core.match`.

Three parts, from the least to the most napari-specific:

* :func:`match_contours` - a generator for a worker thread that runs the
  core's :func:`~napari_physeg.core.iter_match` in that thread and returns a
  :class:`MatchingOutcome` (errors are caught and returned, never raised; a
  ``threading.Event`` cancels it). :func:`compute_matching` runs it to its
  end, for scripts and tests.
* :func:`matching_layer_data` turns a matching into a napari layer data
  tuple: one line (or vector) per pair, from ``a`` to ``b``, coloured by the
  pair's matching cost, with the Matching itself in ``metadata["matching"]``
  (the simulation widget reuses it); :func:`matching_table` gives the pairs
  and their costs as rows for a CSV file. The two contours are read by
  :func:`~._inputs.read_contour_pair`.
* :class:`MatchingWidget` - a magicgui ``Container`` (a
  :class:`~napari_physeg._widgets._worker.WorkerWidget`); Run matches in a
  ``napari.qt.threading.thread_worker`` with a napari progress bar; Cancel
  stops it; "Save pairs as CSV" writes the last matching.

All physics lives in :mod:`napari_physeg.core`.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from functools import partial

import napari
import numpy as np
from magicgui.widgets import CheckBox, ComboBox, Label, PushButton, SpinBox
from napari.utils.colormaps import Colormap
from napari.utils.notifications import show_info

from ..core import iter_match, match
from ..core.tracking import DISPLACEMENT_WEIGHT as IN_PLACE_WEIGHT  # as between the frames of a movie
from ._inputs import (
    MATCHING_KEY,
    ContourPair,
    InputError,
    contour_layer_choices,
    core_default,
    index_in_range,
    is_matching_layer,
    matching_fits,
    pick_default_b,
    read_contour_pair,
)
from ._layers import contours_to_shapes_data
from ._worker import WorkerWidget, relay, run_to_completion

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
    "matching_table",
    "read_contour_pair",
]

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


def match_contours(a, b, *, method: str = core_default(match, "method"), n_modes: int | None = None,
                   displacement_weight: float = core_default(match, "displacement_weight"),
                   cancel: threading.Event | None = None):
    """Match contour ``a`` to contour ``b``; a generator for a worker thread.

    The core's :func:`~napari_physeg.core.iter_match` runs right here (see
    :func:`~._worker.relay`): it yields the core's
    :class:`~napari_physeg.core.MatchingProgress` and stops at its next stage
    once ``cancel`` is set. ``n_modes`` of 0 or None chooses the number of
    modes automatically; ``displacement_weight`` > 0 keeps each node near
    where it was (see :func:`~napari_physeg.core.match`). Returns a
    :class:`MatchingOutcome`: the core's errors are caught and returned in
    it, not raised.
    """
    cancel = cancel if cancel is not None else threading.Event()
    t0 = time.perf_counter()
    try:
        m = yield from relay(iter_match(a, b, method=method, n_modes=int(n_modes) if n_modes else None,
                                        displacement_weight=float(displacement_weight)), cancel)
    except Exception as err:  # reported to the user by the caller
        return MatchingOutcome(error=err, seconds=time.perf_counter() - t0)
    if m.stop_reason == "cancelled":
        return MatchingOutcome(cancelled=True, seconds=time.perf_counter() - t0)
    return MatchingOutcome(matching=m, seconds=time.perf_counter() - t0)


def compute_matching(a, b, *, method: str = core_default(match, "method"), n_modes: int | None = None,
                     displacement_weight: float = core_default(match, "displacement_weight"),
                     cancel: threading.Event | None = None, on_progress=None) -> MatchingOutcome:
    """:func:`match_contours` run to its end, for scripts and tests;
    ``on_progress(fraction)`` (optional) sees the core's progress, 0 to 1."""
    report = None if on_progress is None else (lambda state: on_progress(state.fraction))
    return run_to_completion(match_contours(a, b, method=method, n_modes=n_modes,
                                            displacement_weight=displacement_weight, cancel=cancel), report)


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
        "name": name or f"{pair.a_label} → {pair.b_label} matching ({m.method})",
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


def matching_table(m, pair: ContourPair) -> dict:
    """The pairs of ``m`` as columns for a CSV file: ``node_a``, ``node_b``,
    the nodes' coordinates (``a_row``, ``a_col``, ``b_row``, ``b_col``, in
    ``a``'s layer data coordinates), ``cost`` and ``affinity`` (eq. 12)."""
    pairs = np.asarray(m.pairs, dtype=int)
    a, b = pair.a[pairs[:, 0]], pair.b[pairs[:, 1]]
    return {"node_a": pairs[:, 0], "node_b": pairs[:, 1], "a_row": a[:, 0], "a_col": a[:, 1],
            "b_row": b[:, 0], "b_col": b[:, 1], "cost": np.asarray(m.cost, dtype=float),
            "affinity": np.asarray(m.affinity, dtype=float)[pairs[:, 0], pairs[:, 1]]}


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
               "lasso, ellipse, rectangle or path; or a Points layer, its points in the order clicked. The "
               "lines are drawn in this layer's coordinates.",
    "index_a": "Which shape of layer a is contour a (0 = the first shape drawn).",
    "layer_b": "Shapes layer holding contour b (the target). May be the same layer as a, with another shape "
               "index.",
    "index_b": "Which shape of layer b is contour b. With one layer holding both contours, use 0 for a and 1 "
               "for b.",
    "method": "How correspondences are chosen from the cost matrix.\n" + "\n".join(METHOD_TIPS.values()),
    "n_modes": "Number of vibration modes in the modal affinity (eq. 12). 0 = automatic (6 to 12, cut at a gap "
               "of both spectra). Fewer modes: coarser, more robust; more: finer, more sensitive to noise.",
    "in_place": "The two contours lie in one frame of reference (consecutive frames or z slices of one "
                "object): keep each node near where it was. Modes and curvature are blind to where the shapes "
                "are, so a near-round cell can otherwise be matched half a turn off. Leave off to match shapes "
                "wherever they are, turned or moved (the paper's invariant matching).",
    "output": "Draw the correspondences as a Shapes layer of lines (can be saved as napari's shapes CSV) or "
              "as a Vectors layer of arrows from a to b (lighter for thousands of pairs).",
    "legend": "Colour of each line: its matching cost (modal affinity eq. 12 over the number of modes plus "
              "curvature-difference and inner-distance shape-context terms); 0 would be a perfect match. Blue = low cost = a confident match, "
              "red = high cost = doubtful. The scale spans this matching's lowest to highest cost; the values "
              "are in the layer's features (cost, affinity, node_a, node_b).",
    "run": "Match the nodes of a to those of b in the background and add a layer of correspondences.",
    "cancel": "Stop the running matching; no layer is added.",
    "export": "Save the last matching's pairs as a CSV file: node_a, node_b, their coordinates, cost and "
              "affinity, one row per pair (napari's own CSV export of the lines drops these columns).",
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
        self._method = ComboBox(label="method", choices=list(METHOD_TIPS), value=core_default(match, "method"),
                                tooltip=_TIPS["method"])
        self._n_modes = SpinBox(label="modes (0 = auto)", value=0, min=0, max=60, tooltip=_TIPS["n_modes"])
        self._in_place = CheckBox(text="in place (keep nodes near where they were)", value=False,
                                  tooltip=_TIPS["in_place"])
        self._output = ComboBox(label="output as", choices=[OUTPUT_LINES, OUTPUT_VECTORS], value=OUTPUT_LINES,
                                tooltip=_TIPS["output"])
        self._run_btn = PushButton(text="Run", tooltip=_TIPS["run"])
        self._cancel_btn = PushButton(text="Cancel", tooltip=_TIPS["cancel"], enabled=False)
        self._export_btn = PushButton(text="Save CSV…", tooltip=_TIPS["export"], enabled=False)
        self._legend = Label(value=cost_legend_html(), tooltip=_TIPS["legend"])
        self._status = Label(value="")
        self._lay_out([self._layer_a, self._index_a, self._layer_b, self._index_b, self._method, self._output,
                       self._legend], advanced=[self._in_place, self._n_modes], buttons=[self._export_btn])
        self._export_btn.changed.connect(self._ask_export)
        for layer, index in ((self._layer_a, self._index_a), (self._layer_b, self._index_b)):
            layer.changed.connect(partial(index_in_range, layer, index))
        self._set_item_tooltips()
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
        return {"method": self._method.value, "n_modes": self._n_modes.value or None,
                "displacement_weight": IN_PLACE_WEIGHT if self._in_place.value else 0.0}

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
        self._export_btn.enabled = False
        self._begin(f"Matching {len(pair.a)} to {len(pair.b)} nodes…")
        total = 100
        return self._start(total, match_contours, pair.a, pair.b, **self.parameters(), cancel=self._cancel)

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _must_show(self, state) -> bool:
        return state.fraction >= 1.0  # the bar's end

    def _on_yielded(self, state):
        if not self._gui_alive():
            self._on_destroyed()
            return
        self.n_updates += 1
        self._advance(int(round(100 * state.fraction)))

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
            (self.output_layer,) = self._put_results([matching_layer_data(m, pair, kind=self._output.value)])
        except Exception as err:  # never leave the user with a silent failure
            self._fail(f"Could not add the matching layer: {type(err).__name__}: {err}")
            return
        self._export_btn.enabled = True
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

    # ------------------------------------------------------------ export
    export_what = "pairs"

    def export_table(self) -> dict:
        """The last matching's pairs as CSV columns (see :func:`matching_table`)."""
        if self.last_outcome is None or not self.last_outcome.ok:
            raise InputError("no matching to save yet: press Run first")
        return matching_table(self.last_outcome.matching, self.pair)

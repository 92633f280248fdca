"""What the segmentation, matching and simulation widgets share: running one
computation at a time in a ``napari.qt.threading.thread_worker``.

The computations themselves are plain functions or generators that know
nothing about Qt. Around them every widget does the same: disable Run (and
enable Cancel) while the worker runs, feed a napari progress bar, report
errors as notifications, and make sure that closing the viewer during a run
neither leaves a thread running nor touches deleted Qt widgets.
"""

from __future__ import annotations

import functools
import re
import threading
import time
from collections import deque

import numpy as np

from magicgui.widgets import Container, ProgressBar
from napari.qt.threading import GeneratorWorker, thread_worker
from napari.utils.notifications import show_error, show_warning
from qtpy.QtCore import QEvent, QObject
from threadpoolctl import threadpool_limits

from ..core._drain import drain
from ._layers import created_layer, write_csv

__all__ = ["WorkerWidget", "ask_save_path", "relay", "run_to_completion"]

#: Layer arguments a result layer is made with and keeps when a later run's
#: result takes it over (see WorkerWidget._take_over).
_GIVEN_AT_CREATION = frozenset({"ndim", "shape_type"})


#: At most this share of a run's time goes to showing its updates (previews, progress): the CPU
#: time of every thread but the worker's, the GUI thread's and those software OpenGL paints in.
PREVIEW_SHARE = 0.1
#: GUI time (s) since the last update shown below which the next is always shown.
CHEAP_DRAW = 0.01
#: Least height of a widget's scroll area (px): a row or two of controls.
SCROLL_MIN_HEIGHT = 40


def _holds(layer, key: str, value) -> bool:
    """Whether ``layer``'s ``key`` already has ``value`` (a transform the
    preview was made with): set again, each refreshes the layer, and a
    preview of a thousand nodes took over by its result held the GUI up."""
    if key in ("features", "metadata") or key.endswith("_color"):
        return False
    current = getattr(layer, key, None)
    if key == "affine":
        current = getattr(current, "affine_matrix", current)
    try:
        return bool(np.array_equal(np.asarray(current), np.asarray(value)))
    except (TypeError, ValueError):
        return False


class WorkerWidget(Container):
    """A magicgui ``Container`` that runs its computation in a background worker.

    A subclass builds its controls, among them ``_run_btn``, ``_status`` (a
    Label) and, if its computation can be stopped, ``_cancel_btn``; it lays
    them out with :meth:`_lay_out` and calls :meth:`_connect_signals`. Its ``run`` reads the input, then calls
    :meth:`_begin` and :meth:`_start`; it handles the results in
    ``_on_returned`` and ``_on_errored`` and, for a generator, the updates in
    ``_on_yielded``. The widget's ``_on_layers_changed`` is called when the
    viewer's layers change.

    A computation that can be cancelled takes ``cancel=self._cancel`` (a
    ``threading.Event``) and returns early once it is set: it runs the core's
    generators through :func:`relay`, which tells them to stop.
    """

    #: Widgets whose computation cannot be stopped have no Cancel button.
    _cancel_btn = None

    #: Whether the core's warnings, raised in the worker thread (where napari
    #: does not see them), are shown as napari warnings. A widget that shows
    #: them its own way (from the result) sets it False.
    relay_warnings = True

    def __init__(self, viewer):
        super().__init__(labels=True)
        self.viewer = viewer
        self.worker = None
        self._cancel = threading.Event()
        self._progress_value = 0
        self.n_updates = 0  # progress updates shown in the last run
        self.n_received = 0  # and received (some are not shown when the GUI is busy)
        self._running = False
        self._delivering = False
        self._last_draw = None  # (wall, display CPU) seconds when an update was last shown
        self._worker_clock = None  # the CPU-time clock of the worker's thread
        self._pending = deque()  # worker signals waiting for the one before to be handled
        self._results_put = []  # (layer, the name it was given) for the last run's result layers

    def _lay_out(self, controls, advanced=(), buttons=()):
        """``controls``, then a collapsed "Advanced" section holding ``advanced``,
        in a scroll area (so that every widget docked fits a laptop screen);
        below it, always in view, Run, Cancel and ``buttons`` in a row, and the status.

        napari docks a magicgui widget's ``native`` widget, which for a
        ``scrollable`` Container is the scrolled content, not the scroll area
        (magicgui#431): so the scroll area is placed inside this Container.
        """
        from qtpy.QtCore import Qt
        from qtpy.QtWidgets import QFrame, QScrollArea
        from superqt import QCollapsible

        self._controls = Container(widgets=list(controls), labels=True)
        self._advanced = Container(widgets=list(advanced), labels=True)
        self.advanced_section = None
        if advanced:
            self.advanced_section = QCollapsible("Advanced")
            self.advanced_section.addWidget(self._advanced.native)
            self._controls.native.layout().addWidget(self.advanced_section)
        self._controls.native.layout().addStretch(1)
        self.scroll_area = QScrollArea()
        self.scroll_area.setWidgetResizable(True)
        self.scroll_area.setFrameShape(QFrame.Shape.NoFrame)
        self.scroll_area.setHorizontalScrollBarPolicy(Qt.ScrollBarPolicy.ScrollBarAlwaysOff)
        self.scroll_area.setWidget(self._controls.native)
        # Compact footer: with all four widgets docked on a 1366 x 768 screen
        # each gets ~150 px; the scroll area takes what is left.
        self.scroll_area.setMinimumHeight(SCROLL_MIN_HEIGHT)
        buttons = [self._run_btn] + ([self._cancel_btn] if self._cancel_btn is not None else []) + list(buttons)
        self._buttons = Container(widgets=buttons, layout="horizontal", labels=False)
        self._buttons.margins = (0, 0, 0, 0)
        self.margins = (4, 2, 4, 2)
        self.progress_bar = ProgressBar(value=0, min=0, max=1, visible=False)
        self.extend([self._buttons, self.progress_bar, self._status])
        self.native.layout().insertWidget(0, self.scroll_area, 1)
        self.native.layout().setSpacing(2)
        self._status.native.setWordWrap(True)  # long reports must not widen the dock

    # ------------------------------------------------------------ export (widgets with a "Save CSV…" button)
    #: What the CSV holds, for the file name; a widget that exports sets it and defines export_table().
    export_what = ""

    def export_name(self) -> str:
        """The suggested file name's stem: what the CSV holds, and of which layers."""
        pair = getattr(self, "pair", None)
        return f"{pair.a_label} to {pair.b_label} {self.export_what}" if pair else self.export_what

    def _ask_export(self, *_):
        # Layer names may hold what a file name cannot ("A/B: cells" named a folder that is not there).
        name = re.sub(r'[\\/:*?"<>|]+', "_", self.export_name()).strip(" .") or "export"
        path = ask_save_path(self, f"Save the {self.export_what} as CSV", f"{name}.csv")
        if not path:
            return
        try:
            self.export_csv(path)
        except OSError as err:  # a missing folder, a read-only share, a file open elsewhere
            self._fail(f"Could not save {path}: {err.strerror or err}; choose another place")

    def export_csv(self, path) -> None:
        """Write the last result's :meth:`export_table` to ``path`` as CSV."""
        table = self.export_table()
        write_csv(path, table)
        self._status.value = f"Saved {len(next(iter(table.values())))} rows of {self.export_what} to {path}"

    def controls(self) -> list:
        """The parameter widgets: those in the scroll area, then the Advanced ones."""
        return [*self._controls, *self._advanced]

    def reset_choices(self, *_):
        """Refresh every layer choice, in the scroll area and the Advanced section too."""
        super().reset_choices()
        for part in (getattr(self, "_controls", None), getattr(self, "_advanced", None)):
            if part is not None:
                part.reset_choices()

    def _add_preview(self, layer):
        """Add a run's preview ``layer`` without taking the user's selection.

        napari selects every layer it adds, and each change of the active
        layer rebuilds the layer controls; with the selection's events held
        back while the layer goes in and the selection is put back, nothing
        changes for the user and the run starts sooner (0.03-0.05 s a run
        under software OpenGL)."""
        selection = self.viewer.layers.selection
        active, selected = selection.active, set(selection)
        with selection.events.active.blocker(), selection.events.changed.blocker():
            self.viewer.add_layer(layer)
            selection.clear()
            selection.update(selected)
            selection.active = active
        return layer

    def _add_result(self, data, meta: dict, kind: str, preview=None):
        """Add a result layer; a Shapes result takes over the run's ``preview`` layer, if any.

        napari runs a full ``gc.collect()`` whenever a layer is removed (a
        third of a second in a busy viewer, with the GUI frozen), so the
        preview is not removed and replaced: it becomes the result, with its
        data, style, features, metadata and name.
        """
        if kind != "shapes" or preview is None or preview not in self.viewer.layers:
            return self.viewer.add_layer(created_layer(data, meta, kind))
        return self._take_over(preview, data, meta, kind)

    def _take_over(self, layer, data, meta: dict, kind: str, keep_visibility: bool = False):
        """``layer`` (of ``kind``) with a result's ``data`` and ``meta``: the layer
        itself, or a new one in its place where napari cannot take them
        (``keep_visibility``: leave it shown or hidden as the user left it)."""
        if kind == "shapes" and self.viewer.dims.ndisplay != 2:
            # The user went to the 3D view during the run: napari takes no new
            # data on a Shapes layer there (the results were lost), but adds a
            # new layer. (The collection a removal runs is the lesser harm.)
            return self._replaced(layer, data, meta, kind)
        try:
            if kind == "shapes":
                shape_type = meta.get("shape_type", "polygon")
                layer.data = (data, [shape_type] * len(data) if isinstance(shape_type, str) else shape_type)
            else:
                layer.data = data
        except RuntimeError:  # a face napari cannot triangulate: see created_layer
            return self._replaced(layer, data, meta, kind)
        # The features first: a colour may name one (a matching's lines are coloured by their cost).
        for key in sorted(meta, key=lambda key: (key != "features", key.endswith("_color"))):
            if key in _GIVEN_AT_CREATION or (keep_visibility and key == "visible") or _holds(layer, key, meta[key]):
                continue
            if kind == "shapes" and key in ("edge_color", "face_color"):
                self._set_shape_colours(layer, key, meta[key])
            else:
                setattr(layer, key, meta[key])
        return layer

    @staticmethod
    def _set_shape_colours(layer, key: str, value) -> None:
        """A feature's name, one colour, or one per shape; shapes drawn next get the first colour."""
        from napari.utils.colormaps.standardize_color import transform_color

        if isinstance(value, str) and value in layer.features:
            setattr(layer, key, value)
            return
        colours = transform_color(value)
        setattr(layer, key, colours[0] if len(colours) == 1 else colours)
        setattr(layer, f"current_{key}", colours[0])

    def _replaced(self, layer, data, meta: dict, kind: str):
        """A new layer made of ``data`` and ``meta``, where ``layer`` was."""
        index = self.viewer.layers.index(layer)
        self.viewer.layers.remove(layer)
        new = created_layer(data, meta, kind)
        self.viewer.layers.insert(min(index, len(self.viewer.layers)), new)
        return new

    def _put_results(self, layer_data, preview=None) -> list:
        """Add a run's result layers (``(data, meta, kind)`` tuples) and return them.

        A run done again (its layers' names say its inputs and main choice,
        a material or a method) updates the layers the last run added of
        those names, in place, as magicgui updates the layer of the name a
        function returns: each tracking run added five layers of its own,
        and a user who tried a few settings had a list of look-alikes to
        weed out. A layer the user renamed, or removed, is theirs: it is
        left alone. A Shapes result that finds no such layer takes over the
        run's Shapes ``preview`` (see _add_result); a preview left over is
        removed, and so are the last run's layers that this run has no
        result for.
        """
        earlier = {(name, layer._type_string): layer for layer, name in self._results_put
                   if layer in self.viewer.layers and layer.name == name}
        put, again = [], False
        for data, meta, kind in layer_data:
            layer = earlier.pop((meta.get("name"), kind), None)
            if layer is not None:
                put.append(self._take_over(layer, data, meta, kind, keep_visibility=True))
                again = True
            else:
                put.append(self._add_result(data, meta, kind, preview))
                preview = None if kind == "shapes" else preview
        for layer in earlier.values() if again else ():  # the same run had nothing to show there this time
            self.viewer.layers.remove(layer)
        if preview is not None and preview in self.viewer.layers:
            self.viewer.layers.remove(preview)
        self._results_put = [(layer, layer.name) for layer in put]
        return put

    def _connect_signals(self):
        self._run_btn.changed.connect(self.run)
        if self._cancel_btn is not None:
            self._cancel_btn.changed.connect(self.cancel)
        self.native.destroyed.connect(self._on_destroyed)
        self._dock_watcher = _DockWatcher(self._on_undocked)
        self.native.installEventFilter(self._dock_watcher)
        events = self.viewer.layers.events
        for name in ("inserted", "removed", "reordered", "renamed"):
            emitter = getattr(events, name, None)
            if emitter is not None:
                emitter.connect(self._on_layers_changed)

    # ------------------------------------------------------------ state
    @property
    def is_running(self) -> bool:
        """True while a computation runs in the background."""
        return self._running

    def _fail(self, message: str):
        """Say what went wrong, in full, in the widget (and as a notification)."""
        self._status.value = message
        show_error(message)

    # ------------------------------------------------------------ run
    def _begin(self, status: str):
        """Mark a run as started; after this ``self._cancel`` is the new run's event."""
        self._cancel = threading.Event()  # a fresh one: the last run's stays set
        self._running = True
        self._run_btn.enabled = False
        if self._cancel_btn is not None:
            self._cancel_btn.enabled = True
        self._status.value = status
        self._progress_value = 0
        self._last_draw = None
        self.n_updates = self.n_received = 0

    def _start(self, total: int, function, *args, **kwargs):
        """Run ``function(*args, **kwargs)`` in a worker whose progress goes
        from 0 to ``total`` on the widget's progress bar; return the worker.

        The widget's own bar, not napari's activity dock: napari's animates a
        busy indicator in the status bar for as long as it is open, and the
        main window's repaints at ~30 Hz held the GIL longer than the run
        itself (a 3 s segmentation took 7.7 s in the GUI on software OpenGL).
        """
        self.progress_bar.max = max(int(total), 1)
        self.progress_bar.value = 0
        self.progress_bar.visible = True
        self._worker_clock = None
        worker = thread_worker(_in_worker(function, self._note_worker_clock), start_thread=False)(*args, **kwargs)
        if isinstance(worker, GeneratorWorker):  # only generators report progress
            worker.yielded.connect(self._on_yielded_once)
        worker.returned.connect(self._on_returned_in_order)
        worker.errored.connect(self._on_errored_in_order)
        if self.relay_warnings:
            worker.warned.connect(self._on_warned_in_order)
        worker.finished.connect(self._on_finished_in_order)
        self.worker = worker
        worker.start()
        return worker

    def cancel(self, *_):
        """Stop the running computation (each widget says what it keeps)."""
        if self._running and self._cancel_btn is not None:
            self._cancel.set()
            self._status.value = "Cancelling…"

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _gui_alive(self) -> bool:
        """False once Qt has deleted this widget (e.g. the viewer was closed
        during a run), or its dock was closed (see _DockWatcher)."""
        try:
            self.native.isHidden()
        except RuntimeError:
            return False
        return not getattr(self, "_dock_watcher", None) or not self._dock_watcher.closed

    def _on_undocked(self):
        """The dock was closed: the run stops, and adds nothing (an outside
        tester saw its layers appear seconds later, with nothing left to show
        or cancel them)."""
        if self.is_running:
            self._on_destroyed()

    def _deliver(self, slot, *args):
        """Run the worker's signal handlers one at a time, in the order the
        signals came. napari's progress bar (with the activity dock open)
        processes Qt events, so the next update, the run's result or its end
        can be delivered inside a handler; it waits here and runs after,
        instead of recursing (until RecursionError) or overtaking the updates
        before it (the end of a run handled before its result)."""
        self._pending.append((slot, args))
        if self._delivering:
            return
        self._delivering = True
        try:
            while self._pending:
                slot, args = self._pending.popleft()
                slot(*args)
        finally:
            self._delivering = False

    def _note_worker_clock(self, clock):
        self._worker_clock = clock  # (an int: set from the worker thread at once)

    def _display_cpu(self) -> float:
        """CPU seconds used by this process apart from its worker: the GUI
        thread's and those software OpenGL paints in (the GUI thread's alone
        where the worker's cannot be read)."""
        if self._worker_clock is not None:
            try:
                return time.process_time() - time.clock_gettime(self._worker_clock)
            except OSError:
                self._worker_clock = None
        return time.thread_time()

    def _on_yielded_once(self, update):
        self._deliver(self._draw_if_due, update)

    def _draw_if_due(self, update):
        """Show an update (``_on_yielded``) when the GUI can afford it.

        Drawing a preview and moving the progress bar repaint the window,
        which takes tens of milliseconds (more with software OpenGL), in the
        GUI thread and holding the GIL the worker needs, and in software
        OpenGL's own threads, which take the worker's CPU on a small machine.
        An update is shown only while everything but the worker
        (:meth:`_display_cpu`) has used at most PREVIEW_SHARE of the time
        since the last one shown; the others are dropped (each supersedes the
        last), unless :meth:`_must_show` says otherwise.
        """
        self.n_received += 1
        self._note_update(update)
        now, cpu = time.perf_counter(), self._display_cpu()
        if self._last_draw is not None and not self._must_show(update):
            wall, used = now - self._last_draw[0], cpu - self._last_draw[1]
            if used > max(PREVIEW_SHARE * wall, CHEAP_DRAW):
                return
        self._last_draw = (now, cpu)
        self._on_yielded(update)

    def _must_show(self, update) -> bool:
        """Whether ``update`` is shown even when the GUI is busy (a subclass may say so)."""
        return False

    def _note_update(self, update) -> None:
        """See every update, shown or dropped (a subclass may keep what the next one shown must draw)."""

    def _on_returned_in_order(self, result):
        self._deliver(self._on_returned, result)

    def _on_errored_in_order(self, err):
        self._deliver(self._on_errored, err)

    def _on_warned_in_order(self, showwarning_args):
        self._deliver(show_warning, str(showwarning_args[0]))

    def _on_finished_in_order(self):
        self._deliver(self._on_finished)

    def _on_destroyed(self, *_):
        self._cancel.set()
        if self.worker is not None:
            self.worker.quit()

    def _record_progress(self, value: int) -> int:
        """Note that the run reached ``value``; return how far the bar must move (0: not forward)."""
        delta = max(value - self._progress_value, 0)
        self._progress_value = max(value, self._progress_value)
        return delta

    def _advance(self, value: int):
        """Move the progress bar forward to ``value`` (never back)."""
        if self._record_progress(value):
            self.progress_bar.value = min(self._progress_value, self.progress_bar.max)

    def _on_finished(self):
        self._cancel.set()  # stops a helper thread of the computation too if the worker was aborted
        self.worker = None
        self._running = False
        try:
            self.progress_bar.visible = False
            self._run_btn.enabled = True
            if self._cancel_btn is not None:
                self._cancel_btn.enabled = False
        except RuntimeError:  # the viewer or this widget was closed during the run
            pass


class _DockWatcher(QObject):
    """Watches a widget for being taken out of its dock: napari's
    ``remove_dock_widget`` (the dock's close button) leaves the widget alive,
    with no parent, so Qt's ``destroyed`` never comes. ``closed`` holds until
    the widget is docked again."""

    def __init__(self, on_closed):
        super().__init__()
        self._on_closed, self._docked, self.closed = on_closed, False, False

    def eventFilter(self, watched, event):  # noqa: N802 - Qt's name
        if event.type() == QEvent.Type.ParentChange:
            if watched.parent() is not None:
                self._docked, self.closed = True, False
            elif self._docked:
                self._docked, self.closed = False, True
                self._on_closed()
        return False


def _in_worker(generator_function, note_clock):
    """``generator_function`` as the worker runs it: with BLAS/LAPACK limited
    to one thread, having first passed the worker thread's CPU-time clock
    (or None where the platform has none) to ``note_clock``.

    The core's dense problems are small (at most a few hundred unknowns):
    OpenBLAS's threads only spin against the GUI thread and the worker, and
    a LAPACK call holds the GIL meanwhile. On a busy 2-core machine a
    128 x 128 eigenproblem took 0.5 s instead of 2 ms, and the GUI froze
    that long. The worker's CPU time tells the GUI what the rest of the
    process costs (see ``WorkerWidget._draw_if_due``).
    """

    @functools.wraps(generator_function)
    def run(*args, **kwargs):
        try:
            note_clock(time.pthread_getcpuclockid(threading.get_ident()))
        except (AttributeError, OSError):  # not on every platform (macOS, Windows)
            note_clock(None)
        with threadpool_limits(limits=1, user_api="blas"):
            return (yield from generator_function(*args, **kwargs))

    return run


def ask_save_path(widget, title: str, suggestion: str) -> str:
    """A file name from Qt's save dialog ("" when the user cancels)."""
    from qtpy.QtWidgets import QFileDialog

    path, _ = QFileDialog.getSaveFileName(widget.native, title, suggestion, "CSV files (*.csv)")
    return path


def relay(run, cancel: threading.Event, interval: float = 0.0, wrap=None):
    """Drive the core's generator ``run`` (``iter_segment``, ``iter_match``,
    ``iter_simulate``) in this thread, the worker's: no helper thread, no queue.

    Yields its states, ``wrap(state)`` if given, at most one every ``interval``
    seconds (so that the GUI draws previews at the pace it can); once
    ``cancel`` is set the core is sent ``True`` (stop) after its current step,
    and its result then says ``stop_reason="cancelled"``. Returns the core's
    result; the core's errors propagate.
    """
    last = -np.inf
    try:
        state = next(run)
        while True:
            now = time.perf_counter()
            if now - last >= interval:
                last = now
                yield state if wrap is None else wrap(state)
            state = run.send(cancel.is_set())
    except StopIteration as done:
        return done.value


def run_to_completion(generator, on_progress=None):
    """Drive a computation's generator (``segment_contours``, ``simulate_contours``) synchronously.

    For scripts and tests: ``on_progress`` (if given) receives each yielded
    update; the generator's return value (its outcome) is returned. The
    core's own driver does it (the widgets' generators stop on their cancel
    event, not on what is sent to them).
    """
    return drain(generator, on_progress)

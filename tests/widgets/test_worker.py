"""The worker plumbing's live-update throttle (``_widgets/_worker.py``)."""

import threading
import time

import numpy as np
import pytest

pytest.importorskip("napari")

from napari_physeg._widgets import _worker  # noqa: E402
from napari_physeg._widgets.segmentation import SegmentationProgress, SegmentationWidget  # noqa: E402


def _update(index, step, done=False, total=2):
    return SegmentationProgress(index=index, total=total, step=step, max_steps=100,
                                contour=np.zeros((3, 2)), done=done)


@pytest.fixture
def widget(dock):
    _, widget = dock(SegmentationWidget)
    return widget


def test_a_busy_display_drops_updates_but_not_a_finished_contour(widget, monkeypatch):
    from napari_physeg._widgets import _worker, segmentation

    shown = []
    widget._on_yielded = shown.append
    display_cpu = iter(np.arange(100.0))  # each update finds the display a full CPU second busier
    widget._display_cpu = lambda: next(display_cpu)
    clock = iter([0.0, 0.1, 0.2, 0.2, 0.3, 0.4, 0.5, 0.6])  # the first draw, then one update each 0.1 s
    now = [0.0]

    def perf_counter():
        now[0] = next(clock, now[0] + 0.1)
        return now[0]

    for module in (_worker, segmentation):
        monkeypatch.setattr(module.time, "perf_counter", perf_counter)
    updates = [_update(0, 1, total=3), _update(0, 2, done=True, total=3), _update(1, 1, total=3),
               _update(1, 2, total=3), _update(1, 3, done=True, total=3), _update(2, 1, total=3)]
    for update in updates:
        widget._on_yielded_once(update)
    # The first is shown; the first contour's final state, 0.1 s later, is not
    # (but kept for the next preview drawn); the second's is, more than
    # FINISHED_EVERY after the last drawing.
    assert shown == [updates[0], updates[4]]
    assert set(widget._finished) == {0, 1}
    assert widget.n_received == 6


def test_an_idle_display_shows_every_update(widget):
    shown = []
    widget._on_yielded = shown.append
    widget._display_cpu = lambda: 0.0
    updates = [_update(0, step) for step in range(1, 6)]
    for update in updates:
        widget._on_yielded_once(update)
    assert shown == updates


def _burn(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


@pytest.mark.skipif(not hasattr(time, "pthread_getcpuclockid"), reason="no per-thread CPU clock here")
def test_the_display_cpu_is_every_thread_but_the_workers(widget):
    """What the previews cost is the CPU of every thread but the worker's: a
    thread painting (software OpenGL paints in threads of its own) counts, the
    worker's own second does not."""
    noted, burned, release = threading.Event(), threading.Event(), threading.Event()

    def work():
        widget._note_worker_clock(time.pthread_getcpuclockid(threading.get_ident()))
        noted.set()
        _burn(1.0)
        burned.set()
        release.wait(10)  # alive while the GUI reads its clock

    worker = threading.Thread(target=work)
    worker.start()
    noted.wait(10)
    before = widget._display_cpu()
    painter = threading.Thread(target=_burn, args=(0.5,))
    painter.start()
    painter.join()
    burned.wait(10)
    display = widget._display_cpu() - before
    release.set()
    worker.join()
    assert 0.45 <= display < 0.8

"""Fixtures of the napari widget tests.

These tests need Qt, napari and a display. pytest-xvfb starts a virtual X
server (Xvfb) by itself when it is installed; without any display the tests
are skipped with a message that says what is missing, instead of crashing Qt.
"""

import os
import sys

os.environ.setdefault("QT_API", "pyqt6")

import pytest  # noqa: E402


def _why_no_gui():
    try:
        import qtpy  # noqa: F401
    except Exception as err:  # pragma: no cover - depends on the machine
        return f"no Qt binding ({err}); pip install pyqt6"
    try:
        import napari  # noqa: F401
    except Exception as err:  # pragma: no cover
        return f"napari cannot be imported ({err})"
    headless_qpa = os.environ.get("QT_QPA_PLATFORM", "") in ("offscreen", "minimal")
    if sys.platform.startswith("linux") and not headless_qpa and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):  # pragma: no cover
        return "no display: install Xvfb (scripts/setup.sh) and pytest-xvfb, or run under xvfb-run"
    return None


@pytest.fixture(scope="session")
def _why_no_gui_once():
    # Evaluated when the first test runs: this conftest may be imported before
    # pytest-xvfb has started Xvfb and set DISPLAY (in pytest_configure).
    return _why_no_gui()


@pytest.fixture(autouse=True)
def _needs_gui(_why_no_gui_once):
    if _why_no_gui_once:  # pragma: no cover
        pytest.skip(_why_no_gui_once)


@pytest.fixture
def errors(monkeypatch):
    """Messages the widgets pass to napari's ``show_error`` (all through their shared base class)."""
    from napari_physeg._widgets import _worker

    seen = []
    monkeypatch.setattr(_worker, "show_error", lambda message: seen.append(str(message)))
    return seen


@pytest.fixture
def notes(monkeypatch, errors):
    """Messages the matching and simulation widgets pass to napari's notifications, by severity."""
    from napari_physeg._widgets import matching, simulation

    seen = {"error": errors, "info": [], "warning": []}
    for module in (matching, simulation):
        monkeypatch.setattr(module, "show_info", lambda message: seen["info"].append(str(message)))
    monkeypatch.setattr(simulation, "show_warning", lambda message: seen["warning"].append(str(message)))
    return seen


@pytest.fixture
def napari_notifications():
    """Notifications that reach napari's notification manager (nothing patched)."""
    from napari.utils.notifications import notification_manager

    received = []
    notification_manager.notification_ready.connect(received.append)
    yield received
    notification_manager.notification_ready.disconnect(received.append)


@pytest.fixture
def dock(make_napari_viewer):
    """``dock(WidgetClass, ...)`` -> ``(viewer, widget, ...)``: a new viewer with the widgets docked in it."""

    def make(*classes):
        viewer = make_napari_viewer()
        widgets = [cls(viewer) for cls in classes]
        for widget in widgets:
            viewer.window.add_dock_widget(widget, name=type(widget).__name__.removesuffix("Widget").lower())
        return (viewer, *widgets)

    return make


@pytest.fixture
def wait_done(qtbot, request):
    """Wait for a widget's background run to finish (GUI events keep flowing).

    The default timeout is the test module's ``RUN_TIMEOUT_MS``, else 30 s.
    """
    default = getattr(request.module, "RUN_TIMEOUT_MS", 30_000)

    def wait(widget, timeout=default):
        qtbot.waitUntil(lambda: not widget.is_running, timeout=timeout)

    return wait


@pytest.fixture
def record_progress():
    """``record_progress(widget)`` -> the list of values the widget's progress bar shows from then on."""

    def record(widget):
        values = []
        widget.progress_bar.changed.connect(values.append)
        return values

    return record

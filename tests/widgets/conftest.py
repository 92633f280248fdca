"""Fixtures of the napari widget tests.

These tests need Qt, napari and a display. pytest-xvfb starts a virtual X
server (Xvfb) by itself when it is installed; without any display the tests
are skipped with a message that says what is missing, instead of crashing Qt.
"""

import os
import sys

os.environ.setdefault("QT_API", "pyqt5")

import pytest  # noqa: E402


def _why_no_gui():
    try:
        import qtpy  # noqa: F401
    except Exception as err:  # pragma: no cover - depends on the machine
        return f"no Qt binding ({err}); pip install pyqt5"
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
    """Messages passed to napari's ``show_error`` by the segmentation widget."""
    from napari_physeg._widgets import segmentation

    seen = []
    monkeypatch.setattr(segmentation, "show_error", lambda message: seen.append(str(message)))
    return seen


@pytest.fixture
def viewer_widget(make_napari_viewer):
    """A viewer with the segmentation widget docked in it."""
    from napari_physeg._widgets.segmentation import SegmentationWidget

    viewer = make_napari_viewer()
    widget = SegmentationWidget(viewer)
    viewer.window.add_dock_widget(widget, name="segmentation")
    return viewer, widget


@pytest.fixture
def wait_done(qtbot):
    """Wait for a widget's background run to finish (GUI events keep flowing)."""

    def wait(widget, timeout=30_000):
        qtbot.waitUntil(lambda: not widget.is_running, timeout=timeout)

    return wait

"""The four widgets docked together on a laptop screen."""

import pytest

pytest.importorskip("napari")

from qtpy.QtCore import QPoint  # noqa: E402

from napari_physeg._widgets.matching import MatchingWidget  # noqa: E402
from napari_physeg._widgets.segmentation import SegmentationWidget  # noqa: E402
from napari_physeg._widgets.simulation import SimulationWidget  # noqa: E402
from napari_physeg._widgets.tracking import TrackingWidget  # noqa: E402

pytestmark = [
    pytest.mark.gui,
    pytest.mark.filterwarnings("ignore:System theme detection requires a Qt6 backend:UserWarning"),
]

LAPTOP = (1366, 768)


def test_every_widget_docked_fits_a_laptop_screen(make_napari_viewer, qtbot):
    viewer = make_napari_viewer(show=True)
    widgets = [cls(viewer) for cls in (SegmentationWidget, MatchingWidget, SimulationWidget, TrackingWidget)]
    for widget in widgets:
        viewer.window.add_dock_widget(widget, name=type(widget).__name__, area="right")
    window = viewer.window._qt_window
    window.resize(*LAPTOP)
    qtbot.wait(200)
    # Qt would make the window taller than the screen if the docks needed it.
    assert window.minimumSizeHint().height() <= LAPTOP[1]
    assert window.height() <= LAPTOP[1] and window.width() <= LAPTOP[0]
    for widget in widgets:
        # Run is in view, within the window; the parameters scroll; Advanced starts collapsed.
        button = widget._run_btn.native
        corner = button.mapTo(window, QPoint(button.width(), button.height()))
        assert button.isVisible() and window.rect().contains(corner), type(widget).__name__
        assert widget.scroll_area.widget() is widget._controls.native
        if widget.advanced_section is not None:
            assert not widget.advanced_section.isExpanded()

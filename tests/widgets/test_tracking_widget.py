"""The Tracking widget end to end: a movie and contours drawn on one frame in,
napari's thread worker over the core's generator, Shapes / Tracks / map layers out."""

import numpy as np
import pytest

napari = pytest.importorskip("napari")

from napari.layers import Image, Shapes, Tracks  # noqa: E402

from napari_physeg import data  # noqa: E402
from napari_physeg._sample_data import deforming_cell  # noqa: E402
from napari_physeg._widgets.tracking import TrackingWidget, node_trajectories  # noqa: E402
from napari_physeg.core import track  # noqa: E402
from napari_physeg.core.contour import polygon_mask  # noqa: E402

pytestmark = [
    pytest.mark.gui,
    pytest.mark.filterwarnings("ignore:System theme detection requires a Qt6 backend:UserWarning"),
]

RUN_TIMEOUT_MS = 60_000


def _dock_movie(dock, n_frames):
    viewer, widget = dock(TrackingWidget)
    for data_, meta, kind in deforming_cell():
        viewer.add_layer(napari.layers.Layer.create(data_[:n_frames] if kind == "image" else data_, meta, kind))
    widget._on_layers_changed()
    viewer.dims.set_point(0, 0)
    return viewer, widget


@pytest.fixture
def movie_in_viewer(dock):
    return _dock_movie(dock, 8)


def test_round_trip_adds_contours_tracks_and_maps(movie_in_viewer, wait_done):
    viewer, widget = movie_in_viewer
    movie = data.deforming_cell()
    assert widget._image.value.name == "deforming cell" and widget._shapes.value.name == "contour on frame 0"
    worker = widget.run()
    assert worker is not None
    wait_done(widget)
    result = widget.last_result
    assert result is not None and result.status == [["tracked"] * 8]
    shapes = [layer for layer in widget.output_layers if isinstance(layer, Shapes)]
    tracks = [layer for layer in widget.output_layers if isinstance(layer, Tracks)]
    maps = [layer for layer in widget.output_layers if isinstance(layer, Image)]
    assert len(shapes) == 1 and len(tracks) == 1 and len(maps) == 2
    polygons = shapes[0].data
    assert len(polygons) == 8 and [int(p[0, 0]) for p in polygons] == list(range(8))
    for t, polygon in enumerate(polygons):
        found = polygon_mask(np.asarray(polygon[:, 1:], float), movie.masks[t].shape)
        assert (found & movie.masks[t]).sum() / (found | movie.masks[t]).sum() > 0.97
    assert maps[0].data.shape == (1, 8, 100) and not maps[0].visible  # object x frame x arc
    assert "object" not in viewer.dims.axis_labels  # the movie's time axis keeps its name
    # The centroid track, then the node trajectories, each over the 8 frames.
    assert len(np.unique(tracks[0].data[:, 0])) == 13 and tracks[0].data[:, 1].max() == 7
    assert "tracking preview" not in [layer.name for layer in viewer.layers]
    # updates are shown at the pace the GUI affords; the status counts them all
    assert 1 <= widget.n_updates <= 8 and "8 object-frames tracked" in widget._status.value


def test_cancel_keeps_the_frames_done(dock, qtbot, wait_done):
    viewer, widget = _dock_movie(dock, 30)  # long enough for the cancel to land before the end
    worker = widget.run()
    qtbot.waitUntil(lambda: widget.n_received >= 2, timeout=RUN_TIMEOUT_MS)
    widget.cancel()
    wait_done(widget)
    result = widget.last_result
    assert result.stop_reason == "cancelled"
    done = [c is not None for c in result.contours[0]]
    assert 2 <= sum(done) < 30 and done[: sum(done)] == [True] * sum(done)
    assert len(widget.output_layers[0].data) == sum(done)
    assert worker is not None


def test_contours_off_the_current_frame_are_refused(movie_in_viewer, errors):
    viewer, widget = movie_in_viewer
    viewer.dims.set_point(0, 5)
    assert widget.run() is None
    assert errors and "current frame" in errors[-1]


def test_node_trajectories_follow_the_membrane():
    movie = data.deforming_cell(n_frames=5)
    tr = track(movie.frames, movie.init)
    paths = node_trajectories(tr, 0, n_points=6)
    assert len(paths) == 6 and all(p.shape == (5, 3) for p in paths)
    for path in paths:  # every point stays on its frame's contour
        for t, r, c in path:
            contour = tr.contours[0][int(t)]
            assert np.min(np.hypot(contour[:, 0] - r, contour[:, 1] - c)) < 2.0


def test_updates_never_re_enter_the_slot(movie_in_viewer):
    """napari's progress bar (activity dock open) processes Qt events: an
    update delivered inside the slot waits and is handled after it, in
    order, not recursively."""
    _, widget = movie_in_viewer
    seen, depth = [], []

    def slot(update):
        depth.append(widget._delivering)
        seen.append(update)
        if update < 3:
            widget._on_yielded_once(update + 1)  # what a nested event delivery does

    widget._on_yielded = slot
    widget._on_yielded_once(0)
    assert seen == [0, 1, 2, 3] and widget._delivering is False and not widget._pending


def test_a_run_with_the_activity_dock_open_logs_no_recursion(movie_in_viewer, wait_done, caplog):
    viewer, widget = movie_in_viewer
    viewer.window._status_bar._toggle_activity_dock(True)
    widget.preview_interval = 0.0  # every update redraws the preview
    widget.run()
    wait_done(widget)
    assert widget.last_result.status == [["tracked"] * 8]
    assert not [r for r in caplog.records if "RecursionError" in r.getMessage()]


def test_a_result_delivered_inside_the_slot_comes_after_the_updates(movie_in_viewer):
    """The run's result and end can be delivered inside a handler too: they
    must not overtake what came before them (the progress bar would stop
    short; the end of the run would drop the preview before the result took
    it over)."""
    _, widget = movie_in_viewer
    order = []

    def slot(update):
        order.append(update)
        if update == 0:
            widget._on_yielded_once(1)  # queued
            widget._on_returned_in_order("result")  # delivered inside the slot too

    def returned(result):
        order.append(result)
        widget._on_finished_in_order()  # e.g. processed by a progress bar inside this handler

    widget._on_yielded = slot
    widget._on_returned = returned
    widget._on_finished = lambda: order.append("finished")
    widget._on_yielded_once(0)
    assert order == [0, 1, "result", "finished"]


def test_points_clicked_around_a_cell_are_a_contour(movie_in_viewer, wait_done):
    # A Points layer, its points on the frame in the order clicked, seeds the tracking as a polygon would.
    viewer, widget = movie_in_viewer
    drawn = np.asarray(viewer.layers["contour on frame 0"].data[0])
    viewer.add_points(drawn[::4], name="clicked")
    widget.reset_choices()
    widget._shapes.value = viewer.layers["clicked"]
    widget.run()
    wait_done(widget)
    assert widget.last_result.status == [["tracked"] * 8]


def test_the_preview_does_not_take_the_users_selection(movie_in_viewer, qtbot, wait_done):
    """The live preview layer goes in without changing which layer the user
    has selected (napari selects every layer it adds: the layer controls
    switched to the preview in the middle of the run)."""
    viewer, widget = movie_in_viewer
    drawn = widget._shapes.value
    viewer.layers.selection.active = drawn
    widget.run()
    qtbot.waitUntil(lambda: widget._preview is not None, timeout=RUN_TIMEOUT_MS)
    assert widget._preview in viewer.layers
    assert viewer.layers.selection.active is drawn and set(viewer.layers.selection) == {drawn}
    wait_done(widget)

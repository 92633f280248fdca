"""track(): objects followed through a movie, with known answers."""

import numpy as np
import pytest

from napari_physeg import data
from napari_physeg.core._drain import drain
from napari_physeg.core import LEFT, LOST, TRACKED, iter_track, match, segment, track
from napari_physeg.core.contour import outward_normals, polygon_mask, resample, signed_area
from napari_physeg.core.tracking import curvature, node_origins


def iou(contour, mask):
    found = polygon_mask(contour, mask.shape)
    return (found & mask).sum() / (found | mask).sum()


@pytest.fixture(scope="module")
def movie():
    return data.deforming_cell(n_frames=12)


@pytest.fixture(scope="module")
def tracked(movie):
    return track(movie.frames, movie.init)


def test_the_deforming_cell_is_followed_through_every_frame(movie, tracked):
    assert tracked.status == [[TRACKED] * 12]
    assert tracked.stop_reason == "completed"
    for t, contour in enumerate(tracked.contours[0]):
        assert signed_area(contour) > 0  # positively oriented
        assert iou(contour, movie.masks[t]) > 0.98


@pytest.mark.parametrize("as_list", [False, True])
def test_a_click_on_the_start_frame_is_followed(movie, as_list):
    """One point, alone or in the list of inits, is a click (see
    segment): the cell is followed from it."""
    click = np.argwhere(movie.masks[0]).mean(0)[None]
    res = track(movie.frames[:4], [click] if as_list else click)
    assert res.status == [[TRACKED] * 4]
    assert all(iou(c, m) > 0.95 for c, m in zip(res.contours[0], movie.masks))


def test_normal_velocity_matches_the_known_membrane_motion(movie, tracked):
    errors = []
    for t in range(1, 12):
        contour, velocity = tracked.contours[0][t], tracked.normal_velocity[0][t]
        nearest = np.argmin(((contour[:, None] - movie.outlines[t][None]) ** 2).sum(-1), axis=1)
        errors.append(np.abs(velocity - movie.normal_velocity[t][nearest]))
    errors = np.concatenate(errors)
    assert np.median(errors) < 0.15 and np.percentile(errors, 99) < 0.5
    assert np.isnan(tracked.normal_velocity[0][0]).all() and np.isnan(tracked.origin[0][0]).all()


def test_origins_follow_the_turning_body(movie, tracked):
    """A point followed from frame 0 through the origins ends within about a
    node spacing of where the material point went (the body turns 4.4
    degrees, about 3 node spacings at its tips, in these 12 frames)."""
    first = tracked.contours[0][0]
    spacing = np.mean(np.hypot(*(np.roll(first, -1, axis=0) - first).T))
    steps = [(tracked.contours[0][t], tracked.origin[0][t]) for t in range(1, 12)]
    drift = []
    for i in range(0, len(first), 7):
        material = np.argmin(((movie.outlines[0] - first[i]) ** 2).sum(1))
        drift.append(np.hypot(*(_followed(first[i], steps) - movie.outlines[11][material])) / spacing)
    assert np.median(drift) < 1.0 and np.max(drift) < 2.0


def _followed(point, steps):
    """Where ``point`` goes through ``steps``, pairs of a contour and its
    nodes' origins on the one before: the node whose origin is nearest,
    plus the point's offset from that origin along the membrane."""
    for contour, origins in steps:
        j = np.argmin(((origins - point) ** 2).sum(1))
        point = contour[j] + (point - origins[j])
    return point


@pytest.mark.parametrize("seed", [0, 1])
def test_origins_on_the_true_outlines_stay_on_their_material_points(seed):
    """Every 3rd node of the deforming cell's true outline (90 nodes, no
    segmentation error) followed through node_origins over 30 frames ends
    within a third of a node spacing of its material point in the median.
    The outline fit's own shift, pulled by the waves around the elongated
    body, left 0.37 and 0.59 (the area centroid's: 0.22 and 0.23)."""
    cell = data.deforming_cell(seed=seed)
    outlines = [o[::8] for o in cell.outlines]  # the material points in correspondence
    spacing = np.mean(np.hypot(*(np.roll(outlines[0], -1, axis=0) - outlines[0]).T))
    origins = [node_origins(now, before) for before, now in zip(outlines[:-1], outlines[1:])]
    steps = list(zip(outlines[1:], origins))
    drift = [np.hypot(*(_followed(outlines[0][i], steps) - outlines[-1][i])) / spacing
             for i in range(0, len(outlines[0]), 3)]
    assert np.median(drift) < 0.3 and np.max(drift) < 1.25


def test_arc_origin_is_carried_and_maps_have_the_movie_shape(tracked):
    for arc in tracked.arc[0]:
        assert arc.min() >= 0 and arc.max() < 1 and np.sum(arc == 0) == 1
    velocity_map = tracked.membrane_map(0, "normal_velocity", n_arc=50)
    curvature_map = tracked.membrane_map(0, "curvature", n_arc=50)
    assert velocity_map.shape == curvature_map.shape == (12, 50)
    assert np.isnan(velocity_map[0]).all() and np.isfinite(velocity_map[1:]).all()
    # The elongated body's tips are its most curved parts, twice per turn.
    assert np.isfinite(curvature_map).all() and curvature_map.mean() > 0
    with pytest.raises(ValueError, match="quantity"):
        tracked.membrane_map(0, "speed")
    for ask in (tracked.membrane_map, tracked.centroids, tracked.first_lost):  # numpy's bare IndexError before session 64
        with pytest.raises(IndexError, match="object 3 is not one of the 1 tracked"):
            ask(3)


def test_tidy_table(tracked):
    table = tracked.table()
    assert list(table.columns) == ["object", "frame", "node", "row", "col", "arc", "normal_velocity",
                                   "curvature", "status", "reason"]
    assert len(table) == sum(len(c) for c in tracked.contours[0])
    assert set(table.status) == {TRACKED} and set(table.reason) == {""}
    assert tracked.reason == [[""] * 12] and not tracked.warnings


def test_curvature_of_a_circle_is_one_over_its_radius():
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    circle = np.column_stack([50 + 20 * np.sin(t), 50 + 20 * np.cos(t)])
    for contour in (circle, circle[::-1]):
        assert np.allclose(curvature(contour), 1 / 20, rtol=1e-3)


def test_origins_of_a_shifted_contour_are_its_nodes_shifted_back():
    obj = data.blob()
    contour = obj.outline[::4]
    shifted = contour + [1.5, -0.7]
    origin = node_origins(shifted, contour)
    assert np.abs(origin - contour).max() < 0.1


def _disk_frames(radii, centre=32.0, size=64, noise=5.0, seed=0):
    """Noisy frames of a bright disk of each of ``radii``."""
    rows, cols = np.mgrid[:size, :size]
    rng = np.random.default_rng(seed)
    disks = [np.hypot(rows - centre, cols - centre) <= r for r in radii]
    return np.stack([10.0 + 190.0 * d + rng.normal(0, noise, d.shape) for d in disks]).astype(np.float32)


def test_a_growing_disk_moves_out_at_its_growth_on_every_frame():
    """A disk fits its previous outline at every angle: the turn between
    frames must be the least that fits, not one that the nodes' noise
    chooses (up to 125 degrees, which put every origin far along the
    membrane and gave normal velocities of 18 px/frame)."""
    radii = 8.0 + np.arange(10)
    tr = track(_disk_frames(radii), _circle((32, 32), 12))
    assert tr.status == [[TRACKED] * 10]
    for t in range(1, 10):
        velocity = tr.normal_velocity[0][t]
        assert abs(np.median(velocity) - 1.0) < 0.3 and np.abs(velocity - 1.0).max() < 1.0, t


@pytest.mark.parametrize("radius, depth, turn, seed", [(10, 0.12, 0.0141, 436), (12, 0.2, 0.0051, 37),
                                                       (8, 0.08, 0.0353, 741)])
def test_a_slowly_turning_oval_keeps_its_origins_in_place(radius, depth, turn, seed):
    """A two-fold symmetric shape's modes may take opposite signs on
    consecutive frames; the matching's best pairs then lie half a turn away
    and must not outweigh where the nodes are (36 of 150 such movies had
    normal velocities of 16-27 px/frame for a turn of 0.2-1.6 px)."""
    rows, cols = np.mgrid[:64, :64] - 32.0
    rng = np.random.default_rng(seed)
    angle, distance = np.arctan2(rows, cols), np.hypot(rows, cols)
    frames = np.stack([10.0 + 190.0 * (distance <= radius * (1 + depth * np.cos(2 * (angle - turn * t))))
                       + rng.normal(0, 3.0, rows.shape) for t in range(10)]).astype(np.float32)
    tr = track(frames, _circle((32, 32), 1.4 * radius))
    assert tr.status == [[TRACKED] * 10]
    for t in range(1, 10):
        assert np.abs(tr.normal_velocity[0][t]).max() < 1.5, t
        assert np.median(np.hypot(*(tr.contours[0][t] - tr.origin[0][t]).T)) < 1.0, t


def test_origins_of_a_still_circle_whose_nodes_moved_along_lie_on_it():
    """Origins lie on the smooth curve through the previous nodes: on its
    edges, inside a convex contour by their sagitta, every normal velocity
    of a still circle came out 0.09 px/frame outward."""
    angles = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    before = np.column_stack([50 + 10 * np.sin(angles), 50 + 10 * np.cos(angles)])
    moved_along = np.column_stack([50 + 10 * np.sin(angles + np.pi / 24), 50 + 10 * np.cos(angles + np.pi / 24)])
    origin = node_origins(moved_along, before)
    assert np.abs(np.hypot(*(origin - 50).T) - 10).max() < 0.005
    assert np.abs(((moved_along - origin) * outward_normals(moved_along)).sum(1)).max() < 0.005


def test_curvature_of_a_pixelated_disk_is_convex_everywhere():
    """The outline of a binary disk steps from pixel to pixel; over one
    node's turn its curvature ranged from -0.11 to 0.29 for 0.1."""
    from skimage import measure

    rows, cols = np.mgrid[:60, :60]
    disk = (rows - 30.3) ** 2 + (cols - 29.6) ** 2 <= 10**2
    outline = resample(measure.find_contours(disk.astype(float), 0.5)[0], spacing=2.7)
    assert curvature(outline).min() > 0.02 and np.abs(curvature(outline) - 0.1).max() < 0.07


def test_starting_in_the_middle_tracks_both_ways(movie):
    middle = data.deforming_cell(n_frames=12)
    init = middle.outlines[6][::6] + 3.0 * _outward(middle.outlines[6][::6])
    tr = track(movie.frames, init, start=6)
    assert tr.start == 6 and tr.status == [[TRACKED] * 12]
    assert iou(tr.contours[0][0], movie.masks[0]) > 0.98
    assert np.isnan(tr.normal_velocity[0][0]).all() and np.isfinite(tr.normal_velocity[0][1]).all()
    assert np.isfinite(tr.normal_velocity[0][6]).all()  # frame 6 has a previous frame, 5


def _outward(contour):
    from napari_physeg.core.contour import outward_normals

    return outward_normals(contour)


def _disk_movie(centres, radius=12, shape=(96, 96), noise=0.05):
    rr, cc = np.mgrid[: shape[0], : shape[1]]
    rng = np.random.default_rng(0)
    frames = []
    for frame_centres in centres:
        image = np.full(shape, 0.2)
        for r, c in frame_centres:
            if r is not None:
                image[(rr - r) ** 2 + (cc - c) ** 2 <= radius**2] = 0.8
        frames.append(image + noise * rng.standard_normal(shape))
    return np.stack(frames)


def _centred_disk(radius, contrast, rng, shape=(96, 96)):
    """A frame of a disk of ``contrast`` over a ground of 0.2 in its middle, with white noise of 0.01."""
    rr, cc = np.mgrid[: shape[0], : shape[1]]
    disk = (rr - shape[0] // 2) ** 2 + (cc - shape[1] // 2) ** 2 <= radius**2
    return 0.2 + contrast * disk + 0.01 * rng.standard_normal(shape)


def _circle(centre, radius, n=48):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([centre[0] + radius * np.sin(t), centre[1] + radius * np.cos(t)])


def test_an_object_cut_by_the_side_grows_to_at_most_its_whole():
    """A cell seen whole (315 px) moves into the image's side, which cuts it
    (259 px); then a large bright body comes in along the side and touches
    it. The side hides part of an object it cuts, so its contour may grow
    from one frame to the next by more than an object not at the side (a
    sliver may become the whole), but not beyond twice the whole: the
    contour that spread over the newcomer (1119 px) was reported tracked."""
    centres = [[(48, 60 + 5 * t)] for t in range(7)] + [[(48, 90)]] * 2
    frames = _disk_movie(centres, radius=10)
    frames[7:, 10:90, 82:] = 0.8
    tr = track(frames, _circle((48, 60), 14))
    assert tr.status[0] == [TRACKED] * 7 + [LOST] * 2
    assert abs(signed_area(tr.contours[0][6])) < abs(signed_area(tr.contours[0][5]))  # cut by the side


def test_touching_objects_repel_and_never_overlap():
    """Two cells that come into contact: each keeps its own pixels."""
    centres = [[(48, 30 + 1.5 * t), (48, 66 - 1.5 * t)] for t in range(6)]  # 36 px apart, then 21
    frames = _disk_movie(centres, radius=10)
    tr = track(frames, [_circle((48, 30), 14), _circle((48, 66), 14)])
    assert tr.status == [[TRACKED] * 6, [TRACKED] * 6]
    for t in range(6):
        a, b = (polygon_mask(tr.contours[k][t], frames.shape[1:]) for k in (0, 1))
        assert (a & b).sum() <= 2
        assert abs(tr.centroids(0)[t][1] - centres[t][0][1]) < 1.5


@pytest.mark.parametrize("jump", [8, 12])
def test_an_object_that_moves_further_than_predicted_is_followed_whole(jump):
    """A cell at rest that darts off: the frame's drawing, around where the
    motion predicts it, cuts through it; the contour rests against that
    drawing's limit, and is drawn around again until it holds the whole cell
    (not a part of it reported as tracked: IoU 0.97 and 0.74 before). A jump
    longer than its radius leaves nothing under the drawing: lost."""
    centres = [[(48, 30)], [(48, 30)], [(48, 30 + jump)], [(48, 30 + jump)]]
    frames = _disk_movie(centres, radius=12, shape=(96, 112))
    tr = track(frames, _circle((48, 30), 16))
    assert tr.status[0] == [TRACKED] * 4
    for t in (2, 3):
        assert iou(tr.contours[0][t], frames[t] > 0.5) > 0.98
        assert np.hypot(*(tr.centroids(0)[t] - centres[t][0])) < 1.0


@pytest.mark.parametrize("back", [0, 2, 4])
def test_an_object_that_stops_after_a_dart_is_followed(back):
    """A cell that darts its own radius, then stops (or steps back): the
    motion predicted from the dart puts the next frame's drawing 9-13 px off,
    mostly on the background. The cell is looked for where it was last seen
    too (it was lost on that frame, then found again on the next)."""
    centres = [[(32, 22)], [(41, 22)], [(41 - back, 22)], [(41 - back, 22)]]
    frames = _disk_movie(centres, radius=9, shape=(64, 80))
    tr = track(frames, _circle((32, 22), 13.5))
    assert tr.status[0] == [TRACKED] * 4
    for t in (2, 3):
        assert np.hypot(*(tr.centroids(0)[t] - centres[t][0])) < 1.0


def test_an_object_that_jumps_beyond_where_it_is_looked_for_is_linked_again():
    """A cell that jumps twice its radius (a HeLa nucleus of the Cell
    Tracking Challenge jumped 1.9 radii between its first two frames): its
    drawing, and its looks searched one radius about where it was, miss it,
    and it was lost for good. Once every object of the frame is done, the
    unclaimed blob nearest where it was and likest it in area is segmented."""
    centres = [[(48, 30), (20, 100)]] * 2 + [[(48, 52), (20, 100)]] * 2
    frames = _disk_movie(centres, radius=11, shape=(96, 128))
    tr = track(frames, [_circle((48, 30), 15), _circle((20, 100), 15)])
    assert tr.status == [[TRACKED] * 4] * 2
    for t in (2, 3):
        assert np.hypot(*(tr.centroids(0)[t] - centres[t][0])) < 1.0


def test_the_progress_reports_what_the_result_holds_after_the_second_looks():
    """The object that jumped is lost on the first look at frame 2 and found
    by the second (see the test above): the progress (the widget's preview
    and counts) said 'lost' and no contour, while the result said tracked."""
    centres = [[(48, 30), (20, 100)]] * 2 + [[(48, 52), (20, 100)]] * 2
    frames = _disk_movie(centres, radius=11, shape=(96, 128))
    reported = []
    tr = track(frames, [_circle((48, 30), 15), _circle((20, 100), 15)], callback=reported.append)
    assert len(reported) == 8 and [p.done for p in reported] == list(range(1, 9))
    for p in reported:
        assert p.status == tr.status[p.object][p.frame]
        assert p.contour is tr.contours[p.object][p.frame]

def test_a_segmentation_that_spreads_beyond_any_area_kept_stops_there(monkeypatch):
    """A disk whose ground turns as bright as itself over most of the frame:
    its contour spreads over it and the object is lost, as before; but the
    segmentation stops once it holds more than the tracker could keep
    (tracking.LEAK_AREA_FACTOR times its area), not after crawling on (it converged on the
    plateau after ~50 steps, 100-140 nodes; a phase-contrast cell ran 300
    steps five times on one frame)."""
    from napari_physeg.core import tracking

    rr, cc = np.mgrid[:128, :128]
    rng = np.random.default_rng(0)
    frames = []
    for t in range(3):
        image = np.full((128, 128), 0.2)
        image[(rr - 64) ** 2 + (cc - 64) ** 2 <= 8**2] = 0.8
        if t >= 1:
            image[10:118, 10:118] = 0.8
        frames.append(image + 0.03 * rng.standard_normal(image.shape))
    runs = []
    segment_from = tracking._segment_from
    monkeypatch.setattr(tracking, "_segment_from", lambda *a, **k: runs.append(segment_from(*a, **k)) or runs[-1])
    tr = track(np.stack(frames), _circle((64, 64), 11))
    assert tr.status == [[TRACKED, LOST, LOST]]
    assert runs[0].converged and len(runs) > 1
    assert all(r.stop_reason == "leaked" and r.steps <= 30 for r in runs[1:])

def _dimming_disks(factors, fading=()):
    """Four disks on a ground of 0.2, their contrast times ``factors[t]`` (the
    whole frame: bleaching), and the disks of ``fading`` alone dimming so."""
    centres = [(30, 30), (30, 90), (90, 30), (90, 90)]
    rr, cc = np.mgrid[:120, :120]
    rng = np.random.default_rng(0)
    frames = []
    for t, factor in enumerate(factors):
        image = np.full((120, 120), 0.2)
        for k, (r, c) in enumerate(centres):
            dim = factor if (not fading or k in fading) else 1.0
            image[(rr - r) ** 2 + (cc - c) ** 2 <= 10**2] += 0.6 * dim
        frames.append(image + 0.005 * rng.standard_normal(image.shape))
    return np.stack(frames), [_circle(c, 14) for c in centres]


def test_objects_lost_as_the_whole_movie_dims_fast_are_named_with_what_to_do():
    """Bleached to a tenth within six frames, every disk fades below a fifth of
    its contrast and is lost, though still in view: a warning names them and
    says to even out the frames, which then keeps every track. One disk that
    fades alone (it left the focal plane) is lost without that warning."""
    factors = np.geomspace(1.0, 0.1, 6)
    frames, inits = _dimming_disks(factors)
    with pytest.warns(UserWarning, match="4 object.* faded out.*even out its frames") as caught:
        tr = track(frames, inits)
    assert caught[0].filename == __file__  # the caller's line
    assert all(LOST in row for row in tr.status)
    dimmed = [w for w in tr.warnings if "faded out" in w]
    assert len(dimmed) == 1 and "even out its frames" in dimmed[0]
    median = np.median(frames, axis=(1, 2), keepdims=True)
    even = (frames - median) / (np.percentile(frames, 99, axis=(1, 2), keepdims=True) - median)
    assert track(even, inits).status == [[TRACKED] * 6] * 4
    alone = track(*_dimming_disks(factors, fading=(0,)))
    assert LOST in alone.status[0] and alone.status[1:] == [[TRACKED] * 6] * 3
    assert not any("faded out" in w for w in alone.warnings)

def test_a_vanished_object_is_not_linked_to_an_untracked_neighbour_that_was_there_before():
    """The unclaimed blob a lost object may be linked to is one that was not
    there, unclaimed, on the frame before: a cell that vanishes 2.5 radii
    from one nobody drew is lost, not continued on the other."""
    centres = [[(48, 40), (48, 65)]] * 3 + [[(None, None), (48, 65)]] * 2
    frames = _disk_movie(centres, radius=10, shape=(96, 112))
    tr = track(frames, _circle((48, 40), 14))
    assert tr.status[0] == [TRACKED] * 3 + [LOST] * 2


def test_a_vanished_object_does_not_take_a_neighbour_that_moved_toward_it():
    """Three dark disks; the first vanishes on frame 2 while the third moves
    9 px toward where it was. Found by the tracking fuzz test with three
    objects (session 24): segmented first, the vanished object's drawing took
    the part of the third that had come into it, and the third was lost."""
    centres = [[(32, 22), (32, 58), (14, 40)], [(32, 22), (32, 58), (14, 40)], [(None, None), (32, 58), (19, 33)]]
    frames = 1.0 - _disk_movie(centres, radius=9, shape=(64, 80), noise=0.0)
    tr = track(frames, [_circle(c, 13.5) for c in centres[0]])
    assert tr.status[0] == [TRACKED, TRACKED, LOST] and tr.contours[0][2] is None
    assert tr.status[1] == tr.status[2] == [TRACKED] * 3
    rr, cc = np.mgrid[:64, :80]
    assert iou(tr.contours[2][2], (rr - 19) ** 2 + (cc - 33) ** 2 <= 81) > 0.9


def test_a_vanished_object_does_not_share_a_neighbour_that_moved_next_to_it():
    """A small disk vanishes as a large one moves next to where it was. Found
    by fuzzing disks of other sizes (session 26): the vanished disk's contour
    took the part of the large one that no one owned yet, 13 px (two of its
    radii) from where it was, and the large one was "tracked" on the rest.
    Both were found, so no one was lost to give the pixels back."""
    rr, cc = np.mgrid[:64, :80]
    small, other = ((rr - 32) ** 2 + (cc - c) ** 2 <= 36 for c in (22, 58))
    large = [(rr - r) ** 2 + (cc - c) ** 2 <= 121 for r, c in ((19, 39), (25, 37), (25, 37))]
    frames = np.stack([np.where(small & (t == 0) | other | large[t], 0.5, 0.8) for t in range(3)])
    tr = track(frames, [_circle((32, 22), 7.5), _circle((32, 58), 7.5), _circle((19, 39), 13.75)])
    assert tr.status[0] == [TRACKED, LOST, LOST]
    assert tr.status[2] == [TRACKED] * 3
    assert all(iou(tr.contours[2][t], large[t]) > 0.95 for t in range(3))


def test_two_cells_that_brush_past_each_other_keep_their_identities():
    """A large cell overtakes a small one, as bright, touching it on two
    frames (found by probing unseen cases, session 27). The small one, done
    first, took the part of the large one that had moved beyond its last
    contour: counted as background, the large one's claim left that part a
    shallow crescent with no core of its own, split off the large one. On the
    next frame the small one's motion carried it onto the large one, which
    was lost."""
    from scipy import ndimage as ndi

    small = [(55.7, 44.85), (58.65, 41.42), (62.49, 42.76), (68.1, 41.75), (67.47, 40.33)]
    large = [(45.3, 23.9), (47.58, 27.41), (48.1, 33.47), (48.83, 39.65), (49.19, 43.98)]
    rr, cc = np.mgrid[:96, :96]
    disks = [[(rr - r) ** 2 + (cc - c) ** 2 <= radius ** 2 for (r, c), radius in ((s, 7.5), (g, 10.5))]
             for s, g in zip(small, large)]
    rng = np.random.default_rng(1)
    frames = np.stack([ndi.gaussian_filter(np.where(a | b, 0.62, 0.2), 1) + rng.normal(0, 0.04, (96, 96))
                       for a, b in disks])
    tr = track(frames, [_circle(small[0], 11.5), _circle(large[0], 14.5)])
    assert tr.status == [[TRACKED] * 5] * 2
    assert all(iou(tr.contours[k][t], disks[t][k]) > 0.9 for k in range(2) for t in range(5))


@pytest.mark.parametrize("second", ["same drawing", "click inside"])
def test_two_drawings_of_one_object_are_one_contour_and_a_warning(second):
    """Drawings that mark the same object (drawn twice, or a click inside a
    drawing around it): one contour, never two overlapping ones, and the
    object not found says why, instead of being reported lost in silence."""
    frames = _disk_movie([[(48, 48)]] * 3)
    around = _circle((48, 48), 16)
    other = around if second == "same drawing" else _circle((48, 48), 3)
    with pytest.warns(UserWarning, match="not found on the start frame 0.*mark the same object"):
        tr = track(frames, [around, other])
    found = [k for k in range(2) if tr.status[k] == [TRACKED] * 3]
    assert len(found) == 1 and tr.status[1 - found[0]] == [LOST] * 3
    assert len(tr.warnings) == 1 and "mark the same object" in tr.warnings[0]  # for the widget to show


def test_a_tight_drawing_lost_inside_a_generous_one_is_told_its_own_cause():
    """A tight circle on empty ground inside a generous circle around a cell
    (an outside tester's C2C12 cells, session 75). The tight one is done
    first, the generous one's claim set aside, and its contour leaks on its
    own; the warning blamed the overlap ("taken to mark the same object").
    Only an object found before it can have taken what it marks."""
    frames = _disk_movie([[(40, 36)]] * 2, radius=10, shape=(80, 100), noise=0.03)
    with pytest.warns(UserWarning, match="object 1 was not found on the start frame 0 .*leaked") as caught:
        tr = track(frames, [_circle((40, 50), 30), _circle((40, 66), 6)])
    assert tr.status == [[TRACKED] * 2, [LOST] * 2]
    assert not any("same object" in str(w.message) for w in caught)


def _haloed_disk_movie(n_frames=3, shape=(96, 96)):
    """A nucleus (radius 12) in a dim halo of cytoplasm (out to 17 px), blurred."""
    import cv2

    rr, cc = np.mgrid[: shape[0], : shape[1]]
    distance = np.hypot(rr - 48, cc - 48)
    image = cv2.GaussianBlur(np.where(distance <= 12, 0.8, np.where(distance <= 17, 0.35, 0.2)), (0, 0), 1.5)
    rng = np.random.default_rng(0)
    return np.stack([image + 0.03 * rng.standard_normal(shape) for _ in range(n_frames)])


@pytest.mark.parametrize("listed", ["around first", "click first"])
def test_a_click_inside_a_haloed_nucleus_drawn_around_too_is_one_contour(listed):
    """A click inside a nucleus that a drawing around also marks. The click
    (the smaller drawing, done first) finds the nucleus; the drawing around,
    with the nucleus' pixels counted as background, kept the halo's rim, and
    a closed contour about that rim took the nucleus with it: two contours
    over the same 427 px. One contour, and the warning."""
    frames = _haloed_disk_movie()
    drawings = [_circle((48, 48), 20), _circle((48, 48), 3)]
    if listed == "click first":
        drawings.reverse()
    with pytest.warns(UserWarning, match="not found on the start frame 0.*mark the same object"):
        tr = track(frames, drawings)
    found = [k for k in range(2) if tr.status[k] == [TRACKED] * 3]
    assert len(found) == 1 and tr.status[1 - found[0]] == [LOST] * 3
    assert all(iou(tr.contours[found[0]][t], frames[t] > 0.55) > 0.9 for t in range(3))


@pytest.mark.parametrize("gap", [14, 16])
@pytest.mark.parametrize("listed", [(0, 1), (1, 0)])
def test_clicks_inside_two_touching_nuclei_are_two_contours(gap, listed):
    """Two nuclei (domes of radius 11) that touch along most of their width,
    each clicked inside, as one marks the nuclei of a crowd. The first click
    done took both nuclei (600 px) and the second was reported lost: nothing
    parted them for a drawing alone. The body it took holds the other's
    click, so it is parted between the two at the valley of intensity."""
    rr, cc = np.mgrid[:80, :96]
    centres = [np.array([40.0, 48 - gap / 2]), np.array([40.0, 48 + gap / 2])]
    domes = [np.clip(1 - ((rr - c[0]) ** 2 + (cc - c[1]) ** 2) / 121, 0, None) ** 0.3 for c in centres]
    image = 0.2 + 0.6 * np.maximum(*domes)
    rng = np.random.default_rng(0)
    frames = np.stack([image + 0.03 * rng.standard_normal(image.shape) for _ in range(3)])
    tr = track(frames, [_circle(centres[k], 3) for k in listed])
    assert tr.status == [[TRACKED] * 3] * 2
    for t in range(3):
        masks = [polygon_mask(tr.contours[listed.index(k)][t], image.shape) for k in (0, 1)]
        assert (masks[0] & masks[1]).sum() <= 2
        assert 0.8 < masks[0].sum() / masks[1].sum() < 1.25 and min(m.sum() for m in masks) > 250  # 2 x 300
        assert tr.centroids(listed.index(0))[t][1] < 48 < tr.centroids(listed.index(1))[t][1]


@pytest.mark.parametrize("listed", ["generous first", "tight first"])
def test_a_generous_drawing_over_a_neighbour_takes_nothing_from_it_whatever_the_order(listed):
    """A circle around one cell that passes over the next cell's tight one
    (found by probing, session 27): listed after it, the tight drawing's
    object was lost on every frame, its cell within the generous drawing's
    claim."""
    centres = [[(40, 30 + 0.5 * t), (40, 66 + 0.5 * t)] for t in range(3)]
    frames = _disk_movie(centres, radius=10, shape=(80, 100), noise=0.03)
    generous, tight = _circle((40, 46), 32), _circle((40, 66), 14)
    inits = [generous, tight] if listed == "generous first" else [tight, generous]
    tr = track(frames, inits)
    assert tr.status == [[TRACKED] * 3] * 2
    rr, cc = np.mgrid[:80, :100]
    for k, cell in enumerate((0, 1) if listed == "generous first" else (1, 0)):
        for t in range(3):
            r, c = centres[t][cell]
            assert iou(tr.contours[k][t], (rr - r) ** 2 + (cc - c) ** 2 <= 100) > 0.9


def test_an_object_not_found_on_the_start_frame_gets_a_warning():
    frames = _disk_movie([[(48, 48)]] * 2)
    with pytest.warns(UserWarning, match="object 0 was not found on the start frame 0.*max_steps"):
        tr = track(frames, _circle((48, 48), 16), segment_options={"stiffness": 1e9})  # too stiff to move
    assert tr.status[0] == [LOST] * 2


def test_a_start_frame_of_one_value_is_named_as_the_cause():
    """A movie converted to a type that rounds it to one value (uint8 read as
    int8 // 256, a wrong channel): the warning says so, not "check the drawing"."""
    frames = np.zeros((2, 96, 96), dtype=np.int8)
    with pytest.warns(UserWarning, match="not found on the start frame 0 and is reported lost: every pixel of the "
                                         "frame is 0, so it has no border to follow; check that this is the channel"):
        tr = track(frames, _circle((48, 48), 16))
    assert tr.status[0] == [LOST] * 2


def _dividing_cell_movie(n_frames=11, shape=(80, 110)):
    """A disk that pinches into two daughters moving apart, 3 px a frame."""
    from scipy import ndimage as ndi

    rr, cc = np.mgrid[: shape[0], : shape[1]]
    rng = np.random.default_rng(0)
    frames = []
    for t in range(n_frames):
        apart, r = 1.5 * t, 14 - 3 * min(t / 8, 1)
        cell = ((rr - 40) ** 2 + (cc - 55 + apart) ** 2 <= r * r) | ((rr - 40) ** 2 + (cc - 55 - apart) ** 2 <= r * r)
        frames.append(ndi.gaussian_filter(np.where(cell, 0.8, 0.2), 1) + 0.03 * rng.standard_normal(shape))
    return np.stack(frames)


def test_a_cell_that_divides_ends_its_track_with_a_warning_that_says_so():
    """The contour follows the pinching cell until its daughters stand apart
    (2 px on frame 8); then one contour cannot hold them: it is pinched in two
    and keeps one, the object is lost, and the warning says it divided and how
    to follow the daughters (it said nothing). Before session 32 the region
    force bridged the daughters' gap on frame 8, and the warning came a frame
    later."""
    with pytest.warns(UserWarning, match="object 0 held two bodies on frame 8 .* divided.*start=8"):
        tr = track(_dividing_cell_movie(), _circle((40, 55), 19))
    assert tr.status[0] == [TRACKED] * 8 + [LOST] * 3
    assert len(tr.warnings) == 1 and "divided" in tr.warnings[0]


def _daughters_apart_movie(n_frames=10, shape=(80, 120), split=5):
    """A disk of radius 12 that shows, from frame ``split`` on, as two
    daughters of half its area 7 px apart, moving apart 2 px a frame (a
    frame interval longer than the pinching)."""
    from scipy import ndimage as ndi

    rr, cc = np.mgrid[: shape[0], : shape[1]]
    rng = np.random.default_rng(0)
    frames = []
    for t in range(n_frames):
        if t < split:
            cells = (rr - 40) ** 2 + (cc - 60) ** 2 < 12**2
        else:
            apart = 12 + 2 * (t - split)
            cells = (np.hypot(rr - 40, cc - 60 + apart) < 8.5) | (np.hypot(rr - 40, cc - 60 - apart) < 8.5)
        frames.append(0.1 + 0.7 * ndi.gaussian_filter(cells.astype(float), 1.2) + 0.02 * rng.standard_normal(shape))
    return np.stack(frames)


def test_daughters_that_first_show_apart_end_the_track_with_a_warning():
    """An outside tester (session 68): daughters that first appear apart
    were followed one of them, at half the area, as a nucleus condensing for
    mitosis, 'tracked' and with no word (21 of 25 divisions of a simulated
    Cell Tracking Challenge movie). A contour that shrank with an unclaimed
    sister beside it, the two centred where the mother was, divided."""
    with pytest.warns(UserWarning, match=r"object 0 divided on frame 5: they stand apart at "
                                         r"\(40, 4[78]\) and \(40, 7[23]\); its track ends .*start=5"):
        tr = track(_daughters_apart_movie(), _circle((40, 60), 16))
    assert tr.status[0] == [TRACKED] * 5 + [LOST] * 5
    assert all(c is None for c in tr.contours[0][5:])
    # Tracked backward, the daughters come together: the same frame is named, as two that met.
    with pytest.warns(UserWarning, match=r"object 0, tracked backward, was two bodies on frame 4 \(two that came"):
        back = track(_daughters_apart_movie()[::-1], _circle((40, 60), 16), start=9)
    assert back.status[0] == [LOST] * 5 + [TRACKED] * 5
    # From a frame before the division, the frames before it are tracked too (the division ends the
    # track forward only).
    with pytest.warns(UserWarning, match="object 0 divided on frame 5"):
        middle = track(_daughters_apart_movie(), _circle((40, 60), 16), start=2)
    assert middle.status[0] == [TRACKED] * 5 + [LOST] * 5


def test_tracked_backward_two_cells_that_came_together_are_not_said_to_divide():
    """Backward in time a division reads as two bodies that meet: the warning
    says so, and names the frame to draw the two on (it said 'divided ... from
    frame 1 on', of the frames before)."""
    frames = _dividing_cell_movie()[::-1]
    with pytest.warns(UserWarning, match=r"object 0 held two bodies on frame 2 .* came together .* lost on frame 2; "
                                         r"an earlier frame .*start=2"):
        tr = track(frames, _circle((40, 55), 19), start=10)
    assert tr.status[0] == [LOST] * 3 + [TRACKED] * 8
    assert len(tr.warnings) == 1 and "divided" not in tr.warnings[0]


def _dumbbell(neck, lobe=12.0):
    """Two disks of radius ``lobe``, 2 px apart, joined by a bar ``neck`` px
    wide: the outline of the mask, about a node per pixel."""
    from skimage import measure

    rr, cc = np.mgrid[:60, :100]
    a = (rr - 30) ** 2 + (cc - 20 - lobe) ** 2 <= lobe**2
    b = (rr - 30) ** 2 + (cc - 22 - 3 * lobe) ** 2 <= lobe**2
    bar = (abs(rr - 30) <= neck / 2) & (cc > 20 + lobe) & (cc < 22 + 3 * lobe)
    return max(measure.find_contours((a | b | bar).astype(float), 0.5), key=len)[:-1]


@pytest.mark.parametrize("neck, divided", [(0.5, True), (2.0, True), (8.0, False), (14.0, False)])
def test_a_contour_is_two_bodies_only_across_a_narrow_neck(neck, divided):
    from napari_physeg.core.tracking import pinched_bodies

    contour = _dumbbell(neck)
    for turned in (contour, np.roll(contour, 17, axis=0), contour[::-1], contour @ np.array([[0, 1], [-1, 0]])):
        bodies = pinched_bodies(turned)
        assert (bodies is not None) == divided
        if divided:  # the two disks, not a lobe and the rest
            areas = sorted(abs(signed_area(b)) for b in bodies)
            assert areas[0] > 0.8 * areas[1]
    assert pinched_bodies(_circle((0, 0), 10)) is None


def test_an_object_that_vanishes_is_lost_not_returned_as_garbage():
    """... and the result says why, on each frame it is lost, and a warning
    names it (an outside tester's objects were lost for 29 frames of a real
    movie with no word of why: session 69)."""
    centres = [[(48, 48)]] * 4 + [[(None, None)]] * 3
    with pytest.warns(UserWarning, match=r"1 object\(s\) were lost on some frames\. object 0 on frames 4-6: .+\. "
                                         r"TrackingResult.reason"):
        tr = track(_disk_movie(centres), _circle((48, 48), 16))
    assert tr.status[0] == [TRACKED] * 4 + [LOST] * 3
    assert all(c is None for c in tr.contours[0][4:])
    assert tr.reason[0][:4] == [""] * 4 and all(tr.reason[0][4:])
    assert tr.first_lost(0) == (4, tr.reason[0][4]) and track(_disk_movie(centres[:3]), _circle((48, 48), 16)) \
        .first_lost(0) is None
    table = tr.table()
    assert (table[table.frame >= 4].status == LOST).all() and table[table.frame >= 4].row.isna().all()
    assert list(table[table.frame >= 4].reason) == tr.reason[0][4:]


@pytest.mark.parametrize("blank", [[4], [4, 5]], ids=["one blank frame", "two"])
def test_an_object_missing_from_a_frame_or_two_is_found_again(movie, blank):
    """A blank (dropped) frame loses every object on it, not for good: each is
    looked for again from its last contour on the next MAX_GAP frames, and
    its arc origin and maps carry on across the gap."""
    frames = movie.frames.copy()
    frames[blank] = np.median(frames[0])
    tr = track(frames, movie.init)
    assert tr.status[0] == [LOST if t in blank else TRACKED for t in range(12)]
    after = blank[-1] + 1
    assert iou(tr.contours[0][after], movie.masks[after]) > 0.95
    assert np.isnan(tr.normal_velocity[0][after]).all() and np.isfinite(tr.normal_velocity[0][after + 1]).all()
    assert np.isfinite(tr.membrane_map(0, "curvature")[after:]).all()
    assert np.isfinite(tr.membrane_map(0)[after + 1:]).all()
    assert len(tr.table()) > 0


def test_an_object_missing_for_longer_than_the_gap_stays_lost(movie):
    from napari_physeg.core.tracking import MAX_GAP

    frames = movie.frames.copy()
    frames[4:5 + MAX_GAP] = np.median(frames[0])
    tr = track(frames, movie.init)
    assert tr.status[0] == [TRACKED] * 4 + [LOST] * 8
    assert all(tr.reason[0][4:5 + MAX_GAP]) and "no longer looked for" not in "".join(tr.reason[0][:5 + MAX_GAP])
    assert tr.reason[0][5 + MAX_GAP:] == [f"no longer looked for: lost since frame 4, more than {MAX_GAP} frames "
                                          "before"] * (7 - MAX_GAP)


def test_an_object_that_fades_away_is_lost_one_that_bleaches_is_not():
    """A cell that leaves the focal plane fades to its out-of-focus glow: once
    its contrast is below FADED_CONTRAST of its best within FADE_WINDOW
    frames it is lost, not followed as a dim blob. Photobleaching dims a movie
    slowly: a cell bleached to a tenth over 24 frames is still the cell
    (session 25: lost from frame 17 on, below a fifth of the start frame's)."""
    rr, cc = np.mgrid[:96, :96]
    disk = (rr - 48) ** 2 + (cc - 48) ** 2 <= 12**2
    rng = np.random.default_rng(0)

    def movie(contrasts):
        return np.stack([0.2 + c * disk + 0.01 * rng.standard_normal(disk.shape) for c in contrasts])

    faded = track(movie([0.6, 0.45, 0.3, 0.15, 0.09, 0.06]), _circle((48, 48), 16))
    assert faded.status[0] == [TRACKED] * 4 + [LOST] * 2
    assert [why.startswith("it faded") for why in faded.reason[0]] == [False] * 4 + [True] * 2
    assert len(faded.warnings) == 1 and "object 0 on frames 4-5: it faded" in faded.warnings[0]
    bleached = track(movie([0.6, 0.5, 0.4, 0.3, 0.25, 0.2]), _circle((48, 48), 16))
    assert bleached.status[0] == [TRACKED] * 6
    bleached = track(movie(0.6 * np.geomspace(1.0, 0.1, 24)), _circle((48, 48), 16))
    assert bleached.status[0] == [TRACKED] * 24


@pytest.mark.parametrize("brightening, followed", [(1 / 0.36, True), (1.0, False)],
                         ids=["signal kept: condensed", "signal lost: a part"])
def test_a_nucleus_that_condenses_is_followed_one_that_shrinks_to_a_part_is_lost(brightening, followed):
    """A nucleus entering mitosis gathers its chromatin into a brighter body
    of a third of its area: its signal (contrast times area) is kept, and it
    is the same object (the real HeLa movie lost such nuclei). A contour on a
    body of that size that keeps only its share of the signal is not the
    object (a part of it, or a speck where it vanished): lost, as before."""
    rng = np.random.default_rng(0)
    frames = np.stack([_centred_disk(15, 0.2, rng)] * 3 + [_centred_disk(9, 0.2 * brightening, rng)] * 2)
    tr = track(frames, _circle((48, 48), 19))
    assert tr.status[0] == [TRACKED] * 3 + [TRACKED if followed else LOST] * 2
    if followed:
        assert abs(np.sqrt(abs(signed_area(tr.contours[0][4])) / np.pi) - 9) < 1


@pytest.mark.parametrize("dimming, followed", [(0.36, True), (1.0, False)],
                         ids=["signal kept: spread", "signal grown: more than the object"])
def test_a_nucleus_that_spreads_is_followed_one_that_grows_as_bright_is_lost(dimming, followed):
    """A daughter nucleus decondenses its chromatin over more than twice its
    area within a few frames, dimmer for it: its signal (contrast times
    area) is kept, and it is the same object (the real HeLa movie read every
    second frame lost such nuclei). A contour on a body of that size as bright
    as the object holds far more than its signal (it took in a neighbour, or
    another object lies there): lost, as before."""
    rng = np.random.default_rng(0)
    frames = np.stack([_centred_disk(9, 0.45, rng)] * 3 + [_centred_disk(15, 0.45 * dimming, rng)] * 2)  # 2.8x area
    tr = track(frames, _circle((48, 48), 12))
    assert tr.status[0] == [TRACKED] * 3 + [TRACKED if followed else LOST] * 2
    if followed:
        assert abs(np.sqrt(abs(signed_area(tr.contours[0][4])) / np.pi) - 15) < 1


def test_an_object_that_moves_out_of_the_image_has_left_the_field_of_view():
    centres = [[(48, 60 + 8 * t)] for t in range(7)]  # out by the right side
    tr = track(_disk_movie(centres), _circle((48, 60), 16))
    assert tr.status[0][:3] == [TRACKED] * 3
    assert LEFT in tr.status[0] and tr.status[0][-1] == LEFT
    first_left = tr.status[0].index(LEFT)
    assert all(c is None for c in tr.contours[0][first_left:])


def test_a_registered_movie_s_nan_margin_is_the_side_of_its_field_of_view():
    """A drift-corrected movie has no data (NaN) where the stage moved away:
    an object that goes into that margin leaves the field of view there, as
    it would out of the movie cropped to the data; the contours never take in
    a NaN pixel. (Every frame with NaN was refused.)"""
    centres = [[(48, 40 + 8 * t), (30, 20)] for t in range(7)]
    frames = _disk_movie(centres)
    frames[1:, :, 72:] = np.nan  # the stage moved: nothing was seen there after frame 0
    inits = [_circle((48, 40), 16), _circle((30, 20), 16)]
    with pytest.warns(UserWarning, match=r"NaN \(or masked\) pixels, read as no data, in 6 of 7 frames"):
        tr = track(frames, inits)
    cropped = track(frames[:, :, :72], inits)
    assert tr.status == cropped.status and LEFT in tr.status[0] and tr.status[1] == [TRACKED] * 7
    for t in range(1, 7):
        for k in range(2):
            if tr.status[k][t] == TRACKED:
                mask = polygon_mask(tr.contours[k][t], frames.shape[1:])
                assert not (mask & np.isnan(frames[t])).any()
                assert iou(tr.contours[k][t], np.pad(polygon_mask(cropped.contours[k][t], (96, 72)),
                                                     ((0, 0), (0, 24)))) > 0.97


def test_a_masked_movie_s_mask_is_no_data_as_nan_is():
    """np.asarray dropped a masked array's mask (an outside tester, session
    67): its stored values, here as bright as the objects, were tracked."""
    centres = [[(48, 40 + 8 * t)] for t in range(5)]
    with_nan = _disk_movie(centres)
    with_nan[1:, :, 72:] = np.nan
    stored = np.where(np.isnan(with_nan), np.nanmax(with_nan), with_nan)
    inits = [_circle((48, 40), 16)]
    with pytest.warns(UserWarning, match="no data"):
        expected = track(with_nan, inits)
    for masked in (np.ma.masked_array(stored, mask=np.isnan(with_nan)),
                   [np.ma.masked_array(s, mask=np.isnan(n)) for s, n in zip(stored, with_nan)]):  # a list of frames
        with pytest.warns(UserWarning, match=r"NaN \(or masked\) pixels, read as no data, in 4 of 5 frames"):
            tr = track(masked, inits)
        assert tr.status == expected.status
        for got, want in zip(tr.contours[0], expected.contours[0]):
            assert (got is None and want is None) or np.allclose(got, want)


def test_most_objects_lost_on_one_frame_are_named_in_a_warning():
    """An outside tester (session 68): on a scratch-assay movie whose nuclei
    move about their spacing between frames, 30 of 59 were lost on the second
    frame with no word. Small disks that each jump four radii a frame, every
    one its own way (no stage shift), are lost together: a warning names the
    frame and says what a movie sampled that sparsely needs."""
    start = [(20, 20), (20, 76), (76, 20), (76, 76)]
    # 24 px: four radii, beyond the second looks' three; down, left, right, up. (Two that jumped alike
    # would be a stage's shift that took the other two out of view, as the pixels show.)
    jumped = [(44, 20), (20, 52), (76, 44), (52, 76)]
    frames = _disk_movie([start, start, jumped], radius=6)
    with pytest.warns(UserWarning, match=r"many of the objects followed were lost at once on frame\(s\) 2 "
                                         r"\(4 of 4\): .*laptrack"):
        tr = track(frames, [_circle(c, 9) for c in start])
    assert [row[2] for row in tr.status] == [LOST] * 4
    # One object lost alone is no such frame.
    alone = track(_disk_movie([start, start, [jumped[0], *start[1:]]], radius=6), [_circle(c, 9) for c in start])
    assert [row[2] for row in alone.status] == [LOST] + [TRACKED] * 3
    assert not any("at once" in message for message in alone.warnings)
    # A frame of zeros (a chunk missing from a zarr store) is said to be blank, not blamed on motion.
    frames = _disk_movie([start, start, start, start], radius=6)
    frames[2] = 0.0
    with pytest.warns(UserWarning, match=r"frame\(s\) 2 hold one value throughout \(a dropped frame, or a chunk"):
        tr = track(frames, [_circle(c, 9) for c in start])
    assert [row[2:] for row in tr.status] == [[LOST, TRACKED]] * 4
    assert not any("at once" in message for message in tr.warnings)


def test_a_frame_without_data_is_a_gap_the_objects_are_followed_across():
    """A dropped frame stored as NaN raised out of track() and lost every
    frame done; no object is seen on it, and each is found again after it.
    As the start frame it is bad input."""
    frames = _disk_movie([[(48, 44 + 2 * t)] for t in range(6)])
    frames[3] = np.nan
    # Not "an object that goes into them has left the field of view" (an outside tester, session 66).
    with pytest.warns(UserWarning, match=r"1 frame\(s\) hold NaN pixels only.*frame 3\): every object is lost there"):
        tr = track(frames, _circle((48, 44), 16))
    assert not any("left the field of view" in w for w in tr.warnings)
    assert tr.stop_reason == "completed" and tr.contours[0][3] is None
    # Lost there, not "left the field of view" (it did, session 63: an
    # outside probe found it; the object sits mid-field).
    assert tr.status[0] == [TRACKED] * 3 + [LOST] + [TRACKED] * 2
    assert tr.reason[0][3] == "frame 3 holds no data (NaN pixels only)" and len(tr.warnings) == 1
    assert iou(tr.contours[0][5], polygon_mask(_circle((48, 54), 12, n=200), frames.shape[1:])) > 0.9
    with pytest.raises(ValueError, match="start frame 3 holds NaN pixels only"):
        track(frames, _circle((48, 50), 16), start=3)


def test_an_object_that_shows_a_sliver_of_itself_on_the_start_frame_is_followed_in():
    """A disk 2 px into the view on the start frame: its contour rests a
    tenth of a pixel from the side, and it was taken as seen whole, then
    lost when it showed eight times more of itself (an outside tester,
    session 66; it was followed when another object was drawn too)."""
    frames = _disk_movie([[(75, -8 + 3 * t)] for t in range(6)], shape=(96, 128), radius=10)
    tr = track(frames, _circle((75, -8), 14))
    assert tr.status == [[TRACKED] * 6]


@pytest.mark.parametrize("side", ["left", "right", "top", "bottom"])
def test_an_object_that_moves_in_fast_through_a_side_is_followed(side):
    """A disk that shows a sixth of itself, then half of itself, then the
    whole, as it comes in through a side at 8 px a frame: what the side hid
    is no other object (its visible area more than doubles)."""
    centres = [(48, -8 + 8 * t) for t in range(6)]
    flip = {"left": lambda r, c: (r, c), "right": lambda r, c: (r, 95 - c),
            "top": lambda r, c: (c, r), "bottom": lambda r, c: (95 - c, r)}[side]
    frames = _disk_movie([[flip(*c)] for c in centres], radius=14)
    init = np.clip(_circle(flip(48, 2), 14), 0, 95)
    tr = track(frames, init)
    assert tr.status[0] == [TRACKED] * 6
    whole = polygon_mask(_circle(flip(*centres[-1]), 14, n=200), frames.shape[1:])
    assert iou(tr.contours[0][-1], whole) > 0.9


def test_an_object_that_moves_out_fast_is_followed_until_it_has_left():
    """9 px a frame out by the right side: the disk's visible part halves
    from one frame to the next before it is too little to be followed."""
    centres = [[(48, 71 + 9 * t)] for t in range(6)]
    tr = track(_disk_movie(centres, radius=14), _circle((48, 71), 18))
    assert tr.status[0] == [TRACKED] * 4 + [LEFT] * 2


def test_cancel_keeps_what_was_done(movie):
    seen = []
    tr = track(movie.frames, movie.init, callback=lambda p: seen.append(p.frame) or p.frame < 3)
    assert tr.stop_reason == "cancelled" and seen == [0, 1, 2, 3]
    assert all(c is not None for c in tr.contours[0][:4]) and all(c is None for c in tr.contours[0][4:])
    assert tr.status[0][5] == "not processed"


def test_generator_and_lazy_frames(movie):
    """Frames are read one at a time: a dask array works as a numpy one."""
    dask_array = pytest.importorskip("dask.array")
    lazy = dask_array.from_array(movie.frames[:4], chunks=(1, 80, 80))
    run = iter_track(lazy, movie.init)
    states = []
    res = drain(run, states.append)
    assert [s.frame for s in states] == [0, 1, 2, 3] and states[-1].done == states[-1].total == 4
    eager = track(movie.frames[:4], movie.init)
    for a, b in zip(res.contours[0], eager.contours[0]):
        np.testing.assert_allclose(a, b)


@pytest.mark.parametrize("frames, inits, kwargs, message", [
    (np.zeros((10, 10)), _circle((5, 5), 3), {}, r"\(T, H, W\).*use segment\(\)"),
    # A (T, C, H, W) or colour TIFF stack: told which axis to drop, not to use segment().
    (np.zeros((3, 2, 32, 32)), _circle((16, 16), 5), {}, r"frames\[:, 0\]"),
    (np.zeros((3, 32, 32, 3)), _circle((16, 16), 5), {}, r"colour frames.*frames\[\.\.\., 0\]"),
    (np.zeros((3, 32, 32)), [], {}, "inits is empty"),
    (np.zeros((3, 32, 32)), _circle((100, 100), 3), {}, "wholly outside"),
    # A drawing segment() refuses is refused up front, not reported as an object lost on frame 0.
    (np.zeros((3, 32, 32)), [_circle((16, 16), 5), np.array([[8, 8], [8, 20], [20, 20], [8, 20], [20, 8.0]])], {},
     r"inits\[1\] has 1 identical node"),
    (np.zeros((3, 32, 32)), np.array([[4, 4], [8, 8], [12, 12.0]]), {}, "one line"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"start": 3}, "start"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"start": 1.5}, "an integer"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"start": True}, "an integer"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"segment_options": {"material": "rubbr"}}, "rubbr"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"segment_options": {"stiffness": -1.0}}, "stiffness"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"segment_options": {"avoid": None}}, "avoid"),
    (np.full((3, 32, 32), "a"), _circle((16, 16), 5), {}, "real numeric dtype"),
    (np.zeros((3, 32, 32), complex), _circle((16, 16), 5), {}, "complex dtype"),
    (np.zeros((3, 32, 32), object), _circle((16, 16), 5), {}, "real numeric dtype"),
    # Found by an outside probe (session 64): numpy's "inhomogeneous shape", and
    # match's TypeErrors once every frame was segmented.
    ([np.zeros((32, 32)), np.zeros((30, 32))], _circle((16, 16), 5), {}, r"frame 1 has shape \(30, 32\)"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"match_options": {"method": "local"}}, "cannot set"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"match_options": {"n_mode": 3}}, "not options of match"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"match_options": {"n_modes": -3}}, "match_options: n_modes"),
    # Found by an outside tester (session 66): Python's own TypeErrors, or an option cut without a word.
    (None, _circle((16, 16), 5), {}, "frames must be a .* movie.*got NoneType"),
    (np.zeros((3, 32, 32)), None, {}, "inits must be one .* contour or a list"),
    (np.zeros((3, 32, 32)), 5, {}, "inits must be one .* contour or a list"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"max_steps": 2.5}, "max_steps must be an integer"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"max_steps": "x"}, "max_steps must be an integer"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"segment_options": [1, 2]}, "segment_options must be a dict"),
    (np.zeros((3, 32, 32)), _circle((16, 16), 5), {"match_options": 5}, "match_options must be a dict"),
])
def test_bad_input_gets_a_clear_error(frames, inits, kwargs, message):
    with pytest.raises(ValueError, match=message):
        track(frames, inits, **kwargs)


def test_one_contour_as_nested_lists_is_one_object():
    """A contour as nested lists read as a list of 2-coordinate 'contours'."""
    frames = _disk_movie([[(48, 48)]] * 2)
    tr = track(frames, _circle((48, 48), 16).tolist())
    assert tr.n_objects == 1 and tr.status == [[TRACKED, TRACKED]]


def test_one_drawing_around_two_bodies_apart_is_warned_of_when_they_part():
    """A circle around two disks 6 px apart: the start frame's contour holds
    both, joined by a bar (a person's drawing bridges bodies apart), and the
    object is lost on the next frame; in noise the bar was too wide for a
    division, and nothing said why (an outside tester, session 66)."""
    rows, cols = np.mgrid[:80, :96]
    disks = ((rows - 40) ** 2 + (cols - 30) ** 2 <= 64) | ((rows - 40) ** 2 + (cols - 52) ** 2 <= 64)
    rng = np.random.default_rng(0)
    frames = np.stack([10.0 + 190.0 * disks + rng.normal(0, 3.0, disks.shape) for _ in range(3)])
    with pytest.warns(UserWarning, match="object 0 held two bodies on frame 0"):
        tr = track(frames, _circle((40, 41), 26))
    assert tr.status[0][1] == LOST


@pytest.mark.parametrize("call", ["track", "segment"])
def test_a_callback_that_cannot_be_called_is_refused_before_any_work(call):
    """As match and simulate refuse it: segment's failed at its first step, track's after the first object."""

    with pytest.raises(ValueError, match="^callback must be callable"):
        if call == "track":
            track(np.zeros((3, 32, 32)), _circle((16, 16), 5), callback=5)
        else:
            segment(_disk_movie([[(48, 48)]])[0], _circle((48, 48), 16), callback=5)


def test_displacement_weight_breaks_the_symmetry_of_round_shapes():
    """Modes alone cannot tell which way a circle turned; in one frame of
    reference the displacement term keeps each node near where it was."""
    a = _circle((50, 50), 20, n=60)
    b = np.roll(_circle((50, 50), 20.5, n=60), 7, axis=0)  # same circle, numbered from elsewhere
    pairs = match(a, b, displacement_weight=1.0).pairs
    assert np.hypot(*(a[pairs[:, 0]] - b[pairs[:, 1]]).T).max() < 1.5


def test_a_frame_with_infinite_pixels_stops_the_run_there_and_keeps_the_frames_done():
    """A bad frame late in a movie threw away every frame tracked before it;
    now the run stops there (the other direction goes on), says which frame
    and why, and keeps what was done. On the start frame it is bad input."""
    frames = _disk_movie([[(48, 48)]] * 6)
    frames[4, 10, 10] = np.inf
    with pytest.warns(UserWarning, match="frame 4 has infinite.*forward stopped there"):
        tr = track(frames, _circle((48, 48), 16), start=2)
    assert tr.stop_reason == "frame error" and any("frame 4" in w for w in tr.warnings)
    assert tr.status[0] == [TRACKED] * 4 + ["not processed"] * 2
    assert tr.contours[0][3] is not None and tr.contours[0][4] is None
    with pytest.raises(ValueError, match="frame 2 has infinite"):
        frames[2, 10, 10] = -np.inf
        track(frames, _circle((48, 48), 16), start=2)


def test_a_misspelt_segment_option_fails_before_any_frame():
    with pytest.raises(TypeError, match="stifness"):
        track(np.zeros((3, 32, 32)), _circle((16, 16), 5), segment_options={"stifness": 1.0})


@pytest.mark.parametrize("sigma_factor", [0, 2.5, np.nan])
def test_a_sigma_factor_out_of_range_fails_before_any_frame(sigma_factor):
    # It failed per object and frame: every object was lost, each with segment()'s message.
    with pytest.raises(ValueError, match="sigma_factor must be above 0 and at most 2"):
        track(np.zeros((3, 32, 32)), _circle((16, 16), 5), segment_options={"sigma_factor": sigma_factor})


def test_polarity_can_be_given_for_all_objects():
    frames = _disk_movie([[(48, 48)]] * 3)
    tr = track(frames, _circle((48, 48), 16), segment_options={"polarity": "bright"})
    assert tr.status[0] == [TRACKED] * 3


@pytest.mark.parametrize("degrees", [0.4, -3.0, 10.0])
def test_rigid_motion_between_frames_is_found_in_full(degrees):
    """A bumpy elongated outline turned and shifted, its nodes placed anew
    along it (as a new frame's segmentation places them): the rotation is
    found to a hundredth of a degree. Closest points of the sampled curve
    would hold the nodes back (a third of a small turn was lost)."""
    from napari_physeg.core.contour import resample
    from napari_physeg.core.tracking import _rigid_motion

    t = np.linspace(0, 2 * np.pi, 400, endpoint=False)
    radius = 30 + 4 * np.cos(3 * t) + 2 * np.sin(5 * t)
    outline = np.column_stack([80 + 1.4 * radius * np.sin(t), 90 + radius * np.cos(t)])
    angle = np.deg2rad(degrees)
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    turned = (outline - outline.mean(0)) @ turn.T + outline.mean(0) + [1.5, -0.8]
    source = resample(np.roll(turned, 7, axis=0), spacing=2.7)
    target = resample(outline, spacing=2.7)
    rotation, shift = _rigid_motion(source, target)
    found = np.degrees(np.arctan2(rotation[1, 0], rotation[0, 0]))
    assert found == pytest.approx(-degrees, abs=0.01)
    back = source @ rotation.T + shift  # on the untouched outline again
    dense = resample(outline, spacing=0.05)
    assert np.sqrt(((back[:, None] - dense[None]) ** 2).sum(-1)).min(1).max() < 0.05


def test_a_frame_starts_on_the_predicted_contour_and_reads_its_levels_from_the_drawing(movie):
    """Each frame's contour starts where the previous result and the motion
    predict it, on the border, with the margin-grown drawing around it read
    only for the object's levels: the same outline, in fewer steps, than
    starting from the drawing and travelling its margin back."""
    from napari_physeg.core.segmentation import _segment_from
    from napari_physeg.core.contour import area_centroid
    from napari_physeg.core.tracking import _drawing_around

    before, last = track(movie.frames[:2], movie.init).contours[0]
    predicted = last + area_centroid(last) - area_centroid(before)  # as _predictions' first, on a still stage
    drawing = _drawing_around(predicted)
    from_drawing = segment(movie.frames[2], drawing)
    from_predicted = _segment_from(movie.frames[2], drawing, predicted)
    assert from_predicted.converged and from_drawing.converged
    assert from_predicted.steps < from_drawing.steps
    assert iou(from_predicted.contour, movie.masks[2]) > 0.98
    assert abs(iou(from_predicted.contour, movie.masks[2]) - iou(from_drawing.contour, movie.masks[2])) < 0.01


def test_a_carried_contour_on_the_border_skips_the_evolution(movie):
    """A contour carried over that already rests on the object's border
    starts in the refinement (the region force alone): bringing it there is
    the evolution's job. One carried far inside the object does not."""
    from napari_physeg.core.segmentation import _evolve, _segment_arguments
    from napari_physeg.core.tracking import _grown

    image, outline = movie.frames[3], movie.outlines[3][::8]
    drawing = _grown(outline, 6.0)
    centre = outline.mean(0)

    def run(start):
        steps = list(_evolve(**_segment_arguments(image, drawing, {}), start=start))
        return steps[0].phase, steps[-1].contour

    phase, on_border = run(outline)
    assert phase == "refinement"
    assert iou(on_border, movie.masks[3]) > 0.98
    phase, from_inside = run(centre + 0.6 * (outline - centre))
    assert phase == "evolution"
    assert iou(from_inside, movie.masks[3]) > 0.98


def test_objects_on_a_jittering_stage_are_followed():
    """Three cells 28 px apart on a stage that jumps 13-16 px between frames,
    each way in turn (session 25's code lost 6 of the 24 object-frames, and
    one contour took a neighbour 28 px off)."""
    jumps = [(0, 0), (12, -10), (-13, 9), (10, 12), (-12, -11), (13, -8), (-10, 13), (12, 9)]
    offsets = np.cumsum(jumps, axis=0) + 10
    cells = [(34, 34), (34, 62), (62, 48)]
    centres = [[(r + o[0], c + o[1]) for r, c in cells] for o in offsets]
    tr = track(_disk_movie(centres, radius=9, shape=(128, 128)), [_circle(c, 12.5) for c in centres[0]])
    assert tr.status == [[TRACKED] * 8] * 3
    for k in range(3):
        assert np.all(np.hypot(*(tr.centroids(k) - [c[k] for c in centres]).T) < 1.0)



def test_objects_on_a_stage_that_jumps_beyond_the_looks_reach_are_followed():
    """Three cells on a stage that jumps 40-60 px between frames, four to
    six of their radii: beyond where their looks are searched (two radii),
    the whole frame's shift (read coarsely by phase correlation) says where
    to search them. Without it every cell was lost at the first jump."""
    jumps = [(0, 0), (45, -40), (-52, 44), (40, 55), (-58, -41), (47, -50)]
    offsets = np.cumsum(jumps, axis=0) + 70
    cells = [(34, 34), (34, 62), (62, 48)]
    centres = [[(r + o[0], c + o[1]) for r, c in cells] for o in offsets]
    tr = track(_disk_movie(centres, radius=9, shape=(256, 256), noise=0.05), [_circle(c, 12.5) for c in centres[0]])
    assert tr.status == [[TRACKED] * len(jumps)] * 3
    for k in range(3):
        assert np.all(np.hypot(*(tr.centroids(k) - [c[k] for c in centres]).T) < 1.0)


@pytest.mark.parametrize("shift", [(0, 0), (3, -2), (37, 61), (-90, 20)])
def test_a_frames_shift_is_read_by_phase_correlation_to_the_binnings_precision(shift):
    """_frame_shift: how a textured frame's content moved (its own copy
    rolled), to within the binning factor (a 300 x 500 frame is read at
    1 / 4), whichever way and however far, short of half the frame."""
    from scipy import ndimage as ndi

    from napari_physeg.core.tracking import _frame_shift

    rng = np.random.default_rng(0)
    before = ndi.gaussian_filter(rng.normal(size=(300, 500)), 3.0)
    after = np.roll(before, shift, axis=(0, 1))
    assert np.abs(_frame_shift(before, after) - shift).max() <= 4


@pytest.mark.parametrize("blank", ["before", "after", "both"])
def test_a_blank_frame_shows_no_shift_and_no_warning(blank):
    """_frame_shift with a dropped (blank) frame on either side: no motion,
    and nothing warned from inside scikit-image's phase correlation."""
    import warnings

    from scipy import ndimage as ndi

    from napari_physeg.core.tracking import _frame_shift

    textured = ndi.gaussian_filter(np.random.default_rng(0).normal(size=(120, 150)), 3.0)
    before = np.zeros_like(textured) if blank in ("before", "both") else textured
    after = np.zeros_like(textured) if blank in ("after", "both") else np.roll(textured, (5, -7), axis=(0, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert np.array_equal(_frame_shift(before, after), [0, 0])


@pytest.mark.parametrize("case", ["stage", "one vanished", "two of three vanished", "each its own way", "still"])
def test_the_stage_shift_is_read_off_the_objects_that_move_together(case):
    """_stage_shift: the shift of a jittering stage, read off the looks of
    the objects tracked on the frame before; none when most of them did not
    move together (an object that vanished, or whose look-alike neighbour
    sits where the shift would take it, does not carry it; cells that move
    each their own way show none)."""
    from napari_physeg.core.tracking import _Run, _stage_shift

    cells = [(30, 30), (30, 70), (70, 50)]
    moves = {"stage": [(7, -5)] * 3, "one vanished": [(7, -5), (7, -5), None],
             "two of three vanished": [(0, 0), None, (40, -20)], "each its own way": [(6, 0), (-3, 5), (0, -6)],
             "still": [(0, 0)] * 3}[case]
    after = [(None, None) if m is None else (r + m[0], c + m[1]) for (r, c), m in zip(cells, moves)]
    frames = _disk_movie([cells, after], radius=9, shape=(110, 110), noise=0.05)
    run = _Run(inits=[None] * 3, start=0, options={}, contours=[[_circle(c, 9), None] for c in cells],
               status=[[TRACKED, None]] * 3, seen=[None] * 3)
    shift = _stage_shift(run, frames[0], frames[1], 1, 1)
    expected = {"stage": (7, -5), "one vanished": (7, -5)}.get(case, (0, 0))
    assert np.allclose(shift, expected, atol=1.0)


def test_objects_that_moved_together_beyond_their_predictions_show_a_common_motion():
    """The shift of a jittering stage, read off the objects found first on a
    frame: their common displacement beyond their predictions, when they
    agree; none from fewer than two, from scattered ones (cells moving on
    their own) or below a pixel."""
    from napari_physeg.core.tracking import _common_motion

    rng = np.random.default_rng(0)
    stage = np.array([7.0, -5.0])
    assert np.allclose(_common_motion(list(stage + rng.normal(0, 0.5, (4, 2)))), stage, atol=0.6)
    assert np.allclose(_common_motion(list(stage + rng.normal(0, 0.5, (2, 2)))), stage, atol=0.6)
    assert not _common_motion([stage]).any()
    assert not _common_motion(list(rng.normal(0, 4.0, (9, 2)))).any()
    assert not _common_motion(list(np.array([0.6, 0.3]) + rng.normal(0, 0.05, (5, 2)))).any()


def _stardist_image_and_labels():
    """The Data Science Bowl test image of the stardist wheel and its hand-made labels (make setup installs it)."""
    import importlib.util
    from pathlib import Path

    tifffile = pytest.importorskip("tifffile")
    spec = importlib.util.find_spec("stardist")
    if spec is None:
        pytest.skip("stardist's test images are not installed (make setup installs them)")
    folder = Path(list(spec.submodule_search_locations)[0]) / "data" / "images"
    return tifffile.imread(folder / "img2d.tif").astype(float), tifffile.imread(folder / "mask2d.tif")


def test_two_touching_nuclei_drifting_together_keep_their_own_places():
    """Found by probing (session 29) on a real image: each object's pixels
    were claimed, for the objects done before it, where they were on the
    frame before; as the field drifted, the nucleus done first took the
    band its neighbour moved into, frame after frame: it ended on the
    neighbour's place, reported tracked, and the neighbour was lost."""
    from scipy import ndimage as ndi

    from napari_physeg.core.contour import outward_normals, remove_loops
    from skimage import measure

    image, labels = _stardist_image_and_labels()
    box, drift = (slice(230, 380), slice(260, 430)), np.array([2.5, 1.5])
    frames = np.stack([ndi.shift(image, drift * t, order=1, mode="nearest")[box] for t in range(12)])
    truth = np.stack([ndi.shift(labels, drift * t, order=0)[box] for t in range(12)])
    inits = []
    for label in (138, 139):
        outline = max(measure.find_contours((truth[0] == label).astype(float), 0.5), key=len)[:-1]
        inits.append(remove_loops(outline + 3.0 * outward_normals(outline)))
    tr = track(frames, inits)
    for k, label in enumerate((138, 139)):
        assert tr.status[k] == [TRACKED] * 12
        for t, contour in enumerate(tr.contours[k]):
            mask = polygon_mask(contour, frames.shape[1:])
            assert (truth[t][mask] == label).mean() > 0.5, (k, t)


def test_a_drawing_beyond_the_image_side_is_tracked_without_segment_s_clipping_warning():
    """Found by probing (session 29): every drawing grown beyond the image's
    side warned "2 of 31 nodes of init lie outside the image and were
    clipped to it", naming neither the object nor the frame, on every run."""
    import warnings

    frames = _disk_movie([[(48, 8 + t)] for t in range(3)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr = track(frames, _circle((48, 8), 16))
    assert tr.status[0] == [TRACKED] * 3 and tr.warnings == ()


def test_on_identical_frames_a_blurred_object_s_contour_stays_where_it_was():
    """A tracked frame's drawing reads the object's background. Drawn anew
    around each frame's contour, on a blurred edge its line lay on the ramp
    at a distance the contour itself set, and the contour crept inward frame
    after frame (here 8 % of its area over nine frames); the last frame's
    drawing, carried over while it still lies around the object, holds it."""
    from scipy import ndimage as ndi

    rows, cols = np.mgrid[:96, :96]

    def disk(centre, radius):
        return ((rows - centre[0]) ** 2 + (cols - centre[1]) ** 2 < radius ** 2).astype(float)

    image = ndi.gaussian_filter(disk((48, 48), 12) + 0.8 * disk((48, 74.4), 10.8), 4.0) + 0.1
    rng = np.random.default_rng(1)
    frames = np.stack([image + rng.normal(0, 0.01, image.shape) for _ in range(10)])
    angle = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    tr = track(frames, [np.c_[48 + 15.6 * np.sin(angle), 48 + 15.6 * np.cos(angle)]])
    assert tr.status[0] == [TRACKED] * 10
    areas = [abs(signed_area(c)) for c in tr.contours[0][1:]]
    assert max(areas) / min(areas) < 1.02


def test_small_spots_of_a_sparse_field_are_followed_on_their_own_edges():
    """Four spots 7 px across on a 256 px field (a quarter of a percent of
    it), drifting up to 1.4 px a frame: every frame's contour lies on its
    spot's edge. (The frame's intensity range stopped at the background's
    noise, the spots were clipped flat and the contours ran out onto the
    blur's foot: worst frame 0.71.)"""
    from scipy import ndimage as ndi

    rng = np.random.default_rng(1)
    centres = np.array([[60.3, 70.2], [150.7, 180.1], [200.2, 40.6], [100.5, 200.4]])
    drift = rng.uniform(-1, 1, (4, 2))
    rows, cols = np.mgrid[:256, :256]
    frames, truths = [], []
    for t in range(8):
        spots = [np.hypot(rows - c[0] - v[0] * t, cols - c[1] - v[1] * t) <= 3.5 for c, v in zip(centres, drift)]
        frames.append(ndi.gaussian_filter(0.7 * np.any(spots, axis=0), 1.0) + 0.1 + rng.normal(0, 0.03, rows.shape))
        truths.append(spots)
    angle = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    inits = [np.column_stack([c[0] + 4.5 * np.sin(angle), c[1] + 4.5 * np.cos(angle)]) for c in centres]
    res = track(np.stack(frames), inits)
    for k in range(4):
        for t in range(8):
            assert res.status[k][t] == TRACKED
            found = polygon_mask(res.contours[k][t], rows.shape)
            assert (found & truths[t][k]).sum() / (found | truths[t][k]).sum() > 0.85


@pytest.mark.parametrize("shift", [(0.0, 0.0), (2.3, -1.6), (-5.5, 4.2)])
def test_an_objects_own_motion_is_read_off_its_looks_to_a_fraction_of_a_pixel(shift):
    """_look_shift on a textured blob moved by a known sub-pixel shift, in a
    crowd of others that stay: its own motion, not theirs, within 0.25 px."""
    from scipy import ndimage as ndi

    from napari_physeg.core.tracking import _look_shift

    rng = np.random.default_rng(3)
    rr, cc = np.mgrid[:120, :120]
    still = sum(np.exp(-((rr - r) ** 2 + (cc - c) ** 2) / 60.0) for r, c in [(25, 30), (30, 95), (95, 25), (90, 90)])
    blob = np.exp(-((rr - 60) ** 2 + (cc - 60) ** 2) / 80.0) * (1 + 0.3 * ndi.gaussian_filter(rng.random(rr.shape), 2))
    before, after = still + blob, still + ndi.shift(blob, shift, order=3)
    found = _look_shift(before, after, _circle((60, 60), 12))
    np.testing.assert_allclose(found, shift, atol=0.25)


def test_an_objects_looks_tell_nothing_when_flat_or_moved_beyond_the_search():
    from scipy import ndimage as ndi

    from napari_physeg.core.tracking import _look_shift

    rr, cc = np.mgrid[:120, :120]
    blob = np.exp(-((rr - 60) ** 2 + (cc - 60) ** 2) / 80.0)
    assert _look_shift(np.zeros((120, 120)), blob, _circle((60, 60), 12)) is None
    # The search reaches one radius (12 px): a 20-px jump is beyond it.
    assert _look_shift(blob, ndi.shift(blob, (20, 0), order=1), _circle((60, 60), 12)) is None


@pytest.fixture
def warped(monkeypatch):
    """benchmarks/tracking_warped.py, imported from the benchmarks' folder, and forgotten after."""
    import sys
    from pathlib import Path

    names = ("tracking_warped", "tracking", "real_data", "_common")
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    for name in names:
        monkeypatch.delitem(sys.modules, name, raising=False)
    import tracking_warped

    yield tracking_warped
    for name in names:
        sys.modules.pop(name, None)


def test_touching_nuclei_of_a_warped_real_field_keep_their_own(dsb, warped):
    """Four nuclei of the Data Science Bowl image (labels 100 and 128 touch)
    in a 96-px window of the warped movie of benchmarks/tracking_warped.py
    ("DSB elastic": a smooth field that changes over time, a drift,
    bleaching and noise), each drawn around as a user would. Each part of a
    warped field moves its own way: claimed where the field as a whole
    drifted, a nucleus left a band of its own unclaimed, which its touching
    neighbour, done first, took, a band a frame (6 object-frames on another
    nucleus' label, 3 visible nucleus-frames lost, 3 under two contours).
    Claimed by their own steady motions, none."""
    image, labels = dsb[0].astype(np.float64), dsb[1].astype(np.int32)
    _, elastic = warped.MOVIES["DSB elastic"]
    window = warped.Warp(**{**elastic.__dict__, "window": (156, 56, 96, 96)})
    frames, truth, whole = warped.warp_movie(image, labels, window)
    ids = warped.objects(truth[0])
    inits = [warped.tracking.drawn_around(warped.real_data.largest_filled(truth[0] == i)) for i in ids]
    masks, _, _ = warped.run_ours_masks(frames, inits)
    summary = warped.summarise(warped.score(masks, truth, whole, ids), ids)
    assert len(ids) == 4
    assert (summary["switches"], summary["lost"], summary["duplicates"]) == (0, 0, 0), summary


def test_labels_numbered_per_frame_are_linked_and_a_division_ends_the_track(warped):
    """benchmarks/real_data.linked_labels, which makes the real HeLa movie's truth tracks:
    a nucleus that moves a few px keeps its number; one that divides (two labels of the next
    frame nearest it) ends, and both daughters are new; one that jumps further than the
    link distance, or whose area doubles, is new too."""
    from skimage.draw import disk

    def frame(centres, radii):
        out = np.zeros((100, 160), np.int32)
        for label, (centre, radius) in enumerate(zip(centres, radii), start=1):
            out[disk(centre, radius, shape=out.shape)] = label
        return out

    # Per frame numbering differs: the shipped labels are numbered anew on every frame.
    first = frame([(20, 20), (50, 80), (80, 140), (20, 140)], [6, 8, 6, 6])
    second = frame([(50, 70), (50, 92), (22, 24), (80, 110), (20, 140)], [7, 7, 6, 6, 9])
    linked = warped.real_data.linked_labels(np.stack([first, second]), 25.0, 1.6)
    assert np.array_equal(linked[0], first)
    ids = {label: int(np.bincount(linked[1][second == label]).argmax()) for label in range(1, 6)}
    assert ids[3] == 1  # moved 4.5 px: the same nucleus
    assert len({ids[1], ids[2], ids[4], ids[5]} | {1, 2, 3, 4}) == 8  # all others are new
    # The daughters are new even when one of them lies nearer than any other label.
    assert ids[1] != 2 and ids[2] != 2


@pytest.mark.parametrize("label", [80, 110])
def test_a_click_on_a_real_nucleus_starts_as_segment_alone_reads_it(hela_start, label):
    """A click on the brightest spot of a HeLa nucleus, read at the frame's
    scale as around that spot, ended on it (IoU 0.03 and 0.15; segment()
    alone 0.95, on a magnified view): a click is inside its object, and the
    start frame reads it on that view too (a MitoCheck nucleus clicked so
    was lost on every later frame; an outside tester, session 69)."""
    from scipy import ndimage as ndi

    frames, labels = hela_start
    nucleus = labels[0] == label
    brightest = np.unravel_index(np.argmax(np.where(nucleus, ndi.gaussian_filter(frames[0].astype(float), 1), -np.inf)),
                                 nucleus.shape)
    res = track(frames, np.array([brightest], float))
    assert res.status[0][0] == TRACKED
    assert iou(res.contours[0][0], nucleus) > 0.8


def test_a_real_nucleus_read_first_on_the_ground_is_still_tracked(hela_start):
    """HeLa nucleus 43 on frame 1: the margin about its frame-0 contour is
    first read as lying inside an object at the ground's level, and the
    contour spreads over the ground until that reading gives way to the
    nucleus'. Cutting the ground's arms between the bright nuclei (the rule
    that parts a saturated neighbour's rim from a person's click) changed
    how it gave way, and the nucleus was lost from frame 1 on."""
    from skimage import measure

    frames, labels = hela_start
    nucleus = labels[0] == 43
    # As benchmarks/tracking_warped.py draws it: the outline, 2 px apart, 3 px out.
    outline = resample(max(measure.find_contours(nucleus.astype(float), 0.5), key=len)[:-1], spacing=2.0)
    res = track(frames, outline + 3.0 * outward_normals(outline))
    assert list(res.status[0]) == [TRACKED, TRACKED]
    found = polygon_mask(res.contours[0][1], labels.shape[1:])
    overlaps = np.bincount(labels[1][nucleus])
    overlaps[0] = 0
    later = labels[1] == overlaps.argmax()  # the label frame 1 gives the nucleus
    assert (found & later).sum() / (found | later).sum() > 0.7


def test_the_start_frame_has_segment_s_own_step_budget():
    """The start frame's contours start from the drawings, as segment()'s do:
    a circle about a large, faint mesenchymal stem cell (Cell Tracking
    Challenge) came to rest after 333 steps, and with track()'s 300 steps
    per frame the cell was not found, nor looked for again."""
    rr, cc = np.mgrid[:96, :96]
    disk = np.hypot(rr - 48, cc - 48) <= 14
    frames = np.stack([np.where(disk, 0.8, 0.2) + np.random.default_rng(t).normal(0, 0.03, disk.shape)
                       for t in range(3)])
    t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    far = np.column_stack([48 + 30 * np.sin(t), 48 + 30 * np.cos(t)])
    assert segment(frames[0], far, max_steps=8).stop_reason == "max_steps"  # more than 8 steps from there
    tr = track(frames, far, max_steps=8)
    assert tr.status[0][0] == "tracked"


def _field_of_nuclei(rng, shape=(220, 220), n=26, spacing=24):
    """A sample of ``n`` blurred disks of random radius (7-10 px) and
    brightness, at least ``spacing`` px apart: (image, centres, radii)."""
    from scipy import ndimage as ndi

    centres = []
    while len(centres) < n:
        c = rng.uniform(12, np.array(shape) - 12)
        if all(np.hypot(*(c - o)) >= spacing for o in centres):
            centres.append(c)
    centres, radii = np.array(centres), rng.uniform(7, 10, n)
    rr, cc = np.mgrid[: shape[0], : shape[1]]
    image = np.full(shape, 0.1)
    for (r, c), radius, level in zip(centres, radii, rng.uniform(0.5, 1.0, n)):
        image[(rr - r) ** 2 + (cc - c) ** 2 <= radius**2] = level
    return ndi.gaussian_filter(image, 1.0) + 0.02 * rng.standard_normal(shape), centres, radii


def test_nuclei_on_a_jittering_stage_are_found_where_it_brought_them_and_again_when_back_in_view():
    """A crowd of alike nuclei seen through a window that jumps up to 20 px
    a frame, twice their radius: nuclei leave the view and come back. Each
    is looked for where the stage moved it, never at its old place (which
    shows a neighbour after a jump), and one that left is looked for again
    whenever the stage brings it back, however long it was out (an outside
    tester, session 73: on a real frame so moved, 32 object-frames lay on
    another nucleus and 11 nuclei in view were said to have left it)."""
    rng = np.random.default_rng(7)
    sample, centres, radii = _field_of_nuclei(rng)
    jumps = np.vstack([[0, 0], rng.integers(-20, 21, (9, 2))])
    offsets = np.clip(50 + np.cumsum(jumps, axis=0), 0, 100)
    frames = np.stack([sample[r:r + 120, c:c + 120] for r, c in offsets])
    wholly_in = [np.all((centres - o - radii[:, None] >= 1) & (centres - o + radii[:, None] <= 118), axis=1)
                 for o in offsets]
    drawn = np.flatnonzero(wholly_in[0])
    tr = track(frames, [_circle(centres[j] - offsets[0], 1.3 * radii[j]) for j in drawn])
    came_back = 0
    for k, j in enumerate(drawn):
        for t, o in enumerate(offsets):
            if wholly_in[t][j] and tr.status[k][t] == TRACKED:  # on its own nucleus, never a neighbour's
                assert np.hypot(*(tr.centroids(k)[t] - (centres[j] - o))) < 0.5 * radii[j], (k, t)
            left_before = any(tr.status[k][s] == LEFT for s in range(t))
            if wholly_in[t][j] and left_before:
                came_back += 1
                assert tr.status[k][t] == TRACKED, (k, t, tr.status[k])
    assert came_back >= 10

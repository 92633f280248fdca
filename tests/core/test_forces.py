"""Image forces along normal lines: direction, balance on the border, symmetry."""

import cv2
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from napari_physeg import data
from napari_physeg.core.contour import outward_normals
from napari_physeg.core.features import compute_features
from napari_physeg.core.forces import FORCE_NAMES, ForceField, normalize_weights
from napari_physeg.core.segmentation import segment
from napari_physeg.core.region import drawing_levels, objectness


def _field(obj, weights):
    f = compute_features(obj.image, b=0.7)
    model = drawing_levels(f.intensity, obj.init_near)
    return ForceField.from_features(f.edges, f.distance, objectness(f.intensity, model), weights)


def _circle(c, r, n=80):
    t = 2 * np.pi * np.arange(n) / n
    return np.column_stack([c[0] + r * np.cos(t), c[1] + r * np.sin(t)])


@pytest.fixture(scope="module")
def disc():
    # A bright disc of radius 40 centred at (64, 64), its border at r = 40.
    return data.ellipse((128, 128), center=(64, 64), axes=(40, 40))


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_each_force_pulls_toward_the_border_from_both_sides(disc, name):
    field = _field(disc, {name: 1.0})
    for radius, sign in ((30.0, +1), (50.0, -1)):  # inside: outward, outside: inward
        nodes = _circle((64, 64), radius)
        F = field(nodes)
        radial = (F * outward_normals(nodes)).sum(1)
        assert np.all(np.sign(radial) == sign), (name, radius)


@pytest.mark.parametrize("name", FORCE_NAMES)
def test_each_force_nearly_vanishes_on_the_border(disc, name):
    field = _field(disc, {name: 1.0})
    on = field(_circle((64, 64), 40.0))
    off = field(_circle((64, 64), 44.0))
    assert np.abs(on).mean() < 0.35 * np.abs(off).mean()


def test_forces_are_bounded_by_the_weights(disc):
    w = normalize_weights(FORCE_NAMES, {"edges": 0.5, "intensity": 0.2, "distance": 0.3})
    F = _field(disc, w)(_circle((64, 64), 20.0))
    assert np.linalg.norm(F, axis=1).max() <= sum(w.values()) + 1e-9


@settings(max_examples=30, deadline=None)
@given(
    radius=st.floats(8, 60),
    shift=st.tuples(st.integers(-10, 10), st.integers(-10, 10)),
    weights=st.fixed_dictionaries({k: st.floats(0, 1) for k in FORCE_NAMES}).filter(
        lambda w: sum(w.values()) > 0.01),
)
def test_forces_are_finite_mirror_symmetric_and_translation_equivariant(disc, radius, shift, weights):
    field = _field(disc, weights)
    nodes = _circle((64 + shift[0], 64 + shift[1]), radius, n=64)
    F = field(nodes)
    assert np.all(np.isfinite(F))
    # Mirror the image left-right: the forces on mirrored nodes mirror too.
    mirrored = ForceField(edges=field.edges[:, ::-1].copy(), distance=field.distance[:, ::-1].copy(),
                          objectness=field.objectness[:, ::-1].copy(), weights=field.weights)
    flip = nodes * [1, -1] + [0, 127]
    Fm = mirrored(flip[::-1])[::-1]  # reversed to keep the orientation
    assert np.allclose(Fm * [1, -1], F, atol=1e-4)
    # Shifting the images and the nodes by whole pixels shifts nothing else.
    dr, dc = 7, -5
    moved = ForceField(edges=np.roll(field.edges, (dr, dc), (0, 1)), distance=np.roll(field.distance, (dr, dc), (0, 1)),
                       objectness=np.roll(field.objectness, (dr, dc), (0, 1)), weights=field.weights)
    inside = np.all((nodes > 45) & (nodes < 83), axis=1).all()
    if inside:  # away from the wrapped border
        assert np.allclose(moved(nodes + [dr, dc]), F, atol=1e-4)


def test_normalize_weights_validates():
    assert normalize_weights(("edges",)) == {"edges": 0.4}
    with pytest.raises(ValueError, match="subset"):
        normalize_weights(("edges", "gravity"))
    with pytest.raises(ValueError, match="positive"):
        normalize_weights(FORCE_NAMES, {"edges": 0, "intensity": 0, "distance": 0})


@pytest.mark.parametrize("forces, weights, message", [
    (None, None, "forces must be a non-empty subset.*got None"),
    (FORCE_NAMES, [0.4, 0.3, 0.3], "weights must be a dict"),
    (FORCE_NAMES, {"edges": 1e39}, "from 0 to 1e\\+06"),
    (FORCE_NAMES, {"edges": "1"}, "must be a number"),
    (FORCE_NAMES, {"edges": True}, "must be a number"),
])
def test_forces_and_weights_of_the_wrong_kind_are_told_not_raised_from_inside(forces, weights, message):
    """An outside fuzzer's findings (session 67): forces=None and a list of
    weights raised Python's own TypeErrors from inside; a weight of 1e39
    overflowed the float32 force images to NaN (six RuntimeWarnings)."""
    with pytest.raises(ValueError, match=message):
        normalize_weights(forces, weights)


def test_beyond_the_image_the_border_is_a_wall_and_the_distance_its_mirror():
    rng = np.random.default_rng(3)
    field = ForceField.from_features(rng.random((30, 40)), rng.random((30, 40)) * 9, rng.uniform(-1, 1, (30, 40)),
                                     {"edges": 1.0})
    inside = np.column_stack([rng.uniform(0, 29, 50), rng.uniform(0, 39, 50)])
    # Mirror about the outermost pixels: row -r reads row r, row 29 + r reads 29 - r.
    flips = {"top": (-inside[:, 0], inside[:, 1]), "bottom": (58 - inside[:, 0], inside[:, 1]),
             "left": (inside[:, 0], -inside[:, 1]), "right": (inside[:, 0], 78 - inside[:, 1])}
    for side, (r, c) in flips.items():
        beyond = np.column_stack([r, c])
        far = np.any((beyond < -1) | (beyond > [30, 40]), axis=1)
        got, mirror = field.sample(beyond), field.sample(inside)
        np.testing.assert_allclose(got[:, 1], mirror[:, 1], atol=1e-3, err_msg=side)
        assert np.all(got[far, 0] == 1.0) and np.all(got[far, 2] == -1.0), side


@pytest.mark.parametrize("n", [1, 7, 4096, 4097, 9000])
def test_samples_of_one_image_are_those_of_all_three(n):
    # Points fold into rows of 4096 for cv2.remap: any number comes back whole.
    rng = np.random.default_rng(n)
    field = ForceField.from_features(rng.random((20, 30)), rng.random((20, 30)) * 5, rng.uniform(-1, 1, (20, 30)),
                                     {"edges": 1.0})
    points = rng.uniform(-3, 33, (n, 3, 2))
    every = field.sample(points)
    np.testing.assert_array_equal(field.distance_at(points), every[..., 1])
    from napari_physeg.core import forces

    row_map, col_map, _ = forces._remap_grid(points)
    np.testing.assert_array_equal(field._objectness_maps(row_map, col_map).ravel()[:points.size // 2],
                                  every[..., 2].ravel())


def test_a_contour_of_more_nodes_than_a_remap_map_holds():
    # cv2.remap takes maps of fewer than 2**15 rows: a node per row is cut into runs.
    t = np.linspace(0, 2 * np.pi, 40000, endpoint=False)
    nodes = np.column_stack([64 + 30 * np.sin(t), 64 + 30 * np.cos(t)])
    rows, cols = np.mgrid[:128, :128]
    disc = (np.hypot(rows - 64, cols - 64) < 40).astype(float)
    field = ForceField.from_features(np.zeros_like(disc), np.full(disc.shape, 10.0), 2 * disc - 1,
                                     {"intensity": 1.0, "distance": 1.0})
    forces = field(nodes)
    assert forces.shape == nodes.shape and np.all(np.isfinite(forces))
    outward = (forces * outward_normals(nodes)).sum(1)
    assert np.all(outward > 0)  # inside the disc the region force pushes out


def test_an_image_too_large_for_cv2_is_sampled_alike():
    # cv2.remap refuses images of 2**15 px on a side: those are sampled by
    # scipy, with the same wall, the same mirror and the same interpolation.
    from napari_physeg.core import forces

    rng = np.random.default_rng(4)
    field = ForceField.from_features(rng.random((25, 35)), rng.random((25, 35)) * 9, rng.uniform(-1, 1, (25, 35)),
                                     {"edges": 1.0})
    rows = rng.uniform(-4, 29, (40, 9)).astype(np.float32)
    cols = rng.uniform(-4, 39, (40, 9)).astype(np.float32)
    cases = [(field._stack, cv2.BORDER_CONSTANT, (1.0, 0.0, -1.0, 0.0)),
             (field._distance32, cv2.BORDER_REFLECT_101, 0.0), (field._objectness32, cv2.BORDER_CONSTANT, -1.0)]
    for image, border, value in cases:
        np.testing.assert_allclose(forces._remap_large(image, rows, cols, border, value),
                                   forces._remap(image, rows, cols, border, value), atol=1e-5)


def test_a_contour_across_an_image_too_large_for_cv2():
    image = np.zeros((40, 40000))
    image[10:30, 100:39900] = 1.0
    top = np.column_stack([np.full(200, 4.0), np.linspace(50, 39950, 200)])
    init = np.vstack([top, top[::-1] + [32.0, 0.0]])
    res = segment(image, init)
    along = (res.contour[:, 1] > 300) & (res.contour[:, 1] < 39700)
    assert res.converged
    np.testing.assert_allclose(np.sort(np.abs(res.contour[along, 0] - 19.5)), 10.0, atol=0.1)  # rows 9.5 and 29.5



def _line_field(objectness, phase):
    """The region force alone (refinement), or beside edge and distance
    forces that vanish here (evolution: no edges, a flat distance)."""
    weights = {"intensity": 1.0} if phase == "refinement" else {"edges": 0.4, "intensity": 0.3, "distance": 0.3}
    return ForceField(edges=np.zeros(objectness.shape), distance=np.full(objectness.shape, 9.0),
                      objectness=objectness, weights=weights, min_length=3.0)


@pytest.mark.parametrize("phase", ["evolution", "refinement"])
@pytest.mark.parametrize("gap", [2, 3])
def test_a_slit_narrower_than_the_region_line_pushes_its_wall_back_not_across(gap, phase):
    """Two objects (fingers) ``gap`` px apart: a node of the left one's wall
    half a pixel into the slit sees the right one within its region line. The
    region force must push it back onto its own object, not on across the
    slit (the refinement closed the slits of a closed hand this way, from its
    own outline: IoU 0.944 before session 32, 0.9985 after)."""
    cols = np.arange(64)[None, :].repeat(64, 0)
    signed = np.where((cols <= 30) | (cols > 30 + gap), 1.0, -1.0)  # the slit's walls at 30.5 and 30.5 + gap
    nodes = np.column_stack([np.arange(20.0, 44.0), np.full(24, 31.0)])  # half a pixel into the slit
    normals = np.tile([0.0, 1.0], (24, 1))  # outward: into the slit, toward the other finger
    F = _line_field(signed, phase)(nodes, normals)
    assert np.all(F[:, 1] < 0), F[:, 1]

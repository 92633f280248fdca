import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from napari_physeg.core.contour import (
    bounding_window,
    as_contour,
    densify,
    outward_normals,
    perimeter,
    resample,
    segment_lengths,
    signed_area,
)


def _circle(n, r=10.0, c=(50.0, 60.0), start=0.0):
    t = start + 2 * np.pi * np.arange(n) / n
    return np.column_stack([c[0] + r * np.cos(t), c[1] + r * np.sin(t)])


def test_as_contour_drops_closing_and_duplicate_nodes():
    c = _circle(8)
    closed = np.vstack([c[:3], c[2:3], c[3:], c[:1]])  # duplicate node 2, repeated first node
    out = as_contour(closed)
    assert out.dtype == np.float64 and out.shape == (8, 2)
    assert np.array_equal(out, c)


@pytest.mark.parametrize(
    "points, message",
    [
        (np.empty((0, 2)), "empty"),
        (np.zeros((5, 3)), r"\(N, 2\)"),
        ([[0, 0], [1, 1]], "at least 3"),
        ([[0, 0], [0, 0], [0, 0], [0, 0]], "at least 3"),
        ([[0, 0], [1, 1], [2, 2], [3, 3]], "degenerate"),
        ([[0, 0], [1, np.nan], [2, 0]], "NaN"),
        ("abc", "holds text, not coordinates"),
    ],
)
def test_as_contour_rejects_bad_input(points, message):
    with pytest.raises(ValueError, match=message):
        as_contour(points, name="init")


def test_outward_normals_point_away_from_the_centre_for_both_orientations():
    for c in (_circle(40), _circle(40)[::-1]):
        n = outward_normals(c)
        radial = (c - [50.0, 60.0]) / 10.0
        assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
        assert np.all((n * radial).sum(1) > 0.99)


def test_signed_area_of_a_square():
    sq = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    assert abs(signed_area(sq)) == pytest.approx(4.0)
    assert signed_area(sq) == -signed_area(sq[::-1])


@settings(max_examples=50, deadline=None)
@given(n=st.integers(3, 400), start=st.floats(0, 6.3), spacing_nodes=st.integers(5, 60))
def test_resample_gives_even_spacing_on_the_same_curve(n, start, spacing_nodes):
    c = _circle(spacing_nodes, start=start)
    out = resample(c, n)
    assert out.shape == (n, 2)
    assert np.allclose(out[0], c[0])
    seg = segment_lengths(out)
    assert seg.max() - seg.min() <= 2 * perimeter(c) / spacing_nodes / n + 1e-9 + 0.05 * seg.mean()
    # every new node lies on the original polyline (here: inside the circle, near it)
    r = np.linalg.norm(out - [50.0, 60.0], axis=1)
    assert np.all(r <= 10.0 + 1e-9) and np.all(r >= 10.0 * np.cos(np.pi / spacing_nodes) - 1e-9)


def test_resample_by_spacing():
    out = resample(_circle(100), spacing=2.0)
    assert len(out) == round(perimeter(_circle(100)) / 2.0)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3, 40))
def test_polygon_mask_matches_skimage(seed, n):
    from skimage.draw import polygon2mask

    from napari_physeg.core.contour import polygon_mask

    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = rng.uniform(5, 20, n)
    poly = np.column_stack([25 + r * np.cos(t), 24 + r * np.sin(t)])
    assert np.array_equal(polygon_mask(poly, (50, 48)), polygon2mask((50, 48), poly))


def test_remove_loops_cuts_a_pinched_loop_and_a_twist():
    from napari_physeg.core.contour import _crossing_pairs, remove_loops

    # A square whose top edge makes a small figure-eight loop.
    t = np.linspace(0, 1, 60, endpoint=False)
    square = np.vstack([
        np.column_stack([np.zeros(15), np.linspace(0, 30, 15, endpoint=False)]),
        np.column_stack([np.linspace(0, 30, 15, endpoint=False), np.full(15, 30.0)]),
        np.column_stack([np.full(15, 30.0), np.linspace(30, 0, 15, endpoint=False)]),
        np.column_stack([np.linspace(30, 0, 15, endpoint=False), np.zeros(15)]),
    ])
    loop = np.column_stack([-3 + 3 * np.cos(2 * np.pi * t[:12] / 0.2), 15 + 3 * np.sin(2 * np.pi * t[:12] / 0.2)])
    twisted = np.vstack([square[:7], square[7] + [-1, 0], loop, square[8:]])
    assert len(_crossing_pairs(twisted)) > 0
    clean = remove_loops(twisted)
    assert len(_crossing_pairs(clean)) == 0
    assert len(clean) > 0.8 * len(square)
    # a simple contour is left alone
    circle = _circle(50)
    assert np.array_equal(remove_loops(circle), circle)


def test_positively_oriented_reverses_only_clockwise_contours():
    from napari_physeg.core.contour import positively_oriented

    t = np.linspace(0, 2 * np.pi, 20, endpoint=False)
    ccw = np.column_stack([np.sin(t), np.cos(t)])
    if signed_area(ccw) < 0:
        ccw = ccw[::-1]
    np.testing.assert_array_equal(positively_oriented(ccw), ccw)
    np.testing.assert_array_equal(positively_oriented(ccw[::-1]), ccw)
    assert positively_oriented(ccw[::-1].astype(np.float32)).dtype == np.float64


def test_nodes_for_spacing_is_the_perimeter_over_the_spacing():
    from napari_physeg.core.contour import nodes_for_spacing

    square = np.array([[0, 0], [0, 30.0], [30, 30], [30, 0]])
    assert nodes_for_spacing(square, 3.0) == 40
    assert nodes_for_spacing(square, 1000.0) == 3  # a closed contour needs 3
    with pytest.raises(ValueError, match="spacing"):
        nodes_for_spacing(square, 0.0)


def test_cut_pinches_keeps_the_piece_that_holds_the_given_points():
    """Two squares joined by a pinch (their corners 0.1 px apart): the larger
    piece is kept, unless points say where the object is."""
    from napari_physeg.core.contour import cut_pinches

    big = [(0, 0), (0, 20), (20, 20)]
    small = [(20.1, 20.1), (30, 20.1), (30, 30), (20.1, 30)]
    contour = resample(np.array(big + small + [(20, 0)], float), spacing=1.0)
    kept = cut_pinches(contour, gap=0.5)
    assert abs(signed_area(kept)) > 300
    kept = cut_pinches(contour, gap=0.5, keep=np.array([[25.0, 25.0], [26.0, 24.0]]))
    assert 50 < abs(signed_area(kept)) < 100



def test_bounding_window_holds_the_margin_and_stays_in_the_image():
    contour = np.array([[10.2, 20.7], [30.5, 20.0], [30.0, 45.9]])
    rows, cols = bounding_window(contour, (100, 60), 5.0)
    # Every pixel within 5 px of the bounding box, whole pixels, and no more.
    assert (rows.start, rows.stop) == (5, 37)
    assert (cols.start, cols.stop) == (15, 52)
    # Clipped to the image's sides.
    rows, cols = bounding_window(contour, (32, 48), 50.0)
    assert (rows.start, rows.stop, cols.start, cols.stop) == (0, 32, 0, 48)
    # Grown to cover a window it must keep.
    rows, cols = bounding_window(contour, (100, 60), 0.0, keep=(slice(2, 12), slice(40, 59)))
    assert (rows.start, rows.stop, cols.start, cols.stop) == (2, 32, 20, 59)


def test_densify_splits_long_edges_only_and_keeps_every_vertex_in_order():
    # A rectangle's 4 corners and one short edge: the long sides get nodes at most 3 px apart.
    box = np.array([[0.0, 0.0], [0.0, 40.0], [2.0, 40.0], [2.0, 0.0]])
    dense = densify(box, 3.0, 6.0)
    assert segment_lengths(dense).max() <= 3.0 + 1e-9
    np.testing.assert_allclose(perimeter(dense), perimeter(box))
    corners = [np.flatnonzero(np.all(dense == v, axis=1)) for v in box]
    assert all(len(i) == 1 for i in corners) and np.all(np.diff([i[0] for i in corners]) > 0)
    assert len(dense) == 2 * 14 + 2  # ceil(40 / 3) pieces on each long side, the short ones kept
    circle = _circle(64)
    assert densify(circle, 3.0, 6.0) is not None and np.array_equal(densify(circle, 3.0, 6.0), circle)


def test_a_drawing_gets_nodes_along_its_long_edges_and_a_node_set_is_kept():
    from napari_physeg import data
    from napari_physeg.core.segmentation import DEFAULT_NODE_SPACING, drawing_nodes

    box = np.array([[0.0, 0.0], [0.0, 60.0], [30.0, 60.0], [30.0, 0.0]])  # napari's rectangle: 4 corners
    nodes = drawing_nodes(box)
    assert len(nodes) == 60 and segment_lengths(nodes).max() <= DEFAULT_NODE_SPACING
    hand = data.hand_outline("open", n_nodes=67)  # evenly spaced, 14 px apart: the paper's nodes
    assert np.array_equal(drawing_nodes(hand), hand)
    # 30 clicks, one side a long straight run: that run gets nodes at the clicks' spacing
    clicks = np.vstack([_circle(30, r=20.0)[:29], [[-60.0, 60.0]]])
    spaced = drawing_nodes(clicks)
    assert len(spaced) > len(clicks) and segment_lengths(spaced).max() <= 2 * np.median(segment_lengths(clicks))

"""One contour validation for segment(), match() and simulate() (issue 12):
repeated nodes are refused alike everywhere (but the exact repeats a drawing
takes once), the tests are centred, and no numerical exception of scipy escapes."""

import re
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_physeg import data
from napari_physeg.core import match, segment, simulate
from napari_physeg.core._validation import check_contour
from napari_physeg.core.contour import as_contour, signed_area

HAND = data.hand_outline("open", n_nodes=67)
B66 = data.hand_pair(67, 66)[1]


def figure_eight(n=80, size=40.0):
    """A symmetric lemniscate: it crosses itself and encloses no net area."""
    t = 2 * np.pi * (np.arange(n) + 0.5) / n  # no node on the crossing (it would be there twice)
    return np.column_stack([size * np.sin(t) * np.cos(t), size * np.sin(t)]) + 100.0


def _everywhere(contour):
    """The error (type, message) each public call gives for this contour as its first argument."""
    obj = data.ellipse()
    calls = {
        "segment": lambda: segment(obj.image, contour, max_steps=1),
        "match": lambda: match(contour, B66),
        "simulate": lambda: simulate(contour, B66),
    }
    out = {}
    for name, call in calls.items():
        try:
            call()
            out[name] = None
        except ValueError as err:
            out[name] = str(err)
    return out


@pytest.mark.parametrize(
    "contour, pattern, a_drawing_takes_it",
    [
        (np.vstack([HAND[:5], HAND[4:]]), r"repeated consecutive nodes \(nodes 4 and 5 coincide", True),
        (np.vstack([HAND, HAND[:1]]), r"repeats its first node at the end", True),
        (np.vstack([HAND, HAND[30:31]]), r"1 identical node\(s\) \(nodes 30 and 67 coincide", False),
        (np.insert(HAND, 11, HAND[10] + 1e-9 * (HAND[11] - HAND[10]), axis=0), r"repeated consecutive nodes", False),
        (np.column_stack([np.arange(10.0), 2 * np.arange(10.0) + 1e12]), r"lie on one line", False),
    ],
)
def test_repeated_nodes_and_lines_are_refused_alike_everywhere(contour, pattern, a_drawing_takes_it):
    """Refused alike by the calls that number the nodes; a drawing (segment's)
    takes a node repeated exactly in a row, or the first at the end, once
    (session 75: a ring as find_contours writes it), and refuses the rest alike."""
    errors = _everywhere(contour)
    if a_drawing_takes_it:
        assert errors.pop("segment") is None
    assert all(message is not None for message in errors.values()), errors
    # The same message in every call, but for the argument's name.
    stripped = {message.replace("init", "a") for message in errors.values()}
    assert len(stripped) == 1, errors
    assert all(re.search(pattern, m) for m in errors.values()), errors


def test_no_node_is_dropped_silently():
    """The frames have as many nodes as the contour: none was dropped on the way."""
    a, b, _ = data.hand_pair(68, 66)
    sim = simulate(a, b, n_frames=3)
    assert sim.frames.shape == (3, 68, 2)
    assert match(a, b).affinity.shape == (68, 66)


def test_degeneracy_test_is_centred():
    a = data.hand_outline("open", n_nodes=67)
    for offset in (1e6, 1e10, -1e12):
        m = match(a, a + offset)
        assert np.mean(m.partner == np.arange(67)) >= 0.99
        assert np.array_equal(check_contour(a + offset, "a"), a + offset)
        assert as_contour(a + offset).shape == a.shape
    # The shoelace area is measured from a node: far from the origin it keeps its sign and value.
    assert np.isclose(signed_area(a + 1e10), signed_area(a), rtol=1e-6)


def test_a_figure_eight_is_no_line():
    eight = figure_eight()
    assert abs(signed_area(eight)) < 1e-6 * np.ptp(eight) ** 2  # no net area
    assert check_contour(eight).shape == (80, 2)
    assert as_contour(eight).shape == (80, 2)
    with pytest.warns(UserWarning, match="[ab] crosses itself .* 50% of what it encloses") as caught:
        m = match(eight, eight)
    assert len(caught) == 2 and {w.filename for w in caught} == {__file__}  # at the user's call
    assert m.pairs.shape == (80, 2)


@pytest.mark.parametrize("name, contour", [
    ("star", np.column_stack([np.sin(0.8 * np.pi * np.arange(5)), np.cos(0.8 * np.pi * np.arange(5))]) * 10),
    ("bow-tie", np.array([[0.0, 0.0], [10.0, 10.0], [0.0, 10.0], [10.0, 0.0]])),
])
def test_a_star_or_a_bow_tie_is_warned_of_in_match_and_simulate(name, contour):
    """A pentagram (its middle enclosed twice, which napari's even-odd fill
    leaves out) and a 4-click bow-tie were matched and simulated without a
    word (session 65's outside tester); a lasso that overshoots is not one."""
    b = data.hand_pair(5, 4)[1] if len(contour) == 4 else HAND
    with pytest.warns(UserWarning, match="a crosses itself"):
        m = match(contour, b)
    with pytest.warns(UserWarning, match="a crosses itself") as caught:
        simulate(contour, b, m, n_frames=2, max_steps=5)
    assert caught[0].filename == __file__
    lasso = np.vstack([HAND, HAND[:3] + [0.0, 1.5]])  # past its start, a small loop
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        match(lasso, B66)


def test_text_and_flags_are_refused_as_coordinates():
    """numpy reads "12" and True as numbers: a table read as text, or a
    mask passed for a contour, was matched (session 65)."""
    with pytest.raises(ValueError, match="a holds text, not coordinates"):
        match(np.array([["1", "2"], ["3", "4"], ["5", "7"]]), B66)
    with pytest.raises(ValueError, match="init holds True/False values"):
        segment(data.ellipse().image, np.array([[True, False], [False, True], [True, True]]))
    # A ragged list: numpy's own "inhomogeneous shape" escaped (the complex test read it first).
    with pytest.raises(ValueError, match=r"a must be an \(N, 2\) array of \(row, col\) nodes"):
        match([[0, 0], [1, 2, 3], [4, 5]], B66)


@pytest.mark.parametrize("scale", [1e-10, 1e8])
def test_a_contour_in_other_units_matches_as_in_pixels(scale):
    """Matching is scale-free: in metres (1e-10 across) the inner-distance
    context found no shortest path and an IndexError escaped (session 65)."""
    a, b, _ = data.hand_pair(67, 66)
    assert np.array_equal(match(a * scale, b * scale).pairs, match(a, b).pairs)


def test_far_off_contours_match_and_simulate_as_at_the_origin():
    a, b, truth = data.hand_pair(67, 66)
    ref = match(a, b)
    for offset in (1e10, 1e12):
        moved = match(a, b + offset)
        assert np.mean(moved.partner == ref.partner) >= 0.99
    sim = simulate(a, b, ref)
    far = simulate(a + 1e10, b + 1e10, ref)
    assert far.stop_reason == "converged"
    assert np.abs(far.frames - 1e10 - sim.frames).max() < 1e-3


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    node=st.integers(0, 66),
    log_gap=st.floats(-14, -1),
    offset=st.sampled_from([0.0, 1e6, 1e10]),
    scale=st.sampled_from([1e-3, 1.0, 1e3]),
)
def test_nearly_repeated_nodes_raise_a_clear_error_or_simulate(node, log_gap, offset, scale):
    """No LinAlgError or other numerical exception: a ValueError that names the
    nodes, or a result with a frame node for every node."""
    a = HAND * scale + offset
    nxt = a[(node + 1) % 67]
    a = np.insert(a, node + 1, a[node] + 10.0**log_gap * (nxt - a[node]), axis=0)
    b = B66 * scale + offset
    try:
        m = match(a, b)
    except ValueError as err:
        assert "coincide" in str(err)
        return
    if scale < 1:  # a thousandth of the hands' size: within 100 tol of a point (simulate's rest test is in px)
        with pytest.raises(ValueError, match="the contours span .* less than 100 times tol"):
            simulate(a, b, m, n_frames=3)
        return
    sim = simulate(a, b, m, n_frames=3)
    assert sim.frames.shape == (3, 68, 2) and np.all(np.isfinite(sim.frames))


def test_more_modes_than_the_models_have_are_said_to_be_cut():
    # Accepted silently: all 127 modes were used, the finest following the nodes' noise.
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    a = np.c_[50 + 20 * np.sin(t), 50 + 20 * np.cos(t)]
    b = np.c_[50 + 25 * np.sin(t), 50 + 15 * np.cos(t)]
    with pytest.warns(UserWarning, match="n_modes=500 is more than the 127 modes"):
        res = match(a, b, n_modes=500)
    assert res.n_modes == 127


def test_a_line_drawn_there_and_back_is_said_to_enclose_no_area():
    # Its nodes spaced along it (as the widgets space a drawing's) repeat on the way back: the message
    # was "a has 9 identical node(s) ... pass each node once".
    there = np.linspace([10.0, 10.0], [30.0, 30.0], 10)
    with pytest.raises(ValueError, match="a is degenerate: its nodes lie on one line"):
        match(np.vstack([there, there[-2:0:-1]]), HAND)


def test_a_sliver_and_complex_coordinates_are_refused_by_name():
    """Found by an outside probe (session 64): a triangle a millionth as high
    as long failed in the element ("sigma = 0.00226 is too large"); complex
    coordinates lost their imaginary part with numpy's warning only."""
    with pytest.raises(ValueError, match="b is degenerate: its nodes lie on one line.*millionth"):
        match(HAND, [[0, 0], [0, 10], [1e-6, 5]])
    with pytest.raises(ValueError, match="a has complex coordinates"):
        match(HAND + 0j, HAND)


def test_a_figure_eight_whose_nodes_meet_where_it_crosses_is_told_to_be_redrawn():
    # A bowtie drawn in napari, its nodes spaced along it: two of them fall on the crossing.
    corners = np.array([[0.0, 0.0], [50.0, 50.0], [0.0, 50.0], [50.0, 0.0]])
    nodes = np.vstack([np.linspace(p, q, 10, endpoint=False) for p, q in zip(corners, np.roll(corners, -1, 0))])
    with pytest.raises(ValueError, match="draw a contour that does not cross or touch itself"):
        match(nodes, HAND)


def test_matching_too_many_nodes_or_a_bad_material_is_refused_before_any_work():
    """An outside fuzzer (session 67): two 10,000-node ellipses took 55 s,
    model_nodes=10000 ran on past 20 s, and material=None raised a TypeError
    (in track(), only once every frame was segmented)."""
    from napari_physeg.core import track
    from napari_physeg.core.matching import MAX_MATCH_NODES, MAX_MODEL_NODES

    t = np.linspace(0, 2 * np.pi, MAX_MATCH_NODES + 1, endpoint=False)
    big = np.column_stack([500 + 300 * np.sin(t), 500 + 200 * np.cos(t)])
    with pytest.raises(ValueError, match=f"more than the {MAX_MATCH_NODES} match\\(\\) takes"):
        match(big, HAND)
    with pytest.raises(ValueError, match=f"model_nodes must be at most {MAX_MODEL_NODES}"):
        match(HAND, B66, model_nodes=MAX_MODEL_NODES + 1)
    with pytest.raises(ValueError, match="material must be a preset name"):
        match(HAND, B66, material=None)
    with pytest.raises(ValueError, match="^match_options: material must be"):
        track(np.zeros((2, 40, 40)), HAND * 5 + 20, match_options={"material": None})

"""match() does not depend on where either contour lies, how it is turned or
scaled, where its node numbering starts or which way it runs (issue 12):
at least 99 % of the partners stay the same under any one of these changes
of one contour."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from napari_physeg import data
from napari_physeg.core import match

POSES = ("open", "closed", "spread")
invariance = settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@st.composite
def hand_pairs(draw):
    """Articulated hand pairs, equal or unequal node counts, up to 250 nodes."""
    pose_a, pose_b = draw(st.permutations(POSES))[:2]
    n_a = draw(st.sampled_from([60, 67, 100, 200]))
    n_b = n_a + draw(st.sampled_from([-7, 0, 1, 50]))
    a, b, _ = data.hand_pair(n_a, n_b, pose_a=pose_a, pose_b=pose_b)
    return a, b


def transformed(c, kind, amount):
    """One change of a contour's placement or numbering; and the map from the
    new node numbers to the old."""
    n = len(c)
    centre = c.mean(axis=0)
    if kind == "shift":
        return c + amount * np.array([1.0, -0.7]), np.arange(n)
    if kind == "rotate":
        th = np.deg2rad(amount)
        R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
        return (c - centre) @ R.T + centre, np.arange(n)
    if kind == "scale":
        return (c - centre) * amount + centre, np.arange(n)
    if kind == "roll":
        k = int(amount) % n
        return np.roll(c, -k, axis=0), (np.arange(n) + k) % n
    if kind == "reverse":
        return c[::-1].copy(), np.arange(n)[::-1]
    raise AssertionError(kind)


changes = st.one_of(
    st.tuples(st.just("shift"), st.sampled_from([-250.0, 1e3, 1e10])),
    st.tuples(st.just("rotate"), st.floats(-180.0, 180.0)),
    st.tuples(st.just("scale"), st.sampled_from([0.01, 0.5, 2.0, 100.0])),
    st.tuples(st.just("roll"), st.integers(1, 500)),
    st.tuples(st.just("reverse"), st.just(0)),
)


def unchanged_fraction(a, b, which, kind, amount, method):
    ref = match(a, b, method=method).partner
    if which == "a":
        moved, old_of_new = transformed(a, kind, amount)
        got = match(moved, b, method=method).partner
        back = np.full(len(a), -1)
        back[old_of_new] = got  # partner of the old node numbered old_of_new[k]
        return float(np.mean(back == ref))
    moved, old_of_new = transformed(b, kind, amount)
    got = match(a, moved, method=method).partner
    back = np.where(got >= 0, old_of_new[np.maximum(got, 0)], -1)
    return float(np.mean(back == ref))


@invariance
@given(pair=hand_pairs(), which=st.sampled_from("ab"), change=changes)
@pytest.mark.parametrize("method", ["order", "global"])
def test_partners_do_not_depend_on_one_contours_placement_or_numbering(method, pair, which, change):
    a, b = pair
    assert unchanged_fraction(a, b, which, *change, method) >= 0.99


@pytest.mark.parametrize("method", ["order", "global"])
@pytest.mark.parametrize("kind, amount", [("scale", 2.0), ("scale", 0.5), ("reverse", 0), ("roll", 1),
                                          ("shift", 1e10)])
def test_the_reported_cases(method, kind, amount):
    """Issue 12's cases on 400 / 450-node hands: scale 2 changed 51 % of the
    partners, 0.5 changed 75 %, a reversed b 11.5 %, a shift by 1e10 99.8 %;
    ``global`` moved 7 partners by more than 5 nodes when b was rolled by one."""
    a, b, _ = data.hand_pair(400, 450, pose_a="open", pose_b="closed")
    assert unchanged_fraction(a, b, "b", kind, amount, method) >= 0.99

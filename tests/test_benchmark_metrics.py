"""The real-image benchmark's outline distance (``benchmarks/real.py``): known answers."""

import sys
from pathlib import Path

import numpy as np
import pytest
from skimage.draw import disk

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def real(monkeypatch_module):
    monkeypatch_module.syspath_prepend(str(BENCHMARKS))
    import real

    return real


@pytest.fixture(scope="module")
def monkeypatch_module():
    mp = pytest.MonkeyPatch()
    yield mp
    mp.undo()
    for name in ("real", "real_data", "segmentation", "_common", "noise", "scale", "membranes", "fields", "tracking",
                 "label_levels", "crowd_contacts"):
        sys.modules.pop(name, None)


def _disc(radius, centre=(40.0, 40.0), shape=(80, 80)):
    mask = np.zeros(shape, bool)
    mask[disk(centre, radius, shape=shape)] = True
    return mask


def test_a_mask_is_at_no_distance_from_itself(real):
    assert real.outline_distance(_disc(10), _disc(10)) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("inner, outer", [(10, 12), (8, 11), (15, 16)])
def test_concentric_discs_lie_their_radii_apart(real, inner, outer):
    d = real.outline_distance(_disc(inner), _disc(outer))
    assert d == pytest.approx(outer - inner, abs=0.2)
    assert d == pytest.approx(real.outline_distance(_disc(outer), _disc(inner)))  # symmetric


def test_a_shifted_disc_is_off_by_less_than_its_shift(real):
    # Shifted by 3 px: each outline point lies 3 |cos| px from the other outline, 2/pi * 3 on average.
    d = real.outline_distance(_disc(12), _disc(12, centre=(43.0, 40.0)))
    assert d == pytest.approx(3 * 2 / np.pi, abs=0.25)


def test_an_empty_mask_is_infinitely_far(real):
    assert real.outline_distance(np.zeros((80, 80), bool), _disc(10)) == np.inf


def _ramp_disc(radius=20.0, width=6.0, shape=(80, 80)):
    """A bright disc whose edge falls linearly from 1 at ``radius - width/2`` to 0 at ``radius + width/2``."""
    rows, cols = np.indices(shape)
    r = np.hypot(rows - 40.0, cols - 40.0)
    return np.clip((radius + width / 2 - r) / width, 0.0, 1.0)


def _circle(radius, n=90):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([40.0 + radius * np.sin(t), 40.0 + radius * np.cos(t)])


@pytest.mark.parametrize("radius, height", [(20.0, 0.5), (18.5, 0.75), (21.5, 0.25), (24.5, 0.0)])
def test_an_outline_lies_at_its_height_on_a_linear_ramp(real, radius, height):
    from scipy import ndimage as ndi

    # A 6 px ramp within the 5 px reach either side: its top and foot are in view (the 1 px
    # Gaussian rounds the foot: an outline a pixel and a half beyond it is at the bottom).
    assert real._ramp_height(ndi.gaussian_filter(_ramp_disc(), 1.0), _circle(radius)) == pytest.approx(height, abs=0.05)


@pytest.mark.parametrize("dark", [False, True])
def test_a_dark_object_s_outline_lies_at_its_height_up_from_its_background(real, dark):
    from types import SimpleNamespace

    # Truth half-way up the ramp, ours a quarter up (1.5 px out): for a bright disc and a dark one
    # alike, as the ramp rises from the background's side to the object's.
    image = _ramp_disc()
    obj = SimpleNamespace(image=1.0 - image if dark else image, mask=image >= 0.5)
    line = real.ramp_positions([dict(group="g", obj=obj, contour=_circle(21.5))], ["g"])[0]
    ours, truth = (float(v) for v in line.rsplit("g ", 1)[1].split(" / "))
    assert (ours, truth) == (pytest.approx(0.25, abs=0.05), pytest.approx(0.5, abs=0.05))


def test_drawings_that_end_on_one_region_agree_and_one_that_strays_does_not(real):
    from types import SimpleNamespace

    from skimage.measure import find_contours

    def row(obj, radius, centre=(40.0, 40.0)):
        contour = find_contours(_disc(radius, centre).astype(float), 0.5)[0]
        return dict(group="g", obj=obj, contour=contour, mcv_mask=None, box=None)

    same = SimpleNamespace(name="a", image=np.zeros((80, 80)))
    strays = SimpleNamespace(name="b", image=np.zeros((80, 80)))
    rows = [row(same, 10), row(same, 10), row(strays, 10), row(strays, 10, (40.0, 50.0))]
    lines = real.drawing_agreement(rows, ["g"])
    # Object a: 1.0; object b: two discs of radius 10, 10 px apart, IoU about 0.23.
    mean = float(lines[1].split(": ")[1].split(" ")[0])
    assert mean == pytest.approx((1.0 + 0.23) / 2, abs=0.03)
    assert "(50%)" in lines[1]


def test_a_degenerate_outline_has_no_height(real):
    assert np.isnan(real._ramp_height(_ramp_disc(), _circle(20.0, n=4)))


def test_u2os_truth_outlines_each_nucleus_at_its_own_edge(real):
    """The u2os group's classical truth (``real_data.u2os_truth``): known answers
    on a synthetic field. Two nuclei of very different brightness and two
    touching ones, blurred: four labels, each at its own edge's middle."""
    real_data = sys.modules["real_data"]
    from scipy import ndimage as ndi

    image = np.full((120, 160), 20.0)
    truths = [_disc(12, (30, 30), image.shape), _disc(12, (30, 100), image.shape),
              _disc(11, (85, 60), image.shape), _disc(11, (85, 81), image.shape)]
    for mask, level in zip(truths, (40.0, 250.0, 60.0, 60.0)):
        image[mask] = level
    image = ndi.gaussian_filter(image, 1.5) + np.random.default_rng(0).normal(0, 0.5, image.shape)
    labels = real_data.u2os_truth(image)
    assert labels.max() == 4
    for mask in truths:
        found = labels == np.bincount(labels[mask]).argmax()
        assert (found & mask).sum() / (found | mask).sum() > 0.85


def test_a_drawing_inside_an_object_cut_by_the_side_stays_in_the_image(real):
    """``real_data.init_inside`` on a flat object cut by the image's top side (6 x 41
    px): its deepest point was read on the top row, the image's side not counting as
    its outline, and the circle there poked out of the image (polygon2mask clipped
    it, and it passed as inside: the benchmark's ihc n1 started from a 5-px sliver);
    now the circle lies inside the object, in the image."""
    real_data = sys.modules["real_data"]
    mask = np.zeros((40, 80), bool)
    mask[:6, 20:61] = True
    obj = real_data.Obj("test", "cut", mask.astype(float), mask)
    init, _ = real_data.init_inside(obj, np.random.default_rng(0))
    assert init.min() >= -0.5 and np.all(init.max(axis=0) <= np.array(mask.shape) - 0.5)
    assert real_data.inside(init, mask)


def test_the_circles_on_the_ground_keep_clear_of_every_object(real, monkeypatch_module):
    """``benchmarks/drawings.py``'s circles on the ground: inside the image, at least 1.5 radii
    and 3 px from every labelled pixel, three of each radius on each image."""
    real_data = sys.modules["real_data"]
    from drawings import GROUND_RADII, ground_circles

    mask = np.zeros((160, 200), bool)
    mask[disk((50, 60), 20)] = mask[disk((110, 140), 25)] = True
    real_data.GROUPS["test"] = lambda: [real_data.Obj("test", "a/n1", mask.astype(float), mask)]
    try:
        circles = list(ground_circles(["test"]))
    finally:
        del real_data.GROUPS["test"]
    assert len(circles) == 3 * len(GROUND_RADII) and {c[0] for c in circles} == {"test/a"}
    labelled = np.argwhere(mask)
    for _, image, circle in circles:
        centre, radius = circle.mean(axis=0), np.ptp(circle[:, 0]) / 2
        assert np.all((circle >= 0) & (circle <= np.array(image.shape) - 1))
        assert np.hypot(*(labelled - centre).T).min() > 1.5 * radius + 3 - 1e-9


def test_the_noise_probe_adds_the_noise_it_names(real, monkeypatch_module):
    """``benchmarks/noise.py``: photon counts with the named brightest mean, and white noise of
    the object's contrast over the named SNR."""
    import real_data
    from noise import noisy

    mask = np.zeros((120, 120), bool)
    mask[disk((60, 60), 15)] = True
    obj = real_data.Obj("test", "n1", np.where(mask, 0.8, 0.1), mask)
    rng = np.random.default_rng(0)
    photons = noisy(obj, "poisson50", rng).image
    assert abs(photons[mask].mean() - (0.8 * 50 + 2)) < 1.0 and abs(photons[~mask].mean() - (0.1 * 50 + 2)) < 0.2
    snr = noisy(obj, "snr4", rng).image - obj.image
    assert abs(snr.std() - 0.7 / 4) < 0.01
    assert noisy(obj, "clean", rng) is obj
    hot = noisy(obj, "hot3", rng, init=np.array([[50.0, 50.0], [70.0, 70.0]])).image
    changed = np.argwhere(hot != obj.image)
    assert 1 <= len(changed) <= 3 and np.all(hot[tuple(changed.T)] == 40.0)
    assert np.all(np.abs(changed - 60) <= 15)
    with pytest.raises(ValueError, match="pass the drawing as init"):
        noisy(obj, "hot3", rng)
    for wrong in ("gauss", "poisson", "snr0", "poisson-3", "hot0", "hot"):
        with pytest.raises(ValueError, match=f"unknown noise '{wrong}'.*poisson30 snr2"):
            noisy(obj, wrong, rng)


def test_the_scale_probe_dims_and_vignettes_as_it_says(real, monkeypatch_module):
    """``benchmarks/scale.py``: ``dimmed`` cuts the object's contrast over its surroundings to 60 %
    and leaves the rest; ``vignetted`` adds a background of 0.3 of the range and dims the corners
    to 40 %."""
    import real_data
    from scale import dimmed, vignetted

    mask = np.zeros((101, 101), bool)
    mask[disk((50, 50), 12)] = True
    image = np.where(mask, 1.0, 0.2)
    image[disk((15, 15), 6)] = 1.0  # a neighbour, far away
    obj = real_data.Obj("test", "n1", image, mask)
    dim = dimmed(obj).image
    assert np.isclose(np.median(dim[mask]), 0.2 + 0.6 * 0.8, atol=0.01) and np.isclose(dim[15, 15], 1.0)
    assert np.isclose(dim[50, 90], 0.2)
    vig = vignetted(obj).image
    assert np.isclose(vig[50, 50], 1.0 + 0.3 * 0.8, atol=0.01)
    assert np.isclose(vig[0, 0] / (0.2 + 0.3 * 0.8), 1 - 1.2 * 2 * 0.5 ** 2, atol=0.02)


def test_the_scale_probe_turns_and_mirrors_the_drawing_with_the_image(real, monkeypatch_module):
    """``benchmarks/scale.py --turn``: the drawing goes with the image (the same pixels of the
    object under it), still counterclockwise in (row, col) as drawn, and a case that moved is
    counted against the same case as it comes."""
    import real_data
    from scale import moved, mirrored, turned
    from skimage.draw import polygon2mask

    from napari_physeg.core.contour import signed_area

    mask = np.zeros((60, 90), bool)
    mask[10:30, 20:70] = True
    image = np.where(mask, 1.0, 0.0) + np.linspace(0, 0.1, 90)[None, :]
    obj = real_data.Obj("test", "n1", image, mask)
    init = np.array([[8.0, 18.0], [32.0, 18.0], [32.0, 45.0], [8.0, 45.0]])  # around the left half
    for change in (turned, mirrored):
        obj2, init2 = change(obj, init)
        assert obj2.image.shape == (90, 60) if change is turned else obj2.image.shape == (60, 90)
        drawn, drawn2 = polygon2mask(mask.shape, init), polygon2mask(obj2.mask.shape, init2)
        assert drawn2.sum() == drawn.sum() and (obj2.mask & drawn2).sum() == (mask & drawn).sum()
        assert np.isclose(np.sort(obj2.image[drawn2]), np.sort(image[drawn])).all()
        assert np.sign(signed_area(init2)) == np.sign(signed_area(init))
    rows = [("g", 1.0, 0.9, False, 10, "a"), ("g", "turned", 0.5, False, 10, "a"),
            ("g", 1.0, 0.5, False, 10, "b"), ("g", "turned", 0.55, False, 10, "b")]
    assert moved(rows, [1.0, "turned"]).endswith("turned 1")


def test_the_membrane_probe_draws_the_cells_it_scores(real, monkeypatch_module):
    """``benchmarks/membranes.py``: the scored cell is the left one, out to its ring's outer edge,
    and its inside is as dark as the ground when asked (and a quarter of the ring otherwise)."""
    from membranes import membrane_cells

    for inside in (0.0, 0.25):
        image, centre, cell, lumen = membrane_cells(16, 3, inside, seed=0)
        ring = cell & ~lumen
        assert lumen.sum() < cell.sum() and not (lumen & ~cell).any()
        assert np.hypot(*(np.argwhere(cell).mean(axis=0) - centre)) < 0.5
        assert np.median(image[ring]) > 0.6
        core = np.hypot(*(np.indices(image.shape) - centre[:, None, None])) < 8
        assert abs(np.median(image[core]) - inside) < 0.03
        assert abs(np.median(image[:, :20]) - 0.0) < 0.03


def test_the_field_probe_draws_sparse_and_crowded_spots(real, monkeypatch_module):
    """``benchmarks/fields.py``: the spots it scores are where it says, of the radius it says, at
    least 6 px apart, and a sparse field's cover a quarter to a half of a percent of it."""
    from fields import spots

    for count in (4, 60):
        image, centres = spots(5.0, count, seed=1)
        assert len(centres) == 4 and image.shape == (256, 256)
        for c in centres:
            r, col = np.round(c).astype(int)
            assert image[r, col] > 0.5 and image[r, col + 9] < 0.25
    sparse, _ = spots(3.5, 4, seed=0)
    assert 0.0025 < np.mean(sparse > 0.4) < 0.006


def test_the_field_probe_draws_rods_apart_and_drawings_about_them(real, monkeypatch_module):
    """``benchmarks/fields.py``'s rods: a capsule has the area of a rectangle and a disk, the
    rods it scores lie at least 2 px apart and show in the image, and the drawings are about
    each rod: the circle holds it, the click lies in it."""
    from fields import capsule, rod_drawings, rods
    from scipy import ndimage as ndi
    from skimage.draw import polygon2mask

    rod = capsule((80, 80), (40, 40), 0.7, 30, 8)
    assert abs(rod.sum() - (8 * 22 + np.pi * 16)) < 0.05 * rod.sum()
    image, masks = rods(6, 25, seed=0)
    assert len(masks) == 4
    for i, a in enumerate(masks):
        assert np.median(image[a]) > 0.5
        for b in masks[i + 1:]:
            assert not (ndi.binary_dilation(a, iterations=2) & b).any()
        drawings = rod_drawings(a)
        assert not (a & ~polygon2mask(a.shape, drawings["circle 1.2 half-diagonal"][0])).any()
        assert a[polygon2mask(a.shape, drawings["click 0.4 half-width"][0])].all()


def test_the_field_probe_outlines_the_phantom_s_regions_a_contour_can_hold(real, monkeypatch_module):
    """``benchmarks/fields.py``'s phantom: ten regions of one level, none with a hole (not the
    skull's ring), apart; the noise is the one stated; the click lies in its region and the box
    holds it."""
    from fields import phantom, phantom_drawings
    from scipy import ndimage as ndi
    from skimage import data as skdata
    from skimage.draw import polygon2mask

    image, regions = phantom(seed=0)
    assert len(regions) == 10
    assert abs(np.std(image - skdata.shepp_logan_phantom()) - 0.02) < 0.001
    cover = np.zeros(image.shape, int)
    for _, region in regions:
        assert (ndi.binary_fill_holes(region) == region).all()
        cover += region
        drawings = phantom_drawings(region)
        assert region[polygon2mask(region.shape, drawings["click 0.4 depth"][0])].all()
        assert not (region & ~polygon2mask(region.shape, drawings["box 3 px out"][0])).any()
    assert cover.max() == 1


def test_the_field_probe_bends_crescents_over_their_span(real, monkeypatch_module):
    """``benchmarks/fields.py``'s crescents: a tube over ``span`` degrees of a circle has the area
    of its arc and two half-disk ends, shows in the image, and its click lies on it."""
    from fields import crescent, crescent_drawings
    from skimage.draw import polygon2mask

    for span in (120, 270):
        image, mask, middle = crescent(6, span, seed=0)
        arc = np.deg2rad(span) * 25 * 6 + np.pi * 9
        assert abs(mask.sum() - arc) < 0.05 * arc
        assert np.median(image[mask]) > 0.7 and np.median(image[~mask]) < 0.15
        click = crescent_drawings(mask, middle, 6)["click 0.4 half-width"][0]
        assert mask[polygon2mask(mask.shape, click)].all()


def test_the_field_probe_packs_a_colony_with_the_gap_it_says(real, monkeypatch_module):
    """``benchmarks/fields.py``'s colonies: five rods, none overlapping, each the next one's
    neighbour across a gap of about ``gap`` px (at least 1 px of background between them)."""
    from fields import colony
    from scipy import ndimage as ndi

    for gap in (1, 2):
        image, masks = colony(gap, 6, seed=0)
        assert len(masks) == 5 and not (np.sum(masks, axis=0) > 1).any()
        for a, b in zip(masks, masks[1:]):
            distance = ndi.distance_transform_edt(~a)[b].min()
            assert gap <= distance <= gap + 1.5, distance
        assert np.median(image[masks[2]]) > 0.6


def test_the_scale_probe_leaves_an_object_alone_as_it_says(real, monkeypatch_module):
    """``benchmarks/scale.py --alone``: the object's own pixels are kept, its labelled neighbours
    become its ground (their median within the noise of the background's), and the background
    far from them is left as it was."""
    import real_data
    from scale import alone

    rng = np.random.default_rng(0)
    image = 0.1 + 0.02 * rng.standard_normal((120, 120))
    own, other = np.zeros((120, 120), bool), np.zeros((120, 120), bool)
    own[disk((40, 40), 10)] = True
    other[disk((80, 80), 12)] = True
    image[own], image[other] = 0.8, 0.9
    obj = real_data.Obj("test", "n1", image, own)
    out = alone(obj, other).image
    assert np.array_equal(out[own], image[own])
    assert abs(np.median(out[other]) - 0.1) < 0.01 and abs(out[other].std() - 0.02) < 0.01
    assert np.array_equal(out[:20, 100:], image[:20, 100:])


def test_the_tracking_drift_is_nought_through_the_material_points_and_counts_a_slip(real, monkeypatch_module):
    """``benchmarks/tracking.py``: points followed through correspondences that are the material
    points' own end on them; correspondences that slip one node a frame carry each point one node
    spacing further a frame."""
    import tracking as bench

    from napari_physeg import data

    movie = data.deforming_cell(n_frames=6, shape=(96, 96), n_points=240)
    outlines = list(movie.outlines[:, ::4])
    exact = [None] + outlines[:-1]
    assert bench._drift(movie, outlines, exact).max() < 1e-9
    # Each node's origin is the material point one node back: a point is carried one node on a frame.
    slipped = [None] + [np.roll(o, 1, axis=0) for o in outlines[:-1]]
    first, last = outlines[0], outlines[-1]
    spacing = np.mean(np.hypot(*(np.roll(first, -1, axis=0) - first).T))
    followed = np.arange(0, len(first), 3)
    five_on = np.hypot(*(last[(followed + 5) % len(last)] - last[followed]).T) / spacing
    np.testing.assert_allclose(bench._drift(movie, outlines, slipped), five_on, rtol=1e-9)
    assert 3.5 < five_on.min() and five_on.max() < 6.5


@pytest.fixture(scope="module")
def label_levels(monkeypatch_module):
    monkeypatch_module.syspath_prepend(str(BENCHMARKS))
    import label_levels

    return label_levels


def test_a_border_on_a_blurred_disk_lies_half_way_up_its_ramp_and_lower_outside(label_levels):
    import cv2

    truth = np.zeros((120, 120), bool)
    truth[disk((60, 60), 25)] = True
    image = cv2.GaussianBlur(0.1 + 0.8 * truth, (0, 0), 2.5)
    obj_level, background = label_levels.levels(image, truth)
    assert obj_level == pytest.approx(0.9, abs=0.01) and background == pytest.approx(0.1, abs=0.01)
    at_half = label_levels.border_level(image, truth, obj_level, background)
    assert at_half == pytest.approx(0.5, abs=0.05)
    wider, narrower = np.zeros_like(truth), np.zeros_like(truth)
    wider[disk((60, 60), 27)] = True
    narrower[disk((60, 60), 23)] = True
    assert label_levels.border_level(image, wider, obj_level, background) < at_half - 0.15
    assert label_levels.border_level(image, narrower, obj_level, background) > at_half + 0.15


@pytest.fixture(scope="module")
def crowd_contacts(monkeypatch_module):
    monkeypatch_module.syspath_prepend(str(BENCHMARKS))
    import crowd_contacts

    return crowd_contacts


@pytest.mark.parametrize("case, dip, step", [("alike", 0.0, 0.0), ("dark line", 4.0, 0.0), ("brighter", 0.0, 6.0),
                                             ("overlapping", -3.0, 0.0)])
def test_a_contact_shows_its_dip_and_step_in_noise_sigmas(crowd_contacts, case, dip, step):
    """Two nuclei side by side, their labels meeting along a column: the
    contact's dip and the nuclei's step, in units of the noise, as made (a
    step's contact straddles both levels: half the step above the dimmer)."""
    a, b = np.zeros((20, 30), bool), np.zeros((20, 30), bool)
    a[5:15, 5:15], b[5:15, 15:25] = True, True
    image = np.where(a, 1.0, 0.0) + np.where(b, 1.0 + 0.1 * step, 0.0)
    contact = np.zeros_like(a)
    contact[5:15, 14:16] = True
    image[contact] -= 0.1 * dip
    found = crowd_contacts.contact_contrasts(image, a, b, noise=0.1)
    np.testing.assert_allclose(found, (dip - 0.5 * step, step), atol=1e-9)
    assert crowd_contacts.contact_contrasts(image, a, np.roll(b, 3, axis=1), noise=0.1) is None


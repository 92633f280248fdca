"""Field probe: ``segment()`` and the scikit-image anchors on fields unlike the real images'.

The real images of ``real.py`` are crowded, their objects 8 to 90 px across. Two kinds of field
they never show, with a known answer:

* **Sparse and crowded spots**: blurred disks of radius 3.5, 5 and 7 px (levels 0.6-1.0 over
  0.1, blur sigma 1 px, white noise 0.03) on a 256 px field, 4 of them (a quarter to a half of a
  percent of the field) or 60; three seeds, the first four spots of each. Drawn with a circle
  1.3 r around and a click 0.4 r inside. A field's density should not move the contours.
* **Rods** (rod-shaped bacteria): capsules 6 and 10 px wide and 3-6 times as long, at random
  angles, at least 2 px apart (levels 0.6-1.0 over 0.1, blur sigma 1 px, white noise 0.03) on
  a 256 px field, 6 or 25 of them; three seeds, the first four rods of each. Drawn with a circle
  1.2 times half their extent's diagonal (about their length), a box 1.25 times their extent
  and 2 px, and a click of 0.4 their half-width at their deepest point.
* **Crescents** (curved rods): tubes 6 and 10 px wide along a circle of radius 25 px, over
  120, 200 or 270 degrees, with round ends (noise and blur as for the rods), one a field, two
  seeds (the start angle). Drawn with a circle 1.15 times half their extent's diagonal, a box
  1.2 times their extent and 2 px, a click of 0.4 their half-width half-way along, and a lasso
  traced 3 px outside them.
* **Rod colonies** (a known failure, kept to measure it): five rods side by side, 1 or 2 px
  apart, 6 or 8 px wide and 4-5 times as long (levels 0.7-1.0; blur, noise as above), two
  seeds, the second and third rods scored. Drawn as the rods are, and with a lasso traced
  half the gap outside the rod.
* **Nested levels**: skimage.data's Shepp-Logan phantom with white noise 0.02 (two seeds), its
  regions of one level that a closed contour can outline (at least 50 px, no holes): ellipses
  on a grey ground within a bright ring, beside black ellipses that differ from them more than
  their ground does. Drawn with a circle 1.3 times half their extent, a box 3 px out, and a
  click of 0.4 their depth at their deepest point.
* **Large disks**: a disk of radius 150-300 px on a 1024 px field (7-27 % of it) and one of
  200 px on a 512 px field (48 %), noise 0.05; drawn with circles inside it (0.3, 0.4 and
  0.6 R, centred) and around it (1.2 R).

Ours on the whole image; MGAC and morphological Chan-Vese with ``real.py``'s settings on the same
crops, in one run; IoU and wall-clock time (mean per case, BLAS on one thread):

    python benchmarks/fields.py                        # all six fields, about 12 min
    python benchmarks/fields.py --fields rods crescents
    python benchmarks/fields.py --fields phantom --phantom-blur 1.5   # the phantom blurred
"""

from __future__ import annotations

import argparse
import os
import warnings
from collections import Counter

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402

import real  # noqa: E402
import real_data  # noqa: E402

METHODS = ("ours", "MGAC", "MCV")
LARGE = ((1024, 150), (1024, 200), (1024, 300), (512, 200))  # (field, radius)
FIELDS = {"spots": "spots", "rods": "rods", "crescents": "crescent", "colonies": "colony", "disks": "disk",
          "phantom": "phantom level (area)"}  # the fields and their table's first column


def spots(radius: float, count: int, seed: int, size: int = 256):
    """A field of ``count`` blurred spots of ``radius`` px, at least 6 px apart; the image and
    the first four spots' centres."""
    rng = np.random.default_rng(seed)
    centres = []
    while len(centres) < count:
        c = rng.uniform(2 * radius + 4, size - 2 * radius - 4, 2)
        if all(np.hypot(*(c - d)) > 2 * radius + 6 for d in centres):
            centres.append(c)
    rows, cols = np.mgrid[:size, :size]
    image = np.zeros((size, size))
    for c, level in zip(centres, rng.uniform(0.6, 1.0, count)):
        image[np.hypot(rows - c[0], cols - c[1]) <= radius] = level
    return ndi.gaussian_filter(image, 1.0) + 0.1 + rng.normal(0, 0.03, image.shape), centres[:4]


def capsule(shape, centre, angle, length: float, width: float) -> np.ndarray:
    """The mask of a capsule (a rod) of ``length`` and ``width`` px about ``centre``."""
    rows, cols = np.mgrid[:shape[0], :shape[1]].astype(float)
    axis = np.array([np.sin(angle), np.cos(angle)])
    start = np.asarray(centre, float) - axis * (length - width) / 2
    t = np.clip((rows - start[0]) * axis[0] + (cols - start[1]) * axis[1], 0, length - width)
    return np.hypot(rows - start[0] - t * axis[0], cols - start[1] - t * axis[1]) <= width / 2


def rods(width: float, count: int, seed: int, size: int = 256):
    """A field of up to ``count`` rods ``width`` px wide, at least 2 px apart; the image and the
    first four rods' masks."""
    rng = np.random.default_rng(seed)
    masks, taken = [], np.zeros((size, size), bool)
    for _ in range(2000):
        if len(masks) == count:
            break
        mask = capsule(taken.shape, rng.uniform(30, size - 30, 2), rng.uniform(0, np.pi),
                       rng.uniform(3, 6) * width, width)
        if not (ndi.binary_dilation(mask, iterations=2) & taken).any():
            masks.append(mask)
            taken |= mask
    image = np.zeros((size, size))
    for mask, level in zip(masks, rng.uniform(0.6, 1.0, len(masks))):
        image[mask] = level
    return ndi.gaussian_filter(image, 1.0) + 0.1 + rng.normal(0, 0.03, image.shape), masks[:4]


def rod_drawings(mask):
    """{drawing: (contour, kind)}: a circle about the rod's length, a box around it, a click."""
    rows, cols = np.nonzero(mask)
    centre, extent = np.array([rows.mean(), cols.mean()]), np.array([np.ptp(rows), np.ptp(cols)], float)
    depth = ndi.distance_transform_edt(mask)
    deepest = np.array(np.unravel_index(np.argmax(depth), mask.shape), float)
    return {"circle 1.2 half-diagonal": (real_data.circle(centre, 0.6 * np.hypot(*extent)), "circle"),
            "box 1.25 + 2 px": (real_data.rectangle(centre, 0.625 * extent + 2), "box"),
            "click 0.4 half-width": (real_data.circle(deepest, 0.4 * depth.max(), 12), "inside")}


def crescent(width: float, span: float, seed: int, size: int = 160, radius: float = 25.0):
    """A tube ``width`` px wide along a circle of ``radius`` about the field's centre, over
    ``span`` degrees from an angle the seed draws, with round ends; the image and its mask."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[:size, :size].astype(float)
    centre, start = np.array([size / 2, size / 2]), rng.uniform(0, 2 * np.pi)
    angle = np.mod(np.arctan2(rows - centre[0], cols - centre[1]) - start, 2 * np.pi)
    mask = (np.abs(np.hypot(rows - centre[0], cols - centre[1]) - radius) <= width / 2) & \
        (angle <= np.deg2rad(span))
    for end in (start, start + np.deg2rad(span)):
        tip = centre + radius * np.array([np.sin(end), np.cos(end)])
        mask |= np.hypot(rows - tip[0], cols - tip[1]) <= width / 2
    image = ndi.gaussian_filter(0.8 * mask, 1.0) + 0.1 + rng.normal(0, 0.03, mask.shape)
    middle = start + np.deg2rad(span) / 2
    return image, mask, centre + radius * np.array([np.sin(middle), np.cos(middle)])


def crescent_drawings(mask, middle, width):
    """{drawing: (contour, kind)}: a circle and a box about the crescent, a click half-way
    along it, a lasso 3 px outside it."""
    rows, cols = np.nonzero(mask)
    centre, extent = np.array([rows.mean(), cols.mean()]), np.array([np.ptp(rows), np.ptp(cols)], float)
    return {"circle 1.15 half-diagonal": (real_data.circle(centre, 0.575 * np.hypot(*extent)), "circle"),
            "box 1.2 + 2 px": (real_data.rectangle(centre, 0.6 * extent + 2), "box"),
            "click 0.4 half-width": (real_data.circle(middle, 0.2 * width, 12), "inside"),
            "lasso 3 px out": (real_data.boundary(mask, 3.0), "freehand")}


def colony(gap: float, width: float, seed: int, size: int = 160):
    """Five rods ``width`` px wide side by side, ``gap`` px apart, at an angle the seed draws;
    the image and the rods' masks."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0, np.pi)
    along, across = np.array([np.sin(angle), np.cos(angle)]), np.array([np.cos(angle), -np.sin(angle)])
    masks = [capsule((size, size), size / 2 + i * (width + gap) * across + rng.uniform(-4, 4) * along, angle,
                     rng.uniform(4, 5) * width, width) for i in range(-2, 3)]
    image = np.zeros((size, size))
    for mask, level in zip(masks, rng.uniform(0.7, 1.0, len(masks))):
        image[mask] = level
    return ndi.gaussian_filter(image, 1.0) + 0.1 + rng.normal(0, 0.03, image.shape), masks


def scored(image, truth, init, kind):
    """{method: (IoU, seconds)} and our stop reason (BLAS on one thread)."""
    obj = real_data.Obj("fields", "object", image, truth)
    ours, _ = real.run_ours(obj, init)
    anchors, _, _ = real.run_anchors(obj, init, kind)
    return {"ours": (ours["iou"], ours["time"]), **{m: (anchors[m]["iou"], anchors[m]["time"]) for m in METHODS[1:]}}, \
        ours["stop"]


def spot_rows(seeds: int):
    rows = []
    for radius in (3.5, 5.0, 7.0):
        for count in (4, 60):
            for seed in range(seeds):
                image, centres = spots(radius, count, seed)
                grid = np.mgrid[:image.shape[0], :image.shape[1]]
                for c in centres:
                    truth = np.hypot(grid[0] - c[0], grid[1] - c[1]) <= radius
                    for drawing, factor, n, kind in (("circle 1.3 r", 1.3, 24, "circle"),
                                                     ("click 0.4 r", 0.4, 12, "inside")):
                        ious, stop = scored(image, truth, real_data.circle(c, factor * radius, n), kind)
                        rows.append((f"r {radius:g}, {'sparse (4)' if count == 4 else 'crowded (60)'}", drawing,
                                     ious, stop))
    return rows


def drawn_rows(case: str, image, truth, drawings: dict) -> list:
    """One row per drawing ({name: (contour, kind)}) of ``truth`` on ``image``: case, drawing,
    {method: (IoU, seconds)}, ours' stop reason."""
    return [(case, name, *scored(image, truth, init, kind)) for name, (init, kind) in drawings.items()]


def rod_rows(seeds: int):
    rows = []
    for width in (6, 10):
        for count in (6, 25):
            for seed in range(seeds):
                image, masks = rods(width, count, seed)
                for truth in masks:
                    rows += drawn_rows(f"w {width} px, {count} rods", image, truth, rod_drawings(truth))
    return rows


def crescent_rows(seeds: int):
    rows = []
    for width in (6, 10):
        for span in (120, 200, 270):
            for seed in range(seeds):
                image, truth, middle = crescent(width, span, seed)
                rows += drawn_rows(f"w {width} px, {span} deg", image, truth,
                                   crescent_drawings(truth, middle, width))
    return rows


def colony_rows(seeds: int):
    rows = []
    for gap in (1, 2):
        for width in (6, 8):
            for seed in range(seeds):
                image, masks = colony(gap, width, seed)
                for truth in masks[1:3]:
                    rows += drawn_rows(f"gap {gap} px, w {width} px", image, truth, colony_drawings(truth, gap))
    return rows


def colony_drawings(truth, gap: float) -> dict:
    """A rod's drawings (see rod_drawings) and a lasso traced half the colony's gap outside it."""
    return {**rod_drawings(truth), "lasso half the gap out": (real_data.boundary(truth, gap / 2), "freehand")}


def colony_figure(path) -> None:
    """Ours on the second rod of a colony 1 px apart, 6 px wide, from each drawing: truth green,
    drawing cyan, result red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from skimage.draw import polygon2mask

    from napari_physeg.core import segment

    image, masks = colony(1, 6, 0)
    truth = masks[1]
    drawings = colony_drawings(truth, 1)
    centre = np.argwhere(truth).mean(axis=0)
    fig, axes = plt.subplots(1, len(drawings), figsize=(4 * len(drawings), 4.3))
    for ax, (name, (init, _)) in zip(axes, drawings.items()):
        contour = segment(image, init).contour
        found = polygon2mask(image.shape, contour)
        ax.imshow(image, cmap="gray")
        ax.contour(truth, [0.5], colors="lime", linewidths=1)
        for line, colour in ((init, "cyan"), (contour, "red")):
            closed = np.vstack([line, line[:1]])
            ax.plot(closed[:, 1], closed[:, 0], colour, lw=1)
        ax.set_xlim(centre[1] - 35, centre[1] + 35)
        ax.set_ylim(centre[0] + 35, centre[0] - 35)
        ax.set_title(f"{name}: IoU {(found & truth).sum() / (found | truth).sum():.2f}", fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=80)


def phantom(seed: int, blur: float = 0.0):
    """skimage.data's Shepp-Logan phantom (400 x 400), blurred by a Gaussian of ``blur`` px,
    with white noise 0.02, and its regions of one level (0.1 steps) that a closed contour can
    outline: at least 50 px, no holes (the skull's ring and the grey matter around the inner
    ellipses are left out)."""
    from skimage import data as skdata

    levels = skdata.shepp_logan_phantom()
    image = (ndi.gaussian_filter(levels, blur) if blur > 0 else levels) + \
        np.random.default_rng(seed).normal(0, 0.02, levels.shape)
    regions = []
    for level in np.unique(np.round(levels, 2)):
        labels, n = ndi.label(np.isclose(levels, level, atol=0.005))
        for k in range(1, n + 1):
            region = labels == k
            if 50 <= region.sum() < 0.5 * region.size and not (ndi.binary_fill_holes(region) & ~region).any():
                regions.append((f"{level:.1f} ({region.sum()} px)", region))
    return image, regions


def phantom_drawings(truth) -> dict:
    """{drawing: (contour, kind)}: a circle 1.3 times half the region's extent, a box 3 px
    out, and a click of 0.4 its depth at its deepest point."""
    centre, half = real_data.bounding_box(truth)
    depth = ndi.distance_transform_edt(truth)
    deepest = np.array(np.unravel_index(depth.argmax(), depth.shape), float)
    return {"circle 1.3": (real_data.circle(centre, 1.3 * half.max(), 48), "circle"),
            "box 3 px out": (real_data.rectangle(centre, half + 3), "box"),
            "click 0.4 depth": (real_data.circle(deepest, max(1.5, 0.4 * depth.max()), 24), "inside")}


def phantom_rows(seeds: int, blur: float = 0.0):
    rows = []
    for seed in range(seeds):
        image, regions = phantom(seed, blur)
        for case, truth in regions:
            rows += drawn_rows(case, image, truth, phantom_drawings(truth))
    return rows


def large_rows():
    rows = []
    for size, radius in LARGE:
        centre = (size / 2 + 0.3, size / 2 - 0.2)
        grid = np.mgrid[:size, :size]
        truth = np.hypot(grid[0] - centre[0], grid[1] - centre[1]) <= radius
        image = truth + np.random.default_rng(size + radius).normal(0, 0.05, truth.shape)
        case = f"R {radius} on {size} px ({truth.mean():.0%})"
        for factor in (0.3, 0.4, 0.6, 1.2):
            init = real_data.circle(centre, factor * radius, 64)
            ious, stop = scored(image, truth, init, "inside" if factor < 1 else "circle")
            rows.append((case, f"circle {factor:g} R", ious, stop))
    return rows


def table(rows, first: str) -> str:
    lines = [f"| {first} | drawing | cases | " + " | ".join(f"{m} IoU" for m in METHODS) + " | "
             + " | ".join(f"{m} ms" for m in METHODS) + " | ours' stop reasons |",
             "|---|---|---|" + "---|" * (2 * len(METHODS)) + "---|"]
    for case in dict.fromkeys(r[0] for r in rows):
        for drawing in dict.fromkeys(r[1] for r in rows if r[0] == case):
            mine = [r for r in rows if r[0] == case and r[1] == drawing]
            stops = Counter(r[3] for r in mine)
            lines.append(f"| {case} | {drawing} | {len(mine)} | "
                         + " | ".join(f"{np.mean([r[2][m][0] for r in mine]):.3f}" for m in METHODS) + " | "
                         + " | ".join(f"{1000 * np.mean([r[2][m][1] for r in mine]):.0f}" for m in METHODS)
                         + " | " + ", ".join(f"{k} {v}" for k, v in stops.items()) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="fields of spots or rods per size and density")
    ap.add_argument("--fields", nargs="+", choices=FIELDS, default=list(FIELDS), help="which fields to run")
    ap.add_argument("--colony-figure", metavar="PNG", help="also draw ours on a colony's rod from each drawing")
    ap.add_argument("--phantom-blur", type=float, default=0.0, metavar="SIGMA",
                    help="blur the phantom by a Gaussian of SIGMA px before the noise (the truth stays sharp)")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    print("Command: `python benchmarks/fields.py" + ("" if args.fields == list(FIELDS) else
                                                    " --fields " + " ".join(args.fields))
          + (f" --phantom-blur {args.phantom_blur:g}" if args.phantom_blur else "") + "`")
    for name in args.fields:
        rows = {"spots": lambda: spot_rows(args.seeds), "rods": lambda: rod_rows(args.seeds),
                "crescents": lambda: crescent_rows(max(1, args.seeds - 1)),
                "colonies": lambda: colony_rows(max(1, args.seeds - 1)),
                "disks": large_rows, "phantom": lambda: phantom_rows(max(1, args.seeds - 1), args.phantom_blur)}[name]()
        print()
        print(table(rows, FIELDS[name]))
    if args.colony_figure:
        colony_figure(args.colony_figure)


if __name__ == "__main__":
    main()

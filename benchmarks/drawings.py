"""``segment()`` from drawings beyond those of ``benchmarks/real.py``, on the same real images.

``benchmarks/real.py`` starts each object from four drawings (a rough circle, a freehand
lasso, a circle half the object's size inside it, a box 1.1-1.5x its bounding box) and runs the
scikit-image anchors beside ours. People draw in other ways too; this script tries ours alone
(the anchors have no answer to most of these) on every object of the real groups from seven more,
each seeded by the case's name:

* **polygon**: 5-8 clicks around the object at 1.2-1.6x its radius (+-15 %), their angles
  evenly spread with jitter, so that some chords cut the object's corners;
* **ellipse**: napari's ellipse tool over the bounding box, 1.15-1.4x it;
* **off-centre**: a circle 1.6x the object's radius, its centre 0.35 radius off the object's,
  crossing neighbours and the image's side;
* **tight**: the object's outline 0.5-1.5 px outside it (a label's outline, an earlier result);
* **click inside**: a circle of 0.3x the local depth (1.5-6 px) at a random point at least
  0.3 of the object's depth inside it, as one click-drags inside a large object;
* **box 2x**: a box twice the bounding box, holding whole neighbours in a crowded field;
* **over the edge**: a circle 0.45x the object's radius, three quarters of the way from its
  centroid to a random point of its outline, so that it crosses the object's edge (a hasty
  click-drag near the border);
* **again**: the polygon's own result, started from again (a user refining a result, or
  pressing Segment twice). Under the table: how many of these results move (IoU below 0.9
  with the result they started from).

And circles drawn on the ground, with no object in them (a click that missed): of 8, 14 and
24 px radius, three of each on every image of the groups whose truths label every object, at
random points at least 1.5 radii and 3 px from any labelled pixel. No answer is right there;
the table counts the stop reasons, how far the contours spread (their area over the circle's)
and how long they took.

Run::

    python benchmarks/drawings.py [--write]

It writes every run to ``benchmark_output/drawings_cases.csv``; ``--write`` puts the table
into docs/benchmarks.md between ``<!-- drawings:start -->`` and ``<!-- drawings:end -->``.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import time
import warnings
import zlib

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402
from skimage.draw import polygon2mask  # noqa: E402

import real_data  # noqa: E402
from _common import machine, write_section  # noqa: E402
from real import OUT, run_ours  # noqa: E402
from segmentation import iou  # noqa: E402

GROUPS = ("nuclei", "heldout", "small", "timelapse", "coins", "dsb")


def polygon(obj, rng):
    n = int(rng.integers(5, 9))
    angles = rng.uniform(0, 2 * np.pi) + 2 * np.pi * (np.arange(n) + rng.uniform(-0.3, 0.3, n)) / n
    radii = obj.radius * rng.uniform(1.2, 1.6) * rng.uniform(0.85, 1.15, n)
    return obj.centroid + np.column_stack([radii * np.sin(angles), radii * np.cos(angles)])


def ellipse(obj, rng):
    centre, half = real_data.bounding_box(obj.mask)
    half = rng.uniform(1.15, 1.4) * half
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    return centre + np.column_stack([half[0] * np.sin(t), half[1] * np.cos(t)])


def off_centre(obj, rng):
    angle = rng.uniform(0, 2 * np.pi)
    return real_data.circle(obj.centroid + 0.35 * obj.radius * np.array([np.sin(angle), np.cos(angle)]),
                            1.6 * obj.radius)


def tight(obj, rng):
    return real_data.boundary(obj.mask, rng.uniform(0.5, 1.5))


def click_inside(obj, rng):
    depth = ndi.distance_transform_edt(obj.mask)
    candidates = np.argwhere(depth >= 0.3 * depth.max())
    point = candidates[rng.integers(len(candidates))]
    return real_data.circle(point.astype(float), max(1.5, 0.3 * depth[tuple(point)]))


def box_2x(obj, rng):
    centre, half = real_data.bounding_box(obj.mask)
    return real_data.rectangle(centre, 2 * half)


def over_the_edge(obj, rng):
    outline = real_data.outline_of(obj.mask)
    point = outline[rng.integers(len(outline))]
    return real_data.circle(obj.centroid + 0.75 * (point - obj.centroid), 0.45 * obj.radius)


DRAWINGS = {"polygon": polygon, "ellipse": ellipse, "off-centre": off_centre, "tight": tight,
            "click inside": click_inside, "box 2x": box_2x, "over the edge": over_the_edge}


AGAIN = "again"  # the polygon's result, started from again
MOVED = 0.9  # below this IoU with the result it started from, a result started again has moved


def run(groups=GROUPS):
    """One row per object and drawing: group, object, drawing, IoU, stop reason, and for
    ``AGAIN`` the IoU with the result it started from (else NaN)."""
    rows = []
    for group in groups:
        for obj in real_data.GROUPS[group]():
            for kind, draw in DRAWINGS.items():
                init = draw(obj, real_data.rng_for(f"drawings/{group}/{obj.name}/{kind}"))
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    result, contour = run_ours(obj, init)
                rows.append((group, obj.name, kind, result["iou"], result["stop"], np.nan))
                if kind == "polygon" and contour is not None:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore")
                        again, second = run_ours(obj, contour)
                    same = 0.0 if second is None else iou(polygon2mask(obj.image.shape, contour),
                                                          polygon2mask(obj.image.shape, second))
                    rows.append((group, obj.name, AGAIN, again["iou"], again["stop"], same))
    return rows



#: The groups whose truths label every object of their images: the ground is all the rest.
GROUND_GROUPS = ("nuclei", "heldout", "small", "coins", "dsb")
GROUND_RADII = (8, 14, 24)


def ground_circles(groups=GROUND_GROUPS):
    """(image name, image, circle) for every circle on the ground (see the module's docstring)."""
    for group in groups:
        for name, objects in real_data.objects_by_image(group).items():
            image, labelled = objects[0].image, np.any([obj.mask for obj in objects], axis=0)
            rng = np.random.default_rng(zlib.crc32(name.encode()))
            free = ndi.distance_transform_edt(~labelled)
            for radius in GROUND_RADII:
                ok = np.argwhere(free > 1.5 * radius + 3)
                ok = ok[np.all((ok >= radius) & (ok < np.array(image.shape) - radius), axis=1)]
                for point in ok[rng.choice(len(ok), size=min(3, len(ok)), replace=False)]:
                    yield name, image, real_data.circle(point.astype(float), radius)


def run_ground(groups=GROUND_GROUPS):
    """One row per circle on the ground: image, stop reason, area over the circle's, seconds."""
    from napari_physeg.core import segment

    rows = []
    for name, image, circle in ground_circles(groups):
        t0 = time.perf_counter()
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = segment(image, circle)
        except Exception as exc:  # noqa: BLE001 - every failure is a result here
            rows.append((name, f"{type(exc).__name__}", np.nan, time.perf_counter() - t0))
            continue
        spread = polygon2mask(image.shape, res.contour).sum() / polygon2mask(image.shape, circle).sum()
        rows.append((name, res.stop_reason, spread, time.perf_counter() - t0))
    return rows


def ground_table(rows) -> list[str]:
    lines = ["| stop reason | circles | area over the circle's, median (max) | seconds, median (max) |",
             "|---|---|---|---|"]
    for stop in sorted({r[1] for r in rows}):
        spread = np.array([r[2] for r in rows if r[1] == stop])
        seconds = np.array([r[3] for r in rows if r[1] == stop])
        lines.append(f"| {stop} | {len(spread)} | {np.median(spread):.0f} ({np.max(spread):.0f}) "
                     f"| {np.median(seconds):.2f} ({np.max(seconds):.2f}) |")
    return lines


def table(rows) -> list[str]:
    kinds, groups = [*DRAWINGS, AGAIN], dict.fromkeys(r[0] for r in rows)
    lines = ["| group | " + " | ".join(kinds) + " |", "|---|" + "---|" * len(kinds)]
    for group in groups:
        cells = []
        for kind in kinds:
            iou = np.array([r[3] for r in rows if r[0] == group and r[2] == kind])
            cells.append(f"{iou.mean():.3f} ({np.mean(iou < 0.85):.0%}, {iou.min():.2f})")
        lines.append(f"| {group} | " + " | ".join(cells) + " |")
    stops = {}
    for r in rows:
        stops[r[4]] = stops.get(r[4], 0) + 1
    lines += ["", f"Mean IoU (share below 0.85, worst) over {len(rows)} runs; stop reasons: "
              + ", ".join(f"{k} {v}" for k, v in sorted(stops.items())) + "."]
    moved = {group: [r[5] < MOVED for r in rows if r[0] == group and r[2] == AGAIN] for group in groups}
    lines += ["", f"Started again from the polygon's result, results that moved (IoU below {MOVED} with it): "
              + ", ".join(f"{group} {sum(m)} of {len(m)}" for group, m in moved.items()) + "."]
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = ap.parse_args(argv)
    rows, ground = run(), run_ground()
    OUT.mkdir(exist_ok=True)
    with open(OUT / "drawings_cases.csv", "w", newline="") as f:
        csv.writer(f).writerows([("group", "object", "drawing", "iou", "stop", "iou_with_start"), *rows])
    with open(OUT / "drawings_ground.csv", "w", newline="") as f:
        csv.writer(f).writerows([("image", "stop", "area_over_circle", "seconds"), *ground])
    lines = [f"Machine: {machine()}", "Command: `python benchmarks/drawings.py`", "", *table(rows), "",
             f"Circles on the ground, no object in them ({len(ground)}, on the images of "
             + ", ".join(GROUND_GROUPS) + "; one row per stop reason):", "", *ground_table(ground)]
    print("\n".join(lines))
    if args.write:
        doc = write_section("drawings", lines, "Other drawings on the real images")
        print(f"wrote {doc}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Where each truth of ``real.py`` puts an object's border on its edge's ramp, and where ours does.

An object's blurred edge is a ramp from its level down to its background's. Half-way (the
half maximum) is where a step edge blurred by a symmetric point-spread function lies, and
where ``segment()`` puts the border; a truth may put it higher or lower on the ramp (a
program's labels at its own threshold, a hand tracing the outer extent of what it sees). Such
a convention moves every outline by a fraction of the ramp's width: on objects 20-60 px across
that alone is an IoU of 0.85-0.95.

For every object of the chosen groups (lightly smoothed image, Gaussian sigma 1 px, as the
region force reads it):

* the object's level is the median over the truth's interior (3 px or more inside it, or its
  deeper half on a small object); its background's the lower quartile of a ring 3-8 px outside
  it (the lower quartile: a neighbour may lie in the ring);
* a border's level is the mean of the medians over the pixels just inside and just outside it
  (its 1-px inner and outer rims), on the scale 0 (background) to 1 (object level);
* ours is the result of ``segment()`` from the circle drawing of ``real.py`` (same seed).

The phase-contrast *E. coli* colony is left out by default: a phase image has no ramp between
two levels (a dark rod in a bright halo).

    python benchmarks/label_levels.py [--groups ...] [--write]

``--write`` puts the table into docs/benchmarks.md between ``<!-- label_levels:start -->`` and
``<!-- label_levels:end -->`` and draws the levels per group to
``docs/images/real_label_levels.png``.
"""

from __future__ import annotations

import argparse
import os
import warnings

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
from skimage.draw import polygon2mask  # noqa: E402

import real_data  # noqa: E402
from _common import machine, report, write_section_with_figure  # noqa: E402
from napari_physeg.core import segment  # noqa: E402

_RIM = np.ones((3, 3), np.uint8)


def levels(image: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """The object's level and its background's (see the module's docstring)."""
    depth = cv2.distanceTransform(np.pad(truth, 1).view(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1]
    interior = depth >= min(3.0, 0.5 * float(depth.max()))
    ring = real_data.ring(truth, 3, 8)
    return float(np.median(image[interior])), float(np.percentile(image[ring], 25))


def border_level(image: np.ndarray, mask: np.ndarray, obj_level: float, background: float) -> float:
    """Where ``mask``'s border lies between ``background`` (0) and ``obj_level`` (1)."""
    m8 = mask.view(np.uint8)
    inner = mask & ~cv2.erode(m8, _RIM).view(bool)
    outer = cv2.dilate(m8, _RIM).view(bool) & ~mask
    if not inner.any() or not outer.any():
        return np.nan
    border = 0.5 * (np.median(image[inner]) + np.median(image[outer]))
    return float((border - background) / (obj_level - background))


def measure(groups) -> dict[str, tuple[list, list]]:
    """``{group: (truth's border levels, ours)}``, one value per object."""
    out = {}
    for group in groups:
        truths, ours = [], []
        for obj in real_data.GROUPS[group]():
            smooth = cv2.GaussianBlur(obj.image.astype(np.float64), (0, 0), 1.0)
            obj_level, background = levels(smooth, obj.mask)
            if abs(obj_level - background) < 1e-6:
                continue
            truths.append(border_level(smooth, obj.mask, obj_level, background))
            init, _ = real_data.INITS["circle"](obj, real_data.rng_for(f"{group}/{obj.name}/circle"))
            with warnings.catch_warnings():  # circles partly beyond the image are clipped
                warnings.simplefilter("ignore", UserWarning)
                contour = segment(obj.image, init).contour
            ours.append(border_level(smooth, polygon2mask(obj.image.shape, contour), obj_level, background))
        out[group] = (truths, ours)
    return out


def table(results) -> list[str]:
    def quartiles(values):
        q = np.nanpercentile(values, [25, 50, 75])
        return f"{q[1]:.2f} ({q[0]:.2f}-{q[2]:.2f})"

    lines = ["| group | objects | truth's border level, median (quartiles) | ours, from the circle |",
             "|---|---|---|---|"]
    for group, (truths, ours) in results.items():
        lines.append(f"| {group} | {len(truths)} | {quartiles(truths)} | {quartiles(ours)} |")
    return lines


def figure(results, path) -> None:
    """The truths' border levels and ours, per group, as box plots."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = list(results)
    fig, ax = plt.subplots(figsize=(1.1 * len(groups) + 2, 4))
    at = np.arange(len(groups))
    for shift, which, colour, label in ((-0.18, 0, "tab:green", "truth"), (0.18, 1, "tab:red", "ours (circle)")):
        data = [np.asarray(results[g][which])[np.isfinite(results[g][which])] for g in groups]
        ax.boxplot(data, positions=at + shift, widths=0.3, showfliers=False, patch_artist=True,
                   boxprops=dict(facecolor=colour, alpha=0.5), medianprops=dict(color="black"))
        ax.plot([], [], color=colour, lw=6, alpha=0.5, label=label)
    ax.axhline(0.5, color="grey", lw=0.8, ls="--")
    ax.set_xticks(at, groups)
    ax.set_ylabel("border level (0 background, 1 object)")
    ax.set_title("where each truth puts the border on the edge's ramp, and where ours does")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--groups", nargs="+", choices=list(real_data.GROUPS),
                    default=[g for g in real_data.GROUPS if g != "ecoli"])
    ap.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = ap.parse_args(argv)
    lines, out = report()
    out(f"Machine: {machine()}")
    out("Command: `python benchmarks/label_levels.py`")
    out()
    out("Where the border lies on the edge's ramp, 0 at the background's level and 1 at the object's "
        "(the lightly smoothed image; see the script's docstring):")
    out()
    results = measure(args.groups)
    for line in table(results):
        out(line)
    if args.write:
        doc = write_section_with_figure("label_levels", lines, "Where the truths put the border",
                                        lambda path: figure(results, path), "real_label_levels.png",
                                        "border levels per group")
        print(f"wrote {doc}")


if __name__ == "__main__":
    main()

"""Where a crowd's truth parts touching nuclei: is there anything in the image to part them at?

Of ``real.py``'s Data Science Bowl cases, many that score below 0.85 hold part of a touching
neighbour. Ours parts touching nuclei at necks and at valleys of intensity between them; a
truth drawn by hand may part them where the image shows neither. For every case of the chosen
groups below ``--below`` (IoU of ours, from ``real.py``'s drawings and seeds) whose contour holds
at least a tenth of a *touching* neighbour's label (the neighbour's label most of its pixels
beyond its own fall on), on the lightly smoothed image (Gaussian sigma 1 px, as the region force
reads it):

* the contact is the pixels of either label next to the other's (8-neighbours);
* its *dip* is how much darker the contact is than the dimmer of the two nuclei (medians), in
  noise standard deviations of the image: positive where a dark line parts them, negative where
  the contact is brighter (overlapping nuclei add up);
* its *step* is how much the two nuclei's levels (medians) differ, in the same units: a bright
  nucleus beside a dim one shows where they meet without a dip.

A contact with neither a dip nor a step of VISIBLE noise standard deviations shows nothing in
the image's levels to part the two at; only their shapes can.

    python benchmarks/crowd_contacts.py [--groups dsb] [--below 0.85] [--write]

``--write`` puts the table into docs/benchmarks.md between ``<!-- crowd_contacts:start -->`` and
``<!-- crowd_contacts:end -->`` and draws six of the contacts that show nothing to
``docs/images/real_crowd_contacts.png``.
"""

from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
from scipy import ndimage as ndi  # noqa: E402
from skimage.draw import polygon2mask  # noqa: E402

import real_data  # noqa: E402
from _common import machine, report, write_section_with_figure  # noqa: E402
from napari_physeg.core import segment  # noqa: E402
from napari_physeg.core.features import _noise_sigma  # noqa: E402

#: A neighbour is taken when the contour holds at least this share of the object's area of its label.
TAKEN_SHARE = 0.1
#: A dip or a step of at least this many noise standard deviations shows where two nuclei meet.
VISIBLE = 2.0
_EIGHT = np.ones((3, 3), bool)


def contact_contrasts(smoothed: np.ndarray, a: np.ndarray, b: np.ndarray, noise: float):
    """``(dip, step)`` where masks ``a`` and ``b`` touch, in units of ``noise``: how much darker
    the pixels of the contact are than the dimmer of the two, and how much the two differ
    (medians of ``smoothed``); None if they do not touch."""
    contact = (a & ndi.binary_dilation(b, _EIGHT)) | (b & ndi.binary_dilation(a, _EIGHT))
    if np.count_nonzero(contact) < 3:
        return None
    level_a, level_b = float(np.median(smoothed[a])), float(np.median(smoothed[b]))
    return (min(level_a, level_b) - float(np.median(smoothed[contact]))) / noise, abs(level_a - level_b) / noise


def taken_neighbour(found: np.ndarray, labels: np.ndarray, own: int, area: int) -> int | None:
    """The label other than ``own`` that most of the pixels of the region ``found`` beyond its
    own fall on, if they hold at least TAKEN_SHARE of ``area``; else None."""
    inside = labels[found]
    others = inside[(inside != own) & (inside > 0)]
    return int(np.bincount(others).argmax()) if others.size >= TAKEN_SHARE * area else None


def _labelled_images(group: str) -> dict:
    """Per image of ``group`` (see ``real_data.Obj.image_name``), the labels of its objects (1,
    2, ... in their order)."""
    labels = {}
    for name, objects in real_data.objects_by_image(group).items():
        labels[name] = np.zeros(objects[0].image.shape, np.int32)
        for obj in objects:
            labels[name][obj.mask] = labels[name].max() + 1
    return labels


def measure(groups, below: float) -> tuple[list[dict], int]:
    """One row per case below ``below`` that took a touching neighbour (its name, IoU, dip,
    and what the figure draws), and how many cases lie below ``below``."""
    rows, n_below = [], 0
    for group in groups:
        labelled, looks = _labelled_images(group), {}
        for name, kind, obj, init in real_data.cases([group]):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                contour = segment(obj.image, init).contour
            found = polygon2mask(obj.mask.shape, contour)
            iou = np.count_nonzero(found & obj.mask) / np.count_nonzero(found | obj.mask)
            if iou >= below:
                continue
            n_below += 1
            key = obj.image_name
            labels = labelled[key]
            if key not in looks:
                looks[key] = ndi.gaussian_filter(obj.image, 1.0), _noise_sigma(obj.image)
            smoothed, noise = looks[key]
            own = int(np.bincount(labels[obj.mask]).argmax())
            other = taken_neighbour(found, labels, own, int(obj.mask.sum()))
            contrasts = None if other is None else contact_contrasts(smoothed, labels == own, labels == other, noise)
            if contrasts is not None:
                rows.append(dict(name=name, iou=iou, dip=contrasts[0], step=contrasts[1], contour=contour,
                                 own=labels == own, other=labels == other, image=obj.image))
    return rows, n_below


def _invisible(row) -> bool:
    return row["dip"] < VISIBLE and row["step"] < VISIBLE


def table(rows, n_below: int) -> list[str]:
    def spread(key):
        values = np.array([r[key] for r in rows])
        return " / ".join(f"{v:.1f}" for v in np.percentile(values, [10, 50, 90])) if values.size else "-"

    return ["| cases below the bar | of which took a touching neighbour | contact's dip, 10th / 50th / 90th "
            "percentile (noise sigmas) | the nuclei's step, the same | contacts with neither a dip nor a step of "
            f"{VISIBLE:g} sigmas |",
            "|---|---|---|---|---|",
            f"| {n_below} | {len(rows)} | {spread('dip')} | {spread('step')} | {sum(map(_invisible, rows))} |"]


def figure(rows, path: Path, n: int = 6) -> None:
    """``n`` of the contacts with neither a dip nor a step (see VISIBLE), spread over their
    IoUs, one per nucleus: labels (own green, neighbour yellow), ours red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    seen, invisible = set(), []
    for r in sorted(filter(_invisible, rows), key=lambda r: r["iou"]):
        if r["name"].rsplit("/", 1)[0] not in seen:
            seen.add(r["name"].rsplit("/", 1)[0])
            invisible.append(r)
    picked = [invisible[i] for i in np.unique(np.linspace(0, len(invisible) - 1, n).round().astype(int))]
    fig, axes = plt.subplots(1, len(picked), figsize=(3.2 * len(picked), 3.6))
    for ax, r in zip(np.atleast_1d(axes), picked):
        rr, cc = np.nonzero(r["own"] | r["other"])
        lo = np.maximum(np.minimum([rr.min(), cc.min()], r["contour"].min(0)) - 6, 0).astype(int)
        hi = (np.maximum([rr.max(), cc.max()], r["contour"].max(0)) + 7).astype(int)
        view = (slice(lo[0], hi[0]), slice(lo[1], hi[1]))
        ax.imshow(r["image"][view], cmap="gray")
        ax.contour(r["own"][view], [0.5], colors="lime", linewidths=1)
        ax.contour(r["other"][view], [0.5], colors="yellow", linewidths=1)
        c = np.vstack([r["contour"], r["contour"][:1]]) - lo
        ax.plot(c[:, 1], c[:, 0], "r-", lw=1)
        ax.set_title(f"{r['name'].split('/', 1)[1]}: IoU {r['iou']:.2f}\ndip {r['dip']:.1f}, step {r['step']:.1f} "
                     "sigma", fontsize=8)
        ax.axis("off")
    fig.suptitle("truth green, its touching neighbour yellow, ours red: neither a dip nor a step where the truth "
                 "parts them", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--groups", nargs="+", choices=list(real_data.GROUPS), default=["dsb"])
    ap.add_argument("--below", type=float, default=0.85)
    ap.add_argument("--write", action="store_true", help="write the table into docs/benchmarks.md")
    args = ap.parse_args(argv)
    lines, out = report()
    out(f"Machine: {machine()}")
    out("Command: `python benchmarks/crowd_contacts.py`")
    out()
    rows, n_below = measure(args.groups, args.below)
    out(f"Groups {', '.join(args.groups)}; ours from real.py's drawings; the bar {args.below}:")
    out()
    for line in table(rows, n_below):
        out(line)
    if args.write:
        doc = write_section_with_figure("crowd_contacts", lines, "Where a crowd truth parts touching nuclei",
                                        lambda path: figure(rows, path), "real_crowd_contacts.png",
                                        "touching nuclei parted where the image shows neither a dip nor a step")
        print(f"wrote {doc}")


if __name__ == "__main__":
    main()

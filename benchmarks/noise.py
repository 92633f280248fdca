"""Noise probe: ``segment()`` and the scikit-image anchors on the real-image cases made noisier.

The real images of ``real.py`` are clean confocal and widefield pictures. Live imaging is often
photon-starved instead. This probe adds noise to every ``--every``-th object of each group (with
all its drawings) and runs ours and the anchors of ``real.py`` (snake aside: MGAC and
morphological Chan-Vese on the same crops) on the same drawings, in one run:

* ``poissonN``: photon counting, the image (in [0, 1]) scaled to ``N`` photons at its brightest,
  over a background of 2 photons: ``Poisson(N * image + 2)``;
* ``snrS``: white Gaussian noise of ``contrast / S`` per pixel, ``contrast`` the difference
  between the object's median and that of the ring 2-6 px outside it (the truth's);
* ``hotN``: ``N`` hot pixels of a camera, each 50 times the image's brightest, at random within
  15 px of the drawing's centre (on the object, or about it), the image otherwise as it is.

Each case's noise is drawn ``--draws`` times (seeded; once by default) and shared by the methods;
the table averages over the draws. One draw is enough to rank methods that differ by a tenth,
not to judge a change of ours that moves the mean by a hundredth: a case's IoU can move by a
third from one draw to the next (session 36).

    python benchmarks/noise.py --noise poisson30 snr2 --every 4

Two worker processes; times are not reported (``real.py`` times the methods).
"""

from __future__ import annotations

import argparse
import os
import re
import warnings
from collections import Counter
from dataclasses import replace
from multiprocessing import Pool

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import real  # noqa: E402
import real_data  # noqa: E402

METHODS = ("ours", "MGAC", "MCV")
#: The groups whose images are fluorescence in [0, 1] (coins and the cell are not photon counts).
GROUPS = ("nuclei", "heldout", "small", "timelapse", "dsb", "stack3d", "u2os")


def noisy(obj, noise: str, rng: np.random.Generator, init=None):
    """``obj`` with ``noise`` ("clean", "poissonN", "snrS" or "hotN", about ``init``'s centre)
    added to its image."""
    check_noise(noise)
    image = obj.image
    if noise.startswith("hot"):
        if init is None:
            raise ValueError(f"{noise!r} puts hot pixels about a drawing's centre: pass the drawing as init")
        hot, centre = image.copy(), np.asarray(init, dtype=float).mean(0).astype(int)
        for _ in range(int(noise[len("hot"):])):
            row, col = np.clip(centre + rng.integers(-15, 16, 2), 0, np.array(image.shape) - 1)
            hot[row, col] = 50.0 * image.max()
        return replace(obj, image=hot)
    if noise.startswith("poisson"):
        photons = float(noise[len("poisson"):])
        return replace(obj, image=rng.poisson(np.clip(image, 0.0, None) * photons + 2.0).astype(np.float64))
    if noise.startswith("snr"):
        contrast = abs(np.median(image[obj.mask]) - np.median(image[real_data.ring(obj.mask, 2, 6)]))
        return replace(obj, image=image + rng.normal(0.0, contrast / float(noise[len("snr"):]), image.shape))
    return obj


def check_noise(noise: str) -> None:
    """Raise ValueError if ``noise`` is not "clean", "poissonN", "snrS" (N, S positive numbers) or
    "hotN" (N a positive whole number)."""
    level = re.fullmatch(r"(poisson|snr)(\d+\.?\d*|\.\d+)|hot([1-9]\d*)", noise)
    if noise != "clean" and (level is None or (level[2] is not None and float(level[2]) <= 0)):
        raise ValueError(f"unknown noise {noise!r}: use poissonN (N photons at the brightest), snrS (S the "
                         "object's contrast over the noise) or hotN (N hot pixels), e.g. poisson30 snr2 hot3")


def run_group(job):
    """Rows ``(group, noise, {method: iou}, our stop reason)`` of one group."""
    group, noises, every, draws = job
    warnings.simplefilter("ignore")
    rows = []
    for i, (_, kind, obj, init) in enumerate(real_data.cases([group], every=every)):
        for noise in noises:
            for draw in range(draws if noise != "clean" else 1):
                case = noisy(obj, noise, np.random.default_rng(i if draw == 0 else (i, draw)), init)
                ours, _ = real.run_ours(case, init)
                anchors, _, _ = real.run_anchors(case, init, kind)
                rows.append((group, noise, {"ours": ours["iou"], **{m: anchors[m]["iou"] for m in METHODS[1:]}},
                             ours["stop"]))
    return rows


def table(rows, noises) -> str:
    groups = list(dict.fromkeys(r[0] for r in rows))
    head = "| group | cases | " + " | ".join(f"{m} {n}" for n in noises for m in METHODS) + " |"
    lines = [head, "|" + "---|" * (2 + len(noises) * len(METHODS))]
    for g in groups + ["all"]:
        mine = [r for r in rows if g in ("all", r[0])]
        cells = [f"{np.mean([r[2][m] for r in mine if r[1] == n]):.3f}" for n in noises for m in METHODS]
        lines.append(f"| {g} | {sum(r[1] == 'clean' for r in mine)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--noise", nargs="+", default=["poisson30", "snr2"], help="poissonN, snrS and/or hotN")
    ap.add_argument("--every", type=int, default=4, help="every n-th object of each group, all its drawings")
    ap.add_argument("--draws", type=int, default=1, help="noise draws per case (the table averages them)")
    ap.add_argument("--groups", nargs="+", choices=GROUPS, default=list(GROUPS))
    args = ap.parse_args(argv)
    for noise in args.noise:
        try:
            check_noise(noise)
        except ValueError as error:
            ap.error(str(error))
    noises = ["clean", *args.noise]
    with Pool(2) as pool:
        jobs = [(g, noises, args.every, max(args.draws, 1)) for g in args.groups]
        rows = [r for part in pool.map(run_group, jobs) for r in part]
    groups = "" if list(args.groups) == list(GROUPS) else f" --groups {' '.join(args.groups)}"
    draws = f" --draws {args.draws}" if args.draws > 1 else ""
    print(f"Command: `python benchmarks/noise.py --noise {' '.join(args.noise)} --every {args.every}{draws}{groups}`\n")
    print(table(rows, noises))
    stops = {n: dict(Counter(r[3] for r in rows if r[1] == n)) for n in noises}
    print("\n" + "\n".join(f"- ours' stop reasons, {n}: {s}" for n, s in stops.items()))


if __name__ == "__main__":
    main()

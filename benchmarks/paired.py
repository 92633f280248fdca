"""Paired timing: the working package against the package at another commit, in one process.

This machine's timings drift by up to a quarter within an hour, so a run's time set beside a
figure measured on another day says little about a change. This script imports the package as
it was at ``--ref`` (by ``git archive``) beside the working one, and times both on the same
cases, alternating which goes first, each case the best of ``--repeat`` calls:

* ``real``: ``segment()`` on every ``--every``-th case of the real-image benchmark;
* ``tracking``: ``track()`` on the Cell Tracking Challenge movie, ``--repeat`` times each.

It checks that both give the same results (largest node difference) and reports the medians and
the ratio of the totals. It writes nothing into the docs: quote its output with its command.

    python benchmarks/paired.py --ref 122a37e real --every 3
    python benchmarks/paired.py --ref 122a37e tracking --repeat 6
"""

from __future__ import annotations

import argparse
import importlib
import io
import os
import subprocess
import sys
import tarfile
import tempfile
import time
import warnings
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from _common import machine  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def package_at(ref: str, into: Path):
    """``napari_physeg.core`` as it was at commit ``ref``, imported as ``physeg_ref.core``."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref, "src/napari_physeg"],
                             check=True, capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(into, filter="data")
    (into / "src" / "napari_physeg").rename(into / "physeg_ref")  # the package imports itself relatively
    sys.path.insert(0, str(into))
    return importlib.import_module("physeg_ref.core")


def best_of(fn, repeat: int):
    best, out = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return out, best


def paired_real(ref, new, every: int, repeat: int) -> None:
    import real_data

    cases = [c for g in real_data.GROUPS for c in list(real_data.cases([g]))[::every]]
    times = {"ref": [], "new": []}
    largest, differ = 0.0, 0
    for i, (_, _, obj, init) in enumerate(cases):
        results = {}
        for name in (("ref", "new") if i % 2 else ("new", "ref")):
            module = ref if name == "ref" else new
            try:
                results[name], t = best_of(lambda: module.segment(obj.image, init).contour, repeat)
            except Exception:  # noqa: BLE001 - a failure is timed too, and must be the same in both
                results[name], t = None, np.nan
            times[name].append(t)
        a, b = results["ref"], results["new"]
        if a is not None and b is not None and a.shape == b.shape:
            largest = max(largest, float(np.abs(a - b).max()))
        else:
            differ += (a is None) != (b is None) or a is not None and a.shape != b.shape
    ref_t, new_t = np.array(times["ref"]), np.array(times["new"])
    print(f"segment() on {len(cases)} real cases (one in {every}, best of {repeat}): median "
          f"{1e3 * np.nanmedian(ref_t):.1f} ms at the reference, {1e3 * np.nanmedian(new_t):.1f} ms now; "
          f"total ratio {np.nansum(new_t) / np.nansum(ref_t):.3f}; largest node difference {largest:.2g} px "
          f"where the node counts agree, {differ} case(s) where they or the failures do not")


def paired_tracking(ref, new, repeat: int) -> None:
    import tracking as bench

    frames, _, _, inits = bench.ctc()
    for module in (ref, new):  # warm-up: imports, caches
        module.track(frames[:3], inits)
    n = len(inits) * len(frames)
    times, contours = {"ref": [], "new": []}, {}
    for i in range(repeat):
        for name in (("ref", "new") if i % 2 else ("new", "ref")):
            module = ref if name == "ref" else new
            t0 = time.perf_counter()
            contours[name] = module.track(frames, inits).contours
            times[name].append(1e3 * (time.perf_counter() - t0) / n)
    same = all((a is None) == (b is None) and (a is None or (a.shape == b.shape and np.allclose(a, b, atol=1e-6)))
               for row_a, row_b in zip(contours["ref"], contours["new"]) for a, b in zip(row_a, row_b))
    for name, label in (("ref", "the reference"), ("new", "now")):
        t = times[name]
        print(f"track() on the CTC movie, ms per object-frame, {label}: {' '.join(f'{x:.1f}' for x in t)} "
              f"(best {min(t):.1f})")
    print(f"best ratio {min(times['new']) / min(times['ref']):.3f}; same contours: {same}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("real", "tracking"))
    ap.add_argument("--ref", required=True, help="the commit to compare with (e.g. the session's first)")
    ap.add_argument("--every", type=int, default=3, help="real: every n-th case")
    ap.add_argument("--repeat", type=int, default=2, help="real: calls per case; tracking: runs of each")
    args = ap.parse_args(argv)
    warnings.simplefilter("ignore")
    import napari_physeg.core as new

    print(f"Machine: {machine()}\nCommand: `python benchmarks/paired.py {' '.join(argv or sys.argv[1:])}`")
    with tempfile.TemporaryDirectory() as tmp:
        ref = package_at(args.ref, Path(tmp))
        if args.what == "real":
            paired_real(ref, new, args.every, args.repeat)
        else:
            paired_tracking(ref, new, args.repeat)


if __name__ == "__main__":
    main()

"""Batch benchmark: ``napari_physeg.batch.track_files`` on a local dask cluster.

Movies: ``napari_physeg.data.deforming_cell()`` (one cell, 160 x 160, known answer)
padded by edge replication into larger frames, written as uint16 TIFF stacks, with the
cell's frame-0 outline as the initial contour. Each task tracks one movie; the workers are
``dask.distributed`` processes with one thread each, BLAS pinned to one thread.

* **Throughput** - the same movies (default 8 of 30 frames of 256 x 256) on 1 and on 2
  workers, each cluster started and its workers warmed up (the package imported) before
  the clock starts, the fastest of ``--repeat`` runs: movies per minute, the speed-up, and
  the CPU time per movie of the workers and of the scheduler and client (which a shared
  machine inflates much less than wall time).
* **Memory per worker** - movies of 10, 20 and 40 frames of 512 x 512 on one worker, a
  fresh cluster for each length: the worker's resident memory once warmed up, and its peak
  resident memory during the batch (Linux's ``VmHWM``, reset after the warm-up). Frames are read one at a
  time, so the peak must not grow with the movie's length (a whole 40-frame movie as
  float64 would be 80 MB).
* **Estimate** for 1000 movies of 30 frames (256 x 256) on N workers, from the per-task
  time measured on 2 workers (wall time x workers / tasks: dask's overhead included) and
  the peak memory per worker: time = 1000 x that / N, memory = N x the peak (plus the
  scheduler's and client's, a few hundred MB, not counted).

Run::

    make bench        # or: .venv/bin/python benchmarks/batch.py [--write] [--movies 8] [--repeat 2]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import resource  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import tifffile  # noqa: E402
from distributed import Client, LocalCluster  # noqa: E402

from _common import machine, write_section  # noqa: E402
from napari_physeg import data  # noqa: E402
from napari_physeg.batch import track_files  # noqa: E402



def write_movies(folder: Path, n: int, n_frames: int, size: int):
    """``n`` TIFF movies of ``n_frames`` frames of ``size`` x ``size``, and the initial contour."""
    movie = data.deforming_cell(n_frames=n_frames)
    pad = (size - movie.frames.shape[1]) // 2
    frames = np.pad(movie.frames, ((0, 0), (pad, pad), (pad, pad)), mode="edge")
    stack = (frames * 1000).astype(np.uint16)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        paths.append(folder / f"movie{i:03d}.tif")
        tifffile.imwrite(paths[-1], stack, photometric="minisblack")
    return paths, [movie.init + pad]


def _warm():
    """Import what a task uses, so that the clock and the memory baseline start warm."""
    import pandas  # noqa: F401
    import tifffile  # noqa: F401

    import napari_physeg.batch  # noqa: F401
    import napari_physeg.core  # noqa: F401

    for optional in ("zarr", "pyarrow.parquet"):
        try:
            __import__(optional)
        except ImportError:
            pass
    return os.getpid()


def _rss_now():
    import psutil

    return psutil.Process().memory_info().rss


def _reset_peak():
    """Start the worker's peak resident memory afresh (Linux: VmHWM). ru_maxrss would not do: a
    spawned process inherits the high-water mark of the process it was forked from."""
    with open("/proc/self/clear_refs", "w") as fh:
        fh.write("5")


def _rss_peak():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024  # kB
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def run(paths, inits, out: Path, workers: int) -> dict:
    """Track ``paths`` on a fresh local cluster of ``workers`` processes."""
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster, set_as_default=False) as client:
        client.run(_warm)
        warm = client.run(_rss_now)
        client.run(_reset_peak)
        cpu0, here0 = client.run(_cpu), _cpu()
        t0 = time.perf_counter()
        table = track_files(paths, inits, out, client=client, progress=False)
        wall = time.perf_counter() - t0
        cpu1, here1 = client.run(_cpu), _cpu()
        peak = client.run(_rss_peak)
    assert (table["status"] == "ok").all() and (table["lost"] == 0).all(), table
    return {"wall": wall, "tasks": len(paths), "task_seconds": float(table["seconds"].median()),
            "cpu_per_task": sum(cpu1[w] - cpu0[w] for w in cpu0) / len(paths),
            "client_cpu_per_task": (here1 - here0) / len(paths),
            "warm_mb": max(warm.values()) / 2**20, "peak_mb": max(peak.values()) / 2**20}


def _cpu():
    """CPU seconds this process used: unlike wall time, not stretched by other jobs on the machine."""
    times = os.times()
    return times.user + times.system


def _duration(seconds: float) -> str:
    if seconds >= 3600:
        return f"{int(seconds // 3600)} h {int(round(seconds % 3600 / 60)):02d} min"
    return f"{seconds / 60:.1f} min" if seconds >= 60 else f"{seconds:.0f} s"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--write", action="store_true", help="write the table into docs/batch.md")
    ap.add_argument("--movies", type=int, default=8, help="movies in the throughput runs (default 8)")
    ap.add_argument("--repeat", type=int, default=2, help="throughput runs per worker count; the fastest "
                    "is kept (default 2)")
    args = ap.parse_args(argv)
    lines = []
    load_before = os.getloadavg()[0]
    _warm()  # the client's imports are not the first run's cost
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        paths, inits = write_movies(tmp / "movies", args.movies, 30, 256)
        # Best of --repeat runs (fresh output each): other jobs on a shared machine only slow a run down.
        speed = {w: min((run(paths, inits, tmp / f"out{w}-{i}", w) for i in range(args.repeat)),
                        key=lambda r: r["wall"]) for w in (1, 2)}
        memory = {}
        for n_frames in (10, 20, 40):
            mpaths, minits = write_movies(tmp / f"m{n_frames}", 2, n_frames, 512)
            memory[n_frames] = run(mpaths, minits, tmp / f"mem{n_frames}", 1)
    one, two = speed[1], speed[2]
    load = max(load_before, os.getloadavg()[0])
    lines.append(f"Measured by `benchmarks/batch.py` on {machine()}; load average {load:.1f} "
                 f"around the run" + (f" (other jobs shared the {os.cpu_count()} cores: the times and the "
                                      "speed-up are pessimistic)" if load > 1.0 else "") + ".")
    lines.append("")
    lines.append(f"**Throughput**, {args.movies} movies of 30 frames (256 x 256), one cell each:")
    lines.append("")
    lines.append("| workers | wall time (s) | movies / min | speed-up | worker CPU s per movie | "
                 "scheduler + client CPU s per movie |")
    lines.append("|---:|---:|---:|---:|---:|---:|")
    for w, r in speed.items():
        lines.append(f"| {w} | {r['wall']:.1f} | {60 * r['tasks'] / r['wall']:.1f} | "
                     f"{one['wall'] / r['wall']:.2f}x | {r['cpu_per_task']:.2f} | {r['client_cpu_per_task']:.3f} |")
    lines.append("")
    idle = 2 * one["cpu_per_task"] / (two["cpu_per_task"] + two["client_cpu_per_task"])
    lines.append("CPU time depends much less than wall time on other jobs on the machine (only through shared "
                 "caches). With one worker the scheduler "
                 "has the other core to itself; with two, the workers share the 2 cores with it: on idle cores "
                 f"the speed-up is about 2 x {one['cpu_per_task']:.2f} / ({two['cpu_per_task']:.2f} + "
                 f"{two['client_cpu_per_task']:.3f}) = {idle:.2f}x.")
    lines.append("")
    lines.append("**Memory per worker** (one worker; movies of 512 x 512 frames; a whole 40-frame movie as "
                 "float64 would be 80 MB):")
    lines.append("")
    lines.append("| frames per movie | worker warmed up (MB) | worker peak (MB) | time per movie (s) |")
    lines.append("|---:|---:|---:|---:|")
    for n_frames, r in memory.items():
        lines.append(f"| {n_frames} | {r['warm_mb']:.0f} | {r['peak_mb']:.0f} | {r['task_seconds']:.2f} |")
    per_task = two["wall"] * 2 / two["tasks"]  # dask's overhead included
    peak = two["peak_mb"]
    lines.append("")
    lines.append(f"**Estimate for 1000 movies of 30 frames** (256 x 256, one cell each), from {per_task:.2f} s "
                 f"per movie per worker (measured on 2 workers) and {peak:.0f} MB peak per worker:")
    lines.append("")
    lines.append("| workers | time | time on idle cores (CPU time per movie) | memory (workers) |")
    lines.append("|---:|---:|---:|---:|")
    for n in (2, 8, 32, 128):
        seconds = 1000 * per_task / n
        idle = 1000 * (two["cpu_per_task"] + two["client_cpu_per_task"]) / n
        lines.append(f"| {n} | {_duration(seconds)} | {_duration(idle)} | {n * peak / 1024:.1f} GB |")
    print("\n".join(lines))
    if args.write:
        print(f"wrote {write_section('batch', lines, 'Benchmark', doc='batch.md')}")


if __name__ == "__main__":
    main()

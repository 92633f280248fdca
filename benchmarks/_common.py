"""What both benchmarks need: a median timer and a description of the machine."""

from __future__ import annotations

import os
import platform
import statistics
import time

import numpy as np


def timed(fn, repeat: int = 1):
    """``(result of the last call, median seconds over repeat calls)``."""
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def machine() -> str:
    """CPU model, cores, Python and numpy versions, for the tables' headers."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}"

"""What both benchmarks need: a median timer and a description of the machine."""

from __future__ import annotations

import os
import platform
import statistics
import time
from pathlib import Path

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


def report():
    """``(lines, out)``: ``out(s)`` prints ``s`` at once and keeps it in ``lines`` (for ``write_section``)."""
    lines = []

    def out(s=""):
        print(s, flush=True)
        lines.append(s)

    return lines, out


def write_section(name: str, lines, heading: str, doc: str = "benchmarks.md") -> Path:
    """Put ``lines`` into ``docs/<doc>`` between ``<!-- name:start -->`` and
    ``<!-- name:end -->``, replacing what was there, or append them under
    ``## heading`` the first time; the file's path."""
    doc = Path(__file__).resolve().parents[1] / "docs" / doc
    text = doc.read_text() if doc.exists() else "# Benchmarks\n"
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = start + "\n" + "\n".join(lines) + "\n" + end
    if start in text:
        text = text[: text.index(start)] + block + text[text.index(end) + len(end):]
    else:
        text = text.rstrip() + f"\n\n## {heading}\n\n" + block + "\n"
    doc.write_text(text)
    return doc

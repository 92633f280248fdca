"""What the benchmarks and the demo share: a median timer, a description of the machine, the
docs' sections, and the tracking figures and scores both draw."""

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


def write_section_with_figure(name: str, lines, heading: str, draw, image: str, alt: str) -> Path:
    """:func:`write_section` of ``lines`` and, under them, the figure that
    ``draw(path)`` makes at ``docs/images/<image>`` (``alt``: its text)."""
    draw(Path(__file__).resolve().parents[1] / "docs" / "images" / image)
    return write_section(name, [*lines, "", f"![{alt}](images/{image})"], heading)


def normal_velocity_errors(movie, result, k: int = 0) -> np.ndarray:
    """|tracked - true| normal velocity (px/frame) of every node of object ``k`` of a tracking
    ``result`` of a synthetic ``movie`` (``napari_physeg.data.deforming_cell``), each node
    against the nearest true material point, frames 1 on."""
    errors = []
    for t in range(1, len(movie.frames)):
        c = result.contours[k][t]
        nearest = np.argmin(((c[:, None] - movie.outlines[t][None]) ** 2).sum(-1), axis=1)
        errors.append(np.abs(result.normal_velocity[k][t] - movie.normal_velocity[t][nearest]))
    return np.concatenate(errors)


def plot_membrane_maps(fig, axes, result, k: int, n_arc: int = 200) -> None:
    """Object ``k``'s protrusion/retraction and curvature maps (arc position from the carried
    origin x frame) on the two ``axes`` of ``fig``, each scaled to its 98th percentile."""
    for ax, quantity, cmap, label in ((axes[0], "normal_velocity", "RdBu_r", "normal velocity (px/frame)"),
                                      (axes[1], "curvature", "PiYG", "curvature (1/px)")):
        image = result.membrane_map(k, quantity, n_arc=n_arc)
        lim = max(float(np.nanpercentile(np.abs(image), 98)), 1e-6) if np.isfinite(image).any() else 1.0
        im = ax.imshow(image.T, aspect="auto", cmap=cmap, vmin=-lim, vmax=lim, origin="lower",
                       extent=(-0.5, image.shape[0] - 0.5, 0, 1))
        ax.set_xlabel("frame")
        ax.set_ylabel("arc position (carried origin)")
        fig.colorbar(im, ax=ax, label=label)

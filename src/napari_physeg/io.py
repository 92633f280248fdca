"""Contours in napari's shapes CSV format, without napari.

napari saves a Shapes layer as a CSV table with the columns
``index, shape-type, vertex-index, axis-0, axis-1[, axis-2, ...]`` (one row per
vertex). :func:`read_shapes_csv` reads that (or a plain two-column
``row, col`` table) and :func:`write_shapes_csv` writes it, so contours move
between napari, scripts and the command line unchanged.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

__all__ = ["read_shapes_csv", "write_shapes_csv"]


def read_shapes_csv(path, *, leading: bool = False):
    """Read the shapes in a CSV file as a list of ``(N, 2)`` float64 contours.

    Accepts napari's shapes CSV (for nD shapes the last two axes are kept) or
    a table whose last two columns are ``row, col`` (one shape, an optional
    header).

    With ``leading=True`` also return, per shape, the coordinates of its
    first vertex on the axes before the last two (e.g. ``(frame,)`` for a
    shape drawn on one frame of a movie; ``()`` for 2D shapes).

    Raises
    ------
    ValueError
        If the file holds no shape or its columns cannot be read.
    """
    path = Path(path)
    with path.open(newline="") as fh:
        rows = [r for r in csv.reader(fh) if r and any(c.strip() for c in r)]
    if not rows:
        raise ValueError(f"{path} is empty: expected napari's shapes CSV or 'row,col' lines")
    header = [c.strip() for c in rows[0]]
    try:
        if "index" in header and "axis-0" in header:
            axes = sorted((c for c in header if c.startswith("axis-")), key=lambda c: int(c[5:]))
            cols = [header.index(a) for a in axes]
            index = header.index("index")
            table = [(int(float(r[index])), [float(r[c]) for c in cols]) for r in rows[1:]]
            shapes: dict[int, list] = {}
            for i, xy in table:
                shapes.setdefault(i, []).append(xy)
            full = [np.asarray(v, dtype=np.float64) for _, v in sorted(shapes.items())]
            out = [v[:, -2:] for v in full]
            before = [tuple(v[0, :-2]) for v in full]
        else:
            try:
                [float(c) for c in rows[0][-2:]]
                body = rows
            except ValueError:  # a header line
                body = rows[1:]
            out = [np.asarray([[float(r[-2]), float(r[-1])] for r in body], dtype=np.float64)]
            before = [()]
    except (ValueError, IndexError) as err:
        raise ValueError(f"could not read contours from {path}: {err}") from None
    if not out or all(len(s) == 0 for s in out):
        raise ValueError(f"{path} holds no shape")
    return (out, before) if leading else out


def write_shapes_csv(path, shapes, shape_type: str = "polygon", leading=None) -> Path:
    """Write contours as napari's shapes CSV (polygons), readable by napari.

    ``leading``, one tuple per shape (e.g. ``(frame,)``), puts each shape on
    a slice of an nD layer: its values become the first axes.
    """
    path = Path(path)
    n_lead = len(leading[0]) if leading else 0
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["index", "shape-type", "vertex-index"] + [f"axis-{a}" for a in range(n_lead + 2)])
        for i, shape in enumerate(shapes):
            lead = [repr(float(v)) for v in leading[i]] if leading else []
            for k, (r, c) in enumerate(np.asarray(shape, dtype=np.float64)):
                w.writerow([i, shape_type, k, *lead, repr(float(r)), repr(float(c))])
    return path

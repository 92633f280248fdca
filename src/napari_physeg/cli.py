"""Command line for batch work: ``napari-physeg segment IMAGE --init CONTOUR.csv --out RESULT.csv``.

Contours are read and written in napari's shapes CSV format (File > Save
Selected Layer in napari), so a contour drawn in napari can be segmented in a
batch job and the result opened back in napari.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from .io import read_shapes_csv, write_shapes_csv

EPILOG = """examples:
  napari-physeg segment cells.tif --init rough.csv --out cells.csv
  napari-physeg track movie.tif --init frame0.csv --out tracked/
  napari-physeg segment photo.png --channel 1 --init rough.csv --out result.csv \\
      --material copper --stiffness 1e6 --mask result-mask.png

The initial contour CSV is napari's shapes format (columns index, shape-type,
vertex-index, axis-0, axis-1; every shape is segmented) or a plain 'row,col'
table. Exit status: 0 on success, 2 for bad input (with a message saying what
to fix), 1 when a run did not converge or diverged (track: an object was lost).

track writes OUT/contours.csv (one polygon per object and frame, the frame as
axis-0: open it in napari over the stack) and OUT/tracks.parquet (or .csv
without pyarrow): object, frame, node, row, col, arc, normal_velocity,
curvature, status.
"""


def _load_image(path: Path, channel: int | None) -> np.ndarray:
    from skimage import io

    try:
        image = io.imread(path)
    except Exception as err:  # unreadable file: say so plainly
        raise ValueError(f"could not read image {path}: {err}") from None
    if channel is not None:
        if image.ndim != 3:
            raise ValueError(f"--channel given but {path} has shape {image.shape}, not (rows, cols, channels)")
        if not 0 <= channel < image.shape[-1]:
            raise ValueError(f"--channel {channel} out of range: {path} has {image.shape[-1]} channels")
        image = image[..., channel]
    return image


def _segment(args) -> int:
    from .core import MATERIALS, segment

    if args.material not in MATERIALS:
        raise ValueError(f"unknown --material {args.material!r}; choose from {', '.join(sorted(MATERIALS))}")
    image = _load_image(args.image, args.channel)
    shapes = read_shapes_csv(args.init)
    results, status = [], 0
    for k, init in enumerate(shapes):
        t0 = time.perf_counter()
        res = segment(image, init, material=args.material, stiffness=args.stiffness, n_nodes=args.n_nodes,
                      sigma_factor=args.sigma_factor, max_steps=args.max_steps)
        results.append(res.contour)
        state = "converged" if res.converged else f"stopped ({res.stop_reason})"
        print(f"shape {k}: {res.n_nodes} nodes, {res.steps} steps, {state}, "
              f"{(time.perf_counter() - t0) * 1e3:.0f} ms")
        status = status or (0 if res.converged else 1)
    write_shapes_csv(args.out, results)
    print(f"wrote {args.out}")
    if args.mask:
        from skimage import io

        from .core.contour import polygon_mask

        labels = np.zeros(image.shape[:2], dtype=np.uint16)
        for k, c in enumerate(results, start=1):
            labels[polygon_mask(c, labels.shape)] = k
        io.imsave(args.mask, labels, check_contrast=False)
        print(f"wrote {args.mask}")
    return status


def _load_stack(path: Path):
    """A (T, H, W) stack, lazily when it can be: a zarr array, or a TIFF read
    through a memory map when uncompressed."""
    if path.suffix == ".zarr" or path.is_dir():
        try:
            import zarr
        except ImportError:
            raise ValueError(f"{path} looks like a zarr store: pip install zarr to read it") from None
        stack = zarr.open(str(path), mode="r")
    else:
        import tifffile

        try:
            stack = tifffile.memmap(path, mode="r")
        except Exception:  # compressed or not memory-mappable: read it whole
            try:
                stack = tifffile.imread(path)
            except Exception as err:
                raise ValueError(f"could not read the stack {path}: {err}") from None
    if len(stack.shape) != 3:
        raise ValueError(f"{path} has shape {tuple(stack.shape)}; track needs a (frames, rows, cols) stack")
    return stack


class _ProgressBar:
    """A one-line text progress bar on stderr."""

    def __init__(self, width: int = 30):
        self.width = width

    def __call__(self, progress) -> None:
        done = progress.done / progress.total
        bar = "#" * int(round(done * self.width))
        print(f"\r[{bar:<{self.width}}] frame {progress.frame}, {progress.done}/{progress.total} object-frames",
              end="", file=sys.stderr, flush=True)
        if progress.done == progress.total:
            print(file=sys.stderr)


def _track(args) -> int:
    from .core import LOST, MATERIALS, track

    if args.material not in MATERIALS:
        raise ValueError(f"unknown --material {args.material!r}; choose from {', '.join(sorted(MATERIALS))}")
    stack = _load_stack(args.stack)
    inits, leading = read_shapes_csv(args.init, leading=True)
    frames_drawn = {int(round(lead[0])) for lead in leading if lead}
    if args.start is not None:
        start = args.start
    elif len(frames_drawn) > 1:
        raise ValueError(f"the contours of {args.init} lie on frames {sorted(frames_drawn)}: draw them all on one "
                         "frame, or say which with --start")
    else:
        start = frames_drawn.pop() if frames_drawn else 0
    tr = track(stack, inits, start=start, segment_options=dict(material=args.material, stiffness=args.stiffness),
               callback=_ProgressBar())
    args.out.mkdir(parents=True, exist_ok=True)
    shapes, frames = [], []
    for k in range(tr.n_objects):
        for t, c in enumerate(tr.contours[k]):
            if c is not None:
                shapes.append(c)
                frames.append((t,))
    write_shapes_csv(args.out / "contours.csv", shapes, leading=frames)
    table = tr.table()
    try:
        table.to_parquet(args.out / "tracks.parquet")
        written = "tracks.parquet"
    except ImportError:  # no pyarrow
        table.to_csv(args.out / "tracks.csv", index=False)
        written = "tracks.csv"
    for k in range(tr.n_objects):
        counts = {s: tr.status[k].count(s) for s in dict.fromkeys(tr.status[k])}
        print(f"object {k}: " + ", ".join(f"{n} {s}" for s, n in counts.items()))
    print(f"wrote {args.out / 'contours.csv'} and {args.out / written} ({tr.timings['total']:.1f} s)")
    return 1 if any(LOST in row for row in tr.status) else 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="napari-physeg",
        description="Physical deformable contours: segment objects in images from rough initial contours.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True)
    seg = sub.add_parser("segment", help="segment the object(s) around initial contour(s)",
                         description="Drive each initial contour onto the border of the object it surrounds.",
                         epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    seg.add_argument("image", type=Path, help="2D grey image (any format scikit-image reads)")
    seg.add_argument("--init", type=Path, required=True, help="initial contour(s), napari shapes CSV")
    seg.add_argument("--out", type=Path, required=True, help="where to write the result (napari shapes CSV)")
    seg.add_argument("--channel", type=int, default=None, help="channel of an RGB(A) image to use (0, 1, 2)")
    seg.add_argument("--material", default="rubber", help="virtual material (rubber, soft tissue, aluminium, "
                     "copper, steel); default rubber")
    seg.add_argument("--stiffness", type=float, default=2000.0,
                     help="stiffness constant r in N/m (rubber ~2e3, copper ~1e6); default 2000")
    seg.add_argument("--n-nodes", type=int, default=None, help="nodes of the model (default: one per ~3 px)")
    seg.add_argument("--sigma-factor", type=float, default=1.0,
                     help="node interaction relative to the node spacing, 0.75-1.5; default 1")
    seg.add_argument("--max-steps", type=int, default=1000, help="upper bound on time steps; default 1000")
    seg.add_argument("--mask", type=Path, default=None, help="also write a label image (one label per shape)")
    seg.set_defaults(run=_segment)
    trk = sub.add_parser("track", help="follow the object(s) of initial contour(s) through a time-lapse",
                         description="Segment each object frame by frame from the contours drawn on one frame, "
                         "forward and backward, with node correspondences and membrane velocities.",
                         epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    trk.add_argument("stack", type=Path, help="(frames, rows, cols) TIFF stack or zarr array")
    trk.add_argument("--init", type=Path, required=True,
                     help="contour(s) drawn on one frame, napari shapes CSV (with the frame as axis-0, or 2D)")
    trk.add_argument("--out", type=Path, required=True, help="output folder: contours.csv and the tidy table")
    trk.add_argument("--start", type=int, default=None, help="the frame the contours were drawn on "
                     "(default: their axis-0, else 0)")
    trk.add_argument("--material", default="rubber", help="virtual material; default rubber")
    trk.add_argument("--stiffness", type=float, default=2000.0, help="stiffness constant r in N/m; default 2000")
    trk.set_defaults(run=_track)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except ValueError as err:
        print(f"napari-physeg: error: {err}", file=sys.stderr)
        return 2
    except RuntimeError as err:  # DivergenceError
        print(f"napari-physeg: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

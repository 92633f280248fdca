"""Command line: every step of the widgets, and batches of files on dask.

``napari-physeg segment | match | simulate | track | batch {segment,track}``.
Contours are read and written in napari's shapes CSV format (File > Save
Selected Layer in napari), so a contour drawn in napari can be processed in a
script and the result opened back in napari.

Every path and option is checked before any work starts; a problem ends the
command with exit status 2 and one line saying what to fix. The options'
defaults are the core functions' own (read from their signatures), so the
command line, the widgets and scripts behave alike.
"""

from __future__ import annotations

import argparse
import contextlib
import inspect
import logging
import signal
import sys
import warnings
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from .io import TIFF_SUFFIXES, is_zarr, open_stack, parse_frames, read_shapes_csv, same_file, write_shapes_csv

PROG = "napari-physeg"

EPILOG = """examples:
  napari-physeg segment cells.tif --init rough.csv --out cells.csv
  napari-physeg segment movie.tif --frames 0:10 --init rough.csv --out cells.csv --material copper --stiffness 1e6
  napari-physeg match hands.csv --out pairs.csv --method global
  napari-physeg simulate open.csv closed.csv --out frames.csv --q 30000 --n-frames 10
  napari-physeg track movie.tif --init frame0.csv --out tracked/
  napari-physeg batch track plate/*.tif --init frame0.csv --out plate-tracks/ --workers 8

Contours are napari's shapes CSV (File > Save Selected Layer: columns index,
shape-type, vertex-index, axis-0, axis-1, ...; polygons, rectangles, paths and
ellipses) or a plain 'row,col' table (one contour, or one per object with an
'id' column before the coordinates). Exit status: 0 on success, 2 for bad
input (one line saying what to fix; nothing is written), 1 when a run did not
converge or diverged (segment: a contour failed, named on stderr, the others
written; track, batch track: an object was lost; batch: a task failed).
"""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (no usage block) and exit status 2."""

    def error(self, message):
        self.exit(2, f"{PROG}: error: {message} (see {self.prog} --help)\n")


def _defaults(func) -> dict:
    """The core function's defaults: the one set the widgets and the CLI read."""
    return {name: p.default for name, p in inspect.signature(func).parameters.items()
            if p.default is not inspect.Parameter.empty}


def _path(text: str) -> Path:
    """A path argument: Path("") is the current folder, so an empty --out (a
    shell variable left unset) would have written there."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path: name the file or folder")
    return Path(text)


def _number(kind, low=None, low_open=False, high=None, why=""):
    """An argparse type: a number of ``kind`` above ``low`` and at most ``high`` (``why``: the reason for them)."""
    def parse(text):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {'whole ' if kind is int else ''}number") from None
        if low is not None and (value <= low if low_open else value < low) or not np.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} must be {'>' if low_open else '>='} {low:g}{why}")
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f"{text!r} must be <= {high}{why}")
        return value
    return parse


def _weights(text):
    """``edges=0.4,intensity=0.3`` -> dict."""
    from .core.forces import FORCE_NAMES

    out = {}
    for part in text.split(","):
        name, _, value = part.partition("=")
        name = name.strip()
        if name not in FORCE_NAMES or not value:
            raise argparse.ArgumentTypeError(f"{part!r}: expected name=weight with a name among "
                                             f"{', '.join(FORCE_NAMES)}")
        out[name] = _number(float, 0.0)(value)
    return out


# --------------------------------------------------------------------------
# Options shared by several subcommands
# --------------------------------------------------------------------------


def _add_segment_options(p, *, spacing: bool = True, max_steps: bool = True) -> None:
    from .core import segment
    from .core.forces import DEFAULT_WEIGHTS
    from .core.materials import suggested_stiffness
    from .core.segmentation import MAX_NODES, MAX_SIGMA_FACTOR, MIN_NODE_SPACING

    d = _defaults(segment)
    g = p.add_argument_group("contour model (the Segmentation widget's options; defaults are segment()'s)")
    _add_material_options(g, "the contour", d["material"], "Soft materials move fast and follow details; stiff "
                          "metals keep the contour smooth and need a larger --stiffness")
    g.add_argument("--stiffness", type=_number(float, 0, True), metavar="R",
                   help=f"stiffness constant r (N/m) scaling the image forces: force on a node = r x its feature "
                   f"force; default: the one that suits --material ({suggested_stiffness(d['material']):g} for "
                   f"{d['material']}, 1e6 for copper, see core.materials.SUGGESTED_STIFFNESS); too low and the "
                   "contour barely moves, far too high and it may diverge")
    nodes = g.add_mutually_exclusive_group()
    # segment() takes at most MAX_NODES (5000) nodes: every step costs ~n^2.6 (4000 nodes took 13 s on
    # a 30-px object, a 0.01-px spacing typed for 1 never ended). As in the widgets.
    if spacing:
        nodes.add_argument("--node-spacing", type=_number(float, MIN_NODE_SPACING,
                                                          why=" (closer nodes resolve nothing more)"),
                           metavar="PX", help="distance between nodes in pixels, typically 2-5, at least "
                           f"{MIN_NODE_SPACING:g}, kept as the contour grows or shrinks; smaller follows finer detail "
                           "but is slower (default: one node per ~3 px); a spacing that would give a contour more "
                           f"than {MAX_NODES} nodes gives it {MAX_NODES}, with a warning")
    nodes.add_argument("--n-nodes", type=_number(int, 3, high=MAX_NODES, why=" (each step costs ~n^2.6)"),
                       metavar="N", help=f"number of nodes of each initial contour instead, typically 50-500, at "
                       f"most {MAX_NODES}")
    g.add_argument("--sigma-factor", type=_number(float, 0, True, high=MAX_SIGMA_FACTOR), metavar="F",
                   help=f"width of the interaction between nodes relative to the node spacing, 0.75-1.5 (max "
                   f"{MAX_SIGMA_FACTOR:g}); "
                   f"larger: smoother, stiffer contour; default {d['sigma_factor']:g}")
    g.add_argument("--weights", type=_weights, metavar="NAME=W,...",
                   help="image forces and their weights, e.g. "
                   + ",".join(f"{k}={v:g}" for k, v in DEFAULT_WEIGHTS.items())
                   + " (the default): edges (Shen-Castan edges pull nodes onto the border), intensity (region: "
                   "pushes nodes out of the object's intensity), distance (pulls toward the nearest edge from "
                   "afar); a force left out or weighted 0 is off")
    g.add_argument("--polarity", help=f"the object is 'bright' or 'dark' on its background, or 'auto' (read from "
                   f"the initial contour: its middle, its line and rings outside it); default {d['polarity']}")
    g.add_argument("--contrast", help="what tells the object from its background: 'intensity' (fluorescence, "
                   "stains), 'texture' (flat cells in phase contrast or bright field), or 'auto' (read from the "
                   f"initial contour; 'intensity' with --polarity bright or dark); default {d['contrast']}")
    if max_steps:
        g.add_argument("--max-steps", type=_number(int, 1), metavar="N",
                       help=f"upper bound on time steps per contour; default {d['max_steps']}")


def _add_material_options(g, of: str, default: str, advice: str) -> None:
    """--material and the custom material's constants (--young, --poisson, --density)."""
    from .core import MATERIALS

    g.add_argument("--material", help=f"virtual material of {of}: {', '.join(MATERIALS)}; default {default}. "
                   + advice)
    g.add_argument("--young", type=_number(float, 0, True), metavar="MPA",
                   help="a custom material: Young's modulus E in MPa instead of the --material preset's (rubber "
                   "~100, soft tissue ~0.1, copper ~117000); higher E: a stiffer, smoother, slower contour")
    g.add_argument("--poisson", type=float, metavar="NU", help="a custom material: Poisson's ratio nu instead "
                   "of the preset's, typically 0.25-0.49 (rubber 0.49, metals ~0.3)")
    g.add_argument("--density", type=_number(float, 0, True), metavar="RHO", help="a custom material: mass "
                   "density in kg/m^3 instead of the preset's, typically 1000-9000 (rubber 1100, copper 8960)")


def _material_option(args, default: str):
    """The --material given (a name), a custom Material made of it (or of ``default``) and
    --young, --poisson, --density, or None when none of them is given."""
    from .core import get_material

    changes = {name: value for name, value in (("young", args.young and args.young * 1e6),
                                               ("poisson", args.poisson), ("density", args.density))
               if value is not None}
    if not changes:
        return args.material
    preset = get_material(args.material or default)
    return preset.with_(name=f"custom ({preset.name})", **changes)


def _segment_options(args) -> dict:
    """The segment() options given on the command line (the others keep the
    core's defaults), checked as segment() would before any image is read."""
    from .core.segmentation import check_segment_options

    from .core import segment

    opts = {name: getattr(args, name)
            for name in ("stiffness", "n_nodes", "sigma_factor", "polarity", "contrast", "max_steps")
            if getattr(args, name, None) is not None}
    material = _material_option(args, _defaults(segment)["material"])
    if material is not None:
        opts["material"] = material
    if args.weights is not None:
        opts["forces"] = tuple(k for k, w in args.weights.items() if w > 0)
        opts["weights"] = {k: args.weights[k] for k in opts["forces"]}
        if not opts["forces"]:
            raise ValueError("--weights turns every force off: give at least one a positive weight")
    check_segment_options(**opts)
    return opts


def _add_match_options(p, title: str, *, method: bool = True) -> None:
    from .core import match
    from .core.matching import METHODS

    d = _defaults(match)
    g = p.add_argument_group(title)
    if method:  # track() matches consecutive contours with "order" itself
        g.add_argument("--method", choices=METHODS, help=f"how correspondences are chosen: order (order-preserving, "
                       f"dynamic programming), global (one-to-one assignment), local (mutual best matches "
                       f"only); default {d['method']}")
    g.add_argument("--n-modes", type=_number(int, 1), metavar="N", help="vibration modes in the modal affinity "
                   "(eq. 12); fewer: coarser and more robust, more: finer (default: automatic, 6 to 12)")


def _match_options(args) -> dict:
    return {name: getattr(args, name) for name in ("method", "n_modes") if getattr(args, name, None) is not None}


def _add_io(p, *, out_help: str, init: bool = True) -> None:
    if init:
        p.add_argument("--init", type=_path, required=True, metavar="CONTOURS.csv",
                       help="initial contour(s): napari shapes CSV (polygon, rectangle, path or ellipse; nD "
                       "shapes use their last two axes; a Points layer's CSV: each point a click) or a "
                       "'row,col' table (an 'id,row,col' table: one contour per id, one row a click)")
    p.add_argument("--out", type=_path, required=True, help=out_help)
    p.add_argument("--overwrite", action="store_true", help="replace existing output (never an input file)")


def _check_input(path: Path, what: str, *, image: bool = False) -> None:
    """Refuse an input that is missing, or a folder where a file is expected (an image may be a
    zarr store): a plain sentence, not open()'s [Errno 21]."""
    if not path.exists():
        raise ValueError(f"{what} {path} does not exist")
    if path.is_dir() and not (image and is_zarr(path)):
        kind = "an image or a zarr store" if image else "a CSV file"
        raise ValueError(f"{what} {path} is a folder, not {kind}: give a file in it"
                         + (f" (e.g. {path / '*.tif'})" if image else ""))


def _check_output(path: Path, args, inputs, *, folder: bool = False, writes=(), what: str = "--out") -> None:
    """Refuse an output that is an input, that exists (without --overwrite) or
    that cannot be written: before any work, not after it. ``writes``: the files
    written in the folder ``path``, none of which may be an input either (even
    with --overwrite: the input would be lost)."""
    from .batch import check_writable

    for source in (Path(s) for s in inputs if s is not None):
        if not source.exists():
            continue
        if same_file(path, source):
            raise ValueError(f"{what} {path} is also an input: write the result elsewhere")
        clash = next((path / name for name in writes if same_file(path / name, source)), None)
        if clash is not None:
            raise ValueError(f"{what} {path} would replace the input {source} (the result's {clash.name} is "
                             f"written there): choose another {what} folder, or move the input")
    # A file where a folder goes (or the reverse) first: --overwrite would not help.
    check_writable(path, folder=folder)
    # A device or a pipe (--out /dev/null) is written into, not replaced: no --overwrite needed.
    exists = path.is_dir() and any(path.iterdir()) if folder else path.is_file()
    if exists and not args.overwrite:
        raise ValueError(f"{path} exists: pass --overwrite to replace it, or choose another {what}")


def _check_csv_out(path: Path, more: str = "") -> None:
    """Refuse an --out named as an image: the result is CSV text, which such a name would hide."""
    if path.suffix.lower() in (*TIFF_SUFFIXES, ".png", ".jpg", ".jpeg"):
        raise ValueError(f"--out {path}: the result is written as CSV text: name it .csv{more}")


def _read_contours(path: Path, what: str = "--init", leading: bool = False):
    _check_input(path, what)
    return read_shapes_csv(path, leading=leading)


# --------------------------------------------------------------------------
# segment
# --------------------------------------------------------------------------


def _segment(args) -> int:
    from .batch import check_contours

    _check_input(args.image, "image", image=True)
    shapes, leading = _read_contours(args.init, leading=True)
    _check_output(args.out, args, [args.image, args.init])
    _check_csv_out(args.out, " (--mask writes the label image)")
    if args.mask:
        # --out need not exist yet, so _check_output's test against inputs cannot see this clash.
        if same_file(args.mask, args.out):
            raise ValueError(f"--mask {args.mask} is the same file as --out: give the label image another name "
                             "(e.g. labels.tif)")
        _check_output(args.mask, args, [args.image, args.init], what="--mask")
        if args.mask.suffix.lower() not in (*TIFF_SUFFIXES, ".png"):
            raise ValueError(f"--mask {args.mask}: labels are 16-bit integers, which a TIFF or a PNG holds: name it "
                             ".tif or .png")
    options = _segment_options(args)
    with open_stack(args.image, channel=args.channel) as stack:
        jobs, is_stack = _segment_jobs(args, len(stack), leading, len(shapes))
        check_contours(shapes, stack.shape[1:], args.init)
        if args.mask and is_stack and args.mask.suffix.lower() not in TIFF_SUFFIXES:
            raise ValueError(f"--mask {args.mask}: the labels of a stack are a stack, which only a TIFF holds: "
                             "name it .tif")
        done, failed = _run_segment_jobs(stack, jobs, shapes, options, args.node_spacing, is_stack)
        shape = (len(stack), *stack.shape[1:]) if is_stack else tuple(stack.shape[1:])
    if not done:
        print(f"{PROG}: no contour was segmented: nothing written", file=sys.stderr)
        return 1
    results, frames = [res.contour for _, _, res in done], [(t,) for t, _, _ in done]
    # The input shape each result is of: a contour that failed leaves no row, so the index alone does not say.
    write_shapes_csv(args.out, results, leading=frames if is_stack else None,
                     columns={"object": [k for _, k, _ in done]})
    left_out = f" ({len(done)} of {len(jobs)} contours, without the {failed} that failed)" if failed else ""
    print(f"wrote {args.out}{left_out}")
    if args.mask:
        _write_mask(args.mask, [(t, k, res.contour) for t, k, res in done], shape)
        print(f"wrote {args.mask}")
    return 1 if failed or not all(res.converged for _, _, res in done) else 0


def _run_segment_jobs(stack, jobs, shapes, options, node_spacing, is_stack):
    """Segment shape ``k`` on frame ``t`` for each ``(t, k)`` of ``jobs``, a frame read at a time.

    A shape that fails (it collapsed, diverged, the frame is blank) is named on stderr and the
    others go on, as in a batch task: one bad drawing must not lose the rest.

    Returns
    -------
    done : list of (int, int, SegmentationResult)
        ``(t, k, result)`` of the shapes segmented, in frame order.
    failed : int
        The number of jobs that failed.
    """
    from .batch import segment_options_for
    from .core import segment

    done, failed = [], 0
    for t in sorted({t for t, _ in jobs}):
        image = np.asarray(stack[t], dtype=np.float64)  # one frame at a time
        for k in (k for frame, k in jobs if frame == t):
            where = f"frame {t}, " if is_stack else ""
            try:
                with _named_warnings(f"{where}shape {k}: "):
                    res = segment(image, shapes[k], **segment_options_for(shapes[k], options, node_spacing))
            except (ValueError, RuntimeError) as err:  # ValueError: collapsed, blank frame; RuntimeError: diverged
                print(f"{PROG}: {where}shape {k} failed: {' '.join(str(err).split())}", file=sys.stderr, flush=True)
                failed += 1
                continue
            state = "converged" if res.converged else f"stopped ({res.stop_reason})"
            print(f"{where}shape {k}: {len(res.contour)} nodes, {res.steps} steps, {state}, "
                  f"{res.timings['total'] * 1e3:.0f} ms", flush=True)
            if not res.converged:  # written, but the exit status says a run failed: say which on stderr
                print(f"{PROG}: {where}shape {k} did not converge ({res.stop_reason}); its contour is written "
                      "as it stopped", file=sys.stderr, flush=True)
            done.append((t, k, res))
    return done, failed


@contextlib.contextmanager
def _named_warnings(prefix: str):
    """Warnings raised inside, re-raised with ``prefix`` (which shape, which frame): segment()'s
    "3 of 64 nodes of init lie outside the image" named neither among several shapes."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        warnings.warn(f"{prefix}{w.message}", w.category, stacklevel=3)


def _segment_jobs(args, n_frames: int, leading, n_shapes: int):
    """``[(frame, shape)]`` to segment, and whether the output has a frame axis."""
    if args.frames is not None:
        return [(t, k) for t in parse_frames(args.frames, n_frames) for k in range(n_shapes)], n_frames > 1
    drawn = [int(round(lead[0])) if lead else None for lead in leading]
    if any(t is not None for t in drawn) and n_frames > 1:
        bad = [t for t in drawn if t is None or not 0 <= t < n_frames]
        if bad:
            raise ValueError(f"the contours of {args.init} lie on frames {sorted(set(map(str, drawn)))} but the "
                             f"image has frames 0 to {n_frames - 1}: choose frames with --frames")
        return [(t, k) for k, t in enumerate(drawn)], True
    if n_frames > 1:
        raise ValueError(f"{args.image} is a stack of {n_frames} frames: choose which with --frames (e.g. 0, 0:10 "
                         "or 2,5), or draw the contours on their frames in napari (the CSV's axis-0)")
    return [(0, k) for k in range(n_shapes)], False


def _write_mask(path: Path, contours, shape) -> None:
    """Write a label image of ``shape`` (2D, or frames x rows x cols): each ``(t, k, contour)`` filled
    with label ``k + 1`` on frame ``t``. Labelled by the shape's index, not the result's rank, so an
    object keeps its label on every frame (and when another shape failed)."""
    import tifffile
    from skimage import io

    from .core.contour import polygon_mask
    from .io import atomic_path

    labels = np.zeros(shape, dtype=np.uint16)
    for t, k, c in contours:
        plane = labels[t] if labels.ndim == 3 else labels
        plane[polygon_mask(c, plane.shape)] = k + 1
    with atomic_path(path) as tmp:
        if path.suffix.lower() in TIFF_SUFFIXES:  # minisblack: a stack of 3 or 4 frames is no RGB(A) image
            tifffile.imwrite(tmp, labels, photometric="minisblack")
        else:
            io.imsave(tmp, labels, check_contrast=False)


# --------------------------------------------------------------------------
# match and simulate
# --------------------------------------------------------------------------


def _pair(args):
    """Contours a and b: shape --a-shape of A and --b-shape of B (or of A)."""
    a_shapes = _read_contours(args.a, "contours")
    b_shapes = _read_contours(args.b, "contours") if args.b else a_shapes
    b_index = args.b_shape if args.b_shape is not None else (0 if args.b else 1)
    for shapes, index, path, opt in ((a_shapes, args.a_shape, args.a, "--a-shape"),
                                     (b_shapes, b_index, args.b or args.a, "--b-shape")):
        if not 0 <= index < len(shapes):
            raise ValueError(f"{opt} {index}: {path} holds {len(shapes)} shape(s), numbered from 0"
                             + ("; give a second file B, or two shapes in A" if not args.b and len(shapes) < 2
                                else ""))
    if b_shapes is a_shapes and b_index == args.a_shape:  # as the widgets refuse it
        raise ValueError(f"--a-shape and --b-shape are both shape {b_index} of {args.a}: a contour matched "
                         "with itself says nothing; choose another shape for b, or give a second file B")
    from .core.segmentation import drawing_nodes

    # A rectangle's 4 corners are a drawing, not the element's nodes.
    return drawing_nodes(a_shapes[args.a_shape]), drawing_nodes(b_shapes[b_index])


def _match(args) -> int:
    import csv

    from .core import match
    from .io import atomic_path

    a, b = _pair(args)
    _check_output(args.out, args, [args.a, args.b])
    _check_csv_out(args.out)
    m = match(a, b, **_match_options(args))
    cost = np.asarray(getattr(m, "cost", np.full(len(m.pairs), np.nan)))
    with atomic_path(args.out) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["node_a", "node_b", "row_a", "col_a", "row_b", "col_b", "cost"])
        for (i, j), c in zip(m.pairs, cost):
            w.writerow([int(i), int(j), *map(float, a[i]), *map(float, b[j]), float(c)])
    print(f"{len(m.pairs)} pairs ({m.method}): {len(m.pairs)} of {len(a)} nodes of a matched, "
          f"{len(m.unmatched)} unmatched; wrote {args.out}")
    return 0


def _simulate(args) -> int:
    from .core import get_material, match, simulate

    a, b = _pair(args)
    _check_output(args.out, args, [args.a, args.b])
    _check_csv_out(args.out)
    options = {name: getattr(args, name) for name in ("q", "n_frames", "max_steps") if getattr(args, name) is not None}
    material = _material_option(args, _defaults(simulate)["material"])
    if material is not None:
        options["material"] = get_material(material)  # a misspelt material: before matching
    sim = simulate(a, b, match(a, b, **_match_options(args)), **options)
    write_shapes_csv(args.out, list(sim.frames), leading=[(t,) for t in range(len(sim.frames))])
    state = "came to rest" if sim.converged else "stopped before rest (raise --max-steps)"
    print(f"{len(sim.frames)} frames of {sim.frames.shape[1]} nodes, {sim.steps} steps, {state}; wrote {args.out} "
          "(the frame as axis-0)")
    return 0 if sim.converged else 1


# --------------------------------------------------------------------------
# track
# --------------------------------------------------------------------------


class _ProgressBar:
    """A one-line text progress bar on stderr; in a log (stderr not a
    terminal), a line each time the bar grows: a carriage return per
    object-frame made 672 updates of one run's log (an outside tester)."""

    #: Whether a bar is drawn on the current line of stderr (a message must start a new one).
    mid_line = False

    def __init__(self, width: int = 30):
        self.width = width
        self.shown = -1  # the bar's length last written to a log

    def __call__(self, progress) -> None:
        filled = int(round(progress.done / progress.total * self.width))
        text = (f"[{'#' * filled:<{self.width}}] frame {progress.frame}, {progress.done}/{progress.total} "
                "object-frames")
        if not sys.stderr.isatty():
            if filled != self.shown or progress.done >= progress.total:
                self.shown = filled
                print(text, file=sys.stderr, flush=True)
            return
        print(f"\r{text}", end="", file=sys.stderr, flush=True)
        _ProgressBar.mid_line = progress.done < progress.total
        if not _ProgressBar.mid_line:
            print(file=sys.stderr)


def _new_line() -> str:
    """A line break if a progress bar is drawn on stderr's current line (a message then starts a line
    of its own, not glued to the bar), else nothing."""
    if not _ProgressBar.mid_line:
        return ""
    _ProgressBar.mid_line = False
    return "\n"


#: The core's advice names its Python parameters; the command line's user has options instead.
_CLI_TERMS = {
    "TrackingResult.reason (the table's reason column)": "The reason column of OUT/tracks.csv",
    "the segment_options (e.g. max_steps, material and stiffness)": "--steps-per-frame, --material or --stiffness",
    "or pass a Material": "or make one with --young, --poisson and --density",
    "max_steps and segment_options of track()": "--steps-per-frame, --material or --stiffness",
}


def _in_cli_terms(message) -> str:
    """``message`` on one line, with the core's parameter names given as this program's options."""
    text = " ".join(str(message).split())
    for api, cli in _CLI_TERMS.items():
        text = text.replace(api, cli)
    return text


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line of the program's (not Python's file, line and source), on a line
    of its own when a progress bar is being drawn."""
    print(f"{_new_line()}{PROG}: warning: {_in_cli_terms(message)}", file=sys.stderr, flush=True)


def _start_frame(args, leading):
    from .batch import drawn_frame

    return args.start if args.start is not None else drawn_frame(leading, args.init)


def _track(args) -> int:
    from .batch import TRACK_FILES, track_file
    from .core import LOST

    _check_input(args.stack, "stack", image=True)
    inits, leading = _read_contours(args.init, leading=True)
    _check_output(args.out, args, [args.stack, args.init], folder=True, writes=TRACK_FILES)
    options = _segment_options(args)
    start = _start_frame(args, leading)
    # (track_file checks the frames and start before any work, and numbers the bar's frames as the stack's.)
    tr, frames, written = track_file(args.stack, inits, args.out, frames=args.frames, start=start,
                                     channel=args.channel, node_spacing=args.node_spacing,
                                     max_steps=args.steps_per_frame, match_options=_match_options(args),
                                     callback=_ProgressBar(), **options)
    for k in range(tr.n_objects):
        counts = {s: tr.status[k].count(s) for s in dict.fromkeys(tr.status[k])}
        first = tr.first_lost(k)
        print(f"object {k}: " + ", ".join(f"{n} {s}" for s, n in counts.items())
              + (f" (first lost on frame {frames[first[0]]}: {first[1]})" if first else ""))
    print(f"wrote {', '.join(str(p) for p in written if p.exists())} ({tr.timings['total']:.1f} s)")
    # A frame that could not be used stopped the run (its warning says which): what was done is written.
    return 1 if tr.stop_reason != "completed" or any(LOST in row for row in tr.status) else 0


# --------------------------------------------------------------------------
# batch
# --------------------------------------------------------------------------


def _batch(args) -> int:
    from . import batch

    for path in args.inputs:
        _check_input(path, "input", image=True)
    shapes, leading = _read_contours(args.init, leading=True)
    batch.check_inputs_kept(args.out, [*args.inputs, args.init])
    options = _segment_options(args)
    common = dict(channel=args.channel, node_spacing=args.node_spacing, workers=args.workers,
                  scheduler=args.scheduler, overwrite=args.overwrite, progress=not args.quiet, frames=args.frames)
    if args.kind == "segment":
        table = batch.segment_files(args.inputs, shapes, args.out, **common, **options)
    else:
        table = batch.track_files(args.inputs, shapes, args.out, start=_start_frame(args, leading),
                                  max_steps=args.steps_per_frame, match_options=_match_options(args),
                                  **common, **options)
    return _batch_report(table, args.out, args.inputs)


def _batch_report(summary, out, inputs) -> int:
    """The summary line, a line per input that failed (or whose objects were never found), the exit status:
    1 as for one file (a task failed; segment: a contour did not converge; track: an object was lost). Of
    this run's ``inputs`` only: the summary also keeps the rows of other inputs an earlier run into ``out``
    did (their failures made a run of good files exit 1, an outside tester)."""
    from . import batch

    table = summary[summary["input"].isin({str(Path(p).absolute()) for p in inputs})]
    earlier = len(summary) - len(table)
    counts = [f"{(table['status'] == batch.OK).sum()} of {len(table)} rows ok"]
    failed = (table["status"] == batch.FAILED).sum()
    if failed:
        counts.append(f"{failed} failed")
    if "lost" in table:  # tracking: objects lost on some frames, or found on none
        never = (table["status"] == batch.NOT_FOUND).sum()
        partly = ((table["status"] == batch.OK) & table["lost"].gt(0).fillna(False)).sum()
        counts += [f"{never} object(s) never found"] * bool(never) + [f"{partly} lost on some frames"] * bool(partly)
    else:  # segmentation: contours that did not come to rest on a border (see stop_reason)
        never = 0
        done = table[table["status"] == batch.OK]
        partly = int((~done["converged"].astype(bool)).sum()) if "converged" in done else 0
        counts += [f"{partly} did not converge"] * bool(partly)
    kept = f" (with {earlier} row(s) of other inputs an earlier run did)" if earlier else ""
    print(f"{', '.join(counts)}; summary in {out / 'summary.csv'}{kept}")
    bad = table[table["status"] != batch.OK]
    for _, row in bad.drop_duplicates(["input", "status"]).iterrows():
        named = str(row["input"]) in str(row["error"])  # e.g. "could not read FILE: ..."
        print(f"{row['status']}: {row['error'] if named else f'{row.input}: {row.error}'}", file=sys.stderr)
    return 1 if failed or never or partly else 0


# --------------------------------------------------------------------------
# The parser
# --------------------------------------------------------------------------


def _subparser(sub, name, help, description):
    return sub.add_parser(name, help=help, description=description, epilog=EPILOG,
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def _frames_option(p, what):
    p.add_argument("--frames", "--frame", dest="frames", metavar="FRAMES",
                   help=f"{what}: one frame (3), a range (0:10, stop excluded, ending at the last frame if the "
                   "stack is shorter, as in Python: 0:100 on movies of any length; 0:30:2 every other) or a list "
                   "(2,5,9)")


def _channel_option(p):
    p.add_argument("--channel", type=_number(int, 0), help="channel to use: of an RGB(A) image or movie (0 red, "
                   "1 green, 2 blue), or of the C axis of an ImageJ or OME TIFF hyperstack (e.g. T x C x Y x X)")


def _add_segment(sub):
    p = _subparser(sub, "segment", "segment the object(s) around initial contour(s)",
                   "Drive each initial contour onto the border of the object it surrounds (the Segmentation "
                   "widget). On a stack, each contour is segmented on the frame it was drawn on (the CSV's "
                   "axis-0) or on every frame of --frames.")
    p.add_argument("image", type=_path, help="2D image (TIFF, PNG, ... any format scikit-image reads), or a "
                   "(frames, rows, cols) TIFF stack or zarr array")
    _add_io(p, out_help="where to write the result: napari shapes CSV, one polygon per contour (and frame, "
            "as axis-0, on a stack)")
    _frames_option(p, "frames of a stack to segment every contour on")
    _channel_option(p)
    p.add_argument("--mask", type=_path, help="also write a label image: label k+1 for shape k of --init (0 is "
                   "the background), on every frame of a stack of labels for a stack")
    _add_segment_options(p)
    p.set_defaults(run=_segment)


def _add_pair_arguments(p):
    p.add_argument("a", type=_path, metavar="A.csv", help="napari shapes CSV holding contour a")
    p.add_argument("b", type=_path, nargs="?", metavar="B.csv",
                   help="napari shapes CSV holding contour b (default: A, its second shape)")
    p.add_argument("--a-shape", type=_number(int, 0), default=0, metavar="I",
                   help="which shape of A is contour a (0 = the first drawn); default 0")
    p.add_argument("--b-shape", type=_number(int, 0), metavar="J",
                   help="which shape of B is contour b; default 0 (1 when B is not given)")


def _add_match(sub):
    from .core import match

    p = _subparser(sub, "match", "match the nodes of two contours by modal analysis",
                   "Match the nodes of contour a to those of contour b (the Matching widget).")
    _add_pair_arguments(p)
    _add_io(p, init=False, out_help="CSV of the correspondences: node_a, node_b, row_a, col_a, row_b, col_b, "
            "cost (0 = a perfect match)")
    _add_match_options(p, f"matching (defaults are match()'s: method {_defaults(match)['method']})")
    p.set_defaults(run=_match)


def _add_simulate(sub):
    from .core import simulate

    d = _defaults(simulate)
    p = _subparser(sub, "simulate", "simulate the deformation of one contour into another",
                   "Match a to b (order-preserving by default), then pull each node of a toward its partner and "
                   "let the material deform (the Simulation widget). Writes one polygon per frame, the frame as "
                   "axis-0, to open in napari over a frame slider.")
    _add_pair_arguments(p)
    _add_io(p, init=False, out_help="napari shapes CSV of the frames (frame as axis-0)")
    g = p.add_argument_group("simulation (defaults are simulate()'s)")
    g.add_argument("--q", type=_number(float, 0, True), help=f"global stiffness constant q (N/m) of the forces "
                   f"pulling each node toward its partner (eq. 17); default {d['q']:g}. Larger: ends closer to b; "
                   "stiff materials need ~1e6-1e8")
    _add_material_options(g, "a", d["material"], "Soft materials follow b's details; stiff ones keep a's shape "
                          "smooth on the way and need a larger --q")
    g.add_argument("--n-frames", type=_number(int, 2), metavar="T",
                   help=f"frames written, a and the rest shape included; default {d['n_frames']}")
    g.add_argument("--max-steps", type=_number(int, 1), metavar="N",
                   help=f"upper bound on time steps; default {d['max_steps']}")
    _add_match_options(p, "matching used by the simulation")
    p.set_defaults(run=_simulate)


def _add_track_options(p):
    from .core import track

    d = _defaults(track)
    _frames_option(p, "frames to track (default all)")
    p.add_argument("--start", type=_number(int, 0), help="the frame the contours were drawn on (default: their "
                   "axis-0 in the CSV, else the first frame tracked)")
    _channel_option(p)
    p.add_argument("--steps-per-frame", type=_number(int, 1), metavar="N",
                   help=f"time steps per object and frame (each frame starts from the previous result); "
                   f"default {d['max_steps']}")
    _add_segment_options(p, max_steps=False)
    _add_match_options(p, "node correspondences between frames (order-preserving matching)", method=False)


def _add_track(sub):
    p = _subparser(sub, "track", "follow the object(s) of initial contour(s) through a time-lapse",
                   "Segment each object frame by frame from the contours drawn on one frame, forward and backward, "
                   "with node correspondences and membrane velocities (the Tracking widget). Writes OUT/contours.csv "
                   "(one polygon per object and frame, the frame as axis-0: open it in napari over the stack) and "
                   "OUT/tracks.csv (and tracks.parquet with pyarrow): object, frame, node, row, col, arc, "
                   "normal_velocity, curvature, status, reason (why an object is lost on a frame).")
    p.add_argument("stack", type=_path, help="(frames, rows, cols) TIFF stack or zarr array, read a frame at a time")
    _add_io(p, out_help="output folder (created): contours.csv and the tidy table")
    _add_track_options(p)
    p.set_defaults(run=_track)


def _add_batch(sub):
    p = _subparser(sub, "batch", "segment or track many files at once, on dask",
                   "Run segment or track over many files on a dask cluster. See napari-physeg batch segment --help.")
    kinds = p.add_subparsers(dest="kind", required=True, parser_class=_Parser)
    for kind, text in (("segment", "segment the same contours on every frame (or --frames) of every input"),
                       ("track", "track the same contours through every input movie")):
        q = _subparser(kinds, kind, text, text[0].upper() + text[1:] + ", each task on a worker of a dask "
                       "cluster: a local one (--workers) or an existing one (--scheduler). Writes OUT/summary.csv "
                       "(and summary.parquet with pyarrow), one row per input" + (", frame" if kind == "segment"
                       else "") + " and object with a status column (ok" + (", not found: on no frame"
                       if kind == "track" else "") + " or failed, with the error), and each task's contours "
                       "under OUT/results/. Run the same command again to resume: complete results are kept; "
                       "failed tasks, and inputs replaced since, are run again.")
        q.add_argument("inputs", type=_path, nargs="+", metavar="INPUT",
                       help="images or stacks (TIFF, zarr, ...); a file that cannot be read is reported as failed")
        _add_io(q, out_help="output folder (created; an earlier run's results there are reused)")
        cluster = q.add_mutually_exclusive_group()
        cluster.add_argument("--workers", type=_number(int, 1), metavar="N",
                             help="worker processes of the local dask cluster (default: the cores available)")
        cluster.add_argument("--scheduler", metavar="ADDRESS",
                             help="address of a running dask.distributed scheduler (e.g. tcp://10.0.0.5:8786, or "
                             "one started by dask-jobqueue on SLURM) to run the tasks on instead")
        q.add_argument("--quiet", action="store_true", help="no progress bar on stderr (e.g. in a cluster job's log)")
        if kind == "segment":
            _frames_option(q, "frames of each stack to segment (default all)")
            _channel_option(q)
            _add_segment_options(q)
        else:
            _add_track_options(q)
        q.set_defaults(run=_batch)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog=PROG, epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
                     description="Physical deformable contours: segment objects in images from rough initial "
                     "contours, match and simulate contours, track objects through time-lapses, in batches.")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for add in (_add_segment, _add_match, _add_simulate, _add_track, _add_batch):
        add(sub)
    return parser


def main(argv=None) -> int:
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as stop:  # --help (0), or a malformed argument (2, one line already printed)
        return stop.code
    # tifffile logs what it finds wrong in a file (a truncated one: "invalid page offset") to stderr
    # through logging's last resort, a line before the one this command prints about the same file.
    logging.getLogger("tifffile").addHandler(logging.NullHandler())
    try:
        # The core's dense problems are small: more BLAS threads only fight each
        # other (a 128 x 128 eigenproblem took 0.5 s instead of 2 ms on a busy machine).
        with threadpool_limits(limits=1, user_api="blas"), warnings.catch_warnings(), _terminate_as_interrupt():
            warnings.showwarning = _show_warning
            return args.run(args)
    except (ValueError, OSError) as err:  # bad input, or a file that cannot be read or written
        print(f"{_new_line()}{PROG}: error: {_in_cli_terms(err)}", file=sys.stderr)
        return 2
    except RuntimeError as err:  # DivergenceError
        print(f"{_new_line()}{PROG}: {' '.join(str(err).split())}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        resume = " (run the same command again to resume)" if args.command == "batch" else ""
        print(f"\n{PROG}: interrupted{resume}", file=sys.stderr)
        return 130


@contextlib.contextmanager
def _terminate_as_interrupt():
    """SIGTERM (what SLURM sends at the walltime, and ``kill``'s default) handled as Ctrl-C: a batch's
    tasks are cancelled and the command says it was interrupted and how to resume (it ended with no
    word, an outside tester). Only in the main thread, where Python takes signals."""
    try:
        previous = signal.signal(signal.SIGTERM, _interrupt)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _interrupt(signum, frame):
    raise KeyboardInterrupt


if __name__ == "__main__":
    sys.exit(main())

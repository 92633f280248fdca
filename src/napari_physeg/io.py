"""Files in and out, without napari: contours as napari's shapes CSV, lazy image stacks, tables.

napari saves a Shapes layer as a CSV table with the columns
``index, shape-type, vertex-index, axis-0, axis-1[, axis-2, ...]`` (one row per
vertex). :func:`read_shapes_csv` reads that (or a plain two-column
``row, col`` table) and :func:`write_shapes_csv` writes it, so contours move
between napari, scripts and the command line unchanged.

:func:`open_stack` opens a TIFF (or TIFF stack), a zarr array or any image
scikit-image reads as a lazy ``(frames, rows, cols)`` dask array with one
chunk per frame, so a task holds one frame in memory.
"""

from __future__ import annotations

import contextlib
import csv
import os
import uuid
from collections import Counter
from pathlib import Path

import numpy as np

# The same conversion the widgets use for a Shapes layer (numpy only; importing
# it does not import napari): an ellipse is its polygon, not its 4 box corners.
from ._widgets._layers import CLOSED_SHAPE_TYPES, shape_to_polygon

__all__ = ["read_shapes_csv", "write_shapes_csv", "open_stack", "parse_frames", "check_frames", "write_table",
           "atomic_path", "is_zarr", "same_file", "TIFF_SUFFIXES"]

#: File name endings read with tifffile (lazily, one page per chunk).
TIFF_SUFFIXES = (".tif", ".tiff", ".btf", ".tf8", ".tf2")


def read_shapes_csv(path, *, leading: bool = False):
    """Read the shapes in a CSV file as a list of ``(N, 2)`` float64 contours.

    Parameters
    ----------
    path : str or Path
        napari's shapes CSV (File > Save Selected Layer), with shapes of type
        polygon, rectangle, path (closed by joining its ends) or ellipse (read
        as the ellipse's polygon, not the 4 corners napari stores); for nD
        shapes the last two axes are the contour. Or a table whose last two
        columns are ``row, col`` (or ``x, y``, so named in a header line):
        one shape, or one per object when the column before them is named
        ``id``, ``object``, ``label``... (see OBJECT_COLUMNS; one row of an
        object is a click). A closed contour's repeated first point is dropped.
    leading : bool, optional
        Also return, per shape, the coordinates of its first vertex on the
        axes before the last two (e.g. ``(frame,)`` for a shape drawn on one
        frame of a movie; ``()`` for 2D shapes).

    Returns
    -------
    shapes : list of (N, 2) ndarray
    before : list of tuple
        Only with ``leading=True``.

    Raises
    ------
    ValueError
        If the file holds no shape, a shape that encloses nothing (a line) or
        columns that cannot be read. One point is a shape: a click (see
        :func:`napari_physeg.core.segment`), as each point of napari's
        Points CSV is.
    """
    path = Path(path)
    rows = _csv_rows(path)
    header = [c.strip() for c in rows[0]]
    try:
        if "index" in header and "axis-0" in header:
            index = header.index("index")
            indices = [r[index] for r in rows[1:]]
            if "shape-type" not in header and len(set(indices)) == len(indices):
                full = _napari_points(header, rows[1:])  # a Points layer's: each point a click
            else:
                full = _napari_shapes(header, rows[1:], path)
            out = [v[:, -2:] for v in full]
            before = [tuple(v[0, :-2]) for v in full]
            _check_one_plane(full)
        else:
            try:
                [float(c) for c in rows[0][-2:]]
                body, swap, objects = rows, False, None
            except ValueError:  # a header line
                body, swap = rows[1:], _xy_header(header[-2:])
                objects = _object_column(header, body)
            points = np.asarray([[float(r[-2]), float(r[-1])] for r in body], dtype=np.float64)
            points = points[:, ::-1] if swap else points
            out = [_unclosed(points[objects == o]) for o in dict.fromkeys(objects)] if objects is not None \
                else [_unclosed(points)]
            before = [()] * len(out)
    except IndexError:
        raise ValueError(f"could not read contours from {path}: a line has fewer columns than expected (is it "
                         f"comma-separated, as napari writes it?)") from None
    except (ValueError, OverflowError) as err:  # OverflowError: an index of 1e400
        raise ValueError(f"could not read contours from {path}: {err}") from None
    if not out or all(len(s) == 0 for s in out):
        raise ValueError(f"{path} holds no shape")
    bad = [i for i, (s, b) in enumerate(zip(out, before)) if not (np.isfinite(s).all() and np.isfinite(b).all())]
    if bad:
        raise ValueError(f"could not read contours from {path}: shape {bad[0]} has a NaN or infinite coordinate")
    from .core._validation import on_one_line  # (not at import: the command line's start stays light)

    flat = [i for i, s in enumerate(out) if len(s) > 1 and (len(s) < 3 or on_one_line(s))]
    if flat:
        raise ValueError(f"shape {flat[0]} of {path} encloses nothing ({len(out[flat[0]])} vertices on one line or "
                         "point): a contour needs 3 vertices or more around an area (or one point, a click inside "
                         "the object); draw it again")
    return (out, before) if leading else out


def _check_one_plane(shapes) -> None:
    """A ValueError unless every shape's vertices share their leading
    coordinates (a frame, a slice): only the first vertex's were read."""
    for k, vertices in enumerate(shapes):
        planes = np.unique(vertices[:, :-2], axis=0)
        if len(planes) > 1 and np.isfinite(planes).all():  # (NaN ones are named below)
            shown = ", ".join("(" + ", ".join(f"{x:g}" for x in plane) + ")" for plane in planes[:3])
            raise ValueError(f"shape {k} has vertices on {len(planes)} planes (leading coordinates {shown}"
                             f"{', ...' if len(planes) > 3 else ''}): draw each contour on one frame")


def _csv_rows(path: Path) -> list[list[str]]:
    """The rows of a CSV file that hold something, comments ('#') left out."""
    # utf-8-sig: Excel's "CSV UTF-8" (and many Windows editors) start the file with a byte-order mark,
    # which would otherwise be part of the first header cell ('\ufeffindex': read as a 'row,col' table).
    try:
        with path.open(newline="", encoding="utf-8-sig") as fh:
            lines = [line for line in fh if line.strip() and not line.lstrip().startswith("#")]
        # Fiji and spreadsheets in locales with decimal commas write tabs or ';' between columns.
        delimiter = next((d for d in "\t;" if lines and d in lines[0] and "," not in lines[0].replace(d, "")), ",")
        rows = [_without_trailing_empty(r) for r in csv.reader(lines, delimiter=delimiter)]
    except (UnicodeDecodeError, csv.Error):  # binary: an image given for the contours, most often
        raise ValueError(f"cannot read {path} as a CSV: it is not UTF-8 text (is it the image? a table saved "
                         "in another encoding: save it as CSV UTF-8); contours are napari's shapes CSV or a "
                         "'row,col' table") from None
    if not rows:
        raise ValueError(f"{path} is empty: expected napari's shapes CSV or 'row,col' lines")
    return rows if delimiter == "," else [[c.replace(",", ".") for c in r] for r in rows]


def _without_trailing_empty(row: list) -> list:
    """A CSV row without the empty cells a spreadsheet leaves at its end ("1,2,")."""
    while len(row) > 1 and not row[-1].strip():
        row = row[:-1]
    return row


#: The names of a plain table's column, just before its two coordinates, that
#: says which object each point outlines (e.g. ``id,row,col``).
OBJECT_COLUMNS = ("id", "object", "label", "shape", "cell", "contour", "roi", "track", "track_id", "index")


def _object_column(header, body) -> np.ndarray | None:
    """The object of each row of a plain table, when the column before its two
    coordinates is named as one of OBJECT_COLUMNS, and its values repeat or
    it is named for an object (one row per object: a click on each; an
    ``index`` of values that do not repeat is a row number, as Fiji's
    Results' column, which names no object); else None."""
    if len(header) < 3 or header[-3].lower() not in OBJECT_COLUMNS:
        return None
    objects = np.asarray([r[-3].strip() for r in body])
    return objects if len(set(objects)) < len(objects) or header[-3].lower() != "index" else None


def _napari_points(header, body) -> list[np.ndarray]:
    """The points of napari's Points CSV, each a one-point shape (all axes): a click."""
    axes = sorted((c for c in header if c.startswith("axis-")), key=lambda c: int(c[5:]))
    cols = [header.index(a) for a in axes]
    return [np.asarray([[float(r[c]) for c in cols]], dtype=np.float64) for r in body]


def _unclosed(points: np.ndarray) -> np.ndarray:
    """A contour without its first point repeated at its end, as
    ``skimage.measure.find_contours``, Fiji and shapely write a closed one."""
    return points[:-1] if len(points) > 3 and np.array_equal(points[0], points[-1]) else points


def _xy_header(names) -> bool:
    """Whether a plain table's last two header cells name (x, y) columns, which are (col, row): a
    table saved with x, y was read as row, col, and its contour lay transposed (or wholly outside a
    non-square image). Other names are read as (row, col), the documented order."""
    return [n.lower() for n in names] in (["x", "y"], ["col", "row"], ["column", "row"])


def _napari_shapes(header, body, path) -> list[np.ndarray]:
    """The shapes of napari's CSV, each as the polygon it stands for (all axes)."""
    axes = sorted((c for c in header if c.startswith("axis-")), key=lambda c: int(c[5:]))
    cols = [header.index(a) for a in axes]
    index = header.index("index")
    kind = header.index("shape-type") if "shape-type" in header else None
    order = header.index("vertex-index") if "vertex-index" in header else None
    shapes: dict[int, list] = {}
    types: dict[int, str] = {}
    for r in body:
        i = int(float(r[index]))
        vertex = int(float(r[order])) if order is not None else len(shapes.get(i, ()))
        shapes.setdefault(i, []).append((vertex, [float(r[c]) for c in cols]))
        types.setdefault(i, r[kind].strip() if kind is not None else "polygon")
    out = []
    for i in sorted(shapes):
        vertices = np.asarray([xy for _, xy in sorted(shapes[i], key=lambda v: v[0])], dtype=np.float64)
        if types[i] not in CLOSED_SHAPE_TYPES:
            raise ValueError(f"shape {i} is a {types[i]!r}, which encloses no region; use a polygon, "
                             f"rectangle, ellipse or path ({', '.join(CLOSED_SHAPE_TYPES)})")
        try:
            out.append(shape_to_polygon(vertices, types[i]))
        except ValueError as err:
            raise ValueError(f"shape {i}: {err}") from None
    return out


def write_shapes_csv(path, shapes, shape_type: str = "polygon", leading=None, columns=None) -> Path:
    """Write contours as napari's shapes CSV (polygons), readable by napari.

    ``leading``, one tuple per shape (e.g. ``(frame,)``), puts each shape on
    a slice of an nD layer: its values become the first axes. ``columns``,
    a dict of name -> one value per shape (e.g. ``{"object": [...]}``), adds
    columns after the axes, repeated on each vertex's row: napari reads
    only the index, shape type and axes, so the file still opens as a
    Shapes layer, and a table reader can tell which object each shape is.
    The file is written under a temporary name and renamed, so it is whole
    or absent.
    """
    path = Path(path)
    n_lead = len(leading[0]) if leading else 0
    columns = dict(columns or {})
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["index", "shape-type", "vertex-index"] + [f"axis-{a}" for a in range(n_lead + 2)] + list(columns))
        for i, shape in enumerate(shapes):
            lead = [repr(float(v)) for v in leading[i]] if leading else []
            extra = [values[i] for values in columns.values()]
            for k, (r, c) in enumerate(np.asarray(shape, dtype=np.float64)):
                w.writerow([i, shape_type, k, *lead, repr(float(r)), repr(float(c)), *extra])
    return path


@contextlib.contextmanager
def atomic_path(path):
    """A temporary path next to ``path``, renamed to ``path`` when the block
    ends without error (and removed when it fails): a reader, or a batch run
    that resumes, never sees half a file."""
    path = Path(path)
    if path.exists() and not path.is_file():
        # A device or a pipe (--out /dev/null, /dev/stdout): written in place. Renamed over, it would
        # be replaced by a plain file (as root), or refused after all the work.
        yield path
        return
    # The suffix kept last: writers that choose the format by it still do. Created with mode 0o666
    # (not mkstemp's 0o600): the umask applies, so the file gets the mode a plain open() gives it.
    tmp = path.parent / f".{path.stem}.{uuid.uuid4().hex[:12]}.part{path.suffix}"
    os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_table(table, path) -> list[Path]:
    """Write a pandas DataFrame as ``path`` with the suffix ``.csv``, and as
    ``.parquet`` too when pyarrow is installed; the paths written."""
    path = Path(path)
    written = [path.with_suffix(".csv")]
    with atomic_path(written[0]) as tmp:
        table.to_csv(tmp, index=False)
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return written
    written.append(path.with_suffix(".parquet"))
    with atomic_path(written[1]) as tmp:
        table.to_parquet(tmp, index=False)
    return written


def same_file(a, b) -> bool:
    """Whether paths ``a`` and ``b`` name one file: the same path once resolved (either may not
    exist yet), or, both existing, one file under two names (a hard link)."""
    a, b = Path(a), Path(b)
    if a.resolve() == b.resolve():
        return True
    return a.exists() and b.exists() and a.samefile(b)


def is_zarr(path: Path) -> bool:
    """Whether ``path`` is a zarr store (a ``.zarr`` folder, or one with zarr metadata)."""
    return path.suffix == ".zarr" or (path.is_dir() and any((path / n).exists() for n in
                                                            ("zarr.json", ".zarray", ".zgroup")))


@contextlib.contextmanager
def open_stack(path, *, channel: int | None = None):
    """Open an image file as a lazy ``(T, H, W)`` dask array, one chunk per frame.

    Parameters
    ----------
    path : str or Path
        A TIFF (a 2D image, a stack of pages, an ImageJ or OME series), a zarr
        array (a ``.zarr`` folder) or another 2D image scikit-image reads
        (PNG, JPEG, ...; read whole). A 2D image is a stack of one frame.
    channel : int, optional
        Channel to take: of an RGB(A) image or movie (a last axis of 3 or 4
        samples), or of a TIFF hyperstack whose axes name one C (ImageJ or
        OME, e.g. ``TCYX``).

    Yields
    ------
    dask.array.Array
        ``(T, H, W)``; reading frame ``t`` reads only that frame, in this
        process (dask's synchronous scheduler inside the block). The file is
        closed when the ``with`` block ends.

    Raises
    ------
    ValueError
        If the file cannot be read, or its shape is not an image or a stack of
        2D frames (after ``channel``).
    """
    import dask
    import dask.array as da

    path = Path(path)
    closers = []
    try:
        try:
            if is_zarr(path):
                _need("zarr", path)
                import zarr

                stack = _named_reads(zarr.open_array(str(path), mode="r"), path)
                axes = None  # a zarr array names no axes
            elif path.suffix.lower() in TIFF_SUFFIXES:
                import tifffile

                # Open while the stack is: a movie of a series a page reads its frames from it.
                tif = tifffile.TiffFile(path)
                closers.append(tif.close)
                axes = tif.series[0].axes
                cut = _cut_short(tif.series[0], path) or _pages_missing(tif, path)
                pages = _pages_as_frames(tif, path)
                if cut:
                    raise _Refused(cut)
                try:
                    import zarr
                except ImportError:
                    zarr = None
                if pages is not None:  # one series a page: a frame a page
                    axes, stack = None, pages
                elif zarr is None:  # a memory map if the file allows, else read whole
                    stack = da.from_array(_tiff_without_zarr(path))
                else:
                    store = tifffile.imread(path, aszarr=True)
                    closers.append(store.close)
                    stack = _named_reads(zarr.open(store, mode="r"), path)
            else:
                from skimage import io

                image = io.imread(path)
                axes = None
                stack = da.from_array(image, chunks=image.shape)
        except _Refused:
            raise
        except Exception as err:  # unreadable or corrupt: one plain sentence
            raise ValueError(f"could not read {path}: {type(err).__name__}: {err}{_zarr_group_hint(path)}") \
                from None
        # Frames are read here, in this process: the store is not for sending
        # to a cluster (a distributed Client made default elsewhere would try).
        with dask.config.set(scheduler="synchronous"):
            yield _as_frames(stack, axes, channel, path)
    finally:
        for close in closers:
            close()


def _zarr_group_hint(path: Path) -> str:
    """For a zarr group (an OME-Zarr image), which arrays in it to give instead."""
    if not is_zarr(path):
        return ""
    arrays = sorted(p.name for p in path.iterdir() if p.is_dir() and is_zarr(p) and not (p / ".zgroup").exists())
    return f" ({path} is a group of arrays: give one of them, e.g. {path / arrays[0]})" if arrays else ""


class _NamedReads:
    """An array whose failed reads name the file and the frames: a frame is read deep in a run
    (tracking frame after frame), where a decoder's bare message says neither."""

    def __init__(self, array, path):
        self.array, self.path = array, path
        self.shape, self.dtype, self.ndim = tuple(array.shape), array.dtype, len(array.shape)

    def __getitem__(self, key):
        try:
            return np.asarray(self.array[key])
        except Exception as err:  # noqa: BLE001 - any decoder's or store's error: one plain sentence
            raise ValueError(f"could not read {self._frames(key)}{self.path}: {type(err).__name__}: "
                             f"{' '.join(str(err).split())}") from None

    def _frames(self, key) -> str:
        """'frame 2 of ' for a read of frame 2 (dask asks for a chunk, or one frame), '' for a 2D image."""
        first = key[0] if isinstance(key, tuple) and key else key
        if self.ndim < 3 or not isinstance(first, (int, np.integer, slice)):
            return ""
        frames = range(self.shape[0])[first]
        if isinstance(frames, int):
            return f"frame {frames} of "
        return "" if not frames else (f"frame {frames[0]} of " if len(frames) == 1 else
                                      f"frames {frames[0]} to {frames[-1]} of ")


def _named_reads(array, path):
    """A zarr array (a zarr store, or a TIFF through tifffile's zarr store; or a TIFF's one-page
    series, see _SeriesFrames) as a dask array of its chunks whose reads, when they fail, name the
    file and the frame (see _NamedReads)."""
    import dask.array as da

    return da.from_array(_NamedReads(array, path), chunks=array.chunks, asarray=False,
                         name=f"napari-physeg-{uuid.uuid4().hex}")


class _Refused(ValueError):
    """A file open_stack refuses with its own message (not wrapped as 'could not read')."""


def _cut_short(series, path) -> str | None:
    """Why a TIFF is cut short (an interrupted copy, a full disk), or None: its frames' bytes run
    past the end of the file. Told from the header, before any frame is read; only an uncompressed
    series stored in one piece says where its data end (tifffile's dataoffset), others fail on the
    frame that is missing."""
    end = series.dataoffset + series.nbytes if series.dataoffset is not None else 0
    size = Path(path).stat().st_size
    if end <= size:
        return None
    return (f"{path} is cut short: its {' x '.join(map(str, series.shape))} pixels need {end} bytes, the file "
            f"holds {size} (an interrupted copy, a full disk?): copy it again")


def _pages_missing(tif, path) -> str | None:
    """Why a TIFF whose header names more frames than it holds is cut short (a compressed file cut:
    tifffile reads the pages up to the cut, and took it for one image), or None."""
    if tif.is_shaped and tif.shaped_metadata:
        named = tuple(int(n) for n in tif.shaped_metadata[0].get("shape", ()))
        if named and int(np.prod(named)) > tif.series[0].size:
            return (f"{path} is cut short: its header names {' x '.join(map(str, named))} pixels, the file holds "
                    f"{len(tif.pages)} page(s) (an interrupted copy, a full disk?): copy it again")
    if tif.is_imagej and int((tif.imagej_metadata or {}).get("images", 1)) > len(tif.pages):
        return (f"{path} is cut short: its header names {tif.imagej_metadata['images']} images, the file holds "
                f"{len(tif.pages)} page(s) (an interrupted copy, a full disk?): copy it again")
    return None


def _need(module: str, path) -> None:
    try:
        __import__(module)
    except ImportError:
        raise ValueError(f"{path} needs the {module} package: pip install {module} "
                         "(or napari-physeg[batch])") from None


def _pages_as_frames(tif, path):
    """A TIFF whose pages are each a series of their own (written one at a
    time, or by a program that names no stack) as a lazy ``(pages, H, W)`` dask array;
    None for a TIFF of one series. Only the first series would be read
    otherwise, and the other frames dropped without a word. Series of other
    shapes (an OME file's positions, a page of another size) are refused."""
    series = tif.series
    if len(series) < 2:
        return None
    shapes = [tuple(s.shape) for s in series]
    if tif.is_ome or any(len(shape) != 2 for shape in shapes) or len(set(shapes)) > 1 \
            or len({s.dtype for s in series}) > 1:
        shown = ", ".join(" x ".join(map(str, shape)) for shape in shapes[:4]) + (", ..." if len(shapes) > 4 else "")
        raise _Refused(f"{path} holds {len(series)} images of shapes {shown}, not one stack: save the movie's "
                       "frames as one stack of one shape (e.g. tifffile.imwrite(path, np.stack(frames))), or "
                       "each image to a file of its own")
    return _named_reads(_SeriesFrames(series), path)


class _SeriesFrames:
    """The one-page series of an open TIFF as a ``(pages, H, W)`` array whose frames are read when
    indexed (a movie saved a frame at a time can be larger than memory). One dask chunk a frame:
    stacked as one dask array per page, a 1000-frame movie took 86 ms to slice each frame out."""

    def __init__(self, series):
        self.series = series
        self.shape, self.dtype = (len(series), *series[0].shape), series[0].dtype
        self.chunks = (1, *series[0].shape)

    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        if isinstance(key[0], (int, np.integer)):
            return self.series[key[0]].asarray()[key[1:]]
        frames = range(self.shape[0])[key[0]]
        stacked = np.empty((len(frames), *self.shape[1:]), self.dtype)
        for j, t in enumerate(frames):
            stacked[j] = self.series[t].asarray()
        return stacked[(slice(None), *key[1:])]


def _tiff_without_zarr(path):
    import tifffile

    try:
        return tifffile.memmap(path, mode="r")
    except ValueError:  # compressed or tiled: not memory-mappable
        return tifffile.imread(path)


def _as_frames(stack, axes: str | None, channel, path):
    """``stack`` as ``(T, H, W)`` with one chunk per frame, the channel chosen.

    ``axes`` are the file's own (a TIFF series': ``"TCYX"``, ``"YXS"``, ...), None when it names none.
    """
    if channel is not None and (isinstance(channel, (bool, np.bool_)) or not isinstance(channel, (int, np.integer))):
        raise ValueError(f"channel must be an integer (0 for the first), got {channel!r}")
    where = _channel_axis(stack.shape, axes)
    shape = " x ".join(map(str, stack.shape))
    if channel is not None:
        if where is None and stack.ndim <= 3:
            kind = "image" if stack.ndim == 2 else "stack"
            raise ValueError(f"{path} has no channels (a {shape} {kind}): leave out the channel option (--channel)")
        if where is None:
            raise ValueError(f"{path} has shape ({shape}) and names no channel axis: save one channel per file as "
                             "(frames, rows, cols), or as an ImageJ hyperstack (axes TCYX)")
        n = stack.shape[where]
        if not 0 <= channel < n:
            raise ValueError(f"channel {channel} is out of range: {path} has {n} channels "
                             f"({_channel_name(where, axes)}): choose {_choices(n)}")
        stack = stack[(slice(None),) * where + (channel,)]
    elif where is not None:
        raise ValueError(f"{path} has {stack.shape[where]} channels ({_channel_name(where, axes)}, shape {shape}): "
                         f"choose one with the channel option (--channel): {_choices(stack.shape[where])}")
    if stack.ndim == 2:
        stack = stack[None]
    if stack.ndim != 3:
        raise ValueError(f"{path} has shape {tuple(stack.shape)}: expected a 2D image or a (frames, rows, cols) "
                         "stack; save one channel and one z-plane per file (e.g. in Fiji: Image > Stacks)")
    return stack.rechunk((1, *stack.shape[1:]))


def _channel_axis(shape, axes: str | None) -> int | None:
    """The axis holding channels, or None: the one the file names (a TIFF's S, the samples of an RGB(A)
    image, or C, the channels of an ImageJ or OME hyperstack), else a last axis of 3 or 4 on an image
    or a movie that names no axes (an RGB(A) PNG, a (T, H, W, 3) zarr array)."""
    if axes and axes.endswith("S"):
        return len(axes) - 1
    if axes and "C" in axes:
        return axes.index("C")
    if axes is None and len(shape) in (3, 4) and shape[-1] in (3, 4):
        return len(shape) - 1
    return None


def _channel_name(where: int, axes: str | None) -> str:
    """The channel axis in words, for a message: 'axis C of TCYX', 'RGB(A) samples, the last axis'."""
    if axes and axes[where] == "C":
        return f"axis C of {axes}"
    return "RGB(A) samples, the last axis"


def _choices(n: int) -> str:
    """'0 or 1', '0, 1 or 2', '0 to 4': the channels to choose among."""
    if n > 3:
        return f"0 to {n - 1}"
    return ", ".join(map(str, range(n - 1))) + f" or {n - 1}"


def parse_frames(spec: str, n_frames: int) -> list[int]:
    """Frame indices from ``"3"``, ``"0:10"``, ``"0:30:2"``, ``"2,5,9"`` (Python
    ranges: the stop excluded; negative counts from the end).

    Raises
    ------
    ValueError
        For a malformed spec or a frame outside ``[0, n_frames)``.
    """
    parts = _frame_parts(spec)
    try:
        frames = _select(parts, n_frames)
    except IndexError:
        raise ValueError(f"frames {spec!r}: the stack has frames 0 to {n_frames - 1}") from None
    if not frames:
        raise ValueError(f"frames {spec!r} selects no frame of the {n_frames}")
    _no_repeat(spec, frames)
    return frames


def check_frames(spec: str, include: int | None = None) -> list[int] | None:
    """Check a frame spec before the stack's length is known (before a batch starts).

    Parameters
    ----------
    spec : str
        As for :func:`parse_frames`.
    include : int, optional
        A frame the answer must tell about (e.g. the start frame of tracking).

    Returns
    -------
    list of int or None
        The frames ``spec`` chooses in any stack long enough to hold the frames it
        names (and ``include``), in its order: a range left open is cut after them,
        which keeps its order and repeats. None if the spec counts from the end
        (then only its syntax is checked here; the rest with the stack).

    Raises
    ------
    ValueError
        For a spec that is wrong in any stack: malformed, a step of 0, no frame,
        a frame named twice.
    """
    parts = _frame_parts(spec)
    named = [p for p in parts if isinstance(p, int)] + [b for p in parts if isinstance(p, slice)
                                                        for b in (p.start, p.stop) if b is not None]
    if any(n < 0 for n in named) or any((p.step or 1) < 0 and p.start is None for p in parts
                                        if isinstance(p, slice)):
        return None  # counts from the end: its meaning depends on the stack's length
    # Long enough that each range reaches past every frame named by itself or as a range's start:
    # its order and repeats show. (A range's stop only bounds it: counted, 0:100000000 listed a
    # hundred million frames.)
    steps = [abs(p.step or 1) for p in parts if isinstance(p, slice)]
    firsts = [p for p in parts if isinstance(p, int)] + [p.start for p in parts
                                                         if isinstance(p, slice) and p.start is not None]
    frames = _select(parts, max(firsts + [include or 0]) + max(steps, default=1) + 1)
    if not frames:
        raise ValueError(f"frames {spec!r} selects no frame")
    _no_repeat(spec, frames)
    return frames


def _frame_parts(spec) -> list:
    """The parts of a frame spec, ints and slices; ValueError for a malformed one."""
    parts: list = []
    try:
        for part in str(spec).split(","):
            if ":" in part:
                bounds = [int(x) if x.strip() else None for x in part.split(":")]
                if len(bounds) > 3 or (len(bounds) == 3 and bounds[2] == 0):
                    raise ValueError(part)
                parts.append(slice(*bounds))
            else:
                parts.append(int(part))
    except ValueError:
        raise ValueError(f"frames {spec!r}: expected e.g. 3, 0:10, 0:30:2 or 2,5,9") from None
    return parts


def _select(parts, n_frames: int) -> list[int]:
    """The frames of ``parts`` in a stack of ``n_frames``; IndexError for a frame beyond it."""
    frames: list[int] = []
    for part in parts:
        if isinstance(part, slice):
            frames.extend(range(n_frames)[part])
        elif -n_frames <= part < n_frames:
            frames.append(part % n_frames)
        else:
            raise IndexError(part)
    return frames


def _no_repeat(spec, frames) -> None:
    if len(set(frames)) < len(frames):
        repeated = min(t for t, n in Counter(frames).items() if n > 1)
        raise ValueError(f"frames {spec!r} names frame {repeated} more than once")

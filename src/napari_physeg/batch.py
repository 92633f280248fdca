"""Many files and objects at once, on dask: segmentation or tracking of a folder or a plate.

:func:`segment_files` segments the same initial contours on every frame of
many images or stacks, :func:`track_files` tracks them through many movies.
Both run their tasks on a ``dask.distributed`` cluster: a local one with
``workers`` processes by default, or an existing one at ``scheduler`` (for
instance a SLURM cluster started with ``dask-jobqueue``; see docs/batch.md).

Each task (one frame of one file for segmentation, one movie for tracking)
opens its file itself, lazily (a TIFF or zarr stack is read one frame at a
time), writes its outputs under ``out/results/<name>/`` and reports one row per
object. The outputs of a task are written in a temporary folder that is
renamed when complete, so:

* a run that is stopped (or a worker that is killed) leaves no half result,
  and a task the cluster runs again finds its result and does not redo it;
* running the same command again skips every task already complete
  (*resumable*); failed tasks are tried again, and so are the tasks of an
  input replaced since (its size or modification time changed: a warning
  says so).

A file that cannot be read, or a task that raises, becomes rows with
``status="failed"`` and the error; the other tasks finish. When all are done
``out/summary.csv`` (and ``summary.parquet`` with pyarrow) holds one row per
input (and frame) and object.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import os
import re
import shutil
import signal
import socket
import sys
import time
import traceback
import uuid
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from .io import (TIFF_SUFFIXES, atomic_path, check_frames, is_zarr, open_stack, parse_frames, read_shapes_csv,
                 same_file, write_shapes_csv, write_table)

__all__ = ["segment_files", "track_files", "track_file", "check_writable", "check_inputs_kept", "default_workers",
           "segment_options_for", "TRACK_FILES"]

#: Status of a row whose task (or object) failed; the ``error`` column says why.
FAILED = "failed"
#: Status of a row whose task completed (see the other columns for the outcome).
OK = "ok"
#: Status of a tracking row whose object was found on no frame (lost, or left, on every one).
NOT_FOUND = "not found"

_RESULTS = "results"
_SETTINGS = "batch.json"
_SUMMARY = "summary"
_SOURCE = "input.json"  # the input's size and modification time when the task read it
_SEP = " | "  # between the messages of the warnings column
#: The files :func:`track_file` writes in its folder (the .parquet with pyarrow only).
TRACK_FILES = ("contours.csv", "tracks.csv", "tracks.parquet")


def default_workers() -> int:
    """The number of cores this process may use: the default ``workers``."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def segment_options_for(contour, options: dict, node_spacing: float | None) -> dict:
    """``options`` of :func:`~napari_physeg.core.segment` for one contour:
    ``node_spacing`` (px) becomes its node count, as in the widgets
    (:func:`~napari_physeg.core.contour.nodes_for_spacing`), at most
    ``MAX_NODES`` (with a warning): the most :func:`~napari_physeg.core.segment` takes."""
    from .core.segmentation import nodes_at_spacing

    if node_spacing is None:
        return dict(options)
    return {**options, "n_nodes": nodes_at_spacing(contour, node_spacing)}


# --------------------------------------------------------------------------
# Tasks: run on the workers
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Task:
    """One unit of work: its folder name under ``out/results`` and what to do."""

    kind: str  # "segment" or "track"
    path: str
    name: str  # results/<name>, unique per input (and frame)
    out: str
    inits: tuple
    options: dict = field(default_factory=dict)
    frame: int | None = None  # segment: the frame
    frames: str | None = None  # track: the frame spec
    start: int | None = None  # track: the frame the contours were drawn on
    channel: int | None = None
    node_spacing: float | None = None
    max_steps: int | None = None
    match_options: dict = field(default_factory=dict)
    stamp: list | None = None  # _stamp(path) when the task was made: a result made from another file is stale

    def failed(self, error: str) -> list[dict]:
        base = {"input": self.path, "frame": self.frame} if self.kind == "segment" else {"input": self.path}
        return [{**base, "object": k, "status": FAILED, "error": error} for k in range(len(self.inits))]


def _execute(task: _Task) -> list[dict]:
    """Run ``task`` unless its result exists; its rows. Never raises: an
    error becomes failed rows, so one bad file cannot stop the batch."""
    final = Path(task.out) / _RESULTS / task.name
    if _is_done(final, task):  # done before (an earlier run, or before a worker died)
        return _read_rows(final)
    # Caught here, not printed by the worker: the client shows them naming the file.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")  # each distinct warning once per task
        return _attempt(task, final, caught)


def _attempt(task: _Task, final: Path, caught: list) -> list[dict]:
    tmp = final.parent / f".{final.name}.tmp-{uuid.uuid4().hex}"
    try:
        tmp.mkdir(parents=True)
        stamp = _stamp(task.path)  # before reading: a file replaced meanwhile is run again next time
        rows = _annotated((_segment_task if task.kind == "segment" else _track_task)(task, tmp), task, caught)
        (tmp / _SOURCE).write_text(json.dumps(stamp))
        (tmp / "rows.json").write_text(json.dumps(rows))  # written last: marks the folder complete
        try:
            os.rename(tmp, final)
        except OSError:  # another run of this task finished first: keep its result
            shutil.rmtree(tmp, ignore_errors=True)
            return _read_rows(final)
        return rows
    except Exception as err:  # noqa: BLE001 - isolation: any failure is reported, not raised
        shutil.rmtree(tmp, ignore_errors=True)
        return _annotated(task.failed(_one_line(err)), task, caught)


def _annotated(rows: list[dict], task: _Task, caught: list) -> list[dict]:
    """Rows with who ran them (for the cluster's logs), the warnings caught, outputs named relative to out."""
    said = _SEP.join(dict.fromkeys(" ".join(str(w.message).split()) for w in caught))
    for row in rows:
        row.update(host=socket.gethostname(), pid=os.getpid(), warnings=said)
        for key in ("contours", "tracks"):
            if row.get(key):
                row[key] = str(Path(_RESULTS) / task.name / row[key])
    return rows


def _stamp(path) -> list:
    """Size and modification time (ns) of an input, to tell the file a result was made from from one
    put in its place. Of a zarr store: its files' count, total size and newest modification time (a
    version 3 store rewritten in place changes only its chunks, under ``c/``)."""
    path = Path(path)
    if not path.is_dir():
        return [[path.stat().st_size, path.stat().st_mtime_ns]]
    sizes, times = [], []
    for folder, _, names in os.walk(path):
        for name in names:
            info = os.stat(os.path.join(folder, name))
            sizes.append(info.st_size)
            times.append(info.st_mtime_ns)
    return [[len(sizes), sum(sizes), max(times, default=0)]]


def _is_done(folder: Path, task: _Task) -> bool:
    """Whether ``folder`` holds the task's complete result, made from the input as it is now."""
    if not (folder / "rows.json").exists() or _failed(folder):  # a failed task is tried again
        return False
    if task.stamp is None or not (folder / _SOURCE).exists():  # no stamp to compare (older results)
        return True
    return json.loads((folder / _SOURCE).read_text()) == task.stamp


def _failed(folder: Path) -> bool:
    """Whether the result in ``folder`` says its task failed (a frame that could not be read)."""
    return any(row.get("status") == FAILED for row in _read_rows(folder))


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    if isinstance(err, ValueError):  # our checks: the message says it all
        return text
    where = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
    return f"{type(err).__name__}: {text}" + (f" ({Path(where.filename).name}:{where.lineno})" if where else "")


def _read_rows(folder: Path) -> list[dict]:
    return json.loads((folder / "rows.json").read_text())


def _segment_task(task: _Task, tmp: Path) -> list[dict]:
    from .core import segment
    from .core.contour import area_centroid, perimeter, signed_area

    with open_stack(task.path, channel=task.channel) as stack:
        image = np.asarray(stack[task.frame])  # this frame only
    rows, shapes = [], []
    for k, init in enumerate(task.inits):
        t0 = time.perf_counter()
        row = {"input": task.path, "frame": task.frame, "object": k}
        try:
            res = segment(image, np.asarray(init), **segment_options_for(init, task.options, task.node_spacing))
        except (ValueError, RuntimeError) as err:  # a bad contour or a divergence: this object only
            rows.append({**row, "status": FAILED, "error": _one_line(err)})
            continue
        c = res.contour
        centroid = area_centroid(c)
        rows.append({**row, "status": OK, "error": "", "converged": bool(res.converged),
                     "stop_reason": res.stop_reason, "steps": int(res.steps), "n_nodes": len(c),
                     "area": abs(float(signed_area(c))), "perimeter": float(perimeter(c)),
                     "centroid_row": float(centroid[0]), "centroid_col": float(centroid[1]),
                     "seconds": time.perf_counter() - t0, "contours": "contours.csv", "shape": len(shapes)})
        shapes.append(c)
    if shapes:
        write_shapes_csv(tmp / "contours.csv", shapes, columns={"object": [row["object"] for row in rows
                                                                           if row["status"] == OK]})
    return rows


def _track_task(task: _Task, tmp: Path) -> list[dict]:
    from .core import LEFT, LOST, TRACKED

    t0 = time.perf_counter()
    tr, frames, written = track_file(task.path, task.inits, tmp, frames=task.frames, start=task.start,
                                     channel=task.channel, node_spacing=task.node_spacing, max_steps=task.max_steps,
                                     match_options=task.match_options, **task.options)
    seconds = time.perf_counter() - t0
    # A frame that could not be read stops the tracking there: the frames
    # done are written, but the task failed (a rerun does it again).
    stopped = "" if tr.stop_reason == "completed" else " ".join(
        f"tracking stopped ({tr.stop_reason}): {' | '.join(tr.warnings) or 'no frame after it was processed'}".split())
    rows = []
    for k in range(tr.n_objects):
        counts = {s: tr.status[k].count(s) for s in (TRACKED, LOST, LEFT)}
        first = tr.first_lost(k)
        found = counts[TRACKED] > 0  # else lost (or left) on every frame: not an outcome to call ok
        error = stopped or ("" if found else f"object {k} was found on none of the {tr.n_frames} frames: check "
                            "that the contours were drawn on this movie")
        rows.append({"input": task.path, "object": k, "status": FAILED if stopped else OK if found else NOT_FOUND,
                     "error": error, "frames": tr.n_frames,
                     "tracked": counts[TRACKED], "lost": counts[LOST], "left": counts[LEFT],
                     "last_status": tr.status[k][-1],
                     "first_lost": f"frame {frames[first[0]]}: {first[1]}" if first else "",
                     "seconds": seconds / tr.n_objects,
                     # The CSV, written with or without pyarrow (the .parquet, if any, is next to it).
                     "contours": written[0].name if written[0].exists() else "", "tracks": written[1].name})
    return rows


def _in_stack_frames(callback, chosen):
    """``callback`` given progress states whose ``frame`` is the stack's
    number of the tracked movie's frame (``chosen[frame]``); None for None."""
    if callback is None:
        return None
    return lambda progress: callback(replace(progress, frame=chosen[progress.frame]))


#: A frame number in a message of track(): "frame 4", "start frame 4", "(start=4)"; not the
#: stack's own number in a read error it passes on ("could not read frame 6 of movie.zarr").
_FRAME_NUMBER = re.compile(r"(?<!read )(\bframe |start=)(\d+)")
#: Frames as runs in a message of track() (see tracking.frame_runs): "frames 4-6, 9".
_FRAME_RUNS = re.compile(r"\bframes (\d+(?:-\d+)?(?:, \d+(?:-\d+)?)*)")


def _in_stack_numbers(text: str, chosen) -> str:
    """A message of track() on the frames ``chosen`` of a stack, with the stack's frame numbers."""
    from .core.tracking import frame_runs

    def renumbered(match):
        t = int(match.group(2))
        return match.group(1) + str(chosen[t]) if t < len(chosen) else match.group(0)

    def runs_renumbered(match):
        ends = [[int(n) for n in run.split("-")] for run in match.group(1).split(", ")]
        frames = [t for run in ends for t in range(run[0], run[-1] + 1)]
        return frame_runs([chosen[t] for t in frames]) if frames[-1] < len(chosen) else match.group(0)

    return _FRAME_NUMBER.sub(renumbered, _FRAME_RUNS.sub(runs_renumbered, text))


@contextlib.contextmanager
def _messages_in_stack_frames(chosen):
    """track()'s warnings and errors on the frames ``chosen`` of a stack, passed on with the
    stack's frame numbers (they numbered the frames tracked: "frame 4" of --frames 12:20 was 16)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            yield
        except ValueError as err:
            raise ValueError(_in_stack_numbers(str(err), chosen)) from None
    for w in caught:
        warnings.warn_explicit(_in_stack_numbers(str(w.message), chosen), w.category, w.filename, w.lineno)


def track_file(path, inits, folder, *, frames: str | None = None, start: int | None = None,
               channel: int | None = None, node_spacing: float | None = None, max_steps: int | None = None,
               match_options: dict | None = None, callback=None, **segment_options):
    """Track contours through one movie and write the results in ``folder``.

    Parameters
    ----------
    path : str or Path
        A ``(frames, rows, cols)`` TIFF stack or zarr array, read one frame at a time.
    inits : sequence of (N, 2) array_like
        The contours drawn on frame ``start``.
    folder : Path
        Folder (created when the tracking is done) for ``contours.csv`` (napari shapes CSV, one polygon
        per object and frame, the frame as axis-0) and ``tracks.csv`` (and
        ``tracks.parquet`` with pyarrow): :meth:`~napari_physeg.core.TrackingResult.table`
        with the frames numbered as in the stack.
    frames, start, channel, node_spacing, max_steps, match_options, **segment_options
        As for :func:`track_files`.
    callback : callable, optional
        Called as by :func:`~napari_physeg.core.track`, with each progress
        state's ``frame`` numbered as in the stack.

    Returns
    -------
    result : TrackingResult
        Its frame ``t`` is the stack's frame ``frames[t]``.
    frames : list of int
    written : list of Path
        ``contours.csv`` (absent when no object was found on any frame), then the tables.

    Raises
    ------
    ValueError
        Before tracking (:func:`check_track`): for a single 2D image, frames that are
        malformed, out of the movie's order or without ``start``, contours wholly outside
        the frames.
    """
    from .core import track

    folder = Path(folder)
    with open_stack(path, channel=channel) as stack:
        inits = [np.asarray(c, dtype=np.float64) for c in inits]
        chosen, start = check_track(stack, path, inits, "the contours", frames=frames, start=start)
        movie = stack if chosen == list(range(len(stack))) else stack[chosen]
        options = {"max_steps": max_steps} if max_steps is not None else {}
        with _messages_in_stack_frames(chosen):
            tr = track(movie, inits, start=chosen.index(start), callback=_in_stack_frames(callback, chosen),
                       segment_options=segment_options_for(_mean_contour(inits), segment_options, node_spacing),
                       match_options=dict(match_options or {}), **options)
        tr = replace(tr, warnings=tuple(_in_stack_numbers(text, chosen) for text in tr.warnings),
                     reason=[[_in_stack_numbers(why, chosen) for why in row] for row in tr.reason])
    shapes, leading, objects = [], [], []
    for k in range(tr.n_objects):
        for t, c in enumerate(tr.contours[k]):
            if c is not None:
                shapes.append(c)
                leading.append((chosen[t],))
                objects.append(k)
    folder.mkdir(parents=True, exist_ok=True)
    written = [folder / TRACK_FILES[0]]
    if shapes:
        # Lost frames have no shape: the object column ties each shape to its object (and its rows of the table).
        write_shapes_csv(written[0], shapes, leading=leading, columns={"object": objects})
    table = tr.table()
    table["frame"] = np.asarray(chosen)[table["frame"].to_numpy()]
    written += write_table(table, folder / "tracks")
    return tr, chosen, written


def check_track(stack, path, inits, contours_name, *, frames: str | None = None, start: int | None = None):
    """What tracking would refuse, found before it runs: a single image, bad frames, contours outside.

    ``stack`` is the opened movie (:func:`~napari_physeg.io.open_stack`) of ``path``; ``contours_name``
    names the contours in a message. Returns the frames to track and the start frame.
    """
    if len(stack) < 2:
        raise ValueError(f"{path} is a single 2-D image; track needs a time-lapse (T x H x W)")
    chosen, start = track_frames(frames, start, len(stack))
    check_contours(inits, stack.shape[1:], contours_name)
    return chosen, start


def track_frames(frames: str | None, start: int | None, n_frames: int | None = None):
    """The frames to track (in the movie's order) and the start frame among them.

    With ``n_frames`` None (before the movie is opened), what can be told without its
    length: the spec's syntax, order and repeats, the start among them; then the
    frames are None when the spec does not say them without the length.
    """
    if n_frames is None:
        chosen = check_frames(frames, include=start) if frames is not None else None
        if chosen is None:
            return None, start
    else:
        chosen = parse_frames(frames, n_frames) if frames is not None else list(range(n_frames))
    if chosen != sorted(chosen):
        raise ValueError(f"--frames {frames}: list the frames in the movie's order (tracking runs both ways from "
                         "the start frame by itself)")
    start = chosen[0] if start is None else int(start)
    if start not in chosen:
        among = f"among --frames {frames}" if frames is not None else f"in the stack (frames 0 to {n_frames - 1})"
        raise ValueError(f"the contours are drawn on frame {start}, not {among}: include it, or give the frame "
                         "they are drawn on with --start")
    return chosen, start


def check_contours(shapes, frame_shape, name) -> None:
    """What :func:`~napari_physeg.core.segment` would refuse for a contour (fewer than 3 nodes but
    one, a click; wholly outside the image), found before the first one runs; ``name`` names the
    contours in the message."""
    from .core.contour import as_drawing

    for k, shape in enumerate(shapes):
        c = as_drawing(shape, name=f"shape {k} of {name}")
        if np.any(c.max(0) < 0) or np.any(c.min(0) > np.array(frame_shape) - 1):
            raise ValueError(f"shape {k} of {name} lies wholly outside the image ({frame_shape[0]} x "
                             f"{frame_shape[1]} px): check that the contours were drawn on this image")


def _mean_contour(inits):
    """For ``node_spacing`` in tracking (one node count for all objects): the
    contour of mean perimeter stands for them all."""
    from .core.contour import perimeter

    if len(inits) == 1:
        return inits[0]
    lengths = [perimeter(np.asarray(c, float)) for c in inits]
    return inits[int(np.argmin(np.abs(np.asarray(lengths) - np.mean(lengths))))]


# --------------------------------------------------------------------------
# The run: checks, tasks, the cluster, the summary
# --------------------------------------------------------------------------


def segment_files(inputs, inits, out, *, frames: str | None = None, channel: int | None = None,
                  node_spacing: float | None = None, workers: int | None = None, scheduler: str | None = None,
                  client=None, overwrite: bool = False, progress: bool = True, **segment_options):
    """Segment the same initial contours on every chosen frame of many images.

    Parameters
    ----------
    inputs : sequence of str or Path
        Images or stacks (TIFF, zarr, or any 2D image scikit-image reads).
    inits : str, Path or sequence of (N, 2) array_like
        The initial contours (napari's shapes CSV, or arrays), in every
        image's (row, col) pixel coordinates.
    out : str or Path
        Output folder (created; an earlier run's results there are reused).
    frames : str, optional
        Frames of each stack, e.g. ``"0:10"`` or ``"3,7"`` (default: all).
    channel : int, optional
        Channel of RGB(A) images.
    node_spacing : float, optional
        Distance between nodes (px), turned into each contour's ``n_nodes``.
    workers : int, optional
        Worker processes of the local cluster (default: the cores available).
    scheduler : str, optional
        Address of a running ``dask.distributed`` scheduler to use instead.
    client : distributed.Client, optional
        A client to use instead (e.g. in a notebook).
    overwrite : bool, optional
        Delete the results of an earlier run in ``out`` first.
    progress : bool, optional
        Show a progress bar on stderr.
    **segment_options
        Options of :func:`~napari_physeg.core.segment` (material, stiffness,
        polarity, forces, weights, ...); the core's defaults otherwise.

    Returns
    -------
    pandas.DataFrame
        The summary, one row per input, frame and object (also written to
        ``out/summary.csv``): ``input, frame, object, status`` (``"ok"`` or
        ``"failed"``), ``error``, ``converged, stop_reason, steps, n_nodes,
        area, perimeter, centroid_row, centroid_col, seconds``, ``contours``
        (napari shapes CSV under ``out``), ``shape`` (the object's shape
        index in it), and ``host``, ``pid`` (the worker that ran the task),
        ``warnings`` (those the task raised, ``" | "`` between them; each is
        also warned here, naming the file).

    Raises
    ------
    ValueError
        Before any work, for a missing input or a folder, bad contours, frames
        or options, a missing package of the ``batch`` extra, an output folder
        that cannot be written or that holds results made with other settings.
    """
    from .core.segmentation import check_segment_options

    _check_installed(client)
    check_segment_options(**segment_options)
    if frames is not None:
        check_frames(frames)  # what is wrong in any stack: before anything is written
    paths, inits, out = _checked_run(inputs, inits, out)
    _check_scheduler(scheduler)
    settings = dict(kind="segment", frames=frames, channel=channel, node_spacing=node_spacing,
                    options=segment_options)
    _prepare_out(out, settings, inits, overwrite)
    tasks, failed = [], []
    for path in paths:
        stamp = _stamp(path)
        try:
            n_frames = _frame_count(path, channel)
            chosen = parse_frames(frames, n_frames) if frames is not None else range(n_frames)
        except ValueError as err:
            failed += _Task("segment", path, "", str(out), inits).failed(_one_line(err))
            continue
        tasks += [_Task("segment", path, f"{_name(path)}/t{t:05d}", str(out), inits, segment_options, frame=t,
                        channel=channel, node_spacing=node_spacing, stamp=stamp) for t in chosen]
    return _finish(out, failed + _run(tasks, workers, scheduler, client, progress), ["input", "frame", "object"])


def _frame_count(path, channel) -> int:
    """Frames of a TIFF or zarr stack (its header only); other formats hold one
    2D image (read by the task, not here: the client reads no pixels)."""
    if Path(path).suffix.lower() not in TIFF_SUFFIXES and not is_zarr(Path(path)):
        return 1
    with open_stack(path, channel=channel) as stack:
        return len(stack)


def track_files(inputs, inits, out, *, frames: str | None = None, start: int | None = None,
                channel: int | None = None, node_spacing: float | None = None, max_steps: int | None = None,
                match_options: dict | None = None, workers: int | None = None, scheduler: str | None = None,
                client=None, overwrite: bool = False, progress: bool = True, **segment_options):
    """Track the same initial contours through many movies.

    Parameters
    ----------
    inputs : sequence of str or Path
        ``(frames, rows, cols)`` TIFF stacks or zarr arrays, read one frame at
        a time.
    inits : str, Path or sequence of (N, 2) array_like
        The contours drawn on frame ``start`` (napari's shapes CSV, or arrays).
    out : str or Path
        Output folder (created; an earlier run's results there are reused).
    frames : str, optional
        Frames to track, e.g. ``"0:20"`` (default: all).
    start : int, optional
        The frame the contours were drawn on (default: the CSV's axis-0, else
        the first frame chosen).
    channel, node_spacing, workers, scheduler, client, overwrite, progress
        As for :func:`segment_files` (one node count for all objects: that of
        the contour of mean perimeter).
    max_steps : int, optional
        Time steps per object and frame (default: :func:`~napari_physeg.core.track`'s).
    match_options : dict, optional
        Options of :func:`~napari_physeg.core.match` for the correspondences.
    **segment_options
        Options of :func:`~napari_physeg.core.segment` (material, stiffness, ...).

    Returns
    -------
    pandas.DataFrame
        The summary, one row per input and object (also in
        ``out/summary.csv``): ``input, object, status`` (``"ok"``, ``"not
        found"`` when the object was found on no frame, or ``"failed"``),
        ``error``, ``frames, tracked, lost, left`` (frame counts),
        ``last_status``, ``seconds``, ``contours`` (napari shapes CSV, the
        frame as axis-0) and ``tracks`` (``tracks.csv``, the per-node table of
        :meth:`~napari_physeg.core.TrackingResult.table`, frames numbered as in
        the stack; ``tracks.parquet`` next to it with pyarrow), ``host, pid,
        warnings``.

    Raises
    ------
    ValueError
        As :func:`segment_files`; also for frames out of the movie's order or
        a ``start`` not among them. What needs a movie's length (a frame
        beyond its end) fails that movie's rows instead.
    """
    from .core.segmentation import check_segment_options

    _check_installed(client)
    check_segment_options(**segment_options)
    if inits is not None and not isinstance(inits, (list, tuple)) and start is None:
        start = _drawn_on(inits)
    track_frames(frames, start)  # what can be told without the movies: before anything is written
    paths, inits, out = _checked_run(inputs, inits, out)
    _check_scheduler(scheduler)
    settings = dict(kind="track", frames=frames, start=start, channel=channel, node_spacing=node_spacing,
                    max_steps=max_steps, match_options=match_options or {}, options=segment_options)
    _prepare_out(out, settings, inits, overwrite)
    tasks = [_Task("track", path, _name(path), str(out), inits, segment_options, frames=frames, start=start,
                   channel=channel, node_spacing=node_spacing, max_steps=max_steps,
                   match_options=match_options or {}, stamp=_stamp(path)) for path in paths]
    return _finish(out, _run(tasks, workers, scheduler, client, progress), ["input", "object"])


def _drawn_on(csv_path) -> int | None:
    """The one frame (axis-0) the contours of a shapes CSV lie on, or None for 2D ones."""
    _, leading = read_shapes_csv(csv_path, leading=True)
    return drawn_frame(leading, csv_path)


def drawn_frame(leading, name) -> int | None:
    """The one frame that contours with leading coordinates ``leading`` (as
    :func:`~napari_physeg.io.read_shapes_csv` gives them) lie on, or None for 2D
    ones; ``name`` names the contours in the message."""
    frames = [lead[0] for lead in leading if lead]
    between = [f for f in frames if abs(f - round(f)) > 1e-6]
    if between:  # rounded, it would name a frame the user did not draw on
        raise ValueError(f"a contour of {name} lies at axis-0 = {between[0]:g}, between frames: draw the "
                         "contours on a frame (in a Shapes layer of the image's scale), or say which with start "
                         "(--start)")
    drawn = sorted({int(round(f)) for f in frames})
    if len(drawn) > 1:
        raise ValueError(f"the contours of {name} lie on frames {drawn}: draw them all on one frame, "
                         "or say which with start (--start)")
    return drawn[0] if drawn else None


def _checked_run(inputs, inits, out):
    """Inputs that exist, contours as tuples of float lists, a writable out."""
    from .core.contour import as_drawing

    # Absolute: the workers of a cluster may start elsewhere (the files on a shared file system).
    # One path is one input (a string is not a list of its letters).
    paths = [str(Path(p).absolute()) for p in ([inputs] if isinstance(inputs, (str, os.PathLike)) else inputs)]
    if not paths:
        raise ValueError("no input file given")
    missing = [p for p in paths if not Path(p).exists()]
    if missing:
        more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
        raise ValueError(f"no such input: {', '.join(missing[:3])}{more}")
    folders = [p for p in paths if Path(p).is_dir() and not is_zarr(Path(p))]
    if folders:
        raise ValueError(f"{folders[0]} is a folder, not an image or a zarr store: give the files in it "
                         f"(e.g. {Path(folders[0]) / '*.tif'})")
    seen: dict[str, str] = {}
    for p in paths:
        if _name(p) in seen:
            same = "is given twice" if seen[_name(p)] == p else f"is the same file as {seen[_name(p)]}"
            raise ValueError(f"the input {p} {same}: give each file once")
        seen[_name(p)] = p
    out = Path(out).absolute()
    check_inputs_kept(out, paths + ([inits] if isinstance(inits, (str, Path)) else []))
    if isinstance(inits, (str, Path)):
        inits = read_shapes_csv(inits)
    inits = tuple(as_drawing(c, name=f"contour {k}").tolist() for k, c in enumerate(inits))
    if not inits:
        raise ValueError("no initial contour given")
    check_writable(out, folder=True)
    return paths, inits, out


def _check_installed(client) -> None:
    """The batch extra's packages (a client given brings its own dask.distributed), before anything is written."""
    for module in ("pandas", "tqdm") + (("distributed",) if client is None else ()):
        try:
            __import__(module)
        except ImportError:
            raise ValueError(f'the batch needs the {module} package, which is not installed: pip install '
                             '"napari-physeg[batch]"') from None


def _check_scheduler(scheduler) -> None:
    """Connect to ``scheduler`` once, before anything is written: a wrong address is a bad argument."""
    if scheduler:
        with _client(None, scheduler, None):
            pass


def check_inputs_kept(out, inputs) -> None:
    """Raise ValueError if a batch in ``out`` would write over one of ``inputs`` (files or zarr
    folders): ``out`` itself, its settings and summary files, anything under ``out/results``
    (results are replaced when their input changes, and deleted with ``overwrite``)."""
    out = Path(out)
    written = [out / name for name in (_SETTINGS, f"{_SUMMARY}.csv", f"{_SUMMARY}.parquet")]
    results = (out / _RESULTS).resolve()
    for source in (Path(s) for s in inputs if s is not None):
        if not source.exists():
            continue
        where = source.resolve()
        if out.is_dir() and same_file(source, out):  # a file: check_writable says it is not a folder
            raise ValueError(f"the output folder {out} is also an input: write the results elsewhere")
        if any(same_file(source, w) for w in written) or where == results or results in where.parents:
            raise ValueError(f"the input {source} lies where the batch writes its results in {out}, and would "
                             "be replaced: move it, or choose another output folder")


def check_writable(path: Path, *, folder: bool = False) -> None:
    """Raise ValueError unless ``path`` (a file, or a folder to create) can be
    written: its nearest existing folder is a folder and accepts a new file."""
    path = Path(path)
    if path.exists() and folder != path.is_dir():
        raise ValueError(f"{path} exists and is {'a file' if folder else 'a folder'}: choose another output")
    parent = path if folder and path.exists() else path.parent
    while not parent.exists():  # a folder output: its missing parents are created
        if not folder:
            raise ValueError(f"cannot write {path}: the folder {parent} does not exist; create it first")
        parent = parent.parent
    if not parent.is_dir():
        raise ValueError(f"cannot write {path}: {parent} is not a folder")
    try:  # os.access says yes to root even on a read-only file system: try it
        with atomic_path(parent / ".napari-physeg-write-test") as probe:
            probe.write_bytes(b"")
        os.unlink(parent / ".napari-physeg-write-test")
    except OSError as err:
        raise ValueError(f"cannot write to {parent}: {err.strerror or err}; choose another output") from None


def _name(path) -> str:
    """The results folder of an input: its name and a digest of its absolute
    path (two plates' 'A01.tif' do not collide; the same file finds its results)."""
    path = Path(path)
    digest = hashlib.sha1(str(path.resolve()).encode()).hexdigest()[:8]
    return f"{path.name}-{digest}"


def _prepare_out(out: Path, settings: dict, inits, overwrite: bool) -> None:
    """Create ``out``; refuse to mix results of other settings (or clear them
    with ``overwrite``)."""
    settings = json.loads(json.dumps({**settings, "inits": _digest(inits)}, default=str))
    saved = out / _SETTINGS
    if out.exists() and any(out.iterdir()) and not saved.exists():
        raise ValueError(f"{out} is not empty and holds no batch results: choose another output folder")
    if overwrite:
        shutil.rmtree(out / _RESULTS, ignore_errors=True)
        for name in (_SETTINGS, f"{_SUMMARY}.csv", f"{_SUMMARY}.parquet"):
            with contextlib.suppress(FileNotFoundError):
                (out / name).unlink()
    elif saved.exists():
        before = json.loads(saved.read_text())
        if before != settings:
            changed = sorted(k for k in set(before) | set(settings) if before.get(k) != settings.get(k))
            raise ValueError(f"{out} holds results made with other settings ({', '.join(changed)}): "
                             "choose another output folder, or pass --overwrite to replace them")
    (out / _RESULTS).mkdir(parents=True, exist_ok=True)
    with atomic_path(saved) as tmp:
        tmp.write_text(json.dumps(settings, indent=1))


def _digest(inits) -> str:
    return hashlib.sha1(np.asarray(np.concatenate(inits), dtype=np.float64).tobytes()).hexdigest()[:16]


@contextlib.contextmanager
def _client(workers, scheduler, client):
    """The client to run on: the one given, one connected to ``scheduler``, or
    a local cluster of ``workers`` (an int, see _run) single-threaded processes."""
    if client is not None:
        yield client
        return
    from dask.distributed import Client, LocalCluster

    if scheduler:
        _check_address(scheduler)
        try:
            connected = Client(scheduler, timeout="10s", set_as_default=False)
        except (OSError, ValueError, TypeError) as err:  # refused, timed out, not an address
            raise ValueError(f"could not reach the dask scheduler at {scheduler}: {_one_line(err)}") from None
        with connected:
            yield connected
        return
    n = int(workers)
    if n < 1:
        raise ValueError(f"workers must be at least 1, got {workers!r}")
    # Processes, one thread each: the core is numpy/scipy code that holds the
    # GIL in places; dask's nannies pin BLAS to one thread in each. Not the
    # default client (set_as_default=False): dask computations elsewhere in
    # this process must not be sent to it, nor find it gone once it closes.
    # The scheduler serves HTTP whatever its dashboard setting (None still
    # binds 8787): on a free port, two batches at once do not clash.
    with LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, \
            Client(cluster, set_as_default=False) as local:
        local.run(_ignore_interrupt)
        yield local
        # The results are in: what dask logs while the cluster closes is no
        # news, and on a busy machine it is alarming (a worker's heartbeat
        # that meets the closed scheduler prints a traceback, dask/distributed
        # #7105; a nanny kills a worker slow to exit, with a warning). Not
        # after Ctrl-C or an error: the workers may be gone, and _gather
        # quiets this process's part then.
        local.run(_quiet_dask_logs)
        _quiet_dask_logs()  # this process's (the nannies'); _run restores it


def _check_address(scheduler) -> None:
    """Raise ValueError for a malformed scheduler address (no port, an unknown scheme), before a
    Client is made: Client() raises on one half-built, whose __del__ then waited 20 s at exit and
    printed a traceback."""
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, location = parse_address(str(scheduler))
        get_backend(scheme)  # an unknown scheme: ValueError naming the known ones
        if scheme in ("tcp", "tls", "ws", "wss"):  # host:port (inproc and ucx have their own forms)
            parse_host_port(location)
    except ValueError as err:
        raise ValueError(f"{scheduler!r} is not a dask scheduler address ({_one_line(err)}): give one such as "
                         "tcp://10.0.0.5:8786 or myhost:8786") from None


#: The loggers dask's cluster writes to (tornado's: its event loop's errors).
_DASK_LOGGERS = ("distributed", "tornado")


def _quiet_dask_logs() -> None:
    """Only dask's critical messages from now on, in this process."""
    for name in _DASK_LOGGERS:
        logging.getLogger(name).setLevel(logging.CRITICAL)


def _ignore_interrupt() -> None:
    """On a local cluster's workers: Ctrl-C reaches the terminal's whole process group, and the client
    alone is to handle it (it closes the cluster); a worker would print a traceback."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run(tasks, workers, scheduler, client, progress) -> list[dict]:
    """Run the tasks on the cluster; every task's rows (failed ones too)."""
    out_rows, todo = _pending(tasks)
    if not todo:
        return out_rows
    from tqdm.auto import tqdm

    n = default_workers() if workers is None else int(workers)
    levels = {name: logging.getLogger(name).level for name in _DASK_LOGGERS}
    try:
        with _client(min(n, len(todo)), scheduler, client) as c:  # a worker without a task only costs memory
            futures = {c.submit(_execute, task, key=f"napari-physeg-{task.name}-{uuid.uuid4().hex[:8]}",
                                pure=False): task for task in todo}
            bar = tqdm(total=len(tasks), initial=len(tasks) - len(todo), unit="task", disable=not progress,
                       file=sys.stderr, desc=todo[0].kind)
            new_rows = _gather(c, futures, bar)
    finally:
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)
    _warn(new_rows)
    return out_rows + new_rows


def _gather(c, futures: dict, bar) -> list[dict]:
    """The rows of the tasks as they finish; the bar closed however it ends (no bar redrawn after Ctrl-C)."""
    from dask.distributed import as_completed

    rows: list[dict] = []
    try:
        for future in as_completed(futures, loop=c.loop):  # c need not be the default client
            try:
                rows.extend(future.result())
            except Exception as err:  # noqa: BLE001 - e.g. KilledWorker: the task's workers kept dying
                rows.extend(futures[future].failed(_one_line(err)))
            bar.update(1)
    except BaseException as err:
        # Interrupted (Ctrl-C, a notebook's Interrupt kernel) or failed here: a cluster the caller gave runs on,
        # so the tasks not finished are cancelled (they went on writing results after the call had raised).
        c.cancel([future for future in futures if not future.done()])
        if isinstance(err, KeyboardInterrupt):  # a local cluster now closes with tasks running: no news
            logging.getLogger("distributed").setLevel(logging.ERROR)
        raise
    finally:
        bar.close()
    return rows


def _pending(tasks) -> tuple[list[dict], list]:
    """The rows of the tasks complete already, and the tasks to run. A result made from another file
    at the same path (replaced since) is deleted, and its task run again, with a warning."""
    rows, todo, changed = [], [], {}
    for task in tasks:  # complete ones need no cluster
        done = Path(task.out) / _RESULTS / task.name
        if _is_done(done, task):
            rows.extend(_read_rows(done))
            continue
        if (done / "rows.json").exists():
            if not _failed(done):
                changed[task.path] = task.kind
            shutil.rmtree(done)
        todo.append(task)
    for path, kind in changed.items():
        warnings.warn(f"{path} has changed since its results were made: {kind}ing it again", stacklevel=4)
    return rows, todo


def _warn(rows) -> None:
    """The warnings the tasks caught, here: one per input and message, naming the file (and frames)."""
    said: dict = {}
    for row in rows:
        for text in filter(None, str(row.get("warnings") or "").split(_SEP)):
            said.setdefault((row["input"], text), set()).add(row.get("frame"))
    for (path, text), frames in said.items():
        frames = sorted(t for t in frames if t is not None)
        where = f" (frame{'s' * (len(frames) > 1)} {', '.join(map(str, frames[:5]))}{', ...' * (len(frames) > 5)})"
        warnings.warn(f"{path}{where if frames else ''}: {text}", stacklevel=4)


def _finish(out: Path, rows: list[dict], keys: list[str]):
    """Write the summary (sorted, one row per key) and clear temporary folders."""
    import pandas as pd

    for tmp in (out / _RESULTS).rglob(".*.tmp-*"):  # left by tasks whose worker died
        shutil.rmtree(tmp, ignore_errors=True)
    table = pd.DataFrame(rows)
    # The rows of inputs an earlier run into ``out`` (with the same settings) did and this one did
    # not: their results stay in out/results, and the summary keeps saying so.
    earlier = out / f"{_SUMMARY}.csv"
    if earlier.exists() and len(table):
        before = pd.read_csv(earlier)
        table = pd.concat([before[~before["input"].isin(set(table["input"]))], table], ignore_index=True)
    # Nullable dtypes: a failed row's missing counts leave the others' integers whole.
    table = table.convert_dtypes()
    table = table.sort_values(keys, kind="stable").reset_index(drop=True)
    lead, last = [*keys, "status", "error"], ["host", "pid", "warnings"]  # the outcome first, then who ran it
    table = table[lead + [c for c in table.columns if c not in lead + last] + [c for c in last if c in table]]
    write_table(table, out / _SUMMARY)
    return table

"""The Tracking widget: contours drawn on one frame of a movie, followed through it.

Choose an image with a time axis (its first axis; the last two are the
frame's rows and columns) and a Shapes layer with contours drawn on any frame,
stand on that frame and press Run. The core's generator
:func:`~napari_physeg.core.iter_track` runs in napari's ``thread_worker``
(no second thread, no queue, see :func:`~._worker.relay`); at most one
object-frame every ``preview_interval`` seconds is passed on, to move the
progress bar and the live preview when the GUI can afford it. Cancel sends
the generator a stop: what was tracked is kept and becomes layers like a
finished run's.

The layers (:func:`tracking_layer_data`, no Qt) are what the ecosystem
expects: one Shapes layer with a polygon per object and frame (the frame as
leading coordinate, one colour per object), a Tracks layer with the objects'
centroids and sub-sampled node trajectories, and two Image layers, the
normal-velocity (protrusion/retraction) and curvature maps (frame x arc
position), the objects' side by side, with a Points layer numbering them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import napari
import numpy as np
from magicgui.widgets import ComboBox, Label, PushButton, SpinBox
from napari.layers import Points, Shapes
from napari.utils.notifications import show_info, show_warning
from skimage.util import montage

from ..core import LEFT, LOST, TRACKED, TrackingProgress, TrackingResult, iter_track, segment, track
from ._inputs import (MAP_NUMBERS_KEY, PHYSICS_TIPS, PREVIEW_COLOR, PREVIEW_KEY, PhysicsControls, check_plane_view,
                      contour_layer_choices, contrast_box, core_default, image_layer_choices, in_widget_terms,
                      nothing_drawn, off_image)
from ._layers import PointsAsClicks, image_transform_kwargs, shapes_to_image_coords, slice_index, slices_drawn_on
from ._worker import WorkerWidget, relay

__all__ = ["TrackingWidget", "tracking_layer_data", "node_trajectories"]

#: Colours cycled over the tracked objects.
OBJECT_COLOURS = ("#ff5555", "#55d4ff", "#ffd255", "#7dff7d", "#d77dff", "#ff9b4f", "#4fffd2", "#ff7dc8")


def node_trajectories(result: TrackingResult, k: int, n_points: int = 12) -> list[np.ndarray]:
    """``n_points`` points of object ``k``'s membrane followed through the
    correspondences: each an ``(M, 3)`` array of ``(frame, row, col)``.

    The points start evenly spaced on the start frame's contour and are
    followed forward (each frame, the node whose origin is nearest the point
    plus the point's offset from that origin) and backward (the origin of the
    nearest node), as far as the object is tracked.
    """
    start, contours, origins = result.start, result.contours[k], result.origin[k]
    if contours[start] is None:
        return []
    first = contours[start]
    paths = []
    for i in np.linspace(0, len(first), int(n_points), endpoint=False).astype(int):
        path = {start: first[i]}
        point = first[i]
        for t in range(start + 1, len(contours)):
            if contours[t] is None:
                break
            j = np.argmin(((origins[t] - point) ** 2).sum(1))
            point = contours[t][j] + (point - origins[t][j])
            path[t] = point
        point = first[i]
        for t in range(start - 1, -1, -1):
            if contours[t] is None:
                break
            j = np.argmin(((contours[t + 1] - point) ** 2).sum(1))
            point = origins[t + 1][j]
            path[t] = point
        paths.append(np.array([(t, *path[t]) for t in sorted(path)]))
    return paths


def tracking_layer_data(result: TrackingResult, transform: dict, *, name: str, frame_shape=None,
                        n_trajectories: int = 12, n_arc: int = 100) -> list[tuple]:
    """The output layers of a tracking run, as ``(data, meta, kind)`` tuples for ``Layer.create``.

    ``transform`` are the image's layer keyword arguments
    (:func:`~._layers.image_transform_kwargs`): the Shapes and Tracks layers
    overlay the image; the maps are images of their own (arc x frame), laid
    over a frame of ``frame_shape`` (rows, cols; default: their own size).
    """
    polygons, colours, features = [], [], {"object": [], "frame": [], "status": []}
    for k in range(result.n_objects):
        colour = OBJECT_COLOURS[k % len(OBJECT_COLOURS)]
        for t, c in enumerate(result.contours[k]):
            if c is None:
                continue
            polygons.append(np.column_stack([np.full(len(c), t, float), c]))
            colours.append(colour)
            features["object"].append(k)
            features["frame"].append(t)
            features["status"].append(result.status[k][t])
    common = _placement(transform)
    layers = [(polygons, dict(name=f"{name} contours", ndim=3, shape_type="polygon", edge_color=colours,
                              face_color="transparent", edge_width=1.5, features=features,
                              metadata={"tracking": result}, **common), "shapes")]
    tracks = []
    for k in range(result.n_objects):
        centres = result.centroids(k)
        frames = np.flatnonzero(np.isfinite(centres[:, 0]))
        if len(frames):
            tracks.append(np.column_stack([np.full(len(frames), len(tracks)), frames, centres[frames]]))
        for path in node_trajectories(result, k, n_trajectories):
            if len(path) > 1:
                tracks.append(np.column_stack([np.full(len(path), len(tracks)), path]))
    if tracks:
        layers.append((np.vstack(tracks), dict(name=f"{name} tracks", tail_length=10, **common), "tracks"))
    # One 2D layer per quantity, the objects' maps side by side (a montage,
    # numbered by a Points layer): 13 nuclei made 26 layers otherwise, 5 s to
    # add; stacked on a leading axis, the maps shared the movie's time slider,
    # which ran on past the movie's end when there were more objects than
    # frames, and stepped through objects as it stepped through frames.
    # Every object's map of either quantity is (frames, n_arc): one montage
    # shape, one placement, one numbering for both.
    grid, tile = _map_grid(result.n_objects), (result.n_frames, int(n_arc))
    placement = _map_placement(_montage_shape(grid, tile), transform, frame_shape)
    maps_added = []
    for quantity, colormap in (("normal_velocity", "bwr"), ("curvature", "PiYG")):
        maps = np.stack([result.membrane_map(k, quantity, n_arc=n_arc) for k in range(result.n_objects)])
        if not np.isfinite(maps).any():
            continue
        lim = float(np.nanpercentile(np.abs(maps), 98)) or 1.0
        tiled = montage(maps, fill=np.nan, grid_shape=grid, padding_width=MAP_PADDING)
        maps_added.append((tiled, dict(name=f"{name} {quantity.replace('_', ' ')} maps (frame x arc, per object)",
                                       colormap=colormap, contrast_limits=(-lim, lim), visible=False, **placement),
                           "image"))
    if maps_added:
        layers += maps_added + [_map_numbers(result.n_objects, tile, grid, placement, name)]
    return layers


#: Pixels of NaN that skimage's montage puts between the maps' tiles and around them.
MAP_PADDING = 1


def _montage_shape(grid, tile_shape) -> tuple[int, int]:
    """The shape of the montage of ``grid`` (rows, columns) tiles of ``tile_shape``."""
    return tuple(int(n * (side + MAP_PADDING) + MAP_PADDING) for n, side in zip(grid, tile_shape))


def _map_grid(n_maps: int) -> tuple[int, int]:
    """Rows and columns of tiles for ``n_maps`` maps side by side."""
    columns = int(np.ceil(np.sqrt(n_maps)))
    return int(np.ceil(n_maps / columns)), columns


def _map_numbers(n_maps: int, tile_shape, grid, placement: dict, name: str) -> tuple:
    """A Points layer that numbers the objects' tiles of the maps' montage
    (``grid`` rows and columns of tiles; object ``k`` is the ``k``-th tile, row
    by row), at each tile's first pixel."""
    step = np.asarray(tile_shape, float) + MAP_PADDING
    corners = np.array([divmod(k, grid[1]) for k in range(n_maps)], float) * step + MAP_PADDING
    return (corners, dict(name=f"{name} maps: object numbers", features={"object": np.arange(n_maps)},
                          metadata={MAP_NUMBERS_KEY: True},
                          text={"string": "{object}", "color": "white", "anchor": "upper_left", "size": 10},
                          size=0.1, face_color="transparent", border_width=0, visible=False, **placement),
            "points")


def _placement(transform: dict) -> dict:
    """The movie's transform and units for a layer of (frame, row, col) data:
    a layer in pixels among layers in (s, um, um) would take the viewer's
    units (scale bar, status bar) away."""
    return {key: transform[key] for key in ("scale", "translate", "rotate", "shear", "affine", "units")
            if key in transform}


def _map_placement(shape, transform: dict, frame_shape=None) -> dict:
    """Scale and translate that lay a 2D image of ``shape`` (the maps'
    montage) over the movie's field of view, on every frame: in pixels at
    the origin it stretched the view's extent."""
    scale = np.asarray(transform.get("scale", np.ones(2)), float)[-2:]
    translate = np.asarray(transform.get("translate", np.zeros(2)), float)[-2:]
    frame_shape = np.asarray(shape if frame_shape is None else frame_shape, float)
    # (napari's extent runs from the first pixel's centre to the last's)
    stretch = scale * np.maximum(frame_shape - 1, 1) / np.maximum(np.asarray(shape, float) - 1, 1)
    placement = {"scale": tuple(stretch), "translate": tuple(translate)}
    if "units" in transform:  # in the movie's units, as its frames: the viewer keeps them
        placement["units"] = tuple(transform["units"])[-2:]
    return placement


#: At most this many of a run's warnings are shown one by one; the rest in one.
MAX_WARNINGS_SHOWN = 3


def _grouped(messages: list, most: int = MAX_WARNINGS_SHOWN) -> list:
    """``messages``, the first ``most`` as they are and the rest in one that
    names the objects they are about: fifty drawings, 36 of them on the
    background, made 23 notifications one after the other."""
    if len(messages) <= most:
        return list(messages)
    rest = messages[most:]
    objects = [m.split()[1] for m in rest if m.startswith("object ") and m.split()[1].isdigit()]
    about = f" (object(s) {', '.join(objects)})" if len(objects) == len(rest) else ""
    return list(messages[:most]) + [f"... and {len(rest)} more warning(s) like these{about}"]


@dataclass
class _Failed:
    """The core's error, returned by :func:`track_movie` rather than raised:
    napari re-raises a worker's exceptions in the GUI thread, a traceback on
    top of the widget's own message."""

    error: Exception


def track_movie(run, cancel, interval: float = 0.0):
    """Drive the core's ``iter_track`` generator ``run`` in the worker (see
    :func:`~._worker.relay`); returns its :class:`TrackingResult`, or the
    error it raised in a :class:`_Failed`."""
    try:
        return (yield from relay(run, cancel, interval))
    except Exception as err:  # reported to the user by the widget
        return _Failed(err)


_TIPS = {
    **PHYSICS_TIPS,
    "image": "An image with a time axis: its first axis is time, its last two the frame.",
    "shapes": "Contours drawn on one frame of the movie (around or inside each object), or a Points layer with a "
              "click inside each object. Stand on that frame.",
    "max_steps": "Time steps per object and frame (each frame starts from the previous result).",
    "run": "Track the contours of the current frame through the whole movie (forward, then backward).",
    "cancel": "Stop: the frames tracked so far become layers.",
    "export": "Save the last run's tidy table as a CSV file, one row per object, frame and node: object, frame, "
              "node, row, col (the movie's pixels), arc position, normal velocity (px/frame, protrusion > 0), "
              "curvature, status and why an object is lost (reason); as napari-physeg track writes it.",
}


def _for_the_widget(message: str) -> str:
    """A warning of ``track()`` as the widget's user acts on it: no Python argument."""
    message = in_widget_terms(message).replace("TrackingResult.reason (the table's reason column)",
                              "The reason column of the table Save CSV writes")
    return re.sub(r"track from there \(start=(\d+)\)", r"press Run standing on frame \1", message)


class TrackingWidget(WorkerWidget):
    """Follow the objects of a Shapes layer through a movie (see the module's docstring)."""

    relay_warnings = False  # the result's warnings are shown

    def __init__(self, viewer: napari.viewer.Viewer):
        super().__init__(viewer)
        self.preview_interval = 0.1
        self.last_result: TrackingResult | None = None
        self.output_layers: list = []
        self._preview = None
        self._followed = self._start_frame = None  # (see _follow)
        self._run_info = None
        self._movie_name = None  # the last run's movie, for the file name the export suggests
        self._image = ComboBox(label="movie (image)", choices=self._image_choices, tooltip=_TIPS["image"])
        self._shapes = ComboBox(label="contours (shapes)", choices=self._shapes_choices, tooltip=_TIPS["shapes"])
        self.physics = PhysicsControls(segment, nodes=False)
        self._max_steps = SpinBox(label="steps per frame", value=core_default(track, "max_steps"), min=10,
                                  max=10000, step=50, tooltip=_TIPS["max_steps"])
        self._contrast = contrast_box()
        self._run_btn = PushButton(text="Run", tooltip=_TIPS["run"])
        self._cancel_btn = PushButton(text="Cancel", tooltip=_TIPS["cancel"], enabled=False)
        self._export_btn = PushButton(text="Save CSV…", tooltip=_TIPS["export"], enabled=False)
        self._status = Label(value="")
        self._lay_out([self._image, self._shapes, *self.physics.main], advanced=[self._contrast, self._max_steps],
                      buttons=[self._export_btn])
        self._export_btn.changed.connect(self._ask_export)
        self._connect_signals()

    # ------------------------------------------------------------ inputs
    def _image_choices(self, _widget=None):
        return image_layer_choices(self.viewer, min_ndim=3)

    def _shapes_choices(self, _widget=None):
        return [(name, layer) for name, layer in contour_layer_choices(self.viewer)
                if layer.metadata.get("tracking") is None]

    def _on_layers_changed(self, event=None):
        try:
            self.reset_choices()
        except RuntimeError:  # the Qt widget is gone (viewer closing)
            return

    def _read_input(self):
        image, shapes = self._image.value, self._shapes.value
        if image is None:
            raise ValueError("no movie: add an image layer with a time axis (its first axis)")
        if shapes is None:
            raise ValueError("no contours: add a Shapes layer and draw a contour around each object on one frame")
        frames = image.data[0] if image.multiscale else image.data
        if len(frames.shape) != 3:
            # (Not "Split Stack": it splits along the first axis, time, and a (T, Z, Y, X) movie became one
            # z-stack per time point, which this widget then tracked through z.)
            raise ValueError(f"the movie {image.name!r} has shape {tuple(frames.shape)}: the Tracking widget needs "
                             "(time, rows, cols): make an image of one z-plane or channel, or of a projection over "
                             f"z, e.g. in napari's console: viewer.add_image(viewer.layers[{image.name!r}].data"
                             "[:, 0]) or ...data.max(axis=1)" + (" (an RGB movie: right-click the layer > Split "
                                                                 "RGB)" if image.rgb else ""))
        point = tuple(self.viewer.dims.point)
        check_plane_view(len(point), self.viewer.dims.ndisplay, tuple(self.viewer.dims.order),
                         "track from the current frame")
        if isinstance(shapes, Points):  # its points on this frame: a click on each object
            shapes = PointsAsClicks(shapes, point)
        if (why := nothing_drawn(shapes, "track")) is not None:  # (not "go to the frame ...": nothing is drawn)
            raise ValueError(why)
        sliced = shapes_to_image_coords(shapes, image, world_point=point)
        if not sliced.contours and isinstance(shapes, Shapes) and len(drawn_on := slices_drawn_on(shapes)) == 1:
            # Drawn on one frame, not the one shown (napari opens a movie at its
            # middle frame): track from that frame, and show it.
            point = point[: len(point) - shapes.ndim] + drawn_on[0] + point[len(point) - 2:]
            self.viewer.dims.point = point
            sliced = shapes_to_image_coords(shapes, image, world_point=point)
        if sliced.refused:  # each drawing is an object: none is left out unsaid
            raise ValueError(sliced.refused[0])
        if not sliced.contours:
            raise ValueError(f"no contour of {shapes.name!r} lies on the current frame, and they lie on several "
                             "frames: go to the frame where every object is drawn")
        if sliced.off_slice:  # each drawing is an object: none is left out unsaid
            show_warning(f"{sliced.off_slice} shape(s) of {shapes.name!r} lie on other frames and are not tracked: "
                         "tracking starts from the frame you stand on, where every object must be drawn")
        contours = [c[:, -2:] for c in sliced.contours]
        for k, c in zip(sliced.indices, contours):  # it would be lost on every frame, for no visible reason
            outside = off_image(c, frames.shape, f"shape {k} of {shapes.name!r} lies outside the movie {image.name!r}")
            if outside:
                raise ValueError(outside)
        (start,) = slice_index(image, point, frames.shape)
        return image, frames, contours, start

    # ------------------------------------------------------------ run
    def run(self, *_):
        """Start tracking in napari's thread worker; returns the worker (None for bad input)."""
        if self._running:
            return None
        try:
            image, frames, contours, start = self._read_input()
        except ValueError as err:
            self._fail(str(err))
            return None
        self.last_result = None
        self.output_layers = []
        self._export_btn.enabled = False
        options = {k: v for k, v in self.physics.parameters().items() if k in ("material", "stiffness")}
        options["contrast"] = self._contrast.value
        material = getattr(options["material"], "name", options["material"])
        self._movie_name = image.name
        self._run_info = dict(transform=image_transform_kwargs(image), name=f"{image.name} tracked ({material})",
                              frame_shape=tuple(frames.shape[-2:]))
        self._followed, self._start_frame = None, start  # (see _follow)
        self._begin(f"Tracking {len(contours)} object(s) from frame {start}…")
        total = len(contours) * frames.shape[0]
        # Cancel stops after the current object and frame; what was tracked is kept.
        run = iter_track(frames, contours, start=start, max_steps=int(self._max_steps.value), segment_options=options)
        return self._start(total, track_movie, run, self._cancel, self.preview_interval)

    # ------------------------------------------------------------ worker signals (GUI thread)
    def _on_yielded(self, update: TrackingProgress):
        if not self._gui_alive():
            self._on_destroyed()
            return
        self.n_updates += 1
        self._advance(update.done)
        self._status.value = f"frame {update.frame}, object {update.object}: {update.status}"
        if update.contour is not None:
            self._show_preview(update)

    def _show_preview(self, update: TrackingProgress):
        data = [np.column_stack([np.full(len(update.contour), update.frame, float), update.contour])]
        if self._preview is None or self._preview not in self.viewer.layers:
            transform = self._run_info["transform"]
            common = _placement(transform)
            self._preview = self._add_preview(Shapes(data, shape_type="polygon", edge_color=PREVIEW_COLOR,
                                                     face_color="transparent", name="tracking preview",
                                                     metadata={PREVIEW_KEY: True}, **common))
        else:
            self._preview.data = data
        self._follow(update.frame)

    def _follow(self, frame: int):
        """Move the time slider to ``frame``, where the preview is drawn, so
        that it shows (it stayed on the start frame while the preview ran on:
        an outside tester saw no preview at all), unless the user moved the
        slider since it was last moved here."""
        axis = self.viewer.dims.ndim - 3
        if axis < 0 or self._preview is None:
            return
        if self._followed is not None and self.viewer.dims.current_step[axis] != self._followed:
            return  # the user looks at another frame: leave it
        world = np.asarray(self._preview.data_to_world(np.array([frame, 0.0, 0.0])), dtype=float)
        self.viewer.dims.set_point(axis, float(world[-3]))
        self._followed = self.viewer.dims.current_step[axis]

    def _remove_preview(self):
        if self._preview is not None and self._preview in self.viewer.layers:
            self.viewer.layers.remove(self._preview)
        self._preview = None

    def _on_returned(self, result: TrackingResult | _Failed):
        if isinstance(result, _Failed):
            return self._on_errored(result.error)
        self.last_result = result
        if not self._gui_alive():
            return
        for message in _grouped([_for_the_widget(m) for m in result.warnings]):
            show_warning(message)
        if not any(TRACKED in row for row in result.status):
            self._remove_preview()
            self._fail("Nothing was tracked: no object was found on the start frame (see the warnings); "
                       "draw around (or inside) each object on the frame you stand on")
            return
        self._follow(self._start_frame)  # back where the user drew (the result's layers hold every frame)
        preview, self._preview = self._preview, None
        try:
            self.output_layers = self._put_results(tracking_layer_data(result, **self._run_info), preview)
        except Exception as err:  # never a silent failure
            self._fail(f"Could not add the tracking layers: {type(err).__name__}: {err}")
            return
        self._export_btn.enabled = True
        counts = {s: sum(row.count(s) for row in result.status) for s in (TRACKED, LOST, LEFT)}
        done = {"cancelled": "cancelled: the frames tracked so far were kept",
                "frame error": "stopped at a frame that could not be used (see the warning): the frames tracked "
                               "so far were kept"}.get(result.stop_reason, "done")
        left = f", {counts[LEFT]} out of the field of view" if counts[LEFT] else ""
        textured = result.contrast.count("texture")
        by_texture = f", {textured} read by their texture" if textured else ""
        self._status.value = (f"{result.n_objects} object(s){by_texture}, {counts[TRACKED]} object-frames tracked, "
                              f"{counts[LOST]} lost{left} ({done}, {result.timings['total']:.1f} s)")
        show_info(f"Tracking: {self._status.value}. The membrane maps (frame x arc, one tile per object) are "
                  "hidden image layers")

    # ------------------------------------------------------------ export
    export_what = "tracks"

    def export_name(self) -> str:
        return f"{self._movie_name} {self.export_what}" if self._movie_name else self.export_what

    def export_table(self) -> dict:
        """The last run's tidy table (:meth:`~napari_physeg.core.TrackingResult.table`) as CSV columns."""
        if self.last_result is None:
            raise ValueError("nothing tracked to save yet: press Run first")
        table = self.last_result.table()
        return {name: table[name].to_numpy() for name in table.columns}

    def _on_errored(self, err: Exception):
        self._follow(self._start_frame)  # back where the user drew, as after a run
        self._remove_preview()
        self._fail(f"Tracking failed: {type(err).__name__}: {err}")

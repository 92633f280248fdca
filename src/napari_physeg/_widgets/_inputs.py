"""Inputs the widgets share: layer choices, the physics controls, and defaults.

Every default shown in a widget is read from the core function that uses it
(:func:`core_default`), and every physical meaning (what "node spacing" is,
which r suits a material) lives in the core; the widgets only lay them out.
No widget module imports another: what two widgets share lives here or in
:mod:`._layers`.
"""

from __future__ import annotations

import inspect
import re
from dataclasses import dataclass

import numpy as np
from magicgui.widgets import ComboBox, FloatSpinBox, SpinBox
from napari.layers import Image, Points, Shapes, Vectors

from ..core import MATERIALS, Material
from ..core.materials import suggested_stiffness
from ..core.segmentation import DEFAULT_NODE_SPACING, MAX_NODES, MIN_NODE_SPACING, drawing_nodes, nodes_at_spacing
from ._layers import PointsAsClicks, PointsAsPolygon, image_transform_kwargs, shape_in_layer_coords

__all__ = [
    "CUSTOM",
    "ContourPair",
    "MATCHING_KEY",
    "MatchingInputError",
    "SIMULATION_KEY",
    "InputError",
    "PHYSICS_TIPS",
    "PREVIEW_COLOR",
    "PREVIEW_KEY",
    "PhysicsControls",
    "contour_layer_choices",
    "core_default",
    "follow_matching",
    "image_layer_choices",
    "index_in_range",
    "is_matching_layer",
    "matching_fits",
    "node_count",
    "pick_default_b",
    "read_contour_pair",
]

#: Key in a layer's metadata that marks a temporary preview layer.
PREVIEW_KEY = "napari_physeg_preview"
#: Colour of the live previews: unlike the drawn contours (often yellow) and the results (cyan).
PREVIEW_COLOR = "magenta"
#: Key of the Matching in the output layer's metadata.
MATCHING_KEY = "matching"
#: Key in a layer's metadata that marks a simulation output (not a contour input).
SIMULATION_KEY = "simulation"
#: Key in a layer's metadata that marks the numbers of a tracking's membrane
#: maps (a Points layer, not a contour: read as one, its tile corners were a polygon).
MAP_NUMBERS_KEY = "map numbers"
#: The material choice that shows Young's modulus, Poisson's ratio and density.
CUSTOM = "custom"


#: Tooltips of the physics controls: what each parameter does, and typical values.
PHYSICS_TIPS = {
    "material": "Virtual material of the contour. Soft materials (rubber, soft tissue) move fast and follow "
                "details; stiff metals (aluminium, copper, steel) keep the contour smooth and need a larger "
                "stiffness r. Picking a preset sets a suggested r.",
    "young": "Young's modulus E of the custom material in MPa (rubber ~100, soft tissue ~0.1, "
             "copper ~117000). Higher E: stiffer, smoother, slower contour.",
    "poisson": "Poisson's ratio nu of the custom material, typically 0.25-0.49 (rubber 0.49, metals ~0.3). "
               "Couples stretching along and across the contour.",
    "density": "Mass density rho of the custom material in kg/m^3, typically 1000-9000 (rubber 1100, "
               "copper 8960). More mass: more inertia.",
    "stiffness": "Stiffness constant r (N/m) that scales the image forces: the force on a node is r times "
                 "its feature force. Typical: 2000 for rubber, 1e6 for copper or steel. Too low: the contour "
                 "barely moves; far too high: it may diverge.",
    "spacing": "Distance between nodes in pixels, typically 2-5. Smaller follows finer detail but is slower. "
               "The spacing is kept as the contour grows or shrinks.",
    "count": "Number of nodes of the initial contour, typically 50-500; 0 sets it from the node spacing.",
}


class InputError(ValueError):
    """Bad input to a widget; the message says what is wrong and how to fix it."""


def check_plane_view(n_world: int, ndisplay: int, dims_order=None, what: str = "segment the current 2D slice"):
    """Refuse a view in which the current 2D plane is not what the user sees:
    the 3D view, or displayed axes other than the last two (rows, columns)."""
    if ndisplay != 2:
        raise InputError(f"the viewer is in 3D view: switch to the 2D view (the square/cube button at the "
                         f"bottom left) to {what}")
    if dims_order is not None and set(tuple(dims_order)[-2:]) != {n_world - 2, n_world - 1}:
        raise InputError("the displayed plane is not the image's last two axes: reset the axis order "
                         "(the 'transpose'/'roll dimensions' buttons) so that rows and columns are displayed")


#: The core's words for a script's user, and what they are in the widgets
#: (an outside GUI tester was told of ``init``, ``np.argwhere`` and the
#: ``segment_options of track()``).
_WIDGET_TERMS = (
    (r"(?<![\w.'])init\b", "the drawing"),
    (r", or a mask's pixels as np\.argwhere lists them", ""),
    (r", or pass a mask's outline in order, e\.g\. skimage\.measure\.find_contours\(mask, 0\.5\)\[0\]", ""),
    (r"max_steps and segment_options of track\(\)", "the Tracking widget's steps per frame, material and stiffness"),
    (r",? \(?e\.g\. np\.nan_to_num(\([^)]*\))?\)?", ""),
    (r"contrast='(\w+)'", r"told by: \1 (Advanced)"),
)


def in_widget_terms(message: str) -> str:
    """A message of the core as a widget's user acts on it: no Python name."""
    for pattern, words in _WIDGET_TERMS:
        message = re.sub(pattern, words, message)
    return message


def nothing_drawn(layer, what: str) -> str | None:
    """Why the initial contours' ``layer`` (a Shapes layer, or a Points layer
    read as one polygon or as clicks, see PointsAsPolygon and PointsAsClicks)
    holds no contour, saying what to draw to ``what``; None when it holds one."""
    if isinstance(layer, PointsAsPolygon) and not layer.data:
        return (f"the Points layer {layer.name!r} has {layer.n_points} point(s) on this slice: a contour needs at "
                "least 3; click them around the object, in order")
    if isinstance(layer, PointsAsClicks) and not layer.data:
        return (f"the Points layer {layer.name!r} has no point on this slice: click once inside each object to "
                f"{what} (or draw around each in a Shapes layer)")
    if len(layer.data) == 0:
        return (f"the Shapes layer {layer.name!r} is empty: draw a polygon, lasso, ellipse or rectangle around (or "
                f"inside) the object to {what}, then press Run again")
    return None


def off_image(contour, shape, where: str) -> str | None:
    """Why ``contour`` (image data coordinates) cannot be an object of an
    image of ``shape`` (rows, cols): it lies wholly outside; None when it does not."""
    lo, hi = contour.min(0), contour.max(0)
    if np.all(hi >= 0) and np.all(lo <= np.asarray(shape[-2:], float) - 1):
        return None
    return (f"{where} (rows {lo[0]:.0f}..{hi[0]:.0f}, cols {lo[1]:.0f}..{hi[1]:.0f}; the image has {shape[-2]} x "
            f"{shape[-1]} pixels): draw it on the image, or give the two layers the same scale and translate")


def core_default(function, name: str):
    """The default of keyword ``name`` of the core ``function``: the one source of defaults."""
    return inspect.signature(function).parameters[name].default


def contrast_box() -> ComboBox:
    """The "told by" control of the Segmentation and Tracking widgets: segment()'s ``contrast``."""
    from ..core import segment
    from ..core.texture import CONTRASTS

    return ComboBox(label="told by", choices=list(CONTRASTS), value=core_default(segment, "contrast"),
                    tooltip="What tells the object from its background: its intensity (fluorescence, stains) or "
                            "its texture (flat cells in phase contrast or bright field, whose inside averages "
                            "the background's grey); 'auto' reads it from your drawing. With 'object is' bright "
                            "or dark, 'auto' is the intensity.")


def image_layer_choices(viewer, min_ndim: int = 2) -> list:
    """(name, layer) of the viewer's Image layers with at least ``min_ndim`` dimensions."""
    return [(layer.name, layer) for layer in viewer.layers if isinstance(layer, Image) and layer.ndim >= min_ndim]


def contour_layer_choices(viewer) -> list:
    """(name, layer) of the layers that can hold contours: Shapes, and Points
    (read as one polygon); not the widgets' previews, matchings, simulations
    or map numbers."""
    skip = {PREVIEW_KEY, MATCHING_KEY, SIMULATION_KEY, MAP_NUMBERS_KEY}
    return [(layer.name, layer) for layer in viewer.layers
            if isinstance(layer, (Shapes, Points)) and not (set(layer.metadata) & skip)]


class PhysicsControls:
    """The contour's physics as widgets: first the material preset, the
    image-force constant r and the node spacing; in :attr:`advanced` the
    custom material's constants and the node count.

    Choosing a preset sets r to :func:`~napari_physeg.core.materials.suggested_stiffness`.
    """

    def __init__(self, function, tips: dict = PHYSICS_TIPS, *, nodes: bool = True):
        self._material = ComboBox(label="material", choices=[*MATERIALS, CUSTOM],
                                  value=core_default(function, "material"), tooltip=tips["material"])
        rubber = MATERIALS["rubber"]
        self._young = FloatSpinBox(label="E (MPa)", value=rubber.young / 1e6, min=0.01, max=1e6, step=10.0,
                                   tooltip=tips["young"], visible=False)
        self._poisson = FloatSpinBox(label="Poisson ratio", value=rubber.poisson, min=-0.99, max=0.5, step=0.01,
                                     tooltip=tips["poisson"], visible=False)
        self._density = FloatSpinBox(label="density (kg/m³)", value=rubber.density, min=1.0, max=30000.0,
                                     step=100.0, tooltip=tips["density"], visible=False)
        self._stiffness = FloatSpinBox(label="stiffness r (N/m)",
                                       value=suggested_stiffness(core_default(function, "material")),
                                       min=1.0, max=1e10, step=100.0, tooltip=tips["stiffness"])
        self._spacing = FloatSpinBox(label="node spacing (px)", value=DEFAULT_NODE_SPACING, min=MIN_NODE_SPACING,
                                     max=50.0, step=0.5, tooltip=tips["spacing"])
        self._count = SpinBox(label="node count (0 = by spacing)", value=0, min=0, max=MAX_NODES, step=10,
                              tooltip=tips["count"])
        # The custom constants sit right under the material, shown only for "custom".
        self.main = [self._material, self._young, self._poisson, self._density, self._stiffness]
        self.main += [self._spacing] if nodes else []
        self.advanced = [self._count] if nodes else []
        self._material.changed.connect(self._on_material_changed)
        self._count.changed.connect(self._on_count_changed)

    def _on_material_changed(self, *_):
        name = self._material.value
        custom = name == CUSTOM
        for w in (self._young, self._poisson, self._density):
            w.visible = custom
        if not custom:
            m = MATERIALS[name]
            self._young.value = min(max(m.young / 1e6, self._young.min), self._young.max)
            self._poisson.value = m.poisson
            self._density.value = m.density
        self._stiffness.value = suggested_stiffness(self.material())

    def _on_count_changed(self, *_):
        self._spacing.enabled = self._count.value == 0

    def material(self) -> str | Material:
        """The ``material`` argument of the core: a preset name, or the custom :class:`Material`."""
        if self._material.value != CUSTOM:
            return self._material.value
        return Material(CUSTOM, young=float(self._young.value) * 1e6, poisson=float(self._poisson.value),
                        density=float(self._density.value))

    def parameters(self) -> dict:
        """``material`` and ``stiffness`` of the core, and the node ``node_spacing``
        (px) or ``n_nodes`` (None for the other), see :func:`node_count`."""
        count = int(self._count.value)
        if 0 < count < 3:  # (the spin box cannot leave out 1 and 2; the core said "n_nodes ... got 1")
            raise InputError(f"node count must be 0 (the nodes spaced by 'node spacing') or at least 3, got {count}")
        return {"material": self.material(), "stiffness": float(self._stiffness.value),
                "node_spacing": None if count else float(self._spacing.value), "n_nodes": count or None}


def node_count(contour, node_spacing: float | None = None, n_nodes: int | None = None) -> int | None:
    """The ``n_nodes`` argument of the core for one ``contour``: ``n_nodes`` as
    given, else as many as ``node_spacing`` px apart, else None (the core's default)."""
    if n_nodes is not None:
        return int(n_nodes)
    if node_spacing is None:
        return None
    try:
        return nodes_at_spacing(contour, node_spacing)
    except ValueError as err:
        raise InputError(str(err)) from None


def pick_default_b(layer_a, index_a, layer_b, index_b, candidates) -> None:
    """Make a and b two different shapes when the choice is obvious.

    With b's layer equal to a's: another layer for b when a's layer holds a
    single shape, else another index. (magicgui widgets; changed in place.)
    """
    a, b = layer_a.value, layer_b.value
    if a is None or b is not a:
        return
    others = [layer for _, layer in candidates if layer is not a]
    n_shapes = _shape_count(a)
    if n_shapes < 2 and others:
        layer_b.value = others[0]
    elif n_shapes >= 2 and index_a.value == index_b.value:
        index_b.value = 1 if index_a.value == 0 else 0


def index_in_range(layer_choice, index) -> None:
    """Bring ``index`` (a magicgui SpinBox of shape numbers) back within the
    shapes of the layer ``layer_choice`` holds, once that layer is chosen: a
    number left from another layer made the first Run fail (its maximum
    stays open: the user may draw more shapes)."""
    layer = layer_choice.value
    if layer is None:
        return
    n_shapes = _shape_count(layer)
    if index.value >= n_shapes:
        index.value = max(n_shapes - 1, 0)


def _shape_count(layer) -> int:
    """How many contours a Shapes or Points layer offers (a Points layer is one polygon)."""
    return 1 if isinstance(layer, Points) else len(layer.data)


def follow_matching(matching_layer, layer_a, index_a, layer_b, index_b, candidates) -> None:
    """Set a's and b's layers and shapes to those ``matching_layer``'s
    matching was computed for, where those layers are among ``candidates``
    (the choices, ``(name, layer)``): the simulation runs on the contours of
    the matching it says it uses."""
    meta = getattr(matching_layer, "metadata", None) or {}
    layers = {name: layer for name, layer in candidates}
    for name, index, layer_choice, index_box in (("a_layer", "a_index", layer_a, index_a),
                                                 ("b_layer", "b_index", layer_b, index_b)):
        if meta.get(name) in layers and isinstance(meta.get(index), (int, np.integer)):
            layer_choice.value = layers[meta[name]]
            index_box.value = int(meta[index])


class MatchingInputError(InputError):
    """Bad input to the matching (or simulation) widget."""


# --------------------------------------------------------------------------
# Two contours, and a matching made for them
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class ContourPair:
    """Two contours read from Shapes layers, in the first layer's data coordinates.

    Attributes
    ----------
    a, b : (N, 2) float64 ndarray
        ``(row, col)`` contours, closed, no repeated vertex.
    leading : tuple of float
        Leading (non-spatial) data coordinates of ``a`` in its layer (``()`` for 2D).
    transform : dict
        The first layer's transform, for output layers.
    a_layer, b_layer : str
        Names of the source layers.
    a_index, b_index : int
        Indices of the shapes in them.
    a_label, b_label : str
        Short names for output layers: the layer name, plus ``#index`` when
        the layer holds several shapes.
    """

    a: np.ndarray
    b: np.ndarray
    leading: tuple
    transform: dict
    a_layer: str
    a_index: int
    b_layer: str
    b_index: int
    a_label: str
    b_label: str


def _label(layer, index: int) -> str:
    one = isinstance(layer, Points) or len(layer.data) == 1
    return layer.name if one else f"{layer.name} #{index}"


def _read_one(layer, index: int, role: str, reference=None, world_point=None):
    if layer is None:
        raise MatchingInputError(
            f"no Shapes layer for contour {role}: open File > Open Sample > napari-physeg > Hand poses "
            "(matching), or draw closed shapes (polygon, ellipse, rectangle) in a Shapes layer and select it "
            f"in '{role}'")
    if isinstance(layer, Points):  # its points, in the order added, are one polygon
        layer = PointsAsPolygon(layer, world_point)
        if not layer.data:
            raise MatchingInputError(f"the Points layer {layer.name!r} ({role}) has {layer.n_points} point(s) on "
                                     "this slice: click at least 3 around the object, in order")
    elif not isinstance(layer, Shapes):
        raise MatchingInputError(f"{getattr(layer, 'name', layer)!r} is not a Shapes or Points layer; select "
                                 f"the layer with contour {role}")
    n = len(layer.data)
    if n == 0:
        raise MatchingInputError(f"the Shapes layer {layer.name!r} ({role}) is empty: draw a closed shape "
                                 "(polygon, lasso, ellipse or rectangle) in it, then press Run again")
    if not 0 <= int(index) < n:
        raise MatchingInputError(f"{layer.name!r} has {n} shape(s), numbered 0 to {n - 1}: set the shape index "
                                 f"of {role} to one of them (got {index})")
    try:
        contour, leading = shape_in_layer_coords(layer, int(index), reference, world_point)
    except ValueError as err:
        raise MatchingInputError(f"contour {role}: {err}") from None
    if len(contour) < 3:
        raise MatchingInputError(f"contour {role} (shape {index} of {layer.name!r}) has {len(contour)} distinct "
                                 "vertices: a contour needs at least 3; redraw it as a polygon or ellipse")
    if not np.all(np.isfinite(contour)):
        raise MatchingInputError(f"contour {role} (shape {index} of {layer.name!r}) has non-finite "
                                 "coordinates (NaN); redraw it")
    return drawing_nodes(contour), leading


def read_contour_pair(layer_a, index_a: int, layer_b, index_b: int, *, world_point=None,
                      roles=("a", "b")) -> ContourPair:
    """Read two closed contours for matching or simulation.

    Both are expressed in the DATA coordinates of ``layer_a`` (``b`` goes
    through world coordinates, so the layers may have different transforms),
    so output layers with ``layer_a``'s transform overlay the inputs.

    Parameters
    ----------
    layer_a, layer_b : napari.layers.Shapes
        May be the same layer (then with different indices).
    index_a, index_b : int
        Which shape of each layer.
    world_point : sequence of float, optional
        The viewer's current position, for world axes a layer lacks.
    roles : tuple of str
        What to call the two contours in messages.

    Raises
    ------
    InputError
        With a message that says how to fix the input: no or empty layer, an
        index out of range, a line or a shape with fewer than 3 vertices, the
        same shape twice.
    """
    ra, rb = roles
    if layer_a is not None and layer_a is layer_b and int(index_a) == int(index_b):
        raise MatchingInputError(
            f"{ra} and {rb} are the same shape (shape {index_a} of {layer_a.name!r}): choose another shape "
            f"index for {rb}, or another layer (e.g. the sample 'Hand poses' gives two outlines)")
    a, leading = _read_one(layer_a, index_a, ra, None, world_point)
    b, _ = _read_one(layer_b, index_b, rb, layer_a, world_point)
    return ContourPair(
        a=a, b=b, leading=leading, transform=image_transform_kwargs(layer_a),
        a_layer=layer_a.name, a_index=int(index_a), b_layer=layer_b.name, b_index=int(index_b),
        a_label=_label(layer_a, index_a), b_label=_label(layer_b, index_b),
    )


def is_matching_layer(layer) -> bool:
    """A layer made by :func:`matching_layer_data` (it holds a Matching in its metadata)."""
    return isinstance(layer, (Shapes, Vectors)) and layer.metadata.get(MATCHING_KEY) is not None


def matching_fits(metadata: dict, a, b, atol: float = 1e-3) -> bool:
    """Whether a matching layer's metadata was computed for the contours ``a`` and ``b``."""
    m = metadata.get(MATCHING_KEY)
    ca, cb = metadata.get("a_contour"), metadata.get("b_contour")
    if m is None or ca is None or cb is None:
        return False
    ca, cb = np.asarray(ca), np.asarray(cb)
    a, b = np.asarray(a), np.asarray(b)
    return (ca.shape == a.shape and cb.shape == b.shape and np.asarray(m.affinity).shape == (len(a), len(b))
            and bool(np.allclose(ca, a, atol=atol)) and bool(np.allclose(cb, b, atol=atol)))

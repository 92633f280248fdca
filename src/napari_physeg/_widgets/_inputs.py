"""Inputs the widgets share: layer choices, the physics controls, and defaults.

Every default shown in a widget is read from the core function that uses it
(:func:`core_default`), and every physical meaning (what "node spacing" is,
which r suits a material) lives in the core; the widgets only lay them out.
No widget module imports another: what two widgets share lives here or in
:mod:`._layers`.
"""

from __future__ import annotations

import inspect

from magicgui.widgets import ComboBox, FloatSpinBox, SpinBox
from napari.layers import Image, Points, Shapes

from ..core import MATERIALS, Material
from ..core.contour import nodes_for_spacing
from ..core.materials import suggested_stiffness
from ..core.segmentation import DEFAULT_NODE_SPACING

__all__ = [
    "CUSTOM",
    "InputError",
    "PHYSICS_TIPS",
    "PREVIEW_COLOR",
    "PREVIEW_KEY",
    "PhysicsControls",
    "contour_layer_choices",
    "core_default",
    "image_layer_choices",
    "node_count",
]

#: Key in a layer's metadata that marks a temporary preview layer.
PREVIEW_KEY = "napari_physeg_preview"
#: Colour of the live previews: unlike the drawn contours (often yellow) and the results (cyan).
PREVIEW_COLOR = "magenta"
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


def core_default(function, name: str):
    """The default of keyword ``name`` of the core ``function``: the one source of defaults."""
    return inspect.signature(function).parameters[name].default


def image_layer_choices(viewer, min_ndim: int = 2) -> list:
    """(name, layer) of the viewer's Image layers with at least ``min_ndim`` dimensions."""
    return [(layer.name, layer) for layer in viewer.layers if isinstance(layer, Image) and layer.ndim >= min_ndim]


def contour_layer_choices(viewer) -> list:
    """(name, layer) of the layers that can hold contours: Shapes, and Points
    (read as one polygon), except the widgets' temporary previews."""
    return [(layer.name, layer) for layer in viewer.layers
            if isinstance(layer, (Shapes, Points)) and not layer.metadata.get(PREVIEW_KEY)]


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
        self._stiffness = FloatSpinBox(label="stiffness r (N/m)", value=core_default(function, "stiffness"),
                                       min=1.0, max=1e10, step=100.0, tooltip=tips["stiffness"])
        self._spacing = FloatSpinBox(label="node spacing (px)", value=DEFAULT_NODE_SPACING, min=0.5, max=50.0,
                                     step=0.5, tooltip=tips["spacing"])
        self._count = SpinBox(label="node count (0 = by spacing)", value=0, min=0, max=5000, step=10,
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
        return nodes_for_spacing(contour, node_spacing)
    except ValueError as err:
        raise InputError(str(err)) from None

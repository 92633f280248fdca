"""Virtual materials for the physical contour model.

A :class:`Material` holds the physical constants of the elastic membrane that
models a contour (Young's modulus ``E``, Poisson's ratio ``nu``, mass density
``rho`` and a thickness ``h``) and derives the constants ``alpha``, ``beta`` and
``lambda`` of Sclaroff's isoparametric element (the paper's eqs. 7-9, see
``docs/physics.md``).

Units and scaling
-----------------
Lengths are measured in pixels and one pixel is taken as one metre; ``E`` is in
pascal and ``rho`` in kg/m^3, as in material tables. The membrane thickness is
the single scale factor that ties the two together: stiffness and mass both grow
linearly with ``h``, so ``h`` sets how far a force in newton moves the contour.
The default ``h = 2e-4 m`` (0.2 mm) was chosen so that the paper's settings are
sensible defaults that behave as the paper reports: rubber with a stiffness
constant ``r = 2000 N/m`` and copper with ``r = 1e6 N/m`` both reach an object's
border, rubber moves much faster than copper at equal ``r``, and the simulation
force constant ``q = 30000 N/m`` pulls a rubber contour onto its target.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

__all__ = ["Material", "MATERIALS", "DEFAULT_THICKNESS", "SUGGESTED_STIFFNESS", "get_material",
           "suggested_stiffness"]

#: Membrane thickness (m) that relates the paper's force constants to pixels.
DEFAULT_THICKNESS = 5e-6


@dataclass(frozen=True)
class Material:
    """An isotropic, linear elastic virtual material.

    Parameters
    ----------
    name : str
        A label for reports.
    young : float
        Young's modulus ``E`` in Pa (> 0).
    poisson : float
        Poisson's ratio ``nu``: in [0, 0.5) for plane strain, (-1, 0.5] for
        plane stress.
    density : float
        Mass density ``rho`` in kg/m^3 (> 0).
    thickness : float, optional
        Membrane thickness ``h`` in m (> 0); see the module docstring.
    plane : {"stress", "strain"}, optional
        Plane stress (a thin membrane, the default) or plane strain.

    Examples
    --------
    >>> rubber = MATERIALS["rubber"]
    >>> round(rubber.shear_modulus / 1e6, 2)  # E / (2 (1 + nu)), in MPa
    33.56
    """

    name: str
    young: float
    poisson: float
    density: float
    thickness: float = DEFAULT_THICKNESS
    plane: Literal["stress", "strain"] = "stress"

    def __post_init__(self):
        for field in ("young", "density", "thickness"):
            value = getattr(self, field)
            if not (value > 0 and value < float("inf")):
                raise ValueError(f"Material {field} must be a positive finite number, got {value!r}")
        if self.plane not in ("stress", "strain"):
            raise ValueError(f"Material plane must be 'stress' or 'strain', got {self.plane!r}")
        nu = self.poisson
        upper_ok = nu < 0.5 if self.plane == "strain" else nu <= 0.5
        if not (-1.0 < nu and upper_ok):
            bound = "[0, 0.5)" if self.plane == "strain" else "(-1, 0.5]"
            raise ValueError(
                f"Material poisson ratio must lie in {bound} for plane {self.plane}, got {nu!r}"
                + (" (plane strain is singular at nu = 0.5)" if self.plane == "strain" else "")
            )

    # --- constants of the element's constitutive matrix D = beta [[1, a, 0], [a, 1, 0], [0, 0, l]]
    @property
    def beta(self) -> float:
        """Scale of the constitutive matrix (Pa)."""
        E, nu = self.young, self.poisson
        if self.plane == "stress":
            return E / (1.0 - nu**2)
        return E * (1.0 - nu) / ((1.0 + nu) * (1.0 - 2.0 * nu))

    @property
    def alpha(self) -> float:
        """Off-diagonal (Poisson coupling) coefficient of D / beta."""
        nu = self.poisson
        return nu if self.plane == "stress" else nu / (1.0 - nu)

    @property
    def lam(self) -> float:
        """Shear coefficient of D / beta (the paper's lambda)."""
        nu = self.poisson
        return (1.0 - nu) / 2.0 if self.plane == "stress" else (1.0 - 2.0 * nu) / (2.0 * (1.0 - nu))

    @property
    def shear_modulus(self) -> float:
        """``beta * lambda = E / (2 (1 + nu))`` in Pa, the same in both plane models."""
        return self.beta * self.lam

    def with_(self, **changes) -> "Material":
        """Return a copy with some fields changed (e.g. ``thickness``)."""
        return replace(self, **changes)


#: Presets from standard material tables (E in Pa, rho in kg/m^3).
MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("rubber", young=0.1e9, poisson=0.49, density=1100.0),
        Material("soft tissue", young=0.1e6, poisson=0.45, density=1060.0),
        Material("aluminium", young=69e9, poisson=0.33, density=2700.0),
        Material("copper", young=117e9, poisson=0.34, density=8960.0),
        Material("steel", young=200e9, poisson=0.30, density=7850.0),
    )
}


def get_material(material: str | Material) -> Material:
    """Return a :class:`Material` from a preset name or a Material.

    Raises
    ------
    ValueError
        If ``material`` names no preset, or is neither a name nor a Material.
    """
    if isinstance(material, Material):
        return material
    if isinstance(material, str):
        key = material.strip().lower().replace("_", " ")
        if key in MATERIALS:
            return MATERIALS[key]
        raise ValueError(
            f"Unknown material {material!r}; choose one of {sorted(MATERIALS)} or pass a Material"
        )
    # (A ValueError as for any bad argument of segment, match, simulate and track.)
    raise ValueError(f"material must be a preset name ({', '.join(sorted(MATERIALS))}) or a Material, "
                     f"got {material!r}")


#: Image-force constant r (N/m) suggested for each preset: the paper's 2e3 for
#: rubber and 1e6 for copper (section 4.1); the stiffer metals get a little more.
#: A stiffer material needs a larger r to move the same distance per step.
SUGGESTED_STIFFNESS: dict[str, float] = {
    "rubber": 2e3,
    "soft tissue": 2e3,
    "aluminium": 1e6,
    "copper": 1e6,
    "steel": 2e6,
}


def suggested_stiffness(material: str | Material) -> float:
    """The image-force constant ``r`` (N/m) that suits ``material``.

    A preset gets its entry of :data:`SUGGESTED_STIFFNESS`. A custom material
    gets the preset value of the nearest preset in Young's modulus (on a log
    scale), since r must grow with the material's stiffness for the contour to
    move as far.
    """
    material = get_material(material)
    if material.name in SUGGESTED_STIFFNESS and MATERIALS.get(material.name) == material:
        return SUGGESTED_STIFFNESS[material.name]
    import math

    nearest = min(MATERIALS.values(), key=lambda m: abs(math.log(m.young / material.young)))
    return SUGGESTED_STIFFNESS[nearest.name]

import pytest

from napari_physeg.core.materials import MATERIALS, Material, get_material


@pytest.mark.parametrize("plane", ["stress", "strain"])
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_shear_modulus_is_the_same_in_both_plane_models(name, plane):
    m = MATERIALS[name].with_(plane=plane)
    assert m.shear_modulus == pytest.approx(m.young / (2 * (1 + m.poisson)))


def test_plane_stress_constants():
    m = Material("x", young=3.0, poisson=0.25, density=1.0)
    assert m.beta == pytest.approx(3.0 / (1 - 0.0625))
    assert m.alpha == 0.25 and m.lam == pytest.approx(0.375)


def test_presets_required_by_the_paper_exist_and_are_ordered_by_stiffness():
    for name in ("rubber", "copper", "steel", "soft tissue"):
        assert get_material(name).name == name
    assert MATERIALS["soft tissue"].young < MATERIALS["rubber"].young < MATERIALS["copper"].young < MATERIALS["steel"].young


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(young=-1.0), "young"),
        (dict(density=0.0), "density"),
        (dict(poisson=0.5, plane="strain"), "singular"),
        (dict(poisson=0.7), "poisson"),
        (dict(plane="membrane"), "plane"),
    ],
)
def test_bad_material_rejected(kwargs, message):
    args = dict(name="x", young=1.0, poisson=0.3, density=1.0) | kwargs
    with pytest.raises(ValueError, match=message):
        Material(**args)


def test_unknown_preset_lists_the_choices():
    with pytest.raises(ValueError, match="rubber"):
        get_material("unobtainium")
    assert get_material("Soft_Tissue") is MATERIALS["soft tissue"]


def test_suggested_stiffness_follows_the_paper_and_the_material_stiffness():
    from napari_physeg.core import MATERIALS, Material
    from napari_physeg.core.materials import suggested_stiffness

    assert suggested_stiffness("rubber") == 2e3 and suggested_stiffness("copper") == 1e6  # paper, section 4.1
    # A custom material gets the r of the preset nearest in Young's modulus.
    near_copper = Material("custom", young=100e9, poisson=0.3, density=8000.0)
    assert suggested_stiffness(near_copper) == suggested_stiffness("copper")
    near_rubber = Material("custom", young=0.05e9, poisson=0.49, density=1000.0)
    assert suggested_stiffness(near_rubber) == suggested_stiffness("rubber")
    assert all(suggested_stiffness(name) > 0 for name in MATERIALS)

import pytest

import translucent
from helpers import rd_total


def test_preset_albedo_matches_jensen_closed_form():
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    sp, sa = (2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)
    for c in range(3):
        expect = rd_total(sa[c], sp[c], 1.3)
        assert m.total_diffuse_reflectance[c] == pytest.approx(expect, rel=1e-9)


def test_preset_scale_converts_mm_to_scene_units():
    m = translucent.Material.preset("ketchup", mm_per_unit=1000.0)
    assert m.sigma_a[1] == pytest.approx(970.0)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(sigma_a=-1.0, sigma_s=1.0), "sigma_a"),
        (dict(sigma_a=0.1, sigma_s=float("nan")), "sigma_s"),
        (dict(sigma_a=0.1, sigma_s=1.0, eta=0.9), "eta"),
        (dict(sigma_a=0.1, sigma_s=1.0, g=1.0), "g"),
        (dict(sigma_a=(0.1, 0.2), sigma_s=1.0), "3 components"),
    ],
)
def test_bad_material_raises_value_error_naming_the_parameter(kwargs, words):
    with pytest.raises(ValueError, match=words):
        translucent.Material(**kwargs)


def test_unknown_preset_lists_known_names():
    with pytest.raises(ValueError, match="marble"):
        translucent.Material.preset("jade")

import math

import pytest

import translucent


def jensen_rd_total(alpha_prime: float, eta: float) -> float:
    """Jensen 2001's closed form, written out independently of the Rust code."""
    f_dr = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    a = (1 + f_dr) / (1 - f_dr)
    s = math.sqrt(3 * (1 - alpha_prime))
    return alpha_prime / 2 * (1 + math.exp(-4 / 3 * a * s)) * math.exp(-s)


def test_preset_albedo_matches_jensen_closed_form():
    m = translucent.Material.preset("marble", mm_per_unit=1.0)
    sp, sa = (2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)
    for c in range(3):
        expect = jensen_rd_total(sp[c] / (sp[c] + sa[c]), 1.3)
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

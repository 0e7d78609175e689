"""Cycles references are cached on disk by scene, material and settings (issue 5, point 2):
a second request returns the stored result without rendering; any change of input renders
again. Values are finite, non-negative, one per vertex."""

import pathlib
import sys

import numpy as np
import pytest

pytestmark = pytest.mark.bpy
sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "blender_scripts"))


def test_bakes_are_cached_and_keyed_by_their_inputs(empty_blend, tmp_path, monkeypatch):
    bpy = empty_blend
    import cycles_reference as cr

    import translucent

    monkeypatch.setattr(cr, "CACHE", tmp_path)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.05, segments=16, ring_count=8)
    obj = bpy.context.active_object
    light = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "POINT"))
    light.data.energy = 5.0
    light.location = (0.1, -0.2, 0.2)
    bpy.context.scene.collection.objects.link(light)
    m = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    first, seconds = cr.bake_vertices(obj, m, 2)
    assert first.shape == (len(obj.data.vertices), 3)
    assert np.all(np.isfinite(first)) and first.min() >= 0 and first.max() > 0
    assert len(list(tmp_path.glob("*.npz"))) == 1 and seconds > 0
    again, seconds_again = cr.bake_vertices(obj, m, 2)
    # Served from the cache: the stored wall time comes back (a new bake would time itself).
    assert seconds_again == seconds and len(list(tmp_path.glob("*.npz"))) == 1
    np.testing.assert_array_equal(again, first)
    # Another sample count, or a moved light, is another key: it bakes and stores again.
    cr.bake_vertices(obj, m, 3)
    assert len(list(tmp_path.glob("*.npz"))) == 2
    light.location.x += 0.01
    cr.bake_vertices(obj, m, 2)
    assert len(list(tmp_path.glob("*.npz"))) == 3
    assert obj.data.color_attributes.get("cycles_bake") is None, "the bake's attribute is removed"


def test_one_bakes_noise_is_read_from_several_seeds():
    """`cycles_gap.noise_of_one`: bakes that scatter about the truth by a known 10 % (Gaussian,
    per vertex and channel; 5 % in green) read as 10 % (5 %) noisy whatever the number of
    seeds, not the seeds' biased spread (8 seeds: 7 % low) and not their mean's."""
    import cycles_gap

    rng = np.random.default_rng(7)
    truth = rng.uniform(0.1, 2.0, (3000, 3))
    area = rng.uniform(0.5, 2.0, 3000)
    sigma = np.array([0.10, 0.05, 0.10])
    for seeds in (2, 8):
        bakes = [truth * (1 + sigma * rng.standard_normal(truth.shape)) for _ in range(seeds)]
        # Relative RMS about the mean: sqrt(sum w sigma^2 t^2 / sum w mean^2) = sigma (to 1/sqrt(N)).
        np.testing.assert_allclose(cycles_gap.noise_of_one(bakes, area), sigma, rtol=0.04)

"""The Cycles mapping (issue 5, point 1): (sigma_a, sigma_s, g, eta) to the Principled BSDF's
random-walk inputs of Blender 5.0.1 and back. Round trips; bad input; and Cycles itself as the
independent check: a thick slab rendered with the mapped material reflects the Base Color the
mapping produced (Cycles' random walk is fitted so that a semi-infinite slab's total diffuse
reflectance is the Base Color)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from translucent import cycles

coef = st.floats(1e-3, 1e4)
albedo = st.floats(0.3, 0.9999)  # reduced single-scattering albedo sigma_s / sigma_t


@settings(max_examples=300, deadline=None, derandomize=True)
@given(sigma_t=st.tuples(coef, coef, coef), a=st.tuples(albedo, albedo, albedo), g=st.floats(0.0, 0.9),
       eta=st.floats(1.01, 2.5))
def test_to_then_from_principled_is_the_identity(sigma_t, a, g, eta):
    sigma_s = tuple(t * x for t, x in zip(sigma_t, a))
    sigma_a = tuple(t * (1 - x) for t, x in zip(sigma_t, a))
    p = cycles.to_principled(sigma_a, sigma_s, g, eta)
    assert all(0.0 <= c <= 1.0 for c in p.base_color) and max(p.radius) == pytest.approx(1.0)
    sa, ss, g2, eta2 = cycles.from_principled(p.base_color, p.radius, p.scale, p.anisotropy, p.ior)
    np.testing.assert_allclose(ss, sigma_s, rtol=1e-6)
    np.testing.assert_allclose(np.array(sa) + ss, np.array(sigma_a) + sigma_s, rtol=1e-6)
    assert g2 == g and eta2 == eta


@settings(max_examples=300, deadline=None, derandomize=True)
@given(colour=st.tuples(*[st.floats(0.05, 0.99)] * 3), radius=st.tuples(*[st.floats(0.01, 1.0)] * 3),
       scale=st.floats(1e-4, 1e2), g=st.floats(0.0, 0.9))
def test_from_then_to_principled_is_the_identity(colour, radius, scale, g):
    sa, ss, g2, eta = cycles.from_principled(colour, radius, scale, g, 1.4)
    if max(s / (a + s) for a, s in zip(sa, ss)) > cycles.MAX_ALPHA - 1e-9:
        return  # a channel clamped by Cycles (Base Color above ~0.92 at g = 0): not invertible
    p = cycles.to_principled(sa, ss, g2, eta)
    np.testing.assert_allclose(p.base_color, colour, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(np.array(p.radius) * p.scale, np.array(radius) * scale, rtol=1e-6)


def test_radius_is_four_pi_times_the_mean_free_path():
    # bssrdf_setup_radius ("Random Walk"): d = radius scale / (4 pi), and sigma_t = 1 / d for g = 0.
    sa, ss, _, _ = cycles.from_principled((0.8, 0.8, 0.8), (1.0, 0.5, 0.25), 0.01, 0.0, 1.3)
    np.testing.assert_allclose(np.array(sa) + ss, [4 * math.pi / (r * 0.01) for r in (1.0, 0.5, 0.25)])
    # The remap grows with the albedo and stays in (0, 1).
    alphas = [cycles.single_scattering_albedo(x, 0.3) for x in np.linspace(0.01, 0.9, 50)]
    assert np.all(np.diff(alphas) > 0) and 0 < alphas[0] and alphas[-1] < 1.0


@pytest.mark.parametrize("kw", [dict(g=-0.2), dict(g=0.95), dict(eta=1.0), dict(eta=4.0),
                                dict(sigma_s=(0.0, 1.0, 1.0)), dict(sigma_a=(-1.0, 0.0, 0.0)),
                                dict(sigma_a=(math.nan, 0.0, 0.0))])
def test_what_cycles_cannot_represent_is_a_value_error(kw):
    args = dict(sigma_a=(0.1, 0.1, 0.1), sigma_s=(10.0, 10.0, 10.0), g=0.0, eta=1.3) | kw
    with pytest.raises(ValueError):
        cycles.to_principled(**args)


def test_low_single_scattering_albedo_is_flagged_inexact():
    assert cycles.to_principled((1.0, 0.1, 0.1), (0.1, 10.0, 10.0)).exact is False
    assert cycles.to_principled((0.1, 0.1, 0.1), (10.0, 10.0, 10.0)).exact is True


def ortho_cycles(bpy, ortho_scale, samples):
    """An orthographic camera `ortho_scale` wide as the scene's, Cycles on the CPU at
    `samples` spp, no denoising, 16 x 16 pixels (rendered with `cycles_reference.render_exr`)."""
    from blender_scripts.lib.cycles_reference import use_cycles

    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    cam.data.type, cam.data.ortho_scale = "ORTHO", ortho_scale
    scene = bpy.context.scene
    scene.collection.objects.link(cam)
    scene.camera = cam
    use_cycles(samples)
    scene.render.resolution_x = scene.render.resolution_y = 16
    scene.view_settings.view_transform = "Standard"
    return cam, scene


@pytest.mark.bpy
def test_a_thick_slab_in_cycles_is_what_the_walk_table_predicts(empty_blend):
    """A 1 m x 1 m x 0.5 m slab (mean free path 1-2 cm) under a uniform white world, seen from
    straight above, with Specular IOR Level 0 so only the subsurface part reflects: the centre
    pixels give the slab's total diffuse reflectance. Chiang's albedo fit leaves it 8-17 %
    darker than the Base Color (measured with Blender 5.0.1: 0.604, 0.433, 0.244 against
    0.655, 0.491, 0.292); the random-walk table (`slab_reflectance`, Cycles' walk simulated
    in a half-space, independent of this render) predicts it within 2 % per channel."""
    from blender_scripts.lib.cycles_reference import render_exr

    bpy = empty_blend
    p = cycles.to_principled((2.0, 6.0, 20.0), (60.0, 60.0, 60.0), 0.0, 1.3)
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, -0.25))
    slab = bpy.context.active_object
    slab.scale = (1.0, 1.0, 0.5)
    mat = bpy.data.materials.new("Slab")
    if mat.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    cycles.apply_to_principled(node, p)
    node.inputs["Specular IOR Level"].default_value = 0.0
    slab.data.materials.append(mat)
    world = bpy.data.worlds.new("W")
    if world.node_tree is None:  # Blender < 5.0 (5.0 always has nodes; use_nodes is deprecated)
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1, 1, 1, 1)
    bpy.context.scene.world = world
    cam, scene = ortho_cycles(bpy, 0.1, 128)
    cam.location = (0, 0, 1)
    px = render_exr(scene)[:, :, :3]
    measured = px.reshape(-1, 3).mean(axis=0)
    ratio = measured / np.array(p.base_color)
    assert np.all(ratio > 0.8) and np.all(ratio < 1.02), ratio
    p.specular_ior_level = 0.0
    predicted = np.array(p.material().slab_reflectance("cycles"))
    np.testing.assert_allclose(measured, predicted, rtol=0.02)


@pytest.mark.bpy
def test_volume_reference_material_holds_the_coefficients(empty_blend):
    """The second reference: Volume Scatter (density x colour = sigma_s, anisotropy g) plus
    Volume Absorption (density x (1 - colour) = sigma_a) inside a smooth Refraction BSDF of
    IOR eta; the coefficients read back from the nodes as Cycles defines them."""
    mat = cycles.make_volume_material("Milk", (0.5, 1.0, 3.0), (400.0, 500.0, 600.0), 0.3, 1.35)
    nodes = {n.type: n for n in mat.node_tree.nodes}
    sc, ab, glass = nodes["VOLUME_SCATTER"], nodes["VOLUME_ABSORPTION"], nodes["BSDF_REFRACTION"]
    sigma_s = np.array(sc.inputs["Color"].default_value[:3]) * sc.inputs["Density"].default_value
    sigma_a = (1 - np.array(ab.inputs["Color"].default_value[:3])) * ab.inputs["Density"].default_value
    np.testing.assert_allclose(sigma_s, (400.0, 500.0, 600.0), rtol=1e-6)
    np.testing.assert_allclose(sigma_a, (0.5, 1.0, 3.0), rtol=1e-6)
    assert sc.inputs["Anisotropy"].default_value == pytest.approx(0.3)
    assert glass.inputs["IOR"].default_value == pytest.approx(1.35)
    assert glass.inputs["Roughness"].default_value == 0.0
    out = nodes["OUTPUT_MATERIAL"]
    assert out.inputs["Volume"].is_linked and out.inputs["Surface"].links[0].from_node == glass


@pytest.mark.bpy
def test_a_slanted_view_of_a_block_in_cycles_is_what_the_walk_table_predicts(empty_blend):
    """A 40 cm block of ketchup (the preset at 1 mm = 1/1000 unit) under a sun along its normal,
    seen orthographically from 0, 60 and 75 degrees; the specular layer's own reflection taken
    off (the same render with Base Color black and Subsurface Weight 0). What the subsurface
    lobe sends grows toward slanted views (Cycles walks from the incoming ray refracted into
    the medium, and a shallow walk loses less), against what the specular layer leaves, which
    falls: the view factor (`slab_reflectance` at the view cosine, the walks simulated in a
    half-space, independent of this render) predicts it within 3 % per channel, and
    tests/helpers.py keeps these renders' figures."""
    import translucent
    from blender_scripts.lib.cycles_reference import render_exr
    from helpers import CYCLES_VIEW_KETCHUP

    bpy = empty_blend
    m = translucent.Material.preset("ketchup")
    bpy.ops.mesh.primitive_cube_add(size=0.4, location=(0, 0, -0.2))
    block = bpy.context.active_object
    mat = bpy.data.materials.new("Block")
    if mat.node_tree is None:  # Blender < 5.0
        mat.use_nodes = True
    node = mat.node_tree.nodes["Principled BSDF"]
    cycles.apply_to_principled(node, cycles.principled_for(m))
    block.data.materials.append(mat)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy, sun.data.angle = 1.0, 0.0
    bpy.context.scene.collection.objects.link(sun)
    world = bpy.data.worlds.new("Black")
    if world.node_tree is None:  # Blender < 5.0
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    bpy.context.scene.world = world
    cam, scene = ortho_cycles(bpy, 0.02, 256)

    def seen(deg):
        t = math.radians(deg)
        cam.location = (0, -0.5 * math.sin(t), 0.5 * math.cos(t))
        cam.rotation_euler = (t, 0, 0)
        px = render_exr(scene)[:, :, :3].astype(np.float64)
        return px.reshape(-1, 3).mean(axis=0)

    full = {deg: seen(deg) for deg in (0, 60, 75)}
    node.inputs["Base Color"].default_value = (0, 0, 0, 1)
    node.inputs["Subsurface Weight"].default_value = 0.0
    lobe = {deg: full[deg] - seen(deg) for deg in (0, 60, 75)}
    along = np.array(m.slab_reflectance("cycles", 1.0))
    for deg in (60, 75):
        measured = lobe[deg] / lobe[0]
        np.testing.assert_allclose(measured, CYCLES_VIEW_KETCHUP[deg], rtol=0.04, err_msg=f"{deg} degrees")
        predicted = np.array(m.slab_reflectance("cycles", math.cos(math.radians(deg)))) / along
        np.testing.assert_allclose(measured, predicted, rtol=0.03, err_msg=f"{deg} degrees")


def test_cycles_clamps_are_blenders_and_stated_once():
    """The clamps as Blender 5.0.1's Cycles source states them (kernel/closure/bssrdf.h:
    `bssrdf_setup` clamps anisotropy to [0, 0.9] and the IOR to [1.01, 3.8];
    kernel/integrator/subsurface_random_walk.h clamps the albedo to 0.999999 and walks below
    0.2 with 0.2), read through the one place the project keeps them."""
    import translucent

    assert translucent.CYCLES_CLAMPS == {"anisotropy": (0.0, 0.9), "ior": (1.01, 3.8), "albedo": (0.2, 0.999999)}
    assert (cycles.MIN_ALPHA, cycles.MAX_ALPHA) == (0.2, 0.999999)
    assert cycles.G_RANGE == (0.0, 0.9) and cycles.IOR_RANGE == (1.01, 3.8)
    # The walk refuses what lies outside, naming the clamp.
    with pytest.raises(ValueError, match=r"\[0(\.0)?, 0\.9\]"):
        cycles.to_principled((1.0,) * 3, (10.0,) * 3, g=0.95)
    with pytest.raises(ValueError, match=r"1\.01, 3\.8"):
        cycles.to_principled((1.0,) * 3, (10.0,) * 3, eta=4.0)

"""Issue 30, point 2: a Base Color driven by a link (a procedural, an image texture through the
UV map) is read per vertex by Cycles and each vertex scatters as its own medium. Two spheres
share the textured material under a sun; the add-on's preview against Cycles' vertex bake of
the same scene and material (128 spp, two seeds for its noise).

Measured (2 cm spheres, Subsurface Scale 5 mm, 128 spp): checker 7.3 / 5.5 / 3.6 % per channel,
where the same spheres with a uniform Base Color are 7.8 / 6.0 / 4.0 % from their own bake (the
walks' and the bake's noise); the socket's own value shown uniformly, as before, 68-106 %."""

import numpy as np
import pytest

from helpers import draw_panel, mesh_hash, read_preview

pytestmark = pytest.mark.bpy

COLOUR_A = (0.85, 0.45, 0.3)
COLOUR_B = (0.25, 0.4, 0.7)


def _material(bpy, source: str):
    mat = bpy.data.materials.new("Skin")
    nodes = mat.node_tree.nodes
    p = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
    p.inputs["Subsurface Weight"].default_value = 1.0
    p.inputs["Subsurface Scale"].default_value = 0.005
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    if source == "checker":
        tex = nodes.new("ShaderNodeTexChecker")
        tex.inputs["Scale"].default_value = 2.0
        tex.inputs["Color1"].default_value = (*COLOUR_A, 1.0)
        tex.inputs["Color2"].default_value = (*COLOUR_B, 1.0)
    else:
        # A float (linear) image: the left half of the UV square one colour, the right the other.
        img = bpy.data.images.new("Skin map", 64, 32, float_buffer=True)
        px = np.empty((32, 64, 4), np.float32)
        px[:, :32] = (*COLOUR_A, 1.0)
        px[:, 32:] = (*COLOUR_B, 1.0)
        img.pixels.foreach_set(px.ravel())
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = img
        tex.interpolation = "Closest"
    mat.node_tree.links.new(tex.outputs["Color"], p.inputs["Base Color"])
    return mat, tex


def _scene(bpy, source: str):
    mat, tex = _material(bpy, source)
    objs = []
    for x in (-0.03, 0.03):
        bpy.ops.mesh.primitive_uv_sphere_add(radius=0.02, segments=32, ring_count=16, location=(x, 0.0, 0.0))
        bpy.ops.object.shade_smooth()
        obj = bpy.context.active_object
        obj.data.materials.append(mat)
        objs.append(obj)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    sun.data.energy = 3.0
    sun.data.angle = 0.0
    sun.rotation_euler = (0.6, 0.3, 0.0)
    bpy.context.scene.collection.objects.link(sun)
    return mat, tex, objs


def _user_data(bpy, mat, objs):
    nodes = [(n.name, i.identifier, tuple(i.default_value) if hasattr(i.default_value, "__len__") else i.default_value)
             for n in mat.node_tree.nodes for i in n.inputs if hasattr(i, "default_value")]
    images = [(i.name, tuple(i.size), np.asarray(i.pixels[:]).tobytes()) for i in bpy.data.images]
    counts = tuple(len(c) for c in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.scenes,
                                    bpy.data.images))
    return [mesh_hash(o.data) for o in objs], nodes, images, counts, len(mat.node_tree.links)


def _against_cycles(bpy, s, objs, label: str):
    """The previews of `objs` against Cycles' 128-spp vertex bakes of the same scene (seed 0, a
    second seed for the bake's noise): within 6 % beyond the bake's noise and the preview's own
    estimate (the same spheres with a uniform Base Color: 7.8 % at 128 spp). The bakes and the
    errors per object, and the bake's noise."""
    import translucent
    from addon import export
    from blender_scripts.lib.cycles_reference import bake_diffuse_vertex_colors, use_cycles

    previews = [read_preview(o).copy() for o in objs]
    estimate = max(s.last_eval["error_estimate"])
    passes = {"DIRECT", "INDIRECT", "COLOR"}
    use_cycles(128, 0)
    bakes = [bake_diffuse_vertex_colors(o, passes) for o in objs]
    use_cycles(128, 1)
    areas = [export.export_scene([o])[0].vertex_areas[:, 0] for o in objs]
    again = bake_diffuse_vertex_colors(objs[0], passes)
    noise = max(translucent.relative_error(again, bakes[0], areas[0])["rms"]) / np.sqrt(2)
    errors = [max(translucent.relative_error(p, b, w)["rms"]) for p, b, w in zip(previews, bakes, areas)]
    print(f"{label}: textured preview vs Cycles {[f'{100 * e:.2f} %' for e in errors]}, Cycles' noise "
          f"{100 * noise:.2f} %, estimate {100 * estimate:.2f} %")
    for e in errors:
        assert e <= 0.06 + 2 * noise + estimate, (errors, noise, estimate)
    return bakes, errors, noise


@pytest.mark.parametrize("source", ["checker", "image"])
def test_a_textured_base_colour_matches_a_cycles_bake_of_the_textured_material(addon, source):
    import bpy
    import translucent
    from addon import export, session

    mat, tex, objs = _scene(bpy, source)
    before = _user_data(bpy, mat, objs)
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    s = session.SESSIONS[mat.name]
    label = "Checker Texture" if source == "checker" else "Image Texture"
    assert s.texture_message.startswith(f"Base Color from {label}: read by Cycles at 964 vertices")
    # The user's meshes, material, images and data-blocks as they were (the bake's copies gone).
    assert _user_data(bpy, mat, objs) == before
    bakes, errors, _ = _against_cycles(bpy, s, objs, source)

    # The link removed: the preview follows by itself to the socket's own value, uniformly (what
    # it showed before issue 30), which is far from the textured bake.
    mat.node_tree.links.remove(mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].links[0])
    bpy.context.view_layer.update()
    assert s.base_color is None
    uniform = [max(translucent.relative_error(read_preview(o), b, export.export_scene([o])[0].vertex_areas[:, 0])["rms"])
               for o, b in zip(objs, bakes)]
    assert min(uniform) > 3 * max(errors), (uniform, errors)


@pytest.mark.parametrize("method", ["HIERARCHY", "SPLAT"])
def test_the_hierarchy_and_the_splatting_follow_a_textured_base_colour(addon, method):
    # The same checker previewed by the hierarchy and by the splatting at the vertices: each
    # vertex's Base Color read by Cycles, the media at the checker's two colours summed and
    # blended per vertex (`radiance(base_color=...)`), against the same Cycles bake as PRT's.
    import bpy
    import translucent
    from addon import export, session

    mat, tex, objs = _scene(bpy, "checker")
    before = _user_data(bpy, mat, objs)
    mat.translucent.enabled = True
    mat.translucent.method = method
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    s = session.SESSIONS[mat.name]
    assert s.method == method.lower()
    assert s.texture_message.startswith("Base Color from Checker Texture: read by Cycles at 964 vertices")
    assert s.base_color is not None
    assert _user_data(bpy, mat, objs) == before
    bakes, errors, _ = _against_cycles(bpy, s, objs, f"{method.lower()}, checker")
    mat.node_tree.links.remove(mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].links[0])
    bpy.context.view_layer.update()
    assert s.base_color is None
    uniform = [max(translucent.relative_error(read_preview(o), b, export.export_scene([o])[0].vertex_areas[:, 0])["rms"])
               for o, b in zip(objs, bakes)]
    print(f"{method.lower()}, the socket's value shown uniformly: {[f'{100 * e:.2f} %' for e in uniform]}")
    assert min(uniform) > 3 * max(errors), (uniform, errors)


def test_a_texture_edit_is_read_again_by_itself(addon, monkeypatch):
    # The checker's colour changed: the depsgraph handler bakes the Base Color again (no
    # precompute) and the preview follows; a slider of the Principled node itself does not
    # bake again.
    import bpy
    from addon import session, textures

    bakes = []
    real = textures.bake_base_color
    monkeypatch.setattr(textures, "bake_base_color", lambda *a, **k: bakes.append(1) or real(*a, **k))

    mat, tex, objs = _scene(bpy, "checker")
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    s = session.SESSIONS[mat.name]
    first = read_preview(objs[0]).copy()
    colours = s.base_color.copy()
    tex.inputs["Color1"].default_value = (0.1, 0.1, 0.1, 1.0)
    bpy.context.view_layer.update()
    assert session.SESSIONS[mat.name] is s  # no new precompute
    dark = np.all(np.isclose(s.base_color, 0.1, atol=1e-4), axis=1)
    was_a = np.all(np.isclose(colours, COLOUR_A, atol=1e-4), axis=1)
    assert dark.sum() > 100 and np.array_equal(dark, was_a)
    now = read_preview(objs[0])
    n = len(now)
    assert np.all(now[was_a[:n]].sum(axis=1) < 0.5 * first[was_a[:n]].sum(axis=1) + 1e-6)
    assert len(bakes) == 2  # the precompute's and the edit's
    mat.node_tree.nodes["Principled BSDF"].inputs["Subsurface Scale"].default_value = 0.006
    bpy.context.view_layer.update()
    assert len(bakes) == 2 and not np.array_equal(read_preview(objs[0]), now)


@pytest.mark.parametrize("method", ["PRT", "HIERARCHY", "SPLAT"])
def test_a_textured_subsurface_weight_matches_a_cycles_bake(addon, method):
    # The Subsurface Weight from a checker (1 on one square, 0.1 on the other) under a uniform
    # Base Color: where it is low the diffuse lobe beside the walk takes over. Read by Cycles per
    # vertex and split per vertex (`Prt.radiance(subsurface_weight=...)`, the hierarchy's and
    # the splatting's `radiance(subsurface_weight=...)`), against Cycles' bake of the same
    # material.
    import bpy
    import translucent
    from addon import export, session

    mat, tex, objs = _scene(bpy, "checker")
    mat.translucent.method = method
    p = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.remove(p.inputs["Base Color"].links[0])
    p.inputs["Base Color"].default_value = (*COLOUR_A, 1.0)
    p.inputs["Subsurface Weight"].default_value = 0.5
    tex.inputs["Color1"].default_value = (1.0, 1.0, 1.0, 1.0)
    tex.inputs["Color2"].default_value = (0.1, 0.1, 0.1, 1.0)
    mat.node_tree.links.new(tex.outputs["Color"], p.inputs["Subsurface Weight"])
    before = _user_data(bpy, mat, objs)
    mat.translucent.enabled = True
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    s = session.SESSIONS[mat.name]
    assert s.method == method.lower()
    assert s.texture_message.startswith("Subsurface Weight from Checker Texture: read by Cycles at 964 vertices")
    assert s.base_color is None and s.subsurface_weight is not None
    assert _user_data(bpy, mat, objs) == before
    # The checker's values at the vertices (those on a square's edge read between the two).
    w = s.subsurface_weight
    low, high = np.isclose(w, 0.1, atol=1e-3), np.isclose(w, 1.0, atol=1e-3)
    assert low.sum() > 200 and high.sum() > 200 and (low | high).mean() > 0.7, "both squares on the spheres"
    assert w.min() >= 0.1 - 1e-3 and w.max() <= 1.0
    bakes, errors, noise = _against_cycles(bpy, s, objs, f"{method.lower()}, weight")

    # The link removed: the socket's own weight, 0.5, everywhere again, farther from the bake.
    mat.node_tree.links.remove(p.inputs["Subsurface Weight"].links[0])
    bpy.context.view_layer.update()
    assert s.subsurface_weight is None
    uniform = [max(translucent.relative_error(read_preview(o), b, export.export_scene([o])[0].vertex_areas[:, 0])["rms"])
               for o, b in zip(objs, bakes)]
    print(f"the socket's value shown uniformly: {[f'{100 * e:.2f} %' for e in uniform]}")
    # Beyond the bake's own noise (in quadrature): the 128-spp bakes are not the same from run
    # to run (their noise 3.5-4.0 %), which moved the raw ratio across 1.5 (7.28 against 5.05 %
    # in one clean run, 7.45 against 4.21 % in the next).
    def beyond(e):
        return np.sqrt(max(e * e - noise * noise, 0.0))

    assert min(map(beyond, uniform)) > 1.5 * max(map(beyond, errors)), (uniform, errors, noise)


def _uniform_scene(bpy):
    """`_scene`'s two spheres with the checker's link taken off the Base Color, the preview on:
    the material, the objects and its Principled BSDF node."""
    mat, _, objs = _scene(bpy, "checker")
    p = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.remove(p.inputs["Base Color"].links[0])
    mat.translucent.enabled = True
    return mat, objs, p


def _read_at_its_mean(addon, bpy, mat, obj, socket: str, span: tuple, before: float):
    """Links a Noise Texture (Scale 40) through a Map Range to `span` into the Principled input
    `socket` and precomputes; asserts the mean read lies in `span` away from `before`, that
    the panel's line says it is previewed at it and that no input is left "Connected, not
    followed". Returns `obj`'s preview, the mean, the panel's line and the Map Range node."""
    from addon import principled

    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    noise = nodes.new("ShaderNodeTexNoise")
    noise.inputs["Scale"].default_value = 40.0
    ramp = nodes.new("ShaderNodeMapRange")
    ramp.inputs["To Min"].default_value, ramp.inputs["To Max"].default_value = span
    links.new(noise.outputs["Fac"], ramp.inputs["Value"])
    links.new(ramp.outputs["Result"], nodes["Principled BSDF"].inputs[socket])
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    preview = read_preview(obj).copy()
    mean = principled.MEANS[mat.name][socket]
    assert span[0] < mean < span[1] and abs(mean - before) > 1e-3 * span[1], mean
    labels = draw_panel(addon, mat)
    line = next(t for t in labels if f"{socket} from Map Range: " in t)
    assert f"previewed at their mean {mean:.4g}: one medium, not per vertex yet" in line, line
    assert not any(t.startswith("Connected, not followed") for t in labels), labels
    return preview, mean, line, ramp


def test_a_linked_radius_and_scale_are_previewed_at_their_mean(addon):
    # A Subsurface Scale and Radius driven by links are read by Cycles at the vertices and
    # previewed at their mean (one medium: the transport is spaced for one radius). Driven by
    # constants through nodes (a Value node, a Combine XYZ), the preview is the one with those
    # values typed into the sockets (the same medium exactly: 1e-5). Driven by a Noise Texture,
    # the panel names the range, the mean and that it is not per vertex; the connected line no
    # longer lists them; and the preview is the one with the mean typed in.
    import bpy

    from addon import principled, session

    mat, objs, p = _uniform_scene(bpy)
    p.inputs["Subsurface Scale"].default_value = 0.004
    p.inputs["Subsurface Radius"].default_value = (1.0, 0.5, 0.25)
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    typed = read_preview(objs[0]).copy()
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    value = nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 0.004
    xyz = nodes.new("ShaderNodeCombineXYZ")
    for k, v in enumerate((1.0, 0.5, 0.25)):
        xyz.inputs[k].default_value = v
    p.inputs["Subsurface Scale"].default_value = 0.02  # stale values behind the links
    p.inputs["Subsurface Radius"].default_value = (0.1, 0.1, 0.1)
    links.new(value.outputs[0], p.inputs["Subsurface Scale"])
    links.new(xyz.outputs[0], p.inputs["Subsurface Radius"])
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    np.testing.assert_allclose(read_preview(objs[0]), typed, rtol=1e-5, atol=1e-7)
    means = principled.MEANS[mat.name]
    assert abs(means["Subsurface Scale"] - 0.004) < 1e-6, means
    textured, mean, line, ramp = _read_at_its_mean(addon, bpy, mat, objs[0], "Subsurface Scale", (0.002, 0.006), 0.004)
    assert "Subsurface Radius from Combine XYZ: (1, 0.5, 0.25) to (1, 0.5, 0.25)" in line, line
    assert session.SESSIONS[mat.name].texture_message
    links.remove(p.inputs["Subsurface Scale"].links[0])
    p.inputs["Subsurface Scale"].default_value = mean
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert mat.name not in principled.MEANS or "Subsurface Scale" not in principled.MEANS[mat.name]
    np.testing.assert_allclose(read_preview(objs[0]), textured, rtol=1e-4, atol=1e-7)
    # The hierarchy reads it too, at its mean (the stale socket value not used), and so does
    # the splatting at the vertices.
    links.new(ramp.outputs["Result"], p.inputs["Subsurface Scale"])
    p.inputs["Subsurface Scale"].default_value = 0.005
    mat.translucent.method = "HIERARCHY"
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    assert principled.MEANS[mat.name]["Subsurface Scale"] == pytest.approx(mean, rel=1e-5)
    assert principled.principled_inputs(mat).scale == pytest.approx(mean, rel=1e-5)
    from addon import textures

    principled.MEANS.pop(mat.name)
    line = textures.read(mat, session.SESSIONS[mat.name].info, "splat").message
    assert "Subsurface Scale from Map Range" in line, line
    assert principled.principled_inputs(mat).scale == pytest.approx(mean, rel=1e-5)


def test_a_linked_roughness_is_previewed_at_its_mean(addon):
    # A Roughness driven by a link is read by Cycles at the vertices and previewed at its mean
    # (one walk table: Cycles' walk enters through a rough interface of that Roughness, and
    # the specular layer over the exit is weighted by it). Through a Value node, with a stale
    # value behind the link, the preview is the one with the value typed in (1e-5), which the
    # stale one is not; through a Noise Texture, the one with the mean typed in, the panel
    # naming the range and the mean.
    import bpy

    from addon import principled

    mat, objs, p = _uniform_scene(bpy)
    p.inputs["Roughness"].default_value = 0.9
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    stale = read_preview(objs[0]).copy()
    p.inputs["Roughness"].default_value = 0.3
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    typed = read_preview(objs[0]).copy()
    assert np.abs(typed - stale).max() > 1e-3 * typed.max()
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    value = nodes.new("ShaderNodeValue")
    value.outputs[0].default_value = 0.3
    p.inputs["Roughness"].default_value = 0.9  # stale behind the link
    links.new(value.outputs[0], p.inputs["Roughness"])
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    np.testing.assert_allclose(read_preview(objs[0]), typed, rtol=1e-5, atol=1e-7)
    assert abs(principled.MEANS[mat.name]["Roughness"] - 0.3) < 1e-6
    textured, mean, _, _ = _read_at_its_mean(addon, bpy, mat, objs[0], "Roughness", (0.2, 0.6), 0.3)
    links.remove(p.inputs["Roughness"].links[0])
    p.inputs["Roughness"].default_value = mean
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    np.testing.assert_allclose(read_preview(objs[0]), textured, rtol=1e-4, atol=1e-7)

"""Pressing Precompute with a window (issue 29, point 4): with Cycles' profile a first preview
(no walks, fewer samples, a cheap own light) is shown while the walks run, says so in the
panel, takes slider edits, and is replaced by the full precompute when it is done; the user's
mesh is not written. Driven the way the modal operator drives it, in headless Blender (which
runs no modal loop): the job built by `jobs.start(first_preview=True)`, the first preview shown
by `edits.show_first`, the job finished by `edits.finish`, on a scene with a floor beside the
previewed sphere."""

import numpy as np
import pytest

from helpers import draw_panel, key_light, mesh_hash, read_preview

pytestmark = pytest.mark.bpy


def test_a_first_preview_is_shown_while_the_walks_run_then_replaced(addon):
    import bpy

    from addon import edits, jobs, session

    mat = bpy.data.materials.new("Wax")
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=24, ring_count=12)
    obj = bpy.context.active_object
    obj.data.materials.append(mat)
    bpy.ops.mesh.primitive_plane_add(size=0.5, location=(0.0, 0.0, -0.05))
    floor = bpy.context.active_object
    key_light(bpy)
    s = mat.translucent
    s.enabled = True
    s.preset = "MARBLE"
    before = mesh_hash(obj.data), mesh_hash(floor.data)

    job, objects, info, lighting = jobs.start(mat, method="prt", first_preview=True)
    assert objects == [obj.name], "the floor does not carry the material"
    job.run_here()
    assert job.error is None, job.error
    assert job.first is not None and job.first.report["first_preview"] and job.first_seconds > 0
    assert job.first.report["walks"] is None and job.result.report["walks"] is not None

    edits.show_first(mat, job, objects, info, lighting)
    first_sess = session.SESSIONS[mat.name]
    assert first_sess.transport is job.first
    first = read_preview(obj)
    lines = draw_panel(addon, mat)
    assert any(line.startswith("first preview after") and "refining" in line for line in lines), lines
    assert any("walks through the mesh (first preview" in line for line in lines), lines
    # A slider edit on the first preview: more absorption darkens every channel.
    s.sigma_a = tuple(1.5 * c for c in s.sigma_a)
    edits.edit(mat)
    assert np.all(read_preview(obj).mean(axis=0) < first.mean(axis=0))

    s.sigma_a = tuple(c / 1.5 for c in s.sigma_a)
    edits.finish(mat, job, objects, info, lighting)
    full_sess = session.SESSIONS[mat.name]
    assert full_sess.transport is job.result and not full_sess.method_message.startswith("first preview")
    full = read_preview(obj)
    # The full preview adds the walks (light round the sphere's curve) and the own light;
    # the first preview is the half-space answer, within 20 % of it on this sphere.
    rel = np.sqrt(np.mean((first - full) ** 2) / np.mean(full**2))
    print(f"first preview after {job.first_seconds:.2f} s, {100 * rel:.1f} % from the full preview")
    assert rel < 0.2, rel
    assert (mesh_hash(obj.data), mesh_hash(floor.data)) == before

"""The installable extension: `make addon` builds a zip that installs into (headless) Blender,
enables, and runs a precompute from the installed copy."""

import os
import subprocess
import sys
import textwrap

import pytest

from conftest import REPO

pytestmark = [pytest.mark.bpy, pytest.mark.slow]


def test_extension_zip_installs_enables_and_precomputes(tmp_path):
    build = subprocess.run(
        [sys.executable, str(REPO / "blender_scripts" / "build_extension.py"), "--out", str(tmp_path / "dist")],
        capture_output=True, text=True, timeout=900,
    )
    assert build.returncode == 0, build.stderr[-3000:]
    zip_path = build.stdout.strip().splitlines()[-1]
    script = textwrap.dedent(f"""
        import bpy, sys
        r = bpy.ops.extensions.package_install_files(filepath={zip_path!r}, repo="user_default", enable_on_install=True)
        assert r == {{"FINISHED"}}, r
        assert "bl_ext.user_default.translucent" in bpy.context.preferences.addons
        assert sys.modules["bl_ext.user_default.translucent"].__file__.startswith({str(tmp_path)!r})
        bpy.ops.mesh.primitive_ico_sphere_add(radius=0.05, subdivisions=3)
        obj = bpy.context.active_object
        mat = bpy.data.materials.new("Skin")
        obj.data.materials.append(mat)
        light = bpy.data.objects.new("L", bpy.data.lights.new("L", "SUN"))
        bpy.context.scene.collection.objects.link(light)
        mat.translucent.enabled = True
        mat.translucent.preset = "SKIN1"
        assert bpy.ops.translucent.precompute(material_name="Skin") == {{"FINISHED"}}
        assert "translucent_preview" in obj.data.color_attributes
        print("EXTENSION OK")
    """)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "blender"))
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, env=env)
    assert "EXTENSION OK" in run.stdout, (run.stdout[-2000:], run.stderr[-3000:])

"""The wgpu evaluation path: same numbers as the CPU path (1e-5 relative), clear fallback."""

import numpy as np
import pytest

import translucent
from helpers import plane


def lit_plane():
    p, t = plane(61, 0.1)
    s = translucent.Scene(p, t)
    s.add_spot_light((0.0, 0.0, 0.05), (0, 0, -1), power=5.0, spot_size=1.2, blend=0.3, color=(1.0, 0.6, 0.3))
    s.set_world(color=(0.02, 0.03, 0.05))
    return s


def test_gpu_and_cpu_edits_agree():
    s = lit_plane()
    skin = translucent.Material.preset("skin1")
    prt = translucent.Prt(s, skin, backend="cpu", world_samples=16)
    assert prt.backend == "cpu"
    try:
        message = prt.set_backend("gpu")
    except RuntimeError as e:
        pytest.skip(f"no Vulkan adapter: CI installs Mesa's lavapipe ({e})")
    assert prt.backend == "gpu" and message.startswith("GPU")
    for m in (skin, translucent.Material.preset("ketchup"), translucent.Material(0.0, 5e4, g=0.9)):
        gpu = prt.radiosity(m)
        assert prt.last_eval["backend"] == "gpu" and prt.last_eval["dispatch_seconds"] > 0
        prt.set_backend("cpu")
        cpu = prt.radiosity(m)
        prt.set_backend("gpu")
        np.testing.assert_allclose(gpu, cpu, rtol=1e-5, atol=1e-6 * float(cpu.max()))


def test_f16_transport_states_its_error_and_keeps_within_it():
    s = lit_plane()
    m = translucent.Material.preset("skin1")
    prt = translucent.Prt(s, m, backend="cpu", world_samples=16)
    cpu = prt.radiosity(m)
    try:
        prt.set_backend("gpu", half=True)
    except RuntimeError as e:
        pytest.skip(f"no Vulkan adapter: {e}")
    half = prt.radiosity(m)
    bound = prt.last_eval["transport_f16_error"]
    assert 0 < bound < 1e-3
    err = translucent.relative_error(half, cpu, s.vertex_areas)
    assert max(err["rms"]) <= bound


def test_auto_backend_says_what_it_chose_and_bad_names_are_rejected():
    s = lit_plane()
    m = translucent.Material.preset("marble")
    prt = translucent.Prt(s, m, world_samples=16)
    assert prt.backend in ("cpu", "gpu")
    assert prt.backend_message.startswith("GPU" if prt.backend == "gpu" else "CPU")
    with pytest.raises(ValueError, match="backend"):
        prt.set_backend("tpu")
    with pytest.raises(ValueError, match="backend"):
        translucent.Prt(s, m, backend="quantum")

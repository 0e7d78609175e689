"""Stiff and extreme inputs through the Python API: never NaN/Inf, never negative, never a
crash, whatever the material or scale (a first slice of the stability suite)."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import translucent


def sphere(n: int = 12, radius: float = 1.0):
    """A closed UV sphere: (n+1) rings x 2n segments, poles shared."""
    verts = [(0.0, 0.0, radius)]
    for i in range(1, n):
        th = math.pi * i / n
        for j in range(2 * n):
            ph = math.pi * j / n
            verts.append((radius * math.sin(th) * math.cos(ph), radius * math.sin(th) * math.sin(ph), radius * math.cos(th)))
    verts.append((0.0, 0.0, -radius))
    seg, last = 2 * n, len(verts) - 1
    ring = lambda i, j: 1 + (i - 1) * seg + (j % seg)  # noqa: E731
    tris = [(0, ring(1, j), ring(1, j + 1)) for j in range(seg)]
    for i in range(1, n - 1):
        for j in range(seg):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            tris += [(a, c, d), (a, d, b)]
    tris += [(last, ring(n - 1, j + 1), ring(n - 1, j)) for j in range(seg)]
    return np.array(verts, np.float32), np.array(tris, np.int64)


coefficient = st.one_of(st.just(0.0), st.floats(1e-3, 1e4))


@pytest.fixture(scope="module")
def marble_prt():
    p, t = sphere(12, 1.0)
    scene = translucent.Scene(p, t)
    scene.add_sun((0.3, 0.2, -1.0), irradiance=2.0)
    scene.add_point_light((2.0, -1.0, 1.5), power=50.0)
    scene.set_world(color=(0.1, 0.1, 0.1))
    return translucent.Prt(scene, translucent.Material.preset("marble", mm_per_unit=10.0), samples=20_000, world_samples=16)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sa=st.tuples(coefficient, coefficient, coefficient), ss=st.tuples(coefficient, coefficient, coefficient),
       g=st.floats(-0.99, 0.99))
def test_any_edit_gives_finite_non_negative_radiosity_and_error_estimate(marble_prt, sa, ss, g):
    m = translucent.Material(sa, ss, g=g, eta=1.3)
    b = marble_prt.radiosity(m)
    assert np.all(np.isfinite(b)) and np.all(b >= 0)
    est = marble_prt.last_eval["error_estimate"]
    assert all(math.isfinite(e) and e >= 0 for e in est)
    # Energy: nothing leaves a surface that never arrived (R_d,total <= 1 per channel).
    assert all(0.0 <= r <= 1.0 for r in m.total_diffuse_reflectance)


@settings(max_examples=25, deadline=None)
@given(sa=st.tuples(coefficient, coefficient, coefficient), ss=st.tuples(coefficient, coefficient, coefficient),
       eta=st.floats(1.0, 2.5), scale=st.sampled_from([1e-4, 1e-2, 1.0, 1e2, 1e4]),
       degree=st.sampled_from([1, 2]))
def test_precompute_survives_extreme_materials_and_scales(sa, ss, eta, scale, degree):
    p, t = sphere(6, scale)
    scene = translucent.Scene(p, t)
    scene.add_sun((0.0, 0.0, -1.0), irradiance=1.0)
    m = translucent.Material(sa, ss, g=0.0, eta=eta)
    prt = translucent.Prt(scene, m, degree=degree, samples=2_000)
    b = prt.radiosity(m)
    assert np.all(np.isfinite(b)) and np.all(b >= 0)
    # Lit from above, the top can hold at most R_d,total x the light it receives.
    irr = scene.irradiance(eta=eta)
    top = int(np.argmax(p[:, 2]))
    total = np.array(m.total_diffuse_reflectance)
    assert np.all(b[top] <= total * irr[top].max() * 1.05 + 1e-6)

"""Each object its own medium (issue 30 point 4): two objects merged into one Scene with
`objects=` exchange no light through PRT's transport. Expected values: the dipole's half-plane
integral (helpers.half_plane, from its closed-form disc integral), independent of the code under
test: two sun-lit grids meeting at x = 0, a vertex at a distance d from the other object gathers
E_in (R_total - H(d)); without `objects` it gathers E_in R_total, as one plane does."""

import numpy as np
import pytest

import translucent
from helpers import assert_own_half_plane, entering, half_plane, rd_total


def two_grids(n=41, size=0.2):
    """Two n x n grids side by side, x in [-size, 0] and [0, size], their meeting column
    doubled (each object has its own vertices there): positions, triangles, objects."""
    xs = np.linspace(0.0, size, n, dtype=np.float32)
    x, y = np.meshgrid(xs, xs - size / 2)
    grid = np.stack([x.ravel(), y.ravel(), np.zeros(n * n, np.float32)], axis=1)
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    left = grid.copy()
    left[:, 0] -= size
    p = np.concatenate([left, grid])
    t = np.concatenate([tris, tris + n * n])
    objects = np.repeat([0, 1], n * n)
    return p, t, objects


def lit(p, t, objects=None):
    s = translucent.Scene(p, t, objects=objects)
    s.add_sun((0.0, 0.0, -1.0), irradiance=3.0)
    return s


def test_two_touching_objects_gather_no_light_from_each_other():
    p, t, objects = two_grids()
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    prt = translucent.Prt(lit(p, t, objects), m, profile="dipole")
    b = prt.radiosity(m)
    assert prt.report["skipped_other_object"] > 0
    e_in = entering(m.eta, 1.0, 3.0)
    row = np.abs(p[:, 1]) < 1e-6
    assert assert_own_half_plane(b, p, m, e_in) > 80
    # On the seam itself each object's vertex is on its own rim: half the plane's, H(0) = R_total / 2.
    seam = np.flatnonzero(row & (np.abs(p[:, 0]) < 1e-6))
    assert len(seam) == 2
    for c in range(3):
        half = 0.5 * e_in * rd_total(m.sigma_a[c], (1 - m.g) * m.sigma_s[c], m.eta)
        np.testing.assert_allclose(b[seam, c], half, rtol=0.02)
    # One object: light crosses the seam, the vertices beside it gather the whole plane's.
    whole = translucent.Prt(lit(p, t), m, profile="dipole").radiosity(m)
    near = row & (np.abs(p[:, 0]) > 1e-3) & (np.abs(p[:, 0]) < 0.006)
    total0 = rd_total(m.sigma_a[0], (1 - m.g) * m.sigma_s[0], m.eta)
    assert np.all(np.abs(whole[near, 0] / (e_in * total0) - 1.0) < 0.03)
    # Separated, they lack at least half of the light the other half-plane sends (H(5 mm)).
    assert np.all(b[near, 0] < whole[near, 0] - 0.5 * e_in * half_plane(m, 0, 0.005))


def test_one_object_given_is_the_same_as_none():
    p, t, _ = two_grids(n=21)
    m = translucent.Material.preset("skin1", mm_per_unit=1000.0)
    a = translucent.Prt(lit(p, t), m, profile="dipole").radiosity(m)
    b = translucent.Prt(lit(p, t, np.zeros(len(p), np.int64)), m, profile="dipole").radiosity(m)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("bad, match", [
    (lambda o: o[:-1], "one object index|one non-negative integer per vertex|object indices"),
    (lambda o: np.where(np.arange(len(o)) == 3, -1, o), "non-negative integer"),
    (lambda o: o.astype(np.float64), "non-negative integer"),
    (lambda o: np.where(np.arange(len(o)) == 0, 1, o), "triangle \\d+ joins vertices of objects"),
])
def test_bad_objects_are_refused_naming_them(bad, match):
    p, t, objects = two_grids(n=5)
    with pytest.raises(ValueError, match=match):
        translucent.Scene(p, t, objects=bad(objects))


def test_the_walks_stay_in_their_object():
    # Cycles' profile: the walks through the mesh see their own object's triangles only (its
    # local intersection). Merged as one object the seam vertices gather the whole plane's light
    # (walks cross the seam under the surface); as two objects each is a rim, about half of it
    # (the walks' noise at a rim is some 15 %: the bound is loose, the gap is not).
    p, t, objects = two_grids()
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    apart = translucent.Prt(lit(p, t, objects), m, profile="cycles")
    one = translucent.Prt(lit(p, t), m, profile="cycles").radiosity(m)
    b = apart.radiosity(m)
    assert apart.report["walks"] is not None
    row = np.abs(p[:, 1]) < 1e-6
    seam = np.flatnonzero(row & (np.abs(p[:, 0]) < 1e-6))
    inner = row & (np.abs(p[:, 0]) > 0.03) & (np.abs(p[:, 0]) < 0.06)
    assert np.all(one[seam] > 0.95 * one[inner].mean(axis=0))
    assert np.all(b[seam] < 0.75 * b[inner].mean(axis=0)), (b[seam], b[inner].mean(axis=0))


def test_the_reference_integrates_each_receivers_own_object():
    # The ground truth honours objects too: on the seam row it meets the dipole's half-plane
    # integral, E_in (R_total - H(d)), and E_in R_total / 2 on the seam itself.
    p, t, objects = two_grids(n=21)
    m = translucent.Material.preset("marble", mm_per_unit=1000.0)
    row = np.flatnonzero((np.abs(p[:, 1]) < 1e-6) & (np.abs(p[:, 0]) < 0.05))
    b = translucent.reference_radiosity(lit(p, t, objects), m, rel_tol=1e-3, receivers=row, profile="dipole")
    e_in = entering(m.eta, 1.0, 3.0)
    for c in range(3):
        total = rd_total(m.sigma_a[c], (1 - m.g) * m.sigma_s[c], m.eta)
        expect = np.array([e_in * (total - half_plane(m, c, abs(float(p[v, 0])))) for v in row])
        np.testing.assert_allclose(b[:, c], expect, rtol=0.01)

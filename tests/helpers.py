"""What the Python tests judge by and build with, written once and apart from the code under
test: closed forms (Fresnel, Jensen 2001's total diffuse reflectance and its disc integral,
the plane limit), figures measured in Cycles, and the meshes several tests light (a plane, a
UV sphere). Nothing here calls the code under test for an expected value."""

import hashlib
import math

import numpy as np

# ---------------------------------------------------------------- closed forms


def fresnel_t(eta: float, cos_i: float) -> float:
    """Unpolarised dielectric Fresnel transmittance, written out independently."""
    sin_t = math.sqrt(max(0.0, 1 - cos_i**2)) / eta
    cos_t = math.sqrt(1 - sin_t**2)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 1 - 0.5 * (rs**2 + rp**2)


def boundary_a(eta: float) -> tuple[float, float]:
    """A = (1 + F_dr)/(1 - F_dr) and dA/d eta, F_dr the Egan-Hilgeman fit (Jensen 2001)."""
    f = -1.440 / eta**2 + 0.710 / eta + 0.668 + 0.0636 * eta
    df = 2.880 / eta**3 - 0.710 / eta**2 + 0.0636
    return (1 + f) / (1 - f), 2 * df / (1 - f) ** 2


def rd_total(sigma_a: float, sigma_s_prime: float, eta: float) -> float:
    """Jensen 2001's R_d,total = a'/2 (1 + e^{-4/3 A s}) e^{-s}, s = sqrt(3 sigma_a / sigma_t')
    (= sqrt(3 (1 - a')), written without the 1 - a' that cancels for a' near 1)."""
    if sigma_s_prime <= 0.0:
        return 0.0
    st_ = sigma_a + sigma_s_prime
    s = math.sqrt(3.0 * sigma_a / st_)
    return sigma_s_prime / st_ / 2 * (1 + math.exp(-4 / 3 * boundary_a(eta)[0] * s)) * math.exp(-s)


def disc_integral(m, c: int, rho: float) -> float:
    """M(rho) = 2 pi int_0^rho R_d r dr = a'/2 sum_z (e^{-sigma_tr z} - z e^{-sigma_tr d}/d),
    d = sqrt(rho^2 + z^2) (Jensen's dipole in closed form), written out apart from the core;
    channel `c` of the material `m`."""
    sa, sp = m.sigma_a[c], (1 - m.g) * m.sigma_s[c]
    if sp <= 0:
        return 0.0
    st_ = sa + sp
    zr = 1 / st_
    zv = zr * (1 + 4 * boundary_a(m.eta)[0] / 3)
    tr = math.sqrt(3 * sa * st_)
    total = 0.0
    for z in (zr, zv):
        # e^{-tr z} (1 - (z/d) e^{-tr (d - z)}), d - z = rho^2 / (d + z): no cancellation for
        # rho << z (an optically thin plane).
        dz = rho * rho / (math.hypot(rho, z) + z)
        total += math.exp(-tr * z) * -math.expm1(-math.log1p(dz / z) - tr * dz)
    return 0.5 * sp / st_ * total


def slab_totals(sigma_a: float, sigma_s_prime: float, d: float, a_top: float, a_bottom: float) -> tuple[float, float]:
    """Total reflectance and transmittance of a slab d deep under Donner and Jensen 2005's
    multipole: real poles at z_r,i = 2i(d + z_b0 + z_bd) + l (+1), virtual ones at
    z_v,i = 2i(d + z_b0 + z_bd) - l - 2 z_b0 (-1), l = 1/sigma_t', z_b = 2 A / (3 sigma_t');
    each pole integrates over the plane to sgn(z) e^{-sigma_tr |z|}, z below the top face for
    R and above the bottom face (d - z) for T; a_top, a_bottom the faces' A."""
    st_ = sigma_a + sigma_s_prime
    alpha = sigma_s_prime / st_
    l, zb0, zbd = 1.0 / st_, 2 * a_top / (3 * st_), 2 * a_bottom / (3 * st_)
    tr = math.sqrt(3 * sigma_a * st_)
    i = np.arange(-2000, 2001, dtype=float)
    shift = 2 * i * (d + zb0 + zbd)
    zr, zv = shift + l, shift - l - 2 * zb0

    def term(z):
        return np.sign(z) * np.exp(-tr * np.abs(z))

    return 0.5 * alpha * float(np.sum(term(zr) - term(zv))), 0.5 * alpha * float(np.sum(term(d - zr) - term(d - zv)))


def layered_total(top: tuple[float, float, float], base: tuple[float, float, float], eta: float) -> float:
    """A layer (sigma_a, sigma_s', thickness) over a base (thickness inf: a half-space) at zero
    spatial frequency (Donner and Jensen 2005): R1 + T1 T1' R2 / (1 - R1' R2), the face
    between them index-matched (A = 1)."""
    a = boundary_a(eta)[0]
    r1, t1 = slab_totals(*top, a, 1.0)
    r1u, t1u = slab_totals(*top, 1.0, a)
    if math.isinf(base[2]):
        st_ = base[0] + base[1]
        tr, l, zb = math.sqrt(3 * base[0] * st_), 1 / st_, 2 / (3 * st_)
        r2 = 0.5 * base[1] / st_ * (math.exp(-tr * l) + math.exp(-tr * (l + 2 * zb)))
    else:
        r2 = slab_totals(*base, 1.0, a)[0]
    return r1 + t1 * t1u * r2 / (1 - r1u * r2)


def entering(eta: float, cos_i: float, irradiance: float = 1.0) -> float:
    """The irradiance a sun of `irradiance` at cos_i from the normal sends into the medium:
    F_t(cos_i) E cos_i."""
    return fresnel_t(eta, cos_i) * irradiance * cos_i


def plane_limit(sigma_a: float, sigma_s_prime: float, eta: float, cos_i: float, irradiance: float) -> float:
    """B far inside an infinite sun-lit plane (the dipole): F_t(cos_i) E cos_i R_d,total."""
    return entering(eta, cos_i, irradiance) * rd_total(sigma_a, sigma_s_prime, eta)


def half_plane(m, c, d):
    """The dipole's R_d (material m, channel c) integrated over a half-plane at distance d from
    the point, from its closed-form disc integral M(r): int_d^inf acos(d/r)/pi dM(r)."""
    r = d * np.geomspace(1.0, 2000.0, 4000) if d > 0 else np.geomspace(1e-7, 0.4, 4000)
    mm = np.array([disc_integral(m, c, x) for x in r])
    w = np.arccos(np.clip(d / r, -1, 1)) / math.pi
    mid = 0.5 * (w[1:] + w[:-1])
    return float(np.sum(mid * np.diff(mm)))


def assert_own_half_plane(b, co, m, e_in, keep=None, tol=0.02) -> int:
    """Every vertex on the row y = 0 between 1 mm and 12 cm from the seam x = 0 (and where
    `keep(x)`) gathers only its own side's light: B = E_in (R_total - H(d)) per channel within
    `tol` of E_in R_total (the dipole's half-plane integral, `half_plane`). `b` (N, 3) and `co`
    (N, 3) world positions of the same vertices. Returns how many values were checked."""
    checked = 0
    for c in range(3):
        total = rd_total(m.sigma_a[c], (1 - m.g) * m.sigma_s[c], m.eta)
        for v in np.flatnonzero(np.abs(co[:, 1]) < 1e-6):
            x = float(co[v, 0])
            if abs(x) < 1e-3 or abs(x) > 0.12 or (keep is not None and not keep(x)):
                continue
            expect = e_in * (total - half_plane(m, c, abs(x)))
            assert abs(b[v, c] - expect) < tol * e_in * total, (c, x, b[v, c], expect)
            checked += 1
    return checked


# ---------------------------------------------------------------- measured in Cycles

# Blender 5.0.1, 128 spp: a 1 x 1 x 0.5 m slab under a white world seen from above, sigma_a
# (2, 6, 20) and sigma_s 60 per metre, g 0, Roughness 0.5, Specular IOR Level 0 (no specular
# layer; the walk enters through IOR 1.01): tests/test_cycles_mapping.py renders it.
CYCLES_SLAB = (0.604, 0.433, 0.244)

# Blender 5.0.1, 256 spp: a 40 cm block of ketchup (the preset at 1 mm = 1/1000 unit, Roughness
# 0.5, IOR 1.3) under a sun along its normal, seen orthographically at 60 and 75 degrees, over
# the same seen along the normal; the specular layer's own reflection taken off (the same render
# with Base Color black and Subsurface Weight 0): what the subsurface lobe sends
# (tests/test_cycles_mapping.py renders it).
CYCLES_VIEW_KETCHUP = {60: (1.143, 1.207, 1.204), 75: (1.188, 1.314, 1.317)}
# The same renders for skin1 and marble.
CYCLES_VIEW = {"ketchup": CYCLES_VIEW_KETCHUP,
               "skin1": {60: (1.061, 1.120, 1.155), 75: (1.052, 1.144, 1.207)},
               "marble": {60: (0.999, 0.999, 1.004), 75: (0.960, 0.962, 0.968)}}


def slab_material():
    """The medium of CYCLES_SLAB."""
    import translucent

    return translucent.Material((2.0, 6.0, 20.0), 60.0, g=0.0, eta=1.01).with_layers(roughness=0.5)


# ---------------------------------------------------------------- meshes


def plane(n: int = 41, size: float = 0.2):
    """A flat square grid in z = 0 (metres), n x n vertices, normal +Z."""
    xs = np.linspace(-size / 2, size / 2, n, dtype=np.float32)
    x, y = np.meshgrid(xs, xs)
    p = np.stack([x.ravel(), y.ravel(), np.zeros(n * n, np.float32)], axis=1)
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    t = np.concatenate([np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + n + 1, a + n], 1)])
    return p, t


def centre_index(p: np.ndarray) -> int:
    """The vertex nearest the origin (the centre of `plane`)."""
    return int(np.argmin(np.linalg.norm(p, axis=1)))


def sun_plane(n: int = 81, size: float = 1.0, theta: float = 0.0, strength: float = 1.0, direction=None):
    """`plane(n, size)` under a sun of irradiance `strength`, `theta` from the normal in the
    xz plane (or travelling along `direction`): the positions and the scene."""
    import translucent

    p, t = plane(n, size)
    s = translucent.Scene(p, t)
    s.add_sun((math.sin(theta), 0.0, -math.cos(theta)) if direction is None else direction, irradiance=strength)
    return p, s


def sphere(n: int = 12, radius: float = 1.0):
    """A closed UV sphere: (n+1) rings x 2n segments, poles shared, outward normals."""
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


def mesh_hash(mesh) -> str:
    """Hash of everything a user owns in a Blender mesh: positions, polygons, other attributes
    (the add-on's own `translucent_preview` left out)."""
    h = hashlib.sha256()
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    h.update(co.tobytes())
    loops = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    h.update(loops.tobytes())
    for a in mesh.attributes:
        if a.name == "translucent_preview":
            continue
        h.update(a.name.encode())
        h.update(a.domain.encode())
        h.update(str(len(a.data)).encode())
    return h.hexdigest()


def read_preview(obj) -> np.ndarray:
    """The add-on's preview colours on a Blender mesh object, (N, 3): what the viewport shows."""
    from addon import writeback

    attr = obj.data.color_attributes[writeback.ATTRIBUTE]
    px = np.empty(len(attr.data) * 4, np.float32)
    attr.data.foreach_get("color", px)
    return px.reshape(-1, 4)[:, :3]


# ---------------------------------------------------------------- headless Blender scenes and panel


def key_light(bpy, location=(0.0, -0.15, 0.15), energy: float = 5.0):
    """A point light "Key" of `energy` watts at `location`, linked to the scene."""
    light = bpy.data.objects.new("Key", bpy.data.lights.new("Key", "POINT"))
    light.data.energy = energy
    light.location = location
    bpy.context.scene.collection.objects.link(light)
    return light


def lit_sphere(bpy, method="PRT"):
    """A small sphere (114 vertices) with a Displace modifier of strength 0 and a point light."""
    mat = bpy.data.materials.new("Wax")
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.04, segments=16, ring_count=8)
    obj = bpy.context.active_object
    obj.data.materials.append(mat)
    displace = obj.modifiers.new("Displace", "DISPLACE")  # no texture: along the normals
    displace.strength = 0.0
    light = key_light(bpy)
    s = mat.translucent
    s.enabled = True
    s.preset = "MARBLE"
    s.coefficients = 8
    s.method = method
    assert bpy.ops.translucent.precompute(material_name=mat.name) == {"FINISHED"}
    return mat, obj, light


class Layout:
    """Stands in for a panel's UILayout: records the labels, accepts everything else."""

    def __init__(self, labels):
        self.labels = labels

    def label(self, text="", **_):
        self.labels.append(text)

    def __getattr__(self, name):
        return lambda *a, **k: self

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


def draw_panel(addon, mat):
    from types import SimpleNamespace

    labels = []
    addon.panel.TRANSLUCENT_PT_material.draw(SimpleNamespace(layout=Layout(labels)), SimpleNamespace(material=mat))
    return labels


def square(cx, cy, z, h):
    """A horizontal square 2h wide centred at (cx, cy, z): (positions, triangles)."""
    p = np.array([[cx - h, cy - h, z], [cx + h, cy - h, z], [cx + h, cy + h, z], [cx - h, cy + h, z]], np.float32)
    return p, np.array([[0, 1, 2], [0, 2, 3]])


def assert_shadow_edge(b, p, m, e_in, near=1e-3, tol=0.02) -> int:
    """A blocker covers x > 0 of a plane lit straight down: on the row y = 0, between `near` and
    12 cm from the edge, B is E_in H(d) beneath it and E_in (R_total - H(d)) beside it (the
    dipole's half-plane integral, `half_plane`), within `tol` of E_in R_total per channel.
    Returns how many values were checked."""
    checked = 0
    for c in range(3):
        total = rd_total(m.sigma_a[c], (1 - m.g) * m.sigma_s[c], m.eta)
        for v in np.flatnonzero(np.abs(p[:, 1]) < 1e-6):
            x = float(p[v, 0])
            if abs(x) < near or abs(x) > 0.12:
                continue
            h = half_plane(m, c, abs(x))
            expect = e_in * (h if x > 0 else total - h)
            assert abs(b[v, c] - expect) < tol * e_in * total, (c, x, b[v, c], expect)
            checked += 1
    return checked

//! Walks through the mesh against what they must agree with, none of it the walks' code:
//! - Cycles itself: the thick-slab render of `tests/test_cycles_mapping.py` (Blender 5.0.1);
//! - the half-space table (a separate simulation in an analytic half-space) integrated by
//!   quadrature over a half-lit plane: the radial shape of the exits, not only their total;
//! - a slab thinner than the light's reach lets light through to its far side, which no
//!   half-space sees: the walks' transmission against a brute-force walk between two planes;
//! - the same seed gives the same bits whatever the thread count.

mod common;

use translucent_core::mesh::Mesh;
use translucent_core::optics::{Layers, Material};
use translucent_core::profiles::{ProfileKind, RadialProfile};
use translucent_core::raytrace::Tracer;
use translucent_core::shadow_edges::ShadowEdges;
use translucent_core::walks::{relit_radiosity, walk_radiosity, ExitLight, MeshWalkSettings};
use translucent_core::Vec3;

/// A closed box [-w/2, w/2]^2 x [-depth, 0] whose top face is an n x n grid (the other faces
/// one grid each side too, so the box is watertight), outward normals. Returns the mesh and
/// the index of the top vertex nearest (x, y).
fn grid_box(w: f32, depth: f32, n: usize) -> Mesh {
    let mut p: Vec<Vec3> = Vec::new();
    let mut t: Vec<[u32; 3]> = Vec::new();
    // Six faces, each an n x n grid mapped from (s, u) in [0, 1]^2 by origin + s a + u b with
    // a x b pointing outward; shared edges duplicate vertices at equal positions, which the
    // ray tracer's watertight edge test handles.
    let h = w / 2.0;
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (
            Vec3::new(-h, -h, 0.0),
            Vec3::new(w, 0.0, 0.0),
            Vec3::new(0.0, w, 0.0),
        ), // top +z
        (
            Vec3::new(-h, -h, -depth),
            Vec3::new(0.0, w, 0.0),
            Vec3::new(w, 0.0, 0.0),
        ), // bottom
        (
            Vec3::new(-h, -h, -depth),
            Vec3::new(w, 0.0, 0.0),
            Vec3::new(0.0, 0.0, depth),
        ), // -y
        (
            Vec3::new(-h, h, -depth),
            Vec3::new(0.0, 0.0, depth),
            Vec3::new(w, 0.0, 0.0),
        ), // +y
        (
            Vec3::new(-h, -h, -depth),
            Vec3::new(0.0, 0.0, depth),
            Vec3::new(0.0, w, 0.0),
        ), // -x
        (
            Vec3::new(h, -h, -depth),
            Vec3::new(0.0, w, 0.0),
            Vec3::new(0.0, 0.0, depth),
        ), // +x
    ];
    for (f, (o, a, b)) in faces.iter().enumerate() {
        let k = if f == 0 { n } else { 9 };
        let base = p.len() as u32;
        for j in 0..k {
            for i in 0..k {
                let (s, u) = (i as f32 / (k - 1) as f32, j as f32 / (k - 1) as f32);
                p.push(*o + *a * s + *b * u);
            }
        }
        for j in 0..k - 1 {
            for i in 0..k - 1 {
                let v = base + (j * k + i) as u32;
                let (r, up, d) = (v + 1, v + k as u32, v + k as u32 + 1);
                t.push([v, r, d]);
                t.push([v, d, up]);
            }
        }
    }
    Mesh::new(p, t, None).unwrap()
}

fn nearest(mesh: &Mesh, x: f32, y: f32) -> u32 {
    let target = Vec3::new(x, y, 0.0);
    (0..mesh.vertex_count() as u32)
        .min_by(|&a, &b| {
            let da = mesh.positions()[a as usize].distance(target);
            let db = mesh.positions()[b as usize].distance(target);
            da.total_cmp(&db)
        })
        .unwrap()
}

/// The Cycles thick-slab material of tests/test_cycles_mapping.py: sigma_a (2, 6, 20), sigma_s
/// 60 per metre, g 0, Roughness 0.5, Specular IOR Level 0 (the walk enters through IOR 1.01).
fn slab_material() -> Material {
    Material::new([2.0, 6.0, 20.0], [60.0; 3], 0.0, 1.0)
        .unwrap()
        .with_layers(Layers {
            roughness: 0.5,
            ..Layers::default()
        })
        .unwrap()
}

#[test]
fn walks_in_a_thick_box_reproduce_the_cycles_slab_render() {
    // Blender 5.0.1, 128 spp: a 1 x 1 x 0.5 m slab under a white world seen from above
    // renders 0.604, 0.433, 0.244; with uniform irradiance 1 the radiosity at the top's centre
    // is that slab albedo.
    let cycles = [0.604, 0.433, 0.244];
    let mesh = grid_box(1.0, 0.5, 21);
    let tracer = Tracer::new(&mesh);
    let e = vec![[1.0f32; 3]; mesh.vertex_count()];
    let centre = nearest(&mesh, 0.0, 0.0);
    let settings = MeshWalkSettings {
        walks: 40_000,
        ..MeshWalkSettings::default()
    };
    let r = walk_radiosity(
        &mesh,
        &tracer,
        &slab_material(),
        &e,
        Some(&[centre]),
        &settings,
        None,
    )
    .unwrap();
    for (c, cycles) in cycles.iter().enumerate() {
        let (b, se) = (f64::from(r.radiosity[0][c]), f64::from(r.std_error[0][c]));
        eprintln!("channel {c}: walks {b:.4} +- {se:.4}, Cycles {cycles}");
        assert!(se < 0.005 * b, "noise {se} of {b}");
        assert!(
            (b - cycles).abs() <= 0.02 * cycles + 3.0 * se,
            "channel {c}: walks {b} vs Cycles {cycles}"
        );
    }
}

/// 2 pi-free half-plane integral: the radiosity at distance d from the edge of a lit half-plane
/// (irradiance 1), on its dark side, = int_d^inf R(r) 2 acos(d / r) r dr, by the midpoint rule
/// on a geometric grid.
fn dark_side(p: &impl RadialProfile, d: f64) -> f64 {
    let (mut r, mut acc) = (d, 0.0);
    let end = p.support_radius(1e-7).max(2.0 * d);
    while r < end {
        let next = (r * 1.002).max(r + 1e-6 * end);
        let mid = 0.5 * (r + next);
        acc += p.value(mid) * 2.0 * (d / mid).min(1.0).acos() * mid * (next - r);
        r = next;
    }
    acc
}

/// sigma_t 100 per metre (mean free path 1 cm), g 0.3, Roughness 0.5, IOR 1.4, single-scattering
/// albedo 0.99 / 0.9 / 0.6 per channel: in a 1 m box 0.5 m deep the walks see a half-space.
fn half_space_medium() -> (Material, [f64; 3]) {
    let (sigma_t, g, roughness, ior) = (100.0, 0.3, 0.5, 1.4);
    let albedo = [0.99, 0.9, 0.6];
    let m = Material::new(
        albedo.map(|a| sigma_t * (1.0 - a)),
        albedo.map(|a| sigma_t * a),
        g,
        ior,
    )
    .unwrap()
    .with_layers(Layers {
        roughness,
        ..Layers::default()
    })
    .unwrap();
    (m, albedo)
}

/// Irradiance 1 for x < 0 on the box's top face, 0 beyond and below (0.5 on the edge itself).
fn half_lit(mesh: &Mesh) -> Vec<[f32; 3]> {
    mesh.positions()
        .iter()
        .map(|p| {
            let lit = if p.z < -1e-6 {
                0.0
            } else if p.x.abs() < 1e-6 {
                0.5
            } else if p.x < 0.0 {
                1.0
            } else {
                0.0
            };
            [lit; 3]
        })
        .collect()
}

#[test]
fn walks_on_a_half_lit_plane_follow_the_half_space_table() {
    // sigma_t 100 per metre (mean free path 1 cm), a 1 m box 0.5 m deep: a half-space for the
    // walks. Irradiance 1 for x < 0 and 0 beyond, on a 4 mm grid (the ramp between the two is
    // odd about the edge and costs under 0.1 % at >= 1 cm from it). Both sides of the edge,
    // for three albedos, against the table's profile integrated over the lit half-plane.
    let (m, albedo) = half_space_medium();
    let profiles = ProfileKind::Cycles.profiles(&m).unwrap();
    let mesh = grid_box(1.0, 0.5, 251);
    let tracer = Tracer::new(&mesh);
    let e = half_lit(&mesh);
    let xs = [-0.03f32, -0.012, 0.012, 0.03, 0.06];
    let receivers: Vec<u32> = xs.iter().map(|&x| nearest(&mesh, x, 0.0)).collect();
    let settings = MeshWalkSettings {
        walks: 20_000,
        ..MeshWalkSettings::default()
    };
    let r = walk_radiosity(&mesh, &tracer, &m, &e, Some(&receivers), &settings, None).unwrap();
    for (i, &v) in receivers.iter().enumerate() {
        let x = f64::from(mesh.positions()[v as usize].x);
        for c in 0..3 {
            let p = &profiles[c];
            let expected = if x > 0.0 {
                dark_side(p, x)
            } else {
                p.total() - dark_side(p, -x)
            };
            let (b, se) = (f64::from(r.radiosity[i][c]), f64::from(r.std_error[i][c]));
            eprintln!(
                "x {x:+.3} albedo {}: walks {b:.5} +- {se:.5}, table {expected:.5}",
                albedo[c]
            );
            assert!(
                std::env::var("NOASSERT").is_ok()
                    || (b - expected).abs() <= 0.01 * expected + 4.0 * se + 1e-4,
                "x {x} albedo {}: walks {b} vs table {expected}",
                albedo[c]
            );
        }
    }
}

#[test]
fn on_a_plane_under_linear_light_the_control_variate_leaves_no_noise() {
    // Each walk runs beside a twin in the tangent half-space scored with the irradiance's
    // tangent-plane linearisation, whose mean is known. On a flat top under irradiance linear
    // in x the two are the same walk, so 64 walks give B to within the twin's own total: the
    // half-space table's (a separate simulation) times E(v), with almost no spread. Plain
    // walks at 64 per vertex spread by about 10 % here.
    let (m, albedo) = half_space_medium();
    let profiles = ProfileKind::Cycles.profiles(&m).unwrap();
    let mesh = grid_box(1.0, 0.5, 101);
    let tracer = Tracer::new(&mesh);
    let e: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| [if p.z < -1e-6 { 0.0 } else { 1.0 + p.x }; 3])
        .collect();
    let receivers: Vec<u32> = [-0.1f32, 0.0, 0.15]
        .iter()
        .map(|&x| nearest(&mesh, x, 0.02))
        .collect();
    let settings = MeshWalkSettings {
        walks: 64,
        ..MeshWalkSettings::default()
    };
    let r = walk_radiosity(&mesh, &tracer, &m, &e, Some(&receivers), &settings, None).unwrap();
    for (i, &v) in receivers.iter().enumerate() {
        let ev = f64::from(e[v as usize][0]);
        for c in 0..3 {
            let expected = (profiles[c].total() + profiles[c].point_mass()) * ev;
            let (b, se) = (f64::from(r.radiosity[i][c]), f64::from(r.std_error[i][c]));
            eprintln!(
                "E {ev:.3} albedo {}: walks {b:.5} +- {se:.5}, table {expected:.5}",
                albedo[c]
            );
            assert!(se <= 2e-3 * b, "albedo {}: spread {se} of {b}", albedo[c]);
            assert!(
                (b - expected).abs() <= 6e-3 * expected + 4.0 * se,
                "albedo {}: walks {b} vs table {expected}",
                albedo[c]
            );
        }
    }
}

/// An independent analogue walk between the planes z = 0 (entry) and z = -thickness (index-
/// matched both), isotropic scattering, entering straight down (Roughness 0): the fraction that
/// leaves through the far plane. Written here from the walk's description.
fn brute_transmission(alpha: f64, thickness: f64, walks: usize) -> f64 {
    brute_transmission_across(alpha, thickness, None, walks)
}

/// As `brute_transmission`, with a diffuse interface at depth `interface` (as Cycles passes a
/// surface inside another part: the walk leaves through it, a cosine-distributed path ray
/// carries it across, and a new walk starts beyond, refracted by 1/1.01, without a collision
/// first).
fn brute_transmission_across(
    alpha: f64,
    thickness: f64,
    interface: Option<f64>,
    walks: usize,
) -> f64 {
    brute_slab(alpha, thickness, interface, walks).1
}

/// Uniform numbers in [0, 1) from an xorshift64* stream (the brute-force walks' own, apart
/// from the walks' generator).
fn uniform_stream(seed: u64) -> impl FnMut() -> f64 {
    let mut state = seed;
    move || {
        state ^= state >> 12;
        state ^= state << 25;
        state ^= state >> 27;
        (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The walk of `brute_transmission_across`: the fractions that leave through the entry plane
/// and through the far one.
fn brute_slab(alpha: f64, thickness: f64, interface: Option<f64>, walks: usize) -> (f64, f64) {
    let mut uniform = uniform_stream(0x1234_5678_9abc_def1);
    let (mut back, mut through) = (0usize, 0usize);
    for _ in 0..walks {
        let (mut z, mut dz) = (0.0f64, -1.0f64);
        for _ in 0..256 {
            let next = z + dz * -(1.0 - uniform()).ln();
            if let Some(depth) = interface {
                let zi = -depth;
                if (z - zi) * (next - zi) < 0.0 {
                    // Across: cos theta of a cosine-distributed direction, then Snell.
                    let cos_i = (1.0 - uniform()).sqrt();
                    let eta = 1.0 / 1.01;
                    let cos_t = (1.0 - eta * eta * (1.0 - cos_i * cos_i)).sqrt();
                    (z, dz) = (zi, cos_t * dz.signum());
                    continue;
                }
            }
            z = next;
            if z > 0.0 {
                back += 1;
                break;
            }
            if z < -thickness {
                through += 1;
                break;
            }
            if uniform() >= alpha {
                break;
            }
            dz = 1.0 - 2.0 * uniform();
        }
    }
    (back as f64 / walks as f64, through as f64 / walks as f64)
}

/// sigma_t 100 per metre (mean free path 1 cm), single-scattering albedo `alpha`, g 0,
/// Roughness 0, IOR 1.01 (the walk enters straight down): the two-plane walks' medium.
fn thin_medium(alpha: f64) -> Material {
    Material::new([100.0 * (1.0 - alpha); 3], [100.0 * alpha; 3], 0.0, 1.01)
        .unwrap()
        .with_layers(Layers {
            roughness: 0.0,
            ..Layers::default()
        })
        .unwrap()
}

/// Irradiance 1 at the vertices below height `z`, 0 elsewhere.
fn lit_below(mesh: &Mesh, z: f32) -> Vec<[f32; 3]> {
    mesh.positions()
        .iter()
        .map(|p| if p.z < z { [1.0; 3] } else { [0.0; 3] })
        .collect()
}

/// B in the red channel at the vertex nearest (0, 0, 0) from 40,000 walks, and its standard
/// error.
fn walk_centre(mesh: &Mesh, tracer: &Tracer, m: &Material, e: &[[f32; 3]]) -> (f64, f64) {
    walk_at(mesh, tracer, m, e, 0.0, 0.0)
}

/// As `walk_centre`, at the vertex nearest (x, y).
fn walk_at(
    mesh: &Mesh,
    tracer: &Tracer,
    m: &Material,
    e: &[[f32; 3]],
    x: f32,
    y: f32,
) -> (f64, f64) {
    let vertex = nearest(mesh, x, y);
    let settings = MeshWalkSettings {
        walks: 40_000,
        ..MeshWalkSettings::default()
    };
    let r = walk_radiosity(mesh, tracer, m, e, Some(&[vertex]), &settings, None).unwrap();
    (f64::from(r.radiosity[0][0]), f64::from(r.std_error[0][0]))
}

#[test]
fn a_thin_slab_lets_light_through_to_its_far_side() {
    // sigma_t 100 per metre, 2 cm thick (2 mean free paths), lit only from below: the top's
    // centre receives what crosses the slab, which a half-space profile calls zero.
    let alpha = 0.95;
    let m = thin_medium(alpha);
    let mesh = grid_box(1.0, 0.02, 21);
    let tracer = Tracer::new(&mesh);
    let e = lit_below(&mesh, -0.0199);
    let (b, se) = walk_centre(&mesh, &tracer, &m, &e);
    // Reciprocity: light entering at the top's centre and leaving through the lit bottom.
    let expected = brute_transmission(alpha, 2.0, 400_000);
    eprintln!("transmission: walks {b:.4} +- {se:.4}, brute force {expected:.4}");
    assert!(expected > 0.1);
    assert!((b - expected).abs() <= 0.02 * expected + 4.0 * se);
}

#[test]
fn a_surface_crossed_from_outside_gives_no_light() {
    // Two open sheets, both facing up, 2 cm apart, every vertex lit: a walk entering the upper
    // one and reaching the lower one crosses it from its outside (a walk that left an open mesh
    // through a hole), where Cycles' exit lobe faces down, away from the walk, and finds no
    // light. So the upper sheet's centre gets what the brute-force slab walk returns through
    // its entry plane alone (not that plus what reaches the far plane).
    let alpha = 0.95;
    let m = thin_medium(alpha);
    let (mut p, mut t) = common::plane_parts(41, 1.0);
    let (lp, lt) = common::plane_parts(41, 1.0);
    let base = p.len() as u32;
    p.extend(lp.iter().map(|q| *q - Vec3::Z * 0.02));
    t.extend(lt.iter().map(|tri| tri.map(|i| i + base)));
    let mesh = Mesh::new(p, t, None).unwrap();
    let tracer = Tracer::new(&mesh);
    let e = vec![[1.0f32; 3]; mesh.vertex_count()];
    let (b, se) = walk_centre(&mesh, &tracer, &m, &e);
    let (back, through) = brute_slab(alpha, 2.0, None, 400_000);
    eprintln!(
        "open sheets: walks {b:.4} +- {se:.4}, brute force back {back:.4} (through {through:.4})"
    );
    assert!(through > 0.1);
    assert!((b - back).abs() <= 0.02 * back + 4.0 * se);
}

/// An independent analogue walk about the half-plane sheet z = 0, x < 0 (medium everywhere
/// else: an open mesh's edge), isotropic scattering, entering at the edge straight down: the
/// fraction that leaves up through the sheet (lit); meeting it from above ends the walk dark.
/// Written here from the walk's description.
fn brute_edge(alpha: f64, walks: usize) -> f64 {
    let mut uniform = uniform_stream(0x0fed_cba9_8765_4321);
    let mut lit = 0usize;
    for _ in 0..walks {
        let (mut x, mut z, mut dx, mut dz) = (0.0f64, 0.0f64, 0.0f64, -1.0f64);
        for _ in 0..256 {
            let t = -(1.0 - uniform()).ln();
            let (nx, nz) = (x + dx * t, z + dz * t);
            if z * nz < 0.0 {
                let xc = x + dx * (-z / dz);
                if xc < 0.0 {
                    lit += usize::from(dz > 0.0);
                    break;
                }
            }
            (x, z) = (nx, nz);
            if uniform() >= alpha {
                break;
            }
            // Isotropic: only the x and z components matter.
            let cos = 1.0 - 2.0 * uniform();
            let phi = std::f64::consts::TAU * uniform();
            (dx, dz) = ((1.0 - cos * cos).sqrt() * phi.cos(), cos);
        }
    }
    lit as f64 / walks as f64
}

#[test]
fn at_an_open_edge_walks_go_round_it_into_the_open() {
    // The edge of an open sheet (a scan's hole): a walk entering there can pass round the edge
    // into the open, where it walks on (as Cycles' walk does: no surface, no exit) until it
    // meets the sheet from below (lit) or from above (its outside: dark), or fades.
    let alpha = 0.95;
    let m = thin_medium(alpha);
    let mesh = common::plane(41, 1.0);
    let tracer = Tracer::new(&mesh);
    let e = vec![[1.0f32; 3]; mesh.vertex_count()];
    let (b, se) = walk_at(&mesh, &tracer, &m, &e, 0.5, 0.0);
    let expected = brute_edge(alpha, 400_000);
    let (interior, _) = brute_slab(alpha, 1e9, None, 400_000);
    eprintln!(
        "open edge: walks {b:.4} +- {se:.4}, brute force {expected:.4} (interior {interior:.4})"
    );
    assert!(
        expected < 0.8 * interior,
        "the edge loses light: {expected} vs {interior}"
    );
    assert!((b - expected).abs() <= 0.02 * expected + 4.0 * se);
}

/// `grid_box` moved down by `dz`, as triangles and positions to merge.
fn shifted_box(w: f32, depth: f32, n: usize, dz: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let b = grid_box(w, depth, n);
    let p = b.positions().iter().map(|p| *p - Vec3::Z * dz).collect();
    (p, b.triangles().to_vec())
}

#[test]
fn light_passes_a_part_sunk_into_another_as_cycles_passes_it() {
    // The thin slab of the test above cut in two boxes that overlap by 2 delta (a sunk part):
    // the upper one's walks meet the lower box's top inside the upper box. Cycles leaves
    // there, crosses the overlap on a path ray and walks on in the lower box; the light that
    // reaches the top is the brute-force walk's across a diffuse interface, the overlap's
    // 2 delta taken out of the slab. (Ending the walks there would leave the top dark.)
    let alpha = 0.95;
    let m = thin_medium(alpha);
    let delta = 0.001f32;
    let (mut p, mut t) = shifted_box(1.0, 0.01 + delta, 21, 0.0);
    // The lower box a little narrower, so that its top lies wholly inside the upper box.
    let (lp, lt) = shifted_box(0.98, 0.01 + delta, 21, 0.01 - delta);
    let base = p.len() as u32;
    p.extend(lp);
    t.extend(lt.iter().map(|tri| tri.map(|i| i + base)));
    let mesh = Mesh::new(p, t, None).unwrap();
    let tracer = Tracer::new(&mesh);
    let e = lit_below(&mesh, -0.0199);
    let (b, se) = walk_centre(&mesh, &tracer, &m, &e);
    let sigma = 100.0;
    let upper = sigma * f64::from(0.01 - delta);
    let expected = brute_transmission_across(alpha, 2.0 * upper, Some(upper), 400_000);
    eprintln!(
        "across a sunk part: walks {b:.4} +- {se:.4}, brute force {expected:.4} (no interface {:.4})",
        brute_transmission(alpha, 2.0 * upper, 400_000)
    );
    assert!(expected > 0.1);
    assert!((b - expected).abs() <= 0.02 * expected + 4.0 * se);
}

#[test]
fn the_same_seed_gives_the_same_bits_whatever_the_threads() {
    let mesh = grid_box(1.0, 0.5, 11);
    let tracer = Tracer::new(&mesh);
    let e: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| [(p.x + 1.0).max(0.0); 3])
        .collect();
    let settings = MeshWalkSettings {
        walks: 64,
        ..MeshWalkSettings::default()
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                walk_radiosity(&mesh, &tracer, &slab_material(), &e, None, &settings, None).unwrap()
            })
    };
    let (one, two) = (run(1), run(2));
    assert_eq!(one.radiosity, two.radiosity);
    let other = walk_radiosity(
        &mesh,
        &tracer,
        &slab_material(),
        &e,
        None,
        &MeshWalkSettings {
            seed: 7,
            ..settings.clone()
        },
        None,
    )
    .unwrap();
    assert_ne!(one.radiosity, other.radiosity, "another seed, other walks");
}

#[test]
fn bad_input_is_an_error() {
    let mesh = grid_box(1.0, 0.5, 5);
    let tracer = Tracer::new(&mesh);
    let n = mesh.vertex_count();
    let m = slab_material();
    let s = MeshWalkSettings::default();
    let ok = vec![[1.0f32; 3]; n];
    assert!(walk_radiosity(&mesh, &tracer, &m, &ok[1..], None, &s, None).is_err());
    let mut nan = ok.clone();
    nan[3][1] = f32::NAN;
    assert!(walk_radiosity(&mesh, &tracer, &m, &nan, None, &s, None).is_err());
    assert!(walk_radiosity(&mesh, &tracer, &m, &ok, Some(&[n as u32]), &s, None).is_err());
    let zero = MeshWalkSettings {
        walks: 0,
        ..s.clone()
    };
    assert!(walk_radiosity(&mesh, &tracer, &m, &ok, None, &zero, None).is_err());
    let mut back = m;
    back.g = -0.3;
    assert!(walk_radiosity(&mesh, &tracer, &back, &ok, None, &s, None).is_err());
    let mut neg = m;
    neg.sigma_a[0] = -1.0;
    assert!(walk_radiosity(&mesh, &tracer, &neg, &ok, None, &s, None).is_err());
}

/// The walks kept as a function of the light (`MeshWalkSettings::record`): walked under one
/// light (uniform on the top face), read anew under another (the half-lit plane above) without
/// tracing a walk, they give the half-space table integrated over the lit half-plane, as walks
/// traced under that light do; under their own light they give back what they scored.
#[test]
fn recorded_walks_relit_follow_the_half_space_table() {
    let (m, albedo) = half_space_medium();
    let profiles = ProfileKind::Cycles.profiles(&m).unwrap();
    let mesh = grid_box(1.0, 0.5, 251);
    let tracer = Tracer::new(&mesh);
    let top = |p: &Vec3| p.z > -1e-6;
    let uniform: Vec<[f32; 3]> = mesh
        .positions()
        .iter()
        .map(|p| [if top(p) { 1.0 } else { 0.0 }; 3])
        .collect();
    let half = half_lit(&mesh);
    let xs = [-0.03f32, -0.012, 0.012, 0.03];
    let receivers: Vec<u32> = xs.iter().map(|&x| nearest(&mesh, x, 0.0)).collect();
    let settings = MeshWalkSettings {
        walks: 8_000,
        record: true,
        ..MeshWalkSettings::default()
    };
    let r = walk_radiosity(
        &mesh,
        &tracer,
        &m,
        &uniform,
        Some(&receivers),
        &settings,
        None,
    )
    .unwrap();
    let records = r.records.as_ref().expect("records were asked for");
    let none = ShadowEdges::none();
    let light = |e| ExitLight {
        vertices: e,
        edges: &none,
    };
    let (same, same_se) = relit_radiosity(&mesh, records, &receivers, &light(&uniform)).unwrap();
    for ((a, b), (sa, sb)) in same
        .iter()
        .zip(&r.radiosity)
        .zip(same_se.iter().zip(&r.std_error))
    {
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 1e-5 * b[c].max(1e-6),
                "relit under its own light: {} vs scored {}",
                a[c],
                b[c]
            );
            assert!(
                (sa[c] - sb[c]).abs() <= 1e-4 * sb[c].max(1e-6),
                "standard error {sa:?} vs {sb:?}"
            );
        }
    }
    let (relit, relit_se) = relit_radiosity(&mesh, records, &receivers, &light(&half)).unwrap();
    for (i, &v) in receivers.iter().enumerate() {
        let x = f64::from(mesh.positions()[v as usize].x);
        for c in 0..3 {
            let p = &profiles[c];
            let expected = if x > 0.0 {
                dark_side(p, x)
            } else {
                p.total() - dark_side(p, -x)
            };
            let (b, se) = (f64::from(relit[i][c]), f64::from(relit_se[i][c]));
            eprintln!(
                "relit x {x:+.3} albedo {}: {b:.5}, table {expected:.5}",
                albedo[c]
            );
            assert!(
                (b - expected).abs() <= 0.01 * expected + 4.0 * se + 1e-4,
                "x {x} albedo {}: relit {b} vs table {expected}",
                albedo[c]
            );
        }
    }
}

//! The hierarchy (Mertens 2003) against what does not depend on it: the sun-over-a-plane
//! closed form (Jensen 2001), the ground truth (`reference_radiosity`) on a small curved
//! mesh under shadowing lights, and itself across modes (render after a light move equals a
//! fresh on-the-fly evaluation; incremental after a deformation equals a fresh build).

mod common;
use common::oracles::{rd_total, slab_rd_total};
use common::plane;
use translucent_core::hierarchy::{Hierarchy, HierarchySettings, Mode};
use translucent_core::irradiance::{irradiance, Density, IrradianceSettings};
use translucent_core::lights::{Light, World};
use translucent_core::mesh::Mesh;
use translucent_core::metrics::{relative_error, ErrorStats};
use translucent_core::optics::{fresnel_transmittance, Material, Stack};
use translucent_core::profiles::{ProfileKind, RadialProfile};
use translucent_core::raytrace::Tracer;
use translucent_core::reference::{reference_radiosity, ReferenceSettings};
use translucent_core::scene::Scene;
use translucent_core::Vec3;

/// A closed, lumpy sphere of radius ~`r` (a UV sphere with a bump), normals outward.
fn lumpy_sphere(r: f32, rings: usize, segments: usize, bump: f32) -> Mesh {
    let shape = |th: f32, ph: f32| {
        let dir = Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos());
        dir * r * (1.0 + bump * (3.0 * ph).sin() * th.sin().powi(2))
    };
    let mut p = vec![shape(0.0, 0.0)];
    for i in 1..rings {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        for s in 0..segments {
            p.push(shape(
                th,
                2.0 * std::f32::consts::PI * s as f32 / segments as f32,
            ));
        }
    }
    p.push(shape(std::f32::consts::PI, 0.0));
    let ring = |i: usize, s: usize| (1 + (i - 1) * segments + s % segments) as u32;
    let last = (p.len() - 1) as u32;
    let mut t = Vec::new();
    for s in 0..segments {
        t.push([0, ring(1, s), ring(1, s + 1)]);
        t.push([last, ring(rings - 1, s + 1), ring(rings - 1, s)]);
        for i in 1..rings - 1 {
            t.push([ring(i, s), ring(i + 1, s), ring(i + 1, s + 1)]);
            t.push([ring(i, s), ring(i + 1, s + 1), ring(i, s + 1)]);
        }
    }
    Mesh::new(p, t, None).unwrap()
}

fn settings(model: ProfileKind, mode: Mode) -> HierarchySettings {
    HierarchySettings {
        profile: model,
        mode,
        ..Default::default()
    }
}

/// Every profile kind the hierarchy is checked with.
const PROFILES: [ProfileKind; 3] = [
    ProfileKind::Dipole,
    ProfileKind::Cycles,
    ProfileKind::Multipole,
];

/// The material a profile is checked with: the half-space itself, or for the multipole a
/// 4 mm slab of the same medium (its top face the surface).
fn for_profile(half_space: Material, model: ProfileKind) -> Material {
    match model {
        ProfileKind::Multipole => half_space
            .with_stack(Stack {
                thickness: 4.0,
                top: None,
            })
            .unwrap(),
        _ => half_space,
    }
}

#[test]
#[allow(clippy::needless_range_loop)]
fn sun_over_a_large_plane_gives_the_closed_form() {
    // 200 mm square, 2 mm grid: the marble tail beyond 100 mm is below 1e-5.
    let mesh = plane(101, 200.0);
    let centre = (0..mesh.vertex_count())
        .min_by(|a, b| {
            mesh.positions()[*a]
                .length()
                .total_cmp(&mesh.positions()[*b].length())
        })
        .unwrap();
    for (name, theta) in [
        ("marble", 0.0f64),
        ("marble", 1.0),
        ("ketchup", 0.4),
        ("skimmilk", 0.2),
    ] {
        let half_space = Material::preset(name, 1.0).unwrap();
        for model in PROFILES {
            let m = for_profile(half_space, model);
            let mut scene = Scene::new(mesh.clone());
            let dir = Vec3::new(theta.sin() as f32, 0.0, -theta.cos() as f32);
            scene.lights.push(Light::sun(dir, [2.0; 3]).unwrap());
            let mut h = Hierarchy::new(scene, settings(model, Mode::OnTheFly)).unwrap();
            let b = h.radiosity(&m).unwrap().values;
            let cos = theta.cos();
            for c in 0..3 {
                // B = F_t(θ) E cos θ R_total (dipole); Cycles' walk has no Fresnel on the way in.
                let expect = match model {
                    ProfileKind::Dipole => {
                        fresnel_transmittance(m.eta, cos)
                            * 2.0
                            * cos
                            * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta)
                    }
                    ProfileKind::Cycles => {
                        let p = &model.profiles(&m).unwrap()[c];
                        2.0 * cos * (p.total() + p.point_mass())
                    }
                    ProfileKind::Multipole => {
                        let (sa, sp) = (m.sigma_a[c], m.sigma_s_prime()[c]);
                        fresnel_transmittance(m.eta, cos)
                            * 2.0
                            * cos
                            * slab_rd_total(sa, sp, m.eta, 4.0)
                    }
                };
                let got = f64::from(b[centre][c]);
                assert!(
                    (got - expect).abs() <= 0.01 * expect,
                    "{name} {model:?} θ {theta} channel {c}: B {got} vs closed form {expect} ({:+.2} %)",
                    100.0 * (got / expect - 1.0)
                );
            }
        }
    }
}

/// The ground truth on `scene` for `receivers`, with the same irradiance estimator.
fn truth(scene: &Scene, m: &Material, model: ProfileKind, receivers: &[u32]) -> Vec<[f32; 3]> {
    let tracer = Tracer::new(&scene.mesh);
    let s = IrradianceSettings {
        eta: model.irradiance_eta(m),
        seed: 1,
        ..Default::default()
    };
    let irr = |p: &[Vec3], n: &[Vec3], d: Density| {
        irradiance(scene, &tracer, p, n, &s.for_density(d)).map(|(v, _)| v)
    };
    let settings = ReferenceSettings {
        profile: model,
        max_level: 3,
        ..Default::default()
    };
    reference_radiosity(&scene.mesh, m, &irr, Some(receivers), &settings, None)
        .unwrap()
        .radiosity
}

/// A fresh on-the-fly hierarchy's B at `receivers` against the ground truth.
fn error_on(
    scene: &Scene,
    m: &Material,
    model: ProfileKind,
    receivers: &[u32],
    weights: &[f32],
) -> ErrorStats {
    let mut h = Hierarchy::new(scene.clone(), settings(model, Mode::OnTheFly)).unwrap();
    let b = h.radiosity(m).unwrap().values;
    let b: Vec<[f32; 3]> = receivers.iter().map(|&v| b[v as usize]).collect();
    let t = truth(scene, m, model, receivers);
    relative_error(&b, &t, weights).unwrap()
}

fn lit(mesh: Mesh, light: Vec3) -> Scene {
    let mut scene = Scene::new(mesh);
    scene.lights.push(Light::point(light, [4e4; 3]).unwrap());
    scene
        .lights
        .push(Light::sun(Vec3::new(0.3, 0.5, -0.8), [0.5; 3]).unwrap());
    scene
}

#[test]
fn radiosity_matches_the_ground_truth_on_a_lumpy_sphere() {
    // 10 mm radius, marble and ketchup in mm: the near field spans a few faces, the far field
    // the whole shell; a point light casts a terminator. Every 27th vertex a receiver (43):
    // the ground truth at every 9th took the test 203 s of CI's time, 84 s at these.
    let mesh = lumpy_sphere(10.0, 24, 48, 0.15);
    let receivers: Vec<u32> = (0..mesh.vertex_count() as u32).step_by(27).collect();
    let weights: Vec<f32> = receivers
        .iter()
        .map(|&v| mesh.vertex_areas()[v as usize])
        .collect();
    let scene = lit(mesh, Vec3::new(20.0, -10.0, 30.0));
    for name in ["marble", "ketchup"] {
        let half_space = Material::preset(name, 1.0).unwrap();
        for model in PROFILES {
            let m = for_profile(half_space, model);
            let e = error_on(&scene, &m, model, &receivers, &weights);
            eprintln!("{name} {model:?}: {e:?}");
            assert!(e.worst_rms() < 0.02, "{name} {model:?}: {e:?}");
        }
    }
}

#[test]
fn vertices_on_an_open_edge_match_the_ground_truth() {
    // A 20 mm sheet of 0.67 mm faces under the sun: along its edges the surface lies on one
    // side only, and B falls toward the edge within the profile's near length, which the
    // faces' centroids (inside) overstated: 28-36 % RMS, 97 % at a corner, for the dipole.
    // Each such vertex is now a receiver of its own: 0.05-0.09 % for either profile (3-4 %
    // for Cycles' profile while it still used its faces' links, sampled from their centroids).
    let n = 31;
    let mesh = plane(n, 20.0);
    let on_edge = |v: usize| {
        let (i, j) = (v % n, v / n);
        i == 0 || j == 0 || i == n - 1 || j == n - 1
    };
    let receivers: Vec<u32> = (0..n * n)
        .filter(|&v| on_edge(v))
        .step_by(3)
        .map(|v| v as u32)
        .collect();
    let weights = vec![1.0f32; receivers.len()];
    let mut scene = Scene::new(mesh);
    scene
        .lights
        .push(Light::sun(Vec3::new(0.2, 0.1, -1.0), [1.0; 3]).unwrap());
    for name in ["marble", "skimmilk"] {
        let half_space = Material::preset(name, 1.0).unwrap();
        for model in PROFILES {
            let m = for_profile(half_space, model);
            let e = error_on(&scene, &m, model, &receivers, &weights);
            eprintln!("edge, {name} {model:?}: {e:?}");
            assert!(e.worst_rms() < 0.01, "{name} {model:?}: {e:?}");
        }
    }
}

#[test]
fn render_mode_after_a_light_move_equals_a_fresh_evaluation() {
    let mesh = lumpy_sphere(10.0, 16, 32, 0.1);
    let m = Material::preset("skin1", 1.0).unwrap();
    let scene = lit(mesh, Vec3::new(20.0, -10.0, 30.0));
    let mut render =
        Hierarchy::new(scene.clone(), settings(ProfileKind::Dipole, Mode::Render)).unwrap();
    let before = render.radiosity(&m).unwrap().values;
    let moved = vec![Light::point(Vec3::new(-25.0, 5.0, -10.0), [4e4; 3]).unwrap()];
    render.set_lights(moved.clone(), World::Black);
    let after = render.radiosity(&m).unwrap().values;
    assert!(!render.report().relinked, "render mode keeps its links");
    let mut fresh_scene = scene.clone();
    fresh_scene.lights = moved;
    let mut fresh =
        Hierarchy::new(fresh_scene, settings(ProfileKind::Dipole, Mode::OnTheFly)).unwrap();
    let expect = fresh.radiosity(&m).unwrap().values;
    let w = render.scene().mesh.vertex_areas().to_vec();
    let e = relative_error(&after, &expect, &w).unwrap();
    assert!(e.worst_rms() < 1e-5, "render vs on-the-fly: {e:?}");
    // And the light did move: the answer changed.
    assert!(relative_error(&before, &after, &w).unwrap().worst_rms() > 0.1);
}

#[test]
fn incremental_after_a_deformation_equals_a_fresh_build() {
    let mesh = lumpy_sphere(10.0, 20, 40, 0.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let scene = lit(mesh.clone(), Vec3::new(20.0, -10.0, 30.0));
    let mut inc = Hierarchy::new(
        scene.clone(),
        settings(ProfileKind::Dipole, Mode::Incremental),
    )
    .unwrap();
    inc.radiosity(&m).unwrap();
    // Squash and twist: a deformation, same topology.
    let deformed: Vec<Vec3> = mesh
        .positions()
        .iter()
        .map(|p| {
            let a = 0.04 * p.z;
            Vec3::new(
                p.x * a.cos() - p.y * a.sin(),
                p.x * a.sin() + p.y * a.cos(),
                0.6 * p.z,
            )
        })
        .collect();
    inc.set_positions(deformed.clone(), None).unwrap();
    let got = inc.radiosity(&m).unwrap().values;
    assert!(inc.report().relinked);
    let fresh_mesh = Mesh::new(deformed, mesh.triangles().to_vec(), None).unwrap();
    let mut fresh = Hierarchy::new(
        lit(fresh_mesh, Vec3::new(20.0, -10.0, 30.0)),
        settings(ProfileKind::Dipole, Mode::OnTheFly),
    )
    .unwrap();
    let expect = fresh.radiosity(&m).unwrap().values;
    let w = inc.scene().mesh.vertex_areas().to_vec();
    let e = relative_error(&got, &expect, &w).unwrap();
    eprintln!("incremental vs fresh: {e:?}");
    assert!(e.worst_rms() < 0.01, "incremental vs fresh: {e:?}");
    // A material change re-checks the links too (marble to ketchup: mostly demotions; the
    // links kept are finer than a fresh refinement's) and agrees within the accuracy bar.
    let ketchup = Material::preset("ketchup", 1.0).unwrap();
    let got = inc.radiosity(&ketchup).unwrap().values;
    let expect = fresh.radiosity(&ketchup).unwrap().values;
    let e = relative_error(&got, &expect, &w).unwrap();
    assert!(
        e.worst_rms() < 0.02,
        "incremental vs fresh after a material change: {e:?}"
    );
}

#[test]
fn bad_input_is_an_error() {
    let mesh = plane(5, 1.0);
    let bad = HierarchySettings {
        eps_emitter: f64::NAN,
        ..Default::default()
    };
    assert!(Hierarchy::new(Scene::new(mesh.clone()), bad).is_err());
    let mut h = Hierarchy::new(Scene::new(mesh), HierarchySettings::default()).unwrap();
    assert!(h.set_positions(vec![Vec3::ZERO; 3], None).is_err());
    let mut p = h.scene().mesh.positions().to_vec();
    p[0].x = f32::NAN;
    assert!(h.set_positions(p, None).is_err());
    assert!(Mode::parse("fast").is_err());
}

//! The peeled sources (`peel`: the world, area lights, point lights no frustum holds) against
//! the plane's closed form under a uniform world (Jensen 2001's R_total times the entering
//! irradiance, integrated here by a midpoint rule) and the ground truth
//! (`reference_radiosity` with the scene's own irradiance estimate).

use super::super::*;
use crate::irradiance::IrradianceSettings;
use crate::mesh::test_meshes::oracles::rd_total;
use crate::mesh::test_meshes::{nearest, plane, sphere, sphere_pair};
use crate::mesh::Mesh;
use crate::metrics::ErrorStats;
use crate::optics::{fresnel_transmittance, Material};
use crate::profiles::ProfileKind;
use crate::raytrace::Tracer;
use light_view::{BoundingSphere, LightSample};
use peel::PeelCounts;

fn marble_dipole() -> Resolved {
    Resolved::new(
        ProfileKind::Dipole,
        &Material::preset("marble", 1.0).unwrap(),
    )
    .unwrap()
}

/// The splatting of `scene` against the ground truth at every `step`-th vertex, and the
/// evaluation.
fn against_truth(scene: &Scene, r: &Resolved, step: usize) -> (ErrorStats, Evaluation) {
    let mesh = &scene.mesh;
    let e = splat_radiosity(scene, r, &SplatSettings::default(), None).unwrap();
    let receivers: Vec<u32> = (0..mesh.vertex_count() as u32).step_by(step).collect();
    let (err, truth) = super::against_ground_truth(scene, r, &e.values, &receivers, 1);
    let p = e.details.peel.as_ref().expect("peeled sources");
    eprintln!(
        "{} vertices: {} splats ({} peeled: grid {}, {} layers, {} irradiance rays, {:.2} s), \
         splat {:.2} s; against the ground truth (level {}) rel RMS {:?}",
        mesh.vertex_count(),
        e.details.splats,
        p.counts.samples,
        p.counts.grid,
        p.counts.layers,
        p.counts.irradiance_rays,
        p.seconds,
        e.details.seconds_splat,
        truth.level,
        err.rel_rms,
    );
    (err, e)
}

#[test]
fn a_uniform_world_over_a_plane_gives_the_closed_form_less_eps() {
    // 100 mm of marble in mm under a world of radiance 1: away from the edges the surface takes
    // E = 2 pi int_0^1 F_t(eta, mu) mu dmu from the upper hemisphere, and B = E R_total (Jensen
    // 2001) less the eps of it eq. 4 leaves beyond r_max. The plane is met by the view along
    // Z alone (patches h^2, h = 141 mm / 1024), and the irradiance of each crossing is 8
    // cosine-weighted rays.
    let mesh = plane(81, 100.0);
    let centre = nearest(&mesh, Vec3::ZERO);
    let r = marble_dipole();
    let m = r.material;
    let mut scene = Scene::new(mesh.clone());
    scene.world = World::uniform([1.0; 3]).unwrap();
    let e = splat_radiosity(&scene, &r, &SplatSettings::default(), None).unwrap();
    let steps = 20_000;
    let entering: f64 = (0..steps)
        .map(|k| {
            let mu = (k as f64 + 0.5) / steps as f64;
            fresnel_transmittance(m.eta, mu) * mu / steps as f64
        })
        .sum::<f64>()
        * 2.0
        * std::f64::consts::PI;
    let p = e.details.peel.as_ref().unwrap();
    assert!(p.world && p.lights.is_empty());
    assert_eq!(p.counts.grid, DEFAULT_PEEL_GRID);
    assert_eq!(p.counts.layers, 1, "a sheet is crossed once");
    assert!(e.details.lights.is_empty());
    assert!(!e.skipped.iter().any(|s| s.what.contains("world")));
    for c in 0..3 {
        let expect = (1.0 - 0.01) * entering * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
        let got = f64::from(e.values[centre][c]);
        eprintln!("channel {c}: {:+.3} %", 100.0 * (got / expect - 1.0));
        assert!(
            (got / expect - 1.0).abs() < 0.01,
            "channel {c}: {got} vs {expect} ({:+.2} %)",
            100.0 * (got / expect - 1.0)
        );
    }
}

#[test]
fn the_world_and_an_area_light_match_the_ground_truth_on_a_sphere() {
    // A 10 mm marble sphere (in mm) under a dim world and a 30 mm square area light above one
    // side: every vertex is lit, the area light's penumbra-free cosine falls off across the
    // terminator, and both are peeled (no light view holds either).
    let mesh = sphere(24, 10.0);
    let mut scene = Scene::new(mesh.clone());
    scene.world = World::uniform([0.05, 0.08, 0.1]).unwrap();
    scene.lights.push(
        Light::area(
            Vec3::new(20.0, 0.0, 30.0),
            Vec3::new(-0.5, 0.0, -1.0),
            Vec3::Y,
            30.0,
            30.0,
            [2000.0; 3],
        )
        .unwrap(),
    );
    let (err, e) = against_truth(&scene, &marble_dipole(), 9);
    let p = e.details.peel.as_ref().unwrap();
    assert_eq!(p.lights.len(), 1);
    assert!(p.lights[0].1.contains("area"), "{:?}", p.lights);
    assert_eq!(p.counts.layers, 2, "a closed sphere is crossed twice");
    assert!(err.worst_rms() < 0.03, "{err:?}");
}

#[test]
fn a_point_light_between_two_objects_matches_the_ground_truth() {
    // Two 5 mm marble spheres 10 mm apart (centres at x = -10 and +10) with a point light
    // half way: it lies inside the mesh's bounding sphere, where no frustum holds the mesh,
    // so it is peeled; each sphere is lit on the side facing the other, and no light passes
    // between them (their objects differ).
    let mesh = sphere_pair(24, 5.0, 10.0);
    let mut scene = Scene::new(mesh.clone());
    scene
        .lights
        .push(Light::point(Vec3::ZERO, [500.0; 3]).unwrap());
    let (err, e) = against_truth(&scene, &marble_dipole(), 3);
    let p = e.details.peel.as_ref().unwrap();
    assert_eq!(p.lights.len(), 1);
    assert!(p.lights[0].1.contains("inside"), "{:?}", p.lights);
    assert!(!p.world);
    assert!(e.details.lights.is_empty());
    assert!(err.worst_rms() < 0.03, "{err:?}");
}

#[test]
fn a_bad_peel_grid_is_refused_naming_it() {
    let mut scene = Scene::new(sphere(8, 1.0));
    scene.world = World::uniform([1.0; 3]).unwrap();
    for peel_grid in [0, MAX_GRID + 1] {
        let s = SplatSettings {
            peel_grid,
            ..Default::default()
        };
        let e = splat_radiosity(&scene, &marble_dipole(), &s, None).unwrap_err();
        assert!(e.to_string().contains("peel_grid"), "{e}");
    }
}

/// A mesh whose every ray crosses it `layers` times: that many parallel planes 1 mm apart.
fn stacked_planes(layers: usize) -> Mesh {
    let (mut p, mut t) = (Vec::new(), Vec::new());
    for k in 0..layers {
        let (q, u) = crate::mesh::test_meshes::plane_parts(5, 20.0);
        let base = p.len() as u32;
        p.extend(q.iter().map(|x| *x + Vec3::Z * k as f32));
        t.extend(u.iter().map(|tri| tri.map(|v| v + base)));
    }
    Mesh::new(p, t, None).unwrap()
}

/// The peeled samples of `mesh` under a uniform world with nothing to shadow them (the shadow
/// rays ask a far-off speck), and their counts.
fn unshadowed_peel(mesh: &Mesh) -> (Vec<LightSample>, PeelCounts) {
    let speck = Mesh::new(
        vec![
            Vec3::splat(1e4),
            Vec3::new(1e4 + 1e-3, 1e4, 1e4),
            Vec3::new(1e4, 1e4 + 1e-3, 1e4),
        ],
        vec![[0, 1, 2]],
        None,
    )
    .unwrap();
    let world = World::uniform([1.0; 3]).unwrap();
    peel::peeled_samples(
        mesh,
        (&Tracer::new(mesh), &Tracer::new(&speck)),
        &BoundingSphere::of(mesh),
        DEFAULT_PEEL_GRID,
        ((&[], &[]), &world),
        None,
        &IrradianceSettings::default(),
        None,
        (0.0, 1.0),
    )
    .unwrap()
}

#[test]
fn every_layer_is_peeled_and_the_patches_add_up_to_the_surface() {
    // Five stacked 20 mm sheets 1 mm apart: every ray along Z that meets one meets all five
    // (depth peeling until no fragment is left). A closed sphere: each view crosses it twice,
    // and the patches h^2 / |n . d_k|, each kept by the view most nearly along its normal,
    // add up to its area, wherever it faces.
    let sheets = stacked_planes(5);
    let (s, counts) = unshadowed_peel(&sheets);
    assert_eq!(counts.layers, 5);
    assert_eq!(counts.unlit, 0);
    let area: f64 = s.iter().map(|s| f64::from(s.area)).sum();
    eprintln!("sheets: {counts:?}, patches {area:.2} mm^2 of 2000");
    assert!((area / 2000.0 - 1.0).abs() < 0.01, "{area}");
    for radius in [1.0f32, 10.0] {
        let ball = sphere(48, radius);
        let (s, counts) = unshadowed_peel(&ball);
        let truth: f64 = ball.triangle_areas().iter().map(|a| f64::from(*a)).sum();
        let area: f64 = s.iter().map(|s| f64::from(s.area)).sum();
        eprintln!(
            "sphere {radius}: {counts:?}, patches {:+.3} % of its area",
            100.0 * (area / truth - 1.0)
        );
        assert_eq!(counts.layers, 2);
        assert!((area / truth - 1.0).abs() < 0.005, "{area} vs {truth}");
    }
}

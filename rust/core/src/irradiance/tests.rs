//! The irradiance estimate against closed forms: the sun's, a point light's inverse square,
//! a uniform world's, shadows, and the rays it leaves out.
use super::*;
use crate::mesh::Mesh;

/// A unit-spaced square in z = 0 of side `size`, plus optionally a small blocker square
/// at height 1 above the origin.
fn scene(size: f32, blocker: bool) -> Scene {
    let h = size / 2.0;
    let mut p = vec![
        Vec3::new(-h, -h, 0.0),
        Vec3::new(h, -h, 0.0),
        Vec3::new(h, h, 0.0),
        Vec3::new(-h, h, 0.0),
    ];
    let mut t = vec![[0, 1, 2], [0, 2, 3]];
    if blocker {
        let b = 0.2;
        p.extend([
            Vec3::new(-b, -b, 1.0),
            Vec3::new(b, -b, 1.0),
            Vec3::new(b, b, 1.0),
            Vec3::new(-b, b, 1.0),
        ]);
        t.extend([[4, 5, 6], [4, 6, 7]]);
    }
    Scene::new(Mesh::new(p, t, None).unwrap())
}

fn eval(s: &Scene, pts: &[Vec3], eta: f64) -> (Vec<[f32; 3]>, IrradianceReport) {
    let tracer = Tracer::new(&s.mesh);
    let settings = IrradianceSettings {
        eta,
        world_samples: 1024,
        area_samples: 256,
        seed: 3,
        ..Default::default()
    };
    irradiance(s, &tracer, pts, &vec![Vec3::Z; pts.len()], &settings).unwrap()
}

/// Every channel of `a` within 1e-6 (relative, absolute below 1) of `b`'s.
fn assert_close(a: &[[f32; 3]], b: &[[f32; 3]]) {
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            assert!(
                (x[c] - y[c]).abs() <= 1e-6 * y[c].abs().max(1.0),
                "{x:?} vs {y:?}"
            );
        }
    }
}

#[test]
fn per_source_casts_rays_only_for_the_lights_that_changed() {
    let mut s = scene(4.0, true);
    let pts: Vec<Vec3> = (0..25)
        .map(|i| {
            Vec3::new(
                -1.0 + 0.5 * (i % 5) as f32,
                -1.0 + 0.5 * (i / 5) as f32,
                0.0,
            )
        })
        .collect();
    let normals = vec![Vec3::Z; pts.len()];
    let tracer = Tracer::new(&s.mesh);
    let settings = IrradianceSettings::default();
    s.lights = vec![
        Light::sun(Vec3::new(0.3, 0.2, -1.0), [2.0; 3]).unwrap(),
        Light::point(Vec3::new(0.5, 0.0, 3.0), [40.0, 20.0, 10.0]).unwrap(),
    ];
    let mut cache = PerSource::default();
    let (a, ra) = cache
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_eq!(ra.rays, 50, "both lights, every point");
    // The point light moves; the sun stays.
    s.lights[1] = Light::point(Vec3::new(-0.5, 0.4, 2.0), [40.0, 20.0, 10.0]).unwrap();
    let (b, rb) = cache
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_eq!(rb.rays, 25, "only the moved light casts rays");
    let (fresh, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&b, &fresh);
    assert!(a.iter().zip(&b).any(|(x, y)| (x[0] - y[0]).abs() > 0.01));
    // The point light's power and colour alone: its values rescaled, no ray.
    s.lights[1] = Light::point(Vec3::new(-0.5, 0.4, 2.0), [80.0, 20.0, 5.0]).unwrap();
    let (brighter, rs) = cache
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_eq!(rs.rays, 0, "a power or colour change casts no ray");
    let (fresh, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&brighter, &fresh);
    // Nothing changed: no rays; a light removed: no rays and its share gone.
    let (_, rc) = cache
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_eq!(rc.rays, 0);
    s.lights.truncate(1);
    let (d, rd) = cache
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_eq!(rd.rays, 0);
    let (sun_only, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_eq!(d, sun_only);
    // Another eta is another irradiance: everything again.
    let eta = IrradianceSettings {
        eta: 1.4,
        ..settings
    };
    let (_, re) = cache.evaluate(&s, &tracer, &pts, &normals, &eta).unwrap();
    assert_eq!(re.rays, 25);
}

/// The world by nine SH coefficients, unshadowed (Mertens §5.3): an environment of
/// radiance 1 + z/2 over an upward plane has E = pi + pi/3 for eta = 1 (Ramamoorthi &
/// Hanrahan's pi and 2 pi / 3 on Y_00 and Y_10, written out here), no rays; the traced
/// world agrees within its noise, and a blocker above shadows only the traced one.
#[test]
fn the_world_by_nine_coefficients_meets_its_closed_form_without_rays() {
    let (w, h) = (256usize, 128usize);
    let image: Vec<[f32; 3]> = (0..w * h)
        .map(|i| {
            // Row 0 is the zenith (lights::World::radiance): z = sin(latitude).
            let v = 1.0 - ((i / w) as f32 + 0.5) / h as f32;
            let z = (std::f32::consts::PI * (v - 0.5)).sin();
            [1.0 + 0.5 * z; 3]
        })
        .collect();
    let run = |blocker: bool, unshadowed: bool| {
        let mut s = scene(10.0, blocker);
        s.world = World::environment(w, h, image.clone()).unwrap();
        let tracer = Tracer::new(&s.mesh);
        let settings = IrradianceSettings {
            world_samples: 1024,
            world_unshadowed: unshadowed,
            ..Default::default()
        };
        irradiance(
            &s,
            &tracer,
            &[Vec3::new(0.0, 0.0, 0.0)],
            &[Vec3::Z],
            &settings,
        )
        .unwrap()
    };
    let want = std::f64::consts::PI * (1.0 + 1.0 / 3.0);
    let (sh, report) = run(false, true);
    assert_eq!(report.rays, 0);
    assert!(
        (f64::from(sh[0][0]) / want - 1.0).abs() < 0.005,
        "{sh:?} vs {want}"
    );
    let (traced, _) = run(false, false);
    assert!(
        (f64::from(traced[0][0]) / want - 1.0).abs() < 0.03,
        "{traced:?}"
    );
    let (blocked_sh, _) = run(true, true);
    let (blocked, _) = run(true, false);
    assert_eq!(blocked_sh[0], sh[0]);
    assert!(
        blocked[0][0] < 0.95 * traced[0][0],
        "{blocked:?} vs {traced:?}"
    );
}

/// Unpolarised dielectric transmittance written out apart from `optics`.
fn ft(eta: f64, c: f64) -> f64 {
    let ct = (1.0 - (1.0 - c * c) / (eta * eta)).sqrt();
    let rs = (c - eta * ct) / (c + eta * ct);
    let rp = (eta * c - ct) / (eta * c + ct);
    1.0 - 0.5 * (rs * rs + rp * rp)
}

#[test]
fn sun_gives_fresnel_strength_cosine() {
    let mut s = scene(10.0, false);
    for (theta, eta) in [(0.0f64, 1.0), (0.5, 1.0), (1.0, 1.3), (1.4, 1.3)] {
        s.lights = vec![Light::sun(
            Vec3::new(theta.sin() as f32, 0.0, -theta.cos() as f32),
            [2.0, 1.0, 0.5],
        )
        .unwrap()];
        let (i, rep) = eval(&s, &[Vec3::new(1.0, 1.0, 0.0)], eta);
        let expect = ft(eta, theta.cos()) * theta.cos() * 2.0;
        assert!((f64::from(i[0][0]) - expect).abs() < 1e-5, "theta {theta}");
        assert!((i[0][2] / i[0][0] - 0.25).abs() < 1e-6);
        assert_eq!(rep.rays, 1);
    }
}

#[test]
fn point_light_follows_inverse_square_and_cosine() {
    let mut s = scene(10.0, false);
    s.lights = vec![Light::point(Vec3::new(0.0, 0.0, 2.0), [100.0; 3]).unwrap()];
    let x = Vec3::new(1.5, 0.0, 0.0);
    let (i, _) = eval(&s, &[x], 1.0);
    let d2 = 1.5f64 * 1.5 + 4.0;
    let expect = 100.0 / (4.0 * std::f64::consts::PI) * (2.0 / d2.sqrt()) / d2;
    assert!((f64::from(i[0][0]) - expect).abs() < 1e-5 * expect);
}

#[test]
fn blocker_casts_a_shadow() {
    let mut s = scene(10.0, true);
    s.lights = vec![Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap()];
    // -Z negated is (-0, -0, 1): negative zeros must not confuse the BVH traversal.
    let (i, _) = eval(
        &s,
        &[
            Vec3::new(0.05, 0.0, 0.0),
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
        ],
        1.0,
    );
    assert_eq!(i[0], [0.0; 3]);
    assert_eq!(i[1], [0.0; 3]);
    assert!((i[2][0] - 1.0).abs() < 1e-6);
}

#[test]
fn uniform_world_gives_pi_l_times_average_fresnel() {
    let mut s = scene(10.0, false);
    s.world = World::uniform([0.5; 3]).unwrap();
    let (i, rep) = eval(&s, &[Vec3::new(0.3, 0.2, 0.0)], 1.0);
    assert!((f64::from(i[0][0]) - 0.5 * std::f64::consts::PI).abs() < 1e-4);
    assert_eq!(rep.rays, 1024);
    // eta = 1.3: pi L * 2 int F_t(mu) mu dmu, by Simpson here; stratified MC within 1 %.
    let n = 20_000;
    let h = 1.0 / n as f64;
    let mut avg = 0.0;
    for k in 0..=n {
        let mu = k as f64 * h;
        let w = if k == 0 || k == n {
            1.0
        } else if k % 2 == 1 {
            4.0
        } else {
            2.0
        };
        avg += w * 2.0 * ft(1.3, mu.max(1e-12)) * mu;
    }
    avg *= h / 3.0;
    let (i, _) = eval(&s, &[Vec3::new(0.3, 0.2, 0.0)], 1.3);
    let expect = 0.5 * std::f64::consts::PI * avg;
    assert!(
        (f64::from(i[0][0]) - expect).abs() < 0.01 * expect,
        "{} vs {expect}",
        i[0][0]
    );
}

#[test]
fn small_far_area_light_approaches_a_point_light() {
    let mut s = scene(10.0, false);
    let pos = Vec3::new(0.0, 0.0, 20.0);
    // An area light of power P radiates P / pi W/sr along its normal: a point light of
    // power 4 P gives the same on-axis intensity (P/(4 pi) * 4).
    s.lights = vec![Light::area(pos, -Vec3::Z, Vec3::X, 0.2, 0.2, [10.0; 3]).unwrap()];
    let (a, _) = eval(&s, &[Vec3::ZERO], 1.0);
    s.lights = vec![Light::point(pos, [40.0; 3]).unwrap()];
    let (p, _) = eval(&s, &[Vec3::ZERO], 1.0);
    assert!(
        (a[0][0] / p[0][0] - 1.0).abs() < 1e-3,
        "{} vs {}",
        a[0][0],
        p[0][0]
    );
}

#[test]
fn spot_lights_inside_and_outside_the_cone() {
    let mut s = scene(10.0, false);
    s.lights = vec![Light::spot(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z, [50.0; 3], 1.0, 0.0).unwrap()];
    // Half angle 0.5 rad: tan(0.5) = 0.546 at height 1.
    let (i, _) = eval(
        &s,
        &[Vec3::new(0.3, 0.0, 0.0), Vec3::new(0.8, 0.0, 0.0)],
        1.0,
    );
    let d2 = 1.09f64;
    let expect = 50.0 / (4.0 * std::f64::consts::PI) / d2 * (1.0 / d2.sqrt());
    assert!((f64::from(i[0][0]) - expect).abs() < 1e-5 * expect);
    assert_eq!(i[1][0], 0.0);
}

#[test]
fn black_lights_and_world_cost_no_rays() {
    let mut s = scene(10.0, false);
    s.lights = vec![Light::point(Vec3::Z, [0.0; 3]).unwrap()];
    s.world = World::uniform([0.0; 3]).unwrap();
    let (i, rep) = eval(&s, &[Vec3::ZERO; 5], 1.3);
    assert_eq!(rep.rays, 0);
    assert_eq!(rep.lights_skipped, 1);
    assert!(rep.world_skipped);
    assert!(i.iter().all(|x| *x == [0.0; 3]));
    // A light behind every point casts no ray either.
    s.lights = vec![Light::point(Vec3::new(0.0, 0.0, -3.0), [5.0; 3]).unwrap()];
    let (_, rep) = eval(&s, &[Vec3::ZERO; 5], 1.3);
    assert_eq!(rep.rays, 0);
}

#[test]
fn lights_that_cannot_reach_the_mesh_cost_nothing() {
    let mut s = scene(10.0, false);
    let points = [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0)];
    // A spot 20 above the plane's middle aimed straight up, and an area light below the
    // plane facing down: neither can reach it.
    s.lights = vec![
        Light::spot(Vec3::new(0.0, 0.0, 20.0), Vec3::Z, [50.0; 3], 1.0, 0.1).unwrap(),
        Light::area(
            Vec3::new(0.0, 0.0, -1.0),
            -Vec3::Z,
            Vec3::X,
            1.0,
            1.0,
            [9.0; 3],
        )
        .unwrap(),
    ];
    let (i, rep) = eval(&s, &points, 1.3);
    assert_eq!(rep.lights_unreached, 2);
    assert_eq!(rep.lights_used, 0);
    assert_eq!(rep.rays, 0);
    assert!(i.iter().all(|x| *x == [0.0; 3]));
    // Turned toward the plane, both are used and light it.
    s.lights = vec![
        Light::spot(Vec3::new(0.0, 0.0, 20.0), -Vec3::Z, [50.0; 3], 1.0, 0.1).unwrap(),
        Light::area(
            Vec3::new(0.0, 0.0, 1.0),
            -Vec3::Z,
            Vec3::X,
            1.0,
            1.0,
            [9.0; 3],
        )
        .unwrap(),
    ];
    let (i, rep) = eval(&s, &points, 1.3);
    assert_eq!((rep.lights_unreached, rep.lights_used), (0, 2));
    assert!(rep.rays > 0 && i[0][0] > 0.0);
    // A spot whose cone only grazes the plane's bounding ball is kept (conservative).
    s.lights = vec![Light::spot(Vec3::new(20.0, 0.0, 0.5), -Vec3::X, [50.0; 3], 0.2, 0.0).unwrap()];
    let (_, rep) = eval(&s, &points, 1.3);
    assert_eq!(rep.lights_unreached, 0);
}

#[test]
fn mismatched_inputs_are_errors() {
    let s = scene(1.0, false);
    let t = Tracer::new(&s.mesh);
    let r = irradiance(&s, &t, &[Vec3::ZERO], &[], &IrradianceSettings::default());
    assert!(r.is_err());
}

#[test]
fn corners_give_each_samples_own_shadow_ray_answer_with_a_ray_per_vertex() {
    // A 10 mm sphere under a point light and a sun, a square blocker casting a shadow across
    // it, samples at 0.3 mm: read from the corners (`corners`), every sample's irradiance is
    // the one its own shadow ray gives, but for the few triangles a shadow's edge crosses
    // without touching a corner; the rays fall to the vertices plus the samples of the
    // triangles the edges cross.
    use crate::mesh::test_meshes::sphere;
    let mesh = sphere(24, 5.0);
    let mut scene = Scene::new(mesh.clone());
    scene
        .lights
        .push(Light::point(Vec3::new(3.0, -4.0, 30.0), [4.0e3; 3]).unwrap());
    scene
        .lights
        .push(Light::sun(Vec3::new(-0.6, 0.3, -0.74), [1.0; 3]).unwrap());
    let b = 3.0;
    let wall = [
        Vec3::new(-b, -b, 12.0),
        Vec3::new(b, -b, 12.0),
        Vec3::new(b, b, 12.0),
        Vec3::new(-b, b, 12.0),
    ];
    scene
        .occluders
        .add("blocker", &wall, &[[0, 1, 2], [0, 2, 3]], [0.0; 3])
        .unwrap();
    let tracer = scene.tracer();
    let samples = mesh.surface_samples(0.3).unwrap();
    let points: Vec<Vec3> = samples.iter().map(|s| s.position).collect();
    let normals: Vec<Vec3> = samples.iter().map(|s| s.normal).collect();
    let triangles: Vec<u32> = samples.iter().map(|s| s.triangle).collect();
    let settings = IrradianceSettings {
        eta: 1.4,
        ..Default::default()
    };
    let (each, r_each) = PerSource::default()
        .evaluate(&scene, &tracer, &points, &normals, &settings)
        .unwrap();
    let (read, r_read) = PerSource::default()
        .evaluate_on_mesh(
            &scene,
            &tracer,
            &points,
            &normals,
            Some(&triangles),
            &settings,
            None,
        )
        .unwrap();
    let (mut total, mut off, mut differing) = (0.0f64, 0.0f64, 0usize);
    for ((a, b), s) in each.iter().zip(&read).zip(&samples) {
        total += f64::from(a[0] * s.area);
        off += f64::from((a[0] - b[0]).abs() * s.area);
        differing += usize::from(a != b);
    }
    eprintln!(
        "{} samples, {differing} differ, {:.4} % of the light; rays {} -> {}",
        samples.len(),
        100.0 * off / total,
        r_each.rays,
        r_read.rays
    );
    assert!(off < 2e-3 * total, "{off} of {total}");
    assert!(
        differing * 200 < samples.len(),
        "{differing} of {}",
        samples.len()
    );
    assert!(
        4 * r_read.rays < r_each.rays,
        "{} vs {}",
        r_read.rays,
        r_each.rays
    );
    // Shadow edges and terminators do cross triangles: some samples cast their own ray.
    assert!(r_read.rays > 2 * mesh.vertex_count() as u64);
}

#[test]
fn shadow_linking_lets_only_a_lights_blockers_cast_its_shadows() {
    // A 10-unit plane under two suns straight down (1 and 2 W/m^2) and two occluder squares
    // above it, "roof" over x < 0 and "shade" over x > 0. The first sun is blocked by "roof"
    // alone (Cycles' blocker collection), the second by both: below "roof" neither sun arrives,
    // below "shade" only the first (1), in the open both (3): the suns' closed form, E cos.
    let mut s = scene(10.0, false);
    let square = |x0: f32| {
        [(x0, -1.0), (x0 + 2.0, -1.0), (x0 + 2.0, 1.0), (x0, 1.0)]
            .map(|(x, y)| Vec3::new(x, y, 1.0))
    };
    let tris = [[0, 1, 2], [0, 2, 3]];
    s.occluders
        .add("roof", &square(-3.0), &tris, [0.0; 3])
        .unwrap();
    s.occluders
        .add("shade", &square(1.0), &tris, [0.0; 3])
        .unwrap();
    s.lights = vec![
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap(),
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [2.0; 3]).unwrap(),
    ];
    s.link_shadows(0, &["roof".to_string()], None).unwrap();
    let pts = [
        Vec3::new(-2.0, 0.0, 0.0),
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(4.0, 3.0, 0.0),
    ];
    let normals = vec![Vec3::Z; pts.len()];
    let settings = IrradianceSettings::default();
    let (tracer, _) = s.shadow_tracer(&Tracer::new(&s.mesh));
    let expect = [[0.0f32; 3], [1.0; 3], [3.0; 3]];
    let (plain, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&plain, &expect);
    // Kept light by light (a precompute's and a relight's path) the same.
    let mut kept = PerSource::default();
    let (by_source, _) = kept
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_close(&by_source, &expect);
    // Unlinked, both suns are blocked by either square.
    s.linking.clear();
    let (unlinked, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&unlinked, &[[0.0; 3], [0.0; 3], [3.0; 3]]);
    // An unknown light or occluder is named.
    let e = s.link_shadows(2, &[], None).unwrap_err().to_string();
    assert!(e.contains("light 2"), "{e}");
    let e = s
        .link_shadows(0, &["lid".to_string()], None)
        .unwrap_err()
        .to_string();
    assert!(e.contains("\"lid\""), "{e}");
}

#[test]
fn a_mesh_left_out_of_a_lights_blockers_casts_none_of_its_shadows() {
    // `scene(10, true)`: the mesh's own small square at height 1 over the origin shadows the
    // plane below it from the suns straight down. Left out of the first sun's (2 W/m^2)
    // blocker collection, it casts none of that sun's shadow; the second (1 W/m^2),
    // unlinked, is still shadowed there. Closed form E cos: 2 below the square, 3 beside it.
    let mut s = scene(10.0, true);
    s.lights = vec![
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [2.0; 3]).unwrap(),
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap(),
    ];
    let pts = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(3.0, 3.0, 0.0)];
    let normals = vec![Vec3::Z; pts.len()];
    let settings = IrradianceSettings::default();
    let tracer = s.tracer();
    let (plain, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&plain, &[[0.0; 3], [3.0; 3]]);
    s.link_shadows(0, &[], Some(&[])).unwrap();
    let expect = [[2.0f32; 3], [3.0; 3]];
    let (linked, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&linked, &expect);
    let mut kept = PerSource::default();
    let (by_source, _) = kept
        .evaluate(&s, &tracer, &pts, &normals, &settings)
        .unwrap();
    assert_close(&by_source, &expect);
    // Light linking kept beside it: the sun not lighting the mesh leaves only the other's 1.
    s.link_light(0, &[], Some(&[])).unwrap();
    let (unlit, _) = irradiance(&s, &tracer, &pts, &normals, &settings).unwrap();
    assert_close(&unlit, &[[0.0; 3], [1.0; 3]]);
}

#[test]
fn linking_follows_each_object_of_the_mesh() {
    // `scene(10, true)` as two objects: the plane (0) and the small square at height 1 over the
    // origin (1), under two suns straight down, 2 and 1 W/m^2. Closed form E cos at a point
    // under the square, one in the open and one on the square's top:
    let mut s = scene(10.0, true);
    s.mesh = s
        .mesh
        .clone()
        .with_objects(vec![0, 0, 0, 0, 1, 1, 1, 1])
        .unwrap();
    s.lights = vec![
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [2.0; 3]).unwrap(),
        Light::sun(Vec3::new(0.0, 0.0, -1.0), [1.0; 3]).unwrap(),
    ];
    let pts = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(3.0, 3.0, 0.0),
        Vec3::new(0.1, 0.05, 1.0),
    ];
    let normals = vec![Vec3::Z; pts.len()];
    let settings = IrradianceSettings::default();
    let tracer = Tracer::new(&s.mesh);
    let check = |s: &Scene, expect: [f32; 3]| {
        let expect = expect.map(|e| [e; 3]);
        let (plain, _) = irradiance(s, &tracer, &pts, &normals, &settings).unwrap();
        assert_close(&plain, &expect);
        let (kept, _) = PerSource::default()
            .evaluate(s, &tracer, &pts, &normals, &settings)
            .unwrap();
        assert_close(&kept, &expect);
    };
    // Unlinked: the square shadows both suns below it.
    check(&s, [0.0, 3.0, 3.0]);
    // The square left out of the first sun's blockers: that sun reaches the plane below it.
    s.link_shadows(0, &[], Some(&[0])).unwrap();
    check(&s, [2.0, 3.0, 3.0]);
    // ... and the first sun lighting the square alone: the plane keeps the second sun's 1.
    s.link_light(0, &[], Some(&[1])).unwrap();
    check(&s, [0.0, 1.0, 3.0]);
    let e = s.link_light(0, &[], Some(&[2])).unwrap_err().to_string();
    assert!(e.contains("object 2, but the mesh holds 2"), "{e}");
}

#[test]
fn the_bounce_error_is_the_unbiased_standard_error_of_the_mean() {
    // Two values 1 and 3: mean 2, unbiased variance ((1 - 2)^2 + (3 - 2)^2) / 1 = 2, standard
    // error sqrt(2 / 2) = 1 (the 1/n variance would give 1/sqrt(2)).
    let (mean, error) = mean_and_error(4.0, 10.0, 2);
    assert!(
        (mean - 2.0).abs() < 1e-12 && (error - 1.0).abs() < 1e-12,
        "{mean} {error}"
    );
    // Equal values: no spread, no error.
    assert_eq!(mean_and_error(15.0, 45.0, 5), (3.0, 0.0));
    // One value: its square bounds the variance (it is all we know).
    assert_eq!(mean_and_error(3.0, 9.0, 1), (3.0, 3.0));
}

/// A sphere of radius `r` (96 rings) centred `d` above the origin, and its triangles.
fn lamp_sphere(r: f32, d: f32) -> (Vec<Vec3>, crate::mesh::Mesh) {
    let sphere = crate::mesh::test_meshes::sphere(96, r);
    let moved = (sphere.positions().iter())
        .map(|p| *p + Vec3::Z * d)
        .collect();
    (moved, sphere)
}

/// The mean irradiance per channel over 64 points of a 7 mm square at the origin, facing up,
/// 256 samples of each spread light.
fn mean_below(s: &Scene) -> [f64; 3] {
    let pts: Vec<Vec3> = (0..64)
        .map(|k| Vec3::new((k % 8) as f32 * 1e-3, (k / 8) as f32 * 1e-3, 0.0))
        .collect();
    let tracer = s.tracer();
    let settings = IrradianceSettings {
        area_samples: 256,
        ..Default::default()
    };
    let (i, _) = irradiance(s, &tracer, &pts, &vec![Vec3::Z; pts.len()], &settings).unwrap();
    std::array::from_fn(|c| i.iter().map(|e| f64::from(e[c])).sum::<f64>() / 64.0)
}

#[test]
fn an_emissive_sphere_gives_pi_l_sin_squared_of_its_angular_radius() {
    // A Lambertian sphere of radiance L and radius r, its centre d above a point facing it
    // (wholly above the horizon): E = pi L (r / d)^2 (the sphere's projected solid angle).
    // Tessellated (96 rings) it holds a little less area: 0.1 %. It emits from both sides of
    // its triangles, as Cycles' mesh emission does, and its near side hides its far side,
    // whether or not it is an occluder as well (the add-on exports it as one, as Cycles'
    // shadow rays see it). Averaged over 64 points of a small square below it; the points lie
    // outside its bounding sphere, so it is sampled by solid angle. A shell around the points
    // (they inside its bounding sphere: sampled by area) gives the closed form of a surface
    // inside a uniformly glowing shell.
    let (r, d, l) = (0.3f32, 2.0f32, 5.0f32);
    let (moved, sphere) = lamp_sphere(r, d);
    let mut s = scene(0.02, false);
    s.lights = vec![Light::mesh(&moved, sphere.triangles(), [l, 0.5 * l, 0.0]).unwrap()];
    let expect = std::f64::consts::PI * f64::from(l) * f64::from(r / d).powi(2);
    let mean = |s: &Scene| {
        let e = mean_below(s);
        assert!((e[1] / e[0] - 0.5).abs() < 1e-5 && e[2] == 0.0, "{e:?}");
        e[0]
    };
    let alone = mean(&s);
    assert!((alone / expect - 1.0).abs() < 0.01, "{alone} vs {expect}");
    s.occluders
        .add("lamp", &moved, sphere.triangles(), [0.0; 3])
        .unwrap();
    let hidden = mean(&s);
    assert!((hidden / expect - 1.0).abs() < 0.01, "{hidden} vs {expect}");
    // A 5 m shell around the points: E = pi L at a surface facing up (the upper hemisphere's
    // cosine-weighted solid angle, pi; the lower half lies behind the surface).
    let shell = crate::mesh::test_meshes::sphere(64, 5.0);
    let mut inside = scene(0.02, false);
    let glow = [l, 0.5 * l, 0.0];
    inside.lights = vec![Light::mesh(shell.positions(), shell.triangles(), glow).unwrap()];
    let within = mean(&inside);
    let expect = std::f64::consts::PI * f64::from(l);
    assert!((within / expect - 1.0).abs() < 0.01, "{within} vs {expect}");
}

#[test]
fn a_half_glowing_sphere_lights_what_sees_its_glowing_half_and_through_itself_when_shadowless() {
    // The sphere of the test above, its faces below the equator glowing L (c0, c1, c2) = (1,
    // 0.5, 0.25) through the corners' factors, those above black. The points below it see the
    // cap z < -r^2/d of its near side only: the glowing half, pi L (r / d)^2 (sampled by solid
    // angle, the cone's hit reading its triangle's factors). The upper half glowing instead:
    // hidden by the near side, nothing. Hidden from shadow rays, the emitter hides nothing of
    // itself (each direction of the cone adds up both its crossings): the whole sphere gives
    // twice pi L (r / d)^2, its far side seen through its near side. Inside a shell glowing
    // on its upper half only, a surface facing up receives the closed form pi L of the whole
    // shell; on its lower half only, nothing.
    let (r, d, l) = (0.3f32, 2.0f32, 5.0f32);
    let (moved, sphere) = lamp_sphere(r, d);
    let tint = [1.0f32, 0.5, 0.25];
    let glowing = |mesh: &crate::mesh::Mesh, lower: bool, upper: bool| -> Vec<[[f32; 3]; 3]> {
        (mesh.triangles().iter())
            .map(|t| {
                let z: f32 = t.iter().map(|&i| mesh.positions()[i as usize].z).sum();
                let on = if z < 0.0 { lower } else { upper };
                [if on { tint } else { [0.0; 3] }; 3]
            })
            .collect()
    };
    let mean = |lights: Vec<Light>| -> [f64; 3] {
        let mut s = scene(0.02, false);
        s.lights = lights;
        mean_below(&s)
    };
    let lamp = |lower, upper, shadow| {
        let corners = glowing(&sphere, lower, upper);
        Light::textured_mesh(&moved, sphere.triangles(), [l; 3], Some(&corners), shadow).unwrap()
    };
    let cap = std::f64::consts::PI * f64::from(l) * f64::from(r / d).powi(2);
    let near = |got: [f64; 3], times: f64, what: &str| {
        for c in 0..3 {
            let expect = times * cap * f64::from(tint[c]);
            assert!(
                (got[c] - expect).abs() <= 0.015 * cap * times.max(1.0),
                "{what}, channel {c}: {} vs {expect}",
                got[c]
            );
        }
    };
    near(mean(vec![lamp(true, false, true)]), 1.0, "lower half");
    near(
        mean(vec![lamp(false, true, true)]),
        0.0,
        "upper half, hidden",
    );
    // Each half apart adds up to the whole: seen through the
    // near side, the far crossings reach below the equator (to z = -r^2 / d), so a half alone
    // has no closed form of its own.
    let (up, down) = (
        mean(vec![lamp(false, true, false)]),
        mean(vec![lamp(true, false, false)]),
    );
    near(
        std::array::from_fn(|c| up[c] + down[c]),
        2.0,
        "halves, shadowless",
    );
    near(
        mean(vec![lamp(true, true, false)]),
        2.0,
        "whole, shadowless",
    );
    // Sampled by power inside a shell of 5 m (the points within its bounding sphere): no
    // sample falls on the black half.
    let shell = crate::mesh::test_meshes::sphere(64, 5.0);
    let sky = |lower, upper| {
        let corners = glowing(&shell, lower, upper);
        let light = Light::textured_mesh(
            shell.positions(),
            shell.triangles(),
            [l; 3],
            Some(&corners),
            true,
        );
        mean(vec![light.unwrap()])
    };
    let whole = std::f64::consts::PI * f64::from(l);
    let upper = sky(false, true);
    let lower = sky(true, false);
    for c in 0..3 {
        let expect = whole * f64::from(tint[c]);
        assert!(
            (upper[c] / expect - 1.0).abs() < 0.01,
            "{upper:?} vs {expect}"
        );
        assert!(lower[c].abs() < 1e-3 * expect, "{lower:?}");
    }
}

/// Over the vertices of a 2 x 2 plane (21 x 21) in z = 0 with a 0.6-wide blocker at height 0.5
/// above its middle, lit by `light` and `world`: the stated variance of the irradiance
/// (`PerSource::sampling_error` squared, averaged) and the variance between two seeds (half
/// the squared difference of their estimates, averaged), per channel, over four pairs of seeds.
fn stated_and_seed_variance(light: Option<Light>, world: World, samples: u32) -> [(f64, f64); 3] {
    let flat = crate::mesh::test_meshes::plane(21, 2.0);
    let mut p = flat.positions().to_vec();
    let mut t = flat.triangles().to_vec();
    let b = p.len() as u32;
    p.extend(
        [(-0.3, -0.3), (0.3, -0.3), (0.3, 0.3), (-0.3, 0.3)].map(|(x, y)| Vec3::new(x, y, 0.5)),
    );
    t.extend([[b, b + 2, b + 1], [b, b + 3, b + 2]]);
    let mut scene = Scene::new(Mesh::new(p, t, None).unwrap());
    scene.lights = light.into_iter().collect();
    scene.world = world;
    let tracer = scene.tracer();
    let points = &scene.mesh.positions()[..b as usize];
    let normals = vec![Vec3::Z; points.len()];
    let run = |seed| {
        let settings = IrradianceSettings {
            seed,
            area_samples: samples,
            world_samples: samples,
            ..Default::default()
        };
        let mut kept = PerSource::default();
        let (e, _) = kept
            .evaluate(&scene, &tracer, points, &normals, &settings)
            .unwrap();
        (e, kept.sampling_error())
    };
    // Four pairs of seeds: the spread is itself a sample, over the penumbra's points.
    let mut out = [(0.0, 0.0); 3];
    for pair in 0..4 {
        let ((a, stated), (e, _)) = (run(2 * pair), run(2 * pair + 1));
        let n = 4.0 * a.len() as f64;
        for (c, o) in out.iter_mut().enumerate() {
            o.0 += stated.iter().map(|s| f64::from(s[c]).powi(2)).sum::<f64>() / n;
            o.1 += (a.iter().zip(&e))
                .map(|(x, y)| f64::from(x[c] - y[c]).powi(2) / 2.0)
                .sum::<f64>()
                / n;
        }
    }
    out
}

#[test]
fn the_stated_error_of_an_area_light_and_a_traced_world_is_their_spread_between_seeds() {
    // An area light of 1 x 1 at height 2 over the blocker casts a penumbra across the plane,
    // and a uniform world is half hidden near it: sampled at 16 stratified points (or rays)
    // per point (4 to 64), each estimate states its standard error from its checkerboard
    // halves (`Strata`). Averaged over the plane's 441 vertices the stated variance must lie
    // within 0.75 and 1.5 times the seed-to-seed one (itself a sample over those vertices).
    // Suns and point lights are exact: no error stated.
    let area = Light::area(
        Vec3::new(0.2, 0.1, 2.0),
        Vec3::NEG_Z,
        Vec3::X,
        1.0,
        1.0,
        [8.0, 4.0, 2.0],
    );
    let cases = [
        ("area light", Some(area.unwrap()), World::Black),
        ("world", None, World::uniform([0.5, 0.3, 0.2]).unwrap()),
    ];
    for (what, light, world) in cases {
        for samples in [4, 9, 16, 64] {
            let both = stated_and_seed_variance(light.clone(), world.clone(), samples);
            for (c, (said, spread)) in both.into_iter().enumerate() {
                println!(
                    "{what}, {samples} samples, channel {c}: stated variance {said:.3e}, \
                     between seeds {spread:.3e}, ratio {:.2}",
                    said / spread
                );
                assert!(spread > 0.0, "{what}: no noise to measure");
                assert!(
                    said > 0.75 * spread && said < 1.5 * spread,
                    "{what}, {samples} samples, channel {c}: stated variance {said}, between \
                     seeds {spread}"
                );
            }
        }
    }
    let sun = Light::sun(Vec3::new(0.3, 0.1, -1.0), [2.0; 3]).unwrap();
    for (said, spread) in stated_and_seed_variance(Some(sun), World::Black, 16) {
        assert_eq!((said, spread), (0.0, 0.0));
    }
}

#[test]
fn a_light_that_changes_linearly_across_its_strata_states_no_error() {
    // Values a + b u + c v at the strata's centres, k x k: no noise, only a gradient, which the
    // checkerboard halves cancel (their strata share a centroid) for even and odd k. One value
    // stands by its square. Two halves differing by d give d^2 n_a n_b / n^2.
    for k in [2u32, 3, 4, 7] {
        let mut strata = Strata::new(k);
        for a in 0..k {
            for b in 0..k {
                let (u, v) = ((a as f32 + 0.5) / k as f32, (b as f32 + 0.5) / k as f32);
                strata.push([1.0 + 2.0 * u - 0.5 * v, 3.0 * v, 0.0]);
            }
        }
        let var = strata.variance_of_mean(1.0);
        assert!(var.iter().all(|&x| x < 1e-12), "k = {k}: {var:?}");
    }
    let mut one = Strata::new(1);
    one.push([2.0, 0.0, 1.0]);
    assert_eq!(one.variance_of_mean(3.0), [36.0, 0.0, 9.0]);
    let mut two = Strata::new(2);
    for x in [1.0, 0.0, 0.0, 1.0] {
        two.push([x; 3]); // the white squares 1, the black 0
    }
    assert!((two.variance_of_mean(1.0)[0] - 0.25).abs() < 1e-12);
}

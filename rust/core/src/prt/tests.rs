//! PRT against closed forms on a plane, the far field against brute force, the GPU against the
//! CPU, the basis size, refresh advice, cancelling and bad settings.

use super::*;
use crate::error::{Error, Result};
use crate::mesh::Mesh;
use crate::optics::Material;

use crate::mesh::test_meshes::oracles::rd_total;
use crate::mesh::test_meshes::plane;
use crate::optics::fresnel_transmittance;

/// Irradiance of a sun of strength `e` at zenith angle `theta` on the +Z plane (Xu eq. 3
/// for a delta light): F_t(eta, cos) E cos, the same at every point.
fn sun(
    e: f32,
    theta: f64,
    eta: f64,
) -> impl Fn(&[Vec3], &[Vec3], Density) -> Result<Vec<[f32; 3]>> + Sync {
    let c = theta.cos();
    let i = (fresnel_transmittance(eta, c) * c * f64::from(e)) as f32;
    move |p: &[Vec3], _n: &[Vec3], _d: Density| Ok(vec![[i; 3]; p.len()])
}

fn centre(mesh: &Mesh) -> usize {
    mesh.positions()
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.length().total_cmp(&b.1.length()))
        .unwrap()
        .0
}

#[allow(clippy::needless_range_loop)]
fn check_plane(mesh: &Mesh, m: &Material, theta: f64, tol: f64) {
    let settings = PrtSettings {
        eta: m.eta,
        ..Default::default()
    };
    let prt = Prt::precompute(mesh, &[*m], &settings, &sun(1.0, theta, m.eta), None).unwrap();
    let b = prt.radiosity(m).unwrap().values;
    let v = centre(mesh);
    let e = fresnel_transmittance(m.eta, theta.cos()) * theta.cos();
    for c in 0..3 {
        let expect = e * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
        let got = f64::from(b[v][c]);
        eprintln!(
            "plane: channel {c} B {got:.6e} closed form {expect:.6e} ({:+.3} %)",
            100.0 * (got / expect - 1.0)
        );
        assert!(
            (got - expect).abs() <= tol * expect,
            "channel {c}: B = {got}, closed form {expect} ({:.3} %)",
            100.0 * (got / expect - 1.0)
        );
    }
}

#[test]
fn sun_on_a_large_plane_gives_ft_e_cos_rd_total_for_marble() {
    // 200 mm square, 2 mm grid: the marble tail beyond 100 mm is below 1e-5.
    let mesh = plane(101, 200.0);
    let marble = Material::preset("marble", 1.0).unwrap();
    for theta in [0.0, 0.6, 1.2] {
        check_plane(&mesh, &marble, theta, 0.01);
    }
    let ketchup = Material::preset("ketchup", 1.0).unwrap();
    check_plane(&mesh, &ketchup, 0.3, 0.01);
}

#[test]
#[allow(clippy::needless_range_loop)]
fn the_multipole_on_a_plane_gives_the_slab_and_layer_closed_forms() {
    use crate::mesh::test_meshes::oracles::{layered_rd_total, slab_rd_total, slab_totals};
    use crate::optics::{Stack, TopLayer};
    // The oracle itself: without absorption an index-matched slab reflects or transmits all.
    let (r, t) = slab_totals(0.0, 2.0, 3.0, 1.0, 1.0);
    assert!((r + t - 1.0).abs() < 1e-9, "R {r} + T {t}");
    let mesh = plane(101, 200.0);
    let marble = Material::preset("marble", 1.0).unwrap();
    let skin = Material::preset("skin1", 1.0).unwrap();
    let slab = marble
        .with_stack(Stack {
            thickness: 4.0,
            top: None,
        })
        .unwrap();
    // Skin's first layer, 1.5 mm, over marble: Shah 2009 Fig. 11's thin layer over a thick one.
    let layer = TopLayer {
        sigma_a: skin.sigma_a,
        sigma_s: skin.sigma_s,
        thickness: 1.5,
    };
    let layered = marble
        .with_stack(Stack {
            thickness: f64::INFINITY,
            top: Some(layer),
        })
        .unwrap();
    let theta: f64 = 0.5;
    let e = fresnel_transmittance(marble.eta, theta.cos()) * theta.cos();
    let settings = PrtSettings {
        eta: marble.eta,
        profile: ProfileKind::Multipole,
        ..Default::default()
    };
    // One precompute; the stack is an edit like any other coefficient.
    let irr = sun(1.0, theta, marble.eta);
    let prt = Prt::precompute(&mesh, &[slab], &settings, &irr, None).unwrap();
    let v = centre(&mesh);
    for (m, name) in [(slab, "slab"), (layered, "layer")] {
        let b = prt.radiosity(&m).unwrap().values;
        for c in 0..3 {
            let (sa, sp) = (m.sigma_a[c], m.sigma_s_prime()[c]);
            let total = match name {
                "slab" => slab_rd_total(sa, sp, m.eta, 4.0),
                _ => layered_rd_total(
                    (skin.sigma_a[c], skin.sigma_s_prime()[c], 1.5),
                    (sa, sp, f64::INFINITY),
                    m.eta,
                ),
            };
            let expect = e * total;
            let got = f64::from(b[v][c]);
            assert!(
                (got - expect).abs() <= 0.01 * expect,
                "{name} channel {c}: B = {got}, closed form {expect} ({:+.3} %)",
                100.0 * (got / expect - 1.0)
            );
            // The half-space answer differs by more than the tolerance (the test can fail).
            let half = e * rd_total(sa, sp, m.eta);
            assert!((half - expect).abs() > 0.02 * expect, "{name} channel {c}");
        }
    }
}

#[test]
fn stiff_material_tends_to_the_diffuse_brdf_limit() {
    // sigma_s' = 1e4 per mm on a millimetre mesh: R_d lives far inside one sample.
    let mesh = plane(41, 20.0);
    let stiff = Material::new([1.0, 10.0, 100.0], [1e4; 3], 0.0, 1.3).unwrap();
    check_plane(&mesh, &stiff, 0.4, 0.01);
}

#[test]
fn no_absorption_conserves_energy_on_a_plane() {
    // sigma_a = 0: R_d,total = 1 and the tail falls as 1/r; 1000 mean free paths of plane
    // leave (z_r + z_v) / (2 R) < 0.3 % outside.
    let mesh = plane(161, 100.0);
    let white = Material::new([0.0; 3], [10.0, 20.0, 40.0], 0.0, 1.3).unwrap();
    check_plane(&mesh, &white, 0.0, 0.01);
}

#[test]
fn clustered_far_field_matches_brute_force_sum() {
    let mesh = plane(61, 60.0);
    let m = Material::preset("skin1", 1.0).unwrap();
    // A spatially varying irradiance so clusters are not uniform.
    let irr = |p: &[Vec3], _n: &[Vec3], _d: Density| {
        Ok(p.iter()
            .map(|x| {
                let v = 1.0 + 0.5 * (x.x * 0.2).sin() + 0.3 * (x.y * 0.1).cos();
                [v, 0.5 * v, 0.25 * v]
            })
            .collect())
    };
    let exact = PrtSettings {
        far_field: 0.0,
        ..Default::default()
    };
    let fast = PrtSettings::default();
    let a = Prt::precompute(&mesh, &[m], &exact, &irr, None).unwrap();
    let b = Prt::precompute(&mesh, &[m], &fast, &irr, None).unwrap();
    assert!(b.report().far_clusters > 0 && a.report().far_clusters == 0);
    let ea = a.radiosity(&m).unwrap().values;
    let eb = b.radiosity(&m).unwrap().values;
    let s = crate::metrics::relative_error(&eb, &ea, mesh.vertex_areas()).unwrap();
    eprintln!(
        "clustered vs brute force: {s:?}; {} far clusters",
        b.report().far_clusters
    );
    assert!(s.worst_rms() < 1e-3, "clustered vs brute force: {s:?}");
    assert_eq!(
        b.report().stored_channels,
        1,
        "one colour of light needs one transport"
    );
}

#[test]
fn first_preview_far_field_with_shared_channels_matches_brute_force_sum() {
    // A first preview places each far cluster's pseudo-samples once for every channel. The
    // channels' irradiance here varies by +-90 % in different directions over 21 mm, so its
    // colour changes across the clusters; the brute-force sum is the reference. Measured:
    // 0.54 / 0.35 / 0.27 % (per channel's own placement: 0.13 / 0.21 / 0.21 %), against a
    // first preview's 10 % of Cycles.
    let mesh = plane(61, 60.0);
    let m = Material::preset("skin1", 1.0).unwrap();
    let irr = |p: &[Vec3], _n: &[Vec3], _d: Density| {
        Ok(p.iter()
            .map(|x| {
                [
                    1.0 + 0.9 * (x.x * 0.3).sin(),
                    0.5,
                    1.0 + 0.9 * (x.y * 0.3).cos(),
                ]
            })
            .collect())
    };
    let at = |far_field: f64, first_preview: bool| {
        let settings = PrtSettings {
            far_field,
            first_preview,
            ..Default::default()
        };
        let prt = Prt::precompute(&mesh, &[m], &settings, &irr, None).unwrap();
        (prt.radiosity(&m).unwrap().values, prt.report().far_clusters)
    };
    let (exact, none) = at(0.0, true);
    let (shared, far) = at(0.9, true);
    let (own, _) = at(0.9, false);
    assert!(none == 0 && far > 0);
    let areas = mesh.vertex_areas();
    let shared_err = crate::metrics::relative_error(&shared, &exact, areas).unwrap();
    let own_err = crate::metrics::relative_error(&own, &exact, areas).unwrap();
    let apart = crate::metrics::relative_error(&shared, &own, areas).unwrap();
    eprintln!(
        "shared {shared_err:?}, per channel {own_err:?}, between {apart:?}; {far} far clusters"
    );
    assert!(
        shared_err.worst_rms() < 1e-2,
        "shared channels vs brute force: {shared_err:?}"
    );
    // The two placements differ by more than the test's resolution.
    assert!(apart.worst_rms() > 1e-3, "{apart:?}");
}

#[test]
fn gpu_and_cpu_dot_products_agree() {
    // Three stored channels (coloured irradiance) exercise the full layout.
    let mesh = plane(41, 40.0);
    let irr = |p: &[Vec3], _n: &[Vec3], _d: Density| {
        Ok(p.iter()
            .map(|x| [1.0 + 0.02 * x.x, 0.5 + 0.01 * x.y.abs(), 0.3])
            .collect())
    };
    let m = Material::preset("skin1", 1.0).unwrap();
    let mut prt = Prt::precompute(&mesh, &[m], &PrtSettings::default(), &irr, None).unwrap();
    assert_eq!(prt.report().stored_channels, 3);
    let cpu = prt.radiosity(&m).unwrap().values;
    if let Err(e) = prt.set_backend(Backend::Gpu, true) {
        // CI installs Mesa's lavapipe; elsewhere a machine may have no Vulkan at all.
        eprintln!("skipped: {e}");
        return;
    }
    assert_eq!(prt.backend(), Backend::Gpu);
    let other = Material::preset("ketchup", 1.0).unwrap();
    for mat in [m, other] {
        let gpu = prt.radiosity(&mat).unwrap().values;
        prt.set_backend(Backend::Cpu, true).unwrap();
        let cpu = prt.radiosity(&mat).unwrap().values;
        prt.set_backend(Backend::Gpu, true).unwrap();
        for (g, c) in gpu.iter().zip(&cpu) {
            for k in 0..3 {
                assert!(
                    (g[k] - c[k]).abs() <= 1e-5 * c[k].abs().max(1e-6),
                    "{g:?} vs {c:?}"
                );
            }
        }
    }
    // f16 storage: half the bytes; its stated rounding bound covers what it changes in B.
    prt.set_backend_with(Backend::Gpu, true, true).unwrap();
    let bound = prt.gpu_half_error().unwrap();
    assert!(bound > 0.0 && bound < 1e-3, "f16 rounding bound {bound}");
    let half = prt.radiosity(&m).unwrap().values;
    let s = crate::metrics::relative_error(&half, &cpu, mesh.vertex_areas()).unwrap();
    assert!(
        s.worst_rms() <= bound.max(1e-6) && s.worst_rms() > 0.0,
        "{s:?} vs bound {bound}"
    );
}

#[test]
#[allow(clippy::needless_range_loop)]
fn basis_size_follows_the_fit_tolerance() {
    // Marble per mm on the 200 mm plane: a looser tolerance needs fewer functions, and
    // each choice still meets the closed form F_t E R_d,total at the centre within its
    // tolerance plus the 0.3 % the exact basis-free sum already shows there.
    let mesh = plane(101, 200.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let sizes: Vec<usize> = [3e-2, 3e-3]
        .iter()
        .map(|&tol| {
            let settings = PrtSettings {
                fit_tolerance: Some(tol),
                coefficients: 96,
                samples: Some(200_000),
                ..Default::default()
            };
            let prt = Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
            assert!(prt.report().basis_size_by_tolerance);
            assert!(prt.report().representative_error <= tol);
            let b = prt.radiosity(&m).unwrap().values[centre(&mesh)];
            let e = fresnel_transmittance(1.3, 1.0);
            for c in 0..3 {
                let sp = m.sigma_s[c] * (1.0 - m.g);
                let expect = e * rd_total(m.sigma_a[c], sp, 1.3);
                let rel = (f64::from(b[c]) - expect).abs() / expect;
                assert!(rel < tol + 3e-3, "tol {tol} channel {c}: {rel}");
            }
            prt.basis().len()
        })
        .collect();
    assert!(sizes[0] < sizes[1] && sizes[1] <= 96, "{sizes:?}");
}

#[test]
fn edits_far_from_the_representatives_advise_a_refresh() {
    // 200 mm plane, marble per mm (1/sigma_tr ~ 8 mm): room for a support radius that does
    // not reach across the whole plane.
    let mesh = plane(41, 200.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let settings = PrtSettings {
        samples: Some(40_000),
        ..Default::default()
    };
    let prt = Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
    let scaled = |k: f64| {
        Material::new(
            m.sigma_a.map(|x| x * k),
            m.sigma_s.map(|x| x * k),
            m.g,
            m.eta,
        )
        .unwrap()
    };
    let near = prt.radiosity(&m).unwrap();
    assert!(!prt.refresh_advised(&near.error_estimate.unwrap()));
    // A profile 3 times wider than the knots were placed for: part of it lies beyond the
    // support radius and the estimate says so.
    let wide = prt.radiosity(&scaled(0.3)).unwrap();
    assert!(
        prt.refresh_advised(&wide.error_estimate.unwrap()),
        "{:?}",
        wide.error_estimate
    );
    // A precompute for the new material brings the estimate back under the floor.
    let again =
        Prt::precompute(&mesh, &[scaled(0.3)], &settings, &sun(1.0, 0.0, 1.3), None).unwrap();
    let e = again.radiosity(&scaled(0.3)).unwrap();
    assert!(
        !again.refresh_advised(&e.error_estimate.unwrap()),
        "{:?}",
        e.error_estimate
    );
}

#[test]
fn cancelling_stops_the_precompute() {
    let mesh = plane(11, 10.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let stop = |f: f32| f < 0.5;
    let r = Prt::precompute(
        &mesh,
        &[m],
        &PrtSettings::default(),
        &sun(1.0, 0.0, 1.3),
        Some(&stop),
    );
    assert_eq!(r.unwrap_err(), Error::Cancelled);
}

#[test]
fn the_own_light_beyond_its_limit_is_refused_before_any_work() {
    // 121 vertices: 1490^2 x 121 = 268,632,100 rays exceed 2^28 = 268,435,456 (1489^2 x 121 =
    // 268,271,641 would fit).
    let mesh = plane(11, 10.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let settings = PrtSettings {
        interreflection: Some(1490),
        ..Default::default()
    };
    let asked = std::sync::atomic::AtomicBool::new(false);
    let progress = |_: f32| {
        asked.store(true, std::sync::atomic::Ordering::Relaxed);
        true
    };
    let e =
        Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), Some(&progress)).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidArgument(s) if s.contains("limit own_light_rays")),
        "{e}"
    );
    assert!(
        !asked.load(std::sync::atomic::Ordering::Relaxed),
        "refused only after the work began"
    );
}

#[test]
fn eta_mismatch_and_bad_settings_are_errors() {
    let mesh = plane(11, 10.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let prt = Prt::precompute(
        &mesh,
        &[m],
        &PrtSettings::default(),
        &sun(1.0, 0.0, 1.3),
        None,
    )
    .unwrap();
    let other = Material::new(m.sigma_a, m.sigma_s, 0.0, 1.5).unwrap();
    assert!(prt.radiosity(&other).is_err());
    let bad = PrtSettings {
        tolerance: 0.0,
        ..Default::default()
    };
    assert!(Prt::precompute(&mesh, &[m], &bad, &sun(1.0, 0.0, 1.3), None).is_err());
    assert!(Prt::precompute(
        &mesh,
        &[],
        &PrtSettings::default(),
        &sun(1.0, 0.0, 1.3),
        None
    )
    .is_err());
    let nan = |p: &[Vec3], _n: &[Vec3], _d: Density| Ok(vec![[f32::NAN; 3]; p.len()]);
    assert!(Prt::precompute(&mesh, &[m], &PrtSettings::default(), &nan, None).is_err());
}

#[test]
fn the_default_walk_budget_is_thirty_million_rays_within_600_to_8000_per_vertex() {
    // The bunny at 10 cm (34,834 vertices) and a mid-size mesh get the flat budget; a mesh of
    // 139k vertices 600 per vertex.
    assert_eq!(default_walk_rays(34_834), 30_000_000);
    assert_eq!(default_walk_rays(10_000), 30_000_000);
    assert_eq!(default_walk_rays(139_000), 600 * 139_000);
    // A coarse 3,000-vertex character at most 8000 per vertex (it was capped at 7.5 M), as a
    // smaller mesh.
    assert_eq!(default_walk_rays(3_000), 24_000_000);
    assert_eq!(default_walk_rays(2_000), 16_000_000);
    assert_eq!(default_walk_rays(42), 8000 * 42);
}

/// A new light keeps everything the light does not hold: precomputed under a sun at the
/// zenith, relit to a sun 0.6 rad off it, the plane gives the closed form at the new angle, as
/// a fresh precompute does, bit for bit (samples, knots and irradiance are the same), and
/// nothing is walked.
#[test]
#[allow(clippy::needless_range_loop)]
fn relit_plane_gives_the_closed_form_at_the_new_angle() {
    let mesh = plane(101, 200.0);
    let m = Material::preset("marble", 1.0).unwrap();
    let settings = PrtSettings {
        eta: m.eta,
        ..Default::default()
    };
    let mut prt = Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, m.eta), None).unwrap();
    // A relight stopped halfway leaves the old light in place.
    let before = prt.radiosity(&m).unwrap().values;
    let stop = |f: f32| f < 0.5;
    let err = prt.relight(&mesh, &sun(1.0, 0.6, m.eta), Some(&stop));
    assert!(matches!(err, Err(Error::Cancelled)), "{err:?}");
    assert_eq!(prt.radiosity(&m).unwrap().values, before);
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let progress = |f: f32| {
        assert!((0.0..=1.0).contains(&f));
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        true
    };
    let report = prt
        .relight(&mesh, &sun(1.0, 0.6, m.eta), Some(&progress))
        .unwrap();
    assert_eq!(report.walks_traced, 0);
    assert!(calls.load(std::sync::atomic::Ordering::Relaxed) >= 2);
    let b = prt.radiosity(&m).unwrap().values;
    let v = centre(&mesh);
    let e = fresnel_transmittance(m.eta, 0.6f64.cos()) * 0.6f64.cos();
    for c in 0..3 {
        let expect = e * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
        let got = f64::from(b[v][c]);
        assert!(
            (got - expect).abs() <= 0.01 * expect,
            "channel {c}: relit B {got} vs closed form {expect}"
        );
    }
    let fresh = Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.6, m.eta), None).unwrap();
    assert_eq!(fresh.radiosity(&m).unwrap().values, b);
    // Another mesh is refused, naming what differs.
    let other = plane(101, 100.0);
    let err = prt
        .relight(&other, &sun(1.0, 0.6, m.eta), None)
        .unwrap_err();
    assert!(err.to_string().contains("precomputed for"), "{err}");
}

#[test]
fn fewer_samples_than_triangles_are_refused_and_a_low_cap_still_resolves_the_triangles() {
    // 41 x 41 vertices over 10 mm: 3,200 triangles with sides of 0.25 mm (0.35 mm across).
    let mesh = plane(41, 10.0);
    let floor = mesh.min_sample_count();
    assert_eq!(floor, 3200);
    let m = Material::preset("marble", 1.0).unwrap();
    let settings = PrtSettings {
        samples: Some(floor),
        ..Default::default()
    };
    match Prt::precompute(&mesh, &[m], &settings, &sun(1.0, 0.0, 1.3), None) {
        Err(Error::InvalidArgument(msg)) => assert!(msg.contains("samples 3200"), "{msg}"),
        other => panic!("expected a refusal, got {:?}", other.map(|_| ())),
    }
    // A cap on the default spacing below the triangle count (a first preview's 150,000 on a
    // mesh of 277,804 triangles): the spacing still resolves the triangles. It had been the
    // mesh's diagonal, one receiver disc over the whole mesh.
    let resolved = crate::profiles::Resolved::new(ProfileKind::Dipole, &m).unwrap();
    let spacing = super::knots::default_spacing(&mesh, &resolved.profiles, Some(1000));
    let across = 0.25 * 2f32.sqrt();
    assert!(
        spacing <= 1.001 * across,
        "spacing {spacing} > a triangle's {across}"
    );
    let count = mesh.sample_count(spacing);
    assert!((floor..=8 * floor).contains(&count), "{count} samples");
}

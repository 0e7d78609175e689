//! Cycles' random-walk table against what it must agree with, none of it the table's code:
//! - an independent brute-force walk (analogue absorption, one albedo at a time, written
//!   here from the description of Cycles' walk) at a few albedos, anisotropies and radii;
//! - diffusion theory as the albedo tends to 1: the total of the index-matched dipole
//!   (Jensen 2001 with A for eta = 1), and the share of walks the 256-bounce cap keeps inside
//!   (first passage of a diffusing particle through the extrapolated boundary);
//! - Cycles itself: the thick-slab render of `tests/test_cycles_mapping.py`;
//! - the table's stated noise, under 0.3 %.

use std::f64::consts::PI;
use std::sync::Arc;
use translucent_core::optics::{Layers, Material};
use translucent_core::profiles::table::{TableKey, WalkProfile, WalkTable};
use translucent_core::profiles::walk::{simulate, WalkSettings};
use translucent_core::profiles::RadialProfile;

/// A small generator (xorshift64*), kept apart from the table's PCG.
struct Rng(u64);

impl Rng {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A unit vector at polar cosine `cos` about `axis`, azimuth `phi`.
fn around(axis: [f64; 3], cos: f64, phi: f64) -> [f64; 3] {
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    // Any vector not parallel to axis, then Gram–Schmidt.
    let helper = if axis[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let d = helper[0] * axis[0] + helper[1] * axis[1] + helper[2] * axis[2];
    let mut t = [
        helper[0] - d * axis[0],
        helper[1] - d * axis[1],
        helper[2] - d * axis[2],
    ];
    let n = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2]).sqrt();
    t = [t[0] / n, t[1] / n, t[2] / n];
    let b = [
        axis[1] * t[2] - axis[2] * t[1],
        axis[2] * t[0] - axis[0] * t[2],
        axis[0] * t[1] - axis[1] * t[0],
    ];
    let (c, s) = (phi.cos(), phi.sin());
    std::array::from_fn(|k| cos * axis[k] + sin * (c * t[k] + s * b[k]))
}

/// One analogue walk in the half-space z < 0 (surface z = 0, light enters along -z): the exit
/// radius in mean free paths, or None when absorbed or still inside after 256 bounces.
fn brute_walk(rng: &mut Rng, alpha: f64, g: f64, roughness: f64, ior: f64) -> Option<f64> {
    // Entry: a GGX microfacet normal m seen along the normal (density D(m) cos(theta_m)), and
    // Snell's law through it for the ray coming down along -z.
    let a = roughness * roughness;
    let mut dir = [0.0, 0.0, -1.0];
    if a > 0.0 {
        let u = rng.uniform();
        let theta = (a * (u / (1.0 - u)).sqrt()).atan();
        let m = around([0.0, 0.0, 1.0], theta.cos(), 2.0 * PI * rng.uniform());
        let cos_i = m[2]; // the incoming ray is -z: cos against m
        let eta = 1.0 / ior;
        let cos_t = (1.0 - eta * eta * (1.0 - cos_i * cos_i)).sqrt();
        dir = std::array::from_fn(|k| eta * [0.0, 0.0, -1.0][k] + (eta * cos_i - cos_t) * m[k]);
    }
    let mut pos = [0.0f64; 3];
    for bounce in 0..256 {
        let (sigma_t, albedo, phase_g) = if bounce < 10 {
            (1.0, alpha, g)
        } else {
            // Similarity: sigma_s* = sigma_s (1 - g), sigma_t* = sigma_t - sigma_s + sigma_s*.
            let st = 1.0 - alpha * g;
            (st, alpha * (1.0 - g) / st, 0.0)
        };
        if bounce > 0 {
            let u = rng.uniform();
            let cos = if phase_g == 0.0 {
                1.0 - 2.0 * u
            } else {
                // Inverse CDF of Henyey–Greenstein.
                let q = (1.0 - phase_g * phase_g) / (1.0 + phase_g - 2.0 * phase_g * u);
                (1.0 + phase_g * phase_g - q * q) / (2.0 * phase_g)
            };
            dir = around(dir, cos.clamp(-1.0, 1.0), 2.0 * PI * rng.uniform());
        }
        let t = -(1.0 - rng.uniform()).ln() / sigma_t;
        if pos[2] + dir[2] * t >= 0.0 {
            let s = -pos[2] / dir[2];
            return Some((pos[0] + dir[0] * s).hypot(pos[1] + dir[1] * s));
        }
        for k in 0..3 {
            pos[k] += dir[k] * t;
        }
        if rng.uniform() >= albedo {
            return None;
        }
    }
    None
}

/// The table's profile at sigma_t = 1 (so radii are optical) for albedo alpha.
fn profile(table: &Arc<WalkTable>, alpha: f64, g: f64, roughness: f64, ior: f64) -> WalkProfile {
    let m = Material::new([1.0 - alpha; 3], [alpha; 3], g, ior)
        .unwrap()
        .with_layers(Layers {
            roughness,
            ..Layers::default()
        })
        .unwrap();
    WalkProfile::new(&[(table.clone(), 1.0)], &m, 0)
}

#[test]
fn table_agrees_with_an_independent_brute_force_walk() {
    let (roughness, ior) = (0.5, 1.4);
    let radii = [0.1, 0.3, 1.0, 3.0, 10.0];
    for g in [0.0, 0.7] {
        let key = TableKey::new(g, roughness, ior, 1 << 20).unwrap();
        let table = Arc::new(WalkTable::build(&key, None).unwrap());
        for (i, alpha) in [0.3, 0.9, 0.99].into_iter().enumerate() {
            let n = 1 << 19;
            let mut rng = Rng(0x9e37_79b9_7f4a_7c15 ^ ((i as u64 + 1) * 7919) ^ g.to_bits());
            let exits: Vec<f64> = (0..n)
                .filter_map(|_| brute_walk(&mut rng, alpha, g, roughness, ior))
                .collect();
            let p = profile(&table, alpha, g, roughness, ior);
            let fraction = |rho: f64| exits.iter().filter(|&&r| r <= rho).count() as f64 / n as f64;
            let checks = radii
                .iter()
                .map(|&rho| (rho, fraction(rho), p.disc_integral(rho)))
                .chain(std::iter::once((
                    f64::INFINITY,
                    exits.len() as f64 / n as f64,
                    p.total(),
                )));
            for (rho, brute, tabled) in checks {
                // Binomial noise of the brute force, the table's own stated noise, and a
                // thousandth of the total for interpolation between albedo rows and radii.
                let se_brute = (brute * (1.0 - brute) / n as f64).sqrt();
                let se_table = table.noise_disc.max(table.noise_total) * p.total().max(0.01);
                let allowed = 4.0 * se_brute.hypot(se_table) + 1e-3 * p.total();
                eprintln!(
                    "g {g} alpha {alpha} rho {rho}: brute {brute:.5} table {tabled:.5} \
                     (allowed {allowed:.1e})"
                );
                assert!(
                    (brute - tabled).abs() <= allowed,
                    "g {g}, alpha {alpha}, rho {rho}: brute force {brute} vs table {tabled}"
                );
            }
        }
    }
}

#[test]
fn near_unit_albedo_matches_diffusion_theory() {
    // Without the bounce cap, 1 - R tends to sqrt(3 (1 - alpha)) (1 + 2A/3) as alpha -> 1,
    // the index-matched dipole's total (Jensen 2001, A = (1 + F_dr)/(1 - F_dr) at eta = 1).
    let f_dr = -1.440 + 0.710 + 0.668 + 0.0636;
    let a = (1.0 + f_dr) / (1.0 - f_dr);
    let dipole = |alpha: f64| {
        let s = (3.0 * (1.0 - alpha)).sqrt();
        0.5 * alpha * (1.0 + (-4.0 / 3.0 * a * s).exp()) * (-s).exp()
    };
    let alpha = 0.999;
    let uncapped = WalkSettings {
        walks: 1 << 17,
        max_bounces: 20_000, // alpha^20000 = 2e-9: no cap in effect
        ..Default::default()
    };
    let h = simulate(&uncapped, &[alpha], &[1e9], 1, None).unwrap();
    let r = h.weights.iter().sum::<f64>() / h.walks as f64;
    let expect = dipole(alpha);
    eprintln!("alpha {alpha}: walk R {r:.5}, diffusion {expect:.5}");
    assert!(
        ((1.0 - r) - (1.0 - expect)).abs() <= 0.03 * (1.0 - expect),
        "1 - R: walk {} vs diffusion {}",
        1.0 - r,
        1.0 - expect
    );

    // With Cycles' 256 bounces and no absorption, what stays inside is the survival of a
    // particle diffusing (D = 1/3 per unit path) from its first collision (mean depth 1)
    // past the extrapolated boundary z_b = 2A/3 in a path of 256: (1 + z_b) sqrt(3 / (pi 256)).
    let capped = WalkSettings {
        walks: 1 << 18,
        ..Default::default()
    };
    let h = simulate(&capped, &[0.999_999], &[1e9], 1, None).unwrap();
    let r = h.weights.iter().sum::<f64>() / h.walks as f64;
    let lost = (1.0 + 2.0 * a / 3.0) * (3.0 / (PI * 256.0)).sqrt();
    eprintln!(
        "256 bounces, alpha -> 1: R {r:.5}, diffusion {:.5}",
        1.0 - lost
    );
    assert!((r - (1.0 - lost)).abs() < 0.005, "R {r} vs {}", 1.0 - lost);
}

#[test]
fn table_predicts_the_cycles_thick_slab() {
    // Blender 5.0.1, 128 spp, a 1 x 1 x 0.5 m slab under a white world seen from above
    // (tests/test_cycles_mapping.py): sigma_a (2, 6, 20), sigma_s 60 per metre, g 0, Roughness
    // 0.5, Specular IOR Level 0 (no specular layer, and the walk enters through IOR 1.01).
    let cycles = [0.604, 0.433, 0.244];
    let key = TableKey::new(0.0, 0.5, 1.01, 1 << 20).unwrap();
    let table = WalkTable::build(&key, None).unwrap();
    for (c, sa) in [2.0, 6.0, 20.0].into_iter().enumerate() {
        let total = table.total(60.0 / (60.0 + sa));
        eprintln!("channel {c}: table {total:.4}, Cycles {}", cycles[c]);
        assert!(
            (total - cycles[c]).abs() <= 0.02 * cycles[c],
            "channel {c}: table {total} vs Cycles {}",
            cycles[c]
        );
    }
}

#[test]
fn the_tables_noise_is_below_three_tenths_of_a_percent() {
    for g in [0.0, 0.45, 0.9] {
        let key = TableKey::new(
            g,
            0.5,
            1.5,
            translucent_core::profiles::table::default_walks(g),
        )
        .unwrap();
        let table = WalkTable::build(&key, None).unwrap();
        eprintln!(
            "g {g}: noise of totals {:.2e}, of disc integrals {:.2e} ({:.1} s)",
            table.noise_total, table.noise_disc, table.seconds
        );
        assert!(table.noise_total < 3e-3 && table.noise_disc < 3e-3);
    }
}

#[test]
fn interpolating_between_tables_in_g_costs_under_half_a_percent() {
    // Tables sit on a 0.05 grid in g and a material between two takes their rows blended
    // linearly: against a table simulated at g itself, the worst grid gap (g 0.85-0.9, where
    // g moves the total fastest) and one at the low end. Same walks (seed) for all three, so
    // the comparison sees the interpolation, not the noise.
    for (lo, hi) in [(0.05, 0.1), (0.85, 0.9)] {
        let mid = 0.5 * (lo + hi);
        let build = |g: f64| {
            WalkTable::build(&TableKey::new(g, 0.5, 1.45, 1 << 18).unwrap(), None).unwrap()
        };
        let (a, b, exact) = (build(lo), build(hi), build(mid));
        for alpha in [0.3, 0.8, 0.95, 0.99, 0.999] {
            let blended = 0.5 * (a.total(alpha) + b.total(alpha));
            let truth = exact.total(alpha);
            eprintln!("g {mid}: alpha {alpha}: interpolated {blended:.5}, simulated {truth:.5}");
            assert!(
                (blended - truth).abs() <= 5e-3 * truth,
                "g {mid}, alpha {alpha}: {blended} vs {truth}"
            );
        }
    }
}

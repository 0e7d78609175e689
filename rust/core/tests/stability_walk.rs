//! The stability suite for Cycles' profile (issue 9): the random-walk table and the Principled
//! layers over the whole range Cycles admits, single-scattering albedo alpha in [0, 1], g in
//! [0, 0.9], Roughness in [0, 1], IOR in [1.01, 3.8], extinction 1e-4 .. 1e4 per unit, and the
//! lobes' weights in [0, 1].
//!
//! Tables are built once for the corners of (g, Roughness, IOR) and the middle of g, with 2^15
//! walks each (their noise does not matter here: what is checked holds for any walks), and the
//! properties run over profiles drawn from them:
//! - the profile: R(r) finite and >= 0 from r = 0 to far beyond the last bin, the disc
//!   integral non-decreasing and between 0 and the total, disc + tail = total, total + point
//!   mass <= 1, the support radius finite;
//! - monotone in alpha: a slab's total does not fall as the albedo grows (the walks are shared
//!   across albedos, so this holds exactly, not only on average);
//! - the layers: W(mu) = 1 - E_spec in [0, 1], finite, for any view cosine;
//! - `Material::from_principled` on any inputs: a material with finite profiles, or an error,
//!   never a panic.
//!
//! Cases: 3000 (profiles) + 2000 (monotone) + 2000 (layers) + 2000 (Principled), fixed seed.

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use std::sync::{Arc, OnceLock};
use translucent_core::optics::principled::{layer_weight, specular_albedo, PrincipledInputs};
use translucent_core::optics::{Layers, Material};
use translucent_core::profiles::table::{TableKey, WalkProfile, WalkTable};
use translucent_core::profiles::{ProfileKind, RadialProfile};

fn config(cases: u32) -> Config {
    let mut c = Config::with_cases(cases);
    c.failure_persistence = None;
    if std::env::var_os("PROPTEST_RNG_SEED").is_none() {
        c.rng_seed = RngSeed::Fixed(0x7a61_e5ee);
    }
    c
}

const GS: [f64; 3] = [0.0, 0.45, 0.9];
const ROUGHNESS: [f64; 2] = [0.0, 1.0];
const IORS: [f64; 2] = [1.01, 3.8];

/// Tables with their (g, Roughness, IOR).
type Tables = Vec<((f64, f64, f64), Arc<WalkTable>)>;

/// The tables of every (g, Roughness, IOR) corner, built once (in parallel by rayon inside).
fn tables() -> &'static Tables {
    static TABLES: OnceLock<Tables> = OnceLock::new();
    TABLES.get_or_init(|| {
        let mut out = Vec::new();
        for g in GS {
            for r in ROUGHNESS {
                for ior in IORS {
                    let key = TableKey::new(g, r, ior, 1 << 15).unwrap();
                    out.push(((g, r, ior), Arc::new(WalkTable::build(&key, None).unwrap())));
                }
            }
        }
        out
    })
}

fn layers() -> impl Strategy<Value = Layers> {
    (
        0.0..=1.0f64,
        0.0..=1.0f64,
        0.0..=1.0f64,
        0.0..=1.0f64,
        0.0..=1.0f64,
    )
        .prop_map(
            |(roughness, subsurface_weight, metallic, transmission, base)| Layers {
                roughness,
                subsurface_weight,
                metallic,
                transmission,
                base_color: [base, 0.5 * base, 1.0 - base],
            },
        )
}

fn albedo() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(1.0),
        Just(0.2),
        0.0..=1.0f64,
        (1e-9..1e-1f64).prop_map(|x| 1.0 - x),
        1e-9..1e-1f64,
    ]
}

fn extinction() -> impl Strategy<Value = f64> {
    (-4.0..4.0f64).prop_map(|e| 10f64.powf(e))
}

fn profile(table: usize, alpha: f64, sigma_t: f64, layers: Layers) -> WalkProfile {
    let ((g, _, ior), t) = &tables()[table];
    let m = Material::new([(1.0 - alpha) * sigma_t; 3], [alpha * sigma_t; 3], *g, *ior)
        .unwrap()
        .with_layers(layers)
        .unwrap();
    WalkProfile::new(&[(t.clone(), 1.0)], &m, 0)
}

proptest! {
    #![proptest_config(config(3000))]

    #[test]
    fn walk_profiles_are_finite_bounded_and_consistent(
        table in 0usize..12, alpha in albedo(), sigma_t in extinction(), layers in layers(),
    ) {
        let p = profile(table, alpha, sigma_t, layers);
        let total = p.total();
        prop_assert!(total.is_finite() && total >= 0.0);
        prop_assert!(total + p.point_mass() <= 1.0 + 1e-12, "{} + {}", total, p.point_mass());
        let support = p.support_radius(1e-5);
        prop_assert!(support.is_finite() && support >= 0.0);
        let mut last = 0.0;
        for k in 0..60 {
            // From 0 to 3000 mean free paths: past the table's last bin.
            let r = if k == 0 { 0.0 } else { 1e-4 * 1.3f64.powi(k) / sigma_t };
            let v = p.value(r);
            prop_assert!(v.is_finite() && v >= 0.0, "R({}) = {}", r, v);
            let d = p.disc_integral(r);
            prop_assert!(d.is_finite() && d >= last - 1e-12 * total && d <= total * (1.0 + 1e-12));
            prop_assert!((d + p.tail(r) - total).abs() <= 1e-9 * total.max(1e-300));
            last = d;
        }
    }
}

proptest! {
    #![proptest_config(config(2000))]

    #[test]
    fn a_slabs_total_does_not_fall_as_the_albedo_grows(
        table in 0usize..12, a in albedo(), b in albedo(), sigma_t in extinction(),
    ) {
        let (lo, hi) = (a.min(b), a.max(b));
        let full = Layers::default();
        let t_lo = profile(table, lo, sigma_t, full).total();
        let t_hi = profile(table, hi, sigma_t, full).total();
        prop_assert!(t_lo <= t_hi * (1.0 + 1e-12) + 1e-15, "alpha {} -> {}, {} -> {}", lo, hi, t_lo, t_hi);
    }
}

proptest! {
    #![proptest_config(config(2000))]

    #[test]
    fn the_specular_layer_leaves_a_weight_in_zero_one(
        roughness in 0.0..=1.0f64, mu in prop_oneof![Just(0.0), Just(1.0), 0.0..=1.0f64],
        ior in prop_oneof![Just(1.0), Just(1.01), Just(3.8), Just(5.0), 1.0..=5.0f64],
    ) {
        let w = layer_weight(roughness, mu, ior);
        prop_assert!(w.is_finite() && (0.0..=1.0).contains(&w), "W = {}", w);
        let e = specular_albedo(roughness, mu, ior);
        prop_assert!(e.is_finite() && (0.0..=1.0).contains(&e));
        // Grazing views reflect at least as much as normal ones (Fresnel grows with angle).
        prop_assert!(specular_albedo(roughness, 1.0, ior) <= specular_albedo(roughness, 0.05, ior) + 1e-9);
    }
}

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(-1.0),
        Just(0.0),
        Just(1.0),
        -2.0..6.0f64,
        (-8.0..8.0f64).prop_map(|e| 10f64.powf(e)),
    ]
}

proptest! {
    #![proptest_config(config(2000))]

    #[test]
    fn any_principled_inputs_give_a_material_or_an_error(
        base in any_f64(), radius in any_f64(), scale in any_f64(), anisotropy in any_f64(),
        ior in any_f64(), roughness in any_f64(), weight in any_f64(), metallic in any_f64(),
        transmission in any_f64(), level in any_f64(),
    ) {
        let inputs = PrincipledInputs {
            base_color: [base, 0.5, 0.25],
            radius: [radius, 1.0, 0.5],
            scale,
            anisotropy,
            ior,
            roughness,
            subsurface_weight: weight,
            metallic,
            transmission,
            specular_ior_level: level,
        };
        if let Ok(m) = Material::from_principled(&inputs) {
            prop_assert!(m.sigma_a.iter().chain(&m.sigma_s).all(|x| x.is_finite() && *x >= 0.0));
            prop_assert!((0.0..=0.9).contains(&m.g));
            // The layers' weight is finite for it, whatever the tables.
            let w = ProfileKind::Cycles.exit_weight(&m, 0.5);
            prop_assert!(w.is_finite() && (0.0..=1.0).contains(&w));
        }
    }
}

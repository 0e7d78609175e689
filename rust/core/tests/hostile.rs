//! What a hostile user finds, kept mended (issue 28, point 7): meshes wound inward, repeated,
//! double-sided or with zero normals, meshes beyond the stated coordinate range, coefficients
//! beyond the stated range, out-of-domain inputs of the Principled helpers, light directions
//! of any finite length, and the error metric's undefined cases. Every class is a property
//! over random instances; the expectations come from the contract (docs/stability.md), the
//! closed-form area and volume of the shapes, and plain arithmetic.

mod common;
use common::{plane_parts, sphere_parts};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use translucent_core::lights::{Light, POINT_LIMIT};
use translucent_core::mesh::{Mesh, COORDINATE_LIMIT, MIN_EXTENT};
use translucent_core::metrics::relative_error;
use translucent_core::optics::principled::{
    checked_layer_weight, checked_single_scattering_albedo, G_RANGE,
};
use translucent_core::optics::{Material, MAX_COEFFICIENT};
use translucent_core::Vec3;

fn config(cases: u32) -> Config {
    let mut c = Config::with_cases(cases);
    c.failure_persistence = None;
    if std::env::var_os("PROPTEST_RNG_SEED").is_none() {
        c.rng_seed = RngSeed::Fixed(0x0005_ab1e_5eed);
    }
    c
}

/// A closed sphere moved, scaled and with its triangle list permuted and each triangle's
/// corners rotated (the same winding): (positions, triangles, the volume it encloses).
fn closed_mesh() -> impl Strategy<Value = (Vec<Vec3>, Vec<[u32; 3]>)> {
    (
        3usize..10,
        -3.0f32..3.0,
        prop::array::uniform3(-10.0f32..10.0),
        any::<u64>(),
    )
        .prop_map(|(n, log_r, offset, shuffle)| {
            let (p, mut t) = sphere_parts(n, 10f32.powf(log_r));
            let p = p.into_iter().map(|x| x + Vec3::from(offset)).collect();
            permute(&mut t, shuffle);
            (p, t)
        })
}

/// A deterministic shuffle of the triangles and a rotation of each one's corners.
fn permute(t: &mut [[u32; 3]], seed: u64) {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    for i in (1..t.len()).rev() {
        let j = (next() % (i as u64 + 1)) as usize;
        t.swap(i, j);
    }
    for tri in t.iter_mut() {
        tri.rotate_left((next() % 3) as usize);
    }
}

fn reversed(t: &[[u32; 3]]) -> Vec<[u32; 3]> {
    t.iter().map(|&[a, b, c]| [a, c, b]).collect()
}

/// The corner positions of triangle `i`, as a set.
fn corner_set(p: &[Vec3], t: &[[u32; 3]], i: usize) -> Vec<[u32; 3]> {
    let mut v: Vec<[u32; 3]> = t[i]
        .iter()
        .map(|&k| p[k as usize].to_array().map(f32::to_bits))
        .collect();
    v.sort();
    v
}

/// The triangle indices a message names, in order.
fn numbers_after(message: &str, word: &str) -> Vec<usize> {
    message
        .split(word)
        .skip(1)
        .filter_map(|rest| {
            rest.trim_start()
                .split(|c: char| !c.is_ascii_digit())
                .next()
                .and_then(|d| d.parse().ok())
        })
        .collect()
}

proptest! {
    #![proptest_config(config(64))]

    /// Outward: accepted, one closed surface of positive volume, no open or inconsistent edge.
    /// Every triangle reversed (wound inward): refused, saying so and how to mend it.
    #[test]
    fn a_closed_mesh_wound_inward_is_refused((p, t) in closed_mesh()) {
        let out = Mesh::new(p.clone(), t.clone(), None).unwrap();
        let r = out.report();
        prop_assert_eq!((r.closed_components, r.inward_components), (1, 0));
        prop_assert_eq!((r.open_edges, r.inconsistent_edges, r.non_manifold_edges), (0, 0, 0));
        prop_assert!(r.closed_volume > 0.0);
        let e = Mesh::new(p, reversed(&t), None).unwrap_err().to_string();
        prop_assert!(e.contains("wound inward") && e.contains("Recalculate Outside"), "{}", e);
    }

    /// A hollow shell (an outer sphere outward, an inner one facing the cavity) is a valid
    /// object: accepted, with the cavity counted as an inward component.
    #[test]
    fn a_hollow_shell_with_its_cavity_is_accepted(n in 3usize..8, inner in 0.1f32..0.9) {
        let (mut p, mut t) = sphere_parts(n, 1.0);
        let (q, u) = sphere_parts(n, inner);
        let base = p.len() as u32;
        p.extend(q);
        t.extend(reversed(&u).into_iter().map(|tri| tri.map(|v| v + base)));
        let m = Mesh::new(p, t, None).unwrap();
        prop_assert_eq!((m.report().closed_components, m.report().inward_components), (2, 1));
    }

    /// Any set of triangles given twice (the same corners, by index or by copied vertices at
    /// the same positions, anywhere in the list, corners rotated): refused, naming two
    /// triangles that really are the same.
    #[test]
    fn repeated_triangles_are_refused_naming_them(
        (p, t) in closed_mesh(),
        picks in prop::collection::vec(any::<prop::sample::Index>(), 1..20),
        copy_vertices in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let mut p = p;
        let mut t2 = t.clone();
        for pick in &picks {
            let mut tri = t[pick.index(t.len())];
            if copy_vertices {
                tri = tri.map(|v| {
                    p.push(p[v as usize]);
                    (p.len() - 1) as u32
                });
            }
            t2.push(tri);
        }
        permute(&mut t2, seed);
        let e = Mesh::new(p.clone(), t2.clone(), None).unwrap_err().to_string();
        let named = numbers_after(&e, "triangle");
        prop_assert!(e.contains("repeats") && named.len() == 2, "{}", e);
        prop_assert!(named[0] != named[1]);
        prop_assert_eq!(corner_set(&p, &t2, named[0]), corner_set(&p, &t2, named[1]));
    }

    /// Double-sided (each triangle also reversed, open or closed, in any order): refused.
    #[test]
    fn a_double_sided_mesh_is_refused(
        closed in any::<bool>(), n in 3usize..9, seed in any::<u64>(),
    ) {
        let (p, t) = if closed { sphere_parts(n, 1.0) } else { plane_parts(n, 1.0) };
        let mut t2 = t.clone();
        t2.extend(reversed(&t));
        permute(&mut t2, seed);
        let e = Mesh::new(p, t2, None).unwrap_err().to_string();
        prop_assert!(e.contains("wound the other way") && e.contains("double-sided"), "{}", e);
    }

    /// Given normals: a zero or NaN one anywhere is refused naming its vertex; the normals
    /// reversed on a closed outward mesh are refused; the outward ones are accepted.
    #[test]
    fn zero_nan_and_inward_normals_are_refused(
        n in 3usize..8, pick in any::<prop::sample::Index>(), nan in any::<bool>(),
    ) {
        let (p, t) = sphere_parts(n, 1.0);
        let outward: Vec<Vec3> = p.iter().map(|x| x.normalize()).collect();
        prop_assert!(Mesh::new(p.clone(), t.clone(), Some(outward.clone())).is_ok());
        let k = pick.index(p.len());
        let mut bad = outward.clone();
        bad[k] = if nan { Vec3::new(f32::NAN, 0.0, 1.0) } else { Vec3::ZERO };
        let e = Mesh::new(p.clone(), t.clone(), Some(bad)).unwrap_err().to_string();
        prop_assert!(e.contains(&format!("normals[{k}]")), "{}", e);
        let inward: Vec<Vec3> = outward.iter().map(|x| -*x).collect();
        let e = Mesh::new(p, t, Some(inward)).unwrap_err().to_string();
        prop_assert!(e.contains("normals point into the object"), "{}", e);
    }

    /// Any scale: inside the stated range [MIN_EXTENT, COORDINATE_LIMIT] the area is the
    /// closed form's (a plane of side s has area s^2); outside, an error stating the range
    /// and saying to rescale, never a claim about cross products or "degenerate".
    #[test]
    fn the_coordinate_range_is_stated_and_holds(log_s in -15.0f64..21.0) {
        let s = 10f64.powf(log_s) as f32;
        let (p, t) = plane_parts(5, 1.0);
        let p: Vec<Vec3> = p.into_iter().map(|x| x * s).collect();
        let largest = 0.5 * s;
        let diagonal = f64::from(s) * 2f64.sqrt();
        match Mesh::new(p, t, None) {
            Ok(m) => {
                prop_assert!(largest <= COORDINATE_LIMIT && diagonal >= f64::from(MIN_EXTENT));
                let exact = f64::from(s) * f64::from(s);
                prop_assert!((m.area() / exact - 1.0).abs() < 1e-5, "{} vs {}", m.area(), exact);
            }
            Err(e) => {
                let e = e.to_string();
                prop_assert!(largest > COORDINATE_LIMIT || diagonal < f64::from(MIN_EXTENT));
                prop_assert!(e.contains("rescale") && e.contains("supported"), "{}", e);
                prop_assert!(!e.contains("cross product") && !e.contains("degenerate"), "{}", e);
            }
        }
    }

    /// Coefficients from 1e-300 to 1e40 per unit: accepted exactly up to MAX_COEFFICIENT,
    /// refused above it naming the coefficient and its channel.
    #[test]
    fn coefficients_have_a_stated_range(log_x in -300.0f64..40.0, c in 0usize..3, which in any::<bool>()) {
        let x = 10f64.powf(log_x);
        let mut v = [1.0; 3];
        v[c] = x;
        let (a, s) = if which { (v, [1.0; 3]) } else { ([1.0; 3], v) };
        match Material::new(a, s, 0.0, 1.3) {
            Ok(_) => prop_assert!(x <= MAX_COEFFICIENT),
            Err(e) => {
                let name = if which { "sigma_a" } else { "sigma_s" };
                prop_assert!(x > MAX_COEFFICIENT);
                prop_assert!(e.to_string().contains(&format!("{name}[{c}]")), "{}", e);
            }
        }
    }

    /// `layer_weight` takes what a Material takes: roughness and cos_view in [0, 1], ior in
    /// [1, 5]; outside (NaN included) an error naming the argument; inside W in [0, 1].
    #[test]
    fn layer_weight_refuses_what_material_refuses(
        r in prop_oneof![Just(f64::NAN), -1.0..2.0f64],
        mu in prop_oneof![Just(f64::INFINITY), -0.5..1.5f64],
        ior in prop_oneof![Just(f64::NAN), 0.5..6.0f64],
    ) {
        let inside = |v: f64, lo: f64, hi: f64| v.is_finite() && (lo..=hi).contains(&v);
        match checked_layer_weight(r, mu, ior) {
            Ok(w) => {
                prop_assert!(inside(r, 0.0, 1.0) && inside(mu, 0.0, 1.0) && inside(ior, 1.0, 5.0));
                prop_assert!(w.is_finite() && (0.0..=1.0).contains(&w));
            }
            Err(e) => {
                let e = e.to_string();
                let named = [("roughness", inside(r, 0.0, 1.0)), ("cos_view", inside(mu, 0.0, 1.0)), ("ior", inside(ior, 1.0, 5.0))]
                    .iter().find(|(_, ok)| !ok).map(|(n, _)| *n);
                prop_assert!(named.is_some_and(|n| e.contains(&format!("{n} ="))), "{}", e);
            }
        }
    }

    /// The albedo remap over its domain (albedo in [0, 1], g in Cycles' [0, 0.9]): 0 at 0,
    /// finite and increasing in the albedo (what `cycles.to_principled`'s bisection needs);
    /// outside, an error naming the argument.
    #[test]
    fn the_albedo_remap_has_a_domain(
        a in prop_oneof![Just(f64::NAN), Just(-1.0), -0.5..1.5f64],
        g in prop_oneof![Just(2.0), Just(f64::NAN), -0.5..1.5f64],
    ) {
        let in_a = a.is_finite() && (0.0..=1.0).contains(&a);
        let in_g = g.is_finite() && (G_RANGE.0..=G_RANGE.1).contains(&g);
        match checked_single_scattering_albedo(a, g) {
            Ok(x) => {
                prop_assert!(in_a && in_g);
                prop_assert!(x.is_finite());
                prop_assert_eq!(checked_single_scattering_albedo(0.0, g).unwrap(), 0.0);
                let higher = checked_single_scattering_albedo((a + 0.01).min(1.0), g).unwrap();
                prop_assert!(higher >= x, "{} -> {}", x, higher);
            }
            Err(e) => {
                let e = e.to_string();
                prop_assert!(!(in_a && in_g));
                prop_assert!(if !in_a { e.contains("albedo =") } else { e.contains("g =") }, "{}", e);
            }
        }
    }

    /// A sun direction of any finite, non-zero length (1e-30 to 3e38) is that direction.
    #[test]
    fn sun_directions_of_any_length_are_normalised(
        d in prop::array::uniform3(-1.0f32..1.0), log_k in -30.0f32..38.5,
    ) {
        let d = Vec3::from(d);
        prop_assume!(d.length() > 0.1);
        let k = 10f32.powf(log_k);
        prop_assume!((d * k).is_finite() && (d * k) != Vec3::ZERO);
        let Light::Sun { direction, .. } = Light::sun(d * k, [1.0; 3]).unwrap() else { unreachable!() };
        prop_assert!((direction - d.normalize()).length() < 1e-5, "{:?}", direction);
    }

    /// Point lights within POINT_LIMIT are accepted, beyond it refused stating the limit.
    #[test]
    fn light_positions_have_a_stated_range(log_x in 0.0f32..38.0) {
        let x = 10f32.powf(log_x);
        match Light::point(Vec3::new(x, 0.0, 0.0), [1.0; 3]) {
            Ok(_) => prop_assert!(x <= POINT_LIMIT),
            Err(e) => prop_assert!(x > POINT_LIMIT && e.to_string().contains("supported"), "{}", e),
        }
    }

    /// relative_error: a uniform bias b reads as |b| in both figures (closed form); a NaN
    /// anywhere, or weights all zero, is an error; an all-zero truth channel is 0 where the
    /// estimate is 0 there too and infinite where it is not.
    #[test]
    fn relative_error_is_defined_or_refused(
        truth in prop::collection::vec(prop::array::uniform3(0.01f32..100.0), 1..30),
        b in -0.9f32..2.0,
        nan_at in any::<prop::sample::Index>(),
        zero_channel in 0usize..3,
    ) {
        let w = vec![1.0f32; truth.len()];
        let est: Vec<[f32; 3]> = truth.iter().map(|t| t.map(|x| x * (1.0 + b))).collect();
        let s = relative_error(&est, &truth, &w).unwrap();
        for c in 0..3 {
            prop_assert!((s.rel_rms[c] - f64::from(b.abs())).abs() < 1e-4 * (1.0 + f64::from(b.abs())));
            prop_assert!((s.rel_max[c] - f64::from(b.abs())).abs() < 1e-4 * (1.0 + f64::from(b.abs())));
        }
        let mut bad = est.clone();
        let at = nan_at.index(bad.len());
        bad[at][zero_channel] = f32::NAN;
        prop_assert!(relative_error(&bad, &truth, &w).is_err());
        prop_assert!(relative_error(&est, &bad, &w).is_err());
        prop_assert!(relative_error(&est, &truth, &vec![0.0; w.len()]).is_err());
        let mut zero = truth.clone();
        for t in zero.iter_mut() { t[zero_channel] = 0.0; }
        let s = relative_error(&zero, &zero, &w).unwrap();
        prop_assert_eq!((s.rel_rms[zero_channel], s.rel_max[zero_channel]), (0.0, 0.0));
        let s = relative_error(&est, &zero, &w).unwrap();
        prop_assert!(s.rel_rms[zero_channel].is_infinite() && s.rel_max[zero_channel].is_infinite());
    }
}

/// An open mesh wound inconsistently (half a plane's triangles reversed) is not refused, as
/// nothing says which side is out, but the report counts the edges where the winding flips.
#[test]
fn an_open_mesh_wound_inconsistently_is_reported() {
    let (p, t) = plane_parts(5, 1.0);
    let flip: Vec<[u32; 3]> = t
        .iter()
        .enumerate()
        .map(|(i, &[a, b, c])| if i < 8 { [a, c, b] } else { [a, b, c] })
        .collect();
    let m = Mesh::new(p.clone(), t, None).unwrap();
    assert_eq!(m.report().inconsistent_edges, 0);
    assert_eq!(m.report().open_edges, 16); // 4 x 4 squares: 4 sides of 4 edges
    let m = Mesh::new(p, flip, None).unwrap();
    // The first 8 triangles are the first row of squares: its 4 diagonals lie between
    // two reversed triangles (consistent), and the 4 interior edges between squares of the row
    // too; the 4 edges to the next row join a reversed and a kept triangle.
    assert_eq!(m.report().inconsistent_edges, 4);
    assert_eq!(m.report().closed_components, 0);
}

/// A lone reversed pair (Blender's Suzanne has one: the same triangle wound both ways) in a
/// large mesh is reported, not refused; the same pair in a small mesh is 1 % or more of it.
#[test]
fn a_lone_reversed_pair_is_reported_in_a_large_mesh() {
    let (p, mut t) = plane_parts(12, 1.0); // 242 triangles
    t.push([t[0][0], t[0][2], t[0][1]]);
    let m = Mesh::new(p, t, None).unwrap();
    assert_eq!(m.report().reversed_pairs, 1);
    let (p, mut t) = plane_parts(4, 1.0); // 18 triangles
    t.push([t[0][0], t[0][2], t[0][1]]);
    assert!(Mesh::new(p, t, None).is_err());
}

/// The cost of the topology checks: `Mesh::new` on a 97k-triangle sphere and the analysis
/// alone, medians of 7 (run with --ignored --nocapture; timings only, nothing asserted).
#[test]
#[ignore]
fn topology_cost() {
    let (p, t) = sphere_parts(220, 1.0);
    let areas = vec![1.0f32; t.len()];
    let median = |f: &dyn Fn()| {
        let mut s: Vec<f64> = (0..7)
            .map(|_| {
                let a = std::time::Instant::now();
                f();
                a.elapsed().as_secs_f64() * 1e3
            })
            .collect();
        s.sort_by(f64::total_cmp);
        s[3]
    };
    let new = median(&|| {
        Mesh::new(p.clone(), t.clone(), None).unwrap();
    });
    let top = median(&|| {
        translucent_core::mesh::topology::analyse(&p, &t, &areas, 0.0);
    });
    println!(
        "{} triangles: Mesh::new {new:.1} ms, of which topology {top:.1} ms",
        t.len()
    );
}

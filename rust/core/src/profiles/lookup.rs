//! A fast tabulated copy of any radial profile for methods that evaluate it millions of times
//! (the hierarchy's links): R and its disc integral C on nodes uniform in √ρ up to the support
//! radius (dense where the profile bends, at the entry point), R interpolated linearly in √ρ
//! and C by cubic Hermite in ρ with C' = 2πρR exact at the nodes. Beyond the support both are
//! cut: R = 0 and C = C(support), at most the support tolerance of the total.

use super::{support_by_bisection, LengthScales, RadialProfile, RgbProfile};
use std::f64::consts::PI;

/// Nodes of the table: the interpolation error falls as 1/NODES² (measured below 3e-4 of R
/// over the support and 1e-6 of the total for C, tests below).
pub const NODES: usize = 4096;

/// A tabulated radial profile of one channel.
#[derive(Debug, Clone)]
pub struct LookupProfile {
    support: f64,
    /// NODES / √support.
    scale: f64,
    /// R and C at ρ_i = support (i / NODES)², i = 0..=NODES.
    value: Vec<f64>,
    disc: Vec<f64>,
    total: f64,
    point_mass: f64,
    scales: LengthScales,
}

impl LookupProfile {
    /// Tabulates `p` up to the radius leaving `tail_tolerance` of its total.
    pub fn new(p: &impl RadialProfile, tail_tolerance: f64) -> LookupProfile {
        let scales = p.length_scales();
        let support = if p.is_zero() {
            0.0
        } else {
            p.support_radius(tail_tolerance)
        };
        let (mut value, mut disc) = (vec![0.0; NODES + 1], vec![0.0; NODES + 1]);
        if support > 0.0 {
            for i in 0..=NODES {
                let u = i as f64 / NODES as f64;
                let rho = support * u * u;
                value[i] = p.value(rho);
                disc[i] = p.disc_integral(rho);
            }
        }
        LookupProfile {
            support,
            scale: if support > 0.0 {
                NODES as f64 / support.sqrt()
            } else {
                0.0
            },
            value,
            disc,
            total: p.total(),
            point_mass: p.point_mass(),
            scales,
        }
    }

    /// Where the table ends: R = 0 beyond.
    pub fn support(&self) -> f64 {
        self.support
    }

    #[inline]
    fn locate(&self, rho: f64) -> Option<(usize, f64)> {
        locate(rho, self.support, self.scale)
    }
}

/// On a table up to `support` with `scale` = NODES / √support: the node below √ρ and the
/// fraction past it; None from the support on.
#[inline]
fn locate(rho: f64, support: f64, scale: f64) -> Option<(usize, f64)> {
    locate_in(rho, support, scale, NODES)
}

/// `locate` on a table of `nodes` intervals (`scale` = nodes / √support).
#[inline]
pub(super) fn locate_in(rho: f64, support: f64, scale: f64, nodes: usize) -> Option<(usize, f64)> {
    if rho >= support || rho.is_nan() {
        return None;
    }
    let u = rho.max(0.0).sqrt() * scale;
    let i = (u as usize).min(nodes - 1);
    Some((i, u - i as f64))
}

/// ρ_i = support (i / NODES)².
#[inline]
fn node(support: f64, i: usize) -> f64 {
    node_in(support, i, NODES)
}

/// ρ_i = support (i / nodes)².
#[inline]
pub(super) fn node_in(support: f64, i: usize, nodes: usize) -> f64 {
    let u = i as f64 / nodes as f64;
    support * u * u
}

/// The weights of C_i, R_i, C_i+1 and R_i+1 in the cubic Hermite of C in ρ on [ρ_i, ρ_i+1]
/// (ρ_i = support (i / NODES)²) with slopes C'(ρ) = 2πρR(ρ).
#[inline]
fn hermite(rho: f64, support: f64, i: usize) -> [f64; 4] {
    hermite_in(rho, support, i, NODES)
}

/// `hermite` on a table of `nodes` intervals.
#[inline]
pub(super) fn hermite_in(rho: f64, support: f64, i: usize, nodes: usize) -> [f64; 4] {
    let (r0, r1) = (node_in(support, i, nodes), node_in(support, i + 1, nodes));
    let h = r1 - r0;
    let t = ((rho - r0) / h).clamp(0.0, 1.0);
    let (t2, t3) = (t * t, t * t * t);
    [
        2.0 * t3 - 3.0 * t2 + 1.0,
        (t3 - 2.0 * t2 + t) * 2.0 * PI * r0 * h,
        -2.0 * t3 + 3.0 * t2,
        (t3 - t2) * 2.0 * PI * r1 * h,
    ]
}

impl RadialProfile for LookupProfile {
    #[inline]
    fn value(&self, r: f64) -> f64 {
        match self.locate(r) {
            Some((i, f)) => self.value[i] + f * (self.value[i + 1] - self.value[i]),
            None => 0.0,
        }
    }

    #[inline]
    fn disc_integral(&self, rho: f64) -> f64 {
        let Some((i, _)) = self.locate(rho) else {
            return self.disc[NODES];
        };
        let w = hermite(rho, self.support, i);
        w[0] * self.disc[i]
            + w[1] * self.value[i]
            + w[2] * self.disc[i + 1]
            + w[3] * self.value[i + 1]
    }

    fn tail(&self, rho: f64) -> f64 {
        (self.total - self.disc_integral(rho)).max(0.0)
    }

    fn total(&self) -> f64 {
        self.total
    }

    fn point_mass(&self) -> f64 {
        self.point_mass
    }

    fn support_radius(&self, rel_tol: f64) -> f64 {
        support_by_bisection(self, rel_tol, self.scales.shortest())
    }

    fn length_scales(&self) -> LengthScales {
        self.scales
    }
}

/// R of three channels on one table (one node search for all three): what a method sampling
/// the profile millions of times reads. Nodes uniform in √ρ up to the largest support, R
/// linear between them; each channel is 0 beyond its own support.
#[derive(Debug, Clone)]
pub struct LookupRgb {
    support: f64,
    scale: f64,
    value: Vec<[f64; 3]>,
    /// C of each channel at the same nodes (its own table's, the total from its support on).
    disc: Vec<[f64; 3]>,
    /// R₂(ρ) = ∫_0^ρ s² R(s) ds of each channel at the same nodes: the radial weight of the
    /// first moment ∫ R(|y − x|) (y − x) dA (`surface_integral::corner_terms_rgb`).
    second: Vec<[f64; 3]>,
    /// The shortest near length of the channels that are not zero.
    near: f64,
    /// The same nodes in f32, padded to four lanes (for SIMD readers), and two zero nodes.
    value32: Vec<[f32; 4]>,
}

impl LookupRgb {
    pub fn new(channels: &[LookupProfile; 3]) -> LookupRgb {
        let support = channels.iter().map(|c| c.support()).fold(0.0, f64::max);
        let mut value = vec![[0.0; 3]; NODES + 1];
        let mut disc = vec![[0.0; 3]; NODES + 1];
        if support > 0.0 {
            for (i, (v, d)) in value.iter_mut().zip(disc.iter_mut()).enumerate() {
                let u = i as f64 / NODES as f64;
                let rho = support * u * u;
                *v = std::array::from_fn(|c| channels[c].value(rho));
                *d = std::array::from_fn(|c| channels[c].disc_integral(rho));
            }
        }
        // By parts, s² R = s C'(s) / 2π: R₂(ρ) = (ρ C(ρ) − ∫_0^ρ C) / 2π, the integral of C
        // over each interval that of its cubic Hermite, h (C₀ + C₁) / 2 + h² (C₀' − C₁') / 12.
        let mut second = vec![[0.0; 3]; NODES + 1];
        for i in 0..NODES {
            let (r0, r1) = (node(support, i), node(support, i + 1));
            let h = r1 - r0;
            second[i + 1] = std::array::from_fn(|c| {
                let (c0, c1) = (disc[i][c], disc[i + 1][c]);
                let (s0, s1) = (2.0 * PI * r0 * value[i][c], 2.0 * PI * r1 * value[i + 1][c]);
                let area = h * (c0 + c1) / 2.0 + h * h * (s0 - s1) / 12.0;
                second[i][c] + (r1 * c1 - r0 * c0 - area) / (2.0 * PI)
            });
        }
        LookupRgb {
            second,
            support,
            scale: if support > 0.0 {
                NODES as f64 / support.sqrt()
            } else {
                0.0
            },
            value32: value
                .iter()
                .map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0])
                .chain([[0.0; 4]; 2])
                .collect(),
            value,
            disc,
            near: channels.near(),
        }
    }

    /// The f32 nodes (NODES + 1 of them, at u = √ρ · scale = 0, 1, ..., NODES, then two zeros
    /// that a reader past the support may land on), the scale and the support: R at ρ is the
    /// linear interpolation at u, and 0 from the support on.
    pub fn f32_table(&self) -> (&[[f32; 4]], f64, f64) {
        (&self.value32, self.scale, self.support)
    }

    /// C(ρ) and R₂(ρ) = ∫_0^ρ s² R(s) ds of the three channels (one node search): R₂ by the
    /// cubic Hermite in ρ with slopes R₂' = ρ² R at the nodes.
    #[inline]
    pub fn disc_second_rgb(&self, rho: f64) -> ([f64; 3], [f64; 3]) {
        let Some((i, _)) = locate(rho, self.support, self.scale) else {
            return (self.disc[NODES], self.second[NODES]);
        };
        let w = hermite(rho, self.support, i);
        let (r0, r1) = (node(self.support, i), node(self.support, i + 1));
        // hermite's slope weights carry C' = 2πρR; R₂' = ρ² R is that times ρ / 2π.
        let (k0, k1) = (r0 / (2.0 * PI), r1 / (2.0 * PI));
        let (v0, v1) = (&self.value[i], &self.value[i + 1]);
        let (s0, s1) = (&self.second[i], &self.second[i + 1]);
        (
            self.disc_between(i, &w),
            std::array::from_fn(|c| {
                w[0] * s0[c] + w[1] * k0 * v0[c] + w[2] * s1[c] + w[3] * k1 * v1[c]
            }),
        )
    }

    /// C of the three channels on [ρ_i, ρ_i+1] from `hermite`'s weights `w`.
    #[inline]
    fn disc_between(&self, i: usize, w: &[f64; 4]) -> [f64; 3] {
        let (d0, d1) = (&self.disc[i], &self.disc[i + 1]);
        let (v0, v1) = (&self.value[i], &self.value[i + 1]);
        std::array::from_fn(|c| w[0] * d0[c] + w[1] * v0[c] + w[2] * d1[c] + w[3] * v1[c])
    }

    /// R(r) of the three channels.
    #[inline]
    pub fn value(&self, r: f64) -> [f64; 3] {
        let Some((i, f)) = locate(r, self.support, self.scale) else {
            return [0.0; 3];
        };
        let (a, b) = (&self.value[i], &self.value[i + 1]);
        [
            a[0] + f * (b[0] - a[0]),
            a[1] + f * (b[1] - a[1]),
            a[2] + f * (b[2] - a[2]),
        ]
    }
}

impl RgbProfile for LookupRgb {
    /// One node search for the three channels, then the cubic Hermite of `LookupProfile` in ρ
    /// with slopes C' = 2πρR at the nodes.
    #[inline]
    fn disc_rgb(&self, rho: f64) -> [f64; 3] {
        let Some((i, _)) = locate(rho, self.support, self.scale) else {
            return self.disc[NODES];
        };
        self.disc_between(i, &hermite(rho, self.support, i))
    }

    fn near(&self) -> f64 {
        self.near
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Material;
    use crate::profiles::ProfileKind;

    #[test]
    fn three_channels_on_one_table_follow_each_profile() {
        // Ketchup's channels differ in support by an order of magnitude: the shared nodes
        // (uniform in √ρ up to the largest) must still follow the shortest one.
        for name in ["marble", "ketchup"] {
            let m = Material::preset(name, 1.0).unwrap();
            for model in [ProfileKind::Dipole, ProfileKind::Cycles] {
                let exact = model.profiles(&m).unwrap();
                let lookup = std::array::from_fn(|c| LookupProfile::new(&exact[c], 1e-4));
                let rgb = LookupRgb::new(&lookup);
                let far = lookup.iter().map(|l| l.support()).fold(0.0, f64::max);
                for k in 0..=2000 {
                    let rho = far * 1.1 * (k as f64 / 2000.0).powi(3);
                    let got = rgb.disc_rgb(rho);
                    for c in 0..3 {
                        let want = exact[c].disc_integral(rho.min(lookup[c].support()));
                        let total = exact[c].total();
                        assert!(
                            (got[c] - want).abs() <= 2e-5 * total,
                            "{name} {model:?} channel {c} at {rho}: {} vs {want}",
                            got[c]
                        );
                    }
                }
                assert_eq!(rgb.near(), exact.near());
            }
        }
    }

    #[test]
    fn the_table_follows_the_profile_it_copies() {
        let m = Material::preset("marble", 1.0).unwrap();
        for model in [ProfileKind::Dipole, ProfileKind::Cycles] {
            for p in model.profiles(&m).unwrap() {
                let t = LookupProfile::new(&p, 1e-5);
                let s = p.length_scales();
                let total = p.total();
                // From a tenth of the near length (where far links start) to the support.
                let mut r = 0.1 * s.near;
                while r < t.support() {
                    let (a, b) = (t.value(r), p.value(r));
                    assert!(
                        (a - b).abs() <= 3e-4 * b + 1e-9 * total / (s.near * s.near),
                        "{model:?} R({r}): {a} vs {b}"
                    );
                    let (a, b) = (t.disc_integral(r), p.disc_integral(r));
                    assert!(
                        (a - b).abs() <= 1e-6 * total,
                        "{model:?} C({r}): {a} vs {b}"
                    );
                    r *= 1.07;
                }
                assert_eq!(t.value(2.0 * t.support()), 0.0);
                let channels = [t.clone(), t.clone(), t.clone()];
                let rgb = LookupRgb::new(&channels);
                let mut r = 0.1 * s.near;
                while r < t.support() {
                    let (a, b) = (rgb.value(r)[1], p.value(r));
                    assert!(
                        (a - b).abs() <= 5e-4 * b + 1e-9 * total / (s.near * s.near),
                        "{model:?} RGB R({r}): {a} vs {b}"
                    );
                    r *= 1.07;
                }
                assert!((t.disc_integral(1e9) - total).abs() <= 2e-5 * total);
            }
        }
    }
}

//! Brute-force Monte Carlo through a stack of one or two plane-parallel layers: how much of a
//! beam entering the top leaves through the top and through the bottom. It is the independent
//! reference for `profiles::multipole`: Donner & Jensen 2005 (§5) validate their multipole
//! model against Monte Carlo the same way, total reflectance and transmittance of slabs.
//!
//! The medium is the diffusion model's view of it: reduced coefficients sigma_a, sigma_s'
//! with isotropic scattering (the similarity relation), each layer homogeneous. The walk
//! needs only depths and direction cosines, since the totals do not depend on where along the
//! surface the light leaves. Lengths are in scene units, coefficients in 1/unit.

use crate::error::{Error, Result};
use crate::optics::fresnel_transmittance;
use crate::profiles::walk::{exponential, uniform};
use rand_core::SeedableRng;
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// The most events (collisions and reflections at the outer faces) one walk may take; a walk
/// still inside then is lost, in no field of `SlabAnswer`. Only a stack that hardly absorbs
/// and hardly lets light out (a thick slab without absorption under a large index) comes near.
pub const MAX_EVENTS: u64 = 10_000_000;

/// A walk whose weight falls below this plays Russian roulette.
const ROULETTE_WEIGHT: f64 = 1e-6;
/// The chance of surviving the roulette; a survivor's weight is divided by it (unbiased).
const ROULETTE_SURVIVAL: f64 = 0.1;

/// Walks per rayon task: each task has its own seeded generator, so the answer does not
/// depend on the number of threads.
const CHUNK: usize = 8192;

/// One layer of the stack: reduced coefficients (isotropic scattering; the similarity
/// relation is the diffusion model's view of the medium) in 1/unit, and its thickness in
/// units (f64::INFINITY for a half-space; only the last layer may be infinite).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlabLayer {
    /// Absorption coefficient sigma_a [1/unit].
    pub sigma_a: f64,
    /// Reduced scattering coefficient sigma_s' = sigma_s (1 - g) [1/unit].
    pub sigma_s_prime: f64,
    /// Thickness [unit], infinite for a half-space (last layer only).
    pub thickness: f64,
}

/// How many walks and from which seed.
#[derive(Debug, Clone, PartialEq)]
pub struct SlabWalkSettings {
    /// Walks started, in [1024, 2^28].
    pub walks: usize,
    /// Seed of the generators (one per chunk of walks; the answer is the same on any number
    /// of threads).
    pub seed: u64,
}

impl Default for SlabWalkSettings {
    fn default() -> Self {
        Self {
            walks: 1 << 20,
            seed: 0x736c_6162_5f77_616c,
        }
    }
}

/// What left the stack per unit of entering flux.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlabAnswer {
    /// Left through the top after at least one scattering event (diffuse reflectance).
    pub reflectance: f64,
    /// Left through the bottom after at least one scattering event (diffuse transmittance).
    pub transmittance: f64,
    /// Left through the bottom unscattered, not in `transmittance`: e^{-tau}, tau = sum
    /// sigma_t' d, at eta 1; with eta > 1 the beam bounces between the faces at normal
    /// incidence, (1 - F0) e^{-tau} / (1 - F0^2 e^{-2 tau}), F0 = ((eta - 1)/(eta + 1))^2.
    pub ballistic: f64,
    /// One standard error of `reflectance` (from the per-walk scores).
    pub reflectance_error: f64,
    /// One standard error of `transmittance` (from the per-walk scores).
    pub transmittance_error: f64,
}

/// Runs `settings.walks` walks through `layers` (top first) and scores what leaves.
///
/// `eta`: relative index of refraction of the stack against the outside (the same for all
/// layers, so the interface between layers is index-matched). At the top and bottom faces a
/// walk crossing outwards is reflected back with the exact unpolarised dielectric Fresnel
/// reflectance of the inside (total internal reflection beyond the critical angle), else it
/// leaves. The light enters at normal incidence at the top (the entering flux is normalised
/// to 1: no entry Fresnel loss counted) and flies straight down.
///
/// Analogue walk: at each collision the weight is multiplied by the layer's alpha' =
/// sigma_s'/sigma_t' and the new direction is isotropic; below a weight of 1e-6 Russian
/// roulette ends the walk or lets it go on ten times heavier (unbiased). Free flights cross
/// the index-matched interface between layers by converting the optical depth left to the
/// other layer's sigma_t'. A walk still inside after `MAX_EVENTS` events is lost.
///
/// With eta > 1 and a finite stack, the part of the unscattered beam that the bottom face
/// reflects back and that leaves through the top (a specular reflection, F0 (1 - F0)
/// e^{-2 tau} / (1 - F0^2 e^{-2 tau})) is in no field: it is neither diffuse nor transmitted.
pub fn slab_walk(
    layers: &[SlabLayer],
    eta: f64,
    settings: &SlabWalkSettings,
) -> Result<SlabAnswer> {
    validate(layers, eta, settings)?;
    let stack = Stack::new(layers, eta);
    let walks = settings.walks;
    let parts: Vec<Tally> = (0..walks.div_ceil(CHUNK))
        .into_par_iter()
        .map(|chunk| {
            let mut rng = Pcg64Mcg::seed_from_u64(
                settings.seed ^ (chunk as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15),
            );
            let mut tally = Tally::default();
            for _ in chunk * CHUNK..walks.min((chunk + 1) * CHUNK) {
                tally.score(stack.walk(&mut rng));
            }
            tally
        })
        .collect();
    // Summed in chunk order: the same bits whatever the thread count.
    let sum = parts.iter().fold(Tally::default(), |a, b| a.plus(b));
    let n = walks as f64;
    // The standard error of a mean of n per-walk scores s: sqrt((<s^2> - <s>^2) / (n - 1)).
    let error = |s: f64, s2: f64| ((s2 / n - (s / n).powi(2)).max(0.0) / (n - 1.0)).sqrt();
    Ok(SlabAnswer {
        reflectance: sum.top / n,
        transmittance: sum.bottom / n,
        ballistic: sum.ballistic / n,
        reflectance_error: error(sum.top, sum.top_sq),
        transmittance_error: error(sum.bottom, sum.bottom_sq),
    })
}

/// Refuses what the walk cannot run, naming the argument.
fn validate(layers: &[SlabLayer], eta: f64, settings: &SlabWalkSettings) -> Result<()> {
    let bad = |what: String| Err(Error::InvalidArgument(what));
    if !(1..=2).contains(&layers.len()) {
        return bad(format!(
            "layers: {} given, the walk takes 1 or 2",
            layers.len()
        ));
    }
    for (i, l) in layers.iter().enumerate() {
        for (name, v) in [("sigma_a", l.sigma_a), ("sigma_s_prime", l.sigma_s_prime)] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("layers[{i}].{name} = {v} must be finite and >= 0"));
            }
        }
        if l.sigma_a + l.sigma_s_prime <= 0.0 {
            return bad(format!(
                "layers[{i}]: sigma_t' = sigma_a + sigma_s_prime must be > 0"
            ));
        }
        let last = i + 1 == layers.len();
        let finite_or_last = l.thickness.is_finite() || (last && l.thickness == f64::INFINITY);
        if !(l.thickness > 0.0 && finite_or_last) {
            return bad(format!(
                "layers[{i}].thickness = {} must be > 0 and finite (only the last layer may \
                 be infinite)",
                l.thickness
            ));
        }
    }
    if !(eta.is_finite() && eta >= 1.0) {
        return bad(format!("eta = {eta} must be finite and >= 1"));
    }
    if !(1024..=1 << 28).contains(&settings.walks) {
        return bad(format!(
            "walks = {} must lie in [1024, 2^28]",
            settings.walks
        ));
    }
    Ok(())
}

/// One layer as the walk sees it: its depth range below the top face and its coefficients.
struct Span {
    top: f64,
    bottom: f64,
    sigma_t: f64,
    albedo: f64,
}

/// The validated stack.
struct Stack {
    spans: Vec<Span>,
    eta: f64,
}

/// How a walk ended.
enum Exit {
    /// Left through the top (`bottom` false) or the bottom face with this weight, after at
    /// least one collision (`scattered`) or none.
    Left {
        bottom: bool,
        weight: f64,
        scattered: bool,
    },
    /// Absorbed (weight gone, or ended by the roulette) or lost at the event cap.
    Ended,
}

impl Stack {
    fn new(layers: &[SlabLayer], eta: f64) -> Stack {
        let mut top = 0.0;
        let spans = layers
            .iter()
            .map(|l| {
                let sigma_t = l.sigma_a + l.sigma_s_prime;
                let span = Span {
                    top,
                    bottom: top + l.thickness,
                    sigma_t,
                    albedo: l.sigma_s_prime / sigma_t,
                };
                top = span.bottom;
                span
            })
            .collect();
        Stack { spans, eta }
    }

    /// The Fresnel reflectance of a face for light inside meeting it at cosine `mu` (> 0).
    /// Total internal reflection when eta^2 (1 - mu^2) >= 1; otherwise the light would leave at
    /// cosine mu_o = sqrt(1 - eta^2 (1 - mu^2)), and by reciprocity the reflectance from inside
    /// equals the one from outside at mu_o: 1 - F_t(eta, mu_o) (`fresnel_transmittance`).
    fn reflectance(&self, mu: f64) -> f64 {
        if self.eta == 1.0 {
            return 0.0;
        }
        let sin2_out = self.eta * self.eta * (1.0 - mu * mu);
        if sin2_out >= 1.0 {
            return 1.0;
        }
        1.0 - fresnel_transmittance(self.eta, (1.0 - sin2_out).sqrt())
    }

    /// One walk from the top face, heading straight down.
    fn walk(&self, rng: &mut Pcg64Mcg) -> Exit {
        let last = self.spans.len() - 1;
        let mut layer = 0;
        // Depth below the top face and the direction's cosine along the depth.
        let (mut z, mut mu) = (0.0, 1.0);
        let mut weight = 1.0;
        let mut scattered = false;
        let mut events = 0u64;
        loop {
            // A free flight: the optical depth to the next collision is Exp(1), spent at the
            // rate sigma_t' of whichever layer the flight is in.
            let mut tau = exponential(rng);
            loop {
                let s = &self.spans[layer];
                // Path length to the face of this layer ahead (infinite when flying level or
                // down into a half-space).
                let to_face = if mu > 0.0 {
                    (s.bottom - z) / mu
                } else if mu < 0.0 {
                    (s.top - z) / mu
                } else {
                    f64::INFINITY
                };
                let reach = s.sigma_t * to_face;
                if tau < reach {
                    z = (z + mu * tau / s.sigma_t).clamp(s.top, s.bottom);
                    break;
                }
                tau -= reach;
                let down = mu > 0.0;
                z = if down { s.bottom } else { s.top };
                // The interface between the layers is index-matched: the flight goes on in the
                // other layer with the optical depth it has left.
                if down && layer < last {
                    layer += 1;
                    continue;
                }
                if !down && layer > 0 {
                    layer -= 1;
                    continue;
                }
                // An outer face: Fresnel-reflected back (specularly, the flight goes on), or out.
                events += 1;
                if events >= MAX_EVENTS {
                    return Exit::Ended;
                }
                if uniform(rng) < self.reflectance(mu.abs()) {
                    mu = -mu;
                    continue;
                }
                return Exit::Left {
                    bottom: down,
                    weight,
                    scattered,
                };
            }
            // A collision: the scattered share alpha' of the weight goes on, isotropically.
            events += 1;
            if events >= MAX_EVENTS {
                return Exit::Ended;
            }
            weight *= self.spans[layer].albedo;
            scattered = true;
            if weight < ROULETTE_WEIGHT {
                if weight <= 0.0 || uniform(rng) >= ROULETTE_SURVIVAL {
                    return Exit::Ended;
                }
                weight /= ROULETTE_SURVIVAL;
            }
            mu = 1.0 - 2.0 * uniform(rng);
        }
    }
}

/// Sums of the per-walk scores (and of their squares, for the standard errors).
#[derive(Debug, Clone, Copy, Default)]
struct Tally {
    top: f64,
    top_sq: f64,
    bottom: f64,
    bottom_sq: f64,
    ballistic: f64,
}

impl Tally {
    fn score(&mut self, exit: Exit) {
        match exit {
            Exit::Left {
                bottom: false,
                weight,
                scattered: true,
            } => {
                self.top += weight;
                self.top_sq += weight * weight;
            }
            Exit::Left {
                bottom: true,
                weight,
                scattered: true,
            } => {
                self.bottom += weight;
                self.bottom_sq += weight * weight;
            }
            Exit::Left {
                bottom: true,
                weight,
                scattered: false,
            } => self.ballistic += weight,
            // Unscattered out of the top (specular, see `slab_walk`), absorbed or lost.
            Exit::Left { .. } | Exit::Ended => {}
        }
    }

    fn plus(&self, o: &Tally) -> Tally {
        Tally {
            top: self.top + o.top,
            top_sq: self.top_sq + o.top_sq,
            bottom: self.bottom + o.bottom,
            bottom_sq: self.bottom_sq + o.bottom_sq,
            ballistic: self.ballistic + o.ballistic,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::walk::{simulate, WalkSettings};

    fn layer(sigma_a: f64, sigma_s_prime: f64, thickness: f64) -> SlabLayer {
        SlabLayer {
            sigma_a,
            sigma_s_prime,
            thickness,
        }
    }

    fn settings(walks: usize, seed: u64) -> SlabWalkSettings {
        SlabWalkSettings { walks, seed }
    }

    /// Normal-incidence Fresnel reflectance ((eta - 1)/(eta + 1))^2.
    fn f0(eta: f64) -> f64 {
        ((eta - 1.0) / (eta + 1.0)).powi(2)
    }

    /// The binomial standard error of a fraction p of n walks.
    fn binomial(p: f64, n: usize) -> f64 {
        (p * (1.0 - p) / n as f64).sqrt()
    }

    #[test]
    fn without_absorption_everything_leaves() {
        // Nothing is absorbed, so every walk leaves: diffusely through either face, or
        // unscattered through the bottom or (eta > 1, after the bottom's reflection) the top.
        // The last is the beam bouncing between the faces at normal incidence, a geometric
        // series: F0 (1 - F0) e^{-2 tau} / (1 - F0^2 e^{-2 tau}).
        let n = 1 << 16;
        for (layers, eta) in [
            (vec![layer(0.0, 1.0, 2.0)], 1.0),
            (vec![layer(0.0, 1.0, 0.5), layer(0.0, 3.0, 0.4)], 1.0),
            (vec![layer(0.0, 1.0, 0.5), layer(0.0, 3.0, 0.4)], 1.4),
        ] {
            let a = slab_walk(&layers, eta, &settings(n, 3)).unwrap();
            let tau: f64 = layers.iter().map(|l| l.sigma_s_prime * l.thickness).sum();
            let (f, e2) = (f0(eta), (-2.0 * tau).exp());
            let specular = f * (1.0 - f) * e2 / (1.0 - f * f * e2);
            let sum = a.reflectance + a.transmittance + a.ballistic + specular;
            let sigma =
                a.reflectance_error + a.transmittance_error + binomial(specular, n) + 1e-9 / 4.0;
            assert!(
                (sum - 1.0).abs() <= 4.0 * sigma,
                "eta {eta}: {a:?} + specular {specular} = {sum}"
            );
        }
    }

    #[test]
    fn the_unscattered_beam_follows_beer_lambert() {
        // e^{-tau} at eta 1; with eta > 1 the beam bounces between the faces at normal
        // incidence and leaves the bottom with (1 - F0) e^{-tau} / (1 - F0^2 e^{-2 tau}).
        let n = 1 << 16;
        let layers = [layer(0.3, 0.8, 0.6), layer(1.5, 0.5, 0.35)];
        let tau: f64 = layers
            .iter()
            .map(|l| (l.sigma_a + l.sigma_s_prime) * l.thickness)
            .sum();
        for eta in [1.0, 1.5] {
            let a = slab_walk(&layers, eta, &settings(n, 5)).unwrap();
            let f = f0(eta);
            let closed = (1.0 - f) * (-tau).exp() / (1.0 - f * f * (-2.0 * tau).exp());
            assert!(
                (a.ballistic - closed).abs() <= 4.0 * binomial(closed, n),
                "eta {eta}: {} against {closed}",
                a.ballistic
            );
        }
        // A half-space lets nothing through.
        let half = slab_walk(&[layer(0.1, 1.0, f64::INFINITY)], 1.3, &settings(n, 5)).unwrap();
        assert_eq!((half.ballistic, half.transmittance), (0.0, 0.0));
    }

    #[test]
    fn a_matched_half_space_reflects_what_cycles_walk_returns() {
        // Cycles' walk (`walk::simulate`) with g = 0 at a smooth surface along the normal goes
        // straight in and leaves at the first crossing: the diffuse reflectance of an
        // index-matched half-space. Its bounce cap is lifted so that no weight is lost there.
        // Both are also held to the exact answer, 1 - H(1) sqrt(1 - alpha) with Chandrasekhar's
        // H-function of isotropic scattering (Radiative Transfer, 1950, ch. IV; H from its
        // integral equation 1/H(mu) = sqrt(1 - alpha) + alpha/2 int_0^1 x H(x)/(mu + x) dx,
        // iterated on 800 points, converged to the digits quoted).
        let n = 1 << 17;
        let albedos = [0.99, 0.9, 0.5];
        let exact = [0.752_721, 0.414_947, 0.115_226];
        let cycles = WalkSettings {
            g: 0.0,
            roughness: 0.0,
            ior: 1.5,
            walks: n,
            seed: 11,
            max_bounces: 1_000_000,
            view_cos: 1.0,
            stratified: false,
        };
        let batches = 16;
        let h = simulate(&cycles, &albedos, &[1e9], batches, None).unwrap();
        let bins = h.bins();
        for (i, &alpha) in albedos.iter().enumerate() {
            let total = |w: &[f64]| w[i * bins..(i + 1) * bins].iter().sum::<f64>();
            let theirs = total(&h.weights) / n as f64;
            // Their standard error from the spread of the batch means.
            let means: Vec<f64> = (0..batches)
                .map(|b| total(&h.batch_weights[b]) / h.batch_walks[b] as f64)
                .collect();
            let var = means.iter().map(|m| (m - theirs).powi(2)).sum::<f64>()
                / (batches * (batches - 1)) as f64;
            let ours = slab_walk(
                &[layer(1.0 - alpha, alpha, f64::INFINITY)],
                1.0,
                &settings(n, 13),
            )
            .unwrap();
            let sigma = (var + ours.reflectance_error.powi(2)).sqrt();
            assert!(
                (ours.reflectance - theirs).abs() <= 4.0 * sigma,
                "alpha {alpha}: {} +- {} against Cycles' {theirs} +- {}",
                ours.reflectance,
                ours.reflectance_error,
                var.sqrt()
            );
            for (what, got, err) in [
                ("ours", ours.reflectance, ours.reflectance_error),
                ("Cycles'", theirs, var.sqrt()),
            ] {
                assert!(
                    (got - exact[i]).abs() <= 4.0 * err + 1e-6,
                    "alpha {alpha}: {what} {got} +- {err} against H-function {}",
                    exact[i]
                );
            }
        }
    }

    #[test]
    fn two_equal_layers_are_one_layer() {
        let n = 1 << 17;
        let split = [layer(0.1, 1.0, 0.7), layer(0.1, 1.0, 1.3)];
        let whole = [layer(0.1, 1.0, 2.0)];
        for eta in [1.0, 1.3] {
            let a = slab_walk(&split, eta, &settings(n, 17)).unwrap();
            let b = slab_walk(&whole, eta, &settings(n, 19)).unwrap();
            let near = |x: f64, y: f64, ex: f64, ey: f64| (x - y).abs() <= 4.0 * ex.hypot(ey);
            assert!(
                near(
                    a.reflectance,
                    b.reflectance,
                    a.reflectance_error,
                    b.reflectance_error
                ),
                "eta {eta}: {a:?} against {b:?}"
            );
            assert!(
                near(
                    a.transmittance,
                    b.transmittance,
                    a.transmittance_error,
                    b.transmittance_error
                ),
                "eta {eta}: {a:?} against {b:?}"
            );
            let e = binomial(b.ballistic, n);
            assert!(near(a.ballistic, b.ballistic, e, e), "{a:?} against {b:?}");
        }
    }

    #[test]
    fn same_seed_same_answer_whatever_the_thread_count() {
        let layers = [layer(0.2, 1.0, 0.5), layer(0.05, 2.0, f64::INFINITY)];
        let s = settings(2 * CHUNK + 100, 23);
        let a = slab_walk(&layers, 1.3, &s).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        assert_eq!(a, pool.install(|| slab_walk(&layers, 1.3, &s).unwrap()));
    }

    #[test]
    fn bad_input_is_refused() {
        let ok = layer(0.1, 1.0, 1.0);
        let s = settings(1024, 1);
        let refused = |layers: &[SlabLayer], eta: f64, s: &SlabWalkSettings| {
            matches!(slab_walk(layers, eta, s), Err(Error::InvalidArgument(_)))
        };
        assert!(slab_walk(&[ok], 1.3, &s).is_ok());
        assert!(slab_walk(&[ok, layer(0.1, 1.0, f64::INFINITY)], 1.3, &s).is_ok());
        // 1 or 2 layers.
        assert!(refused(&[], 1.3, &s));
        assert!(refused(&[ok, ok, ok], 1.3, &s));
        // Coefficients finite and >= 0, sigma_t' > 0.
        for bad in [
            layer(-0.1, 1.0, 1.0),
            layer(0.1, -1.0, 1.0),
            layer(f64::NAN, 1.0, 1.0),
            layer(0.1, f64::INFINITY, 1.0),
            layer(0.0, 0.0, 1.0),
        ] {
            assert!(refused(&[bad], 1.3, &s), "{bad:?}");
            assert!(refused(&[ok, bad], 1.3, &s), "{bad:?}");
        }
        // Thickness > 0, finite except in the last layer.
        for d in [0.0, -1.0, f64::NAN, f64::NEG_INFINITY] {
            assert!(refused(&[layer(0.1, 1.0, d)], 1.3, &s), "{d}");
        }
        assert!(refused(&[layer(0.1, 1.0, f64::INFINITY), ok], 1.3, &s));
        // eta finite and >= 1.
        for eta in [0.9, f64::NAN, f64::INFINITY] {
            assert!(refused(&[ok], eta, &s), "{eta}");
        }
        // walks in [1024, 2^28].
        assert!(refused(&[ok], 1.3, &settings(1023, 1)));
        assert!(refused(&[ok], 1.3, &settings((1 << 28) + 1, 1)));
    }
}

//! Whether a precompute takes single scattering: the share a thick slab's single scattering
//! has of what it returns, and the decision by `SHARE_TOLERANCE` (or as asked).

use crate::error::{Error, Result};
use crate::optics::Material;

/// The single-scattering share of what a thick slab of `material` returns under a sun along
/// the normal, per channel: L1 / (L1 + L_d) with L1 of the single-scattering plane limit (docs/design.md) seen along the
/// normal and L_d = F_t(0)^2 R_total / pi (the dipole's total, Jensen 2001). The phase function
/// is taken at its mean over directions, 1 / 4 pi: the share of single-scattered light
/// whichever way g sends it (at the backscattering angle alone a g = 0.9 medium would look
/// negligible, while its forward lobe shows under grazing and back light). What
/// `Prt(single_scattering=None)` decides by. Since R_total falls faster than the albedo, the
/// share is at least ~12 % for any scattering medium (marble: 13 %) and 0 without scattering.
pub fn single_share(material: &Material, rd_total: [f64; 3]) -> [f64; 3] {
    let f0 = crate::optics::fresnel_transmittance(material.eta, 1.0);
    let sigma_t = material.sigma_t();
    std::array::from_fn(|c| {
        if sigma_t[c] <= 0.0 {
            return 0.0;
        }
        let l1 = material.sigma_s[c] / sigma_t[c] * f0 * f0 / (4.0 * std::f64::consts::PI) / 2.0;
        let ld = f0 * f0 * rd_total[c] / std::f64::consts::PI;
        if l1 + ld > 0.0 {
            l1 / (l1 + ld)
        } else {
            0.0
        }
    })
}

/// A material whose single-scattering share (`single_share`, worst channel) is below this
/// needs no single scattering: it would change the preview by less than 1 %.
pub const SHARE_TOLERANCE: f64 = 0.01;

/// Whether single scattering is computed, the share it was decided on, and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub on: bool,
    /// The largest `single_share` over the representatives' channels (0 for Cycles' profile).
    pub share: f64,
    pub reason: String,
}

/// Decides single scattering for a precompute: `request` Some(true) asks for it (an error for
/// Cycles' profile, whose walk holds every order of scattering already), Some(false) leaves it
/// out, None takes it when the representatives' share reaches `SHARE_TOLERANCE`.
pub fn decide(
    model: crate::profiles::ProfileKind,
    representatives: &[Material],
    request: Option<bool>,
) -> Result<Decision> {
    use crate::profiles::{ProfileKind, RadialProfile};
    if model == ProfileKind::Cycles {
        if request == Some(true) {
            return Err(Error::InvalidArgument(
                "single scattering joins the dipole only: Cycles' random-walk profile already \
                 contains every order of scattering (adding it would count it twice)"
                    .into(),
            ));
        }
        return Ok(Decision {
            on: false,
            share: 0.0,
            reason: "profile 'cycles' already contains every order of scattering".into(),
        });
    }
    if model == ProfileKind::Multipole {
        // Xu 2007 eq. 5's single scattering is the half-space's: the dipole's companion.
        if request == Some(true) {
            return Err(Error::InvalidArgument(
                "single scattering joins the dipole only: it is a half-space's term, and the \
                 multipole's stack is not one"
                    .into(),
            ));
        }
        return Ok(Decision {
            on: false,
            share: 0.0,
            reason: "profile 'multipole': single scattering is the half-space's term".into(),
        });
    }
    let mut share = 0.0f64;
    for m in representatives {
        let p = model.profiles(m)?;
        let totals = std::array::from_fn(|c| p[c].total());
        share = single_share(m, totals)
            .iter()
            .copied()
            .fold(share, f64::max);
    }
    let (on, reason) = match request {
        Some(true) => (true, "asked for".to_string()),
        Some(false) => (false, "switched off".to_string()),
        None if share >= SHARE_TOLERANCE => (
            true,
            format!("share {share:.4} >= tolerance {SHARE_TOLERANCE}"),
        ),
        None => (
            false,
            format!("share {share:.4} < tolerance {SHARE_TOLERANCE}: negligible"),
        ),
    };
    Ok(Decision { on, share, reason })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::profiles::ProfileKind;

    #[test]
    fn the_share_decides_and_cycles_never_adds_single_scattering() {
        let marble = Material::preset("marble", 1.0).unwrap();
        let d = decide(ProfileKind::Dipole, &[marble], None).unwrap();
        // Marble: albedo ~1, 1/(4 pi) / 2 = 0.040 against R_total / pi = 0.866 / pi = 0.276
        // (Jensen 2001's closed form at alpha' = 0.999, eta 1.3): 0.126 on the worst channel.
        assert!(d.on && (d.share - 0.126).abs() < 0.01, "{d:?}");
        assert!(
            !decide(ProfileKind::Dipole, &[marble], Some(false))
                .unwrap()
                .on
        );
        assert!(decide(ProfileKind::Cycles, &[marble], Some(true)).is_err());
        let c = decide(ProfileKind::Cycles, &[marble], None).unwrap();
        assert!(!c.on && c.reason.contains("cycles"));
        // No scattering: nothing single scatters toward the eye.
        let dark = Material::new([50.0; 3], [0.0; 3], 0.0, 1.3).unwrap();
        let d = decide(ProfileKind::Dipole, &[dark], None).unwrap();
        assert!(!d.on && d.share < SHARE_TOLERANCE, "{d:?}");
    }
}

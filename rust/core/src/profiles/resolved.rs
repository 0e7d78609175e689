//! A material resolved once under one profile kind: its three channels' profiles (the walk
//! tables looked up or built once) and the weights every method reads off them. A method
//! resolves the material at its door and hands this on, so no step asks for the profiles again.

use super::{Profile, ProfileKind, RadialProfile};
use crate::error::Result;
use crate::optics::Material;

/// `material` under `kind`: the profiles and what is read from them (docs/design.md).
#[derive(Debug, Clone)]
pub struct Resolved {
    pub kind: ProfileKind,
    pub material: Material,
    pub profiles: [Profile; 3],
}

impl Resolved {
    /// Looks up (Cycles: builds when missing, seconds) the material's three profiles.
    pub fn new(kind: ProfileKind, material: &Material) -> Result<Resolved> {
        Self::with_progress(kind, material, None)
    }

    /// As `new`; building missing walk tables reports `progress` and stops on a cancel.
    pub fn with_progress(
        kind: ProfileKind,
        material: &Material,
        progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
    ) -> Result<Resolved> {
        Ok(Resolved {
            kind,
            material: *material,
            profiles: kind.profiles_with_progress(material, progress)?,
        })
    }

    /// The relative index of refraction of the irradiance's Fresnel factor
    /// (`ProfileKind::irradiance_eta`).
    pub fn irradiance_eta(&self) -> f64 {
        self.kind.irradiance_eta(&self.material)
    }

    /// `ProfileKind::exit_weight`: W(cos_o), the same for every channel.
    pub fn exit_weight(&self, cos_o: f64) -> f64 {
        self.kind.exit_weight(&self.material, cos_o)
    }

    /// `ProfileKind::exit_weights`: W(cos_o) V_c(cos_o) per channel.
    pub fn exit_weights(&self, cos_o: f64) -> [f64; 3] {
        self.kind
            .exit_weights(&self.material, &self.profiles, cos_o)
    }

    /// `ProfileKind::specular_reflectance`: what the surface reflects without entering.
    pub fn specular_reflectance(&self, cos_o: f64) -> f64 {
        self.kind.specular_reflectance(&self.material, cos_o)
    }

    /// What a thick slab returns per unit irradiance, profile and lobes: the profile's total
    /// plus its point mass, per channel (radiosity per irradiance).
    pub fn totals(&self) -> [f64; 3] {
        std::array::from_fn(|c| self.profiles[c].total() + self.profiles[c].point_mass())
    }

    /// The radiance factor of a thick slab under uniform irradiance E seen at view cosine
    /// `cos_view`: L = factor E / pi per channel, W(mu) V(mu) (total + point mass); for the
    /// dipole F_t(mu) R_d,total (Jensen et al. 2001 eq. 5 with Xu 2007 eq. 2).
    pub fn slab_reflectance(&self, cos_view: f64) -> [f64; 3] {
        let w = self.exit_weights(cos_view);
        let t = self.totals();
        std::array::from_fn(|c| w[c] * t[c])
    }

    /// What the surface sends on per unit irradiance toward a viewer at cosine `cos`, times
    /// pi: `slab_reflectance` plus what it reflects (`specular_reflectance`). Along the
    /// normal, a thick slab's albedo.
    pub fn sent_on(&self, cos: f64) -> [f64; 3] {
        let r = self.slab_reflectance(cos);
        let s = self.specular_reflectance(cos);
        r.map(|x| x + s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::fresnel_transmittance;
    use crate::profiles::Dipole;

    #[test]
    fn dipole_slab_is_fresnel_times_rd_total() {
        let m = Material::new([0.0032, 0.0017, 0.0048], [2.19, 2.62, 3.0], 0.0, 1.3).unwrap();
        let r = Resolved::new(ProfileKind::Dipole, &m).unwrap();
        for mu in [1.0, 0.5, 0.1] {
            let s = r.slab_reflectance(mu);
            for (c, got) in s.iter().enumerate() {
                // R_d,total is checked against a quadrature of Jensen's eq. 4 in `dipole`.
                let rd = Dipole::new(m.sigma_a[c], m.sigma_s_prime()[c], 1.3).rd_total();
                let expect = fresnel_transmittance(1.3, mu) * rd;
                assert!(
                    (got - expect).abs() <= 1e-6 * expect,
                    "mu {mu} channel {c}: {got} vs {expect}"
                );
            }
            // The dipole has no specular layer: sent on = slab reflectance.
            assert_eq!(r.sent_on(mu), s);
        }
    }
}

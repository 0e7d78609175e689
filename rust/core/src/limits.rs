//! The stated limits on request sizes: a request whose memory or time would exceed one is
//! refused up front, naming the limit and what was asked. Each value says why it is what it
//! is; Python reads them as `translucent.LIMITS` (docs/api.md, "Limits").

use crate::{Error, Result};

/// One limit: its name (the key in `translucent.LIMITS`), its value and what it counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Limit {
    pub name: &'static str,
    pub value: f64,
    pub counts: &'static str,
}

/// Walks per vertex and channel of a reference walk (`reference_radiance`): 2^24 leaves a
/// standard error of 2.4e-4 of one walk's spread, below what a float32 bake records, and one
/// vertex at 2^24 walks already takes minutes on a desktop CPU.
pub const WALKS_PER_VERTEX: Limit = Limit {
    name: "walks_per_vertex",
    value: (1u64 << 24) as f64,
    counts: "walks per vertex and channel",
};

/// Walks per walked vertex and channel inside a precompute (`Prt(walks=...)`): 2^20, a
/// thousand times the default budget per vertex; the geometry term's noise is far below the
/// basis fit's error long before.
pub const PRT_WALKS_PER_VERTEX: Limit = Limit {
    name: "prt_walks_per_vertex",
    value: (1u64 << 20) as f64,
    counts: "walks per walked vertex and channel of a precompute",
};

/// Walks of one call, receivers x channels x walks: 2^36 = 6.9e10, about a day on 16 cores
/// at the ~20 rays per walk of a 10 cm skin bunny. Beyond that a request is a typo.
pub const TOTAL_WALKS: Limit = Limit {
    name: "total_walks",
    value: (1u64 << 36) as f64,
    counts: "walks of one call (receivers x channels x walks)",
};

/// World rays per point (`world_samples`): 2^20, stratified (a 1024 x 1024 grid over the
/// hemisphere), puts the estimate's noise below float32's resolution for any smooth world.
pub const WORLD_SAMPLES: Limit = Limit {
    name: "world_samples",
    value: (1u64 << 20) as f64,
    counts: "world rays per point",
};

/// Points per area light and point (`area_samples`): 2^16, a 256 x 256 stratified grid,
/// resolves any penumbra a float32 vertex value can show.
pub const AREA_SAMPLES: Limit = Limit {
    name: "area_samples",
    value: (1u64 << 16) as f64,
    counts: "points per area light and point",
};

/// Shadow rays of one irradiance estimate, points x (world rays + area points x lights):
/// 2^40 = 1.1e12, hours of a desktop CPU at 5e7 rays/s.
pub const IRRADIANCE_RAYS: Limit = Limit {
    name: "irradiance_rays",
    value: (1u64 << 40) as f64,
    counts: "shadow rays of one irradiance estimate",
};

/// Cells per channel along each receiver's path in the brute-force single scattering
/// (`reference_single_scattering(steps=...)`): 2^20; the exponential steps' quadrature error
/// falls as steps^-2 and is below 1e-9 of L^(1) at 2^16.
pub const SINGLE_STEPS: Limit = Limit {
    name: "single_steps",
    value: (1u64 << 20) as f64,
    counts: "steps per channel along each receiver's path",
};

/// The smallest `rel_tol` of `reference_radiosity`: its values are returned in float32
/// (relative resolution 6e-8) and its lighting is a Monte Carlo estimate; agreement between
/// levels below 1e-6 cannot be told from rounding.
pub const REL_TOL_MIN: Limit = Limit {
    name: "rel_tol_min",
    value: 1e-6,
    counts: "the smallest rel_tol of reference_radiosity",
};

/// Sub-triangles of one reference level (`max_nodes`): 2^25 = 3.4e7 at ~200 bytes each
/// (corners, centroid, irradiance, normal) is ~6.7 GB.
pub const REFERENCE_NODES: Limit = Limit {
    name: "reference_nodes",
    value: (1u64 << 25) as f64,
    counts: "sub-triangles of one reference level (max_nodes)",
};

/// Surface samples of a precompute (`Prt(samples=...)`): 8e6, four times the default cap
/// (`prt::DEFAULT_MAX_SAMPLES`); at ~140 bytes each (sample, tree, irradiance: 50 M took 7 GB)
/// about 1.1 GB.
pub const PRT_SAMPLES: Limit = Limit {
    name: "prt_samples",
    value: 8e6,
    counts: "surface samples of a precompute",
};

/// Bytes per precompute sample, for the refusal's memory figure (measured: 50 M samples took
/// 7 GB).
pub const PRT_SAMPLE_BYTES: f64 = 140.0;

/// Rays of one pass of the object's own light (`interreflection`, Python's
/// `Prt(interreflection_rays=...)`), vertices x rays per vertex: 2^28 = 2.7e8, about two
/// minutes on 2 cores at the 2.2e6 rays/s measured there (a bumpy 48k-vertex sphere, 12 x 12
/// rays per vertex; each ray a closest hit and an interpolation of what the hit sends); a
/// precompute casts about 1.9 passes (the later bounces with (2/3)^2 of the rays), about four
/// minutes. The default 144 rays per vertex stays within it up to 1.8 M vertices.
pub const OWN_LIGHT_RAYS: Limit = Limit {
    name: "own_light_rays",
    value: (1u64 << 28) as f64,
    counts: "rays of one pass of the object's own light (vertices x rays per vertex)",
};

/// Every limit, for the binding to export.
pub const ALL: [Limit; 11] = [
    WALKS_PER_VERTEX,
    PRT_WALKS_PER_VERTEX,
    TOTAL_WALKS,
    WORLD_SAMPLES,
    AREA_SAMPLES,
    IRRADIANCE_RAYS,
    SINGLE_STEPS,
    REL_TOL_MIN,
    REFERENCE_NODES,
    PRT_SAMPLES,
    OWN_LIGHT_RAYS,
];

impl Limit {
    /// `Ok` when `asked` (the value of `argument`, or what it implies) is within the limit;
    /// else an error naming the argument, the limit and both values.
    pub fn at_most(&self, argument: &str, asked: f64) -> Result<()> {
        if asked <= self.value {
            return Ok(());
        }
        Err(self.refusal(argument, asked, "at most"))
    }

    /// `Ok` when `asked` is at least the limit (a floor such as `REL_TOL_MIN`).
    pub fn at_least(&self, argument: &str, asked: f64) -> Result<()> {
        if asked >= self.value {
            return Ok(());
        }
        Err(self.refusal(argument, asked, "at least"))
    }

    fn refusal(&self, argument: &str, asked: f64, bound: &str) -> Error {
        Error::InvalidArgument(format!(
            "{argument} asks for {} {}: the limit {} is {bound} {} (translucent.LIMITS)",
            number(asked),
            self.counts,
            self.name,
            number(self.value)
        ))
    }
}

/// Whole numbers in full, others in scientific notation.
fn number(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e16 {
        format!("{}", x as i64)
    } else {
        format!("{x:e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_name_the_argument_the_limit_and_both_values() {
        assert!(WORLD_SAMPLES.at_most("world_samples", 1048576.0).is_ok());
        let e = WORLD_SAMPLES.at_most("world_samples", 1e9).unwrap_err();
        let s = e.to_string();
        assert!(s.contains("world_samples asks for 1000000000"), "{s}");
        assert!(s.contains("limit world_samples is at most 1048576"), "{s}");
        let s = REL_TOL_MIN
            .at_least("rel_tol", 1e-9)
            .unwrap_err()
            .to_string();
        assert!(
            s.contains("rel_tol asks for 1e-9") && s.contains("at least 1e-6"),
            "{s}"
        );
        assert!(REL_TOL_MIN.at_least("rel_tol", 1e-6).is_ok());
    }

    #[test]
    fn names_are_unique() {
        for (i, a) in ALL.iter().enumerate() {
            assert!(ALL[i + 1..].iter().all(|b| b.name != a.name), "{}", a.name);
        }
    }
}

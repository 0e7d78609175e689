//! Radiosity at the receivers from Cycles' walks through the mesh (`walker`, `twin`): what
//! Cycles renders at a vertex, without Blender, with each receiver's noise.
//!
//! Where the half-space profiles' flat-surface assumption stops holding (ears, noses, thin
//! and curved parts) the walks take the mesh as it is. By reciprocity the radiosity at the entry
//! vertex is B(x_o) = w E[throughput E(x_exit)] + point mass E(x_o), w the subsurface lobe's
//! weight (and Cycles' alpha / 0.2 below albedo 0.2), so that L = W(mu_o) B / pi as for every
//! profile.
//!
//! A vertex's walks enter where Blender's vertex bake samples it (`bake_points`: each corner,
//! 0.1 mm towards the corner triangle's centroid at 10 cm scale, with the smooth normal there),
//! spread evenly over its corners, so that a vertex means what a vertex bake means (at a
//! spike's apex or an open rim the radiance changes within that 0.1 mm).
//!
//! Deterministic: each (vertex, channel) has its own seeded generator. (The half-space table
//! draws its first numbers from a Kronecker sequence; here that drifted every vertex's exits
//! by about a mean free path in one direction, which a radial table never sees: measured on a
//! half-lit plane, `tests/walks.rs`. Plain pseudo-random numbers have no such bias.)

use super::operator::{CornerLight, ReceiverRecord};
use super::twin::tangent_gradients;
use super::walker::{media, placements, Walker};
use crate::bake_points::BakePoints;
use crate::error::{Error, Result};
use crate::limits;
use crate::mesh::Mesh;
use crate::optics::principled::IOR_RANGE;
use crate::optics::{Material, CHANNELS};
use crate::profiles::walk::{ANISOTROPIC_BOUNCES, MAX_BOUNCES};
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use crate::shadow_edges::ShadowEdges;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// How many walks, from which seed.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshWalkSettings {
    /// Walks per vertex and channel.
    pub walks: usize,
    pub seed: u64,
    /// 256 in Cycles.
    pub max_bounces: usize,
    /// Enter at Cycles' vertex-bake sample points (`bake_points`: 0.1 mm into each corner
    /// triangle at 10 cm scale, the walks spread evenly over them) instead of at the vertex
    /// itself: what a vertex bake records.
    pub at_bake_points: bool,
    /// Follow Cycles past an exit inside another part of the mesh (`Walker::tunnel`). That
    /// light reaches the receiver after the exit's bounce, so Cycles files it as indirect
    /// light: off, the walks give Cycles' direct light alone (what a direct-light bake holds),
    /// such an exit bringing nothing.
    pub tunnel: bool,
    /// Keep what the walks found independent of the light (`ReceiverRecord`: the exits and
    /// the control variate's coefficients), so a new light is read at the same exits.
    pub record: bool,
}

impl Default for MeshWalkSettings {
    fn default() -> Self {
        Self {
            walks: 256,
            seed: 0x6d65_7368_7761_6c6b,
            max_bounces: MAX_BOUNCES,
            at_bake_points: true,
            tunnel: true,
            record: false,
        }
    }
}

/// Vertices per progress tick.
const TICK: usize = 512;
/// Walks per progress tick within a vertex (~1-10 ms of work): a vertex with 2^24 walks
/// ticks too.
pub(super) const WALK_TICK: usize = 256;

/// The walks' answer per receiver vertex.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshWalkResult {
    /// B per receiver (the walks' exits and the diffuse lobe's point mass), in the
    /// irradiance's units.
    pub radiosity: Vec<[f32; 3]>,
    /// Standard error of B per receiver, from the spread of its walks.
    pub std_error: Vec<[f32; 3]>,
    /// Area-weighted relative RMS of the standard error over the receivers, per channel:
    /// the walks' own noise.
    pub noise: [f64; 3],
    pub walks: u64,
    /// Rays cast (one per flight).
    pub rays: u64,
    /// Rays cast per receiver (all channels): what its walks cost.
    pub receiver_rays: Vec<u64>,
    /// Channels that carry no subsurface light (zero weight or no scattering): no walks.
    pub channels_skipped: usize,
    pub seconds: f64,
    /// Per receiver, with `MeshWalkSettings::record`: its walks as a function of the light.
    pub records: Option<Vec<ReceiverRecord>>,
}

/// Radiosity at the `receivers` (all vertices when None) from walks inside `mesh`, lit by
/// `irradiance` per vertex (the plain irradiance E: Cycles' exit has no Fresnel). `progress`
/// in [0, 1]; false cancels.
pub fn walk_radiosity(
    mesh: &Mesh,
    tracer: &Tracer,
    material: &Material,
    irradiance: &[[f32; 3]],
    receivers: Option<&[u32]>,
    settings: &MeshWalkSettings,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<MeshWalkResult> {
    let light = ExitLight {
        vertices: irradiance,
        edges: &ShadowEdges::none(),
    };
    walk_radiosity_lit(
        mesh, tracer, material, &light, receivers, settings, progress,
    )
}

/// The light the walks' exits read: per vertex, and finer where a shadow's edge crosses a
/// triangle (`shadow_edges`).
#[derive(Debug, Clone, Copy)]
pub struct ExitLight<'a> {
    pub vertices: &'a [[f32; 3]],
    pub edges: &'a ShadowEdges,
}

/// As `walk_radiosity`, the exits reading `light`.
pub fn walk_radiosity_lit(
    mesh: &Mesh,
    tracer: &Tracer,
    material: &Material,
    light: &ExitLight,
    receivers: Option<&[u32]>,
    settings: &MeshWalkSettings,
    progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<MeshWalkResult> {
    let start = Instant::now();
    let irradiance = light.vertices;
    check(mesh, irradiance, settings)?;
    let n = mesh.vertex_count();
    let all: Vec<u32>;
    let receivers = match receivers {
        Some(r) => {
            if let Some(bad) = r.iter().find(|&&v| v as usize >= n) {
                return Err(Error::InvalidArgument(format!(
                    "receiver index {bad} out of range for {n} vertices"
                )));
            }
            r
        }
        None => {
            all = (0..n as u32).collect();
            &all
        }
    };
    let media = media(material)?;
    let walker = Walker::new(mesh, tracer, material, light, settings);
    let active: Vec<usize> = (0..CHANNELS).filter(|&c| media[c].scale > 0.0).collect();
    let total = (receivers.len() * active.len()) as f64 * settings.walks as f64;
    limits::TOTAL_WALKS.at_most("walks x receivers x channels", total)?;
    let ticker = Ticker::new(progress, total as u64);
    // The control variate's known mean: the half-space twin's total per channel.
    let mut plane = [0f64; CHANNELS];
    for &c in &active {
        plane[c] = walker.plane_total_cached(&media[c], &ticker);
        ticker.check()?;
    }
    let gradients = tangent_gradients(mesh, irradiance);
    let mut radiosity = Vec::with_capacity(receivers.len());
    let mut std_error = Vec::with_capacity(receivers.len());
    let mut receiver_rays = Vec::with_capacity(receivers.len());
    let mut records = settings.record.then(|| Vec::with_capacity(receivers.len()));
    let mut rays = 0u64;
    for chunk in receivers.chunks(TICK) {
        // Per receiver: B, its standard error, rays, and (asked for) its record.
        type Scored = ([f32; 3], [f32; 3], u64, Option<ReceiverRecord>);
        let part: Vec<Scored> = chunk
            .par_iter()
            .map(|&v| {
                let e = irradiance[v as usize];
                let mut b = std::array::from_fn(|c| (media[c].point_mass * f64::from(e[c])) as f32);
                let mut se = [0f32; 3];
                let mut rays = 0;
                let mut record = settings.record.then(|| ReceiverRecord {
                    scale: media.map(|m| m.scale as f32),
                    point_mass: media.map(|m| m.point_mass as f32),
                    ..ReceiverRecord::default()
                });
                for &c in &active {
                    let grad =
                        Vec3::from_array(std::array::from_fn(|k| gradients[v as usize][k][c]));
                    let (mean, err, r, pass) = walker.vertex(
                        v,
                        c,
                        &media[c],
                        settings,
                        plane[c],
                        grad,
                        &ticker,
                        settings.record,
                    );
                    b[c] += (media[c].scale * mean) as f32;
                    se[c] = (media[c].scale * err) as f32;
                    rays += r;
                    if let (Some(rec), Some(pass)) = (record.as_mut(), pass) {
                        rec.passes[c].push(pass);
                    }
                }
                (b, se, rays, record)
            })
            .collect();
        for (b, se, r, record) in part {
            radiosity.push(b);
            std_error.push(se);
            receiver_rays.push(r);
            rays += r;
            if let (Some(all), Some(record)) = (records.as_mut(), record) {
                all.push(record);
            }
        }
        ticker.check()?;
    }
    let noise = relative_noise(mesh, receivers, &radiosity, &std_error);
    Ok(MeshWalkResult {
        radiosity,
        std_error,
        noise,
        walks: (receivers.len() * active.len() * settings.walks) as u64,
        rays,
        receiver_rays,
        channels_skipped: CHANNELS - active.len(),
        seconds: start.elapsed().as_secs_f64(),
        records,
    })
}

/// B per receiver and its standard error.
pub type Relit = (Vec<[f32; 3]>, Vec<[f32; 3]>);

/// B and its standard error at the `receivers` of walks that kept their records
/// (`MeshWalkSettings::record`), lit anew by `light`: the same exits read under the new light
/// and the estimator replayed (`operator`), no walk traced.
pub fn relit_radiosity(
    mesh: &Mesh,
    records: &[ReceiverRecord],
    receivers: &[u32],
    light: &ExitLight,
) -> Result<Relit> {
    RelitLight::new(mesh, light)?.radiosity(mesh, records, receivers)
}

/// A new light as the recorded exits read it, checked and laid out once for every group of
/// walked vertices relit under it (`relit_radiosity`).
pub(crate) struct RelitLight<'a> {
    gradients: Vec<[[f32; 3]; 3]>,
    corners: CornerLight<'a>,
}

impl<'a> RelitLight<'a> {
    pub(crate) fn new(mesh: &Mesh, light: &ExitLight<'a>) -> Result<Self> {
        check_irradiance(mesh, light.vertices)?;
        Ok(RelitLight {
            gradients: tangent_gradients(mesh, light.vertices),
            corners: CornerLight::new(mesh, light),
        })
    }

    /// `relit_radiosity` under this light.
    pub(crate) fn radiosity(
        &self,
        mesh: &Mesh,
        records: &[ReceiverRecord],
        receivers: &[u32],
    ) -> Result<Relit> {
        if records.len() != receivers.len() {
            return Err(Error::InvalidArgument(format!(
                "{} records for {} receivers",
                records.len(),
                receivers.len()
            )));
        }
        let n = mesh.vertex_count();
        if let Some(bad) = receivers.iter().find(|&&v| v as usize >= n) {
            return Err(Error::InvalidArgument(format!(
                "receiver index {bad} out of range for {n} vertices"
            )));
        }
        Ok(records
            .par_iter()
            .zip(receivers.par_iter())
            .map(|(r, &v)| r.radiosity(v, &self.corners, &self.gradients))
            .unzip())
    }
}

/// One finite irradiance >= 0 per vertex.
fn check_irradiance(mesh: &Mesh, irradiance: &[[f32; 3]]) -> Result<()> {
    let n = mesh.vertex_count();
    if irradiance.len() != n {
        return Err(Error::InvalidArgument(format!(
            "{} irradiance values for {n} vertices",
            irradiance.len()
        )));
    }
    if irradiance
        .iter()
        .flatten()
        .any(|e| !e.is_finite() || *e < 0.0)
    {
        return Err(Error::InvalidArgument(
            "irradiance must be finite and >= 0".into(),
        ));
    }
    Ok(())
}

/// The irradiance (one finite value >= 0 per vertex) and the walks' counts, checked.
fn check(mesh: &Mesh, irradiance: &[[f32; 3]], settings: &MeshWalkSettings) -> Result<()> {
    check_irradiance(mesh, irradiance)?;
    if settings.walks == 0 {
        return Err(Error::InvalidArgument("walks = 0 must be >= 1".into()));
    }
    limits::WALKS_PER_VERTEX.at_most("walks", settings.walks as f64)?;
    if !(ANISOTROPIC_BOUNCES + 1..=1_000_000).contains(&settings.max_bounces) {
        return Err(Error::InvalidArgument(format!(
            "max_bounces = {} must lie in [11, 10^6]",
            settings.max_bounces
        )));
    }
    Ok(())
}

impl<'a> Walker<'a> {
    /// What every walk of `material` inside `mesh` shares, its exits reading `light`.
    fn new(
        mesh: &'a Mesh,
        tracer: &'a Tracer,
        material: &Material,
        light: &ExitLight<'a>,
        settings: &MeshWalkSettings,
    ) -> Self {
        Walker {
            mesh,
            tracer,
            irradiance: light.vertices,
            edges: light.edges,
            g: material.g,
            entry_alpha: material.layers.roughness * material.layers.roughness,
            inv_ior: 1.0 / material.eta.clamp(IOR_RANGE.0, IOR_RANGE.1),
            max_bounces: settings.max_bounces,
            placement: placements(mesh, tracer),
            bake_points: settings.at_bake_points.then(|| BakePoints::new(mesh)),
            tunnel: settings.tunnel,
        }
    }
}

/// The walks' own noise: the area-weighted relative RMS of the standard errors over the
/// receivers, per channel.
pub(crate) fn relative_noise(
    mesh: &Mesh,
    receivers: &[u32],
    radiosity: &[[f32; 3]],
    std_error: &[[f32; 3]],
) -> [f64; 3] {
    let areas = mesh.vertex_areas();
    std::array::from_fn(|c| {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for ((&v, b), se) in receivers.iter().zip(radiosity).zip(std_error) {
            let a = f64::from(areas[v as usize]);
            num += a * f64::from(se[c]).powi(2);
            den += a * f64::from(b[c]).powi(2);
        }
        if den > 0.0 {
            (num / den).sqrt()
        } else {
            0.0
        }
    })
}

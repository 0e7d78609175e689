//! What a hierarchy is asked to do (`HierarchySettings`, Mertens 2003's thresholds and modes,
//! §5.5) and what its last evaluation did (`HierarchyReport`).

use crate::error::{Error, Result};
use crate::profiles::ProfileKind;

/// Which of Mertens' three modes (§5.5) an evaluation runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    OnTheFly,
    Incremental,
    Render,
}

impl Mode {
    pub fn parse(name: &str) -> Result<Mode> {
        match name {
            "on_the_fly" => Ok(Mode::OnTheFly),
            "incremental" => Ok(Mode::Incremental),
            "render" => Ok(Mode::Render),
            other => Err(Error::InvalidArgument(format!(
                "mode {other:?}: choose 'on_the_fly', 'incremental' or 'render'"
            ))),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Mode::OnTheFly => "on_the_fly",
            Mode::Incremental => "incremental",
            Mode::Render => "render",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct HierarchySettings {
    /// ε₁: largest change of an emitter's solid angle [sr] across a receiver's children.
    pub eps_receiver: f64,
    /// ε₂: largest solid angle [sr] an emitter may subtend at a far link.
    pub eps_emitter: f64,
    pub profile: ProfileKind,
    pub mode: Mode,
    /// Share of the profile's total left out beyond its support radius.
    pub support_tolerance: f64,
    pub world_samples: u32,
    /// The world shadowed by the mesh (`world_samples` rays per point) rather than by its
    /// nine spherical-harmonic coefficients unshadowed (Mertens 2003 §5.3, no rays: the
    /// paper's choice and the default).
    pub world_shadows: bool,
    pub area_samples: u32,
    pub seed: u64,
    /// Receivers (vertices, or faces with `Receivers::Faces`) whose radiosity the error
    /// estimate recomputes with ε/4.
    pub estimate_receivers: usize,
    /// The walks' geometry term and the object's own light (`terms`, Cycles' profile only);
    /// None: the half-space profile alone, as Mertens 2003 has it.
    pub terms: Option<crate::surface_terms::TermSettings>,
    /// Where B is gathered: at every vertex, each refined from the root (`Vertices`, the
    /// default: within 2 % of the ground truth on coarse and held-out meshes), or at the faces'
    /// centroids and averaged to the vertices (`Faces`, Mertens' §3.2: on-the-fly 258-301
    /// against 377 ms at 130k triangles, 2.4-6 % off on faces as wide as the diffusion
    /// length; docs/hierarchy.md).
    pub receivers: Receivers,
}

/// Where the hierarchy gathers B (`HierarchySettings::receivers`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Receivers {
    #[default]
    Vertices,
    Faces,
}

impl Receivers {
    pub fn parse(name: &str) -> Result<Receivers> {
        match name {
            "vertices" => Ok(Receivers::Vertices),
            "faces" => Ok(Receivers::Faces),
            other => Err(Error::InvalidArgument(format!(
                "receivers {other:?} is not one of \"vertices\", \"faces\""
            ))),
        }
    }
}

impl Default for HierarchySettings {
    fn default() -> Self {
        Self {
            eps_receiver: 0.005,
            eps_emitter: 0.5,
            profile: ProfileKind::Cycles,
            mode: Mode::OnTheFly,
            support_tolerance: 1e-4,
            world_samples: 64,
            world_shadows: false,
            area_samples: 16,
            seed: 1,
            estimate_receivers: 32,
            terms: None,
            receivers: Receivers::Vertices,
        }
    }
}

/// What the last evaluation did and how long each phase took [s].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HierarchyReport {
    pub mode: &'static str,
    pub faces: usize,
    pub clusters: usize,
    pub depth: usize,
    /// Links of the last evaluation (on-the-fly: used, not stored; dark emitters skipped).
    pub far_links: u64,
    pub near_links: u64,
    pub oracle_tests: u64,
    pub dropped_beyond_support: u64,
    /// Faces wide against the profile, their light sampled at four points.
    pub split_faces: usize,
    /// Faces around vertex receivers resolved at sixteen points for a shadow's edge
    /// (`edges`).
    pub edge_faces: usize,
    /// Whether links were refined (on-the-fly, first build, incremental re-check).
    pub relinked: bool,
    pub rays: u64,
    pub seconds_build: f64,
    pub seconds_refit: f64,
    pub seconds_irradiance: f64,
    pub seconds_pull: f64,
    /// Refinement and gather (they run together in one traversal).
    pub seconds_links: f64,
    pub seconds_push: f64,
    pub seconds_estimate: f64,
    pub seconds: f64,
    /// Area-weighted relative RMS per channel between the receivers' radiosity and the same
    /// recomputed with ε/4 on `estimate_receivers` of them (vertices or faces); None when `estimate_receivers` is 0
    /// (no estimate computed, never a made-up zero). The sampled irradiance's noise added
    /// (`irradiance_noise`), and with the walks on, theirs.
    pub error_estimate: Option<[f64; 3]>,
    /// What the sampled irradiance's noise (the bounce off the rest of the scene, area lights,
    /// a traced world) leaves in B at the estimate's receivers, relative RMS per channel; 0
    /// where nothing is sampled or no estimate is computed.
    pub irradiance_noise: [f64; 3],
    /// The walks' term and the own light, when on (`HierarchySettings::terms`).
    pub terms: Option<crate::surface_terms::TermReport>,
}

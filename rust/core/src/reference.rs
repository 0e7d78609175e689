//! STUB (helper replaces)
use crate::{error::Result, mesh::Mesh, optics::Material};
use glam::Vec3;
pub struct ReferenceSettings {
    pub rel_tol: f64,
    pub max_level: u32,
    pub max_nodes: usize,
}
impl Default for ReferenceSettings {
    fn default() -> Self {
        Self {
            rel_tol: 1e-3,
            max_level: 4,
            max_nodes: 4_000_000,
        }
    }
}
pub struct ReferenceResult {
    pub radiosity: Vec<[f32; 3]>,
    pub receivers: Vec<u32>,
    pub level: u32,
    pub nodes: usize,
    pub estimated_rel_error: f64,
    pub converged: bool,
    pub skipped_far: u64,
    pub seconds: f64,
}
pub fn reference_radiosity(
    _mesh: &Mesh,
    _material: &Material,
    _irradiance: &(dyn Fn(&[Vec3], &[Vec3]) -> Result<Vec<[f32; 3]>> + Sync),
    _receivers: Option<&[u32]>,
    _settings: &ReferenceSettings,
    _progress: Option<&(dyn Fn(f32) -> bool + Sync)>,
) -> Result<ReferenceResult> {
    unimplemented!()
}

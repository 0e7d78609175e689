//! STUB (helper replaces)
use crate::{error::Result, raytrace::Tracer, scene::Scene};
use glam::Vec3;
#[derive(Debug, Clone)]
pub struct IrradianceSettings {
    pub eta: f64,
    pub world_samples: u32,
    pub area_samples: u32,
    pub seed: u64,
}
impl Default for IrradianceSettings {
    fn default() -> Self {
        Self {
            eta: 1.0,
            world_samples: 64,
            area_samples: 16,
            seed: 0,
        }
    }
}
#[derive(Debug, Clone, Default)]
pub struct IrradianceReport {
    pub rays: u64,
    pub lights_used: usize,
    pub lights_skipped: usize,
    pub world_skipped: bool,
}
pub fn irradiance(
    _scene: &Scene,
    _tracer: &Tracer,
    _points: &[Vec3],
    _normals: &[Vec3],
    _settings: &IrradianceSettings,
) -> Result<(Vec<[f32; 3]>, IrradianceReport)> {
    unimplemented!()
}

//! The wgpu adapter every GPU path runs on (PRT's edit kernels, the splatting's render
//! passes): the first adapter wgpu offers, preferring a real GPU, Mesa's software lavapipe only
//! where it is allowed (CI has no GPU).

use crate::error::{Error, Result};

/// Which adapter the evaluator runs on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct AdapterDescription {
    pub name: String,
    pub backend: String,
    /// "DiscreteGpu", "IntegratedGpu", "Cpu" (lavapipe), ...
    pub device_type: String,
    /// Whether this is a software rasteriser rather than a real GPU.
    pub is_software: bool,
}

/// The first adapter wgpu offers, preferring real GPUs; `allow_software` admits lavapipe.
pub fn adapter(allow_software: bool) -> Result<(wgpu::Adapter, AdapterDescription)> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        ..Default::default()
    }))
    .map_err(|e| Error::GpuUnavailable(format!("no wgpu adapter: {e}")))?;
    let info = adapter.get_info();
    let description = AdapterDescription {
        name: info.name.clone(),
        backend: format!("{:?}", info.backend),
        device_type: format!("{:?}", info.device_type),
        is_software: info.device_type == wgpu::DeviceType::Cpu,
    };
    if description.is_software && !allow_software {
        return Err(Error::GpuUnavailable(format!(
            "only a software adapter ({}) is available",
            description.name
        )));
    }
    Ok((adapter, description))
}

/// Whether a GPU adapter exists (a software one counts when `allow_software`), and which.
pub fn probe(allow_software: bool) -> Result<AdapterDescription> {
    adapter(allow_software).map(|(_, d)| d)
}

//! Where an edit's dot product runs (rayon or wgpu), and single scattering attached to the
//! transport there.

use super::{single, Prt};
use crate::error::{Error, Result};
use crate::profiles::ProfileKind;

/// Where the per-edit dot product runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// rayon over blocks of vertices.
    Cpu,
    /// wgpu compute (any Vulkan adapter, lavapipe included).
    Gpu,
}

impl Prt {
    /// Moves the dot product to a GPU (uploading the transport once), or back to the CPU.
    /// `allow_software` admits a software adapter (lavapipe). On failure the CPU stays in use
    /// and the error says why.
    pub fn set_backend(&mut self, backend: Backend, allow_software: bool) -> Result<()> {
        self.set_backend_with(backend, allow_software, false)
    }

    /// As `set_backend`; `half` stores the GPU transport as f16 (see `gpu_half_error`).
    pub fn set_backend_with(
        &mut self,
        backend: Backend,
        allow_software: bool,
        half: bool,
    ) -> Result<()> {
        match backend {
            Backend::Cpu => {
                self.gpu = None;
                Ok(())
            }
            Backend::Gpu => {
                let t = &self.transport;
                let mut gpu = crate::prt::gpu::GpuEvaluator::new(
                    t.values(),
                    t.vertices(),
                    t.channels(),
                    t.stride(),
                    allow_software,
                    half,
                )?;
                // Single scattering joins it there.
                if let Some(s) = &self.single {
                    s.attach_to(&mut gpu)?;
                }
                self.gpu = Some(gpu);
                Ok(())
            }
        }
    }

    pub fn backend(&self) -> Backend {
        if self.gpu.is_some() {
            Backend::Gpu
        } else {
            Backend::Cpu
        }
    }

    /// The rounding error f16 transport storage adds (see `GpuEvaluator::half_error`).
    pub fn gpu_half_error(&self) -> Option<f64> {
        self.gpu.as_ref().and_then(|g| g.half_error())
    }

    /// The GPU adapter in use, if any.
    pub fn gpu_adapter(&self) -> Option<&crate::prt::gpu::AdapterDescription> {
        self.gpu.as_ref().map(|g| g.adapter())
    }

    /// Attaches single scattering precomputed for the same mesh (the dipole only: Cycles'
    /// walk already holds every order of scattering, and adding L^(1) would count it twice).
    pub fn set_single_scattering(
        &mut self,
        single: Option<single::SingleScattering>,
    ) -> Result<()> {
        if let Some(s) = &single {
            if self.profile != ProfileKind::Dipole {
                return Err(Error::InvalidArgument(format!(
                    "single scattering joins the dipole only: the {} profile already contains it",
                    self.profile.name()
                )));
            }
            if s.report().coefficients == 0 || s.vertex_count() != self.vertex_count() {
                return Err(Error::InvalidArgument(
                    "single scattering was precomputed for another mesh".into(),
                ));
            }
        }
        if let Some(gpu) = self.gpu.as_mut() {
            match &single {
                Some(s) => s.attach_to(gpu)?,
                None => gpu.detach_single(),
            }
        }
        self.single = single;
        Ok(())
    }

    pub fn single_scattering(&self) -> Option<&single::SingleScattering> {
        self.single.as_ref()
    }

    /// Whether an edit's single scattering runs on the GPU (beside the MS dot products).
    pub fn single_on_gpu(&self) -> bool {
        self.single.is_some() && self.gpu.as_ref().is_some_and(|g| g.has_single())
    }
}

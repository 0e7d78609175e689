//! The GPU path of the per-edit dot product (Xu 2007 eq. 9) through wgpu compute: the transport
//! is uploaded once, each edit uploads only the coefficients (3 x stride floats), dispatches,
//! and reads the radiosity back. Runs on any Vulkan adapter, Mesa's software lavapipe included.

use crate::error::{Error, Result};
use std::time::Instant;
use wgpu::util::DeviceExt;

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

/// Times of one GPU edit [s].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GpuTimings {
    pub upload: f64,
    pub dispatch: f64,
    pub readback: f64,
}

/// The transport resident on a GPU, ready for edits.
pub struct GpuEvaluator {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    coefficients: wgpu::Buffer,
    output: wgpu::Buffer,
    staging: wgpu::Buffer,
    vertices: usize,
    stride: usize,
    adapter: AdapterDescription,
    half_error: Option<f64>,
}

impl std::fmt::Debug for GpuEvaluator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuEvaluator")
            .field("adapter", &self.adapter)
            .field("vertices", &self.vertices)
            .finish()
    }
}

/// The first adapter wgpu offers, preferring real GPUs; `allow_software` admits lavapipe.
fn adapter(allow_software: bool) -> Result<(wgpu::Adapter, AdapterDescription)> {
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

/// Packs the transport as f16 pairs in u32 words, each run of `run` values (16 lanes: one
/// coefficient of 16 vertices) divided by its largest magnitude (returned as the scales), and
/// measures the rounding: the largest |x - decoded(x)| relative to its run's largest |x|.
fn pack_half(values: &[f32], run: usize) -> (Vec<u32>, Vec<f32>, f64) {
    let mut halves = Vec::with_capacity(values.len());
    let mut scales = Vec::with_capacity(values.len() / run.max(1) + 1);
    let mut worst = 0.0f64;
    for chunk in values.chunks(run.max(1)) {
        let scale = chunk.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        let inv = if scale > 0.0 { 1.0 / scale } else { 0.0 };
        scales.push(scale);
        for x in chunk {
            let h = half::f16::from_f32(x * inv);
            if scale > 0.0 {
                worst = worst.max(f64::from((h.to_f32() * scale - x).abs() / scale));
            }
            halves.push(h.to_bits());
        }
    }
    let words = halves
        .chunks(2)
        .map(|p| u32::from(p[0]) | (u32::from(p.get(1).copied().unwrap_or(0)) << 16))
        .collect();
    (words, scales, worst)
}

impl GpuEvaluator {
    /// Uploads `transport` ([block][channel][j][16 lanes] f32, see prt/layout.rs), as f32 or,
    /// with `half`, as IEEE f16 (half the memory and bandwidth; `half_error` says what it costs).
    pub fn new(
        transport: &[f32],
        vertices: usize,
        channels: usize,
        stride: usize,
        allow_software: bool,
        half: bool,
    ) -> Result<GpuEvaluator> {
        let (adapter, description) = adapter(allow_software)?;
        let limits = adapter.limits();
        let (words, scales, half_error) = if half {
            let (w, s, e) = pack_half(transport, 16);
            (w, s, Some(e))
        } else {
            let bits: Vec<u32> = transport.iter().map(|x| x.to_bits()).collect();
            (bits, vec![1.0f32], None)
        };
        let bytes = std::mem::size_of_val(words.as_slice()) as u64;
        if bytes > limits.max_storage_buffer_binding_size {
            return Err(Error::GpuUnavailable(format!(
                "transport of {bytes} bytes exceeds the adapter's storage binding limit of {}",
                limits.max_storage_buffer_binding_size
            )));
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("translucent"),
            required_limits: limits,
            ..Default::default()
        }))
        .map_err(|e| Error::GpuUnavailable(format!("request_device failed: {e}")))?;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("prt dot"),
            source: wgpu::ShaderSource::Wgsl(include_str!("dot.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("prt dot"),
            layout: None,
            module: &shader,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let params: [u32; 4] = [
            vertices as u32,
            channels as u32,
            stride as u32,
            u32::from(half),
        ];
        let params = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("params"),
            contents: bytemuck::cast_slice(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let transport_buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("transport"),
            contents: bytemuck::cast_slice(&words),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let scales = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("scales"),
            contents: bytemuck::cast_slice(&scales),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let coefficients = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("coefficients"),
            size: (3 * stride * 4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let out_size = (vertices.max(1) * 3 * 4) as u64;
        let output = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("radiosity"),
            size: out_size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: out_size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let layout = pipeline.get_bind_group_layout(0);
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("prt dot"),
            layout: &layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: transport_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: coefficients.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: output.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: scales.as_entire_binding(),
                },
            ],
        });
        Ok(GpuEvaluator {
            device,
            queue,
            pipeline,
            bind_group,
            coefficients,
            output,
            staging,
            vertices,
            stride,
            adapter: description,
            half_error,
        })
    }

    /// With f16 storage: the largest rounding error of a transport entry relative to the
    /// largest of the same coefficient over its 16 vertices; None for f32. For coefficient
    /// vectors of one sign (fitted dipole profiles) it bounds the error of B relative to the
    /// brightest of those 16 vertices (a dim vertex beside bright ones can see more).
    pub fn half_error(&self) -> Option<f64> {
        self.half_error
    }

    pub fn adapter(&self) -> &AdapterDescription {
        &self.adapter
    }

    /// B per vertex for coefficients `[3][stride]` (colour already folded in).
    pub fn dot(&self, coefficients: &[f32]) -> Result<(Vec<[f32; 3]>, GpuTimings)> {
        if coefficients.len() != 3 * self.stride {
            return Err(Error::InvalidArgument(format!(
                "{} coefficients for a stride of {}",
                coefficients.len(),
                self.stride
            )));
        }
        let mut t = GpuTimings::default();
        let t0 = Instant::now();
        self.queue
            .write_buffer(&self.coefficients, 0, bytemuck::cast_slice(coefficients));
        t.upload = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(self.vertices.div_ceil(64).max(1) as u32, 1, 1);
        }
        encoder.copy_buffer_to_buffer(&self.output, 0, &self.staging, 0, self.staging.size());
        self.queue.submit(Some(encoder.finish()));
        let slice = self.staging.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::GpuUnavailable(format!("device poll failed: {e}")))?;
        rx.recv()
            .map_err(|e| Error::GpuUnavailable(format!("readback lost: {e}")))?
            .map_err(|e| Error::GpuUnavailable(format!("readback failed: {e}")))?;
        t.dispatch = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        let out = {
            let view = slice
                .get_mapped_range()
                .map_err(|e| Error::GpuUnavailable(format!("mapping failed: {e}")))?;
            let floats: &[f32] = bytemuck::cast_slice(&view);
            floats[..self.vertices * 3]
                .chunks_exact(3)
                .map(|c| [c[0], c[1], c[2]])
                .collect()
        };
        self.staging.unmap();
        t.readback = t2.elapsed().as_secs_f64();
        Ok((out, t))
    }
}

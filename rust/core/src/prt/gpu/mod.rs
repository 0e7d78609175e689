//! The GPU path of the per-edit dot product (Xu 2007 eq. 9) through wgpu compute: the transport
//! is uploaded once, each edit uploads only the coefficients (3 x stride floats), dispatches,
//! and reads the radiosity back. Runs on any Vulkan adapter, Mesa's software lavapipe included.
//! Single scattering (Xu 2007 eq. 14, `single.wgsl`) joins it on the same device: its S_j are
//! uploaded once (`attach_single`), and an edit dispatches both kernels in one submission and
//! reads both results back with one wait.

use crate::error::{Error, Result};
use crate::gpu::adapter;
pub use crate::gpu::{probe, AdapterDescription};
use std::time::Instant;
use wgpu::util::DeviceExt;

/// Times of one GPU edit [s].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GpuTimings {
    pub upload: f64,
    pub dispatch: f64,
    pub readback: f64,
}

/// Single scattering's transport as the GPU takes it (see prt/single/quantized.rs `Quantized`).
#[derive(Debug, Clone, Copy)]
pub struct SingleTransport<'a> {
    /// [vertex][group][q][run] u16 values, two per word (the first in the low half).
    pub words: &'a [u32],
    /// [vertex][group]
    pub scales: &'a [f32],
    /// [vertex][position, normal] (w unused).
    pub geometry: &'a [[f32; 4]],
    /// [group] light colour (w unused).
    pub colours: &'a [[f32; 4]],
    /// Basis functions of E.
    pub n: usize,
    /// u16 values per (vertex, group, q) run: n rounded up to even.
    pub run: usize,
    /// Spread light (area lights, the world): [vertex][group][moment][run] u16 values, S_j,0
    /// then the Y_lm moments up to `order` (prt/single/quantized.rs `Quantized`).
    pub spread_words: &'a [u32],
    /// [vertex][spread group]
    pub spread_scales: &'a [f32],
    /// [spread group] light colour (w unused).
    pub spread_colours: &'a [[f32; 4]],
    /// The Y_lm order of the moments (0 without spread light).
    pub order: usize,
}

/// One edit's single scattering parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct SingleEdit {
    /// [3][n]: E's coefficients per channel.
    pub coefficients: Vec<f32>,
    pub g: f32,
    pub eta: f32,
    /// false: Eddington (Xu eq. 11), true: Henyey–Greenstein.
    pub henyey_greenstein: bool,
    /// None: along each normal.
    pub eye: Option<[f32; 3]>,
    pub sigma_s: [f32; 3],
}

/// Single scattering resident on the GPU.
struct SingleResident {
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    params: wgpu::Buffer,
    coefficients: wgpu::Buffer,
    output: wgpu::Buffer,
    staging: wgpu::Buffer,
    groups: usize,
    spread_groups: usize,
    order: usize,
    n: usize,
    run: usize,
    bytes: u64,
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
    single: Option<SingleResident>,
}

impl std::fmt::Debug for GpuEvaluator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuEvaluator")
            .field("adapter", &self.adapter)
            .field("vertices", &self.vertices)
            .finish()
    }
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

/// What each edit writes and reads back: its coefficients ([3][per_channel] f32, written per
/// edit), its per-vertex RGB output, and the mappable copy the output is read back through.
fn edit_buffers(
    device: &wgpu::Device,
    label: &str,
    per_channel: usize,
    vertices: usize,
) -> [wgpu::Buffer; 3] {
    let buffer = |what: &str, size: usize, usage| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("{label} {what}")),
            size: size as u64,
            usage,
            mapped_at_creation: false,
        })
    };
    let out_size = vertices.max(1) * 3 * 4;
    use wgpu::BufferUsages as U;
    [
        buffer(
            "coefficients",
            3 * per_channel * 4,
            U::STORAGE | U::COPY_DST,
        ),
        buffer("output", out_size, U::STORAGE | U::COPY_SRC),
        buffer("readback", out_size, U::MAP_READ | U::COPY_DST),
    ]
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
        let [coefficients, output, staging] = edit_buffers(&device, "radiosity", stride, vertices);
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
            single: None,
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

    /// Uploads single scattering's transport beside the multiple-scattering one (once per
    /// precompute); every `evaluate` with a `SingleEdit` then runs both kernels.
    pub fn attach_single(&mut self, t: &SingleTransport) -> Result<()> {
        let groups = t.colours.len();
        let spread_groups = t.spread_colours.len();
        let moments = (t.order + 1) * (t.order + 1);
        let vertices = self.vertices;
        if t.run < t.n
            || t.run % 2 != 0
            || t.order > crate::spherical_harmonics::MAX_ORDER
            || t.geometry.len() != 2 * vertices
            || t.scales.len() != vertices * groups
            || t.words.len() * 2 != vertices * groups * 4 * t.run
            || t.spread_scales.len() != vertices * spread_groups
            || t.spread_words.len() * 2 != vertices * spread_groups * moments * t.run
        {
            return Err(Error::InvalidArgument(
                "single-scattering transport does not match the mesh on the GPU".into(),
            ));
        }
        let device = &self.device;
        let limit = device.limits().max_storage_buffer_binding_size;
        let bytes =
            std::mem::size_of_val(t.words).max(std::mem::size_of_val(t.spread_words)) as u64;
        if bytes > limit {
            return Err(Error::GpuUnavailable(format!(
                "single-scattering transport of {bytes} bytes exceeds the adapter's storage \
                 binding limit of {limit}"
            )));
        }
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("single scattering"),
            source: wgpu::ShaderSource::Wgsl(include_str!("single.wgsl").into()),
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("single scattering"),
            layout: None,
            module: &shader,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let init = |label: &str, contents: &[u8]| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                // An empty binding is invalid: at least one word.
                contents: if contents.is_empty() {
                    &[0; 16]
                } else {
                    contents
                },
                usage: wgpu::BufferUsages::STORAGE,
            })
        };
        let words = init("single words", bytemuck::cast_slice(t.words));
        let scales = init("single scales", bytemuck::cast_slice(t.scales));
        let geometry = init("single geometry", bytemuck::cast_slice(t.geometry));
        let colours = init("single colours", bytemuck::cast_slice(t.colours));
        let spread_words = init("spread words", bytemuck::cast_slice(t.spread_words));
        let spread_scales = init("spread scales", bytemuck::cast_slice(t.spread_scales));
        let spread_colours = init("spread colours", bytemuck::cast_slice(t.spread_colours));
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("single params"),
            size: 80,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let [coefficients, output, staging] =
            edit_buffers(device, "single radiance", t.n.max(1), vertices);
        let layout = pipeline.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = [
            &params,
            &words,
            &scales,
            &geometry,
            &colours,
            &coefficients,
            &output,
            &spread_words,
            &spread_scales,
            &spread_colours,
        ]
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("single scattering"),
            layout: &layout,
            entries: &entries,
        });
        self.single = Some(SingleResident {
            pipeline,
            bind_group,
            params,
            coefficients,
            output,
            staging,
            groups,
            spread_groups,
            order: t.order,
            n: t.n,
            run: t.run,
            bytes: (std::mem::size_of_val(t.words)
                + std::mem::size_of_val(t.scales)
                + std::mem::size_of_val(t.spread_words)
                + std::mem::size_of_val(t.spread_scales)) as u64,
        });
        Ok(())
    }

    /// Frees single scattering's buffers.
    pub fn detach_single(&mut self) {
        self.single = None;
    }

    /// Whether single scattering is resident (`attach_single`).
    pub fn has_single(&self) -> bool {
        self.single.is_some()
    }

    /// Bytes of single scattering's transport on the GPU.
    pub fn single_bytes(&self) -> Option<u64> {
        self.single.as_ref().map(|s| s.bytes)
    }

    /// B per vertex for coefficients `[3][stride]` (colour already folded in).
    pub fn dot(&self, coefficients: &[f32]) -> Result<(Vec<[f32; 3]>, GpuTimings)> {
        self.evaluate(coefficients, None).map(|(b, _, t)| (b, t))
    }

    /// B per vertex for coefficients `[3][stride]` and, with `single`, L^(1) per vertex too:
    /// both kernels in one submission, both results read back after one wait.
    #[allow(clippy::type_complexity)]
    pub fn evaluate(
        &self,
        coefficients: &[f32],
        single: Option<&SingleEdit>,
    ) -> Result<(Vec<[f32; 3]>, Option<Vec<[f32; 3]>>, GpuTimings)> {
        if coefficients.len() != 3 * self.stride {
            return Err(Error::InvalidArgument(format!(
                "{} coefficients for a stride of {}",
                coefficients.len(),
                self.stride
            )));
        }
        let resident = match single {
            Some(edit) => {
                let r = self.single.as_ref().ok_or_else(|| {
                    Error::InvalidArgument("no single scattering on the GPU".into())
                })?;
                if edit.coefficients.len() != 3 * r.n {
                    return Err(Error::InvalidArgument(format!(
                        "{} single-scattering coefficients for {} basis functions",
                        edit.coefficients.len(),
                        r.n
                    )));
                }
                Some((r, edit))
            }
            None => None,
        };
        let mut t = GpuTimings::default();
        let t0 = Instant::now();
        self.queue
            .write_buffer(&self.coefficients, 0, bytemuck::cast_slice(coefficients));
        if let Some((r, edit)) = resident {
            let eye = edit.eye.unwrap_or([0.0; 3]);
            // Eddington is exact at order 1; HG takes every stored order.
            let order = if edit.henyey_greenstein {
                r.order
            } else {
                r.order.min(1)
            };
            let params: [u32; 20] = [
                self.vertices as u32,
                r.groups as u32,
                r.n as u32,
                r.run as u32,
                u32::from(edit.henyey_greenstein),
                u32::from(edit.eye.is_some()),
                edit.g.to_bits(),
                edit.eta.to_bits(),
                eye[0].to_bits(),
                eye[1].to_bits(),
                eye[2].to_bits(),
                0,
                edit.sigma_s[0].to_bits(),
                edit.sigma_s[1].to_bits(),
                edit.sigma_s[2].to_bits(),
                0,
                r.spread_groups as u32,
                ((r.order + 1) * (r.order + 1)) as u32,
                order as u32,
                0,
            ];
            self.queue
                .write_buffer(&r.params, 0, bytemuck::cast_slice(&params));
            self.queue
                .write_buffer(&r.coefficients, 0, bytemuck::cast_slice(&edit.coefficients));
        }
        t.upload = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let groups = self.vertices.div_ceil(64).max(1) as u32;
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            pass.dispatch_workgroups(groups, 1, 1);
            if let Some((r, _)) = resident {
                pass.set_pipeline(&r.pipeline);
                pass.set_bind_group(0, &r.bind_group, &[]);
                pass.dispatch_workgroups(groups, 1, 1);
            }
        }
        encoder.copy_buffer_to_buffer(&self.output, 0, &self.staging, 0, self.staging.size());
        if let Some((r, _)) = resident {
            encoder.copy_buffer_to_buffer(&r.output, 0, &r.staging, 0, r.staging.size());
        }
        self.queue.submit(Some(encoder.finish()));
        let (tx, rx) = std::sync::mpsc::channel();
        let mut stagings = vec![&self.staging];
        if let Some((r, _)) = resident {
            stagings.push(&r.staging);
        }
        for (k, staging) in stagings.iter().enumerate() {
            let tx = tx.clone();
            staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send((k, r));
            });
        }
        drop(tx);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::GpuUnavailable(format!("device poll failed: {e}")))?;
        for _ in 0..stagings.len() {
            rx.recv()
                .map_err(|e| Error::GpuUnavailable(format!("readback lost: {e}")))?
                .1
                .map_err(|e| Error::GpuUnavailable(format!("readback failed: {e}")))?;
        }
        t.dispatch = t1.elapsed().as_secs_f64();
        let t2 = Instant::now();
        let mut results = Vec::with_capacity(stagings.len());
        for staging in &stagings {
            let out = {
                let view = staging
                    .slice(..)
                    .get_mapped_range()
                    .map_err(|e| Error::GpuUnavailable(format!("mapping failed: {e}")))?;
                let floats: &[f32] = bytemuck::cast_slice(&view);
                floats[..self.vertices * 3]
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect::<Vec<[f32; 3]>>()
            };
            staging.unmap();
            results.push(out);
        }
        t.readback = t2.elapsed().as_secs_f64();
        let single_out = if results.len() > 1 {
            results.pop()
        } else {
            None
        };
        let b = results.pop().unwrap_or_default();
        Ok((b, single_out, t))
    }
}

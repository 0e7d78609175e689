//! Pass 3 of Shah, Konttinen and Pattanaik 2009 on a wgpu render pipeline (`splat.wgsl`): every
//! splat drawn as a quad over the pixels it can reach, its R(|x_o - x_i|) E_i dA_i added into
//! each receiver pixel of its own object by additive blending. The receivers (pass 2's
//! position and object-ID target) are uploaded from the camera's view (`camera::camera_view`);
//! the splats are the CPU gather's (`receivers::Prepared`: the same groups, taken as their sum
//! where a receiver is far from them, and the same near-zone disc means), so the GPU draws the
//! same sum the CPU gathers, in f32.
//!
//! The accumulation target is `Rgba32Float`, which needs the adapter's float-32 blending
//! (`Features::FLOAT32_BLENDABLE`; desktop Vulkan drivers and lavapipe have it). Every adapter
//! blends `Rgba16Float`, but a half float keeps 11 bits: each of the thousands of splats a
//! pixel sums is rounded to 2^-11 of the running sum, and the image is off by up to
//! `HALF_LOSS`. So half floats are used only when asked for (`half`), and an adapter without
//! float-32 blending is refused otherwise (the CPU gather stays); each render says which target
//! it used.

use super::camera::{Camera, PixelHit};
use super::receivers::{disc_mean, Prepared, DISC_NODES, NEAR_DISCS};
use crate::error::{Error, Result};
use crate::gpu::{adapter, AdapterDescription};
use crate::profiles::LookupRgb;
use crate::progress::{ProgressFn, Ticker};
use crate::quadrature::gauss_legendre;
use rayon::prelude::*;
use std::time::Instant;
use wgpu::util::DeviceExt;

/// What half-float targets cost, measured (`tests::gpu`: two 10 mm marble spheres, grid 128,
/// 48 x 32 pixels, against float 32): the worst pixel's error relative to the brightest.
pub const HALF_LOSS: &str = "16 % of the brightest pixel";
/// Intervals of the near table across d / a in [0, `NEAR_DISCS`].
pub const NEAR_INTERVALS: u32 = 512;
/// Radii of the near table per octave of the splats' disc radii (linear in log a between).
pub const NEAR_PER_OCTAVE: f64 = 16.0;
/// Quads per submission: progress and cancel are checked between batches.
const BATCH: usize = 1 << 16;
/// Object IDs travel as f32 (exact below 2^24).
const MAX_OBJECT: u32 = 1 << 24;

/// One quad: a splat, or a group's sum (radius < 0).
#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Quad {
    position_radius: [f32; 4],
    power_object: [f32; 4],
    centre_near: [f32; 4],
    rect: [f32; 4],
}

#[repr(C)]
#[derive(Debug, Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    size: [f32; 2],
    far_scale: f32,
    far_last: u32,
    reach: f32,
    search: f32,
    near_discs: f32,
    near_j: u32,
    near_k: u32,
    log_lo: f32,
    log_step: f32,
    pad: f32,
}

/// What one GPU splatting pass did.
#[derive(Debug, Clone, PartialEq)]
pub struct GpuPassReport {
    pub adapter: AdapterDescription,
    /// "Rgba32Float" or "Rgba16Float" (no float-32 blending on the adapter, or asked for).
    pub target: &'static str,
    /// Quads drawn: groups' sums and single splats.
    pub groups: usize,
    pub splats: usize,
    /// Quads whose rectangle misses the image (not drawn).
    pub culled: usize,
    /// Building the quads and the near table, and uploading them with the receivers [s].
    pub seconds_upload: f64,
    /// The draws, to the GPU's finish [s].
    pub seconds_draw: f64,
    pub seconds_readback: f64,
}

/// A wgpu device with the splatting's pipeline, kept between renders.
pub struct GpuSplatter {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    format: wgpu::TextureFormat,
    adapter: AdapterDescription,
}

impl std::fmt::Debug for GpuSplatter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSplatter")
            .field("adapter", &self.adapter)
            .field("format", &self.format)
            .finish()
    }
}

fn gpu_err(what: &str) -> impl Fn(String) -> Error + '_ {
    move |e| Error::GpuUnavailable(format!("{what}: {e}"))
}

impl GpuSplatter {
    /// The first adapter (`crate::gpu::adapter`; lavapipe only with `allow_software`), with a
    /// float-32 target where it blends one and `half` does not ask for half floats.
    pub fn new(allow_software: bool, half: bool) -> Result<GpuSplatter> {
        let (adapter, description) = adapter(allow_software)?;
        if !half
            && !adapter
                .features()
                .contains(wgpu::Features::FLOAT32_BLENDABLE)
        {
            return Err(Error::GpuUnavailable(format!(
                "{} cannot blend float-32 targets (FLOAT32_BLENDABLE); half floats are \
                 {HALF_LOSS} off at worst on a test scene, so they are used only when asked for",
                description.name
            )));
        }
        let full = !half;
        let format = if full {
            wgpu::TextureFormat::Rgba32Float
        } else {
            wgpu::TextureFormat::Rgba16Float
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("translucent splat"),
            required_features: if full {
                wgpu::Features::FLOAT32_BLENDABLE
            } else {
                wgpu::Features::empty()
            },
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| gpu_err("request_device failed")(e.to_string()))?;
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("splat"),
            source: wgpu::ShaderSource::Wgsl(include_str!("splat.wgsl").into()),
        });
        let visible = wgpu::ShaderStages::VERTEX_FRAGMENT;
        let storage = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: visible,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("splat"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: visible,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: visible,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                storage(2),
                storage(3),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("splat"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let add = wgpu::BlendComponent {
            src_factor: wgpu::BlendFactor::One,
            dst_factor: wgpu::BlendFactor::One,
            operation: wgpu::BlendOperation::Add,
        };
        let attributes = wgpu::vertex_attr_array![
            0 => Float32x4, 1 => Float32x4, 2 => Float32x4, 3 => Float32x4
        ];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("splat"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<Quad>() as u64,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &attributes,
                })],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: wgpu::MultisampleState::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::ColorTargetState {
                    format,
                    blend: Some(wgpu::BlendState {
                        color: add,
                        alpha: add,
                    }),
                    write_mask: wgpu::ColorWrites::ALL,
                })],
            }),
            multiview_mask: None,
            cache: None,
        });
        Ok(GpuSplatter {
            device,
            queue,
            pipeline,
            layout,
            format,
            adapter: description,
        })
    }

    pub fn adapter(&self) -> &AdapterDescription {
        &self.adapter
    }

    /// "Rgba32Float" or "Rgba16Float".
    pub fn target(&self) -> &'static str {
        match self.format {
            wgpu::TextureFormat::Rgba32Float => "Rgba32Float",
            _ => "Rgba16Float",
        }
    }

    /// B at each of `hits` (pixels of `camera`'s image) from the `prepared` splats of
    /// `profile`, drawn on the GPU; `progress` from `from` to `to` per batch of quads, false
    /// cancels (`Error::Cancelled`). Errors: an image larger than the adapter's textures, an
    /// object ID of 2^24 or more (`Error::GpuUnavailable` / `Error::InvalidArgument`).
    pub fn splat(
        &self,
        prepared: &Prepared,
        profile: &LookupRgb,
        camera: &Camera,
        hits: &[PixelHit],
        progress: Option<&ProgressFn>,
        (from, to): (f32, f32),
    ) -> Result<(Vec<[f64; 3]>, GpuPassReport)> {
        let (width, height) = (camera.width(), camera.height());
        let side = self.device.limits().max_texture_dimension_2d;
        if width > side || height > side {
            return Err(Error::GpuUnavailable(format!(
                "an image of {width} x {height} exceeds the adapter's largest texture side \
                 ({side})"
            )));
        }
        if hits.iter().any(|h| h.object >= MAX_OBJECT) {
            return Err(Error::InvalidArgument(format!(
                "object IDs of {MAX_OBJECT} or more cannot be splatted on the GPU"
            )));
        }
        let t0 = Instant::now();
        // The powers are drawn times `unit`, which puts the brightest irradiance E = E dA / dA at
        // 1, so that half floats hold the sums at full precision, not in their subnormals.
        let unit = unit(prepared);
        let (quads, groups, culled) = quads(prepared, camera, unit as f32);
        let splats = quads.len() - groups;
        let (near, near_params) = near_table(profile, prepared);
        let (nodes, scale, _) = profile.f32_table();
        let params = Params {
            size: [width as f32, height as f32],
            far_scale: scale as f32,
            far_last: (nodes.len() - 2) as u32,
            reach: prepared.reach as f32,
            search: prepared.search as f32,
            near_discs: NEAR_DISCS as f32,
            near_j: NEAR_INTERVALS,
            near_k: near_params.0,
            log_lo: near_params.1,
            log_step: near_params.2,
            pad: 0.0,
        };
        let init = |label: &str, contents: &[u8], usage| {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents,
                    usage,
                })
        };
        use wgpu::BufferUsages as U;
        let params = init("params", bytemuck::bytes_of(&params), U::UNIFORM);
        let far = init("far", bytemuck::cast_slice(nodes), U::STORAGE);
        let near = init("near", bytemuck::cast_slice(&near), U::STORAGE);
        // Pass 2's target: x_o and its object + 1 (0: no receiver).
        let mut texels = vec![[0.0f32; 4]; camera.pixels()];
        for h in hits {
            let p = h.position;
            texels[h.pixel as usize] = [p.x, p.y, p.z, (h.object + 1) as f32];
        }
        let extent = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let gbuffer = self.device.create_texture_with_data(
            &self.queue,
            &wgpu::TextureDescriptor {
                label: Some("receivers"),
                size: extent,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(&texels),
        );
        let target = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("radiosity"),
            size: extent,
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: self.format,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = target.create_view(&Default::default());
        let gview = gbuffer.create_view(&Default::default());
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        let bind = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat"),
            layout: &self.layout,
            entries: &[
                entry(0, params.as_entire_binding()),
                entry(1, wgpu::BindingResource::TextureView(&gview)),
                entry(2, far.as_entire_binding()),
                entry(3, near.as_entire_binding()),
            ],
        });
        let batch_bytes = (BATCH.min(quads.len().max(1)) * std::mem::size_of::<Quad>()) as u64;
        let instances = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("quads"),
            size: batch_bytes,
            usage: U::VERTEX | U::COPY_DST,
            mapped_at_creation: false,
        });
        let seconds_upload = t0.elapsed().as_secs_f64();

        let t1 = Instant::now();
        let ticker = Ticker::span(progress, quads.len().max(1) as u64, from, to);
        let wait = || {
            self.device
                .poll(wgpu::PollType::wait_indefinitely())
                .map(|_| ())
                .map_err(|e| gpu_err("device poll failed")(e.to_string()))
        };
        let mut first = true;
        let mut batches = quads.chunks(BATCH).peekable();
        if batches.peek().is_none() {
            self.clear(&view);
        }
        for batch in batches {
            self.queue
                .write_buffer(&instances, 0, bytemuck::cast_slice(batch));
            let mut encoder = self.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: Some("splat"),
                    color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                        view: &view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: if first {
                                wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT)
                            } else {
                                wgpu::LoadOp::Load
                            },
                            store: wgpu::StoreOp::Store,
                        },
                    })],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.set_vertex_buffer(0, instances.slice(..));
                pass.draw(0..6, 0..batch.len() as u32);
            }
            self.queue.submit(Some(encoder.finish()));
            wait()?;
            first = false;
            if !ticker.add(batch.len() as u64) {
                return Err(Error::Cancelled);
            }
        }
        let seconds_draw = t1.elapsed().as_secs_f64();

        let t2 = Instant::now();
        let texel = if self.format == wgpu::TextureFormat::Rgba32Float {
            16
        } else {
            8
        };
        let row = (width * texel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let staging = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(row) * u64::from(height),
            usage: U::MAP_READ | U::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            target.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &staging,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            extent,
        );
        self.queue.submit(Some(encoder.finish()));
        let (tx, rx) = std::sync::mpsc::channel();
        staging
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |r| drop(tx.send(r)));
        wait()?;
        rx.recv()
            .map_err(|e| gpu_err("readback lost")(e.to_string()))?
            .map_err(|e| gpu_err("readback failed")(e.to_string()))?;
        let out = {
            let bytes = staging
                .slice(..)
                .get_mapped_range()
                .map_err(|e| gpu_err("mapping failed")(e.to_string()))?;
            let at = |pixel: u32| {
                let (x, y) = (pixel % width, pixel / width);
                (y * row + x * texel) as usize
            };
            hits.iter()
                .map(|h| {
                    let o = at(h.pixel);
                    std::array::from_fn(|c| {
                        let v = if texel == 16 {
                            let b = &bytes[o + 4 * c..o + 4 * c + 4];
                            f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                        } else {
                            let b = &bytes[o + 2 * c..o + 2 * c + 2];
                            f64::from(half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                        };
                        v / unit
                    })
                })
                .collect()
        };
        staging.unmap();
        Ok((
            out,
            GpuPassReport {
                adapter: self.adapter.clone(),
                target: self.target(),
                groups,
                splats,
                culled,
                seconds_upload,
                seconds_draw,
                seconds_readback: t2.elapsed().as_secs_f64(),
            },
        ))
    }

    /// Clears `view` (a render with nothing to splat).
    fn clear(&self, view: &wgpu::TextureView) {
        let mut encoder = self.device.create_command_encoder(&Default::default());
        drop(encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("clear"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        }));
        self.queue.submit(Some(encoder.finish()));
    }
}

/// The quads of `prepared` in `camera`'s image: per group its sum (over the receivers at least
/// its near distance from it, out to the reach) and each of its splats (over the receivers
/// nearer, out to the search radius); with how many are groups' sums and how many missed the
/// image.
fn quads(prepared: &Prepared, camera: &Camera, unit: f32) -> (Vec<Quad>, usize, usize) {
    let (reach, search) = (prepared.reach as f32, prepared.search as f32);
    let groups: Vec<_> = prepared.groups().collect();
    let per_group: Vec<(Vec<Quad>, bool, usize)> = groups
        .par_iter()
        .map(|(g, splats)| {
            let object = g.object as f32;
            let power = |p: [f32; 3]| [p[0] * unit, p[1] * unit, p[2] * unit, object];
            let centre_near = [g.centre.x, g.centre.y, g.centre.z, g.near];
            let mut out = Vec::with_capacity(splats.len() + 1);
            let mut culled = 0;
            let sum = camera.sphere_rect(g.centroid, reach).map(|rect| Quad {
                position_radius: [g.centroid.x, g.centroid.y, g.centroid.z, -1.0],
                power_object: power(g.power),
                centre_near,
                rect,
            });
            let has_sum = sum.is_some();
            out.extend(sum);
            culled += usize::from(!has_sum);
            for s in *splats {
                // Drawn only where the receiver lies within the group's near distance.
                let r = search.min(g.near + (s.position - g.centre).length());
                match camera.sphere_rect(s.position, r) {
                    Some(rect) => out.push(Quad {
                        position_radius: [s.position.x, s.position.y, s.position.z, s.radius],
                        power_object: power(s.power),
                        centre_near,
                        rect,
                    }),
                    None => culled += 1,
                }
            }
            (out, has_sum, culled)
        })
        .collect();
    let sums = per_group.iter().filter(|(_, s, _)| *s).count();
    let culled = per_group.iter().map(|(_, _, c)| c).sum();
    let quads = per_group.into_iter().flat_map(|(q, _, _)| q).collect();
    (quads, sums, culled)
}

/// 1 / the brightest irradiance of a splat with a disc (E dA / pi a^2), or 1 / the largest
/// power where none has one: B is then of order 1.
fn unit(prepared: &Prepared) -> f64 {
    let (mut e, mut p) = (0.0f64, 0.0f64);
    for (_, splats) in prepared.groups() {
        for s in splats {
            let most = f64::from(s.power.iter().cloned().fold(0.0, f32::max));
            p = p.max(most);
            if s.radius > 0.0 {
                e = e.max(most / (std::f64::consts::PI * f64::from(s.radius).powi(2)));
            }
        }
    }
    let top = if e > 0.0 { e } else { p };
    if top > 0.0 && top.is_finite() {
        1.0 / top
    } else {
        1.0
    }
}

/// The near table: for radii a_k geometric over `radii` (`NEAR_PER_OCTAVE` an octave) and
/// d_j = (j / `NEAR_INTERVALS`) `NEAR_DISCS` a_k, the disc mean (`receivers::disc_mean`) times
/// the near zone's factor the CPU gather gives splats of that radius (`Prepared::near_scale`),
/// row k after row; with (radii, log a_0, the step in log a). A single unused row where no
/// splat has a disc.
fn near_table(profile: &LookupRgb, prepared: &Prepared) -> (Vec<[f32; 4]>, (u32, f32, f32)) {
    let rows = NEAR_INTERVALS as usize + 1;
    let Some((lo, hi)) = prepared.radii else {
        return (vec![[0.0; 4]; rows], (1, 0.0, 1.0));
    };
    let (log_lo, log_hi) = (lo.ln(), hi.max(lo).ln());
    let k = ((log_hi - log_lo) / std::f64::consts::LN_2 * NEAR_PER_OCTAVE).ceil() as usize + 1;
    let step = if k > 1 {
        (log_hi - log_lo) / (k - 1) as f64
    } else {
        1.0
    };
    let rule = gauss_legendre(DISC_NODES);
    let table: Vec<[f32; 4]> = (0..k)
        .into_par_iter()
        .flat_map_iter(|row| {
            let a = (log_lo + step * row as f64).exp();
            let scale = prepared.near_scale(a);
            (0..rows).map(move |j| {
                let d = j as f64 / NEAR_INTERVALS as f64 * NEAR_DISCS * a;
                let m = disc_mean(profile, d, a, rule);
                [
                    (m[0] * scale[0]) as f32,
                    (m[1] * scale[1]) as f32,
                    (m[2] * scale[2]) as f32,
                    0.0,
                ]
            })
        })
        .collect();
    (table, (k as u32, log_lo as f32, step as f32))
}

//! Image-space splatting after Shah, Konttinen and Pattanaik 2009 (*Image-space subsurface
//! scattering for interactive rendering of deformable translucent objects*): nothing is
//! precomputed, so a deformed mesh, a moved light or an edited material costs one evaluation.
//! Pass 1 finds the splat sources x_i from each light's view (`light_view`), the splat size and
//! count follow from the profile (`sizes`: r_max by eq. 4, n_o by eq. 5, n = (1/2) n_o W /
//! r_max), and each vertex gathers R(|x_o - x_i|) E_i dA_i from the splats within r_max of it
//! and of its own object (`receivers`, the compute variant of pass 3; "Rendering Multiple
//! Objects").
//!
//! B is the quantity `reference::reference_radiosity` integrates (any profile of `profiles`),
//! plus the profile's point mass times the vertex's own irradiance. Suns, point and spot lights
//! are splatted from their own views; the world, area lights and point lights inside the
//! mesh's bounding sphere from the whole surface, found by depth peeling (`peel`, Shah's
//! §Environment Lighting). The light the rest of the scene sends back is not yet, and each
//! evaluation says so in `skipped`.
//!
//! Where the paper is not followed to the letter: eq. 5's grid is far beyond any budget and is
//! capped (`sizes`); the pass-1 "render" is a ray cast per cell on the CPU (`light_view`); near
//! a splat a vertex reads the profile's mean over the splat's patch, not its value at the
//! centre (`receivers`).

pub mod camera;
mod colored;
pub mod estimate;
pub mod gpu;
pub mod light_view;
pub mod peel;
pub mod receivers;
pub mod reuse;
pub mod sizes;
#[cfg(test)]
mod tests;

use crate::error::{Error, Result};
use crate::evaluation::{check_eye, Quantity, Skipped};
use crate::irradiance::{
    irradiance as irradiance_of_scene, irradiance_of_linked_sources, IrradianceSettings,
};
use crate::lights::{Light, World};
use crate::occluders::Occluders;
use crate::optics::Material;
use crate::profiles::{LookupProfile, LookupRgb, ProfileKind, RadialProfile, Resolved};
use crate::progress::{ProgressFn, Ticker};
use crate::raytrace::Tracer;
use crate::scene::{Linking, Scene};
use crate::surface_terms::{self, TermReport, TermSettings, Terms};
use camera::{camera_view, Camera, PixelHit};
use glam::Vec3;
use gpu::{GpuPassReport, GpuSplatter};
use light_view::{light_samples, BoundingSphere, View, ViewCounts};
use peel::{peeled_samples, PeelCounts};
use receivers::{gather, Prepared, Splat};
use reuse::{Reuse, ReuseCounts};
use sizes::{Sizes, Spread};
use std::sync::Mutex;
use std::time::Instant;

use estimate::EstimateReport;
pub use estimate::DEFAULT_ESTIMATE_RECEIVERS;
pub use peel::DEFAULT_PEEL_GRID;
pub use sizes::{DEFAULT_EPS, DEFAULT_MAX_GRID, MAX_GRID};

/// One material evaluated by the splatting (`evaluation::Evaluation`), with its report.
pub type Evaluation = crate::evaluation::Evaluation<SplatReport>;

/// What the walks' term and own light add to B per vertex, and their report (`Splatting::layer`).
type Layer = (Vec<[f32; 3]>, TermReport);

/// Adds a layer (`Layer`: signed, what the walks take away too) to B per vertex, B floored at 0.
fn add_layer(b: &mut [[f32; 3]], layer: &[[f32; 3]]) {
    for (x, a) in b.iter_mut().zip(layer) {
        *x = std::array::from_fn(|c| (x[c] + a[c]).max(0.0));
    }
}

/// The splatting's two knobs (Shah 2009 "Algorithm Implementation Steps").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SplatSettings {
    /// The threshold of eqs. 4 and 5, in (0, 1): the share of each splat's light left beyond
    /// r_max, and Weber's fraction for the overlap.
    pub eps: f64,
    /// The largest side of a light's grid, in [1, `MAX_GRID`]: eq. 5's grid is cut to it (and
    /// the cut reported).
    pub max_grid: u32,
    /// The largest side of each of the three peeled views' grids (`peel`: the world, area
    /// lights, point lights no frustum holds), in [1, `MAX_GRID`]; `max_grid` where that is
    /// smaller.
    pub peel_grid: u32,
    /// The vertices the error estimate reads the ground truth at (`estimate`); 0: none.
    pub estimate_receivers: usize,
}

/// The most vertices an error estimate may read the ground truth at.
pub const MAX_ESTIMATE_RECEIVERS: usize = 4096;

impl Default for SplatSettings {
    fn default() -> Self {
        Self {
            eps: DEFAULT_EPS,
            max_grid: DEFAULT_MAX_GRID,
            peel_grid: DEFAULT_PEEL_GRID,
            estimate_receivers: DEFAULT_ESTIMATE_RECEIVERS,
        }
    }
}

impl SplatSettings {
    /// Errors: `eps`, `max_grid`, `peel_grid` or `estimate_receivers` out of range
    /// (`Error::InvalidArgument`, naming it).
    pub fn check(&self) -> Result<()> {
        sizes::check_eps(self.eps)?;
        sizes::check_max_grid(self.max_grid)?;
        if !(1..=MAX_GRID).contains(&self.peel_grid) {
            return Err(Error::InvalidArgument(format!(
                "peel_grid = {}: each peeled view's side must lie in [1, {MAX_GRID}] (3 x \
                 {MAX_GRID}^2 rays at most)",
                self.peel_grid
            )));
        }
        if self.estimate_receivers > MAX_ESTIMATE_RECEIVERS {
            return Err(Error::InvalidArgument(format!(
                "estimate_receivers = {}: at most {MAX_ESTIMATE_RECEIVERS} vertices (the ground \
                 truth at each costs about a tenth of a second)",
                self.estimate_receivers
            )));
        }
        Ok(())
    }
}

/// The peeled splat sources (`peel`, Shah's §Environment Lighting): which sources lit them,
/// the grid and what was found.
#[derive(Debug, Clone, PartialEq)]
pub struct PeelReport {
    /// The scene's lights lit this way (their indices), each with why no light view holds it.
    pub lights: Vec<(usize, String)>,
    /// Whether the world lit them.
    pub world: bool,
    /// Whether the rest of the scene's bounce lit them: every source's light sent back off the
    /// occluders (`Occluders::bouncing`), the light views' included.
    pub bounce: bool,
    pub sizes: Sizes,
    pub counts: PeelCounts,
    pub seconds: f64,
}

/// The `Splat::light` of the peeled splats: no light index (groups never mix it with a light's).
pub const PEELED: u32 = u32::MAX;

/// One light's view: how it was looked through and what it found.
#[derive(Debug, Clone, PartialEq)]
pub struct LightReport {
    /// The light's index in `Scene::lights`.
    pub light: usize,
    pub kind: &'static str,
    /// "orthographic" (a sun) or "perspective".
    pub projection: &'static str,
    /// The frustum's width W [unit].
    pub width: f64,
    pub sizes: Sizes,
    /// W / grid: the splats' spacing across the light (at the bounding sphere's centre for a
    /// point or spot) [unit]. Where it exceeds the profile's near length (the dipole's z_r),
    /// the cap, not eq. 5, sets the accuracy: on a plane of marble (z_r = 0.33-0.46 mm) splats
    /// 0.26 mm apart along the slant gave -0.02 %, 0.51 mm apart -0.16 to -0.77 %; Cycles'
    /// profile, rising as 1/r at the entry, wants it finer still (`tests::method`).
    pub spacing: f64,
    pub counts: ViewCounts,
    /// What the reuse of earlier frames' samples did (`reuse`), where it is on.
    pub reuse: Option<ReuseCounts>,
    pub seconds: f64,
}

/// What the splatting did.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SplatReport {
    pub eps: f64,
    /// Each channel's splat radius (eq. 4) [unit]; 0 where it does not diffuse.
    pub r_max: [f64; 3],
    /// Each channel's overlap n_o (eq. 5); 0 where it does not diffuse.
    pub overlap: [u64; 3],
    /// The lights splatted, in scene order.
    pub lights: Vec<LightReport>,
    /// Splats in all (light-view samples where light enters).
    pub splats: usize,
    /// Pass 1: the lights' views.
    pub seconds_light_view: f64,
    /// The gather at the vertices (with the splats' binning).
    pub seconds_splat: f64,
    /// The point mass's irradiance at the vertices (0 where the profile has none).
    pub seconds_point_mass: f64,
    /// Pass 2, a render only: the camera's view (0 at the vertices).
    pub seconds_camera_view: f64,
    /// Pixels that see the mesh, a render only (0 at the vertices).
    pub pixels: usize,
    /// The walks' term and the object's own light, where they are on (`Splatting::with_walks`).
    pub terms: Option<TermReport>,
    /// A render whose pass 3 ran on the GPU (`gpu`): the adapter, target and quads; None on
    /// the CPU.
    pub gpu: Option<GpuPassReport>,
    /// The peeled sources (the world, area lights, point lights inside the bounding sphere),
    /// where the scene has any.
    pub peel: Option<PeelReport>,
    /// What the error estimate cost (`estimate`), where one was computed.
    pub estimate: Option<EstimateReport>,
}

fn light_kind(light: &Light) -> &'static str {
    match light {
        Light::Sun { .. } => "sun",
        Light::Point { .. } => "point",
        Light::Spot { .. } => "spot",
        Light::Area { .. } => "area",
        Light::Mesh(_) => "emissive mesh",
    }
}

/// Calls `progress` with `f` (a stage boundary); false is `Error::Cancelled`.
fn tick(progress: Option<&ProgressFn>, f: f32) -> Result<()> {
    match progress {
        Some(p) if !p(f) => Err(Error::Cancelled),
        _ => Ok(()),
    }
}

/// How each source of `scene` is splatted: the lights seen through a view of their own, the
/// lights peeled (`peel`: no single frustum holds them) with the reason, and what is left out.
struct Plan {
    views: Vec<(usize, View)>,
    peeled: Vec<(usize, String)>,
    skipped: Vec<Skipped>,
}

/// `bounce`: the box of the rest of the scene that sends light back, where some does.
fn plan(scene: &Scene, sphere: &BoundingSphere, bounce: Option<(Vec3, Vec3)>) -> Plan {
    let mut skipped = vec![
        Skipped::new(
            "walks through the mesh",
            "the splatting sums the radial profile (Shah 2009): walks off",
        ),
        Skipped::new(
            "the object's own light",
            "the splatting gathers the direct light only",
        ),
    ];
    let (lo, hi) = scene.mesh.bounds();
    let mut views = Vec::new();
    let mut peeled = Vec::new();
    for (k, light) in scene.lights.iter().enumerate() {
        let what = format!("light {k} ({})", light_kind(light));
        if light.is_black() {
            skipped.push(Skipped::new(what, "it emits nothing"));
        } else if !light.can_reach(lo, hi) {
            if bounce.is_some_and(|(blo, bhi)| light.can_reach(blo, bhi)) {
                peeled.push((
                    k,
                    "it reaches the mesh by the rest of the scene's bounce alone".to_string(),
                ));
            } else {
                skipped.push(Skipped::new(what, "it cannot reach the mesh"));
            }
        } else {
            match View::for_light(light, sphere) {
                Ok(view) => views.push((k, view)),
                Err(why) => peeled.push((k, why)),
            }
        }
    }
    Plan {
        views,
        peeled,
        skipped,
    }
}

/// Pass 1's result: the splats of every light splatted, with what the receivers need.
struct Sources {
    splats: Vec<Splat>,
    /// The lights splatted and the world where it is peeled (what the point mass's irradiance
    /// is taken from), each light with its light and shadow linking (`Scene::linking_of`).
    used: Vec<Light>,
    links: Vec<Option<Linking>>,
    world: World,
    /// The mesh and the occluders that can shadow it from those lights.
    tracer: Tracer,
    /// The mesh alone, for the camera to add every occluder to.
    mesh_tracer: Tracer,
    /// The mesh's box.
    bounds: (Vec3, Vec3),
    report: SplatReport,
    skipped: Vec<Skipped>,
}

/// What a frame may use beyond the scene: a GPU for pass 3 of a render, and the samples kept
/// from earlier frames (`reuse`, Shah's sampling coherence).
#[derive(Clone, Copy, Default)]
pub struct Passes<'a> {
    pub gpu: Option<&'a GpuSplatter>,
    pub reuse: Option<&'a Mutex<Reuse>>,
    /// B is gathered at the estimate's vertices (`Render::at_vertices`) but not read against
    /// the ground truth: the caller estimates (`colored`: against each vertex's own medium).
    pub no_truth: bool,
}

/// Pass 1: each light's view of `scene.mesh` (`progress` from `from` to `to`, per row of rays),
/// merged with the samples kept from earlier frames where `reuse` is given.
fn sources(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    reuse: Option<&Mutex<Reuse>>,
    progress: Option<&ProgressFn>,
    (from, to): (f32, f32),
) -> Result<Sources> {
    settings.check()?;
    let eta = resolved.irradiance_eta();
    let spreads: [Option<Spread>; 3] = sizes::spreads(&resolved.profiles, settings.eps)?;
    tick(progress, from)?;
    let mesh = &scene.mesh;
    let sphere = BoundingSphere::of(mesh);
    // The rest of the scene's bounce (every occluder with its albedo) rides on the tracer: the
    // peeled crossings gather it, as the world's light, for every source.
    let mesh_tracer = Tracer::new(mesh).with_bounce(scene.occluders.bouncing());
    let Plan {
        views,
        peeled,
        mut skipped,
    } = plan(scene, &sphere, mesh_tracer.bounce_bounds());
    let order: Vec<usize> = (views.iter().map(|(k, _)| *k))
        .chain(peeled.iter().map(|(k, _)| *k))
        .collect();
    let used: Vec<Light> = order.iter().map(|&k| scene.lights[k].clone()).collect();
    let links: Vec<Option<Linking>> = order.iter().map(|&k| scene.linking_of(k)).collect();
    let world = scene.world.clone();
    // The rest of the scene that can shadow the mesh from the lights splatted and the world.
    let (kept, _) = (scene.occluders).relevant(mesh.bounds(), &used, &world);
    let tracer = mesh_tracer.with_occluders(&kept);
    // The light views' own light is splatted from their views; what they send back off the
    // rest of the scene reaches the mesh from every side, so the peeled crossings gather it.
    let views_bounce = tracer.bounces() && !views.is_empty();
    let mut report = SplatReport {
        eps: settings.eps,
        r_max: spreads.map(|s| s.map_or(0.0, |s| s.r_max)),
        overlap: spreads.map(|s| s.map_or(0, |s| s.overlap)),
        ..Default::default()
    };
    let t = Instant::now();
    let planned: Vec<Sizes> = (views.iter())
        .map(|(_, v)| Sizes::from_spreads(&spreads, v.width(), settings.max_grid))
        .collect::<Result<_>>()?;
    let rays: u64 = planned.iter().map(|s| u64::from(s.grid).pow(2)).sum();
    // The peeled views take the rest of the stage, if there are any.
    let peel_from = if peeled.is_empty() && world.is_black() && !views_bounce {
        to
    } else {
        from + 0.5 * (to - from)
    };
    let ticker = Ticker::span(progress, rays, from, peel_from);
    let mut splats = Vec::new();
    for ((k, view), sizes) in views.iter().zip(planned) {
        let light = &scene.lights[*k];
        let t_light = Instant::now();
        // Light and shadow linking: what this light lights and what casts its shadows.
        let linked = tracer.linked(scene.linking_of(*k));
        let (s, counts) =
            light_samples(view, light, mesh, &linked, sizes.grid, eta, Some(&ticker))?;
        let (s, reused) = match reuse {
            Some(r) => {
                let mut r = r.lock().unwrap_or_else(|e| e.into_inner());
                let (s, c) = r.merge(*k, sizes.grid, light, mesh, &linked, eta, (view, s));
                (s, Some(c))
            }
            None => (s, None),
        };
        if s.is_empty() && sizes.grid > 0 {
            skipped.push(Skipped::new(
                format!("light {k} ({})", light_kind(light)),
                "it reaches no point of the mesh: every ray of its view missed, met a back \
                 face, or was shadowed",
            ));
        }
        splats.extend(s.iter().map(|s| Splat {
            light: *k as u32,
            ..Splat::new(s)
        }));
        report.lights.push(LightReport {
            light: *k,
            kind: light_kind(light),
            projection: view.kind(),
            width: view.width(),
            spacing: if sizes.grid > 0 {
                view.width() / f64::from(sizes.grid)
            } else {
                0.0
            },
            sizes,
            counts,
            reuse: reused,
            seconds: t_light.elapsed().as_secs_f64(),
        });
    }
    if peel_from < to {
        let t_peel = Instant::now();
        // Never finer than the light views (`max_grid`, the knob of Shah's Fig. 12).
        let cap = settings.peel_grid.min(settings.max_grid);
        let sizes = Sizes::from_spreads(&spreads, 2.0 * sphere.radius, cap)?;
        let irradiance = IrradianceSettings {
            eta,
            ..Default::default()
        };
        let (s, counts) = peeled_samples(
            mesh,
            (&mesh_tracer, &tracer),
            &sphere,
            sizes.grid,
            ((&used[views.len()..], &links[views.len()..]), &world),
            views_bounce.then_some((&used[..views.len()], &links[..views.len()])),
            &irradiance,
            progress,
            (peel_from, to),
        )?;
        splats.extend(s.iter().map(|s| Splat {
            light: PEELED,
            ..Splat::new(s)
        }));
        report.peel = Some(PeelReport {
            lights: peeled,
            world: !world.is_black(),
            bounce: tracer.bounces(),
            sizes,
            counts,
            seconds: t_peel.elapsed().as_secs_f64(),
        });
    }
    report.seconds_light_view = t.elapsed().as_secs_f64();
    report.splats = splats.len();
    tick(progress, to)?;
    Ok(Sources {
        splats,
        used,
        links,
        world,
        tracer,
        mesh_tracer,
        bounds: mesh.bounds(),
        report,
        skipped,
    })
}

/// Pass 3 and the point mass: B at `points` (with their shading `normals` and `objects`), the
/// splats gathered with R cut at each channel's r_max (`progress` from `from` to `to`, per
/// receiver), plus the profile's point mass times the irradiance there from the lights
/// splatted, as the ground truth adds it. With `on_gpu` (the device, the camera and the pixels
/// the points are) the splats are drawn into those pixels by `gpu::GpuSplatter` instead.
fn radiosity_at(
    src: &mut Sources,
    resolved: &Resolved,
    settings: &SplatSettings,
    (points, normals, objects): (&[Vec3], &[Vec3], &[u32]),
    on_gpu: Option<(&GpuSplatter, &Camera, &[PixelHit])>,
    progress: Option<&ProgressFn>,
    (from, to): (f32, f32),
) -> Result<Vec<[f64; 3]>> {
    let t = Instant::now();
    let table = LookupRgb::new(&std::array::from_fn(|c| {
        LookupProfile::new(&resolved.profiles[c], settings.eps)
    }));
    let receivers: Vec<(Vec3, u32)> = points
        .iter()
        .copied()
        .zip(objects.iter().copied())
        .collect();
    let reach = src.report.r_max.iter().cloned().fold(0.0, f64::max);
    let splats = std::mem::take(&mut src.splats);
    let mut b = match on_gpu {
        Some((gpu, camera, hits)) => match Prepared::new(splats, &table, reach) {
            Some(p) => {
                let (b, r) = gpu.splat(&p, &table, camera, hits, progress, (from, to))?;
                src.report.gpu = Some(r);
                b
            }
            None => vec![[0.0; 3]; receivers.len()],
        },
        None => {
            let ticker = Ticker::span(progress, receivers.len() as u64, from, to);
            gather(splats, &table, reach, &receivers, Some(&ticker))?
        }
    };
    src.report.seconds_splat = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let point: [f64; 3] = std::array::from_fn(|c| resolved.profiles[c].point_mass());
    if point.iter().any(|m| *m > 0.0) && !(src.used.is_empty() && src.world.is_black()) {
        tick(progress, to)?;
        let s = IrradianceSettings {
            eta: resolved.irradiance_eta(),
            ..Default::default()
        };
        let (e, _) = irradiance_of_linked_sources(
            src.bounds,
            (&src.used, &src.links),
            &src.world,
            &src.tracer,
            points,
            normals,
            &s,
            Some(&crate::progress::held_at(progress, to)),
        )?;
        for (bv, ev) in b.iter_mut().zip(&e) {
            for c in 0..3 {
                bv[c] += point[c] * f64::from(ev[c]);
            }
        }
    }
    src.report.seconds_point_mass = t.elapsed().as_secs_f64();
    Ok(b)
}

/// The error estimate of `values`, B at the vertices `at` (`estimate`), with its report in
/// `src`; None, and a skip saying so, where no vertex is asked for.
fn estimated(
    scene: &Scene,
    resolved: &Resolved,
    src: &mut Sources,
    at: &[u32],
    values: &[[f64; 3]],
    progress: Option<&ProgressFn>,
) -> Result<Option<[f64; 3]>> {
    if at.is_empty() {
        src.skipped.push(Skipped::new(
            "error estimate",
            "estimate_receivers = 0: the ground truth is read at no vertex",
        ));
        return Ok(None);
    }
    let sources = (
        (src.used.as_slice(), src.links.as_slice()),
        &src.world,
        &src.tracer,
    );
    let (e, report) = estimate::estimate(scene, resolved, sources, at, values, progress)?;
    src.report.estimate = Some(report);
    Ok(Some(e))
}

/// Radiosity B per vertex of `scene.mesh` for the material `resolved` by splatting, with the
/// shared evaluation's seconds, skips and error estimate (`estimate`). `progress` hears of the
/// light views (the first 45 %, per row of rays) and the gather (to 95 %, per vertex); false
/// cancels (`Error::Cancelled`). Errors: a setting out of range (`SplatSettings::check`).
pub fn splat_radiosity(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    progress: Option<&ProgressFn>,
) -> Result<Evaluation> {
    radiosity_with(scene, resolved, settings, None, progress)
}

/// `splat_radiosity` with the samples kept from earlier frames where `reuse` is given.
fn radiosity_with(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    reuse: Option<&Mutex<Reuse>>,
    progress: Option<&ProgressFn>,
) -> Result<Evaluation> {
    let start = Instant::now();
    let mut src = sources(scene, resolved, settings, reuse, progress, (0.0, 0.45))?;
    let mesh = &scene.mesh;
    let objects: Vec<u32> = (0..mesh.vertex_count())
        .map(|v| mesh.object_of_vertex(v))
        .collect();
    let b = radiosity_at(
        &mut src,
        resolved,
        settings,
        (mesh.positions(), mesh.normals(), &objects),
        None,
        progress,
        (0.45, 0.95),
    )?;
    let at = estimate::receivers(mesh.vertex_count(), settings.estimate_receivers);
    let values: Vec<[f64; 3]> = at.iter().map(|&v| b[v as usize]).collect();
    let error_estimate = estimated(scene, resolved, &mut src, &at, &values, progress)?;
    tick(progress, 1.0)?;
    Ok(Evaluation {
        values: b.iter().map(|v| v.map(|x| x as f32)).collect(),
        quantity: Quantity::Radiosity,
        error_estimate,
        seconds: start.elapsed().as_secs_f64(),
        skipped: src.skipped,
        details: src.report,
    })
}

/// Outgoing radiance per vertex, L = W(cos_o) V(cos_o) B / pi (`evaluation::
/// radiance_from_radiosity`), toward `eye` or along each normal; as `splat_radiosity`
/// otherwise. Errors also on an eye that is not finite.
pub fn splat_radiance(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    eye: Option<Vec3>,
    progress: Option<&ProgressFn>,
) -> Result<Evaluation> {
    check_eye(eye)?;
    let start = Instant::now();
    let mut e = splat_radiosity(scene, resolved, settings, progress)?;
    e.into_radiance(&scene.mesh, eye, &|cos| resolved.exit_weights(cos), start);
    Ok(e)
}

/// The camera's image of the splatting (Shah 2009's passes 2-4): per pixel the radiance the
/// previewed mesh sends toward the eye, L = W(cos_o) B / pi with B gathered at the point the
/// pixel sees (`camera::camera_view`), row-major from the top row; 0 where the pixel sees
/// nothing of the mesh. `mask` holds the object seen plus 1 per pixel (0: none). The
/// evaluation's values are the pixels; its report adds the camera's seconds and pixel count.
pub struct Render {
    pub evaluation: Evaluation,
    pub mask: Vec<u32>,
    pub width: u32,
    pub height: u32,
    /// The pixels that see the previewed mesh: where, on which triangle (a per-vertex input is
    /// interpolated there).
    pub hits: Vec<PixelHit>,
    /// B (half-space, before any layer) at the estimate's vertices
    /// (`estimate::receivers`), in their order.
    pub at_vertices: Vec<[f64; 3]>,
}

/// `Render` of `scene` seen by `camera`. `progress`: the light views to 30 %, the camera view
/// to 40 %, the gather per pixel to 95 %; false cancels (`Error::Cancelled`).
pub fn splat_render(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    camera: &Camera,
    progress: Option<&ProgressFn>,
) -> Result<Render> {
    render_with_layer(
        scene,
        resolved,
        settings,
        camera,
        None,
        Passes::default(),
        progress,
    )
}

/// `splat_render` with `layer` (B per vertex: the walks' term and the object's own light,
/// `surface_terms`) interpolated across each hit triangle and added to the gathered B: the
/// per-vertex layer rasterised in the camera pass (Shah's pass 2 with an extra target). With
/// `passes.gpu`, pass 3 draws the splats on it (`gpu::GpuSplatter`) instead of gathering on
/// the CPU; with `passes.reuse`, pass 1 keeps earlier frames' samples (`reuse`).
pub fn render_with_layer(
    scene: &Scene,
    resolved: &Resolved,
    settings: &SplatSettings,
    camera: &Camera,
    layer: Option<&[[f32; 3]]>,
    passes: Passes,
    progress: Option<&ProgressFn>,
) -> Result<Render> {
    let start = Instant::now();
    let gpu = passes.gpu;
    let mut src = sources(
        scene,
        resolved,
        settings,
        passes.reuse,
        progress,
        (0.0, 0.3),
    )?;
    // Pass 2: the receivers, hidden by every object of the rest of the scene in front.
    let t = Instant::now();
    let seen = src.mesh_tracer.with_occluders(scene.occluders.triangles());
    let ticker = Ticker::span(progress, camera.pixels() as u64, 0.3, 0.4);
    let hits = camera_view(camera, &scene.mesh, &seen, Some(&ticker))?;
    drop(seen);
    src.report.seconds_camera_view = t.elapsed().as_secs_f64();
    src.report.pixels = hits.len();
    // The error estimate's vertices: gathered with the pixels on the CPU (one binning of the
    // splats); beside a GPU's draw, by a CPU gather of their own first.
    let mesh = &scene.mesh;
    let at = estimate::receivers(mesh.vertex_count(), settings.estimate_receivers);
    let pick = |x: &[Vec3]| at.iter().map(|&v| x[v as usize]).collect::<Vec<_>>();
    let at_objects: Vec<u32> = (at.iter())
        .map(|&v| mesh.object_of_vertex(v as usize))
        .collect();
    let mut points: Vec<Vec3> = hits.iter().map(|h| h.position).collect();
    let mut normals: Vec<Vec3> = hits.iter().map(|h| h.normal).collect();
    let mut objects: Vec<u32> = hits.iter().map(|h| h.object).collect();
    let mut at_vertices = Vec::new();
    if gpu.is_none() {
        points.extend(pick(mesh.positions()));
        normals.extend(pick(mesh.normals()));
        objects.extend(&at_objects);
    } else if !at.is_empty() {
        let kept = src.splats.clone();
        at_vertices = radiosity_at(
            &mut src,
            resolved,
            settings,
            (&pick(mesh.positions()), &pick(mesh.normals()), &at_objects),
            None,
            progress,
            (0.4, 0.4),
        )?;
        src.splats = kept;
    }
    let mut b = radiosity_at(
        &mut src,
        resolved,
        settings,
        (&points, &normals, &objects),
        gpu.map(|g| (g, camera, hits.as_slice())),
        progress,
        (0.4, 0.95),
    )?;
    if gpu.is_none() {
        at_vertices = b.split_off(hits.len());
    }
    // Pass 4: what leaves toward the eye.
    let eye = camera.eye();
    let mut values = vec![[0.0f32; 3]; camera.pixels()];
    let mut mask = vec![0u32; camera.pixels()];
    let tris = scene.mesh.triangles();
    for (h, bv) in hits.iter().zip(&b) {
        let mut bv = *bv;
        if let Some(layer) = layer {
            let [i, j, k] = tris[h.triangle as usize].map(|v| v as usize);
            let [u, v] = h.uv.map(f64::from);
            for c in 0..3 {
                // The layer is signed (a walk that loses light takes it away): B floored at 0.
                bv[c] = (bv[c]
                    + (1.0 - u - v) * f64::from(layer[i][c])
                    + u * f64::from(layer[j][c])
                    + v * f64::from(layer[k][c]))
                .max(0.0);
            }
        }
        let to_eye = (eye - h.position).normalize_or_zero();
        let k = resolved.exit_weights(f64::from(h.normal.dot(to_eye)));
        values[h.pixel as usize] =
            std::array::from_fn(|c| (bv[c] * k[c] / std::f64::consts::PI) as f32);
        mask[h.pixel as usize] = h.object + 1;
    }
    let error_estimate = if passes.no_truth {
        None
    } else {
        estimated(scene, resolved, &mut src, &at, &at_vertices, progress)?
    };
    tick(progress, 1.0)?;
    Ok(Render {
        evaluation: Evaluation {
            values,
            quantity: Quantity::Radiance,
            error_estimate,
            seconds: start.elapsed().as_secs_f64(),
            skipped: src.skipped,
            details: src.report,
        },
        mask,
        width: camera.width(),
        height: camera.height(),
        hits,
        at_vertices,
    })
}

/// The splatting over a scene it keeps (Shah 2009's setting: geometry, lights and material may
/// all change between frames): nothing is precomputed, so `set_positions` and `set_lighting`
/// only replace what the next evaluation reads. With the walks on (`with_walks`, Cycles'
/// profile), the walks' geometry term and the object's own light (`surface_terms`, shared with
/// the hierarchy) are walked at the first evaluation and carried to a new light or pose after.
pub struct Splatting {
    scene: Scene,
    profile: ProfileKind,
    settings: SplatSettings,
    terms: Option<std::sync::Mutex<Terms>>,
    /// Where a render's pass 3 runs: this device, or the CPU (None).
    gpu: Option<GpuSplatter>,
    /// The samples kept between frames (`reuse`), where the reuse is on.
    reuse: Option<Mutex<Reuse>>,
}

impl Splatting {
    /// Errors: a setting out of range (`SplatSettings::check`).
    pub fn new(scene: Scene, profile: ProfileKind, settings: SplatSettings) -> Result<Self> {
        settings.check()?;
        Ok(Self {
            scene,
            profile,
            settings,
            terms: None,
            gpu: None,
            reuse: None,
        })
    }

    /// The next evaluation walks the walks' term and the object's own light anew, on the shape
    /// and under the light it has then, for the material it evaluates (a pose carries them,
    /// `carried_pose`, until this). Nothing without the walks.
    pub fn retrace_walks(&self) {
        if let Some(t) = &self.terms {
            let mut t = t.lock().unwrap_or_else(|e| e.into_inner());
            t.rep = None;
            t.current = false;
        }
    }

    /// Shah 2009's sampling coherence between frames on (`reuse`: each frame keeps the
    /// earlier frames' splat sources that still see the light) or off.
    pub fn set_reuse(&mut self, on: bool) {
        self.reuse = on.then(|| Mutex::new(Reuse::default()));
    }

    /// Whether earlier frames' samples are kept.
    pub fn reuse(&self) -> bool {
        self.reuse.is_some()
    }

    /// Renders draw their splats on `gpu` from now on (None: gather on the CPU). The vertex
    /// radiosity is gathered on the CPU either way.
    pub fn set_gpu(&mut self, gpu: Option<GpuSplatter>) {
        self.gpu = gpu;
    }

    /// The device renders draw on, if any.
    pub fn gpu(&self) -> Option<&GpuSplatter> {
        self.gpu.as_ref()
    }

    /// This splatting with the walks' term and the object's own light (`surface_terms`).
    /// Errors: a profile other than Cycles' (the walks are Cycles' random walk).
    pub fn with_walks(mut self, settings: TermSettings) -> Result<Self> {
        if self.profile != ProfileKind::Cycles {
            return Err(Error::InvalidArgument(
                "walks: the walks' term is Cycles' random walk: use profile 'cycles' with it"
                    .into(),
            ));
        }
        self.terms = Some(std::sync::Mutex::new(Terms::new(settings)));
        Ok(self)
    }

    pub fn walks(&self) -> bool {
        self.terms.is_some()
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    pub fn profile(&self) -> ProfileKind {
        self.profile
    }

    pub fn settings(&self) -> SplatSettings {
        self.settings
    }

    /// A pose: the same vertices and triangles at `positions` (`Mesh::posed`); the walks'
    /// term is carried to it at the next evaluation.
    pub fn set_positions(
        &mut self,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
    ) -> Result<()> {
        self.scene.mesh = self.scene.mesh.posed(positions, normals)?;
        if let Some(t) = &self.terms {
            t.lock().unwrap_or_else(|e| e.into_inner()).stale(true);
        }
        Ok(())
    }

    /// New lights and world, and a new rest of the scene where `occluders` is given.
    pub fn set_lighting(&mut self, lights: Vec<Light>, world: World, occluders: Option<Occluders>) {
        self.scene.lights = lights;
        self.scene.world = world;
        if let Some(o) = occluders {
            self.scene.occluders = o;
        }
        if let Some(t) = &self.terms {
            t.lock().unwrap_or_else(|e| e.into_inner()).stale(false);
        }
    }

    /// The walks' term and own light for `material` per vertex (what they add to B), walked or
    /// carried first where the light or shape changed; `halfspace`: the splatted B at the
    /// vertices for `material`, when the caller has it. None without the walks.
    /// `beside`: other media with their splatted B (a textured Base Color's, `colored`): the
    /// walks are walked again where they do not cover one, and walk those beside the
    /// representative (`Terms::update`). `sent`: what the surface sends on to its own light
    /// where its vertices' lobes differ (`receiver_color::Lobes::sent`).
    fn layer(
        &self,
        material: &Material,
        halfspace: Option<&[[f32; 3]]>,
        beside: &[(Resolved, Vec<[f32; 3]>)],
        sent: Option<[f64; 3]>,
        progress: Option<&ProgressFn>,
    ) -> Result<Option<Layer>> {
        let Some(terms) = &self.terms else {
            return Ok(None);
        };
        let mut t = terms.lock().unwrap_or_else(|e| e.into_inner());
        let resolved = Resolved::new(self.profile, material)?;
        // A medium the walks do not reach is walked anew rather than read far outside the
        // walked lengths: this material as the representative (the whole budget, as at the
        // first evaluation), one given beside it beside it.
        let own_uncovered = t.rep.is_some() && !t.covers(&resolved);
        let uncovered =
            own_uncovered || (t.rep.is_some() && !beside.iter().all(|(m, _)| t.covers(m)));
        if !t.current || uncovered {
            let rep = match t.rep {
                Some(r) if !own_uncovered => r,
                _ => *material,
            };
            let fresh = t.rep.is_none() || uncovered;
            let rep_resolved = Resolved::new(self.profile, &rep)?;
            let quiet = SplatSettings {
                estimate_receivers: 0,
                ..self.settings
            };
            let splatted = |m: &Resolved| -> Result<Vec<[f32; 3]>> {
                Ok(splat_radiosity(&self.scene, m, &quiet, None)?.values)
            };
            let half = match halfspace.filter(|_| rep == *material) {
                Some(h) => h.to_vec(),
                None => splatted(&rep_resolved)?,
            };
            let mesh = &self.scene.mesh;
            let tracer = self.scene.tracer();
            let irradiance = IrradianceSettings {
                eta: rep_resolved.irradiance_eta(),
                ..Default::default()
            };
            let (vertices, _) = irradiance_of_scene(
                &self.scene,
                &tracer,
                mesh.positions(),
                mesh.normals(),
                &irradiance,
            )?;
            let lit = surface_terms::Lit {
                scene: &self.scene,
                tracer: &tracer,
                irradiance,
                vertices: &vertices,
                halfspace: &half,
            };
            // Beside the representative: the media given and, carried to a new light or pose,
            // the media walked beside it before (each with its splatted B, so none is dropped).
            let mut others: Vec<(Resolved, Vec<[f32; 3]>)> = (beside.iter())
                .filter(|(m, _)| m.material != rep)
                .cloned()
                .collect();
            if !fresh {
                for m in t.beside_media() {
                    if m.material != rep && !others.iter().any(|(x, _)| x.material == m.material) {
                        let b = splatted(&m)?;
                        others.push((m, b));
                    }
                }
            }
            t.update(&lit, &rep_resolved, &others, fresh, progress)?;
        }
        let mut added = vec![[0.0f32; 3]; self.scene.mesh.vertex_count()];
        let mut error = [0.0; 3];
        // A layer of its own (added to B at each vertex or pixel): signed, floored with B.
        t.add_to(&mut added, &resolved, &mut error, true, sent)?;
        Ok(Some((added, t.report.clone())))
    }

    /// What the walks take out of `skipped` and put in the report.
    fn with_terms(e: &mut Evaluation, report: TermReport) {
        e.skipped
            .retain(|s| s.what != "walks through the mesh" && s.what != "the object's own light");
        e.details.terms = Some(report);
    }

    /// `splat_radiosity` of `material` under the kept profile (tables built if needed), with
    /// the walks' term and own light where they are on.
    pub fn radiosity(
        &self,
        material: &Material,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        let start = Instant::now();
        let resolved = Resolved::new(self.profile, material)?;
        let mut e = radiosity_with(
            &self.scene,
            &resolved,
            &self.settings,
            self.reuse.as_ref(),
            progress,
        )?;
        if let Some((added, report)) = self.layer(material, Some(&e.values), &[], None, None)? {
            add_layer(&mut e.values, &added);
            Self::with_terms(&mut e, report);
            e.seconds = start.elapsed().as_secs_f64();
        }
        Ok(e)
    }

    /// `splat_render` of `material` seen by `camera`, the walks' term and own light (per
    /// vertex) interpolated into the image where they are on.
    pub fn render(
        &self,
        material: &Material,
        camera: &Camera,
        progress: Option<&ProgressFn>,
    ) -> Result<Render> {
        let start = Instant::now();
        let resolved = Resolved::new(self.profile, material)?;
        let layer = self.layer(material, None, &[], None, None)?;
        let mut r = render_with_layer(
            &self.scene,
            &resolved,
            &self.settings,
            camera,
            layer.as_ref().map(|(a, _)| a.as_slice()),
            Passes {
                gpu: self.gpu.as_ref(),
                reuse: self.reuse.as_ref(),
                no_truth: false,
            },
            progress,
        )?;
        if let Some((_, report)) = layer {
            Self::with_terms(&mut r.evaluation, report);
            r.evaluation.seconds = start.elapsed().as_secs_f64();
        }
        Ok(r)
    }

    /// `radiosity` as radiance toward `eye` or along each normal.
    pub fn radiance(
        &self,
        material: &Material,
        eye: Option<Vec3>,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        check_eye(eye)?;
        let start = Instant::now();
        let resolved = Resolved::new(self.profile, material)?;
        let mut e = self.radiosity(material, progress)?;
        e.into_radiance(
            &self.scene.mesh,
            eye,
            &|cos| resolved.exit_weights(cos),
            start,
        );
        Ok(e)
    }
}

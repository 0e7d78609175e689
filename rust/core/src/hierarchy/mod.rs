//! Hierarchical boundary elements for translucency (Mertens, Kautz, Bekaert, Seidel, Van Reeth
//! 2003): geometry, lighting and material may all change, and nothing is precomputed that a
//! deformation invalidates. A face-cluster hierarchy (`clusters`, §5.1.1) is built once per
//! topology; links between clusters are refined from the root by the solid-angle oracle
//! (`links`, §3.2, §5.2); irradiance is sampled at the faces and pulled up, gathered over the
//! links (polygon integral near, point sample far, §3.1, §4), pushed down and averaged to the
//! vertices (§3.2). Any profile (`profiles::ProfileKind`), read through a lookup table.
//!
//! Modes (§5.5): on-the-fly refines and gathers from scratch each time, storing no links;
//! render keeps the links and only gathers the new irradiance over them (after a material or
//! geometry change it re-integrates the near links' form factors but keeps the links);
//! incremental keeps the links and, after a material or geometry change, re-checks each one
//! against the oracle: kept, demoted (opened or moved down) or promoted (two sibling emitters
//! replaced by their parent), one level per update.
//!
//! B is the quantity `reference::reference_radiosity` integrates: the profile over the
//! irradiance I (with the profile's Fresnel factor), plus the profile's point mass times the
//! vertex's own irradiance; the irradiance from `irradiance::irradiance` (lights with ray-cast
//! shadows, the world) at the face centroids with interpolated normals, as the ground truth
//! samples it.

pub mod clusters;
mod colored;
pub mod edges;
pub mod far;
pub mod links;
pub mod ring;
mod settings;

use crate::surface_terms as terms;
pub use crate::surface_terms::{TermReport, TermSettings};
pub use settings::{HierarchyReport, HierarchySettings, Mode, Receivers};

use crate::error::{Error, Result};
use crate::evaluation::{Quantity, Skipped};
use crate::irradiance::keyed::KeyedPerSource;
use crate::irradiance::{BounceLight, Density, IrradianceSettings, PerSource};
use crate::lights::{Light, World};
use crate::mesh::{interpolated_normal, Mesh};
use crate::occluders::Occluders;
use crate::optics::Material;
use crate::profiles::table::{walk_table_with_progress, TableKey};
use crate::profiles::{LookupProfile, LookupRgb, ProfileKind, RadialProfile, Resolved};
use crate::progress::{cancel_only, stage, ProgressFn, Ticker};
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::surface_integral::{EdgeRule, Triangle};
use clusters::ClusterTree;
use far::FarEmitters;
use glam::Vec3;
use links::{Context, LinkCounts, NodeLinks, Slot};
use rayon::prelude::*;
use ring::Rings;
use std::time::Instant;

/// One material evaluated by the hierarchy (`evaluation::Evaluation`), with its report.
pub type Evaluation = crate::evaluation::Evaluation<HierarchyReport>;

/// The hierarchy of one scene, with the links and irradiance of its last evaluation.
pub struct Hierarchy {
    scene: Scene,
    tracer: Tracer,
    settings: HierarchySettings,
    tree: ClusterTree,
    faces: Vec<Triangle>,
    slots: Vec<Slot>,
    /// Vertices on a hole's rim or a sheet's edge: receivers of their own.
    rim: Vec<u32>,
    /// Their links (render, incremental).
    rim_links: Vec<NodeLinks>,
    /// Each vertex's faces (`ring`: the irradiance linear across them where the profile is
    /// short).
    rings: Rings,
    /// Each face's angle at its corners: the weights of the average to the vertices.
    corner_angles: Vec<[f64; 3]>,
    /// Each vertex's mean edge length (`ring`: which channels are short there).
    mean_edges: Vec<f64>,
    /// The clusters as far emitters, rebuilt after each pull.
    far: FarEmitters,
    has_links: bool,
    /// Face irradiance and the eta it was taken with; None when stale.
    face_irradiance: Option<(Vec<[f32; 3]>, f64)>,
    /// Each face's irradiance at its four midpoint sub-triangles' centroids (`SUB_POINTS`):
    /// the near links integrate each sub-triangle under its own.
    face_sub: Vec<[[f32; 3]; 4]>,
    /// The faces around vertex receivers that a shadow's edge crosses, their light at finer
    /// leaves (`edges`); None when stale (with `face_irradiance`).
    edge_light: Option<edges::EdgeLight>,
    /// Their leaves' form factors, kept until the material or the shape changes.
    edge_forms: edges::EdgeForms,
    /// Their leaves' light kept light by light (`irradiance::keyed`): a moved light casts its
    /// own rays, the others only at leaves they have not seen.
    edge_sources: KeyedPerSource,
    /// Faces wide against the profile's shortest decay length (`SPLIT_SHARE`), whose light is
    /// sampled at four points; the others at their centroid. Set by the material.
    split: Vec<bool>,
    /// Each light's share of it, so that a moved light costs only its own rays.
    face_sources: PerSource,
    vertex_sources: PerSource,
    vertex_irradiance: Option<(Vec<[f32; 3]>, f64)>,
    /// The bounce at each vertex averaged over its ring (`Rings::spread`) and its standard
    /// error: the faces' points take theirs from their corners' (`VERTEX_BOUNCE_FACTOR`);
    /// empty where nothing sends light back.
    vertex_bounce: Vec<([f32; 3], [f32; 3])>,
    /// How far averaging the bounce over the ring may have moved it, per vertex (`spread`'s
    /// bias, estimated): carried to B beside the noise (`irradiance_noise`).
    vertex_bounce_bias: Vec<[f32; 3]>,
    profiles: Option<(Material, [LookupProfile; 3], LookupRgb)>,
    geometry_changed: bool,
    report: HierarchyReport,
    /// The walks' term and the own light (`terms`), when on.
    terms: Option<terms::Terms>,
    /// The next evaluation walks the terms anew (`retrace_terms`).
    retrace: bool,
    /// Media the walks must cover beside the representative (a textured Base Color's media,
    /// `colored`): walked too where its lengths do not reach theirs.
    walk_media: Vec<Material>,
}

/// Each channel's decay length (infinite where nothing diffuses).
fn decays(lookup: &[LookupProfile; 3]) -> [f64; 3] {
    std::array::from_fn(|c| {
        if lookup[c].is_zero() {
            f64::INFINITY
        } else {
            lookup[c].length_scales().decay
        }
    })
}

/// B plus sparse corrections ΔB per vertex (`ring`, `edges`), kept non-negative.
/// `k` of `n` indices (all where `k` >= `n`) spread evenly through 0..n: the receivers an
/// estimate reads.
fn spread(n: usize, k: usize) -> Vec<usize> {
    let k = k.min(n);
    let step = n as f64 / k.max(1) as f64;
    (0..k).map(|i| (i as f64 * step) as usize).collect()
}

/// The profile integrated over `face` around `x` (`r`: to its centroid), per channel: what a
/// unit of the face's irradiance adds to B at `x`. Near the face (within three of its
/// widths, where the profile's peak lies on it) a midpoint rule on 64 sub-triangles; beyond,
/// its centroid's value times its area.
fn face_weight(face: &Triangle, x: glam::DVec3, r: f64, rgb: &LookupRgb) -> [f64; 3] {
    if r >= 3.0 * face.diam {
        return rgb.value(r).map(|p| p * face.area);
    }
    const N: usize = 8;
    let [a, b, c] = face.corners;
    let (u, v) = ((b - a) / N as f64, (c - a) / N as f64);
    let mut sum = [0.0f64; 3];
    let mut add = |m: glam::DVec3| {
        let p = rgb.value((m - x).length());
        for k in 0..3 {
            sum[k] += p[k];
        }
    };
    for i in 0..N {
        for j in 0..N - i {
            let o = a + u * i as f64 + v * j as f64;
            add(o + (u + v) / 3.0);
            if i + j + 1 < N {
                add(o + (u + v) * (2.0 / 3.0));
            }
        }
    }
    sum.map(|s| s * face.area / (N * N) as f64)
}

fn add_corrections(out: &mut [[f32; 3]], delta: Vec<(u32, [f64; 3])>) {
    for (v, d) in delta {
        let o = &mut out[v as usize];
        (0..3).for_each(|c| o[c] = (f64::from(o[c]) + d[c]).max(0.0) as f32);
    }
}

/// Calls `progress` with `f` (not throttled: for a few stage boundaries); false is
/// `Error::Cancelled`.
fn tick(progress: Option<&ProgressFn>, f: f32) -> Result<()> {
    match progress {
        Some(p) if !p(f) => Err(Error::Cancelled),
        _ => Ok(()),
    }
}

/// A face whose longest edge exceeds this share of the profile's shortest decay length has its
/// light sampled at four points and its near links integrated per quarter: on coarse and
/// held-out meshes the light changes across such a face as much as the profile does.
const SPLIT_SHARE: f64 = 0.25;

/// Bounce rays at a vertex, in `IrradianceSettings::vertex_bounce_factor` (64 at the default
/// 64 world samples), a fixed count: the vertex's own light (Cycles' profile's point mass)
/// and its faces' points read it, averaged over its ring (`Hierarchy::bounce_at`,
/// `Rings::spread`). Suzanne (2,012 vertices, marble) and the 10 cm bunny over a floor, a
/// moved light, against PRT's relight (2-core Xeon): 16 rays 4.7-5.1 / 2.1-2.5 % in 0.13 /
/// 0.46 s, 64 rays 3.3-3.6 / 1.5-1.8 % in 0.14 / 0.83 s; 32 rays cast on up to 128 while
/// noisy (`irradiance::BOUNCE_ADAPT`) 2.8-3.0 / 1.4-1.7 % in 0.15 / 1.22 s: the adaptation
/// asks light by light, and at a vertex a light does not reach directly the bounce is all
/// there is, so it went on at most of the bunny's vertices.
pub const VERTEX_BOUNCE_FACTOR: u32 = 4;

/// Barycentrics of the centroids of a face's four midpoint sub-triangles, in the order of
/// `links::sub_triangles`: the middle one, then those at corners 0, 1 and 2.
const SUB_POINTS: [[f32; 3]; 4] = [
    [1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0],
    [2.0 / 3.0, 1.0 / 6.0, 1.0 / 6.0],
    [1.0 / 6.0, 2.0 / 3.0, 1.0 / 6.0],
    [1.0 / 6.0, 1.0 / 6.0, 2.0 / 3.0],
];

fn faces_of(mesh: &Mesh) -> Vec<Triangle> {
    let p = mesh.positions();
    mesh.triangles()
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| p[v as usize].as_dvec3());
            Triangle::new(a, b, c)
        })
        .collect()
}

/// Area-weighted relative RMS per channel of (area, coarse, fine) triples against the fine.
fn relative_rms(pairs: impl Iterator<Item = (f64, [f64; 3], [f64; 3])>) -> [f64; 3] {
    let (mut num, mut den) = ([0.0f64; 3], [0.0f64; 3]);
    for (a, coarse, fine) in pairs {
        for c in 0..3 {
            num[c] += a * (coarse[c] - fine[c]).powi(2);
            den[c] += a * fine[c].powi(2);
        }
    }
    std::array::from_fn(|c| {
        if den[c] > 0.0 {
            (num[c] / den[c]).sqrt()
        } else if num[c] == 0.0 {
            0.0 // dark on both: nothing to be wrong about
        } else {
            f64::INFINITY // lit where the finer answer is dark
        }
    })
}

impl Hierarchy {
    /// Builds the cluster hierarchy of `scene.mesh` (no evaluation yet).
    pub fn new(scene: Scene, settings: HierarchySettings) -> Result<Hierarchy> {
        Self::new_with_progress(scene, settings, None)
    }

    /// `new` reporting `progress` in [0, 1] (0 first, 1 last; false cancels:
    /// `Error::Cancelled`): the clusters' merging (`ClusterTree::build`, asked between the
    /// steps of each round) is the first 70 %, the ray tracer's tree and the rest of the build
    /// the remainder, asked between them. The tracer's tree is one uninterrupted step
    /// (measured 0.2 s at 193k faces, 1.5 s at 1M on 2 cores).
    pub fn new_with_progress(
        scene: Scene,
        settings: HierarchySettings,
        progress: Option<&ProgressFn>,
    ) -> Result<Hierarchy> {
        for (name, v) in [
            ("eps receiver", settings.eps_receiver),
            ("eps emitter", settings.eps_emitter),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::InvalidArgument(format!(
                    "{name} = {v}: must be a positive solid angle [sr]"
                )));
            }
        }
        if !(settings.support_tolerance > 0.0 && settings.support_tolerance < 1.0) {
            return Err(Error::InvalidArgument(format!(
                "support tolerance {} must lie in (0, 1)",
                settings.support_tolerance
            )));
        }
        if settings.terms.is_some() && settings.profile != ProfileKind::Cycles {
            return Err(Error::InvalidArgument(
                "walks: the walks' term is Cycles' random walk: use profile 'cycles' with it"
                    .into(),
            ));
        }
        let start = Instant::now();
        tick(progress, 0.0)?;
        let clusters = stage(progress, 0.0, 0.7);
        let mut tree = ClusterTree::build(
            scene.mesh.positions(),
            scene.mesh.triangles(),
            progress.map(|_| &clusters as &ProgressFn),
        )?;
        tick(progress, 0.7)?;
        let faces = faces_of(&scene.mesh);
        // Shadow rays see the rest of the scene too (`Scene::shadow_tracer`).
        let tracer = scene.tracer();
        tick(progress, 0.9)?;
        tree.refit(&faces);
        // Every vertex gathers for itself (`Receivers::Vertices`), or only those on a rim.
        let every = settings.receivers == Receivers::Vertices;
        let rim: Vec<u32> = (scene.mesh.vertex_coverage().iter().enumerate())
            .filter(|(_, c)| every || (**c > 0.0 && **c < 1.0))
            .map(|(v, _)| v as u32)
            .collect();
        let rings = Rings::new(scene.mesh.vertex_count(), scene.mesh.triangles());
        let report = HierarchyReport {
            mode: settings.mode.name(),
            faces: faces.len(),
            clusters: tree.len(),
            depth: tree.depth,
            seconds_build: start.elapsed().as_secs_f64(),
            ..Default::default()
        };
        tick(progress, 1.0)?;
        Ok(Hierarchy {
            slots: Vec::new(),
            scene,
            tracer,
            tree,
            faces,
            has_links: false,
            rim,
            rim_links: Vec::new(),
            rings,
            corner_angles: Vec::new(),
            mean_edges: Vec::new(),
            far: FarEmitters::default(),
            face_irradiance: None,
            face_sub: Vec::new(),
            edge_light: None,
            edge_forms: Default::default(),
            edge_sources: Default::default(),
            split: Vec::new(),
            face_sources: PerSource::default(),
            vertex_sources: PerSource::default(),
            vertex_irradiance: None,
            vertex_bounce: Vec::new(),
            vertex_bounce_bias: Vec::new(),
            profiles: None,
            geometry_changed: false,
            report,
            terms: settings.terms.clone().map(terms::Terms::new),
            retrace: false,
            walk_media: Vec::new(),
            settings,
        })
    }

    /// Takes the walks' term and the own light walked by another method (`Prt::walked_terms`)
    /// in place of its own: carried to this hierarchy's light against its own half-space B at
    /// the next evaluation, no walk traced (the hierarchy up in about 1 s on the 10 cm bunny
    /// instead of 20 s with its own walks). Errors where the hierarchy has no terms (walks
    /// off: the dipole) or where they were walked on another mesh or shape.
    pub fn adopt_terms(&mut self, walked: terms::Walked) -> Result<()> {
        let Some(settings) = self.settings.terms.clone() else {
            return Err(Error::InvalidArgument(
                "walked terms for a hierarchy without walks (walks are Cycles' profile's)".into(),
            ));
        };
        walked.check_mesh(&self.scene.mesh)?;
        self.terms = Some(terms::Terms::carried(settings, walked));
        self.retrace = false;
        Ok(())
    }

    /// The next evaluation walks the terms anew on the mesh as it is now (after a pose they
    /// are carried: `HierarchyReport::terms`'s `carried_pose`). No-op without the terms.
    pub fn retrace_terms(&mut self) {
        self.retrace = self.terms.is_some();
    }

    pub fn settings(&self) -> &HierarchySettings {
        &self.settings
    }

    pub fn report(&self) -> &HierarchyReport {
        &self.report
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// Changes the mode; links kept from before stay valid.
    pub fn set_mode(&mut self, mode: Mode) {
        self.settings.mode = mode;
    }

    /// The mesh deformed: same triangles, new positions (and normals, or computed ones).
    pub fn set_positions(
        &mut self,
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
    ) -> Result<()> {
        let mesh = self.scene.mesh.posed(positions, normals)?;
        self.faces = faces_of(&mesh);
        self.scene.mesh = mesh;
        self.tracer = self.scene.tracer();
        self.geometry_changed = true;
        self.face_irradiance = None;
        self.vertex_irradiance = None;
        self.face_sources.clear();
        self.edge_sources.clear();
        self.vertex_sources.clear();
        if let Some(t) = &mut self.terms {
            t.stale(true);
        }
        Ok(())
    }

    /// New lights and world: the next evaluation samples the irradiance again, for the lights
    /// that changed only (`irradiance::PerSource`).
    pub fn set_lights(&mut self, lights: Vec<Light>, world: World) {
        self.set_lighting(lights, world, None);
    }

    /// Light and shadow linking per light (`Scene::linking`, by the lights' places): a light
    /// whose linking changed is lit again at the next evaluation.
    pub fn link(&mut self, linking: Vec<Option<crate::scene::Linking>>) {
        if linking != self.scene.linking {
            self.scene.linking = linking;
            self.face_irradiance = None;
            self.vertex_irradiance = None;
            if let Some(t) = &mut self.terms {
                t.stale(false);
            }
        }
    }

    /// New lights and world, and a new rest of the scene where `occluders` is given and differs
    /// (a prop moved, added or hidden): then every light's shadows change, so the irradiance
    /// kept light by light is dropped and the next evaluation casts every source's rays again.
    /// The shadow tracer is rebuilt once, for both.
    pub fn set_lighting(&mut self, lights: Vec<Light>, world: World, occluders: Option<Occluders>) {
        self.scene.lights = lights;
        self.scene.world = world;
        let new_rest = occluders.filter(|o| *o != self.scene.occluders);
        let changed = new_rest.is_some();
        if let Some(o) = new_rest {
            self.scene.occluders = o;
            self.face_sources.clear();
            self.edge_sources.clear();
            self.vertex_sources.clear();
        }
        if changed || !self.scene.occluders.is_empty() {
            // The occluders that can shadow the mesh under the new lights (the mesh's BVH
            // shared): a light kept keeps its own, so its kept irradiance stays right.
            self.tracer = self.scene.shadow_tracer(&self.tracer).0;
        }
        self.face_irradiance = None;
        self.vertex_irradiance = None;
        if let Some(t) = &mut self.terms {
            t.stale(false);
        }
    }

    /// The irradiance's settings for points of `density`: vertices cast `VERTEX_BOUNCE_FACTOR`
    /// times the bounce rays and keep the bounce apart, the faces' points leave it out and take
    /// their corners' (`bounce_at`).
    fn irradiance_settings(&self, eta: f64, density: Density) -> IrradianceSettings {
        let (bounce, vertex_bounce_factor) = match density {
            Density::Receivers => (BounceLight::Kept, VERTEX_BOUNCE_FACTOR),
            Density::Dense => (BounceLight::LeftOut, 1),
        };
        IrradianceSettings {
            bounce,
            vertex_bounce_factor,
            bounce_target: f32::INFINITY, // a fixed count (`VERTEX_BOUNCE_FACTOR`)
            ..self.walk_irradiance_settings(eta)
        }
        .for_density(density)
    }

    /// The irradiance's settings the walks' terms read their exits' light with (the bounce
    /// added, as many rays as the world's give).
    fn walk_irradiance_settings(&self, eta: f64) -> IrradianceSettings {
        IrradianceSettings {
            eta,
            world_samples: self.settings.world_samples,
            area_samples: self.settings.area_samples,
            seed: self.settings.seed,
            world_unshadowed: !self.settings.world_shadows,
            ..Default::default()
        }
    }

    /// The bounce off the rest of the scene at barycentrics `b` of face `f`, from its corners'
    /// (`vertex_bounce`; zero where nothing sends light back). The bounce is smooth across a
    /// face; one ray or two at each of the faces' points left B 8-9 % from PRT's on Suzanne
    /// over a floor (marble, 2,012 vertices) where the corners' many rays are shared.
    fn bounce_at(&self, f: usize, b: [f32; 3]) -> [f32; 3] {
        if self.vertex_bounce.is_empty() {
            return [0.0; 3];
        }
        let t = self.scene.mesh.triangles()[f];
        std::array::from_fn(|c| {
            (0..3)
                .map(|k| b[k] * self.vertex_bounce[t[k] as usize].0[c])
                .sum()
        })
    }

    /// Irradiance within each face with the interpolated normals: a split face (`split`) at its
    /// four midpoint sub-triangles' centroids (`SUB_POINTS`), kept per sub-triangle for the near
    /// links, its irradiance their mean (a four-point rule for its average over the face); any
    /// other face at its centroid alone, the value repeated in all four slots. One sample
    /// at the centroid could not follow light that changes across a face as wide as the
    /// diffusion length (spot at 10 cm, marble: 5-6 % off the ground truth). Returns rays cast.
    fn sample_faces(&mut self, eta: f64) -> Result<u64> {
        if matches!(&self.face_irradiance, Some((_, e)) if *e == eta) {
            return Ok(0);
        }
        let mesh = &self.scene.mesh;
        let split = &self.split;
        let (points, normals): (Vec<Vec3>, Vec<Vec3>) = mesh
            .triangles()
            .par_iter()
            .zip(self.faces.par_iter())
            .enumerate()
            .flat_map_iter(|(i, (t, f))| {
                let corners = t.map(|v| mesh.normals()[v as usize]);
                let at = t.map(|v| mesh.positions()[v as usize]);
                let k = if split[i] { 4 } else { 1 };
                SUB_POINTS[..k].iter().map(move |b| {
                    let n = interpolated_normal(&corners, b[1], b[2], f.normal.as_vec3());
                    (at[0] * b[0] + at[1] * b[1] + at[2] * b[2], n)
                })
            })
            .unzip();
        let s = self.irradiance_settings(eta, Density::Dense);
        let (values, r) =
            self.face_sources
                .evaluate(&self.scene, &self.tracer, &points, &normals, &s)?;
        // The bounce from the corners': the vertices' taken first where there is one.
        let corner_rays = if self.tracer.bounces() {
            self.sample_vertices(eta)?
        } else {
            0
        };
        let mut next = values.iter();
        let face_sub: Vec<[[f32; 3]; 4]> = (self.split.iter())
            .enumerate()
            .map(|(f, &four)| {
                let k = if four { 4 } else { 1 };
                let mut e = [[0.0f32; 3]; 4];
                for (j, b) in SUB_POINTS[..k].iter().enumerate() {
                    let direct = *next.next().unwrap_or(&[0.0; 3]);
                    let bounce = self.bounce_at(f, *b);
                    e[j] = std::array::from_fn(|c| direct[c] + bounce[c]);
                }
                if !four {
                    e = [e[0]; 4];
                }
                e
            })
            .collect();
        self.face_sub = face_sub;
        let mean = (self.face_sub.iter())
            .map(|e| std::array::from_fn(|c| e.iter().map(|v| v[c]).sum::<f32>() / 4.0))
            .collect();
        self.face_irradiance = Some((mean, eta));
        self.edge_light = None;
        Ok(r.rays + corner_rays)
    }

    /// Whether split faces at vertex receivers are to be checked for a shadow's edge
    /// (`edges`): their corners' irradiance is then sampled too.
    fn edges_asked(&self) -> bool {
        !self.rim.is_empty() && self.split.iter().any(|s| *s)
    }

    /// The light at the leaves of each split face at a vertex receiver that a shadow's edge
    /// crosses (`edges::faces_to_resolve`, `edges::EdgeLight::refine`), each quarter's sample
    /// replaced by its leaves' mean. Kept until the face irradiance is taken again. Returns
    /// rays cast.
    fn sample_edges(&mut self, eta: f64, progress: Option<&ProgressFn>) -> Result<u64> {
        if self.edge_light.is_some() || !self.edges_asked() {
            return Ok(0);
        }
        let Some((corners, _)) = &self.vertex_irradiance else {
            return Ok(0);
        };
        let which = edges::faces_to_resolve(
            self.scene.mesh.triangles(),
            &self.rim,
            &self.split,
            &self.face_sub,
            corners,
        );
        let corner_light: Vec<[[f32; 3]; 3]> = (which.iter())
            .map(|&f| self.scene.mesh.triangles()[f as usize].map(|v| corners[v as usize]))
            .collect();
        let s = self.irradiance_settings(eta, Density::Dense);
        // Before the irradiance stage's tick at 0.3: the bar held where it is, asking whether
        // to go on.
        let held = crate::progress::held_at(progress, 0.0);
        let ask = Some(&held as &ProgressFn);
        let mesh = &self.scene.mesh;
        let faces = &self.faces;
        let rays = std::cell::Cell::new(0u64);
        let kept = std::cell::RefCell::new(std::mem::take(&mut self.edge_sources));
        // The light at the asked points with the normals interpolated there, each light's
        // kept where it saw the point before.
        let light_at = |asked: &[(u32, glam::DVec3, u32)]| -> Result<Vec<[f32; 3]>> {
            let (points, normals): (Vec<Vec3>, Vec<Vec3>) = (asked.par_iter())
                .map(|&(f, at, _)| {
                    let face = &faces[f as usize];
                    let corners = mesh.triangles()[f as usize].map(|v| mesh.normals()[v as usize]);
                    let b = edges::barycentric(face, at);
                    let n = interpolated_normal(
                        &corners,
                        b[1] as f32,
                        b[2] as f32,
                        face.normal.as_vec3(),
                    );
                    (at.as_vec3(), n)
                })
                .unzip();
            let keys: Vec<(u32, u32)> = asked.iter().map(|&(f, _, code)| (f, code)).collect();
            let (values, r) = kept.borrow_mut().evaluate(
                &self.scene,
                &self.tracer,
                &keys,
                &points,
                &normals,
                &s,
                ask,
            )?;
            rays.set(rays.get() + r.rays);
            // The bounce from the face's corners, as the face's points take it.
            Ok((values.iter().zip(asked))
                .map(|(e, &(f, at, _))| {
                    let b = edges::barycentric(&faces[f as usize], at).map(|x| x as f32);
                    let bounce = self.bounce_at(f as usize, b);
                    std::array::from_fn(|c| e[c] + bounce[c])
                })
                .collect())
        };
        let refined =
            edges::EdgeLight::refine(&self.faces, which, &self.face_sub, &corner_light, &light_at);
        self.edge_sources = kept.into_inner();
        let light = refined?;
        // Each quarter's light becomes its leaves' mean and the face's the quarters' mean, so
        // that the near links and the far clusters carry the power the leaves found; the
        // corrections then only move it within each quarter (`edges::corrections`).
        for (i, &f) in light.faces.iter().enumerate() {
            let quarters = light.quarter_means(i);
            self.face_sub[f as usize] = quarters;
            if let Some((mean, _)) = &mut self.face_irradiance {
                mean[f as usize] =
                    std::array::from_fn(|c| quarters.iter().map(|e| e[c]).sum::<f32>() / 4.0);
            }
        }
        self.edge_light = Some(light);
        Ok(rays.get())
    }

    fn sample_vertices(&mut self, eta: f64) -> Result<u64> {
        if matches!(&self.vertex_irradiance, Some((_, e)) if *e == eta) {
            return Ok(0);
        }
        let mesh = &self.scene.mesh;
        let s = self.irradiance_settings(eta, Density::Receivers);
        let (values, r) = self.vertex_sources.evaluate(
            &self.scene,
            &self.tracer,
            mesh.positions(),
            mesh.normals(),
            &s,
        )?;
        self.vertex_bounce_bias.clear();
        self.vertex_bounce = if self.tracer.bounces() {
            // For the faces' points, each vertex's bounce averaged over its ring
            // (`Rings::spread`); the vertex itself keeps its own rays' (its point mass and
            // diffuse lobe read it alone, where the average's bias would not average out).
            let raw = self.vertex_sources.bounce();
            let triangles = mesh.triangles();
            let spread = self.rings.spread(triangles, &self.faces, &raw);
            // What the average moves a bounce that curves across the ring (a coarse sphere
            // over a floor: 2 % of B): told by averaging the averaged bounce once more, whose
            // change is the average's own, its noise mostly gone.
            let twice = self.rings.spread(triangles, &self.faces, &spread);
            self.vertex_bounce_bias = (spread.iter().zip(&twice))
                .map(|(a, b)| std::array::from_fn(|c| (b.0[c] - a.0[c]).abs()))
                .collect();
            spread
        } else {
            Vec::new()
        };
        self.vertex_irradiance = Some((values, eta));
        Ok(r.rays)
    }

    /// The lookup profiles of `material`; whether they changed. Cycles' walk tables not yet
    /// in memory are built first (seconds each), asking `progress` whether to go on.
    fn prepare_profiles(
        &mut self,
        material: &Material,
        progress: Option<&ProgressFn>,
    ) -> Result<bool> {
        if matches!(&self.profiles, Some((m, _, _)) if m == material) {
            return Ok(false);
        }
        if self.settings.profile == ProfileKind::Cycles {
            let ask = cancel_only(progress);
            // A material the walk cannot take is refused by `profiles`, with its message.
            for (key, _) in TableKey::of(material).unwrap_or_default() {
                walk_table_with_progress(&key, progress.map(|_| &ask as &ProgressFn))?;
            }
        }
        let (lookup, rgb) = self.lookups_of(material)?;
        self.profiles = Some((*material, lookup, rgb));
        Ok(true)
    }

    /// `material`'s three profiles under this hierarchy's kind, tabulated for its links (the
    /// support cut at `support_tolerance`), and their channels together.
    fn lookups_of(&self, material: &Material) -> Result<([LookupProfile; 3], LookupRgb)> {
        let exact = self.settings.profile.profiles(material)?;
        let tol = self.settings.support_tolerance;
        let lookup = std::array::from_fn(|c| LookupProfile::new(&exact[c], tol));
        let rgb = LookupRgb::new(&lookup);
        Ok((lookup, rgb))
    }

    fn context<'a>(
        &'a self,
        lookup: &'a [LookupProfile; 3],
        rgb: &'a LookupRgb,
        skip_dark: bool,
        scale: f64,
    ) -> Context<'a> {
        Context {
            tree: &self.tree,
            faces: &self.faces,
            rgb,
            far: &self.far,
            eps_receiver: self.settings.eps_receiver * scale,
            eps_emitter: self.settings.eps_emitter * scale,
            support: lookup.iter().map(|p| p.support()).fold(0.0, f64::max),
            supports: std::array::from_fn(|c| lookup[c].support()),
            decays: decays(lookup),
            rule: EdgeRule::FAST,
            skip_dark,
            ticker: None,
            sub: &self.face_sub,
            split: &self.split,
        }
    }

    /// Radiosity B per vertex (the quantity `reference_radiosity` integrates), with the
    /// estimate, seconds and skips of the shared evaluation.
    pub fn radiosity(&mut self, material: &Material) -> Result<Evaluation> {
        self.radiosity_with_progress(material, None)
    }

    /// `radiosity` reporting `progress` in [0, 1] (0 first, 1 last; false cancels:
    /// `Error::Cancelled`, the links of an unfinished refinement dropped): Cycles' walk tables
    /// (built when missing, asking with NaN) and the irradiance are the first 30 % (asked
    /// before and after), refining the links and gathering over them the next 60 % (counted
    /// per receiver cluster), the rest asked between its stages.
    pub fn radiosity_with_progress(
        &mut self,
        material: &Material,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        self.radiosity_sending(material, None, progress)
    }

    /// `radiosity_with_progress` with the object's own light sent by `sent` (what the surface
    /// sends on where its vertices' lobes differ, `receiver_color::Lobes::sent`); None: by
    /// what `material` sends on.
    fn radiosity_sending(
        &mut self,
        material: &Material,
        sent: Option<[f64; 3]>,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        let needs_terms = self
            .terms
            .as_ref()
            .is_some_and(|t| !t.current || self.retrace || !self.walk_media.is_empty());
        let direct = if needs_terms {
            stage(progress, 0.0, 0.2)
        } else {
            stage(progress, 0.0, 1.0)
        };
        let mut values = self.radiosity_values(material, progress.map(|_| &direct as _))?;
        if self.terms.is_some() {
            let rest = stage(progress, 0.2, 1.0);
            self.add_terms(material, sent, &mut values, progress.map(|_| &rest as _))?;
        }
        Ok(Evaluation {
            values,
            quantity: Quantity::Radiosity,
            error_estimate: self.report.error_estimate,
            seconds: self.report.seconds,
            skipped: self.skipped(),
            details: self.report.clone(),
        })
    }

    /// What the hierarchy leaves out of every evaluation, and why.
    fn skipped(&self) -> Vec<Skipped> {
        let mut out = match &self.terms {
            None => vec![
                Skipped::new(
                    "walks through the mesh",
                    "the hierarchy sums the half-space profile (Mertens 2003): walks off",
                ),
                Skipped::new(
                    "the object's own light",
                    "the hierarchy gathers the direct light only: walks off",
                ),
            ],
            Some(t) if t.report.carried_pose => vec![Skipped::new(
                "the walks and the own light's rays on this pose",
                "carried from the pose they were traced on (read on the same triangles): \
                 retracing the walks on this pose refines them",
            )],
            Some(t) if t.settings.interreflection.is_none() => vec![Skipped::new(
                "the object's own light",
                "interreflection off",
            )],
            Some(_) => Vec::new(),
        };
        if self.settings.estimate_receivers == 0 {
            out.push(Skipped::new("error estimate", "estimate_receivers = 0"));
        }
        if !self.settings.world_shadows && !self.scene.world.is_black() {
            out.push(Skipped::new(
                "the world's shadows",
                "world_shadows = false: the world lights every face unoccluded",
            ));
        }
        out
    }

    /// Whether a medium of `walk_media` lies beyond the lengths walked (a new walk is due).
    fn walk_media_uncovered(&self) -> Result<bool> {
        let Some(t) = self.terms.as_ref().filter(|t| t.rep.is_some()) else {
            return Ok(false);
        };
        for m in &self.walk_media {
            if !t.covers(&crate::profiles::Resolved::new(ProfileKind::Cycles, m)?) {
                return Ok(true);
            }
        }
        Ok(false)
    }

    /// `walk_media` other than `rep`, each with its half-space B under this light and shape
    /// (this evaluation's report kept; the profiles are the last medium's after, so the next
    /// evaluation of another material links again).
    fn beside_media(&mut self, rep: &Material) -> Result<Vec<(Resolved, Vec<[f32; 3]>)>> {
        let media: Vec<Material> = (self.walk_media.iter())
            .filter(|m| *m != rep)
            .copied()
            .collect();
        if media.is_empty() {
            return Ok(Vec::new());
        }
        let report = self.report.clone();
        let out = media
            .iter()
            .map(|m| {
                Ok((
                    Resolved::new(ProfileKind::Cycles, m)?,
                    self.radiosity_values(m, None)?,
                ))
            })
            .collect();
        self.report = report;
        out
    }

    /// Adds the walks' term and the own light for `material` to `values` (B per vertex), and
    /// their noise to the error estimate; carries (or walks, the first time or after
    /// `retrace_terms`) them to the current light and shape first, for the representative.
    /// `sent`: as `radiosity_sending`.
    fn add_terms(
        &mut self,
        material: &Material,
        sent: Option<[f64; 3]>,
        values: &mut [[f32; 3]],
        progress: Option<&ProgressFn>,
    ) -> Result<()> {
        let Some(current) = self.terms.as_ref().map(|t| t.current) else {
            return Ok(());
        };
        let uncovered = self.walk_media_uncovered()?;
        if !current || self.retrace || uncovered {
            let rep = self.terms.as_ref().and_then(|t| t.rep).unwrap_or(*material);
            let fresh =
                self.retrace || uncovered || self.terms.as_ref().is_some_and(|t| t.rep.is_none());
            // The representative's half-space B under this light and shape (its own evaluation
            // when another material is asked for; this evaluation's report kept).
            let halfspace = if rep == *material {
                values.to_vec()
            } else {
                let report = self.report.clone();
                let b = self.radiosity_values(&rep, None);
                self.report = report;
                b?
            };
            let eta = self.settings.profile.irradiance_eta(&rep);
            self.sample_vertices(eta)?;
            let vertices = match &self.vertex_irradiance {
                Some((v, _)) => v.clone(),
                None => return Err(Error::InvalidArgument("no vertex irradiance".into())),
            };
            let resolved = crate::profiles::Resolved::new(ProfileKind::Cycles, &rep)?;
            let beside = self.beside_media(&rep)?;
            let lit = terms::Lit {
                scene: &self.scene,
                tracer: &self.tracer,
                irradiance: self.walk_irradiance_settings(eta),
                vertices: &vertices,
                halfspace: &halfspace,
            };
            let mut terms = self.terms.take().expect("checked above");
            let done = terms.update(&lit, &resolved, &beside, fresh, progress);
            self.terms = Some(terms);
            done?;
            self.retrace = false;
        }
        let resolved = crate::profiles::Resolved::new(ProfileKind::Cycles, material)?;
        let terms = self.terms.as_ref().expect("checked above");
        let mut error = self.report.error_estimate.unwrap_or([0.0; 3]);
        terms.add_to(values, &resolved, &mut error, false, sent)?;
        if self.report.error_estimate.is_some() {
            self.report.error_estimate = Some(error);
        }
        self.report.terms = Some(terms.report.clone());
        Ok(())
    }

    fn radiosity_values(
        &mut self,
        material: &Material,
        progress: Option<&ProgressFn>,
    ) -> Result<Vec<[f32; 3]>> {
        let start = Instant::now();
        tick(progress, 0.0)?;
        let mut report = HierarchyReport {
            mode: self.settings.mode.name(),
            faces: self.faces.len(),
            clusters: self.tree.len(),
            depth: self.tree.depth,
            seconds_build: self.report.seconds_build,
            ..Default::default()
        };
        let material_changed = self.prepare_profiles(material, progress)?;
        let t = Instant::now();
        let geometry_changed = self.geometry_changed;
        if geometry_changed {
            self.tree.refit(&self.faces);
            self.geometry_changed = false;
        }
        if geometry_changed || self.corner_angles.len() != self.faces.len() {
            self.corner_angles = (self.faces.par_iter())
                .map(|f| std::array::from_fn(|k| f.corner_angle(k)))
                .collect();
            self.mean_edges = self.rings.mean_edges(&self.faces);
        }
        // Which faces are wide against the profile: their light sampled at four points, their
        // near links integrated per quarter. A new split asks for the light again.
        if let Some((_, lookup, _)) = &self.profiles {
            let shortest = decays(lookup).into_iter().fold(f64::INFINITY, f64::min);
            let split: Vec<bool> = (self.faces.iter())
                .map(|f| f.diam > SPLIT_SHARE * shortest)
                .collect();
            if split != self.split {
                self.split = split;
                self.face_irradiance = None;
                self.face_sources.clear();
                self.edge_sources.clear();
            }
        }
        report.split_faces = self.split.iter().filter(|s| **s).count();
        report.seconds_refit = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let eta = self.settings.profile.irradiance_eta(material);
        report.rays = self.sample_faces(eta)?;
        let point_mass = self
            .profiles
            .as_ref()
            .map(|(_, p, _)| p.iter().any(|p| p.point_mass() > 0.0))
            .unwrap_or(false);
        let short = match &self.profiles {
            Some((_, lookup, _)) => Rings::short_channels(&self.mean_edges, &decays(lookup)),
            None => Vec::new(),
        };
        let ring_linear = short.iter().any(|s| *s != 0);
        // A split face's corners tell whether a shadow's edge crosses it (`edges`).
        if point_mass || ring_linear || self.edges_asked() {
            report.rays += self.sample_vertices(eta)?;
        }
        report.rays += self.sample_edges(eta, progress)?;
        report.seconds_irradiance = t.elapsed().as_secs_f64();
        tick(progress, 0.3)?;
        let t = Instant::now();
        if let Some((irr, _)) = &self.face_irradiance {
            self.tree.pull(irr);
        }
        self.far.update(&self.tree);
        report.seconds_pull = t.elapsed().as_secs_f64();

        let (_, lookup, rgb) = self
            .profiles
            .take()
            .ok_or_else(|| Error::InvalidArgument("no profiles prepared".into()))?;
        // With every vertex a receiver of its own the faces' B would be overwritten at every
        // vertex: the faces' traversal is not run at all (the estimate is taken at vertices).
        let every = self.settings.receivers == Receivers::Vertices;
        let result = if every {
            Ok(Vec::new())
        } else {
            self.evaluate(
                &lookup,
                &rgb,
                material_changed,
                geometry_changed,
                &mut report,
                progress,
            )
        };
        self.profiles = Some((*material, lookup, rgb));
        let face_b = result?;
        if !every {
            tick(progress, 0.95)?;
        }

        // A vertex on a hole's rim has surface on one side only: B falls toward the rim within
        // the profile's near length, and the faces' centroids, inside, overstate it (measured
        // +26 % for marble on the bunny's rim). Such a vertex is a receiver of its own, refined
        // from the root (its nearest faces integrated from it); with `Receivers::Vertices` every
        // vertex is. Render and incremental modes keep its links until the material or the
        // shape changes.
        let at_rim = if self.rim.is_empty() {
            None
        } else {
            let t = Instant::now();
            let b = self.gather_at_rim(
                material_changed,
                geometry_changed,
                every,
                &mut report,
                progress,
            )?;
            if every {
                report.seconds_links = t.elapsed().as_secs_f64();
                let t = Instant::now();
                report.error_estimate = self.estimate_at_vertices(&b);
                report.seconds_estimate = t.elapsed().as_secs_f64();
                tick(progress, 0.95)?;
            }
            Some(b)
        };

        // Average to the vertices (§3.2), each face weighted by its angle at the vertex: where
        // the profile is short against the faces, B at a vertex is the irradiance of the faces
        // around it in proportion to the angle each spans there, and B at each face's centroid
        // is its own irradiance (area weights measured 0.3–0.5 % worse on the bunny).
        let t = Instant::now();
        let mesh = &self.scene.mesh;
        let mut sum = vec![[0.0f64; 4]; mesh.vertex_count()];
        for (f, tri) in mesh.triangles().iter().enumerate().take(face_b.len()) {
            for (k, &v) in tri.iter().enumerate() {
                let a = self.corner_angles[f][k];
                let s = &mut sum[v as usize];
                (0..3).for_each(|c| s[c] += a * face_b[f][c]);
                s[3] += a;
            }
        }
        let masses: [f64; 3] = match &self.profiles {
            Some((_, p, _)) => std::array::from_fn(|c| p[c].point_mass()),
            None => [0.0; 3],
        };
        if let Some(at_rim) = &at_rim {
            for (&v, b) in self.rim.iter().zip(at_rim) {
                sum[v as usize] = [b[0], b[1], b[2], 1.0];
            }
        }
        let mut out: Vec<[f32; 3]> = sum
            .iter()
            .enumerate()
            .map(|(v, s)| {
                let own = match &self.vertex_irradiance {
                    Some((i, _)) if point_mass => i[v],
                    _ => [0.0; 3],
                };
                std::array::from_fn(|c| {
                    let b = if s[3] > 0.0 { s[c] / s[3] } else { 0.0 };
                    (b + masses[c] * f64::from(own[c])) as f32
                })
            })
            .collect();
        if let (true, Some((face_irr, _)), Some((vertex_irr, _)), Some((_, _, rgb))) = (
            ring_linear,
            &self.face_irradiance,
            &self.vertex_irradiance,
            &self.profiles,
        ) {
            let delta = self.rings.corrections(
                &self.faces,
                mesh.triangles(),
                &short,
                face_irr,
                vertex_irr,
                &self.rim,
                rgb,
                &EdgeRule::FAST,
            );
            add_corrections(&mut out, delta);
        }
        // A shadow's edge across the faces around a vertex receiver (`edges`).
        if material_changed || geometry_changed {
            self.edge_forms.clear();
        }
        if let (Some(light), Some((_, _, rgb))) = (&self.edge_light, &self.profiles) {
            report.edge_faces = light.faces.len();
            self.edge_forms.fill(
                &self.faces,
                mesh.triangles(),
                &self.rings,
                mesh.positions(),
                &self.rim,
                light,
                rgb,
                &EdgeRule::FAST,
            );
            add_corrections(
                &mut out,
                edges::corrections(light, &self.edge_forms, &self.face_sub),
            );
        }
        report.seconds_push += t.elapsed().as_secs_f64();
        // The sampled irradiance's own noise (the bounce off the rest of the scene, area
        // lights, a traced world), carried through the profile to the estimate's receivers.
        if let Some(err) = report.error_estimate.as_mut() {
            let t = Instant::now();
            let noise = self.irradiance_noise(&out);
            report.irradiance_noise = noise;
            for c in 0..3 {
                err[c] += noise[c];
            }
            report.seconds_estimate += t.elapsed().as_secs_f64();
        }
        report.seconds = start.elapsed().as_secs_f64();
        tick(progress, 1.0)?;
        self.report = report;
        Ok(out)
    }

    /// The `estimate_receivers` vertices an estimate at the vertices reads (`spread`).
    fn estimate_vertices(&self) -> Vec<usize> {
        spread(
            self.scene.mesh.vertex_count(),
            self.settings.estimate_receivers,
        )
    }

    /// What the sampled irradiance's noise leaves in B (`b` per vertex), as a relative RMS per
    /// channel at the estimate's vertices (`estimate_vertices`): each face's standard error
    /// (`PerSource::sampling_error`, its sub-points taken as independent) carried to the
    /// receiver by the profile over the face (`face_weight`), Var B(x) = sum_f (int_f
    /// R(|x - y|) dy sigma_f)^2, the bounce's error at each corner carried by its share of
    /// its faces' weights (the faces take their bounce from their corners, `bounce_at`), and
    /// the point mass's share of the vertex's own error. Zero
    /// where nothing is sampled (suns, points and spots are exact up to their shadows).
    fn irradiance_noise(&self, b: &[[f32; 3]]) -> [f64; 3] {
        let Some((_, lookup, rgb)) = &self.profiles else {
            return [0.0; 3];
        };
        let sub = self.face_sources.sampling_error();
        let zero = |e: &[f32; 3]| e.iter().all(|x| *x == 0.0);
        let vertex_error = self.vertex_sources.sampling_error();
        if sub.iter().all(zero) && vertex_error.iter().all(zero) {
            return [0.0; 3];
        }
        // Per face: its sub-points' errors, each standing for its share of the face.
        let mut next = sub.iter();
        let faces: Vec<[f64; 3]> = (self.split.iter())
            .map(|&four| {
                let k = if four { 4 } else { 1 };
                let mut var = [0.0f64; 3];
                for _ in 0..k {
                    let e = next.next().copied().unwrap_or([0.0; 3]);
                    for c in 0..3 {
                        var[c] += (f64::from(e[c]) / k as f64).powi(2);
                    }
                }
                var.map(f64::sqrt)
            })
            .collect();
        let masses: [f64; 3] = std::array::from_fn(|c| lookup[c].point_mass());
        let picks = self.estimate_vertices();
        if picks.is_empty() {
            return [0.0; 3];
        }
        let positions = self.scene.mesh.positions();
        let areas = self.scene.mesh.vertex_areas();
        let object = |v: usize| self.scene.mesh.object_of_vertex(v);
        let support = lookup.iter().map(|p| p.support()).fold(0.0, f64::max);
        let per_pick: Vec<(f64, [f64; 3], [f64; 3])> = picks
            .par_iter()
            .map(|&v| {
                let x = positions[v].as_dvec3();
                let mut var = [0.0f64; 3];
                // Each corner's share of the faces' bounce here (a third of each face's).
                let mut corners: rustc_hash::FxHashMap<u32, [f64; 3]> = Default::default();
                for (f, face) in self.faces.iter().enumerate() {
                    let r = (face.centroid - x).length();
                    if r - face.diam >= support
                        || self.scene.mesh.object_of_triangle(f) != object(v)
                    {
                        continue;
                    }
                    let w = face_weight(face, x, r, rgb);
                    for c in 0..3 {
                        var[c] += (w[c] * faces[f][c]).powi(2);
                    }
                    if !self.vertex_bounce.is_empty() {
                        for &k in &self.scene.mesh.triangles()[f] {
                            let share = corners.entry(k).or_default();
                            (0..3).for_each(|c| share[c] += w[c] / 3.0);
                        }
                    }
                }
                // The corners' bounce is shared by their faces: each corner's error carried
                // once, by its share of them all; the ring average's bias, the same way but
                // added before squaring (it does not average out).
                let mut bias = [0.0f64; 3];
                for (k, share) in &corners {
                    let e = self.vertex_bounce[*k as usize].1;
                    let moved = self.vertex_bounce_bias[*k as usize];
                    for c in 0..3 {
                        var[c] += (share[c] * f64::from(e[c])).powi(2);
                        bias[c] += share[c] * f64::from(moved[c]);
                    }
                }
                (0..3).for_each(|c| var[c] += bias[c] * bias[c]);
                if let Some(e) = vertex_error.get(v) {
                    for c in 0..3 {
                        var[c] += (masses[c] * f64::from(e[c])).powi(2);
                    }
                }
                (f64::from(areas[v]), var, b[v].map(f64::from))
            })
            .collect();
        std::array::from_fn(|c| {
            let (num, den) = per_pick.iter().fold((0.0, 0.0), |(n, d), (a, var, bv)| {
                (n + a * var[c], d + a * bv[c] * bv[c])
            });
            if den > 0.0 {
                (num / den).sqrt()
            } else {
                0.0
            }
        })
    }

    /// B at the rim's vertices (every vertex with `Receivers::Vertices`), each refined from the
    /// root (Mertens 2003 §3.2's refinement with the vertex as a point receiver); render and
    /// incremental modes keep the links until the material or the shape changes. `progress`
    /// hears of [0.3, 0.9] over the vertices when they are every receiver ([0.9, 0.95] for a
    /// rim beside the faces); a cancel drops the kept links.
    fn gather_at_rim(
        &mut self,
        material_changed: bool,
        geometry_changed: bool,
        every: bool,
        report: &mut HierarchyReport,
        progress: Option<&ProgressFn>,
    ) -> Result<Vec<[f64; 3]>> {
        let Some((_, lookup, rgb)) = &self.profiles else {
            return Err(Error::InvalidArgument("no profiles prepared".into()));
        };
        let keep = self.settings.mode != Mode::OnTheFly;
        let ctx = self.context(lookup, rgb, !keep, 1.0);
        let positions = self.scene.mesh.positions();
        let fresh =
            !keep || material_changed || geometry_changed || self.rim_links.len() != self.rim.len();
        let (from, to) = if every { (0.3, 0.9) } else { (0.9, 0.95) };
        let ticker = Ticker::span(progress, self.rim.len() as u64, from, to);
        if !keep {
            // On-the-fly: each vertex's links gathered as soon as refined, none kept.
            let gathered: Vec<([f64; 3], u64, u64)> = (self.rim.par_iter())
                .map(|&v| {
                    if !ticker.add(1) {
                        return ([0.0; 3], 0, 0);
                    }
                    let l = ctx.links_at(positions[v as usize].as_dvec3());
                    (ctx.gather_at(&l), l.far.len() as u64, l.near_count() as u64)
                })
                .collect();
            if ticker.stopped() {
                return Err(Error::Cancelled);
            }
            report.far_links += gathered.iter().map(|g| g.1).sum::<u64>();
            report.near_links += gathered.iter().map(|g| g.2).sum::<u64>();
            report.relinked |= every;
            self.rim_links.clear();
            return Ok(gathered.into_iter().map(|g| g.0).collect());
        }
        let relinked: Vec<NodeLinks> = if fresh {
            (self.rim.par_iter())
                .map(|&v| {
                    if !ticker.add(1) {
                        return NodeLinks::default();
                    }
                    ctx.links_at(positions[v as usize].as_dvec3())
                })
                .collect()
        } else {
            Vec::new()
        };
        if ticker.stopped() {
            self.rim_links.clear();
            return Err(Error::Cancelled);
        }
        let links = if fresh { &relinked } else { &self.rim_links };
        // The vertices' own links count with the faces'.
        report.far_links += links.iter().map(|l| l.far.len() as u64).sum::<u64>();
        report.near_links += links.iter().map(|l| l.near_count() as u64).sum::<u64>();
        let at_rim: Vec<[f64; 3]> = links.par_iter().map(|l| ctx.gather_at(l)).collect();
        if fresh {
            report.relinked |= every;
            self.rim_links = if keep { relinked } else { Vec::new() };
        }
        Ok(at_rim)
    }

    /// The error estimate with every vertex a receiver: `estimate_receivers` vertices spread
    /// over the mesh refined again with ε/4, their area-weighted relative RMS against `b` (B
    /// at `self.rim`, which is then every vertex).
    fn estimate_at_vertices(&self, b: &[[f64; 3]]) -> Option<[f64; 3]> {
        let picks = spread(self.rim.len(), self.settings.estimate_receivers);
        let (_, lookup, rgb) = self.profiles.as_ref()?;
        if picks.is_empty() {
            return None;
        }
        let ctx = self.context(lookup, rgb, true, 0.25);
        let positions = self.scene.mesh.positions();
        let areas = self.scene.mesh.vertex_areas();
        let fine: Vec<[f64; 3]> = (picks.par_iter())
            .map(|&i| ctx.gather_at(&ctx.links_at(positions[self.rim[i] as usize].as_dvec3())))
            .collect();
        let pairs = picks.iter().zip(&fine).map(|(&i, f)| {
            let a = f64::from(areas[self.rim[i] as usize]);
            (a, b[i], *f)
        });
        Some(relative_rms(pairs))
    }

    /// Links and gather by mode; returns B per face. `progress` hears of [0.3, 0.9] over the
    /// receivers refined; a cancel drops the links (the next evaluation refines from the root).
    fn evaluate(
        &mut self,
        lookup: &[LookupProfile; 3],
        rgb: &LookupRgb,
        material_changed: bool,
        geometry_changed: bool,
        report: &mut HierarchyReport,
        progress: Option<&ProgressFn>,
    ) -> Result<Vec<[f64; 3]>> {
        let mode = self.settings.mode;
        let root = self.tree.root();
        let n = self.tree.len();
        let t = Instant::now();
        let ticker = Ticker::span(progress, n as u64, 0.3, 0.9);
        let cancelled = |h: &mut Hierarchy| {
            h.slots.clear();
            h.has_links = false;
            Err(Error::Cancelled)
        };
        let counts: LinkCounts;
        if mode == Mode::OnTheFly || !self.has_links {
            // From the root: refine and gather in one traversal.
            let keep = mode != Mode::OnTheFly;
            let mut slots = std::mem::take(&mut self.slots);
            slots.clear();
            slots.resize_with(n, Slot::default);
            let ctx = Context {
                ticker: Some(&ticker),
                ..self.context(lookup, rgb, !keep, 1.0)
            };
            counts = ctx.visit(root, vec![root], [0.0; 3], &mut slots, None, keep);
            if ticker.stopped() {
                return cancelled(self);
            }
            self.slots = slots;
            self.has_links = keep;
            report.relinked = true;
            report.seconds_links = t.elapsed().as_secs_f64();
        } else if mode == Mode::Incremental && (material_changed || geometry_changed) {
            let previous = std::mem::take(&mut self.slots);
            let mut slots: Vec<Slot> = Vec::new();
            slots.resize_with(n, Slot::default);
            let ctx = Context {
                ticker: Some(&ticker),
                ..self.context(lookup, rgb, false, 1.0)
            };
            counts = ctx.visit(
                root,
                Vec::new(),
                [0.0; 3],
                &mut slots,
                Some(&previous),
                true,
            );
            if ticker.stopped() {
                return cancelled(self);
            }
            self.slots = slots;
            report.relinked = true;
            report.seconds_links = t.elapsed().as_secs_f64();
        } else {
            // Same links: the near form factors again if the profile or the shape changed,
            // then gather (par over receivers) and push (top-down).
            let mut slots = std::mem::take(&mut self.slots);
            let ctx = self.context(lookup, rgb, false, 1.0);
            if material_changed || geometry_changed {
                slots.par_iter_mut().enumerate().for_each(|(r, s)| {
                    ctx.refresh_near(r as u32, &mut s.links);
                    s.links.far_factors = ctx.far_factors(r as u32, &s.links.far);
                });
            }
            slots.par_iter_mut().enumerate().for_each(|(r, s)| {
                s.radiosity = ctx.gather(r as u32, &s.links);
            });
            report.seconds_links = t.elapsed().as_secs_f64();
            let t = Instant::now();
            for node in (0..n).rev() {
                let p = self.tree.parent[node];
                if p != u32::MAX {
                    let up = slots[p as usize].radiosity;
                    (0..3).for_each(|c| slots[node].radiosity[c] += up[c]);
                }
            }
            report.seconds_push = t.elapsed().as_secs_f64();
            let mut c = LinkCounts::default();
            for s in &slots {
                c.far += s.links.far.len() as u64;
                c.near += s.links.near_count() as u64;
            }
            counts = c;
            self.slots = slots;
        }
        report.far_links = counts.far;
        report.near_links = counts.near;
        report.oracle_tests = counts.oracle_tests;
        report.dropped_beyond_support = counts.dropped_beyond_support;

        let mut face_b = vec![[0.0f64; 3]; self.faces.len()];
        for node in 0..n {
            let f = self.tree.face[node];
            if f != u32::MAX {
                face_b[f as usize] = self.slots[node].radiosity;
            }
        }
        tick(progress, 0.9)?;
        // The error estimate: a few faces again with ε/4, from the root.
        let t = Instant::now();
        report.error_estimate = self.estimate(lookup, rgb, &face_b);
        report.seconds_estimate = t.elapsed().as_secs_f64();
        Ok(face_b)
    }

    fn estimate(
        &self,
        lookup: &[LookupProfile; 3],
        rgb: &LookupRgb,
        face_b: &[[f64; 3]],
    ) -> Option<[f64; 3]> {
        let k = self.settings.estimate_receivers.min(self.faces.len());
        if k == 0 {
            return None;
        }
        let leaves: Vec<u32> = (0..self.tree.len() as u32)
            .filter(|&r| self.tree.is_leaf(r))
            .collect();
        let step = leaves.len() as f64 / k as f64;
        let picks: Vec<u32> = (0..k).map(|i| leaves[(i as f64 * step) as usize]).collect();
        let ctx = self.context(lookup, rgb, true, 0.25);
        let root = self.tree.root();
        let fine: Vec<[f64; 3]> = picks
            .par_iter()
            .map(|&r| {
                let mut slot = [Slot::default()];
                ctx.visit(r, vec![root], [0.0; 3], &mut slot, None, false);
                slot[0].radiosity
            })
            .collect();
        let pairs = picks.iter().zip(&fine).map(|(&r, f)| {
            let i = self.tree.face[r as usize] as usize;
            (self.faces[i].area, face_b[i], *f)
        });
        Some(relative_rms(pairs))
    }

    /// Radiance toward `eye` (along each vertex normal without one): L = W(cos_o) B / π with
    /// W the profile's exit weight (dipole: F_t, Xu 2007 eq. 2; Cycles: the Principled layers).
    pub fn radiance(&mut self, material: &Material, eye: Option<Vec3>) -> Result<Evaluation> {
        self.radiance_with_progress(material, eye, None)
    }

    /// `radiance` reporting `progress` as `radiosity_with_progress` does.
    pub fn radiance_with_progress(
        &mut self,
        material: &Material,
        eye: Option<Vec3>,
        progress: Option<&ProgressFn>,
    ) -> Result<Evaluation> {
        crate::evaluation::check_eye(eye)?;
        let start = Instant::now();
        let mut e = self.radiosity_with_progress(material, progress)?;
        self.turn_to_radiance(&mut e, material, eye, start)?;
        Ok(e)
    }

    /// `e` (B per vertex) as radiance toward `eye` through `material`'s exit weight and view
    /// factor, its seconds counted from `start`.
    fn turn_to_radiance(
        &self,
        e: &mut Evaluation,
        material: &Material,
        eye: Option<Vec3>,
        start: Instant,
    ) -> Result<()> {
        let model = self.settings.profile;
        let profiles = model.profiles(material)?;
        let exit = |cos_o| model.exit_weights(material, &profiles, cos_o);
        e.into_radiance(&self.scene.mesh, eye, &exit, start);
        Ok(())
    }

    /// The links stored per receiver (render and incremental modes), for tests and tools: per
    /// vertex with `Receivers::Vertices`, per cluster with `Receivers::Faces`.
    pub fn links(&self) -> Option<Vec<&NodeLinks>> {
        if self.settings.receivers == Receivers::Vertices {
            return (!self.rim_links.is_empty()).then(|| self.rim_links.iter().collect());
        }
        self.has_links
            .then(|| self.slots.iter().map(|s| &s.links).collect())
    }
}

#[cfg(test)]
mod tests;

//! A scene: one mesh carrying the translucent material, the lights and the world around it, and
//! the rest of the scene that shadows it (`Occluders`).

use crate::error::{Error, Result};
use crate::lights::{Light, World};
use crate::mesh::Mesh;
use crate::occluders::{OccluderReport, Occluders};
use crate::raytrace::Tracer;
use std::sync::Arc;

/// Cycles' light and shadow linking of one light (`Scene::link_light`, `Scene::link_shadows`).
/// Occluder objects by their place among the objects added, the mesh's objects by their index
/// (`Mesh::with_objects`; 0 for a mesh of one); an object past a list's end is in it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LightLinking {
    /// The occluder objects that cast its shadows (its blocker collection); None: every one.
    pub blockers: Option<Vec<bool>>,
    /// The mesh's objects that cast its shadows; None: every one.
    pub mesh_blockers: Option<Vec<bool>>,
    /// The occluder objects it lights (its receiver collection), and so the ones that send
    /// it back as the bounce; None: every one.
    pub receivers: Option<Vec<bool>>,
    /// The mesh's objects it lights; None: every one. An object left out gets none of its
    /// direct light; what the occluders it lights send back still reaches it (Cycles links a
    /// light to the surface it shades, so an object left out still receives that light from
    /// the objects left in).
    pub mesh_receivers: Option<Vec<bool>>,
}

impl LightLinking {
    /// Whether the mesh's object `object` is lit.
    pub fn lights_object(&self, object: u32) -> bool {
        in_mask(self.mesh_receivers.as_deref(), object)
    }

    /// Whether it lights none of the mesh's objects (`Scene::link_light` with no object).
    pub fn lights_no_mesh_object(&self) -> bool {
        (self.mesh_receivers.as_ref()).is_some_and(|m| m.iter().all(|&x| !x))
    }

    /// Whether the mesh's object `object` casts the shadows.
    pub fn mesh_object_blocks(&self, object: u32) -> bool {
        in_mask(self.mesh_blockers.as_deref(), object)
    }

    /// Whether occluder object `object` is lit (and so sends the light back).
    pub fn lights_occluder(&self, object: u32) -> bool {
        in_mask(self.receivers.as_deref(), object)
    }

    /// Whether occluder object `object` casts the shadows.
    pub fn occluder_blocks(&self, object: u32) -> bool {
        in_mask(self.blockers.as_deref(), object)
    }
}

/// Whether a mask (None: everything) holds `k` (past its end: it does).
fn in_mask(mask: Option<&[bool]>, k: u32) -> bool {
    mask.is_none_or(|m| m.get(k as usize).copied().unwrap_or(true))
}

/// One light's linking, shared between the scene and the tracers cast for it.
pub type Linking = Arc<LightLinking>;

/// Everything a method needs besides the material.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mesh: Mesh,
    pub lights: Vec<Light>,
    pub world: World,
    /// Other objects: they cast shadows on `mesh` and send light back by their albedo, and do
    /// not scatter.
    pub occluders: Occluders,
    /// Light and shadow linking (Cycles' receiver and blocker collections), per light by its
    /// place in `lights` (`link_light`, `link_shadows`); None, or no entry: unlinked.
    pub linking: Vec<Option<Linking>>,
}

impl Scene {
    pub fn new(mesh: Mesh) -> Self {
        Self {
            mesh,
            lights: Vec::new(),
            world: World::Black,
            occluders: Occluders::default(),
            linking: Vec::new(),
        }
    }

    /// A copy of the mesh and the occluders with no light, world or linking: for a caller
    /// that adds the lights again while the rest of the scene stays as it was (the add-on's
    /// light drag, which would otherwise export the meshes again for every step).
    pub fn without_lights(&self) -> Scene {
        Scene {
            mesh: self.mesh.clone(),
            lights: Vec::new(),
            world: World::Black,
            occluders: self.occluders.clone(),
            linking: Vec::new(),
        }
    }

    /// Shadow linking for light `light` (its place in `lights`): only the occluders named in
    /// `blockers` cast its shadows (every occluder added under such a name), and of the mesh
    /// the objects `mesh` holds (`Mesh::with_objects`' indices; None: all). Errors name an
    /// unknown light, occluder or object.
    pub fn link_shadows(
        &mut self,
        light: usize,
        blockers: &[String],
        mesh: Option<&[u32]>,
    ) -> Result<()> {
        let mask = self.occluder_mask(light, "blockers", blockers)?;
        let objects = self.object_mask("mesh", mesh)?;
        self.relink(light, |l| {
            l.blockers = Some(mask);
            l.mesh_blockers = objects;
        });
        Ok(())
    }

    /// Light linking for light `light` (its place in `lights`): it lights only the occluders
    /// named in `receivers` (and only they send it back as the bounce), and of the mesh the
    /// objects `mesh` holds (None: all). Errors name an unknown light, occluder or object.
    pub fn link_light(
        &mut self,
        light: usize,
        receivers: &[String],
        mesh: Option<&[u32]>,
    ) -> Result<()> {
        let mask = self.occluder_mask(light, "receivers", receivers)?;
        let objects = self.object_mask("mesh", mesh)?;
        self.relink(light, |l| {
            l.receivers = Some(mask);
            l.mesh_receivers = objects;
        });
        Ok(())
    }

    /// How many objects the mesh holds (`Mesh::with_objects`; 1 without).
    pub fn mesh_object_count(&self) -> usize {
        (self.mesh.objects()).map_or(1, |o| o.iter().max().map_or(1, |m| *m as usize + 1))
    }

    /// Per object of the mesh, whether `objects` holds it (None: all, no mask); errors name
    /// an object the mesh does not hold.
    fn object_mask(&self, what: &str, objects: Option<&[u32]>) -> Result<Option<Vec<bool>>> {
        let Some(objects) = objects else {
            return Ok(None);
        };
        let count = self.mesh_object_count();
        if let Some(o) = objects.iter().find(|&&o| o as usize >= count) {
            return Err(Error::InvalidArgument(format!(
                "{what}: object {o}, but the mesh holds {count} object(s)"
            )));
        }
        Ok(Some(
            (0..count as u32).map(|k| objects.contains(&k)).collect(),
        ))
    }

    /// Per occluder object, whether `names` names it; errors name an unknown light or name.
    fn occluder_mask(&self, light: usize, what: &str, names: &[String]) -> Result<Vec<bool>> {
        if light >= self.lights.len() {
            return Err(Error::InvalidArgument(format!(
                "light {light}: the scene has {} lights",
                self.lights.len()
            )));
        }
        if let Some(b) = (names.iter()).find(|b| !self.occluders.names().any(|n| n == *b)) {
            return Err(Error::InvalidArgument(format!(
                "{what}: no occluder named {b:?}"
            )));
        }
        Ok((self.occluders.names())
            .map(|n| names.iter().any(|b| b == n))
            .collect())
    }

    fn relink(&mut self, light: usize, change: impl FnOnce(&mut LightLinking)) {
        if self.linking.len() < self.lights.len() {
            self.linking.resize(self.lights.len(), None);
        }
        let mut l = self.linking[light].as_deref().cloned().unwrap_or_default();
        change(&mut l);
        self.linking[light] = Some(Arc::new(l));
    }

    /// Light `light`'s linking (`link_light`, `link_shadows`), None: unlinked.
    pub fn linking_of(&self, light: usize) -> Option<Linking> {
        self.linking.get(light).cloned().flatten()
    }

    /// The tracer shadow rays of this scene are cast with: `mesh_tracer` (built over `mesh`)
    /// with the occluders that can shadow the mesh under the current lights and world, and
    /// every occluder with its albedo where some sends light back (the irradiance's bounce),
    /// and what was kept of them. The mesh's BVH is shared, not rebuilt.
    pub fn shadow_tracer(&self, mesh_tracer: &Tracer) -> (Tracer, OccluderReport) {
        let (kept, objects, report) =
            (self.occluders).relevant_of(self.mesh.bounds(), &self.lights, &self.world);
        let tracer = mesh_tracer
            .with_occluder_objects(&kept, &objects)
            .with_bounce(self.occluders.bouncing());
        (tracer, report)
    }

    /// `shadow_tracer` over a BVH of the mesh built here.
    pub fn tracer(&self) -> Tracer {
        self.shadow_tracer(&Tracer::new(&self.mesh)).0
    }
}

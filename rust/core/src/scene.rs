//! A scene: one mesh carrying the translucent material, the lights and the world around it, and
//! the rest of the scene that shadows it (`Occluders`).

use crate::error::{Error, Result};
use crate::lights::{Light, World};
use crate::mesh::Mesh;
use crate::occluders::{OccluderReport, Occluders};
use crate::raytrace::Tracer;
use std::sync::Arc;

/// The occluder objects that cast one light's shadows (`Scene::link_shadows`), by their place
/// among the objects added.
pub type Blockers = Arc<Vec<bool>>;

/// Everything a method needs besides the material.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mesh: Mesh,
    pub lights: Vec<Light>,
    pub world: World,
    /// Other objects: they cast shadows on `mesh` and send light back by their albedo, and do
    /// not scatter.
    pub occluders: Occluders,
    /// Shadow linking (Cycles' blocker collections), per light by its place in `lights`: which
    /// occluder objects cast its shadows (`link_shadows`); None, or no entry: every one. The
    /// mesh always casts them.
    pub shadow_blockers: Vec<Option<Blockers>>,
}

impl Scene {
    pub fn new(mesh: Mesh) -> Self {
        Self {
            mesh,
            lights: Vec::new(),
            world: World::Black,
            occluders: Occluders::default(),
            shadow_blockers: Vec::new(),
        }
    }

    /// Shadow linking for light `light` (its place in `lights`): only the occluders named in
    /// `blockers` cast its shadows (every occluder added under such a name), the mesh always.
    /// Errors name an unknown light or occluder.
    pub fn link_shadows(&mut self, light: usize, blockers: &[String]) -> Result<()> {
        if light >= self.lights.len() {
            return Err(Error::InvalidArgument(format!(
                "light {light}: the scene has {} lights",
                self.lights.len()
            )));
        }
        if let Some(b) = (blockers.iter()).find(|b| !self.occluders.names().any(|n| n == *b)) {
            return Err(Error::InvalidArgument(format!(
                "blockers: no occluder named {b:?}"
            )));
        }
        let mask = (self.occluders.names())
            .map(|n| blockers.iter().any(|b| b == n))
            .collect();
        if self.shadow_blockers.len() < self.lights.len() {
            self.shadow_blockers.resize(self.lights.len(), None);
        }
        self.shadow_blockers[light] = Some(Arc::new(mask));
        Ok(())
    }

    /// The occluder objects that cast light `light`'s shadows (`link_shadows`), None: all.
    pub fn blockers_of(&self, light: usize) -> Option<Blockers> {
        self.shadow_blockers.get(light).cloned().flatten()
    }

    /// Whether some light's shadows are linked (`link_shadows`).
    pub fn links_shadows(&self) -> bool {
        self.shadow_blockers.iter().any(Option::is_some)
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

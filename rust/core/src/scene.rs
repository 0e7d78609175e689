//! A scene: one mesh carrying the translucent material, the lights and the world around it, and
//! the rest of the scene that shadows it (`Occluders`).

use crate::lights::{Light, World};
use crate::mesh::Mesh;
use crate::occluders::{OccluderReport, Occluders};
use crate::raytrace::Tracer;

/// Everything a method needs besides the material.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mesh: Mesh,
    pub lights: Vec<Light>,
    pub world: World,
    /// Other objects: they cast shadows on `mesh` and send light back by their albedo, and do
    /// not scatter.
    pub occluders: Occluders,
}

impl Scene {
    pub fn new(mesh: Mesh) -> Self {
        Self {
            mesh,
            lights: Vec::new(),
            world: World::Black,
            occluders: Occluders::default(),
        }
    }

    /// The tracer shadow rays of this scene are cast with: `mesh_tracer` (built over `mesh`)
    /// with the occluders that can shadow the mesh under the current lights and world, and
    /// every occluder with its albedo where some sends light back (the irradiance's bounce),
    /// and what was kept of them. The mesh's BVH is shared, not rebuilt.
    pub fn shadow_tracer(&self, mesh_tracer: &Tracer) -> (Tracer, OccluderReport) {
        let (kept, report) = self
            .occluders
            .relevant(self.mesh.bounds(), &self.lights, &self.world);
        let tracer = mesh_tracer
            .with_occluders(&kept)
            .with_bounce(self.occluders.bouncing());
        (tracer, report)
    }

    /// `shadow_tracer` over a BVH of the mesh built here.
    pub fn tracer(&self) -> Tracer {
        self.shadow_tracer(&Tracer::new(&self.mesh)).0
    }
}

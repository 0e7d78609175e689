//! A scene: one mesh carrying the translucent material, the lights and the world around it.

use crate::lights::{Light, World};
use crate::mesh::Mesh;

/// Everything a method needs besides the material.
#[derive(Debug, Clone)]
pub struct Scene {
    pub mesh: Mesh,
    pub lights: Vec<Light>,
    pub world: World,
}

impl Scene {
    pub fn new(mesh: Mesh) -> Self {
        Self {
            mesh,
            lights: Vec::new(),
            world: World::Black,
        }
    }
}

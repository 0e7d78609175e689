//! STUB (helper replaces)
use crate::mesh::Mesh;
use glam::Vec3;
pub struct Tracer;
pub struct Hit {
    pub t: f32,
    pub triangle: u32,
}
impl Tracer {
    pub fn new(_mesh: &Mesh) -> Tracer {
        Tracer
    }
    pub fn occluded(&self, _o: Vec3, _d: Vec3, _t: f32) -> bool {
        unimplemented!()
    }
    pub fn intersect(&self, _o: Vec3, _d: Vec3, _t: f32) -> Option<Hit> {
        unimplemented!()
    }
}

//! Where Cycles' vertex bake samples a vertex: Blender bakes a vertex colour as the mean over
//! the vertex's corners of Cycles' answer at a point moved from the vertex towards the corner
//! triangle's centroid by min(that distance, 1e-4 max(1, max_i |P_i|)), P the vertex's
//! position (`bake_offset_towards_center`, intern/cycles/kernel/integrator/init_from_bake.h),
//! shaded there with the smooth normal interpolated at that point (`triangle_smooth_normal`).
//!
//! Where the radiance changes within that offset (an open mesh's rim, a spike's apex whose
//! triangles face 60-90 degrees away from the vertex normal) the bake is not the radiance at
//! the vertex: measured on the horse's spike apex (vertex 11890, ketchup, 4,096 walks), the
//! walk entering at the vertex gives 0.02 of the mean blue, the mean over its five bake
//! points 48.8, the 1024-spp bake 52.3. The walks through the mesh (`walks`) enter at these
//! points so that a vertex means what a vertex bake means.

use crate::mesh::{barycentric, interpolated_normal, Mesh};
use glam::Vec3;

/// Cycles' `position_offset`: the offset's length per unit of the vertex's largest coordinate
/// (at least 1).
pub const POSITION_OFFSET: f32 = 1e-4;

/// One corner's sample point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BakePoint {
    pub position: Vec3,
    /// The smooth normal interpolated at `position` (Cycles' shading normal N).
    pub normal: Vec3,
    /// The corner triangle's own normal (Cycles' Ng).
    pub face_normal: Vec3,
}

/// Every vertex's corner sample points (degenerate triangles have none).
#[derive(Debug, Clone)]
pub struct BakePoints {
    start: Vec<u32>,
    points: Vec<BakePoint>,
}

impl BakePoints {
    pub fn new(mesh: &Mesh) -> Self {
        let (p, nrm) = (mesh.positions(), mesh.normals());
        let mut corners: Vec<(u32, BakePoint)> = Vec::with_capacity(3 * mesh.triangles().len());
        for tri in mesh.triangles() {
            let x = tri.map(|i| p[i as usize]);
            let Some(face) = (x[1] - x[0]).cross(x[2] - x[0]).try_normalize() else {
                continue;
            };
            let centre = (x[0] + x[1] + x[2]) / 3.0;
            for k in 0..3 {
                let to_centre = centre - x[k];
                let reach = POSITION_OFFSET * x[k].abs().max_element().max(1.0);
                let position = x[k] + to_centre.clamp_length_max(reach);
                let normal = match barycentric(&x, position) {
                    Some(w) => interpolated_normal(&tri.map(|i| nrm[i as usize]), w[1], w[2], face),
                    None => face,
                };
                corners.push((
                    tri[k],
                    BakePoint {
                        position,
                        normal,
                        face_normal: face,
                    },
                ));
            }
        }
        // Stable: a vertex's corners in triangle order.
        corners.sort_by_key(|(v, _)| *v);
        let mut start = vec![0u32; mesh.vertex_count() + 1];
        for (v, _) in &corners {
            start[*v as usize + 1] += 1;
        }
        for i in 0..mesh.vertex_count() {
            start[i + 1] += start[i];
        }
        Self {
            start,
            points: corners.into_iter().map(|(_, b)| b).collect(),
        }
    }

    /// The sample points of vertex `v`'s corners (empty for a vertex only in degenerate
    /// triangles).
    pub fn of(&self, v: u32) -> &[BakePoint] {
        let v = v as usize;
        &self.points[self.start[v] as usize..self.start[v + 1] as usize]
    }
}

/// Vertices whose bake points may see another radiance than the vertex itself: on an open
/// edge (`Mesh::open_edge_vertices`: the rim of the bunny's open base, where the bake is 1.3-2.4x
/// the radiance at the vertex in blue in every material), or with a corner triangle facing
/// more than acos(`facing`) away from the vertex normal (a spike's apex). Counted with
/// `facing` 0.5 on this project's meshes: Suzanne 168 (all on open edges), the bunny at 10 cm
/// 223 on open edges and 28 by facing, the horse 126 by facing, of 8k-48k vertices.
pub fn sharp_vertices(mesh: &Mesh, facing: f32) -> Vec<bool> {
    let (p, nrm) = (mesh.positions(), mesh.normals());
    let mut sharp = mesh.open_edge_vertices();
    for tri in mesh.triangles() {
        let x = tri.map(|i| p[i as usize]);
        if let Some(face) = (x[1] - x[0]).cross(x[2] - x[0]).try_normalize() {
            for &v in tri {
                let n = nrm[v as usize];
                sharp[v as usize] |= n != Vec3::ZERO && face.dot(n) < facing;
            }
        }
    }
    sharp
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fan of `k` triangles about a vertex at `apex`, their far corners on a circle of
    /// radius `size` at height `-drop size` (a spike's apex when `drop` is large).
    fn fan(k: usize, apex: Vec3, drop: f32, size: f32) -> Mesh {
        let mut p = vec![apex];
        for i in 0..k {
            let a = std::f32::consts::TAU * i as f32 / k as f32;
            p.push(apex + size * Vec3::new(a.cos(), a.sin(), -drop));
        }
        let t: Vec<[u32; 3]> = (0..k as u32)
            .map(|i| [0, 1 + i, 1 + (i + 1) % k as u32])
            .collect();
        Mesh::new(p, t, None).unwrap()
    }

    #[test]
    fn each_corner_point_lies_the_offset_towards_its_centroid() {
        for (apex, reach) in [(Vec3::ZERO, 1e-4), (Vec3::new(0.0, -40.0, 3.0), 4e-3)] {
            let mesh = fan(5, apex, 0.5, 1.0);
            let b = BakePoints::new(&mesh);
            assert_eq!(b.of(0).len(), 5);
            for (i, q) in b.of(0).iter().enumerate() {
                let x = [1 + i, 1 + (i + 1) % 5].map(|j| mesh.positions()[j]);
                let centre = (apex + x[0] + x[1]) / 3.0;
                // Independent of the code: the point on the segment apex -> centroid at
                // distance `reach` (1e-4 per unit of the largest |coordinate|, at least 1).
                let want = apex + (centre - apex).normalize() * reach;
                assert!(
                    q.position.distance(want) < 1e-6 * reach.max(1.0) + 1e-9,
                    "{:?} vs {want:?}",
                    q.position
                );
                let face = (x[0] - apex).cross(x[1] - apex).normalize();
                assert!(q.face_normal.distance(face) < 1e-5);
            }
        }
        // A far corner of a fan 1e-6 across: the offset is capped by the distance itself.
        let small = fan(3, Vec3::ZERO, 0.0, 1.0);
        let tiny = Mesh::new(
            small.positions().iter().map(|&x| x * 1e-6).collect(),
            small.triangles().to_vec(),
            None,
        )
        .unwrap();
        let x = tiny.positions();
        let centre = (x[0] + x[1] + x[2]) / 3.0;
        assert!(BakePoints::new(&tiny).of(1)[0].position.distance(centre) < 1e-12);
    }

    #[test]
    fn open_edges_and_apexes_are_sharp() {
        // A flat fan: its centre is neither (every triangle faces along its normal), its rim
        // is an open edge.
        let flat = fan(6, Vec3::ZERO, 0.0, 1.0);
        assert_eq!(
            sharp_vertices(&flat, 0.5),
            [vec![false], vec![true; 6]].concat()
        );
        // A spike closed by a base: the apex's triangles face 66.6 degrees away (cos 0.40).
        let spike = fan(6, Vec3::ZERO, 2.0, 1.0);
        let mut t = spike.triangles().to_vec();
        t.extend((1..5u32).map(|i| [1, i + 2, i + 1]));
        let closed = Mesh::new(spike.positions().to_vec(), t, None).unwrap();
        let apex = |facing| sharp_vertices(&closed, facing)[0];
        assert!(apex(0.5) && !apex(0.35));
    }

    #[test]
    fn the_normal_is_the_smooth_one_at_the_point() {
        // A spike 0.3 mm across (the horse's): its apex normal points up the axis, its
        // triangles face 63 degrees away from it; 0.1 mm from the apex the normal lies between.
        let mesh = fan(6, Vec3::ZERO, 2.0, 1.5e-4);
        let b = BakePoints::new(&mesh);
        let apex_n = mesh.normals()[0];
        for q in b.of(0) {
            let c = q.normal.dot(apex_n);
            assert!((q.normal.length() - 1.0).abs() < 1e-5);
            assert!(c > q.face_normal.dot(apex_n) && c < 0.99, "{c}");
        }
    }
}

//! A uniform hash grid over vertices, and the kernel average over it that carries the walk
//! term's D from the walked vertices to their neighbours (`term`).

use crate::mesh::Mesh;
use glam::Vec3;
use std::collections::HashMap;

/// A uniform hash grid over candidate vertices.
pub(super) struct Grid {
    cell: f32,
    cells: HashMap<[i32; 3], Vec<usize>>,
}

impl Grid {
    pub(super) fn new(mesh: &Mesh, candidates: &[u32], cell: f32) -> Grid {
        let cell = cell.max(f32::MIN_POSITIVE);
        let mut cells: HashMap<[i32; 3], Vec<usize>> = HashMap::new();
        for (i, &v) in candidates.iter().enumerate() {
            let k = (mesh.positions()[v as usize] / cell)
                .floor()
                .as_ivec3()
                .to_array();
            cells.entry(k).or_default().push(i);
        }
        Grid { cell, cells }
    }

    pub(super) fn visit(&self, p: Vec3, mut f: impl FnMut(usize)) {
        let k = (p / self.cell).floor().as_ivec3().to_array();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = self.cells.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                        list.iter().for_each(|&i| f(i));
                    }
                }
            }
        }
    }

    /// Kernel average of the candidates' D at vertex v, (1 - d^2/R^2)^2 times the cosine
    /// between the normals (candidates facing away are left out: the two sides of an ear;
    /// so are those of the other `class`: embedded or exposed), and the variance of that
    /// average.
    pub(super) fn average(
        &self,
        mesh: &Mesh,
        v: u32,
        candidates: &[u32],
        diff: &[([f32; 3], [f32; 3])],
        class: &[bool],
    ) -> ([f32; 3], [f32; 3]) {
        let (p, n) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
        let own = class[v as usize];
        let r2 = self.cell * self.cell;
        let mut wsum = 0f32;
        let (mut acc, mut var) = ([0f32; 3], [0f32; 3]);
        self.visit(p, |i| {
            let u = candidates[i] as usize;
            let d2 = mesh.positions()[u].distance_squared(p);
            let cos = mesh.normals()[u].dot(n);
            if d2 < r2 && cos > 0.0 && class[u] == own {
                let w = (1.0 - d2 / r2).powi(2) * cos;
                wsum += w;
                for c in 0..3 {
                    acc[c] += w * diff[i].0[c];
                    var[c] += w * w * diff[i].1[c];
                }
            }
        });
        if wsum <= 0.0 {
            return ([0.0; 3], [0.0; 3]);
        }
        (acc.map(|a| a / wsum), var.map(|x| x / (wsum * wsum)))
    }
}

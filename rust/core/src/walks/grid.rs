//! A uniform hash grid over vertices, and the kernel average over it that carries the walk
//! term's D from the walked vertices to their neighbours (`term`).

use crate::mesh::Mesh;
use glam::Vec3;
// Fx hashing: the cells are looked up 27 times a vertex in every relight (SipHash took
// a quarter of the kernel average's time).
use rustc_hash::FxHashMap as HashMap;

/// A uniform hash grid over candidate vertices.
pub(super) struct Grid {
    cell: f32,
    cells: HashMap<[i32; 3], Vec<usize>>,
}

impl Grid {
    pub(super) fn new(mesh: &Mesh, candidates: &[u32], cell: f32) -> Grid {
        let cell = cell.max(f32::MIN_POSITIVE);
        let mut cells: HashMap<[i32; 3], Vec<usize>> = HashMap::default();
        for (i, &v) in candidates.iter().enumerate() {
            let k = (mesh.positions()[v as usize] / cell)
                .floor()
                .as_ivec3()
                .to_array();
            cells.entry(k).or_default().push(i);
        }
        Grid { cell, cells }
    }

    /// The kernel's radius (the grid's cell).
    pub(super) fn radius(&self) -> f32 {
        self.cell
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
        self.sums_where(mesh, v, candidates, diff, class, |_| true)
            .mean()
    }

    /// The kernel's weighted sums at vertex v over the candidates `keep` accepts (by index);
    /// `average` is their mean over all.
    pub(super) fn sums_where(
        &self,
        mesh: &Mesh,
        v: u32,
        candidates: &[u32],
        diff: &[([f32; 3], [f32; 3])],
        class: &[bool],
        keep: impl Fn(usize) -> bool,
    ) -> KernelSums {
        let mut sums = KernelSums::default();
        self.weights(mesh, v, candidates, class, |i, w| {
            if keep(i) {
                sums.add(w, diff[i]);
            }
        });
        sums
    }

    /// The kernel's weight at vertex v of each candidate it takes (by index): (1 - d^2/R^2)^2
    /// times the cosine between the normals, for those within R, facing the same side and of
    /// v's `class`.
    pub(super) fn weights(
        &self,
        mesh: &Mesh,
        v: u32,
        candidates: &[u32],
        class: &[bool],
        mut f: impl FnMut(usize, f32),
    ) {
        let (p, n) = (mesh.positions()[v as usize], mesh.normals()[v as usize]);
        let own = class[v as usize];
        let r2 = self.cell * self.cell;
        self.visit(p, |i| {
            let u = candidates[i] as usize;
            let d2 = mesh.positions()[u].distance_squared(p);
            let cos = mesh.normals()[u].dot(n);
            if d2 < r2 && cos > 0.0 && class[u] == own {
                f(i, (1.0 - d2 / r2).powi(2) * cos);
            }
        });
    }
}

/// Sums of a kernel average: weights, weighted D and squared weights times D's variance.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct KernelSums {
    pub(super) weight: f32,
    acc: [f32; 3],
    var: [f32; 3],
}

impl KernelSums {
    fn add(&mut self, w: f32, (d, var): ([f32; 3], [f32; 3])) {
        self.weight += w;
        for c in 0..3 {
            self.acc[c] += w * d[c];
            self.var[c] += w * w * var[c];
        }
    }

    /// The sums less one term of weight `w` (the receiver's own D, weight 1, for a
    /// leave-one-out average).
    pub(super) fn without(mut self, w: f32, (d, var): ([f32; 3], [f32; 3])) -> KernelSums {
        self.add(-w, (d, var.map(|x| -x)));
        self
    }

    /// The weighted mean and its variance; zero where no weight is left.
    pub(super) fn mean(&self) -> ([f32; 3], [f32; 3]) {
        let w = self.weight;
        if w <= 0.0 {
            return ([0.0; 3], [0.0; 3]);
        }
        (
            self.acc.map(|a| a / w),
            self.var.map(|x| (x / (w * w)).max(0.0)),
        )
    }
}

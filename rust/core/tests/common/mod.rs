//! Test meshes shared by the integration tests (each test crate uses part of them) and, as
//! `mesh::test_meshes`, by the unit tests.
#![allow(dead_code)]

use translucent_core::mesh::Mesh;
use translucent_core::Vec3;

pub mod oracles;

/// A flat square grid of `n` x `n` vertices and side `size`, centred at the origin, normal +Z.
pub fn plane_parts(n: usize, size: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let x = size * (i as f32 / (n - 1) as f32 - 0.5);
            let y = size * (j as f32 / (n - 1) as f32 - 0.5);
            p.push(Vec3::new(x, y, 0.0));
        }
    }
    let mut t = Vec::new();
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let a = (j * n + i) as u32;
            let (b, c, d) = (a + 1, a + n as u32, a + n as u32 + 1);
            t.push([a, b, d]);
            t.push([a, d, c]);
        }
    }
    (p, t)
}

/// `plane_parts` as a mesh.
pub fn plane(n: usize, size: f32) -> Mesh {
    mesh(plane_parts(n, size))
}

/// A closed UV sphere of `radius`: n - 1 rings of 2n vertices and two poles, normals outward.
pub fn sphere_parts(n: usize, radius: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = vec![Vec3::new(0.0, 0.0, radius)];
    for i in 1..n {
        let th = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..2 * n {
            let ph = std::f32::consts::PI * j as f32 / n as f32;
            p.push(radius * Vec3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()));
        }
    }
    p.push(Vec3::new(0.0, 0.0, -radius));
    let seg = 2 * n;
    let last = (p.len() - 1) as u32;
    let ring = |i: usize, j: usize| (1 + (i - 1) * seg + (j % seg)) as u32;
    let mut t: Vec<[u32; 3]> = (0..seg).map(|j| [0, ring(1, j), ring(1, j + 1)]).collect();
    for i in 1..n - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (
                ring(i, j),
                ring(i, j + 1),
                ring(i + 1, j),
                ring(i + 1, j + 1),
            );
            t.push([a, c, d]);
            t.push([a, d, b]);
        }
    }
    t.extend((0..seg).map(|j| [last, ring(n - 1, j + 1), ring(n - 1, j)]));
    (p, t)
}

/// `sphere_parts` as a mesh.
pub fn sphere(n: usize, radius: f32) -> Mesh {
    mesh(sphere_parts(n, radius))
}

/// Two `sphere_parts(n, radius)` centred at x = -`centre` (object 0) and x = +`centre`
/// (object 1), one mesh.
pub fn sphere_pair(n: usize, radius: f32, centre: f32) -> Mesh {
    let (mut p, mut t) = sphere_parts(n, radius);
    let count = p.len() as u32;
    for x in p.iter_mut() {
        x.x -= centre;
    }
    let (q, u) = sphere_parts(n, radius);
    p.extend(q.iter().map(|x| *x + Vec3::X * centre));
    t.extend(u.iter().map(|tri| tri.map(|v| v + count)));
    let objects = (0..p.len() as u32).map(|v| u32::from(v >= count)).collect();
    Mesh::new(p, t, None)
        .and_then(|m| m.with_objects(objects))
        .expect("a valid test mesh")
}

pub fn mesh((p, t): (Vec<Vec3>, Vec<[u32; 3]>)) -> Mesh {
    Mesh::new(p, t, None).expect("a valid test mesh")
}

/// Index of the vertex nearest `x`.
pub fn nearest(mesh: &Mesh, x: Vec3) -> usize {
    (0..mesh.vertex_count())
        .min_by(|a, b| {
            (mesh.positions()[*a] - x)
                .length()
                .total_cmp(&(mesh.positions()[*b] - x).length())
        })
        .unwrap()
}

//! A validated triangle mesh: positions, triangles, vertex normals, areas, and the
//! area-uniform surface samples every integration over the surface starts from.

mod order;
pub mod topology;

use crate::error::{Error, Result};
use glam::Vec3;
pub use order::morton_order;
pub use topology::Topology;

/// The largest coordinate magnitude a mesh may have [scene units]. The methods work in single
/// precision, where a mesh's squared areas (extent^4) overflow above ~1e9 units; 1e8 leaves room.
pub const COORDINATE_LIMIT: f32 = 1e8;
/// The smallest bounding-box diagonal a mesh with area may have [scene units]: below, squared
/// areas (extent^4) fall under single precision's smallest normal number (1.2e-38) with little room.
pub const MIN_EXTENT: f32 = 1e-8;

/// A triangle mesh in scene units. Built only through `Mesh::new`, which validates it.
#[derive(Debug, Clone)]
pub struct Mesh {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<Vec3>,
    triangle_areas: Vec<f32>,
    vertex_areas: Vec<f32>,
    report: MeshReport,
    /// Per vertex, the object it belongs to (`with_objects`): light never scatters from one
    /// object into another, as Cycles' walk stays in its own object. None: one object.
    objects: Option<Vec<u32>>,
}

/// What validation found that is not fatal.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MeshReport {
    /// Triangles with (numerically) zero area: kept, but they carry no surface.
    pub degenerate_triangles: usize,
    /// Vertices referenced by no triangle: they get zero area and radiosity from their position.
    pub isolated_vertices: usize,
    /// Vertices whose normal was zero at a vertex without area (loose, or only on degenerate
    /// triangles) and was replaced by +Z. A given zero normal on the surface is refused.
    pub zero_normals: usize,
    /// Vertices whose given normal points against the area-weighted normal of the triangles
    /// around them (dot < 0): the normals and the winding disagree there.
    pub normals_against_winding: usize,
    /// Edges exactly one triangle uses (0 for a closed surface).
    pub open_edges: usize,
    /// Edges three or more triangles use.
    pub non_manifold_edges: usize,
    /// Edges whose two triangles are wound opposite ways (an open or broken mesh is not
    /// refused for it; a consistently wound surface has none).
    pub inconsistent_edges: usize,
    /// Pairs of triangles over the same three points wound opposite ways (refused from 1 % of
    /// the triangles: a double-sided sheet).
    pub reversed_pairs: usize,
    /// Closed, consistently wound surfaces, and how many of them are wound inward on their
    /// own (a cavity inside another surface is, correctly).
    pub closed_components: usize,
    pub inward_components: usize,
    /// Signed volume the closed surfaces enclose [unit^3]: > 0 wound outward.
    pub closed_volume: f64,
    /// Total surface area [unit^2].
    pub area: f64,
}

/// A point on the surface that stands for a patch of area around it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SurfaceSample {
    pub position: Vec3,
    /// Shading normal: the vertex normals interpolated at the sample (as Cycles shades a
    /// smooth mesh), the triangle's flat normal where they cancel.
    pub normal: Vec3,
    /// Area this sample stands for [unit^2]; the areas of all samples sum to the mesh area.
    pub area: f32,
    pub triangle: u32,
}

impl Mesh {
    /// Validates and builds a mesh. `normals`, if given, must have one entry per vertex; when
    /// absent, area-weighted vertex normals are computed. Errors: empty input, NaN/Inf
    /// coordinates, indices out of range, coordinates beyond `COORDINATE_LIMIT` or an extent
    /// below `MIN_EXTENT`, a mesh of zero total area, a normal of zero length, a repeated
    /// triangle, a triangle with its reverse, closed surfaces wound inward (signed volume < 0),
    /// normals pointing inward on a closed outward mesh. Degenerate triangles among others, open
    /// edges and inconsistently wound neighbours are reported, not fatal.
    pub fn new(
        positions: Vec<Vec3>,
        triangles: Vec<[u32; 3]>,
        normals: Option<Vec<Vec3>>,
    ) -> Result<Self> {
        if positions.is_empty() {
            return Err(Error::InvalidMesh("the mesh has no vertices".into()));
        }
        if triangles.is_empty() {
            return Err(Error::InvalidMesh("the mesh has no triangles".into()));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::InvalidMesh(format!(
                "vertex {i} has a non-finite coordinate {:?}",
                positions[i]
            )));
        }
        let n = positions.len() as u64;
        for (t, tri) in triangles.iter().enumerate() {
            if let Some(&v) = tri.iter().find(|&&v| u64::from(v) >= n) {
                return Err(Error::InvalidMesh(format!(
                    "triangle {t} references vertex {v}, but the mesh has only {n} vertices"
                )));
            }
        }
        if let Some(normals) = &normals {
            if normals.len() != positions.len() {
                return Err(Error::InvalidMesh(format!(
                    "{} normals given for {} vertices",
                    normals.len(),
                    positions.len()
                )));
            }
            if let Some(i) = normals.iter().position(|p| !p.is_finite()) {
                return Err(Error::InvalidMesh(format!(
                    "normals[{i}] = {:?} has a non-finite component; give finite normals, or \
                     none to have them computed from the triangles",
                    normals[i]
                )));
            }
        }
        check_extent(&positions)?;

        let mut report = MeshReport::default();
        let mut triangle_areas = Vec::with_capacity(triangles.len());
        let mut vertex_areas = vec![0.0f32; positions.len()];
        let mut accumulated = vec![Vec3::ZERO; positions.len()];
        let mut used = vec![false; positions.len()];
        let diagonal = bounding_diagonal(&positions);
        let scale = diagonal.max(f32::MIN_POSITIVE);
        for tri in &triangles {
            let [a, b, c] = tri.map(|v| positions[v as usize]);
            let cross = (b - a).cross(c - a);
            // Finite: `check_extent` keeps |cross|^2 <= (2 sqrt(3) 1e8)^4 ~ 1e34.
            let area = 0.5 * cross.length();
            // Zero area relative to the mesh's size, not in absolute units (scale 1e-4..1e4).
            if area <= 1e-12 * scale * scale {
                report.degenerate_triangles += 1;
            }
            triangle_areas.push(area);
            report.area += f64::from(area);
            for &v in tri {
                vertex_areas[v as usize] += area / 3.0;
                accumulated[v as usize] += cross; // area-weighted
                used[v as usize] = true;
            }
        }
        // No surface at all (every vertex in one point, or on one line): nothing can scatter
        // light, and every method would divide by the area or sample it. Refused, saying so.
        if report.degenerate_triangles == triangles.len() {
            return Err(Error::InvalidMesh(format!(
                "the mesh has zero total area: all {} triangle(s) are degenerate (their vertices \
                 coincide or lie on one line), so there is no surface to scatter light",
                triangles.len()
            )));
        }
        report.isolated_vertices = used.iter().filter(|u| !**u).count();
        let top = topology::analyse(
            &positions,
            &triangles,
            &triangle_areas,
            1e-12 * scale * scale,
        );
        check_topology(&top, diagonal)?;
        report.open_edges = top.open_edges;
        report.non_manifold_edges = top.non_manifold_edges;
        report.inconsistent_edges = top.inconsistent_edges;
        report.reversed_pairs = top.reversed_pairs;
        report.closed_components = top.closed_components;
        report.inward_components = top.inward_components;
        report.closed_volume = top.closed_volume;
        if let Some(given) = &normals {
            // A zero normal where there is surface has no direction to shade with (it used to
            // become +Z silently, changing B x2-13 there); at a vertex without area (loose, or
            // only on degenerate triangles, where Blender gives zero too) it is replaced.
            if let Some(i) =
                (0..given.len()).find(|&i| given[i].length() == 0.0 && accumulated[i] != Vec3::ZERO)
            {
                return Err(Error::InvalidMesh(format!(
                    "normals[{i}] = {:?} has zero length at a vertex on the surface; give unit \
                     normals (Blender: Mesh > Normals > Recalculate Outside), or none to have them \
                     computed",
                    given[i]
                )));
            }
            report.normals_against_winding = check_normals(given, &accumulated, &top)?;
        }
        let normals = normals.unwrap_or(accumulated);
        let normals = normals
            .into_iter()
            .map(|nrm| {
                let len = nrm.length();
                if len > 0.0 && len.is_finite() {
                    nrm / len
                } else {
                    report.zero_normals += 1;
                    Vec3::Z
                }
            })
            .collect();
        Ok(Self {
            positions,
            triangles,
            normals,
            triangle_areas,
            vertex_areas,
            report,
            objects: None,
        })
    }

    /// This mesh as several objects (issue 30 point 4): `objects[v]` is the object vertex `v`
    /// belongs to. Every triangle's corners must belong to one object; errors name the first
    /// triangle that mixes two, or a count that is not one per vertex.
    pub fn with_objects(mut self, objects: Vec<u32>) -> Result<Self> {
        if objects.len() != self.positions.len() {
            return Err(Error::InvalidMesh(format!(
                "{} object indices for {} vertices: give one per vertex",
                objects.len(),
                self.positions.len()
            )));
        }
        if let Some((t, tri)) = (self.triangles.iter().enumerate()).find(|(_, t)| {
            t.iter()
                .any(|&v| objects[v as usize] != objects[t[0] as usize])
        }) {
            return Err(Error::InvalidMesh(format!(
                "triangle {t} joins vertices of objects {:?}: a triangle belongs to one object",
                tri.map(|v| objects[v as usize])
            )));
        }
        self.objects = Some(objects);
        Ok(self)
    }

    /// The object vertex `v` belongs to (0 when the mesh is one object).
    pub fn object_of_vertex(&self, v: usize) -> u32 {
        self.objects.as_ref().map_or(0, |o| o[v])
    }

    /// The object triangle `t` belongs to.
    pub fn object_of_triangle(&self, t: usize) -> u32 {
        self.object_of_vertex(self.triangles[t][0] as usize)
    }

    /// Per vertex its object, where the mesh holds several (`with_objects`).
    /// This mesh posed: the same triangles and object indices, the vertices at `positions`
    /// (one per vertex) with `normals` (computed when None), validated as `new` does. Errors
    /// when the count differs (a topology change is a new mesh).
    pub fn posed(&self, positions: Vec<Vec3>, normals: Option<Vec<Vec3>>) -> Result<Mesh> {
        let n = self.vertex_count();
        if positions.len() != n {
            return Err(Error::InvalidArgument(format!(
                "{} positions for a mesh of {n} vertices (a pose keeps the vertices and \
                 triangles; a topology change is a new mesh)",
                positions.len()
            )));
        }
        let mesh = Mesh::new(positions, self.triangles.clone(), normals)?;
        match &self.objects {
            Some(objects) => mesh.with_objects(objects.clone()),
            None => Ok(mesh),
        }
    }

    pub fn objects(&self) -> Option<&[u32]> {
        self.objects.as_deref()
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// Unit vertex normals.
    pub fn normals(&self) -> &[Vec3] {
        &self.normals
    }
    pub fn triangle_areas(&self) -> &[f32] {
        &self.triangle_areas
    }
    /// One third of the area of each adjacent triangle: the weight of a vertex in area-weighted errors.
    pub fn vertex_areas(&self) -> &[f32] {
        &self.vertex_areas
    }
    pub fn report(&self) -> &MeshReport {
        &self.report
    }
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }
    pub fn area(&self) -> f64 {
        self.report.area
    }
    /// Length of the bounding-box diagonal [unit].
    pub fn diagonal(&self) -> f32 {
        bounding_diagonal(&self.positions)
    }

    /// How much of a small disc around each vertex the surface covers: 1 inside the surface,
    /// the sum of the incident triangles' angles over 2 pi on an open boundary (a hole's rim,
    /// a plane's edge: 1/2 on a straight edge, 1/4 at a square corner), 0 for a vertex no
    /// triangle of positive area uses. An edge is on the boundary when exactly one triangle of
    /// positive area uses it.
    pub fn vertex_coverage(&self) -> Vec<f32> {
        let (weld, boundary) = self.welded_open_edges();
        let mut angles = vec![0f64; self.positions.len()];
        let mut used = vec![false; self.positions.len()];
        for (tri, area) in self.triangles.iter().zip(&self.triangle_areas) {
            if *area <= 0.0 {
                continue;
            }
            let w = tri.map(|v| weld[v as usize]);
            for k in 0..3 {
                let (v, a, b) = (w[k], w[(k + 1) % 3], w[(k + 2) % 3]);
                let p = self.positions[v as usize].as_dvec3();
                let (ea, eb) = (
                    self.positions[a as usize].as_dvec3() - p,
                    self.positions[b as usize].as_dvec3() - p,
                );
                angles[v as usize] += ea.angle_between(eb);
                used[v as usize] = true;
            }
        }
        weld.iter()
            .map(|&v| match (used[v as usize], boundary[v as usize]) {
                (false, _) => 0.0,
                (true, false) => 1.0,
                (true, true) => ((angles[v as usize] / std::f64::consts::TAU) as f32).min(1.0),
            })
            .collect()
    }

    /// Per vertex, whether it lies on an open boundary (an edge exactly one triangle of
    /// positive area uses; vertices at the same position are one point, as in
    /// `vertex_coverage`).
    pub fn open_edge_vertices(&self) -> Vec<bool> {
        let (weld, boundary) = self.welded_open_edges();
        weld.iter().map(|&w| boundary[w as usize]).collect()
    }

    /// Per vertex the first vertex at its position on its object (a seam split by an exporter
    /// is not a boundary; where two objects meet, each has its own), and per such welded vertex
    /// whether an edge exactly one triangle of positive area uses ends there.
    fn welded_open_edges(&self) -> (Vec<u32>, Vec<bool>) {
        use std::collections::HashMap;
        let mut canonical: HashMap<([u32; 3], u32), u32> = HashMap::new();
        let weld: Vec<u32> = self
            .positions
            .iter()
            .enumerate()
            .map(|(i, p)| {
                *canonical
                    .entry((p.to_array().map(f32::to_bits), self.object_of_vertex(i)))
                    .or_insert(i as u32)
            })
            .collect();
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        for (tri, area) in self.triangles.iter().zip(&self.triangle_areas) {
            if *area <= 0.0 {
                continue;
            }
            let w = tri.map(|v| weld[v as usize]);
            for k in 0..3 {
                let (v, a) = (w[k], w[(k + 1) % 3]);
                *edges.entry((v.min(a), v.max(a))).or_insert(0) += 1;
            }
        }
        let mut boundary = vec![false; self.positions.len()];
        for ((a, b), count) in edges {
            if count == 1 {
                boundary[a as usize] = true;
                boundary[b as usize] = true;
            }
        }
        (weld, boundary)
    }

    /// The axis-aligned bounding box (lo, hi) of the vertices.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        bounds(&self.positions)
    }

    /// Area-uniform samples with spacing about `spacing`: each triangle is split into k^2 equal
    /// sub-triangles, k = ceil(longest edge / spacing), and a sample sits at each sub-triangle's
    /// centroid carrying its area. Deterministic and evenly spread (Xu 2007 §6.1 asks for
    /// "evenly and densely distributed" points), so the sum over samples is a midpoint rule.
    pub fn surface_samples(&self, spacing: f32) -> Result<Vec<SurfaceSample>> {
        if !(spacing.is_finite() && spacing > 0.0) {
            return Err(Error::InvalidArgument(format!(
                "sample spacing {spacing} must be finite and > 0"
            )));
        }
        let mut out = Vec::new();
        for (t, tri) in self.triangles.iter().enumerate() {
            let area = self.triangle_areas[t];
            if area <= 0.0 {
                continue;
            }
            let [a, b, c] = tri.map(|v| self.positions[v as usize]);
            let flat = (b - a).cross(c - a).normalize_or_zero();
            let corner_normals = tri.map(|v| self.normals[v as usize]);
            let longest = (b - a).length().max((c - b).length()).max((a - c).length());
            let k = ((longest / spacing).ceil() as usize).clamp(1, 4096);
            let sub_area = area / (k * k) as f32;
            let (e1, e2) = ((b - a) / k as f32, (c - a) / k as f32);
            for i in 0..k {
                for j in 0..(k - i) {
                    // Upright sub-triangle (i, j), (i+1, j), (i, j+1).
                    let base = a + e1 * i as f32 + e2 * j as f32;
                    let (u, v) = (
                        (i as f32 + 1.0 / 3.0) / k as f32,
                        (j as f32 + 1.0 / 3.0) / k as f32,
                    );
                    out.push(SurfaceSample {
                        position: base + (e1 + e2) / 3.0,
                        normal: interpolated_normal(&corner_normals, u, v, flat),
                        area: sub_area,
                        triangle: t as u32,
                    });
                    // Inverted sub-triangle (i+1, j), (i, j+1), (i+1, j+1).
                    if i + j + 1 < k {
                        let (u, v) = (
                            (i as f32 + 2.0 / 3.0) / k as f32,
                            (j as f32 + 2.0 / 3.0) / k as f32,
                        );
                        out.push(SurfaceSample {
                            position: base + (e1 + e2) * (2.0 / 3.0),
                            normal: interpolated_normal(&corner_normals, u, v, flat),
                            area: sub_area,
                            triangle: t as u32,
                        });
                    }
                }
            }
        }
        Ok(out)
    }

    /// Number of samples `surface_samples(spacing)` produces.
    pub fn sample_count(&self, spacing: f32) -> usize {
        self.triangles
            .iter()
            .zip(&self.triangle_areas)
            .filter(|(_, a)| **a > 0.0)
            .map(|(tri, _)| {
                let [a, b, c] = tri.map(|v| self.positions[v as usize]);
                let longest = (b - a).length().max((c - b).length()).max((a - c).length());
                ((longest / spacing).ceil() as usize).clamp(1, 4096).pow(2)
            })
            .sum()
    }

    /// The fewest samples `sample_count` gives at any spacing: one per triangle of non-zero
    /// area. Below it `spacing_for_sample_count` has nothing to find.
    pub fn min_sample_count(&self) -> usize {
        self.triangle_areas.iter().filter(|a| **a > 0.0).count()
    }

    /// The sample spacing that yields about `count` samples (bisection on `sample_count`);
    /// for `count` at or below `min_sample_count`, the mesh's diagonal (one sample per
    /// triangle, at a spacing that says nothing of their density: callers refuse it).
    pub fn spacing_for_sample_count(&self, count: usize) -> f32 {
        let (mut lo, mut hi) = (
            self.diagonal() * 1e-6,
            self.diagonal().max(f32::MIN_POSITIVE),
        );
        for _ in 0..40 {
            let mid = (lo * hi).sqrt();
            if self.sample_count(mid) > count {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }
}

/// Barycentric coordinates (w_a, w_b, w_c) of `y`, projected on the plane of `corners`,
/// clamped into the triangle; None for a degenerate triangle.
pub fn barycentric(corners: &[Vec3; 3], y: Vec3) -> Option<[f32; 3]> {
    let [a, b, c] = *corners;
    let (e1, e2, d) = (b - a, c - a, y - a);
    let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d20, d21) = (d.dot(e1), d.dot(e2));
    let den = d00 * d11 - d01 * d01;
    if den <= 0.0 || !den.is_finite() {
        return None;
    }
    let bv = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let bw = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - bv);
    Some([1.0 - bv - bw, bv, bw])
}

/// What a ray hit at `p` on triangle `t` of `mesh`: the triangle's own unit normal, the
/// barycentric (u, v) of its corners 1 and 2 at `p` (the centroid where the projection fails)
/// and the shading normal there (the vertex normals interpolated, as Cycles' smooth shading);
/// None for a degenerate triangle (it carries no surface).
pub fn hit_surface(mesh: &Mesh, t: u32, p: Vec3) -> Option<(Vec3, [f32; 2], Vec3)> {
    let tri = mesh.triangles()[t as usize];
    let corners = tri.map(|v| mesh.positions()[v as usize]);
    let flat = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .try_normalize()?;
    let uv = match barycentric(&corners, p) {
        Some([_, u, v]) => [u, v],
        None => [1.0 / 3.0; 2],
    };
    let normals = tri.map(|v| mesh.normals()[v as usize]);
    Some((flat, uv, interpolated_normal(&normals, uv[0], uv[1], flat)))
}

/// The corner normals [n_a, n_b, n_c] interpolated at barycentric (1 - u - v, u, v) and
/// normalised; `flat` where they cancel. Shared with the reference so both see the same surface.
pub fn interpolated_normal(corners: &[Vec3; 3], u: f32, v: f32, flat: Vec3) -> Vec3 {
    let n = corners[0] * (1.0 - u - v) + corners[1] * u + corners[2] * v;
    n.try_normalize().unwrap_or(flat)
}

/// Refuses coordinates beyond `COORDINATE_LIMIT` and a mesh with extent below `MIN_EXTENT`
/// (but not zero: one point has no area, and is refused for that), saying how to rescale.
fn check_extent(positions: &[Vec3]) -> Result<()> {
    let largest = positions
        .iter()
        .map(|p| p.abs().max_element())
        .fold(0.0f32, f32::max);
    let rescale = "rescale the scene (e.g. to metres; material coefficients, per unit of \
                   length, scale inversely)";
    let (lo, hi) = bounds(positions);
    let diagonal = (hi.as_dvec3() - lo.as_dvec3()).length();
    if largest > COORDINATE_LIMIT {
        // Say "overflows" only where it does: squared areas (diagonal^4) beyond f32::MAX.
        let what = if diagonal.powi(4) > f64::from(f32::MAX) {
            "the mesh's extent overflows single precision (its squared areas exceed 3.4e38)"
        } else {
            "the mesh is too large for single precision with room"
        };
        return Err(Error::InvalidMesh(format!(
            "{what}: coordinates reach {largest:e} scene units, beyond the supported \
             |x| <= {COORDINATE_LIMIT:e}; {rescale}"
        )));
    }
    if diagonal > 0.0 && diagonal < f64::from(MIN_EXTENT) {
        return Err(Error::InvalidMesh(format!(
            "the mesh is {diagonal:e} scene units across (bounding-box diagonal), below the \
             supported {MIN_EXTENT:e}: in single precision its triangles' squared areas \
             underflow to zero and its triangles would have no area; {rescale}"
        )));
    }
    Ok(())
}

/// Refuses what makes every method count surface wrongly: a repeated triangle, a triangle and
/// its reverse (a double-sided sheet), closed surfaces wound inward.
fn check_topology(top: &Topology, diagonal: f32) -> Result<()> {
    if let Some((first, again)) = top.duplicate {
        return Err(Error::InvalidMesh(format!(
            "triangle {again} repeats triangle {first} (the same three corners, the same \
             winding): the surface there would count twice; remove duplicated faces (Blender: \
             Mesh > Clean Up > Merge by Distance)"
        )));
    }
    // A lone pair (Blender's Suzanne has one) changes B locally; a sheet made double-sided
    // (every triangle with its reverse) changes it everywhere. Refused from 1 % of the surface.
    if let Some((first, again)) = top
        .first_reversed
        .filter(|_| 200 * top.reversed_pairs > top.triangles)
    {
        return Err(Error::InvalidMesh(format!(
            "triangle {again} is triangle {first} wound the other way ({} such pair(s)): a \
             double-sided sheet has no inside for light to scatter in; keep one side of each \
             pair (Blender: Mesh > Clean Up > Merge by Distance), the one facing outward",
            top.reversed_pairs
        )));
    }
    let d = f64::from(diagonal);
    if top.closed_volume < -1e-9 * d * d * d {
        return Err(Error::InvalidMesh(format!(
            "the mesh is wound inward: its closed surfaces enclose a signed volume of {:e} \
             (< 0; {} of {} closed surface(s) face inward), so every normal points into the \
             object and no light would enter; flip it (Blender: Mesh > Normals > Recalculate \
             Outside, or Flip; a negative object scale mirrors it too: apply the scale), i.e. \
             reverse each triangle's vertex order",
            top.closed_volume, top.inward_components, top.closed_components
        )));
    }
    Ok(())
}

/// How many given normals point against the triangles' winding (dot with the area-weighted
/// face normal < 0); refused when that is most of the vertices of a closed, outward mesh:
/// then the normals, not the winding, are flipped.
fn check_normals(given: &[Vec3], accumulated: &[Vec3], top: &Topology) -> Result<usize> {
    let (mut against, mut defined) = (0usize, 0usize);
    for (g, a) in given.iter().zip(accumulated) {
        if a.length_squared() > 0.0 {
            defined += 1;
            if g.dot(*a) < 0.0 {
                against += 1;
            }
        }
    }
    let closed = top.open_edges == 0 && top.non_manifold_edges == 0 && top.inconsistent_edges == 0;
    if closed && top.closed_volume > 0.0 && 2 * against > defined {
        return Err(Error::InvalidMesh(format!(
            "the normals point into the object at {against} of {defined} vertices while the \
             triangles are wound outward: flip the normals (Blender: Mesh > Normals > \
             Recalculate Outside), or give none to have them computed from the triangles"
        )));
    }
    Ok(against)
}

fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

fn bounding_diagonal(points: &[Vec3]) -> f32 {
    let (lo, hi) = bounds(points);
    (hi - lo).length()
}

/// The integration tests' meshes (`tests/common`), for the unit tests too.
#[cfg(test)]
#[path = "../../tests/common/mod.rs"]
pub(crate) mod test_meshes;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coverage_is_one_inside_and_the_angle_share_on_the_boundary() {
        // A 3 x 3 grid of vertices (2 x 2 squares, each split along its diagonal) plus one
        // vertex no triangle uses.
        let mut p: Vec<Vec3> = (0..9)
            .map(|i| Vec3::new((i % 3) as f32, (i / 3) as f32, 0.0))
            .collect();
        p.push(Vec3::new(5.0, 5.0, 1.0));
        let mut t = Vec::new();
        for j in 0..2u32 {
            for i in 0..2u32 {
                let a = j * 3 + i;
                t.push([a, a + 1, a + 4]);
                t.push([a, a + 4, a + 3]);
            }
        }
        let m = Mesh::new(p, t, None).unwrap();
        let c = m.vertex_coverage();
        assert_eq!(c[4], 1.0); // the centre
        assert!((c[1] - 0.5).abs() < 1e-6); // middle of an edge: a half disc
        assert!((c[2] - 0.25).abs() < 1e-6); // a square corner
        assert!((c[0] - 0.25).abs() < 1e-6);
        assert_eq!(c[9], 0.0); // isolated
    }

    fn quad() -> Mesh {
        Mesh::new(
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 3.0, 0.0),
                Vec3::new(0.0, 3.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
            None,
        )
        .unwrap()
    }

    #[test]
    fn areas_and_normals_of_a_rectangle() {
        let m = quad();
        assert!((m.area() - 6.0).abs() < 1e-6);
        let va: f32 = m.vertex_areas().iter().sum();
        assert!((va - 6.0).abs() < 1e-5);
        for n in m.normals() {
            assert!((*n - Vec3::Z).length() < 1e-6);
        }
    }

    #[test]
    fn samples_tile_the_surface_and_stay_on_it() {
        let m = quad();
        let s = m.surface_samples(0.1).unwrap();
        let total: f64 = s.iter().map(|x| f64::from(x.area)).sum();
        assert!((total - 6.0).abs() < 1e-4);
        // First moment: the area-weighted centroid of a 2 x 3 rectangle is (1, 1.5).
        let cx: f64 = s
            .iter()
            .map(|x| f64::from(x.area * x.position.x))
            .sum::<f64>()
            / total;
        let cy: f64 = s
            .iter()
            .map(|x| f64::from(x.area * x.position.y))
            .sum::<f64>()
            / total;
        assert!((cx - 1.0).abs() < 1e-4 && (cy - 1.5).abs() < 1e-4);
        assert!(s
            .iter()
            .all(|x| x.position.z == 0.0 && x.position.x >= 0.0 && x.position.x <= 2.0));
    }

    #[test]
    fn bad_meshes_are_rejected_with_reasons() {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        assert!(Mesh::new(vec![], vec![[0, 1, 2]], None).is_err());
        assert!(Mesh::new(p.clone(), vec![], None).is_err());
        let e = Mesh::new(p.clone(), vec![[0, 1, 3]], None).unwrap_err();
        assert!(e.to_string().contains("vertex 3"), "{e}");
        let e = Mesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(f32::NAN, 0.0, 0.0)],
            vec![[0, 1, 2]],
            None,
        )
        .unwrap_err();
        assert!(e.to_string().contains("non-finite"), "{e}");
        assert!(Mesh::new(p.clone(), vec![[0, 1, 2]], Some(vec![Vec3::Z])).is_err());
    }

    #[test]
    fn a_mesh_without_area_is_refused_saying_so() {
        // Three vertices on one line, and three in one point.
        for p in [
            vec![Vec3::ZERO, Vec3::X, Vec3::new(2.0, 0.0, 0.0)],
            vec![Vec3::splat(0.5); 3],
        ] {
            let e = Mesh::new(p, vec![[0, 1, 2], [2, 1, 0]], None).unwrap_err();
            assert!(e.to_string().contains("zero total area"), "{e}");
        }
    }

    #[test]
    fn meshes_beyond_the_coordinate_range_are_refused_stating_it() {
        // 1e10 and 1.2e19: finite in f32, and the old messages claimed a cross product
        // "above 3.4e38"; the real limit is the stated coordinate range.
        for r in [1.01e8f32, 1e10, 1.2e19, 1e20] {
            let p = vec![Vec3::ZERO, Vec3::new(r, 0.0, 0.0), Vec3::new(0.0, r, 0.0)];
            let e = Mesh::new(p, vec![[0, 1, 2]], None).unwrap_err().to_string();
            assert!(
                e.contains("beyond the supported |x| <= 1e8") && e.contains("rescale"),
                "{e}"
            );
        }
        for r in [1e-12f32, 7e-9] {
            let p = vec![Vec3::ZERO, Vec3::new(r, 0.0, 0.0), Vec3::new(0.0, r, 0.0)];
            let e = Mesh::new(p, vec![[0, 1, 2]], None).unwrap_err().to_string();
            assert!(
                e.contains("below the supported 1e-8") && e.contains("rescale"),
                "{e}"
            );
        }
        // Inside the range, at both ends, a triangle has its area.
        for r in [1e-8f32, 5e7] {
            let p = vec![Vec3::ZERO, Vec3::new(r, 0.0, 0.0), Vec3::new(0.0, r, 0.0)];
            let m = Mesh::new(p, vec![[0, 1, 2]], None).unwrap();
            let exact = 0.5 * f64::from(r) * f64::from(r);
            assert!((m.area() / exact - 1.0).abs() < 1e-6, "{r}: {}", m.area());
        }
    }

    #[test]
    fn degenerate_and_isolated_are_reported_not_fatal() {
        let m = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::splat(5.0),
            ],
            vec![[0, 1, 2], [0, 1, 3]],
            None,
        )
        .unwrap();
        assert_eq!(m.report().degenerate_triangles, 1);
        assert_eq!(m.report().isolated_vertices, 1);
        assert!(m.normals().iter().all(|n| n.is_finite()));
    }
}

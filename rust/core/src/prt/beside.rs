//! A uniform material beside the faces of other materials (issue 30, point 3): an object whose
//! eyes, teeth or clothes are another material. Their faces bound the walks and cast shadows
//! as Cycles' walk and shadow rays see them, and their vertices scatter as their own colour
//! (`textured`), but they are not previewed.
//!
//! B at a previewed vertex is its own medium's profile applied to the light around it (Xu 2007
//! eq. 9; Cycles' walk takes its medium from where it starts), so the other materials'
//! colours reach the previewed vertices only through the object's own light: E_ind is scaled
//! by what the whole surface sends on, averaged over its vertices (`Bounce::ratio`), each
//! vertex its own medium's slab albedo. Everything else is the uniform edit's (one fit, one dot
//! product, the walks' term of the one medium), without the per-vertex table a textured edit
//! reads, and exact where that table interpolates. The other materials' rows come back NaN.

use super::evaluate::Evaluation;
use super::Prt;
use crate::error::{Error, Result};
use crate::evaluation::Skipped;
use crate::optics::principled::PrincipledInputs;
use crate::optics::Material;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Distinct colours of other materials taken one by one (one slab albedo each); beyond this
/// (another material that is itself textured) the edit reads them per vertex (`textured`).
pub const OTHER_COLORS_MOST: usize = 16;

/// The other materials' vertices: each distinct colour and how many vertices carry it, and
/// the previewed vertices' count.
struct Others {
    colors: Vec<([f32; 3], usize)>,
    previewed: usize,
}

/// A row of `others` that is neither a finite colour nor NaN in all three channels.
fn bad_row(row: &[f32; 3]) -> bool {
    let nans = row.iter().filter(|x| x.is_nan()).count();
    (nans > 0 && nans < 3) || row.iter().any(|x| x.is_infinite())
}

/// `others` checked (one row per vertex: a finite colour, or NaN in all three channels for a
/// previewed vertex) and its distinct colours counted; None past `OTHER_COLORS_MOST`. In
/// chunks on every core, merged in order.
fn count(others: &[[f32; 3]], vertices: usize) -> Result<Option<Others>> {
    if others.len() != vertices {
        return Err(Error::InvalidArgument(format!(
            "others has {} rows, the transport {vertices} vertices",
            others.len()
        )));
    }
    const CHUNK: usize = 16_384;
    let parts: Option<Vec<Others>> = (others.par_chunks(CHUNK)).map(count_chunk).collect();
    let Some(parts) = parts else {
        // A chunk stopped early: at a bad row, or past the colours taken one by one.
        return match others.iter().position(bad_row) {
            Some(v) => Err(Error::InvalidArgument(format!(
                "others row {v} is {:?}: a finite colour (another material's vertex) or NaN in \
                 all three channels (a previewed vertex)",
                others[v]
            ))),
            None => Ok(None),
        };
    };
    // Every row checked: the chunks' colours merged, in order.
    let mut out = Others {
        colors: Vec::new(),
        previewed: 0,
    };
    for part in parts {
        out.previewed += part.previewed;
        for (color, n) in part.colors {
            match out.colors.iter().position(|c| c.0 == color) {
                Some(k) => out.colors[k].1 += n,
                None => out.colors.push((color, n)),
            }
        }
    }
    Ok((out.colors.len() <= OTHER_COLORS_MOST).then_some(out))
}

/// `count` over some rows; None at a bad row or past `OTHER_COLORS_MOST` colours.
fn count_chunk(rows: &[[f32; 3]]) -> Option<Others> {
    let mut out = Others {
        colors: Vec::new(),
        previewed: 0,
    };
    let mut last = usize::MAX;
    for row in rows {
        let &[a, b, c] = row;
        if !(a.is_finite() && b.is_finite() && c.is_finite()) {
            if a.is_nan() && b.is_nan() && c.is_nan() {
                out.previewed += 1;
                continue;
            }
            return None;
        }
        // Rows repeat along a face's vertices: the colour before is tried first.
        if last < out.colors.len() && out.colors[last].0 == *row {
            out.colors[last].1 += 1;
            continue;
        }
        last = match out.colors.iter().position(|c| c.0 == *row) {
            Some(k) => k,
            None if out.colors.len() < OTHER_COLORS_MOST => {
                out.colors.push((*row, 0));
                out.colors.len() - 1
            }
            None => return None,
        };
        out.colors[last].1 += 1;
    }
    Some(out)
}

/// The Base Color per vertex: `base` at the previewed vertices, the others' own elsewhere.
fn merged(base: [f32; 3], others: &[[f32; 3]]) -> Vec<[f32; 3]> {
    (others.iter())
        .map(|o| if o[0].is_nan() { base } else { *o })
        .collect()
}

impl Prt {
    /// Multiple-scattering radiosity of the uniform material `inputs` at the vertices whose
    /// `others` row is NaN, beside vertices of other materials (`others`' finite rows: each
    /// one's Base Color, linear RGB). Those vertices scatter as their own colour into the
    /// object's own light and come back NaN (not previewed); `skipped` says so. `bounce` and
    /// `walks` as `radiosity_parts`.
    pub fn radiosity_beside(
        &self,
        inputs: &PrincipledInputs,
        others: &[[f32; 3]],
        bounce: bool,
        walks: bool,
    ) -> Result<Evaluation> {
        self.beside(inputs, others, bounce, walks, None)
    }

    /// Multiple-scattering radiance toward `eye` (or along each normal) as `radiosity_beside`.
    pub fn radiance_beside(
        &self,
        inputs: &PrincipledInputs,
        others: &[[f32; 3]],
        eye: Option<Vec3>,
    ) -> Result<Evaluation> {
        crate::evaluation::check_eye(eye)?;
        self.beside(inputs, others, true, true, Some(eye))
    }

    /// `radiosity_beside`, or with `radiance` (the eye, or None along the normals) the
    /// radiance.
    fn beside(
        &self,
        inputs: &PrincipledInputs,
        others: &[[f32; 3]],
        bounce: bool,
        walks: bool,
        radiance: Option<Option<Vec3>>,
    ) -> Result<Evaluation> {
        let t0 = Instant::now();
        let mut e = match count(others, self.positions.len())? {
            Some(counted) => {
                let material = Material::from_principled(inputs)?;
                let resolved = self.resolve(&material)?;
                // What the surface sends on: each vertex its own medium's slab albedo.
                let sent = match self.bounce.as_ref().filter(|_| bounce) {
                    Some(_) => Some(self.mean_sent(inputs, &resolved, &counted)?),
                    None => None,
                };
                let counting = t0.elapsed().as_secs_f64();
                let (mut e, _) = match radiance {
                    Some(eye) => self.radiance_inner(&resolved, eye, None, sent)?,
                    None => self.radiosity_inner(&resolved, bounce, walks, None, sent)?,
                };
                e.details.fit_seconds += counting;
                e.seconds += counting;
                e
            }
            // Another material that is itself textured: every vertex read as its own colour.
            None => {
                let colors = merged(inputs.base_color.map(|x| x as f32), others);
                let mut e = match radiance {
                    Some(eye) => self.radiance_textured(inputs, &colors, None, eye)?,
                    None => self.radiosity_textured(inputs, &colors, None, bounce, walks)?,
                };
                let merging = t0.elapsed().as_secs_f64() - e.seconds;
                e.details.fit_seconds += merging;
                e.seconds += merging;
                e
            }
        };
        let t = Instant::now();
        let hidden: usize = (e.values.par_iter_mut().zip(others))
            .map(|(value, other)| {
                let other = !other[0].is_nan();
                if other {
                    *value = [f32::NAN; 3];
                }
                usize::from(other)
            })
            .sum();
        e.seconds += t.elapsed().as_secs_f64();
        e.details.dot_seconds += t.elapsed().as_secs_f64();
        e.skipped.push(Skipped::new(
            "other materials' vertices",
            format!(
                "{hidden} vertices of other materials: not previewed (NaN); they scatter as \
                 their own colour into the object's own light"
            ),
        ));
        Ok(e)
    }

    /// The slab albedo along the normal (`Resolved::sent_on`) averaged over the vertices: the
    /// previewed ones of `resolved`, the others of `inputs` with their own Base Color.
    fn mean_sent(
        &self,
        inputs: &PrincipledInputs,
        resolved: &crate::profiles::Resolved,
        counted: &Others,
    ) -> Result<[f64; 3]> {
        let own = resolved.sent_on(1.0);
        let mut sum = own.map(|s| s * counted.previewed as f64);
        for &(color, n) in &counted.colors {
            let m = Material::from_principled(&PrincipledInputs {
                base_color: color.map(f64::from),
                ..*inputs
            })?;
            let s = self.resolve(&m)?.sent_on(1.0);
            for c in 0..3 {
                sum[c] += s[c] * n as f64;
            }
        }
        let n = (counted.previewed + counted.colors.iter().map(|c| c.1).sum::<usize>()).max(1);
        Ok(sum.map(|s| s / n as f64))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::Density;
    use crate::mesh::test_meshes::sphere_pair;
    use crate::mesh::Mesh;
    use crate::prt::PrtSettings;

    /// Base Colour 0.75 (a node of the textured edit's table: no interpolation for the
    /// previewed vertices there), radius (2, 1, 0.5) units, IOR 1.5.
    fn inputs() -> PrincipledInputs {
        PrincipledInputs {
            base_color: [0.75; 3],
            radius: [2.0, 1.0, 0.5],
            scale: 1.0,
            subsurface_weight: 1.0,
            ..Default::default()
        }
    }

    /// Two spheres of radius 10 two units apart, lit from above: each lights the other (the
    /// object's own light is not nil), the dipole with 8 x 8 own-light rays per vertex.
    fn pair() -> (Mesh, Prt) {
        let mesh = sphere_pair(14, 10.0, 11.0);
        let light = |_: &[Vec3], n: &[Vec3], _: Density| {
            Ok(n.iter().map(|n| [0.2 + n.z.max(0.0); 3]).collect())
        };
        let settings = PrtSettings {
            eta: 1.5,
            interreflection: Some(8),
            ..Default::default()
        };
        let m = Material::from_principled(&inputs()).unwrap();
        let prt = Prt::precompute(&mesh, &[m], &settings, &light, None).unwrap();
        (mesh, prt)
    }

    /// The second sphere's vertices (x > 0) carry `color`, the first's are previewed.
    fn others_on_second(mesh: &Mesh, color: impl Fn(usize) -> [f32; 3]) -> Vec<[f32; 3]> {
        (mesh.positions().iter().enumerate())
            .map(|(v, p)| if p.x > 0.0 { color(v) } else { [f32::NAN; 3] })
            .collect()
    }

    /// The per-vertex edit with the others' colours in its rows (the previewed ones 0.75).
    fn per_vertex(prt: &Prt, others: &[[f32; 3]]) -> Vec<[f32; 3]> {
        (prt.radiosity_textured(&inputs(), &merged([0.75; 3], others), None, true, true))
            .unwrap()
            .values
    }

    /// At every previewed vertex `got` within `rel` of `expect`; the others' rows NaN.
    fn check(expect: &[[f32; 3]], got: &[[f32; 3]], others: &[[f32; 3]], rel: f32) {
        for ((a, b), o) in expect.iter().zip(got).zip(others) {
            if !o[0].is_nan() {
                assert!(b.iter().all(|x| x.is_nan()), "another material's row {b:?}");
                continue;
            }
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= rel * a[c].abs().max(1e-6),
                    "{a:?} {b:?}"
                );
            }
        }
    }

    #[test]
    fn others_of_the_materials_own_colour_are_the_uniform_edit() {
        // Nothing differs from the uniform material at the previewed vertices: the same
        // values up to rounding, whatever the others' rows are called.
        let (mesh, prt) = pair();
        let m = Material::from_principled(&inputs()).unwrap();
        let uniform = prt.radiosity(&m).unwrap().values;
        let own = others_on_second(&mesh, |_| [0.75; 3]);
        let got = prt.radiosity_beside(&inputs(), &own, true, true).unwrap();
        check(&uniform, &got.values, &own, 1e-6);
        assert!(got
            .skipped
            .iter()
            .any(|s| s.what.contains("other materials")));
        let bare = prt.radiosity_with(&m, false).unwrap().values;
        let lit: f64 = (uniform.iter().zip(&bare))
            .map(|(u, b)| f64::from(u[0] - b[0]))
            .sum();
        assert!(lit > 0.0, "the own light must not be nil here: {lit}");
    }

    #[test]
    fn the_others_colours_reach_the_previewed_vertices_as_the_per_vertex_edit_has_them() {
        // The per-vertex edit (`textured`: each vertex its own medium from a table of them,
        // the own light scaled by the table's blend of what each vertex sends on) is the
        // reference: at the previewed vertices (Base Colour on a node) only the others' slab
        // albedos differ, interpolated there, exact here: within the table's tolerance of the
        // own light. A dark neighbour lights the previewed sphere less than a bright one.
        let (mesh, prt) = pair();
        let mut sums = Vec::new();
        for shade in [0.05f32, 0.95] {
            let others = others_on_second(&mesh, |_| [shade, 0.5 * shade, 0.3]);
            let got = prt
                .radiosity_beside(&inputs(), &others, true, true)
                .unwrap();
            check(&per_vertex(&prt, &others), &got.values, &others, 2e-3);
            let previewed = got.values.iter().filter(|b| !b[0].is_nan());
            sums.push(previewed.map(|b| f64::from(b[0])).sum::<f64>());
        }
        assert!(
            sums[0] < sums[1],
            "dark {} against bright {}",
            sums[0],
            sums[1]
        );
    }

    #[test]
    fn another_material_that_is_itself_textured_is_read_per_vertex() {
        // Past `OTHER_COLORS_MOST` distinct colours the edit is the per-vertex one, the
        // others' rows NaN.
        let (mesh, prt) = pair();
        let others = others_on_second(&mesh, |v| [(v % 40) as f32 / 40.0, 0.4, 0.6]);
        let got = prt
            .radiosity_beside(&inputs(), &others, true, true)
            .unwrap();
        check(&per_vertex(&prt, &others), &got.values, &others, 1e-6);
    }

    #[test]
    fn bad_others_are_errors_that_name_the_argument() {
        let (mesh, prt) = pair();
        let n = mesh.vertex_count();
        let e = (prt.radiosity_beside(&inputs(), &[[0.5; 3]; 3], true, true)).unwrap_err();
        assert!(e.to_string().contains("others has 3 rows"), "{e}");
        for bad in [[0.5, f32::NAN, 0.5], [0.5, f32::INFINITY, 0.5]] {
            let mut others = vec![[f32::NAN; 3]; n];
            others[7] = bad;
            let e = (prt.radiosity_beside(&inputs(), &others, true, true)).unwrap_err();
            assert!(e.to_string().contains("others row 7"), "{e}");
        }
        let e =
            (prt.radiance_beside(&inputs(), &vec![[f32::NAN; 3]; n], Some(Vec3::NAN))).unwrap_err();
        assert!(matches!(e, Error::InvalidArgument(_)), "{e}");
    }
}

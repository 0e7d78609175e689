//! A Base Color that varies over the surface (issue 30, point 2): an image texture, a colour
//! attribute or a procedural driving the Principled BSDF's Base Color.
//!
//! Cycles' random walk takes its medium from the point where it starts (the shading point
//! whose closure set it up: `subsurface_random_walk` reads the BSSRDF's albedo and radius
//! there), so B at a vertex is the profile of that vertex's own Base Color applied to the
//! light around it (Xu 2007 eq. 9 with a coefficient vector per vertex):
//!
//! ```text
//! B(x_o) = sum_j c_j(a(x_o)) T_j(x_o),
//! ```
//!
//! a(x_o) the vertex's Base Color per channel, read from the table of media (`color_table`:
//! fitted at nodes of the Base Color, interpolated linearly between them, its interpolation
//! error in the estimate) at each vertex's place among its nodes (`color_picks`). The point
//! mass, the walks' term (read at each vertex's diffusion length, scaled by its slab albedo)
//! and the object's own light (received at each vertex's totals) follow the vertex's nodes the
//! same way (`vertex_media`). Subsurface Radius and Scale stay uniform (the transport's samples
//! and knots are spaced for one radius).

use super::color_table::{Node, Table};
use super::evaluate::{add_indirect_noise, Evaluation, PrtDetails};
use super::vertex_media::{add_layers, blend, Finish, OwnLight, PerNode, Vertex};
use super::Prt;
use crate::error::{Error, Result};
use crate::evaluation::{radiance_from_radiosity_each, Quantity, Skipped};
use crate::optics::principled::PrincipledInputs;
use crate::profiles::ProfileKind;
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// The Subsurface Weight per vertex checked: one value in [0, 1] per vertex.
fn check_weights(weights: &[f32], vertices: usize) -> Result<()> {
    if weights.len() != vertices {
        return Err(Error::InvalidArgument(format!(
            "subsurface_weight has {} values, the transport {vertices} vertices",
            weights.len()
        )));
    }
    if let Some(v) = (weights.iter()).position(|w| !(w.is_finite() && (0.0..=1.0).contains(w))) {
        return Err(Error::InvalidArgument(format!(
            "subsurface_weight of vertex {v} is {}: must lie in [0, 1]",
            weights[v]
        )));
    }
    Ok(())
}

/// The Base Color per vertex checked: one finite triple per vertex.
fn check_colors(colors: &[[f32; 3]], vertices: usize) -> Result<()> {
    if colors.len() != vertices {
        return Err(Error::InvalidArgument(format!(
            "base_color has {} rows, the transport {vertices} vertices",
            colors.len()
        )));
    }
    if let Some(v) = colors.iter().position(|c| c.iter().any(|x| !x.is_finite())) {
        return Err(Error::InvalidArgument(format!(
            "base_color of vertex {v} is not finite: {:?}",
            colors[v]
        )));
    }
    Ok(())
}

impl Prt {
    /// Multiple-scattering radiosity with the Base Color per vertex (`colors`, linear RGB;
    /// Cycles saturates it to [0, 1]) and optionally the Subsurface Weight per vertex
    /// (`weights`, in [0, 1]; Cycles' profile only), the rest of the Principled inputs
    /// uniform (`inputs.base_color`, and `inputs.subsurface_weight` where `weights` is given,
    /// are not read). `bounce` and `walks` as `radiosity_parts`. The estimate adds the
    /// interpolation error between the table's nodes; single scattering and a GPU copy are not
    /// read (the dot product runs on the CPU).
    ///
    /// The weight splits the Principled BSDF's lobes under its layers (Cycles'
    /// `principled::lobe_weights`): subsurface w and diffuse (1 - w), both times the Base
    /// Color. Each part is linear in w, so the table is fitted at w = 1 and each vertex takes
    /// w of that medium's answer (the transport, the walks, the own light it receives) and
    /// (1 - w) of the diffuse lobe's, its Base Color times its irradiance plus the own light.
    pub fn radiosity_textured(
        &self,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        weights: Option<&[f32]>,
        bounce: bool,
        walks: bool,
    ) -> Result<Evaluation> {
        (self.textured(inputs, colors, weights, bounce, walks, false)).map(|(e, _)| e)
    }

    /// `radiosity_textured` and the table it read; `along_normals`: radiance along each
    /// normal instead (B times the vertex's exit weight and view factor blended between its
    /// nodes, over pi), taken in the same pass as the layers.
    fn textured(
        &self,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        weights: Option<&[f32]>,
        bounce: bool,
        walks: bool,
        along_normals: bool,
    ) -> Result<(Evaluation, Table)> {
        let t0 = Instant::now();
        check_colors(colors, self.positions.len())?;
        if let Some(w) = weights {
            if self.profile != ProfileKind::Cycles {
                return Err(Error::InvalidArgument(
                    "subsurface_weight per vertex splits the Principled lobes: Cycles' profile \
                     only (the dipole has no lobes)"
                        .into(),
                ));
            }
            check_weights(w, self.positions.len())?;
        }
        // With a weight per vertex the media are fitted whole (w = 1), their diffuse part apart.
        let fitted = PrincipledInputs {
            subsurface_weight: if weights.is_some() {
                1.0
            } else {
                inputs.subsurface_weight
            },
            ..*inputs
        };
        let inputs = &fitted;
        let table = self.table(inputs, colors)?;
        let fit_seconds = t0.elapsed().as_secs_f64();
        let t1 = Instant::now();
        let vectors: Vec<Option<[Vec<f32>; 3]>> = table
            .nodes
            .iter()
            .map(|n| n.as_ref().map(|n| n.coefficients.vectors.clone()))
            .collect();
        let mut radiosity = self
            .transport
            .dot_interpolated(&vectors, &table.picked.picks);
        // The lobes' split per vertex: the subsurface share w, and the diffuse lobe's albedo
        // (1 - w) x below x Base Color (saturated), below = (1 - Metallic)(1 - Transmission).
        let below = (1.0 - inputs.metallic) * (1.0 - inputs.transmission);
        let vertex = Vertex {
            picks: &table.picked.picks,
            weights,
            colors,
            below,
        };
        if let Some(w) = weights {
            (radiosity.par_iter_mut().enumerate()).for_each(|(v, b)| {
                let i = self.vertex_irradiance[v];
                for c in 0..3 {
                    let d = vertex.diffuse(v, c) * f64::from(i[c]);
                    b[c] = (f64::from(w[v]) * f64::from(b[c]) + d) as f32;
                }
            });
        }
        // Per node, the quantities a vertex blends as it blends the coefficients.
        let per_node = |f: &dyn Fn(&Node) -> [f64; 3]| -> Vec<[f64; 3]> {
            table
                .nodes
                .iter()
                .map(|n| n.as_ref().map_or([0.0; 3], f))
                .collect()
        };
        let nodes = PerNode {
            fitted: table.nodes.iter().map(Option::is_some).collect(),
            point_mass: per_node(&|n| n.coefficients.point_mass),
            ln_length: per_node(&|n| n.ln_length),
            walk_albedo: per_node(&|n| n.walk_albedo),
            totals: per_node(&|n| n.totals),
        };
        let mut error_estimate = table.error;
        let own = self.bounce.as_ref().filter(|_| bounce).map(|own| {
            // What the surface sends on, averaged over the vertices (each sender has its own
            // Base Color; the gathered E_ind holds no record of who sent it), against the
            // representative's: the indirect light's scale.
            let n = table.picked.picks.len().max(1) as f64;
            let (sent_per_node, along) = (per_node(&|n| n.sent), per_node(&|n| n.along_normal));
            // A vertex of weight w sends w of its medium's and (1 - w) of its diffuse lobe's:
            // the same exit weight and specular layer, the lobe's albedo for the medium's total.
            let mut sent: [f64; 3] = std::array::from_fn(|c| {
                (sent_per_node.iter().zip(&table.picked.node_weights))
                    .map(|(s, w)| s[c] * w[c])
                    .sum()
            });
            if weights.is_some() {
                let lobes: [f64; 3] = (table.picked.picks.par_iter().enumerate())
                    .map(|(v, p)| -> [f64; 3] {
                        std::array::from_fn(|c| {
                            let lobe = (1.0 - vertex.share(v)) * blend(&nodes.totals, p, c)
                                - vertex.diffuse(v, c);
                            blend(&along, p, c) * lobe
                        })
                    })
                    .reduce(|| [0.0; 3], |a, b| std::array::from_fn(|c| a[c] + b[c]));
                sent = std::array::from_fn(|c| sent[c] - lobes[c]);
            }
            OwnLight {
                irradiance: &own.irradiance,
                ratio: own.ratio(sent.map(|s| s / n)),
                walked: own.walked.as_ref().filter(|_| walks),
            }
        });
        // Radiance along the normals: each vertex's B times its exit weight and view factor
        // (blended as the coefficients are) over pi, with the lights' scale, once B is whole.
        let along = along_normals.then(|| {
            let scale = self.light_scale;
            Finish {
                along: per_node(&|n| n.along_normal),
                scale: std::array::from_fn(|c| f64::from(scale[c]) / std::f64::consts::PI),
            }
        });
        let (direct, indirect) = add_layers(
            &mut radiosity,
            &vertex,
            &nodes,
            &self.vertex_irradiance,
            self.walks.as_ref().filter(|_| walks),
            own.as_ref(),
            along.as_ref(),
        );
        for (e, a) in error_estimate.iter_mut().zip(direct) {
            *e += a;
        }
        // The vertices' bounce noise (`irradiance_noise`): each vertex's gain blended from its
        // nodes, split between its lobes, and turned into radiance as its B was.
        let irradiance_noise = self.irradiance_noise.as_ref().map_or([0.0; 3], |n| {
            let near = per_node(&|n| {
                std::array::from_fn(|c| {
                    f64::from(n.coefficients.vectors[c][0]) + n.coefficients.point_mass[c]
                })
            });
            let picks = &table.picked.picks;
            let finish = |v: usize, c: usize, x: f64| {
                along
                    .as_ref()
                    .map_or(x, |f| x * blend(&f.along, &picks[v], c) * f.scale[c])
            };
            let gain = |v: usize, c: usize| {
                finish(
                    v,
                    c,
                    vertex.share(v) * blend(&near, &picks[v], c) + vertex.diffuse(v, c),
                )
            };
            let scale = |v: usize, c: usize| {
                let a = blend(&nodes.totals, &picks[v], c) / n.totals[c];
                finish(v, c, vertex.share(v) * a)
            };
            let walked = self.walks.is_some() && walks;
            n.relative(&radiosity, &gain, &scale, walked)
        });
        for (e, x) in error_estimate.iter_mut().zip(irradiance_noise) {
            *e += x;
        }
        if own.as_ref().is_some_and(|o| o.walked.is_some()) {
            add_indirect_noise(
                &mut error_estimate,
                indirect,
                self.report.interreflection_share,
            );
        }
        if !along_normals {
            self.apply_light_scale(&mut radiosity);
        }
        let dot_seconds = t1.elapsed().as_secs_f64();
        let mut skipped = self.skipped(bounce, walks);
        if self.single.is_some() {
            skipped.push(Skipped::new(
                "single scattering",
                "not with a Base Color per vertex yet (multiple scattering alone)",
            ));
        }
        let fit_error = std::array::from_fn(|c| {
            table
                .nodes
                .iter()
                .flatten()
                .map(|n| n.coefficients.fit_error[c])
                .fold(0.0, f64::max)
        });
        let evaluation = Evaluation {
            values: radiosity,
            quantity: Quantity::Radiosity,
            error_estimate: Some(error_estimate),
            seconds: fit_seconds + dot_seconds,
            skipped,
            details: PrtDetails {
                fit_error,
                fit_seconds,
                dot_seconds,
                gpu: None,
                irradiance_noise,
            },
        };
        Ok((evaluation, table))
    }

    /// Multiple-scattering radiance toward `eye` (or along each normal) with the Base Color
    /// per vertex: `radiosity_textured` turned into radiance by each vertex's own exit weight
    /// (its view factor blended between its nodes as the coefficients are).
    pub fn radiance_textured(
        &self,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        weights: Option<&[f32]>,
        eye: Option<Vec3>,
    ) -> Result<Evaluation> {
        crate::evaluation::check_eye(eye)?;
        let (mut e, table) = self.textured(inputs, colors, weights, true, true, eye.is_none())?;
        let t = Instant::now();
        // Along the normals (no eye) the layers' pass took it. Toward an eye, per vertex the
        // shared exit weight and each channel's view factor at its two nodes.
        if eye.is_some() {
            let along: Vec<[f64; 3]> = table
                .nodes
                .iter()
                .map(|n| n.as_ref().map_or([0.0; 3], |n| n.along_normal))
                .collect();
            let weights = |v: usize, cos_o: Option<f64>| -> [f64; 3] {
                let p = &table.picked.picks[v];
                let Some(cos) = cos_o else {
                    return std::array::from_fn(|c| blend(&along, p, c));
                };
                std::array::from_fn(|c| {
                    let (k, t) = p[c];
                    let at = |k: u32| {
                        table.nodes[k as usize].as_ref().map_or(0.0, |n| {
                            n.resolved.exit_weight(cos) * n.resolved.profiles[c].view_factor(cos)
                        })
                    };
                    let below = at(k);
                    if t > 0.0 {
                        below + f64::from(t) * (at(k + 1) - below)
                    } else {
                        below
                    }
                })
            };
            radiance_from_radiosity_each(
                &mut e.values,
                &self.positions,
                &self.normals,
                eye,
                &weights,
            );
        }
        e.quantity = Quantity::Radiance;
        e.details.dot_seconds += t.elapsed().as_secs_f64();
        e.seconds = e.details.fit_seconds + e.details.dot_seconds;
        Ok(e)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::irradiance::Density;
    use crate::mesh::test_meshes::oracles::rd_total;
    use crate::mesh::test_meshes::plane;
    use crate::mesh::Mesh;
    use crate::optics::fresnel_transmittance;
    use crate::optics::Material;
    use crate::profiles::Resolved;
    use crate::prt::color_table::DARK_SHARE;
    use crate::prt::PrtSettings;

    /// A Principled BSDF of radius (2, 1, 0.5) units, IOR 1.5: under the dipole, each
    /// channel's medium is Cycles' map of the Base Color.
    fn inputs() -> PrincipledInputs {
        PrincipledInputs {
            base_color: [0.8; 3],
            radius: [2.0, 1.0, 0.5],
            scale: 1.0,
            subsurface_weight: 1.0,
            ..Default::default()
        }
    }

    #[test]
    fn each_vertex_of_a_uniformly_lit_plane_returns_its_own_base_colours_slab_albedo() {
        // Under uniform irradiance E on a large plane, B at a vertex is E R_d,total of its own
        // medium whatever its neighbours' (the profile is the receiver's, Cycles' walk the
        // starting point's): the dipole's closed form (Jensen 2001 eq. 5) per vertex, with
        // Base Colours drawn at random so every node and interval of the table is read.
        let mesh = plane(121, 400.0);
        let eta = 1.5;
        let e = fresnel_transmittance(eta, 1.0) as f32;
        let light = move |p: &[Vec3], _: &[Vec3], _: Density| Ok(vec![[e; 3]; p.len()]);
        // The texture's darkest and brightest Base Colours as representatives: the support
        // and knots cover every medium between them (what the add-on passes).
        let reps = [0.05, 0.85].map(|x| {
            Material::from_principled(&PrincipledInputs {
                base_color: [x; 3],
                ..inputs()
            })
            .unwrap()
        });
        let settings = PrtSettings {
            eta,
            ..Default::default()
        };
        let prt = Prt::precompute(&mesh, &reps, &settings, &light, None).unwrap();
        let support = prt.report().support_radius;
        let mut next = draws(7);
        let colors: Vec<[f32; 3]> = (0..mesh.vertex_count())
            .map(|_| [0.05 + 0.8 * next(), 0.85 * next(), 0.3 + 0.55 * next()])
            .collect();
        let got = prt
            .radiosity_textured(&inputs(), &colors, None, true, true)
            .unwrap();
        let estimate = got.error_estimate.unwrap();
        let mut expected = vec![[0.0f64; 3]; colors.len()];
        for (v, col) in colors.iter().enumerate() {
            let m = Material::from_principled(&PrincipledInputs {
                base_color: col.map(f64::from),
                ..inputs()
            })
            .unwrap();
            expected[v] = std::array::from_fn(|c| {
                f64::from(e) * rd_total(m.sigma_a[c], m.sigma_s_prime()[c], eta)
            });
        }
        let mut worst = [0.0f64; 3];
        let inner = |p: &Vec3| (p.x.abs().max(p.y.abs()) as f64) < 200.0 - support;
        let checked = mesh.positions().iter().filter(|p| inner(p)).count();
        assert!(
            checked > 500,
            "{checked} vertices inside the rim (support {support})"
        );
        for c in 0..3 {
            // Judged against the channel's brightest beside the darkest (`DARK_SHARE`).
            let floor = DARK_SHARE * expected.iter().map(|x| x[c]).fold(0.0, f64::max);
            for (v, p) in mesh.positions().iter().enumerate() {
                if !inner(p) {
                    continue; // the plane's rim: less surface around than the closed form's
                }
                let expect = expected[v][c];
                let rel = (f64::from(got.values[v][c]) - expect).abs() / expect.max(floor);
                worst[c] = worst[c].max(rel);
            }
        }
        eprintln!(
            "worst per-vertex error {worst:?} over {checked} vertices, estimate {estimate:?}"
        );
        for c in 0..3 {
            assert!(worst[c] < 0.02, "channel {c}: {:.2} %", 100.0 * worst[c]);
            assert!(
                estimate[c] < 0.05 && estimate[c] > 0.0,
                "estimate {estimate:?}"
            );
        }
    }

    /// Uniform draws in [0, 1) from a linear congruential sequence seeded with `seed`.
    fn draws(mut seed: u64) -> impl FnMut() -> f32 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 40) as f32) / (1u64 << 24) as f32
        }
    }

    /// `got` within `rel` of `expect` at every vertex and channel (relative, floored at 1e-6).
    fn assert_close(expect: &[[f32; 3]], got: &[[f32; 3]], rel: f32, what: &str) {
        assert_eq!(expect.len(), got.len(), "{what}");
        for (a, b) in expect.iter().zip(got) {
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= rel * a[c].abs().max(1e-6),
                    "{what}: {a:?} {b:?}"
                );
            }
        }
    }

    /// A uniformly lit plane under Cycles' profile, `inputs` with Base Colour 0.75 (a node:
    /// no interpolation between media), precomputed for the whole medium (weight 1).
    fn cycles_plane() -> (Mesh, Prt, PrincipledInputs) {
        let mesh = plane(61, 200.0);
        let light = |p: &[Vec3], _: &[Vec3], _: Density| Ok(vec![[1.0f32; 3]; p.len()]);
        let at = PrincipledInputs {
            base_color: [0.75; 3],
            ..inputs()
        };
        let settings = PrtSettings {
            eta: 1.0, // Cycles' irradiance: the specular layer takes the Fresnel part
            profile: ProfileKind::Cycles,
            ..Default::default()
        };
        let m = Material::from_principled(&at).unwrap();
        let prt = Prt::precompute(&mesh, &[m], &settings, &light, None).unwrap();
        (mesh, prt, at)
    }

    #[test]
    fn a_subsurface_weight_per_vertex_splits_each_vertex_between_its_lobes() {
        // Under uniform irradiance E = 1 on a large plane, B at a vertex of weight w is
        // w T + (1 - w) a: T the whole medium's total (its profile's integral, from the walk
        // table, not from the transport) and a the diffuse lobe's albedo, the Base Colour
        // (Metallic and Transmission 0). Weights drawn at random per vertex.
        let (mesh, prt, at) = cycles_plane();
        let whole = Material::from_principled(&at).unwrap();
        let total = Resolved::new(ProfileKind::Cycles, &whole).unwrap().totals();
        let n = mesh.vertex_count();
        let mut next = draws(11);
        let weights: Vec<f32> = (0..n).map(|_| next()).collect();
        let colors = vec![[0.75f32; 3]; n];
        let got = prt
            .radiosity_textured(&at, &colors, Some(&weights), true, true)
            .unwrap();
        let support = prt.report().support_radius;
        let inner = |p: &Vec3| (p.x.abs().max(p.y.abs()) as f64) < 100.0 - support;
        let mut worst = 0.0f64;
        let mut checked = 0;
        for (v, p) in mesh.positions().iter().enumerate() {
            if !inner(p) {
                continue;
            }
            checked += 1;
            let w = f64::from(weights[v]);
            for (t, b) in total.iter().zip(got.values[v]) {
                let expect = w * t + (1.0 - w) * 0.75;
                worst = worst.max((f64::from(b) - expect).abs() / expect);
            }
        }
        assert!(checked > 100, "{checked} vertices inside the rim");
        assert!(worst < 0.02, "worst vertex {:.2} %", 100.0 * worst);
        // Weight 0 everywhere is the diffuse lobe alone: the Base Colour times E, exactly.
        let zero = prt
            .radiosity_textured(&at, &colors, Some(&vec![0.0; n]), true, true)
            .unwrap();
        assert!(zero
            .values
            .iter()
            .flatten()
            .all(|b| (b - 0.75).abs() < 1e-6));
    }

    #[test]
    fn one_weight_at_every_vertex_is_the_uniform_material_of_that_weight() {
        // The uniform material carries its diffuse lobe as the profile's point mass (the walk
        // table's, `profiles::table`), an independent route to the same answer.
        let (mesh, prt, at) = cycles_plane();
        let n = mesh.vertex_count();
        let colors = vec![[0.75f32; 3]; n];
        for w in [0.0f64, 0.35, 0.8] {
            let uniform = Material::from_principled(&PrincipledInputs {
                subsurface_weight: w,
                ..at
            })
            .unwrap();
            let expect = prt.radiosity(&uniform).unwrap().values;
            let got = prt
                .radiosity_textured(&at, &colors, Some(&vec![w as f32; n]), true, true)
                .unwrap()
                .values;
            assert_close(&expect, &got, 2e-3, &format!("w {w}"));
        }
    }

    #[test]
    fn bad_subsurface_weights_are_errors_that_name_the_argument() {
        let (mesh, prt, at) = cycles_plane();
        let n = mesh.vertex_count();
        let colors = vec![[0.75f32; 3]; n];
        for (weights, says) in [
            (vec![0.5f32; n - 1], "values"),
            (vec![1.5f32; n], "[0, 1]"),
            (vec![-0.1f32; n], "[0, 1]"),
            (vec![f32::NAN; n], "[0, 1]"),
        ] {
            let got = prt.radiosity_textured(&at, &colors, Some(&weights), true, true);
            let Err(Error::InvalidArgument(m)) = got else {
                panic!("accepted {:?}", &weights[..1]);
            };
            assert!(m.contains("subsurface_weight") && m.contains(says), "{m}");
        }
        // The dipole has no lobes to split.
        let light = |p: &[Vec3], _: &[Vec3], _: Density| Ok(vec![[1.0f32; 3]; p.len()]);
        let m = Material::from_principled(&at).unwrap();
        let settings = PrtSettings {
            eta: 1.5,
            ..Default::default()
        };
        let dipole = Prt::precompute(&mesh, &[m], &settings, &light, None).unwrap();
        let got = dipole.radiosity_textured(&at, &colors, Some(&vec![0.5; n]), true, true);
        assert!(matches!(got, Err(Error::InvalidArgument(m)) if m.contains("Cycles")));
    }

    #[test]
    fn a_uniform_base_colour_on_a_node_is_the_uniform_edit() {
        // Base Colour 0.75 in every channel lies on a node (12/16): the table reads that node
        // alone, so the edit is the uniform material's bit for bit up to the summation order.
        let mesh = plane(21, 100.0);
        let light = |p: &[Vec3], _: &[Vec3], _: Density| Ok(vec![[1.0f32; 3]; p.len()]);
        let m = Material::from_principled(&PrincipledInputs {
            base_color: [0.75; 3],
            ..inputs()
        })
        .unwrap();
        let settings = PrtSettings {
            eta: 1.5,
            ..Default::default()
        };
        let prt = Prt::precompute(&mesh, &[m], &settings, &light, None).unwrap();
        let uniform = prt.radiosity(&m).unwrap().values;
        let colors = vec![[0.75f32; 3]; mesh.vertex_count()];
        let textured = prt
            .radiosity_textured(&inputs(), &colors, None, true, true)
            .unwrap();
        assert_close(&uniform, &textured.values, 1e-5, "uniform");
    }

    #[test]
    fn bad_base_colours_are_errors_that_name_the_argument() {
        let mesh = plane(5, 10.0);
        let light = |p: &[Vec3], _: &[Vec3], _: Density| Ok(vec![[1.0f32; 3]; p.len()]);
        let m = Material::from_principled(&inputs()).unwrap();
        let settings = PrtSettings {
            eta: 1.5,
            ..Default::default()
        };
        let prt = Prt::precompute(&mesh, &[m], &settings, &light, None).unwrap();
        let short = vec![[0.5f32; 3]; 3];
        let e = prt
            .radiosity_textured(&inputs(), &short, None, true, true)
            .unwrap_err();
        assert!(e.to_string().contains("base_color has 3 rows"), "{e}");
        let mut nan = vec![[0.5f32; 3]; mesh.vertex_count()];
        nan[4][1] = f32::NAN;
        let e = prt
            .radiosity_textured(&inputs(), &nan, None, true, true)
            .unwrap_err();
        assert!(e.to_string().contains("base_color of vertex 4"), "{e}");
        // Beyond [0, 1] Cycles saturates: 1.7 is 1, -0.2 is 0.
        let over = vec![[1.7f32, -0.2, 1.0]; mesh.vertex_count()];
        let clamped = vec![[1.0f32, 0.0, 1.0]; mesh.vertex_count()];
        let a = prt
            .radiosity_textured(&inputs(), &over, None, true, true)
            .unwrap();
        let b = prt
            .radiosity_textured(&inputs(), &clamped, None, true, true)
            .unwrap();
        assert_eq!(a.values, b.values);
    }
}

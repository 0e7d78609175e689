//! A Base Color per vertex for a method that sums one medium's profile at a time (the
//! hierarchy): the surface is summed with a few media (`media`, Base Colors at the vertices'
//! area-weighted quantiles, channel by channel), and each receiver takes the two around its own
//! colour, each scaled by its own medium's slab total over that medium's, blended linearly.
//!
//! Cycles' random walk takes its medium where it starts, the shading point (docs/textures.md),
//! so B(x_o) = int R_{a(x_o)}(|x_o - x|) E(x) dA: the receiver's own profile over the light
//! around it. Under a light that is uniform over the profile's reach that is E T(a(x_o)), T the
//! slab total, and each scaled sum is exact; a receiver whose colour is a medium's is exact
//! under any light. Where the light changes within the reach, the profile's shape (not only its
//! total) changes with the albedo between media; the method measures that part at its
//! estimate's receivers (`Hierarchy`: each one summed again with its own medium).
//!
//! T(x) per channel is read from a table at Base Colors k / `NODES_PER_UNIT`, blended linearly;
//! every interval read is checked at its midpoint, and the worst miss is the table's error.
//!
//! A Subsurface Weight per vertex (`ReceiverColors::weighted`, Cycles' profile) splits the
//! Principled BSDF's lobes under its layers (`optics::principled::lobe_weights`): the media are
//! summed whole (weight 1) and each vertex takes w of its blend and (1 - w) of the diffuse lobe,
//! (1 - Metallic)(1 - Transmission) a(x_o) times the light at x_o (`Lobes::apply`), every part
//! linear in w, as PRT's textured path does (docs/textures.md).

use crate::error::{Error, Result};
use crate::optics::principled::PrincipledInputs;
use crate::optics::Material;
use crate::profiles::{ProfileKind, Resolved};

/// Intervals of the totals' table over the Base Color [0, 1].
pub const NODES_PER_UNIT: usize = 64;
/// The most media a textured evaluation sums.
pub const MAX_MEDIA: usize = 16;

/// One vertex's channel: B = a S_j + b S_{j+1}, S_j the sum with medium j.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Blend {
    pub j: u16,
    pub a: f32,
    pub b: f32,
}

impl Blend {
    /// a S_j + b S_{j+1}, with `sum(m)` medium m's sum (S_{j+1} read only where b is not 0:
    /// past the last medium there is none).
    #[inline]
    pub fn apply(self, sum: impl Fn(usize) -> f64) -> f64 {
        let j = self.j as usize;
        let next = if self.b != 0.0 { sum(j + 1) } else { 0.0 };
        f64::from(self.a) * sum(j) + f64::from(self.b) * next
    }
}

/// The media summed and each vertex's blend of them.
#[derive(Debug, Clone)]
pub struct ReceiverColors {
    /// The Principled inputs of each medium summed (their Base Color per channel a quantile
    /// of the vertices', increasing).
    pub media: Vec<PrincipledInputs>,
    /// Per vertex and channel.
    pub blends: Vec<[Blend; 3]>,
    /// The Base Color per vertex, saturated to [0, 1] as Cycles does.
    pub colors: Vec<[f32; 3]>,
    /// Per channel: the table's worst relative miss at the midpoint of an interval read.
    pub table_error: [f64; 3],
    /// A Subsurface Weight per vertex (`weighted`); None: the inputs' own weight everywhere.
    pub lobes: Option<Lobes>,
}

/// The Principled lobes' split per vertex by its Subsurface Weight.
#[derive(Debug, Clone)]
pub struct Lobes {
    /// The Subsurface Weight per vertex, in [0, 1].
    pub weights: Vec<f32>,
    /// (1 - Metallic)(1 - Transmission): what lies under the specular layer.
    pub below: f64,
    /// Per channel, what the surface sends on along the normal per unit irradiance
    /// (`Resolved::sent_on`), each vertex's two lobes by its weight, area-weighted over the
    /// vertices: the object's own light is sent by this mean (PRT's textured path does so).
    pub sent: [f64; 3],
}

impl Lobes {
    /// B = w B_medium + (1 - w) below a L per vertex: `b` holds each vertex's B of its medium at
    /// weight 1, `light` the light its diffuse lobe takes (irradiance plus the own light).
    /// What the sampling error of the light the diffuse lobes take (`errors`, its standard
    /// error per vertex) leaves in `b` (B after `apply`): the area-weighted relative RMS per
    /// channel of (1 - w) below a sigma. A lobe reads its vertex's light alone, so its noise
    /// does not average out under a profile.
    pub fn noise(
        &self,
        colors: &[[f32; 3]],
        errors: &[[f32; 3]],
        b: &[[f32; 3]],
        areas: &[f32],
    ) -> [f64; 3] {
        std::array::from_fn(|c| {
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for (v, bv) in b.iter().enumerate() {
                let a = f64::from(areas.get(v).copied().unwrap_or(0.0));
                let e = errors.get(v).map_or(0.0, |e| f64::from(e[c]));
                let lobe =
                    (1.0 - f64::from(self.weights[v])) * self.below * f64::from(colors[v][c]);
                num += a * (lobe * e).powi(2);
                den += a * f64::from(bv[c]).powi(2);
            }
            if den > 0.0 {
                (num / den).sqrt()
            } else {
                0.0
            }
        })
    }

    pub fn apply(&self, b: &mut [[f32; 3]], colors: &[[f32; 3]], light: &[[f32; 3]]) {
        for (v, bv) in b.iter_mut().enumerate() {
            let w = f64::from(self.weights[v]);
            for c in 0..3 {
                let diffuse = self.below * f64::from(colors[v][c]) * f64::from(light[v][c]);
                bv[c] = (w * f64::from(bv[c]) + (1.0 - w) * diffuse) as f32;
            }
        }
    }
}

impl ReceiverColors {
    /// `colors` (one per vertex, `areas` the vertices' areas) under `inputs`' other Principled
    /// inputs and profile `kind`, summed with `media` media (1 to `MAX_MEDIA`). Errors name
    /// `base_color` for a wrong length or a value that is not finite, and `media`; Cycles
    /// saturates the rest to [0, 1].
    pub fn new(
        kind: ProfileKind,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        areas: &[f32],
        media: usize,
    ) -> Result<ReceiverColors> {
        if !(1..=MAX_MEDIA).contains(&media) {
            return Err(Error::InvalidArgument(format!(
                "media = {media}: must lie in [1, {MAX_MEDIA}]"
            )));
        }
        if colors.len() != areas.len() {
            return Err(Error::InvalidArgument(format!(
                "base_color has {} rows for {} vertices",
                colors.len(),
                areas.len()
            )));
        }
        if let Some(v) = colors.iter().position(|c| c.iter().any(|x| !x.is_finite())) {
            return Err(Error::InvalidArgument(format!(
                "base_color of vertex {v} is not finite: {:?}",
                colors[v]
            )));
        }
        let colors: Vec<[f32; 3]> = colors
            .iter()
            .map(|c| c.map(|x| x.clamp(0.0, 1.0)))
            .collect();
        // Per channel, the media's Base Colors: area-weighted quantiles (k + 1/2) / media.
        let nodes: [Vec<f64>; 3] = std::array::from_fn(|c| {
            let mut order: Vec<(f32, f32)> =
                colors.iter().zip(areas).map(|(x, &a)| (x[c], a)).collect();
            order.sort_by(|x, y| x.0.total_cmp(&y.0));
            let total: f64 = order.iter().map(|x| f64::from(x.1)).sum();
            let mut out = Vec::with_capacity(media);
            let (mut acc, mut i) = (0.0f64, 0usize);
            for k in 0..media {
                let q = (k as f64 + 0.5) / media as f64 * total;
                while i + 1 < order.len() && acc + f64::from(order[i].1) < q {
                    acc += f64::from(order[i].1);
                    i += 1;
                }
                out.push(order.get(i).map_or(0.0, |x| f64::from(x.0)));
            }
            out
        });
        let table = Totals::new(kind, inputs, &colors, &nodes)?;
        let media: Vec<PrincipledInputs> = (0..media)
            .map(|j| PrincipledInputs {
                base_color: std::array::from_fn(|c| nodes[c][j]),
                ..*inputs
            })
            .collect();
        let at_nodes: [Vec<f64>; 3] =
            std::array::from_fn(|c| nodes[c].iter().map(|&x| table.at(c, x)).collect());
        let ratio = |t: f64, at: f64| if at > 0.0 { (t / at) as f32 } else { 0.0 };
        let blends = (colors.iter())
            .map(|col| {
                std::array::from_fn(|c| {
                    let x = f64::from(col[c]);
                    let t = table.at(c, x);
                    let n = &nodes[c];
                    // The last node at or below x (the first when x is below them all).
                    let j = n.iter().rposition(|&y| y <= x).unwrap_or(0);
                    if j + 1 >= n.len() || n[j + 1] <= n[j] || x <= n[j] {
                        return Blend {
                            j: j as u16,
                            a: ratio(t, at_nodes[c][j]),
                            b: 0.0,
                        };
                    }
                    let w = (x - n[j]) / (n[j + 1] - n[j]);
                    Blend {
                        j: j as u16,
                        a: (1.0 - w) as f32 * ratio(t, at_nodes[c][j]),
                        b: w as f32 * ratio(t, at_nodes[c][j + 1]),
                    }
                })
            })
            .collect();
        Ok(ReceiverColors {
            media,
            blends,
            colors,
            table_error: table.error,
            lobes: None,
        })
    }

    /// `new` with a Subsurface Weight per vertex (`weights`, in [0, 1], Cycles' profile only):
    /// the media summed at weight 1 (`inputs.subsurface_weight` is not read) and each vertex's
    /// lobes split by its own weight (`Lobes`). Errors name `subsurface_weight`.
    pub fn weighted(
        kind: ProfileKind,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        areas: &[f32],
        media: usize,
        weights: &[f32],
    ) -> Result<ReceiverColors> {
        if kind != ProfileKind::Cycles {
            return Err(Error::InvalidArgument(
                "subsurface_weight per vertex splits the Principled lobes: Cycles' profile only \
                 (the dipole has no lobes)"
                    .into(),
            ));
        }
        if weights.len() != areas.len() {
            return Err(Error::InvalidArgument(format!(
                "subsurface_weight has {} values for {} vertices",
                weights.len(),
                areas.len()
            )));
        }
        if let Some(v) = (weights.iter()).position(|w| !(w.is_finite() && (0.0..=1.0).contains(w)))
        {
            return Err(Error::InvalidArgument(format!(
                "subsurface_weight of vertex {v} is {}: must lie in [0, 1]",
                weights[v]
            )));
        }
        let whole = PrincipledInputs {
            subsurface_weight: 1.0,
            ..*inputs
        };
        let mut out = Self::new(kind, &whole, colors, areas, media)?;
        // What each lobe sends on along the normal: the diffuse lobe's is affine in its colour
        // (its albedo below the layer plus the layer's reflection), read at 0 and 1; the
        // subsurface lobe's at each medium, interpolated between the two around the vertex.
        let sent_of = |w: f64, a: [f64; 3]| -> Result<[f64; 3]> {
            let m = Material::from_principled(&PrincipledInputs {
                base_color: a,
                subsurface_weight: w,
                ..*inputs
            })?;
            Ok(Resolved::new(kind, &m)?.sent_on(1.0))
        };
        let (d0, d1) = (sent_of(0.0, [0.0; 3])?, sent_of(0.0, [1.0; 3])?);
        let whole_sent = (out.media.iter())
            .map(|m| sent_of(1.0, m.base_color))
            .collect::<Result<Vec<_>>>()?;
        let mut sent = [0.0f64; 3];
        let mut area = 0.0f64;
        for (v, (&w, &a)) in weights.iter().zip(areas).enumerate() {
            let (w, a) = (f64::from(w), f64::from(a));
            area += a;
            for c in 0..3 {
                let j = out.blends[v][c].j as usize;
                let x = f64::from(out.colors[v][c]);
                let whole = match (out.media.get(j), out.media.get(j + 1)) {
                    (Some(m0), Some(m1)) if m1.base_color[c] > m0.base_color[c] => {
                        let (x0, x1) = (m0.base_color[c], m1.base_color[c]);
                        let t = ((x - x0) / (x1 - x0)).clamp(0.0, 1.0);
                        (1.0 - t) * whole_sent[j][c] + t * whole_sent[j + 1][c]
                    }
                    _ => whole_sent[j][c],
                };
                let diffuse = d0[c] + x * (d1[c] - d0[c]);
                sent[c] += a * (w * whole + (1.0 - w) * diffuse);
            }
        }
        out.lobes = Some(Lobes {
            weights: weights.to_vec(),
            below: (1.0 - inputs.metallic) * (1.0 - inputs.transmission),
            sent: sent.map(|s| if area > 0.0 { s / area } else { 0.0 }),
        });
        Ok(out)
    }

    /// The medium of vertex `v`'s own Base Color (the estimate sums it again with this).
    pub fn medium_at(&self, v: usize) -> Result<Material> {
        Material::from_principled(&PrincipledInputs {
            base_color: self.colors[v].map(f64::from),
            ..self.media[0]
        })
    }

    /// The material vertex `v` scatters as, its own weight included where the lobes are split
    /// per vertex (the profile's point mass then holds its diffuse lobe): the ground truth of
    /// its B with every part, where `medium_at` is its medium summed whole.
    pub fn own_medium_at(&self, v: usize) -> Result<Material> {
        Material::from_principled(&PrincipledInputs {
            base_color: self.colors[v].map(f64::from),
            subsurface_weight: (self.lobes.as_ref())
                .map_or(self.media[0].subsurface_weight, |l| f64::from(l.weights[v])),
            ..self.media[0]
        })
    }

    /// The Material of each medium summed, in `media`' order.
    pub fn materials(&self) -> Result<Vec<Material>> {
        self.media.iter().map(Material::from_principled).collect()
    }

    /// Vertex `v`'s B from each medium's sum at it (`sums[j]`).
    pub fn blend_at(&self, v: usize, sums: &[[f64; 3]]) -> [f64; 3] {
        std::array::from_fn(|c| self.blends[v][c].apply(|m| sums[m][c]))
    }

    /// B per vertex from each medium's B per vertex (`sums[j]`, in `media`' order).
    pub fn blend(&self, sums: &[Vec<[f32; 3]>]) -> Vec<[f32; 3]> {
        (self.blends.iter().enumerate())
            .map(|(v, b)| std::array::from_fn(|c| b[c].apply(|m| f64::from(sums[m][v][c])) as f32))
            .collect()
    }
}

/// The slab totals T(x) per channel at the nodes the colours read.
struct Totals {
    /// nodes[k]: T at Base Color k / NODES_PER_UNIT in each channel, where read.
    nodes: Vec<Option<[f64; 3]>>,
    error: [f64; 3],
}

impl Totals {
    fn new(
        kind: ProfileKind,
        inputs: &PrincipledInputs,
        colors: &[[f32; 3]],
        media: &[Vec<f64>; 3],
    ) -> Result<Totals> {
        let n = NODES_PER_UNIT;
        let mut read = vec![false; n];
        let mut mark = |x: f64| read[interval(x)] = true;
        colors.iter().flatten().for_each(|&x| mark(f64::from(x)));
        media.iter().flatten().for_each(|&x| mark(x));
        let total = |x: f64| -> Result<[f64; 3]> {
            let m = Material::from_principled(&PrincipledInputs {
                base_color: [x; 3],
                ..*inputs
            })?;
            Ok(Resolved::new(kind, &m)?.totals())
        };
        let mut nodes = vec![None; n + 1];
        let mut error = [0.0f64; 3];
        let brightest = total(1.0)?;
        for i in (0..n).filter(|&i| read[i]) {
            for k in [i, i + 1] {
                if nodes[k].is_none() {
                    nodes[k] = Some(total(k as f64 / n as f64)?);
                }
            }
            // The interval's midpoint, against its ends' blend (judged against 1 % of the
            // brightest total where the medium is darker: a large relative miss there is not
            // seen).
            let (a, b) = (
                nodes[i].unwrap_or_default(),
                nodes[i + 1].unwrap_or_default(),
            );
            let mid = total((i as f64 + 0.5) / n as f64)?;
            for c in 0..3 {
                let floor = (0.01 * brightest[c]).max(mid[c]);
                if floor > 0.0 {
                    error[c] = error[c].max((0.5 * (a[c] + b[c]) - mid[c]).abs() / floor);
                }
            }
        }
        Ok(Totals { nodes, error })
    }

    /// T of channel `c` at Base Color `x` in [0, 1] (its interval read).
    fn at(&self, c: usize, x: f64) -> f64 {
        let i = interval(x);
        let t = x * NODES_PER_UNIT as f64 - i as f64;
        match (self.nodes[i], self.nodes[i + 1]) {
            (Some(a), Some(b)) => (1.0 - t) * a[c] + t * b[c],
            _ => f64::NAN, // unreachable: every interval read has both ends
        }
    }
}

/// The table's interval holding Base Color `x` in [0, 1].
fn interval(x: f64) -> usize {
    ((x * NODES_PER_UNIT as f64) as usize).min(NODES_PER_UNIT - 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn inputs() -> PrincipledInputs {
        PrincipledInputs {
            base_color: [0.5; 3],
            radius: [1.0, 0.5, 0.25],
            scale: 0.01,
            subsurface_weight: 1.0,
            ..PrincipledInputs::default()
        }
    }

    fn total(kind: ProfileKind, x: [f64; 3]) -> [f64; 3] {
        let m = Material::from_principled(&PrincipledInputs {
            base_color: x,
            ..inputs()
        })
        .unwrap();
        Resolved::new(kind, &m).unwrap().totals()
    }

    /// Under a light uniform over the profile's reach each medium's sum is its slab total: the
    /// blend gives every vertex its own medium's total (resolved directly, not through the
    /// table), within the table's stated error, for any number of media.
    #[test]
    fn under_uniform_light_each_vertex_gets_its_own_total() {
        for kind in [ProfileKind::Dipole, ProfileKind::Cycles] {
            let colors = vec![
                [0.9, 0.3, 0.05],
                [0.2, 0.6, 0.75],
                [0.55, 0.45, 0.4],
                [0.05, 0.95, 0.6],
            ];
            let areas = vec![1.0, 2.0, 1.0, 0.5];
            for media in [1, 2, 3] {
                let r = ReceiverColors::new(kind, &inputs(), &colors, &areas, media).unwrap();
                assert_eq!(r.media.len(), media);
                let sums: Vec<Vec<[f32; 3]>> = (r.media.iter())
                    .map(|m| vec![total(kind, m.base_color).map(|x| x as f32); colors.len()])
                    .collect();
                let got = r.blend(&sums);
                for (v, col) in colors.iter().enumerate() {
                    let own = total(kind, col.map(f64::from));
                    for c in 0..3 {
                        let tol = 2.0 * r.table_error[c] * own[c] + 1e-6;
                        let g = f64::from(got[v][c]);
                        assert!(
                            (g - own[c]).abs() <= tol,
                            "{kind:?} media {media} vertex {v} channel {c}: {g} vs {} (tol {tol})",
                            own[c]
                        );
                    }
                }
                assert!(
                    r.table_error.iter().all(|e| *e < 0.01),
                    "{:?}",
                    r.table_error
                );
            }
        }
    }

    /// Two colours over equal areas and two media: the media are the two colours, and each
    /// vertex reads its own medium's sum alone, whatever the light made of it.
    #[test]
    fn a_vertex_of_a_media_colour_reads_that_sum_alone() {
        let colors = vec![
            [0.8, 0.3, 0.6],
            [0.2, 0.7, 0.1],
            [0.8, 0.3, 0.6],
            [0.2, 0.7, 0.1],
        ];
        let r = ReceiverColors::new(ProfileKind::Dipole, &inputs(), &colors, &[1.0; 4], 2).unwrap();
        assert_eq!(r.media[0].base_color, [0.2f32, 0.3, 0.1].map(f64::from));
        assert_eq!(r.media[1].base_color, [0.8f32, 0.7, 0.6].map(f64::from));
        let sums = vec![vec![[1.0, 2.0, 3.0]; 4], vec![[5.0, 7.0, 11.0]; 4]];
        let got = r.blend(&sums);
        assert_eq!(got[0], [5.0, 2.0, 11.0]);
        assert_eq!(got[1], [1.0, 7.0, 3.0]);
        // One colour everywhere: one medium, every factor 1.
        let u = ReceiverColors::new(ProfileKind::Cycles, &inputs(), &[[0.4; 3]; 5], &[1.0; 5], 1)
            .unwrap();
        assert!(u
            .blends
            .iter()
            .flatten()
            .all(|b| (b.a - 1.0).abs() < 1e-6 && b.b == 0.0));
    }

    #[test]
    fn refuses_what_cycles_would_not_read() {
        let k = ProfileKind::Dipole;
        let e = ReceiverColors::new(k, &inputs(), &[[0.5, f32::NAN, 0.5]], &[1.0], 1).unwrap_err();
        assert!(e.to_string().contains("base_color of vertex 0"), "{e}");
        let e = ReceiverColors::new(k, &inputs(), &[[0.5; 3]], &[1.0, 1.0], 1).unwrap_err();
        assert!(e.to_string().contains("base_color has 1 rows"), "{e}");
        let e = ReceiverColors::new(k, &inputs(), &[[0.5; 3]], &[1.0], 0).unwrap_err();
        assert!(e.to_string().contains("media = 0"), "{e}");
        let e = ReceiverColors::new(k, &inputs(), &[[0.5; 3]], &[1.0], 17).unwrap_err();
        assert!(e.to_string().contains("media = 17"), "{e}");
        // Out of [0, 1] is saturated, as Cycles does: 2 reads as 1, -1 as 0.
        let r = ReceiverColors::new(
            k,
            &inputs(),
            &[[2.0, -1.0, 0.5], [1.0, 0.0, 0.2]],
            &[1.0; 2],
            1,
        )
        .unwrap();
        assert_eq!(r.colors[0], [1.0, 0.0, 0.5]);
        assert_eq!(r.blends[0][..2], r.blends[1][..2]);
    }

    fn sent(w: f64, x: [f64; 3], metallic: f64) -> [f64; 3] {
        let m = Material::from_principled(&PrincipledInputs {
            base_color: x,
            subsurface_weight: w,
            metallic,
            ..inputs()
        })
        .unwrap();
        Resolved::new(ProfileKind::Cycles, &m).unwrap().sent_on(1.0)
    }

    /// The lobes' split: B = w B_medium + (1 - w) below a L per vertex, and what the surface
    /// sends on is each vertex's lobes by its weight, against the slab albedo of a material of
    /// that weight resolved directly (one colour, so one medium: nothing interpolated). The
    /// media are summed at weight 1 whatever the inputs say.
    #[test]
    fn a_weight_per_vertex_splits_the_lobes() {
        let metallic = 0.25;
        let base = PrincipledInputs {
            subsurface_weight: 0.3, // not read: the media are whole
            metallic,
            ..inputs()
        };
        let a = [0.7f32, 0.4, 0.2];
        let colors = vec![a; 4];
        for w in [0.0f32, 0.4, 1.0] {
            let r = ReceiverColors::weighted(
                ProfileKind::Cycles,
                &base,
                &colors,
                &[1.0; 4],
                1,
                &[w; 4],
            )
            .unwrap();
            assert_eq!(r.media[0].subsurface_weight, 1.0);
            let lobes = r.lobes.as_ref().unwrap();
            let expect = sent(f64::from(w), a.map(f64::from), metallic);
            for (c, (got, want)) in lobes.sent.iter().zip(expect).enumerate() {
                assert!(
                    (got - want).abs() <= 1e-6 * want.max(1e-3),
                    "w {w} channel {c}: {got} vs {want}"
                );
            }
            let mut b = vec![[2.0f32, 3.0, 5.0]; 4];
            lobes.apply(&mut b, &r.colors, &[[10.0, 20.0, 30.0]; 4]);
            for c in 0..3 {
                let whole = [2.0, 3.0, 5.0][c];
                let diffuse = 0.75 * f64::from(a[c]) * [10.0, 20.0, 30.0][c];
                let expect = f64::from(w) * whole + (1.0 - f64::from(w)) * diffuse;
                assert!(
                    (f64::from(b[0][c]) - expect).abs() <= 1e-5 * expect,
                    "{w} {c}"
                );
            }
        }
    }

    #[test]
    fn bad_weights_are_refused_naming_the_argument() {
        let colors = vec![[0.5f32; 3]; 3];
        let areas = [1.0f32; 3];
        for (kind, weights) in [
            (ProfileKind::Cycles, vec![0.5f32; 2]),
            (ProfileKind::Cycles, vec![0.5, 1.5, 0.5]),
            (ProfileKind::Cycles, vec![0.5, -0.1, 0.5]),
            (ProfileKind::Cycles, vec![0.5, f32::NAN, 0.5]),
            (ProfileKind::Dipole, vec![0.5f32; 3]),
        ] {
            let e = ReceiverColors::weighted(kind, &inputs(), &colors, &areas, 2, &weights)
                .unwrap_err()
                .to_string();
            assert!(e.contains("subsurface_weight"), "{e}");
        }
    }
}

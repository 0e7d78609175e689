//! Links between receiver and emitter clusters, refined from the root by the solid-angle
//! oracle (Mertens 2003 §3.2, §5.2, after Jensen & Buhler 2002), and the gather over them.
//!
//! A candidate (R, E) is tested with ω(x, E) = A_E / |x − c_E|² (∞ inside E's bounding
//! sphere):
//! - receiver (ε₁): the largest |ω(c_k, E) − ω(c_R, E)| over R's children k; above ε₁ the
//!   candidate moves down to R's children;
//! - emitter (ε₂): ω(c_R, E); above ε₂ E is opened.
//!
//! When both fail the larger cluster is opened (a self-link opens both in turn). A face that
//! still fails ε₂ is integrated (a near link: the polygon form factor of `surface_integral`,
//! Mertens §4, from c_R over the face, times its mean irradiance) when it lies within
//! `NEAR_FACTOR` of its radii (`NEAR_FACTOR_STEEP` where the profile is steep across it),
//! else sampled like a cluster. Every other link is a far link:
//! the emitter's power times the profile sampled about its centroid (Mertens §3.1, eq. 6), a
//! factor that render and incremental modes store with the link (`far`).
//!
//! Departures from the paper, each where the profile must have a say or where one sample is
//! biased: emitters beyond the profile's support are dropped; a cluster wider than
//! `DECAY_SHARE` of the shortest decay length among the channels reaching it is opened; a far link samples the profile at two
//! sigma points of the emitter's spread (its surface's covariance) instead of once at its centre
//! (R is convex: one sample underestimates by about ½ R″ σ², 5–10 % per link at ε₂ = 0.05).
//!
//! The traversal walks the receiver tree top-down carrying the candidate emitters, so that the
//! two children of a receiver are independent (rayon) and what a receiver gathers is pushed
//! to its children on the way down (push, §3.2). It either gathers at once (on-the-fly) or
//! records the links per receiver (render and incremental modes).

use super::clusters::ClusterTree;
use super::far::FarEmitters;
use crate::profiles::LookupRgb;
use crate::progress::Ticker;
use crate::surface_integral::{triangle_integral_rgb, EdgeRule, Triangle};
use glam::DVec3;

/// A far link may point-sample an emitter whose radius is below this share of the profile's
/// decay length (R ∝ e^(−r/decay) varies by about this much across it).
pub const DECAY_SHARE: f64 = 1.0;

/// A face within this many of its radii of the receiver is integrated (polygon form factor);
/// beyond, its spread is sampled (two sigma points), where the profile is smooth across the
/// face ...
pub const NEAR_FACTOR: f64 = 0.8;

/// ... and within this many where it is steep there: the face's radius over `STEEP_SHARE` of
/// the shortest decay length among the channels reaching it (measured on the bunny: Cycles'
/// ketchup 1.24 % at 1.0 radii, 1.89 % at 0.8; marble and skimmilk within 0.1 % either way;
/// at 0.6 radii Cycles' marble reached 2.11 %).
pub const NEAR_FACTOR_STEEP: f64 = 1.0;
pub const STEEP_SHARE: f64 = 0.5;

/// A point receiver (a rim vertex, `links_at`) sits on the corners of the faces around it, up
/// to a radius from their centroids: those are integrated (at 0.8 a sheet's edge vertices were
/// 1.2 % off for marble, 0.05–0.09 % at 1.2).
pub const NEAR_FACTOR_POINT: f64 = 1.2;

/// Everything the oracle and the gather read.
pub struct Context<'a> {
    pub tree: &'a ClusterTree,
    pub faces: &'a [Triangle],
    /// The three channels' profiles on one table: R for the far links, C for the near ones.
    pub rgb: &'a LookupRgb,
    /// The clusters as far emitters (after `pull`).
    pub far: &'a FarEmitters,
    pub eps_receiver: f64,
    pub eps_emitter: f64,
    /// Largest support radius over the channels: emitters farther away are dropped.
    pub support: f64,
    /// Each channel's support radius and decay length: a cluster must be narrow against the
    /// decay of the channels that reach it.
    pub supports: [f64; 3],
    pub decays: [f64; 3],
    pub rule: EdgeRule,
    /// Skip emitters with no power (on-the-fly only: stored links must outlive the lighting).
    pub skip_dark: bool,
    /// Counts the receivers `visit` refines (one per node); once it says stop, `visit` leaves
    /// the rest of the tree untouched and its caller returns `Error::Cancelled`.
    pub ticker: Option<&'a Ticker<'a>>,
    /// Each face's irradiance per midpoint sub-triangle (`sub_triangles`'s order).
    pub sub: &'a [[[f32; 3]; 4]],
    /// Which faces are split into their four sub-triangles.
    pub split: &'a [bool],
}

/// A near link's form factors per channel, one per midpoint sub-triangle of the face.
pub type NearFactors = [[f32; 3]; 4];

/// A face split at its edges' midpoints: the middle sub-triangle, then those at corners 0, 1
/// and 2 (the order of the hierarchy's `SUB_POINTS`).
pub fn sub_triangles(face: &Triangle) -> [Triangle; 4] {
    let [a, b, c] = face.corners;
    let (ab, bc, ca) = (0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a));
    [
        Triangle::new(ab, bc, ca),
        Triangle::new(a, ab, ca),
        Triangle::new(ab, b, bc),
        Triangle::new(ca, bc, c),
    ]
}

/// The links gathered at one receiver node.
#[derive(Debug, Clone, Default)]
pub struct NodeLinks {
    /// Emitters point-sampled.
    pub far: Vec<u32>,
    /// Their factors from the geometric moments (stored links only; `far::FarEmitters`).
    pub far_factors: Vec<[f32; 4]>,
    /// Emitter faces integrated whole, with their form factor per channel (geometry and
    /// profile only): faces that are not split, their light one sample.
    pub near: Vec<(u32, [f32; 3])>,
    /// Split faces integrated, with the form factor per channel of each of the face's four
    /// midpoint sub-triangles (`sub_triangles`): 52 bytes a link where the others take 16.
    pub near_split: Vec<(u32, NearFactors)>,
}

impl NodeLinks {
    /// Near links, split faces' and the others'.
    pub fn near_count(&self) -> usize {
        self.near.len() + self.near_split.len()
    }

    /// The emitters of every near link.
    pub fn near_emitters(&self) -> impl Iterator<Item = u32> + '_ {
        (self.near.iter().map(|(e, _)| *e)).chain(self.near_split.iter().map(|(e, _)| *e))
    }
}

/// What the traversal leaves at each node.
#[derive(Debug, Clone, Default)]
pub struct Slot {
    /// B gathered at this node plus everything pushed from its ancestors.
    pub radiosity: [f64; 3],
    pub links: NodeLinks,
}

/// Counts of one traversal.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LinkCounts {
    pub far: u64,
    pub near: u64,
    pub oracle_tests: u64,
    pub dropped_beyond_support: u64,
}

impl LinkCounts {
    fn add(&mut self, o: &LinkCounts) {
        self.far += o.far;
        self.near += o.near;
        self.oracle_tests += o.oracle_tests;
        self.dropped_beyond_support += o.dropped_beyond_support;
    }
}

enum Verdict {
    Drop,
    Far,
    Near,
    OpenEmitter,
    MoveDown,
}

impl Context<'_> {
    #[inline]
    fn omega(&self, x: DVec3, e: usize) -> f64 {
        let d2 = (x - self.tree.centroid[e]).length_squared();
        let r = self.tree.radius[e];
        if d2 <= r * r {
            f64::INFINITY
        } else {
            self.tree.area[e] / d2
        }
    }

    /// The oracle (Mertens §5.2) with the profile's support and decay.
    fn judge(&self, r: u32, e: u32) -> Verdict {
        let t = self.tree;
        let ri = r as usize;
        self.judge_from(t.centroid[ri], t.radius[ri], t.children[ri], e)
    }

    /// The oracle for a receiver of centre `x`, radius `radius` and children `kids` (a point:
    /// radius 0, no children).
    fn judge_from(&self, x: DVec3, radius: f64, kids: Option<[u32; 2]>, e: u32) -> Verdict {
        let t = self.tree;
        let ei = e as usize;
        let d = (x - t.centroid[ei]).length();
        let gap = d - radius - t.radius[ei];
        if gap > self.support {
            return Verdict::Drop;
        }
        let decay = (0..3)
            .filter(|&c| gap <= self.supports[c])
            .map(|c| self.decays[c])
            .fold(f64::INFINITY, f64::min);
        let emitter_leaf = t.is_leaf(e);
        let w = self.omega(x, ei);
        let receiver_fails = match kids {
            None => false,
            Some(kids) => {
                !w.is_finite()
                    || kids.iter().any(|&k| {
                        let wk = self.omega(t.centroid[k as usize], ei);
                        (wk - w).abs() > self.eps_receiver
                    })
            }
        };
        // Too wide for one sample against the decay of the channels that reach it (a face,
        // which can only be integrated, at twice the share: its two sigma points still hold).
        let share = if emitter_leaf {
            2.0 * DECAY_SHARE
        } else {
            DECAY_SHARE
        };
        let too_wide = t.radius[ei] > share * decay;
        let near_factor = if kids.is_none() && radius == 0.0 {
            NEAR_FACTOR_POINT
        } else if t.radius[ei] > STEEP_SHARE * decay {
            NEAR_FACTOR_STEEP
        } else {
            NEAR_FACTOR
        };
        let close = d < near_factor * t.radius[ei];
        let emitter_fails = w > self.eps_emitter || close || too_wide;
        match (receiver_fails, emitter_fails) {
            (false, false) => Verdict::Far,
            // A face cannot be opened: integrated if close or wide, else its spread sampled.
            (false, true) if emitter_leaf && (close || too_wide) => Verdict::Near,
            (false, true) if emitter_leaf => Verdict::Far,
            (false, true) => Verdict::OpenEmitter,
            (true, false) => Verdict::MoveDown,
            (true, true) => {
                if !emitter_leaf && t.radius[ei] > radius {
                    Verdict::OpenEmitter
                } else {
                    Verdict::MoveDown
                }
            }
        }
    }

    /// The near links of receiver `r` integrated again from its centroid (the profile or the
    /// shape changed): the form factors F(A_k, c_R) per channel over the face, or over each of
    /// its sub-triangles A_k where it is split (Mertens eq. 7, §4, on each quarter of the
    /// face). A face whose split changed moves to its list.
    pub fn refresh_near(&self, r: u32, links: &mut NodeLinks) {
        let x = self.tree.centroid[r as usize];
        let emitters: Vec<u32> = links.near_emitters().collect();
        links.near.clear();
        links.near_split.clear();
        for e in emitters {
            self.push_near(x, e, links);
        }
    }

    /// A near link from `x` to face cluster `e`: F(A, x) per channel for a face that is not
    /// split (its light one sample), F(A_k, x) per sub-triangle for a split one.
    fn push_near(&self, x: DVec3, e: u32, links: &mut NodeLinks) {
        let f = self.tree.face[e as usize] as usize;
        let face = &self.faces[f];
        if !self.split.get(f).copied().unwrap_or(false) {
            let whole = triangle_integral_rgb(x, face, self.rgb, &self.rule).map(|v| v as f32);
            links.near.push((e, whole));
        } else {
            let quarters = sub_triangles(face)
                .map(|t| triangle_integral_rgb(x, &t, self.rgb, &self.rule).map(|v| v as f32));
            links.near_split.push((e, quarters));
        }
    }

    /// Sum over the split face's sub-triangles of F times the irradiance sampled there.
    #[inline]
    fn split_contribution(&self, e: u32, f: &NearFactors) -> [f64; 3] {
        let sub = &self.sub[self.tree.face[e as usize] as usize];
        std::array::from_fn(|c| {
            (f.iter().zip(sub))
                .map(|(f, e)| f64::from(f[c]) * f64::from(e[c]))
                .sum()
        })
    }

    /// Refines the candidates at receiver `r`: accepted links go to `links`, candidates for
    /// the children to `down`.
    fn refine_at(
        &self,
        r: u32,
        mut stack: Vec<u32>,
        links: &mut NodeLinks,
        down: &mut Vec<u32>,
        counts: &mut LinkCounts,
    ) {
        let at = self.tree.centroid[r as usize];
        self.refine(&|e| self.judge(r, e), at, &mut stack, links, down, counts);
    }

    /// The refinement loop under the oracle `judge`; near faces integrated from `at`.
    fn refine(
        &self,
        judge: &dyn Fn(u32) -> Verdict,
        at: DVec3,
        stack: &mut Vec<u32>,
        links: &mut NodeLinks,
        down: &mut Vec<u32>,
        counts: &mut LinkCounts,
    ) {
        while let Some(e) = stack.pop() {
            if self.skip_dark && self.tree.power[e as usize].iter().all(|p| *p == 0.0) {
                continue;
            }
            counts.oracle_tests += 1;
            match judge(e) {
                Verdict::Drop => counts.dropped_beyond_support += 1,
                Verdict::Far => {
                    counts.far += 1;
                    links.far.push(e);
                }
                Verdict::Near => {
                    counts.near += 1;
                    self.push_near(at, e, links);
                }
                Verdict::OpenEmitter => {
                    if let Some([a, b]) = self.tree.children[e as usize] {
                        stack.push(a);
                        stack.push(b);
                    }
                }
                Verdict::MoveDown => down.push(e),
            }
        }
    }

    /// The stored factors of receiver `r`'s far links.
    pub fn far_factors(&self, r: u32, far: &[u32]) -> Vec<[f32; 4]> {
        self.far
            .factors(self.tree.centroid[r as usize], far, self.rgb)
    }

    /// Every link of the point `x` as a receiver of its own (radius 0, no children), refined
    /// from the root: its nearest faces integrated from `x`, the far factors taken from `x`.
    pub fn links_at(&self, x: DVec3) -> NodeLinks {
        let mut links = NodeLinks::default();
        let (mut down, mut counts) = (Vec::new(), LinkCounts::default());
        let mut stack = vec![self.tree.root()];
        let judge = |e| self.judge_from(x, 0.0, None, e);
        self.refine(&judge, x, &mut stack, &mut links, &mut down, &mut counts);
        debug_assert!(down.is_empty());
        links.far_factors = self.far.factors(x, &links.far, self.rgb);
        links
    }

    /// The radiosity at the point `x` over `links` from `links_at(x)`, or over stored links.
    pub fn gather_at(&self, links: &NodeLinks) -> [f64; 3] {
        let b = self.far.sum_stored(&links.far, &links.far_factors);
        self.with_near(b, links)
    }

    /// The radiosity node `r` gathers over `links`: stored factors where the links keep them,
    /// else the far emitters sampled from `r`'s centroid.
    pub fn gather(&self, r: u32, links: &NodeLinks) -> [f64; 3] {
        if links.far_factors.len() == links.far.len() {
            return self.gather_at(links);
        }
        let b = self
            .far
            .sum(self.tree.centroid[r as usize], &links.far, self.rgb);
        self.with_near(b, links)
    }

    /// `b` plus the near links' form factors times their faces' irradiance.
    fn with_near(&self, mut b: [f64; 3], links: &NodeLinks) -> [f64; 3] {
        // A face that is not split keeps its centroid's light in its first sub-sample.
        for (e, f) in &links.near {
            let i = &self.sub[self.tree.face[*e as usize] as usize][0];
            (0..3).for_each(|c| b[c] += f64::from(f[c]) * f64::from(i[c]));
        }
        for (e, f) in &links.near_split {
            let v = self.split_contribution(*e, f);
            (0..3).for_each(|c| b[c] += v[c]);
        }
        b
    }

    /// Refines and gathers over the subtree of `r`, whose slots are `slots`
    /// (`tree.first[r]..=r`), starting from the candidate emitters `candidates` plus, in
    /// incremental mode, the node's previous links `previous` (re-checked: kept, opened,
    /// moved down, or replaced by their parent when both siblings pass there: one level of
    /// promotion per update). `keep` stores the links in the slots.
    #[allow(clippy::too_many_arguments)]
    pub fn visit(
        &self,
        r: u32,
        candidates: Vec<u32>,
        pushed: [f64; 3],
        slots: &mut [Slot],
        previous: Option<&[Slot]>,
        keep: bool,
    ) -> LinkCounts {
        let t = self.tree;
        let first = t.first[r as usize] as usize;
        debug_assert_eq!(slots.len(), r as usize - first + 1);
        if self.ticker.is_some_and(|k| k.stopped()) {
            return LinkCounts::default();
        }
        let mut stack = candidates;
        if let Some(prev) = previous {
            let old = &prev[r as usize].links;
            stack.extend(self.promoted(r, old));
        }
        let mut links = NodeLinks::default();
        let mut down = Vec::new();
        let mut counts = LinkCounts::default();
        self.refine_at(r, stack, &mut links, &mut down, &mut counts);
        if let Some(k) = self.ticker {
            k.add(1);
        }
        if keep {
            links.far_factors = self.far_factors(r, &links.far);
        }
        let own = self.gather(r, &links);
        let total: [f64; 3] = std::array::from_fn(|c| pushed[c] + own[c]);
        let (rest, this) = slots.split_at_mut(slots.len() - 1);
        this[0].radiosity = total;
        this[0].links = if keep { links } else { NodeLinks::default() };
        if let Some([a, b]) = t.children[r as usize] {
            let split = a as usize - first + 1;
            let (left, right) = rest.split_at_mut(split);
            let big = rest_len_is_big(left.len() + right.len());
            let down_b = down.clone();
            let (ca, cb) = if big {
                rayon::join(
                    || self.visit(a, down, total, left, previous, keep),
                    || self.visit(b, down_b, total, right, previous, keep),
                )
            } else {
                (
                    self.visit(a, down, total, left, previous, keep),
                    self.visit(b, down_b, total, right, previous, keep),
                )
            };
            counts.add(&ca);
            counts.add(&cb);
        }
        counts
    }

    /// The previous links of `r` as candidates: an emitter whose sibling is linked too and
    /// whose parent passes the oracle at `r` is replaced by that parent (promotion, Mertens
    /// §5.5 after Drettakis & Sillion 1997).
    fn promoted(&self, r: u32, old: &NodeLinks) -> Vec<u32> {
        let t = self.tree;
        let mut emitters: Vec<u32> = old.far.iter().copied().chain(old.near_emitters()).collect();
        emitters.sort_unstable();
        let mut out = Vec::with_capacity(emitters.len());
        let mut i = 0;
        while i < emitters.len() {
            let e = emitters[i];
            let p = t.parent[e as usize];
            // Siblings are adjacent in post-order: the left child's sibling is parent − 1.
            if p != u32::MAX && i + 1 < emitters.len() && emitters[i + 1] == p - 1 {
                if let Some([a, _]) = t.children[p as usize] {
                    if a == e && matches!(self.judge(r, p), Verdict::Far) {
                        out.push(p);
                        i += 2;
                        continue;
                    }
                }
            }
            out.push(e);
            i += 1;
        }
        out
    }
}

fn rest_len_is_big(n: usize) -> bool {
    n > 256
}

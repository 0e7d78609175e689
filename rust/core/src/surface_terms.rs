//! What the half-space profile cannot see, for a method that sums it (the hierarchy, the
//! splatting): the walks' geometry term (`walks::WalkTerm`) and the object's own light
//! (`own_light::Bounce`), the shared kernels PRT holds too, so every method shows the same
//! Cycles-matching answer (issue 29, point 3; issue 31, point 6).
//!
//! They are computed at the first evaluation with walks on (`HierarchySettings::terms`,
//! `Splatting::with_walks`), for that evaluation's material (the representative):
//! D = B_walk - B_half against the method's own half-space B, carried to every vertex by the
//! walks' kernels; the own light
//! cast from the direct B over kept rays. After a new light or a pose they are carried, not
//! traced again: the walks' exits and the own light's hits are a triangle and barycentrics,
//! read on the same triangles under the new light and shape (exact for a rigid motion with the
//! lights; near a bend the rest pose's paths, until `Hierarchy::retrace_terms` walks the pose).
//! Any edit scales them as PRT's: D / A at the edited diffusion length, the own light by the
//! ratio of the slab albedos sent on.

use crate::error::{Error, Result};
use crate::irradiance::{irradiance_with_progress, IrradianceSettings};
use crate::mesh::Mesh;
use crate::optics::Material;
use crate::own_light::{self, Bounce};
use crate::profiles::Resolved;
use crate::progress::ProgressFn;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use crate::shadow_edges::ShadowEdges;
use crate::walks::{ExitLight, WalkTerm, WalkTermReport, WalkTermSettings};
use glam::Vec3;
use std::time::Instant;

/// The walks' and the own light's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TermSettings {
    pub walks: WalkTermSettings,
    /// Own-light rays per vertex as `strata` x `strata`; None leaves the own light out.
    pub interreflection: Option<usize>,
}

/// What the terms did: their walks, the own light's rays and share, and whether they are
/// carried from another pose or light.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TermReport {
    pub walks: Option<WalkTermReport>,
    pub walks_indirect: Option<WalkTermReport>,
    pub own_light_rays: u64,
    /// The own light's share of B (worst channel).
    pub own_light_share: f64,
    /// Walked on another pose than this one (carried to it).
    pub carried_pose: bool,
    /// Seconds of the last computation or carrying.
    pub seconds: f64,
}

/// The terms and the state they are in.
pub struct Terms {
    pub settings: TermSettings,
    /// The material they were walked for; None before the first evaluation.
    pub rep: Option<Material>,
    walks: Option<WalkTerm>,
    bounce: Option<Bounce>,
    /// Lit and shaped as the method now is.
    pub current: bool,
    pub report: TermReport,
}

/// The method's state the terms read.
pub struct Lit<'a> {
    pub scene: &'a Scene,
    pub tracer: &'a Tracer,
    pub irradiance: IrradianceSettings,
    /// Irradiance per vertex (with the representative's Fresnel factor).
    pub vertices: &'a [[f32; 3]],
    /// The representative's half-space B per vertex.
    pub halfspace: &'a [[f32; 3]],
}

/// Terms walked by another method (a PRT precompute's, `Prt::walked_terms`) for `material`:
/// handed to a method that sums the half-space profile, they are carried to its light and
/// half-space B at its next evaluation (`Terms::carried`) instead of walked again. The walk
/// records and the own light's rays are shared, not copied.
#[derive(Debug, Clone)]
pub struct Walked {
    pub material: Material,
    pub walks: WalkTerm,
    pub bounce: Option<Bounce>,
    /// The vertices they were walked on: a method on another shape of the mesh refuses them.
    pub positions: Vec<Vec3>,
}

impl Walked {
    /// Errors unless `mesh` is the mesh and shape they were walked on.
    pub fn check_mesh(&self, mesh: &Mesh) -> Result<()> {
        if self.positions != mesh.positions() {
            return Err(Error::InvalidArgument(format!(
                "that Prt was precomputed on another mesh or shape ({} vertices) than this \
                 scene's ({} vertices)",
                self.positions.len(),
                mesh.vertex_count()
            )));
        }
        Ok(())
    }
}

impl Terms {
    /// Terms walked elsewhere, carried (not walked) at the next evaluation: the walks read
    /// under the new light against the new method's own half-space B, the own light gathered
    /// over the kept rays. Walked anew later only where `Terms::update` would walk anyway (a
    /// medium the walks do not cover, a retrace).
    pub fn carried(settings: TermSettings, walked: Walked) -> Terms {
        Terms {
            settings,
            rep: Some(walked.material),
            walks: Some(walked.walks),
            bounce: walked.bounce,
            current: false,
            report: TermReport::default(),
        }
    }

    pub fn new(settings: TermSettings) -> Terms {
        Terms {
            settings,
            rep: None,
            walks: None,
            bounce: None,
            current: false,
            report: TermReport::default(),
        }
    }

    /// The lights or the shape changed: carried at the next evaluation.
    pub fn stale(&mut self, posed: bool) {
        self.current = false;
        if posed && self.walks.is_some() {
            self.report.carried_pose = true;
        }
    }

    /// The media walked beside the representative (none before any walk).
    pub fn beside_media(&self) -> Vec<Resolved> {
        self.walks
            .as_ref()
            .map_or_else(Vec::new, |w| w.beside_media())
    }

    /// Whether the walks (the direct term's and the own light's) cover `medium`'s diffusion
    /// lengths (`WalkTerm::covers`); true before any walk.
    pub fn covers(&self, medium: &Resolved) -> bool {
        let own = self.bounce.as_ref().and_then(|b| b.walked.as_ref());
        self.walks.iter().chain(own).all(|w| w.covers(medium))
    }

    /// Computes the terms under `lit` (walked anew when `fresh` or never walked; else the kept
    /// walks and rays read again). `beside`: other media with their half-space B under `lit`;
    /// walked anew, those whose lengths the representative's do not reach are walked too
    /// (`walks::media_to_walk`, the ray budget shared); carried, those kept are read again
    /// where `beside` still holds their medium, and dropped where it does not.
    pub fn update(
        &mut self,
        lit: &Lit<'_>,
        rep: &Resolved,
        beside: &[(Resolved, Vec<[f32; 3]>)],
        fresh: bool,
        progress: Option<&ProgressFn>,
    ) -> Result<()> {
        let start = Instant::now();
        let mesh = &lit.scene.mesh;
        let irradiance = |p: &[Vec3], n: &[Vec3]| -> Result<Vec<[f32; 3]>> {
            Ok(irradiance_with_progress(lit.scene, lit.tracer, p, n, &lit.irradiance, None)?.0)
        };
        // Carried to a pose, the walks' exits read the light from their triangles' corners
        // (as PRT's pose preview does: the shadow edges are a third of the carrying's time);
        // walked, or carried to a new light, from a finer grid where a shadow's edge crosses.
        let edges = if fresh || !self.report.carried_pose {
            ShadowEdges::new(mesh, lit.vertices, &irradiance)?
        } else {
            ShadowEdges::none()
        };
        let exits = ExitLight {
            vertices: lit.vertices,
            edges: &edges,
        };
        let kept = if fresh { None } else { self.walks.take() };
        let walks = match kept.filter(WalkTerm::relightable) {
            Some(mut term) => {
                let mut carried = Vec::new();
                for (medium, mut t) in term.take_beside() {
                    if let Some((_, b)) = beside.iter().find(|(m, _)| m.material == medium.material)
                    {
                        t.relight(mesh, &medium, &exits, b)?;
                        carried.push((medium, t));
                    }
                }
                term.relight(mesh, rep, &exits, lit.halfspace)?;
                term.set_beside(carried);
                term
            }
            None => {
                self.report.carried_pose = false;
                let mut media = vec![rep.clone()];
                media.extend(beside.iter().map(|(m, _)| m.clone()));
                let walked = crate::walks::media_to_walk(&media);
                let mut shared = self.settings.walks.clone();
                shared.rays /= 1 + walked.len() as u64;
                let share = 1.0 / (1 + walked.len()) as f32;
                let part =
                    |k: usize| progress.map(move |p| move |f: f32| p(share * (k as f32 + f)));
                let first = part(0);
                let mut term = WalkTerm::compute(
                    mesh,
                    lit.tracer,
                    rep,
                    &exits,
                    lit.halfspace,
                    &shared,
                    first.as_ref().map(|f| f as _),
                )?;
                let mut others = Vec::with_capacity(walked.len());
                for (k, &i) in walked.iter().enumerate() {
                    let (medium, b) = &beside[i - 1];
                    let tick = part(k + 1);
                    let t = WalkTerm::compute(
                        mesh,
                        lit.tracer,
                        medium,
                        &exits,
                        b,
                        &shared,
                        tick.as_ref().map(|f| f as _),
                    )?;
                    others.push((medium.clone(), t));
                }
                term.set_beside(others);
                term
            }
        };
        self.report.walks = Some(walks.report.clone());
        // The direct B with the walks' term: what the surface sends on.
        let mut direct = lit.halfspace.to_vec();
        walks.add_to(&mut direct, &rep.profiles);
        self.walks = Some(walks);
        let kept_bounce = if fresh { None } else { self.bounce.take() };
        self.bounce = match self.settings.interreflection {
            Some(strata) => Some(self.cast(mesh, lit, rep, &direct, strata, kept_bounce)?),
            None => None,
        };
        self.rep = Some(rep.material);
        self.current = true;
        self.report.seconds = start.elapsed().as_secs_f64();
        Ok(())
    }

    /// The own light (`own_light::cast`): from the kept rays' hits when there are some.
    fn cast(
        &mut self,
        mesh: &Mesh,
        lit: &Lit<'_>,
        rep: &Resolved,
        direct: &[[f32; 3]],
        strata: usize,
        kept: Option<Bounce>,
    ) -> Result<Bounce> {
        let walked_part: Vec<[f32; 3]> = direct
            .iter()
            .zip(lit.halfspace)
            .map(|(b, h)| std::array::from_fn(|c| b[c] - h[c]))
            .collect();
        let (gather, walked_before) = match kept {
            Some(b) => (Some(b.gather), b.walked),
            None => (None, None),
        };
        let cast = own_light::cast(
            mesh,
            lit.tracer,
            rep,
            own_light::Sent {
                halfspace: lit.halfspace,
                irradiance: lit.vertices,
                walked: Some(&walked_part),
            },
            strata,
            gather,
            None,
        )?;
        let receiving = rep.totals();
        self.report.own_light_rays = cast.rays;
        self.report.own_light_share =
            own_light::share(&cast.irradiance, direct, mesh.vertex_areas(), &receiving);
        // What walks make of the indirect light beyond its local conversion, as PRT's does.
        let beside = self
            .walks
            .as_ref()
            .map_or_else(Vec::new, |w| w.beside_media());
        let walked = own_light::walked_term(
            mesh,
            lit.tracer,
            rep,
            &beside,
            &cast.irradiance,
            &self.settings.walks,
            walked_before,
            None,
        )?;
        self.report.walks_indirect = Some(walked.report.clone());
        Ok(Bounce {
            irradiance: cast.irradiance,
            source_albedo: rep.sent_on(1.0),
            walked: Some(walked),
            gather: cast.gather,
        })
    }

    /// The object's own light at each vertex (its irradiance, not yet through a profile) from
    /// a surface sending `sent` on (`Bounce::ratio`); None without it. A vertex's diffuse lobe
    /// takes it as it takes the direct light (`receiver_color::Lobes`).
    pub fn own_irradiance(&self, sent: [f64; 3]) -> Option<Vec<[f32; 3]>> {
        let b = self.bounce.as_ref()?;
        let k = b.ratio(sent).map(|r| r as f32);
        Some(
            b.irradiance
                .iter()
                .map(|e| std::array::from_fn(|c| k[c] * e[c]))
                .collect(),
        )
    }

    /// Adds the terms for `material` to `radiosity` (B per vertex) and their noise to `error`.
    /// `signed`: `radiosity` is a layer of its own, not B (the splatting adds it to B at each
    /// pixel): a term that takes light away stays negative in it, where added to B it floors
    /// B at 0. `sent`: what the surface sends on to the own light where its vertices differ
    /// (`receiver_color::Lobes::sent`); None: what `material` sends.
    pub fn add_to(
        &self,
        radiosity: &mut [[f32; 3]],
        material: &Resolved,
        error: &mut [f64; 3],
        signed: bool,
        sent: Option<[f64; 3]>,
    ) -> Result<()> {
        if !self.current {
            return Err(Error::InvalidArgument(
                "the walks' term is not carried to this light or shape yet".into(),
            ));
        }
        if let Some(w) = &self.walks {
            let added = if signed {
                w.add_signed_to(radiosity, &material.profiles, [1.0; 3])
            } else {
                w.add_to(radiosity, &material.profiles)
            };
            for (e, a) in error.iter_mut().zip(added) {
                *e += a;
            }
        }
        if let Some(b) = &self.bounce {
            let ratio = b.ratio(sent.unwrap_or_else(|| material.sent_on(1.0)));
            let share = self.report.own_light_share;
            b.add_scaled(radiosity, material, ratio, true, share, error, signed);
        }
        Ok(())
    }
}

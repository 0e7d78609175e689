//! A pose of the precomputed mesh (issue 29, point 3): the same vertices and triangles, moved
//! by an armature, a shape key or any deformation. What depends on the shape and the light is
//! computed on the posed mesh: the surface samples, their irradiance, the sample tree and the
//! transport rows (Xu 2007 eq. 10). What the walks through the mesh found and the object's own
//! light are carried: the walks' exits and the own light's hits are kept as a triangle and
//! barycentrics (`walks::operator`, `interreflection::Gather`), so they are read on the same
//! triangles of the posed mesh under its light, with no walk or own-light ray traced. That is
//! exact for a rigid motion of the whole mesh with its lights; near a bend the walks' paths
//! and the own light's visibility are the rest pose's until a precompute on the posed mesh
//! refines them (`PrtReport::carried_pose`, and the evaluation's skipped list says so).
//!
//! Two speeds: `reposed_scene` keeps the precompute's sample spacing (the transport as a
//! fresh precompute would hold it), `posed_preview` takes a first preview's (at most
//! `FIRST_PREVIEW_SAMPLES` samples, far clusters from `FIRST_PREVIEW_FAR_FIELD`) for a preview
//! within about a second.

use super::relight::RelightReport;
use super::request::FIRST_PREVIEW_FAR_FIELD;
use super::{Density, ProgressFn, Prt};
use crate::error::{Error, Result};
use crate::irradiance::{irradiance_with_progress, IrradianceReport, IrradianceSettings};
use crate::profiles::Resolved;
use crate::progress::cancel_only;
use crate::raytrace::Tracer;
use crate::scene::Scene;
use glam::Vec3;
use std::sync::Mutex;
use std::time::Instant;

impl Prt {
    /// Errors unless `scene`'s mesh has this transport's vertex count and triangles.
    fn check_pose(&self, scene: &Scene) -> Result<()> {
        let mesh = &scene.mesh;
        if mesh.vertex_count() != self.positions.len()
            || mesh.triangles() != self.triangles.as_slice()
        {
            return Err(Error::InvalidArgument(format!(
                "a pose keeps the precomputed mesh's {} vertices and {} triangles (this mesh \
                 has {} and {}, or other triangles): precompute again for a new topology",
                self.positions.len(),
                self.triangles.len(),
                mesh.vertex_count(),
                mesh.triangles().len()
            )));
        }
        Ok(())
    }

    /// The transport carried to a pose of its mesh at the precompute's sample spacing, under
    /// the lights and world of `scene` (whose mesh is the pose), estimated with `settings`.
    /// Errors when the triangles differ; `Error::Cancelled` when `progress` says stop.
    pub fn reposed_scene(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Prt, RelightReport, IrradianceReport)> {
        self.check_pose(scene)?;
        self.lit_in_scene(scene, tracer, settings, progress, true)
    }

    /// The pose's first preview: a first preview's transport on the posed mesh (the half-space
    /// profile on at most `FIRST_PREVIEW_SAMPLES` samples, far clusters from
    /// `FIRST_PREVIEW_FAR_FIELD`), with this transport's walks and own light carried to it
    /// (`carry_terms`). Same representatives, profile and basis settings; a walk term that kept
    /// no records is walked again. `reposed_scene` otherwise.
    pub fn posed_preview(
        &self,
        scene: &Scene,
        tracer: &Tracer,
        settings: &IrradianceSettings,
        progress: Option<&ProgressFn>,
    ) -> Result<(Prt, RelightReport, IrradianceReport)> {
        let settings = &super::relight::at_vertices(settings);
        self.check_pose(scene)?;
        let start = Instant::now();
        let mesh = &scene.mesh;
        let ask = cancel_only(progress);
        let lighting = Mutex::new(IrradianceReport::default());
        let irradiance = |p: &[Vec3], n: &[Vec3], d: Density| {
            let (v, r) = irradiance_with_progress(
                scene,
                tracer,
                p,
                n,
                &settings.for_density(d),
                Some(&ask),
            )?;
            let mut total = lighting.lock().unwrap_or_else(|e| e.into_inner());
            *total = total.merge(&r);
            Ok(v)
        };
        let mut quick = self.settings.clone();
        quick.first_preview = true;
        quick.walks = None;
        quick.interreflection = None;
        if quick.far_field > 0.0 {
            quick.far_field = quick.far_field.max(FIRST_PREVIEW_FAR_FIELD);
        }
        let transport_progress = progress.map(|p| move |f: f32| p(0.7 * f));
        let mut next = Prt::precompute_traced(
            mesh,
            Some(tracer),
            &self.representatives,
            &quick,
            &irradiance,
            transport_progress.as_ref().map(|f| f as _),
        )?;
        let mut out = RelightReport {
            posed: true,
            seconds_irradiance: next.report.seconds_irradiance,
            seconds_transport: next.report.seconds_tree + next.report.seconds_transport,
            ..Default::default()
        };
        next.settings.walks = self.settings.walks.clone();
        next.settings.interreflection = self.settings.interreflection;
        next.walks = self.walks.clone();
        next.bounce = self.bounce.clone();
        next.report.carried_pose = true;
        let rep = Resolved::new(self.profile, &self.representatives[0])?;
        // The shadows' edges on the posed mesh are left to the refinement: the walks' exits read the
        // light from their triangles' corners (a fifth of this preview's time on Suzanne).
        next.carry_terms(mesh, &rep, &irradiance, false, progress, &mut out)?;
        let report = lighting.into_inner().unwrap_or_else(|e| e.into_inner());
        out.irradiance_rays = report.rays;
        out.seconds = start.elapsed().as_secs_f64();
        next.report.last_relight = Some(out.clone());
        if let Some(p) = progress {
            if !p(1.0) {
                return Err(Error::Cancelled);
            }
        }
        Ok((next, out, report))
    }
}

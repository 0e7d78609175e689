//! The camera's view: the receivers x_o of Shah, Konttinen and Pattanaik 2009's pass 2 ("the
//! object is rendered from the camera's view into position, normal and object-ID targets").
//! Done on the CPU by casting one ray through the centre of each pixel, as a rasteriser
//! samples there: a pinhole at `eye` looking at `target`, `up` giving the image's up, `fov` the
//! angle across the image's larger side (Blender's camera `angle` with sensor fit Auto), row 0
//! the top of the image.
//!
//! A pixel is a receiver where its ray's first hit on the scene is the previewed mesh: the rest
//! of the scene (`Scene`'s occluders) in front of it hides it, as it hides it in a render. The
//! receiver carries the hit point, the shading normal there (the vertex normals interpolated,
//! as Cycles' smooth shading and the light view take it) and its object.

use crate::error::{Error, Result};
use crate::mesh::{hit_surface, Mesh};
use crate::progress::Ticker;
use crate::raytrace::Tracer;
use glam::{DVec3, Vec3};
use rayon::prelude::*;

/// The largest side of an image [pixels].
pub const MAX_SIDE: u32 = 8192;
/// The most pixels an image may have (4096 x 4096).
pub const MAX_PIXELS: u64 = 4096 * 4096;
/// The widest field of view: 179 degrees across the larger side.
pub const MAX_FOV: f64 = 179.0 * std::f64::consts::PI / 180.0;
/// Blender's default camera: a 50 mm lens on a 36 mm sensor, 2 atan(18 / 50) [rad].
pub const DEFAULT_FOV: f64 = 0.691_150_383_789_754_6;

/// A pinhole camera and the image it makes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    /// tan of half the field of view across the image's width and across its height.
    tan_x: f64,
    tan_y: f64,
    width: u32,
    height: u32,
}

/// One pixel that sees the previewed mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelHit {
    /// Its index in the image, row-major from the top row.
    pub pixel: u32,
    pub position: Vec3,
    /// The shading normal at the hit (unit).
    pub normal: Vec3,
    pub object: u32,
    /// The hit triangle and the barycentric u, v of its corners 1 and 2 there (what a
    /// per-vertex layer is interpolated with).
    pub triangle: u32,
    pub uv: [f32; 2],
}

impl Camera {
    /// Errors (`Error::InvalidArgument`, naming the argument): a coordinate that is not
    /// finite, `target` at `eye`, `up` along the view, `fov` outside (0, 179 degrees], a side
    /// outside [1, `MAX_SIDE`] or more than `MAX_PIXELS` pixels.
    pub fn new(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov: f64,
        (width, height): (u32, u32),
    ) -> Result<Camera> {
        let bad = |m: String| Err(Error::InvalidArgument(m));
        for (name, v) in [("eye", eye), ("target", target), ("up", up)] {
            if !v.is_finite() {
                return bad(format!("{name} = {:?} is not finite", v.to_array()));
            }
        }
        let (eye, target, up) = (eye.as_dvec3(), target.as_dvec3(), up.as_dvec3());
        let Some(forward) = (target - eye).try_normalize() else {
            return bad(format!(
                "target = {target:?} lies at the eye: no direction to look"
            ));
        };
        let Some(right) = forward.cross(up).try_normalize().filter(|_| {
            // Up must stand off the view by more than a hundredth of a degree.
            forward.cross(up.normalize_or_zero()).length() > 1.7e-4
        }) else {
            return bad(format!(
                "up = {:?} is zero or along the view direction: the image has no up",
                up.to_array()
            ));
        };
        if !(fov.is_finite() && fov > 0.0 && fov <= MAX_FOV) {
            return bad(format!(
                "fov = {fov}: the field of view must lie in (0, {MAX_FOV:.4}] radians (179 degrees)"
            ));
        }
        for (name, n) in [("width", width), ("height", height)] {
            if !(1..=MAX_SIDE).contains(&n) {
                return bad(format!(
                    "size: {name} = {n} pixels must lie in [1, {MAX_SIDE}]"
                ));
            }
        }
        if u64::from(width) * u64::from(height) > MAX_PIXELS {
            return bad(format!(
                "size = ({width}, {height}): more than {MAX_PIXELS} pixels"
            ));
        }
        // Sensor fit Auto: the field of view spans the larger side.
        let t = (0.5 * fov).tan();
        let (w, h) = (f64::from(width), f64::from(height));
        let (tan_x, tan_y) = if width >= height {
            (t, t * h / w)
        } else {
            (t * w / h, t)
        };
        Ok(Camera {
            eye,
            forward,
            right,
            up: right.cross(forward),
            tan_x,
            tan_y,
            width,
            height,
        })
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    pub fn eye(&self) -> Vec3 {
        self.eye.as_vec3()
    }

    /// The unit ray through the centre of pixel (`column`, `row`), row 0 at the top.
    pub fn ray(&self, column: u32, row: u32) -> Vec3 {
        let x = 2.0 * (f64::from(column) + 0.5) / f64::from(self.width) - 1.0;
        let y = 1.0 - 2.0 * (f64::from(row) + 0.5) / f64::from(self.height);
        (self.forward + self.right * (x * self.tan_x) + self.up * (y * self.tan_y))
            .normalize()
            .as_vec3()
    }

    /// Where `p` lands in the image: (column, row) in pixels (fractional, the centre of pixel
    /// (0, 0) at (0.5, 0.5)), None behind the eye.
    pub fn project(&self, p: Vec3) -> Option<(f64, f64)> {
        let d = p.as_dvec3() - self.eye;
        let z = d.dot(self.forward);
        if z <= 0.0 {
            return None;
        }
        let x = d.dot(self.right) / (z * self.tan_x);
        let y = d.dot(self.up) / (z * self.tan_y);
        Some((
            0.5 * (x + 1.0) * f64::from(self.width),
            0.5 * (1.0 - y) * f64::from(self.height),
        ))
    }
}

impl Camera {
    /// The pixels whose centres may see a point within `radius` of `centre`: [x0, y0, x1, y1]
    /// in pixel-edge coordinates (whole numbers, clipped to the image; the centre of pixel
    /// (c, r) is (c + 0.5, r + 0.5)), None where it lies wholly outside the image or behind the
    /// eye. A point p of the sphere has depth z in [z_c - r, z_c + r] and lateral offset x in
    /// [x_c - r, x_c + r], and x / z is monotone in z for either sign of x, so the box's
    /// corners bound its image; a sphere that reaches the eye's plane may be anywhere.
    pub fn sphere_rect(&self, centre: Vec3, radius: f32) -> Option<[f32; 4]> {
        let d = centre.as_dvec3() - self.eye;
        let r = f64::from(radius);
        let z = d.dot(self.forward);
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        if z + r <= 0.0 {
            return None;
        }
        let (x0, x1, y0, y1) = if z - r <= 1e-9 * (z.abs() + r) {
            (0.0, w, 0.0, h)
        } else {
            let bound = |c: f64| {
                let hi = if c + r >= 0.0 {
                    (c + r) / (z - r)
                } else {
                    (c + r) / (z + r)
                };
                let lo = if c - r <= 0.0 {
                    (c - r) / (z - r)
                } else {
                    (c - r) / (z + r)
                };
                (lo, hi)
            };
            let (xl, xh) = bound(d.dot(self.right));
            let (yl, yh) = bound(d.dot(self.up));
            (
                0.5 * (xl / self.tan_x + 1.0) * w,
                0.5 * (xh / self.tan_x + 1.0) * w,
                0.5 * (1.0 - yh / self.tan_y) * h,
                0.5 * (1.0 - yl / self.tan_y) * h,
            )
        };
        let (x0, y0) = (x0.floor().max(0.0), y0.floor().max(0.0));
        let (x1, y1) = (x1.ceil().min(w), y1.ceil().min(h));
        (x0 < x1 && y0 < y1).then_some([x0 as f32, y0 as f32, x1 as f32, y1 as f32])
    }
}

/// The pixels of `camera`'s image that see `mesh` first (before the rest of the scene in
/// `tracer`), in pixel order. One tick per pixel on `ticker`; a cancel returns
/// `Error::Cancelled`.
pub fn camera_view(
    camera: &Camera,
    mesh: &Mesh,
    tracer: &Tracer,
    ticker: Option<&Ticker>,
) -> Result<Vec<PixelHit>> {
    let eye = camera.eye();
    let rows: Vec<Vec<PixelHit>> = (0..camera.height)
        .into_par_iter()
        .map(|row| {
            let mut out = Vec::new();
            if ticker.is_some_and(|t| !t.add(u64::from(camera.width))) {
                return out; // cancelled: checked below
            }
            for column in 0..camera.width {
                let dir = camera.ray(column, row);
                let Some(hit) = tracer.intersect(eye, dir, f32::INFINITY) else {
                    continue;
                };
                if tracer.occluded_by_rest(eye, dir, hit.t) {
                    continue; // the rest of the scene stands in front
                }
                let p = eye + dir * hit.t;
                let Some((_, uv, normal)) = hit_surface(mesh, hit.triangle, p) else {
                    continue;
                };
                out.push(PixelHit {
                    pixel: row * camera.width + column,
                    position: p,
                    normal,
                    object: mesh.object_of_triangle(hit.triangle as usize),
                    triangle: hit.triangle,
                    uv,
                });
            }
            out
        })
        .collect();
    if let Some(t) = ticker {
        t.check()?;
    }
    Ok(rows.into_iter().flatten().collect())
}

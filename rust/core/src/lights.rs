//! Light sources and the world, in Blender/Cycles units so that a comparison with a Cycles
//! render is like for like (docs/design.md, "wgpu and headless Blender"):
//! sun Strength = irradiance [W/m^2] on a surface facing it; point/spot Power P [W] gives
//! radiant intensity P/(4 pi) [W/sr]; an area light of power P and area A emits radiance
//! P/(pi A) from its front side; the world colour is radiance.

use crate::error::{Error, Result};
use glam::Vec3;

/// One light. Colours are linear RGB multipliers of the power/strength.
#[derive(Debug, Clone, PartialEq)]
pub enum Light {
    /// A distant light: `direction` is the way the light travels (Blender's sun points along -Z
    /// of its object), `irradiance` the Strength [W/m^2].
    Sun {
        direction: Vec3,
        irradiance: [f32; 3],
    },
    /// An isotropic point light of `power` [W] per channel.
    Point { position: Vec3, power: [f32; 3] },
    /// A spot light: a point light restricted to a cone of full angle `spot_size` [rad] around
    /// `direction`, softened over the fraction `blend` of the cone (Cycles' smoothstep).
    Spot {
        position: Vec3,
        direction: Vec3,
        power: [f32; 3],
        spot_size: f32,
        blend: f32,
    },
    /// A rectangular one-sided area light centred at `position`, emitting along `direction`,
    /// with edges `size_u` x `size_v` along the unit vectors `axis_u`, `axis_v`.
    Area {
        position: Vec3,
        direction: Vec3,
        axis_u: Vec3,
        size_u: f32,
        size_v: f32,
        power: [f32; 3],
    },
    /// A mesh emitting a uniform radiance from both sides of its triangles (an Emission
    /// shader on any shape: `emissive_mesh`).
    Mesh(std::sync::Arc<crate::emissive_mesh::EmissiveMesh>),
}

/// What surrounds the scene: radiance arriving from directions that escape the mesh.
#[derive(Debug, Clone, PartialEq, Default)]
pub enum World {
    /// Nothing: costs no rays at all.
    #[default]
    Black,
    /// A uniform radiance [W/(m^2 sr)] from every direction.
    Uniform([f32; 3]),
    /// An equirectangular radiance image (row-major, row 0 at the top = +Z), mapped the way
    /// Cycles maps an Environment Texture with default vector: u = -atan2(d.y, d.x)/(2 pi) + 1/2,
    /// v = atan2(d.z, hypot(d.x, d.y))/pi + 1/2.
    Environment {
        width: usize,
        height: usize,
        radiance: Vec<[f32; 3]>,
    },
}

/// The largest coordinate a point off the mesh (a light, the eye) may have [scene units]:
/// squared distances to it stay in single precision (3 (2e15)^2 ~ 1e31) with room.
pub const POINT_LIMIT: f32 = 1e15;

/// Why a point off the mesh (a light, the eye) cannot be used, if it cannot: not finite, or
/// beyond `POINT_LIMIT`.
fn point_problem(name: &str, v: Vec3) -> Option<String> {
    if !v.is_finite() {
        return Some(format!("{name} {v:?} is not finite"));
    }
    (v.abs().max_element() > POINT_LIMIT).then(|| {
        format!(
            "{name} {v:?} lies beyond the supported |x| <= {POINT_LIMIT:e} scene units \
             (squared distances to it would leave single precision); bring it closer: from \
             that far the directions to it no longer change across a mesh"
        )
    })
}

/// The eye (or any point off the mesh that is not a light): finite, within `POINT_LIMIT`.
pub fn check_point(name: &str, v: Vec3) -> Result<Vec3> {
    point_problem(name, v).map_or(Ok(v), |m| Err(Error::InvalidArgument(m)))
}

fn check_vec(name: &str, v: Vec3) -> Result<Vec3> {
    point_problem(name, v).map_or(Ok(v), |m| Err(Error::InvalidLight(m)))
}

/// A unit direction: normalised in double precision (a finite (-1e30, 0, 0) is a direction,
/// though its squared length overflows single precision).
fn check_dir(name: &str, v: Vec3) -> Result<Vec3> {
    if !v.is_finite() {
        return Err(Error::InvalidLight(format!("{name} {v:?} is not finite")));
    }
    v.as_dvec3()
        .try_normalize()
        .map(|d| d.as_vec3())
        .ok_or_else(|| Error::InvalidLight(format!("{name} {v:?} has zero length")))
}

fn check_rgb(name: &str, c: [f32; 3]) -> Result<[f32; 3]> {
    if c.iter().any(|x| !x.is_finite() || *x < 0.0) {
        return Err(Error::InvalidLight(format!(
            "{name} {c:?} must be finite and >= 0"
        )));
    }
    Ok(c)
}

impl Light {
    pub fn sun(direction: Vec3, irradiance: [f32; 3]) -> Result<Self> {
        Ok(Light::Sun {
            direction: check_dir("sun direction", direction)?,
            irradiance: check_rgb("sun irradiance", irradiance)?,
        })
    }

    pub fn point(position: Vec3, power: [f32; 3]) -> Result<Self> {
        Ok(Light::Point {
            position: check_vec("point light position", position)?,
            power: check_rgb("point light power", power)?,
        })
    }

    pub fn spot(
        position: Vec3,
        direction: Vec3,
        power: [f32; 3],
        spot_size: f32,
        blend: f32,
    ) -> Result<Self> {
        if !(spot_size.is_finite() && spot_size > 0.0 && spot_size <= std::f32::consts::PI) {
            return Err(Error::InvalidLight(format!(
                "spot_size {spot_size} must lie in (0, pi] radians"
            )));
        }
        if !(blend.is_finite() && (0.0..=1.0).contains(&blend)) {
            return Err(Error::InvalidLight(format!(
                "spot blend {blend} must lie in [0, 1]"
            )));
        }
        Ok(Light::Spot {
            position: check_vec("spot position", position)?,
            direction: check_dir("spot direction", direction)?,
            power: check_rgb("spot power", power)?,
            spot_size,
            blend,
        })
    }

    pub fn area(
        position: Vec3,
        direction: Vec3,
        axis_u: Vec3,
        size_u: f32,
        size_v: f32,
        power: [f32; 3],
    ) -> Result<Self> {
        let direction = check_dir("area light direction", direction)?;
        let axis_u = check_dir("area light axis_u", axis_u)?;
        if axis_u.dot(direction).abs() > 1e-3 {
            return Err(Error::InvalidLight(
                "area light axis_u must be perpendicular to its direction".into(),
            ));
        }
        for (n, s) in [("size_u", size_u), ("size_v", size_v)] {
            if !(s.is_finite() && s > 0.0) {
                return Err(Error::InvalidLight(format!(
                    "area light {n} {s} must be > 0"
                )));
            }
        }
        Ok(Light::Area {
            position: check_vec("area light position", position)?,
            direction,
            axis_u,
            size_u,
            size_v,
            power: check_rgb("area light power", power)?,
        })
    }

    /// A mesh emitting `radiance` [W/(unit^2 sr)] from both sides of `triangles`.
    pub fn mesh(positions: &[Vec3], triangles: &[[u32; 3]], radiance: [f32; 3]) -> Result<Self> {
        let m = crate::emissive_mesh::EmissiveMesh::new(positions, triangles, radiance)?;
        Ok(Light::Mesh(std::sync::Arc::new(m)))
    }

    /// `mesh` with `radiance` times a factor per triangle corner (`EmissiveMesh::textured`),
    /// hidden from shadow rays where `visible_shadow` is false.
    pub fn textured_mesh(
        positions: &[Vec3],
        triangles: &[[u32; 3]],
        radiance: [f32; 3],
        corners: Option<&[[[f32; 3]; 3]]>,
        visible_shadow: bool,
    ) -> Result<Self> {
        let m = crate::emissive_mesh::EmissiveMesh::textured(
            positions,
            triangles,
            radiance,
            corners,
            visible_shadow,
        )?;
        Ok(Light::Mesh(std::sync::Arc::new(m)))
    }

    /// What it emits per channel: a sun's irradiance, a mesh's radiance, the others' power.
    pub fn emission(&self) -> [f32; 3] {
        match self {
            Light::Sun { irradiance, .. } => *irradiance,
            Light::Point { power, .. } | Light::Spot { power, .. } | Light::Area { power, .. } => {
                *power
            }
            Light::Mesh(m) => m.radiance(),
        }
    }

    /// Whether it is sampled at several points (an area light, an emissive mesh): its light
    /// arrives from a spread of directions.
    pub fn is_spread(&self) -> bool {
        matches!(self, Light::Area { .. } | Light::Mesh(_))
    }

    /// Whether the light emits anything at all (a black light costs no rays).
    pub fn is_black(&self) -> bool {
        self.emission().iter().all(|x| *x == 0.0)
    }

    /// Whether the light can reach any point of the box [`lo`, `hi`] that bounds the
    /// translucent surface: a spot whose cone misses the box's bounding ball, or an area light
    /// with the whole box behind its one-sided front, reaches nothing and needs no work at all.
    /// Conservative: `true` whenever it cannot tell.
    pub fn can_reach(&self, lo: Vec3, hi: Vec3) -> bool {
        let centre = 0.5 * (lo + hi);
        let radius = 0.5 * (hi - lo).length() * 1.0001 + 1e-6;
        match self {
            Light::Sun { .. } | Light::Point { .. } => true,
            Light::Spot {
                position,
                direction,
                spot_size,
                ..
            } => {
                // Cone-sphere test: the angle from the axis to the ball's centre, less the
                // ball's angular radius, must fall inside the half angle.
                let v = centre - *position;
                let d = v.length();
                if d <= radius {
                    return true;
                }
                let to_centre = (v / d).dot(*direction).clamp(-1.0, 1.0).acos();
                let angular_radius = (radius / d).clamp(-1.0, 1.0).asin();
                to_centre - angular_radius < 0.5 * spot_size
            }
            Light::Area {
                position,
                direction,
                ..
            } => {
                // The rectangle is one plane emitting to its front: a box wholly behind (or on)
                // that plane receives nothing.
                let extent = (0.5 * (hi - lo)).dot(direction.abs());
                (centre - *position).dot(*direction) + extent > 0.0
            }
            // Two-sided and of any shape: it may reach anything.
            Light::Mesh(_) => true,
        }
    }
}

/// The point at `u` in [0, 1]^2 of an area light's rectangle (centred at `position`, edges
/// `size_u` along `axis_u` and `size_v` along `direction` x `axis_u`).
pub fn rectangle_point(
    position: Vec3,
    direction: Vec3,
    axis_u: Vec3,
    size_u: f32,
    size_v: f32,
    u: [f32; 2],
) -> Vec3 {
    let axis_v = direction.cross(axis_u);
    position + axis_u * ((u[0] - 0.5) * size_u) + axis_v * ((u[1] - 0.5) * size_v)
}

/// Light arriving at a point from one sample of a light (pbrt-v4's `SampleLi`): the unit
/// direction toward the light, how far it is (infinite for a sun), and the radiance integrated
/// over the sample's solid angle [W/unit^2 at normal incidence]. A surface facing it receives
/// `value` x cos; an area light's sample is one of `count` points (divide by the count).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Incident {
    pub direction: Vec3,
    pub distance: f32,
    pub value: [f32; 3],
}

impl Light {
    /// `incident`, but an emissive mesh seen from outside its bounding sphere is sampled by
    /// solid angle (`EmissiveMesh::toward`: a direction in the cone, the first surface along
    /// it): far less noise than by area, where half the points lie on its far side. What the
    /// irradiance estimate takes; the same `u` at points of one line does not give one
    /// direction here (single scattering asks `incident`).
    #[inline]
    pub fn sample(&self, x: Vec3, u: [f32; 2]) -> Option<Incident> {
        use crate::emissive_mesh::Toward;
        match self {
            Light::Mesh(m) => match m.toward(x, u) {
                Toward::Hit(s) => Some(Incident {
                    direction: s.direction,
                    distance: s.distance,
                    value: s.value,
                }),
                Toward::Miss => None,
                Toward::Inside => self.incident(x, u),
            },
            _ => self.incident(x, u),
        }
    }

    /// The light arriving at `x` from the sample `u` in [0, 1)^2 (only area lights and emissive
    /// meshes read it: the point of the rectangle at (u - 1/2) x size, or of the mesh). None where nothing arrives (outside a
    /// spot's cone, behind an area light, at the light itself). The same `u` at every point
    /// of one line toward the light gives the same direction: single scattering finds where a
    /// ray enters the medium and asks again there.
    #[inline]
    pub fn incident(&self, x: Vec3, u: [f32; 2]) -> Option<Incident> {
        use std::f32::consts::PI;
        let toward = |pos: Vec3| {
            let v = pos - x;
            let d2 = v.length_squared();
            (d2 > 0.0 && d2.is_finite()).then(|| (v / d2.sqrt(), d2.sqrt(), d2))
        };
        match self {
            // Sun Strength is the irradiance on a surface facing it.
            Light::Sun {
                direction,
                irradiance,
            } => Some(Incident {
                direction: -*direction,
                distance: f32::INFINITY,
                value: *irradiance,
            }),
            // Power P [W] is radiant intensity P / (4 pi) [W/sr]: P / (4 pi d^2) at distance d.
            Light::Point { position, power } => {
                let (l, d, d2) = toward(*position)?;
                Some(Incident {
                    direction: l,
                    distance: d,
                    value: power.map(|p| p / (4.0 * PI * d2)),
                })
            }
            // Cycles' spot_light_attenuation: smoothstep over the blend fraction of the cone.
            Light::Spot {
                position,
                direction,
                power,
                spot_size,
                blend,
            } => {
                let (l, d, d2) = toward(*position)?;
                let mask = spot_mask((-l).dot(*direction), *spot_size, *blend);
                if mask <= 0.0 {
                    return None;
                }
                Some(Incident {
                    direction: l,
                    distance: d,
                    value: power.map(|p| mask * p / (4.0 * PI * d2)),
                })
            }
            // A Lambertian rectangle of radiance P / (pi A): one point of it stands for
            // L cos_l A / d^2 of solid-angle-integrated radiance.
            Light::Area {
                position,
                direction,
                axis_u,
                size_u,
                size_v,
                power,
            } => {
                let q = rectangle_point(*position, *direction, *axis_u, *size_u, *size_v, u);
                let (l, d, d2) = toward(q)?;
                let cos_l = direction.dot(-l);
                if cos_l <= 0.0 {
                    return None;
                }
                let area = size_u * size_v;
                Some(Incident {
                    direction: l,
                    distance: d,
                    value: power.map(|p| p / (PI * area) * cos_l * area / d2),
                })
            }
            // Radiance from both sides: one point q stands for L(q) |cos_l| A_i / (p_i d^2)
            // (`EmissiveMesh::point`), where the emitter's own surface does not hide it from
            // `x` (its far side). The shadow ray stops short of the point (`short_of`): the
            // emitter, an occluder too as Cycles sees it, never shadows its own sampled point.
            Light::Mesh(m) => {
                let (q, n, stands_for) = m.point(u);
                let (l, d, d2) = toward(q)?;
                let cos_l = n.dot(l).abs();
                if cos_l <= 0.0 || m.hides(x, l, d) {
                    return None;
                }
                let k = cos_l / d2;
                Some(Incident {
                    direction: l,
                    distance: m.short_of(d),
                    value: stands_for.map(|r| r * k),
                })
            }
        }
    }
}

impl World {
    pub fn uniform(radiance: [f32; 3]) -> Result<Self> {
        let c = check_rgb("world colour", radiance)?;
        Ok(if c == [0.0; 3] {
            World::Black
        } else {
            World::Uniform(c)
        })
    }

    pub fn environment(width: usize, height: usize, radiance: Vec<[f32; 3]>) -> Result<Self> {
        if width == 0 || height == 0 || radiance.len() != width * height {
            return Err(Error::InvalidLight(format!(
                "environment image of {width} x {height} needs {} pixels, got {}",
                width * height,
                radiance.len()
            )));
        }
        for p in &radiance {
            check_rgb("environment pixel", *p)?;
        }
        if radiance.iter().all(|p| *p == [0.0; 3]) {
            return Ok(World::Black);
        }
        Ok(World::Environment {
            width,
            height,
            radiance,
        })
    }

    pub fn is_black(&self) -> bool {
        matches!(self, World::Black)
    }

    /// Radiance arriving from direction `dir` (unit, pointing away from the scene).
    /// Equirectangular lookup as Cycles' default Environment Texture:
    /// u = -atan2(y, x) / (2 pi) + 1/2, v = atan2(z, hypot(x, y)) / pi + 1/2, v = 1 at the
    /// zenith (image row 0).
    pub fn radiance(&self, dir: Vec3) -> [f32; 3] {
        use std::f32::consts::PI;
        match self {
            World::Black => [0.0; 3],
            World::Uniform(c) => *c,
            World::Environment {
                width,
                height,
                radiance,
            } => {
                let u = -dir.y.atan2(dir.x) / (2.0 * PI) + 0.5;
                let v = dir.z.atan2(dir.x.hypot(dir.y)) / PI + 0.5;
                let x = ((u * *width as f32) as usize).min(width - 1);
                let y = (((1.0 - v) * *height as f32) as usize).min(height - 1);
                radiance[y * width + x]
            }
        }
    }
}

/// A direction leaving a light, drawn by its emission: where a light path starts
/// (`Light::emitted`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Emitted {
    pub origin: Vec3,
    /// Unit.
    pub direction: Vec3,
    /// Its density over the sphere of directions [1/sr] (`Light::emitted_pdf`).
    pub pdf: f32,
}

impl Light {
    /// A direction from a point light uniform over the sphere, from a spot uniform over its
    /// cone (its blend left to the light's value at the far end), and its density; None for
    /// the lights sampled from the receiving point alone (a sun, an area light, an emissive
    /// mesh). The light side of the bounce's two strategies (`irradiance`: Veach 1997 §9.2).
    pub fn emitted(&self, u: [f32; 2]) -> Option<Emitted> {
        let (origin, axis, one_minus) = self.emitted_cap()?;
        Some(Emitted {
            origin,
            direction: cone_direction(axis, one_minus, u),
            pdf: 1.0 / (2.0 * std::f32::consts::PI * one_minus),
        })
    }

    /// The density of `emitted`'s directions [1/sr]: 1 / 4 pi for a point light,
    /// 1 / (2 pi (1 - cos(spot_size / 2))) inside a spot's cone (outside it the light sends
    /// nothing); None for the lights `emitted` does not draw.
    pub fn emitted_pdf(&self) -> Option<f32> {
        let (_, _, one_minus) = self.emitted_cap()?;
        Some(1.0 / (2.0 * std::f32::consts::PI * one_minus))
    }

    /// The cap `emitted` draws from: its apex, axis and 1 - cos of its half angle (2 for a
    /// point light's whole sphere).
    fn emitted_cap(&self) -> Option<(Vec3, Vec3, f32)> {
        let (origin, axis, one_minus) = match self {
            Light::Point { position, .. } => (*position, Vec3::Z, 2.0),
            Light::Spot {
                position,
                direction,
                spot_size,
                ..
            } => (*position, *direction, 1.0 - (0.5 * spot_size).cos()),
            _ => return None,
        };
        (one_minus > 0.0).then_some((origin, axis, one_minus))
    }
}

/// A direction uniform over the cap about the unit `axis` whose half angle has
/// 1 - cos = `one_minus` (2: the whole sphere), from `u` in [0, 1)^2: cos theta uniform over
/// [1 - one_minus, 1] is uniform over the cap's solid angle 2 pi `one_minus`.
pub fn cone_direction(axis: Vec3, one_minus: f32, u: [f32; 2]) -> Vec3 {
    let cos = 1.0 - u[0] * one_minus;
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * u[1];
    let (a, b) = axis.any_orthonormal_pair();
    (axis * cos + (a * phi.cos() + b * phi.sin()) * sin).normalize()
}

/// Cycles' spot cone (`spot_light_attenuation`): 0 outside the cone of full angle `spot_size`,
/// a smoothstep over the `blend` fraction of the cone's cosine range, 1 inside it; no extra
/// cosine. `cos_axis` is the cosine between the spot's axis and the direction to the point.
pub fn spot_mask(cos_axis: f32, spot_size: f32, blend: f32) -> f32 {
    let cos_half = (0.5 * spot_size).cos();
    if cos_axis <= cos_half {
        return 0.0;
    }
    if blend > 0.0 {
        let t = ((cos_axis - cos_half) / ((1.0 - cos_half) * blend)).clamp(0.0, 1.0);
        t * t * (3.0 - 2.0 * t)
    } else {
        1.0
    }
}

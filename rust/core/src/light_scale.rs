//! Whether new lights are the old ones with every emission scaled by one factor per channel:
//! then everything a transport holds (linear in the light) is that factor times the old, and
//! no ray is needed (a power or colour slider on a scene's only light).

use crate::lights::{Light, World};

/// The factor per channel k with new = k old for every light's emission and the world's
/// radiance, the lights' kind and geometry unchanged; None otherwise. Channels dark in both
/// take 1.
pub fn common_scale(
    old_lights: &[Light],
    old_world: &World,
    new_lights: &[Light],
    new_world: &World,
) -> Option<[f32; 3]> {
    if old_lights.len() != new_lights.len() {
        return None;
    }
    let mut pairs: Vec<([f32; 3], [f32; 3])> = Vec::new();
    for (a, b) in old_lights.iter().zip(new_lights) {
        pairs.push(same_but_emission(a, b)?);
    }
    match (old_world, new_world) {
        (World::Black, World::Black) => {}
        (World::Uniform(a), World::Uniform(b)) => pairs.push((*a, *b)),
        (
            World::Environment {
                width: wa,
                height: ha,
                radiance: ra,
            },
            World::Environment {
                width: wb,
                height: hb,
                radiance: rb,
            },
        ) if wa == wb && ha == hb => pairs.extend(ra.iter().copied().zip(rb.iter().copied())),
        _ => return None,
    }
    let mut k: [Option<f32>; 3] = [None; 3];
    for (a, b) in pairs {
        for c in 0..3 {
            if a[c] == 0.0 {
                if b[c] != 0.0 {
                    return None; // light where there was none: not a rescale
                }
                continue;
            }
            let r = b[c] / a[c];
            match k[c] {
                None => k[c] = Some(r),
                Some(s) if (r - s).abs() <= 1e-6 * s.abs().max(r.abs()) => {}
                Some(_) => return None,
            }
        }
    }
    Some(k.map(|x| x.unwrap_or(1.0)))
}

/// Which source of a scene: its light at this place in `lights`, or its world.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Which {
    Light(usize),
    World,
}

/// Whether the new lights are the old ones with exactly one source's emission scaled (one
/// light, or the world), every other light and the world unchanged: that source and the
/// factor per channel k (new = k old for it, `common_scale`). None where nothing changed,
/// more than one source changed, or anything but an emission did.
pub fn one_source_scaled(
    old_lights: &[Light],
    old_world: &World,
    new_lights: &[Light],
    new_world: &World,
) -> Option<(Which, [f32; 3])> {
    if old_lights.len() != new_lights.len() {
        return None;
    }
    let mut changed = (0..old_lights.len())
        .filter(|&i| old_lights[i] != new_lights[i])
        .map(Which::Light)
        .chain((old_world != new_world).then_some(Which::World));
    let (Some(which), None) = (changed.next(), changed.next()) else {
        return None;
    };
    let k = match which {
        Which::Light(i) => light_scale(&old_lights[i], &new_lights[i]),
        Which::World => world_scale(old_world, new_world),
    }?;
    Some((which, k))
}

/// `common_scale` of one light alone: the factor per channel from `old`'s emission to `new`'s
/// when they are the same light but for it.
pub fn light_scale(old: &Light, new: &Light) -> Option<[f32; 3]> {
    common_scale(
        std::slice::from_ref(old),
        &World::Black,
        std::slice::from_ref(new),
        &World::Black,
    )
}

/// `common_scale` of a world alone.
pub fn world_scale(old: &World, new: &World) -> Option<[f32; 3]> {
    common_scale(&[], old, &[], new)
}

/// The two emissions when `a` and `b` are the same light but for it.
fn same_but_emission(a: &Light, b: &Light) -> Option<([f32; 3], [f32; 3])> {
    use Light::*;
    match (a, b) {
        (
            Sun {
                direction: d1,
                irradiance: e1,
            },
            Sun {
                direction: d2,
                irradiance: e2,
            },
        ) if d1 == d2 => Some((*e1, *e2)),
        (
            Point {
                position: p1,
                power: e1,
            },
            Point {
                position: p2,
                power: e2,
            },
        ) if p1 == p2 => Some((*e1, *e2)),
        (
            Spot {
                position: p1,
                direction: d1,
                power: e1,
                spot_size: s1,
                blend: b1,
            },
            Spot {
                position: p2,
                direction: d2,
                power: e2,
                spot_size: s2,
                blend: b2,
            },
        ) if p1 == p2 && d1 == d2 && s1 == s2 && b1 == b2 => Some((*e1, *e2)),
        (
            Area {
                position: p1,
                direction: d1,
                axis_u: u1,
                size_u: su1,
                size_v: sv1,
                power: e1,
            },
            Area {
                position: p2,
                direction: d2,
                axis_u: u2,
                size_u: su2,
                size_v: sv2,
                power: e2,
            },
        ) if p1 == p2 && d1 == d2 && u1 == u2 && su1 == su2 && sv1 == sv2 => Some((*e1, *e2)),
        (Mesh(m1), Mesh(m2)) if m1.same_shape(m2) => Some((m1.radiance(), m2.radiance())),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn key(power: [f32; 3], x: f32) -> Light {
        Light::Point {
            position: Vec3::new(x, 0.0, 1.0),
            power,
        }
    }

    fn sun(e: [f32; 3]) -> Light {
        Light::Sun {
            direction: Vec3::new(0.0, 0.0, -1.0),
            irradiance: e,
        }
    }

    #[test]
    fn a_common_factor_is_found_and_anything_else_is_not_a_rescale() {
        let old = [key([5.0; 3], 0.0), sun([2.0, 2.0, 0.0])];
        let w = World::Uniform([0.1; 3]);
        // Twice as bright in red, half in green and blue (the sun's blue dark in both).
        let new_world = World::Uniform([0.2, 0.05, 0.05]);
        let new = [key([10.0, 2.5, 2.5], 0.0), sun([4.0, 1.0, 0.0])];
        assert_eq!(
            common_scale(&old, &w, &new, &new_world),
            Some([2.0, 0.5, 0.5])
        );
        // One of two lights brighter: not one factor.
        let one = [key([10.0; 3], 0.0), sun([2.0, 2.0, 0.0])];
        assert_eq!(common_scale(&old, &w, &one, &w), None);
        // Moved, or dark where it was lit, or another count: not a rescale.
        assert_eq!(
            common_scale(&old, &w, &[key([5.0; 3], 0.1), sun([2.0, 2.0, 0.0])], &w),
            None
        );
        assert_eq!(
            common_scale(&old, &w, &[key([5.0; 3], 0.0), sun([2.0, 2.0, 1.0])], &w),
            None
        );
        assert_eq!(common_scale(&old, &w, &old[..1], &w), None);
        assert_eq!(common_scale(&old, &w, &old, &World::Black), None);
        assert_eq!(common_scale(&old, &w, &old, &w), Some([1.0; 3]));
    }

    #[test]
    fn one_source_scaled_names_the_one_light_or_world_that_changed_its_emission_only() {
        let old = [key([5.0; 3], 0.0), sun([2.0, 2.0, 0.0])];
        let w = World::Uniform([0.1; 3]);
        let brighter_sun = [key([5.0; 3], 0.0), sun([3.0, 1.0, 0.0])];
        assert_eq!(
            one_source_scaled(&old, &w, &brighter_sun, &w),
            Some((Which::Light(1), [1.5, 0.5, 1.0]))
        );
        let dim_world = World::Uniform([0.05, 0.1, 0.2]);
        assert_eq!(
            one_source_scaled(&old, &w, &old, &dim_world),
            Some((Which::World, [0.5, 1.0, 2.0]))
        );
        // Nothing changed, two sources changed, a light moved, light where there was none,
        // another count: not one source's rescale.
        assert_eq!(one_source_scaled(&old, &w, &old, &w), None);
        assert_eq!(one_source_scaled(&old, &w, &brighter_sun, &dim_world), None);
        let moved = [key([5.0; 3], 0.2), sun([2.0, 2.0, 0.0])];
        assert_eq!(one_source_scaled(&old, &w, &moved, &w), None);
        let blue_sun = [key([5.0; 3], 0.0), sun([2.0, 2.0, 1.0])];
        assert_eq!(one_source_scaled(&old, &w, &blue_sun, &w), None);
        assert_eq!(one_source_scaled(&old, &w, &old[..1], &w), None);
    }
}

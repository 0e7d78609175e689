//! A material's three profiles under the multipole (Donner and Jensen 2005): its medium as a
//! slab of its `Stack`'s thickness in the open (`multipole::Slab`, closed forms, microseconds)
//! or under the stack's top layer (`layered::Layered`, a Hankel-transformed table, a fraction
//! of a second per channel, so the tables are kept: an edit back to a stack seen before, or
//! the same material resolved by another method, builds nothing).

use super::layered::Layered;
use super::multipole::{Medium, Slab};
use super::Profile;
use crate::error::{Error, Result};
use crate::optics::{Material, TopLayer};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

/// Layered tables kept in memory (about 33 KB each); all are dropped when it is full.
const KEPT: usize = 96;

/// The three channels' multipole profiles of `material` (its `stack`).
pub fn profiles(material: &Material) -> Result<[Profile; 3]> {
    material.stack.validate()?;
    let stack = material.stack;
    let eta = material.eta;
    match stack.top {
        None => Ok(std::array::from_fn(|c| {
            Profile::Slab(
                Slab::in_the_open(medium(material, c), stack.thickness, eta).reflectance(),
            )
        })),
        Some(top) => {
            let mut out = Vec::with_capacity(3);
            for c in 0..3 {
                let (upper, base, key) = layers(material, &top, c);
                out.push(Profile::Layered(layered(key, || {
                    Layered::new(upper, top.thickness, base, stack.thickness, eta).map_err(|e| {
                        match e {
                            Error::InvalidArgument(m) => {
                                Error::InvalidMaterial(format!("channel {c}: {m}"))
                            }
                            other => other,
                        }
                    })
                })?));
            }
            Ok(out.try_into().expect("three channels"))
        }
    }
}

/// Whether `profiles(material)` will build nothing: a slab without a top layer (closed forms),
/// or a layered stack whose three tables are kept. A stack that `profiles` would refuse is
/// "ready" too: the refusal costs nothing.
pub fn ready(material: &Material) -> bool {
    let Some(top) = material.stack.top else {
        return true;
    };
    if material.stack.validate().is_err() {
        return true;
    }
    let map = kept()
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    (0..3).all(|c| map.contains_key(&layers(material, &top, c).2))
}

/// The material's own medium in channel `c`.
fn medium(material: &Material, c: usize) -> Medium {
    Medium {
        sigma_a: material.sigma_a[c],
        sigma_s_prime: material.sigma_s_prime()[c],
    }
}

/// Channel `c` of a layered stack: the top layer's medium (with the material's phase
/// function), the base's, and the key of their table.
fn layers(material: &Material, top: &TopLayer, c: usize) -> (Medium, Medium, Key) {
    let upper = Medium {
        sigma_a: top.sigma_a[c],
        sigma_s_prime: (1.0 - material.g) * top.sigma_s[c],
    };
    let base = medium(material, c);
    let key = Key::new(
        &upper,
        top.thickness,
        &base,
        material.stack.thickness,
        material.eta,
    );
    (upper, base, key)
}

/// What a layered table depends on, bit for bit: the two media, both thicknesses and eta.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct Key([u64; 7]);

impl Key {
    fn new(top: &Medium, thickness: f64, base: &Medium, base_thickness: f64, eta: f64) -> Key {
        Key([
            top.sigma_a,
            top.sigma_s_prime,
            thickness,
            base.sigma_a,
            base.sigma_s_prime,
            base_thickness,
            eta,
        ]
        .map(f64::to_bits))
    }
}

fn kept() -> &'static Mutex<HashMap<Key, Arc<Layered>>> {
    static KEPT_TABLES: OnceLock<Mutex<HashMap<Key, Arc<Layered>>>> = OnceLock::new();
    KEPT_TABLES.get_or_init(|| Mutex::new(HashMap::new()))
}

/// The kept table for `key`, built by `build` when missing (outside the lock).
fn layered(key: Key, build: impl FnOnce() -> Result<Layered>) -> Result<Arc<Layered>> {
    let lock = || {
        kept()
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    };
    if let Some(t) = lock().get(&key) {
        return Ok(t.clone());
    }
    let table = Arc::new(build()?);
    let mut map = lock();
    if map.len() >= KEPT {
        map.clear();
    }
    map.insert(key, table.clone());
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::Stack;
    use crate::profiles::{Dipole, RadialProfile};

    fn marble_mm() -> Material {
        Material::preset("marble", 1.0).unwrap()
    }

    #[test]
    fn a_half_space_is_the_dipole() {
        // Infinite thickness, no layer: the multipole's single pair is Jensen's dipole.
        let m = marble_mm();
        let p = profiles(&m).unwrap();
        for (c, got) in p.iter().enumerate() {
            let d = Dipole::new(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
            for r in [0.01, 0.3, 2.0, 10.0] {
                assert!(
                    (got.value(r) - d.value(r)).abs() <= 1e-9 * d.value(r),
                    "r {r}"
                );
            }
            assert!((got.total() - d.rd_total()).abs() <= 1e-9);
        }
    }

    #[test]
    fn a_thin_slab_returns_less_than_the_half_space() {
        // Light that would have come back from below the slab's floor leaves through it.
        let m = marble_mm();
        let thin = m
            .with_stack(Stack {
                thickness: 2.0,
                top: None,
            })
            .unwrap();
        let (a, b) = (profiles(&m).unwrap(), profiles(&thin).unwrap());
        for c in 0..3 {
            assert!(b[c].total() < a[c].total(), "channel {c}");
            assert!(b[c].total() > 0.0);
        }
    }

    #[test]
    fn a_layer_of_the_same_medium_is_the_base_alone() {
        // A top layer of the material's own medium over it: one half-space (index-matched
        // between the layers), so the dipole again, up to the composition's own error: each
        // slab's diffusion puts a zero-fluence extrapolated boundary at the shared face, and
        // the sum over passes restarts light at a source depth below it (Donner and Jensen
        // 2005 compose slabs this way; `layered::against_the_walk` measures 0.5-0.9 % against
        // a brute-force walk through two layers).
        let m = Material::preset("skin1", 1.0).unwrap();
        let same = m
            .with_stack(Stack {
                thickness: f64::INFINITY,
                top: Some(TopLayer {
                    sigma_a: m.sigma_a,
                    sigma_s: m.sigma_s,
                    thickness: 3.0,
                }),
            })
            .unwrap();
        let p = profiles(&same).unwrap();
        for (c, got) in p.iter().enumerate() {
            let d = Dipole::new(m.sigma_a[c], m.sigma_s_prime()[c], m.eta);
            assert!(
                (got.total() - d.rd_total()).abs() <= 1.5e-2 * d.rd_total(),
                "channel {c}: {} vs {}",
                got.total(),
                d.rd_total()
            );
            for r in [0.05, 0.5, 2.0] {
                let (x, y) = (got.value(r), d.value(r));
                assert!((x - y).abs() <= 2e-2 * y, "channel {c} r {r}: {x} vs {y}");
            }
        }
        // Asked again, the kept tables come back (the same allocation).
        let q = profiles(&same).unwrap();
        match (&p[0], &q[0]) {
            (Profile::Layered(a), Profile::Layered(b)) => assert!(Arc::ptr_eq(a, b)),
            _ => panic!("expected layered profiles"),
        }
    }

    #[test]
    fn ready_says_whether_a_table_will_be_built() {
        let m = marble_mm();
        assert!(ready(&m)); // a half-space: closed forms
        let layer = |thickness| {
            m.with_stack(Stack {
                thickness: f64::INFINITY,
                top: Some(TopLayer {
                    sigma_a: [0.0123; 3],
                    sigma_s: [1.87; 3],
                    thickness,
                }),
            })
            .unwrap()
        };
        let stack = layer(3.125); // a stack no other test builds
        assert!(!ready(&stack));
        profiles(&stack).unwrap();
        assert!(ready(&stack));
        assert!(!ready(&layer(3.126)));
    }

    #[test]
    fn a_layer_too_thin_for_diffusion_is_refused_naming_the_channel() {
        let m = marble_mm();
        let e = m
            .with_stack(Stack {
                thickness: f64::INFINITY,
                top: Some(TopLayer {
                    sigma_a: [0.01; 3],
                    sigma_s: [1.0; 3],
                    thickness: 0.1,
                }),
            })
            .map(|m| profiles(&m))
            .unwrap()
            .unwrap_err();
        assert!(e.to_string().contains("channel 0"), "{e}");
        assert!(e.to_string().contains("source depth"), "{e}");
        let bad = |stack: Stack| m.with_stack(stack).unwrap_err().to_string();
        assert!(bad(Stack {
            thickness: 0.0,
            top: None
        })
        .contains("thickness = 0"));
        let top = TopLayer {
            sigma_a: [0.01, f64::NAN, 0.0],
            sigma_s: [1.0; 3],
            thickness: 1.0,
        };
        assert!(bad(Stack {
            thickness: 1.0,
            top: Some(top)
        })
        .contains("top_layer.sigma_a[1]"));
    }
}

//! translucent-core: homogeneous subsurface scattering on triangle meshes, for any radial
//! profile (Jensen's dipole, Cycles' random walk). Pure Rust; the Python binding lives in its
//! own crate. One module per concept (docs/design.md), grouped as the README's layout is.

// Shared: what every method uses.
pub mod bake_points; // where Cycles' vertex bake samples a vertex (its corners, 0.1 mm in)
pub mod emissive_mesh; // a mesh emitting light: triangles sampled by area, both sides
pub mod error; // the one error type
pub mod evaluation; // the one answer every method gives: values, error estimate, seconds, skips
pub mod gpu; // the wgpu adapter the GPU paths share (a real GPU, or lavapipe where allowed)
pub mod irradiance; // shadowed irradiance from the scene's lights (Xu 2007 eq. 3)
pub mod light_scale; // new lights that are the old ones times one factor per channel
pub mod lights; // Blender/Cycles lights and the world
pub mod limits; // the stated limits on request sizes, refused up front
pub mod mesh; // validated triangle meshes, surface samples, vertex areas
pub mod metrics; // area-weighted relative error
pub mod occluders; // the rest of the scene: shadow casters that do not scatter, culled per light
pub mod optics; // material, Fresnel, measured data, Principled layers
pub mod own_light; // the object's own light falling back on it: kept rays, bounces, any edit
pub mod profiles; // radial profiles R(r): the dipole, Cycles' random walk tabulated, the multipole
pub mod progress; // progress and cancelling of long loops (a Ticker over an atomic counter)
pub mod quadrature; // Gauss–Legendre and Simpson rules
pub mod raytrace; // BVH, shadow rays, rays from inside a part, the inside test (obvhs)
pub mod receiver_color; // a Base Color per vertex for a method summing one medium: B scaled per receiver
pub mod scene; // a mesh with its lights
pub mod shadow_edges; // the irradiance on a finer grid where a shadow's edge crosses a triangle
pub mod single_scattering; // Xu 2007 eq. 5's path model, phase functions, brute force
pub mod spherical_harmonics; // real Y_lm and HG's Legendre series (addition theorem)
pub mod surface_integral; // a profile over a triangle or polygon from a point (Mertens 2003 §4)
pub mod surface_terms; // the walks' term and the object's own light for a half-space method
pub mod walks; // Cycles' walk traced inside the mesh, its half-space twin, the walk term

// Methods, each with its private parts inside it (prt: basis, gpu, single;
// hierarchy: clusters, links, far field, rings; splat: sizes, light view, receivers).
pub mod hierarchy; // Mertens et al. 2003: face clusters and links, deformation and moving lights
pub mod prt; // Xu et al. 2007: precomputed transport, live material edits
pub mod splat; // Shah et al. 2009: light-view splats gathered at the vertices, nothing precomputed

// Reference.
pub mod reference; // brute-force integration of the same model: the ground truth

pub use error::{Error, Result};
pub use glam::Vec3;

// The test meshes of `tests/common` name this crate as the integration tests do.
#[cfg(test)]
extern crate self as translucent_core;

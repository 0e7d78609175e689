//! Ground truths the methods are judged against, each sharing only the profile, the light and
//! the mesh with what it judges: the half-space profile integrated over the mesh
//! (`radiosity`) and Cycles' walk traced through the mesh to the radiance a vertex bake
//! records (`radiance`).

pub mod radiance;
pub mod radiosity;

pub use radiance::{reference_radiance, RadianceReference, RadianceReferenceSettings};
pub use radiosity::*;

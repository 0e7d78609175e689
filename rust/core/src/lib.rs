//! translucent-core: homogeneous subsurface scattering on triangle meshes with Jensen's dipole.
//! Pure Rust; the Python binding lives in its own crate. One module per concept (DESIGN.md).

pub mod basis;
pub mod error;
pub mod gpu;
pub mod irradiance;
pub mod lights;
pub mod mesh;
pub mod metrics;
pub mod optics;
pub mod prt;
pub mod quadrature;
pub mod raytrace;
pub mod reference;
pub mod scene;

pub use error::{Error, Result};
pub use glam::Vec3;

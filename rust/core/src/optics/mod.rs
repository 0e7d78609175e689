//! What a homogeneous translucent material is and what light does at its surface: the
//! material (`material`), Fresnel transmission at a smooth boundary (`fresnel`), Jensen 2001's
//! measured data (`measured`) and the Principled BSDF's layers and input mapping as Cycles
//! defines them (`principled`). What carries light under the surface is `profiles`.

pub mod fresnel;
pub mod material;
pub mod measured;
pub mod principled;

pub use fresnel::{boundary_a, f_dr, fresnel_transmittance, refracted_cosine};
pub use material::{Layers, Material, Stack, TopLayer, CHANNELS, MAX_COEFFICIENT};
pub use measured::{MEASURED, MEASURED_ETA};

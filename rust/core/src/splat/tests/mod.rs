//! The splatting against what does not depend on it: closed forms of areas and solid angles
//! for the light's view, the plane's closed form (Jensen 2001) and the ground truth
//! (`reference_radiosity`) for the gathered radiosity, and the shared evaluation's contract
//! (skips, bad input, cancelling).

mod camera;
mod estimate;
mod gpu;
mod light_view;
mod method;
mod peel;
mod receivers;
mod reuse;

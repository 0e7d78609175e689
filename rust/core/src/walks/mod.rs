//! Cycles' random walk traced inside the mesh (with its half-space twin as control variate),
//! and the walk term: what those walks add to PRT's half-space profile, carried to every vertex.

mod allocation;
mod combine;
mod grid;
mod knots;
mod media;
mod operator;
mod passes;
mod radiosity;
mod relight;
mod shrinkage;
mod smoothing;
mod term;
mod twin;
mod walker;

pub use knots::KnotReader;
pub use media::media_to_walk;
pub use operator::ReceiverRecord;
pub use radiosity::{
    relit_radiosity, walk_radiosity, walk_radiosity_lit, ExitLight, MeshWalkResult,
    MeshWalkSettings,
};
pub(crate) use term::lengths_and_albedos;
pub use term::{
    default_walk_rays, WalkTerm, WalkTermReport, WalkTermSettings, DEFAULT_WALK_RAYS,
    FLAT_TOLERANCE, LENGTH_MARGIN, MAX_WALK_RAYS_PER_VERTEX, MIN_WALK_RAYS_PER_VERTEX,
};

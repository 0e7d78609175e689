//! The one error type of the core. Everything a user can cause (bad numbers, bad indices,
//! empty input, cancelling) is a variant here; internal invariants are debug assertions.

/// Errors the core reports to its caller. The binding maps each variant to a Python exception.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// A material parameter is out of its physical range (negative coefficient, eta < 1, |g| >= 1, NaN).
    #[error("invalid material: {0}")]
    InvalidMaterial(String),
    /// The mesh cannot be used (empty, NaN/Inf coordinates, index out of range).
    #[error("invalid mesh: {0}")]
    InvalidMesh(String),
    /// A light or world description cannot be used (negative power, zero direction, bad image size).
    #[error("invalid light: {0}")]
    InvalidLight(String),
    /// Any other argument out of range (basis size, tolerance, receiver index).
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
    /// No usable GPU adapter (or it failed); the CPU path is always available.
    #[error("GPU unavailable: {0}")]
    GpuUnavailable(String),
    /// The caller's progress callback asked to stop.
    #[error("cancelled by the caller")]
    Cancelled,
}

pub type Result<T> = std::result::Result<T, Error>;

//! robocal-core: the numerical core of robocal — kinematic models with an exact Jacobian,
//! identification, validation on held-out poses, the sim-to-real diagnosis, compensation and the
//! virtual cell. Everything here is in SI units (m, rad, kg) and does no I/O; the service (the
//! `robocal` crate) converts the wire and file formats (mm, deg) to and from these types, once.

// Numeric kernels index several parallel per-joint arrays with one joint index; iterator zips of
// four arrays read worse than the formulas they implement.
#![allow(clippy::needless_range_loop)]

pub mod cell;
pub mod diagnose;
pub mod formats;
pub mod identify;
pub mod kinematics;
pub mod metrology;
pub mod sim;
pub mod units;
pub mod validate;

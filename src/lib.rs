//! robocal: robot calibration — kinematic models, identification, validation and compensation.
//!
//! The pure-math layers (`kinematics`, `metrology`) know nothing of I/O; `domain` converts the
//! wire and file formats (mm, deg) to and from them, once; `cli` is a thin front end.

// Numeric kernels index several parallel per-joint arrays with one joint index; iterator zips of
// four arrays read worse than the formulas they implement.
#![allow(clippy::needless_range_loop)]

pub mod cell;
pub mod cli;
pub mod domain;
pub mod identify;
pub mod import;
pub mod kinematics;
pub mod metrology;
pub mod sim;
pub mod validate;

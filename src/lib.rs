//! robocal: robot calibration — kinematic models, identification, validation and compensation.
//!
//! The pure-math layers (`kinematics`, `metrology`, `identify`, `validate`, `sim`) know nothing
//! of I/O; `domain` converts the wire and file formats (mm, deg) to and from them, once; `db`
//! (SQLite), `app` (what the routes and the jobs share: the state, a robot's model, a cell from
//! stored sessions), `jobs` (the persisted queue) and `http` (axum) make the service, each using
//! only the layers below it; `cli` and `server` are thin front ends over the same calls.

// Numeric kernels index several parallel per-joint arrays with one joint index; iterator zips of
// four arrays read worse than the formulas they implement.
#![allow(clippy::needless_range_loop)]

// The numerical core lives in its own crate (crates/robocal-core), which compiles without the
// service's dependencies; its modules keep their paths here.
pub use robocal_core::{cell, diagnose, identify, kinematics, metrology, sim, units, validate};

pub mod app;
pub mod cli;
pub mod db;
pub mod demo;
pub mod domain;
pub mod experiments;
pub mod http;
pub mod import;
pub mod jobs;
pub mod report;
pub mod server;

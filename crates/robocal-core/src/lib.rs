//! robocal-core: the numerical core of robocal — kinematic models with an exact Jacobian,
//! identification, validation on held-out poses, the sim-to-real diagnosis, compensation and the
//! virtual cell. Everything here is in SI units (m, rad, kg) and does no I/O; the service (the
//! `robocal` crate) converts the wire and file formats (mm, deg) to and from these types, once.
//!
//! # Calibrate, validate on held-out poses, compensate
//!
//! The thesis's virtual cell: an IRB 120 whose true geometry, β and gear compliances differ from
//! the controller's nominal model, measured on a TriCal artefact, with validation poses the fit
//! never sees. Identification keeps the thesis's 31 parameters; validated against the true
//! positions, the calibrated model misses by a fraction of what the nominal one does; compensation
//! finds the joints that put the calibrated robot's TCP on a target.
//!
//! ```
//! use robocal_core::sim::simulate::{SimulateOptions, simulate};
//! use robocal_core::{
//!     Compensator, Frame, IdentifyOptions, JointState, Reference, Seed, identify, validate, validation_sessions,
//! };
//!
//! let sim = simulate(&SimulateOptions { seed: 1, ..Default::default() })?;
//! let id = identify(&sim.cell, &IdentifyOptions::default())?;
//! assert_eq!(id.free_names.len(), 31);
//!
//! let held_out = validation_sessions(&sim.cell);
//! let report = validate(&id.set, &sim.cell, &held_out, Reference::Truth(&sim.run))?;
//! let (calibrated, nominal) = (report.calibrated.position.mean, report.nominal.position.mean);
//! assert!(calibrated < 0.1 * nominal, "{calibrated} m against {nominal} m");
//!
//! // Where the controller's (nominal) model puts the TCP at these joints (rad) is the target a
//! // program asks for. The real robot at those joints misses it; at the compensated ("fake
//! // target") joints the calibrated model lands on it.
//! let q = [0.2, 0.3, 0.2, 0.1, 1.0, 0.0];
//! let target: Frame = id.set.nominal_chain().fk(&JointState::new(&q));
//! let (uncompensated, _) = id.set.fk(&q).distance(&target);
//! let c = Compensator::new(&id.set).pose(&target, Seed::Joints(&q))?;
//! let (compensated, _) = id.set.fk(c.joints()).distance(&target);
//! assert!(uncompensated > 1e-4 && compensated < 1e-6, "{uncompensated} m, then {compensated} m");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! # The API
//!
//! What a user needs is re-exported here, at the crate's root: the robot model ([`RobotModel`],
//! [`Preset`], [`Tool`]), the parameter set and its chain ([`ParameterSet`], [`Chain`]: forward
//! kinematics and the exact Jacobian; [`AnalyticIk`] and [`Compensator`]: inverse kinematics and
//! fake targets), the cell and its file ([`Cell`], [`parse_cell`], [`cell_to_json`]), the
//! parameter-set file ([`ParameterSetDoc`]), [`identify()`] with [`IdentifyOptions`], [`validate()`],
//! and [`diagnose()`] with [`DiagnoseOptions`]. The modules hold the rest: the formats' wire types,
//! the solver's pieces, the simulator.
//!
//! A cell file read, written and read back keeps its sessions and measurements:
//!
//! ```
//! use robocal_core::sim::simulate::{SimulateOptions, simulate};
//! use robocal_core::{cell_to_json, parse_cell};
//!
//! let sim = simulate(&SimulateOptions { seed: 2, id_per_ball: 10, validation: 20, ..Default::default() })?;
//! let text = cell_to_json(&sim.cell);
//! let cell = parse_cell(&text)?;
//! assert_eq!(cell.sessions.len(), sim.cell.sessions.len());
//! for (a, b) in cell.sessions.iter().zip(&sim.cell.sessions) {
//!     assert_eq!((&a.name, a.measurements.len()), (&b.name, b.measurements.len()));
//! }
//! // A bad field is named by its path in the file.
//! let err = parse_cell(&text.replacen("\"purpose\": \"identification\"", "\"purpose\": \"fitting\"", 1))
//!     .unwrap_err();
//! assert!(err.path.starts_with("sessions[0]"), "{err}");
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

// Numeric kernels index several parallel per-joint arrays with one joint index; iterator zips of
// four arrays read worse than the formulas they implement.
#![allow(clippy::needless_range_loop)]
#![warn(missing_docs)]
// A type the public API hands out must be nameable by its users (re-exported where its module is
// private to the crate).
#![warn(unnameable_types)]

pub mod cell;
// Every public item is documented (`missing_docs`), so a new undocumented item fails the build;
// the docs of `formats` become the OpenAPI document's descriptions (issue 28).
pub mod diagnose;
pub mod formats;
pub mod identify;
pub mod kinematics;
pub mod metrology;
pub mod sim;
pub mod units;
pub mod validate;

pub use cell::{Cell, Measurement, Purpose, Session};
pub use diagnose::{DiagnoseError, DiagnoseOptions, Diagnosis, diagnose};
pub use formats::cell::{cell_to_json, parse_cell};
pub use formats::{DomainError, ParameterSetDoc};
pub use identify::{Identification, IdentifyError, IdentifyOptions, identify};
pub use kinematics::{
    AnalyticIk, Chain, Compensated, Compensator, Frame, JointState, ParameterSet, Preset, RobotModel, Seed, Tool,
};
pub use validate::report::{Reference, ValidateError, ValidationReport, validate, validation_sessions};

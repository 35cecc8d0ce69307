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
//! use robocal_core::identify::{IdentifyOptions, identify};
//! use robocal_core::kinematics::compensate::{Compensator, Seed};
//! use robocal_core::kinematics::{Frame, JointState};
//! use robocal_core::sim::simulate::{SimulateOptions, simulate};
//! use robocal_core::validate::report::{Reference, validate, validation_sessions};
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

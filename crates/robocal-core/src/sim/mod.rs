//! The virtual cell: a "true" robot with unmodelled effects, the instruments that measure it, and
//! pose generation (product code: the service reuses it for pose plans). Pure math, SI units,
//! deterministic for a seed; the one exception to "no I/O" is [`tracker_run::TrackerRun::write`],
//! which writes the three-reflector text files.
//!
//! - [`simulate`]: the entry point — plan, measure, return the cell and its truth.
//! - [`truth`] and [`effects`]: the true robot and the unmodelled effects it can carry.
//! - [`instruments`] and [`measure`]: the noise, and the TriCal and laser-tracker runs.
//! - `poses`, `collision` and `geometry`: collision-free pose planning.
//! - [`tracker_run`]: a customer-style laser-tracker run in the three-reflector format.

pub mod collision;
pub mod effects;
pub(crate) mod geometry;
pub mod instruments;
pub mod measure;
pub mod poses;
pub mod simulate;
pub mod tracker_run;
pub mod truth;

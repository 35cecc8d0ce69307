//! The virtual cell: a "true" robot with unmodelled effects, the instruments that measure it, and
//! pose generation (product code: the service reuses it for pose plans). Pure math, SI units,
//! deterministic for a seed.

pub mod collision;
pub mod effects;
pub mod geometry;
pub mod instruments;
pub mod measure;
pub mod poses;
pub mod simulate;
pub mod tracker_run;
pub mod truth;

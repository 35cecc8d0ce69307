//! Identification (thesis §4.2, §6; digest §4, §6): the parameters of a better model from a
//! cell's measurements — least squares on faer with Levenberg–Marquardt damping, automatic
//! identifiability, conditioning and observability, honest uncertainties, DETMAX pose selection.

pub mod detmax;
pub mod observability;

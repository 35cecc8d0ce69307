//! Measurement geometry: the artefact that defines {W} and the TriCal's indicator trilateration.
//! Pure math, SI units. (Not in ENGINEERING.md's layout: it is neither kinematics nor the virtual
//! cell, and both the identification and the simulator use it.)

pub(crate) mod artefact;
pub mod registration;
pub(crate) mod trical;

pub use artefact::{ArtefactError, BallTriangle};
pub use trical::{TriCal, TriCalError};

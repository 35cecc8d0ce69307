//! Validation of a parameter set on a cell's sessions.

//! Validated input types and the one unit-conversion layer: files and the wire use millimetres
//! and degrees with the unit in the field name; the kinematics use metres and radians.
//! Parse, don't validate: every `to_*` conversion returns a checked SI value or a [`DomainError`]
//! naming the field path and the reason.

pub mod drift;
pub mod export;
pub mod history;
pub mod iso9283;
pub mod measurement_csv;
pub mod origin;
pub mod pose;
pub mod program;
pub mod truth;

// The formats of robots, tools and parameter sets, and the error type of every format, live in
// the core (`robocal_core::formats`) so that its users read the same files; re-exported here
// under their old paths.
pub use pose::{Choice, CompensationResult, PoseOut, PoseSpec, Target, TargetSpec};
pub use robocal_core::formats::{
    DomainError, field_path, finite, from_json, from_value, joints_deg, limits, param_set, robot, rounding, to_deg,
    vec3_mm, with_article,
};
pub use robocal_core::formats::{JointSpec, RobotSpec, ToolSpec};
pub use robocal_core::formats::{cell, diagnosis, diagnosis_spec, validation, validity};
/// An identification's run and its parameter-set document, and its options as given (checked
/// once, for every front end), under their old path.
pub mod identification {
    pub use robocal_core::formats::identification::*;
    pub use robocal_core::formats::identify_options::*;
}
pub use robocal_core::formats::{ParamEntry, ParameterSetDoc, ParameterSetFile, Quality, quality};

/// The boundary's units, defined once in [`crate::units`]; re-exported here because every file
/// format converts with them.
pub use crate::units::{DEG, MM};

//! A stored robot's model and base guess, as the routes and the jobs read them.

use serde_json::Value;

use super::AppError;
use crate::db::records::RobotRow;
use crate::domain::RobotSpec;
use crate::domain::cell::PoseXyzAbc;
use crate::kinematics::RobotModel;

/// The robot's validated model.
pub fn model_of(row: &RobotRow) -> Result<RobotModel, AppError> {
    let v: Value =
        serde_json::from_str(&row.model_json).map_err(|e| AppError::Internal(format!("robot {}: {e}", row.id)))?;
    RobotSpec::from_json_value(&v)
        .and_then(|s| s.to_model())
        .map_err(|e| AppError::Internal(format!("robot {}: stored model invalid: {e}", row.id)))
}

/// The robot's base guess T_0^W: planning needs to know where the artefact is relative to the
/// robot.
pub fn robot_base(robot: &RobotRow) -> Result<[f64; 6], AppError> {
    let Some(json) = robot.base_guess_json.as_deref() else {
        return Err(AppError::invalid(
            "base_guess",
            format!(
                "robot '{}' has no base_guess: pose planning needs where the artefact lies relative to the robot",
                robot.name
            ),
        ));
    };
    let b: PoseXyzAbc = serde_json::from_str(json)
        .map_err(|e| AppError::Internal(format!("robot {}: stored base guess: {e}", robot.id)))?;
    b.to_si("base_guess").map_err(|e| AppError::Invalid { field: e.field(), detail: e.to_string() })
}

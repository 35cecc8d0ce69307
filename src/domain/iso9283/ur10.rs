//! Pose ids for the UR10 data set's ISO 9283 series (`Series_D`): the file has no pose id column,
//! only each row's goal (the commanded TCP pose). Rows are read in file order (the measuring
//! program's log) and:
//! - **pose**: a row whose goal lies within [`SAME_POSITION`] (0.5 mm) and [`SAME_ANGLE`] (0.5°) of
//!   a pose seen before is that pose again; otherwise it starts a new pose, named `D001`, `D002`, …
//!   in order of first appearance. (Series D's cube centres differ by ≥ 0.9 mm between sessions of
//!   the program, while repeated goals of one pose differ by ≤ 0.05 mm.)
//! - **cycle**: the visit's count of that pose (1, 2, …): consecutive visits are cycles.
//! - **approach**: the signs of the move from the previous row's goal into this one, in the robot
//!   base's axes (`+x-y-z`; an axis moved less than 1 mm is `0`). The first row has none.
//!
//! The goals are in ROS's `base_link`, the UR base turned 180° about z: x and y are negated to
//! put the approach in the base frame the evaluation uses.

use std::path::Path;

use nalgebra::{Matrix3, Vector3};

use super::evaluate::Assignment;
use crate::kinematics::frame::{rot_x, rot_y, rot_z, rotation_angle};
use crate::units::{DEG, MM};

/// Goals closer than this are one pose, m.
pub const SAME_POSITION: f64 = 0.5 * MM;
/// Goals turned less than this are one pose, rad.
pub const SAME_ANGLE: f64 = 0.5 * DEG;

const GOAL_COLUMNS: [&str; 6] = ["Goal x", "Goal y", "Goal z", "Goal roll", "Goal pitch", "Goal yaw"];

/// One goal: position (m) and rotation, in `base_link`.
#[derive(Clone, Debug, PartialEq)]
pub struct Goal {
    pub position: Vector3<f64>,
    pub rotation: Matrix3<f64>,
}

fn number(text: &str) -> Option<f64> {
    text.trim().replace(',', ".").parse::<f64>().ok().filter(|v| v.is_finite())
}

/// The goals of a `measurements_*.csv` text (semicolon-separated, decimal commas), in row order.
pub fn read_goals(text: &str) -> Result<Vec<Goal>, String> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().ok_or("the file is empty")?.split(';').map(str::trim).collect();
    let cols: Vec<usize> = GOAL_COLUMNS
        .iter()
        .map(|c| header.iter().position(|h| h == c).ok_or_else(|| format!("no column '{c}' in the header")))
        .collect::<Result<_, _>>()?;
    let mut goals = Vec::new();
    for (k, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(';').collect();
        let mut v = [0.0; 6];
        for (i, &c) in cols.iter().enumerate() {
            v[i] = fields
                .get(c)
                .and_then(|f| number(f))
                .ok_or_else(|| format!("line {}: column '{}' is not a number", k + 2, GOAL_COLUMNS[i]))?;
        }
        goals
            .push(Goal { position: Vector3::new(v[0], v[1], v[2]), rotation: rot_z(v[5]) * rot_y(v[4]) * rot_x(v[3]) });
    }
    if goals.is_empty() {
        return Err("no rows after the header".into());
    }
    Ok(goals)
}

/// The goals of the one `measurements_*.csv` file in a series folder.
pub fn read_series_goals(dir: &Path) -> Result<Vec<Goal>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let mut files: Vec<std::path::PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("measurements_") && n.ends_with(".csv"))
        })
        .collect();
    files.sort();
    let [file] = files.as_slice() else {
        return Err(format!("{}: expected exactly one measurements_*.csv file, found {}", dir.display(), files.len()));
    };
    let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
    read_goals(&text).map_err(|e| format!("{}: {e}", file.display()))
}

/// Pose, cycle and approach of every row (see the module documentation).
pub fn assign_poses(goals: &[Goal]) -> Vec<Assignment> {
    let mut poses: Vec<(usize, u32)> = Vec::new(); // (row of the first visit, visits so far)
    let mut out = Vec::with_capacity(goals.len());
    for (i, g) in goals.iter().enumerate() {
        let found = poses.iter().position(|&(first, _)| {
            let f = &goals[first];
            (f.position - g.position).norm() <= SAME_POSITION
                && rotation_angle(&(f.rotation * g.rotation.transpose())) <= SAME_ANGLE
        });
        let k = match found {
            Some(k) => {
                poses[k].1 += 1;
                k
            }
            None => {
                poses.push((i, 1));
                poses.len() - 1
            }
        };
        let approach = (i > 0).then(|| {
            let d = g.position - goals[i - 1].position;
            // base_link → base: x and y negated.
            let d = Vector3::new(-d.x, -d.y, d.z);
            ["x", "y", "z"]
                .iter()
                .enumerate()
                .map(|(a, n)| {
                    let s = if d[a] > MM {
                        "+"
                    } else if d[a] < -MM {
                        "-"
                    } else {
                        "0"
                    };
                    format!("{s}{n}")
                })
                .collect::<String>()
        });
        out.push(Assignment { index: i, pose: format!("D{:03}", k + 1), cycle: poses[k].1, approach });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(x: f64, y: f64, z: f64, yaw: f64) -> String {
        let f = |v: f64| format!("{v}").replace('.', ",");
        format!("x;{};{};{};0;0;{}", f(x), f(y), f(z), f(yaw))
    }

    /// A centre and a corner visited twice, the second time 0.01 mm off and with the yaw written
    /// as −π instead of π (the same rotation): two poses, cycles 1 and 2, approaches from the
    /// moves in the base frame (base_link's x and y negated).
    #[test]
    fn repeated_goals_are_one_pose_and_count_cycles() {
        let pi = std::f64::consts::PI;
        let text = [
            "Timestamp;Goal x;Goal y;Goal z;Goal roll;Goal pitch;Goal yaw".to_string(),
            row(0.1, 0.6, 0.7, pi),
            row(0.3, 0.8, 0.5, pi),
            row(0.10001, 0.6, 0.7, -pi),
            row(0.3, 0.80001, 0.5, pi),
        ]
        .join("\n");
        let a = assign_poses(&read_goals(&text).unwrap());
        let got: Vec<(&str, u32, Option<&str>)> =
            a.iter().map(|a| (a.pose.as_str(), a.cycle, a.approach.as_deref())).collect();
        assert_eq!(
            got,
            vec![
                ("D001", 1, None),
                ("D002", 1, Some("-x-y-z")),
                ("D001", 2, Some("+x+y+z")),
                ("D002", 2, Some("-x-y-z")),
            ]
        );
        assert!(read_goals("Timestamp;Goal x\n1;2").unwrap_err().contains("Goal y"));
        let bad = format!("{}\n{}", "Timestamp;Goal x;Goal y;Goal z;Goal roll;Goal pitch;Goal yaw", "x;a;1;1;1;1;1");
        assert_eq!(read_goals(&bad).unwrap_err(), "line 2: column 'Goal x' is not a number");
    }
}

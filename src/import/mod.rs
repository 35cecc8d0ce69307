//! Converters from real data sets' formats into cells.
//!
//! Each importer reads files in the instrument's or the data set's own units and conventions and
//! produces a [`Cell`] in SI units (metres, radians) that passes the cell-file validation of
//! [`crate::domain::cell`], plus human-readable notes on what was assumed or left out.
//!
//! - [`ur10_ipa`]: the UR10 laser-tracker data set (semicolon CSV with decimal commas, 6D poses).
//! - [`three_reflector`]: a joints file plus one positions file per tracker reflector.
//!
//! Errors name the file, the 1-based line and the column (or joint) of the offending value; no
//! input makes an importer panic.

use std::fmt;
use std::path::{Path, PathBuf};

use crate::cell::Cell;
use crate::kinematics::model::ModelError;

pub mod three_reflector;
pub mod ur10_ipa;

/// An imported cell and the notes an importer wants the user to read (assumptions, data left out,
/// anomalies found in the files).
#[derive(Clone, Debug, PartialEq)]
pub struct Imported {
    pub cell: Cell,
    pub notes: Vec<String>,
}

/// Why a data set could not be imported.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A value that does not parse or is out of range.
    #[error("{} line {line}, column {column}: {reason}", file.display())]
    Value { file: PathBuf, line: u64, column: String, reason: String },
    /// A line whose shape is wrong (number of fields, undecodable text).
    #[error("{} line {line}: {reason}", file.display())]
    Line { file: PathBuf, line: u64, reason: String },
    #[error("{}: no column '{column}' in the header", file.display())]
    MissingColumn { file: PathBuf, column: String },
    #[error("{}: {reason}", file.display())]
    File { file: PathBuf, reason: String },
    #[error("{}: not a 4×4 homogeneous transform: {reason}", file.display())]
    Matrix { file: PathBuf, reason: String },
    /// Line-aligned files that do not hold the same number of poses.
    #[error("{} has {count} poses but {} has {other_count}", file.display(), other.display())]
    PoseCount { file: PathBuf, count: usize, other: PathBuf, other_count: usize },
    #[error("{0}")]
    Input(String),
    #[error("robot model: {0}")]
    Model(#[from] ModelError),
}

impl ImportError {
    fn io(path: &Path, source: std::io::Error) -> Self {
        ImportError::Io { path: path.to_path_buf(), source }
    }

    fn value(file: &Path, line: u64, column: impl fmt::Display, reason: impl Into<String>) -> Self {
        ImportError::Value { file: file.to_path_buf(), line, column: column.to_string(), reason: reason.into() }
    }

    fn line(file: &Path, line: u64, reason: impl Into<String>) -> Self {
        ImportError::Line { file: file.to_path_buf(), line, reason: reason.into() }
    }
}

/// A run imported apart (`run`) added to a cell already written (`into`, read from `into_path`):
/// one cell holding both, so that the second run can be scored against the first's calibration
/// with its base refitted (`crossval --transfer`, `diagnose --transfer`). The robot model must be
/// the cell's, and no session name may be taken (a three-reflector run is then imported under
/// another name, `import_run`'s `name`).
///
/// A tracker moved between the runs puts the run in another frame, which a cell's single base
/// cannot serve: each run is registered on the nominal robot (base and reflectors alternating,
/// as the identification starts), and the note says whether the run's base lies in another frame
/// than the cell's first session (beyond 50 mm or 2°, against the few millimetres a nominal model
/// misses by) and so must be scored with its base refitted, not identified with it.
pub fn merge(into: Cell, into_path: &Path, run: Imported) -> Result<Imported, ImportError> {
    let file = || into_path.to_path_buf();
    if into.model != run.cell.model {
        return Err(ImportError::File {
            file: file(),
            reason: "its robot model differs from the one the run was imported with (--robot): a cell holds one robot's runs".into(),
        });
    }
    let taken: Vec<&str> = run
        .cell
        .sessions
        .iter()
        .map(|s| s.name.as_str())
        .filter(|n| into.sessions.iter().any(|s| s.name == *n))
        .collect();
    if !taken.is_empty() {
        return Err(ImportError::File {
            file: file(),
            reason: format!(
                "it already holds session(s) {}: import the run under another name (--name day2 gives day2-1, day2-2, …)",
                taken.join(", ")
            ),
        });
    }
    let names: Vec<String> = run.cell.sessions.iter().map(|s| s.name.clone()).collect();
    let names = names.join(", ");
    let mut notes = run.notes;
    let first = into.sessions.first().map(|s| s.name.clone());
    let frame = |sessions: &[crate::cell::Session]| {
        let cell = Cell { model: into.model.clone(), base_guess: None, artefact: None, sessions: sessions.to_vec() };
        registered_base(&cell)
    };
    let note = match (
        &first,
        into.sessions.first().and_then(|s| frame(std::slice::from_ref(s))),
        frame(&run.cell.sessions),
    ) {
        (None, _, _) => format!("{names}: merged into {}, which held no session", into_path.display()),
        (Some(first), Some(a), Some(b)) => {
            let (d, angle) = a.distance(&b);
            let (mm, deg) = (d / crate::units::MM, angle / crate::units::DEG);
            if d > 0.05 || angle > 2.0 * crate::units::DEG {
                format!(
                    "{names}: merged into {}; measured in another tracker frame than {first} (the robot base registers {mm:.0} mm and {deg:.1}° apart on the nominal robot): score the run with its base refitted (`crossval --transfer {}`, `diagnose --transfer {}`, or `identify --start … --only base,tool`), and do not identify it together with {first}",
                    into_path.display(),
                    names.replace(", ", ","),
                    names.replace(", ", ",")
                )
            } else {
                format!(
                    "{names}: merged into {}; the robot base registers {mm:.1} mm and {deg:.2}° from {first}'s on the nominal robot, within what a nominal model misses by (50 mm, 2°): no move of the tracker that these registrations can see (a smaller one shows in a joint fit's residual; `crossval --transfer` scores the run with its own base either way)",
                    into_path.display()
                )
            }
        }
        (Some(first), _, _) => format!(
            "{names}: merged into {}; whether it shares {first}'s tracker frame is not known (a registration on the nominal robot failed): score it with its base refitted (`crossval --transfer`)",
            into_path.display()
        ),
    };
    notes.push(note);
    let mut sessions = into.sessions;
    sessions.extend(run.cell.sessions);
    Ok(Imported {
        cell: Cell { model: into.model, base_guess: into.base_guess, artefact: into.artefact, sessions },
        notes,
    })
}

/// The sessions of run `run` in `cell` (`{run}-1`, `{run}-2`, …) measured the same reflectors as
/// those of run `plate` (`{plate}-1`, …): one plate, not remounted between the runs. Each pair
/// then names one `target`, so a fit's TCP for the plate's reflector applies to the run's (a
/// validation of the first run's set on the second run is scored with the TCPs it fitted), and the
/// run's sessions declare the plate's tool (one plate: its payload and centre of mass; sessions
/// sharing a target declare one tool). A plate session without a target gets its own name as
/// one. Returns the plate's sessions given a target (cell indices, the target), which a caller
/// that keeps the cell's text writes in. Refused: the run named as its own plate, a run or plate
/// without sessions of those names, runs of different numbers of reflectors, and a payload mass
/// declared for the run (not 0 kg, the unknown payload) that differs from the plate's.
pub fn share_plate(cell: &mut Cell, run: &str, plate: &str) -> Result<Vec<(usize, String)>, ImportError> {
    let input = |reason: String| Err(ImportError::Input(reason));
    if run == plate {
        return input(format!("{plate} is the run being imported"));
    }
    let numbered = |name: &str| -> Vec<usize> {
        (1..).map_while(|k| cell.sessions.iter().position(|s| s.name == format!("{name}-{k}"))).collect()
    };
    let (ours, theirs) = (numbered(run), numbered(plate));
    if theirs.is_empty() {
        // The cell's own sessions: the run's were appended to it under the run's name.
        return input(format!(
            "the cell holds no session {plate}-1 (its sessions: {})",
            cell.sessions
                .iter()
                .enumerate()
                .filter(|(i, _)| !ours.contains(i))
                .map(|(_, s)| s.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if ours.len() != theirs.len() {
        return input(format!(
            "{plate} has {} reflectors and this run {}: one plate's runs measure the same \
             reflectors, in the same order",
            theirs.len(),
            ours.len()
        ));
    }
    let mut given = Vec::new();
    for (&o, &t) in ours.iter().zip(&theirs) {
        let (mass, plate_mass) = (cell.sessions[o].tool.mass, cell.sessions[t].tool.mass);
        if mass != 0.0 && mass != plate_mass {
            return input(format!(
                "this run declares a {mass} kg payload and {} {plate_mass} kg: one plate \
                 carries one payload",
                cell.sessions[t].name
            ));
        }
        let target = match &cell.sessions[t].target {
            Some(name) => name.clone(),
            None => {
                let name = cell.sessions[t].name.clone();
                cell.sessions[t].target = Some(name.clone());
                given.push((t, name.clone()));
                name
            }
        };
        let tool = cell.sessions[t].tool.clone();
        let s = &mut cell.sessions[o];
        s.target = Some(target);
        s.tool = tool;
    }
    Ok(given)
}

/// The robot's base in the measurement frame, registered with every session's reflector or
/// probe on the nominal robot; `None` when it fails.
fn registered_base(cell: &Cell) -> Option<crate::kinematics::frame::Frame> {
    register_nominal(cell).map(|r| crate::kinematics::frame::Frame::from_xyzabc(&r.base))
}

/// Every measurement of `cell` registered on the nominal robot, base and unknown TCPs
/// alternating as the identification starts; `None` when it fails.
fn register_nominal(cell: &Cell) -> Option<crate::identify::base::Registration> {
    use crate::identify::{base::register_base_and_tcps, tool_blocks};
    let picks: Vec<(usize, usize)> =
        cell.sessions.iter().enumerate().flat_map(|(s, x)| (0..x.measurements.len()).map(move |i| (s, i))).collect();
    let (blocks, session_tool) = tool_blocks(cell, &picks);
    register_base_and_tcps(cell, &picks, &blocks, &session_tool, None).ok()
}

/// The whole text of a file.
fn read_text(path: &Path) -> Result<String, ImportError> {
    std::fs::read_to_string(path).map_err(|e| ImportError::io(path, e))
}

/// A run of 1-based line numbers written compactly for notes: `3, 7, 12 and 4 more`.
fn line_list(lines: &[u64]) -> String {
    const SHOWN: usize = 5;
    let head: Vec<String> = lines.iter().take(SHOWN).map(u64::to_string).collect();
    if lines.len() > SHOWN { format!("{} and {} more", head.join(", "), lines.len() - SHOWN) } else { head.join(", ") }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_read_file_line_column_reason() {
        let e = ImportError::value(Path::new("m.csv"), 17, "elbow_joint", "'1,2x' is not a number");
        assert_eq!(e.to_string(), "m.csv line 17, column elbow_joint: '1,2x' is not a number");
        let e = ImportError::PoseCount { file: "a.txt".into(), count: 3, other: "b.txt".into(), other_count: 4 };
        assert_eq!(e.to_string(), "a.txt has 3 poses but b.txt has 4");
    }

    #[test]
    fn line_lists_are_short() {
        assert_eq!(line_list(&[3, 7]), "3, 7");
        assert_eq!(line_list(&[1, 2, 3, 4, 5, 6, 7]), "1, 2, 3, 4, 5 and 2 more");
    }
}

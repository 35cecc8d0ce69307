//! Three-reflector format: a joints file plus one positions file per reflector, for a laser
//! tracker following several reflectors (nests) fixed on the robot's last link.
//!
//! - The **joints file** holds one pose per line: the joint values in **degrees**,
//!   whitespace-separated, as many as the robot has joints.
//! - Each **positions file** holds one line per pose, line-aligned with the joints file:
//!   `x y z` in **mm** in the tracker frame, the position of that file's reflector at that pose.
//!   A line `nan nan nan` (any case) or a single `-` means the reflector was not visible at that
//!   pose: that measurement is skipped for that reflector only. A pose line with no reading in
//!   any file (every reflector hidden, or a row rejected as an outlier and blanked) is still a
//!   stop the robot made: each measurement's `approach` is then written from the joints file's
//!   order with it counted (deleting the line instead leaves the move after it a guess).
//! - In every file, blank lines and lines starting with `#` are comments. They do not count as
//!   poses: pose i is the i-th non-comment line of each file, so all files must hold the same
//!   number of pose lines. A first line without a number in it (`x y z`, `q1,q2,…`) is a column
//!   header, skipped, and the import says so; anywhere else such a line is an error.
//! - Values are separated by whitespace or commas, with a decimal point (`1.5 2 3`, `1.5,2,3`,
//!   `1.5, 2, 3`); or by semicolons, then with a decimal point or a decimal comma (`1,5;2;3`),
//!   as a spreadsheet in a locale with decimal commas writes them.
//!
//! Each reflector becomes one laser-tracker session, `reflector-1`, `reflector-2`, … in the order
//! the files are given, with its measurements in file (measuring) order: the sessions are marked
//! `order: measured`, and each measurement's `sequence` is its pose's index (0-based, among the
//! pose lines), the same in every reflector's session — one stop, one number. Where a reflector sits on
//! the flange is unknown, so its tool has a zero TCP with `identify_tcp` set: the identification
//! gives each reflector a TCP of its own and starts them, and the base, from an alternating
//! registration (`identify::base`). The cell has no base guess and no artefact.
//!
//! The payload (the plate with its reflectors) is what the user declares ([`Payload`]); when it is
//! unknown the tools declare 0 kg, which the identification reads as unknown and estimates, and
//! the import says so. Its centre of mass is the reflectors' centroid unless declared.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::{ImportError, Imported, line_list, read_text};
use crate::cell::{Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session};
use crate::kinematics::{RobotModel, Tool};
use crate::units::{DEG, MM};

/// What the reflectors' plate weighs, as far as the user knows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Payload {
    /// Not known (the files carry none): the tools declare 0 kg, which the identification takes
    /// as unknown and estimates when its model has compliance
    /// ([`crate::identify::IdentifyOptions::identify_payload`]).
    Unknown,
    /// Known mass (kg) and, when known, centre of mass in the flange frame (m).
    Declared { mass_kg: f64, com: Option<Vector3<f64>> },
}

/// Import a joints file and one positions file per reflector for `model`, every session with
/// `purpose`, the payload unknown.
pub fn import(
    joints: &Path,
    positions: &[PathBuf],
    model: RobotModel,
    purpose: Purpose,
) -> Result<Imported, ImportError> {
    import_with_payload(joints, positions, model, purpose, Payload::Unknown)
}

/// The sessions' name unless another is given: `reflector-1`, `reflector-2`, …
pub const DEFAULT_NAME: &str = "reflector";

/// As [`import`], with what is known of the payload. Its centre of mass, when not given, is put
/// at the reflectors' centroid on the flange (a plate carrying them), found by registering the
/// base and the reflectors' positions on the nominal robot (to a millimetre or so: the torques
/// it drives are insensitive to that).
pub fn import_with_payload(
    joints: &Path,
    positions: &[PathBuf],
    model: RobotModel,
    purpose: Purpose,
    payload: Payload,
) -> Result<Imported, ImportError> {
    import_run(joints, positions, model, purpose, payload, DEFAULT_NAME)
}

/// As [`import_with_payload`], the sessions named `{name}-1`, `{name}-2`, … (one per positions
/// file): a second run to be merged into a cell that already holds `reflector-…`
/// ([`super::merge`]). The name is refused when empty or when it holds a comma, whitespace or a
/// control character (commands take session names as comma-separated lists).
pub fn import_run(
    joints: &Path,
    positions: &[PathBuf],
    model: RobotModel,
    purpose: Purpose,
    payload: Payload,
    name: &str,
) -> Result<Imported, ImportError> {
    if name.is_empty() || name.len() > 100 || name.chars().any(|c| c == ',' || c.is_whitespace() || c.is_control()) {
        return Err(ImportError::Input(format!(
            "session name {name:?}: give 1–100 characters without commas, spaces or control characters (sessions are named {name}-1, {name}-2, …)"
        )));
    }
    if let Payload::Declared { mass_kg, com } = payload {
        if !(mass_kg.is_finite() && (0.0..=1000.0).contains(&mass_kg)) {
            return Err(ImportError::Input(format!("payload mass must be 0–1000 kg, got {mass_kg}")));
        }
        if com.is_some_and(|c| !(c.iter().all(|v| v.is_finite() && v.abs() <= 10.0))) {
            return Err(ImportError::Input(
                "payload centre of mass must be finite and within 10 m of the flange".into(),
            ));
        }
    }
    let mut imported = match read_files(joints, positions, model.clone(), purpose, name) {
        Ok(imported) => imported,
        Err(e) => return Err(convention_beyond_limits(joints, positions, &model, purpose, e)),
    };
    // A unit mistake (joints in radians, positions in metres or inches) is refused here, as
    // identify would refuse it, before a payload centre is registered on it and a cell written.
    // A miss no change of the readings explains (a wrong length in the robot file, readings in a
    // convention further off than the search goes) is imported, and said: it was dropped here,
    // and a Fanuc's sweeps read with five joints in another convention imported silently, then
    // `identify` refused "7 outliers" up to 172 mm.
    let note = crate::identify::check_readings(&imported.cell).map_err(|e| ImportError::Input(e.to_string()))?;
    imported.notes.extend(note);
    let (mass, com) = match payload {
        Payload::Unknown => (0.0, None),
        Payload::Declared { mass_kg, com } => (mass_kg, com),
    };
    let com = match com {
        Some(c) => Some((c, "as declared")),
        None => reflector_centroid(&imported.cell)
            .map(|c| (c, "at the reflectors' centroid, from a registration on the nominal robot")),
    };
    for s in &mut imported.cell.sessions {
        s.tool.mass = mass;
        if let Some((c, _)) = com {
            s.tool.com = c;
        }
    }
    let at = match com {
        Some((c, how)) => format!("({:.1}, {:.1}, {:.1}) mm in the flange frame, {how}", c.x / MM, c.y / MM, c.z / MM),
        None => "the flange origin (the registration failed)".into(),
    };
    imported.notes.push(match payload {
        Payload::Unknown => format!(
            "payload unknown (the files carry none): the tools declare 0 kg with the centre of mass at {at}; an identification with compliance estimates the mass (tool_mass), or give it (--payload-kg)"
        ),
        Payload::Declared { .. } => format!("payload {mass} kg, centre of mass at {at}"),
    });
    Ok(imported)
}

/// A file refused (`e`) that reads with the robot's limits opened, and whose readings then follow
/// another convention than the robot model (`identify::convention`): the refusal adds the change
/// that explains them, since a joint counted from another zero is what most often puts readings
/// beyond a joint's limits. Any other refusal is returned as it is.
fn convention_beyond_limits(
    joints: &Path,
    positions: &[PathBuf],
    model: &RobotModel,
    purpose: Purpose,
    e: ImportError,
) -> ImportError {
    let mut opened = model.clone();
    for l in &mut opened.links {
        l.limits = [-720.0 * DEG, 720.0 * DEG];
    }
    let Ok(read) = read_files(joints, positions, opened, purpose, DEFAULT_NAME) else { return e };
    match crate::identify::check_readings(&read.cell) {
        Err(c @ crate::identify::IdentifyError::JointConvention { .. }) => {
            let c = c.to_string();
            let mut first = c.chars();
            let c = first.next().map(|f| f.to_uppercase().collect::<String>() + first.as_str()).unwrap_or(c);
            ImportError::Input(format!("{e}. {c}"))
        }
        _ => e,
    }
}

/// The centroid of the reflectors' positions on the flange, from the alternating registration
/// of the base and the TCPs on the nominal robot; `None` when it fails.
fn reflector_centroid(cell: &Cell) -> Option<Vector3<f64>> {
    let r = super::register_nominal(cell)?;
    let n = r.tcps.len();
    (n > 0).then(|| r.tcps.iter().map(|t| Vector3::new(t[0], t[1], t[2])).sum::<Vector3<f64>>() / n as f64)
}

/// The files as sessions (payload not yet set).
fn read_files(
    joints: &Path,
    positions: &[PathBuf],
    model: RobotModel,
    purpose: Purpose,
    name: &str,
) -> Result<Imported, ImportError> {
    model.validate()?;
    if positions.is_empty() {
        return Err(ImportError::Input("give at least one reflector positions file".into()));
    }
    let joint_text = read_text(joints)?;
    let (joint_lines, joint_header) = without_header(pose_lines(&joint_text));
    let poses: Vec<Vec<f64>> =
        joint_lines.iter().map(|(line, text)| joint_values(joints, *line, text, &model)).collect::<Result<_, _>>()?;

    let mut notes = vec![format!(
        "{} poses of {} joints from {}, {} reflector file(s)",
        poses.len(),
        model.dof(),
        joints.display(),
        positions.len()
    )];
    notes.extend(joint_header.map(|h| header_note(joints, h)));
    let mut sessions = Vec::with_capacity(positions.len());
    // Every pose line's readings, bit for bit, for the copies check below.
    let mut readings: Vec<Vec<Option<[u64; 3]>>> = vec![Vec::new(); poses.len()];
    for (k, path) in positions.iter().enumerate() {
        let name = format!("{name}-{}", k + 1);
        let text = read_text(path)?;
        let (lines, header) = without_header(pose_lines(&text));
        notes.extend(header.map(|h| header_note(path, h)));
        if lines.len() != poses.len() {
            return Err(ImportError::PoseCount {
                file: joints.to_path_buf(),
                count: poses.len(),
                other: path.clone(),
                other_count: lines.len(),
            });
        }
        let mut measurements = Vec::with_capacity(lines.len());
        let (mut hidden, mut zeros) = (Vec::new(), Vec::new());
        for (pose, ((line, text), q)) in lines.iter().zip(&poses).enumerate() {
            let read = position(path, *line, text)?;
            readings[pose].push(read.map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]));
            match read {
                None => hidden.push(*line),
                Some(p) => {
                    if p == Vector3::zeros() {
                        zeros.push(*line);
                    }
                    measurements.push(Measurement {
                        q: q.clone(),
                        observation: Observation::Position(p),
                        temperature_c: None,
                        time_s: None,
                        sequence: Some(pose as u64),
                        approach: None,
                        indicators: None,
                        sigma: None,
                    })
                }
            }
        }
        let mut note = format!("{name}: {} measurements from {}", measurements.len(), path.display());
        if !hidden.is_empty() {
            note.push_str(&format!(
                "; not visible at {} pose(s) (line(s) {}), skipped",
                hidden.len(),
                line_list(&hidden)
            ));
        }
        // A reflector at the instrument's own origin cannot be measured: zeros are what some
        // exports write for a reading not taken. Read as written (the fit then refuses them as
        // outliers metres off), and said here, where the remedy is.
        if !zeros.is_empty() {
            note.push_str(&format!(
                "; {} line(s) read exactly 0 0 0, the instrument's own origin (line(s) {}): if the instrument writes zeros for a reading it did not take, write `nan nan nan` there",
                zeros.len(),
                line_list(&zeros)
            ));
        }
        notes.push(note);
        sessions.push(Session {
            name,
            purpose,
            instrument: Instrument::LaserTracker,
            tool: Tool::flange(),
            identify_tcp: true,
            target: None,
            measurements,
            order: MeasuringOrder::Measured,
        });
    }
    // Nothing measured is nothing to calibrate: refused here, where the files are named, rather
    // than written as a cell that every later command refuses.
    if poses.is_empty() {
        return Err(ImportError::Input(format!("{}: no pose lines (only comments or blank lines)", joints.display())));
    }
    if sessions.iter().all(|s| s.measurements.is_empty()) {
        let files: Vec<String> = positions.iter().map(|p| p.display().to_string()).collect();
        return Err(ImportError::Input(format!(
            "no reflector was visible at any of the {} poses: every line of {} reads `nan nan nan` or `-`, so there is nothing to calibrate (check that these are the run's positions files)",
            poses.len(),
            files.join(", ")
        )));
    }
    notes.extend(copied_lines(&poses, &readings, &joint_lines));
    notes.extend(approach_through_unread_stops(&mut sessions, &poses, &joint_lines));
    Ok(Imported { cell: Cell { model, base_guess: None, artefact: None, sessions }, notes })
}

/// Pose lines equal, bit for bit, to an earlier one in the joints file and in every positions file
/// (with a reading there): a line copied, not a stop measured again — a second measurement of a
/// stop differs by the instrument's noise. The public FANUC run has one (its rows 36 and 37). It
/// is imported as written, and said: the copy weighs twice in every fit, the drift test counts it
/// once. `None` without copies.
fn copied_lines(poses: &[Vec<f64>], readings: &[Vec<Option<[u64; 3]>>], lines: &[PoseLine<'_>]) -> Option<String> {
    /// A pose line's joints and readings, bit for bit.
    type Line<'a> = (Vec<u64>, &'a [Option<[u64; 3]>]);
    let mut first: std::collections::HashMap<Line<'_>, usize> = Default::default();
    let mut copies = Vec::new();
    for (k, (q, r)) in poses.iter().zip(readings).enumerate() {
        if r.iter().all(Option::is_none) {
            continue;
        }
        let key = (q.iter().map(|v| v.to_bits()).collect(), r.as_slice());
        match first.get(&key) {
            Some(&was) => copies.push(format!("{} (as {})", lines[k].0, lines[was].0)),
            None => {
                first.insert(key, k);
            }
        }
    }
    (!copies.is_empty()).then(|| {
        format!(
            "{} pose line(s) repeat an earlier one exactly, joints and every reflector's position: line(s) {}. A stop measured again differs by the instrument's noise; a copied line weighs twice in every fit: delete it if it is a copy",
            copies.len(),
            copies.join(", ")
        )
    })
}

/// Where some pose lines have no reading in any file (every reflector hidden, or the row's
/// positions blanked as an outlier), the robot still stopped there: the move into the next
/// stop started from it, which the measurements alone cannot tell (a derivation from them
/// would take the move from the stop before, wrong for about a third of the joints). So the
/// import writes every measurement's `approach` from the joints file's order, every pose line
/// counted, and says so. Without such lines the measurements are every stop and the
/// derivation from their `sequence` gives the same directions: nothing is written.
fn approach_through_unread_stops(
    sessions: &mut [Session],
    poses: &[Vec<f64>],
    lines: &[PoseLine<'_>],
) -> Option<String> {
    let mut read = vec![false; poses.len()];
    for m in sessions.iter().flat_map(|s| &s.measurements) {
        if let Some(k) = m.sequence.and_then(|n| usize::try_from(n).ok()).filter(|&k| k < read.len()) {
            read[k] = true;
        }
    }
    let unread: Vec<u64> = read.iter().zip(lines).filter(|(r, _)| !**r).map(|(_, (line, _))| *line).collect();
    if unread.is_empty() || unread.len() == poses.len() {
        return None;
    }
    let dirs = crate::cell::order::directions(poses.iter().map(Vec::as_slice));
    for m in sessions.iter_mut().flat_map(|s| &mut s.measurements) {
        m.approach = m.sequence.and_then(|n| dirs.get(usize::try_from(n).ok()?)).cloned();
    }
    Some(format!(
        "{} pose(s) without a reading in any file (line(s) {} of the joints file): the robot stopped there all the same, so each measurement's approach (the direction of each joint's move into its stop, what backlash depends on) is written from the joints file's order with those stops counted",
        unread.len(),
        line_list(&unread)
    ))
}

/// A line of a file: its 1-based number and its text, trimmed.
type PoseLine<'a> = (u64, &'a str);

/// The pose lines of a file with their 1-based line numbers: comments (`#`) and blank lines out,
/// and the byte-order mark a spreadsheet writes before the first line.
fn pose_lines(text: &str) -> Vec<PoseLine<'_>> {
    text.strip_prefix('\u{feff}')
        .unwrap_or(text)
        .lines()
        .enumerate()
        .map(|(i, l)| (i as u64 + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .collect()
}

/// The first pose line when it is a column header — no field of it reads as a number and one
/// holds a letter (so `-`, a hidden reflector, is not one) — split off the pose lines.
fn without_header(mut lines: Vec<PoseLine<'_>>) -> (Vec<PoseLine<'_>>, Option<PoseLine<'_>>) {
    let header = lines.first().is_some_and(|(_, text)| {
        let fields = fields(text);
        fields.iter().all(|f| number(f).is_err() && !f.eq_ignore_ascii_case("nan"))
            && fields.iter().any(|f| f.chars().any(char::is_alphabetic))
    });
    if header { (lines.split_off(1), Some(lines[0])) } else { (lines, None) }
}

fn header_note(path: &Path, (line, text): PoseLine<'_>) -> String {
    format!("{} line {line} read as a column header and skipped: {text}", path.display())
}

/// The values of a pose line: separated by semicolons (each may use a decimal comma), else by
/// whitespace and commas.
fn fields(text: &str) -> Vec<String> {
    if text.contains(';') {
        text.split(';').map(|f| f.trim().replace(',', ".")).filter(|f| !f.is_empty()).collect()
    } else {
        text.split(|c: char| c.is_whitespace() || c == ',').filter(|f| !f.is_empty()).map(str::to_owned).collect()
    }
}

/// When a line holds a comma between two digits and no semicolon: a hint that its commas may be
/// decimal commas (read here as separators).
fn comma_hint(text: &str) -> String {
    let b = text.as_bytes();
    let decimal_comma =
        (1..b.len().saturating_sub(1)).any(|i| b[i] == b',' && b[i - 1].is_ascii_digit() && b[i + 1].is_ascii_digit());
    if decimal_comma && !text.contains(';') {
        format!(
            " (read as decimal commas, {}: write a decimal point, or separate the values by semicolons)",
            text.split_whitespace().count()
        )
    } else {
        String::new()
    }
}

/// Why a line may hold another count of values than `expected`: decimal commas read as
/// separators ([`comma_hint`]), else one value too many whose first reads as a whole number — a
/// line or point number (a spreadsheet's index column), which the files do not hold.
fn count_hint(text: &str, fields: &[String], expected: usize) -> String {
    let commas = comma_hint(text);
    let counter = fields.first().is_some_and(|f| !f.is_empty() && f.bytes().all(|b| b.is_ascii_digit()));
    if commas.is_empty() && fields.len() == expected + 1 && counter {
        format!(
            " (the first, {}, reads as a line or point number: the file holds the values alone, so remove that column)",
            fields[0]
        )
    } else {
        commas
    }
}

/// A finite number written with a decimal point.
fn number(field: &str) -> Result<f64, String> {
    match field.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("'{field}' is not a finite number")),
        Err(_) => Err(format!("'{field}' is not a number")),
    }
}

/// One joints line → q in rad, within the robot's limits.
fn joint_values(path: &Path, line: u64, text: &str, model: &RobotModel) -> Result<Vec<f64>, ImportError> {
    let fields = fields(text);
    if fields.len() != model.dof() {
        return Err(ImportError::line(
            path,
            line,
            format!(
                "expected {} joint values, got {}{}",
                model.dof(),
                fields.len(),
                count_hint(text, &fields, model.dof())
            ),
        ));
    }
    let mut q = Vec::with_capacity(fields.len());
    for (j, f) in fields.iter().enumerate() {
        let column = format!("joint {}", j + 1);
        let deg = number(f).map_err(|reason| ImportError::value(path, line, &column, reason))?;
        let rad = deg * DEG;
        if !model.within_limits(j, rad) {
            let [lo, hi] = model.links[j].limits;
            return Err(ImportError::value(
                path,
                line,
                &column,
                format!("{deg}° is outside joint {}'s limits [{:.1}°, {:.1}°]", j + 1, lo / DEG, hi / DEG),
            ));
        }
        q.push(rad);
    }
    Ok(q)
}

/// One positions line → the reflector position in m, or `None` when it was not visible.
fn position(path: &Path, line: u64, text: &str) -> Result<Option<Vector3<f64>>, ImportError> {
    let fields = fields(text);
    if fields == ["-"] || (fields.len() == 3 && fields.iter().all(|f| f.eq_ignore_ascii_case("nan"))) {
        return Ok(None);
    }
    if fields.len() != 3 {
        return Err(ImportError::line(
            path,
            line,
            format!(
                "expected x y z (3 values, or `nan nan nan` / `-` when not visible), got {}{}",
                fields.len(),
                count_hint(text, &fields, 3)
            ),
        ));
    }
    let mut p = [0.0; 3];
    for (i, (f, axis)) in fields.iter().zip(["x", "y", "z"]).enumerate() {
        p[i] = number(f).map_err(|reason| ImportError::value(path, line, axis, reason))?;
    }
    Ok(Some(Vector3::from(p) * MM))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::model::irb120;
    use proptest::prelude::*;

    /// A scratch directory of this test process for the files a test imports, removed when dropped.
    struct Scratch(PathBuf);

    impl Scratch {
        fn new(tag: &str) -> Self {
            let dir = std::env::temp_dir().join(format!("robocal-3r-{tag}-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            Scratch(dir)
        }

        /// Write `text` to the file `name` in it; its path.
        fn write(&self, name: &str, text: &str) -> PathBuf {
            let path = self.0.join(name);
            std::fs::write(&path, text).unwrap();
            path
        }
    }

    impl Drop for Scratch {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    proptest! {
        /// Positions printed in mm with full precision come back exactly, in metres.
        #[test]
        fn positions_read_back(p in prop::array::uniform3(-5e3_f64..5e3)) {
            let line = format!("{}\t{} {}", p[0], p[1], p[2]);
            let back = position(Path::new("r.txt"), 1, &line).unwrap().unwrap();
            prop_assert_eq!(back, Vector3::from(p) * MM);
        }

        /// Arbitrary lines give a value or an error, never a panic.
        #[test]
        fn arbitrary_lines_never_panic(line in "\\PC{0,40}") {
            let _ = position(Path::new("r.txt"), 1, &line);
            let _ = joint_values(Path::new("j.txt"), 1, &line, &irb120());
        }
    }

    #[test]
    fn comments_and_blank_lines_are_not_poses() {
        let lines = pose_lines("# header\n\n1 2 3\r\n  # indented comment\n   \n4 5 6\n");
        assert_eq!(lines, vec![(3, "1 2 3"), (6, "4 5 6")]);
        // A byte-order mark before a comment leaves it a comment (it read as a column header).
        assert_eq!(pose_lines("\u{feff}# x y z, mm\r\n1 2 3\r\n"), vec![(2, "1 2 3")]);
    }

    #[test]
    fn an_index_column_is_named() {
        let e = joint_values(Path::new("j.txt"), 2, "1 11.5 -14.1 -23.7 -158.4 -12.6 -38.1", &irb120())
            .unwrap_err()
            .to_string();
        assert!(e.contains("expected 6 joint values, got 7 (the first, 1, reads as a line or point number"), "{e}");
        let e = position(Path::new("r.txt"), 2, "17;1742,8;-1070,9;320,4").unwrap_err().to_string();
        assert!(e.contains("got 4 (the first, 17, reads as a line or point number"), "{e}");
        // A value too many whose first has a decimal point: no such hint.
        let e = position(Path::new("r.txt"), 2, "1742.8 -1070.9 320.4 0.02").unwrap_err().to_string();
        assert!(!e.contains("line or point number"), "{e}");
    }

    #[test]
    fn hidden_reflectors_and_bad_positions() {
        let p = Path::new("r1.txt");
        assert_eq!(position(p, 1, "nan nan nan").unwrap(), None);
        assert_eq!(position(p, 1, "NaN NAN nan").unwrap(), None);
        assert_eq!(position(p, 1, "-").unwrap(), None);
        assert_eq!(position(p, 1, "1000 -250.5 3e2").unwrap(), Some(Vector3::new(1.0, -0.2505, 0.3)));
        let e = position(p, 4, "1 nan 3").unwrap_err();
        assert_eq!(e.to_string(), "r1.txt line 4, column y: 'nan' is not a finite number");
        let e = position(p, 5, "1,5 2,25 3,75").unwrap_err();
        assert_eq!(
            e.to_string(),
            "r1.txt line 5: expected x y z (3 values, or `nan nan nan` / `-` when not visible), got 6 (read as decimal commas, 3: write a decimal point, or separate the values by semicolons)"
        );
        let e = position(p, 5, "1.5;2;x").unwrap_err();
        assert_eq!(e.to_string(), "r1.txt line 5, column z: 'x' is not a number");
        let e = position(p, 6, "1 2").unwrap_err();
        assert!(e.to_string().starts_with("r1.txt line 6: expected x y z"), "{e}");
    }

    /// A run in which no reflector was ever seen, or a joints file without poses, is refused by
    /// name rather than written as an empty cell; one hidden reflector among visible ones is a
    /// session skipped, as before.
    #[test]
    fn a_run_with_nothing_measured_is_refused() {
        let dir = Scratch::new("empty");
        let write = |name: &str, text: &str| dir.write(name, text);
        let joints = write("j.txt", "0 10 20 0 30 0\n5 -10 15 20 -30 40\n");
        let hidden = write("r1.txt", "nan nan nan\n-\n");
        let hidden2 = write("r2.txt", "# x y z\nNaN NaN NaN\nnan nan nan\n");
        let seen = write("r3.txt", "700 0 500\n650 -40 520\n");
        let e = import(&joints, &[hidden.clone(), hidden2.clone()], irb120(), Purpose::Identification)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no reflector was visible at any of the 2 poses"), "{e}");
        assert!(e.contains("r1.txt") && e.contains("r2.txt"), "{e}");
        let empty = write("j0.txt", "# joints (deg)\n\n");
        let e = import(&empty, &[write("r0.txt", "# nothing\n")], irb120(), Purpose::Identification)
            .unwrap_err()
            .to_string();
        assert!(e.contains("j0.txt: no pose lines"), "{e}");
        let ok = import(&joints, &[hidden, seen], irb120(), Purpose::Identification).unwrap();
        assert_eq!(ok.cell.sessions.iter().map(|s| s.measurements.len()).collect::<Vec<_>>(), vec![0, 2]);
    }

    /// Whitespace, commas, or semicolons with decimal commas: the same position.
    #[test]
    fn separators_of_the_usual_exports_read_the_same() {
        let p = Path::new("r1.txt");
        let want = Some(Vector3::new(1.0, -0.2505, 0.3));
        for line in [
            "1000 -250.5 3e2",
            "1000\t-250.5\t300",
            "1000,-250.5,300",
            "1000, -250.5, 300",
            "1000;-250,5;300",
            "1000 ; -250.5 ; 300",
        ] {
            assert_eq!(position(p, 1, line).unwrap(), want, "{line}");
        }
        assert_eq!(position(p, 1, "nan,nan,nan").unwrap(), None);
        assert_eq!(position(p, 1, "NaN;NaN;NaN").unwrap(), None);
        let q = joint_values(Path::new("j.txt"), 1, "10,-20.5,30,0,45,-90", &irb120()).unwrap();
        let r = joint_values(Path::new("j.txt"), 1, "10;-20,5;30;0;45;-90", &irb120()).unwrap();
        assert_eq!(q, r);
        assert!((q[1] - (-20.5 * DEG)).abs() < 1e-15);
    }

    /// A first line of labels is a header; a hidden reflector's `-` or `nan` line and a line of
    /// numbers are not; only the first pose line can be one.
    #[test]
    fn a_first_line_of_labels_is_a_header() {
        for text in ["x y z\n1 2 3\n", "# c\nX [mm],Y [mm],Z [mm]\n1,2,3\n", "q1;q2;q3;q4;q5;q6\n1;2;3;4;5;6\n"] {
            let (lines, header) = without_header(pose_lines(text));
            assert!(header.is_some(), "{text}");
            assert_eq!(lines.len(), 1, "{text}");
        }
        for text in ["-\n1 2 3\n", "nan nan nan\n1 2 3\n", "1 2 3\nx y z\n", "1 2 y\n"] {
            let (lines, header) = without_header(pose_lines(text));
            assert!(header.is_none(), "{text}");
            assert_eq!(lines.len(), text.lines().count(), "{text}");
        }
    }

    /// Files with headers and commas import as the same files without them, and the import says
    /// which lines it read as headers.
    #[test]
    fn headers_are_skipped_and_said() {
        let dir = Scratch::new("labels");
        let write = |name: &str, text: &str| dir.write(name, text);
        let joints = [[0.0, 10.0, 20.0, 30.0, 40.0, 50.0], [5.0, -10.0, 25.0, -30.0, 45.0, 60.0]];
        let plain_j = joints.iter().map(|q| q.map(|v| v.to_string()).join(" ") + "\n").collect::<String>();
        let comma_j = "J1,J2,J3,J4,J5,J6\n".to_owned()
            + &joints.iter().map(|q| q.map(|v| v.to_string()).join(",") + "\n").collect::<String>();
        let plain = read_files(
            &write("j.txt", &plain_j),
            &[write("r.txt", "500 20 300\n-\n")],
            irb120(),
            Purpose::Identification,
            DEFAULT_NAME,
        )
        .unwrap();
        let headed = read_files(
            &write("jh.csv", &comma_j),
            &[write("rh.csv", "X;Y;Z\n500;20;300\nnan;nan;nan\n")],
            irb120(),
            Purpose::Identification,
            DEFAULT_NAME,
        )
        .unwrap();
        let (a, b) = (&plain.cell.sessions[0].measurements, &headed.cell.sessions[0].measurements);
        assert_eq!(a.len(), 1);
        assert_eq!((&a[0].q, a[0].sequence), (&b[0].q, b[0].sequence));
        assert_eq!(format!("{:?}", a[0].observation), format!("{:?}", b[0].observation));
        let notes = headed.notes.join("\n");
        assert!(notes.contains("jh.csv line 1 read as a column header and skipped: J1,J2,J3,J4,J5,J6"), "{notes}");
        assert!(notes.contains("rh.csv line 1 read as a column header and skipped: X;Y;Z"), "{notes}");
        assert!(!plain.notes.join("\n").contains("header"), "{:?}", plain.notes);
        assert!(!plain.notes.join("\n").contains("0 0 0"), "{:?}", plain.notes);
        // Zeros where a reading was not taken: read as written, said with their lines.
        let zeros = read_files(
            &write("jz.txt", &plain_j),
            &[write("rz.txt", "500 20 300\n0.000 0.000 0.000\n")],
            irb120(),
            Purpose::Identification,
            DEFAULT_NAME,
        )
        .unwrap();
        assert_eq!(zeros.cell.sessions[0].measurements.len(), 2);
        let notes = zeros.notes.join("\n");
        assert!(notes.contains("1 line(s) read exactly 0 0 0, the instrument's own origin (line(s) 2)"), "{notes}");
    }

    /// A run's session name is refused where the commands could not take it back (they read
    /// session lists split at commas), before any file is read; a good one names every session.
    #[test]
    fn a_runs_name_is_one_the_commands_can_take() {
        let dir = Scratch::new("names");
        let j = dir.write("j.txt", "0 10 20 30 40 50\n5 -10 25 -30 45 60\n");
        let r = [dir.write("r1.txt", "500 20 300\n510 25 310\n"), dir.write("r2.txt", "600 20 300\n610 25 310\n")];
        for bad in ["", "day 2", "day,2", "day\t2"] {
            let e = import_run(&j, &r, irb120(), Purpose::Validation, Payload::Unknown, bad).unwrap_err().to_string();
            assert!(e.contains("without commas, spaces or control characters"), "{bad:?}: {e}");
        }
        let names: Vec<String> = read_files(&j, &r, irb120(), Purpose::Validation, "day2")
            .unwrap()
            .cell
            .sessions
            .iter()
            .map(|s| s.name.clone())
            .collect();
        assert_eq!(names, ["day2-1", "day2-2"]);
    }
}

//! UR10 laser-tracker data set of `../shared/datasets/ur10-ipa` (Landgraf et al., IEEE CASE 2021,
//! MIT licence): a Universal Robots UR10 carrying a Leica T-Mac 6D probe on its flange, measured by
//! a laser tracker.
//!
//! # Files of one series folder (`Series_A` … `Series_D`)
//!
//! - `measurements_*.csv` (exactly one): semicolon-separated with a header row and **decimal
//!   commas** (`0,365141`, `2,78E-05`). Columns are found by name, because their order differs
//!   between series and only series B–D have the tracker's `measurement_std_*` columns:
//!   - `Timestamp`: `yyyymmddhhmmss`, local time. Series B–D went through a spreadsheet that
//!     rewrote it as `2,02011E+13`, losing the time of day. When any timestamp of a file is not a
//!     full 14-digit integer, `time_s` is left unset for the whole session (and a note says so);
//!     otherwise `time_s` is the calendar-exact number of seconds since the first row's
//!     timestamp. Rows stay in file order even where their timestamps do not (series A has
//!     re-measured poses appended at the end), so `time_s` need not increase.
//!   - `shoulder_pan_joint`, `shoulder_lift_joint`, `elbow_joint`, `wrist_1_joint`,
//!     `wrist_2_joint`, `wrist_3_joint`: joint angles in rad, UR convention, which is the `q` of
//!     the [`ur10`] preset directly (zero offsets).
//!   - `measurement_temperature`: °C.
//!   - `measurement_x/y/z`: the probe position in the tracker frame, mm.
//!   - `measurement_rx/ry/rz`: the probe orientation in the tracker frame, degrees, **intrinsic**
//!     XYZ Euler angles: `R = Rx(rx) · Ry(ry) · Rz(rz)`.
//!   - `measurement_std_x/y/z/rx/ry/rz` (series B–D): the tracker's standard deviation of each
//!     reading, carried as the measurement's own σ (`sigma_mm`, and `sigma_rotation_deg` about the
//!     axes of {W}, propagated from the Euler angles'; see [`own_sigma`]).
//!   - Ignored: `Goal x/y/z/roll/pitch/yaw` (the commanded TCP pose, m and rad, extrinsic xyz, in
//!     ROS's `base_link`, which is the UR base frame turned 180° about z).
//! - `Trafo_TM_F_init.txt`: a 4×4 homogeneous matrix in mm, four whitespace-separated lines. Its
//!   translation, about (0, 0.087, −109) mm, shows that it is the **flange pose in a probe
//!   frame**: its inverse puts that frame at (0, 0, +109) mm on the flange's z axis, rotated
//!   ZY'X'' ≈ (+90.05°, 0°, −0.05°). That inverse is the TCP the robot was commanded with: seen
//!   from the flange, the `Goal` poses coincide with it to 0.2° and 1 mm on every row of all four
//!   series. The T-Mac frame whose orientation the tracker reports is that TCP **turned 180° about
//!   its z axis** (x and y opposite): with the tracker-to-base transform fitted to the positions
//!   alone, the measured orientations place the probe at ≈ −90° about the flange's z axis, not
//!   +90°, every row within 0.35° of the others. The tool's TCP (T_T^6, the observed frame in the
//!   flange frame) is therefore `inverse(file) · Rz(180°)`: the same position, x and y flipped,
//!   ZY'X'' ≈ (−89.95°, 0°, +0.05°). The file's rotation block, rounded to eight decimals, is
//!   projected onto the nearest rotation first. It is only the authors' starting guess, so the
//!   session asks for the TCP to be identified (`identify_tcp`); `tests/suite/import.rs` checks all of
//!   this on the data.
//! - `Trafo_TM_F_init_calib.txt` and `calibration_handeye.csv` are not read.
//!
//! Each row becomes one [`Measurement`] whose observation is the full probe pose in the tracker
//! frame (`Observation::Pose`), with the temperature, `time_s` as above, and `sequence` = the row's
//! place in the file (0-based): the files are the measuring program's logs, so the session is
//! marked `order: measured`. Where the timestamps survive they are the better record of when
//! (series A's appended rows), and the approach directions go by them. The cell uses the
//! [`ur10`] preset with no base guess: the tracker frame is metres away from the robot and rotated
//! arbitrarily, so the base transform has to be identified from scratch.

use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Matrix4, Vector3};

use super::{ImportError, Imported, line_list, read_text};
use crate::cell::{Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session, Sigma};
use crate::kinematics::Frame;
use crate::kinematics::frame::{rot_x, rot_y, rot_z};
use crate::kinematics::model::{RobotModel, Tool, ur10};
use crate::units::{DEG, MM};

/// The file holding the initial probe transform in every series folder.
pub const PROBE_TRANSFORM_FILE: &str = "Trafo_TM_F_init.txt";

/// The joint columns, in joint order.
pub const JOINT_COLUMNS: [&str; 6] =
    ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"];
const TIME_COLUMN: &str = "Timestamp";
const TEMPERATURE_COLUMN: &str = "measurement_temperature";
const POSITION_COLUMNS: [&str; 3] = ["measurement_x", "measurement_y", "measurement_z"];
const ROTATION_COLUMNS: [&str; 3] = ["measurement_rx", "measurement_ry", "measurement_rz"];
/// The tracker's standard deviations (series B–D): position mm, then rotation deg (of rx, ry, rz).
const STD_COLUMNS: [&str; 6] = [
    "measurement_std_x",
    "measurement_std_y",
    "measurement_std_z",
    "measurement_std_rx",
    "measurement_std_ry",
    "measurement_std_rz",
];

/// How to import a series.
#[derive(Clone, Debug, PartialEq)]
pub struct Ur10Options {
    /// What the session is for ([`import_cell`] takes it per series instead).
    pub purpose: Purpose,
    /// The probe's mass, kg. The data set does not give it, and the gravity-compliance model needs
    /// it: give the real value when compliance is to be identified. Default 0.
    pub tool_mass_kg: f64,
    /// The probe's centre of mass in the flange frame, mm. Default (`None`): at the TCP position.
    pub tool_com_mm: Option<[f64; 3]>,
}

impl Default for Ur10Options {
    fn default() -> Self {
        Self { purpose: Purpose::Identification, tool_mass_kg: 0.0, tool_com_mm: None }
    }
}

/// One series folder (e.g. `.../Series_C`) → one laser-tracker [`Session`] named after the folder
/// (`series-C`), plus notes on what the import assumed or found.
///
/// The session's tool is the inverse of the folder's [`PROBE_TRANSFORM_FILE`] turned 180° about its
/// z axis (see the module documentation, [`probe_tool`]), with the probe mass and centre of mass of
/// `opts` (see [`Ur10Options::tool_mass_kg`]).
pub fn import_series(dir: &Path, opts: &Ur10Options) -> Result<(Session, Vec<String>), ImportError> {
    let name = session_name(dir);
    let probe_file = dir.join(PROBE_TRANSFORM_FILE);
    let probe = read_probe_transform(&probe_file)?;
    let tool = probe_tool(&probe.frame, opts)?;
    let csv_path = measurements_file(dir)?;
    let model = ur10();
    let rows = read_rows(&csv_path, &model)?;
    let file_name = csv_path.file_name().map_or_else(|| csv_path.display().to_string(), |n| n.to_string_lossy().into());
    if rows.is_empty() {
        return Err(ImportError::File { file: csv_path, reason: "no measurement rows after the header".into() });
    }

    let mut notes = Vec::new();
    let (t_min, t_max) = rows
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| (lo.min(r.temperature), hi.max(r.temperature)));
    notes
        .push(format!("{name}: {} measurements from {file_name}, temperature {t_min:.2} to {t_max:.2} °C", rows.len()));

    let times = session_times(&rows);
    match &times {
        Times::Lost { count, first_line, first_text } => notes.push(format!(
            "{name}: {count} of {} Timestamp values are not full 14-digit yyyymmddhhmmss integers (first at line \
             {first_line}: '{first_text}', digits lost through a spreadsheet): time_s is left unset for the whole session",
            rows.len()
        )),
        Times::Seconds(t) => {
            let span_h = t.iter().fold(0.0_f64, |m, v| m.max(*v)) / 3600.0;
            let mut note = format!("{name}: time_s counts seconds from the first row's Timestamp, up to {span_h:.1} h");
            let back: Vec<u64> = rows.windows(2).zip(t.windows(2)).filter(|(_, w)| w[1] < w[0]).map(|(r, _)| r[1].line).collect();
            if !back.is_empty() {
                note.push_str(&format!(
                    "; {} rows are timestamped earlier than the row before (lines {}): rows are kept in file order, \
                     so time_s does not always increase",
                    back.len(),
                    line_list(&back)
                ));
            }
            notes.push(note);
        }
    }

    let [x, y, z, a, b, c] = tool.tcp;
    notes.push(format!(
        "{name}: tool TCP = inverse of {PROBE_TRANSFORM_FILE} (the commanded TCP) turned 180° about its z axis \
         (the T-Mac frame the tracker reports has x and y opposite to it): ({:.4}, {:.4}, {:.4}) mm, \
         ZY'X'' ({:.4}, {:.4}, {:.4})°, a starting guess to be identified (file rotation re-orthonormalised, \
         defect {:.1e}); probe mass {} kg from the options, not from the data",
        x / MM,
        y / MM,
        z / MM,
        a / DEG,
        b / DEG,
        c / DEG,
        probe.orthogonality_defect,
        tool.mass
    ));
    let with_std = rows.iter().filter(|r| r.std.is_some()).count();
    notes.push(if with_std > 0 {
        format!(
            "{name}: the Goal columns are not carried into the cell; the tracker's standard deviations \
             (measurement_std_*) are, as each measurement's sigma_mm and sigma_rotation_deg ({with_std} rows)"
        )
    } else {
        format!("{name}: the Goal columns are not carried into the cell; no measurement_std_* columns")
    });

    let measurements = rows
        .iter()
        .enumerate()
        .map(|(i, r)| Measurement {
            q: r.q.to_vec(),
            observation: Observation::Pose(Frame::new(
                rot_x(r.rotation_deg[0] * DEG) * rot_y(r.rotation_deg[1] * DEG) * rot_z(r.rotation_deg[2] * DEG),
                Vector3::from(r.position_mm) * MM,
            )),
            temperature_c: Some(r.temperature),
            time_s: match &times {
                Times::Seconds(t) => Some(t[i]),
                Times::Lost { .. } => None,
            },
            sequence: Some(i as u64),
            approach: None,
            indicators: None,
            sigma: r.std.map(|s| own_sigma(&s, &r.rotation_deg)),
        })
        .collect();
    let session = Session {
        name,
        purpose: opts.purpose,
        instrument: Instrument::LaserTracker,
        tool,
        identify_tcp: true,
        target: None,
        measurements,
        order: MeasuringOrder::Measured,
    };
    Ok((session, notes))
}

/// Several series folders, each with its purpose (which overrides `opts.purpose`) → one cell with
/// the [`ur10`] preset, no base guess, no artefact, and one session per folder in the given order.
pub fn import_cell(series: &[(PathBuf, Purpose)], opts: &Ur10Options) -> Result<Imported, ImportError> {
    if series.is_empty() {
        return Err(ImportError::Input("no series folder given".into()));
    }
    let mut sessions: Vec<Session> = Vec::with_capacity(series.len());
    let mut notes = Vec::new();
    for (dir, purpose) in series {
        let (session, mut n) = import_series(dir, &Ur10Options { purpose: *purpose, ..opts.clone() })?;
        if sessions.iter().any(|s| s.name == session.name) {
            return Err(ImportError::Input(format!(
                "two series folders give the session name '{}' (the second is {})",
                session.name,
                dir.display()
            )));
        }
        sessions.push(session);
        notes.append(&mut n);
    }
    notes.extend(frame_notes(&sessions));
    Ok(Imported { cell: Cell { model: ur10(), base_guess: None, artefact: None, sessions }, notes })
}

/// A cell has one world frame, but a tracker moved between measuring days puts each series in its
/// own. Register each session's positions on the nominal model separately and say which
/// sessions' frames differ from the first's by more than a nominal model can explain (50 mm or
/// 2°, against the nominal UR10's few millimetres): those must be scored with their base refitted
/// (`robocal crossval --transfer`, or `identify --start … --only base,tool`), not validated in the
/// first session's frame.
fn frame_notes(sessions: &[Session]) -> Vec<String> {
    use crate::identify::base::estimate_base;
    let frames: Vec<Option<Frame>> = sessions
        .iter()
        .map(|s| {
            let one = Cell { model: ur10(), base_guess: None, artefact: None, sessions: vec![s.clone()] };
            estimate_base(&one).ok().map(|(x, _)| Frame::from_xyzabc(&x))
        })
        .collect();
    let Some(Some(first)) = frames.first() else { return Vec::new() };
    let mut notes = Vec::new();
    for (s, f) in sessions.iter().zip(&frames).skip(1) {
        let Some(f) = f else { continue };
        let (d, angle) = first.distance(f);
        if d > 0.05 || angle > 2.0 * DEG {
            notes.push(format!(
                "{}: measured in another tracker frame than {} (the robot base registers {:.0} mm and {:.1}° apart): \
                 validate it with its base refitted (crossval --transfer, or identify --start … --only base,tool)",
                s.name,
                sessions[0].name,
                d / MM,
                angle / DEG
            ));
        }
    }
    notes
}

/// The transform of a `Trafo_TM_F_init.txt` file (m), with the rotation block projected onto SO(3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ProbeTransform {
    /// The flange pose in the probe frame, T_6^T.
    pub frame: Frame,
    /// max |RᵀR − I| of the rotation block as written in the file.
    pub orthogonality_defect: f64,
}

/// Read a 4×4 homogeneous matrix in mm (four lines of four whitespace-separated numbers; blank
/// lines ignored). The rotation block must be a proper rotation to 1e-6; it is replaced by the
/// nearest rotation (polar decomposition) so that the inverse is exact.
pub fn read_probe_transform(path: &Path) -> Result<ProbeTransform, ImportError> {
    let bad = |reason: String| ImportError::Matrix { file: path.to_path_buf(), reason };
    let text = read_text(path)?;
    let lines: Vec<(usize, &str)> =
        text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty()).collect();
    if lines.len() != 4 {
        return Err(bad(format!("expected 4 lines of 4 numbers, got {} lines", lines.len())));
    }
    let mut m = Matrix4::zeros();
    for (row, (line_no, line)) in lines.iter().enumerate() {
        let fields: Vec<&str> = line.split_whitespace().collect();
        if fields.len() != 4 {
            return Err(bad(format!("line {line_no}: expected 4 numbers, got {}", fields.len())));
        }
        for (col, f) in fields.iter().enumerate() {
            m[(row, col)] = match f.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                _ => return Err(bad(format!("line {line_no}: '{f}' is not a finite number"))),
            };
        }
    }
    let last = [m[(3, 0)], m[(3, 1)], m[(3, 2)], m[(3, 3)]];
    if last.iter().zip([0.0, 0.0, 0.0, 1.0]).any(|(v, w)| (v - w).abs() > 1e-9) {
        return Err(bad(format!("the last row is {last:?}, not [0, 0, 0, 1]")));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let defect = (r.transpose() * r - Matrix3::identity()).abs().max();
    if defect > 1e-6 || r.determinant() <= 0.0 {
        return Err(bad(format!(
            "the 3×3 block is not a rotation (max |RᵀR − I| = {defect:.1e}, det = {:.6})",
            r.determinant()
        )));
    }
    let svd = r.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Err(bad("the 3×3 block could not be decomposed".into()));
    };
    let t = Vector3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]) * MM;
    Ok(ProbeTransform { frame: Frame::new(u * v_t, t), orthogonality_defect: defect })
}

/// The probe as a tool: TCP = the inverse of the flange-in-probe transform of the file turned 180°
/// about its z axis (see the module documentation), payload from `opts`.
pub fn probe_tool(flange_in_probe: &Frame, opts: &Ur10Options) -> Result<Tool, ImportError> {
    let m = opts.tool_mass_kg;
    if !m.is_finite() || m < 0.0 {
        return Err(ImportError::Input(format!("tool mass: {m} kg is not a finite, non-negative mass")));
    }
    let tcp = flange_in_probe.inverse().compose(&Frame::new(rot_z(std::f64::consts::PI), Vector3::zeros())).to_xyzabc();
    let com = match opts.tool_com_mm {
        None => Vector3::new(tcp[0], tcp[1], tcp[2]),
        Some(c) if c.iter().all(|v| v.is_finite()) => Vector3::from(c) * MM,
        Some(c) => return Err(ImportError::Input(format!("tool centre of mass: {c:?} mm is not finite"))),
    };
    Ok(Tool { tcp, mass: m, com })
}

/// `Series_C` → `series-C`; any other folder name is kept as it is.
fn session_name(dir: &Path) -> String {
    let base = match dir.file_name() {
        Some(n) => n.to_string_lossy().into_owned(),
        // `.` or `..`: the folder's real name.
        None => dir
            .canonicalize()
            .ok()
            .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
            .unwrap_or_else(|| dir.display().to_string()),
    };
    match base.strip_prefix("Series_") {
        Some(rest) if !rest.is_empty() => format!("series-{rest}"),
        _ => base,
    }
}

/// The one `measurements_*.csv` of a series folder.
fn measurements_file(dir: &Path) -> Result<PathBuf, ImportError> {
    let entries = std::fs::read_dir(dir).map_err(|e| ImportError::io(dir, e))?;
    let mut found = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| ImportError::io(dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        if name.starts_with("measurements_") && name.ends_with(".csv") {
            found.push(entry.path());
        }
    }
    found.sort();
    match found.len() {
        1 => Ok(found.remove(0)),
        n => Err(ImportError::File {
            file: dir.to_path_buf(),
            reason: format!("expected exactly one measurements_*.csv file, found {n}"),
        }),
    }
}

/// A row's standard deviations as the cell's per-measurement σ: the position's per axis of the
/// tracker frame ({W}), and the rotation's per axis of {W} from those of the intrinsic XYZ Euler
/// angles. With R = Rx(a)·Ry(b)·Rz(c) the world rotation vector moves by δω = E·(δa, δb, δc),
/// E = [x, Rx(a)·y, Rx(a)·Ry(b)·z]; its covariance E·diag(σ²)·Eᵀ (the tracker reports no
/// correlations) has the diagonal taken here.
fn own_sigma(std: &[f64; 6], rotation_deg: &[f64; 3]) -> Sigma {
    let (a, b) = (rotation_deg[0] * DEG, rotation_deg[1] * DEG);
    let e = [Vector3::x(), rot_x(a) * Vector3::y(), rot_x(a) * rot_y(b) * Vector3::z()];
    let rotation =
        std::array::from_fn(|axis| (0..3).map(|k| (e[k][axis] * std[3 + k] * DEG).powi(2)).sum::<f64>().sqrt());
    Sigma { position: [std[0] * MM, std[1] * MM, std[2] * MM], rotation: Some(rotation) }
}

/// One parsed row, in file units except the joints (rad).
struct Row {
    line: u64,
    /// The timestamp in seconds on a continuous calendar scale ([`timestamp`]), or the field's text
    /// when it is not a whole `yyyymmddhhmmss` (digits lost).
    stamp: Result<i64, String>,
    q: [f64; 6],
    temperature: f64,
    position_mm: [f64; 3],
    rotation_deg: [f64; 3],
    /// The tracker's standard deviations (x, y, z mm; rx, ry, rz deg), when the file has them.
    std: Option<[f64; 6]>,
}

/// Column indices of the fields the importer reads.
struct Columns {
    time: usize,
    joints: [usize; 6],
    temperature: usize,
    position: [usize; 3],
    rotation: [usize; 3],
    /// All six standard-deviation columns, or none.
    std: Option<[usize; 6]>,
}

impl Columns {
    fn find(path: &Path, header_line: u64, header: &[&str]) -> Result<Self, ImportError> {
        let find = |name: &str| -> Result<usize, ImportError> {
            let mut hits = header.iter().enumerate().filter(|(_, h)| **h == name).map(|(i, _)| i);
            match (hits.next(), hits.next()) {
                (Some(i), None) => Ok(i),
                (None, _) => Err(ImportError::MissingColumn { file: path.to_path_buf(), column: name.to_string() }),
                (Some(_), Some(_)) => {
                    Err(ImportError::line(path, header_line, format!("column '{name}' appears twice")))
                }
            }
        };
        let three = |names: [&str; 3]| -> Result<[usize; 3], ImportError> {
            Ok([find(names[0])?, find(names[1])?, find(names[2])?])
        };
        let mut joints = [0; 6];
        for (j, name) in JOINT_COLUMNS.iter().enumerate() {
            joints[j] = find(name)?;
        }
        Ok(Self {
            time: find(TIME_COLUMN)?,
            joints,
            temperature: find(TEMPERATURE_COLUMN)?,
            position: three(POSITION_COLUMNS)?,
            rotation: three(ROTATION_COLUMNS)?,
            std: if STD_COLUMNS.iter().any(|c| header.contains(c)) {
                let mut std = [0; 6];
                for (k, name) in STD_COLUMNS.iter().enumerate() {
                    std[k] = find(name)?;
                }
                Some(std)
            } else {
                None
            },
        })
    }
}

/// Parse every data row of a measurements file, checking joints against `model`'s limits and the
/// temperature against the cell format's plausible range. Blank lines are skipped; fields are
/// unquoted (the data set quotes nothing), so a line is split at every `;`.
fn read_rows(path: &Path, model: &RobotModel) -> Result<Vec<Row>, ImportError> {
    let text = read_text(path)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(&text);
    let mut lines = text.lines().enumerate().map(|(i, l)| (i as u64 + 1, l)).filter(|(_, l)| !l.trim().is_empty());
    let Some((header_line, header)) = lines.next() else {
        return Err(ImportError::File { file: path.to_path_buf(), reason: "empty file: no header".into() });
    };
    let header: Vec<&str> = header.split(';').map(str::trim).collect();
    let cols = Columns::find(path, header_line, &header)?;
    let mut rows = Vec::new();
    for (line, text) in lines {
        let fields: Vec<&str> = text.split(';').collect();
        if fields.len() != header.len() {
            return Err(ImportError::line(
                path,
                line,
                format!("{} fields where the header has {}", fields.len(), header.len()),
            ));
        }
        let number = |i: usize| -> Result<f64, ImportError> {
            decimal_comma(fields[i]).map_err(|reason| ImportError::value(path, line, header[i], reason))
        };
        let stamp = timestamp(fields[cols.time])
            .map_err(|reason| ImportError::value(path, line, TIME_COLUMN, reason))?
            .ok_or_else(|| fields[cols.time].trim().to_string());
        let mut q = [0.0; 6];
        for (j, &i) in cols.joints.iter().enumerate() {
            q[j] = number(i)?;
            if !model.within_limits(j, q[j]) {
                let [lo, hi] = model.links[j].limits;
                return Err(ImportError::value(
                    path,
                    line,
                    JOINT_COLUMNS[j],
                    format!("{} rad is outside the joint's limits [{lo:.4}, {hi:.4}] rad", q[j]),
                ));
            }
        }
        let temperature = number(cols.temperature)?;
        if !(-50.0..=150.0).contains(&temperature) {
            return Err(ImportError::value(
                path,
                line,
                TEMPERATURE_COLUMN,
                format!("{temperature} °C is not a plausible robot temperature"),
            ));
        }
        let position_mm = [number(cols.position[0])?, number(cols.position[1])?, number(cols.position[2])?];
        let rotation_deg = [number(cols.rotation[0])?, number(cols.rotation[1])?, number(cols.rotation[2])?];
        let std = match cols.std {
            None => None,
            Some(c) => {
                let mut v = [0.0; 6];
                for k in 0..6 {
                    v[k] = number(c[k])?;
                    if v[k] <= 0.0 {
                        return Err(ImportError::value(
                            path,
                            line,
                            STD_COLUMNS[k],
                            format!("{} is not a positive σ", v[k]),
                        ));
                    }
                }
                Some(v)
            }
        };
        rows.push(Row { line, stamp, q, temperature, position_mm, rotation_deg, std });
    }
    Ok(rows)
}

/// A number written with a decimal comma: `-0,000181978`, `2,78E-05`, `0`. A decimal point is
/// refused (in a decimal-comma file it would be a thousands separator), and so are NaN and ±∞.
fn decimal_comma(field: &str) -> Result<f64, String> {
    let s = field.trim();
    if s.is_empty() {
        return Err("empty value".into());
    }
    let plausible = s.bytes().all(|b| b.is_ascii_digit() || matches!(b, b',' | b'-' | b'+' | b'e' | b'E'))
        && s.matches(',').count() <= 1;
    let v: f64 = match plausible.then(|| s.replacen(',', ".", 1).parse::<f64>()) {
        Some(Ok(v)) => v,
        _ => return Err(format!("'{s}' is not a number")),
    };
    if v.is_finite() { Ok(v) } else { Err(format!("'{s}' is not a finite number")) }
}

/// A `yyyymmddhhmmss` timestamp as seconds on a continuous calendar-exact scale.
/// `Ok(None)` when the field is not a 14-digit integer (digits lost); an error when it is one but
/// not a valid date and time.
fn timestamp(field: &str) -> Result<Option<i64>, String> {
    let s = field.trim();
    if s.len() != 14 || !s.bytes().all(|b| b.is_ascii_digit()) {
        return Ok(None);
    }
    let digits =
        |from: usize, to: usize| s.as_bytes()[from..to].iter().fold(0_i64, |n, d| n * 10 + i64::from(d - b'0'));
    let (year, month, day) = (digits(0, 4), digits(4, 6), digits(6, 8));
    let (hour, minute, second) = (digits(8, 10), digits(10, 12), digits(12, 14));
    if !(1..=12).contains(&month)
        || !(1..=days_in_month(year, month)).contains(&day)
        || hour > 23
        || minute > 59
        || second > 59
    {
        return Err(format!("'{s}' is not a valid yyyymmddhhmmss date and time"));
    }
    Ok(Some(days_from_civil(year, month, day) * 86_400 + hour * 3600 + minute * 60 + second))
}

fn days_in_month(year: i64, month: i64) -> i64 {
    let leap = (year % 4 == 0 && year % 100 != 0) || year % 400 == 0;
    match month {
        2 if leap => 29,
        2 => 28,
        4 | 6 | 9 | 11 => 30,
        _ => 31,
    }
}

/// Days since 0000-03-01 of the proleptic Gregorian calendar (H. Hinnant's `days_from_civil`,
/// shifted; only differences are used). Valid for years ≥ 0.
fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let mp = (month + 9) % 12; // March = 0
    let doy = (153 * mp + 2) / 5 + day - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe
}

/// The session's times: seconds since the first row, or why there are none.
enum Times {
    Seconds(Vec<f64>),
    Lost { count: usize, first_line: u64, first_text: String },
}

fn session_times(rows: &[Row]) -> Times {
    let lost: Vec<&Row> = rows.iter().filter(|r| r.stamp.is_err()).collect();
    if let Some(first) = lost.first() {
        return Times::Lost {
            count: lost.len(),
            first_line: first.line,
            first_text: first.stamp.as_ref().err().cloned().unwrap_or_default(),
        };
    }
    let stamps: Vec<i64> = rows.iter().filter_map(|r| r.stamp.as_ref().ok().copied()).collect();
    let t0 = stamps.first().copied().unwrap_or(0);
    Times::Seconds(stamps.iter().map(|s| (s - t0) as f64).collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A valid date (year, month, day) and the next day, stepped by hand.
    fn date_and_next() -> impl Strategy<Value = ((i64, i64, i64), (i64, i64, i64))> {
        (1900_i64..2200, 1_i64..=12, 1_i64..=31).prop_map(|(y, m, d)| {
            let d = d.min(days_in_month(y, m));
            let next = if d < days_in_month(y, m) {
                (y, m, d + 1)
            } else if m < 12 {
                (y, m + 1, 1)
            } else {
                (y + 1, 1, 1)
            };
            ((y, m, d), next)
        })
    }

    proptest! {
        /// Whatever a decimal-comma writer prints comes back exactly.
        #[test]
        fn decimal_comma_reads_back_what_is_written(v in -1e7_f64..1e7, exp in any::<bool>()) {
            let text = if exp { format!("{v:E}") } else { v.to_string() }.replace('.', ",");
            prop_assert_eq!(decimal_comma(&text), Ok(v));
        }

        /// Midnight to midnight is 86,400 s across month, year and leap-day boundaries.
        #[test]
        fn consecutive_days_are_a_day_apart(((y, m, d), (y2, m2, d2)) in date_and_next(), h in 0_i64..24, s in 0_i64..60) {
            let a = timestamp(&format!("{y:04}{m:02}{d:02}{h:02}00{s:02}")).unwrap().unwrap();
            let b = timestamp(&format!("{y2:04}{m2:02}{d2:02}{h:02}00{s:02}")).unwrap().unwrap();
            prop_assert_eq!(b - a, 86_400);
        }

        /// Arbitrary text gives a value or an error, never a panic.
        #[test]
        fn parsers_never_panic(text in "\\PC{0,24}", digits in "[0-9]{14}") {
            let _ = decimal_comma(&text);
            let _ = timestamp(&text);
            let _ = timestamp(&digits);
        }
    }

    #[test]
    fn decimal_commas_parse_and_junk_does_not() {
        assert_eq!(decimal_comma("0,365141"), Ok(0.365141));
        assert_eq!(decimal_comma("-0,000212669"), Ok(-0.000212669));
        assert_eq!(decimal_comma("2,78E-05"), Ok(2.78e-5));
        assert_eq!(decimal_comma("4,3869e-05"), Ok(4.3869e-5));
        assert_eq!(decimal_comma("0"), Ok(0.0));
        assert_eq!(decimal_comma(" -1,25 "), Ok(-1.25));
        assert_eq!(decimal_comma("1,2x"), Err("'1,2x' is not a number".into()));
        assert_eq!(decimal_comma("1.5"), Err("'1.5' is not a number".into()));
        assert_eq!(decimal_comma("1,2,3"), Err("'1,2,3' is not a number".into()));
        assert_eq!(decimal_comma("nan"), Err("'nan' is not a number".into()));
        assert_eq!(decimal_comma("1e999"), Err("'1e999' is not a finite number".into()));
        assert_eq!(decimal_comma(""), Err("empty value".into()));
    }

    /// Differences across day, month, leap-day and year boundaries, counted by hand.
    #[test]
    fn timestamps_follow_the_calendar() {
        let t = |s: &str| timestamp(s).unwrap().unwrap();
        assert_eq!(t("20200714163924") - t("20200714163904"), 20);
        assert_eq!(t("20200715000001") - t("20200714235959"), 2);
        assert_eq!(t("20200801000000") - t("20200731235959"), 1);
        assert_eq!(t("20200301000000") - t("20200228000000"), 2 * 86_400); // 2020 is a leap year
        assert_eq!(t("20210301000000") - t("20210228000000"), 86_400);
        assert_eq!(t("21000301000000") - t("21000228000000"), 86_400); // 2100 is not
        assert_eq!(t("20210101000000") - t("20201231000000"), 86_400);
        assert_eq!(t("20210101000000") - t("20200101000000"), 366 * 86_400);
        // Series A: 2020-07-14 16:39:04 to 2020-07-18 21:27:57.
        assert_eq!(t("20200718212757") - t("20200714163904"), ((4 * 24 + 4) * 60 + 48) * 60 + 53);
        assert_eq!(timestamp("2,02011E+13"), Ok(None));
        assert_eq!(timestamp("2020071416390"), Ok(None));
        assert!(timestamp("20200230120000").unwrap_err().contains("not a valid"));
        assert!(timestamp("20201301120000").is_err());
        assert!(timestamp("20200714246000").is_err());
    }

    fn scratch(name: &str, text: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("robocal-ur10-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn the_probe_matrix_is_checked() {
        let good = "-0.00079633 0.99999968 -0. -0.\r\n-0.99999937 -0.00079633 -0.00079633 0.08679961\r\n\
                    -0.00079633 -0.00000063 0.99999968 -108.99996544\r\n0. 0. 0. 1.";
        let p = read_probe_transform(&scratch("good.txt", good)).unwrap();
        assert!((p.frame.t - Vector3::new(0.0, 0.08679961e-3, -108.99996544e-3)).norm() < 1e-18);
        assert!((p.frame.r.transpose() * p.frame.r - Matrix3::identity()).abs().max() < 1e-15);
        assert!(p.orthogonality_defect > 0.0 && p.orthogonality_defect < 1e-7);

        let check = |name: &str, text: &str, needle: &str| {
            let e = read_probe_transform(&scratch(name, text)).unwrap_err();
            assert!(matches!(e, ImportError::Matrix { .. }), "{e}");
            assert!(e.to_string().contains(needle), "{e}");
        };
        check("three.txt", "1 0 0 0\n0 1 0 0\n0 0 0 1\n", "got 3 lines");
        check("short.txt", "1 0 0 0\n0 1 0\n0 0 1 0\n0 0 0 1\n", "line 2: expected 4 numbers, got 3");
        check("word.txt", "1 0 0 0\n0 1 0 0\n0 0 one 0\n0 0 0 1\n", "line 3: 'one' is not a finite number");
        check("last.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 1 1\n", "not [0, 0, 0, 1]");
        check("scaled.txt", "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "not a rotation");
        check("mirror.txt", "-1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n", "not a rotation");
    }

    #[test]
    fn session_names_come_from_the_folder() {
        assert_eq!(session_name(Path::new("/data/ur10-ipa/Series_C")), "series-C");
        assert_eq!(session_name(Path::new("/data/ur10-ipa/Series_C/")), "series-C");
        assert_eq!(session_name(Path::new("/data/my_run")), "my_run");
    }

    #[test]
    fn bad_options_are_refused() {
        let f = Frame::identity();
        let opts = |m: f64, c: Option<[f64; 3]>| Ur10Options { tool_mass_kg: m, tool_com_mm: c, ..Default::default() };
        assert!(probe_tool(&f, &opts(-1.0, None)).unwrap_err().to_string().contains("tool mass"));
        assert!(probe_tool(&f, &opts(f64::NAN, None)).is_err());
        assert!(probe_tool(&f, &opts(1.0, Some([0.0, f64::INFINITY, 0.0]))).is_err());
        let t = probe_tool(&f, &opts(1.2, Some([0.0, 0.0, 50.0]))).unwrap();
        assert_eq!((t.mass, t.com), (1.2, Vector3::new(0.0, 0.0, 0.05)));
    }
}

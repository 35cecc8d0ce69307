//! Program filtering: a robot program as the controller reads it, every Cartesian target (and, if
//! asked, every joint target) replaced by its compensated value, every other byte kept.
//!
//! Four languages, one module each: ABB RAPID (`rapid`), KUKA KRL (`krl`, the `.src` + `.dat`
//! pair), Fanuc TP text (`fanuc`, `.ls`) and Universal Robots URScript (`urscript`). Each parser is
//! pure text → targets: the value of each target in SI units in its work frame, its configuration
//! (posture), the tool and work frame it is programmed with (declared in the program, or named
//! there and given by the caller), and the byte spans of its numbers. The engine here resolves
//! the frames, compensates every target with [`Compensator`] (the same solver and the same
//! envelope and uncertainty checks as `compensate`: [`crate::domain::pose::guard_target`]), and
//! hands each result back to its language, which writes the new numbers into those spans. A
//! target that cannot be compensated keeps its bytes and gets a comment in the language's own
//! syntax; the report says why.
//!
//! Frames, as on the controllers: a target is the TCP pose in its work frame (RAPID `wobjdata`,
//! KRL `$BASE`, Fanuc `UF`, the base for URScript), the work frame given in the robot's base frame
//! (the controller's world frame is taken as the robot's base). The target is read in the
//! *calibrated* base frame and its fake pose written in the controller's (nominal) one, as
//! `compensate` with `"frame": "base"` and a work object does.

mod engine;
pub mod fanuc;
pub mod krl;
pub(crate) mod lex;
pub mod rapid;
pub mod urscript;

use std::collections::BTreeMap;
use std::fmt;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use super::validity::HeldOutUncertainty;
use super::validity::{Envelope, PredictionCovariance};
use super::{DEG, DomainError, MM};
use crate::kinematics::frame::{rot_zyx, rotation_angle};
use crate::kinematics::{Branch, Compensator, Confdata, Frame, ParameterSet, Tool};
use engine::Frames;
use lex::{Edit, Lines};

/// A controller language.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum Language {
    /// ABB RAPID modules (`.mod`, `.prg`, `.modx`, `.sys`).
    Rapid,
    /// KUKA KRL: a `.src` and its `.dat`.
    Krl,
    /// Fanuc TP programs as text (`.ls`).
    Fanuc,
    /// Universal Robots URScript (`.script`, `.urscript`).
    Urscript,
}

impl Language {
    pub const ALL: [Language; 4] = [Language::Rapid, Language::Krl, Language::Fanuc, Language::Urscript];

    pub fn name(self) -> &'static str {
        match self {
            Language::Rapid => "rapid",
            Language::Krl => "krl",
            Language::Fanuc => "fanuc",
            Language::Urscript => "urscript",
        }
    }

    /// `rapid`, `krl`, `fanuc`, `urscript` (any case), or an error naming `field`.
    pub fn parse(s: &str, field: &str) -> Result<Language, DomainError> {
        Language::ALL.into_iter().find(|l| l.name().eq_ignore_ascii_case(s.trim())).ok_or_else(|| {
            DomainError::new(field, format!("unknown language '{s}': one of rapid, krl, fanuc, urscript"))
        })
    }

    /// The language of a file name's extension.
    pub fn of_file(name: &str) -> Option<Language> {
        let ext = name.rsplit_once('.')?.1.to_ascii_lowercase();
        match ext.as_str() {
            "mod" | "prg" | "modx" | "sys" | "sysx" => Some(Language::Rapid),
            "src" | "dat" => Some(Language::Krl),
            "ls" => Some(Language::Fanuc),
            "script" | "urscript" => Some(Language::Urscript),
            _ => None,
        }
    }

    /// The language a program's first words say it is in: a RAPID `MODULE` (or `%%%` header), a
    /// Fanuc `/PROG`, a KRL `DEF`/`DEFDAT`/`&ACCESS`, or a URScript `def name():`.
    pub fn sniff(bytes: &[u8]) -> Option<Language> {
        let text = lex::latin1(&bytes[..bytes.len().min(4096)]);
        for line in text.lines() {
            let t = line.trim_start_matches('\u{feff}').trim();
            let up = t.to_ascii_uppercase();
            if t.is_empty() || t.starts_with('!') || t.starts_with(';') || t.starts_with('#') && !t.starts_with("#!") {
                continue;
            }
            if up.starts_with("%%%") || up.starts_with("MODULE ") {
                return Some(Language::Rapid);
            }
            if up.starts_with("/PROG") {
                return Some(Language::Fanuc);
            }
            // URScript's `def name():` ends with a colon; KRL's `DEF NAME( )` does not.
            if t.starts_with("def ") && t.trim_end().ends_with(':') {
                return Some(Language::Urscript);
            }
            if up.starts_with('&')
                || up.starts_with("DEF ")
                || up.starts_with("DEFDAT ")
                || up.starts_with("GLOBAL DEF")
            {
                return Some(Language::Krl);
            }
            return None;
        }
        None
    }
}

/// One file of a program: its name (for messages, the report and the language) and its bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProgramFile {
    pub name: String,
    pub bytes: Vec<u8>,
}

/// What to do with joint targets (RAPID `jointtarget`, KRL `E6AXIS`/`AXIS`, Fanuc joint
/// positions, URScript `movej([…])`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum JointTargets {
    /// Leave them as written (taught on the real robot, or meant as joints).
    #[default]
    Keep,
    /// Replace each by the joints that put the real robot's TCP where the nominal model puts it
    /// at the written joints (the program was made on the nominal model).
    Recompute,
}

impl JointTargets {
    pub fn parse(s: &str, field: &str) -> Result<JointTargets, DomainError> {
        match s.trim().to_ascii_lowercase().as_str() {
            "keep" => Ok(JointTargets::Keep),
            "recompute" => Ok(JointTargets::Recompute),
            _ => Err(DomainError::new(field, format!("'{s}': keep or recompute"))),
        }
    }
}

/// Tools and work frames a program names but does not declare (KRL `TOOL_DATA[n]`, Fanuc `UT`/`UF`
/// numbers, RAPID data declared in another module, URScript's TCP), keyed by the name the program
/// uses (lower case; numbers as written).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GivenFrames {
    pub tools: BTreeMap<String, Tool>,
    pub bases: BTreeMap<String, Frame>,
}

/// How a frame argument's angles are ordered.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleOrder {
    /// a, b, c: ZY'X'' (KUKA's A, B, C; robocal's `rotation_deg`).
    Abc,
    /// w, p, r: Fanuc's rotations about the fixed x, y, z axes (the same rotation as ZY'X'' with
    /// a = r, b = p, c = w).
    Wpr,
}

impl GivenFrames {
    /// Add a tool from `NAME:x,y,z,a,b,c` (mm, deg) or `NAME:x,y,z,a,b,c,mass_kg,cx,cy,cz` (the
    /// payload: kg, centre of mass in the flange frame, mm); `field` names the option in errors.
    pub fn add_tool(&mut self, spec: &str, order: AngleOrder, field: &str) -> Result<(), DomainError> {
        let (key, v) = frame_arg(spec, order, field, true)?;
        let tcp = Frame::from_xyzabc(&[v[0] * MM, v[1] * MM, v[2] * MM, v[3] * DEG, v[4] * DEG, v[5] * DEG]);
        let (mass, com) = if v.len() == 10 {
            if v[6] < 0.0 {
                return Err(DomainError::new(field, format!("'{spec}': the payload mass must not be negative")));
            }
            (v[6], Vector3::new(v[7], v[8], v[9]) * MM)
        } else {
            (0.0, Vector3::zeros())
        };
        if self.tools.insert(key.clone(), Tool { tcp: tcp.to_xyzabc(), mass, com }).is_some() {
            return Err(DomainError::new(field, format!("tool '{key}' is given twice")));
        }
        Ok(())
    }

    /// Add a work frame (base, user frame, work object) from `NAME:x,y,z,a,b,c` (mm, deg).
    pub fn add_base(&mut self, spec: &str, order: AngleOrder, field: &str) -> Result<(), DomainError> {
        let (key, v) = frame_arg(spec, order, field, false)?;
        let f = Frame::from_xyzabc(&[v[0] * MM, v[1] * MM, v[2] * MM, v[3] * DEG, v[4] * DEG, v[5] * DEG]);
        if self.bases.insert(key.clone(), f).is_some() {
            return Err(DomainError::new(field, format!("frame '{key}' is given twice")));
        }
        Ok(())
    }
}

/// `NAME:v1,…,v6[,v7,…,v10]` → (lower-case name, values with the angles as a, b, c).
fn frame_arg(spec: &str, order: AngleOrder, field: &str, payload: bool) -> Result<(String, Vec<f64>), DomainError> {
    let form = if payload { "NAME:x,y,z,a,b,c or NAME:x,y,z,a,b,c,mass_kg,cx,cy,cz" } else { "NAME:x,y,z,a,b,c" };
    let form = if order == AngleOrder::Wpr { form.replace("a,b,c", "w,p,r") } else { form.to_string() };
    let Some((name, values)) = spec.split_once(':') else {
        return Err(DomainError::new(field, format!("'{spec}': expected {form} (mm, deg)")));
    };
    let name = name.trim();
    if name.is_empty() || name.chars().any(|c| c.is_whitespace() || c.is_control()) || name.len() > 64 {
        return Err(DomainError::new(field, format!("'{spec}': the name before ':' must be a word")));
    }
    let mut v = Vec::new();
    for part in values.split(',') {
        match part.trim().parse::<f64>() {
            Ok(x) if x.is_finite() => v.push(x),
            _ => return Err(DomainError::new(field, format!("'{spec}': '{}' is not a finite number", part.trim()))),
        }
    }
    if !(v.len() == 6 || payload && v.len() == 10) {
        return Err(DomainError::new(field, format!("'{spec}': {} numbers; expected {form} (mm, deg)", v.len())));
    }
    if order == AngleOrder::Wpr {
        v.swap(3, 5);
    }
    Ok((name.to_ascii_lowercase(), v))
}

/// What a filter run is asked to do besides compensating poses.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FilterOptions {
    /// The language; default: the files' extensions, else their first words.
    pub language: Option<Language>,
    pub joint_targets: JointTargets,
    pub frames: GivenFrames,
    /// The joints (rad) the robot starts from, for languages whose poses carry no configuration
    /// (URScript, KRL `FRAME` and `POS` without `S`/`T`): the first such pose takes the solution
    /// nearest these, each next one the solution nearest the pose before it.
    pub seed_joints: Option<Vec<f64>>,
}

/// The calibrated robot a program is filtered for, with what compensation checks.
#[derive(Clone, Copy)]
pub struct Calibration<'a> {
    pub set: &'a ParameterSet,
    /// The set's compensator with its own tool (reused when a program's tool is that tool).
    pub compensator: &'a Compensator,
    pub envelope: Option<&'a Envelope>,
    pub allow_outside_envelope: bool,
    pub covariance: Option<&'a PredictionCovariance>,
    /// What the set's held-out validation measured (the uncertainty's other parts); `None`: no
    /// held-out validation given, and no `uncertainty_mm`.
    pub held_out: Option<&'a HeldOutUncertainty>,
}

/// A malformed program: the file, the line (1-based) and what is wrong there.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProgramError {
    pub file: String,
    pub line: usize,
    pub message: String,
}

impl ProgramError {
    pub fn new(file: &str, line: usize, message: impl Into<String>) -> Self {
        ProgramError { file: file.to_string(), line, message: message.into() }
    }
}

impl fmt::Display for ProgramError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line == 0 {
            write!(f, "{}: {}", self.file, self.message)
        } else {
            write!(f, "{} line {}: {}", self.file, self.line, self.message)
        }
    }
}

/// Why a program was not filtered at all.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FilterError {
    /// The program does not parse: the line says where.
    #[error("{0}")]
    Program(ProgramError),
    /// An option contradicts the program (a frame given that the program declares, a language
    /// the files are not in): the option's name is the error's path.
    #[error("{0}")]
    Input(DomainError),
}

impl From<ProgramError> for FilterError {
    fn from(e: ProgramError) -> Self {
        FilterError::Program(e)
    }
}

/// Whether a report line is a pose or a joint target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TargetKind {
    Pose,
    Joints,
}

/// What happened to a target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum TargetStatus {
    /// Rewritten with its compensated value.
    Compensated,
    /// A joint target left as written (`joint_targets: keep`).
    Kept,
    /// Left as written and marked with a comment: see `error`.
    Failed,
}

/// One line of the report: a target of the program and what the filter did with it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TargetReport {
    /// The file the target is in.
    pub file: String,
    /// Its name in the program (`p10`, `XP3`, `P[12]`), or where it is written when inline
    /// (`MoveL@42`).
    pub name: String,
    /// The 1-based line of its value.
    pub line: usize,
    pub kind: TargetKind,
    pub status: TargetStatus,
    /// The value as written (whitespace runs as one space).
    pub original: String,
    /// The value written in its place.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub compensated: Option<String>,
    /// How far the programmed TCP moved: position (mm) and rotation (deg) between the written and
    /// the compensated pose (for a joint target, between the nominal model's poses of the two).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_mm: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub correction_deg: Option<f64>,
    /// The compensated joints, deg.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints_deg: Option<Vec<f64>>,
    /// The predicted standard uncertainty of the TCP position at the compensated joints, mm, as
    /// `compensate` gives it: √(covariance² + unexplained² + extrapolation²). Absent when a part is
    /// unknown (no held-out validation given, no recorded region).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty_mm: Option<f64>,
    /// Why it was not compensated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

/// A filtered program: its files rewritten, and the report.
#[derive(Clone, Debug, PartialEq)]
pub struct Filtered {
    pub language: Language,
    pub files: Vec<ProgramFile>,
    pub report: Vec<TargetReport>,
}

impl Filtered {
    pub fn failed(&self) -> usize {
        self.report.iter().filter(|r| r.status == TargetStatus::Failed).count()
    }

    pub fn compensated(&self) -> usize {
        self.report.iter().filter(|r| r.status == TargetStatus::Compensated).count()
    }
}

// ---------------------------------------------------------------------------------------------
// What the language parsers hand the engine.

/// A frame or tool a target is programmed with.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Ref<T> {
    /// Known from the program (declared, inline, or a predefined identity such as `tool0`).
    Given(T),
    /// A name to look up among the program's declarations, then the caller's frames.
    Named(String),
    /// Cannot be known; why.
    Missing(String),
}

/// How a pose target picks among the inverse-kinematics solutions.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Posture {
    /// ABB confdata: the branch, and the quadrants of axes 1, 4, 6.
    Confdata(Confdata),
    /// A branch, and for some joints the interval [lo, hi) (rad) their value must lie in (KUKA's
    /// turn bits, Fanuc's turn numbers): the closed-form seed is moved by whole turns into it.
    Turns { branch: Branch, ranges: [Option<(f64, f64)>; 6] },
    /// The solution nearest the joints of the motion before it (URScript; KRL poses without status
    /// and turn).
    Nearest,
}

// A pose target's posture is large; targets live once in one Vec, so boxing would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Kind {
    /// A TCP pose in its work frame (SI).
    Pose { pose: Frame, posture: Posture },
    /// Joint values, rad.
    Joints { q: Vec<f64> },
}

/// A target found in a program.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Target {
    pub file: usize,
    pub name: String,
    pub line: usize,
    pub kind: Kind,
    pub tool: Ref<Tool>,
    /// The payload the program sets for it, when it does (URScript `set_payload`): kg and the
    /// centre of mass in the flange frame (m); replaces the resolved tool's.
    pub payload: Option<(f64, Vector3<f64>)>,
    pub base: Ref<Frame>,
    /// The byte spans of the numbers the language rewrites, in the language's order.
    pub slots: Vec<(usize, usize)>,
    /// The written values of those numbers (for the representation of the answer: Euler family,
    /// quaternion sign, number of digits).
    pub values: Vec<f64>,
    /// The whole value's bytes, for the report.
    pub extent: (usize, usize),
    /// Why this target cannot be compensated, found while reading it (a value that is an
    /// expression, a name used with two tools).
    pub problem: Option<String>,
    /// Notes to pass on (a quaternion normalised).
    pub notes: Vec<String>,
    /// Language-specific detail for writing it back.
    pub style: Style,
}

/// What a language needs, besides the slots, to write a target back.
#[derive(Clone, Debug, PartialEq, Default)]
pub(crate) enum Style {
    #[default]
    Plain,
    /// KRL: which slots hold S and T, and whether they were written as `'B…'` bit strings (with
    /// that many digits).
    Krl { s: Option<(usize, Option<usize>)>, t: Option<(usize, Option<usize>)> },
    /// Fanuc: the CONFIG string's span (inside the quotes) and where to put the failure comment.
    Fanuc { config: Option<(usize, usize)>, comment: FanucComment },
}

/// Where a Fanuc position's comment goes: `P[n]` has none (insert `:"…"` before `]`), or its
/// text starts at this byte.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FanucComment {
    None { close: usize },
    Text { start: usize },
}

/// A program read by its language.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Parsed {
    pub targets: Vec<Target>,
    /// Tools the program declares, by lower-case name: the tool, or why it cannot be used.
    pub tools: BTreeMap<String, Declared<Tool>>,
    pub bases: BTreeMap<String, Declared<Frame>>,
    /// Target indices in the order the motions use them (repeats allowed): the order in which
    /// [`Posture::Nearest`] poses take the solution nearest the pose before.
    pub sequence: Vec<usize>,
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Declared<T> {
    pub value: Result<T, String>,
    pub file: usize,
    pub line: usize,
}

/// A compensated target, as its language writes it back.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Solution {
    /// The fake pose in the target's work frame (pose targets).
    pub pose: Option<Frame>,
    /// The compensated joints, rad.
    pub joints: Vec<f64>,
    /// The controller's (nominal) configuration data of the joints, when the robot has a closed
    /// form.
    pub confdata: Option<Confdata>,
}

/// A language: its parser, and how it writes a compensated target and marks a failed one.
pub(crate) trait Dialect: Sync {
    fn parse(&self, files: &[ProgramFile]) -> Result<Parsed, ProgramError>;
    /// The edits that write `s` into `t`'s slots.
    fn render(&self, t: &Target, s: &Solution) -> Vec<Edit>;
    /// The edit that marks `t` as not compensated, with the reason (in the language's comment
    /// syntax, on the target's own line: line numbers do not move).
    fn mark(&self, bytes: &[u8], lines: &Lines, t: &Target, why: &str) -> Edit;
}

fn dialect(lang: Language) -> &'static dyn Dialect {
    match lang {
        Language::Rapid => &rapid::Rapid,
        Language::Krl => &krl::Krl,
        Language::Fanuc => &fanuc::Fanuc,
        Language::Urscript => &urscript::UrScript,
    }
}

/// The language of a program: as asked, or what the files' extensions (then their first words)
/// say; every file must agree.
pub fn detect(files: &[ProgramFile], asked: Option<Language>) -> Result<Language, FilterError> {
    if files.is_empty() {
        return Err(FilterError::Input(DomainError::new("program", "no program file")));
    }
    if let Some(l) = asked {
        return Ok(l);
    }
    let mut found: Option<Language> = None;
    for f in files {
        let l = Language::of_file(&f.name).or_else(|| Language::sniff(&f.bytes)).ok_or_else(|| {
            FilterError::Input(DomainError::new(
                "language",
                format!(
                    "{}: cannot tell the language from the name or the first line; say rapid, krl, fanuc or urscript",
                    f.name
                ),
            ))
        })?;
        match found {
            Some(p) if p != l => {
                return Err(FilterError::Input(DomainError::new(
                    "language",
                    format!("{} is {} but the other files are {}", f.name, l.name(), p.name()),
                )));
            }
            _ => found = Some(l),
        }
    }
    Ok(found.expect("at least one file"))
}

/// A program's targets as its language reads them, with their frames resolved: what a test or a
/// tool reads back from a filtered program.
#[derive(Clone, Debug, PartialEq)]
pub struct ReadTarget {
    pub file: usize,
    pub name: String,
    pub line: usize,
    /// The pose in its work frame (SI), for pose targets.
    pub pose: Option<Frame>,
    /// The joints (rad), for joint targets.
    pub joints: Option<Vec<f64>>,
    /// ABB confdata or the language's configuration translated to it (cf1/cf4/cf6 from the turn
    /// ranges are not translated: 0), when the target states a branch.
    pub branch: Option<Branch>,
    /// The intervals (rad) the joints must lie in, when the language states them (ABB quadrants
    /// for axes 1, 4, 6; KUKA turn bits; Fanuc turn numbers).
    pub ranges: [Option<(f64, f64)>; 6],
    pub tool: Result<Tool, String>,
    pub base: Result<Frame, String>,
    /// The lines its value spans.
    pub lines: (usize, usize),
    pub problem: Option<String>,
}

/// Read a program's targets (no compensation): its frames resolved as [`filter`] resolves them.
pub fn read(files: &[ProgramFile], opts: &FilterOptions) -> Result<(Language, Vec<ReadTarget>), FilterError> {
    let lang = detect(files, opts.language)?;
    let parsed = dialect(lang).parse(files)?;
    let frames = Frames::new(&parsed, &opts.frames, files)?;
    let lines: Vec<Lines> = files.iter().map(|f| Lines::new(&f.bytes)).collect();
    let out = parsed
        .targets
        .iter()
        .map(|t| {
            let (pose, joints, branch, ranges) = match &t.kind {
                Kind::Pose { pose, posture } => {
                    let (b, r) = match posture {
                        Posture::Confdata(c) => (Some(c.cfx), quadrant_ranges(c)),
                        Posture::Turns { branch, ranges } => (Some(*branch), *ranges),
                        Posture::Nearest => (None, [None; 6]),
                    };
                    (Some(*pose), None, b, r)
                }
                Kind::Joints { q } => (None, Some(q.clone()), None, [None; 6]),
            };
            ReadTarget {
                file: t.file,
                name: t.name.clone(),
                line: t.line,
                pose,
                joints,
                branch,
                ranges,
                tool: frames.tool(t),
                base: frames.base(t),
                lines: (lines[t.file].line_of(t.extent.0), lines[t.file].line_of(t.extent.1.saturating_sub(1))),
                problem: t.problem.clone(),
            }
        })
        .collect();
    Ok((lang, out))
}

/// The joint intervals of ABB quadrants: axis k in [cf·90°, (cf+1)·90°).
fn quadrant_ranges(c: &Confdata) -> [Option<(f64, f64)>; 6] {
    let q = |cf: i32| Some((f64::from(cf) * 90.0 * DEG, f64::from(cf + 1) * 90.0 * DEG));
    [q(c.cf1), None, None, q(c.cf4), None, q(c.cf6)]
}

/// Filter a program: every target compensated with `cal` and written back in place, every other
/// byte as it was. A target that cannot be compensated is left as written, marked, and reported
/// (`Filtered::failed`); a program that does not parse, or options that contradict it, are an
/// error.
pub fn filter(cal: &Calibration, files: &[ProgramFile], opts: &FilterOptions) -> Result<Filtered, FilterError> {
    let lang = detect(files, opts.language)?;
    let d = dialect(lang);
    let parsed = d.parse(files)?;
    engine::filter_parsed(cal, files, opts, lang, d, &parsed)
}

/// The targets in the order the program's motions use them, repeats included (indices into
/// [`read`]'s targets): what a reader checks a program's motion order with. Targets no motion
/// uses are not listed.
pub fn motion_order(files: &[ProgramFile], language: Option<Language>) -> Result<Vec<usize>, FilterError> {
    let lang = detect(files, language)?;
    Ok(dialect(lang).parse(files)?.sequence)
}

/// How many targets a program holds (its parse only): for a caller's bound before the work.
pub fn count_targets(files: &[ProgramFile], language: Option<Language>) -> Result<usize, FilterError> {
    let lang = detect(files, language)?;
    Ok(dialect(lang).parse(files)?.targets.len())
}

// ---------------------------------------------------------------------------------------------
// Helpers the languages share.

/// A rotation of ZY'X'' angles in degrees.
pub(crate) fn rot_deg(a: f64, b: f64, c: f64) -> nalgebra::Matrix3<f64> {
    rot_zyx(a * DEG, b * DEG, c * DEG)
}

/// A frame from a position in mm and ZY'X'' angles in degrees.
pub(crate) fn frame_mm_deg(p: [f64; 3], abc: [f64; 3]) -> Frame {
    Frame::new(rot_deg(abc[0], abc[1], abc[2]), Vector3::new(p[0], p[1], p[2]) * MM)
}

/// The rotation angle between two frames' orientations (rad).
#[allow(dead_code)]
pub(crate) fn angle_between(a: &Frame, b: &Frame) -> f64 {
    rotation_angle(&(a.r.transpose() * b.r))
}

/// A tool from a TCP frame, massless.
pub(crate) fn tool_of(tcp: &Frame) -> Tool {
    Tool { tcp: tcp.to_xyzabc(), mass: 0.0, com: Vector3::zeros() }
}

/// The per-target report as CSV (one line per target), for the command line's `--report`.
pub fn report_csv(report: &[TargetReport]) -> String {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "file",
        "name",
        "line",
        "kind",
        "status",
        "correction_mm",
        "correction_deg",
        "uncertainty_mm",
        "original",
        "compensated",
        "joints_deg",
        "error",
        "notes",
    ])
    .expect("csv in memory");
    let num = |v: Option<f64>| v.map(|x| x.to_string()).unwrap_or_default();
    for r in report {
        let kind = match r.kind {
            TargetKind::Pose => "pose",
            TargetKind::Joints => "joints",
        };
        let status = match r.status {
            TargetStatus::Compensated => "compensated",
            TargetStatus::Kept => "kept",
            TargetStatus::Failed => "failed",
        };
        let joints = r
            .joints_deg
            .as_ref()
            .map(|q| q.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" "))
            .unwrap_or_default();
        w.write_record([
            r.file.as_str(),
            &r.name,
            &r.line.to_string(),
            kind,
            status,
            &num(r.correction_mm),
            &num(r.correction_deg),
            &num(r.uncertainty_mm),
            &r.original,
            r.compensated.as_deref().unwrap_or_default(),
            &joints,
            r.error.as_deref().unwrap_or_default(),
            &r.notes.join("; "),
        ])
        .expect("csv in memory");
    }
    String::from_utf8(w.into_inner().expect("csv in memory")).expect("csv of strings")
}

#[cfg(test)]
mod tests {
    use super::engine::into_range;
    use super::*;

    #[test]
    fn frame_arguments_parse_with_their_units_and_order() {
        let mut g = GivenFrames::default();
        g.add_tool("Gripper:0,0,150,0,90,0,2.5,0,0,60", AngleOrder::Abc, "--tool").unwrap();
        let t = &g.tools["gripper"];
        assert!((t.tcp[2] - 0.15).abs() < 1e-15 && (t.tcp[4] - 90.0 * DEG).abs() < 1e-12);
        assert_eq!(t.mass, 2.5);
        assert!((t.com.z - 0.06).abs() < 1e-15);
        // Fanuc's w, p, r are the same rotation as ZY'X'' (a, b, c) = (r, p, w).
        g.add_base("1:100,0,0,10,20,30", AngleOrder::Wpr, "--uframe").unwrap();
        let f = g.bases["1"];
        let want = rot_deg(30.0, 20.0, 10.0);
        assert!((f.r - want).abs().max() < 1e-15);
        let e = g.add_base("1:0,0,0,0,0,0", AngleOrder::Abc, "--base").unwrap_err();
        assert!(e.reason.contains("twice"), "{}", e.reason);
        for bad in ["x:1,2,3", "nocolon", ":1,2,3,4,5,6", "x:1,2,3,4,5,nan"] {
            assert_eq!(g.add_base(bad, AngleOrder::Abc, "--base").unwrap_err().path, "--base", "{bad}");
        }
        assert!(g.add_base("y:1,2,3,4,5,6,7,8,9,10", AngleOrder::Abc, "--base").is_err());
    }

    #[test]
    fn languages_are_told_by_name_and_by_content() {
        assert_eq!(Language::of_file("weld.MOD"), Some(Language::Rapid));
        assert_eq!(Language::of_file("a/b.dat"), Some(Language::Krl));
        assert_eq!(Language::of_file("P1.ls"), Some(Language::Fanuc));
        assert_eq!(Language::of_file("x.script"), Some(Language::Urscript));
        assert_eq!(Language::of_file("x.txt"), None);
        assert_eq!(Language::sniff(b"%%%\n  VERSION:1\n%%%\nMODULE A\n"), Some(Language::Rapid));
        assert_eq!(Language::sniff(b"\n! c\nMODULE A\n"), Some(Language::Rapid));
        assert_eq!(Language::sniff(b"/PROG  P1\n"), Some(Language::Fanuc));
        assert_eq!(Language::sniff(b"&ACCESS RVP\nDEF a()\n"), Some(Language::Krl));
        assert_eq!(Language::sniff(b"# x\ndef prog():\n"), Some(Language::Urscript));
        assert_eq!(Language::sniff(b"hello"), None);
        let f = |name: &str| ProgramFile { name: name.into(), bytes: Vec::new() };
        assert_eq!(detect(&[f("a.src"), f("a.dat")], None).unwrap(), Language::Krl);
        assert!(matches!(detect(&[f("a.src"), f("b.mod")], None), Err(FilterError::Input(e)) if e.path == "language"));
        assert!(matches!(detect(&[f("a.txt")], None), Err(FilterError::Input(e)) if e.path == "language"));
        assert_eq!(detect(&[f("a.txt")], Some(Language::Urscript)).unwrap(), Language::Urscript);
    }

    #[test]
    fn whole_turns_move_into_the_asked_interval_within_the_limits() {
        let tau = std::f64::consts::TAU;
        let wide = [-7.0, 7.0];
        assert!((into_range(0.2, -tau, 0.0, wide) - (0.2 - tau)).abs() < 1e-15);
        assert_eq!(into_range(-0.2, -tau, 0.0, wide), -0.2);
        assert!((into_range(-0.2, 0.0, tau, wide) - (tau - 0.2)).abs() < 1e-15);
        // Beyond the joint's limits: left where it is.
        assert_eq!(into_range(0.2, -tau, 0.0, [-3.0, 3.0]), 0.2);
    }
}

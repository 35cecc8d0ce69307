//! Cell files — one JSON document, the contract shared by the CLI, the service, tests and benches:
//!
//! ```text
//! { "robot": {"preset": "irb120"} | { …custom model… },
//!   "base_guess": {"x_mm": …, "y_mm": …, "z_mm": …, "a_deg": …, "b_deg": …, "c_deg": …},   (optional)
//!   "artefact": {"kind": "ball_triangle", "distances_mm": {"d12": …, "d13": …, "d23": …}, "ball_diameter_mm": 12.7},
//!   "sessions": [
//!     { "name": "trical-1", "purpose": "identification", "instrument": "trical",
//!       "tool": {"tcp_mm": [x, y, z], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
//!       "order": "measured",
//!       "measurements": [ {"joints_deg": [...], "ball": 1, "temperature_c": 22.0, "time_s": 0.0,
//!                          "sequence": 0, "approach": [1, -1, 1, 1, 1, -1]}, … ] },
//!     { "name": "tracker-1", "purpose": "validation", "instrument": "laser_tracker", "tool": { … },
//!       "measurements": [ {"joints_deg": [...], "position_mm": [x, y, z]}, … ] } ] }
//! ```
//!
//! A measurement is ball-constrained (`ball`, 1-based) or a measured `position_mm` in {W},
//! optionally a full pose (`rotation_deg`, ZY'X''). Errors name the session, the measurement index
//! and the field: `sessions[0] "trical-1".measurements[12].ball: …`.
//!
//! Measuring order: a session's `order` says whether its measurements are listed as measured
//! (`measured`), permuted afterwards (`shuffled`), drawn from measured sessions (`resampled`), or
//! nobody said (`unknown`, the default, omitted when written); a measurement's `sequence` is its
//! place in the measuring order of its run (see [`crate::cell::order`]).

use std::collections::HashSet;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::robot::{RobotSpec, ToolSpec};
use super::{DomainError, finite, from_json, joints_deg, to_deg};
use crate::cell::{Artefact, Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session, Sigma};
use crate::kinematics::Frame;
use crate::kinematics::frame::{rot_zyx, zyx_from_rot};
use crate::metrology::{ArtefactError, BallTriangle};
use crate::units::{DEG, MM};

/// A pose vector in file units: a position in mm and ZY'X'' angles (a about Z, b about Y', c
/// about X'') in deg, e.g. the base guess T_0^W ({0} in {W}).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct PoseXyzAbc {
    /// Position x, mm (±100 000).
    pub x_mm: f64,
    /// Position y, mm (±100 000).
    pub y_mm: f64,
    /// Position z, mm (±100 000).
    pub z_mm: f64,
    /// First ZY'X'' angle, about Z, deg (±360).
    pub a_deg: f64,
    /// Second ZY'X'' angle, about Y', deg (±360).
    pub b_deg: f64,
    /// Third ZY'X'' angle, about X'', deg (±360).
    pub c_deg: f64,
}

impl PoseXyzAbc {
    /// The pose as χ = (x, y, z, a, b, c) in m and rad; refuses a field out of bounds, naming it
    /// under `path` (e.g. `base_guess.z_mm`).
    pub fn to_si(&self, path: &str) -> Result<[f64; 6], DomainError> {
        let v = [self.x_mm, self.y_mm, self.z_mm, self.a_deg, self.b_deg, self.c_deg];
        let names = ["x_mm", "y_mm", "z_mm", "a_deg", "b_deg", "c_deg"];
        let mut out = [0.0; 6];
        for k in 0..6 {
            let field = format!("{path}.{}", names[k]);
            out[k] = if k < 3 {
                super::limits::position_mm(v[k], &field)? * MM
            } else {
                super::limits::angle_deg(v[k], &field)? * DEG
            };
        }
        Ok(out)
    }

    /// The file form of χ = (x, y, z, a, b, c) in m and rad.
    pub fn from_si(chi: &[f64; 6]) -> Self {
        Self {
            x_mm: chi[0] / MM,
            y_mm: chi[1] / MM,
            z_mm: chi[2] / MM,
            a_deg: chi[3] / DEG,
            b_deg: chi[4] / DEG,
            c_deg: chi[5] / DEG,
        }
    }
}

/// The measured distances between the artefact's ball centres, mm; they must form a triangle
/// (not nearly collinear).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct Distances {
    /// Between balls 1 and 2, mm (0.001 to 100 000).
    pub d12: f64,
    /// Between balls 1 and 3, mm (0.001 to 100 000).
    pub d13: f64,
    /// Between balls 2 and 3, mm (0.001 to 100 000).
    pub d23: f64,
}

/// The kind of artefact.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum ArtefactKind {
    /// Three balls on a plate (`ball_triangle`), the TriCal's artefact.
    BallTriangle,
}

/// The artefact of a cell: three balls on a plate whose centres define the world frame {W}
/// (ball 1 at the origin, ball 2 on +X, ball 3 in the XY plane; thesis eq. 4.3–4.7).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct ArtefactSpec {
    /// The kind of artefact: `ball_triangle`.
    pub kind: ArtefactKind,
    /// The measured distances between the ball centres, mm.
    pub distances_mm: Distances,
    /// Diameter of the balls, mm (0.001 to 100 000).
    pub ball_diameter_mm: f64,
}

impl ArtefactSpec {
    /// The ball triangle (ball centres in {W} from the three measured distances, thesis
    /// eq. 4.3–4.7) and the ball diameter, in SI; errors name `distances_mm.d12` … or
    /// `ball_diameter_mm`. The one conversion the cell files, the artefact endpoints and the
    /// pose-plan jobs share.
    pub fn to_artefact(&self) -> Result<Artefact, DomainError> {
        let d = &self.distances_mm;
        use super::limits::{MAX_ARTEFACT_MM, MIN_ARTEFACT_MM, show};
        // The plausible range first: a positive distance below it (5e-324 mm) would reach the
        // triangle as 0 m. Not finite or not positive is the triangle's to say.
        for (field, v) in [("d12", d.d12), ("d13", d.d13), ("d23", d.d23)] {
            let out = if v > MAX_ARTEFACT_MM {
                format!("{} mm is beyond the plausible {MAX_ARTEFACT_MM} mm", show(v))
            } else if v > 0.0 && v < MIN_ARTEFACT_MM {
                format!("{} mm is below the plausible {MIN_ARTEFACT_MM} mm", show(v))
            } else {
                continue;
            };
            return Err(DomainError::new(format!("distances_mm.{field}"), out));
        }
        let triangle = BallTriangle::from_distances(d.d12 * MM, d.d13 * MM, d.d23 * MM).map_err(|e| match e {
            ArtefactError::Distance { field, reason } => DomainError::new(format!("distances_mm.{field}"), reason),
            other => DomainError::new("distances_mm", other.to_string()),
        })?;
        let diameter = self.ball_diameter_mm;
        if !(diameter.is_finite() && diameter > 0.0) {
            return Err(DomainError::new("ball_diameter_mm", "must be a positive number"));
        }
        if diameter < MIN_ARTEFACT_MM {
            return Err(DomainError::new(
                "ball_diameter_mm",
                format!("{} mm is below the plausible {MIN_ARTEFACT_MM} mm", show(diameter)),
            ));
        }
        if diameter > MAX_ARTEFACT_MM {
            return Err(DomainError::new(
                "ball_diameter_mm",
                format!("{} mm is beyond the plausible {MAX_ARTEFACT_MM} mm", show(diameter)),
            ));
        }
        Ok(Artefact { triangle, ball_diameter: diameter * MM })
    }

    /// The specification of an artefact (the inverse of [`ArtefactSpec::to_artefact`]).
    pub fn from_artefact(a: &Artefact) -> Self {
        ArtefactSpec {
            kind: ArtefactKind::BallTriangle,
            distances_mm: Distances { d12: a.triangle.d12 / MM, d13: a.triangle.d13 / MM, d23: a.triangle.d23 / MM },
            ball_diameter_mm: a.ball_diameter / MM,
        }
    }
}

/// What a session is for, as files, the wire and the store spell it: `identification`,
/// `validation`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum PurposeSpec {
    /// Measurements to identify the parameters from (the default identification selection).
    Identification,
    /// Measurements to score an identified parameter set on (the default validation selection).
    Validation,
}

impl PurposeSpec {
    /// The core's purpose.
    pub fn to_purpose(self) -> Purpose {
        match self {
            PurposeSpec::Identification => Purpose::Identification,
            PurposeSpec::Validation => Purpose::Validation,
        }
    }

    /// The file form of a purpose.
    pub fn from_purpose(p: Purpose) -> Self {
        match p {
            Purpose::Identification => PurposeSpec::Identification,
            Purpose::Validation => PurposeSpec::Validation,
        }
    }

    /// The name files, the wire and the store use.
    pub fn as_str(self) -> &'static str {
        self.to_purpose().as_str()
    }
}

/// The instrument of a session, as files, the wire and the store spell it: `trical`,
/// `laser_tracker`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum InstrumentSpec {
    /// Closed loop on the artefact's balls: each measurement names a ball (`ball`).
    Trical,
    /// A laser tracker (or any 3D/6D instrument): each measurement is a position in {W}, maybe
    /// a full pose.
    LaserTracker,
}

impl InstrumentSpec {
    /// The core's instrument.
    pub fn to_instrument(self) -> Instrument {
        match self {
            InstrumentSpec::Trical => Instrument::TriCal,
            InstrumentSpec::LaserTracker => Instrument::LaserTracker,
        }
    }

    /// The file form of an instrument.
    pub fn from_instrument(i: Instrument) -> Self {
        match i {
            Instrument::TriCal => InstrumentSpec::Trical,
            Instrument::LaserTracker => InstrumentSpec::LaserTracker,
        }
    }

    /// The name files, the wire and the store use.
    pub fn as_str(self) -> &'static str {
        match self {
            InstrumentSpec::Trical => "trical",
            InstrumentSpec::LaserTracker => "laser_tracker",
        }
    }
}

/// Whether a session's measurements are listed in measuring order, as files, the wire and the
/// store spell it: `measured`, `shuffled`, `resampled`, `unknown`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(rename_all = "snake_case")]
pub enum OrderSpec {
    /// Listed as measured.
    Measured,
    /// Permuted after measuring: the list says nothing of the measuring order (`time_s` and
    /// `sequence` still do).
    Shuffled,
    /// Drawn from measured sessions (a subset, a bootstrap sample, a selection).
    Resampled,
    /// Not said (the default; cells written before the marker existed).
    #[default]
    Unknown,
}

impl OrderSpec {
    /// The core's measuring order.
    pub fn to_order(self) -> MeasuringOrder {
        match self {
            OrderSpec::Measured => MeasuringOrder::Measured,
            OrderSpec::Shuffled => MeasuringOrder::Shuffled,
            OrderSpec::Resampled => MeasuringOrder::Resampled,
            OrderSpec::Unknown => MeasuringOrder::Unknown,
        }
    }

    /// The file form of a measuring order.
    pub fn from_order(o: MeasuringOrder) -> Self {
        match o {
            MeasuringOrder::Measured => OrderSpec::Measured,
            MeasuringOrder::Shuffled => OrderSpec::Shuffled,
            MeasuringOrder::Resampled => OrderSpec::Resampled,
            MeasuringOrder::Unknown => OrderSpec::Unknown,
        }
    }

    /// `unknown`: not said (and then omitted when written).
    pub fn is_unknown(&self) -> bool {
        *self == OrderSpec::Unknown
    }

    /// The name files, the wire and the store use.
    pub fn as_str(self) -> &'static str {
        match self {
            OrderSpec::Measured => "measured",
            OrderSpec::Shuffled => "shuffled",
            OrderSpec::Resampled => "resampled",
            OrderSpec::Unknown => "unknown",
        }
    }
}

/// The three session enums read back from their stored names (a database column, a form field):
/// the serde spelling, an unknown name an error naming the type.
macro_rules! from_name {
    ($($t:ident),*) => {$(
        impl TryFrom<String> for $t {
            type Error = String;

            fn try_from(s: String) -> Result<Self, String> {
                serde_json::from_value(Value::String(s.clone())).map_err(|_| format!("'{s}' is not a {}", stringify!($t)))
            }
        }
    )*};
}

from_name!(PurposeSpec, InstrumentSpec, OrderSpec);

/// One measurement: the joint readings and what the instrument observed there — a ball of the
/// artefact (`ball`, trical sessions) or a measured position in {W} (`position_mm`, maybe with
/// `rotation_deg`), never both.
#[derive(Clone, Debug, PartialEq, Default, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct MeasurementSpec {
    /// Joint readings, deg, one per joint, each within the robot's joint limits.
    pub joints_deg: Vec<f64>,
    /// The artefact's ball the TCP was centred on (1, 2 or 3); trical sessions only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ball: Option<usize>,
    /// The measured TCP position in {W}, mm (±100 000, and within 3 × the robot's reach of the
    /// base guess when there is one); laser-tracker sessions only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub position_mm: Option<[f64; 3]>,
    /// The measured TCP orientation in {W}, ZY'X'' angles, deg (±360), making the measurement a
    /// full pose; needs `position_mm`. Absent: a position only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub rotation_deg: Option<[f64; 3]>,
    /// Robot temperature, °C (−50 … 150); absent: the reference temperature (20 °C) is assumed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub temperature_c: Option<f64>,
    /// Time stamp of the reading, s, any origin (epoch seconds fit; within ±1e10); gives the
    /// measuring order where the list does not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_s: Option<f64>,
    /// Place in the measuring order of the session's run: increasing as measured; measurements
    /// taken at one stop (several reflectors) share it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence: Option<u64>,
    /// Per joint, the direction of the last motion into the pose: −1, 0 or +1 (one per joint);
    /// absent: not recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<Vec<i8>>,
    /// TriCal indicator readings left after centring (dx, dy, dz), mm (±1 000); trical sessions
    /// only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub indicators_mm: Option<[f64; 3]>,
    /// The instrument's standard uncertainty of this position, 1σ along X, Y, Z of {W}, mm (e.g.
    /// what a laser tracker reports with each reading; each from 1e-6 to 1 000). Without it the
    /// instrument model applies.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub sigma_mm: Option<[f64; 3]>,
    /// The same for the orientation of a full pose, 1σ about X, Y, Z of {W}, deg (each 1e-7 to
    /// 180); needs `rotation_deg` and `sigma_mm`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub sigma_rotation_deg: Option<[f64; 3]>,
}

/// One session of a cell file: measurements taken with one instrument and one tool.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SessionSpec {
    /// The session's name, unique in the cell (1 … 200 characters, not blank).
    pub name: String,
    /// What the session is for: `identification` or `validation`.
    pub purpose: PurposeSpec,
    /// The instrument: `trical` (needs the cell's artefact) or `laser_tracker`.
    pub instrument: InstrumentSpec,
    /// The tool carried: TCP in the flange frame, payload.
    pub tool: ToolSpec,
    /// The tool's TCP is a guess to be identified (e.g. an unmeasured reflector nest).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub identify_tcp: bool,
    /// Whether the measurements are listed in measuring order.
    #[serde(default, skip_serializing_if = "OrderSpec::is_unknown")]
    pub order: OrderSpec,
    /// The physical target (reflector, nest) measured: sessions naming the same target share one
    /// TCP and must declare the same tool. Without it, a session whose TCP is identified gets a
    /// TCP of its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<String>,
    /// The measurements, in the order `order` describes.
    pub measurements: Vec<MeasurementSpec>,
}

/// A cell file: the robot, the approximate base pose, the artefact and the measurement sessions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CellFile {
    /// The robot: `{"preset": "irb120"}` or a custom joint table.
    pub robot: Value,
    /// The base pose T_0^W ({0} in {W}) when known approximately; absent: unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub base_guess: Option<PoseXyzAbc>,
    /// The artefact; needed by trical sessions, absent when there is none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub artefact: Option<ArtefactSpec>,
    /// The measurement sessions.
    pub sessions: Vec<SessionSpec>,
}

/// Parse and validate a cell file.
pub fn parse_cell(text: &str) -> Result<Cell, DomainError> {
    from_json::<CellFile>(text)?.to_cell()
}

/// Serialise a cell (pretty JSON, deterministic).
pub fn cell_to_json(cell: &Cell) -> String {
    serde_json::to_string_pretty(&CellFile::from_cell(cell)).expect("cell serialises")
}

impl CellFile {
    /// Check and convert to SI. Errors name the session and measurement, e.g.
    /// `sessions[0] "trical-1".measurements[12].ball`: a duplicate session name, a target shared
    /// with another tool, a trical session without an artefact, a bad robot, tool or measurement.
    pub fn to_cell(&self) -> Result<Cell, DomainError> {
        let model =
            RobotSpec::from_json_value(&self.robot).and_then(|r| r.to_model()).map_err(|e| e.within("robot"))?;
        let base_guess = self.base_guess.as_ref().map(|b| b.to_si("base_guess")).transpose()?;
        let artefact = self.artefact.as_ref().map(|a| a.to_artefact().map_err(|e| e.within("artefact"))).transpose()?;
        let mut names = HashSet::new();
        let mut targets: std::collections::HashMap<&str, (usize, &ToolSpec)> = Default::default();
        let bounds = position_bounds(&model, base_guess.as_ref());
        let mut sessions = Vec::with_capacity(self.sessions.len());
        for (si, s) in self.sessions.iter().enumerate() {
            let at = format!("sessions[{si}] \"{}\"", s.name);
            super::limits::name(&s.name, &format!("sessions[{si}].name"))?;
            if !names.insert(s.name.clone()) {
                return Err(DomainError::new(format!("{at}.name"), "another session has this name"));
            }
            let tool = s.tool.to_tool().map_err(|e| e.within(&format!("{at}.tool")))?;
            if let Some(t) = &s.target {
                super::limits::name(t, &format!("{at}.target"))?;
                match targets.get(t.as_str()) {
                    Some((first, other)) if *other != &s.tool => {
                        return Err(DomainError::new(
                            format!("{at}.target"),
                            format!(
                                "session \"{}\" names target '{t}' with another tool: sessions sharing a target declare the same tool",
                                self.sessions[*first].name
                            ),
                        ));
                    }
                    Some(_) => {}
                    None => {
                        targets.insert(t, (si, &s.tool));
                    }
                }
            }
            let instrument = s.instrument.to_instrument();
            if instrument == Instrument::TriCal && artefact.is_none() {
                return Err(DomainError::new(format!("{at}.instrument"), "a trical session needs the cell's artefact"));
            }
            let mut measurements = Vec::with_capacity(s.measurements.len());
            for (mi, m) in s.measurements.iter().enumerate() {
                let mp = format!("{at}.measurements[{mi}]");
                measurements
                    .push(measurement(m, &model, instrument, artefact.as_ref(), &bounds).map_err(|e| e.within(&mp))?);
            }
            sessions.push(Session {
                name: s.name.clone(),
                purpose: s.purpose.to_purpose(),
                instrument,
                tool,
                identify_tcp: s.identify_tcp,
                target: s.target.clone(),
                measurements,
                order: s.order.to_order(),
            });
        }
        Ok(Cell { model, base_guess, artefact, sessions })
    }

    /// The file form of a cell, in mm and degrees.
    pub fn from_cell(c: &Cell) -> CellFile {
        CellFile {
            robot: RobotSpec::from_model(&c.model).to_json_value(),
            base_guess: c.base_guess.as_ref().map(PoseXyzAbc::from_si),
            artefact: c.artefact.as_ref().map(ArtefactSpec::from_artefact),
            sessions: c
                .sessions
                .iter()
                .map(|s| SessionSpec {
                    name: s.name.clone(),
                    purpose: PurposeSpec::from_purpose(s.purpose),
                    instrument: InstrumentSpec::from_instrument(s.instrument),
                    tool: ToolSpec::from_tool(&s.tool),
                    identify_tcp: s.identify_tcp,
                    order: OrderSpec::from_order(s.order),
                    target: s.target.clone(),
                    measurements: s.measurements.iter().map(measurement_spec).collect(),
                })
                .collect(),
        }
    }
}

/// Where a robot's measured positions may lie (domain::limits): within
/// [`super::limits::REACH_MULTIPLE`] times its reach of its base guess, and ±100 m anyway.
pub fn position_bounds(
    model: &crate::kinematics::RobotModel,
    base_guess: Option<&[f64; 6]>,
) -> super::limits::PositionBounds {
    let reach_mm: f64 = model.links.iter().map(|l| l.a.abs() + l.d.abs()).sum::<f64>() / MM;
    super::limits::PositionBounds::of(reach_mm, base_guess.map(|b| [b[0] / MM, b[1] / MM, b[2] / MM]))
}

/// Validate one measurement against the robot, the session's instrument and the artefact (SI),
/// and against the physical bounds (`bounds`: where the robot's positions may lie).
pub fn measurement(
    m: &MeasurementSpec,
    model: &crate::kinematics::RobotModel,
    instrument: Instrument,
    artefact: Option<&Artefact>,
    bounds: &super::limits::PositionBounds,
) -> Result<Measurement, DomainError> {
    let q = joints_deg(&m.joints_deg, model.dof(), "joints_deg")?;
    for (j, &v) in q.iter().enumerate() {
        if !model.within_limits(j, v) {
            let [lo, hi] = model.links[j].limits;
            let shown = if (v / DEG).abs() < 1e9 { format!("{:.4}", v / DEG) } else { super::limits::show(v / DEG) };
            return Err(DomainError::new(
                format!("joints_deg[{j}]"),
                format!("{shown}° is outside joint {}'s limits [{:.1}°, {:.1}°]", j + 1, lo / DEG, hi / DEG),
            ));
        }
    }
    let observation = match (m.ball, m.position_mm, m.rotation_deg) {
        (Some(_), Some(_), _) => return Err(DomainError::new("ball", "give ball or position_mm, not both")),
        (Some(k), None, None) => {
            if instrument != Instrument::TriCal {
                return Err(DomainError::new("ball", "ball-constrained measurements belong to a trical session"));
            }
            let a = artefact.ok_or_else(|| DomainError::new("ball", "the cell has no artefact"))?;
            if a.triangle.ball(k).is_none() {
                return Err(DomainError::new("ball", format!("ball {k} is not on the artefact (balls 1, 2, 3)")));
            }
            Observation::Ball(k)
        }
        (Some(_), None, Some(_)) => {
            return Err(DomainError::new("rotation_deg", "only a measured position can carry a rotation"));
        }
        (None, Some(p), rot) => {
            if instrument == Instrument::TriCal {
                return Err(DomainError::new("position_mm", "a trical session measures balls: give ball"));
            }
            bounds.check(p, "position_mm")?;
            let t = super::vec3_mm(p, "position_mm")?;
            match rot {
                None => Observation::Position(t),
                Some(r) => {
                    super::limits::angle3_deg(r, "rotation_deg")?;
                    Observation::Pose(Frame::new(rot_zyx(r[0] * DEG, r[1] * DEG, r[2] * DEG), t))
                }
            }
        }
        (None, None, _) => return Err(DomainError::new("ball", "a measurement needs ball or position_mm")),
    };
    let temperature_c = m.temperature_c.map(|t| finite(t, "temperature_c")).transpose()?;
    let [t_lo, t_hi] = super::limits::TEMPERATURE_C;
    if let Some(t) = temperature_c
        && !(t_lo..=t_hi).contains(&t)
    {
        return Err(DomainError::new(
            "temperature_c",
            format!("{t} °C is not a plausible robot temperature ([{t_lo}, {t_hi}] °C)"),
        ));
    }
    let time_s = m.time_s.map(|t| super::limits::time_s(t, "time_s")).transpose()?;
    if let Some(a) = &m.approach {
        if a.len() != model.dof() {
            return Err(DomainError::new("approach", format!("expected {} values, got {}", model.dof(), a.len())));
        }
        if let Some(i) = a.iter().position(|v| !(-1..=1).contains(v)) {
            return Err(DomainError::new(format!("approach[{i}]"), "must be -1, 0 or 1"));
        }
    }
    let indicators = match m.indicators_mm {
        None => None,
        Some(d) => {
            if instrument != Instrument::TriCal {
                return Err(DomainError::new("indicators_mm", "only a trical measurement has indicator readings"));
            }
            for (i, x) in d.iter().enumerate() {
                let m = super::limits::MAX_INDICATOR_MM;
                super::limits::within(*x, -m, m, "mm", &format!("indicators_mm[{i}]"))?;
            }
            let v = super::vec3_mm(d, "indicators_mm")?;
            Some([v.x, v.y, v.z])
        }
    };
    let sigma = match (m.sigma_mm, m.sigma_rotation_deg) {
        (None, None) => None,
        (None, Some(_)) => {
            return Err(DomainError::new("sigma_rotation_deg", "give sigma_mm too (the position's σ)"));
        }
        (Some(p), r) => {
            let position = positive3(p, MM, super::limits::MIN_SIGMA_MM, super::limits::MAX_SIGMA_MM, "sigma_mm")?;
            let rotation = match r {
                None => None,
                Some(_) if !matches!(observation, Observation::Pose(_)) => {
                    return Err(DomainError::new("sigma_rotation_deg", "only a full pose (rotation_deg) has one"));
                }
                Some(r) => Some(positive3(
                    r,
                    DEG,
                    super::limits::MIN_SIGMA_DEG,
                    super::limits::MAX_SIGMA_DEG,
                    "sigma_rotation_deg",
                )?),
            };
            Some(Sigma { position, rotation })
        }
    };
    Ok(Measurement {
        q,
        observation,
        temperature_c,
        time_s,
        sequence: m.sequence,
        approach: m.approach.clone(),
        indicators,
        sigma,
    })
}

/// Three standard deviations in file units → SI, each finite, positive and at most `max`.
fn positive3(v: [f64; 3], unit: f64, min: f64, max: f64, path: &str) -> Result<[f64; 3], DomainError> {
    let mut out = [0.0; 3];
    for i in 0..3 {
        if !(v[i].is_finite() && v[i] > 0.0) {
            return Err(DomainError::new(format!("{path}[{i}]"), "must be a positive number (1σ)"));
        }
        if v[i] < min {
            return Err(DomainError::new(
                format!("{path}[{i}]"),
                format!("{} is below the plausible {} (1σ)", super::limits::show(v[i]), super::limits::show(min)),
            ));
        }
        if v[i] > max {
            return Err(DomainError::new(
                format!("{path}[{i}]"),
                format!("{} is beyond the plausible {max} (1σ)", super::limits::show(v[i])),
            ));
        }
        out[i] = v[i] * unit;
    }
    Ok(out)
}

fn measurement_spec(m: &Measurement) -> MeasurementSpec {
    let (ball, position_mm, rotation_deg) = match &m.observation {
        Observation::Ball(k) => (Some(*k), None, None),
        Observation::Position(p) => (None, Some([p.x / MM, p.y / MM, p.z / MM]), None),
        Observation::Pose(f) => {
            let [a, b, c] = zyx_from_rot(&f.r);
            (None, Some([f.t.x / MM, f.t.y / MM, f.t.z / MM]), Some([a / DEG, b / DEG, c / DEG]))
        }
    };
    MeasurementSpec {
        joints_deg: to_deg(&m.q),
        ball,
        position_mm,
        rotation_deg,
        temperature_c: m.temperature_c,
        time_s: m.time_s,
        sequence: m.sequence,
        approach: m.approach.clone(),
        indicators_mm: m.indicators.map(|d| [d[0] / MM, d[1] / MM, d[2] / MM]),
        sigma_mm: m.sigma.map(|s| s.position.map(|v| v / MM)),
        sigma_rotation_deg: m.sigma.and_then(|s| s.rotation).map(|r| r.map(|v| v / DEG)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    /// The names the store binds (`as_str`) are the serde names it reads back (`TryFrom<String>`),
    /// for every variant; an unknown name is refused naming the type.
    #[test]
    fn stored_names_round_trip() {
        fn check<T: Serialize + TryFrom<String, Error = String> + PartialEq + std::fmt::Debug + Copy>(
            all: &[T],
            name: impl Fn(T) -> &'static str,
        ) {
            for &v in all {
                assert_eq!(serde_json::to_value(v).unwrap(), Value::String(name(v).to_string()));
                assert_eq!(T::try_from(name(v).to_string()), Ok(v));
            }
        }
        check(&[PurposeSpec::Identification, PurposeSpec::Validation], PurposeSpec::as_str);
        check(&[InstrumentSpec::Trical, InstrumentSpec::LaserTracker], InstrumentSpec::as_str);
        use OrderSpec::*;
        check(&[Measured, Shuffled, Resampled, Unknown], OrderSpec::as_str);
        assert_eq!(OrderSpec::try_from("sorted".to_string()), Err("'sorted' is not a OrderSpec".to_string()));
    }

    fn good() -> Value {
        json!({
            "robot": {"preset": "irb120"},
            "base_guess": {"x_mm": 160.0, "y_mm": -255.0, "z_mm": -220.0, "a_deg": 91.6, "b_deg": 0.5, "c_deg": -1.4},
            "artefact": {"kind": "ball_triangle", "distances_mm": {"d12": 300.0, "d13": 300.0, "d23": 300.0}, "ball_diameter_mm": 12.7},
            "sessions": [
                {"name": "trical-1", "purpose": "identification", "instrument": "trical",
                 "tool": {"tcp_mm": [40, 0, 130], "mass_kg": 1.7, "com_mm": [30, 0, 64]},
                 "measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "ball": 2, "temperature_c": 22.0, "time_s": 0.0, "approach": [1, -1, 1, 1, 1, -1]}]},
                {"name": "tracker-1", "purpose": "validation", "instrument": "laser_tracker",
                 "tool": {"tcp_mm": [40, 0, 130]},
                 "measurements": [{"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [1, 2, 3]},
                                  {"joints_deg": [0, 10, 20, 0, 30, 0], "position_mm": [1, 2, 3], "rotation_deg": [10, 20, 30]}]}]
        })
    }

    #[test]
    fn a_cell_round_trips() {
        let cell = CellFile::from_cell(&from_json::<CellFile>(&good().to_string()).unwrap().to_cell().unwrap());
        let text = serde_json::to_string_pretty(&cell).unwrap();
        let back = parse_cell(&text).unwrap();
        assert_eq!(cell_to_json(&back), text);
        assert_eq!(back.sessions[0].measurements[0].observation, Observation::Ball(2));
        assert!(matches!(back.sessions[1].measurements[1].observation, Observation::Pose(_)));
        assert!((back.base_guess.unwrap()[3] - 91.6 * DEG).abs() < 1e-15);
    }

    /// `order` and `sequence` survive the file: the marker is written unless unknown, a sequence
    /// number is kept exactly, an unknown marker is refused at its path.
    #[test]
    fn measuring_order_round_trips() {
        let mut v = good();
        v["sessions"][1]["order"] = json!("shuffled");
        v["sessions"][1]["measurements"][0]["sequence"] = json!(7);
        v["sessions"][1]["measurements"][1]["sequence"] = json!(u64::MAX);
        let cell = parse_cell(&v.to_string()).unwrap();
        assert_eq!(cell.sessions[0].order, MeasuringOrder::Unknown);
        assert_eq!(cell.sessions[1].order, MeasuringOrder::Shuffled);
        assert_eq!(cell.sessions[1].measurements[0].sequence, Some(7));
        assert_eq!(cell.sessions[1].measurements[1].sequence, Some(u64::MAX));
        assert_eq!(cell.sessions[0].measurements[0].sequence, None);
        let text = cell_to_json(&cell);
        assert_eq!(parse_cell(&text).unwrap(), cell);
        let back: Value = serde_json::from_str(&text).unwrap();
        assert!(back["sessions"][0].get("order").is_none(), "unknown is the default, not written");
        assert_eq!(back["sessions"][1]["order"], "shuffled");
        assert_eq!(back["sessions"][1]["measurements"][1]["sequence"], json!(u64::MAX));
        for (order, want) in [("measured", MeasuringOrder::Measured), ("resampled", MeasuringOrder::Resampled)] {
            v["sessions"][1]["order"] = json!(order);
            assert_eq!(parse_cell(&v.to_string()).unwrap().sessions[1].order, want);
        }
        v["sessions"][1]["order"] = json!("sorted");
        assert_eq!(parse_cell(&v.to_string()).unwrap_err().path, "sessions[1].order");
        let mut v = good();
        v["sessions"][1]["measurements"][0]["sequence"] = json!(-1);
        assert_eq!(parse_cell(&v.to_string()).unwrap_err().path, "sessions[1].measurements[0].sequence");
    }

    /// A shared target and per-measurement σ read, convert and round-trip; their errors name the
    /// field.
    #[test]
    fn targets_and_sigmas() {
        let mut v = good();
        v["sessions"][1]["target"] = json!("nest-1");
        v["sessions"][1]["identify_tcp"] = json!(true);
        v["sessions"][1]["measurements"][1]["sigma_mm"] = json!([0.01, 0.02, 0.005]);
        v["sessions"][1]["measurements"][1]["sigma_rotation_deg"] = json!([0.001, 0.002, 0.003]);
        let cell = parse_cell(&v.to_string()).unwrap();
        assert_eq!(cell.sessions[1].target.as_deref(), Some("nest-1"));
        let s = cell.sessions[1].measurements[1].sigma.unwrap();
        assert!((s.position[1] - 20e-6).abs() < 1e-18 && (s.rotation.unwrap()[2] - 0.003 * DEG).abs() < 1e-18);
        assert_eq!(cell_to_json(&parse_cell(&cell_to_json(&cell)).unwrap()), cell_to_json(&cell));
        assert!(cell_to_json(&cell).contains("\"sigma_mm\""));

        let check = |edit: &dyn Fn(&mut Value), path: &str, needle: &str| {
            let mut w = v.clone();
            edit(&mut w);
            let e = parse_cell(&w.to_string()).unwrap_err();
            assert_eq!(e.path, path, "{e}");
            assert!(e.reason.contains(needle), "{e}");
        };
        let m1 = "sessions[1] \"tracker-1\".measurements[1]";
        check(
            &|w| w["sessions"][1]["measurements"][1]["sigma_mm"][2] = json!(0.0),
            &format!("{m1}.sigma_mm[2]"),
            "positive",
        );
        // Positive but below a nanometre: 5e-324 mm is 0 m once converted, a weight of ∞.
        check(
            &|w| w["sessions"][1]["measurements"][1]["sigma_mm"][0] = json!(5e-324),
            &format!("{m1}.sigma_mm[0]"),
            "below the plausible",
        );
        check(
            &|w| w["sessions"][1]["measurements"][0]["sigma_rotation_deg"] = json!([1, 1, 1]),
            "sessions[1] \"tracker-1\".measurements[0].sigma_rotation_deg",
            "sigma_mm",
        );
        check(
            &|w| {
                w["sessions"][1]["measurements"][0]["sigma_mm"] = json!([1, 1, 1]);
                w["sessions"][1]["measurements"][0]["sigma_rotation_deg"] = json!([1, 1, 1]);
            },
            "sessions[1] \"tracker-1\".measurements[0].sigma_rotation_deg",
            "full pose",
        );
        // Sessions sharing a target declare one tool.
        check(&|w| w["sessions"][0]["target"] = json!("nest-1"), "sessions[1] \"tracker-1\".target", "same tool");
        check(&|w| w["sessions"][1]["target"] = json!(" "), "sessions[1] \"tracker-1\".target", "empty");
    }

    /// One conversion for every artefact: a round trip, and errors at the spec's own fields.
    #[test]
    fn artefact_specs_convert_once() {
        let spec: ArtefactSpec = serde_json::from_value(good()["artefact"].clone()).unwrap();
        assert_eq!(ArtefactSpec::from_artefact(&spec.to_artefact().unwrap()), spec);
        let bad = |edit: &dyn Fn(&mut ArtefactSpec)| {
            let mut s = spec.clone();
            edit(&mut s);
            s.to_artefact().unwrap_err().path
        };
        assert_eq!(bad(&|s| s.distances_mm.d13 = -1.0), "distances_mm.d13");
        assert_eq!(bad(&|s| s.distances_mm.d23 = 700.0), "distances_mm");
        assert_eq!(bad(&|s| s.ball_diameter_mm = 0.0), "ball_diameter_mm");
        assert_eq!(bad(&|s| s.ball_diameter_mm = f64::NAN), "ball_diameter_mm");
        // Positive but below a micrometre (5e-324 mm is 0 m once converted): refused, not a
        // degenerate triangle.
        assert_eq!(bad(&|s| s.ball_diameter_mm = 5e-324), "ball_diameter_mm");
        assert_eq!(bad(&|s| s.distances_mm.d13 = 5e-324), "distances_mm.d13");
    }

    /// Each promised error, with the session, measurement index and field in its path.
    #[test]
    fn bad_cells_name_session_measurement_and_field() {
        let check = |edit: &dyn Fn(&mut Value), path: &str, needle: &str| {
            let mut v = good();
            edit(&mut v);
            let e = parse_cell(&v.to_string()).unwrap_err();
            assert_eq!(e.path, path, "{e}");
            assert!(e.reason.contains(needle), "{e}");
        };
        let m0 = "sessions[0] \"trical-1\".measurements[0]";
        check(
            &|v| v["sessions"][0]["measurements"][0]["joints_deg"] = json!([0, 1, 2]),
            &format!("{m0}.joints_deg"),
            "expected 6",
        );
        check(
            &|v| v["sessions"][0]["measurements"][0]["joints_deg"][4] = json!(150.0),
            &format!("{m0}.joints_deg[4]"),
            "outside",
        );
        check(
            &|v| v["sessions"][0]["measurements"][0]["ball"] = json!(4),
            &format!("{m0}.ball"),
            "not on the artefact",
        );
        check(
            &|v| v["sessions"][0]["measurements"][0]["approach"] = json!([1, 2, 1, 1, 1, 1]),
            &format!("{m0}.approach[1]"),
            "-1, 0 or 1",
        );
        check(
            &|v| v["sessions"][0]["measurements"][0]["temperature_c"] = json!(900.0),
            &format!("{m0}.temperature_c"),
            "plausible",
        );
        check(
            &|v| v["sessions"][1]["measurements"][0]["ball"] = json!(1),
            "sessions[1] \"tracker-1\".measurements[0].ball",
            "not both",
        );
        check(&|v| v["sessions"][1]["name"] = json!("trical-1"), "sessions[1] \"trical-1\".name", "another session");
        check(&|v| v["artefact"]["distances_mm"]["d23"] = json!(700.0), "artefact.distances_mm", "impossible");
        check(&|v| v["artefact"]["distances_mm"]["d12"] = json!(-1.0), "artefact.distances_mm.d12", "positive");
        check(
            &|v| v["sessions"][0]["tool"]["mass_kg"] = json!(-2.0),
            "sessions[0] \"trical-1\".tool.mass_kg",
            "negative",
        );
        // Unknown keys and JSON-level errors carry serde's path.
        let mut v = good();
        v["sessions"][0]["measurements"][0]["colour"] = json!("red");
        let e = parse_cell(&v.to_string()).unwrap_err();
        assert_eq!(e.path, "sessions[0].measurements[0].colour");
        assert!(e.reason.contains("colour"), "{e}");
        let mut v = good();
        v["sessions"][0]["measurements"][0]["joints_deg"][1] = json!("NaN");
        let e = parse_cell(&v.to_string()).unwrap_err();
        assert_eq!(e.path, "sessions[0].measurements[0].joints_deg[1]", "{e}");
    }
}

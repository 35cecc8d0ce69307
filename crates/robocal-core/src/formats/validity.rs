//! Where a parameter set may be trusted, and how well.
//!
//! - The **calibrated envelope**: the joint ranges its identification measurements (and a held-out
//!   validation's) covered, widened by a stated margin. A model identified from data extrapolates
//!   outside them, so compensation refuses a target there unless asked. The box of {W} they were
//!   measured in is kept too: a target outside it is noted with its distance (the thesis's
//!   Fig. 5.16: the error grows with the distance to the calibration zone), not refused.
//! - The **predicted uncertainty** of the TCP position at a pose: σ = √trace(J·Cov·Jᵀ), J the
//!   position Jacobian with respect to the free parameters and Cov their covariance from the
//!   identification (σ̂²(JᵀJ)⁻¹, stored as standard deviations and a correlation matrix).
//!
//! Both come from the parameter set's document (`quality.envelope`, `quality.free`,
//! `quality.correlation`, each parameter's `std`); a set without them (a table typed in, an old
//! export) has no envelope to check and no uncertainty to give, and compensation says so.

use nalgebra::{DMatrix, Vector3};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::DomainError;
use super::param_set::ParameterSetDoc;
use crate::identify::Identification;
use crate::kinematics::{Chain, JointState, ParamLayout, Rows};
use crate::units::{DEG, MM};
use crate::validate::report::Region;

/// Margin added on both sides of each joint's calibrated range, deg.
pub const JOINT_MARGIN_DEG: f64 = 5.0;
/// Margin added on every side of the calibrated box of {W}, mm.
pub const POSITION_MARGIN_MM: f64 = 50.0;

/// The calibrated envelope as a parameter set's quality report stores it (`quality.envelope`),
/// in degrees and millimetres; the ranges are the measured ones, the margins apply on top.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[serde(deny_unknown_fields)]
pub struct EnvelopeFile {
    /// Per joint, [min, max] of the identification measurements, deg.
    #[cfg_attr(feature = "openapi", schema(value_type = Vec<JointRangeDeg>))]
    pub joints_deg: Vec<[f64; 2]>,
    /// The measured TCP positions' box in {W}: lower corner, mm.
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub position_min_mm: [f64; 3],
    /// Upper corner, mm.
    #[cfg_attr(feature = "openapi", schema(min_items = 3, max_items = 3))]
    pub position_max_mm: [f64; 3],
    /// Widening of each joint range on both sides, deg.
    pub joint_margin_deg: f64,
    /// Widening of the box on every side, mm.
    pub position_margin_mm: f64,
    /// Measurements the envelope was taken from.
    pub n_measurements: usize,
}

/// A joint's calibrated range in the OpenAPI document: [min, max], deg (two numbers, as
/// `EnvelopeFile::joints_deg` reads them).
#[cfg(feature = "openapi")]
pub struct JointRangeDeg;

#[cfg(feature = "openapi")]
impl utoipa::PartialSchema for JointRangeDeg {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        use utoipa::openapi::schema::{ArrayBuilder, ObjectBuilder, Type};
        ArrayBuilder::new()
            .items(
                ObjectBuilder::new()
                    .schema_type(Type::Number)
                    .format(Some(utoipa::openapi::SchemaFormat::KnownFormat(utoipa::openapi::KnownFormat::Double))),
            )
            .min_items(Some(2))
            .max_items(Some(2))
            .description(Some("[min, max], deg."))
            .into()
    }
}

#[cfg(feature = "openapi")]
impl utoipa::ToSchema for JointRangeDeg {}

/// The envelope in SI, margins included.
#[derive(Clone, Debug, PartialEq)]
pub struct Envelope {
    joints: Vec<(f64, f64)>,
    lo: Vector3<f64>,
    hi: Vector3<f64>,
    file: EnvelopeFile,
}

impl Envelope {
    /// The envelope of measurements given as (joints in rad, measured position in {W} in m).
    /// `None` without measurements.
    pub fn of_measurements<'a>(points: impl IntoIterator<Item = (&'a [f64], Vector3<f64>)>) -> Option<Envelope> {
        Region::of(points).and_then(|r| Envelope::of_region(&r))
    }

    /// The envelope of a region (the margins added); `None` when the region's figures do not
    /// make one (a coordinate beyond a double in mm).
    pub fn of_region(r: &Region) -> Option<Envelope> {
        let file = EnvelopeFile {
            joints_deg: r.joints.iter().map(|j| [j[0] / DEG, j[1] / DEG]).collect(),
            position_min_mm: [r.lo.x / MM, r.lo.y / MM, r.lo.z / MM],
            position_max_mm: [r.hi.x / MM, r.hi.y / MM, r.hi.z / MM],
            joint_margin_deg: JOINT_MARGIN_DEG,
            position_margin_mm: POSITION_MARGIN_MM,
            n_measurements: r.n,
        };
        Envelope::from_file(&file).ok()
    }

    /// The smallest envelope holding both (measured ranges joined, the larger margins): the
    /// identification's data and a held-out validation's, where the model was shown to hold.
    pub fn union(&self, other: &Envelope) -> Envelope {
        let (a, b) = (&self.file, &other.file);
        let n = a.joints_deg.len().min(b.joints_deg.len());
        let file = EnvelopeFile {
            joints_deg: (0..n)
                .map(|j| [a.joints_deg[j][0].min(b.joints_deg[j][0]), a.joints_deg[j][1].max(b.joints_deg[j][1])])
                .collect(),
            position_min_mm: std::array::from_fn(|k| a.position_min_mm[k].min(b.position_min_mm[k])),
            position_max_mm: std::array::from_fn(|k| a.position_max_mm[k].max(b.position_max_mm[k])),
            joint_margin_deg: a.joint_margin_deg.max(b.joint_margin_deg),
            position_margin_mm: a.position_margin_mm.max(b.position_margin_mm),
            n_measurements: a.n_measurements + b.n_measurements,
        };
        Envelope::from_file(&file).expect("the union of two valid envelopes is valid")
    }

    /// The envelope of an identification's measurements (those it used).
    pub fn of_identification(id: &Identification) -> Option<Envelope> {
        let dof = id.set.dof();
        Envelope::of_measurements(id.problem.obs.iter().map(|o| (&o.state.q[..dof], o.measured_position())))
    }

    /// Check a stored envelope.
    pub fn from_file(f: &EnvelopeFile) -> Result<Envelope, DomainError> {
        let bad = |path: &str, why: &str| Err(DomainError::new(path, why));
        if !(f.joint_margin_deg.is_finite() && f.joint_margin_deg >= 0.0) {
            return bad("joint_margin_deg", "must be a finite number ≥ 0");
        }
        if !(f.position_margin_mm.is_finite() && f.position_margin_mm >= 0.0) {
            return bad("position_margin_mm", "must be a finite number ≥ 0");
        }
        let mut joints = Vec::with_capacity(f.joints_deg.len());
        for (j, r) in f.joints_deg.iter().enumerate() {
            if !(r[0].is_finite() && r[1].is_finite() && r[0] <= r[1]) {
                return bad(&format!("joints_deg[{j}]"), "must be [min, max], finite, min ≤ max");
            }
            joints.push(((r[0] - f.joint_margin_deg) * DEG, (r[1] + f.joint_margin_deg) * DEG));
        }
        let (lo, hi) = (Vector3::from(f.position_min_mm), Vector3::from(f.position_max_mm));
        for k in 0..3 {
            if !(lo[k].is_finite() && hi[k].is_finite() && lo[k] <= hi[k]) {
                return bad("position_min_mm", "the box's corners must be finite, lower ≤ upper");
            }
        }
        let m = Vector3::repeat(f.position_margin_mm);
        Ok(Envelope { joints, lo: (lo - m) * MM, hi: (hi + m) * MM, file: f.clone() })
    }

    /// The envelope as its file records it: the measured ranges and the margins, in mm and deg.
    pub fn file(&self) -> &EnvelopeFile {
        &self.file
    }

    /// Each joint's range, margin included, rad.
    pub fn joint_ranges(&self) -> &[(f64, f64)] {
        &self.joints
    }

    /// Why joints `q` (rad) lie outside the calibrated joint ranges, or `None` inside. The
    /// envelope is judged in joint space: the model's parameters are excited by joint motion,
    /// and a TriCal calibration measures a small zone of {W} from many configurations. The model
    /// is a function of each joint angle modulo one turn (geometry and gravity torques alike), so
    /// an angle a whole turn away from a calibrated one is inside.
    pub fn outside(&self, q: &[f64]) -> Option<String> {
        let f = &self.file;
        for (j, (&v, &(lo, hi))) in q.iter().zip(&self.joints).enumerate() {
            let beyond = (-2..=2)
                .map(|k| v + f64::from(k) * std::f64::consts::TAU)
                .map(|x| {
                    if x < lo {
                        lo - x
                    } else if x > hi {
                        x - hi
                    } else {
                        0.0
                    }
                })
                .fold(f64::INFINITY, f64::min);
            if beyond > 0.0 {
                return Some(format!(
                    "joint {} at {:.3}° (or a turn away) is {:.3}° beyond the calibrated range [{:.3}, {:.3}]° (measured range ± {}°)",
                    j + 1,
                    v / DEG,
                    beyond / DEG,
                    f.joints_deg[j][0],
                    f.joints_deg[j][1],
                    f.joint_margin_deg
                ));
            }
        }
        None
    }

    /// How far the TCP position `p` ({W}, m) lies from the measured box (margin included), when
    /// it lies outside: a note, not a refusal (the error grows with that distance, thesis
    /// Fig. 5.16; the held-out validation says by how much).
    pub fn distance_note(&self, p: &Vector3<f64>) -> Option<String> {
        let out = (p - self.hi).sup(&(self.lo - p)).sup(&Vector3::zeros());
        (out.max() > 0.0).then(|| {
            format!(
                "the TCP is {:.1} mm outside the measured region of {{W}} (its box ± {} mm)",
                out.norm() / MM,
                self.file.position_margin_mm
            )
        })
    }

    /// How far the TCP position `p` ({W}, m) lies outside the *measured* box (no margin), m; 0
    /// inside. The distance the error's growth outside the measured region is charged for.
    pub fn outside_measured(&self, p: &Vector3<f64>) -> f64 {
        let (lo, hi) = (Vector3::from(self.file.position_min_mm) * MM, Vector3::from(self.file.position_max_mm) * MM);
        (p - hi).sup(&(lo - p)).sup(&Vector3::zeros()).norm()
    }

    /// The envelope a parameter-set document records, if any.
    pub fn of_doc(doc: &ParameterSetDoc) -> Result<Option<Envelope>, DomainError> {
        let Some(f) = doc.quality.as_ref().and_then(|q| q.envelope.as_ref()) else { return Ok(None) };
        Envelope::from_file(f).map(Some).map_err(|e| e.within("quality.envelope"))
    }
}

/// The free parameters' covariance, on the layout columns it concerns (SI).
#[derive(Clone, Debug, PartialEq)]
pub struct PredictionCovariance {
    layout: ParamLayout,
    /// Layout column of each covariance row.
    cols: Vec<usize>,
    /// Whether each row is a tool parameter (dropped when the targets use another tool).
    tool: Vec<bool>,
    cov: DMatrix<f64>,
}

impl PredictionCovariance {
    /// From a parameter-set document: the free parameters (`quality.free`), their correlation
    /// (`quality.correlation`) and standard deviations (`std`). `None` when the document carries
    /// no covariance; an error when it carries a malformed one.
    pub fn of_doc(doc: &ParameterSetDoc) -> Result<Option<PredictionCovariance>, DomainError> {
        let Some(q) = doc.quality.as_ref() else { return Ok(None) };
        let (Some(free), Some(corr)) = (&q.free, &q.correlation) else { return Ok(None) };
        let m = free.len();
        if corr.len() != m || corr.iter().any(|r| r.len() != m) {
            return Err(DomainError::new(
                "quality.correlation",
                format!("must be {m} × {m}, one row per free parameter"),
            ));
        }
        let layout = &doc.set.layout;
        // Free parameters of this set's layout (others: a second tool's block) with their σ.
        let mut rows = Vec::new();
        for (a, name) in free.iter().enumerate() {
            let Some(c) = layout.find(name) else { continue };
            let Some(s) = doc.std[c] else {
                return Err(DomainError::new("parameters", format!("free parameter '{name}' has no std")));
            };
            let is_tool = matches!(layout.params()[c], crate::kinematics::Param::Tool(_));
            rows.push((a, c, s, is_tool));
        }
        let n = rows.len();
        // An undefined correlation (`null`, written for NaN) makes the covariance unusable.
        let cov = DMatrix::from_fn(n, n, |i, j| rows[i].2 * rows[j].2 * corr[rows[i].0][rows[j].0].unwrap_or(f64::NAN));
        if cov.iter().any(|v| !v.is_finite()) {
            return Err(DomainError::new("quality.correlation", "must be finite"));
        }
        Ok(Some(PredictionCovariance {
            layout: layout.clone(),
            cols: rows.iter().map(|r| r.1).collect(),
            tool: rows.iter().map(|r| r.3).collect(),
            cov,
        }))
    }

    /// The same without the tool's parameters: for targets with a tool the identification did not
    /// see, only the robot's parameters carry uncertainty.
    pub fn without_tool(&self) -> PredictionCovariance {
        let keep: Vec<usize> = (0..self.cols.len()).filter(|&i| !self.tool[i]).collect();
        PredictionCovariance {
            layout: self.layout.clone(),
            cols: keep.iter().map(|&i| self.cols[i]).collect(),
            tool: vec![false; keep.len()],
            cov: DMatrix::from_fn(keep.len(), keep.len(), |i, j| self.cov[(keep[i], keep[j])]),
        }
    }

    /// Standard uncertainty of the TCP position at state `s` of `chain` (the calibrated chain of
    /// the same layout): √trace(J·Cov·Jᵀ), m.
    pub fn sigma(&self, chain: &Chain, s: &JointState) -> f64 {
        let n = self.cols.len();
        let mut buf = vec![0.0; 3 * n];
        chain.jacobian_columns_into(s, &self.layout, Rows::Position, self.cols.iter().copied().zip(0..n), &mut buf, 3);
        let mut var = 0.0;
        for r in 0..3 {
            for a in 0..n {
                let ja = buf[a * 3 + r];
                if ja == 0.0 {
                    continue;
                }
                for b in 0..n {
                    var += ja * self.cov[(a, b)] * buf[b * 3 + r];
                }
            }
        }
        var.max(0.0).sqrt()
    }
}

/// What a compensation checks and adds per target: the envelope (refused outside unless
/// `allow_outside`) and the predicted uncertainty.
#[derive(Clone, Copy, Debug, Default)]
pub struct Guard<'a> {
    /// The set's calibrated envelope; `None`: the set records none, and targets are not checked.
    pub envelope: Option<&'a Envelope>,
    /// A target outside the envelope is compensated (and noted) rather than refused.
    pub allow_outside: bool,
    /// The set's parameter covariance, for each target's predicted uncertainty; `None`: the set
    /// records none, and no covariance part is given.
    pub covariance: Option<&'a PredictionCovariance>,
    /// What the set's latest held-out validation measured: the error the covariance does not
    /// explain and its growth with distance. `None`: unknown (no held-out validation given).
    pub held_out: Option<&'a HeldOutUncertainty>,
}

impl<'a> Guard<'a> {
    /// No envelope, no uncertainty: what a set without either gets.
    pub fn none() -> Guard<'static> {
        Guard::default()
    }
}

/// Coverage factor of a 1-D normal variable at 95 % (two-sided), for the growth's slope.
const Z95: f64 = 1.959_963_984_540_054;
/// p95 / RMS of the length of an isotropic 3-D normal error (Maxwell: √(χ²₃(0.95) / 3)), the shape
/// factor used when a validation gives none.
pub const MAXWELL_K95: f64 = 1.613_881_245_898_081_5;

/// What a held-out validation measured about the error a parameter set's covariance does not
/// predict (its report's `uncertainty`; compensation reads it from the set's latest held-out
/// validation). Lengths mm; each an RMS of the 3-D position error over the held-out measurements.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct HeldOutUncertainty {
    /// Held-out measurements these figures come from.
    pub n: usize,
    /// RMS of the calibrated model's |error| on them.
    pub rms_mm: f64,
    /// √(mean σ²) of the parameter covariance's prediction at their joints (0 when the set
    /// records no covariance: the unexplained part then holds it).
    pub covariance_rms_mm: f64,
    /// √(mean σ²) of the reference's own noise: the instrument (its model, or each reading's
    /// `sigma_mm`), the robot's repeatability left in (it is an error at the target too); 0 when
    /// validated against the simulator's truth.
    pub instrument_rms_mm: f64,
    /// √max(0, rms² − covariance² − instrument²): the held-out error neither the parameter
    /// covariance nor the instrument explains (unmodelled effects, the data's own spread). The
    /// same for every target.
    pub unexplained_mm: f64,
    /// The shape factor turning an RMS into a 95 % bound: the held-out |error|'s p95 / RMS, at
    /// least an isotropic normal error's (1.614).
    pub k95: f64,
    /// How the held-out |error| grows with distance, when a regression could be fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub growth: Option<GrowthFit>,
}

/// The held-out |error| against a distance: what its growth away from the validated poses is
/// extrapolated from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct GrowthFit {
    /// `zone` (the distance to the calibration zone, the artefact's ball centroid) or `base` (to
    /// the base origin, when the cell has no artefact).
    pub against: String,
    /// The point distances are taken from, {W}, mm.
    pub from_mm: [f64; 3],
    /// The held-out poses' mean distance from it, mm: the unexplained part is their RMS error, so
    /// a target farther than the mean is charged the growth beyond it.
    pub mean_distance_mm: f64,
    /// The held-out poses' largest distance from it, mm.
    pub max_distance_mm: f64,
    /// Slope of the held-out |error| against the distance (least squares), mm per mm.
    pub slope_mm_per_mm: f64,
    /// Standard error of the slope, mm per mm; the 95 % growth charges slope + 1.96 × this.
    pub slope_stderr_mm_per_mm: f64,
    /// Number of held-out measurements the slope is fitted on.
    pub n: usize,
}

impl GrowthFit {
    /// How far a TCP at `p` ({W}, m) lies beyond the held-out poses' mean distance, m (0 nearer).
    pub fn beyond(&self, p: &Vector3<f64>) -> f64 {
        ((p - Vector3::from(self.from_mm) * MM).norm() - self.mean_distance_mm * MM).max(0.0)
    }
}

impl HeldOutUncertainty {
    /// The uncertainty model of a held-out validation report of `set` (its document `doc`) on
    /// `cell`; `None` when the report is not held out. The residuals must still carry the cell's
    /// measurement indices.
    pub fn of_report(
        doc: &ParameterSetDoc,
        cell: &crate::cell::Cell,
        report: &crate::validate::report::ValidationReport,
    ) -> Result<Option<HeldOutUncertainty>, DomainError> {
        use crate::validate::report::{approach_for, joint_state, session_chains};
        if !report.held_out() || report.residuals.is_empty() {
            return Ok(None);
        }
        let set = &doc.set;
        // The directions the validation applied the set's hysteresis with (derived from the
        // measuring order where not logged): the covariance's σ at each reading is taken there.
        let filled = approach_for(set, cell, &report.sessions).0;
        let cell = filled.as_ref().unwrap_or(cell);
        let covariance = PredictionCovariance::of_doc(doc)?;
        let robot_only = covariance.as_ref().map(PredictionCovariance::without_tool);
        let noise = crate::identify::noise::NoiseModel::default();
        let rep2 = noise.repeatability.powi(2);
        let (mut cov2, mut inst2, mut e2) = (0.0, 0.0, 0.0);
        let mut n = 0usize;
        for session in cell.sessions.iter().filter(|s| report.sessions.contains(&s.name)) {
            let (chain, _) = session_chains(set, session);
            let gravity = set.gravity_for(&session.tool);
            let pc = if session.tool == set.tool { covariance.as_ref() } else { robot_only.as_ref() };
            for r in report.residuals.iter().filter(|r| r.session == session.name) {
                let Some(m) = session.measurements.get(r.index) else { continue };
                if let Some(pc) = pc {
                    let s = joint_state(&gravity, &m.q, m.approach.as_deref(), m.temperature_c, set.dof());
                    cov2 += pc.sigma(&chain, &s).powi(2);
                }
                if !report.against_truth {
                    let row = noise.row_sigmas(session.instrument, &r.position, m.sigma.as_ref());
                    inst2 += (0..3).map(|k| (row[k].powi(2) - rep2).max(0.0)).sum::<f64>();
                }
                e2 += r.error.norm_squared();
                n += 1;
            }
        }
        if n == 0 {
            return Ok(None);
        }
        let nf = n as f64;
        let (cov2, inst2, e2) = (cov2 / nf, inst2 / nf, e2 / nf);
        let stats = &report.calibrated.position;
        // The shape factor: the held-out errors' own p95/RMS, and at least an isotropic normal
        // error's (a sample whose tail is thinner than a normal's is not trusted to stay so).
        let k95 = if stats.rms > 0.0 { (stats.p95 / stats.rms).max(MAXWELL_K95) } else { MAXWELL_K95 };
        let zone = cell.artefact.as_ref().map(|a| a.triangle.centroid());
        let base_origin = set.chain().base().t;
        let growth = match (&report.calibrated.vs_zone_distance, &report.calibrated.vs_base_distance, zone) {
            (Some(f), _, Some(z)) => Some(("zone", f, z)),
            (_, Some(f), _) => Some(("base", f, base_origin)),
            _ => None,
        }
        .filter(|(_, f, _)| f.slope.is_finite() && f.slope_stderr.is_finite())
        .map(|(against, f, from)| {
            let d: Vec<f64> = report.residuals.iter().map(|r| (r.position - from).norm()).collect();
            GrowthFit {
                against: against.into(),
                from_mm: [from.x / MM, from.y / MM, from.z / MM],
                mean_distance_mm: d.iter().sum::<f64>() / d.len().max(1) as f64 / MM,
                max_distance_mm: d.iter().copied().fold(0.0, f64::max) / MM,
                slope_mm_per_mm: f.slope,
                slope_stderr_mm_per_mm: f.slope_stderr,
                n: f.n,
            }
        });
        Ok(Some(HeldOutUncertainty {
            n,
            rms_mm: e2.sqrt() / MM,
            covariance_rms_mm: cov2.sqrt() / MM,
            instrument_rms_mm: inst2.sqrt() / MM,
            unexplained_mm: (e2 - cov2 - inst2).max(0.0).sqrt() / MM,
            k95,
            growth,
        }))
    }
}

/// A compensated target's predicted position uncertainty, part by part (mm; each part the RMS of
/// the 3-D position error it accounts for).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct UncertaintyOut {
    /// From the identification's parameter covariance at these joints, √trace(J·Cov·Jᵀ); absent
    /// when the set records no covariance (a held-out validation's unexplained part then holds
    /// it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub covariance_mm: Option<f64>,
    /// The set's hysteresis where the target does not say which way a joint that has it arrives
    /// (its `approach` 0 or absent): the target is compensated for the middle of each band, and
    /// this is the RMS, over the directions the robot may arrive from, of how far that moves the
    /// TCP. Absent when the set has no hysteresis or every such joint's approach is given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hysteresis_mm: Option<f64>,
    /// The set's latest held-out validation's RMS error beyond the covariance and the
    /// instrument's noise: what the model misses that its covariance does not say. Absent when
    /// unknown (no held-out validation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unexplained_mm: Option<f64>,
    /// How far the TCP lies outside the measured region: the box of the positions the
    /// identification and the held-out validation measured. Absent when the set records none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub outside_measured_mm: Option<f64>,
    /// How far the TCP lies beyond the held-out poses' mean distance from the calibration zone
    /// (or from the base, without an artefact): what the growth is charged on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beyond_validated_mm: Option<f64>,
    /// The error's growth there: the held-out |error|'s slope against that distance (when
    /// positive) times `beyond_validated_mm`. Absent when unknown (no held-out validation, or one
    /// without a regression, for a TCP outside the measured region).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extrapolation_mm: Option<f64>,
    /// A radius expected to hold 95 % of the position errors: k95 · √(covariance² +
    /// hysteresis² + unexplained²) + (slope + 1.96 · its standard error) · beyond_validated_mm,
    /// k95 the held-out errors' p95/RMS. Absent when a part is unknown.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound_95_mm: Option<f64>,
    /// The parts that are not known, and why (then `uncertainty_mm` is not given).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unknown: Vec<String>,
}

impl UncertaintyOut {
    /// The parts at a target whose covariance σ is `sigma` (m), whose hysteresis left unapplied
    /// spreads it by `hysteresis` (m, RMS), whose TCP is at `tcp` ({W}, m) and lies `outside` (m)
    /// outside the measured region (`None`: no region recorded), with a validation's model
    /// `held_out`. Returns the parts and the combined standard uncertainty (mm) when every part is
    /// known.
    pub fn of(
        sigma: Option<f64>,
        hysteresis: Option<f64>,
        tcp: &Vector3<f64>,
        outside: Option<f64>,
        held_out: Option<&HeldOutUncertainty>,
    ) -> (UncertaintyOut, Option<f64>) {
        use crate::units::{OUT_MM, round_to};
        let mut u = UncertaintyOut {
            covariance_mm: sigma.map(|s| s / MM),
            hysteresis_mm: hysteresis.map(|h| h / MM),
            ..UncertaintyOut::default()
        };
        if sigma.is_none() && held_out.is_none() {
            u.unknown.push("covariance: the set records no parameter covariance".into());
        }
        match held_out {
            None => u.unknown.push(
                "unexplained: no held-out validation to measure the error the covariance does not predict".into(),
            ),
            Some(h) => u.unexplained_mm = Some(h.unexplained_mm),
        }
        u.outside_measured_mm = outside.map(|d| d / MM);
        let (mut growth, mut growth95) = (None, None);
        match (held_out.and_then(|h| h.growth.as_ref()), outside) {
            (Some(g), _) => {
                let d = g.beyond(tcp);
                u.beyond_validated_mm = Some(d / MM);
                growth = Some(g.slope_mm_per_mm.max(0.0) * d / MM);
                growth95 = Some((g.slope_mm_per_mm + Z95 * g.slope_stderr_mm_per_mm).max(0.0) * d / MM);
            }
            (None, Some(0.0)) => (growth, growth95) = (Some(0.0), Some(0.0)),
            (None, Some(_)) => u.unknown.push(
                "extrapolation: the TCP is outside the measured region and no held-out validation says how the \
                 error grows with distance"
                    .into(),
            ),
            (None, None) => u.unknown.push("extrapolation: the set records no measured region".into()),
        }
        u.extrapolation_mm = growth;
        // The covariance and the unapplied hysteresis, combined: independent parts.
        let cov = u.covariance_mm.unwrap_or(0.0).hypot(u.hysteresis_mm.unwrap_or(0.0));
        let combined = match (u.unexplained_mm, growth) {
            (Some(un), Some(g)) if u.unknown.is_empty() => Some((cov * cov + un * un + g * g).sqrt()),
            _ => None,
        };
        if let (Some(h), Some(un), Some(g95)) = (held_out, u.unexplained_mm, growth95)
            && u.unknown.is_empty()
        {
            u.bound_95_mm = Some(round_to(h.k95 * (cov * cov + un * un).sqrt() + g95, OUT_MM));
        }
        let r = |v: Option<f64>| v.map(|x| round_to(x, OUT_MM));
        u.covariance_mm = r(u.covariance_mm);
        u.hysteresis_mm = r(u.hysteresis_mm);
        u.unexplained_mm = r(u.unexplained_mm);
        u.outside_measured_mm = r(u.outside_measured_mm);
        u.beyond_validated_mm = r(u.beyond_validated_mm);
        u.extrapolation_mm = r(u.extrapolation_mm);
        (u, r(combined))
    }
}

/// What a compensation checked, reported with its results.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ValidityOut {
    /// The calibrated envelope targets were checked against (measured ranges; the margins
    /// apply on top); absent when the set records none, and then nothing was checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelope: Option<EnvelopeFile>,
    /// Targets outside the envelope were compensated (and noted) rather than refused.
    pub allow_outside_envelope: bool,
    /// Whether each result carries a covariance part (`uncertainty.covariance_mm`: the set
    /// records its parameter covariance).
    pub uncertainty: bool,
    /// What the unexplained and extrapolation parts of each target's uncertainty come from: the
    /// set's latest held-out validation's measurements; absent when there is none (those parts
    /// are then unknown and `uncertainty_mm` is not given).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_uncertainty: Option<HeldOutUncertainty>,
    /// What could not be checked, in words.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The held-out validation the set was accepted on (service only): its id, and its mean
    /// errors, calibrated and nominal, mm; absent when there is none that passed and unvalidated
    /// use was asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation: Option<ValidationCheck>,
}

/// The latest held-out validation of a parameter set, as compensation judges it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
pub struct ValidationCheck {
    /// Id of the validation (as the service stores it).
    pub validation_id: String,
    /// Its mean position error with the calibrated parameters, mm.
    pub mean_mm: f64,
    /// Its mean position error with the nominal parameters, mm.
    pub nominal_mean_mm: f64,
}

impl ValidityOut {
    /// What `guard` checks, with a note for each of the envelope, covariance and held-out
    /// uncertainty model the set lacks; `validation` is left absent (the service fills it in).
    pub fn new(guard: &Guard) -> Self {
        let mut notes = Vec::new();
        if guard.envelope.is_none() {
            notes.push("the parameter set records no calibrated envelope: targets were not checked against one".into());
        }
        if guard.covariance.is_none() {
            notes.push("the parameter set records no parameter covariance: no predicted uncertainty".into());
        }
        if guard.held_out.is_none() {
            notes.push(
                "no held-out validation's uncertainty model: each target's uncertainty gives its covariance part \
                 only, and no uncertainty_mm"
                    .into(),
            );
        }
        ValidityOut {
            envelope: guard.envelope.map(|e| e.file().clone()),
            allow_outside_envelope: guard.allow_outside,
            uncertainty: guard.covariance.is_some(),
            held_out_uncertainty: guard.held_out.cloned(),
            notes,
            validation: None,
        }
    }
}

/// A calibrated TCP further than this from the declared one (m) is noted with a compensation.
/// A tool calibration corrects a declared TCP by a fraction of a millimetre to a few; 10 mm is
/// beyond what a tool's drawing or teaching misses by, and is what a point measured during the
/// calibration but not on the controller's tool (a reflector on a plate, declared at the flange)
/// differs by (50–150 mm on a three-reflector plate).
pub const TOOL_NOTE_BEYOND: f64 = 10.0 * MM;

/// The note a compensation with `comp`'s own tool carries when its calibrated TCP lies beyond
/// [`TOOL_NOTE_BEYOND`] from the declared one; `give` says how to compensate for another tool.
pub fn tool_note(comp: &crate::kinematics::Compensator, give: &str) -> Option<String> {
    let d = comp.tool_correction();
    (d > TOOL_NOTE_BEYOND).then(|| {
        let t = comp.nominal_chain().tool().t / MM;
        format!(
            "the set's calibrated TCP lies {:.1} mm from the TCP it declares ({:.1}, {:.1}, {:.1}) mm, and each target \
             is compensated for the calibrated one: right when the controller's tool data miss by that much, wrong \
             when the calibrated TCP is a point measured during the calibration that is not the controller's tool (a \
             reflector on a plate, with the flange declared); {give}",
            d / MM,
            t.x,
            t.y,
            t.z
        )
    })
}

/// The envelope of a quality report as JSON (for `quality.envelope`).
pub fn envelope_json(e: &Envelope) -> Value {
    serde_json::to_value(e.file()).expect("an envelope serialises")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::thesis::irb120_table_5_1;
    use crate::kinematics::{Param, Tool};

    #[test]
    fn the_envelope_is_the_measured_ranges_widened_by_the_margins() {
        let q1 = [0.1, -0.2, 0.3, 0.0, 0.5, -1.0];
        let q2 = [0.4, 0.2, -0.1, 0.2, 0.9, 1.0];
        let p1 = Vector3::new(0.3, -0.1, 0.4);
        let p2 = Vector3::new(0.5, 0.2, 0.6);
        let e = Envelope::of_measurements([(&q1[..], p1), (&q2[..], p2)]).unwrap();
        assert_eq!(e.file().n_measurements, 2);
        assert!((e.file().joints_deg[0][1] - 0.4 / DEG).abs() < 1e-12);
        let mid = [0.25, 0.0, 0.1, 0.1, 0.7, 0.0];
        let pm = (p1 + p2) / 2.0;
        assert_eq!(e.outside(&mid), None);
        assert_eq!(e.distance_note(&pm), None);
        // Within the margin: still inside; beyond it: outside, naming the joint.
        let mut q = mid;
        q[1] = 0.2 + 4.9 * DEG;
        assert_eq!(e.outside(&q), None);
        q[1] = 0.2 + 5.1 * DEG;
        let why = e.outside(&q).unwrap();
        assert!(why.starts_with("joint 2 at") && why.contains("0.100° beyond"), "{why}");
        // A whole turn away is the same angle to the model.
        let mut q = mid;
        q[5] = 1.0 * DEG + 360.0 * DEG;
        assert_eq!(e.outside(&q), None);
        q[5] = -1.5 - 5.1 * DEG;
        assert!(e.outside(&q).unwrap().starts_with("joint 6"));
        let far = p2 + Vector3::new(0.0, 0.0, 0.060);
        let why = e.distance_note(&far).unwrap();
        assert!(why.contains("10.0 mm outside"), "{why}");
        // Stored and read back: the same envelope.
        let back = Envelope::from_file(&serde_json::from_value(envelope_json(&e)).unwrap()).unwrap();
        assert_eq!(back, e);
        assert!(Envelope::of_measurements(std::iter::empty()).is_none());
        let mut f = e.file().clone();
        f.joints_deg[2] = [1.0, -1.0];
        assert_eq!(Envelope::from_file(&f).unwrap_err().path, "joints_deg[2]");
    }

    /// An unapplied hysteresis is one more independent part: the combined standard uncertainty
    /// and the 95 % bound take it in quadrature with the covariance, and it is reported by itself.
    #[test]
    fn a_hysteresis_left_unapplied_joins_the_uncertainty_in_quadrature() {
        let held_out = HeldOutUncertainty {
            n: 100,
            rms_mm: 0.2,
            covariance_rms_mm: 0.01,
            instrument_rms_mm: 0.02,
            unexplained_mm: 0.15,
            k95: 1.8,
            growth: None,
        };
        let tcp = Vector3::new(0.4, 0.1, 0.5);
        let (sigma, h) = (0.03 * MM, 0.12 * MM);
        let (without, a) = UncertaintyOut::of(Some(sigma), None, &tcp, Some(0.0), Some(&held_out));
        let (with, b) = UncertaintyOut::of(Some(sigma), Some(h), &tcp, Some(0.0), Some(&held_out));
        assert_eq!((without.hysteresis_mm, with.hysteresis_mm), (None, Some(0.12)));
        // Every figure is written to the micrometre.
        let (a, b) = (a.unwrap(), b.unwrap());
        assert!((a - 0.03f64.hypot(0.15)).abs() <= 5e-4, "{a}");
        assert!((b - 0.03f64.hypot(0.15).hypot(0.12)).abs() <= 5e-4, "{b}");
        let (ba, bb) = (without.bound_95_mm.unwrap(), with.bound_95_mm.unwrap());
        assert!((ba - 1.8 * 0.03f64.hypot(0.15)).abs() <= 5e-4, "{ba}");
        assert!((bb - 1.8 * 0.03f64.hypot(0.15).hypot(0.12)).abs() <= 5e-4, "{bb}");
    }

    /// σ from the stored std and correlation equals √trace(J·Cov·Jᵀ) with the Jacobian taken by
    /// central differences of the FK.
    #[test]
    fn the_predicted_uncertainty_matches_a_finite_difference_jacobian() {
        let set = irb120_table_5_1(Tool { tcp: [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], ..Tool::flange() });
        let mut doc = ParameterSetDoc::new(set.clone());
        let names = ["a2", "d4", "theta3", "tool_z"];
        let sig = [2e-5, 3e-5, 1e-4, 1e-5];
        let corr = [[1.0, 0.3, 0.0, -0.2], [0.3, 1.0, 0.1, 0.0], [0.0, 0.1, 1.0, 0.0], [-0.2, 0.0, 0.0, 1.0]];
        for (n, s) in names.iter().zip(sig) {
            doc.std[set.layout.find(n).unwrap()] = Some(s);
        }
        doc.quality = Some(crate::formats::Quality {
            free: Some(names.iter().map(|n| n.to_string()).collect()),
            correlation: Some(corr.iter().map(|r| r.iter().map(|&c| Some(c)).collect()).collect()),
            ..Default::default()
        });
        let pc = PredictionCovariance::of_doc(&doc).unwrap().unwrap();
        let q = [0.3, 0.2, -0.4, 0.5, 0.8, -0.3];
        let s = JointState::new(&q);
        let chain = set.chain();
        let got = pc.sigma(&chain, &s);
        let h = 1e-7;
        let jac: Vec<Vector3<f64>> = names
            .iter()
            .map(|n| {
                let i = set.layout.find(n).unwrap();
                let fk = |d: f64| {
                    let mut v = set.clone();
                    v.values[i] += d;
                    v.chain().fk(&s).t
                };
                (fk(h) - fk(-h)) / (2.0 * h)
            })
            .collect();
        let mut var = 0.0;
        for a in 0..4 {
            for b in 0..4 {
                var += jac[a].dot(&jac[b]) * sig[a] * sig[b] * corr[a][b];
            }
        }
        let want = var.sqrt();
        assert!((got - want).abs() < 1e-6 * want, "{got} vs {want}");
        // Without the tool: tool_z's row and column dropped.
        let robot_only = pc.without_tool().sigma(&chain, &s);
        let mut var = 0.0;
        for a in 0..3 {
            for b in 0..3 {
                var += jac[a].dot(&jac[b]) * sig[a] * sig[b] * corr[a][b];
            }
        }
        assert!((robot_only - var.sqrt()).abs() < 1e-6 * var.sqrt());
        assert!(matches!(set.layout.params()[set.layout.find("tool_z").unwrap()], Param::Tool(2)));
        // No covariance recorded: none.
        assert_eq!(PredictionCovariance::of_doc(&ParameterSetDoc::new(set)).unwrap(), None);
    }
}

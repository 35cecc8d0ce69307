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

use super::{DEG, DomainError, MM, ParameterSetDoc};
use crate::identify::Identification;
use crate::kinematics::{Chain, JointState, ParamLayout, Rows};
use crate::validate::report::Region;

/// Margin added on both sides of each joint's calibrated range, deg.
pub const JOINT_MARGIN_DEG: f64 = 5.0;
/// Margin added on every side of the calibrated box of {W}, mm.
pub const POSITION_MARGIN_MM: f64 = 50.0;

/// The calibrated envelope as a parameter set's quality report stores it (`quality.envelope`),
/// in degrees and millimetres; the ranges are the measured ones, the margins apply on top.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct EnvelopeFile {
    /// Per joint, [min, max] of the identification measurements, deg.
    pub joints_deg: Vec<[f64; 2]>,
    /// The measured TCP positions' box in {W}: lower corner, mm.
    pub position_min_mm: [f64; 3],
    /// Upper corner, mm.
    pub position_max_mm: [f64; 3],
    /// Widening of each joint range on both sides, deg.
    pub joint_margin_deg: f64,
    /// Widening of the box on every side, mm.
    pub position_margin_mm: f64,
    /// Measurements the envelope was taken from.
    pub n_measurements: usize,
}

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
        Region::of(points).map(|r| Envelope::of_region(&r))
    }

    /// The envelope of a region (the margins added).
    pub fn of_region(r: &Region) -> Envelope {
        let file = EnvelopeFile {
            joints_deg: r.joints.iter().map(|j| [j[0] / DEG, j[1] / DEG]).collect(),
            position_min_mm: [r.lo.x / MM, r.lo.y / MM, r.lo.z / MM],
            position_max_mm: [r.hi.x / MM, r.hi.y / MM, r.hi.z / MM],
            joint_margin_deg: JOINT_MARGIN_DEG,
            position_margin_mm: POSITION_MARGIN_MM,
            n_measurements: r.n,
        };
        Envelope::from_file(&file).expect("an envelope of finite measurements is valid")
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

    pub fn file(&self) -> &EnvelopeFile {
        &self.file
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

    /// The envelope a parameter-set document records, if any.
    pub fn of_doc(doc: &ParameterSetDoc) -> Result<Option<Envelope>, DomainError> {
        let Some(v) = doc.quality.as_ref().and_then(|q| q.get("envelope")) else { return Ok(None) };
        if v.is_null() {
            return Ok(None);
        }
        let f: EnvelopeFile =
            serde_json::from_value(v.clone()).map_err(|e| DomainError::new("quality.envelope", e.to_string()))?;
        Envelope::from_file(&f).map(Some).map_err(|e| e.within("quality.envelope"))
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
        let (Some(free), Some(corr)) = (q.get("free"), q.get("correlation")) else { return Ok(None) };
        let free: Vec<String> =
            serde_json::from_value(free.clone()).map_err(|e| DomainError::new("quality.free", e.to_string()))?;
        let corr: Vec<Vec<f64>> =
            serde_json::from_value(corr.clone()).map_err(|e| DomainError::new("quality.correlation", e.to_string()))?;
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
        let cov = DMatrix::from_fn(n, n, |i, j| rows[i].2 * rows[j].2 * corr[rows[i].0][rows[j].0]);
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
    pub envelope: Option<&'a Envelope>,
    pub allow_outside: bool,
    pub covariance: Option<&'a PredictionCovariance>,
}

impl<'a> Guard<'a> {
    /// No envelope, no uncertainty: what a set without either gets.
    pub fn none() -> Guard<'static> {
        Guard::default()
    }
}

/// What a compensation checked, reported with its results.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ValidityOut {
    /// The calibrated envelope targets were checked against (measured ranges; the margins
    /// apply on top); absent when the set records none, and then nothing was checked.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub envelope: Option<EnvelopeFile>,
    /// Targets outside the envelope were compensated (and noted) rather than refused.
    pub allow_outside_envelope: bool,
    /// Whether each result carries `uncertainty_mm` (the set records its covariance).
    pub uncertainty: bool,
    /// What could not be checked, in words.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The validation the set was accepted on (service only): its id, and its held-out mean
    /// errors, calibrated and nominal, mm; absent when unvalidated use was asked for.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub validation: Option<ValidationCheck>,
}

/// The latest held-out validation of a parameter set, as compensation judges it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct ValidationCheck {
    pub validation_id: String,
    pub mean_mm: f64,
    pub nominal_mean_mm: f64,
}

impl ValidityOut {
    pub fn new(guard: &Guard) -> Self {
        let mut notes = Vec::new();
        if guard.envelope.is_none() {
            notes.push("the parameter set records no calibrated envelope: targets were not checked against one".into());
        }
        if guard.covariance.is_none() {
            notes.push("the parameter set records no parameter covariance: no predicted uncertainty".into());
        }
        ValidityOut {
            envelope: guard.envelope.map(|e| e.file().clone()),
            allow_outside_envelope: guard.allow_outside,
            uncertainty: guard.covariance.is_some(),
            notes,
            validation: None,
        }
    }
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

    /// σ from the stored std and correlation equals √trace(J·Cov·Jᵀ) with the Jacobian taken by
    /// central differences of the FK.
    #[test]
    fn the_predicted_uncertainty_matches_a_finite_difference_jacobian() {
        let set = irb120_table_5_1(Tool { tcp: [0.0, 0.0, 0.1, 0.0, 0.0, 0.0], ..Tool::flange() });
        let mut doc = ParameterSetDoc::new(set.clone());
        let names = ["a2", "d4", "theta3", "tool_z"];
        let sig = [2e-5, 3e-5, 1e-4, 1e-5];
        let corr = vec![
            vec![1.0, 0.3, 0.0, -0.2],
            vec![0.3, 1.0, 0.1, 0.0],
            vec![0.0, 0.1, 1.0, 0.0],
            vec![-0.2, 0.0, 0.0, 1.0],
        ];
        for (n, s) in names.iter().zip(sig) {
            doc.std[set.layout.find(n).unwrap()] = Some(s);
        }
        doc.quality = Some(serde_json::json!({"free": names, "correlation": corr}));
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

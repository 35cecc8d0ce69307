//! ISO 9283 pose characteristics (issue 26, item 2): the statistics ([`stats`], SI), a cell's
//! session paired with a model's predictions ([`evaluate`]), pose ids derived from the UR10 data
//! set's goals ([`ur10`]), the pose-assignment sidecar file, and the report in mm and degrees.
//!
//! Implemented clauses: 7.2.1 (AP), 7.2.2 (RP), 7.2.3 (vAP), 7.5 (AD, RD, positions only).
//! Not implemented: 7.2.4 distance orientation components (ADa…, RDa…), 7.3 pose stabilisation
//! time, 7.4 pose overshoot, 7.6 drift of pose characteristics, and the path characteristics of
//! clause 8: they need the instrument's readings timed along the motion (a sampled trajectory),
//! and a static tracker session holds one reading per stop.
//!
//! # Pose-assignment file (sidecar)
//! The cell file format has no pose id. Rather than add a field to every measurement of every
//! cell (a change of the stored format that every reader and writer would carry), the pose of
//! each measurement comes in a small CSV beside the cell: header `index,pose_id,cycle,approach`,
//! one row per measurement to evaluate; `index` is the 0-based index in the session, `cycle` a
//! positive integer or empty (then: the visit's count of that pose in index order), `approach`
//! a label or empty. Measurements not listed are not evaluated.

pub mod evaluate;
pub mod plan;
pub mod stats;
pub mod ur10;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use self::evaluate::{Assignment, EvaluateError, Evaluated, Registration, evaluate_session};
use self::stats::{DistanceResult, IsoError, PoseResult, Visit, distance_characteristics, pose_characteristics};
use super::DomainError;
use crate::cell::Cell;
use crate::kinematics::ParameterSet;
use crate::units::{DEG, MM};

/// The header of the pose-assignment file.
pub const POSES_HEADER: &str = "index,pose_id,cycle,approach";

/// Read a pose-assignment file (see the module documentation).
pub fn parse_assignments(text: &str) -> Result<Vec<Assignment>, DomainError> {
    let mut lines = text.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or_else(|| DomainError::new("poses", "the file is empty"))?;
    if header.trim().trim_start_matches('\u{feff}') != POSES_HEADER {
        return Err(DomainError::new("poses.line 1", format!("the header must be '{POSES_HEADER}'")));
    }
    let mut out: Vec<Assignment> = Vec::new();
    let mut seen_index = std::collections::HashSet::new();
    let mut visits: std::collections::HashMap<String, u32> = std::collections::HashMap::new();
    for (k, line) in lines {
        let at = |field: &str| format!("poses.line {}.{field}", k + 1);
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() < 2 || f.len() > 4 {
            return Err(DomainError::new(
                format!("poses.line {}", k + 1),
                format!("expected 2 to 4 fields ({POSES_HEADER}), found {}", f.len()),
            ));
        }
        let index: usize =
            f[0].parse().map_err(|_| DomainError::new(at("index"), format!("'{}' is not a 0-based index", f[0])))?;
        if !seen_index.insert(index) {
            return Err(DomainError::new(at("index"), format!("measurement {index} is listed twice")));
        }
        let pose = f[1].to_string();
        if pose.is_empty() {
            return Err(DomainError::new(at("pose_id"), "empty"));
        }
        let count = visits.entry(pose.clone()).or_insert(0);
        *count += 1;
        let cycle = match f.get(2).copied().filter(|c| !c.is_empty()) {
            None => *count,
            Some(c) => c
                .parse::<u32>()
                .ok()
                .filter(|&c| c > 0)
                .ok_or_else(|| DomainError::new(at("cycle"), format!("'{c}' is not a positive integer")))?,
        };
        let approach = f.get(3).copied().filter(|a| !a.is_empty()).map(str::to_string);
        out.push(Assignment { index, pose, cycle, approach });
    }
    if out.is_empty() {
        return Err(DomainError::new("poses", "no rows after the header"));
    }
    Ok(out)
}

/// Write a pose-assignment file.
pub fn write_assignments(a: &[Assignment]) -> String {
    let mut s = format!("{POSES_HEADER}\n");
    for r in a {
        s.push_str(&format!("{},{},{},{}\n", r.index, r.pose, r.cycle, r.approach.as_deref().unwrap_or("")));
    }
    s
}

/// One pose's characteristics, mm and degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseRow {
    pub pose: String,
    pub cycles: usize,
    pub ap_p_mm: f64,
    pub ap_xyz_mm: [f64; 3],
    /// AP_a, AP_b, AP_c (about the base's x, y, z), deg.
    pub ap_abc_deg: Option<[f64; 3]>,
    /// The instrument's standard uncertainty of AP_P and of each AP_x, mm.
    pub ap_p_u_mm: Option<f64>,
    pub ap_abc_u_deg: Option<f64>,
    pub rp_l_mm: Option<f64>,
    pub l_mean_mm: Option<f64>,
    pub s_l_mm: Option<f64>,
    /// RP_a, RP_b, RP_c (± this), deg.
    pub rp_abc_deg: Option<[f64; 3]>,
    /// Approximate standard uncertainty of RP_l from the number of cycles, mm.
    pub rp_sampling_u_mm: Option<f64>,
    /// The RP the instrument alone would show, mm.
    pub rp_instrument_floor_mm: Option<f64>,
    pub vap_p_mm: Option<f64>,
    pub vap_abc_deg: Option<[f64; 3]>,
    pub approaches: Vec<(String, usize)>,
}

/// One pair's distance characteristics, mm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DistanceRow {
    pub from: String,
    pub to: String,
    pub cycles: usize,
    pub d_mean_mm: f64,
    pub d_commanded_mm: f64,
    pub ad_p_mm: f64,
    pub ad_xyz_mm: [f64; 3],
    pub ad_u_mm: Option<f64>,
    pub rd_mm: Option<f64>,
    pub rd_xyz_mm: Option<[f64; 3]>,
    pub rd_sampling_u_mm: Option<f64>,
}

/// A summary over the poses (what a one-line table shows).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Summary {
    pub poses: usize,
    pub visits: usize,
    /// Poses with at least two cycles (RP defined).
    pub repeated_poses: usize,
    pub ap_p_mean_mm: f64,
    pub ap_p_max_mm: f64,
    /// Over the repeated poses.
    pub ap_p_mean_repeated_mm: Option<f64>,
    pub rp_l_mean_mm: Option<f64>,
    pub rp_l_max_mm: Option<f64>,
}

/// The ISO 9283 report of one model on one session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IsoReport {
    /// `nominal` or `calibrated (predicted)`.
    pub model: String,
    pub summary: Summary,
    pub poses: Vec<PoseRow>,
    pub distances: Vec<DistanceRow>,
    pub registration: Option<RegistrationRow>,
    pub notes: Vec<String>,
}

/// How base and tool were registered, mm and degrees.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RegistrationRow {
    pub base_xyz_mm: [f64; 3],
    pub base_abc_deg: [f64; 3],
    pub tool_xyz_mm: [f64; 3],
    pub tool_abc_deg: [f64; 3],
    pub kappa_scaled: f64,
    pub rms_position_mm: f64,
    /// Base or tool parameters held at their start values in both models' registrations because
    /// one of them left them undetermined: both are registered with the same freedoms.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held: Vec<String>,
}

impl From<&Registration> for RegistrationRow {
    fn from(r: &Registration) -> Self {
        let xyz = |v: &[f64; 6]| [v[0] / MM, v[1] / MM, v[2] / MM];
        let abc = |v: &[f64; 6]| [v[3] / DEG, v[4] / DEG, v[5] / DEG];
        RegistrationRow {
            base_xyz_mm: xyz(&r.base),
            base_abc_deg: abc(&r.base),
            tool_xyz_mm: xyz(&r.tool),
            tool_abc_deg: abc(&r.tool),
            kappa_scaled: r.kappa_scaled,
            rms_position_mm: r.rms_position / MM,
            held: r.held.clone(),
        }
    }
}

fn v3(v: &nalgebra::Vector3<f64>, unit: f64) -> [f64; 3] {
    [v.x / unit, v.y / unit, v.z / unit]
}

impl From<&PoseResult> for PoseRow {
    fn from(p: &PoseResult) -> Self {
        PoseRow {
            pose: p.pose.clone(),
            cycles: p.n,
            ap_p_mm: p.ap_p / MM,
            ap_xyz_mm: v3(&p.ap_xyz, MM),
            ap_abc_deg: p.ap_abc.as_ref().map(|v| v3(v, DEG)),
            ap_p_u_mm: p.ap_p_u.map(|v| v / MM),
            ap_abc_u_deg: p.ap_abc_u.map(|v| v / DEG),
            rp_l_mm: p.rp_l.map(|v| v / MM),
            l_mean_mm: p.l_mean.map(|v| v / MM),
            s_l_mm: p.s_l.map(|v| v / MM),
            rp_abc_deg: p.rp_abc.as_ref().map(|v| v3(v, DEG)),
            rp_sampling_u_mm: p.rp_sampling_u.map(|v| v / MM),
            rp_instrument_floor_mm: p.rp_instrument_floor.map(|v| v / MM),
            vap_p_mm: p.vap_p.map(|v| v / MM),
            vap_abc_deg: p.vap_abc.as_ref().map(|v| v3(v, DEG)),
            approaches: p.approaches.clone(),
        }
    }
}

impl From<&DistanceResult> for DistanceRow {
    fn from(d: &DistanceResult) -> Self {
        DistanceRow {
            from: d.from.clone(),
            to: d.to.clone(),
            cycles: d.n,
            d_mean_mm: d.d_mean / MM,
            d_commanded_mm: d.d_commanded / MM,
            ad_p_mm: d.ad_p / MM,
            ad_xyz_mm: v3(&d.ad_xyz, MM),
            ad_u_mm: d.ad_u.map(|v| v / MM),
            rd_mm: d.rd.map(|v| v / MM),
            rd_xyz_mm: d.rd_xyz.as_ref().map(|v| v3(v, MM)),
            rd_sampling_u_mm: d.rd_sampling_u.map(|v| v / MM),
        }
    }
}

/// An evaluation of a session: the nominal model's figures and, with a calibrated set, its
/// predicted ones. What `robocal iso9283 evaluate --json` prints and the service stores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    pub session: String,
    pub nominal: IsoReport,
    pub calibrated: Option<IsoReport>,
}

/// Why an evaluation was not made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvaluationError {
    /// The session, a measurement, or the registration.
    #[error(transparent)]
    Session(#[from] EvaluateError),
    /// The statistics refused the visits (a pose visited twice in one cycle, a pair without a
    /// common cycle, a value that is not finite).
    #[error("{model}: {error}")]
    Statistics { model: String, error: IsoError },
}

/// The evaluation of `session` of `cell`: the nominal model, and `set`'s predicted figures when
/// given; `pairs` for AD and RD; `kappa_limit` of the base-and-tool registration. The one call
/// `robocal iso9283 evaluate` and the service's job make.
pub fn evaluate(
    cell: &Cell,
    session: &str,
    set: Option<&ParameterSet>,
    assignments: &[Assignment],
    pairs: &[(String, String)],
    kappa_limit: f64,
) -> Result<Evaluation, EvaluationError> {
    let register = |set: Option<&ParameterSet>, held: &[String]| {
        evaluate_session(cell, session, set, assignments, kappa_limit, held)
    };
    let mut nominal = register(None, &[])?;
    let mut calibrated = set.map(|s| register(Some(s), &[])).transpose()?;
    // One registration for both models. A base or tool parameter the session's data leave at the
    // edge of determined (the UR10's probe z on series D, σ ≈ 10 mm along base x) is held by one
    // registration and freed by the other, and AP would compare the models with different
    // freedoms: series D's calibrated registration freed it at κ 2,100 where the nominal's held it
    // (κ 7). What one held is held in both.
    let held = calibrated.as_ref().map_or_else(Vec::new, |c| {
        crate::identify::free_in_some_only(&[&nominal.registration.free, &c.registration.free])
    });
    if !held.is_empty() {
        if nominal.registration.free.iter().any(|n| held.contains(n)) {
            nominal = register(None, &held)?;
        }
        if let (Some(s), Some(c)) = (set, &mut calibrated)
            && c.registration.free.iter().any(|n| held.contains(n))
        {
            *c = register(Some(s), &held)?;
        }
    }
    let one = |e: &Evaluated, model: &str| -> Result<IsoReport, EvaluationError> {
        let mut r = report(model, &e.visits, pairs, Some(&e.registration))
            .map_err(|error| EvaluationError::Statistics { model: model.to_string(), error })?;
        r.notes.extend(e.notes.iter().cloned());
        if !held.is_empty() {
            if let Some(g) = &mut r.registration {
                g.held = held.clone();
            }
            r.notes.push(format!(
                "Registration: {} held at its start value in both models' registrations (one of them left it \
                 undetermined by these data), so the two are compared with the same freedoms.",
                held.join(", ")
            ));
        }
        Ok(r)
    };
    Ok(Evaluation {
        session: session.to_string(),
        nominal: one(&nominal, "nominal")?,
        calibrated: calibrated.as_ref().map(|c| one(c, "calibrated (predicted)")).transpose()?,
    })
}

/// The pattern of a pose id and of an approach label on the wire: 1–64 letters, digits or
/// `_ . : + -`.
pub const POSE_ID_PATTERN: &str = r"^[A-Za-z0-9_.:+-]{1,64}$";
/// The most pose assignments (measurements evaluated) one request holds.
pub const MAX_ASSIGNMENTS: usize = 100_000;
/// The κ limit of the base-and-tool registration the service uses (`robocal iso9283 evaluate
/// --kappa-limit`'s default).
pub const KAPPA_LIMIT: f64 = 1e4;
/// The most pose pairs (AD, RD) one request holds.
pub const MAX_PAIRS: usize = 1000;

fn pose_id_ok(s: &str) -> bool {
    (1..=64).contains(&s.len()) && s.bytes().all(|b| b.is_ascii_alphanumeric() || b"_.:+-".contains(&b))
}

/// Which pose a measurement is, as the service takes it: one row of the pose-assignment file.
/// (The stored measurement has no pose id, as the cell file has none: the assignment travels with
/// the request, exactly as the file travels beside the cell for the command line.)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PoseAssignment {
    /// 0-based index of the measurement in the session (the index the API lists measurements by;
    /// at most 2³¹−1).
    #[schema(maximum = 2147483647)]
    pub index: usize,
    /// The pose (P1 … P5, or any id): 1–64 letters, digits or `_ . : + -`.
    #[schema(pattern = r"^[A-Za-z0-9_.:+-]{1,64}$", min_length = 1, max_length = 64)]
    pub pose_id: String,
    /// The cycle (1-based); absent: the count of this pose's visits so far, in the order listed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 1, maximum = 1000000)]
    pub cycle: Option<u32>,
    /// The direction the pose was approached from (a label, e.g. `+x`), for vAP.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(pattern = r"^[A-Za-z0-9_.:+-]{1,64}$", min_length = 1, max_length = 64)]
    pub approach: Option<String>,
}

/// A pose pair for distance accuracy and repeatability (AD, RD).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PosePair {
    #[schema(pattern = r"^[A-Za-z0-9_.:+-]{1,64}$", min_length = 1, max_length = 64)]
    pub from: String,
    #[schema(pattern = r"^[A-Za-z0-9_.:+-]{1,64}$", min_length = 1, max_length = 64)]
    pub to: String,
}

/// The assignments of a request (`poses`), checked: every pose id and approach label of the
/// pattern, each measurement listed once, each (pose, cycle) once; cycles counted where absent, as
/// the file's. Errors name `poses[i].field`.
pub fn assignments_of(rows: &[PoseAssignment]) -> Result<Vec<Assignment>, DomainError> {
    if rows.is_empty() {
        return Err(DomainError::new("poses", "assign at least one measurement to a pose"));
    }
    if rows.len() > MAX_ASSIGNMENTS {
        return Err(DomainError::new("poses", format!("at most {MAX_ASSIGNMENTS} assignments, got {}", rows.len())));
    }
    let mut index_row = std::collections::HashMap::new();
    let mut visit_row = std::collections::HashMap::new();
    let mut visits: std::collections::HashMap<&str, u32> = std::collections::HashMap::new();
    let mut out = Vec::with_capacity(rows.len());
    for (i, r) in rows.iter().enumerate() {
        let at = |field: &str| format!("poses[{i}].{field}");
        if r.index > i32::MAX as usize {
            return Err(DomainError::new(at("index"), "at most 2³¹−1"));
        }
        if !pose_id_ok(&r.pose_id) {
            return Err(DomainError::new(at("pose_id"), "1–64 letters, digits or '_ . : + -'"));
        }
        if let Some(a) = &r.approach
            && !pose_id_ok(a)
        {
            return Err(DomainError::new(at("approach"), "1–64 letters, digits or '_ . : + -'"));
        }
        if let Some(first) = index_row.insert(r.index, i) {
            return Err(DomainError::new(
                at("index"),
                format!("measurement {} is assigned twice (poses[{first}] and poses[{i}])", r.index),
            ));
        }
        let count = visits.entry(r.pose_id.as_str()).or_insert(0);
        *count += 1;
        let cycle = match r.cycle {
            None => *count,
            Some(c) if !(1..=1_000_000).contains(&c) => {
                return Err(DomainError::new(at("cycle"), "cycles count from 1 to 1000000"));
            }
            Some(c) => c,
        };
        if let Some(first) = visit_row.insert((r.pose_id.as_str(), cycle), i) {
            return Err(DomainError::new(
                at("cycle"),
                format!("pose '{}' is visited twice in cycle {cycle} (poses[{first}] and poses[{i}])", r.pose_id),
            ));
        }
        out.push(Assignment { index: r.index, pose: r.pose_id.clone(), cycle, approach: r.approach.clone() });
    }
    Ok(out)
}

/// The pairs of a request, checked against the assignments: two different poses, each assigned.
/// Errors name `pairs[i].from` or `pairs[i].to`.
pub fn pairs_of(pairs: &[PosePair], assignments: &[Assignment]) -> Result<Vec<(String, String)>, DomainError> {
    if pairs.len() > MAX_PAIRS {
        return Err(DomainError::new("pairs", format!("at most {MAX_PAIRS} pairs, got {}", pairs.len())));
    }
    let assigned: std::collections::HashSet<&str> = assignments.iter().map(|a| a.pose.as_str()).collect();
    pairs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            for (field, id) in [("from", &p.from), ("to", &p.to)] {
                if !pose_id_ok(id) {
                    return Err(DomainError::new(format!("pairs[{i}].{field}"), "1–64 letters, digits or '_ . : + -'"));
                }
                if !assigned.contains(id.as_str()) {
                    return Err(DomainError::new(
                        format!("pairs[{i}].{field}"),
                        format!("no measurement is assigned to pose '{id}'"),
                    ));
                }
            }
            if p.from == p.to {
                return Err(DomainError::new(format!("pairs[{i}].to"), "a pair needs two different poses"));
            }
            Ok((p.from.clone(), p.to.clone()))
        })
        .collect()
}

/// The report of `visits` (one model), with the distance characteristics of `pairs`.
pub fn report(
    model: &str,
    visits: &[Visit],
    pairs: &[(String, String)],
    registration: Option<&Registration>,
) -> Result<IsoReport, IsoError> {
    let poses = pose_characteristics(visits)?;
    let distances = pairs.iter().map(|(a, b)| distance_characteristics(visits, a, b)).collect::<Result<Vec<_>, _>>()?;
    let repeated: Vec<&PoseResult> = poses.iter().filter(|p| p.n >= 2).collect();
    let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
    let ap: Vec<f64> = poses.iter().map(|p| p.ap_p / MM).collect();
    let ap_rep: Vec<f64> = repeated.iter().map(|p| p.ap_p / MM).collect();
    let rp: Vec<f64> = repeated.iter().filter_map(|p| p.rp_l).map(|v| v / MM).collect();
    let summary = Summary {
        poses: poses.len(),
        visits: visits.len(),
        repeated_poses: repeated.len(),
        ap_p_mean_mm: mean(&ap).unwrap_or(0.0),
        ap_p_max_mm: ap.iter().copied().fold(0.0, f64::max),
        ap_p_mean_repeated_mm: mean(&ap_rep),
        rp_l_mean_mm: mean(&rp),
        rp_l_max_mm: rp.iter().copied().reduce(f64::max),
    };
    let mut notes = vec![
        "AP is measured against the model's prediction from each visit's joint readings, in the robot base frame; \
         the base and tool registration was fitted on the same data, so it absorbs any error common to all poses."
            .to_string(),
        "Uncertainties: *_u_mm is the instrument's share only (its 1σ per reading propagated into the mean); \
         the registration's uncertainty is not included. rp_sampling_u_mm is the approximate standard error of RP \
         from the number of cycles (normal theory)."
            .to_string(),
        "Not implemented: pose stabilisation time (7.3), overshoot (7.4), drift (7.6) and path characteristics \
         (clause 8) need instrument readings timed along the motion; orientation components of AD/RD."
            .to_string(),
    ];
    if model.starts_with("calibrated") {
        notes.push(
            "Calibrated: the calibrated model's prediction of where the robot went against the measurement, i.e. the \
             predicted AP after compensation; no robot was re-run with compensated targets. RP is the measured one \
             (compensation does not change repeatability)."
                .to_string(),
        );
    }
    if repeated.iter().any(|p| p.n < 30) {
        notes.push(
            "ISO 9283 asks for 30 cycles; poses with fewer give an RP with a larger sampling error (rp_sampling_u_mm)."
                .to_string(),
        );
    }
    Ok(IsoReport {
        model: model.to_string(),
        summary,
        poses: poses.iter().map(PoseRow::from).collect(),
        distances: distances.iter().map(DistanceRow::from).collect(),
        registration: registration.map(RegistrationRow::from),
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pose_file_round_trips_and_names_bad_fields() {
        let a = vec![
            Assignment { index: 0, pose: "P1".into(), cycle: 1, approach: None },
            Assignment { index: 3, pose: "P2".into(), cycle: 1, approach: Some("+x".into()) },
        ];
        assert_eq!(parse_assignments(&write_assignments(&a)).unwrap(), a);
        // Cycles counted when left empty.
        let got = parse_assignments("index,pose_id,cycle,approach\n0,A\n1,B,,\n2,A\n").unwrap();
        assert_eq!(got.iter().map(|a| a.cycle).collect::<Vec<_>>(), vec![1, 1, 2]);
        let e = parse_assignments("index,pose_id,cycle,approach\n0,A,0\n").unwrap_err();
        assert_eq!(e.path, "poses.line 2.cycle");
        let e = parse_assignments("index,pose_id,cycle,approach\nx,A\n").unwrap_err();
        assert_eq!(e.path, "poses.line 2.index");
        let e = parse_assignments("index,pose_id,cycle,approach\n0,A\n0,B\n").unwrap_err();
        assert!(e.reason.contains("listed twice"), "{e:?}");
        assert_eq!(parse_assignments("pose,index\n").unwrap_err().path, "poses.line 1");
    }
}

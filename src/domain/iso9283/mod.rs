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

use serde::Serialize;

use self::evaluate::{Assignment, Registration};
use self::stats::{DistanceResult, IsoError, PoseResult, Visit, distance_characteristics, pose_characteristics};
use super::DomainError;
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
#[derive(Clone, Debug, PartialEq, Serialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize)]
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
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegistrationRow {
    pub base_xyz_mm: [f64; 3],
    pub base_abc_deg: [f64; 3],
    pub tool_xyz_mm: [f64; 3],
    pub tool_abc_deg: [f64; 3],
    pub kappa_scaled: f64,
    pub rms_position_mm: f64,
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

//! ISO 9283:1998 pose characteristics from measured cycles, in SI (m, rad), in the robot's base
//! frame: clause 7.2.1 pose accuracy AP, 7.2.2 pose repeatability RP, 7.2.3 multi-directional
//! pose accuracy variation vAP, 7.5 distance accuracy AD and distance repeatability RD.
//!
//! # Definitions (n = number of cycles of a pose, j = 1…n)
//! - Barycentre of the attained positions: x̄ = (1/n)·Σ x_j (ȳ, z̄ likewise).
//! - AP_x = x̄ − x̄_c (y, z likewise), AP_P = √(AP_x² + AP_y² + AP_z²). The standard has one
//!   commanded pose per pose; here each visit carries its own (a model's prediction from that
//!   visit's joint readings varies by the encoders' noise), so x̄_c is the mean of the visits'
//!   commanded positions. With one command for all visits this is the standard's formula.
//! - Orientation: the standard's a, b, c are rotations about the base's x, y, z axes, and
//!   AP_a = ā − a_c. Here each visit's orientation deviation is the rotation vector
//!   e_j = log(R_attained,j · R_commanded,jᵀ), in the base's axes, and (AP_a, AP_b, AP_c) = ē. For
//!   deviations of a few mrad this equals the difference of the roll/pitch/yaw angles to second
//!   order, and it has no Euler wrap-around or gimbal lock.
//! - RP_l = l̄ + 3·S_l with l_j = |P_j − P̄| (attained positions only), l̄ = (1/n)·Σ l_j,
//!   S_l = √(Σ (l_j − l̄)² / (n − 1)).
//! - RP_a = ±3·S_a, S_a = √(Σ (a_j − ā)² / (n − 1)), with a_j the x component of the attained
//!   orientation relative to one reference (the first visit's commanded orientation):
//!   ε_j = log(R_attained,j · R_refᵀ). Likewise b (y) and c (z).
//! - vAP_P = max over pairs of approach directions (h, k) of |P̄_h − P̄_k| (barycentres of the
//!   visits approached from h and from k); vAP_a = max |ā_h − ā_k| of the deviations e (b, c
//!   likewise). Only for poses visited from at least two directions.
//! - Distance between two poses in cycle j: D_j = |P1_j − P2_j|, commanded D_cj = |Pc1_j − Pc2_j|.
//!   AD_P = D̄ − D̄_c; per axis AD_x = mean |x1_j − x2_j| − mean |xc1_j − xc2_j|. RD = ±3·S_D with
//!   S_D the sample standard deviation of D_j (RD_x, RD_y, RD_z likewise). Cycles are matched by
//!   number: a cycle in which one of the two poses is missing is left out.
//!
//! # What the instrument lets one claim
//! Each visit may carry the instrument's 1σ per axis (position) and per axis of rotation.
//! - AP is a mean: the instrument's share of its standard uncertainty is √(Σ σ_j²)/n per axis,
//!   which for AP_P (the length of a vector, gradient of unit length) is the same figure when σ is
//!   the same on every axis (the σ of a visit is taken as the RMS of its three axes).
//!   Not included, and usually larger: the uncertainty of the registration (tracker frame to robot
//!   base) that puts the measurements in the base frame; a registration fitted on the same data
//!   absorbs any error common to all poses, so AP then measures pose-to-pose differences only.
//! - RP is a spread: the instrument adds to it. With isotropic Gaussian noise σ and a perfectly
//!   repeatable robot, l_j = σ·√((n−1)/n)·χ₃, whose mean is 2√(2/π) = 1.5958 and standard deviation
//!   √(3 − 8/π) = 0.6734 times σ·√((n−1)/n): the instrument alone shows
//!   RP ≈ (1.5958 + 3·0.6734)·σ·√((n−1)/n) = 3.616·σ·√((n−1)/n) (`rp_instrument_floor`). An RP near
//!   that floor says only that the robot repeats better than the instrument resolves.
//! - The sample size limits RP much more: the standard error of S from n normal samples is about
//!   S/√(2(n−1)) (50 % at n = 3, 13 % at the standard's n = 30) and that of l̄ is S_l/√n, so
//!   u(RP) ≈ S_l·√(1/n + 9/(2(n−1))) (`rp_sampling_u`; normal theory, an approximation since l is
//!   not normal). For RD likewise 3·S_D/√(2(n−1)). With two cycles l_1 = l_2 and S_l = 0 by
//!   construction: RP is then half the distance between the two visits, and no sampling
//!   uncertainty is given (`None`).

use std::collections::BTreeMap;

use nalgebra::{Matrix3, Vector3};

use crate::kinematics::Frame;
use crate::kinematics::frame::rotation_vector;

/// E[χ₃] = 2·√(2/π): the mean length of a 3D standard normal vector.
pub const CHI3_MEAN: f64 = 1.595_769_121_605_731;
/// sd(χ₃) = √(3 − 8/π).
pub const CHI3_SD: f64 = 0.673_439_611_642_851_4;

/// The instrument's standard uncertainty of one reading (1σ, the same on each axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VisitSigma {
    /// m, per axis.
    pub position: f64,
    /// rad, per axis of rotation (full-pose readings only).
    pub rotation: Option<f64>,
}

impl VisitSigma {
    /// From a per-axis σ: the RMS of the axes (a diagonal covariance turned into the base frame
    /// keeps its trace, so the RMS is frame-independent).
    pub fn from_axes(position: [f64; 3], rotation: Option<[f64; 3]>) -> VisitSigma {
        let rms = |v: [f64; 3]| ((v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) / 3.0).sqrt();
        VisitSigma { position: rms(position), rotation: rotation.map(rms) }
    }
}

/// One measured visit of a pose, in the robot base frame (m, rad).
#[derive(Clone, Debug, PartialEq)]
pub struct Visit {
    pub pose: String,
    /// Cycle number (visits of different poses with the same number belong to one cycle).
    pub cycle: u32,
    pub attained: Frame,
    pub commanded: Frame,
    /// Whether the orientation was measured (false: position only, `attained.r` is meaningless).
    pub orientation: bool,
    /// Approach direction label (vAP), if known.
    pub approach: Option<String>,
    pub sigma: Option<VisitSigma>,
}

/// Clause 7.2.1 and 7.2.2 for one pose, and 7.2.3 where it applies.
#[derive(Clone, Debug, PartialEq)]
pub struct PoseResult {
    pub pose: String,
    pub n: usize,
    /// Barycentre of the attained positions, m.
    pub barycentre: Vector3<f64>,
    /// Mean commanded position, m.
    pub commanded: Vector3<f64>,
    /// AP_x, AP_y, AP_z, m.
    pub ap_xyz: Vector3<f64>,
    /// AP_P, m.
    pub ap_p: f64,
    /// AP_a, AP_b, AP_c, rad (with orientation measured on every visit).
    pub ap_abc: Option<Vector3<f64>>,
    /// The instrument's standard uncertainty of AP_P (and of each AP_x), m.
    pub ap_p_u: Option<f64>,
    /// The instrument's standard uncertainty of each of AP_a, AP_b, AP_c, rad.
    pub ap_abc_u: Option<f64>,
    /// l̄, S_l and RP_l = l̄ + 3·S_l, m (n ≥ 2).
    pub l_mean: Option<f64>,
    pub s_l: Option<f64>,
    pub rp_l: Option<f64>,
    /// RP_a, RP_b, RP_c = 3·S, rad (n ≥ 2, orientation measured).
    pub rp_abc: Option<Vector3<f64>>,
    /// Approximate standard uncertainty of RP_l from the sample size, m.
    pub rp_sampling_u: Option<f64>,
    /// The RP the instrument alone would show, m.
    pub rp_instrument_floor: Option<f64>,
    /// vAP_P (m) and vAP_a, b, c (rad), when approached from ≥ 2 directions.
    pub vap_p: Option<f64>,
    pub vap_abc: Option<Vector3<f64>>,
    /// The approach directions seen, with their visit counts.
    pub approaches: Vec<(String, usize)>,
}

/// Clause 7.5 for one pair of poses.
#[derive(Clone, Debug, PartialEq)]
pub struct DistanceResult {
    pub from: String,
    pub to: String,
    /// Cycles in which both poses were visited.
    pub n: usize,
    /// D̄ and D̄_c, m.
    pub d_mean: f64,
    pub d_commanded: f64,
    /// AD_P, m.
    pub ad_p: f64,
    /// AD_x, AD_y, AD_z, m.
    pub ad_xyz: Vector3<f64>,
    /// RD = 3·S_D, m (n ≥ 2).
    pub rd: Option<f64>,
    /// RD_x, RD_y, RD_z, m (n ≥ 2).
    pub rd_xyz: Option<Vector3<f64>>,
    /// The instrument's standard uncertainty of AD_P, m.
    pub ad_u: Option<f64>,
    /// Approximate standard uncertainty of RD from the sample size, m.
    pub rd_sampling_u: Option<f64>,
}

/// Why a set of visits cannot be evaluated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum IsoError {
    #[error("no visits to evaluate")]
    Empty,
    #[error("pose '{pose}' is visited twice in cycle {cycle}")]
    DuplicateCycle { pose: String, cycle: u32 },
    #[error("visit {index} (pose '{pose}'): {reason}")]
    NotFinite { index: usize, pose: String, reason: String },
    #[error("no pose named '{0}'")]
    UnknownPose(String),
    #[error("poses '{0}' and '{1}' have no cycle in common")]
    NoCommonCycle(String, String),
}

fn sample_sd(v: &[f64]) -> Option<f64> {
    let n = v.len();
    if n < 2 {
        return None;
    }
    let m = v.iter().sum::<f64>() / n as f64;
    Some((v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1) as f64).sqrt())
}

fn mean_vec(v: &[Vector3<f64>]) -> Vector3<f64> {
    v.iter().fold(Vector3::zeros(), |a, b| a + b) / v.len() as f64
}

/// e_j = log(R_a · R_bᵀ): the rotation from b to a, in the base's axes.
fn deviation(a: &Matrix3<f64>, b: &Matrix3<f64>) -> Vector3<f64> {
    rotation_vector(&(a * b.transpose()))
}

/// Check the visits: finite values, at most one visit of a pose per cycle.
fn check(visits: &[Visit]) -> Result<(), IsoError> {
    if visits.is_empty() {
        return Err(IsoError::Empty);
    }
    let mut seen = std::collections::HashSet::new();
    for (i, v) in visits.iter().enumerate() {
        let finite = |f: &Frame| f.t.iter().chain(f.r.iter()).all(|x| x.is_finite());
        if !finite(&v.attained) || !finite(&v.commanded) {
            return Err(IsoError::NotFinite { index: i, pose: v.pose.clone(), reason: "a pose is not finite".into() });
        }
        if let Some(s) = v.sigma
            && !(s.position.is_finite() && s.position >= 0.0 && s.rotation.is_none_or(|r| r.is_finite() && r >= 0.0))
        {
            return Err(IsoError::NotFinite {
                index: i,
                pose: v.pose.clone(),
                reason: "sigma must be finite and ≥ 0".into(),
            });
        }
        if !seen.insert((v.pose.as_str(), v.cycle)) {
            return Err(IsoError::DuplicateCycle { pose: v.pose.clone(), cycle: v.cycle });
        }
    }
    Ok(())
}

/// The visits grouped by pose, poses in order of first appearance, visits in cycle order.
pub fn group(visits: &[Visit]) -> Vec<(String, Vec<&Visit>)> {
    let mut order: Vec<String> = Vec::new();
    let mut by: BTreeMap<&str, Vec<&Visit>> = BTreeMap::new();
    for v in visits {
        if !by.contains_key(v.pose.as_str()) {
            order.push(v.pose.clone());
        }
        by.entry(v.pose.as_str()).or_default().push(v);
    }
    order
        .into_iter()
        .map(|p| {
            let mut vs = by.remove(p.as_str()).unwrap_or_default();
            vs.sort_by_key(|v| v.cycle);
            (p, vs)
        })
        .collect()
}

/// Clauses 7.2.1–7.2.3 for every pose of `visits` (poses in order of first appearance).
pub fn pose_characteristics(visits: &[Visit]) -> Result<Vec<PoseResult>, IsoError> {
    check(visits)?;
    Ok(group(visits).into_iter().map(|(pose, vs)| one_pose(pose, &vs)).collect())
}

fn one_pose(pose: String, vs: &[&Visit]) -> PoseResult {
    let n = vs.len();
    let nf = n as f64;
    let attained: Vec<Vector3<f64>> = vs.iter().map(|v| v.attained.t).collect();
    let commanded: Vec<Vector3<f64>> = vs.iter().map(|v| v.commanded.t).collect();
    let barycentre = mean_vec(&attained);
    let command = mean_vec(&commanded);
    let ap_xyz = barycentre - command;
    let with_orientation = vs.iter().all(|v| v.orientation);
    let dev: Option<Vec<Vector3<f64>>> =
        with_orientation.then(|| vs.iter().map(|v| deviation(&v.attained.r, &v.commanded.r)).collect());
    let ap_abc = dev.as_ref().map(|d| mean_vec(d));

    let sigmas: Option<Vec<VisitSigma>> = vs.iter().map(|v| v.sigma).collect();
    let ap_p_u = sigmas.as_ref().map(|s| s.iter().map(|s| s.position * s.position).sum::<f64>().sqrt() / nf);
    let ap_abc_u = if with_orientation {
        sigmas.as_ref().and_then(|s| {
            let r: Option<Vec<f64>> = s.iter().map(|s| s.rotation).collect();
            r.map(|r| r.iter().map(|x| x * x).sum::<f64>().sqrt() / nf)
        })
    } else {
        None
    };

    let l: Vec<f64> = attained.iter().map(|p| (p - barycentre).norm()).collect();
    let s_l = sample_sd(&l);
    let l_mean = (n >= 2).then(|| l.iter().sum::<f64>() / nf);
    let rp_l = l_mean.zip(s_l).map(|(m, s)| m + 3.0 * s);
    let rp_abc = if with_orientation && n >= 2 {
        let reference = vs[0].commanded.r;
        let eps: Vec<Vector3<f64>> = vs.iter().map(|v| deviation(&v.attained.r, &reference)).collect();
        let sd = |k: usize| sample_sd(&eps.iter().map(|e| e[k]).collect::<Vec<_>>()).unwrap_or(0.0);
        Some(Vector3::new(3.0 * sd(0), 3.0 * sd(1), 3.0 * sd(2)))
    } else {
        None
    };
    // Two cycles: l_1 = l_2 (half the distance between the visits), so S_l = 0 by construction and
    // says nothing of the spread: no sampling uncertainty can be given.
    let rp_sampling_u = s_l.filter(|_| n >= 3).map(|s| s * (1.0 / nf + 9.0 / (2.0 * (nf - 1.0))).sqrt());
    let rp_instrument_floor = if n >= 2 {
        sigmas.as_ref().map(|s| {
            let rms = (s.iter().map(|s| s.position * s.position).sum::<f64>() / nf).sqrt();
            (CHI3_MEAN + 3.0 * CHI3_SD) * rms * ((nf - 1.0) / nf).sqrt()
        })
    } else {
        None
    };

    // 7.2.3: barycentres per approach direction.
    let mut groups: Vec<(String, Vec<usize>)> = Vec::new();
    for (i, v) in vs.iter().enumerate() {
        if let Some(a) = &v.approach {
            match groups.iter_mut().find(|(g, _)| g == a) {
                Some((_, idx)) => idx.push(i),
                None => groups.push((a.clone(), vec![i])),
            }
        }
    }
    let (mut vap_p, mut vap_abc) = (None, None);
    if groups.len() >= 2 {
        let centres: Vec<Vector3<f64>> =
            groups.iter().map(|(_, idx)| mean_vec(&idx.iter().map(|&i| attained[i]).collect::<Vec<_>>())).collect();
        let devs: Option<Vec<Vector3<f64>>> = dev
            .as_ref()
            .map(|d| groups.iter().map(|(_, idx)| mean_vec(&idx.iter().map(|&i| d[i]).collect::<Vec<_>>())).collect());
        let mut p = 0.0_f64;
        let mut abc = Vector3::<f64>::zeros();
        for h in 0..groups.len() {
            for k in h + 1..groups.len() {
                p = p.max((centres[h] - centres[k]).norm());
                if let Some(d) = &devs {
                    for c in 0..3 {
                        abc[c] = abc[c].max((d[h][c] - d[k][c]).abs());
                    }
                }
            }
        }
        vap_p = Some(p);
        vap_abc = devs.map(|_| abc);
    }
    PoseResult {
        pose,
        n,
        barycentre,
        commanded: command,
        ap_xyz,
        ap_p: ap_xyz.norm(),
        ap_abc,
        ap_p_u,
        ap_abc_u,
        l_mean,
        s_l,
        rp_l,
        rp_abc,
        rp_sampling_u,
        rp_instrument_floor,
        vap_p,
        vap_abc,
        approaches: groups.iter().map(|(g, i)| (g.clone(), i.len())).collect(),
    }
}

/// Clause 7.5 between poses `from` and `to`, over the cycles in which both were visited.
pub fn distance_characteristics(visits: &[Visit], from: &str, to: &str) -> Result<DistanceResult, IsoError> {
    check(visits)?;
    let of = |p: &str| -> Result<BTreeMap<u32, &Visit>, IsoError> {
        let m: BTreeMap<u32, &Visit> = visits.iter().filter(|v| v.pose == p).map(|v| (v.cycle, v)).collect();
        if m.is_empty() { Err(IsoError::UnknownPose(p.to_string())) } else { Ok(m) }
    };
    let (a, b) = (of(from)?, of(to)?);
    let pairs: Vec<(&Visit, &Visit)> = a.iter().filter_map(|(c, va)| b.get(c).map(|vb| (*va, *vb))).collect();
    if pairs.is_empty() {
        return Err(IsoError::NoCommonCycle(from.to_string(), to.to_string()));
    }
    let n = pairs.len();
    let nf = n as f64;
    let d: Vec<f64> = pairs.iter().map(|(p, q)| (p.attained.t - q.attained.t).norm()).collect();
    let dc: Vec<f64> = pairs.iter().map(|(p, q)| (p.commanded.t - q.commanded.t).norm()).collect();
    let axis = |k: usize, f: fn(&Visit) -> Vector3<f64>| -> Vec<f64> {
        pairs.iter().map(|(p, q)| (f(p)[k] - f(q)[k]).abs()).collect()
    };
    let att = |v: &Visit| v.attained.t;
    let com = |v: &Visit| v.commanded.t;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let d_mean = mean(&d);
    let d_commanded = mean(&dc);
    let ad_xyz = Vector3::from_fn(|k, _| mean(&axis(k, att)) - mean(&axis(k, com)));
    let rd = sample_sd(&d).map(|s| 3.0 * s);
    let rd_xyz = (n >= 2).then(|| Vector3::from_fn(|k, _| 3.0 * sample_sd(&axis(k, att)).unwrap_or(0.0)));
    let ad_u = pairs
        .iter()
        .map(|(p, q)| p.sigma.zip(q.sigma).map(|(s, t)| s.position * s.position + t.position * t.position))
        .collect::<Option<Vec<f64>>>()
        .map(|v| v.iter().sum::<f64>().sqrt() / nf);
    let rd_sampling_u = rd.map(|r| r / (2.0 * (nf - 1.0)).sqrt());
    Ok(DistanceResult {
        from: from.to_string(),
        to: to.to_string(),
        n,
        d_mean,
        d_commanded,
        ad_p: d_mean - d_commanded,
        ad_xyz,
        rd,
        rd_xyz,
        ad_u,
        rd_sampling_u,
    })
}

//! The evidence behind each accepted joint effect, as a plot shows it: the held-out residual
//! before the effect, as the angle error at its joint, binned along the effect's own variable,
//! beside what the effect predicts and what is left after it.

use nalgebra::Vector3;

use super::library::Kind;
use super::{cv, search};
use crate::kinematics::chain::basis_at;
use crate::kinematics::params::MapEdge;
use crate::kinematics::{JointTerm, Param};

/// The evidence for one accepted joint effect, as a plot can show it: the held-out residual of
/// the model before the effect, turned into the joint-angle error at the effect's joint that
/// explains it best (e = r·s / |s|², s = ∂p/∂θ_j at the pose), against the effect's own variable
/// (the joint's reading, its approach direction, its torque, the coupled joint's reading), beside
/// what the accepted effect predicts there and the held-out residual after it — binned.
#[derive(Clone, Debug, PartialEq)]
pub struct Evidence {
    /// The effect's label ([`super::library::Candidate::label`]).
    pub effect: String,
    /// The joint whose angle it corrects (0-based).
    pub joint: usize,
    /// What the x axis is.
    pub variable: EvidenceVariable,
    /// The bins, in increasing order of the x variable.
    pub bins: Vec<EvidenceBin>,
    /// 1 − Σ after² / Σ before² over the measurements' residual angles: the share of the held-out
    /// residual at this joint that the model with the effect removes. The term alone need not
    /// match the residual before it: the model before absorbs what its own parameters can of
    /// the effect (a joint offset, a link length), and the model after refits those too.
    pub explained: Option<f64>,
    /// The tested measurements used (a stop read on several reflectors counts once per reading).
    pub n: usize,
}

/// The x axis of an [`Evidence`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EvidenceVariable {
    /// A joint's reading, rad.
    Reading(usize),
    /// A joint's approach direction (−1, 0, +1).
    Approach(usize),
    /// A joint's holding torque, N·m.
    Torque(usize),
    /// The phase of a periodic term of a joint, (f·q_j) mod 2π, rad, for f cycles per
    /// revolution: the residual folded onto one period, as a periodic error is shown.
    Phase(usize, f64),
}

/// One bin of an [`Evidence`]: angles in rad.
#[derive(Clone, Debug, PartialEq)]
pub struct EvidenceBin {
    /// The bin's centre on the x axis (rad, a direction, N·m).
    pub at: f64,
    /// Tested observations in the bin.
    pub n: usize,
    /// Mean and standard error of the before-residual angle.
    pub before: f64,
    /// Standard error of that mean, s/√n (s the sample standard deviation, divisor n − 1; 0 for one
    /// observation), rad.
    pub before_sem: f64,
    /// Mean of what the effect predicts.
    pub predicted: f64,
    /// Mean of the after-residual angle (the effect included).
    pub after: f64,
}

/// Evidence bins along a continuous variable: at most this many, each with at least 5 measurements.
const EVIDENCE_BINS: usize = 24;

/// The evidence of each accepted joint effect (see [`Evidence`]); effects on no joint angle
/// (β, base, tool, payload, temperature) have none.
pub(super) fn evidence(s: &search::Search, figures: &[&cv::Heldout]) -> Vec<Evidence> {
    let mut out = Vec::new();
    for (k, c) in s.accepted.iter().enumerate() {
        let (Some(before_stage), Some(after_stage), Some(before), Some(after)) =
            (s.stages.get(k), s.stages.get(k + 1), figures.get(k), figures.get(k + 1))
        else {
            continue;
        };
        let Some(j) = c.joint else { continue };
        let variable = match c.kind {
            Kind::Backlash => EvidenceVariable::Approach(j),
            Kind::Compliance | Kind::ComplianceCubic => EvidenceVariable::Torque(j),
            Kind::Cyclic => match c.quarters {
                Some(q) => EvidenceVariable::Phase(j, q as f64 / 4.0),
                None => EvidenceVariable::Reading(j),
            },
            Kind::JointMap => EvidenceVariable::Reading(j),
            Kind::Coupling => match c.from {
                Some(f) => EvidenceVariable::Reading(f),
                None => continue,
            },
            _ => continue,
        };
        // The effect's terms and their values in the model that accepted it; table edges as the
        // chain takes them (the first and last knot of a table hold their value beyond it).
        let terms: Vec<(JointTerm, f64)> = c
            .params
            .iter()
            .filter_map(|p| match *p {
                Param::Joint(pj, t) if pj == j => after_stage.set.value(*p).map(|v| (t, v)),
                _ => None,
            })
            .collect();
        if terms.is_empty() {
            continue;
        }
        let knots: Vec<i16> = terms
            .iter()
            .filter_map(|(t, _)| if let JointTerm::Map { knot, .. } = t { Some(*knot) } else { None })
            .collect();
        let (lo, hi) = (knots.iter().min().copied(), knots.iter().max().copied());
        let predict = |st: &crate::kinematics::JointState| -> f64 {
            terms
                .iter()
                .map(|(t, v)| {
                    let edge = match t {
                        JointTerm::Map { knot, .. } => MapEdge { first: Some(*knot) == lo, last: Some(*knot) == hi },
                        _ => MapEdge::default(),
                    };
                    v * basis_at(*t, j, st, edge)
                })
                .sum()
        };
        // ∂p/∂θ_j per observation, unweighted.
        let cols = before_stage.columns(&[Param::Theta(j)]);
        let pr = &after_stage.problem;
        let sens: Vec<Option<Vector3<f64>>> = before_stage
            .problem
            .obs
            .iter()
            .map(|o| {
                let w = &o.weight;
                (w[0] > 0.0 && w[1] > 0.0 && w[2] > 0.0).then(|| {
                    Vector3::new(cols[(o.row, 0)] / w[0], cols[(o.row + 1, 0)] / w[1], cols[(o.row + 2, 0)] / w[2])
                })
            })
            .collect();
        let mut norms: Vec<f64> = sens.iter().flatten().map(|v| v.norm()).collect();
        norms.sort_by(f64::total_cmp);
        let Some(&median) = norms.get(norms.len() / 2) else { continue };
        let angle = |i: usize, e: &Vector3<f64>| -> Option<f64> {
            let sv = sens.get(i).copied().flatten()?;
            let n2 = sv.norm_squared();
            (n2.sqrt() >= 0.2 * median && n2 > 0.0).then(|| e.dot(&sv) / n2)
        };
        let after_of: std::collections::HashMap<usize, Vector3<f64>> = after.errors.iter().copied().collect();
        // (x, before angle, predicted, after angle) per tested observation.
        let mut pts: Vec<EvidencePoint> = Vec::new();
        for (i, e) in &before.errors {
            let (Some(o), Some(ea)) = (pr.obs.get(*i), after_of.get(i)) else { continue };
            let (Some(b), Some(a)) = (angle(*i, e), angle(*i, ea)) else { continue };
            let x = match variable {
                EvidenceVariable::Reading(v) => o.state.q[v],
                EvidenceVariable::Approach(v) => o.state.approach[v],
                EvidenceVariable::Torque(v) => o.state.tau[v],
                EvidenceVariable::Phase(v, f) => (f * o.state.q[v]).rem_euclid(std::f64::consts::TAU),
            };
            let p = predict(&o.state);
            if [x, b, a, p].iter().all(|v| v.is_finite()) {
                pts.push((x, b, p, a));
            }
        }
        if pts.len() < 10 {
            continue;
        }
        let sb: f64 = pts.iter().map(|p| p.1 * p.1).sum();
        let sa: f64 = pts.iter().map(|p| p.3 * p.3).sum();
        let explained = (sb > 0.0).then(|| 1.0 - sa / sb);
        out.push(Evidence {
            effect: c.label(),
            joint: j,
            variable,
            bins: evidence_bins(&mut pts, matches!(variable, EvidenceVariable::Approach(_))),
            explained,
            n: pts.len(),
        });
    }
    out
}

/// One measurement of an evidence plot: (x, before angle, predicted angle, after angle).
type EvidencePoint = (f64, f64, f64, f64);

/// Bins of (x, before, predicted, after): one per distinct value of a discrete variable, else up
/// to [`EVIDENCE_BINS`] of equal counts (at least 5 measurements each).
fn evidence_bins(pts: &mut [EvidencePoint], discrete: bool) -> Vec<EvidenceBin> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let groups: Vec<&[EvidencePoint]> = if discrete {
        pts.chunk_by(|a, b| a.0 == b.0).collect()
    } else {
        let nb = (pts.len() / 5).clamp(1, EVIDENCE_BINS);
        let size = pts.len().div_ceil(nb);
        pts.chunks(size).collect()
    };
    groups
        .into_iter()
        .map(|g| {
            let n = g.len() as f64;
            let mean = |f: &dyn Fn(&EvidencePoint) -> f64| g.iter().map(f).sum::<f64>() / n;
            let before = mean(&|p| p.1);
            let var = if g.len() > 1 { g.iter().map(|p| (p.1 - before).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
            EvidenceBin {
                at: mean(&|p| p.0),
                n: g.len(),
                before,
                before_sem: (var / n).sqrt(),
                predicted: mean(&|p| p.2),
                after: mean(&|p| p.3),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::evidence_bins;

    /// Bins by hand: a discrete variable gets one bin per value (mean, standard error of the
    /// mean); a continuous one equal-count bins in order of x.
    #[test]
    fn evidence_bins_by_hand() {
        // (x, before, predicted, after)
        let mut pts =
            vec![(1.0, 2.0, 1.0, 0.5), (-1.0, -1.0, -1.0, 0.0), (1.0, 4.0, 1.0, 1.5), (-1.0, -3.0, -1.0, -1.0)];
        let b = evidence_bins(&mut pts, true);
        assert_eq!(b.len(), 2);
        assert_eq!((b[0].at, b[0].n, b[0].before, b[0].predicted, b[0].after), (-1.0, 2, -2.0, -1.0, -0.5));
        // before −1, −3: s = √2, s.e.m. = √2/√2 = 1.
        assert!((b[0].before_sem - 1.0).abs() < 1e-15);
        assert_eq!((b[1].at, b[1].before, b[1].after), (1.0, 3.0, 1.0));
        // 12 points, continuous: 12/5 → 2 bins of 6, x = 0…11.
        let mut pts: Vec<_> = (0..12).rev().map(|i| (i as f64, 2.0 * i as f64, 0.0, 0.0)).collect();
        let b = evidence_bins(&mut pts, false);
        assert_eq!(b.iter().map(|b| (b.n, b.at, b.before)).collect::<Vec<_>>(), vec![(6, 2.5, 5.0), (6, 8.5, 17.0)]);
    }
}

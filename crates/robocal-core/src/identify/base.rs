//! The starting base pose T_0^W of a cell that has no base guess (thesis §4.2.1 needs a starting
//! point near the solution): the nominal TCP positions of the chosen measurements, computed with
//! the base at identity and each session's tool, registered onto their observed positions (ball
//! centres or measured positions) by [`crate::metrology::registration`].
//!
//! When TCPs are unknown too (reflectors on the flange, `identify_tcp`), the base and the TCPs
//! are registered in turn ([`register_base_and_tcps`]): Kabsch for the base given the TCPs, then
//! for each unknown TCP the linear least-squares point in the flange given the base, until
//! neither moves. Each half-step minimises the same sum of squares over its own unknowns, so the
//! sum never increases.

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

use super::problem::ToolBlock;
use crate::cell::{Cell, Observation};
use crate::kinematics::{Frame, JointState, ParameterSet, Tool};
use crate::metrology::registration::{RegistrationError, register, register_base};

/// Estimate T_0^W of a cell from all its measurements: χ (m, rad) and the RMS residual (m).
pub fn estimate_base(cell: &Cell) -> Result<([f64; 6], f64), RegistrationError> {
    let picks: Vec<(usize, usize)> =
        cell.sessions.iter().enumerate().flat_map(|(s, x)| (0..x.measurements.len()).map(move |i| (s, i))).collect();
    estimate_base_of(cell, &picks)
}

/// As [`estimate_base`] on the given measurements only, (session index, measurement index): the
/// ones an identification uses. Sessions measured in different instrument frames (a tracker
/// moved between days) must not be registered together.
pub(crate) fn estimate_base_of(cell: &Cell, picks: &[(usize, usize)]) -> Result<([f64; 6], f64), RegistrationError> {
    let (model, observed) = point_pairs(cell, picks);
    register_base(&model, &observed)
}

/// The base and the unknown TCPs registered on the nominal robot ([`register_base_and_tcps`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Registration {
    /// T_0^W as χ (m, rad).
    pub base: [f64; 6],
    /// Per tool block, T_T^6 as χ: the estimate for a block whose TCP is identified, its declared
    /// tool otherwise. A block without a measured orientation keeps its declared rotation.
    pub tcps: Vec<[f64; 6]>,
    /// RMS distance between the nominal model's TCP positions and the observed ones, m.
    pub rms: f64,
    /// Alternations made (0: the TCPs were all declared, or the base was given).
    pub iterations: usize,
}

/// Most alternations; they stop earlier once neither the base nor a TCP moves by 1e-10 m.
const MAX_ALTERNATIONS: usize = 500;

/// Starting values of the base and of the TCPs to identify, from the picked measurements on the
/// nominal robot: the tool blocks of the problem ([`super::problem::tool_blocks`]) and, per
/// session, its block. With `base` given (the cell's guess), only the TCPs are fitted to it, in
/// one linear step. Otherwise the base is registered with the declared TCPs (for a zero guess: the
/// flange), each unknown TCP is fitted in its flange given that base, and the two alternate to
/// convergence. Only blocks with `identify_tcp` and no guess (a zero TCP translation) move; a
/// block's rotation moves only when it observed full poses (a point has no orientation).
pub fn register_base_and_tcps(
    cell: &Cell,
    picks: &[(usize, usize)],
    blocks: &[ToolBlock],
    session_tool: &[usize],
    base: Option<[f64; 6]>,
) -> Result<Registration, RegistrationError> {
    // The flange frame of every picked measurement with an observed position, base at identity.
    let chains: Vec<_> = blocks
        .iter()
        .map(|b| {
            let flange = Tool { tcp: [0.0; 6], ..b.tool.clone() };
            ParameterSet::nominal(cell.model.clone(), flange, [0.0; 6]).nominal_chain()
        })
        .collect();
    struct Point {
        block: usize,
        flange: Frame,
        observed: Vector3<f64>,
        rotation: Option<Matrix3<f64>>,
    }
    let mut points = Vec::with_capacity(picks.len());
    for &(s, i) in picks {
        let m = &cell.sessions[s].measurements[i];
        if let Some(observed) = cell.observed_position(m) {
            let block = session_tool[s];
            let rotation = match &m.observation {
                Observation::Pose(f) => Some(f.r),
                _ => None,
            };
            points.push(Point { block, flange: chains[block].fk(&JointState::new(&m.q)), observed, rotation });
        }
    }
    let mut tcp: Vec<Frame> = blocks.iter().map(|b| Frame::from_xyzabc(&b.tool.tcp)).collect();
    let register_with = |tcp: &[Frame]| {
        let model: Vec<Vector3<f64>> = points.iter().map(|p| p.flange.transform_point(&tcp[p.block].t)).collect();
        let observed: Vec<Vector3<f64>> = points.iter().map(|p| p.observed).collect();
        register(&model, &observed)
    };
    let given = base.is_some();
    let mut base = match base {
        Some(b) => Frame::from_xyzabc(&b),
        None => register_with(&tcp)?.0,
    };
    // A TCP is unknown when it is to be identified and its guess is the flange itself (no guess:
    // the three-reflector import). A guess off the flange (the UR10 probe's transform) is kept: it
    // knows more than a fit on the nominal robot, whose errors would bias the estimate.
    let unknown: Vec<usize> = (0..blocks.len()).filter(|&b| is_unknown(&blocks[b])).collect();
    let mut iterations = 0;
    while !unknown.is_empty() && iterations < MAX_ALTERNATIONS {
        iterations += 1;
        // Each unknown TCP given the base: ‖B·(F·t) − p‖ = ‖t − F⁻¹·B⁻¹·p‖, so the least-squares t
        // is the mean of F⁻¹·B⁻¹·p over the block's points; its rotation the rotation nearest
        // to the mean of (B·F)⁻¹·R_measured (the chordal mean).
        let inv = base.inverse();
        let mut moved = 0.0f64;
        for &b in &unknown {
            let (mut sum, mut n, mut rot) = (Vector3::zeros(), 0usize, Matrix3::zeros());
            for p in points.iter().filter(|p| p.block == b) {
                sum += p.flange.inverse().transform_point(&inv.transform_point(&p.observed));
                n += 1;
                if let Some(r) = p.rotation {
                    rot += p.flange.r.transpose() * base.r.transpose() * r;
                }
            }
            if n == 0 {
                continue;
            }
            let t = sum / n as f64;
            moved = moved.max((t - tcp[b].t).norm());
            tcp[b].t = t;
            if blocks[b].has_orientation
                && let Some(r) = nearest_rotation(&rot)
            {
                tcp[b].r = r;
            }
        }
        if given {
            break;
        }
        let (next, _) = register_with(&tcp)?;
        let (dp, da) = next.distance(&base);
        base = next;
        if moved.max(dp).max(da) < 1e-10 {
            break;
        }
    }
    let ss: f64 = points
        .iter()
        .map(|p| (base.transform_point(&p.flange.transform_point(&tcp[p.block].t)) - p.observed).norm_squared())
        .sum();
    let rms = (ss / points.len().max(1) as f64).sqrt();
    let tcps = blocks
        .iter()
        .zip(&tcp)
        .map(|(b, f)| {
            let mut chi = b.tool.tcp;
            if is_unknown(b) {
                let est = f.to_xyzabc();
                let k = if b.has_orientation { 6 } else { 3 };
                chi[..k].copy_from_slice(&est[..k]);
            }
            chi
        })
        .collect();
    Ok(Registration { base: base.to_xyzabc(), tcps, rms, iterations })
}

/// A block whose TCP is to be identified and has no guess (zero translation).
fn is_unknown(b: &ToolBlock) -> bool {
    b.identify_tcp && b.tool.tcp[..3] == [0.0; 3]
}

/// The rotation nearest to `m` in the Frobenius norm (polar decomposition), or `None` for a
/// (nearly) zero matrix.
fn nearest_rotation(m: &Matrix3<f64>) -> Option<Matrix3<f64>> {
    if m.norm() < 1e-12 {
        return None;
    }
    let svd = m.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let d = (u * v_t).determinant().signum();
    Some(u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t)
}

/// The RMS distance (m) between the nominal robot's TCP positions with the base at `base` and the
/// observed positions of the picked measurements: how far a base guess starts from them. `None`
/// when no picked measurement observes a position.
pub(crate) fn miss_at(cell: &Cell, picks: &[(usize, usize)], base: &[f64; 6]) -> Option<f64> {
    let (model, observed) = point_pairs(cell, picks);
    if model.is_empty() {
        return None;
    }
    let b = Frame::from_xyzabc(base);
    let sum: f64 = model.iter().zip(&observed).map(|(m, o)| (b.transform_point(m) - o).norm_squared()).sum();
    Some((sum / model.len() as f64).sqrt())
}

/// The (nominal TCP position with the base at identity, observed position) pairs of the picked
/// measurements that have an observed position, in pick order.
fn point_pairs(cell: &Cell, picks: &[(usize, usize)]) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let chains: Vec<_> = cell
        .sessions
        .iter()
        .map(|s| ParameterSet::nominal(cell.model.clone(), s.tool.clone(), [0.0; 6]).nominal_chain())
        .collect();
    // In parallel (one FK a reading), in pick order.
    picks
        .par_iter()
        .with_min_len(super::problem::PAR_MIN_OBS)
        .filter_map(|&(s, i)| {
            let m = &cell.sessions[s].measurements[i];
            cell.observed_position(m).map(|p| (chains[s].fk(&JointState::new(&m.q)).t, p))
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell::fixtures::{irb120_cell, measurement, random_configurations, session};
    use crate::cell::{Observation, Purpose};
    use crate::kinematics::model::irb120;
    use crate::kinematics::thesis::trical_tool;

    /// Positions observed in {W} with the base at `base`: the nominal TCP, moved by T_0^W.
    fn observed(base: &[f64; 6], qs: &[Vec<f64>]) -> Vec<crate::cell::Measurement> {
        let chain = ParameterSet::nominal(irb120(), trical_tool(), *base).nominal_chain();
        qs.iter().map(|q| measurement(q.clone(), Observation::Position(chain.fk(&JointState::new(q)).t))).collect()
    }

    /// Exact positions from a known base give that base back (to rounding), with no residual.
    #[test]
    fn recovers_the_base_the_positions_were_measured_from() {
        let base = [0.160, -0.256, -0.221, 1.6, 0.009, -0.024];
        let cell = irb120_cell(vec![session(
            "id",
            Purpose::Identification,
            trical_tool(),
            observed(&base, &random_configurations(12, 1)),
        )]);
        let (chi, rms) = estimate_base(&cell).unwrap();
        let (dp, da) = Frame::from_xyzabc(&chi).distance(&Frame::from_xyzabc(&base));
        assert!(dp < 1e-12 && da < 1e-12 && rms < 1e-12, "{dp:e} m, {da:e} rad, rms {rms:e}");
    }

    /// Three reflectors ~120 mm apart, their TCPs unknown (zero guesses), no base guess: the
    /// alternation finds the base and the three TCPs from exact positions; with the base given,
    /// one step finds the TCPs. Declared TCPs are kept.
    #[test]
    fn alternation_recovers_base_and_unknown_tcps() {
        use crate::identify::problem::tool_blocks;
        let base = [0.9, -1.2, 0.4, 2.1, -0.05, 0.3];
        let nests = [[0.0, 0.060, 0.080], [0.0, -0.060, 0.080], [-0.060, 0.0, 0.080]];
        let mut sessions = Vec::new();
        for (k, n) in nests.iter().enumerate() {
            let tool = Tool { tcp: [n[0], n[1], n[2], 0.0, 0.0, 0.0], ..Tool::flange() };
            let chain = ParameterSet::nominal(irb120(), tool, base).nominal_chain();
            let ms = random_configurations(15, 20 + k as u64)
                .into_iter()
                .map(|q| {
                    let p = chain.fk(&JointState::new(&q)).t;
                    measurement(q, Observation::Position(p))
                })
                .collect();
            let mut s = session(&format!("r{k}"), Purpose::Identification, Tool::flange(), ms);
            s.identify_tcp = k < 2;
            if k == 2 {
                s.tool.tcp[..3].copy_from_slice(n); // declared, and right
            }
            sessions.push(s);
        }
        let cell = irb120_cell(sessions);
        let picks: Vec<(usize, usize)> = (0..3).flat_map(|s| (0..15).map(move |i| (s, i))).collect();
        let (blocks, session_tool) = tool_blocks(&cell, &picks);
        for given in [None, Some(base)] {
            let r = register_base_and_tcps(&cell, &picks, &blocks, &session_tool, given).unwrap();
            let (dp, da) = Frame::from_xyzabc(&r.base).distance(&Frame::from_xyzabc(&base));
            assert!(dp < 1e-9 && da < 1e-9, "base {dp:e} m {da:e} rad after {} alternations", r.iterations);
            for (k, n) in nests.iter().enumerate() {
                let err = (Vector3::from_column_slice(&r.tcps[k][..3]) - Vector3::from(*n)).norm();
                assert!(err < 1e-9, "TCP {k}: {err:e} m");
                assert_eq!(r.tcps[k][3..], [0.0; 3], "positions say nothing of the TCP's rotation");
            }
            assert!(r.rms < 1e-9, "rms {}", r.rms);
            assert_eq!(r.iterations == 1, given.is_some(), "one TCP step when the base is given");
        }
    }

    /// Only the picked measurements are registered: a session measured in another frame spoils
    /// the fit of the whole cell but not the registration of the first session alone. Ball
    /// observations in a cell without an artefact have no position and are left out.
    #[test]
    fn registers_the_picked_measurements_only() {
        let (b1, b2) = ([0.160, -0.256, -0.221, 1.6, 0.009, -0.024], [0.9, 0.4, -0.2, -0.5, 0.0, 0.0]);
        let mut first = observed(&b1, &random_configurations(10, 2));
        first.push(measurement(random_configurations(1, 3).remove(0), Observation::Ball(1)));
        let mut cell = irb120_cell(vec![
            session("day1", Purpose::Identification, trical_tool(), first),
            session("day2", Purpose::Identification, trical_tool(), observed(&b2, &random_configurations(10, 4))),
        ]);
        cell.artefact = None;
        let picks: Vec<(usize, usize)> = (0..11).map(|i| (0, i)).collect();
        let (chi, rms) = estimate_base_of(&cell, &picks).unwrap();
        assert!(Frame::from_xyzabc(&chi).distance(&Frame::from_xyzabc(&b1)).0 < 1e-12 && rms < 1e-12);
        let (_, rms_all) = estimate_base(&cell).unwrap();
        assert!(rms_all > 0.1, "two frames registered together: rms {rms_all} m");
        // Too few positions is the registration's error.
        assert_eq!(estimate_base_of(&cell, &picks[..2]), Err(RegistrationError::TooFew(2)));
    }
}

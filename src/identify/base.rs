//! The starting base pose T_0^W of a cell that has no base guess (thesis §4.2.1 needs a starting
//! point near the solution): the nominal TCP positions of the chosen measurements, computed with
//! the base at identity and each session's tool, registered onto their observed positions (ball
//! centres or measured positions) by [`crate::metrology::registration`].

use nalgebra::Vector3;

use crate::cell::Cell;
use crate::kinematics::{JointState, ParameterSet};
use crate::metrology::registration::{RegistrationError, register_base};

/// Estimate T_0^W of a cell from all its measurements: χ (m, rad) and the RMS residual (m).
pub fn estimate_base(cell: &Cell) -> Result<([f64; 6], f64), RegistrationError> {
    let picks: Vec<(usize, usize)> =
        cell.sessions.iter().enumerate().flat_map(|(s, x)| (0..x.measurements.len()).map(move |i| (s, i))).collect();
    estimate_base_of(cell, &picks)
}

/// As [`estimate_base`] on the given measurements only, (session index, measurement index): the
/// ones an identification uses. Sessions measured in different instrument frames (a tracker
/// moved between days) must not be registered together.
pub fn estimate_base_of(cell: &Cell, picks: &[(usize, usize)]) -> Result<([f64; 6], f64), RegistrationError> {
    let (model, observed) = point_pairs(cell, picks);
    register_base(&model, &observed)
}

/// The (nominal TCP position with the base at identity, observed position) pairs of the picked
/// measurements that have an observed position, in pick order.
fn point_pairs(cell: &Cell, picks: &[(usize, usize)]) -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
    let chains: Vec<_> = cell
        .sessions
        .iter()
        .map(|s| ParameterSet::nominal(cell.model.clone(), s.tool.clone(), [0.0; 6]).nominal_chain())
        .collect();
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for &(s, i) in picks {
        let m = &cell.sessions[s].measurements[i];
        if let Some(p) = cell.observed_position(m) {
            a.push(chains[s].fk(&JointState::new(&m.q)).t);
            b.push(p);
        }
    }
    (a, b)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cell::fixtures::{irb120_cell, measurement, random_configurations, session};
    use crate::cell::{Observation, Purpose};
    use crate::kinematics::Frame;
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

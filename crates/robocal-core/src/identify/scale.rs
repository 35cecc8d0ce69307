//! A unit mistake caught before it is fitted: positions in centimetres, inches or metres read as
//! millimetres make a robot of a tenth, a 25th or a thousandth of its size, which a fit of the
//! lengths then "identifies" (a2 27 mm for 270 mm) with a small residual.

use rayon::prelude::*;

use super::IdentifyError;
use super::problem::Problem;
use crate::cell::Cell;

/// Fewer readings than this in a session say too little about its spread to judge it.
const MIN_READINGS: usize = 10;
/// Below this spread of the nominal robot's TCP (m) the motion is too small to judge: an unknown
/// reflector offset, turned by the wrist, would dominate the measured spread.
const MIN_NOMINAL_SPREAD: f64 = 0.05;
/// The largest ratio of the two spreads, either way, that an unknown TCP (up to a few hundred mm
/// from the flange) and the base's placement can explain. Every unit confusion lies beyond it
/// (×10, ×25.4, ×1000 and their inverses).
const MAX_SPREAD_RATIO: f64 = 3.0;

/// The checks of an identification's readings before anything is fitted — units
/// ([`IdentifyError::PositionScale`], [`IdentifyError::JointUnit`]), the pairing of positions
/// with readings ([`IdentifyError::RowsShifted`]), a mirrored frame
/// ([`IdentifyError::MirroredFrame`]) and joint conventions
/// ([`IdentifyError::JointConvention`]) — on their own, on the nominal robot with the default
/// options: for an importer, to refuse a file before anything is written. `Ok` also when the
/// checks cannot be set up (an identification then says why); `Ok(Some(note))` when the nominal
/// robot misses the positions by far more than a real robot's few millimetres and no change of
/// the readings explains it (a wrong length in a robot file): the importer says so.
pub fn check_readings(cell: &Cell) -> Result<Option<String>, IdentifyError> {
    let opts = super::IdentifyOptions::default();
    match super::prepare(cell, &opts) {
        Ok(p) => {
            check_position_scale(&p.problem, &p.x0, cell)?;
            super::convention::check(cell, &opts, p.start_rms)
        }
        Err(_) => Ok(None),
    }
}

/// Per session of measured points or poses: the RMS distance of the measured positions from their
/// centroid against that of the nominal robot's declared TCP (the flange where none is declared) at
/// the same joint readings, which neither the base pose nor the instrument's frame changes. Refused when they differ by more than
/// [`MAX_SPREAD_RATIO`]: the positions are not in the unit the file says, or the joints are not —
/// named when the readings taken as radians make the spreads agree ([`IdentifyError::JointUnit`]).
pub(crate) fn check_position_scale(problem: &Problem, x0: &[f64], cell: &Cell) -> Result<(), IdentifyError> {
    let chains = problem.chains(x0);
    for (s, session) in cell.sessions.iter().enumerate() {
        let obs: Vec<_> = problem.obs.iter().filter(|o| o.session == s && !o.is_ball()).collect();
        if obs.len() < MIN_READINGS {
            continue;
        }
        // The declared TCP, not the start's: a TCP registered from the data carries their scale.
        let declared: Vec<_> = chains.iter().map(|c| c.with_base_tool(c.base_pose(), session.tool.tcp)).collect();
        let measured = spread(obs.iter().map(|o| o.measured_position()));
        if !measured.is_finite() {
            continue;
        }
        // One FK a reading, in parallel, in order.
        let at_declared: Vec<_> =
            obs.par_iter().with_min_len(super::problem::PAR_MIN_OBS).map(|o| o.fk(&declared[o.tool]).t).collect();
        let nominal = spread(at_declared.into_iter());
        let agrees = |nominal: f64| {
            nominal >= MIN_NOMINAL_SPREAD && (1.0 / MAX_SPREAD_RATIO..=MAX_SPREAD_RATIO).contains(&(measured / nominal))
        };
        if agrees(nominal) {
            continue;
        }
        // Radians read as degrees: every reading, taken as radians, within its joint's limits (a
        // robot that moved metres turns more than a few degrees somewhere), and the readings as
        // radians move the nominal TCP as measured.
        let radians_read_as_degrees = |q: &[f64]| {
            cell.model
                .links
                .iter()
                .zip(q)
                .all(|(l, q)| (l.limits[0] - 1e-9..=l.limits[1] + 1e-9).contains(&q.to_degrees()))
        };
        if obs.iter().all(|o| radians_read_as_degrees(&o.state.q)) {
            let as_radians = |o: &&super::problem::Obs| {
                let mut state = o.state;
                state.q.iter_mut().for_each(|q| *q = q.to_degrees());
                declared[o.tool].fk(&state).t
            };
            let nominal_radians = spread(obs.iter().map(as_radians));
            if agrees(nominal_radians) {
                return Err(IdentifyError::JointUnit {
                    session: session.name.clone(),
                    measured,
                    nominal,
                    nominal_radians,
                });
            }
        }
        if nominal >= MIN_NOMINAL_SPREAD {
            let ratio = measured / nominal;
            return Err(IdentifyError::PositionScale { session: session.name.clone(), measured, nominal, ratio });
        }
    }
    Ok(())
}

/// RMS distance of points from their centroid, m.
pub(crate) fn spread(points: impl Iterator<Item = nalgebra::Vector3<f64>>) -> f64 {
    let p: Vec<_> = points.collect();
    let n = p.len().max(1) as f64;
    let centroid = p.iter().sum::<nalgebra::Vector3<f64>>() / n;
    (p.iter().map(|x| (x - centroid).norm_squared()).sum::<f64>() / n).sqrt()
}

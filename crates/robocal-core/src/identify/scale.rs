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
/// from the flange) and the base's placement can explain where the arm moves the flange. Every
/// unit confusion lies beyond it (×10, ×25.4, ×1000 and their inverses).
const MAX_SPREAD_RATIO: f64 = 3.0;
/// The farthest a measured point (a reflector, a tool the file does not declare) is taken to lie
/// from the declared TCP, m. Where the wrist turns more than the arm moves, a point this far off
/// spreads more than [`MAX_SPREAD_RATIO`] times the TCP (the sweeps of a FANUC R-2000iC
/// measured at reflectors 200 mm off the flange: 229 mm against the flange's 74 mm, read as a unit
/// mistake before): [`reach`] bounds its spread from the turns themselves.
pub const MAX_TCP_OFFSET: f64 = 0.5;
/// Margin on [`reach`]'s bounds for the real robot's geometry and the instrument.
const REACH_MARGIN: f64 = 1.25;

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
            obs.par_iter().with_min_len(super::problem::PAR_MIN_OBS).map(|o| o.fk(&declared[o.tool])).collect();
        let nominal = spread(at_declared.iter().map(|f| f.t));
        let agrees = |nominal: f64| {
            nominal >= MIN_NOMINAL_SPREAD && (1.0 / MAX_SPREAD_RATIO..=MAX_SPREAD_RATIO).contains(&(measured / nominal))
        };
        // Above the ratio, a point off the TCP that the wrist turns may explain the spread. Not
        // below it: random orientations bound nothing there (the least spread of a point 0.5 m
        // off is 0), and positions in cm read as mm would pass.
        let reach = reach(&at_declared, nominal, MAX_TCP_OFFSET);
        if agrees(nominal)
            || (nominal >= MIN_NOMINAL_SPREAD && measured > nominal && measured <= reach.1 * REACH_MARGIN)
        {
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
            return Err(IdentifyError::PositionScale {
                session: session.name.clone(),
                measured,
                nominal,
                ratio,
                reach,
            });
        }
    }
    Ok(())
}

/// The least and the most RMS spread, m, of a point fixed at up to `offset` (m) from the frames'
/// origin, over the frames whose origins spread `centre` (m): with p_i = t_i + R_i·r, Minkowski's
/// inequality puts the spread of p within spread(t) ± ‖r‖·√λ_max(mean (R_i − R̄)ᵀ(R_i − R̄)). The
/// least is said in the refusal; only the most is a bound of the check.
fn reach(frames: &[crate::kinematics::Frame], centre: f64, offset: f64) -> (f64, f64) {
    let n = frames.len().max(1) as f64;
    let mean = frames.iter().map(|f| f.r).sum::<nalgebra::Matrix3<f64>>() / n;
    let m = frames.iter().map(|f| (f.r - mean).transpose() * (f.r - mean)).sum::<nalgebra::Matrix3<f64>>() / n;
    let turn = m.symmetric_eigenvalues().max().max(0.0).sqrt() * offset;
    ((centre - turn).max(0.0), centre + turn)
}

/// RMS distance of points from their centroid, m.
pub(crate) fn spread(points: impl Iterator<Item = nalgebra::Vector3<f64>>) -> f64 {
    let p: Vec<_> = points.collect();
    let n = p.len().max(1) as f64;
    let centroid = p.iter().sum::<nalgebra::Vector3<f64>>() / n;
    (p.iter().map(|x| (x - centroid).norm_squared()).sum::<f64>() / n).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::Frame;
    use nalgebra::{Rotation3, Vector3};
    use rand::{Rng, SeedableRng};

    fn frames(rng: &mut rand_chacha::ChaCha8Rng, n: usize, arm: f64, turn: f64) -> Vec<Frame> {
        (0..n)
            .map(|_| Frame {
                r: *Rotation3::from_scaled_axis(Vector3::from_fn(|_, _| rng.random_range(-turn..turn))).matrix(),
                t: Vector3::from_fn(|_, _| arm * rng.random_range(-1.0..1.0)),
            })
            .collect()
    }

    /// Every point up to the offset from the frames' origin spreads within the bounds, and with the
    /// origins fixed the most is reached along the turns' widest direction.
    #[test]
    fn a_point_off_the_origin_spreads_within_the_reach() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        for (arm, turn) in [(0.3, 0.2), (0.05, 2.0), (0.0, 1.0)] {
            let f = frames(&mut rng, 60, arm, turn);
            let (lo, hi) = reach(&f, spread(f.iter().map(|x| x.t)), 0.5);
            for _ in 0..300 {
                let r = Vector3::<f64>::from_fn(|_, _| rng.random_range(-1.0..1.0)).normalize()
                    * rng.random_range(0.0..0.5);
                let s = spread(f.iter().map(|x| x.t + x.r * r));
                assert!(s >= lo - 1e-12 && s <= hi + 1e-12, "{s} outside {lo}–{hi}");
            }
            if arm == 0.0 {
                let n = f.len() as f64;
                let mean = f.iter().map(|x| x.r).sum::<nalgebra::Matrix3<f64>>() / n;
                let m = f.iter().map(|x| (x.r - mean).transpose() * (x.r - mean)).sum::<nalgebra::Matrix3<f64>>() / n;
                let e = m.symmetric_eigen();
                let k = e.eigenvalues.imax();
                let r = e.eigenvectors.column(k) * 0.5;
                let s = spread(f.iter().map(|x| x.t + x.r * r));
                assert!((s - hi).abs() < 1e-12 && lo == 0.0, "{s} against {hi}");
            }
        }
    }
}

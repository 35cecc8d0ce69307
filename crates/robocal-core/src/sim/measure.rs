//! Simulated measuring runs: the true robot measured by the TriCal on the artefact's balls and
//! by a laser tracker on reflector nests, along a list of planned configurations.
//!
//! TriCal (digest §7, thesis §2.3): the robot goes to the planned joints, the indicators are
//! read, the TCP is moved by the reading until it sits within ε of the ball centre, and the
//! joints are recorded.
//! Simulated as that loop: the first approach leaves the physical TCP within ±0.35 mm per axis of
//! the ball (the thesis's initial-deviation range, §2.4); each stop adds a fresh non-repeatable
//! offset η (physical = FK_true(q) + η); each correction moves the TCP by −d in the tool frame
//! *as the controller's nominal model computes it*, so it lands a little off; the loop ends
//! when ‖d‖ ≤ ε. The recorded joints are the last ones. The error of the pair (q_a, ball) that
//! identification sees, FK_true(q_a) − c_k, is therefore the previous stop's η plus the
//! correction's model error — about the repeatability, not ε: the indicators measured the
//! physical offset that the last move removed. Tracker: the robot stops at the planned joints
//! (recorded as commanded); the reflector is physically at FK_true(q) + η and the tracker reads
//! that plus its own noise. Times advance 25 s per TriCal measurement (thesis §2.3) and 10 s
//! per tracker measurement; the temperature follows [`Effects::temperature_at`]; each joint's
//! approach direction is the sign of its last move. Consecutive tracker poses at the same joints
//! are one stop read on several nests: the robot does not move, so they share the approach and
//! the repeatability offset. Every session is in measuring order (`order` measured) and every
//! measurement carries its stop's `sequence` number, one numbering for the whole run (TriCal
//! stops first, then the tracker's; the nests' sessions interleave in it).

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::effects::Effects;
use super::instruments::{Centring, Noise};
use super::truth::{Truth, TruthSolveError};
use crate::cell::{Artefact, Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session};
use crate::kinematics::{Frame, ParameterSet, RobotModel, Tool};
use crate::metrology::TriCal;

/// A planned TriCal measurement: joints and the ball (1-based).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallPose {
    /// Planned joints, rad: where the robot goes before centring.
    pub q: [f64; 6],
    /// The ball, 1-based (1, 2 or 3).
    pub ball: usize,
}

/// A planned tracker measurement: joints and the reflector nest (0-based index into the tools).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NestPose {
    /// Joints, rad: the robot stops exactly there and they are recorded as commanded.
    pub q: [f64; 6],
    /// The nest, 0-based index into [`Rig::nests`].
    pub nest: usize,
}

/// The fixed parts of a virtual cell.
#[derive(Clone, Debug)]
pub struct Rig<'a> {
    /// The nominal model written to the cell file (what the controller knows).
    pub model: &'a RobotModel,
    /// T_0^W as the controller knows it (the cell file's base guess).
    pub base_guess: [f64; 6],
    /// The artefact: the ball triangle that defines {W}, and the ball diameter.
    pub artefact: &'a Artefact,
    /// The TriCal tool used for identification.
    pub trical: &'a Tool,
    /// One tool per reflector nest, for validation.
    pub nests: &'a [Tool],
    /// Laser tracker position in the robot base frame {0}, m.
    pub tracker_in_base: Vector3<f64>,
    /// Instrument and robot noise.
    pub noise: Noise,
    /// Record the TriCal indicator readings left after centring.
    pub record_indicators: bool,
}

/// What really happened at one measurement (for scoring and tests).
#[derive(Clone, Debug, PartialEq)]
pub struct MeasurementTruth {
    /// Where the true model puts the TCP at the recorded joints, {W}: the best any model can do.
    pub model_position: Vector3<f64>,
    /// Where the TCP physically was, {W} (model position minus the repeatability offset).
    pub physical_position: Vector3<f64>,
    /// TriCal: the centring offset u of the physical TCP from the ball centre, {W}; `None` for
    /// a tracker measurement.
    pub centring_offset: Option<Vector3<f64>>,
}

/// The truth behind each session's measurements, in the cell's order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RunTruth {
    /// Per session: its name and one truth per measurement, in the session's order.
    pub sessions: Vec<(String, Vec<MeasurementTruth>)>,
}

/// Why a run could not be measured.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MeasureError {
    /// A [`BallPose`] names a ball the artefact does not have (not 1, 2 or 3).
    #[error("ball {0} is not on the artefact")]
    Ball(usize),
    /// A [`NestPose`] names a nest beyond [`Rig::nests`].
    #[error("nest {0} does not exist")]
    Nest(usize),
    /// The true robot could not be put at a TriCal measurement's pose, or a centring correction
    /// met a singular nominal Jacobian (then `source` holds the reading and the moves made).
    #[error("measurement {index} of {session}: {source}")]
    Solve {
        /// The session (`trical-1`).
        session: String,
        /// The measurement, 0-based.
        index: usize,
        /// The failed solve.
        source: TruthSolveError,
    },
    /// Auto-centring did not bring the reading within ε in [`MAX_CENTRING_MOVES`] moves.
    #[error(
        "measurement {index} of {session}: auto-centring did not reach ε in {iterations} moves (last reading {reading_mm:.4} mm)"
    )]
    Centring {
        /// The session (`trical-1`).
        session: String,
        /// The measurement, 0-based.
        index: usize,
        /// Correction moves made.
        iterations: usize,
        /// The last reading's length, mm.
        reading_mm: f64,
    },
}

/// Half-width of the first approach's deviation from the ball centre, per axis, m (thesis §2.4:
/// the indicators' design range for the initial deviation, ±0.350 mm).
pub(crate) const INITIAL_DEVIATION: f64 = 0.35e-3;
/// Correction moves after which auto-centring gives up.
pub const MAX_CENTRING_MOVES: usize = 30;

/// Seconds per TriCal measurement (centring loop included, thesis §2.3).
pub(crate) const TRICAL_SECONDS: f64 = 25.0;
/// Seconds per tracker reading (each nest read at a stop counts once).
pub(crate) const TRACKER_SECONDS: f64 = 10.0;

/// Simulate the TriCal run on `balls` then the tracker run on `nests`, starting from `home`
/// (rad; the robot returns home between the runs), as the module describes.
///
/// Returns the cell — `rig`'s model, base guess and artefact; a session `trical-1`
/// (identification, the TriCal tool) and one `tracker-n{k}` (validation, nest k's tool, 1-based)
/// per nest that was read — and the truth behind every measurement. Times run on from the
/// TriCal run into the tracker run, and readings are in {W} (the tracker position is moved
/// there with the truth's base).
///
/// Random: the centring offsets, repeatability offsets and tracker noise come from ChaCha8
/// seeded with `seed`, on a stream of its own (so they do not repeat the planner's draws for the
/// same seed). Same inputs, same seed: the same cell, to the bit.
///
/// Errors: [`MeasureError`] — an unknown ball or nest, a pose the true robot cannot be solved
/// to, or a centring loop that does not converge.
pub fn measure(
    truth: &Truth,
    rig: &Rig<'_>,
    home: &[f64; 6],
    balls: &[BallPose],
    nests: &[NestPose],
    seed: u64,
) -> Result<(Cell, RunTruth), MeasureError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(0x6d65_6173); // "meas": independent of the planner's stream
    let effects: &Effects = &truth.effects;
    let trical = TriCal::default();
    let mut prev = *home;
    let mut t = 0.0;
    let mut run = RunTruth::default();

    // TriCal identification run.
    let robot = truth.robot(rig.trical);
    let nominal = ParameterSet::nominal(rig.model.clone(), rig.trical.clone(), rig.base_guess).nominal_chain();
    let mut id = Vec::with_capacity(balls.len());
    let mut id_truth = Vec::with_capacity(balls.len());
    for (i, p) in balls.iter().enumerate() {
        let centre = rig.artefact.triangle.ball(p.ball).ok_or(MeasureError::Ball(p.ball))?;
        let approach = approach(&prev, &p.q);
        let temp = effects.temperature_at(t);
        let r_true = robot.tcp(&robot.state(&p.q, &approach, temp)).r;
        let fail = |source| MeasureError::Solve { session: "trical-1".into(), index: i, source };
        let (q, fk, u) = match rig.noise.centring {
            Centring::UniformBall => {
                let u = rig.noise.centring_offset(&mut rng);
                let r = rig.noise.repeatability_offset(&mut rng);
                let q = robot.solve(&Frame::new(r_true, centre + u + r), &p.q, &approach, temp).map_err(fail)?;
                let mut qa = [0.0; 6];
                qa.copy_from_slice(&q[..6]);
                (qa, robot.tcp(&robot.state(&qa, &approach, temp)), u)
            }
            Centring::Loop => {
                // First approach: the physical TCP lands within the initial-deviation box of the ball.
                let o0 = Vector3::from_fn(|_, _| rng.random_range(-INITIAL_DEVIATION..=INITIAL_DEVIATION));
                let mut eta = -rig.noise.repeatability_offset(&mut rng);
                let q0 = robot.solve(&Frame::new(r_true, centre + o0 - eta), &p.q, &approach, temp).map_err(fail)?;
                let mut q = [0.0; 6];
                q.copy_from_slice(&q0[..6]);
                let mut moves = 0;
                let (fk, u) = loop {
                    let f = robot.tcp(&robot.state(&q, &approach, temp));
                    let u = f.t + eta - centre;
                    // ε = 0 (a noise-free study): centre to 1 pm.
                    if u.norm() <= rig.noise.epsilon.max(1e-12) {
                        break (f, u);
                    }
                    if moves == MAX_CENTRING_MOVES {
                        return Err(MeasureError::Centring {
                            session: "trical-1".into(),
                            index: i,
                            iterations: moves,
                            reading_mm: u.norm() * 1e3,
                        });
                    }
                    // The indicators read u in the TriCal frame; the controller moves its tool frame by
                    // −reading, computed on its own nominal model (one Newton step of its joint Jacobian
                    // is exact to far below a nanometre for sub-millimetre moves).
                    let reading = f.r.transpose() * u;
                    let tr = nominal.trace(&nominal.joint_angles(&crate::kinematics::JointState::new(&q)));
                    let step = tr.tcp.r * -reading;
                    let jt = nominal.joint_jacobian(&tr);
                    let e = nalgebra::Vector6::new(step.x, step.y, step.z, 0.0, 0.0, 0.0);
                    let dq = nalgebra::Matrix6::from_fn(|r, k| jt[k][r])
                        .lu()
                        .solve(&e)
                        .ok_or_else(|| fail(TruthSolveError { residual_mm: u.norm() * 1e3, iterations: moves }))?;
                    for k in 0..6 {
                        q[k] += dq[k];
                    }
                    eta = -rig.noise.repeatability_offset(&mut rng);
                    moves += 1;
                };
                (q, fk, u)
            }
        };
        let indicators = if rig.record_indicators {
            // The ball centre seen from the physical TCP, in the TriCal (tool) frame.
            let b = fk.r.transpose() * (-u);
            trical.readings(&(trical.zero_centre + b)).ok()
        } else {
            None
        };
        let mut qa = [0.0; 6];
        qa.copy_from_slice(&q[..6]);
        id.push(Measurement {
            q: qa.to_vec(),
            observation: Observation::Ball(p.ball),
            temperature_c: Some(temp),
            time_s: Some(t),
            sequence: Some(i as u64),
            approach: Some(approach.iter().map(|&a| a as i8).collect()),
            indicators,
            sigma: None,
        });
        id_truth.push(MeasurementTruth {
            model_position: fk.t,
            physical_position: centre + u,
            centring_offset: Some(u),
        });
        prev = qa;
        t += TRICAL_SECONDS;
    }
    let mut sessions = vec![Session {
        name: "trical-1".into(),
        purpose: Purpose::Identification,
        instrument: Instrument::TriCal,
        tool: rig.trical.clone(),
        identify_tcp: false,
        target: None,
        measurements: id,
        order: MeasuringOrder::Measured,
    }];
    run.sessions.push(("trical-1".into(), id_truth));

    // Laser-tracker validation run: one session per reflector nest, in measuring order within each.
    let base = truth.set.pose_of(crate::kinematics::Param::Base);
    let tracker_w = Frame::from_xyzabc(&base).transform_point(&rig.tracker_in_base);
    let robots: Vec<_> = rig.nests.iter().map(|n| truth.robot(n)).collect();
    let mut per_nest: Vec<(Vec<Measurement>, Vec<MeasurementTruth>)> = vec![(Vec::new(), Vec::new()); rig.nests.len()];
    // Between the runs the TriCal's reflectors are fitted and the robot goes home.
    prev = *home;
    let mut stop: Option<Stop> = None;
    let mut next_stop = balls.len() as u64;
    for p in nests {
        let robot = robots.get(p.nest).ok_or(MeasureError::Nest(p.nest))?;
        let (approach, eta, sequence) = match stop {
            // Another nest read at the same stop: the robot did not move.
            Some((q, a, eta, n)) if q == p.q => (a, eta, n),
            _ => {
                let a = approach(&prev, &p.q);
                let eta = rig.noise.repeatability_offset(&mut rng);
                stop = Some((p.q, a, eta, next_stop));
                next_stop += 1;
                (a, eta, next_stop - 1)
            }
        };
        let temp = effects.temperature_at(t);
        let fk = robot.tcp(&robot.state(&p.q, &approach, temp)).t;
        let physical = fk - eta;
        let reading = physical + rig.noise.tracker_error(&mut rng, (physical - tracker_w).norm());
        per_nest[p.nest].0.push(Measurement {
            q: p.q.to_vec(),
            observation: Observation::Position(reading),
            temperature_c: Some(temp),
            time_s: Some(t),
            sequence: Some(sequence),
            approach: Some(approach.iter().map(|&a| a as i8).collect()),
            indicators: None,
            sigma: None,
        });
        per_nest[p.nest].1.push(MeasurementTruth {
            model_position: fk,
            physical_position: physical,
            centring_offset: None,
        });
        prev = p.q;
        t += TRACKER_SECONDS;
    }
    for (k, (ms, tr)) in per_nest.into_iter().enumerate() {
        if ms.is_empty() {
            continue;
        }
        let name = format!("tracker-n{}", k + 1);
        sessions.push(Session {
            name: name.clone(),
            purpose: Purpose::Validation,
            instrument: Instrument::LaserTracker,
            tool: rig.nests[k].clone(),
            identify_tcp: false,
            target: None,
            measurements: ms,
            order: MeasuringOrder::Measured,
        });
        run.sessions.push((name, tr));
    }
    let cell = Cell {
        model: rig.model.clone(),
        base_guess: Some(rig.base_guess),
        artefact: Some(rig.artefact.clone()),
        sessions,
    };
    Ok((cell, run))
}

/// A tracker stop: its joints, the approach into it, its repeatability offset, its number.
type Stop = ([f64; 6], [f64; 6], Vector3<f64>, u64);

/// Sign of each joint's move from `from` to `to`.
fn approach(from: &[f64; 6], to: &[f64; 6]) -> [f64; 6] {
    let mut a = [0.0; 6];
    for j in 0..6 {
        let d = to[j] - from[j];
        a[j] = if d > 0.0 {
            1.0
        } else if d < 0.0 {
            -1.0
        } else {
            0.0
        };
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::frame::{rot_x, rot_z};
    use crate::kinematics::model::irb120;
    use crate::kinematics::thesis::{TABLE_5_1_NOMINAL_BASE, irb120_table_5_1, trical_tool};
    use crate::kinematics::{AnalyticIk, Branch, ParameterSet};
    use crate::metrology::BallTriangle;

    fn rig_parts() -> (RobotModel, [f64; 6], Artefact, Tool, Vec<Tool>) {
        let b = TABLE_5_1_NOMINAL_BASE;
        let base = [b[0] * 1e-3, b[1] * 1e-3, b[2] * 1e-3, b[3].to_radians(), b[4].to_radians(), b[5].to_radians()];
        let artefact =
            Artefact { triangle: BallTriangle::from_distances(0.3, 0.3, 0.3).unwrap(), ball_diameter: 0.0127 };
        let nest = Tool { tcp: [0.0, 0.06, 0.08, 0.0, 0.0, 0.0], ..trical_tool() };
        (irb120(), base, artefact, trical_tool(), vec![nest])
    }

    /// TriCal straight above each ball (tool z down), several spins, on the nominal model.
    fn planned(model: &RobotModel, base: [f64; 6], artefact: &Artefact, tool: &Tool) -> Vec<BallPose> {
        let chain = ParameterSet::nominal(model.clone(), tool.clone(), base).nominal_chain();
        let ik = AnalyticIk::new(model, chain.base(), chain.tool()).unwrap();
        let mut out = Vec::new();
        for ball in 1..=3 {
            for spin in [0.0f64, 0.5, 1.0, 2.0] {
                let target =
                    Frame::new(rot_z(spin) * rot_x(std::f64::consts::PI), artefact.triangle.ball(ball).unwrap());
                if let Some(q) = Branch::ALL.iter().find_map(|&b| ik.solve(&target, b).ok()) {
                    out.push(BallPose { q, ball });
                }
            }
        }
        assert!(out.len() >= 6);
        out
    }

    #[test]
    fn recorded_joints_put_the_true_tcp_on_the_ball() {
        let (model, base, artefact, tool, nests) = rig_parts();
        let balls = planned(&model, base, &artefact, &tool);
        let nest_poses: Vec<NestPose> = balls.iter().map(|p| NestPose { q: p.q, nest: 0 }).collect();
        for (noise, spec) in
            [(Noise::none(), ""), (Noise::default(), ""), (Noise::default(), "backlash,thermal,link_bending,tool_mass")]
        {
            let truth = Truth::new(irb120_table_5_1(trical_tool()), Effects::parse(spec, 6).unwrap());
            let rig = Rig {
                model: &model,
                base_guess: base,
                artefact: &artefact,
                trical: &tool,
                nests: &nests,
                tracker_in_base: Vector3::new(3.0, 0.5, 0.8),
                noise: noise.clone(),
                record_indicators: true,
            };
            let (cell, run) = measure(&truth, &rig, &[0.0, 0.0, 0.0, 0.0, 0.5, 0.0], &balls, &nest_poses, 4).unwrap();
            let robot = truth.robot(&tool);
            for (m, mt) in cell.sessions[0].measurements.iter().zip(&run.sessions[0].1) {
                let approach: Vec<f64> = m.approach.as_ref().unwrap().iter().map(|&a| a as f64).collect();
                let fk = robot.tcp(&robot.state(&m.q, &approach, m.temperature_c.unwrap())).t;
                let centre = cell.observed_position(m).unwrap();
                assert!((fk - mt.model_position).norm() < 1e-12);
                assert!((mt.physical_position - centre).norm() <= noise.epsilon.max(1e-12) + 1e-15);
                if noise.epsilon == 0.0 && noise.repeatability == 0.0 {
                    assert!((fk - centre).norm() < 1e-12);
                }
                // Indicator readings decode to the centring offset (trilateration, tool frame).
                let d = m.indicators.unwrap();
                let off = TriCal::default().offset(d).unwrap();
                let r = robot.tcp(&robot.state(&m.q, &approach, m.temperature_c.unwrap())).r;
                assert!((r * off + mt.centring_offset.unwrap()).norm() < 1e-9);
            }
            // The tracker read the nest near its true position.
            for (m, mt) in cell.sessions[1].measurements.iter().zip(&run.sessions[1].1) {
                let p = cell.observed_position(m).unwrap();
                assert!((p - mt.model_position).norm() < if noise.tracker_sigma == 0.0 { 1e-15 } else { 2e-4 });
            }
        }
    }

    #[test]
    fn same_seed_same_bytes() {
        let (model, base, artefact, tool, nests) = rig_parts();
        let balls = planned(&model, base, &artefact, &tool);
        let truth = Truth::new(irb120_table_5_1(trical_tool()), Effects::default());
        let rig = Rig {
            model: &model,
            base_guess: base,
            artefact: &artefact,
            trical: &tool,
            nests: &nests,
            tracker_in_base: Vector3::new(3.0, 0.5, 0.8),
            noise: Noise::default(),
            record_indicators: false,
        };
        // Debug prints every f64 in its shortest round-tripping form: equal text, equal values.
        let run = |seed| format!("{:?}", measure(&truth, &rig, &[0.0; 6], &balls, &[], seed).unwrap().0);
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }
}

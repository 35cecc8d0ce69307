//! A realistic twin of a real laser-tracker calibration run (issue 24): what a customer brings,
//! rather than the thesis's lab.
//!
//! - A tracker follows several SMRs fixed on a plate on the flange (three, ≈150 mm apart by
//!   default), all opening along the flange axis; every pose reads every SMR.
//! - Poses are random over the workspace (joint values uniform within the limits), kept where
//!   the plate faces the tracker, in measuring order: the robot moves from one to the next, so
//!   each joint's direction of motion is the sign of q(k) − q(k−1).
//! - The positions are in the tracker's own frame: nothing gives the base, and the SMRs' places
//!   on the plate are not declared (the three-reflector format).
//! - The true robot carries a payload (the plate) that the files do not declare, hysteresis
//!   (backlash by the direction of motion) and any other effect of [`Effects`], and errors that
//!   change from pose to pose and that no term explains (settling, repeatability, the tracker's
//!   angular error at range): a fresh random turn of every joint at every stop, common to the
//!   SMRs read there.
//! - Afterwards a few rows are removed (the outlier rows a metrologist deletes), so that the
//!   direction derived from consecutive kept rows is wrong where a removed stop reversed it.
//!
//! The output is the three-reflector text format (the service's `import::three_reflector`): a joints
//! file in degrees and one positions file per SMR in mm. Deterministic for a seed.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

use super::effects::Effects;
use super::truth::Truth;
use crate::kinematics::thesis::irb120_table_5_1;
use crate::kinematics::{MAX_JOINTS, Param, Tool};
use crate::units::{DEG, MM};

/// What the run is.
#[derive(Clone, Debug)]
pub struct TrackerRunOptions {
    /// Seeds every random draw of the run (ChaCha8): poses, jitter, tracker noise, removed rows.
    pub seed: u64,
    /// Stops measured (before rows are removed).
    pub poses: usize,
    /// Rows removed afterwards, at random.
    pub removed: usize,
    /// The SMR centres in the flange frame, m.
    pub smrs: Vec<Vector3<f64>>,
    /// The true payload (the plate and its SMRs), kg, at `payload_com`. The files do not
    /// declare it.
    pub payload_kg: f64,
    /// The payload's centre of mass in the flange frame, m; `None`: the SMRs' centroid.
    pub payload_com: Option<Vector3<f64>>,
    /// The true robot's unmodelled effects (backlash is the hysteresis by direction of motion).
    /// A thermal effect acts through the robot's temperature at each stop
    /// ([`Effects::temperature_at`] of the stop's time, `stop_s` apart): the warm-up over a run
    /// drifts along the measuring order, and the files log neither time nor temperature.
    pub effects: Effects,
    /// Seconds from one stop to the next (0: every stop at the run's start and its temperature).
    pub stop_s: f64,
    /// σ of the random turn of each joint at each stop, rad: the pose-to-pose error no term
    /// explains (0.012° at the IRB 120's ~0.5 m lever is ≈0.1 mm per joint).
    pub jitter: f64,
    /// Tracker noise per axis, 1σ: `tracker_sigma + tracker_sigma_per_m · range`, the range being
    /// the SMR's distance from the tracker; this is the constant part, m.
    pub tracker_sigma: f64,
    /// The tracker σ's growth with range, m per m.
    pub tracker_sigma_per_m: f64,
    /// T_0^T: the robot's base in the tracker frame (χ, m and rad).
    pub base_in_tracker: [f64; 6],
    /// Largest angle between the plate's normal (the flange's z axis) and the line of sight to the
    /// tracker, rad.
    pub acceptance: f64,
}

impl Default for TrackerRunOptions {
    /// 982 stops over the IRB 120's workspace, 10 rows removed, three SMRs on a 150 mm triangle
    /// 40 mm above the flange and 20 mm off its axis, a 1 kg plate, backlash of 0.006° on joints
    /// 1–3, a jitter of 0.012° per joint (≈0.2 mm at the SMRs), a tracker of 20 µm + 5 µm/m about
    /// 2.3 m from the base, poses kept within 55° of facing it.
    fn default() -> Self {
        let centre = Vector3::new(0.020, 0.0, 0.040);
        let r = 0.150 / 3f64.sqrt();
        let smrs = [90.0f64, 210.0, 330.0]
            .iter()
            .map(|a| centre + Vector3::new(r * (a * DEG).cos(), r * (a * DEG).sin(), 0.0))
            .collect();
        Self {
            seed: 1,
            poses: 982,
            removed: 10,
            smrs,
            payload_kg: 1.0,
            payload_com: None,
            effects: Effects::parse("backlash:j=1:deg=0.006,backlash:j=2:deg=0.006,backlash:j=3:deg=0.006", 6)
                .expect("a valid specification"),
            jitter: 0.012 * DEG,
            tracker_sigma: 20e-6,
            tracker_sigma_per_m: 5e-6,
            base_in_tracker: [1.90, -1.25, -0.55, 2.4, 0.002, -0.003],
            acceptance: 55.0 * DEG,
            stop_s: 0.0,
        }
    }
}

/// A simulated run and its truth.
#[derive(Clone, Debug)]
pub struct TrackerRun {
    /// Joint readings of the kept rows, rad, in measuring order.
    pub joints: Vec<[f64; MAX_JOINTS]>,
    /// Per SMR, per kept row: the tracker's reading, m.
    pub positions: Vec<Vec<Vector3<f64>>>,
    /// Per SMR, per kept row: where the SMR was, without the jitter and the tracker's noise (what
    /// a perfect model of the robot predicts from the readings), m.
    pub true_positions: Vec<Vec<Vector3<f64>>>,
    /// The true robot (base in the tracker frame) and its effects.
    pub truth: Truth,
    /// The true payload (mass, CoM in the flange frame).
    pub payload: Tool,
    /// Index in the measured sequence of each kept row.
    pub kept: Vec<usize>,
    /// Per kept row: the true direction of each joint's last move, +1 or −1 (a joint that did not
    /// move counts as −1; the first stop's move starts from (0, 0, 0, 0, 30°, 0)); 0 beyond the
    /// robot's joints.
    pub approach: Vec<[i8; MAX_JOINTS]>,
}

/// Why a run could not be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackerRunError {
    /// An option is unusable (the message says which): no SMR, `removed` ≥ `poses`, or a
    /// payload, jitter or tracker σ that is negative or not finite.
    #[error("{0}")]
    Option(String),
    /// Fewer random poses than `poses` passed the filters within 400 draws per pose.
    #[error("only {found} of {wanted} random poses face the tracker after {tries} tries")]
    TooFewPoses {
        /// Poses kept.
        found: usize,
        /// Poses asked for.
        wanted: usize,
        /// Draws made.
        tries: usize,
    },
}

/// Simulate a run of the thesis's identified IRB 120 (Table 5.1) with `opts`, its base moved to
/// `base_in_tracker` (true and nominal), carrying the undeclared payload.
///
/// Poses: joint values uniform within the limits, kept when |q5| ≥ 10°, the flange is at least
/// 50 mm above the base's XY plane and 150 mm from its z axis, and the plate's normal is within
/// `acceptance` of the line of sight to the tracker (at the frame's origin). Then, in order, each
/// stop's directions of motion, one jitter turn per joint (common to the SMRs) and each SMR's
/// tracker noise; last, `removed` distinct rows drawn at random are dropped. Every draw comes
/// from one ChaCha8 generator seeded with `opts.seed`.
pub fn tracker_run(opts: &TrackerRunOptions) -> Result<TrackerRun, TrackerRunError> {
    if opts.smrs.is_empty() {
        return Err(TrackerRunError::Option("at least one SMR".into()));
    }
    if opts.removed >= opts.poses {
        return Err(TrackerRunError::Option(format!("{} rows removed of {} measured", opts.removed, opts.poses)));
    }
    for (name, v) in [
        ("payload_kg", opts.payload_kg),
        ("jitter", opts.jitter),
        ("tracker_sigma", opts.tracker_sigma),
        ("tracker_sigma_per_m", opts.tracker_sigma_per_m),
        ("stop_s", opts.stop_s),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(TrackerRunError::Option(format!("{name} must be a non-negative number")));
        }
    }
    let centroid = opts.smrs.iter().sum::<Vector3<f64>>() / opts.smrs.len() as f64;
    let payload = Tool { tcp: [0.0; 6], mass: opts.payload_kg, com: opts.payload_com.unwrap_or(centroid) };
    let mut set = irb120_table_5_1(payload.clone());
    for k in 0..6 {
        let i = set.layout.index_of(Param::Base(k)).expect("a base");
        set.values[i] = opts.base_in_tracker[k];
        set.nominal[i] = opts.base_in_tracker[k];
    }
    let truth = Truth::new(set, opts.effects.clone());
    let dof = truth.set.dof();
    let robots: Vec<_> = opts
        .smrs
        .iter()
        .map(|s| truth.robot(&Tool { tcp: [s.x, s.y, s.z, 0.0, 0.0, 0.0], ..payload.clone() }))
        .collect();
    let flange = truth.robot(&payload);
    let limits: Vec<[f64; 2]> = truth.set.model.links.iter().map(|l| l.limits).collect();

    let mut rng = ChaCha8Rng::seed_from_u64(opts.seed);
    // Poses: uniform within the limits, kept where the flange is above the base's plane, the
    // wrist is not stretched out at a singularity, and the plate faces the tracker.
    let mut poses: Vec<[f64; MAX_JOINTS]> = Vec::with_capacity(opts.poses);
    let base = *truth.set.chain().base();
    let tries = opts.poses * 400;
    for _ in 0..tries {
        if poses.len() == opts.poses {
            break;
        }
        let mut q = [0.0; MAX_JOINTS];
        for j in 0..dof {
            q[j] = rng.random_range(limits[j][0]..=limits[j][1]);
        }
        if q[4].abs() < 10.0 * DEG {
            continue;
        }
        let s = flange.state(&q[..dof], &[0.0; MAX_JOINTS][..dof], 20.0);
        let f = flange.tcp(&s);
        let up = base.r.transpose() * (f.t - base.t);
        if up.z < 0.05 || up.xy().norm() < 0.15 {
            continue;
        }
        let normal = f.r * Vector3::z();
        let sight = -f.t.normalize();
        if normal.dot(&sight).acos() > opts.acceptance {
            continue;
        }
        poses.push(q);
    }
    if poses.len() < opts.poses {
        return Err(TrackerRunError::TooFewPoses { found: poses.len(), wanted: opts.poses, tries });
    }

    // Measure in order: the direction of each joint's move into the stop, a fresh jitter, the
    // tracker's noise.
    let jitter = Normal::new(0.0, opts.jitter.max(f64::MIN_POSITIVE)).expect("σ > 0");
    let unit = Normal::new(0.0, 1.0).expect("σ = 1");
    let mut previous = [0.0; MAX_JOINTS];
    previous[4] = 30.0 * DEG;
    let n_smr = opts.smrs.len();
    let mut readings = vec![Vec::with_capacity(opts.poses); n_smr];
    let mut exact = vec![Vec::with_capacity(opts.poses); n_smr];
    let mut approaches = Vec::with_capacity(opts.poses);
    for (stop, q) in poses.iter().enumerate() {
        let temperature_c = opts.effects.temperature_at(stop as f64 * opts.stop_s);
        let mut approach = [0i8; MAX_JOINTS];
        let mut app = [0.0; MAX_JOINTS];
        for j in 0..dof {
            approach[j] = if q[j] > previous[j] { 1 } else { -1 };
            app[j] = approach[j] as f64;
        }
        previous = *q;
        approaches.push(approach);
        let mut moved = *q;
        if opts.jitter > 0.0 {
            for v in moved.iter_mut().take(dof) {
                *v += jitter.sample(&mut rng);
            }
        }
        for (k, robot) in robots.iter().enumerate() {
            let p_true = robot.tcp(&robot.state(&moved[..dof], &app[..dof], temperature_c)).t;
            let p_model = robot.tcp(&robot.state(&q[..dof], &app[..dof], temperature_c)).t;
            let sigma = opts.tracker_sigma + opts.tracker_sigma_per_m * p_true.norm();
            let noise = Vector3::from_fn(|_, _| unit.sample(&mut rng) * sigma);
            readings[k].push(p_true + noise);
            exact[k].push(p_model);
        }
    }

    // Rows removed afterwards.
    let mut removed = std::collections::BTreeSet::new();
    while removed.len() < opts.removed {
        removed.insert(rng.random_range(0..opts.poses));
    }
    let kept: Vec<usize> = (0..opts.poses).filter(|i| !removed.contains(i)).collect();
    let pick = |v: &Vec<Vector3<f64>>| kept.iter().map(|&i| v[i]).collect::<Vec<_>>();
    Ok(TrackerRun {
        joints: kept.iter().map(|&i| poses[i]).collect(),
        positions: readings.iter().map(pick).collect(),
        true_positions: exact.iter().map(pick).collect(),
        approach: kept.iter().map(|&i| approaches[i]).collect(),
        truth,
        payload,
        kept,
    })
}

impl TrackerRun {
    /// Write the run in the three-reflector format: `{tag}-joints.txt` (the first `dof` joints of
    /// each kept row, degrees, 6 decimals) and `{tag}-smr{k}.txt` (k from 1; x y z in the tracker
    /// frame, mm, 4 decimals) in `dir`, each file opening with a `#` comment line and overwritten
    /// if present. Returns the joints file and the positions files; I/O errors are passed on.
    pub fn write(&self, dir: &Path, tag: &str, dof: usize) -> std::io::Result<(PathBuf, Vec<PathBuf>)> {
        let joints = dir.join(format!("{tag}-joints.txt"));
        let mut text = String::from("# joint readings, degrees, in measuring order\n");
        for q in &self.joints {
            let line: Vec<String> = q[..dof].iter().map(|v| format!("{:.6}", v / DEG)).collect();
            text.push_str(&line.join(" "));
            text.push('\n');
        }
        std::fs::write(&joints, text)?;
        let mut files = Vec::new();
        for (k, rows) in self.positions.iter().enumerate() {
            let path = dir.join(format!("{tag}-smr{}.txt", k + 1));
            let mut text = String::from("# x y z, mm, tracker frame\n");
            for p in rows {
                text.push_str(&format!("{:.4} {:.4} {:.4}\n", p.x / MM, p.y / MM, p.z / MM));
            }
            std::fs::write(&path, text)?;
            files.push(path);
        }
        Ok((joints, files))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The run is what it says: every kept row's reading is within a few tracker σ plus the jitter
    /// of the true SMR position, the directions are the signs of the moves between consecutive
    /// measured stops, the removed rows are gone, and the same seed gives the same run.
    #[test]
    fn a_run_is_deterministic_and_consistent() {
        let o = TrackerRunOptions { poses: 120, removed: 5, ..Default::default() };
        let a = tracker_run(&o).unwrap();
        let b = tracker_run(&o).unwrap();
        assert_eq!(a.joints, b.joints);
        assert_eq!(a.positions, b.positions);
        assert_eq!(a.joints.len(), 115);
        assert_eq!(a.kept.len(), 115);
        assert_eq!(a.positions.len(), 3);
        // Jitter of 0.012° per joint: the readings stay within ~1.5 mm of the model position.
        for k in 0..3 {
            let worst =
                a.positions[k].iter().zip(&a.true_positions[k]).map(|(p, t)| (p - t).norm()).fold(0.0, f64::max);
            let mean = a.positions[k].iter().zip(&a.true_positions[k]).map(|(p, t)| (p - t).norm()).sum::<f64>()
                / a.joints.len() as f64;
            assert!(worst < 1.5e-3 && mean > 0.05e-3 && mean < 0.4e-3, "SMR {k}: mean {mean}, worst {worst}");
        }
        // Consecutive kept rows that were consecutive stops carry the sign of the move.
        for w in 1..a.kept.len() {
            if a.kept[w] == a.kept[w - 1] + 1 {
                for j in 0..6 {
                    let d = a.joints[w][j] - a.joints[w - 1][j];
                    assert_eq!(a.approach[w][j], d.signum() as i8);
                }
            }
        }
        // The SMRs are 150 mm apart.
        let s = &o.smrs;
        assert!(((s[0] - s[1]).norm() - 0.150).abs() < 1e-12 && ((s[1] - s[2]).norm() - 0.150).abs() < 1e-12);
    }

    /// A warm-up drifts along the measuring order: with `stop_s` the thermal effect's expansion
    /// grows from nothing at the first stop to α·ΔT of the reflector's distance from the base at
    /// the last (23 ppm × 8 °C·(1 − e^(−119·10/3600)) ≈ 52 ppm of ≈0.6 m here); without it every
    /// stop is at the start's 20 °C and the thermal effect changes nothing.
    #[test]
    fn a_warm_up_drifts_along_the_measuring_order() {
        let none = Effects::parse("", 6).unwrap();
        let plain = TrackerRunOptions { poses: 120, removed: 0, jitter: 0.0, effects: none, ..Default::default() };
        let thermal = Effects::parse("thermal", 6).unwrap();
        let warm = |stop_s: f64| TrackerRunOptions { effects: thermal.clone(), stop_s, ..plain.clone() };
        let (a, b, c) =
            (tracker_run(&plain).unwrap(), tracker_run(&warm(0.0)).unwrap(), tracker_run(&warm(10.0)).unwrap());
        assert_eq!(a.joints, c.joints);
        let base = a.truth.set.chain().base().t;
        let ratio = |k: usize, i: usize| {
            let (p, q) = (a.true_positions[k][i], c.true_positions[k][i]);
            (q - p).norm() / (p - base).norm()
        };
        for k in 0..3 {
            let same =
                a.true_positions[k].iter().zip(&b.true_positions[k]).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
            assert!(same < 1e-12, "stop_s 0 is the start's temperature: {same} m apart");
            let rise = 1.0 - (-119.0 * 10.0 / 3600.0f64).exp();
            let want = 23e-6 * 8.0 * rise;
            assert!(ratio(k, 0) < 2e-7, "first stop: {}", ratio(k, 0));
            let last = ratio(k, 119);
            assert!(last > 0.5 * want && last < 1.5 * want, "last stop: {last} of the range, about {want}");
        }
    }
}

//! A drift along the measuring order: whether the starting model's held-out errors change with
//! the stop's place in the run, beyond what the configuration explains.
//!
//! A real run of a thousand stops lasts hours. The robot warms up, the tracker or the base settles,
//! and the files log neither time nor temperature: the error then depends on *when* a pose was
//! measured, which no model term of a robot takes (the thermal term needs logged temperatures).
//! It is said here, as where the model misses, not named as an effect of the robot.
//!
//! The test, per stop (the readings of several reflectors at one stop averaged into one error
//! vector e_s in {W}): the regression e_s = Z_s·γ + X_s·b + ε, with Z the configuration (1,
//! sin q_j, cos q_j, and the measured position's x, y, z with their squares and products) and X the Legendre polynomials P1…P3 of the stop's place in the run scaled to
//! [−1, 1]. The statistic is the squared norm of the errors' projection on X beyond Z
//! (Frisch–Waugh), summed over x, y, z; its null distribution comes from permuting the residuals
//! of the reduced model e ~ Z over the stops (Freedman–Lane), so neither normality nor equal
//! variances are assumed, and the reflectors of one stop, which share its error, move together.
//! Written here rather than taken from a crate: no maintained Rust crate does a Freedman–Lane
//! permutation test; the linear algebra is nalgebra's and, for the bases, faer's.
//!
//! Where the measuring order follows the configuration (a planner's sweep over the joints, a grid
//! in Cartesian space), an error of the pose the configuration basis does not span would look like
//! a drift: the adjusted R² of the run position on Z is reported, and above [`CONFOUNDED_R2`] no
//! drift is claimed. Where consecutive stops are neighbours (a sweep, a grid, an order planned for
//! short moves) the errors of neighbouring poses are alike, the residuals are correlated along the
//! order and the permutation's null too narrow: the mean joint distance between consecutive stops
//! against that between any two is reported, and below [`LOCALITY_LIMIT`] no drift is claimed
//! either. (A UR5's public tracker run on a Cartesian grid, 1,000 stops in planes of 100 measured
//! in no monotone order: R² 0.16 on the configuration, consecutive stops 0.1 as far apart as any
//! two, p = 0.001 — an error of the pose, not a drift, as far as these data can tell.)

use nalgebra::{DMatrix, Vector3};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// Permutations of the test (its smallest p is 1/(N + 1) = 0.001).
pub const PERMUTATIONS: usize = 999;
/// Fewest stops tested.
pub const MIN_STOPS: usize = 60;
/// Above this adjusted R² of the run position on the configuration basis, a trend along the order
/// cannot be told from an error of the pose, and no drift is claimed.
pub const CONFOUNDED_R2: f64 = 0.2;
/// Below this ratio of the mean joint distance between consecutive stops to that between any two,
/// the order moves between neighbouring poses and no drift is claimed.
pub const LOCALITY_LIMIT: f64 = 0.8;
/// Significance level at which a drift is said.
pub const LEVEL: f64 = 0.01;
const DEGREE: usize = 3;

/// Where each stop's place in the run came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunPosition {
    /// The measurements' logged times (`time_s`).
    Time,
    /// Their sequence numbers (`sequence`).
    Sequence,
    /// Their order in the session's list (one session, listed as measured).
    FileOrder,
}

impl RunPosition {
    /// The name reports use: `time_s`, `sequence` or `file_order`.
    pub fn as_str(self) -> &'static str {
        match self {
            RunPosition::Time => "time_s",
            RunPosition::Sequence => "sequence",
            RunPosition::FileOrder => "file_order",
        }
    }
}

/// The outcome of the test.
#[derive(Clone, Debug, PartialEq)]
pub struct OrderDrift {
    /// Where the run positions came from.
    pub source: RunPosition,
    /// Stops tested (readings at one stop count once).
    pub stops: usize,
    /// Permutation p-value of H0 "the errors do not depend on the place in the run beyond the
    /// configuration".
    pub p: f64,
    /// Permutations drawn.
    pub permutations: usize,
    /// The fitted trend's mean over the last tenth of the stops minus its mean over the first
    /// tenth, {W}, m (a polynomial's value at the very ends is its least certain).
    pub first_to_last: Vector3<f64>,
    /// Its standard deviation per axis, m: the regression's, σ̂²·cᵀ(X̃ᵀX̃)⁻¹c with σ̂² each axis's
    /// residual variance after the full regression (stops independent; their reflectors averaged).
    pub first_to_last_std: Vector3<f64>,
    /// Adjusted R² of the run position on the configuration basis: how much the measuring order
    /// follows the pose.
    pub order_on_configuration_r2: f64,
    /// Mean joint distance (RMS over the joints) between consecutive stops over that between any
    /// two: about 1 for poses measured in random order, small for a sweep or a grid.
    pub order_locality: f64,
}

impl OrderDrift {
    /// Whether a drift is said: significant at [`LEVEL`] and the order not confounded with the
    /// configuration.
    pub fn found(&self) -> bool {
        self.p < LEVEL && !self.confounded()
    }

    /// Whether the order carries the configuration: it follows it (R²) or moves between
    /// neighbouring poses (locality), so that the test cannot tell a drift from an error of the pose.
    pub fn confounded(&self) -> bool {
        self.order_on_configuration_r2 > CONFOUNDED_R2 || self.order_locality < LOCALITY_LIMIT
    }

    /// What the test says, in a sentence (millimetres).
    pub fn statement(&self) -> String {
        let mm = |v: f64| v / crate::units::MM;
        let d = self.first_to_last;
        let source = match self.source {
            RunPosition::Time => "their logged times",
            RunPosition::Sequence => "their sequence numbers",
            RunPosition::FileOrder => "the session's list order",
        };
        let figures = format!(
            "{:.3} mm from the first tenth of the run to the last (x {:+.3} ± {:.3}, y {:+.3} ± {:.3}, z {:+.3} ± {:.3} mm), p = {:.3} ({} permutations over {} stops, beyond what the configuration explains; the order from {source})",
            mm(d.norm()),
            mm(d.x),
            mm(self.first_to_last_std.x),
            mm(d.y),
            mm(self.first_to_last_std.y),
            mm(d.z),
            mm(self.first_to_last_std.z),
            self.p,
            self.permutations,
            self.stops,
        );
        if self.found() {
            format!(
                "the starting model's held-out errors drift along the measuring order: {figures}. No term of a robot's model takes a drift in time that no logged temperature follows (a warm-up, a tracker or a base that settled): log time_s and temperature_c with each measurement, or measure after warming up; the figures above include it"
            )
        } else if self.confounded() {
            format!(
                "a drift cannot be told from an error of the pose: the measuring order carries the configuration here (the place in the run on the joint readings and positions: adjusted R² {:.2}; consecutive stops {:.2} as far apart in the joints as any two), so alike errors of neighbouring poses can make a trend along the order (p = {:.3} over {} stops, a level that holds only for an order at random)",
                self.order_on_configuration_r2, self.order_locality, self.p, self.stops
            )
        } else {
            format!("no drift along the measuring order: {figures}")
        }
    }
}

/// One stop: its place in the run, its joint readings and its error (mean over its readings), m.
#[derive(Clone, Debug)]
pub struct Stop {
    /// Place in the run (seconds, sequence number or list index).
    pub at: f64,
    /// Joint readings, rad.
    pub q: Vec<f64>,
    /// Measured position, {W}, m (the mean over its readings).
    pub position: Vector3<f64>,
    /// The held-out error, {W}, m.
    pub error: Vector3<f64>,
}

/// One reading: its place in the run, joint readings (rad), measured position and held-out error
/// ({W}, m).
pub type Reading = (f64, Vec<f64>, Vector3<f64>, Vector3<f64>);

/// Group readings into stops: sorted by place, consecutive readings at the same joint readings are
/// one stop (the reflectors of a plate), their positions and errors averaged.
pub fn stops(mut readings: Vec<Reading>) -> Vec<Stop> {
    readings.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<(Stop, usize)> = Vec::new();
    for (at, q, position, e) in readings {
        match out.last_mut() {
            Some((s, n)) if s.q.iter().zip(&q).all(|(a, b)| (a - b).abs() < 1e-12) => {
                s.error += e;
                s.position += position;
                *n += 1;
            }
            _ => out.push((Stop { at, q, position, error: e }, 1)),
        }
    }
    out.into_iter()
        .map(|(mut s, n)| {
            s.error /= n as f64;
            s.position /= n as f64;
            s
        })
        .collect()
}

/// The configuration basis of one stop: 1, sin and cos of every joint, and the position's x, y, z,
/// squares and products (centred and scaled by `centre`, `scale` so the columns are of order 1).
fn configuration(s: &Stop, centre: &Vector3<f64>, scale: f64) -> Vec<f64> {
    let mut z = vec![1.0];
    z.extend(s.q.iter().map(|q| q.sin()));
    z.extend(s.q.iter().map(|q| q.cos()));
    let p = (s.position - centre) / scale;
    z.extend([p.x, p.y, p.z, p.x * p.x, p.y * p.y, p.z * p.z, p.x * p.y, p.x * p.z, p.y * p.z]);
    z
}

/// Orthonormal basis of the column space of `a` (the diagnosis's thin-SVD kernel on faer,
/// `linalg::orthonormal_basis`; directions below 1e-10 of the largest dropped).
fn orthonormal(a: &DMatrix<f64>) -> DMatrix<f64> {
    let m = faer::Mat::<f64>::from_fn(a.nrows(), a.ncols(), |i, j| a[(i, j)]);
    let q = super::linalg::orthonormal_basis(m.as_ref(), 1e-10);
    DMatrix::from_fn(q.nrows(), q.ncols(), |i, j| q[(i, j)])
}

/// `a` minus its projection on the orthonormal columns of `q`.
fn remove(q: &DMatrix<f64>, a: &DMatrix<f64>) -> DMatrix<f64> {
    a - q * (q.transpose() * a)
}

/// The map of places in the run onto [−1, 1] (first to last); `None` when they are all the same or
/// not finite.
pub(crate) fn unit_scale(at: impl Iterator<Item = f64>) -> Option<impl Fn(f64) -> f64> {
    let (lo, hi) = at.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), t| (l.min(t), h.max(t)));
    let span = hi - lo;
    (span > 0.0 && span.is_finite()).then_some(move |t: f64| 2.0 * (t - lo) / span - 1.0)
}

/// Legendre polynomials P1…P3 at u ∈ [−1, 1].
pub(crate) fn legendre(u: f64) -> [f64; DEGREE] {
    [u, 0.5 * (3.0 * u * u - 1.0), 0.5 * (5.0 * u * u * u - 3.0 * u)]
}

/// The test on `stops` (see the module). `None` with fewer than [`MIN_STOPS`] stops, or when every
/// stop has the same place in the run.
pub fn order_drift(stops: &[Stop], source: RunPosition, seed: u64) -> Option<OrderDrift> {
    let m = stops.len();
    if m < MIN_STOPS {
        return None;
    }
    let u = unit_scale(stops.iter().map(|s| s.at))?;
    let centre = stops.iter().map(|s| s.position).sum::<Vector3<f64>>() / m as f64;
    let scale = (stops.iter().map(|s| (s.position - centre).norm_squared()).sum::<f64>() / m as f64).sqrt().max(1e-9);
    let rows: Vec<Vec<f64>> = stops.iter().map(|s| configuration(s, &centre, scale)).collect();
    let z = DMatrix::from_fn(m, rows[0].len(), |i, k| rows[i][k]);
    let x = DMatrix::from_fn(m, DEGREE, |i, k| legendre(u(stops[i].at))[k]);
    let y = DMatrix::from_fn(m, 3, |i, c| stops[i].error[c]);
    let qz = orthonormal(&z);
    let xr = remove(&qz, &x);
    let r = remove(&qz, &y);
    let w = orthonormal(&xr);
    if w.ncols() == 0 {
        return None;
    }
    let stat = |rows: &[usize]| -> f64 {
        // ‖Wᵀ·R_π‖²: R's rows taken in the order `rows`.
        let mut acc = DMatrix::<f64>::zeros(w.ncols(), 3);
        for (i, &pi) in rows.iter().enumerate() {
            for k in 0..w.ncols() {
                let wk = w[(i, k)];
                for c in 0..3 {
                    acc[(k, c)] += wk * r[(pi, c)];
                }
            }
        }
        acc.norm_squared()
    };
    let identity: Vec<usize> = (0..m).collect();
    let observed = stat(&identity);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6f72_6465_7264_7266);
    let mut perm = identity.clone();
    let mut above = 0usize;
    for _ in 0..PERMUTATIONS {
        perm.shuffle(&mut rng);
        if stat(&perm) >= observed * (1.0 - 1e-12) {
            above += 1;
        }
    }
    let p = (1 + above) as f64 / (1 + PERMUTATIONS) as f64;
    // The trend: the coefficients of X in the full regression (Frisch–Waugh: R on X beyond Z).
    let xtx = xr.transpose() * &xr;
    let b = xtx.clone().cholesky().map(|c| c.solve(&(xr.transpose() * &r)))?;
    // c: the basis averaged over the last tenth of the stops minus over the first tenth, so that
    // the change is cᵀb.
    let mut ats: Vec<f64> = stops.iter().map(|s| s.at).collect();
    ats.sort_by(f64::total_cmp);
    let tenth = (m / 10).max(1);
    let basis_mean = |part: &[f64]| {
        let mut c = [0.0; DEGREE];
        for &a in part {
            for (ck, pk) in c.iter_mut().zip(legendre(u(a))) {
                *ck += pk / part.len() as f64;
            }
        }
        c
    };
    let (last, first) = (basis_mean(&ats[m - tenth..]), basis_mean(&ats[..tenth]));
    let c = nalgebra::DVector::from_fn(DEGREE, |k, _| last[k] - first[k]);
    let first_to_last = Vector3::from_fn(|axis, _| (0..DEGREE).map(|k| c[k] * b[(k, axis)]).sum());
    // Residual variance per axis after the full regression (Z and X), and cᵀ(X̃ᵀX̃)⁻¹c.
    let full = &r - &xr * &b;
    let rest = (m - qz.ncols() - DEGREE).max(1) as f64;
    let ctc = xtx.cholesky().map_or(f64::NAN, |ch| c.dot(&ch.solve(&c)));
    let first_to_last_std = Vector3::from_fn(|axis, _| (full.column(axis).norm_squared() / rest * ctc).sqrt());
    // How much the order follows the pose: adjusted R² of u on Z.
    let uu = DMatrix::from_fn(m, 1, |i, _| u(stops[i].at));
    let ur = remove(&qz, &uu);
    let centred = uu.add_scalar(-uu.mean());
    let (sse, sst) = (ur.norm_squared(), centred.norm_squared());
    let k = (qz.ncols() - 1) as f64;
    let r2 = 1.0 - (sse / (m as f64 - k - 1.0)) / (sst / (m as f64 - 1.0));
    Some(OrderDrift {
        source,
        stops: m,
        p,
        permutations: PERMUTATIONS,
        first_to_last,
        first_to_last_std,
        order_on_configuration_r2: r2.max(0.0),
        order_locality: locality(stops),
    })
}

/// Mean joint distance between consecutive stops (in run order) over the mean between any two.
pub(crate) fn locality(stops: &[Stop]) -> f64 {
    let mut order: Vec<&Stop> = stops.iter().collect();
    order.sort_by(|a, b| a.at.total_cmp(&b.at));
    let dist = |a: &Stop, b: &Stop| {
        (a.q.iter().zip(&b.q).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.q.len().max(1) as f64).sqrt()
    };
    let m = order.len();
    let consecutive = order.windows(2).map(|w| dist(w[0], w[1])).sum::<f64>() / (m - 1) as f64;
    let mut all = 0.0;
    for i in 0..m {
        for j in i + 1..m {
            all += dist(order[i], order[j]);
        }
    }
    let all = all / (m * (m - 1) / 2) as f64;
    if all > 0.0 { consecutive / all } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;
    use rand_distr::{Distribution, Normal};

    /// Stops at random configurations in random order, each with an error of noise plus an error
    /// of the pose, and `drift(k)` at the k-th stop.
    fn run(m: usize, seed: u64, drift: impl Fn(f64) -> Vector3<f64>) -> Vec<Stop> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let noise = Normal::new(0.0, 50e-6).unwrap();
        (0..m)
            .map(|k| {
                let q: Vec<f64> = (0..6).map(|_| rng.random_range(-2.5..2.5)).collect();
                let pose = Vector3::new(40e-6 * q[1].sin(), -30e-6 * q[2].cos(), 20e-6 * (q[1] + q[2]).sin());
                let e = Vector3::from_fn(|_, _| noise.sample(&mut rng)) + pose + drift(k as f64 / m as f64);
                let reach = 0.5 + 0.4 * q[1].cos();
                let position = Vector3::new(q[0].cos() * reach, q[0].sin() * reach, 0.4 * q[1].sin());
                Stop { at: k as f64, q, position, error: e }
            })
            .collect()
    }

    #[test]
    fn a_warm_up_is_found_and_measured() {
        // 60 µm along x over the run, as an exponential warm-up: 1 − e^(−3t).
        let warm = |t: f64| 60e-6 * (1.0 - (-3.0 * t).exp());
        let m = 500;
        let d = run(m, 3, |t| Vector3::new(warm(t), 0.0, 0.0));
        let r = order_drift(&d, RunPosition::Sequence, 1).expect("tested");
        assert!(r.found() && r.p <= 0.002, "{r:?}");
        // The truth: the drift's mean over the last 50 stops minus over the first 50 (48.4 µm).
        let truth = truth_first_to_last(m, warm);
        let z = (r.first_to_last - Vector3::new(truth, 0.0, 0.0)).component_div(&r.first_to_last_std);
        assert!(z.amax() < 3.0, "{truth:e} {z} {r:?}");
        assert!(r.order_on_configuration_r2 < 0.05 && r.order_locality > 0.9, "{r:?}");
        assert!(r.statement().starts_with("the starting model's held-out errors drift"), "{}", r.statement());
    }

    fn truth_first_to_last(m: usize, drift: impl Fn(f64) -> f64) -> f64 {
        let at: Vec<f64> = (0..m).map(|k| drift(k as f64 / m as f64)).collect();
        let tenth = |part: &[f64]| part.iter().sum::<f64>() / part.len() as f64;
        tenth(&at[m - m / 10..]) - tenth(&at[..m / 10])
    }

    #[test]
    fn the_change_along_the_run_has_an_honest_standard_deviation() {
        // Over 40 runs the z-scores of the change against the truth have an RMS near 1 and a mean
        // near 0: the σ stated is the spread found (the cubic fits this warm-up to 0.1 µm).
        let warm = |t: f64| 50e-6 * (1.0 - (-2.0 * t).exp());
        let truth = truth_first_to_last(300, warm);
        let z: Vec<f64> = (0..40)
            .flat_map(|s| {
                let r = order_drift(&run(300, 500 + s, |t| Vector3::new(warm(t), 0.0, -warm(t))), RunPosition::Time, s)
                    .unwrap();
                let d = r.first_to_last - Vector3::new(truth, 0.0, -truth);
                [d.x / r.first_to_last_std.x, d.y / r.first_to_last_std.y, d.z / r.first_to_last_std.z]
            })
            .collect();
        let rms = (z.iter().map(|v| v * v).sum::<f64>() / z.len() as f64).sqrt();
        let mean = z.iter().sum::<f64>() / z.len() as f64;
        assert!((0.8..1.25).contains(&rms) && mean.abs() < 0.3, "rms {rms}, mean {mean}: {z:?}");
    }

    #[test]
    fn without_a_drift_the_test_holds_its_level() {
        // 100 runs without drift: p below 0.05 in about 5 of them (binomial: at most 12 with
        // probability 0.999), and the p-values spread over (0, 1].
        let ps: Vec<f64> = (0..100)
            .map(|s| order_drift(&run(200, 100 + s, |_| Vector3::zeros()), RunPosition::Sequence, s).unwrap().p)
            .collect();
        let low = ps.iter().filter(|&&p| p < 0.05).count();
        assert!(low <= 12, "{low} of 100 below 0.05: {ps:?}");
        let high = ps.iter().filter(|&&p| p > 0.5).count();
        assert!((35..=65).contains(&high), "{high} of 100 above 0.5");
    }

    #[test]
    fn an_order_that_follows_the_pose_claims_no_drift() {
        // A planner's sweep: q1 rises with the order; the error depends on q1 in a way the
        // configuration basis does not span (q1³), so the order carries it.
        let mut d = run(400, 5, |_| Vector3::zeros());
        let n = d.len() as f64;
        for (k, s) in d.iter_mut().enumerate() {
            s.q[0] = -2.5 + 5.0 * k as f64 / n;
            s.error.x += 80e-6 * s.q[0].powi(3) / 15.6;
        }
        let r = order_drift(&d, RunPosition::Sequence, 1).expect("tested");
        // The order carries the pose's error (significant), and the guard keeps it unnamed.
        assert!(r.p < LEVEL && r.order_on_configuration_r2 > CONFOUNDED_R2, "{r:?}");
        assert!(!r.found(), "{r:?}");
        assert!(r.statement().starts_with("a drift cannot be told from an error of the pose"), "{}", r.statement());
    }

    #[test]
    fn a_cartesian_grid_measured_in_order_claims_no_drift() {
        // A 10 × 10 × 10 grid of positions, x the outer loop: an error cubic in x, which the
        // quadratic position basis does not span, rises with the order.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let noise = Normal::new(0.0, 20e-6).unwrap();
        let d: Vec<Stop> = (0..1000)
            .map(|k| {
                let g = |i: usize| -0.3 + 0.6 * i as f64 / 9.0;
                let position = Vector3::new(g(k / 100), g(k / 10 % 10), 0.5 + g(k % 10));
                let q: Vec<f64> = (0..6).map(|_| rng.random_range(-2.5..2.5)).collect();
                let error = Vector3::new(40e-6 * (position.x / 0.3).powi(3) + noise.sample(&mut rng), 0.0, 0.0);
                Stop { at: k as f64, q, position, error }
            })
            .collect();
        let r = order_drift(&d, RunPosition::FileOrder, 1).expect("tested");
        assert!(r.p < LEVEL && r.order_on_configuration_r2 > CONFOUNDED_R2, "{r:?}");
        assert!(!r.found(), "{r:?}");
    }

    #[test]
    fn a_grid_measured_plane_by_plane_in_no_monotone_order_claims_no_drift() {
        // As a UR5's public grid: ten planes of 10 × 10 positions, each swept row by row, the
        // planes taken in a scrambled order, the joints following the position; an error of the
        // pose that the basis does not span: a step per plane that happens to rise with the order
        // the planes were taken in. The order is not a function of the pose (R² low) but
        // consecutive stops are neighbours.
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let noise = Normal::new(0.0, 15e-6).unwrap();
        let planes = [3, 7, 1, 0, 4, 9, 6, 8, 5, 2];
        let d: Vec<Stop> = (0..1000)
            .map(|k| {
                let g = |i: usize| -0.3 + 0.6 * i as f64 / 9.0;
                let (row, col) = (k / 10 % 10, if k / 10 % 2 == 0 { k % 10 } else { 9 - k % 10 });
                let position = Vector3::new(0.6 + g(row), g(col), 0.4 + g(planes[k / 100]));
                let q = vec![
                    position.y.atan2(position.x),
                    -position.z,
                    1.5 - position.xy().norm(),
                    0.1 * position.y,
                    1.0 + 0.2 * position.z,
                    0.0,
                ];
                let plane = ((position.z - 0.1) / (0.6 / 9.0)).round() as usize;
                let taken = planes.iter().position(|&p| p == plane).unwrap() as f64;
                let error = Vector3::new(
                    30e-6 * taken / 9.0 + noise.sample(&mut rng),
                    noise.sample(&mut rng),
                    noise.sample(&mut rng),
                );
                Stop { at: k as f64, q, position, error }
            })
            .collect();
        let r = order_drift(&d, RunPosition::Sequence, 1).expect("tested");
        assert!(r.order_locality < 0.3 && r.order_on_configuration_r2 < CONFOUNDED_R2, "{r:?}");
        assert!(r.p < LEVEL, "the pose's error makes a trend along this order: {r:?}");
        assert!(!r.found(), "{r:?}");
        assert!(r.statement().starts_with("a drift cannot be told from an error of the pose"), "{}", r.statement());
    }

    #[test]
    fn the_readings_of_one_stop_are_one_stop() {
        let e = |x: f64| Vector3::new(x, 0.0, 0.0);
        let z = Vector3::zeros();
        let s = stops(vec![
            (1.0, vec![0.1, 0.2], z, e(3.0)),
            (0.0, vec![0.0, 0.0], z, e(1.0)),
            (1.0, vec![0.1, 0.2], z, e(5.0)),
        ]);
        assert_eq!(s.len(), 2);
        assert_eq!((s[0].at, s[0].error.x), (0.0, 1.0));
        assert_eq!((s[1].at, s[1].error.x), (1.0, 4.0));
    }
}

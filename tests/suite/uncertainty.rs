//! An honest uncertainty per target (issue 25, item 2): compensation's `uncertainty` combines the
//! parameter covariance, the error a held-out validation found beyond it (and beyond the
//! instrument's noise), and the error's growth with distance beyond the validated poses. Here the
//! stated 95 % bound is checked against the true errors of the virtual cell (`robocal simulate`:
//! the simulator knows where the TCP physically was) on tracker poses the uncertainty model never
//! saw — in the calibration zone and away from it.
//!
//! The set is identified from the TriCal session. Its held-out validation uses the half of the
//! tracker poses nearest the calibration zone, every other one of them (A); the others of that
//! half (B) test the bound in the zone, the far half away from it (where the bound adds the
//! growth). `cargo test --release --test suite uncertainty:: -- --ignored --nocapture` prints the table of
//! BENCHMARKS.md over several seeds.

use robocal::cell::{Cell, Purpose};
use robocal::domain::identification::run_identification;
use robocal::domain::validation::fit_data;
use robocal::domain::validity::{Envelope, HeldOutUncertainty, PredictionCovariance, UncertaintyOut};
use robocal::identify::{IdentifyOptions, MeasurementSelection};
use robocal::sim::simulate::{SimulateOptions, simulate};
use robocal::units::MM;
use robocal::validate::report::{Reference, joint_state, session_chains, validate_fitted};

/// Coverage of the stated 95 % bound over one group of test poses.
#[derive(Debug, Default)]
struct Coverage {
    n: usize,
    covered: usize,
    /// Sums for the means: true |e|, the bound, the standard uncertainty, the distance outside.
    error: f64,
    bound: f64,
    standard: f64,
    outside: f64,
    /// Coverage of the covariance alone (the old `uncertainty_mm`, as a 95 % radius).
    covariance_only: usize,
    /// Sums of squares: true |e|, the covariance σ (for RMS figures).
    error2: f64,
    cov2: f64,
    /// The true |e| over the standard uncertainty, per pose (its p95 is the honest k95).
    ratios: Vec<f64>,
}

impl Coverage {
    fn rate(&self) -> f64 {
        self.covered as f64 / self.n.max(1) as f64
    }
    fn mean(&self, v: f64) -> f64 {
        v / self.n.max(1) as f64
    }
}

struct Run {
    model: HeldOutUncertainty,
    inside: Coverage,
    outside: Coverage,
}

/// `reported_sigma`: the tracker readings carry their own σ, as a tracker reports it (the
/// simulator's noise: 16 µm + 0.8 µm per metre from the tracker, per axis); otherwise the
/// instrument model applies, which does not know where the tracker stands and measures the
/// distance from {W}'s origin (the tracker stands 3 m away: it underestimates the noise, and
/// the unexplained part comes out larger than it is).
fn run(seed: u64, reported_sigma: bool) -> Run {
    let opts = SimulateOptions { seed, ..Default::default() };
    let sim = simulate(&opts).unwrap();
    let mut cell = sim.cell.clone();
    if reported_sigma {
        let tracker = sim.truth.set.chain().base().transform_point(&opts.layout.tracker);
        for s in cell.sessions.iter_mut().filter(|s| s.purpose == Purpose::Validation) {
            for m in &mut s.measurements {
                let robocal::cell::Observation::Position(p) = &m.observation else { continue };
                let sigma = opts.noise.tracker_sigma + opts.noise.tracker_sigma_per_m * (p - tracker).norm();
                m.sigma = Some(robocal::cell::Sigma { position: [sigma; 3], rotation: None });
            }
        }
    }
    let cell = &cell;
    let opts = IdentifyOptions {
        selection: MeasurementSelection { sessions: vec!["trical-1".into()], ..Default::default() },
        ..Default::default()
    };
    let (_, doc) = run_identification(cell, opts, None, &|| ()).unwrap();
    let zone = cell.artefact.as_ref().unwrap().triangle.centroid();

    // Tracker poses by their distance to the calibration zone (the reading's position).
    let mut poses: Vec<(usize, usize, f64)> = Vec::new();
    for (si, s) in cell.sessions.iter().enumerate().filter(|(_, s)| s.purpose == Purpose::Validation) {
        for (mi, m) in s.measurements.iter().enumerate() {
            let robocal::cell::Observation::Position(p) = &m.observation else { panic!("a tracker reading") };
            poses.push((si, mi, (p - zone).norm()));
        }
    }
    poses.sort_by(|a, b| a.2.total_cmp(&b.2));
    let half = poses.len() / 2;
    let (near, far) = poses.split_at(half);
    let a: Vec<(usize, usize)> = near.iter().step_by(2).map(|p| (p.0, p.1)).collect();
    let b: Vec<(usize, usize)> = near.iter().skip(1).step_by(2).map(|p| (p.0, p.1)).collect();

    // The held-out validation on A: a cell holding only those readings.
    let mut cell_a = Cell { sessions: Vec::new(), ..cell.clone() };
    for (si, s) in cell.sessions.iter().enumerate().filter(|(_, s)| s.purpose == Purpose::Validation) {
        let mut t = s.clone();
        t.measurements = a.iter().filter(|p| p.0 == si).map(|p| s.measurements[p.1].clone()).collect();
        if !t.measurements.is_empty() {
            cell_a.sessions.push(t);
        }
    }
    let names: Vec<String> = cell_a.sessions.iter().map(|s| s.name.clone()).collect();
    let fit = fit_data(&doc, &[]);
    let report = validate_fitted(&doc.set, &cell_a, &names, Reference::Measured, Some(&fit)).unwrap();
    assert!(report.held_out());
    let model = HeldOutUncertainty::of_report(&doc, &cell_a, &report).unwrap().unwrap();
    let envelope =
        Envelope::of_doc(&doc).unwrap().unwrap().union(&Envelope::of_region(report.region.as_ref().unwrap()).unwrap());
    let covariance = PredictionCovariance::of_doc(&doc).unwrap().unwrap();

    // The bound against the physical error at B and at the far poses.
    let set = &doc.set;
    let (mut inside, mut outside) = (Coverage::default(), Coverage::default());
    let far_set: std::collections::HashSet<(usize, usize)> = far.iter().map(|p| (p.0, p.1)).collect();
    for &(si, mi) in b.iter().chain(far_set.iter()) {
        let s = &cell.sessions[si];
        let m = &s.measurements[mi];
        let (chain, _) = session_chains(set, s);
        let pc = if s.tool == set.tool { covariance.clone() } else { covariance.without_tool() };
        let state = joint_state(&set.gravity_for(&s.tool), &m.q, m.approach.as_deref(), m.temperature_c, set.dof());
        let p_model = chain.fk(&state).t;
        let truth = &sim.run.sessions.iter().find(|(n, _)| *n == s.name).unwrap().1[mi];
        let e = (truth.physical_position - p_model).norm() / MM;
        let sigma = pc.sigma(&chain, &state);
        let d = envelope.outside_measured(&p_model);
        let (u, standard) = UncertaintyOut::of(Some(sigma), None, &p_model, Some(d), Some(&model));
        let bound = u.bound_95_mm.expect("every part known");
        let g = if far_set.contains(&(si, mi)) { &mut outside } else { &mut inside };
        g.n += 1;
        g.covered += usize::from(e <= bound);
        g.covariance_only += usize::from(e <= robocal::domain::validity::MAXWELL_K95 * sigma / MM);
        g.error += e;
        g.error2 += e * e;
        g.cov2 += (sigma / MM).powi(2);
        g.ratios.push(e / standard.unwrap());
        g.bound += bound;
        g.standard += standard.unwrap();
        g.outside += u.beyond_validated_mm.unwrap_or(0.0);
    }
    Run { model, inside, outside }
}

/// Seeds 1–5 of the thesis's virtual lab (1,900 test poses): the bound holds about 95 % of the
/// true errors in the calibration zone and away from it, where the covariance alone holds 71 % and
/// 82 %. With readings that carry no σ the instrument model underestimates the tracker's noise
/// (it does not know the tracker stands 3 m away), the unexplained part comes out larger than it
/// is, and the bound is conservative: it holds more, never fewer.
#[test]
fn the_95_percent_bound_covers_the_true_errors_in_the_zone_and_away_from_it() {
    let total = |reported: bool| {
        let (mut i, mut o) = (Coverage::default(), Coverage::default());
        for seed in 1..=5 {
            let r = run(seed, reported);
            for (all, g) in [(&mut i, &r.inside), (&mut o, &r.outside)] {
                all.n += g.n;
                all.covered += g.covered;
                all.covariance_only += g.covariance_only;
                all.error += g.error;
                all.bound += g.bound;
            }
        }
        (i, o)
    };
    let (i, o) = total(true);
    let rate = |g: &Coverage| g.covered as f64 / g.n as f64;
    let cov = |g: &Coverage| g.covariance_only as f64 / g.n as f64;
    eprintln!(
        "with σ: in the zone {:.3} (covariance only {:.3}), away {:.3} (covariance only {:.3}); mean |e| {:.4} / {:.4}, bound {:.4} / {:.4}",
        rate(&i),
        cov(&i),
        rate(&o),
        cov(&o),
        i.mean(i.error),
        o.mean(o.error),
        i.mean(i.bound),
        o.mean(o.bound)
    );
    assert_eq!((i.n, o.n), (630, 1265));
    // About 95 %: measured 92.5 % and 99.5 % (BENCHMARKS.md); the parameter errors are one draw
    // per seed, so the rate moves from seed to seed (84–100 %).
    assert!((0.90..=0.98).contains(&rate(&i)), "in the zone: {:.3}", rate(&i));
    assert!((0.93..=1.0).contains(&rate(&o)), "away: {:.3}", rate(&o));
    // The covariance alone (what uncertainty_mm was) holds far fewer.
    assert!(cov(&i) < rate(&i) - 0.15 && cov(&o) < rate(&o) - 0.1, "{} {}", cov(&i), cov(&o));
    // The bound is a bound, not a blanket: within three times the mean error.
    assert!(i.mean(i.bound) < 3.0 * i.mean(i.error) && o.mean(o.bound) < 3.0 * o.mean(o.error));
    let (i, o) = total(false);
    assert!(rate(&i) >= 0.95 && rate(&o) >= 0.95, "without σ: {:.3} {:.3}", rate(&i), rate(&o));
}

/// The table in BENCHMARKS.md: seeds 1–5, the readings with their own σ and without.
#[test]
#[ignore = "a benchmark: cargo test --release --test suite uncertainty:: -- --ignored --nocapture"]
fn coverage_table() {
    for reported in [true, false] {
        println!(
            "\n{}\n",
            if reported {
                "Tracker readings with their own σ (as a tracker reports it):"
            } else {
                "Tracker readings without σ (the instrument model, which places the tracker at {W}'s origin):"
            }
        );
        println!(
            "| seed | unexplained (mm) | covariance RMS (mm) | growth (mm/m) | inside: n, coverage, mean \\|e\\| / bound (mm) | outside: n, coverage, mean distance (mm), mean \\|e\\| / bound (mm) | covariance alone: inside, outside |"
        );
        println!("|---|---|---|---|---|---|---|");
        let (mut ci, mut ni, mut co, mut no, mut vi, mut vo) = (0, 0, 0, 0, 0, 0);
        for seed in 1..=5 {
            let r = run(seed, reported);
            let (i, o) = (&r.inside, &r.outside);
            let growth = r.model.growth.as_ref().map_or("—".to_string(), |g| {
                format!("{:+.4} ± {:.4}", g.slope_mm_per_mm * 1e3, g.slope_stderr_mm_per_mm * 1e3)
            });
            println!(
                "| {seed} | {:.4} | {:.4} | {growth} | {}, {:.1} %, {:.4} / {:.4} | {}, {:.1} %, {:.0}, {:.4} / {:.4} | {:.1} %, {:.1} % |",
                r.model.unexplained_mm,
                r.model.covariance_rms_mm,
                i.n,
                100.0 * i.rate(),
                i.mean(i.error),
                i.mean(i.bound),
                o.n,
                100.0 * o.rate(),
                o.mean(o.outside),
                o.mean(o.error),
                o.mean(o.bound),
                100.0 * i.covariance_only as f64 / i.n as f64,
                100.0 * o.covariance_only as f64 / o.n as f64,
            );
            (ci, ni, co, no) = (ci + i.covered, ni + i.n, co + o.covered, no + o.n);
            (vi, vo) = (vi + i.covariance_only, vo + o.covariance_only);
        }
        println!(
            "| all | | | | {ni}, {:.1} % | {no}, {:.1} % | {:.1} %, {:.1} % |",
            100.0 * ci as f64 / ni as f64,
            100.0 * co as f64 / no as f64,
            100.0 * vi as f64 / ni as f64,
            100.0 * vo as f64 / no as f64
        );
    }
}

//! Hot paths of the kinematic core (ISSUE 2 targets): FK + full identification Jacobian,
//! gravity torques, and compensated numerical IK with compliance on 1,000 reachable targets.
//!
//! Run: `cargo bench --bench kinematics`. Besides criterion's timings, the IK group prints the
//! per-target latency distribution (median, p99) and the share of answers on the requested branch.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robocal::kinematics::frame::wrap_pi;
use robocal::kinematics::thesis::{irb120_table_5_1, trical_tool};
use robocal::kinematics::{AnalyticIk, Compensator, Frame, JointState, ParameterSet, Rows, Seed};

/// The IRB 120 as the thesis identified it (Table 5.1 means), with the TriCal tool.
fn calibrated() -> ParameterSet {
    irb120_table_5_1(trical_tool())
}

fn random_configs(set: &ParameterSet, n: usize, seed: u64) -> Vec<[f64; 6]> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let mut q = [0.0; 6];
            for (j, l) in set.model.links.iter().enumerate() {
                q[j] = rng.random_range(l.limits[0]..l.limits[1]);
            }
            q[5] = wrap_pi(q[5]);
            q
        })
        .collect()
}

fn fk_and_jacobian(c: &mut Criterion) {
    let set = calibrated();
    let chain = set.chain();
    let gravity = set.gravity();
    let states: Vec<JointState> =
        random_configs(&set, 1000, 1).iter().map(|q| JointState::with_torques(q, &gravity.torques(q)[..6])).collect();
    let m = set.layout.len();
    let mut out = vec![0.0; 6 * m];
    let mut g = c.benchmark_group("kinematics");
    let mut i = 0;
    g.bench_function("fk_pose", |b| {
        b.iter(|| {
            i = (i + 1) % states.len();
            black_box(chain.fk(black_box(&states[i])))
        })
    });
    g.bench_function("fk_plus_jacobian_43_position", |b| {
        b.iter(|| {
            i = (i + 1) % states.len();
            black_box(chain.jacobian_into(black_box(&states[i]), &set.layout, Rows::Position, &mut out, 3))
        })
    });
    g.bench_function("fk_plus_jacobian_43_pose", |b| {
        b.iter(|| {
            i = (i + 1) % states.len();
            black_box(chain.jacobian_into(black_box(&states[i]), &set.layout, Rows::Pose, &mut out, 6))
        })
    });
    let qs = random_configs(&set, 1000, 2);
    g.bench_function("gravity_torques_newton_euler", |b| {
        b.iter(|| {
            i = (i + 1) % qs.len();
            black_box(gravity.torques(black_box(&qs[i])))
        })
    });
    g.bench_function("gravity_torques_and_jacobian", |b| {
        b.iter(|| {
            i = (i + 1) % qs.len();
            black_box(gravity.torques_and_jacobian(black_box(&qs[i])))
        })
    });
    let ik = AnalyticIk::new(&set.model, chain.base(), chain.tool()).unwrap();
    let poses: Vec<(Frame, robocal::kinematics::Branch)> = qs
        .iter()
        .filter(|q| q[4].abs() > 0.05)
        .map(|q| (set.nominal_chain().fk(&JointState::new(q)), ik.classify(q)))
        .collect();
    g.bench_function("analytic_ik_one_branch", |b| {
        b.iter(|| {
            i = (i + 1) % poses.len();
            black_box(ik.solve_unchecked(black_box(&poses[i].0), poses[i].1).ok())
        })
    });
    g.finish();
}

/// 1,000 random reachable targets of the calibrated (compliant) model, each with the branch of the
/// configuration that generated it.
fn ik_targets(set: &ParameterSet) -> Vec<(Frame, robocal::kinematics::Branch)> {
    let comp = Compensator::new(set);
    let chain = set.chain();
    let gravity = set.gravity();
    let ik = AnalyticIk::new(&set.model, chain.base(), chain.tool()).unwrap();
    let mut out = Vec::new();
    for q in random_configs(set, 5000, 3) {
        if out.len() == 1000 {
            break;
        }
        let tau = gravity.torques(&q);
        let target = chain.fk(&JointState::with_torques(&q, &tau[..6]));
        let b = ik.classify_on(&chain, &JointState::with_torques(&q, &tau[..6]));
        // Reachable by construction; skip the wrist singularity and joint-limit edge cases where the
        // generating configuration is not the branch's in-limit solution.
        if q[4].abs() < 0.05 || comp.pose(&target, Seed::Branch(b)).is_err() {
            continue;
        }
        out.push((target, b));
    }
    out
}

fn numerical_ik(c: &mut Criterion) {
    let set = calibrated();
    let comp = Compensator::new(&set);
    let targets = ik_targets(&set);
    // Per-target latency distribution: each target solved 50 times, its median kept.
    let mut per_target: Vec<f64> = Vec::with_capacity(targets.len());
    let mut on_branch = 0;
    let mut iters = Vec::new();
    for (t, b) in &targets {
        let mut runs = [0.0; 50];
        for r in runs.iter_mut() {
            let start = Instant::now();
            let res = black_box(comp.pose(black_box(t), Seed::Branch(*b)));
            *r = start.elapsed().as_secs_f64();
            if let Ok(s) = &res {
                iters.push(s.iterations);
            }
        }
        runs.sort_by(f64::total_cmp);
        per_target.push(runs[runs.len() / 2]);
        if comp.pose(t, Seed::Branch(*b)).is_ok_and(|s| s.branch == Some(*b)) {
            on_branch += 1;
        }
    }
    per_target.sort_by(f64::total_cmp);
    let pct = |p: f64| per_target[((per_target.len() - 1) as f64 * p).round() as usize] * 1e6;
    iters.sort();
    println!(
        "compensated IK, {} targets: median {:.2} µs, p99 {:.2} µs, max {:.2} µs; on the requested branch {}/{}; iterations median {} max {}",
        targets.len(),
        pct(0.5),
        pct(0.99),
        pct(1.0),
        on_branch,
        targets.len(),
        iters[iters.len() / 2],
        iters[iters.len() - 1]
    );
    let mut g = c.benchmark_group("ik");
    let mut i = 0;
    g.bench_function("compensated_ik_with_compliance", |b| {
        b.iter(|| {
            i = (i + 1) % targets.len();
            black_box(comp.pose(black_box(&targets[i].0), Seed::Branch(targets[i].1)).ok())
        })
    });
    g.finish();
}

criterion_group!(benches, fk_and_jacobian, numerical_ik);
criterion_main!(benches);

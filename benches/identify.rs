//! Hot paths of identification: DETMAX pose selection (O1) on realistic pools of the thesis's
//! IRB 120 (Table 5.1 parameters, TriCal tool), position blocks of the 31 identified parameters.
//!
//! - `detmax/75_of_360_trical`: 75 of 360 planned TriCal candidates, 120 per ball, ν ≤ 50°
//!   (the thesis's setting, §4.1, §4.2.5);
//! - `detmax/100_of_10000_random`: 100 of 10,000 configurations drawn within the joint limits.
//!
//! Each also `…_detmax_alone`: the thesis's DETMAX without the final exchange scan
//! (`DetmaxOptions::polish = false`). And `detmax/75_of_360_trical_prediction`: the same 75 of 360
//! chosen by the prediction criterion (`detmax_prediction`) over 500 configurations drawn within
//! the joint limits.
//!
//! Run: `cargo bench --bench identify`. Before criterion's timings it prints, per pool, the
//! selection's O1 and κ and the number of exchanges.

use std::f64::consts::PI;
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use robocal::identify::detmax::{Block, DetmaxOptions, Workspace, detmax, detmax_prediction, selection_observability};
use robocal::kinematics::frame::wrap_pi;
use robocal::kinematics::thesis::{irb120_table_5_1, trical_tool};
use robocal::kinematics::{JointState, ParameterSet, Rows};
use robocal::sim::poses::{CellLayout, PlanningCell};

/// The 31 parameters the thesis identifies (§3.6, Table 5.1).
const IDENTIFIED: [&str; 31] = [
    "alpha1", "alpha2", "alpha3", "alpha4", "alpha5", "a1", "a2", "a3", "a4", "a5", "d3", "d4", "d5", "d6", "theta2",
    "theta3", "theta4", "theta5", "theta6", "c2", "c3", "c4", "c5", "c6", "beta2", "base_x", "base_y", "base_z",
    "base_a", "base_b", "base_c",
];
const M: usize = IDENTIFIED.len();

fn blocks(set: &ParameterSet, qs: &[[f64; 6]]) -> Vec<Block> {
    let chain = set.chain();
    let g = set.gravity();
    let cols: Vec<usize> = IDENTIFIED.iter().map(|n| set.layout.find(n).expect("an IRB 120 parameter")).collect();
    let mut buf = vec![0.0; 3 * set.layout.len()];
    qs.iter()
        .map(|q| {
            let s = JointState::with_torques(q, &g.torques(q)[..6]);
            chain.jacobian_into(&s, &set.layout, Rows::Position, &mut buf, 3);
            Block::from_column_major(&buf, 3, 3, &cols)
        })
        .collect()
}

fn trical_pool(set: &ParameterSet) -> Vec<Block> {
    let cell = PlanningCell::new(&CellLayout::default()).unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(2016);
    let mut qs = Vec::new();
    for k in 1..=3 {
        qs.extend(
            cell.identification_candidates(k, 50.0 * PI / 180.0, 120, 120 * 200, &mut rng).unwrap().iter().map(|p| p.q),
        );
    }
    blocks(set, &qs)
}

fn random_pool(set: &ParameterSet, count: usize, seed: u64) -> Vec<Block> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut qs = Vec::with_capacity(count);
    while qs.len() < count {
        let mut q = [0.0; 6];
        for (j, l) in set.model.links.iter().enumerate() {
            q[j] = rng.random_range(l.limits[0]..l.limits[1]);
        }
        q[5] = wrap_pi(q[5]);
        if q[4].abs() >= 0.05 {
            qs.push(q);
        }
    }
    blocks(set, &qs)
}

fn report(name: &str, pool: &[Block], opts: &DetmaxOptions) {
    let r = detmax(pool, M, opts).unwrap();
    let o = selection_observability(pool, M, &r.selected);
    println!(
        "{name}{}: O1 {:.4} (random start {:.4}), κ {:.1}, {} exchanges ({} by the exchange scan), converged {}",
        if opts.polish { "" } else { ", DETMAX alone" },
        r.index_final,
        r.index_initial,
        o.condition_number(),
        r.exchanges,
        r.polish_exchanges,
        r.converged
    );
}

fn detmax_bench(c: &mut Criterion) {
    let set = irb120_table_5_1(trical_tool());
    let trical = trical_pool(&set);
    let random = random_pool(&set, 10_000, 1);
    let o75 = DetmaxOptions { seed: 1, ..DetmaxOptions::new(75) };
    let o100 = DetmaxOptions { seed: 1, ..DetmaxOptions::new(100) };
    let thesis = |o: DetmaxOptions| DetmaxOptions { polish: false, ..o };
    for o in [o75, thesis(o75)] {
        report("75 of 360 TriCal", &trical, &o);
    }
    for o in [o100, thesis(o100)] {
        report("100 of 10,000 random", &random, &o);
    }

    let workspace = Workspace::new(&random_pool(&set, 500, 2), M).unwrap();
    let p = detmax_prediction(&trical, M, &workspace, &o75).unwrap();
    println!(
        "75 of 360 TriCal, prediction criterion: prediction RMS per σ {:.3} (random start {:.3}; O1 selection {:.3}), O1 {:.4}, {} exchanges ({} by the exchange scan)",
        p.index_final,
        p.index_initial,
        workspace.prediction_rms(&trical, &detmax(&trical, M, &o75).unwrap().selected),
        selection_observability(&trical, M, &p.selected).o1,
        p.exchanges,
        p.polish_exchanges
    );

    let mut g = c.benchmark_group("detmax");
    for (name, o) in [("75_of_360_trical", o75), ("75_of_360_trical_detmax_alone", thesis(o75))] {
        g.bench_function(name, |b| b.iter(|| black_box(detmax(black_box(&trical), M, &o).unwrap())));
    }
    g.bench_function("75_of_360_trical_prediction", |b| {
        b.iter(|| black_box(detmax_prediction(black_box(&trical), M, &workspace, &o75).unwrap()))
    });
    g.sample_size(10);
    for (name, o) in [("100_of_10000_random", o100), ("100_of_10000_random_detmax_alone", thesis(o100))] {
        g.bench_function(name, |b| b.iter(|| black_box(detmax(black_box(&random), M, &o).unwrap())));
    }
    g.finish();
}

criterion_group!(benches, detmax_bench);
criterion_main!(benches);

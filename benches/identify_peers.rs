//! Identification speed on the peers' data (`../shared/datasets/irb120-sim-peers/`): the IRB 120
//! plain MDH model, 23 parameters (all 24 MDH but d3, redundant with d2), no base (identity), the
//! tool (30, 0, 120) mm fixed, 3 residuals per pose — the problem `../shared/peers/numpy_calib.py`
//! and pybotics solve. Validated against the noise-free truth of `validation_500.csv`.
//!
//! Run: `cargo bench --bench identify_peers`; the side-by-side reference:
//! `scripts/bench_identify_peers.sh` (runs this bench and numpy_calib.py in one session).

use std::hint::black_box;
use std::path::PathBuf;

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Vector3;
use robocal::cell::{Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session};
use robocal::identify::{IdentifyOptions, ModelOptions, identify};
use robocal::kinematics::model::irb120;
use robocal::kinematics::{JointState, Tool};

fn data(name: &str) -> Vec<([f64; 6], Vector3<f64>, Vector3<f64>)> {
    let path: PathBuf =
        [env!("CARGO_MANIFEST_DIR"), "..", "shared", "datasets", "irb120-sim-peers", name].iter().collect();
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.lines()
        .skip(1)
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
            let q = [v[0], v[1], v[2], v[3], v[4], v[5]];
            (q, Vector3::new(v[6], v[7], v[8]) * 1e-3, Vector3::new(v[9], v[10], v[11]) * 1e-3)
        })
        .collect()
}

fn tool() -> Tool {
    Tool { tcp: [0.030, 0.0, 0.120, 0.0, 0.0, 0.0], mass: 0.0, com: Vector3::zeros() }
}

fn cell(n: usize) -> Cell {
    let measurements = data(&format!("identification_{n}.csv"))
        .into_iter()
        .map(|(q, _, meas)| Measurement {
            q: q.to_vec(),
            observation: Observation::Position(meas),
            temperature_c: None,
            time_s: None,
            sequence: None,
            approach: None,
            indicators: None,
            sigma: None,
        })
        .collect();
    Cell {
        model: irb120(),
        base_guess: Some([0.0; 6]),
        artefact: None,
        sessions: vec![Session {
            name: "peers".into(),
            purpose: Purpose::Identification,
            instrument: Instrument::LaserTracker,
            tool: tool(),
            identify_tcp: false,
            target: None,
            measurements,
            order: MeasuringOrder::Unknown,
        }],
    }
}

/// The peers' 23-parameter problem: plain MDH (no β, no compliance), base and tool fixed, d3 fixed.
fn options() -> IdentifyOptions {
    IdentifyOptions {
        model: ModelOptions { beta: false, compliance: false, ..Default::default() },
        fixed: ["base_x", "base_y", "base_z", "base_a", "base_b", "base_c", "d3"].map(String::from).to_vec(),
        ..Default::default()
    }
}

fn validation_mean_um(id: &robocal::identify::Identification) -> f64 {
    let chain = id.set.chain();
    let v = data("validation_500.csv");
    v.iter().map(|(q, truth, _)| (chain.fk(&JointState::new(q)).t - truth).norm()).sum::<f64>() / v.len() as f64 * 1e6
}

fn identification(c: &mut Criterion) {
    let mut g = c.benchmark_group("identify_peers");
    g.sample_size(20);
    for n in [75, 1000, 5000] {
        let cell = cell(n);
        let opts = options();
        let id = identify(&cell, &opts).unwrap();
        println!(
            "peers {n}: {} parameters, {} iterations, validation mean {:.3} µm (references: 5.47 / 1.11 / 0.63 µm for 75 / 1000 / 5000)",
            id.free_names.len(),
            id.iterations,
            validation_mean_um(&id)
        );
        g.bench_function(format!("{n}_poses"), |b| b.iter(|| black_box(identify(black_box(&cell), &opts).unwrap())));
    }
    g.finish();
}

criterion_group!(benches, identification);
criterion_main!(benches);

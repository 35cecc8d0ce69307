//! Program filtering (issue 26): a 10,000-target program in each language, filtered whole —
//! parsing, frames, compensation with the predicted uncertainty of every target, writing back.
//! The target: ≤ 1 s on 2 cores.
//!
//! Run: `cargo bench --bench program_filter`. The programs are the tests' seeded generators
//! (`tests/suite/programs.rs`): IRB 120 (thesis Table 5.1) for RAPID, KRL and Fanuc, a perturbed
//! UR10 for URScript; joint targets recomputed. The IRB 120 set is given a parameter covariance
//! (σ 10 µm / 10 µrad per identified parameter, uncorrelated) so every target also pays for its
//! uncertainty, as with a set identified by robocal.

#[path = "../tests/suite/programs.rs"]
mod programs;

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use robocal::domain::ParameterSetDoc;
use robocal::domain::program::{Calibration, FilterOptions, JointTargets, filter};
use robocal::domain::validity::PredictionCovariance;
use robocal::kinematics::thesis::TABLE_5_1_MEANS;
use robocal::kinematics::{Compensator, ParameterSet};

/// A covariance for the set: the Table 5.1 parameters free, σ 1e-5 (m or rad), uncorrelated.
fn covariance(set: &ParameterSet) -> Option<PredictionCovariance> {
    let mut doc = ParameterSetDoc::new(set.clone());
    let names: Vec<&str> = TABLE_5_1_MEANS.iter().map(|(n, _)| *n).filter(|n| set.layout.find(n).is_some()).collect();
    for n in &names {
        doc.std[set.layout.find(n).unwrap()] = Some(1e-5);
    }
    let m = names.len();
    let corr = (0..m).map(|i| (0..m).map(|j| Some(f64::from(u8::from(i == j)))).collect()).collect();
    doc.quality = Some(robocal::domain::Quality {
        free: Some(names.iter().map(|n| n.to_string()).collect()),
        correlation: Some(corr),
        ..Default::default()
    });
    PredictionCovariance::of_doc(&doc).unwrap()
}

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("program_filter");
    g.sample_size(10);
    let irb = programs::irb120_set();
    let ur = programs::ur10_set();
    let samples = [
        ("rapid", &irb, programs::rapid(1, 10_000)),
        ("krl", &irb, programs::krl(1, 10_000)),
        ("fanuc", &irb, programs::fanuc(1, 10_000)),
        ("urscript", &ur, programs::urscript(1, 10_000)),
    ];
    for (name, set, sample) in &samples {
        let comp = Compensator::new(set);
        let cov = if name == &"urscript" { None } else { covariance(set) };
        let cal = Calibration {
            set,
            compensator: &comp,
            envelope: None,
            allow_outside_envelope: false,
            covariance: cov.as_ref(),
            held_out: None,
        };
        let opts = FilterOptions {
            language: None,
            joint_targets: JointTargets::Recompute,
            frames: sample.frames.clone(),
            seed_joints: sample.seed_joints.clone(),
        };
        let t0 = Instant::now();
        let out = filter(&cal, &sample.files, &opts).unwrap();
        let bytes: usize = sample.files.iter().map(|f| f.bytes.len()).sum();
        eprintln!(
            "{name}: {} targets ({} compensated, {} failed), {:.1} MB, first run {:.3} s",
            out.report.len(),
            out.compensated(),
            out.failed(),
            bytes as f64 / 1e6,
            t0.elapsed().as_secs_f64()
        );
        g.bench_function(format!("{name}_10000_targets"), |b| {
            b.iter(|| black_box(filter(&cal, &sample.files, &opts).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

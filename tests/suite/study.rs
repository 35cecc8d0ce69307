//! The thesis's Algorithm 5.1 (issue 4, item 6): DETMAX-optimised sets of each size, identified
//! and validated; results independent of the thread count; the spread shrinks with n.

use robocal::identify::IdentifyOptions;
use robocal::identify::observability::Index;
use robocal::identify::study::{StudyOptions, study};
use robocal::sim::simulate::{SimulateOptions, simulate};

#[test]
fn study_is_deterministic_and_shrinks_with_n() {
    let sim = simulate(&SimulateOptions { seed: 2, ..Default::default() }).unwrap();
    let opts = |threads| StudyOptions {
        sizes: vec![20, 75],
        sets: 8,
        index: Index::O1,
        polish: false,
        seed: 1,
        threads,
        validation: Vec::new(),
        identify: IdentifyOptions::default(),
    };
    let one = study(&sim.cell, &opts(1)).unwrap();
    let two = study(&sim.cell, &opts(2)).unwrap();
    assert_eq!(one.runs, two.runs, "the thread count changed a result");
    assert_eq!(one.pool, 360);
    assert_eq!(one.validation, ["tracker-n1", "tracker-n2", "tracker-n3"]);
    let (small, large) = (&one.rows[0], &one.rows[1]);
    assert_eq!((small.failed, large.failed), (0, 0));
    // Fig. 5.8–5.10: the boxes narrow and the maxima fall as n grows.
    let iqr = |q: &[f64; 5]| q[3] - q[1];
    assert!(iqr(&large.mean) < iqr(&small.mean), "{:?} vs {:?}", large.mean, small.mean);
    assert!(large.max[2] < small.max[2], "{:?} vs {:?}", large.max, small.max);
    // Every run's statistics are consistent: 0 < std ≤ mean-ish, mean ≤ max.
    for r in &one.runs {
        assert!(r.error.is_none());
        assert!(r.mean > 0.0 && r.mean <= r.max && r.std > 0.0, "{r:?}");
    }
}

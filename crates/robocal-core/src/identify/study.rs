//! The thesis's Algorithm 5.1 (§5.2): for each set size n, draw `sets` random starts, let DETMAX
//! optimise each set of n identification measurements, identify on it, and validate the result
//! on the validation sessions; summarise each n by the quartiles of the validation mean, standard
//! deviation and maximum over its sets (the box plots of Fig. 5.8–5.10).
//!
//! The identifications are independent, so they run on `threads` scoped worker threads that take
//! jobs from a shared counter; every job's seed depends only on (n, set), so the result does not
//! depend on the thread count.

use std::sync::Mutex;
use std::sync::atomic::{AtomicUsize, Ordering};

use super::observability::Index;
use super::{DetmaxPool, IdentifyError, IdentifyOptions, identify};
use crate::cell::Cell;
use crate::validate::report::{Reference, validate, validation_sessions};

/// Settings of a study.
#[derive(Clone, Debug)]
pub struct StudyOptions {
    /// Set sizes n (identification measurements per set).
    pub sizes: Vec<usize>,
    /// Sets per size.
    pub sets: usize,
    /// The index DETMAX maximises.
    pub index: Index,
    /// Finish each DETMAX run with exchange-optimal polishing. Off by default: the thesis's DETMAX
    /// alone, whose random starts end in different local optima — the spread Algorithm 5.1
    /// measures. Polished runs converge to nearly the same set from every start.
    pub polish: bool,
    /// Base seed; set i of size n starts DETMAX from seed `seed + 1000·n + i`.
    pub seed: u64,
    /// Worker threads (≥ 1).
    pub threads: usize,
    /// Sessions to validate on; empty: every validation session of the cell.
    pub validation: Vec<String>,
    /// Everything else about the identification (sessions of the pool, model, κ limit, …).
    pub identify: IdentifyOptions,
}

/// One identification of the study.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyRun {
    /// Set size: identification measurements.
    pub n: usize,
    /// Index of the set among its size's, 0-based.
    pub set: usize,
    /// DETMAX's seed: `seed + 1000·n + set` (wrapping).
    pub seed: u64,
    /// Validation position error of the calibrated model, m: mean, standard deviation, maximum.
    pub mean: f64,
    /// Their standard deviation, m.
    pub std: f64,
    /// Their maximum, m.
    pub max: f64,
    /// κ in SI units and O1 of the identification.
    pub kappa: f64,
    /// O1 of the identification (SI units).
    pub o1: f64,
    /// Why there is no result (a refused fit: rank deficiency, κ above the limit, divergence).
    pub error: Option<String>,
}

/// Minimum, first quartile, median, third quartile, maximum.
pub type Quartiles = [f64; 5];

/// The summary of one set size.
#[derive(Clone, Debug, PartialEq)]
pub struct StudyRow {
    /// Set size.
    pub n: usize,
    /// Identifications that produced a parameter set.
    pub succeeded: usize,
    /// Identifications refused, with their reasons.
    pub failed: usize,
    /// Quartiles of the runs' validation mean position errors, m (NaN when no run succeeded).
    pub mean: Quartiles,
    /// Quartiles of their standard deviations, m.
    pub std: Quartiles,
    /// Quartiles of their maxima, m.
    pub max: Quartiles,
}

/// The result of a study.
#[derive(Clone, Debug)]
pub struct Study {
    /// Candidates in the DETMAX pool (measurements of the pool's sessions).
    pub pool: usize,
    /// The sessions validated on.
    pub validation: Vec<String>,
    /// One summary per set size, in the options' order.
    pub rows: Vec<StudyRow>,
    /// Every identification: sizes in the options' order, sets in order within each.
    pub runs: Vec<StudyRun>,
}

/// Quartiles by linear interpolation between order statistics (the `quantile` of
/// [`crate::validate::stats`]); `None` for an empty sample.
fn quartiles(values: &[f64]) -> Option<Quartiles> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    Some([0.0, 0.25, 0.5, 0.75, 1.0].map(|p| crate::validate::stats::quantile(&v, p)))
}

/// Run the study on `cell`.
pub fn study(cell: &Cell, opts: &StudyOptions) -> Result<Study, IdentifyError> {
    study_with_progress(cell, opts, &|_, _| {})
}

/// [`study`], calling `progress` with (runs done, runs in all) after each identification.
pub fn study_with_progress(
    cell: &Cell,
    opts: &StudyOptions,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Study, IdentifyError> {
    if opts.sizes.is_empty() || opts.sets == 0 {
        return Err(IdentifyError::option("the study needs at least one size and one set"));
    }
    if opts.threads == 0 {
        return Err(IdentifyError::field("threads", "must be at least 1"));
    }
    let validation = if opts.validation.is_empty() { validation_sessions(cell) } else { opts.validation.clone() };
    if validation.is_empty() {
        return Err(IdentifyError::option("the cell has no validation session to score the study on"));
    }
    // Named sessions are checked once here, not discovered as a failure of every run.
    for name in &opts.validation {
        match cell.session(name) {
            None => {
                let known = validation_sessions(cell).join(", ");
                return Err(IdentifyError::field(
                    "validation",
                    format!("no session '{name}' in the cell (its validation sessions: {known})"),
                ));
            }
            Some(s) if s.purpose != crate::cell::Purpose::Validation => {
                return Err(IdentifyError::field(
                    "validation",
                    format!("'{name}' is an identification session, not a validation one"),
                ));
            }
            Some(_) => {}
        }
    }
    let pool = DetmaxPool::new(cell, &opts.identify)?;
    if let Some(&n) = opts.sizes.iter().find(|&&n| n >= pool.len()) {
        return Err(IdentifyError::field(
            "sizes",
            format!("set size {n} must be smaller than the pool's {} measurements", pool.len()),
        ));
    }
    let jobs: Vec<(usize, usize)> = opts.sizes.iter().flat_map(|&n| (0..opts.sets).map(move |i| (n, i))).collect();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<StudyRun>>> = Mutex::new(vec![None; jobs.len()]);
    let one = |n: usize, set: usize| -> StudyRun {
        let seed = opts.seed.wrapping_add(1000 * n as u64 + set as u64);
        let mut run = StudyRun {
            n,
            set,
            seed,
            mean: f64::NAN,
            std: f64::NAN,
            max: f64::NAN,
            kappa: f64::NAN,
            o1: f64::NAN,
            error: None,
        };
        let outcome = (|| -> Result<(), String> {
            let o = super::detmax::DetmaxOptions {
                index: opts.index,
                seed,
                polish: opts.polish,
                ..super::detmax::DetmaxOptions::new(n)
            };
            let (subset, _) = pool.select_with(&o).map_err(|e| e.to_string())?;
            let mut o = opts.identify.clone();
            o.selection.subset = subset;
            let id = identify(cell, &o).map_err(|e| e.to_string())?;
            run.kappa = id.quality.kappa;
            run.o1 = id.quality.observability.o1;
            let report = validate(&id.set, cell, &validation, Reference::Measured).map_err(|e| e.to_string())?;
            let p = &report.calibrated.position;
            (run.mean, run.std, run.max) = (p.mean, p.std, p.max);
            Ok(())
        })();
        run.error = outcome.err();
        run
    };
    std::thread::scope(|scope| {
        for _ in 0..opts.threads.min(jobs.len()) {
            scope.spawn(|| {
                loop {
                    let k = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(n, set)) = jobs.get(k) else { break };
                    let r = one(n, set);
                    results.lock().expect("no worker panics while holding the lock")[k] = Some(r);
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, jobs.len());
                }
            });
        }
    });
    let runs: Vec<StudyRun> =
        results.into_inner().expect("workers joined").into_iter().map(|r| r.expect("every job ran")).collect();
    let rows = opts
        .sizes
        .iter()
        .map(|&n| {
            let ok: Vec<&StudyRun> = runs.iter().filter(|r| r.n == n && r.error.is_none()).collect();
            let q = |f: fn(&StudyRun) -> f64| {
                quartiles(&ok.iter().map(|r| f(r)).collect::<Vec<_>>()).unwrap_or([f64::NAN; 5])
            };
            StudyRow {
                n,
                succeeded: ok.len(),
                failed: opts.sets - ok.len(),
                mean: q(|r| r.mean),
                std: q(|r| r.std),
                max: q(|r| r.max),
            }
        })
        .collect();
    Ok(Study { pool: pool.len(), validation, rows, runs })
}

/// Parse a size list: `20..100` (every n from 20 to 100), `20..100:5` (step 5), or `20,50,75`.
pub fn parse_sizes(spec: &str) -> Result<Vec<usize>, String> {
    let spec = spec.trim();
    let num = |s: &str| s.trim().parse::<usize>().map_err(|_| format!("'{}' is not a whole number", s.trim()));
    let sizes = if let Some((a, b)) = spec.split_once("..") {
        let (b, step) = match b.split_once(':') {
            Some((b, st)) => (b, num(st)?),
            None => (b, 1),
        };
        let (a, b) = (num(a)?, num(b)?);
        if step == 0 {
            return Err("the step must be at least 1".into());
        }
        if a > b {
            return Err(format!("the range {a}..{b} is empty"));
        }
        (a..=b).step_by(step).collect()
    } else {
        spec.split(',').map(num).collect::<Result<Vec<_>, _>>()?
    };
    if sizes.is_empty() {
        return Err("no set size given".into());
    }
    if let Some(n) = sizes.iter().find(|&&n| n == 0) {
        return Err(format!("set size {n} must be at least 1"));
    }
    Ok(sizes)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_sizes("20..23").unwrap(), vec![20, 21, 22, 23]);
        assert_eq!(parse_sizes("20..100:40").unwrap(), vec![20, 60, 100]);
        assert_eq!(parse_sizes("20, 50,75").unwrap(), vec![20, 50, 75]);
        assert!(parse_sizes("30..20").unwrap_err().contains("empty"));
        assert!(parse_sizes("20..x").unwrap_err().contains("'x'"));
        assert!(parse_sizes("0,5").unwrap_err().contains("at least 1"));
        assert!(parse_sizes("5..9:0").unwrap_err().contains("step"));
    }

    #[test]
    fn quartiles_interpolate() {
        let q = quartiles(&[4.0, 1.0, 3.0, 2.0, 5.0]).unwrap();
        assert_eq!(q, [1.0, 2.0, 3.0, 4.0, 5.0]);
        assert!(quartiles(&[]).is_none());
    }
}

//! The report of `robocal study`: one typed document, serialised as the `--out` JSON and rendered
//! as the text table. Lengths in mm.

use serde::Serialize;

use super::reports::finite;
use crate::identify::observability::Index;
use crate::identify::study::Study;
use crate::units::MM;

/// `robocal study`: per set size the quartiles over the sets, and every identification.
#[derive(Clone, Debug, Serialize)]
pub struct StudyReport {
    /// Measurements in the pool DETMAX draws from.
    pub pool: usize,
    pub validation_sessions: Vec<String>,
    pub sets: usize,
    pub index: &'static str,
    pub polish: bool,
    pub seed: u64,
    pub quartiles: &'static str,
    pub rows: Vec<StudySize>,
    pub runs: Vec<StudyRunFigures>,
    /// Wall-clock seconds and worker threads: the text's, not the document's.
    #[serde(skip)]
    pub seconds: f64,
    #[serde(skip)]
    pub threads: usize,
}

/// One set size: quartiles (min, q1, median, q3, max) over its sets of the validation errors.
#[derive(Clone, Debug, Serialize)]
pub struct StudySize {
    pub n: usize,
    pub succeeded: usize,
    pub refused: usize,
    pub mean_mm_quartiles: [f64; 5],
    pub std_mm_quartiles: [f64; 5],
    pub max_mm_quartiles: [f64; 5],
}

/// One identification of the study (figures absent when it was refused).
#[derive(Clone, Debug, Serialize)]
pub struct StudyRunFigures {
    pub n: usize,
    pub set: usize,
    pub seed: u64,
    pub mean_mm: Option<f64>,
    pub std_mm: Option<f64>,
    pub max_mm: Option<f64>,
    pub kappa_si: Option<f64>,
    pub o1_si: Option<f64>,
    pub refused: Option<String>,
}

fn quartiles_mm(q: &[f64; 5]) -> [f64; 5] {
    q.map(|v| v / MM)
}

impl StudyReport {
    pub fn new(st: &Study, sets: usize, index: Index, polish: bool, seed: u64, seconds: f64, threads: usize) -> Self {
        StudyReport {
            pool: st.pool,
            validation_sessions: st.validation.clone(),
            sets,
            index: index.name(),
            polish,
            seed,
            quartiles: "min, q1, median, q3, max over the sets of each size",
            rows: st
                .rows
                .iter()
                .map(|r| StudySize {
                    n: r.n,
                    succeeded: r.succeeded,
                    refused: r.failed,
                    mean_mm_quartiles: quartiles_mm(&r.mean),
                    std_mm_quartiles: quartiles_mm(&r.std),
                    max_mm_quartiles: quartiles_mm(&r.max),
                })
                .collect(),
            runs: st
                .runs
                .iter()
                .map(|r| StudyRunFigures {
                    n: r.n,
                    set: r.set,
                    seed: r.seed,
                    mean_mm: finite(r.mean / MM),
                    std_mm: finite(r.std / MM),
                    max_mm: finite(r.max / MM),
                    kappa_si: finite(r.kappa),
                    o1_si: finite(r.o1),
                    refused: r.error.clone(),
                })
                .collect(),
            seconds,
            threads,
        }
    }

    /// The summary line and the quartile table.
    pub fn text(&self) -> String {
        let mut text = format!(
            "{} identifications ({} sizes × {} DETMAX-optimised sets from a pool of {}), validated on {}, in {:.1} s on {} threads\n",
            self.runs.len(),
            self.rows.len(),
            self.sets,
            self.pool,
            self.validation_sessions.join(", "),
            self.seconds,
            self.threads
        );
        text.push_str("quartiles over the sets (min / q1 / median / q3 / max), mm\n");
        text.push_str(&format!("{:>4} {:>7}  {:<36}  {:<36}  {:<36}\n", "n", "refused", "mean", "std", "max"));
        let fmt = |q: &[f64; 5]| q.iter().map(|v| format!("{v:.3}")).collect::<Vec<_>>().join(" ");
        for r in &self.rows {
            text.push_str(&format!(
                "{:>4} {:>7}  {:<36}  {:<36}  {:<36}\n",
                r.n,
                r.refused,
                fmt(&r.mean_mm_quartiles),
                fmt(&r.std_mm_quartiles),
                fmt(&r.max_mm_quartiles)
            ));
        }
        text
    }
}

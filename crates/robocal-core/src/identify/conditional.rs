//! What the free parameters' values and standard deviations assume of the parameters held because
//! the data leave them undetermined.
//!
//! A held parameter is not known: the data could not tell it (its σ would be beyond the bound, or
//! its estimate not significant), so it is kept at its start value. The free parameters are then
//! fitted *given* that value, and their σ are conditional on it. Where a held parameter is nearly
//! one direction with free ones, the statement "base_x ± 0.03 mm" is true only if the held one is
//! exactly right: on the UR10's series D the probe's z is held (σ 11 mm, correlation +1.000 with
//! base_x) and base_x moves a millimetre for every millimetre the probe's z is off.
//!
//! How far a held parameter is off is not in the data (a prior would be a type-B estimate from a
//! drawing or a tolerance, which the product does not have). What the data do give is the
//! sensitivity: the free parameters' least-squares shift per unit of the held one,
//! ∂x_f/∂x_h = −(J_fᵀJ_f)⁻¹ J_fᵀ J_h, with the fit's own weights, at the solution. With the
//! held parameter's own σ (the one that decided to hold it) it says which free parameters the
//! held one could move by more than their stated σ: those are reported, with the coefficient,
//! so whoever knows the held value better can correct them and whoever does not knows that the
//! σ assumes it.

use faer::Mat;
use nalgebra::DMatrix;

use super::fixed::FixedReason;
use super::identifiability::Status;
use super::problem::{GlobalParam, Problem};
use super::quality::Quality;
use super::solver::Fit;
use crate::kinematics::Param;

/// A held parameter and the free parameters its value moves by more than their own σ.
#[derive(Clone, Debug, PartialEq)]
pub struct Conditional {
    /// The held parameter's name.
    pub held: String,
    /// Its file unit (`mm`, `deg`, `kg`, …).
    pub unit: &'static str,
    /// The value it is held at, in its file unit.
    pub value: f64,
    /// Its standard deviation as judged when it was held (file unit): what the data would leave it
    /// free.
    pub std: f64,
    /// Per free parameter moved beyond its σ by one σ of the held one: (name, its file unit,
    /// its shift per file unit of the held parameter, its own σ in its file unit), largest
    /// |shift·std_held/σ| first.
    pub moves: Vec<(String, &'static str, f64, f64)>,
}

/// The SI standard deviation recorded when parameter `g` was held for want of information, or
/// `None` when it was held for another reason (the user's choice, the model, no effect at all). A
/// compliance held as not significant is not among them: its hold's own note gives what the hold
/// moved (`hold::hold_notes`).
fn held_std(status: &Status) -> Option<f64> {
    match status {
        Status::Fixed(FixedReason::Undetermined { std, .. } | FixedReason::UndeterminedAtSolution { std, .. }) => {
            Some(*std)
        }
        Status::Fixed(FixedReason::PayloadInsignificant { std_kg, .. }) => Some(*std_kg),
        _ => None,
    }
}

fn param_of(problem: &Problem, g: usize) -> Param {
    match problem.params[g] {
        GlobalParam::Robot(i) => problem.layout.params()[i],
        GlobalParam::Tool { k, .. } => Param::Tool(k),
    }
}

/// The conditionals of a fit: for each parameter held for want of information, the free
/// parameters one σ of it would move by more than their own reported σ.
pub(super) fn conditionals(
    problem: &Problem,
    fit: &Fit,
    free: &[usize],
    status: &[Status],
    quality: &Quality,
) -> Vec<Conditional> {
    let held: Vec<(usize, f64)> = (0..problem.n_params())
        .filter(|g| !free.contains(g))
        .filter_map(|g| held_std(&status[g]).filter(|s| s.is_finite() && *s > 0.0).map(|s| (g, s)))
        .collect();
    let m = free.len();
    if held.is_empty() || m == 0 || fit.jacobian.ncols() != m {
        return Vec::new();
    }
    // The held columns with the fit's weights: the instrument's (in `linearise`) and the robust
    // loss's per observation (as `fit.jacobian` carries them).
    let hg: Vec<usize> = held.iter().map(|h| h.0).collect();
    let mut jh = Mat::<f64>::zeros(problem.n_rows, hg.len());
    let mut res = vec![0.0; problem.n_rows];
    problem.linearise(&fit.x, &hg, &mut jh, &mut res);
    for (o, w) in problem.obs.iter().zip(&fit.weights) {
        let w = w.sqrt();
        for r in o.row..o.row + o.rows {
            for c in 0..hg.len() {
                jh[(r, c)] *= w;
            }
        }
    }
    let jf = fit.jacobian.as_ref();
    // Column-scaled normal equations of the free parameters: G = DJ_fᵀJ_fD, B = DJ_fᵀJ_h.
    let g0: Mat<f64> = jf.transpose() * jf;
    let b0: Mat<f64> = jf.transpose() * jh.as_ref();
    let norm: Vec<f64> = (0..m).map(|c| if g0[(c, c)] > 0.0 { 1.0 / g0[(c, c)].sqrt() } else { 1.0 }).collect();
    let g = DMatrix::from_fn(m, m, |a, b| norm[a] * norm[b] * g0[(a, b)]);
    let b = DMatrix::from_fn(m, hg.len(), |a, c| norm[a] * b0[(a, c)]);
    let Ok(s) = g.svd(true, true).solve(&b, 1e-13) else { return Vec::new() };
    held.iter()
        .enumerate()
        .filter_map(|(c, &(gh, std_h))| {
            let ph = param_of(problem, gh);
            let to_h = ph.unit().to_si();
            let mut moves: Vec<(String, &'static str, f64, f64, f64)> = free
                .iter()
                .enumerate()
                .filter_map(|(a, &gf)| {
                    let per_si = -s[(a, c)] * norm[a];
                    let sd = *quality.std.get(a)?;
                    let ratio = (per_si * std_h).abs() / sd;
                    (ratio > 1.0 && ratio.is_finite()).then(|| {
                        let pf = param_of(problem, gf);
                        let to_f = pf.unit().to_si();
                        (problem.name(gf), pf.unit().as_str(), per_si * to_h / to_f, sd / to_f, ratio)
                    })
                })
                .collect();
            moves.sort_by(|x, y| y.4.total_cmp(&x.4));
            (!moves.is_empty()).then(|| Conditional {
                held: problem.name(gh),
                unit: ph.unit().as_str(),
                value: fit.x[gh] / to_h,
                std: std_h / to_h,
                moves: moves.into_iter().map(|(n, u, k, sd, _)| (n, u, k, sd)).collect(),
            })
        })
        .collect()
}

/// `v` to four significant digits, signed.
fn sig4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v:+}");
    }
    let d = (3 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{v:+.d$}")
}

/// `v` to the decimals of two significant digits of `sd`.
fn to_sd(v: f64, sd: f64) -> (String, String) {
    let d = if sd > 0.0 && sd.is_finite() { (1 - sd.log10().floor() as i32).clamp(0, 12) as usize } else { 4 };
    (format!("{v:.d$}"), format!("{sd:.d$}"))
}

/// One sentence per conditional, as the notes give it: the held value, and the largest moves.
pub(super) fn conditional_notes(c: &[Conditional]) -> Vec<String> {
    const SHOWN: usize = 4;
    c.iter()
        .map(|c| {
            let names: Vec<&str> = c.moves.iter().map(|m| m.0.as_str()).collect();
            let shown: Vec<String> = c
                .moves
                .iter()
                .take(SHOWN)
                .map(|(n, u, k, sd)| format!("{n} {} {u} (its σ {} {u})", sig4(*k), to_sd(0.0, *sd).1))
                .collect();
            let more = if c.moves.len() > SHOWN { format!(" and {} more", c.moves.len() - SHOWN) } else { String::new() };
            // The held value is exact (it is what the fit used): four decimals at least.
            let sd = to_sd(0.0, c.std).1;
            let d = sd.split('.').nth(1).map_or(0, str::len).max(4);
            let value = format!("{:.d$}", c.value);
            format!(
                "{} is held at {value} {} (the data would leave it ± {sd} {1}), and the values and σ of {} assume that value: per {1} of {0}, {}{more}; where {0} is known better, correct them by these amounts",
                c.held,
                c.unit,
                names.join(", "),
                shown.join(", "),
            )
        })
        .collect()
}

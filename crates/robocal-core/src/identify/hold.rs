//! Parameters the data do not determine are held, not fitted: an unknown payload, geometric
//! parameters whose standard deviation at the solution is beyond the undetermined bound (below),
//! and compliances.
//!
//! A geometric parameter is judged at the start by a sweep that bounds its σ from below
//! ([`super::identifiability::select_given_noise`]); two that are nearly one direction pass it one
//! by one. At the solution each free one's σ (as reported) is compared with the bound (1°, 10 mm):
//! the worst beyond it is held at its start value, the rest refitted, and the test repeated.
//!
//! A compliance c_j acts through the holding torque τ_j of its joint. When the measured poses
//! barely change τ_j (the wrist joints of an arm carrying no payload: a few N·m from the wrist's
//! own links), c_j is fitted from almost nothing: its estimate swings with the data, often with
//! the wrong sign, and its standard deviation is as large as the estimate. In range that costs
//! nothing — c_j·τ_j stays within the noise — but a pose whose τ_j lies outside the identified
//! range multiplies an estimate that means nothing. On the UR10's series D (ISO cubes, no
//! payload) a 5-fold cross-validation of the default model predicted one held-out pose 25.8 mm
//! wrong because c4 and c5 came out −0.053 ± 0.064 and +0.015 ± 0.009 deg/(N·m) in one fold;
//! holding them took its maximum to 1.24 mm and the mean from 0.344 to 0.304 mm, and on series B
//! and C (where they are 0.8–2.7 σ) left the held-out mean unchanged (0.362 → 0.363, 0.432 →
//! 0.432 mm).
//!
//! So, like an undeclared payload ([`PAYLOAD_SIGNIFICANCE`]), a compliance is kept only
//! when its difference from the nominal value (what is known without these data; 0 for the
//! presets) exceeds [`COMPLIANCE_SIGNIFICANCE`] of its own (reported, cluster-robust) standard
//! deviation. The least determined one is held at its start value, the model refitted, and the
//! test repeated, since holding one sharpens the others. Each held compliance says so in its
//! status, with the estimate and σ that decided it.
//!
//! The test is against the nominal value, not the start: a fit started from a calibrated set
//! (`identify --start`) starts every compliance at its estimate, so every change from the start
//! is 0 σ. Tested against the start, every compliance was held there, the payload alone moved
//! (to 1.41 ± 0.05 kg on an IRB 120 twin whose set had held it at 0 kg), and the refit was worse
//! than the set it started from (residual 0.429 against 0.383 mm, issue 24).

use super::fixed::FixedReason;
use super::identifiability::{Status, undetermined_bound};
use super::problem::{GlobalParam, Problem};
use super::quality::Quality;
use super::solver::{self, Fit, SolveError, SolverOptions};
use crate::kinematics::{JointTerm, Param};

/// A fitted compliance must differ from its nominal value by more than this many of its standard
/// deviations to be kept (the same rule as an undeclared payload's mass).
pub const COMPLIANCE_SIGNIFICANCE: f64 = 3.0;

/// A geometric parameter is held at the solution ([`undetermined_geometry`]) only when its
/// correlation with another free parameter reaches this: |r| ≥ 0.99, a variance inflated at least
/// fifty-fold by that near-dependence (θ5 and a5 of an SMR 0.2 mm off the flange axis: 1.000).
pub const COLLINEAR: f64 = 0.99;

/// An unknown payload's identified mass must exceed this many of its standard deviations to be
/// kept (see [`super::IdentifyOptions::identify_payload`]).
pub const PAYLOAD_SIGNIFICANCE: f64 = 3.0;

/// The fit and the statistics [`hold_undetermined`] works on.
pub(super) struct Fitted<'a> {
    pub problem: &'a Problem,
    /// The start values (a held parameter returns to its own).
    pub x0: &'a [f64],
    /// Per observation, its (first row, row count) in the residual.
    pub rows: &'a [(usize, usize)],
    /// Per observation, its pose (for the cluster-robust σ).
    pub pose_of_obs: &'a [usize],
    pub n_poses: usize,
    pub solver: &'a SolverOptions,
    /// The global index of an unknown payload's mass, when the problem identifies one.
    pub payload: Option<usize>,
    /// Hold the compliances the data do not determine too
    /// ([`super::IdentifyOptions::hold_undetermined_compliance`]).
    pub compliances: bool,
    /// The κ above which the fit is refused ([`super::IdentifyOptions::kappa_limit`]).
    pub kappa_limit: f64,
}

/// What the next round holds: (column in `free`, global index, its statistic).
enum Undetermined {
    /// An unknown payload whose mass is not above [`PAYLOAD_SIGNIFICANCE`] of its σ (one-sided:
    /// a negative mass is not determined either).
    Payload(usize, usize, f64),
    /// A geometric parameter whose standard deviation at the solution exceeds its bound
    /// ([`super::identifiability::UNDETERMINED_ANGLE_RAD`], `UNDETERMINED_LENGTH_M`).
    Geometry(usize, usize),
    /// A compliance whose difference from its nominal is below [`COMPLIANCE_SIGNIFICANCE`] of its σ.
    Compliance(usize, usize, f64),
}

/// Hold, one at a time, every free parameter the data do not determine (see the module's
/// documentation): an unknown payload first (the compliances act through it), then the
/// compliances, least determined first, refitting after each. Returns the quality (with its
/// cluster-robust σ) of the fit that stands.
///
/// A compliance's refit that fails leaves the last good fit and the compliance free: holding
/// one is a refinement, never a new way to fail. A payload's refit that fails is an error: the
/// fit with an undetermined payload cannot stand.
pub(super) fn hold_undetermined(
    f: &Fitted<'_>,
    fit: &mut Fit,
    free: &mut Vec<usize>,
    status: &mut [Status],
    shifts: &mut Vec<HoldShift>,
) -> Result<Quality, SolveError> {
    // Geometric parameters held for a near-dependence, with the compliance they were one direction
    // with; each is tried free again at most once (`release_geometry`).
    let mut held_geometry: Vec<(usize, Option<usize>)> = Vec::new();
    loop {
        let mut q = Quality::of(fit, f.problem.obs.len(), f.rows);
        q.make_robust(fit, f.rows, f.pose_of_obs, f.n_poses);
        let next = undetermined_payload(f, fit, free, &q)
            .or_else(|| undetermined_geometry(f.problem, free, &q, q.kappa_scaled > f.kappa_limit))
            .or_else(|| f.compliances.then(|| weakest_compliance(f.problem, fit, free, &q)).flatten());
        let Some(next) = next else {
            if release_geometry(f, fit, free, status, &mut held_geometry) {
                continue;
            }
            return Ok(q);
        };
        let (c, g) = match next {
            Undetermined::Payload(c, g, _) | Undetermined::Geometry(c, g) | Undetermined::Compliance(c, g, _) => (c, g),
        };
        let mut held: Vec<usize> = free.clone();
        held.remove(c);
        if held.is_empty() {
            return Ok(q);
        }
        let mut x = fit.x.clone();
        x[g] = f.x0[g];
        let refit = match (&next, solver::solve(f.problem, &held, &x, f.solver)) {
            (_, Ok(refit)) => refit,
            (Undetermined::Payload(..), Err(e)) => return Err(e),
            // The fit that stands is then judged as it is (its κ, above the limit, refuses it
            // naming the weak combination).
            (Undetermined::Geometry(..) | Undetermined::Compliance(..), Err(_)) => return Ok(q),
        };
        status[g] = Status::Fixed(match next {
            Undetermined::Payload(_, _, m) => {
                FixedReason::PayloadInsignificant { mass_kg: m, std_kg: q.std[c], sigmas: PAYLOAD_SIGNIFICANCE }
            }
            Undetermined::Geometry(..) => {
                let (bound, angle) = undetermined_bound(f.problem, g).expect("a geometric parameter");
                let partner =
                    strongest_partner(free, &q, c).map(|(k, _)| free[k]).filter(|&h| is_compliance(f.problem, h));
                held_geometry.push((g, partner));
                FixedReason::UndeterminedAtSolution {
                    name: f.problem.name(g),
                    std: q.std[c],
                    bound,
                    angle,
                    with: strongest_correlation(f.problem, free, &q, c),
                }
            }
            Undetermined::Compliance(_, _, t) => FixedReason::ComplianceInsignificant {
                name: f.problem.name(g),
                change: fit.x[g] - f.problem.nominal[g],
                std: q.std[c],
                t,
                sigmas: COMPLIANCE_SIGNIFICANCE,
                held_at: f.x0[g],
            },
        });
        if matches!(next, Undetermined::Compliance(..)) {
            shifts.push(HoldShift { held: g, before: fit.x.clone(), after: refit.x.clone() });
        }
        *fit = refit;
        *free = held;
    }
}

/// A geometric parameter held for its near-dependence on a compliance that was then held too
/// (insignificant, [`weakest_compliance`]) is determined without it: the hold's reason is gone.
/// On a FANUC's joint sweeps with no payload, θ3 was held (σ 5.8°, correlation −1.000 with c3)
/// and c3 then held at 0; every other parameter's value assumed θ3 = 0, where the same model with
/// c3 held from the start reads θ3 −0.050 ± 0.035° and fits better. The first such parameter is
/// freed and the fit redone; it stays free when its σ is then within its bound and the fit's κ
/// within the limit, else the fit before stands. Each is tried once. Returns whether one was freed.
fn release_geometry(
    f: &Fitted<'_>,
    fit: &mut Fit,
    free: &mut Vec<usize>,
    status: &mut [Status],
    held: &mut Vec<(usize, Option<usize>)>,
) -> bool {
    while let Some(k) = held.iter().position(|(_, partner)| partner.is_some_and(|h| !free.contains(&h))) {
        let (g, _) = held.remove(k);
        let mut again = free.clone();
        again.push(g);
        again.sort_unstable();
        let Ok(refit) = solver::solve(f.problem, &again, &fit.x, f.solver) else { continue };
        let mut q = Quality::of(&refit, f.problem.obs.len(), f.rows);
        q.make_robust(&refit, f.rows, f.pose_of_obs, f.n_poses);
        let c = again.iter().position(|&x| x == g).expect("pushed");
        let determined = undetermined_bound(f.problem, g).is_some_and(|(bound, _)| q.std[c] <= bound)
            && q.kappa_scaled <= f.kappa_limit;
        if determined {
            status[g] = Status::Identified;
            *fit = refit;
            *free = again;
            return true;
        }
    }
    false
}

/// What holding one compliance did to the other parameters: the solution with it free, and the
/// refit with it held ([`hold_undetermined`]).
pub(super) struct HoldShift {
    /// The held compliance's global index.
    pub held: usize,
    /// Every global parameter's value before the hold, and after its refit.
    pub before: Vec<f64>,
    pub after: Vec<f64>,
}

/// The robot parameters (not a table's knots) that a compliance's hold moved by more than their
/// final σ, as one note per hold: the σ are those of the model with the compliance held, so they
/// do not count that choice, and a reader comparing two fits that held different compliances
/// would read them as many σ apart. On the UR10's series C cut into two interleaved halves, with
/// tables on joints 1, 2, 3 and 5 (which make c2 and c3 nearly one direction), one half kept c2
/// and held c3 (2.1 σ), the other the reverse: θ2 read 4.0 σ apart, a1 3.7 σ, θ4 3.5 σ, and the
/// geometry's RMS z was 1.77. With the same compliance in both halves it was 0.80–0.95.
pub(super) fn hold_notes(problem: &Problem, free: &[usize], q: &Quality, shifts: &[HoldShift]) -> Vec<String> {
    const SHOWN: usize = 6;
    shifts
        .iter()
        .filter_map(|h| {
            let mut moved: Vec<(f64, String)> = free
                .iter()
                .enumerate()
                .filter_map(|(c, &g)| {
                    let GlobalParam::Robot(i) = problem.params[g] else { return None };
                    let p = problem.layout.params()[i];
                    if matches!(p, Param::Joint(_, JointTerm::Map { .. })) {
                        return None;
                    }
                    let (sd, shift) = (q.std[c], h.after[g] - h.before[g]);
                    let z = shift.abs() / sd;
                    let u = p.unit();
                    (z > 1.0).then(|| {
                        // Two significant digits of the σ, and the values to the same decimal: a
                        // 0.1 mm move of a 572 mm length must show.
                        let sd_u = sd / u.to_si();
                        let d = (1 - sd_u.log10().floor() as i32).clamp(0, 9) as usize;
                        let (unit, v) = (u.as_str(), |x: f64| x / u.to_si());
                        let text = format!(
                            "{p} from {:.d$} {unit} with it free to {:.d$} ± {sd_u:.d$} {unit}",
                            v(h.before[g]),
                            v(h.after[g]),
                        );
                        (z, text)
                    })
                })
                .collect();
            if moved.is_empty() {
                return None;
            }
            moved.sort_by(|a, b| b.0.total_cmp(&a.0));
            let more = moved.len().saturating_sub(SHOWN);
            let list: Vec<String> = moved.into_iter().take(SHOWN).map(|m| m.1).collect();
            let more = if more > 0 { format!(" and {more} more") } else { String::new() };
            Some(format!(
                "holding {} (see its status) moved {}{more}, each by more than its σ: those σ are the model's with {0} held and do not count that choice, so a fit that keeps it, or holds another compliance instead, reads these parameters elsewhere",
                problem.name(h.held),
                list.join(", ")
            ))
        })
        .collect()
}

/// The unknown payload, when it is free and its mass is not above [`PAYLOAD_SIGNIFICANCE`] of
/// its σ: (column, global index, mass in kg). A mass below that is one direction with the
/// compliances (c5·m, c3·m… act as products when the arm's own weight barely loads a joint), the
/// fit crawls along it and every fold lands elsewhere.
fn undetermined_payload(f: &Fitted<'_>, fit: &Fit, free: &[usize], q: &Quality) -> Option<Undetermined> {
    let g = f.payload?;
    let c = free.iter().position(|&x| x == g)?;
    let (m, sd) = (fit.x[g], q.std[c]);
    let determined = m > PAYLOAD_SIGNIFICANCE * sd; // false for a NaN σ too
    (!determined).then_some(Undetermined::Payload(c, g, m))
}

/// The free geometric parameter whose standard deviation at the solution (as reported: the larger
/// of the classic and the cluster-robust) exceeds its bound by the largest factor, with its column,
/// global index and that factor. The sweep of [`super::identifiability::select_given_noise`]
/// bounds each σ from below by the parameters kept before it; two parameters that are nearly one
/// direction only together (θ5 and a5 of a UR5 whose SMR sits 0.2 mm off the flange axis: σ 4.5°
/// and 8.6 mm, κ 20,000) pass it one by one. Holding the worst leaves the other determined
/// (there: a5 0.09 ± 0.02 mm, κ 181).
///
/// A fit whose κ is above the limit (`ill_conditioned`) would be refused; there the σ beyond
/// its bound suffices, whatever its pairwise correlations. A near-dependence of several
/// parameters leaves every pairwise correlation below [`COLLINEAR`] and still puts the fit
/// beyond the limit: a Fanuc R-2000iC's joint sweeps (a 9° sweep of joint 1; base, a1, θ2 and
/// the base tilt nearly one direction) gave base_x σ 20 mm with its strongest pairwise
/// correlation 0.9899 in one fold of five, 0.9900–0.9904 in the others, so one fold's fit was
/// refused at κ 2,662 while the rest held base_x and converged at κ 466–510.
fn undetermined_geometry(
    problem: &Problem,
    free: &[usize],
    q: &Quality,
    ill_conditioned: bool,
) -> Option<Undetermined> {
    free.iter()
        .enumerate()
        .filter_map(|(c, &g)| {
            let (bound, _) = undetermined_bound(problem, g)?;
            let ratio = q.std[c] / bound;
            // A σ that is not finite is not determined either.
            let ratio = if ratio.is_nan() { f64::INFINITY } else { ratio };
            // Only a σ that a near-dependence makes large: a residual far above the instrument's
            // (a gross reading, a wrong TCP) inflates every σ, and the fit is then refused as a
            // misfit or for its outliers, naming them — holding parameter after parameter would
            // hide that.
            let collinear = strongest_correlation(problem, free, q, c).is_some_and(|(_, r)| r.abs() >= COLLINEAR);
            (ratio > 1.0 && (collinear || ill_conditioned)).then_some((c, g, ratio))
        })
        .max_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(c, g, _)| Undetermined::Geometry(c, g))
}

/// The free parameter most correlated with column `c`, with the correlation (the one it is one
/// direction with), when there is another.
fn strongest_correlation(problem: &Problem, free: &[usize], q: &Quality, c: usize) -> Option<(String, f64)> {
    strongest_partner(free, q, c).map(|(k, r)| (problem.name(free[k]), r))
}

/// The column of the free parameter most correlated with column `c`, with the correlation.
fn strongest_partner(free: &[usize], q: &Quality, c: usize) -> Option<(usize, f64)> {
    (0..free.len())
        .filter(|&k| k != c)
        .map(|k| (k, q.correlation[(c, k)]))
        .filter(|(_, r)| r.is_finite())
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
}

/// The free compliance with the smallest |estimate − nominal|/σ below the threshold (with its
/// column, global index and ratio). A σ that is not finite counts as undetermined.
fn weakest_compliance(problem: &Problem, fit: &Fit, free: &[usize], q: &Quality) -> Option<Undetermined> {
    free.iter()
        .enumerate()
        .filter(|&(_, &g)| is_compliance(problem, g))
        .map(|(c, &g)| {
            let t = (fit.x[g] - problem.nominal[g]).abs() / q.std[c];
            (c, g, if t.is_nan() { 0.0 } else { t })
        })
        .filter(|&(_, _, t)| t < COMPLIANCE_SIGNIFICANCE)
        .min_by(|a, b| a.2.total_cmp(&b.2))
        .map(|(c, g, t)| Undetermined::Compliance(c, g, t))
}

fn is_compliance(problem: &Problem, g: usize) -> bool {
    match problem.params[g] {
        GlobalParam::Robot(i) => matches!(problem.layout.params()[i], Param::Joint(_, JointTerm::Compliance)),
        _ => false,
    }
}

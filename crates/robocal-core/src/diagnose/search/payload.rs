//! An unknown payload that the named terms determine, adopted into the final model when the
//! model refitted with it predicts held-out poses better.
//!
//! An identification holds an undeclared payload at 0 kg when its data do not determine the mass
//! (below [`PAYLOAD_SIGNIFICANCE`] of its σ), and the diagnosis keeps that decision while it
//! searches ([`super::super::unrefused`]): every candidate is judged against the calibration the
//! engineer has. But a term the model lacked leaks into the payload through the compliances, and
//! once it is named the payload can stand out of its σ. On an independent simulator's twin of a
//! 300-stop tracker run with an unknown 3 kg tool, `identify` read 2.071 ± 0.702 kg and held it;
//! with the named hysteresis the data read 2.504 ± 0.649 kg, and the model that used it
//! cross-validated at 0.229 mm against 0.240 mm with the payload held (BENCHMARKS, "Eight more
//! independent twins"). Saying so without adopting it left the diagnosis's own figures 6 % above
//! what its statement promised.
//!
//! The payload is not a new cause to name — every tool has a mass, and the question is only
//! whether these data determine it — so it is not held to the relative size a name needs
//! ([`SearchOptions::min_rel_gain`]). It is adopted when, in the model with every named term:
//! - its mass exceeds [`PAYLOAD_SIGNIFICANCE`] of its σ on the pooled data (the identification's
//!   own rule, one-sided: a negative mass is not determined either);
//! - the model refitted in full on the same folds reproduces the gain of its linearised folds, as
//!   every accepted term must ([`refit_disagrees`]): significantly better per pose, no pose
//!   predicted wildly worse, and neither the held-out mean nor the RMS worse over all the poses.
//!
//! Adopted, it becomes the last stage of the search (the shrink table's last row, the model that
//! accepting produces and that the transfer carries); not adopted, what it read and why it was not
//! is kept for the verdict.

use super::*;
use crate::identify::PAYLOAD_SIGNIFICANCE;

/// What became of a payload the set held, tried in the model with the named terms.
#[derive(Clone, Debug, PartialEq)]
pub struct PayloadTrial {
    /// The payload's mass in the model with it, fitted on the pooled data, kg.
    pub mass: f64,
    /// Its standard deviation there (the data's own scale), kg; `None` when it has none.
    pub std: Option<f64>,
    /// The model with it refitted in full on the folds against the model without it; `None` when
    /// it was not cross-validated (not determined) or a refit failed.
    pub refit: Option<Paired>,
    /// Adopted (the last stage of the search carries it), or why not.
    pub adopted: Result<(), String>,
}

/// Try the payload in the search's last model when the set held an unknown one (`held`: the set's
/// identification held an undeclared payload at 0 kg). Adopted, the model with it is appended to
/// the search's stages, baselines and refits. `None` when there is nothing to try: no effect was
/// named, the tools declare a payload, the model has no compliance for it to act through or
/// already carries it, or the last round judged a payload error partial, refuted or a look-alike
/// of another candidate (its decision stands).
pub fn adopt_payload(
    cell: &Cell,
    s: &mut Search,
    folds: &Folds,
    held: bool,
    opts: &SearchOptions,
) -> Option<PayloadTrial> {
    let stage = s.stages.last()?;
    if !held || s.accepted.is_empty() || stage.problem.robot_index(Param::ToolMass).is_some() {
        return None;
    }
    if stage.problem.tools.iter().any(|t| t.tool.mass != 0.0) {
        return None;
    }
    let compliance = stage.problem.layout.params().iter().enumerate().any(|(i, p)| {
        matches!(p, Param::Joint(_, JointTerm::Compliance)) && stage.problem.params.contains(&GlobalParam::Robot(i))
    });
    if !compliance {
        return None;
    }
    // A payload error the last round judged partial or refuted stays out. One it found not
    // separable from the compliances because the data hold a single payload is what is tried
    // here: that is about naming a cause (the payload's torques are told from the compliances'
    // only through the robot file's link masses), and the trial says it rests on those masses.
    let last = s.rounds.last()?;
    let judged = match &last.decision {
        Decision::Partial { best, .. } | Decision::Refuted { best, .. } => Some(*best),
        Decision::NotSeparable { best, lookalike: Some(_), .. } => Some(*best),
        _ => None,
    };
    if judged.is_some_and(|i| last.screened[i].candidate.kind == Kind::ToolMass) {
        return None;
    }
    let cand = Candidate::new(Kind::ToolMass, None, vec![Param::ToolMass]);
    let cols = stage.columns(&cand.params);
    let next_opts = extend_options(&stage.options, stage, &cand);
    let next = match stage.extend(cell, next_opts, &cand.params, &[], &cols, opts.map_smoothing) {
        Ok(next) => next,
        Err(e) => {
            return Some(PayloadTrial {
                mass: f64::NAN,
                std: None,
                refit: None,
                adopted: Err(format!("the model with it cannot be fitted: {e}")),
            });
        }
    };
    let g = next.problem.robot_index(Param::ToolMass)?;
    let (mass, std) = (next.x[g], next.stds_of(&[g])[0]);
    let trial = |refit: Option<Paired>, adopted: Result<(), String>| Some(PayloadTrial { mass, std, refit, adopted });
    if !std.is_some_and(|sd| mass > PAYLOAD_SIGNIFICANCE * sd) {
        let read = std.map_or(format!("{mass:.3} kg, no σ"), |sd| format!("{mass:.3} ± {sd:.3} kg"));
        return trial(
            None,
            Err(format!(
                "in the anchored fit of the final model it is not determined ({read}, below {PAYLOAD_SIGNIFICANCE} σ)"
            )),
        );
    }
    let before = match s.refits.last() {
        Some(Ok(before)) => before,
        _ => return trial(None, Err("the model without it could not be refitted on the folds".into())),
    };
    let after = match refit_heldout(cell, &next, folds, opts.threads) {
        Ok(after) => after,
        Err(e) => return trial(None, Err(format!("the model with it cannot be refitted on the folds: {e}"))),
    };
    let refit = paired(before, &after);
    if !(refit.p.is_some_and(|p| p < opts.confirm_p) && refit.gain_rms_core > opts.min_gain) {
        let why = format!(
            "the model refitted with it on the same folds does not predict held-out poses significantly better (the RMS of the bulk of the poses changes by {:+.4} mm, p = {:.1e})",
            -refit.gain_rms_core * 1e3,
            refit.p.unwrap_or(f64::NAN)
        );
        return trial(Some(refit), Err(why));
    }
    let linearised = cross_validate(&next, folds, None);
    let linear = paired(s.baselines.last().expect("a baseline"), &linearised);
    if let Some(reason) = refit_disagrees(&linear, &refit, opts) {
        return trial(Some(refit), Err(reason));
    }
    s.stages.push(next);
    s.baselines.push(linearised);
    s.refits.push(Ok(after));
    trial(Some(refit), Ok(()))
}

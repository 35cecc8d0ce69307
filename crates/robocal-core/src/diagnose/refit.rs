//! One model, one figure (DIAGNOSIS §7): the held-out errors of a model refitted in full — the
//! nonlinear identification that the diagnosis reports and that accepting it produces — on each
//! fold's training measurements, predicting that fold's tested measurements.
//!
//! The search screens and confirms candidates on linearised folds ([`super::cv`]): one
//! Gauss–Newton step from the pooled solution, exact to second order for small effects and
//! fast enough for hundreds of candidates. A linearisation can be wrong — a large step, a
//! parameter that runs away, a branch change, a fit that lands elsewhere — and then a gain
//! confirmed on it is not a gain of the model that is reported. So every model the search
//! accepts is refitted here on the same folds, and its figures are the ones the shrink table
//! shows; an acceptance the refit does not reproduce is withdrawn.
//!
//! Each fold's refit starts from the stage's solution (base, geometry, every identified TCP), is
//! the stage's own model and options (its anchors, its weights), and leaves out the fold's
//! tested measurements; the prediction of a tested measurement uses the refit's parameters and
//! the TCP it identified for that measurement's target.

use nalgebra::Vector3;

use super::cv::{Folds, Heldout, Paired};
use super::search::SearchOptions;
use super::stage::Stage;
use crate::cell::Cell;
use crate::identify::crossval::with_identified_tools;
use crate::identify::{GlobalParam, identify};
use crate::kinematics::Param;
use crate::validate::report::{Reference, validate};

/// The cell a refit of `stage` starts from: the stage's base as the base guess, and every TCP the
/// stage identified as its session's declared TCP (still identified).
fn start_cell(work: &Cell, stage: &Stage) -> Cell {
    let pr = &stage.problem;
    let mut cell = work.clone();
    cell.base_guess = Some(stage.set.pose_of(Param::Base));
    for (t, block) in pr.tools.iter().enumerate() {
        if !block.identify_tcp {
            continue;
        }
        let Some(off) = pr.params.iter().position(|p| *p == GlobalParam::Tool { tool: t, k: 0 }) else { continue };
        let mut tcp = [0.0; 6];
        tcp.copy_from_slice(&stage.x[off..off + 6]);
        for s in cell.sessions.iter_mut().filter(|s| block.sessions.contains(&s.name)) {
            s.tool.tcp = tcp;
        }
    }
    cell
}

/// Held-out errors of the stage's model refitted in full on each fold (threads: folds run on up
/// to this many scoped threads; the result does not depend on it). `Err` names the fold whose
/// refit failed and why.
pub(crate) fn refit_heldout(work: &Cell, stage: &Stage, folds: &Folds, threads: usize) -> Result<Heldout, String> {
    let pr = &stage.problem;
    let cell = start_cell(work, stage);
    let fold_ids: Vec<usize> = (0..folds.k).collect();
    let one = |&f: &usize| -> Result<Vec<(usize, Vector3<f64>)>, String> {
        let test: Vec<usize> = (0..pr.obs.len()).filter(|&o| folds.fold_of_obs[o] == Some(f)).collect();
        if test.is_empty() {
            return Ok(Vec::new());
        }
        let mut o = stage.options.clone();
        o.start = Some(stage.set.clone());
        // A fold predicts; its conditioning is the stage's, reported with it. A fold with a fifth
        // of the tested poses out may pass the limit that the pooled fit met (a thermal term next
        // to d1 and the base height) — refusing it would withdraw a model that predicts.
        o.kappa_limit = f64::INFINITY;
        o.selection.subset.clear();
        o.selection
            .exclude
            .extend(test.iter().map(|&i| (pr.session_names[pr.obs[i].session].clone(), pr.obs[i].index)));
        let id = identify(&cell, &o).map_err(|e| format!("fold {}: {e}", f + 1))?;
        let mut scored = cell.clone();
        with_identified_tools(&mut scored, &cell, &id);
        // Every session with a tested measurement, scored whole (a few thousand positions) and
        // the tested ones picked out.
        let mut sessions: Vec<String> = test.iter().map(|&i| pr.session_names[pr.obs[i].session].clone()).collect();
        sessions.sort();
        sessions.dedup();
        let report =
            validate(&id.set, &scored, &sessions, Reference::Measured).map_err(|e| format!("fold {}: {e}", f + 1))?;
        let at: std::collections::HashMap<(&str, usize), Vector3<f64>> =
            report.residuals.iter().map(|r| ((r.session.as_str(), r.index), r.error)).collect();
        test.iter()
            .map(|&i| {
                let key = (pr.session_names[pr.obs[i].session].as_str(), pr.obs[i].index);
                at.get(&key)
                    .map(|e| (i, *e))
                    .ok_or_else(|| format!("fold {}: measurement {}[{}] not scored", f + 1, key.0, key.1))
            })
            .collect()
    };
    let per_fold = super::search::par_map(&fold_ids, threads, one);
    let mut errors = Vec::new();
    for r in per_fold {
        errors.extend(r?);
    }
    errors.sort_by_key(|(o, _)| *o);
    let mut pose_sq = vec![0.0; folds.n_poses];
    for (o, e) in &errors {
        if let Some(p) = folds.pose_of_obs[*o] {
            pose_sq[p] += e.norm_squared();
        }
    }
    Ok(Heldout { errors, pose_sq })
}

/// Whether the model refitted in full on the folds reproduces a gain confirmed on the linearised
/// folds ([`refit_disagrees`] says why not).
#[cfg(test)]
pub(crate) fn refit_confirms(linear: &Paired, refit: &Paired, opts: &SearchOptions) -> bool {
    refit_disagrees(linear, refit, opts).is_none()
}

/// A refitted pose this many times worse than the worst pose of the model before it (and worse by
/// more than [`BLOWN_MIN`]) is a model that extrapolates wildly, whatever its other poses gain.
pub const BLOWN_RATIO: f64 = 3.0;
/// See [`BLOWN_RATIO`], m.
pub const BLOWN_MIN: f64 = 0.5e-3;

/// Why the model refitted in full on the folds does not reproduce a gain confirmed on the
/// linearised folds, or `None` when it does:
/// - H0 "it does not lower a pose's held-out squared error" is not rejected by the one-sided
///   Wilcoxon at `confirm_p`;
/// - its gain is below `min_gain`, or below half the linearised one (a second-order difference is
///   a few per cent; a linearisation that was wrong predicts gains the model does not have). Both
///   gains are the bulk's ([`Paired::gain_rms_core`]): one pose predicted centimetres wrong by
///   either model must not decide (it would make any gain, or none, on its own);
/// - it predicts a pose [`BLOWN_RATIO`] times worse than the worst of the model before it: a
///   model that is reported must not hide such a pose behind a better bulk;
/// - over all the poses, its held-out RMS or mean error is larger than the model's before it: a
///   term whose own row in the shrink table reads worse is not confirmed, whatever its bulk gains
///   (one pose predicted 0.2 mm worse can outweigh a bulk gain of a few micrometres).
pub fn refit_disagrees(linear: &Paired, refit: &Paired, opts: &SearchOptions) -> Option<String> {
    let mm = |x: f64| format!("{:+.4} mm", x * 1e3);
    let (before, after) = refit.worst;
    if after > BLOWN_RATIO * before && after - before > BLOWN_MIN {
        return Some(format!(
            "the model refitted in full on the same folds predicts a held-out pose {:.3} mm wrong, where the worst of the model before it was {:.3} mm",
            after * 1e3,
            before * 1e3
        ));
    }
    if refit.gain_rms < 0.0 || refit.gain_mean < 0.0 {
        return Some(format!(
            "the model refitted in full on the same folds gains {} on the bulk of the poses but makes the held-out error over all of them worse (RMS {}, mean {}; worst pose {:.3} → {:.3} mm)",
            mm(refit.gain_rms_core),
            mm(-refit.gain_rms),
            mm(-refit.gain_mean),
            before * 1e3,
            after * 1e3
        ));
    }
    let significant = refit.p.is_some_and(|p| p < opts.confirm_p);
    let g = refit.gain_rms_core;
    if significant && g > opts.min_gain && g >= 0.5 * linear.gain_rms_core {
        return None;
    }
    Some(format!(
        "confirmed on linearised folds (held-out RMS {}) but the model refitted in full on the same folds gives {}{}",
        mm(-linear.gain_rms_core),
        mm(-g),
        refit.p.map_or(String::new(), |p| format!(" (p = {p:.2e})"))
    ))
}

#[cfg(test)]
mod tests {
    use super::super::cv::paired;
    use super::*;

    fn paired_of(p: Option<f64>, gain_rms: f64) -> Paired {
        Paired { p, gain_rms, gain_mean: gain_rms, gain_rms_core: gain_rms, worst: (1e-3, 1e-3) }
    }

    /// Held-out errors of one observation per pose, of the given sizes (m), along x.
    fn heldout(sizes: &[f64]) -> super::super::cv::Heldout {
        super::super::cv::Heldout {
            errors: sizes.iter().enumerate().map(|(i, &e)| (i, nalgebra::Vector3::new(e, 0.0, 0.0))).collect(),
            pose_sq: sizes.iter().map(|e| e * e).collect(),
        }
    }

    /// One pose predicted centimetres wrong decides neither way: a refit whose bulk gains 0.1 mm
    /// but predicts one pose 25 mm wrong is refused for that pose (the reason names it); a refit
    /// that repairs a blown-up pose of the model before it but gains nothing on the bulk is
    /// refused although its RMS gain is large; the same refit without the blown-up pose passes.
    #[test]
    fn one_blown_up_pose_does_not_decide_the_refit_check() {
        let o = SearchOptions::default();
        let n = 200;
        let base: Vec<f64> = (0..n).map(|i| 0.3e-3 + 1e-6 * (i % 7) as f64).collect();
        let good: Vec<f64> = base.iter().map(|e| e - 0.1e-3).collect();
        let linear = paired(&heldout(&base), &heldout(&good));
        assert!((linear.gain_rms_core - 0.1e-3).abs() < 2e-6, "{linear:?}");
        assert!(refit_confirms(&linear, &linear, &o));

        let mut blown = good.clone();
        blown[17] = 25e-3;
        let r = paired(&heldout(&base), &heldout(&blown));
        assert!(r.gain_rms < 0.0, "one pose makes the RMS gain negative: {r:?}");
        assert!((r.gain_rms_core - 0.1e-3).abs() < 2e-6, "the bulk still gains 0.1 mm: {r:?}");
        let why = refit_disagrees(&linear, &r, &o).expect("refused");
        assert!(why.contains("25.000 mm wrong"), "{why}");

        let mut base_blown = base.clone();
        base_blown[17] = 25e-3;
        let mut repaired = base.clone();
        repaired[17] = 0.3e-3;
        let r = paired(&heldout(&base_blown), &heldout(&repaired));
        assert!(r.gain_rms > 1e-3, "the RMS gain is large: {r:?}");
        assert!(r.gain_rms_core.abs() < 1e-9, "the bulk gains nothing: {r:?}");
        assert!(!refit_confirms(&linear, &r, &o));
    }

    /// A term whose bulk gains but whose own row would read worse over all the poses is not
    /// confirmed (the UR10's series B, first 100 readings: joint table j3 gained 7.6 µm in mean
    /// and lost 1.7 µm in RMS, one pose 0.560 → 0.771 mm, below the blow-up rule's 3×). With 100
    /// poses the bulk leaves out the one worst; the same refit without that pose's loss passes.
    #[test]
    fn a_term_that_makes_the_whole_held_out_rms_worse_is_not_confirmed() {
        let o = SearchOptions::default();
        let n = 100;
        let base: Vec<f64> = (0..n).map(|i| 0.15e-3 + 1e-6 * (i % 11) as f64).collect();
        let mut after: Vec<f64> = base.iter().map(|e| e - 8e-6).collect();
        let linear = paired(&heldout(&base), &heldout(&after));
        assert!(refit_confirms(&linear, &linear, &o), "{linear:?}");
        let mut base_worse = base.clone();
        base_worse[40] = 0.560e-3;
        after[40] = 0.771e-3;
        let r = paired(&heldout(&base_worse), &heldout(&after));
        assert!(r.gain_rms < 0.0 && r.gain_rms_core > 7e-6, "{r:?}");
        assert!(r.worst.1 < BLOWN_RATIO * r.worst.0, "not a blow-up: {r:?}");
        let why = refit_disagrees(&linear, &r, &o).expect("refused");
        assert!(why.contains("worse") && why.contains("0.560 → 0.771 mm"), "{why}");
        after[40] = 0.552e-3;
        let r = paired(&heldout(&base_worse), &heldout(&after));
        assert!(r.gain_rms > 0.0, "{r:?}");
        assert!(refit_confirms(&linear, &r, &o), "{r:?}");
    }

    /// The refit check of issue 24: a linearised gain of 33 µm is withdrawn when the refitted
    /// model loses 7 mm (the IRB 120 data set's backlash j1), gains a third of it, or gains
    /// without significance or below the resolution; a refit within second-order terms keeps it.
    #[test]
    fn a_refit_must_reproduce_the_linearised_gain() {
        let o = SearchOptions::default();
        let linear = paired_of(Some(1e-6), 33e-6);
        assert!(refit_confirms(&linear, &paired_of(Some(1e-5), 31e-6), &o));
        assert!(refit_confirms(&linear, &paired_of(Some(1e-5), 40e-6), &o));
        assert!(!refit_confirms(&linear, &paired_of(Some(1e-9), -6.99e-3), &o));
        assert!(!refit_confirms(&linear, &paired_of(Some(1e-5), 11e-6), &o));
        assert!(!refit_confirms(&linear, &paired_of(Some(0.2), 31e-6), &o));
        assert!(!refit_confirms(&linear, &paired_of(None, 31e-6), &o));
        let tiny = paired_of(Some(1e-6), 0.6e-6);
        assert!(!refit_confirms(&tiny, &paired_of(Some(1e-6), 0.4e-6), &o));
    }
}

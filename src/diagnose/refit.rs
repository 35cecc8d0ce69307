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

use super::cv::{Folds, Heldout};
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
pub fn refit_heldout(work: &Cell, stage: &Stage, folds: &Folds, threads: usize) -> Result<Heldout, String> {
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
        with_identified_tools(&mut scored, &id);
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

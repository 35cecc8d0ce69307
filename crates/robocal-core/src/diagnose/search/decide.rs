//! The decision of a round of the search on its confirmed candidates: the best (the simplest among
//! the nearly best), and whether it is named, partial, unknown or not separable — against the
//! smoother, a payload, what the model absorbs and its look-alikes.

use super::*;

/// The smoother of a round: its columns and ridge, its held-out figures and their comparison with
/// the model, and whether it predicts significantly better.
pub(super) struct Smoother<'a> {
    pub(super) cols: &'a Mat<f64>,
    pub(super) pen: &'a Mat<f64>,
    pub(super) heldout: &'a Heldout,
    pub(super) vs_model: &'a Paired,
    pub(super) ok: bool,
}

/// What the round decides about its best confirmed candidate, with the figures it rests on.
pub(super) struct Decided {
    pub(super) decision: Decision,
    pub(super) smoother_vs_best: Paired,
    pub(super) share: (f64, bool),
    pub(super) closure: f64,
}

/// The decision on a round whose held-out check confirmed some candidates: the best (the simplest
/// among the nearly best), named only when it stands apart from the smoother, from a payload it
/// cannot be told from, from what the model absorbs and from its look-alikes.
#[allow(clippy::too_many_arguments)]
pub(super) fn decide(
    stage: &Stage,
    base: &Heldout,
    floor_ms: f64,
    cvb: &CvBase<'_>,
    confirmed: &[&Evaluated],
    screened: &[Screened],
    columns: &[(Mat<f64>, Option<Mat<f64>>)],
    sm: &Smoother<'_>,
    opts: &SearchOptions,
) -> Decided {
    let best = choose(confirmed, screened, opts);
    let sb = paired(&best.heldout, sm.heldout);
    // The candidate's share of what a smooth function of the configuration explains beyond
    // the model (on the same folds). Only a candidate inside the smoother's span (given the
    // smoother it adds nothing: encompassing test at `confirm_p`) can be a partial
    // explanation of a structure that lies outside the library; one outside the span (a
    // backlash, a thermal term) is an effect of its own whatever the smoother also finds.
    let within = {
        let rp = Basis::project(stage.q.as_ref(), &stage.r);
        encompassing(stage, &rp, &unabsorbed(stage, sm.cols), &columns[best.index].0) > opts.confirm_p.log10()
    };
    let (bc, bp) = &columns[best.index];
    let joint_cols = hcat(bc, sm.cols);
    let joint_pen = block_diag(bp.as_ref(), bc.ncols(), Some(sm.pen), sm.cols.ncols());
    let joint = cvb.heldout(Some((&joint_cols, Some(&joint_pen))));
    let gain = |h: &Heldout| rms2(base) - rms2(h);
    let explainable = gain(&best.heldout).max(gain(&joint)).max(gain(sm.heldout));
    let share = if explainable > 0.0 { (gain(&best.heldout) / explainable).clamp(0.0, 1.0) } else { 1.0 };
    // A name inside the smoother's span must close most of the gap to the floor, and the
    // smoother must not predict significantly better: otherwise it is one of the smooth
    // function's forms taking a share of something else — a partial explanation, or, for a
    // sliver, none.
    let rms = |h: &Heldout| rms2(h).sqrt();
    let closure = {
        let gap = rms(base) - floor_ms.sqrt();
        if gap > 0.0 { (rms(base) - rms(&best.heldout)) / gap } else { 1.0 }
    };
    let smoother_better = sm.ok
        && sb.p.is_some_and(|p| p < opts.confirm_p)
        && sb.gain_rms > opts.min_gain.max(0.05 * best.vs_model.gain_rms);
    // The smoother is the reference of "what a smooth function explains" only where these poses
    // can estimate it. Where it predicts held-out poses worse than the model, and adds error to
    // the candidate inside its own span, its 3n² terms are beyond the data (60 poses in six
    // single-joint sweeps of a FANUC: −0.119 mm, and the candidate's 0.169 mm "100 % of what a
    // smooth function explains"): no share of it, and no "the rest changes from pose to pose".
    let smoother_unestimable = within
        && !smoother_better
        && closure < opts.name_closure
        && sm.vs_model.gain_rms <= 0.0
        && paired(base, &joint).gain_rms < best.vs_model.gain_rms;
    let decision = if smoother_unestimable {
        Decision::NotSeparable {
            best: best.index,
            lookalike: None,
            canonical: None,
            reason: format!(
                "it closes {:.0} % of the gap to the floor (held-out RMS gain {:.4} mm), and a smooth function of the configuration cannot be estimated from these poses (it predicts held-out poses worse than the model, held-out RMS gain {:.4} mm, and worse than this term beside it): nothing here tells this term from a look-alike of an effect outside the library, or says whether the rest is smooth",
                100.0 * closure.max(0.0),
                best.vs_model.gain_rms / crate::units::MM,
                sm.vs_model.gain_rms / crate::units::MM,
            ),
        }
    } else if within && (smoother_better || closure < opts.name_closure) && share < opts.partial_share {
        Decision::Unknown { best: Some(best.index) }
    } else if within && (smoother_better || closure < opts.name_closure) {
        let sg = sm.vs_model.gain_rms.max(paired(base, &joint).gain_rms);
        Decision::Partial {
            best: best.index,
            share,
            smoother_gain_rms: sg,
            closure_only: (!smoother_better).then_some(closure),
        }
    } else if screened[best.index].candidate.kind == Kind::ToolMass && payloads(stage) < 2 {
        // A payload error acts through the compliances: with one payload it changes every
        // holding torque in proportion to what the compliances already scale, and what is
        // left to tell them apart is the nominal link masses' share of the torques — a detail
        // of the model, not of the data. It takes a second payload to separate them.
        Decision::NotSeparable {
            best: best.index,
            lookalike: None,
            canonical: None,
            reason: "with a single payload in the data, a payload error and the joint compliances are look-alikes"
                .into(),
        }
    } else if screened[best.index].score.rho < opts.rho_min && best.vs_model.gain_rms < 0.25 * floor_ms.sqrt() {
        // Mostly absorbed, and what is left to tell it by is a signature smaller than the
        // noise at a pose: the name would rest on details of the model (the nominal masses
        // behind the holding torques, say) that a look-alike could reproduce. A large effect
        // with a small ρ (a cubic compliance next to the linear one) is still named: its
        // unabsorbed part alone stands far above the floor.
        Decision::NotSeparable {
            best: best.index,
            lookalike: None,
            canonical: None,
            reason: "absorbed by the current model".into(),
        }
    } else {
        match lookalike(best, confirmed, screened, columns, stage, opts) {
            Some((other, corr, beyond)) => Decision::NotSeparable {
                best: best.index,
                lookalike: Some(other),
                canonical: Some(corr),
                reason: format!(
                    "given {}, {} adds nothing these data can show (p = {:.2e})",
                    screened[other].candidate.label(),
                    screened[best.index].candidate.label(),
                    10f64.powf(beyond)
                ),
            },
            None => Decision::Accept(best.index),
        }
    };
    Decided { decision, smoother_vs_best: sb, share: (share, within), closure }
}

/// Nested forms of one effect: a compliance inside the group; a cyclic term and the same
/// joint's table or another frequency of it.
fn nested(a: &Candidate, b: &Candidate) -> bool {
    match (a.kind, b.kind) {
        (Kind::Compliance, Kind::Compliance) | (Kind::Backlash, Kind::Backlash) => {
            a.joint.is_none() || b.joint.is_none() || a.joint == b.joint
        }
        (x, y) if x.is_transmission() && y.is_transmission() => a.joint == b.joint,
        _ => a.same_effect(b),
    }
}

/// Parameters of a candidate, for parsimony (a table's effective size is its knot count).
fn size(c: &Candidate) -> usize {
    c.params.len().max(c.frees.len())
}

/// The best confirmed candidate: lowest held-out squared error, then the simplest of its nested
/// forms unless the richer one predicts significantly better.
fn choose<'e>(confirmed: &[&'e Evaluated], screened: &[Screened], opts: &SearchOptions) -> &'e Evaluated {
    let mut best = *confirmed.iter().min_by(|a, b| a.heldout.mse().total_cmp(&b.heldout.mse())).expect("non-empty");
    loop {
        let simpler = confirmed
            .iter()
            .filter(|e| {
                let (c, b) = (&screened[e.index].candidate, &screened[best.index].candidate);
                e.index != best.index && nested(c, b) && size(c) < size(b)
            })
            .find(|e| {
                let richer_better = paired(&e.heldout, &best.heldout);
                !richer_better.p.is_some_and(|p| p < opts.confirm_p)
            });
        match simpler {
            Some(s) => best = s,
            None => return best,
        }
    }
}

/// The look-alike check: a confirmed candidate of another effect (not a nested form of the best)
/// whose unabsorbed columns are nearly collinear with the best's, or that predicts nearly as
/// well, is tested against the best both ways by encompassing score tests:
/// - H0: "given the alternative, the best adds nothing" (F form, on the residual of the model
///   plus the alternative); if it is not rejected at `confirm_p`, these data cannot tell the
///   best from the alternative → `not_separable`.
///
/// Returns the look-alike, the canonical correlation and log10 p of the best beyond it.
fn lookalike(
    best: &Evaluated,
    confirmed: &[&Evaluated],
    screened: &[Screened],
    columns: &[(Mat<f64>, Option<Mat<f64>>)],
    stage: &Stage,
    opts: &SearchOptions,
) -> Option<(usize, f64, f64)> {
    let bc = &screened[best.index].candidate;
    let tb = unabsorbed(stage, &columns[best.index].0);
    let rp = Basis::project(stage.q.as_ref(), &stage.r);
    for e in confirmed {
        let c = &screened[e.index].candidate;
        if e.index == best.index || nested(c, bc) {
            continue;
        }
        let ta = unabsorbed(stage, &columns[e.index].0);
        let corr = canonical_correlation(tb.as_ref(), ta.as_ref());
        let close = e.vs_model.gain_rms >= super::LOOKALIKE_GAIN_SHARE * best.vs_model.gain_rms;
        if corr <= opts.lookalike_corr && !close {
            continue;
        }
        let beyond = encompassing(stage, &rp, &ta, &columns[best.index].0);
        if beyond > opts.confirm_p.log10() || corr > 0.999_999 {
            return Some((e.index, corr, beyond));
        }
    }
    None
}

/// log10 p of the score test of `cols` on the model plus the (unabsorbed) columns `alt`.
fn encompassing(stage: &Stage, rp: &[f64], alt: &Mat<f64>, cols: &Mat<f64>) -> f64 {
    let ua = orthonormal_basis(alt.as_ref(), 1e-9);
    let k = ua.ncols();
    let q = hcat(&stage.q, &ua);
    let r = Basis::project(ua.as_ref(), rp);
    let rss = r[..stage.n_obs_rows()].iter().map(|v| v * v).sum();
    let basis = Basis { q: q.as_ref(), r: &r, rss, n: stage.n_obs_rows(), p: stage.p() + k };
    score(&basis, cols.as_ref(), None).log10_p
}

/// The part of a candidate's columns the model cannot absorb, (I − QQᵀ)·J_k.
fn unabsorbed(stage: &Stage, c: &Mat<f64>) -> Mat<f64> {
    let a = at_b(stage.q.as_ref(), c.as_ref());
    let proj = crate::diagnose::linalg::a_b(stage.q.as_ref(), a.as_ref());
    Mat::<f64>::from_fn(c.nrows(), c.ncols(), |r, k| c[(r, k)] - proj[(r, k)])
}

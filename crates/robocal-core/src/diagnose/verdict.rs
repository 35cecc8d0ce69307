//! The verdict from the rounds of the search: what was named (each with its estimate and the
//! held-out figures of the refitted models), or why nothing was — and the experiment that would
//! tell.

use super::library::{Candidate, Kind};
use super::search::{self, Decision};
use super::{Decomposition, Effect, ParamEstimate, Status, Verdict};
use crate::kinematics::{Param, Unit};
use crate::validate::stats::ErrorStats;

/// The experiment that separates two kinds of effect (DIAGNOSIS §1).
pub fn experiment(a: Kind, b: Option<Kind>) -> String {
    use Kind::*;
    let pair = |x: Kind, y: Kind| (a == x && b == Some(y)) || (a == y && b == Some(x));
    if pair(Compliance, ToolMass) || pair(ComplianceCubic, ToolMass) || (a == ToolMass && b.is_none()) {
        "measure with a second payload (add a known mass to the tool)".into()
    } else if a == Thermal || b == Some(Thermal) {
        "a temperature ramp, or the same poses measured cold and warm".into()
    } else if a == Backlash || b == Some(Backlash) {
        "the same poses approached from both sides of every joint".into()
    } else if a.is_transmission() && b.is_some_and(|k| k.is_transmission()) {
        "a sweep of the joint in fine steps (a few tenths of a degree) over its range".into()
    } else if a == Base || b == Some(Base) || a == HayatiBeta || b == Some(HayatiBeta) {
        "more balls and more orientations: calibration poses spread over the workspace".into()
    } else if matches!(a, Compliance | ComplianceCubic) || b.is_some_and(|k| matches!(k, Compliance | ComplianceCubic))
    {
        "a second payload, and poses that vary the holding torque of the suspect joint".into()
    } else {
        "poses spread over the whole range of the joints involved, and more of them".into()
    }
}

pub(super) fn effect_of(s: &search::Search, round: usize, index: usize, stage_after: Option<usize>) -> Effect {
    let r = &s.rounds[round];
    let sc = &r.screened[index];
    let ev = r.evaluated.iter().find(|e| e.index == index);
    let c = sc.candidate.clone();
    // Parameter values: from the model that carries the effect when accepted, else the screening's
    // linear estimate.
    let mut parameters = Vec::new();
    match stage_after.map(|k| &s.stages[k]) {
        Some(st) => {
            let pr = &st.problem;
            let found: Vec<(Param, usize)> =
                c.params.iter().filter_map(|p| pr.robot_index(*p).map(|g| (*p, g))).collect();
            let stds = st.stds_of(&found.iter().map(|f| f.1).collect::<Vec<_>>());
            for ((p, g), std) in found.into_iter().zip(stds) {
                parameters.push(ParamEstimate { param: p, value: st.x[g], std });
            }
        }
        None => {
            for (p, v) in c.params.iter().zip(&sc.score.estimate) {
                parameters.push(ParamEstimate { param: *p, value: *v, std: None });
            }
        }
    }
    let (estimate, std, unit) = magnitude(&c, &parameters);
    // An accepted effect's gain is the refitted model's (what is reported and accepted); a
    // suspect's, the linearised confirmation's.
    let gain = match (stage_after, &r.refit) {
        (Some(_), Some(refit)) => Some(refit),
        _ => ev.map(|e| &e.vs_model),
    };
    Effect {
        estimate,
        std,
        unit,
        parameters,
        gain_mean: gain.map_or(0.0, |g| g.gain_mean),
        gain_rms: gain.map_or(0.0, |g| g.gain_rms),
        confirm_p: gain.and_then(|g| g.p),
        screen_log10_p: sc.log10_p_holm,
        separability: sc.score.rho,
        candidate: c,
    }
}

/// The size of an effect in one number: the amplitude of a cyclic pair, the RMS of a table, the
/// value of a one-parameter effect, the largest (in σ) of a group.
fn magnitude(c: &Candidate, p: &[ParamEstimate]) -> (Option<f64>, Option<f64>, Unit) {
    let unit = p.first().map_or(Unit::Mm, |e| e.param.unit());
    match c.kind {
        Kind::Cyclic if p.len() == 2 => {
            let (a, b) = (p[0].value, p[1].value);
            let amp = a.hypot(b);
            let std = match (p[0].std, p[1].std) {
                (Some(sa), Some(sb)) if amp > 0.0 => Some(((a * sa).powi(2) + (b * sb).powi(2)).sqrt() / amp),
                _ => None,
            };
            (Some(amp), std, unit)
        }
        Kind::JointMap if !p.is_empty() => {
            let rms = (p.iter().map(|e| e.value * e.value).sum::<f64>() / p.len() as f64).sqrt();
            (Some(rms), None, unit)
        }
        _ if p.len() == 1 => (Some(p[0].value), p[0].std, unit),
        _ => {
            let best = p.iter().max_by(|a, b| {
                let z = |e: &ParamEstimate| e.std.map_or(0.0, |s| (e.value / s).abs());
                z(a).total_cmp(&z(b))
            });
            (best.map(|e| e.value), best.and_then(|e| e.std), best.map_or(unit, |e| e.param.unit()))
        }
    }
}

/// A number in four significant digits, without an exponent where it reads as plain decimals.
fn num(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if (1e-3..1e5).contains(&a) {
        let digits = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
        format!("{v:.digits$}")
    } else {
        format!("{v:.3e}")
    }
}

/// A value (SI) in its file unit, with its σ when known: `0.01956 ± 7.613e-4 deg`.
pub(super) fn with_sd(v: f64, sd: Option<f64>, unit: Unit) -> String {
    match sd {
        Some(sd) => format!("{} ± {} {}", num(v / unit.to_si()), num(sd / unit.to_si()), unit.as_str()),
        None => format!("{} {}", num(v / unit.to_si()), unit.as_str()),
    }
}

/// A held-out RMS this many times the floor's, and this much above it (m), is an excess that a
/// `none` would hide.
const EXCESS_RATIO: f64 = 2.0;
const EXCESS_MIN: f64 = 10e-6;

/// What the last round of the search found, or why it named nothing.
struct Finding {
    status: Status,
    summary: String,
    lookalike: Option<Candidate>,
    canonical_correlation: Option<f64>,
    absorbed_by: Vec<(String, f64)>,
    experiment: Option<String>,
    /// The effects it suspects without naming them.
    suspects: Vec<Effect>,
}

impl Finding {
    fn new(status: Status, summary: String) -> Finding {
        Finding {
            status,
            summary,
            lookalike: None,
            canonical_correlation: None,
            absorbed_by: Vec::new(),
            experiment: None,
            suspects: Vec::new(),
        }
    }
}

/// The verdict from the rounds of the search: the effects named (with the last round's finding
/// as what remains), or the last round's finding when none was.
pub(super) fn verdict(s: &search::Search, d: &Decomposition) -> Verdict {
    let mut effects = Vec::new();
    for (k, round) in s.rounds.iter().enumerate() {
        if let Decision::Accept(i) = round.decision {
            effects.push(effect_of(s, k, i, Some(k + 1)));
        }
    }
    let f = last_finding(s, d);
    if effects.is_empty() {
        return Verdict {
            status: f.status,
            effects: f.suspects,
            summary: f.summary,
            lookalike: f.lookalike,
            canonical_correlation: f.canonical_correlation,
            absorbed_by: f.absorbed_by,
            experiment: f.experiment,
            remaining: None,
        };
    }
    Verdict {
        status: Status::Named,
        summary: format!(
            "{} named and confirmed on held-out poses by the refitted model{}",
            named(s, d, &effects),
            payload_change(s)
        ),
        effects,
        lookalike: None,
        canonical_correlation: None,
        absorbed_by: Vec::new(),
        experiment: None,
        remaining: (f.status != Status::None).then_some((f.status, f.summary)),
    }
}

/// When the named terms move an identified payload by more than its σ: a clause saying so (""
/// otherwise; a payload the starting model held is `held_payload_with_named`'s, in the module
/// above). A term the model lacked (a coupling, a
/// hysteresis) leaks into the payload through the compliances; on a twin with an unmodelled
/// coupling 2→3 the default model read 0.41 ± 0.11 kg for a 2.84 kg plate, and the model with the
/// named terms 2.73 ± 0.20 kg.
pub(super) fn payload_change(s: &search::Search) -> String {
    let (Some(first), Some(last)) = (s.stages.first(), s.stages.last().filter(|_| s.stages.len() > 1)) else {
        return String::new();
    };
    // A payload in the starting model is free in every stage (the diagnosis keeps the set's
    // decision), so both σ exist.
    let mass = |st: &super::stage::Stage| {
        let g = st.problem.robot_index(Param::ToolMass)?;
        Some((st.x[g], st.stds_of(&[g])[0]?))
    };
    let (Some((before, sd_before)), Some((after, sd_after))) = (mass(first), mass(last)) else {
        return String::new();
    };
    if (after - before).abs() <= sd_before.max(sd_after) {
        return String::new();
    }
    format!(
        "; with the named terms the payload reads {after:.3} ± {sd_after:.3} kg (the model without them: {before:.3} ± {sd_before:.3} kg; σ with the tool's centre of mass and the robot file's link masses taken as exact; identify with them to use it)"
    )
}

fn mm(x: f64) -> String {
    format!("{:.4} mm", x * 1e3)
}

/// Candidates these data cannot test, as a clause for a summary ("" when there are none).
fn untestable(s: &search::Search) -> String {
    let missing: Vec<String> = s.unavailable.iter().map(|u| format!("{} ({})", u.kind.name(), u.reason)).collect();
    if missing.is_empty() { String::new() } else { format!("; not testable on these data: {}", missing.join("; ")) }
}

/// The candidate the held-out poses confirm in all but its size (the largest mean gain), if any.
fn too_small(lr: &search::Round) -> Option<&search::Evaluated> {
    lr.evaluated.iter().filter(|e| e.too_small).max_by(|a, b| a.vs_model.gain_mean.total_cmp(&b.vs_model.gain_mean))
}

/// "cyclic j2 h2, predicts held-out poses better (p = …) but lowers the held-out mean by only …
/// (… %)", the share of `base` (the mean it was judged against, m).
/// A direction term's clause says why the exception for such terms did not name it.
fn too_small_clause(lr: &search::Round, e: &search::Evaluated, base: f64) -> String {
    let why = match &e.apart {
        Some(search::Apart::NotBeyond(b)) => format!(
            " and, beyond a smooth function of the configuration and a drift along the run, not significantly better (p = {:.1e})",
            b.p.unwrap_or(f64::NAN)
        ),
        Some(search::Apart::NeighbourOrder(locality)) => format!(
            " in an order whose consecutive stops are neighbours (locality {locality:.2}), where the sign of each move follows the neighbourhood"
        ),
        Some(search::Apart::NoOrder) => " with no measuring order to test it against a drift".into(),
        _ => String::new(),
    };
    format!(
        "{}, predicts held-out poses better (p = {:.1e}) but lowers the held-out mean by only {} ({:.1} %){why}",
        lr.screened[e.index].candidate.label(),
        e.vs_model.p.unwrap_or(f64::NAN),
        mm(e.vs_model.gain_mean),
        100.0 * e.vs_model.gain_mean / base
    )
}

/// The held-out mean the last round judged its candidates against (its model's, linearised
/// folds); `otherwise` without a baseline figure.
fn round_mean(s: &search::Search, otherwise: f64) -> f64 {
    ErrorStats::of(&s.baselines[s.accepted.len()].norms()).map_or(otherwise, |e| e.mean)
}

/// What the last round found (or did not).
fn last_finding(s: &search::Search, d: &Decomposition) -> Finding {
    let last = s.rounds.len() - 1;
    let lr = &s.rounds[last];
    match &lr.decision {
        Decision::Accept(_) | Decision::Nothing => nothing_new(s, d),
        Decision::NotSeparable { best, lookalike, canonical, reason } => {
            let b = &lr.screened[*best];
            let la = lookalike.map(|i| lr.screened[i].candidate.clone());
            let mut suspects = vec![effect_of(s, last, *best, None)];
            if let Some(i) = lookalike {
                suspects.push(effect_of(s, last, *i, None));
            }
            Finding {
                experiment: Some(experiment(b.candidate.kind, la.as_ref().map(|c| c.kind))),
                lookalike: la,
                canonical_correlation: *canonical,
                absorbed_by: b.absorbed_by.clone(),
                suspects,
                ..Finding::new(Status::NotSeparable, format!("{}: {reason}", b.candidate.label()))
            }
        }
        Decision::Partial { best, share, smoother_gain_rms, closure_only } => {
            let b = &lr.screened[*best];
            let gain = lr.evaluated.iter().find(|e| e.index == *best).map_or(0.0, |e| e.vs_model.gain_rms);
            // The smoother's own gain is the round's (`rounds[].smoother_gain_rms_mm`); where the
            // term beside it gains more, that is what the share was taken of, and both are said.
            let against = if *smoother_gain_rms > lr.smoother.gain_rms {
                format!(
                    "{} for a smooth function of the configuration, {} for both together",
                    mm(lr.smoother.gain_rms),
                    mm(*smoother_gain_rms)
                )
            } else {
                format!("{} for a smooth function of the configuration", mm(lr.smoother.gain_rms))
            };
            let explains = format!(
                "{} explains {:.0} % of what a smooth function of the configuration explains beyond the model (held-out RMS gain {} against {against})",
                b.candidate.label(),
                share * 100.0,
                mm(gain),
            );
            let summary = match closure_only {
                // No smooth structure beyond it: what it leaves changes from pose to pose. Too
                // small a share of the gap to tell it from a look-alike, not evidence of one.
                Some(c) => format!(
                    "{explains}, but closes only {:.0} % of the gap to the floor; the rest changes from pose to pose, and so small a share cannot tell this term from a look-alike of an effect outside the library: not named",
                    c * 100.0
                ),
                None => format!(
                    "{explains}; the rest is unexplained: an effect outside the library, of which this term is a look-alike"
                ),
            };
            Finding {
                absorbed_by: b.absorbed_by.clone(),
                experiment: Some(experiment(b.candidate.kind, None)),
                suspects: vec![effect_of(s, last, *best, None)],
                ..Finding::new(Status::Partial, summary)
            }
        }
        Decision::Refuted { best, reason, .. } => {
            let b = &lr.screened[*best];
            Finding {
                absorbed_by: b.absorbed_by.clone(),
                experiment: Some(experiment(b.candidate.kind, None)),
                suspects: vec![effect_of(s, last, *best, None)],
                ..Finding::new(
                    Status::NotSeparable,
                    format!("{}: {reason}; not named, and the model is kept without it", b.candidate.label()),
                )
            }
        }
        Decision::Unknown { best } => {
            let small = too_small(lr);
            let what = match best {
                Some(i) => format!(
                    "a smooth function of the configuration predicts the residual better than the best candidate ({}), which is one of its forms",
                    lr.screened[*i].candidate.label()
                ),
                None => {
                    let base = round_mean(s, d.heldout.mean);
                    let sm = &lr.smoother;
                    let smooth = format!(
                        "a smooth function of the configuration predicts the residual (held-out mean lower by {}, {:.1} %)",
                        mm(sm.gain_mean),
                        100.0 * sm.gain_mean / base
                    );
                    // A candidate the held-out poses confirm in all but its size is said, with its
                    // figures: "no candidate does" would be contradicted by them.
                    match small {
                        Some(e) => format!(
                            "{smooth}; no candidate predicts enough of it to name: the best, {}",
                            too_small_clause(lr, e, base)
                        ),
                        None => format!("{smooth}; no candidate does"),
                    }
                }
            };
            // Candidates these data cannot test are named here too: the cause may be one of them.
            Finding {
                suspects: match (best, small) {
                    (None, Some(e)) => vec![effect_of(s, last, e.index, None)],
                    _ => Vec::new(),
                },
                ..Finding::new(Status::UnknownEffect, format!("{what}{}", untestable(s)))
            }
        }
    }
}

/// The last round accepted an effect or found none to test: an excess far above the floor that
/// nothing predicts comes first (its cause may be untestable on these data); then screening
/// evidence that no held-out test could confirm (an effect the current model absorbs); else none.
fn nothing_new(s: &search::Search, d: &Decomposition) -> Finding {
    let last = s.rounds.len() - 1;
    let lr = &s.rounds[last];
    // The model the last round judged (an adopted payload comes after it).
    let last_fig = match &s.refits[s.accepted.len()] {
        Ok(h) => h,
        _ => &s.baselines[s.accepted.len()],
    };
    let now = ErrorStats::of(&last_fig.norms()).unwrap_or(d.heldout);
    let strong = lr
        .screened
        .iter()
        .filter(|c| c.significant && c.log10_p_holm < -6.0 && c.score.rho < 0.5)
        .max_by(|a, b| a.score.bic_gain.total_cmp(&b.score.bic_gain));
    // Candidates these data cannot test: named in the summary, with the log that would make them
    // testable, whenever the verdict is not a plain `none`.
    let untestable = untestable(s);
    let exp = s
        .unavailable
        .iter()
        .map(|u| match u.kind {
            Kind::Backlash => {
                "log each joint's approach direction, or keep the measuring order with its times".to_string()
            }
            Kind::Thermal => "log the robot's temperature".to_string(),
            k => experiment(k, None),
        })
        .collect::<Vec<_>>();
    // A candidate the held-out poses confirm in all but its size: in the data, too small to name.
    // Its share is of the mean it was judged against (the round's model, linearised folds).
    let small = if matches!(lr.decision, Decision::Accept(_)) { None } else { too_small(lr) };
    match strong {
        _ if now.rms > EXCESS_RATIO * d.floor.rms && now.rms - d.floor.rms > EXCESS_MIN => Finding {
            experiment: Some(if exp.is_empty() {
                "repeat poses to measure the robot's repeatability, and check the instrument's noise".into()
            } else {
                exp.join("; ")
            }),
            suspects: small.map(|e| vec![effect_of(s, last, e.index, None)]).unwrap_or_default(),
            ..Finding::new(
                Status::NotSeparable,
                match small {
                    None => format!(
                        "the held-out error (RMS {}) stands far above the floor ({}), but neither a candidate nor a smooth function of the configuration predicts it: an error that changes from pose to pose{untestable}",
                        mm(now.rms),
                        mm(d.floor.rms),
                    ),
                    Some(e) => format!(
                        "the held-out error (RMS {}) stands far above the floor ({}), and neither a candidate nor a smooth function of the configuration predicts most of it: the best candidate, {}, too little to name it or to tell it from a look-alike; the rest is an error that changes from pose to pose{untestable}",
                        mm(now.rms),
                        mm(d.floor.rms),
                        too_small_clause(lr, e, round_mean(s, now.mean)),
                    ),
                },
            )
        },
        Some(c) if !matches!(lr.decision, Decision::Accept(_)) => {
            let i = lr.screened.iter().position(|x| std::ptr::eq(x, c)).expect("from the list");
            Finding {
                absorbed_by: c.absorbed_by.clone(),
                experiment: Some(
                    std::iter::once(experiment(c.candidate.kind, None)).chain(exp).collect::<Vec<_>>().join("; "),
                ),
                suspects: vec![effect_of(s, last, i, None)],
                ..Finding::new(
                    Status::NotSeparable,
                    format!(
                        "{} is in the data (screening p = 1e{:.0}) but the current model absorbs {:.0} % of it (ρ = {:.2}): it does not predict held-out poses better{untestable}",
                        c.candidate.label(),
                        c.log10_p_holm,
                        (1.0 - c.score.rho * c.score.rho) * 100.0,
                        c.score.rho
                    ),
                )
            }
        }
        _ => Finding::new(
            Status::None,
            format!(
                "no effect above the floor (held-out mean {} against a floor of {})",
                mm(d.heldout.mean),
                mm(d.floor.mean)
            ),
        ),
    }
}

/// Each named effect with its numbers: the estimate ± σ, and the held-out mean of the refitted
/// models before and after it (the shrink table's rows), with the gap closure; "; "-separated.
fn named(s: &search::Search, d: &Decomposition, effects: &[Effect]) -> String {
    let figures: Vec<Option<f64>> = s
        .refits
        .iter()
        .zip(&s.baselines)
        .map(|(r, b)| ErrorStats::of(&r.as_ref().unwrap_or(b).norms()).map(|e| e.mean))
        .collect();
    let gap_mean = d.heldout.mean - d.floor.mean;
    effects
        .iter()
        .enumerate()
        .map(|(k, e)| {
            // A group (every joint's backlash or compliance) says each term, those it tells from
            // zero first (the group is confirmed as a whole; a term within 2 σ of zero — a joint
            // the data barely see — is no finding of its own); a table its RMS; a cyclic pair its
            // amplitude.
            let value = if e.candidate.joint.is_none() && e.parameters.len() > 1 && e.candidate.kind != Kind::JointMap {
                let term = |p: &&ParamEstimate| format!("{} {}", p.param, with_sd(p.value, p.std, p.param.unit()));
                let (told, near_zero): (Vec<&ParamEstimate>, Vec<&ParamEstimate>) =
                    e.parameters.iter().partition(|p| p.std.is_none_or(|sd| p.value.abs() >= 2.0 * sd));
                let mut text = told.iter().map(term).collect::<Vec<_>>().join(", ");
                if !near_zero.is_empty() {
                    let rest = near_zero.iter().map(term).collect::<Vec<_>>().join(", ");
                    text = if text.is_empty() {
                        format!("each within 2 σ of zero: {rest}")
                    } else {
                        format!("{text}; within 2 σ of zero: {rest}")
                    };
                }
                format!(" ({text})")
            } else {
                match e.estimate {
                    Some(v) => format!(" {}", with_sd(v, e.std, e.unit)),
                    None => String::new(),
                }
            };
            let held = match (figures.get(k).copied().flatten(), figures.get(k + 1).copied().flatten()) {
                (Some(a), Some(b)) => {
                    let closure = if gap_mean > 0.0 {
                        format!(", closing {:.0} % of the gap to the floor", (d.heldout.mean - b) / gap_mean * 100.0)
                    } else {
                        String::new()
                    };
                    format!(" (held-out mean {} → {}{closure})", mm(a), mm(b))
                }
                _ => String::new(),
            };
            format!("{}{value}{held}{}", e.candidate.label(), apart_clause(s, k))
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// For the k-th named effect when it was confirmed below `min_rel_gain` (a direction-of-motion
/// term beyond the smoother and a drift along the run): a clause saying so, with its figures;
/// "" otherwise.
fn apart_clause(s: &search::Search, k: usize) -> String {
    let Some((round, i)) =
        s.rounds.iter().filter_map(|r| if let Decision::Accept(i) = r.decision { Some((r, i)) } else { None }).nth(k)
    else {
        return String::new();
    };
    let Some(search::Apart::Beyond(apart)) =
        round.evaluated.iter().find(|e| e.index == i).and_then(|e| e.apart.as_ref())
    else {
        return String::new();
    };
    format!(
        ", smaller than the {:.0} % of the held-out mean a name otherwise needs, but beyond a smooth function of the configuration and a drift along the run it still predicts held-out poses better (p = {:.1e}, mean {} lower)",
        100.0 * s.min_rel_gain,
        apart.p.unwrap_or(f64::NAN),
        mm(apart.gain_mean)
    )
}

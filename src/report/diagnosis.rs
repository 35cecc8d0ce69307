//! The diagnosis report (issue 11): the verdict, the decomposition of the held-out error (noise
//! floor, what the named effects explain, what remains unexplained, and the extrapolation gap of
//! the set as given), the candidate table, where the model misses (binned error profiles against
//! each variable, the voxels above the floor) and the shrink table. Its input is the diagnosis's
//! wire form, `domain::diagnosis::DiagnosisOut`, as `robocal diagnose` writes it and the service
//! stores it.

use super::html::{esc, figure, fixed, mm, opt, p_value, page, sig, table};
use super::plot::{self, Panel, Segment};
use crate::domain::diagnosis::{CandidateOut, CandidateRef, DiagnosisOut, EvidenceOut, ParamOut, StatsOut};

/// The decomposition, mm: (label, segments) rows of the stacked bar.
///
/// Held-out error of the starting model (mean |e|) = noise floor + explained by the named effects
/// (start − final held-out mean) + unexplained (final − floor); the set as given on the validation
/// poses adds the extrapolation gap (calibrated − held-out) when that is positive.
pub fn decomposition_rows(d: &DiagnosisOut) -> Vec<(String, Vec<Segment>)> {
    let dec = &d.decomposition;
    let start = dec.heldout.figures.mean_mm;
    let floor = dec.floor.mean_mm.min(start);
    let last = d.shrink.last().map_or(start, |s| s.mean_mm).clamp(floor, start);
    let seg = |label: &str, length: f64, shade: usize| Segment { label: label.into(), length, shade };
    let mut rows = vec![(
        "held-out, starting model".to_string(),
        vec![
            seg("noise floor", floor, 0),
            seg("unexplained", last - floor, 2),
            seg("explained by the named effects", start - last, 1),
        ],
    )];
    if let Some(c) = &dec.calibrated {
        let cal = c.figures.mean_mm;
        let mut segments = vec![seg("held-out, starting model", cal.min(start), 3)];
        if cal > start {
            segments.push(seg("extrapolation gap", cal - start, plot::HATCHED));
        }
        rows.push(("calibrated, as given".to_string(), segments));
    }
    rows
}

/// Candidates of each round shown before the fold.
const CANDIDATES_SHOWN: usize = 8;

fn candidate_name(c: &CandidateRef) -> String {
    esc(&c.label)
}

/// The diagnosis's sections.
pub fn diagnosis_sections(d: &DiagnosisOut) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "<p class=\"meta\">Identification sessions: {}; tested poses: {} ({}-fold grouped cross-validation).</p>",
        esc(&d.sessions.identification.join(", ")),
        esc(&if d.sessions.validation.is_empty() {
            d.sessions.identification.join(", ")
        } else {
            d.sessions.validation.join(", ")
        }),
        d.sessions.folds
    ));
    verdict_section(&mut s, d);
    decomposition_section(&mut s, d);
    candidates_section(&mut s, d);
    where_section(&mut s, d);
    evidence_section(&mut s, d);
    shrink_section(&mut s, d);
    transfer_section(&mut s, d);
    if !d.notes.is_empty() {
        s.push_str("<h3>Notes</h3><ul>");
        for n in &d.notes {
            s.push_str(&format!("<li>{}</li>", esc(n)));
        }
        s.push_str("</ul>");
    }
    s
}

/// The verdict, its named effects (estimate, σ, held-out before → after, gap closed), what
/// remains, the experiment that would separate it, and the final model.
fn verdict_section(s: &mut String, d: &DiagnosisOut) {
    let v = &d.verdict;
    s.push_str("<h2>Verdict</h2>");
    s.push_str(&format!("<p><strong>{}</strong>: {}</p>", v.status, esc(&v.summary)));
    if !v.effects.is_empty() {
        // The shrink table holds the start, then one model per accepted effect in the order
        // they were named: effect k is shrink[k] → shrink[k + 1] (only for a named verdict); a
        // last row beyond them is the model with an adopted payload.
        let steps = v.status == crate::diagnose::Status::Named && d.shrink.len() > v.effects.len();
        let rows: Vec<Vec<String>> = v
            .effects
            .iter()
            .enumerate()
            .map(|(k, e)| {
                let (before_after, closed) = if steps {
                    let (a, b) = (&d.shrink[k], &d.shrink[k + 1]);
                    (
                        format!("{} → {}", mm(a.mean_mm), mm(b.mean_mm)),
                        b.gap_closure.map_or("—".into(), |g| format!("{} %", fixed(100.0 * g, 0))),
                    )
                } else {
                    ("—".into(), "—".into())
                };
                // A group of terms over several joints (backlash j1–j6) has one estimate per
                // term; `estimate` alone is its most significant term's, which read as the
                // group's size would mislead: each term gets its line.
                let group = e.parameters.len() > 1 && !matches!(e.which.name.as_str(), "cyclic" | "joint_map");
                let per_term =
                    |cell: &dyn Fn(&ParamOut) -> String| e.parameters.iter().map(cell).collect::<Vec<_>>().join("<br>");
                let (estimate, std) = if group {
                    (
                        per_term(&|p| format!("{} {} {}", esc(&p.name), opt(Some(p.estimate), 4), esc(&p.unit))),
                        per_term(&|p| p.std.map_or("—".into(), |x| format!("{} {}", sig(x), esc(&p.unit)))),
                    )
                } else {
                    (
                        format!("{} {}", opt(e.estimate, 4), esc(&e.unit)),
                        e.std.map_or("—".into(), |x| format!("{} {}", sig(x), esc(&e.unit))),
                    )
                };
                vec![
                    esc(&e.which.label),
                    estimate,
                    std,
                    before_after,
                    closed,
                    e.confirm_p.map_or("—".into(), p_value),
                    fixed(e.screen_log10_p, 1),
                    fixed(e.separability, 3),
                ]
            })
            .collect();
        // A partial or not-separable verdict's effects are suspects, not added to the model: their
        // estimate is the screening's one-step linear one, without σ (a twice-per-turn term fitted
        // over 9° of joint travel read "5.8623 deg" under the title "Named effects").
        let (title, estimate_header) = if v.status == crate::diagnose::Status::Named {
            (
                "Named effects: estimate ± σ, held-out mean before → after (the model refitted on the folds), gap closed",
                "estimate",
            )
        } else {
            (
                "Suspected, not named: the screening's one-step linear estimate (not added to the model, so no σ and no refit)",
                "screening estimate",
            )
        };
        s.push_str(&table(
            title,
            &["effect", estimate_header, "σ", "held-out mean (mm)", "gap closed", "confirm p", "log10 p (Holm)", "ρ"],
            &rows,
            &[false, true, true, true, true, true, true, true],
        ));
    }
    if let Some(r) = &v.remaining {
        s.push_str(&format!("<p>What remains: <strong>{}</strong> — {}</p>", r.status, esc(&r.summary)));
    }
    if let Some(x) = &v.experiment {
        s.push_str(&format!("<p class=\"note\">Experiment that would separate it: {}</p>", esc(x)));
    }
    s.push_str(&format!("<p>Final model: <code>{}</code></p>", esc(&d.model)));
}

/// The starting model's error split into the floor, the explained and the unexplained part.
fn decomposition_section(s: &mut String, d: &DiagnosisOut) {
    s.push_str("<h2>Decomposition of the error</h2>");
    let dec = &d.decomposition;
    let rows = decomposition_rows(d);
    s.push_str(&figure(
        &plot::stacked_bars_svg("Mean |e| decomposed", "mean |e| (mm)", &rows),
        "The starting model's held-out mean error split into the noise floor (instrument and repeatability), what \
         the named effects explain and what stays unexplained; below, the set as given on the tested poses.",
    ));
    let mut t = vec![
        vec![
            "held-out, starting model".into(),
            dec.heldout.n.to_string(),
            mm(dec.heldout.figures.mean_mm),
            mm(dec.heldout.figures.rms_mm),
            mm(dec.heldout.figures.p95_mm),
        ],
        vec!["noise floor".into(), "".into(), mm(dec.floor.mean_mm), mm(dec.floor.rms_mm), mm(dec.floor.p95_mm)],
    ];
    if let Some(c) = &dec.calibrated {
        t.insert(
            0,
            vec![
                "calibrated, as given".into(),
                c.n.to_string(),
                mm(c.figures.mean_mm),
                mm(c.figures.rms_mm),
                mm(c.figures.p95_mm),
            ],
        );
    }
    s.push_str(&table(
        "Error figures, mm",
        &["model", "n", "mean (mm)", "RMS (mm)", "p95 (mm)"],
        &t,
        &[false, true, true, true, true],
    ));
    s.push_str(&format!(
        "<p>Unmodelled gap (held-out − floor): {} mm; extrapolation gap (calibrated − held-out): {} mm; \
         instrument σ per axis {} mm; prediction RMS from the covariance {} mm.</p>",
        mm(dec.unmodelled_gap_mm),
        dec.extrapolation_gap_mm.map_or("—".into(), mm),
        mm(dec.floor.instrument_sigma_mm),
        mm(dec.floor.prediction_rms_mm)
    ));
}

/// The screened candidates: the most significant of each round and every one checked on held-out
/// poses, the full list folded, and those these data cannot test.
fn candidates_section(s: &mut String, d: &DiagnosisOut) {
    s.push_str("<h2>Candidates</h2>");
    // The top CANDIDATES_SHOWN of each round by Holm-corrected p, and every one the held-out
    // check evaluated; the full list folded below.
    let mut shown: Vec<&CandidateOut> = Vec::new();
    let rounds = d.candidates.iter().map(|c| c.round).max().unwrap_or(0);
    for r in 1..=rounds {
        let mut of: Vec<&CandidateOut> = d.candidates.iter().filter(|c| c.round == r).collect();
        of.sort_by(|a, b| a.log10_p_holm.total_cmp(&b.log10_p_holm));
        for (i, c) in of.into_iter().enumerate() {
            if i < CANDIDATES_SHOWN || c.heldout.is_some() {
                shown.push(c);
            }
        }
    }
    let candidate_row = |c: &CandidateOut| -> Vec<String> {
        let h = c.heldout.as_ref();
        vec![
            c.round.to_string(),
            candidate_name(&c.which),
            fixed(c.statistic, 1),
            fixed(c.dof, 0),
            fixed(c.log10_p_holm, 1),
            if c.significant { "yes".into() } else { "no".into() },
            fixed(c.separability, 3),
            fixed(c.bic_gain, 1),
            h.map_or("—".into(), |h| mm(h.gain_mean_mm)),
            h.and_then(|h| h.p).map_or("—".into(), p_value),
            h.map_or("—".into(), |h| match (&h.beyond_smoother_and_drift, h.confirmed) {
                (Some(b), true) => {
                    format!("confirmed beyond the smoother and a drift (p {})", b.p.map_or("—".into(), p_value))
                }
                (_, true) => "confirmed".into(),
                (Some(b), false) => {
                    format!("not confirmed (beyond the smoother and a drift: p {})", b.p.map_or("—".into(), p_value))
                }
                (None, false) => "not confirmed".into(),
            }),
        ]
    };
    let header = [
        "round",
        "candidate",
        "S",
        "dof",
        "log10 p (Holm)",
        "significant",
        "ρ",
        "BIC gain",
        "held-out gain (mm)",
        "p",
        "held-out",
    ];
    let right = [true, false, true, true, true, false, true, true, true, true, false];
    let rows: Vec<Vec<String>> = shown.iter().map(|c| candidate_row(c)).collect();
    s.push_str(&table(
        &format!(
            "Screened candidates: the {CANDIDATES_SHOWN} most significant of each round and every one checked on held-out \
             poses ({} of {}); score statistic, Holm-corrected p, separability ρ, and the held-out check",
            shown.len(),
            d.candidates.len()
        ),
        &header,
        &rows,
        &right,
    ));
    if shown.len() < d.candidates.len() {
        let all: Vec<Vec<String>> = d.candidates.iter().map(candidate_row).collect();
        s.push_str(&format!(
            "<details><summary>All {} screened candidates</summary>{}</details>",
            d.candidates.len(),
            table("Every screened candidate, in screening order", &header, &all, &right)
        ));
    }
    if !d.unavailable.is_empty() {
        let rows: Vec<Vec<String>> = d.unavailable.iter().map(|u| vec![esc(&u.name), esc(&u.reason)]).collect();
        s.push_str(&table("Candidates these data cannot test", &["candidate", "why"], &rows, &[false, false]));
    }
}

/// Where the starting model misses: binned profiles, the signed error per axis, the voxels above
/// the floor.
fn where_section(s: &mut String, d: &DiagnosisOut) {
    s.push_str("<h2>Where the model misses</h2>");
    let w = &d.location;
    let panels: Vec<Panel> = w
        .against
        .iter()
        // A variable that does not vary over the tested poses (τ1 of a vertical first axis: no
        // gravity torque) has no profile to draw.
        .filter(|a| {
            let (lo, hi) =
                a.profile.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), b| (l.min(b.at), h.max(b.at)));
            a.profile.len() >= 2 && hi - lo > 1e-6
        })
        .map(|a| Panel {
            title: format!(
                "r = {}, p = {}",
                a.r.map_or("—".into(), |r| fixed(r, 2)),
                a.p_value.map_or("—".into(), p_value)
            ),
            x_desc: format!("{} ({})", a.variable, a.unit),
            points: a.profile.iter().map(|b| (b.at, b.mean_mm)).collect(),
            reference: Some(d.decomposition.floor.mean_mm),
        })
        .collect();
    if panels.is_empty() {
        s.push_str("<p class=\"note\">No binned profile to draw.</p>");
    } else {
        s.push_str(&figure(
            &plot::panels_svg("mean |e| (mm)", &panels),
            &format!(
                "Held-out |e| of the starting model over {} tested poses, binned against each variable; dashed: the noise floor's mean.",
                w.n
            ),
        ));
    }
    let axes = [("x", &w.per_axis.x), ("y", &w.per_axis.y), ("z", &w.per_axis.z)];
    let rows: Vec<Vec<String>> = axes
        .iter()
        .map(|(k, a)| vec![k.to_string(), mm(a.mean_mm), mm(a.std_mm), a.shapiro_p.map_or("—".into(), p_value)])
        .collect();
    s.push_str(&table(
        "Held-out signed error per axis of {W}",
        &["axis", "mean (mm)", "σ (mm)", "Shapiro–Wilk p"],
        &rows,
        &[false, true, true, true],
    ));
    let rows: Vec<Vec<String>> = w
        .voxels
        .above_floor
        .iter()
        .map(|x| {
            vec![
                format!("{}, {}, {}", fixed(x.centre_mm[0], 0), fixed(x.centre_mm[1], 0), fixed(x.centre_mm[2], 0)),
                x.n.to_string(),
                mm(x.mean_mm),
                mm(x.floor_mean_mm),
                p_value(x.p),
                p_value(x.q),
            ]
        })
        .collect();
    if rows.is_empty() {
        s.push_str(&format!(
            "<p>No workspace voxel ({} mm edge, {} tested) stands above the floor at the false-discovery rate.</p>",
            fixed(w.voxels.size_mm, 0),
            w.voxels.tested
        ));
    } else {
        s.push_str(&table(
            &format!(
                "Voxels above the floor ({} mm edge, {} tested), worst first",
                fixed(w.voxels.size_mm, 0),
                w.voxels.tested
            ),
            &["centre (mm)", "n", "mean (mm)", "floor mean (mm)", "p", "q (BH)"],
            &rows,
            &[false, true, true, true, true, true],
        ));
    }
    match &w.order_drift {
        Some(d) => s.push_str(&format!(
            "<p{}>Along the measuring order, {}.</p>",
            if d.found || d.joint_creep.as_ref().is_some_and(|c| c.found) { " class=\"warn\"" } else { "" },
            esc(&d.statement)
        )),
        None => s.push_str(
            "<p class=\"note\">Along the measuring order: not tested (the stops' places in the run are unknown — no times, no one sequence numbering, not one session listed as measured — or fewer than 40 stops).</p>",
        ),
    }
}

/// The evidence for each named effect, one figure each.
fn evidence_section(s: &mut String, d: &DiagnosisOut) {
    if !d.evidence.is_empty() {
        s.push_str("<h2>The evidence for each named effect</h2>");
        s.push_str(
            "<p>Per tested pose, the held-out residual of the model before the effect, turned into \
             the joint-angle error at the effect's joint that explains it best (r·s/|s|², s the \
             TCP's motion per radian of that joint), binned along the effect's own variable: \
             mean ± 2 standard errors; beside it the effect's own term, and the held-out residual \
             after the effect. The term need not match the residual before it: the model before \
             took what its own parameters could of the effect (a joint offset, a link length), and \
             the model after refits those too. The caption gives the share of the residual at the \
             joint that the model with the effect removes (1 − Σ after² / Σ before², per pose).</p>\n",
        );
        for e in &d.evidence {
            s.push_str(&evidence_figure(e));
        }
    }
}

/// How far the held-out error shrinks, model by model.
fn shrink_section(s: &mut String, d: &DiagnosisOut) {
    s.push_str("<h2>How far the error shrinks</h2>");
    let rows: Vec<Vec<String>> = d
        .shrink
        .iter()
        .map(|x| {
            vec![
                esc(&x.model),
                x.n.to_string(),
                mm(x.mean_mm),
                mm(x.rms_mm),
                mm(x.p95_mm),
                mm(x.max_mm),
                x.gap_closure.map_or("—".into(), |g| format!("{} %", fixed(100.0 * g, 1))),
            ]
        })
        .collect();
    s.push_str(&table(
        "Held-out errors from the starting model to the last accepted one; gap closure against the floor",
        &["model", "n", "mean (mm)", "RMS (mm)", "p95 (mm)", "max (mm)", "gap closed"],
        &rows,
        &[false, true, true, true, true, true, true],
    ));
}

/// The models carried to other sessions, inside and outside the identified joint ranges.
fn transfer_section(s: &mut String, d: &DiagnosisOut) {
    if !d.transfer.is_empty() {
        let rows: Vec<Vec<String>> = d
            .transfer
            .iter()
            .map(|t| {
                let r = t.joint_range.as_ref();
                let part =
                    |p: Option<&StatsOut>| p.map_or("—".into(), |e| format!("{} (n {})", mm(e.figures.mean_mm), e.n));
                vec![
                    esc(&t.session),
                    esc(&t.model),
                    t.errors.as_ref().map_or("—".into(), |e| mm(e.figures.mean_mm)),
                    t.errors.as_ref().map_or("—".into(), |e| mm(e.figures.p95_mm)),
                    r.map_or("—".into(), |r| format!("{:.0} %", 100.0 * r.inside_share)),
                    part(r.and_then(|r| r.inside.as_ref())),
                    part(r.and_then(|r| r.outside.as_ref())),
                    t.change_from_start
                        .as_ref()
                        .map_or("—".into(), |c| format!("{:+.4} ± {:.4}", c.mean_mm, c.standard_error_mm)),
                    t.kappa_scaled.map_or("—".into(), sig),
                    esc(t.error.as_deref().unwrap_or("")),
                ]
            })
            .collect();
        s.push_str(&table(
            "Transfer to other sessions (base and tools refitted)",
            &[
                "session",
                "model",
                "mean (mm)",
                "p95 (mm)",
                "inside the identified joint ranges",
                "mean inside (mm)",
                "mean outside (mm)",
                "change from start (mm)",
                "κ scaled",
                "refused",
            ],
            &rows,
            &[false, false, true, true, true, true, true, true, true, false],
        ));
        s.push_str(
            "<p>A pose is inside when every joint lies within the range the identification sessions \
             measured; outside, the model's joint terms (tables, harmonics, compliance) are \
             extrapolated, and its error there tests that extrapolation. The change from start is \
             the mean of the model's error minus the starting model's, reading by reading, ± its \
             standard error from the change's means over runs of consecutive poses.</p>\n",
        );
        zeros_section(s, d);
    }
}

/// The start and the final model registered with the joints' zero offsets too, held out on
/// alternate poses.
fn zeros_section(s: &mut String, d: &DiagnosisOut) {
    let rows: Vec<Vec<String>> = d
        .transfer
        .iter()
        .filter_map(|t| t.zeros_refitted.as_ref().map(|z| (t, z)))
        .map(|(t, z)| {
            let beyond: Vec<String> = z
                .zero_shifts
                .iter()
                .filter(|x| x.change_deg.abs() > crate::diagnose::ZERO_SHIFT_SIGMAS * x.std_deg)
                .map(|x| format!("{} {:+.4} ± {:.4}°", x.parameter, x.change_deg, x.std_deg))
                .collect();
            vec![
                esc(&t.session),
                esc(&t.model),
                z.held_out_base_tool.as_ref().map_or("—".into(), |e| mm(e.figures.mean_mm)),
                z.held_out_with_zeros.as_ref().map_or("—".into(), |e| mm(e.figures.mean_mm)),
                z.change.as_ref().map_or("—".into(), |c| format!("{:+.4} ± {:.4}", c.mean_mm, c.standard_error_mm)),
                esc(&beyond.join(", ")),
                esc(z.error.as_deref().unwrap_or("")),
            ]
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    s.push_str(&table(
        "Registered with the joints' zeros too (held out on alternate poses)",
        &[
            "session",
            "model",
            "base and tools, mean (mm)",
            "with the zeros, mean (mm)",
            "change (mm)",
            "zeros beyond 3 σ from the model's",
            "refused",
        ],
        &rows,
        &[false, false, true, true, true, false, false],
    ));
    s.push_str(
        "<p>Each half of the session's poses, taken alternately in measuring order, registers the \
         model and the other half is scored: with base and tools, and with the joints' zero \
         offsets as well. A robot re-mastered between the set-ups, or whose zeros drifted, gains \
         so; so does a model error outside the identified joint ranges that looks like a zero, \
         and one session does not tell them apart. Each zero's σ combines the registration's and \
         the model's own.</p>\n",
    );
}

/// The diagnosis report page.
pub fn diagnosis_report(d: &DiagnosisOut) -> String {
    page("Diagnosis report", &diagnosis_sections(d))
}

/// One named effect's evidence: the binned residual angle before it (± 2 s.e.), its prediction
/// and the residual after it, in mdeg against its variable.
fn evidence_figure(e: &EvidenceOut) -> String {
    let md = |v: f64| v * 1000.0;
    let curves = [
        plot::Curve {
            label: "held-out residual before (± 2 s.e.)".into(),
            points: e
                .bins
                .iter()
                .map(|b| {
                    let (m, w) = (md(b.before_deg), 2.0 * md(b.before_sem_deg));
                    (b.at, [m - w, m - w, m, m + w, m + w])
                })
                .collect(),
            pooled: None,
        },
        plot::Curve {
            label: "the effect's term".into(),
            points: e.bins.iter().map(|b| (b.at, [md(b.predicted_deg); 5])).collect(),
            pooled: None,
        },
        plot::Curve {
            label: "held-out residual after".into(),
            points: e.bins.iter().map(|b| (b.at, [md(b.after_deg); 5])).collect(),
            pooled: None,
        },
    ];
    let x_desc = match e.unit.as_str() {
        "direction" => format!("{} (approach direction of joint {})", e.variable, e.joint),
        u => format!("{} ({u})", e.variable),
    };
    let title = format!("{}: joint {} angle error", e.effect, e.joint);
    let slope = match e.explained_share {
        Some(x) => format!("{:.0} % of the residual at joint {} removed, {} poses", 100.0 * x, e.joint, e.n),
        None => format!("{} poses", e.n),
    };
    figure(
        &plot::learning_curve_svg(&title, &x_desc, &format!("angle at joint {} (mdeg)", e.joint), &curves),
        &format!("{}: {}", e.effect, slope),
    )
}

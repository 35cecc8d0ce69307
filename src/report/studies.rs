//! The study's report (Algorithm 5.1, thesis Fig. 5.8–5.10: box plots of the validation error's
//! mean, σ and maximum over the sets of each size) and the cross-validation's (the learning curve
//! of each model: held-out error against the number of identification poses, with the k-fold
//! figure; the k-fold and transfer tables).

use super::html::{esc, figure, fixed, mm, opt, page, sig, table};
use super::plot::{self, Curve};
use crate::identify::crossval::{Crossval, HeldOut};
use crate::identify::study::Study;
use crate::units::MM;

fn q_mm(q: &[f64; 5]) -> [f64; 5] {
    q.map(|v| v / MM)
}

fn quartile_cell(q: &[f64; 5]) -> String {
    q.iter().map(|v| mm(*v)).collect::<Vec<_>>().join(" / ")
}

/// The study's page.
pub fn study_report(st: &Study) -> String {
    let mut s = format!(
        "<p class=\"meta\">{} identifications from a pool of {} measurements, validated on {}.</p>",
        st.runs.len(),
        st.pool,
        esc(&st.validation.join(", "))
    );
    let labels: Vec<String> = st.rows.iter().map(|r| r.n.to_string()).collect();
    s.push_str("<h2>Validation error against the number of measurements</h2>");
    for (what, pick, fig) in [("mean |e|", 0, "5.8"), ("σ of |e|", 1, "5.9"), ("max |e|", 2, "5.10")] {
        let q: Vec<[f64; 5]> = st
            .rows
            .iter()
            .map(|r| {
                q_mm(match pick {
                    0 => &r.mean,
                    1 => &r.std,
                    _ => &r.max,
                })
            })
            .collect();
        s.push_str(&figure(
            &plot::boxplot_svg(
                &format!("{what} over the sets of each size"),
                "measurements in the identification",
                &format!("{what} (mm)"),
                &labels,
                &q,
            ),
            &format!("Box: first to third quartile, thick line: median, whiskers: min and max over the sets (cf. Fig. {fig})."),
        ));
    }
    let rows: Vec<Vec<String>> = st
        .rows
        .iter()
        .map(|r| {
            vec![
                r.n.to_string(),
                r.succeeded.to_string(),
                r.failed.to_string(),
                quartile_cell(&q_mm(&r.mean)),
                quartile_cell(&q_mm(&r.std)),
                quartile_cell(&q_mm(&r.max)),
            ]
        })
        .collect();
    s.push_str(&table(
        "Quartiles over the sets (min / q1 / median / q3 / max), mm",
        &["n", "succeeded", "refused", "mean |e|", "σ |e|", "max |e|"],
        &rows,
        &[true, true, true, true, true, true],
    ));
    let refused: Vec<Vec<String>> = st
        .runs
        .iter()
        .filter_map(|r| r.error.as_ref().map(|e| vec![r.n.to_string(), r.set.to_string(), esc(e)]))
        .collect();
    if !refused.is_empty() {
        s.push_str(&table("Refused identifications", &["n", "set", "why"], &refused, &[true, true, false]));
    }
    page("Study report", &s)
}

fn held_row(label: String, h: &HeldOut) -> Vec<String> {
    let p = &h.position;
    vec![
        label,
        p.n.to_string(),
        mm(p.mean / MM),
        mm(p.median / MM),
        mm(p.p95 / MM),
        mm(p.max / MM),
        h.orientation.map_or("—".into(), |o| fixed(o.mean * 1e3, 3)),
    ]
}

/// The learning curves: per model, per identification size, the quartiles of the draws' mean
/// held-out |e| (mm), and the k-fold pooled mean.
pub fn learning_curves(cv: &Crossval) -> Vec<Curve> {
    let mut curves: Vec<Curve> = Vec::new();
    for size in &cv.sizes {
        let Some(q) = size.quartiles(|h| h.position.mean) else { continue };
        let k = match curves.iter().position(|c| c.label == size.variant) {
            Some(k) => k,
            None => {
                let pooled = cv
                    .folds
                    .iter()
                    .find(|f| f.variant == size.variant)
                    .and_then(|f| f.pooled.as_ref())
                    .map(|h| h.position.mean / MM);
                curves.push(Curve { label: size.variant.clone(), points: Vec::new(), pooled });
                curves.len() - 1
            }
        };
        curves[k].points.push((size.n as f64, q_mm(&q)));
    }
    curves
}

/// The cross-validation's page.
pub fn crossval_report(cv: &Crossval) -> String {
    let mut s = format!(
        "<p class=\"meta\">Sessions {}: {} measurements at {} poses; splits by pose.</p>",
        esc(&cv.sessions.join(", ")),
        cv.measurements,
        cv.poses
    );
    for note in &cv.notes {
        s.push_str(&format!("<p class=\"meta\">Note: {}</p>", esc(note)));
    }
    let curves = learning_curves(cv);
    if !curves.is_empty() {
        s.push_str("<h2>Learning curve</h2>");
        s.push_str(&figure(
            &plot::learning_curve_svg(
                "Held-out mean |e| against the identification size",
                "poses in the identification",
                "held-out mean |e| (mm)",
                &curves,
            ),
            "Per model: the median over the draws (markers, joined), q1–q3 (bars); the thin dashed line is the model's \
             k-fold cross-validated mean.",
        ));
        let rows: Vec<Vec<String>> = cv
            .sizes
            .iter()
            .map(|z| {
                let q = z.quartiles(|h| h.position.mean).map(|q| q_mm(&q));
                vec![
                    esc(&z.variant),
                    z.n.to_string(),
                    z.draws.iter().filter(|d| d.is_err()).count().to_string(),
                    opt(z.mean(|h| h.position.mean / MM), 3),
                    q.map_or("—".into(), |q| quartile_cell(&q)),
                ]
            })
            .collect();
        s.push_str(&table(
            "Few-poses scheme: mean held-out |e| over the draws, mm",
            &["model", "n", "refused", "mean", "min / q1 / median / q3 / max"],
            &rows,
            &[false, true, true, true, true],
        ));
    }
    if !cv.folds.is_empty() {
        s.push_str("<h2>k-fold cross-validation</h2>");
        let rows: Vec<Vec<String>> = cv
            .folds
            .iter()
            .filter_map(|f| {
                f.pooled.as_ref().map(|h| held_row(format!("{} ({} identified)", esc(&f.variant), f.identified), h))
            })
            .collect();
        s.push_str(&table(
            "Pooled over the folds",
            &["model", "n", "mean (mm)", "median (mm)", "p95 (mm)", "max (mm)", "orientation mean (mrad)"],
            &rows,
            &[false, true, true, true, true, true, true],
        ));
    }
    if !cv.transfer.is_empty() {
        s.push_str("<h2>Transfer</h2>");
        let rows: Vec<Vec<String>> = cv
            .transfer
            .iter()
            .map(|t| {
                let mut r = match &t.errors {
                    Ok(h) => held_row(format!("{} → {}", esc(&t.variant), esc(&t.session)), h),
                    Err(e) => vec![
                        format!("{} → {}: {}", esc(&t.variant), esc(&t.session), esc(e)),
                        "—".into(),
                        "—".into(),
                        "—".into(),
                        "—".into(),
                        "—".into(),
                        "—".into(),
                    ],
                };
                r.push(t.kappa_scaled.map_or("—".into(), sig));
                r
            })
            .collect();
        s.push_str(&table(
            "The whole-session model on another session, base and tools refitted",
            &[
                "model → session",
                "n",
                "mean (mm)",
                "median (mm)",
                "p95 (mm)",
                "max (mm)",
                "orientation mean (mrad)",
                "κ scaled",
            ],
            &rows,
            &[false, true, true, true, true, true, true, true],
        ));
    }
    page("Cross-validation report", &s)
}

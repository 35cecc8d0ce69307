//! A robot's calibration history as a page: the held-out error of each parameter set (mean, p95
//! and maximum of its latest held-out validation, and the nominal model's mean on the same poses)
//! against its version, in-sample figures (a validation on sessions the set was fitted on) apart
//! as their own marked curve and columns, and the table of the sets — date, sessions, activation,
//! figures, diagnosis verdict.
//! The service's `GET /v1/robots/{id}/history/report` draws it from the same entries as the JSON
//! time series (`GET /v1/robots/{id}/history`).

use super::html::{esc, figure, opt, page, table};
use super::plot::{self, Curve};

/// One parameter set of the history, as the page needs it (mm).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HistoryPoint {
    pub version: i64,
    pub created_at: String,
    pub sessions: Vec<String>,
    pub active: bool,
    pub archived: bool,
    pub mean_mm: Option<f64>,
    pub p95_mm: Option<f64>,
    pub max_mm: Option<f64>,
    pub nominal_mean_mm: Option<f64>,
    /// The latest in-sample validation's mean and the sessions it shares with the fit: a fit
    /// residual, never plotted or listed as held out.
    pub in_sample_mean_mm: Option<f64>,
    pub in_sample_sessions: Vec<String>,
    pub verdict: Option<String>,
}

/// The curves of the history plot: one per figure, a point per validated set.
pub fn history_curves(points: &[HistoryPoint]) -> Vec<Curve> {
    let curve = |label: &str, pick: fn(&HistoryPoint) -> Option<f64>| Curve {
        label: label.to_string(),
        points: points.iter().filter_map(|p| pick(p).map(|v| (p.version as f64, [v; 5]))).collect(),
        pooled: None,
    };
    [
        curve("mean |e|", |p| p.mean_mm),
        curve("p95 |e|", |p| p.p95_mm),
        curve("max |e|", |p| p.max_mm),
        curve("nominal model, mean |e|", |p| p.nominal_mean_mm),
        curve("in-sample (not held out), mean |e|", |p| p.in_sample_mean_mm),
    ]
    .into_iter()
    .filter(|c| !c.points.is_empty())
    .collect()
}

/// The page.
pub fn history_report(robot: &str, points: &[HistoryPoint]) -> String {
    let validated = points.iter().filter(|p| p.mean_mm.is_some()).count();
    let in_sample = points.iter().filter(|p| p.in_sample_mean_mm.is_some()).count();
    let mut s = format!(
        "<p class=\"meta\">Robot {}: {} parameter set{}, {} with a held-out validation{}.</p>",
        esc(robot),
        points.len(),
        if points.len() == 1 { "" } else { "s" },
        validated,
        if in_sample > 0 {
            format!(", {in_sample} with an in-sample one (on sessions the set was fitted on)")
        } else {
            String::new()
        }
    );
    s.push_str("<h2>Held-out error of each parameter set</h2>");
    let curves = history_curves(points);
    if curves.is_empty() {
        s.push_str("<p class=\"note\">No parameter set of this robot has been validated yet: nothing to plot.</p>");
    } else if validated == 0 {
        s.push_str(&figure(
            &plot::learning_curve_svg(
                "No held-out validation yet: in-sample figures only",
                "parameter set version",
                "|e| on the sessions it was fitted on (mm)",
                &curves,
            ),
            "No set of this robot has a held-out validation: the points are in-sample figures (fit residuals on \
             sessions each set was fitted on), which say nothing of the error elsewhere.",
        ));
    } else {
        s.push_str(&figure(
            &plot::learning_curve_svg(
                "Latest held-out validation of each set: calibrated mean, p95, max and the nominal mean",
                "parameter set version",
                "|e| on held-out poses (mm)",
                &curves,
            ),
            "Each set's latest held-out validation (the calibrated model's error on validation sessions it was \
             not fitted on) and, for reference, the nominal model's mean error on the same poses. A set without one \
             has no point. In-sample figures (a validation on sessions the set was fitted on, e.g. after accepting \
             a diagnosis that pooled them) are their own curve: fit residuals, not a validation.",
        ));
    }
    let rows: Vec<Vec<String>> = points
        .iter()
        .map(|p| {
            vec![
                p.version.to_string(),
                esc(&p.created_at),
                esc(&p.sessions.join(", ")),
                match (p.active, p.archived) {
                    (true, _) => "active".into(),
                    (_, true) => "archived".into(),
                    _ => String::new(),
                },
                opt(p.mean_mm, 4),
                opt(p.p95_mm, 4),
                opt(p.max_mm, 4),
                opt(p.nominal_mean_mm, 4),
                opt(p.in_sample_mean_mm, 4),
                esc(&p.in_sample_sessions.join(", ")),
                esc(p.verdict.as_deref().unwrap_or("")),
            ]
        })
        .collect();
    s.push_str(&table(
        "Parameter sets, oldest first (figures in mm: held-out from each set's latest held-out validation; \
         in-sample apart)",
        &[
            "version",
            "created",
            "identified from",
            "state",
            "held-out mean",
            "p95",
            "max",
            "nominal mean",
            "in-sample mean",
            "in-sample on",
            "diagnosis",
        ],
        &rows,
        &[true, false, false, false, true, true, true, true, true, false, false],
    ));
    page(&format!("Calibration history — {robot}"), &s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_history_page_plots_the_validated_sets_and_lists_them_all() {
        let points = vec![
            HistoryPoint { version: 1, created_at: "2026-11-01T10:00:00Z".into(), ..Default::default() },
            HistoryPoint {
                version: 2,
                created_at: "2026-11-02T10:00:00Z".into(),
                sessions: vec!["trical-1".into()],
                active: true,
                mean_mm: Some(0.0351),
                p95_mm: Some(0.07),
                max_mm: Some(0.091),
                nominal_mean_mm: Some(2.652),
                verdict: Some("none".into()),
                ..Default::default()
            },
            HistoryPoint {
                version: 3,
                mean_mm: Some(0.03),
                p95_mm: Some(0.06),
                max_mm: Some(0.08),
                ..Default::default()
            },
        ];
        let curves = history_curves(&points);
        assert_eq!(curves.len(), 4, "no in-sample figure: no in-sample curve");
        assert_eq!(curves[0].points, vec![(2.0, [0.0351; 5]), (3.0, [0.03; 5])]);
        assert_eq!(curves[3].points.len(), 1);
        let html = history_report("cell-3 irb120", &points);
        assert_eq!(html.matches("<svg").count(), 1);
        assert_eq!(html.matches("<tr>").count(), 4, "header and three sets");
        assert!(html.contains("0.0351") && html.contains("active") && html.contains("trical-1"));
        assert!(!html.contains("<script") && !html.contains("http://") && !html.contains("https://"));
        // An in-sample figure is its own curve and column, never a held-out point.
        let mut with = points.clone();
        with[2].in_sample_mean_mm = Some(0.029);
        with[2].in_sample_sessions = vec!["tracker-n1".into()];
        let curves = history_curves(&with);
        assert_eq!(curves.len(), 5);
        assert_eq!(curves[4].label, "in-sample (not held out), mean |e|");
        assert_eq!(curves[4].points, vec![(3.0, [0.029; 5])]);
        assert_eq!(curves[0].points.len(), 2, "the held-out curve is unchanged");
        let html = history_report("r", &with);
        assert!(html.contains("1 with an in-sample one") && html.contains("tracker-n1"), "{html}");
        // Only in-sample figures: plotted under a title that says so.
        let only = vec![HistoryPoint { version: 1, in_sample_mean_mm: Some(0.03), ..Default::default() }];
        assert!(history_report("r", &only).contains("No held-out validation yet"));
        // Nothing validated: a note, no plot.
        let html = history_report("r", &points[..1]);
        assert_eq!(html.matches("<svg").count(), 0);
        assert!(html.contains("nothing to plot"));
    }
}

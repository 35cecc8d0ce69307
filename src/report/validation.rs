//! The validation report (thesis §5.4, Tables 5.2–5.4, Fig. 5.11–5.28): the before/after table,
//! per-axis statistics with Shapiro–Wilk, the error distributions (histogram, CDF, Q–Q; pooled
//! and per axis), error against distance to the base and to the calibration zone with the fitted
//! lines, and the validation poses seen from the top, front and side, shaded by error.
//!
//! Its input is the validation report's wire form ([`ValidationOut`], as `robocal validate
//! --residuals` writes it and the service stores it), read back with [`read_validation`].

use crate::domain::cell::PurposeSpec;
use crate::domain::validation::{FitOut, ModelErrorsOut, ReferenceOut, ResidualOut, ValidationOut};

use super::html::{esc, figure, fixed, mm, opt, p_value, table};
use super::plot::{self, ScatterSeries};

/// Read a stored validation document (this version's or an earlier one's: the fields it lacks
/// are absent, and the report leaves out what they would tell); the error names the field.
pub fn read_validation(v: &serde_json::Value) -> Result<ValidationOut, String> {
    serde_path_to_error::deserialize(v).map_err(|e| format!("validation report: {}: {}", e.path(), e.inner()))
}

/// The number of plots [`validation_sections`] draws for this document.
pub fn plot_count(v: &ValidationOut) -> usize {
    let Some(res) = v.residuals.as_ref().filter(|r| !r.is_empty()) else { return 0 };
    // Histogram, the CDFs of the calibrated and the nominal model (each on its own scale),
    // Q–Q, per-axis grid; |e| against each distance, calibrated and nominal apart.
    let mut n = 5;
    n += 2 * usize::from(v.calibrated.vs_base_distance.is_some());
    n +=
        2 * usize::from(v.calibrated.vs_zone_distance.is_some() && res.iter().all(|r| r.distance_to_zone_mm.is_some()));
    n += usize::from(res.iter().all(|r| r.position_mm.is_some()));
    n
}

/// The before/after rows (Table 5.4): statistic, nominal, calibrated, change.
pub fn before_after_rows(v: &ValidationOut) -> Vec<Vec<String>> {
    let (c, n) = (&v.calibrated.position, &v.nominal.position);
    let row = |name: &str, nom: f64, cal: f64| {
        let change = if nom != 0.0 { format!("{} %", fixed(100.0 * (cal - nom) / nom, 1)) } else { "—".into() };
        vec![esc(name), mm(nom), mm(cal), change]
    };
    vec![
        row("mean |e|", n.mean_mm, c.mean_mm),
        row("median |e|", n.median_mm, c.median_mm),
        row("σ |e|", n.std_mm, c.std_mm),
        row("RMS |e|", n.rms_mm, c.rms_mm),
        row("p95 |e|", n.p95_mm, c.p95_mm),
        row("max |e|", n.max_mm, c.max_mm),
    ]
}

fn axis_rows(m: &ModelErrorsOut, model: &str) -> Vec<Vec<String>> {
    [("x", &m.per_axis.x), ("y", &m.per_axis.y), ("z", &m.per_axis.z)]
        .into_iter()
        .map(|(k, a)| {
            vec![
                esc(model),
                k.to_string(),
                mm(a.mean_mm),
                mm(a.std_mm),
                mm(a.min_mm),
                mm(a.max_mm),
                opt(a.shapiro_w, 4),
                a.shapiro_p.map_or("—".into(), p_value),
            ]
        })
        .collect()
}

fn fit_cell(f: &Option<FitOut>) -> [String; 4] {
    match f {
        Some(f) => [
            format!("{} ± {}", fixed(f.slope_mm_per_mm * 1e3, 3), fixed(f.slope_stderr_mm_per_mm * 1e3, 3)),
            mm(f.intercept_mm),
            fixed(f.r2, 4),
            p_value(f.p),
        ],
        None => ["—".into(), "—".into(), "—".into(), "—".into()],
    }
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next().map_or_else(String::new, |f| f.to_uppercase().collect::<String>() + c.as_str())
}

/// The validation's sections (tables and plots), for a page of its own or inside the
/// identification's report.
pub fn validation_sections(v: &ValidationOut) -> String {
    let mut s = String::new();
    let sessions: Vec<String> =
        v.sessions.iter().zip(&v.purposes).map(|(s, p)| format!("{} ({})", esc(s), esc(p.as_str()))).collect();
    s.push_str(&format!(
        "<p class=\"meta\">Validated on {}; {} measurements; errors = {} − model, in the artefact frame {{W}}.</p>",
        sessions.join(", "),
        v.calibrated.n,
        match v.reference {
            ReferenceOut::Truth => "true position (virtual cell)",
            ReferenceOut::Measured => "measured position",
        }
    ));
    match (v.held_out, &v.held_out_statement) {
        (Some(true), Some(why)) => s.push_str(&format!("<p class=\"meta\">{}.</p>", esc(&capitalised(why)))),
        (Some(false), Some(why)) => s.push_str(&format!("<p class=\"warn\">{}.</p>", esc(&capitalised(why)))),
        _ => {}
    }
    if v.purposes.contains(&PurposeSpec::Identification) {
        s.push_str(
            "<p class=\"warn\">Some sessions were used for the identification: their figures score the fit, \
             not the model's validity.</p>",
        );
    }
    s.push_str("<h2>Before and after calibration</h2>");
    s.push_str(&table(
        "Position error |e|, mm (cf. thesis Table 5.4)",
        &["statistic", "nominal (mm)", "calibrated (mm)", "change"],
        &before_after_rows(v),
        &[false, true, true, true],
    ));
    if let (Some(c), Some(n)) = (&v.calibrated.orientation, &v.nominal.orientation) {
        s.push_str(&table(
            &format!("Orientation error over the {} full-pose measurements, mrad", c.n),
            &["model", "mean (mrad)", "σ (mrad)", "p95 (mrad)", "max (mrad)"],
            &[
                vec![
                    "nominal".into(),
                    fixed(n.mean_mrad, 3),
                    fixed(n.std_mrad, 3),
                    fixed(n.p95_mrad, 3),
                    fixed(n.max_mrad, 3),
                ],
                vec![
                    "calibrated".into(),
                    fixed(c.mean_mrad, 3),
                    fixed(c.std_mrad, 3),
                    fixed(c.p95_mrad, 3),
                    fixed(c.max_mrad, 3),
                ],
            ],
            &[false, true, true, true, true],
        ));
    }
    let mut rows = axis_rows(&v.calibrated, "calibrated");
    rows.extend(axis_rows(&v.nominal, "nominal"));
    s.push_str(&table(
        "Signed error per axis of {W}, mm, with Shapiro–Wilk (cf. Tables 5.2–5.3)",
        &["model", "axis", "mean (mm)", "σ (mm)", "min (mm)", "max (mm)", "W", "p"],
        &rows,
        &[false, false, true, true, true, true, true, true],
    ));
    let sw = |m: &ModelErrorsOut| {
        m.shapiro.as_ref().map_or("—".into(), |t| format!("W = {}, p = {}", fixed(t.w, 4), p_value(t.p)))
    };
    s.push_str(&format!("<p>Shapiro–Wilk on |e|: calibrated {}; nominal {}.</p>", sw(&v.calibrated), sw(&v.nominal)));
    if v.per_session.len() > 1 {
        let rows: Vec<Vec<String>> = v
            .per_session
            .iter()
            .map(|p| {
                vec![
                    esc(&p.session),
                    esc(p.purpose.as_str()),
                    p.calibrated.n.to_string(),
                    mm(p.nominal.position.mean_mm),
                    mm(p.calibrated.position.mean_mm),
                    mm(p.calibrated.position.std_mm),
                    mm(p.calibrated.position.p95_mm),
                    mm(p.calibrated.position.max_mm),
                ]
            })
            .collect();
        s.push_str(&table(
            "Per session, mm",
            &["session", "purpose", "n", "nominal mean", "mean", "σ", "p95", "max"],
            &rows,
            &[false, false, true, true, true, true, true, true],
        ));
    }
    let fits = [
        ("distance to the base", &v.calibrated.vs_base_distance, &v.nominal.vs_base_distance),
        ("distance to the zone centre", &v.calibrated.vs_zone_distance, &v.nominal.vs_zone_distance),
    ];
    let mut rows = Vec::new();
    for (what, c, n) in fits {
        for (model, f) in [("calibrated", c), ("nominal", n)] {
            let mut r = vec![esc(what), model.to_string()];
            r.extend(fit_cell(f));
            rows.push(r);
        }
    }
    s.push_str(&table(
        "Regression of |e| on distance (cf. Fig. 5.15–5.16)",
        &["against", "model", "slope (mm/m) ± 1σ", "intercept (mm)", "R²", "p (slope = 0)"],
        &rows,
        &[false, false, true, true, true, true],
    ));

    let Some(res) = v.residuals.as_ref().filter(|r| !r.is_empty()) else {
        s.push_str(
            "<p class=\"note\">This validation was stored without its per-measurement residuals: no plots. \
             Validate again with residuals to draw them.</p>",
        );
        return s;
    };
    let cal: Vec<f64> = res.iter().map(|r| r.error_norm_mm).collect();
    let nom: Vec<f64> = res.iter().map(|r| r.nominal_error_norm_mm).collect();
    distribution_section(&mut s, v, res, &cal, &nom);
    distance_section(&mut s, v, res, &cal, &nom);
    positions_section(&mut s, v, res, &cal);
    s
}

/// The distributions of the position errors: histogram, CDFs, Q–Q, per axis.
fn distribution_section(s: &mut String, v: &ValidationOut, res: &[ResidualOut], cal: &[f64], nom: &[f64]) {
    s.push_str("<h2>Distribution of the position errors</h2>");
    // Each model on its own scale: the nominal model's errors are a hundred times the calibrated
    // one's, and on one axis the calibrated curve would be a flat line at zero.
    let [hist, cdf, qq] = plot::distribution_svgs("|e|", "mm", cal, None);
    let [_, nominal_cdf, _] = plot::distribution_svgs("|e| of the nominal model", "mm", nom, None);
    s.push_str(&figure(&hist, "Calibrated |e| with the normal of the same mean and σ (cf. Fig. 5.17)."));
    s.push_str(&figure(&cdf, "Empirical CDF of the calibrated |e| (solid) with its fitted normal (dashed)."));
    s.push_str(&figure(
        &nominal_cdf,
        "Empirical CDF of the nominal model's |e| on the same poses, on its own scale (with its fitted normal).",
    ));
    s.push_str(&figure(&qq, "Normal Q–Q plot of the calibrated |e|: points on the line are normal."));
    let axes: [Vec<f64>; 3] = std::array::from_fn(|k| res.iter().map(|r| r.error_mm[k]).collect());
    s.push_str(&figure(
        &plot::per_axis_svg([&axes[0], &axes[1], &axes[2]], "mm"),
        &format!(
            "Signed calibrated error per axis of {{W}}: histogram, CDF and Q–Q (cf. Fig. 5.18–5.28). Shapiro–Wilk p: x {}, y {}, z {}.",
            v.calibrated.per_axis.x.shapiro_p.map_or("—".into(), p_value),
            v.calibrated.per_axis.y.shapiro_p.map_or("—".into(), p_value),
            v.calibrated.per_axis.z.shapiro_p.map_or("—".into(), p_value)
        ),
    ));
}

/// |e| of each model against the distance to the base and to the calibration zone.
fn distance_section(s: &mut String, v: &ValidationOut, res: &[ResidualOut], cal: &[f64], nom: &[f64]) {
    s.push_str("<h2>Error against distance</h2>");
    let line = |f: &Option<FitOut>| f.as_ref().map(|f| (f.slope_mm_per_mm, f.intercept_mm));
    let r2 = |f: &Option<FitOut>| f.as_ref().map_or("—".into(), |f| fixed(f.r2, 3));
    // One panel per model, each on its own |e| scale (the nominal errors would flatten the
    // calibrated ones against zero).
    let mut against = |what: &str, x_desc: &str, d: &[f64], fits: (&Option<FitOut>, &Option<FitOut>), fig: &str| {
        for (model, errors, fit) in [("calibrated", &cal, fits.0), ("nominal", &nom, fits.1)] {
            let points: Vec<(f64, f64)> = d.iter().zip(errors.iter()).map(|(x, e)| (*x, *e)).collect();
            let svg = plot::scatter_fit_svg(
                &format!("|e| of the {model} model against the distance to {what}"),
                x_desc,
                "|e| (mm)",
                &[ScatterSeries { label: model, points: &points, line: line(fit) }],
            );
            s.push_str(&figure(&svg, &format!("Least-squares line: {model} R² = {} (cf. Fig. {fig}).", r2(fit))));
        }
    };
    if v.calibrated.vs_base_distance.is_some() {
        let d: Vec<f64> = res.iter().map(|r| r.distance_to_base_mm).collect();
        against(
            "the base",
            "distance to the base origin (mm)",
            &d,
            (&v.calibrated.vs_base_distance, &v.nominal.vs_base_distance),
            "5.15",
        );
    }
    let zone: Option<Vec<f64>> = res.iter().map(|r| r.distance_to_zone_mm).collect();
    if let (Some(zone), Some(_)) = (&zone, &v.calibrated.vs_zone_distance) {
        against(
            "the calibration zone",
            "distance to the balls' centroid (mm)",
            zone,
            (&v.calibrated.vs_zone_distance, &v.nominal.vs_zone_distance),
            "5.16",
        );
    }
}

/// Where the validation poses are, shaded by their calibrated |e|.
fn positions_section(s: &mut String, v: &ValidationOut, res: &[ResidualOut], cal: &[f64]) {
    let positions: Option<Vec<[f64; 3]>> = res.iter().map(|r| r.position_mm).collect();
    if let Some(p) = positions {
        s.push_str("<h2>Where the validation poses are</h2>");
        let (lo, hi) = cal.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| (a.min(*x), b.max(*x)));
        s.push_str(&figure(
            &plot::projections_svg(&p, cal, v.balls_mm.as_ref()),
            &format!(
                "Measured positions in {{W}}, darker and larger for a larger calibrated |e| ({} mm to {} mm); \
                 × the artefact's balls, dashed their triangle (the calibration zone) (cf. Fig. 5.11–5.14).",
                mm(lo),
                mm(hi)
            ),
        ));
    }
}

/// The whole validation report page.
pub fn validation_report(v: &ValidationOut) -> String {
    super::html::page("Validation report", &validation_sections(v))
}

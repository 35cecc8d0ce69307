//! The identification's report: the parameter set (cf. thesis Table 5.1) — each parameter's
//! nominal and identified value, the change and its uncertainty (±1.96σ, 95 %), drawn as error
//! bars per unit — the fit's quality (κ in SI units against the thesis's ≤ 1000 criterion, κ of
//! the scaled Jacobian, O1, the residual against the instrument's prediction), and the set's
//! latest validation when there is one.

use serde_json::Value;

use super::html::{esc, figure, fixed, mm, page, sig, table};
use super::plot;
use super::validation::validation_sections;
use crate::domain::Quality;
use crate::domain::param_set::{ParamEntry, ParameterSetFile};
use crate::domain::validation::ValidationOut;

/// Decimals of a value and of its σ in `unit`: µm for mm, 0.1 mdeg (≈ 1.7 µrad) for deg.
fn decimals(unit: &str) -> Option<(usize, usize)> {
    match unit {
        "mm" => Some((3, 4)),
        "deg" => Some((4, 5)),
        _ => None,
    }
}

fn value(v: f64, unit: &str, sigma: bool) -> String {
    match decimals(unit) {
        Some((d, ds)) => fixed(v, if sigma { ds } else { d }),
        None => sig(v),
    }
}

/// The 95 % half-width of a parameter: 1.96 σ.
pub const Z95: f64 = 1.959963984540054;

/// One parameter's row: name, unit, nominal, identified, change, σ, ±95 %, status.
pub fn parameter_row(p: &ParamEntry) -> Vec<String> {
    let unit = p.unit.as_deref().unwrap_or("");
    let change = p.nominal.map(|n| p.value - n);
    vec![
        esc(&p.name),
        esc(unit),
        p.nominal.map_or("—".into(), |n| value(n, unit, false)),
        value(p.value, unit, false),
        change.map_or("—".into(), |c| value(c, unit, false)),
        p.std.map_or("—".into(), |s| value(s, unit, true)),
        p.std.map_or("—".into(), |s| value(Z95 * s, unit, true)),
        esc(p.status.as_deref().unwrap_or("")),
    ]
}

/// The quality rows: what, value, comment.
pub fn quality_rows(quality: &Quality) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    let mut push = |what: &str, v: String, note: &str| rows.push(vec![esc(what), v, esc(note)]);
    if let Some(s) = &quality.sessions {
        push("sessions", esc(&s.join(", ")), "");
    }
    for (v, what) in [
        (quality.n_measurements, "measurements"),
        (quality.n_parameters, "parameters identified"),
        (quality.iterations, "iterations"),
    ] {
        if let Some(v) = v {
            push(what, v.to_string(), "");
        }
    }
    if let Some(k) = quality.kappa_si {
        let note = if k <= 1000.0 {
            "≤ 1000: the thesis's criterion is met"
        } else {
            "> 1000: above the thesis's criterion"
        };
        push("κ(J), SI units (m, rad)", sig(k), note);
    }
    if let Some(k) = quality.kappa_scaled {
        push("κ(J), columns scaled", sig(k), "what the kappa limit refuses on");
    }
    if let Some(o) = quality.observability_si.as_ref().and_then(|o| o.o1) {
        push("O1 (observability, SI)", sig(o), "larger is better (Borm & Menq)");
    }
    if let Some(v) = quality.rms_residual_mm {
        push("residual RMS", format!("{} mm", mm(v)), "");
    }
    if let Some(v) = quality.expected_rms_mm {
        push("RMS the instrument predicts", format!("{} mm", mm(v)), "");
    }
    if let Some(v) = quality.residual_ratio {
        // The ratio leaves out the outliers a robust loss down-weighted: say what it is of when
        // that is not the RMS above.
        let of = quality
            .expected_rms_mm
            .map(|e| v * e)
            .filter(|r| r.is_finite() && quality.rms_residual_mm.is_some_and(|all| (r - all).abs() > 0.005 * all));
        if let Some(r) = of {
            push("residual RMS, outliers left out", format!("{} mm", mm(r)), "what the ratio below is of");
        }
        push("residual / predicted", fixed(v, 2), "near 1: the residual is the instrument's noise");
    }
    if let Some(v) = quality.sigma_mm {
        push("σ̂ of the residuals", format!("{} mm", mm(v)), "");
    }
    if let Some(v) = quality.sigma_ratio {
        push("σ̂ / instrument σ (weighted)", fixed(v, 3), "");
    }
    if let Some(p) = &quality.payload {
        let kg = |m: Option<f64>, s: Option<f64>| match (m, s) {
            (Some(m), Some(s)) => format!("{} ± {} kg", fixed(m, 3), fixed(s, 3)),
            (Some(m), None) => format!("{} kg, not determined (held)", fixed(m, 3)),
            _ => "–".to_string(),
        };
        let at = p
            .com_mm
            .map_or(String::new(), |c| format!(" at ({}, {}, {}) mm", fixed(c[0], 1), fixed(c[1], 1), fixed(c[2], 1)));
        push(
            &format!("payload not declared: mass with its centre of mass{at} in the flange frame"),
            kg(p.mass_kg, p.std_kg),
            "σ for this centre of mass, the robot file's link masses taken as exact",
        );
        if let Some(f) = &p.at_flange {
            match &f.failed {
                Some(e) => push("the same with its centre of mass at the flange", "no fit".to_string(), e),
                None => push(
                    "the same with its centre of mass at the flange",
                    kg(f.mass_kg, f.std_kg),
                    &f.rms_residual_mm.map_or(String::new(), |r| {
                        let against =
                            quality.rms_residual_mm.map_or(String::new(), |a| format!(" against {} mm", fixed(a, 4)));
                        format!("residual RMS {} mm{against}", fixed(r, 4))
                    }),
                ),
            }
        }
        if let Some(c) = &p.with_centre_of_mass {
            let label = "the same with its centre of mass identified too";
            match (&c.failed, c.com_mm, c.com_std_mm) {
                (Some(e), _, _) => push(label, "no fit".to_string(), e),
                (None, Some(m), Some(s)) => {
                    let at = format!(
                        "centre of mass ({} ± {}, {} ± {}, {} ± {}) mm",
                        fixed(m[0], 1),
                        fixed(s[0], 1),
                        fixed(m[1], 1),
                        fixed(s[1], 1),
                        fixed(m[2], 1),
                        fixed(s[2], 1)
                    );
                    let verdict = match c.undetermined_because() {
                        None => "determined by these data".to_string(),
                        Some(why) => format!("not determined by these data ({why})"),
                    };
                    push(label, kg(c.mass_kg, c.std_kg), &format!("{at}: {verdict}"));
                }
                _ => push(label, kg(c.mass_kg, c.std_kg), "which places no centre of mass"),
            }
        }
    }
    rows
}

/// The parameters of one unit that carry an uncertainty: the unit, their names, and per
/// parameter (change from nominal, 95 % half-width).
pub type BarGroup = (String, Vec<String>, Vec<(f64, f64)>);

/// The parameters with an uncertainty, grouped by unit.
pub fn error_bar_groups(set: &ParameterSetFile) -> Vec<BarGroup> {
    let mut groups: Vec<BarGroup> = Vec::new();
    for p in &set.parameters {
        let (Some(s), Some(n)) = (p.std, p.nominal) else { continue };
        let unit = p.unit.clone().unwrap_or_default();
        let k = match groups.iter().position(|g| g.0 == unit) {
            Some(k) => k,
            None => {
                groups.push((unit, Vec::new(), Vec::new()));
                groups.len() - 1
            }
        };
        groups[k].1.push(p.name.clone());
        groups[k].2.push((p.value - n, Z95 * s));
    }
    groups
}

/// The identification's sections: quality, parameter table, error bars.
pub fn parameter_sections(set: &ParameterSetFile) -> String {
    let mut s = String::new();
    let robot = set.robot.get("name").or_else(|| set.robot.get("preset")).and_then(Value::as_str).unwrap_or("robot");
    s.push_str(&format!("<p class=\"meta\">Robot: {}; {} parameters.</p>", esc(robot), set.parameters.len()));
    if let Some(quality) = &set.quality {
        s.push_str("<h2>Quality of the identification</h2>");
        s.push_str(&table("", &["figure", "value", "comment"], &quality_rows(quality), &[false, true, false]));
    } else {
        s.push_str(
            "<p class=\"note\">This parameter set carries no identification quality (imported, or made by hand).</p>",
        );
    }
    s.push_str("<h2>Parameters</h2>");
    let rows: Vec<Vec<String>> = set.parameters.iter().map(parameter_row).collect();
    s.push_str(&table(
        "Nominal and identified values, the change, σ and the 95 % half-width 1.96σ (cf. Table 5.1)",
        &["parameter", "unit", "nominal", "identified", "change", "σ", "±95 %", "status"],
        &rows,
        &[false, false, true, true, true, true, true, false],
    ));
    let groups = error_bar_groups(set);
    if groups.is_empty() {
        s.push_str("<p class=\"note\">No parameter has an uncertainty: no error bars to draw.</p>");
    }
    for (unit, names, bars) in &groups {
        let u = if unit.is_empty() { "1".to_string() } else { unit.clone() };
        let svg = plot::error_bars_svg(
            &format!("Change from nominal, parameters in {u}"),
            &format!("identified − nominal ({u})"),
            names,
            bars,
        );
        s.push_str(&figure(
            &svg,
            "Identified − nominal with its 95 % interval (±1.96σ); the dashed line is no change.",
        ));
    }
    s
}

/// Where an identification report's set comes from: the one line of the page the front ends
/// write differently (the service names its stored set, the command line its files).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReportSource {
    /// The set: `parameter set <id>, version <n>` or `parameter-set file <path>`.
    pub set: String,
    /// When it was made (RFC 3339).
    pub made: Option<String>,
    /// What it was made from: the sessions and the robot, or the cell file.
    pub input: Option<String>,
}

impl ReportSource {
    /// The line, marked `class="meta source"` (the pages of the two front ends differ in it only).
    pub fn html(&self) -> String {
        let mut s = format!("<p class=\"meta source\">{}", esc(&self.set));
        if let Some(m) = &self.made {
            s.push_str(&format!("; made {}", esc(m)));
        }
        if let Some(i) = &self.input {
            s.push_str(&format!(" from {}", esc(i)));
        }
        s.push_str(".</p>\n");
        s
    }
}

/// The identification's report page, with the set's latest validation when given, headed by
/// where the set comes from.
pub fn parameter_set_report(
    set: &ParameterSetFile,
    validation: Option<&ValidationOut>,
    source: &ReportSource,
) -> String {
    let mut body = source.html();
    body.push_str(&parameter_sections(set));
    match validation {
        Some(v) => {
            body.push_str("<h2>Latest validation</h2>");
            body.push_str(&validation_sections(v));
        }
        None => body.push_str("<p class=\"note\">No validation of this parameter set yet.</p>"),
    }
    page("Identification report", &body)
}

//! The reports against the data they draw: one `<svg` per expected plot, the tables' numbers
//! recomputed from the SI reports, nothing fetched from anywhere.

use serde_json::json;

use super::*;
use crate::cell::Purpose;
use crate::domain::ParameterSetDoc;
use crate::domain::diagnosis::DiagnosisOut;
use crate::domain::validation::report_to_json;
use crate::kinematics::Param;
use crate::sim::simulate::{SimulateOptions, Simulated, simulate};
use crate::units::MM;
use crate::validate::report::{Reference, ValidationReport, validate};

fn sim() -> Simulated {
    simulate(&SimulateOptions { seed: 5, id_per_ball: 10, validation: 40, ..Default::default() }).unwrap()
}

fn validation(sim: &Simulated) -> ValidationReport {
    let sessions: Vec<String> = sim.cell.sessions_for(Purpose::Validation).map(|s| s.name.clone()).collect();
    validate(&sim.truth.set, &sim.cell, &sessions, Reference::Measured).unwrap()
}

fn count(html: &str, what: &str) -> usize {
    html.matches(what).count()
}

/// Nothing a browser would fetch, nothing it would run.
fn self_contained(html: &str) {
    assert!(!html.contains("<script"), "a script");
    assert!(!html.contains("http"), "a URL");
    assert!(!html.contains("src="), "an external resource");
    assert!(!html.contains("<p class=\"warn\">plot not drawn"), "a plot failed");
    for (i, _) in html.match_indices("href=") {
        assert!(html[i..].starts_with("href=\"data:"), "a link to somewhere: {}", &html[i..i + 40]);
    }
    assert!(html.starts_with("<!DOCTYPE html>") && html.trim_end().ends_with("</html>"));
}

#[test]
fn the_validation_report_draws_every_plot_and_tells_the_reports_numbers() {
    let sim = sim();
    let report = validation(&sim);
    let doc = read_validation(&report_to_json(&report, true)).unwrap();
    let t = std::time::Instant::now();
    let html = validation_report(&doc);
    let elapsed = t.elapsed();
    self_contained(&html);
    // Histogram, the calibrated and the nominal CDF (each on its own scale), Q–Q, the per-axis
    // grid, |e| against both distances (calibrated and nominal apart), the projections.
    assert!(sim.cell.artefact.is_some());
    assert_eq!(count(&html, "<svg"), 10);
    assert_eq!(validation::plot_count(&doc), 10);
    // The projections' points: one circle (fill) and one outline per validation pose per view,
    // beside the other plots' circles.
    let n = report.residuals.len();
    assert_eq!(n, 40);

    // The before/after table, from the SI report: mean, σ, max, p95 in mm at µm resolution.
    let (c, nom) = (&report.calibrated.position, &report.nominal.position);
    for (name, a, b) in [
        ("mean |e|", nom.mean, c.mean),
        ("σ |e|", nom.std, c.std),
        ("max |e|", nom.max, c.max),
        ("p95 |e|", nom.p95, c.p95),
    ] {
        let row = format!("<td>{name}</td><td class=\"n\">{:.3}</td><td class=\"n\">{:.3}</td>", a / MM, b / MM);
        assert!(html.contains(&row), "missing row {row}");
    }
    // The regressions' R² and the Shapiro–Wilk p of each axis.
    let r2 = report.calibrated.vs_base_distance.unwrap().r2;
    assert!(html.contains(&format!("calibrated R² = {r2:.3}")), "R² {r2}");
    assert!(html.contains("|e| of the calibrated model against the distance to the base"));
    assert!(html.contains("|e| of the nominal model against the distance to the base"));
    let px = report.calibrated.per_axis[0].shapiro.unwrap().p_value;
    assert!(html.contains(&html::p_value(px)));
    // Rendering is fast (a debug build; a release build is several times faster).
    assert!(elapsed.as_millis() < 2000, "{elapsed:?}");

    // Stored without residuals: the tables, no plot.
    let bare = read_validation(&report_to_json(&report, false)).unwrap();
    let html = validation_report(&bare);
    assert_eq!(count(&html, "<svg"), 0);
    assert!(html.contains("without its per-measurement residuals"));
}

/// The fields of a validation document as robocal wrote it at a commit of
/// `crates/robocal-core/src/formats/validation.rs` (formerly `src/domain/validation.rs`), read
/// from that commit's `ValidationOut`, `SessionErrorsOut` and `ResidualOut`: the top level's and
/// each session's besides the flattened `ModelErrorsOut` ([`MODEL`], unchanged since the first),
/// and whether residuals had `position_mm`.
struct Written {
    top: &'static [&'static str],
    session: &'static [&'static str],
    positions: bool,
}

/// `ModelErrorsOut`'s fields (flattened) and `nominal`, in every version.
const MODEL: &[&str] = &[
    "n",
    "mean_mm",
    "median_mm",
    "std_mm",
    "rms_mm",
    "p95_mm",
    "max_mm",
    "orientation",
    "per_axis",
    "shapiro",
    "vs_base_distance",
    "vs_zone_distance",
    "nominal",
];

/// `ResidualOut`'s fields in every version (`position_mm` came later).
const RESIDUAL: &[&str] = &[
    "session",
    "index",
    "error_mm",
    "error_norm_mm",
    "nominal_error_mm",
    "nominal_error_norm_mm",
    "orientation_error_mrad",
    "nominal_orientation_error_mrad",
    "distance_to_base_mm",
    "distance_to_zone_mm",
];

/// 2d4aa5a (2026-11-22, the first JSON report) up to 1c46f89: no `per_session`, no `balls_mm`,
/// residuals without `position_mm`, nothing about held out.
const BEFORE_PER_SESSION: Written =
    Written { top: &["sessions", "purposes", "reference", "residuals"], session: &[], positions: false };

/// ad0899c (2026-11-24, the HTML report) and de0f43f (`validated_envelope`) up to 8de8956: per
/// session and positions, nothing about held out.
const BEFORE_HELD_OUT: Written = Written {
    top: &["sessions", "purposes", "reference", "residuals", "per_session", "balls_mm", "validated_envelope"],
    session: &["session", "purpose"],
    positions: true,
};

/// Today's document as the version `w` describes wrote it: every field it did not write removed.
fn as_written(today: &serde_json::Value, w: &Written) -> serde_json::Value {
    let keep = |v: &mut serde_json::Value, fields: &[&[&str]]| {
        v.as_object_mut().unwrap().retain(|k, _| fields.iter().any(|f| f.contains(&k.as_str())));
    };
    let mut old = today.clone();
    keep(&mut old, &[w.top, MODEL]);
    for s in old.get_mut("per_session").and_then(|p| p.as_array_mut()).into_iter().flatten() {
        keep(s, &[w.session, MODEL]);
    }
    let position: &[&str] = if w.positions { &["position_mm"] } else { &[] };
    for r in old.get_mut("residuals").and_then(|r| r.as_array_mut()).into_iter().flatten() {
        keep(r, &[RESIDUAL, position]);
    }
    old
}

#[test]
fn validations_stored_by_earlier_versions_render_without_what_they_lack() {
    let sim = sim();
    let report = validation(&sim);
    let today = report_to_json(&report, true);
    let statement = today["held_out_statement"].as_str().unwrap().to_string();

    // Today's: every field, the statement, the per-session table, every plot.
    let doc = read_validation(&today).unwrap();
    assert_eq!(doc.held_out, Some(report.held_out()));
    assert!(doc.per_session.len() > 1 && doc.per_session.iter().all(|p| p.fitted == Some(false)));
    // Read back, it writes the same document: nothing added, nothing lost.
    assert_eq!(serde_json::to_value(&doc).unwrap(), today);
    let html = validation_report(&doc);
    self_contained(&html);
    // The statement, capitalised, in a paragraph of its own.
    let said = html.find(&html::esc(&statement[1..])).expect("the held-out statement");
    let (from, to) = (html[..said].rfind("<p class=").unwrap(), said + html[said..].find("</p>").unwrap() + 4);
    assert!(html[from..said].ends_with(&statement[..1].to_uppercase()));
    assert!(html.contains("Per session, mm"));
    assert_eq!(count(&html, "<svg"), 10);
    let tables = |html: &str| html.split("<h2>Distribution").next().unwrap().to_string();
    // Today's tables without the statement: what a document lacking only it shows.
    let today_tables = tables(&format!("{}{}", &html[..from], &html[to..]));

    for (w, svgs) in [(&BEFORE_HELD_OUT, 10), (&BEFORE_PER_SESSION, 9)] {
        let old = as_written(&today, w);
        assert!(old.get("held_out").is_none() && old.get("held_out_statement").is_none());
        let doc = read_validation(&old).unwrap();
        // What it lacks is absent, not made up.
        assert!(doc.held_out.is_none() && doc.held_out_statement.is_none());
        assert!(doc.fit.is_none() && doc.in_sample_sessions.is_none());
        assert!(doc.per_session.iter().all(|p| p.fitted.is_none() && p.fitted_measurements.is_none()));
        // And it writes back as stored.
        assert_eq!(serde_json::to_value(&doc).unwrap(), old);
        let html = validation_report(&doc);
        self_contained(&html);
        assert!(!html.contains(&html::esc(&statement[1..])), "a held-out statement the document does not make");
        assert_eq!(count(&html, "<svg"), svgs);
        assert_eq!(validation::plot_count(&doc), svgs);
        if w.top.contains(&"per_session") {
            // The same tables as today's but for the statement.
            assert_eq!(tables(&html), today_tables);
        } else {
            // No per-session figures, no positions: no per-session table, no projections.
            assert!(doc.per_session.is_empty() && doc.balls_mm.is_none());
            assert!(doc.residuals.iter().flatten().all(|r| r.position_mm.is_none()));
            assert!(!html.contains("Per session, mm") && !html.contains("Where the validation poses are"));
        }
    }
}

#[test]
fn the_projections_place_every_pose() {
    let sim = sim();
    let report = validation(&sim);
    let positions: Vec<[f64; 3]> = report.residuals.iter().map(|r| (r.position / MM).into()).collect();
    let errors: Vec<f64> = report.residuals.iter().map(|r| r.error.norm() / MM).collect();
    let balls: Option<[[f64; 3]; 3]> = report.balls.map(|b| b.map(|c| (c / MM).into()));
    let svg = plot::projections_svg(&positions, &errors, balls.as_ref());
    // Three views, each a filled circle and an outline per pose.
    assert_eq!(count(&svg, "<circle"), 3 * 2 * positions.len());
    // The reference position is the measured one: distance to the base agrees with the report.
    let base = sim.truth.set.chain().base().t / MM;
    for (r, p) in report.residuals.iter().zip(&positions) {
        let d = ((p[0] - base.x).powi(2) + (p[1] - base.y).powi(2) + (p[2] - base.z).powi(2)).sqrt();
        assert!((d - r.distance_to_base / MM).abs() < 1e-9);
    }
}

#[test]
fn the_identification_report_tabulates_each_parameter_with_its_error_bar() {
    let sim = sim();
    let mut set = sim.truth.set.clone();
    let a2 = set.layout.index_of(Param::A(2)).unwrap();
    set.values[a2] = set.nominal[a2] + 0.000146;
    let mut doc = ParameterSetDoc::new(set);
    doc.std[a2] = Some(4e-6);
    doc.status[a2] = Some("identified".into());
    let beta = doc.set.layout.index_of(Param::Beta(2)).unwrap();
    doc.std[beta] = Some(1e-5);
    doc.quality = Some(
        serde_json::from_value(
            json!({"kappa_si": 812.5, "kappa_scaled": 40.2, "observability_si": {"O1": 0.0123}, "n_measurements": 30}),
        )
        .unwrap(),
    );
    let file = doc.to_file();
    let html = parameter_set_report(&file, None, &crate::report::ReportSource::default());
    self_contained(&html);
    // Two units with uncertainties (mm, deg): two error-bar plots.
    assert_eq!(count(&html, "<svg"), 2);
    // a2: nominal, identified, change, σ and 1.96σ, mm.
    let nominal = doc.set.nominal[a2] / MM;
    let value = doc.set.values[a2] / MM;
    let row = format!(
        "<td>a2</td><td>mm</td><td class=\"n\">{nominal:.3}</td><td class=\"n\">{value:.3}</td><td class=\"n\">{:.3}</td><td class=\"n\">{:.4}</td><td class=\"n\">{:.4}</td><td>identified</td>",
        value - nominal,
        0.004,
        1.96 * 0.004
    );
    assert!(html.contains(&row), "missing {row}");
    assert!(html.contains("812.5") && html.contains("≤ 1000"));
    assert!(html.contains("No validation of this parameter set yet."));

    // With its validation: the validation's plots follow.
    let v = read_validation(&report_to_json(&validation(&sim), true)).unwrap();
    let html = parameter_set_report(&file, Some(&v), &crate::report::ReportSource::default());
    assert_eq!(count(&html, "<svg"), 2 + 10);
}

fn diagnosis_json() -> serde_json::Value {
    let stats = |n: usize, mean: f64| json!({"n": n, "mean_mm": mean, "median_mm": mean, "std_mm": 0.01, "rms_mm": mean, "p95_mm": mean * 1.5, "max_mm": mean * 2.0});
    json!({
        "verdict": {"status": "named", "summary": "joint 2 cyclic error", "effects": [], "absorbed_by": []},
        "decomposition": {
            "calibrated": stats(40, 0.200), "heldout": stats(40, 0.150),
            "floor": {"mean_mm": 0.050, "rms_mm": 0.06, "p95_mm": 0.09, "instrument_sigma_mm": 0.02, "prediction_rms_mm": 0.01},
            "extrapolation_gap_mm": 0.05, "unmodelled_gap_mm": 0.1
        },
        "where": {"n": 40, "per_axis": {"x": {"mean_mm": 0.0, "std_mm": 0.1}, "y": {"mean_mm": 0.0, "std_mm": 0.1}, "z": {"mean_mm": 0.0, "std_mm": 0.1}},
            "against": [{"variable": "q2", "unit": "deg", "r": 0.5, "profile": [{"at": -30.0, "mean_mm": 0.1, "n": 10}, {"at": 0.0, "mean_mm": 0.2, "n": 10}]},
                {"variable": "tau1", "unit": "N·m", "r": null, "profile": [{"at": 0.0, "mean_mm": 0.1, "n": 10}, {"at": 0.0, "mean_mm": 0.2, "n": 10}]}],
            "voxels": {"size_mm": 100.0, "tested": 4, "above_floor": []}},
        "candidates": [],
        "shrink": [
            {"model": "start", "effects": [], "n": 40, "mean_mm": 0.150, "rms_mm": 0.2, "p95_mm": 0.3, "max_mm": 0.4},
            {"model": "start + cyc2", "effects": ["cyc2"], "n": 40, "mean_mm": 0.080, "rms_mm": 0.1, "p95_mm": 0.2, "max_mm": 0.3, "gap_closure": 0.7}
        ],
        "rounds": [], "unavailable": [], "model": "+cyc2_h1",
        "sessions": {"identification": ["id"], "validation": ["val"], "tested": "validation", "folds": 5},
        "transfer": [], "notes": []
    })
}

#[test]
fn the_diagnosis_decomposes_the_held_out_error() {
    let d: DiagnosisOut = serde_json::from_value(diagnosis_json()).unwrap();
    let rows = diagnosis::decomposition_rows(&d);
    // floor 0.05 + unexplained (0.08 − 0.05) + explained (0.15 − 0.08) = the held-out 0.15 mm.
    let held: Vec<f64> = rows[0].1.iter().map(|s| s.length).collect();
    assert!((held[0] - 0.05).abs() < 1e-12 && (held[1] - 0.03).abs() < 1e-12 && (held[2] - 0.07).abs() < 1e-12);
    let cal: f64 = rows[1].1.iter().map(|s| s.length).sum();
    assert!((cal - 0.2).abs() < 1e-12);
    // Every label of the bars has a shade of its own (the extrapolation gap was the explained
    // part's colour).
    let mut shades: Vec<(String, usize)> = Vec::new();
    for s in rows.iter().flat_map(|r| &r.1) {
        if !shades.iter().any(|(l, _)| *l == s.label) {
            assert!(!shades.iter().any(|(_, k)| *k == s.shade), "{} shares a shade: {shades:?}", s.label);
            shades.push((s.label.clone(), s.shade));
        }
    }
    assert_eq!(shades.len(), 5);
    let html = diagnosis_report(&d);
    self_contained(&html);
    // The decomposition bar and the residual profiles.
    assert_eq!(count(&html, "<svg"), 2);
    assert!(html.contains("<td class=\"n\">70.0 %</td>"), "gap closure");
    // A variable that does not vary (τ1 of a vertical first axis) gets no panel.
    assert!(html.contains("q2 (deg)") && !html.contains("tau1 (N·m)"));
}

/// A group of terms over several joints (backlash on j1 and j2) is one named effect whose
/// `estimate` is its most significant term's; the report lists each term with its σ, where one
/// number would read as the group's size. A cyclic term keeps its one amplitude.
#[test]
fn a_group_effect_lists_each_of_its_terms() {
    let mut v = diagnosis_json();
    let which = |name: &str, label: &str, joint: Option<usize>| {
        json!({"name": name, "label": label, "joint": joint, "from_joint": null, "harmonic": null,
               "frequency_cpr": null, "scanned": false, "step_deg": null})
    };
    let effect = |which: serde_json::Value, estimate: f64, std: f64, params: serde_json::Value| {
        let mut e = which;
        let m = e.as_object_mut().unwrap();
        for (k, x) in [
            ("estimate", json!(estimate)),
            ("std", json!(std)),
            ("unit", json!("deg")),
            ("parameters", params),
            ("gain_mean_mm", json!(0.05)),
            ("gain_rms_mm", json!(0.05)),
            ("confirm_p", json!(1e-9)),
            ("screen_log10_p", json!(-30.0)),
            ("separability", json!(0.9)),
        ] {
            m.insert(k.into(), x);
        }
        e
    };
    let p =
        |name: &str, estimate: f64, std: f64| json!({"name": name, "estimate": estimate, "std": std, "unit": "deg"});
    v["verdict"]["effects"] = json!([
        effect(
            which("backlash", "backlash", None),
            0.0253,
            0.0011,
            json!([p("backlash1", 0.0187, 0.0012), p("backlash2", 0.0253, 0.0011)])
        ),
        effect(
            which("cyclic", "cyclic j3 h2", Some(3)),
            0.0100,
            0.0004,
            json!([p("cyc3_h2_sin", 0.0060, 0.0004), p("cyc3_h2_cos", 0.0080, 0.0004)])
        ),
    ]);
    let d: DiagnosisOut = serde_json::from_value(v).unwrap();
    let html = diagnosis_report(&d);
    self_contained(&html);
    assert!(
        html.contains("<td class=\"n\">backlash1 0.0187 deg<br>backlash2 0.0253 deg</td>"),
        "each backlash term: {html}"
    );
    assert!(html.contains("0.0012 deg<br>"), "each term's σ");
    assert!(html.contains("<td class=\"n\">0.0100 deg</td>"), "the cyclic amplitude alone");
    assert!(!html.contains("cyc3_h2_sin"), "a cyclic term's sine and cosine are its amplitude");
}

/// A partial verdict's effect is a suspect, not added to the model: the table says so and calls
/// its number the screening's estimate. It was listed under "Named effects" (a twice-per-turn
/// term of joint 1 fitted over a 9° sweep: "cyclic j1 h2 5.8623 deg", no σ).
#[test]
fn a_suspect_is_not_listed_as_a_named_effect() {
    let mut v = diagnosis_json();
    v["verdict"]["status"] = json!("partial");
    v["verdict"]["effects"] = json!([{"name": "cyclic", "label": "cyclic j1 h2", "joint": 1, "from_joint": null,
        "harmonic": 2, "frequency_cpr": 2.0, "scanned": false, "step_deg": null, "estimate": 5.8623, "std": null,
        "unit": "deg", "parameters": [{"name": "cyc1_h2_sin", "estimate": -4.374, "std": null, "unit": "deg"},
        {"name": "cyc1_h2_cos", "estimate": -3.903, "std": null, "unit": "deg"}], "gain_mean_mm": 0.17,
        "gain_rms_mm": 0.17, "confirm_p": 7e-4, "screen_log10_p": -37.8, "separability": 0.005}]);
    let d: DiagnosisOut = serde_json::from_value(v.clone()).unwrap();
    let html = diagnosis_report(&d);
    self_contained(&html);
    assert!(!html.contains("Named effects"), "{html}");
    assert!(html.contains("Suspected, not named") && html.contains("screening estimate"), "{html}");
    // Named, the same table keeps its title.
    v["verdict"]["status"] = json!("named");
    let named = diagnosis_report(&serde_json::from_value(v).unwrap());
    assert!(named.contains("Named effects") && !named.contains("Suspected, not named"));
}

#[test]
fn the_quality_table_says_every_reading_of_an_undeclared_payload() {
    use crate::domain::quality::{PayloadAtFlangeQuality, PayloadComQuality, PayloadQuality};
    let quality = crate::domain::Quality {
        rms_residual_mm: Some(0.185),
        payload: Some(PayloadQuality {
            mass_kg: Some(0.568920059528),
            std_kg: Some(0.150075943501),
            com_mm: Some([20.021, 0.0861, 40.3995]),
            at_flange: Some(PayloadAtFlangeQuality {
                mass_kg: Some(0.843283783961),
                std_kg: Some(0.233975438803),
                rms_residual_mm: Some(0.1851),
                ..Default::default()
            }),
            with_centre_of_mass: Some(PayloadComQuality {
                mass_kg: Some(0.95667),
                std_kg: Some(0.55134),
                com_mm: Some([32.21, 20.46, 69.96]),
                com_std_mm: Some([20.81, 19.24, 70.66]),
                determined: Some(false),
                rms_residual_mm: Some(0.1849),
                ..Default::default()
            }),
            ..Default::default()
        }),
        ..Default::default()
    };
    let rows = parameters::quality_rows(&quality);
    assert_eq!(rows.len(), 4, "{rows:?}");
    let rows = &rows[1..];
    assert!(rows[0][0].contains("at (20.0, 0.1, 40.4) mm") && rows[0][1] == "0.569 ± 0.150 kg", "{rows:?}");
    assert_eq!(rows[1][1], "0.843 ± 0.234 kg");
    assert!(rows[1][2].contains("residual RMS 0.1851 mm against 0.1850 mm"), "{rows:?}");
    assert_eq!(rows[2][1], "0.957 ± 0.551 kg");
    assert!(
        rows[2][2]
            == "centre of mass (32.2 ± 20.8, 20.5 ± 19.2, 70.0 ± 70.7) mm: not determined by these data (the σ of x, y, z above 10 mm and the mass within 3 σ of 0)",
        "{rows:?}"
    );
}

/// A payload the free centre-of-mass fit takes to 0 kg or below places no centre of mass: the row
/// says so, and shows no position.
#[test]
fn the_quality_table_says_when_a_payload_places_no_centre_of_mass() {
    use crate::domain::quality::{PayloadComQuality, PayloadQuality};
    let quality = crate::domain::Quality {
        payload: Some(PayloadQuality {
            mass_kg: Some(0.41),
            std_kg: Some(0.12),
            com_mm: Some([20.0, 0.0, 40.0]),
            with_centre_of_mass: Some(PayloadComQuality {
                mass_kg: Some(-0.2),
                std_kg: Some(0.5),
                determined: Some(false),
                ..Default::default()
            }),
            ..Default::default()
        }),
        ..Default::default()
    };
    let rows = parameters::quality_rows(&quality);
    let last = rows.last().expect("rows");
    assert_eq!(last[1], "-0.200 ± 0.500 kg", "{rows:?}");
    assert_eq!(last[2], "which places no centre of mass", "{rows:?}");
}

//! The validation report as a person reads it on a terminal: the before/after table (nominal and
//! calibrated model), the same per session, per-axis statistics with their normality test, and
//! the error's trend with the distance to the base and to the calibration zone. The numbers are
//! the JSON report's (`--format json`), printed at 1 µm (the report's own resolution is finer).

use std::fmt::Write;

use crate::domain::validation::{AxisOut, FitOut, ModelErrorsOut, ReferenceOut, ValidationOut};

fn row(out: &mut String, w: usize, name: &str, m: &ModelErrorsOut) {
    let p = &m.position;
    let _ = writeln!(
        out,
        "  {name:<w$} {:>5} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
        m.n, p.mean_mm, p.median_mm, p.std_mm, p.rms_mm, p.p95_mm, p.max_mm
    );
}

fn header(out: &mut String, w: usize) {
    let _ = writeln!(
        out,
        "  {:<w$} {:>5} {:>8} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "", "n", "mean", "median", "std", "rms", "p95", "max"
    );
}

fn axis(out: &mut String, name: &str, a: &AxisOut) {
    let shapiro = match (a.shapiro_w, a.shapiro_p) {
        (Some(w), Some(p)) => format!("W {w:.3}, p {p:.3}"),
        _ => "—".to_string(),
    };
    let _ = writeln!(
        out,
        "    {name}  {:>8.3} {:>8.3} {:>8.3} {:>8.3}   {shapiro}",
        a.mean_mm, a.std_mm, a.min_mm, a.max_mm
    );
}

fn trend(out: &mut String, name: &str, f: Option<&FitOut>) {
    match f {
        Some(f) => {
            let _ = writeln!(
                out,
                "  |error| vs distance to {name:<5} {:+.5} ± {:.5} mm/m (R {:.2}, p {:.3}), {:.3} mm at 0",
                f.slope_mm_per_mm * 1000.0,
                f.slope_stderr_mm_per_mm * 1000.0,
                f.r,
                f.p,
                f.intercept_mm
            );
        }
        None => {
            let _ = writeln!(out, "  |error| vs distance to {name:<5} — (no {name} position known, or too few poses)");
        }
    }
}

/// The report as text.
pub fn text(v: &ValidationOut) -> String {
    let mut s = String::new();
    let reference = match v.reference {
        ReferenceOut::Truth => "the simulator's true TCP positions",
        ReferenceOut::Measured => "the measurements",
    };
    let _ = writeln!(s, "Validation on {} against {reference}", v.sessions.join(", "));
    // Always recorded by this version (`ValidationOut::from_report`).
    if let Some(why) = &v.held_out_statement {
        let _ = writeln!(s, "{why}");
    }
    for note in &v.notes {
        let _ = writeln!(s, "note: {note}");
    }
    let per_session: Vec<(String, String, &crate::domain::validation::SessionErrorsOut)> = if v.per_session.len() > 1 {
        v.per_session
            .iter()
            .map(|p| {
                let head = format!("{} ({})", p.session, p.purpose.as_str());
                (format!("{head}, nominal"), format!("{head}, calibrated"), p)
            })
            .collect()
    } else {
        Vec::new()
    };
    let w = per_session.iter().map(|(_, c, _)| c.chars().count()).max().unwrap_or(0).max(16);
    let _ = writeln!(s, "\nPosition error (mm)");
    header(&mut s, w);
    row(&mut s, w, "nominal model", &v.nominal);
    row(&mut s, w, "calibrated model", &v.calibrated);
    for (n, c, p) in &per_session {
        row(&mut s, w, n, &p.nominal);
        row(&mut s, w, c, &p.calibrated);
    }
    if let (Some(n), Some(c)) = (&v.nominal.orientation, &v.calibrated.orientation) {
        let _ = writeln!(s, "\nOrientation error (mrad)");
        for (name, o) in [("nominal model", n), ("calibrated model", c)] {
            let _ = writeln!(
                s,
                "  {name:<w$} {:>5} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3} {:>8.3}",
                o.n, o.mean_mrad, o.median_mrad, o.std_mrad, o.rms_mrad, o.p95_mrad, o.max_mrad
            );
        }
    }
    let _ = writeln!(s, "\nCalibrated model per axis in {{W}} (mm)");
    let _ = writeln!(s, "        {:>8} {:>8} {:>8} {:>8}   normality (Shapiro–Wilk)", "mean", "std", "min", "max");
    axis(&mut s, "x", &v.calibrated.per_axis.x);
    axis(&mut s, "y", &v.calibrated.per_axis.y);
    axis(&mut s, "z", &v.calibrated.per_axis.z);
    if let Some(sh) = &v.calibrated.shapiro {
        let _ = writeln!(s, "    |error|  W {:.3}, p {:.3}", sh.w, sh.p);
    }
    let _ = writeln!(s, "\nCalibrated model, error against distance");
    trend(&mut s, "base", v.calibrated.vs_base_distance.as_ref());
    trend(&mut s, "zone", v.calibrated.vs_zone_distance.as_ref());
    s.trim_end().to_string()
}

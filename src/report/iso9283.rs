//! The ISO 9283 report (issue 26, item 2): per pose, AP before (nominal) and after calibration
//! (the calibrated model's prediction, never called measured), RP, vAP, the instrument's share of
//! each figure's uncertainty beside it, the distance characteristics, which clauses are
//! implemented and which are not and why. Input: the wire form (`domain::iso9283::IsoReport`).

use std::fmt::Write;

use super::html::{esc, fixed, opt, page, sig, table};
use crate::domain::iso9283::{IsoReport, PoseRow};

fn pm(v: Option<f64>, u: Option<f64>, decimals: usize) -> String {
    match (v, u) {
        (Some(v), Some(u)) => format!("{} ± {}", fixed(v, decimals), fixed(u, decimals + 1)),
        (Some(v), None) => fixed(v, decimals),
        _ => "—".into(),
    }
}

fn abc(v: Option<[f64; 3]>) -> String {
    v.map_or("—".into(), |v| format!("{}, {}, {}", fixed(v[0], 4), fixed(v[1], 4), fixed(v[2], 4)))
}

/// The page for one session: the nominal report, and the calibrated one when given.
pub fn render(session: &str, nominal: &IsoReport, calibrated: Option<&IsoReport>) -> String {
    let mut b = String::new();
    let _ = write!(
        b,
        "<p class=\"meta\">Session {}: {} poses, {} visits, {} poses with at least two cycles.</p>",
        esc(session),
        nominal.summary.poses,
        nominal.summary.visits,
        nominal.summary.repeated_poses
    );
    b.push_str(
        "<div class=\"note\"><b>What “after calibration” means here.</b> The robot was not re-run with compensated \
         targets. The calibrated column is the calibrated model's prediction of where the robot went against the \
         measurement: the AP the compensated program is predicted to reach. It is not a measurement. RP and RD use \
         the measured positions only and are the same for both models: compensation does not change repeatability.</div>",
    );
    b.push_str("<h2>Summary</h2>");
    let mut rows = Vec::new();
    for r in std::iter::once(nominal).chain(calibrated) {
        let s = &r.summary;
        rows.push(vec![
            esc(&r.model),
            fixed(s.ap_p_mean_mm, 3),
            fixed(s.ap_p_max_mm, 3),
            opt(s.ap_p_mean_repeated_mm, 3),
            opt(s.rp_l_mean_mm, 3),
            opt(s.rp_l_max_mm, 3),
            r.registration.as_ref().map_or("—".into(), |g| sig(g.kappa_scaled)),
            r.registration.as_ref().map_or("—".into(), |g| fixed(g.rms_position_mm, 3)),
            r.registration.as_ref().filter(|g| !g.held.is_empty()).map_or("—".into(), |g| esc(&g.held.join(", "))),
        ]);
    }
    b.push_str(&table(
        "",
        &[
            "model",
            "AP_P mean (mm)",
            "AP_P max (mm)",
            "AP_P mean, repeated poses (mm)",
            "RP_l mean (mm)",
            "RP_l max (mm)",
            "registration κ (scaled)",
            "registration RMS (mm)",
            "held in both registrations",
        ],
        &rows,
        &[false, true, true, true, true, true, true, true, false],
    ));

    b.push_str("<h2>Poses with at least two cycles</h2>");
    let cal = |p: &PoseRow| calibrated.and_then(|c| c.poses.iter().find(|q| q.pose == p.pose));
    let rows: Vec<Vec<String>> = nominal
        .poses
        .iter()
        .filter(|p| p.cycles >= 2)
        .map(|p| {
            let c = cal(p);
            vec![
                esc(&p.pose),
                p.cycles.to_string(),
                pm(Some(p.ap_p_mm), p.ap_p_u_mm, 3),
                c.map_or("—".into(), |c| pm(Some(c.ap_p_mm), c.ap_p_u_mm, 3)),
                abc(p.ap_abc_deg),
                c.map_or("—".into(), |c| abc(c.ap_abc_deg)),
                pm(p.rp_l_mm, p.rp_sampling_u_mm, 3),
                opt(p.rp_instrument_floor_mm, 4),
                abc(p.rp_abc_deg),
                opt(p.vap_p_mm, 3),
            ]
        })
        .collect();
    b.push_str(&table(
        "AP ± the instrument's standard uncertainty; RP ± its approximate sampling standard uncertainty",
        &[
            "pose",
            "cycles",
            "AP_P nominal (mm)",
            "AP_P calibrated, predicted (mm)",
            "AP_a, b, c nominal (°)",
            "AP_a, b, c calibrated (°)",
            "RP_l (mm)",
            "RP instrument floor (mm)",
            "RP_a, b, c (± °)",
            "vAP_P (mm)",
        ],
        &rows,
        &[false, true, true, true, true, true, true, true, true, true],
    ));

    if !nominal.distances.is_empty() {
        b.push_str("<h2>Distance accuracy and repeatability (clause 7.5)</h2>");
        let rows: Vec<Vec<String>> = nominal
            .distances
            .iter()
            .enumerate()
            .map(|(i, d)| {
                let c = calibrated.and_then(|c| c.distances.get(i));
                vec![
                    format!("{} → {}", esc(&d.from), esc(&d.to)),
                    d.cycles.to_string(),
                    fixed(d.d_mean_mm, 3),
                    pm(Some(d.ad_p_mm), d.ad_u_mm, 4),
                    c.map_or("—".into(), |c| pm(Some(c.ad_p_mm), c.ad_u_mm, 4)),
                    pm(d.rd_mm, d.rd_sampling_u_mm, 4),
                ]
            })
            .collect();
        b.push_str(&table(
            "",
            &["pair", "cycles", "D̄ (mm)", "AD_P nominal (mm)", "AD_P calibrated, predicted (mm)", "RD (± mm)"],
            &rows,
            &[false, true, true, true, true, true],
        ));
    }

    b.push_str("<h2>Clauses</h2><ul>");
    for (clause, state) in [
        ("7.2.1 pose accuracy AP (position and orientation)", "implemented"),
        ("7.2.2 pose repeatability RP (position and orientation)", "implemented"),
        ("7.2.3 multi-directional pose accuracy variation vAP", "implemented where approach directions are given"),
        ("7.5 distance accuracy AD and repeatability RD", "implemented for positions; orientation components not"),
        (
            "7.3 pose stabilisation time, 7.4 pose overshoot",
            "not implemented: they need the instrument's readings timed along the approach, and a static tracker session holds one reading per stop",
        ),
        ("7.6 drift of pose characteristics", "not implemented: needs timed cycles over hours"),
        ("clause 8 path characteristics", "not implemented: needs a sampled trajectory"),
    ] {
        let _ = write!(b, "<li>{}: {}</li>", esc(clause), esc(state));
    }
    b.push_str("</ul><h2>Notes</h2><ul>");
    for n in calibrated.unwrap_or(nominal).notes.iter() {
        let _ = write!(b, "<li>{}</li>", esc(n));
    }
    b.push_str("</ul>");
    page(&format!("ISO 9283 pose characteristics — {session}"), &b)
}

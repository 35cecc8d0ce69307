//! An identification written as a parameter-set file: per parameter value, nominal, std, unit and
//! status, plus the quality report (in mm and degrees where it has lengths and angles).

use serde_json::{Value, json};

use super::{DEG, MM, ParameterSetDoc};
use crate::identify::Identification;

/// The parameter-set document of an identification; `selection` describes how the measurements
/// were chosen (e.g. DETMAX settings), carried into the quality report.
pub fn identification_doc(id: &Identification, sessions: &[String], selection: Option<Value>) -> ParameterSetDoc {
    let mut doc = ParameterSetDoc::new(id.set.clone());
    doc.std = id.std.clone();
    doc.status = id.status.iter().map(|s| Some(s.clone())).collect();
    let q = &id.quality;
    let m = q.std.len();
    let tools: Vec<Value> = id
        .tools
        .iter()
        .map(|t| {
            let c = &t.tool.tcp;
            json!({
                "sessions": t.sessions,
                "tcp_mm": [c[0] / MM, c[1] / MM, c[2] / MM],
                "tcp_rotation_deg": [c[3] / DEG, c[4] / DEG, c[5] / DEG],
                "std": (0..6).map(|k| t.std[k].map(|s| if k < 3 { s / MM } else { s / DEG })).collect::<Vec<_>>(),
                "status": t.status,
            })
        })
        .collect();
    let corr: Vec<Vec<f64>> = (0..m).map(|a| (0..m).map(|b| q.correlation[(a, b)]).collect()).collect();
    doc.quality = Some(json!({
        "sessions": sessions,
        "selection": selection,
        "n_measurements": q.n_configs,
        "n_rows": q.n_rows,
        "n_parameters": m,
        "iterations": id.iterations,
        "kappa_si": q.kappa,
        "kappa_scaled": q.kappa_scaled,
        "observability_si": {"O1": q.observability.o1, "O2": q.observability.o2, "O3": q.observability.o3, "O4": q.observability.o4, "O5": q.observability.o5},
        "sigma_mm": q.sigma / MM,
        "rms_residual_mm": q.rms_residual / MM,
        "singular_values_si": q.singular_values,
        "free": id.free_names,
        "correlation": corr,
        "tools": tools,
        "downweighted": id.downweighted.iter().map(|(s, i, w)| json!({"session": s, "index": i, "weight": w})).collect::<Vec<_>>(),
    }));
    doc
}

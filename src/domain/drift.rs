//! The drift between two parameter sets of one robot: for each parameter both identify, the two
//! values, the change, the combined standard uncertainty √(σa² + σb²) and the change in units of
//! it; parameters identified in only one of them are listed as such. Values in each parameter's
//! file unit (mm, deg, deg/(N·m), …).
//!
//! The drift terms along a measuring run (`drift_x_p1` …, `identify --model +drift`) are each run's
//! own nuisance, not a property of the robot: they are not compared, and a note says so.
//!
//! "Moved" means |Δ| > σ: one combined standard deviation, the question a dashboard asks ("did
//! this change by more than the sets' own uncertainty?"), not a significance test — with 30-odd
//! parameters some move by more than 1σ by chance; `n_sigma` says by how much.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{DomainError, ParameterSetDoc};
use crate::kinematics::Param;

/// One parameter both sets identify.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct DriftEntry {
    pub name: String,
    pub unit: String,
    /// The value in set A (the one asked about) and in set B (`against`).
    pub value_a: f64,
    pub value_b: f64,
    /// value_a − value_b: how far A moved from B.
    pub change: f64,
    pub std_a: f64,
    pub std_b: f64,
    /// √(std_a² + std_b²).
    pub combined_std: f64,
    /// |change| / combined_std; absent when both σ are zero.
    pub n_sigma: Option<f64>,
    /// |change| > combined_std.
    pub moved: bool,
}

/// The drift of set A against set B.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct DriftReport {
    pub robot: String,
    /// Parameters both sets identify, in A's order.
    pub parameters: Vec<DriftEntry>,
    /// How many of them moved by more than their combined σ.
    pub moved: usize,
    /// Identified in A only (fixed in B, or not in B's model).
    pub only_in_a: Vec<String>,
    /// Identified in B only.
    pub only_in_b: Vec<String>,
    pub notes: Vec<String>,
}

/// Whether parameter `i` of a set was identified: its status says so, or (a file without
/// statuses) it carries a standard deviation.
fn identified(doc: &ParameterSetDoc, i: usize) -> bool {
    match doc.status[i].as_deref() {
        Some(s) => s == "identified",
        None => doc.std[i].is_some(),
    }
}

/// The drift of `a` against `b`; they must be sets of the same robot model (the error names
/// `field`).
pub fn drift(a: &ParameterSetDoc, b: &ParameterSetDoc, field: &str) -> Result<DriftReport, DomainError> {
    if a.set.model != b.set.model {
        return Err(DomainError::new(
            field,
            format!(
                "the sets are of different robot models ('{}' and '{}'): a drift compares two sets of one robot",
                a.set.model.name, b.set.model.name
            ),
        ));
    }
    let mut parameters = Vec::new();
    let mut only_in_a = Vec::new();
    let mut notes = Vec::new();
    let run_term = |p: &Param| matches!(p, Param::Drift(..));
    if [a, b].iter().any(|d| d.set.layout.params().iter().any(run_term)) {
        notes.push(
            "the drift terms along a measuring run (drift_*) are each run's own nuisance, not the robot's: not compared"
                .into(),
        );
    }
    for (i, p) in a.set.layout.params().iter().enumerate() {
        if run_term(p) {
            continue;
        }
        let j = b.set.layout.index_of(*p);
        let in_b = j.is_some_and(|j| identified(b, j));
        match (identified(a, i), in_b) {
            (true, true) => {
                let j = j.expect("identified in b");
                let k = p.unit().to_si();
                let (va, vb) = (a.set.values[i] / k, b.set.values[j] / k);
                let (sa, sb) = (a.std[i].unwrap_or(0.0) / k, b.std[j].unwrap_or(0.0) / k);
                if a.std[i].is_none() || b.std[j].is_none() {
                    notes.push(format!("{p}: identified without a standard deviation in one set; taken as 0"));
                }
                let change = va - vb;
                let combined = sa.hypot(sb);
                // Printed as README promises: mm at 0.1 µm, deg at 1e-6°, the rest to 12
                // significant digits; the decision uses the unrounded figures.
                let unit = p.unit().as_str();
                let out = |v: f64| match unit {
                    "mm" => crate::units::round_to(v, crate::units::OUT_MM),
                    "deg" => crate::units::round_to(v, crate::units::OUT_DEG),
                    _ => super::rounding::significant(v, super::rounding::SIGNIFICANT),
                };
                parameters.push(DriftEntry {
                    name: p.to_string(),
                    unit: unit.to_string(),
                    value_a: out(va),
                    value_b: out(vb),
                    change: out(change),
                    std_a: out(sa),
                    std_b: out(sb),
                    combined_std: out(combined),
                    n_sigma: (combined > 0.0).then(|| super::rounding::significant(change.abs() / combined, 6)),
                    moved: change.abs() > combined,
                });
            }
            (true, false) => only_in_a.push(p.to_string()),
            _ => {}
        }
    }
    let only_in_b = b
        .set
        .layout
        .params()
        .iter()
        .enumerate()
        .filter(|&(j, p)| {
            identified(b, j) && !run_term(p) && !a.set.layout.index_of(*p).is_some_and(|i| identified(a, i))
        })
        .map(|(_, p)| p.to_string())
        .collect();
    let moved = parameters.iter().filter(|e| e.moved).count();
    Ok(DriftReport { robot: a.set.model.name.clone(), parameters, moved, only_in_a, only_in_b, notes })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn doc(params: serde_json::Value) -> ParameterSetDoc {
        ParameterSetDoc::from_json(&json!({"robot": {"preset": "irb120"}, "parameters": params}).to_string()).unwrap()
    }

    /// Against a hand computation: a2 270.146 ± 0.003 vs 270.140 ± 0.004 mm → Δ = 0.006 mm,
    /// σ = √(0.003² + 0.004²) = 0.005 mm, 1.2 σ: moved. theta2 −89.910 ± 0.010 vs −89.905 ± 0.010
    /// deg → Δ = −0.005 deg, σ = 0.0141421 deg, 0.354 σ: not moved.
    #[test]
    fn drift_matches_a_hand_computation() {
        let a = doc(json!([
            {"name": "a2", "value": 270.146, "std": 0.003, "status": "identified"},
            {"name": "theta2", "value": -89.910, "std": 0.010, "status": "identified"},
            {"name": "c5", "value": -0.0304, "std": 0.001, "status": "identified"},
            {"name": "d2", "value": 0.0, "status": "dependent on d3 (parallel axes 2–3)"}]));
        let b = doc(json!([
            {"name": "a2", "value": 270.140, "std": 0.004, "status": "identified"},
            {"name": "theta2", "value": -89.905, "std": 0.010, "status": "identified"},
            {"name": "d2", "value": 0.01, "std": 0.002, "status": "identified"}]));
        let r = drift(&a, &b, "against").unwrap();
        assert_eq!(r.parameters.len(), 2);
        let a2 = &r.parameters[0];
        assert_eq!((a2.name.as_str(), a2.unit.as_str()), ("a2", "mm"));
        assert!((a2.change - 0.006).abs() < 1e-9, "{a2:?}");
        assert!((a2.combined_std - 0.005).abs() < 1e-12);
        assert!((a2.n_sigma.unwrap() - 1.2).abs() < 1e-6);
        assert!(a2.moved);
        let t2 = &r.parameters[1];
        assert_eq!(t2.unit, "deg");
        assert!((t2.change + 0.005).abs() < 1e-9);
        // Printed at 1e-6°, as README promises: √2 · 0.01 = 0.0141421… → 0.014142.
        assert_eq!(t2.combined_std, 0.014142);
        assert_eq!(a2.combined_std, 0.005);
        assert!((t2.n_sigma.unwrap() - 0.35355339).abs() < 1e-6);
        assert!(!t2.moved);
        assert_eq!(r.moved, 1);
        assert_eq!(r.only_in_a, ["c5"]);
        assert_eq!(r.only_in_b, ["d2"]);
        // Swapped, the change changes sign and the lists swap.
        let s = drift(&b, &a, "against").unwrap();
        assert!((s.parameters[0].change + a2.change).abs() < 1e-15);
        assert_eq!(
            (s.only_in_a.as_slice(), s.only_in_b.as_slice()),
            (["d2".to_string()].as_slice(), ["c5".to_string()].as_slice())
        );
    }

    /// Each run's drift terms are its own: two sets that both fit them (different values, far
    /// beyond their σ) compare their robot parameters only, and a note says why the drift terms
    /// are left out; a set with them against one without lists them in neither `only_in` list.
    #[test]
    fn the_drift_terms_of_each_run_are_not_compared() {
        let with = |v: f64| {
            doc(json!([
                {"name": "a2", "value": 270.146, "std": 0.003, "status": "identified"},
                {"name": "drift_x_p1", "value": v, "std": 0.001, "status": "identified"}]))
        };
        let r = drift(&with(0.05), &with(-0.05), "against").unwrap();
        assert_eq!(r.parameters.iter().map(|e| e.name.as_str()).collect::<Vec<_>>(), ["a2"]);
        assert_eq!(r.moved, 0);
        assert!(r.notes.iter().any(|n| n.contains("drift_*") && n.contains("not compared")), "{:?}", r.notes);
        let plain = doc(json!([{"name": "a2", "value": 270.146, "std": 0.003, "status": "identified"}]));
        for r in [drift(&with(0.05), &plain, "against").unwrap(), drift(&plain, &with(0.05), "against").unwrap()] {
            assert!(r.only_in_a.is_empty() && r.only_in_b.is_empty(), "{r:?}");
        }
        assert!(drift(&plain, &plain, "against").unwrap().notes.is_empty());
    }

    #[test]
    fn sets_of_different_robots_are_refused() {
        let a = doc(json!([]));
        let b =
            ParameterSetDoc::from_json(&json!({"robot": {"preset": "ur10"}, "parameters": []}).to_string()).unwrap();
        assert_eq!(drift(&a, &b, "against").unwrap_err().path, "against");
    }
}

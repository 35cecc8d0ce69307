//! Identifications at the boundary: the run every front end makes (the CLI, the service, Python;
//! their options checked once, in [`super::identify_options`]), and the result written as a
//! parameter-set file — per parameter value,
//! nominal, std, unit and status, plus the quality report (in mm and degrees where it has lengths
//! and angles).

use serde_json::Value;

use super::identify_options::DetmaxSelection;
use super::param_set::ParameterSetDoc;
use super::quality::{
    ConditionalMove, ConditionalQuality, Downweighted, FitMeasurements, Observability, PayloadAtFlangeQuality,
    PayloadComQuality, PayloadQuality, Quality, ToolQuality, WorstMeasurement,
};
use crate::cell::Cell;
use crate::identify::{Identification, IdentifyError, IdentifyOptions};
use crate::units::{DEG, MM};

/// An identification as `robocal identify` and the identification job both run it: the DETMAX
/// selection when asked (its description goes into the quality report; `selected` is told when
/// it is done), the fit, and the parameter-set document. The same calls in the same order, so the
/// two front ends give the same parameter set, bit for bit.
pub fn run_identification(
    cell: &Cell,
    mut opts: IdentifyOptions,
    select: Option<DetmaxSelection>,
    selected: &dyn Fn(),
) -> Result<(Identification, ParameterSetDoc), IdentifyError> {
    let selection = match select {
        None => None,
        Some(s) => {
            let (subset, info) = crate::identify::select_detmax(cell, &opts, s.n, s.index, s.seed)?;
            opts.selection.subset = subset;
            Some(info)
        }
    };
    selected();
    let id = crate::identify::identify(cell, &opts)?;
    let sessions: Vec<String> = id.problem.tools.iter().flat_map(|t| t.sessions.clone()).collect();
    let detmax = selection.is_some();
    let payload = payload_quality(&id, payload_again_at_flange(cell, &opts, &id, detmax))
        .map(|p| PayloadQuality { with_centre_of_mass: payload_with_centre_of_mass(&opts, &id, detmax), ..p });
    let doc = identification_doc(&id, &sessions, selection, payload);
    Ok((id, doc))
}

/// The undeclared payload fitted again with its centre of mass at the flange
/// ([`crate::identify::payload_at_flange`]), when the first fit determined it — not for a centre of
/// mass already within 1 mm of the flange, nor for a DETMAX selection (`detmax`), whose subset the
/// second fit would not share.
fn payload_again_at_flange(
    cell: &Cell,
    opts: &IdentifyOptions,
    id: &Identification,
    detmax: bool,
) -> Option<PayloadAtFlangeQuality> {
    let (_, std) = id.undeclared_payload()?;
    if std.is_none() || detmax || id.set.tool.com.norm() <= MM {
        return None;
    }
    match crate::identify::payload_at_flange(cell, opts) {
        Ok(f) => f.map(|f| PayloadAtFlangeQuality {
            mass_kg: Some(f.mass),
            std_kg: f.std,
            rms_residual_mm: Some(f.rms_residual / MM),
            ..Default::default()
        }),
        Err(e) => Some(PayloadAtFlangeQuality { failed: Some(e.to_string()), ..Default::default() }),
    }
}

/// The undeclared payload fitted again with its centre of mass free
/// ([`crate::identify::payload_centre_of_mass`]), when the first fit determined its mass — not for
/// a DETMAX selection (`detmax`), like [`payload_again_at_flange`].
pub(crate) fn payload_with_centre_of_mass(
    opts: &IdentifyOptions,
    id: &Identification,
    detmax: bool,
) -> Option<PayloadComQuality> {
    if detmax {
        return None;
    }
    match crate::identify::payload_centre_of_mass(id, opts) {
        Ok(f) => f.map(|f| PayloadComQuality {
            mass_kg: Some(f.mass).filter(|v| v.is_finite()),
            std_kg: Some(f.std).filter(|v| v.is_finite()),
            com_mm: f.com.map(|c| [c.x / MM, c.y / MM, c.z / MM]),
            com_std_mm: f.com_std.map(|s| s.map(|s| s / MM)),
            determined: Some(f.determined),
            rms_residual_mm: Some(f.rms_residual / MM),
            ..Default::default()
        }),
        Err(e) => Some(PayloadComQuality { failed: Some(e.to_string()), ..Default::default() }),
    }
}

/// What an identification made of a payload the sessions do not declare, with `at_flange` the
/// second fit's ([`payload_again_at_flange`]); `None` when the sessions declare a payload or the
/// model has none.
pub(crate) fn payload_quality(
    id: &Identification,
    at_flange: Option<PayloadAtFlangeQuality>,
) -> Option<PayloadQuality> {
    let (mass, std) = id.undeclared_payload()?;
    let com = id.set.tool.com;
    Some(PayloadQuality {
        mass_kg: Some(mass),
        std_kg: std,
        com_mm: Some([com.x / MM, com.y / MM, com.z / MM]),
        at_flange,
        ..Default::default()
    })
}

/// The measurements an identification fitted, per session in cell order (0-based indices,
/// ascending) — what a validation checks to tell a held-out figure from an in-sample one.
pub fn fit_measurements(id: &Identification) -> Vec<FitMeasurements> {
    let names = &id.problem.session_names;
    let dof = id.set.dof();
    let mut per: Vec<Vec<&crate::identify::problem::Obs>> = vec![Vec::new(); names.len()];
    for o in &id.problem.obs {
        per[o.session].push(o);
    }
    names
        .iter()
        .zip(per)
        .filter(|(_, obs)| !obs.is_empty())
        .map(|(name, mut obs)| {
            obs.sort_by_key(|o| o.index);
            obs.dedup_by_key(|o| o.index);
            let fingerprints =
                obs.iter().map(|o| crate::cell::fingerprint::of_reading(&o.state.q[..dof], &o.measured_position()));
            FitMeasurements {
                session: name.clone(),
                indices: obs.iter().map(|o| o.index).collect(),
                fingerprints: Some(fingerprints.collect()),
                other: Default::default(),
            }
        })
        .collect()
}

/// The measurements an identification was told to leave out, per session in the order first
/// named (0-based indices, ascending, each with its fingerprint); `None` when none was.
pub fn excluded_measurements(id: &Identification) -> Option<Vec<FitMeasurements>> {
    let mut per: Vec<FitMeasurements> = Vec::new();
    for (session, index, fingerprint) in &id.excluded {
        let at = match per.iter().position(|f| &f.session == session) {
            Some(at) => at,
            None => {
                per.push(FitMeasurements {
                    session: session.clone(),
                    fingerprints: Some(Vec::new()),
                    ..Default::default()
                });
                per.len() - 1
            }
        };
        let f = &mut per[at];
        if f.indices.contains(index) {
            continue;
        }
        f.indices.push(*index);
        // A ball of a cell without its artefact has no position to fingerprint: the index alone
        // then names it.
        match (fingerprint, f.fingerprints.as_mut()) {
            (Some(p), Some(ps)) => ps.push(p.clone()),
            _ => f.fingerprints = None,
        }
    }
    for f in &mut per {
        let mut order: Vec<usize> = (0..f.indices.len()).collect();
        order.sort_by_key(|&k| f.indices[k]);
        f.fingerprints = f.fingerprints.take().map(|ps| order.iter().map(|&k| ps[k].clone()).collect());
        f.indices = order.iter().map(|&k| f.indices[k]).collect();
    }
    (!per.is_empty()).then_some(per)
}

/// The parameter-set document of an identification; `selection` describes how the measurements
/// were chosen (e.g. DETMAX settings) and `payload` what was made of an undeclared payload, both
/// carried into the quality report.
pub fn identification_doc(
    id: &Identification,
    sessions: &[String],
    selection: Option<Value>,
    payload: Option<PayloadQuality>,
) -> ParameterSetDoc {
    let mut doc = ParameterSetDoc::new(id.set.clone());
    doc.std = id.std.clone();
    doc.status = id.status.iter().map(|s| Some(s.to_string())).collect();
    let q = &id.quality;
    let m = q.std.len();
    let tools = id
        .tools
        .iter()
        .map(|t| {
            let c = &t.tool.tcp;
            ToolQuality {
                sessions: t.sessions.clone(),
                tcp_mm: [c[0] / MM, c[1] / MM, c[2] / MM],
                tcp_rotation_deg: [c[3] / DEG, c[4] / DEG, c[5] / DEG],
                std: (0..6).map(|k| t.std[k].map(|s| if k < 3 { s / MM } else { s / DEG })).collect(),
                status: t.status.to_vec(),
                other: Default::default(),
            }
        })
        .collect();
    let corr = (0..m).map(|a| (0..m).map(|b| Some(q.correlation[(a, b)])).collect()).collect();
    let o = &q.observability;
    let quality = Quality {
        sessions: Some(sessions.to_vec()),
        fit_measurements: Some(fit_measurements(id)),
        excluded: excluded_measurements(id),
        selection,
        n_measurements: Some(q.n_configs),
        n_rows: Some(q.n_rows),
        n_parameters: Some(m),
        iterations: Some(id.iterations),
        kappa_si: Some(q.kappa),
        kappa_scaled: Some(q.kappa_scaled),
        observability_si: Some(Observability {
            o1: Some(o.o1),
            o2: Some(o.o2),
            o3: Some(o.o3),
            o4: Some(o.o4),
            o5: Some(o.o5),
            other: Default::default(),
        }),
        // Rows weighted by an instrument model: σ̂ is a ratio to the instrument's σ, not a length.
        sigma_mm: (!q.weighted).then(|| q.sigma / MM),
        sigma_ratio: q.weighted.then_some(q.sigma),
        // How each std was computed: "classic" σ̂²(JᵀJ)⁻¹, or its larger with the cluster-robust
        // (by pose) one where the data hold enough poses.
        std_method: Some(if q.robust { "max(classic, cluster-robust by pose)" } else { "classic" }.to_string()),
        rms_residual_mm: Some(q.rms_residual / MM),
        singular_values_si: Some(q.singular_values.clone()),
        free: Some(id.free_names.clone()),
        correlation: Some(corr),
        tools: Some(tools),
        downweighted: Some(
            id.downweighted
                .iter()
                .map(|(s, i, w)| Downweighted { session: s.clone(), index: *i, weight: *w, other: Default::default() })
                .collect(),
        ),
        expected_rms_mm: Some(q.expected_rms / MM),
        residual_ratio: Some(q.residual_ratio),
        envelope: super::validity::Envelope::of_identification(id).map(|e| e.file().clone()),
        worst: Some(
            id.worst
                .iter()
                .map(|w| WorstMeasurement {
                    session: w.session.clone(),
                    index: w.index,
                    residual_mm: Some(w.residual / MM),
                    ratio: Some(w.ratio),
                    other: Default::default(),
                })
                .collect(),
        ),
        payload,
        conditional: (!id.conditional.is_empty()).then(|| {
            id.conditional
                .iter()
                .map(|c| ConditionalQuality {
                    held: c.held.clone(),
                    unit: c.unit.to_string(),
                    value: c.value,
                    std: c.std,
                    moves: c
                        .moves
                        .iter()
                        .map(|(name, unit, per_unit, std)| ConditionalMove {
                            name: name.clone(),
                            unit: unit.to_string(),
                            per_unit: *per_unit,
                            std: *std,
                            other: Default::default(),
                        })
                        .collect(),
                    other: Default::default(),
                })
                .collect()
        }),
        notes: Some(id.notes.clone()),
        diagnosis: None,
        other: Default::default(),
    };
    doc.quality = Some(rounded(&quality));
    doc
}

/// `q` with its numbers rounded for output by their field's unit ([`super::rounding::round_json`]),
/// through its JSON: what is written is what is kept. A non-finite figure (written `null`) is
/// `None` afterwards.
fn rounded(q: &Quality) -> Quality {
    let mut v = serde_json::to_value(q).expect("the quality report has only string keys");
    super::rounding::round_json(&mut v);
    serde_json::from_value(v).expect("the quality report reads back what it writes")
}

/// The text of a reason, as the parameter-set files and the wire carry it in `status` (which is
/// `identified` for the others): the parameter's name, then why, with the figures in mm, degrees
/// and kg.
impl std::fmt::Display for crate::identify::FixedReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        use crate::identify::{FixedReason::*, ModelTerm, Structure};
        let start = |at_start: &bool| if *at_start { "its start value" } else { "nominal" };
        match self {
            ByUser { name, at_start } => write!(f, "{name}: fixed by the user (at {})", start(at_start)),
            NotInOnly { name, at_start } => write!(f, "{name}: fixed at {}, not in `only`", start(at_start)),
            NotInModel { name, term: ModelTerm::Beta } => write!(f, "{name}: fixed, the model has no β (-beta)"),
            NotInModel { name, term: ModelTerm::Compliance } => {
                write!(f, "{name}: fixed, the model has no compliance (-compliance)")
            }
            DeclaredTcp { name } => write!(f, "{name}: fixed, the session declares its TCP (measured, e.g. on a CMM)"),
            NoGravityTorque { name, axis, massless: false } => write!(f, "{name}: no gravity torque on axis {axis}"),
            NoGravityTorque { name, axis, massless: true } => write!(
                f,
                "{name}: no gravity torque on axis {axis} in this model (its links declare no mass and its tools no payload: give each joint's mass_kg and com_mm in the robot file to fit compliance)"
            ),
            NoApproachDirection { name, axis } => write!(f, "{name}: no approach direction logged for axis {axis}"),
            NoTemperatureChange { name } => write!(f, "{name}: no temperature change in the data"),
            NoRunOrder { name } => write!(
                f,
                "{name}: the measurements have no place in one run (no time_s, no sequence, not one session listed as measured)"
            ),
            TcpOnLastAxis { name, axis } => {
                write!(f, "{name}: no effect, the TCP lies on axis {axis} and orientation is not measured")
            }
            OrientationNotMeasured { name } => write!(f, "{name}: orientation not measured"),
            NoEffect { name } => write!(f, "{name}: no effect on the measured quantities"),
            Dependent { name, on, structure } => {
                write!(f, "{name}: dependent on {}", on.join(", "))?;
                match structure {
                    Some(Structure::ParallelAxes { lo, hi }) => write!(f, " (parallel axes {lo}–{hi})"),
                    Some(Structure::Base) => write!(f, " (redundant with the base pose)"),
                    Some(Structure::Joint { joint }) => write!(f, " (redundant with joint-{joint} parameters)"),
                    None => Ok(()),
                }
            }
            Undetermined { name, std, bound, angle: true } => write!(
                f,
                "{name}: not determined by these data (its standard deviation would be at least {:.3}°, beyond {:.0}°)",
                std / DEG,
                bound / DEG
            ),
            Undetermined { name, std, bound, angle: false } => write!(
                f,
                "{name}: not determined by these data (its standard deviation would be at least {:.3} mm, beyond {:.0} mm)",
                std / MM,
                bound / MM
            ),
            UndeterminedAtSolution { name, std, bound, angle, with } => {
                let (v, b, unit) = if *angle { (std / DEG, bound / DEG, "°") } else { (std / MM, bound / MM, " mm") };
                write!(
                    f,
                    "{name}: not determined by these data (standard deviation {v:.3}{unit} at the solution, beyond {b:.0}{unit}"
                )?;
                if let Some((other, r)) = with {
                    write!(f, "; correlation {r:+.3} with {other}")?;
                }
                write!(f, "): held at its start value")
            }
            // A mass below zero by more than the same σ is no payload at all: the model misses
            // something that the mass's torques absorb, and the statement says so rather than
            // calling a significant negative estimate "below 3 σ".
            PayloadInsignificant { mass_kg, std_kg, sigmas } if *mass_kg < -sigmas * std_kg => write!(
                f,
                "payload not determined by these data: it reads {mass_kg:.3} ± {std_kg:.3} kg, negative by {:.1} σ, which no payload weighs — the model misses something that the payload's torques absorb (an effect it lacks, or joint readings in another convention than the robot file): held at the declared 0 kg",
                -mass_kg / std_kg
            ),
            PayloadInsignificant { mass_kg, std_kg, sigmas } => write!(
                f,
                "payload not determined by these data ({mass_kg:.3} ± {std_kg:.3} kg, below {sigmas} σ): held at the declared 0 kg"
            ),
            PayloadUnsettled { error } => write!(
                f,
                "payload not determined by these data (the fit with it does not settle: {error}): held at the declared 0 kg"
            ),
            ComplianceInsignificant { name, change, std, t, sigmas, held_at } => write!(
                f,
                "{name} not determined by these data ({:+.3e} ± {:.3e} deg/(N·m) from its nominal, {} σ, below {sigmas} σ): held at {} deg/(N·m)",
                change.to_degrees(),
                std.to_degrees(),
                if t.is_finite() { format!("{t:.1}") } else { "undefined".into() },
                if *held_at == 0.0 { "0".to_string() } else { format!("{:.3e}", held_at.to_degrees()) },
            ),
            NotInProblem => write!(f, "fixed: not a parameter of this identification"),
        }
    }
}

//! The job kinds, each in three steps: load the inputs from the store (async), compute
//! (blocking, off the async runtime — the same library calls the CLI makes), store the result
//! (inside the transaction that also ends the job).

use crate::db::Pool;
use serde_json::{Value, json};

use super::JobError;
use super::requests::{
    DiagnosisJob, IdentificationRequest, Iso9283Request, PosePlanRequest, SelectSpec, ValidationJob,
};
use super::results::{
    DiagnosisResult, IdentificationResult, IdentificationSummary, Iso9283Result, JobResult, PlanNest, PlannedBallPose,
    PlannedTrackerPose, PosePlan, PosePlanResult, ValidationJobSummary, ValidationResult,
};
use crate::app::cells::{self, StoredIndices};
use crate::app::robots::{model_of, robot_base};
use crate::cell::{Cell, Instrument, Measurement, MeasuringOrder, Observation, Purpose, Session};
use crate::db::jobs::JobKind;
use crate::db::records::{self, RobotRow, SessionRow};
use crate::diagnose::DiagnoseError;
use crate::domain::cell::{ArtefactSpec, CellFile, PurposeSpec};
use crate::domain::diagnosis::{DiagnoseSpec, accepted_doc, diagnosis_out, input_of};
use crate::domain::identification::{DetmaxSelection, MeasurementRef, run_identification};
use crate::domain::validation::ErrorFigures;
use crate::domain::{ParameterSetDoc, ToolSpec, to_deg};
use crate::identify::{DetmaxPool, IdentifyError, IdentifyOptions, SolveError, Worst};
use crate::kinematics::{Preset, RobotModel};
use crate::sim::poses::{CellLayout, IdentificationOptions, PlanningCell, ValidationOptions};
use crate::units::{DEG, MM};

/// Everything a job needs, loaded. A cell is the stored sessions without their excluded
/// measurements; `indices` gives each cell measurement's stored index, what the job reports.
pub enum Inputs {
    PosePlan {
        base: [f64; 6],
        model: RobotModel,
        request: PosePlanRequest,
        artefact: ArtefactSpec,
    },
    Identification {
        robot: RobotRow,
        request: IdentificationRequest,
        cell: CellFile,
        indices: StoredIndices,
        excluded: usize,
        session_names: Vec<String>,
    },
    Validation {
        job: ValidationJob,
        set_json: String,
        /// The sessions the store lists for the set (what it was fitted on).
        set_sessions: Vec<String>,
        cell: CellFile,
        indices: StoredIndices,
        session_names: Vec<String>,
    },
    Diagnosis {
        job: DiagnosisJob,
        set_json: String,
        cell: CellFile,
        indices: StoredIndices,
        sessions: DiagnosisSessions,
    },
    Iso9283 {
        request: Iso9283Request,
        /// The session's name in the cell.
        session: String,
        set_json: Option<String>,
        cell: CellFile,
        indices: StoredIndices,
    },
}

/// What a job computed.
#[derive(Clone)]
pub enum Output {
    PosePlan {
        plan: PosePlan,
    },
    Identification {
        doc_json: String,
        sessions_json: String,
        summary: IdentificationSummary,
        activate: bool,
    },
    Validation {
        parameter_set_id: String,
        report: Value,
        sessions_json: String,
        summary: ValidationJobSummary,
    },
    Diagnosis {
        parameter_set_id: String,
        sessions_json: String,
        report_json: String,
        accepted_doc_json: Option<String>,
        status: crate::diagnose::Status,
        summary: String,
        effects: Vec<String>,
    },
    Iso9283 {
        session_id: String,
        session: String,
        parameter_set_id: Option<String>,
        evaluation: Box<crate::domain::iso9283::Evaluation>,
    },
}

/// The sessions a diagnosis uses, by name as the cell has them.
#[derive(Clone, Debug, PartialEq)]
pub struct DiagnosisSessions {
    pub identification: Vec<String>,
    pub validation: Vec<String>,
}

/// The robot's sessions a diagnosis names (ids or names): `identification` empty means every
/// identification session holding measurements, `validation` `None` every validation session
/// holding measurements, `Some([])` none. Named sessions must exist, have that purpose and hold
/// measurements (422 at `identification[i]` / `validation[i]`); there must be at least one
/// identification session (422 at `identification`).
pub async fn diagnosis_sessions(
    pool: &Pool,
    robot_id: &str,
    identification: &[String],
    validation: Option<&[String]>,
) -> Result<(Vec<SessionRow>, Vec<SessionRow>), JobError> {
    let id = if identification.is_empty() {
        let all = cells::sessions_with_purpose(pool, robot_id, PurposeSpec::Identification).await?;
        if all.is_empty() {
            return Err(JobError::invalid(
                "identification",
                "the robot has no identification session with measurements to diagnose from",
            ));
        }
        all
    } else {
        cells::checked_sessions(pool, robot_id, identification, PurposeSpec::Identification, "identification").await?
    };
    let val = match validation {
        None => cells::sessions_with_purpose(pool, robot_id, PurposeSpec::Validation).await?,
        Some([]) => Vec::new(),
        Some(v) => cells::checked_sessions(pool, robot_id, v, PurposeSpec::Validation, "validation").await?,
    };
    Ok((id, val))
}

fn stored<T: serde::de::DeserializeOwned>(json: &str, what: &str) -> Result<T, JobError> {
    serde_json::from_str(json).map_err(|e| JobError::Internal(format!("stored {what}: {e}")))
}

/// Load a job's inputs.
pub async fn load(pool: &Pool, kind: JobKind, robot_id: &str, request_json: &str) -> Result<Inputs, JobError> {
    let robot =
        records::robot(pool, robot_id).await?.ok_or_else(|| JobError::Internal(format!("robot {robot_id} missing")))?;
    match kind {
        JobKind::PosePlan => {
            let request: PosePlanRequest = stored(request_json, "pose-plan request")?;
            let row = records::artefact(pool, &request.artefact_id)
                .await?
                .ok_or_else(|| JobError::unknown("artefact_id", format!("no artefact '{}'", request.artefact_id)))?;
            let artefact: ArtefactSpec = stored(&row.spec_json, "artefact")?;
            let model = model_of(&robot)?;
            let base = robot_base(&robot)?;
            Ok(Inputs::PosePlan { base, model, request, artefact })
        }
        JobKind::Identification => {
            let request: IdentificationRequest = stored(request_json, "identification request")?;
            let sessions = cells::resolve_sessions(pool, &robot.id, &request.sessions, "sessions").await?;
            let stored = cells::stored_cell(pool, &robot, &sessions, false).await?;
            let session_names = sessions.iter().map(|s| s.name.clone()).collect();
            Ok(Inputs::Identification {
                robot,
                request,
                cell: stored.file,
                indices: stored.indices,
                excluded: stored.excluded,
                session_names,
            })
        }
        JobKind::Validation => {
            let job: ValidationJob = stored(request_json, "validation request")?;
            let set = records::parameter_set(pool, &job.parameter_set_id)
                .await?
                .ok_or_else(|| JobError::Internal(format!("parameter set {} missing", job.parameter_set_id)))?;
            let sessions = cells::resolve_sessions(pool, &robot.id, &job.request.sessions, "sessions").await?;
            let mut stored = cells::stored_cell(pool, &robot, &sessions, false).await?;
            if stored.file.artefact.is_none() {
                // The calibration zone of `vs_zone_distance`, as the CLI has it from the cell file.
                stored.file.artefact = cells::calibration_artefact(pool, &robot.id).await?;
            }
            let session_names = sessions.iter().map(|s| s.name.clone()).collect();
            let set_sessions = self::stored(&set.sessions_json, "parameter-set sessions")?;
            Ok(Inputs::Validation {
                job,
                set_json: set.doc_json,
                set_sessions,
                cell: stored.file,
                indices: stored.indices,
                session_names,
            })
        }
        JobKind::Diagnosis => {
            let job: DiagnosisJob = stored(request_json, "diagnosis request")?;
            let set = records::parameter_set(pool, &job.parameter_set_id)
                .await?
                .ok_or_else(|| JobError::Internal(format!("parameter set {} missing", job.parameter_set_id)))?;
            let (id, val) =
                diagnosis_sessions(pool, &robot.id, &job.request.identification, job.request.validation.as_deref())
                    .await?;
            let names = |s: &[SessionRow]| s.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
            let sessions = DiagnosisSessions { identification: names(&id), validation: names(&val) };
            let all: Vec<SessionRow> = id.into_iter().chain(val).collect();
            let stored = cells::stored_cell(pool, &robot, &all, false).await?;
            Ok(Inputs::Diagnosis { job, set_json: set.doc_json, cell: stored.file, indices: stored.indices, sessions })
        }
        JobKind::Iso9283 => {
            let request: Iso9283Request = stored(request_json, "ISO 9283 request")?;
            let session = records::session_of_robot(pool, &robot.id, &request.session).await?.ok_or_else(|| {
                JobError::unknown("session", format!("this robot has no session '{}'", request.session))
            })?;
            let set_json = match &request.parameter_set_id {
                None => None,
                Some(id) => Some(
                    records::parameter_set(pool, id)
                        .await?
                        .ok_or_else(|| JobError::Internal(format!("parameter set {id} missing")))?
                        .doc_json,
                ),
            };
            let stored = cells::stored_cell(pool, &robot, std::slice::from_ref(&session), false).await?;
            Ok(Inputs::Iso9283 { request, session: session.name, set_json, cell: stored.file, indices: stored.indices })
        }
    }
}

/// An ISO 9283 evaluation: the request's assignments (stored indices) mapped to the cell's, then
/// the call `robocal iso9283 evaluate` makes. Errors name the request's field.
fn iso9283(
    request: Iso9283Request,
    session: String,
    set_json: Option<String>,
    cell: CellFile,
    indices: StoredIndices,
    progress: &(dyn Fn(f64, &'static str) + Sync),
) -> Result<Output, JobError> {
    use crate::domain::iso9283::evaluate::EvaluateError;
    use crate::domain::iso9283::{EvaluationError, assignments_of, evaluate, pairs_of};
    let mut assignments = assignments_of(&request.poses).map_err(JobError::field)?;
    let pairs = pairs_of(&request.pairs, &assignments).map_err(JobError::field)?;
    for (i, a) in assignments.iter_mut().enumerate() {
        a.index = indices.cell(&session, a.index).ok_or_else(|| {
            JobError::invalid(format!("poses[{i}].index"), format!("measurement {} is excluded", a.index))
        })?;
    }
    let set = set_json
        .map(|j| ParameterSetDoc::from_json(&j).map(|d| d.set))
        .transpose()
        .map_err(|e| JobError::Internal(format!("stored parameter set: {e}")))?;
    let cell_si = cell.to_cell().map_err(|e| JobError::domain(e, "stored cell"))?;
    progress(0.1, "registering base and tool");
    let row_of = |index: usize| assignments.iter().position(|a| a.index == index).unwrap_or(0);
    let evaluation =
        evaluate(&cell_si, &session, set.as_ref(), &assignments, &pairs, crate::domain::iso9283::KAPPA_LIMIT).map_err(
            |e| {
                let detail = e.to_string();
                match e {
                    EvaluationError::Session(EvaluateError::UnknownMeasurement { row, .. }) => {
                        JobError::invalid(format!("poses[{row}].index"), detail)
                    }
                    EvaluationError::Session(EvaluateError::NotMeasured { index, .. }) => {
                        JobError::invalid(format!("poses[{}].index", row_of(index)), detail)
                    }
                    EvaluationError::Session(EvaluateError::UnknownSession(_)) => JobError::unknown("session", detail),
                    EvaluationError::Session(EvaluateError::Registration(_)) => JobError::Numerical {
                        kind: "registration",
                        title: "The base and tool could not be registered",
                        detail,
                    },
                    EvaluationError::Statistics { .. } => JobError::Invalid { detail, field: Some("poses".into()) },
                }
            },
        )?;
    progress(0.95, "storing");
    Ok(Output::Iso9283 {
        session_id: request.session,
        session,
        parameter_set_id: request.parameter_set_id,
        evaluation: Box::new(evaluation),
    })
}

/// Identification options from a request (checked as `robocal identify` checks its flags); an
/// error is 422 at the request's field.
pub fn identify_options(
    r: &IdentificationRequest,
    dof: usize,
    sessions: Vec<String>,
) -> Result<IdentifyOptions, JobError> {
    let mut o = r.spec().to_options(dof).map_err(JobError::field)?;
    o.selection.sessions = sessions;
    Ok(o)
}

/// A request's DETMAX selection, checked; an error is 422 at `select.n` or `select.index`.
pub fn selection(s: &SelectSpec) -> Result<DetmaxSelection, JobError> {
    s.to_selection().map_err(|e| JobError::field(e.within("select")))
}

/// Numerical trouble as its own problem kind; input trouble as 422.
pub fn identify_error(e: IdentifyError) -> JobError {
    let detail = e.to_string();
    let (kind, title) = match e {
        IdentifyError::RankDeficient { .. } => ("rank-deficient", "Rank-deficient fit"),
        IdentifyError::IllConditioned { .. } => ("ill-conditioned", "Ill-conditioned fit (κ above the limit)"),
        IdentifyError::Underdetermined { .. } => ("underdetermined", "Fewer residuals than parameters"),
        IdentifyError::Solve(SolveError::Diverged { .. }) => ("divergence", "The fit diverged"),
        IdentifyError::Solve(SolveError::IterationLimit { .. }) => ("no-convergence", "The fit did not converge"),
        IdentifyError::Registration(_) => ("registration", "The base could not be registered"),
        IdentifyError::Misfit { .. } => ("misfit", "The model does not describe these data"),
        IdentifyError::Outliers { .. } => ("outliers", "Outlier measurements"),
        IdentifyError::PositionScale { .. } => {
            ("position-scale", "The measured positions are not on the robot's scale (a unit mistake)")
        }
        IdentifyError::RowsShifted { .. } => {
            ("rows-shifted", "The measured positions are not paired with their joint readings")
        }
        IdentifyError::MirroredFrame { .. } => {
            ("mirrored-frame", "The measured positions are mirrored against the robot")
        }
        IdentifyError::JointConvention { .. } => {
            ("joint-convention", "The joint readings follow another convention than the robot model")
        }
        IdentifyError::JointUnit { .. } => ("joint-unit", "The joint readings are in radians, not degrees"),
        IdentifyError::StartRobot { .. } => {
            return JobError::Invalid { detail, field: Some("parameter_set_id".into()) };
        }
        IdentifyError::Option { .. } => return JobError::Invalid { field: e.field_path(), detail },
        IdentifyError::Problem(_) => return JobError::Invalid { detail, field: None },
    };
    JobError::Numerical { kind, title, detail }
}

/// An identification's failure with the measurements it names (outliers, the worst residuals of
/// a misfit) by their stored index.
fn stored_identify_error(e: IdentifyError, indices: &StoredIndices) -> IdentifyError {
    let remap = |ws: Vec<Worst>| {
        ws.into_iter().map(|w| Worst { index: indices.stored(&w.session, w.index), ..w }).collect::<Vec<_>>()
    };
    match e {
        IdentifyError::Outliers { outliers, factor } => IdentifyError::Outliers { outliers: remap(outliers), factor },
        IdentifyError::Misfit { rms, expected, ratio, limit, worst } => {
            IdentifyError::Misfit { rms, expected, ratio, limit, worst: remap(worst) }
        }
        other => other,
    }
}

/// A parameter-set document's quality report with the measurements it names (`worst`,
/// `downweighted`, `fit_measurements`, `excluded`) by their stored index.
fn stored_quality(doc: &mut ParameterSetDoc, indices: &StoredIndices) {
    let Some(q) = doc.quality.as_mut() else { return };
    for w in q.worst.iter_mut().flatten() {
        w.index = indices.stored(&w.session, w.index);
    }
    for d in q.downweighted.iter_mut().flatten() {
        d.index = indices.stored(&d.session, d.index);
    }
    for f in q.fit_measurements.iter_mut().flatten().chain(q.excluded.iter_mut().flatten()) {
        for i in f.indices.iter_mut() {
            *i = indices.stored(&f.session, *i);
        }
    }
}

/// The readings a set's identification left out (`quality.excluded`, stored indices) by their
/// index in the job's cell; those excluded in the store since are not in the cell and go.
fn cell_excluded(doc: &mut ParameterSetDoc, indices: &StoredIndices) {
    let Some(q) = doc.quality.as_mut() else { return };
    for f in q.excluded.iter_mut().flatten() {
        let kept: Vec<(usize, usize)> =
            f.indices.iter().enumerate().filter_map(|(k, &i)| Some((k, indices.cell(&f.session, i)?))).collect();
        f.fingerprints = f.fingerprints.take().map(|p| kept.iter().filter_map(|&(k, _)| p.get(k).cloned()).collect());
        f.indices = kept.into_iter().map(|(_, i)| i).collect();
    }
}

/// A diagnosis's failure: its options as 422, the starting model's fit as an identification's.
pub fn diagnose_error(e: DiagnoseError) -> JobError {
    match e {
        DiagnoseError::Option(detail) => JobError::Invalid { detail, field: None },
        DiagnoseError::Identify(e) => identify_error(e),
    }
}

/// The computation (blocking). `progress` is told how far it got (0–1) and what it is doing.
pub fn compute(inputs: Inputs, progress: &(dyn Fn(f64, &'static str) + Sync)) -> Result<Output, JobError> {
    match inputs {
        Inputs::PosePlan { base, model, request, artefact } => pose_plan(&model, base, &request, &artefact, progress),
        Inputs::Identification { robot: _, mut request, cell, indices, excluded, session_names } => {
            let cell_si = cell.to_cell().map_err(|e| JobError::domain(e, "stored cell"))?;
            // The request names measurements by their stored index; one already excluded in the
            // store is not in the cell.
            request.exclude = request
                .exclude
                .iter()
                .filter_map(|m| indices.cell(&m.session, m.index).map(|index| MeasurementRef { index, ..m.clone() }))
                .collect();
            let opts = identify_options(&request, cell_si.model.dof(), session_names.clone())?;
            let select = request.select.as_ref().map(selection).transpose()?;
            progress(0.05, if select.is_some() { "selecting poses (DETMAX)" } else { "identifying" });
            let (id, mut doc) = run_identification(&cell_si, opts, select, &|| progress(0.3, "identifying"))
                .map_err(|e| identify_error(stored_identify_error(e, &indices)))?;
            progress(0.95, "storing");
            stored_quality(&mut doc, &indices);
            let q = &id.quality;
            let summary = IdentificationSummary {
                identified: id.free_names.len(),
                measurements: q.n_configs,
                excluded,
                iterations: id.iterations,
                kappa_si: q.kappa,
                kappa_scaled: q.kappa_scaled,
                o1_si: q.observability.o1,
                rms_residual_mm: q.rms_residual / MM,
            };
            Ok(Output::Identification {
                doc_json: doc.to_json_pretty(),
                sessions_json: json!(session_names).to_string(),
                summary,
                activate: request.activate,
            })
        }
        Inputs::Validation { job, set_json, set_sessions, cell, indices, session_names } => {
            let doc = ParameterSetDoc::from_json(&set_json)
                .map_err(|e| JobError::Internal(format!("stored parameter set: {e}")))?;
            let cell_si = cell.to_cell().map_err(|e| JobError::domain(e, "stored cell"))?;
            progress(0.1, "validating");
            // What the set was fitted on, in stored indices; the cell's indices are mapped to them
            // below, before the report counts the fitted measurements.
            let fit = crate::domain::validation::fit_data(&doc, &set_sessions);
            let mut report = crate::validate::report::validate_fitted(
                &doc.set,
                &cell_si,
                &session_names,
                crate::validate::report::Reference::Measured,
                Some(&fit),
            )
            .map_err(|e| JobError::Invalid { detail: e.to_string(), field: Some("sessions".into()) })?;
            // Measured on the cell's indices, before they are mapped to the stored ones.
            let uncertainty = crate::domain::validity::HeldOutUncertainty::of_report(&doc, &cell_si, &report)
                .map_err(|e| JobError::Internal(format!("stored parameter set: {e}")))?;
            for r in &mut report.residuals {
                r.index = indices.stored(&r.session, r.index);
            }
            let full = crate::domain::validation::report_to_json_with(&report, uncertainty, job.request.residuals);
            let summary = ValidationJobSummary {
                measurements: report.calibrated.position.n,
                held_out: Some(report.held_out()),
                held_out_statement: Some(crate::domain::validation::held_out_statement(&report)),
                calibrated: ErrorFigures::of(&report.calibrated.position),
                nominal: ErrorFigures::of(&report.nominal.position),
            };
            Ok(Output::Validation {
                parameter_set_id: job.parameter_set_id,
                report: full,
                sessions_json: json!(session_names).to_string(),
                summary,
            })
        }
        Inputs::Diagnosis { job, set_json, cell, indices, sessions } => {
            let mut doc = ParameterSetDoc::from_json(&set_json)
                .map_err(|e| JobError::Internal(format!("stored parameter set: {e}")))?;
            cell_excluded(&mut doc, &indices);
            let cell_si = cell.to_cell().map_err(|e| JobError::domain(e, "stored cell"))?;
            // The sessions by the names the cell gives them. The held-out refits run on this
            // worker's thread (`threads: 1`, the default): a worker is one solver thread.
            let spec = DiagnoseSpec {
                identification: sessions.identification.clone(),
                validation: Some(sessions.validation.clone()),
                ..job.request
            };
            let opts = spec.to_options().map_err(JobError::field)?;
            progress(0.05, "fitting the current model");
            let d = crate::diagnose::diagnose_with_progress(&input_of(&cell_si, &doc), &opts, &|f, what| {
                progress(0.05 + 0.9 * f, what)
            })
            .map_err(|e| match e {
                DiagnoseError::Identify(e) => identify_error(stored_identify_error(e, &indices)),
                other => diagnose_error(other),
            })?;
            progress(0.95, "storing");
            let mut out = diagnosis_out(&d);
            // The readings left out, by their stored index (as the request and the set name them).
            for m in &mut out.sessions.excluded {
                m.index = indices.stored(&m.session, m.index);
            }
            Ok(Output::Diagnosis {
                parameter_set_id: job.parameter_set_id,
                sessions_json: json!({"identification": sessions.identification, "validation": sessions.validation})
                    .to_string(),
                report_json: serde_json::to_string(&out).expect("a diagnosis serialises"),
                accepted_doc_json: accepted_doc(&d).map(|mut doc| {
                    stored_quality(&mut doc, &indices);
                    doc.to_json_pretty()
                }),
                status: out.verdict.status,
                summary: out.verdict.summary.clone(),
                effects: out.verdict.effects.iter().map(|e| e.which.label.clone()).collect(),
            })
        }
        Inputs::Iso9283 { request, session, set_json, cell, indices } => {
            iso9283(request, session, set_json, cell, indices, progress)
        }
    }
}

/// The planning cell of a request: the thesis's lab geometry (plate, rods, tracker, TriCal
/// collision shape and reflector nests) with this robot, tool, base guess and artefact.
pub fn planning_cell(
    model: &RobotModel,
    base: [f64; 6],
    request: &PosePlanRequest,
    artefact: &ArtefactSpec,
) -> Result<PlanningCell, JobError> {
    if model.preset != Some(Preset::Irb120) {
        return Err(JobError::invalid(
            "robot",
            format!(
                "pose planning needs the closed-form inverse kinematics and collision model of the irb120 preset; robot '{}' has neither",
                model.name
            ),
        ));
    }
    let tool = request.tool.to_tool().map_err(|e| JobError::domain(e, "tool"))?;
    let artefact = artefact.to_artefact().map_err(|e| JobError::invalid("artefact_id", e.to_string()))?;
    let layout = CellLayout { robot: model.clone(), tool, base, artefact, ..CellLayout::default() };
    PlanningCell::new(&layout).map_err(|e| JobError::invalid("tool", e.to_string()))
}

fn plan_error(e: crate::sim::poses::PlanError) -> JobError {
    JobError::Numerical { kind: "unplannable", title: "No collision-free plan", detail: e.to_string() }
}

fn pose_plan(
    model: &RobotModel,
    base: [f64; 6],
    request: &PosePlanRequest,
    artefact: &ArtefactSpec,
    progress: &(dyn Fn(f64, &'static str) + Sync),
) -> Result<Output, JobError> {
    plan_poses(model, base, request, artefact, progress).map(|plan| Output::PosePlan { plan })
}

/// A pose plan: the job's work, and `robocal plan`'s, so both give the same plan.
pub fn plan_poses(
    model: &RobotModel,
    base: [f64; 6],
    request: &PosePlanRequest,
    artefact: &ArtefactSpec,
    progress: &(dyn Fn(f64, &'static str) + Sync),
) -> Result<PosePlan, JobError> {
    progress(0.05, "planning ball poses");
    let pc = planning_cell(model, base, request, artefact)?;
    let id_opts = IdentificationOptions { per_ball: request.per_ball, ..Default::default() };
    let candidates = pc.plan_identification(&id_opts, request.seed).map_err(plan_error)?;
    progress(0.4, "planning ball poses");
    let mut identification = candidates.poses.clone();
    let mut selection_info = None;
    if let Some(s) = &request.select {
        let select = selection(s)?;
        if s.n >= identification.len() {
            return Err(JobError::invalid(
                "select.n",
                format!("must be smaller than the {} candidates", identification.len()),
            ));
        }
        // The candidates as a TriCal session of ball measurements: DETMAX on their Jacobian blocks
        // at the nominal model (the identification's own starting point).
        let tool = request.tool.to_tool().map_err(|e| JobError::domain(e, "tool"))?;
        let cell = Cell {
            model: model.clone(),
            base_guess: Some(base),
            artefact: Some(pc.layout().artefact.clone()),
            sessions: vec![Session {
                name: "candidates".into(),
                purpose: Purpose::Identification,
                instrument: Instrument::TriCal,
                tool,
                identify_tcp: false,
                target: None,
                measurements: identification
                    .iter()
                    .map(|p| Measurement {
                        q: p.q.to_vec(),
                        observation: Observation::Ball(p.ball.expect("identification poses have a ball")),
                        temperature_c: None,
                        time_s: None,
                        sequence: None,
                        approach: None,
                        indicators: None,
                        sigma: None,
                    })
                    .collect(),
                order: MeasuringOrder::Unknown,
            }],
        };
        progress(0.45, "selecting poses (DETMAX)");
        let pool = DetmaxPool::new(&cell, &IdentifyOptions::default()).map_err(identify_error)?;
        let (subset, info) = pool.select(select.n, select.index, select.seed).map_err(identify_error)?;
        progress(0.7, "planning tracker poses");
        let chosen: Vec<_> = subset.iter().map(|(_, i)| identification[*i].clone()).collect();
        identification = pc.sequence(chosen).map_err(plan_error)?;
        selection_info = Some(info);
    }
    let validation = if request.validation == 0 {
        Vec::new()
    } else {
        let v_opts = ValidationOptions { count: request.validation, ..Default::default() };
        pc.plan_validation(&v_opts, request.seed).map_err(plan_error)?.poses
    };
    let plan = PosePlan {
        identification: identification
            .iter()
            .map(|p| PlannedBallPose { joints_deg: to_deg(&p.q), ball: p.ball, nu_deg: p.nu.map(|v| v / DEG) })
            .collect(),
        validation: validation.iter().map(|p| PlannedTrackerPose { joints_deg: to_deg(&p.q), nest: p.nest }).collect(),
        candidates: candidates.poses.len(),
        selection: selection_info,
        nests: pc
            .layout()
            .nests
            .iter()
            .map(|n| PlanNest { tool: ToolSpec::from_tool(&n.tool), opening: [n.opening.x, n.opening.y, n.opening.z] })
            .collect(),
        home_deg: to_deg(&pc.layout().home),
    };
    Ok(plan)
}

/// Write a job's output; returns the job's result.
pub async fn store(
    tx: &mut crate::db::Conn,
    job_id: &str,
    robot_id: &str,
    request_json: &str,
    out: Output,
) -> Result<JobResult, JobError> {
    match out {
        Output::PosePlan { plan } => {
            let row = records::PosePlanRow {
                id: crate::db::new_id(),
                robot_id: robot_id.to_string(),
                request_json: request_json.to_string(),
                result_json: serde_json::to_string(&plan).expect("a plan serialises"),
                job_id: Some(job_id.to_string()),
                created_at: crate::db::now(),
            };
            records::insert_pose_plan(&mut *tx, &row).await?;
            Ok(JobResult::PosePlan(PosePlanResult {
                pose_plan_id: row.id,
                identification: plan.identification.len(),
                validation: plan.validation.len(),
            }))
        }
        Output::Identification { doc_json, sessions_json, summary, activate } => {
            let row =
                records::insert_parameter_set(&mut *tx, robot_id, &doc_json, &sessions_json, Some(job_id)).await?;
            if activate {
                crate::db::corrections::activate(&mut *tx, robot_id, &row.id, None, Some(job_id)).await?;
            }
            Ok(JobResult::Identification(IdentificationResult {
                parameter_set_id: row.id,
                version: row.version,
                activated: activate,
                summary,
            }))
        }
        Output::Validation { parameter_set_id, report, sessions_json, summary } => {
            let row = records::ValidationRow {
                id: crate::db::new_id(),
                parameter_set_id: parameter_set_id.clone(),
                sessions_json,
                report_json: report.to_string(),
                job_id: Some(job_id.to_string()),
                created_at: crate::db::now(),
            };
            records::insert_validation(&mut *tx, &row).await?;
            Ok(JobResult::Validation(ValidationResult { validation_id: row.id, parameter_set_id, summary }))
        }
        Output::Diagnosis {
            parameter_set_id,
            sessions_json,
            report_json,
            accepted_doc_json,
            status,
            summary,
            effects,
        } => {
            let row = records::DiagnosisRow {
                id: crate::db::new_id(),
                parameter_set_id: parameter_set_id.clone(),
                request_json: request_json.to_string(),
                sessions_json,
                report_json,
                accepted_doc_json,
                accepted_parameter_set_id: None,
                job_id: Some(job_id.to_string()),
                created_at: crate::db::now(),
            };
            records::insert_diagnosis(&mut *tx, &row).await?;
            Ok(JobResult::Diagnosis(DiagnosisResult {
                diagnosis_id: row.id,
                parameter_set_id,
                status,
                summary,
                effects,
            }))
        }
        Output::Iso9283 { session_id, session, parameter_set_id, evaluation } => {
            let row = crate::db::iso9283::Iso9283Row {
                id: crate::db::new_id(),
                robot_id: robot_id.to_string(),
                session_id,
                parameter_set_id: parameter_set_id.clone(),
                request_json: request_json.to_string(),
                report_json: serde_json::to_string(&evaluation).expect("an evaluation serialises"),
                job_id: Some(job_id.to_string()),
                created_at: crate::db::now(),
            };
            crate::db::iso9283::insert(&mut *tx, &row).await?;
            Ok(JobResult::Iso9283(Iso9283Result {
                evaluation_id: row.id,
                session,
                parameter_set_id,
                nominal: evaluation.nominal.summary.clone(),
                calibrated: evaluation.calibrated.as_ref().map(|c| c.summary.clone()),
            }))
        }
    }
}

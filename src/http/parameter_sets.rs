//! Parameter sets: immutable and versioned per robot. A robot's calibration history (created,
//! sessions used, quality, validation figures when known); activating one is an explicit call,
//! recorded in the robot's activation history; export (`exports.rs`: the parameter-set file that
//! `robocal compensate --params` reads, and other tools' formats); import of a set made elsewhere (e.g. the thesis's Table 5.1).
//! A set is never deleted (DELETE answers 405): it is archived — hidden from the history, never
//! activated again — with a reason, and stays in the activation history.

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use serde::{Deserialize, Serialize};
use serde_json::Value;
use utoipa::{IntoParams, ToSchema};

use super::audit::{Event, reason};
use super::extract::{Authorized, CALIBRATE, JsonBody, READ};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::robots::model_of;
use crate::db::{self, corrections, records};
use crate::domain::ParameterSetFile;

/// Validation figures of a set (mm).
#[derive(Debug, Serialize, ToSchema)]
pub struct ValidationSummary {
    pub validation_id: String,
    pub created_at: String,
    pub sessions: Vec<String>,
    /// Held out: none of its sessions was used to fit the set, and one is a validation session.
    /// An in-sample validation's figures are fit residuals; only a held-out one vouches for the
    /// set (compensation counts no other).
    pub held_out: bool,
    #[schema(value_type = Object)]
    pub figures: Value,
}

/// A parameter set in a robot's history.
#[derive(Debug, Serialize, ToSchema)]
pub struct ParameterSetOut {
    pub id: String,
    pub robot_id: String,
    /// 1, 2, 3 … per robot.
    pub version: i64,
    pub created_at: String,
    /// Whether compensation uses it.
    pub active: bool,
    /// Names of the sessions it was identified from (empty when imported).
    pub sessions: Vec<String>,
    /// The sessions it was fitted on, as its file and the store record them (an imported file
    /// may record some): a validation on any of them is in-sample, not held out.
    pub fit_sessions: Vec<String>,
    /// Single-set answers: what to do when the set has no held-out validation yet (a set accepted
    /// from a diagnosis that pooled the validation sessions has none: it was fitted on them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub validation_needed: Option<String>,
    /// The identification job, when it came from one.
    pub job_id: Option<String>,
    /// Quality summary: `identified`, `kappa_si`, `kappa_scaled`, `rms_residual_mm`,
    /// `measurements` (from the set's quality report, when it has one).
    /// `null` for a set without a quality report (an imported one).
    #[schema(value_type = Option<Object>)]
    pub quality: Value,
    /// Validations of this set, newest first.
    pub validations: Vec<ValidationSummary>,
    /// When, by whom and why it was archived; absent when it is not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub archived: Option<ArchivedOut>,
    /// The parameter-set file (only in single-set answers).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Object>)]
    pub parameter_set: Option<Value>,
}

/// An archived set's record.
#[derive(Debug, Serialize, ToSchema)]
pub struct ArchivedOut {
    pub at: String,
    /// The bearer token's name; absent when the server took the request without a token.
    pub by: Option<String>,
    pub reason: String,
}

/// The part of a stored document a set's summary shows: the quality report's summary fields.
/// Everything else (the parameters, the correlation matrix, per-measurement lists) is skipped by
/// the parser without building values — a page of sets reads as much text but allocates little.
#[derive(Deserialize)]
struct QualityOnly {
    #[serde(default)]
    quality: Option<QualityFields>,
}

#[derive(Deserialize)]
struct QualityFields {
    /// The sessions fitted on; absent or `null` where a report does not record them (an imported
    /// table, an older file).
    #[serde(default)]
    sessions: Option<Vec<String>>,
    #[serde(default)]
    n_parameters: Value,
    #[serde(default)]
    n_measurements: Value,
    #[serde(default)]
    iterations: Value,
    #[serde(default)]
    kappa_si: Value,
    #[serde(default)]
    kappa_scaled: Value,
    #[serde(default)]
    rms_residual_mm: Value,
}

/// The quality summary of a stored set and the sessions it was fitted on (its document's
/// `quality.sessions` joined with the store's list, as `domain::validation::fit_data` joins them).
fn quality_summary(row: &records::ParameterSetRow) -> Result<(Value, Vec<String>), ApiError> {
    let q: QualityOnly = serde_json::from_str(&row.doc_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    let mut fit: Vec<String> = q.quality.as_ref().and_then(|q| q.sessions.clone()).unwrap_or_default();
    let listed: Vec<String> =
        serde_json::from_str(&row.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    for s in listed {
        if !fit.contains(&s) {
            fit.push(s);
        }
    }
    let summary = q.quality.map_or(Value::Null, |q| {
        serde_json::json!({
            "identified": q.n_parameters, "measurements": q.n_measurements, "iterations": q.iterations,
            "kappa_si": q.kappa_si, "kappa_scaled": q.kappa_scaled, "rms_residual_mm": q.rms_residual_mm,
        })
    });
    Ok((summary, fit))
}

/// The figures a validation summary shows, read from a stored validation report without its
/// per-measurement residuals.
#[derive(Deserialize, Default)]
struct Figures {
    #[serde(default)]
    n: Value,
    #[serde(default)]
    mean_mm: Value,
    #[serde(default)]
    median_mm: Value,
    #[serde(default)]
    std_mm: Value,
    #[serde(default)]
    rms_mm: Value,
    #[serde(default)]
    p95_mm: Value,
    #[serde(default)]
    max_mm: Value,
    #[serde(default)]
    nominal: Option<Box<Figures>>,
    #[serde(default)]
    purposes: Vec<crate::domain::cell::PurposeSpec>,
}

impl Figures {
    fn json(self) -> Value {
        serde_json::json!({
            "n": self.n, "mean_mm": self.mean_mm, "median_mm": self.median_mm, "std_mm": self.std_mm,
            "rms_mm": self.rms_mm, "p95_mm": self.p95_mm, "max_mm": self.max_mm,
        })
    }
}

/// A validation's summary; `fit_sessions`: what its set was fitted on.
fn validation_summary(v: records::ValidationRow, fit_sessions: &[String]) -> Result<ValidationSummary, ApiError> {
    let mut report: Figures = serde_json::from_str(&v.report_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    let nominal = report.nominal.take().map_or_else(Figures::default, |b| *b);
    let purposes: Vec<_> = report.purposes.iter().map(|p| p.to_purpose()).collect();
    let mut figures = report.json();
    figures["nominal"] = nominal.json();
    let sessions: Vec<String> =
        serde_json::from_str(&v.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?;
    Ok(ValidationSummary {
        validation_id: v.id,
        created_at: v.created_at,
        held_out: crate::validate::report::is_held_out(&sessions, &purposes, fit_sessions),
        sessions,
        figures,
    })
}

fn summary_out(
    row: &records::ParameterSetRow,
    active: bool,
    (quality, fit_sessions): (Value, Vec<String>),
    validations: Vec<ValidationSummary>,
    doc: Option<Value>,
) -> Result<ParameterSetOut, ApiError> {
    Ok(ParameterSetOut {
        id: row.id.clone(),
        robot_id: row.robot_id.clone(),
        version: row.version,
        created_at: row.created_at.clone(),
        active,
        sessions: serde_json::from_str(&row.sessions_json).map_err(|e| ApiError::Internal(e.to_string()))?,
        fit_sessions,
        validation_needed: None,
        job_id: row.job_id.clone(),
        quality,
        validations,
        archived: row.archived_at.as_ref().map(|at| ArchivedOut {
            at: at.clone(),
            by: row.archived_by.clone(),
            reason: row.archive_reason.clone().unwrap_or_default(),
        }),
        parameter_set: doc,
    })
}

/// One set with its validations; `full` adds the parameter-set file.
pub(super) async fn set_out(
    state: &AppState,
    row: &records::ParameterSetRow,
    active: bool,
    full: bool,
) -> Result<ParameterSetOut, ApiError> {
    let (quality, fit_sessions) = quality_summary(row)?;
    let validations = records::validations_of_set(&state.pool, &row.id)
        .await?
        .into_iter()
        .map(|v| validation_summary(v, &fit_sessions))
        .collect::<Result<Vec<_>, _>>()?;
    let doc =
        full.then(|| serde_json::from_str(&row.doc_json)).transpose().map_err(|e| ApiError::Internal(e.to_string()))?;
    let needed = if full && !validations.iter().any(|v| v.held_out) {
        Some(validation_needed(state, row, &fit_sessions).await?)
    } else {
        None
    };
    let mut out = summary_out(row, active, (quality, fit_sessions), validations, doc)?;
    out.validation_needed = needed;
    Ok(out)
}

/// What a set without a held-out validation needs, in words: the robot's validation sessions it
/// was not fitted on, or — when it was fitted on all of them (a diagnosis that pooled them) — a
/// new validation session to measure.
async fn validation_needed(
    state: &AppState,
    row: &records::ParameterSetRow,
    fit_sessions: &[String],
) -> Result<String, ApiError> {
    let sessions = records::sessions_of_robot(&state.pool, &row.robot_id).await?;
    let validation: Vec<&records::SessionRow> =
        sessions.iter().filter(|s| s.purpose == crate::domain::cell::PurposeSpec::Validation).collect();
    let fitted: Vec<&str> =
        validation.iter().filter(|s| fit_sessions.contains(&s.name)).map(|s| s.name.as_str()).collect();
    let free: Vec<&str> =
        validation.iter().filter(|s| !fit_sessions.contains(&s.name)).map(|s| s.name.as_str()).collect();
    let pooled = if fitted.is_empty() {
        String::new()
    } else {
        format!(" It was fitted on the validation sessions {}: a validation on them is in-sample.", fitted.join(", "))
    };
    Ok(if free.is_empty() {
        format!(
            "no held-out validation.{pooled} Measure a new validation session (POST /v1/robots/{}/sessions with \
             \"purpose\": \"validation\", then its measurements) and validate the set on it (POST \
             /v1/parameter-sets/{}/validations); until then compensation refuses it (409) unless allow_unvalidated.",
            row.robot_id, row.id
        )
    } else {
        format!(
            "no held-out validation.{pooled} Validate it on {} (POST /v1/parameter-sets/{}/validations): sessions it \
             was not fitted on; until then compensation refuses it (409) unless allow_unvalidated.",
            free.join(", "),
            row.id
        )
    })
}

async fn find(state: &AppState, id: &str) -> Result<records::ParameterSetRow, ApiError> {
    records::parameter_set(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("parameter set", id))
}

pub(super) async fn is_active(state: &AppState, row: &records::ParameterSetRow) -> Result<bool, ApiError> {
    Ok(find_robot(state, &row.robot_id).await?.active_parameter_set_id.as_deref() == Some(row.id.as_str()))
}

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct HistoryQuery {
    /// List archived sets too (default false).
    pub include_archived: Option<bool>,
}

/// A robot's calibration history, newest version first, a page at a time; archived sets only
/// with `include_archived=true`.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/parameter-sets", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id"), HistoryQuery, PageQuery),
    responses(
        (status = 200, description = "Parameter sets, newest first, with quality and validation figures", body = Vec<ParameterSetOut>, headers(
            ("X-Total-Count" = i64, description = "Parameter sets in the history"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn history(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    Query(q): Query<HistoryQuery>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<ParameterSetOut>>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let archived = q.include_archived.unwrap_or(false);
    let crate::db::paging::Page { items: rows, total } =
        records::parameter_sets_of_robot(&state.pool, &robot.id, archived, page.offset, page.limit).await?;
    // The page's validations in one query, not one per set.
    let ids: Vec<&str> = rows.iter().map(|r| r.id.as_str()).collect();
    let mut by_set: std::collections::HashMap<String, Vec<ValidationSummary>> = std::collections::HashMap::new();
    let summaries: std::collections::HashMap<&str, (Value, Vec<String>)> =
        rows.iter().map(|r| Ok((r.id.as_str(), quality_summary(r)?))).collect::<Result<_, ApiError>>()?;
    for v in records::validations_of_sets(&state.pool, &ids).await? {
        let fit = summaries.get(v.parameter_set_id.as_str()).map_or(&[][..], |(_, f)| &f[..]);
        by_set.entry(v.parameter_set_id.clone()).or_default().push(validation_summary(v, fit)?);
    }
    let mut out = Vec::with_capacity(rows.len());
    let mut summaries = summaries;
    for row in &rows {
        let active = robot.active_parameter_set_id.as_deref() == Some(row.id.as_str());
        let validations = by_set.remove(&row.id).unwrap_or_default();
        let summary = summaries.remove(row.id.as_str()).unwrap_or((Value::Null, Vec::new()));
        out.push(summary_out(row, active, summary, validations, None)?);
    }
    Ok(page.answer(total, out))
}

/// Import a parameter set made elsewhere (a parameter-set file) as the robot's next version.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/parameter-sets", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = crate::domain::ParameterSetFile, description = "A parameter-set file: {\"robot\", \"tool\", \"parameters\": [{\"name\", \"value\", \"nominal\", \"unit\"}, …]}", content_type = "application/json"),
    responses(
        (status = 201, description = "Stored as the next version (not activated)", body = ParameterSetOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid file, or made for another robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn import(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(file): JsonBody<ParameterSetFile>,
) -> Result<(StatusCode, Json<ParameterSetOut>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let model = model_of(&robot)?;
    let doc = file.to_doc().map_err(|e| ApiError::domain(e, ""))?;
    if doc.set.model != model {
        return Err(ApiError::invalid(
            "robot",
            format!("the file is for robot '{}', this robot is '{}'", doc.set.model.name, model.name),
        ));
    }
    // Stored as text, compiled from that text by every later use (`app::cache`): what it reads
    // back must compile, or each compensation with the set would answer 500.
    let text = doc.to_json_pretty();
    let back = crate::domain::ParameterSetDoc::from_json(&text)
        .map_err(|e| ApiError::invalid(&e.path, format!("the file does not read back as written: {e}")))?;
    crate::app::cache::usable_parts(&back).map_err(|e| ApiError::domain(e, ""))?;
    let mut tx = db::begin_write(&state.pool).await?;
    let row = records::insert_parameter_set(&mut tx, &robot.id, &text, "[]", None).await?;
    tx.commit().await?;
    Ok((StatusCode::CREATED, Json(set_out(&state, &row, false, true).await?)))
}

/// Get a parameter set with its file.
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    responses(
        (status = 200, description = "The set, its quality, validations and file", body = ParameterSetOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let row = find(&state, &set_id).await?;
    let active = is_active(&state, &row).await?;
    Ok(Json(set_out(&state, &row, active, true).await?))
}

/// The robot's active parameter set.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/active-parameter-set", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "The active set", body = ParameterSetOut),
        (status = 404, description = "Unknown robot, or no set is active", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn active(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let id = robot
        .active_parameter_set_id
        .clone()
        .ok_or_else(|| ApiError::NotFound { what: "active parameter set of robot", id: robot_id.clone() })?;
    let row = find(&state, &id).await?;
    Ok(Json(set_out(&state, &row, true, true).await?))
}

/// Which set to activate.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Activate {
    pub parameter_set_id: String,
}

/// Activate one of the robot's parameter sets: compensation uses it from now on. The activation
/// is recorded (who, when) in the robot's activation history. An archived set is not activated.
#[utoipa::path(put, path = "/v1/robots/{robot_id}/active-parameter-set", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = Activate, content_type = "application/json"),
    responses(
        (status = 200, description = "Activated", body = ParameterSetOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The set is archived (the `hint` says how to unarchive it)", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown set, or a set of another robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn activate(
    State(state): State<AppState>,
    auth: Authorized<CALIBRATE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<Activate>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let row = records::parameter_set(&state.pool, &body.parameter_set_id).await?.ok_or_else(|| {
        ApiError::unknown("parameter_set_id", format!("no parameter set '{}'", body.parameter_set_id))
    })?;
    if row.robot_id != robot.id {
        return Err(ApiError::foreign_set("parameter_set_id"));
    }
    let mut tx = db::begin_write(&state.pool).await?;
    // Under the write lock: the set cannot be archived between the check and the activation.
    let row = find_in(&mut tx, &row.id).await?;
    if let Some(at) = &row.archived_at {
        return Err(ApiError::conflict_hint(
            format!("parameter set version {} was archived at {at}: an archived set is not activated", row.version),
            format!(
                "unarchive it first: PATCH /v1/parameter-sets/{} with {{\"archived\": false, \"reason\": …}}",
                row.id
            ),
        ));
    }
    corrections::activate(&mut tx, &robot.id, &row.id, auth.actor().as_deref(), None).await?;
    tx.commit().await?;
    state.caches.robot_changed(&state.pool, &robot.id).await;
    Ok(Json(set_out(&state, &row, true, true).await?))
}

async fn find_in(tx: &mut crate::db::Conn, id: &str) -> Result<records::ParameterSetRow, ApiError> {
    records::parameter_set(&mut *tx, id).await?.ok_or_else(|| ApiError::not_found("parameter set", id))
}

/// A change of a parameter set: archive it or unarchive it, saying why.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ParameterSetPatch {
    /// `true`: archive (hidden from the history, never activated); `false`: unarchive.
    pub archived: bool,
    /// Why (required, not blank, at most 2000 characters): kept with the set and in the audit timeline.
    #[serde(default)]
    #[schema(value_type = String, required = true, min_length = 1, max_length = 2000, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub reason: Option<String>,
}

/// Archive a parameter set — or unarchive it — with a reason. An archived set is hidden from
/// the robot's history (`?include_archived=true` lists it), cannot be activated (409) and stays
/// readable, exportable and in the activation history: a set that was active once is never
/// removed from the record. The active set cannot be archived (409: activate another first).
#[utoipa::path(patch, path = "/v1/parameter-sets/{set_id}", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    request_body(content = ParameterSetPatch, content_type = "application/json",
        example = json!({"archived": true, "reason": "identified with the wrong tool mass"})),
    responses(
        (status = 200, description = "Archived or unarchived", body = ParameterSetOut),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The set is the robot's active one; already archived (or, unarchiving, not archived)", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`reason` missing or empty", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn patch(
    State(state): State<AppState>,
    auth: Authorized<CALIBRATE>,
    Path(set_id): Path<String>,
    JsonBody(body): JsonBody<ParameterSetPatch>,
) -> Result<Json<ParameterSetOut>, ApiError> {
    find(&state, &set_id).await?;
    let why = reason(body.reason.as_deref())?;
    let actor = auth.actor();
    let mut tx = db::begin_write(&state.pool).await?;
    let row = find_in(&mut tx, &set_id).await?;
    let robot = records::robot(&mut *tx, &row.robot_id)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("robot {} of parameter set {} missing", row.robot_id, row.id)))?;
    let active = robot.active_parameter_set_id.as_deref() == Some(row.id.as_str());
    let at = db::now();
    let action = match (body.archived, &row.archived_at) {
        (true, Some(when)) => {
            return Err(ApiError::conflict(format!(
                "parameter set version {} is already archived (at {when})",
                row.version
            )));
        }
        (false, None) => {
            return Err(ApiError::conflict(format!("parameter set version {} is not archived", row.version)));
        }
        (true, None) if active => {
            return Err(ApiError::conflict_hint(
                format!(
                    "parameter set version {} is robot '{}''s active set: it cannot be archived",
                    row.version, robot.name
                ),
                format!(
                    "activate another set first (PUT /v1/robots/{}/active-parameter-set), then archive this one",
                    robot.id
                ),
            ));
        }
        (true, None) => {
            corrections::set_archived(&mut *tx, &row.id, Some((&at, actor.as_deref(), &why))).await?;
            "parameter_set_archived"
        }
        (false, Some(_)) => {
            corrections::set_archived(&mut *tx, &row.id, None).await?;
            "parameter_set_unarchived"
        }
    };
    let detail = serde_json::json!({"version": row.version, "created_at": row.created_at});
    super::audit::record(
        &mut tx,
        actor.as_deref(),
        &at,
        Event { action, robot_id: Some(&row.robot_id), subject_id: &row.id, reason: &why, detail },
    )
    .await?;
    let row = find_in(&mut tx, &set_id).await?;
    tx.commit().await?;
    Ok(Json(set_out(&state, &row, active, true).await?))
}

/// Parameter sets are never deleted: 405 (with `Allow` and a `hint`), after a 404 for an unknown
/// set. A set that was used must stay, so that what was compensated with it can be explained;
/// archive one instead (`PATCH` with `{"archived": true, "reason": …}`).
#[utoipa::path(delete, path = "/v1/parameter-sets/{set_id}", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id")),
    responses(
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 405, description = "Never deleted: archive instead (the problem's `hint`)", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["calibrate"])))]
pub async fn delete(
    State(state): State<AppState>,
    _auth: Authorized<CALIBRATE>,
    Path(set_id): Path<String>,
) -> Result<StatusCode, ApiError> {
    let row = find(&state, &set_id).await?;
    Err(ApiError::MethodNotAllowed {
        detail: format!("parameter sets are archived, not deleted (version {} stays in the record)", row.version),
        hint: format!("PATCH /v1/parameter-sets/{} with {{\"archived\": true, \"reason\": …}}", row.id),
        allow: "GET, PATCH",
    })
}

/// An activation of a parameter set.
#[derive(Debug, Serialize, ToSchema)]
pub struct ActivationOut {
    pub parameter_set_id: String,
    pub version: i64,
    /// Absent for the set that was active when activations began to be recorded.
    pub activated_at: Option<String>,
    /// The bearer token's name; absent without a token (or when a job activated its result).
    pub activated_by: Option<String>,
    /// The identification job that activated its own result.
    pub job_id: Option<String>,
    /// The set is the robot's active one now.
    pub active: bool,
    /// The set has been archived since.
    pub archived: bool,
}

/// A robot's activation history, newest first, a page at a time: which set compensation used
/// from when, archived sets included.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/activations", tag = "parameter-sets",
    params(("robot_id" = String, Path, description = "Robot id"), PageQuery),
    responses(
        (status = 200, description = "Activations, newest first", body = Vec<ActivationOut>, headers(
            ("X-Total-Count" = i64, description = "The robot's activations in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn activations(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<ActivationOut>>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let activations = corrections::activations(&state.pool, &robot.id, page.offset, page.limit).await?;
    let mut out = Vec::new();
    for a in activations.items {
        let set = find(&state, &a.parameter_set_id).await?;
        out.push(ActivationOut {
            active: robot.active_parameter_set_id.as_deref() == Some(set.id.as_str()),
            archived: set.archived_at.is_some(),
            version: set.version,
            parameter_set_id: a.parameter_set_id,
            activated_at: a.activated_at,
            activated_by: a.activated_by,
            job_id: a.job_id,
        });
    }
    Ok(page.answer(activations.total, out))
}

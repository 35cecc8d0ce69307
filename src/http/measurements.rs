//! A session's measurements: batches appended in one transaction — all rows or none — with an
//! `Idempotency-Key` so a cell PC can retry safely, and a keyless re-upload of a batch already
//! stored refused (409) unless asked for; JSON or CSV (parsed by
//! [`crate::domain::measurement_csv`]); listed with paging. A measurement is never deleted: it is
//! excluded (left out of every job) and restored by records that say who, when and why.

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use utoipa::{IntoParams, ToSchema};

use super::audit::{Event, reason};
use super::extract::{Authorized, JsonBody, MEASURE, READ, is_json, parse_json};
use super::paging::{MeasurementPageQuery, Paging};
use super::robots::find as find_robot;
use super::sessions::find;
use super::{ApiError, AppState};
use crate::app::robots::model_of;
use crate::db::{self, corrections, records};
use crate::domain::cell::{ArtefactSpec, MeasurementSpec, measurement};
use crate::domain::measurement_csv::parse_csv;

/// A batch of measurements (JSON form).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewMeasurements {
    /// At most the server's batch limit (`serve --max-batch`, default 10,000; the served document
    /// states the server's).
    #[schema(min_items = 1, max_items = 10000)]
    pub measurements: Vec<MeasurementSpec>,
}

/// The stored batch.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct BatchOut {
    pub batch_id: String,
    pub session_id: String,
    /// Index (0-based, within the session) of the batch's first measurement.
    pub first_index: i64,
    pub count: i64,
    /// Measurements in the session after this batch.
    pub total: i64,
}

/// The header that makes a batch upload idempotent.
pub const IDEMPOTENCY_KEY: &str = "idempotency-key";

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct AppendQuery {
    /// Append even when the session already holds a batch of exactly these measurements (the same
    /// poses measured again on purpose). Without it, a keyless re-upload is refused (409).
    pub allow_duplicate: Option<bool>,
}

/// Append a batch of measurements to a session: one transaction, all rows or none. A retry with
/// the same `Idempotency-Key` and the same body returns the first answer (with
/// `Idempotency-Replayed: true`) instead of appending twice; the same key with another body is 409.
/// Without a key, a batch whose measurements are exactly those of a batch the session already
/// holds (as JSON or CSV, however formatted) is refused with 409 naming that batch, unless
/// `?allow_duplicate=true`.
#[utoipa::path(post, path = "/v1/sessions/{session_id}/measurements", tag = "sessions",
    params(
        ("session_id" = String, Path, description = "Session id"),
        ("Idempotency-Key" = Option<String>, Header, description = "Makes a retried upload safe: the same key and body return the first answer (1–200 visible ASCII characters)",
            min_length = 1, max_length = 200, pattern = r"^[!-~]([ -~]{0,198}[!-~])?$"),
        AppendQuery),
    request_body(description = "JSON {\"measurements\": [...]} (the cell-file measurement objects) or CSV with a header row \
(q1_deg … qN_deg, ball, x_mm y_mm z_mm, a_deg b_deg c_deg, temperature_c, time_s, sequence, approach_1 … approach_N, dx_mm dy_mm dz_mm)",
        content((NewMeasurements = "application/json"), (String = "text/csv"))),
    responses(
        (status = 201, description = "Appended (or replayed)", body = BatchOut),
        (status = 400, description = "Malformed JSON or CSV", body = super::Problem, content_type = "application/problem+json"),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Idempotency key reused with another body; or, without a key, the same measurements as a batch already appended (the problem's `hint` says how to resend)", body = super::Problem, content_type = "application/problem+json"),
        (status = 413, description = "More measurements than the batch limit, or body too large", body = super::Problem, content_type = "application/problem+json"),
        (status = 415, description = "Neither JSON nor CSV", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid measurement (NaN, wrong length, joints outside limits, unknown ball…), naming it", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn append(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    Path(session_id): Path<String>,
    Query(q): Query<AppendQuery>,
    headers: HeaderMap,
    body: Result<Bytes, BytesRejection>,
) -> Result<Response, ApiError> {
    let session = find(&state, &session_id).await?;
    let body = body.map_err(|e| {
        if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            ApiError::TooLarge { detail: "the request body exceeds the server's body limit".into(), field: None }
        } else {
            ApiError::malformed(None, e.body_text())
        }
    })?;
    let robot = find_robot(&state, &session.robot_id).await?;
    let model = model_of(&robot)?;
    let ct = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("");
    let is_csv = ct.split(';').next().unwrap_or("").trim().eq_ignore_ascii_case("text/csv");
    let (specs, prefix): (Vec<MeasurementSpec>, &str) = if is_json(Some(ct)) {
        (parse_json::<NewMeasurements>(&body)?.measurements, "measurements")
    } else if is_csv {
        (parse_csv(&body, model.dof())?, "csv row")
    } else {
        return Err(ApiError::UnsupportedMediaType(format!(
            "measurements are application/json or text/csv, got {}",
            if ct.is_empty() { "none" } else { ct }
        )));
    };
    if specs.is_empty() {
        return Err(ApiError::invalid("measurements", "the batch is empty"));
    }
    if specs.len() > state.config.max_batch {
        return Err(ApiError::TooLarge {
            detail: format!("{} measurements in one batch; the limit is {}", specs.len(), state.config.max_batch),
            field: Some("measurements".into()),
        });
    }
    let key = match headers.get(IDEMPOTENCY_KEY) {
        None => None,
        Some(v) => {
            let k = v.to_str().map(str::trim).unwrap_or("");
            if k.is_empty() || k.len() > 200 {
                return Err(ApiError::malformed(
                    Some("Idempotency-Key".into()),
                    "must be 1–200 visible ASCII characters",
                ));
            }
            Some(k.to_string())
        }
    };

    // Validate every measurement against the robot, the instrument and the artefact.
    let instrument = session.instrument.to_instrument();
    let artefact = match &session.artefact_id {
        None => None,
        Some(id) => {
            let row = records::artefact(&state.pool, id)
                .await?
                .ok_or_else(|| ApiError::Internal(format!("artefact {id} missing")))?;
            let spec: ArtefactSpec =
                serde_json::from_str(&row.spec_json).map_err(|e| ApiError::Internal(e.to_string()))?;
            Some(super::artefacts::artefact(&spec)?)
        }
    };
    // Where this robot's readings may lie: near its base guess (when it has one), ±100 m anyway.
    let base_guess = match robot.base_guess_json {
        None => None,
        Some(_) => Some(crate::app::robots::robot_base(&robot)?),
    };
    let bounds = crate::domain::cell::position_bounds(&model, base_guess.as_ref());
    let mut rows = Vec::with_capacity(specs.len());
    for (i, m) in specs.iter().enumerate() {
        let at = if prefix == "csv row" { format!("csv line {}", i + 2) } else { format!("{prefix}[{i}]") };
        measurement(m, &model, instrument, artefact.as_ref(), &bounds).map_err(|e| ApiError::domain(e, &at))?;
        rows.push(serde_json::to_string(m).expect("serialises"));
    }
    let hash = {
        let mut h = Sha256::new();
        h.update(if is_csv { b"csv\0" as &[u8] } else { b"json\0" });
        h.update(&body);
        h.finalize().iter().map(|b| format!("{b:02x}")).collect::<String>()
    };

    let mut tx = db::begin_write(&state.pool).await?;
    if let Some(k) = &key
        && let Some(b) = records::batch_by_key(&mut *tx, &session.id, k).await?
    {
        if b.request_hash != hash {
            return Err(ApiError::Conflict {
                detail: format!("Idempotency-Key '{k}' was used for another batch of this session (batch {})", b.id),
                field: Some("Idempotency-Key".into()),
                hint: None,
            });
        }
        let total = records::measurement_count(&mut *tx, &session.id).await?;
        tx.commit().await?;
        let out = BatchOut { batch_id: b.id, session_id: session.id, first_index: b.first_seq, count: b.count, total };
        let mut res = (StatusCode::CREATED, Json(out)).into_response();
        res.headers_mut().insert("idempotency-replayed", HeaderValue::from_static("true"));
        return Ok(res);
    }
    let content = records::content_hash(&rows);
    if key.is_none()
        && !q.allow_duplicate.unwrap_or(false)
        && let Some(b) = records::identical_batch(&mut tx, &session.id, &content, rows.len() as i64).await?
    {
        return Err(ApiError::conflict_hint(
            format!(
                "these {} measurements are a duplicate of batch {} appended to session '{}' at {} (measurements {}–{}); nothing was appended",
                rows.len(),
                b.id,
                session.name,
                b.created_at,
                b.first_seq,
                b.first_seq + b.count - 1
            ),
            "if this is a retry, the batch is already stored: resend uploads with an Idempotency-Key so a retry returns the first answer; if the same poses were measured again on purpose, resend with ?allow_duplicate=true",
        ));
    }
    let first = records::measurement_count(&mut *tx, &session.id).await?;
    let batch = records::BatchRow {
        id: db::new_id(),
        session_id: session.id.clone(),
        idempotency_key: key,
        request_hash: hash,
        first_seq: first,
        count: rows.len() as i64,
        created_at: db::now(),
        content_hash: Some(content),
    };
    records::insert_batch(&mut *tx, &batch).await?;
    records::insert_measurements(&mut tx, &session.id, first, &batch.id, &rows).await?;
    tx.commit().await?;
    let out = BatchOut {
        batch_id: batch.id,
        session_id: session.id,
        first_index: first,
        count: batch.count,
        total: first + batch.count,
    };
    Ok((StatusCode::CREATED, Json(out)).into_response())
}

/// An exclusion of a measurement: who left it out of the jobs, when and why; once restored,
/// who brought it back, when and why.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct ExclusionOut {
    pub id: String,
    pub reason: String,
    /// The bearer token's name; absent when the server took the request without a token.
    pub excluded_by: Option<String>,
    pub excluded_at: String,
    pub restore_reason: Option<String>,
    pub restored_by: Option<String>,
    /// Absent while the exclusion holds.
    pub restored_at: Option<String>,
}

fn exclusion_out(e: corrections::ExclusionRow) -> ExclusionOut {
    ExclusionOut {
        id: e.id,
        reason: e.reason,
        excluded_by: e.excluded_by,
        excluded_at: e.excluded_at,
        restore_reason: e.restore_reason,
        restored_by: e.restored_by,
        restored_at: e.restored_at,
    }
}

/// One stored measurement with its index in the session and whether the jobs use it.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct MeasurementItem {
    pub index: i64,
    #[serde(flatten)]
    pub measurement: MeasurementSpec,
    /// Left out of identification, validation and diagnosis (and of the exported cell).
    pub excluded: bool,
    /// The exclusion in force (reason, who, when), when excluded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub exclusion: Option<ExclusionOut>,
}

/// A page of measurements.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct MeasurementPage {
    pub items: Vec<MeasurementItem>,
    pub total: i64,
    pub offset: i64,
    /// Offset of the next page; absent on the last.
    pub next_offset: Option<i64>,
}

/// A page of a session's measurements, in order (`offset` is the first measurement's index;
/// `limit` defaults to 1000 here, at most 10000).
#[utoipa::path(get, path = "/v1/sessions/{session_id}/measurements", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id"), MeasurementPageQuery),
    responses(
        (status = 200, description = "Measurements offset … offset + limit", body = MeasurementPage, headers(
            ("X-Total-Count" = i64, description = "Measurements in the session"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad paging values", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn measurements(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(session_id): Path<String>,
    page: Paging<1000, 10_000>,
) -> Result<(HeaderMap, Json<MeasurementPage>), ApiError> {
    let session = find(&state, &session_id).await?;
    let offset = page.offset;
    let mut tx = state.pool.begin().await?;
    let rows = records::measurements(&mut *tx, &session.id, offset, page.limit).await?;
    let mut open =
        corrections::open_exclusions(&mut *tx, &session.id, offset, page.limit).await?.into_iter().peekable();
    tx.commit().await?;
    let items = rows
        .into_iter()
        .map(|(index, json)| {
            let exclusion = open.next_if(|e| e.seq == index).map(exclusion_out);
            serde_json::from_str(&json)
                .map(|measurement| MeasurementItem { index, measurement, excluded: exclusion.is_some(), exclusion })
                .map_err(|e| ApiError::Internal(format!("measurement {index} of session {}: {e}", session.id)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let total = session.measurements;
    let next = offset + items.len() as i64;
    let headers = page.headers(total, items.len());
    Ok((headers, Json(MeasurementPage { items, total, offset, next_offset: (next < total).then_some(next) })))
}

/// A stored measurement with its exclusion state and the history of its exclusions.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct MeasurementOut {
    pub session_id: String,
    pub index: i64,
    #[serde(flatten)]
    pub measurement: MeasurementSpec,
    /// Left out of identification, validation and diagnosis (and of the exported cell).
    pub excluded: bool,
    /// The exclusion in force, when excluded.
    pub exclusion: Option<ExclusionOut>,
    /// Every exclusion the measurement had, oldest first, restored ones with their restoring.
    pub history: Vec<ExclusionOut>,
}

/// A session's measurement by index, or 404.
async fn measurement_out(
    db: &mut crate::db::Conn,
    session: &records::SessionRow,
    index: i64,
) -> Result<MeasurementOut, ApiError> {
    let not_found = || ApiError::NotFound { what: "measurement", id: format!("{index} of session {}", session.id) };
    let (_, json) = records::measurements(&mut *db, &session.id, index.max(0), 1)
        .await?
        .pop()
        .filter(|(i, _)| *i == index)
        .ok_or_else(not_found)?;
    let measurement = serde_json::from_str(&json)
        .map_err(|e| ApiError::Internal(format!("measurement {index} of session {}: {e}", session.id)))?;
    let history: Vec<ExclusionOut> =
        corrections::exclusion_history(&mut *db, &session.id, index).await?.into_iter().map(exclusion_out).collect();
    let exclusion = history.iter().find(|e| e.restored_at.is_none()).map(|e| ExclusionOut {
        id: e.id.clone(),
        reason: e.reason.clone(),
        excluded_by: e.excluded_by.clone(),
        excluded_at: e.excluded_at.clone(),
        restore_reason: None,
        restored_by: None,
        restored_at: None,
    });
    Ok(MeasurementOut {
        session_id: session.id.clone(),
        index,
        measurement,
        excluded: exclusion.is_some(),
        exclusion,
        history,
    })
}

/// A stored measurement, whether it is excluded, and the history of its exclusions.
#[utoipa::path(get, path = "/v1/sessions/{session_id}/measurements/{index}", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id"),
           ("index" = i64, Path, description = "The measurement's 0-based index in the session")),
    responses(
        (status = 200, description = "The measurement", body = MeasurementOut),
        (status = 404, description = "Unknown session or index", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path((session_id, index)): Path<(String, i64)>,
) -> Result<Json<MeasurementOut>, ApiError> {
    let session = find(&state, &session_id).await?;
    let mut conn = state.pool.acquire().await?;
    Ok(Json(measurement_out(&mut conn, &session, index).await?))
}

/// A change of a measurement: exclude it or restore it, saying why.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MeasurementPatch {
    /// `true`: leave the measurement out of every job from now on; `false`: restore it.
    pub excluded: bool,
    /// Why (required, not blank, at most 2000 characters): kept with the exclusion, or with its restoring.
    #[serde(default)]
    #[schema(value_type = String, required = true, min_length = 1, max_length = 2000, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub reason: Option<String>,
}

/// Exclude a measurement from identification, validation and diagnosis — or restore it — with a
/// reason. Nothing is deleted: an exclusion is a record (who: the token's name, when, why), and
/// restoring closes it with its own who, when and why; the measurement's `history` keeps both,
/// and the audit timeline (`GET /v1/audit-events`) shows them. Jobs submitted afterwards leave
/// excluded measurements out (a job reports the measurements it used, and names measurements by
/// their stored index); parameter sets already made are unchanged.
#[utoipa::path(patch, path = "/v1/sessions/{session_id}/measurements/{index}", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id"),
           ("index" = i64, Path, description = "The measurement's 0-based index in the session")),
    request_body(content = MeasurementPatch, content_type = "application/json",
        example = json!({"excluded": true, "reason": "ball 2 was not seated: indicator reading 0.4 mm"})),
    responses(
        (status = 200, description = "Excluded or restored: the measurement with its history", body = MeasurementOut),
        (status = 404, description = "Unknown session or index", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Already excluded (or, restoring, not excluded)", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`reason` missing or empty", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn patch(
    State(state): State<AppState>,
    auth: Authorized<MEASURE>,
    Path((session_id, index)): Path<(String, i64)>,
    JsonBody(body): JsonBody<MeasurementPatch>,
) -> Result<Json<MeasurementOut>, ApiError> {
    let session = find(&state, &session_id).await?;
    let why = reason(body.reason.as_deref())?;
    let actor = auth.actor();
    let mut tx = db::begin_write(&state.pool).await?;
    let before = measurement_out(&mut tx, &session, index).await?;
    let at = db::now();
    let action = match (body.excluded, before.exclusion) {
        (true, Some(e)) => {
            return Err(ApiError::conflict_hint(
                format!(
                    "measurement {index} of session '{}' is already excluded (since {}{}: {})",
                    session.name,
                    e.excluded_at,
                    e.excluded_by.map(|b| format!(" by {b}")).unwrap_or_default(),
                    e.reason
                ),
                "restore it first ({\"excluded\": false, \"reason\": …}) to exclude it again with another reason",
            ));
        }
        (false, None) => {
            return Err(ApiError::conflict(format!(
                "measurement {index} of session '{}' is not excluded: there is nothing to restore",
                session.name
            )));
        }
        (true, None) => {
            let row = corrections::ExclusionRow {
                id: db::new_id(),
                session_id: session.id.clone(),
                seq: index,
                reason: why.clone(),
                excluded_by: actor.clone(),
                excluded_at: at.clone(),
                restore_reason: None,
                restored_by: None,
                restored_at: None,
            };
            corrections::insert_exclusion(&mut *tx, &row).await?;
            "measurement_excluded"
        }
        (false, Some(e)) => {
            if !corrections::close_exclusion(&mut *tx, &e.id, &why, actor.as_deref(), &at).await? {
                return Err(ApiError::Internal(format!("exclusion {} vanished under the write lock", e.id)));
            }
            "measurement_restored"
        }
    };
    let detail = serde_json::json!({"session_name": session.name, "index": index});
    super::audit::record(
        &mut tx,
        actor.as_deref(),
        &at,
        Event { action, robot_id: Some(&session.robot_id), subject_id: &session.id, reason: &why, detail },
    )
    .await?;
    let after = measurement_out(&mut tx, &session, index).await?;
    tx.commit().await?;
    Ok(Json(after))
}

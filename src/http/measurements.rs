//! A session's measurements: batches appended in one transaction — all rows or none — with an
//! `Idempotency-Key` so a cell PC can retry safely; JSON or CSV (parsed by
//! [`crate::domain::measurement_csv`]); listed with paging.

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use utoipa::ToSchema;

use super::extract::{Authorized, MEASURE, READ, is_json, parse_json};
use super::paging::{PageQuery, Paging};
use super::robots::find as find_robot;
use super::sessions::find;
use super::{ApiError, AppState};
use crate::app::robots::model_of;
use crate::db::{self, records};
use crate::domain::cell::{ArtefactSpec, MeasurementSpec, measurement};
use crate::domain::measurement_csv::parse_csv;

/// A batch of measurements (JSON form).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewMeasurements {
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

/// Append a batch of measurements to a session: one transaction, all rows or none. A retry with
/// the same `Idempotency-Key` and the same body returns the first answer (with
/// `Idempotency-Replayed: true`) instead of appending twice; the same key with another body is 409.
#[utoipa::path(post, path = "/v1/sessions/{session_id}/measurements", tag = "sessions",
    params(
        ("session_id" = String, Path, description = "Session id"),
        ("Idempotency-Key" = Option<String>, Header, description = "Makes a retried upload safe: the same key and body return the first answer")),
    request_body(description = "JSON {\"measurements\": [...]} (the cell-file measurement objects) or CSV with a header row \
(q1_deg … qN_deg, ball, x_mm y_mm z_mm, a_deg b_deg c_deg, temperature_c, time_s, sequence, approach_1 … approach_N, dx_mm dy_mm dz_mm)",
        content((NewMeasurements = "application/json"), (String = "text/csv"))),
    responses(
        (status = 201, description = "Appended (or replayed)", body = BatchOut),
        (status = 400, description = "Malformed JSON or CSV", body = super::Problem, content_type = "application/problem+json"),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Idempotency key reused with another body", body = super::Problem, content_type = "application/problem+json"),
        (status = 413, description = "More measurements than the batch limit, or body too large", body = super::Problem, content_type = "application/problem+json"),
        (status = 415, description = "Neither JSON nor CSV", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid measurement (NaN, wrong length, joints outside limits, unknown ball…), naming it", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn append(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    Path(session_id): Path<String>,
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
    let mut rows = Vec::with_capacity(specs.len());
    for (i, m) in specs.iter().enumerate() {
        let at = if prefix == "csv row" { format!("csv line {}", i + 2) } else { format!("{prefix}[{i}]") };
        measurement(m, &model, instrument, artefact.as_ref()).map_err(|e| ApiError::domain(e, &at))?;
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
            });
        }
        let total = records::measurement_count(&mut *tx, &session.id).await?;
        tx.commit().await?;
        let out = BatchOut { batch_id: b.id, session_id: session.id, first_index: b.first_seq, count: b.count, total };
        let mut res = (StatusCode::CREATED, Json(out)).into_response();
        res.headers_mut().insert("idempotency-replayed", HeaderValue::from_static("true"));
        return Ok(res);
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

/// One stored measurement with its index in the session.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct MeasurementItem {
    pub index: i64,
    #[serde(flatten)]
    pub measurement: MeasurementSpec,
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
    params(("session_id" = String, Path, description = "Session id"), PageQuery),
    responses(
        (status = 200, description = "Measurements offset … offset + limit", body = MeasurementPage, headers(
            ("X-Total-Count" = i64, description = "Measurements in the session"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad paging values", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn measurements(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(session_id): Path<String>,
    page: Paging<1000, 10_000>,
) -> Result<(HeaderMap, Json<MeasurementPage>), ApiError> {
    let session = find(&state, &session_id).await?;
    let offset = page.offset;
    let rows = records::measurements(&state.pool, &session.id, offset, page.limit).await?;
    let items = rows
        .into_iter()
        .map(|(index, json)| {
            serde_json::from_str(&json)
                .map(|measurement| MeasurementItem { index, measurement })
                .map_err(|e| ApiError::Internal(format!("measurement {index} of session {}: {e}", session.id)))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let total = session.measurements;
    let next = offset + items.len() as i64;
    let headers = page.headers(total, items.len());
    Ok((headers, Json(MeasurementPage { items, total, offset, next_offset: (next < total).then_some(next) })))
}

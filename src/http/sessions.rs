//! Measuring sessions of a robot (purpose, instrument, tool, artefact) and their measurements:
//! batches appended in one transaction — all rows or none — with an `Idempotency-Key` so a cell
//! PC can retry safely; JSON or CSV; listed with paging.

use axum::Json;
use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use utoipa::{IntoParams, ToSchema};

use super::extract::{Authorized, JsonBody, MEASURE, READ, is_json, parse_json};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::app::robots::model_of;
use crate::db::{self, records};
use crate::domain::ToolSpec;
use crate::domain::cell::{ArtefactSpec, InstrumentSpec, MeasurementSpec, PurposeSpec, measurement};

/// A session to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewSession {
    /// Unique per robot, e.g. `trical-1`.
    pub name: String,
    pub purpose: PurposeSpec,
    pub instrument: InstrumentSpec,
    /// The tool measured with: TCP (and payload) in the flange frame.
    pub tool: ToolSpec,
    /// The TCP is only a guess (e.g. an unmeasured reflector nest): identify it.
    #[serde(default)]
    pub identify_tcp: bool,
    /// The artefact whose balls a TriCal session measures (required for `trical`).
    #[serde(default)]
    pub artefact_id: Option<String>,
}

/// A session.
#[derive(Debug, Serialize, ToSchema)]
pub struct SessionOut {
    pub id: String,
    pub robot_id: String,
    pub name: String,
    pub purpose: PurposeSpec,
    pub instrument: InstrumentSpec,
    pub tool: ToolSpec,
    pub identify_tcp: bool,
    pub artefact_id: Option<String>,
    /// Measurements stored.
    pub measurements: i64,
    pub created_at: String,
}

pub fn session_out(s: &records::SessionRow) -> Result<SessionOut, ApiError> {
    Ok(SessionOut {
        id: s.id.clone(),
        robot_id: s.robot_id.clone(),
        name: s.name.clone(),
        purpose: s.purpose,
        instrument: s.instrument,
        tool: serde_json::from_str(&s.tool_json).map_err(|e| ApiError::Internal(format!("session {}: {e}", s.id)))?,
        identify_tcp: s.identify_tcp,
        artefact_id: s.artefact_id.clone(),
        measurements: s.measurements,
        created_at: s.created_at.clone(),
    })
}

async fn find(state: &AppState, id: &str) -> Result<records::SessionRow, ApiError> {
    records::session(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("session", id))
}

/// Create a session of a robot.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/sessions", tag = "sessions",
    params(("robot_id" = String, Path, description = "Robot id")),
    request_body(content = NewSession, content_type = "application/json"),
    responses(
        (status = 201, description = "Created", body = SessionOut),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "The robot has a session with this name", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid tool, missing or unknown artefact", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    Path(robot_id): Path<String>,
    JsonBody(body): JsonBody<NewSession>,
) -> Result<(StatusCode, Json<SessionOut>), ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let name = body.name.trim();
    if name.is_empty() {
        return Err(ApiError::invalid("name", "must not be empty"));
    }
    body.tool.to_tool().map_err(|e| ApiError::domain(e, "tool"))?;
    if body.artefact_id.is_none() && body.instrument == InstrumentSpec::Trical {
        return Err(ApiError::invalid(
            "artefact_id",
            "a trical session measures the balls of an artefact: give its id",
        ));
    }
    if let Some(a) = &body.artefact_id
        && records::artefact(&state.pool, a).await?.is_none()
    {
        return Err(ApiError::invalid("artefact_id", format!("no artefact '{a}'")));
    }
    let row = records::SessionRow {
        id: db::new_id(),
        robot_id: robot.id.clone(),
        name: name.to_string(),
        purpose: body.purpose,
        instrument: body.instrument,
        tool_json: serde_json::to_string(&body.tool).expect("serialises"),
        identify_tcp: body.identify_tcp,
        artefact_id: body.artefact_id.clone(),
        created_at: db::now(),
        measurements: 0,
    };
    records::insert_session(&state.pool, &row).await.map_err(|e| {
        if db::is_unique_violation(&e) {
            ApiError::Conflict {
                detail: format!("robot '{}' has a session named '{name}'", robot.name),
                field: Some("name".into()),
            }
        } else {
            e.into()
        }
    })?;
    Ok((StatusCode::CREATED, Json(session_out(&row)?)))
}

/// A robot's sessions.
#[utoipa::path(get, path = "/v1/robots/{robot_id}/sessions", tag = "sessions",
    params(("robot_id" = String, Path, description = "Robot id")),
    responses(
        (status = 200, description = "The robot's sessions, oldest first", body = Vec<SessionOut>),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(robot_id): Path<String>,
) -> Result<Json<Vec<SessionOut>>, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let rows = records::sessions_of_robot(&state.pool, &robot.id).await?;
    Ok(Json(rows.iter().map(session_out).collect::<Result<_, _>>()?))
}

/// Get a session.
#[utoipa::path(get, path = "/v1/sessions/{session_id}", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id")),
    responses(
        (status = 200, description = "The session", body = SessionOut),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(session_id): Path<String>,
) -> Result<Json<SessionOut>, ApiError> {
    Ok(Json(session_out(&find(&state, &session_id).await?)?))
}

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

/// CSV columns: `q1_deg … qN_deg`, then any of `ball`, `x_mm y_mm z_mm`, `a_deg b_deg c_deg`
/// (ZY'X'' rotation), `temperature_c`, `time_s`, `approach_1 … approach_N`, `dx_mm dy_mm dz_mm`
/// (TriCal indicator readings). Empty cells are absent values.
pub fn parse_csv(text: &[u8], dof: usize) -> Result<Vec<MeasurementSpec>, ApiError> {
    let mut rdr = csv::ReaderBuilder::new().trim(csv::Trim::All).from_reader(text);
    let headers: Vec<String> = rdr
        .headers()
        .map_err(|e| ApiError::malformed(Some("csv header".into()), format!("cannot read the CSV header: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    let col = |name: &str| headers.iter().position(|h| h == name);
    let joints: Vec<String> = (1..=dof).map(|j| format!("q{j}_deg")).collect();
    let approach: Vec<String> = (1..=dof).map(|j| format!("approach_{j}")).collect();
    let known: Vec<&str> = joints
        .iter()
        .chain(&approach)
        .map(String::as_str)
        .chain([
            "ball",
            "x_mm",
            "y_mm",
            "z_mm",
            "a_deg",
            "b_deg",
            "c_deg",
            "temperature_c",
            "time_s",
            "dx_mm",
            "dy_mm",
            "dz_mm",
        ])
        .collect();
    if let Some(bad) = headers.iter().find(|h| !known.contains(&h.as_str())) {
        return Err(ApiError::invalid(
            format!("csv column '{bad}'"),
            format!(
                "unknown column; expected q1_deg…q{dof}_deg, ball, x_mm y_mm z_mm, a_deg b_deg c_deg, temperature_c, time_s, approach_1…approach_{dof}, dx_mm dy_mm dz_mm"
            ),
        ));
    }
    for j in &joints {
        if col(j).is_none() {
            return Err(ApiError::invalid("csv header", format!("missing column '{j}'")));
        }
    }
    let mut out = Vec::new();
    for (i, rec) in rdr.records().enumerate() {
        let line = i + 2;
        let rec = rec.map_err(|e| ApiError::malformed(Some(format!("csv line {line}")), e.to_string()))?;
        let num = |name: &str| -> Result<Option<f64>, ApiError> {
            match col(name).and_then(|c| rec.get(c)).filter(|s| !s.is_empty()) {
                None => Ok(None),
                Some(s) => s.parse::<f64>().map(Some).map_err(|_| {
                    ApiError::invalid(format!("csv line {line}, column {name}"), format!("'{s}' is not a number"))
                }),
            }
        };
        let three = |names: [&str; 3]| -> Result<Option<[f64; 3]>, ApiError> {
            let v = [num(names[0])?, num(names[1])?, num(names[2])?];
            match v {
                [Some(a), Some(b), Some(c)] => Ok(Some([a, b, c])),
                [None, None, None] => Ok(None),
                _ => Err(ApiError::invalid(
                    format!("csv line {line}, column {}", names[0]),
                    format!("give all of {} or none", names.join(", ")),
                )),
            }
        };
        let mut q = Vec::with_capacity(dof);
        for j in &joints {
            q.push(num(j)?.ok_or_else(|| {
                ApiError::invalid(format!("csv line {line}, column {j}"), "a joint value is required")
            })?);
        }
        let ball = match num("ball")? {
            None => None,
            Some(b) if b.fract() == 0.0 && b >= 0.0 => Some(b as usize),
            Some(b) => {
                return Err(ApiError::invalid(
                    format!("csv line {line}, column ball"),
                    format!("{b} is not a ball number"),
                ));
            }
        };
        let approach = {
            let v: Vec<Option<f64>> = approach.iter().map(|a| num(a)).collect::<Result<_, _>>()?;
            if v.iter().all(Option::is_none) {
                None
            } else {
                let mut a = Vec::with_capacity(dof);
                for (j, x) in v.iter().enumerate() {
                    match x {
                        Some(x) if x.fract() == 0.0 && (-1.0..=1.0).contains(x) => a.push(*x as i8),
                        _ => {
                            return Err(ApiError::invalid(
                                format!("csv line {line}, column approach_{}", j + 1),
                                "must be -1, 0 or 1 (all approach columns or none)",
                            ));
                        }
                    }
                }
                Some(a)
            }
        };
        out.push(MeasurementSpec {
            joints_deg: q,
            ball,
            position_mm: three(["x_mm", "y_mm", "z_mm"])?,
            rotation_deg: three(["a_deg", "b_deg", "c_deg"])?,
            temperature_c: num("temperature_c")?,
            time_s: num("time_s")?,
            approach,
            indicators_mm: three(["dx_mm", "dy_mm", "dz_mm"])?,
        });
    }
    Ok(out)
}

/// Append a batch of measurements to a session: one transaction, all rows or none. A retry with
/// the same `Idempotency-Key` and the same body returns the first answer (with
/// `Idempotency-Replayed: true`) instead of appending twice; the same key with another body is 409.
#[utoipa::path(post, path = "/v1/sessions/{session_id}/measurements", tag = "sessions",
    params(
        ("session_id" = String, Path, description = "Session id"),
        ("Idempotency-Key" = Option<String>, Header, description = "Makes a retried upload safe: the same key and body return the first answer")),
    request_body(description = "JSON {\"measurements\": [...]} (the cell-file measurement objects) or CSV with a header row \
(q1_deg … qN_deg, ball, x_mm y_mm z_mm, a_deg b_deg c_deg, temperature_c, time_s, approach_1 … approach_N, dx_mm dy_mm dz_mm)",
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

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct Page {
    /// Index of the first measurement (default 0).
    #[param(minimum = 0)]
    pub offset: Option<i64>,
    /// At most this many (default 1000, at most 10000).
    #[param(minimum = 1, maximum = 10000)]
    pub limit: Option<i64>,
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

/// A page of a session's measurements, in order.
#[utoipa::path(get, path = "/v1/sessions/{session_id}/measurements", tag = "sessions",
    params(("session_id" = String, Path, description = "Session id"), Page),
    responses(
        (status = 200, description = "Measurements offset … offset + limit", body = MeasurementPage),
        (status = 404, description = "Unknown session", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Bad paging values", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = [])))]
pub async fn measurements(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(session_id): Path<String>,
    Query(page): Query<Page>,
) -> Result<Json<MeasurementPage>, ApiError> {
    let session = find(&state, &session_id).await?;
    let offset = page.offset.unwrap_or(0);
    let limit = page.limit.unwrap_or(1000);
    if offset < 0 {
        return Err(ApiError::invalid("offset", "must not be negative"));
    }
    if !(1..=10_000).contains(&limit) {
        return Err(ApiError::invalid("limit", "must be 1–10000"));
    }
    let rows = records::measurements(&state.pool, &session.id, offset, limit).await?;
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
    Ok(Json(MeasurementPage { items, total, offset, next_offset: (next < total).then_some(next) }))
}

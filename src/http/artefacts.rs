//! Ball-triangle artefacts: created from the three measured distances, the ball centres in {W}
//! computed (thesis §2, eq. 4.3–4.7) and returned.

use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, StatusCode};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::audit::{Event, ReasonQuery, reason};
use super::error::OrConflict;
use super::extract::{Authorized, JsonBody, MEASURE, READ};
use super::paging::{PageQuery, Paging};
use super::{ApiError, AppState};
use crate::cell::Artefact;
use crate::db::{self, corrections, records};
use crate::domain::cell::{ArtefactKind, ArtefactSpec, Distances};
use crate::domain::limits;
use crate::units::MM;

/// An artefact to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewArtefact {
    /// Unique name, e.g. `plate-A` (not blank).
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub name: String,
    /// `ball_triangle` (the only kind).
    #[serde(default = "ball_triangle")]
    pub kind: ArtefactKind,
    /// Measured centre distances, mm.
    pub distances_mm: Distances,
    pub ball_diameter_mm: f64,
}

fn ball_triangle() -> ArtefactKind {
    ArtefactKind::BallTriangle
}

/// An artefact with its ball centres in {W} (ball 1 at the origin, ball 2 on +x, ball 3 in the
/// xy plane with y > 0).
#[derive(Debug, Serialize, ToSchema)]
pub struct ArtefactOut {
    pub id: String,
    pub name: String,
    pub kind: ArtefactKind,
    pub distances_mm: Distances,
    pub ball_diameter_mm: f64,
    pub ball_centres_mm: [[f64; 3]; 3],
    pub created_at: String,
}

/// Validate an artefact specification (distances form a proper triangle, positive diameter).
pub fn artefact(spec: &ArtefactSpec) -> Result<Artefact, ApiError> {
    spec.to_artefact().map_err(ApiError::field)
}

pub fn artefact_out(row: &records::ArtefactRow) -> Result<ArtefactOut, ApiError> {
    let spec: ArtefactSpec =
        serde_json::from_str(&row.spec_json).map_err(|e| ApiError::Internal(format!("artefact {}: {e}", row.id)))?;
    let t = artefact(&spec)?.triangle;
    let c = |k: usize| {
        let p = t.ball(k).expect("balls 1–3");
        [p.x / MM, p.y / MM, p.z / MM]
    };
    Ok(ArtefactOut {
        id: row.id.clone(),
        name: row.name.clone(),
        kind: spec.kind,
        distances_mm: spec.distances_mm,
        ball_diameter_mm: spec.ball_diameter_mm,
        ball_centres_mm: [c(1), c(2), c(3)],
        created_at: row.created_at.clone(),
    })
}

/// Create an artefact from its three measured distances.
#[utoipa::path(post, path = "/v1/artefacts", tag = "artefacts",
    request_body(content = NewArtefact, content_type = "application/json"),
    responses(
        (status = 201, description = "Created, with the ball centres", body = ArtefactOut),
        (status = 409, description = "An artefact with this name exists", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Impossible or degenerate triangle, bad diameter", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<MEASURE>,
    JsonBody(body): JsonBody<NewArtefact>,
) -> Result<(StatusCode, Json<ArtefactOut>), ApiError> {
    let name = limits::name(&body.name, "name").map_err(|e| ApiError::domain(e, ""))?;
    let spec =
        ArtefactSpec { kind: body.kind, distances_mm: body.distances_mm, ball_diameter_mm: body.ball_diameter_mm };
    artefact(&spec)?;
    let row = records::ArtefactRow {
        id: db::new_id(),
        name: name.to_string(),
        spec_json: serde_json::to_string(&spec).expect("serialises"),
        created_at: db::now(),
    };
    records::insert_artefact(&state.pool, &row)
        .await
        .or_conflict("name", || format!("an artefact named '{name}' exists"))?;
    Ok((StatusCode::CREATED, Json(artefact_out(&row)?)))
}

/// List artefacts, oldest first, a page at a time.
#[utoipa::path(get, path = "/v1/artefacts", tag = "artefacts", params(PageQuery),
    responses(
        (status = 200, description = "Artefacts, oldest first", body = Vec<ArtefactOut>, headers(
            ("X-Total-Count" = i64, description = "Artefacts in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<ArtefactOut>>), ApiError> {
    page.respond(records::artefacts(&state.pool, page.offset, page.limit).await?, |r| artefact_out(&r))
}

/// Get an artefact.
#[utoipa::path(get, path = "/v1/artefacts/{artefact_id}", tag = "artefacts",
    params(("artefact_id" = String, Path, description = "Artefact id")),
    responses(
        (status = 200, description = "The artefact", body = ArtefactOut),
        (status = 404, description = "Unknown artefact", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn get(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(artefact_id): Path<String>,
) -> Result<Json<ArtefactOut>, ApiError> {
    let row = records::artefact(&state.pool, &artefact_id)
        .await?
        .ok_or_else(|| ApiError::not_found("artefact", &artefact_id))?;
    Ok(Json(artefact_out(&row)?))
}

/// Delete an artefact nothing uses, saying why. Refused (409, naming them) while sessions were
/// measured on it, pose plans were made for it, or a pose-plan job on it is queued or running.
/// The audit timeline keeps who, when, why and the artefact's specification.
#[utoipa::path(delete, path = "/v1/artefacts/{artefact_id}", tag = "artefacts",
    params(("artefact_id" = String, Path, description = "Artefact id"), ReasonQuery),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "Unknown artefact", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "Sessions, pose plans or unfinished jobs use the artefact (named in the detail)", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`reason` missing or empty", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["measure"])))]
pub async fn delete(
    State(state): State<AppState>,
    auth: Authorized<MEASURE>,
    Path(artefact_id): Path<String>,
    Query(q): Query<ReasonQuery>,
) -> Result<StatusCode, ApiError> {
    records::artefact(&state.pool, &artefact_id).await?.ok_or_else(|| ApiError::not_found("artefact", &artefact_id))?;
    let why = reason(q.reason.as_deref())?;
    let mut tx = db::begin_write(&state.pool).await?;
    let a = records::artefact(&mut *tx, &artefact_id)
        .await?
        .ok_or_else(|| ApiError::not_found("artefact", &artefact_id))?;
    let refs = corrections::artefact_references(&mut tx, &a).await?;
    if !refs.is_empty() {
        return Err(ApiError::conflict_hint(
            format!("artefact '{}' is used by {}; nothing was deleted", a.name, refs.join(", ")),
            "only an artefact nothing was measured on or planned for can be deleted: delete the unused sessions first",
        ));
    }
    let spec: serde_json::Value =
        serde_json::from_str(&a.spec_json).map_err(|e| ApiError::Internal(format!("artefact {}: {e}", a.id)))?;
    corrections::delete_artefact(&mut *tx, &a.id).await?;
    let detail = serde_json::json!({"name": a.name, "spec": spec, "created_at": a.created_at});
    let actor = auth.actor();
    super::audit::record(
        &mut tx,
        actor.as_deref(),
        &db::now(),
        Event { action: "artefact_deleted", robot_id: None, subject_id: &a.id, reason: &why, detail },
    )
    .await?;
    tx.commit().await?;
    Ok(StatusCode::NO_CONTENT)
}

//! Exports of a parameter set: `GET /v1/parameter-sets/{id}/export?format=json|csv-dh|urdf`
//! (the file as stored, the modified-DH table, the URDF), and the RAPID module of a compensated
//! batch: `POST /v1/parameter-sets/{id}/export?format=rapid` with the targets (a compensation
//! request without `parameter_set_id`: the set is the path's). A batch with a target that cannot
//! be compensated is refused (422 naming that target) unless `allow_partial=true`: then the module
//! is written without it, lists it in a comment, and `X-Failed-Targets` counts the failures.

use axum::extract::{Path, Query, State};
use axum::http::{HeaderName, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};

use super::compensation::{GIVE_TOOL, check_batch, checks, run_batch};
use super::extract::{Authorized, COMPENSATE, JsonBody, READ};
use super::{ApiError, AppState};
use crate::db::records;
use crate::domain::export::rapid::{RapidHeader, write as write_rapid};
use crate::domain::export::{ExportFormat, ExportSource, csv_dh, urdf};
use crate::domain::pose::{FrameKind, WorkObjectSpec};
use crate::domain::{ParameterSetDoc, TargetSpec, ToolSpec};

/// The header counting a RAPID module's targets that were not compensated.
pub const FAILED_TARGETS: HeaderName = HeaderName::from_static("x-failed-targets");

#[derive(Debug, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct ExportQuery {
    /// `json` (default: the parameter-set file as stored), `csv-dh`, `urdf`; `rapid` with POST.
    #[param(value_type = Option<crate::domain::export::ExportFormat>, inline)]
    pub format: Option<String>,
    /// RAPID only: write the module even when targets fail (they are listed in a comment and
    /// counted in `X-Failed-Targets`); default false: 422.
    pub allow_partial: Option<bool>,
    /// URDF only: a payload-specific URDF, the compliance deflection at this payload (kg, at the
    /// set's tool centre of mass) folded into the joint zero offsets; its header says what is
    /// left and whether that is a fair approximation.
    #[param(minimum = 0, maximum = 5000)]
    pub payload_kg: Option<f64>,
}

/// The targets of a RAPID export: a compensation request, the set being the path's.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RapidExportRequest {
    /// The tool the targets are for; default: the parameter set's own (identified) tool.
    #[serde(default)]
    pub tool: Option<ToolSpec>,
    /// `world` (default) or `base`, as in a compensation request.
    #[serde(default)]
    pub frame: Option<FrameKind>,
    /// Targets and fake poses relative to this work object (declared in the base frame).
    #[serde(default)]
    pub work_object: Option<WorkObjectSpec>,
    /// As in a compensation request: use a set without a passing held-out validation.
    #[serde(default)]
    pub allow_unvalidated: bool,
    /// As in a compensation request: compensate targets outside the calibrated envelope.
    #[serde(default)]
    pub allow_outside_envelope: bool,
    /// At least one target; ids for all or none, each once.
    #[schema(min_items = 1)]
    pub targets: Vec<TargetSpec>,
}

fn format_of(q: &ExportQuery) -> Result<ExportFormat, ApiError> {
    match q.format.as_deref() {
        None => Ok(ExportFormat::Json),
        Some(f) => ExportFormat::parse(f, "format").map_err(|e| ApiError::domain(e, "")),
    }
}

async fn find(state: &AppState, id: &str) -> Result<records::ParameterSetRow, ApiError> {
    records::parameter_set(&state.pool, id).await?.ok_or_else(|| ApiError::not_found("parameter set", id))
}

fn doc_of(row: &records::ParameterSetRow) -> Result<ParameterSetDoc, ApiError> {
    ParameterSetDoc::from_json(&row.doc_json)
        .map_err(|e| ApiError::Internal(format!("parameter set {}: stored file invalid: {e}", row.id)))
}

fn file(format: ExportFormat, name: String, body: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, format.content_type().to_string()),
            (header::CONTENT_DISPOSITION, format!("attachment; filename=\"{name}\"")),
        ],
        body,
    )
        .into_response()
}

/// Export a parameter set: the file exactly as stored (`json`: mm, deg, deg/(N·m); per parameter
/// value, nominal, std, unit, status; the quality report), the modified-DH table (`csv-dh`: mm and
/// deg, base and tool rows, `#` header lines naming robot, set and convention) or the calibrated
/// chain (`urdf`: geometry only — compliance cannot be expressed, the file says so).
#[utoipa::path(get, path = "/v1/parameter-sets/{set_id}/export", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id"), ExportQuery),
    responses(
        (status = 200, description = "The exported file (Content-Disposition names it: parameter-set-v<version>.json|.csv|.urdf)",
            content(
                (Object = "application/json"),
                (String = "text/csv; charset=utf-8; header=present"),
                (String = "application/xml"))),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "Unknown `format`, or `rapid` (which needs targets: POST)", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["read"])))]
pub async fn export(
    State(state): State<AppState>,
    _auth: Authorized<READ>,
    Path(set_id): Path<String>,
    Query(q): Query<ExportQuery>,
) -> Result<Response, ApiError> {
    let format = format_of(&q)?;
    let payload = match q.payload_kg {
        None => None,
        Some(_) if format != ExportFormat::Urdf => {
            return Err(ApiError::invalid("payload_kg", "only a urdf export folds a payload's deflection"));
        }
        Some(kg) => Some(crate::domain::limits::mass(kg, "payload_kg").map_err(|e| ApiError::domain(e, ""))?),
    };
    let row = find(&state, &set_id).await?;
    let name = format!("parameter-set-v{}.{}", row.version, format.extension());
    let source = ExportSource::stored(&row.id, row.version);
    let body = match format {
        ExportFormat::Json => row.doc_json.clone(),
        ExportFormat::CsvDh => csv_dh::write(&doc_of(&row)?, &source),
        ExportFormat::Urdf => {
            let doc = doc_of(&row)?;
            let payload = payload.map(|kg| crate::kinematics::Tool { mass: kg, ..doc.set.tool.clone() });
            urdf::write_with(&doc, &source, &urdf::UrdfOptions { payload })
        }
        ExportFormat::Rapid => {
            return Err(ApiError::invalid(
                "format",
                format!(
                    "a RAPID module is a compensated target batch: POST /v1/parameter-sets/{}/export?format=rapid \
                     with {{\"targets\": […]}}",
                    row.id
                ),
            ));
        }
    };
    Ok(file(format, name, body))
}

/// Export a compensated target batch as an ABB RAPID module (`format=rapid`): per target a
/// `CONST robtarget p_<id>` (fake pose, confdata) and a `CONST jointtarget j_<id>` (compensated
/// joints), external axes 9E9, with a header naming robot, set, date and frame. The body is a
/// compensation request without `parameter_set_id`. A target that cannot be compensated makes it
/// 422 (naming the first such target) unless `allow_partial=true`: then it is left out, listed in a
/// comment, and counted in `X-Failed-Targets`.
#[utoipa::path(post, path = "/v1/parameter-sets/{set_id}/export", tag = "parameter-sets",
    params(("set_id" = String, Path, description = "Parameter set id"), ExportQuery),
    request_body(content = RapidExportRequest, content_type = "application/json"),
    responses(
        (status = 200, description = "The RAPID module (Content-Disposition: targets-v<version>.mod)", body = String, content_type = "text/plain; charset=utf-8",
            headers(("X-Failed-Targets" = i64, description = "Targets left out of the module (0 unless allow_partial)"))),
        (status = 404, description = "Unknown parameter set", body = super::Problem, content_type = "application/problem+json"),
        (status = 413, description = "More targets than the batch limit", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "`format` other than `rapid`; invalid tool or frame; a target not compensated (without allow_partial)", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["compensate"])))]
pub async fn export_rapid(
    State(state): State<AppState>,
    _auth: Authorized<COMPENSATE>,
    Path(set_id): Path<String>,
    Query(q): Query<ExportQuery>,
    JsonBody(body): JsonBody<RapidExportRequest>,
) -> Result<Response, ApiError> {
    let format = match q.format.as_deref() {
        None => ExportFormat::Rapid,
        Some(_) => format_of(&q)?,
    };
    if format != ExportFormat::Rapid {
        return Err(ApiError::invalid(
            "format",
            format!("'{}' needs no targets: GET /v1/parameter-sets/{set_id}/export?format={0}", format.name()),
        ));
    }
    find(&state, &set_id).await?;
    check_batch(&state, &body.targets)?;
    let compiled = state
        .caches
        .parameter_set(&state.pool, &set_id)
        .await?
        .ok_or_else(|| ApiError::not_found("parameter set", &set_id))?;
    crate::domain::pose::check_targets(&body.targets, &compiled.set.model).map_err(|e| ApiError::domain(e, ""))?;
    let tool = match &body.tool {
        Some(_) => "the tool of the request (program the targets with it)".to_string(),
        None => crate::domain::export::rapid::own_tool(
            crate::domain::validity::tool_note(&compiled.compensator, GIVE_TOOL).as_deref(),
        ),
    };
    let checked = checks(&state, &compiled, body.allow_unvalidated).await?;
    let frames = crate::domain::pose::TargetFrames::new(&compiled.compensator, body.frame, body.work_object.as_ref())
        .map_err(|e| ApiError::domain(e, ""))?;
    let tool_spec = match &body.tool {
        Some(t) => t.to_tool().map_err(|e| ApiError::domain(e, "tool"))?,
        None => compiled.set.tool.clone(),
    };
    let (frame, results, _) = run_batch(
        compiled.clone(),
        body.tool.as_ref(),
        body.frame,
        body.work_object.as_ref(),
        checked,
        body.allow_outside_envelope,
        body.targets,
    )
    .await?;
    let source = ExportSource::stored(&compiled.row.id, compiled.row.version);
    let date = crate::db::now();
    let module = write_rapid(
        &RapidHeader {
            robot: &compiled.set.model.name,
            source: &source,
            date: &date,
            frame: &frame,
            tool: &tool,
            tooldata: Some(&tool_spec),
            work_object: frames.work_object.as_ref(),
        },
        &results,
    );
    if let Some(first) = module.failed.first()
        && !q.allow_partial.unwrap_or(false)
    {
        let listed = module
            .failed
            .iter()
            .take(5)
            .map(|f| format!("targets[{}]: {}", f.index, f.error))
            .collect::<Vec<_>>()
            .join("; ");
        return Err(ApiError::invalid(
            format!("targets[{}]", first.index),
            format!(
                "{} of {} targets not compensated ({listed}): no module written; pass allow_partial=true to write \
                 the others",
                module.failed.len(),
                results.len()
            ),
        ));
    }
    let mut res = file(ExportFormat::Rapid, format!("targets-v{}.mod", compiled.row.version), module.text);
    res.headers_mut().insert(FAILED_TARGETS, HeaderValue::from(module.failed.len()));
    Ok(res)
}

//! The HTTP service: axum routers, one module per resource, errors as problem+json, OpenAPI 3.1
//! generated from the handlers (utoipa), Prometheus metrics.

pub mod artefacts;
pub mod audit;
pub mod client;
pub mod compensation;
pub mod diagnoses;
pub mod error;
pub mod exports;
pub mod extract;
pub mod guard;
pub mod history;
pub mod identifications;
pub mod iso9283;
pub mod jobs;
pub mod measurements;
pub mod metrics;
pub mod ops;
pub mod paging;
pub mod parameter_sets;
pub mod plans;
pub mod programs;
pub mod reports;
pub mod robots;
pub mod sessions;
pub mod tokens;
pub mod validations;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::StatusCode;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::timeout::TimeoutLayer;
use tower_http::trace::TraceLayer;
use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

pub use crate::app::{AppState, CorsOrigins, ServiceConfig, cache};
pub use error::{ApiError, Problem};
pub use metrics::Metrics;

struct BearerAuth;

impl Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).bearer_format("opaque").build()),
        );
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "robocal",
        description = "Robot calibration service: stores each robot's measurements, identifies a better kinematic \
model (MDH geometry, Hayati β, gear compliance under gravity), validates it on held-out poses and serves \
compensated (fake-target) joint targets. Units: millimetres and degrees on the wire, with the unit in the field \
name. Errors are application/problem+json naming the field. Bearer tokens carry scopes: measure, calibrate, \
compensate, read, admin (admin implies all); a server bound to loopback accepts requests without a token.",
        license(name = "MIT")
    ),
    modifiers(&BearerAuth),
    tags(
        (name = "robots", description = "Robots, their calibration history and active parameter set"),
        (name = "artefacts", description = "Ball-triangle artefacts"),
        (name = "sessions", description = "Measuring sessions and their measurements"),
        (name = "pose-plans", description = "Collision-checked measurement poses (job)"),
        (name = "identifications", description = "Parameter identification (job)"),
        (name = "parameter-sets", description = "Immutable, versioned parameter sets"),
        (name = "validations", description = "Validation statistics (job)"),
        (name = "diagnoses", description = "Sim-to-real diagnosis of a parameter set (job): where it misses, which unmodelled effect, how far the error shrinks; accepting a named effect"),
        (name = "compensation", description = "Compensated (fake-target) joint targets"),
        (name = "iso9283", description = "ISO 9283 pose characteristics of a measured session (job): AP, RP, vAP, AD, RD, nominal and calibrated (predicted)"),
        (name = "jobs", description = "Background jobs"),
        (name = "tokens", description = "Bearer tokens (admin)"),
        (name = "audit", description = "Corrections of stored data (exclusions, deletions, archiving): who, when, why"),
        (name = "ops", description = "Health, readiness, metrics, this document")
    )
)]
struct ApiDoc;

/// Every documented route, without state.
fn api_router() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .routes(routes!(ops::healthz))
        .routes(routes!(ops::readyz))
        .routes(routes!(ops::metrics))
        .routes(routes!(ops::openapi))
        .routes(routes!(robots::create, robots::list))
        .routes(routes!(robots::get))
        .routes(routes!(robots::cell))
        .routes(routes!(parameter_sets::history, parameter_sets::import))
        .routes(routes!(parameter_sets::active, parameter_sets::activate))
        .routes(routes!(parameter_sets::activations))
        .routes(routes!(parameter_sets::get, parameter_sets::patch, parameter_sets::delete))
        .routes(routes!(exports::export, exports::export_rapid))
        .routes(routes!(history::history))
        .routes(routes!(history::drift))
        .routes(routes!(artefacts::create, artefacts::list))
        .routes(routes!(artefacts::get, artefacts::delete))
        .routes(routes!(sessions::create, sessions::list))
        .routes(routes!(sessions::get, sessions::delete))
        .routes(routes!(measurements::append, measurements::measurements))
        .routes(routes!(measurements::get, measurements::patch))
        .routes(routes!(plans::create, plans::list))
        .routes(routes!(plans::get))
        .routes(routes!(identifications::create))
        .routes(routes!(validations::create))
        .routes(routes!(validations::get))
        .routes(routes!(reports::validation))
        .routes(routes!(reports::parameter_set))
        .routes(routes!(reports::diagnosis))
        .routes(routes!(reports::history))
        .routes(routes!(diagnoses::create, diagnoses::list))
        .routes(routes!(diagnoses::get))
        .routes(routes!(diagnoses::accept))
        .routes(routes!(compensation::compensate))
        .routes(routes!(programs::filter_program))
        .routes(routes!(iso9283::create))
        .routes(routes!(iso9283::get))
        .routes(routes!(iso9283::report))
        .routes(routes!(jobs::list))
        .routes(routes!(jobs::get))
        .routes(routes!(jobs::cancel))
        .routes(routes!(tokens::create, tokens::list))
        .routes(routes!(tokens::revoke))
        .routes(routes!(audit::list))
}

/// The OpenAPI document (3.1) of a server that requires authentication (`serve --require-auth`,
/// or bound beyond loopback): every `/v1` operation needs a bearer token with the scope its
/// security requirement names. This is the committed `openapi/openapi.json`.
pub fn openapi() -> utoipa::openapi::OpenApi {
    openapi_for(true)
}

/// The OpenAPI document as a server in the given mode serves it. Without `require_auth` (a
/// loopback server) the operations that accept a request without a token declare an empty
/// security requirement (`[{}]`: no token needed; one that is sent is still checked); those that
/// need the `admin` scope (token management) keep theirs, since they always ask for a token.
pub fn openapi_for(require_auth: bool) -> utoipa::openapi::OpenApi {
    let mut api = api_router().split_for_parts().1;
    common_responses(&mut api);
    physical_bounds(&mut api);
    if !require_auth {
        use utoipa::openapi::security::SecurityRequirement;
        for item in api.paths.paths.values_mut() {
            for op in [&mut item.get, &mut item.post, &mut item.put, &mut item.patch, &mut item.delete] {
                let Some(op) = op.as_mut() else { continue };
                if required_scope(op).is_some_and(|s| s != "admin") {
                    op.security = Some(vec![SecurityRequirement::default()]);
                }
            }
        }
    }
    api
}

/// The physical bounds of `domain::limits::SCHEMA_BOUNDS` written into the request schemas
/// (`minimum`/`maximum`, on the number or on an array's items, through a nullable `oneOf`), so
/// the document states every constant bound the server enforces.
fn physical_bounds(api: &mut utoipa::openapi::OpenApi) {
    use crate::domain::limits::{Applies, SCHEMA_BOUNDS};
    use serde_json::{Value, json};
    // A document that does not convert both ways would silently lose every bound: fail loudly (the
    // OpenAPI test and the server's start both build it).
    let mut doc = serde_json::to_value(&*api).expect("the OpenAPI document converts to JSON");
    fn set(s: &mut Value, lo: f64, hi: f64, exclusive: bool) {
        if exclusive {
            s["exclusiveMinimum"] = json!(lo);
        } else {
            s["minimum"] = json!(lo);
        }
        s["maximum"] = json!(hi);
    }
    fn apply(s: &mut Value, lo: f64, hi: f64, to: Applies, exclusive: bool) {
        for key in ["oneOf", "anyOf"] {
            if let Some(alts) = s.get_mut(key).and_then(Value::as_array_mut) {
                for a in alts.iter_mut().filter(|a| a.get("type") != Some(&json!("null"))) {
                    apply(a, lo, hi, to, exclusive);
                }
                return;
            }
        }
        match to {
            Applies::Items => {
                if let Some(items) = s.get_mut("items") {
                    set(items, lo, hi, exclusive);
                }
            }
            Applies::Value => set(s, lo, hi, exclusive),
        }
    }
    for &(schema, property, lo, hi, to, exclusive) in SCHEMA_BOUNDS {
        let at = format!("/components/schemas/{schema}/properties/{property}");
        let p = doc.pointer_mut(&at).unwrap_or_else(|| panic!("SCHEMA_BOUNDS names {at}, which the document lacks"));
        apply(p, lo, hi, to, exclusive);
    }
    // Session lists name each session once (`uniqueItems`, which utoipa's attributes lack): the
    // server refuses a session named twice.
    for at in ["IdentificationRequest/properties/sessions", "ValidationRequest/properties/sessions"] {
        let p =
            doc.pointer_mut(&format!("/components/schemas/{at}")).unwrap_or_else(|| panic!("the document lacks {at}"));
        p["uniqueItems"] = json!(true);
    }
    *api = serde_json::from_value(doc).expect("the OpenAPI document reads back with its bounds (a schema utoipa cannot read, e.g. serde_json::Value's, must be declared by hand)");
}

/// The scope an operation's bearer requirement names (`read`, `measure`, …, `admin`), if any.
pub fn required_scope(op: &utoipa::openapi::path::Operation) -> Option<String> {
    let value = serde_json::to_value(op.security.as_ref()?).ok()?;
    value.as_array()?.iter().find_map(|req| req.get("bearer")?.get(0)?.as_str().map(str::to_string))
}

/// Every `/v1` operation can also answer 400 (a query string or body that does not parse), 401
/// and 403 (token), 503 (request timeout); those with a body 408 (body too slow), 413 and 415.
/// Documented once here rather than on each handler.
fn common_responses(api: &mut utoipa::openapi::OpenApi) {
    use utoipa::openapi::{ContentBuilder, Ref, RefOr, ResponseBuilder};
    let problem = |description: &str| {
        RefOr::T(
            ResponseBuilder::new()
                .description(description)
                .content(
                    error::PROBLEM_JSON,
                    ContentBuilder::new().schema(Some(Ref::from_schema_name("Problem"))).build(),
                )
                .build(),
        )
    };
    for (path, item) in api.paths.paths.iter_mut() {
        if !path.starts_with("/v1/") {
            continue;
        }
        let with_body = [item.post.is_some(), item.put.is_some()];
        for (op, body) in [
            (&mut item.get, false),
            (&mut item.post, with_body[0]),
            (&mut item.put, with_body[1]),
            (&mut item.patch, true),
            (&mut item.delete, false),
        ] {
            let Some(op) = op.as_mut() else { continue };
            let mut add = vec![
                ("400", "Malformed request (body or query string)"),
                ("401", "Missing, unknown or revoked bearer token"),
                ("403", "The token lacks the scope"),
                ("503", "The request exceeded the server's timeout"),
            ];
            if body {
                add.push(("408", "The request body arrived slower than the server's minimum rate"));
                add.push(("413", "Request body over the server's limit"));
                add.push(("415", "Content type not accepted"));
            }
            for (code, description) in add {
                op.responses.responses.entry(code.to_string()).or_insert_with(|| problem(description));
            }
        }
    }
}

/// The OpenAPI document as committed in `openapi/openapi.json` (the `--require-auth` form).
pub fn openapi_json() -> String {
    openapi_json_for(true)
}

/// The OpenAPI document as a server in the given mode serves it, pretty-printed.
pub fn openapi_json_for(require_auth: bool) -> String {
    let mut s = openapi_for(require_auth).to_pretty_json().expect("the OpenAPI document serialises");
    s.push('\n');
    s
}

/// The document of a server whose batch limit (`--max-batch`) is not the default: the batches'
/// `maxItems` state that server's limit.
pub fn openapi_json_with(require_auth: bool, max_batch: usize) -> String {
    let mut doc: serde_json::Value = serde_json::from_str(&openapi_json_for(require_auth)).expect("JSON");
    for (schema, field) in [("NewMeasurements", "measurements"), ("CompensationRequest", "targets")] {
        if let Some(p) = doc.pointer_mut(&format!("/components/schemas/{schema}/properties/{field}")) {
            p["maxItems"] = max_batch.into();
        }
    }
    let mut s = serde_json::to_string_pretty(&doc).expect("JSON");
    s.push('\n');
    s
}

/// The request headers a page may send, and the response headers it may read, across origins.
const CORS_REQUEST_HEADERS: [&str; 4] = ["authorization", "content-type", "idempotency-key", "x-request-id"];
const CORS_EXPOSED_HEADERS: [&str; 7] =
    ["x-request-id", "server-timing", "location", "link", "x-total-count", "idempotency-replayed", "www-authenticate"];

/// The CORS layer for the configured origins (`None` when off: no CORS header at all, and an
/// `OPTIONS` request is routed like any other).
fn cors(origins: &CorsOrigins) -> Option<CorsLayer> {
    use axum::http::{HeaderName, HeaderValue, Method};
    let allow = match origins {
        CorsOrigins::Off => return None,
        CorsOrigins::Any => AllowOrigin::any(),
        CorsOrigins::List(list) => AllowOrigin::list(
            list.iter().map(|o| HeaderValue::from_str(o.as_str()).expect("a parsed origin is a header value")),
        ),
    };
    Some(
        CorsLayer::new()
            .allow_origin(allow)
            .allow_methods([Method::GET, Method::POST, Method::PUT, Method::PATCH, Method::DELETE, Method::OPTIONS])
            .allow_headers(CORS_REQUEST_HEADERS.map(HeaderName::from_static))
            .expose_headers(CORS_EXPOSED_HEADERS.map(HeaderName::from_static))
            .max_age(std::time::Duration::from_secs(600)),
    )
}

/// The application: routes, state and middleware (request ids, tracing, CORS when configured,
/// metrics, timeouts, body limits, compression).
pub fn app(state: AppState) -> Router {
    let (router, _) = api_router().split_for_parts();
    let limit = state.config.max_body_bytes;
    let timeout = state.config.request_timeout;
    let cors = cors(&state.config.cors);
    let router = router
        .with_state(state.clone())
        .fallback(ops::not_found)
        // Innermost first: body limit, the body guard (a declared length over the limit, a body
        // too slow) and timeout, then every error made a problem document (before compression,
        // so it reads and replaces plain bodies), the storage record for /readyz, then metrics
        // (which see timed-out requests as the 503s they are), compression, CORS, request ids and
        // tracing.
        .layer(DefaultBodyLimit::max(limit))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard::body))
        .layer(TimeoutLayer::with_status_code(StatusCode::SERVICE_UNAVAILABLE, timeout))
        .layer(axum::middleware::map_response(error::problem_fallback))
        .layer(axum::middleware::from_fn_with_state(state.clone(), guard::storage))
        .layer(axum::middleware::from_fn_with_state(state, metrics::track))
        .layer(CompressionLayer::new());
    // CORS outside everything that answers for the API: a preflight is answered here, before
    // routing and before any token is asked for (a browser never sends one with it), and every
    // answer, a 401 or a 503 included, carries the origin's header so the page can read it.
    // Inside the request-id layers, so a preflight is traced and has its X-Request-Id too.
    let router = match cors {
        Some(cors) => router.layer(cors),
        None => router,
    };
    router
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(TraceLayer::new_for_http().make_span_with(|req: &axum::http::Request<axum::body::Body>| {
            let rid = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
            tracing::info_span!("http", method = %req.method(), uri = %req.uri(), request_id = %rid)
        }))
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
}

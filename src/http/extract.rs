//! Request extractors whose rejections speak problem+json: JSON bodies parsed with the path of the
//! first field that does not fit, and bearer-token scopes.

use std::sync::Arc;

use axum::body::Bytes;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::{StatusCode, header, request::Parts};
use serde::de::DeserializeOwned;

use super::AppState;
use super::error::ApiError;
use crate::db::tokens::{Scope, TokenRow};

/// A JSON request body. Syntax errors are 400, values that do not fit the schema are 422 with the
/// field's path, a body over the limit is 413, another content type 415.
pub struct JsonBody<T>(pub T);

/// Whether a content type is JSON (`application/json`, `application/…+json`).
pub fn is_json(content_type: Option<&str>) -> bool {
    content_type.is_some_and(|ct| {
        let mime = ct.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
        mime == "application/json" || (mime.starts_with("application/") && mime.ends_with("+json"))
    })
}

/// Read a request body, mapping the body-limit rejection to 413.
pub async fn body_bytes<S: Send + Sync>(req: Request, state: &S) -> Result<Bytes, ApiError> {
    Bytes::from_request(req, state).await.map_err(|e| {
        if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
            ApiError::TooLarge { detail: "the request body exceeds the server's body limit".into(), field: None }
        } else {
            ApiError::malformed(None, format!("cannot read the request body: {}", e.body_text()))
        }
    })
}

/// Parse JSON bytes into `T`: first as JSON (a syntax error is 400), then into `T` (a value that
/// does not fit — a wrong type, a missing field, an array of the wrong length — is 422 with the
/// field's path). Numbers parse to the same f64 either way.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| ApiError::malformed(None, format!("malformed JSON: {e}")))?;
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let detail = e.into_inner().to_string();
        let field = crate::domain::field_path(&path, &detail);
        ApiError::Invalid { detail, field: (!field.is_empty()).then_some(field) }
    })
}

impl<S: Send + Sync, T: DeserializeOwned> FromRequest<S> for JsonBody<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &S) -> Result<Self, ApiError> {
        let ct = req.headers().get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).map(str::to_string);
        if !is_json(ct.as_deref()) {
            return Err(ApiError::UnsupportedMediaType(format!(
                "expected Content-Type: application/json, got {}",
                ct.as_deref().unwrap_or("none")
            )));
        }
        let bytes = body_bytes(req, state).await?;
        parse_json(&bytes).map(JsonBody)
    }
}

/// Scope markers for [`Authorized`].
pub const MEASURE: u8 = 0;
pub const CALIBRATE: u8 = 1;
pub const COMPENSATE: u8 = 2;
pub const READ: u8 = 3;
pub const ADMIN: u8 = 4;

fn scope_of(s: u8) -> Scope {
    match s {
        MEASURE => Scope::Measure,
        CALIBRATE => Scope::Calibrate,
        COMPENSATE => Scope::Compensate,
        READ => Scope::Read,
        _ => Scope::Admin,
    }
}

/// A request allowed the scope `S`: a live bearer token carrying it (or `admin`), or — when the
/// server does not require authentication (loopback bind) — no token at all. A token that is
/// presented is always checked (against the store at most a second old, see `cache`), so a
/// revoked token stops working.
pub struct Authorized<const S: u8>(pub Option<Arc<TokenRow>>);

impl<const S: u8> Authorized<S> {
    /// Who is asking, as the audit records it: the token's name, `None` without a token.
    pub fn actor(&self) -> Option<String> {
        self.0.as_ref().map(|t| t.name.clone())
    }
}

impl<const S: u8> FromRequestParts<AppState> for Authorized<S> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, ApiError> {
        let need = scope_of(S);
        let header = parts.headers.get(header::AUTHORIZATION).map(|v| v.to_str().unwrap_or(""));
        let Some(h) = header else {
            if state.config.require_auth {
                return Err(ApiError::Unauthorized(format!(
                    "this server requires a bearer token with the '{}' scope (Authorization: Bearer …)",
                    need.as_str()
                )));
            }
            return Ok(Authorized(None));
        };
        let secret = h
            .strip_prefix("Bearer ")
            .or_else(|| h.strip_prefix("bearer "))
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .ok_or_else(|| ApiError::Unauthorized("the Authorization header must be 'Bearer <token>'".into()))?;
        let token = state
            .caches
            .token(&state.pool, secret)
            .await?
            .ok_or_else(|| ApiError::Unauthorized("unknown or revoked token".into()))?;
        let scopes = token.scopes();
        if !(scopes.contains(&need) || scopes.contains(&Scope::Admin)) {
            return Err(ApiError::Forbidden(format!(
                "token '{}' has the scopes [{}], this needs '{}'",
                token.name,
                token.scopes,
                need.as_str()
            )));
        }
        Ok(Authorized(Some(token)))
    }
}

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
/// field's path). Numbers parse to the same f64 either way, and an integer-valued number written
/// with a fraction or exponent (`844.0`, `8e2`) is an integer, as JSON Schema has it, so an
/// integer field accepts it (see [`integral_numbers`]).
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let mut value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| ApiError::malformed(None, format!("malformed JSON: {e}")))?;
    integral_numbers(&mut value);
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        let detail = e.into_inner().to_string();
        let field = crate::domain::field_path(&path, &detail);
        ApiError::Invalid { detail, field: (!field.is_empty()).then_some(field) }
    })
}

/// Rewrite every integer-valued float of a JSON document (`844.0`, `8e2`) as that integer, so that
/// integer fields accept what JSON Schema calls an integer ("a number with a zero fractional
/// part"). Lossless for float fields: the integer converts back to the same f64. Left as they are:
/// `-0.0` (its sign would be lost) and values beyond ±2⁶³ (no integer field can hold them, and the
/// float field keeps its exact value).
pub fn integral_numbers(value: &mut serde_json::Value) {
    use serde_json::Value;
    match value {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(f64::NAN);
            // 2^63 is exactly representable; values in [-2^63, 2^63) convert to i64 exactly.
            const LIMIT: f64 = 9_223_372_036_854_775_808.0;
            if x.fract() == 0.0 && (-LIMIT..LIMIT).contains(&x) && !(x == 0.0 && x.is_sign_negative()) {
                *value = Value::from(x as i64);
            }
        }
        Value::Array(items) => items.iter_mut().for_each(integral_numbers),
        Value::Object(map) => map.values_mut().for_each(integral_numbers),
        _ => {}
    }
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
/// server does not require authentication (loopback bind) and `S` is not `admin` — no token at all. A token that is
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
            // Token management (the `admin` scope) always asks for a token, on loopback too: any
            // local process could otherwise mint itself one. The first token comes from the
            // command line (`robocal token create`).
            if state.config.require_auth || need == Scope::Admin {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integral_floats_become_integers_and_floats_keep_their_bits() {
        let mut v: serde_json::Value =
            serde_json::from_str(r#"{"seed": 844.0, "n": [8e1, 2.5, -0.0, -3.0, 1e300, 0.1]}"#).unwrap();
        integral_numbers(&mut v);
        assert_eq!(v["seed"].as_u64(), Some(844));
        assert_eq!(v["n"][0].as_i64(), Some(80));
        assert_eq!(v["n"][1].as_f64(), Some(2.5));
        assert!(v["n"][2].as_f64().unwrap().is_sign_negative(), "-0.0 keeps its sign");
        assert_eq!(v["n"][3].as_i64(), Some(-3));
        assert_eq!(v["n"][4].as_f64(), Some(1e300), "beyond i64: left a float");
        assert_eq!(v["n"][5].as_f64(), Some(0.1));
        // Float fields read back the same number whichever way it was written.
        for x in [844.0_f64, -3.0, 4_503_599_627_370_496.0, -9_223_372_036_854_775_808.0] {
            let mut v = serde_json::json!(x);
            integral_numbers(&mut v);
            assert_eq!(serde_json::from_value::<f64>(v).unwrap().to_bits(), x.to_bits());
        }
        #[derive(serde::Deserialize)]
        struct Seeded {
            seed: u64,
            n: u8,
        }
        let s: Seeded = parse_json(br#"{"seed": 844.0, "n": 80.0}"#).unwrap_or_else(|_| panic!("integral floats"));
        assert_eq!((s.seed, s.n), (844, 80));
        assert!(parse_json::<Seeded>(br#"{"seed": 844.5, "n": 80}"#).is_err(), "a fraction stays refused");
    }
}

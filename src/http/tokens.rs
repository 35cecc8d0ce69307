//! Bearer tokens (admin): create (the secret is shown once), list, revoke. `robocal token create`
//! makes the first one, since creating tokens over HTTP needs an admin token.

use axum::Json;
use axum::extract::{Path, State};
use axum::http::{HeaderMap, StatusCode};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::extract::{ADMIN, Authorized, JsonBody};
use super::paging::{PageQuery, Paging};
use super::{ApiError, AppState};
use crate::db::tokens::{self, Scope, TokenRow};
use crate::domain::limits;

/// A token to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewToken {
    /// Who uses it, e.g. `cell-3-pc` (not blank).
    #[schema(min_length = 1, max_length = 200, pattern = "^[^\\u0000]*[^\\s\\u0000][^\\u0000]*$")]
    pub name: String,
    /// Any of `measure`, `calibrate`, `compensate`, `read`, `admin` (repeats count once).
    #[schema(min_items = 1)]
    pub scopes: Vec<Scope>,
}

/// A token (never its secret, except once at creation).
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct TokenOut {
    pub id: String,
    pub name: String,
    pub scopes: Vec<Scope>,
    pub created_at: String,
    pub revoked_at: Option<String>,
    /// The secret: only in the answer to its creation. Send it as `Authorization: Bearer <token>`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub token: Option<String>,
}

pub fn token_out(t: &TokenRow, secret: Option<String>) -> TokenOut {
    TokenOut {
        id: t.id.clone(),
        name: t.name.clone(),
        scopes: t.scopes(),
        created_at: t.created_at.clone(),
        revoked_at: t.revoked_at.clone(),
        token: secret,
    }
}

/// Create a token.
#[utoipa::path(post, path = "/v1/tokens", tag = "tokens",
    request_body(content = NewToken, content_type = "application/json"),
    responses(
        (status = 201, description = "Created; the answer carries the secret, shown only here", body = TokenOut),
        (status = 422, description = "Empty name or unknown scope", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["admin"])))]
pub async fn create(
    State(state): State<AppState>,
    _auth: Authorized<ADMIN>,
    JsonBody(body): JsonBody<NewToken>,
) -> Result<(StatusCode, Json<TokenOut>), ApiError> {
    let name = limits::name(&body.name, "name").map_err(|e| ApiError::domain(e, ""))?;
    // An unknown name is refused where the body is read, with its path (`scopes[0]`).
    let mut scopes = body.scopes;
    scopes.sort();
    scopes.dedup();
    if scopes.is_empty() {
        return Err(ApiError::invalid("scopes", "give at least one scope"));
    }
    let (row, secret) = tokens::create(&state.pool, name, &scopes).await?;
    Ok((StatusCode::CREATED, Json(token_out(&row, Some(secret)))))
}

/// List tokens (without secrets), oldest first, a page at a time.
#[utoipa::path(get, path = "/v1/tokens", tag = "tokens", params(PageQuery),
    responses(
        (status = 200, description = "Tokens, revoked ones included, oldest first", body = Vec<TokenOut>, headers(
            ("X-Total-Count" = i64, description = "Tokens in all"),
            ("Link" = String, description = "`rel=\"next\"` / `rel=\"prev\"` pages, when there are"))),
        (status = 422, description = "Bad `offset` or `limit`", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["admin"])))]
pub async fn list(
    State(state): State<AppState>,
    _auth: Authorized<ADMIN>,
    page: Paging,
) -> Result<(HeaderMap, Json<Vec<TokenOut>>), ApiError> {
    page.respond(tokens::page(&state.pool, page.offset, page.limit).await?, |t| Ok(token_out(&t, None)))
}

/// Revoke a token.
#[utoipa::path(delete, path = "/v1/tokens/{token_id}", tag = "tokens",
    params(("token_id" = String, Path, description = "Token id")),
    responses(
        (status = 204, description = "Revoked"),
        (status = 404, description = "Unknown or already revoked token", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["admin"])))]
pub async fn revoke(
    State(state): State<AppState>,
    _auth: Authorized<ADMIN>,
    Path(token_id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if tokens::revoke(&state.pool, &token_id).await? {
        state.caches.tokens_changed(&state.pool).await;
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(ApiError::not_found("live token", &token_id))
    }
}

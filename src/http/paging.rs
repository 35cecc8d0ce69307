//! Paging, the same on every list: `?offset=` (items to skip, ≥ 0, default 0) and `?limit=`
//! (items at most, 1–1000, default 100; a session's measurements 1–10000, default 1000). A bad
//! value is 422 naming the parameter. The bodies stay what they were (a bare array; the
//! measurements' page object), and every list answers with the paging in headers:
//! `X-Total-Count` (items in the whole list, filters applied) and `Link` with `rel="next"` and
//! `rel="prev"` (RFC 8288) where there is such a page, the request's other parameters kept.

use axum::Json;
use axum::extract::{FromRequestParts, OriginalUri, Query};
use axum::http::request::Parts;
use axum::http::{HeaderMap, HeaderName, HeaderValue};
use serde::Deserialize;
use utoipa::IntoParams;

use super::error::ApiError;
use crate::db::paging::Page;

/// The paging parameters as they arrive (text, so a value that is not a number is a 422 naming
/// it, not a bare 400).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct PageQuery {
    /// Items to skip (default 0).
    #[param(value_type = Option<i64>, minimum = 0)]
    pub offset: Option<String>,
    /// Items at most (default 100, at most 1000).
    #[param(value_type = Option<i64>, minimum = 1, maximum = 1000)]
    pub limit: Option<String>,
}

/// The paging parameters of a session's measurements, whose pages are larger (the schema only:
/// they are read as [`PageQuery`]).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct MeasurementPageQuery {
    /// Items to skip (default 0).
    #[param(value_type = Option<i64>, minimum = 0)]
    pub offset: Option<String>,
    /// Items at most (default 1000, at most 10000).
    #[param(value_type = Option<i64>, minimum = 1, maximum = 10000)]
    pub limit: Option<String>,
}

/// The header carrying the length of the whole list.
pub const TOTAL_COUNT: HeaderName = HeaderName::from_static("x-total-count");

/// Checked paging of a request, with where it was asked (for the `Link` header). `DEFAULT` and
/// `MAX` are the limit's default and largest value.
#[derive(Clone, Debug, PartialEq)]
pub struct Paging<const DEFAULT: i64 = 100, const MAX: i64 = 1000> {
    pub offset: i64,
    pub limit: i64,
    path: String,
    /// The request's other query parameters, as sent (still percent-encoded).
    rest: Vec<String>,
}

/// Parse `offset` and `limit` against a limit's default and largest value.
pub fn check(q: &PageQuery, default: i64, max: i64) -> Result<(i64, i64), ApiError> {
    // Absent: the default. Present, it must be a whole number as the document declares (an empty
    // `?limit=` is not one); an integer-valued decimal (`5.0`) is one, as in JSON Schema.
    let number = |v: &Option<String>, field: &str, what: &str| -> Result<Option<i64>, ApiError> {
        let Some(s) = v.as_deref() else { return Ok(None) };
        let whole = s
            .parse::<i64>()
            .ok()
            .or_else(|| s.parse::<f64>().ok().filter(|x| x.fract() == 0.0 && x.abs() < 9.2e18).map(|x| x as i64));
        whole.map(Some).ok_or_else(|| ApiError::invalid(field, format!("'{s}' is not a whole number: {what}")))
    };
    let limits = format!("must be 1–{max}");
    let offset = number(&q.offset, "offset", "must be 0 or more")?.unwrap_or(0);
    let limit = number(&q.limit, "limit", &limits)?.unwrap_or(default);
    if offset < 0 {
        return Err(ApiError::invalid("offset", "must be 0 or more"));
    }
    if !(1..=max).contains(&limit) {
        return Err(ApiError::invalid("limit", limits));
    }
    Ok((offset, limit))
}

impl<const DEFAULT: i64, const MAX: i64> Paging<DEFAULT, MAX> {
    /// The paging headers of a page of `returned` items out of `total`.
    pub fn headers(&self, total: i64, returned: usize) -> HeaderMap {
        let mut h = HeaderMap::new();
        h.insert(TOTAL_COUNT, HeaderValue::from(total));
        let mut links = Vec::new();
        let next = self.offset + returned as i64;
        if returned > 0 && next < total {
            links.push(format!("<{}>; rel=\"next\"", self.link(next)));
        }
        if self.offset > 0 {
            links.push(format!("<{}>; rel=\"prev\"", self.link((self.offset - self.limit).max(0))));
        }
        if !links.is_empty()
            && let Ok(v) = HeaderValue::from_str(&links.join(", "))
        {
            h.insert(axum::http::header::LINK, v);
        }
        h
    }

    /// The answer to a list request: the page's rows in their wire form (`wire` maps each row),
    /// with the paging headers.
    pub fn respond<R, T>(
        &self,
        page: Page<R>,
        wire: impl FnMut(R) -> Result<T, ApiError>,
    ) -> Result<(HeaderMap, Json<Vec<T>>), ApiError> {
        let out = page.items.into_iter().map(wire).collect::<Result<Vec<T>, ApiError>>()?;
        Ok(self.answer(page.total, out))
    }

    /// The answer to a list request whose items are already in their wire form, out of `total`.
    pub fn answer<T>(&self, total: i64, items: Vec<T>) -> (HeaderMap, Json<Vec<T>>) {
        (self.headers(total, items.len()), Json(items))
    }

    fn link(&self, offset: i64) -> String {
        let mut q = self.rest.clone();
        q.push(format!("offset={offset}"));
        q.push(format!("limit={}", self.limit));
        format!("{}?{}", self.path, q.join("&"))
    }
}

impl<S: Send + Sync, const DEFAULT: i64, const MAX: i64> FromRequestParts<S> for Paging<DEFAULT, MAX> {
    type Rejection = ApiError;

    async fn from_request_parts(parts: &mut Parts, state: &S) -> Result<Self, ApiError> {
        let Query(q) = Query::<PageQuery>::from_request_parts(parts, state)
            .await
            .map_err(|e| ApiError::malformed(None, e.body_text()))?;
        let (offset, limit) = check(&q, DEFAULT, MAX)?;
        let uri = parts.extensions.get::<OriginalUri>().map(|u| u.0.clone()).unwrap_or_else(|| parts.uri.clone());
        let rest = uri
            .query()
            .unwrap_or("")
            .split('&')
            .filter(|p| !p.is_empty())
            .filter(|p| {
                let name = p.split('=').next().unwrap_or("");
                name != "offset" && name != "limit"
            })
            .map(str::to_string)
            .collect();
        Ok(Paging { offset, limit, path: uri.path().to_string(), rest })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn q(offset: Option<&str>, limit: Option<&str>) -> PageQuery {
        PageQuery { offset: offset.map(str::to_string), limit: limit.map(str::to_string) }
    }

    #[test]
    fn values_are_checked_and_the_field_named() {
        assert_eq!(check(&q(None, None), 100, 1000).unwrap(), (0, 100));
        assert_eq!(check(&q(Some("5"), Some("1000")), 100, 1000).unwrap(), (5, 1000));
        assert_eq!(check(&q(Some("5.0"), Some("1e2")), 100, 1000).unwrap(), (5, 100), "integer-valued decimals");
        for (o, l, field) in [
            (Some("-1"), None, "offset"),
            (Some("x"), None, "offset"),
            (None, Some("0"), "limit"),
            (None, Some("1001"), "limit"),
            (None, Some("1.5"), "limit"),
            (None, Some(""), "limit"),
            (Some(" 5"), None, "offset"),
            (Some("NaN"), None, "offset"),
        ] {
            let e = check(&q(o, l), 100, 1000).unwrap_err().problem();
            assert_eq!((e.status, e.field.as_deref()), (422, Some(field)), "{o:?} {l:?}");
        }
    }

    #[test]
    fn links_keep_the_other_parameters() {
        let p: Paging = Paging { offset: 10, limit: 10, path: "/v1/jobs".into(), rest: vec!["state=failed".into()] };
        let h = p.headers(25, 10);
        assert_eq!(h[TOTAL_COUNT], "25");
        assert_eq!(
            h[axum::http::header::LINK],
            "</v1/jobs?state=failed&offset=20&limit=10>; rel=\"next\", </v1/jobs?state=failed&offset=0&limit=10>; rel=\"prev\""
        );
        let last = p.headers(20, 10);
        assert!(!last[axum::http::header::LINK].to_str().unwrap().contains("next"));
    }
}

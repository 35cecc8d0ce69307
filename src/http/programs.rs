//! Program filtering: `POST /v1/robots/{id}/programs/filter` with a robot program as the body
//! (RAPID, KRL, Fanuc TP text, URScript; `domain::program`) → the same program with every target
//! replaced by its compensated value, and a report per target.
//!
//! The body is the program file itself (`application/octet-stream` or `text/plain`; its bytes are
//! kept as they are, ISO-8859-1 included), or several files as `multipart/form-data`, one file part
//! each (a KRL `.src` and its `.dat`, RAPID modules read together). Options are in the query. The
//! parameter set is the robot's active one or `parameter_set_id`, gated as compensation is: a set
//! without a passing held-out validation is refused (409) unless `allow_unvalidated`, and targets
//! outside the calibrated envelope fail unless `allow_outside_envelope`.
//!
//! The answer: with `Accept: application/json`, the report (`FilterOut`: every target's line,
//! original and compensated values, correction and uncertainty) with the files' text; otherwise
//! the filtered file itself (`application/octet-stream`, its name in `Content-Disposition`), the
//! counts in `X-Compensated-Targets`, `X-Kept-Targets` and `X-Failed-Targets` (several files:
//! JSON). A target that cannot be compensated is left as written and marked with a comment in the
//! program; the answer is still 200 and counts it.

use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, HeaderName, HeaderValue, header};
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};

use super::compensation::{Checked, checks, robot_set};
use super::extract::{Authorized, COMPENSATE};
use super::robots::find as find_robot;
use super::{ApiError, AppState};
use crate::domain::program::{
    AngleOrder, Calibration, FilterError, FilterOptions, JointTargets, Language, ProgramFile, TargetReport,
    TargetStatus, filter,
};
use crate::domain::validity::{Guard, ValidityOut};
use crate::units::DEG;

pub const COMPENSATED_TARGETS: HeaderName = HeaderName::from_static("x-compensated-targets");
pub const KEPT_TARGETS: HeaderName = HeaderName::from_static("x-kept-targets");
pub const FAILED_TARGETS: HeaderName = HeaderName::from_static("x-failed-targets");

/// The options of a filter request (query parameters).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[into_params(parameter_in = Query)]
pub struct FilterQuery {
    /// The program's language; default: from `name`'s extension (or the file parts' names), else
    /// from the program's first line.
    #[param(value_type = Option<Language>, inline)]
    pub language: Option<String>,
    /// The file's name, for the language, the report and `Content-Disposition` (`weld.mod`). Not
    /// blank, at most 200 characters.
    #[param(min_length = 1, max_length = 200)]
    pub name: Option<String>,
    /// The parameter set to use; default: the robot's active one.
    pub parameter_set_id: Option<String>,
    /// Joint targets: `keep` (default) or `recompute`.
    #[param(value_type = Option<JointTargets>, inline)]
    pub joint_targets: Option<String>,
    /// Use a set without a passing held-out validation (409 otherwise).
    pub allow_unvalidated: Option<bool>,
    /// Compensate targets outside the calibrated envelope instead of failing each.
    pub allow_outside_envelope: Option<bool>,
    /// A tool the program names but does not declare: `NAME:x,y,z,a,b,c` (mm, ZY'X'' deg), or with
    /// the payload `NAME:x,y,z,a,b,c,mass_kg,cx,cy,cz`. Repeat the parameter for several.
    #[param(max_items = 64)]
    pub tool: Option<Vec<String>>,
    /// A work frame the program names but does not declare (KRL base, RAPID work object):
    /// `NAME:x,y,z,a,b,c` in the robot's base frame. Repeatable.
    #[param(max_items = 64)]
    pub base: Option<Vec<String>>,
    /// A Fanuc tool frame: `N:x,y,z,w,p,r[,mass_kg,cx,cy,cz]`. Repeatable.
    #[param(max_items = 64)]
    pub utool: Option<Vec<String>>,
    /// A Fanuc user frame: `N:x,y,z,w,p,r`. Repeatable.
    #[param(max_items = 64)]
    pub uframe: Option<Vec<String>>,
    /// The joints the robot starts from (deg, comma-separated), for poses without a configuration
    /// (URScript; KRL without S and T).
    pub seed_joints_deg: Option<String>,
}

/// A program file's bytes (`application/octet-stream`).
#[derive(Debug, ToSchema)]
#[schema(value_type = String, format = Binary)]
#[allow(dead_code)]
pub struct ProgramBytes(pub Vec<u8>);

/// Several program files as `multipart/form-data`: one file part each, named by its filename.
#[derive(Debug, ToSchema)]
#[allow(dead_code)]
pub struct ProgramUpload {
    /// The files (a KRL `.src` and its `.dat`; RAPID modules).
    #[schema(value_type = Vec<String>, format = Binary)]
    pub files: Vec<Vec<u8>>,
}

/// A filtered file, as text.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct FilteredFile {
    pub name: String,
    /// `utf-8`, or `iso-8859-1` when the bytes are not UTF-8 (then every character of `content` is
    /// one byte: encode it back as ISO-8859-1 to get the file).
    pub encoding: String,
    pub content: String,
}

/// A filtered program and its report.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct FilterOut {
    pub parameter_set_id: String,
    pub version: i64,
    pub language: Language,
    /// What was checked: the validation the set was accepted on, the envelope, the uncertainty.
    pub validity: ValidityOut,
    pub files: Vec<FilteredFile>,
    /// One per target, in the order of the files: name, line, original and compensated values,
    /// correction, uncertainty, or why it was not compensated.
    pub targets: Vec<TargetReport>,
    pub compensated: usize,
    pub kept: usize,
    pub failed: usize,
}

/// The query's options, parsed; unknown parameters refused.
fn options(pairs: &[(String, String)]) -> Result<(FilterQuery, FilterOptions), ApiError> {
    let mut q = FilterQuery::default();
    let mut opts = FilterOptions::default();
    let bool_of = |k: &str, v: &str| match v {
        "true" => Ok(true),
        "false" => Ok(false),
        _ => Err(ApiError::invalid(k, format!("'{v}' is not true or false"))),
    };
    let field = |e: crate::domain::DomainError| ApiError::field(e);
    for (k, v) in pairs {
        match k.as_str() {
            "language" => opts.language = Some(Language::parse(v, "language").map_err(field)?),
            "name" => {
                crate::domain::limits::name(v, "name").map_err(field)?;
                q.name = Some(v.clone());
            }
            "parameter_set_id" => q.parameter_set_id = Some(v.clone()),
            "joint_targets" => opts.joint_targets = JointTargets::parse(v, "joint_targets").map_err(field)?,
            "allow_unvalidated" => q.allow_unvalidated = Some(bool_of(k, v)?),
            "allow_outside_envelope" => q.allow_outside_envelope = Some(bool_of(k, v)?),
            "tool" => opts.frames.add_tool(v, AngleOrder::Abc, "tool").map_err(field)?,
            "utool" => opts.frames.add_tool(v, AngleOrder::Wpr, "utool").map_err(field)?,
            "base" => opts.frames.add_base(v, AngleOrder::Abc, "base").map_err(field)?,
            "uframe" => opts.frames.add_base(v, AngleOrder::Wpr, "uframe").map_err(field)?,
            "seed_joints_deg" => {
                let mut seed = Vec::new();
                for s in v.split(',') {
                    match s.trim().parse::<f64>() {
                        Ok(x) if x.is_finite() => seed.push(x * DEG),
                        _ => {
                            return Err(ApiError::invalid(
                                "seed_joints_deg",
                                format!("'{}' is not a finite number", s.trim()),
                            ));
                        }
                    }
                }
                opts.seed_joints = Some(seed);
            }
            other => return Err(ApiError::invalid(other, "unknown parameter")),
        }
    }
    for key in ["tool", "base", "utool", "uframe"] {
        if pairs.iter().filter(|(k, _)| k == key).count() > 64 {
            return Err(ApiError::invalid(key, "at most 64 of them"));
        }
    }
    Ok((q, opts))
}

/// The program files of a request body.
fn program_files(headers: &HeaderMap, body: &[u8], name: Option<&str>) -> Result<Vec<ProgramFile>, ApiError> {
    let ct = headers.get(header::CONTENT_TYPE).and_then(|v| v.to_str().ok()).unwrap_or("");
    let mime = ct.split(';').next().unwrap_or("").trim().to_ascii_lowercase();
    match mime.as_str() {
        "application/octet-stream" | "text/plain" => {
            if body.is_empty() {
                return Err(ApiError::invalid("program", "the body is empty: send the program file"));
            }
            Ok(vec![ProgramFile { name: name.unwrap_or("program").to_string(), bytes: body.to_vec() }])
        }
        "multipart/form-data" => {
            if name.is_some() {
                return Err(ApiError::invalid("name", "with multipart/form-data the file parts name the files"));
            }
            let files = multipart(ct, body)?;
            if files.is_empty() {
                return Err(ApiError::invalid("program", "no file part in the multipart body"));
            }
            Ok(files)
        }
        _ => Err(ApiError::UnsupportedMediaType(format!(
            "expected the program as application/octet-stream or text/plain, or its files as multipart/form-data; got {}",
            if ct.is_empty() { "none" } else { ct }
        ))),
    }
}

/// The parts of a `multipart/form-data` body (RFC 7578) as files: each part's `filename` (else its
/// `name`) and its bytes.
fn multipart(content_type: &str, body: &[u8]) -> Result<Vec<ProgramFile>, ApiError> {
    let boundary = content_type
        .split(';')
        .skip(1)
        .filter_map(|p| p.trim().split_once('='))
        .find(|(k, _)| k.trim().eq_ignore_ascii_case("boundary"))
        .map(|(_, v)| v.trim().trim_matches('"').to_string())
        .filter(|b| !b.is_empty() && b.len() <= 70)
        .ok_or_else(|| ApiError::malformed(None, "multipart/form-data without a boundary"))?;
    let bad = || ApiError::malformed(None, "malformed multipart/form-data body");
    let delim = format!("--{boundary}").into_bytes();
    let find = |hay: &[u8], from: usize, needle: &[u8]| -> Option<usize> {
        hay.get(from..)?.windows(needle.len()).position(|w| w == needle).map(|p| from + p)
    };
    let mut at = find(body, 0, &delim).ok_or_else(bad)? + delim.len();
    let mut files = Vec::new();
    loop {
        if body.get(at..at + 2) == Some(b"--") {
            return Ok(files);
        }
        if body.get(at..at + 2) != Some(b"\r\n") {
            return Err(bad());
        }
        at += 2;
        let head_end = find(body, at, b"\r\n\r\n").ok_or_else(bad)?;
        let head = String::from_utf8_lossy(&body[at..head_end]).to_string();
        let content_start = head_end + 4;
        let mut next_delim = b"\r\n".to_vec();
        next_delim.extend_from_slice(&delim);
        let end = find(body, content_start, &next_delim).ok_or_else(bad)?;
        let mut name = None;
        let mut filename = None;
        for line in head.split("\r\n") {
            let Some((k, v)) = line.split_once(':') else { continue };
            if !k.trim().eq_ignore_ascii_case("content-disposition") {
                continue;
            }
            for p in v.split(';').skip(1) {
                if let Some((pk, pv)) = p.trim().split_once('=') {
                    let pv = pv.trim().trim_matches('"').to_string();
                    match pk.trim().to_ascii_lowercase().as_str() {
                        "name" => name = Some(pv),
                        "filename" => filename = Some(pv),
                        _ => {}
                    }
                }
            }
        }
        let file_name =
            filename.or(name).filter(|n| !n.trim().is_empty()).unwrap_or_else(|| format!("part{}", files.len() + 1));
        // A path in the filename is not ours to keep.
        let file_name = file_name.rsplit(['/', '\\']).next().unwrap_or_default().to_string();
        crate::domain::limits::name(&file_name, "program").map_err(ApiError::field)?;
        files.push(ProgramFile { name: file_name, bytes: body[content_start..end].to_vec() });
        at = end + next_delim.len();
        if files.len() > 64 {
            return Err(ApiError::invalid("program", "at most 64 files"));
        }
    }
}

/// Whether `Accept` asks for JSON (`application/json` with a non-zero q).
fn wants_json(headers: &HeaderMap) -> bool {
    headers.get_all(header::ACCEPT).iter().filter_map(|v| v.to_str().ok()).flat_map(|v| v.split(',')).any(|range| {
        let mut parts = range.split(';').map(str::trim);
        let media = parts.next().unwrap_or("").to_ascii_lowercase();
        let q = parts
            .filter_map(|p| p.strip_prefix("q="))
            .filter_map(|q| q.trim().parse::<f64>().ok())
            .next()
            .unwrap_or(1.0);
        q > 0.0 && media == "application/json"
    })
}

/// Filter a robot program with the robot's calibration.
#[utoipa::path(post, path = "/v1/robots/{robot_id}/programs/filter", tag = "compensation",
    params(("robot_id" = String, Path, description = "Robot id"), FilterQuery),
    request_body(description = "The program file (RAPID .mod/.prg, KRL .src or .dat, Fanuc .ls, URScript), or several files as multipart/form-data (a KRL .src with its .dat)",
        content(
            (ProgramBytes = "application/octet-stream"),
            (String = "text/plain"),
            (ProgramUpload = "multipart/form-data"))),
    responses(
        (status = 200, description = "The filtered program: the file itself (Accept other than application/json), or the report with the files (Accept: application/json; always for several files). Targets that could not be compensated are left as written, marked with a comment, and counted",
            headers(
                ("X-Compensated-Targets" = i64, description = "Targets rewritten with their compensated value"),
                ("X-Kept-Targets" = i64, description = "Joint targets left as written (joint_targets=keep)"),
                ("X-Failed-Targets" = i64, description = "Targets not compensated: left as written and marked")),
            content(
                (ProgramBytes = "application/octet-stream"),
                (FilterOut = "application/json"))),
        (status = 404, description = "Unknown robot", body = super::Problem, content_type = "application/problem+json"),
        (status = 409, description = "No parameter set named and none active; the set has no passing held-out validation (unless allow_unvalidated)", body = super::Problem, content_type = "application/problem+json"),
        (status = 413, description = "More targets than the batch limit, or a body over the size limit", body = super::Problem, content_type = "application/problem+json"),
        (status = 415, description = "Neither application/octet-stream, text/plain nor multipart/form-data", body = super::Problem, content_type = "application/problem+json"),
        (status = 422, description = "A program that does not parse (the detail names the file and line), an unknown language, a frame the program declares itself, a malformed option", body = super::Problem, content_type = "application/problem+json")),
    security(("bearer" = ["compensate"])))]
pub async fn filter_program(
    State(state): State<AppState>,
    _auth: Authorized<COMPENSATE>,
    Path(robot_id): Path<String>,
    Query(pairs): Query<Vec<(String, String)>>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, ApiError> {
    let robot = find_robot(&state, &robot_id).await?;
    let (q, opts) = options(&pairs)?;
    let files = program_files(&headers, &body, q.name.as_deref())?;
    let compiled = robot_set(&state, &robot, q.parameter_set_id.as_deref()).await?;
    let Checked { validation, envelope, held_out } =
        checks(&state, &compiled, q.allow_unvalidated.unwrap_or(false)).await?;
    let allow_outside = q.allow_outside_envelope.unwrap_or(false);
    let max = state.config.max_batch;
    let set = compiled.clone();
    let (filtered, validity) = tokio::task::spawn_blocking(move || {
        let count = crate::domain::program::count_targets(&files, opts.language)?;
        if count > max {
            return Ok(Err(count));
        }
        let cal = Calibration {
            set: &set.set,
            compensator: &set.compensator,
            envelope: envelope.as_ref(),
            allow_outside_envelope: allow_outside,
            covariance: set.covariance.as_ref(),
            held_out: held_out.as_ref(),
        };
        let validity = ValidityOut::new(&Guard {
            envelope: envelope.as_ref(),
            allow_outside,
            covariance: set.covariance.as_ref(),
            held_out: held_out.as_ref(),
        });
        filter(&cal, &files, &opts).map(|f| Ok((f, validity)))
    })
    .await?
    .map_err(|e| match e {
        FilterError::Program(e) => ApiError::invalid("program", e.to_string()),
        FilterError::Input(e) => ApiError::field(e),
    })?
    .map_err(|count| ApiError::TooLarge {
        detail: format!("the program has {count} targets; the limit is {max}"),
        field: Some("program".into()),
    })?;
    let mut validity = validity;
    validity.validation = validation;
    let count = |s: TargetStatus| filtered.report.iter().filter(|r| r.status == s).count();
    let (compensated, kept, failed) =
        (count(TargetStatus::Compensated), count(TargetStatus::Kept), count(TargetStatus::Failed));
    let counts = [(COMPENSATED_TARGETS, compensated), (KEPT_TARGETS, kept), (FAILED_TARGETS, failed)];
    let mut res = if wants_json(&headers) || filtered.files.len() > 1 {
        let files = filtered
            .files
            .iter()
            .map(|f| match String::from_utf8(f.bytes.clone()) {
                Ok(content) => FilteredFile { name: f.name.clone(), encoding: "utf-8".into(), content },
                Err(_) => FilteredFile {
                    name: f.name.clone(),
                    encoding: "iso-8859-1".into(),
                    content: f.bytes.iter().map(|&b| b as char).collect(),
                },
            })
            .collect();
        axum::Json(FilterOut {
            parameter_set_id: compiled.row.id.clone(),
            version: compiled.row.version,
            language: filtered.language,
            validity,
            files,
            targets: filtered.report,
            compensated,
            kept,
            failed,
        })
        .into_response()
    } else {
        let f = &filtered.files[0];
        let safe: String =
            f.name.chars().map(|c| if c.is_ascii_graphic() && c != '"' && c != '\\' { c } else { '_' }).collect();
        (
            [
                (header::CONTENT_TYPE, "application/octet-stream".to_string()),
                (header::CONTENT_DISPOSITION, format!("attachment; filename=\"{safe}\"")),
            ],
            f.bytes.clone(),
        )
            .into_response()
    };
    for (h, n) in counts {
        res.headers_mut().insert(h, HeaderValue::from(n));
    }
    Ok(res)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multipart_bodies_split_into_files() {
        let body = b"preamble\r\n--XyZ\r\nContent-Disposition: form-data; name=\"files\"; filename=\"a/weld.src\"\r\nContent-Type: application/octet-stream\r\n\r\nDEF weld()\r\nEND\r\n--XyZ\r\nContent-Disposition: form-data; name=\"files\"; filename=\"weld.dat\"\r\n\r\nDEFDAT weld\r\n\xe9ENDDAT\r\n--XyZ--\r\n";
        let files = multipart("multipart/form-data; boundary=\"XyZ\"", body).unwrap();
        assert_eq!(files.len(), 2);
        assert_eq!(files[0].name, "weld.src");
        assert_eq!(files[0].bytes, b"DEF weld()\r\nEND");
        assert_eq!(files[1].bytes, b"DEFDAT weld\r\n\xe9ENDDAT");
        assert!(multipart("multipart/form-data", body).is_err());
        assert!(multipart("multipart/form-data; boundary=XyZ", b"--XyZ\r\nno head").is_err());
    }

    #[test]
    fn options_refuse_what_they_do_not_know() {
        let p = |k: &str, v: &str| vec![(k.to_string(), v.to_string())];
        assert!(options(&p("tool", "1:0,0,100,0,0,0")).is_ok());
        for (k, v) in [
            ("tool", "1:0,0"),
            ("language", "cobol"),
            ("joint_targets", "maybe"),
            ("bogus", "1"),
            ("allow_unvalidated", "yes"),
        ] {
            let e = options(&p(k, v)).unwrap_err();
            assert_eq!(e.problem().field.as_deref(), Some(k), "{k}={v}");
        }
    }
}

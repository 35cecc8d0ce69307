//! A robot's calibration history as a time series, for dashboards: one entry per parameter set,
//! oldest first — its version and date, the sessions it was identified from, the latest
//! validation's mean/p95/max (mm), the latest diagnosis's verdict, and whether it is or was
//! active. The JSON route (`GET /v1/robots/{id}/history`) and any page plotting it call
//! [`history`].

use crate::db::Pool;
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;

use super::AppError;
use crate::db::{corrections, records};
use crate::domain::history::TimeRange;

/// Which part of the history.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HistoryFilter {
    /// Created in `[from, to)`.
    pub range: TimeRange,
    /// Archived sets too.
    pub include_archived: bool,
    /// Entries to skip.
    pub offset: i64,
    /// Entries at most (`None`: all).
    pub limit: Option<i64>,
}

/// A validation of a set (figures in mm, the calibrated model's).
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct HistoryValidation {
    pub validation_id: String,
    pub created_at: String,
    /// Sessions validated on.
    pub sessions: Vec<String>,
    /// Held out: none of these sessions was used to fit the set (and one is a validation
    /// session). `false`: in-sample, the figures are fit residuals.
    pub held_out: bool,
    /// Measurements in the figures.
    pub n: Option<u64>,
    pub mean_mm: Option<f64>,
    pub p95_mm: Option<f64>,
    pub max_mm: Option<f64>,
    /// The nominal model's mean on the same measurements, for the before/after line.
    pub nominal_mean_mm: Option<f64>,
}

/// The latest diagnosis of a set.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct HistoryDiagnosis {
    pub diagnosis_id: String,
    pub created_at: String,
    pub verdict: crate::diagnose::Status,
    pub summary: String,
}

/// One parameter set in the time series.
#[derive(Clone, Debug, PartialEq, Serialize, ToSchema)]
pub struct HistoryEntry {
    pub parameter_set_id: String,
    /// 1, 2, 3 … per robot.
    pub version: i64,
    /// When the set was made (RFC 3339, UTC).
    pub created_at: String,
    /// Names of the sessions it was identified from (empty when imported).
    pub sessions: Vec<String>,
    /// The identification job, when it came from one.
    pub job_id: Option<String>,
    /// Compensation uses it now.
    pub active: bool,
    /// It has been activated at some time (now or before).
    pub was_active: bool,
    /// Its first recorded activation (absent when never, or activated before activations were
    /// recorded).
    pub first_activated_at: Option<String>,
    pub archived: bool,
    /// The latest held-out validation (on sessions the set was not fitted on): absent until
    /// there is one.
    pub validation: Option<HistoryValidation>,
    /// The latest in-sample validation (on sessions the set was fitted on, e.g. after accepting a
    /// diagnosis that pooled them), when it is newer than the held-out one or there is none:
    /// shown apart, never as held out.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub in_sample: Option<HistoryValidation>,
    /// The sessions the set was fitted on (its file's record and the store's joined).
    pub fit_sessions: Vec<String>,
    /// Absent until the set is diagnosed.
    pub diagnosis: Option<HistoryDiagnosis>,
}

/// A page of the history and how long the whole (filtered) history is.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryPage {
    pub total: i64,
    pub entries: Vec<HistoryEntry>,
}

fn json(text: &str, what: &str) -> Result<Value, AppError> {
    serde_json::from_str(text).map_err(|e| AppError::Internal(format!("{what}: stored JSON: {e}")))
}

/// The sessions a stored set was fitted on: its document's `quality.sessions` (read without the
/// rest of the document) joined with the store's list.
fn fit_sessions(doc_json: &str, listed: &[String]) -> Result<Vec<String>, serde_json::Error> {
    #[derive(serde::Deserialize)]
    struct Doc {
        #[serde(default)]
        quality: Option<Quality>,
    }
    #[derive(serde::Deserialize)]
    struct Quality {
        /// Absent or `null` where a report does not record them (an imported table, an older file).
        #[serde(default)]
        sessions: Option<Vec<String>>,
    }
    let d: Doc = serde_json::from_str(doc_json)?;
    let mut out = d.quality.and_then(|q| q.sessions).unwrap_or_default();
    for s in listed {
        if !out.contains(s) {
            out.push(s.clone());
        }
    }
    Ok(out)
}

/// The history of robot `robot_id` (which must exist: the caller has found it) in `filter`.
pub async fn history(pool: &Pool, robot_id: &str, filter: &HistoryFilter) -> Result<HistoryPage, AppError> {
    let robot = records::robot(pool, robot_id)
        .await?
        .ok_or_else(|| AppError::unknown("robot_id", format!("no robot '{robot_id}'")))?;
    let (from, to) = (filter.range.from.as_deref(), filter.range.to.as_deref());
    let total = records::parameter_set_count_in_range(pool, robot_id, filter.include_archived, from, to).await?;
    let limit = filter.limit.unwrap_or(i64::MAX);
    let rows =
        records::parameter_sets_in_range(pool, robot_id, filter.include_archived, from, to, filter.offset, limit)
            .await?;
    let mut entries = Vec::with_capacity(rows.len());
    for row in rows {
        let what = format!("parameter set {}", row.id);
        let listed: Vec<String> = serde_json::from_str(&row.sessions_json)
            .map_err(|e| AppError::Internal(format!("{what}: sessions: {e}")))?;
        let fit_sessions =
            fit_sessions(&row.doc_json, &listed).map_err(|e| AppError::Internal(format!("{what}: {e}")))?;
        // Newest first: the latest held-out one, and an in-sample one newer than it.
        let (mut validation, mut in_sample) = (None, None);
        for v in records::validations_of_set(pool, &row.id).await? {
            let r = json(&v.report_json, &what)?;
            let sessions: Vec<String> = serde_json::from_str(&v.sessions_json)
                .map_err(|e| AppError::Internal(format!("{what}: validation sessions: {e}")))?;
            let purposes: Vec<crate::cell::Purpose> = r["purposes"]
                .as_array()
                .map(|a| {
                    a.iter()
                        .filter_map(|p| match p.as_str() {
                            Some("validation") => Some(crate::cell::Purpose::Validation),
                            Some("identification") => Some(crate::cell::Purpose::Identification),
                            _ => None,
                        })
                        .collect()
                })
                .unwrap_or_default();
            let held_out = crate::validate::report::is_held_out(&sessions, &purposes, &fit_sessions);
            let entry = HistoryValidation {
                validation_id: v.id,
                created_at: v.created_at,
                sessions,
                held_out,
                n: r["n"].as_u64(),
                mean_mm: r["mean_mm"].as_f64(),
                p95_mm: r["p95_mm"].as_f64(),
                max_mm: r["max_mm"].as_f64(),
                nominal_mean_mm: r["nominal"]["mean_mm"].as_f64(),
            };
            if held_out {
                validation = Some(entry);
                break;
            }
            in_sample.get_or_insert(entry);
        }
        let diagnosis = match records::diagnoses_of_set(pool, &row.id, 0, 1).await?.items.into_iter().next() {
            None => None,
            Some(d) => {
                // Only the verdict of the stored report, typed: a report without one is a stored
                // document gone wrong, said as such, not an empty verdict.
                #[derive(serde::Deserialize)]
                struct Report {
                    verdict: Verdict,
                }
                #[derive(serde::Deserialize)]
                struct Verdict {
                    status: crate::diagnose::Status,
                    summary: String,
                }
                let r: Report = serde_json::from_str(&d.report_json)
                    .map_err(|e| AppError::Internal(format!("{what}: stored diagnosis {}: {e}", d.id)))?;
                Some(HistoryDiagnosis {
                    diagnosis_id: d.id,
                    created_at: d.created_at,
                    verdict: r.verdict.status,
                    summary: r.verdict.summary,
                })
            }
        };
        let activations = corrections::activations_of_set(pool, &row.id).await?;
        let active = robot.active_parameter_set_id.as_deref() == Some(row.id.as_str());
        entries.push(HistoryEntry {
            version: row.version,
            created_at: row.created_at.clone(),
            sessions: serde_json::from_str(&row.sessions_json)
                .map_err(|e| AppError::Internal(format!("{what}: sessions: {e}")))?,
            job_id: row.job_id.clone(),
            active,
            was_active: active || !activations.is_empty(),
            first_activated_at: activations.iter().find_map(|a| a.activated_at.clone()),
            archived: row.archived_at.is_some(),
            validation,
            in_sample,
            fit_sessions,
            diagnosis,
            parameter_set_id: row.id,
        });
    }
    Ok(HistoryPage { total, entries })
}

//! ISO 9283 evaluations (migration 0007): one row per evaluation job, written once.

use crate::db::AnyExecutor;

/// An evaluation row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct Iso9283Row {
    pub id: String,
    pub robot_id: String,
    pub session_id: String,
    pub parameter_set_id: Option<String>,
    pub request_json: String,
    pub report_json: String,
    pub job_id: Option<String>,
    pub created_at: String,
}

pub async fn insert(db: impl AnyExecutor<'_>, r: &Iso9283Row) -> Result<(), sqlx::Error> {
    sqlx::query(
        "INSERT INTO iso9283_evaluations (id, robot_id, session_id, parameter_set_id, request_json, report_json, \
             job_id, created_at) \
         VALUES ($1, $2, $3, $4, $5, $6, $7, $8)",
    )
    .bind(&r.id)
    .bind(&r.robot_id)
    .bind(&r.session_id)
    .bind(&r.parameter_set_id)
    .bind(&r.request_json)
    .bind(&r.report_json)
    .bind(&r.job_id)
    .bind(&r.created_at)
    .execute(db)
    .await?;
    Ok(())
}

pub async fn get(db: impl AnyExecutor<'_>, id: &str) -> Result<Option<Iso9283Row>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM iso9283_evaluations WHERE id = $1").bind(id).fetch_optional(db).await
}

/// The evaluations of a session, oldest first (what keeps it from being deleted).
pub async fn of_session(db: impl AnyExecutor<'_>, session_id: &str) -> Result<Vec<String>, sqlx::Error> {
    sqlx::query_scalar("SELECT id FROM iso9283_evaluations WHERE session_id = $1 ORDER BY created_at, id")
        .bind(session_id)
        .fetch_all(db)
        .await
}

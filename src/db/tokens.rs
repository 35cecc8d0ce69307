//! Bearer tokens. The secret is shown once, at creation; the store keeps only its SHA-256, so a
//! copy of the database does not hand out access.

use crate::db::AnyExecutor;
use crate::db::Pool;
use sha2::{Digest, Sha256};

use super::paging::{self, Page};

/// What a token may do; on the wire, its lower-case name (`measure`).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Scope {
    /// Create robots, artefacts and sessions; append measurements.
    Measure,
    /// Start and cancel jobs (pose plans, identifications, validations); import and activate
    /// parameter sets.
    Calibrate,
    /// Ask for compensated targets.
    Compensate,
    /// Read everything (dashboards).
    Read,
    /// Manage tokens; implies every other scope.
    Admin,
}

impl Scope {
    pub const ALL: [Scope; 5] = [Scope::Measure, Scope::Calibrate, Scope::Compensate, Scope::Read, Scope::Admin];

    pub fn as_str(self) -> &'static str {
        match self {
            Scope::Measure => "measure",
            Scope::Calibrate => "calibrate",
            Scope::Compensate => "compensate",
            Scope::Read => "read",
            Scope::Admin => "admin",
        }
    }

    pub fn parse(s: &str) -> Option<Scope> {
        Scope::ALL.into_iter().find(|x| x.as_str() == s)
    }
}

/// Parse a scope list (`measure,read` or space-separated); errors name the bad item.
pub fn parse_scopes(s: &str) -> Result<Vec<Scope>, String> {
    let mut out = Vec::new();
    for item in s.split([',', ' ']).map(str::trim).filter(|x| !x.is_empty()) {
        let sc = Scope::parse(item)
            .ok_or_else(|| format!("'{item}' is not a scope (measure, calibrate, compensate, read, admin)"))?;
        if !out.contains(&sc) {
            out.push(sc);
        }
    }
    if out.is_empty() {
        return Err("at least one scope is needed (measure, calibrate, compensate, read, admin)".into());
    }
    out.sort();
    Ok(out)
}

/// The stored form of a secret.
pub fn hash(secret: &str) -> String {
    let d = Sha256::digest(secret.as_bytes());
    d.iter().map(|b| format!("{b:02x}")).collect()
}

/// A fresh secret: `rc_` and 32 random bytes in hex (the thread RNG is a CSPRNG seeded by the OS).
pub fn new_secret() -> String {
    use rand::RngCore;
    let mut b = [0u8; 32];
    rand::rng().fill_bytes(&mut b);
    format!("rc_{}", b.iter().map(|x| format!("{x:02x}")).collect::<String>())
}

/// A token row.
#[derive(Clone, Debug, PartialEq, sqlx::FromRow)]
pub struct TokenRow {
    pub id: String,
    pub name: String,
    pub hash: String,
    pub scopes: String,
    pub created_at: String,
    pub revoked_at: Option<String>,
}

impl TokenRow {
    pub fn scopes(&self) -> Vec<Scope> {
        self.scopes.split(' ').filter_map(Scope::parse).collect()
    }
}

/// Create a token; returns the row and the secret (never stored).
pub async fn create(db: impl AnyExecutor<'_>, name: &str, scopes: &[Scope]) -> Result<(TokenRow, String), sqlx::Error> {
    let secret = new_secret();
    let row = TokenRow {
        id: super::new_id(),
        name: name.to_string(),
        hash: hash(&secret),
        scopes: scopes.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(" "),
        created_at: super::now(),
        revoked_at: None,
    };
    sqlx::query("INSERT INTO tokens (id, name, hash, scopes, created_at) VALUES ($1, $2, $3, $4, $5)")
        .bind(&row.id)
        .bind(&row.name)
        .bind(&row.hash)
        .bind(&row.scopes)
        .bind(&row.created_at)
        .execute(db)
        .await?;
    Ok((row, secret))
}

/// The live token with this secret.
pub async fn by_secret(db: impl AnyExecutor<'_>, secret: &str) -> Result<Option<TokenRow>, sqlx::Error> {
    by_hash(db, &hash(secret)).await
}

/// The live token whose secret hashes to `hash`.
pub async fn by_hash(db: impl AnyExecutor<'_>, hash: &str) -> Result<Option<TokenRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM tokens WHERE hash = $1 AND revoked_at IS NULL").bind(hash).fetch_optional(db).await
}

pub async fn list(db: impl AnyExecutor<'_>) -> Result<Vec<TokenRow>, sqlx::Error> {
    sqlx::query_as("SELECT * FROM tokens ORDER BY created_at, id").fetch_all(db).await
}

/// Tokens `offset..offset + limit`, oldest first.
pub async fn page(db: &Pool, offset: i64, limit: i64) -> Result<Page<TokenRow>, sqlx::Error> {
    let query = sqlx::query_as(
        "SELECT *, COUNT(*) OVER () AS total_rows FROM tokens ORDER BY created_at, id LIMIT $1 OFFSET $2",
    );
    paging::fetch(db, query, offset, limit, count(db)).await
}

pub async fn count(db: impl AnyExecutor<'_>) -> Result<i64, sqlx::Error> {
    sqlx::query_scalar("SELECT COUNT(*) FROM tokens").fetch_one(db).await
}

/// Revoke; `false` if unknown or already revoked.
pub async fn revoke(db: impl AnyExecutor<'_>, id: &str) -> Result<bool, sqlx::Error> {
    let r = sqlx::query("UPDATE tokens SET revoked_at = $1 WHERE id = $2 AND revoked_at IS NULL")
        .bind(super::now())
        .bind(id)
        .execute(db)
        .await?;
    Ok(r.rows_affected() == 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scopes_parse_and_name_bad_items() {
        assert_eq!(parse_scopes("read, measure read").unwrap(), vec![Scope::Measure, Scope::Read]);
        assert!(parse_scopes("read,write").unwrap_err().contains("'write'"));
        assert!(parse_scopes(" ").is_err());
    }

    /// SHA-256 of "abc" (FIPS 180-2, appendix B.1).
    #[test]
    fn hash_is_sha256() {
        assert_eq!(hash("abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        let s = new_secret();
        assert!(s.starts_with("rc_") && s.len() == 67 && s != new_secret());
    }
}

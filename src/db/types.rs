//! What `sqlx::Any` lacks for the store's columns (see the module documentation of `db`).

use sqlx::Type;
use sqlx::any::{Any, AnyTypeInfo, AnyValueRef};
use sqlx::decode::Decode;
use sqlx::error::BoxDynError;

/// A flag column: BOOLEAN on PostgreSQL, an INTEGER 0/1 on SQLite (which `Any` hands over as an
/// integer and refuses to decode as `bool`). Anything but 0 or 1 is an error, not a guess. Bind
/// flags as plain `bool`: `Any` writes 0/1 to SQLite and a BOOLEAN to PostgreSQL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Flag(pub bool);

impl From<Flag> for bool {
    fn from(f: Flag) -> bool {
        f.0
    }
}

impl Type<Any> for Flag {
    fn type_info() -> AnyTypeInfo {
        <bool as Type<Any>>::type_info()
    }

    fn compatible(_ty: &AnyTypeInfo) -> bool {
        true
    }
}

impl<'r> Decode<'r, Any> for Flag {
    fn decode(value: AnyValueRef<'r>) -> Result<Self, BoxDynError> {
        if let Ok(b) = <bool as Decode<Any>>::decode(value.clone()) {
            return Ok(Flag(b));
        }
        match <i64 as Decode<Any>>::decode(value)? {
            0 => Ok(Flag(false)),
            1 => Ok(Flag(true)),
            n => Err(format!("a flag column holds {n}, not 0 or 1").into()),
        }
    }
}

/// What `Any` needs of an enum stored as its snake_case name (the text its serde form and its
/// derived `sqlx::Type` use). sqlx's derive writes `Type` for SQLite and PostgreSQL only, and its
/// `Decode` goes through `&str`, which `Any` does not decode; so `Type<Any>` is written here (the
/// derived `Encode` then serves binds), and rows decode the column as text through
/// `TryFrom<String>` (`#[sqlx(try_from = "String")]`), an unknown name being an error.
macro_rules! text_enum {
    ($($t:ty),* $(,)?) => {$(
        impl Type<Any> for $t {
            fn type_info() -> AnyTypeInfo {
                <str as Type<Any>>::type_info()
            }

            fn compatible(ty: &AnyTypeInfo) -> bool {
                <str as Type<Any>>::compatible(ty)
            }
        }

        impl TryFrom<String> for $t {
            type Error = String;

            fn try_from(s: String) -> Result<Self, String> {
                serde_json::from_value(serde_json::Value::String(s.clone()))
                    .map_err(|_| format!("'{s}' is not a {}", std::any::type_name::<$t>().rsplit("::").next().unwrap_or("name")))
            }
        }
    )*};
}

text_enum!(super::jobs::JobKind, super::jobs::JobState,);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::db::jobs::{JobKind, JobState};

    /// Both spellings of a flag decode; a 2 is refused; enums round-trip by name through SQLite.
    #[tokio::test]
    async fn flags_and_names_round_trip_on_sqlite() {
        let pool = crate::db::connect_memory().await.unwrap();
        let f: Vec<Flag> = sqlx::query_scalar("SELECT 0 UNION ALL SELECT 1 ORDER BY 1").fetch_all(&pool).await.unwrap();
        assert_eq!(f, vec![Flag(false), Flag(true)]);
        let bad = sqlx::query_scalar::<_, Flag>("SELECT 2").fetch_one(&pool).await.unwrap_err();
        assert!(bad.to_string().contains("holds 2"), "{bad}");
        let (k, s): (String, String) = sqlx::query_as("SELECT $1, $2")
            .bind(JobKind::PosePlan)
            .bind(JobState::Cancelled)
            .fetch_one(&pool)
            .await
            .unwrap();
        assert_eq!((k.as_str(), s.as_str()), ("pose_plan", "cancelled"));
        assert_eq!(JobKind::try_from("iso9283".to_string()), Ok(JobKind::Iso9283));
        assert_eq!(JobState::try_from("lost".to_string()), Err("'lost' is not a JobState".to_string()));
    }
}

//! The values `robocal migrate` moves: the target column types, one row value, the conversion by
//! the target column's type and the canonical encoding both sides' checksums hash.

use std::fmt::Write as _;

/// A target column's type, as `information_schema.columns.data_type` names it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PgType {
    Boolean,
    SmallInt,
    Integer,
    BigInt,
    Double,
    Text,
    Bytea,
}

impl PgType {
    pub(super) fn parse(data_type: &str) -> Option<PgType> {
        Some(match data_type {
            "boolean" => PgType::Boolean,
            "smallint" => PgType::SmallInt,
            "integer" => PgType::Integer,
            "bigint" => PgType::BigInt,
            "double precision" => PgType::Double,
            "text" => PgType::Text,
            "bytea" => PgType::Bytea,
            _ => return None,
        })
    }

    pub(super) fn is_text(self) -> bool {
        self == PgType::Text
    }
}

/// One value, read from either side.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Null,
    Int(i64),
    Real(f64),
    Text(String),
    Blob(Vec<u8>),
    Bool(bool),
}

impl Value {
    fn storage(&self) -> &'static str {
        match self {
            Value::Null => "NULL",
            Value::Int(_) => "INTEGER",
            Value::Real(_) => "REAL",
            Value::Text(_) => "TEXT",
            Value::Blob(_) => "BLOB",
            Value::Bool(_) => "BOOLEAN",
        }
    }

    /// The value shown in a message (a key).
    pub(super) fn show(&self) -> String {
        match self {
            Value::Null => "NULL".into(),
            Value::Int(i) => i.to_string(),
            Value::Real(r) => format!("{r:?}"),
            Value::Text(t) => format!("'{t}'"),
            Value::Blob(b) => format!("x'{}'", hex(b)),
            Value::Bool(b) => b.to_string(),
        }
    }
}

pub(super) fn hex(bytes: &[u8]) -> String {
    let mut s = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        let _ = write!(s, "{b:02x}");
    }
    s
}

/// A SQLite value (by its storage class) as the target column's type holds it, or why it cannot
/// be: lossless conversions only.
pub fn convert(v: Value, ty: PgType) -> Result<Value, String> {
    const EXACT: i64 = 1 << 53;
    Ok(match (v, ty) {
        (Value::Null, _) => Value::Null,
        (Value::Int(i @ (0 | 1)), PgType::Boolean) => Value::Bool(i == 1),
        (Value::Int(i), PgType::Boolean) => return Err(format!("{i} is not a 0/1 flag (the column is BOOLEAN)")),
        (Value::Int(i), PgType::BigInt) => Value::Int(i),
        (Value::Int(i), PgType::Integer) if i32::try_from(i).is_ok() => Value::Int(i),
        (Value::Int(i), PgType::SmallInt) if i16::try_from(i).is_ok() => Value::Int(i),
        (Value::Int(i), PgType::Integer | PgType::SmallInt) => return Err(format!("{i} is out of the column's range")),
        (Value::Real(r), PgType::Double) => Value::Real(r),
        (Value::Int(i), PgType::Double) if (-EXACT..=EXACT).contains(&i) => Value::Real(i as f64),
        (Value::Text(t), PgType::Text) => Value::Text(t),
        (Value::Blob(b), PgType::Bytea) => Value::Blob(b),
        (v, ty) => return Err(format!("an {} value cannot go into a {ty:?} column", v.storage())),
    })
}

/// The canonical text of one row, appended to `out`: each value as `<length>:<text>` (integers in
/// decimal, reals in Rust's round-trip `{:?}` form, booleans as 0/1, text as is, blobs in
/// lower-case hex) or `-` for NULL, then a newline. The length prefix makes the framing
/// unambiguous whatever the text holds.
pub fn encode_row(out: &mut Vec<u8>, row: &[Value]) {
    for v in row {
        let text: std::borrow::Cow<str> = match v {
            Value::Null => {
                out.push(b'-');
                continue;
            }
            Value::Int(i) => i.to_string().into(),
            Value::Real(r) => format!("{r:?}").into(),
            Value::Bool(b) => (if *b { "1" } else { "0" }).into(),
            Value::Text(t) => t.as_str().into(),
            Value::Blob(b) => hex(b).into(),
        };
        let _ = write!(ByteWriter(&mut *out), "{}:", text.len());
        out.extend_from_slice(text.as_bytes());
    }
    out.push(b'\n');
}

struct ByteWriter<'a>(&'a mut Vec<u8>);

impl std::fmt::Write for ByteWriter<'_> {
    fn write_str(&mut self, s: &str) -> std::fmt::Result {
        self.0.extend_from_slice(s.as_bytes());
        Ok(())
    }
}

/// A double-quoted identifier (both dialects).
pub(super) fn quote(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

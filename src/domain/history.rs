//! The date filter of a robot's calibration history: `from` (inclusive) and `to` (exclusive) as
//! RFC 3339 date-times with their offset (`2026-11-24T13:00:00Z`, `…+02:00`), or full dates
//! (`2026-11-24`, midnight UTC). Parsed once into the store's text form (UTC, milliseconds), so
//! the store compares them as text.

use std::time::{Duration, SystemTime};

use super::DomainError;

/// A checked date range, in the store's time format.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TimeRange {
    /// Created at or after this.
    pub from: Option<String>,
    /// Created before this.
    pub to: Option<String>,
}

impl TimeRange {
    /// Parse `from` and `to` (either may be absent); errors name the field. A `to` at or before
    /// `from` is an empty range, not an error: no set was created in it.
    pub fn parse(from: Option<&str>, to: Option<&str>) -> Result<Self, DomainError> {
        let one = |v: Option<&str>, field: &str| -> Result<Option<SystemTime>, DomainError> {
            match v {
                None => Ok(None),
                Some(s) => parse_time(s).map(Some).map_err(|reason| DomainError::new(field, reason)),
            }
        };
        let (f, t) = (one(from, "from")?, one(to, "to")?);
        Ok(TimeRange { from: f.map(stored), to: t.map(stored) })
    }
}

/// The store's form of a time, rounded up to the millisecond (stored times are on that grid, so
/// `created >= from` and `created < to` keep their meaning).
fn stored(t: SystemTime) -> String {
    let since = t.duration_since(SystemTime::UNIX_EPOCH).unwrap_or_default();
    let sub_ms = since.subsec_nanos() % 1_000_000;
    let t = if sub_ms > 0 { t + Duration::from_nanos(u64::from(1_000_000 - sub_ms)) } else { t };
    humantime::format_rfc3339_millis(t).to_string()
}

/// 9999-12-31T23:59:59.999Z, the last instant RFC 3339 writes, in ms since 1970.
const LAST_MS: u64 = 253_402_300_799_999;

const FORMAT: &str = "an RFC 3339 date-time with its offset (2026-11-24T13:00:00Z, 2026-11-24T15:00:00+02:00) or a \
                      date (2026-11-24)";

/// An RFC 3339 date-time with `Z` or a `±hh:mm` offset, or a full date (midnight UTC). A space
/// where the offset's `+` belongs is taken as `+` (an unencoded `+` in a query string arrives as one).
///
/// Every year RFC 3339 has (0000–9999) is read: a time before 1970, when nothing was stored, is
/// taken as 1970-01-01T00:00:00Z (`from` before it is "from the start", `to` before it an empty
/// range), its calendar date still checked; humantime, which reads the rest, starts at 1970.
pub fn parse_time(s: &str) -> Result<SystemTime, String> {
    let bad = || format!("'{s}' is not {FORMAT}");
    if !s.is_ascii() {
        return Err(bad());
    }
    if s.len() >= 10 && s.as_bytes()[..4].iter().all(u8::is_ascii_digit) {
        let year: u32 = s[..4].parse().map_err(|_| bad())?;
        if year < 1970 {
            // The same date in a year of the same leap kind: 2000 (leap) or 2001.
            let leap = year.is_multiple_of(4) && (!year.is_multiple_of(100) || year.is_multiple_of(400));
            let twin = format!("{}{}", if leap { "2000" } else { "2001" }, &s[4..]);
            parse_time(&twin)?;
            return Ok(SystemTime::UNIX_EPOCH);
        }
    }
    if s.len() == 10 {
        return humantime::parse_rfc3339(&format!("{s}T00:00:00Z")).map_err(|_| bad());
    }
    if s.len() < 20 || !matches!(s.as_bytes()[10], b'T' | b't') {
        return Err(bad());
    }
    let (main, offset_s): (String, i64) = if s.ends_with(['Z', 'z']) {
        (format!("{}Z", &s[..s.len() - 1]), 0)
    } else {
        let (head, zone) = s.split_at(s.len() - 6);
        let z = zone.as_bytes();
        let sign = match z[0] {
            b'+' | b' ' => 1,
            b'-' => -1,
            _ => return Err(format!("'{s}' has no time zone: {FORMAT}")),
        };
        let digits = |a: u8, b: u8| -> Option<i64> {
            (a.is_ascii_digit() && b.is_ascii_digit()).then(|| i64::from(a - b'0') * 10 + i64::from(b - b'0'))
        };
        let (Some(h), Some(m), b':') = (digits(z[1], z[2]), digits(z[4], z[5]), z[3]) else {
            return Err(bad());
        };
        if h > 23 || m > 59 {
            return Err(bad());
        }
        (format!("{head}Z"), sign * (h * 3600 + m * 60))
    };
    let main = main.replacen(['t'], "T", 1);
    let t = humantime::parse_rfc3339(&main).map_err(|_| bad())?;
    // Local time = UTC + offset.
    let d = Duration::from_secs(offset_s.unsigned_abs());
    let utc = if offset_s >= 0 { t.checked_sub(d) } else { t.checked_add(d) };
    // Near either end of the span an offset can carry the instant outside it: held at the end.
    let last = SystemTime::UNIX_EPOCH + Duration::from_millis(LAST_MS);
    utc.map(|u| u.clamp(SystemTime::UNIX_EPOCH, last)).ok_or_else(bad)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_and_offsets_are_read_in_utc() {
        let r = TimeRange::parse(Some("2026-11-24T15:30:00+02:00"), Some("2026-11-25")).unwrap();
        assert_eq!(r.from.as_deref(), Some("2026-11-24T13:30:00.000Z"));
        assert_eq!(r.to.as_deref(), Some("2026-11-25T00:00:00.000Z"));
        let r = TimeRange::parse(Some("2026-11-24T08:00:00.0004-05:30"), None).unwrap();
        assert_eq!(r.from.as_deref(), Some("2026-11-24T13:30:00.001Z"));
        let r = TimeRange::parse(Some("2026-11-24t13:00:00z"), Some("2026-11-24T13:00:00 00:00")).unwrap();
        assert_eq!(r.from, r.to);
        // Before 1970 nothing was stored: the start; a to before from is an empty range.
        let r = TimeRange::parse(Some("0001-02-28T00:00:00-23:59"), Some("1969-12-31")).unwrap();
        assert_eq!(r.from.as_deref(), Some("1970-01-01T00:00:00.000Z"));
        assert_eq!(r.to, r.from);
        let r = TimeRange::parse(Some("2026-11-25"), Some("2026-11-24")).unwrap();
        assert!(r.to < r.from);
        let r = TimeRange::parse(Some("9999-12-31T23:59:59.999999-23:59"), None).unwrap();
        assert_eq!(r.from.as_deref(), Some("9999-12-31T23:59:59.999Z"));
    }

    #[test]
    fn bad_dates_name_their_field() {
        for (from, to, field) in [
            (Some("yesterday"), None, "from"),
            (Some("2026-11-24T13:00:00"), None, "from"),
            (None, Some("2026-13-01"), "to"),
            (None, Some("2026-11-24T13:00:00+2:00"), "to"),
            (Some(""), None, "from"),
            (None, Some("1900-02-29"), "to"),
            (Some("1600-02-30"), None, "from"),
        ] {
            let e = TimeRange::parse(from, to).unwrap_err();
            assert_eq!(e.path, field, "{from:?} {to:?}: {e}");
        }
    }
}

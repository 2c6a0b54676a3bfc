//! ISO 8601 date-times (`YYYY-MM-DDTHH:MM:SS[.fraction](Z|±HH:MM)`) to seconds since the Unix
//! epoch and back: the one form the run files use. The shape is checked here, strictly (no
//! space for `T`, no `+0100`, no week or ordinal dates); the calendar (which dates exist, days
//! since 1970, the civil date of an instant) and the printing are `jiff`'s, used in this module
//! only.

use jiff::SignedDuration;
use jiff::civil::{Date, DateTime};

/// 1970-01-01, the day the seconds count from.
const EPOCH_DAY: Date = Date::constant(1970, 1, 1);

/// The civil date `year-month-day` of the proleptic Gregorian calendar, if it exists.
fn civil_date(year: i64, month: i64, day: i64) -> Option<Date> {
    Date::new(year.try_into().ok()?, month.try_into().ok()?, day.try_into().ok()?).ok()
}

/// Days from 1970-01-01 to `date` (negative before 1970).
fn days_since_epoch(date: Date) -> i64 {
    date.duration_since(EPOCH_DAY).as_secs().div_euclid(86_400)
}

/// The decimal number written in `bytes[range]`, if that range exists and holds only ASCII
/// digits.
fn digits(bytes: &[u8], range: std::ops::Range<usize>) -> Option<i64> {
    let part = bytes.get(range)?;
    if part.is_empty() || !part.iter().all(u8::is_ascii_digit) {
        return None;
    }
    Some(part.iter().fold(0, |n, d| n * 10 + i64::from(d - b'0')))
}

/// Parse `YYYY-MM-DDTHH:MM:SS[.fraction](Z|±HH:MM)` into seconds since 1970-01-01T00:00:00Z.
///
/// `T` and `Z` may also be lower case (as RFC 3339 allows). Ranges are checked: month 1-12, a
/// day that exists in that month (leap years included), hour < 24, minute < 60, second < 61 (a
/// leap second is accepted and counted as the first second of the next minute), zone offset
/// hour < 24 and minute < 60. `Err` says what is wrong.
pub fn parse_iso8601(s: &str) -> Result<f64, String> {
    let bad = || {
        format!(
            "\"{s}\" is not an ISO 8601 time of the form YYYY-MM-DDTHH:MM:SS[.fraction] followed by Z or ±HH:MM, e.g. 2026-11-21T10:00:00Z"
        )
    };
    let b = s.as_bytes();
    let separators = [(4, b'-'), (7, b'-'), (13, b':'), (16, b':')];
    if b.len() < 20 || separators.iter().any(|&(i, c)| b[i] != c) || !matches!(b[10], b'T' | b't') {
        return Err(bad());
    }
    let field = |range| digits(b, range).ok_or_else(bad);
    let (year, month, day) = (field(0..4)?, field(5..7)?, field(8..10)?);
    let (hour, minute, second) = (field(11..13)?, field(14..16)?, field(17..19)?);

    // Optional fraction of a second: a '.' and at least one digit.
    let mut i = 19;
    let mut fraction = 0.0;
    if b[i] == b'.' {
        let start = i;
        i += 1;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == start + 1 {
            return Err(bad());
        }
        // The bytes are '.' and ASCII digits, so this is a valid slice and a valid number.
        fraction = s.get(start..i).and_then(|f| f.parse::<f64>().ok()).ok_or_else(bad)?;
    }

    // Zone: Z or ±HH:MM.
    let zone = &b[i..];
    let offset_s = match zone {
        [b'Z' | b'z'] => 0,
        [sign @ (b'+' | b'-'), _, _, b':', _, _] => {
            let (zh, zm) = (field(i + 1..i + 3)?, field(i + 4..i + 6)?);
            if zh > 23 || zm > 59 {
                return Err(format!(
                    "\"{s}\": the zone offset {}{zh:02}:{zm:02} is out of range",
                    *sign as char
                ));
            }
            let offset = zh * 3600 + zm * 60;
            if *sign == b'-' { -offset } else { offset }
        }
        _ => return Err(bad()),
    };

    if !(1..=12).contains(&month) {
        return Err(format!("\"{s}\": month {month} is not 1-12"));
    }
    let Some(date) = civil_date(year, month, day) else {
        return Err(format!("\"{s}\": day {day} does not exist in {year:04}-{month:02}"));
    };
    if hour > 23 || minute > 59 || second > 60 {
        return Err(format!("\"{s}\": time {hour:02}:{minute:02}:{second:02} is out of range"));
    }
    // Seconds are added to the minute rather than given to the calendar, which has no 60th.
    let whole = days_since_epoch(date) * 86_400 + hour * 3600 + minute * 60 + second - offset_s;
    Ok(whole as f64 + fraction)
}

/// Seconds since 1970-01-01T00:00:00Z as ISO 8601 UTC, `YYYY-MM-DDTHH:MM:SS[.fff]Z`, to the
/// millisecond (the fraction left out when it is 0); [`parse_iso8601`] reads it back. An instant
/// outside the years -9999 to 9999 (the calendar's range) is written as the nearer end of it.
pub fn format_iso8601(unix_s: f64) -> String {
    let whole = unix_s.floor();
    let millis = ((unix_s - whole) * 1000.0).round() as i64;
    let (whole, millis) =
        if millis == 1000 { (whole as i64 + 1, 0) } else { (whole as i64, millis) };
    // 0 <= millis < 1000, so the nanoseconds fit an i32.
    let since_epoch = SignedDuration::new(whole, (millis * 1_000_000) as i32);
    let at = DateTime::from(EPOCH_DAY).checked_add(since_epoch).unwrap_or(if whole < 0 {
        DateTime::MIN
    } else {
        DateTime::constant(9999, 12, 31, 23, 59, 59, 0)
    });
    if at.subsec_nanosecond() == 0 { format!("{at}Z") } else { format!("{at:.3}Z") }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// True for a leap year of the proleptic Gregorian calendar.
    fn is_leap_year(year: i64) -> bool {
        (year % 4 == 0 && year % 100 != 0) || year % 400 == 0
    }

    /// Number of days in `month` (1-12) of `year`, by the rule, independently of the calendar
    /// crate.
    fn days_in_month(year: i64, month: i64) -> i64 {
        match month {
            2 if is_leap_year(year) => 29,
            2 => 28,
            4 | 6 | 9 | 11 => 30,
            _ => 31,
        }
    }

    /// Days from 1970-01-01 to an existing civil date, as [`parse_iso8601`] counts them.
    fn days_from_civil(year: i64, month: i64, day: i64) -> i64 {
        days_since_epoch(civil_date(year, month, day).expect("the date exists"))
    }

    #[test]
    fn formatted_times_read_back() {
        for s in [
            "1970-01-01T00:00:00Z",
            "2000-02-29T23:59:59.999Z",
            "2025-09-04T16:10:55.312Z",
            "1969-12-31T23:59:59.500Z",
            "2026-11-21T10:00:00Z",
        ] {
            let secs = parse_iso8601(s).expect("parses");
            assert_eq!(format_iso8601(secs), s);
        }
        // Rounding to the millisecond carries into the next second.
        assert_eq!(format_iso8601(951_782_399.999_6), "2000-02-29T00:00:00Z");
    }

    #[test]
    fn known_instants() {
        assert_eq!(parse_iso8601("1970-01-01T00:00:00Z"), Ok(0.0));
        assert_eq!(parse_iso8601("1969-12-31T23:59:59Z"), Ok(-1.0));
        assert_eq!(parse_iso8601("2000-01-01T00:00:00Z"), Ok(946_684_800.0));
        assert_eq!(parse_iso8601("2026-11-21T10:00:00Z"), Ok(1_795_255_200.0));
        assert_eq!(parse_iso8601("2038-01-19T03:14:07Z"), Ok(2_147_483_647.0));
        assert_eq!(parse_iso8601("1900-03-01T00:00:00Z"), Ok(-2_203_891_200.0));
        assert_eq!(parse_iso8601("2000-02-29T00:00:00.5Z"), Ok(951_782_400.5));
        assert_eq!(parse_iso8601("2026-11-21t10:00:00z"), Ok(1_795_255_200.0));
    }

    #[test]
    fn zone_offsets_and_fractions() {
        let utc = 1_795_255_200.0;
        assert_eq!(parse_iso8601("2026-11-21T11:00:00+01:00"), Ok(utc));
        assert_eq!(parse_iso8601("2026-11-21T04:30:00-05:30"), Ok(utc));
        assert_eq!(parse_iso8601("2026-11-21T10:00:00-00:00"), Ok(utc));
        let t = parse_iso8601("2026-11-21T10:02:53.097Z").unwrap();
        assert!((t - (utc + 173.097)).abs() < 1e-6, "{t}");
        let t = parse_iso8601("2026-11-21T10:00:00.123456789+00:00").unwrap();
        assert!((t - (utc + 0.123_456_789)).abs() < 1e-6, "{t}");
        // A leap second counts as the next minute's first second.
        assert_eq!(parse_iso8601("2016-12-31T23:59:60Z"), parse_iso8601("2017-01-01T00:00:00Z"));
    }

    #[test]
    fn days_from_civil_counts_every_day_from_1600_to_2400() {
        let mut n = days_from_civil(1600, 1, 1);
        assert_eq!(n, -135_140);
        for year in 1600..2400 {
            for month in 1..=12 {
                for day in 1..=days_in_month(year, month) {
                    assert_eq!(days_from_civil(year, month, day), n, "{year}-{month}-{day}");
                    n += 1;
                }
            }
        }
        assert_eq!(days_from_civil(1970, 1, 1), 0);
    }

    #[test]
    fn leap_years() {
        assert!(parse_iso8601("2024-02-29T00:00:00Z").is_ok());
        assert!(parse_iso8601("2000-02-29T00:00:00Z").is_ok());
        for bad in ["2026-02-29T00:00:00Z", "1900-02-29T00:00:00Z", "2100-02-29T00:00:00Z"] {
            assert!(parse_iso8601(bad).unwrap_err().contains("does not exist"), "{bad}");
        }
    }

    #[test]
    fn out_of_range_fields_are_rejected() {
        for (bad, what) in [
            ("2026-13-01T00:00:00Z", "month 13"),
            ("2026-00-01T00:00:00Z", "month 0"),
            ("2026-04-31T00:00:00Z", "day 31"),
            ("2026-04-00T00:00:00Z", "day 0"),
            ("2026-11-21T24:00:00Z", "out of range"),
            ("2026-11-21T10:60:00Z", "out of range"),
            ("2026-11-21T10:00:61Z", "out of range"),
            ("2026-11-21T10:00:00+24:00", "zone offset"),
            ("2026-11-21T10:00:00+01:60", "zone offset"),
        ] {
            let e = parse_iso8601(bad).unwrap_err();
            assert!(e.contains(what), "{bad}: {e}");
        }
    }

    #[test]
    fn malformed_text_is_rejected_without_panicking() {
        for bad in [
            "",
            "yesterday",
            "2026-11-21",
            "2026-11-21 10:00:00Z",
            "2026-11-21T10:00:00",
            "2026-11-21T10:00:00.Z",
            "2026-11-21T10:00:00ZZ",
            "2026-11-21T10:00:00+0100",
            "2026-11-21T10:00:00+01:00:00",
            "2026-11-21T10:00Z",
            "26-11-21T10:00:00Z",
            "+2026-11-21T10:00:00Z",
            "2026-1-21T10:00:00Z",
            "2026-11-21T10:0é:00Z",
            "2026-11-21T10:00:0éZ",
            "2026-11-21T10:00:00+é1:00",
            "2026-11-21T10:00:00,5Z",
            "2026-11-21T1-:00:00Z",
            "２026-11-21T10:00:00Z",
        ] {
            let e = parse_iso8601(bad).unwrap_err();
            assert!(e.contains("ISO 8601"), "{bad}: {e}");
        }
    }
}

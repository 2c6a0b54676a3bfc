//! UTC timestamps for simulated runs: seconds since the Unix epoch to ISO 8601.

/// Format seconds since 1970-01-01T00:00:00Z as `YYYY-MM-DDTHH:MM:SS[.fff]Z`.
pub fn format_utc(unix_s: f64) -> String {
    let whole = unix_s.floor();
    let millis = ((unix_s - whole) * 1000.0).round() as i64;
    let (whole, millis) = if millis == 1000 { (whole as i64 + 1, 0) } else { (whole as i64, millis) };
    let days = whole.div_euclid(86_400);
    let secs = whole.rem_euclid(86_400);
    // Civil date from days since the epoch (H. Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    let (h, m, s) = (secs / 3600, secs % 3600 / 60, secs % 60);
    if millis == 0 {
        format!("{year:04}-{month:02}-{day:02}T{h:02}:{m:02}:{s:02}Z")
    } else {
        format!("{year:04}-{month:02}-{day:02}T{h:02}:{m:02}:{s:02}.{millis:03}Z")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn known_dates() {
        assert_eq!(super::format_utc(0.0), "1970-01-01T00:00:00Z");
        assert_eq!(super::format_utc(1_795_255_200.0), "2026-11-21T10:00:00Z");
        assert_eq!(super::format_utc(951_782_400.5), "2000-02-29T00:00:00.500Z");
    }
}

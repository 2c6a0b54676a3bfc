//! ISO 8601 timestamps (`YYYY-MM-DDTHH:MM:SS[.f](Z|±HH:MM)`) to seconds since the Unix epoch.

fn days_from_civil(y: i64, m: i64, d: i64) -> i64 {
    let y = if m <= 2 { y - 1 } else { y };
    let era = y.div_euclid(400);
    let yoe = y - era * 400;
    let doy = (153 * (if m > 2 { m - 3 } else { m + 9 }) + 2) / 5 + d - 1;
    let doe = yoe * 365 + yoe / 4 - yoe / 100 + doy;
    era * 146_097 + doe - 719_468
}

/// Parse an ISO 8601 date-time with a zone; `Err` says what is wrong.
pub fn parse_iso8601(s: &str) -> Result<f64, String> {
    let bad = || format!("\"{s}\" is not an ISO 8601 time like 2026-11-21T10:00:00Z");
    let b = s.as_bytes();
    if b.len() < 20 || b[4] != b'-' || b[7] != b'-' || !(b[10] == b'T' || b[10] == b't') || b[13] != b':' || b[16] != b':' {
        return Err(bad());
    }
    let num = |r: std::ops::Range<usize>| -> Result<i64, String> {
        let t = &s[r];
        if t.bytes().all(|c| c.is_ascii_digit()) { t.parse().map_err(|_| bad()) } else { Err(bad()) }
    };
    let (y, mo, d, h, mi) = (num(0..4)?, num(5..7)?, num(8..10)?, num(11..13)?, num(14..16)?);
    let mut i = 19;
    let mut sec = num(17..19)? as f64;
    if b.get(i) == Some(&b'.') {
        let start = i;
        i += 1;
        while i < b.len() && b[i].is_ascii_digit() {
            i += 1;
        }
        if i == start + 1 {
            return Err(bad());
        }
        sec += s[start..i].parse::<f64>().map_err(|_| bad())?;
    }
    let offset = match &s[i..] {
        "Z" | "z" => 0,
        z if z.len() == 6 && (z.starts_with('+') || z.starts_with('-')) && &z[3..4] == ":" => {
            let (zh, zm) = (num(i + 1..i + 3)?, num(i + 4..i + 6)?);
            if zh > 23 || zm > 59 {
                return Err(bad());
            }
            let o = zh * 3600 + zm * 60;
            if z.starts_with('-') { -o } else { o }
        }
        _ => return Err(bad()),
    };
    let leap = (y % 4 == 0 && y % 100 != 0) || y % 400 == 0;
    let dim = [31, if leap { 29 } else { 28 }, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31];
    if !(1..=12).contains(&mo) || d < 1 || d > dim[(mo - 1) as usize] || h > 23 || mi > 59 || sec >= 61.0 {
        return Err(format!("\"{s}\": date or time out of range"));
    }
    Ok((days_from_civil(y, mo, d) * 86_400 + h * 3600 + mi * 60 - offset) as f64 + sec)
}

#[cfg(test)]
mod tests {
    use super::parse_iso8601 as p;
    #[test]
    fn parses_and_rejects() {
        assert_eq!(p("1970-01-01T00:00:00Z").unwrap(), 0.0);
        assert_eq!(p("2026-11-21T10:00:00Z").unwrap(), 1_795_255_200.0);
        assert_eq!(p("2026-11-21T11:00:00+01:00").unwrap(), 1_795_255_200.0);
        assert_eq!(p("2000-02-29T00:00:00.5Z").unwrap(), 951_782_400.5);
        for bad in ["2026-02-29T00:00:00Z", "2026-13-01T00:00:00Z", "2026-11-21 10:00:00Z", "2026-11-21T10:00:00", "yesterday"] {
            assert!(p(bad).is_err(), "{bad}");
        }
    }
}

//! The session's particulars at the top of the page, for the machine's file: the machine and
//! its serial number, the ballbar and its calibration, the temperature, the operator, the date.
//!
//! Each field is read from the runs' headers (a `.b5r` import keeps what the vendor's file says,
//! under the keys of [`FIELDS`]) and may be given or overridden on the command line
//! (`ballbar report … --info KEY=VALUE`). A field nobody knows is printed empty, with a line to
//! fill in by hand, so that the printed page is complete once signed. The keys are listed in
//! `docs/report.md`.

use std::fmt::Write;

use ballbar_model::Run;

use crate::svg::esc;

/// One field of the form.
#[derive(Clone, Copy, Debug)]
pub struct FieldSpec {
    /// The key (`--info KEY=VALUE`), also the run-header key it is read from.
    pub key: &'static str,
    /// Other run-header keys that hold the same field (a `.b5r` run's `run_temperature_c`).
    pub also_from: &'static [&'static str],
    /// The label printed.
    pub label: &'static str,
}

/// The fields, in the order printed.
pub const FIELDS: [FieldSpec; 12] = [
    FieldSpec { key: "machine_name", also_from: &[], label: "machine" },
    FieldSpec { key: "machine_serial", also_from: &[], label: "machine serial number" },
    FieldSpec { key: "location", also_from: &[], label: "location" },
    FieldSpec { key: "ballbar_model", also_from: &[], label: "ballbar" },
    FieldSpec { key: "ballbar_serial", also_from: &[], label: "ballbar serial number" },
    FieldSpec { key: "ballbar_last_calibrated", also_from: &[], label: "ballbar calibrated on" },
    FieldSpec { key: "ballbar_certificate", also_from: &[], label: "calibration certificate" },
    FieldSpec { key: "calibrator_serial", also_from: &[], label: "calibrator serial number" },
    FieldSpec {
        key: "temperature_c",
        also_from: &["run_temperature_c"],
        label: "temperature during the test, °C",
    },
    FieldSpec { key: "operator", also_from: &[], label: "operator" },
    FieldSpec { key: "test_date", also_from: &[], label: "date of the test" },
    FieldSpec { key: "checked_by", also_from: &[], label: "checked by (name, signature)" },
];

/// A field's value and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// Given on the command line.
    Given(String),
    /// Read from the runs' headers (distinct values listed with their runs where they differ).
    FromRuns(String),
    /// Neither given nor in the runs: the archived machine's own name (`machine_name` only).
    FromMachine(String),
    /// Nobody knows it: a line to fill in.
    Unknown,
}

/// Check `--info` pairs: each key one of [`FIELDS`], each at most once, with a value. The
/// message names what is wrong (a usage error of the command).
pub fn check_given(given: &[(String, String)]) -> Result<(), String> {
    for (i, (k, v)) in given.iter().enumerate() {
        if !FIELDS.iter().any(|f| f.key == k) {
            let keys: Vec<&str> = FIELDS.iter().map(|f| f.key).collect();
            return Err(format!(
                "--info {k}=…: unknown key \"{k}\" (the keys: {})",
                keys.join(", ")
            ));
        }
        if v.trim().is_empty() {
            return Err(format!("--info {k}=: no value (leave a field out to print it empty)"));
        }
        if given[..i].iter().any(|(k2, _)| k2 == k) {
            return Err(format!("--info {k} is given twice"));
        }
    }
    Ok(())
}

/// Split `KEY=VALUE` (the command line's `--info`); the key is checked by [`check_given`].
pub fn parse_pair(s: &str) -> Result<(String, String), String> {
    let (k, v) = s.split_once('=').ok_or_else(|| format!("\"{s}\" is not KEY=VALUE"))?;
    Ok((k.trim().to_string(), v.trim().to_string()))
}

/// Each field's value: given on the command line, else what the runs' headers say, else
/// unknown. The date of the test defaults to the first run's start ([`first_start`]); the
/// machine to `machine` (the archived machine spec's name), where there is one.
pub fn fields(
    runs: &[&Run],
    given: &[(String, String)],
    machine: Option<&str>,
) -> Vec<(FieldSpec, Value)> {
    FIELDS
        .iter()
        .map(|f| {
            if let Some((_, v)) = given.iter().find(|(k, _)| k == f.key) {
                return (*f, Value::Given(v.clone()));
            }
            let from_runs =
                if f.key == "test_date" { first_start(runs) } else { from_headers(runs, f) };
            match (from_runs, machine.filter(|m| f.key == "machine_name" && !m.trim().is_empty())) {
                (Some(v), _) => (*f, Value::FromRuns(v)),
                (None, Some(m)) => (*f, Value::FromMachine(m.to_string())),
                (None, None) => (*f, Value::Unknown),
            }
        })
        .collect()
}

/// The values the runs' headers hold for `f`: one value, or each distinct value with its runs.
fn from_headers(runs: &[&Run], f: &FieldSpec) -> Option<String> {
    let mut distinct: Vec<(String, Vec<String>)> = Vec::new();
    for r in runs {
        let v = r
            .header
            .extra
            .iter()
            .find(|(k, _)| k == f.key || f.also_from.contains(&k.as_str()))
            .map(|(_, v)| v.trim().to_string());
        let Some(v) = v.filter(|v| !v.is_empty()) else { continue };
        match distinct.iter_mut().find(|(d, _)| *d == v) {
            Some((_, names)) => names.push(r.name()),
            None => distinct.push((v, vec![r.name()])),
        }
    }
    match distinct.len() {
        0 => None,
        // One value for every run that has one.
        1 => Some(distinct.remove(0).0),
        _ => Some(
            distinct
                .iter()
                .map(|(v, names)| format!("{v} ({})", names.join(", ")))
                .collect::<Vec<_>>()
                .join("; "),
        ),
    }
}

/// The first run's `started_at`, as written (the date of the test by default).
pub fn first_start(runs: &[&Run]) -> Option<String> {
    runs.iter()
        .min_by(|a, b| a.header.started_at_unix_s.total_cmp(&b.header.started_at_unix_s))
        .map(|r| r.header.started_at.clone())
}

/// The value of `key` among `fields`, if known (for the page's title and footer).
pub fn known<'a>(fields: &'a [(FieldSpec, Value)], key: &str) -> Option<&'a str> {
    fields.iter().find(|(f, _)| f.key == key).and_then(|(_, v)| match v {
        Value::Given(s) | Value::FromRuns(s) | Value::FromMachine(s) => Some(s.as_str()),
        Value::Unknown => None,
    })
}

/// A date as a run header writes it, as a person reads it: a vendor's `20240416` (YYYYMMDD)
/// as `2024-04-16`, an RFC 3339 UTC time `2025-09-04T16:10:55.312Z` as `2025-09-04 16:10:55
/// UTC`; anything else (not a valid date of these forms) unchanged.
pub fn readable_date(s: &str) -> String {
    let t = s.trim();
    let digits = |x: &str| !x.is_empty() && x.bytes().all(|b| b.is_ascii_digit());
    let valid = |y: &str, m: &str, d: &str| {
        let (m, d): (u32, u32) = (m.parse().unwrap_or(0), d.parse().unwrap_or(0));
        digits(y) && y.len() == 4 && (1..=12).contains(&m) && (1..=31).contains(&d)
    };
    if t.len() == 8 && digits(t) && valid(&t[..4], &t[4..6], &t[6..]) {
        return format!("{}-{}-{}", &t[..4], &t[4..6], &t[6..]);
    }
    // YYYY-MM-DDTHH:MM:SS[.fff]Z
    let b = t.as_bytes();
    if t.len() >= 20
        && t.ends_with('Z')
        && b[4] == b'-'
        && b[7] == b'-'
        && b[10] == b'T'
        && b[13] == b':'
        && b[16] == b':'
        && valid(&t[..4], &t[5..7], &t[8..10])
        && [&t[11..13], &t[14..16], &t[17..19]].iter().all(|x| digits(x))
        && (t.len() == 20 || (b[19] == b'.' && digits(&t[20..t.len() - 1])))
    {
        return format!("{} {} UTC", &t[..10], &t[11..19]);
    }
    s.to_string()
}

/// The form as a two-column table (two fields per row); where the values came from under it.
pub fn html(h: &mut String, fields: &[(FieldSpec, Value)]) {
    h.push_str(r#"<table id="session-info" class="form">"#);
    for pair in fields.chunks(2) {
        h.push_str("<tr>");
        for (f, v) in pair {
            let (class, text) = match v {
                Value::Given(s) => ("given", esc(s)),
                Value::FromRuns(s) => ("from-runs", esc(&readable_date(s))),
                Value::FromMachine(s) => ("from-machine", esc(s)),
                Value::Unknown => ("fill", String::new()),
            };
            let _ = write!(
                h,
                r#"<th>{}</th><td class="{class}" data-key="{}">{text}</td>"#,
                esc(f.label),
                f.key
            );
        }
        h.push_str("</tr>");
    }
    h.push_str("</table>");
    let given: Vec<&str> =
        fields.iter().filter(|(_, v)| matches!(v, Value::Given(_))).map(|(f, _)| f.key).collect();
    let read: Vec<&str> = fields
        .iter()
        .filter(|(_, v)| matches!(v, Value::FromRuns(_)))
        .map(|(f, _)| f.key)
        .collect();
    let mut said = Vec::new();
    if !read.is_empty() {
        said.push(format!("from the runs' headers: {}", read.join(", ")));
    }
    if !given.is_empty() {
        said.push(format!("given with --info: {}", given.join(", ")));
    }
    let machine: Vec<&str> = fields
        .iter()
        .filter(|(_, v)| matches!(v, Value::FromMachine(_)))
        .map(|(f, _)| f.key)
        .collect();
    if !machine.is_empty() {
        said.push(format!("from the archived machine's description: {}", machine.join(", ")));
    }
    if fields.iter().any(|(_, v)| *v == Value::Unknown) {
        said.push("empty fields: not in the runs, to fill in by hand (or give them with --info KEY=VALUE)".into());
    }
    let _ = write!(h, r#"<p class="form-note">{}.</p>"#, esc(&said.join("; ")));
}

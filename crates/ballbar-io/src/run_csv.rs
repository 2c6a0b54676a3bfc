//! The run CSV, version 1 (`shared/spec/run-format.md`): strict reader, writer, and the copy
//! with one more column that `predict` writes.

use std::path::{Path, PathBuf};

use ballbar_model::{Axis, Direction, Plane, Run, RunHeader};

use crate::IoError;

/// Largest allowed mismatch between the radius and the axis coordinates, mm (the spec's).
const RADIUS_TOLERANCE_MM: f64 = 1.0;

fn line_err(path: &Path, line: usize, message: impl Into<String>) -> IoError {
    IoError::Line { path: path.to_path_buf(), line, message: message.into() }
}

/// Read a run file.
pub fn read_run(path: &Path) -> Result<Run, IoError> {
    let text = std::fs::read_to_string(path).map_err(|source| IoError::Io { path: path.to_path_buf(), source })?;
    parse_run(&text, &path.to_string_lossy())
}

fn parse_triple(v: &str) -> Option<[f64; 3]> {
    let parts: Vec<&str> = v.split(',').map(str::trim).collect();
    if parts.len() != 3 {
        return None;
    }
    let mut out = [0.0; 3];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p.parse::<f64>().ok().filter(|x| x.is_finite())?;
    }
    Some(out)
}

/// Parse run-CSV text; `source` names the file in messages.
pub fn parse_run(text: &str, source: &str) -> Result<Run, IoError> {
    let path = PathBuf::from(source);
    let p = path.as_path();
    let lines: Vec<&str> = text.split('\n').map(|l| l.strip_suffix('\r').unwrap_or(l)).collect();
    let mut keys: Vec<(String, String, usize)> = Vec::new();
    let mut idx = 0;
    // Header.
    while idx < lines.len() && lines[idx].starts_with('#') {
        let ln = idx + 1;
        let body = lines[idx][1..].trim_start();
        let (k, v) = body
            .split_once(':')
            .ok_or_else(|| line_err(p, ln, format!("header line must be '# key: value', got \"{}\"", lines[idx])))?;
        let (k, v) = (k.trim(), v.trim());
        if k.is_empty() || k.chars().any(|c| c.is_uppercase() || c.is_whitespace()) {
            return Err(line_err(p, ln, format!("header key \"{k}\" must be lower case without spaces")));
        }
        if keys.iter().any(|(kk, _, _)| kk == k) {
            return Err(line_err(p, ln, format!("header key \"{k}\" appears twice")));
        }
        keys.push((k.to_string(), v.to_string(), ln));
        idx += 1;
    }
    let column_line = idx + 1;
    if idx >= lines.len() || lines[idx].trim().is_empty() {
        return Err(line_err(p, column_line, "expected the column line (t_s,...,dR_um) after the header"));
    }
    let get = |k: &str| keys.iter().find(|(kk, _, _)| kk == k).map(|(_, v, l)| (v.as_str(), *l));
    let require = |k: &str| get(k).ok_or_else(|| line_err(p, column_line, format!("the header has no required key \"{k}\"")));
    let (ver, vl) = require("ballbar-run")?;
    let format_version: u32 = ver
        .parse()
        .map_err(|_| line_err(p, vl, format!("ballbar-run version \"{ver}\" is not a number")))?;
    if format_version != 1 {
        return Err(line_err(p, vl, format!("ballbar-run version {format_version} is not supported (this reader knows 1)")));
    }
    let (pl, pll) = require("plane")?;
    let plane = Plane::from_name(pl).ok_or_else(|| line_err(p, pll, format!("plane \"{pl}\" must be XY, YZ, ZX or free")))?;
    let direction = match get("direction") {
        Some((d, dl)) => Some(Direction::from_name(d).ok_or_else(|| line_err(p, dl, format!("direction \"{d}\" must be CW or CCW")))?),
        None if plane == Plane::Free => None,
        None => return Err(line_err(p, column_line, "the header has no required key \"direction\"")),
    };
    let positive = |k: &str| -> Result<f64, IoError> {
        let (v, l) = require(k)?;
        v.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite() && *x > 0.0)
            .ok_or_else(|| line_err(p, l, format!("{k} \"{v}\" must be a positive number")))
    };
    let radius_mm = positive("radius_mm")?;
    let feed_mm_per_min = positive("feed_mm_per_min")?;
    let triple = |k: &str, required: bool| -> Result<[f64; 3], IoError> {
        match get(k) {
            Some((v, l)) => parse_triple(v).ok_or_else(|| line_err(p, l, format!("{k} \"{v}\" must be three finite numbers separated by commas"))),
            None if required => Err(line_err(p, column_line, format!("the header has no required key \"{k}\""))),
            None => Ok([0.0; 3]),
        }
    };
    let pivot_mm = triple("pivot_mm", true)?;
    let table_ball_mm = triple("table_ball_mm", false)?;
    let tool_ball_mm = triple("tool_ball_mm", false)?;
    let (started_at, sl) = require("started_at")?;
    let started_at_unix_s = crate::time::parse_iso8601(started_at).map_err(|m| line_err(p, sl, format!("started_at: {m}")))?;
    const KNOWN: [&str; 11] = [
        "ballbar-run", "machine", "plane", "direction", "radius_mm", "feed_mm_per_min", "pivot_mm", "table_ball_mm", "tool_ball_mm",
        "started_at", "run_id",
    ];
    let header = RunHeader {
        format_version,
        machine: get("machine").map(|(v, _)| v.to_string()),
        plane,
        direction,
        radius_mm,
        feed_mm_per_min,
        pivot_mm,
        table_ball_mm,
        tool_ball_mm,
        started_at: started_at.to_string(),
        started_at_unix_s,
        run_id: get("run_id").map(|(v, _)| v.to_string()),
        extra: keys.iter().filter(|(k, _, _)| !KNOWN.contains(&k.as_str())).map(|(k, v, _)| (k.clone(), v.clone())).collect(),
    };
    // Columns.
    let names: Vec<&str> = lines[idx].split(',').map(str::trim).collect();
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(line_err(p, column_line, format!("column \"{n}\" appears twice")));
        }
    }
    let find = |n: &str| names.iter().position(|c| *c == n);
    let t_col = find("t_s").ok_or_else(|| line_err(p, column_line, "the column line has no t_s column"))?;
    let dr_col = find("dR_um").ok_or_else(|| line_err(p, column_line, "the column line has no dR_um column"))?;
    let axis_cols: Vec<(Axis, usize)> = Axis::ALL.iter().filter_map(|&a| find(a.column_name()).map(|c| (a, c))).collect();
    if axis_cols.is_empty() {
        return Err(line_err(p, column_line, "the column line has no axis column (X_mm, Y_mm, Z_mm, A_deg, B_deg, C_deg)"));
    }
    if let Some((u, v, _)) = plane.axes() {
        for a in [u, v] {
            if !axis_cols.iter().any(|(b, _)| *b == a) {
                return Err(line_err(p, column_line, format!("a {plane} test needs the column {}", a.column_name())));
            }
        }
    }
    // Samples.
    let mut end = lines.len();
    if end > idx + 1 && lines[end - 1].is_empty() {
        end -= 1; // the final newline
    }
    let n = end - idx - 1;
    let mut t_s = Vec::with_capacity(n);
    let mut dr_mm = Vec::with_capacity(n);
    let mut cols: Vec<Vec<f64>> = axis_cols.iter().map(|_| Vec::with_capacity(n)).collect();
    let mut line_nos = Vec::with_capacity(n);
    let mut fields: Vec<&str> = Vec::with_capacity(names.len());
    for (k, line) in lines[idx + 1..end].iter().enumerate() {
        let ln = idx + 2 + k;
        if line.trim().is_empty() {
            return Err(line_err(p, ln, "blank line among the samples"));
        }
        if line.starts_with('#') {
            return Err(line_err(p, ln, "header line after the column line"));
        }
        fields.clear();
        fields.extend(line.split(','));
        if fields.len() != names.len() {
            return Err(line_err(p, ln, format!("{} fields, but the column line has {}", fields.len(), names.len())));
        }
        let num = |c: usize| -> Result<f64, IoError> {
            let f = fields[c].trim();
            f.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| line_err(p, ln, format!("column {}: \"{f}\" is not a finite number", names[c])))
        };
        let t = num(t_col)?;
        if let Some(&prev) = t_s.last() {
            if t <= prev {
                return Err(line_err(p, ln, format!("t_s {t} does not increase (previous {prev})")));
            }
        }
        t_s.push(t);
        dr_mm.push(num(dr_col)? * 1e-3);
        for ((a, c), col) in axis_cols.iter().zip(cols.iter_mut()) {
            let v = num(*c)?;
            col.push(if a.is_rotary() { v.to_radians() } else { v });
        }
        if plane != Plane::Free {
            let mut d2 = 0.0;
            for a in Axis::LINEAR {
                let q = axis_cols.iter().position(|(b, _)| *b == a).map(|j| cols[j][k]).unwrap_or(pivot_mm[a.index()]);
                d2 += (q - pivot_mm[a.index()]).powi(2);
            }
            let r = d2.sqrt();
            if (r - radius_mm).abs() > RADIUS_TOLERANCE_MM {
                return Err(line_err(p, ln, format!("the axis coordinates lie {r:.3} mm from the pivot, but radius_mm is {radius_mm}")));
            }
        }
        line_nos.push(ln as u32);
    }
    if t_s.len() < 3 {
        return Err(line_err(p, end.max(column_line), format!("a run needs at least 3 samples, this one has {}", t_s.len())));
    }
    let mut axes: [Option<Vec<f64>>; 6] = Default::default();
    for ((a, _), col) in axis_cols.iter().zip(cols) {
        axes[a.index()] = Some(col);
    }
    Ok(Run { header, source: source.to_string(), t_s, axes, dr_mm, lines: line_nos })
}

fn fmt_num(x: f64) -> String {
    format!("{x}")
}

/// The run as run-CSV text.
pub fn format_run(run: &Run) -> String {
    use std::fmt::Write;
    let h = &run.header;
    let mut s = String::with_capacity(64 * (run.len() + 16));
    let triple = |v: [f64; 3]| format!("{}, {}, {}", fmt_num(v[0]), fmt_num(v[1]), fmt_num(v[2]));
    let _ = writeln!(s, "# ballbar-run: {}", h.format_version);
    if let Some(m) = &h.machine {
        let _ = writeln!(s, "# machine: {m}");
    }
    let _ = writeln!(s, "# plane: {}", h.plane);
    if let Some(d) = h.direction {
        let _ = writeln!(s, "# direction: {d}");
    }
    let _ = writeln!(s, "# radius_mm: {}", fmt_num(h.radius_mm));
    let _ = writeln!(s, "# feed_mm_per_min: {}", fmt_num(h.feed_mm_per_min));
    let _ = writeln!(s, "# pivot_mm: {}", triple(h.pivot_mm));
    let _ = writeln!(s, "# table_ball_mm: {}", triple(h.table_ball_mm));
    let _ = writeln!(s, "# tool_ball_mm: {}", triple(h.tool_ball_mm));
    let _ = writeln!(s, "# started_at: {}", h.started_at);
    if let Some(id) = &h.run_id {
        let _ = writeln!(s, "# run_id: {id}");
    }
    for (k, v) in &h.extra {
        let _ = writeln!(s, "# {k}: {v}");
    }
    let present: Vec<Axis> = Axis::ALL.into_iter().filter(|a| run.axis(*a).is_some()).collect();
    s.push_str("t_s");
    for a in &present {
        s.push(',');
        s.push_str(a.column_name());
    }
    s.push_str(",dR_um\n");
    for i in 0..run.len() {
        let _ = write!(s, "{:.6}", run.t_s[i]);
        for a in &present {
            let v = run.axis(*a).expect("present")[i];
            if a.is_rotary() {
                let _ = write!(s, ",{:.7}", v.to_degrees());
            } else {
                let _ = write!(s, ",{v:.6}");
            }
        }
        let _ = writeln!(s, ",{:.4}", run.dr_mm[i] * 1e3);
    }
    s
}

/// Write a run file atomically.
pub fn write_run(run: &Run, path: &Path) -> Result<(), IoError> {
    crate::atomic::write_atomic(path, format_run(run).as_bytes())
}

/// A copy of run-CSV `text` with column `name` appended (or, if present, replaced) holding
/// `values_um` (4 decimals); every other byte of every line is kept.
pub fn append_column(text: &str, source: &str, name: &str, values_um: &[f64]) -> Result<String, IoError> {
    let p = Path::new(source);
    let mut out = String::with_capacity(text.len() + values_um.len() * 12);
    let mut in_header = true;
    let mut replace: Option<usize> = None;
    let mut k = 0;
    for (i, raw) in text.split_inclusive('\n').enumerate() {
        let (line, eol) = match raw.strip_suffix("\r\n") {
            Some(l) => (l, "\r\n"),
            None => match raw.strip_suffix('\n') {
                Some(l) => (l, "\n"),
                None => (raw, ""),
            },
        };
        if in_header && line.starts_with('#') {
            out.push_str(raw);
            continue;
        }
        if line.is_empty() {
            out.push_str(raw);
            continue;
        }
        let mut fields: Vec<String> = line.split(',').map(str::to_string).collect();
        if in_header {
            in_header = false;
            replace = fields.iter().position(|f| f.trim() == name);
            if replace.is_none() {
                fields.push(name.to_string());
            }
        } else {
            let v = values_um
                .get(k)
                .ok_or_else(|| line_err(p, i + 1, format!("more samples than the {} model values", values_um.len())))?;
            let val = format!("{v:.4}");
            match replace {
                Some(c) if c < fields.len() => fields[c] = val,
                _ => fields.push(val),
            }
            k += 1;
        }
        out.push_str(&fields.join(","));
        out.push_str(eol);
    }
    if k != values_um.len() {
        return Err(line_err(p, 0, format!("{k} samples but {} model values", values_um.len())));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = "# ballbar-run: 1\n# machine: column\n# plane: XY\n# direction: CCW\n# radius_mm: 100\n# feed_mm_per_min: 1000\n# pivot_mm: 300, 200, -300\n# table_ball_mm: 0, 0, 50\n# tool_ball_mm: 0, 0, -100\n# started_at: 2026-11-21T10:00:00Z\n# run_id: xy-ccw-1\nt_s,X_mm,Y_mm,Z_mm,dR_um\n0.000,400.000000,200.000000,-300.000000,0.512\n0.004,399.999998,200.020944,-300.000000,0.498\n0.008,399.999991,200.041888,-300.000000,0.470\n";

    fn err(text: &str) -> String {
        parse_run(text, "runs/x.csv").unwrap_err().to_string()
    }

    #[test]
    fn the_spec_example_parses() {
        let r = parse_run(GOOD, "x.csv").unwrap();
        assert_eq!(r.len(), 3);
        assert_eq!(r.header.plane, Plane::XY);
        assert_eq!(r.header.direction, Some(Direction::CCW));
        assert!((r.dr_mm[0] - 0.512e-3).abs() < 1e-15);
        assert_eq!(r.lines, vec![13, 14, 15]);
        assert_eq!(r.header.run_id.as_deref(), Some("xy-ccw-1"));
    }

    #[test]
    fn round_trip_with_a_rotary_axis_and_crlf() {
        let mut r = parse_run(GOOD, "x.csv").unwrap();
        r.axes[Axis::C.index()] = Some(vec![0.1, 0.2, 0.3]);
        r.header.extra.push(("operator".into(), "A. N. Other".into()));
        let text = format_run(&r);
        let back = parse_run(&text.replace('\n', "\r\n"), "x.csv").unwrap();
        assert_eq!(back.header, r.header);
        for a in Axis::ALL {
            match (r.axis(a), back.axis(a)) {
                (Some(x), Some(y)) => {
                    for (p, q) in x.iter().zip(y) {
                        assert!((p - q).abs() < 1e-8, "{a}");
                    }
                }
                (None, None) => {}
                _ => panic!("axis {a} lost"),
            }
        }
        for (p, q) in r.dr_mm.iter().zip(&back.dr_mm) {
            assert!((p - q).abs() < 1e-7 * 1e-3 + 1e-12);
        }
        assert_eq!(back.t_s, r.t_s);
    }

    #[test]
    fn every_malformed_case_names_file_line_and_problem() {
        let cases: Vec<(String, &str, &str)> = vec![
            (GOOD.replace("# ballbar-run: 1\n", ""), "x.csv:11", "ballbar-run"),
            (GOOD.replace("ballbar-run: 1", "ballbar-run: 2"), "x.csv:1", "not supported"),
            (GOOD.replace("# plane: XY\n", ""), "x.csv:11", "\"plane\""),
            (GOOD.replace("plane: XY", "plane: XZ"), "x.csv:3", "plane"),
            (GOOD.replace("# direction: CCW\n", ""), "x.csv:11", "direction"),
            (GOOD.replace("direction: CCW", "direction: ccw"), "x.csv:4", "CW or CCW"),
            (GOOD.replace("radius_mm: 100", "radius_mm: -1"), "x.csv:5", "positive"),
            (GOOD.replace("feed_mm_per_min: 1000", "feed_mm_per_min: fast"), "x.csv:6", "positive"),
            (GOOD.replace("pivot_mm: 300, 200, -300", "pivot_mm: 300, 200"), "x.csv:7", "three"),
            (GOOD.replace("started_at: 2026-11-21T10:00:00Z", "started_at: tomorrow"), "x.csv:10", "ISO 8601"),
            (GOOD.replace("# machine: column", "# Machine: column"), "x.csv:2", "lower case"),
            (GOOD.replace("# run_id: xy-ccw-1", "# plane: XY"), "x.csv:11", "twice"),
            (GOOD.replace("t_s,X_mm", "time,X_mm"), "x.csv:12", "t_s"),
            (GOOD.replace(",dR_um", ",dr"), "x.csv:12", "dR_um"),
            (GOOD.replace("t_s,X_mm,Y_mm", "t_s,X_mm,Q_mm"), "x.csv:12", "Y_mm"),
            (GOOD.replace("0.004,399.999998", "0.004,abc"), "x.csv:14", "X_mm"),
            (GOOD.replace("0.004,399.999998", "0.004,NaN"), "x.csv:14", "finite"),
            (GOOD.replace(",0.498", ",inf"), "x.csv:14", "finite"),
            (GOOD.replace(",0.498", ","), "x.csv:14", "dR_um"),
            (GOOD.replace("0.004,", "0.000,"), "x.csv:14", "does not increase"),
            (GOOD.replace(",0.498", ",0.498,7"), "x.csv:14", "fields"),
            (GOOD.replace("0.004,399.999998", "0.004,390.0"), "x.csv:14", "from the pivot"),
            (GOOD.replace("0.008,", "\n0.008,"), "x.csv:15", "blank"),
            (GOOD.replace("0.008,", "# note\n0.008,"), "x.csv:15", "header line after"),
            (GOOD.replace("0.008,399.999991,200.041888,-300.000000,0.470\n", "").replace("0.004,399.999998,200.020944,-300.000000,0.498\n", ""), "x.csv:", "at least 3"),
        ];
        for (text, at, what) in cases {
            let e = parse_run(&text, "x.csv").unwrap_err().to_string();
            assert!(e.starts_with(at) && e.contains(what), "expected {at} … {what}, got: {e}");
        }
        assert!(err("").contains("runs/x.csv"));
    }

    #[test]
    fn append_column_keeps_every_other_byte_and_replaces_an_existing_column() {
        let crlf = GOOD.replace('\n', "\r\n");
        let out = append_column(&crlf, "x.csv", "dR_model_um", &[1.0, 2.0, 3.5]).unwrap();
        assert!(out.contains("t_s,X_mm,Y_mm,Z_mm,dR_um,dR_model_um\r\n"));
        assert!(out.contains("0.000,400.000000,200.000000,-300.000000,0.512,1.0000\r\n"));
        assert!(out.starts_with("# ballbar-run: 1\r\n# machine: column\r\n"));
        let again = append_column(&out, "x.csv", "dR_model_um", &[4.0, 5.0, 6.0]).unwrap();
        assert!(again.contains(",0.512,4.0000\r\n") && !again.contains("dR_model_um,dR_model_um"));
        assert!(append_column(GOOD, "x.csv", "m", &[1.0]).is_err());
        let parsed = parse_run(&again, "x.csv").unwrap();
        assert_eq!(parsed.len(), 3);
    }

    #[test]
    fn atomic_write_leaves_no_temporary_and_reports_a_missing_folder() {
        let dir = std::env::temp_dir().join(format!("ballbar-io-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("run.csv");
        write_run(&parse_run(GOOD, "x.csv").unwrap(), &f).unwrap();
        assert!(read_run(&f).is_ok());
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let e = write_run(&parse_run(GOOD, "x.csv").unwrap(), &dir.join("nope/run.csv")).unwrap_err();
        assert!(e.to_string().contains("nope"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

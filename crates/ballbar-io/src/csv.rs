//! The run CSV, version 1 (`shared/spec/run-format.md`): a strict reader, the writer, and the
//! copy with one more column that `ballbar predict` writes.
//!
//! Units are converted here and nowhere else: the file holds mm, degrees, s and µm (`dR_um`);
//! a [`Run`] holds mm, radians, s and mm.
//!
//! The reader and [`append_column`] share the line handling (line ends, the end of the header,
//! the structure of a sample line); the reader parses the fields and leaves the checks of the
//! values (increasing times, the radius, the number of samples) to [`crate::check::check_run`],
//! which every importer calls too.

use std::collections::{HashMap, HashSet};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use ballbar_model::{Axis, Direction, Plane, Run, RunHeader};

use crate::IoError;
use crate::atomic::Existing;

/// The format version this module reads and writes (`# ballbar-run: 1`).
pub const FORMAT_VERSION: u32 = 1;

pub use crate::check::{MIN_SAMPLES, RADIUS_TOLERANCE_MM};

/// Most columns a run file may have. The reader knows eight (`t_s`, six axes, `dR_um`); the
/// others it keeps unread are a few (`dR_model_um` from `ballbar predict`, a note): a column
/// line of hundreds of names is not a run file, and is refused before anything else is read.
pub const MAX_COLUMNS: usize = 256;

/// Most header lines a run file may have. Version 1 has 11 keys and `ballbar import` adds
/// about 35 that say where a run came from.
pub const MAX_HEADER_LINES: usize = 1024;

/// Longest line of a run file, bytes. A sample line of [`MAX_COLUMNS`] numbers written in full
/// is under 7 kB; a header value is a name, a date or a short comment.
pub const MAX_LINE_BYTES: usize = 65_536;

/// Longest `run_id`, bytes. A run id names files (`<run-id>.csv` from `export`, `<run-id>.nc`
/// from `program`), and a file name has at most 255 bytes on the common file systems.
pub const MAX_RUN_ID_BYTES: usize = 240;

/// Longest piece of a file's text that an error message quotes, characters: enough to
/// recognise it; a longer text is shortened with `…`.
const QUOTED_CHARS: usize = 60;

/// `text` quoted for an error message (as `{:?}` does), shortened to [`QUOTED_CHARS`]
/// characters with `…` when longer, so that a message about a long line stays one line.
pub(crate) fn quoted(text: &str) -> String {
    match text.char_indices().nth(QUOTED_CHARS) {
        None => format!("{text:?}"),
        Some((end, _)) => format!("{:?}…", &text[..end]),
    }
}

/// The header keys of version 1, in the order the writer writes them.
const KNOWN_KEYS: [&str; 11] = [
    "ballbar-run",
    "machine",
    "plane",
    "direction",
    "radius_mm",
    "feed_mm_per_min",
    "pivot_mm",
    "table_ball_mm",
    "tool_ball_mm",
    "started_at",
    "run_id",
];

/// Spaces and tabs around fields and values are not part of them.
pub(crate) fn trim(s: &str) -> &str {
    s.trim_matches([' ', '\t'])
}

/// Whether `c` ends a line for some reader: besides `\n` and `\r`, Python's `splitlines` and
/// many spreadsheets end lines at VT, FF, FS, GS, RS, NEL and the Unicode line and paragraph
/// separators.
pub(crate) fn is_line_break(c: char) -> bool {
    matches!(
        c,
        '\n' | '\r' | '\u{0b}' | '\u{0c}' | '\u{1c}'
            ..='\u{1e}' | '\u{85}' | '\u{2028}' | '\u{2029}'
    )
}

/// Why `value` cannot be a header value: a header value is one line without control characters
/// (a tab excepted), so that every reader sees the same lines. Header values are refused, not
/// escaped: the format has no escapes, and a backslash in a value (a Windows path) means itself.
pub fn header_value_problem(value: &str) -> Option<String> {
    let c = value.chars().find(|&c| is_line_break(c) || (c.is_control() && c != '\t'))?;
    let name = match c {
        '\n' => "a line feed, ",
        '\r' => "a carriage return, ",
        '\u{0b}' => "a vertical tab, ",
        '\u{0c}' => "a form feed, ",
        '\u{85}' => "a next-line character, ",
        '\u{2028}' => "a line separator, ",
        '\u{2029}' => "a paragraph separator, ",
        _ => "",
    };
    let what = if is_line_break(c) { "a line break" } else { "a control character" };
    Some(format!(
        "contains {what} ({name}U+{:04X}); a header value is one line without control characters",
        u32::from(c)
    ))
}

/// `text` as one header value: its lines (split at every line break) trimmed and joined by
/// " / ", empty ones left out, and any other control character a space. For text that another
/// program wrote (a `.b5r` file's operator or comment), which a run keeps in its header.
pub(crate) fn one_line(text: &str) -> String {
    text.split(is_line_break)
        .map(|l| l.chars().map(|c| if c.is_control() { ' ' } else { c }).collect::<String>())
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.trim().to_string())
        .collect::<Vec<_>>()
        .join(" / ")
}

/// One line of the text: its content without the line end, and the line end.
#[derive(Clone, Copy)]
pub(crate) struct Line<'a> {
    /// The line without its line end.
    pub(crate) text: &'a str,
    /// `"\r\n"`, `"\n"`, or for a last line without `\n`, `"\r"` or `""` (a `\r` before the
    /// end of the text ends a line too).
    pub(crate) end: &'a str,
}

/// The text's lines. A final line end does not start another line; any other empty line is
/// kept (and is an error where it is not allowed). Concatenating every line's `text` and `end`
/// gives the text back.
pub(crate) fn split_lines(text: &str) -> Vec<Line<'_>> {
    let mut lines = Vec::with_capacity(text.bytes().filter(|&b| b == b'\n').count() + 1);
    lines.extend(text.split_inclusive('\n').map(|raw| {
        let (text, end) = split_line_end(raw);
        Line { text, end }
    }));
    lines
}

/// The index of the first line that is not a header (`#`) line: the column line if the text
/// has one.
fn header_end(lines: &[Line]) -> usize {
    lines.iter().position(|l| !l.text.starts_with('#')).unwrap_or(lines.len())
}

/// The column line, at index `idx` (from [`header_end`]): an error if the text ends before it
/// or it is blank.
fn column_line<'a>(lines: &[Line<'a>], idx: usize, err: &Errors) -> Result<&'a str, IoError> {
    match lines.get(idx) {
        None => Err(err.format(idx + 1, "the file ends before the column line (t_s,...,dR_um)")),
        Some(l) if trim(l.text).is_empty() => Err(err.format(
            idx + 1,
            "blank line where the column line (t_s,...,dR_um) should follow the header",
        )),
        Some(l) => Ok(l.text),
    }
}

/// The structure of a sample line `ln`: not blank, not a `#` line, as many fields as the column
/// line (line `column_line`, `n_columns` names).
fn check_sample_line(
    line: &str,
    ln: usize,
    column_line: usize,
    n_columns: usize,
    err: &Errors,
) -> Result<(), IoError> {
    if trim(line).is_empty() {
        return Err(
            err.format(ln, "blank line; the samples run to the end of the file without gaps")
        );
    }
    if line.starts_with('#') {
        return Err(err.format(ln, "a '#' line after the column line; header lines come before it"));
    }
    let fields = line.bytes().filter(|&b| b == b',').count() + 1;
    if fields != n_columns {
        return Err(err.format(
            ln,
            format!("{fields} fields, but the column line (line {column_line}) has {n_columns}"),
        ));
    }
    Ok(())
}

/// Line `ln` is not longer than [`MAX_LINE_BYTES`].
fn check_line_length(line: &str, ln: usize, err: &Errors) -> Result<(), IoError> {
    if line.len() > MAX_LINE_BYTES {
        return Err(err.format(
            ln,
            format!(
                "the line is {} bytes long; a run file's lines are at most {MAX_LINE_BYTES} bytes",
                line.len()
            ),
        ));
    }
    Ok(())
}

/// A number field: trimmed of spaces, `.` as decimal point, finite. `Err` says what is wrong.
pub(crate) fn number(field: &str) -> Result<f64, String> {
    let f = trim(field);
    if f.is_empty() {
        return Err("the value is missing".into());
    }
    match f.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err(format!("{} is not a finite number", quoted(f))),
        Err(_) => Err(format!("{} is not a number", quoted(f))),
    }
}

/// Why a header key is not a valid key: `Some(true)` for upper case, `Some(false)` for other
/// characters; `None` if valid (ASCII lower-case letters, digits, `_` and `-`).
fn key_problem(key: &str) -> Option<bool> {
    if key.chars().any(char::is_uppercase) {
        return Some(true);
    }
    let valid = !key.is_empty()
        && key
            .bytes()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == b'_' || c == b'-');
    (!valid).then_some(false)
}

/// A header line `# key: value` (spaces around key and value are not part of them).
struct HeaderLine<'a> {
    key: &'a str,
    value: &'a str,
    line: usize,
}

/// What a column of the file holds.
#[derive(Clone, Copy, PartialEq)]
enum Column {
    Time,
    Dr,
    Axis(Axis),
    /// A column this reader does not know: kept in the file, not parsed.
    Other,
}

/// Builds the errors of one file.
struct Errors<'a> {
    path: &'a Path,
}

impl Errors<'_> {
    fn path(&self) -> PathBuf {
        self.path.to_path_buf()
    }
    fn format(&self, line: usize, message: impl Into<String>) -> IoError {
        IoError::Format { path: self.path(), line, message: message.into() }
    }
    fn header(&self, h: &HeaderLine, message: impl Into<String>) -> IoError {
        IoError::Header {
            path: self.path(),
            line: h.line,
            key: h.key.to_string(),
            message: message.into(),
        }
    }
    fn missing(&self, line: usize, keys: Vec<String>) -> IoError {
        IoError::MissingKey { path: self.path(), line, keys }
    }
    fn columns(&self, line: usize, message: impl Into<String>) -> IoError {
        IoError::Columns { path: self.path(), line, message: message.into() }
    }
    fn sample(&self, line: usize, column: &str, message: impl Into<String>) -> IoError {
        IoError::Sample {
            path: self.path(),
            line,
            column: column.to_string(),
            message: message.into(),
        }
    }
}

/// Read a run file. `Run::source` is `path` as given.
pub fn read_run(path: &Path) -> Result<Run, IoError> {
    parse_run(&read_text(path)?, &path.to_string_lossy())
}

/// The text of a file; text that is not UTF-8 is an error at the line of the first bad byte.
pub(crate) fn read_text(path: &Path) -> Result<String, IoError> {
    let bytes =
        std::fs::read(path).map_err(|error| IoError::Io { path: path.to_path_buf(), error })?;
    String::from_utf8(bytes).map_err(|e| {
        let bytes = e.as_bytes();
        let line =
            1 + bytes[..e.utf8_error().valid_up_to()].iter().filter(|&&b| b == b'\n').count();
        IoError::Format { path: path.to_path_buf(), line, message: "the text is not UTF-8".into() }
    })
}

/// Parse run-CSV text. `source` names the file in error messages and becomes `Run::source`.
///
/// Strict: every departure from the spec is an error naming `source`, the 1-based line and what
/// is wrong; nothing is skipped. A UTF-8 byte-order mark at the start is accepted. Errors of
/// structure and parsing come first, in the order of the lines; then the run is checked with
/// [`crate::check::check_run`] (increasing times, the radius, the number of samples).
pub fn parse_run(text: &str, source: &str) -> Result<Run, IoError> {
    let err = Errors { path: Path::new(source) };
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let lines = split_lines(text);
    if lines.is_empty() {
        return Err(err.format(1, "the file is empty"));
    }

    // Header lines, up to the column line.
    let idx = header_end(&lines);
    let mut entries: Vec<HeaderLine> = Vec::with_capacity(idx.min(MAX_HEADER_LINES));
    // Each key's first line, for keys given twice.
    let mut first_line: HashMap<&str, usize> = HashMap::with_capacity(idx.min(MAX_HEADER_LINES));
    for (i, line) in lines[..idx].iter().enumerate() {
        if i == MAX_HEADER_LINES {
            return Err(err.format(
                i + 1,
                format!(
                    "more than {MAX_HEADER_LINES} header lines; a run file's header is shorter"
                ),
            ));
        }
        check_line_length(line.text, i + 1, &err)?;
        let h = parse_header_line(line.text, i + 1, &err)?;
        if let Some(first) = first_line.insert(h.key, h.line) {
            return Err(err.header(&h, format!("given twice (first on line {first})")));
        }
        if h.key == "ballbar-run" && h.value != "1" {
            let message = format!(
                "format version {} is not supported (this reader reads version {FORMAT_VERSION})",
                quoted(h.value)
            );
            return Err(err.header(&h, message));
        }
        entries.push(h);
    }
    let column_text = column_line(&lines, idx, &err)?;
    let column_line = idx + 1;
    check_line_length(column_text, column_line, &err)?;
    let header = parse_header(&entries, column_line, &err)?;

    // The column line.
    let names: Vec<&str> = column_text.split(',').map(trim).collect();
    let kinds = parse_columns(&names, header.plane, column_line, &err)?;
    let present: Vec<Axis> =
        Axis::ALL.into_iter().filter(|a| kinds.contains(&Column::Axis(*a))).collect();

    // Samples: their structure and fields here, their values in check_run.
    let first = idx + 1;
    let n = lines.len() - first;
    let mut t_s: Vec<f64> = Vec::with_capacity(n);
    let mut dr_mm: Vec<f64> = Vec::with_capacity(n);
    let mut cols: [Vec<f64>; 6] = Default::default();
    for a in &present {
        cols[a.index()].reserve_exact(n);
    }
    let mut line_numbers: Vec<u32> = Vec::with_capacity(n);
    for (k, line) in lines[first..].iter().enumerate() {
        let ln = first + k + 1;
        check_line_length(line.text, ln, &err)?;
        check_sample_line(line.text, ln, column_line, names.len(), &err)?;
        for (field, kind) in line.text.split(',').zip(&kinds) {
            match *kind {
                Column::Other => {}
                Column::Time => t_s.push(number(field).map_err(|m| err.sample(ln, "t_s", m))?),
                Column::Dr => {
                    dr_mm.push(number(field).map_err(|m| err.sample(ln, "dR_um", m))? * 1e-3)
                }
                Column::Axis(a) => {
                    let v = number(field).map_err(|m| err.sample(ln, a.column_name(), m))?;
                    cols[a.index()].push(if a.is_rotary() { v.to_radians() } else { v });
                }
            }
        }
        line_numbers.push(u32::try_from(ln).unwrap_or(u32::MAX));
    }
    let axes = std::array::from_fn(|i| {
        present.contains(&Axis::ALL[i]).then(|| std::mem::take(&mut cols[i]))
    });
    let run = Run { header, source: source.to_string(), t_s, axes, dr_mm, lines: line_numbers };
    let unterminated = match lines[first..] {
        [.., before, last] if last.end.is_empty() => Some(crate::check::Unterminated {
            last: last.text,
            before: before.text,
            columns: &names,
        }),
        _ => None,
    };
    // What the data say against a header key is an error at the key's line.
    crate::check::check_run_text(&run, lines.len(), unterminated).map_err(|e| match e {
        IoError::Setup { path, key, message } => match entries.iter().find(|h| h.key == key) {
            Some(h) => IoError::Header { path, line: h.line, key, message },
            None => IoError::Setup { path, key, message },
        },
        e => e,
    })?;
    Ok(with_normal_axis_at_pivot(run))
}

/// A planar run's axis normal to its plane, when the file has no column for it, sits at the
/// pivot (the contract's radius check reads it so): the run is given that constant column, as
/// a `.b5r` run and a plain table are, so that a machine with that axis can evaluate it.
fn with_normal_axis_at_pivot(mut run: Run) -> Run {
    if let Some((_, _, w)) = run.header.plane.axes()
        && run.axes[w.index()].is_none()
    {
        run.axes[w.index()] = Some(vec![run.header.pivot_mm[w.index()]; run.len()]);
    }
    run
}

/// Split a `#` line into key and value, checking the key's spelling.
fn parse_header_line<'a>(
    line: &'a str,
    ln: usize,
    err: &Errors,
) -> Result<HeaderLine<'a>, IoError> {
    let body = line.strip_prefix('#').unwrap_or(line);
    let not_key_value = || {
        err.format(ln, format!("header line {} is not of the form \"# key: value\"", quoted(line)))
    };
    let (key, value) = body.split_once(':').ok_or_else(not_key_value)?;
    let h = HeaderLine { key: trim(key), value: trim(value), line: ln };
    match key_problem(h.key) {
        None => match header_value_problem(h.value) {
            // Another reader would end the line there, and read what follows as another key.
            Some(problem) => Err(err.header(&h, format!("the value {problem}"))),
            None => Ok(h),
        },
        Some(true) => Err(err.header(&h, "header keys are lower case")),
        Some(false) => Err(not_key_value()),
    }
}

/// Three comma-separated finite numbers.
fn triple(value: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = value.split(',').collect();
    if parts.len() != 3 {
        return Err(format!(
            "{} is not three numbers separated by commas (X, Y, Z)",
            quoted(value)
        ));
    }
    let mut out = [0.0; 3];
    for (o, (p, which)) in out.iter_mut().zip(parts.into_iter().zip(["first", "second", "third"])) {
        *o = number(p).map_err(|m| format!("{which} value: {m}"))?;
    }
    Ok(out)
}

/// The header from its lines: every value checked, every required key present, unknown keys
/// kept in order in `extra`.
fn parse_header(
    entries: &[HeaderLine],
    column_line: usize,
    err: &Errors,
) -> Result<RunHeader, IoError> {
    let mut version = None;
    let mut machine = None;
    let mut plane = None;
    let mut direction = None;
    let mut radius_mm = None;
    let mut feed_mm_per_min = None;
    let mut pivot_mm = None;
    let mut table_ball_mm = None;
    let mut tool_ball_mm = None;
    let mut started_at = None;
    let mut run_id = None;
    let mut extra = Vec::new();
    for h in entries {
        let v = h.value;
        let text = || -> Result<String, IoError> {
            if v.is_empty() { Err(err.header(h, "the value is empty")) } else { Ok(v.to_string()) }
        };
        let positive = || -> Result<f64, IoError> {
            match number(v) {
                Ok(x) if x > 0.0 => Ok(x),
                Ok(_) => Err(err.header(h, format!("{} is not a positive number", quoted(v)))),
                Err(m) => Err(err.header(h, m)),
            }
        };
        let point = || triple(v).map_err(|m| err.header(h, m));
        match h.key {
            "ballbar-run" => version = Some(FORMAT_VERSION), // checked as it was read
            "machine" => machine = Some(text()?),
            "plane" => {
                let p = Plane::from_name(v).ok_or_else(|| {
                    err.header(h, format!("{} is not XY, YZ, ZX or free", quoted(v)))
                })?;
                plane = Some(p);
            }
            "direction" => {
                let d = Direction::from_name(v)
                    .ok_or_else(|| err.header(h, format!("{} is not CW or CCW", quoted(v))))?;
                direction = Some(d);
            }
            "radius_mm" => radius_mm = Some(positive()?),
            "feed_mm_per_min" => feed_mm_per_min = Some(positive()?),
            "pivot_mm" => pivot_mm = Some(point()?),
            "table_ball_mm" => table_ball_mm = Some(point()?),
            "tool_ball_mm" => tool_ball_mm = Some(point()?),
            "started_at" => {
                let seconds =
                    ballbar_model::time::parse_iso8601(v).map_err(|m| err.header(h, m))?;
                started_at = Some((v.to_string(), seconds));
            }
            "run_id" => {
                if v.len() > MAX_RUN_ID_BYTES {
                    return Err(err.header(
                        h,
                        format!(
                            "the run id is {} bytes long; it names files, and is at most {MAX_RUN_ID_BYTES} bytes",
                            v.len()
                        ),
                    ));
                }
                run_id = Some(text()?)
            }
            _ => extra.push((h.key.to_string(), v.to_string())),
        }
    }
    // Every missing key at once, in the spec's order. A missing plane may be a planar one, which
    // needs a direction.
    let missing: Vec<String> = [
        ("ballbar-run", version.is_none()),
        ("plane", plane.is_none()),
        ("direction", direction.is_none() && plane != Some(Plane::Free)),
        ("radius_mm", radius_mm.is_none()),
        ("feed_mm_per_min", feed_mm_per_min.is_none()),
        ("pivot_mm", pivot_mm.is_none()),
        ("started_at", started_at.is_none()),
    ]
    .into_iter()
    .filter(|&(_, absent)| absent)
    .map(|(key, _)| key.to_string())
    .collect();
    let (
        Some(format_version),
        Some(plane),
        Some(radius_mm),
        Some(feed_mm_per_min),
        Some(pivot_mm),
        Some((started_at, started_at_unix_s)),
    ) = (version, plane, radius_mm, feed_mm_per_min, pivot_mm, started_at)
    else {
        return Err(err.missing(column_line, missing));
    };
    if !missing.is_empty() {
        return Err(err.missing(column_line, missing)); // the direction alone
    }
    Ok(RunHeader {
        format_version,
        machine,
        plane,
        direction,
        radius_mm,
        feed_mm_per_min,
        pivot_mm,
        defaulted: ballbar_model::run::DefaultedKeys {
            table_ball_mm: table_ball_mm.is_none(),
            tool_ball_mm: tool_ball_mm.is_none(),
        },
        table_ball_mm: table_ball_mm.unwrap_or([0.0; 3]),
        tool_ball_mm: tool_ball_mm.unwrap_or([0.0; 3]),
        started_at,
        started_at_unix_s,
        run_id,
        extra,
    })
}

/// What each column holds, checking the column line.
fn parse_columns(
    names: &[&str],
    plane: Plane,
    line: usize,
    err: &Errors,
) -> Result<Vec<Column>, IoError> {
    if names.len() > MAX_COLUMNS {
        return Err(err.columns(
            line,
            format!("{} columns; a run file has at most {MAX_COLUMNS}", names.len()),
        ));
    }
    let mut seen: HashSet<&str> = HashSet::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        if name.is_empty() {
            return Err(err.columns(line, format!("column {} has no name", i + 1)));
        }
        if !seen.insert(name) {
            return Err(err.columns(line, format!("column {} is given twice", quoted(name))));
        }
    }
    let kinds: Vec<Column> = names
        .iter()
        .map(|&name| match name {
            "t_s" => Column::Time,
            "dR_um" => Column::Dr,
            _ => Axis::from_column_name(name).map_or(Column::Other, Column::Axis),
        })
        .collect();
    for (kind, name) in [(Column::Time, "t_s"), (Column::Dr, "dR_um")] {
        if !kinds.contains(&kind) {
            return Err(err.columns(line, format!("there is no {name} column")));
        }
    }
    if !kinds.iter().any(|k| matches!(k, Column::Axis(_))) {
        return Err(
            err.columns(line, "there is no axis column (X_mm, Y_mm, Z_mm, A_deg, B_deg, C_deg)")
        );
    }
    if let Some((u, v, _)) = plane.axes() {
        for a in [u, v] {
            if !kinds.contains(&Column::Axis(a)) {
                return Err(err.columns(
                    line,
                    format!("a test in plane {plane} needs the column {}", a.column_name()),
                ));
            }
        }
    }
    Ok(kinds)
}

/// Append the header line `# key: value` (`# key:` for an empty value).
fn push_key(s: &mut String, key: &str, value: &str) {
    s.push_str("# ");
    s.push_str(key);
    s.push(':');
    if !value.is_empty() {
        s.push(' ');
        s.push_str(value);
    }
    s.push('\n');
}

/// `dR_um` in the file to mm in a [`Run`], as the reader converts it (and so the writer
/// inverts it).
fn um_to_mm(um: f64) -> f64 {
    um * 1e-3
}

/// Degrees in the file to radians in a [`Run`], as the reader converts them.
fn deg_to_rad(deg: f64) -> f64 {
    deg.to_radians()
}

/// A reading in mm as a run CSV can carry it: its shortest decimal moved three places (µm) and
/// converted as the reader converts `dR_um`. Not every mm value is a µm value times 1e-3 in
/// floating point (about 3 % of the readings of a real `.b5r` file are not); the readers that
/// take readings in mm pass them through this, so that every run read from any file can be
/// written as a run CSV that reads back bit for bit. The value moves by at most an ulp.
pub(crate) fn reading_mm(mm: f64) -> f64 {
    if !mm.is_finite() {
        return mm;
    }
    let text = format!("{mm:e}");
    let um = match text.split_once('e') {
        Some((mantissa, exp)) => exp
            .parse::<i32>()
            .ok()
            .and_then(|e| format!("{mantissa}e{}", e + 3).parse::<f64>().ok()),
        None => None,
    };
    um.map_or(mm, um_to_mm)
}

/// How a sample value is written: its unit in the file against the run's, and the decimals
/// [`Numbers::Rounded`] keeps.
#[derive(Clone, Copy)]
enum Unit {
    /// `t_s` and the `_mm` axes: the same number in the file and the run; 6 decimals.
    Same,
    /// `_deg` axes: radians in the run; 7 decimals.
    Degrees,
    /// `dR_um`: mm in the run; 4 decimals.
    Micrometres,
}

impl Unit {
    fn decimals(self) -> usize {
        match self {
            Unit::Same => 6,
            Unit::Degrees => 7,
            Unit::Micrometres => 4,
        }
    }

    /// The run's value as the file's (the first guess at the file's number).
    fn to_file(self, v: f64) -> f64 {
        match self {
            Unit::Same => v,
            Unit::Degrees => v.to_degrees(),
            Unit::Micrometres => v * 1e3,
        }
    }

    /// The file's number as the reader converts it.
    fn to_run(self, v: f64) -> f64 {
        match self {
            Unit::Same => v,
            Unit::Degrees => deg_to_rad(v),
            Unit::Micrometres => um_to_mm(v),
        }
    }
}

/// How [`format_run`] writes sample values.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Numbers {
    /// The number that reads back as the run's value bit for bit, as `t_s` 6, mm 6, degrees 7
    /// and µm 4 decimals where those are exact (what a file written at that resolution holds,
    /// so such a file is written again byte for byte), otherwise the shortest decimal that is.
    Exact,
    /// Rounded to those decimals: 1 µs, 1 nm, 1e-7°, 0.1 nm of reading.
    Rounded,
}

/// How many floats either side of the first guess at a file's number are tried for one that
/// converts back exactly: a product and a conversion back are each within half an ulp, so the
/// number, when there is one, lies within two.
const NEIGHBOURS: usize = 4;

/// Append the run's value `v` as the file's number.
fn push_value(s: &mut String, v: f64, unit: Unit, numbers: Numbers) {
    let d0 = unit.to_file(v);
    let decimals = unit.decimals();
    if numbers == Numbers::Rounded || !v.is_finite() || !d0.is_finite() {
        let _ = write!(s, "{d0:.decimals$}");
        return;
    }
    let exact = |d: f64| d.is_finite() && unit.to_run(d).to_bits() == v.to_bits();
    let mark = s.len();
    let _ = write!(s, "{d0:.decimals$}");
    if s[mark..].parse::<f64>().is_ok_and(exact) {
        return;
    }
    s.truncate(mark);
    // The shortest decimal of the first guess or a neighbour that converts back exactly (the
    // same number in the same unit converts back to itself: no neighbour to try).
    let mut best: Option<(usize, f64)> = None;
    let mut consider = |d: f64, s: &mut String| {
        if exact(d) {
            let _ = write!(s, "{d}");
            let len = s.len() - mark;
            s.truncate(mark);
            if best.is_none_or(|(l, _)| len < l) {
                best = Some((len, d));
            }
        }
    };
    consider(d0, s);
    if !matches!(unit, Unit::Same) {
        let (mut up, mut down) = (d0, d0);
        for _ in 0..NEIGHBOURS {
            up = up.next_up();
            down = down.next_down();
            consider(up, s);
            consider(down, s);
        }
    }
    // None converts back exactly: the first guess, which reads back within an ulp (the
    // exact writers check what reads back, and say so).
    let d = best.map_or(d0, |(_, d)| d);
    let _ = write!(s, "{d}");
}

/// The run as run-CSV text, version 1, every value as it is: read back, the text gives the
/// run's values bit for bit wherever the format can hold them (checked by [`exact_text`]).
///
/// Header keys in the spec's order (ballbar-run, machine if any, plane, direction if any,
/// radius_mm, feed_mm_per_min, pivot_mm, table_ball_mm and tool_ball_mm unless the run did not
/// give them (`RunHeader::defaulted`: a key left out reads back as not given, so a run read,
/// exported or predicted keeps saying so), started_at, run_id if any, then `extra` in order),
/// header numbers in Rust's shortest round-trip form; columns `t_s`, the axes present in X, Y,
/// Z, A, B, C order (mm, degrees), `dR_um`, each value the number that the reader converts
/// back to the run's value exactly: with 6 decimals for `t_s` and mm, 7 for degrees and 4 for
/// µm where that number has them (a file written at that resolution is written again byte for
/// byte), otherwise the shortest decimal that converts back (Rust's `{}`: no exponent). `\n`
/// line ends. `started_at` is written as the string, not from `started_at_unix_s`.
///
/// A value the format cannot hold exactly (an mm reading that is no µm number times 1e-3, a
/// radian that is no degree value converted: only runs not read from a file have them) is
/// written as the nearest number, and [`exact_text`] refuses the run.
///
/// Meant for runs [`write_run`] accepts; for others it still returns text (a value missing from
/// a short column is written `NaN`) that the reader rejects. Never panics.
pub fn format_run(run: &Run) -> String {
    format_with(run, Numbers::Exact)
}

/// The run as run-CSV text at the simulator's resolution: as [`format_run`], but `t_s` rounded
/// to 6 decimals (1 µs), mm to 6 (1 nm), degrees to 7 and `dR_um` to 4 (0.1 nm), what
/// `ballbar simulate` writes, like an instrument of that resolution. The values read back are
/// the rounded ones.
pub fn format_run_rounded(run: &Run) -> String {
    format_with(run, Numbers::Rounded)
}

fn format_with(run: &Run, numbers: Numbers) -> String {
    let h = &run.header;
    let present: Vec<(Axis, &[f64])> =
        Axis::ALL.into_iter().filter_map(|a| run.axis(a).map(|c| (a, c))).collect();
    let mut s = String::with_capacity(512 + run.len() * (16 + 14 * present.len() + 12));
    let triple = |v: [f64; 3]| format!("{}, {}, {}", v[0], v[1], v[2]);
    push_key(&mut s, "ballbar-run", &FORMAT_VERSION.to_string());
    if let Some(m) = &h.machine {
        push_key(&mut s, "machine", m);
    }
    push_key(&mut s, "plane", h.plane.name());
    if let Some(d) = h.direction {
        push_key(&mut s, "direction", d.name());
    }
    push_key(&mut s, "radius_mm", &h.radius_mm.to_string());
    push_key(&mut s, "feed_mm_per_min", &h.feed_mm_per_min.to_string());
    push_key(&mut s, "pivot_mm", &triple(h.pivot_mm));
    // A defaulted key holds 0, 0, 0, which is what leaving it out says.
    if !h.defaulted.table_ball_mm || h.table_ball_mm != [0.0; 3] {
        push_key(&mut s, "table_ball_mm", &triple(h.table_ball_mm));
    }
    if !h.defaulted.tool_ball_mm || h.tool_ball_mm != [0.0; 3] {
        push_key(&mut s, "tool_ball_mm", &triple(h.tool_ball_mm));
    }
    push_key(&mut s, "started_at", &h.started_at);
    if let Some(id) = &h.run_id {
        push_key(&mut s, "run_id", id);
    }
    for (k, v) in &h.extra {
        push_key(&mut s, k, v);
    }
    s.push_str("t_s");
    for (a, _) in &present {
        s.push(',');
        s.push_str(a.column_name());
    }
    s.push_str(",dR_um\n");
    for (i, &t) in run.t_s.iter().enumerate() {
        push_value(&mut s, t, Unit::Same, numbers);
        for (a, col) in &present {
            let v = col.get(i).copied().unwrap_or(f64::NAN);
            s.push(',');
            push_value(&mut s, v, if a.is_rotary() { Unit::Degrees } else { Unit::Same }, numbers);
        }
        s.push(',');
        push_value(
            &mut s,
            run.dr_mm.get(i).copied().unwrap_or(f64::NAN),
            Unit::Micrometres,
            numbers,
        );
        s.push('\n');
    }
    s
}

/// What keeps `run` from being written faithfully, beyond what reading the text back finds:
/// columns of different lengths, header text that would not read back as it is.
fn write_problem(run: &Run) -> Option<String> {
    let n = run.len();
    for (name, len) in Axis::ALL
        .into_iter()
        .filter_map(|a| run.axis(a).map(|c| (a.column_name(), c.len())))
        .chain([("dR_um", run.dr_mm.len())])
    {
        if len != n {
            return Some(format!("column {name} has {len} values but t_s has {n}"));
        }
    }
    let h = &run.header;
    let mut texts: Vec<(&str, &str)> = vec![("started_at", &h.started_at)];
    texts.extend(h.machine.as_deref().map(|m| ("machine", m)));
    texts.extend(h.run_id.as_deref().map(|id| ("run_id", id)));
    let mut written: HashSet<&str> = HashSet::with_capacity(h.extra.len());
    for (k, v) in &h.extra {
        if key_problem(k).is_some() {
            return Some(format!(
                "header key {} is not lower-case letters, digits, '_' and '-'",
                quoted(k)
            ));
        }
        if KNOWN_KEYS.contains(&k.as_str()) || !written.insert(k) {
            return Some(format!("header key {} would be written twice", quoted(k)));
        }
        texts.push((k, v));
    }
    for (k, v) in texts {
        if let Some(problem) = header_value_problem(v) {
            return Some(format!("the value of header key {k:?} {problem}"));
        }
        if trim(v) != v {
            return Some(format!("the value of header key {k:?} starts or ends with a space"));
        }
    }
    None
}

/// [`write_problem`], then [`parse_run`] of `text` as an error message (the reader's message
/// without a file name: `line N: what is wrong`), or the run read back.
fn read_back(run: &Run, text: &str) -> Result<Run, String> {
    if let Some(message) = write_problem(run) {
        return Err(message);
    }
    parse_run(text, "").map_err(|e| {
        // The error names no file (source ""): its text is ":{line}: what is wrong".
        let line = e.line().unwrap_or(0);
        let text = e.to_string();
        let what = text.strip_prefix(&format!(":{line}: ")).unwrap_or(&text);
        format!("the text would not read back: line {line}: {what}")
    })
}

/// The first value of `run` that `back` (its text read back) does not hold bit for bit, as a
/// message naming the line and the column of the text.
fn first_difference(run: &Run, back: &Run) -> Option<String> {
    let (h, g) = (&run.header, &back.header);
    let keys = [
        ("machine", h.machine == g.machine),
        ("plane", h.plane == g.plane),
        ("direction", h.direction == g.direction),
        ("radius_mm", h.radius_mm.to_bits() == g.radius_mm.to_bits()),
        ("feed_mm_per_min", h.feed_mm_per_min.to_bits() == g.feed_mm_per_min.to_bits()),
        ("pivot_mm", h.pivot_mm.map(f64::to_bits) == g.pivot_mm.map(f64::to_bits)),
        ("table_ball_mm", h.table_ball_mm.map(f64::to_bits) == g.table_ball_mm.map(f64::to_bits)),
        ("tool_ball_mm", h.tool_ball_mm.map(f64::to_bits) == g.tool_ball_mm.map(f64::to_bits)),
        ("table_ball_mm or tool_ball_mm left out", h.defaulted == g.defaulted),
        ("started_at", h.started_at == g.started_at),
        ("started_at", h.started_at_unix_s.to_bits() == g.started_at_unix_s.to_bits()),
        ("run_id", h.run_id == g.run_id),
        ("ballbar-run", h.format_version == g.format_version),
        ("the keys this version does not know", h.extra == g.extra),
    ];
    if let Some((key, _)) = keys.iter().find(|(_, same)| !same) {
        return Some(format!("header {key}: reads back as another value"));
    }
    let mut columns: Vec<(&str, &[f64], &[f64], &str)> = vec![("t_s", &run.t_s, &back.t_s, "s")];
    for a in Axis::ALL {
        if let (Some(c), Some(d)) = (run.axis(a), back.axis(a)) {
            columns.push((a.column_name(), c, d, if a.is_rotary() { "rad" } else { "mm" }));
        } else if run.axis(a).is_some() != back.axis(a).is_some() {
            return Some(format!("column {}: present in one and not the other", a.column_name()));
        }
    }
    columns.push(("dR_um", &run.dr_mm, &back.dr_mm, "mm"));
    for (name, ours, theirs, unit) in columns {
        if ours.len() != theirs.len() {
            return Some(format!(
                "column {name}: {} values read back as {}",
                ours.len(),
                theirs.len()
            ));
        }
        if let Some(k) = ours.iter().zip(theirs).position(|(x, y)| x.to_bits() != y.to_bits()) {
            let line = back.lines.get(k).copied().unwrap_or(0);
            let cannot = match name {
                "dR_um" => {
                    ": no number of µm converts back to it (µm × 1e-3), so a run CSV cannot hold it"
                }
                n if n.ends_with("_deg") => {
                    ": no number of degrees converts back to it, so a run CSV cannot hold it"
                }
                _ => "",
            };
            return Some(format!(
                "line {line}: column {name}: the run holds {} {unit}, which reads back as {} {unit}{cannot}",
                ours[k], theirs[k]
            ));
        }
    }
    None
}

/// The run as run-CSV text ([`format_run`]) that is checked to read back as the run itself:
/// the header, and every sample value bit for bit. Otherwise the message says what would not:
/// what keeps the run from being written at all ([`write_run`]'s checks), or the line and
/// column of the first value the text would change (a value that came from no file, such as a
/// simulated reading that is no µm number times 1e-3).
pub fn exact_text(run: &Run) -> Result<String, String> {
    let text = format_run(run);
    let back = read_back(run, &text)?;
    match first_difference(run, &back) {
        None => Ok(text),
        Some(what) => Err(format!("it would not read back exactly: {what}")),
    }
}

/// The run as run-CSV text for the file `path`, every value exactly ([`exact_text`]); refused
/// ([`IoError::Unwritable`], naming `path`) where the file would not read back as this run:
/// columns of different lengths, header text with line breaks or other control characters,
/// invalid or repeated extra keys, anything [`parse_run`] rejects in the formatted text (too few
/// samples, non-finite values, times that do not increase, a radius mismatch, ...), and a value
/// that the text would change. Every writer of exact run CSVs makes its text here.
pub fn run_text(run: &Run, path: &Path) -> Result<String, IoError> {
    exact_text(run).map_err(|message| IoError::Unwritable { path: path.to_path_buf(), message })
}

/// The run as run-CSV text at the simulator's resolution ([`format_run_rounded`]): what
/// `ballbar simulate` writes. Refused as [`run_text`] refuses a run whose file would not read
/// back as a valid run; its values read back rounded, by design.
pub fn run_text_rounded(run: &Run, path: &Path) -> Result<String, IoError> {
    let text = format_run_rounded(run);
    read_back(run, &text)
        .map_err(|message| IoError::Unwritable { path: path.to_path_buf(), message })?;
    Ok(text)
}

/// Write a run file atomically (see [`crate::atomic`]), every value exactly ([`run_text`]),
/// replacing a file there only as `existing` says.
pub fn write_run(run: &Run, path: &Path, existing: Existing) -> Result<(), IoError> {
    let text = run_text(run, path)?;
    crate::atomic::write_atomic(path, text.as_bytes(), existing)
}

/// Write a run file atomically at the simulator's resolution ([`run_text_rounded`]).
pub fn write_run_rounded(run: &Run, path: &Path, existing: Existing) -> Result<(), IoError> {
    let text = run_text_rounded(run, path)?;
    crate::atomic::write_atomic(path, text.as_bytes(), existing)
}

/// A line without its line end, and the line end: `"\r\n"`, `"\n"`, or for a last line without
/// `\n`, `"\r"` or `""` (the reader takes a `\r` before the end of the text as a line end too).
fn split_line_end(raw: &str) -> (&str, &str) {
    if let Some(l) = raw.strip_suffix("\r\n") {
        (l, "\r\n")
    } else if let Some(l) = raw.strip_suffix('\n') {
        (l, "\n")
    } else if let Some(l) = raw.strip_suffix('\r') {
        (l, "\r")
    } else {
        (raw, "")
    }
}

/// A copy of run-CSV `text` with a column `name` holding `values_um` (4 decimals), one value per
/// sample line in order. `source` names the file in error messages.
///
/// The column is appended at the end of the column line and of every sample line; if a column
/// `name` is already there, its values are replaced in place instead. Every other byte of every
/// line is kept: header lines, the other columns, spaces, each line's end (`\n` or `\r\n`).
///
/// Checks the structure it relies on (a column line; sample lines with as many fields as the
/// column line, no blank or `#` lines among them), that `name` is a usable column name, that the
/// values are finite, and that there are as many values as sample lines ([`IoError::ValueCount`]).
/// It does not check the samples themselves: that is [`parse_run`]'s job.
pub fn append_column(
    text: &str,
    source: &str,
    name: &str,
    values_um: &[f64],
) -> Result<String, IoError> {
    let err = Errors { path: Path::new(source) };
    let mut out = String::with_capacity(text.len() + name.len() + 1 + values_um.len() * 12);
    // A byte-order mark is kept, and is not part of the first line.
    let body = match text.strip_prefix('\u{feff}') {
        Some(rest) => {
            out.push('\u{feff}');
            rest
        }
        None => text,
    };
    let lines = split_lines(body);

    // Header lines, kept as they are, then the column line.
    let idx = header_end(&lines);
    for l in &lines[..idx] {
        out.push_str(l.text);
        out.push_str(l.end);
    }
    let column_text = column_line(&lines, idx, &err)?;
    let column_line = idx + 1;
    if name.is_empty() || trim(name) != name || name.contains([',', '\n', '\r']) {
        let message = format!(
            "cannot add a column named {name:?}: not empty, no commas, line breaks or surrounding spaces"
        );
        return Err(err.columns(column_line, message));
    }
    let names: Vec<&str> = column_text.split(',').map(trim).collect();
    if names.iter().filter(|n| **n == name).count() > 1 {
        return Err(err.columns(column_line, format!("column {name:?} is given twice")));
    }
    // The column's index if it is being replaced.
    let replace = names.iter().position(|n| *n == name);
    out.push_str(column_text);
    if replace.is_none() {
        out.push(',');
        out.push_str(name);
    }
    out.push_str(lines[idx].end);

    // Sample lines.
    let samples = lines.len() - column_line;
    for (k, l) in lines[column_line..].iter().enumerate() {
        let ln = column_line + k + 1;
        let line = l.text;
        let eol = l.end;
        check_sample_line(line, ln, column_line, names.len(), &err)?;
        let Some(&v) = values_um.get(k) else {
            continue; // counted below
        };
        if !v.is_finite() {
            return Err(err.sample(ln, name, format!("the new value {v} is not finite")));
        }
        match replace {
            None => {
                let _ = write!(out, "{line},{v:.4}{eol}");
            }
            Some(c) => {
                // Byte range of field c: after the c-th comma, up to the next one.
                let start = match c {
                    0 => 0,
                    _ => line.match_indices(',').nth(c - 1).map_or(line.len(), |(p, _)| p + 1),
                };
                let end = line[start..].find(',').map_or(line.len(), |p| start + p);
                let _ = write!(out, "{}{v:.4}{}{eol}", &line[..start], &line[end..]);
            }
        }
    }
    if samples != values_um.len() {
        // The first sample without a value, or the last line when values are left over.
        let line =
            if values_um.len() < samples { column_line + values_um.len() + 1 } else { lines.len() };
        return Err(IoError::ValueCount {
            path: err.path(),
            line,
            column: name.to_string(),
            samples,
            values: values_um.len(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The spec's example, verbatim (a macro, so that [`VALID`] can extend it).
    macro_rules! spec_example {
        () => {
            "\
# ballbar-run: 1
# machine: column
# plane: XY
# direction: CCW
# radius_mm: 100
# feed_mm_per_min: 1000
# pivot_mm: 300, 200, -300
# table_ball_mm: 0, 0, 50
# tool_ball_mm: 0, 0, -100
# started_at: 2026-11-21T10:00:00Z
# run_id: xy-ccw-1
t_s,X_mm,Y_mm,Z_mm,dR_um
0.000,400.000000,200.000000,-300.000000,0.512
0.004,399.999998,200.020944,-300.000000,0.498
"
        };
    }

    /// The spec's example, verbatim.
    const SPEC_EXAMPLE: &str = spec_example!();

    /// The spec's example as a run: its arc stated (`arc_deg`, after its header) and a third
    /// sample where its feed takes the ball 8 ms after the start. Header on lines 1-12, column
    /// line 13, samples on lines 14-16.
    fn spec_run() -> String {
        let header =
            SPEC_EXAMPLE.replace("# run_id: xy-ccw-1\n", "# run_id: xy-ccw-1\n# arc_deg: 0.07\n");
        format!("{header}0.008,399.999911,200.133333,-300.000000,0.470\n")
    }

    /// The spec's example with three more samples on the same circle, stating its arc where
    /// the example gives the (optional) table ball: a valid run. Header on lines 1-11, column
    /// line 12, samples on lines 13-17. (The spec's own two samples turn at a third of its
    /// feed; the last one here is where the feed has taken the ball by then, so that the run's
    /// duration is its path over its feed.)
    const VALID: &str = "\
# ballbar-run: 1
# machine: column
# plane: XY
# direction: CCW
# radius_mm: 100
# feed_mm_per_min: 1000
# pivot_mm: 300, 200, -300
# arc_deg: 0.15
# tool_ball_mm: 0, 0, -100
# started_at: 2026-11-21T10:00:00Z
# run_id: xy-ccw-1
t_s,X_mm,Y_mm,Z_mm,dR_um
0.000,400.000000,200.000000,-300.000000,0.512
0.004,399.999998,200.020944,-300.000000,0.498
0.008,399.999991,200.041888,-300.000000,0.470
0.012,399.999980,200.062832,-300.000000,0.455
0.016,399.999644,200.266666,-300.000000,0.431
";

    const FILE: &str = "fixtures/x.csv";

    /// `VALID` with `from` (which must occur exactly once) replaced by `to`.
    fn valid_with(from: &str, to: &str) -> String {
        assert_eq!(VALID.matches(from).count(), 1, "{from:?} must occur once in VALID");
        VALID.replacen(from, to, 1)
    }

    /// The error of parsing `text` as `FILE`, checking that its message starts with
    /// `fixtures/x.csv:{line}: ` and contains `what`.
    fn error_at(text: &str, line: usize, what: &str) -> IoError {
        crate::expect_error_at(parse_run(text, FILE), FILE, line, what)
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    // ---- reading valid files ----

    #[test]
    fn the_spec_example_has_every_header_field_and_two_samples_on_the_circle() {
        // The example has only two samples.
        let e = error_at(SPEC_EXAMPLE, 14, "at least 3 samples; this file has 2");
        assert!(matches!(e, IoError::Format { .. }));
        // With a third on the same course it reads as the arc the run format allows, with a
        // warning: its samples cover 0.02°, and no arc is stated to tell an arc from a cut.
        let text = format!("{SPEC_EXAMPLE}0.008,399.999991,200.041888,-300.000000,0.470\n");
        let r = parse_run(&text, FILE).unwrap();
        let w = crate::check::warnings(&r);
        assert!(w.iter().any(|w| w.contains("a partial arc, or a file cut short")), "{w:?}");
        // With its arc stated and the third sample where the feed takes the ball by then, its
        // header reads as the spec says.
        let text = spec_run();
        let r = parse_run(&text, FILE).unwrap();
        let h = &r.header;
        assert_eq!(h.format_version, 1);
        assert_eq!(h.machine.as_deref(), Some("column"));
        assert_eq!(h.plane, Plane::XY);
        assert_eq!(h.direction, Some(Direction::CCW));
        assert_eq!(h.radius_mm, 100.0);
        assert_eq!(h.feed_mm_per_min, 1000.0);
        assert_eq!(h.pivot_mm, [300.0, 200.0, -300.0]);
        assert_eq!(h.table_ball_mm, [0.0, 0.0, 50.0]);
        assert_eq!(h.tool_ball_mm, [0.0, 0.0, -100.0]);
        assert_eq!(h.started_at, "2026-11-21T10:00:00Z");
        assert_eq!(h.started_at_unix_s, 1_795_255_200.0);
        assert_eq!(h.run_id.as_deref(), Some("xy-ccw-1"));
        assert_eq!(h.extra, [("arc_deg".to_string(), "0.07".to_string())]);
        assert_eq!(r.source, FILE);
        assert_eq!(r.t_s, vec![0.0, 0.004, 0.008]);
        assert_eq!(r.axis(Axis::X).unwrap(), &[400.0, 399.999998, 399.999911]);
        assert_eq!(r.axis(Axis::Y).unwrap(), &[200.0, 200.020944, 200.133333]);
        assert_eq!(r.axis(Axis::Z).unwrap(), &[-300.0, -300.0, -300.0]);
        assert!(
            r.axis(Axis::A).is_none() && r.axis(Axis::B).is_none() && r.axis(Axis::C).is_none()
        );
        // dR_um is micrometres, dr_mm millimetres.
        for (got, um) in r.dr_mm.iter().zip([0.512, 0.498, 0.470]) {
            assert!(close(*got, um * 1e-3, 1e-15), "{got}");
        }
        assert_eq!(r.lines, vec![14, 15, 16]);
        // Both example samples lie 100 mm from the pivot.
        for i in 0..2 {
            let (x, y) = (r.axis(Axis::X).unwrap()[i] - 300.0, r.axis(Axis::Y).unwrap()[i] - 200.0);
            assert!(close(x.hypot(y), 100.0, 1e-5));
        }
    }

    #[test]
    fn the_minimal_example_of_docs_run_format_reads() {
        let block = crate::doc_csv_block("### A minimal example");
        let r = parse_run(block, "docs/run-format.md").unwrap();
        assert_eq!(r.len(), 4);
        assert_eq!(r.header.pivot_mm, [0.0; 3]);
        // No Z_mm column: Z sits at the pivot's Z, 0.
        assert_eq!(r.axis(Axis::Z), Some(&[0.0; 4][..]));
        // On the circle to the file's 6 decimals, at the feed's angle.
        for i in 0..4 {
            let th = 1000.0 / 60.0 * r.t_s[i] / 100.0;
            assert!(close(r.axis(Axis::X).unwrap()[i], 100.0 * th.cos(), 0.6e-6));
            assert!(close(r.axis(Axis::Y).unwrap()[i], 100.0 * th.sin(), 0.6e-6));
        }
    }

    #[test]
    fn crlf_lines_and_a_missing_final_line_end_read_the_same() {
        let plain = parse_run(VALID, FILE).unwrap();
        assert_eq!(parse_run(&VALID.replace('\n', "\r\n"), FILE).unwrap(), plain);
        assert_eq!(parse_run(VALID.trim_end_matches('\n'), FILE).unwrap(), plain);
        // Mixed line ends, line by line.
        let mixed = valid_with("# plane: XY\n", "# plane: XY\r\n").replace("0.470\n", "0.470\r\n");
        assert_eq!(parse_run(&mixed, FILE).unwrap(), plain);
        // A UTF-8 byte-order mark (spreadsheet programs write one).
        assert_eq!(parse_run(&format!("\u{feff}{VALID}"), FILE).unwrap(), plain);
    }

    #[test]
    fn spaces_around_header_values_and_fields_are_not_part_of_them() {
        let text = valid_with("# radius_mm: 100", "#radius_mm:   100  ")
            .replace("0.004,399.999998,", " 0.004 ,\t399.999998 ,");
        let r = parse_run(&text, FILE).unwrap();
        assert_eq!(r.header.radius_mm, 100.0);
        assert_eq!(r.t_s[1], 0.004);
        assert_eq!(r.axis(Axis::X).unwrap()[1], 399.999998);
    }

    #[test]
    fn unknown_keys_are_kept_in_order() {
        let text = valid_with(
            "# run_id: xy-ccw-1\n",
            "# run_id: xy-ccw-1\n# operator: A. N. Other: day shift\n# bar_serial: 1234\n# empty:\n",
        );
        let r = parse_run(&text, FILE).unwrap();
        let extra: Vec<(&str, &str)> =
            r.header.extra.iter().map(|(k, v)| (k.as_str(), v.as_str())).collect();
        assert_eq!(
            extra,
            [
                ("arc_deg", "0.15"),
                ("operator", "A. N. Other: day shift"),
                ("bar_serial", "1234"),
                ("empty", "")
            ]
        );
    }

    #[test]
    fn optional_keys_default() {
        let text = valid_with("# machine: column\n", "")
            .replace("# table_ball_mm: 0, 0, 50\n", "")
            .replace("# tool_ball_mm: 0, 0, -100\n", "")
            .replace("# run_id: xy-ccw-1\n", "");
        let r = parse_run(&text, FILE).unwrap();
        assert_eq!(r.header.machine, None);
        assert_eq!(r.header.run_id, None);
        assert_eq!(r.header.table_ball_mm, [0.0; 3]);
        assert_eq!(r.header.tool_ball_mm, [0.0; 3]);
        assert_eq!(r.lines, vec![10, 11, 12, 13, 14]);
        // Absent is told apart from given as 0, 0, 0; the writer leaves an absent key out, so
        // the text reads back the same.
        assert!(r.header.defaulted.table_ball_mm && r.header.defaulted.tool_ball_mm);
        let written = format_run(&r);
        assert!(
            !written.contains("table_ball_mm") && !written.contains("tool_ball_mm"),
            "{written}"
        );
        assert_eq!(parse_run(&written, FILE).unwrap().header, r.header);
        let zero = valid_with("# tool_ball_mm: 0, 0, -100\n", "# tool_ball_mm: 0, 0, 0\n")
            .replace("# table_ball_mm: 0, 0, 50\n", "");
        let z = parse_run(&zero, FILE).unwrap();
        assert_eq!(z.header.tool_ball_mm, [0.0; 3]);
        assert!(z.header.defaulted.table_ball_mm && !z.header.defaulted.tool_ball_mm);
        let written = format_run(&z);
        assert!(
            written.contains("# tool_ball_mm: 0, 0, 0\n") && !written.contains("table_ball_mm"),
            "{written}"
        );
        assert_eq!(parse_run(&written, FILE).unwrap().header, z.header);
        let given = valid_with("# tool_ball_mm", "# table_ball_mm: 0, 0, 50\n# tool_ball_mm");
        assert_eq!(parse_run(&given, FILE).unwrap().header.defaulted, Default::default());
    }

    #[test]
    fn other_columns_are_ignored_and_not_parsed() {
        let text = valid_with("Z_mm,dR_um\n", "Z_mm,note,dR_um,dR_model_um\n")
            .replace(",-300.000000,0.512\n", ",-300.000000,,0.512,abc\n")
            .replace(",-300.000000,0.498\n", ",-300.000000,nan,0.498,\n")
            .replace(",-300.000000,0.470\n", ",-300.000000,x,0.470,1.5\n")
            .replace(",-300.000000,0.455\n", ",-300.000000,y,0.455,1.5\n")
            .replace(",-300.000000,0.431\n", ",-300.000000,z,0.431,1.5\n");
        let r = parse_run(&text, FILE).unwrap();
        assert_eq!(r.len(), 5);
        assert!(close(r.dr_mm[1], 0.498e-3, 1e-15));
    }

    #[test]
    fn an_axis_column_absent_from_a_planar_run_sits_at_the_pivot() {
        // No Z_mm: the radius check takes Z from pivot_mm.
        let text: String = VALID.replace(",Z_mm", "").replace(",-300.000000", "");
        let r = parse_run(&text, FILE).unwrap();
        assert!(r.axis(Axis::Z).unwrap().iter().all(|&z| z == -300.0));
        // Still checked in plane: 2 mm off in Y is an error.
        let off = text.replace("399.999980,200.062832", "401.999980,200.062832");
        assert!(matches!(error_at(&off, 16, "from pivot_mm"), IoError::Radius { .. }));
    }

    #[test]
    fn rotary_columns_are_degrees_in_the_file_and_radians_in_the_run() {
        let text = valid_with("Z_mm,dR_um\n", "Z_mm,C_deg,A_deg,dR_um\n")
            .replace(",-300.000000,0.512\n", ",-300.000000,0,-90,0.512\n")
            .replace(",-300.000000,0.498\n", ",-300.000000,90,-90,0.498\n")
            .replace(",-300.000000,0.470\n", ",-300.000000,180,-90,0.470\n")
            .replace(",-300.000000,0.455\n", ",-300.000000,270,-90,0.455\n")
            .replace(",-300.000000,0.431\n", ",-300.000000,720,-90,0.431\n");
        let r = parse_run(&text, FILE).unwrap();
        let c = r.axis(Axis::C).unwrap();
        for (got, want) in c.iter().zip([0.0, PI / 2.0, PI, 1.5 * PI, 4.0 * PI]) {
            assert!(close(*got, want, 1e-12), "{got} vs {want}");
        }
        assert!(r.axis(Axis::A).unwrap().iter().all(|a| close(*a, -PI / 2.0, 1e-12)));
        assert!(r.axis(Axis::B).is_none());
    }

    #[test]
    fn a_free_path_needs_no_direction_and_no_circle() {
        // X moves 20 mm in 16 ms: 75,000 mm/min.
        let text = valid_with("# plane: XY\n# direction: CCW\n", "# plane: free\n")
            .replace("# feed_mm_per_min: 1000\n", "# feed_mm_per_min: 75000\n")
            .replace("t_s,X_mm,Y_mm,Z_mm,dR_um", "t_s,X_mm,B_deg,dR_um")
            .replace("400.000000,200.000000,-300.000000", "0,10")
            .replace("399.999998,200.020944,-300.000000", "5,11")
            .replace("399.999991,200.041888,-300.000000", "10,12")
            .replace("399.999980,200.062832,-300.000000", "15,13")
            .replace("399.999644,200.266666,-300.000000", "20,14");
        let r = parse_run(&text, FILE).unwrap();
        assert_eq!(r.header.plane, Plane::Free);
        assert_eq!(r.header.direction, None);
        assert_eq!(r.axis(Axis::X).unwrap(), &[0.0, 5.0, 10.0, 15.0, 20.0]);
        assert!(close(r.axis(Axis::B).unwrap()[4], 14f64.to_radians(), 1e-15));
        // A direction may still be given, and is checked.
        let with_direction = text.replace("# plane: free\n", "# plane: free\n# direction: CW\n");
        assert_eq!(parse_run(&with_direction, FILE).unwrap().header.direction, Some(Direction::CW));
        let bad_direction = text.replace("# plane: free\n", "# plane: free\n# direction: up\n");
        error_at(&bad_direction, 4, "\"up\" is not CW or CCW");
    }

    #[test]
    fn the_radius_tolerance_is_one_millimetre() {
        // 0.9 mm outside and inside the circle: accepted.
        let r = parse_run(&valid_with("0.012,399.999980,", "0.012,400.899980,"), FILE).unwrap();
        assert_eq!(r.len(), 5);
        parse_run(&valid_with("0.012,399.999980,", "0.012,399.099980,"), FILE).unwrap();
        // 1.1 mm: not.
        let e = error_at(
            &valid_with("0.012,399.999980,", "0.012,401.099980,"),
            16,
            "lie 101.1000 mm from pivot_mm, but radius_mm is 100",
        );
        match e {
            IoError::Radius { line, distance_mm, radius_mm, .. } => {
                assert_eq!(line, 16);
                assert!(close(distance_mm, 101.1, 1e-4));
                assert_eq!(radius_mm, 100.0);
            }
            other => panic!("{other:?}"),
        }
        // Off the plane counts too.
        error_at(
            &valid_with(
                "0.016,399.999644,200.266666,-300.000000",
                "0.016,399.999644,200.266666,-285.000000",
            ),
            17,
            "from pivot_mm",
        );
    }

    // ---- malformed header: one test per case ----

    #[test]
    fn missing_version_line() {
        let e = error_at(
            &valid_with("# ballbar-run: 1\n", ""),
            11,
            "the header lacks the required key ballbar-run (see docs/run-format.md)",
        );
        assert!(
            matches!(e, IoError::MissingKey { ref keys, line: 11, .. } if keys == &["ballbar-run"]),
            "{e:?}"
        );
    }

    #[test]
    fn every_missing_key_in_one_message() {
        // A CSV without any header: the column line is line 1, and every required key is named.
        let bare = VALID.lines().skip(11).collect::<Vec<_>>().join("\n");
        let e = error_at(&bare, 1, "");
        assert_eq!(
            e.to_string(),
            "fixtures/x.csv:1: the header lacks the required keys ballbar-run, plane, direction, \
             radius_mm, feed_mm_per_min, pivot_mm, started_at (see docs/run-format.md)"
        );
        // Several keys missing, in the spec's order whatever the order of the lines.
        let text = valid_with("# ballbar-run: 1\n", "")
            .replace("# radius_mm: 100\n", "")
            .replace("# started_at: 2026-11-21T10:00:00Z\n", "")
            .replace("# direction: CCW\n", "");
        let e = error_at(
            &text,
            8,
            "the header lacks the required keys ballbar-run, direction, radius_mm, started_at (see",
        );
        match e {
            IoError::MissingKey { keys, line, path } => {
                assert_eq!(keys, ["ballbar-run", "direction", "radius_mm", "started_at"]);
                assert_eq!(line, 8);
                assert_eq!(path, Path::new(FILE));
            }
            other => panic!("{other:?}"),
        }
        // A free run needs no direction: not listed.
        let free = valid_with("# plane: XY\n# direction: CCW\n", "# plane: free\n")
            .replace("# feed_mm_per_min: 1000\n", "")
            .replace("# pivot_mm: 300, 200, -300\n", "");
        error_at(&free, 9, "the header lacks the required keys feed_mm_per_min, pivot_mm (see");
        // A value error on a line comes first: it is found where it is.
        let bad = text.replace("# plane: XY", "# plane: xy");
        error_at(&bad, 2, "header key \"plane\": \"xy\" is not XY");
    }

    #[test]
    fn unsupported_version() {
        for v in ["2", "0", "1.0", "01", "one", ""] {
            let e = error_at(
                &valid_with("# ballbar-run: 1", &format!("# ballbar-run: {v}")),
                1,
                "not supported",
            );
            assert!(matches!(e, IoError::Header { ref key, .. } if key == "ballbar-run"), "{e:?}");
        }
    }

    #[test]
    fn a_header_line_that_is_not_key_colon_value() {
        for line in
            ["# a note without colon", "#", "# : no key", "# two words: value", "# key;x: v"]
        {
            let e = error_at(
                &valid_with("# machine: column\n", &format!("# machine: column\n{line}\n")),
                3,
                "is not of the form \"# key: value\"",
            );
            assert!(matches!(e, IoError::Format { .. }), "{e:?}");
        }
    }

    #[test]
    fn an_upper_case_key() {
        let e = error_at(
            &valid_with("# machine: column", "# Machine: column"),
            2,
            "header key \"Machine\": header keys are lower case",
        );
        assert!(matches!(e, IoError::Header { ref key, .. } if key == "Machine"));
        error_at(&valid_with("# radius_mm: 100", "# RADIUS_MM: 100"), 5, "\"RADIUS_MM\"");
    }

    #[test]
    fn a_key_given_twice() {
        let e = error_at(
            &valid_with("# run_id: xy-ccw-1\n", "# run_id: xy-ccw-1\n# plane: XY\n"),
            12,
            "header key \"plane\": given twice (first on line 3)",
        );
        assert!(matches!(e, IoError::Header { .. }));
        // Unknown keys too.
        error_at(
            &valid_with("# run_id: xy-ccw-1\n", "# run_id: xy-ccw-1\n# note: a\n# note: b\n"),
            13,
            "\"note\": given twice",
        );
    }

    #[test]
    fn missing_required_keys() {
        for (line, key) in [
            ("# plane: XY\n", "plane"),
            ("# direction: CCW\n", "direction"),
            ("# radius_mm: 100\n", "radius_mm"),
            ("# feed_mm_per_min: 1000\n", "feed_mm_per_min"),
            ("# pivot_mm: 300, 200, -300\n", "pivot_mm"),
            ("# started_at: 2026-11-21T10:00:00Z\n", "started_at"),
        ] {
            // Without the line, the column line is line 11.
            let e = error_at(
                &valid_with(line, ""),
                11,
                &format!("the header lacks the required key {key} (see docs/run-format.md)"),
            );
            assert!(matches!(e, IoError::MissingKey { ref keys, .. } if keys == &[key]), "{e:?}");
        }
    }

    #[test]
    fn a_bad_plane() {
        for v in ["XZ", "xy", "Free", "", "XYZ"] {
            let e = error_at(
                &valid_with("# plane: XY", &format!("# plane: {v}")),
                3,
                "is not XY, YZ, ZX or free",
            );
            assert!(matches!(e, IoError::Header { ref key, .. } if key == "plane"));
        }
    }

    #[test]
    fn a_bad_direction() {
        for v in ["ccw", "CLOCKWISE", "", "+1"] {
            error_at(
                &valid_with("# direction: CCW", &format!("# direction: {v}")),
                4,
                "is not CW or CCW",
            );
        }
    }

    #[test]
    fn a_radius_or_feed_that_is_not_a_positive_finite_number() {
        for (key, line) in [("radius_mm: 100", 5), ("feed_mm_per_min: 1000", 6)] {
            let name = key.split(':').next().unwrap();
            for (v, what) in [
                ("0", "is not a positive number"),
                ("-100", "is not a positive number"),
                ("inf", "is not a finite number"),
                ("NaN", "is not a finite number"),
                ("fast", "is not a number"),
                ("1,000", "is not a number"),
                ("", "missing"),
            ] {
                let e = error_at(&valid_with(key, &format!("{name}: {v}")), line, what);
                assert!(matches!(e, IoError::Header { ref key, .. } if key == name), "{e:?}");
            }
        }
    }

    #[test]
    fn a_point_that_is_not_three_finite_numbers() {
        for (v, what) in [
            ("300, 200", "is not three numbers"),
            ("300, 200, -300, 0", "is not three numbers"),
            ("300 200 -300", "is not three numbers"),
            ("300, abc, -300", "second value: \"abc\" is not a number"),
            ("300, 200, inf", "third value: \"inf\" is not a finite number"),
            ("300, , -300", "second value: the value is missing"),
        ] {
            error_at(
                &valid_with("# pivot_mm: 300, 200, -300", &format!("# pivot_mm: {v}")),
                7,
                what,
            );
        }
        error_at(
            &valid_with("# tool_ball_mm", "# table_ball_mm: 0, 0\n# tool_ball_mm"),
            9,
            "table_ball_mm",
        );
        error_at(
            &valid_with("# tool_ball_mm: 0, 0, -100", "# tool_ball_mm: 0, 0, -1e999"),
            9,
            "tool_ball_mm",
        );
    }

    #[test]
    fn a_started_at_that_is_not_iso_8601() {
        for (v, what) in [
            ("tomorrow", "ISO 8601"),
            ("2026-11-21T10:00:00", "ISO 8601"),
            ("2026-11-21 10:00:00Z", "ISO 8601"),
            ("2026-02-29T10:00:00Z", "does not exist"),
            ("2026-11-21T25:00:00Z", "out of range"),
        ] {
            let e = error_at(&valid_with("2026-11-21T10:00:00Z", v), 10, what);
            assert!(matches!(e, IoError::Header { ref key, .. } if key == "started_at"));
        }
    }

    #[test]
    fn an_empty_machine_or_run_id() {
        error_at(
            &valid_with("# machine: column", "# machine:"),
            2,
            "\"machine\": the value is empty",
        );
        error_at(
            &valid_with("# run_id: xy-ccw-1", "# run_id:   "),
            11,
            "\"run_id\": the value is empty",
        );
    }

    /// A header value with a line break that the line split here does not see (a lone `\r`,
    /// a Unicode line separator) would be two lines to another reader, the second maybe a
    /// second `radius_mm`: refused at its line, as is any other control character. A tab is
    /// text.
    #[test]
    fn a_header_value_with_a_line_break_or_a_control_character() {
        error_at(
            &valid_with("# machine: column", "# machine: column\r# radius_mm: 50"),
            2,
            "\"machine\": the value contains a line break (a carriage return, U+000D)",
        );
        error_at(
            &valid_with("# run_id: xy-ccw-1", "# run_id: xy\u{2028}ccw"),
            11,
            "\"run_id\": the value contains a line break (a line separator, U+2028)",
        );
        error_at(
            &valid_with("# run_id: xy-ccw-1", "# operator: J.\u{7}Doe\n# run_id: xy-ccw-1"),
            11,
            "\"operator\": the value contains a control character (U+0007)",
        );
        let r = parse_run(&valid_with("# run_id: xy-ccw-1", "# run_id: xy\tccw"), FILE).unwrap();
        assert_eq!(r.header.run_id.as_deref(), Some("xy\tccw"));
    }

    #[test]
    fn text_from_another_program_becomes_one_header_value() {
        assert_eq!(one_line("J. Doe\r# radius_mm: 50"), "J. Doe / # radius_mm: 50");
        assert_eq!(one_line(" a \r\n\r\n b\u{85}c\u{2028}d\u{7}e\tf "), "a / b / c / d e f");
        assert_eq!(one_line("\n \n"), "");
        assert!(header_value_problem(&one_line("x\u{1e}y\u{0}z")).is_none());
    }

    // ---- malformed structure and column line ----

    #[test]
    fn an_empty_file_or_one_without_a_column_line() {
        error_at("", 1, "the file is empty");
        error_at("\n", 1, "blank line where the column line");
        let header_only: String = VALID.lines().take(11).map(|l| format!("{l}\n")).collect();
        error_at(&header_only, 12, "the file ends before the column line");
    }

    #[test]
    fn a_blank_line_between_header_and_column_line() {
        let e = error_at(
            &valid_with("# run_id: xy-ccw-1\n", "# run_id: xy-ccw-1\n\n"),
            12,
            "blank line",
        );
        assert!(matches!(e, IoError::Format { .. }));
    }

    #[test]
    fn a_column_line_without_t_s_or_dr_um() {
        let e = error_at(
            &valid_with("t_s,X_mm", "time,X_mm"),
            12,
            "column line: there is no t_s column",
        );
        assert!(matches!(e, IoError::Columns { line: 12, .. }));
        error_at(&valid_with(",dR_um\n", ",dR_mm\n"), 12, "there is no dR_um column");
        error_at(&valid_with(",dR_um\n", ",dr_um\n"), 12, "there is no dR_um column");
    }

    #[test]
    fn a_column_line_without_an_axis_column() {
        let text = valid_with("# plane: XY\n# direction: CCW\n", "# plane: free\n")
            .replace("t_s,X_mm,Y_mm,Z_mm,dR_um", "t_s,x_mm,y_mm,z_mm,dR_um");
        error_at(&text, 11, "there is no axis column");
    }

    #[test]
    fn a_planar_test_without_an_in_plane_axis() {
        error_at(
            &valid_with("t_s,X_mm,Y_mm,Z_mm", "t_s,X_mm,Q_mm,Z_mm"),
            12,
            "a test in plane XY needs the column Y_mm",
        );
        error_at(
            &valid_with("# plane: XY", "# plane: YZ")
                .replace("t_s,X_mm,Y_mm,Z_mm", "t_s,X_mm,Y_mm,W_mm"),
            12,
            "plane YZ needs the column Z_mm",
        );
        error_at(
            &valid_with("# plane: XY", "# plane: ZX").replace("t_s,X_mm", "t_s,U_mm"),
            12,
            "plane ZX needs the column X_mm",
        );
    }

    #[test]
    fn a_column_name_given_twice_or_empty() {
        let e = error_at(
            &valid_with("Z_mm,dR_um\n", "Z_mm,dR_um,X_mm\n"),
            12,
            "column \"X_mm\" is given twice",
        );
        assert!(matches!(e, IoError::Columns { .. }));
        error_at(
            &valid_with("Z_mm,dR_um\n", "Z_mm,dR_um,note,note\n"),
            12,
            "\"note\" is given twice",
        );
        error_at(&valid_with("Z_mm,dR_um\n", "Z_mm,,dR_um\n"), 12, "column 5 has no name");
    }

    // ---- malformed samples ----

    #[test]
    fn a_value_that_is_not_a_number() {
        let e = error_at(&valid_with("0.004,399.999998", "0.004,abc"), 14, "");
        assert_eq!(e.to_string(), "fixtures/x.csv:14: column X_mm: \"abc\" is not a number");
        assert!(matches!(e, IoError::Sample { line: 14, ref column, .. } if column == "X_mm"));
        error_at(
            &valid_with("0.008,", "0,008,"),
            15,
            "6 fields, but the column line (line 12) has 5",
        );
        error_at(&valid_with(",0.455", ",0.455µ"), 16, "column dR_um: \"0.455µ\" is not a number");
        error_at(&valid_with("0.012,", "0x10,"), 16, "column t_s: \"0x10\" is not a number");
    }

    #[test]
    fn a_value_that_is_not_finite() {
        for v in ["nan", "NaN", "inf", "-inf", "infinity", "1e400"] {
            let e = error_at(
                &valid_with("200.020944", v),
                14,
                &format!("column Y_mm: \"{v}\" is not a finite number"),
            );
            assert!(matches!(e, IoError::Sample { .. }));
        }
    }

    #[test]
    fn a_missing_value() {
        error_at(&valid_with(",0.498", ","), 14, "column dR_um: the value is missing");
        error_at(&valid_with("0.004,", " ,"), 14, "column t_s: the value is missing");
    }

    #[test]
    fn a_line_with_the_wrong_number_of_fields() {
        let e = error_at(
            &valid_with(",0.498", ",0.498,7"),
            14,
            "6 fields, but the column line (line 12) has 5",
        );
        assert!(matches!(e, IoError::Format { .. }));
        error_at(&valid_with(",-300.000000,0.470", ",0.470"), 15, "4 fields");
        error_at(&valid_with(",0.431\n", ",0.431,\n"), 17, "6 fields");
    }

    #[test]
    fn a_time_that_does_not_increase() {
        let e = error_at(
            &valid_with("0.008,", "0.004,"),
            15,
            "column t_s: 0.004 does not increase: the sample before (line 14) has 0.004",
        );
        assert!(matches!(e, IoError::Sample { ref column, .. } if column == "t_s"));
        error_at(&valid_with("0.012,", "0.001,"), 16, "does not increase");
        error_at(
            &valid_with("0.000,", "-0.001,").replace("0.004,", "-0.002,"),
            14,
            "does not increase",
        );
    }

    #[test]
    fn fewer_than_three_samples() {
        let two: String = VALID.lines().take(14).map(|l| format!("{l}\n")).collect();
        let e = error_at(&two, 14, "a run needs at least 3 samples; this file has 2");
        assert!(matches!(e, IoError::Format { .. }));
        let none: String = VALID.lines().take(12).map(|l| format!("{l}\r\n")).collect();
        error_at(&none, 12, "this file has 0");
    }

    #[test]
    fn a_file_cut_short_is_refused_saying_what_was_kept() {
        // Cut at a line end: the samples end before the arc the header states.
        let cut = VALID.lines().take(16).map(|l| format!("{l}\n")).collect::<String>();
        error_at(
            &cut,
            16,
            "the run ends early: its samples sweep 0.04° of the 0.15° its header states (arc_deg) (kept: 4 samples (lines 13-16), t_s 0 to 0.012 s,",
        );
        // Cut inside the last number: the last line has no line end and fewer digits.
        let inside = VALID.trim_end_matches("31\n");
        assert!(inside.ends_with(",0.4"));
        error_at(
            inside,
            17,
            "the last line has no line end and its dR_um \"0.4\" has fewer digits than the line before's \"0.455\": the file looks cut inside a number (kept: 5 samples (lines 13-17), t_s 0 to 0.016 s); if the file is whole, end its last line with a line end",
        );
        // Cut at a line end without the line end, or whole without it: the digits agree.
        parse_run(VALID.trim_end_matches('\n'), FILE).unwrap();
        let e = parse_run(cut.trim_end_matches('\n'), FILE).unwrap_err().to_string();
        assert!(e.contains("the file was cut short (its last line has no line end)"), "{e}");
    }

    #[test]
    fn a_blank_line_among_or_after_the_samples() {
        let e = error_at(&valid_with("0.008,", "\n0.008,"), 15, "blank line");
        assert!(matches!(e, IoError::Format { .. }));
        error_at(&valid_with("0.008,", "  \r\n0.008,"), 15, "blank line");
        // One final line end is the end of the last line; a second one is a blank line.
        error_at(&format!("{VALID}\n"), 18, "blank line");
        error_at(&format!("{}\r\n\r\n", VALID.trim_end()).replace('\n', "\n"), 18, "blank line");
    }

    #[test]
    fn a_hash_line_after_the_column_line() {
        let e = error_at(
            &valid_with("0.008,", "# note: x\n0.008,"),
            15,
            "a '#' line after the column line",
        );
        assert!(matches!(e, IoError::Format { .. }));
        error_at(&format!("{VALID}# end\n"), 18, "'#' line");
    }

    #[test]
    fn errors_name_the_source_as_given() {
        let e = parse_run(&valid_with("0.004,", "x,"), "some dir/run 1.csv").unwrap_err();
        assert!(e.to_string().starts_with("some dir/run 1.csv:14: column t_s:"), "{e}");
    }

    #[test]
    fn no_input_makes_the_reader_panic() {
        // Cut the text at every char boundary, and replace every character with a few others.
        let text = VALID.replace("0.008,", "0.008 , ");
        let n_lines = text.lines().count();
        let check = |t: &str| {
            if let Err(e) = parse_run(t, FILE) {
                let msg = e.to_string();
                assert!(msg.starts_with(&format!("{FILE}:")), "{msg}");
                let line = e.line().unwrap();
                assert!((1..=n_lines + 1).contains(&line), "{msg}");
            }
            let _ = append_column(t, FILE, "m", &[1.0; 5]);
        };
        for (i, _) in text.char_indices() {
            check(&text[..i]);
        }
        for (i, c) in text.char_indices() {
            for r in
                ["", ",", "\n", "\r", "#", ":", " ", "é", "\u{feff}", "9", "-", "e", ".", "\r\n\n"]
            {
                check(&format!("{}{r}{}", &text[..i], &text[i + c.len_utf8()..]));
            }
        }
    }

    // ---- reading files ----

    #[test]
    fn read_run_reads_a_file_and_names_a_missing_one() {
        let dir = crate::test_dir("csv-read");
        let f = dir.join("run.csv");
        std::fs::write(&f, VALID).unwrap();
        let r = read_run(&f).unwrap();
        assert_eq!(r.source, f.to_string_lossy());
        assert_eq!(r.len(), 5);
        let missing = dir.join("missing.csv");
        let e = read_run(&missing).unwrap_err();
        assert!(matches!(e, IoError::Io { ref path, .. } if *path == missing), "{e:?}");
        assert!(e.to_string().contains("missing.csv"), "{e}");
        // Text that is not UTF-8: the line of the first bad byte.
        let mut bytes = VALID.as_bytes().to_vec();
        let at = VALID.find("0.012,").unwrap();
        bytes[at + 2] = 0xff;
        std::fs::write(&f, &bytes).unwrap();
        let e = read_run(&f).unwrap_err();
        assert_eq!(e.line(), Some(16));
        assert!(e.to_string().contains("run.csv:16: the text is not UTF-8"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    // ---- writing ----

    /// A run of `n` samples on the circle of radius 150 about (300, 200, -300) in `plane`, with
    /// the given extra axes (rotary in radians): a full circle CW in 2 s (π rad/s, 28,274
    /// mm/min).
    fn circle_run(plane: Plane, n: usize, rotary: &[Axis]) -> Run {
        let pivot = [300.0, 200.0, -300.0];
        let radius = 150.0;
        let (u, v, _) = plane.axes().unwrap();
        let dt = 2.0 / (n - 1) as f64;
        let t_s: Vec<f64> = (0..n).map(|i| i as f64 * dt + 1e-7 * (i % 3) as f64).collect();
        let mut axes: [Option<Vec<f64>>; 6] = Default::default();
        for a in Axis::LINEAR {
            let col = t_s
                .iter()
                .map(|&t| {
                    let th = 0.3 - std::f64::consts::PI * t;
                    let on = if a == u {
                        radius * th.cos()
                    } else if a == v {
                        radius * th.sin()
                    } else {
                        0.0
                    };
                    pivot[a.index()] + on + 1e-7 * t.sin()
                })
                .collect();
            axes[a.index()] = Some(col);
        }
        for (k, a) in rotary.iter().enumerate() {
            axes[a.index()] =
                Some(t_s.iter().map(|t| -3.0 + 1.7 * t + k as f64 + 1e-9 * t.cos()).collect());
        }
        let dr_mm = t_s.iter().map(|t| 1e-3 * (7.0 * t).sin() * 12.345_678_9).collect();
        Run {
            header: RunHeader {
                format_version: 1,
                machine: Some("column".into()),
                plane,
                direction: Some(Direction::CW),
                radius_mm: radius,
                feed_mm_per_min: 150.0 * std::f64::consts::PI * 60.0,
                pivot_mm: pivot,
                table_ball_mm: [0.1, -2.0 / 3.0, 50.0],
                tool_ball_mm: [0.0, 1e-9, -100.125],
                defaulted: ballbar_model::run::DefaultedKeys::default(),
                started_at: "2026-11-21T10:02:53.097+01:00".into(),
                started_at_unix_s: 1_795_255_200.0 - 3600.0 + 173.097,
                run_id: Some("zx-cw-7".into()),
                extra: vec![
                    ("operator".into(), "A. N. Other: day shift".into()),
                    ("empty".into(), String::new()),
                ],
            },
            source: "memory".into(),
            t_s,
            axes,
            dr_mm,
            lines: Vec::new(),
        }
    }

    /// Every field of `back` equals `run`'s to the written precision.
    fn assert_round_trip(run: &Run, back: &Run, source: &str) {
        // Header numbers use the shortest round-trip form: exact.
        let mut header = run.header.clone();
        header.started_at_unix_s = back.header.started_at_unix_s;
        assert_eq!(back.header, header);
        assert!(close(back.header.started_at_unix_s, run.header.started_at_unix_s, 1e-6));
        assert_eq!(back.source, source);
        assert_eq!(back.len(), run.len());
        let h = &run.header;
        let header_lines = 8
            + [h.machine.is_some(), h.direction.is_some(), h.run_id.is_some()]
                .iter()
                .filter(|x| **x)
                .count()
            + h.extra.len();
        let first_sample = header_lines as u32 + 2;
        assert_eq!(back.lines, (0..run.len() as u32).map(|i| first_sample + i).collect::<Vec<_>>());
        for (a, b) in run.t_s.iter().zip(&back.t_s) {
            assert!(close(*a, *b, 0.5e-6 + 1e-12), "t_s {a} {b}");
        }
        for axis in Axis::ALL {
            match (run.axis(axis), back.axis(axis)) {
                (None, None) => {}
                (Some(x), Some(y)) => {
                    let tol = if axis.is_rotary() { (0.5e-7f64).to_radians() } else { 0.5e-6 };
                    for (p, q) in x.iter().zip(y) {
                        assert!(close(*p, *q, tol + 1e-12), "{axis}: {p} {q}");
                    }
                }
                _ => panic!("axis {axis} present in one run only"),
            }
        }
        for (a, b) in run.dr_mm.iter().zip(&back.dr_mm) {
            assert!(close(*a, *b, 0.5e-4 * 1e-3 + 1e-15), "dR {a} {b}");
        }
    }

    #[test]
    fn round_trip_of_a_linear_run() {
        for plane in Plane::PLANAR {
            let run = circle_run(plane, 50, &[]);
            let text = format_run(&run);
            let back = parse_run(&text, "back.csv").unwrap();
            assert_round_trip(&run, &back, "back.csv");
            // Written again, the text is the same.
            assert_eq!(format_run(&back), text);
        }
    }

    #[test]
    fn round_trip_of_a_run_with_rotary_axes() {
        let run = circle_run(Plane::XY, 40, &[Axis::C, Axis::A]);
        let text = format_run(&run);
        assert!(text.contains("\nt_s,X_mm,Y_mm,Z_mm,A_deg,C_deg,dR_um\n"), "{text}");
        let back = parse_run(&text, "c.csv").unwrap();
        assert_round_trip(&run, &back, "c.csv");
        // C in the file is in degrees, at the simulator's resolution with 7 decimals.
        let text = format_run_rounded(&run);
        assert_round_trip(&run, &parse_run(&text, "c.csv").unwrap(), "c.csv");
        let first = text.lines().nth(14).unwrap();
        let c_deg: f64 = first.split(',').nth(5).unwrap().parse().unwrap();
        assert!(close(c_deg, (-3.0 + 1e-9f64).to_degrees(), 0.5e-7), "{first}");
        assert_eq!(first.split(',').nth(5).unwrap().split('.').nth(1).unwrap().len(), 7);
        // A free run without direction.
        let mut free = run.clone();
        free.header.plane = Plane::Free;
        free.header.direction = None;
        let text = format_run(&free);
        assert!(!text.contains("direction"));
        assert_round_trip(&free, &parse_run(&text, "f.csv").unwrap(), "f.csv");
    }

    #[test]
    fn the_writer_writes_the_spec_example_header_and_number_formats() {
        let text = spec_run();
        let run = parse_run(&text, FILE).unwrap();
        let written = format_run(&run);
        let header: String = text.lines().take(13).map(|l| format!("{l}\n")).collect();
        assert!(written.starts_with(&header), "{written}");
        assert_eq!(
            &written[header.len()..],
            "0.000000,400.000000,200.000000,-300.000000,0.5120\n\
             0.004000,399.999998,200.020944,-300.000000,0.4980\n\
             0.008000,399.999911,200.133333,-300.000000,0.4700\n"
        );
        // Header numbers: shortest round-trip form, no exponent.
        let mut r = run.clone();
        r.header.radius_mm = 0.1 + 0.2;
        r.header.pivot_mm = [1e-7, -0.0, 123456789.125];
        let w = format_run(&r);
        assert!(w.contains("\n# radius_mm: 0.30000000000000004\n"), "{w}");
        assert!(w.contains("\n# pivot_mm: 0.0000001, -0, 123456789.125\n"), "{w}");
    }

    #[test]
    fn write_run_writes_atomically_and_reads_back() {
        let dir = crate::test_dir("csv-write");
        let f = dir.join("run.csv");
        // A run as read from a file: write_run writes it exactly.
        let run =
            parse_run(&format_run_rounded(&circle_run(Plane::YZ, 30, &[Axis::B])), "m").unwrap();
        write_run(&run, &f, Existing::Keep).unwrap();
        write_run(&run, &f, Existing::Replace).unwrap(); // over an existing file
        let back = read_run(&f).unwrap();
        assert_bits_equal(&run, &back);
        // At the simulator's resolution, any run.
        let sim = circle_run(Plane::YZ, 30, &[Axis::B]);
        write_run_rounded(&sim, &f, Existing::Replace).unwrap();
        assert_round_trip(&sim, &read_run(&f).unwrap(), &f.to_string_lossy());
        let names: Vec<_> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("run.csv")]);
        let e = write_run(&run, &dir.join("nope").join("run.csv"), Existing::Keep).unwrap_err();
        assert!(matches!(e, IoError::Io { .. }), "{e:?}");
        assert!(e.to_string().contains("nope") && e.to_string().contains("run.csv"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Every sample value of `a` and `b` the same bit for bit, and the same header.
    fn assert_bits_equal(a: &Run, b: &Run) {
        assert_eq!(a.header, b.header);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.t_s), bits(&b.t_s), "t_s");
        for axis in Axis::ALL {
            assert_eq!(a.axis(axis).map(bits), b.axis(axis).map(bits), "{axis}");
        }
        assert_eq!(bits(&a.dr_mm), bits(&b.dr_mm), "dR");
    }

    /// Whether a run CSV can hold the reading `mm` exactly: the writer's number reads back as it.
    fn holdable(mm: f64) -> bool {
        let mut s = String::new();
        push_value(&mut s, mm, Unit::Micrometres, Numbers::Exact);
        s.parse::<f64>().is_ok_and(|um| um_to_mm(um).to_bits() == mm.to_bits())
    }

    /// A run 0.5 µs a sample with readings of 10 decimals, as a file holds it.
    fn fast_run_text(n: usize) -> String {
        let mut text = String::from(
            "# ballbar-run: 1\n# plane: XY\n# direction: CCW\n# radius_mm: 100\n\
             # feed_mm_per_min: 1000\n# pivot_mm: 0, 0, 0\n# started_at: 2026-11-21T10:00:00Z\n\
             t_s,X_mm,Y_mm,dR_um\n",
        );
        for k in 0..n {
            let t = format!("0.{:07}", 5 * k);
            let th = 1000.0 / 60.0 * t.parse::<f64>().unwrap() / 100.0;
            let reading = 46.363_712_345_6 + 0.012_345_678_9 * k as f64;
            let _ = writeln!(text, "{t},{},{},{reading:.10}", 100.0 * th.cos(), 100.0 * th.sin());
        }
        text
    }

    #[test]
    fn times_half_a_microsecond_apart_and_ten_decimal_readings_are_written_exactly() {
        let run = parse_run(&fast_run_text(40), "fast.csv").unwrap();
        let written = exact_text(&run).unwrap();
        let back = parse_run(&written, "fast.csv").unwrap();
        assert_bits_equal(&run, &back);
        assert!(written.contains("\n0.0000005,"), "{written}");
        assert!(written.contains(",46.3637123456\n"), "{written}");
        // Written again: the same text.
        assert_eq!(format_run(&back), written);
    }

    #[test]
    fn a_file_written_at_the_simulators_resolution_is_written_again_byte_for_byte() {
        let text = format_run_rounded(&circle_run(Plane::XY, 60, &[Axis::C, Axis::A]));
        let run = parse_run(&text, "sim.csv").unwrap();
        assert_eq!(format_run(&run), text);
        assert_eq!(exact_text(&run).unwrap(), text);
    }

    #[test]
    fn random_values_of_every_column_are_written_exactly() {
        // xorshift64*, seeded: values over many magnitudes, as files could hold them.
        let mut state: u64 = 0x9e37_79b9_7f4a_7c15;
        let mut uniform = move || {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut run = circle_run(Plane::XY, 2000, &[Axis::C]);
        run.header.direction = Some(Direction::CCW);
        run.header.started_at_unix_s =
            ballbar_model::time::parse_iso8601(&run.header.started_at).unwrap();
        // The circle at the run's feed, from random steps of 0.1 µs to 10 ms; the positions off
        // the circle by up to 1 µm; readings and rotary angles as the reader makes them from a
        // file's µm and degrees, with 1 to 17 significant digits.
        let (pivot, r) = (run.header.pivot_mm, run.header.radius_mm);
        let w = run.header.feed_mm_per_min / 60.0 / r;
        let mut t = 0.0;
        for i in 0..run.len() {
            t += 10f64.powf(-7.0 + 5.0 * uniform());
            run.t_s[i] = t;
            let th = 0.3 + w * t;
            let x = pivot[0] + r * th.cos() + 1e-3 * (uniform() - 0.5);
            let y = pivot[1] + r * th.sin() + 1e-3 * (uniform() - 0.5);
            run.axes[Axis::X.index()].as_mut().unwrap()[i] = x;
            run.axes[Axis::Y.index()].as_mut().unwrap()[i] = y;
            run.axes[Axis::Z.index()].as_mut().unwrap()[i] = pivot[2];
            let digits = 1 + (17.0 * uniform()) as usize;
            let um: f64 = format!("{:.*e}", digits - 1, 100.0 * (uniform() - 0.5)).parse().unwrap();
            run.dr_mm[i] = um_to_mm(um);
            let deg: f64 =
                format!("{:.*e}", digits - 1, 720.0 * (uniform() - 0.5)).parse().unwrap();
            run.axes[Axis::C.index()].as_mut().unwrap()[i] = deg_to_rad(deg);
        }
        let written = exact_text(&run).unwrap();
        assert_bits_equal(&run, &parse_run(&written, "memory").unwrap());
    }

    #[test]
    fn readings_in_mm_are_taken_as_a_run_csv_holds_them() {
        // Readings of a vendor's file, mm with 5 decimals: some (about 3 %) are no µm number
        // times 1e-3; taken through reading_mm, every one is, within an ulp of the mm value.
        let mut state: u64 = 0x2545_f491_4f6c_dd1d;
        let mut not_holdable = 0;
        for _ in 0..5000 {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            let k = (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as i64 % 20_000 - 10_000;
            let mm: f64 = format!("{:+.5}", k as f64 * 1e-5).parse().unwrap();
            not_holdable += usize::from(!holdable(mm));
            let r = reading_mm(mm);
            assert!(holdable(r), "{mm}: {r}");
            assert!(r == mm || r.next_up() == mm || r.next_down() == mm, "{mm}: {r}");
        }
        assert!(not_holdable > 50, "{not_holdable}");
        assert_eq!(reading_mm(0.0), 0.0);
        assert!(reading_mm(f64::NAN).is_nan());
    }

    #[test]
    fn a_value_a_run_csv_cannot_hold_is_named_and_not_written() {
        let mut run = parse_run(VALID, FILE).unwrap();
        let mut mm = 0.000_463_637;
        while holdable(mm) {
            mm = mm.next_up();
        }
        run.dr_mm[2] = mm;
        let e = exact_text(&run).unwrap_err();
        assert!(
            e.starts_with("it would not read back exactly: line 15: column dR_um: the run holds ")
                && e.contains("no number of µm converts back to it"),
            "{e}"
        );
        let dir = crate::test_dir("csv-inexact");
        let f = dir.join("run.csv");
        let e = write_run(&run, &f, Existing::Replace).unwrap_err();
        assert!(matches!(e, IoError::Unwritable { .. }), "{e:?}");
        assert!(!f.exists());
        // At the simulator's resolution it is written, rounded.
        write_run_rounded(&run, &f, Existing::Replace).unwrap();
        assert!(read_run(&f).unwrap().dr_mm[2] != mm);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn write_run_refuses_a_run_that_would_not_read_back() {
        let dir = crate::test_dir("csv-refuse");
        let f = dir.join("run.csv");
        let good = circle_run(Plane::XY, 10, &[]);
        type Change = Box<dyn Fn(&mut Run)>;
        let cases: Vec<(Change, &str)> = vec![
            (
                Box::new(|r| {
                    r.dr_mm.pop();
                }),
                "column dR_um has 9 values but t_s has 10",
            ),
            (
                Box::new(|r| r.axes[Axis::Y.index()].as_mut().unwrap().push(1.0)),
                "column Y_mm has 11 values",
            ),
            (
                Box::new(|r| r.header.machine = Some("a\nb".into())),
                "\"machine\" contains a line break",
            ),
            (
                Box::new(|r| r.header.extra.push(("comment".into(), "J. Doe\r# plane: YZ".into()))),
                "\"comment\" contains a line break (a carriage return, U+000D)",
            ),
            (
                Box::new(|r| r.header.extra.push(("comment".into(), "a\u{2028}b".into()))),
                "\"comment\" contains a line break (a line separator, U+2028)",
            ),
            (
                Box::new(|r| r.header.run_id = Some("bell\u{7}".into())),
                "\"run_id\" contains a control character (U+0007)",
            ),
            (
                Box::new(|r| r.header.run_id = Some(" id".into())),
                "\"run_id\" starts or ends with a space",
            ),
            (
                Box::new(|r| r.header.extra.push(("plane".into(), "YZ".into()))),
                "\"plane\" would be written twice",
            ),
            (
                Box::new(|r| r.header.extra.push(("operator".into(), "B".into()))),
                "\"operator\" would be written twice",
            ),
            (
                Box::new(|r| r.header.extra.push(("Shift".into(), "B".into()))),
                "header key \"Shift\" is not lower-case",
            ),
            (Box::new(|r| r.header.extra.push(("a: b".into(), "B".into()))), "is not lower-case"),
            (
                Box::new(|r| r.header.machine = Some(String::new())),
                "line 2: header key \"machine\": the value is empty",
            ),
            (
                Box::new(|r| r.header.started_at = "now".into()),
                "line 10: header key \"started_at\"",
            ),
            (Box::new(|r| r.header.radius_mm = f64::NAN), "line 5: header key \"radius_mm\""),
            (
                Box::new(|r| r.t_s[3] = f64::INFINITY),
                "line 18: column t_s: \"inf\" is not a finite number",
            ),
            (Box::new(|r| r.t_s[5] = r.t_s[4]), "line 20: column t_s"),
            (
                Box::new(|r| r.axes[Axis::X.index()].as_mut().unwrap()[2] += 3.0),
                "line 17: the axis coordinates lie",
            ),
            (
                Box::new(|r| r.header.direction = None),
                "line 13: the header lacks the required key direction",
            ),
            (
                Box::new(|r| r.axes[Axis::Y.index()] = None),
                "line 14: column line: a test in plane XY needs the column Y_mm",
            ),
            (
                Box::new(|r| {
                    r.t_s.truncate(2);
                    r.dr_mm.truncate(2);
                    for c in r.axes.iter_mut().flatten() {
                        c.truncate(2);
                    }
                }),
                "at least 3 samples",
            ),
        ];
        for (change, what) in cases {
            let mut run = good.clone();
            change(&mut run);
            let e = write_run(&run, &f, Existing::Replace).unwrap_err();
            let msg = e.to_string();
            assert!(matches!(e, IoError::Unwritable { .. }), "{e:?}");
            assert!(msg.starts_with(&format!("{}: cannot write this run: ", f.display())), "{msg}");
            assert!(msg.contains(what), "expected {what:?} in: {msg}");
            assert!(!f.exists());
            // format_run never panics, even on these.
            let _ = format_run(&run);
        }
        assert!(std::fs::read_dir(&dir).unwrap().next().is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn format_run_writes_nan_for_values_missing_from_a_short_column() {
        let mut run = circle_run(Plane::XY, 4, &[]);
        run.axes[Axis::Z.index()].as_mut().unwrap().truncate(2);
        run.dr_mm.clear();
        let text = format_run(&run);
        let last = text.lines().last().unwrap();
        assert!(last.ends_with(",NaN,NaN"), "{last}");
    }

    // ---- append_column ----

    #[test]
    fn append_column_adds_a_column_and_keeps_every_other_byte() {
        let out = append_column(VALID, FILE, "dR_model_um", &[1.0, -0.5, 1.23456, 0.0, 1234.56789])
            .unwrap();
        let expected = VALID
            .replace(",dR_um\n", ",dR_um,dR_model_um\n")
            .replace(",0.512\n", ",0.512,1.0000\n")
            .replace(",0.498\n", ",0.498,-0.5000\n")
            .replace(",0.470\n", ",0.470,1.2346\n")
            .replace(",0.455\n", ",0.455,0.0000\n")
            .replace(",0.431\n", ",0.431,1234.5679\n");
        assert_eq!(out, expected);
        // The result is a valid run with the same data.
        assert_eq!(parse_run(&out, FILE).unwrap().dr_mm, parse_run(VALID, FILE).unwrap().dr_mm);
    }

    #[test]
    fn append_column_keeps_crlf_mixed_line_ends_spaces_and_a_missing_final_line_end() {
        let crlf = VALID.replace('\n', "\r\n");
        let out = append_column(&crlf, FILE, "m", &[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        assert_eq!(
            out,
            append_column(VALID, FILE, "m", &[1.0, 2.0, 3.0, 4.0, 5.0])
                .unwrap()
                .replace('\n', "\r\n")
        );
        // Mixed, odd spacing, no final line end, a byte-order mark.
        let odd = format!(
            "\u{feff}{}",
            VALID
                .replace("# plane: XY\n", "#plane:XY\r\n")
                .replace("0.008,399.999991,", "0.008 , 399.999991 ,")
        );
        let odd = odd.trim_end_matches('\n').replace(",0.470\n", ",0.470\r\n");
        let out = append_column(&odd, FILE, "m", &[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        let expected = odd
            .replace(",dR_um\n", ",dR_um,m\n")
            .replace(",0.512\n", ",0.512,1.0000\n")
            .replace(",0.498\n", ",0.498,2.0000\n")
            .replace(",0.470\r\n", ",0.470,3.0000\r\n")
            .replace(",0.455\n", ",0.455,4.0000\n")
            + ",5.0000";
        assert_eq!(out, expected);
        assert!(out.starts_with("\u{feff}# ballbar-run: 1\n"));
        parse_run(&out, FILE).unwrap();
        // A last line ending in a lone '\r' (the reader takes it as a line end): kept at the end.
        let cr = format!("{}\r", VALID.trim_end_matches('\n'));
        let out = append_column(&cr, FILE, "m", &[1.0; 5]).unwrap();
        assert!(out.ends_with(",0.431,1.0000\r"), "{out:?}");
        parse_run(&cr, FILE).unwrap();
    }

    #[test]
    fn append_column_replaces_an_existing_column_in_place() {
        let first = append_column(VALID, FILE, "dR_model_um", &[1.0; 5]).unwrap();
        let again = append_column(&first, FILE, "dR_model_um", &[2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        assert_eq!(
            again,
            append_column(VALID, FILE, "dR_model_um", &[2.0, 3.0, 4.0, 5.0, 6.0]).unwrap()
        );
        // A column in the middle, with spaces around its name: replaced where it is.
        let middle = valid_with("t_s,X_mm,Y_mm,Z_mm,dR_um", "t_s,X_mm, m ,Y_mm,Z_mm,dR_um")
            .replace("400.000000,200.000000", "400.000000, old ,200.000000")
            .replace("399.999998,200.020944", "399.999998,,200.020944")
            .replace("399.999991,200.041888", "399.999991,x,200.041888")
            .replace("399.999980,200.062832", "399.999980,1,200.062832")
            .replace("399.999644,200.266666", "399.999965,2,200.083776");
        let out = append_column(&middle, FILE, "m", &[7.0, 8.0, 9.0, 10.0, 11.0]).unwrap();
        let expected = middle
            .replace(", old ,", ",7.0000,")
            .replace("399.999998,,", "399.999998,8.0000,")
            .replace(",x,", ",9.0000,")
            .replace("399.999980,1,", "399.999980,10.0000,")
            .replace("399.999965,2,", "399.999965,11.0000,");
        assert_eq!(out, expected);
        // The first column, and the last.
        let out = append_column(VALID, FILE, "t_s", &[0.0, 1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(
            out,
            VALID
                .replace("\n0.000,", "\n0.0000,")
                .replace("\n0.004,", "\n1.0000,")
                .replace("\n0.008,", "\n2.0000,")
                .replace("\n0.012,", "\n3.0000,")
                .replace("\n0.016,", "\n4.0000,")
        );
        let out = append_column(VALID, FILE, "dR_um", &[0.0, 1.0, 2.0, 3.0, 4.0]).unwrap();
        assert!(out.ends_with(",-300.000000,4.0000\n"), "{out}");
        assert_eq!(out.lines().count(), VALID.lines().count());
    }

    #[test]
    fn append_column_needs_one_value_per_sample_line() {
        let e = append_column(VALID, FILE, "m", &[1.0, 2.0]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "fixtures/x.csv:15: the file has 5 samples, but 2 values were given for column m"
        );
        assert!(matches!(e, IoError::ValueCount { line: 15, samples: 5, values: 2, .. }));
        let e = append_column(VALID, FILE, "m", &[1.0; 6]).unwrap_err();
        assert!(matches!(e, IoError::ValueCount { line: 17, samples: 5, values: 6, .. }), "{e:?}");
        let e = append_column(VALID, FILE, "m", &[]).unwrap_err();
        assert!(matches!(e, IoError::ValueCount { line: 13, samples: 5, values: 0, .. }), "{e:?}");
    }

    #[test]
    fn append_column_rejects_what_it_cannot_write_faithfully() {
        let five = [1.0; 5];
        for bad in ["", "a,b", " m", "m\n", "x\r"] {
            let e = append_column(VALID, FILE, bad, &five).unwrap_err();
            assert!(matches!(e, IoError::Columns { line: 12, .. }), "{bad:?}: {e:?}");
        }
        let e = append_column(VALID, FILE, "m", &[1.0, 2.0, f64::NAN, 4.0, 5.0]).unwrap_err();
        assert_eq!(e.to_string(), "fixtures/x.csv:15: column m: the new value NaN is not finite");
        let e = append_column(&valid_with("0.008,", "\n0.008,"), FILE, "m", &five).unwrap_err();
        assert!(matches!(e, IoError::Format { line: 15, .. }), "{e:?}");
        let e =
            append_column(&valid_with("0.008,", "# x: y\n0.008,"), FILE, "m", &five).unwrap_err();
        assert!(matches!(e, IoError::Format { line: 15, .. }), "{e:?}");
        let e = append_column(&valid_with(",0.470", ",0.470,9"), FILE, "m", &five).unwrap_err();
        assert!(e.to_string().starts_with("fixtures/x.csv:15: 6 fields"), "{e}");
        let e = append_column(&valid_with("Z_mm,dR_um\n", "Z_mm,dR_um,m,m\n"), FILE, "m", &five)
            .unwrap_err();
        assert!(matches!(e, IoError::Columns { line: 12, .. }), "{e:?}");
        let header_only: String = VALID.lines().take(11).map(|l| format!("{l}\n")).collect();
        let e = append_column(&header_only, FILE, "m", &five).unwrap_err();
        assert!(matches!(e, IoError::Format { line: 12, .. }), "{e:?}");
    }
}

//! The file edges of the project: the run CSV (reader, writer, extra columns), Renishaw `.b5r`
//! files, plain tables of angle and reading, the one check every run passes ([`check`]), RON files and
//! atomic writes. Every data error names the file, the line and what is wrong.

use std::path::PathBuf;

pub mod atomic;
pub mod b5r;
pub mod check;
pub mod csv;
pub mod gcode;
// RON files (truth files, saved models) were already here and are used by ballbar-cli and xtask.
pub mod ron_files;
pub mod table;

#[cfg(test)]
mod limits_tests;

#[cfg(test)]
mod fuzz_tests;

pub use atomic::{Existing, write_all_atomic, write_atomic};
pub use csv::{
    append_column, exact_text, format_run, format_run_rounded, parse_run, read_run, run_text,
    run_text_rounded, write_run, write_run_rounded,
};

/// Errors at the file edges.
///
/// Every variant names the file; every variant about the content of a file also names the
/// 1-based line. The `Display` text is complete on its own (`path:line: what is wrong`), so
/// none of the variants reports a separate `source()` error.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The file could not be read or written (the OS error, or a path that is not a file path).
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The structure of the file is wrong: a line that should be `# key: value` is not, a blank
    /// line, a `#` line after the column line, a sample with the wrong number of fields, too few
    /// samples, text that is not UTF-8, a file that ends before the column line.
    #[error("{}:{line}: {message}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A header key or its value is wrong: a key with upper case, a key given twice, an
    /// unsupported format version, a value that does not fit the key.
    #[error("{}:{line}: header key \"{key}\": {message}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the header line.
        line: usize,
        /// The key as written.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// Required header keys are missing: all of them, in the spec's order, in one error.
    #[error(
        "{}:{line}: the header lacks the required {} {} (see docs/run-format.md)",
        path.display(),
        if keys.len() == 1 { "key" } else { "keys" },
        keys.join(", ")
    )]
    MissingKey {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the column line (where the header ends).
        line: usize,
        /// The missing keys, in the order of the spec's table (never empty).
        keys: Vec<String>,
    },
    /// A value of a run's set-up that comes from no line of the file is wrong: a value of an
    /// importer's [`table::TableSetup`], or a header that an importer built and
    /// [`check::check_run`] rejects (a radius that is not a positive number, a planar run
    /// without direction or without one of its in-plane axes, ...).
    #[error("{}: {key}: {message}", path.display())]
    Setup {
        /// The file the run comes from.
        path: PathBuf,
        /// The set-up value, named as the run-CSV header key (`radius_mm`) or the
        /// [`table::TableSetup`] field (`start_angle_deg`).
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The column line is wrong: no `t_s` or `dR_um`, no axis column, a missing in-plane axis,
    /// a column name given twice or empty.
    #[error("{}:{line}: column line: {message}", path.display())]
    Columns {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the column line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A value of a sample is wrong: missing, not a number, not finite, a time that does not
    /// increase.
    #[error("{}:{line}: column {column}: {message}", path.display())]
    Sample {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the sample.
        line: usize,
        /// The column name.
        column: String,
        /// What is wrong.
        message: String,
    },
    /// The axis coordinates of a sample of a planar test do not lie on the circle of radius
    /// `radius_mm` about `pivot_mm` (within the spec's 1 mm).
    #[error(
        "{}:{line}: the axis coordinates lie {distance_mm:.4} mm from pivot_mm, but radius_mm is {radius_mm} (more than 1 mm apart)",
        path.display()
    )]
    Radius {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the sample.
        line: usize,
        /// Distance of the sample's (X, Y, Z) from the pivot, mm.
        distance_mm: f64,
        /// The header's radius, mm.
        radius_mm: f64,
    },
    /// [`append_column`] was given a different number of values than the text has samples.
    #[error(
        "{}:{line}: the file has {samples} samples, but {values} values were given for column {column}",
        path.display()
    )]
    ValueCount {
        /// The file.
        path: PathBuf,
        /// 1-based line: the first sample without a value, or the last line of the file when
        /// values are left over.
        line: usize,
        /// The column being added.
        column: String,
        /// Number of sample lines in the text.
        samples: usize,
        /// Number of values given.
        values: usize,
    },
    /// A run cannot be written as a valid run file (columns of different lengths, a header
    /// value with a line break, a text that would not read back).
    #[error("{}: cannot write this run: {message}", path.display())]
    Unwritable {
        /// The target file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A RON file is wrong.
    #[error("{}:{line}:{column}: {message}", path.display())]
    Ron {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
}

impl IoError {
    /// The 1-based line the error is about, for the variants that have one.
    pub fn line(&self) -> Option<usize> {
        match self {
            IoError::Format { line, .. }
            | IoError::Header { line, .. }
            | IoError::MissingKey { line, .. }
            | IoError::Columns { line, .. }
            | IoError::Sample { line, .. }
            | IoError::Radius { line, .. }
            | IoError::ValueCount { line, .. }
            | IoError::Ron { line, .. } => Some(*line),
            IoError::Io { .. } | IoError::Unwritable { .. } | IoError::Setup { .. } => None,
        }
    }
}

/// The first ```csv block after `heading` in `docs/run-format.md`, for the tests that keep its
/// examples honest.
#[cfg(test)]
pub(crate) fn doc_csv_block(heading: &str) -> &'static str {
    let doc = include_str!("../../../docs/run-format.md");
    let at = doc.find(heading).expect("the section is there");
    doc[at..].split("```csv\n").nth(1).and_then(|b| b.split("```").next()).expect("a csv block")
}

/// The error `result` must be: its message starts with `file:line: ` and contains `what`.
#[cfg(test)]
pub(crate) fn expect_error_at<T>(
    result: Result<T, IoError>,
    file: &str,
    line: usize,
    what: &str,
) -> IoError {
    let e = match result {
        Ok(_) => panic!("expected an error at line {line} ({what}), but it parsed"),
        Err(e) => e,
    };
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("{file}:{line}: ")), "expected line {line}, got: {msg}");
    assert!(msg.contains(what), "expected {what:?} in: {msg}");
    assert_eq!(e.line(), Some(line));
    e
}

/// A fresh, empty folder under the system's temporary folder, for tests.
#[cfg(test)]
pub(crate) fn test_dir(tag: &str) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!(
        "ballbar-io-{tag}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a test folder");
    dir
}

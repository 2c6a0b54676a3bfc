//! Session archives: one self-describing [MCAP](https://mcap.dev) file per measurement session,
//! holding the runs, the input files, the machine, the fit and the diagnosis.
//!
//! Generic MCAP tools (Foxglove, the `mcap` CLI, the Python reader) can list and plot
//! everything: every schema has encoding `jsonschema` and every message encoding `json`.
//! [`write()`] writes atomically; [`read()`] reads the whole file sequentially, checks every
//! CRC and says, when it fails, what was still readable. A CRC of 0 is MCAP's "not computed":
//! [`read_with_checksums()`] says which parts carry none ([`Checksums`]). Each run read is
//! checked as a run file's is (`ballbar_io::check::check_run`).
//!
//! # File layout (archive schema version [`SCHEMA_VERSION`] = 1)
//! MCAP profile `ballbar`, chunks compressed with zstd (each run ends a chunk); chunk,
//! attachment, data-section and summary CRCs written (and checked by [`read()`]); chunk and
//! message indexes and a summary for random access. Records in the data section, in order:
//!
//! 1. **Metadata `ballbar`** (string map): `schema_version`, `software_version`,
//!    `created_unix_s`, `machine_name`, `command` (the command line), and what the file holds:
//!    `runs` and `samples` (counts), `machine`, `fit`, `residuals`, `diagnosis` (`true`/`false`),
//!    `attachments` (count). A reader refuses a `schema_version` newer than its own.
//! 2. **Per run** `k` (in session order; `<name>` is the run id, else the file name, made unique
//!    with `#2`, `#3`, …), each channel with metadata `part` and `run_index` = `k`:
//!    - `/runs/<name>/header`, schema `ballbar.RunHeader`, one message at `started_at`: `index`,
//!      `name`, `file_name`, `source`, `format_version`, `machine`, `plane`, `direction`,
//!      `radius_mm`, `feed_mm_per_min`, `pivot_mm`, `table_ball_mm`, `tool_ball_mm`,
//!      `defaulted` (the ball-position keys the run did not give; left out when empty, and
//!      read as empty from older archives), `started_at` (the string as written), `started_at_unix_s`, `run_id`, `extra` (unknown
//!      header keys, `[key, value]` pairs in order), `columns` (the axis columns present, e.g.
//!      `["X_mm","Y_mm","Z_mm"]`), `samples` (count), `first_line` and, only if the sample
//!      lines are not consecutive, `lines`.
//!    - `/runs/<name>/samples`, schema `ballbar.Sample`, one message per sample at
//!      `started_at + t_s`: `t_s`, the axes present (`x_mm`, `y_mm`, `z_mm`, `a_deg`, `b_deg`,
//!      `c_deg`) and `dr_um`. Values are in the CSV's units, chosen so that converting them the
//!      way the CSV reader does (`deg.to_radians()`, `µm × 1e-3`) gives back the run's internal
//!      value bit for bit; the shortest such decimal is written, so a value read from a CSV
//!      file is stored as the file had it. Where no such value exists (a simulated run can
//!      hold radians that no degree value converts to), the exact internal value is added as
//!      `a_rad`/`b_rad`/`c_rad`/`dr_mm`, and readers use it.
//! 3. **`/machine`** (optional), schema `ballbar.Machine`: `spec` (the `MachineSpec`),
//!    `options` (`ModelOptions`), `plugin_name`, `plugin_version`, `machine_file` (`name`,
//!    `text` of a user's RON chain file, or `null`).
//! 4. **`/fit/parameters`** (optional), schema `ballbar.FitParameters`, one message: each
//!    parameter (`id`, `label`, `unit` display name, `display_factor` internal → display,
//!    `class`, `nuisance`, `value` and `std_uncertainty` in internal units mm/rad/s,
//!    `estimable`), `n_machine`, `rank`, `condition_number`, `sigma_mm`, `dof`, `rho`,
//!    `inflation`, `n_samples`, `singular_values`, `null_space` (`text` and `components`
//!    `{id, amount, unit}`). Non-finite numbers are written as the strings `"NaN"`, `"inf"`,
//!    `"-inf"`.
//!    **`/fit/residuals/<name>`**, schema `ballbar.Residual`, one message per sample of each
//!    run at the sample's time: `t_s`, `residual_um` (and `residual_mm` where `residual_um ×
//!    1e-3` would not give the value back exactly).
//! 5. **`/diagnosis`** (optional), schema `ballbar.Diagnosis`: the diagnosis JSON verbatim.
//! 6. **Attachments**: the input files as given by the caller (normally each run file, name =
//!    file name, media type `text/csv`), at the session's creation time.
//!
//! Message times are nanoseconds since 1970 (`log_time` = `publish_time`); machine, fit and
//! diagnosis messages are at the session's creation time. Sequence numbers are 0 (not
//! assigned). `README.md` beside this crate has the same reference with examples.
//!
//! # Safety
//! [`write()`] streams into `.{name}.{pid}.{n}.tmp` in the destination folder, syncs it and
//! gives it the final name ([`ballbar_io::atomic`]): a process killed while writing leaves no
//! file under the final name and a previous file intact. An existing file is replaced only
//! under [`Existing::Replace`] (keeping its permission bits and owner); under [`Existing::Keep`]
//! a file that took the name while the archive was being written is kept. With [`PAUSE_ENV`] set the writer sleeps after each run (a
//! hook for kill tests). [`read()`] never panics on any input; a truncated file, a checksum
//! mismatch, a file that is not MCAP and a newer archive each give their own [`ArchiveError`]
//! naming the file and what was still readable ([`Readable`]). [`read_partial()`] recovers the
//! runs a damaged archive still holds whole and names what was lost ([`Recovered`]).

use std::fmt;
use std::path::PathBuf;

use ballbar_model::{MachineSpec, ModelOptions, Run};
use serde::{Deserialize, Serialize};

mod json;
mod read;
mod write;

pub use ballbar_io::atomic::Existing;
pub use read::{
    checksums, read, read_bytes, read_partial, read_partial_bytes, read_with_checksums,
};
pub use write::{WritePhase, write, write_observed};

/// The archive schema version this crate writes and the newest it reads.
pub const SCHEMA_VERSION: u32 = 1;

/// Environment variable for kill tests: when set to a number of milliseconds, [`write()`] sleeps
/// that long after each run's samples are on disk in the temporary file.
pub const PAUSE_ENV: &str = "BALLBAR_ARCHIVE_TEST_PAUSE_MS";

/// One measurement session: everything one archive holds.
#[derive(Clone, Debug, PartialEq)]
pub struct Session {
    /// Who wrote it, when, with which command.
    pub info: SessionInfo,
    /// The runs, in order.
    pub runs: Vec<ArchivedRun>,
    /// The machine the runs were fitted with.
    pub machine: Option<ArchivedMachine>,
    /// The fit.
    pub fit: Option<ArchivedFit>,
    /// The diagnosis report (JSON), stored verbatim.
    pub diagnosis: Option<serde_json::Value>,
    /// Files stored as they were (normally the input run files).
    pub attachments: Vec<Attachment>,
}

/// The session metadata (the `ballbar` metadata record).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionInfo {
    /// Version of the software that wrote the archive.
    pub software_version: String,
    /// When the archive was made, seconds since 1970-01-01T00:00:00Z.
    pub created_unix_s: u64,
    /// Name of the machine (type) measured.
    pub machine_name: String,
    /// The command line that made the archive.
    pub command: String,
}

impl SessionInfo {
    /// Metadata stamped with the current time.
    pub fn now(software_version: &str, machine_name: &str, command: &str) -> SessionInfo {
        let created_unix_s = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs());
        SessionInfo {
            software_version: software_version.to_string(),
            created_unix_s,
            machine_name: machine_name.to_string(),
            command: command.to_string(),
        }
    }
}

/// What makes an archived run unusable, as the run-CSV reader would refuse it (at least
/// [`ballbar_io::csv::MIN_SAMPLES`] samples, strictly increasing times, a line per sample when
/// lines are given) or as `export` could not write it back (a file name that is a bare name,
/// not a path): `None` when it is sound. Checked by the writer and the reader.
pub(crate) fn run_problem(r: &ArchivedRun) -> Option<String> {
    let run = &r.run;
    let name = std::path::Path::new(&r.file_name);
    if r.file_name.is_empty()
        || name.file_name().map(|n| n.to_string_lossy()) != Some(r.file_name.as_str().into())
    {
        return Some(format!("file name {:?} is not a bare file name", r.file_name));
    }
    if run.len() < ballbar_io::csv::MIN_SAMPLES {
        return Some(format!(
            "a run needs at least {} samples; it has {}",
            ballbar_io::csv::MIN_SAMPLES,
            run.len()
        ));
    }
    if let Some(i) = run
        .t_s
        .windows(2)
        .position(|w| w[1].partial_cmp(&w[0]) != Some(std::cmp::Ordering::Greater))
    {
        return Some(format!(
            "t_s must increase: sample {} is at {} s after {} s",
            i + 2,
            run.t_s[i + 1],
            run.t_s[i]
        ));
    }
    if !run.lines.is_empty() && run.lines.len() != run.len() {
        return Some(format!("{} line numbers for {} samples", run.lines.len(), run.len()));
    }
    None
}

/// A run and the name of the file it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct ArchivedRun {
    /// The run, internal units (read back bit for bit).
    pub run: Run,
    /// The original file name (`xy-ccw-1.csv`); also the name [`runs_to_csv`] gives it.
    pub file_name: String,
}

impl ArchivedRun {
    /// A run with the file name taken from `run.source` (its last path component).
    pub fn new(run: Run) -> ArchivedRun {
        let file_name = std::path::Path::new(&run.source)
            .file_name()
            .map_or_else(|| run.source.clone(), |n| n.to_string_lossy().into_owned());
        ArchivedRun { run, file_name }
    }
}

/// The machine description used for the session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArchivedMachine {
    /// The machine description.
    pub spec: MachineSpec,
    /// The model variant.
    pub options: ModelOptions,
    /// The plugin that provided it.
    pub plugin_name: String,
    /// The plugin's version.
    pub plugin_version: String,
    /// A user-defined RON chain file, as read.
    pub machine_file: Option<TextFile>,
}

/// A text file stored whole.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TextFile {
    /// File name (or path as given).
    pub name: String,
    /// Its text.
    pub text: String,
}

/// The result of a fit, as archived.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ArchivedFit {
    /// The parameters in column order.
    pub parameters: Vec<FitParameter>,
    /// Number of machine parameters (the leading ones).
    pub n_machine: usize,
    /// Numerical rank.
    pub rank: usize,
    /// σ_max / σ_min over the kept singular values.
    #[serde(with = "json::any_f64")]
    pub condition_number: f64,
    /// Residual standard deviation, mm.
    #[serde(with = "json::any_f64")]
    pub sigma_mm: f64,
    /// Degrees of freedom.
    pub dof: usize,
    /// Lag-one autocorrelation of the residuals within runs.
    #[serde(with = "json::any_f64")]
    pub rho: f64,
    /// Variance inflation applied to the covariance.
    #[serde(with = "json::any_f64")]
    pub inflation: f64,
    /// Number of samples fitted.
    pub n_samples: usize,
    /// Singular values of the column-scaled design, descending.
    #[serde(with = "json::any_f64_vec")]
    pub singular_values: Vec<f64>,
    /// Combinations of parameters the tests cannot separate.
    pub null_space: Vec<NullCombination>,
    /// Residual (reading − model) per run and sample, mm; empty, or one entry per run of the
    /// session with one value per sample (stored on `/fit/residuals/<run>`).
    #[serde(skip)]
    pub residuals: Vec<Vec<f64>>,
}

/// One fitted parameter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitParameter {
    /// Identifier (`EXX1`, `SQXY`, `CX@xy-ccw-1`).
    pub id: String,
    /// Description.
    pub label: String,
    /// Display unit name (`µm`, `µrad`, `ms`, …).
    pub unit: String,
    /// Factor from the internal unit (mm, rad, s) to the display unit.
    #[serde(with = "json::any_f64")]
    pub display_factor: f64,
    /// What it is (`Term(Positional)`, `PlaneMismatch`, `BarLength`, `Centring`).
    pub class: String,
    /// True for nuisance parameters (centring).
    pub nuisance: bool,
    /// Estimate, internal units (minimum-norm when not estimable).
    #[serde(with = "json::any_f64")]
    pub value: f64,
    /// Standard uncertainty, internal units.
    #[serde(with = "json::any_f64")]
    pub std_uncertainty: f64,
    /// Whether the tests determine it on its own.
    pub estimable: bool,
    /// Whether a gauge of the fit fixes it on its own (at 0: an axis at rest, a bar at one
    /// radius), rather than a combination it belongs to (the mean of the servo lags). An
    /// archive without the field reads as `false`.
    #[serde(default)]
    pub fixed: bool,
}

/// A combination of parameters the tests cannot separate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NullCombination {
    /// Human-readable form (`+1 µm EXX1 -0.5 µrad SQXY`); a caller may replace it with a
    /// richer text.
    pub text: String,
    /// The amounts, display units.
    pub components: Vec<NullComponent>,
}

/// One term of a [`NullCombination`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NullComponent {
    /// Parameter id.
    pub id: String,
    /// Amount in the parameter's display unit.
    #[serde(with = "json::any_f64")]
    pub amount: f64,
    /// The display unit.
    pub unit: String,
}

impl ArchivedFit {
    /// The archived form of a fit (residuals included, one entry per run of the fit).
    pub fn from_fit(fit: &ballbar_fit::Fit) -> ArchivedFit {
        let parameters = fit
            .parameters
            .iter()
            .enumerate()
            .map(|(i, p)| FitParameter {
                id: p.id.clone(),
                label: p.label.clone(),
                unit: p.unit.display_name().to_string(),
                display_factor: p.unit.display_factor(),
                class: format!("{:?}", p.class),
                nuisance: p.class.is_nuisance(),
                value: fit.values.get(i).copied().unwrap_or(f64::NAN),
                std_uncertainty: fit.std_uncertainty.get(i).copied().unwrap_or(f64::NAN),
                estimable: fit.estimable.get(i).copied().unwrap_or(false),
                fixed: fit.gauges.iter().any(|g| g.fixes_each() && g.parameters.contains(&i)),
            })
            .collect();
        let null_space = fit
            .null_space
            .iter()
            .map(|c| {
                let components: Vec<NullComponent> = c
                    .components
                    .iter()
                    .filter_map(|&(i, amount)| {
                        let p = fit.parameters.get(i)?;
                        Some(NullComponent {
                            id: p.id.clone(),
                            amount,
                            unit: p.unit.display_name().to_string(),
                        })
                    })
                    .collect();
                let text = components
                    .iter()
                    .map(|c| format!("{:+} {} {}", c.amount, c.unit, c.id))
                    .collect::<Vec<_>>()
                    .join(" ");
                NullCombination { text, components }
            })
            .collect();
        ArchivedFit {
            parameters,
            n_machine: fit.n_machine,
            rank: fit.rank,
            condition_number: fit.condition_number,
            sigma_mm: fit.sigma_mm,
            dof: fit.dof,
            rho: fit.rho,
            inflation: fit.inflation,
            n_samples: fit.n_samples,
            singular_values: fit.singular_values.clone(),
            null_space,
            residuals: fit.residuals.clone(),
        }
    }
}

/// A file stored as it was (an MCAP attachment).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Attachment {
    /// File name.
    pub name: String,
    /// Media type (`text/csv` for run files).
    pub media_type: String,
    /// The bytes.
    pub data: Vec<u8>,
}

impl Attachment {
    /// A run file: media type `text/csv`.
    pub fn csv(name: &str, data: Vec<u8>) -> Attachment {
        Attachment { name: name.to_string(), media_type: "text/csv".to_string(), data }
    }
}

/// What [`write()`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteStats {
    /// Size of the archive, bytes.
    pub bytes: u64,
    /// Samples written (all runs).
    pub samples: usize,
    /// Runs written.
    pub runs: usize,
}

/// Each run as run-CSV text (`ballbar_io::format_run`), with its file name: what an export
/// writes. Two runs with the same file name give two entries with that name.
pub fn runs_to_csv(session: &Session) -> Vec<(String, String)> {
    session.runs.iter().map(|r| (r.file_name.clone(), ballbar_io::format_run(&r.run))).collect()
}

/// How far a failed read got: the parts of the archive that were read and checked before it
/// stopped.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Readable {
    /// The session metadata was read.
    pub metadata: bool,
    /// Runs the metadata announces.
    pub runs_expected: Option<usize>,
    /// Runs whose header was read, in order: name, samples read, samples announced.
    pub runs: Vec<RunProgress>,
    /// The metadata announces a machine description / it was read.
    pub machine: (bool, bool),
    /// The metadata announces a fit / its parameters were read.
    pub fit: (bool, bool),
    /// Runs whose residuals were read completely.
    pub residual_runs: usize,
    /// The metadata announces the fit's residuals.
    pub residuals_expected: bool,
    /// The metadata announces a diagnosis / it was read.
    pub diagnosis: (bool, bool),
    /// Attachments read.
    pub attachments: usize,
    /// Attachments the metadata announces.
    pub attachments_expected: Option<usize>,
}

/// How much of one run was read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RunProgress {
    /// The run's name.
    pub name: String,
    /// Samples read.
    pub samples: usize,
    /// Samples the header announces.
    pub samples_expected: usize,
}

impl Readable {
    /// Runs all of whose samples were read.
    pub fn complete_runs(&self) -> usize {
        self.runs.iter().filter(|r| r.samples == r.samples_expected).count()
    }
}

impl Readable {
    /// What the file holds intact, in file order: `session metadata`, `runs a, b`, `header and
    /// 12 of 40 samples of run c`, `machine`, `fit`, `residuals of 3 runs`, `2 attachments`.
    pub fn intact(&self) -> Vec<String> {
        if !self.metadata {
            return Vec::new();
        }
        let mut out = vec!["session metadata".to_string()];
        let complete: Vec<&str> = self
            .runs
            .iter()
            .filter(|r| r.samples == r.samples_expected)
            .map(|r| r.name.as_str())
            .collect();
        if !complete.is_empty() {
            let noun = if complete.len() == 1 { "run" } else { "runs" };
            out.push(format!("{noun} {}", complete.join(", ")));
        }
        for r in self.runs.iter().filter(|r| r.samples != r.samples_expected) {
            out.push(format!(
                "header and {} of {} samples of run {}",
                r.samples, r.samples_expected, r.name
            ));
        }
        for (name, (_, read)) in [("machine", self.machine), ("fit", self.fit)] {
            if read {
                out.push(name.to_string());
            }
        }
        if self.fit.1 && self.residual_runs > 0 {
            out.push(format!("residuals of {} runs", self.residual_runs));
        }
        if self.diagnosis.1 {
            out.push("diagnosis".to_string());
        }
        if self.attachments > 0 {
            out.push(count(self.attachments, "attachment", "attachments"));
        }
        out
    }

    /// What the metadata announces and the file does not hold intact, in file order: `2 more
    /// runs`, `the rest of run c (28 samples)`, `machine`, `fit`, `residuals of 3 runs`,
    /// `diagnosis`, `6 attachments`. Empty without the metadata (nothing is known to be lost).
    pub fn lost(&self) -> Vec<String> {
        if !self.metadata {
            return Vec::new();
        }
        let mut out = Vec::new();
        for r in self.runs.iter().filter(|r| r.samples != r.samples_expected) {
            out.push(format!(
                "the rest of run {} ({} samples)",
                r.name,
                r.samples_expected.saturating_sub(r.samples)
            ));
        }
        if let Some(n) = self.runs_expected
            && n > self.runs.len()
        {
            let noun = if n - self.runs.len() == 1 { "run" } else { "runs" };
            out.push(format!("{} more {noun}", n - self.runs.len()));
        }
        for (name, (expected, read)) in [("machine", self.machine), ("fit", self.fit)] {
            if expected && !read {
                out.push(name.to_string());
            }
        }
        if self.fit.0
            && self.residuals_expected
            && let Some(n) = self.runs_expected
            && n > self.residual_runs
        {
            let noun = if n - self.residual_runs == 1 { "run" } else { "runs" };
            out.push(format!("the fit's residuals of {} {noun}", n - self.residual_runs));
        }
        if self.diagnosis.0 && !self.diagnosis.1 {
            out.push("diagnosis".to_string());
        }
        if let Some(n) = self.attachments_expected
            && n > self.attachments
        {
            out.push(count(n - self.attachments, "attachment", "attachments"));
        }
        out
    }
}

/// `1 attachment`, `3 attachments`.
fn count(n: usize, one: &str, many: &str) -> String {
    format!("{n} {}", if n == 1 { one } else { many })
}

impl fmt::Display for Readable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.metadata {
            return f.write_str("nothing is readable (the session metadata was not reached)");
        }
        let total = self.runs_expected.map_or_else(|| "?".to_string(), |n| n.to_string());
        // What the file holds, not what a command did with it: a failed read returns nothing.
        write!(
            f,
            "{} of {total} runs are intact in the file (every sample checked); intact: {}",
            self.complete_runs(),
            self.intact().join(", ")
        )?;
        let lost = self.lost();
        if !lost.is_empty() {
            write!(f, "; not readable: {}", lost.join(", "))?;
        }
        Ok(())
    }
}

/// What [`read_partial()`] recovered of an archive.
#[derive(Debug)]
pub struct Recovered {
    /// The session metadata, when it was read.
    pub info: Option<SessionInfo>,
    /// Every run read whole and sound, in session order; a run cut short is not among them.
    pub runs: Vec<ArchivedRun>,
    /// `None` when the archive read whole (`runs` are all of it); otherwise the error [`read()`]
    /// gives, which says what stopped the read and what was intact.
    pub damage: Option<ArchiveError>,
    /// Which parts carry no checksum (of the records read).
    pub checksums: Checksums,
}

/// Which parts of an archive carry a checksum (a CRC32 that [`read()`] checks). MCAP allows a
/// CRC of 0 for "not computed", and a part without one is read unchecked: a file whose CRCs
/// were set to 0 after editing reads as if intact. This crate's writer computes every CRC.
///
/// The data section's CRC covers every record in it (chunks and attachments too); without it,
/// a chunk or an attachment is covered by its own CRC only, and the records outside chunks (the
/// `ballbar` metadata) by none.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Checksums {
    /// The data section's CRC is given; `None` when the file ends (or its damage stops the
    /// reading) before the record that holds it.
    pub data_section: Option<bool>,
    /// Chunks in the file.
    pub chunks: usize,
    /// Chunks whose CRC is 0.
    pub chunks_without: usize,
    /// Attachments in the file.
    pub attachments: usize,
    /// Attachments whose CRC is 0.
    pub attachments_without: usize,
    /// The file has a summary section (the index other MCAP tools read).
    pub summary: bool,
    /// The summary section's CRC is 0.
    pub summary_without: bool,
}

impl Checksums {
    /// The parts in which damage would go unnoticed, for a message; empty when a checksum
    /// covers every part.
    pub fn unchecked(&self) -> Vec<String> {
        let mut parts = Vec::new();
        if self.data_section != Some(true) {
            if self.data_section == Some(false) {
                parts.push("the records outside chunks (the session's metadata)".to_string());
            }
            if self.chunks_without > 0 {
                parts.push(format!(
                    "{} of {} chunks (the runs and what was computed)",
                    self.chunks_without, self.chunks
                ));
            }
            if self.attachments_without > 0 {
                parts.push(format!(
                    "{} of {} attachments (the input files)",
                    self.attachments_without, self.attachments
                ));
            }
        }
        if self.summary_without {
            parts.push("the summary section (the index other MCAP tools read)".to_string());
        }
        parts
    }
}

impl Recovered {
    /// What the archive announces and was not recovered (see [`Readable::lost`]); for a file
    /// that read to its end but is not a valid archive, what stopped its reading.
    pub fn lost(&self) -> Vec<String> {
        match self.damage.as_ref().and_then(ArchiveError::readable) {
            Some(r) => r.lost(),
            None => Vec::new(),
        }
    }
}

/// Errors of writing and reading archives. Every variant names the file; the read errors say
/// what was still readable.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ArchiveError {
    /// The file could not be read, created, written, synced or renamed.
    #[error("{}: {error}", path.display())]
    Io {
        /// The archive.
        path: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
    /// The session cannot be archived faithfully (a non-finite value, columns of different
    /// lengths, residuals that do not match the runs).
    #[error("{}: cannot archive this session: {message}", path.display())]
    Unwritable {
        /// The archive.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file is not an MCAP file at all.
    #[error("{}: not an MCAP archive ({what})", path.display())]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// What it starts with instead.
        what: String,
    },
    /// The file ends early: it was cut short (a copy or a write that did not finish).
    #[error("{}: the archive is truncated (it ends at byte {len} {detail}): {readable}", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Its length, bytes.
        len: u64,
        /// Where it ends.
        detail: String,
        /// What was read before the end.
        readable: Box<Readable>,
    },
    /// The file is damaged: a checksum does not match or a record does not parse.
    #[error("{}: the archive is damaged ({problem}): {readable}", path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// What is wrong, where.
        problem: String,
        /// What was read and checked before the damage.
        readable: Box<Readable>,
    },
    /// The archive was written by a newer version of the software.
    #[error("{}: archive schema version {found} (written by ballbar {software_version}) is newer than this reader's version {supported}; read it with a newer ballbar", path.display())]
    NewerVersion {
        /// The file.
        path: PathBuf,
        /// The archive's schema version.
        found: u32,
        /// [`SCHEMA_VERSION`].
        supported: u32,
        /// The version of the software that wrote it.
        software_version: String,
    },
    /// A valid MCAP file whose content is not a valid ballbar archive (no `ballbar` metadata, a
    /// message that does not match its schema, missing samples).
    #[error("{}: not a valid ballbar archive: {message}; {readable}", path.display())]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
        /// What was read before.
        readable: Box<Readable>,
    },
}

impl ArchiveError {
    /// What stopped the read, without what was readable: `the archive is truncated (it ends at
    /// byte 12577 inside a record: it was cut short)`; the whole message for other errors.
    pub fn problem(&self) -> String {
        match self {
            ArchiveError::Truncated { len, detail, .. } => {
                format!("the archive is truncated (it ends at byte {len} {detail})")
            }
            ArchiveError::Corrupt { problem, .. } => format!("the archive is damaged ({problem})"),
            ArchiveError::Invalid { message, .. } => {
                format!("not a valid ballbar archive: {message}")
            }
            other => other.to_string(),
        }
    }

    /// What was readable, for the read errors that have it.
    pub fn readable(&self) -> Option<&Readable> {
        match self {
            ArchiveError::Truncated { readable, .. }
            | ArchiveError::Corrupt { readable, .. }
            | ArchiveError::Invalid { readable, .. } => Some(&**readable),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests;

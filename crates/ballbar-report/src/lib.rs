//! Reports of a ballbar session: the fit report ([`fit_report`]: terminal text and the
//! `ballbar-fit/1` JSON) and the self-contained HTML page of an archived session ([`page`]),
//! with a compensation's section where one is given ([`compensation`]).

pub mod aliases;
pub mod assumed;
mod cells;
pub mod compensation;
pub mod fit_report;
pub mod history;
pub mod page;
mod rotary;
pub mod session_info;
mod svg;
pub mod tolerance;
pub mod vendor;
pub mod vendor_fit;
pub mod vendor_rank;
pub mod vendor_spikes;
mod vendor_table;
pub mod wording;

pub use fit_report::FitReport;
pub use page::{Page, PageOptions, build, build_with};

#[cfg(test)]
mod tests;

/// Errors of a report.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// The archive cannot be reported.
    #[error("{archive}: {message}")]
    Archive {
        /// The archive's name.
        archive: String,
        /// What is wrong.
        message: String,
    },
    /// A file the report reads (a tolerance file) cannot be read or parsed: the error names
    /// the file, line and column.
    #[error("{0}")]
    File(ballbar_io::IoError),
    /// A value of a tolerance file is wrong.
    #[error("{path}:{line}: {message}")]
    Tolerance {
        /// The file.
        path: String,
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

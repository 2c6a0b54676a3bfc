//! Run CSV, RON files and atomic writes: the file edges of the project. Every data error names
//! the file, the line and what is wrong.

use std::path::PathBuf;

pub mod atomic;
pub mod ron_files;
pub mod run_csv;
pub mod time;

pub use atomic::write_atomic;
pub use run_csv::{append_column, format_run, parse_run, read_run, write_run};

/// Errors at the file edges.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum IoError {
    /// The file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// A line of a data file is wrong.
    #[error("{}:{line}: {message}", path.display())]
    Line {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
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

//! RON files: truth files for the simulator and saved models, read with line and column in
//! every error, written atomically.

use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::IoError;

/// Read and deserialise a RON file.
pub fn read_ron<T: DeserializeOwned>(path: &Path) -> Result<T, IoError> {
    let text = std::fs::read_to_string(path)
        .map_err(|error| IoError::Io { path: path.to_path_buf(), error })?;
    parse_ron(&text, path)
}

/// Deserialise RON text; `path` names it in messages.
pub fn parse_ron<T: DeserializeOwned>(text: &str, path: &Path) -> Result<T, IoError> {
    ron::from_str(text).map_err(|e| IoError::Ron {
        path: path.to_path_buf(),
        line: e.span.start.line,
        column: e.span.start.col,
        message: e.code.to_string(),
    })
}

/// Serialise to pretty RON and write atomically, replacing a file there only as `existing`
/// says.
pub fn write_ron<T: Serialize>(
    value: &T,
    path: &Path,
    existing: crate::atomic::Existing,
) -> Result<(), IoError> {
    let text =
        ron::ser::to_string_pretty(value, ron::ser::PrettyConfig::default()).map_err(|e| {
            IoError::Ron { path: path.to_path_buf(), line: 0, column: 0, message: e.to_string() }
        })?;
    crate::atomic::write_atomic(path, text.as_bytes(), existing)
}

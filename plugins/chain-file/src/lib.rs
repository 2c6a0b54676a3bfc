//! User-defined machines: a plugin that reads a RON chain file at run time and builds its
//! [`MachineSpec`], so that an integrator adds a machine type without compiling anything
//! (`ballbar fit --machine-file my-machine.ron ...`). The format is `docs/chain-files.md`.
//!
//! ```text
//! (
//!     schema: 1, name: "column", version: "1.0.0", description: "...",
//!     joints: [
//!         (name: "Z head",   parent: "base",     axis: Z, kind: Linear, direction: (0, 0, 1), origin_mm: (0, 0, 0)),
//!         (name: "Y saddle", parent: "base",     axis: Y, kind: Linear, direction: (0, 1, 0), origin_mm: (0, 0, 0)),
//!         (name: "X table",  parent: "Y saddle", axis: X, kind: Linear, direction: (1, 0, 0), origin_mm: (0, 0, 0)),
//!     ],
//!     tool: "Z head", workpiece: "X table",
//!     normalisation: [(axis: X, reference_mm: 0, length_mm: 250), ...],
//!     errors: [Paper],
//! )
//! ```
//!
//! Two stages, as ripgrep turns raw flags into a validated config: [`raw`] is the file as
//! written (serde, with every check that one value can decide made while ron reads it, so the
//! error sits at that value), [`validate`] the whole-file checks and the model's own validation
//! ([`ballbar_model::machine::Model::new`]), each error placed in the file by [`locate`]. Every
//! error is `LINE:COLUMN: what`, 1-based, which the host turns into `file:LINE:COLUMN: what`.

use ballbar_model::machine::MachineSpec;

pub mod locate;
pub mod raw;
pub mod validate;

#[cfg(test)]
mod tests;

/// The plugin's name.
pub const NAME: &str = "chain-file";

/// A chain file is wrong at a place.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChainFileError {
    /// 1-based line.
    pub line: usize,
    /// 1-based column, in characters.
    pub column: usize,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for ChainFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}: {}", self.line, self.column, self.message)
    }
}

impl std::error::Error for ChainFileError {}

impl ChainFileError {
    /// ron's error, placed at the first non-blank character of its span: ron's span of a
    /// value of the wrong type starts at the blank before the value. Its positions are 1-based;
    /// the floor keeps a real place even if that ever changed.
    fn from_ron(text: &str, e: ron::error::SpannedError) -> ChainFileError {
        let (mut line, mut column) = (e.span.start.line.max(1), e.span.start.col.max(1));
        let end = (e.span.end.line, e.span.end.col);
        let mut rest = text
            .lines()
            .nth(line - 1)
            .map(|l| l.chars().skip(column - 1).collect::<Vec<char>>())
            .unwrap_or_default();
        // Across the line's blanks, and the line end, toward the end of the span.
        loop {
            if (line, column) >= end {
                break;
            }
            match rest.first() {
                Some(c) if c.is_whitespace() => {
                    rest.remove(0);
                    column += 1;
                }
                None if line < end.0 => {
                    line += 1;
                    column = 1;
                    rest =
                        text.lines().nth(line - 1).map(|l| l.chars().collect()).unwrap_or_default();
                }
                _ => break,
            }
        }
        ChainFileError { line, column, message: e.code.to_string() }
    }
}

/// Read a chain file's text into a validated machine description.
pub fn parse(text: &str) -> Result<MachineSpec, ChainFileError> {
    // The schema first, whatever else the file holds: a newer file says so before anything in
    // it that this plugin does not know.
    let ron_error = |e| ChainFileError::from_ron(text, e);
    ron::Options::default().from_str_seed(text, raw::SchemaProbe).map_err(ron_error)?;
    let file: raw::RawChainFile = ron::Options::default().from_str(text).map_err(ron_error)?;
    validate::validate(text, file)
}

/// The plugin's description: the machine of the chain file `input`, as RON.
fn describe(input: &str) -> Result<String, String> {
    if input.is_empty() {
        return Err(format!(
            "plugin '{NAME}' builds a machine from a chain file and needs one: --machine-file FILE (docs/chain-files.md); it was given no text"
        ));
    }
    let spec = parse(input).map_err(|e| e.to_string())?;
    ron::ser::to_string(&spec)
        .map_err(|e| format!("the machine description could not be written as RON: {e}"))
}

ballbar_plugin_api::declare_plugin! {
    name: NAME,
    version: env!("CARGO_PKG_VERSION"),
    flags: ballbar_plugin_api::FLAG_MACHINE_FILE,
    describe: describe,
    kernels: [],
}

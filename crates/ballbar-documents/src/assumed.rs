//! `assumed`: the defaults taken for runs that change a result (a tool ball not given), one
//! entry per run-header key, in `fit`, `diagnose` and `replay` documents.

use serde::{Deserialize, Serialize};

/// One header key taken at its default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Assumed {
    /// The header key (`tool_ball_mm`).
    pub key: String,
    /// The value taken, mm.
    pub value_mm: [f64; 3],
    /// The runs that did not give it.
    pub runs: Vec<String>,
    /// How many runs there are in all.
    pub of_runs: usize,
    /// What depends on the value taken, in words.
    pub depends: String,
    /// The sentence the terminal and the page give.
    pub note: String,
}

//! The horizontal machining centre of Pahk, Kim & Moon (1997): the column moves X on the bed,
//! the spindle head moves Y (vertical) on the column, the spindle points along Z, and the table
//! moves Z towards it.
//!
//! ```text
//! tool branch:      base ─ X column ─ Y head ─ spindle (gauge point) ─ tool ball
//! workpiece branch: base ─ Z table ─ table ball
//! ```
//! The error set is the paper's, as for the column machine. The Y head rides on the X column,
//! so the column's pitch and yaw act with the head height as Abbe arm: the same 18-function
//! span as eq. (40), with other factors in front.

use ballbar_model::machine::{linear, paper_terms, AxisNorm, MachineSpec};
use ballbar_model::Axis;

/// Machine type name.
pub const NAME: &str = "horizontal";

/// Normalisation length of every axis, mm.
pub const NORM_LENGTH_MM: f64 = 250.0;

/// The machine description.
pub fn machine() -> MachineSpec {
    MachineSpec {
        name: NAME.into(),
        version: env!("CARGO_PKG_VERSION").into(),
        description: "horizontal machining centre (column X, head Y on the column, table Z)".into(),
        tool: vec![linear("X column", Axis::X, [0.0, 0.0, 0.0]), linear("Y head", Axis::Y, [0.0, 0.0, 0.0])],
        workpiece: vec![linear("Z table", Axis::Z, [0.0, 0.0, 0.0])],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

//! The column-type (vertical) machining centre of Pahk, Kim & Moon (1997), section 3: the table
//! moves X on a saddle that moves Y on the bed; the spindle head moves Z on the column.
//!
//! ```text
//! tool branch:      base ─ column ─ Z head ─ spindle (gauge point) ─ tool ball
//! workpiece branch: base ─ Y saddle ─ X table ─ table ball
//! ```
//! Error set (the paper's): positional (degree 1) and straightness (degree 2, pitch and yaw tied)
//! of each axis, squareness XY, YZ, ZX, backlash and servo lag of each axis. The next issue loads
//! this crate as a plugin; for now the binary links it.

use ballbar_model::machine::{linear, paper_terms, AxisNorm, MachineSpec};
use ballbar_model::Axis;

/// Machine type name.
pub const NAME: &str = "column";

/// Normalisation length of every axis, mm: half of a 500 mm travel class, fixed for the
/// machine so that runs at any centre and radius share one model.
pub const NORM_LENGTH_MM: f64 = 250.0;

/// The machine description.
pub fn machine() -> MachineSpec {
    MachineSpec {
        name: NAME.into(),
        version: env!("CARGO_PKG_VERSION").into(),
        description: "column-type vertical machining centre (table X on saddle Y, head Z)".into(),
        tool: vec![linear("Z head", Axis::Z, [0.0, 0.0, 0.0])],
        workpiece: vec![linear("Y saddle", Axis::Y, [0.0, 0.0, 0.0]), linear("X table", Axis::X, [0.0, 0.0, 0.0])],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

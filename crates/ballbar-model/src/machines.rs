//! The paper's two machines (Pahk, Kim & Moon 1997) as machine descriptions: the column-type
//! and the horizontal machining centre, each with the paper's error set ([`paper_terms`]).
//!
//! The bundled plugins `ballbar-machine-column` and `ballbar-machine-horizontal` export these
//! descriptions; tests, benchmarks and the validation suite call them here by name, since two
//! plugins' exported symbols cannot be linked into one binary.

use crate::axis::Axis;
use crate::machine::{AxisNorm, MachineSpec, linear, paper_terms};

/// Machine type name of the column machine ([`column()`]).
pub const COLUMN: &str = "column";

/// Normalisation length of every axis of the column machine, mm: half of a 500 mm travel class,
/// fixed for the machine so that runs at any centre and radius share one model.
pub const COLUMN_NORM_LENGTH_MM: f64 = 250.0;

/// Machine type name of the horizontal machine ([`horizontal()`]).
pub const HORIZONTAL: &str = "horizontal";

/// Normalisation length of every axis of the horizontal machine, mm.
pub const HORIZONTAL_NORM_LENGTH_MM: f64 = 250.0;

/// The column-type (vertical) machining centre of the paper's section 3: the table moves X on a
/// saddle that moves Y on the bed; the spindle head moves Z on the column.
///
/// ```text
/// tool branch:      base ─ column ─ Z head ─ spindle (gauge point) ─ tool ball
/// workpiece branch: base ─ Y saddle ─ X table ─ table ball
/// ```
/// Error set (the paper's): positional (degree 1) and straightness (degree 2, pitch and yaw
/// tied) of each axis, squareness XY, YZ, ZX, backlash and servo lag of each axis.
pub fn column() -> MachineSpec {
    MachineSpec {
        name: COLUMN.into(),
        // The workspace's version, which the plugins that export the machine share.
        version: env!("CARGO_PKG_VERSION").into(),
        description: "column-type vertical machining centre (table X on saddle Y, head Z)".into(),
        tool: vec![linear("Z head", Axis::Z, [0.0, 0.0, 0.0])],
        workpiece: vec![
            linear("Y saddle", Axis::Y, [0.0, 0.0, 0.0]),
            linear("X table", Axis::X, [0.0, 0.0, 0.0]),
        ],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: COLUMN_NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

/// The horizontal machining centre of the paper: the column moves X on the bed, the spindle head
/// moves Y (vertical) on the column, the spindle points along Z, and the table moves Z towards
/// it.
///
/// ```text
/// tool branch:      base ─ X column ─ Y head ─ spindle (gauge point) ─ tool ball
/// workpiece branch: base ─ Z table ─ table ball
/// ```
/// The error set is the paper's, as for the column machine. The Y head rides on the X column,
/// so the column's pitch and yaw act with the head height as Abbe arm: the same 18-function
/// span as eq. (40), with other factors in front.
pub fn horizontal() -> MachineSpec {
    MachineSpec {
        name: HORIZONTAL.into(),
        // The workspace's version, which the plugins that export the machine share.
        version: env!("CARGO_PKG_VERSION").into(),
        description: "horizontal machining centre (column X, head Y on the column, table Z)".into(),
        tool: vec![
            linear("X column", Axis::X, [0.0, 0.0, 0.0]),
            linear("Y head", Axis::Y, [0.0, 0.0, 0.0]),
        ],
        workpiece: vec![linear("Z table", Axis::Z, [0.0, 0.0, 0.0])],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: HORIZONTAL_NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

//! The machine description itself, free of the plugin export: tests that need the definition
//! linked statically next to another machine include this file (`#[path]`), since two
//! plugins' exported symbols cannot share one binary.

use ballbar_model::Axis;
use ballbar_model::machine::{AxisNorm, MachineSpec, linear, paper_terms};

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
        workpiece: vec![
            linear("Y saddle", Axis::Y, [0.0, 0.0, 0.0]),
            linear("X table", Axis::X, [0.0, 0.0, 0.0]),
        ],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

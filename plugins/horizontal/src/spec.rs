//! The machine description itself, free of the plugin export: tests that need the definition
//! linked statically next to another machine include this file (`#[path]`), since two
//! plugins' exported symbols cannot share one binary.

use ballbar_model::Axis;
use ballbar_model::machine::{AxisNorm, MachineSpec, linear, paper_terms};

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
        tool: vec![
            linear("X column", Axis::X, [0.0, 0.0, 0.0]),
            linear("Y head", Axis::Y, [0.0, 0.0, 0.0]),
        ],
        workpiece: vec![linear("Z table", Axis::Z, [0.0, 0.0, 0.0])],
        normalisation: Axis::LINEAR
            .iter()
            .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: NORM_LENGTH_MM })
            .collect(),
        terms: paper_terms(),
    }
}

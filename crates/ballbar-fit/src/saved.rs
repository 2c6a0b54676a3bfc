//! The saved model (`--save-model`, RON): the machine description, the model options and the
//! fitted machine parameters, enough for `predict` to replay the model without the plugin.

use ballbar_model::Unit;
use ballbar_model::machine::{MachineSpec, ModelOptions};
use serde::{Deserialize, Serialize};

/// Format tag of saved models.
pub const SAVED_MODEL_FORMAT: &str = "ballbar-model/1";

/// One fitted machine parameter, internal units (mm, rad, s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedParameter {
    /// Identifier.
    pub id: String,
    /// Value in internal units (where not estimable, the gauge's or the minimum-norm value).
    pub value: f64,
    /// Dimension.
    pub unit: Unit,
    /// Standard uncertainty, internal units.
    pub std_uncertainty: f64,
    /// Whether the tests determined it.
    pub estimable: bool,
}

/// A saved model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedModel {
    /// [`SAVED_MODEL_FORMAT`].
    pub format: String,
    /// The machine.
    pub machine: MachineSpec,
    /// Model variant.
    pub options: ModelOptions,
    /// Machine parameters (no per-run nuisances).
    pub parameters: Vec<SavedParameter>,
    /// The plugin that provided the machine (needed again only for its kernel terms).
    #[serde(default)]
    pub plugin: Option<SavedPlugin>,
    /// Effects added to the machine's terms (a diagnosis's accepted effects), in column order.
    #[serde(default)]
    pub effects: Vec<ballbar_model::Effect>,
}

/// The plugin a model was fitted with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedPlugin {
    /// Plugin (machine type) name.
    pub name: String,
    /// Plugin version.
    pub version: String,
}

impl SavedModel {
    /// The machine part of a fit. Non-estimable parameters are saved with the values the fit's
    /// gauges (or the minimum norm) gave them: the prediction of any reading the tests
    /// constrain does not depend on them.
    pub fn from_fit(fit: &crate::Fit, machine: &MachineSpec, options: ModelOptions) -> SavedModel {
        SavedModel {
            format: SAVED_MODEL_FORMAT.into(),
            machine: machine.clone(),
            options,
            parameters: (0..fit.n_machine)
                .map(|i| SavedParameter {
                    id: fit.parameters[i].id.clone(),
                    value: fit.values[i],
                    unit: fit.parameters[i].unit,
                    std_uncertainty: fit.std_uncertainty[i],
                    estimable: fit.estimable[i],
                })
                .collect(),
            plugin: None,
            effects: Vec::new(),
        }
    }
}

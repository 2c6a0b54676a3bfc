//! `vendor_comparison`: our values beside the vendor's own analysis of a `.b5r` file, one entry
//! per vendor feature we compute, in the vendor's units and sign convention (`shared/spec/cli.md`,
//! "`vendor_comparison`"; the mapping of each feature is in `ballbar_report::vendor`).

use serde::{Deserialize, Serialize};

use crate::num;

/// One feature: the vendor's value and ours.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VendorEntry {
    /// The test plane (`XY`).
    #[serde(default)]
    pub plane: String,
    /// The vendor's feature name (`AF_SQUARENESS`).
    #[serde(default)]
    pub feature: String,
    /// The vendor's unit (`µm/m`).
    #[serde(default)]
    pub unit: String,
    /// The vendor's value.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub vendor: f64,
    /// Our computation made with the vendor's conventions (its sample placement, its term set,
    /// its centre), in its unit and sign: it reproduces the vendor's value; `None` where we do
    /// not reproduce the feature (the note says why).
    #[serde(default)]
    pub ours_as_vendor: Option<f64>,
    /// Our best value in the vendor's unit and sign; `None` where we have none.
    #[serde(default)]
    pub ours: Option<f64>,
    /// Its standard uncertainty, where there is one: it includes the spread between the model
    /// forms the data cannot choose between, where that matters.
    #[serde(default)]
    pub ours_u: Option<f64>,
    /// False where the vendor marks its value not to be trusted.
    #[serde(default = "valid")]
    pub vendor_valid: bool,
    /// Where our value comes from, or why we have none or disagree.
    #[serde(default)]
    pub note: String,
    /// Why `ours` and `vendor` differ, where they differ by more than the uncertainties allow:
    /// one sentence with the evidence; absent where they agree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub why: Option<String>,
    /// The run, for per-run features (`AF_CIRCULARITY`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
}

/// A vendor value is taken as valid unless the document says otherwise.
fn valid() -> bool {
    true
}

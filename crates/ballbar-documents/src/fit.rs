//! `ballbar-fit/1`: what `ballbar fit --json` writes: the base model's parameters with their
//! uncertainties and gauges, what the runs cannot determine, the paper's quantities and each
//! run's ISO 230-4 figures before and after the model.
//!
//! Values of parameters the runs cannot determine are `null` (never reported); a parameter or
//! quantity that holds only for a gauge's choice lists that gauge (`conditional_on_gauges`,
//! indices into `gauges`). Units are the display units each entry names (µm, µrad, ms).

use serde::{Deserialize, Serialize};

use crate::assumed::Assumed;
use crate::num;
use crate::vendor::VendorEntry;

/// The value of `format`.
pub const FORMAT: &str = "ballbar-fit/1";

/// The fit document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fit {
    /// [`FORMAT`].
    pub format: String,
    /// The machine's name.
    pub machine: String,
    /// The servo model (`per-axis lag`, `paper plane mismatch`).
    pub servo: String,
    /// Samples fitted.
    pub samples: usize,
    /// Rank, condition and null space of the design.
    pub identifiability: Identifiability,
    /// The residual after the model.
    pub residual: Residual,
    /// The paper's quantities at the first planar run's radius and feed.
    pub paper: Paper,
    /// What was fixed because the runs cannot determine it, and why.
    pub gauges: Vec<Gauge>,
    /// Every parameter, machine parameters first, then the nuisances.
    pub parameters: Vec<Parameter>,
    /// Each run's figures before and after the model.
    pub runs: Vec<RunFigures>,
    /// The hysteresis of each CW/CCW pair before and after the model.
    pub hysteresis: Vec<Hysteresis>,
    /// The defaults taken for the runs that change a result.
    #[serde(default)]
    pub assumed: Vec<Assumed>,
    /// The vendor's own analysis beside ours, when the input carries it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vendor_comparison: Option<Vec<VendorEntry>>,
    /// What each planar test determines where it is: local scales and squareness of the
    /// fitted error field at the circle's centre (not moved by the pivot or the tool length).
    #[serde(default)]
    pub local: Vec<LocalQuantity>,
    /// What the runs cannot tell from the base model (a term it lacks, set-up metadata they
    /// cannot check), with what it moves; `conditional_on_aliases` of a parameter indexes it.
    #[serde(default)]
    pub aliases: Vec<Alias>,
}

/// A local quantity of one planar test.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LocalQuantity {
    /// `local scale X`, `local squareness XY`.
    pub name: String,
    /// The test's plane.
    pub plane: String,
    /// The circle's centre (the runs' pivot), mm.
    pub pivot_mm: [f64; 3],
    /// The tool ball from the gauge point, mm.
    pub tool_ball_mm: [f64; 3],
    /// The runs of the test.
    #[serde(default)]
    pub runs: Vec<String>,
    /// Its estimate (`ppm` for a scale, `µrad` for a squareness, the model's squareness sign).
    pub estimate: Estimate,
}

/// An alias of the base model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Alias {
    /// What (`positional_higher_order`, `straightness_higher_order`, `angular_error`, `pivot`,
    /// `tool_length`).
    pub kind: String,
    /// The axis it concerns.
    #[serde(default)]
    pub axis: Option<String>,
    /// In words.
    #[serde(default)]
    pub description: String,
    /// Set-up metadata rather than a term of the machine.
    #[serde(default)]
    pub metadata: bool,
    /// The base parameters that carry most of it.
    #[serde(default)]
    pub with: Vec<String>,
    /// Share of its energy outside the base model's span.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub visible_share: f64,
    /// The alternative explanation in words (a term sized so that `with[0]` vanishes).
    #[serde(default)]
    pub alternative: Option<String>,
    /// The test that would separate it.
    #[serde(default)]
    pub test_to_separate: String,
    /// The quantities it moves.
    #[serde(default)]
    pub moves: Vec<Move>,
}

/// How an alias moves a reported quantity (display units of `unit`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Move {
    /// A parameter id, or a local quantity's name with its test.
    pub quantity: String,
    /// Its display unit.
    pub unit: String,
    /// The reported value.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub value: f64,
    /// Its statistical standard uncertainty.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub std_uncertainty: f64,
    /// The value if the alternative holds (a term); `None` for metadata.
    #[serde(default)]
    pub alternative: Option<f64>,
    /// The standard uncertainty with half the distance to the alternative in quadrature.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub std_uncertainty_with_alias: f64,
    /// For metadata: the change of the value per 100 mm of it.
    #[serde(default)]
    pub per_100_mm: Option<f64>,
    /// For a term: how much the base takes into the value from the term at its plausible size
    /// (1 µm at L for a polynomial, 5 µrad for an angle).
    #[serde(default)]
    pub at_plausible_size: Option<f64>,
}

/// Rank, condition and null space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Identifiability {
    /// Numerical rank of the column-scaled design.
    pub rank: usize,
    /// Number of parameters.
    pub parameters: usize,
    /// Condition number of the estimable part.
    #[serde(deserialize_with = "num::f64")]
    pub condition_number: f64,
    /// Singular values of the column-scaled design, largest first.
    pub singular_values: Vec<f64>,
    /// The combinations of parameters the runs cannot determine.
    pub null_space: Vec<NullCombination>,
}

/// A combination of parameters the runs cannot determine.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NullCombination {
    /// Its components.
    pub components: Vec<Component>,
    /// The test that would determine it.
    pub test_to_separate: String,
}

/// One parameter's share of a null combination.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Component {
    /// The parameter id.
    pub id: String,
    /// Its amount in the (unit-norm) combination.
    #[serde(deserialize_with = "num::f64")]
    pub amount: f64,
    /// The parameter's display unit.
    pub unit: String,
}

/// The residual after the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Residual {
    /// Its standard deviation, µm.
    #[serde(deserialize_with = "num::f64")]
    pub sigma_um: f64,
    /// Lag-one autocorrelation.
    #[serde(deserialize_with = "num::f64")]
    pub lag1_autocorrelation: f64,
    /// The factor on the uncertainties for that correlation.
    #[serde(deserialize_with = "num::f64")]
    pub uncertainty_inflation: f64,
}

/// The paper's quantities.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Paper {
    /// The radius they are stated at, mm.
    #[serde(deserialize_with = "num::f64")]
    pub radius_mm: f64,
    /// The feed they are stated at, mm/min.
    #[serde(deserialize_with = "num::f64")]
    pub feed_mm_per_min: f64,
    /// Each quantity in the paper's units and in the vendor's.
    pub quantities: Vec<PaperQuantity>,
}

/// One of the paper's quantities.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PaperQuantity {
    /// In the paper's units.
    pub paper: Estimate,
    /// In the vendor's units.
    pub vendor: Estimate,
}

/// A quantity's estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The quantity's name.
    pub name: String,
    /// Its unit.
    pub unit: String,
    /// Its value; `None` where the runs cannot determine it.
    pub value: Option<f64>,
    /// Its standard uncertainty; `None` with the value.
    pub std_uncertainty: Option<f64>,
    /// Whether the runs determine it.
    pub estimable: bool,
    /// The gauges (indices into `gauges`) whose choice it holds for.
    pub conditional_on_gauges: Vec<usize>,
    /// The aliases (indices into `aliases`) that move it.
    #[serde(default)]
    pub conditional_on_aliases: Vec<usize>,
}

/// A gauge: what was fixed because the runs cannot determine it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gauge {
    /// Its kind (`bar_length`, `common_lag`, …).
    pub kind: String,
    /// What it fixes, in words.
    pub what: String,
    /// The choice made.
    pub choice: String,
    /// Why the runs cannot determine it.
    pub why: String,
    /// The test that would.
    pub test_to_separate: String,
    /// The parameters it fixes.
    pub parameters: Vec<String>,
    /// The parameters whose values hold only for its choice.
    pub conditional: Vec<String>,
}

/// One parameter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parameter {
    /// Its id (`EXX1`).
    pub id: String,
    /// What it is, in words.
    pub label: String,
    /// Its display unit.
    pub unit: String,
    /// A nuisance (a run's centring) rather than a machine parameter.
    pub nuisance: bool,
    /// A polynomial term's basis in words (`θ·(X/250 mm)^1`).
    pub basis: Option<String>,
    /// A polynomial term's normalisation.
    pub normalisation: Option<Normalisation>,
    /// Whether the runs determine it.
    pub estimable: bool,
    /// Its value; `None` where not estimable.
    pub value: Option<f64>,
    /// Its standard uncertainty; `None` where not estimable.
    pub std_uncertainty: Option<f64>,
    /// The gauge (index into `gauges`) that sets it to 0, if any.
    pub fixed_by_gauge: Option<usize>,
    /// The gauges whose choice its value holds for.
    pub conditional_on_gauges: Vec<usize>,
    /// The aliases (indices into `aliases`) that move its value: a compensation written from
    /// it holds only for the base model's explanation.
    #[serde(default)]
    pub conditional_on_aliases: Vec<usize>,
    /// Its standard uncertainty with, in quadrature, half the distance to each alternative of
    /// the term aliases that move it (the spread of a choice the runs cannot make); `None`
    /// where no term alias moves it (set-up aliases state their sensitivity instead).
    #[serde(default)]
    pub std_uncertainty_with_aliases: Option<f64>,
}

/// A polynomial term's normalisation: θ·((q − reference)/length)^degree.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalisation {
    /// The axis q.
    pub axis: String,
    /// The reference position, mm.
    #[serde(deserialize_with = "num::f64")]
    pub reference_mm: f64,
    /// The normalisation length, mm.
    #[serde(deserialize_with = "num::f64")]
    pub length_mm: f64,
    /// The degree.
    pub degree: u32,
}

/// One run's figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunFigures {
    /// The run's name.
    pub run: String,
    /// The file it was read from.
    pub file: String,
    /// Its plane.
    pub plane: String,
    /// Its direction (`None` for a free run).
    pub direction: Option<String>,
    /// Its radius, mm.
    #[serde(deserialize_with = "num::f64")]
    pub radius_mm: f64,
    /// Its feed, mm/min.
    #[serde(deserialize_with = "num::f64")]
    pub feed_mm_per_min: f64,
    /// Its samples.
    pub samples: usize,
    /// How its samples were placed on the arc: `feed` (a `.b5r` run at the programmed
    /// feed), `even` (evenly, the feed disagreeing), `vendor` (evenly, the vendor's
    /// convention, `--b5r-angles vendor`) or `recorded` (a run file's own times and
    /// coordinates). Absent in documents written before it (read as empty).
    #[serde(default)]
    pub placement: String,
    /// Before the model (the readings).
    pub before: CircleFigures,
    /// After the model (the residuals).
    pub after: CircleFigures,
}

/// ISO 230-4 figures of a trace, µm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CircleFigures {
    /// RMS.
    #[serde(deserialize_with = "num::f64")]
    pub rms_um: f64,
    /// Circular deviation G about the least-squares circle.
    #[serde(deserialize_with = "num::f64")]
    pub g_um: f64,
    /// Largest radial deviation F max.
    #[serde(deserialize_with = "num::f64")]
    pub f_max_um: f64,
    /// Smallest radial deviation F min.
    #[serde(deserialize_with = "num::f64")]
    pub f_min_um: f64,
}

/// The hysteresis of a CW/CCW pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hysteresis {
    /// The CW run.
    pub cw: String,
    /// The CCW run.
    pub ccw: String,
    /// Before the model, µm.
    #[serde(deserialize_with = "num::f64")]
    pub before_um: f64,
    /// After the model, µm.
    #[serde(deserialize_with = "num::f64")]
    pub after_um: f64,
}

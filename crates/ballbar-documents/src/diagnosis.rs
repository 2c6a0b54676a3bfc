//! `ballbar-diagnosis/1`: what `ballbar diagnose --json` writes, what an archive keeps of a
//! diagnosis and what the report reads back (`shared/spec/cli.md`, "`diagnose --json`").
//!
//! The required fields of the contract are `format`, `machine`, `gap.base_rms_um`,
//! `gap.noise_floor_um`, `gap.where[]` (`plane`, `direction`, `sector_deg`, `share`),
//! `effects[]` (`kind`, `axis`, `held_out_rms_before_um`, `held_out_rms_after_um`, `parameters`)
//! and `aliased[]` (`kind`, `axis`, `with`, `test_to_separate`); the rest extends it. Reading is
//! lenient where an archive written by an older version may lack a field: a number reads as NaN,
//! a list as empty, and what the report must tell apart from empty (no `effects` at all, an
//! effect's `folds`, an aliased effect's `description`) as `None`.
//!
//! # The statistics and names
//! - `f_statistic` (terminal and page: **partial-F**): the added-variable F test of an effect's
//!   columns on all the data, the variance they explain over the noise variance (the noise's
//!   correlation allowed for, `gap.noise_inflation`); a candidate needs χ²(k) at 1e-6 over k
//!   (`declined[].why.needed`). A test statistic without a unit: not ISO 230-4's radial
//!   deviation F of a circle (`f_max_um`/`f_min_um` in the fit document).
//! - `held_out_t`: the held-out gain of an effect over its standard error (across the held-out
//!   groups); an effect is named from 3 (`declined[].why.needed`).
//! - The excess above the noise of an RMS `r` against the floor `f` is `sqrt(max(r² − f², 0))`
//!   (noise and structure add in quadrature; `ballbar_diagnose::excess`): `gap.excess_um` of the
//!   base model's residual. The share of it an effect closes, `1 − excess(after)/excess(before)`
//!   of the held-out RMS figures beside it, is the gap an engineer means and the figure stated
//!   on the terminal and page: `effects[].held_out_excess_closed` (against
//!   `gap.noise_floor_um`), `held_out.excess_closed`, `declined[].why.excess_closed`,
//!   `unexplained.excess_left`, `unexplained.nearest[].excess_closed`.
//! - The floor carries its standard uncertainty, `gap.noise_floor_u_um` (a block jackknife
//!   over `gap.noise_floor_blocks` blocks); the claimed shares their uncertainty,
//!   `effects[].held_out_excess` and `held_out.excess` ([`ExcessShare`]): an interval at
//!   k = 1, or, where the excess before is within two standard uncertainties of zero, not
//!   determined (the share `null`, the bound on the excess beside it).
//! - `shrink` and `shrink_interval`: the fraction by which the held-out RMS itself falls,
//!   `1 − after/before` (noise included), and ±2 jackknife standard errors of it;
//!   `declined[].why.share_of_excess`, `unexplained.share_left` and
//!   `unexplained.nearest[].share_closed`: shares of the excess *energy* (the squared scale);
//!   `gap.where[].share`: the fraction of the gap's energy above the noise in that arc.
//!   Fractions here, percentages on the terminal and page.
//! - `parameters`: `<name>_<unit>` (`amplitude_um`, `tau_ms`).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::assumed::Assumed;
use crate::num;
use crate::vendor::VendorEntry;

/// The value of `format`.
pub const FORMAT: &str = "ballbar-diagnosis/1";

/// The diagnosis document.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Diagnosis {
    /// [`FORMAT`].
    #[serde(default)]
    pub format: String,
    /// The machine's name.
    #[serde(default)]
    pub machine: String,
    /// Where the gap between the base model and the readings lies.
    #[serde(default)]
    pub gap: Gap,
    /// The effects the evidence accepts, most important first; `None` only in a document that
    /// lists none at all (not even an empty list).
    #[serde(default)]
    pub effects: Option<Vec<Effect>>,
    /// Effects the tests cannot separate from the base model.
    #[serde(default)]
    pub aliased: Vec<Aliased>,
    /// The best candidates of each kind and axis that were tried and not accepted, nearest
    /// misses first.
    #[serde(default)]
    pub declined: Vec<Declined>,
    /// What the diagnosis could not describe, and why.
    #[serde(default)]
    pub notes: Vec<String>,
    /// How the data were split for held-out evaluation, in words.
    #[serde(default)]
    pub cross_validation: String,
    /// The schemes of folds used: the primary first.
    #[serde(default)]
    pub folds: Vec<Fold>,
    /// The claim for the accepted effects together.
    #[serde(default)]
    pub held_out: HeldOut,
    /// The gap the accepted effects leave unexplained, when it is most of a significant gap.
    #[serde(default)]
    pub unexplained: Option<Unexplained>,
    /// Candidates screened (grid points included); `None` where not recorded.
    #[serde(default)]
    pub candidates_screened: Option<usize>,
    /// Each run's residual RMS and G before and after the effects.
    #[serde(default)]
    pub runs: Vec<RunFigures>,
    /// The defaults taken for the runs that change a result.
    #[serde(default)]
    pub assumed: Vec<Assumed>,
    /// The vendor's own analysis beside ours, when the input carries it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub vendor_comparison: Option<Vec<VendorEntry>>,
    /// How a change of the runs' mean radius from run to run (the bar's own length) was
    /// treated; `None` in a document that does not say.
    #[serde(default)]
    pub run_radius: Option<RunRadius>,
}

/// How a change of the runs' mean radius from run to run was treated.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunRadius {
    /// `candidate`: the effect `bar_length_drift`, one constant per run, judged as the other
    /// candidates are (not a nuisance of the held-out scoring).
    #[serde(default)]
    pub treatment: String,
    /// `named`, `declined`, `aliased` or `not_tried`.
    #[serde(default)]
    pub status: String,
    /// What it is, its alias and how it was judged, in words.
    #[serde(default)]
    pub description: String,
}

/// How the noise floor was estimated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum NoiseSource {
    /// From the differences of repeated runs (what does not repeat is noise), through their
    /// second differences (what changes slowly between the repeats, a drift, a thermal
    /// growth, a centring, cancels).
    Repeats,
    /// From second differences of the residual (its high-frequency part).
    HighFrequency,
}

impl NoiseSource {
    /// The name in the document (`repeats`, `high_frequency`).
    pub fn name(self) -> &'static str {
        match self {
            NoiseSource::Repeats => "repeats",
            NoiseSource::HighFrequency => "high_frequency",
        }
    }

    /// How the floor was taken, in words (the terminal and the page say it alike).
    pub fn description(self) -> &'static str {
        match self {
            NoiseSource::Repeats => {
                "from the second differences of the differences of repeats, where slow change between them cancels"
            }
            NoiseSource::HighFrequency => {
                "from the second differences of the residual (its high-frequency part)"
            }
        }
    }
}

/// Where the gap lies.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gap {
    /// Residual RMS of the base model over all samples, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub base_rms_um: f64,
    /// The noise floor, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub noise_floor_um: f64,
    /// Its standard uncertainty (k = 1), µm: the spread of the floor refitted with each block
    /// of the data it is estimated from left out in turn (a block jackknife, which counts the
    /// noise's correlation).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub noise_floor_u_um: f64,
    /// The number of those blocks; the u's degrees of freedom are one fewer. `None` where not
    /// recorded.
    #[serde(default)]
    pub noise_floor_blocks: Option<usize>,
    /// The excess of `base_rms_um` above the noise floor, `sqrt(base_rms² − floor²)`, µm: the
    /// gap itself.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_um: f64,
    /// How the noise floor was estimated.
    #[serde(default)]
    pub noise_source: Option<NoiseSource>,
    /// Lag-one autocorrelation of the noise.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub noise_lag1_autocorrelation: f64,
    /// The factor on the noise variance in the diagnosis's F statistics (the noise's
    /// correlation); `None` where not recorded.
    #[serde(default)]
    pub noise_inflation: Option<f64>,
    /// Length of the moving average the noise is seen through, samples (1: none).
    #[serde(default)]
    pub noise_filter_samples: Option<usize>,
    /// The arcs (or planes, or rotary runs) that hold the gap, largest share first.
    #[serde(default, rename = "where")]
    pub where_: Vec<Where>,
    /// By plane × direction × feed.
    #[serde(default)]
    pub groups: Vec<GroupGap>,
    /// By run.
    #[serde(default)]
    pub runs: Vec<RunGap>,
    /// Direction-even and -odd parts of CW/CCW pairs.
    #[serde(default)]
    pub parity: Vec<Parity>,
    /// Largest peaks against angle (orders per revolution).
    #[serde(default)]
    pub angle_spectrum: Vec<Peak>,
    /// Largest peaks against time (Hz).
    #[serde(default)]
    pub time_spectrum: Vec<Peak>,
    /// Largest ripple against each axis's position.
    #[serde(default)]
    pub position_spectrum: Vec<PositionPeak>,
    /// The trend over the session.
    #[serde(default)]
    pub trend: Option<Trend>,
    /// Whether the gap is locked to angle (or axis position) or to time, across feeds.
    #[serde(default)]
    pub locking: Option<Locking>,
}

impl Default for Gap {
    fn default() -> Gap {
        Gap {
            base_rms_um: f64::NAN,
            noise_floor_um: f64::NAN,
            noise_floor_u_um: f64::NAN,
            noise_floor_blocks: None,
            excess_um: f64::NAN,
            noise_source: None,
            noise_lag1_autocorrelation: f64::NAN,
            noise_inflation: None,
            noise_filter_samples: None,
            where_: Vec::new(),
            groups: Vec::new(),
            runs: Vec::new(),
            parity: Vec::new(),
            angle_spectrum: Vec::new(),
            time_spectrum: Vec::new(),
            position_spectrum: Vec::new(),
            trend: None,
            locking: None,
        }
    }
}

/// One arc (or a whole plane, or a whole rotary run) where the gap lies.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Where {
    /// Plane (`free` for a rotary-axis run).
    #[serde(default)]
    pub plane: String,
    /// Direction (`-` for a free run that turns more than one axis).
    #[serde(default)]
    pub direction: String,
    /// Start and end of the arc, degrees (the end may be smaller: the arc wraps through 0°).
    /// For a free run, in its turning axis's own degrees: 0-360 wrapping through 0° for a run
    /// of a whole turn or more, else within the run's travel (an A run from -90° to 30° has
    /// sectors like -90°-(-60°)).
    #[serde(default = "num::nan_pair", deserialize_with = "num::pair")]
    pub sector_deg: [f64; 2],
    /// Share of the total excess energy.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub share: f64,
    /// The axes that reverse inside the arc (none for a free run).
    #[serde(default)]
    pub reversals: Vec<String>,
    /// A free run's turning axis (`C`). Absent for planar entries.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub axis: Option<String>,
    /// A free run's name (its run id). Absent for planar entries: they are of a plane and
    /// direction, every run of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub run: Option<String>,
}

/// Entries of [`Gap::where_`] that are one pattern: the same arc and the same reversals, in
/// several planes or directions (a servo mismatch spread over every run is one line, not six).
/// A rotary run's entry (with its own `run`) is never grouped.
#[derive(Clone, Debug, PartialEq)]
pub struct WhereGroup<'a> {
    /// The entries, in their order in `where_`.
    pub members: Vec<&'a Where>,
}

/// Relative difference under which the members' shares are one share "each" (a pattern over
/// several runs is never split exactly evenly by noise; 10 % of a share keeps 16.7 % and
/// 15.6 % apart when printed to a tenth).
const EACH_SHARE_RELATIVE: f64 = 0.1;

impl WhereGroup<'_> {
    /// The planes and directions, compactly: `XY, YZ, ZX; CW and CCW` when every plane has
    /// every direction, else `XY CW, YZ CCW`.
    pub fn runs_text(&self) -> String {
        let mut planes: Vec<&str> = Vec::new();
        let mut dirs: Vec<&str> = Vec::new();
        for w in &self.members {
            if !planes.contains(&w.plane.as_str()) {
                planes.push(&w.plane);
            }
            if !dirs.contains(&w.direction.as_str()) {
                dirs.push(&w.direction);
            }
        }
        if self.members.len() > 1 && self.members.len() == planes.len() * dirs.len() {
            let dirs = match dirs.len() {
                1 => dirs[0].to_string(),
                _ => format!("{} and {}", dirs[..dirs.len() - 1].join(", "), dirs[dirs.len() - 1]),
            };
            format!("{}; {dirs}", planes.join(", "))
        } else {
            self.members
                .iter()
                .map(|w| format!("{} {}", w.plane, w.direction))
                .collect::<Vec<_>>()
                .join(", ")
        }
    }

    /// The members' shares, as fractions: one value "each" when they agree within
    /// [`EACH_SHARE_RELATIVE`], with their sum; else each.
    pub fn share_text(&self) -> String {
        let shares: Vec<f64> = self.members.iter().map(|w| w.share).collect();
        let (lo, hi) = shares
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        let pct = |x: f64| format!("{:.1} %", 100.0 * x);
        match shares.len() {
            1 => pct(shares[0]),
            _ if hi - lo <= EACH_SHARE_RELATIVE * hi => {
                format!(
                    "{} each, {} together",
                    pct(shares.iter().sum::<f64>() / shares.len() as f64),
                    pct(shares.iter().sum())
                )
            }
            _ => shares.iter().map(|&x| pct(x)).collect::<Vec<_>>().join(", "),
        }
    }

    /// The arc in words: `the whole circle` for 0°-360°, else `175° to 185°`.
    pub fn sector_text(&self) -> String {
        let [a, b] = self.members[0].sector_deg;
        if (b - a - 360.0).abs() < 1e-9 {
            "the whole circle".into()
        } else {
            format!("{a:.0}° to {b:.0}°")
        }
    }
}

/// [`Gap::where_`] with what is one pattern together ([`WhereGroup`]), in the order of each
/// group's first entry.
pub fn grouped_where(where_: &[Where]) -> Vec<WhereGroup<'_>> {
    let mut groups: Vec<WhereGroup<'_>> = Vec::new();
    for w in where_ {
        let joins = |g: &WhereGroup<'_>| {
            let f = g.members[0];
            w.run.is_none()
                && f.run.is_none()
                && f.sector_deg == w.sector_deg
                && f.reversals == w.reversals
                && !g.members.iter().any(|m| m.plane == w.plane && m.direction == w.direction)
        };
        match groups.iter_mut().find(|g| joins(g)) {
            Some(g) => g.members.push(w),
            None => groups.push(WhereGroup { members: vec![w] }),
        }
    }
    groups
}

/// The gap of one plane × direction × feed group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupGap {
    /// Plane.
    pub plane: String,
    /// Direction.
    pub direction: String,
    /// Feed, mm/min.
    #[serde(deserialize_with = "num::f64")]
    pub feed_mm_per_min: f64,
    /// Runs in the group.
    pub runs: Vec<String>,
    /// Residual RMS, µm.
    #[serde(deserialize_with = "num::f64")]
    pub rms_um: f64,
    /// Share of the total excess energy.
    #[serde(deserialize_with = "num::f64")]
    pub share: f64,
}

/// The gap of one run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunGap {
    /// Run name.
    pub run: String,
    /// Residual RMS, µm.
    #[serde(deserialize_with = "num::f64")]
    pub rms_um: f64,
    /// Share of the total excess energy.
    #[serde(deserialize_with = "num::f64")]
    pub share: f64,
}

/// Direction-even and direction-odd parts of a CW/CCW pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Parity {
    /// Plane.
    pub plane: String,
    /// Feed, mm/min.
    #[serde(deserialize_with = "num::f64")]
    pub feed_mm_per_min: f64,
    /// RMS of (r_CW + r_CCW)/2 on a 1° grid, µm.
    #[serde(deserialize_with = "num::f64")]
    pub even_rms_um: f64,
    /// RMS of (r_CW - r_CCW)/2, µm.
    #[serde(deserialize_with = "num::f64")]
    pub odd_rms_um: f64,
}

/// A spectral peak.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Peak {
    /// Order per revolution (angle spectrum) or frequency in Hz (time spectrum).
    #[serde(deserialize_with = "num::f64")]
    pub at: f64,
    /// Amplitude, µm (RMS over the runs of the amplitude of a sinusoid).
    #[serde(deserialize_with = "num::f64")]
    pub amplitude_um: f64,
}

/// The largest ripple against one axis's position.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PositionPeak {
    /// The axis.
    pub axis: String,
    /// Pitch (wavelength along the axis), mm.
    #[serde(deserialize_with = "num::f64")]
    pub pitch_mm: f64,
    /// Amplitude of the ripple along the axis, µm.
    #[serde(deserialize_with = "num::f64")]
    pub amplitude_um: f64,
}

/// The trend over the session.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Trend {
    /// Slope of the run-mean residual against session time within repeated tests, µm/h; NaN
    /// (`null`) where the runs cannot determine it (no test repeated, or too few repeats to
    /// check a line by: `note` says which).
    #[serde(deserialize_with = "num::f64")]
    pub slope_um_per_h: f64,
    /// Standard uncertainty (k = 1) of `slope_um_per_h`, µm/h; NaN (`null`) with it.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub slope_std_uncertainty_um_per_h: f64,
    /// Mean over runs of (end - start) of the residual (start and end do not meet), µm.
    #[serde(deserialize_with = "num::f64")]
    pub closure_um: f64,
    /// Standard uncertainty (k = 1) of `closure_um`, µm: the scatter of the runs' closures, and
    /// never less than the noise allows.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub closure_std_uncertainty_um: f64,
    /// What the slope rests on, or why it is not known (empty in older documents).
    #[serde(default)]
    pub note: String,
    /// What the closure includes besides a drift within the runs (the transient of a reversal
    /// at which the runs start), empty when nothing.
    #[serde(default)]
    pub closure_note: String,
}

/// What the gap is locked to, judged across feeds: a pattern locked to the angle on the circle
/// or to an axis's position sits at the same angles at every feed (its frequency in Hz scales
/// with the feed); a pattern locked to time (a vibration) keeps its frequency in Hz and not
/// its place on the circle.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Locking {
    /// `angle_or_position`, `time`, `undetermined` (neither stands out, or one feed only), or
    /// `none` (no gap above the noise).
    #[serde(default)]
    pub verdict: String,
    /// Correlation of the residual against angle between feeds of the same plane and
    /// direction, energy-weighted; `None` with one feed.
    #[serde(default)]
    pub angle_coherence: Option<f64>,
    /// Correlation between feeds of the residual's power spectrum against time; `None` with
    /// one feed.
    #[serde(default)]
    pub time_coherence: Option<f64>,
    /// The reason in words.
    #[serde(default)]
    pub why: String,
}

/// What an entry of `effects`, `aliased`, `declined` or `unexplained.nearest` is about.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Subject {
    /// The kind (`reversal_spike`, …: `shared/spec/cli.md`).
    #[serde(default)]
    pub kind: String,
    /// The axis that carries it (`X`): the axis whose motion is in error; a pair (`XY`) for
    /// effects of a pair of axes and of neither alone; `None` for effects of no axis.
    #[serde(default)]
    pub axis: Option<String>,
    /// A lateral play's switching axis (the axis whose reversals switch it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub switched_by: Option<String>,
}

impl Subject {
    /// Whether it is of `kind` on `axis`.
    pub fn is(&self, kind: &str, axis: &str) -> bool {
        self.kind == kind && self.axis.as_deref() == Some(axis)
    }
}

/// An accepted effect.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Effect {
    /// Which effect, on which axis.
    #[serde(flatten)]
    pub subject: Subject,
    /// The effect in words.
    #[serde(default)]
    pub description: String,
    /// Held-out RMS of the base model, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_rms_before_um: f64,
    /// Held-out RMS with the effect, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_rms_after_um: f64,
    /// The folds that judged it; `None` where not recorded.
    #[serde(default)]
    pub folds: Option<String>,
    /// Held-out ISO 230-4 G before, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_g_before_um: f64,
    /// Held-out ISO 230-4 G after, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_g_after_um: f64,
    /// The share of the held-out excess above the noise (`gap.noise_floor_um`) it closes:
    /// `1 − excess(after)/excess(before)` of the two RMS figures above; `null` where it is not
    /// determined (`held_out_excess.determined`).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_excess_closed: f64,
    /// That share's uncertainty, or why it is not determined; `None` where not recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out_excess: Option<ExcessShare>,
    /// The fraction by which it lowers the held-out RMS itself, `1 − after/before`.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub shrink: f64,
    /// ±2 jackknife standard errors of the shrink.
    #[serde(default = "num::nan_pair", deserialize_with = "num::pair")]
    pub shrink_interval: [f64; 2],
    /// Its parameters, `<name>_<unit>`.
    #[serde(default, deserialize_with = "num::map")]
    pub parameters: BTreeMap<String, f64>,
    /// The standard uncertainties of those parameters that have one.
    #[serde(default, deserialize_with = "num::map")]
    pub std_uncertainties: BTreeMap<String, f64>,
    /// Its coefficients in the model, as fitted.
    #[serde(default)]
    pub coefficients: Vec<Coefficient>,
    /// The partial-F statistic.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub f_statistic: f64,
    /// The held-out gain over its standard error.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub held_out_t: f64,
    /// A note on what differs from the data or the definition.
    #[serde(default)]
    pub note: Option<String>,
}

/// A coefficient of an effect in the model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Coefficient {
    /// The parameter id.
    pub id: String,
    /// Its value, in `unit`.
    #[serde(deserialize_with = "num::f64")]
    pub value: f64,
    /// Its standard uncertainty, in `unit`.
    #[serde(deserialize_with = "num::f64")]
    pub std_uncertainty: f64,
    /// The display unit.
    pub unit: String,
}

/// An effect the tests cannot separate from the base model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aliased {
    /// Which effect, on which axis.
    #[serde(flatten)]
    pub subject: Subject,
    /// The effect in words; `None` where not recorded.
    #[serde(default)]
    pub description: Option<String>,
    /// The base parameters it would hide in.
    #[serde(default)]
    pub with: Vec<String>,
    /// The extra test that would separate it.
    #[serde(default)]
    pub test_to_separate: String,
    /// Share of its energy outside the base model's span.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub visible_share: f64,
    /// The alternative explanation in words (the term sized so that the base term that carries
    /// it vanishes); `None` where not stated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alternative: Option<String>,
    /// The reported values it moves (as in `ballbar-fit/1`'s `aliases`); empty where not stated.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub moves: Vec<crate::fit::Move>,
}

/// A candidate tried and not accepted.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Declined {
    /// Which effect, on which axis.
    #[serde(flatten)]
    pub subject: Subject,
    /// The candidate in words.
    #[serde(default)]
    pub description: String,
    /// Why it was declined.
    #[serde(default)]
    pub why: Why,
}

/// Why a candidate was declined: the test it did not pass, with its figures (`test` names it).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(tag = "test", rename_all = "snake_case")]
pub enum Why {
    /// Its partial-F statistic is below the level `needed`.
    F {
        /// The partial-F statistic.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        f_statistic: f64,
        /// Its 1e-6 false-alarm level.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        needed: f64,
    },
    /// Its held-out gain is too few standard errors from zero.
    HeldOut {
        /// The partial-F statistic.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        f_statistic: f64,
        /// Held-out RMS before, µm.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_rms_before_um: f64,
        /// Held-out RMS after, µm.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_rms_after_um: f64,
        /// The held-out gain over its standard error.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_t: f64,
        /// The least `held_out_t` that names an effect.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        needed: f64,
        /// The folds.
        #[serde(default)]
        folds: String,
    },
    /// Real but minor: it closes too small a share of what is left above the noise.
    Material {
        /// The partial-F statistic.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        f_statistic: f64,
        /// Held-out RMS before, µm.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_rms_before_um: f64,
        /// Held-out RMS after, µm.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_rms_after_um: f64,
        /// The share of the excess energy above the noise it closes.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        share_of_excess: f64,
        /// The least `share_of_excess` that names an effect.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        needed: f64,
        /// The share of the excess above the noise it closes (the figure stated).
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        excess_closed: f64,
        /// The least `excess_closed` that names an effect.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        excess_closed_needed: f64,
        /// The folds.
        #[serde(default)]
        folds: String,
    },
    /// No held-out folds can judge it.
    Judgeable {
        /// The folds tried.
        #[serde(default)]
        folds_tried: Vec<String>,
    },
    /// Accepted, then made redundant by the other effects named.
    Redundant {
        /// The held-out gain it keeps over its standard error.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        held_out_t: f64,
        /// The least `held_out_t` that names an effect.
        #[serde(default = "num::nan", deserialize_with = "num::f64")]
        needed: f64,
    },
    /// It adds nothing to the accepted effects.
    Rank,
    /// It passes, but the limit on the number of effects was reached.
    Limit,
    /// A test this version does not know, or none recorded.
    #[default]
    #[serde(other)]
    NotRecorded,
}

impl Why {
    /// The test's name in the document (`f`, `held_out`, …).
    pub fn test(&self) -> &'static str {
        match self {
            Why::F { .. } => "f",
            Why::HeldOut { .. } => "held_out",
            Why::Material { .. } => "material",
            Why::Judgeable { .. } => "judgeable",
            Why::Redundant { .. } => "redundant",
            Why::Rank => "rank",
            Why::Limit => "limit",
            Why::NotRecorded => "not_recorded",
        }
    }
}

/// A scheme of folds used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fold {
    /// Its name (`repeats`, `quarters`, `later_runs`, …).
    pub kind: String,
    /// What it holds out, in words.
    pub description: String,
}

/// The held-out figures of the accepted effects together.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// The folds (`None` when there was no candidate to hold anything out for).
    #[serde(default)]
    pub folds: Option<String>,
    /// Held-out RMS of the base model, µm (NaN, written `null`, without folds).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub rms_before_um: f64,
    /// With the accepted effects, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub rms_after_um: f64,
    /// The noise floor, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub noise_floor_um: f64,
    /// `1 - after/before` of the RMS itself.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub shrink: f64,
    /// The share of the excess above the noise the effects close; `null` where it is not
    /// determined (`excess.determined`).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_closed: f64,
    /// The noise floor's standard uncertainty, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub noise_floor_u_um: f64,
    /// That share's uncertainty, or why it is not determined; `None` where not recorded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub excess: Option<ExcessShare>,
}

/// What is known of a held-out share of the excess above the noise
/// (`ballbar_diagnose::excess::share`): the excess energy before, `r₀² − f²`, has a standard
/// uncertainty from the floor's and from the held-out samples' own chance; where it is not
/// two of those above zero, the excess is not told from the noise and the share is not
/// determined.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ExcessShare {
    /// Whether the share is determined.
    #[serde(default)]
    pub determined: bool,
    /// The share at the excess energies ∓ their standard uncertainty (k = 1), low first;
    /// `null`s when not determined.
    #[serde(default = "num::nan_pair", deserialize_with = "num::pair")]
    pub interval: [f64; 2],
    /// The held-out excess before, `sqrt(max(r₀² − f², 0))`, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_before_um: f64,
    /// The bound it lies below, `sqrt(max(r₀² − f², 0) + 2u)`, µm (k = 2).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_before_bound_um: f64,
    /// `u`: the standard uncertainty of the excess energy before, `r₀² − f²`, µm².
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_energy_u_um2: f64,
}

impl Default for HeldOut {
    fn default() -> HeldOut {
        HeldOut {
            folds: None,
            rms_before_um: f64::NAN,
            rms_after_um: f64::NAN,
            noise_floor_um: f64::NAN,
            shrink: f64::NAN,
            excess_closed: f64::NAN,
            noise_floor_u_um: f64::NAN,
            excess: None,
        }
    }
}

/// The gap the accepted effects leave unexplained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Unexplained {
    /// The folds it was measured on.
    #[serde(default)]
    pub folds: Option<String>,
    /// Share of the base model's held-out excess energy over the noise still left.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub share_left: f64,
    /// Share of the base model's held-out excess over the noise still left (the figure
    /// stated): `sqrt(share_left)`.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_left: f64,
    /// RMS of that excess, µm.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_rms_um: f64,
    /// Where the base model's residual has its excess, in words.
    #[serde(default, rename = "where")]
    pub where_: Vec<String>,
    /// The nearest candidates with the share of the gap each closes.
    #[serde(default)]
    pub nearest: Vec<Nearest>,
}

/// A candidate near the unexplained gap.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Nearest {
    /// Which effect, on which axis.
    #[serde(flatten)]
    pub subject: Subject,
    /// The candidate in words.
    #[serde(default)]
    pub description: String,
    /// The share of the base model's held-out excess energy it closes.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub share_closed: f64,
    /// The share of the base model's held-out excess it closes (the figure stated).
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub excess_closed: f64,
}

/// One run's residual RMS and ISO 230-4 G, base model and with the effects, µm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunFigures {
    /// The run's name.
    #[serde(default)]
    pub run: String,
    /// How its samples were placed on the arc, as the fit document's `runs` say it (`feed`,
    /// `even`, `vendor`, `recorded`); absent in documents written before it.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub placement: String,
    /// RMS with the base model.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub rms_before_um: f64,
    /// RMS with the effects.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub rms_after_um: f64,
    /// G with the base model.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub g_before_um: f64,
    /// G with the effects.
    #[serde(default = "num::nan", deserialize_with = "num::f64")]
    pub g_after_um: f64,
}

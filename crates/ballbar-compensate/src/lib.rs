//! Closing the loop: from a saved model and the runs it was fitted to, the terms a compensation
//! can act on, the controller's files (LinuxCNC, [`linuxcnc`]; SINUMERIK, FANUC and HEIDENHAIN
//! through [`tables`]: [`siemens`], [`fanuc`], [`heidenhain`]), the trace the controller will
//! produce after them, and the verdicts of the repeated tests (`../shared/spec/compensate.md`).
//!
//! # From the model's convention to a trim
//! The model states an axis's errors as the tool's position relative to the workpiece minus the
//! commanded one, in the axis's coordinate (`ballbar_model`'s sign conventions): positional
//! `δ_X = Σ θ_k s^k`, `s = (X - X_ref)/L`, and backlash `δ_X = -(B/2) sign(dX/dt)`. A controller
//! adds a trim `t` to the commanded joint position, so the joint goes to `q + t + δ(q + t) ≈ q +
//! t + δ(q)`: the trim that cancels the error is `t = -δ`, which is LinuxCNC's `nominal -
//! actual`. Moving up (`dX/dt > 0`), `t = -Σ θ_k s^k + B/2`; moving down, `-Σ θ_k s^k - B/2`. A
//! positive backlash B is LinuxCNC's `BACKLASH = B`, whose `+B/2` up and `-B/2` down are these
//! trims (tested by hand in [`tests`]).
//!
//! # What is written
//! Backlash, scale (positional degree 1) and positional degrees ≥ 2 of a linear axis go into
//! the joint's table (or `BACKLASH` when the backlash is all there is), when the tests determine
//! them and `|value| ≥ 2u`; one a repeat of the same tests could not verify (`|value| < 6√2 u`,
//! or a correction within `3√2 u` above the controller's resolution) is written and flagged, `verifiable_by_repeat: false` with the sessions that would
//! ([`VERIFIABLE_IN_U`]). A term whose value an alias moves (a curvature the tests cannot
//! tell from a straightness, a scale that moves with it) is not written, its `why` naming the
//! aliases, unless `--include-aliased` names it ([`Options::include_aliased`]): then it is
//! written as fitted and a note says so. A table covers the span the tests measured, or
//! `--travel`; past the measured span a pure slope is extended linearly and a polynomial with a
//! curvature is held at its end values (`extended` in `compensation.json`). Without the runs
//! only a backlash is written. Everything else the model has is listed, not compensated, with
//! why and what would correct it.
//!
//! # Joints
//! An axis's joint is `--joints`' where given, else the existing configuration's layout
//! (`--existing`: `[KINS] KINEMATICS coordinates=`, `[TRAJ] COORDINATES`), else trivkins'
//! default order. A gantry's axis (two joints) is refused unless `--joints` picks one.

mod advice;
pub mod cross;
pub mod fanuc;
pub mod heidenhain;
pub mod linuxcnc;
pub mod reading;
pub mod siemens;
pub mod tables;
pub mod verify;

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::{Axis, ParamClass, Run, TermClass, Unit};
use serde::{Deserialize, Serialize};

/// Format tag of `compensation.json`.
pub const COMPENSATION_FORMAT: &str = "ballbar-compensation/1";

/// The controllers the contract names, and whether this version writes their files.
pub const CONTROLLERS: [(&str, bool); 4] =
    [("linuxcnc", true), ("siemens", true), ("fanuc", true), ("heidenhain", true)];

/// Spacing of a table's nominals where 256 entries allow it, mm: a quadratic of a few µm over
/// a 250 mm normalisation length bends by far less than the trims' 0.1 nm between nominals 1
/// mm apart (`θ h²/(4 L²)` = 1e-8 mm for θ = 2.5 µm).
const NODE_SPACING_MM: f64 = 1.0;

/// A fitted machine parameter as `compensate` and `verify` need it, internal units.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Identifier (`EXX1`, `BX`, `SQXY`, `MXY`).
    pub id: String,
    /// What it is.
    pub class: ParamClass,
    /// Dimension.
    pub unit: Unit,
    /// Value.
    pub value: f64,
    /// Standard uncertainty.
    pub u: f64,
    /// Whether the tests determine it.
    pub estimable: bool,
    /// The aliases it is conditional on, each in words with its alternative value.
    pub aliases: Vec<String>,
}

/// One term of `compensation.json` (values in the model's convention and display units).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Term {
    /// `backlash`, `scale`, `positional`, `straightness`, `squareness`, `servo_mismatch`,
    /// `reversal_spike`, `rotary_location`.
    pub term: String,
    /// The axis (`X`), or the plane of a squareness or plane servo mismatch (`XY`).
    pub axis: String,
    /// The model's parameter; for one side of a reversal transient, its parts' common stem
    /// (`SPXP` for `SPXP0`..`SPXP2`, the reversal at X's positive end; `SPXN` its negative end;
    /// `SPX` for a transient fitted for both sides), [`terms_with`].
    pub id: String,
    /// Polynomial degree (positional, straightness).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degree: Option<u32>,
    /// Value, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_um: Option<f64>,
    /// Standard uncertainty, µm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_um: Option<f64>,
    /// Value, ppm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_ppm: Option<f64>,
    /// Standard uncertainty, ppm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_ppm: Option<f64>,
    /// Value, µrad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_urad: Option<f64>,
    /// Standard uncertainty, µrad.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_urad: Option<f64>,
    /// Value, ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub value_ms: Option<f64>,
    /// Standard uncertainty, ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub u_ms: Option<f64>,
    /// Whether the files act on it.
    pub compensated: bool,
    /// The files that carry it.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub files: Vec<String>,
    /// The span its table covers, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub span_mm: Option<[f64; 2]>,
    /// The span the tests measured on its axis, mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_span_mm: Option<[f64; 2]>,
    /// Whether the table extends it past the measured span (a scale, linearly).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub extended: Option<bool>,
    /// The value a re-measurement should show, from the files as written and interpolated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub predicted_after: Option<f64>,
    /// What the existing compensation (`--existing`) applied of it, the same unit: its tables'
    /// least-squares polynomial over the measured span.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub existing: Option<f64>,
    /// What is written: the existing compensation plus the measured correction, the same unit,
    /// as `existing` is taken. Where the existing tables are no polynomial of the compensated
    /// degrees (a FANUC staircase) the circles read them otherwise, and a positional term's
    /// `written` less `existing` is the measured value plus that difference, which a note gives
    /// ([`reading`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub written: Option<f64>,
    /// Why not compensated, and what would correct it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub why: Option<String>,
    /// The aliases its value is conditional on, with their alternatives.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub conditional_on_aliases: Vec<String>,
    /// An extension: `false` on a written term that a repeat of the same tests could not be
    /// expected to verify, `|value| < 6√2 u` ([`VERIFIABLE_IN_U`]) or a correction within
    /// `3√2 u` above the controller's resolution ([`flag_unverifiable`]): `verify` will read it
    /// `not_resolved` unless more sessions are measured. Absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verifiable_by_repeat: Option<bool>,
    /// An extension, with `verifiable_by_repeat: false`: the sessions of the tests, fitted
    /// together before and after, that would verify it ([`sessions_to_verify`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sessions_to_verify: Option<u32>,
}

impl Term {
    /// `(value, u, unit)` in its display unit.
    pub fn value(&self) -> (f64, f64, &'static str) {
        let pick = |v: Option<f64>, u: Option<f64>| v.map(|v| (v, u.unwrap_or(f64::NAN)));
        if let Some((v, u)) = pick(self.value_um, self.u_um) {
            (v, u, "µm")
        } else if let Some((v, u)) = pick(self.value_ppm, self.u_ppm) {
            (v, u, "ppm")
        } else if let Some((v, u)) = pick(self.value_urad, self.u_urad) {
            (v, u, "µrad")
        } else if let Some((v, u)) = pick(self.value_ms, self.u_ms) {
            (v, u, "ms")
        } else {
            (f64::NAN, f64::NAN, "")
        }
    }
}

impl Term {
    /// The correction the files apply to this term, in its display unit: its value less the
    /// value predicted after them (what the files add to the compensation active during the
    /// tests, as the controller rounds and applies it: with `--existing`, the written value
    /// less the existing one), as `verify` compares it; the value itself where nothing is
    /// predicted.
    pub fn correction(&self) -> f64 {
        let (value, _, _) = self.value();
        self.predicted_after.map_or(value, |p| value - p)
    }

    /// A resolution of the files, `resolution_mm`, in this term's display unit: a length in µm;
    /// a slope (a scale in ppm, a squareness in µrad) as that length over the span the tests
    /// measured (the whole span, where a table's steps add up least), or over 1 m without one;
    /// 0 for a time (a servo lag: no file holds one, so nothing rounds it).
    pub fn resolution(&self, resolution_mm: f64) -> f64 {
        let span_mm = self.measured_span_mm.map_or(1000.0, |[lo, hi]| hi - lo);
        match self.value().2 {
            "ppm" | "µrad" => resolution_mm / span_mm * 1e6,
            "ms" => 0.0,
            _ => resolution_mm * 1e3,
        }
    }

    /// `(value, u, unit)` in its display unit, or why not: a term read from a file
    /// (`compensation.json`, named `file`) must give both its value and its standard
    /// uncertainty, finite, and `u ≥ 0` (a missing `u` would make every comparison with it
    /// fail or, read as 0, tighten it silently).
    pub fn checked_value(&self, file: &str) -> Result<(f64, f64, &'static str), String> {
        let (v, u, unit) = self.value();
        if unit.is_empty() || !v.is_finite() {
            return Err(format!(
                "{file}: term {} ({} {}) has no value (value_um, value_ppm, value_urad or value_ms)",
                self.id, self.term, self.axis
            ));
        }
        if !(u.is_finite() && u >= 0.0) {
            let key = match unit {
                "µm" => "u_um",
                "ppm" => "u_ppm",
                "µrad" => "u_urad",
                _ => "u_ms",
            };
            return Err(format!(
                "{file}: term {} ({} {}) has no standard uncertainty {key} (or not a finite one ≥ 0): verify compares within 3 u and cannot without it",
                self.id, self.term, self.axis
            ));
        }
        Ok((v, u, unit))
    }
}

/// A run's figures before and predicted after, µm: the RMS about the least-squares circle and
/// ISO 230-4's circular deviation G.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Predicted {
    /// The run's id.
    pub run: String,
    /// Its plane (`XY`, `YZ`, `ZX`), an extension: `verify` checks the repeated runs against
    /// it and names the runs that measure a term its runs do not. Absent in a document written
    /// without it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plane: Option<String>,
    /// RMS before, about the least-squares circle.
    pub rms_before_um: f64,
    /// RMS predicted after.
    pub rms_after_um: f64,
    /// G before.
    #[serde(rename = "G_before_um")]
    pub g_before_um: f64,
    /// G predicted after.
    #[serde(rename = "G_after_um")]
    pub g_after_um: f64,
}

/// `compensation.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Compensation {
    /// [`COMPENSATION_FORMAT`].
    pub format: String,
    /// `linuxcnc`.
    pub controller: String,
    /// Every term a compensation could act on, compensated or not.
    pub terms: Vec<Term>,
    /// Each given planar run, before and predicted after.
    pub predicted: Vec<Predicted>,
    /// Joint number of each compensated axis.
    #[serde(default)]
    pub joints: BTreeMap<String, usize>,
    /// What the reader should know (runs not predicted, extensions, aliases).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
    /// The resolution of a written value, mm: what the controller cannot apply finer (FANUC's
    /// detection unit, the files' last decimal elsewhere). `verify` takes a term within it as
    /// corrected; a document without it is read with its controller's ([`resolution_of`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resolution_mm: Option<f64>,
    /// Each predicted run with its trace as predicted after the files (`dr_mm`), in the order
    /// of `predicted`: the caller fits their change from the measured traces for the values a
    /// re-measurement should show of the terms the files do not write (a table's steps move
    /// them through the fit). Not part of the document.
    #[serde(skip)]
    pub predicted_runs: Vec<Run>,
}

impl Compensation {
    /// The resolution of its files, mm: as written, else its controller's.
    pub fn resolution(&self) -> f64 {
        self.resolution_mm.unwrap_or_else(|| resolution_of(&self.controller))
    }
}

/// A controller's resolution of a written value, mm: LinuxCNC's trims to 0.1 nm, SINUMERIK's
/// and HEIDENHAIN's values to 1 nm, FANUC's detection unit (1 µm, IS-B); LinuxCNC's for a
/// controller this version does not write.
pub fn resolution_of(controller: &str) -> f64 {
    match controller {
        "siemens" => siemens::RESOLUTION_MM,
        "fanuc" => fanuc::DETECTION_UNIT_MM,
        "heidenhain" => heidenhain::RESOLUTION_MM,
        _ => linuxcnc::TRIM_RESOLUTION_MM,
    }
}

/// The choices of `compensate`.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// `--travel AXIS=MIN:MAX`, mm.
    pub travel: BTreeMap<Axis, [f64; 2]>,
    /// `--joints X=0,...`: joint numbers (otherwise X, Y, Z, A, B, C are 0 to 5, trivkins'
    /// default order).
    pub joints: BTreeMap<Axis, usize>,
    /// The LinuxCNC compensation active while the tests ran.
    pub existing: Option<linuxcnc::Files>,
    /// The SINUMERIK, FANUC or HEIDENHAIN compensation active while the tests ran, as the
    /// controller applies it.
    pub existing_tables: Option<std::sync::Arc<dyn tables::Existing>>,
    /// `--include-aliased`: terms written although their value is conditional on an alias,
    /// each a parameter id (`EXX1`) or a term (`scale`), matched without regard to case.
    pub include_aliased: Vec<String>,
    /// How the runs read a table that is no polynomial of the compensated degrees
    /// ([`reading`]); without it (no runs, or a caller without the model) tables are taken by
    /// their least-squares polynomials over the measured span.
    pub reading: Option<std::sync::Arc<dyn reading::Reading>>,
    /// The covariance of the model's parameters (the CLI's fit of the runs): the u of a
    /// reversal transient's heights and of the servo lags' differences ([`Covariance`]);
    /// without it (no runs) a height's u is its parts' bound and no lag difference is said.
    pub covariance: Option<std::sync::Arc<dyn Covariance>>,
}

impl Options {
    /// Whether `--include-aliased` names this term (by its id or its kind).
    fn includes_aliased(&self, t: &Term) -> bool {
        self.include_aliased
            .iter()
            .any(|n| n.eq_ignore_ascii_case(&t.id) || n.eq_ignore_ascii_case(&t.term))
    }
}

/// What a parameter is, as a compensation sees it: `(term, axis, degree)`, or `None` for what
/// no compensation acts on (bar length, centring, angular motions, drifts).
fn kind(e: &Estimate) -> Option<(&'static str, String, Option<u32>)> {
    let id = e.id.as_str();
    let ch = |k: usize| id.get(k..k + 1).unwrap_or("").to_string();
    let degree = || id.get(3..).and_then(|d| d.parse::<u32>().ok());
    match e.class {
        ParamClass::Term(TermClass::Positional) => {
            let d = degree()?;
            Some((if d == 1 { "scale" } else { "positional" }, ch(2), Some(d)))
        }
        ParamClass::Term(TermClass::Straightness) => Some(("straightness", ch(2), degree())),
        ParamClass::Term(TermClass::Squareness) => Some(("squareness", id.get(2..)?.into(), None)),
        ParamClass::Term(TermClass::Backlash) => Some(("backlash", ch(1), None)),
        ParamClass::Term(TermClass::ServoLag) => Some(("servo_mismatch", ch(1), None)),
        ParamClass::PlaneMismatch => Some(("servo_mismatch", id.get(1..)?.into(), None)),
        ParamClass::Term(TermClass::RotaryLocation) => Some(("rotary_location", ch(3), None)),
        ParamClass::Term(TermClass::Effect) if id.starts_with("SP") => {
            Some(("reversal_spike", ch(2), None))
        }
        _ => None,
    }
}

/// A term's entry with its value in display units (a scale in ppm of the axis's `L`).
fn entry(e: &Estimate, term: &str, axis: String, degree: Option<u32>, length_mm: f64) -> Term {
    let mut t = Term {
        term: term.into(),
        axis,
        id: e.id.clone(),
        degree,
        value_um: None,
        u_um: None,
        value_ppm: None,
        u_ppm: None,
        value_urad: None,
        u_urad: None,
        value_ms: None,
        u_ms: None,
        compensated: false,
        files: Vec::new(),
        span_mm: None,
        measured_span_mm: None,
        extended: None,
        predicted_after: None,
        existing: None,
        written: None,
        why: None,
        conditional_on_aliases: e.aliases.clone(),
        verifiable_by_repeat: None,
        sessions_to_verify: None,
    };
    let f = e.unit.display_factor();
    match (term, e.unit) {
        ("scale", _) => {
            t.value_ppm = Some(e.value / length_mm * 1e6);
            t.u_ppm = Some(e.u / length_mm * 1e6);
        }
        (_, Unit::Length) => (t.value_um, t.u_um) = (Some(e.value * f), Some(e.u * f)),
        (_, Unit::Angle) => (t.value_urad, t.u_urad) = (Some(e.value * f), Some(e.u * f)),
        (_, Unit::Time) => (t.value_ms, t.u_ms) = (Some(e.value * f), Some(e.u * f)),
        _ => {}
    }
    t
}

/// The normalisation `(reference, length)` of an axis, mm.
fn norm(model: &SavedModel, axis: Axis) -> (f64, f64) {
    model
        .machine
        .normalisation
        .iter()
        .find(|n| n.axis == axis)
        .map_or((0.0, 1.0), |n| (n.reference_mm, n.length_mm))
}

/// The covariance of a fit's machine parameters, as far as `compensate` and `verify` need it:
/// the standard uncertainty of a linear combination of them, and whether the tests determine
/// it. A combination can be determined where its parameters are not (the differences of the
/// axes' servo lags, whose common part no circle at one feed sees), and its uncertainty is not
/// its parts' (a reversal transient's parts are strongly correlated: on the shared real test
/// they reach 15.6 µm for a spike of 2.8 µm).
pub trait Covariance: std::fmt::Debug + Send + Sync {
    /// `(u, estimable)` of `Σ w θ` over `(id, w)`, internal units; `None` where an id is not a
    /// machine parameter of the fit.
    fn combination(&self, weights: &[(&str, f64)]) -> Option<(f64, bool)>;
}

/// A reversal transient's part, `SP<axis><side><k>` (`SPXP0`, `SPXN2`, `SPY1`): `(axis, side,
/// k)` with side `P`, `N` or empty (both sides); `None` for any other id (a machine's spike is
/// `SP<axis>`, one parameter).
fn transient_part(id: &str) -> Option<(Axis, &str, u32)> {
    let rest = id.strip_prefix("SP")?;
    let axis = Axis::from_name(rest.get(..1)?)?;
    let (side, k) = rest.get(1..)?.split_at(rest.len().checked_sub(2)?);
    let k: u32 = k.parse().ok().filter(|k| *k < 3)?;
    matches!(side, "P" | "N" | "").then_some((axis, side, k))
}

/// The reversal transient of `axis` in the model (a machine's term or a diagnosis's effect), as
/// the effect whose [`ballbar_model::Effect::report`] gives its heights, and whether its size is
/// scaled by the feed (its heights are then those at its reference feed).
pub(crate) fn transient_of(
    model: &SavedModel,
    axis: Axis,
) -> Option<(ballbar_model::Effect, bool)> {
    use ballbar_model::Effect;
    use ballbar_model::machine::TermSpec;
    let plain = |e: &Effect| matches!(e, Effect::ReversalTransient { axis: a, .. } if *a == axis);
    model
        .effects
        .iter()
        .find_map(|e| match e {
            Effect::FeedScaled { effect, .. } if plain(effect) => {
                Some((effect.as_ref().clone(), true))
            }
            e if plain(e) => Some((e.clone(), false)),
            _ => None,
        })
        .or_else(|| {
            model.machine.terms.iter().find_map(|t| match t {
                TermSpec::ReversalTransient { axis: a, tau_ms, period_ms, per_side }
                    if *a == axis =>
                {
                    Some((
                        Effect::ReversalTransient {
                            axis,
                            tau_ms: *tau_ms,
                            period_ms: *period_ms,
                            per_side: *per_side,
                        },
                        false,
                    ))
                }
                _ => None,
            })
        })
}

/// One side of a reversal transient as a term: `SP<axis><side>` (`SPXP`, the reversal at X's
/// positive end; `SPXN`, its negative end; `SPX` for a transient fitted once for both), its
/// value the height of the fitted transient at its peak (`Effect::report`'s `amplitude_pos_um`,
/// `amplitude_neg_um` or `amplitude_um`, the figures `diagnose` reports), mm. That height is
/// `Σ_k a_k h_k(t*)` over the side's parts at the fitted peak `t*`
/// (`Effect::linear_parameters`): its u is that combination's, from `cov`; without one (no
/// runs to refit), the bound `Σ_k |h_k(t*)| u_k`, which holds whatever the parts' correlation.
/// Determined when each of its parts is (and, with `cov`, the combination). `None` where the
/// model has no transient of the axis with this side, or a part is missing.
fn spike_side(
    model: &SavedModel,
    estimates: &[Estimate],
    axis: Axis,
    side: &str,
    cov: Option<&dyn Covariance>,
) -> Option<Estimate> {
    let (effect, _) = transient_of(model, axis)?;
    let ballbar_model::Effect::ReversalTransient { per_side, .. } = effect else { return None };
    let sides: &[&str] = if per_side { &["P", "N"] } else { &[""] };
    let at = sides.iter().position(|s| *s == side)?;
    let ids: Vec<String> =
        sides.iter().flat_map(|s| (0..3).map(move |k| format!("SP{axis}{s}{k}"))).collect();
    let parts: Vec<&Estimate> =
        ids.iter().map(|id| estimates.iter().find(|e| e.id == *id)).collect::<Option<_>>()?;
    let coeffs: Vec<f64> = parts.iter().map(|e| e.value).collect();
    let name = match (per_side, at) {
        (false, _) => "amplitude_um",
        (true, 0) => "amplitude_pos_um",
        (true, _) => "amplitude_neg_um",
    };
    let height_um = effect.report(&coeffs).into_iter().find(|(n, _)| n == name)?.1;
    // Weights in µm per mm of each coefficient: per mm, divided by 1e3.
    let w_um = effect.linear_parameters(&coeffs).into_iter().find(|(n, _)| n == name)?.1;
    let weights: Vec<(&str, f64)> =
        ids.iter().zip(&w_um).map(|(id, w)| (id.as_str(), w * 1e-3)).collect();
    let own = &parts[3 * at..3 * at + 3];
    let bound = || weights.iter().zip(&parts).map(|((_, w), e)| (w * e.u).abs()).sum::<f64>();
    let (u, determined) =
        cov.and_then(|c| c.combination(&weights)).unwrap_or_else(|| (bound(), true));
    let mut aliases: Vec<String> = Vec::new();
    for a in own.iter().flat_map(|e| &e.aliases) {
        if !aliases.contains(a) {
            aliases.push(a.clone());
        }
    }
    Some(Estimate {
        id: format!("SP{axis}{side}"),
        class: own[0].class,
        unit: Unit::Length,
        value: height_um * 1e-3,
        u,
        estimable: determined && own.iter().all(|e| e.estimable),
        aliases,
    })
}

/// Every term of the model a compensation could act on, in the model's order, as an entry of
/// `compensation.json` (none compensated yet); with each its estimate. A reversal transient is
/// one term per side ([`terms_with`]), its u without the fit's covariance the bound of its
/// parts'.
pub fn terms(model: &SavedModel, estimates: &[Estimate]) -> Vec<(Term, Estimate)> {
    terms_with(model, estimates, None)
}

/// One parameter's entry as [`terms`] makes it, but never grouped: a reversal transient's
/// part by itself, as a `compensation.json` written before the parts were grouped into sides
/// lists it (`verify` reads such a document); `None` for a parameter no compensation acts on.
pub fn term_of(model: &SavedModel, e: &Estimate) -> Option<Term> {
    let (term, axis, degree) = kind(e)?;
    let l = Axis::from_name(&axis).map_or(1.0, |a| norm(model, a).1);
    Some(entry(e, term, axis, degree, l))
}

/// [`terms`], with the covariance of the estimates: a reversal transient, fitted as three
/// parts per side whose coefficients say nothing by themselves, is one term per side, its value
/// the height the model reports and its u that of the combination (`spike_side`), in place of
/// its parts, at the place of the side's first part.
pub fn terms_with(
    model: &SavedModel,
    estimates: &[Estimate],
    cov: Option<&dyn Covariance>,
) -> Vec<(Term, Estimate)> {
    let mut out = Vec::new();
    let mut sides: BTreeMap<(Axis, String), Option<Estimate>> = BTreeMap::new();
    for e in estimates {
        let Some((term, axis, degree)) = kind(e) else { continue };
        let e = match transient_part(&e.id).filter(|_| term == "reversal_spike") {
            Some((a, side, k)) => {
                let grouped = sides
                    .entry((a, side.to_string()))
                    .or_insert_with(|| spike_side(model, estimates, a, side, cov));
                match (grouped, k) {
                    (Some(s), 0) => s.clone(),
                    (Some(_), _) => continue,
                    (None, _) => e.clone(),
                }
            }
            None => e.clone(),
        };
        let l = Axis::from_name(&axis).map_or(1.0, |a| norm(model, a).1);
        out.push((entry(&e, term, axis, degree, l), e));
    }
    out
}

/// How far a change of the traces moves each term of `terms(model, before)`, in its display
/// unit, by id, from `change`, each parameter's estimate fitted to the change alone: a term of
/// one parameter by the change's value (the fit is linear in the parameters); a reversal
/// transient's side by its height with the change added less its height before, as a height
/// is no linear function of its parts (its peak moves with them).
pub fn moves(
    model: &SavedModel,
    before: &[Estimate],
    change: &[Estimate],
) -> BTreeMap<String, f64> {
    let value = |estimates: &[Estimate]| -> BTreeMap<String, f64> {
        terms(model, estimates).into_iter().map(|(t, _)| (t.id.clone(), t.value().0)).collect()
    };
    let summed: Vec<Estimate> = before
        .iter()
        .map(|b| {
            let d = change.iter().find(|c| c.id == b.id).map_or(0.0, |c| c.value);
            Estimate { value: b.value + d, ..b.clone() }
        })
        .collect();
    let (was, now) = (value(before), value(&summed));
    let mut out = value(change);
    for (id, v) in out.iter_mut() {
        if !change.iter().any(|c| c.id == *id)
            && let (Some(a), Some(b)) = (now.get(id), was.get(id))
        {
            *v = a - b;
        }
    }
    out
}

/// Why a term LinuxCNC's joint compensation cannot take is not written, and what would.
fn why_not_linuxcnc(term: &str) -> &'static str {
    match term {
        "straightness" => {
            "LinuxCNC's joint compensation has no cross-axis table: a straightness is corrected by the guideway's alignment or a controller with cross-axis compensation"
        }
        "squareness" => {
            "LinuxCNC's joint compensation has no cross-axis table: correct the squareness mechanically, or with a kinematics module that shears the axes"
        }
        "servo_mismatch" => {
            "advice, not a table: match the axes' position-loop response (the HAL pid components' P and FF1 gains) so that their lags are equal"
        }
        "reversal_spike" => {
            "advice, not a table: friction/quadrant-glitch compensation is not in LinuxCNC's joint compensation; tune the pid's FF1/bias or the drive's friction compensation"
        }
        "rotary_location" => {
            "correct the rotary axis's location (ISO 230-7) in the kinematics module's parameters; writing LinuxCNC's kinematics parameters is not done yet"
        }
        _ => "LinuxCNC's joint compensation does not take this term",
    }
}

/// The span `[min, max]` of an axis's commanded positions over the runs, mm.
fn measured_span(runs: &[Run], axis: Axis) -> Option<[f64; 2]> {
    let mut span = [f64::INFINITY, f64::NEG_INFINITY];
    for r in runs {
        if let Some(c) = r.axis(axis) {
            for &x in c {
                span = [span[0].min(x), span[1].max(x)];
            }
        }
    }
    (span[1] - span[0] > 1.0).then_some(span)
}

/// The direction LinuxCNC takes at each sample: the sign of the commanded velocity (central
/// differences of the column), the previous one where it is 0, the first one moving before.
pub fn directions(col: &[f64]) -> Vec<bool> {
    let n = col.len();
    let v: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n.saturating_sub(1)));
            col[b] - col[a]
        })
        .collect();
    let mut last = v.iter().find(|x| **x != 0.0).is_none_or(|x| *x > 0.0);
    v.iter()
        .map(|&x| {
            if x != 0.0 {
                last = x > 0.0;
            }
            last
        })
        .collect()
}

/// The compensated correction of one axis: a polynomial over the measured span and a backlash.
#[derive(Clone, Debug)]
struct AxisCorrection {
    /// `(degree, θ)`, mm at `s = 1`.
    positional: Vec<(u32, f64)>,
    /// Backlash, mm.
    backlash: f64,
    reference_mm: f64,
    length_mm: f64,
    /// The span the tests measured on the axis (none without the runs: a backlash only).
    measured: Option<[f64; 2]>,
}

impl AxisCorrection {
    /// Whether the positional correction is a pure slope (a scale), the one polynomial that may
    /// be extended past the measured span.
    fn pure_slope(&self) -> bool {
        self.positional.iter().all(|&(k, _)| k == 1)
    }

    /// The trims that cancel it, mm (module docs): a pure slope linearly everywhere; a
    /// polynomial with a curvature held at its value at the measured span's ends past them.
    fn trim(&self, q: f64, forward: bool) -> f64 {
        let x = match self.measured {
            Some([lo, hi]) if !self.pure_slope() => q.clamp(lo, hi),
            _ => q,
        };
        let p: f64 = self
            .positional
            .iter()
            .map(|&(k, th)| th * ((x - self.reference_mm) / self.length_mm).powi(k as i32))
            .sum();
        let half = 0.5 * self.backlash;
        -p + if forward { half } else { -half }
    }
}

/// The least `|value|/u` of a written term that a repeat of the same tests can be expected to
/// verify. The correction is `c ≈ -value`; `verify` resolves it when `|c| > 6u`
/// ([`verify::RESOLVED_IN_U`]) with `u = √(u_before² + u_after²)`, and a repeat of the same
/// tests on the same machine refits with `u_after ≈ u_before`, so `|value| ≥ 6√2 u_before`
/// (8.49 u). A term written below it (significant, `|value| ≥ 2u`, and so written: withholding
/// a significant correction would leave the error it measures) is flagged at write time,
/// `verifiable_by_repeat: false` with its [`sessions_to_verify`]: on the repeat a correction
/// applied, not loaded or entered with the wrong sign read alike (`not_resolved`, exit 3).
pub const VERIFIABLE_IN_U: f64 = verify::RESOLVED_IN_U * std::f64::consts::SQRT_2;

/// How many sessions of the tests, fitted together before and as many after, a repeat needs to
/// verify a correction of `|value|` with one session's `u`, written at a `resolution` (all in
/// one unit, the term's): each fit's u falls as `1/√n` (independent sessions), and `verify`
/// resolves the correction when `√(2u²/n)` is below both `|value|/6` and `(|value| −
/// resolution)/3` ([`verify::sessions_to_resolve`] with no u before that stays). Without a
/// resolution that is `|value| ≥ 6√2 u/√n`, from `n = 72 u²/value²` on ([`VERIFIABLE_IN_U`]),
/// the least such `n ≥ 1`. `None` where `u` or `value` is not finite, or `|value|` is not above
/// the resolution (no number would: the controller cannot apply it finer).
pub fn sessions_to_verify(value: f64, u: f64, resolution: f64) -> Option<u32> {
    if !value.is_finite() {
        return None;
    }
    verify::sessions_to_resolve(value, 0.0, u * std::f64::consts::SQRT_2, resolution)
}

/// Why a term `flag_unverifiable` flagged may not show on a repeat, in words: its u unknown,
/// its correction not above the controller's resolution (`resolution` in the term's unit), or
/// which bound it misses: `|c| < 6√2 u` ([`VERIFIABLE_IN_U`]), or `|c| − resolution < 3√2 u`.
pub fn unverifiable_reason(t: &Term, resolution: f64) -> String {
    let (_, u, unit) = t.value();
    let c = t.correction().abs();
    if !u.is_finite() {
        "its uncertainty is not known".to_string()
    } else if verify::within_resolution(c, resolution) {
        format!(
            "|c| = {c:.3} {unit} is not above the controller's resolution of {resolution:.3} {unit}"
        )
    } else if c / 6.0 <= (c - resolution) / 3.0 {
        format!("|c| = {:.1} u < {:.1} u", c / u, VERIFIABLE_IN_U)
    } else {
        format!(
            "|c| = {:.1} u, but above the controller's resolution of {resolution:.3} {unit} by only {:.1} u < {:.1} u",
            c / u,
            (c - resolution) / u,
            VERIFIABLE_IN_U / 2.0
        )
    }
}

/// Flag each written term of `comp` that one repeat of the tests could not be expected to
/// verify at the files' resolution ([`Compensation::resolution`], in the term's unit,
/// [`Term::resolution`]): `verifiable_by_repeat: false` with its [`sessions_to_verify`]. The
/// correction counted is the one the files apply, `value − predicted_after` (the written value
/// rounded as the controller takes it), as `verify` compares it: a FANUC backlash of 1.2 µm
/// with u 0.1 µm is 12 u, beyond [`VERIFIABLE_IN_U`], but is written as 1 µm, its detection
/// unit, which a repeat cannot tell from nothing applied (`|c|` not above the resolution): no
/// number of sessions would show it.
pub(crate) fn flag_unverifiable(comp: &mut Compensation) {
    let resolution_mm = comp.resolution();
    for t in comp.terms.iter_mut().filter(|t| t.compensated) {
        let n = sessions_to_verify(t.correction(), t.value().1, t.resolution(resolution_mm));
        if n != Some(1) {
            t.verifiable_by_repeat = Some(false);
            t.sessions_to_verify = n;
        }
    }
}

/// Whether a determined term is written, by the criteria every table shares: significant
/// (`|value| ≥ 2u`) and not moved by an alias unless `--include-aliased` names it (said in
/// `notes`); otherwise its `why` says which. A term written that a repeat of the tests could
/// not verify is flagged once the files' resolution is known ([`flag_unverifiable`]).
fn admit(t: &mut Term, e: &Estimate, options: &Options, notes: &mut Vec<String>) -> bool {
    if e.value.abs() < 2.0 * e.u {
        t.why = Some(format!(
            "not significant: |value| is below twice its standard uncertainty ({:.3} against u {:.3})",
            t.value().0,
            t.value().1
        ));
        return false;
    }
    if !e.aliases.is_empty() {
        if !options.includes_aliased(t) {
            t.why = Some(format!(
                "its value depends on what these tests cannot separate ({}): measure what separates them, or write it as fitted with --include-aliased {}",
                e.aliases.join("; "),
                t.id
            ));
            return false;
        }
        notes.push(format!(
            "{} ({} {}) is written as fitted (--include-aliased), although its value depends on what the tests cannot separate: {}",
            t.id,
            t.term,
            t.axis,
            e.aliases.join("; ")
        ));
    }
    true
}

/// The terms of a model, those an axis's own compensation (a table and a backlash) takes
/// marked compensated, with their axis's correction; the others with why (`why_not(term)` for
/// a term the controller's axis compensation does not take). Every controller selects by these
/// rules: determined, an axis the tests moved (without runs, a backlash only), significant, and
/// not moved by an alias unless `--include-aliased` names it (said in `notes`); one a repeat of
/// the tests could not verify is flagged with the files ([`flag_unverifiable`]).
pub(crate) fn select(
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
    why_not: &dyn Fn(&str) -> String,
    notes: &mut Vec<String>,
) -> (Vec<(Term, Estimate)>, BTreeMap<Axis, AxisCorrection>) {
    let mut entries = terms_with(model, estimates, options.covariance.as_deref());
    let mut per_axis: BTreeMap<Axis, AxisCorrection> = BTreeMap::new();
    for (t, e) in entries.iter_mut() {
        if !e.estimable {
            t.why = Some("the tests do not determine it (a gauge's choice fixes it)".into());
            continue;
        }
        let Some(axis) = Axis::from_name(&t.axis).filter(|a| !a.is_rotary()) else {
            t.why = Some(why_not(&t.term));
            continue;
        };
        if !matches!(t.term.as_str(), "backlash" | "scale" | "positional") {
            t.why = Some(why_not(&t.term));
            continue;
        }
        let measured = if runs.is_empty() {
            if t.term != "backlash" {
                t.why = Some(
                    "no runs given: a table covers the span the tests measured, which only the runs give; give the runs to write it".into(),
                );
                continue;
            }
            None
        } else {
            let Some(m) = measured_span(runs, axis) else {
                t.why = Some(format!("the tests do not move {axis}"));
                continue;
            };
            Some(m)
        };
        t.measured_span_mm = measured;
        if !admit(t, e, options, notes) {
            continue;
        }
        let (reference_mm, length_mm) = norm(model, axis);
        let c = per_axis.entry(axis).or_insert(AxisCorrection {
            positional: Vec::new(),
            backlash: 0.0,
            reference_mm,
            length_mm,
            measured,
        });
        if t.term == "backlash" {
            c.backlash = e.value;
        } else {
            c.positional.push((t.degree.unwrap_or(1), e.value));
        }
        t.compensated = true;
    }
    advice::amend(&mut entries, model, runs, options.covariance.as_deref(), why_not);
    if runs.is_empty() {
        notes.push(
            "no runs given: no prediction, and the aliases of the model's values could not be assessed (a saved model does not carry them); only the backlash is written".into(),
        );
    }
    // A transient's side is a combination of its parts: without their covariance its u is the
    // bound of theirs.
    let sides: Vec<&str> = entries
        .iter()
        .filter(|(t, _)| t.term == "reversal_spike" && !estimates.iter().any(|e| e.id == t.id))
        .map(|(t, _)| t.id.as_str())
        .collect();
    if options.covariance.is_none() && !sides.is_empty() {
        notes.push(format!(
            "the u of {} is the bound Σ|w_k| u_k of its parts (the height is Σ w_k a_k over the transient's parts at its peak): their covariance needs the runs the model was fitted to",
            sides.join(", ")
        ));
    }
    (entries, per_axis)
}

/// The controller joint of each compensated axis: `--joints` where given (then it must name
/// every compensated axis); else the existing configuration's layout (one joint per axis: a
/// gantry's axis is refused, as is a kinematics other than trivkins without `coordinates=`);
/// else trivkins' default order (X, Y, Z, A, B, C: 0 to 5).
fn joint_numbers(axes: &[Axis], options: &Options) -> Result<BTreeMap<Axis, usize>, String> {
    let existing = options.existing.as_ref();
    let layout = existing.and_then(|f| f.layout.as_ref().map(|l| (l, &f.coordinates)));
    let letter = |a: Axis| a.name().chars().next().unwrap_or('?');
    let mut out = BTreeMap::new();
    for &a in axes {
        let n = if !options.joints.is_empty() {
            let n = *options.joints.get(&a).ok_or_else(|| {
                format!(
                    "--joints names no joint for {a}, which is compensated: add {a}=<joint number>"
                )
            })?;
            if let Some((source, coordinates)) = layout {
                let there = coordinates.chars().nth(n);
                if there != Some(letter(a)) {
                    return Err(format!(
                        "--joints {a}={n}: the existing configuration ({source}) has {} as joint {n}",
                        there.map_or("no axis".to_string(), |c| format!("axis {c}"))
                    ));
                }
            }
            n
        } else if let Some((source, coordinates)) = layout {
            let joints: Vec<usize> = coordinates
                .char_indices()
                .filter(|(_, c)| *c == letter(a))
                .map(|(k, _)| k)
                .collect();
            match joints.as_slice() {
                [n] => *n,
                [] => {
                    return Err(format!(
                        "{a} is compensated but the existing configuration ({source}) has no joint for it: pass --joints {a}=<joint number>"
                    ));
                }
                many => {
                    return Err(format!(
                        "{a} is joints {} in the existing configuration ({source}), a gantry: the ballbar measures the axis, not each of its joints, and which joint's table takes the correction is a choice it cannot make; pass --joints with one joint for {a} (e.g. --joints {a}={}) to write that joint only, and set the other by hand",
                        many.iter().map(|n| n.to_string()).collect::<Vec<_>>().join(" and "),
                        many[0]
                    ));
                }
            }
        } else if let Some(k) =
            existing.and_then(|f| f.kinematics.as_ref()).filter(|k| k.as_str() != "trivkins")
        {
            return Err(format!(
                "the existing configuration's kinematics is {k}, whose joints are not the axes in trivkins' order: pass --joints (e.g. --joints X=0,Y=1,Z=2)"
            ));
        } else {
            a.index()
        };
        if let Some((other, _)) = out.iter().find(|&(_, m)| *m == n) {
            return Err(format!("--joints: {other} and {a} are both joint {n}"));
        }
        out.insert(a, n);
    }
    Ok(out)
}

/// Every `--travel` a span: its end above its start, both finite. Checked before anything is
/// chosen, whatever axis it names: a travel is asked for by the user, and one that is not a
/// span is an error naming it, never passed over (an existing table's span, or an axis with
/// nothing to tabulate, would otherwise take its place unsaid).
pub(crate) fn check_travel(options: &Options) -> Result<(), String> {
    for (axis, span) in &options.travel {
        let what = if span.iter().any(|x| !x.is_finite()) {
            "both ends must be finite numbers, the end above the start"
        } else if span[1] <= span[0] {
            "the end must be above the start"
        } else {
            continue;
        };
        return Err(format!("--travel {axis}={}:{}: {what}", span[0], span[1]));
    }
    Ok(())
}

/// The LinuxCNC files for a model, and `compensation.json` without its predictions
/// ([`predict`] adds them). `runs` may be empty: then only a backlash is written (a table needs
/// the span the tests measured). An error says why no file could be written as LinuxCNC reads
/// it.
pub fn linuxcnc(
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
) -> Result<(Compensation, linuxcnc::Files), String> {
    check_travel(options)?;
    let mut notes = Vec::new();
    if let Some(ex) = &options.existing {
        notes.extend(ex.notes.iter().cloned());
    }
    let (mut entries, mut per_axis) =
        select(model, estimates, runs, options, &|t| why_not_linuxcnc(t).into(), &mut notes);
    let axes: Vec<Axis> = per_axis.keys().copied().collect();
    let joint_of = joint_numbers(&axes, options)?;
    let existing_trim = |axis: Axis, q: f64, forward: bool| {
        let n = joint_of.get(&axis)?;
        options.existing.as_ref()?.joints.get(n).map(|j| j.trim(q, forward))
    };
    if let (Some(r), Some(_)) = (&options.reading, &options.existing) {
        notes.extend(reading::raise_by_existing(
            model,
            &mut per_axis,
            &entries,
            runs,
            r.as_ref(),
            &existing_trim,
        ));
    }
    // The joints: each compensated axis's, and the existing compensation's others kept.
    let mut files = linuxcnc::Files::default();
    // A kept table is written into the output folder under this writer's name for its joint,
    // never under the existing configuration's (an absolute path or `../` would leave the
    // folder, or name the machine's own file).
    if let Some(ex) = &options.existing {
        files.joints = ex
            .joints
            .iter()
            .map(|(&n, j)| {
                let kept = match j {
                    linuxcnc::Joint::Table { table, .. } => linuxcnc::Joint::Table {
                        file: linuxcnc::comp_file_name(n),
                        table: table.clone(),
                    },
                    other => other.clone(),
                };
                (n, kept)
            })
            .collect();
    }
    let existing_of = |n: usize| options.existing.as_ref().and_then(|f| f.joints.get(&n));
    for (&axis, c) in &per_axis {
        let n = joint_of[&axis];
        let existing = existing_of(n);
        // `BACKLASH` is a lost motion, positive: a negative one (the axis overshoots at its
        // reversals) is given as a table's two directions, which take any sign.
        let b_total = c.backlash
            + match existing {
                Some(linuxcnc::Joint::Backlash(b)) => *b,
                _ => 0.0,
            };
        let table_needed = !c.positional.is_empty()
            || b_total < 0.0
            || matches!(existing, Some(linuxcnc::Joint::Table { .. }));
        let joint = if table_needed {
            let span = options.travel.get(&axis).copied().or(c.measured);
            if let Some(span) = span
                && (span[1] <= span[0] || span.iter().any(|x| !x.is_finite()))
            {
                return Err(format!(
                    "--travel {axis}={}:{}: the end must be above the start",
                    span[0], span[1]
                ));
            }
            let round = |x: f64| (x * 1e6).round() / 1e6;
            // The existing table's nominals are kept (its trims are linear between them, so
            // the merged table reproduces them exactly wherever the new nominals fall); the new
            // ones fill what LinuxCNC's 256 entries leave.
            let existing_entries = match existing {
                Some(linuxcnc::Joint::Table { table, .. }) => table.entries().len(),
                _ => 0,
            };
            let room = linuxcnc::MAX_ENTRIES.saturating_sub(existing_entries).max(2);
            let mut nominals: Vec<f64> = match span {
                Some(span) => {
                    let count = (((span[1] - span[0]) / NODE_SPACING_MM).ceil() as usize + 1)
                        .clamp(2, room);
                    (0..count)
                        .map(|k| {
                            round(span[0] + (span[1] - span[0]) * k as f64 / (count - 1) as f64)
                        })
                        .collect()
                }
                None => Vec::new(),
            };
            if let Some(linuxcnc::Joint::Table { table, .. }) = existing {
                nominals.extend(table.entries().iter().map(|e| e.nominal));
            }
            if nominals.is_empty() {
                // A backlash alone, without a span: one entry, which LinuxCNC holds everywhere.
                nominals.push(0.0);
            }
            nominals.sort_by(f64::total_cmp);
            nominals.dedup();
            let rows: Vec<linuxcnc::Entry> = nominals
                .iter()
                .map(|&q| {
                    let ex = |fwd: bool| existing.map_or(0.0, |j| j.trim(q, fwd));
                    linuxcnc::Entry {
                        nominal: q,
                        forward: ex(true) + c.trim(q, true),
                        reverse: ex(false) + c.trim(q, false),
                    }
                })
                .collect();
            let table = linuxcnc::Table::new(rows).map_err(|m| {
                let over = span.map_or(String::new(), |s| format!(", {NODE_SPACING_MM} mm apart over {}..{} mm", s[0], s[1]));
                format!("joint {n} ({axis}): {m}: the merged table (the existing entries and the new ones{over}) cannot be written as LinuxCNC reads it")
            })?;
            if let (Some(span), Some(m)) = (span, c.measured)
                && (span[0] < m[0] || span[1] > m[1])
                && !c.positional.is_empty()
            {
                notes.push(if c.pure_slope() {
                    format!(
                        "{axis}: the table covers {}..{} mm, the tests measured {:.3}..{:.3} mm: the scale, a pure slope, is extended linearly past them",
                        span[0], span[1], m[0], m[1]
                    )
                } else {
                    format!(
                        "{axis}: the table covers {}..{} mm, the tests measured {:.3}..{:.3} mm: the positional correction has a curvature, so none of it is extended: past the measured ends the table holds its values there",
                        span[0], span[1], m[0], m[1]
                    )
                });
            }
            linuxcnc::Joint::Table { file: linuxcnc::comp_file_name(n), table }
        } else {
            linuxcnc::Joint::Backlash(b_total)
        };
        files.joints.insert(n, joint);
    }
    // The layout: the existing configuration's where it states one, else the joints written.
    match options.existing.as_ref().filter(|f| f.layout.is_some()) {
        Some(ex) => (files.coordinates, files.layout) = (ex.coordinates.clone(), ex.layout.clone()),
        None => {
            let top = joint_of.values().copied().max().map_or(0, |n| n + 1);
            let mut letters = vec!['-'; top];
            for (a, &n) in &joint_of {
                letters[n] = a.name().chars().next().unwrap_or('-');
            }
            files.coordinates = letters.into_iter().collect();
        }
    }
    // Read back what will be written: the prediction uses the files as LinuxCNC reads them.
    let texts: BTreeMap<String, String> = files.texts().into_iter().collect();
    let read = |name: &str| texts.get(name).cloned().ok_or_else(|| "not written".to_string());
    let mut written = linuxcnc::Files::parse(&texts["linuxcnc.ini"], "linuxcnc.ini", &read)?;
    (written.coordinates, written.layout) = (files.coordinates.clone(), files.layout.clone());
    // Per term: the files, the span, and the value predicted after, from the correction as
    // written (new trims minus existing ones) over the measured span.
    for (t, _) in entries.iter_mut() {
        let Some(axis) = Axis::from_name(&t.axis).filter(|_| t.compensated) else { continue };
        let n = joint_of[&axis];
        let c = &per_axis[&axis];
        let joint = &written.joints[&n];
        let over = if let linuxcnc::Joint::Table { file, table } = joint {
            t.files = vec![file.clone()];
            let e = table.entries();
            let span = [e[0].nominal, e[e.len() - 1].nominal];
            t.span_mm = Some(span);
            if t.term != "backlash" {
                let beyond = c.measured.is_some_and(|m| span[0] < m[0] || span[1] > m[1]);
                t.extended = Some(beyond && c.pure_slope());
            }
            span
        } else {
            t.files = vec!["linuxcnc.ini".into()];
            [0.0, 0.0]
        };
        let existing = existing_of(n);
        let (applied, before_applied) =
            applied(t, c, c.measured.unwrap_or(over), &|q, f| joint.trim(q, f), &|q, f| {
                existing.map_or(0.0, |j| j.trim(q, f))
            })?;
        let (v, _, _) = t.value();
        t.predicted_after = Some(value_after(t, v, before_applied, applied));
        t.existing = options.existing.as_ref().map(|_| before_applied);
        t.written = Some(applied);
    }
    if let Some(r) = &options.reading {
        let new = |axis: Axis, q: f64, forward: bool| {
            written.joints.get(joint_of.get(&axis)?).map(|j| j.trim(q, forward))
        };
        match reading::prediction_moves(model, &per_axis, runs, r.as_ref(), &new, &existing_trim) {
            Ok(moves) => notes.extend(reading::apply_moves(&mut entries, &moves)),
            Err(m) => notes.push(reading::not_read_note(&m)),
        }
    }
    notes.extend(order_note(entries.iter().map(|(t, _)| t)));
    let joints = joint_of.iter().map(|(a, n)| (a.name().to_string(), *n)).collect();
    let terms = entries.into_iter().map(|(t, _)| t).collect();
    let mut comp = Compensation {
        format: COMPENSATION_FORMAT.into(),
        controller: "linuxcnc".into(),
        terms,
        predicted: Vec::new(),
        joints,
        notes,
        resolution_mm: Some(linuxcnc::TRIM_RESOLUTION_MM),
        predicted_runs: Vec::new(),
    };
    flag_unverifiable(&mut comp);
    Ok((comp, written))
}

/// The note on the order of the predictions where a positional degree 2 or up is written
/// ([`value_after`]); `None` without one.
pub(crate) fn order_note<'a>(terms: impl IntoIterator<Item = &'a Term>) -> Option<String> {
    let ids: Vec<&str> = terms
        .into_iter()
        .filter(|t| t.compensated && t.term == "positional")
        .map(|t| t.id.as_str())
        .collect();
    (!ids.is_empty()).then(|| {
        format!(
            "predicted_after of {} is first order in the trim (the error where the axis goes moves by its slope times the trim, of the order of 1e-4 of the value); a scale's is exact, a backlash's needs no second order",
            ids.join(", ")
        )
    })
}

/// The value of term `t` a re-measurement shows after trims applying `applied` of it, where
/// the tests measured `v` with trims applying `before` (the existing compensation's, 0
/// without), each in the term's unit ([`applied`]). A trim is added to the commanded position
/// and the axis then moves with its errors: a scale `s` (actual − commanded over the position)
/// under trims of slope `−a` leaves `s − a − s·a`, a product, so the measured `v = s − b − s·b`
/// gives `s = (v + b)/(1 − b)` and the scale after is exact, not first order (which leaves
/// `−s²`, 0.003 ppm at 56 ppm, 0.008 ppm at 89 ppm). A backlash does not depend on where the
/// axis is, so the trim leaves it exactly `v − (applied − before)`; a higher degree is first
/// order in the trim: the error where the axis goes moves by its slope times the trim, of the
/// order of 1e-4 of the value for µm over hundreds of mm (`compensation.json` says so in a
/// note).
pub(crate) fn value_after(t: &Term, v: f64, before: f64, applied: f64) -> f64 {
    if t.term != "scale" {
        return v - (applied - before);
    }
    let (v, b, a) = (v * 1e-6, before * 1e-6, applied * 1e-6);
    let s = (v + b) / (1.0 - b);
    (s - a - s * a) * 1e6
}

/// What trims `new` and `old` apply of a term, in its display unit, over `span` (the measured
/// one; for a backlash without runs, the table's, or a point): the backlash as the mean
/// difference of the two directions; a positional degree as the
/// coefficient of a least-squares fit (QR, `ballbar_fit::lstsq`) of the directions' mean trim
/// over the span, on the term's basis with a constant and the other compensated degrees,
/// sign-reversed (a trim of `-θ s^k` applies `θ`); a scale in ppm of `L`.
fn applied(
    t: &Term,
    c: &AxisCorrection,
    span: [f64; 2],
    new: &dyn Fn(f64, bool) -> f64,
    old: &dyn Fn(f64, bool) -> f64,
) -> Result<(f64, f64), String> {
    // 201 points over the span: enough to separate a constant and up to a few degrees.
    let m = 201;
    let grid: Vec<f64> =
        (0..m).map(|i| span[0] + (span[1] - span[0]) * i as f64 / (m - 1) as f64).collect();
    let of = |trim: &dyn Fn(f64, bool) -> f64| -> Result<f64, String> {
        if t.term == "backlash" {
            let d: f64 =
                grid.iter().map(|&q| trim(q, true) - trim(q, false)).sum::<f64>() / m as f64;
            return Ok(d * 1e3);
        }
        let mut degrees: Vec<u32> = c.positional.iter().map(|p| p.0).collect();
        degrees.sort();
        let cols = degrees.len() + 1;
        let s = |q: f64| (q - c.reference_mm) / c.length_mm;
        let a = faer::Mat::<f64>::from_fn(m, cols, |i, j| {
            if j == 0 { 1.0 } else { s(grid[i]).powi(degrees[j - 1] as i32) }
        });
        let y: Vec<f64> = grid.iter().map(|&q| 0.5 * (trim(q, true) + trim(q, false))).collect();
        let (x, _) = ballbar_fit::lstsq(a.as_ref(), &y).map_err(|e| e.to_string())?;
        let k = t.degree.unwrap_or(1);
        let j = degrees.iter().position(|&d| d == k).map_or(0, |p| p + 1);
        let theta = -x[j];
        Ok(if t.term == "scale" { theta / c.length_mm * 1e6 } else { theta * 1e3 })
    };
    Ok((of(new)?, of(old)?))
}

/// The trace of each planar run predicted after the compensation, µm figures: the measured
/// reading (the model's trace, its residual and the noise) plus what the correction (the written
/// trims minus the existing ones) changes, `ΔR = û·t`, `t` the trim each joint takes at its
/// commanded position and direction as LinuxCNC interpolates it, `û` the bar's direction. A
/// run that is not a planar circle is left out (named in the notes).
pub fn predict(
    comp: &mut Compensation,
    files: &linuxcnc::Files,
    existing: Option<&linuxcnc::Files>,
    runs: &[Run],
) {
    predict_with(
        comp,
        runs,
        &|comp, axis, q, forward| {
            let n = *comp.joints.get(axis.name())?;
            let joint = files.joints.get(&n);
            let old = existing.and_then(|f| f.joints.get(&n));
            if joint.is_none() && old.is_none() {
                return None;
            }
            let trim = |j: Option<&linuxcnc::Joint>| j.map_or(0.0, |j| j.trim(q, forward));
            Some(trim(joint) - trim(old))
        },
        None,
    );
}

/// Whether a run is a planar circle, whose trace `compensate` predicts (others are named in
/// the notes, not predicted).
pub fn predictable(run: &Run) -> bool {
    ballbar_fit::metrics::angles(run).is_some() && run.header.plane.axes().is_some()
}

/// Each planar run's trace predicted after a compensation, µm figures (every controller's
/// prediction): the measured reading plus `ΔR = û·Δt`, `Δt = change(axis, q, forward)` the
/// change of the trim the controller applies to `axis` at its commanded position and direction
/// (`None`: the axis is not compensated) plus `cross(input, axis, q_input)` summed over the
/// other axes (cross-axis tables), `û` the bar's direction. A run that is not a planar
/// circle is left out (named in the notes).
pub(crate) fn predict_with(
    comp: &mut Compensation,
    runs: &[Run],
    change: &dyn Fn(&Compensation, Axis, f64, bool) -> Option<f64>,
    cross: Option<&dyn Fn(Axis, Axis, f64) -> f64>,
) {
    for run in runs {
        let (Some(theta), Some((u, v, _))) =
            (ballbar_fit::metrics::angles(run), run.header.plane.axes())
        else {
            comp.notes.push(format!("{}: not a planar circle: no prediction", run.name()));
            continue;
        };
        let mut after = run.dr_mm.clone();
        for (axis, proj) in [(u, 0usize), (v, 1usize)] {
            let Some(col) = run.axis(axis) else { continue };
            let dirs = directions(col);
            for i in 0..run.len() {
                let Some(t) = change(comp, axis, col[i], dirs[i]) else { continue };
                let unit = if proj == 0 { theta[i].cos() } else { theta[i].sin() };
                after[i] += unit * t;
            }
            // Cross-axis tables: the trim of `axis` from each other axis's commanded position.
            let Some(cross) = cross else { continue };
            for input in Axis::LINEAR.into_iter().filter(|a| *a != axis) {
                let Some(q) = run.axis(input) else { continue };
                for i in 0..run.len() {
                    let unit = if proj == 0 { theta[i].cos() } else { theta[i].sin() };
                    after[i] += unit * cross(input, axis, q[i]);
                }
            }
        }
        let figures = |dr: &[f64]| {
            let about = ballbar_fit::metrics::about_lsq_circle(&theta, dr);
            (
                ballbar_fit::metrics::rms(&about) * 1e3,
                ballbar_fit::metrics::figures(run, dr).g * 1e3,
            )
        };
        let (rms_before_um, g_before_um) = figures(&run.dr_mm);
        let (rms_after_um, g_after_um) = figures(&after);
        let mut predicted_run = run.clone();
        predicted_run.dr_mm = after;
        comp.predicted_runs.push(predicted_run);
        comp.predicted.push(Predicted {
            run: run.name().to_string(),
            plane: Some(run.header.plane.to_string()),
            rms_before_um,
            rms_after_um,
            g_before_um,
            g_after_um,
        });
    }
}

#[cfg(test)]
mod tests;

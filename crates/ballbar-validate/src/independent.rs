//! The second validation set of the diagnosis, kept apart from the first ([`crate::suite`]):
//! effects whose shapes are *not* the candidates' shapes, and held-out runs that the user
//! would meet next.
//!
//! # A scenario
//! The shared simulator ([`ballbar_sim::simulate`]) simulates the base machine alone: the
//! paper's column machine with its base errors (or several times them), 3 µm random centring
//! per run, reading noise, no [`ballbar_sim::TruthEffect`]. The physical perturbations of
//! [`perturb`] are then added to the readings, each computed by hand, per sample, from the
//! runs' commanded axes, times and headers (their derivations are there): thermal growth of a
//! ball screw (linear or saturating in time, its bearing at either end of the travel), a
//! reversal spike whose height grows with the feed and recovers algebraically, a spike that
//! rings as it recovers (on one side of the reversals or both), stick-slip from a Stribeck
//! friction law, lateral play that switches smoothly (`tanh`), a vibration whose amplitude
//! grows with the feed, a cyclic error with a second harmonic, a slow drift of the bar's own
//! length; and nulls (white plus strongly correlated noise; a worn machine whose base errors
//! are three times the paper's; long runs at a low feed; another station and tool).
//!
//! Most scenarios use the paper's model (its plane servo terms, a calibrated bar). Those of
//! the set-ups a user varies (two feeds, two tool lengths, two radii, one plane repeated, a
//! 220° arc) use the model a new user gets by default, a servo lag per axis and the bar length
//! fitted ([`default_session`]): there the base model needs the configurations to determine
//! its own parameters, which is what holding a configuration out must not break. Others
//! change what the first ones share: the horizontal machine ([`horizontal_session`]), one
//! plane (YZ; a partial arc in XY), 250 Hz and 1 kHz, radii and feeds together, two effects
//! at once.
//!
//! A scenario that fails one check for a class of the method not yet fixed keeps that check
//! and is marked open with it and the class ([`Scenario::open`]): the scoreboard shows it as
//! `open` with the failed check and the class; any other failed check fails the set.
//!
//! Every scenario is one session, simulated in order: first the **training** runs, given to
//! [`diagnose`] with [`Options::default`] and the paper's model options ([`PAPER`]), no hint;
//! then the **held-out** runs, never shown to it: the last cycle of the session (what comes
//! later in time), or a feed or centre the training never saw. The split is stated per
//! scenario ([`Scenario::split`]).
//!
//! # What is judged
//! - **Names**: each perturbation is named among the accepted effects with the kind and axis
//!   it is ([`Expected`]); nothing else is accepted; for the nulls, nothing at all.
//! - **Closure**: the diagnosis *claims* a held-out closure,
//!   `1 − effects.last().held_out_rms_after_um / effects.first().held_out_rms_before_um`
//!   (0 when it accepts nothing); the held-out runs *measure* one,
//!   `1 − RMS_augmented / RMS_base` ([`held_out_rms`]: each model fitted on the training runs,
//!   its backlash switching where a model saved from them does ([`training_switch`]), each
//!   held-out run predicted with the fitted machine parameters, only its own nuisances
//!   refitted on it; 0 when nothing is accepted). They must agree within
//!   [`CLOSURE_TOLERANCE`].
//! - **Share of the excess**: the diagnosis also claims the share of the held-out excess above
//!   the noise its effects close (`held_out.excess_closed`, [`ballbar_diagnose::excess`]: the
//!   gap an engineer means); the held-out runs show
//!   `1 − excess(RMS_augmented)/excess(RMS_base)` above the same floor (the one the diagnosis
//!   states, `held_out.noise_um`: the share is of the excess above it). They must agree within
//!   [`CLOSURE_TOLERANCE`] too. This is the stronger check: a spike that takes a 1 kHz trace
//!   from 0.294 to 0.255 µm against a floor of 0.250 µm shrinks its RMS by 13 % and closes
//!   two thirds of its excess, so a claim can pass the RMS check and be far off on the excess.
//!   Where the diagnosis says the share is not determined (its held-out excess within two
//!   standard uncertainties of zero: the floor's and the held-out samples' own chance,
//!   [`ballbar_diagnose::excess::share`]), the held-out runs' excess must be within that
//!   stated uncertainty too ([`undetermined_check`]), their own chance beside it.
//!
//! No oracle: the truth's shapes are not in the model library, so there is no "true model" to
//! fit. The scoreboard's figures are the held-out runs' own.

pub mod perturb;

use std::path::Path;
use std::time::Instant;

use ballbar_diagnose::{DiagnoseError, Diagnosis, Options, diagnose};
use ballbar_fit::fit;
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Axis, BlockScratch, Design, Direction, Effect, NoKernels, Plane, Run};
use ballbar_sim::{TestSpec, Truth, simulate};

use crate::suite::{Check, PAPER, ValidationError};
use perturb::{Growth, Perturbation};

/// The claimed held-out closure must lie within this of the measured one (15 percentage
/// points): a claim that far off misleads a user deciding whether to model the effect, while
/// the held-out runs' own noise moves the measured closure by a few points (the closure of an
/// effect that is a few times the noise sits at 50-90 %, where a change of the effect's share
/// by half moves it by about ten).
pub const CLOSURE_TOLERANCE: f64 = 0.15;

/// The paper's column machine as its truth file states it (base errors, centring, noise).
const PAPER_TRUTH: &str = include_str!("../../../fixtures/column-paper/truth.ron");

/// The paper's horizontal machine as its truth file states it.
const HORIZONTAL_TRUTH: &str = include_str!("../../../fixtures/horizontal-paper/truth.ron");

/// The session's start, s since 1970 (2026-11-21T10:00:00Z, as the first set's).
const SESSION_START_UNIX_S: f64 = 1_795_255_200.0;

/// Sampling rate of every scenario, Hz.
const SAMPLE_RATE_HZ: f64 = 125.0;

/// Radius of every circle, mm.
const RADIUS_MM: f64 = 100.0;

/// The standard station: pivot and tool ball (tool length 100 mm).
const PIVOT: [f64; 3] = [300.0, 200.0, -300.0];
const TOOL_BALL: [f64; 3] = [0.0, 0.0, -100.0];

/// The longer and the middle tool of the scenarios with several tool lengths (200 and 150 mm).
const LONG_TOOL: [f64; 3] = [0.0, 0.0, -200.0];
const MID_TOOL: [f64; 3] = [0.0, 0.0, -150.0];

/// Another station: a pivot away from the standard one and a 180 mm tool.
const OTHER_PIVOT: [f64; 3] = [250.0, 150.0, -350.0];
const OTHER_TOOL: [f64; 3] = [0.0, 0.0, -180.0];

/// A full circle and a 220° arc from −20° (start, sweep), degrees.
const FULL: (f64, f64) = (0.0, 360.0);
const ARC_220: (f64, f64) = (-20.0, 220.0);

/// The pause between runs of a thermal session, s: a cycle of six runs at 1000 mm/min (37.7 s
/// each) every 30 minutes, as a machine warming up is checked.
const THERMAL_PAUSE_S: f64 = 262.3;

/// The pause between runs otherwise, s.
const PAUSE_S: f64 = 60.0;

/// A thermal growth's figure against the truth's: 10 %. The growth over 90 minutes is
/// 14-23 ppm, 2-3 µm over the 150 mm the circles span on the axis, determined by 18 runs to a
/// few hundredths of a ppm by the noise (the fit's u ≈ 0.03 ppm); what is left is the law's
/// misfit (a saturating law of τ 43 for one of 35 min) and the bearing that a circle does not
/// see, a few per cent.
pub const GROWTH_TOLERANCE: f64 = 0.10;

/// A play's or a vibration's size against the truth's: 10 %. The noise determines it to a few
/// thousandths of a µm; the play's finite stiffness (a tanh crossing over some samples where
/// the candidate steps) and the vibration's amplitude growing with the feed within a run's
/// set-up (the candidate's is one per run) are the misfit, a few per cent.
pub const PLAY_TOLERANCE: f64 = 0.10;

/// An effect the diagnosis must name: its kind (the diagnosis JSON's `kind`) and axis, and for
/// lateral play the axis whose reversals switch it.
#[derive(Clone, Debug, PartialEq)]
pub struct Expected {
    /// Kind (`thermal_growth`, `reversal_spike`, ...).
    pub kind: &'static str,
    /// The axis that carries it (for lateral play, the axis that moves sideways); `None` for
    /// the bar's own (`bar_length_drift`).
    pub axis: Option<Axis>,
    /// For lateral play, the axis whose reversals switch it.
    pub switched_by: Option<Axis>,
    /// The figures the diagnosis reports for it, against the truth's.
    pub figures: Vec<Figure>,
}

/// A figure of an accepted effect against the truth's, where the effect's shape has the
/// truth's parameter (a growth rate, a play, a frequency); where it does not (a spike of
/// another recovery law, a Stribeck stick-slip), its fitted size is that of another shape and
/// is not checked.
#[derive(Clone, Debug, PartialEq)]
pub enum Figure {
    /// The reported parameter `name` within `tolerance` (relative) of `truth`.
    Parameter {
        /// As in the diagnosis's `parameters`.
        name: &'static str,
        /// The truth's value.
        truth: f64,
        /// Relative.
        tolerance: f64,
    },
    /// A thermal growth's scale change at `minutes` after the session's start (linear:
    /// rate·t; saturating: size·(1 − e^{−t/τ})), ppm, within `tolerance` (relative) of
    /// `truth_ppm`: over a session of two or three time constants a saturating growth's size and
    /// τ trade against each other, the growth they predict over the session does not.
    GrowthAt {
        /// Since the session's start.
        minutes: f64,
        /// The truth's growth then.
        truth_ppm: f64,
        /// Relative.
        tolerance: f64,
    },
}

impl Figure {
    /// The check of `a`'s figure: its name, pass, detail.
    pub fn check(&self, a: &ballbar_diagnose::Accepted) -> (String, bool, String) {
        let get = |n: &str| a.parameters.iter().find(|(k, _)| k == n).map(|x| x.1);
        let within = |found: f64, truth: f64, tol: f64| {
            (
                (found - truth).abs() <= tol * truth.abs(),
                format!("{found:.3} against {truth:.3} (within {:.0} %)", tol * 100.0),
            )
        };
        match *self {
            Figure::Parameter { name, truth, tolerance } => match get(name) {
                Some(v) => {
                    let (pass, detail) = within(v, truth, tolerance);
                    (name.to_string(), pass, detail)
                }
                None => (
                    name.to_string(),
                    false,
                    format!("not among the reported parameters {:?}", a.parameters),
                ),
            },
            Figure::GrowthAt { minutes, truth_ppm, tolerance } => {
                let found =
                    match (get("rate_ppm_per_h"), get("growth_ppm"), get("time_constant_min")) {
                        (Some(rate), _, _) => Some(rate * minutes / 60.0),
                        (None, Some(size), Some(tau)) => {
                            Some(size * (1.0 - (-minutes / tau).exp()))
                        }
                        _ => None,
                    };
                let name = format!("growth at {minutes} min, ppm");
                match found {
                    Some(v) => {
                        let (pass, detail) = within(v, truth_ppm, tolerance);
                        (name, pass, detail)
                    }
                    None => (name, false, format!("no growth parameters among {:?}", a.parameters)),
                }
            }
        }
    }
}

impl Expected {
    fn on(kind: &'static str, axis: Axis) -> Expected {
        Expected { kind, axis: Some(axis), switched_by: None, figures: vec![] }
    }

    /// The bar's own length changing from run to run (`bar_length_drift`, no axis).
    fn of_the_bar() -> Expected {
        Expected { kind: "bar_length_drift", axis: None, switched_by: None, figures: vec![] }
    }

    fn with(mut self, figure: Figure) -> Expected {
        self.figures.push(figure);
        self
    }

    /// True when the accepted effect `e` is this one: same kind, same axis (lateral play: the
    /// moving axis and `switched_by`, as the CLI contract names them). A size scaled with the
    /// feed is its effect's kind.
    pub fn matches(&self, e: &Effect) -> bool {
        if let Effect::FeedScaled { effect, .. } = e {
            return self.matches(effect);
        }
        if e.kind() != self.kind {
            return false;
        }
        if let Effect::LateralPlay { axis, switched_by, .. } = e {
            return Some(*axis) == self.axis && Some(*switched_by) == self.switched_by;
        }
        e.axis_label().as_deref() == self.axis.map(Axis::name)
    }

    /// `kind axis` (`lateral_play Y switched by X`).
    pub fn label(&self) -> String {
        match (self.axis, self.switched_by) {
            (Some(a), Some(b)) => format!("{} {a} switched by {b}", self.kind),
            (Some(a), None) => format!("{} {a}", self.kind),
            (None, _) => self.kind.to_string(),
        }
    }
}

/// A named scenario.
#[derive(Clone, Debug)]
pub struct Scenario {
    /// Short name.
    pub name: &'static str,
    /// The machine.
    pub machine: MachineSpec,
    /// The base model's options (the paper's: plane servo mismatch, calibrated bar).
    pub options: ModelOptions,
    /// The base machine and the session's tests, training first (no truth effects).
    pub base: Truth,
    /// The simulator's seed; the perturbations' generator is seeded from it too.
    pub seed: u64,
    /// What is added to the simulated readings.
    pub perturbations: Vec<Perturbation>,
    /// The first this many runs of the session are the training runs, the rest held out.
    pub training_runs: usize,
    /// The effects to name (empty: a null, nothing may be named).
    pub expect: Vec<Expected>,
    /// The truth in words.
    pub truth: String,
    /// Training and held-out runs in words, and why those are held out.
    pub split: String,
    /// A check this scenario fails for a reason of the method not yet fixed: (the check's
    /// name, the failure's class in words). The scoreboard shows the scenario as `open` with
    /// the failed check, and the set does not fail for it; any other failed check fails it.
    pub open: Option<(&'static str, &'static str)>,
}

/// A scoreboard row.
pub struct Outcome {
    /// Scenario name.
    pub scenario: &'static str,
    /// The truth in words.
    pub truth: String,
    /// The split in words.
    pub split: String,
    /// The accepted effects with their axes (`no effect` when none).
    pub diagnosis: String,
    /// Held-out RMS of the base model, µm.
    pub held_out_base_um: f64,
    /// Held-out RMS of the base model plus the accepted effects, µm (the base's when none).
    pub held_out_augmented_um: f64,
    /// The closure the diagnosis claims (0 when it accepts nothing).
    pub claimed: f64,
    /// The closure the held-out runs show (0 when nothing is accepted).
    pub measured: f64,
    /// The share of the held-out excess above the noise the diagnosis claims its effects close
    /// (`held_out.excess_closed`; 0 when it accepts nothing, NaN when it found no excess or
    /// says the share is not determined).
    pub claimed_excess: f64,
    /// The share of the excess above the same floor the held-out runs show (0 when nothing is
    /// accepted, NaN when their base RMS is not above the floor).
    pub measured_excess: f64,
    /// The checks.
    pub checks: Vec<Check>,
    /// Wall time of simulation, diagnosis and held-out evaluation, s.
    pub seconds: f64,
    /// The diagnosis.
    pub diagnosis_result: Diagnosis,
    /// The scenario's open check and class ([`Scenario::open`]).
    pub open: Option<(&'static str, &'static str)>,
}

impl Outcome {
    /// True when every check passed.
    pub fn passed(&self) -> bool {
        crate::suite::failed(&self.checks).is_empty()
    }

    /// True when the only failed check is the scenario's open one ([`Scenario::open`]).
    pub fn open_only(&self) -> bool {
        let failed = self.failures();
        !failed.is_empty()
            && failed.iter().all(|c| self.open.is_some_and(|(name, _)| c.name == name))
    }

    /// True when a check failed that is not the scenario's open one: the set fails.
    pub fn failed(&self) -> bool {
        !self.passed() && !self.open_only()
    }

    /// The failed checks.
    pub fn failures(&self) -> Vec<&Check> {
        crate::suite::failed(&self.checks)
    }
}

fn paper_truth() -> Truth {
    ballbar_io::ron_files::parse_ron(PAPER_TRUTH, Path::new("fixtures/column-paper/truth.ron"))
        .expect("the shipped truth file parses")
}

/// The horizontal machine's session: as [`session`] (its tests, rate, noise, pause), with the
/// horizontal machine's own base errors, servo terms, bar and centring from its truth file.
pub(crate) fn horizontal_session(
    training: Vec<TestSpec>,
    held_out: Vec<TestSpec>,
    noise: (f64, f64),
    pause_s: f64,
) -> (Truth, usize) {
    let (mut t, n) = session(training, held_out, noise, pause_s, 1.0);
    let h: Truth = ballbar_io::ron_files::parse_ron(
        HORIZONTAL_TRUTH,
        Path::new("fixtures/horizontal-paper/truth.ron"),
    )
    .expect("the shipped truth file parses");
    t.servo = h.servo;
    t.errors = h.errors;
    t.paper = h.paper;
    t.bar_length_um = h.bar_length_um;
    t.centring_sd_um = h.centring_sd_um;
    (t, n)
}

/// The session `s` sampled at `hz` instead of [`SAMPLE_RATE_HZ`].
fn at_rate((mut t, n): (Truth, usize), hz: f64) -> (Truth, usize) {
    t.sample_rate_hz = hz;
    (t, n)
}

/// The three planes, CW then CCW, at one feed and station.
pub(crate) fn circles(feed_mm_per_min: f64, pivot_mm: [f64; 3]) -> Vec<TestSpec> {
    Plane::PLANAR
        .into_iter()
        .map(|plane| TestSpec {
            plane,
            directions: vec![Direction::CW, Direction::CCW],
            radius_mm: RADIUS_MM,
            feed_mm_per_min,
            pivot_mm,
            table_ball_mm: [0.0, 0.0, 50.0],
            tool_ball_mm: TOOL_BALL,
            repeats: 1,
            start_deg: 0.0,
            sweep_deg: 360.0,
            rotary: None,
        })
        .collect()
}

/// The base machine for a session of `training` then `held_out` tests: the paper's errors
/// times `wear`, 3 µm centring, reading noise `(σ µm, correlation ms)`, no truth effects.
pub(crate) fn session(
    training: Vec<TestSpec>,
    held_out: Vec<TestSpec>,
    noise: (f64, f64),
    pause_s: f64,
    wear: f64,
) -> (Truth, usize) {
    let runs_of =
        |t: &[TestSpec]| t.iter().map(|s| s.directions.len() * s.repeats as usize).sum::<usize>();
    let n_training = runs_of(&training);
    let mut t = paper_truth();
    if let Some(p) = t.paper.as_mut() {
        for x in p
            .positional_um
            .iter_mut()
            .chain(&mut p.straightness_um)
            .chain(&mut p.squareness_urad)
            .chain(&mut p.backlash_um)
            .chain(&mut p.servo_mismatch_um)
        {
            *x *= wear;
        }
    }
    t.tests = training.into_iter().chain(held_out).collect();
    t.sample_rate_hz = SAMPLE_RATE_HZ;
    (t.noise_um, t.noise_correlation_ms) = noise;
    t.pause_s = pause_s;
    t.effects = vec![];
    (t, n_training)
}

/// The tests of `planes` at one set-up, each CW then CCW: a circle of `radius_mm` (or the arc
/// `start_deg`, `sweep_deg` of it) about `pivot_mm`, the tool ball at `tool_ball_mm`.
pub(crate) fn tests_at(
    planes: &[Plane],
    radius_mm: f64,
    feed_mm_per_min: f64,
    pivot_mm: [f64; 3],
    tool_ball_mm: [f64; 3],
    (start_deg, sweep_deg): (f64, f64),
) -> Vec<TestSpec> {
    planes
        .iter()
        .map(|&plane| TestSpec {
            plane,
            directions: vec![Direction::CW, Direction::CCW],
            radius_mm,
            feed_mm_per_min,
            pivot_mm,
            table_ball_mm: [0.0, 0.0, 50.0],
            tool_ball_mm,
            repeats: 1,
            start_deg,
            sweep_deg,
            rotary: None,
        })
        .collect()
}

/// The servo lags of the machines that the default model judges, ms (X, Y, Z): drives with
/// feed-forward, mismatched by up to 0.5 ms. The default model fits each axis's lag less their
/// mean; the common 0.35 ms shortens R = 100 mm by 1e-3 µm at 2000 mm/min (`(Vτ)²/2R`), far
/// below the noise, so these sessions have no common lag to find. The simulated axes switch
/// their backlash when their lagged position reverses, 0.1 to 0.6 ms after the command.
pub const AXIS_LAGS_MS: [f64; 3] = [0.6, 0.1, 0.35];

/// A session for the model a new user gets by default (a servo lag per axis, the bar length
/// fitted): the paper's base errors as machine parameters, its three plane servo terms
/// replaced by the lags [`AXIS_LAGS_MS`] (the paper's plane terms are not the lags of any
/// axes, so a default model would see them as a gap of their own).
pub(crate) fn default_session(
    training: Vec<TestSpec>,
    held_out: Vec<TestSpec>,
    noise: (f64, f64),
    pause_s: f64,
) -> (Truth, usize) {
    let (mut t, n) = session(training, held_out, noise, pause_s, 1.0);
    let paper = t.paper.take().expect("the shipped truth states the paper's values");
    let model = Model::with_kernels(ballbar_model::machines::column(), PAPER, &NoKernels)
        .expect("the column machine builds");
    let params = model.parameters();
    let values = ballbar_model::paper::parameters_from_paper(&model, &paper)
        .expect("the paper's values fit the column machine");
    for (id, v) in values.into_iter().filter(|(id, _)| !id.starts_with('M')) {
        let unit = params.iter().find(|p| p.id == id).expect("a parameter of the model").unit;
        t.errors.insert(id, v * unit.display_factor());
    }
    for (a, lag) in Axis::LINEAR.into_iter().zip(AXIS_LAGS_MS) {
        t.errors.insert(format!("T{a}"), lag);
    }
    t.servo = ballbar_model::machine::ServoVariant::AxisLag;
    (t, n)
}

/// The scenario on the horizontal machine.
fn on_horizontal(mut s: Scenario) -> Scenario {
    s.machine = ballbar_model::machines::horizontal();
    s
}

/// The scenario under the model a new user gets by default (a lag per axis, the bar length
/// fitted) instead of the paper's.
fn defaults(mut s: Scenario) -> Scenario {
    s.options = ModelOptions::default();
    s
}

/// A scenario of one session.
fn scenario(
    name: &'static str,
    (base, training_runs): (Truth, usize),
    seed: u64,
    perturbations: Vec<Perturbation>,
    expect: Vec<Expected>,
    base_text: &str,
    split: &str,
) -> Scenario {
    let noise = if base.noise_correlation_ms > 0.0 {
        format!("noise {} µm AR(1) {} ms", base.noise_um, base.noise_correlation_ms)
    } else {
        format!("noise {} µm", base.noise_um)
    };
    let mut parts: Vec<String> = perturbations.iter().map(Perturbation::describe).collect();
    parts.push(noise);
    parts.push(base_text.to_string());
    Scenario {
        name,
        machine: ballbar_model::machines::column(),
        options: PAPER,
        base,
        seed,
        perturbations,
        training_runs,
        expect,
        truth: parts.join("; "),
        split: split.to_string(),
        open: None,
    }
}

/// The name of the check of the claimed share of the excess above the noise
/// ([`excess_check`]).
pub const EXCESS: &str = "claimed share of the excess";

/// The scenarios whose claimed share of the excess the held-out runs do not confirm, with
/// their class and figures; each is marked open with [`EXCESS`]. Every claim carries its
/// uncertainty (the floor's and the held-out samples' own chance, [`ballbar_diagnose::excess`]);
/// horizontal-ringing-spike-z's measured share lies inside its claim's interval, which is wider
/// than the check's 15 points. (thermal-saturating-x was open here: its later-runs fold
/// predicted a whole cycle from one, further than the session's model is asked to; blocks of
/// half a cycle took its claim from 75 % to 88 % against 90 % measured.)
const EXCESS_OPEN: [(&str, &str); 1] = [(
    "horizontal-ringing-spike-z",
    "a determined share whose interval is wider than the check: claimed 77 % (50-100 % at k = 1; the excess 0.031 µm above a floor of 0.151 µm, its energy 9.9e-4 ± 2.7e-4 µm²), measured 58 %, inside the interval but 19 points from the point, and the held-out runs' own share is as uncertain (their excess energy 1.0e-3 µm² before and 1.2e-4 after, each with about 2e-4 of chance): a share determined at k = 2 is not yet known to 15 points; the check is kept, a determined share within 15 points",
)];

/// The scenario with its check `check` open, for the class `why` ([`Scenario::open`]).
fn open(mut s: Scenario, check: &'static str, why: &'static str) -> Scenario {
    s.open = Some((check, why));
    s
}

/// Every scenario of the second set.
pub fn scenarios() -> Vec<Scenario> {
    use Axis::{X, Y, Z};
    let cycle = || circles(1000.0, PIVOT);
    let cycles = |n: usize| (0..n).flat_map(|_| cycle()).collect::<Vec<_>>();
    // A warm-up session: three cycles of six runs, 30 minutes apart; the last cycle held out.
    let thermal = || session(cycles(2), cycle(), (0.1, 0.0), THERMAL_PAUSE_S, 1.0);
    let thermal_split = "training: the first two cycles (12 runs, 0-60 min); held out: the third cycle (6 runs, 60-90 min), what the machine does next";
    let two_feeds =
        |a: f64, b: f64| circles(a, PIVOT).into_iter().chain(circles(b, PIVOT)).collect::<Vec<_>>();
    let paper = "the paper's base errors, 3 µm centring, R 100, 125 Hz";
    let growth =
        |axis, bearing_mm, growth| Perturbation::ThermalGrowth { axis, bearing_mm, growth };
    let default_feeds = |a: f64, b: f64| {
        [a, b]
            .into_iter()
            .flat_map(|f| tests_at(&Plane::PLANAR, RADIUS_MM, f, PIVOT, TOOL_BALL, FULL))
            .collect::<Vec<_>>()
    };
    let lags = format!(
        "the paper's base errors with servo lags X {} Y {} Z {} ms, 3 µm centring, 125 Hz",
        AXIS_LAGS_MS[0], AXIS_LAGS_MS[1], AXIS_LAGS_MS[2]
    );
    let all = vec![
        // Thermal growth of each linear axis, linear and saturating, the bearing at either end
        // of the travel (X 0..500, Y 0..400, Z -500..0 mm; the circles sit at X 200..400,
        // Y 100..300, Z -400..-200).
        scenario(
            "thermal-linear-x",
            thermal(),
            101,
            vec![growth(X, 0.0, Growth::Linear { ppm_per_h: 15.0 })],
            vec![Expected::on("thermal_growth", X).with(Figure::GrowthAt {
                minutes: 90.0,
                truth_ppm: 22.5,
                tolerance: GROWTH_TOLERANCE,
            })],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        scenario(
            "thermal-linear-z",
            thermal(),
            102,
            vec![growth(Z, 0.0, Growth::Linear { ppm_per_h: 12.0 })],
            vec![Expected::on("thermal_growth", Z).with(Figure::GrowthAt {
                minutes: 90.0,
                truth_ppm: 18.0,
                tolerance: GROWTH_TOLERANCE,
            })],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        scenario(
            "thermal-saturating-y",
            thermal(),
            103,
            vec![growth(Y, 0.0, Growth::Saturating { ppm: 20.0, time_constant_min: 25.0 })],
            // 20·(1 − e^{−90/25}) = 19.454 ppm.
            vec![Expected::on("thermal_growth", Y).with(Figure::GrowthAt {
                minutes: 90.0,
                truth_ppm: 19.454,
                tolerance: GROWTH_TOLERANCE,
            })],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        scenario(
            "thermal-saturating-x",
            thermal(),
            104,
            vec![growth(X, 500.0, Growth::Saturating { ppm: 15.0, time_constant_min: 35.0 })],
            // 15·(1 − e^{−90/35}) = 13.855 ppm.
            vec![Expected::on("thermal_growth", X).with(Figure::GrowthAt {
                minutes: 90.0,
                truth_ppm: 13.855,
                tolerance: GROWTH_TOLERANCE,
            })],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        // A spike of Y growing with the feed (1.7 µm at 500, 3 µm at 1000, 5.2 µm at 2000
        // mm/min), learned at two feeds, predicted at a third.
        scenario(
            "spike-feed-y",
            session(two_feeds(500.0, 2000.0), circles(1000.0, PIVOT), (0.1, 0.0), PAUSE_S, 1.0),
            105,
            vec![Perturbation::FeedSpike { axis: Y, height_um: 3.0, exponent: 0.8, tau_ms: 40.0 }],
            vec![Expected::on("reversal_spike", Y)],
            &format!("{paper}; F 500 and 2000, then 1000"),
            "training: F 500 and 2000 (12 runs); held out: F 1000 (6 runs, after them), a feed the training never saw",
        ),
        // Stribeck friction of X (v_s = 100 mm/min: ±11° of each X reversal at 500 mm/min,
        // ±6° at 1000), the Coulomb part a backlash step of the base model.
        scenario(
            "stick-slip-stribeck-x",
            session(two_feeds(500.0, 1000.0), circles(700.0, PIVOT), (0.2, 0.0), PAUSE_S, 1.0),
            106,
            vec![Perturbation::Stribeck {
                axis: X,
                stribeck_um: 2.5,
                coulomb_um: 1.0,
                speed_mm_per_min: 100.0,
            }],
            vec![Expected::on("stick_slip", X)],
            &format!("{paper}; F 500 and 1000, then 700"),
            "training: F 500 and 1000 (12 runs); held out: F 700 (6 runs, after them), a feed the training never saw",
        ),
        // The X carriage's play across its guide (in Y), crossing over ±15 samples of an X
        // reversal at 1000 mm/min, ±4 at 2000.
        scenario(
            "lateral-play-soft-yx",
            session(two_feeds(1000.0, 2000.0), circles(1500.0, PIVOT), (0.2, 0.0), PAUSE_S, 1.0),
            107,
            vec![Perturbation::SoftLateralPlay {
                axis: Y,
                switched_by: X,
                play_um: 3.0,
                switch_mm_per_min: 10.0,
            }],
            vec![Expected {
                kind: "lateral_play",
                axis: Some(Y),
                switched_by: Some(X),
                figures: vec![Figure::Parameter {
                    name: "play_um",
                    truth: 3.0,
                    tolerance: PLAY_TOLERANCE,
                }],
            }],
            &format!("{paper}; F 1000 and 2000, then 1500"),
            "training: F 1000 and 2000 (12 runs); held out: F 1500 (6 runs, after them), a feed the training never saw",
        ),
        // A 23 Hz mode of X excited in proportion to the feed (0.6 µm at 1000 mm/min).
        scenario(
            "vibration-feed-x",
            session(two_feeds(1000.0, 2000.0), circles(1500.0, PIVOT), (0.2, 0.0), PAUSE_S, 1.0),
            108,
            vec![Perturbation::FeedVibration { axis: X, amplitude_um: 0.6, frequency_hz: 23.0 }],
            // The reported amplitude is the RMS over the runs of each run's: 0.6 µm at F 1000 and
            // 1.2 µm at F 2000, six runs each, √((0.36 + 1.44)/2) = 0.949 µm.
            vec![
                Expected::on("vibration", X)
                    .with(Figure::Parameter { name: "frequency_hz", truth: 23.0, tolerance: 0.002 })
                    .with(Figure::Parameter {
                        name: "amplitude_um",
                        truth: 0.949,
                        tolerance: PLAY_TOLERANCE,
                    }),
            ],
            &format!("{paper}; F 1000 and 2000, then 1500"),
            "training: F 1000 and 2000 (12 runs); held out: F 1500 (6 runs, after them), a feed the training never saw",
        ),
        // The set-ups a user varies, under the model a user gets by default (a lag per axis,
        // the bar length fitted), each with one effect of modest size: the base model needs
        // the configurations to determine its own parameters, the held-out runs are a set-up
        // the training never saw.
        defaults(scenario(
            "vibration-two-feeds-default-y",
            default_session(
                default_feeds(1000.0, 2000.0),
                tests_at(&Plane::PLANAR, RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL),
                (0.2, 0.0),
                PAUSE_S,
            ),
            112,
            vec![Perturbation::FeedVibration { axis: Y, amplitude_um: 0.5, frequency_hz: 19.0 }],
            vec![Expected::on("vibration", Y).with(Figure::Parameter {
                name: "frequency_hz",
                truth: 19.0,
                tolerance: 0.002,
            })],
            &format!("{lags}; F 1000 and 2000, then 1500"),
            "training: F 1000 and 2000 (12 runs); held out: F 1500 (6 runs, after them), a feed the training never saw",
        )),
        defaults(scenario(
            "spike-one-side-two-tools-x",
            default_session(
                [TOOL_BALL, LONG_TOOL]
                    .into_iter()
                    .flat_map(|tool| tests_at(&Plane::PLANAR, RADIUS_MM, 1000.0, PIVOT, tool, FULL))
                    .collect(),
                tests_at(&Plane::PLANAR, RADIUS_MM, 1000.0, PIVOT, MID_TOOL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            113,
            vec![Perturbation::RingingSpike {
                axis: X,
                height_um: 2.5,
                tau_ms: 30.0,
                ring_hz: 20.0,
                side: Some(1.0),
            }],
            vec![Expected::on("reversal_spike", X)],
            &format!("{lags}; tool lengths 100 and 200 mm, then 150, F 1000"),
            "training: tool lengths 100 and 200 mm (12 runs); held out: 150 mm (6 runs, after them), a tool the training never saw",
        )),
        defaults(scenario(
            "cyclic-two-radii-y",
            default_session(
                [RADIUS_MM, 150.0]
                    .into_iter()
                    .flat_map(|r| tests_at(&Plane::PLANAR, r, 1000.0, PIVOT, TOOL_BALL, FULL))
                    .collect(),
                tests_at(&Plane::PLANAR, 125.0, 1000.0, PIVOT, TOOL_BALL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            114,
            vec![Perturbation::CyclicWaviness {
                axis: Y,
                pitch_mm: 20.0,
                first_um: 0.6,
                second_um: 0.25,
            }],
            vec![Expected::on("cyclic_error", Y)],
            &format!("{lags}; R 100 and 150, then 125, F 1000"),
            "training: R 100 and 150 mm (12 runs); held out: R 125 mm (6 runs, after them), a bar the training never saw",
        )),
        // The shop floor's test: one plane, CW and CCW, repeated.
        defaults(scenario(
            "spike-single-plane-y",
            default_session(
                (0..3)
                    .flat_map(|_| tests_at(&[Plane::XY], RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL))
                    .collect(),
                tests_at(&[Plane::XY], RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            115,
            vec![Perturbation::RingingSpike {
                axis: Y,
                height_um: 3.0,
                tau_ms: 25.0,
                ring_hz: 30.0,
                side: None,
            }],
            vec![Expected::on("reversal_spike", Y)],
            &format!("{lags}; XY only, F 1500"),
            "training: three repeats of XY CW and CCW (6 runs); held out: a fourth (2 runs, after them)",
        )),
        // A partial arc where the full circle does not fit (220° in ZX, from −20°).
        defaults(scenario(
            "play-partial-arc-zx",
            default_session(
                (0..3)
                    .flat_map(|_| {
                        tests_at(&[Plane::ZX], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, ARC_220)
                    })
                    .collect(),
                tests_at(&[Plane::ZX], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, ARC_220),
                (0.15, 0.0),
                PAUSE_S,
            ),
            116,
            vec![Perturbation::SoftLateralPlay {
                axis: X,
                switched_by: Z,
                play_um: 2.5,
                switch_mm_per_min: 10.0,
            }],
            vec![Expected {
                kind: "lateral_play",
                axis: Some(X),
                switched_by: Some(Z),
                figures: vec![],
            }],
            &format!("{lags}; ZX arcs of 220° from −20°, F 1000"),
            "training: three repeats of the ZX arc CW and CCW (6 runs); held out: a fourth (2 runs, after them)",
        )),
        defaults(scenario(
            "null-feeds-and-tools-default",
            default_session(
                [
                    (1000.0, TOOL_BALL),
                    (2000.0, TOOL_BALL),
                    (1000.0, LONG_TOOL),
                    (2000.0, LONG_TOOL),
                ]
                .into_iter()
                .flat_map(|(f, tool)| tests_at(&Plane::PLANAR, RADIUS_MM, f, PIVOT, tool, FULL))
                .collect(),
                tests_at(&Plane::PLANAR, RADIUS_MM, 1500.0, PIVOT, MID_TOOL, FULL),
                (0.2, 0.0),
                PAUSE_S,
            ),
            117,
            vec![],
            vec![],
            &format!(
                "{lags}; F 1000 and 2000 × tool lengths 100 and 200 mm, then F 1500 with 150 mm"
            ),
            "training: two feeds × two tool lengths (24 runs); held out: F 1500 with a 150 mm tool (6 runs, after them), a set-up the training never saw",
        )),
        // Set-ups the scenarios above do not have, as a user meets them, each with shapes the
        // library does not have.
        // The horizontal machine (table Z, column X, head Y on it), under the paper's model.
        on_horizontal(scenario(
            "horizontal-ringing-spike-z",
            horizontal_session(cycles(2), cycle(), (0.15, 0.0), PAUSE_S),
            118,
            vec![Perturbation::RingingSpike {
                axis: Z,
                height_um: 2.5,
                tau_ms: 30.0,
                ring_hz: 25.0,
                side: None,
            }],
            vec![Expected::on("reversal_spike", Z)],
            "the horizontal machine's paper base errors, 3 µm centring, R 100, 125 Hz; 18 runs at F 1000",
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        )),
        // A YZ-only session (X at rest), repeated, a mode of Z driven by the feed.
        defaults(scenario(
            "vibration-yz-only-z",
            default_session(
                (0..3)
                    .flat_map(|_| tests_at(&[Plane::YZ], RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL))
                    .collect(),
                tests_at(&[Plane::YZ], RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            119,
            vec![Perturbation::FeedVibration { axis: Z, amplitude_um: 0.4, frequency_hz: 27.0 }],
            // 0.4 µm at 1000 mm/min, ∝ F: 0.6 µm at 1500 in every run.
            vec![
                Expected::on("vibration", Z)
                    .with(Figure::Parameter { name: "frequency_hz", truth: 27.0, tolerance: 0.002 })
                    .with(Figure::Parameter {
                        name: "amplitude_um",
                        truth: 0.6,
                        tolerance: PLAY_TOLERANCE,
                    }),
            ],
            &format!("{lags}; YZ only, F 1500"),
            "training: three repeats of YZ CW and CCW (6 runs); held out: a fourth (2 runs, after them)",
        )),
        // A session sampled at 250 Hz: a spike of X recovering over 8 ms (one sample interval at
        // 125 Hz, two at 250 Hz).
        scenario(
            "spike-250hz-x",
            at_rate(session(cycles(2), cycle(), (0.15, 0.0), PAUSE_S, 1.0), 250.0),
            120,
            vec![Perturbation::FeedSpike { axis: X, height_um: 2.0, exponent: 0.8, tau_ms: 8.0 }],
            vec![Expected::on("reversal_spike", X)],
            "the paper's base errors, 3 µm centring, R 100, 250 Hz; 18 runs at F 1000",
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        ),
        // A session at the instrument's own 1 kHz, XY only: a small spike on one side of Y's
        // reversals that removes most of the excess above the noise and little of the RMS.
        defaults(scenario(
            "spike-1khz-one-side-y",
            at_rate(
                default_session(
                    (0..3)
                        .flat_map(|_| {
                            tests_at(&[Plane::XY], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, FULL)
                        })
                        .collect(),
                    tests_at(&[Plane::XY], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, FULL),
                    (0.25, 0.0),
                    PAUSE_S,
                ),
                1000.0,
            ),
            121,
            vec![Perturbation::RingingSpike {
                axis: Y,
                height_um: 1.5,
                tau_ms: 10.0,
                ring_hz: 40.0,
                side: Some(-1.0),
            }],
            vec![Expected::on("reversal_spike", Y)],
            &format!("{}; XY only, F 1000", lags.replace("125 Hz", "1 kHz")),
            "training: three repeats of XY CW and CCW (6 runs); held out: a fourth (2 runs, after them)",
        )),
        // Radii and feeds varied together.
        defaults(scenario(
            "cyclic-radii-and-feeds-x",
            default_session(
                [(RADIUS_MM, 1000.0), (RADIUS_MM, 2000.0), (150.0, 1000.0), (150.0, 2000.0)]
                    .into_iter()
                    .flat_map(|(r, f)| tests_at(&Plane::PLANAR, r, f, PIVOT, TOOL_BALL, FULL))
                    .collect(),
                tests_at(&Plane::PLANAR, 125.0, 1500.0, PIVOT, TOOL_BALL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            122,
            vec![Perturbation::CyclicWaviness {
                axis: X,
                pitch_mm: 16.0,
                first_um: 0.5,
                second_um: 0.2,
            }],
            vec![Expected::on("cyclic_error", X)],
            &format!("{lags}; R 100 and 150 × F 1000 and 2000, then R 125 at F 1500"),
            "training: two radii × two feeds (24 runs); held out: R 125 mm at F 1500 (6 runs, after them), a set-up the training never saw",
        )),
        // Two effects at once: a saturating growth of X in a warm-up with a spike on one side
        // of Y's reversals.
        scenario(
            "thermal-saturating-x-with-spike-y",
            thermal(),
            123,
            vec![
                growth(X, 0.0, Growth::Saturating { ppm: 15.0, time_constant_min: 30.0 }),
                Perturbation::RingingSpike {
                    axis: Y,
                    height_um: 2.0,
                    tau_ms: 25.0,
                    ring_hz: 20.0,
                    side: Some(1.0),
                },
            ],
            // 15·(1 − e^{−90/30}) = 14.253 ppm.
            vec![
                Expected::on("thermal_growth", X).with(Figure::GrowthAt {
                    minutes: 90.0,
                    truth_ppm: 14.253,
                    tolerance: GROWTH_TOLERANCE,
                }),
                Expected::on("reversal_spike", Y),
            ],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        // A spike of X while the bar itself drifts slowly with the shop's air: its length
        // differs from run to run, which the diagnosis names (`bar_length_drift`) and then
        // judges the spike on what that leaves.
        scenario(
            "spike-with-bar-drift-x",
            session(cycles(2), cycle(), (0.15, 0.0), PAUSE_S, 1.0),
            124,
            vec![
                Perturbation::FeedSpike { axis: X, height_um: 2.5, exponent: 0.8, tau_ms: 30.0 },
                Perturbation::BarDrift {
                    amplitude_um: [0.15, 0.1],
                    period_min: [7.0, 17.0],
                    phase_deg: [30.0, 200.0],
                },
            ],
            vec![Expected::on("reversal_spike", X), Expected::of_the_bar()],
            &format!("{paper}; 18 runs at F 1000"),
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        ),
        // An effect of Z, learned at two feeds under the default model (the lags rest on the
        // two feeds).
        defaults(scenario(
            "spike-two-feeds-default-z",
            default_session(
                default_feeds(1000.0, 2000.0),
                tests_at(&Plane::PLANAR, RADIUS_MM, 1500.0, PIVOT, TOOL_BALL, FULL),
                (0.15, 0.0),
                PAUSE_S,
            ),
            125,
            vec![Perturbation::FeedSpike { axis: Z, height_um: 2.5, exponent: 0.8, tau_ms: 30.0 }],
            vec![Expected::on("reversal_spike", Z)],
            &format!("{lags}; F 1000 and 2000, then 1500"),
            "training: F 1000 and 2000 (12 runs); held out: F 1500 (6 runs, after them), a feed the training never saw",
        )),
        // A 220° arc in XY (from −20°) with a cyclic error of X.
        defaults(scenario(
            "cyclic-partial-arc-xy-x",
            default_session(
                (0..3)
                    .flat_map(|_| {
                        tests_at(&[Plane::XY], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, ARC_220)
                    })
                    .collect(),
                tests_at(&[Plane::XY], RADIUS_MM, 1000.0, PIVOT, TOOL_BALL, ARC_220),
                (0.15, 0.0),
                PAUSE_S,
            ),
            126,
            vec![Perturbation::CyclicWaviness {
                axis: X,
                pitch_mm: 20.0,
                first_um: 0.6,
                second_um: 0.25,
            }],
            vec![Expected::on("cyclic_error", X)],
            &format!("{lags}; XY arcs of 220° from −20°, F 1000"),
            "training: three repeats of the XY arc CW and CCW (6 runs); held out: a fourth (2 runs, after them)",
        )),
        // Nulls of set-ups above.
        defaults(scenario(
            "null-low-feed-long-runs",
            default_session(
                (0..2)
                    .flat_map(|_| {
                        tests_at(&Plane::PLANAR, RADIUS_MM, 500.0, PIVOT, TOOL_BALL, FULL)
                    })
                    .collect(),
                tests_at(&Plane::PLANAR, RADIUS_MM, 500.0, PIVOT, TOOL_BALL, FULL),
                (0.2, 40.0),
                PAUSE_S,
            ),
            127,
            vec![],
            vec![],
            &format!("{lags}; 18 runs of 75 s at F 500"),
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        )),
        defaults(scenario(
            "null-tool-and-pivot-default",
            default_session(
                (0..2)
                    .flat_map(|_| {
                        tests_at(&Plane::PLANAR, RADIUS_MM, 1000.0, OTHER_PIVOT, OTHER_TOOL, FULL)
                    })
                    .collect(),
                tests_at(&Plane::PLANAR, RADIUS_MM, 1000.0, OTHER_PIVOT, OTHER_TOOL, FULL),
                (0.2, 0.0),
                PAUSE_S,
            ),
            128,
            vec![],
            vec![],
            &format!("{lags}; pivot (250, 150, −350) mm, tool length 180 mm, F 1000"),
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        )),
        // Nulls.
        scenario(
            "null-correlated-noise",
            session(cycles(2), cycle(), (0.25, 80.0), PAUSE_S, 1.0),
            109,
            vec![Perturbation::WhiteNoise { sd_um: 0.1 }],
            vec![],
            &format!("{paper}; 18 runs at F 1000"),
            "training: two repeats (12 runs); held out: a third repeat (6 runs, after them)",
        ),
        // The thermal session's 90 minutes with nothing growing: the later-runs folds' log-ratio
        // t must not turn correlated noise into a growth.
        scenario(
            "null-long-session",
            session(cycles(2), cycle(), (0.25, 80.0), THERMAL_PAUSE_S, 1.0),
            111,
            vec![Perturbation::WhiteNoise { sd_um: 0.1 }],
            vec![],
            &format!("{paper}; 18 runs at F 1000 over 90 min"),
            thermal_split,
        ),
        scenario(
            "null-worn-machine",
            session(cycles(2), circles(1000.0, [200.0, 200.0, -300.0]), (0.2, 0.0), PAUSE_S, 3.0),
            110,
            vec![],
            vec![],
            "three times the paper's base errors (squareness YZ 399 µrad, backlash X 11.4 µm), 3 µm centring, R 100, 125 Hz; centre X 300, then X 200",
            "training: two repeats at the centre X 300 (12 runs); held out: 6 runs centred at X 200, after them, a centre the training never saw",
        ),
    ];
    all.into_iter()
        .map(|s| match EXCESS_OPEN.iter().find(|(name, _)| *name == s.name) {
            Some((_, why)) => open(s, EXCESS, why),
            None => s,
        })
        .collect()
}

/// The runs of a scenario's session, in order (training first): the base machine simulated,
/// the perturbations added.
pub fn runs(s: &Scenario) -> Result<Vec<Run>, ValidationError> {
    let mut runs = simulate(&s.machine, &s.base, SESSION_START_UNIX_S, s.seed)?.runs;
    perturb::apply(&s.perturbations, &mut runs, s.seed ^ 0x9e37_79b9_7f4a_7c15);
    Ok(runs)
}

/// Refinements of a held-out run's nuisances against the exact chain: the first solve is
/// linear in them; each further one corrects the second order (centring of micrometres on a
/// 100 mm bar: 1e-7 µm), so two reach rounding.
pub const NUISANCE_REFINEMENTS: usize = 3;

/// Where the backlash of a model fitted on the training runs `training` switches, s per axis
/// (X, Y, Z, A, B, C): the base model's switch search on them
/// ([`ballbar_fit::switch::switch_at_lagged_reversals`]), as `ballbar fit` and `ballbar
/// diagnose` find it and save it with the model (`switch_lags_s`; the diagnosis's augmented
/// fit switches where its base does), and as `predict` then evaluates new runs with it. All 0
/// (the commanded reversal) when the model has no servo-lag term or the runs do not determine
/// the switch. A judge that switched at the commanded reversal where the saved model does not
/// would count, on each held-out run, the samples between the two switches of an axis with
/// backlash as a gap no effect can close (on spike-single-plane-y, two thirds of the held-out
/// excess energy: 6.7e-3 µm² at the commanded reversal, 2.4e-3 at X's lagged one).
pub fn training_switch(
    spec: &MachineSpec,
    options: ModelOptions,
    training: &[Run],
    threads: usize,
) -> Result<[f64; 6], ValidationError> {
    let model =
        Model::with_kernels(spec.clone(), options, &NoKernels).map_err(DiagnoseError::from)?;
    let design = Design::new(&model, training).map_err(DiagnoseError::from)?;
    let (_, switch) = ballbar_fit::switch::switch_at_lagged_reversals(design, threads)
        .map_err(DiagnoseError::from)?;
    Ok(switch.lags_s)
}

/// The held-out RMS (mm) of a model (the base model of `spec`, `options`, plus `effects`)
/// fitted on the training runs `runs[..n_training]` ([`ballbar_fit::fit`]: exact chain, gauges)
/// with its backlash switching `switch_lags_s` after the commanded reversals
/// ([`training_switch`]) and predicting the held-out runs `runs[n_training..]`.
///
/// Each held-out run is predicted with the training fit's machine parameters (by id) and its
/// switch lags, as the CLI's `predict` evaluates a saved model ([`Design::exact_run`]), and only the run's own
/// nuisances are fitted on it: its centring and its own coefficients of the model's run terms
/// (a vibration's phase), [`Design::run_columns`]. They are solved by least squares on the
/// run's own design columns ([`Design::fill_run`], [`ballbar_fit::lstsq`]) against the
/// residual of the exact model, refined [`NUISANCE_REFINEMENTS`] times. The design holds every
/// run of the session, so that session time (a drift's clock) starts where the training's
/// did. The RMS pools every held-out sample. (A run term's two columns fitted on a held-out
/// run of thousands of samples also take up its noise's share, 2/m of its variance: 0.02 % of
/// the closure, not added back.)
pub fn held_out_rms(
    spec: &MachineSpec,
    options: ModelOptions,
    effects: &[Effect],
    runs: &[Run],
    n_training: usize,
    switch_lags_s: [f64; 6],
    threads: usize,
) -> Result<f64, ValidationError> {
    assert!(n_training > 0 && n_training < runs.len(), "training and held-out runs");
    let model = if effects.is_empty() {
        Model::with_kernels(spec.clone(), options, &NoKernels)
    } else {
        Model::with_effects(spec.clone(), options, &NoKernels, effects)
    }
    .map_err(DiagnoseError::from)?;
    let training = Design::new(&model, &runs[..n_training])
        .map_err(DiagnoseError::from)?
        .with_switch_lags(switch_lags_s);
    let fitted = fit(&training, threads).map_err(DiagnoseError::from)?;
    let all =
        Design::new(&model, runs).map_err(DiagnoseError::from)?.with_switch_lags(switch_lags_s);
    let mut theta = vec![0.0; all.n_cols()];
    for (j, p) in all.parameters[..all.n_machine].iter().enumerate() {
        let k = fitted.index(&p.id).expect("one model: the same machine parameters");
        theta[j] = fitted.values[k];
    }
    let (mut sse, mut n) = (0.0, 0usize);
    for r in n_training..runs.len() {
        let res = held_out_residuals(&all, r, &mut theta)?;
        sse += res.iter().map(|x| x * x).sum::<f64>();
        n += res.len();
    }
    Ok((sse / n.max(1) as f64).sqrt())
}

/// The residuals (mm) of held-out run `r` under `theta`, its own nuisance columns fitted on it
/// (written into `theta`).
fn held_out_residuals(
    design: &Design<'_>,
    r: usize,
    theta: &mut [f64],
) -> Result<Vec<f64>, DiagnoseError> {
    let run = &design.runs[r];
    let m = run.len();
    let cols: Vec<usize> = design.run_columns(r).collect();
    let mut a = vec![0.0; m * cols.len()];
    let mut targets = vec![0.0; m];
    design.fill_run(r, &cols, &mut a, &mut targets, &mut BlockScratch::default())?;
    let a = faer::MatRef::from_column_major_slice(&a, m, cols.len());
    let residual = |theta: &[f64]| -> Result<Vec<f64>, DiagnoseError> {
        Ok(run.dr_mm.iter().zip(design.exact_run(r, theta)?).map(|(y, f)| y - f).collect())
    };
    let mut res = residual(theta)?;
    for _ in 0..NUISANCE_REFINEMENTS {
        let (step, _) = ballbar_fit::lstsq(a, &res)?;
        for (&c, s) in cols.iter().zip(&step) {
            theta[c] += s;
        }
        res = residual(theta)?;
    }
    Ok(res)
}

/// Run a scenario: simulate and perturb, diagnose the training runs, measure the held-out
/// closure, check.
pub fn run(s: &Scenario, threads: usize) -> Result<Outcome, ValidationError> {
    let t0 = Instant::now();
    let runs = runs(s)?;
    let training = &runs[..s.training_runs];
    let d = diagnose(
        &s.machine,
        s.options,
        &NoKernels,
        training,
        Options { threads, ..Options::default() },
    )?;

    // Measured: the held-out runs under the base and the augmented model.
    // Each model switches where a model saved from the training runs does.
    let lags = training_switch(&s.machine, s.options, training, threads)?;
    let base = held_out_rms(&s.machine, s.options, &[], &runs, s.training_runs, lags, threads)?;
    let augmented = if d.model_effects.is_empty() {
        base
    } else {
        let (effects, n) = (&d.model_effects, s.training_runs);
        held_out_rms(&s.machine, s.options, effects, &runs, n, lags, threads)?
    };
    let measured =
        if d.model_effects.is_empty() || base <= 0.0 { 0.0 } else { 1.0 - augmented / base };
    // Claimed: the diagnosis's own claim for its effects together (what the terminal and the
    // JSON `held_out` say), on the folds it chose for the user's question.
    let claimed = if d.effects.is_empty() { 0.0 } else { d.held_out.shrink };

    let mut checks = Vec::new();
    let mut used = vec![false; d.effects.len()];
    for exp in &s.expect {
        let found = d.effects.iter().enumerate().find(|(i, a)| !used[*i] && exp.matches(&a.effect));
        match found {
            Some((i, a)) => {
                used[i] = true;
                checks.push(check(
                    format!("kind and axis: {}", exp.label()),
                    true,
                    a.effect.describe(),
                ));
                for fig in &exp.figures {
                    let (name, pass, detail) = fig.check(a);
                    checks.push(check(format!("{}: {name}", exp.label()), pass, detail));
                }
            }
            None => checks.push(check(
                format!("kind and axis: {}", exp.label()),
                false,
                format!("not among the accepted effects ({})", named(&d)),
            )),
        }
    }
    let extra: Vec<String> = d
        .effects
        .iter()
        .zip(&used)
        .filter(|(_, u)| !**u)
        .map(|(a, _)| a.effect.describe())
        .collect();
    let name = if s.expect.is_empty() { "no effect" } else { "no other effect" };
    checks.push(check(
        name,
        extra.is_empty(),
        if extra.is_empty() { "none".to_string() } else { extra.join("; ") },
    ));
    let gap = (claimed - measured).abs();
    checks.push(check(
        "claimed closure",
        gap <= CLOSURE_TOLERANCE,
        format!(
            "claimed {:.1} %, measured {:.1} % on the held-out runs (base {:.3} µm, augmented {:.3} µm): |Δ| {:.1} points (≤ {:.0})",
            claimed * 100.0,
            measured * 100.0,
            base * 1e3,
            augmented * 1e3,
            gap * 100.0,
            CLOSURE_TOLERANCE * 100.0
        ),
    ));
    // The share of the excess above the noise: claimed, and shown by the held-out runs above
    // the floor the diagnosis states; or, where the claim says the share is not determined,
    // the held-out runs' excess against the bound it states.
    let floor = d.held_out.noise_um * 1e-3;
    let (claimed_excess, measured_excess) = if d.model_effects.is_empty() {
        (0.0, 0.0)
    } else {
        (d.held_out.excess_closed, ballbar_diagnose::excess::closed(base, augmented, floor))
    };
    let held_out_samples: usize = runs[s.training_runs..].iter().map(Run::len).sum();
    let undetermined =
        d.held_out.excess.filter(|share| !d.model_effects.is_empty() && !share.determined).map(
            |share| {
                // The held-out runs' own chance: the diagnosis's noise over their samples (the
                // floor's u is the claim's; the same floor serves both).
                let chance = ballbar_diagnose::excess::Chance {
                    floor_u: 0.0,
                    ..ballbar_diagnose::excess::Chance::of(&d.noise, held_out_samples)
                };
                (share, chance.excess_energy_u(base, floor) * 1e6)
            },
        );
    checks.push(match undetermined {
        Some((share, own_u_um2)) => undetermined_check(&share, own_u_um2, (base, augmented, floor)),
        None => excess_check(claimed_excess, measured_excess, (base, augmented, floor)),
    });

    Ok(Outcome {
        scenario: s.name,
        truth: s.truth.clone(),
        split: s.split.clone(),
        diagnosis: named(&d),
        held_out_base_um: base * 1e3,
        held_out_augmented_um: augmented * 1e3,
        claimed,
        measured,
        claimed_excess,
        measured_excess,
        checks,
        seconds: t0.elapsed().as_secs_f64(),
        diagnosis_result: d,
        open: s.open,
    })
}

/// The accepted effects as `kind axis` with their description, in the order accepted.
fn named(d: &Diagnosis) -> String {
    if d.effects.is_empty() {
        return "no effect".into();
    }
    d.effects
        .iter()
        .map(|a| match a.effect.axis_label() {
            Some(axis) => format!("{} {axis} [{}]", a.effect.kind(), a.effect.describe()),
            None => format!("{} [{}]", a.effect.kind(), a.effect.describe()),
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The check of the claimed share of the excess above the noise against the share the
/// held-out runs show (`(base, augmented, floor)`, mm), within [`CLOSURE_TOLERANCE`]. Where the
/// held-out runs have no excess above the floor to close (their base RMS at or below it), no
/// share can be shown: the claim passes when it claims none (NaN or 0), or that the effects
/// leave nothing above the noise (within the tolerance of all of it), as the held-out runs
/// then show too (their augmented RMS is at or below the floor as well).
pub fn excess_check(
    claimed: f64,
    measured: f64,
    (base, augmented, floor): (f64, f64, f64),
) -> Check {
    let figures = format!(
        "held-out runs: base {:.3} µm, augmented {:.3} µm, floor {:.3} µm",
        base * 1e3,
        augmented * 1e3,
        floor * 1e3
    );
    if measured.is_nan() {
        let pass = claimed.is_nan()
            || claimed == 0.0
            || (augmented <= floor && claimed >= 1.0 - CLOSURE_TOLERANCE);
        return check(
            EXCESS,
            pass,
            format!(
                "claimed {:.1} % of the excess above the noise; the {figures}: no excess above the floor to close",
                claimed * 100.0
            ),
        );
    }
    let gap = (claimed - measured).abs();
    check(
        EXCESS,
        gap <= CLOSURE_TOLERANCE,
        format!(
            "claimed {:.1} %, measured {:.1} % of the excess above the noise ({figures}): |Δ| {:.1} points (≤ {:.0})",
            claimed * 100.0,
            measured * 100.0,
            gap * 100.0,
            CLOSURE_TOLERANCE * 100.0
        ),
    )
}

/// The check of a claim that the share of the excess is not determined (its excess energy
/// before within two standard uncertainties of zero, [`ballbar_diagnose::excess::share`]):
/// the held-out runs' excess energy above the same floor, `base² − floor²`, must be within the
/// stated uncertainty too, `D₀ + 2·√(u² + u_h²)` with `D₀` and `u` the claim's (µm², the
/// share's `excess_before` squared and `excess_energy_u`) and `u_h` the held-out runs' own
/// chance (`own_u_um2`: their noise's mean square over their samples, and the cross term,
/// from the diagnosis's noise model). A claim that the excess is within its uncertainty of
/// zero where the runs that come next show more is as wrong as a share they do not show.
pub fn undetermined_check(
    share: &ballbar_diagnose::excess::Share,
    own_u_um2: f64,
    (base, augmented, floor): (f64, f64, f64),
) -> Check {
    let d0 = share.excess_before * share.excess_before;
    let allowed = d0 + 2.0 * share.excess_energy_u.hypot(own_u_um2);
    let shown = (base * base - floor * floor) * 1e6;
    check(
        EXCESS,
        shown <= allowed,
        format!(
            "claimed not determined (held-out excess {:.3} µm, its energy {:.2e} ± {:.1e} µm²); the held-out runs: base {:.3} µm, augmented {:.3} µm, floor {:.3} µm: excess energy {:.2e} µm² (± {:.1e} of their own), within the claim's D₀ + 2√(u² + u_h²) = {:.2e} µm²: {}",
            share.excess_before,
            d0,
            share.excess_energy_u,
            base * 1e3,
            augmented * 1e3,
            floor * 1e3,
            shown,
            own_u_um2,
            allowed,
            if shown <= allowed { "yes" } else { "no" }
        ),
    )
}

fn check(name: impl Into<String>, pass: bool, detail: impl Into<String>) -> Check {
    Check { name: name.into(), pass, detail: detail.into() }
}

/// The scoreboard as a table: per scenario the held-out base and augmented RMS, the claimed and
/// measured closure, the claimed and measured share of the excess above the noise (`exc`), the result and the time; then the truth, the split, the diagnosis and
/// each failed check.
pub fn scoreboard(rows: &[Outcome]) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "{:<24} {:>8} {:>8} {:>8} {:>9} {:>8} {:>9} {:>7} {:>6}\n",
        "scenario", "base µm", "aug µm", "claimed", "measured", "cl. exc", "ms. exc", "result", "s"
    ));
    let indent = "    ";
    for r in rows {
        s.push_str(&format!(
            "{:<24} {:>8.3} {:>8.3} {:>7.1}% {:>8.1}% {:>7.1}% {:>8.1}% {:>7} {:>6.1}\n",
            r.scenario,
            r.held_out_base_um,
            r.held_out_augmented_um,
            r.claimed * 100.0,
            r.measured * 100.0,
            if r.claimed_excess.is_nan() { f64::NAN } else { r.claimed_excess * 100.0 },
            r.measured_excess * 100.0,
            if r.passed() {
                "pass"
            } else if r.open_only() {
                "open"
            } else {
                "FAIL"
            },
            r.seconds
        ));
        s.push_str(&format!(
            "{indent}truth: {}\n{indent}split: {}\n{indent}→ {}\n",
            r.truth, r.split, r.diagnosis
        ));
        for c in r.failures() {
            s.push_str(&format!("{indent}✗ {}: {}\n", c.name, c.detail));
        }
        if let (false, Some((_, why))) = (r.passed(), r.open) {
            s.push_str(&format!("{indent}open: {why}\n"));
        }
    }
    s
}

//! Pass/fail against the user's tolerances (`ballbar report --tolerance FILE`): a small RON
//! file of limits (format in `docs/report.md`, example `fixtures/tolerances/example.ron`),
//! each limit checked on every plane, axis or run the session tests, and an overall verdict.
//!
//! # What is compared
//! - `circular_deviation_um`: ISO 230-4 circular deviation G of each planar run as measured
//!   (about its least-squares circle, before any model), optionally per plane
//!   (`circular_deviation_per_plane_um`, which overrides it for that plane);
//! - `squareness_um_per_m`, `servo_mismatch_ms` (the lag difference of the plane's axes),
//!   `scale_mismatch_ppm` (the difference of the plane's two axis scales): per tested plane;
//! - `backlash_um`, `scale_error_ppm`: per axis of the tested planes;
//! - `reversal_spike_um`, `lateral_play_um`: per axis, from the diagnosis's named effects.
//!
//! Squareness, scale error and scale mismatch are the local values of each planar test at its
//! circle's centre ([`ballbar_fit::local`], the page's vendor table): what the test determines,
//! whatever pivot and tool length are given for the runs. The machine's global squareness and
//! scales can move with those (a one-plane test cannot tell a squareness from a straightness's
//! slope at its place, nor a scale from an Abbe term at its tool length), and a verdict must
//! not: giving the circle's machine coordinates once turned the shared real file's squareness
//! check from PASS to FAIL. A plane or axis tested at several places gets a row for each. The
//! servo mismatch and backlash are the paper's quantities (the parameters' table, the vendor's
//! units). Every limit bounds the magnitude: |value| ≤ limit. A value that holds only for a
//! choice the tests leave open (a gauge of the fit: the scale error with the bar taken at its
//! nominal length) is NOT CHECKED, naming the choice and the test that would determine it,
//! unless the choice is a calibration the runs state (`.b5r` readings are relative to the
//! calibrated bar): then it is judged, "assuming" it. A limit that no plane, axis or run of the
//! session can check gives a NOT CHECKED row saying why.
//!
//! # Decision rule
//! By default ISO 14253-1's: with the expanded uncertainty U = k·u, k = 2 ([`COVERAGE_FACTOR`]),
//! a value passes when |value| + U ≤ limit (conformance proven), fails when |value| − U > limit
//! (non-conformance proven), and is undecided in between. `decision: Simple` compares
//! |value| ≤ limit and shows U without using it. A figure without an uncertainty (G, measured
//! directly; an effect the diagnosis gives no uncertainty for) is compared plainly, and the page
//! says so. u is the fit's standard uncertainty: it does not include the ballbar's calibration
//! uncertainty. Where the diagnosis names no spike or play of an axis, the check passes only
//! when the limit is above the largest such effect it could have missed
//! ([`detection_bound_um`]), and is UNDECIDED otherwise. The overall verdict is FAIL when a
//! check fails, PASS when there are checks and every one passes, and NOT PROVEN otherwise (a
//! check undecided or not checked, or no check at all).

use std::fmt::Write;
use std::path::Path;

use ballbar_documents::diagnosis::{Diagnosis, Subject, Why};
use ballbar_fit::local::{LocalQuantity, local_quantities};
use ballbar_fit::{Fit, GaugeKind, metrics, quantity};
use ballbar_model::local::LocalKind;
use ballbar_model::machine::Model;
use ballbar_model::paper::{self, Quantity};
use ballbar_model::{Axis, Design, Plane, Run};
use serde::Deserialize;

use crate::ReportError;
use crate::cells::td;
use crate::svg::esc;

/// The coverage factor of the expanded uncertainty U = k·u (ISO 14253-1 uses U at about 95 %:
/// k = 2 for a normal distribution).
pub const COVERAGE_FACTOR: f64 = 2.0;

/// The limits of a tolerance file. Every limit is optional; a key the format does not know is
/// an error (a typo must not drop a check silently).
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Tolerances {
    /// How a value near its limit is judged.
    #[serde(default)]
    pub decision: Decision,
    /// ISO 230-4 circular deviation G of each planar run, µm.
    #[serde(default)]
    pub circular_deviation_um: Option<f64>,
    /// G per plane, µm: overrides `circular_deviation_um` for that plane.
    #[serde(default)]
    pub circular_deviation_per_plane_um: Option<PerPlane>,
    /// |squareness| of each tested plane, µm/m.
    #[serde(default)]
    pub squareness_um_per_m: Option<f64>,
    /// |backlash| of each axis, µm.
    #[serde(default)]
    pub backlash_um: Option<f64>,
    /// |scale error| (positional error per length) of each axis, ppm.
    #[serde(default)]
    pub scale_error_ppm: Option<f64>,
    /// |scale of the plane's first axis − scale of its second| per tested plane, ppm.
    #[serde(default)]
    pub scale_mismatch_ppm: Option<f64>,
    /// |servo mismatch| (lag difference of the plane's axes) per tested plane, ms.
    #[serde(default)]
    pub servo_mismatch_ms: Option<f64>,
    /// |reversal spike| height of each axis, µm (from the diagnosis).
    #[serde(default)]
    pub reversal_spike_um: Option<f64>,
    /// |lateral play| of each axis, µm (from the diagnosis).
    #[serde(default)]
    pub lateral_play_um: Option<f64>,
}

/// A limit per plane.
#[derive(Clone, Debug, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerPlane {
    /// The XY plane.
    #[serde(default)]
    pub xy: Option<f64>,
    /// The YZ plane.
    #[serde(default)]
    pub yz: Option<f64>,
    /// The ZX plane.
    #[serde(default)]
    pub zx: Option<f64>,
}

impl PerPlane {
    fn of(&self, p: Plane) -> Option<f64> {
        match p {
            Plane::XY => self.xy,
            Plane::YZ => self.yz,
            Plane::ZX => self.zx,
            _ => None,
        }
    }
}

/// How a value near its limit is judged.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
pub enum Decision {
    /// ISO 14253-1: pass when |value| + U ≤ limit, fail when |value| − U > limit, else undecided.
    #[default]
    Iso14253,
    /// |value| ≤ limit, the uncertainty shown but not used.
    Simple,
}

impl Decision {
    /// The rule in words, for the page.
    pub fn describe(self) -> String {
        match self {
            Decision::Iso14253 => format!(
                "ISO 14253-1: with the expanded uncertainty U = {COVERAGE_FACTOR}·u (u the fit's standard uncertainty, which leaves out the ballbar's calibration), PASS when |value| + U ≤ limit, FAIL when |value| − U > limit, UNDECIDED in between; a figure without an uncertainty is compared as it is (|value| ≤ limit)"
            ),
            Decision::Simple => "plain comparison, |value| ≤ limit (the file's decision: Simple); U is shown, not used".to_string(),
        }
    }
}

/// A tolerance file, read.
#[derive(Clone, Debug, PartialEq)]
pub struct ToleranceFile {
    /// The file as named on the command line.
    pub name: String,
    /// Its limits.
    pub limits: Tolerances,
}

/// Read a tolerance file: RON errors at their line and column, a limit that is not a positive
/// number at its line.
pub fn read(path: &Path) -> Result<ToleranceFile, ReportError> {
    let text = std::fs::read_to_string(path).map_err(|error| {
        ReportError::File(ballbar_io::IoError::Io { path: path.to_path_buf(), error })
    })?;
    parse(&text, path)
}

/// Parse the text of a tolerance file; `path` names it in messages.
pub fn parse(text: &str, path: &Path) -> Result<ToleranceFile, ReportError> {
    // Limits are written as plain numbers (`backlash_um: 5.0`) or as `Some(5.0)`: RON's
    // `implicit_some` accepts both, so it is enabled here whether or not the file says so. The
    // attribute goes on the file's first line, so that line numbers stay the file's; a column
    // on that line is moved back by its length.
    const IMPLICIT: &str = "#![enable(implicit_some)] ";
    let limits: Tolerances = ballbar_io::ron_files::parse_ron(&format!("{IMPLICIT}{text}"), path)
        .map_err(|e| match e {
        ballbar_io::IoError::Ron { path, line: 1, column, message } => {
            ReportError::File(ballbar_io::IoError::Ron {
                path,
                line: 1,
                column: column.saturating_sub(IMPLICIT.len()).max(1),
                message,
            })
        }
        e => ReportError::File(e),
    })?;
    let t = &limits;
    let per = t.circular_deviation_per_plane_um.clone().unwrap_or_default();
    let all = [
        ("circular_deviation_um", t.circular_deviation_um),
        ("xy", per.xy),
        ("yz", per.yz),
        ("zx", per.zx),
        ("squareness_um_per_m", t.squareness_um_per_m),
        ("backlash_um", t.backlash_um),
        ("scale_error_ppm", t.scale_error_ppm),
        ("scale_mismatch_ppm", t.scale_mismatch_ppm),
        ("servo_mismatch_ms", t.servo_mismatch_ms),
        ("reversal_spike_um", t.reversal_spike_um),
        ("lateral_play_um", t.lateral_play_um),
    ];
    for (key, v) in all {
        if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(ReportError::Tolerance {
                path: path.display().to_string(),
                line: line_of(text, key),
                message: format!("{key}: a limit is a positive number, not {v}"),
            });
        }
    }
    if all.iter().all(|(_, v)| v.is_none()) {
        return Err(ReportError::Tolerance {
            path: path.display().to_string(),
            line: 1,
            message: "the file gives no limit (docs/report.md lists them)".into(),
        });
    }
    Ok(ToleranceFile { name: path.display().to_string(), limits })
}

/// The 1-based line where `key:` is written (1 if not found).
fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            let l = l.split("//").next().unwrap_or("");
            l.find(key).is_some_and(|i| {
                let before = l[..i].chars().next_back();
                !before.is_some_and(|c| c.is_alphanumeric() || c == '_')
                    && l[i + key.len()..].trim_start().starts_with(':')
            })
        })
        .map_or(1, |i| i + 1)
}

/// The outcome of one check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Within the limit (by the decision rule).
    Pass,
    /// Beyond the limit.
    Fail,
    /// Within U of the limit: neither proven.
    Undecided,
    /// These runs cannot give the value.
    NotChecked,
}

impl Verdict {
    /// As printed.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Pass => "PASS",
            Verdict::Fail => "FAIL",
            Verdict::Undecided => "UNDECIDED",
            Verdict::NotChecked => "NOT CHECKED",
        }
    }
}

/// Judge |value| against `limit` with standard uncertainty `u` (`None`: compared as it is).
pub fn judge(value: f64, u: Option<f64>, limit: f64, decision: Decision) -> Verdict {
    let a = value.abs();
    match (decision, u.filter(|u| u.is_finite() && *u > 0.0)) {
        (Decision::Iso14253, Some(u)) => {
            let big_u = COVERAGE_FACTOR * u;
            if a + big_u <= limit {
                Verdict::Pass
            } else if a - big_u > limit {
                Verdict::Fail
            } else {
                Verdict::Undecided
            }
        }
        _ if a <= limit => Verdict::Pass,
        _ => Verdict::Fail,
    }
}

/// One limit checked on one plane, axis or run.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// The file's key.
    pub key: &'static str,
    /// What is checked, in words ("squareness").
    pub what: &'static str,
    /// On what: a plane, an axis, a run.
    pub on: String,
    /// The value (signed), in `unit`; `None` where there is none.
    pub value: Option<f64>,
    /// Its standard uncertainty, where there is one.
    pub u: Option<f64>,
    /// The limit on |value|.
    pub limit: f64,
    /// The unit.
    pub unit: &'static str,
    /// The outcome.
    pub verdict: Verdict,
    /// Where the value comes from, or why there is none.
    pub note: String,
}

impl Check {
    /// The axes the check is about, as a sentence names them: `X` for an axis, `X and Y` for a
    /// plane or a run in it, `the machine` for the session.
    fn axes(&self) -> String {
        if let Some(a) = self.on.strip_prefix("axis ") {
            return a.split_whitespace().next().unwrap_or(a).to_string();
        }
        let plane = self
            .on
            .split(|c: char| !c.is_ascii_alphabetic())
            .find(|w| Plane::PLANAR.iter().any(|p| p.name() == *w));
        match plane.and_then(|w| Plane::PLANAR.into_iter().find(|p| p.name() == w)) {
            Some(p) => {
                let (u, v, _) = p.axes().expect("planar");
                format!("{u} and {v}")
            }
            None => "the machine".into(),
        }
    }

    /// What is out and what to do about it, from the shared shop-floor sentences
    /// (`ballbar_documents::advice::shop_floor`): the check's value as the fault's size.
    fn action(&self, value: f64) -> String {
        use ballbar_documents::advice::{Facts, shop_floor};
        use ballbar_documents::diagnosis::Subject;
        let (kind, parameter) = match self.key {
            "backlash_um" => ("backlash", "value_um"),
            "reversal_spike_um" => ("reversal_spike", "amplitude_um"),
            "lateral_play_um" => ("lateral_play", "play_um"),
            "servo_mismatch_ms" => ("servo_mismatch", "lag_difference_ms"),
            "squareness_um_per_m" => ("squareness", "value_um_per_m"),
            "scale_error_ppm" => ("scale", "value_ppm"),
            "scale_mismatch_ppm" => ("scale_mismatch", "value_ppm"),
            // G sums every error the circle sees: the other rows and the diagnosis say which.
            _ => {
                return "G sums every error the plane's circle sees: act on the other checks that are out and on the diagnosis's \"what the machine needs\" (largest first), compensate what `ballbar compensate` takes (backlash, scale), then repeat this test at the same radius and feed.".into();
            }
        };
        let subject = Subject { kind: kind.into(), axis: Some(self.axes()), switched_by: None };
        let parameters = std::collections::BTreeMap::from([(parameter.to_string(), value)]);
        let sentence = shop_floor(&Facts {
            subject: &subject,
            parameters: &parameters,
            g_before_um: f64::NAN,
            g_after_um: f64::NAN,
        });
        format!("{sentence} Then repeat this test to confirm.")
    }

    /// The check's verdict in one shop-floor line: what is out (the error, on which axis or
    /// plane, its size against the limit) and what to do next; for a PASS that nothing is to
    /// be done, for a check that cannot be judged why and what would judge it.
    pub fn advice(&self) -> String {
        let decimals = if self.unit == "ms" { 3 } else { 2 };
        let on =
            if Plane::PLANAR.iter().any(|p| self.on.starts_with(&format!("{} plane", p.name()))) {
                format!("the {}", self.on)
            } else {
                self.on.clone()
            };
        let subject = format!("{} of {on}", self.what);
        let unit = self.unit;
        let limit = format!("{:.decimals$} {unit}", self.limit);
        let big_u = self.u.map(|u| format!("{:.decimals$}", COVERAGE_FACTOR * u));
        let size = |v: f64| match &big_u {
            Some(u) => format!("{:.decimals$} ± {u} {unit} (U, k = {COVERAGE_FACTOR})", v.abs()),
            None => format!("{:.decimals$} {unit}", v.abs()),
        };
        match (self.verdict, self.value) {
            (Verdict::Pass, Some(v)) => {
                format!(
                    "PASS: {subject} is {}, within the limit of {limit}: nothing to do.",
                    size(v)
                )
            }
            (Verdict::Pass, None) => {
                format!("PASS: {subject}: {}; nothing to do.", self.note)
            }
            (Verdict::Fail, Some(v)) => format!(
                "FAIL: {subject} is {}, {:.1} times the limit of {limit}. {}",
                size(v),
                v.abs() / self.limit,
                self.action(v)
            ),
            (Verdict::Undecided, Some(v)) => format!(
                "UNDECIDED: {subject} is {} against the limit of {limit}: within U of it, so neither in nor out is proven. Repeat the test to lower U (more CW/CCW pairs at the same radius and feed); should it prove out: {}",
                size(v),
                self.action(v)
            ),
            // Named by no effect: the diagnosis's bound is above the limit (more runs lower
            // the noise it is drawn from), or the diagnosis gives no bound at all.
            (Verdict::Undecided, None) if self.note.contains("could go unnamed") => format!(
                "UNDECIDED: {subject} against the limit of {limit}: {}. To decide, repeat the test with more runs: the bound falls with the noise.",
                self.note
            ),
            (Verdict::Undecided, None) => format!(
                "UNDECIDED: {subject} against the limit of {limit}: {}. The diagnosis cannot bound it from these runs: check the axis directly (a dial gauge at its reversals) to decide.",
                self.note
            ),
            (Verdict::NotChecked, _) | (Verdict::Fail, None) => format!(
                "NOT CHECKED: {subject} against the limit of {limit}: {}.",
                if self.note.is_empty() { "these runs give no value" } else { &self.note }
            ),
        }
    }
}

/// The overall verdict in one line and its reason: (CSS class, word, why).
fn summary(checks: &[Check]) -> (&'static str, &'static str, String) {
    let n_fail = checks.iter().filter(|c| c.verdict == Verdict::Fail).count();
    let n_undecided = checks.iter().filter(|c| c.verdict == Verdict::Undecided).count();
    let n_unchecked = checks.iter().filter(|c| c.verdict == Verdict::NotChecked).count();
    match overall(checks) {
        Verdict::Fail => ("fail", "FAIL", format!("{n_fail} of {} checks fail", checks.len())),
        Verdict::Pass => ("pass", "PASS", format!("all {} checks pass", checks.len())),
        _ if checks.is_empty() => ("undecided", "NOT PROVEN", "nothing was checked".to_string()),
        _ => {
            let mut parts = Vec::new();
            if n_undecided > 0 {
                parts.push(format!("{n_undecided} undecided"));
            }
            if n_unchecked > 0 {
                parts.push(format!("{n_unchecked} that these runs cannot check"));
            }
            (
                "undecided",
                "NOT PROVEN",
                format!("no check fails, but of {} checks: {}", checks.len(), parts.join(", ")),
            )
        }
    }
}

/// The acceptance for the terminal: the overall verdict with the file's name, then each
/// check's [`Check::advice`], the same sentences as the page's.
pub fn terminal_lines(file: &ToleranceFile, checks: &[Check]) -> Vec<String> {
    let (_, word, why) = summary(checks);
    std::iter::once(format!("acceptance against {}: {word} — {why}", file.name))
        .chain(checks.iter().map(|c| format!("  {}", c.advice())))
        .collect()
}

/// The overall verdict of `checks`: FAIL when one fails; PASS when there are checks and every
/// one passes; otherwise not proven ([`Verdict::Undecided`], printed NOT PROVEN): a check
/// undecided or not checked, or no check at all (nothing was shown to conform).
pub fn overall(checks: &[Check]) -> Verdict {
    if checks.iter().any(|c| c.verdict == Verdict::Fail) {
        Verdict::Fail
    } else if !checks.is_empty() && checks.iter().all(|c| c.verdict == Verdict::Pass) {
        Verdict::Pass
    } else {
        Verdict::Undecided
    }
}

/// The planes the session tests (planar runs), in order, with the first run of each.
fn tested_planes(runs: &[Run]) -> Vec<(Plane, &Run)> {
    Plane::PLANAR
        .into_iter()
        .filter_map(|p| runs.iter().find(|r| r.header.plane == p).map(|r| (p, r)))
        .collect()
}

/// The first of `of` at each distinct test place (centre, tool ball), in the runs' order: a
/// plane or an axis tested at one place gets one row, named as before; at several, one row
/// each (at one place every test's quantity of an axis is the same functional).
fn first_at_each_place(of: Vec<&LocalQuantity>) -> Vec<&LocalQuantity> {
    let mut out: Vec<&LocalQuantity> = Vec::new();
    for q in of {
        if !out.iter().any(|o| (o.pivot_mm, o.tool_ball_mm) == (q.pivot_mm, q.tool_ball_mm)) {
            out.push(q);
        }
    }
    out
}

fn ids(q: &Quantity) -> Vec<&str> {
    q.terms.iter().map(|(id, _)| id.as_str()).collect()
}

/// The bar-length choice as a calibration the runs state: every run says the calibrated length
/// its readings are relative to (a `.b5r` import keeps `calibrated_length_mm`), so the bar at its
/// nominal length (BAR = 0) is the calibrated bar, not a guess.
fn stated_bar_calibration(runs: &[Run]) -> Option<String> {
    let lengths: Vec<&str> = runs
        .iter()
        .map(|r| {
            r.header.extra.iter().find(|(k, _)| k == "calibrated_length_mm").map(|(_, v)| v.trim())
        })
        .collect::<Option<Vec<_>>>()?;
    let first = *lengths.first()?;
    (!first.is_empty() && lengths.iter().all(|l| *l == first)).then(|| format!("assuming the bar at its calibrated length ({first} mm, the runs' readings are relative to it)"))
}

/// Check every limit of `t` on the session: `model` and `f` the page's fit of `runs`, `diag`
/// the archived diagnosis JSON. Every limit gives at least one row: one that no plane, axis or
/// run of the session can check gives a NOT CHECKED row saying why.
pub fn evaluate(
    t: &Tolerances,
    model: &Model,
    f: &Fit,
    runs: &[Run],
    diag: Option<&Diagnosis>,
) -> Vec<Check> {
    let planes = tested_planes(runs);
    let mut axes: Vec<Axis> = Vec::new();
    for (p, _) in &planes {
        let (u, v, _) = p.axes().expect("planar");
        for a in [u, v] {
            if !axes.contains(&a) {
                axes.push(a);
            }
        }
    }
    axes.sort_by_key(|a| a.index());
    // The paper's rows at each tested plane's radius and feed (a servo mismatch in ms depends
    // on the feed), and at the first plane's for the per-axis rows.
    let rows_of = |r: &Run| paper::report(model, r.header.radius_mm, r.header.feed_mm_per_min);
    let first_rows = planes.first().map(|(_, r)| rows_of(r)).unwrap_or_default();
    let calibration = stated_bar_calibration(runs);
    let mut out = Vec::new();
    // A fitted quantity against a limit. A value that holds only for a choice the tests leave
    // open is not judged (another choice, as consistent with the runs, gives another value),
    // unless the choice is a calibration the runs state (the bar length of a `.b5r` session).
    // An estimate against a limit: `Ok((value, u, the fit's functional))` in the limit's unit,
    // or why there is none. A value that holds only for a choice the tests leave open is not
    // judged (another choice, as consistent with the runs, gives another value), unless the
    // choice is a calibration the runs state (the bar length of a `.b5r` session).
    let judged = |key: &'static str,
                  what: &'static str,
                  on: String,
                  estimate: Result<(f64, f64, Vec<(usize, f64)>), String>,
                  limit: f64,
                  unit: &'static str|
     -> Check {
        let unchecked = |note: String| Check {
            key,
            what,
            on: on.clone(),
            value: None,
            u: None,
            limit,
            unit,
            verdict: Verdict::NotChecked,
            note,
        };
        let (value, u, coeffs) = match estimate {
            Ok(e) => e,
            Err(why) => return unchecked(why),
        };
        let mut assumed = Vec::new();
        for g in f.depends_on(&coeffs).into_iter().filter_map(|g| f.gauges.get(g)) {
            match (&g.kind, &calibration) {
                (GaugeKind::BarLength, Some(stated)) => assumed.push(stated.clone()),
                _ => {
                    return unchecked(format!(
                        "depends on a choice these tests leave open: {}: {} (to determine it: {})",
                        g.what, g.choice, g.separate_by
                    ));
                }
            }
        }
        Check {
            key,
            what,
            on: on.clone(),
            value: Some(value),
            u: Some(u),
            limit,
            unit,
            verdict: judge(value, Some(u), limit, t.decision),
            note: assumed.join("; "),
        }
    };
    // A quantity of the paper's tables (the vendor's units) against a limit; `missing` says
    // why there is none.
    let fitted = |key: &'static str,
                  what: &'static str,
                  on: String,
                  q: Option<Quantity>,
                  limit: f64,
                  unit: &'static str,
                  missing: &str|
     -> Check {
        let estimate = match q {
            None => Err(missing.to_string()),
            Some(q) => match quantity(f, &q).map(|e| e.estimate) {
                Some(e) if e.estimable => Ok((
                    e.value,
                    e.std_uncertainty,
                    q.terms.iter().filter_map(|(id, c)| f.index(id).map(|i| (i, *c))).collect(),
                )),
                _ => Err("not identifiable from these tests".into()),
            },
        };
        judged(key, what, on, estimate, limit, unit)
    };
    // What each planar test determines where it is (`ballbar_fit::local`): the local scales
    // and squareness of the fitted field at the circle's centre. They do not move with the
    // pivot or tool length given for the runs, where the machine's global squareness and
    // scales may (a one-plane test cannot tell a squareness from a straightness's slope at
    // its place, nor a scale from an Abbe term at its tool length: `ballbar_fit::alias`), so
    // a verdict on them does not either. They are the vendor table's values.
    let locals: Vec<LocalQuantity> = Design::new(model, runs)
        .ok()
        .and_then(|d| local_quantities(&d, f).ok())
        .unwrap_or_default();
    // Σ w_k q_k in the limit's unit: its value from the quantities' values (the exact field's),
    // its u from the fit's covariance of the combined functional.
    let combined =
        |parts: &[(&LocalQuantity, f64)]| -> Result<(f64, f64, Vec<(usize, f64)>), String> {
            if parts.iter().any(|(q, _)| !q.estimate.estimable) {
                return Err("not identifiable from these tests".into());
            }
            let value = parts.iter().map(|(q, w)| w * q.estimate.value).sum();
            let mut coeffs: Vec<(usize, f64)> = Vec::new();
            for (q, w) in parts {
                for &(j, c) in &q.coefficients {
                    match coeffs.iter_mut().find(|(i, _)| *i == j) {
                        Some(e) => e.1 += w * c,
                        None => coeffs.push((j, w * c)),
                    }
                }
            }
            Ok((value, f.functional(&coeffs).std_uncertainty, coeffs))
        };
    let at_place = |name: String, n: usize, q: &LocalQuantity| {
        if n > 1 { format!("{name} ({})", q.test_text()) } else { name }
    };
    if t.circular_deviation_um.is_some() || t.circular_deviation_per_plane_um.is_some() {
        let per = t.circular_deviation_per_plane_um.clone().unwrap_or_default();
        for run in runs.iter().filter(|r| r.header.plane != Plane::Free) {
            let Some(limit) = per.of(run.header.plane).or(t.circular_deviation_um) else {
                continue;
            };
            let g_um = metrics::figures(run, &run.dr_mm).g * 1e3;
            let on = format!(
                "{} ({} {})",
                run.name(),
                run.header.plane.name(),
                run.header.direction.map(|d| d.name()).unwrap_or("")
            );
            let note = String::new();
            out.push(Check {
                key: "circular_deviation_um",
                what: "circular deviation G",
                on,
                value: Some(g_um),
                u: None,
                limit,
                unit: "µm",
                verdict: judge(g_um, None, limit, t.decision),
                note,
            });
        }
        for p in Plane::PLANAR {
            if let (Some(limit), false) = (per.of(p), planes.iter().any(|(q, _)| *q == p)) {
                out.push(Check {
                    key: "circular_deviation_per_plane_um",
                    what: "circular deviation G",
                    on: format!("{} plane", p.name()),
                    value: None,
                    u: None,
                    limit,
                    unit: "µm",
                    verdict: Verdict::NotChecked,
                    note: format!("no run in the {} plane", p.name()),
                });
            }
        }
    }
    // Per tested plane, one limit after the other.
    let of_plane = |p: Plane, kind: LocalKind| -> Vec<&LocalQuantity> {
        locals.iter().filter(|q| q.plane == p && q.kind == kind).collect()
    };
    let no_test = |p: Plane| format!("no planar test of the {} plane in the fit", p.name());
    for (p, _) in planes.iter().filter(|_| t.squareness_um_per_m.is_some()) {
        let limit = t.squareness_um_per_m.expect("filtered");
        let tests = first_at_each_place(of_plane(*p, LocalKind::Squareness));
        let on = format!("{} plane", p.name());
        if tests.is_empty() {
            out.push(judged(
                "squareness_um_per_m",
                "squareness",
                on.clone(),
                Err(no_test(*p)),
                limit,
                "µm/m",
            ));
        }
        // µrad = µm/m.
        let n = tests.len();
        for q in tests {
            out.push(judged(
                "squareness_um_per_m",
                "squareness",
                at_place(on.clone(), n, q),
                combined(&[(q, 1e6)]),
                limit,
                "µm/m",
            ));
        }
    }
    // The servo mismatch per plane and feed: with the paper's plane terms the lag difference is
    // the term over the feed, another at each feed; with one lag per axis it is the same at
    // every feed, and one row says so.
    for (p, _) in planes.iter().filter(|_| t.servo_mismatch_ms.is_some()) {
        let (u, v, _) = p.axes().expect("planar");
        let m = format!("M{}", p.name());
        let mut lags = [format!("T{u}"), format!("T{v}")];
        lags.sort_unstable();
        // The plane's term of the paper's servo variant, or the lag difference of its axes.
        let is_servo = |q: &Quantity| {
            let mut i = ids(q);
            i.sort_unstable();
            q.unit == "ms" && (i == [m.as_str()] || i == [lags[0].as_str(), lags[1].as_str()])
        };
        let mut at_feeds: Vec<(f64, Option<Quantity>)> = Vec::new();
        for r in runs.iter().filter(|r| r.header.plane == *p) {
            let feed = r.header.feed_mm_per_min;
            if !at_feeds.iter().any(|(f, _)| *f == feed) {
                at_feeds.push((
                    feed,
                    rows_of(r).into_iter().find(|row| is_servo(&row.vendor)).map(|row| row.vendor),
                ));
            }
        }
        at_feeds.sort_by(|a, b| a.0.total_cmp(&b.0));
        let terms = |q: &Option<Quantity>| q.as_ref().map(|q| q.terms.clone());
        let one = at_feeds.iter().all(|(_, q)| terms(q) == terms(&at_feeds[0].1));
        let limit = t.servo_mismatch_ms.expect("filtered");
        let missing = format!("the machine's model has no servo terms of {u} and {v}");
        let feeds_text =
            |fs: &[f64]| fs.iter().map(|f| format!("{f}")).collect::<Vec<_>>().join(", ");
        if one && at_feeds.len() > 1 {
            let fs: Vec<f64> = at_feeds.iter().map(|(f, _)| *f).collect();
            let on =
                format!("{} plane (at F {} mm/min: the same at each)", p.name(), feeds_text(&fs));
            out.push(fitted(
                "servo_mismatch_ms",
                "servo mismatch (lag difference)",
                on,
                at_feeds[0].1.clone(),
                limit,
                "ms",
                &missing,
            ));
        } else {
            for (feed, q) in at_feeds {
                let on = format!("{} plane (at F {} mm/min)", p.name(), feed);
                out.push(fitted(
                    "servo_mismatch_ms",
                    "servo mismatch (lag difference)",
                    on,
                    q,
                    limit,
                    "ms",
                    &missing,
                ));
            }
        }
    }
    for (p, _) in planes.iter().filter(|_| t.scale_mismatch_ppm.is_some()) {
        let (u, v, _) = p.axes().expect("planar");
        let limit = t.scale_mismatch_ppm.expect("filtered");
        let on = format!("{} plane ({u} − {v})", p.name());
        let (us, vs) = (of_plane(*p, LocalKind::ScaleU), of_plane(*p, LocalKind::ScaleV));
        if us.is_empty() {
            out.push(judged(
                "scale_mismatch_ppm",
                "scale mismatch",
                on.clone(),
                Err(no_test(*p)),
                limit,
                "ppm",
            ));
        }
        // ppm: the local scales are ratios.
        let us = first_at_each_place(us);
        let n = us.len();
        for qu in us {
            let place = (qu.pivot_mm, qu.tool_ball_mm);
            let qv = vs.iter().find(|o| (o.pivot_mm, o.tool_ball_mm) == place);
            let estimate = match qv {
                Some(qv) => combined(&[(qu, 1e6), (qv, -1e6)]),
                None => Err(no_test(*p)),
            };
            out.push(judged(
                "scale_mismatch_ppm",
                "scale mismatch",
                at_place(on.clone(), n, qu),
                estimate,
                limit,
                "ppm",
            ));
        }
    }
    // Per axis of the tested planes.
    for a in axes.iter().filter(|_| t.backlash_um.is_some()) {
        let b = format!("B{a}");
        let q = first_rows
            .iter()
            .find(|row| ids(&row.vendor) == [b.as_str()])
            .map(|row| row.vendor.clone());
        let limit = t.backlash_um.expect("filtered");
        out.push(fitted(
            "backlash_um",
            "backlash",
            format!("axis {a}"),
            q,
            limit,
            "µm",
            &format!("the machine's model has no backlash term of {a}"),
        ));
    }
    for a in axes.iter().filter(|_| t.scale_error_ppm.is_some()) {
        let limit = t.scale_error_ppm.expect("filtered");
        // The local scale of `a` in each test of a plane holding it (at one place every such
        // test's is the same functional, J_aa there).
        let tests: Vec<&LocalQuantity> = locals
            .iter()
            .filter(|q| {
                let (u, v, _) = q.plane.axes().expect("planar");
                (q.kind == LocalKind::ScaleU && u == *a) || (q.kind == LocalKind::ScaleV && v == *a)
            })
            .collect();
        let on = format!("axis {a}");
        if tests.is_empty() {
            let why = format!("no planar test of axis {a} in the fit");
            out.push(judged("scale_error_ppm", "scale error", on.clone(), Err(why), limit, "ppm"));
        }
        let tests = first_at_each_place(tests);
        let n = tests.len();
        for q in tests {
            out.push(judged(
                "scale_error_ppm",
                "scale error",
                at_place(on.clone(), n, q),
                combined(&[(q, 1e6)]),
                limit,
                "ppm",
            ));
        }
    }
    for (key, limit, kind, what) in [
        ("reversal_spike_um", t.reversal_spike_um, "reversal_spike", "reversal spike"),
        ("lateral_play_um", t.lateral_play_um, "lateral_play", "lateral play"),
    ] {
        let Some(limit) = limit else { continue };
        for a in &axes {
            out.push(diagnosed(key, what, kind, *a, limit, diag, t.decision));
        }
    }
    // A limit that produced no row: nothing in these runs for it to apply to. Said, not dropped.
    let per = t.circular_deviation_per_plane_um.as_ref();
    let given = [
        (
            "circular_deviation_um",
            "circular deviation G",
            t.circular_deviation_um.or_else(|| per.and_then(|p| p.xy.or(p.yz).or(p.zx))),
            "µm",
            "each planar run",
        ),
        ("squareness_um_per_m", "squareness", t.squareness_um_per_m, "µm/m", "each tested plane"),
        (
            "servo_mismatch_ms",
            "servo mismatch (lag difference)",
            t.servo_mismatch_ms,
            "ms",
            "each tested plane",
        ),
        ("scale_mismatch_ppm", "scale mismatch", t.scale_mismatch_ppm, "ppm", "each tested plane"),
        ("backlash_um", "backlash", t.backlash_um, "µm", "each axis of the tested planes"),
        (
            "scale_error_ppm",
            "scale error",
            t.scale_error_ppm,
            "ppm",
            "each axis of the tested planes",
        ),
        (
            "reversal_spike_um",
            "reversal spike",
            t.reversal_spike_um,
            "µm",
            "each axis of the tested planes",
        ),
        (
            "lateral_play_um",
            "lateral play",
            t.lateral_play_um,
            "µm",
            "each axis of the tested planes",
        ),
    ];
    for (key, what, limit, unit, applies) in given {
        let Some(limit) = limit else { continue };
        let keys: &[&str] = if key == "circular_deviation_um" {
            &["circular_deviation_um", "circular_deviation_per_plane_um"]
        } else {
            &[key]
        };
        if !out.iter().any(|c| keys.contains(&c.key)) {
            let note = format!(
                "no planar run (the limit applies to {applies}); these {} runs test no plane (rotary or free runs only)",
                runs.len()
            );
            out.push(Check {
                key,
                what,
                on: "the session".into(),
                value: None,
                u: None,
                limit,
                unit,
                verdict: Verdict::NotChecked,
                note,
            });
        }
    }
    out
}

/// χ²(6) at the 1e-6 level (Q(3, x/2) = 1e-6): the diagnosis's F gate (`ballbar-diagnose`,
/// an effect accepted only when its F statistic passes χ²(k) at 1e-6 over k) for the most
/// columns a spike or a play adds, k = 6 (a reversal transient per side: three parts a side;
/// a play adds one). χ²(k) grows with k, so the gate of k = 6 bounds those of fewer columns.
pub const CHI2_6_AT_1E6: f64 = 38.26;

/// The largest spike or play (µm) the diagnosis could have left unnamed when its F gate
/// declined it, from the residual σ its gate divides by (µm RMS a sample: the residual of the
/// model with the accepted effects, never below the noise floor) and the noise's inflation κ
/// (the factor on σ² in its F statistics): D = σ·√(χ²₆(1e-6)·κ).
///
/// Why: the gate accepts a candidate of k columns only when its gain (the drop in the residual
/// sum of squares) reaches χ²ₖ(1e-6)·σ²κ, σ² the residual variance of the fit with it. An effect of size h shows at its full size in at
/// least one sample (a spike of height h at its peak; a play of L moves every sample by L/2,
/// and four samples give L²), so it gains at least h²: a gain below the gate means
/// h < σ·√(χ²ₖ·κ) ≤ D. The bound is conservative (a spike spans several samples at each of
/// several reversals, a play the whole run), and it holds only where the F gate is what
/// declined the candidate: one that passed it and was declined on held-out evidence, taken up
/// by other effects, or aliased with the base model has no size bound.
pub fn detection_bound_um(noise_floor_um: f64, inflation: f64) -> f64 {
    noise_floor_um * (CHI2_6_AT_1E6 * inflation.max(1.0)).sqrt()
}

/// A limit on an effect the diagnosis names (a reversal spike, a lateral play) of axis `a`.
/// Where it names none, the check passes only when the limit is above [`detection_bound_um`]
/// and the F gate is what declined the candidates of the kind on the axis (the diagnosis lists
/// them declined by the F test): UNDECIDED otherwise (one the diagnosis does not list was not
/// shortlisted, so never met the gate: its size is not bounded).
fn diagnosed(
    key: &'static str,
    what: &'static str,
    kind: &str,
    a: Axis,
    limit: f64,
    diag: Option<&Diagnosis>,
    decision: Decision,
) -> Check {
    let on = format!("axis {a}");
    let mut c = Check {
        key,
        what,
        on,
        value: None,
        u: None,
        limit,
        unit: "µm",
        verdict: Verdict::NotChecked,
        note: String::new(),
    };
    let Some(d) = diag else {
        c.note = "needs the diagnosis: report an archive of `ballbar diagnose --record`, or the run files".into();
        return c;
    };
    let Some(effects) = &d.effects else {
        c.note =
            "the archived diagnosis lists no effects (no `effects`): nothing to judge by".into();
        return c;
    };
    let of_axis = |s: &Subject| s.is(kind, a.name());
    let mut best: Option<(f64, Option<f64>, String)> = None;
    for e in effects.iter().filter(|e| of_axis(&e.subject)) {
        // The parameters that hold the effect's size: a spike's height per side where it has
        // two, else its one height; a play's size.
        let keys: &[&str] = match kind {
            "reversal_spike" if e.parameters.contains_key("amplitude_pos_um") => {
                &["amplitude_pos_um", "amplitude_neg_um"]
            }
            "reversal_spike" => &["amplitude_um"],
            _ => &["play_um"],
        };
        for k in keys {
            let v = e.parameters.get(*k).copied().unwrap_or(f64::NAN);
            if v.is_finite() && best.as_ref().is_none_or(|b| v.abs() > b.0.abs()) {
                let u = e.std_uncertainties.get(*k).copied();
                let name = if e.description.is_empty() { kind } else { &e.description };
                best = Some((v, u, format!("{name} ({k})")));
            }
        }
    }
    if let Some((v, u, from)) = best {
        c.value = Some(v);
        c.u = u;
        c.verdict = judge(v, u, limit, decision);
        c.note = if u.is_some() {
            format!("the diagnosis's {from}")
        } else {
            format!("the diagnosis's {from}; no uncertainty: compared as it is")
        };
        return c;
    }
    // Named by no effect: how large could it be?
    c.verdict = Verdict::Undecided;
    let (Some(floor), inflation) = (
        Some(d.gap.noise_floor_um).filter(|s| s.is_finite() && *s > 0.0),
        d.gap.noise_inflation.filter(|k| k.is_finite()).unwrap_or(1.0),
    ) else {
        c.note = "none named by the diagnosis, which gives no noise floor: how large an unnamed one could be is not known".into();
        return c;
    };
    // The gate divides by the residual of the fit with the accepted effects, which is above the
    // noise floor wherever something is left unexplained: the largest run's RMS after the
    // effects bounds it from above (the session's RMS is a mean of the runs').
    let after =
        d.runs.iter().map(|r| r.rms_after_um).filter(|x| x.is_finite()).fold(f64::NAN, f64::max);
    let sigma = if after.is_finite() { floor.max(after) } else { floor };
    let bound = detection_bound_um(sigma, inflation);
    let bound_text = format!(
        "the diagnosis's detection bound {bound:.2} µm (residual σ {sigma:.3} µm after the effects, noise floor {floor:.3} µm, noise inflation {inflation:.1})"
    );
    let aliased = d.aliased.iter().any(|e| of_axis(&e.subject));
    let not_by_f: Vec<String> = d
        .declined
        .iter()
        .filter(|e| of_axis(&e.subject) && !matches!(e.why, Why::F { .. }))
        .map(|e| e.why.test().to_string())
        .collect();
    let listed = d.declined.iter().any(|e| of_axis(&e.subject));
    if aliased {
        c.note = format!(
            "none named, but the diagnosis finds it aliased with the base model: its size is not bounded ({bound_text} does not apply)"
        );
    } else if !not_by_f.is_empty() {
        c.note = format!(
            "none named, but a candidate passed the F gate and was declined by the {} test: its size is not bounded",
            not_by_f.join(", ")
        );
    } else if !listed {
        c.note = "none named, and no candidate of it met the diagnosis's F gate (it was not among the shortlisted candidates): its size is not bounded".into();
    } else if limit > bound {
        c.verdict = Verdict::Pass;
        c.note = format!("none named: any is below {bound_text}, under the limit");
    } else {
        c.note = format!(
            "none named, but one up to {bound_text} could go unnamed: the limit is not above it"
        );
    }
    c
}

/// The section: the overall verdict, the rule, one row per check.
pub fn section(h: &mut String, file: &ToleranceFile, checks: &[Check], diag: Option<&Diagnosis>) {
    let noise = diag.map(|d| d.gap.noise_floor_um).filter(|x| !x.is_nan());
    let (class, word, why) = summary(checks);
    let _ = write!(
        h,
        r#"<section id="tolerance"><h2>Acceptance: {word}</h2><p class="verdict {class}" data-verdict="{word}">Overall: <b>{word}</b> — {}.</p><p>Limits from {}; each bounds the magnitude of the value. Decision rule: {}. G: ISO 230-4 circular deviation of each run's readings about their least-squares circle, measured (no uncertainty). Squareness and scales (error and mismatch): what each planar test determines at its circle's centre, the vendor table's local values (they do not move with the pivot or tool length given for the runs, where the machine's global terms in the parameters' table may); servo mismatch (per plane and feed), backlash: the fit's values in the vendor's units (the parameters' table); a value that holds only for a choice these tests leave open is NOT CHECKED, unless the choice is a calibration the runs state (then judged, "assuming" it). Reversal spikes, lateral play: the diagnosis's named effects; where it names none, PASS only when the limit is above the largest it could have missed, D = σ·√(χ²₆(1e-6)·κ){}, and its F gate declined the candidate; UNDECIDED otherwise; NOT CHECKED without a diagnosis. A limit that nothing in these runs can check is NOT CHECKED; the overall verdict is PASS only when every check passes.</p>"#,
        esc(&why),
        esc(&file.name),
        esc(&file.limits.decision.describe()),
        noise.map(|n| format!(" (noise floor σ {n:.3} µm RMS)")).unwrap_or_default()
    );
    h.push_str(r#"<table id="tolerance-checks"><tr><th>check</th><th>on</th><th>value</th><th>U (k = 2)</th><th>limit</th><th>unit</th><th>result</th><th>from</th></tr>"#);
    for c in checks {
        let decimals = if c.unit == "ms" { 3 } else { 2 };
        let value =
            c.value.map_or_else(|| "<td class=\"num\">—</td>".to_string(), |v| td(v, decimals));
        let big_u =
            c.u.map_or_else(|| "<td></td>".to_string(), |u| td(COVERAGE_FACTOR * u, decimals));
        let _ = write!(
            h,
            r#"<tr data-check="{}" data-on="{}" data-verdict="{}"><td>{}</td><td>{}</td>{value}{big_u}{}<td>{}</td><td class="verdict {}">{}</td><td class="note">{}</td></tr>"#,
            c.key,
            esc(&c.on),
            c.verdict.name(),
            esc(c.what),
            esc(&c.on),
            td(c.limit, decimals),
            esc(c.unit),
            c.verdict.name().to_lowercase().replace(' ', "-"),
            c.verdict.name(),
            esc(&c.note)
        );
        // The verdict in shop-floor words, under its row (the terminal prints the same line).
        let _ = write!(
            h,
            r#"<tr class="advice" data-advice-for="{}" data-advice-on="{}"><td colspan="8">{}</td></tr>"#,
            c.key,
            esc(&c.on),
            esc(&c.advice())
        );
    }
    h.push_str("</table></section>");
}

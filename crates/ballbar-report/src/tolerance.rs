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
//! The fitted values are those of the page's tables (the paper's quantities in the vendor's
//! units). Every limit bounds the magnitude: |value| ≤ limit.
//!
//! # Decision rule
//! By default ISO 14253-1's: with the expanded uncertainty U = k·u, k = 2 ([`COVERAGE_FACTOR`]),
//! a value passes when |value| + U ≤ limit (conformance proven), fails when |value| − U > limit
//! (non-conformance proven), and is undecided in between. `decision: Simple` compares
//! |value| ≤ limit and shows U without using it. A figure without an uncertainty (G, measured
//! directly; an effect the diagnosis gives no uncertainty for) is compared plainly, and the page
//! says so. u is the fit's standard uncertainty: it does not include the ballbar's calibration
//! uncertainty. The overall verdict is FAIL when a check fails, PASS when every check passes,
//! and NOT PROVEN otherwise (a check undecided, or a limit these runs cannot check).

use std::fmt::Write;
use std::path::Path;

use ballbar_fit::{metrics, quantity, Fit};
use ballbar_model::machine::Model;
use ballbar_model::paper::{self, Quantity};
use ballbar_model::{Axis, Plane, Run};
use serde::Deserialize;
use serde_json::Value;

use crate::page::{td, ReportError};
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
    let text = std::fs::read_to_string(path).map_err(|error| ReportError::File(ballbar_io::IoError::Io { path: path.to_path_buf(), error }))?;
    parse(&text, path)
}

/// Parse the text of a tolerance file; `path` names it in messages.
pub fn parse(text: &str, path: &Path) -> Result<ToleranceFile, ReportError> {
    let limits: Tolerances = ballbar_io::ron_files::parse_ron(text, path).map_err(ReportError::File)?;
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
            return Err(ReportError::Tolerance { path: path.display().to_string(), line: line_of(text, key), message: format!("{key}: a limit is a positive number, not {v}") });
        }
    }
    if all.iter().all(|(_, v)| v.is_none()) {
        return Err(ReportError::Tolerance { path: path.display().to_string(), line: 1, message: "the file gives no limit (docs/report.md lists them)".into() });
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
                !before.is_some_and(|c| c.is_alphanumeric() || c == '_') && l[i + key.len()..].trim_start().starts_with(':')
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

/// The overall verdict of `checks`.
pub fn overall(checks: &[Check]) -> Verdict {
    if checks.iter().any(|c| c.verdict == Verdict::Fail) {
        Verdict::Fail
    } else if checks.iter().all(|c| c.verdict == Verdict::Pass) {
        Verdict::Pass
    } else {
        Verdict::Undecided
    }
}

/// The planes the session tests (planar runs), in order, with the first run of each.
fn tested_planes(runs: &[Run]) -> Vec<(Plane, &Run)> {
    Plane::PLANAR.into_iter().filter_map(|p| runs.iter().find(|r| r.header.plane == p).map(|r| (p, r))).collect()
}

fn ids(q: &Quantity) -> Vec<&str> {
    q.terms.iter().map(|(id, _)| id.as_str()).collect()
}

/// Check every limit of `t` on the session: `model` and `f` the page's fit of `runs`, `diag`
/// the archived diagnosis JSON.
pub fn evaluate(t: &Tolerances, model: &Model, f: &Fit, runs: &[Run], diag: Option<&Value>) -> Vec<Check> {
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
    let mut out = Vec::new();
    // A fitted quantity against a limit.
    let fitted = |key: &'static str, what: &'static str, on: String, q: Option<Quantity>, limit: f64, unit: &'static str, missing: &str| -> Check {
        let Some(q) = q else {
            return Check { key, what, on, value: None, u: None, limit, unit, verdict: Verdict::NotChecked, note: missing.to_string() };
        };
        match quantity(f, &q).map(|e| e.estimate) {
            Some(e) if e.estimable => {
                let coeffs: Vec<(usize, f64)> = q.terms.iter().filter_map(|(id, c)| f.index(id).map(|i| (i, *c))).collect();
                let note = if f.depends_on(&coeffs).is_empty() { String::new() } else { "holds for a choice these tests leave open (summary: fixed by the tests' limits)".to_string() };
                Check { key, what, on, value: Some(e.value), u: Some(e.std_uncertainty), limit, unit, verdict: judge(e.value, Some(e.std_uncertainty), limit, t.decision), note }
            }
            _ => Check { key, what, on, value: None, u: None, limit, unit, verdict: Verdict::NotChecked, note: "not identifiable from these tests".into() },
        }
    };
    if t.circular_deviation_um.is_some() || t.circular_deviation_per_plane_um.is_some() {
        let per = t.circular_deviation_per_plane_um.clone().unwrap_or_default();
        for run in runs.iter().filter(|r| r.header.plane != Plane::Free) {
            let Some(limit) = per.of(run.header.plane).or(t.circular_deviation_um) else { continue };
            let g_um = metrics::figures(run, &run.dr_mm).g * 1e3;
            let on = format!("{} ({} {})", run.name(), run.header.plane.name(), run.header.direction.map(|d| d.name()).unwrap_or(""));
            let note = String::new();
            out.push(Check { key: "circular_deviation_um", what: "circular deviation G", on, value: Some(g_um), u: None, limit, unit: "µm", verdict: judge(g_um, None, limit, t.decision), note });
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
    for (p, r) in planes.iter().filter(|_| t.squareness_um_per_m.is_some()) {
        let sq = format!("SQ{}", p.name());
        let q = rows_of(r).into_iter().find(|row| ids(&row.vendor) == [sq.as_str()]).map(|row| row.vendor);
        let limit = t.squareness_um_per_m.expect("filtered");
        out.push(fitted("squareness_um_per_m", "squareness", format!("{} plane", p.name()), q, limit, "µm/m", &format!("the machine's model has no squareness {} term", p.name())));
    }
    for (p, r) in planes.iter().filter(|_| t.servo_mismatch_ms.is_some()) {
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
        let q = rows_of(r).into_iter().find(|row| is_servo(&row.vendor)).map(|row| row.vendor);
        let on = format!("{} plane (at F {} mm/min)", p.name(), r.header.feed_mm_per_min);
        let limit = t.servo_mismatch_ms.expect("filtered");
        out.push(fitted("servo_mismatch_ms", "servo mismatch (lag difference)", on, q, limit, "ms", &format!("the machine's model has no servo terms of {u} and {v}")));
    }
    for (p, r) in planes.iter().filter(|_| t.scale_mismatch_ppm.is_some()) {
        let (u, v, _) = p.axes().expect("planar");
        let rows = rows_of(r);
        let scale = |a: Axis| rows.iter().find(|row| row.vendor.unit == "ppm" && ids(&row.vendor) == [format!("E{a}{a}1").as_str()]).map(|row| row.vendor.terms.clone());
        let q = match (scale(u), scale(v)) {
            (Some(su), Some(sv)) => {
                let terms = su.into_iter().chain(sv.into_iter().map(|(id, c)| (id, -c))).collect();
                Some(Quantity { name: format!("scale mismatch {}", p.name()), unit: "ppm", terms })
            }
            _ => None,
        };
        let limit = t.scale_mismatch_ppm.expect("filtered");
        out.push(fitted("scale_mismatch_ppm", "scale mismatch", format!("{} plane ({u} − {v})", p.name()), q, limit, "ppm", &format!("the machine's model has no positional terms of {u} and {v}")));
    }
    // Per axis of the tested planes.
    for a in axes.iter().filter(|_| t.backlash_um.is_some()) {
        let b = format!("B{a}");
        let q = first_rows.iter().find(|row| ids(&row.vendor) == [b.as_str()]).map(|row| row.vendor.clone());
        let limit = t.backlash_um.expect("filtered");
        out.push(fitted("backlash_um", "backlash", format!("axis {a}"), q, limit, "µm", &format!("the machine's model has no backlash term of {a}")));
    }
    for a in axes.iter().filter(|_| t.scale_error_ppm.is_some()) {
        let e = format!("E{a}{a}1");
        let q = first_rows.iter().find(|row| row.vendor.unit == "ppm" && ids(&row.vendor) == [e.as_str()]).map(|row| row.vendor.clone());
        let limit = t.scale_error_ppm.expect("filtered");
        out.push(fitted("scale_error_ppm", "scale error", format!("axis {a}"), q, limit, "ppm", &format!("the machine's model has no positional term of {a}")));
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
    out
}

/// A limit on an effect the diagnosis names (a reversal spike, a lateral play) of axis `a`.
fn diagnosed(key: &'static str, what: &'static str, kind: &str, a: Axis, limit: f64, diag: Option<&Value>, decision: Decision) -> Check {
    let on = format!("axis {a}");
    let mut c = Check { key, what, on, value: None, u: None, limit, unit: "µm", verdict: Verdict::NotChecked, note: String::new() };
    let Some(d) = diag else {
        c.note = "needs the diagnosis: report an archive of `ballbar diagnose --record`, or the run files".into();
        return c;
    };
    let mut best: Option<(f64, Option<f64>, String)> = None;
    for e in d["effects"].as_array().into_iter().flatten().filter(|e| e["kind"] == kind && e["axis"] == a.name()) {
        // The parameters that hold the effect's size: a spike's height per side where it has
        // two, else its one height; a play's size.
        let keys: &[&str] = match kind {
            "reversal_spike" if e["parameters"]["amplitude_pos_um"].is_number() => &["amplitude_pos_um", "amplitude_neg_um"],
            "reversal_spike" => &["amplitude_um"],
            _ => &["play_um"],
        };
        for k in keys {
            let v = e["parameters"][*k].as_f64().unwrap_or(f64::NAN);
            if v.is_finite() && best.as_ref().is_none_or(|b| v.abs() > b.0.abs()) {
                let u = e["std_uncertainties"][*k].as_f64();
                best = Some((v, u, format!("{} ({k})", e["description"].as_str().unwrap_or(kind))));
            }
        }
    }
    match best {
        Some((v, u, from)) => {
            c.value = Some(v);
            c.u = u;
            c.verdict = judge(v, u, limit, decision);
            c.note = if u.is_some() { format!("the diagnosis's {from}") } else { format!("the diagnosis's {from}; no uncertainty: compared as it is") };
        }
        None => {
            // Named by no effect: none stands out of the noise.
            c.verdict = Verdict::Pass;
            c.note = "none named by the diagnosis: taken as passing".to_string();
        }
    }
    c
}

/// The section: the overall verdict, the rule, one row per check.
pub fn section(h: &mut String, file: &ToleranceFile, checks: &[Check], diag: Option<&Value>) {
    let noise = diag.and_then(|d| d["gap"]["noise_floor_um"].as_f64());
    let all = overall(checks);
    let n_fail = checks.iter().filter(|c| c.verdict == Verdict::Fail).count();
    let n_undecided = checks.iter().filter(|c| c.verdict == Verdict::Undecided).count();
    let n_unchecked = checks.iter().filter(|c| c.verdict == Verdict::NotChecked).count();
    let (class, word, why) = match all {
        Verdict::Fail => ("fail", "FAIL", format!("{n_fail} of {} checks fail", checks.len())),
        Verdict::Pass => ("pass", "PASS", format!("all {} checks pass", checks.len())),
        _ => {
            let mut parts = Vec::new();
            if n_undecided > 0 {
                parts.push(format!("{n_undecided} within the uncertainty of the limit"));
            }
            if n_unchecked > 0 {
                parts.push(format!("{n_unchecked} that these runs cannot check"));
            }
            ("undecided", "NOT PROVEN", format!("no check fails, but of {} checks: {}", checks.len(), parts.join(", ")))
        }
    };
    let _ = write!(
        h,
        r#"<section id="tolerance"><h2>Acceptance: {word}</h2><p class="verdict {class}" data-verdict="{word}">Overall: <b>{word}</b> — {}.</p><p>Limits from {}; each bounds the magnitude of the value. Decision rule: {}. G: ISO 230-4 circular deviation of each run's readings about their least-squares circle, measured (no uncertainty). Squareness, servo mismatch, scale, backlash: the fit's values in the vendor's units (the parameters' table). Reversal spikes, lateral play: the diagnosis's named effects; where it names none, none stands out of the noise{}, taken as passing.</p>"#,
        esc(&why),
        esc(&file.name),
        esc(&file.limits.decision.describe()),
        noise.map(|n| format!(" (floor {n:.3} µm RMS)")).unwrap_or_default()
    );
    h.push_str(r#"<table id="tolerance-checks"><tr><th>check</th><th>on</th><th>value</th><th>U (k = 2)</th><th>limit</th><th>unit</th><th>result</th><th>from</th></tr>"#);
    for c in checks {
        let decimals = if c.unit == "ms" { 3 } else { 2 };
        let value = c.value.map_or_else(|| "<td class=\"num\">—</td>".to_string(), |v| td(v, decimals));
        let big_u = c.u.map_or_else(|| "<td></td>".to_string(), |u| td(COVERAGE_FACTOR * u, decimals));
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
    }
    h.push_str("</table></section>");
}

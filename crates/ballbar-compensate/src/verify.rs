//! `ballbar verify`: each term of `compensation.json` before, predicted after and measured after
//! the tests were repeated with the files active, and its verdict (`../shared/spec/compensate.md`).
//!
//! With `b` the value before, `p` the predicted value after, `a` the measured one, `c = p - b`
//! the correction the files apply and `m = a - b` the move measured, and `tol = 3 u` with
//! `u = √(u_b² + u_a²)` (two independent fits; the prediction carries the before's
//! uncertainty, the files' rounding being far below it):
//! - a compensated term is `corrected` when `|a - p| ≤ max(tol, resolution)` (the controller's
//!   resolution of the written values, in the term's unit) and the move is resolved the
//!   correction's way, `|m| > tol` and `m c > 0`; `not_resolved` when it is within both,
//!   `|a - p| ≤ max(tol, resolution)` and `|m| ≤ tol`: the repeat agrees with the prediction and
//!   with the value before alike, so it cannot tell the files applied from not loaded. (A move
//!   resolved and within `tol` of `p` also rules out the wrong sign, `a ≈ b - c`: with `c > 0`,
//!   `a - p ≥ -tol` and `a - b > tol` give `a - (b - c) > tol + c`; where a coarse resolution
//!   widens the band past `tol` (FANUC's 1 µm), the wrong sign is ruled out by the move's
//!   direction, `m c > 0`. The two bands are apart, and a repeat can only read `corrected` or
//!   `unchanged` for a correction applied or not loaded, when `|c| > tol + max(tol,
//!   resolution)`, `6u` at a fine resolution: [`RESOLVED_IN_U`]; `compensate` flags a term it
//!   writes below `6u` for a repeat as good as the tests, [`crate::VERIFIABLE_IN_U`].) Where the
//!   files leave the term (`c` zero to rounding) there is nothing to load, and within the band
//!   it is `corrected`. A move resolved the wrong way inside a wide band is judged as one
//!   outside it. Else `unchanged` when `|m| ≤
//!   tol` (the file was not loaded, or was not active); else `changed` when `|c| ≤ 3 u_b` (the files
//!   were to leave it, and it moved: `c` is computed from the files and the value before, so it
//!   is as uncertain as that value); else, with `r = m/c` the share of the correction
//!   measured:
//!   - `reversed` when `r` is within 0.5 of -1: moved away by about twice its size (the
//!     correction applied with the wrong sign);
//!   - `scaled` when `log10 r` is within 0.15 of a non-zero integer k ≤ 3 in size, or of `±log10
//!     25.4` (a unit mistake: ×10^k, or a file in mm read by a controller set to inches, the
//!     factor given; 0.15 in the logarithm is ±41 %, which keeps 10× apart from 1×, from 25.4×
//!     and from a share of a half);
//!     A correction within `tol` (resolved by the value before, not by the refit: a refit
//!     whose u a table's coarse steps inflate, say) is `scaled` only when the move resolves
//!     the factor by itself, `3u/|m| ≤ 0.41` (the band of `log10 r`), and `changed` otherwise,
//!     as are the verdicts below, which need the correction resolved against `tol`;
//!   - `partly` when `0 < r < 1`: moved towards the prediction, not all the way (the share);
//!   - `overshot` when `r ≥ 1`: moved past the prediction (the share);
//!   - `moved_away` when `r < 0` otherwise: away from the prediction, but not as a wrong sign
//!     would move it (the share, negative);
//! - a term not compensated is `not_compensated` when `|a - p| ≤ tol`, `changed` otherwise.
//!   Its `p` is `b` plus what the files' trims move it by through the fit (a table's steps,
//!   an existing table replaced: `compensation.json`'s `predicted_after`), else `b`; the
//!   resolution does not widen it (that move is computed from the trims as written).
//!
//! A term that the repeated tests do not determine (not estimable in their refit: an axis they do
//! not move, a plane they do not test, a direction a gauge's choice fixes), or that the tests
//! before did not (not estimable in the saved model), is `not_measured` (an extension of the
//! contract's list), whatever the refit's number says: that number is a gauge's choice, not a
//! measurement, so it can be neither `corrected` nor `changed`. A compensated term
//! `not_measured` was not verified (exit 3), and the advice names the tests that measure it
//! ([`tests_that_measure`]); one not compensated does not change the exit code.
//!
//! A correction a thousand times too small moves a term by less than its uncertainty, and reads
//! as `unchanged`: no measurement tells it from a file not loaded.
//!
//! A `not_resolved` term says how many sessions of the repeated tests, fitted together, would
//! resolve its correction ([`sessions_to_resolve`]), or that none would (the value before is
//! itself too uncertain, or the correction is within the controller's resolution): then only
//! reading the value back from the controller shows it. A refit whose uncertainty is not finite
//! shows nothing: a compensated term is then `not_resolved`.

use serde::{Deserialize, Serialize};

/// Format tag of the verification.
pub const VERIFICATION_FORMAT: &str = "ballbar-verification/1";

/// How many comparison uncertainties `u` a correction must exceed for a repeat to resolve it:
/// the band of `corrected` (`|a - p| ≤ 3u`) and that of a file not loaded (`|a - b| ≤ 3u`) are
/// apart when `|c| > 3u + 3u` (module docs). From 6u on a correction applied reads `corrected`
/// but for the 0.27 % of a refit outside the prediction's own 3u band (at 6u that band's near
/// edge is where the move reaches 3u).
pub const RESOLVED_IN_U: f64 = 6.0;

/// How many sessions of the repeated tests, fitted together, resolve a correction `c` against
/// the value before's `u_b`, one session's refit `u_a` (same unit) and the controller's
/// resolution `res` of the written values, the refit's uncertainty falling as `1/√n`
/// (independent sessions): the least `n ≥ 1` whose `u_n = √(u_b² + u_a²/n)` keeps the bands of
/// `corrected` (`|a − p| ≤ max(3u_n, res)`) and of a file not loaded (`|a − b| ≤ 3u_n`) apart,
/// `|c| > 3u_n + max(3u_n, res)`: `u_n < min(|c|/6, (|c| − res)/3)` ([`RESOLVED_IN_U`]),
/// `n ≥ u_a² / (min(…)² − u_b²)`. `None` where no number does: the value before itself too
/// uncertain, a correction within the controller's resolution (only reading the value back
/// shows it), or an uncertainty that is not finite.
pub fn sessions_to_resolve(c: f64, u_before: f64, u_after: f64, resolution: f64) -> Option<u32> {
    if within_resolution(c, resolution) {
        return None;
    }
    let bound = (c.abs() / RESOLVED_IN_U).min((c.abs() - resolution.max(0.0)) / 3.0);
    let room = if bound > 0.0 { bound * bound - u_before.powi(2) } else { f64::NAN };
    if !(room > 0.0 && u_after.is_finite()) {
        return None;
    }
    let n = (u_after.powi(2) / room).ceil().max(1.0);
    (n <= f64::from(u32::MAX)).then_some(n as u32)
}

/// The verdict of a term the repeated tests, or the tests before, do not determine (module
/// docs).
pub const NOT_MEASURED: &str = "not_measured";

/// The tests that measure a term of `compensation.json` (`term`, `axis`, `id` as there), in
/// words: a circle in a plane that moves the axis, for an axis's own term (backlash, scale,
/// positional, servo lag, reversal spike); a circle in the plane of the two axes, for a
/// squareness, a plane's servo mismatch and a straightness (`E<d><a><k>`: the error along `d`
/// as `a` moves); a rotary test of the axis, for a rotary location. The tests before
/// compensation (`predicted`, where their planes are known) determined it: those of them in
/// such a plane that are not among the `repeated` runs are named (a circle of such a plane can
/// still leave it undetermined, through an alias that another plane's circle separates: the
/// scale of X from the straightness of X in Z, on XY circles alone).
pub fn tests_that_measure(
    term: &str,
    axis: &str,
    id: &str,
    predicted: &[crate::Predicted],
    repeated: &[String],
) -> String {
    const PLANES: [&str; 3] = ["XY", "YZ", "ZX"];
    let plane_of =
        |a: char, b: char| PLANES.into_iter().find(|p| p.contains(a) && p.contains(b) && a != b);
    let two = |mut c: std::str::Chars<'_>| match (c.next(), c.next()) {
        (Some(a), Some(b)) => plane_of(a, b).into_iter().collect(),
        _ => Vec::new(),
    };
    let planes: Vec<&str> = match term {
        "rotary_location" => {
            return format!("rotary tests of {axis} (axial, radial or tangential)");
        }
        // `E<d><a><k>`: the error along d as a moves.
        "straightness" => two(id.get(1..).unwrap_or("").chars()),
        _ if axis.len() == 2 => two(axis.chars()),
        _ => PLANES.into_iter().filter(|p| p.contains(axis)).collect(),
    };
    if planes.is_empty() {
        return "the tests the model was fitted to".into();
    }
    let circles = format!("circles in the {} plane", planes.join(" or "));
    let missing: Vec<&str> = predicted
        .iter()
        .filter(|p| {
            p.plane.as_deref().is_some_and(|pl| planes.contains(&pl)) && !repeated.contains(&p.run)
        })
        .map(|p| p.run.as_str())
        .collect();
    if missing.is_empty() {
        circles
    } else {
        format!(
            "{circles}: of the tests before compensation, which determined it, {} not repeated",
            if missing.len() == 1 {
                format!("{} was", missing[0])
            } else {
                format!("{} were", missing.join(", "))
            }
        )
    }
}

/// What the repeated runs (`repeated`: each run's id and plane, `None` for a test that is no
/// planar circle) leave out of, or add to, the runs `compensation.json` predicted (`predicted`),
/// in words; `None` where they are the same runs (by id, and by plane where `compensation.json`
/// gives it). Runs of another session or machine, or only part of the tests, make the terms
/// they do not determine `not_measured` and the rest a comparison of other tests.
pub fn runs_mismatch(
    predicted: &[crate::Predicted],
    repeated: &[(String, Option<String>)],
) -> Option<String> {
    if predicted.is_empty() {
        return None;
    }
    let mut said = Vec::new();
    let missing: Vec<&str> = predicted
        .iter()
        .filter(|p| !repeated.iter().any(|(r, _)| *r == p.run))
        .map(|p| p.run.as_str())
        .collect();
    if !missing.is_empty() {
        said.push(format!("not repeated: {}", missing.join(", ")));
    }
    let extra: Vec<&str> = repeated
        .iter()
        .filter(|(r, plane)| plane.is_some() && !predicted.iter().any(|p| p.run == *r))
        .map(|(r, _)| r.as_str())
        .collect();
    if !extra.is_empty() {
        said.push(format!("not among them: {}", extra.join(", ")));
    }
    let moved: Vec<String> = predicted
        .iter()
        .filter_map(|p| {
            let was = p.plane.as_deref()?;
            let (_, now) = repeated.iter().find(|(r, _)| *r == p.run)?;
            let now = now.as_deref().unwrap_or("not a planar circle");
            (now != was).then(|| format!("{} is {now}, was {was}", p.run))
        })
        .collect();
    if !moved.is_empty() {
        said.push(format!("another plane: {}", moved.join(", ")));
    }
    (!said.is_empty()).then(|| {
        let names: Vec<&str> = predicted.iter().map(|p| p.run.as_str()).collect();
        format!(
            "the repeated runs are not the runs compensation.json predicted ({}): {}; runs of another machine or session compare other tests, and a term only the runs not repeated measure is not_measured",
            names.join(", "),
            said.join("; ")
        )
    })
}

/// The repeated runs whose header names a machine other than the model's (`machine`, the
/// saved model's machine name; `runs`: each run's id and its header's machine, where given),
/// in words; `None` where every run that names one names the model's.
pub fn machine_mismatch(machine: &str, runs: &[(String, Option<String>)]) -> Option<String> {
    let other: Vec<String> = runs
        .iter()
        .filter_map(|(r, m)| m.as_deref().filter(|m| *m != machine).map(|m| format!("{r} ({m})")))
        .collect();
    (!other.is_empty()).then(|| {
        format!(
            "the repeated runs name another machine than the model's, {machine}: {}; a verification compares the same machine's tests",
            other.join(", ")
        )
    })
}

/// Whether a correction `c` is not above the controller's `resolution` (same unit): a
/// correction of one detection unit, computed from the written table's mean, exceeds it by a
/// rounding (1.0000000000000007 µm for FANUC's 1 µm), which must not count as resolvable; a
/// relative 1e-9 is far above that rounding and far below any bar's uncertainty.
pub fn within_resolution(c: f64, resolution: f64) -> bool {
    c.abs() <= resolution.max(0.0) * (1.0 + 1e-9)
}

/// One term's comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TermCheck {
    /// As in `compensation.json`.
    pub term: String,
    /// As in `compensation.json`.
    pub axis: String,
    /// The model's parameter.
    pub id: String,
    /// Value before (the model's).
    pub before: f64,
    /// Value predicted after.
    pub predicted_after: f64,
    /// Value measured after.
    pub after: f64,
    /// Standard uncertainty of the comparison, `√(u_b² + u_a²)`.
    pub u: f64,
    /// Display unit.
    pub unit: String,
    /// Whether the files act on it.
    pub compensated: bool,
    /// The verdict.
    pub verdict: String,
    /// For `partly`, `overshot`, `moved_away` and `reversed`: the share of the correction
    /// measured (`m/c`, module docs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub share: Option<f64>,
    /// For `scaled`: the power of ten the correction was applied with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub factor: Option<f64>,
    /// For `not_resolved`: how many sessions of the repeated tests, fitted together, would
    /// resolve the correction ([`sessions_to_resolve`]); absent where none would.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sessions: Option<u32>,
    /// As in `compensation.json` (an extension): `false` where `compensate` flagged the term
    /// at write time as one a repeat of the tests could not verify; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub verifiable_by_repeat: Option<bool>,
    /// For `not_measured` (an extension): the tests that measure the term
    /// ([`tests_that_measure`]). Its `after` and the `u` are then the refit's, a gauge's choice
    /// and not a measurement (or, where the tests before did not determine it, compared with a
    /// gauge's choice).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measured_by: Option<String>,
}

/// One run's circular deviation G, µm.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunCheck {
    /// The run's id.
    pub run: String,
    /// G before.
    #[serde(rename = "G_before_um")]
    pub g_before_um: f64,
    /// G predicted.
    #[serde(rename = "G_predicted_um")]
    pub g_predicted_um: f64,
    /// G measured after.
    #[serde(rename = "G_after_um")]
    pub g_after_um: f64,
}

/// `ballbar-verification/1`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Verification {
    /// [`VERIFICATION_FORMAT`].
    pub format: String,
    /// Per term.
    pub terms: Vec<TermCheck>,
    /// Per run found in both.
    pub runs: Vec<RunCheck>,
    /// What the reader should know (an extension): the repeated runs not the ones predicted
    /// ([`runs_mismatch`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl Verification {
    /// True when every compensated term is `corrected` and no term `changed` (exit 0): a
    /// compensated term `not_measured` fails it (it was not verified), one not compensated does
    /// not.
    pub fn passed(&self) -> bool {
        self.terms
            .iter()
            .all(|t| (!t.compensated || t.verdict == "corrected") && t.verdict != "changed")
    }
}

/// The verdict of one term: `(verdict, share, factor)` (module docs), with `u` the comparison's
/// uncertainty taken as the value before's too (`verdict_of` with `(u, 0)`).
pub fn verdict(
    compensated: bool,
    values: (f64, f64, f64),
    u: f64,
    resolution: f64,
) -> (&'static str, Option<f64>, Option<f64>) {
    verdict_of(compensated, values, (u, 0.0), resolution)
}

/// The verdict of one term: `(verdict, share, factor)` (module docs), from the uncertainties of
/// the value before and of the refit, `(u_b, u_a)`.
pub fn verdict_of(
    compensated: bool,
    (before, predicted, after): (f64, f64, f64),
    (u_before, u_after): (f64, f64),
    resolution: f64,
) -> (&'static str, Option<f64>, Option<f64>) {
    // The controller's resolution widens only `corrected` (the spec's "within 3 u, or the
    // controller's resolution"): whether a term moved at all is judged on its uncertainty, so a
    // coarse detection unit cannot turn a change into `not_compensated` or `unchanged`.
    let u = u_before.hypot(u_after);
    let tol = 3.0 * u;
    let moved = after - before;
    if !u.is_finite() {
        // A refit without a finite uncertainty shows nothing either way.
        return (if compensated { "not_resolved" } else { "not_compensated" }, None, None);
    }
    if !compensated {
        let off = after - predicted;
        return (if off.abs() <= tol { "not_compensated" } else { "changed" }, None, None);
    }
    let c = predicted - before;
    // The files leave the term (a correction of rounding's size against the values).
    let nothing = c.abs() <= 1e-12 * before.abs().max(predicted.abs()).max(resolution);
    if (after - predicted).abs() <= tol.max(resolution) {
        // Within the prediction's band: `corrected` only where the data also rule out the
        // value before (the files not loaded) and the move went the correction's way, which
        // rules out the wrong sign where the controller's resolution widens the band past
        // 3u (module docs); where the files leave the term there is nothing to tell apart. A
        // move resolved the other way, or any resolved move where the files leave the term
        // (the resolution widens nothing there: no value was rounded), is judged below.
        if (nothing && moved.abs() <= tol) || (moved.abs() > tol && moved * c > 0.0) {
            return ("corrected", None, None);
        }
        if moved.abs() <= tol {
            return ("not_resolved", None, None);
        }
    }
    if moved.abs() <= tol {
        return ("unchanged", None, None);
    }
    if c.abs() <= 3.0 * u_before {
        return ("changed", None, None);
    }
    let r = moved / c;
    let inch = 25.4f64;
    let factors = [1e-3, 1e-2, 1e-1, 1.0 / inch, inch, 1e1, 1e2, 1e3];
    let factor = || {
        (r > 0.0)
            .then(|| factors.into_iter().find(|f| (r.log10() - f.log10()).abs() <= 0.15))
            .flatten()
    };
    if c.abs() <= tol {
        // The refit does not resolve the correction: `log10 r`'s 3σ, `3u/(|m| ln 10)` to
        // first order, is read as the relative band `3u/|m|` against the band's ±41 %
        // (`10^0.15 − 1`), the move resolving the factor by itself.
        return match factor() {
            Some(f) if tol / moved.abs() <= 10f64.powf(0.15) - 1.0 => ("scaled", None, Some(f)),
            _ => ("changed", None, None),
        };
    }
    if (r + 1.0).abs() <= 0.5 {
        return ("reversed", Some(r), None);
    }
    if let Some(f) = factor() {
        return ("scaled", None, Some(f));
    }
    let name = if r < 0.0 {
        "moved_away"
    } else if r < 1.0 {
        "partly"
    } else {
        "overshot"
    };
    (name, Some(r), None)
}

impl TermCheck {
    /// What the verdict means on the shop floor and what to do next, in one sentence; `None`
    /// for a term that is as it should be (`corrected`, `not_compensated`).
    pub fn advice(&self) -> Option<String> {
        let what = format!("{} of {} ({})", self.term, self.axis, self.id);
        let moved = format!(
            "{} → {} {} where {} {} was predicted",
            fmt(self.before),
            fmt(self.after),
            self.unit,
            fmt(self.predicted_after),
            self.unit
        );
        Some(match self.verdict.as_str() {
            "corrected" | "not_compensated" => return None,
            "unchanged" => {
                // A wrong sign leaves `b - c`: where that is within 3u of the value measured
                // too, the repeat cannot tell it from a file not loaded.
                let wrong_sign = 2.0 * self.before - self.predicted_after;
                let either = if (self.after - wrong_sign).abs() <= 3.0 * self.u {
                    format!(
                        " or is applying it with the wrong sign (its correction, {} {}, is within the {} {} a repeat resolves, 6u: these tests cannot tell which; read the value back from the controller)",
                        fmt(self.correction()),
                        self.unit,
                        fmt(RESOLVED_IN_U * self.u),
                        self.unit
                    )
                } else {
                    String::new()
                };
                format!(
                    "{what} did not move ({moved}): the controller is not applying the file{either}. Check that it is loaded and active (LinuxCNC: COMP_FILE in the joint's section and a restart; SINUMERIK: MD32700 and a reset; FANUC: the parameters entered; HEIDENHAIN: the table marked active in the .CMA), then repeat the test"
                )
            }
            "not_resolved" => format!(
                "{what} reads as predicted and as before alike ({moved}, u {} {}): its correction, {} {}, is within the {} {} a repeat resolves (6u){}, so these tests cannot tell the file loaded from not loaded or entered with the wrong sign. {} the value back from the controller (the parameter or table) and check it against the file",
                fmt(self.u),
                self.unit,
                fmt(self.correction()),
                self.unit,
                fmt(RESOLVED_IN_U * self.u),
                self.unit,
                if self.verifiable_by_repeat == Some(false) {
                    ", as compensate said when it wrote the files"
                } else {
                    ""
                },
                match self.sessions {
                    Some(n) => format!(
                        "Repeat the tests to {n} sessions in all and verify with all of them, or read"
                    ),
                    None => "No number of repeats resolves it (the value before is itself too uncertain, 6 u_before ≥ |correction|, or the correction is within the controller's resolution): read".into(),
                }
            ),
            NOT_MEASURED if self.compensated => format!(
                "{what} is compensated, but the repeated tests do not measure it (their fit does not determine it: its value after, {} {}, is a gauge's choice): its correction, {} {}, is not verified. It is measured by {}: repeat them with the files active and verify again",
                fmt(self.after),
                self.unit,
                fmt(self.correction()),
                self.unit,
                self.measured_by.as_deref().unwrap_or("the tests the model was fitted to")
            ),
            NOT_MEASURED => return None,
            "reversed" => format!(
                "{what} moved the wrong way, by about twice its size ({moved}): the correction was entered with the wrong sign. Reverse the sign of its values, reload and repeat the test"
            ),
            "scaled" => format!(
                "{what} moved {} times the correction ({moved}): a unit mistake (mm, µm or inch) when the values were entered. Check the file's units against the controller's setting, reload and repeat the test",
                self.factor.map_or("a power of ten".into(), |f| format!("{f}"))
            ),
            "partly" => format!(
                "{what} moved {} of the way to the prediction ({moved}): part of the correction acts. Check for a value the controller clipped or a table shorter than the travel; repeat the test before adding more",
                share(self.share)
            ),
            "overshot" => format!(
                "{what} moved past the prediction, {} of the correction ({moved}): too much was entered, or another compensation acts as well. Check for a compensation applied twice",
                share(self.share)
            ),
            "moved_away" => format!(
                "{what} moved away from the prediction ({moved}), not as a wrong sign would: something other than the file acts. Check that the file went to this axis (the joint or axis number)"
            ),
            "changed" => format!(
                "{what} was not to change, and moved ({moved}): something else changed on the machine (temperature, a collision, another adjustment). Find what before trusting this comparison"
            ),
            other => format!("{what}: {other} ({moved})"),
        })
    }
}

impl TermCheck {
    /// The correction the files apply, `predicted_after - before`.
    pub fn correction(&self) -> f64 {
        self.predicted_after - self.before
    }
}

/// A value as the verification prints it (3 decimals).
fn fmt(x: f64) -> String {
    format!("{x:.3}")
}

/// A share of the correction as a percentage, or "part" when not given.
fn share(s: Option<f64>) -> String {
    s.map_or("part".into(), |s| format!("{:.0} %", 100.0 * s))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The resolution is the spec's allowance for `corrected` only: a 1 µm detection unit does
    /// not hide a 0.6 µm change of a term the files left alone (u 0.05 µm), while 0.6 µm off
    /// the prediction is still `corrected`.
    #[test]
    fn the_resolution_widens_only_corrected() {
        assert_eq!(verdict(false, (2.0, 2.0, 2.6), 0.05, 1.0).0, "changed");
        assert_eq!(verdict(false, (2.0, 2.0, 2.1), 0.05, 1.0).0, "not_compensated");
        assert_eq!(verdict(true, (2.0, 1.2, 1.8), 0.05, 1.0).0, "corrected");
        assert_eq!(verdict(true, (4.0, 0.0, 0.6), 0.05, 1.0).0, "corrected");
        assert_eq!(verdict(true, (4.0, 0.0, 4.02), 0.05, 1.0).0, "unchanged");
        assert_eq!(verdict(true, (4.0, 0.0, 8.0), 0.05, 1.0).0, "reversed");
    }

    #[test]
    fn each_wrong_application_gives_its_verdict() {
        // A backlash of 4 µm, u 0.05 µm, corrected to 0.
        let (b, p, u) = (4.0, 0.0, 0.05);
        let v = |a: f64| verdict(true, (b, p, a), u, 1e-4).0;
        assert_eq!(v(0.1), "corrected");
        assert_eq!(v(4.05), "unchanged");
        assert_eq!(v(8.0), "reversed");
        // ×10 (a 40 µm correction: -36 µm) and ×1000.
        assert_eq!(v(b - 40.0), "scaled");
        assert_eq!(verdict(true, (b, p, b - 4000.0), u, 1e-4).2, Some(1000.0));
        // A file in mm read as inches: ×25.4.
        assert_eq!(verdict(true, (b, p, b - 4.0 * 25.4), u, 1e-4).2, Some(25.4));
        // ÷10: 0.4 µm of correction, 10 %.
        assert_eq!(verdict(true, (b, p, 3.6), u, 1e-4).2, Some(0.1));
        // Half of it: partly, share 0.5.
        let (name, share, _) = verdict(true, (b, p, 2.0), u, 1e-4);
        assert_eq!((name, share), ("partly", Some(0.5)));
        // Moved away, but not to about twice: not partly (no negative share of a correction
        // reads as progress), and not reversed.
        let (name, share, _) = verdict(true, (b, p, 5.0), u, 1e-4);
        assert_eq!((name, share), ("moved_away", Some(-0.25)));
        let (name, share, _) = verdict(true, (b, p, 4.0 + 4.0 * 2.0), u, 1e-4);
        assert_eq!((name, share), ("moved_away", Some(-2.0)));
        // Past the prediction by 60 %: overshot, not partly (and not a unit's factor).
        let (name, share, _) = verdict(true, (b, p, 4.0 - 6.4), u, 1e-4);
        assert_eq!(name, "overshot");
        assert!((share.unwrap() - 1.6).abs() < 1e-12);
        // A compensated term the files were to leave as it was (a correction of 0, as when the
        // existing compensation already holds it): moved means changed, never a division by 0.
        assert_eq!(verdict(true, (b, b, 5.0), u, 1e-4), ("changed", None, None));
        assert_eq!(verdict(true, (b, b, 4.01), u, 1e-4).0, "corrected");
        // Not compensated: still as it was, or changed.
        assert_eq!(verdict(false, (b, b, 4.1), u, 1e-4).0, "not_compensated");
        assert_eq!(verdict(false, (b, b, 5.0), u, 1e-4).0, "changed");
        // A scale of 56.5 ppm (u 1 ppm before) corrected by 55.6 ppm and applied ten times
        // (a FANUC's pitch data read in units ten times too large): the refit's u, 43 ppm, is
        // inflated by the table's 10 µm steps, which the model does not describe, so it does
        // not resolve the correction (3 u > 55.6 ppm); the move, -557 ppm, resolves the factor
        // (3 u/|m| = 0.23 ≤ 0.41): `scaled`, 10. With the before's u taken as the whole u the
        // correction is not resolved, and the term reads as changed.
        let (b, p, a) = (56.5, 0.85, 56.5 - 10.0 * 55.65);
        assert_eq!(verdict_of(true, (b, p, a), (1.0, 43.0), 1e-4), ("scaled", None, Some(10.0)));
        assert_eq!(verdict(true, (b, p, a), 43.0, 1e-4).0, "changed");
        // The same refit, the correction applied four times (r = 4): no factor, and not resolved:
        // changed. A move that does not resolve the factor (3 u/|m| > 0.41): changed.
        assert_eq!(verdict_of(true, (b, p, b - 4.0 * 55.65), (1.0, 43.0), 1e-4).0, "changed");
        assert_eq!(verdict_of(true, (b, p, a), (1.0, 100.0), 1e-4).0, "changed");
        // A correction within the before's 3 u: the files were to leave it.
        assert_eq!(verdict_of(true, (b, b - 2.0, a), (1.0, 43.0), 1e-4).0, "changed");
        // Not compensated, but moved by the files through the fit (a table's steps): as
        // predicted it is not a change of the machine; where it was before, it is.
        assert_eq!(verdict(false, (b, 5.0, 5.1), u, 1e-4).0, "not_compensated");
        assert_eq!(verdict(false, (b, 5.0, b), u, 1e-4).0, "changed");
        let pass = |verdict: &str, compensated| {
            Verification {
                format: VERIFICATION_FORMAT.into(),
                terms: vec![TermCheck {
                    term: "backlash".into(),
                    axis: "X".into(),
                    id: "BX".into(),
                    before: b,
                    predicted_after: p,
                    after: 0.0,
                    u,
                    unit: "µm".into(),
                    compensated,
                    verdict: verdict.into(),
                    share: None,
                    factor: None,
                    sessions: None,
                    verifiable_by_repeat: None,
                    measured_by: None,
                }],
                runs: vec![],
                notes: vec![],
            }
            .passed()
        };
        assert!(pass("corrected", true));
        assert!(!pass("reversed", true));
        assert!(pass("not_compensated", false));
        assert!(!pass("changed", false));
    }

    /// A backlash whose correction is about 3u, `u = √(0.06² + 0.08²) = 0.1` µm (`tol` 0.3):
    /// 0.35 µm corrected to 0. The repeat's bands, `|a - p| ≤ 0.3` (applied) and `|a - b| ≤
    /// 0.3` (not loaded), overlap on 0.05..0.3: a value there is `not_resolved`, never
    /// `corrected`, whichever way the file went in. The same numbers with a correction of
    /// 0.8 µm (8u, beyond the 6u that keeps the bands apart) keep their verdicts.
    #[test]
    fn a_correction_the_repeat_cannot_resolve_never_reads_corrected() {
        let us = (0.06, 0.08);
        let v = |b: f64, a: f64| verdict_of(true, (b, 0.0, a), us, 1e-4).0;
        // Applied: exactly as predicted, it moved 0.35 > 0.3: the data show it.
        assert_eq!(v(0.35, 0.0), "corrected");
        // Applied, the refit 0.1 high: within both bands (0.1 of p, 0.25 of b).
        assert_eq!(v(0.35, 0.1), "not_resolved");
        // Not loaded, the refit 0.1 low: 0.25 from the prediction, which read `corrected`
        // before; 0.1 from the value before.
        assert_eq!(v(0.35, 0.25), "not_resolved");
        // Not loaded, 0.05 high: 0.4 from the prediction, 0.05 from before: unchanged.
        assert_eq!(v(0.35, 0.40), "unchanged");
        // The wrong sign, `b - c` = 0.7, the refit 0.15 low: 0.55 from the prediction, 0.2 from
        // before and 0.15 from the wrong sign: unchanged, and the advice says it could be
        // either.
        assert_eq!(v(0.35, 0.55), "unchanged");
        // A correction of 1.4u (0.14 µm): the wrong sign, 0.28, is within 0.3 of the
        // prediction too, and read `corrected` before; it is 0.14 from before.
        assert_eq!(v(0.14, 0.28), "not_resolved");
        // Resolved, 8u: applied (0.1 off), not loaded (0.05 off) and the wrong sign, as before.
        assert_eq!(v(0.8, 0.1), "corrected");
        assert_eq!(v(0.8, 0.85), "unchanged");
        assert_eq!(verdict_of(true, (0.8, 0.0, 1.6), us, 1e-4), ("reversed", Some(-1.0), None));
        // Files that leave the term (c = 0): nothing to load, as predicted. A correction below
        // the controller's resolution (0.05 against 0.2) is not shown by a move of 0.03.
        assert_eq!(verdict_of(true, (0.35, 0.35, 0.32), us, 0.2).0, "corrected");
        assert_eq!(verdict_of(true, (0.35, 0.3, 0.32), us, 0.2).0, "not_resolved");
        // A resolution wider than 3u (FANUC's 1 µm against tol 0.3): a correction of 0.45 µm
        // with the wrong sign lands 0.9 from the prediction, inside the 1 µm band, and moved
        // 0.45 > 0.3, the wrong way: not `corrected` (it read so before the move's direction
        // was asked); not loaded, 0.45 from p, moved 0: `not_resolved`; applied: `corrected`.
        assert_eq!(verdict_of(true, (0.45, 0.0, 0.9), us, 1.0), ("reversed", Some(-1.0), None));
        // Files that leave the term, and a move of 0.85 (2.8u) inside the 1 µm band: no value
        // was rounded, so the band is 3u: `changed`, as for a term not compensated.
        assert_eq!(verdict_of(true, (0.35, 0.35, 1.2), us, 1.0).0, "changed");
        // A refit without a finite u shows nothing.
        assert_eq!(
            verdict_of(true, (0.35, 0.0, 0.0), (0.06, f64::INFINITY), 1e-4).0,
            "not_resolved"
        );
        assert_eq!(verdict_of(true, (0.45, 0.0, 0.45), us, 1.0).0, "not_resolved");
        assert_eq!(verdict_of(true, (0.45, 0.0, 0.02), us, 1.0).0, "corrected");
        // Fails the verification (exit 3): it is not `corrected`.
        let t = TermCheck {
            before: 0.35,
            after: 0.1,
            u: 0.1,
            verdict: "not_resolved".into(),
            sessions: sessions_to_resolve(-0.35, us.0, us.1, 1e-4),
            ..check("not_resolved", None, None)
        };
        let v = Verification {
            format: VERIFICATION_FORMAT.into(),
            terms: vec![t],
            runs: vec![],
            notes: vec![],
        };
        assert!(!v.passed());
        // 6 u_b = 0.36 ≥ 0.35: no number of sessions resolves it.
        assert_eq!(v.terms[0].sessions, None);
        assert!(v.terms[0].advice().unwrap().contains("No number of repeats"));
    }

    /// Sessions to resolve a correction: `c` = 0.5, `u_b` 0.06, `u_a` 0.08: `n ≥ 0.0064 /
    /// ((0.5/6)² - 0.0036) = 0.0064/0.0033444 = 1.91`, so 2 (check: 6 √(0.0036 + 0.0032) =
    /// 0.495 ≤ 0.5, and one session's 6 × 0.1 = 0.6 is not). A correction of 1.0: 6 u = 0.6
    /// already, one session. 0.36 = 6 u_b: none.
    #[test]
    fn the_sessions_that_resolve_a_correction_are_derived_by_hand() {
        assert_eq!(sessions_to_resolve(0.5, 0.06, 0.08, 1e-4), Some(2));
        assert_eq!(sessions_to_resolve(-0.5, 0.06, 0.08, 1e-4), Some(2));
        assert_eq!(sessions_to_resolve(1.0, 0.06, 0.08, 1e-4), Some(1));
        assert_eq!(sessions_to_resolve(0.36, 0.06, 0.08, 1e-4), None);
        assert_eq!(sessions_to_resolve(0.5, 0.06, f64::NAN, 1e-4), None);
        // A resolution of 1 µm: a correction of 1 µm is within it whatever the sessions (read
        // it back); 1.5 µm needs u_n < (1.5 − 1)/3 = 0.1667 (below 1.5/6 = 0.25): one session's
        // 0.1 already; 1.2 µm needs u_n < 0.0667, `n ≥ 0.0064/(0.004444 − 0.0036) = 7.58`, 8.
        assert_eq!(sessions_to_resolve(1.0, 0.06, 0.08, 1.0), None);
        assert_eq!(sessions_to_resolve(1.5, 0.06, 0.08, 1.0), Some(1));
        assert_eq!(sessions_to_resolve(1.2, 0.06, 0.08, 1.0), Some(8));
        let t = TermCheck {
            before: 0.5,
            after: 0.1,
            u: 0.1,
            sessions: Some(2),
            ..check("not_resolved", None, None)
        };
        let a = t.advice().unwrap();
        assert_eq!(
            a,
            "backlash of X (BX) reads as predicted and as before alike (0.500 → 0.100 µm where 0.000 µm was predicted, u 0.100 µm): its correction, -0.500 µm, is within the 0.600 µm a repeat resolves (6u), so these tests cannot tell the file loaded from not loaded or entered with the wrong sign. Repeat the tests to 2 sessions in all and verify with all of them, or read the value back from the controller (the parameter or table) and check it against the file"
        );
        // Flagged by `compensate` at write time: the advice says it said so.
        let flagged = TermCheck { verifiable_by_repeat: Some(false), ..t.clone() };
        let said = flagged.advice().unwrap();
        assert_eq!(
            said,
            a.replace("(6u), so", "(6u), as compensate said when it wrote the files, so")
        );
        assert!(!a.contains("as compensate said"));
        // `unchanged` where the wrong sign fits as well says so; where it does not, not.
        let either = TermCheck { before: 0.35, after: 0.55, ..check("unchanged", None, None) };
        assert!(either.advice().unwrap().contains("or is applying it with the wrong sign"));
        let plain = TermCheck { before: 0.8, after: 0.85, ..check("unchanged", None, None) };
        assert!(!plain.advice().unwrap().contains("wrong sign"));
    }

    fn check(verdict: &str, share: Option<f64>, factor: Option<f64>) -> TermCheck {
        TermCheck {
            term: "backlash".into(),
            axis: "X".into(),
            id: "BX".into(),
            before: 3.8,
            predicted_after: 0.0,
            after: 7.6,
            u: 0.1,
            unit: "µm".into(),
            compensated: true,
            verdict: verdict.into(),
            share,
            factor,
            sessions: None,
            verifiable_by_repeat: None,
            measured_by: None,
        }
    }

    /// Each verdict that needs an action says what is wrong and what to do, with the numbers;
    /// a term as it should be says nothing.
    #[test]
    fn each_verdict_that_needs_an_action_says_which() {
        assert_eq!(check("corrected", None, None).advice(), None);
        assert_eq!(check("not_compensated", None, None).advice(), None);
        let r = check("reversed", Some(-1.0), None).advice().unwrap();
        assert_eq!(
            r,
            "backlash of X (BX) moved the wrong way, by about twice its size (3.800 → 7.600 µm where 0.000 µm was predicted): the correction was entered with the wrong sign. Reverse the sign of its values, reload and repeat the test"
        );
        assert!(check("unchanged", None, None).advice().unwrap().contains("not applying the file"));
        assert!(
            check("scaled", None, Some(10.0))
                .advice()
                .unwrap()
                .contains("moved 10 times the correction")
        );
        assert!(check("scaled", None, Some(10.0)).advice().unwrap().contains("unit mistake"));
        assert!(
            check("partly", Some(0.42), None).advice().unwrap().contains("moved 42 % of the way")
        );
        assert!(
            check("overshot", Some(1.6), None)
                .advice()
                .unwrap()
                .contains("160 % of the correction")
        );
        assert!(
            check("moved_away", Some(-0.3), None)
                .advice()
                .unwrap()
                .contains("joint or axis number")
        );
        assert!(check("changed", None, None).advice().unwrap().contains("something else changed"));
    }

    fn predicted(run: &str, plane: Option<&str>) -> crate::Predicted {
        crate::Predicted {
            run: run.into(),
            plane: plane.map(Into::into),
            rms_before_um: 1.0,
            rms_after_um: 1.0,
            g_before_um: 1.0,
            g_after_um: 1.0,
        }
    }

    /// The tests that measure a term: a circle in a plane that moves its axis, in the plane of
    /// its two axes, or a rotary test; with the runs before compensation in those planes that
    /// were not repeated.
    #[test]
    fn the_tests_that_measure_a_term_are_named_with_the_runs_not_repeated() {
        let p = [
            predicted("xy-ccw-1", Some("XY")),
            predicted("yz-cw-1", Some("YZ")),
            predicted("zx-cw-1", Some("ZX")),
        ];
        let xy = ["xy-ccw-1".to_string()];
        assert_eq!(
            tests_that_measure("backlash", "Z", "BZ", &p, &xy),
            "circles in the YZ or ZX plane: of the tests before compensation, which determined it, yz-cw-1, zx-cw-1 were not repeated"
        );
        assert_eq!(
            tests_that_measure("squareness", "YZ", "SQYZ", &p, &xy),
            "circles in the YZ plane: of the tests before compensation, which determined it, yz-cw-1 was not repeated"
        );
        // Straightness of X along Z: the ZX plane.
        assert_eq!(
            tests_that_measure("straightness", "X", "EZX2", &p, &xy),
            "circles in the ZX plane: of the tests before compensation, which determined it, zx-cw-1 was not repeated"
        );
        // X's scale: XY repeated, ZX not.
        assert_eq!(
            tests_that_measure("scale", "X", "EXX1", &p, &xy),
            "circles in the XY or ZX plane: of the tests before compensation, which determined it, zx-cw-1 was not repeated"
        );
        // A document without the runs' planes names the planes only.
        let old = [predicted("xy-ccw-1", None)];
        assert_eq!(
            tests_that_measure("scale", "X", "EXX1", &old, &[]),
            "circles in the XY or ZX plane"
        );
        assert_eq!(
            tests_that_measure("rotary_location", "A", "EA0A", &p, &xy),
            "rotary tests of A (axial, radial or tangential)"
        );
    }

    /// The repeated runs against those `compensation.json` predicted: the same (none said),
    /// some not repeated, others added, a run of another plane under the same name.
    #[test]
    fn repeated_runs_that_are_not_the_predicted_ones_are_said() {
        let p = [predicted("xy-ccw-1", Some("XY")), predicted("yz-cw-1", Some("YZ"))];
        let r = |v: &[(&str, Option<&str>)]| -> Vec<(String, Option<String>)> {
            v.iter().map(|(a, b)| (a.to_string(), b.map(Into::into))).collect()
        };
        // The same runs, and a rotary test (no plane) beside them: nothing to say.
        assert_eq!(
            runs_mismatch(
                &p,
                &r(&[("xy-ccw-1", Some("XY")), ("yz-cw-1", Some("YZ")), ("c-radial-1", None)])
            ),
            None
        );
        let said = runs_mismatch(&p, &r(&[("xy-ccw-1", Some("XY"))])).unwrap();
        assert!(said.contains("(xy-ccw-1, yz-cw-1): not repeated: yz-cw-1;"), "{said}");
        let said = runs_mismatch(&p, &r(&[("a-1", Some("XY")), ("a-2", Some("XY"))])).unwrap();
        assert!(
            said.contains("not repeated: xy-ccw-1, yz-cw-1; not among them: a-1, a-2"),
            "{said}"
        );
        let said =
            runs_mismatch(&p, &r(&[("xy-ccw-1", Some("XY")), ("yz-cw-1", Some("ZX"))])).unwrap();
        assert!(said.contains("another plane: yz-cw-1 is ZX, was YZ"), "{said}");
        // Nothing predicted (compensate without runs): nothing to compare.
        assert_eq!(runs_mismatch(&[], &r(&[("xy-ccw-1", Some("XY"))])), None);
    }

    /// Runs whose header names another machine than the model's are said; runs that name
    /// none, or the model's, are not.
    #[test]
    fn runs_of_another_machine_are_said() {
        let r = |v: &[(&str, Option<&str>)]| -> Vec<(String, Option<String>)> {
            v.iter().map(|(a, b)| (a.to_string(), b.map(Into::into))).collect()
        };
        assert_eq!(machine_mismatch("column", &r(&[("a", Some("column")), ("b", None)])), None);
        assert_eq!(
            machine_mismatch("column", &r(&[("a", Some("column")), ("b", Some("horizontal"))])),
            Some("the repeated runs name another machine than the model's, column: b (horizontal); a verification compares the same machine's tests".into())
        );
    }

    /// A compensated term the repeat does not measure fails the verification and says which
    /// tests would measure it; one not compensated neither fails it nor needs an action.
    #[test]
    fn a_term_not_measured_fails_only_where_it_is_compensated() {
        let t = TermCheck {
            term: "backlash".into(),
            axis: "Z".into(),
            id: "BZ".into(),
            before: 3.199,
            predicted_after: 0.0,
            after: 0.0,
            verdict: NOT_MEASURED.into(),
            measured_by: Some("circles in the YZ or ZX plane".into()),
            ..check("corrected", None, None)
        };
        let v = |terms: Vec<TermCheck>| Verification {
            format: VERIFICATION_FORMAT.into(),
            terms,
            runs: vec![],
            notes: vec![],
        };
        assert!(!v(vec![t.clone()]).passed());
        assert_eq!(
            t.advice().unwrap(),
            "backlash of Z (BZ) is compensated, but the repeated tests do not measure it (their fit does not determine it: its value after, 0.000 µm, is a gauge's choice): its correction, -3.199 µm, is not verified. It is measured by circles in the YZ or ZX plane: repeat them with the files active and verify again"
        );
        let free = TermCheck { compensated: false, predicted_after: 3.199, ..t };
        assert!(v(vec![free.clone()]).passed());
        assert_eq!(free.advice(), None);
    }
}

//! Our values beside the vendor's own analysis of a `.b5r` file (`vendor_comparison` in
//! `shared/spec/cli.md`), feature by feature, in the vendor's units and sign conventions.
//!
//! # The mapping (vendor feature ← our quantity), plane (A, B) as the file names it
//! - `AF_SCALE_ERROR_A/B` (ppm) ← the positional (scale) error of axis A / B.
//! - `AF_GLOBAL_SCALE` (µm) ← (s_A + s_B)/2 · R, the mean radial deviation the scales make.
//! - `AF_SCALE_MISMATCH` (µm) ← (s_A − s_B) · 2R, their difference over the diameter.
//!   (These three verified on the shared real file: 40.4 and 10.3 ppm give 1.3 and 3.0 µm.)
//! - `AF_SQUARENESS` (µm/m) ← our squareness α of the plane (µrad), same sign: the vendor's
//!   value is −2 × the sin 2θ coefficient of the CW/CCW mean profile over R, and our α makes
//!   ΔR = −α R sin θ cos θ in either orientation of the plane's axes.
//! - `AF_BACKLASH_{A,B}_GLOBAL` (µm) ← our backlash B of the axis, same sign (the shared file:
//!   −0.88 / 0.34 against the vendor's −0.9 / 0.3).
//! - `AF_SERVO_MISMATCH` (ms) ← τ_A − τ_B, the lag of A minus the lag of B. The sign is the
//!   opposite of the paper's plane term `M/V` (M = V (τ_V − τ_U)); it rests on one other
//!   vendor file (ours +0.06 ms with the paper's sign against the vendor's −0.05 ms): the
//!   shared file's mismatch is 0.00 ms and cannot confirm it.
//! - `AF_CENTRE_OFFSET_A/B` (µm), `AF_BEST_RADIUS` (mm) and the per-run `AF_CIRCULARITY` (µm):
//!   the vendor's own definitions (least-squares circle of the readings over the analysed arc;
//!   ISO 230-4 circular deviation about it) applied to the same readings on the vendor's own
//!   angles of the samples ([`B5rTest::vendor_angles_deg`]). They check the reading of the
//!   file, not the model.
//! - `AF_STRAIGHTNESS_A` (µm) ← S of ΔB = S (A/R)², our "B straightness along A" at this R
//!   (and B likewise): the vendor's 4 × the sin 3θ (−4 × cos 3θ for B) coefficient.
//! - `AF_REVERSAL_SPIKES_*`, `AF_CYCLIC_ERROR_*`, `AF_LATERAL_PLAY_*` ← the effects the diagnosis
//!   names (POS: the reversal at the axis's positive end, NEG the negative; FWD: the axis moving
//!   positive), with what differs in the definitions said; where the diagnosis names none, why.
//! - `<ERROR>_IC`, `_PERC`, `_RANK`: our impact of the same error by the vendor's definitions,
//!   its share and rank among ours (`ranking`).
//! - `RMS` (µm): the readings minus the vendor's model against the readings minus ours.

use std::fmt::Write as _;

use ballbar_fit::{Fit, metrics, quantity};
use ballbar_io::b5r::{B5rTest, VendorFeature};

use ballbar_documents::VendorEntry;
use ballbar_documents::diagnosis::{self as doc, Why};
use ballbar_model::machine::{Model, ServoVariant};
use ballbar_model::{Axis, Plane, Run, paper};

/// One feature: the vendor's value and ours.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The test plane.
    pub plane: Plane,
    /// The vendor's feature name.
    pub feature: String,
    /// The vendor's unit.
    pub unit: &'static str,
    /// The vendor's value.
    pub vendor: f64,
    /// False where the vendor marks its value not to be trusted.
    pub vendor_valid: bool,
    /// Our value in the vendor's unit and sign; `None` where we have none.
    pub ours: Option<f64>,
    /// Its standard uncertainty, where there is one.
    pub ours_u: Option<f64>,
    /// The run, for per-run features.
    pub run: Option<String>,
    /// Where our value comes from, or why we have none or disagree.
    pub note: String,
}

/// Our side of one feature.
struct Ours {
    value: Option<f64>,
    u: Option<f64>,
    note: String,
}

impl Ours {
    fn none(note: impl Into<String>) -> Ours {
        Ours { value: None, u: None, note: note.into() }
    }
    fn exact(value: f64, note: impl Into<String>) -> Ours {
        Ours { value: Some(value), u: None, note: note.into() }
    }
}

/// What the diagnosis adds to the comparison: the residual after the diagnosed model (µm), and
/// the diagnosis document (`ballbar-diagnosis/1`) for its effects.
#[derive(Clone, Copy, Debug, Default)]
pub struct Diagnosed<'a> {
    /// RMS of the readings minus the diagnosed model over the file's runs, µm.
    pub rms_after_um: Option<f64>,
    /// The diagnosis.
    pub diagnosis: Option<&'a doc::Diagnosis>,
}

/// The comparison for one `.b5r` file: `runs` are the command's runs, `indices` those of this
/// file (in file order), `fit` the base fit of all the runs with `model`.
pub fn compare(
    test: &B5rTest,
    runs: &[Run],
    indices: std::ops::Range<usize>,
    model: &Model,
    fit: &Fit,
    diagnosed: Diagnosed,
) -> Vec<Entry> {
    let mut out = Vec::new();
    let file_runs = &runs[indices.clone()];
    let Some(first) = file_runs.first() else { return out };
    let (r_mm, feed) = (first.header.radius_mm, first.header.feed_mm_per_min);
    let (a, b) = (test.axis_a, test.axis_b);
    let plane = test.plane;

    // Per run: the circle of the readings and its circularity, on the vendor's own angles of
    // the samples (its definitions), else on the run's.
    let angles: Vec<Option<Vec<f64>>> = file_runs
        .iter()
        .enumerate()
        .map(|(k, run)| match test.vendor_angles_deg.get(k).filter(|v| v.len() == run.len()) {
            Some(deg) => Some(deg.iter().map(|d| d.to_radians()).collect()),
            None => run_angles(run, a, b),
        })
        .collect();
    let circles: Vec<Option<[f64; 3]>> = file_runs
        .iter()
        .zip(&angles)
        .map(|(run, th)| th.as_ref().map(|th| metrics::lsq_circle(th, &run.dr_mm)))
        .collect();
    for ((run, th), features) in file_runs.iter().zip(&angles).zip(&test.run_features) {
        if let (Some(f), Some(th)) = (features.iter().find(|f| f.name == "AF_CIRCULARITY"), th) {
            let about = metrics::about_lsq_circle(th, &run.dr_mm);
            let g = (about.iter().copied().fold(f64::MIN, f64::max)
                - about.iter().copied().fold(f64::MAX, f64::min))
                * 1e3;
            let ours = Ours::exact(
                g,
                "ISO 230-4 circular deviation of the readings about their least-squares circle (the vendor's definition, the same readings)",
            );
            push(&mut out, plane, f, ours, Some(run.name()));
        }
    }

    let rows = paper::report(model, r_mm, feed);
    let row = |name: &str| rows.iter().find(|r| r.vendor.name == name).map(|r| &r.vendor);
    let estimate = |terms: Vec<(String, f64)>, note: &str| -> Ours {
        let q = paper::Quantity { name: String::new(), unit: "", terms };
        match quantity(fit, &q) {
            Some(e) if e.estimate.estimable => Ours {
                value: Some(e.estimate.value),
                u: Some(e.estimate.std_uncertainty),
                note: note.into(),
            },
            Some(_) => {
                Ours::none("not identifiable from these tests (see the fit's identifiability)")
            }
            None => Ours::none("not in this machine's model"),
        }
    };
    let scale_terms = |axis: Axis, factor: f64| -> Option<Vec<(String, f64)>> {
        row(&format!("{axis} scale"))
            .map(|q| q.terms.iter().map(|(id, f)| (id.clone(), f * factor)).collect())
    };
    let Some(diag) = test.diagnostics() else { return out };
    // Where the runs are spaced as the machine moved and the vendor's even spread differs, the
    // terms that its drift of angle moves say so.
    let by_feed =
        ballbar_io::b5r::SpacingMode::of(first) == Some(ballbar_io::b5r::SpacingMode::Feed);
    let rate = first.sample_rate_hz().unwrap_or(0.0);
    let arc_deg = first
        .header
        .extra
        .iter()
        .find(|(k, _)| k == "arc_deg")
        .and_then(|(_, v)| v.parse::<f64>().ok())
        .unwrap_or(360.0);
    // Samples the programmed feed takes over the arc.
    let per_arc = std::f64::consts::TAU * r_mm * rate / (feed / 60.0) * arc_deg / 360.0;
    let n = first.len() as f64;
    let spacing_note = (by_feed && (n - per_arc).abs() >= 1.0).then(|| {
        let drift_deg = (n - per_arc).abs() / 2.0 * arc_deg / per_arc;
        format!(
            "; on the samples spaced as the machine moved: the vendor spreads its arc's {n:.0} samples over its {arc_deg}°, the programmed feed takes {per_arc:.1}, so its angles drift by up to {drift_deg:.2}° at the arc's ends, which through the set-up eccentricity moves the 2θ and scale terms (--b5r-angles vendor reads with the vendor's convention)"
        )
    });
    for f in &diag.features {
        let ours = match f.name.as_str() {
            "AF_CENTRE_OFFSET_A" | "AF_CENTRE_OFFSET_B" => {
                let k = if f.name.ends_with('A') { 1 } else { 2 };
                mean(circles.iter().map(|c| c.map(|c| c[k] * 1e3))).map_or_else(
                    || Ours::none("a run is not a planar circle"),
                    |v| Ours::exact(v, "least-squares circle of the readings, mean of the runs (the vendor's definition, the same readings)"),
                )
            }
            "AF_BEST_RADIUS" => mean(circles.iter().map(|c| c.map(|c| r_mm + c[0]))).map_or_else(
                || Ours::none("a run is not a planar circle"),
                |v| Ours::exact(v, "nominal R plus the mean radial deviation of the readings' least-squares circles"),
            ),
            "AF_SCALE_ERROR_A" | "AF_SCALE_ERROR_B" => {
                let axis = if f.name.ends_with('A') { a } else { b };
                match scale_terms(axis, 1.0) {
                    Some(t) => estimate(t, &format!("positional (scale) error of {axis}, degree 1")),
                    None => Ours::none("not in this machine's model"),
                }
            }
            "AF_GLOBAL_SCALE" | "AF_SCALE_MISMATCH" => {
                // ppm × R mm × 1e-3 = µm.
                let (fa, fb, what) = if f.name == "AF_GLOBAL_SCALE" {
                    (0.5 * r_mm * 1e-3, 0.5 * r_mm * 1e-3, format!("(s_{a} + s_{b})/2 · R"))
                } else {
                    (2.0 * r_mm * 1e-3, -2.0 * r_mm * 1e-3, format!("(s_{a} − s_{b}) · 2R"))
                };
                match (scale_terms(a, fa), scale_terms(b, fb)) {
                    (Some(mut x), Some(y)) => {
                        x.extend(y);
                        estimate(x, &format!("{what} from the fitted scale errors"))
                    }
                    _ => Ours::none("not in this machine's model"),
                }
            }
            "AF_SQUARENESS" => match row(&format!("squareness {plane}")) {
                Some(q) => estimate(q.terms.clone(), &format!("squareness {plane} of the fit (µrad = µm/m), jointly fitted with the model's other terms")),
                None => Ours::none("not in this machine's model"),
            },
            "AF_BACKLASH_A_GLOBAL" | "AF_BACKLASH_B_GLOBAL" => {
                let axis = if f.name.contains("_A_") { a } else { b };
                match row(&format!("backlash {axis}")) {
                    Some(q) => estimate(q.terms.clone(), &format!("backlash of {axis} (a step of B at each reversal of {axis})")),
                    None => Ours::none("not in this machine's model"),
                }
            }
            "AF_SERVO_MISMATCH" => servo_mismatch(model, a, b, plane, feed, &estimate),
            "AF_STRAIGHTNESS_A" | "AF_STRAIGHTNESS_B" => {
                // STRAIGHTNESS_A: the B error growing with A, ΔB = S (A/R)² (the bow over the
                // diameter), our "B straightness along A" at this R.
                let (along, toward) = if f.name.ends_with('A') { (a, b) } else { (b, a) };
                match row(&format!("{toward} straightness along {along} (bow over 2R)")) {
                    Some(q) => estimate(q.terms.clone(), &format!("{toward} straightness along {along}, Δ{toward} = S ({along}/R)² (the bow over the diameter)")),
                    None => Ours::none("not in this machine's model"),
                }
            }
            name if name.starts_with("AF_REVERSAL_SPIKES_") || name.starts_with("AF_CYCLIC_ERROR_") || name.starts_with("AF_LATERAL_PLAY_") => {
                match diagnosed_feature(name, a, b, diagnosed.diagnosis) {
                    Some(o) => o,
                    None => continue,
                }
            }
            "RMS" => {
                let base = rms_um(&fit.residuals, indices.clone());
                let note = match diagnosed.rms_after_um {
                    Some(after) => format!("readings minus our diagnosed model ({after:.2} µm; the base model leaves {base:.2} µm)"),
                    None => "readings minus our base model (diagnose adds the unmodelled effects)".to_string(),
                };
                Ours::exact(diagnosed.rms_after_um.unwrap_or(base), note)
            }
            _ => continue,
        };
        let mut ours = ours;
        if let Some(why) =
            spacing_note.as_ref().filter(|_| SPACING_SENSITIVE.contains(&f.name.as_str()))
        {
            ours.note.push_str(why);
        }
        push(&mut out, plane, f, ours, None);
    }
    ranking(&mut out, diag, plane, r_mm, feed, diagnosed.diagnosis.is_some());
    out
}

/// Our value of a vendor feature that the diagnosis gives (a reversal spike, a cyclic error, a
/// lateral play), from the diagnosis: `None` when the feature is not one of these.
fn diagnosed_feature(
    name: &str,
    a: Axis,
    b: Axis,
    diagnosis: Option<&doc::Diagnosis>,
) -> Option<Ours> {
    let rest = name.strip_prefix("AF_")?;
    let (kind, tail) = [
        ("REVERSAL_SPIKES_", "reversal_spike"),
        ("CYCLIC_ERROR_", "cyclic_error"),
        ("LATERAL_PLAY_", "lateral_play"),
    ]
    .into_iter()
    .find_map(|(p, k)| rest.strip_prefix(p).map(|t| (k, t)))?;
    let (axis, side) = match tail.split_once('_') {
        Some(("A", side)) => (a, side),
        Some(("B", side)) => (b, side),
        _ => return None,
    };
    if !matches!(side, "POS" | "NEG" | "FWD" | "REV" | "GLOBAL") {
        return None;
    }
    let Some(d) = diagnosis else {
        return Some(Ours::none(
            "diagnose finds the unmodelled effects (spikes, cyclic errors, lateral play); fit does not",
        ));
    };
    let named = d.effects.iter().flatten().find(|e| e.subject.is(kind, axis.name()));
    let Some(e) = named else {
        let declined = d.declined.iter().find(|e| e.subject.is(kind, axis.name()));
        return Some(Ours::none(match declined {
            Some(x) => format!(
                "not named: the diagnosis tried it and found it inside the noise ({})",
                why_text(&x.why)
            ),
            None => format!(
                "not named by the diagnosis: no {} of {axis} stands out of the noise",
                kind.replace('_', " ")
            ),
        }));
    };
    let num = |k: &str| e.parameters.get(k).copied();
    Some(match kind {
        "reversal_spike" => {
            let key = match side {
                "POS" => "amplitude_pos_um",
                "NEG" => "amplitude_neg_um",
                _ => "",
            };
            let u = e.std_uncertainties.get(key).copied();
            match num(key) {
                Some(v) => Ours {
                    value: Some(v),
                    u,
                    note: format!(
                        "height of our fitted spike after the reversal at the {} end of {axis}",
                        if side == "POS" { "positive" } else { "negative" }
                    ),
                },
                None => Ours {
                    value: num("amplitude_um"),
                    u: None,
                    note: format!(
                        "our spike of {axis}: one height for both reversals, decaying with τ = {:.0} ms (the vendor fits a triangle per reversal)",
                        num("tau_ms").unwrap_or(f64::NAN)
                    ),
                },
            }
        }
        "cyclic_error" => {
            // The vendor's figure is ≈ 2√2 × the amplitude C of ΔA = C sin(2πA/p + φ) on the
            // shared file (found empirically, 2.80-2.87; its definition is not published).
            let c = num("amplitude_um");
            Ours {
                value: c.map(|c| c * 2.0 * std::f64::consts::SQRT_2),
                u: None,
                note: format!(
                    "2√2 × our amplitude {:.2} µm at pitch {:.2} mm, one amplitude for both directions (the factor is empirical, from the shared real file)",
                    c.unwrap_or(f64::NAN),
                    num("pitch_mm").unwrap_or(f64::NAN)
                ),
            }
        }
        _ => Ours {
            value: num("play_um"),
            u: None,
            note: format!(
                "our lateral play of {axis} switched by the other axis's reversals, one value for both (not verified against the vendor: its sign, and whether its A/B names the axis that moves sideways or the one that reverses)"
            ),
        },
    })
}

/// The diagnosis's F statistic of an effect as text: `partial-F 4.2`, `partial-F 1.11e6` (the
/// added-variable F test of the effect's columns on all the data, noise-inflated; not ISO
/// 230-4's radial deviation F), three significant digits from 10,000 on.
pub fn partial_f_text(f: f64) -> String {
    format!("partial-F {}", stat_number(f))
}

/// A test statistic as text: one decimal below 10,000, three significant digits from there on
/// (`1.11e6`, not a seven-digit number that reads like a measurement).
pub fn stat_number(x: f64) -> String {
    if x.abs() >= 1e4 { format!("{x:.2e}") } else { format!("{x:.1}") }
}

/// The unit suffixes of the diagnosis's parameter keys (`amplitude_um`), longest first.
const KEY_UNITS: [(&str, &str); 13] = [
    ("_mm_per_min", "mm/min"),
    ("_ppm_per_h", "ppm/h"),
    ("_um_per_h", "µm/h"),
    ("_urad", "µrad"),
    ("_ms2", "ms²"),
    ("_ppm", "ppm"),
    ("_deg", "°"),
    ("_min", "min"),
    ("_um", "µm"),
    ("_ms", "ms"),
    ("_mm", "mm"),
    ("_hz", "Hz"),
    ("_s", "s"),
];

/// An effect's parameter (a key of the diagnosis JSON's `parameters`) as an engineer reads it:
/// its name in words, the value (± its standard uncertainty `u` where there is one, to two
/// significant digits) and the unit from the key's suffix: `amplitude_um` 5.8 →
/// `amplitude 5.800 µm`, `tau_ms` → `decay τ 61.000 ms`, `value_um` → `9.806 ± 0.011 µm`.
pub fn parameter_text(key: &str, value: f64, u: Option<f64>) -> String {
    let (stem, unit) = KEY_UNITS
        .iter()
        .find_map(|(suffix, unit)| key.strip_suffix(suffix).map(|s| (s, *unit)))
        .unwrap_or((key, ""));
    let name = match stem {
        "value" => String::new(),
        "amplitude_pos" => "amplitude after the reversal at the positive end".into(),
        "amplitude_neg" => "amplitude after the reversal at the negative end".into(),
        "tau" => "decay τ".into(),
        "peak" => "peak after the reversal at".into(),
        "period" => "ringing period".into(),
        "lag_squared" => "lag²".into(),
        "reference_feed" => "at the feed".into(),
        "speed" => "below the speed".into(),
        other => other.replace('_', " "),
    };
    let (v, u) = match u.filter(|u| u.is_finite()) {
        Some(u) => {
            let (v, u) = crate::fit_report::value_and_u(value, u, 3);
            (v, format!(" ± {u}"))
        }
        None => (format!("{value:.3}"), String::new()),
    };
    let sep = if name.is_empty() { "" } else { " " };
    let space = if unit.is_empty() || unit == "°" { "" } else { " " };
    format!("{name}{sep}{v}{u}{space}{unit}")
}

/// A declined candidate's reason, from the diagnosis (its `why`).
pub(crate) fn why_text(why: &Why) -> String {
    let folds = |f: &str| f.replace('_', " ");
    match why {
        Why::F { f_statistic, needed } => format!(
            "{} below {needed:.1} (its 1e-6 false-alarm level)",
            partial_f_text(*f_statistic)
        ),
        Why::HeldOut { held_out_t, needed, folds: f, .. } => format!(
            "held-out ({}) gain {held_out_t:.1} standard errors from zero, below {needed}",
            folds(f)
        ),
        Why::Material { share_of_excess, needed, folds: f, .. } => format!(
            "held-out ({}) real but minor: closes {:.0} % of what is left above the noise (at least {:.0} % to be named)",
            folds(f),
            100.0 * share_of_excess,
            100.0 * needed
        ),
        Why::Judgeable { folds_tried } => {
            let tried: Vec<String> = folds_tried.iter().map(|k| folds(k)).collect();
            format!(
                "no held-out folds can determine it (tried: {})",
                if tried.is_empty() { "none".into() } else { tried.join(", ") }
            )
        }
        Why::Redundant { held_out_t, needed } => format!(
            "accepted, then made redundant by the others (held-out gain {held_out_t:.1} standard errors from zero, below {needed})"
        ),
        Why::Rank => "it adds nothing to the accepted effects".into(),
        Why::Limit => "the limit on the number of effects".into(),
        Why::NotRecorded => "not recorded".into(),
    }
}

/// The vendor's ranking (`<ERROR>_IC`, `_PERC`, `_RANK`) with ours beside it: our value of the
/// same error's impact on circularity, by the vendor's own definitions (worked out on the
/// shared real file, where 12 of 13 match to its 0.1 µm): squareness |α|·R, scale mismatch M/2,
/// straightness S/2, servo mismatch V·|Δτ|, backlash |B|, spikes and cyclic errors and lateral
/// play as their values above (the largest side); the share is our impact over the sum of ours.
/// An error we have no value of (a spike under `fit`) is left out of our ranking, not ranked 0;
/// under `diagnose`, an effect it does not name is inside the noise: 0.
fn ranking(
    out: &mut Vec<Entry>,
    diag: &ballbar_io::b5r::VendorAnalysis,
    plane: Plane,
    r_mm: f64,
    feed: f64,
    diagnosed: bool,
) {
    let errors: Vec<&str> =
        diag.features.iter().filter_map(|f| f.name.strip_suffix("_IC")).collect();
    if errors.is_empty() {
        return;
    }
    let ours_of = |feature: &str| {
        out.iter().find(|e| e.feature == feature && e.run.is_none()).and_then(|e| e.ours)
    };
    let largest =
        |names: &[String]| names.iter().filter_map(|n| ours_of(n)).map(f64::abs).reduce(f64::max);
    let impact = |error: &str| -> Option<f64> {
        let e = error.strip_prefix("AF_")?;
        let sides = |base: &str| {
            ["POS", "NEG", "FWD", "REV", "GLOBAL"].map(|s| format!("AF_{base}_{s}")).to_vec()
        };
        Some(match e {
            "SQUARENESS" => ours_of("AF_SQUARENESS")?.abs() * r_mm * 1e-3,
            "SCALE_MISMATCH" => ours_of("AF_SCALE_MISMATCH")?.abs() / 2.0,
            "STRAIGHTNESS_A" | "STRAIGHTNESS_B" => ours_of(error)?.abs() / 2.0,
            // V·|Δτ|: mm/s × ms = µm.
            "SERVO_MISMATCH" => ours_of("AF_SERVO_MISMATCH")?.abs() * feed / 60.0,
            _ => {
                let base = [
                    "BACKLASH_A",
                    "BACKLASH_B",
                    "REVERSAL_SPIKES_A",
                    "REVERSAL_SPIKES_B",
                    "CYCLIC_ERROR_A",
                    "CYCLIC_ERROR_B",
                    "LATERAL_PLAY_A",
                    "LATERAL_PLAY_B",
                ]
                .into_iter()
                .find(|b| *b == e)?;
                // The diagnosis tried every such effect: one it does not name is inside the noise.
                match largest(&sides(base)) {
                    Some(v) => v,
                    None if diagnosed => 0.0,
                    None => return None,
                }
            }
        })
    };
    let ours: Vec<(String, Option<f64>)> =
        errors.iter().map(|e| (e.to_string(), impact(e))).collect();
    let total: f64 = ours.iter().filter_map(|(_, v)| *v).sum();
    let mut order: Vec<&(String, Option<f64>)> = ours.iter().filter(|(_, v)| v.is_some()).collect();
    order.sort_by(|x, y| y.1.unwrap_or(0.0).total_cmp(&x.1.unwrap_or(0.0)));
    for (error, value) in &ours {
        let rank = order.iter().position(|(e, _)| e == error).map(|k| (k + 1) as f64);
        let share = value.filter(|_| total > 0.0).map(|v| 100.0 * v / total);
        for (suffix, ours, note) in [
            ("_IC", *value, "our impact on circularity, by the vendor's definition for this error"),
            ("_PERC", share, "our impact's share of the sum of ours"),
            ("_RANK", rank, "our rank by impact"),
        ] {
            if let Some(f) = diag.feature(&format!("{error}{suffix}")) {
                let why = "we have no value of this error (diagnose evaluates spikes, cyclic errors and lateral play); left out of our ranking";
                let ours = Ours {
                    value: ours,
                    u: None,
                    note: if ours.is_some() { note.to_string() } else { why.to_string() },
                };
                push(out, plane, f, ours, None);
            }
        }
    }
}

/// The features that the placement of the samples on the circle moves (2θ and scale terms).
const SPACING_SENSITIVE: [&str; 7] = [
    "AF_SQUARENESS",
    "AF_SCALE_ERROR_A",
    "AF_SCALE_ERROR_B",
    "AF_GLOBAL_SCALE",
    "AF_SCALE_MISMATCH",
    "AF_STRAIGHTNESS_A",
    "AF_STRAIGHTNESS_B",
];

/// The servo mismatch τ_A − τ_B in ms, from the model's servo terms.
fn servo_mismatch(
    model: &Model,
    a: Axis,
    b: Axis,
    plane: Plane,
    feed: f64,
    estimate: &dyn Fn(Vec<(String, f64)>, &str) -> Ours,
) -> Ours {
    let ids: Vec<String> = model.parameters().iter().map(|p| p.id.clone()).collect();
    let has = |id: &str| ids.iter().any(|i| i == id);
    match model.options.servo {
        ServoVariant::AxisLag => {
            let (ta, tb) = (format!("T{a}"), format!("T{b}"));
            if has(&ta) && has(&tb) {
                estimate(
                    vec![(ta, 1e3), (tb, -1e3)],
                    &format!("lag of {a} minus lag of {b} (per-axis servo lags)"),
                )
            } else {
                Ours::none("not in this machine's model")
            }
        }
        ServoVariant::PlaneMismatch => {
            let id = format!("M{plane}");
            if !has(&id) {
                return Ours::none("not in this machine's model");
            }
            // M = V (τ_V − τ_U), so τ_A − τ_B = −M/V when A is the plane's U, +M/V when it is V.
            let (u, _, _) = plane.axes().expect("planar");
            let v_mm_per_s = feed / 60.0;
            let sign = if a == u { -1.0 } else { 1.0 };
            estimate(
                vec![(id, sign * 1e3 / v_mm_per_s)],
                "the paper's plane mismatch M as a lag difference: ∓M/V",
            )
        }
    }
}

/// Add a feature. A length is compared in µm whatever unit the file gives it in (`DT`, read per
/// value: the per-run features are in mm), a radius in mm: ours are in those units.
fn push(out: &mut Vec<Entry>, plane: Plane, f: &VendorFeature, ours: Ours, run: Option<String>) {
    let (vendor, unit) = match f.um() {
        Some(um) if f.name == "AF_BEST_RADIUS" => (um * 1e-3, "mm"),
        Some(um) => (um, "µm"),
        None => (f.value, f.unit.symbol()),
    };
    out.push(Entry {
        plane,
        feature: f.name.clone(),
        unit,
        vendor,
        vendor_valid: f.valid,
        ours: ours.value,
        ours_u: ours.u,
        run,
        note: ours.note,
    });
}

fn mean(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Option<Vec<f64>> = values.collect();
    v.filter(|v| !v.is_empty()).map(|v| v.iter().sum::<f64>() / v.len() as f64)
}

/// RMS of residuals over the runs `indices`, µm.
pub fn rms_um(residuals: &[Vec<f64>], indices: std::ops::Range<usize>) -> f64 {
    metrics::rms(&residuals[indices].concat()) * 1e3
}

/// The angle of each sample in the vendor's frame (from +A towards +B), from the run's
/// coordinates. `None` for a run without those axes.
fn run_angles(run: &Run, a: Axis, b: Axis) -> Option<Vec<f64>> {
    let (xa, xb) = (run.axis(a)?, run.axis(b)?);
    let (pa, pb) = (run.header.pivot_mm[a.index()], run.header.pivot_mm[b.index()]);
    Some(xa.iter().zip(xb).map(|(x, y)| (y - pb).atan2(x - pa)).collect())
}

/// The comparison as `vendor_comparison` entries (cli.md), with our note. A value that is not
/// a number is left out (`null`), as the document would read it back.
pub fn document(entries: &[Entry]) -> Vec<VendorEntry> {
    entries
        .iter()
        .map(|e| VendorEntry {
            plane: e.plane.name().into(),
            feature: e.feature.clone(),
            unit: e.unit.into(),
            vendor: e.vendor,
            ours: e.ours.filter(|v| v.is_finite()),
            ours_u: e.ours_u.filter(|u| u.is_finite()),
            vendor_valid: e.vendor_valid,
            note: e.note.clone(),
            run: e.run.clone(),
        })
        .collect()
}

/// Decimals to show a value in `unit`: a radius in mm to 0.1 µm, the rest to 0.01.
pub fn decimals(unit: &str) -> usize {
    if unit == "mm" { 4 } else { 2 }
}

/// The comparison as a terminal table.
pub fn terminal(file: &str, entries: &[Entry]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\nThe vendor's analysis in {file} beside ours (vendor's units and signs; u: our standard uncertainty)"
    );
    let width = entries
        .iter()
        .map(|e| e.run.as_ref().map_or(0, |r| r.chars().count()))
        .max()
        .unwrap_or(0)
        .clamp(3, crate::fit_report::NAME_COLUMN_CHARS);
    let _ = writeln!(
        s,
        "  {:<22} {:<width$} {:>10} {:>10} {:>7}  {:<6}  ours is",
        "feature", "run", "vendor", "ours", "u", "unit"
    );
    for e in entries {
        let d = decimals(e.unit);
        let vendor = if e.vendor_valid {
            format!("{:.d$}", e.vendor)
        } else {
            format!("({:.d$})", e.vendor)
        };
        let ours = e.ours.map_or("—".into(), |v| format!("{v:.d$}"));
        // u to two significant digits (a small u never reads 0.00).
        let u = e.ours_u.map_or(String::new(), |u| crate::fit_report::value_and_u(0.0, u, d).1);
        let run = crate::fit_report::clipped(e.run.as_deref().unwrap_or(""), width);
        let _ = writeln!(
            s,
            "  {:<22} {run:<width$} {vendor:>10} {ours:>10} {u:>7}  {:<6}  {}",
            e.feature, e.unit, e.note
        );
    }
    if entries.iter().any(|e| !e.vendor_valid) {
        let _ = writeln!(s, "  (values in brackets: the vendor marks them not valid)");
    }
    s
}

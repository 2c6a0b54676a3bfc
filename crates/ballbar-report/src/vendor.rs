//! Our values beside the vendor's own analysis of a `.b5r` file (`vendor_comparison` in
//! `shared/spec/cli.md`), feature by feature, in the vendor's units and sign conventions.
//!
//! # The mapping (vendor feature ← our quantity), plane (A, B) as the file names it
//! - `AF_SCALE_ERROR_A/B` (ppm) ← the local scale of axis A / B at the circle's centre
//!   (`ballbar_fit::local`: the slope of the fitted field there, what a one-plane test
//!   determines whatever pivot and tool length are given; at the default pivot it is the
//!   positional error's degree-1 term, with a pivot or a tool length given the global terms may
//!   move along an alias, which the fit reports, while this does not).
//! - `AF_GLOBAL_SCALE` (µm) ← (s_A + s_B)/2 · R, the mean radial deviation the scales make.
//! - `AF_SCALE_MISMATCH` (µm) ← (s_A − s_B) · 2R, their difference over the diameter.
//!   (These three verified on the shared real file: 40.4 and 10.3 ppm give 1.3 and 3.0 µm.)
//! - `AF_SQUARENESS` (µm/m) ← the local squareness α of the plane at the circle's centre
//!   (µrad), same sign: the vendor's value is −2 × the sin 2θ coefficient of the CW/CCW mean
//!   profile over R, and our α makes ΔR = −α R sin θ cos θ in either orientation of the
//!   plane's axes.
//! - `AF_BACKLASH_{A,B}_GLOBAL` (µm) ← our backlash B of the axis, same sign (the shared file:
//!   −0.88 / 0.34 against the vendor's −0.9 / 0.3).
//! - `AF_SERVO_MISMATCH` (ms) ← τ_A − τ_B, the lag of A minus the lag of B. The sign is the
//!   opposite of the paper's plane term `M/V` (M = V (τ_V − τ_U)); it rests on one other
//!   vendor file (ours +0.06 ms with the paper's sign against the vendor's −0.05 ms): the
//!   shared file's mismatch is 0.00 ms and cannot confirm it.
//! - `AF_CENTRE_OFFSET_A/B` (µm), `AF_BEST_RADIUS` (mm): the circle of the readings fitted
//!   jointly with the vendor's common terms ([`crate::vendor_fit`]), on our placement of the
//!   samples (on a partial arc a plain circle takes the 2θ and 3θ terms into its centre); the
//!   per-run `AF_CIRCULARITY` (µm): the vendor's definition (ISO 230-4 circular deviation about
//!   the least-squares circle) on the vendor's own angles of the samples
//!   ([`B5rTest::vendor_angles_deg`]). They check the reading of the file, not the model.
//! - `AF_STRAIGHTNESS_A` (µm) ← S of ΔB = S (A/R)², our "B straightness along A" at this R
//!   (and B likewise): the vendor's 4 × the sin 3θ (−4 × cos 3θ for B) coefficient.
//! - `AF_REVERSAL_SPIKES_*`, `AF_CYCLIC_ERROR_*`, `AF_LATERAL_PLAY_*` ← the effects the diagnosis
//!   names (POS: the reversal at the axis's positive end, NEG the negative; FWD: the axis moving
//!   positive), with what differs in the definitions said; where the diagnosis names none, why.
//! - `<ERROR>_IC`, `_PERC`, `_RANK`: our impact of the same error by the vendor's definitions
//!   ([`crate::vendor_rank`], which says which were verified on the shared file), its share
//!   and rank among ours (`ranking`); in the vendor's conventions, the same formulas on our
//!   values in its conventions where every input has one.
//! - `RMS` (µm): the readings minus the vendor's model against the readings minus ours.
//!
//! # Three values per feature
//! - `ours_as_vendor`: the vendor's computation done here ([`crate::vendor_fit`]: its even
//!   spread of the samples over the arc, its term set for full circles and partial arcs, the
//!   exact eccentric circle, its centre from that joint fit; the circularity by its ISO 230-4
//!   definition on its angles). It is given wherever it is computed, whether or not it
//!   reproduces the vendor's printed value: where it is further from it than half the printed
//!   step ([`printed_step`]) the note says "not reproduced", with both numbers and what is known
//!   of why; where it is not computed (`None`) the note says why. On the shared real file it
//!   reproduces the centre, radius, circularities, global scale, A straightness, backlash and
//!   servo mismatch; not the squareness (−9.95 against −10.3), the scales (41.0 and 9.9
//!   against 40.4 and 10.3 ppm), the mismatch (3.11 against 3.0) and the B straightness (1.06
//!   against 1.0): its fit of them is not an ordinary least squares of the readings
//!   ([`crate::vendor_fit`] gives the evidence). The reversal spikes are computed by
//!   [`crate::vendor_spikes`] on any arc and direction, a rule inferred from the vendor's model
//!   trace of the shared file with its local baseline chosen on that file: B's come within half
//!   the printed step of the shared file's (3.19 and 2.73 against 3.2 and 2.7), although the
//!   same rule gives 3.12 and 2.62 on the vendor's own trace, so it is not the vendor's rule
//!   exactly; A's do not. Lateral play, cyclic error and RMS
//!   are not reproduced ([`crate::vendor_fit`] says what was tried): for a full circle in both
//!   directions those drive features are computed by [`vendor_fit::decompose`] (the term set
//!   with lateral play, cyclic error at the file's pitches and free-form columns
//!   [`DRIVE_WINDOW`] samples either side of each reversal) from the readings, given as
//!   `ours_as_vendor`, and from the vendor's own model trace, whose residual away from the
//!   reversals the note gives; none reproduces the vendor's on the shared file. Of the
//!   ranking, the impacts of the errors whose inputs have a value in its conventions, and the
//!   shares and ranks where every ranked error's impact has one.
//! - `ours`, `ours_u`: our best value, the model fit's, in one place per feature (the arms of
//!   `compare`'s match); u adds, in quadrature, half the range between the model forms the
//!   data cannot choose between: the two placements of the samples, unless the trace's own
//!   timing ([`ballbar_io::b5r::feed_factor`]) confirms the programmed feed and rejects the
//!   even spread (then the note gives the evidence and u holds no placement spread), and on a
//!   partial arc the term sets (per-axis or common scale, with or without the 3θ term) that
//!   the readings do not refuse against the richest ([`vendor_fit::VendorFit::rejects`]: a
//!   form whose added residual is beyond χ²'s 1e-3 quantile is named in the note, not
//!   counted; on a 220° arc with 0.15 µm of noise and distinct scales, counting every form
//!   made the squareness's u 6.6 µm/m where the fit's is 0.6).
//! - `why`: where |ours − vendor| > [`allowed`], the gap split by convention, each piece
//!   recomputed from the file's readings with one convention changed at a time: our model
//!   against the vendor's term set (both on our placement), our placement against the vendor's
//!   (both in its term set), and what is left between the vendor's figure and ours in its
//!   conventions; largest first.

use std::fmt::Write as _;

use ballbar_fit::local::{LocalQuantity, local_quantities};
use ballbar_fit::{Fit, metrics, quantity};

use crate::vendor_fit::{self, Decomposition, Samples, TermSet, VendorFit};
use crate::vendor_rank;
use crate::vendor_spikes;
use ballbar_io::b5r::{B5rTest, VendorFeature};

use ballbar_documents::VendorEntry;
use ballbar_documents::diagnosis::{self as doc, Why};
use ballbar_model::local::LocalKind;
use ballbar_model::machine::{Model, ServoVariant};
use ballbar_model::{Axis, Design, Plane, Run, paper};

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
    /// Our computation in the vendor's conventions ([`crate::vendor_fit`]), whether or not it
    /// reproduces the vendor's value (the note says where not); `None` where we do not compute
    /// the feature in its conventions (the note says why).
    pub ours_as_vendor: Option<f64>,
    /// Our best value in the vendor's unit and sign; `None` where we have none.
    pub ours: Option<f64>,
    /// Its standard uncertainty, where there is one, with the spread between the model forms
    /// the data cannot choose between.
    pub ours_u: Option<f64>,
    /// The run, for per-run features.
    pub run: Option<String>,
    /// Where our value comes from, or why we have none or disagree.
    pub note: String,
    /// Why ours and the vendor's differ, where they differ by more than [`allowed`].
    pub why: Option<String>,
}

/// Our side of one feature.
struct Ours {
    value: Option<f64>,
    u: Option<f64>,
    note: String,
    as_vendor: Option<f64>,
}

impl Ours {
    fn none(note: impl Into<String>) -> Ours {
        Ours { value: None, u: None, note: note.into(), as_vendor: None }
    }
    fn exact(value: f64, note: impl Into<String>) -> Ours {
        Ours { value: Some(value), u: None, note: note.into(), as_vendor: None }
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
    let arc_deg = first
        .header
        .extra
        .iter()
        .find(|(k, _)| k == "arc_deg")
        .and_then(|(_, v)| v.parse::<f64>().ok())
        .unwrap_or(360.0);
    let conv = Conventions::of(test, file_runs, r_mm, feed, arc_deg);

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
            let mut ours = Ours::exact(
                g,
                "ISO 230-4 circular deviation of the readings about their least-squares circle (the vendor's definition, the same readings)",
            );
            // On the vendor's angles, this is its computation too.
            if conv.is_some() {
                ours.as_vendor = Some(g);
            }
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
                as_vendor: None,
            },
            Some(_) => {
                Ours::none("not identifiable from these tests (see the fit's identifiability)")
            }
            None => Ours::none("not in this machine's model"),
        }
    };
    // What this file's test determines where it is: the local scales and squareness of the
    // fitted field at the circle's centre (they do not move with the pivot or tool length given,
    // where the machine's global terms may: `ballbar_fit::alias`).
    let locals: Vec<LocalQuantity> = Design::new(model, runs)
        .ok()
        .and_then(|d| local_quantities(&d, fit).ok())
        .unwrap_or_default()
        .into_iter()
        .filter(|q| q.plane == plane && q.runs.iter().all(|r| indices.contains(r)))
        .collect();
    let (u_axis, _, _) = plane.axes().unwrap_or((a, b, a));
    let axis_kind = |axis: Axis| if axis == u_axis { LocalKind::ScaleU } else { LocalKind::ScaleV };
    // A combination Σ w_k q_k of this test's local quantities: its value from their values
    // (the exact field's), its u from the fit's covariance of the combined functional.
    let local_value = |parts: &[(LocalKind, f64)], note: &str| -> Ours {
        let found: Option<Vec<(&LocalQuantity, f64)>> = parts
            .iter()
            .map(|(k, w)| locals.iter().find(|q| q.kind == *k).map(|q| (q, *w)))
            .collect();
        let Some(found) = found.filter(|f| !f.is_empty()) else {
            return Ours::none("no planar test of this file in the fit");
        };
        if found.iter().any(|(q, _)| !q.estimate.estimable) {
            return Ours::none("not identifiable from these tests (see the fit's identifiability)");
        }
        let value: f64 = found.iter().map(|(q, w)| w * q.estimate.value).sum();
        let mut coeffs: Vec<(usize, f64)> = Vec::new();
        for (q, w) in &found {
            for &(j, c) in &q.coefficients {
                match coeffs.iter_mut().find(|(i, _)| *i == j) {
                    Some(e) => e.1 += w * c,
                    None => coeffs.push((j, w * c)),
                }
            }
        }
        Ours {
            value: Some(value),
            u: Some(fit.functional(&coeffs).std_uncertainty),
            note: note.into(),
            as_vendor: None,
        }
    };
    let Some(diag) = test.diagnostics() else {
        finish(&mut out, conv.as_ref());
        return out;
    };
    for f in &diag.features {
        let ours = match f.name.as_str() {
            // The set-up: the joint fit of the readings (circle and the common terms, which a
            // plain circle on a partial arc would take into its centre) on our placement of
            // the samples; a plain circle where the vendor's conventions cannot be applied.
            "AF_CENTRE_OFFSET_A" | "AF_CENTRE_OFFSET_B" | "AF_BEST_RADIUS" => {
                match conv.as_ref().and_then(|c| fit_value(c.own(), &f.name)) {
                    Some(v) => Ours::exact(
                        v,
                        "the circle of the readings fitted jointly with the vendor's common terms, on our placement of the samples, mean of the runs",
                    ),
                    None => {
                        let k = match f.name.as_str() {
                            "AF_CENTRE_OFFSET_A" => 1,
                            "AF_CENTRE_OFFSET_B" => 2,
                            _ => 0,
                        };
                        let at = |c: [f64; 3]| if k == 0 { r_mm + c[0] } else { c[k] * 1e3 };
                        mean(circles.iter().map(|c| c.map(at))).map_or_else(
                            || Ours::none("a run is not a planar circle"),
                            |v| {
                                Ours::exact(
                                    v,
                                    "least-squares circle of the readings, mean of the runs",
                                )
                            },
                        )
                    }
                }
            }
            "AF_SCALE_ERROR_A" | "AF_SCALE_ERROR_B" => {
                let axis = if f.name.ends_with('A') { a } else { b };
                // ppm: the local scale is a ratio.
                local_value(
                    &[(axis_kind(axis), 1e6)],
                    &format!(
                        "local scale of {axis}: the slope of {axis}'s error along {axis} at the circle's centre (what this test determines, whatever pivot and tool length are given)"
                    ),
                )
            }
            "AF_GLOBAL_SCALE" | "AF_SCALE_MISMATCH" => {
                // ppm × R mm × 1e-3 = µm: a ratio × R mm × 1e3 = µm.
                let (fa, fb, what) = if f.name == "AF_GLOBAL_SCALE" {
                    (0.5 * r_mm * 1e3, 0.5 * r_mm * 1e3, format!("(s_{a} + s_{b})/2 · R"))
                } else {
                    (2.0 * r_mm * 1e3, -2.0 * r_mm * 1e3, format!("(s_{a} − s_{b}) · 2R"))
                };
                local_value(
                    &[(axis_kind(a), fa), (axis_kind(b), fb)],
                    &format!("{what} from the local scales at the circle's centre"),
                )
            }
            "AF_SQUARENESS" => local_value(
                &[(LocalKind::Squareness, 1e6)],
                &format!(
                    "local squareness {plane} at the circle's centre (µrad = µm/m; what this test determines, whatever pivot and tool length are given: the machine's squareness of the fit may differ where a straightness's slope at this place is in it)"
                ),
            ),
            "AF_BACKLASH_A_GLOBAL" | "AF_BACKLASH_B_GLOBAL" => {
                let axis = if f.name.contains("_A_") { a } else { b };
                match row(&format!("backlash {axis}")) {
                    Some(q) => estimate(
                        q.terms.clone(),
                        &format!("backlash of {axis} (a step of B at each reversal of {axis})"),
                    ),
                    None => Ours::none("not in this machine's model"),
                }
            }
            "AF_SERVO_MISMATCH" => servo_mismatch(model, a, b, plane, feed, &estimate),
            "AF_STRAIGHTNESS_A" | "AF_STRAIGHTNESS_B" => {
                // STRAIGHTNESS_A: the B error growing with A, ΔB = S (A/R)² (the bow over the
                // diameter), our "B straightness along A" at this R.
                let (along, toward) = if f.name.ends_with('A') { (a, b) } else { (b, a) };
                match row(&format!("{toward} straightness along {along} (bow over 2R)")) {
                    Some(q) => estimate(
                        q.terms.clone(),
                        &format!(
                            "{toward} straightness along {along}, Δ{toward} = S ({along}/R)² (the bow over the diameter)"
                        ),
                    ),
                    None => Ours::none("not in this machine's model"),
                }
            }
            name if name.starts_with("AF_REVERSAL_SPIKES_")
                || name.starts_with("AF_CYCLIC_ERROR_")
                || name.starts_with("AF_LATERAL_PLAY_") =>
            {
                match diagnosed_feature(name, a, b, diagnosed.diagnosis) {
                    Some(o) => o,
                    None => continue,
                }
            }
            "RMS" => {
                let base = rms_um(&fit.residuals, indices.clone());
                let note = match diagnosed.rms_after_um {
                    Some(after) => format!(
                        "readings minus our diagnosed model ({after:.2} µm; the base model leaves {base:.2} µm)"
                    ),
                    None => "readings minus our base model (diagnose adds the unmodelled effects)"
                        .to_string(),
                };
                Ours::exact(diagnosed.rms_after_um.unwrap_or(base), note)
            }
            _ => continue,
        };
        let mut ours = ours;
        in_vendor_conventions(&mut ours, &f.name, conv.as_ref());
        push(&mut out, plane, f, ours, None);
    }
    ranking(&mut out, diag, plane, r_mm, feed, diagnosed.diagnosis.is_some());
    finish(&mut out, conv.as_ref());
    out
}

/// What every entry gets once all are made: `why`, and the note's word on whether
/// `ours_as_vendor` reproduces the vendor.
fn finish(out: &mut [Entry], conv: Option<&Conventions>) {
    for e in out {
        e.why = why(e, conv);
        say_if_not_reproduced(e, conv);
    }
}

/// `ours_as_vendor` is our computation in the vendor's conventions whether or not it
/// reproduces the vendor's printed value (the spec: where it does not, that is a defect of
/// ours, shown, not hidden). Where it is further from the vendor's value than half its printed
/// step (the vendor's rounding; [`printed_step`]) the note says "not reproduced", with both
/// values and what is known of why.
fn say_if_not_reproduced(e: &mut Entry, conv: Option<&Conventions>) {
    let Some(v) = e.ours_as_vendor else { return };
    // Half the step, and a part in 1e9 of it for the decimal value's binary rounding.
    let h = printed_step(e.unit) / 2.0 * (1.0 + 1e-9);
    if (v - e.vendor).abs() <= h {
        if let Some(t) = conv.and_then(|c| drive_text(c, &e.feature, e.vendor)) {
            let _ = write!(e.note, "; as vendor: {t}");
        }
        return;
    }
    let d = decimals(e.unit);
    if let Some(t) = conv.and_then(|c| drive_text(c, &e.feature, e.vendor)) {
        let _ = write!(
            e.note,
            "; in the vendor's conventions as computed here {v:.d$}, not its {:.d$} within half its printed step: not reproduced: {t}",
            e.vendor
        );
        return;
    }
    if ["_IC", "_PERC", "_RANK"].iter().any(|s| e.feature.ends_with(s)) {
        let _ = write!(
            e.note,
            "; in the vendor's conventions as reproduced here {v:.d$}, not its {:.d$} within half its printed step: not reproduced: an input's value in its conventions is not the vendor's (see its row)",
            e.vendor
        );
        return;
    }
    let terms = conv.map_or(String::new(), |c| {
        format!(" ({})", TermSet::vendor((c.arc_deg - 360.0).abs() < 1e-9).describe())
    });
    let _ = write!(
        e.note,
        "; in the vendor's conventions as reproduced here (its placement, its term set{terms}, the exact eccentric circle) {v:.d$}, not its {:.d$} within half its printed step: not reproduced: on the shared real file the vendor's own model trace has its squareness in this term set, but its fit of the readings is not an ordinary least squares of them (how it weights or selects the samples is not known)",
        e.vendor
    );
}

/// `ours_as_vendor` of a feature, and what the model forms the data cannot choose between add
/// to our uncertainty.
fn in_vendor_conventions(ours: &mut Ours, name: &str, conv: Option<&Conventions>) {
    let Some(c) = conv.filter(|_| ours.as_vendor.is_none()) else {
        if ours.as_vendor.is_none() {
            let _ = write!(ours.note, "; {}", not_reproduced(name, conv));
        }
        return;
    };
    ours.as_vendor = fit_value(&c.vendor, name);
    if let Some((axis, pos)) = spike_of(name) {
        // Said by `say_if_not_reproduced`, with `drive_text`.
        match vendor_spikes::feature(c.spikes.as_deref().unwrap_or_default(), axis, pos) {
            Some((v, _)) => ours.as_vendor = Some(v),
            None => {
                let _ = write!(ours.note, "; {}", not_reproduced(name, conv));
            }
        }
        return;
    }
    if ours.as_vendor.is_none() {
        if let Some(v) = c.drives.as_ref().and_then(|d| drive_value(&d.readings, name)) {
            // Said by `say_if_not_reproduced`, with `drive_text`.
            ours.as_vendor = Some(v);
            return;
        }
        let _ = write!(ours.note, "; {}", not_reproduced(name, conv));
        return;
    }
    let _ = write!(
        ours.note,
        "; as vendor: its placement and term set ({}), the exact eccentric circle: rank {} of {}, condition {:.1}",
        TermSet::vendor((c.arc_deg - 360.0).abs() < 1e-9).describe(),
        c.vendor.rank,
        c.vendor.columns,
        c.vendor.condition
    );
    let Some(u) = ours.u else { return };
    let mut spread: Vec<(f64, String)> = Vec::new();
    // The placement: two defensible forms, unless the trace's timing chooses.
    if let (Some(v), Some(f)) = (fit_value(&c.vendor, name), fit_value(&c.feed, name)) {
        let half = (v - f).abs() / 2.0;
        let read_as = if c.runs_by_feed { "the programmed feed" } else { "the even spread" };
        if let Some(chosen) = c.timing_chooses().filter(|&chosen| chosen != read_as) {
            // The runs were read with the placement the data reject (`--b5r-angles vendor` on
            // a file whose trace times the programmed feed): ours holds for it, and says so.
            let there = if c.runs_by_feed { v } else { f };
            let _ = write!(
                ours.note,
                "; placement: these runs were read with {read_as}, as asked, which the data reject ({}): ours holds for it; on {chosen} this is {there:.2} in the vendor's conventions (without --b5r-angles, ours is computed there)",
                c.timing_text()
            );
        } else if let Some(chosen) = c.timing_chooses() {
            let _ = write!(
                ours.note,
                "; placement: the vendor's even spread gives {v:.2} in its conventions, the programmed feed's {f:.2}; {}: the data choose {chosen}, so u holds no placement spread (--b5r-angles vendor reads with the vendor's)",
                c.timing_text()
            );
        } else if half > 0.0 {
            // Two equally defensible forms: a two-point distribution's standard deviation is
            // half their distance.
            spread.push((
                half,
                format!(
                    "placement ({v:.2} spread evenly, {f:.2} at the programmed feed; {})",
                    c.timing_text()
                ),
            ));
        }
    }
    // The term set on a partial arc: the range of its forms that the readings do not refuse
    // against the richest (`VendorFit::rejects`), half of it as a standard uncertainty (the
    // same reasoning: any of them may hold). A form the readings refuse is named, not counted.
    let richest = c.term_sets.iter().max_by_key(|(_, f)| f.columns).map(|(_, f)| f);
    let mut refused = Vec::new();
    let values: Vec<(TermSet, f64)> = c
        .term_sets
        .iter()
        .filter(|(t, f)| match richest.and_then(|r| f.rejects(r)) {
            Some((true, chi2)) => {
                refused.push(format!("{} (Δχ² {chi2:.0})", t.describe()));
                false
            }
            _ => true,
        })
        .filter_map(|(t, f)| fit_value(f, name).map(|v| (*t, v)))
        .collect();
    let refused = if refused.is_empty() {
        String::new()
    } else {
        format!("; the readings refuse {}", refused.join(", "))
    };
    if values.len() > 1 {
        let lo = values.iter().map(|v| v.1).fold(f64::INFINITY, f64::min);
        let hi = values.iter().map(|v| v.1).fold(f64::NEG_INFINITY, f64::max);
        let forms: Vec<String> =
            values.iter().map(|(t, v)| format!("{v:.2} with {}", t.describe())).collect();
        spread.push((
            (hi - lo) / 2.0,
            format!("the partial arc's term sets ({}{refused})", forms.join("; ")),
        ));
    } else if !refused.is_empty() {
        let _ = write!(
            ours.note,
            "; of the partial arc's term sets{refused}: u holds no term-set spread"
        );
    }
    if spread.is_empty() {
        return;
    }
    let total = (u * u + spread.iter().map(|s| s.0 * s.0).sum::<f64>()).sqrt();
    let words: Vec<String> = spread.iter().map(|s| s.1.clone()).collect();
    let _ = write!(
        ours.note,
        "; u {total:.2} includes half the range between the model forms the data cannot choose between, added in quadrature to the fit's {u:.2}: {}",
        words.join(" and ")
    );
    ours.u = Some(total);
}

/// Why ours and the vendor's differ, where they differ by more than [`allowed`]: the gap split
/// by convention, each recomputed with one convention changed at a time (the placement of the
/// samples, then the term set), from this file's numbers.
fn why(e: &Entry, conv: Option<&Conventions>) -> Option<String> {
    let ours = e.ours.filter(|v| v.is_finite())?;
    let allow = allowed(e.ours_u, e.unit);
    let gap = ours - e.vendor;
    if gap.abs() <= allow || !e.vendor.is_finite() {
        return None;
    }
    let d = decimals(e.unit);
    let unit = e.unit;
    let drives = conv.and_then(|c| drive_text(c, &e.feature, e.vendor));
    let head = format!(
        "{}ours {ours:.d$} and the vendor's {:.d$} are {:.d$} {unit} apart, beyond 2·√(u² + h²) = {allow:.d$} (h: half its printed step)",
        if e.vendor_valid { "" } else { "the vendor marks its value not valid; " },
        e.vendor,
        gap.abs()
    );
    let parts = conv.and_then(|c| {
        let v = fit_value(&c.vendor, &e.feature)?;
        let f = fit_value(&c.feed, &e.feature)?;
        let own = if c.runs_by_feed { f } else { v };
        let e_um = c.vendor.centre_um[0].hypot(c.vendor.centre_um[1]);
        let mut parts: Vec<(f64, String)> = vec![(
            ours - own,
            format!(
                "our model against the vendor's term set ({}) moves it by {:+.d$}",
                TermSet::vendor((c.arc_deg - 360.0).abs() < 1e-9).describe(),
                ours - own
            ),
        )];
        if c.runs_by_feed {
            parts.push((
                f - v,
                format!(
                    "the placement moves it by {:+.d$} through the {e_um:.0} µm set-up offset: the vendor spreads the {} samples evenly over the {}° arc, and {}",
                    f - v,
                    c.n,
                    c.arc_deg,
                    c.timing_text(),
                ),
            ));
        }
        parts.push((
            v - e.vendor,
            format!("{:+.d$} is left between the vendor's figure and ours in its conventions", v - e.vendor),
        ));
        // A part that rounds to zero at the printed digits says nothing (and would read -0.00).
        parts.retain(|p| p.0.abs() >= 0.5 * 10f64.powi(-(d as i32)));
        parts.sort_by(|a, b| b.0.abs().total_cmp(&a.0.abs()));
        if parts.is_empty() {
            return None;
        }
        Some(parts.into_iter().map(|p| p.1).collect::<Vec<String>>().join("; "))
    });
    if let Some(t) = drives {
        return Some(format!("{head}; in the vendor's conventions as decomposed here, {t}"));
    }
    Some(match (parts, e.ours_as_vendor) {
        (Some(p), _) => format!("{head}: {p}"),
        (None, Some(v)) => format!(
            "{head}: in the vendor's conventions ours is {v:.d$}, so {:+.d$} of the gap is our model and placement against its conventions (see the inputs' rows)",
            ours - v
        ),
        (None, None) if ["_IC", "_PERC", "_RANK"].iter().any(|s| e.feature.ends_with(s)) => {
            format!(
                "{head}; an input of the vendor's ranking has no value in its conventions here (the note names it), so which convention makes the gap is not known"
            )
        }
        (None, None) => format!(
            "{head}; the vendor's computation of this feature is not reproduced here, so which convention makes the gap is not known"
        ),
    })
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
                    as_vendor: None,
                    note: format!(
                        "height of our fitted spike after the reversal at the {} end of {axis}",
                        if side == "POS" { "positive" } else { "negative" }
                    ),
                },
                None => Ours {
                    value: num("amplitude_um"),
                    u: None,
                    as_vendor: None,
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
                as_vendor: None,
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
            as_vendor: None,
            note: format!(
                "our lateral play of {axis} switched by the other axis's reversals, one value for both (not verified against the vendor: its sign, and whether its A/B names the axis that moves sideways or the one that reverses)"
            ),
        },
    })
}

/// A fraction as a whole percentage, or "an unknown share" where not recorded.
pub fn percent_or_unknown(x: f64) -> String {
    if x.is_finite() { format!("{:.0} %", 100.0 * x) } else { "an unknown share".into() }
}

/// The one wording of the share of the excess above the noise an effect closes
/// (`ballbar_diagnose::excess`): "closes 68 % of the excess above the noise (held-out RMS
/// 0.294 → 0.255 µm, noise floor 0.250 µm)"; a share not recorded (an older document) is said
/// to be unknown. With what is known of it ([`excess_share_text`]) where the document has it.
pub fn excess_closed_text(closed: f64, before_um: f64, after_um: f64, floor_um: f64) -> String {
    format!(
        "closes {} of the excess above the noise (held-out RMS {before_um:.3} → {after_um:.3} µm, noise floor {floor_um:.3} µm)",
        percent_or_unknown(closed)
    )
}

/// The share of the excess above the noise with what is known of it (`share`, the
/// document's `held_out_excess` or `held_out.excess`; the floor's standard uncertainty
/// `floor_u_um`): "closes 68 % (57-88 %, k = 1) of the excess above the noise (held-out RMS
/// 0.294 → 0.255 µm, noise floor 0.250 ± 0.002 µm)"; where it is not determined, "closes a
/// share of the excess above the noise that is not determined: the held-out excess, 0.050 µm,
/// is within two standard uncertainties of zero (below 0.084 µm; held-out RMS 0.255 → 0.251
/// µm, noise floor 0.250 ± 0.002 µm)". Without `share` (an older document),
/// [`excess_closed_text`].
pub fn excess_share_text(
    closed: f64,
    share: Option<&ballbar_documents::diagnosis::ExcessShare>,
    before_um: f64,
    after_um: f64,
    floor_um: f64,
    floor_u_um: f64,
) -> String {
    let Some(share) = share else {
        return excess_closed_text(closed, before_um, after_um, floor_um);
    };
    let floor = if floor_u_um.is_finite() {
        format!("noise floor {floor_um:.3} ± {}", two_digits(floor_u_um))
    } else {
        format!("noise floor {floor_um:.3}")
    };
    if share.determined {
        format!(
            "closes {} ({:.0}-{:.0} %, k = 1) of the excess above the noise (held-out RMS {before_um:.3} → {after_um:.3} µm, {floor} µm)",
            percent_or_unknown(closed),
            100.0 * share.interval[0],
            100.0 * share.interval[1]
        )
    } else {
        format!(
            "closes a share of the excess above the noise that is not determined: the held-out excess, {:.3} µm, is within two standard uncertainties of zero (below {:.3} µm; held-out RMS {before_um:.3} → {after_um:.3} µm, {floor} µm)",
            share.excess_before_um, share.excess_before_bound_um
        )
    }
}

/// A standard uncertainty to two significant digits (`0.0021`, `0.35`).
pub fn two_digits(u: f64) -> String {
    if u <= 0.0 {
        return format!("{u}");
    }
    let decimals = (1 - u.log10().floor() as i32).max(0) as usize;
    format!("{u:.decimals$}")
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
        Why::Material { excess_closed, excess_closed_needed, folds: f, .. } => format!(
            "held-out ({}) real but minor: closes {} of what is left above the noise (at least {} to be named)",
            folds(f),
            percent_or_unknown(*excess_closed),
            percent_or_unknown(*excess_closed_needed)
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

/// The vendor's ranking (`<ERROR>_IC`, `_PERC`, `_RANK`) with ours beside it, by the vendor's
/// definitions ([`crate::vendor_rank`], worked out on the shared real file). `ours`: the same
/// formulas on our values (our backlash is one value for both sides; under `diagnose` an effect
/// it tried and did not name is inside the noise: 0; under `fit` an error we have no value of
/// is left out of our ranking, not ranked 0). `ours_as_vendor`: the formulas on our values in
/// the vendor's conventions, only where every input has one (the share and rank only where
/// every ranked error's impact has one); else the note names what is missing.
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
    let entry = |feature: &str| out.iter().find(|e| e.feature == feature && e.run.is_none());
    let tried = |name: &str| {
        ["AF_REVERSAL_SPIKES_", "AF_CYCLIC_ERROR_", "AF_LATERAL_PLAY_"]
            .iter()
            .any(|p| name.starts_with(p))
    };
    let ours_value = |name: &str| -> Option<f64> {
        entry(name)
            .and_then(|e| e.ours)
            .or_else(|| {
                let (base, _) = name.rsplit_once('_')?;
                entry(&format!("{base}_GLOBAL")).and_then(|e| e.ours)
            })
            .or_else(|| (diagnosed && tried(name)).then_some(0.0))
    };
    let as_vendor_value = |name: &str| entry(name).and_then(|e| e.ours_as_vendor);
    let ours: Vec<Option<f64>> =
        errors.iter().map(|e| vendor_rank::impact(e, r_mm, feed, &ours_value).ok()).collect();
    let as_vendor: Vec<Result<f64, Vec<String>>> =
        errors.iter().map(|e| vendor_rank::impact(e, r_mm, feed, &as_vendor_value)).collect();
    let ours_sr = vendor_rank::shares_and_ranks(&ours);
    let all_as_vendor = as_vendor.iter().all(Result::is_ok);
    let vendor_sr = vendor_rank::shares_and_ranks(
        &as_vendor.iter().map(|r| r.as_ref().ok().copied()).collect::<Vec<_>>(),
    );
    let lacking: Vec<String> = errors
        .iter()
        .zip(&as_vendor)
        .filter(|(_, r)| r.is_err())
        .map(|(e, _)| e.strip_prefix("AF_").unwrap_or(e).to_lowercase().replace('_', " "))
        .collect();
    for (k, error) in errors.iter().enumerate() {
        let formula = vendor_rank::describe(error);
        let (share, rank) = ours_sr[k];
        let (v_share, v_rank) = vendor_sr[k];
        let ic_reason = match &as_vendor[k] {
            Ok(v) => format!("; as vendor: {formula} on ours in its conventions, {v:.2} µm"),
            Err(missing) => format!(
                "; not computed in the vendor's conventions: {} has no value in them",
                missing.join(" and ")
            ),
        };
        let rest_reason = if all_as_vendor {
            "; as vendor: of the impacts in its conventions".to_string()
        } else {
            format!(
                "; not computed in the vendor's conventions: the impact of {} has no value in them",
                lacking.join(", ")
            )
        };
        for (suffix, value, v, what, reason) in [
            (
                "_IC",
                ours[k],
                as_vendor[k].as_ref().ok().copied(),
                format!("our impact on circularity by the vendor's definition: {formula}"),
                &ic_reason,
            ),
            (
                "_PERC",
                share,
                v_share.filter(|_| all_as_vendor),
                "our impact's share of the sum of ours".to_string(),
                &rest_reason,
            ),
            (
                "_RANK",
                rank,
                v_rank.filter(|_| all_as_vendor),
                "our rank by impact".to_string(),
                &rest_reason,
            ),
        ] {
            if let Some(f) = diag.feature(&format!("{error}{suffix}")) {
                let what = if value.is_some() {
                    what
                } else {
                    "we have no value of this error (diagnose evaluates spikes, cyclic errors and lateral play); left out of our ranking".to_string()
                };
                let ours = Ours { value, u: None, as_vendor: v, note: format!("{what}{reason}") };
                push(out, plane, f, ours, None);
            }
        }
    }
}

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
        ours_as_vendor: ours.as_vendor,
        ours: ours.value,
        ours_u: ours.u,
        run,
        note: ours.note,
        why: None,
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
            ours_as_vendor: e.ours_as_vendor.filter(|v| v.is_finite()),
            ours: e.ours.filter(|v| v.is_finite()),
            ours_u: e.ours_u.filter(|u| u.is_finite()),
            vendor_valid: e.vendor_valid,
            note: e.note.clone(),
            why: e.why.clone(),
            run: e.run.clone(),
        })
        .collect()
}

/// Decimals to show a value in `unit`: a radius in mm to 0.1 µm, the rest to 0.01.
pub fn decimals(unit: &str) -> usize {
    if unit == "mm" { 4 } else { 2 }
}

/// The comparison as a terminal table: vendor, ours in the vendor's conventions, ours ± u, and
/// the note's first clause; a `why` folded onto the lines below its row, shortened past
/// four lines (the whole text is in the JSON).
pub fn terminal(file: &str, entries: &[Entry]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "\nThe vendor's analysis in {file} beside ours (vendor's units and signs; as vendor: ours computed in the vendor's conventions; u: our standard uncertainty)"
    );
    let width = entries
        .iter()
        .map(|e| e.run.as_ref().map_or(0, |r| r.chars().count()))
        .max()
        .unwrap_or(0)
        .clamp(3, crate::fit_report::NAME_COLUMN_CHARS);
    let _ = writeln!(
        s,
        "  {:<22} {:<width$} {:>10} {:>10} {:>10} {:>7}  {:<6}  ours is",
        "feature", "run", "vendor", "as vendor", "ours", "u", "unit"
    );
    for e in entries {
        let d = decimals(e.unit);
        let vendor = if e.vendor_valid {
            format!("{:.d$}", e.vendor)
        } else {
            format!("({:.d$})", e.vendor)
        };
        let as_vendor = e.ours_as_vendor.map_or("—".into(), |v| format!("{v:.d$}"));
        let ours = e.ours.map_or("—".into(), |v| format!("{v:.d$}"));
        // u to two significant digits (a small u never reads 0.00).
        let u = e.ours_u.map_or(String::new(), |u| crate::fit_report::value_and_u(0.0, u, d).1);
        let run = crate::fit_report::clipped(e.run.as_deref().unwrap_or(""), width);
        let note = crate::vendor_table::clauses(&e.note).0;
        let _ = writeln!(
            s,
            "  {:<22} {run:<width$} {vendor:>10} {as_vendor:>10} {ours:>10} {u:>7}  {:<6}  {}",
            e.feature,
            e.unit,
            crate::fit_report::clipped(note, NOTE_CHARS)
        );
        if let Some(why) = &e.why {
            for line in folded(&format!("why: {why}"), WHY_WIDTH, WHY_LINES) {
                let _ = writeln!(s, "      {line}");
            }
        }
    }
    if entries.iter().any(|e| !e.vendor_valid) {
        let _ = writeln!(s, "  (values in brackets: the vendor marks them not valid)");
    }
    if entries.iter().any(|e| !crate::vendor_table::clauses(&e.note).1.is_empty()) {
        let _ = writeln!(
            s,
            "  (notes shortened to their first clause; each entry's whole note and why in --json's vendor_comparison)"
        );
    }
    s
}

/// Characters of a note in the terminal table.
const NOTE_CHARS: usize = 100;
/// Width and most lines of a folded `why` in the terminal table.
const WHY_WIDTH: usize = 110;
const WHY_LINES: usize = 4;

/// `text` folded at spaces into lines of at most `width` characters, at most `lines` of them,
/// the last ending in `…` where text was left out.
fn folded(text: &str, width: usize, lines: usize) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        if !line.is_empty() && line.chars().count() + 1 + word.chars().count() > width {
            out.push(std::mem::take(&mut line));
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(word);
    }
    if !line.is_empty() {
        out.push(line);
    }
    if out.len() > lines {
        out.truncate(lines);
        if let Some(last) = out.last_mut() {
            last.push_str(" …");
        }
    }
    out
}

/// The vendor's conventions applied to one file's readings ([`crate::vendor_fit`]): its term
/// set on its placement of the samples (`ours_as_vendor`), the same on the placement by the
/// programmed feed, the partial arc's defensible term sets, and the trace's own timing.
struct Conventions {
    /// The vendor's term set on the vendor's placement.
    vendor: VendorFit,
    /// The vendor's term set on the programmed feed's placement.
    feed: VendorFit,
    /// The runs (and so `ours`) are placed by the programmed feed.
    runs_by_feed: bool,
    /// On a partial arc: the fits with each defensible term set on the runs' placement.
    term_sets: Vec<(TermSet, VendorFit)>,
    /// The machine's speed over the programmed feed, from the reversals' timing.
    timing: Option<ballbar_io::b5r::FeedFactor>,
    /// The factor the vendor's even spread implies (its step over the programmed feed's).
    even_factor: f64,
    /// Samples of the analysed arc, the arc (°).
    n: usize,
    arc_deg: f64,
    /// The drives in the vendor's conventions: the readings and the vendor's own model trace
    /// decomposed with [`DRIVES`]'s columns (a full circle in both directions only).
    drives: Option<Drives>,
    /// The reversal spikes by the rule inferred from the vendor's model trace
    /// ([`vendor_spikes`]), on the programmed feed's placement (any arc, either direction), or
    /// why its fit failed; and each run's direction for the notes.
    spikes: Result<Vec<vendor_spikes::Spike>, String>,
    directions: Vec<String>,
}

/// The vendor's drive features from [`vendor_fit::decompose`]: of the readings (its fit
/// extended by those columns) and of its own model trace.
struct Drives {
    readings: Decomposition,
    trace: Option<Decomposition>,
    window: usize,
}

/// Free-form columns this many samples either side of each reversal: the vendor's model trace
/// of the shared file has its reversal shapes within about ±8° (33 to 38 samples at 0.23°),
/// and 45 holds them with a margin (60 leaves 0.079 µm away from them against 45's 0.081).
const DRIVE_WINDOW: usize = 45;

impl Conventions {
    fn of(test: &B5rTest, runs: &[Run], r_mm: f64, feed: f64, arc_deg: f64) -> Option<Conventions> {
        let full = (arc_deg - 360.0).abs() < 1e-9;
        let mut vendor_th = Vec::new();
        let mut feed_th = Vec::new();
        let mut even_factor = 1.0;
        for (k, run) in runs.iter().enumerate() {
            let deg = test.vendor_angles_deg.get(k).filter(|v| v.len() == run.len())?;
            let n = deg.len();
            let rate = run.sample_rate_hz()?;
            let even = arc_deg / n as f64;
            let step = (feed / 60.0 / r_mm).to_degrees() / rate;
            even_factor = even / step;
            // Both placements are centred on the arc: scale the vendor's about its middle.
            let mid = deg.iter().sum::<f64>() / n as f64;
            vendor_th.push(deg.iter().map(|d| d.to_radians()).collect::<Vec<f64>>());
            feed_th
                .push(deg.iter().map(|d| (mid + (d - mid) * step / even).to_radians()).collect());
        }
        let samples = |th: &[Vec<f64>]| -> Vec<Samples> {
            th.iter()
                .zip(runs)
                .map(|(t, run)| Samples { theta: t.clone(), dr_mm: &run.dr_mm })
                .collect()
        };
        let terms = TermSet::vendor(full);
        let vendor = vendor_fit::fit(&samples(&vendor_th), r_mm, feed, terms).ok()?;
        let feed_fit = vendor_fit::fit(&samples(&feed_th), r_mm, feed, terms).ok()?;
        let runs_by_feed = runs
            .first()
            .and_then(ballbar_io::b5r::SpacingMode::of)
            .is_some_and(|m| m == ballbar_io::b5r::SpacingMode::Feed);
        let own = if runs_by_feed { &feed_th } else { &vendor_th };
        let term_sets = if full {
            Vec::new()
        } else {
            [(true, true), (true, false), (false, true), (false, false)]
                .into_iter()
                .filter_map(|(per_axis_scales, three_theta)| {
                    let t = TermSet { per_axis_scales, three_theta, reversals: false };
                    vendor_fit::fit(&samples(own), r_mm, feed, t).ok().map(|f| (t, f))
                })
                .collect()
        };
        // The free-form windows of two reversals 90° apart must not meet: a run's quarter
        // holds both (a full circle of at least 8 windows' samples); fewer samples (a low rate
        // at a fast feed) leave the drive features without a value in these conventions.
        let apart = runs.iter().all(|r| r.len() >= 8 * DRIVE_WINDOW);
        let drives = if full && apart && vendor.servo_mismatch_ms.is_some() {
            drives_of(test, runs, &samples(&vendor_th), r_mm, feed)
        } else {
            None
        };
        Some(Conventions {
            vendor,
            feed: feed_fit,
            runs_by_feed,
            term_sets,
            timing: ballbar_io::b5r::feed_factor(test, runs),
            even_factor,
            n: runs.first().map_or(0, Run::len),
            arc_deg,
            drives,
            spikes: vendor_spikes::spikes(&samples(&feed_th)).map_err(|e| e.to_string()),
            directions: runs
                .iter()
                .map(|r| {
                    // The file's own word (its A, B frame), as the model traces are named.
                    match r.header.extra.iter().find(|(k, _)| k == "vendor_direction") {
                        Some((_, d)) => d.clone(),
                        None => "?".into(),
                    }
                })
                .collect(),
        })
    }

    /// The vendor's term set on the runs' own placement.
    fn own(&self) -> &VendorFit {
        if self.runs_by_feed { &self.feed } else { &self.vendor }
    }

    /// The placement the trace's timing chooses, if it chooses one: within 2u of one
    /// placement's factor (the programmed feed's 1, or the even spread's) and more than 4u
    /// from the other's (2u: a 95 % coverage; 4u: the two hypotheses apart by more than twice
    /// that coverage).
    fn timing_chooses(&self) -> Option<&'static str> {
        let t = self.timing?;
        let (feed, even) = ((t.factor - 1.0).abs(), (t.factor - self.even_factor).abs());
        if feed <= 2.0 * t.u && even > 4.0 * t.u {
            Some("the programmed feed")
        } else if even <= 2.0 * t.u && feed > 4.0 * t.u {
            Some("the even spread")
        } else {
            None
        }
    }

    /// The trace's timing in words.
    fn timing_text(&self) -> String {
        match self.timing {
            Some(t) => format!(
                "the trace's own timing ({} reversals) puts them at the programmed feed × {:.5} ± {:.5} (the even spread needs × {:.5})",
                t.reversals, t.factor, t.u, self.even_factor
            ),
            None => "the trace's reversals are too few or too faint to time the feed".into(),
        }
    }
}

/// The readings (on the vendor's placement) and the vendor's own model trace, where the file
/// has it for every run, decomposed with the file's cyclic pitches (none where it prints none).
fn drives_of(
    test: &B5rTest,
    runs: &[Run],
    readings: &[Samples],
    r_mm: f64,
    feed: f64,
) -> Option<Drives> {
    let diag = test.diagnostics();
    let pitch = |name: &str| diag.and_then(|d| d.feature(name)).map(|f| f.value);
    let cyclic_pitch_mm = match (pitch("AF_CYCLIC_PITCH_A"), pitch("AF_CYCLIC_PITCH_B")) {
        (Some(a), Some(b)) if a > 0.0 && b > 0.0 => Some([a, b]),
        _ => None,
    };
    let drives = vendor_fit::Drives {
        lateral_play: true,
        per_side: false,
        cyclic_pitch_mm,
        window: DRIVE_WINDOW,
    };
    let of_readings = vendor_fit::decompose(readings, r_mm, feed, drives).ok()?;
    let traces = diag.and_then(|d| vendor_fit::model_traces(runs, d));
    let trace = traces.filter(|t| !t.is_empty() && t.len() == readings.len()).and_then(|t| {
        let runs: Vec<Samples> = readings
            .iter()
            .zip(t)
            .map(|(s, y)| Samples { theta: s.theta.clone(), dr_mm: y })
            .collect();
        vendor_fit::decompose(&runs, r_mm, feed, drives).ok()
    });
    Some(Drives { readings: of_readings, trace, window: DRIVE_WINDOW })
}

/// A drive feature (lateral play, cyclic error) from a decomposition, in µm; `None` where it
/// does not give it (the reversal spikes are [`vendor_spikes`]').
fn drive_value(d: &Decomposition, name: &str) -> Option<f64> {
    let rest = name.strip_prefix("AF_")?;
    let axis = |s: &str| match s {
        "A" => Some(0usize),
        "B" => Some(1),
        _ => None,
    };
    if let Some(r) = rest.strip_prefix("LATERAL_PLAY_") {
        let (ax, which) = r.split_once('_')?;
        return if which == "GLOBAL" { Some(d.lateral_play_um?[axis(ax)?]) } else { None };
    }
    if let Some(r) = rest.strip_prefix("CYCLIC_ERROR_") {
        let (ax, dir) = r.split_once('_')?;
        let k = match dir {
            "FWD" => 0,
            "REV" => 1,
            _ => return None,
        };
        return Some(d.cyclic?[axis(ax)?][k].amplitude_um);
    }
    None
}

/// The axis (0: A, 1: B) and side (POS) of an `AF_REVERSAL_SPIKES_*` feature.
fn spike_of(name: &str) -> Option<(usize, bool)> {
    match name.strip_prefix("AF_REVERSAL_SPIKES_")? {
        "A_POS" => Some((0, true)),
        "A_NEG" => Some((0, false)),
        "B_POS" => Some((1, true)),
        "B_NEG" => Some((1, false)),
        _ => None,
    }
}

/// A reversal spike in the vendor's conventions ([`vendor_spikes`]), in words: the rule, each
/// run's value, their mean; `None` where no run gives one.
fn spike_text(c: &Conventions, axis: usize, pos: bool) -> Option<String> {
    let (mean, _) = vendor_spikes::feature(c.spikes.as_deref().unwrap_or_default(), axis, pos)?;
    let runs: Vec<String> = c
        .spikes
        .as_deref()
        .unwrap_or_default()
        .iter()
        .filter(|s| s.axis == axis && s.pos == pos)
        .map(|s| {
            let dir = c.directions.get(s.run).map_or("?", String::as_str);
            format!("run {} {dir} {:.2} over {} samples", s.run + 1, s.height_um, s.samples)
        })
        .collect();
    Some(format!(
        "the vendor's spike shape (a rise over {} samples from the axis's reversal at the programmed feed's timing, a fall at that rate to a quarter and at a third of it to 0, over {} samples in all) fitted with a cubic and a step to the readings {} samples either side of the reversal (a rule inferred from the vendor's model trace of one file, its baseline chosen on that file; on that trace itself it gives B's spikes 0.08 µm below the printed ones, and its counts of samples may be a time or an arc at another rate, feed or radius): {}, mean {mean:.2}; the vendor's reversal model also holds shapes this one does not (on the shared real file, in place of a spike at A's positive end, a drop of 3 to 4 µm over two samples 3.5 to 4.5 samples after the reversal: ballbar-report's vendor_fit documentation)",
        vendor_spikes::RISE_SAMPLES,
        vendor_spikes::SPAN_SAMPLES,
        vendor_spikes::HALF_WINDOW_SAMPLES,
        runs.join(", ")
    ))
}

/// A drive feature's value in the vendor's conventions as decomposed here, in words, with what
/// the vendor's own model trace gives and leaves: `None` for other features.
fn drive_text(c: &Conventions, name: &str, vendor: f64) -> Option<String> {
    if let Some((axis, pos)) = spike_of(name) {
        return spike_text(c, axis, pos);
    }
    let d = c.drives.as_ref()?;
    let r = drive_value(&d.readings, name)?;
    let columns = format!(
        "the vendor's term set with lateral play, {}free-form columns {} samples either side of each reversal",
        if d.readings.cyclic.is_some() {
            "a cyclic error per axis and direction at its pitches, "
        } else {
            ""
        },
        d.window
    );
    let trace = match &d.trace {
        Some(t) => match drive_value(t, name) {
            Some(tv) => format!(
                "; its own model trace with the same columns gives {tv:.2} and is left with {:.3} µm RMS away from the reversals, where its rounding to 0.01 µm leaves 0.003: the vendor's model holds columns these lack (ballbar-report's vendor_fit documentation lists what was tried)",
                t.rms_away_um
            ),
            None => String::new(),
        },
        None => "; the file has no model trace of the vendor's to decompose".into(),
    };
    Some(format!(
        "{columns}, fitted to the readings (rank {} of {}, condition {:.1}), gives {r:.2} against its {vendor:.2}{trace}",
        d.readings.fit.rank, d.readings.fit.columns, d.readings.fit.condition
    ))
}

/// A vendor feature from a fit in its conventions, in the entry's unit; `None` where the fit
/// does not give it.
fn fit_value(f: &VendorFit, name: &str) -> Option<f64> {
    Some(match name {
        "AF_CENTRE_OFFSET_A" => f.centre_um[0],
        "AF_CENTRE_OFFSET_B" => f.centre_um[1],
        "AF_BEST_RADIUS" => f.best_radius_mm,
        "AF_GLOBAL_SCALE" => f.global_scale_um,
        "AF_SCALE_ERROR_A" => f.scale_ppm[0],
        "AF_SCALE_ERROR_B" => f.scale_ppm[1],
        "AF_SCALE_MISMATCH" => f.scale_mismatch_um?,
        "AF_SQUARENESS" => f.squareness_um_per_m,
        "AF_STRAIGHTNESS_A" => f.straightness_um?[0],
        "AF_STRAIGHTNESS_B" => f.straightness_um?[1],
        "AF_SERVO_MISMATCH" => f.servo_mismatch_ms?,
        "AF_BACKLASH_A_GLOBAL" => f.backlash_um?[0],
        "AF_BACKLASH_B_GLOBAL" => f.backlash_um?[1],
        _ => return None,
    })
}

/// Why a feature has no value in the vendor's conventions.
fn not_reproduced(name: &str, conv: Option<&Conventions>) -> String {
    let Some(c) = conv else {
        return "not computed in the vendor's conventions: they need its angles of the samples, which only a .b5r file read whole gives".into();
    };
    if name == "RMS" {
        return format!(
            "not reproduced in the vendor's conventions: its term set as reproduced here ({}) leaves {:.2} µm; the vendor's model also holds its reversal spikes, lateral play and cyclic error",
            TermSet::vendor((c.arc_deg - 360.0).abs() < 1e-9).describe(),
            c.vendor.rms_um
        );
    }
    let full = (c.arc_deg - 360.0).abs() < 1e-9;
    if !full && (name == "AF_SERVO_MISMATCH" || name.starts_with("AF_BACKLASH_")) {
        return "not computed in the vendor's conventions: its term set on a partial arc has no servo or backlash term (vendor-b5r.md)".into();
    }
    if name == "AF_SERVO_MISMATCH" && c.vendor.servo_mismatch_ms.is_none() {
        return "not computed in the vendor's conventions: the servo mismatch needs runs in both directions".into();
    }
    if !full && name == "AF_SCALE_MISMATCH" {
        return "not computed in the vendor's conventions: on a partial arc it fits one scale common to both axes".into();
    }
    if name.starts_with("AF_LATERAL_PLAY_") && !name.ends_with("_GLOBAL") {
        return "not computed in the vendor's conventions: per side, the difference of an axis's lateral play between its two ends is exactly aliased with the other axis's backlash difference between its ends in any fit of a circle's trace (one column: ballbar-report's vendor_fit decomposition finds it), so the vendor's split is a choice its file does not show; its global value is in the GLOBAL row".into();
    }
    if let (Some(_), Err(e)) = (spike_of(name), &c.spikes) {
        return format!(
            "not computed in the vendor's conventions: the fit of the spike failed: {e}"
        );
    }
    if spike_of(name).is_some() {
        return format!(
            "not computed in the vendor's conventions: no run holds this reversal with the samples its rule needs ({} before it and the spike's {} after it on the analysed arc, and reversals at least {} samples apart; ballbar-report's vendor_spikes)",
            vendor_spikes::MIN_BEFORE_SAMPLES,
            vendor_spikes::SPAN_SAMPLES,
            vendor_spikes::HALF_WINDOW_SAMPLES as f64 + vendor_spikes::SPAN_SAMPLES
        );
    }
    "not reproduced in the vendor's conventions: the vendor's reversal model (lateral play and cyclic error per direction, over windows of about ±9° around each reversal, as its model trace shows) is not published, and the term set here does not hold it (ballbar-report's vendor_fit documentation lists what was tried)".into()
}

/// The vendor's printed step for a value in `unit` (the entry's unit): lengths to 0.1 µm
/// (radius 0.0001 mm), squareness to 0.1 µm/m, scale to 0.1 ppm, servo mismatch to 0.01 ms,
/// shares and ranks to 1, as the shared real file prints them.
pub fn printed_step(unit: &str) -> f64 {
    match unit {
        "mm" => 1e-4,
        "ms" => 0.01,
        "%" | "rank" => 1.0,
        _ => 0.1,
    }
}

/// How far ours and the vendor's may differ before `why` is given: 2·√(u² + h²), with u our
/// standard uncertainty and h half the vendor's printed step (its rounding, read as a
/// standard uncertainty of h: generous against the uniform h/√3); 2: a 95 % coverage.
pub fn allowed(u: Option<f64>, unit: &str) -> f64 {
    let h = printed_step(unit) / 2.0;
    2.0 * (u.unwrap_or(0.0).powi(2) + h * h).sqrt()
}

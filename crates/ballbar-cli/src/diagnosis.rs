//! The diagnosis report: the terminal text a metrologist reads in a minute, and the document
//! of `shared/spec/cli.md` ([`document`]: `ballbar_documents::diagnosis`, which defines every
//! field and statistic, `gap`, `effects`, `aliased`, and more).
//!
//! # How the terminal and the page write them
//! - `f_statistic` is **partial-F**, shown as `1.11e6` from 10,000 on; not ISO 230-4's radial
//!   deviation F of a circle.
//! - Fractions (`shrink`, `share`) are percentages on the terminal and page.
//! - `parameters` (`<name>_<unit>`) are written as `amplitude 5.800 µm`
//!   ([`ballbar_report::vendor::parameter_text`]).
//! - `description`: the effect in words. A plane's servo mismatch term beside per-axis lags is
//!   the sum of the paper's three plane terms, whichever plane carries it, and is named so
//!   ([`describe`]); `kind` stays `servo_mismatch` and `axis` the plane that carries it.

use std::fmt::Write;

use ballbar_diagnose::{Diagnosis, Verdict, excess};
use ballbar_documents::diagnosis as doc;
use ballbar_fit::metrics;
use ballbar_model::{Effect, Run};

/// Whether the base model has one servo lag per linear axis (then a plane's mismatch term is
/// the sum of the paper's three).
fn lags_per_axis(d: &Diagnosis) -> bool {
    ["TX", "TY", "TZ"].iter().all(|id| d.base.parameters.iter().any(|p| p.id == *id))
}

/// An effect's name in the report: the model's description, except a plane's servo mismatch
/// term accepted beside per-axis lags: the lags make any three plane terms that sum to zero, so
/// the one plane term takes the sum M_XY + M_YZ + M_ZX, whichever plane carries it (which is
/// arbitrary); named by the plane alone it would read as that plane's mismatch.
pub fn describe(effect: &Effect, lags_per_axis: bool) -> String {
    match effect {
        Effect::ServoMismatch { plane } if lags_per_axis => {
            format!(
                "servo mismatch beyond the per-axis lags: the sum M_XY + M_YZ + M_ZX of the three planes' terms (fitted as the {plane} term)"
            )
        }
        other => other.describe(),
    }
}

/// The standard uncertainties of an accepted effect's parameters: those the diagnosis gives
/// (the parameters linear in the coefficients), and the `value_*` of a one-coefficient effect
/// (a bar length, a higher-order term, a plane's servo mismatch), which is its coefficient in
/// the same display unit.
fn uncertainties(e: &ballbar_diagnose::Accepted) -> Vec<(String, f64)> {
    let mut out = e.uncertainties.clone();
    if let [(_, _, u, _)] = e.coefficients.as_slice() {
        for (k, _) in e.parameters.iter().filter(|(k, _)| k.starts_with("value_")) {
            if !out.iter().any(|(j, _)| j == k) {
                out.push((k.clone(), *u));
            }
        }
    }
    out
}

/// An accepted effect's parameters as text (`amplitude 5.800 ± 0.120 µm, decay τ 61.000 ms`).
fn parameters_text(e: &ballbar_diagnose::Accepted) -> String {
    let us = uncertainties(e);
    e.parameters
        .iter()
        .map(|(k, v)| {
            let u = us.iter().find(|(j, _)| j == k).map(|(_, u)| *u);
            ballbar_report::vendor::parameter_text(k, *v, u)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The terminal report.
pub fn terminal(d: &Diagnosis, runs: &[Run]) -> String {
    let g = &d.gap;
    let lags = lags_per_axis(d);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "ballbar diagnose — machine '{}', {} runs, {} samples",
        d.machine,
        runs.len(),
        d.base.n_samples
    );
    let _ = writeln!(
        s,
        "base model: rank {} of {} parameters, residual RMS {:.3} µm; noise floor {:.3}{} ({}; lag-1 autocorrelation {:.2}; the instrument averages {} sample{}; the partial-F tests allow ×{:.1} for the noise's correlation)",
        d.base.rank,
        d.base.parameters.len(),
        g.base_rms_um,
        g.noise_floor_um,
        if g.noise_floor_blocks >= 2 {
            format!(
                " ± {} µm (u, k = 1: its spread with each of {} blocks of its data left out in turn, {} degrees of freedom)",
                ballbar_report::vendor::two_digits(g.noise_floor_u_um),
                g.noise_floor_blocks,
                g.noise_floor_blocks - 1
            )
        } else {
            " µm".into()
        },
        g.noise_source.description(),
        g.noise_lag1_autocorrelation,
        g.noise_filter_samples,
        if g.noise_filter_samples == 1 { "" } else { "s" },
        g.noise_inflation
    );
    let _ = writeln!(s, "\nWhere the gap lies (share of the energy above the noise)");
    if g.where_.is_empty() {
        let _ = writeln!(s, "  nowhere: the residual is at the noise floor");
    }
    // What is one pattern over several planes and directions (the same arc and reversals) is
    // one line.
    for group in ballbar_documents::diagnosis::grouped_where(&g.where_) {
        let w = group.members[0];
        let rev = if w.reversals.is_empty() {
            String::new()
        } else {
            format!(", at the reversal of {}", w.reversals.join(", "))
        };
        // A rotary run's sector is of its turning axis's angle, in that run.
        let run = match (&w.axis, &w.run) {
            (Some(a), Some(r)) => format!(" ({a} of run {r})"),
            _ => String::new(),
        };
        let _ = writeln!(
            s,
            "  {}: {}{rev}{run}: {}",
            group.runs_text(),
            group.sector_text(),
            group.share_text()
        );
    }
    for p in &g.parity {
        let _ = writeln!(
            s,
            "  {} at {} mm/min: RMS of the CW/CCW mean (the same in both directions) {:.3} µm, of their half-difference (reversing with the direction) {:.3} µm",
            p.plane, p.feed_mm_per_min, p.even_rms_um, p.odd_rms_um
        );
    }
    if let Some(p) = g.angle_spectrum.first() {
        let _ = writeln!(
            s,
            "  largest harmonic of the angle: {:.0} per revolution (amplitude {:.3} µm)",
            p.at, p.amplitude_um
        );
    }
    if let Some(p) = g.time_spectrum.first() {
        let _ = writeln!(
            s,
            "  largest frequency in time: {:.2} Hz (amplitude {:.3} µm)",
            p.at, p.amplitude_um
        );
    }
    for p in &g.position_spectrum {
        let _ = writeln!(
            s,
            "  largest ripple along {}: pitch {:.2} mm (amplitude {:.3} µm)",
            p.axis, p.pitch_mm, p.amplitude_um
        );
    }
    let _ = writeln!(s, "  {}", trend_line(&g.trend));
    let _ = writeln!(s, "  locked to: {} — {}", g.locking.verdict.replace('_', " "), g.locking.why);

    let _ = writeln!(s, "\nHeld out (the claims come from these folds):");
    for (kind, why) in &d.schemes {
        let _ = writeln!(s, "  {}: {why}", kind.name().replace('_', " "));
    }
    let run_radius = ballbar_diagnose::RunRadius::of(&d.model_effects, &d.declined, &d.aliased);
    let _ = writeln!(s, "  the runs' mean radius: {}", run_radius.description);
    let _ = writeln!(s, "\nUnmodelled effects, most important first");
    let _ = writeln!(
        s,
        "  (partial-F: the variance an effect explains on all the data over the noise's, a test statistic, not ISO 230-4's F; held-out: on data not used to fit or choose it)"
    );
    if d.effects.is_empty() {
        let _ = writeln!(
            s,
            "  none stands out of the noise ({} candidates tried)",
            d.candidates_screened
        );
    }
    for e in &d.effects {
        // What it means on the shop floor first; the statistics beneath.
        let parameters: std::collections::BTreeMap<String, f64> =
            e.parameters.iter().cloned().collect();
        let sentence = ballbar_documents::advice::shop_floor(&ballbar_documents::advice::Facts {
            subject: &subject(&e.effect),
            parameters: &parameters,
            g_before_um: e.held_out_g_before_um,
            g_after_um: e.held_out_g_after_um,
        });
        let _ = writeln!(s, "  ▸ {sentence}");
        let _ = writeln!(s, "  {}: {}", describe(&e.effect, lags), parameters_text(e));
        let _ = writeln!(
            s,
            "      held-out ({}): {}; ISO 230-4 G {:.2} → {:.2} µm; the RMS itself falls {:.0} % ({:.0} to {:.0} % within ±2 jackknife standard errors); {}, held-out gain {:.1} standard errors from zero",
            e.folds.name().replace('_', " "),
            ballbar_report::vendor::excess_share_text(
                e.held_out_excess_closed,
                Some(&excess_share(&e.held_out_excess)),
                e.held_out_rms_before_um,
                e.held_out_rms_after_um,
                g.noise_floor_um,
                g.noise_floor_u_um
            ),
            e.held_out_g_before_um,
            e.held_out_g_after_um,
            100.0 * e.shrink,
            100.0 * e.shrink_interval[0],
            100.0 * e.shrink_interval[1],
            ballbar_report::vendor::partial_f_text(e.f_statistic),
            e.held_out_t
        );
        if let Some(n) = &e.note {
            let _ = writeln!(s, "      note: {n}");
        }
    }
    if !d.effects.is_empty() {
        let h = &d.held_out;
        let _ = writeln!(
            s,
            "  together, on {}: {}",
            h.folds.map_or("no folds", |f| f.name()).replace('_', " "),
            ballbar_report::vendor::excess_share_text(
                h.excess_closed,
                h.excess.as_ref().map(excess_share).as_ref(),
                h.before_um,
                h.after_um,
                h.noise_um,
                h.noise_u_um
            )
        );
    }
    if let Some(u) = &d.unexplained {
        let _ = writeln!(
            s,
            "\nUnexplained: {:.0} % of the held-out excess above the noise ({:.3} µm RMS) is left by {}; no candidate the held-out runs could judge describes it. Where the base model's excess lies:",
            100.0 * excess::left_from_energy_share(u.share_left),
            u.excess_rms_um,
            if d.effects.is_empty() { "the base model" } else { "the effects named" }
        );
        for w in &u.where_ {
            let _ = writeln!(s, "  {w}");
        }
        for (e, share) in &u.nearest {
            let _ = writeln!(
                s,
                "  nearest candidate: {} closes {:.0} % of it",
                describe(e, lags),
                100.0 * excess::closed_from_energy_share(*share)
            );
        }
    }
    if !d.declined.is_empty() {
        let _ = writeln!(s, "\nTried and declined, nearest misses first:");
        for x in &d.declined {
            let _ = writeln!(s, "  {}: {}", describe(&x.effect, lags), verdict_text(&x.verdict));
        }
    }
    for n in &d.notes {
        let _ = writeln!(s, "\nNote: {n}");
    }
    if !d.aliased.is_empty() {
        let _ = writeln!(
            s,
            "\nEffects these tests cannot separate from the base model (an effect of ordinary size would hide in):"
        );
        for a in &d.aliased {
            let _ = writeln!(
                s,
                "  {:<40} → {}\n      separate with: {}",
                describe(&a.effect, lags),
                a.with.join(", "),
                a.test_to_separate
            );
        }
    }
    s.push_str(&ballbar_report::aliases::terminal(&d.base, &d.base_aliases));
    if !d.effects.is_empty() {
        let _ = writeln!(
            s,
            "\nRuns: residual RMS and ISO 230-4 G (about the least-squares circle), base → with the effects, µm"
        );
        for (r, run) in runs.iter().enumerate() {
            let (b, a) = (
                metrics::figures(run, &d.base.residuals[r]),
                metrics::figures(run, &d.augmented.residuals[r]),
            );
            let _ = writeln!(
                s,
                "  {:<14} RMS {:>6.3} → {:<6.3}  G {:>6.2} → {:<6.2}",
                run.name(),
                b.rms * 1e3,
                a.rms * 1e3,
                b.g * 1e3,
                a.g * 1e3
            );
        }
    }
    s
}

/// Why a candidate was declined, in words.
/// The trend's line: the drift with its standard uncertainty where the runs determine it (and
/// whether it stands out of it), else why it is not determined; the closure with its own.
fn trend_line(t: &ballbar_documents::diagnosis::Trend) -> String {
    let drift = if t.slope_um_per_h.is_finite() && t.slope_std_uncertainty_um_per_h.is_finite() {
        let (b, u) = (t.slope_um_per_h, t.slope_std_uncertainty_um_per_h);
        let within = if b.abs() < 2.0 * u { ", within 2u of zero: no drift shown" } else { "" };
        format!("{b:+.2} ± {u:.2} µm/h (u, k = 1; {}{within})", t.note)
    } else {
        t.note.clone()
    };
    let closure = if t.closure_um.is_finite() {
        let note = if t.closure_note.is_empty() {
            String::new()
        } else {
            format!(" ({})", t.closure_note)
        };
        format!("{:+.3} ± {:.3} µm{note}", t.closure_um, t.closure_std_uncertainty_um)
    } else {
        "not measured (no run of 12 samples or more)".into()
    };
    format!(
        "drift over the session: {drift}; a run's end minus its start, mean over the runs: {closure}"
    )
}

fn verdict_text(v: &ballbar_diagnose::Verdict) -> String {
    match v {
        ballbar_diagnose::Verdict::F { f, needed } => format!(
            "{} below {needed:.1} (its 1e-6 false-alarm level)",
            ballbar_report::vendor::partial_f_text(*f)
        ),
        ballbar_diagnose::Verdict::HeldOut { before_um, after_um, t, folds, .. } => format!(
            "held-out ({}) RMS {before_um:.3} → {after_um:.3} µm, a gain {t:.1} standard errors from zero, below {}",
            folds.name().replace('_', " "),
            ballbar_diagnose::HELD_OUT_T
        ),
        ballbar_diagnose::Verdict::NotMaterial { before_um, after_um, share, folds, .. } => {
            format!(
                "held-out ({}) RMS {before_um:.3} → {after_um:.3} µm: real but minor, it closes {:.0} % of what is left above the noise (at least {:.0} % to be named)",
                folds.name().replace('_', " "),
                100.0 * excess::closed_from_energy_share(*share),
                100.0 * ballbar_diagnose::MATERIAL
            )
        }
        ballbar_diagnose::Verdict::NotMaterialOnAllRuns {
            rms_before_um,
            rms_after_um,
            share,
            ..
        } => format!(
            "on all runs, the model fitted on every one, RMS {rms_before_um:.3} → {rms_after_um:.3} µm: each run's own bar length closes {:.0} % of what is left above the noise (at least {:.0} % to be named); a constant per run predicts no held-out run, so it is judged there",
            100.0 * excess::closed_from_energy_share(share.min(1.0)),
            100.0 * ballbar_diagnose::MATERIAL
        ),
        ballbar_diagnose::Verdict::NotJudgeable { tried } => format!(
            "no held-out folds can judge it (the training of some fold of {} cannot determine it)",
            if tried.is_empty() {
                "later runs (no later runs to predict: the first runs that hold every plane in every direction are the whole session)".to_string()
            } else {
                tried.iter().map(|k| k.name().replace('_', " ")).collect::<Vec<_>>().join(", ")
            }
        ),
        ballbar_diagnose::Verdict::Redundant { t } => format!(
            "accepted, then made redundant by the other effects named (leaving it out of them loses a held-out gain {t:.1} standard errors from zero, or less than {:.0} % of what is left above the noise)",
            100.0 * ballbar_diagnose::MATERIAL
        ),
        ballbar_diagnose::Verdict::NoRank => "adds nothing to the accepted effects".into(),
        ballbar_diagnose::Verdict::Passed => {
            "passes, but the limit on the number of effects was reached".into()
        }
    }
}

/// What an entry is about, for the document: the effect's kind and axis; a lateral play names
/// the axis that moves sideways and the axis whose reversals switch it (cli.md), not the pair.
fn subject(effect: &Effect) -> doc::Subject {
    let (axis, switched_by) = match effect {
        Effect::LateralPlay { axis, switched_by } => {
            (Some(axis.name().to_string()), Some(switched_by.name().to_string()))
        }
        other => (other.axis_label(), None),
    };
    doc::Subject { kind: effect.kind().into(), axis, switched_by }
}

/// A share of the excess as the document states it.
fn excess_share(s: &excess::Share) -> doc::ExcessShare {
    doc::ExcessShare {
        determined: s.determined,
        interval: s.interval,
        excess_before_um: s.excess_before,
        excess_before_bound_um: s.excess_before_bound,
        excess_energy_u_um2: s.excess_energy_u,
    }
}

/// The gap as the document states it.
fn gap(g: &ballbar_diagnose::localise::Gap) -> doc::Gap {
    doc::Gap {
        base_rms_um: g.base_rms_um,
        noise_floor_um: g.noise_floor_um,
        noise_floor_u_um: g.noise_floor_u_um,
        noise_floor_blocks: Some(g.noise_floor_blocks),
        excess_um: excess::excess(g.base_rms_um, g.noise_floor_um),
        noise_source: Some(g.noise_source),
        noise_lag1_autocorrelation: g.noise_lag1_autocorrelation,
        noise_inflation: Some(g.noise_inflation),
        noise_filter_samples: Some(g.noise_filter_samples),
        where_: g.where_.clone(),
        groups: g.groups.clone(),
        runs: g.runs.clone(),
        parity: g.parity.clone(),
        angle_spectrum: g.angle_spectrum.clone(),
        time_spectrum: g.time_spectrum.clone(),
        position_spectrum: g.position_spectrum.clone(),
        trend: Some(g.trend.clone()),
        locking: Some(g.locking.clone()),
    }
}

/// Why a candidate was declined, as the document states it.
fn why(v: &Verdict) -> doc::Why {
    match v {
        Verdict::F { f, needed } => doc::Why::F { f_statistic: *f, needed: *needed },
        Verdict::HeldOut { f, before_um, after_um, t, folds } => doc::Why::HeldOut {
            f_statistic: *f,
            held_out_rms_before_um: *before_um,
            held_out_rms_after_um: *after_um,
            held_out_t: *t,
            needed: ballbar_diagnose::HELD_OUT_T,
            folds: folds.name().into(),
        },
        Verdict::NotMaterial { f, before_um, after_um, share, folds } => doc::Why::Material {
            f_statistic: *f,
            held_out_rms_before_um: *before_um,
            held_out_rms_after_um: *after_um,
            share_of_excess: *share,
            needed: 1.0 - (1.0 - ballbar_diagnose::MATERIAL).powi(2),
            excess_closed: excess::closed_from_energy_share(*share),
            excess_closed_needed: ballbar_diagnose::MATERIAL,
            folds: folds.name().into(),
        },
        Verdict::NotMaterialOnAllRuns { f, rms_before_um, rms_after_um, share } => {
            doc::Why::Material {
                f_statistic: *f,
                held_out_rms_before_um: *rms_before_um,
                held_out_rms_after_um: *rms_after_um,
                share_of_excess: *share,
                needed: 1.0 - (1.0 - ballbar_diagnose::MATERIAL).powi(2),
                excess_closed: excess::closed_from_energy_share(share.min(1.0)),
                excess_closed_needed: ballbar_diagnose::MATERIAL,
                folds: "all_runs".into(),
            }
        }
        Verdict::NotJudgeable { tried } => {
            doc::Why::Judgeable { folds_tried: tried.iter().map(|k| k.name().into()).collect() }
        }
        Verdict::Redundant { t } => {
            doc::Why::Redundant { held_out_t: *t, needed: ballbar_diagnose::HELD_OUT_T }
        }
        Verdict::NoRank => doc::Why::Rank,
        Verdict::Passed => doc::Why::Limit,
    }
}

/// The diagnosis document (`ballbar-diagnosis/1`), without `assumed` and `vendor_comparison`,
/// which the command adds from its inputs.
pub fn document(d: &Diagnosis, runs: &[Run]) -> doc::Diagnosis {
    let lags = lags_per_axis(d);
    let effects = d
        .effects
        .iter()
        .map(|e| doc::Effect {
            subject: subject(&e.effect),
            description: describe(&e.effect, lags),
            held_out_rms_before_um: e.held_out_rms_before_um,
            held_out_rms_after_um: e.held_out_rms_after_um,
            folds: Some(e.folds.name().into()),
            held_out_g_before_um: e.held_out_g_before_um,
            held_out_g_after_um: e.held_out_g_after_um,
            held_out_excess_closed: e.held_out_excess_closed,
            held_out_excess: Some(excess_share(&e.held_out_excess)),
            shrink: e.shrink,
            shrink_interval: e.shrink_interval,
            parameters: e.parameters.iter().cloned().collect(),
            std_uncertainties: uncertainties(e).into_iter().collect(),
            coefficients: e
                .coefficients
                .iter()
                .map(|(id, value, u, unit)| doc::Coefficient {
                    id: id.clone(),
                    value: *value,
                    std_uncertainty: *u,
                    unit: unit.to_string(),
                })
                .collect(),
            f_statistic: e.f_statistic,
            held_out_t: e.held_out_t,
            note: e.note.clone(),
        })
        .collect();
    // The diagnosis's own aliased candidates, then the base fit's aliases
    // (`ballbar_fit::alias`: terms it lacks, set-up metadata), one entry per kind and axis,
    // with the values each moves.
    let base = ballbar_report::aliases::documents(&d.base, &d.base_aliases);
    let mut aliased: Vec<doc::Aliased> = d
        .aliased
        .iter()
        .map(|a| {
            let same = d.base_aliases.aliases.iter().position(
                |b| matches!(&b.candidate, ballbar_fit::alias::Candidate::Term(e) if *e == a.effect),
            );
            doc::Aliased {
                subject: subject(&a.effect),
                description: Some(describe(&a.effect, lags)),
                with: a.with.clone(),
                test_to_separate: a.test_to_separate.into(),
                visible_share: a.visible_share,
                alternative: same.and_then(|k| base[k].alternative.clone()),
                moves: same.map(|k| base[k].moves.clone()).unwrap_or_default(),
            }
        })
        .collect();
    let named = |ids: &[String]| -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for id in ids {
            let label =
                d.base.parameters.iter().find(|p| &p.id == id).map_or(id.as_str(), |p| &p.label);
            let name = ballbar_diagnose::parameter_name(id, label);
            if !out.contains(&name) {
                out.push(name);
            }
        }
        out
    };
    for (b, al) in base.iter().zip(&d.base_aliases.aliases) {
        let listed = aliased.iter().any(|a| {
            a.subject.kind == b.kind
                && a.subject.axis == b.axis
                && a.description.as_deref() == Some(b.description.as_str())
        });
        let own = d.aliased.iter().any(
            |a| matches!(&al.candidate, ballbar_fit::alias::Candidate::Term(e) if *e == a.effect),
        );
        if !listed && !own {
            aliased.push(doc::Aliased {
                subject: doc::Subject {
                    kind: b.kind.clone(),
                    axis: b.axis.clone(),
                    switched_by: None,
                },
                description: Some(b.description.clone()),
                // The carriers' names, as the diagnosis's own entries give them.
                with: named(&b.with),
                test_to_separate: b.test_to_separate.clone(),
                visible_share: b.visible_share,
                alternative: b.alternative.clone(),
                moves: b.moves.clone(),
            });
        }
    }
    let declined = d
        .declined
        .iter()
        .map(|x| doc::Declined {
            subject: subject(&x.effect),
            description: describe(&x.effect, lags),
            why: why(&x.verdict),
        })
        .collect();
    let runs = runs
        .iter()
        .enumerate()
        .map(|(r, run)| {
            let (b, a) = (
                metrics::figures(run, &d.base.residuals[r]),
                metrics::figures(run, &d.augmented.residuals[r]),
            );
            doc::RunFigures {
                run: run.name(),
                placement: ballbar_report::fit_report::placement_key(run).into(),
                rms_before_um: b.rms * 1e3,
                rms_after_um: a.rms * 1e3,
                g_before_um: b.g * 1e3,
                g_after_um: a.g * 1e3,
            }
        })
        .collect();
    doc::Diagnosis {
        format: doc::FORMAT.into(),
        machine: d.machine.clone(),
        gap: gap(&d.gap),
        effects: Some(effects),
        aliased,
        declined,
        notes: d.notes.clone(),
        cross_validation: d.cross_validation.clone(),
        folds: d
            .schemes
            .iter()
            .map(|(k, why)| doc::Fold { kind: k.name().into(), description: why.clone() })
            .collect(),
        held_out: doc::HeldOut {
            folds: d.held_out.folds.map(|f| f.name().into()),
            rms_before_um: d.held_out.before_um,
            rms_after_um: d.held_out.after_um,
            noise_floor_um: d.held_out.noise_um,
            shrink: d.held_out.shrink,
            excess_closed: d.held_out.excess_closed,
            noise_floor_u_um: d.held_out.noise_u_um,
            excess: d.held_out.excess.as_ref().map(excess_share),
        },
        unexplained: d.unexplained.as_ref().map(|u| doc::Unexplained {
            folds: Some(u.folds.name().into()),
            share_left: u.share_left,
            excess_left: excess::left_from_energy_share(u.share_left),
            excess_rms_um: u.excess_rms_um,
            where_: u.where_.clone(),
            nearest: u
                .nearest
                .iter()
                .map(|(e, share)| doc::Nearest {
                    subject: subject(e),
                    description: describe(e, lags),
                    share_closed: *share,
                    excess_closed: excess::closed_from_energy_share(*share),
                })
                .collect(),
        }),
        candidates_screened: Some(d.candidates_screened),
        runs,
        assumed: Vec::new(),
        vendor_comparison: None,
        run_radius: Some({
            let r = ballbar_diagnose::RunRadius::of(&d.model_effects, &d.declined, &d.aliased);
            doc::RunRadius {
                treatment: r.treatment.into(),
                status: r.status.into(),
                description: r.description,
            }
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::{describe, parameters_text, uncertainties, verdict_text};
    use ballbar_diagnose::{Accepted, SchemeKind, Verdict};
    use ballbar_model::{Effect, Plane};

    fn servo_mismatch(plane: Plane) -> Accepted {
        Accepted {
            effect: Effect::ServoMismatch { plane },
            parameters: vec![("value_um".into(), 9.80612)],
            coefficients: vec![(format!("M{}", plane.name()), 9.80612, 0.0106, "µm")],
            uncertainties: vec![],
            held_out_rms_before_um: 2.2,
            held_out_rms_after_um: 0.2,
            folds: SchemeKind::Quarters,
            held_out_g_before_um: 7.0,
            held_out_g_after_um: 1.4,
            held_out_excess_closed: ballbar_diagnose::excess::closed(2.2, 0.2, 0.19),
            held_out_excess: ballbar_diagnose::excess::share(
                2.2,
                0.2,
                0.19,
                &ballbar_diagnose::excess::Chance {
                    floor_u: 0.002,
                    mean_square_var: 1e-6,
                    cross_var_per_excess: 0.0,
                },
            ),
            shrink: 0.91,
            shrink_interval: [0.9, 0.92],
            f_statistic: 1_108_678.0,
            held_out_t: 614.8,
            note: None,
        }
    }

    /// Beside per-axis lags, one plane's mismatch term is the sum of the three planes' terms,
    /// and is named so whichever plane carries it; without lags (the paper's model) it is that
    /// plane's own.
    #[test]
    fn a_plane_term_beside_per_axis_lags_is_named_the_sum_of_the_three() {
        for plane in Plane::PLANAR {
            let name = describe(&Effect::ServoMismatch { plane }, true);
            assert!(
                name.contains("the sum M_XY + M_YZ + M_ZX of the three planes' terms"),
                "{name}"
            );
            assert!(!name.starts_with(&format!("servo mismatch {plane}")), "{name}");
        }
        assert_eq!(
            describe(&Effect::ServoMismatch { plane: Plane::YZ }, false),
            Effect::ServoMismatch { plane: Plane::YZ }.describe()
        );
    }

    /// The F statistic is a partial-F in three significant digits, and an effect's value
    /// carries its unit and its uncertainty (its one coefficient's).
    #[test]
    fn the_statistics_and_the_parameters_read_without_a_manual() {
        let e = servo_mismatch(Plane::ZX);
        assert_eq!(uncertainties(&e), vec![("value_um".to_string(), 0.0106)]);
        assert_eq!(parameters_text(&e), "9.806 ± 0.011 µm");
        assert_eq!(
            verdict_text(&Verdict::F { f: 4.2, needed: 23.9 }),
            "partial-F 4.2 below 23.9 (its 1e-6 false-alarm level)"
        );
        let v = verdict_text(&Verdict::HeldOut {
            f: 40.0,
            before_um: 0.5,
            after_um: 0.49,
            t: 1.2,
            folds: SchemeKind::Quarters,
        });
        assert!(v.ends_with("a gain 1.2 standard errors from zero, below 3"), "{v}");
    }
}

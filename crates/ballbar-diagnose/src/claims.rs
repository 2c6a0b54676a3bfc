//! Step 5 of the method: the final fit's figures, the held-out claims, the gap left
//! unexplained and the notes.
//!
//! The accepted effects, as refined and selected, are added to the base model and fitted
//! exactly: their parameters and uncertainties come from that fit. The held-out RMS before
//! and after each effect is reported with the share of the excess above the noise it closes
//! (the gap an engineer means, defined once in [`excess`](crate::excess), with its interval from
//! the floor's uncertainty and the held-out samples' own chance, or not determined where the
//! held-out excess is within its uncertainty of zero: [`excess::share`](crate::excess::share)), the shrink of the RMS itself
//! ± two jackknife standard errors over the held-out groups, and the held-out ISO 230-4 G; the effects together are claimed on the
//! folds that ask the user's question ([`Diagnosis::held_out`](crate::Diagnosis::held_out): later runs when a
//! time-dependent effect is among them). When the base's held-out gap is significant
//! ([`SIGNIFICANT_GAP`] times the noise floor) and the accepted effects leave most of it
//! ([`UNEXPLAINED_SHARE`]), the gap is reported as unexplained ([`Unexplained`]) with where
//! it lies and the nearest candidates with how little they close, rather than naming the
//! nearest. What no candidate can reach is said in [`Diagnosis::notes`](crate::Diagnosis::notes) (a transient where a
//! run starts or ends at a reversal).
//!

use std::ops::Range;

use ballbar_fit::{Fit, FitError, fit};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Axis, Design, Effect, KernelSource, Run};

use crate::library::{self, candidate_columns, candidate_model, sample_rate};
use crate::selection::{
    Eval, Evaluator, Selection, Selector, Step, nuisance_chance, set_refit_chance,
};
use crate::{
    Accepted, Declined, DiagnoseError, Gap, SchemeKind, Verdict, engine, excess, folds, localise,
};

/// Held-out RMS (mm) of the base model and of the base plus `effects`, by the diagnosis's own
/// grouped cross-validation: the same units and folds as [`diagnose`](crate::diagnose), each fold's fit on
/// the others, a held-out run's centring fitted on it when the run is not in training. With the
/// true effects of a simulation at their true non-linear parameters, an oracle for the
/// diagnosis's held-out figures.
pub fn held_out_rms(
    spec: &MachineSpec,
    options: ModelOptions,
    kernels: &dyn KernelSource,
    runs: &[Run],
    effects: &[Effect],
    threads: usize,
) -> Result<(f64, f64), DiagnoseError> {
    let model0 = Model::with_kernels(spec.clone(), options, kernels)?;
    let (design0, _) =
        ballbar_fit::switch::switch_at_lagged_reversals(Design::new(&model0, runs)?, threads)?;
    let fit0 = fit(&design0, threads)?;
    let (all, refs, usable) =
        candidate_model(&library::bare(spec), library::BARE_OPTIONS, kernels, effects)?;
    let cand = design0.with_model(&all)?;
    let (cand_cols, columns) = candidate_columns(&cand, &refs);
    let cols: Vec<usize> = columns.iter().flatten().copied().collect();
    let splits = folds::splits(runs);
    let mut blocks = engine::build(
        &design0,
        &fit0.residuals,
        &fit0.values,
        &cand,
        &cand_cols,
        &splits.units,
        std::slice::from_ref(&cols),
        threads,
    )?;
    let noise = localise::noise_floor(runs, &fit0.residuals);
    set_refit_chance(&mut blocks, &usable, &columns, &noise, sample_rate(runs));
    blocks.nuisance_chance = nuisance_chance(&noise);
    // The scheme the diagnosis claims on: later runs for a time-dependent effect; else the
    // primary, or the secondary where some fold of the primary cannot determine the effects.
    let (schemes, secondary, forward) = splits.schemes();
    let ev = Evaluator::new(&blocks, &schemes, noise.sigma * noise.sigma);
    let s = match forward {
        Some(f) if effects.iter().any(Effect::is_time_dependent) => f,
        _ => {
            let (b, w) = (ev.eval(0, &[])?, ev.eval(0, &cols)?);
            let all_units: Vec<usize> = (0..blocks.units.len()).collect();
            let k = blocks.fit(&all_units, 0, &cols)?.rank - blocks.fit(&all_units, 0, &[])?.rank;
            match secondary {
                Some(sec) if !ev.judgeable(0, &w, &b, &cols, k) => sec,
                _ => 0,
            }
        }
    };
    let (b, w) = (ev.eval(s, &[])?, ev.eval(s, &cols)?);
    Ok((b.rms(), w.rms()))
}

/// A gap is significant when the base model's held-out RMS exceeds the noise floor by this
/// factor (its energy by 56 %): the noise floor is itself estimated (from repeats, or from the
/// residual's second differences), within about ten per cent on real bars, so a smaller excess
/// may be the noise model's error rather than structure.
pub const SIGNIFICANT_GAP: f64 = 1.25;

/// A significant gap is reported as unexplained when the accepted effects leave more than this
/// share of its held-out excess energy: most of it (√0.5 = 71 % of its excess RMS,
/// [`excess::left_from_energy_share`](crate::excess::left_from_energy_share), which is how it is stated).
pub const UNEXPLAINED_SHARE: f64 = 0.5;

/// The held-out figures of the accepted effects together.
#[derive(Clone, Debug)]
pub struct HeldOut {
    /// The folds (`None` when there was no candidate to hold anything out for).
    pub folds: Option<SchemeKind>,
    /// Held-out RMS of the base model, µm.
    pub before_um: f64,
    /// With the accepted effects, µm.
    pub after_um: f64,
    /// The noise floor, µm (what no model can go below).
    pub noise_um: f64,
    /// Its standard uncertainty, µm ([`localise::noise_floor`]).
    pub noise_u_um: f64,
    /// `1 - after/before` of the RMS itself.
    pub shrink: f64,
    /// The share of the excess above the noise the effects close ([`excess::closed`](crate::excess::closed));
    /// NaN where it is not determined.
    pub excess_closed: f64,
    /// That share with its interval, or not determined, in µm ([`excess::share`]); `None`
    /// without folds.
    pub excess: Option<excess::Share>,
}

/// Structure the accepted effects leave unexplained: most of a significant gap.
#[derive(Clone, Debug)]
pub struct Unexplained {
    /// The folds it was measured on.
    pub folds: SchemeKind,
    /// Share of the base model's held-out excess energy over the noise still left
    /// ([`excess::left_from_energy_share`](crate::excess::left_from_energy_share) gives the share of the excess stated).
    pub share_left: f64,
    /// RMS of that excess, µm (`sqrt(held-out MS - noise variance)`).
    pub excess_rms_um: f64,
    /// Where the base model's residual has its excess (plane, direction, arc, share), its
    /// locking and its largest spectral lines, in words: where the gap lies before any effect.
    pub where_: Vec<String>,
    /// The nearest candidates with the share of the base's held-out excess *energy* each closes
    /// ([`excess::closed_from_energy_share`](crate::excess::closed_from_energy_share) gives the share of the excess stated).
    pub nearest: Vec<(Effect, f64)>,
}

/// The gap left unexplained: when the base model's held-out RMS is [`SIGNIFICANT_GAP`] times
/// the noise floor or more and the accepted effects leave more than [`UNEXPLAINED_SHARE`] of
/// its excess, where it lies and the nearest candidates with how little they close.
pub(crate) fn unexplained(
    base: &Eval,
    last: &Eval,
    declined: &[Declined],
    gap: &Gap,
    scheme: &folds::Scheme,
) -> Option<Unexplained> {
    let noise = base.noise_var.sqrt();
    if base.rms() < SIGNIFICANT_GAP * noise {
        return None;
    }
    let (e0, e1) = (base.excess(), last.excess());
    if e0 <= 0.0 || e1 <= UNEXPLAINED_SHARE * e0 {
        return None;
    }
    let per_sample0 = e0 / base.n().max(1) as f64;
    let nearest = declined
        .iter()
        .filter_map(|d| match d.verdict {
            Verdict::HeldOut { before_um, after_um, .. }
            | Verdict::NotMaterial { before_um, after_um, .. } => Some((
                d.effect.clone(),
                (before_um * before_um - after_um * after_um) * 1e-6 / per_sample0,
            )),
            _ => None,
        })
        .filter(|(_, share)| *share > 0.0)
        .take(3)
        .collect();
    let mut where_: Vec<String> = gap
        .where_
        .iter()
        .take(3)
        .map(|w| match (&w.axis, &w.run) {
            // A rotary-axis run: its turning axis's sector, in that axis's degrees.
            (Some(axis), Some(run)) => format!(
                "{axis} run {run} ({}, {}): {axis} {:.0}°-{:.0}°: {:.0} % of the excess",
                w.plane,
                w.direction,
                w.sector_deg[0],
                w.sector_deg[1],
                100.0 * w.share
            ),
            _ => format!(
                "{} {} {:.0}°-{:.0}°: {:.0} % of the excess{}",
                w.plane,
                w.direction,
                w.sector_deg[0],
                w.sector_deg[1],
                100.0 * w.share,
                if w.reversals.is_empty() {
                    String::new()
                } else {
                    format!(" (reversals of {})", w.reversals.join(", "))
                }
            ),
        })
        .collect();
    where_.push(format!("locking: {} ({})", gap.locking.verdict, gap.locking.why));
    if let Some(p) = gap.angle_spectrum.first() {
        where_.push(format!(
            "largest line against angle: {:.1} per turn, {:.2} µm",
            p.at, p.amplitude_um
        ));
    }
    if let Some(p) = gap.time_spectrum.first() {
        where_.push(format!("largest line against time: {:.2} Hz, {:.2} µm", p.at, p.amplitude_um));
    }
    Some(Unexplained {
        folds: scheme.kind,
        share_left: e1 / e0,
        excess_rms_um: (e1 / last.n().max(1) as f64).sqrt() * 1e3,
        where_,
        nearest,
    })
}

/// How long after a reversal a transient is looked for at a run's ends, s: the longest decay
/// time of the domain's reversal spikes (20-150 ms).
pub(crate) const END_WINDOW_S: f64 = 0.15;

/// An axis is at rest at a run's end when its speed there is below this share of the path
/// speed (a circle's axis at its extreme: the speed is that share of the feed within ±3° of
/// the reversal).
pub(crate) const END_AT_REST: f64 = 0.05;

/// The residual at a run's ends is worth a note when those windows hold this many times their
/// share of the samples, and at least [`END_NOTE_SHARE`] of the residual energy.
pub(crate) const END_NOTE_FACTOR: f64 = 3.0;

/// See [`END_NOTE_FACTOR`].
pub(crate) const END_NOTE_SHARE: f64 = 0.1;

/// Notes on transients at the ends of runs that start or end at a reversal of one of their
/// axes (a full circle from 180° starts and ends at X's reversal): the model's reversal
/// effects (spike, stick-slip) begin at a reversal inside a run, so none can describe what
/// follows a reversal at the first sample, whose lead-in is not in the run. When the first
/// and last [`END_WINDOW_S`] of such runs hold much of the residual the model leaves, the note
/// says so with the figures.
pub(crate) fn run_end_notes(runs: &[Run], residuals: &[Vec<f64>]) -> Vec<String> {
    let total: f64 = residuals.iter().flatten().map(|x| x * x).sum();
    let samples: usize = runs.iter().map(Run::len).sum();
    if total <= 0.0 || samples == 0 {
        return vec![];
    }
    let mut notes = Vec::new();
    for a in Axis::LINEAR {
        let (mut energy, mut count, mut names) = (0.0, 0usize, Vec::new());
        for (run, r) in runs.iter().zip(residuals) {
            let Some(q) = run.axis(a) else { continue };
            let n = run.len();
            let v_path = run.header.feed_mm_per_s();
            let (lo, hi) = q
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
            if n < 4 || hi - lo < 1.0 || v_path <= 0.0 {
                continue;
            }
            let (v, d): (Vec<f64>, Vec<f64>) = (0..n)
                .map(|i| ballbar_model::design::velocity_and_direction(&run.t_s, q, i))
                .unzip();
            let reversals = ballbar_model::design::reversal_times(&run.t_s, &v, &d);
            let (t0, t1) = (run.t_s[0], run.t_s[n - 1]);
            let mut window = vec![false; n];
            let mut any = false;
            // The start: at rest, and no reversal inside the window (a spike would begin there).
            if v[0].abs() < END_AT_REST * v_path
                && reversals.first().is_none_or(|&t| t > t0 + END_WINDOW_S)
            {
                run.t_s
                    .iter()
                    .enumerate()
                    .filter(|&(_, &t)| t - t0 <= END_WINDOW_S)
                    .for_each(|(i, _)| window[i] = true);
                any = true;
            }
            // The end: at rest, and what follows the reversal is after the run.
            if v[n - 1].abs() < END_AT_REST * v_path {
                run.t_s
                    .iter()
                    .enumerate()
                    .filter(|&(_, &t)| t1 - t <= END_WINDOW_S)
                    .for_each(|(i, _)| window[i] = true);
                any = true;
            }
            if any {
                energy +=
                    window.iter().zip(r).filter(|(w, _)| **w).map(|(_, x)| x * x).sum::<f64>();
                count += window.iter().filter(|w| **w).count();
                names.push(run.name());
            }
        }
        let (e_share, n_share) = (energy / total, count as f64 / samples as f64);
        if count > 0 && e_share >= END_NOTE_SHARE && e_share >= END_NOTE_FACTOR * n_share {
            notes.push(format!(
                "{} start or end where {a} reverses (its speed is zero at the first or last sample): the first and last {:.2} s there hold {:.0} % of the residual the model leaves, in {:.1} % of the samples. No candidate can describe a transient there: the model's reversal effects begin at a reversal inside a run, and the lead-in over which this one began is not in the run. Runs that start between reversals (at 45°, say), or that keep the lead-in, would show it.",
                names.join(", "),
                END_WINDOW_S,
                100.0 * e_share,
                100.0 * n_share
            ));
        }
    }
    notes
}

/// The mean over runs of the ISO 230-4 G (mm) of each run's held-out residual trace, for the
/// base plus the first `k` accepted effects, `k = 0..=accepted.len()`. Each sample's residual
/// comes from the fit of the fold that held it out; a run's held-out samples, gathered over
/// the folds (a whole run in one fold when repeats or feeds are left out, its quarters or
/// halves in several otherwise), make one trace, whose G is taken about its least-squares
/// circle (so a held-out run's own centring does not enter).
#[allow(clippy::too_many_arguments)]
pub(crate) fn held_out_g(
    design0: &Design<'_>,
    fit0: &Fit,
    cand: &Design<'_>,
    cand_cols: &[usize],
    blocks: &engine::Blocks,
    folds: &[(Vec<usize>, Vec<usize>)],
    columns: &[Vec<usize>],
    accepted: &[usize],
    threads: usize,
) -> Result<Vec<f64>, FitError> {
    let runs = design0.runs;
    // Per run: base columns and block, candidate block, linear targets.
    let fills = ballbar_model::parallel::par_map(
        runs.len(),
        threads,
        |r| -> Result<(Vec<usize>, Vec<f64>, Vec<f64>, Vec<f64>), FitError> {
            let m = runs[r].len();
            let cols: Vec<usize> =
                (0..design0.n_machine).chain(design0.centring_columns(r)).collect();
            let mut scratch = ballbar_model::BlockScratch::default();
            let mut a = vec![0.0; m * cols.len()];
            let mut dummy = vec![0.0; m];
            design0.fill_run(r, &cols, &mut a, &mut dummy, &mut scratch)?;
            let mut c = vec![0.0; m * cand_cols.len()];
            cand.fill_run(r, cand_cols, &mut c, &mut dummy, &mut scratch)?;
            let targets = (0..m)
                .map(|i| {
                    fit0.residuals[r][i]
                        + cols
                            .iter()
                            .enumerate()
                            .map(|(j, &g)| a[j * m + i] * fit0.values[g])
                            .sum::<f64>()
                })
                .collect();
            Ok((cols, a, c, targets))
        },
    );
    let fills = fills.into_iter().collect::<Result<Vec<_>, _>>()?;
    // Each run's angles, for the traces' least-squares circles.
    let angles: Vec<Option<Vec<f64>>> = runs.iter().map(ballbar_fit::metrics::angles).collect();
    let mut out = Vec::with_capacity(accepted.len() + 1);
    for k in 0..=accepted.len() {
        let set: Vec<usize> =
            accepted[..k].iter().flat_map(|&i| columns[i].iter().copied()).collect();
        // Each fold's held-out traces (run, samples, residual), the folds on the worker
        // threads; each fold's traces are its own numbers whatever the thread count.
        let traces = ballbar_model::parallel::par_map(
            folds.len(),
            threads,
            |fi| -> Result<Vec<(usize, Range<usize>, Vec<f64>)>, FitError> {
                let (train, held) = &folds[fi];
                let f = blocks.fit(train, 0, &set)?;
                // The base combinations the training cannot determine, as the held-out error
                // takes them: fitted on the held-out runs.
                let refit =
                    |h: usize| !train.iter().any(|&t| blocks.units[t].run == blocks.units[h].run);
                let shift = blocks.held_out_shift(train, held, &f, 0, &set, refit);
                let theta_of = |g: usize| f.theta[g] + shift.get(g).copied().unwrap_or(0.0);
                let mut out = Vec::with_capacity(held.len());
                for &h in held {
                    let u = &blocks.units[h];
                    if angles[u.run].is_none() {
                        continue;
                    }
                    let (cols, a, c, t) = &fills[u.run];
                    let m = runs[u.run].len();
                    let mut trace: Vec<f64> = u
                        .range
                        .clone()
                        .map(|i| {
                            let base: f64 = cols
                                .iter()
                                .enumerate()
                                .map(|(j, &g)| a[j * m + i] * theta_of(g))
                                .sum();
                            let eff: f64 =
                                set.iter().zip(&f.beta).map(|(&col, b)| c[col * m + i] * b).sum();
                            t[i] - base - eff
                        })
                        .collect();
                    // A run not in training: its own columns (a vibration's phase) fitted on
                    // it, as in the held-out error (G is about the least-squares circle: the
                    // centring does not enter).
                    let in_training = train.iter().any(|&x| blocks.units[x].run == u.run);
                    let own: Vec<usize> = set
                        .iter()
                        .copied()
                        .filter(|&col| blocks.col_run[col] == Some(u.run))
                        .collect();
                    if !in_training && !own.is_empty() {
                        let x = faer::Mat::<f64>::from_fn(u.range.len(), own.len(), |i, j| {
                            c[own[j] * m + u.range.start + i]
                        });
                        if let Ok((g, _)) = ballbar_fit::lstsq(x.as_ref(), &trace) {
                            for (i, v) in trace.iter_mut().enumerate() {
                                *v -= (0..own.len()).map(|j| x[(i, j)] * g[j]).sum::<f64>();
                            }
                        }
                    }
                    out.push((u.run, u.range.clone(), trace));
                }
                Ok(out)
            },
        );
        // Per run, its held-out samples (angle, residual) gathered over the folds in order.
        let mut per_run: Vec<(Vec<f64>, Vec<f64>)> = vec![(Vec::new(), Vec::new()); runs.len()];
        for fold in traces {
            for (r, range, trace) in fold? {
                let theta = angles[r].as_ref().expect("a trace only of a run with angles");
                per_run[r].0.extend_from_slice(&theta[range]);
                per_run[r].1.extend(trace);
            }
        }
        let (mut sum, mut n) = (0.0, 0usize);
        for (theta, trace) in per_run.iter().filter(|p| !p.0.is_empty()) {
            let about = ballbar_fit::metrics::about_lsq_circle(theta, trace);
            let (lo, hi) = about
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
            sum += hi - lo;
            n += 1;
        }
        out.push(if n > 0 { sum / n as f64 } else { 0.0 });
    }
    Ok(out)
}

/// What a run's own bar length is and what it cannot be told from, in words: the note of an
/// accepted [`Effect::BarLengthDrift`] and of the diagnosis's [`crate::RunRadius`].
pub const BAR_DRIFT_ALIAS: &str = "each run's own mean radius (the bar's length in that run: its temperature, a recalibration), which predicts no other run: a saved model carries it and `predict` leaves it out of a new run; the spread is about the runs' mean, which the base holds (a common scale of the axes at one radius, or one bar length). In a circle test a common thermal growth of the axes, a common servo lag's loss at one feed and a bar growing with time change the radius alike: what separates the bar from the machine is the bar re-measured in its calibrator between runs (the machine's radius changes do not move it), or a law of the machine in time or feed that predicts later runs, which the diagnosis tries first (each round takes a run's own bar length only when nothing else passes)";

/// A note on an accepted effect whose value needs reading: the paper's plane servo term
/// accepted next to per-axis lags. The lags make any three plane terms whose sum is zero
/// (`M_XY = V(τ_Y - τ_X)`, ...), so one plane's term completes them and takes the sum of the
/// three: which plane carries it is arbitrary.
pub(crate) fn note_for(e: &Effect, base: &Model) -> Option<String> {
    if let Effect::Vibration { .. } = e {
        return Some("each run has its own phase (a run does not start in step with the vibration): the amplitude is the RMS over the runs it shows in; a saved model carries the effect, and `predict` leaves it out of a new run, whose phase it cannot know".into());
    }
    if let Effect::BarLengthDrift = e {
        return Some(BAR_DRIFT_ALIAS.into());
    }
    let Effect::ServoMismatch { .. } = e else { return None };
    let ids: Vec<String> = base.parameters().into_iter().map(|p| p.id).collect();
    let lags = ["TX", "TY", "TZ"].iter().all(|id| ids.iter().any(|x| x == id));
    lags.then(|| {
        "with one servo lag per axis in the model, any one plane's mismatch term completes the lags: its value is the sum M_XY + M_YZ + M_ZX of the three plane terms, the part no set of per-axis lags can make; which plane carries it is arbitrary".to_string()
    })
}

/// The claim for the accepted effects together, on the folds that ask the user's question:
/// later runs when a time-dependent effect is among them, else the secondary scheme when an
/// effect needed it, else the primary. The scheme, the held-out figures before and after the
/// effects, and the gap they leave unexplained.
pub(crate) fn claim(
    sel: &Selector<'_>,
    selection: &Selection,
    declined: &[Declined],
    gap: &Gap,
    noise: &localise::Noise,
) -> Result<(usize, HeldOut, Option<Unexplained>), FitError> {
    let noise_sigma = noise.sigma;
    let ev = sel.ev;
    let time_dependent = selection.accepted.iter().any(|&i| sel.effects[i].is_time_dependent());
    let claim_scheme = if time_dependent {
        sel.forward.unwrap_or(0)
    } else {
        selection.steps.iter().map(|s| s.scheme).max().unwrap_or(0)
    };
    let current = selection.columns(sel.columns, selection.accepted.len());
    let base_eval = ev.eval(claim_scheme, &[])?;
    let final_eval = ev.eval(claim_scheme, &current)?;
    let share = share_um(base_eval.rms(), final_eval.rms(), noise, base_eval.n());
    let overall = HeldOut {
        folds: Some(ev.schemes[claim_scheme].kind),
        before_um: base_eval.rms() * 1e3,
        after_um: final_eval.rms() * 1e3,
        noise_um: noise_sigma * 1e3,
        noise_u_um: noise.sigma_u * 1e3,
        shrink: 1.0 - final_eval.rms() / base_eval.rms().max(f64::MIN_POSITIVE),
        excess_closed: share.closed,
        excess: Some(share),
    };
    let unexplained =
        unexplained(&base_eval, &final_eval, declined, gap, &ev.schemes[claim_scheme]);
    Ok((claim_scheme, overall, unexplained))
}

/// The share of the excess closed from held-out RMS `before` to `after` (mm) over `n` samples
/// against the floor `noise` ([`excess::share`]), its figures in µm.
fn share_um(before: f64, after: f64, noise: &localise::Noise, n: usize) -> excess::Share {
    let s = excess::share(before, after, noise.sigma, &excess::Chance::of(noise, n));
    excess::Share {
        excess_before: s.excess_before * 1e3,
        excess_before_bound: s.excess_before_bound * 1e3,
        excess_energy_u: s.excess_energy_u * 1e6,
        ..s
    }
}

/// The accepted effects as reported: their parameters, coefficients and uncertainties from
/// `fit_f` (the base model plus the effects, `model_f`, fitted exactly), their held-out
/// figures from the selection's steps (on `schemes`) and the held-out G of each step
/// (`g_steps`, mm, from [`held_out_g`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn accepted(
    model_f: &Model,
    fit_f: &Fit,
    effects: &[Effect],
    steps: &[Step],
    schemes: &[folds::Scheme],
    g_steps: &[f64],
    noise: &localise::Noise,
    base: &Model,
) -> Vec<Accepted> {
    let mut accepted = Vec::new();
    for (step, ((e, ids), st)) in effects.iter().zip(&model_f.effect_ids).zip(steps).enumerate() {
        // A run term's parameters are `ID@run`, in run order; a run's set is kept only when all
        // of it is estimable (in runs it cannot act in, a vibration of X in a YZ run, none is).
        let of_effect = |i: usize| {
            let p = &fit_f.parameters[i];
            let (term, run) =
                p.id.split_once('@')
                    .filter(|_| p.class.is_nuisance())
                    .map(|(t, r)| (t, Some(r)))
                    .unwrap_or((p.id.as_str(), None));
            ids.iter().any(|x| x == term).then_some(run)
        };
        let idx: Vec<usize> = (0..fit_f.parameters.len())
            .filter(|&i| match of_effect(i) {
                Some(None) => true,
                Some(Some(run)) => (0..fit_f.parameters.len())
                    .filter(|&j| of_effect(j) == Some(Some(run)))
                    .all(|j| fit_f.estimable[j]),
                None => false,
            })
            .collect();
        // What the effect's figures are: for a run's own bar length, each run's offset alone
        // is not determined (their mean is a common scale of the axes at one radius, or one
        // bar length), each offset from their mean is, and those are its coefficients.
        type Coefficient = (String, f64, f64, &'static str);
        let (parameters, uncertainties, coefficients): (_, _, Vec<Coefficient>) =
            if *e == Effect::BarLengthDrift {
                let idx: Vec<usize> = (0..fit_f.parameters.len())
                    .filter(|&i| matches!(of_effect(i), Some(Some(_))))
                    .collect();
                let n = idx.len().max(1) as f64;
                let about_mean = |r: usize| -> Vec<(usize, f64)> {
                    idx.iter()
                        .enumerate()
                        .map(|(s, &j)| (j, if s == r { 1.0 - 1.0 / n } else { -1.0 / n }))
                        .collect()
                };
                let coefficients: Vec<Coefficient> = idx
                    .iter()
                    .enumerate()
                    .map(|(r, &i)| {
                        let p = &fit_f.parameters[i];
                        let f = fit_f.functional(&about_mean(r));
                        let k = p.unit.display_factor();
                        (p.id.clone(), f.value * k, f.std_uncertainty * k, p.unit.display_name())
                    })
                    .collect();
                let offsets: Vec<f64> = coefficients.iter().map(|c| c.1 * 1e-3).collect();
                (e.report(&offsets), vec![], coefficients)
            } else {
                let coeffs: Vec<f64> = idx.iter().map(|&i| fit_f.values[i]).collect();
                let uncertainties = e
                    .linear_parameters(&coeffs)
                    .into_iter()
                    .map(|(name, w)| {
                        let pairs: Vec<(usize, f64)> = idx.iter().copied().zip(w).collect();
                        (name, fit_f.functional(&pairs).std_uncertainty)
                    })
                    .collect();
                let coefficients = idx
                    .iter()
                    .map(|&i| {
                        let p = &fit_f.parameters[i];
                        let k = p.unit.display_factor();
                        (
                            p.id.clone(),
                            fit_f.values[i] * k,
                            fit_f.std_uncertainty[i] * k,
                            p.unit.display_name(),
                        )
                    })
                    .collect();
                (e.report(&coeffs), uncertainties, coefficients)
            };
        let excess = share_um(st.before, st.after, noise, st.eval.n());
        accepted.push(Accepted {
            effect: e.clone(),
            parameters,
            uncertainties,
            coefficients,
            held_out_rms_before_um: st.before * 1e3,
            held_out_rms_after_um: st.after * 1e3,
            folds: schemes[st.scheme].kind,
            held_out_g_before_um: g_steps[step] * 1e3,
            held_out_g_after_um: g_steps[step + 1] * 1e3,
            held_out_excess_closed: excess.closed,
            held_out_excess: excess,
            shrink: 1.0 - st.after / st.before.max(f64::MIN_POSITIVE),
            shrink_interval: st.interval,
            f_statistic: st.f,
            held_out_t: st.t,
            note: note_for(e, base),
        });
    }
    accepted
}

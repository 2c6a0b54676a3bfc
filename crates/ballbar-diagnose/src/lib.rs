//! The sim-to-real gap. The fitted base model is the simulation, the measured traces are the
//! real: this crate says where they still disagree ([`localise`]), which unmodelled effect
//! causes it ([`diagnose`]), and how far the gap shrinks on data not used to fit or to choose.
//!
//! # Method
//! 1. Fit the base model (exact chain, [`ballbar_fit::fit`]); localise its residuals and
//!    measure the noise floor ([`localise::noise_floor`]): a model of real bar noise (an AR(1)
//!    process seen through the instrument's moving average, plus white noise such as the
//!    readings' quantisation) fitted to robust variances of second differences, where what
//!    is smooth in time cancels and sparse spikes are trimmed: of the differences of repeats
//!    when there are repeats (what repeats cancels there, and what changed slowly between
//!    them, a drift, a thermal growth, a centring, cancels in the second differences), else of
//!    the residual itself. The gap's `noise_source` says which.
//! 2. The candidate library ([`library()`], the module [`library`](mod@library)): every effect
//!    the base model lacks, its non-linear parameters on a grid or at the peaks of a spectrum.
//! 3. Screening on all data ([`screening`]): each candidate added alone to the base, an F
//!    statistic against the correlated noise; a candidate the base model holds and the data do
//!    not determine is reported as aliased ([`Aliased`]).
//! 4. Selection ([`selection`]): greedy, by held-out prediction on folds that hold out what the
//!    user varies ([`folds`]), each accepted effect material ([`MATERIAL`]) and standing by
//!    itself in the final set; the candidates declined with why ([`Declined`]).
//! 5. Claims ([`claims`]): the accepted effects fitted exactly with the base, their held-out
//!    figures and the claim for them together ([`Diagnosis::held_out`]), the gap left
//!    unexplained ([`Unexplained`]) and what no candidate can reach ([`Diagnosis::notes`]).
//!
//! [`diagnose`] runs the steps in turn; the QR-block engine that tries candidates without
//! refactoring the base is [`engine`], and what "the gap" and the share of it an effect closes
//! mean is defined once in [`excess`].

pub mod claims;
pub mod engine;
pub mod excess;
pub mod folds;
pub mod library;
pub mod localise;
pub mod screening;
pub mod selection;

use ballbar_fit::{Fit, FitError, fit};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, Effect, KernelSource, ModelError, Run};
pub use claims::{HeldOut, SIGNIFICANT_GAP, UNEXPLAINED_SHARE, Unexplained, held_out_rms};
use claims::{held_out_g, note_for, run_end_notes, unexplained};
pub use folds::SchemeKind;
pub use library::{
    CYCLIC_PITCH_MM, FEED_EXPONENTS, GROWTH_TAU_MIN, SPIKE_TAU_MS, STICK_SLIP_MM_PER_MIN,
    cyclic_candidates, library, sample_rate, vibration_candidates,
};
use library::{candidate_columns, candidate_model};
pub use localise::{Gap, localise};
use screening::{ALIASED_F, ALIASED_VISIBLE, aliased_with, chi2_1e6};
use selection::{
    Eval, Evaluator, Step, describe_nuisances, nuisance_chance, refine, set_refit_chance,
};
pub use selection::{HELD_OUT_T, MATERIAL};

/// Errors of a diagnosis.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DiagnoseError {
    /// The model could not be built or evaluated.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// A fit failed.
    #[error(transparent)]
    Fit(#[from] FitError),
}

/// Options of a diagnosis.
#[derive(Clone, Debug)]
pub struct Options {
    /// Worker threads.
    pub threads: usize,
    /// At most this many effects are accepted.
    pub max_effects: usize,
    /// Screened candidates (best per kind and axis) that go on to cross-validation.
    pub shortlist: usize,
    /// Look only for these kinds (`reversal_spike`, ...); all when empty.
    pub kinds: Vec<String>,
    /// The base's backlash switches at the commanded reversal, not searched
    /// ([`ballbar_fit::switch`]).
    pub commanded_switch: bool,
}

impl Default for Options {
    fn default() -> Options {
        Options {
            threads: 2,
            max_effects: 4,
            shortlist: 10,
            kinds: Vec::new(),
            commanded_switch: false,
        }
    }
}

/// An accepted effect.
#[derive(Clone, Debug)]
pub struct Accepted {
    /// The effect, its non-linear parameters as refined.
    pub effect: Effect,
    /// Reported parameters (name with unit, value), from the final exact fit.
    pub parameters: Vec<(String, f64)>,
    /// The fitted coefficients with their standard uncertainties, display units: (id, value, u, unit).
    pub coefficients: Vec<(String, f64, f64, &'static str)>,
    /// The standard uncertainties of the reported parameters that are linear in the
    /// coefficients at the fitted shape (a spike's heights; [`Effect::linear_parameters`]),
    /// display units: (name, u), from the final fit's covariance.
    pub uncertainties: Vec<(String, f64)>,
    /// Held-out RMS before this effect was added (with the effects accepted before it), µm.
    pub held_out_rms_before_um: f64,
    /// Held-out RMS with it, µm.
    pub held_out_rms_after_um: f64,
    /// The folds that judged it and gave these figures.
    pub folds: SchemeKind,
    /// ISO 230-4 circular deviation G of each run's held-out trace (every sample from the fold
    /// that held it out) before this effect was added, mean over the runs, µm.
    pub held_out_g_before_um: f64,
    /// The same with it, µm.
    pub held_out_g_after_um: f64,
    /// The share of the held-out excess above the noise it closes
    /// ([`excess::closed`] of the two RMS figures and the noise floor): the gap an engineer
    /// means, the figure stated.
    pub held_out_excess_closed: f64,
    /// Shrink of the held-out RMS itself, `1 − after/before`, fraction; its interval below.
    pub shrink: f64,
    /// The interval.
    pub shrink_interval: [f64; 2],
    /// F statistic (noise-inflated) on all data.
    pub f_statistic: f64,
    /// Held-out gain over its standard error.
    pub held_out_t: f64,
    /// What the value means where that needs saying.
    pub note: Option<String>,
}

/// Why a shortlisted candidate was not accepted (in the last round it was tried in).
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// Its F statistic on all data (noise-inflated) is below the acceptance level.
    F {
        /// The statistic.
        f: f64,
        /// The level it had to reach (χ²(k) at 1e-6 over k).
        needed: f64,
    },
    /// It passed the F test, but its held-out gain did not stand three standard errors from
    /// zero (or was not positive).
    HeldOut {
        /// The F statistic.
        f: f64,
        /// Held-out RMS without it (with the effects accepted before), µm.
        before_um: f64,
        /// With it, µm.
        after_um: f64,
        /// Its held-out gain over the gain's standard error.
        t: f64,
        /// The folds.
        folds: SchemeKind,
    },
    /// Its held-out gain stands out from zero but closes less than [`MATERIAL`] of what the
    /// model still leaves above the noise on the held-out data: a near miss, not named.
    NotMaterial {
        /// The F statistic.
        f: f64,
        /// Held-out RMS without it, µm.
        before_um: f64,
        /// With it, µm.
        after_um: f64,
        /// The share of the held-out excess *energy* over the noise it closes (the selection's
        /// own figure; [`excess::closed_from_energy_share`] gives the share of the excess stated).
        share: f64,
        /// The folds.
        folds: SchemeKind,
    },
    /// No scheme of folds could judge it: the training of some fold cannot determine it (an
    /// effect seen only across set-ups that the folds hold out whole, a time-dependent effect
    /// in runs not spread over time).
    NotJudgeable {
        /// The schemes tried.
        tried: Vec<SchemeKind>,
    },
    /// It was accepted, but the other accepted effects made it redundant: leaving it out of
    /// the final set loses held-out gain only this many standard errors from zero, or less
    /// than [`MATERIAL`] of the excess.
    Redundant {
        /// Its held-out gain in the final set over the gain's standard error.
        t: f64,
    },
    /// It adds nothing to the model's rank (its columns are taken up by the accepted effects).
    NoRank,
    /// It passed both tests but was not accepted: the limit on the number of effects was
    /// reached.
    Passed,
}

impl Verdict {
    /// How close it came to acceptance, for ordering the near misses: the held-out share for a
    /// held-out verdict, the F statistic's share of its level below.
    fn closeness(&self) -> f64 {
        match self {
            Verdict::Passed => 4.0,
            Verdict::Redundant { .. } => 3.0,
            Verdict::NotMaterial { share, .. } => 2.0 + share.clamp(0.0, 0.99),
            Verdict::HeldOut { t, .. } => 1.0 + (t / HELD_OUT_T).clamp(0.0, 0.99),
            Verdict::F { f, needed } => (f / needed).clamp(0.0, 0.99),
            Verdict::NotJudgeable { .. } | Verdict::NoRank => -1.0,
        }
    }
}

/// A shortlisted candidate the evidence did not accept, with the figures that say why.
#[derive(Clone, Debug)]
pub struct Declined {
    /// The effect, its non-linear parameter as refined.
    pub effect: Effect,
    /// Why.
    pub verdict: Verdict,
}

/// An effect the tests cannot separate from the base model.
#[derive(Clone, Debug)]
pub struct Aliased {
    /// The effect.
    pub effect: Effect,
    /// The base parameters it would hide in (names).
    pub with: Vec<String>,
    /// Share of its energy outside the base model's span.
    pub visible_share: f64,
    /// The extra test that would separate it.
    pub test_to_separate: &'static str,
}

/// A diagnosis.
pub struct Diagnosis {
    /// The machine.
    pub machine: String,
    /// Where the gap lies.
    pub gap: Gap,
    /// Accepted effects, in the order accepted (most important first).
    pub effects: Vec<Accepted>,
    /// Effects aliased with the base model.
    pub aliased: Vec<Aliased>,
    /// The best candidates of each kind and axis that were tried and not accepted, with why
    /// (inside the noise: their F statistic or their held-out gain).
    pub declined: Vec<Declined>,
    /// What the diagnosis could not describe and why (a transient where a run starts or ends at
    /// a reversal, which no candidate reaches).
    pub notes: Vec<String>,
    /// How the data were split for held-out evaluation (the schemes' descriptions).
    pub cross_validation: String,
    /// The schemes of folds used: the primary first, then the secondary and the later runs
    /// where the runs have them.
    pub schemes: Vec<(SchemeKind, String)>,
    /// The claim for the accepted effects together, on the folds that ask the user's question
    /// (later runs when a time-dependent effect is among them).
    pub held_out: HeldOut,
    /// The gap the accepted effects leave unexplained, when it is most of a significant gap.
    pub unexplained: Option<Unexplained>,
    /// Candidates screened (grid points included).
    pub candidates_screened: usize,
    /// The base fit.
    pub base: Fit,
    /// Where the base's backlash switches ([`ballbar_fit::switch`]); the augmented fit's
    /// design switches there too.
    pub switch: ballbar_fit::switch::Switch,
    /// The fit of the base model plus the accepted effects.
    pub augmented: Fit,
    /// The accepted effects (as added to the model).
    pub model_effects: Vec<Effect>,
    /// The base fit's local quantities and aliases ([`ballbar_fit::alias`]): terms it lacks and
    /// set-up metadata the runs cannot tell from it, with the values each moves.
    pub base_aliases: ballbar_fit::alias::Assessment,
}

/// Diagnose the gap between a machine's base model and runs.
pub fn diagnose(
    spec: &MachineSpec,
    options: ModelOptions,
    kernels: &dyn KernelSource,
    runs: &[Run],
    opts: Options,
) -> Result<Diagnosis, DiagnoseError> {
    let threads = opts.threads.max(1);
    let model0 = Model::with_kernels(spec.clone(), options, kernels)?;
    // The backlash switches where the lagging axes reverse, not the commands: otherwise its
    // misplaced step is a spike at every reversal, which a candidate would then explain.
    let (design0, switch) = if opts.commanded_switch {
        (Design::new(&model0, runs)?, ballbar_fit::switch::Switch::commanded())
    } else {
        ballbar_fit::switch::switch_at_lagged_reversals(Design::new(&model0, runs)?, threads)?
    };
    let (fit0, fac0) = ballbar_fit::fit_factored(&design0, threads)?;
    // What the base takes for something else (terms it lacks, set-up metadata): listed with
    // the aliased candidates, with what each moves.
    let base_aliases = ballbar_fit::alias::assess(&design0, &fit0, &fac0, threads)?;
    drop(fac0);
    let mut gap = localise(runs, &fit0.residuals);
    let noise = localise::noise_floor(runs, &fit0.residuals);
    let inflation = noise.inflation();

    // The folds; without later runs to predict from earlier ones (one cycle of runs, or all at
    // one time) a time-dependent candidate could not be judged on what it claims (the next
    // runs), and interleaved folds would flatter it: it is not offered, and a note says so.
    let splits = folds::splits(runs);
    let mut notes_before = Vec::new();

    // The candidates and one model holding all their columns.
    let mut effects = library(&model0, runs);
    if splits.forward.is_none() && effects.iter().any(Effect::is_time_dependent) {
        effects.retain(|e| !e.is_time_dependent());
        notes_before.push(
            "thermal growth and drift not tried: no runs come after a start of the session that holds every plane in every direction, so nothing could judge them on later runs; repeat the test cycle later to see them"
                .to_string(),
        );
    }
    let (cyclic, position_spectrum) = cyclic_candidates(&model0, runs, &fit0.residuals);
    effects.extend(cyclic);
    effects.extend(vibration_candidates(&model0, runs, &fit0.residuals));
    gap.position_spectrum = position_spectrum;
    if !opts.kinds.is_empty() {
        effects.retain(|e| opts.kinds.iter().any(|k| k == e.kind()));
    }
    let bare = MachineSpec { terms: vec![], ..spec.clone() };
    // No terms, and options that add no reading terms: only the effects' own columns.
    let bare_options = ModelOptions {
        bar_length: ballbar_model::BarLength::Known(0.0),
        servo: ballbar_model::ServoVariant::AxisLag,
    };
    let (all, column_refs, usable) = candidate_model(&bare, bare_options, kernels, &effects)?;
    if column_refs.is_empty() {
        // Nothing to try (every kind filtered out, or none applies): the gap, and no effect.
        return Ok(Diagnosis {
            machine: spec.name.clone(),
            gap,
            effects: vec![],
            aliased: vec![],
            declined: vec![],
            notes: notes_before.into_iter().chain(run_end_notes(runs, &fit0.residuals)).collect(),
            cross_validation: "none: no candidate to try".into(),
            schemes: vec![],
            held_out: HeldOut {
                folds: None,
                before_um: f64::NAN,
                after_um: f64::NAN,
                noise_um: noise.sigma * 1e3,
                shrink: 0.0,
                excess_closed: f64::NAN,
            },
            unexplained: None,
            candidates_screened: 0,
            augmented: fit0.clone(),
            base: fit0,
            switch,
            model_effects: vec![],
            base_aliases,
        });
    }
    let cand_design = design0.with_model(&all)?;
    let (cand_cols, columns) = candidate_columns(&cand_design, &column_refs);

    // Pass 1: every candidate alone against the base, on all data.
    let units = &splits.units;
    let blocks = engine::build(
        &design0,
        &fit0.residuals,
        &fit0.values,
        &cand_design,
        &cand_cols,
        units,
        &columns,
        threads,
    )?;
    let all_units: Vec<usize> = (0..blocks.units.len()).collect();
    let m = design0.n_rows();
    let base_fit = blocks.fit(&all_units, 0, &[])?;
    let unreachable = blocks.unreachable(&all_units)?;
    let mut screened: Vec<(usize, f64, f64)> = Vec::new(); // (effect, F, gain)
    let mut aliased = Vec::new();
    for (j, cols) in columns.iter().enumerate() {
        ballbar_model::progress::update("diagnose: screening the candidates", j, columns.len());
        let cn: f64 = cols.iter().map(|&c| blocks.c_norm2[c]).sum();
        if cn <= 0.0 {
            continue;
        }
        let bn: f64 = cols.iter().map(|&c| unreachable[c]).sum();
        let visible = bn / cn;
        // What an effect of typical size would show outside the base, against the noise.
        let typical = usable[j].typical_size();
        let detectable = typical * typical * bn
            / cols.len() as f64
            / (noise.sigma * noise.sigma * inflation).max(f64::MIN_POSITIVE);
        let f = blocks.fit(&all_units, j, cols)?;
        let k = cols.len();
        let dof = m.saturating_sub(f.rank).max(1) as f64;
        let gain = base_fit.rss - f.rss;
        let fstat = (gain / k as f64) / (f.rss / dof * inflation);
        // Aliased: the base model takes up most of the candidate, and what it leaves would not
        // show at its typical size; and the data do not determine it otherwise: it adds less
        // than its full rank to the base's (some combination of it lies in the base's span,
        // to the fit's truncation), or its own F statistic does not pass the acceptance
        // level. A candidate the data determine is fitted and judged like any other, whatever
        // its typical size says (a common lag of 4 ms at two feeds, 256 times the signal
        // energy of the typical 1 ms, is not noise). A candidate that the base model leaves
        // mostly alone but that is small against the noise at its typical size (a spike of
        // 10 ms sampled every 8 ms) is not aliased with anything either.
        let estimable = f.rank >= base_fit.rank + k;
        if visible < ALIASED_VISIBLE
            && detectable < ALIASED_F
            && (!estimable || fstat < chi2_1e6(k) / k as f64)
        {
            // With what: project the candidate on the base (its coefficients in display units
            // times the parameter's column norm, the largest three).
            let with = aliased_with(&blocks, &all_units, cols, &design0)?;
            aliased.push(Aliased {
                effect: usable[j].clone(),
                with,
                visible_share: visible,
                test_to_separate: usable[j].separating_test(),
            });
            continue;
        }
        screened.push((j, fstat, gain));
    }
    let candidates_screened = columns.len();
    // Aliased effects: one entry per kind and axis.
    let mut seen = Vec::new();
    aliased.retain(|a: &Aliased| {
        // Grid effects (decay time, speed, pitch) once per kind and axis; the others (an
        // angular error about each direction, each degree) each.
        let key = match &a.effect {
            Effect::ReversalSpike { .. }
            | Effect::ReversalTransient { .. }
            | Effect::StickSlip { .. }
            | Effect::CyclicError { .. }
            | Effect::ThermalGrowth { .. }
            | Effect::FeedScaled { .. } => {
                format!("{} {:?}", a.effect.kind(), a.effect.axis_label())
            }
            other => format!("{other:?}"),
        };
        if seen.contains(&key) {
            false
        } else {
            seen.push(key);
            true
        }
    });

    // The shortlist: the best grid point of each kind and axis.
    screened.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut shortlist: Vec<usize> = Vec::new();
    let mut keys = Vec::new();
    for &(j, _, _) in &screened {
        let key = (usable[j].kind(), usable[j].axis_label());
        if !keys.contains(&key) {
            keys.push(key);
            shortlist.push(j);
        }
        if shortlist.len() >= opts.shortlist {
            break;
        }
    }

    // Greedy forward selection with grouped cross-validation, on the shortlist's effects with
    // their non-linear parameters refined by a parabola through the screening gains of the
    // neighbouring grid points (log scale): the selection, the held-out figures and the final
    // fit all use the effect as reported. (With the grid value, the misfit of an effect whose
    // decay time or speed lies between grid points is a structured residual that the next
    // round takes for another effect.)
    // The noise variance of a sample, inflated for its correlation, for the choice of a
    // spike's ringing.
    let noise_var = noise.sigma * noise.sigma * inflation;
    let refined: Vec<Effect> =
        shortlist.iter().map(|&j| refine(&usable, &screened, noise_var, j)).collect();
    let (short_model, short_refs, short_effects) =
        candidate_model(&bare, bare_options, kernels, &refined)?;
    let short_design = design0.with_model(&short_model)?;
    let (short_cand, short_columns) = candidate_columns(&short_design, &short_refs);
    let short_cols: Vec<usize> = short_columns.iter().flatten().copied().collect();
    let mut blocks2 = engine::build(
        &design0,
        &fit0.residuals,
        &fit0.values,
        &short_design,
        &short_cand,
        units,
        std::slice::from_ref(&short_cols),
        threads,
    )?;
    set_refit_chance(&mut blocks2, &short_effects, &short_columns, &noise, sample_rate(runs));
    blocks2.nuisance_chance = nuisance_chance(&noise);
    let blocks2 = blocks2;
    // The schemes: 0 the primary, then the secondary and the later runs where they exist.
    let (mut schemes, secondary, forward) = splits.schemes();
    describe_nuisances(&blocks2, &design0, &mut schemes);
    let ev = Evaluator::new(&blocks2, &schemes, noise.sigma * noise.sigma);
    let mut accepted_i: Vec<usize> = Vec::new();
    let mut accepted_stats: Vec<Step> = Vec::new();
    let mut current: Vec<usize> = Vec::new();
    let mut current_fit = blocks2.fit(&all_units, 0, &[])?;
    // Per scheme, the held-out evaluation of the accepted set (computed when first needed).
    let mut current_eval: Vec<Option<Eval>> = vec![None; schemes.len()];
    // Per shortlisted candidate, the verdict of the last round it was tried in.
    let mut verdicts: Vec<Option<Verdict>> = vec![None; short_columns.len()];
    while accepted_i.len() < opts.max_effects {
        let mut best: Option<(usize, Step)> = None;
        for (i, own) in short_columns.iter().enumerate() {
            ballbar_model::progress::update(
                &format!("diagnose: selecting effect {}", accepted_i.len() + 1),
                i,
                short_columns.len(),
            );
            if accepted_i.contains(&i) {
                continue;
            }
            let cols: Vec<usize> = current.iter().chain(own).copied().collect();
            let f = blocks2.fit(&all_units, 0, &cols)?;
            // The columns the candidate adds to the rank (a run's own column that is zero in its
            // run, a vibration of an axis that stands still there, adds none).
            let k = f.rank.saturating_sub(current_fit.rank);
            if k == 0 {
                verdicts[i] = Some(Verdict::NoRank);
                continue;
            }
            let dof = m.saturating_sub(f.rank).max(1) as f64;
            let fstat = ((current_fit.rss - f.rss) / k as f64) / (f.rss / dof * inflation);
            let needed = chi2_1e6(k) / k as f64;
            if fstat < needed {
                verdicts[i] = Some(Verdict::F { f: fstat, needed });
                continue;
            }
            // The scheme that judges it: later runs for a time-dependent effect, else the
            // primary, else (when some fold's training cannot determine it) the secondary.
            let order: Vec<usize> = if short_effects[i].is_time_dependent() {
                forward.into_iter().collect()
            } else {
                std::iter::once(0).chain(secondary).collect()
            };
            let mut judged = None;
            for &s in &order {
                if current_eval[s].is_none() {
                    current_eval[s] = Some(ev.eval(s, &current)?);
                }
                let with = ev.eval(s, &cols)?;
                let before = current_eval[s].as_ref().expect("computed above");
                if ev.judgeable(s, &with, before, own, k) {
                    judged = Some((s, with));
                    break;
                }
            }
            let Some((s, with)) = judged else {
                verdicts[i] = Some(Verdict::NotJudgeable {
                    tried: order.iter().map(|&s| schemes[s].kind).collect(),
                });
                continue;
            };
            let before = current_eval[s].as_ref().expect("computed above");
            let stats = ev.stats(s, before, &with, own);
            let (b_um, a_um) = (before.rms() * 1e3, with.rms() * 1e3);
            if stats.gain <= 0.0 || stats.t < HELD_OUT_T {
                verdicts[i] = Some(Verdict::HeldOut {
                    f: fstat,
                    before_um: b_um,
                    after_um: a_um,
                    t: stats.t,
                    folds: schemes[s].kind,
                });
                continue;
            }
            // Parsimony: it must close a material share of what the model still leaves above
            // the noise on the held-out data, not only stand out from zero.
            let share = stats.gain / before.excess().max(f64::MIN_POSITIVE);
            if excess::closed_from_energy_share(share) < MATERIAL {
                verdicts[i] = Some(Verdict::NotMaterial {
                    f: fstat,
                    before_um: b_um,
                    after_um: a_um,
                    share,
                    folds: schemes[s].kind,
                });
                continue;
            }
            verdicts[i] = Some(Verdict::Passed);
            // The best: the largest share of its scheme's held-out energy (schemes differ in
            // what they hold out, so gains are compared as shares).
            let rel = stats.gain / before.sse().max(f64::MIN_POSITIVE);
            if best.as_ref().is_none_or(|b| rel > b.1.relative_gain) {
                best = Some((
                    i,
                    Step {
                        f: fstat,
                        before: before.rms(),
                        after: with.rms(),
                        interval: stats.interval,
                        t: stats.t,
                        scheme: s,
                        relative_gain: rel,
                        eval: with,
                    },
                ));
            }
        }
        let Some((i, step)) = best else { break };
        current.extend(short_columns[i].iter().copied());
        current_fit = blocks2.fit(&all_units, 0, &current)?;
        current_eval = vec![None; schemes.len()];
        current_eval[step.scheme] = Some(step.eval.clone());
        accepted_stats.push(step);
        accepted_i.push(i);
    }
    // Each accepted effect must stand by itself: with the others in the model, leaving it out
    // must lose held-out gain three standard errors from zero, on its own scheme. One that the
    // others have made redundant (an extra that took part of a misfit the next effect
    // explained) is dropped, the weakest first, and the test repeated.
    let mut redundant: Vec<(usize, f64)> = Vec::new();
    loop {
        if accepted_i.len() < 2 {
            break;
        }
        let mut weakest: Option<(usize, f64)> = None;
        for (pos, &i) in accepted_i.iter().enumerate() {
            let s = accepted_stats[pos].scheme;
            let all: Vec<usize> =
                accepted_i.iter().flat_map(|&x| short_columns[x].iter().copied()).collect();
            let without: Vec<usize> = accepted_i
                .iter()
                .filter(|&&x| x != i)
                .flat_map(|&x| short_columns[x].iter().copied())
                .collect();
            let (w, wo) = (ev.eval(s, &all)?, ev.eval(s, &without)?);
            let stats = ev.stats(s, &wo, &w, &short_columns[i]);
            let share = stats.gain / wo.excess().max(f64::MIN_POSITIVE);
            if (stats.t < HELD_OUT_T || excess::closed_from_energy_share(share) < MATERIAL)
                && weakest.is_none_or(|b| stats.t < b.1)
            {
                weakest = Some((pos, stats.t));
            }
        }
        let Some((pos, t)) = weakest else { break };
        redundant.push((accepted_i[pos], t));
        accepted_i.remove(pos);
        accepted_stats.remove(pos);
    }
    for &(i, t) in &redundant {
        verdicts[i] = Some(Verdict::Redundant { t });
    }
    current = accepted_i.iter().flat_map(|&i| short_columns[i].iter().copied()).collect();
    // With one dropped, the others' figures came from a chain that held it: each step again,
    // the effects before it against them and it, on its own folds.
    if !redundant.is_empty() {
        for pos in 0..accepted_i.len() {
            let s = accepted_stats[pos].scheme;
            let before_cols: Vec<usize> =
                accepted_i[..pos].iter().flat_map(|&x| short_columns[x].iter().copied()).collect();
            let after_cols: Vec<usize> =
                accepted_i[..=pos].iter().flat_map(|&x| short_columns[x].iter().copied()).collect();
            let (b, a) = (ev.eval(s, &before_cols)?, ev.eval(s, &after_cols)?);
            let stats = ev.stats(s, &b, &a, &short_columns[accepted_i[pos]]);
            let step = &mut accepted_stats[pos];
            (step.before, step.after, step.interval, step.t) =
                (b.rms(), a.rms(), stats.interval, stats.t);
        }
    }
    let mut declined: Vec<Declined> = verdicts
        .iter()
        .enumerate()
        .filter(|(i, _)| !accepted_i.contains(i))
        .filter_map(|(i, v)| {
            Some(Declined { effect: short_effects[i].clone(), verdict: v.clone()? })
        })
        .collect();
    // Near misses first: what came closest to being accepted.
    declined.sort_by(|a, b| b.verdict.closeness().total_cmp(&a.verdict.closeness()));

    // The claim for the accepted effects together, on the folds that ask the user's question:
    // later runs when a time-dependent effect is among them, else the secondary scheme when an
    // effect needed it, else the primary.
    let claim_scheme = if accepted_i.iter().any(|&i| short_effects[i].is_time_dependent()) {
        forward.unwrap_or(0)
    } else {
        accepted_stats.iter().map(|s| s.scheme).max().unwrap_or(0)
    };
    let base_eval = ev.eval(claim_scheme, &[])?;
    let final_eval = ev.eval(claim_scheme, &current)?;
    let overall = HeldOut {
        folds: Some(schemes[claim_scheme].kind),
        before_um: base_eval.rms() * 1e3,
        after_um: final_eval.rms() * 1e3,
        noise_um: noise.sigma * 1e3,
        shrink: 1.0 - final_eval.rms() / base_eval.rms().max(f64::MIN_POSITIVE),
        excess_closed: excess::closed(base_eval.rms(), final_eval.rms(), noise.sigma),
    };
    let unexplained = unexplained(&base_eval, &final_eval, &declined, &gap, &schemes[claim_scheme]);

    // Held-out ISO 230-4 G, step by step: the traces of the held-out units under each fold's
    // fit of the base plus the effects accepted so far (on the claim's folds).
    let g_steps = held_out_g(
        &design0,
        &fit0,
        &short_design,
        &short_cand,
        &blocks2,
        &schemes[claim_scheme].folds,
        &short_columns,
        &accepted_i,
        threads,
    )?;

    // The accepted effects added to the base model and fitted exactly.
    let model_effects: Vec<Effect> = accepted_i.iter().map(|&i| short_effects[i].clone()).collect();
    let model_f = Model::with_effects(spec.clone(), options, kernels, &model_effects)?;
    let design_f = design0.with_model(&model_f)?;
    let fit_f = fit(&design_f, threads)?;
    let mut accepted = Vec::new();
    for (step, ((e, ids), st)) in
        model_effects.iter().zip(&model_f.effect_ids).zip(&accepted_stats).enumerate()
    {
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
        let coeffs: Vec<f64> = idx.iter().map(|&i| fit_f.values[i]).collect();
        let uncertainties = e
            .linear_parameters(&coeffs)
            .into_iter()
            .map(|(name, w)| {
                let pairs: Vec<(usize, f64)> = idx.iter().copied().zip(w).collect();
                (name, fit_f.functional(&pairs).std_uncertainty)
            })
            .collect();
        accepted.push(Accepted {
            effect: e.clone(),
            parameters: e.report(&coeffs),
            uncertainties,
            coefficients: idx
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
                .collect(),
            held_out_rms_before_um: st.before * 1e3,
            held_out_rms_after_um: st.after * 1e3,
            folds: schemes[st.scheme].kind,
            held_out_g_before_um: g_steps[step] * 1e3,
            held_out_g_after_um: g_steps[step + 1] * 1e3,
            held_out_excess_closed: excess::closed(st.before, st.after, noise.sigma),
            shrink: 1.0 - st.after / st.before.max(f64::MIN_POSITIVE),
            shrink_interval: st.interval,
            f_statistic: st.f,
            held_out_t: st.t,
            note: note_for(e, &model0),
        });
    }
    let notes = notes_before.into_iter().chain(run_end_notes(runs, &fit_f.residuals)).collect();
    Ok(Diagnosis {
        machine: spec.name.clone(),
        gap,
        effects: accepted,
        aliased,
        declined,
        notes,
        cross_validation: schemes
            .iter()
            .map(|s| s.description.clone())
            .collect::<Vec<_>>()
            .join("; "),
        schemes: schemes.iter().map(|s| (s.kind, s.description.clone())).collect(),
        held_out: overall,
        unexplained,
        candidates_screened,
        base: fit0,
        switch,
        augmented: fit_f,
        model_effects,
        base_aliases,
    })
}

#[cfg(test)]
mod tests;

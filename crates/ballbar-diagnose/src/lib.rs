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
//!    itself in the final set; the candidates declined with why ([`Declined`]). Each fold
//!    scores a candidate with its non-linear parameters chosen on the fold's training alone
//!    (a frequency, a pitch, a decay time, a speed, a time constant, an exponent of the feed:
//!    [`selection::fold_variants`]), never on data that include what it holds out. Screening
//!    alone against the base ranks first what takes up the strongest effect, so the
//!    shortlist is widened by what its own selection's effects crowded out: the kinds and
//!    axes left off it screened again given them, those that then pass the F gate added, and
//!    the selection made again.
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
use ballbar_model::parallel::par_map;
use ballbar_model::{Design, Effect, KernelSource, ModelError, Run};
pub use claims::{HeldOut, SIGNIFICANT_GAP, UNEXPLAINED_SHARE, Unexplained, held_out_rms};
use claims::{held_out_g, run_end_notes};
pub use folds::SchemeKind;
pub use library::{
    CYCLIC_PITCH_MM, FEED_EXPONENTS, GROWTH_TAU_MIN, SPIKE_TAU_MS, STICK_SLIP_MM_PER_MIN,
    cyclic_candidates, library, sample_rate, vibration_candidates,
};
use library::{candidate_columns, candidate_model};
pub use localise::{Gap, localise};
use selection::{Evaluator, Selector, describe_nuisances, refine};
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
    /// means, the figure stated; NaN where it is not determined (`held_out_excess`).
    pub held_out_excess_closed: f64,
    /// That share with its interval, or not determined ([`excess::share`]: the floor's
    /// uncertainty and the held-out samples' own chance).
    pub held_out_excess: excess::Share,
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
    /// A run's own bar length ([`Effect::BarLengthDrift`]) that passed the F test but, with
    /// the model fitted on every run, closes less than [`MATERIAL`] of what it leaves above
    /// the noise there: the change of the mean radius the held-out folds would show is the
    /// other terms' extrapolation, not the bar's.
    NotMaterialOnAllRuns {
        /// The F statistic.
        f: f64,
        /// RMS of all runs without it (the accepted effects fitted on every run), µm.
        rms_before_um: f64,
        /// With it, µm.
        rms_after_um: f64,
        /// The share of the excess *energy* over the noise it closes there.
        share: f64,
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
            Verdict::NotMaterial { share, .. } | Verdict::NotMaterialOnAllRuns { share, .. } => {
                2.0 + share.clamp(0.0, 0.99)
            }
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

/// How the diagnosis treats a change of the runs' mean radius from run to run (the bar's own
/// length): a candidate of its own ([`Effect::BarLengthDrift`]), not a nuisance of the held-out
/// scoring. A nuisance refitted on every held-out run would take up the radius change of every
/// real effect that has one (a common servo lag's loss with the feed, a growth of the axes in
/// time, half of an axis's growth in each plane of it), which then could not be found; as a
/// candidate it is named, with its alias, and once named it is refitted on each held-out run
/// as the centring is, so the effects judged after it are judged on what it leaves.
#[derive(Clone, Debug, PartialEq)]
pub struct RunRadius {
    /// `candidate` (the method's choice).
    pub treatment: &'static str,
    /// `named` (accepted), `declined`, `aliased`, or `not_tried` (one run, or the kinds
    /// asked for leave it out).
    pub status: &'static str,
    /// What it is, what it cannot be told from and how it was judged, in words.
    pub description: String,
}

impl RunRadius {
    /// The statement for a diagnosis's accepted, declined and aliased effects.
    pub fn of(effects: &[Effect], declined: &[Declined], aliased: &[Aliased]) -> RunRadius {
        let is = |e: &Effect| *e == Effect::BarLengthDrift;
        let status = if effects.iter().any(is) {
            "named"
        } else if declined.iter().any(|d| is(&d.effect)) {
            "declined"
        } else if aliased.iter().any(|a| is(&a.effect)) {
            "aliased"
        } else {
            "not_tried"
        };
        RunRadius {
            treatment: "candidate",
            status,
            description: format!(
                "a change of the mean radius from run to run is the candidate bar_length_drift, not a nuisance of the held-out scoring (a nuisance would take up the radius change of real effects: a common lag's loss with the feed, a growth of the axes); it is {}: {}",
                status.replace('_', " "),
                claims::BAR_DRIFT_ALIAS
            ),
        }
    }
}

/// A diagnosis.
pub struct Diagnosis {
    /// The machine.
    pub machine: String,
    /// Where the gap lies.
    pub gap: Gap,
    /// The noise floor's model, its standard uncertainty with it ([`localise::noise_floor`]):
    /// what the chance of other held-out figures is judged by ([`excess::Chance::of`]).
    pub noise: localise::Noise,
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

/// The base model fitted on the runs, and what the steps read of it (step 1 of the method).
pub(crate) struct Base<'a> {
    /// The base model's design, its backlash switching at `switch`.
    pub(crate) design: Design<'a>,
    /// Where the base's backlash switches.
    pub(crate) switch: ballbar_fit::switch::Switch,
    /// The base fit.
    pub(crate) fit: Fit,
    /// The base fit's aliases: terms it lacks and set-up metadata.
    pub(crate) aliases: ballbar_fit::alias::Assessment,
    /// Where its residual lies.
    pub(crate) gap: Gap,
    /// The noise floor.
    pub(crate) noise: localise::Noise,
    /// The base's factors per unit, from the screening's blocks to the shortlist's (the
    /// same base, residuals and units): released after them.
    pub(crate) units: engine::BaseUnits,
}

/// Step 1: fit the base model, its backlash switching where the lagging axes reverse (unless
/// the options say at the command: otherwise its misplaced step is a spike at every reversal,
/// which a candidate would then explain); localise its residual and measure the noise floor;
/// and search its spectra for step 2's candidates ([`library::Searches`]).
fn fit_base<'a>(
    model0: &'a Model,
    runs: &'a [Run],
    commanded_switch: bool,
    threads: usize,
) -> Result<(Base<'a>, Vec<library::Found>), DiagnoseError> {
    // The diagnosis evaluates these runs again and again (the switch search's rounds, the
    // fit's passes, the aliases, the candidates' blocks, the final fit): their geometry is
    // kept from the first evaluation on (the same numbers, `Design::keep_geometry`).
    let design = Design::new(model0, runs)?;
    design.keep_geometry();
    let (design, switch, factored) = if commanded_switch {
        (design, ballbar_fit::switch::Switch::commanded(), None)
    } else {
        ballbar_fit::switch::switch_and_factor(design, threads)?
    };
    // The switch search factored the design it returns: the fit takes that factorisation up.
    let (fit, fac) = ballbar_fit::fit_prefactored(&design, factored, threads)?;
    // What the base takes for something else (terms it lacks, set-up metadata): listed with
    // the aliased candidates, with what each moves.
    let aliases = ballbar_fit::alias::assess(&design, &fit, &fac, threads)?;
    drop(fac);
    // The noise floor once, for the gap and for what follows, with where the gap lies; beside
    // them on the worker threads, the searches of the residual's spectra for step 2, each
    // task on its own data (the same results whatever the thread count).
    let searches = library::Searches::new(model0, runs, &fit.residuals);
    enum Task {
        // The gap boxed: it is large beside a search's few effects.
        Floor(localise::Noise, Box<Gap>),
        Search(library::Found),
    }
    let tasks = par_map(1 + searches.len(), threads, |t| {
        if t == 0 {
            let noise = localise::noise_floor(runs, &fit.residuals);
            let gap = localise::localise_with_noise(runs, &fit.residuals, &noise);
            Task::Floor(noise, Box::new(gap))
        } else {
            Task::Search(searches.run(t - 1))
        }
    });
    let mut floor = None;
    let mut found = Vec::with_capacity(searches.len());
    for task in tasks {
        match task {
            Task::Floor(noise, gap) => floor = Some((noise, *gap)),
            Task::Search(f) => found.push(f),
        }
    }
    let (noise, gap) = floor.expect("task 0 is the noise floor");
    let units = engine::BaseUnits::new(runs.len());
    Ok((Base { design, switch, fit, aliases, gap, noise, units }, found))
}

/// A base parameter's short metrological name (`squareness XY`, `positional X (degree 1)`,
/// `straightness Y in X (degree 2)`; its label where it has none), as the diagnosis's aliased
/// entries name what a candidate hides in: for the base fit's aliases, whose carriers are
/// parameter ids, so that every `with` of the JSON reads alike.
pub fn parameter_name(id: &str, label: &str) -> String {
    screening::names_for(id, label)
}

/// Diagnose the gap between a machine's base model and runs: the method's steps in turn.
pub fn diagnose(
    spec: &MachineSpec,
    options: ModelOptions,
    kernels: &dyn KernelSource,
    runs: &[Run],
    opts: Options,
) -> Result<Diagnosis, DiagnoseError> {
    let threads = opts.threads.max(1);
    let model0 = Model::with_kernels(spec.clone(), options, kernels)?;
    // 1. The base.
    let (mut base, found) = fit_base(&model0, runs, opts.commanded_switch, threads)?;
    let splits = folds::splits(runs);
    let units = &splits.units;

    // 2. The candidates, and one model holding all their columns.
    let (effects, notes_before) = library::candidates(
        &model0,
        runs,
        found,
        splits.forward.is_some(),
        &opts.kinds,
        &mut base.gap,
    );
    let bare = library::bare(spec);
    let (all, column_refs, usable) =
        candidate_model(&bare, library::BARE_OPTIONS, kernels, &effects)?;
    if column_refs.is_empty() {
        return Ok(nothing_to_try(spec, base, notes_before, runs));
    }
    let cand_design = base.design.with_model(&all)?;
    let (cand_cols, columns) = candidate_columns(&cand_design, &column_refs);

    // Every fold's training units (of every scheme, in order): the shortlisted effects'
    // non-linear parameters are chosen again on each alone.
    let trainings: Vec<Vec<usize>> =
        splits.schemes().0.iter().flat_map(|s| s.folds.iter().map(|(t, _)| t.clone())).collect();

    // 3. Every candidate alone against the base, on all data; the shortlist.
    let screening = screening::screen(
        (&base.design, &base.fit, &base.noise, &base.units),
        &cand_design,
        &cand_cols,
        &columns,
        &usable,
        units,
        (opts.shortlist, &trainings, opts.shortlist),
        threads,
    )?;

    // 4. Greedy forward selection with grouped cross-validation, on the shortlist's effects
    // with their non-linear parameters refined by a parabola through the screening gains of
    // the neighbouring grid points (log scale): the selection, the held-out figures and the
    // final fit all use the effect as reported. (With the grid value, the misfit of an effect
    // whose decay time or speed lies between grid points is a structured residual that the
    // next round takes for another effect.) The noise variance of a sample, inflated for its
    // correlation, chooses a spike's ringing.
    let inflation = base.noise.inflation();
    let noise_var = base.noise.sigma * base.noise.sigma * inflation;
    let refined: Vec<Effect> = screening
        .shortlist
        .iter()
        .map(|&j| refine(&usable, &screening.screened, noise_var, j))
        .collect();
    // Their shapes chosen on each fold's training alone, which the folds score.
    let variants = selection::fold_variants(
        &refined,
        (&usable, &screening.train_gains),
        noise_var,
        &trainings,
        units,
        (&model0, runs, &base.fit.residuals),
        threads,
    );
    let ctx = Context {
        spec,
        options,
        kernels,
        bare: &bare,
        model0: &model0,
        runs,
        splits: &splits,
        trainings: &trainings,
        inflation,
        threads,
    };
    // The accepted effects added to the base model and fitted exactly. With none accepted
    // the final model is the base model, and its fit the base fit.
    let final_fit = |selector: &Selector<'_>,
                     selection: &selection::Selection|
     -> Result<(Vec<Effect>, Model, Fit), DiagnoseError> {
        let model_effects: Vec<Effect> =
            selection.accepted.iter().map(|&i| selector.effects[i].clone()).collect();
        let model_f = Model::with_effects(spec.clone(), options, kernels, &model_effects)?;
        let fit_f = if model_effects.is_empty() {
            base.fit.clone()
        } else {
            fit(&base.design.with_model(&model_f)?, threads)?
        };
        Ok((model_effects, model_f, fit_f))
    };
    // 5. The claims of the selection kept: the effects together on the user's question, the
    // held-out ISO 230-4 G step by step (on the claim's folds), the effects' figures from
    // the final fit.
    let claim = |selector: &Selector<'_>,
                 selection: &selection::Selection,
                 short_design: &Design<'_>,
                 short_cand: &[usize],
                 schemes: &[folds::Scheme],
                 (model_effects, model_f, fit_f): (Vec<Effect>, Model, Fit)|
     -> Result<Chosen, DiagnoseError> {
        let declined = selection.declined(selector.effects);
        let (claim_scheme, held_out, unexplained) =
            claims::claim(selector, selection, &declined, &base.gap, &base.noise)?;
        let g_steps = held_out_g(
            &base.design,
            &base.fit,
            short_design,
            short_cand,
            selector.ev.blocks,
            &schemes[claim_scheme].folds,
            selector.columns,
            &selection.accepted,
            threads,
        )?;
        let accepted = claims::accepted(
            &model_f,
            &fit_f,
            &model_effects,
            &selection.steps,
            schemes,
            &g_steps,
            &base.noise,
            &model0,
        );
        Ok(Chosen {
            declined,
            held_out,
            unexplained,
            model_effects,
            fit_f,
            accepted,
            schemes: schemes.to_vec(),
        })
    };
    // The shortlist widened by what the first selection's effects crowded out of it (with
    // their final fit), and the selection made again on it when it grew; the claims are
    // made for the selection kept.
    let lib = Screened {
        design: &cand_design,
        cand: &cand_cols,
        columns: &columns,
        usable: &usable,
        screening: &screening,
    };
    let first = with_selection(
        &base,
        &ctx,
        (&refined, &variants),
        opts.max_effects,
        |selector, selection, short_design, short_cand, schemes| {
            let fitted = final_fit(selector, selection)?;
            let crowded = (fitted.0.as_slice(), &fitted.2);
            Ok(match widened(&base, &ctx, &lib, (&refined, &variants), crowded, opts.shortlist)? {
                Some((wider, wider_variants)) => First::Widened(wider, wider_variants),
                None => First::Kept(Box::new(claim(
                    selector,
                    selection,
                    short_design,
                    short_cand,
                    schemes,
                    fitted,
                )?)),
            })
        },
    )?;
    let chosen = match first {
        First::Kept(chosen) => *chosen,
        First::Widened(wider, wider_variants) => with_selection(
            &base,
            &ctx,
            (&wider, &wider_variants),
            opts.max_effects,
            |selector, selection, short_design, short_cand, schemes| {
                let fitted = final_fit(selector, selection)?;
                claim(selector, selection, short_design, short_cand, schemes, fitted)
            },
        )?,
    };
    // No block is built on the base after these: its factors are released.
    base.units = engine::BaseUnits::new(0);
    let Chosen { declined, held_out, unexplained, model_effects, fit_f, accepted, schemes } =
        chosen;
    let notes = notes_before.into_iter().chain(run_end_notes(runs, &fit_f.residuals)).collect();
    Ok(Diagnosis {
        machine: spec.name.clone(),
        gap: base.gap,
        noise: base.noise,
        effects: accepted,
        aliased: screening.aliased,
        declined,
        notes,
        cross_validation: schemes
            .iter()
            .map(|s| s.description.clone())
            .collect::<Vec<_>>()
            .join("; "),
        schemes: schemes.iter().map(|s| (s.kind, s.description.clone())).collect(),
        held_out,
        unexplained,
        candidates_screened: screening.candidates_screened,
        base: base.fit,
        switch: base.switch,
        augmented: fit_f,
        model_effects,
        base_aliases: base.aliases,
    })
}

/// What the selection passes share: the machine, its base model's options and kernels, the
/// candidates' bare machine, the base model, the runs and their folds (with every fold's
/// training, in the schemes' order), the noise's inflation, the threads.
struct Context<'c> {
    spec: &'c MachineSpec,
    options: ModelOptions,
    kernels: &'c dyn KernelSource,
    bare: &'c MachineSpec,
    model0: &'c Model,
    runs: &'c [Run],
    splits: &'c folds::Splits,
    trainings: &'c [Vec<usize>],
    inflation: f64,
    threads: usize,
}

/// The screening of the whole library: its candidate design and columns, its effects and
/// what it found.
struct Screened<'s> {
    design: &'s Design<'s>,
    cand: &'s [usize],
    columns: &'s [Vec<usize>],
    usable: &'s [Effect],
    screening: &'s screening::Screening,
}

/// What the final selection pass hands on to the diagnosis.
struct Chosen {
    declined: Vec<Declined>,
    held_out: HeldOut,
    unexplained: Option<Unexplained>,
    model_effects: Vec<Effect>,
    fit_f: Fit,
    accepted: Vec<Accepted>,
    schemes: Vec<folds::Scheme>,
}

/// The first selection's outcome: its claims, or the widened shortlist to select from again.
enum First {
    // Boxed: it is large beside a list of effects.
    Kept(Box<Chosen>),
    /// The widened shortlist and its folds' shapes.
    Widened(Vec<Effect>, Vec<Vec<Option<Effect>>>),
}

/// Step 4 on the shortlisted effects `refined`: their model, design and blocks (with the
/// columns of their shapes chosen on each fold's training, `variants[i][t]` for training `t`,
/// [`selection::fold_variants`]), the schemes of folds and their evaluator (each fold scored
/// with its training's shapes), the greedy selection and the stand-alone check; `then` reads
/// them (the selector, the selection, the shortlist's design and candidate columns, the
/// schemes).
fn with_selection<R>(
    base: &Base<'_>,
    ctx: &Context<'_>,
    (refined, variants): (&[Effect], &[Vec<Option<Effect>>]),
    max_effects: usize,
    then: impl FnOnce(
        &Selector<'_>,
        &selection::Selection,
        &Design<'_>,
        &[usize],
        &[folds::Scheme],
    ) -> Result<R, DiagnoseError>,
) -> Result<R, DiagnoseError> {
    // The shortlisted effects first, then the folds' shapes that differ from them.
    let mut all_effects = refined.to_vec();
    for v in variants.iter().flatten().flatten() {
        if !all_effects.contains(v) {
            all_effects.push(v.clone());
        }
    }
    let (short_model, short_refs, short_effects) =
        candidate_model(ctx.bare, library::BARE_OPTIONS, ctx.kernels, &all_effects)?;
    let short_design = base.design.with_model(&short_model)?;
    let (short_cand, short_columns) = candidate_columns(&short_design, &short_refs);
    // The judged effects: the shortlisted ones that could be built (the first ones).
    let n_judged =
        short_effects.iter().position(|e| !refined.contains(e)).unwrap_or(short_effects.len());
    let blocks = selection::shortlist_blocks(
        base,
        &short_design,
        &short_cand,
        &short_columns,
        &short_effects,
        &ctx.splits.units,
        ctx.runs,
        ctx.threads,
    )?;
    // The schemes: 0 the primary, then the secondary and the later runs where they exist.
    let (mut schemes, secondary, forward) = ctx.splits.schemes();
    describe_nuisances(&blocks, &base.design, &mut schemes);
    // Per judged effect, scheme and fold: the columns of the shape its training chose.
    let column_of = |e: &Effect, fallback: usize| {
        short_effects
            .iter()
            .position(|x| x == e)
            .map_or(&short_columns[fallback], |k| &short_columns[k])
    };
    let fold_cols: Vec<Vec<Vec<Option<Vec<usize>>>>> = (0..n_judged)
        .map(|i| {
            let r = refined.iter().position(|x| *x == short_effects[i]).expect("a judged effect");
            let mut t = 0;
            schemes
                .iter()
                .map(|s| {
                    s.folds
                        .iter()
                        .map(|_| {
                            let cols = match variants.get(r).and_then(|v| v.get(t)) {
                                Some(Some(e)) => Some(column_of(e, i).clone()),
                                Some(None) => None,
                                None => Some(short_columns[i].clone()),
                            };
                            t += 1;
                            cols
                        })
                        .collect()
                })
                .collect()
        })
        .collect();
    let ev = Evaluator::new(&blocks, &schemes, base.noise.sigma * base.noise.sigma)
        .with_variants(selection::Variants::new(&short_columns[..n_judged], fold_cols));
    let selector = Selector {
        ev: &ev,
        columns: &short_columns[..n_judged],
        effects: &short_effects[..n_judged],
        secondary,
        forward,
        m: base.design.n_rows(),
        inflation: ctx.inflation,
    };
    let mut selection = selector.greedy(max_effects)?;
    selector.stand_alone(&mut selection)?;
    then(&selector, &selection, &short_design, &short_cand, &schemes)
}

/// Step 4's shortlist widened by what its own selection's effects crowded out of it, or
/// `None` when nothing was.
///
/// Screening tries each candidate alone against the base. When one effect is strong, every
/// candidate that takes up part of it screens high, and the shortlist (the best of each kind
/// and axis) fills with them; a weaker effect of another kind is left off (a spike beside a
/// thermal growth, whose best grid point alone is the one that takes up most growth). So
/// when a kind and axis that passes the gate alone is not on the shortlist (the shortlist
/// ranks by F, and the gate depends on the columns, so a kind that fails its gate can take a
/// place; when every passing one is on it, none was crowded out, and the screening is not
/// repeated) and the selection on the shortlist accepted `accepted` (fitted as `fit_a`),
/// the kinds and axes left off are screened again against the base plus those effects
/// (their fit's residual: what they leave), and each whose best grid point given them passes
/// the same F gate is added, refined on the screening given them, at most `shortlist_len` of
/// them, best F first. The selection is then made again on the widened shortlist from the
/// base up, by the same rules: an effect added here is accepted only on its own held-out
/// evidence.
fn widened(
    base: &Base<'_>,
    ctx: &Context<'_>,
    lib: &Screened<'_>,
    (refined, variants): (&[Effect], &[Vec<Option<Effect>>]),
    (accepted, fit_a): (&[Effect], &ballbar_fit::Fit),
    shortlist_len: usize,
) -> Result<Option<(Vec<Effect>, Vec<Vec<Option<Effect>>>)>, DiagnoseError> {
    let passes = |j: usize, f: f64| {
        let k = lib.columns[j].len();
        f >= screening::chi2_1e6(k) / k as f64
    };
    let key = |e: &Effect| (e.kind(), e.axis_label());
    let mut passing: Vec<_> = lib
        .screening
        .screened
        .iter()
        .filter(|s| passes(s.0, s.1))
        .map(|s| key(&lib.usable[s.0]))
        .collect();
    passing.sort();
    passing.dedup();
    let shortlisted: Vec<_> =
        lib.screening.shortlist.iter().map(|&j| key(&lib.usable[j])).collect();
    if passing.iter().all(|k| shortlisted.contains(k)) || accepted.is_empty() {
        return Ok(None);
    }
    // Only the kinds and axes the shortlist does not hold are screened again: the candidate
    // columns of their grid points, renumbered.
    let keep: Vec<usize> =
        (0..lib.usable.len()).filter(|&j| !shortlisted.contains(&key(&lib.usable[j]))).collect();
    let mut sub_cand = Vec::new();
    let sub_columns: Vec<Vec<usize>> = keep
        .iter()
        .map(|&j| {
            lib.columns[j]
                .iter()
                .map(|&c| {
                    sub_cand.push(lib.cand[c]);
                    sub_cand.len() - 1
                })
                .collect()
        })
        .collect();
    let sub_usable: Vec<Effect> = keep.iter().map(|&j| lib.usable[j].clone()).collect();
    let model_a = Model::with_effects(ctx.spec.clone(), ctx.options, ctx.kernels, accepted)?;
    let design_a = base.design.with_model(&model_a)?;
    // Screened once: no unit's factors are kept for a later build (an empty cache).
    let given = screening::screen(
        (&design_a, fit_a, &base.noise, &engine::BaseUnits::new(0)),
        lib.design,
        &sub_cand,
        &sub_columns,
        &sub_usable,
        &ctx.splits.units,
        (usize::MAX, ctx.trainings, shortlist_len),
        ctx.threads,
    )?;
    // Back to the library's numbering.
    let screened: Vec<(usize, f64, f64)> =
        given.screened.iter().map(|&(j, f, g)| (keep[j], f, g)).collect();
    let noise_var = base.noise.sigma * base.noise.sigma * ctx.inflation;
    let mut wider = refined.to_vec();
    for j in given.shortlist.iter().map(|&j| keep[j]) {
        if wider.len() - refined.len() >= shortlist_len {
            break;
        }
        let f = screened.iter().find(|s| s.0 == j).map_or(0.0, |s| s.1);
        if !passes(j, f) {
            continue;
        }
        let e = refine(lib.usable, &screened, noise_var, j);
        if !wider.contains(&e) {
            wider.push(e);
        }
    }
    if wider.len() == refined.len() {
        return Ok(None);
    }
    // The added effects' shapes on each fold's training, from the screening given the
    // accepted effects (the spectra's peaks from the base's residual, where the library found
    // them).
    let train_gains: Vec<(usize, Vec<f64>)> =
        given.train_gains.iter().map(|(j, g)| (keep[*j], g.clone())).collect();
    let added = selection::fold_variants(
        &wider[refined.len()..],
        (lib.usable, &train_gains),
        noise_var,
        ctx.trainings,
        &ctx.splits.units,
        (ctx.model0, ctx.runs, &base.fit.residuals),
        ctx.threads,
    );
    let all_variants = variants.iter().cloned().chain(added).collect();
    Ok(Some((wider, all_variants)))
}

/// The diagnosis when there is nothing to try (every kind filtered out, or none applies): the
/// gap, and no effect.
fn nothing_to_try(
    spec: &MachineSpec,
    base: Base<'_>,
    notes_before: Vec<String>,
    runs: &[Run],
) -> Diagnosis {
    Diagnosis {
        machine: spec.name.clone(),
        gap: base.gap,
        noise: base.noise,
        effects: vec![],
        aliased: vec![],
        declined: vec![],
        notes: notes_before.into_iter().chain(run_end_notes(runs, &base.fit.residuals)).collect(),
        cross_validation: "none: no candidate to try".into(),
        schemes: vec![],
        held_out: HeldOut {
            folds: None,
            before_um: f64::NAN,
            after_um: f64::NAN,
            noise_um: base.noise.sigma * 1e3,
            noise_u_um: base.noise.sigma_u * 1e3,
            shrink: 0.0,
            excess_closed: f64::NAN,
            excess: None,
        },
        unexplained: None,
        candidates_screened: 0,
        augmented: base.fit.clone(),
        base: base.fit,
        switch: base.switch,
        model_effects: vec![],
        base_aliases: base.aliases,
    }
}

#[cfg(test)]
mod tests;

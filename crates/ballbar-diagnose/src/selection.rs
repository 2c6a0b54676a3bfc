//! Step 4 of the method: the greedy selection, its held-out evaluation and the stand-alone
//! check.
//!
//! Selection, greedy: the best screened candidates (the best grid point of each kind and
//! axis, its non-linear parameters refined by a parabola through the screening gains of its
//! grid neighbours along each, [`refine`]; a reversal spike, screened with one set of
//! coefficients for both reversals of its axis, goes on with one set per side) are scored
//! by held-out prediction on folds that hold out what the user varies ([`folds`]): whole
//! configurations (tool length, ball height, centre, radius, feed) when the runs have more
//! than one, else whole repeats, else each quarter of each planar run centred on an axis
//! reversal, else halves of runs; a candidate that the training of some fold cannot
//! determine (seen only across the configurations held out whole) is judged on repeats or on
//! each configuration's planes; every time-dependent candidate (thermal growth, drift) on
//! later runs predicted from earlier ones only (forward validation; not offered when the
//! session has no later runs to predict, with a note saying so). A held-out run's
//! centring is fitted on it (a nuisance of each run; from the rest of the run when parts of
//! runs are held out), and so are its own columns of a per-run effect, with their expected
//! chance gain (the noise power at the column's frequency) added back. So are the base
//! model's own combinations that a fold's training cannot determine as all data do (the
//! bar length against the common scale when a radius is held out; their uncertainty more
//! than √10 times what the lost samples explain, [`engine::Blocks::undetermined`](crate::engine::Blocks::undetermined)): fitted
//! on the fold's held-out runs together, their chance gain (the noise's long-run variance
//! per dimension) added back, and named in the scheme's description; otherwise the
//! held-out gap would be the base's extrapolation along them, which real effects close
//! only a little of, or a wrong effect closes by absorbing it. A candidate's non-linear
//! parameters are chosen inside each fold on its training units alone ([`fold_variants`]):
//! a vibration's frequency and a cyclic error's pitch at the same peak (the largest, or the
//! second) of the spectrum of the training samples alone, a spike's decay time and ringing, a
//! stick-slip's speed, a growth's time constant (or none) and a size's exponent of the feed
//! at the grid point with the largest gain on the training units, refined between its
//! neighbours as on all data ([`refine`]); the fold's held-out units are scored with that
//! shape. Otherwise the held-out data would have chosen the shape they judge (a peak of a
//! spectrum summed over every run, held-out runs among them, is in part those runs' own noise,
//! which their refitted phases then take up as gain). The effect named and fitted is the one
//! chosen on all data. An effect is accepted when
//! its F statistic (its degrees of freedom the rank it adds) passes the 1e-6 level of χ² (a
//! bound that also covers the search over candidates and grids), its held-out gain is
//! positive and three standard errors from zero, the standard error taken over the held-out
//! groups (a run's samples in one fold) the candidate acts in (its columns are not zero
//! there: a group it cannot change says nothing about whether its gain repeats; on later
//! runs the t is of the log ratio of each group's held-out error before and after, since
//! the horizon grows from group to group, [`PerGroup`]), and it
//! closes at least [`MATERIAL`] of what the model still leaves above the noise there
//! ([`excess::closed`](crate::excess::closed))
//! (parsimony: a real but minor structure is a near miss, not a cause). The best is the
//! largest share of its folds' held-out energy. The search stops when no candidate passes.
//!
//! A change of the runs' mean radius from run to run (the bar's own length: its temperature,
//! a recalibration) is a candidate, [`Effect::BarLengthDrift`], one constant per run, not a
//! nuisance of the held-out scoring: refitted on every held-out run, a nuisance would take
//! up the radius change of every real effect that has one (a common lag's loss with the
//! feed, a common growth of the axes in time, the mean half of an axis's growth in each of
//! its planes), which then could never be found. Unnamed, it stays in the held-out excess,
//! against which a real effect beside it (a spike) closes too small a share to be named. As a
//! candidate it is refitted on each held-out run as a vibration's phase is (its chance gain,
//! the noise's long-run variance per run, added back), and once accepted the effects judged
//! after it are judged on what it leaves. It holds every change of the mean radius, so it is
//! taken only in a round where no other candidate passes (a law of the machine that predicts
//! the radius, in the feed or in time, is named first), and since a constant per run predicts
//! nothing, its evidence is on all runs: with the set so far fitted on every run, it must close
//! [`MATERIAL`] of what that fit leaves above the noise there
//! ([`Verdict::NotMaterialOnAllRuns`](crate::Verdict::NotMaterialOnAllRuns)), not only of a
//! held-out fold's, where it would also take up the other effects' extrapolation (a growth
//! fitted on one cycle predicting another). Its alias is said with it: a common growth of the
//! axes changes a circle's radius alike; the bar re-measured in its calibrator, or a law in
//! time that predicts later runs, separates them.
//! Then every accepted effect must stand by itself in the final set (leaving it out loses a
//! held-out gain three standard errors from zero and material); one made redundant by later
//! ones is dropped. The candidates tried and not accepted are reported, nearest misses
//! first, with the figure that declined them ([`Declined`](crate::Declined)).

use std::ops::Range;

use ballbar_fit::FitError;
use ballbar_model::machine::Model;
use ballbar_model::parallel::par_map;
use ballbar_model::{Axis, Design, Effect, Run};

use crate::library::{ring_hz, ring_period_ms, sample_rate};
use crate::screening::chi2_1e6;
use crate::{Base, Declined, Verdict, engine, excess, folds, library, localise, screening};

/// Held-out gain must stand this many standard errors from zero.
pub const HELD_OUT_T: f64 = 3.0;

/// A held-out unit counts in the t statistic of a candidate's gain when the candidate's
/// columns hold more than this share of their largest energy in any unit there. A unit the
/// candidate does not act in (a lateral play of X switched by Y in a YZ or ZX run, where its
/// columns are zero) gains nothing by it, whatever the effect's size: counted, such units
/// capped t at 2.35 for an effect seen in one plane of three with 12 runs, so no effect of a
/// single plane could be accepted. A unit below a thousandth of the largest can gain at most
/// about a thousandth of what that one gains: it carries no evidence either way.
pub(crate) const REACHED: f64 = 1e-3;

/// An effect must close at least this share of what the model still leaves above the noise on
/// the held-out data (of the excess RMS, [`excess::closed`](crate::excess::closed)) to be named. An effect that
/// stands three standard errors from zero but closes less is a real but minor structure (a
/// higher-order term taking a little of another effect's misfit, a second angular error
/// absorbing a tenth of the first's): naming it sends an engineer after a cause that is not the
/// gap's. A tenth: the smallest single effect of the validation suites closes more than half
/// of what is left when it is found, and the extras named on the independent simulator closed
/// a few per cent each. A tenth of the excess *energy*, as the suites were judged: on the
/// excess's own scale `1 − √0.9 = 0.0513` (rounded to the fourth decimal, which moves the
/// level by 2e-5 of the excess: below anything a held-out estimate resolves).
pub const MATERIAL: f64 = 0.0513;

/// One accepted step: its figures on the scheme that judged it.
pub(crate) struct Step {
    pub(crate) f: f64,
    pub(crate) before: f64,
    pub(crate) after: f64,
    pub(crate) interval: [f64; 2],
    pub(crate) t: f64,
    pub(crate) scheme: usize,
    pub(crate) relative_gain: f64,
    pub(crate) eval: Eval,
}

/// A column set's held-out evaluation on one scheme.
#[derive(Clone, Debug)]
pub(crate) struct Eval {
    /// Per unit: SSE and samples (zero where the scheme never holds it out).
    pub(crate) per_unit: Vec<(f64, usize)>,
    /// Per fold: the rank of the training fit.
    pub(crate) fold_rank: Vec<usize>,
    /// The noise floor's variance of a sample, mm².
    pub(crate) noise_var: f64,
}

impl Eval {
    pub(crate) fn sse(&self) -> f64 {
        self.per_unit.iter().map(|x| x.0).sum()
    }
    pub(crate) fn n(&self) -> usize {
        self.per_unit.iter().map(|x| x.1).sum()
    }
    pub(crate) fn rms(&self) -> f64 {
        let n = self.n();
        if n > 0 { (self.sse() / n as f64).sqrt() } else { 0.0 }
    }
    /// The held-out energy above the noise floor's.
    pub(crate) fn excess(&self) -> f64 {
        (self.sse() - self.n() as f64 * self.noise_var).max(0.0)
    }
}

/// Held-out evaluation of column sets on the schemes.
pub(crate) struct Evaluator<'a> {
    pub(crate) blocks: &'a engine::Blocks,
    pub(crate) schemes: &'a [folds::Scheme],
    pub(crate) noise_var: f64,
    /// Per scheme: the held-out group of each unit (a run's samples in one fold), and the
    /// number of groups.
    groups: Vec<(Vec<Option<usize>>, usize)>,
    /// The shapes each fold's training chose ([`fold_variants`]), when there are any.
    variants: Option<Variants>,
}

/// The columns each judged effect holds in each fold: those of its shape chosen on the fold's
/// training ([`fold_variants`]) instead of those of its shape chosen on all data.
pub(crate) struct Variants {
    /// Per candidate column of the blocks' set: the judged effect whose all-data columns hold
    /// it.
    owner: Vec<Option<usize>>,
    /// Per judged effect, per scheme, per fold: its columns there (`None`: the fold's
    /// training cannot determine its shape, [`fold_variants`]).
    cols: Vec<Vec<Vec<Option<Vec<usize>>>>>,
    /// Per judged effect: its all-data columns.
    all: Vec<Vec<usize>>,
}

impl Variants {
    /// `columns[i]`: judged effect `i`'s all-data columns; `fold_cols[i][s][f]`: its columns in
    /// fold `f` of scheme `s`.
    pub(crate) fn new(
        columns: &[Vec<usize>],
        fold_cols: Vec<Vec<Vec<Option<Vec<usize>>>>>,
    ) -> Variants {
        let n = columns.iter().flatten().map(|&c| c + 1).max().unwrap_or(0);
        let mut owner = vec![None; n];
        for (i, cols) in columns.iter().enumerate() {
            for &c in cols {
                owner[c] = Some(i);
            }
        }
        Variants { owner, cols: fold_cols, all: columns.to_vec() }
    }

    /// True when fold `f` of scheme `s` determines the shape of every judged effect in `cols`.
    pub(crate) fn determined(&self, s: usize, f: usize, cols: &[usize]) -> bool {
        cols.iter()
            .filter_map(|&c| self.owner.get(c).copied().flatten())
            .all(|i| self.cols[i][s][f].is_some())
    }

    /// The columns of the set `cols` (all-data shapes) in fold `f` of scheme `s`: each judged
    /// effect's replaced by its fold's shape, in the order of first appearance.
    pub(crate) fn in_fold(&self, s: usize, f: usize, cols: &[usize]) -> Vec<usize> {
        let mut out = Vec::with_capacity(cols.len());
        let mut seen: Vec<usize> = Vec::new();
        for &c in cols {
            match self.owner.get(c).copied().flatten() {
                Some(i) => {
                    if !seen.contains(&i) {
                        seen.push(i);
                        // A shape the fold cannot determine: its all-data one (the fold is
                        // not asked to judge the effect, [`Variants::determined`]).
                        out.extend_from_slice(self.cols[i][s][f].as_ref().unwrap_or(&self.all[i]));
                    }
                }
                None => out.push(c),
            }
        }
        out
    }
}

impl<'a> Evaluator<'a> {
    pub(crate) fn new(
        blocks: &'a engine::Blocks,
        schemes: &'a [folds::Scheme],
        noise_var: f64,
    ) -> Evaluator<'a> {
        let groups = schemes
            .iter()
            .map(|s| {
                let mut keys: Vec<(usize, usize)> = Vec::new();
                let mut of = vec![None; blocks.units.len()];
                for (f, (_, held)) in s.folds.iter().enumerate() {
                    for &u in held {
                        let key = (blocks.units[u].run, f);
                        of[u] = Some(keys.iter().position(|k| *k == key).unwrap_or_else(|| {
                            keys.push(key);
                            keys.len() - 1
                        }));
                    }
                }
                (of, keys.len())
            })
            .collect();
        Evaluator { blocks, schemes, noise_var, groups, variants: None }
    }

    /// The evaluator scoring each fold with the shapes its training chose.
    pub(crate) fn with_variants(mut self, variants: Variants) -> Evaluator<'a> {
        self.variants = Some(variants);
        self
    }

    /// The columns of the set `cols` in fold `f` of scheme `s` ([`Variants::in_fold`]).
    fn fold_cols(&self, s: usize, f: usize, cols: &[usize]) -> Vec<usize> {
        match &self.variants {
            Some(v) => v.in_fold(s, f, cols),
            None => cols.to_vec(),
        }
    }

    pub(crate) fn eval(&self, s: usize, cols: &[usize]) -> Result<Eval, FitError> {
        let b = self.blocks;
        let mut per_unit = vec![(0.0, 0usize); b.units.len()];
        let mut fold_rank = Vec::new();
        for (fold, (train, held)) in self.schemes[s].folds.iter().enumerate() {
            let cols = &self.fold_cols(s, fold, cols);
            let f = b.fit(train, 0, cols)?;
            fold_rank.push(f.rank);
            // A held-out run's centring, and the base combinations the training cannot
            // determine, are nuisances of the held-out data.
            let refit = |h: usize| !train.iter().any(|&t| b.units[t].run == b.units[h].run);
            let sse = b.held_out_fold(train, held, &f, 0, cols, refit);
            for (&h, e) in held.iter().zip(sse) {
                per_unit[h] = (e, b.units[h].len());
            }
        }
        Ok(Eval { per_unit, fold_rank, noise_var: self.noise_var })
    }

    /// True when the training of every fold determines the candidate `own` (added to the set of
    /// `before`, giving `with`): it adds there the rank `k` it adds on all data, less its
    /// columns of runs the fold holds out whole (a vibration's phase in a held-out run, which
    /// the held-out run refits).
    pub(crate) fn judgeable(
        &self,
        s: usize,
        with: &Eval,
        before: &Eval,
        own: &[usize],
        k: usize,
    ) -> bool {
        let b = self.blocks;
        self.schemes[s].folds.iter().enumerate().all(|(f, (train, _))| {
            if self.variants.as_ref().is_some_and(|v| !v.determined(s, f, own)) {
                return false;
            }
            let missing = self
                .fold_cols(s, f, own)
                .iter()
                .filter(|&&c| {
                    b.c_norm2[c] > 0.0
                        && b.col_run[c].is_some_and(|r| !train.iter().any(|&t| b.units[t].run == r))
                })
                .count();
            with.fold_rank[f].saturating_sub(before.fold_rank[f]) >= k.saturating_sub(missing)
        })
    }

    /// The comparison of two evaluations over the scheme's held-out groups, the t statistic
    /// over the groups `own` acts in.
    pub(crate) fn stats(
        &self,
        s: usize,
        before: &Eval,
        after: &Eval,
        own: &[usize],
    ) -> SubsetStats {
        let (of, n) = &self.groups[s];
        let grouped = |e: &Eval| {
            let mut out = vec![(0.0, 0usize); *n];
            for (u, x) in e.per_unit.iter().enumerate() {
                if let Some(g) = of[u] {
                    out[g].0 += x.0;
                    out[g].1 += x.1;
                }
            }
            out
        };
        let energy: Vec<f64> = self.blocks.units.iter().map(|u| u.energy(own)).collect();
        let emax = energy.iter().copied().fold(0.0, f64::max);
        let mut reached = vec![false; *n];
        for (u, &e) in energy.iter().enumerate() {
            if let Some(g) = of[u] {
                reached[g] |= e > REACHED * emax;
            }
        }
        let per = if self.schemes[s].kind == folds::SchemeKind::LaterRuns {
            PerGroup::LogRatio
        } else {
            PerGroup::Gain
        };
        SubsetStats::new(&grouped(before), &grouped(after), &reached, per)
    }
}

/// The expected chance gain (mm²) of fitting one column of a held-out run's own at frequency
/// `f_hz` to its noise alone: the noise's spectral density there ([`localise::Noise::power_at`]).
pub(crate) fn chance_gain(noise: &localise::Noise, f_hz: f64, rate_hz: f64) -> f64 {
    noise.power_at(f_hz, rate_hz)
}

/// Set the chance gains of the run-term columns of `effects` (a vibration's, a run's own bar
/// length's) in `blocks`.
pub(crate) fn set_refit_chance(
    blocks: &mut engine::Blocks,
    effects: &[Effect],
    columns: &[Vec<usize>],
    noise: &localise::Noise,
    rate_hz: f64,
) {
    for (e, cols) in effects.iter().zip(columns) {
        let chance = match e {
            Effect::Vibration { frequency_hz, .. } => chance_gain(noise, *frequency_hz, rate_hz),
            // A constant over the run: its mean's variance times its samples, the noise's
            // long-run variance.
            Effect::BarLengthDrift => nuisance_chance(noise),
            _ => continue,
        };
        for &c in cols {
            blocks.refit_chance[c] = chance;
        }
    }
}

/// What fitting one base combination on a held-out fold's noise alone gains in expectation,
/// mm² ([`engine::Blocks::nuisance_chance`]): the base's columns are smooth over a run (a few
/// cycles a revolution, against hundreds of samples), where the noise's power is its long-run
/// variance, the variance of a sample times [`localise::Noise::inflation`].
pub(crate) fn nuisance_chance(noise: &localise::Noise) -> f64 {
    noise.sigma * noise.sigma * noise.inflation()
}

/// Each scheme's description completed with what its folds fit on the held-out data besides
/// the centring: per fold whose training cannot determine some base combinations
/// ([`engine::Blocks::undetermined`]), how many and the parameters that carry each (those
/// within a quarter of its largest component, the columns scaled by their norms).
pub(crate) fn describe_nuisances(
    blocks: &engine::Blocks,
    design: &Design<'_>,
    schemes: &mut [folds::Scheme],
) {
    let all: Vec<usize> = (0..blocks.units.len()).collect();
    let norms: Vec<f64> = (0..design.n_machine).map(|j| blocks.base_col_norm(&all, j)).collect();
    for s in schemes.iter_mut() {
        let mut parts = Vec::new();
        for (f, (train, _)) in s.folds.iter().enumerate() {
            let v = blocks.undetermined(train);
            if v.ncols() == 0 {
                continue;
            }
            let nm = v.nrows();
            let names: Vec<String> = (0..v.ncols())
                .map(|c| {
                    let w: Vec<f64> = (0..nm).map(|j| (v[(j, c)] * norms[j]).abs()).collect();
                    let top = w.iter().copied().fold(0.0, f64::max);
                    let ids: Vec<&str> = (0..nm)
                        .filter(|&j| w[j] >= 0.25 * top && top > 0.0)
                        .map(|j| design.parameters[j].id.as_str())
                        .collect();
                    ids.join("+")
                })
                .collect();
            parts.push(format!("fold {}: {}", f + 1, names.join(", ")));
        }
        if !parts.is_empty() {
            s.description.push_str(&format!(
                "; base combinations a fold's training cannot determine (a set-up the base needs is held out) are fitted on its held-out runs as nuisances, with their chance gain added back: {}",
                parts.join("; ")
            ));
        }
    }
}

/// Held-out comparison of two column sets over held-out groups (a run's samples in one fold:
/// a whole run, or a quarter or half of one; the entries passed in are per group).
pub(crate) struct SubsetStats {
    /// Total held-out SSE gain, mm².
    pub(crate) gain: f64,
    /// The mean of the per-group figure ([`PerGroup`]) over its standard error (the held-out
    /// groups the candidate acts in, as independent).
    pub(crate) t: f64,
    /// The RMS shrink ± two jackknife standard errors over the held-out units (≈ 95 % for
    /// many units; a single held-out unit gives no spread and a point).
    pub(crate) interval: [f64; 2],
}

/// What the t statistic averages over the held-out groups.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum PerGroup {
    /// The SSE gain: groups alike in what they hold (folds of one kind of set-up).
    Gain,
    /// The log of the SSE ratio before / after: groups predicted over different horizons
    /// (later runs, each block further from its training than the one before). What a
    /// time-dependent effect leaves grows with the horizon, so its gains grow with it (as the
    /// square of the time for a linear growth) and their spread, not chance, holds their t
    /// down: a thermal growth that takes every later run from 0.4-1.4 µm down to the 0.22 µm
    /// noise has gains of 0.36, 0.59, 1.54 and 1.88 µm²·n in its four groups, t 2.99, and is
    /// declined on them. The share it takes is alike across the horizon (log ratios 2.2, 2.6, 3.5,
    /// 3.7; t 8.2). Without an effect the ratios scatter about one or below it (the candidate's
    /// fitted noise adds to the held-out error), so the test still asks for a consistent
    /// improvement; [`MATERIAL`] then asks that it be of a size that matters.
    LogRatio,
}

impl SubsetStats {
    /// `reached[u]`: the candidate acts in unit `u` (the t statistic is over those units; the
    /// gain and the interval over all held-out units).
    pub(crate) fn new(
        before: &[(f64, usize)],
        after: &[(f64, usize)],
        reached: &[bool],
        per: PerGroup,
    ) -> SubsetStats {
        let units: Vec<usize> = (0..before.len()).filter(|&u| before[u].1 > 0).collect();
        let gain: f64 = units.iter().map(|&u| before[u].0 - after[u].0).sum();
        let figure = |u: usize| match per {
            PerGroup::Gain => before[u].0 - after[u].0,
            // Held-out SSEs are sums of squares of hundreds of samples with noise in them: both
            // positive. The floor keeps a degenerate empty group from dividing by zero.
            PerGroup::LogRatio => {
                (before[u].0.max(f64::MIN_POSITIVE) / after[u].0.max(f64::MIN_POSITIVE)).ln()
            }
        };
        let d: Vec<f64> = units.iter().filter(|&&u| reached[u]).map(|&u| figure(u)).collect();
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n.max(1.0);
        let var = if n > 1.0 {
            d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            f64::INFINITY
        };
        let t = if var > 0.0 {
            mean / (var / n).sqrt()
        } else if mean > 0.0 {
            f64::INFINITY
        } else {
            0.0
        };
        // Jackknife of the shrink 1 - sqrt(SSE_after/SSE_before) (sample counts cancel).
        let (sb, sa): (f64, f64) =
            units.iter().fold((0.0, 0.0), |(b, a), &u| (b + before[u].0, a + after[u].0));
        let shrink = |b: f64, a: f64| if b > 0.0 { 1.0 - (a / b).sqrt() } else { 0.0 };
        let full = shrink(sb, sa);
        let loo: Vec<f64> =
            units.iter().map(|&u| shrink(sb - before[u].0, sa - after[u].0)).collect();
        let nu = loo.len() as f64;
        let mloo = loo.iter().sum::<f64>() / nu.max(1.0);
        let se =
            ((nu - 1.0) / nu.max(1.0) * loo.iter().map(|x| (x - mloo).powi(2)).sum::<f64>()).sqrt();
        SubsetStats { gain, t, interval: [full - 2.0 * se, full + 2.0 * se] }
    }
}

/// The vertex of the parabola through the point of `pts` (abscissa, gain; any order) at `x0`
/// and its two neighbours, kept between the neighbours; `None` at an end of the grid, or when
/// the parabola does not open downward.
pub(crate) fn parabola_vertex(mut pts: Vec<(f64, f64)>, x0: f64) -> Option<f64> {
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    let i = pts.iter().position(|p| (p.0 - x0).abs() < 1e-9 * x0.abs().max(1.0))?;
    if i == 0 || i + 1 >= pts.len() {
        return None;
    }
    let (a, b, c) = (pts[i - 1], pts[i], pts[i + 1]);
    let den = (a.0 - b.0) * (a.0 - c.0) * (b.0 - c.0);
    if den == 0.0 {
        return None;
    }
    let pa = (c.0 * (b.1 - a.1) + b.0 * (a.1 - c.1) + a.0 * (c.1 - b.1)) / den;
    let pb = (c.0 * c.0 * (a.1 - b.1) + b.0 * b.0 * (c.1 - a.1) + a.0 * a.0 * (b.1 - c.1)) / den;
    if pa >= 0.0 {
        return None;
    }
    Some((-pb / (2.0 * pa)).clamp(a.0, c.0))
}

/// A shortlisted grid effect with its non-linear parameters refined between its grid
/// neighbours: a parabola through the screening gains of the best grid point and its two
/// neighbours along each parameter (a decay time and a stick-slip speed on a log scale, a
/// spike's ringing frequency linearly). A reversal spike comes out with one set of
/// coefficients per side of the axis's travel (its shape was profiled with one set for both).
///
/// A spike rings only on evidence: its best grid point's gain must exceed the best gain
/// without ringing by the F gate's level for one more parameter (χ²(1) at 1e-6, times
/// `noise_var`, the noise floor's variance of a sample, inflated for its correlation);
/// otherwise it is the best spike without ringing. (The three parts hold a non-ringing
/// `e^{-t/τ}` at any frequency, so without ringing in the data the profile's frequency is the
/// noise's choice, and a period would be reported that means nothing.)
pub(crate) fn refine(
    effects: &[Effect],
    screened: &[(usize, f64, f64)],
    noise_var: f64,
    j: usize,
) -> Effect {
    // A feed-scaled effect: its inner effect refined among the grid points of its exponent,
    // then its exponent by a parabola through the gains of the inner grid point at the other
    // exponents (0: the effect itself).
    let exponent = |o: &Effect| match o {
        Effect::FeedScaled { exponent, .. } => *exponent,
        _ => 0.0,
    };
    let inner = |o: &Effect| match o {
        Effect::FeedScaled { effect, .. } => (**effect).clone(),
        other => other.clone(),
    };
    if let Effect::FeedScaled { effect, exponent: p, reference_mm_per_min } = &effects[j] {
        let same_p: Vec<usize> =
            screened.iter().map(|s| s.0).filter(|&x| exponent(&effects[x]) == *p).collect();
        let inner_effects: Vec<Effect> = effects.iter().map(inner).collect();
        let sub: Vec<(usize, f64, f64)> =
            screened.iter().filter(|s| same_p.contains(&s.0)).copied().collect();
        let refined = refine(&inner_effects, &sub, noise_var, j);
        let along_p: Vec<(f64, f64)> = screened
            .iter()
            .filter(|s| inner(&effects[s.0]) == **effect)
            .map(|s| (exponent(&effects[s.0]), s.2))
            .collect();
        let p = parabola_vertex(along_p, *p).unwrap_or(*p);
        return if p.abs() < 1e-9 {
            refined
        } else {
            Effect::FeedScaled {
                effect: Box::new(refined),
                exponent: p,
                reference_mm_per_min: *reference_mm_per_min,
            }
        };
    }
    let e = &effects[j];
    let same =
        |o: &Effect| o.kind() == e.kind() && o.axis_label() == e.axis_label() && exponent(o) == 0.0;
    let gains = || screened.iter().filter(|s| same(&effects[s.0])).map(|s| (&effects[s.0], s.2));
    match e {
        Effect::ReversalTransient { axis, tau_ms, period_ms, .. } => {
            let gain_of = |o: &Effect| {
                gains().find(|(x, _)| *x == o).map(|(_, g)| g).unwrap_or(f64::NEG_INFINITY)
            };
            let calm = gains()
                .filter(|(o, _)| matches!(o, Effect::ReversalTransient { period_ms: None, .. }))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(o, g)| (o.clone(), g));
            let (tau_ms, period_ms) = match calm {
                Some((Effect::ReversalTransient { tau_ms: t, .. }, g))
                    if period_ms.is_some() && gain_of(e) - g < chi2_1e6(1) * noise_var =>
                {
                    (t, None)
                }
                _ => (*tau_ms, *period_ms),
            };
            let f0 = ring_hz(period_ms);
            let along_tau: Vec<(f64, f64)> = gains()
                .filter_map(|(o, g)| match o {
                    Effect::ReversalTransient { tau_ms: t, period_ms: p, .. }
                        if (ring_hz(*p) - f0).abs() < 1e-9 =>
                    {
                        Some((t.ln(), g))
                    }
                    _ => None,
                })
                .collect();
            let along_f: Vec<(f64, f64)> = gains()
                .filter_map(|(o, g)| match o {
                    Effect::ReversalTransient { tau_ms: t, period_ms: p, .. }
                        if (t - tau_ms).abs() < 1e-9 * tau_ms =>
                    {
                        Some((ring_hz(*p), g))
                    }
                    _ => None,
                })
                .collect();
            let tau = parabola_vertex(along_tau, tau_ms.ln()).map(f64::exp).unwrap_or(tau_ms);
            let f = parabola_vertex(along_f, f0).unwrap_or(f0);
            Effect::ReversalTransient {
                axis: *axis,
                tau_ms: tau,
                period_ms: ring_period_ms(f),
                per_side: true,
            }
        }
        Effect::ReversalSpike { axis, tau_ms } => {
            let pts = gains()
                .filter_map(|(o, g)| {
                    if let Effect::ReversalSpike { tau_ms: t, .. } = o {
                        Some((t.ln(), g))
                    } else {
                        None
                    }
                })
                .collect();
            Effect::ReversalSpike {
                axis: *axis,
                tau_ms: parabola_vertex(pts, tau_ms.ln()).map(f64::exp).unwrap_or(*tau_ms),
            }
        }
        Effect::ThermalGrowth { axis, time_constant_min: Some(t) } => {
            let pts = gains()
                .filter_map(|(o, g)| {
                    if let Effect::ThermalGrowth { time_constant_min: Some(x), .. } = o {
                        Some((x.ln(), g))
                    } else {
                        None
                    }
                })
                .collect();
            Effect::ThermalGrowth {
                axis: *axis,
                time_constant_min: Some(parabola_vertex(pts, t.ln()).map(f64::exp).unwrap_or(*t)),
            }
        }
        Effect::StickSlip { axis, speed_mm_per_min } => {
            let pts = gains()
                .filter_map(|(o, g)| {
                    if let Effect::StickSlip { speed_mm_per_min: v, .. } = o {
                        Some((v.ln(), g))
                    } else {
                        None
                    }
                })
                .collect();
            Effect::StickSlip {
                axis: *axis,
                speed_mm_per_min: parabola_vertex(pts, speed_mm_per_min.ln())
                    .map(f64::exp)
                    .unwrap_or(*speed_mm_per_min),
            }
        }
        other => other.clone(),
    }
}

/// Each shortlisted effect's shape chosen on each fold's training units alone (`trainings`,
/// every fold of every scheme in order): `out[i][t]` for `refined[i]` and training `t`.
///
/// - A vibration or a cyclic error: the spectrum of the base residual on the training samples
///   alone (the others' set to zero: their runs, or their quarters or halves, add nothing to
///   it), searched as on all data ([`library::vibration_candidates`],
///   [`library::cyclic_candidates`]), and its peak of the same rank along the same axis (the
///   largest, or the second); where the training's spectrum has fewer, its last.
/// - A kind searched on a grid ([`screening::searched`]): the grid point of its family (kind
///   and axis) with the largest gain on the training units ([`screening::Screening::train_gains`],
///   against the same base), refined between its neighbours by those gains ([`refine`]).
/// - Any other effect (no non-linear parameter), or a family whose gains on the trainings
///   were not computed: the effect itself in every fold.
///
/// `None` where the training cannot determine the shape: a size's exponent of the feed on a
/// training of one feed (its columns at every exponent are then one column scaled, so the
/// choice would be rounding's; an effect of one size is chosen there among the grid points of
/// one size). That fold cannot judge the effect
/// ([`Evaluator::judgeable`]), and the scheme is passed over for it as for a rank the training
/// lacks.
///
/// The base residual is the base fit's on all data: the base is the model the diagnosis
/// starts from, and a held-out unit's share in it is that of a few dozen base parameters
/// against its thousands of samples.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fold_variants(
    refined: &[Effect],
    (usable, train_gains): (&[Effect], &[(usize, Vec<f64>)]),
    noise_var: f64,
    trainings: &[Vec<usize>],
    units: &[(usize, Range<usize>, Option<usize>)],
    (model, runs, residuals): (&Model, &[Run], &[Vec<f64>]),
    threads: usize,
) -> Vec<Vec<Option<Effect>>> {
    let n_t = trainings.len();
    let mut out: Vec<Vec<Option<Effect>>> =
        refined.iter().map(|e| vec![Some(e.clone()); n_t]).collect();
    // The feeds each training holds.
    let feeds: Vec<usize> = trainings
        .iter()
        .map(|t| {
            let mut f: Vec<f64> =
                t.iter().map(|&u| runs[units[u].0].header.feed_mm_per_min).collect();
            f.sort_by(f64::total_cmp);
            f.dedup();
            f.len()
        })
        .collect();
    // Grid kinds, from the trainings' gains.
    for (e, variants) in refined.iter().zip(out.iter_mut()) {
        if !screening::searched(e) {
            continue;
        }
        let fam: Vec<&(usize, Vec<f64>)> = train_gains
            .iter()
            .filter(|(j, _)| screening::family(&usable[*j]) == screening::family(e))
            .collect();
        if fam.len() < 2 {
            continue;
        }
        let is_scaled = |x: &Effect| matches!(x, Effect::FeedScaled { .. });
        for (t, v) in variants.iter_mut().enumerate() {
            // On one feed the exponent is not determined: a size scaled by the feed cannot be
            // judged there, and an effect of one size is chosen among the grid points of one
            // size.
            let one_feed = feeds[t] < 2;
            if one_feed && is_scaled(e) {
                *v = None;
                continue;
            }
            let screened: Vec<(usize, f64, f64)> = fam
                .iter()
                .filter(|(j, _)| !(one_feed && is_scaled(&usable[*j])))
                .map(|(j, g)| (*j, 0.0, g[t]))
                .collect();
            let best = screened.iter().max_by(|a, b| a.2.total_cmp(&b.2)).map(|x| x.0);
            if let Some(best) = best {
                *v = Some(refine(usable, &screened, noise_var, best));
            }
        }
    }
    // Spectral kinds: the rank of each one's peak on all data, then each training's peak of
    // that rank.
    let spectral: Vec<(usize, bool, Axis, usize)> = refined
        .iter()
        .enumerate()
        .filter_map(|(i, e)| match e {
            Effect::Vibration { axis, .. } => Some((i, true, *axis)),
            Effect::CyclicError { axis, .. } => Some((i, false, *axis)),
            _ => None,
        })
        .filter_map(|(i, vib, axis)| {
            let found = spectrum_peaks(vib, axis, model, runs, residuals);
            found.iter().position(|x| *x == refined[i]).map(|k| (i, vib, axis, k))
        })
        .collect();
    if spectral.is_empty() || n_t == 0 {
        return out;
    }
    let chosen = par_map(n_t, threads, |t| {
        let mut masked: Vec<Vec<f64>> = residuals.iter().map(|r| vec![0.0; r.len()]).collect();
        for &u in &trainings[t] {
            let (r, ref range, _) = units[u];
            masked[r][range.clone()].copy_from_slice(&residuals[r][range.clone()]);
        }
        spectral
            .iter()
            .map(|&(_, vib, axis, k)| {
                let found = spectrum_peaks(vib, axis, model, runs, &masked);
                found.get(k).or(found.last()).cloned()
            })
            .collect::<Vec<Option<Effect>>>()
    });
    for (t, picks) in chosen.into_iter().enumerate() {
        for (&(i, ..), pick) in spectral.iter().zip(picks) {
            if let Some(e) = pick {
                out[i][t] = Some(e);
            }
        }
    }
    out
}

/// The vibration (`vib`) or cyclic-error candidates along `axis` of a residual, as the library
/// finds them.
fn spectrum_peaks(
    vib: bool,
    axis: Axis,
    model: &Model,
    runs: &[Run],
    residuals: &[Vec<f64>],
) -> Vec<Effect> {
    if !library::linear_axes(model).contains(&axis) {
        return Vec::new();
    }
    if vib {
        library::VibrationGrid::of(runs)
            .map(|g| library::vibration_axis(&g, axis, runs, residuals))
            .unwrap_or_default()
    } else {
        library::cyclic_axis(axis, runs, residuals).0
    }
}

/// The engine's blocks of the shortlisted effects against the base, every effect's columns in
/// one set, with the chance gains that a held-out fold's refits add back.
#[allow(clippy::too_many_arguments)]
pub(crate) fn shortlist_blocks(
    base: &Base<'_>,
    design: &Design<'_>,
    cand: &[usize],
    columns: &[Vec<usize>],
    effects: &[Effect],
    units: &[(usize, Range<usize>, Option<usize>)],
    runs: &[Run],
    threads: usize,
) -> Result<engine::Blocks, FitError> {
    let cols: Vec<usize> = columns.iter().flatten().copied().collect();
    let mut blocks = engine::build_reusing(
        &base.design,
        &base.fit.residuals,
        &base.fit.values,
        design,
        cand,
        units,
        std::slice::from_ref(&cols),
        threads,
        &base.units,
    )?;
    set_refit_chance(&mut blocks, effects, columns, &base.noise, sample_rate(runs));
    blocks.nuisance_chance = nuisance_chance(&base.noise);
    Ok(blocks)
}

/// The outcome of the selection: the shortlisted effects accepted (indices, in the order
/// accepted), each one's figures on the scheme that judged it, and per shortlisted effect the
/// verdict of the last round it was tried in.
pub(crate) struct Selection {
    pub(crate) accepted: Vec<usize>,
    pub(crate) steps: Vec<Step>,
    pub(crate) verdicts: Vec<Option<Verdict>>,
}

impl Selection {
    /// The columns of the first `n` accepted effects.
    pub(crate) fn columns(&self, columns: &[Vec<usize>], n: usize) -> Vec<usize> {
        self.accepted[..n].iter().flat_map(|&x| columns[x].iter().copied()).collect()
    }

    /// The shortlisted effects not accepted, with their verdicts, nearest misses first.
    pub(crate) fn declined(&self, effects: &[Effect]) -> Vec<Declined> {
        let mut declined: Vec<Declined> = self
            .verdicts
            .iter()
            .enumerate()
            .filter(|(i, _)| !self.accepted.contains(i))
            .filter_map(|(i, v)| Some(Declined { effect: effects[i].clone(), verdict: v.clone()? }))
            .collect();
        declined.sort_by(|a, b| b.verdict.closeness().total_cmp(&a.verdict.closeness()));
        declined
    }
}

/// The greedy selection over the shortlisted effects (their columns in the engine's one set).
pub(crate) struct Selector<'a> {
    /// The held-out evaluation on the schemes.
    pub(crate) ev: &'a Evaluator<'a>,
    /// Each shortlisted effect's columns.
    pub(crate) columns: &'a [Vec<usize>],
    /// The shortlisted effects, refined.
    pub(crate) effects: &'a [Effect],
    /// The secondary scheme and the later runs, where the runs have them.
    pub(crate) secondary: Option<usize>,
    pub(crate) forward: Option<usize>,
    /// Samples of all runs.
    pub(crate) m: usize,
    /// The noise's long-run variance ratio.
    pub(crate) inflation: f64,
}

/// The figures of the set selected so far.
struct Current {
    cols: Vec<usize>,
    fit: engine::SubsetFit,
    /// Per scheme, its held-out evaluation (computed when first needed).
    eval: Vec<Option<Eval>>,
}

impl Selector<'_> {
    fn all_units(&self) -> Vec<usize> {
        (0..self.ev.blocks.units.len()).collect()
    }

    /// Greedy forward selection: each round, every shortlisted effect not yet accepted is
    /// judged against the set so far ([`Selector::judge`]); the one that passes with the
    /// largest share of its scheme's held-out energy joins the set, until none passes or
    /// `max_effects` are accepted.
    pub(crate) fn greedy(&self, max_effects: usize) -> Result<Selection, FitError> {
        let blocks = self.ev.blocks;
        let all_units = self.all_units();
        let n_schemes = self.ev.schemes.len();
        let mut sel =
            Selection { accepted: vec![], steps: vec![], verdicts: vec![None; self.columns.len()] };
        let mut current = Current {
            cols: Vec::new(),
            fit: blocks.fit(&all_units, 0, &[])?,
            eval: vec![None; n_schemes],
        };
        while sel.accepted.len() < max_effects {
            // A run's own bar length is taken only in a round where nothing else passes: it
            // holds every change of the runs' mean radius, so it would take the part of a
            // cause's that a law of the machine (a loss with the feed, a growth in time)
            // predicts, and hide the cause.
            let mut best: Option<(usize, Step)> = None;
            let mut last_resort: Option<(usize, Step)> = None;
            for i in 0..self.columns.len() {
                ballbar_model::progress::update(
                    &format!("diagnose: selecting effect {}", sel.accepted.len() + 1),
                    i,
                    self.columns.len(),
                );
                if sel.accepted.contains(&i) {
                    continue;
                }
                let (verdict, step) = self.judge(i, &mut current, &all_units)?;
                sel.verdicts[i] = Some(verdict);
                // The best: the largest share of its scheme's held-out energy (schemes differ
                // in what they hold out, so gains are compared as shares).
                let slot = if self.effects[i] == Effect::BarLengthDrift {
                    &mut last_resort
                } else {
                    &mut best
                };
                if let Some(step) = step
                    && slot.as_ref().is_none_or(|b| step.relative_gain > b.1.relative_gain)
                {
                    *slot = Some((i, step));
                }
            }
            let Some((i, step)) = best.or(last_resort) else { break };
            current.cols.extend(self.columns[i].iter().copied());
            current.fit = blocks.fit(&all_units, 0, &current.cols)?;
            current.eval = vec![None; n_schemes];
            current.eval[step.scheme] = Some(step.eval.clone());
            sel.steps.push(step);
            sel.accepted.push(i);
        }
        Ok(sel)
    }

    /// Judge shortlisted effect `i` added to the current set: its F statistic on all data
    /// (its degrees of freedom the rank it adds), then its held-out gain on the scheme that
    /// can judge it, then whether that gain is material. The verdict, and the step's figures
    /// when it passed.
    fn judge(
        &self,
        i: usize,
        current: &mut Current,
        all_units: &[usize],
    ) -> Result<(Verdict, Option<Step>), FitError> {
        let (ev, own) = (self.ev, &self.columns[i]);
        let cols: Vec<usize> = current.cols.iter().chain(own).copied().collect();
        let f = ev.blocks.fit(all_units, 0, &cols)?;
        // The columns the candidate adds to the rank (a run's own column that is zero in its
        // run, a vibration of an axis that stands still there, adds none).
        let k = f.rank.saturating_sub(current.fit.rank);
        if k == 0 {
            return Ok((Verdict::NoRank, None));
        }
        let dof = self.m.saturating_sub(f.rank).max(1) as f64;
        let fstat = ((current.fit.rss - f.rss) / k as f64) / (f.rss / dof * self.inflation);
        let needed = chi2_1e6(k) / k as f64;
        if fstat < needed {
            return Ok((Verdict::F { f: fstat, needed }, None));
        }
        // A run's own bar length is refitted on every held-out run, so held out it takes
        // whatever change of the mean radius the model trained on the fold leaves there, its
        // extrapolation error included (a growth fitted on one cycle predicting another). It
        // predicts nothing, so its evidence is on all data, the model fitted on every run: it
        // must close a material share of what that model leaves above the noise there.
        if self.effects[i] == Effect::BarLengthDrift {
            let floor = self.m as f64 * ev.noise_var;
            // Nothing above the noise on all runs: nothing for it to close (the share 0, not
            // the clamp's 1).
            let above = current.fit.rss - floor;
            let share = if above > 0.0 { (current.fit.rss - f.rss) / above } else { 0.0 };
            if excess::closed_from_energy_share(share.min(1.0)) < MATERIAL {
                let rms = |rss: f64| (rss / self.m.max(1) as f64).sqrt() * 1e3;
                let v = Verdict::NotMaterialOnAllRuns {
                    f: fstat,
                    rms_before_um: rms(current.fit.rss),
                    rms_after_um: rms(f.rss),
                    share,
                };
                return Ok((v, None));
            }
        }
        // The scheme that judges it: later runs for a time-dependent effect, else the
        // primary, else (when some fold's training cannot determine it) the secondary.
        let order: Vec<usize> = if self.effects[i].is_time_dependent() {
            self.forward.into_iter().collect()
        } else {
            std::iter::once(0).chain(self.secondary).collect()
        };
        let mut judged = None;
        for &s in &order {
            if current.eval[s].is_none() {
                current.eval[s] = Some(ev.eval(s, &current.cols)?);
            }
            let with = ev.eval(s, &cols)?;
            let before = current.eval[s].as_ref().expect("computed above");
            if ev.judgeable(s, &with, before, own, k) {
                judged = Some((s, with));
                break;
            }
        }
        let Some((s, with)) = judged else {
            let tried = order.iter().map(|&s| ev.schemes[s].kind).collect();
            return Ok((Verdict::NotJudgeable { tried }, None));
        };
        let before = current.eval[s].as_ref().expect("computed above");
        let stats = ev.stats(s, before, &with, own);
        let (b_um, a_um) = (before.rms() * 1e3, with.rms() * 1e3);
        let folds = ev.schemes[s].kind;
        if stats.gain <= 0.0 || stats.t < HELD_OUT_T {
            let v =
                Verdict::HeldOut { f: fstat, before_um: b_um, after_um: a_um, t: stats.t, folds };
            return Ok((v, None));
        }
        // Parsimony: it must close a material share of what the model still leaves above
        // the noise on the held-out data, not only stand out from zero.
        let share = stats.gain / before.excess().max(f64::MIN_POSITIVE);
        if excess::closed_from_energy_share(share) < MATERIAL {
            let v =
                Verdict::NotMaterial { f: fstat, before_um: b_um, after_um: a_um, share, folds };
            return Ok((v, None));
        }
        let rel = stats.gain / before.sse().max(f64::MIN_POSITIVE);
        let step = Step {
            f: fstat,
            before: before.rms(),
            after: with.rms(),
            interval: stats.interval,
            t: stats.t,
            scheme: s,
            relative_gain: rel,
            eval: with,
        };
        Ok((Verdict::Passed, Some(step)))
    }

    /// Each accepted effect must stand by itself: with the others in the model, leaving it out
    /// must lose held-out gain three standard errors from zero, and material, on its own
    /// scheme. One that the others have made redundant (an extra that took part of a misfit
    /// the next effect explained) is dropped, the weakest first, and the test repeated; the
    /// others' figures then come from a chain that held it, so each step is evaluated again.
    pub(crate) fn stand_alone(&self, sel: &mut Selection) -> Result<(), FitError> {
        let (ev, columns) = (self.ev, self.columns);
        let mut redundant: Vec<(usize, f64)> = Vec::new();
        while sel.accepted.len() >= 2 {
            let mut weakest: Option<(usize, f64)> = None;
            for (pos, &i) in sel.accepted.iter().enumerate() {
                let s = sel.steps[pos].scheme;
                let all = sel.columns(columns, sel.accepted.len());
                let without: Vec<usize> = sel
                    .accepted
                    .iter()
                    .filter(|&&x| x != i)
                    .flat_map(|&x| columns[x].iter().copied())
                    .collect();
                let (w, wo) = (ev.eval(s, &all)?, ev.eval(s, &without)?);
                let stats = ev.stats(s, &wo, &w, &columns[i]);
                let share = stats.gain / wo.excess().max(f64::MIN_POSITIVE);
                if (stats.t < HELD_OUT_T || excess::closed_from_energy_share(share) < MATERIAL)
                    && weakest.is_none_or(|b| stats.t < b.1)
                {
                    weakest = Some((pos, stats.t));
                }
            }
            let Some((pos, t)) = weakest else { break };
            redundant.push((sel.accepted[pos], t));
            sel.accepted.remove(pos);
            sel.steps.remove(pos);
        }
        for &(i, t) in &redundant {
            sel.verdicts[i] = Some(Verdict::Redundant { t });
        }
        if !redundant.is_empty() {
            for pos in 0..sel.accepted.len() {
                let s = sel.steps[pos].scheme;
                let (before_cols, after_cols) =
                    (sel.columns(columns, pos), sel.columns(columns, pos + 1));
                let (b, a) = (ev.eval(s, &before_cols)?, ev.eval(s, &after_cols)?);
                let stats = ev.stats(s, &b, &a, &columns[sel.accepted[pos]]);
                let step = &mut sel.steps[pos];
                (step.before, step.after, step.interval, step.t) =
                    (b.rms(), a.rms(), stats.interval, stats.t);
            }
        }
        Ok(())
    }
}

//! Backlash that switches where the axis reverses: at its lagged reversal, the commanded one
//! delayed by the axis's servo lag.
//!
//! The fit determines the lags' differences (the servo mismatch) but not their mean: a lag
//! common to the axes shifts a circle along itself, which a ballbar does not see to first order,
//! and [`crate::gauge`] takes it as 0. The reversal does see it: a backlash switched τ early
//! leaves its whole step on the samples of those τ. So the switch lags are the fitted lags
//! (their differences) plus a common lag `c` that the switch alone determines, found by
//! minimising the base fit's residual over `c` ([`switch_at_lagged_reversals`]).

use ballbar_model::{Design, TermClass};

use crate::{Factorisation, FitError, Prefactored};

mod update;

use update::SwitchUpdate;

/// At most this many rounds of (fit the lags' differences, search the common lag).
pub const MAX_SWITCH_PASSES: usize = 3;

/// The switch lags are settled when no axis's moves by more than this between rounds, s. A
/// switch that moves by 1 µs flips a sample only where one falls within that µs of a reversal
/// (one reversal in a thousand at a 1 kHz bar) and moves a reversal transient's clock by 1e-5
/// of its shortest time constant (domain brief §4: 20 ms): below any bar's noise either way.
pub const SWITCH_LAG_TOLERANCE_S: f64 = 1e-6;

/// The largest common lag searched, s: an axis of position-loop gain 16.7 s⁻¹ (1 m/min/mm, the
/// low end of machine tools without feed-forward) lags its command by 60 ms.
pub const MAX_COMMON_LAG_S: f64 = 0.1;

/// Each axis's servo lag in `theta` (the design's parameter values), s: the sum of the
/// coefficients of the model's servo-lag terms on that axis (`TX`: `δ_X = -θ dX/dt`). 0 for an
/// axis without one, and under the paper's plane mismatch terms, which state no axis's lag.
pub fn axis_lags(design: &Design<'_>, theta: &[f64]) -> [f64; 6] {
    let mut lags = [0.0; 6];
    for (k, bt) in design.model.terms.iter().enumerate() {
        if bt.term.class() == TermClass::ServoLag {
            lags[bt.axis.index()] += theta[k];
        }
    }
    lags
}

/// The axes with a servo-lag term that move in some run (an axis at rest never reverses, and
/// its lag is a gauge's 0, not a lag to take the others' differences from).
fn lagging_axes(design: &Design<'_>) -> [bool; 6] {
    let mut out = [false; 6];
    for bt in &design.model.terms {
        if bt.term.class() == TermClass::ServoLag {
            let moves = design.runs.iter().any(|r| {
                r.axis(bt.axis).is_some_and(|q| {
                    let (lo, hi) =
                        q.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                            (lo.min(x), hi.max(x))
                        });
                    hi > lo
                })
            });
            out[bt.axis.index()] |= moves;
        }
    }
    out
}

/// The first-order fit at the design's switch lags: its lags, its residual sum of squares
/// (mm²), its degrees of freedom (samples less the rank), the lag-one autocorrelation of its
/// residuals within runs, and, where the model allows ([`update::applies`]), the sums that
/// give its residual at other switch lags up to `max_lag_s` without another factorisation.
struct FirstOrder {
    lags: [f64; 6],
    rss: f64,
    dof: usize,
    rho: f64,
    update: Option<SwitchUpdate>,
    /// The factorisation, for the fit that follows when the search ends on this design.
    factored: Option<Prefactored>,
}

fn first_order(
    design: &Design<'_>,
    lagging: Option<&[bool; 6]>,
    threads: usize,
) -> Result<FirstOrder, FitError> {
    let fac = Factorisation::new(design, threads)?;
    let dof = design.n_rows().saturating_sub(fac.kept.len()).max(1);
    let theta = fac.solve_targets();
    let (rss, lag1) = fac.first_order_residual()?;
    let rho = if rss > 0.0 { lag1 / rss } else { 0.0 };
    let lags = axis_lags(design, &theta);
    let update = match lagging {
        Some(lagging) if update::applies(design) => {
            let max_lag_s = search_bound(design, &differences(&lags, lagging)) + UPDATE_SLACK_S;
            SwitchUpdate::new(design, &fac, max_lag_s, threads)?
        }
        _ => None,
    };
    Ok(FirstOrder { lags, rss, dof, rho, update, factored: Some(fac.detach()) })
}

/// How much further than its own search reaches the sums of a fit give the residual, s: the
/// lags' differences move between rounds (by the shift that ends them, 1 µs, at the end), and
/// the switch is judged at the previous round's differences. 10 ms is ten sample intervals at
/// 1 kHz; a shift beyond it (a search far from settled) factors the design at each lag instead.
const UPDATE_SLACK_S: f64 = 0.01;

/// The lags' differences: each lagging axis's lag less the lowest's (0 for the others).
fn differences(lags: &[f64; 6], lagging: &[bool; 6]) -> [f64; 6] {
    let lowest = (0..6).filter(|&a| lagging[a]).map(|a| lags[a]).fold(f64::INFINITY, f64::min);
    std::array::from_fn(|a| if lagging[a] { lags[a] - lowest } else { 0.0 })
}

/// The first-order residual sum of squares (mm²) of `design` at switch lags `lags_s`: from
/// `update` (the sums of a factorisation of `design`) where there is one, else by factoring
/// the design at those lags.
fn rss_at(
    design: &Design<'_>,
    update: Option<&SwitchUpdate>,
    lags_s: [f64; 6],
    threads: usize,
) -> Result<f64, FitError> {
    match update {
        Some(u) => u.rss(design, lags_s, threads),
        None => Ok(first_order(&design.at_switch_lags(lags_s), None, threads)?.rss),
    }
}

/// Above this lag-one autocorrelation of the residuals at the best switch the switch timing
/// is not evidence of a lag: the base then misses structure of the data (a reversal spike, a
/// cyclic error), and the switch, its one free timing, fits that instead. 0.5 is a residual
/// whose low-frequency power is three times white noise's ((1+ρ)/(1-ρ), the fit's variance
/// inflation): residuals of a base that describes the runs have ρ near 0 (white noise), the
/// real file's (spikes of 2.7-4.2 µm the base lacks, the vendor's figures) 0.84.
pub const SWITCH_WHITE_RHO: f64 = 0.5;

/// Above this Δχ² (the residual at the commanded reversal less the residual at the lagged
/// one, over the noise variance) the switch timing determines the common lag: the same
/// threshold as an alias that would show at a plausible size (`crate::alias`, χ² ≥ 9, a
/// three-σ change of the residual). Below it the data cannot tell the lagged reversal from
/// the commanded one (no backlash to speak of, or too few samples near the reversals), and
/// the backlash switches at the commanded reversal.
pub const SWITCH_DETERMINED_CHI2: f64 = 9.0;

/// Below this Δχ² of the first round's best switch against the commanded reversal (both
/// residuals from the round's sums, the noise variance the commanded fit's) the switch is
/// judged not determined at once, without the fit at the best switch and the rounds after it:
/// half of
/// [`SWITCH_DETERMINED_CHI2`], so that what further rounds could add (the lags' differences
/// refitted at the switch, which moves them little: a lag's own column is 0 at its axis's
/// reversal, where the switches act) cannot reach the threshold from below it.
const EARLY_UNDETERMINED_CHI2: f64 = SWITCH_DETERMINED_CHI2 / 2.0;

/// How far each side of the best common lag the residual is followed for its interval, in
/// sample intervals: a common lag not pinned to within this is not determined by the data.
const INTERVAL_SAMPLES: usize = 10;

/// Where the backlash switches, as [`switch_at_lagged_reversals`] found it.
#[derive(Clone, Debug, PartialEq)]
pub struct Switch {
    /// Per axis (X, Y, Z, A, B, C), s: the switch lag after the commanded reversal the design
    /// holds (all 0: the commanded reversal).
    pub lags_s: [f64; 6],
    /// The axes with a servo-lag term, whose switch was searched.
    pub axes: Vec<ballbar_model::Axis>,
    /// Rounds of (fit the lags' differences, search the common lag) taken; 0 when the model
    /// has no servo-lag term (nothing to search).
    pub rounds: usize,
    /// The common lag the switch timing gives, s (the smallest axis's switch lag at the lower
    /// end of the best step: the earliest switch the runs allow), whether or not it is held.
    pub common_lag_s: f64,
    /// The common lags whose residual is within Δχ² = 1 of the best, s: the first lags found
    /// outside it on either side (to half a sample interval; 0 where the interval reaches the
    /// commanded reversal). `[0, ∞]` when open ([`Switch::common_lag_u_s`] infinite).
    pub common_lag_interval_s: [f64; 2],
    /// Its standard uncertainty, s: half the width of the common lags whose residual is within
    /// Δχ² = 1 of the best (the staircase's step at least); `f64::INFINITY` when that interval
    /// reaches [`INTERVAL_SAMPLES`] sample intervals on a side or the search's bound.
    pub common_lag_u_s: f64,
    /// χ² of the residual at the commanded reversal less at the best lagged one.
    pub delta_chi2: f64,
    /// Lag-one autocorrelation of the first-order residuals at the best switch; at the
    /// commanded reversal where the search stopped after its first round
    /// ([`EARLY_UNDETERMINED_CHI2`]: the Δχ² decided it).
    pub rho: f64,
    /// The data determine the switch: Δχ² ≥ [`SWITCH_DETERMINED_CHI2`], a finite interval
    /// and residuals at it no more correlated than [`SWITCH_WHITE_RHO`]. Otherwise `lags_s`
    /// are all 0 (the commanded reversal).
    pub determined: bool,
}

impl Switch {
    /// No search: the commanded reversal.
    pub fn commanded() -> Switch {
        Switch {
            lags_s: [0.0; 6],
            axes: Vec::new(),
            rounds: 0,
            common_lag_s: 0.0,
            common_lag_interval_s: [0.0, f64::INFINITY],
            common_lag_u_s: f64::INFINITY,
            delta_chi2: 0.0,
            rho: 0.0,
            determined: false,
        }
    }

    /// One line for a person: where the backlash switches and why (`None` when the model has
    /// no servo-lag term, where nothing was searched).
    pub fn describe(&self) -> Option<String> {
        if self.rounds == 0 {
            return None;
        }
        Some(if self.determined {
            let each: Vec<String> = self
                .axes
                .iter()
                .map(|a| format!("{a:?} {:.3} ms", self.lags_s[a.index()] * 1e3))
                .collect();
            format!(
                "backlash switch: at each axis's lagged reversal, {} after the command (the axes' common lag {:.3} ± {:.3} ms from the switch timing, the earliest it allows within {:.3} to {:.3} ms; Δχ² {:.0} against the commanded reversal)",
                each.join(", "),
                self.common_lag_s * 1e3,
                self.common_lag_u_s * 1e3,
                self.common_lag_interval_s[0] * 1e3,
                self.common_lag_interval_s[1] * 1e3,
                self.delta_chi2
            )
        } else {
            let why = if self.delta_chi2 < SWITCH_DETERMINED_CHI2 {
                format!(
                    "it improves χ² by {:.1}, below {SWITCH_DETERMINED_CHI2}: no backlash to speak of, or too few samples near the reversals",
                    self.delta_chi2
                )
            } else if !self.common_lag_u_s.is_finite() {
                "the residual does not pin it within 10 sample intervals".to_string()
            } else {
                format!(
                    "its residual is not white (lag-1 autocorrelation {:.2} > {SWITCH_WHITE_RHO}): the base misses structure near the reversals (a spike, diagnose) that the switch timing would fit instead, which one the runs cannot tell",
                    self.rho
                )
            };
            format!(
                "backlash switch: at the commanded reversal: these runs do not determine when the lagging axes reverse (the switch timing's best common lag {:.3} ms{}: {why})",
                self.common_lag_s * 1e3,
                if self.common_lag_u_s.is_finite() {
                    format!(" ± {:.3} ms", self.common_lag_u_s * 1e3)
                } else {
                    String::new()
                },
            )
        })
    }
}

/// The design with each axis's backlash, and its reversal transients' clock, switching at the
/// model's own lagged reversal ([`Design::with_switch_lags`]).
///
/// Each round fits the design at the current switch lags (the commanded reversals at first)
/// and takes the lags' differences from it; then the common lag `c` that the fit gauges is
/// found by minimising the first-order residual over `c ∈ [c₀, c₀ + 100 ms]` (`c₀` the
/// smallest that leaves no axis a negative lag). The residual is a staircase in `c` (a sample
/// changes sign only when a switch crosses it) that falls towards the true lag and rises past
/// it, each step the samples a misplaced switch puts on the wrong side: a golden-section search
/// brackets the lowest steps to one sample interval, but its lowest step can be narrower than
/// that (its width is the spacing of the reversals' phases against the samples), so the
/// bracket and a sample interval either side are then scanned at a tenth of one. Without
/// backlash in the data the staircase is flat and any `c` is as good (it then moves nothing the
/// model holds but its reversal transients' clock). The differences move little when the
/// switches move (a lag's own column, `-τ v`, is 0 at its axis's reversal, where the switches
/// act): the rounds stop when they move by no more than [`SWITCH_LAG_TOLERANCE_S`], after at
/// most [`MAX_SWITCH_PASSES`].
///
/// The common lag is determined only to within the step the samples allow (a fraction of a
/// sample interval, or several milliseconds where the runs' reversals fall at few phases);
/// within it the residual is the same, and the step's lower end is taken
/// ([`search_common_lag`]). A first-order fit is enough: the refinement against the exact
/// chain moves a lag by about |Δ|/R ≈ 1e-3 of itself. Each round factors the design once: the
/// residual at each of the ~45 lags it searches (and the ~10 that find its step's lower end)
/// comes from that factorisation's sums and the rows near the reversals ([`update`], equal to
/// a factorisation at that lag to 1e-9 of the residual, tested), except for a model whose
/// other terms read the direction or the time since a reversal (an effect, a plugin's term),
/// whose design is factored at each lag.
///
/// The switch is then judged against the commanded reversal: held only when it lowers χ² by
/// [`SWITCH_DETERMINED_CHI2`] or more and the residual pins the common lag to a finite
/// interval ([`Switch::common_lag_u_s`]); otherwise the design switches at the commanded
/// reversal, and the [`Switch`] says so. A first round whose best switch lowers χ² by less than
/// half that ([`EARLY_UNDETERMINED_CHI2`], from the round's sums) ends the search there, judged
/// from those sums, with the commanded fit's factorisation.
///
/// Returns the design and where it switches (rounds 0: the model has no servo-lag term, the
/// design is returned as it is).
pub fn switch_at_lagged_reversals<'a>(
    design: Design<'a>,
    threads: usize,
) -> Result<(Design<'a>, Switch), FitError> {
    switch_and_factor(design, threads).map(|(d, s, _)| (d, s))
}

/// [`switch_at_lagged_reversals`], and the factorisation of the design it returns where the
/// search made one (the last round's, or the first's when the switch stays at the commanded
/// reversal): for [`crate::fit_prefactored`], which then need not factor it again.
pub fn switch_and_factor<'a>(
    design: Design<'a>,
    threads: usize,
) -> Result<(Design<'a>, Switch, Option<Prefactored>), FitError> {
    let lagging = lagging_axes(&design);
    if !lagging.iter().any(|&l| l) || design.runs.is_empty() {
        return Ok((design, Switch::commanded(), None));
    }
    let dt = design
        .runs
        .iter()
        .flat_map(|r| r.t_s.windows(2).map(|w| w[1] - w[0]))
        .fold(f64::INFINITY, f64::min);
    let dt = if dt.is_finite() && dt > 0.0 { dt } else { 1e-3 };
    let mut design = design;
    let mut rounds = 0;
    // The last round's lags' differences (`fitted` less its lowest) and best common lag.
    let mut last = ([0.0; 6], 0.0);
    // The fit at the design's switch lags (the next round's start, or the switch judged).
    let mut here = first_order(&design, Some(&lagging), threads)?;
    // The residual at the commanded reversal, against which the switch is judged: this first
    // fit's when the design starts there.
    let commanded_rss = (design.switch_lags() == [0.0; 6]).then_some(here.rss);
    // Its factorisation too, for the fit when the switch stays there.
    let commanded = if commanded_rss.is_some() { here.factored.take() } else { None };
    while rounds < MAX_SWITCH_PASSES {
        rounds += 1;
        let fitted = here.lags;
        let differences = differences(&fitted, &lagging);
        let at = |c: f64| -> [f64; 6] {
            std::array::from_fn(|a| if lagging[a] { differences[a] + c } else { 0.0 })
        };
        // The sums of `here` cover the lags this round searches, or the design is factored
        // at each.
        let update =
            here.update.as_ref().filter(|u| u.max_lag_s() >= search_bound(&design, &differences));
        let rss = |c: f64| rss_at(&design, update, at(c), threads);
        let best_c = search_common_lag(&rss, dt)?;
        last = (differences, best_c);
        // A first round from the commanded reversal whose best switch is far from determined:
        // judged from the same sums, without the fit at the best switch (at 1 kHz, 7 % of a
        // diagnosis), since the design stays at the commanded reversal.
        if rounds == 1
            && let (Some(rss_commanded), Some(u)) = (commanded_rss, update)
        {
            let var = (rss_commanded / here.dof as f64).max(f64::MIN_POSITIVE);
            // Both residuals from the sums, computed alike.
            let rss_best = u.rss(&design, at(best_c), threads)?;
            let delta_chi2 = (u.rss(&design, [0.0; 6], threads)? - rss_best) / var;
            if delta_chi2 < EARLY_UNDETERMINED_CHI2 {
                let (common_lag_interval_s, common_lag_u_s) =
                    interval(&rss, best_c, rss_best, var, dt)?;
                let switch = Switch {
                    lags_s: [0.0; 6],
                    axes: ballbar_model::Axis::ALL
                        .into_iter()
                        .filter(|a| lagging[a.index()])
                        .collect(),
                    rounds,
                    common_lag_s: best_c,
                    common_lag_interval_s,
                    common_lag_u_s,
                    delta_chi2,
                    rho: here.rho,
                    determined: false,
                };
                return Ok((design, switch, commanded));
            }
        }
        design = design.with_switch_lags(at(best_c));
        // The next round's differences are fitted at these switches; stop when they and the
        // common lag no longer move.
        here = first_order(&design, Some(&lagging), threads)?;
        let shift = (0..6)
            .filter(|&a| lagging[a])
            .map(|a| (here.lags[a] - fitted[a]).abs())
            .fold(0.0, f64::max);
        if shift <= SWITCH_LAG_TOLERANCE_S {
            break;
        }
    }
    judge(design, here, last, rounds, dt, (commanded_rss, commanded), threads)
}

/// The largest switch lag a round's search may set, s: the lags' largest difference above
/// [`MAX_COMMON_LAG_S`], or the design's own largest lag if that is more (the residual's sums
/// at the design's lags must cover both).
fn search_bound(design: &Design<'_>, differences: &[f64; 6]) -> f64 {
    let most = |l: &[f64; 6]| l.iter().copied().fold(0.0, f64::max);
    (most(differences) + MAX_COMMON_LAG_S).max(most(&design.switch_lags()))
}

/// The common lag in `[0, MAX_COMMON_LAG_S]` of the lowest residual `rss(c)`: a golden-section
/// search to one sample interval `dt`, then the bracket and a sample interval either side
/// scanned at a tenth of one (the staircase's lowest step can be narrower than the bracket:
/// its width is the spacing of the reversals' phases against the samples). Ties keep the
/// lower side, and in the scan the first found.
///
/// Then the lowest step's lower end ([`lowest_end_of_step`]): every lag on the step fits the
/// runs alike, and the one returned is the earliest switch they allow. Where the runs'
/// reversals all fall at few phases against the samples (every run at a feed starting alike,
/// a 125 Hz bar), that step is several milliseconds wide: on the independent set's two-feed
/// session, 0.1 to 5.1 ms, the axes' least true lag 0.1 ms. A point picked inside it by the
/// search (2.1 ms there) switches the backlash of runs at another feed, whose samples fall
/// inside the step, on samples where the axis has not yet reversed: the base model then
/// predicts a held-out feed 0.163 µm RMS where the switch at the step's lower end gives 0.152
/// against a noise of 0.150. Drives with feed-forward lag by tenths of a millisecond and
/// without it by tens (`MAX_COMMON_LAG_S`), so the earliest switch the data allow is the
/// nearer one on the machines that leave wide steps (small lags, few phases); on a 1 kHz bar
/// with runs at random phases the step is tens of µs wide and the choice moves nothing.
fn search_common_lag(rss: &dyn Fn(f64) -> Result<f64, FitError>, dt: f64) -> Result<f64, FitError> {
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut lo, mut hi) = (0.0, MAX_COMMON_LAG_S);
    let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
    let (mut f1, mut f2) = (rss(x1)?, rss(x2)?);
    while hi - lo > dt {
        if f1 <= f2 {
            hi = x2;
            (x2, f2) = (x1, f1);
            x1 = hi - g * (hi - lo);
            f1 = rss(x1)?;
        } else {
            lo = x1;
            (x1, f1) = (x2, f2);
            x2 = lo + g * (hi - lo);
            f2 = rss(x2)?;
        }
    }
    let (mut best_c, mut best_f) = if f1 <= f2 { (x1, f1) } else { (x2, f2) };
    let steps = 10 * 3 + (10.0 * (hi - lo) / dt).ceil() as usize;
    for k in 0..=steps {
        let c = lo - dt + k as f64 * dt / 10.0;
        if !(0.0..=MAX_COMMON_LAG_S).contains(&c) {
            continue;
        }
        let f = rss(c)?;
        if f < best_f {
            (best_c, best_f) = (c, f);
        }
    }
    lowest_end_of_step(rss, best_c, best_f, dt)
}

/// A residual within this relative amount of the lowest is on the lowest step: the residuals
/// compared come from one set of sums or factorisations, equal for a switch between the same
/// samples to rounding (1e-13 of the residual in double precision); a step a sample's sign
/// makes is at least that sample's share, 1e-6 of the residual or more at any bar's noise and
/// a backlash of a tenth of a µm.
const FLAT_STEP_RELATIVE: f64 = 1e-9;

/// How finely the lower end of the lowest step is found, in sample intervals: 1/100 of one
/// (80 µs at 125 Hz, 10 µs at 1 kHz), below the spacing of reversals' phases that a step's
/// width reflects.
const STEP_END_RESOLUTION: f64 = 0.01;

/// The lower end of the step of `rss` on which `best_c` lies (residual `best_f`): walked down
/// from it by a tenth of a sample interval `dt`, the step doubling each time (a step of any
/// width in a few residuals), to the first lag off the step (or `c = 0`), then bisected to
/// [`STEP_END_RESOLUTION`] of one; the lowest lag found on the step. A lower residual met on
/// the way is a lower step: the walk goes on from it. Where the residual is not flat (a
/// reversal transient's clock moves with the switch) the step is the best lag alone and that
/// is returned.
fn lowest_end_of_step(
    rss: &dyn Fn(f64) -> Result<f64, FitError>,
    best_c: f64,
    best_f: f64,
    dt: f64,
) -> Result<f64, FitError> {
    let mut best_f = best_f;
    let on_step = |f: f64, best_f: f64| f <= best_f + FLAT_STEP_RELATIVE * best_f.abs();
    let (mut on, mut off, mut step) = (best_c, None, dt / 10.0);
    while on > 0.0 {
        let c = (on - step).max(0.0);
        let f = rss(c)?;
        if on_step(f, best_f) {
            best_f = best_f.min(f);
            on = c;
            step *= 2.0;
        } else {
            off = Some(c);
            break;
        }
    }
    if let Some(mut off) = off {
        while on - off > STEP_END_RESOLUTION * dt {
            let mid = 0.5 * (on + off);
            let f = rss(mid)?;
            if on_step(f, best_f) {
                best_f = best_f.min(f);
                on = mid;
            } else {
                off = mid;
            }
        }
    }
    Ok(on)
}

/// The common lags about `best_c` (residual `rss_base`) whose residual `rss` is within Δχ² = 1
/// of it (noise variance `var`): followed outwards at half a sample interval `dt` (a switch
/// crosses each sample of a reversal once per interval, so no edge of the staircase is missed
/// by more than that) until the residual rises by more, the first lag outside on each side. The
/// physical bound c = 0 (the lowest axis at its commanded reversal) ends it too; the search's
/// bound or [`INTERVAL_SAMPLES`] leave it open. Returns the interval as [`Switch`] states it
/// (`[0, ∞]` when open) and its u, half the interval between the first lags outside (the
/// scan's half sample interval included, so never narrower than the resolution the samples
/// allow; infinite when open).
fn interval(
    rss: &dyn Fn(f64) -> Result<f64, FitError>,
    best_c: f64,
    rss_base: f64,
    var: f64,
    dt: f64,
) -> Result<([f64; 2], f64), FitError> {
    let open = Ok(([0.0, f64::INFINITY], f64::INFINITY));
    let mut ends = [best_c, best_c];
    for (side, sign) in [(0, -1.0), (1, 1.0)] {
        let mut k = 1;
        loop {
            let c = best_c + sign * k as f64 * dt / 2.0;
            if c < 0.0 {
                ends[side] = 0.0;
                break;
            }
            if c > MAX_COMMON_LAG_S || k > 2 * INTERVAL_SAMPLES {
                return open;
            }
            if (rss(c)? - rss_base) / var > 1.0 {
                ends[side] = c;
                break;
            }
            k += 1;
        }
    }
    Ok((ends, (ends[1] - ends[0]) / 2.0))
}

/// The switch found (`last`: the lags' differences and the best common lag; `best`: the fit
/// at it) against the commanded reversal (`commanded_rss`, the first-order residual there when
/// already known): its Δχ², the interval of common lags the residual allows, and the design
/// that holds the one the data determine.
fn judge<'a>(
    design: Design<'a>,
    best: FirstOrder,
    (differences, best_c): ([f64; 6], f64),
    rounds: usize,
    dt: f64,
    (commanded_rss, commanded): (Option<f64>, Option<Prefactored>),
    threads: usize,
) -> Result<(Design<'a>, Switch, Option<Prefactored>), FitError> {
    let lagging = lagging_axes(&design);
    let at = |c: f64| -> [f64; 6] {
        std::array::from_fn(|a| if lagging[a] { differences[a] + c } else { 0.0 })
    };
    let (rss_best, dof, rho) = (best.rss, best.dof, best.rho);
    // The noise variance of the best fit: χ² of another switch is its RSS less the best's over it.
    let var = (rss_best / dof as f64).max(f64::MIN_POSITIVE);
    let rss_commanded = match commanded_rss {
        Some(rss) => rss,
        None => first_order(&design.at_switch_lags([0.0; 6]), None, threads)?.rss,
    };
    let delta_chi2 = (rss_commanded - rss_best) / var;
    // The interval ([`interval`]); the residuals compared are computed alike (the best's too,
    // where the sums give them).
    let update = best.update.as_ref().filter(|u| {
        u.max_lag_s() >= search_bound(&design, &differences) && design.switch_lags() == at(best_c)
    });
    let rss_base = match update {
        Some(_) => rss_at(&design, update, at(best_c), threads)?,
        None => rss_best,
    };
    let rss = |c: f64| rss_at(&design, update, at(c), threads);
    let (common_lag_interval_s, common_lag_u_s) = interval(&rss, best_c, rss_base, var, dt)?;
    let determined = delta_chi2 >= SWITCH_DETERMINED_CHI2
        && common_lag_u_s.is_finite()
        && rho <= SWITCH_WHITE_RHO;
    let lags_s = if determined { at(best_c) } else { [0.0; 6] };
    let design = design.with_switch_lags(lags_s);
    // The factorisation of the design returned, where the search made one.
    let factored = [best.factored, commanded]
        .into_iter()
        .flatten()
        .find(|p| p.shape == crate::shape_of(&design));
    Ok((
        design,
        Switch {
            lags_s,
            rho,
            axes: ballbar_model::Axis::ALL.into_iter().filter(|a| lagging[a.index()]).collect(),
            rounds,
            common_lag_s: best_c,
            common_lag_interval_s,
            common_lag_u_s,
            delta_chi2,
            determined,
        },
        factored,
    ))
}

#[cfg(test)]
mod step_tests {
    use super::*;

    #[test]
    fn the_common_lag_is_the_lowest_steps_lower_end_and_a_sloped_minimum_stays() {
        // A staircase as a 125 Hz bar's few reversal phases leave it: samples 0.05, 5.1 and
        // 13.1 ms after the reversals (then every 8 ms), the true lag 0.3 ms; each sample
        // between the switch and the true lag adds its backlash's square, 0.1. The lowest
        // step is (0.05, 5.1] ms; the earliest lag on it is 0.05 ms, found to 1/100 of a
        // sample interval (0.08 ms).
        let dt = 8e-3;
        let samples: Vec<f64> = [0.05e-3, 5.1e-3, 13.1e-3]
            .into_iter()
            .chain((3..14).map(|k| 0.05e-3 + k as f64 * dt))
            .collect();
        let truth = 0.3e-3;
        let staircase = |c: f64| -> Result<f64, FitError> {
            let wrong = samples.iter().filter(|&&t| (t < c) != (t < truth)).count();
            Ok(1.0 + 0.1 * wrong as f64)
        };
        let c = search_common_lag(&staircase, dt).unwrap();
        assert!(c > 0.05e-3 && c <= 0.05e-3 + STEP_END_RESOLUTION * dt, "{c}");
        assert_eq!(staircase(c).unwrap(), 1.0);
        // A residual that falls to its least at 3 ms and rises past it (a transient's clock
        // moving with the switch): the least, to the scan's tenth of a sample interval.
        let sloped = |c: f64| -> Result<f64, FitError> { Ok(1.0 + (c - 3e-3).powi(2)) };
        let c = search_common_lag(&sloped, dt).unwrap();
        assert!((c - 3e-3).abs() <= dt / 10.0, "{c}");
    }
}

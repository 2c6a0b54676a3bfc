//! Backlash that switches where the axis reverses: at its lagged reversal, the commanded one
//! delayed by the axis's servo lag.
//!
//! The fit determines the lags' differences (the servo mismatch) but not their mean: a lag
//! common to the axes shifts a circle along itself, which a ballbar does not see to first order,
//! and [`crate::gauge`] takes it as 0. The reversal does see it: a backlash switched τ early
//! leaves its whole step on the samples of those τ. So the switch lags are the fitted lags
//! (their differences) plus a common lag `c` that the switch alone determines, found by
//! minimising the base fit's residual over `c` ([`switch_at_lagged_reversals`]).

use ballbar_model::parallel::par_map;
use ballbar_model::{Design, TermClass};

use crate::{Factorisation, FitError};

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

/// The axes with a servo-lag term.
fn lagging_axes(design: &Design<'_>) -> [bool; 6] {
    let mut out = [false; 6];
    for bt in &design.model.terms {
        if bt.term.class() == TermClass::ServoLag {
            out[bt.axis.index()] = true;
        }
    }
    out
}

/// The first-order fit at the design's switch lags: its lags and its residual sum of squares
/// (mm²).
fn first_order(design: &Design<'_>, threads: usize) -> Result<([f64; 6], f64), FitError> {
    let fac = Factorisation::new(design, threads)?;
    let theta = fac.solve_targets();
    let rss: Vec<Result<f64, FitError>> = par_map(design.runs.len(), threads, |r| {
        let model = fac.apply(r, &theta)?;
        Ok(fac.targets(r).iter().zip(&model).map(|(b, m)| (b - m) * (b - m)).sum())
    });
    let rss = rss.into_iter().sum::<Result<f64, FitError>>()?;
    Ok((axis_lags(design, &theta), rss))
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
/// sample interval); within it the residual is the same. A first-order fit is enough: the
/// refinement against the exact chain moves a lag by about |Δ|/R ≈ 1e-3 of itself. Each
/// round costs about 45 factorisations of the design.
///
/// Returns the design and the rounds taken (0: the model has no servo-lag term, the design is
/// returned as it is).
pub fn switch_at_lagged_reversals<'a>(
    design: Design<'a>,
    threads: usize,
) -> Result<(Design<'a>, usize), FitError> {
    let lagging = lagging_axes(&design);
    if !lagging.iter().any(|&l| l) || design.runs.is_empty() {
        return Ok((design, 0));
    }
    let dt = design
        .runs
        .iter()
        .flat_map(|r| r.t_s.windows(2).map(|w| w[1] - w[0]))
        .fold(f64::INFINITY, f64::min);
    let dt = if dt.is_finite() && dt > 0.0 { dt } else { 1e-3 };
    let mut design = design;
    let mut rounds = 0;
    while rounds < MAX_SWITCH_PASSES {
        rounds += 1;
        let (fitted, _) = first_order(&design, threads)?;
        let lowest =
            (0..6).filter(|&a| lagging[a]).map(|a| fitted[a]).fold(f64::INFINITY, f64::min);
        let at = |c: f64| -> [f64; 6] {
            std::array::from_fn(|a| if lagging[a] { fitted[a] - lowest + c } else { 0.0 })
        };
        let evaluate = |d: Design<'a>, c: f64| -> Result<(Design<'a>, f64), FitError> {
            let d = d.with_switch_lags(at(c));
            let (_, rss) = first_order(&d, threads)?;
            Ok((d, rss))
        };
        // Golden section on [0, MAX_COMMON_LAG_S]; ties keep the lower side.
        let g = (5f64.sqrt() - 1.0) / 2.0;
        let (mut lo, mut hi) = (0.0, MAX_COMMON_LAG_S);
        let (mut x1, mut x2) = (hi - g * (hi - lo), lo + g * (hi - lo));
        let (d, mut f1) = evaluate(design, x1)?;
        let (d, mut f2) = evaluate(d, x2)?;
        design = d;
        while hi - lo > dt {
            if f1 <= f2 {
                hi = x2;
                (x2, f2) = (x1, f1);
                x1 = hi - g * (hi - lo);
                let (d, f) = evaluate(design, x1)?;
                (design, f1) = (d, f);
            } else {
                lo = x1;
                (x1, f1) = (x2, f2);
                x2 = lo + g * (hi - lo);
                let (d, f) = evaluate(design, x2)?;
                (design, f2) = (d, f);
            }
        }
        // The staircase's lowest step can be narrower than the bracket (its width is the
        // spacing of the reversals' phases against the samples): scan the bracket and a
        // sample interval either side at a tenth of it.
        let (mut best_c, mut best_f) = if f1 <= f2 { (x1, f1) } else { (x2, f2) };
        let steps = 10 * 3 + (10.0 * (hi - lo) / dt).ceil() as usize;
        for k in 0..=steps {
            let c = lo - dt + k as f64 * dt / 10.0;
            if !(0.0..=MAX_COMMON_LAG_S).contains(&c) {
                continue;
            }
            let (d, f) = evaluate(design, c)?;
            design = d;
            if f < best_f {
                (best_c, best_f) = (c, f);
            }
        }
        let best = at(best_c);
        design = design.with_switch_lags(best);
        // The next round's differences are fitted at these switches; stop when they and the
        // common lag no longer move.
        let (refitted, _) = first_order(&design, threads)?;
        let shift = (0..6)
            .filter(|&a| lagging[a])
            .map(|a| (refitted[a] - fitted[a]).abs())
            .fold(0.0, f64::max);
        if shift <= SWITCH_LAG_TOLERANCE_S {
            break;
        }
    }
    Ok((design, rounds))
}

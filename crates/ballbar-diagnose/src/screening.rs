//! Step 3 of the method: screening every candidate on all data, and the aliased ones.
//!
//! Screening on all data: each candidate added alone to the base; an F statistic whose
//! noise variance is inflated by the noise model's long-run variance ratio
//! ([`localise::Noise::inflation`](crate::localise::Noise::inflation), `(1+ρ)/(1-ρ)` for AR(1) noise: neighbouring samples of
//! a trace are not independent). A candidate is *aliased* when the base model's span holds
//! most of it, an effect of ordinary size ([`Effect::typical_size`](ballbar_model::Effect::typical_size)) would leave, outside
//! that span over all units together, a signal too small to show against the noise, and the
//! data do not determine it either (it adds less than its full rank to the base's, or its F
//! statistic does not pass the acceptance level): it is reported with the base parameters
//! it would hide in and the test that would separate it. Typical sizes decide only that,
//! what is called aliased: a candidate whose size the data determine is fitted and judged
//! like any other, however far from its typical size (a common servo lag of 4 ms seen at
//! two feeds, against the typical 1 ms). Nothing else in the diagnosis reads them.

use std::ops::Range;

use ballbar_fit::FitError;
use ballbar_model::parallel::par_map;
use ballbar_model::{Design, Effect};

use crate::{Aliased, DiagnoseError, engine};

/// χ²(k) at the 1e-6 level (an effect of one pair of columns per run has k up to 2 × runs):
/// the upper-tail quantile of the χ² distribution, by bisection on the regularised upper
/// incomplete gamma function Q(k/2, x/2) = 1e-6.
pub(crate) fn chi2_1e6(k: usize) -> f64 {
    let a = k.max(1) as f64 / 2.0;
    let (mut lo, mut hi) = (0.0, 20.0 * k.max(1) as f64 + 100.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if gamma_q(a, mid / 2.0) > 1e-6 { lo = mid } else { hi = mid }
    }
    0.5 * (lo + hi)
}

/// ln Γ(a), a > 0 (Lanczos, g = 7, 9 terms: 1e-15 relative).
pub(crate) fn ln_gamma(a: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    let x = a - 1.0;
    let t = x + 7.5;
    let s = C[0] + (1..9).map(|i| C[i] / (x + i as f64)).sum::<f64>();
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + s.ln()
}

/// The regularised upper incomplete gamma function Q(a, x): the series of P below `a + 1`, the
/// continued fraction (modified Lentz) above.
pub(crate) fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let front = (-x + a * x.ln() - ln_gamma(a)).exp();
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        return (1.0 - sum * front).max(0.0);
    }
    let tiny = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / tiny;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..10_000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < tiny {
            d = tiny;
        }
        c = b + an / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-16 {
            break;
        }
    }
    front * h
}

/// A candidate is aliased with the base model when an effect of typical size
/// ([`Effect::typical_size`]) would leave, outside the base model's span, a signal whose F
/// statistic against the noise stays below this (a tenth of the acceptance level: not even a
/// hint would show), and the data do not show it at its own size (the screening).
pub(crate) const ALIASED_F: f64 = 2.0;

/// A candidate can be aliased with the base model only when the base model's span holds more
/// than half of its energy (the share outside it, [`Aliased::visible_share`], is below this).
/// The aliases of the suite lie far below (a bar-length error at one radius and an angular
/// error at one tool length: 0; on the real single-plane file, degree-3 straightness against
/// squareness 0.2). A candidate the base leaves mostly alone is a shape of its own whatever its
/// size: on the real file a reversal spike keeps 97 % of its energy outside the base (backlash,
/// servo mismatch) at τ = 10 ms and 53-66 % at 180 ms, the share going to zero only as τ → ∞,
/// where the spike becomes a backlash step. A spike is aliased with backlash and servo
/// mismatch only when the noise floor makes every candidate too small to show.
pub(crate) const ALIASED_VISIBLE: f64 = 0.5;

/// The base parameter names a set of coefficients projects onto most.
pub(crate) fn names_for(id: &str, label: &str) -> String {
    // Short metrological names for the paper's ids (ASCII by construction); the label
    // otherwise, so that an id of other characters (a plugin's) never meets a byte slice.
    let c: Vec<char> = id.chars().collect();
    let axis = |x: char| matches!(x, 'X' | 'Y' | 'Z');
    match c.as_slice() {
        ['B', 'A', 'R'] => "bar length".into(),
        ['S', 'Q', u, v] => format!("squareness {u}{v}"),
        ['C', ..] if id.contains('@') => "centring".into(),
        ['B', a] if axis(*a) => format!("backlash {a}"),
        ['T', a] if axis(*a) => format!("servo lag {a}"),
        ['E', e, a, d] if e == a && axis(*a) && d.is_ascii_digit() => {
            format!("positional {a} (degree {d})")
        }
        ['E', e, a, d] if axis(*e) && axis(*a) && d.is_ascii_digit() => {
            format!("straightness {a} in {e} (degree {d})")
        }
        _ => label.to_string(),
    }
}

/// The base parameters an aliased candidate hides in: the three largest contributions of its
/// projection onto the base columns.
pub(crate) fn aliased_with(
    blocks: &engine::Blocks,
    train: &[usize],
    cols: &[usize],
    design: &Design<'_>,
) -> Result<Vec<String>, FitError> {
    // Fit the candidate's first column as the target of the base: the top rows carry its
    // projection (W), so stack [R | W_col] and solve R x ≈ W_col.
    let col = cols[0];
    let proj = blocks.project(train, col)?;
    let mut contrib: Vec<(usize, f64)> = proj
        .iter()
        .enumerate()
        .map(|(i, &x)| (i, x.abs() * blocks.base_col_norm(train, i)))
        .collect();
    contrib.sort_by(|a, b| b.1.total_cmp(&a.1));
    let total: f64 = contrib.iter().map(|c| c.1).sum();
    let mut names: Vec<String> = Vec::new();
    for (i, c) in contrib {
        if (c < 0.1 * total && !names.is_empty()) || names.len() >= 3 || c <= 0.0 {
            break;
        }
        let p = &design.parameters[i];
        let name = names_for(&p.id, &p.label);
        if !names.contains(&name) {
            names.push(name);
        }
    }
    Ok(names)
}

/// What screening leaves for the selection.
pub(crate) struct Screening {
    /// The candidates that are not aliased: (effect, F, gain on all data).
    pub(crate) screened: Vec<(usize, f64, f64)>,
    /// The aliased candidates, one entry per kind and axis ([`one_per_kind`]).
    pub(crate) aliased: Vec<Aliased>,
    /// The best grid point of each kind and axis, best F first, at most the options' shortlist.
    pub(crate) shortlist: Vec<usize>,
    /// Candidates screened (grid points included).
    pub(crate) candidates_screened: usize,
    /// Per grid point of the searched kinds on the shortlist ([`searched`]: the grid points of
    /// its first families, every one not aliased), its gain on each fold's training units
    /// alone (`trainings`, in order): what the selection chooses a fold's non-linear
    /// parameters from ([`crate::selection::fold_variants`]), so that no held-out unit has a
    /// say in the shape it is scored with.
    pub(crate) train_gains: Vec<(usize, Vec<f64>)>,
}

/// True for an effect whose non-linear parameters the library searches on a grid (a spike's
/// decay time and ringing, a stick-slip's speed, a thermal growth's time constant or none,
/// a size's exponent of the feed): the screening's gains over its grid points choose them.
pub(crate) fn searched(e: &Effect) -> bool {
    match e {
        Effect::ReversalTransient { .. }
        | Effect::ReversalSpike { .. }
        | Effect::StickSlip { .. }
        | Effect::ThermalGrowth { .. } => true,
        Effect::FeedScaled { effect, .. } => searched(effect),
        _ => false,
    }
}

/// The family of an effect on the grid: its kind and axis (a size scaled by the feed is its
/// effect's kind), as the shortlist holds one of each.
pub(crate) fn family(e: &Effect) -> (&'static str, Option<String>) {
    (e.kind(), e.axis_label())
}

/// Screen every candidate alone against the base (its design, fit and noise, and the cache of
/// its units' factors, [`engine::BaseUnits`], for that design and fit alone), on all data: its
/// F statistic, or aliased; then the shortlist.
#[allow(clippy::too_many_arguments)]
pub(crate) fn screen(
    (design0, fit0, noise, reuse): (
        &Design<'_>,
        &ballbar_fit::Fit,
        &crate::localise::Noise,
        &engine::BaseUnits,
    ),
    cand_design: &Design<'_>,
    cand_cols: &[usize],
    columns: &[Vec<usize>],
    usable: &[Effect],
    units: &[(usize, Range<usize>, Option<usize>)],
    (shortlist_len, trainings, families): (usize, &[Vec<usize>], usize),
    threads: usize,
) -> Result<Screening, DiagnoseError> {
    let inflation = noise.inflation();
    let blocks = engine::build_reusing(
        design0,
        &fit0.residuals,
        &fit0.values,
        cand_design,
        cand_cols,
        units,
        columns,
        threads,
        reuse,
    )?;
    let all_units: Vec<usize> = (0..blocks.units.len()).collect();
    let m = design0.n_rows();
    let base_fit = blocks.fit(&all_units, 0, &[])?;
    let unreachable = blocks.unreachable(&all_units)?;
    // Each candidate alone, on the worker threads (each fit stands alone: the same numbers
    // whatever the thread count), in the library's order.
    enum Outcome {
        Empty,
        Aliased(Aliased),
        Screened(f64, f64),
    }
    let done = std::sync::atomic::AtomicUsize::new(0);
    let outcomes = par_map(columns.len(), threads, |j| -> Result<Outcome, DiagnoseError> {
        let cols = &columns[j];
        let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        ballbar_model::progress::update("diagnose: screening the candidates", d, columns.len());
        let cn: f64 = cols.iter().map(|&c| blocks.c_norm2[c]).sum();
        if cn <= 0.0 {
            return Ok(Outcome::Empty);
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
            let with = aliased_with(&blocks, &all_units, cols, design0)?;
            return Ok(Outcome::Aliased(Aliased {
                effect: usable[j].clone(),
                with,
                visible_share: visible,
                test_to_separate: usable[j].separating_test(),
            }));
        }
        Ok(Outcome::Screened(fstat, gain))
    });
    let mut screened: Vec<(usize, f64, f64)> = Vec::new(); // (effect, F, gain)
    let mut aliased = Vec::new();
    for (j, outcome) in outcomes.into_iter().enumerate() {
        match outcome? {
            Outcome::Empty => {}
            Outcome::Aliased(a) => aliased.push(a),
            Outcome::Screened(fstat, gain) => screened.push((j, fstat, gain)),
        }
    }
    let candidates_screened = columns.len();
    one_per_kind(&mut aliased);
    let shortlist = shortlist(&mut screened, usable, shortlist_len);
    // The grid points of the first `families` searched families of the shortlist, each on
    // every fold's training alone.
    let keys: Vec<_> = shortlist
        .iter()
        .filter(|&&j| searched(&usable[j]))
        .take(families)
        .map(|&j| family(&usable[j]))
        .collect();
    let members: Vec<usize> = screened
        .iter()
        .map(|s| s.0)
        .filter(|&j| searched(&usable[j]) && keys.contains(&family(&usable[j])))
        .collect();
    let train_gains = if trainings.is_empty() || members.is_empty() {
        Vec::new()
    } else {
        let base_rss: Vec<f64> = trainings
            .iter()
            .map(|t| blocks.fit(t, 0, &[]).map(|f| f.rss))
            .collect::<Result<_, _>>()?;
        let gains = ballbar_model::parallel::par_map(members.len(), threads, |m| {
            let j = members[m];
            trainings
                .iter()
                .zip(&base_rss)
                .map(|(t, b)| blocks.fit(t, j, &columns[j]).map(|f| b - f.rss))
                .collect::<Result<Vec<f64>, FitError>>()
        });
        members
            .iter()
            .copied()
            .zip(gains)
            .map(|(j, g)| g.map(|g| (j, g)))
            .collect::<Result<Vec<_>, FitError>>()?
    };
    Ok(Screening { screened, aliased, shortlist, candidates_screened, train_gains })
}

/// Aliased effects: one entry per kind and axis for the grid effects (decay time, speed,
/// pitch), each of the others (an angular error about each direction, each degree).
fn one_per_kind(aliased: &mut Vec<Aliased>) {
    let mut seen = Vec::new();
    aliased.retain(|a: &Aliased| {
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
}

/// The shortlist: the best grid point of each kind and axis, `screened` sorted by F, best
/// first, at most `len` of them.
fn shortlist(screened: &mut [(usize, f64, f64)], usable: &[Effect], len: usize) -> Vec<usize> {
    screened.sort_by(|a, b| b.1.total_cmp(&a.1));
    let mut shortlist: Vec<usize> = Vec::new();
    let mut keys = Vec::new();
    for &(j, _, _) in screened.iter() {
        let key = (usable[j].kind(), usable[j].axis_label());
        if !keys.contains(&key) {
            keys.push(key);
            shortlist.push(j);
        }
        if shortlist.len() >= len {
            break;
        }
    }
    shortlist
}

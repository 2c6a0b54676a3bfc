//! What the base model would silently take for something else: plausible terms it lacks and
//! set-up metadata the runs cannot check, each projected onto the base design of the runs at
//! hand, with what it would move and the test that would tell.
//!
//! # Method
//! A candidate is a column `c` over the runs' samples, per unit of its size:
//! - a term the base lacks ([`Candidate::Term`]): a positional error of each moving axis of a
//!   degree above the base's, straightness degrees the base does not hold, angular error
//!   motions not tied to a straightness (with the runs' own Abbe arms); its column is the
//!   term's design column;
//! - set-up metadata ([`Candidate::PivotShift`], [`Candidate::ToolLength`]): the derivative of
//!   the fitted model's exact prediction with respect to the whole set-up shifted along an axis
//!   (pivot and coordinates together, as `--pivot` moves a `.b5r` test) or the tool made longer,
//!   at the fitted parameters, by forward differences of [`METADATA_STEP_MM`], at the base's
//!   switch lags.
//!
//! The base absorbs `β = A⁺ c` ([`crate::Factorisation::solve`]); what it cannot absorb is
//! `c - A β`. A candidate of plausible size `a` ([`Candidate::plausible_size`]) would show in
//! the residual with `χ² = a² ‖c - Aβ‖² / (σ² k)` (`k` the fit's AR(1) variance inflation). Below
//! [`SHOWS_CHI2`] the data cannot tell it: it is an alias, and every reported quantity `f·θ`
//! moves by `f·β` per unit of it. A quantity it moves by more than its standard uncertainty at
//! the plausible size is *conditional* on it; so is one that the alternative below moves by
//! more than its u, when the runs cannot refuse that alternative either (χ² at its size below
//! [`SHOWS_CHI2`]): at shop-floor noise a curvature of plausible size moves the straightness
//! that carries it by less than that straightness's u, while the fitted straightness is many u
//! from zero and the curvature that would replace it fits the readings as well.
//!
//! For a term, the alternative explanation is stated as a value: the candidate sized so that
//! the polynomial term (positional, straightness, angular) that carries most of its projection
//! (largest `|β_j| ‖A_j‖`, and at least a tenth of the largest carrier's) vanishes,
//! `a* = θ_j / β_j`; each moved quantity then reads `f·θ - a* f·β` (for the quadratic pitch
//! of X against straightness of X along Y and Z at one centre: the squareness that holds if
//! the curvature is X's positional error). Which holds is a choice the runs cannot make, so
//! the quantity's uncertainty carries it: [`Move::u_with_spread`] adds half the distance to
//! the alternative in quadrature (the two explanations taken as the ends of a range, its
//! half-width as a standard uncertainty: the conservative reading of GUM's rectangular
//! `half-width/√3`), and the statistical `u` is kept beside it. For metadata the spread has
//! no natural end (a pivot can be wrong by any amount): the sensitivity per 100 mm is given
//! instead, and the local quantities ([`crate::local`]) are the determined ones.

use ballbar_model::parallel::par_map;
use ballbar_model::{
    Axis, BlockScratch, Design, Effect, MachineSpec, Model, ModelOptions, NoKernels, ParamClass,
    TermClass, Unit,
};

use ballbar_model::local::local_functional;

use crate::local::{LocalQuantity, local_quantities};
use crate::{Factorisation, Fit, FitError};

/// A candidate shows in the residual when, at its plausible size, the part the base cannot
/// absorb stands 3 standard deviations above the noise in its own direction (χ² of one degree
/// of freedom ≥ 9: a chance of 0.27 % under noise alone). Below, the runs cannot tell it.
pub const SHOWS_CHI2: f64 = 9.0;

/// A quantity is conditional on metadata when 100 mm of it ([`Candidate::plausible_size`])
/// moves the quantity by more than this many of its standard uncertainties; on a term when the
/// term's plausible size moves it by more than one. Metadata has no plausible bound (a pivot
/// not given is 0, 0, 0, hundreds of mm from the truth): a tenth, so that a value that moves
/// at all with a choice the user may have made blindly says so.
pub const METADATA_RELEVANCE: f64 = 0.1;

/// Step of the metadata's forward differences, mm: the prediction is a polynomial of degree
/// ≤ 4 in positions normalised by L ≥ 100 mm, so the truncation error is ≲ 4 h/(2L) ≈ 2e-4
/// relative at h = 0.01 mm; rounding (1e-16 of coordinates of ≲ 1e3 mm, over h) is ≈ 1e-11
/// per mm, against sensitivities of ≳ 1e-7 (0.1 µm per m of shift) where one matters. One
/// evaluation of the exact chain per candidate, and one shared, rather than two each.
pub const METADATA_STEP_MM: f64 = 0.01;

/// A plausible term the base lacks, or set-up metadata the runs cannot check.
#[derive(Clone, Debug, PartialEq)]
pub enum Candidate {
    /// A term the base model lacks.
    Term(Effect),
    /// The whole set-up (pivot and coordinates) shifted along an axis, per mm.
    PivotShift(Axis),
    /// The tool longer (the tool ball farther from the gauge point along -Z), per mm.
    ToolLength,
}

impl Candidate {
    /// The kind, as the JSON names it (`positional_higher_order`, `pivot`, `tool_length`, …).
    pub fn kind(&self) -> &'static str {
        match self {
            Candidate::Term(e) => e.kind(),
            Candidate::PivotShift(_) => "pivot",
            Candidate::ToolLength => "tool_length",
        }
    }

    /// The axis it concerns, as the JSON names it.
    pub fn axis(&self) -> Option<String> {
        match self {
            Candidate::Term(e) => e.axis_label(),
            Candidate::PivotShift(a) => Some(a.to_string()),
            Candidate::ToolLength => None,
        }
    }

    /// In words.
    pub fn description(&self) -> String {
        match self {
            Candidate::Term(e) => e.describe(),
            Candidate::PivotShift(a) => format!("the circle centre's {a} coordinate (--pivot)"),
            Candidate::ToolLength => {
                "the tool length the runs state (their tool ball, --tool-ball-mm)".into()
            }
        }
    }

    /// True for set-up metadata.
    pub fn is_metadata(&self) -> bool {
        !matches!(self, Candidate::Term(_))
    }

    /// A plausible size, internal units: a term's ordinary size on a machine worth measuring
    /// ([`Effect::typical_size`]: 1 µm at L for a polynomial, 5 µrad for an angle); 100 mm for
    /// metadata (a circle centre's machine coordinates, or a tool length, not given: the
    /// fixtures' pivots and tools lie within a few hundred mm).
    pub fn plausible_size(&self) -> f64 {
        match self {
            Candidate::Term(e) => e.typical_size(),
            Candidate::PivotShift(_) | Candidate::ToolLength => 100.0,
        }
    }

    /// The unit of its size.
    pub fn unit(&self) -> Unit {
        match self {
            Candidate::Term(Effect::AngularError { .. }) => Unit::Angle,
            _ => Unit::Length,
        }
    }

    /// The test that would separate it from the base model.
    pub fn test_to_separate(&self) -> &'static str {
        match self {
            Candidate::Term(Effect::PositionalHigherOrder { .. }) => {
                "circles at a second centre along the axis, or a laser's positional measurement of the axis"
            }
            Candidate::Term(Effect::StraightnessHigherOrder { .. }) => {
                "circles at a second centre along the axis, or another radius"
            }
            Candidate::Term(e) => e.separating_test(),
            Candidate::PivotShift(_) => {
                "give the circle centre's machine coordinates (--pivot); circles at a second centre determine the field's slope along the axis"
            }
            Candidate::ToolLength => {
                "state the tool length measured (--tool-ball-mm, or the run header); a second tool length separates the angular errors"
            }
        }
    }
}

/// A reported quantity: a machine parameter or a local quantity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// A machine parameter (index into the fit's parameters).
    Parameter(usize),
    /// A local quantity (index into [`Assessment::local`]).
    Local(usize),
}

/// How an alias moves one reported quantity.
#[derive(Clone, Debug, PartialEq)]
pub struct Move {
    /// The quantity.
    pub quantity: Quantity,
    /// Its name (a parameter id, or a local quantity's name and test).
    pub name: String,
    /// Its unit.
    pub unit: Unit,
    /// Its change per unit of the candidate, internal units: for a term, how much the base's
    /// estimate takes up per unit of the term in the machine (`f·β`); for metadata, how much the
    /// estimate changes per mm that the set-up is given shifted (`-f·β`).
    pub per_unit: f64,
    /// The reported value, internal units.
    pub value: f64,
    /// Its statistical standard uncertainty.
    pub std_uncertainty: f64,
    /// For a term: the value if the alternative explanation holds.
    pub alternative: Option<f64>,
    /// `u` with half the distance to the alternative in quadrature (`u` for metadata).
    pub u_with_spread: f64,
}

/// A candidate the runs cannot tell from the base model, and what it moves.
#[derive(Clone, Debug, PartialEq)]
pub struct Alias {
    /// The candidate.
    pub candidate: Candidate,
    /// Share of its energy that the base cannot absorb.
    pub visible_share: f64,
    /// χ² of that share at the plausible size against the noise.
    pub chi2_at_plausible: f64,
    /// For a term: the base parameter that carries most of it (index), and the candidate's size
    /// (internal units) at which that parameter would vanish.
    pub alternative: Option<(usize, f64)>,
    /// The base parameters that carry most of its projection (ids, largest first, at most 3).
    pub with: Vec<String>,
    /// The quantities it moves by more than their `u` at its plausible size.
    pub moves: Vec<Move>,
    /// What the base takes up per unit of it, `β = A⁺ c` (every parameter, internal units).
    pub absorbed: Vec<f64>,
}

impl Alias {
    /// The alternative in words: `if the curvature is positional error of X, degree 2 (EYX2 =
    /// 0): 3.1 µm`.
    pub fn alternative_text(&self, fit: &Fit) -> Option<String> {
        let (j, a) = self.alternative?;
        let p = &fit.parameters[j];
        let unit = self.candidate.unit();
        Some(format!(
            "if the data's shape is {} of {:.3} {} (and {} is 0)",
            self.candidate.description(),
            a * unit.display_factor(),
            unit.display_name(),
            p.id
        ))
    }
}

/// What the fit determines where the tests are, and what it takes for something else.
#[derive(Clone, Debug, PartialEq)]
pub struct Assessment {
    /// The local quantities of every planar test.
    pub local: Vec<LocalQuantity>,
    /// The aliases, terms first, then metadata.
    pub aliases: Vec<Alias>,
    /// The candidates tried.
    pub candidates_tried: usize,
}

impl Assessment {
    /// The aliases (indices into [`Assessment::aliases`]) a reported quantity is conditional on:
    /// what a compensation writer must refuse or flag.
    pub fn conditional_on(&self, q: Quantity) -> Vec<usize> {
        self.aliases
            .iter()
            .enumerate()
            .filter(|(_, a)| a.moves.iter().any(|m| m.quantity == q))
            .map(|(k, _)| k)
            .collect()
    }

    /// The move of quantity `q` by alias `k`, if it moves it.
    pub fn move_of(&self, k: usize, q: Quantity) -> Option<&Move> {
        self.aliases.get(k)?.moves.iter().find(|m| m.quantity == q)
    }

    /// The aliases that move another reported functional of the machine parameters (a paper
    /// quantity, say: `Σ c_i θ_i`), by the same rule as the listed quantities: by more than its
    /// u at the alias's plausible size (a tenth of it for metadata).
    pub fn conditional_functional(&self, fit: &Fit, coeffs: &[(usize, f64)]) -> Vec<usize> {
        let e = fit.functional(coeffs);
        if !e.estimable {
            return Vec::new();
        }
        self.aliases
            .iter()
            .enumerate()
            .filter(|(_, a)| {
                let taken: f64 = coeffs.iter().map(|&(i, c)| c * a.absorbed[i]).sum();
                let relevant = if a.candidate.is_metadata() { METADATA_RELEVANCE } else { 1.0 };
                (a.candidate.plausible_size() * taken).abs() > relevant * e.std_uncertainty
            })
            .map(|(k, _)| k)
            .collect()
    }
}

/// The linear axes the runs move (by more than 1 mm in some run).
fn moving_axes(design: &Design<'_>) -> Vec<Axis> {
    design
        .model
        .chain
        .axes()
        .into_iter()
        .filter(|a| !a.is_rotary())
        .filter(|&a| {
            design.runs.iter().any(|r| {
                r.axis(a).is_some_and(|c| {
                    let (lo, hi) =
                        c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                            (l.min(x), h.max(x))
                        });
                    hi - lo > 1.0
                })
            })
        })
        .collect()
}

/// The candidate terms the base model lacks, for the axes the runs move.
pub fn term_candidates(design: &Design<'_>) -> Vec<Effect> {
    let ids: Vec<String> = design.parameters.iter().map(|p| p.id.clone()).collect();
    let has = |id: String| ids.contains(&id);
    let axes = moving_axes(design);
    let linear: Vec<Axis> =
        design.model.chain.axes().into_iter().filter(|a| !a.is_rotary()).collect();
    let mut out = Vec::new();
    for &a in &axes {
        let top = (1..=ballbar_model::machine::MAX_DEGREE)
            .filter(|d| has(format!("E{a}{a}{d}")))
            .max()
            .unwrap_or(0);
        for degree in (top + 1).max(2)..=(top + 2).max(3) {
            if degree <= ballbar_model::machine::MAX_DEGREE && !has(format!("E{a}{a}{degree}")) {
                out.push(Effect::PositionalHigherOrder { axis: a, degree });
            }
        }
        for &b in linear.iter().filter(|&&b| b != a) {
            for degree in [2, 3] {
                if !has(format!("E{b}{a}{degree}")) {
                    out.push(Effect::StraightnessHigherOrder { axis: a, toward: b, degree });
                }
            }
        }
        for about in Axis::LINEAR {
            let rot = ["A", "B", "C"][about.index()];
            if !has(format!("E{rot}{a}1")) {
                out.push(Effect::AngularError { axis: a, about });
            }
        }
    }
    out
}

/// A candidate's column per run, and its own part of each local quantity per unit of it.
type Column = (Vec<Vec<f64>>, Vec<f64>);

/// The candidates' columns per run, as the design's `fill_run` gives them, and each one's own
/// coefficient in each local quantity of `local`. The candidates' design is the base design's
/// runs under a model of the candidates alone ([`Design::with_model`]: the runs' preparation
/// and kept geometry reused); `threads` runs at a time.
fn term_columns(
    design: &Design<'_>,
    effects: &[Effect],
    local: &[LocalQuantity],
    threads: usize,
) -> Result<Vec<Column>, FitError> {
    // A model of the candidates alone (no machine terms, no reading terms): its machine
    // columns are the candidates' own, one column each (each effect here is one term).
    let bare = MachineSpec { terms: vec![], ..design.model.spec.clone() };
    let options = ModelOptions {
        bar_length: ballbar_model::BarLength::Known(0.0),
        servo: ballbar_model::ServoVariant::AxisLag,
    };
    let model = Model::with_effects(bare, options, &NoKernels, effects)?;
    let cdesign = design.with_model(&model)?;
    let nc = cdesign.n_machine;
    let cols: Vec<usize> = (0..nc).collect();
    let per_run = par_map(design.runs.len(), threads, |r| {
        let mr = design.runs[r].len();
        let mut buf = vec![0.0; mr * nc];
        let mut b = vec![0.0; mr];
        cdesign.fill_run(r, &cols, &mut buf, &mut b, &mut BlockScratch::default()).map(|_| buf)
    });
    let per_run = per_run.into_iter().collect::<Result<Vec<_>, _>>()?;
    // The candidates' own local functionals: what each adds to the field where the tests are.
    let own: Vec<Vec<f64>> = local
        .iter()
        .map(|l| local_functional(&model, l.plane, &l.pivot_mm, &l.tool_ball_mm, l.kind))
        .collect::<Result<_, _>>()?;
    // Effect k owns the columns model.effect_ids[k]; one each here.
    let mut out = Vec::with_capacity(effects.len());
    let mut at = 0;
    for ids in &model.effect_ids {
        let k = at;
        at += ids.len();
        let column = (0..design.runs.len())
            .map(|r| {
                let mr = design.runs[r].len();
                per_run[r][k * mr..(k + 1) * mr].to_vec()
            })
            .collect();
        out.push((column, own.iter().map(|g| g[k]).collect()));
    }
    Ok(out)
}

/// A change of the set-up metadata: `shift(pivot, tool_ball, h)` moves it by `h` mm (the runs'
/// coordinates move with the pivot).
type Shift = dyn Fn(&mut [f64; 3], &mut [f64; 3], f64) + Sync;

/// The derivative of the exact prediction at `theta` with respect to each set-up change of
/// `shifts`, forward from `at` (the prediction as given), and of each local quantity's
/// functional at `theta` (the local quantities are stated where the metadata puts the test;
/// central differences, a few functionals). Each run under each change is evaluated as a
/// design of its own (its own columns taken from `theta`: the same numbers as in a design of
/// every run), `threads` at a time. `None` for a change under which some run cannot be
/// evaluated (a chain whose nominal geometry the change breaks).
fn metadata_columns(
    design: &Design<'_>,
    theta: &[f64],
    at: &[Vec<f64>],
    threads: usize,
    local: &[LocalQuantity],
    shifts: &[&Shift],
) -> Vec<Option<Column>> {
    let h = METADATA_STEP_MM;
    let n_runs = design.runs.len();
    let nm = design.n_machine;
    let moved = par_map(shifts.len() * n_runs, threads, |t| -> Option<Vec<f64>> {
        let (shift, r) = (shifts[t / n_runs], t % n_runs);
        let mut run = design.runs[r].clone();
        let hd = &mut run.header;
        let (pivot, tool) = (&mut hd.pivot_mm, &mut hd.tool_ball_mm);
        let before = *pivot;
        shift(pivot, tool, h);
        let by: Vec<f64> = (0..3).map(|i| pivot[i] - before[i]).collect();
        // The coordinates of each axis move as the pivot's component does.
        for (c, by) in run.axes.iter_mut().zip(by) {
            if let Some(c) = c.as_mut().filter(|_| by != 0.0) {
                c.iter_mut().for_each(|x| *x += by);
            }
        }
        // At the base's switch lags, so that the difference is the set-up's alone.
        let d =
            Design::with_origin(design.model, std::slice::from_ref(&run), design.origin_unix_s())
                .ok()?
                .with_switch_lags(design.switch_lags());
        let own = design.run_columns(r);
        if d.n_cols() != nm + own.len() {
            return None;
        }
        let theta_r: Vec<f64> = theta[..nm].iter().chain(&theta[own]).copied().collect();
        let p = d.exact_run(0, &theta_r).ok()?;
        Some(p.iter().zip(&at[r]).map(|(a, b)| (a - b) / h).collect())
    });
    let mut moved = moved.into_iter();
    shifts
        .iter()
        .map(|shift| {
            let column: Option<Vec<Vec<f64>>> = moved.by_ref().take(n_runs).collect();
            let column = column?;
            // The local values' functionals where the metadata puts the test (first order, as
            // the projection is).
            let value = |l: &LocalQuantity, h: f64| -> Option<f64> {
                let (mut p, mut t) = (l.pivot_mm, l.tool_ball_mm);
                shift(&mut p, &mut t, h);
                let f = local_functional(design.model, l.plane, &p, &t, l.kind).ok()?;
                Some(f.iter().zip(theta).map(|(a, b)| a * b).sum())
            };
            let values = local
                .iter()
                .map(|l| Some((value(l, h)? - value(l, -h)?) / (2.0 * h)))
                .collect::<Option<Vec<f64>>>()?;
            Some((column, values))
        })
        .collect()
}

/// Assess the fit: its local quantities and its aliases, on the design it was fitted on, with
/// the factorisation it was solved with ([`crate::fit_factored`]).
pub fn assess(
    design: &Design<'_>,
    fit: &Fit,
    fac: &Factorisation,
    threads: usize,
) -> Result<Assessment, FitError> {
    let local = local_quantities(design, fit)?;
    let n_runs = design.runs.len();
    let machine: Vec<usize> = (0..design.n_machine)
        .filter(|&j| fit.estimable[j] && !fit.parameters[j].class.is_nuisance())
        .collect();
    // The base columns' norms ‖A_j‖, to rank what carries a projection.
    let norms: Vec<f64> = (0..design.n_machine).map(|j| fac.column_norm(j)).collect();
    let mut candidates: Vec<(Candidate, Column)> = Vec::new();
    let effects = term_candidates(design);
    if !effects.is_empty() {
        for (e, c) in effects.iter().zip(term_columns(design, &effects, &local, threads)?) {
            candidates.push((Candidate::Term(e.clone()), c));
        }
    }
    let planar = design.runs.iter().all(|r| r.header.plane.axes().is_some());
    // The prediction as the metadata stand, shared by the forward differences.
    let at: Option<Vec<Vec<f64>>> = planar
        .then(|| par_map(n_runs, threads, |r| design.exact_run(r, &fit.values).ok()))
        .and_then(|v| v.into_iter().collect());
    if let Some(at) = &at {
        let pivot = |i: usize| move |p: &mut [f64; 3], _: &mut [f64; 3], h: f64| p[i] += h;
        let [x, y, z] = Axis::LINEAR.map(|a| pivot(a.index()));
        let tool = |_: &mut [f64; 3], t: &mut [f64; 3], h: f64| t[2] -= h;
        let shifts: [&Shift; 4] = [&x, &y, &z, &tool];
        let which =
            Axis::LINEAR.map(Candidate::PivotShift).into_iter().chain([Candidate::ToolLength]);
        let columns = metadata_columns(design, &fit.values, at, threads, &local, &shifts);
        for (cand, col) in which.zip(columns) {
            if let Some(c) = col {
                candidates.push((cand, c));
            }
        }
    }
    let candidates_tried = candidates.len();
    let noise = (fit.sigma_mm * fit.sigma_mm * fit.inflation).max(f64::MIN_POSITIVE);
    // Every candidate's projection in one pass over the rows (each pass regenerates them).
    let rhs: Vec<&[Vec<f64>]> = candidates.iter().map(|(_, (c, _))| c.as_slice()).collect();
    let betas = fac.solve_many(&rhs)?;
    let thetas: Vec<&[f64]> = betas.iter().map(Vec::as_slice).collect();
    let absorbed = par_map(n_runs, threads, |r| fac.apply_many(r, &thetas));
    let absorbed = absorbed.into_iter().collect::<Result<Vec<_>, _>>()?;
    let results: Vec<(Vec<f64>, f64, f64, f64)> = candidates
        .iter()
        .zip(betas)
        .enumerate()
        .map(|(k, ((cand, (c, _)), beta))| {
            let (mut total, mut left) = (0.0, 0.0);
            for (r, col) in c.iter().enumerate() {
                total += col.iter().map(|x| x * x).sum::<f64>();
                left +=
                    col.iter().zip(&absorbed[r][k]).map(|(x, y)| (x - y) * (x - y)).sum::<f64>();
            }
            let size = cand.plausible_size();
            (beta, total, left, size * size * left / noise)
        })
        .collect();
    let mut aliases = Vec::new();
    for ((cand, (_, own)), (beta, total, left, chi2)) in candidates.into_iter().zip(results) {
        if total <= 0.0 || chi2 >= SHOWS_CHI2 {
            continue;
        }
        let size = cand.plausible_size();
        // What carries it: the largest contributions |β_j| ‖A_j‖ among the reported machine
        // parameters.
        let mut carriers: Vec<(usize, f64)> =
            machine.iter().map(|&j| (j, beta[j].abs() * norms[j])).collect();
        carriers.sort_by(|a, b| b.1.total_cmp(&a.1));
        let with: Vec<String> = carriers
            .iter()
            .filter(|c| c.1 > 0.1 * carriers[0].1)
            .take(3)
            .map(|c| fit.parameters[c.0].id.clone())
            .collect();
        // The alternative: the candidate in place of the polynomial term (positional,
        // straightness, angular) that carries most of it. A squareness, backlash or lag is a
        // quantity of its own, never the term an absent polynomial is taken for.
        let polynomial = |j: usize| {
            matches!(
                fit.parameters[j].class,
                ParamClass::Term(
                    TermClass::Positional | TermClass::Straightness | TermClass::Angular
                )
            )
        };
        let alternative = match (&cand, carriers.iter().find(|c| polynomial(c.0))) {
            (Candidate::Term(_), Some(&(j, w))) if w > 0.1 * carriers[0].1 && beta[j] != 0.0 => {
                Some((j, fit.values[j] / beta[j]))
            }
            _ => None,
        };
        // The alternative is one the runs cannot refuse: at its size the candidate's part
        // outside the base would not show either (χ² scales with the size squared). A larger
        // one would leave a residual the fit does not have, so it is no alternative, and a
        // quantity it alone would move is not conditional on it.
        let consistent = alternative.is_some_and(|(_, a)| chi2 * (a / size).powi(2) < SHOWS_CHI2);
        let mut moves = Vec::new();
        // `direct`: the quantity's own change per unit of the candidate: for a term, its part of
        // the quantity (what the truth holds beside what the base takes up); for metadata, the
        // change of the quantity's functional where the metadata puts the test.
        let mut consider =
            |quantity: Quantity, name: String, unit: Unit, f: &[(usize, f64)], direct: f64| {
                let mut e = fit.functional(f);
                if !e.estimable {
                    return;
                }
                if let Quantity::Local(i) = quantity {
                    e.value = local[i].estimate.value;
                }
                // First order, as β is: a local value's second-order part (which its value
                // carries, `crate::local`) would need the exact refit at the changed metadata,
                // not its linearisation; measured by such refits, it stays within a few tenths
                // of u (the invariance tests).
                let taken = f.iter().map(|&(i, x)| x * beta[i]).sum::<f64>();
                let per_unit = if cand.is_metadata() { direct - taken } else { taken - direct };
                let relevant = if cand.is_metadata() { METADATA_RELEVANCE } else { 1.0 };
                // Conditional when the candidate at its plausible size moves the quantity by
                // more than its u, or when the alternative the runs cannot refuse does (a
                // straightness fitted at 4 µm that a pitch curvature of 4 µm would replace, on
                // a test whose noise hides a plausible 1 µm: the reported value is one of two).
                let by_alternative = alternative
                    .filter(|_| consistent)
                    .is_some_and(|(_, a)| (a * per_unit).abs() > e.std_uncertainty);
                if (size * per_unit).abs() <= relevant * e.std_uncertainty && !by_alternative {
                    return;
                }
                // The carrier's own alternative is zero by construction (a* = θ_j / β_j): what
                // the subtraction leaves of it is rounding, 1e-16 of the terms, which would
                // print as a negative zero. A difference within 1e-12 of the larger term is
                // taken as the zero it is.
                let alt = alternative.map(|(_, a)| {
                    let (x, y) = (e.value, a * per_unit);
                    if (x - y).abs() <= 1e-12 * x.abs().max(y.abs()) { 0.0 } else { x - y }
                });
                let spread = alt.map(|x| 0.5 * (x - e.value)).unwrap_or(0.0);
                moves.push(Move {
                    quantity,
                    name,
                    unit,
                    per_unit,
                    value: e.value,
                    std_uncertainty: e.std_uncertainty,
                    alternative: alt,
                    u_with_spread: e.std_uncertainty.hypot(spread),
                });
            };
        for &j in &machine {
            let p = &fit.parameters[j];
            if matches!(
                p.class,
                ParamClass::Term(_) | ParamClass::PlaneMismatch | ParamClass::BarLength
            ) {
                consider(Quantity::Parameter(j), p.id.clone(), p.unit, &[(j, 1.0)], 0.0);
            }
        }
        // The local values against metadata: their functional moves with the test as the
        // fit's solution does, so they are unchanged to first order by construction; β here is
        // of the exact prediction's derivative (second order included) and the functional's
        // change first order, so their difference would be the second order alone, and only
        // half of it: the refits of the invariance tests measure it instead (≤ 0.3 u).
        for (i, l) in local.iter().enumerate().filter(|_| !cand.is_metadata()) {
            let name = format!("{} ({})", l.name, l.test_text());
            consider(Quantity::Local(i), name, l.unit, &l.coefficients, own[i]);
        }
        if moves.is_empty() {
            continue;
        }
        aliases.push(Alias {
            candidate: cand,
            visible_share: left / total,
            chi2_at_plausible: chi2,
            alternative,
            with,
            moves,
            absorbed: beta,
        });
    }
    Ok(Assessment { local, aliases, candidates_tried })
}

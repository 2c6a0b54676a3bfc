//! The fit report: the terminal text a metrologist reads and the JSON other programs read
//! (`ballbar-fit/1`), and the helpers the HTML page shares with them.
//!
//! # What the labels mean (terminal, JSON, the HTML page alike)
//! - **u**: the standard uncertainty (k = 1), shown to two significant digits with the value to
//!   the same decimal place ([`value_and_u`]), so that a small u is never shown as 0.
//! - **In Renishaw's units** (JSON `paper.quantities[].vendor`): the same quantity as Renishaw's
//!   ballbar software states it, to compare with its report: a positional error as the axis's
//!   scale error (ppm), an angular error in arcsec, a squareness in µm/m, a servo mismatch as
//!   the lag difference of its two axes (ms) ([`RENISHAW_UNITS`]).
//! - **Polynomial parameters** (`EXX1`, `EYX2`, `ECX1`…: positional, straightness and angular
//!   terms): θ is the coefficient of `s^k`, `s = (q − q_ref)/L` the axis position normalised by
//!   the machine's fixed length `L` (not by the test's radius): θ is the error at `q = q_ref + L`.
//!   The paper's quantities at radius R are θ·(R/L)^k (a positional EXX1 = 14.12 µm with
//!   L = 250 mm is 8.47 µm at R = 150 mm). Each such parameter says its basis ([`Basis`]):
//!   terminal and page `θ·(X/250 mm)²`, JSON `basis` and `normalisation` (`axis`,
//!   `reference_mm`, `length_mm`, `degree`; null for other parameters).
//! - **G, F, H** of the runs: ISO 230-4's circular deviation (about the least-squares circle),
//!   radial deviation (max and min about the nominal radius) and hysteresis (between CW and
//!   CCW). Not the diagnosis's partial-F statistic.

use std::fmt::Write;

use ballbar_documents::fit as doc;
use ballbar_fit::{Fit, metrics, quantity};
use ballbar_model::machine::{Model, ServoVariant, TermSpec};
use ballbar_model::{Axis, Design, ParamClass, Run, TermClass, paper};

/// Everything a fit report shows, computed once.
pub struct FitReport<'a> {
    model: &'a Model,
    design: &'a Design<'a>,
    fit: &'a Fit,
    /// The fit's aliases ([`ballbar_fit::alias`]), to mark what they move.
    aliases: Option<&'a ballbar_fit::alias::Assessment>,
}

fn um(x_mm: f64) -> f64 {
    x_mm * 1e3
}

/// Widest name a terminal table shows, characters. A name sets its column's width, and a width
/// beyond the formatter's range (65,535) panicked; a longer name is shortened ([`clipped`]).
pub const NAME_COLUMN_CHARS: usize = 48;

/// `name` for a table column of at most `max` characters: as it is when it fits, otherwise
/// its start and its end around `…` (the end tells a file's runs apart: `…-ccw-2`).
pub fn clipped(name: &str, max: usize) -> std::borrow::Cow<'_, str> {
    let n = name.chars().count();
    if n <= max || max < 3 {
        return name.into();
    }
    let tail = (max - 1) / 2;
    let head = max - 1 - tail;
    let start: String = name.chars().take(head).collect();
    let end: String = name.chars().skip(n - tail).collect();
    format!("{start}…{end}").into()
}

impl<'a> FitReport<'a> {
    /// Prepare a report.
    pub fn new(model: &'a Model, design: &'a Design<'a>, fit: &'a Fit) -> FitReport<'a> {
        FitReport { model, design, fit, aliases: None }
    }

    /// Mark the values the fit's aliases move (`†`, with the aliases' numbers).
    pub fn with_aliases(mut self, a: &'a ballbar_fit::alias::Assessment) -> FitReport<'a> {
        self.aliases = Some(a);
        self
    }

    /// `" †[0,3]"` for a functional that aliases move, else empty.
    fn alias_mark(&self, coeffs: &[(usize, f64)]) -> String {
        match self.aliases.map(|a| a.conditional_functional(self.fit, coeffs)) {
            Some(k) if !k.is_empty() => {
                format!(" †[{}]", k.iter().map(|k| k.to_string()).collect::<Vec<_>>().join(","))
            }
            _ => String::new(),
        }
    }

    fn servo(&self) -> &'static str {
        match self.model.options.servo {
            ServoVariant::AxisLag => "per-axis lag",
            ServoVariant::PlaneMismatch => "paper plane mismatch",
        }
    }

    fn combination(&self, c: &ballbar_fit::NullCombination) -> (String, String) {
        let f = self.fit;
        let text = c
            .components
            .iter()
            .map(|&(i, a)| {
                format!("{} {:+.3} {}", f.parameters[i].id, a, f.parameters[i].unit.display_name())
            })
            .collect::<Vec<_>>()
            .join(", ");
        (text, null_hint(f, c))
    }

    /// The terminal report.
    pub fn terminal(&self) -> String {
        let f = self.fit;
        let runs = self.design.runs;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "ballbar fit — machine '{}', servo model: {}, {} runs, {} samples",
            self.model.spec.name,
            self.servo(),
            runs.len(),
            f.n_samples
        );
        let _ = writeln!(
            s,
            "rank {} of {} parameters, condition number {:.3e}, residual σ {:.3} µm (lag-1 autocorrelation of the residuals {:.2}: uncertainties ×{:.2} for it)",
            f.rank,
            f.parameters.len(),
            f.condition_number,
            um(f.sigma_mm),
            f.rho,
            f.inflation.sqrt()
        );
        let (r, feed, rows) = paper_rows(self.model, f, runs);
        let held = paper_conditional(self.model, f, runs);
        let _ = writeln!(
            s,
            "\nThe paper's quantities at R = {r} mm, F = {feed} mm/min (u: standard uncertainty, k = 1)"
        );
        let _ = writeln!(
            s,
            "  {:<34} {:>10} {:>9}  {:<6} {:>12}",
            "quantity", "value", "u", "unit", "in Renishaw's units"
        );
        let functionals = paper_functionals(self.model, f, runs);
        let mut marked = false;
        for (((p, v), held), c) in rows.iter().zip(&held).zip(&functionals) {
            if p.estimate.estimable {
                let dagger = self.alias_mark(c);
                marked |= !dagger.is_empty();
                let (value, u) = value_and_u(p.estimate.value, p.estimate.std_uncertainty, 2);
                let (vendor, _) = value_and_u(v.estimate.value, v.estimate.std_uncertainty, 2);
                let mark = if held.is_empty() { "" } else { " *" };
                let _ = writeln!(
                    s,
                    "  {:<34} {value:>10} {u:>9}  {:<6} {vendor:>12} {}{mark}{dagger}",
                    p.name, p.unit, v.unit
                );
            } else {
                let _ = writeln!(
                    s,
                    "  {:<34} {:>10} {:>9}  {:<6} {:>12}",
                    p.name,
                    "—",
                    "",
                    p.unit,
                    crate::wording::NOT_IDENTIFIABLE
                );
            }
        }
        let _ = writeln!(s, "  in Renishaw's units: {RENISHAW_UNITS}");
        if held.iter().any(|h| !h.is_empty()) {
            let _ = writeln!(
                s,
                "  * holds for a choice these tests leave open (below: Fixed by these tests' limits)"
            );
        }
        if marked {
            let _ = writeln!(
                s,
                "  †[k] moved by alias k: holds only for the base model's explanation, or for the pivot and tool length given (below: What these runs cannot tell)"
            );
        }
        let _ = writeln!(s, "\nMachine parameters (value ± standard uncertainty, k = 1)");
        let bases: Vec<Option<Basis>> =
            (0..f.n_machine).map(|i| Basis::of(self.model, &f.parameters[i].id)).collect();
        if let Some(text) = normalisation_text(&bases) {
            let _ = writeln!(s, "  {text}");
        }
        for (i, basis) in bases.iter().enumerate() {
            let p = &f.parameters[i];
            let k = p.unit.display_factor();
            let what = match basis {
                Some(b) => format!("{}: {}", p.label, b.text()),
                None => p.label.clone(),
            };
            if f.estimable[i] {
                let mark = if f.depends_on(&[(i, 1.0)]).is_empty() { "" } else { " *" };
                let dagger = match self.aliases {
                    Some(a) => {
                        let k = a.conditional_on(ballbar_fit::alias::Quantity::Parameter(i));
                        if k.is_empty() {
                            String::new()
                        } else {
                            let k: Vec<String> = k.iter().map(|k| k.to_string()).collect();
                            format!(" †[{}]", k.join(","))
                        }
                    }
                    None => String::new(),
                };
                let (value, u) = value_and_u(f.values[i] * k, f.std_uncertainty[i] * k, 3);
                let _ = writeln!(
                    s,
                    "  {:<6} {value:>11} ± {u:<9} {:<5} {what}{mark}{dagger}",
                    p.id,
                    p.unit.display_name()
                );
            } else {
                // The status in the value and u columns (11 + 3 + 9 characters).
                let _ = writeln!(
                    s,
                    "  {:<6} {:>23} {:<5} {what}",
                    p.id,
                    crate::wording::not_estimated(f, i),
                    p.unit.display_name()
                );
            }
        }
        // A single parameter that a choice below fixes is said there.
        let nulls: Vec<&ballbar_fit::NullCombination> = f
            .null_space
            .iter()
            .filter(|c| !(c.components.len() == 1 && fixed_by(f, c.components[0].0).is_some()))
            .collect();
        if !nulls.is_empty() {
            let _ = writeln!(
                s,
                "\nWhat these tests cannot separate (moving the parameters together by these amounts changes no reading):"
            );
            for c in nulls {
                let (text, hint) = self.combination(c);
                let _ = writeln!(s, "  {text}\n      → {hint}");
            }
        }
        if !f.gauges.is_empty() {
            let _ = writeln!(
                s,
                "\nFixed by these tests' limits (the fit's choices for what these runs cannot determine):"
            );
            for g in &f.gauges {
                let held = if g.conditional.is_empty() {
                    String::new()
                } else {
                    format!("; {} (marked *) hold for this choice", ids(f, &g.conditional))
                };
                let _ = writeln!(s, "  {}: {}{held}\n      → {}", g.what, g.choice, g.separate_by);
            }
        }
        let _ = writeln!(
            s,
            "\nRuns: before → after the model, µm (ISO 230-4: G the circular deviation about the least-squares circle; F the radial deviation, max / min about the nominal radius; H the hysteresis)"
        );
        // Run names as long as they come (a .b5r file's runs carry the file's name), up to a
        // width the table can hold.
        let names: Vec<String> =
            runs.iter().map(|r| clipped(&r.name(), NAME_COLUMN_CHARS).into_owned()).collect();
        let w = names.iter().map(|n| n.chars().count()).max().unwrap_or(0).max(14);
        let _ = writeln!(
            s,
            "  {:<w$} {:<5} {:<4} {:>7}  {:>16}  {:>16}  {:>18}",
            "run", "plane", "dir", "feed", "RMS", "G", "F max / min after"
        );
        for (k, (b, a)) in run_figures(f, runs).iter().enumerate() {
            let h = &runs[k].header;
            let _ = writeln!(
                s,
                "  {:<w$} {:<5} {:<4} {:>7}  {:>7.2} → {:<6.2}  {:>7.2} → {:<6.2}  {:>8.2} / {:<8.2}",
                names[k],
                h.plane.name(),
                h.direction.map(|d| d.name()).unwrap_or("-"),
                h.feed_mm_per_min,
                um(b.rms),
                um(a.rms),
                um(b.g),
                um(a.g),
                um(a.f_max),
                um(a.f_min)
            );
        }
        // How the samples were placed, where a reader chose it (a `.b5r` file's runs).
        let mut placed: Vec<(&str, Vec<&str>)> = Vec::new();
        for (k, run) in runs.iter().enumerate() {
            if ballbar_io::b5r::SpacingMode::of(run).is_none() {
                continue;
            }
            match placed.iter_mut().find(|p| p.0 == placement_words(run)) {
                Some(p) => p.1.push(&names[k]),
                None => placed.push((placement_words(run), vec![&names[k]])),
            }
        }
        for (words, which) in &placed {
            let runs_text =
                if placed.len() > 1 { format!(" ({})", which.join(", ")) } else { String::new() };
            let _ = writeln!(s, "  samples placed on the arc {words}{runs_text}");
        }
        for (i, j) in pairs(runs) {
            let before = metrics::hysteresis(&runs[i], &runs[i].dr_mm, &runs[j], &runs[j].dr_mm);
            let after = metrics::hysteresis(&runs[i], &f.residuals[i], &runs[j], &f.residuals[j]);
            if let (Some(b), Some(a)) = (before, after) {
                let _ = writeln!(
                    s,
                    "  hysteresis H {} / {}: {:.2} → {:.2} µm",
                    runs[i].name(),
                    runs[j].name(),
                    um(b),
                    um(a)
                );
            }
        }
        s
    }

    /// The fit document (`ballbar-fit/1`), without `assumed` and `vendor_comparison`, which
    /// the command adds from its inputs.
    pub fn json(&self) -> doc::Fit {
        let f = self.fit;
        let runs = self.design.runs;
        let (r, feed, rows) = paper_rows(self.model, f, runs);
        let held = paper_conditional(self.model, f, runs);
        let est = |q: &ballbar_fit::QuantityEstimate, held: &[usize]| doc::Estimate {
            name: q.name.clone(),
            unit: q.unit.into(),
            value: q.estimate.estimable.then_some(q.estimate.value),
            std_uncertainty: q.estimate.estimable.then_some(q.estimate.std_uncertainty),
            estimable: q.estimate.estimable,
            conditional_on_gauges: held.to_vec(),
            conditional_on_aliases: Vec::new(),
        };
        let parameters = (0..f.parameters.len())
            .map(|i| {
                let p = &f.parameters[i];
                let k = p.unit.display_factor();
                let basis = (i < f.n_machine).then(|| Basis::of(self.model, &p.id)).flatten();
                doc::Parameter {
                    id: p.id.clone(),
                    label: p.label.clone(),
                    unit: p.unit.display_name().into(),
                    nuisance: p.class.is_nuisance(),
                    basis: basis.as_ref().map(Basis::text),
                    normalisation: basis.as_ref().map(|b| doc::Normalisation {
                        axis: b.axis.name().into(),
                        reference_mm: b.reference_mm,
                        length_mm: b.length_mm,
                        degree: b.degree,
                    }),
                    estimable: f.estimable[i],
                    value: f.estimable[i].then_some(f.values[i] * k),
                    std_uncertainty: f.estimable[i].then_some(f.std_uncertainty[i] * k),
                    fixed_by_gauge: if f.estimable[i] { None } else { fixed_by(f, i) },
                    conditional_on_gauges: if f.estimable[i] {
                        f.depends_on(&[(i, 1.0)])
                    } else {
                        Vec::new()
                    },
                    conditional_on_aliases: Vec::new(),
                    std_uncertainty_with_aliases: None,
                }
            })
            .collect();
        let null_space = f
            .null_space
            .iter()
            .map(|c| doc::NullCombination {
                components: c
                    .components
                    .iter()
                    .map(|&(i, a)| doc::Component {
                        id: f.parameters[i].id.clone(),
                        amount: a,
                        unit: f.parameters[i].unit.display_name().into(),
                    })
                    .collect(),
                test_to_separate: self.combination(c).1,
            })
            .collect();
        let ids = |cols: &[usize]| cols.iter().map(|&j| f.parameters[j].id.clone()).collect();
        let gauges = f
            .gauges
            .iter()
            .map(|g| doc::Gauge {
                kind: g.kind.name().into(),
                what: g.what.clone(),
                choice: g.choice.clone(),
                why: g.why.clone(),
                test_to_separate: g.separate_by.clone(),
                parameters: ids(&g.parameters),
                conditional: ids(&g.conditional),
            })
            .collect();
        let circle = |c: &metrics::CircleFigures| doc::CircleFigures {
            rms_um: um(c.rms),
            g_um: um(c.g),
            f_max_um: um(c.f_max),
            f_min_um: um(c.f_min),
        };
        let figs = run_figures(f, runs);
        let run_docs = runs
            .iter()
            .zip(&figs)
            .map(|(run, (b, a))| {
                let h = &run.header;
                doc::RunFigures {
                    run: run.name(),
                    file: run.source.clone(),
                    plane: h.plane.name().into(),
                    direction: h.direction.map(|d| d.name().into()),
                    radius_mm: h.radius_mm,
                    feed_mm_per_min: h.feed_mm_per_min,
                    samples: run.len(),
                    placement: placement_key(run).into(),
                    before: circle(b),
                    after: circle(a),
                }
            })
            .collect();
        let hysteresis = pairs(runs)
            .into_iter()
            .filter_map(|(i, j)| {
                let b = metrics::hysteresis(&runs[i], &runs[i].dr_mm, &runs[j], &runs[j].dr_mm)?;
                let a = metrics::hysteresis(&runs[i], &f.residuals[i], &runs[j], &f.residuals[j])?;
                Some(doc::Hysteresis {
                    cw: runs[i].name(),
                    ccw: runs[j].name(),
                    before_um: um(b),
                    after_um: um(a),
                })
            })
            .collect();
        doc::Fit {
            format: doc::FORMAT.into(),
            machine: self.model.spec.name.clone(),
            servo: self.servo().into(),
            samples: f.n_samples,
            identifiability: doc::Identifiability {
                rank: f.rank,
                parameters: f.parameters.len(),
                condition_number: f.condition_number,
                singular_values: f.singular_values.clone(),
                null_space,
            },
            residual: doc::Residual {
                sigma_um: um(f.sigma_mm),
                lag1_autocorrelation: f.rho,
                uncertainty_inflation: f.inflation.sqrt(),
            },
            paper: doc::Paper {
                radius_mm: r,
                feed_mm_per_min: feed,
                quantities: rows
                    .iter()
                    .zip(&held)
                    .map(|((p, v), h)| doc::PaperQuantity { paper: est(p, h), vendor: est(v, h) })
                    .collect(),
            },
            gauges,
            parameters,
            runs: run_docs,
            hysteresis,
            assumed: Vec::new(),
            vendor_comparison: None,
            local: Vec::new(),
            aliases: Vec::new(),
        }
    }
}

/// The gauge (index into `Fit::gauges`) that sets parameter `i` to 0, if any.
pub fn fixed_by(f: &Fit, i: usize) -> Option<usize> {
    f.gauges.iter().position(|g| g.fixes_each() && g.parameters.contains(&i))
}

fn ids(f: &Fit, cols: &[usize]) -> String {
    cols.iter().map(|&j| f.parameters[j].id.as_str()).collect::<Vec<_>>().join(", ")
}

/// The radius and feed the paper's quantities are stated at: the first planar run's (a rotary
/// run's radius is its bar's, not a circle's), else the first run's; the paper's own when
/// there is none.
fn paper_setting(runs: &[Run]) -> (f64, f64) {
    runs.iter()
        .find(|r| r.header.plane != ballbar_model::Plane::Free)
        .or(runs.first())
        .map(|r| (r.header.radius_mm, r.header.feed_mm_per_min))
        .unwrap_or((150.0, 500.0))
}

/// Per row of [`paper_rows`], the gauges whose choice its value holds for (empty: none).
pub fn paper_conditional(model: &Model, f: &Fit, runs: &[Run]) -> Vec<Vec<usize>> {
    let (r, feed) = paper_setting(runs);
    paper::report(model, r, feed)
        .iter()
        .filter_map(|row| {
            quantity(f, &row.paper)?;
            quantity(f, &row.vendor)?;
            let coeffs: Vec<(usize, f64)> =
                row.paper.terms.iter().filter_map(|(id, c)| f.index(id).map(|i| (i, *c))).collect();
            Some(if quantity(f, &row.paper)?.estimate.estimable {
                f.depends_on(&coeffs)
            } else {
                Vec::new()
            })
        })
        .collect()
}

/// Per row of [`paper_rows`], its functional over the fit's parameters (the paper's unit).
pub fn paper_functionals(model: &Model, f: &Fit, runs: &[Run]) -> Vec<Vec<(usize, f64)>> {
    let (r, feed) = paper_setting(runs);
    paper::report(model, r, feed)
        .iter()
        .filter_map(|row| {
            quantity(f, &row.paper)?;
            quantity(f, &row.vendor)?;
            Some(
                row.paper.terms.iter().filter_map(|(id, c)| f.index(id).map(|i| (i, *c))).collect(),
            )
        })
        .collect()
}

/// Which extra test would separate a null combination of a fit: the test of the gauge that
/// fixes one of its parameters (a zero error's angular reference or second tool length, the
/// bar length's second radius, the common lag's), else [`separation_hint`] by its classes.
pub fn null_hint(f: &Fit, c: &ballbar_fit::NullCombination) -> String {
    let in_it = |j: &usize| c.components.iter().any(|&(i, _)| i == *j);
    f.gauges
        .iter()
        .filter(|g| {
            !matches!(
                g.kind,
                ballbar_fit::gauge::GaugeKind::AcrossBar | ballbar_fit::gauge::GaugeKind::Weak
            )
        })
        .find(|g| g.parameters.iter().any(in_it))
        .map(|g| g.separate_by.clone())
        .unwrap_or_else(|| {
            separation_hint(
                &c.components.iter().map(|&(i, _)| f.parameters[i].class).collect::<Vec<_>>(),
            )
            .to_string()
        })
}

/// Hint for a null combination: which extra test would separate it.
pub fn separation_hint(classes: &[ParamClass]) -> &'static str {
    let has = |c: ParamClass| classes.contains(&c);
    if classes.len() == 1 {
        return "has no effect on these tests: test in a plane where its axis moves";
    }
    if has(ParamClass::BarLength) && has(ParamClass::Term(TermClass::Positional)) {
        return "a second radius (scale grows with R, bar length does not), or a calibrated bar (--bar-length-um)";
    }
    if classes.iter().all(|c| *c == ParamClass::Term(TermClass::ServoLag)) {
        return "a common lag changes no radius to first order: runs at two feeds show its radius loss";
    }
    if classes.contains(&ParamClass::Term(TermClass::RotaryLocation)) {
        return "a rotary test that turns the axis (a ballbar sees a rotary axis's location errors only as it turns): radial at two ball heights, tangential, axial";
    }
    if classes.contains(&ParamClass::Centring) {
        return "a test in a plane where these axes move (in this one they sit still, their errors act as a centring)";
    }
    "offset circle centres, another radius, or another tool length or ball height"
}

/// Paired CW/CCW runs (same plane, radius, feed, pivot), by index.
pub fn pairs(runs: &[Run]) -> Vec<(usize, usize)> {
    metrics::pairs(runs)
}

/// The paper's quantities and their vendor-unit forms, at the first run's radius and feed.
pub type PaperRows =
    (f64, f64, Vec<(ballbar_fit::QuantityEstimate, ballbar_fit::QuantityEstimate)>);

/// The paper report of a fit at the first run's radius and feed.
pub fn paper_rows(model: &Model, f: &Fit, runs: &[Run]) -> PaperRows {
    let (r, feed) = paper_setting(runs);
    let rows = paper::report(model, r, feed)
        .iter()
        .filter_map(|row| Some((quantity(f, &row.paper)?, quantity(f, &row.vendor)?)))
        .collect();
    (r, feed, rows)
}

/// Figures of every run before and after the model.
pub fn run_figures(f: &Fit, runs: &[Run]) -> Vec<(metrics::CircleFigures, metrics::CircleFigures)> {
    runs.iter()
        .enumerate()
        .map(|(r, run)| (metrics::figures(run, &run.dr_mm), metrics::figures(run, &f.residuals[r])))
        .collect()
}

/// What the vendor-unit column of the paper's quantities is (terminal legend, page legend).
pub const RENISHAW_UNITS: &str = "the same quantity as Renishaw's ballbar software states it, to compare with its report: a positional error as the axis's scale error (ppm), an angular error in arcsec, a squareness in µm/m, a servo mismatch as the lag difference of its two axes (ms)";

/// Decimal places that show a standard uncertainty `u` to two significant digits (GUM 7.2.6),
/// 0 to 9; `None` where `u` is not positive and finite, or below 1e-8 (which would need 10
/// decimals or more).
pub fn u_decimals(u: f64) -> Option<usize> {
    if !(u.is_finite() && u > 0.0) {
        return None;
    }
    let d = 1 - u.log10().floor() as i32;
    (d <= 9).then_some(d.max(0) as usize)
}

/// A value and its standard uncertainty as text: u to two significant digits and the value to
/// the same decimal place (0.0042 → `18.3367`, `0.0042`), so that no non-zero u reads 0. A u of
/// 0 (nothing uncertain) shows the value at `decimals` and u as `0`; a u below 1e-8 in
/// e-notation; a u that is not a number as `—`.
pub fn value_and_u(value: f64, u: f64, decimals: usize) -> (String, String) {
    match u_decimals(u) {
        Some(d) => (format!("{value:.d$}"), format!("{u:.d$}")),
        None if u == 0.0 => (format!("{value:.decimals$}"), "0".into()),
        None if u.is_finite() && u > 0.0 => (format!("{value:.9}"), format!("{u:.1e}")),
        None => (format!("{value:.decimals$}"), "—".into()),
    }
}

/// The basis of a polynomial parameter (a positional, straightness or angular term of a linear
/// axis): `θ·((q − q_ref)/L)^k`, `q` the axis position, `L` the machine's normalisation length
/// of that axis (`ballbar_model::machine::AxisNorm`).
#[derive(Clone, Debug, PartialEq)]
pub struct Basis {
    /// The axis whose position `q` the polynomial is in.
    pub axis: Axis,
    /// `q_ref`, mm.
    pub reference_mm: f64,
    /// `L`, mm.
    pub length_mm: f64,
    /// `k`.
    pub degree: u32,
}

impl Basis {
    /// The basis of parameter `id` of `model`, if it is a built-in polynomial term (a plugin's
    /// kernel term says nothing of its shape: `None`).
    pub fn of(model: &Model, id: &str) -> Option<Basis> {
        let bound = model.terms.iter().find(|t| t.term.id() == id)?;
        if !matches!(
            bound.term.class(),
            TermClass::Positional | TermClass::Straightness | TermClass::Angular
        ) {
            return None;
        }
        if model.spec.terms.iter().any(|t| matches!(t, TermSpec::Kernel { id: k, .. } if k == id)) {
            return None;
        }
        // The built-in polynomial ids end in their degree (EXX1, EYX2, ECX1).
        let digits = id.len() - id.trim_end_matches(|c: char| c.is_ascii_digit()).len();
        let degree: u32 = id[id.len() - digits..].parse().ok()?;
        let norm = model.spec.normalisation.iter().find(|n| n.axis == bound.axis)?;
        Some(Basis {
            axis: bound.axis,
            reference_mm: norm.reference_mm,
            length_mm: norm.length_mm,
            degree,
        })
    }

    /// `θ·(X/250 mm)²`, or `θ·((X − 100 mm)/250 mm)` about a reference off zero.
    pub fn text(&self) -> String {
        let a = self.axis.name();
        let q = if self.reference_mm == 0.0 {
            a.to_string()
        } else {
            format!(
                "({a} {} {} mm)",
                if self.reference_mm > 0.0 { '−' } else { '+' },
                self.reference_mm.abs()
            )
        };
        format!("θ·({q}/{} mm){}", self.length_mm, superscript(self.degree))
    }
}

/// `k` as a superscript (nothing for 1).
fn superscript(k: u32) -> String {
    if k == 1 {
        return String::new();
    }
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    k.to_string().chars().map(|c| DIGITS[c.to_digit(10).unwrap_or(0) as usize]).collect()
}

/// The sentence that says how the polynomial parameters are normalised, from their bases (in
/// parameter order); `None` without any.
pub fn normalisation_text(bases: &[Option<Basis>]) -> Option<String> {
    let mut groups: Vec<(f64, f64, Vec<&'static str>)> = Vec::new();
    for b in bases.iter().flatten() {
        match groups.iter_mut().find(|g| g.0 == b.reference_mm && g.1 == b.length_mm) {
            Some(g) if !g.2.contains(&b.axis.name()) => g.2.push(b.axis.name()),
            Some(_) => {}
            None => groups.push((b.reference_mm, b.length_mm, vec![b.axis.name()])),
        }
    }
    if groups.is_empty() {
        return None;
    }
    let at_zero = groups.iter().all(|g| g.0 == 0.0);
    let lengths = groups
        .iter()
        .map(|(r, l, axes)| {
            if at_zero {
                format!("L = {l} mm for {}", axes.join(", "))
            } else {
                format!("q_ref = {r} mm, L = {l} mm for {}", axes.join(", "))
            }
        })
        .collect::<Vec<_>>()
        .join("; ");
    Some(if at_zero {
        format!(
            "polynomial terms are θ·(q/L)^k in the axis position q, {lengths} (a fixed length of the machine, not the test's radius): θ is the error at q = L"
        )
    } else {
        format!(
            "polynomial terms are θ·((q − q_ref)/L)^k in the axis position q, {lengths} (fixed by the machine, not by the test): θ is the error at q = q_ref + L"
        )
    })
}

/// How a run's samples were placed on its arc, in words (the run tables): a `.b5r` run's by
/// the programmed feed or evenly (the vendor's convention), a run file's as its times and
/// coordinates say.
pub fn placement_words(run: &Run) -> &'static str {
    match ballbar_io::b5r::SpacingMode::of(run) {
        Some(ballbar_io::b5r::SpacingMode::Feed) => "at the programmed feed",
        Some(ballbar_io::b5r::SpacingMode::Even) => "evenly (the feed disagrees)",
        Some(ballbar_io::b5r::SpacingMode::Vendor) => "evenly (the vendor's)",
        None => "as recorded",
    }
}

/// [`placement_words`] as the JSON states it (`placement` of `runs`): `feed`, `even`,
/// `vendor` (a `.b5r` run's `angle_spacing_mode`) or `recorded` (a run file's own times and
/// coordinates).
pub fn placement_key(run: &Run) -> &'static str {
    ballbar_io::b5r::SpacingMode::of(run).map_or("recorded", |m| m.name())
}

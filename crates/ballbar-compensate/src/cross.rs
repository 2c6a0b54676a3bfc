//! Cross-axis corrections: a squareness or a straightness of the model as the error of one
//! axis (the output) as a function of another's position (the input), which a controller with
//! cross-axis tables corrects (SINUMERIK's CEC, [`crate::siemens`]).
//!
//! # From the model's convention to a table
//! The model's squareness of `axis` toward `toward` (`SQXY`: X toward Y) is `δ_toward = -α
//! (q_axis - q_ref)` (`ballbar_model`'s sign conventions: `ΔY = -α X` for XY, `ΔX = -β₁ Z` for
//! ZX, `ΔY = -β₂ Z` for YZ), and its straightness `E{toward}{axis}k` is `δ_toward = θ s^k`, `s
//! = (q_axis - q_ref)/L`. With `s` the input's normalised position, the output's error is the
//! polynomial `δ_out(s) = -α L s + Σ θ_k s^k` (up to a constant, which a ballbar does not see),
//! and the trim that cancels it, added to the output's commanded position, `t = -δ_out`. Past the
//! span the tests measured on the input a pure slope (a squareness alone) is extended
//! linearly; a polynomial with a curvature is held at its values at the measured ends.
//!
//! A straightness whose angle is tied to it (`tie_angles`: the carriage pitches or yaws with
//! the slope of its path) moves the tool by that angle times its arm as well, in the output
//! axis and in the input's own: a table of the output over the input holds the translation
//! only, and the tests would read what it leaves as a squareness and a scale. Measured on the
//! column machine (`EYX2` = 3 µm, X's yaw tied, arms of 300 mm in X and 200 mm in Y): the table
//! of its translation took `EYX2` to 0 and moved `SQXY` by -29 µrad (`2θ·300/L²`) and X's
//! scale by -19 ppm (`2θ·200/L²`). Such a straightness is not written (its `why` says so);
//! one the model holds as a translation alone is.
//!
//! Which terms are written follows the criteria of the axis tables ([`crate::select`]):
//! determined, an input axis the tests moved, significant, and not moved by an alias unless
//! `--include-aliased` names it.

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::machine::TermSpec;
use ballbar_model::{Axis, Run};

use crate::{Estimate, Options, Term};

/// One cross-axis correction: the output axis's error as a polynomial of the input's position.
#[derive(Clone, Debug, PartialEq)]
pub struct Cross {
    /// The axis whose position the correction follows.
    pub input: Axis,
    /// The axis corrected.
    pub output: Axis,
    /// `(degree, θ)`: the output's error `Σ θ s^k`, mm, `s = (q_input - reference)/length`.
    pub polynomial: Vec<(u32, f64)>,
    /// The input's normalisation reference, mm.
    pub reference_mm: f64,
    /// The input's normalisation length, mm.
    pub length_mm: f64,
    /// The span the tests measured on the input, mm.
    pub measured: [f64; 2],
    /// The span its table covers: `--travel` of the input, else the measured one, mm.
    pub span: [f64; 2],
    /// The model's terms it carries.
    pub ids: Vec<String>,
}

impl Cross {
    /// Whether the polynomial is a pure slope (a squareness alone): extended linearly.
    pub fn pure_slope(&self) -> bool {
        self.polynomial.iter().all(|&(k, _)| k == 1)
    }

    /// The note for a `table` ("table", "column") covering `span` of the input, where that
    /// reaches past the span the tests measured: how the correction is carried there.
    pub fn extension_note(&self, table: &str, span: [f64; 2]) -> Option<String> {
        let m = self.measured;
        (span[0] < m[0] || span[1] > m[1]).then(|| {
            format!(
                "{} over {}: the {table} covers {:.3}..{:.3} mm of {}, the tests measured {:.3}..{:.3} mm: {}",
                self.output,
                self.input,
                span[0],
                span[1],
                self.input,
                m[0],
                m[1],
                if self.pure_slope() {
                    "the squareness, a pure slope, is extended linearly"
                } else {
                    "the correction has a curvature and is held at its values at the measured ends"
                }
            )
        })
    }

    /// The output's error at input position `q`, mm (actual minus commanded): past the
    /// measured span a pure slope goes on, a curvature is held at the span's ends.
    pub fn error_mm(&self, q: f64) -> f64 {
        let x = if self.pure_slope() { q } else { q.clamp(self.measured[0], self.measured[1]) };
        let s = (x - self.reference_mm) / self.length_mm;
        self.polynomial.iter().map(|&(k, th)| th * s.powi(k as i32)).sum()
    }
}

/// `(input, output, degree, θ at s = 1 in mm)` of a squareness or straightness entry, from
/// the machine's term: a squareness `α` is `-α L` at degree 1.
pub(crate) fn shape(model: &SavedModel, t: &Term, e: &Estimate) -> Option<(Axis, Axis, u32, f64)> {
    match t.term.as_str() {
        "squareness" => model.machine.terms.iter().find_map(|spec| match spec {
            TermSpec::Squareness { id, axis, toward } if *id == t.id => {
                let (_, l) = crate::norm(model, *axis);
                Some((*axis, *toward, 1, -e.value * l))
            }
            _ => None,
        }),
        "straightness" => {
            let output = Axis::from_name(t.id.get(1..2)?)?;
            let input = Axis::from_name(t.id.get(2..3)?)?;
            Some((input, output, t.degree?, e.value))
        }
        _ => None,
    }
}

/// Whether the machine's straightness of `input` toward `output` has its angle tied.
fn tied(model: &SavedModel, input: Axis, output: Axis) -> bool {
    model.machine.terms.iter().any(|spec| {
        matches!(spec, TermSpec::Straightness { axis, toward, tie_angles: true, .. }
            if *axis == input && *toward == output)
    })
}

/// The squareness and straightness terms a controller's cross-axis tables take, marked
/// compensated, by `(input, output)`; the others keep their `why`, replaced where these criteria
/// say more (not determined, an input the tests did not move, not significant, an alias).
pub(crate) fn select(
    model: &SavedModel,
    entries: &mut [(Term, Estimate)],
    runs: &[Run],
    options: &Options,
    notes: &mut Vec<String>,
) -> Result<BTreeMap<(Axis, Axis), Cross>, String> {
    let mut out: BTreeMap<(Axis, Axis), Cross> = BTreeMap::new();
    for (t, e) in entries.iter_mut() {
        if !matches!(t.term.as_str(), "squareness" | "straightness") || !e.estimable {
            continue;
        }
        let Some((input, output, degree, theta)) = shape(model, t, e) else { continue };
        if t.term == "straightness" && tied(model, input, output) {
            t.why = Some(format!(
                "its angle is tied to it (the {input} carriage turns with the slope of its path), which moves the tool by the angle times its arm, in {input} too: a table of {output} over {input} would hold the translation alone, and the tests would read what it leaves as a squareness and a scale of {input}; correct the guideway, or the angle with the machine's volumetric compensation"
            ));
            continue;
        }
        if input.is_rotary() || output.is_rotary() {
            continue;
        }
        if runs.is_empty() {
            t.why = Some(
                "no runs given: a cross-axis table covers the span the tests measured on its input axis, which only the runs give; give the runs to write it".into(),
            );
            continue;
        }
        let Some(measured) = crate::measured_span(runs, input) else {
            t.why = Some(format!("the tests do not move {input}, whose position it follows"));
            continue;
        };
        t.measured_span_mm = Some(measured);
        let span = options.travel.get(&input).copied().unwrap_or(measured);
        if span[1] <= span[0] || span.iter().any(|x| !x.is_finite()) {
            return Err(format!(
                "--travel {input}={}:{}: the end must be above the start",
                span[0], span[1]
            ));
        }
        if !crate::admit(t, e, options, notes) {
            continue;
        }
        let (reference_mm, length_mm) = crate::norm(model, input);
        let c = out.entry((input, output)).or_insert(Cross {
            input,
            output,
            polynomial: Vec::new(),
            reference_mm,
            length_mm,
            measured,
            span,
            ids: Vec::new(),
        });
        c.ids.push(t.id.clone());
        match c.polynomial.iter_mut().find(|(k, _)| *k == degree) {
            Some(p) => p.1 += theta,
            None => c.polynomial.push((degree, theta)),
        }
        t.compensated = true;
        t.why = None;
    }
    Ok(out)
}

/// What a cross-axis trim `trim(q_input)` (mm, added to the output) applies of a term, in its
/// display unit, over the measured span: the least-squares fit (QR, `ballbar_fit::lstsq`) of
/// the trim on a constant and the table's degrees, sign-reversed (a trim of `-θ s^k` applies
/// `θ`); a squareness `α = -θ₁/L`, µrad.
pub(crate) fn applied(t: &Term, c: &Cross, trim: &dyn Fn(f64) -> f64) -> Result<f64, String> {
    // 201 points over the span: enough to separate a constant and a few degrees.
    let m = 201;
    let grid: Vec<f64> = (0..m)
        .map(|i| c.measured[0] + (c.measured[1] - c.measured[0]) * i as f64 / (m - 1) as f64)
        .collect();
    let mut degrees: Vec<u32> = c.polynomial.iter().map(|p| p.0).collect();
    degrees.sort();
    let s = |q: f64| (q - c.reference_mm) / c.length_mm;
    let a = faer::Mat::<f64>::from_fn(m, degrees.len() + 1, |i, j| {
        if j == 0 { 1.0 } else { s(grid[i]).powi(degrees[j - 1] as i32) }
    });
    let y: Vec<f64> = grid.iter().map(|&q| trim(q)).collect();
    let (x, _) = ballbar_fit::lstsq(a.as_ref(), &y).map_err(|e| e.to_string())?;
    let k = if t.term == "squareness" { 1 } else { t.degree.unwrap_or(2) };
    let j = degrees.iter().position(|&d| d == k).map_or(0, |p| p + 1);
    let theta = -x[j];
    Ok(if t.term == "squareness" { -theta / c.length_mm * 1e6 } else { theta * 1e3 })
}

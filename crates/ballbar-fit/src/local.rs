//! What each planar test determines where it is: the local scales and squareness of the fitted
//! error field at the circle's centre ([`ballbar_model::local`], signs documented there), one
//! set per test (plane, circle centre, tool offset), as estimates of the fit.
//!
//! A circle reads the linear part of the field about its centre whole (`ΔR = R n·J n`), so
//! these are what the runs determine whatever the polynomials' origin: they do not move with
//! the pivot or the tool length given for the runs, where the machine's global squareness and
//! positional terms may (module [`crate::alias`]). They are the quantities to compare with a
//! vendor's analysis of one plane, which states the same field about the same centre.

use ballbar_model::local::{LocalKind, exact_local_value, local_functional};
use ballbar_model::{Design, Plane, Unit};

use crate::{Estimate, Fit, FitError};

/// One local quantity of one test.
#[derive(Clone, Debug, PartialEq)]
pub struct LocalQuantity {
    /// The test's plane.
    pub plane: Plane,
    /// The circle's centre, machine coordinates (the runs' `pivot_mm`), mm.
    pub pivot_mm: [f64; 3],
    /// The tool ball from the gauge point (the runs' `tool_ball_mm`), mm.
    pub tool_ball_mm: [f64; 3],
    /// The runs of the test (indices into the design's runs).
    pub runs: Vec<usize>,
    /// The test's radius (its runs' mean), mm.
    pub radius_mm: f64,
    /// Which quantity.
    pub kind: LocalKind,
    /// Its short name (`local scale X`, `local squareness XY`).
    pub name: String,
    /// Its unit: [`Unit::Ratio`] for a scale, [`Unit::Angle`] for a squareness.
    pub unit: Unit,
    /// The functional over the fit's parameters, `(index, coefficient)`.
    pub coefficients: Vec<(usize, f64)>,
    /// Its estimate, internal units.
    pub estimate: Estimate,
    /// The gauges (indices into [`Fit::gauges`]) whose choice its value holds for.
    pub conditional_on_gauges: Vec<usize>,
}

impl LocalQuantity {
    /// The test it belongs to, in words: `XY at (0, 0, 0) mm, tool ball (0, 0, -100) mm`.
    pub fn test_text(&self) -> String {
        let p = |v: &[f64; 3]| format!("({}, {}, {})", v[0], v[1], v[2]);
        format!(
            "{} at {} mm, tool ball {} mm",
            self.plane,
            p(&self.pivot_mm),
            p(&self.tool_ball_mm)
        )
    }
}

/// The tests of a design: runs of one plane at one centre with one tool offset (free and
/// rotary runs have no plane and none).
pub fn tests(design: &Design<'_>) -> Vec<(Plane, [f64; 3], [f64; 3], Vec<usize>)> {
    let mut out: Vec<(Plane, [f64; 3], [f64; 3], Vec<usize>)> = Vec::new();
    for (r, run) in design.runs.iter().enumerate() {
        let h = &run.header;
        if h.plane.axes().is_none() {
            continue;
        }
        match out.iter_mut().find(|t| t.0 == h.plane && t.1 == h.pivot_mm && t.2 == h.tool_ball_mm)
        {
            Some(t) => t.3.push(r),
            None => out.push((h.plane, h.pivot_mm, h.tool_ball_mm, vec![r])),
        }
    }
    out
}

/// The local quantities of every test of the design, as estimated by `fit`.
pub fn local_quantities(design: &Design<'_>, fit: &Fit) -> Result<Vec<LocalQuantity>, FitError> {
    let mut out = Vec::new();
    for (plane, pivot_mm, tool_ball_mm, runs) in tests(design) {
        // The test's radius: the mean of its runs' (one in every shipped test).
        let radius_mm =
            runs.iter().map(|&r| design.runs[r].header.radius_mm).sum::<f64>() / runs.len() as f64;
        let (u, v, _) = plane.axes().expect("planar");
        for kind in LocalKind::ALL {
            let c = local_functional(design.model, plane, &pivot_mm, &tool_ball_mm, kind)?;
            let coefficients: Vec<(usize, f64)> =
                c.iter().enumerate().filter(|(_, x)| **x != 0.0).map(|(i, x)| (i, *x)).collect();
            let (name, unit) = match kind {
                LocalKind::ScaleU => (format!("local scale {u}"), Unit::Ratio),
                LocalKind::ScaleV => (format!("local scale {v}"), Unit::Ratio),
                LocalKind::Squareness => (format!("local squareness {u}{v}"), Unit::Angle),
            };
            // The value from the exact field (what the fit matched the readings with, second
            // order included); u and estimability from the first-order functional.
            let mut estimate = fit.functional(&coefficients);
            if estimate.estimable {
                let theta = &fit.values[..design.n_machine];
                estimate.value = exact_local_value(
                    design.model,
                    plane,
                    &pivot_mm,
                    &tool_ball_mm,
                    radius_mm,
                    kind,
                    theta,
                )?;
            }
            let conditional_on_gauges =
                if estimate.estimable { fit.depends_on(&coefficients) } else { Vec::new() };
            out.push(LocalQuantity {
                plane,
                pivot_mm,
                tool_ball_mm,
                runs: runs.clone(),
                radius_mm,
                kind,
                name,
                unit,
                coefficients,
                estimate,
                conditional_on_gauges,
            });
        }
    }
    Ok(out)
}

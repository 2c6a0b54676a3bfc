//! How the tests read a table that is no polynomial of the compensated degrees.
//!
//! What a table applies of a term is taken as the coefficient of its least-squares polynomial
//! over the measured span (`applied` in the crate root). The circles do not read a table so:
//! they read it at their own samples, through the fit with every other term of the model. For a
//! table that is a polynomial of the compensated degrees to within its resolution (LinuxCNC's,
//! SINUMERIK's and HEIDENHAIN's, written from the model's polynomial at their points and
//! interpolated linearly between them) the two agree. For
//! one that is not, they differ: a FANUC staircase in whole detection units is off its line by up
//! to half a unit, and a circle of diameter 2R reads a difference d between its ends as a scale of
//! d/2R (3.3 ppm over 300 mm for 1 µm); an existing table with detail (a laser's pitch error
//! measurement) is read at the circles' positions.
//!
//! The *residual* of a table is the mean of its two directions less that least-squares
//! polynomial (on the compensated degrees and a constant, over the measured span); what the
//! circles read of it is the fit ([`Reading`]) of the change `ΔR = û·r` it makes in each run's
//! trace. It is used twice:
//! - the merge (`--existing`): the tests measured the machine less the existing compensation
//!   *as the circles read it*, so the correction written for a positional term (a scale or a
//!   higher degree: what an axis's table holds) is its measured value plus what the circles read
//!   of the existing table's residual (a residual trim `r` reads as the fitted value `d`, so it
//!   corrects `-d`); the table's slope is then the machine's, where the existing table taken by
//!   its line would leave the residual's reading in it. The backlash is not raised (the residual
//!   is both directions' mean), nor a cross-axis table (its residual is not computed: the
//!   cross-axis tables written are their polynomials);
//! - the prediction of every written term: its value after from the tables' polynomials
//!   (`value_after`, or the cross-axis table's), plus what the circles read of the new tables'
//!   residuals less the existing ones' (the fit moves the backlash and the squareness with
//!   them too).
//!
//! Only the residual goes through the fit, not the whole table: the predicted trace takes the
//! trims without the servo's lag, and the fit of a whole trim's change leaks into the other terms
//! by more than the smallest uncertainties the tests give (0.05 ppm on a noise-free X against a u
//! of 0.02 ppm on Z); on a residual of at most a detection unit that leak is a few thousandths of
//! a ppm. A residual that moves no run's trace by [`NEGLIGIBLE_MM`] is not fitted.

use std::collections::BTreeMap;

use ballbar_model::{Axis, Run};

use crate::{AxisCorrection, Estimate, Term};

/// A residual below this (mm) over the measured span, or on every run's samples, is read as
/// nothing, without a fit. SINUMERIK's and HEIDENHAIN's values are rounded to 1 nm, so an
/// existing table and a new one on another grid differ by up to 1 nm from their polynomials;
/// 2 nm over a circle of 100 mm radius is a scale of 0.01 ppm, half the smallest uncertainty of
/// a scale the tests give (0.02 ppm, the fixture's Z).
pub const NEGLIGIBLE_MM: f64 = 2e-6;

/// The fit of a change of the traces, through the runs the compensation was computed from and
/// with the model its estimates came from (the CLI's: the machine's model, the backlash
/// switching where the measured runs' fit put it).
pub trait Reading: std::fmt::Debug + Send + Sync {
    /// Each machine parameter's estimate from the runs `change` (the measured runs, each
    /// `dr_mm` replaced by the change alone).
    fn read(&self, change: &[Run]) -> Result<Vec<Estimate>, String>;
}

/// The mean of both directions of `trim` (mm) less its least-squares polynomial on `c`'s
/// degrees and a constant over the measured span, as a function of the axis's position (mm).
fn residual<'a>(
    c: &AxisCorrection,
    trim: &'a dyn Fn(f64, bool) -> f64,
) -> Result<Option<impl Fn(f64) -> f64 + 'a>, String> {
    let Some(span) = c.measured else { return Ok(None) };
    if c.positional.is_empty() {
        return Ok(None);
    }
    let mut degrees: Vec<u32> = c.positional.iter().map(|p| p.0).collect();
    degrees.sort();
    degrees.dedup();
    // 201 points over the span, as `applied` takes them: the same polynomial.
    let m = 201;
    let grid: Vec<f64> =
        (0..m).map(|i| span[0] + (span[1] - span[0]) * i as f64 / (m - 1) as f64).collect();
    let cols = degrees.len() + 1;
    let (reference, length) = (c.reference_mm, c.length_mm);
    let basis = move |q: f64, j: usize| -> f64 {
        if j == 0 { 1.0 } else { ((q - reference) / length).powi(degrees[j - 1] as i32) }
    };
    let a = faer::Mat::<f64>::from_fn(m, cols, |i, j| basis(grid[i], j));
    let mean = move |q: f64| 0.5 * (trim(q, true) + trim(q, false));
    let y: Vec<f64> = grid.iter().map(|&q| mean(q)).collect();
    let (x, _) = ballbar_fit::lstsq(a.as_ref(), &y).map_err(|e| e.to_string())?;
    Ok(Some(move |q: f64| mean(q) - (0..cols).map(|j| x[j] * basis(q, j)).sum::<f64>()))
}

/// What the circles read of the tables `trims` (per axis, the trim at a position and direction,
/// mm; `None` for an axis without one) beyond their least-squares polynomials on `per_axis`'s
/// degrees: each machine parameter's estimate; empty where the residuals move no run's trace by
/// [`NEGLIGIBLE_MM`]. An error where a residual is not negligible over the measured span and a
/// run is not a planar circle (its trace change is not `û·r`).
pub(crate) fn read_residual(
    per_axis: &BTreeMap<Axis, AxisCorrection>,
    runs: &[Run],
    reading: &dyn Reading,
    trims: &dyn Fn(Axis, f64, bool) -> Option<f64>,
) -> Result<Vec<Estimate>, String> {
    let mut of_axis: Vec<(Axis, Box<dyn Fn(f64, bool) -> f64 + '_>)> = Vec::new();
    for (&axis, c) in per_axis {
        let Some(span) = c.measured else { continue };
        if trims(axis, span[0], true).is_none() {
            continue;
        }
        of_axis.push((axis, Box::new(move |q, f| trims(axis, q, f).unwrap_or(0.0))));
    }
    let mut residuals: BTreeMap<Axis, Box<dyn Fn(f64) -> f64 + '_>> = BTreeMap::new();
    for (axis, trim) in &of_axis {
        if let Some(r) = residual(&per_axis[axis], trim.as_ref())? {
            residuals.insert(*axis, Box::new(r));
        }
    }
    // Negligible over the whole measured span (2001 points, a tenth of a FANUC section at
    // least for spans up to 800 mm): nothing to read, whatever the runs are.
    residuals.retain(|axis, r| {
        let span = per_axis[axis].measured.unwrap_or([0.0, 0.0]);
        (0..=2000)
            .map(|i| span[0] + (span[1] - span[0]) * i as f64 / 2000.0)
            .any(|q| r(q).abs() >= NEGLIGIBLE_MM)
    });
    if residuals.is_empty() {
        return Ok(Vec::new());
    }
    let mut change = Vec::with_capacity(runs.len());
    let mut largest: f64 = 0.0;
    for run in runs {
        let (Some(theta), Some((u, v, _))) =
            (ballbar_fit::metrics::angles(run), run.header.plane.axes())
        else {
            return Err(format!("{} is not a planar circle", run.name()));
        };
        let mut dr = vec![0.0; run.len()];
        for (axis, cos) in [(u, true), (v, false)] {
            let (Some(r), Some(col)) = (residuals.get(&axis), run.axis(axis)) else { continue };
            for i in 0..run.len() {
                let unit = if cos { theta[i].cos() } else { theta[i].sin() };
                dr[i] += unit * r(col[i]);
            }
        }
        largest = dr.iter().fold(largest, |m, x| m.max(x.abs()));
        let mut r = run.clone();
        r.dr_mm = dr;
        change.push(r);
    }
    if largest < NEGLIGIBLE_MM {
        return Ok(Vec::new());
    }
    reading.read(&change)
}

/// The merge's correction (module docs): each positional coefficient of `per_axis` raised by
/// what the circles read of the existing tables' residuals (`existing`, the trims they apply).
/// Returns a note saying by how much, or why it could not (then the least-squares polynomial
/// of the existing tables stands).
pub(crate) fn raise_by_existing(
    model: &ballbar_fit::saved::SavedModel,
    per_axis: &mut BTreeMap<Axis, AxisCorrection>,
    entries: &[(Term, Estimate)],
    runs: &[Run],
    reading: &dyn Reading,
    existing: &dyn Fn(Axis, f64, bool) -> Option<f64>,
) -> Option<String> {
    let read = match read_residual(per_axis, runs, reading, existing) {
        Ok(read) => read,
        Err(m) => {
            return Some(format!(
                "the existing tables are taken by their least-squares polynomials over the measured span, not as the circles read them: {m}"
            ));
        }
    };
    let mut raised = Vec::new();
    let positional = |t: &Term| matches!(t.term.as_str(), "scale" | "positional");
    for (t, _) in entries.iter().filter(|(t, _)| t.compensated && positional(t)) {
        let Some(axis) = Axis::from_name(&t.axis) else { continue };
        let Some(c) = per_axis.get_mut(&axis) else { continue };
        let Some(d) = read.iter().find(|e| e.id == t.id) else { continue };
        let Some(p) = c.positional.iter_mut().find(|p| Some(p.0) == t.degree) else { continue };
        // A residual trim read as `d` corrects `-d` of the term.
        p.1 -= d.value;
        let corrects = Estimate { value: -d.value, ..d.clone() };
        // Said where it shows at the printed digits (0.01).
        if let Some((shown, _)) = crate::terms(model, &[corrects]).into_iter().next()
            && shown.value().0.abs() >= 0.01
        {
            let (v, _, unit) = shown.value();
            raised.push(format!("{} {v:+.2} {unit}", t.id));
        }
    }
    (!raised.is_empty()).then(|| {
        format!(
            "the existing tables are no polynomials of the compensated degrees (a staircase, or detail), and the circles read them at their own positions: the correction written takes the existing tables as the circles read them, which adds {} to the measured values",
            raised.join(", ")
        )
    })
}

/// The change of each written term's predicted value (its display unit, by id) by
/// what the circles read of the new tables' residuals (`new`) less the existing ones'
/// (`existing`), on `model`'s terms; a note where it could not be read.
pub(crate) fn prediction_moves(
    model: &ballbar_fit::saved::SavedModel,
    per_axis: &BTreeMap<Axis, AxisCorrection>,
    runs: &[Run],
    reading: &dyn Reading,
    new: &dyn Fn(Axis, f64, bool) -> Option<f64>,
    existing: &dyn Fn(Axis, f64, bool) -> Option<f64>,
) -> Result<BTreeMap<String, f64>, String> {
    let change = |axis: Axis, q: f64, f: bool| match (new(axis, q, f), existing(axis, q, f)) {
        (None, None) => None,
        (a, b) => Some(a.unwrap_or(0.0) - b.unwrap_or(0.0)),
    };
    let read = read_residual(per_axis, runs, reading, &change)?;
    Ok(crate::terms(model, &read).into_iter().map(|(t, _)| (t.id.clone(), t.value().0)).collect())
}

/// Each written term's prediction moved by `moves` (its display unit, by id); a note
/// for each move that shows at the printed digits (0.01), with the value the tables' slope
/// leaves beside it.
pub(crate) fn apply_moves(
    entries: &mut [(Term, Estimate)],
    moves: &BTreeMap<String, f64>,
) -> Vec<String> {
    let mut notes = Vec::new();
    for (t, _) in entries.iter_mut().filter(|(t, _)| t.compensated) {
        let (Some(p), Some(&d)) = (t.predicted_after, moves.get(&t.id)) else { continue };
        t.predicted_after = Some(p + d);
        if d.abs() >= 0.01 {
            let unit = t.value().2;
            notes.push(format!(
                "{} ({} {}): a re-measurement should read {:.2} {unit}, of which {d:+.2} {unit} is how the circles read the tables' steps or detail beyond their polynomial (the new tables' less the existing ones')",
                t.id,
                t.term,
                t.axis,
                p + d
            ));
        }
    }
    notes
}

/// The note where the tables' residuals could not be read for the predictions.
pub(crate) fn not_read_note(why: &str) -> String {
    format!(
        "the written terms' predictions take the tables by their least-squares polynomials over the measured span, not as the circles read them: {why}"
    )
}

#[cfg(test)]
mod tests {
    use std::sync::Mutex;

    use super::*;
    use crate::tables::fixtures::{POS, circle, estimate};

    /// A reading that records the change it is given and reads it as `EXX1 = value`.
    #[derive(Debug, Default)]
    struct Recorder {
        seen: Mutex<Vec<Vec<Run>>>,
        value: f64,
    }

    impl Reading for Recorder {
        fn read(&self, change: &[Run]) -> Result<Vec<Estimate>, String> {
            self.seen.lock().unwrap().push(change.to_vec());
            Ok(vec![estimate("EXX1", POS, self.value, 0.0)])
        }
    }

    /// X's scale correction over the circle's span, normalised at 0 over 100 mm.
    fn scale_of_x(theta_mm: f64, run: &Run) -> BTreeMap<Axis, AxisCorrection> {
        let x = run.axis(Axis::X).unwrap();
        let span =
            x.iter().fold([f64::INFINITY, f64::NEG_INFINITY], |s, &q| [s[0].min(q), s[1].max(q)]);
        BTreeMap::from([(
            Axis::X,
            AxisCorrection {
                positional: vec![(1, theta_mm)],
                backlash: 0.0,
                reference_mm: 0.0,
                length_mm: 100.0,
                measured: Some(span),
            },
        )])
    }

    fn entries() -> Vec<(Term, Estimate)> {
        let e = estimate("EXX1", POS, 0.003, 1e-5);
        let mut t = crate::entry(&e, "scale", "X".into(), Some(1), 100.0);
        t.compensated = true;
        vec![(t, e)]
    }

    #[test]
    fn a_table_that_is_its_polynomial_is_not_read() {
        let run = circle();
        let mut per_axis = scale_of_x(0.003, &run);
        let reading = Recorder::default();
        // A pure slope and a constant: its least-squares line exactly.
        let linear = |a: Axis, q: f64, _: bool| (a == Axis::X).then_some(-28e-6 * q + 0.001);
        let model = crate::tables::fixtures::model(&[("EXX1", 0.003, 1e-5)]);
        let note = raise_by_existing(&model, &mut per_axis, &entries(), &[run], &reading, &linear);
        assert_eq!(note, None);
        assert!(reading.seen.lock().unwrap().is_empty());
        assert_eq!(per_axis[&Axis::X].positional, vec![(1, 0.003)]);
    }

    /// A staircase of whole µm: the change handed to the fit is `cos θ · r(x)`, `r` the
    /// staircase less its least-squares line over the measured span (computed here by the
    /// closed-form regression on the same 201 points), and the correction is raised by minus
    /// what the fit reads.
    #[test]
    fn a_staircase_is_read_by_its_residual_and_raises_the_correction() {
        let run = circle();
        let mut per_axis = scale_of_x(0.003, &run);
        let span = per_axis[&Axis::X].measured.unwrap();
        let reading = Recorder { value: 2e-4, ..Default::default() };
        let stair = |q: f64| -(28e-6 * q / 1e-3).round() * 1e-3;
        let trims = |a: Axis, q: f64, _: bool| (a == Axis::X).then(|| stair(q));
        let model = crate::tables::fixtures::model(&[("EXX1", 0.003, 1e-5)]);
        let note = raise_by_existing(
            &model,
            &mut per_axis,
            &entries(),
            std::slice::from_ref(&run),
            &reading,
            &trims,
        )
        .expect("a note");
        // 2e-4 mm over the model's X length, in ppm, with the sign of a correction.
        let ppm = -2e-4 / crate::norm(&model, Axis::X).1 * 1e6;
        assert!(note.contains(&format!("EXX1 {ppm:+.2} ppm")), "{note}");
        assert_eq!(per_axis[&Axis::X].positional, vec![(1, 0.003 - 2e-4)]);
        // The residual by hand: y = a + b q on 201 points.
        let q: Vec<f64> =
            (0..201).map(|i| span[0] + (span[1] - span[0]) * i as f64 / 200.0).collect();
        let n = q.len() as f64;
        let (sq, sy) = (q.iter().sum::<f64>(), q.iter().map(|&x| stair(x)).sum::<f64>());
        let sqq = q.iter().map(|x| x * x).sum::<f64>();
        let sqy = q.iter().map(|&x| x * stair(x)).sum::<f64>();
        let b = (n * sqy - sq * sy) / (n * sqq - sq * sq);
        let a = (sy - b * sq) / n;
        let seen = reading.seen.lock().unwrap();
        assert_eq!(seen.len(), 1);
        let theta = ballbar_fit::metrics::angles(&run).unwrap();
        let x = run.axis(Axis::X).unwrap();
        let mut largest: f64 = 0.0;
        for (i, dr) in seen[0][0].dr_mm.iter().enumerate() {
            let r = stair(x[i]) - (a + b * x[i]);
            // 1e-12 mm: the two regressions' rounding on values of 1e-3 mm.
            assert!((dr - theta[i].cos() * r).abs() < 1e-12, "{i}: {dr} against {r}");
            largest = largest.max(dr.abs());
        }
        assert!(largest > NEGLIGIBLE_MM, "{largest}");
    }

    #[test]
    fn the_prediction_reads_only_the_change_of_the_residuals() {
        let run = circle();
        let per_axis = scale_of_x(0.003, &run);
        let reading = Recorder { value: 2e-4, ..Default::default() };
        let model = crate::tables::fixtures::model(&[("EXX1", 0.003, 1e-5)]);
        let stair =
            |a: Axis, q: f64, _: bool| (a == Axis::X).then(|| -(28e-6 * q / 1e-3).round() * 1e-3);
        // The same staircase before and after: nothing changes, nothing is fitted.
        let moves = prediction_moves(
            &model,
            &per_axis,
            std::slice::from_ref(&run),
            &reading,
            &stair,
            &stair,
        )
        .unwrap();
        assert!(moves.is_empty() && reading.seen.lock().unwrap().is_empty());
        // A staircase replaced by its line: the fit's reading, as a scale in ppm of the
        // model's X length.
        let line = |a: Axis, q: f64, _: bool| (a == Axis::X).then_some(-28e-6 * q);
        let moves = prediction_moves(&model, &per_axis, &[run], &reading, &line, &stair).unwrap();
        let l = crate::norm(&model, Axis::X).1;
        assert!((moves["EXX1"] - 2e-4 / l * 1e6).abs() < 1e-9, "{moves:?}");
    }

    /// A reading by hand: the least squares (QR) of a change on X's scale shape
    /// `cos θ · x / L` and a centre offset `cos θ`, `L` the model's X length.
    #[derive(Debug)]
    struct ScaleOfX(f64);

    impl Reading for ScaleOfX {
        fn read(&self, change: &[Run]) -> Result<Vec<Estimate>, String> {
            let (mut rows, mut y) = (Vec::new(), Vec::new());
            for run in change {
                let theta = ballbar_fit::metrics::angles(run).unwrap();
                let x = run.axis(Axis::X).unwrap();
                for i in 0..run.len() {
                    rows.push([theta[i].cos() * x[i] / self.0, theta[i].cos()]);
                    y.push(run.dr_mm[i]);
                }
            }
            let a = faer::Mat::<f64>::from_fn(rows.len(), 2, |i, j| rows[i][j]);
            let (x, _) = ballbar_fit::lstsq(a.as_ref(), &y).map_err(|e| e.to_string())?;
            Ok(vec![estimate("EXX1", POS, x[0], 0.0)])
        }
    }

    /// The sign, physically: a machine whose X is `θ·x/L` long runs with an existing staircase
    /// correcting part of it; the circle's trace is the error plus the trims, `cos θ (θ x/L +
    /// t(x))`, and what it reads of X's scale is what is measured. The merge must write a table
    /// whose slope is the machine's: the existing staircase's least-squares slope plus the
    /// raised correction is `θ` (taken by its line alone it would be off by what the circle
    /// reads of the steps).
    #[test]
    fn the_merged_slope_is_the_machines() {
        let run = circle();
        let model = crate::tables::fixtures::model(&[("EXX1", 0.003, 1e-5)]);
        let l = crate::norm(&model, Axis::X).1;
        let reading = ScaleOfX(l);
        let machine = 0.014; // mm at x = L: 56 ppm over 250 mm
        // The existing staircase: whole µm of half the error, as a trim.
        let stair = |q: f64| -(0.5 * machine * q / l / 1e-3).round() * 1e-3;
        let mut measured = run.clone();
        let theta = ballbar_fit::metrics::angles(&run).unwrap();
        let x = run.axis(Axis::X).unwrap().to_vec();
        measured.dr_mm =
            (0..run.len()).map(|i| theta[i].cos() * (machine * x[i] / l + stair(x[i]))).collect();
        let v = reading.read(std::slice::from_ref(&measured)).unwrap()[0].value;
        let mut per_axis = scale_of_x(v, &run);
        per_axis.get_mut(&Axis::X).unwrap().length_mm = l;
        let trims = |a: Axis, q: f64, _: bool| (a == Axis::X).then(|| stair(q));
        raise_by_existing(
            &model,
            &mut per_axis,
            &entries(),
            std::slice::from_ref(&run),
            &reading,
            &trims,
        );
        // The staircase's least-squares slope over the measured span, on the same basis.
        let span = per_axis[&Axis::X].measured.unwrap();
        let q: Vec<f64> =
            (0..201).map(|i| span[0] + (span[1] - span[0]) * i as f64 / 200.0).collect();
        let a = faer::Mat::<f64>::from_fn(q.len(), 2, |i, j| if j == 0 { 1.0 } else { q[i] / l });
        let ys: Vec<f64> = q.iter().map(|&x| stair(x)).collect();
        let (line, _) = ballbar_fit::lstsq(a.as_ref(), &ys).unwrap();
        let written = -line[1] + per_axis[&Axis::X].positional[0].1;
        // 1e-9 mm: rounding on values of 1e-2 mm; the steps' reading is some 1e-4 mm.
        assert!((written - machine).abs() < 1e-9, "written {written}, machine {machine}");
        assert!((-line[1] + v - machine).abs() > 1e-6, "the steps read as nothing: no test");
    }
}

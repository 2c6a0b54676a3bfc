//! HEIDENHAIN TNC 640 / iTNC 530: nonlinear axis error compensation, a compensation value table
//! per axis (`X.COM`) and the assignment table that activates them (`CONFIG.CMA`), as the
//! *Technical Manual* states them: "Nonlinear axis error compensation" (entering compensation
//! values in `*.COM` tables; assigning the tables to the axes in a `*.CMA` table), and "Linear
//! axis error compensation" (MP720 on older controls) for the sign.
//!
//! - A `*.COM` table holds, per row, the compensation point `AXISPOS` (machine coordinates, from
//!   the machine datum) and, in the column of the axis the values depend on, the value there;
//!   the `BACKLASH` column holds the values measured in the negative direction of traverse.
//!   Between points the control interpolates linearly; a table has at most [`MAX_ROWS`] rows.
//! - `CONFIG.CMA` names, in each axis's column, the table compensating it (`[axis in the .COM's
//!   column] = F(axis of the .CMA's column)`); the row marked `*` in `ACTIVE` is active.
//! - Sign: the value is the axis's error, positive where the travel is too long (the manual's
//!   linear axis error compensation, MP720), actual minus commanded: the model's convention. The
//!   control subtracts it: the trim is `-value`. Moving up the axis's error is the positional
//!   error minus half the backlash, moving down plus half: the axis column and `BACKLASH` hold
//!   those.
//! - The file form is the TNC's table format: `BEGIN <name> MM`, a line of column names, a row
//!   a line (`NR` first), `[END]`.
//!
//! Assumed where the manual available to us did not settle it, stated in the files: the
//! `BACKLASH` column holds the whole error moving negative (not its difference to the axis
//! column); outside the table the end values hold; a `DOC` column (as the TNC's other tables
//! have) carries the comment; values and positions in mm to 1 nm (six decimals). At 0.1 µm
//! (four decimals) the rounding of a table whose points are 1.2 mm apart beats with the slope
//! and moves terms the tables do not touch: on the shipped fixture the XY squareness by 1.9
//! µrad and two straightnesses by 0.15 µm, more than 3 u, which `verify` reports as `changed`.
//! The backlash machine parameter (`CfgAxisComp backLash`, MP710 on the iTNC 530) is not written:
//! the tables' two directions take the backlash.
//!
//! # Cross-axis columns
//! The manual's assignment is `[axis of the .COM's column] = F(axis of the .CMA's column in
//! which the .COM is entered)`, its example axis sag `Z = F(Y)`. A squareness or straightness
//! of the model is an error of one axis (the output) as a function of another's position (the
//! input, [`crate::cross`]): it is written as a column of the output in the input's table
//! (`X.COM`, entered in the `.CMA`'s `X` column), `AXISPOS` the input's position. The
//! squareness `SQXY` (`ΔY = −α X`) is `X.COM`'s `Y` column, `−α X` (up to a constant), and
//! a straightness of X in Y the model holds as a translation alone joins it; one whose angle
//! the machine ties to it is not written ([`crate::cross`] says why). Assumed, as the manual
//! available to us does not say otherwise: a column of another axis holds the output's error
//! with the sign of the axis's own column (the control subtracts it from the output's
//! position; the TNC 407 manual's sag example plots it as the error in Z over Y), the same
//! whichever way either axis moves (`BACKLASH` is the table's own axis's), interpolated
//! linearly and held past the end rows as the axis's own. Only a re-measurement proves it:
//! a column the control applies the other way reads as `reversed` in `verify`.

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::{Axis, Run};

use crate::tables::{self, ControllerFiles};
use crate::{Compensation, Estimate, Options};

/// The manual section the files follow.
pub const MANUAL: &str = "HEIDENHAIN TNC 640 / iTNC 530 Technical Manual: Nonlinear axis error compensation (*.COM compensation value tables, *.CMA assignment)";

/// The most rows a `*.COM` table has.
pub const MAX_ROWS: usize = 256;

/// The assignment table's name.
pub const ASSIGNMENT_FILE: &str = "CONFIG.CMA";

/// Decimal places of a written value, mm: 1 nm.
const DECIMALS: usize = 6;

/// The resolution of a written value, mm: its last decimal.
pub const RESOLUTION_MM: f64 = 1e-6;

/// One axis's compensation value table, mm: rows of `(AXISPOS, value moving up, value moving
/// down)`, each value the error there (actual minus commanded), and the columns of other axes
/// (their errors as a function of this axis's position).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The rows, `AXISPOS` ascending.
    pub rows: Vec<(f64, f64, f64)>,
    /// Whether the table has the axis's own column and `BACKLASH` (a table of cross-axis
    /// columns alone has not).
    pub own: bool,
    /// The columns of other axes, by that axis: its error at each row's `AXISPOS`.
    pub cross: BTreeMap<Axis, Vec<f64>>,
}

impl Table {
    /// The error the table states at `q` moving up (`forward`) or down: linear between rows,
    /// the end rows' values beyond them.
    pub fn value_mm(&self, q: f64, forward: bool) -> f64 {
        let pick = |r: &(f64, f64, f64)| if forward { r.1 } else { r.2 };
        let (first, last) = (&self.rows[0], &self.rows[self.rows.len() - 1]);
        if q <= first.0 {
            return pick(first);
        }
        if q >= last.0 {
            return pick(last);
        }
        let k = self.rows.partition_point(|r| r.0 <= q);
        let (a, b) = (&self.rows[k - 1], &self.rows[k]);
        pick(a) + (q - a.0) / (b.0 - a.0) * (pick(b) - pick(a))
    }

    /// The error of `output` its column states at this axis's position `q`: linear between
    /// rows, the end rows' values beyond them; 0 without the column.
    pub fn cross_mm(&self, output: Axis, q: f64) -> f64 {
        let Some(v) = self.cross.get(&output) else { return 0.0 };
        let n = self.rows.len();
        if q <= self.rows[0].0 {
            return v[0];
        }
        if q >= self.rows[n - 1].0 {
            return v[n - 1];
        }
        let k = self.rows.partition_point(|r| r.0 <= q);
        let (a, b) = (self.rows[k - 1].0, self.rows[k].0);
        v[k - 1] + (q - a) / (b - a) * (v[k] - v[k - 1])
    }
}

/// The tables, by axis.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Files {
    /// `<axis>.COM`.
    pub tables: BTreeMap<Axis, Table>,
}

/// The name of an axis's table.
pub fn table_name(axis: Axis) -> String {
    format!("{}.COM", axis.name())
}

impl Files {
    /// An axis's `*.COM` text.
    pub fn table_text(&self, axis: Axis) -> String {
        let t = &self.tables[&axis];
        let name = table_name(axis);
        let a = axis.name();
        let mut s = format!("BEGIN {name} MM\n");
        let mut header = format!("{:<6}{:<14}", "NR", "AXISPOS");
        if t.own {
            header.push_str(&format!("{a:<14}"));
        }
        for o in t.cross.keys() {
            header.push_str(&format!("{:<14}", o.name()));
        }
        if t.own {
            header.push_str(&format!("{:<14}", "BACKLASH"));
        }
        s.push_str(&format!("{header}DOC\n"));
        let mut docs = vec![format!("ballbar compensate: {MANUAL}")];
        if t.own {
            docs.push(format!(
                "{a} = F({a}): the error, actual minus commanded, mm, moving positive; BACKLASH: moving negative"
            ));
        }
        for o in t.cross.keys() {
            docs.push(format!(
                "{o} = F({a}): {o}'s error, actual minus commanded, mm, over {a}'s position, subtracted from {o} (assumed: as the axis's own column)"
            ));
        }
        let num = |x: f64| format!("{:<14}", format!("{x:+.DECIMALS$}"));
        for (k, (q, up, down)) in t.rows.iter().enumerate() {
            let mut line = format!("{k:<6}{}", num(*q));
            if t.own {
                line.push_str(&num(*up));
            }
            for v in t.cross.values() {
                line.push_str(&num(v[k]));
            }
            if t.own {
                line.push_str(&num(*down));
            }
            line.push_str(docs.get(k).map_or("", |d| d.as_str()));
            s.push_str(line.trim_end());
            s.push('\n');
        }
        s.push_str("[END]\n");
        s
    }

    /// `CONFIG.CMA`: one row, active, naming each axis's table.
    pub fn assignment_text(&self) -> String {
        let mut s = format!("BEGIN {ASSIGNMENT_FILE}\n{:<6}", "NR");
        for a in self.tables.keys() {
            s.push_str(&format!("{:<10}", a.name()));
        }
        s.push_str(&format!("{:<8}DOC\n{:<6}", "ACTIVE", 0));
        for a in self.tables.keys() {
            s.push_str(&format!("{:<10}", table_name(*a)));
        }
        s.push_str(&format!("{:<8}ballbar compensate: {MANUAL}\n[END]\n", "*"));
        s
    }
}

impl ControllerFiles for Files {
    fn texts(&self) -> Vec<(String, String)> {
        let mut out: Vec<(String, String)> =
            self.tables.keys().map(|a| (table_name(*a), self.table_text(*a))).collect();
        out.push((ASSIGNMENT_FILE.to_string(), self.assignment_text()));
        out
    }

    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64 {
        self.tables.get(&axis).filter(|t| t.own).map_or(0.0, |t| -t.value_mm(q_mm, forward))
    }

    fn has(&self, axis: Axis) -> bool {
        self.tables.get(&axis).is_some_and(|t| t.own)
    }

    fn files_of(&self, axis: Axis, _term: &str) -> Vec<String> {
        vec![table_name(axis), ASSIGNMENT_FILE.to_string()]
    }

    fn resolution_mm(&self) -> f64 {
        RESOLUTION_MM
    }

    /// Minus the error the column of `output` in `input`'s table states (the control subtracts
    /// it, the module's assumption).
    fn cross_trim_mm(&self, input: Axis, output: Axis, q_mm: f64) -> f64 {
        self.tables.get(&input).map_or(0.0, |t| -t.cross_mm(output, q_mm))
    }

    fn has_cross(&self) -> bool {
        self.tables.values().any(|t| !t.cross.is_empty())
    }

    fn cross_span_mm(&self, input: Axis, output: Axis) -> Option<[f64; 2]> {
        let t = self.tables.get(&input).filter(|t| t.cross.contains_key(&output))?;
        Some([t.rows.first()?.0, t.rows.last()?.0])
    }

    /// The input's table, which holds the column, and the assignment.
    fn cross_files_of(&self, input: Axis, _output: Axis) -> Vec<String> {
        vec![table_name(input), ASSIGNMENT_FILE.to_string()]
    }
}

/// Why a term the axis tables do not take is not written, and what would.
fn why_not(term: &str) -> String {
    match term {
        "straightness" | "squareness" => "a HEIDENHAIN takes it in a column of the output axis in the input axis's .COM table (Y = F(X): X.COM's Y column) of two linear axes".into(),
        "servo_mismatch" => "advice, not a table: match the axes' position-loop gains (kv factor, CfgPosControl kvFactor / MP1810, in (m/min)/mm: Kv in 1/s is 16.67 times it) so that their lags are equal".into(),
        "reversal_spike" => "advice, not a table: the compensation of reversal peaks (Technical Manual, The control loop, Compensation of reversal peaks: compStrength the distance in mm the pulse moves the axis, whose starting value is the peak's height, compWidth its duration; iTNC 530 analog axes: MP711 the height of the spikes in mm and MP712 the compensation per control loop cycle; tuned by the circular test)".into(),
        "rotary_location" => "correct the rotary axis's location (ISO 230-7) in the kinematics table; not written".into(),
        _ => "a HEIDENHAIN's axis tables do not take this term".into(),
    }
}

/// The HEIDENHAIN tables for a model, and `compensation.json` without its predictions.
pub fn compensate(
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
) -> Result<(Compensation, Files), String> {
    crate::check_travel(options)?;
    let (mut entries, per_axis, mut notes) =
        tables::select(model, estimates, runs, options, &why_not);
    let crosses = crate::cross::select(model, &mut entries, runs, options, &mut notes)?;
    let existing = options.existing_tables.as_deref();
    // The cross-axis columns, by input: the new ones and the existing ones (kept), each with
    // the span it covers.
    let mut columns: BTreeMap<Axis, BTreeMap<Axis, [f64; 2]>> = BTreeMap::new();
    for c in crosses.values() {
        columns.entry(c.input).or_default().insert(c.output, c.span);
    }
    for (i, o, span) in existing.map(|e| e.crosses()).unwrap_or_default() {
        let s = columns.entry(i).or_default().entry(o).or_insert(span);
        *s = [s[0].min(span[0]), s[1].max(span[1])];
    }
    let mut axes = tables::merged_axes(&per_axis, existing);
    axes.extend(columns.keys().copied());
    axes.sort();
    axes.dedup();
    // Without the runs a backlash alone is written over the axis's travel: its BACKLASH column
    // is a table's, which covers a span, and past its rows what the control applies is assumed,
    // not known; every axis that lacks one is named at once.
    let lacking: Vec<Axis> = per_axis
        .keys()
        .copied()
        .filter(|&a| {
            runs.is_empty()
                && !options.travel.contains_key(&a)
                && existing.and_then(|e| e.span_mm(a)).is_none()
        })
        .collect();
    if !lacking.is_empty() {
        let names: Vec<&str> = lacking.iter().map(|a| a.name()).collect();
        let flags: Vec<String> = lacking.iter().map(|a| format!("--travel {a}=MIN:MAX")).collect();
        return Err(format!(
            "no runs given: the backlash of {} is a HEIDENHAIN table's BACKLASH column, and a table covers a span, which the runs give: give the runs, or the travel of each of these axes, {} (machine coordinates, mm)",
            names.join(", "),
            flags.join(" ")
        ));
    }
    let mut files = Files::default();
    let mut spans = BTreeMap::new();
    for axis in axes {
        let c = per_axis.get(&axis);
        // A backlash alone is a table too: its two directions. Merged with an existing table,
        // the span covers both; with cross-axis columns, theirs too (one AXISPOS for all).
        let own_span = tables::merged_span(options, axis, c, true)?;
        let own = own_span.is_some();
        let cols = columns.get(&axis).cloned().unwrap_or_default();
        let Some(span) = cols
            .values()
            .fold(own_span, |s, c| Some(s.map_or(*c, |s| [s[0].min(c[0]), s[1].max(c[1])])))
        else {
            continue;
        };
        let round =
            |x: f64| (x * 10f64.powi(DECIMALS as i32)).round() / 10f64.powi(DECIMALS as i32);
        // A span of one point (an existing table of one row, nothing measured along the
        // axis): one row, as AXISPOS must rise from row to row.
        let rows_n = if round(span[1]) <= round(span[0]) {
            1
        } else {
            (((span[1] - span[0]) / 1.0).ceil() as usize + 1).clamp(2, MAX_ROWS)
        };
        let backlash = c.map_or(0.0, |c| c.backlash);
        let rows = (0..rows_n)
            .map(|k| {
                let q =
                    round(span[0] + (span[1] - span[0]) * k as f64 / (rows_n.max(2) - 1) as f64);
                let p = c.map_or(0.0, |c| tables::positional_error_mm(c, q));
                // The existing error each way (the control subtracts it: minus its trim) plus
                // the measured one.
                let (up, down) = (
                    -tables::existing_trim(options, axis, q, true),
                    -tables::existing_trim(options, axis, q, false),
                );
                (q, round(up + p - 0.5 * backlash), round(down + p + 0.5 * backlash))
            })
            .collect();
        if c.is_some_and(|c| !c.positional.is_empty()) {
            spans.insert(axis, span);
        }
        let rows: Vec<(f64, f64, f64)> = rows;
        // Each column of another axis: the existing error there (minus its trim) plus the
        // measured one.
        let cross = cols
            .keys()
            .map(|&o| {
                let values = rows
                    .iter()
                    .map(|r| {
                        let old = -existing.map_or(0.0, |e| e.cross_trim_mm(axis, o, r.0));
                        let new = crosses.get(&(axis, o)).map_or(0.0, |c| c.error_mm(r.0));
                        round(old + new)
                    })
                    .collect();
                (o, values)
            })
            .collect();
        // A column covers the input's whole table, which the axis's own span, an existing
        // table's or another column's can widen past what the tests measured.
        for c in crosses.values().filter(|c| c.input == axis) {
            notes.extend(c.extension_note("column", span));
        }
        files.tables.insert(axis, Table { rows, own, cross });
    }
    let joints = per_axis.keys().map(|a| (a.name().to_string(), a.index())).collect();
    if !options.joints.is_empty() {
        notes.push("--joints: a HEIDENHAIN names its axes (the .CMA's columns), not their numbers: ignored".into());
    }
    let comp = tables::finish(
        "heidenhain",
        entries,
        &per_axis,
        tables::Written {
            model,
            files: &files,
            spans: &spans,
            crosses: &crosses,
            existing,
            runs,
            reading: options.reading.as_deref(),
        },
        joints,
        notes,
    )?;
    Ok((comp, files))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tables::fixtures::{BACK, POS, circle, estimate, model};

    #[test]
    fn the_values_are_the_error_each_way_and_the_tables_are_the_tncs_form() {
        // EXX1 = 10 µm at L = 250 mm (40 ppm too long: +0.008 mm at X = 200), BX = 4 µm: moving
        // up the axis stays 2 µm short (+0.008 - 0.002), moving down 2 µm beyond (+0.010).
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.004, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
        let (comp, files) = compensate(&m, &est, &[circle()], &Options::default()).unwrap();
        let t = &files.tables[&Axis::X];
        assert_eq!(t.rows.len(), 201);
        assert!((t.value_mm(200.0, true) - 0.006).abs() < 1e-4);
        assert!((t.value_mm(200.0, false) - 0.010).abs() < 1e-4);
        assert!((t.value_mm(400.0, true) - 0.014).abs() < 1e-4);
        // The control subtracts the error: at 400 mm moving up the axis is sent 14 µm short.
        assert!((files.trim_mm(Axis::X, 400.0, true) + 0.014).abs() < 1e-4);
        let text = files.table_text(Axis::X);
        assert!(
            text.starts_with(
                "BEGIN X.COM MM\nNR    AXISPOS       X             BACKLASH      DOC\n"
            ),
            "{text}"
        );
        assert!(text.contains("\n200   +400.000000   +0.014000     +0.018000\n"), "{text}");
        assert!(text.ends_with("\n[END]\n") && text.contains("Technical Manual"));
        let cma = files.assignment_text();
        assert!(
            cma.starts_with(
                "BEGIN CONFIG.CMA\nNR    X         ACTIVE  DOC\n0     X.COM     *       ballbar"
            ),
            "{cma}"
        );
        // The backlash as the tables leave it: nothing (±2 µm written exactly).
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!(bx.predicted_after.unwrap().abs() < 1e-9, "{bx:?}");
    }

    /// `--existing`: each row is the existing error plus the measured one, each way; an axis
    /// only the existing files compensate keeps its table; `existing` and `written` say what
    /// each applies, and the prediction is from the change alone.
    #[test]
    fn an_existing_table_is_merged_row_by_row_and_other_axes_are_kept() {
        use crate::tables::fixtures::FakeExisting;
        // Existing: X 20 ppm too long corrected (+20e-6·X) with 1 µm of backlash sent lower
        // moving negative; Z 10 ppm over 0..300 mm. Measured: X 40 ppm (EXX1 = 10 µm at L =
        // 250 mm) and 4 µm more backlash.
        let ex = FakeExisting {
            kind: "heidenhain",
            axes: vec![
                (Axis::X, 20e-6, 0.001, [100.0, 500.0]),
                (Axis::Z, 10e-6, 0.0, [0.0, 300.0]),
            ],
            crosses: vec![],
        };
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.004, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let (comp, files) = compensate(&m, &est, &[circle()], &o).unwrap();
        let t = &files.tables[&Axis::X];
        // The span is the existing table's and the measured one joined: 100..500 mm.
        assert_eq!((t.rows[0].0, t.rows[t.rows.len() - 1].0), (100.0, 500.0));
        // At 300 mm moving up: existing 20e-6·300 = 0.006, measured 40e-6·300 - 0.002 = 0.010;
        // moving down: existing 0.006 + 0.001, measured 0.012 + 0.002.
        assert!((t.value_mm(300.0, true) - 0.016).abs() < 1e-6, "{t:?}");
        assert!((t.value_mm(300.0, false) - 0.021).abs() < 1e-6, "{t:?}");
        // Z is kept as it was: 10e-6·200 = 0.002 each way.
        let z = &files.tables[&Axis::Z];
        assert!((z.value_mm(200.0, true) - 0.002).abs() < 1e-6 && z.rows[0].0 == 0.0);
        assert!(files.assignment_text().contains("Z.COM"));
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!((bx.existing.unwrap() - 1.0).abs() < 1e-6, "{bx:?}");
        assert!((bx.written.unwrap() - 5.0).abs() < 1e-6, "{bx:?}");
        assert!(bx.predicted_after.unwrap().abs() < 1e-6, "{bx:?}");
        // The scale in ppm: 20 existing, 60 written, and only the product left: the 40 ppm
        // measured with 20 active is s = (40 + 20)/(1 - 20e-6) = 60.0012 ppm, 60 ppm of trims
        // leave s - 60 - s × 60e-6 = -0.0024 ppm (to the values' 1 nm rounding).
        let sx = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
        assert!((sx.existing.unwrap() - 20.0).abs() < 1e-3, "{sx:?}");
        assert!((sx.written.unwrap() - 60.0).abs() < 1e-3, "{sx:?}");
        assert!((sx.predicted_after.unwrap() - (-0.0024)).abs() < 5e-4, "{sx:?}");
    }

    /// `--existing`: a term not written this time (not significant, an alias) still says what
    /// the existing files applied of it, and its axis's table is kept as it was.
    #[test]
    fn a_term_not_written_says_what_the_existing_files_applied() {
        use crate::tables::fixtures::FakeExisting;
        let ex = FakeExisting {
            kind: "heidenhain",
            axes: vec![(Axis::X, 20e-6, 0.001, [100.0, 500.0])],
            crosses: vec![],
        };
        // BX is 0.1 ± 1 µm (not significant), EXX1 moved by an alias.
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.0001, 1e-3)]);
        let sx = Estimate {
            aliases: vec!["positional error of X, degree 2".into()],
            ..estimate("EXX1", POS, 0.010, 1e-5)
        };
        let est = [sx, estimate("BX", BACK, 0.0001, 1e-3)];
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let (comp, files) = compensate(&m, &est, &[circle()], &o).unwrap();
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!(!bx.compensated && (bx.existing.unwrap() - 1.0).abs() < 1e-6, "{bx:?}");
        let sx = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
        assert!(!sx.compensated && (sx.existing.unwrap() - 20.0).abs() < 1e-3, "{sx:?}");
        let t = &files.tables[&Axis::X];
        assert!((t.value_mm(300.0, true) - 0.006).abs() < 1e-6, "{t:?}");
        assert!((t.value_mm(300.0, false) - 0.007).abs() < 1e-6, "{t:?}");
    }

    /// The squareness SQXY (`ΔY = −α X`) is Y's error over X: X.COM's `Y` column, `−α (X −
    /// reference)` up to a constant, X.COM then a table of that column alone (X itself is not
    /// compensated); the straightness the column machine ties to its yaw is not written.
    #[test]
    fn a_squareness_is_a_column_of_the_output_in_the_inputs_table() {
        use ballbar_model::{ParamClass, TermClass, Unit};
        let (alpha, theta) = (40e-6, 0.003);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let st = estimate("EYX2", ParamClass::Term(TermClass::Straightness), theta, 1e-5);
        let m = model(&[("SQXY", alpha, 1e-7), ("EYX2", theta, 1e-5)]);
        let (mut comp, files) =
            compensate(&m, &[sq.clone(), st], &[circle()], &Options::default()).unwrap();
        tables::predict(&mut comp, &files, None, &[circle()]);
        let x = &files.tables[&Axis::X];
        assert!(!x.own && x.cross.keys().copied().collect::<Vec<_>>() == vec![Axis::Y]);
        let (reference, _) = crate::norm(&m, Axis::X);
        for q in [200.0, 250.5, 333.3, 400.0] {
            assert!((x.cross_mm(Axis::Y, q) + alpha * (q - reference)).abs() < 1e-6, "{q}");
            // The control subtracts the error from Y: Y is sent α (X − reference) up.
            let trim = files.cross_trim_mm(Axis::X, Axis::Y, q);
            assert!((trim - alpha * (q - reference)).abs() < 1e-6, "{q}");
        }
        assert!(!files.has(Axis::X) && !files.has(Axis::Y));
        let text = files.table_text(Axis::X);
        assert!(
            text.starts_with("BEGIN X.COM MM\nNR    AXISPOS       Y             DOC\n"),
            "{text}"
        );
        assert!(text.contains("Y = F(X)"), "{text}");
        assert!(files.assignment_text().contains("\n0     X.COM     *"));
        let sq_term = comp.terms.iter().find(|t| t.id == "SQXY").unwrap();
        assert!(sq_term.compensated, "{sq_term:?}");
        assert_eq!(sq_term.files, vec!["X.COM".to_string(), ASSIGNMENT_FILE.to_string()]);
        assert!(sq_term.predicted_after.unwrap().abs() < 0.01, "{sq_term:?}");
        let st = comp.terms.iter().find(|t| t.id == "EYX2").unwrap();
        assert!(!st.compensated && st.why.as_ref().unwrap().contains("angle is tied"), "{st:?}");
        // The prediction adds the column's trim along the bar, `ΔR = sin φ · α (X − ref)`, X =
        // 300 + R cos φ: on the nominal circle the shear (αR/2) sin 2φ, RMS αR/(2√2) = 1.414
        // µm (the 50 Hz samples and the 1 nm rounding: within 1 %).
        let by_hand_um = alpha * 100.0 / (2.0 * 2f64.sqrt()) * 1e3;
        assert!(comp.predicted[0].rms_before_um < 1e-9, "{:?}", comp.predicted);
        let rms = comp.predicted[0].rms_after_um;
        assert!((rms - by_hand_um).abs() < 0.01 * by_hand_um, "{rms} {by_hand_um}");
        // With X's scale as well: one table, its own column, Y's and BACKLASH.
        let m = model(&[("SQXY", alpha, 1e-7), ("EXX1", 0.010, 1e-5)]);
        let sx = estimate("EXX1", POS, 0.010, 1e-5);
        let (_, files) = compensate(&m, &[sq, sx], &[circle()], &Options::default()).unwrap();
        let x = &files.tables[&Axis::X];
        assert!(x.own && files.has(Axis::X));
        assert!((x.value_mm(300.0, true) - 0.012).abs() < 1e-6);
        assert!((x.cross_mm(Axis::Y, 300.0) + alpha * (300.0 - reference)).abs() < 1e-6);
        let text = files.table_text(Axis::X);
        assert!(
            text.contains("\nNR    AXISPOS       X             Y             BACKLASH      DOC\n")
        );
        // With an existing column of Y in X's table (Y sent 10e-6·X up: a 10 µrad squareness
        // corrected) the column is the existing error plus the new: −(10e-6 + α) X.
        let ex = crate::tables::fixtures::FakeExisting {
            kind: "heidenhain",
            axes: vec![],
            crosses: vec![(Axis::X, Axis::Y, [0.0, 600.0], 10e-6)],
        };
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let (comp, files) = compensate(&m, &[sq], &[circle()], &o).unwrap();
        let x = &files.tables[&Axis::X];
        assert_eq!((x.rows[0].0, x.rows[x.rows.len() - 1].0), (0.0, 600.0));
        for q in [0.0, 250.5, 600.0] {
            let want = -10e-6 * q - alpha * (q - reference);
            assert!((x.cross_mm(Axis::Y, q) - want).abs() < 1e-6, "{q}");
        }
        let t = comp.terms.iter().find(|t| t.id == "SQXY").unwrap();
        assert!((t.existing.unwrap() - 10.0).abs() < 0.01, "{t:?}");
        assert!((t.written.unwrap() - 50.0).abs() < 0.01, "{t:?}");
        // The column as written covers the existing one's 0..600 mm, past the 200..400 mm the
        // circle measured: said in the term and in a note.
        assert_eq!((t.span_mm, t.extended), (Some([0.0, 600.0]), Some(true)), "{t:?}");
        assert!(
            comp.notes.iter().any(|n| n.contains("the column covers 0.000..600.000")),
            "{:?}",
            comp.notes
        );
    }

    /// An existing table of one row and a backlash measured without runs: one row, not two
    /// rows at one AXISPOS (which the control refuses: AXISPOS rises from row to row).
    #[test]
    fn an_existing_table_of_one_row_gives_one_row() {
        let ex = crate::tables::fixtures::FakeExisting {
            kind: "heidenhain",
            axes: vec![(Axis::X, 0.0, 0.001, [100.0, 100.0])],
            crosses: vec![],
        };
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let m = model(&[("BX", 0.004, 1e-5)]);
        let (_, files) = compensate(&m, &[estimate("BX", BACK, 0.004, 1e-5)], &[], &o).unwrap();
        let x = &files.tables[&Axis::X];
        assert_eq!(x.rows.len(), 1, "{x:?}");
        assert_eq!(x.rows[0].0, 100.0);
    }

    /// Without the runs a backlash alone is written over `--travel`, the same each row (the
    /// BACKLASH column 4 µm above the axis's: B = 4 µm); an axis without a travel is named with
    /// the option that would write it.
    #[test]
    fn without_runs_a_backlash_is_written_over_the_travel_given() {
        let m = model(&[("BX", 0.004, 1e-5), ("BY", 0.003, 1e-5)]);
        let est = [estimate("BX", BACK, 0.004, 1e-5), estimate("BY", BACK, 0.003, 1e-5)];
        let e = compensate(&m, &est, &[], &Options::default()).unwrap_err();
        assert!(e.contains("--travel X=MIN:MAX --travel Y=MIN:MAX"), "{e}");
        let mut o = Options::default();
        o.travel.insert(Axis::X, [0.0, 500.0]);
        let e = compensate(&m, &est, &[], &o).unwrap_err();
        assert!(e.contains("backlash of Y") && !e.contains("X=MIN"), "{e}");
        o.travel.insert(Axis::Y, [-100.0, 300.0]);
        let (comp, files) = compensate(&m, &est, &[], &o).unwrap();
        let x = &files.tables[&Axis::X];
        assert_eq!((x.rows[0].0, x.rows[x.rows.len() - 1].0), (0.0, 500.0));
        assert!(x.rows.iter().all(|r| r.1 == -0.002 && r.2 == 0.002), "{x:?}");
        let y = &files.tables[&Axis::Y];
        assert_eq!((y.rows[0].0, y.rows[y.rows.len() - 1].0), (-100.0, 300.0));
        assert!(y.rows.iter().all(|r| (r.2 - r.1 - 0.003).abs() < 1e-12), "{y:?}");
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!(bx.compensated && bx.predicted_after.unwrap().abs() < 1e-9, "{bx:?}");
    }

    #[test]
    fn a_long_travel_keeps_to_256_rows() {
        let m = model(&[("EXX1", 0.010, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5)];
        let mut o = Options::default();
        o.travel.insert(Axis::X, [-500.0, 1500.0]);
        let (_, files) = compensate(&m, &est, &[circle()], &o).unwrap();
        let t = &files.tables[&Axis::X];
        assert_eq!(t.rows.len(), MAX_ROWS);
        assert!(t.rows.windows(2).all(|w| w[1].0 > w[0].0));
        assert!((t.value_mm(1500.0, true) - 0.060).abs() < 1e-4);
    }
}

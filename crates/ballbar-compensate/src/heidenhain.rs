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
//! the tables' two directions take the backlash. Cross-axis tables (a `.COM` column of another
//! axis: straightness, sag) are not written by this version.

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
/// down)`, each value the error there (actual minus commanded).
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// The rows, `AXISPOS` ascending.
    pub rows: Vec<(f64, f64, f64)>,
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
        s.push_str(&format!("{:<6}{:<14}{:<14}{:<14}DOC\n", "NR", "AXISPOS", a, "BACKLASH"));
        for (k, (q, up, down)) in t.rows.iter().enumerate() {
            let doc = match k {
                0 => format!("ballbar compensate: {MANUAL}"),
                1 => format!(
                    "{a} = F({a}): the error, actual minus commanded, mm, moving positive; BACKLASH: moving negative"
                ),
                _ => String::new(),
            };
            let line = format!(
                "{k:<6}{:<14}{:<14}{:<14}{doc}",
                format!("{q:+.DECIMALS$}"),
                format!("{up:+.DECIMALS$}"),
                format!("{down:+.DECIMALS$}")
            );
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
        self.tables.get(&axis).map_or(0.0, |t| -t.value_mm(q_mm, forward))
    }

    fn has(&self, axis: Axis) -> bool {
        self.tables.contains_key(&axis)
    }

    fn files_of(&self, axis: Axis, _term: &str) -> Vec<String> {
        vec![table_name(axis), ASSIGNMENT_FILE.to_string()]
    }

    fn resolution_mm(&self) -> f64 {
        RESOLUTION_MM
    }
}

/// Why a term the axis tables do not take is not written, and what would.
fn why_not(term: &str) -> String {
    match term {
        "straightness" | "squareness" => "a HEIDENHAIN takes it in a cross-axis compensation table (a .COM column of another axis, e.g. Y = F(X)) or KinematicsComp: writing cross-axis tables is not done by this version".into(),
        "servo_mismatch" => "advice, not a table: match the axes' position-loop gains (kv factor, CfgPosControl kvFactor / MP1810) so that their lags are equal".into(),
        "reversal_spike" => "advice, not a table: reversal spike compensation (CfgAxisComp / MP711-MP716)".into(),
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
    let (entries, per_axis, mut notes) = tables::select(model, estimates, runs, options, &why_not);
    let existing = options.existing_tables.as_deref();
    let mut files = Files::default();
    let mut spans = BTreeMap::new();
    for axis in tables::merged_axes(&per_axis, existing) {
        let c = per_axis.get(&axis);
        // A backlash alone is a table too: its two directions. Merged with an existing table,
        // the span covers both.
        let Some(span) = tables::merged_span(options, axis, c, true)? else { continue };
        let rows_n = (((span[1] - span[0]) / 1.0).ceil() as usize + 1).clamp(2, MAX_ROWS);
        let round =
            |x: f64| (x * 10f64.powi(DECIMALS as i32)).round() / 10f64.powi(DECIMALS as i32);
        let backlash = c.map_or(0.0, |c| c.backlash);
        let rows = (0..rows_n)
            .map(|k| {
                let q = round(span[0] + (span[1] - span[0]) * k as f64 / (rows_n - 1) as f64);
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
        files.tables.insert(axis, Table { rows });
    }
    let joints = per_axis.keys().map(|a| (a.name().to_string(), a.index())).collect();
    if !options.joints.is_empty() {
        notes.push("--joints: a HEIDENHAIN names its axes (the .CMA's columns), not their numbers: ignored".into());
    }
    let comp = tables::finish(
        "heidenhain",
        entries,
        &per_axis,
        tables::Written { files: &files, spans: &spans, crosses: &BTreeMap::new(), existing },
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
        // The scale in ppm: 20 existing, 60 written, none left.
        let sx = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
        assert!((sx.existing.unwrap() - 20.0).abs() < 1e-3, "{sx:?}");
        assert!((sx.written.unwrap() - 60.0).abs() < 1e-3, "{sx:?}");
        assert!(sx.predicted_after.unwrap().abs() < 1e-3, "{sx:?}");
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

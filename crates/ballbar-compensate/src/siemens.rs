//! SINUMERIK 840D sl: leadscrew/measuring-system error compensation (LEC, part of MSEC) tables
//! and the backlash machine data, as the function manual states them: *SINUMERIK 840D sl
//! Extended Functions, Function Manual*, section K3 "Compensation", "Interpolatory
//! compensation" → "Compensation of leadscrew errors and measuring system errors" (the example
//! program `%_N_AX_EEC_INI`) and "Backlash compensation" (MD32450 `$MA_BACKLASH`).
//!
//! - A table is `$AA_ENC_COMP[0,N,AXn]` (the compensation value of interpolation point `N`,
//!   mm), `$AA_ENC_COMP_STEP[0,AXn]` (the points' spacing), `$AA_ENC_COMP_MIN[0,AXn]` (the
//!   position of point 0), `$AA_ENC_COMP_MAX[0,AXn]` (the table's end), and
//!   `$AA_ENC_COMP_IS_MODULO[0,AXn]` (0: a linear axis). Between points the NC interpolates
//!   linearly; below `MIN` it holds point 0's value, above `MAX` the last point's. The NC
//!   neither limits nor checks a value.
//! - Sign: the value modifies the axis's actual position value, and "a positive compensation
//!   value causes the corresponding machine axis to move in the negative direction". A value
//!   is therefore the error it cancels, actual minus commanded (`δ`, the model's convention),
//!   and the trim it applies is `-value`.
//! - Tables become active with MD32700 `$MA_ENC_COMP_ENABLE[0,AXn] = 1` after the axis is
//!   referenced; the values are written while it is 0. MD38000 `$MA_MM_ENC_COMP_MAX_POINTS`
//!   must be at least the points a table has (its memory is reserved at power on).
//! - MD32450 `$MA_BACKLASH[0,AXn]`, mm: positive when the encoder leads the machine part (a lost
//!   motion, the normal case), negative when it trails; applied at each reversal. A positive
//!   backlash B of the model (`δ = -(B/2) sign(v)`) is `$MA_BACKLASH = B`.
//!
//! Assumed where the manual's example does not say: machine axis `AXn` is the `n`-th machine
//! axis, X, Y, Z as 1, 2, 3 unless `--joints` says otherwise (`--joints X=0` is `AX1`); the
//! tables are written with at most [`MAX_POINTS`] points (a configuration's MD38000 may allow
//! more); values in mm to 1 nm.
//!
//! Squareness and straightness go into sag/angularity compensation tables (CEC, the same
//! section: "Compensation of sag and angularity errors"), `NC_CEC.INI` as the manual's example
//! program `%_N_NC_CEC_INI`: per table `t`, `$AN_CEC[t,N]` (the value of point `N`, mm),
//! `$AN_CEC_INPUT_AXIS[t]` (the base axis, whose setpoint position indexes the table),
//! `$AN_CEC_OUTPUT_AXIS[t]` (the compensation axis), `$AN_CEC_STEP[t]`, `$AN_CEC_MIN[t]`,
//! `$AN_CEC_MAX[t]` (below MIN the first point's value holds, above MAX the last's),
//! `$AN_CEC_DIRECTION[t]=0` (both directions of the base axis), `$AN_CEC_MULT_BY_TABLE[t]=0`,
//! `$AN_CEC_IS_MODULO[t]=0`; the tables of one compensation axis are summed. They act with
//! MD32710 `$MA_CEC_ENABLE[AXn]=1` on the compensation axis and SD41300
//! `$SN_CEC_TABLE_ENABLE[t]=1`; MD18342 `$MN_MM_CEC_MAX_POINTS[t]` must be at least the
//! table's points. One table per pair of axes, the squareness and the straightness of the pair
//! summed in it (a straightness whose angle is tied to it is not written: [`crate::cross`]).
//!
//! Assumed, as the manual's text available to us does not state it for CEC (LEC's value is the
//! error, moving the axis the other way): a CEC value is a correction added to the compensation
//! axis's position setpoint, so a positive value moves the axis positive, and a value is the
//! trim `-δ` of the output axis. Only a re-measurement proves it (`verify` reads a table applied
//! the other way as `reversed`); the files say so in a comment.

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::{Axis, Run};

use crate::tables::{self, ControllerFiles};
use crate::{Compensation, Estimate, Options};

/// The manual section the files follow (named in each file's comment).
pub const MANUAL: &str = "SINUMERIK 840D sl Function Manual Extended Functions, K3 Compensation: Interpolatory compensation, Compensation of leadscrew errors and measuring system errors (MSEC/LEC); Backlash compensation (MD32450)";

/// The most interpolation points a written table has: SINUMERIK 808D's fixed 200, within any
/// 840D sl whose MD38000 allows them.
pub const MAX_POINTS: usize = 200;

/// Decimal places of a written value, mm: 1 nm.
const DECIMALS: usize = 6;

/// The resolution of a written value, mm: its last decimal.
pub const RESOLUTION_MM: f64 = 1e-6;

/// The table file's name.
pub const TABLE_FILE: &str = "AX_EEC.INI";
/// The machine data file's name.
pub const MACHINE_DATA_FILE: &str = "MD_COMP.INI";

/// One axis's LEC table, mm.
#[derive(Clone, Debug, PartialEq)]
pub struct Table {
    /// `$AA_ENC_COMP_MIN`: the position of point 0.
    pub min_mm: f64,
    /// `$AA_ENC_COMP_STEP`.
    pub step_mm: f64,
    /// `$AA_ENC_COMP[0,N,..]`, N = 0, 1, ...: the error at each point (actual minus commanded).
    pub values_mm: Vec<f64>,
}

impl Table {
    /// `$AA_ENC_COMP_MAX`: the last point's position.
    pub fn max_mm(&self) -> f64 {
        self.min_mm + self.step_mm * (self.values_mm.len() - 1) as f64
    }

    /// The value at position `q`: linear between points, the end points' values beyond them.
    pub fn value_mm(&self, q: f64) -> f64 {
        let n = self.values_mm.len();
        let x = ((q - self.min_mm) / self.step_mm).clamp(0.0, (n - 1) as f64);
        let k = (x.floor() as usize).min(n.saturating_sub(2));
        if n == 1 {
            return self.values_mm[0];
        }
        let f = x - k as f64;
        self.values_mm[k] + f * (self.values_mm[k + 1] - self.values_mm[k])
    }
}

/// The table file of the cross-axis (sag/angularity) tables.
pub const CEC_FILE: &str = "NC_CEC.INI";

/// One sag/angularity compensation (CEC) table: the correction of `output` over `input`'s
/// position, mm.
#[derive(Clone, Debug, PartialEq)]
pub struct Cec {
    /// `$AN_CEC_INPUT_AXIS`: the base axis.
    pub input: Axis,
    /// `$AN_CEC_OUTPUT_AXIS`: the compensation axis.
    pub output: Axis,
    /// The points: `$AN_CEC_MIN`, `$AN_CEC_STEP` and `$AN_CEC[t,N]`, each the correction
    /// added to the output's setpoint (the module's assumption), `-δ`.
    pub table: Table,
}

/// What the files set, by axis.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Files {
    /// Machine axis name of each compensated axis (`AX1`).
    pub names: BTreeMap<Axis, String>,
    /// LEC tables.
    pub tables: BTreeMap<Axis, Table>,
    /// MD32450 `$MA_BACKLASH`, mm.
    pub backlash_mm: BTreeMap<Axis, f64>,
    /// Sag/angularity tables, table index `t` their place.
    pub cec: Vec<Cec>,
}

impl Files {
    /// `AX_EEC.INI`: the tables, in the manual's example program's form.
    pub fn table_text(&self) -> String {
        let mut s = String::from("%_N_AX_EEC_INI\n");
        s.push_str(&format!(
            "; ballbar compensate: leadscrew error compensation tables ({MANUAL})\n"
        ));
        s.push_str("; a value is the axis's error at the point, actual minus commanded, mm: a positive value moves the axis negative\n");
        s.push_str("; load with MD32700 $MA_ENC_COMP_ENABLE = 0, then set it to 1 (MD_COMP.INI) and reset the NCK\n");
        s.push_str("CHANDATA(1)\n");
        for (axis, t) in &self.tables {
            let ax = &self.names[axis];
            s.push_str(&format!(
                "; {axis} ({ax}): {} points, MD38000 $MA_MM_ENC_COMP_MAX_POINTS[0,{ax}] must be at least {}\n",
                t.values_mm.len(),
                t.values_mm.len()
            ));
            for (n, v) in t.values_mm.iter().enumerate() {
                s.push_str(&format!("$AA_ENC_COMP[0,{n},{ax}]={v:.DECIMALS$}\n"));
            }
            s.push_str(&format!("$AA_ENC_COMP_STEP[0,{ax}]={:.DECIMALS$}\n", t.step_mm));
            s.push_str(&format!("$AA_ENC_COMP_MIN[0,{ax}]={:.DECIMALS$}\n", t.min_mm));
            s.push_str(&format!("$AA_ENC_COMP_MAX[0,{ax}]={:.DECIMALS$}\n", t.max_mm()));
            s.push_str(&format!("$AA_ENC_COMP_IS_MODULO[0,{ax}]=0\n"));
        }
        s.push_str("M17\n");
        s
    }

    /// `NC_CEC.INI`: the sag/angularity tables, in the manual's example program's form.
    pub fn cec_text(&self) -> String {
        let mut s = String::from("%_N_NC_CEC_INI\n");
        s.push_str(&format!(
            "; ballbar compensate: sag and angularity compensation tables (CEC) ({MANUAL})\n"
        ));
        s.push_str("; a value is the correction added to the compensation axis's setpoint, mm, at the base axis's setpoint position: assumed (the manual's text at hand does not state the CEC sign); a re-measurement proves it\n");
        s.push_str("; load with MD32710 $MA_CEC_ENABLE = 0, then set it and SD41300 $SN_CEC_TABLE_ENABLE to 1 (MD_COMP.INI) and reset the NCK\n");
        s.push_str("CHANDATA(1)\n");
        for (t, c) in self.cec.iter().enumerate() {
            let (i, o) = (&self.names[&c.input], &self.names[&c.output]);
            let n = c.table.values_mm.len();
            s.push_str(&format!(
                "; table {t}: {} = F({}) ({o} over {i}), {n} points, MD18342 $MN_MM_CEC_MAX_POINTS[{t}] must be at least {n}\n",
                c.output, c.input
            ));
            for (k, v) in c.table.values_mm.iter().enumerate() {
                s.push_str(&format!("$AN_CEC[{t},{k}]={v:.DECIMALS$}\n"));
            }
            s.push_str(&format!("$AN_CEC_INPUT_AXIS[{t}]=({i})\n"));
            s.push_str(&format!("$AN_CEC_OUTPUT_AXIS[{t}]=({o})\n"));
            s.push_str(&format!("$AN_CEC_STEP[{t}]={:.DECIMALS$}\n", c.table.step_mm));
            s.push_str(&format!("$AN_CEC_MIN[{t}]={:.DECIMALS$}\n", c.table.min_mm));
            s.push_str(&format!("$AN_CEC_MAX[{t}]={:.DECIMALS$}\n", c.table.max_mm()));
            s.push_str(&format!("$AN_CEC_DIRECTION[{t}]=0\n"));
            s.push_str(&format!("$AN_CEC_MULT_BY_TABLE[{t}]=0\n"));
            s.push_str(&format!("$AN_CEC_IS_MODULO[{t}]=0\n"));
        }
        s.push_str("M17\n");
        s
    }

    /// `MD_COMP.INI`: MD32700 for each table, MD32450 for each backlash.
    pub fn machine_data_text(&self) -> String {
        let mut s = String::from("%_N_MD_COMP_INI\n");
        s.push_str(&format!("; ballbar compensate: machine data ({MANUAL})\n"));
        s.push_str("; MD32450 $MA_BACKLASH in mm, positive for a lost motion (encoder leading the machine part); active after NEW CONF\n");
        for (axis, ax) in &self.names {
            if self.tables.contains_key(axis) {
                s.push_str(&format!("$MA_ENC_COMP_ENABLE[0,{ax}]=1\n"));
            }
            if let Some(b) = self.backlash_mm.get(axis) {
                s.push_str(&format!("$MA_BACKLASH[0,{ax}]={b:.DECIMALS$}\n"));
            }
            if self.cec.iter().any(|c| c.output == *axis) {
                s.push_str(&format!("$MA_CEC_ENABLE[{ax}]=1\n"));
            }
        }
        for t in 0..self.cec.len() {
            s.push_str(&format!("$SN_CEC_TABLE_ENABLE[{t}]=1\n"));
        }
        s.push_str("M17\n");
        s
    }
}

impl ControllerFiles for Files {
    fn texts(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        if !self.tables.is_empty() {
            out.push((TABLE_FILE.to_string(), self.table_text()));
        }
        if !self.cec.is_empty() {
            out.push((CEC_FILE.to_string(), self.cec_text()));
        }
        out.push((MACHINE_DATA_FILE.to_string(), self.machine_data_text()));
        out
    }

    /// `-value` of the table (a positive value moves the axis negative), and the backlash
    /// `±B/2` (its level, which depends on the direction of the reference approach, is a
    /// constant offset of the axis).
    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64 {
        let table = self.tables.get(&axis).map_or(0.0, |t| -t.value_mm(q_mm));
        let b = self.backlash_mm.get(&axis).copied().unwrap_or(0.0);
        table + if forward { 0.5 * b } else { -0.5 * b }
    }

    fn has(&self, axis: Axis) -> bool {
        self.names.contains_key(&axis)
    }

    /// A table's terms: the table and the machine data that enables it; a backlash: the
    /// machine data.
    fn files_of(&self, axis: Axis, term: &str) -> Vec<String> {
        if matches!(term, "squareness" | "straightness") {
            return vec![CEC_FILE.to_string(), MACHINE_DATA_FILE.to_string()];
        }
        let mut f = Vec::new();
        if term != "backlash" && self.tables.contains_key(&axis) {
            f.push(TABLE_FILE.to_string());
        }
        if self.has(axis) {
            f.push(MACHINE_DATA_FILE.to_string());
        }
        f
    }

    fn resolution_mm(&self) -> f64 {
        RESOLUTION_MM
    }

    /// The sum of the tables of `input` over `output`: the value, a correction (the module's
    /// assumption).
    fn cross_trim_mm(&self, input: Axis, output: Axis, q_mm: f64) -> f64 {
        self.cec
            .iter()
            .filter(|c| c.input == input && c.output == output)
            .map(|c| c.table.value_mm(q_mm))
            .sum()
    }

    fn has_cross(&self) -> bool {
        !self.cec.is_empty()
    }
}

/// A table's spacing and points over `span`: 1 mm apart where [`MAX_POINTS`] allow it, the
/// spacing a whole number of µm, the last point at or past the span's end.
fn points(span: [f64; 2]) -> (f64, usize) {
    let step_um = ((span[1] - span[0]) * 1e3 / (MAX_POINTS - 1) as f64).ceil().max(1000.0);
    let step_mm = step_um * 1e-3;
    let n = (((span[1] - span[0]) / step_mm - 1e-9).ceil() as usize + 1).max(2);
    (step_mm, n)
}

/// Why a term Siemens's axis compensation does not take is not written, and what would.
fn why_not(term: &str) -> String {
    match term {
        "straightness" | "squareness" => "SINUMERIK takes it in a sag/angularity compensation table (CEC, $AN_CEC with $AN_CEC_INPUT_AXIS and $AN_CEC_OUTPUT_AXIS, MD32710 CEC_ENABLE) of two linear axes".into(),
        "servo_mismatch" => "advice, not a table: match the axes' position-loop gains (MD32200 $MA_POSCTRL_GAIN, Kv in (m/min)/mm: Kv in 1/s is 16.67 times it) or their feed-forward so that their lags are equal".into(),
        "reversal_spike" => "advice, not a table: friction compensation (SINUMERIK 840D sl Function Manual Extended Functions, K3 Compensation, Friction compensation (quadrant error compensation): MD32490 $MA_FRICT_COMP_MODE = 1 and MD32500 $MA_FRICT_COMP_ENABLE = 1, MD32520 $MA_FRICT_COMP_CONST_MAX the injected amplitude in mm/min, MD32540 $MA_FRICT_COMP_TIME its time constant in s; tuned by the circularity test)".into(),
        "rotary_location" => "correct the rotary axis's location (ISO 230-7) in the kinematic chain / TRAFO5 data; writing Siemens kinematics is not done yet".into(),
        _ => "SINUMERIK's axis compensation does not take this term".into(),
    }
}

/// The SINUMERIK files for a model, and `compensation.json` without its predictions.
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
    let mut axes = tables::merged_axes(&per_axis, existing);
    axes.extend(crosses.keys().flat_map(|&(i, o)| [i, o]));
    // The existing CEC tables are kept, merged with a new one of the same pair.
    let mut pairs: BTreeMap<(Axis, Axis), Option<[f64; 2]>> =
        crosses.keys().map(|&k| (k, None)).collect();
    for (i, o, span) in existing.map(|e| e.crosses()).unwrap_or_default() {
        axes.extend([i, o]);
        // Two existing tables of one pair (the NC sums them): one table over both spans.
        let s = pairs.entry((i, o)).or_insert(None);
        *s = Some(s.map_or(span, |s| [s[0].min(span[0]), s[1].max(span[1])]));
    }
    axes.sort();
    axes.dedup();
    let numbers = tables::axis_numbers(axes.iter().copied(), options)?;
    let number = |a: Axis| numbers[&a];
    let mut files = Files::default();
    let mut spans = BTreeMap::new();
    let mut joints = BTreeMap::new();
    for axis in tables::merged_axes(&per_axis, existing) {
        let c = per_axis.get(&axis);
        files.names.insert(axis, format!("AX{}", number(axis)));
        joints.insert(axis.name().to_string(), number(axis) - 1);
        // MD32450 as the NC applies it: moving negative the axis is sent B lower.
        let existing_backlash = tables::existing_trim(options, axis, 0.0, true)
            - tables::existing_trim(options, axis, 0.0, false);
        let backlash = c.map_or(0.0, |c| c.backlash) + existing_backlash;
        if backlash != 0.0 {
            files.backlash_mm.insert(axis, backlash);
        }
        let Some(span) = tables::merged_span(options, axis, c, false)? else { continue };
        let (step_mm, n) = points(span);
        let round = |x: f64| (x * 1e6).round() / 1e6;
        let min_mm = round(span[0]);
        // The existing table's value (the error it cancels: minus its trim moving positive,
        // where MD32450 adds nothing) plus the measured error.
        let value = |q: f64| {
            -tables::existing_trim(options, axis, q, true)
                + c.map_or(0.0, |c| tables::positional_error_mm(c, q))
        };
        let values_mm = (0..n).map(|k| round(value(min_mm + step_mm * k as f64))).collect();
        if c.is_some_and(|c| !c.positional.is_empty()) {
            spans.insert(axis, span);
        }
        files.tables.insert(axis, Table { min_mm, step_mm, values_mm });
    }
    for (&(input, output), old_span) in &pairs {
        for a in [input, output] {
            files.names.insert(a, format!("AX{}", number(a)));
            joints.insert(a.name().to_string(), number(a) - 1);
        }
        let new = crosses.get(&(input, output));
        let span = match (new.map(|c| c.span), *old_span) {
            (Some(n), Some(o)) => [n[0].min(o[0]), n[1].max(o[1])],
            (Some(s), None) | (None, Some(s)) => s,
            (None, None) => continue,
        };
        let (step_mm, n) = points(span);
        let round = |x: f64| (x * 1e6).round() / 1e6;
        let min_mm = round(span[0]);
        // A value is a correction (the module's assumption): the existing one, minus the
        // measured error.
        let value = |q: f64| {
            existing.map_or(0.0, |e| e.cross_trim_mm(input, output, q))
                - new.map_or(0.0, |c| c.error_mm(q))
        };
        let values_mm = (0..n).map(|k| round(value(min_mm + step_mm * k as f64))).collect();
        files.cec.push(Cec { input, output, table: Table { min_mm, step_mm, values_mm } });
        let Some(c) = new else { continue };
        notes.extend(c.extension_note("table", span));
    }
    let mut numbers: BTreeMap<String, Axis> = BTreeMap::new();
    for (a, name) in &files.names {
        if let Some(other) = numbers.insert(name.clone(), *a) {
            return Err(format!("--joints: {other} and {a} are both {name}"));
        }
    }
    let comp = tables::finish(
        "siemens",
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
    fn a_value_is_the_error_and_moves_the_axis_the_other_way() {
        // EXX1 = 10 µm at L = 250 mm: X goes 40 ppm too far, δ = +0.010·X/250 mm. The manual:
        // a positive value moves the axis negative, so the value is δ itself: +0.008 mm at
        // X = 200, +0.016 mm at X = 400. BX = 4 µm, a lost motion: $MA_BACKLASH = +0.004.
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.004, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
        let (comp, files) = compensate(&m, &est, &[circle()], &Options::default()).unwrap();
        let t = &files.tables[&Axis::X];
        // The measured span 200..400 mm in at most 200 points: 1.006 mm apart (the next whole
        // µm above 200/199 mm), the last point past 400 mm.
        assert_eq!(t.values_mm.len(), 200);
        assert!((t.min_mm - 200.0).abs() < 1e-3 && t.step_mm == 1.006, "{t:?}");
        assert!(t.max_mm() >= 400.0);
        assert!((t.value_mm(200.0) - 0.008).abs() < 1e-6);
        assert!((t.value_mm(400.0) - 0.016).abs() < 1e-6);
        // The trim applied is the opposite: the axis is sent 16 µm short at X = 400.
        assert!((files.trim_mm(Axis::X, 400.0, true) - (-0.016 + 0.002)).abs() < 1e-6);
        let text = files.table_text();
        assert!(text.starts_with("%_N_AX_EEC_INI\n"), "{text}");
        assert!(text.contains("\n$AA_ENC_COMP[0,0,AX1]=0.008000\n"), "{text}");
        // The last point, 199 steps of 1.006 mm above 200 mm: 400.194 mm, 0.010·400.194/250 mm.
        assert!(text.contains("\n$AA_ENC_COMP[0,199,AX1]=0.016008\n"), "{text}");
        assert!(text.contains("\n$AA_ENC_COMP_STEP[0,AX1]=1.006000\n"));
        assert!(text.contains("\n$AA_ENC_COMP_MAX[0,AX1]=400.194"), "{text}");
        assert!(text.contains("\n$AA_ENC_COMP_IS_MODULO[0,AX1]=0\nM17\n"));
        // Every comment line names the manual section or says what the file does, after `;`.
        assert!(text.lines().nth(1).unwrap().starts_with("; ") && text.contains("K3"));
        let md = files.machine_data_text();
        assert!(
            md.contains("\n$MA_ENC_COMP_ENABLE[0,AX1]=1\n$MA_BACKLASH[0,AX1]=0.004000\n"),
            "{md}"
        );
        // Nothing left after the files but the scale's product with its trim: a scale v ppm
        // corrected leaves -v² × 1e-6 ppm (the backlash 0), to the values' 1 nm rounding.
        for t in comp.terms.iter().filter(|t| t.compensated) {
            let want = t.value_ppm.map_or(0.0, |v| -v * v * 1e-6);
            assert!((t.predicted_after.unwrap() - want).abs() < 5e-4, "{t:?}");
        }
    }

    #[test]
    fn a_long_span_keeps_to_the_point_limit_and_a_squareness_says_where_it_would_go() {
        let m = model(&[("EXX1", 0.010, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5)];
        let mut o = Options::default();
        o.travel.insert(Axis::X, [0.0, 1000.0]);
        let (comp, files) = compensate(&m, &est, &[circle()], &o).unwrap();
        let t = &files.tables[&Axis::X];
        assert!(t.values_mm.len() <= MAX_POINTS);
        assert!(t.max_mm() >= 1000.0 - 1e-9);
        // A scale is extended linearly: 0.040 mm at 1000 mm.
        assert!((t.value_mm(1000.0) - 0.040).abs() < 1e-6);
        assert_eq!(comp.terms[0].extended, Some(true));
        assert!(why_not("squareness").contains("$AN_CEC"));
    }

    /// A squareness of XY goes into a CEC table of Y over X, its values the correction `-δ_Y(X)`
    /// derived by hand from the model's convention (`ΔY = -α X`), and leaves nothing after it;
    /// the column machine's straightness of X in Y, its yaw tied to it, is not written.
    #[test]
    fn a_squareness_becomes_a_cec_table_of_the_output_over_the_input() {
        use ballbar_model::{ParamClass, TermClass, Unit};
        let (alpha, theta) = (40e-6, 0.003);
        let m = model(&[("SQXY", alpha, 1e-7), ("EYX2", theta, 1e-5)]);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let st = estimate("EYX2", ParamClass::Term(TermClass::Straightness), theta, 1e-5);
        let (mut comp, files) =
            compensate(&m, &[sq, st], &[circle()], &Options::default()).unwrap();
        tables::predict(&mut comp, &files, None, &[circle()]);
        assert_eq!(files.cec.len(), 1);
        let c = &files.cec[0];
        assert_eq!((c.input, c.output), (Axis::X, Axis::Y));
        let (reference, _) = crate::norm(&m, Axis::X);
        for x in [200.0, 250.5, 333.3, 400.0] {
            assert!((c.table.value_mm(x) - alpha * (x - reference)).abs() < 1e-6, "{x}");
        }
        let text = files.cec_text();
        assert!(text.starts_with("%_N_NC_CEC_INI\n; ") && text.ends_with("M17\n"), "{text}");
        for line in [
            "$AN_CEC_INPUT_AXIS[0]=(AX1)",
            "$AN_CEC_OUTPUT_AXIS[0]=(AX2)",
            "$AN_CEC_DIRECTION[0]=0",
            "$AN_CEC_IS_MODULO[0]=0",
        ] {
            assert!(text.contains(&format!("\n{line}\n")), "{line}: {text}");
        }
        let md = files.machine_data_text();
        assert!(md.contains("\n$MA_CEC_ENABLE[AX2]=1\n"), "{md}");
        assert!(md.contains("\n$SN_CEC_TABLE_ENABLE[0]=1\n"), "{md}");
        assert!(!md.contains("ENC_COMP_ENABLE"), "{md}");
        // Nothing left of the squareness: below 0.01 µrad (the 1 nm rounding over 200 mm).
        let sq = comp.terms.iter().find(|t| t.id == "SQXY").unwrap();
        assert!(sq.compensated, "{sq:?}");
        assert_eq!(sq.files, vec![CEC_FILE.to_string(), MACHINE_DATA_FILE.to_string()]);
        assert!(sq.predicted_after.unwrap().abs() < 0.01, "{sq:?}");
        let st = comp.terms.iter().find(|t| t.id == "EYX2").unwrap();
        assert!(!st.compensated && st.why.as_ref().unwrap().contains("angle is tied"), "{st:?}");
        // The prediction adds the table's trim along the bar, `ΔR = sin φ · α (X - ref)`, X =
        // 300 + R cos φ: on the nominal circle the shear (αR/2) sin 2φ, RMS αR/(2√2) = 1.414
        // µm (the 50 Hz samples and the 1 nm rounding: within 1 %).
        let by_hand_um = alpha * 100.0 / (2.0 * 2f64.sqrt()) * 1e3;
        let rms = comp.predicted[0].rms_after_um;
        assert!(comp.predicted[0].rms_before_um < 1e-9, "{:?}", comp.predicted);
        assert!((rms - by_hand_um).abs() < 0.01 * by_hand_um, "{rms} {by_hand_um}");
    }

    /// `--existing`: a CEC table of Y over X the existing files hold is merged with the new
    /// one of the same pair (the existing correction plus the measured one), a CEC table of
    /// another pair is kept as it was, and MD32450 is the sum of the backlashes.
    #[test]
    fn existing_cec_tables_are_merged_or_kept_and_the_backlash_summed() {
        use crate::tables::fixtures::FakeExisting;
        use ballbar_model::{ParamClass, TermClass, Unit};
        let alpha = 40e-6;
        // Existing: Y sent 10e-6·X up over X 0..600 (a 10 µrad squareness corrected), Z sent
        // 5e-6·Y down over Y 0..400, X's backlash 1 µm.
        let ex = FakeExisting {
            kind: "siemens",
            axes: vec![(Axis::X, 0.0, 0.001, [0.0, 600.0])],
            crosses: vec![
                (Axis::X, Axis::Y, [0.0, 600.0], 10e-6),
                (Axis::Y, Axis::Z, [0.0, 400.0], -5e-6),
            ],
        };
        let m = model(&[("SQXY", alpha, 1e-7), ("BX", 0.002, 1e-5)]);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let bx = estimate("BX", BACK, 0.002, 1e-5);
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let (comp, files) = compensate(&m, &[sq, bx], &[circle()], &o).unwrap();
        assert_eq!(files.cec.len(), 2);
        let xy = files.cec.iter().find(|c| (c.input, c.output) == (Axis::X, Axis::Y)).unwrap();
        let (reference, _) = crate::norm(&m, Axis::X);
        // Over the joined span 0..600 mm: 10e-6·X + α (X − reference), the new correction.
        assert!(xy.table.min_mm == 0.0 && xy.table.max_mm() >= 600.0, "{xy:?}");
        // Within 3 nm: the 1 nm rounding, and at 600 mm the last point (600.2 mm, the points
        // 3.016 mm apart) where the existing table holds its end value, 2 nm below its slope.
        for x in [0.0, 200.0, 333.3, 600.0] {
            let want = 10e-6 * x + alpha * (x - reference);
            let got = xy.table.value_mm(x);
            assert!((got - want).abs() < 3e-6, "{x} {got} {want}");
        }
        let yz = files.cec.iter().find(|c| (c.input, c.output) == (Axis::Y, Axis::Z)).unwrap();
        assert!((yz.table.value_mm(300.0) + 5e-6 * 300.0).abs() < 1e-6, "{yz:?}");
        assert!((files.backlash_mm[&Axis::X] - 0.003).abs() < 1e-12);
        let t = comp.terms.iter().find(|t| t.id == "SQXY").unwrap();
        // In the model's convention: 10 µrad was corrected, 50 is, none is left.
        assert!((t.existing.unwrap() - 10.0).abs() < 0.05, "{t:?}");
        assert!((t.written.unwrap() - 50.0).abs() < 0.05, "{t:?}");
        assert!(t.predicted_after.unwrap().abs() < 0.05, "{t:?}");
        let md = files.machine_data_text();
        assert!(md.contains("$SN_CEC_TABLE_ENABLE[1]=1"), "{md}");
    }

    /// Two existing CEC tables of one pair (the NC sums them) are merged as one table over both
    /// spans, not the last one's span alone.
    #[test]
    fn two_existing_cec_tables_of_a_pair_are_merged_over_both_spans() {
        use crate::tables::fixtures::FakeExisting;
        use ballbar_model::{ParamClass, TermClass, Unit};
        let alpha = 40e-6;
        let ex = FakeExisting {
            kind: "siemens",
            axes: vec![],
            crosses: vec![
                (Axis::X, Axis::Y, [0.0, 300.0], 10e-6),
                (Axis::X, Axis::Y, [300.0, 600.0], 20e-6),
            ],
        };
        let m = model(&[("SQXY", alpha, 1e-7)]);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let o = Options { existing_tables: Some(std::sync::Arc::new(ex)), ..Default::default() };
        let (_, files) = compensate(&m, &[sq], &[circle()], &o).unwrap();
        assert_eq!(files.cec.len(), 1);
        let xy = &files.cec[0];
        assert!(xy.table.min_mm == 0.0 && xy.table.max_mm() >= 600.0, "{xy:?}");
        let (reference, _) = crate::norm(&m, Axis::X);
        for x in [50.0f64, 150.0, 450.0] {
            let existing = 10e-6 * x.clamp(0.0, 300.0) + 20e-6 * x.clamp(300.0, 600.0);
            let want = existing + alpha * (x - reference);
            let got = xy.table.value_mm(x);
            // The 1 nm rounding and the points' linear interpolation of a slope: 3 nm.
            assert!((got - want).abs() < 3e-6, "{x} {got} {want}");
        }
    }

    /// A `--travel` of a CEC table's input axis whose end is not above its start is a usage
    /// error naming it, as for an axis's own table, not a note on the term.
    #[test]
    fn a_reversed_travel_of_a_cec_input_is_an_error() {
        use ballbar_model::{ParamClass, TermClass, Unit};
        let m = model(&[("SQXY", 40e-6, 1e-7)]);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), 40e-6, 1e-7)
        };
        let mut options = Options::default();
        options.travel.insert(Axis::X, [400.0, 200.0]);
        let e = compensate(&m, &[sq], &[circle()], &options).unwrap_err();
        assert!(e.contains("--travel X=400:200"), "{e}");
    }

    /// A straightness the machine holds as a translation alone (no tied angle) joins the
    /// squareness in the same table: `-δ_Y(X) = α X - θ (X/L)²`, by hand, and both are left at
    /// 0 after it.
    #[test]
    fn a_straightness_without_a_tied_angle_joins_the_squareness_in_its_table() {
        use ballbar_model::machine::TermSpec;
        use ballbar_model::{ParamClass, TermClass, Unit};
        let (alpha, theta) = (40e-6, 0.003);
        let mut m = model(&[("SQXY", alpha, 1e-7), ("EYX2", theta, 1e-5)]);
        for spec in &mut m.machine.terms {
            if let TermSpec::Straightness { tie_angles, .. } = spec {
                *tie_angles = false;
            }
        }
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), alpha, 1e-7)
        };
        let st = estimate("EYX2", ParamClass::Term(TermClass::Straightness), theta, 1e-5);
        let (comp, files) = compensate(&m, &[sq, st], &[circle()], &Options::default()).unwrap();
        assert_eq!(files.cec.len(), 1);
        let (reference, l) = crate::norm(&m, Axis::X);
        let by_hand = |x: f64| alpha * (x - reference) - theta * ((x - reference) / l).powi(2);
        for x in [200.0, 250.5, 333.3, 400.0] {
            assert!((files.cec[0].table.value_mm(x) - by_hand(x)).abs() < 2e-6, "{x}");
        }
        for t in &comp.terms {
            assert!(t.compensated && t.predicted_after.unwrap().abs() < 0.01, "{t:?}");
        }
    }
}

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
//! more); values in mm to 1 nm. Cross-axis (sag/angularity, CEC `$AN_CEC`) tables, which take a
//! squareness or straightness, are not written by this version.

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

/// What the files set, by axis.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Files {
    /// Machine axis name of each compensated axis (`AX1`).
    pub names: BTreeMap<Axis, String>,
    /// LEC tables.
    pub tables: BTreeMap<Axis, Table>,
    /// MD32450 `$MA_BACKLASH`, mm.
    pub backlash_mm: BTreeMap<Axis, f64>,
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
}

/// Why a term Siemens's axis compensation does not take is not written, and what would.
fn why_not(term: &str) -> String {
    match term {
        "straightness" | "squareness" => "SINUMERIK takes it in a sag/angularity compensation table (CEC, $AN_CEC with $AN_CEC_INPUT_AXIS and $AN_CEC_OUTPUT_AXIS, MD32710 CEC_ENABLE): writing CEC tables is not done by this version".into(),
        "servo_mismatch" => "advice, not a table: match the axes' position-loop gains (MD32200 $MA_POSCTRL_GAIN) so that their lags are equal".into(),
        "reversal_spike" => "advice, not a table: friction/quadrant-error compensation (MD32500 $MA_FRICT_COMP_ENABLE and its parameters)".into(),
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
    let (entries, per_axis, notes) = tables::select(model, estimates, runs, options, &why_not);
    let numbers = tables::axis_numbers(&per_axis, options)?;
    let number = |a: Axis| numbers[&a];
    let mut files = Files::default();
    let mut spans = BTreeMap::new();
    let mut joints = BTreeMap::new();
    for (&axis, c) in &per_axis {
        files.names.insert(axis, format!("AX{}", number(axis)));
        joints.insert(axis.name().to_string(), number(axis) - 1);
        if c.backlash != 0.0 {
            files.backlash_mm.insert(axis, c.backlash);
        }
        if c.positional.is_empty() {
            continue;
        }
        let span = tables::table_span(options, axis, c)?;
        // Points 1 mm apart where MAX_POINTS allow it, the spacing a whole number of µm.
        let step_um = ((span[1] - span[0]) * 1e3 / (MAX_POINTS - 1) as f64).ceil().max(1000.0);
        let step_mm = step_um * 1e-3;
        let n = (((span[1] - span[0]) / step_mm - 1e-9).ceil() as usize + 1).max(2);
        let round = |x: f64| (x * 1e6).round() / 1e6;
        let min_mm = round(span[0]);
        let values_mm = (0..n)
            .map(|k| round(tables::positional_error_mm(c, min_mm + step_mm * k as f64)))
            .collect();
        spans.insert(axis, span);
        files.tables.insert(axis, Table { min_mm, step_mm, values_mm });
    }
    let mut numbers: BTreeMap<String, Axis> = BTreeMap::new();
    for (a, name) in &files.names {
        if let Some(other) = numbers.insert(name.clone(), *a) {
            return Err(format!("--joints: {other} and {a} are both {name}"));
        }
    }
    let comp = tables::finish("siemens", entries, &per_axis, &files, &spans, joints, notes)?;
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
        // Nothing left after the files: the scale and the backlash are predicted at 0.
        for t in comp.terms.iter().filter(|t| t.compensated) {
            assert!(t.predicted_after.unwrap().abs() < 1e-3, "{t:?}");
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
}

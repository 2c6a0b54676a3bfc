//! A SINUMERIK 840D sl's leadscrew error compensation (LEC) and backlash compensation, emulated
//! from the function manual for `simulate --compensation DIR`: *SINUMERIK 840D sl Extended
//! Functions*, K3 "Compensation" (interpolatory compensation: measuring system error
//! compensation; backlash compensation).
//!
//! Written from the manual, independently of the code that writes the files
//! (`ballbar-compensate`):
//! - the files are NC programs / INI files: `;` starts a comment, `%_N_..._INI`, `CHANDATA(n)`
//!   and `M17`/`M30` are accepted and do nothing here; every other line is an assignment
//!   `$VARIABLE[indices]=value`;
//! - `$AA_ENC_COMP[0,N,AXn]` is the value of interpolation point `N` (mm) of machine axis `AXn`,
//!   at `$AA_ENC_COMP_MIN + N·$AA_ENC_COMP_STEP`, up to `$AA_ENC_COMP_MAX`; between points the
//!   value is interpolated linearly, below the first point the first value holds, above `MAX`
//!   the value at `MAX`; values are neither limited nor checked;
//! - the value corrects the actual position value, and a positive value moves the axis in the
//!   negative direction: the axis is sent to `q - value(q)`;
//! - a table acts only with `$MA_ENC_COMP_ENABLE[0,AXn]=1` (MD32700); an axis whose table is
//!   incomplete (a point missing, no step) is an error here, as the NC refuses to activate it;
//! - `$MA_BACKLASH[0,AXn]=B` (MD32450, mm) is applied at each reversal: moving in one direction
//!   the axis is sent `B` further than in the other. The level (which direction carries it)
//!   follows the direction of the reference point approach, which the manual leaves to the
//!   machine; here the axis is referenced moving positive, so moving negative it is sent `B`
//!   lower (a constant offset of the axis otherwise, which a ballbar test does not see).
//!
//! - sag/angularity compensation (CEC, K3 "Compensation of sag and angularity errors"):
//!   `$AN_CEC[t,N]` is the value of point `N` of table `t` (mm), at `$AN_CEC_MIN[t] +
//!   N·$AN_CEC_STEP[t]` of the base axis `$AN_CEC_INPUT_AXIS[t]=(AXi)`, whose setpoint position
//!   indexes it; linear between points, the first point's value below `MIN`, the last's above
//!   `MAX`; it acts on the compensation axis `$AN_CEC_OUTPUT_AXIS[t]=(AXo)` when MD32710
//!   `$MA_CEC_ENABLE[AXo]=1` and SD41300 `$SN_CEC_TABLE_ENABLE[t]=1`, weighted by SD41310
//!   `$SN_CEC_TABLE_WEIGHT[t]` (1 unless set); the tables of one compensation axis are summed.
//!   A direction-dependent (`$AN_CEC_DIRECTION` ≠ 0), multiplied (`$AN_CEC_MULT_BY_TABLE` ≠ 0)
//!   or modulo table is not simulated: an error. MD18342 `$MN_MM_CEC_MAX_POINTS[t]` is
//!   accepted and checked against the points.
//!
//! Assumed: `AX1`, `AX2`, `AX3` are X, Y, Z (the machine axes' order); the names `X1`, `Y1`,
//! `Z1` (MD10000's default names) are taken too. The CEC value's sign, which the manual's text
//! at hand does not state: a correction added to the compensation axis's setpoint (a positive
//! value moves it positive), unlike LEC's.

use std::collections::BTreeMap;

use ballbar_model::Axis;

/// One axis's table as the NC holds it.
#[derive(Clone, Debug, Default, PartialEq)]
struct Lec {
    points: BTreeMap<usize, f64>,
    step: Option<f64>,
    min: Option<f64>,
    max: Option<f64>,
    modulo: bool,
    /// Where the table's first assignment is (`file:line`), for errors about the whole table.
    from: String,
}

/// One CEC table as the NC holds it.
#[derive(Clone, Debug, Default, PartialEq)]
struct Cec {
    points: BTreeMap<usize, f64>,
    input: Option<Axis>,
    output: Option<Axis>,
    step: Option<f64>,
    min: Option<f64>,
    max: Option<f64>,
    enabled: bool,
    weight: Option<f64>,
    max_points: Option<f64>,
    /// Where an unsupported setting was made: `(file, line, what)`.
    unsupported: Option<String>,
    /// Where the table's first `$AN_CEC` or `$SN_CEC` assignment is (`file:line`), for errors
    /// about the whole table.
    from: String,
}

/// An active CEC table: base axis, compensation axis, `(min, step, max, values)`, weight.
type ActiveCec = (Axis, Axis, (f64, f64, f64, Vec<f64>), f64);

/// The compensation of a SINUMERIK's axes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Siemens {
    tables: BTreeMap<Axis, (f64, f64, f64, Vec<f64>)>,
    backlash: BTreeMap<Axis, f64>,
    cec: Vec<ActiveCec>,
}

/// A table's value at `q`: linear between points, the end points' values beyond them (the
/// last point used the one at or below `max`).
fn table_value((min, step, max, v): &(f64, f64, f64, Vec<f64>), q: f64) -> f64 {
    let last = (((max - min) / step + 1e-9).floor() as usize).min(v.len() - 1);
    let x = (q.clamp(*min, *max) - min) / step;
    if x >= last as f64 {
        v[last]
    } else {
        let k = x.floor() as usize;
        v[k] + (x - k as f64) * (v[k + 1] - v[k])
    }
}

fn axis_of(name: &str, file: &str, line: usize) -> Result<Axis, String> {
    let n = name.trim().to_uppercase();
    let axis = match n.as_str() {
        "AX1" | "X1" => Some(Axis::X),
        "AX2" | "Y1" => Some(Axis::Y),
        "AX3" | "Z1" => Some(Axis::Z),
        _ => None,
    };
    axis.ok_or_else(|| format!("{file}:{line}: machine axis '{name}' is not one of the simulator's (AX1..AX3, X1, Y1, Z1)"))
}

impl Siemens {
    /// Read the files (`(name, text)`): errors name the file and line.
    pub fn parse(files: &[(String, String)]) -> Result<Siemens, String> {
        let mut lec: BTreeMap<Axis, Lec> = BTreeMap::new();
        let mut enabled: BTreeMap<Axis, bool> = BTreeMap::new();
        let mut backlash = BTreeMap::new();
        let mut cec: BTreeMap<usize, Cec> = BTreeMap::new();
        let mut cec_enabled: BTreeMap<Axis, bool> = BTreeMap::new();
        for (file, text) in files {
            for (k, raw) in text.lines().enumerate() {
                let line = k + 1;
                let code = raw.split(';').next().unwrap_or("").trim();
                let upper = code.to_uppercase();
                if code.is_empty()
                    || upper.starts_with('%')
                    || upper.starts_with("CHANDATA(")
                    || upper == "M17"
                    || upper == "M30"
                {
                    continue;
                }
                let bad = |what: &str| format!("{file}:{line}: '{code}': {what}");
                let (lhs, value) = code.split_once('=').ok_or_else(|| bad("not an assignment"))?;
                let upper_lhs = lhs.trim().to_uppercase();
                if upper_lhs.starts_with("$AN_CEC")
                    || upper_lhs.starts_with("$SN_CEC")
                    || upper_lhs.starts_with("$MA_CEC")
                    || upper_lhs.starts_with("$MN_MM_CEC")
                {
                    cec_assignment(&upper_lhs, value.trim(), &mut cec, &mut cec_enabled)
                        .map_err(|m| bad(&m))?;
                    if upper_lhs.starts_with("$AN_CEC") || upper_lhs.starts_with("$SN_CEC") {
                        let t = table_index(&upper_lhs).map_err(|m| bad(&m))?;
                        let c = cec.entry(t).or_default();
                        if c.from.is_empty() {
                            c.from = format!("{file}:{line}");
                        }
                    }
                    if upper_lhs.starts_with("$AN_CEC_DIRECTION")
                        || upper_lhs.starts_with("$AN_CEC_MULT_BY_TABLE")
                        || upper_lhs.starts_with("$AN_CEC_IS_MODULO")
                    {
                        let nonzero = value.trim().parse::<f64>() != Ok(0.0);
                        if nonzero {
                            let t = table_index(&upper_lhs).map_err(|m| bad(&m))?;
                            cec.entry(t).or_default().unsupported =
                                Some(format!("{file}:{line}: '{code}'"));
                        }
                    }
                    continue;
                }
                let value: f64 = value
                    .trim()
                    .parse()
                    .ok()
                    .filter(|v: &f64| v.is_finite())
                    .ok_or_else(|| bad("the value is not a number"))?;
                let (var, idx) = lhs
                    .trim()
                    .strip_suffix(']')
                    .and_then(|l| l.split_once('['))
                    .ok_or_else(|| bad("expected $VARIABLE[indices]"))?;
                let idx: Vec<&str> = idx.split(',').map(str::trim).collect();
                let var = var.trim().to_uppercase();
                if idx.first() != Some(&"0") {
                    return Err(bad("only the first measuring system (index 0) is simulated"));
                }
                let axis = axis_of(idx[idx.len() - 1], file, line)?;
                let t = lec.entry(axis).or_default();
                if t.from.is_empty() {
                    t.from = format!("{file}:{line}");
                }
                match (var.as_str(), idx.len()) {
                    ("$AA_ENC_COMP", 3) => {
                        let n: usize =
                            idx[1].parse().map_err(|_| bad("the point number is not a number"))?;
                        t.points.insert(n, value);
                    }
                    ("$AA_ENC_COMP_STEP", 2) => t.step = Some(value),
                    ("$AA_ENC_COMP_MIN", 2) => t.min = Some(value),
                    ("$AA_ENC_COMP_MAX", 2) => t.max = Some(value),
                    ("$AA_ENC_COMP_IS_MODULO", 2) => t.modulo = value != 0.0,
                    ("$MA_ENC_COMP_ENABLE", 2) => {
                        enabled.insert(axis, value != 0.0);
                    }
                    ("$MA_BACKLASH", 2) => {
                        backlash.insert(axis, value);
                    }
                    _ => return Err(bad("not a compensation variable the simulator knows")),
                }
            }
        }
        let mut tables = BTreeMap::new();
        for (axis, t) in lec {
            if !enabled.get(&axis).copied().unwrap_or(false) || t.points.is_empty() {
                continue;
            }
            let (Some(step), Some(min), Some(max)) = (t.step, t.min, t.max) else {
                return Err(format!(
                    "{}: {axis}: the table needs $AA_ENC_COMP_STEP, _MIN and _MAX",
                    t.from
                ));
            };
            if t.modulo {
                return Err(format!("{}: {axis}: a modulo table is for a rotary axis", t.from));
            }
            if !(step > 0.0 && max > min) {
                return Err(format!(
                    "{}: {axis}: the table's step must be positive and MAX above MIN",
                    t.from
                ));
            }
            let values: Vec<f64> = (0..t.points.len())
                .map(|n| {
                    t.points.get(&n).copied().ok_or_else(|| {
                        format!(
                            "{}: {axis}: interpolation point {n} of $AA_ENC_COMP is missing",
                            t.from
                        )
                    })
                })
                .collect::<Result<_, _>>()?;
            tables.insert(axis, (min, step, max, values));
        }
        let mut active = Vec::new();
        for (t, c) in cec {
            let Some(output) = c.output else {
                if c.enabled {
                    return Err(format!(
                        "{}: CEC table {t}: enabled ($SN_CEC_TABLE_ENABLE) without $AN_CEC_OUTPUT_AXIS",
                        c.from
                    ));
                }
                continue;
            };
            if !c.enabled || !cec_enabled.get(&output).copied().unwrap_or(false) {
                continue;
            }
            if let Some(place) = c.unsupported {
                return Err(format!(
                    "{place}: CEC table {t}: a direction-dependent, multiplied or modulo table is not simulated"
                ));
            }
            let (Some(input), Some(step), Some(min), Some(max)) = (c.input, c.step, c.min, c.max)
            else {
                return Err(format!(
                    "{}: CEC table {t}: it needs $AN_CEC_INPUT_AXIS, $AN_CEC_STEP, _MIN and _MAX",
                    c.from
                ));
            };
            if !(step > 0.0 && max > min) || c.points.is_empty() {
                return Err(format!(
                    "{}: CEC table {t}: the step must be positive, MAX above MIN, and a point given",
                    c.from
                ));
            }
            let values: Vec<f64> = (0..c.points.len())
                .map(|n| {
                    c.points.get(&n).copied().ok_or_else(|| {
                        format!(
                            "{}: CEC table {t}: interpolation point {n} of $AN_CEC is missing",
                            c.from
                        )
                    })
                })
                .collect::<Result<_, _>>()?;
            if let Some(m) = c.max_points.filter(|m| (values.len() as f64) > *m) {
                return Err(format!(
                    "{}: CEC table {t}: {} points, more than MD18342 $MN_MM_CEC_MAX_POINTS[{t}] = {m}",
                    c.from,
                    values.len()
                ));
            }
            active.push((input, output, (min, step, max, values), c.weight.unwrap_or(1.0)));
        }
        Ok(Siemens { tables, backlash, cec: active })
    }

    /// Whether `axis` is compensated (by its own table, its backlash or a CEC table).
    pub fn has(&self, axis: Axis) -> bool {
        self.tables.contains_key(&axis)
            || self.backlash.contains_key(&axis)
            || self.cec.iter().any(|c| c.1 == axis)
    }

    /// What the CEC tables add to the setpoint of `output`, mm, at the commanded positions
    /// `commanded[axis.index()]` of the base axes: their weighted values, summed.
    pub fn cross(&self, output: Axis, commanded: &[f64; 6]) -> f64 {
        self.cec
            .iter()
            .filter(|c| c.1 == output)
            .map(|(input, _, table, weight)| weight * table_value(table, commanded[input.index()]))
            .sum()
    }

    /// The span of `axis`'s leadscrew error table, `[MIN, the last point at or below MAX]`,
    /// mm; `None` without one.
    pub fn span(&self, axis: Axis) -> Option<[f64; 2]> {
        self.tables.get(&axis).map(|(min, step, max, v)| {
            let last = (((max - min) / step + 1e-9).floor() as usize).min(v.len() - 1);
            [*min, min + step * last as f64]
        })
    }

    /// The active CEC tables' `(base axis, compensation axis, span)`, span as [`Self::span`].
    pub fn cross_tables(&self) -> Vec<(Axis, Axis, [f64; 2])> {
        self.cec
            .iter()
            .map(|(input, output, (min, step, max, v), _)| {
                let last = (((max - min) / step + 1e-9).floor() as usize).min(v.len() - 1);
                (*input, *output, [*min, min + step * last as f64])
            })
            .collect()
    }

    /// What the CEC tables of base axis `input` add to the setpoint of `output` at `input`'s
    /// position `q`, mm.
    pub fn cross_of(&self, input: Axis, output: Axis, q: f64) -> f64 {
        self.cec
            .iter()
            .filter(|c| c.0 == input && c.1 == output)
            .map(|(_, _, table, weight)| weight * table_value(table, q))
            .sum()
    }

    /// What is added to the commanded position `q` of `axis` moving up or down, mm.
    pub fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        let lec = self.tables.get(&axis).map_or(0.0, |t| -table_value(t, q));
        let b = self.backlash.get(&axis).copied().unwrap_or(0.0);
        lec + if forward { 0.0 } else { -b }
    }
}

/// The table index of a CEC variable `$..._CEC...[t]` or `$AN_CEC[t,N]`.
fn table_index(lhs: &str) -> Result<usize, String> {
    let idx = lhs
        .strip_suffix(']')
        .and_then(|l| l.split_once('['))
        .map(|(_, i)| i)
        .ok_or("expected $VARIABLE[index]")?;
    idx.split(',')
        .next()
        .unwrap_or("")
        .trim()
        .parse()
        .map_err(|_| "the table index is not a number".into())
}

/// One CEC assignment (`lhs` upper case), into the tables and the axes' MD32710.
fn cec_assignment(
    lhs: &str,
    value: &str,
    cec: &mut BTreeMap<usize, Cec>,
    enabled: &mut BTreeMap<Axis, bool>,
) -> Result<(), String> {
    let (var, idx) = lhs
        .strip_suffix(']')
        .and_then(|l| l.split_once('['))
        .ok_or("expected $VARIABLE[indices]")?;
    let idx: Vec<&str> = idx.split(',').map(str::trim).collect();
    let number = || -> Result<f64, String> {
        value
            .parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .ok_or("the value is not a number".into())
    };
    let axis_value = || -> Result<Axis, String> {
        let name =
            value.trim().strip_prefix('(').and_then(|v| v.strip_suffix(')')).unwrap_or(value);
        axis_of(name, "", 0).map_err(|_| {
            format!("machine axis '{name}' is not one of the simulator's (AX1..AX3, X1, Y1, Z1)")
        })
    };
    if var == "$MA_CEC_ENABLE" {
        let axis = axis_of(idx[idx.len() - 1], "", 0).map_err(|_| {
            format!("machine axis '{}' is not one of the simulator's", idx[idx.len() - 1])
        })?;
        enabled.insert(axis, number()? != 0.0);
        return Ok(());
    }
    let t: usize = idx[0].parse().map_err(|_| "the table index is not a number".to_string())?;
    let c = cec.entry(t).or_default();
    match (var, idx.len()) {
        ("$AN_CEC", 2) => {
            let n: usize = idx[1].parse().map_err(|_| "the point number is not a number")?;
            c.points.insert(n, number()?);
        }
        ("$AN_CEC_INPUT_AXIS", 1) => c.input = Some(axis_value()?),
        ("$AN_CEC_OUTPUT_AXIS", 1) => c.output = Some(axis_value()?),
        ("$AN_CEC_STEP", 1) => c.step = Some(number()?),
        ("$AN_CEC_MIN", 1) => c.min = Some(number()?),
        ("$AN_CEC_MAX", 1) => c.max = Some(number()?),
        ("$AN_CEC_DIRECTION" | "$AN_CEC_MULT_BY_TABLE" | "$AN_CEC_IS_MODULO", 1) => {
            number()?;
        }
        ("$SN_CEC_TABLE_ENABLE", 1) => c.enabled = number()? != 0.0,
        ("$SN_CEC_TABLE_WEIGHT", 1) => c.weight = Some(number()?),
        ("$MN_MM_CEC_MAX_POINTS", 1) => c.max_points = Some(number()?),
        _ => return Err("not a compensation variable the simulator knows".into()),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn files(text: &str) -> Vec<(String, String)> {
        vec![("T.INI".to_string(), text.to_string())]
    }

    #[test]
    fn a_positive_value_moves_the_axis_negative_interpolated_and_held_at_the_ends() {
        let s = Siemens::parse(&files(
            "%_N_AX_EEC_INI\n; the manual's example, shortened\nCHANDATA(1)\n$AA_ENC_COMP[0,0,AX1]=0.003 ; +3 µm\n$AA_ENC_COMP[0,1,AX1]=0.01\n$AA_ENC_COMP[0,2,AX1]=0.012\n$AA_ENC_COMP_STEP[0,AX1]=1.0\n$AA_ENC_COMP_MIN[0,AX1]=-200.0\n$AA_ENC_COMP_MAX[0,AX1]=-198.0\n$AA_ENC_COMP_IS_MODULO[0,AX1]=0\n$MA_ENC_COMP_ENABLE[0,AX1]=1\n$MA_BACKLASH[0,Y1]=0.004\nM17\n",
        ))
        .unwrap();
        // +10 µm at -199 mm: the axis is sent 10 µm lower.
        assert!((s.trim(Axis::X, -199.0, true) + 0.010).abs() < 1e-15);
        // Halfway between points 1 and 2: 11 µm.
        assert!((s.trim(Axis::X, -198.5, false) + 0.011).abs() < 1e-15);
        // Beyond the ends: the end values.
        assert_eq!(s.trim(Axis::X, -500.0, true), -0.003);
        assert_eq!(s.trim(Axis::X, 500.0, true), -0.012);
        // Backlash: moving down the axis is sent 4 µm lower than moving up.
        assert_eq!(s.trim(Axis::Y, 7.0, true) - s.trim(Axis::Y, 7.0, false), 0.004);
        assert!(!s.has(Axis::Z));
    }

    #[test]
    fn a_table_not_enabled_does_nothing_and_a_bad_line_names_its_place() {
        let t = "$AA_ENC_COMP[0,0,AX1]=0.003\n$AA_ENC_COMP[0,1,AX1]=0.01\n$AA_ENC_COMP_STEP[0,AX1]=1\n$AA_ENC_COMP_MIN[0,AX1]=0\n$AA_ENC_COMP_MAX[0,AX1]=1\n";
        let s = Siemens::parse(&files(t)).unwrap();
        assert!(!s.has(Axis::X));
        let m = Siemens::parse(&files("$AA_ENC_COMP[0,0,AX1]=3um\n")).unwrap_err();
        assert!(m.starts_with("T.INI:1:"), "{m}");
        let m = Siemens::parse(&files("$AA_ENC_COMP[0,0,AX7]=0\n")).unwrap_err();
        assert!(m.contains("AX7"), "{m}");
        let gap = "$MA_ENC_COMP_ENABLE[0,AX1]=1\n$AA_ENC_COMP[0,0,AX1]=0\n$AA_ENC_COMP[0,2,AX1]=0\n$AA_ENC_COMP_STEP[0,AX1]=1\n$AA_ENC_COMP_MIN[0,AX1]=0\n$AA_ENC_COMP_MAX[0,AX1]=2\n";
        assert!(Siemens::parse(&files(gap)).unwrap_err().contains("point 1"));
    }

    /// The column machine with `errors` (RON map entries) run on an XY circle, CW and CCW,
    /// 100 mm at 1000 mm/min, each axis lagging alike, under the tables `c`.
    fn xy_circles(errors: &str, c: Option<&Siemens>) -> Vec<ballbar_model::Run> {
        let spec = ballbar_model::machines::column();
        let mut truth: crate::Truth = ron::from_str(&format!(
            "(errors: {{{errors}}}, sample_rate_hz: 50.0, started_at: \"2026-11-21T10:00:00Z\", tests: [(plane: XY, directions: [CW, CCW], radius_mm: 100.0, feed_mm_per_min: 1000.0, pivot_mm: (300.0, 200.0, -300.0), tool_ball_mm: (0.0, 0.0, -100.0))])"
        ))
        .unwrap();
        truth.servo = ballbar_model::ServoVariant::AxisLag;
        crate::simulate_controlled(&spec, &ballbar_model::NoKernels, &truth, 0.0, 1, c)
            .unwrap()
            .runs
    }

    #[test]
    fn a_machine_with_its_errors_in_the_tables_reads_the_nominal_circle() {
        // X is 40 ppm long (EXX1 = 10 µm at L = 250 mm) with a 4 µm lost motion; the values that
        // cancel them, by hand from the manual: the error itself, 0.010·X/250 mm (linear: two
        // points suffice), and MD32450 = +0.004 mm.
        let sim = |c: Option<&Siemens>| xy_circles(r#""EXX1": 10.0, "BX": 4.0"#, c);
        let c = Siemens::parse(&files(
            "$AA_ENC_COMP[0,0,AX1]=0\n$AA_ENC_COMP[0,1,AX1]=0.020\n$AA_ENC_COMP_STEP[0,AX1]=500\n$AA_ENC_COMP_MIN[0,AX1]=0\n$AA_ENC_COMP_MAX[0,AX1]=500\n$MA_ENC_COMP_ENABLE[0,AX1]=1\n$MA_BACKLASH[0,AX1]=0.004\n",
        ))
        .unwrap();
        let worst = |runs: &[ballbar_model::Run], offset_x: f64| {
            runs.iter()
                .flat_map(|r| {
                    let x = r.axis(Axis::X).unwrap();
                    // A constant offset of X reads as offset·cos θ, cos θ = (X - 300)/100.
                    r.dr_mm
                        .iter()
                        .zip(x)
                        .map(move |(d, x)| (d - offset_x * (x - 300.0) / 100.0).abs())
                })
                .fold(0.0f64, f64::max)
        };
        assert!(worst(&sim(None), 0.0) > 2e-3);
        // With: X stands 2 µm low in both directions (the backlash's level: referenced moving
        // positive, moving negative it is sent B lower, and the lost motion takes B/2 each
        // way), which moves the circle's centre as a centring does; what is left is second
        // order, 40e-6 × 0.02 mm ≈ 1e-6 mm, and the column rounding (1 nm).
        let with = worst(&sim(Some(&c)), -0.002);
        assert!(with < 2e-6, "{with}");
    }

    /// A CEC table of Y over X whose values are the correction of a squareness by hand from the
    /// manual's semantics (the value added to Y's setpoint at X's setpoint position: `+α X`
    /// cancels `ΔY = -α X`) takes the squareness out of the circle; disabled (SD41300 = 0) it
    /// does nothing; a direction-dependent table is refused, naming its line.
    #[test]
    fn a_cec_table_corrects_the_output_axis_over_the_input_axis() {
        let sim = |c: Option<&Siemens>| xy_circles(r#""SQXY": 40.0"#, c);
        // The largest reading about the circle's own centre and radius (uniform samples over
        // whole turns: the least-squares circle is the mean and twice the cos and sin moments).
        let worst = |runs: &[ballbar_model::Run]| {
            runs.iter()
                .map(|r| {
                    let (x, y) = (r.axis(Axis::X).unwrap(), r.axis(Axis::Y).unwrap());
                    let n = r.len() as f64;
                    let phi: Vec<f64> =
                        x.iter().zip(y).map(|(x, y)| (y - 200.0).atan2(x - 300.0)).collect();
                    let a = r.dr_mm.iter().sum::<f64>() / n;
                    let b =
                        2.0 * r.dr_mm.iter().zip(&phi).map(|(d, p)| d * p.cos()).sum::<f64>() / n;
                    let c =
                        2.0 * r.dr_mm.iter().zip(&phi).map(|(d, p)| d * p.sin()).sum::<f64>() / n;
                    r.dr_mm
                        .iter()
                        .zip(&phi)
                        .map(|(d, p)| (d - a - b * p.cos() - c * p.sin()).abs())
                        .fold(0.0f64, f64::max)
                })
                .fold(0.0f64, f64::max)
        };
        let table = |enable: u8, direction: i8| {
            format!(
                "%_N_NC_CEC_INI\nCHANDATA(1)\n$AN_CEC[0,0]=0\n$AN_CEC[0,1]=0.020\n$AN_CEC_INPUT_AXIS[0]=(AX1)\n$AN_CEC_OUTPUT_AXIS[0]=(AX2)\n$AN_CEC_STEP[0]=500\n$AN_CEC_MIN[0]=0\n$AN_CEC_MAX[0]=500\n$AN_CEC_DIRECTION[0]={direction}\n$MA_CEC_ENABLE[AX2]=1\n$SN_CEC_TABLE_ENABLE[0]={enable}\nM17\n"
            )
        };
        // 40 µrad over R = 100 mm: a shear of ±2 µm about the circle.
        let without = worst(&sim(None));
        assert!(without > 1.5e-3, "{without}");
        let c = Siemens::parse(&files(&table(1, 0))).unwrap();
        assert!(c.has(Axis::Y) && !c.has(Axis::X));
        assert!((c.cross(Axis::Y, &[250.0, 0.0, 0.0, 0.0, 0.0, 0.0]) - 0.010).abs() < 1e-15);
        // What is left: second order (40e-6 × 4 µm) and the sampling: below 0.05 µm.
        let with = worst(&sim(Some(&c)));
        assert!(with < 5e-5, "{with}");
        let off = Siemens::parse(&files(&table(0, 0))).unwrap();
        assert!(!off.has(Axis::Y));
        let m = Siemens::parse(&files(&table(1, 1))).unwrap_err();
        assert!(m.starts_with("T.INI:10:") && m.contains("not simulated"), "{m}");
        // An enabled table without its output axis is refused, not skipped.
        let no_output = table(1, 0).replace("$AN_CEC_OUTPUT_AXIS[0]=(AX2)\n", "");
        let m = Siemens::parse(&files(&no_output)).unwrap_err();
        assert!(m.contains("without $AN_CEC_OUTPUT_AXIS"), "{m}");
    }
}

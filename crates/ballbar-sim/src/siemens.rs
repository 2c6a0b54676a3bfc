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
//! Assumed: `AX1`, `AX2`, `AX3` are X, Y, Z (the machine axes' order); the names `X1`, `Y1`,
//! `Z1` (MD10000's default names) are taken too.

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
}

/// The compensation of a SINUMERIK's axes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Siemens {
    tables: BTreeMap<Axis, (f64, f64, f64, Vec<f64>)>,
    backlash: BTreeMap<Axis, f64>,
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
                return Err(format!("{axis}: the table needs $AA_ENC_COMP_STEP, _MIN and _MAX"));
            };
            if t.modulo {
                return Err(format!("{axis}: a modulo table is for a rotary axis"));
            }
            if !(step > 0.0 && max > min) {
                return Err(format!("{axis}: the table's step must be positive and MAX above MIN"));
            }
            let values: Vec<f64> = (0..t.points.len())
                .map(|n| {
                    t.points.get(&n).copied().ok_or_else(|| {
                        format!("{axis}: interpolation point {n} of $AA_ENC_COMP is missing")
                    })
                })
                .collect::<Result<_, _>>()?;
            tables.insert(axis, (min, step, max, values));
        }
        Ok(Siemens { tables, backlash })
    }

    /// Whether `axis` is compensated.
    pub fn has(&self, axis: Axis) -> bool {
        self.tables.contains_key(&axis) || self.backlash.contains_key(&axis)
    }

    /// What is added to the commanded position `q` of `axis` moving up or down, mm.
    pub fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        let lec = self.tables.get(&axis).map_or(0.0, |(min, step, max, v)| {
            // The table's last point used is the one at or below MAX.
            let last = (((max - min) / step + 1e-9).floor() as usize).min(v.len() - 1);
            let x = (q.clamp(*min, *max) - min) / step;
            let value = if x >= last as f64 {
                v[last]
            } else {
                let k = x.floor() as usize;
                v[k] + (x - k as f64) * (v[k + 1] - v[k])
            };
            -value
        });
        let b = self.backlash.get(&axis).copied().unwrap_or(0.0);
        lec + if forward { 0.0 } else { -b }
    }
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

    #[test]
    fn a_machine_with_its_errors_in_the_tables_reads_the_nominal_circle() {
        // X is 40 ppm long (EXX1 = 10 µm at L = 250 mm) with a 4 µm lost motion; the values that
        // cancel them, by hand from the manual: the error itself, 0.010·X/250 mm (linear: two
        // points suffice), and MD32450 = +0.004 mm.
        let spec = ballbar_model::machines::column();
        let mut truth: crate::Truth = ron::from_str(
            "(errors: {\"EXX1\": 10.0, \"BX\": 4.0}, sample_rate_hz: 50.0, started_at: \"2026-11-21T10:00:00Z\", tests: [(plane: XY, directions: [CW, CCW], radius_mm: 100.0, feed_mm_per_min: 1000.0, pivot_mm: (300.0, 200.0, -300.0), tool_ball_mm: (0.0, 0.0, -100.0))])",
        )
        .unwrap();
        truth.servo = ballbar_model::ServoVariant::AxisLag;
        let sim = |c: Option<&Siemens>| {
            crate::simulate_controlled(&spec, &ballbar_model::NoKernels, &truth, 0.0, 1, c)
                .unwrap()
                .runs
        };
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
}

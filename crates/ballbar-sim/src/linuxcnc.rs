//! A LinuxCNC controller's joint compensation, emulated from LinuxCNC's own code, for
//! `simulate --compensation DIR`: the machine runs with the files active.
//!
//! Written from LinuxCNC's source, independently of the code that writes the files
//! (`ballbar-compensate`): the INI keys are read as `src/emc/ini/inijoint.cc` reads them
//! (`[JOINT_n]` `BACKLASH`, `COMP_FILE`, `COMP_FILE_TYPE`), a compensation file as
//! `usrmotLoadComp()` in `src/emc/motion/usrmotintf.cc` does (lines of three numbers `nominal
//! forward reverse`; reading stops at the first line that is not; type 0 holds the positions
//! reached, so the trims are `nominal - position`, type 1 the trims themselves), and the motion
//! module keeps at most 256 entries, strictly ascending (`src/emc/motion/command.c`,
//! `EMCMOT_SET_JOINT_COMP`: an entry out of order is refused). Each servo cycle
//! `compute_screw_comp()` in `src/emc/motion/control.c` sets the joint's correction
//! `backlash_corr` from the commanded joint velocity `vel_cmd`, the change of the commanded
//! position over the last servo period (`[EMCMOT] SERVO_PERIOD`, ns; 1 ms, the sample
//! configurations' value, when the INI file does not give it): positive, the forward trim;
//! negative, the reverse trim, each interpolated linearly between the entries around the
//! commanded position and held at the end entries outside them (without a table, `±BACKLASH/2`);
//! zero, the correction is left as it was ("not moving, use whatever was there before"), which
//! is 0 until the joint first moves ([`LinuxCnc::servo_cycle`]). A simulated run starts with the
//! machine positioned at its first point, so an axis holds the trim of that positioning move
//! ([`crate::controller::JointTrims::positioned`]) until it moves in the run, or throughout it.
//! `output_to_hal()` adds it to
//! the commanded position. LinuxCNC ramps a change of the trim at half the joint's velocity and
//! acceleration limits; this emulation applies it at once (the limits are the machine's, not in
//! these files: at 0.5 m/s² a 10 µm step takes 9 ms, 0.15 mm of path at 1000 mm/min).
//!
//! Joints map to axes as trivkins does: `[KINS] KINEMATICS = trivkins coordinates=XYZ` makes
//! joint `n` the `n`-th letter; without it, `XYZABCUVW`.

use std::collections::BTreeMap;

use ballbar_model::Axis;

/// One joint's compensation as the motion module holds it.
#[derive(Clone, Debug, PartialEq)]
enum Joint {
    /// `BACKLASH`, mm.
    Backlash(f64),
    /// `(nominal, forward trim, reverse trim)`, ascending, mm.
    Table(Vec<(f64, f64, f64)>),
}

/// LinuxCNC's servo period where the INI file does not give `[EMCMOT] SERVO_PERIOD`: 1 ms,
/// the value of LinuxCNC's sample configurations.
pub const DEFAULT_SERVO_PERIOD_S: f64 = 1e-3;

/// The joint compensation of a LinuxCNC configuration, by axis.
#[derive(Clone, Debug, PartialEq)]
pub struct LinuxCnc {
    joints: BTreeMap<Axis, Joint>,
    /// `[EMCMOT] SERVO_PERIOD`, s.
    servo_period_s: f64,
}

impl LinuxCnc {
    /// Read an INI file's joint compensation; `read` gives a compensation file's text by the
    /// name the INI file gives. Errors name the file and line.
    pub fn parse(
        ini: &str,
        ini_name: &str,
        read: &dyn Fn(&str) -> Result<String, String>,
    ) -> Result<LinuxCnc, String> {
        let mut section = String::new();
        let mut coordinates: Vec<char> = "XYZABCUVW".chars().collect();
        let mut per_joint: BTreeMap<usize, BTreeMap<String, String>> = BTreeMap::new();
        let mut servo_period_s = DEFAULT_SERVO_PERIOD_S;
        for (k, raw) in ini.lines().enumerate() {
            let line = raw.trim();
            if line.starts_with('#') || line.starts_with(';') || line.is_empty() {
                continue;
            }
            if line.starts_with('[') && line.ends_with(']') {
                section = line[1..line.len() - 1].to_string();
                continue;
            }
            let Some((key, value)) = line.split_once('=') else { continue };
            let (key, value) = (key.trim(), value.trim());
            if section == "EMCMOT" && key == "SERVO_PERIOD" {
                servo_period_s = value
                    .parse::<f64>()
                    .ok()
                    .filter(|ns| ns.is_finite() && *ns > 0.0)
                    .ok_or_else(|| {
                        format!(
                            "{ini_name}:{}: [EMCMOT] SERVO_PERIOD = {value}: not a period in ns",
                            k + 1
                        )
                    })?
                    * 1e-9;
            } else if section == "KINS" && key == "KINEMATICS" {
                for word in value.split_whitespace() {
                    if let Some(c) = word.strip_prefix("coordinates=") {
                        coordinates = c.to_uppercase().chars().collect();
                    }
                }
            } else if let Some(n) = section.strip_prefix("JOINT_") {
                let n = n.parse::<usize>().map_err(|_| {
                    format!("{ini_name}:{}: [{section}]: not a joint number", k + 1)
                })?;
                per_joint.entry(n).or_default().insert(key.to_string(), value.to_string());
            }
        }
        let mut joints = BTreeMap::new();
        for (n, keys) in per_joint {
            let letter = coordinates.get(n).copied().ok_or_else(|| {
                format!("{ini_name}: [JOINT_{n}]: the kinematics' coordinates name no joint {n}")
            })?;
            let axis = Axis::from_name(&letter.to_string()).ok_or_else(|| {
                format!(
                    "{ini_name}: [JOINT_{n}] is axis {letter}, which the simulator does not have"
                )
            })?;
            let number = |key: &str| -> Result<Option<f64>, String> {
                keys.get(key)
                    .map(|v| {
                        v.parse::<f64>().map_err(|_| {
                            format!("{ini_name}: [JOINT_{n}] {key} = {v}: not a number")
                        })
                    })
                    .transpose()
            };
            let joint = if let Some(file) = keys.get("COMP_FILE") {
                let kind = number("COMP_FILE_TYPE")?.unwrap_or(0.0);
                let text = read(file)
                    .map_err(|m| format!("{ini_name}: [JOINT_{n}] COMP_FILE {file}: {m}"))?;
                Joint::Table(load_comp(&text, file, kind != 0.0)?)
            } else if let Some(b) = number("BACKLASH")? {
                Joint::Backlash(b)
            } else {
                continue;
            };
            joints.insert(axis, joint);
        }
        Ok(LinuxCnc { joints, servo_period_s })
    }

    /// The servo period, s.
    pub fn servo_period_s(&self) -> f64 {
        self.servo_period_s
    }

    /// One servo cycle of `compute_screw_comp()` for `axis`: the correction after it, from the
    /// commanded position `q`, the commanded velocity's sign (`velocity`, any unit) and the
    /// correction `previous` before it (0 when the joint has not moved yet): the trim of the
    /// direction of motion, or `previous` when the velocity is 0.
    pub fn servo_cycle(&self, axis: Axis, q: f64, velocity: f64, previous: f64) -> f64 {
        if velocity > 0.0 {
            self.trim(axis, q, true)
        } else if velocity < 0.0 {
            self.trim(axis, q, false)
        } else {
            previous
        }
    }

    /// Whether any joint of `axis` is compensated.
    pub fn has(&self, axis: Axis) -> bool {
        self.joints.contains_key(&axis)
    }

    /// The trim added to the commanded position `q` of `axis` moving up (`forward`) or down, mm.
    pub fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        match self.joints.get(&axis) {
            None => 0.0,
            Some(Joint::Backlash(b)) => {
                if forward {
                    b / 2.0
                } else {
                    -b / 2.0
                }
            }
            Some(Joint::Table(t)) => {
                let value = |e: &(f64, f64, f64)| if forward { e.1 } else { e.2 };
                // The motion module's table: the end entries' values beyond them.
                if q <= t[0].0 {
                    return value(&t[0]);
                }
                let last = &t[t.len() - 1];
                if q >= last.0 {
                    return value(last);
                }
                let mut k = 0;
                while t[k + 1].0 <= q {
                    k += 1;
                }
                let (a, b) = (&t[k], &t[k + 1]);
                value(a) + (value(b) - value(a)) * (q - a.0) / (b.0 - a.0)
            }
        }
    }
}

/// A compensation file as LinuxCNC loads it: three numbers a line until the first line that
/// is not; at most 256 entries; an entry not above the previous refused.
fn load_comp(text: &str, name: &str, trims: bool) -> Result<Vec<(f64, f64, f64)>, String> {
    let mut out: Vec<(f64, f64, f64)> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let v: Vec<f64> = line.split_whitespace().map_while(|w| w.parse::<f64>().ok()).collect();
        if v.len() < 3 {
            break;
        }
        let (nom, f, r) = (v[0], v[1], v[2]);
        if out.len() == 256 {
            return Err(format!("{name}:{}: more than 256 entries", k + 1));
        }
        if out.last().is_some_and(|l| nom <= l.0) {
            return Err(format!(
                "{name}:{}: nominal {nom} is not above the previous entry's",
                k + 1
            ));
        }
        out.push(if trims { (nom, f, r) } else { (nom, nom - f, nom - r) });
    }
    if out.is_empty() {
        return Err(format!("{name}: no entry"));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linuxcnc_reads_to_the_first_line_that_is_not_three_numbers_and_holds_the_ends() {
        let ini = "[KINS]\nKINEMATICS = trivkins coordinates=YXZ\n[JOINT_0]\nCOMP_FILE = a.comp\nCOMP_FILE_TYPE = 1\n[JOINT_2]\nBACKLASH = 0.004\n";
        let comp = "0 0.001 -0.001\n10 0.003 0.001\n# the rest is not read\n20 1 1\n";
        let c = LinuxCnc::parse(ini, "m.ini", &|_| Ok(comp.into())).unwrap();
        // Joint 0 is Y here.
        assert!(c.has(Axis::Y) && !c.has(Axis::X));
        assert!((c.trim(Axis::Y, 5.0, true) - 0.002).abs() < 1e-15);
        assert!((c.trim(Axis::Y, 2.5, false) - (-0.0005)).abs() < 1e-15);
        // Past the last entry read (10): held, the line after the comment never read.
        assert_eq!(c.trim(Axis::Y, 30.0, true), 0.003);
        assert_eq!(c.trim(Axis::Y, -5.0, false), -0.001);
        assert_eq!(c.trim(Axis::Z, 0.0, true), 0.002);
        assert_eq!(c.trim(Axis::Z, 0.0, false), -0.002);
        // Type 0: positions reached.
        let ini0 = "[JOINT_0]\nCOMP_FILE = a.comp\n";
        let c0 = LinuxCnc::parse(ini0, "m.ini", &|_| Ok("100 99.998 100.001\n".into())).unwrap();
        assert!((c0.trim(Axis::X, 100.0, true) - 0.002).abs() < 1e-12);
        // Descending: refused, as the motion module refuses it.
        assert!(LinuxCnc::parse(ini0, "m.ini", &|_| Ok("10 0 0\n5 0 0\n".into())).is_err());
        // The servo period: the INI file's, ns, else 1 ms.
        assert_eq!(c0.servo_period_s(), DEFAULT_SERVO_PERIOD_S);
        let p =
            LinuxCnc::parse("[EMCMOT]\nSERVO_PERIOD = 250000\n", "m.ini", &|_| Err(String::new()));
        assert!((p.unwrap().servo_period_s() - 2.5e-4).abs() < 1e-18);
    }

    #[test]
    fn at_rest_the_correction_is_the_last_one_and_zero_before_the_joint_first_moves() {
        let c = LinuxCnc::parse("[JOINT_0]\nBACKLASH = 0.004\n", "m.ini", &|_| Err(String::new()))
            .unwrap();
        // control.c: at rest before any motion, backlash_corr is still its initial 0 (not the
        // forward trim); moving down, -b/2; at rest after it, -b/2 kept; moving up, +b/2.
        let mut corr = 0.0;
        let mut seen = Vec::new();
        for v in [0.0, 0.0, -1.0, -1.0, 0.0, 0.0, 1.0, 0.0] {
            corr = c.servo_cycle(Axis::X, 10.0, v, corr);
            seen.push(corr);
        }
        assert_eq!(seen, [0.0, 0.0, -0.002, -0.002, -0.002, -0.002, 0.002, 0.002]);
    }

    #[test]
    fn a_machine_with_its_errors_trimmed_away_reads_the_nominal_circle() {
        // X is 40 ppm long (EXX1 = 10 µm at L = 250 mm) with a 4 µm backlash; the trims that
        // cancel them, by hand: -0.010·X/250 ± 0.002 (linear: two entries suffice).
        let spec = ballbar_model::machines::column();
        let mut truth: crate::Truth = ron::from_str(
            "(errors: {\"EXX1\": 10.0, \"BX\": 4.0}, sample_rate_hz: 50.0, started_at: \"2026-11-21T10:00:00Z\", tests: [(plane: XY, directions: [CW, CCW], radius_mm: 100.0, feed_mm_per_min: 1000.0, pivot_mm: (300.0, 200.0, -300.0), tool_ball_mm: (0.0, 0.0, -100.0))])",
        )
        .unwrap();
        truth.servo = ballbar_model::ServoVariant::AxisLag;
        let sim = |c: Option<&LinuxCnc>| {
            crate::simulate_controlled(&spec, &ballbar_model::NoKernels, &truth, 0.0, 1, c)
                .unwrap()
                .runs
        };
        let comp = "0 0.002 -0.002\n500 -0.018 -0.022\n";
        let c = LinuxCnc::parse(
            "[JOINT_0]\nCOMP_FILE = x.comp\nCOMP_FILE_TYPE = 1\n",
            "m.ini",
            &|_| Ok(comp.into()),
        )
        .unwrap();
        let worst = |runs: &[ballbar_model::Run]| {
            runs.iter().flat_map(|r| r.dr_mm.iter()).fold(0.0f64, |m, x| m.max(x.abs()))
        };
        // Without: the scale's ellipse and the steps, micrometres.
        assert!(worst(&sim(None)) > 2e-3);
        // With: what is left is second order, the error at the trimmed position against the
        // commanded one, 40e-6 × 0.02 mm ≈ 1e-6 mm, and the column rounding (1 nm).
        assert!(worst(&sim(Some(&c))) < 2e-6, "{}", worst(&sim(Some(&c))));
    }
}

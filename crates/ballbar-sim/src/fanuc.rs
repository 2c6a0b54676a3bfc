//! A FANUC 0i/30i's pitch error compensation and backlash compensation, emulated from its
//! parameter manual for `simulate --compensation DIR`: "Parameters of pitch error compensation"
//! (Nos. 3620-3624), "Parameters of backlash compensation" (No. 1851), and the parameter
//! input/output format.
//!
//! Written from the manual, independently of the code that writes the file
//! (`ballbar-compensate`):
//! - the file is a parameter tape: `%` at its start and end, a block a line (`;` may end it),
//!   text in parentheses skipped (ISO control-out/control-in); `N<no>A<axis>P<value>...` sets an
//!   axis parameter per axis, `N<10000 + n>P<value>` the pitch error data of point `n`;
//! - point `n` holds the change of the compensation across its section, `((n − No.3620 − 1)·d,
//!   (n − No.3620)·d]` of the machine coordinate, `d` = No. 3624 (mm), in detection units times
//!   No. 3623 (the magnification); a value beyond ±7 is refused; the points of an axis run from
//!   No. 3621 to No. 3622, and the compensation at the reference position is 0;
//! - the compensation is a correction added to the axis's position; between points it is that
//!   of the last point passed (the CNC outputs a section's compensation at the point that ends
//!   it), beyond the farthest points it holds;
//! - No. 1851: the backlash in detection units, added at each reversal: moving in one
//!   direction the axis is sent B further than in the other; the level follows the reference
//!   position return's direction (No. 1006#5), taken as positive: moving negative the axis is
//!   sent B lower.
//!
//! Assumed: detection unit 0.001 mm (IS-B); the reference position at machine coordinate 0;
//! axes 1, 2, 3 are X, Y, Z.

use std::collections::BTreeMap;

use ballbar_model::Axis;

/// One axis's compensation as the CNC holds it.
#[derive(Clone, Debug, Default, PartialEq)]
struct AxisParams {
    reference: Option<i64>,
    negative: Option<i64>,
    positive: Option<i64>,
    magnification: Option<i64>,
    interval_mm: Option<f64>,
    backlash: Option<i64>,
}

/// The pitch error and backlash compensation of a FANUC's axes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Fanuc {
    /// Per axis: (reference, most negative, interval mm, the absolute compensation at each
    /// point from the most negative section's start, detection units).
    pitch: BTreeMap<Axis, (i64, i64, f64, Vec<i64>)>,
    backlash: BTreeMap<Axis, i64>,
}

/// The detection unit, mm.
const UNIT_MM: f64 = 0.001;

/// The largest compensation point number read: the pitch error data are `N1xxxx`, four digits
/// (series differ in how many points they have; none has more).
const MAX_POINT: i64 = 9999;

/// The largest magnification, No. 3623 (0 to 100 in the parameter manual).
const MAX_MAGNIFICATION: i64 = 100;

/// A block's code with its comments taken out. A comment runs from control-out `(` to the
/// first control-in `)` (ISO code; the CNC skips what lies between): a `(` inside a comment, a
/// `)` outside one, or a comment left open at the end of the block is an error, as is an
/// end-of-block `;` inside a comment (it would end the block there).
fn without_comments(raw: &str) -> Result<String, &'static str> {
    let mut code = String::new();
    let mut inside = false;
    for ch in raw.chars() {
        match (ch, inside) {
            ('(', false) => inside = true,
            ('(', true) => return Err("a '(' inside a comment (comments do not nest)"),
            (')', true) => inside = false,
            (')', false) => return Err("a ')' with no comment open"),
            (';', true) => return Err("an end of block ';' inside a comment"),
            (_, true) => {}
            (c, false) => code.push(c),
        }
    }
    if inside {
        return Err("a comment not closed by ')' before the end of the block");
    }
    Ok(code)
}

impl Fanuc {
    /// Read a parameter file (`name` for messages).
    pub fn parse(text: &str, name: &str) -> Result<Fanuc, String> {
        let mut params: BTreeMap<usize, AxisParams> = BTreeMap::new();
        let mut data: BTreeMap<i64, i64> = BTreeMap::new();
        for (k, raw) in text.lines().enumerate() {
            let line = k + 1;
            let code = without_comments(raw)
                .map_err(|what| format!("{name}:{line}: '{}': {what}", raw.trim()))?;
            let code = code.trim().trim_end_matches(';').trim().to_uppercase();
            if code.is_empty() || code == "%" {
                continue;
            }
            let bad = |what: &str| format!("{name}:{line}: '{code}': {what}");
            let rest = code.strip_prefix('N').ok_or_else(|| bad("a block starts with N"))?;
            let digits: String = rest.chars().take_while(|c| c.is_ascii_digit()).collect();
            let number: i64 = digits.parse().map_err(|_| bad("no parameter number"))?;
            let rest = &rest[digits.len()..];
            if number >= 10000 {
                let v = rest
                    .strip_prefix('P')
                    .ok_or_else(|| bad("pitch error data is N<no>P<value>"))?;
                let v: i64 = v.parse().map_err(|_| bad("the value is not a whole number"))?;
                if v.abs() > 7 {
                    return Err(bad("a pitch error compensation value is within -7..7"));
                }
                data.insert(number - 10000, v);
                continue;
            }
            // A<axis>P<value>, repeated.
            for field in rest.split('A').skip(1) {
                let (axis, value) =
                    field.split_once('P').ok_or_else(|| bad("expected A<axis>P<value>"))?;
                let axis: usize =
                    axis.parse().map_err(|_| bad("the axis number is not a number"))?;
                let p = params.entry(axis).or_default();
                let int =
                    || value.parse::<i64>().map_err(|_| bad("the value is not a whole number"));
                match number {
                    1851 => p.backlash = Some(int()?),
                    3620 => p.reference = Some(int()?),
                    3621 => p.negative = Some(int()?),
                    3622 => p.positive = Some(int()?),
                    3623 => p.magnification = Some(int()?),
                    3624 => {
                        p.interval_mm = Some(
                            value
                                .parse::<f64>()
                                .ok()
                                .filter(|d| d.is_finite())
                                .ok_or_else(|| bad("the interval is not a number"))?,
                        )
                    }
                    _ => return Err(bad("not a parameter the simulator knows")),
                }
            }
            if !rest.starts_with('A') {
                return Err(bad("expected A<axis>P<value>"));
            }
        }
        let mut out = Fanuc::default();
        for (n, p) in params {
            let axis = match n {
                1 => Axis::X,
                2 => Axis::Y,
                3 => Axis::Z,
                _ => return Err(format!("{name}: axis {n} is not one of the simulator's (1..3)")),
            };
            if let Some(b) = p.backlash {
                out.backlash.insert(axis, b);
            }
            let (Some(r), Some(lo), Some(hi), Some(m), Some(d)) =
                (p.reference, p.negative, p.positive, p.magnification, p.interval_mm)
            else {
                continue;
            };
            if !(lo <= r && r <= hi && d > 0.0) {
                return Err(format!(
                    "{name}: axis {n}: Nos. 3621 <= 3620 <= 3622 and 3624 > 0 are needed"
                ));
            }
            // Compensation point numbers are four digits (the data's N1xxxx) and the
            // magnification (No. 3623) at most 100, the parameter manual's ranges.
            if lo < 0 || hi > MAX_POINT {
                return Err(format!(
                    "{name}: axis {n}: compensation points {lo}..{hi} (Nos. 3621, 3622) outside 0..{MAX_POINT}"
                ));
            }
            if !(0..=MAX_MAGNIFICATION).contains(&m) {
                return Err(format!(
                    "{name}: axis {n}: magnification {m} (No. 3623) outside 0..{MAX_MAGNIFICATION}"
                ));
            }
            // The absolute compensation at the grid points lo - r - 1 ..= hi - r (relative to
            // the reference), 0 at the reference.
            let value = |k: i64| data.get(&k).copied().unwrap_or(0) * m;
            let mut abs = vec![0i64; (hi - lo + 2) as usize];
            let at_ref = (r - lo + 1) as usize;
            for k in at_ref + 1..abs.len() {
                abs[k] = abs[k - 1] + value(lo + k as i64 - 1);
            }
            for k in (0..at_ref).rev() {
                abs[k] = abs[k + 1] - value(lo + k as i64);
            }
            out.pitch.insert(axis, (r, lo, d, abs));
        }
        Ok(out)
    }

    /// Whether `axis` is compensated.
    pub fn has(&self, axis: Axis) -> bool {
        self.pitch.contains_key(&axis) || self.backlash.contains_key(&axis)
    }

    /// The span of `axis`'s pitch error compensation, mm: from the start of its most negative
    /// section to the end of its most positive; `None` without one.
    pub fn span(&self, axis: Axis) -> Option<[f64; 2]> {
        self.pitch.get(&axis).map(|(r, lo, d, abs)| {
            let first = (lo - r - 1) as f64 * d;
            [first, first + (abs.len() - 1) as f64 * d]
        })
    }

    /// What is added to the commanded position `q` of `axis` moving up or down, mm.
    pub fn trim(&self, axis: Axis, q: f64, forward: bool) -> f64 {
        let pitch = self.pitch.get(&axis).map_or(0.0, |(r, lo, d, abs)| {
            // The last grid point passed, as an index into `abs` (grid point lo - r - 1 first).
            let j = (q / d).floor() as i64 - (lo - r - 1);
            abs[j.clamp(0, abs.len() as i64 - 1) as usize] as f64 * UNIT_MM
        });
        let b = self.backlash.get(&axis).copied().unwrap_or(0) as f64 * UNIT_MM;
        pitch + if forward { 0.0 } else { -b }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sections_sum_from_the_reference_and_the_last_point_passed_holds() {
        // The manual's numbering: reference No. 40, farthest 33 and 56, 50 mm apart, values
        // +2 in No. 41 (0..50 mm) and -1 in No. 40 (-50..0 mm), magnification 2.
        let f = Fanuc::parse(
            "%\n(EXAMPLE)\nN01851A2P5;\nN03620A1P40\nN03621A1P33\nN03622A1P56\nN03623A1P2\nN03624A1P50.0\nN10040P-1\nN10041P2\n%\n",
            "F.DAT",
        )
        .unwrap();
        assert_eq!(f.trim(Axis::X, 25.0, true), 0.0);
        assert_eq!(f.trim(Axis::X, 50.0, true), 0.004);
        assert_eq!(f.trim(Axis::X, 999.0, false), 0.004);
        assert_eq!(f.trim(Axis::X, -25.0, true), 0.002);
        assert_eq!(f.trim(Axis::X, -9999.0, true), 0.002);
        // Y: backlash 5 µm, moving down sent 5 µm lower.
        assert_eq!(f.trim(Axis::Y, 3.0, true) - f.trim(Axis::Y, 3.0, false), 0.005);
        assert!(!f.has(Axis::Z));
    }

    #[test]
    fn a_value_beyond_seven_and_a_bad_block_are_refused_naming_the_line() {
        let m = Fanuc::parse("%\nN10003P8\n%\n", "F.DAT").unwrap_err();
        assert!(m.starts_with("F.DAT:2:") && m.contains("-7..7"), "{m}");
        let m = Fanuc::parse("%\nN03620A1PX\n", "F.DAT").unwrap_err();
        assert!(m.starts_with("F.DAT:2:"), "{m}");
        assert!(Fanuc::parse("G01X5\n", "F.DAT").is_err());
    }

    #[test]
    fn ranges_beyond_the_manuals_are_refused() {
        let params = |lo: i64, hi: i64, m: i64, d: &str| {
            format!(
                "%\nN03620A1P{lo}\nN03621A1P{lo}\nN03622A1P{hi}\nN03623A1P{m}\nN03624A1P{d}\n%\n"
            )
        };
        assert!(Fanuc::parse(&params(0, 10, 1, "10"), "F.DAT").is_ok());
        let m = Fanuc::parse(&params(0, 4_000_000_000, 1, "10"), "F.DAT").unwrap_err();
        assert!(m.contains("3622") && m.contains("outside"), "{m}");
        let m = Fanuc::parse(&params(0, 10, 101, "10"), "F.DAT").unwrap_err();
        assert!(m.contains("3623"), "{m}");
        let m = Fanuc::parse(&params(0, 10, 1, "inf"), "F.DAT").unwrap_err();
        assert!(m.starts_with("F.DAT:6:"), "{m}");
    }

    #[test]
    fn a_comment_ends_at_its_first_closing_parenthesis() {
        // Comments taken out, one or two on a line, a block beside them.
        let f = Fanuc::parse("%\n(A)(B)\nN01851A1P4(X AXIS)\n%\n", "F.DAT").unwrap();
        assert_eq!(f.trim(Axis::X, 0.0, true) - f.trim(Axis::X, 0.0, false), 0.004);
        // Nested: the first `)` ends the comment and the rest is code, which the CNC would
        // misread; refused, naming the line.
        for bad in ["(NOS. (3620))", "(OPEN", "CLOSE)", "(IS-B; REFERENCE)"] {
            let m = Fanuc::parse(&format!("%\n{bad}\n%\n"), "F.DAT").unwrap_err();
            assert!(m.starts_with("F.DAT:2:"), "{bad}: {m}");
        }
    }
}

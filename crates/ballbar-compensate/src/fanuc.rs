//! FANUC Series 0i / 30i: pitch error compensation and backlash parameters, as a parameter file
//! in the CNC's parameter input/output format (`FANUC.DAT`), following the *Parameter Manual*
//! (B-64310EN for 0i-D, B-63950EN for 30i), "Parameters of pitch error compensation" (Nos.
//! 3620 to 3624) and "Parameters of backlash compensation" (No. 1851), and the manual's section
//! "Inputting and outputting parameters" for the file's form.
//!
//! - No. 3620: the number of the compensation point of the reference position; 3621 / 3622: the
//!   numbers of the farthest points in the negative / positive direction; 3623: the
//!   magnification (each value is multiplied by it); 3624: the interval between points (mm).
//! - Point `n` holds the change of the compensation across the section `((n − N₃₆₂₀ − 1)·d,
//!   (n − N₃₆₂₀)·d]` of the machine coordinate (the reference position at 0), in detection units
//!   times the magnification: values are *incremental* from point to point, each within
//!   [`MAX_INCREMENT`] (the manual's example: reference at No. 40, stroke −400..+800 mm at 50
//!   mm gives Nos. 33 to 56). The compensation at the reference position is 0.
//! - A compensation value is the amount the CNC adds to the axis's position (a correction, the
//!   crate's trim `-δ`): an axis that goes too far gets negative values.
//! - No. 1851: the backlash in detection units, positive for a lost motion.
//! - The file: `%`, then one block per parameter, `N<number>A<axis>P<value>...` for an axis
//!   parameter and `N<10000 + point>P<value>` for the pitch error data, then `%`.
//!
//! Assumed where the manual available to us did not settle it, stated in the file: the detection
//! unit is 0.001 mm (IS-B); the reference position is at machine coordinate 0 (No. 1240 = 0);
//! the CNC outputs a section's compensation when the axis passes the point that ends it, so that
//! between points the compensation is that of the last point passed (a staircase, not
//! interpolated: interpolated pitch error compensation is an option not assumed); the comment
//! after the leading `%` is in parentheses, ISO code's control-out/control-in, which the CNC
//! skips (a comment ends at its first `)`: none holds a parenthesis or a `;` of its own); the
//! axis numbered `n` (1 for the first) takes the points `128 (n − 1) .. 128 n − 1`.
//!
//! No cross-axis term is written. FANUC's cross-axis function is straightness compensation
//! ([`CROSS_AXIS_MANUAL`]): "moving the tool along an axis (the movement axis, specified with a
//! parameter) compensates another axis (the compensation axis, specified with a parameter)
//! within the range for pitch error compensation for the movement axis", in detection units, at
//! four compensation points a, b, c, d of the movement axis ("same as the numbers of the pitch
//! error compensation points") with compensation values α, β, γ, ε. The parameter numbers that
//! hold them, their units, ranges and magnification were not in the manual text available, so a
//! squareness or straightness is listed as not written, naming the section. Inclination
//! compensation (four points of an axis's own pitch error compensation, added to it) corrects
//! an axis's own position, which the pitch error data already take, and cannot hold a
//! squareness.

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::{Axis, Run};

use crate::tables::{self, ControllerFiles};
use crate::{Compensation, Estimate, Options};

/// The manual section that describes FANUC's cross-axis compensation, which this writer does
/// not use (its parameters were not found): the terms it would take say so.
pub const CROSS_AXIS_MANUAL: &str =
    "FANUC Series 16i/18i/160i/180i Descriptions (B-63522EN/02) 15.5 Straightness compensation";

/// The manual sections the file follows.
pub const MANUAL: &str = "FANUC Series 0i/30i Parameter Manual: Parameters of pitch error compensation (Nos. 3620-3624), Parameters of backlash compensation (No. 1851), Inputting and outputting parameters";

/// The file's name.
pub const FILE: &str = "FANUC.DAT";

/// The detection unit, mm (IS-B).
pub const DETECTION_UNIT_MM: f64 = 0.001;

/// The largest value of a point, in units of the magnification.
pub const MAX_INCREMENT: i64 = 7;

/// The points of one axis: at most this many sections.
pub const POINTS_PER_AXIS: i64 = 128;

/// The largest magnification (No. 3623).
pub const MAX_MAGNIFICATION: i64 = 100;

/// One axis's pitch error compensation.
#[derive(Clone, Debug, PartialEq)]
pub struct Pitch {
    /// No. 3620.
    pub reference: i64,
    /// No. 3621.
    pub most_negative: i64,
    /// No. 3622.
    pub most_positive: i64,
    /// No. 3623.
    pub magnification: i64,
    /// No. 3624, mm.
    pub interval_mm: f64,
    /// The values of points `most_negative ..= most_positive`, each within ±[`MAX_INCREMENT`].
    pub values: Vec<i64>,
}

impl Pitch {
    /// The compensation at the grid point `j` intervals from the reference position, detection
    /// units: the sum of the sections' values from the reference to it.
    pub fn absolute_at(&self, j: i64) -> i64 {
        let v = |n: i64| self.values[(n - self.most_negative) as usize] * self.magnification;
        let r = self.reference;
        if j >= 0 {
            (r + 1..=(r + j).min(self.most_positive)).map(v).sum()
        } else {
            -(((r + j + 1).max(self.most_negative))..=r).map(v).sum::<i64>()
        }
    }

    /// The compensation the CNC adds at machine coordinate `q` (mm): that of the last point
    /// passed, held beyond the farthest points.
    pub fn compensation_mm(&self, q: f64) -> f64 {
        let j = (q / self.interval_mm).floor() as i64;
        let j =
            j.clamp(self.most_negative - self.reference - 1, self.most_positive - self.reference);
        self.absolute_at(j) as f64 * DETECTION_UNIT_MM
    }
}

/// What the file sets, by axis.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Files {
    /// The CNC's axis number of each compensated axis (`A1`).
    pub numbers: BTreeMap<Axis, usize>,
    /// Pitch error compensation.
    pub pitch: BTreeMap<Axis, Pitch>,
    /// No. 1851, detection units.
    pub backlash: BTreeMap<Axis, i64>,
}

impl Files {
    /// `FANUC.DAT`.
    pub fn text(&self) -> String {
        let mut s = String::from("%\n");
        s.push_str(&comment(&format!("ballbar compensate: {MANUAL}")));
        s.push_str(&comment("detection unit 0.001 mm, IS-B, reference position at machine coordinate 0, No. 1240 = 0"));
        s.push_str(&comment(
            "pitch error data incremental per section, a correction: added to the position",
        ));
        let axis_param = |s: &mut String, no: u32, value: &dyn Fn(Axis) -> Option<String>| {
            let fields: String = self
                .numbers
                .iter()
                .filter_map(|(a, n)| value(*a).map(|v| format!("A{n}P{v}")))
                .collect();
            if !fields.is_empty() {
                s.push_str(&format!("N{no:05}{fields}\n"));
            }
        };
        axis_param(&mut s, 1851, &|a| self.backlash.get(&a).map(|b| b.to_string()));
        axis_param(&mut s, 3620, &|a| self.pitch.get(&a).map(|p| p.reference.to_string()));
        axis_param(&mut s, 3621, &|a| self.pitch.get(&a).map(|p| p.most_negative.to_string()));
        axis_param(&mut s, 3622, &|a| self.pitch.get(&a).map(|p| p.most_positive.to_string()));
        axis_param(&mut s, 3623, &|a| self.pitch.get(&a).map(|p| p.magnification.to_string()));
        axis_param(&mut s, 3624, &|a| self.pitch.get(&a).map(|p| format!("{:.3}", p.interval_mm)));
        for p in self.pitch.values() {
            for (k, v) in p.values.iter().enumerate() {
                s.push_str(&format!("N{}P{v}\n", 10000 + p.most_negative + k as i64));
            }
        }
        s.push_str("%\n");
        s
    }
}

/// `text` as a comment line of the file: upper case between control-out `(` and control-in
/// `)`. A comment ends at the first `)`, and neither `(` nor the end-of-block `;` may stand
/// inside it, so a parenthesis of the text becomes a comma or nothing and a `;` a comma.
fn comment(text: &str) -> String {
    let inner = text.replace(" (", ", ").replace(['(', ';'], ",").replace(')', "");
    format!("({})\n", inner.to_uppercase())
}

impl ControllerFiles for Files {
    fn texts(&self) -> Vec<(String, String)> {
        vec![(FILE.to_string(), self.text())]
    }

    /// The pitch error compensation, and the backlash `±B/2` (its level, which follows the
    /// reference position return's direction, is a constant offset of the axis).
    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64 {
        let pitch = self.pitch.get(&axis).map_or(0.0, |p| p.compensation_mm(q_mm));
        let b = self.backlash.get(&axis).copied().unwrap_or(0) as f64 * DETECTION_UNIT_MM;
        pitch + if forward { 0.5 * b } else { -0.5 * b }
    }

    fn has(&self, axis: Axis) -> bool {
        self.numbers.contains_key(&axis)
    }

    fn files_of(&self, _axis: Axis, _term: &str) -> Vec<String> {
        vec![FILE.to_string()]
    }

    /// The detection unit: the position loop's own step, which the re-measured machine follows
    /// only to within one unit whatever the tables hold. The pitch table's coarser step (the
    /// magnification times the unit) is in the prediction already, rounded as the files are.
    fn resolution_mm(&self) -> f64 {
        DETECTION_UNIT_MM
    }
}

/// Why a term FANUC's axis compensation does not take is not written, and what would.
fn why_not(term: &str) -> String {
    match term {
        "straightness" | "squareness" => format!(
            "FANUC takes it in straightness compensation ({CROSS_AXIS_MANUAL}: a movement axis's position corrects a compensation axis, at four of the movement axis's pitch error compensation points); its parameter numbers were not found in the manual text available to this version, so it is not written"
        ),
        "servo_mismatch" => "advice, not a table: match the axes' position gains (No. 1825, servo loop gain in 0.01/s: Kv in 1/s is a hundredth of it) so that their lags are equal".into(),
        "reversal_spike" => "advice, not a table: backlash acceleration / quadrant protrusion compensation (Nos. 2048, 2071 and the servo tuning; their units are the servo parameter manual's, which this version does not have: the amount below is in µm, ms and mm/min, not converted)".into(),
        "rotary_location" => "correct the rotary axis's location (ISO 230-7) in the five-axis machining parameters (tool centre point control); not written".into(),
        _ => "FANUC's axis compensation does not take this term".into(),
    }
}

/// The pitch error compensation of an axis over `span` (mm) for an error `delta(q)` (mm,
/// actual minus commanded): the correction `-δ` at each point, in detection units, quantised
/// as a whole (the rounding does not accumulate), held outside `span`; the interval the
/// smallest whole mm that keeps the sections from the reference position to both ends within
/// [`POINTS_PER_AXIS`] (at least 1 mm: No. 3624's least is the fastest feed / 7500), the magnification the smallest that keeps every value within
/// ±[`MAX_INCREMENT`]. `first` is the axis's first point number.
pub fn pitch_table(
    span: [f64; 2],
    delta: &dyn Fn(f64) -> f64,
    first: i64,
) -> Result<Pitch, String> {
    let (lo, hi) = (span[0].min(0.0), span[1].max(0.0));
    // Each end may add a part section: 3 short of the points keeps the whole within them.
    let interval_mm = ((hi - lo) / (POINTS_PER_AXIS - 3) as f64).ceil().max(1.0);
    let s_neg = (-lo / interval_mm - 1e-9).ceil().max(0.0) as i64;
    let s_pos = (hi / interval_mm - 1e-9).ceil().max(0.0) as i64;
    // The section ending at a point holds from it to the next: the correction there is taken
    // at the section's middle (half an interval up), the staircase's best fit.
    let target = |j: i64| -> f64 {
        let q = ((j as f64 + 0.5) * interval_mm).clamp(span[0], span[1]);
        let q0 = (0.5 * interval_mm).clamp(span[0], span[1]);
        -(delta(q) - delta(q0)) / DETECTION_UNIT_MM
    };
    let reference = first + s_neg.max(1) - 1;
    let most_negative = first;
    let most_positive = reference + s_pos;
    for magnification in 1..=MAX_MAGNIFICATION {
        let quantised = |j: i64| (target(j) / magnification as f64).round() as i64;
        let values: Vec<i64> = (most_negative..=most_positive)
            .map(|n| {
                // Point n: the section from grid point j - 1 to j, j = n - reference.
                let j = n - reference;
                quantised(j) - quantised(j - 1)
            })
            .collect();
        if values.iter().all(|v| v.abs() <= MAX_INCREMENT) {
            return Ok(Pitch {
                reference,
                most_negative,
                most_positive,
                magnification,
                interval_mm,
                values,
            });
        }
    }
    Err(format!(
        "a pitch error over {}..{} mm needs more than {MAX_INCREMENT} × {MAX_MAGNIFICATION} detection units per {interval_mm} mm interval",
        span[0], span[1]
    ))
}

/// The FANUC parameter file for a model, and `compensation.json` without its predictions.
pub fn compensate(
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
) -> Result<(Compensation, Files), String> {
    crate::check_travel(options)?;
    let (entries, per_axis, mut notes) = tables::select(model, estimates, runs, options, &why_not);
    let existing = options.existing_tables.as_deref();
    let axes = tables::merged_axes(&per_axis, existing);
    let numbers = tables::axis_numbers(axes.iter().copied(), options)?;
    let number = |a: Axis| numbers[&a];
    let mut files = Files::default();
    let mut spans = BTreeMap::new();
    let mut joints = BTreeMap::new();
    for &axis in &axes {
        let c = per_axis.get(&axis);
        let n = number(axis);
        if files.numbers.values().any(|m| *m == n) {
            return Err(format!("--joints: two axes are both axis {n}"));
        }
        files.numbers.insert(axis, n);
        joints.insert(axis.name().to_string(), n - 1);
        // No. 1851 as the CNC applies it: moving negative the axis is sent B lower.
        let existing_backlash = tables::existing_trim(options, axis, 0.0, true)
            - tables::existing_trim(options, axis, 0.0, false);
        let backlash = c.map_or(0.0, |c| c.backlash) + existing_backlash;
        if backlash != 0.0 {
            let b = (backlash / DETECTION_UNIT_MM).round() as i64;
            if b.abs() > 9999 {
                return Err(format!(
                    "{axis}: a backlash of {b} detection units is beyond No. 1851's ±9999"
                ));
            }
            files.backlash.insert(axis, b);
            if files.backlash.len() == 1 {
                notes.push(
                    "No. 1852 (rapid traverse backlash) is not written: it acts only where No. 1800's RBK bit separates the cutting feed's and rapid traverse's backlash, and a ballbar test measures at one cutting feed; with RBK set, measure at rapid traverse for No. 1852, or set it equal to No. 1851 knowing that the lost motion may differ at rapid traverse".into(),
                );
            }
            if b == 0 {
                notes.push(format!(
                    "{axis}: the backlash is below half the detection unit (0.001 mm): No. 1851 is 0"
                ));
            }
        }
        let Some(span) = tables::merged_span(options, axis, c, false)? else { continue };
        let first = (n as i64 - 1) * POINTS_PER_AXIS;
        // The existing pitch error compensation (the correction it adds moving positive, so
        // minus the error it cancels) plus the measured error.
        let delta = |q: f64| {
            -tables::existing_trim(options, axis, q, true)
                + c.map_or(0.0, |c| tables::positional_error_mm(c, q))
        };
        let pitch = pitch_table(span, &delta, first).map_err(|m| format!("{axis}: {m}"))?;
        if c.is_some_and(|c| !c.positional.is_empty()) {
            spans.insert(axis, span);
        }
        files.pitch.insert(axis, pitch);
    }
    let comp = tables::finish(
        "fanuc",
        entries,
        &per_axis,
        tables::Written {
            model,
            files: &files,
            spans: &spans,
            crosses: &BTreeMap::new(),
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
    fn the_manuals_example_numbers_its_points_and_sums_its_sections() {
        // The manual's example: reference position at No. 40, stroke -400..+800 mm, 50 mm
        // apart: the farthest points are 40 - 400/50 + 1 = 33 and 40 + 800/50 = 56. Here with a
        // zero error: 1200 mm in at most 125 sections (128 points, less a part section at each
        // end and the reference's): 10 mm apart (the smallest whole mm).
        let p = pitch_table([-400.0, 800.0], &|_| 0.0, 0).unwrap();
        assert_eq!(p.interval_mm, 10.0);
        assert_eq!((p.most_negative, p.reference, p.most_positive), (0, 39, 119));
        assert_eq!(p.values.len(), 120);
        // Hand-made values: +2 in the section just above the reference, -1 just below.
        let mut q = p.clone();
        q.values = vec![0; 120];
        q.values[40] = 2; // No. 40: the section 0..10 mm
        q.values[39] = -1; // No. 39 (the reference's): the section -10..0 mm
        assert_eq!(q.absolute_at(1), 2);
        assert_eq!(q.absolute_at(5), 2);
        assert_eq!(q.absolute_at(-1), 1);
        // Between points: the last one passed, held beyond the farthest.
        assert_eq!(q.compensation_mm(5.0), 0.0);
        assert_eq!(q.compensation_mm(10.0), 0.002);
        assert_eq!(q.compensation_mm(-5.0), 0.001);
        assert_eq!(q.compensation_mm(5000.0), 0.002);
    }

    #[test]
    fn values_are_increments_within_seven_and_a_steep_error_raises_the_magnification() {
        // X goes 40 ppm too far (δ = 40e-6·q): the correction falls 0.4 µm per 10 mm; with
        // whole µm it steps -1 every 2.5 intervals on average, never more than 1 per point.
        let p = pitch_table([0.0, 1000.0], &|q| 40e-6 * q, 0).unwrap();
        assert_eq!((p.interval_mm, p.magnification), (8.0, 1));
        assert!(p.values.iter().all(|v| (-1..=0).contains(v)), "{:?}", p.values);
        // The whole: -40 µm over 1000 mm, to the half µm of the rounding.
        let end = p.absolute_at(p.most_positive - p.reference) as f64;
        assert!((end - (-40e-3 * (p.most_positive - p.reference) as f64 * 8.0)).abs() <= 1.0);
        // 2000 ppm: 16 µm per 8 mm interval, beyond 7: magnification 3 (16/3 = 5.3 per point).
        let p = pitch_table([0.0, 1000.0], &|q| 2e-3 * q, 0).unwrap();
        assert_eq!(p.magnification, 3);
        assert!(p.values.iter().all(|v| v.abs() <= MAX_INCREMENT));
        // 1 mm per mm is beyond every magnification: refused.
        assert!(pitch_table([0.0, 1000.0], &|q| q, 0).is_err());
    }

    #[test]
    fn the_file_is_fanucs_parameter_format_and_the_correction_is_minus_the_error() {
        // EXX1 = 10 µm at L = 250 mm (40 ppm too far), BX = 3.6 µm: No. 1851 = 4.
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.0036, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.0036, 1e-5)];
        let (comp, files) = compensate(&m, &est, &[circle()], &Options::default()).unwrap();
        let text = files.text();
        assert!(text.starts_with("%\n(BALLBAR COMPENSATE: FANUC") && text.ends_with("\n%\n"));
        assert!(text.contains("\nN01851A1P4\n"), "{text}");
        // X spans 200..400 mm from the reference at 0: 4 mm apart (400/125 rounded up).
        assert!(
            text.contains("\nN03620A1P0\nN03621A1P0\nN03622A1P100\nN03623A1P1\nN03624A1P4.000\n"),
            "{text}"
        );
        let p = &files.pitch[&Axis::X];
        // The correction between 200 and 400 mm: -40 ppm × 200 mm = -8 µm, to a µm.
        let d = p.compensation_mm(400.0) - p.compensation_mm(200.0);
        assert!((d + 0.008).abs() <= 0.001 + 1e-12, "{d}");
        assert!(text.contains("\nN10000P0\n"));
        // Below the tests' span nothing changes: the values there are 0.
        assert!(p.values[..50].iter().all(|v| *v == 0));
        // No. 1852 is not written, and a note says why.
        assert!(!text.contains("N01852"));
        assert!(
            comp.notes
                .iter()
                .any(|n| n.starts_with("No. 1852 (rapid traverse backlash) is not written"))
        );
        // The prediction carries the rounding: the backlash is left at 3.6 - 4 = -0.4 µm.
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!((bx.predicted_after.unwrap() + 0.4).abs() < 1e-9, "{bx:?}");
    }

    /// A squareness and a straightness are listed as not written, naming FANUC's cross-axis
    /// section (whose parameters were not found), and the file holds only the axis tables.
    #[test]
    fn a_squareness_and_a_straightness_are_not_written_and_say_which_section_would_take_them() {
        use ballbar_model::{ParamClass, TermClass, Unit};
        let m = model(&[("EXX1", 0.010, 1e-5), ("SQXY", 40e-6, 1e-7), ("EYX2", 0.003, 1e-5)]);
        let sq = Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), 40e-6, 1e-7)
        };
        let st = estimate("EYX2", ParamClass::Term(TermClass::Straightness), 0.003, 1e-5);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), sq, st];
        let (comp, files) = compensate(&m, &est, &[circle()], &Options::default()).unwrap();
        for id in ["SQXY", "EYX2"] {
            let t = comp.terms.iter().find(|t| t.id == id).unwrap();
            assert!(!t.compensated, "{t:?}");
            let why = t.why.as_deref().unwrap();
            assert!(why.contains("B-63522EN/02) 15.5 Straightness compensation"), "{why}");
            assert!(why.contains("not written"), "{why}");
        }
        // Only X's pitch error data and its parameters: no block of Y's points (128..255).
        let text = files.text();
        assert!(text.contains("\nN10000P0\n"), "{text}");
        assert!(!text.contains("\nN10128P"), "{text}");
    }

    /// `verify` compares within the detection unit: a FANUC's backlash can be corrected only to
    /// a whole µm, so a re-measured value 0.7 µm off the prediction is `corrected` here, where
    /// LinuxCNC's 0.1 nm trims would call it `overshot`.
    #[test]
    fn verify_compares_within_the_detection_unit() {
        let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.0036, 1e-5)]);
        let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.0036, 1e-5)];
        let (comp, _) = compensate(&m, &est, &[circle()], &Options::default()).unwrap();
        assert_eq!(comp.resolution_mm, Some(DETECTION_UNIT_MM));
        // A document without the field is read with its controller's.
        let old = Compensation { resolution_mm: None, ..comp.clone() };
        assert_eq!(old.resolution(), DETECTION_UNIT_MM);
        let bx = comp.terms.iter().find(|t| t.id == "BX").unwrap();
        assert!((bx.resolution(comp.resolution()) - 1.0).abs() < 1e-12);
        // The scale's: 1 µm over the measured 200 mm (to the samples' spacing) is 5 ppm.
        let sx = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
        assert!((sx.resolution(comp.resolution()) - 5.0).abs() < 1e-3);
        let (b, p) = (3.6, bx.predicted_after.unwrap());
        let fanuc =
            crate::verify::verdict(true, (b, p, p + 0.7), 0.01, bx.resolution(comp.resolution()));
        assert_eq!(fanuc.0, "corrected");
        let linuxcnc = crate::verify::verdict(
            true,
            (b, p, p + 0.7),
            0.01,
            bx.resolution(crate::resolution_of("linuxcnc")),
        );
        assert_ne!(linuxcnc.0, "corrected");
    }
}

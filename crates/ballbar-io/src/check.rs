//! The checks that make a [`Run`] valid, written once for every way in: the run-CSV reader
//! ([`crate::csv::parse_run`]), the plain-table importer ([`crate::table::parse_table`]) and the
//! vendor importers all end with [`check_run`].
//!
//! A reader keeps the errors that are parse errors (a field that is not a number, a line with
//! the wrong number of fields) where it parses; what is wrong with the values themselves is
//! found here, with the same messages whichever format the run came from. Errors name
//! `run.source` and the sample's line (`run.lines[i]`).

use std::path::PathBuf;

use ballbar_model::{Axis, Plane, Run};

use crate::IoError;

/// Largest allowed difference between `radius_mm` and the distance of a sample's axis
/// coordinates from `pivot_mm`, mm (the spec's 1 mm).
pub const RADIUS_TOLERANCE_MM: f64 = 1.0;

/// Fewest samples a run may have.
pub const MIN_SAMPLES: usize = 3;

/// Largest reading, as a fraction of the bar's nominal length `radius_mm`. A ballbar's travel
/// is about ±1 mm, so a reading of a tenth of the bar (15 mm on a 150 mm bar) is not a
/// deviation: it is a length written for a deviation (which is as large as the bar), a wrong
/// unit or a damaged number. Bounding it also keeps the fit's sums of squares finite: a
/// reading of 1e300 µm made them overflow into NaN.
pub const MAX_READING_FRACTION: f64 = 0.1;

/// A value for a message: as it reads in a file, in e-notation when its digits would not fit
/// on a line.
pub(crate) fn shown(v: f64) -> String {
    if v.abs() < 1e9 { v.to_string() } else { format!("{v:e}") }
}

/// Check a run from any format: set-up, columns and samples.
///
/// - the set-up ([`IoError::Setup`]): `radius_mm` and `feed_mm_per_min` positive and finite,
///   `pivot_mm`, `table_ball_mm` and `tool_ball_mm` finite; a planar run has a `direction` and
///   the columns of its two in-plane axes;
/// - the columns have equal lengths: `t_s`, every axis present, `dr_mm` and `lines` (one line
///   number per sample) ([`IoError::Format`]);
/// - sample by sample, in order: every value finite ([`IoError::Sample`]), the reading within
///   [`MAX_READING_FRACTION`] of `radius_mm` ([`IoError::Sample`]), `t_s` strictly increasing
///   ([`IoError::Sample`]), and for a planar run the axis coordinates (X, Y, Z; an
///   axis the run does not have sits at the pivot) within [`RADIUS_TOLERANCE_MM`] of `radius_mm`
///   from `pivot_mm` ([`IoError::Radius`]);
/// - at least [`MIN_SAMPLES`] samples ([`IoError::Format`], at the last sample's line).
///
/// Errors name `run.source` and the 1-based line of the sample (`run.lines[i]`). The first
/// problem found is returned.
pub fn check_run(run: &Run) -> Result<(), IoError> {
    let last_line = run.lines.last().map_or(1, |&l| l as usize);
    check_run_ending_at(run, last_line)
}

/// [`check_run`], with the line that a count error names: the last line of the source (for a
/// file with no sample, the line where the samples would start). For readers that know it.
pub(crate) fn check_run_ending_at(run: &Run, last_line: usize) -> Result<(), IoError> {
    let path = || PathBuf::from(&run.source);
    let setup =
        |key: &str, message: String| IoError::Setup { path: path(), key: key.to_string(), message };
    let h = &run.header;

    // The set-up.
    for (key, v) in [("radius_mm", h.radius_mm), ("feed_mm_per_min", h.feed_mm_per_min)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(setup(key, format!("{v} is not a positive number")));
        }
    }
    for (key, p) in [
        ("pivot_mm", h.pivot_mm),
        ("table_ball_mm", h.table_ball_mm),
        ("tool_ball_mm", h.tool_ball_mm),
    ] {
        if p.iter().any(|c| !c.is_finite()) {
            return Err(setup(
                key,
                format!("({}, {}, {}) is not three finite numbers", p[0], p[1], p[2]),
            ));
        }
    }
    if let Some((u, v, _)) = h.plane.axes() {
        if h.direction.is_none() {
            return Err(setup(
                "direction",
                format!("a test in plane {} needs a direction (CW or CCW)", h.plane),
            ));
        }
        for a in [u, v] {
            if run.axis(a).is_none() {
                return Err(setup(
                    "plane",
                    format!("a test in plane {} needs the column {}", h.plane, a.column_name()),
                ));
            }
        }
    }

    // Columns of equal length: every column as long as t_s, one line number per sample.
    let n = run.len();
    let line_at = |i: usize| run.lines.get(i).map_or(last_line, |&l| l as usize);
    let columns = Axis::ALL
        .into_iter()
        .filter_map(|a| run.axis(a).map(|c| (a.column_name(), c.len())))
        .chain([("dR_um", run.dr_mm.len()), ("line numbers", run.lines.len())]);
    for (name, len) in columns {
        if len != n {
            return Err(IoError::Format {
                path: path(),
                line: line_at(len.min(n)),
                message: format!("column {name} has {len} values but t_s has {n}"),
            });
        }
    }

    // Samples, in order.
    let sample = |line: usize, column: &str, message: String| IoError::Sample {
        path: path(),
        line,
        column: column.to_string(),
        message,
    };
    let not_finite = |v: f64| format!("{:?} is not a finite number", v.to_string());
    let present: Vec<(Axis, &[f64])> =
        Axis::ALL.into_iter().filter_map(|a| run.axis(a).map(|c| (a, c))).collect();
    let pivot = h.pivot_mm;
    for i in 0..n {
        let line = line_at(i);
        let t = run.t_s[i];
        if !t.is_finite() {
            return Err(sample(line, "t_s", not_finite(t)));
        }
        let mut xyz = pivot; // an axis the run does not have sits at the pivot
        for &(a, column) in &present {
            let v = column[i];
            if !v.is_finite() {
                return Err(sample(line, a.column_name(), not_finite(v)));
            }
            if !a.is_rotary() {
                xyz[a.index()] = v;
            }
        }
        let dr_mm = run.dr_mm[i];
        if !dr_mm.is_finite() {
            return Err(sample(line, "dR_um", not_finite(dr_mm)));
        }
        if dr_mm.abs() > MAX_READING_FRACTION * h.radius_mm {
            let message = format!(
                "{} µm is not a ballbar reading: it is more than a tenth of the bar's length \
                 ({} mm), where a ballbar's travel is about ±1 mm (a length written for the \
                 deviation, a wrong unit or a damaged number?)",
                shown(dr_mm * 1e3),
                h.radius_mm
            );
            return Err(sample(line, "dR_um", message));
        }
        if i > 0 && t <= run.t_s[i - 1] {
            let message = format!(
                "{t} does not increase: the sample before (line {}) has {}",
                line_at(i - 1),
                run.t_s[i - 1]
            );
            return Err(sample(line, "t_s", message));
        }
        if h.plane != Plane::Free {
            let d = ((xyz[0] - pivot[0]).powi(2)
                + (xyz[1] - pivot[1]).powi(2)
                + (xyz[2] - pivot[2]).powi(2))
            .sqrt();
            if (d - h.radius_mm).abs() > RADIUS_TOLERANCE_MM {
                return Err(IoError::Radius {
                    path: path(),
                    line,
                    distance_mm: d,
                    radius_mm: h.radius_mm,
                });
            }
        }
    }

    if n < MIN_SAMPLES {
        return Err(IoError::Format {
            path: path(),
            line: last_line,
            message: format!("a run needs at least {MIN_SAMPLES} samples; this file has {n}"),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::{Direction, RunHeader};

    /// A valid run of 5 samples on the circle of radius 100 about (300, 200, -300) in XY,
    /// lines 13-17, from "r.b5r".
    fn run() -> Run {
        let pivot = [300.0, 200.0, -300.0];
        let th: Vec<f64> = (0..5).map(|i| 0.01 * i as f64).collect();
        let x = th.iter().map(|t| pivot[0] + 100.0 * t.cos()).collect();
        let y = th.iter().map(|t| pivot[1] + 100.0 * t.sin()).collect();
        let mut axes: [Option<Vec<f64>>; 6] = Default::default();
        axes[Axis::X.index()] = Some(x);
        axes[Axis::Y.index()] = Some(y);
        axes[Axis::C.index()] = Some(vec![0.0; 5]);
        Run {
            header: RunHeader {
                format_version: 1,
                machine: None,
                plane: Plane::XY,
                direction: Some(Direction::CCW),
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: pivot,
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0; 3],
                defaulted: ballbar_model::run::DefaultedKeys::default(),
                started_at: "2026-11-21T10:00:00Z".into(),
                started_at_unix_s: 1_795_255_200.0,
                run_id: None,
                extra: Vec::new(),
            },
            source: "r.b5r".into(),
            t_s: vec![0.0, 0.1, 0.2, 0.3, 0.4],
            axes,
            dr_mm: vec![1e-3; 5],
            lines: vec![13, 14, 15, 16, 17],
        }
    }

    /// The error of checking the run changed by `change`, with its message.
    fn error(change: impl Fn(&mut Run)) -> (IoError, String) {
        let mut r = run();
        change(&mut r);
        let e = check_run(&r).unwrap_err();
        let msg = e.to_string();
        (e, msg)
    }

    #[test]
    fn a_valid_run_passes() {
        check_run(&run()).unwrap();
        // A free run needs no direction, no in-plane axes and no circle.
        let mut free = run();
        free.header.plane = Plane::Free;
        free.header.direction = None;
        free.axes[Axis::Y.index()] = None;
        free.axes[Axis::X.index()] = Some(vec![0.0, 1.0, 2.0, 3.0, 4.0]);
        check_run(&free).unwrap();
    }

    #[test]
    fn samples_are_checked_in_order_with_the_readers_messages() {
        let (e, msg) = error(|r| r.t_s[3] = 0.2);
        assert!(matches!(e, IoError::Sample { line: 16, ref column, .. } if column == "t_s"));
        assert_eq!(
            msg,
            "r.b5r:16: column t_s: 0.2 does not increase: the sample before (line 15) has 0.2"
        );
        let (e, msg) = error(|r| r.axes[Axis::X.index()].as_mut().unwrap()[2] += 1.5);
        assert!(matches!(e, IoError::Radius { line: 15, .. }), "{e:?}");
        assert!(msg.starts_with("r.b5r:15: the axis coordinates lie 101.4"), "{msg}");
        // 0.9 mm is within the tolerance.
        let mut ok = run();
        ok.axes[Axis::Y.index()].as_mut().unwrap()[1] += 0.9;
        check_run(&ok).unwrap();
        // The first problem in sample order wins.
        let (_, msg) = error(|r| {
            r.t_s[4] = 0.0;
            r.dr_mm[2] = f64::NAN;
        });
        assert_eq!(msg, "r.b5r:15: column dR_um: \"NaN\" is not a finite number");
    }

    #[test]
    fn every_value_must_be_finite() {
        let (_, msg) = error(|r| r.t_s[0] = f64::INFINITY);
        assert_eq!(msg, "r.b5r:13: column t_s: \"inf\" is not a finite number");
        let (_, msg) = error(|r| r.axes[Axis::C.index()].as_mut().unwrap()[1] = f64::NAN);
        assert_eq!(msg, "r.b5r:14: column C_deg: \"NaN\" is not a finite number");
        let (_, msg) = error(|r| r.axes[Axis::Y.index()].as_mut().unwrap()[4] = f64::NEG_INFINITY);
        assert_eq!(msg, "r.b5r:17: column Y_mm: \"-inf\" is not a finite number");
    }

    #[test]
    fn columns_must_have_equal_lengths() {
        let (e, msg) = error(|r| {
            r.dr_mm.pop();
        });
        assert!(matches!(e, IoError::Format { line: 17, .. }), "{e:?}");
        assert_eq!(msg, "r.b5r:17: column dR_um has 4 values but t_s has 5");
        let (_, msg) = error(|r| r.axes[Axis::X.index()].as_mut().unwrap().push(1.0));
        assert_eq!(msg, "r.b5r:17: column X_mm has 6 values but t_s has 5");
        let (_, msg) = error(|r| r.lines.clear());
        assert_eq!(msg, "r.b5r:1: column line numbers has 0 values but t_s has 5");
    }

    #[test]
    fn at_least_three_samples() {
        let (e, msg) = error(|r| {
            r.t_s.truncate(2);
            r.dr_mm.truncate(2);
            r.lines.truncate(2);
            for c in r.axes.iter_mut().flatten() {
                c.truncate(2);
            }
        });
        assert!(matches!(e, IoError::Format { line: 14, .. }), "{e:?}");
        assert_eq!(msg, "r.b5r:14: a run needs at least 3 samples; this file has 2");
    }

    #[test]
    fn the_set_up_is_checked() {
        for (change, what) in [
            (
                Box::new(|r: &mut Run| r.header.radius_mm = f64::NAN) as Box<dyn Fn(&mut Run)>,
                "r.b5r: radius_mm: NaN is not a positive number",
            ),
            (
                Box::new(|r: &mut Run| r.header.feed_mm_per_min = 0.0),
                "r.b5r: feed_mm_per_min: 0 is not a positive number",
            ),
            (
                Box::new(|r: &mut Run| r.header.pivot_mm[1] = f64::INFINITY),
                "r.b5r: pivot_mm: (300, inf, -300) is not three finite numbers",
            ),
            (
                Box::new(|r: &mut Run| r.header.direction = None),
                "r.b5r: direction: a test in plane XY needs a direction (CW or CCW)",
            ),
            (
                Box::new(|r: &mut Run| r.axes[Axis::Y.index()] = None),
                "r.b5r: plane: a test in plane XY needs the column Y_mm",
            ),
        ] {
            let mut r = run();
            change(&mut r);
            let e = check_run(&r).unwrap_err();
            assert!(matches!(e, IoError::Setup { .. }), "{e:?}");
            assert_eq!(e.line(), None);
            assert_eq!(e.to_string(), what);
        }
    }
}

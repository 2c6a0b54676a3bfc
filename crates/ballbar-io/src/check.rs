//! The checks that make a [`Run`] valid, written once for every way in: the run-CSV reader
//! ([`crate::csv::parse_run`]), the plain-table importer ([`crate::table::parse_table`]) and the
//! vendor importers all end with [`check_run`].
//!
//! A reader keeps the errors that are parse errors (a field that is not a number, a line with
//! the wrong number of fields) where it parses; what is wrong with the values themselves is
//! found here, with the same messages whichever format the run came from. Errors name
//! `run.source` and the sample's line (`run.lines[i]`).

use std::path::PathBuf;

use ballbar_model::{Axis, Direction, Plane, Run};

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
    check_run_text(run, last_line, None)
}

/// [`check_run_ending_at`] for a run read from text whose last line may lack its line end
/// (`unterminated`): the sign of a file cut inside its last number.
pub(crate) fn check_run_text(
    run: &Run,
    last_line: usize,
    unterminated: Option<Unterminated>,
) -> Result<(), IoError> {
    check_values(run, last_line)?;
    plausibility(run, unterminated).map(|_| ())
}

/// What a valid run's data say is unusual about it, as lines to state (without the file's
/// name): a duration a little off its path over its feed (a feed override), readings that
/// barely move. Empty for a run [`check_run`] refuses.
pub fn warnings(run: &Run) -> Vec<String> {
    plausibility(run, None).unwrap_or_default()
}

/// The values of a run: set-up, columns, samples, their number.
fn check_values(run: &Run, last_line: usize) -> Result<(), IoError> {
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

/// The last sample line of a run's text when it has no line end, with the sample line before
/// it and the column names: what tells a file cut inside its last number.
#[derive(Clone, Copy)]
pub(crate) struct Unterminated<'a> {
    /// The last line, without a line end.
    pub(crate) last: &'a str,
    /// The sample line before it.
    pub(crate) before: &'a str,
    /// The names of the columns, in the order of the fields.
    pub(crate) columns: &'a [&'a str],
}

/// Digits after the decimal point of a number field, `None` for one in exponent form (whose
/// digits say nothing of a cut).
fn decimals(field: &str) -> Option<usize> {
    let f = field.trim_matches([' ', '\t']);
    if f.contains(['e', 'E']) {
        return None;
    }
    Some(f.split_once('.').map_or(0, |(_, d)| d.len()))
}

/// A number for a message: as written, unless it is absurdly large or small (then in
/// exponent form, not hundreds of digits).
pub(crate) fn shown(v: f64) -> String {
    if v != 0.0 && !(1e-6..1e9).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}

/// An angle step wrapped into (−π, π].
fn wrap(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::TAU);
    if w > std::f64::consts::PI { w - std::f64::consts::TAU } else { w }
}

/// What the data of a valid run say about its own header: errors for what cannot be a real
/// test as the header describes it, warnings (returned) for what is unusual.
///
/// - A last line without its line end whose numbers have fewer digits than the line before's:
///   the file was cut inside a number (the reader says what was kept).
/// - `feed_mm_per_min` and `radius_mm` within the bounds of a ballbar test
///   ([`ballbar_model::plausible`]).
/// - A planar run's path: the axis off the plane stays at the pivot (within
///   [`RADIUS_TOLERANCE_MM`]), so the path lies in the plane its header names; its angle
///   advances in the header's direction; and it sweeps the arc the header states (`arc_deg`,
///   else a full circle) to within the spacing a `.b5r` file may have
///   ([`crate::b5r::FEED_AGREEMENT`]) and two samples: a run that ends early was cut short.
/// - The duration against the path length over the feed (the acceleration allowed for,
///   [`ballbar_model::plausible::DURATION_TOLERANCE`]): t_s in ms, a feed in mm/s, a scaled
///   time are errors naming the likely cause; a few per cent beyond is a warning.
/// - The readings: none beyond the bar's range ([`ballbar_model::plausible::MAX_READING_MM`]);
///   not all within ±[`ballbar_model::plausible::MIN_READING_PEAK_UM`] (readings in mm); a
///   warning when they barely move.
fn plausibility(run: &Run, unterminated: Option<Unterminated>) -> Result<Vec<String>, IoError> {
    use ballbar_model::plausible as p;
    let mut warnings = Vec::new();
    let path = || PathBuf::from(&run.source);
    let setup =
        |key: &str, message: String| IoError::Setup { path: path(), key: key.to_string(), message };
    let h = &run.header;
    let n = run.len();
    let line = |i: usize| run.lines.get(i).map_or(1, |&l| l as usize);
    let extra = |key: &str| h.extra.iter().find(|(k, _)| k == key).map(|(_, v)| v.as_str());
    let kept = || {
        format!(
            "kept: {n} samples (lines {}-{}), t_s {} to {} s",
            line(0),
            line(n - 1),
            shown(run.t_s[0]),
            shown(run.t_s[n - 1])
        )
    };

    // A file cut inside its last number: the last line has no line end and fewer digits.
    if let Some(u) = unterminated {
        let fields = u.last.split(',').zip(u.before.split(',')).zip(u.columns);
        for ((now, before), column) in fields {
            if let (Some(a), Some(b)) = (decimals(now), decimals(before))
                && a < b
            {
                return Err(IoError::Format {
                    path: path(),
                    line: line(n - 1),
                    message: format!(
                        "the last line has no line end and its {column} {:?} has fewer digits than the line before's {:?}: the file looks cut inside a number ({}); if the file is whole, end its last line with a line end",
                        now.trim(),
                        before.trim(),
                        kept()
                    ),
                });
            }
        }
    }

    // The set-up's own bounds.
    let (lo, hi) = p::FEED_MM_PER_MIN;
    if !(lo..=hi).contains(&h.feed_mm_per_min) {
        return Err(setup(
            "feed_mm_per_min",
            format!(
                "{} mm/min is not the feed of a ballbar test ({lo} to {hi} mm/min): a wrong unit or a typo",
                shown(h.feed_mm_per_min)
            ),
        ));
    }
    let (lo, hi) = p::RADIUS_MM;
    if !(lo..=hi).contains(&h.radius_mm) {
        return Err(setup(
            "radius_mm",
            format!(
                "{} mm is not the length of a ballbar ({lo} to {hi} mm): a wrong unit or a typo",
                shown(h.radius_mm)
            ),
        ));
    }

    // The path: its plane, its sense, its arc; its length.
    let pivot = h.pivot_mm;
    let path_mm = match h.plane.axes() {
        Some((u, v, w)) => {
            let (cu, cv) = (run.axis(u).unwrap_or(&[]), run.axis(v).unwrap_or(&[]));
            if let Some(cw) = run.axis(w)
                && let Some(i) =
                    cw.iter().position(|x| (x - pivot[w.index()]).abs() > RADIUS_TOLERANCE_MM)
            {
                // Which plane the path does lie in: the two axes that move most.
                let range = |a: Axis| {
                    run.axis(a).map_or(0.0, |c| {
                        let (l, h) =
                            c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                                (l.min(x), h.max(x))
                            });
                        h - l
                    })
                };
                let mut moving = Axis::LINEAR;
                moving.sort_by(|a, b| range(*b).total_cmp(&range(*a)));
                let lies_in = Plane::PLANAR
                    .into_iter()
                    .find(|pl| {
                        pl.axes().is_some_and(|(a, b, _)| {
                            [a, b].contains(&moving[0]) && [a, b].contains(&moving[1])
                        })
                    })
                    .map_or(String::new(), |pl| format!(": the path lies in {pl}"));
                return Err(IoError::Sample {
                    path: path(),
                    line: line(i),
                    column: w.column_name().to_string(),
                    message: format!(
                        "{} is {:.3} mm off the pivot's {}, but a circle in plane {} holds {} at the pivot{lies_in} (is the header's plane wrong?)",
                        cw[i],
                        cw[i] - pivot[w.index()],
                        pivot[w.index()],
                        h.plane,
                        w.name()
                    ),
                });
            }
            let angle = |i: usize| (cv[i] - pivot[v.index()]).atan2(cu[i] - pivot[u.index()]);
            let mut swept = 0.0;
            let mut before = angle(0);
            for i in 1..n {
                let now = angle(i);
                swept += wrap(now - before);
                before = now;
            }
            let sense = if swept > 0.0 { Direction::CCW } else { Direction::CW };
            if let Some(d) = h.direction
                && d != sense
                && swept != 0.0
            {
                let (from, to) = (u.name(), v.name());
                return Err(setup(
                    "direction",
                    format!(
                        "{d}, but the path's angle {} by {:.2}° from {:.2}° (angles from +{from} towards +{to}): the run goes {sense} (is the header's direction wrong, or are the columns {} and {} swapped?)",
                        if swept > 0.0 { "increases" } else { "decreases" },
                        swept.abs().to_degrees(),
                        angle(0).to_degrees(),
                        u.column_name(),
                        v.column_name()
                    ),
                ));
            }
            // The arc the header states, else a full circle.
            let (arc_deg, stated) = match extra("arc_deg") {
                Some(text) => match text.trim().parse::<f64>() {
                    Ok(a) if a.is_finite() && a > 0.0 => (a, "its header states (arc_deg)"),
                    _ => {
                        return Err(setup(
                            "arc_deg",
                            format!(
                                "{text:?} is not a positive angle in degrees (the arc the test sweeps)"
                            ),
                        ));
                    }
                },
                None => (360.0, "of a full circle"),
            };
            let swept_deg = swept.abs().to_degrees();
            let step_deg = swept_deg / (n - 1) as f64;
            let short = swept_deg < arc_deg * (1.0 - crate::b5r::FEED_AGREEMENT) - 2.0 * step_deg;
            if short && extra("arc_deg").is_none() && unterminated.is_none() {
                // The run format allows an arc without saying so: a run short of a full circle
                // whose header states no arc and whose last line is whole may be a partial arc
                // as well as a file cut at a line end. Said, not refused.
                warnings.push(format!(
                    "{}:{}: the samples sweep {swept_deg:.2}° ({}): a partial arc, or a file cut short at a line end? The header states no arc (# arc_deg: <degrees>) to tell",
                    run.source,
                    line(n - 1),
                    kept()
                ));
            } else if short {
                let cut =
                    if unterminated.is_some() { " (its last line has no line end)" } else { "" };
                let partial = if extra("arc_deg").is_none() {
                    "; a partial arc states its arc in the header (# arc_deg: <degrees>)"
                } else {
                    ""
                };
                return Err(IoError::Format {
                    path: path(),
                    line: line(n - 1),
                    message: format!(
                        "the run ends early: its samples sweep {swept_deg:.2}° of the {arc_deg}° {stated} ({}, from {:.2}° to {:.2}°): the file was cut short{cut}{partial}",
                        kept(),
                        angle(0).to_degrees(),
                        (angle(0) + swept).to_degrees()
                    ),
                });
            }
            h.radius_mm * swept.abs()
        }
        None => {
            // A free run: the length of its (X, Y, Z) path, chord by chord.
            let xyz = |i: usize| {
                let mut q = pivot;
                for a in Axis::LINEAR {
                    if let Some(c) = run.axis(a) {
                        q[a.index()] = c[i];
                    }
                }
                q
            };
            (1..n)
                .map(|i| {
                    let (a, b) = (xyz(i - 1), xyz(i));
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
                })
                .sum()
        }
    };

    // The duration against the path over the feed. A free path too short to time (a rotary
    // test whose commanded point barely moves) is not judged.
    let duration = run.t_s[n - 1] - run.t_s[0];
    let speed = h.feed_mm_per_min / 60.0;
    // A path that is not finite (coordinates beyond any machine) is left to the fit, which
    // names the largest number.
    if path_mm.is_finite() && path_mm >= ballbar_model::path::MIN_ARM_MM {
        let expected = path_mm / speed;
        let ratio = duration / expected;
        let low = 1.0 - p::DURATION_TOLERANCE;
        let high = (1.0 + p::DURATION_TOLERANCE)
            * (1.0 + speed / p::MIN_ACCELERATION_MM_PER_S2 / expected);
        let said = || {
            format!(
                "the samples span {} s, but the path ({path_mm:.1} mm) at feed_mm_per_min {} takes {expected:.4} s",
                shown(duration),
                h.feed_mm_per_min
            )
        };
        if !(low..=high).contains(&ratio) {
            let w = p::DURATION_WARNING_FACTOR;
            if (low / w..=high * w).contains(&ratio) {
                warnings.push(format!(
                    "{}: the machine ran at {:.0} mm/min ({:.0} % of the feed), a feed override, or a time or feed slightly off; the feed-dependent results (the servo lags) take the stated feed",
                    said(),
                    h.feed_mm_per_min / ratio,
                    100.0 / ratio
                ));
            } else {
                let near = |x: f64| (ratio / x - 1.0).abs() < 0.1;
                let (key, cause) = if near(1000.0) {
                    ("t_s", "t_s looks like milliseconds (the column is in seconds)".to_string())
                } else if near(1e6) {
                    ("t_s", "t_s looks like microseconds (the column is in seconds)".to_string())
                } else if near(1.0 / 60.0) {
                    (
                        "feed_mm_per_min",
                        "feed_mm_per_min looks like mm/s (the key is in mm/min), or t_s like minutes".to_string(),
                    )
                } else if near(1e-3) {
                    (
                        "feed_mm_per_min",
                        "feed_mm_per_min looks like m/min (the key is in mm/min)".to_string(),
                    )
                } else if near(1.0 / 25.4) {
                    (
                        "feed_mm_per_min",
                        "feed_mm_per_min looks like inches per minute (the key is in mm/min)"
                            .to_string(),
                    )
                } else {
                    (
                        "t_s",
                        format!(
                            "t_s and feed_mm_per_min disagree by a factor of {}: one of them is wrong (times scaled, a sample rate off, or the feed of another test)",
                            if (1e-3..1e3).contains(&ratio) {
                                format!("{ratio:.3}")
                            } else {
                                format!("{ratio:.3e}")
                            }
                        ),
                    )
                };
                let from = match (extra("sample_rate_hz"), extra("table_t_s")) {
                    (Some(rate), _) => format!(
                        " (t_s comes from the file's sample rate, {} Hz)",
                        rate.parse::<f64>().map_or(rate.to_string(), shown)
                    ),
                    (None, Some(how)) => format!(" (t_s: {how})"),
                    _ => String::new(),
                };
                let message = format!("{}{from}: {cause}", said());
                // The times are wrong at the last sample, which spans the run; a feed at its key.
                return Err(if key == "t_s" {
                    IoError::Sample { path: path(), line: line(n - 1), column: key.into(), message }
                } else {
                    setup(key, message)
                });
            }
        }
    }

    // The readings.
    let (mut peak, mut at) = (0.0f64, 0);
    for (i, r) in run.dr_mm.iter().enumerate() {
        if r.abs() > peak {
            (peak, at) = (r.abs(), i);
        }
    }
    if peak > p::MAX_READING_MM {
        return Err(IoError::Sample {
            path: path(),
            line: line(at),
            column: "dR_um".into(),
            message: format!(
                "{} µm is beyond a ballbar's range of ±{} mm: the reading is the bar's length minus radius_mm, in µm (not the length itself, nor in other units)",
                run.dr_mm[at] * 1e3,
                p::MAX_READING_MM
            ),
        });
    }
    let unit = extra("table_reading_unit")
        .map_or(String::new(), |u| format!("; the table's readings were taken as {u}"));
    let peak_um = peak * 1e3;
    if peak_um < p::MIN_READING_PEAK_UM {
        return Err(IoError::Sample {
            path: path(),
            line: line(at),
            column: "dR_um".into(),
            message: format!(
                "every reading lies within ±{} µm (the largest, here, {peak_um:.4} µm): no real run reads so flat, since the set-up's centring alone moves a trace by more; readings in mm? dR_um is in µm (multiply by 1000){unit}",
                p::MIN_READING_PEAK_UM
            ),
        });
    }
    if peak_um < p::LOW_READING_PEAK_UM {
        warnings.push(format!(
            "every reading lies within ±{} µm (the largest {peak_um:.3} µm): rare on a real machine; if the readings are in mm, dR_um wants µm{unit}",
            p::LOW_READING_PEAK_UM
        ));
    }
    if run.dr_mm.iter().all(|&r| r == run.dr_mm[0]) {
        warnings.push(format!(
            "every reading is {} µm: a ballbar's reading moves by its noise at least (did the bar measure?)",
            run.dr_mm[0] * 1e3
        ));
    }
    Ok(warnings)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::{Direction, RunHeader};

    /// A valid run of 5 samples on the circle of radius 100 about (300, 200, -300) in XY,
    /// lines 13-17, from "r.b5r": an arc of 2.3° (as its header states) at 600 mm/min.
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
                feed_mm_per_min: 600.0,
                pivot_mm: pivot,
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0; 3],
                defaulted: ballbar_model::run::DefaultedKeys::default(),
                started_at: "2026-11-21T10:00:00Z".into(),
                started_at_unix_s: 1_795_255_200.0,
                run_id: None,
                extra: vec![("arc_deg".into(), "2.3".into())],
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

    // ---- what the data say against the header ----

    /// A full circle CCW in XY, R 100 mm about (300, 200, -300), at 1000 mm/min sampled at
    /// 10 Hz (376 samples, the last 1.9° short of closing), lines 13 on, from "c.csv"; its
    /// readings a set-up's eccentricity of 20 µm and an ellipse of 3 µm.
    fn circle() -> Run {
        let mut r = run();
        let omega = 1000.0 / 60.0 / 100.0;
        let n = (std::f64::consts::TAU / omega * 10.0) as usize;
        let t: Vec<f64> = (0..n).map(|i| i as f64 / 10.0).collect();
        let th: Vec<f64> = t.iter().map(|t| omega * t).collect();
        r.header.feed_mm_per_min = 1000.0;
        r.header.extra.clear();
        r.axes[Axis::X.index()] = Some(th.iter().map(|a| 300.0 + 100.0 * a.cos()).collect());
        r.axes[Axis::Y.index()] = Some(th.iter().map(|a| 200.0 + 100.0 * a.sin()).collect());
        r.axes[Axis::C.index()] = Some(vec![0.0; n]);
        r.dr_mm = th.iter().map(|a| 0.020 * (a - 0.3).cos() + 0.003 * (2.0 * a).cos()).collect();
        r.lines = (13..13 + n as u32).collect();
        r.t_s = t;
        r.source = "c.csv".into();
        r
    }

    /// The circle changed by `change`: its error's message.
    fn refused(change: impl Fn(&mut Run)) -> String {
        let mut r = circle();
        change(&mut r);
        check_run(&r).unwrap_err().to_string()
    }

    /// Every column of the run cut to its first `k` samples.
    fn keep(r: &mut Run, k: usize) {
        r.t_s.truncate(k);
        r.dr_mm.truncate(k);
        r.lines.truncate(k);
        for c in r.axes.iter_mut().flatten() {
            c.truncate(k);
        }
    }

    #[test]
    fn the_circle_passes_without_a_word() {
        let r = circle();
        assert_eq!(r.len(), 376);
        check_run(&r).unwrap();
        assert!(warnings(&r).is_empty(), "{:?}", warnings(&r));
    }

    #[test]
    fn a_duration_that_is_not_the_path_over_the_feed_names_the_likely_cause() {
        // Times scaled by 2: squareness moves with them at the same residual.
        let m = refused(|r| r.t_s.iter_mut().for_each(|t| *t *= 2.0));
        assert!(
            m.starts_with("c.csv:388: column t_s: the samples span 75 s, but the path (625.0 mm) at feed_mm_per_min 1000 takes 37.5000 s: t_s and feed_mm_per_min disagree by a factor of 2.000: one of them is wrong"),
            "{m}"
        );
        let m = refused(|r| r.t_s.iter_mut().for_each(|t| *t *= 1000.0));
        assert!(m.contains("t_s looks like milliseconds (the column is in seconds)"), "{m}");
        // A feed in mm/s under feed_mm_per_min.
        let m = refused(|r| r.header.feed_mm_per_min /= 60.0);
        assert!(m.starts_with("c.csv: feed_mm_per_min: the samples span 37.5 s"), "{m}");
        assert!(m.contains("feed_mm_per_min looks like mm/s (the key is in mm/min)"), "{m}");
        // Where the times come from a sample rate, the message says so.
        let m = refused(|r| {
            r.t_s.iter_mut().for_each(|t| *t *= 2.0);
            r.header.extra.push(("sample_rate_hz".into(), "5".into()));
        });
        assert!(m.contains("(t_s comes from the file's sample rate, 5 Hz)"), "{m}");
        // Within 5 % (and the start's acceleration): nothing said. A 10 % override: a warning.
        let mut r = circle();
        r.t_s.iter_mut().for_each(|t| *t *= 1.04);
        check_run(&r).unwrap();
        assert!(warnings(&r).is_empty());
        r.t_s.iter_mut().for_each(|t| *t *= 1.1 / 1.04);
        check_run(&r).unwrap();
        let w = warnings(&r);
        assert!(
            w.len() == 1
                && w[0]
                    .contains("the machine ran at 909 mm/min (91 % of the feed), a feed override"),
            "{w:?}"
        );
    }

    #[test]
    fn values_beyond_a_ballbar_test_are_refused() {
        let m = refused(|r| r.header.feed_mm_per_min = 1e12);
        assert_eq!(
            m,
            "c.csv: feed_mm_per_min: 1e12 mm/min is not the feed of a ballbar test (1 to 100000 mm/min): a wrong unit or a typo"
        );
        let m = refused(|r| r.header.feed_mm_per_min = 0.25);
        assert!(m.starts_with("c.csv: feed_mm_per_min: 0.25 mm/min is not the feed"), "{m}");
    }

    #[test]
    fn readings_in_mm_or_beyond_the_bars_range_are_refused() {
        // Readings in mm under dR_um: 20 µm reads as 0.02.
        let m = refused(|r| r.dr_mm.iter_mut().for_each(|x| *x *= 1e-3));
        assert!(
            m.starts_with("c.csv:24: column dR_um: every reading lies within ±0.5 µm (the largest, here, 0.0227 µm): no real run reads so flat")
                && m.contains("readings in mm? dR_um is in µm (multiply by 1000)"),
            "{m}"
        );
        let m = refused(|r| r.dr_mm[40] = 150.02);
        assert!(m.starts_with("c.csv:53: column dR_um: 150020 µm is not a ballbar reading"), "{m}");
        let m = refused(|r| r.dr_mm[40] = 5.0);
        assert!(
            m.starts_with("c.csv:53: column dR_um: 5000 µm is beyond a ballbar's range of ±1 mm"),
            "{m}"
        );
        // Within ±2 µm: stated; every reading the same: stated.
        let mut r = circle();
        r.dr_mm.iter_mut().for_each(|x| *x *= 0.05);
        check_run(&r).unwrap();
        let w = warnings(&r);
        assert!(w[0].starts_with("every reading lies within ±2 µm (the largest 1.1"), "{w:?}");
        r.dr_mm.iter_mut().for_each(|x| *x = 0.004);
        check_run(&r).unwrap();
        assert_eq!(
            warnings(&r),
            [
                "every reading is 4 µm: a ballbar's reading moves by its noise at least (did the bar measure?)"
            ]
        );
    }

    #[test]
    fn the_path_must_lie_in_the_plane_and_turn_the_way_the_header_says() {
        // An XY circle labelled YZ: X moves, and YZ holds it at the pivot.
        let m = refused(|r| {
            r.header.plane = Plane::YZ;
            r.axes[Axis::Z.index()] = Some(vec![-300.0; r.len()]);
        });
        assert!(
            m.starts_with("c.csv:13: column X_mm: 400 is 100.000 mm off the pivot's 300, but a circle in plane YZ holds X at the pivot: the path lies in XY (is the header's plane wrong?)"),
            "{m}"
        );
        // CW in the header, CCW on the path.
        let m = refused(|r| r.header.direction = Some(Direction::CW));
        assert!(
            m.starts_with("c.csv: direction: CW, but the path's angle increases by 358.10° from 0.00° (angles from +X towards +Y): the run goes CCW"),
            "{m}"
        );
    }

    #[test]
    fn a_run_that_ends_early_against_its_arc_is_refused_saying_what_was_kept() {
        // 22 of 57 samples of a circle kept (cut at a line end).
        let mut r = circle();
        let every = 376 / 57 + 1;
        let pick = |c: &[f64]| c.iter().step_by(every).copied().collect::<Vec<f64>>();
        r.t_s = pick(&r.t_s);
        r.dr_mm = pick(&r.dr_mm);
        r.lines = (13..13 + r.t_s.len() as u32).collect();
        for c in r.axes.iter_mut().flatten() {
            *c = pick(c);
        }
        assert_eq!(r.len(), 54);
        check_run(&r).unwrap();
        keep(&mut r, 22);
        // No arc stated: the run format allows an arc, so it is said, not refused.
        check_run(&r).unwrap();
        assert_eq!(
            warnings(&r),
            vec!["c.csv:34: the samples sweep 140.37° (kept: 22 samples (lines 13-34), t_s 0 to 14.7 s): a partial arc, or a file cut short at a line end? The header states no arc (# arc_deg: <degrees>) to tell".to_string()]
        );
        r.header.extra.push(("arc_deg".into(), "360".into()));
        let m = check_run(&r).unwrap_err().to_string();
        assert_eq!(
            m,
            "c.csv:34: the run ends early: its samples sweep 140.37° of the 360° its header states (arc_deg) (kept: 22 samples (lines 13-34), t_s 0 to 14.7 s, from 0.00° to 140.37°): the file was cut short"
        );
        // A partial arc that states its arc: whole, it passes; cut, it does not.
        let mut arc = circle();
        keep(&mut arc, 231);
        arc.header.extra.push(("arc_deg".into(), "220".into()));
        check_run(&arc).unwrap();
        keep(&mut arc, 200);
        let m = check_run(&arc).unwrap_err().to_string();
        assert!(
            m.ends_with("sweep 190.03° of the 220° its header states (arc_deg) (kept: 200 samples (lines 13-212), t_s 0 to 19.9 s, from 0.00° to 190.03°): the file was cut short"),
            "{m}"
        );
        arc.header.extra.last_mut().unwrap().1 = "a lot".into();
        assert!(
            check_run(&arc)
                .unwrap_err()
                .to_string()
                .starts_with("c.csv: arc_deg: \"a lot\" is not a positive angle")
        );
        // A free run has no arc to close.
        let mut free = circle();
        keep(&mut free, 100);
        free.header.plane = Plane::Free;
        check_run(&free).unwrap();
    }
}

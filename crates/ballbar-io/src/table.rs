//! Plain tables of ballbar readings (angle or time, and the reading), with the test's set-up
//! given beside them, read into a validated [`Run`] — the way in for data from any ballbar
//! software that can export a table (`docs/run-format.md`, "Bringing a plain table").
//!
//! The table: one row per sample, fields separated by `,`, `;` or a tab (the first row that is
//! not a comment decides which), `.` as the decimal point; `#` lines and blank lines are
//! comments. Its columns, in any order when a header row names them:
//!
//! | columns | time | angle |
//! |---|---|---|
//! | angle, reading | from the feed, $t = R\,\lvert\theta - \theta_0\rvert / F$, or from [`TableSetup::sample_rate_hz`] | the table's |
//! | time, reading | the table's | from the feed and direction, $\theta = \theta_0 \pm F (t - t_0) / R$, $\theta_0$ = [`TableSetup::start_angle_deg`] |
//! | time, angle, reading | the table's | the table's |
//! | reading | $t = i / f_s$, [`TableSetup::sample_rate_hz`] | from the feed, as above |
//!
//! The angle is in degrees from +U towards +V of the plane (XY: from +X towards +Y), so it
//! increases in a CCW run. The commanded axis coordinates are put on the circle of radius
//! `radius_mm` about `pivot_mm`: $U = U_p + R\cos\theta$, $V = V_p + R\sin\theta$, $W = W_p$.
//! Times are counted from the first sample (`started_at` is the time of the first sample).
//! What the importer derived is said in the run's header (`table_*` keys), and the run is
//! checked by [`crate::check::check_run`] like every run.

use std::path::{Path, PathBuf};

use ballbar_model::{Axis, Direction, Plane, Run, RunHeader};

use crate::IoError;
use crate::check::shown;
use crate::csv::{Line, quoted, split_lines, trim};

/// Largest magnitude of a reading, mm: a ballbar measures within about ±1 mm of its nominal
/// length. A larger value is the bar's length rather than its deviation, or a wrong unit.
pub const MAX_READING_MM: f64 = 1.0;

/// When a table does not say the unit of its readings (they are then µm), the largest reading
/// must exceed this, µm: readings in mm read as µm would all lie within it (0.5 µm of a real
/// trace is a perfect machine; 0.5 mm a wrecked one), so the unit is asked for instead.
pub const UNSTATED_UNIT_MIN_PEAK_UM: f64 = 0.5;

/// The unit of a table's readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ReadingUnit {
    /// Micrometres, the default (as `dR_um` in the run CSV).
    Micrometre,
    /// Millimetres.
    Millimetre,
}

impl ReadingUnit {
    /// Millimetres per unit.
    pub fn mm_per_unit(self) -> f64 {
        match self {
            ReadingUnit::Micrometre => 1e-3,
            ReadingUnit::Millimetre => 1.0,
        }
    }

    /// The unit's symbol (`µm`, `mm`).
    pub fn symbol(self) -> &'static str {
        match self {
            ReadingUnit::Micrometre => "µm",
            ReadingUnit::Millimetre => "mm",
        }
    }
}

/// The set-up of a test whose readings come as a plain table: what a run file's header says
/// (`docs/run-format.md`), and what the importer needs to complete the table.
#[derive(Clone, Debug, PartialEq)]
pub struct TableSetup {
    /// Test plane: `XY`, `YZ` or `ZX` (a table is a circle; free paths need the run CSV).
    pub plane: Plane,
    /// Contouring direction, seen from the positive third axis (CCW: increasing angle).
    pub direction: Direction,
    /// Nominal bar length R, mm.
    pub radius_mm: f64,
    /// Programmed feed F, mm/min.
    pub feed_mm_per_min: f64,
    /// Axis coordinates (X, Y, Z) of the circle centre, mm (the header's `pivot_mm`).
    pub pivot_mm: [f64; 3],
    /// Table-ball centre in the table frame, mm (the header's `table_ball_mm`); `None`: not
    /// given, taken as 0, 0, 0 and left out of the run's header (`docs/run-format.md`).
    pub table_ball_mm: Option<[f64; 3]>,
    /// Tool-ball centre from the spindle gauge point, mm (the header's `tool_ball_mm`); `None`:
    /// not given, taken as 0, 0, 0 (a default that the fit's output states).
    pub tool_ball_mm: Option<[f64; 3]>,
    /// ISO 8601 time of the first sample. Required: runs of a session share a clock, and the
    /// diagnosis looks for drift across runs along it; an invented time would mislead it.
    pub started_at: String,
    /// Sampling rate, Hz, for a table without a time column: sample `i` is at `i / rate` s.
    /// Without it, an angle table's times come from the feed. An error with a time column.
    pub sample_rate_hz: Option<f64>,
    /// Angle of the first sample, degrees from +U towards +V, for a table without an angle
    /// column (required then); an error with an angle column.
    pub start_angle_deg: Option<f64>,
    /// The arc the test sweeps, degrees (the header's `arc_deg`), for a table that is not a full
    /// circle; `None`: a full circle, which the table's samples must close (a table cut short
    /// is refused).
    pub arc_deg: Option<f64>,
    /// Unit of the readings when the table does not say it (its header row may, in the
    /// reading column's name: `dR_mm`, `reading_um`); must agree when both say it. Neither:
    /// µm, unless every reading is within [`UNSTATED_UNIT_MIN_PEAK_UM`] (then an error).
    pub reading_unit: Option<ReadingUnit>,
    /// Informative machine type name (the header's `machine`).
    pub machine: Option<String>,
    /// Free-text run identifier (the header's `run_id`).
    pub run_id: Option<String>,
}

impl TableSetup {
    /// A set-up with the required values; the optional ones empty (balls at 0, no sample rate,
    /// no start angle, reading unit from the table or µm, no machine, no run id).
    pub fn new(
        plane: Plane,
        direction: Direction,
        radius_mm: f64,
        feed_mm_per_min: f64,
        pivot_mm: [f64; 3],
        started_at: impl Into<String>,
    ) -> TableSetup {
        TableSetup {
            plane,
            direction,
            radius_mm,
            feed_mm_per_min,
            pivot_mm,
            table_ball_mm: None,
            tool_ball_mm: None,
            started_at: started_at.into(),
            sample_rate_hz: None,
            start_angle_deg: None,
            arc_deg: None,
            reading_unit: None,
            machine: None,
            run_id: None,
        }
    }
}

/// Read a table file (see [`parse_table`]). `Run::source` is `path` as given.
pub fn read_table(path: &Path, setup: &TableSetup) -> Result<Run, IoError> {
    parse_table(&crate::csv::read_text(path)?, &path.to_string_lossy(), setup)
}

/// Parse a plain table of readings into a validated [`Run`] with the given set-up. `source`
/// names the file in error messages and becomes `Run::source`.
///
/// The table's shape, units and what is derived are in the module documentation. Errors:
/// a wrong set-up value ([`IoError::Setup`]); a row with the wrong number of fields, a decimal
/// comma, an unusable header row ([`IoError::Format`], at its line); a value that is not a
/// number, a reading beyond [`MAX_READING_MM`], an angle that does not advance in the run's
/// direction ([`IoError::Sample`], at its line); then whatever
/// [`crate::check::check_run`] finds. Nothing is guessed: a unit or a column that cannot be
/// told is an error that says what to write.
pub fn parse_table(text: &str, source: &str, setup: &TableSetup) -> Result<Run, IoError> {
    let path = PathBuf::from(source);
    let (started_at_unix_s, (u_axis, v_axis, w_axis)) = check_setup(setup, &path)?;
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let lines = split_lines(text);
    let rows: Vec<(usize, &str)> = lines
        .iter()
        .enumerate()
        .filter(|(_, l)| !is_comment(l))
        .map(|(i, l)| (i + 1, l.text))
        .collect();
    let format =
        |line: usize, message: String| IoError::Format { path: path.clone(), line, message };
    let Some(&(first_line, first_text)) = rows.first() else {
        let message = "the table has no rows, only comments or blank lines".to_string();
        return Err(format(lines.len().max(1), message));
    };

    let (separator, header_row, columns) = layout(first_line, first_text, &path)?;
    let n_columns = columns.len();
    let find = |q: Quantity| columns.iter().position(|c| c.quantity == q);
    let (time_col, angle_col) = (find(Quantity::Time), find(Quantity::Angle));
    let reading_col = find(Quantity::Reading).expect("named_columns requires a reading column");

    // What the set-up must complete, and must not contradict.
    let setup_error = |key: &str, message: &str| IoError::Setup {
        path: path.clone(),
        key: key.to_string(),
        message: message.to_string(),
    };
    if time_col.is_some() && setup.sample_rate_hz.is_some() {
        return Err(setup_error(
            "sample_rate_hz",
            "the table has a time column; give the sample rate only for a table without one",
        ));
    }
    if time_col.is_none() && angle_col.is_none() && setup.sample_rate_hz.is_none() {
        return Err(setup_error(
            "sample_rate_hz",
            "a table of readings alone needs the sample rate (the time of sample i is i / rate)",
        ));
    }
    if angle_col.is_some() && setup.start_angle_deg.is_some() {
        return Err(setup_error(
            "start_angle_deg",
            "the table has an angle column; give the start angle only for a table without one",
        ));
    }
    if angle_col.is_none() && setup.start_angle_deg.is_none() {
        return Err(setup_error(
            "start_angle_deg",
            "the table has no angle column: give the angle of the first sample, in degrees \
             from +U towards +V of the plane",
        ));
    }
    let reading_unit_line = header_row.unwrap_or(first_line);
    let (reading_unit, unit_said_by) = match (columns[reading_col].unit, setup.reading_unit) {
        (Some(Unit::Reading(a)), Some(b)) if a != b => {
            return Err(format(
                reading_unit_line,
                format!(
                    "header row: column {} is in {}, but the set-up says {}",
                    columns[reading_col].name,
                    a.symbol(),
                    b.symbol()
                ),
            ));
        }
        (Some(Unit::Reading(a)), _) => (a, Some(format!("column {}", columns[reading_col].name))),
        (_, Some(b)) => (b, Some("the set-up".to_string())),
        (_, None) => (ReadingUnit::Micrometre, None),
    };

    // The rows.
    let data = &rows[usize::from(header_row.is_some())..];
    let n = data.len();
    let mut times: Vec<f64> = Vec::with_capacity(n);
    let mut angles_rad: Vec<f64> = Vec::with_capacity(n);
    let mut dr_mm: Vec<f64> = Vec::with_capacity(n);
    let mut line_numbers: Vec<u32> = Vec::with_capacity(n);
    let sign = setup.direction.angular_sign();
    let time_from_angle = time_col.is_none() && setup.sample_rate_hz.is_none();
    for &(ln, row) in data {
        let fields = separator.split(row);
        if fields.len() != n_columns {
            let which = if header_row.is_some() { "the header row" } else { "the first row" };
            return Err(format(
                ln,
                format!(
                    "{} fields, but {which} (line {first_line}) has {n_columns}{}",
                    fields.len(),
                    separator.decimal_comma_hint()
                ),
            ));
        }
        for (field, column) in fields.iter().zip(&columns) {
            let sample = |message: String| IoError::Sample {
                path: path.clone(),
                line: ln,
                column: column.name.clone(),
                message,
            };
            let v = table_number(field).map_err(sample)?;
            match column.quantity {
                Quantity::Time => times.push(v * column.unit.map_or(1.0, Unit::factor)),
                Quantity::Angle => {
                    let rad = v * column.unit.map_or(1f64.to_radians(), Unit::factor);
                    // Unwrapped: each step taken in (-180°, 180°], so 359° → 1° is +2°.
                    let unwrapped = match angles_rad.last() {
                        None => rad,
                        Some(&previous) => previous + reduce(rad - previous),
                    };
                    if let (Some(&previous), Some(&previous_line)) =
                        (angles_rad.last(), line_numbers.last())
                    {
                        let step = sign * (unwrapped - previous);
                        // When the time comes from the angle, the angle must move.
                        if step < 0.0 || (step == 0.0 && time_from_angle) {
                            let message = format!(
                                "{} does not advance {} from the sample before (line \
                                 {previous_line}): in a {} run the angle {}",
                                shown(v),
                                setup.direction.name(),
                                setup.direction.name(),
                                if sign > 0.0 { "increases" } else { "decreases" }
                            );
                            return Err(sample(message));
                        }
                    }
                    angles_rad.push(unwrapped);
                }
                Quantity::Reading => {
                    let mm = v * reading_unit.mm_per_unit();
                    if mm.abs() > MAX_READING_MM {
                        let assumed = if unit_said_by.is_none() {
                            " (the table does not say its unit: µm)"
                        } else {
                            ""
                        };
                        let message = format!(
                            "{} {}{assumed} is beyond a ballbar's range of ±{MAX_READING_MM} \
                             mm: the reading is the measured length minus radius_mm, not the \
                             length itself",
                            shown(v),
                            reading_unit.symbol()
                        );
                        return Err(sample(message));
                    }
                    // In µm the reading is converted as the run CSV's `dR_um`; in mm, as a run
                    // CSV can carry it (so that the imported file holds it exactly).
                    dr_mm.push(match reading_unit {
                        ReadingUnit::Micrometre => mm,
                        ReadingUnit::Millimetre => crate::csv::reading_mm(mm),
                    });
                }
            }
        }
        line_numbers.push(u32::try_from(ln).unwrap_or(u32::MAX));
    }
    if unit_said_by.is_none() && n > 0 {
        let peak_um = dr_mm.iter().fold(0.0f64, |m, v| m.max(v.abs())) * 1e3;
        if peak_um <= UNSTATED_UNIT_MIN_PEAK_UM {
            return Err(format(
                reading_unit_line,
                format!(
                    "the table does not say the unit of its readings, and every reading is \
                     within ±{UNSTATED_UNIT_MIN_PEAK_UM} µm, as readings in mm would be: say \
                     the unit, in a header row (e.g. dR_mm or dR_um) or in the set-up"
                ),
            ));
        }
    }

    // Time and angle, each from the table or derived.
    let radius_mm = setup.radius_mm;
    let speed_mm_per_s = setup.feed_mm_per_min / 60.0;
    let mut extra: Vec<(String, String)> = Vec::new();
    let column_names: Vec<&str> = columns.iter().map(|c| c.name.as_str()).collect();
    extra.push((
        "table_columns".into(),
        match header_row {
            Some(_) => column_names.join(", "),
            None => format!("{} (no header row)", column_names.join(", ")),
        },
    ));
    extra.push((
        "table_reading_unit".into(),
        match &unit_said_by {
            Some(by) => format!("{} (from {by})", reading_unit.symbol()),
            None => "µm (the default: the table does not say)".into(),
        },
    ));
    if let Some(arc) = setup.arc_deg {
        extra.push(("arc_deg".into(), arc.to_string()));
    }
    let t_s: Vec<f64> = if time_col.is_some() {
        let t0 = times.first().copied().unwrap_or(0.0);
        if t0 != 0.0 {
            extra.push((
                "table_t_s".into(),
                format!("the table's time minus {t0} s, its first sample's"),
            ));
        }
        times.iter().map(|t| t - t0).collect()
    } else if let Some(rate_hz) = setup.sample_rate_hz {
        extra.push((
            "table_t_s".into(),
            format!("from the sample rate: sample i at i / {rate_hz} Hz"),
        ));
        (0..n).map(|i| i as f64 / rate_hz).collect()
    } else {
        extra.push((
            "table_t_s".into(),
            "from the feed: t = R·|θ − θ₀| / F (the table has no time column)".into(),
        ));
        let a0 = angles_rad.first().copied().unwrap_or(0.0);
        angles_rad.iter().map(|a| radius_mm * (a - a0).abs() / speed_mm_per_s).collect()
    };
    if angle_col.is_none() {
        let start_deg = setup.start_angle_deg.unwrap_or(0.0);
        extra.push((
            "table_angle".into(),
            format!(
                "from the feed and direction: θ = {start_deg}° {} F·t/R (the table has no angle column)",
                if sign > 0.0 { "+" } else { "−" }
            ),
        ));
        let w_rad_per_s = sign * speed_mm_per_s / radius_mm;
        angles_rad = t_s.iter().map(|t| start_deg.to_radians() + w_rad_per_s * t).collect();
    }

    // The commanded axis coordinates on the circle.
    let pivot = setup.pivot_mm;
    let mut axes: [Option<Vec<f64>>; 6] = Default::default();
    axes[u_axis.index()] =
        Some(angles_rad.iter().map(|a| pivot[u_axis.index()] + radius_mm * a.cos()).collect());
    axes[v_axis.index()] =
        Some(angles_rad.iter().map(|a| pivot[v_axis.index()] + radius_mm * a.sin()).collect());
    axes[w_axis.index()] = Some(vec![pivot[w_axis.index()]; n]);

    let run = Run {
        header: RunHeader {
            format_version: crate::csv::FORMAT_VERSION,
            machine: setup.machine.clone(),
            plane: setup.plane,
            direction: Some(setup.direction),
            radius_mm,
            feed_mm_per_min: setup.feed_mm_per_min,
            pivot_mm: pivot,
            table_ball_mm: setup.table_ball_mm.unwrap_or([0.0; 3]),
            tool_ball_mm: setup.tool_ball_mm.unwrap_or([0.0; 3]),
            defaulted: ballbar_model::run::DefaultedKeys {
                table_ball_mm: setup.table_ball_mm.is_none(),
                tool_ball_mm: setup.tool_ball_mm.is_none(),
            },
            started_at: setup.started_at.clone(),
            started_at_unix_s,
            run_id: setup.run_id.clone(),
            extra,
        },
        source: source.to_string(),
        t_s,
        axes,
        dr_mm,
        lines: line_numbers,
    };
    crate::check::check_run_ending_at(&run, lines.len().max(1))?;
    Ok(run)
}

/// The layout of a table from its first row (line `first_line`): the separator, the line of
/// the header row if the first row is one, and the columns.
fn layout(
    first_line: usize,
    first_text: &str,
    path: &Path,
) -> Result<(Separator, Option<usize>, Vec<TableColumn>), IoError> {
    let format =
        |line: usize, message: String| IoError::Format { path: path.to_path_buf(), line, message };
    // The separator, then the header row if the first row is one.
    let separator = Separator::of(first_text);
    let first_fields = separator.split(first_text);
    for field in &first_fields {
        if let Some(m) = decimal_comma(field) {
            return Err(format(first_line, m));
        }
    }
    // A first row without a number is the header row (a row of numbers with a missing or bad
    // field is a sample, and the field's error says so).
    let header_row = (first_fields.iter().all(|f| f.parse::<f64>().is_err())
        && first_fields.iter().any(|f| !f.is_empty()))
    .then_some(first_line);
    let n_columns = first_fields.len();
    let too_many = |line: usize| {
        format(
            line,
            format!(
                "{n_columns} columns: a table has one to three (time, angle, reading){}",
                separator.decimal_comma_hint()
            ),
        )
    };
    let columns: Vec<TableColumn> = match header_row {
        Some(line) => {
            if first_fields.iter().any(|f| f.is_empty()) {
                let k = first_fields.iter().position(|f| f.is_empty()).unwrap_or(0);
                return Err(format(line, format!("header row: column {} has no name", k + 1)));
            }
            if n_columns > 3 {
                return Err(too_many(line));
            }
            named_columns(&first_fields).map_err(|m| format(line, format!("header row: {m}")))?
        }
        None => match n_columns {
            1 => vec![TableColumn::unnamed(1, Quantity::Reading)],
            3 => vec![
                TableColumn::unnamed(1, Quantity::Time),
                TableColumn::unnamed(2, Quantity::Angle),
                TableColumn::unnamed(3, Quantity::Reading),
            ],
            2 => {
                return Err(format(
                    first_line,
                    format!(
                        "two columns and no header row: is the first the angle or the time? Add \
                         a header row naming them, e.g. angle_deg,reading_um or t_s,reading_um{}",
                        separator.decimal_comma_hint()
                    ),
                ));
            }
            _ => return Err(too_many(first_line)),
        },
    };
    Ok((separator, header_row, columns))
}

/// A blank line or a `#` comment line (spaces before the `#` allowed).
fn is_comment(line: &Line) -> bool {
    let t = trim(line.text);
    t.is_empty() || t.starts_with('#')
}

/// An angle step reduced to (-π, π].
fn reduce(step_rad: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    let r = step_rad.rem_euclid(tau); // [0, 2π)
    if r > std::f64::consts::PI { r - tau } else { r }
}

/// Check the set-up; its start time in seconds since 1970 and the plane's axes (U, V, W).
fn check_setup(setup: &TableSetup, path: &Path) -> Result<(f64, (Axis, Axis, Axis)), IoError> {
    let error = |key: &str, message: String| IoError::Setup {
        path: path.to_path_buf(),
        key: key.to_string(),
        message,
    };
    let axes = setup.plane.axes().ok_or_else(|| {
        error(
            "plane",
            "a table is a circle: plane XY, YZ or ZX (a free path needs the run CSV)".into(),
        )
    })?;
    let positive = [
        ("radius_mm", Some(setup.radius_mm)),
        ("feed_mm_per_min", Some(setup.feed_mm_per_min)),
        ("sample_rate_hz", setup.sample_rate_hz),
        ("arc_deg", setup.arc_deg),
    ];
    for (key, v) in positive {
        if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(error(key, format!("{v} is not a positive number")));
        }
    }
    // A sample rate or start angle beyond a ballbar's would be taken at its word: the times
    // (and the angles the feed derives from them) follow from it alone.
    let (low, high) = ballbar_model::plausible::SAMPLE_RATE_HZ;
    if let Some(r) = setup.sample_rate_hz.filter(|r| !(low..=high).contains(r)) {
        return Err(error(
            "sample_rate_hz",
            format!(
                "{} Hz is not a ballbar's sample rate ({low} to {high} Hz): a wrong unit or a typo",
                crate::check::shown(r)
            ),
        ));
    }
    if let Some(a) = setup.start_angle_deg.filter(|a| !a.is_finite()) {
        return Err(error("start_angle_deg", format!("{a} is not a finite number")));
    }
    let turn = ballbar_model::plausible::MAX_START_ANGLE_DEG;
    if let Some(a) = setup.start_angle_deg.filter(|a| a.abs() > turn) {
        return Err(error(
            "start_angle_deg",
            format!(
                "{}° is more than a turn ({turn}°) either way: a typo, or an angle in other units",
                crate::check::shown(a)
            ),
        ));
    }
    for (key, p) in [
        ("pivot_mm", setup.pivot_mm),
        ("table_ball_mm", setup.table_ball_mm.unwrap_or_default()),
        ("tool_ball_mm", setup.tool_ball_mm.unwrap_or_default()),
    ] {
        if p.iter().any(|c| !c.is_finite()) {
            let message = format!("({}, {}, {}) is not three finite numbers", p[0], p[1], p[2]);
            return Err(error(key, message));
        }
    }
    let started_at_unix_s = ballbar_model::time::parse_iso8601(&setup.started_at)
        .map_err(|m| error("started_at", m))?;
    for (key, v) in [("machine", &setup.machine), ("run_id", &setup.run_id)] {
        if let Some(v) = v
            && (v.is_empty() || trim(v) != v || crate::csv::header_value_problem(v).is_some())
        {
            let message = format!("{v:?} is not a one-line text without surrounding spaces");
            return Err(error(key, message));
        }
    }
    Ok((started_at_unix_s, axes))
}

/// How the fields of a row are separated.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Separator {
    /// One column: no separator.
    None,
    Comma,
    Semicolon,
    Tab,
}

impl Separator {
    /// The separator of a table from its first row: `;` if there is one; a tab if there is one
    /// and the row has no `,` or a `,` only as a decimal comma between tabs; else `,` if there
    /// is one; else one column.
    fn of(row: &str) -> Separator {
        if row.contains(';') {
            Separator::Semicolon
        } else if row.contains('\t')
            && (!row.contains(',') || row.split('\t').any(|f| decimal_comma(f).is_some()))
        {
            Separator::Tab
        } else if row.contains(',') {
            Separator::Comma
        } else if row.contains('\t') {
            Separator::Tab
        } else {
            Separator::None
        }
    }

    /// The fields of a row, trimmed of spaces and tabs and of one pair of surrounding double
    /// quotes (spreadsheet programs quote text).
    fn split(self, row: &str) -> Vec<&str> {
        fn field(f: &str) -> &str {
            let f = trim(f);
            let f = f.strip_prefix('"').and_then(|g| g.strip_suffix('"')).unwrap_or(f);
            trim(f)
        }
        match self {
            Separator::None => vec![field(row)],
            Separator::Comma => row.split(',').map(field).collect(),
            Separator::Semicolon => row.split(';').map(field).collect(),
            Separator::Tab => row.split('\t').map(field).collect(),
        }
    }

    /// A hint for a comma-separated table whose fields do not count up: decimal commas.
    fn decimal_comma_hint(self) -> &'static str {
        match self {
            Separator::Comma => {
                " (numbers with a decimal comma? this reader takes '.' as the decimal point)"
            }
            _ => "",
        }
    }
}

/// `Some(message)` if `field` is a number written with a decimal comma (`0,512`, `-1,5e-3`).
fn decimal_comma(field: &str) -> Option<String> {
    let f = trim(field);
    let (int, frac) = f.split_once(',')?;
    let int = int.strip_prefix(['-', '+']).unwrap_or(int);
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    let frac_digits = frac.split(['e', 'E']).next().unwrap_or("");
    (digits(int) && digits(frac_digits) && f.replacen(',', ".", 1).parse::<f64>().is_ok()).then(
        || {
            format!(
                "{} has a decimal comma: this reader takes '.' as the decimal point (export \
             the table with '.', or replace each ',' in the numbers by '.')",
                quoted(f)
            )
        },
    )
}

/// A number field of a table: as the run CSV's (`.` decimal point, finite), with the decimal
/// comma and separators other than the table's named in the message.
fn table_number(field: &str) -> Result<f64, String> {
    if let Some(m) = decimal_comma(field) {
        return Err(m);
    }
    crate::csv::number(field).map_err(|m| {
        if field.contains([' ', '\t', ',', ';']) {
            format!("{m} (fields are separated by the first row's ',', ';' or tab)")
        } else {
            m
        }
    })
}

/// What a column holds.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Quantity {
    Time,
    Angle,
    Reading,
}

impl Quantity {
    fn name(self) -> &'static str {
        match self {
            Quantity::Time => "time",
            Quantity::Angle => "angle",
            Quantity::Reading => "reading",
        }
    }
}

/// A unit a column name may state.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Unit {
    Seconds,
    Milliseconds,
    Degrees,
    Radians,
    Reading(ReadingUnit),
}

impl Unit {
    /// The quantity the unit measures.
    fn quantity(self) -> Quantity {
        match self {
            Unit::Seconds | Unit::Milliseconds => Quantity::Time,
            Unit::Degrees | Unit::Radians => Quantity::Angle,
            Unit::Reading(_) => Quantity::Reading,
        }
    }

    /// Internal units (s, rad, mm) per unit.
    fn factor(self) -> f64 {
        match self {
            Unit::Seconds => 1.0,
            Unit::Milliseconds => 1e-3,
            Unit::Degrees => 1f64.to_radians(),
            Unit::Radians => 1.0,
            Unit::Reading(u) => u.mm_per_unit(),
        }
    }

    /// The unit a word of a column name stands for.
    fn from_word(w: &str) -> Option<Unit> {
        Some(match w {
            "s" | "sec" | "secs" | "second" | "seconds" => Unit::Seconds,
            "ms" => Unit::Milliseconds,
            "deg" | "degree" | "degrees" | "°" => Unit::Degrees,
            "rad" | "radian" | "radians" => Unit::Radians,
            "mm" | "millimetre" | "millimetres" | "millimeter" | "millimeters" => {
                Unit::Reading(ReadingUnit::Millimetre)
            }
            "um" | "µm" | "μm" | "micron" | "microns" | "micrometre" | "micrometres"
            | "micrometer" | "micrometers" => Unit::Reading(ReadingUnit::Micrometre),
            _ => return None,
        })
    }
}

/// The quantity a word of a column name stands for.
fn quantity_of_word(w: &str) -> Option<Quantity> {
    match w {
        "t" | "time" => Some(Quantity::Time),
        "angle" | "theta" | "θ" | "phi" | "φ" | "ang" => Some(Quantity::Angle),
        "dr" | "δr" | "deltar" | "reading" | "deviation" | "dev" | "delta" => {
            Some(Quantity::Reading)
        }
        _ => None,
    }
}

/// A column of the table: what it holds, the unit its name states, its name for messages.
#[derive(Clone, Debug)]
struct TableColumn {
    quantity: Quantity,
    unit: Option<Unit>,
    /// The header row's name, or `k (quantity)` without a header row.
    name: String,
}

impl TableColumn {
    /// Column `k` (1-based) of a table without a header row.
    fn unnamed(k: usize, quantity: Quantity) -> TableColumn {
        TableColumn { quantity, unit: None, name: format!("{k} ({})", quantity.name()) }
    }
}

/// What a column name says: its quantity and, if stated, its unit. The name is words
/// (separated by anything but letters, digits, `µ` and `°`; case does not matter) whose last
/// may be the unit: `dR_um`, `reading [mm]`, `Angle (°)`, `t_s`, `time_ms`, `radial deviation`.
fn classify(name: &str) -> Result<(Quantity, Option<Unit>), String> {
    let shown = quoted(name);
    let lower = name.to_lowercase();
    let words: Vec<&str> = lower
        .split(|c: char| !(c.is_alphanumeric() || c == '°'))
        .filter(|w| !w.is_empty())
        .collect();
    let names_it = "name the columns e.g. t_s, angle_deg, dR_um (see docs/run-format.md)";
    let (last, before) = words
        .split_last()
        .ok_or_else(|| format!("cannot tell what column {shown} holds: {names_it}"))?;
    let unit = Unit::from_word(last);
    let quantity_words = if unit.is_some() { before } else { &words[..] };
    if let Some(other) = quantity_words.iter().find(|w| Unit::from_word(w).is_some()) {
        return Err(format!("column {shown} names two units ({other} and {last}): which is it?"));
    }
    let quantities: Vec<Quantity> =
        quantity_words.iter().filter_map(|w| quantity_of_word(w)).collect();
    let Some(&quantity) = quantities.first() else {
        if unit.is_none() && !before.is_empty() {
            return Err(format!(
                "cannot tell what column {shown} holds, nor read {} as a unit (s, ms, \
                 deg, rad, mm, µm): {names_it}",
                quoted(last)
            ));
        }
        return Err(format!("cannot tell what column {shown} holds: {names_it}"));
    };
    if quantities.iter().any(|q| *q != quantity) {
        return Err(format!(
            "column {shown} names both a {} and a {}",
            quantity.name(),
            quantities.iter().find(|q| **q != quantity).map_or("", |q| q.name())
        ));
    }
    if unit.is_none() && quantity_of_word(last).is_none() {
        return Err(format!(
            "column {shown}: {} is not a unit this reader knows (s, ms, deg, rad, mm, µm)",
            quoted(last)
        ));
    }
    if let Some(u) = unit
        && u.quantity() != quantity
    {
        return Err(format!(
            "column {shown}: {last} is not a unit of {} ({})",
            quantity.name(),
            match quantity {
                Quantity::Time => "s, ms",
                Quantity::Angle => "deg, rad",
                Quantity::Reading => "mm, µm",
            }
        ));
    }
    Ok((quantity, unit))
}

/// The columns of a header row: each named, each quantity once, a reading among them.
fn named_columns(names: &[&str]) -> Result<Vec<TableColumn>, String> {
    let mut columns: Vec<TableColumn> = Vec::with_capacity(names.len());
    for name in names {
        let (quantity, unit) = classify(name)?;
        if let Some(first) = columns.iter().find(|c| c.quantity == quantity) {
            return Err(format!(
                "columns {} and {} both hold the {}",
                quoted(&first.name),
                quoted(name),
                quantity.name()
            ));
        }
        columns.push(TableColumn { quantity, unit, name: name.to_string() });
    }
    if !columns.iter().any(|c| c.quantity == Quantity::Reading) {
        return Err(format!(
            "no column holds the reading (name it e.g. dR_um or reading_mm); the columns are {}",
            names.join(", ")
        ));
    }
    Ok(columns)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "data/table.csv";

    /// XY, CCW, R = 100 mm, F = 600 mm/min (10 mm/s), about (300, 200, -300); an arc of 0.3°
    /// (the tables here are short arcs, of 0.3° or more).
    fn setup() -> TableSetup {
        TableSetup {
            arc_deg: Some(0.3),
            ..TableSetup::new(
                Plane::XY,
                Direction::CCW,
                100.0,
                600.0,
                [300.0, 200.0, -300.0],
                "2026-11-21T10:00:00Z",
            )
        }
    }

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    /// The error of parsing `text` with `setup`, checking that its message starts with
    /// `data/table.csv:{line}: ` and contains `what`.
    fn error_at(text: &str, setup: &TableSetup, line: usize, what: &str) -> IoError {
        crate::expect_error_at(parse_table(text, FILE, setup), FILE, line, what)
    }

    /// The value of the run's extra header key.
    fn extra<'a>(run: &'a Run, key: &str) -> &'a str {
        run.header
            .extra
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, v)| v.as_str())
            .unwrap_or_else(|| panic!("no key {key} in {:?}", run.header.extra))
    }

    #[test]
    fn an_angle_table_puts_the_samples_on_the_circle_with_times_from_the_feed() {
        let text = "# exported by some ballbar software\nangle_deg,dR_um\n0,1.5\n90,-2.25\n\n180,3\n270.5,0.75\n";
        let run = parse_table(text, FILE, &setup()).unwrap();
        assert_eq!(run.source, FILE);
        assert_eq!(run.lines, vec![3, 4, 6, 7]);
        let (x, y, z) =
            (run.axis(Axis::X).unwrap(), run.axis(Axis::Y).unwrap(), run.axis(Axis::Z).unwrap());
        for (i, deg) in [0.0f64, 90.0, 180.0, 270.5].into_iter().enumerate() {
            let th = deg.to_radians();
            assert!(close(x[i], 300.0 + 100.0 * th.cos(), 1e-9), "{}", x[i]);
            assert!(close(y[i], 200.0 + 100.0 * th.sin(), 1e-9), "{}", y[i]);
            assert_eq!(z[i], -300.0);
            // t = R·θ / v, v = 10 mm/s.
            assert!(close(run.t_s[i], 100.0 * th / 10.0, 1e-12), "{}", run.t_s[i]);
        }
        for (got, um) in run.dr_mm.iter().zip([1.5, -2.25, 3.0, 0.75]) {
            assert!(close(*got, um * 1e-3, 1e-15));
        }
        assert!(run.axis(Axis::A).is_none());
        let h = &run.header;
        assert_eq!(
            (h.plane, h.direction, h.radius_mm, h.feed_mm_per_min),
            (Plane::XY, Some(Direction::CCW), 100.0, 600.0)
        );
        assert_eq!(h.started_at_unix_s, 1_795_255_200.0);
        assert_eq!(extra(&run, "table_columns"), "angle_deg, dR_um");
        assert_eq!(extra(&run, "table_reading_unit"), "µm (from column dR_um)");
        assert!(extra(&run, "table_t_s").starts_with("from the feed"));
        // The run writes and reads back as a run CSV, extra keys and all.
        let back = crate::csv::parse_run(&crate::csv::format_run(&run), "back.csv").unwrap();
        assert_eq!(back.header, run.header);
        assert_eq!(back.len(), 4);
    }

    #[test]
    fn the_table_example_of_docs_run_format_imports() {
        let block = crate::doc_csv_block("## Bringing a plain table");
        let s = TableSetup {
            arc_deg: Some(1.5),
            ..TableSetup::new(
                Plane::XY,
                Direction::CCW,
                100.0,
                1000.0,
                [300.0, 200.0, -300.0],
                "2026-11-21T10:00:00Z",
            )
        };
        let run = parse_table(block, "xy-ccw.csv", &s).unwrap();
        assert_eq!(extra(&run, "arc_deg"), "1.5");
        // Without its arc, it reads as the arc the run format allows, with a warning that it
        // may be a circle cut short.
        let unstated = TableSetup { arc_deg: None, ..s };
        let open = parse_table(block, "xy-ccw.csv", &unstated).unwrap();
        let w = crate::check::warnings(&open);
        assert!(w.iter().any(|w| w.contains("sweep 1.50°") && w.contains("cut short")), "{w:?}");
        assert_eq!(run.len(), 4);
        assert_eq!(run.lines, vec![3, 4, 5, 6]);
        // 1.5° at 1000 mm/min on R = 100 mm.
        assert!(close(run.t_s[3], 100.0 * 1.5f64.to_radians() / (1000.0 / 60.0), 1e-12));
    }

    #[test]
    fn every_plane_and_direction_follows_the_spec_convention() {
        // In plane UV the angle runs from +U towards +V; CW runs have decreasing angles.
        let text = "angle_deg;reading_um\n90;1\n60;2\n30;3\n0;4\n";
        for (plane, u, v, w) in [
            (Plane::XY, Axis::X, Axis::Y, Axis::Z),
            (Plane::YZ, Axis::Y, Axis::Z, Axis::X),
            (Plane::ZX, Axis::Z, Axis::X, Axis::Y),
        ] {
            let s = TableSetup { plane, direction: Direction::CW, ..setup() };
            let run = parse_table(text, FILE, &s).unwrap();
            let p = s.pivot_mm;
            // The first sample at 90°: on +V.
            assert!(close(run.axis(u).unwrap()[0], p[u.index()], 1e-9));
            assert!(close(run.axis(v).unwrap()[0], p[v.index()] + 100.0, 1e-9));
            // The last at 0°: on +U.
            assert!(close(run.axis(u).unwrap()[3], p[u.index()] + 100.0, 1e-9));
            assert!(close(run.axis(v).unwrap()[3], p[v.index()], 1e-9));
            assert!(run.axis(w).unwrap().iter().all(|c| *c == p[w.index()]));
            assert!(close(run.t_s[3], 100.0 * 90f64.to_radians() / 10.0, 1e-12));
        }
        // The same table as CCW: the angle goes the wrong way.
        let e = error_at(text, &setup(), 3, "");
        assert_eq!(
            e.to_string(),
            "data/table.csv:3: column angle_deg: 60 does not advance CCW from the sample before \
             (line 2): in a CCW run the angle increases"
        );
        assert!(matches!(e, IoError::Sample { ref column, .. } if column == "angle_deg"));
    }

    #[test]
    fn angles_wrap_through_360_and_may_pause_only_with_a_time_column() {
        let text = "angle_deg,dR_um\n350,1\n355,2\n0,3\n5,4\n";
        let run = parse_table(text, FILE, &setup()).unwrap();
        // 15° of travel: 2.618 s at 10 mm/s on R = 100 mm.
        assert!(close(run.t_s[3], 100.0 * 15f64.to_radians() / 10.0, 1e-12));
        assert!(close(run.axis(Axis::X).unwrap()[2], 400.0, 1e-9));
        // Without time, a repeated angle would repeat the time.
        error_at(
            "angle_deg,dR_um\n0,1\n10,2\n10,3\n20,4\n",
            &setup(),
            4,
            "10 does not advance CCW",
        );
        // With a time column, the machine may pause (20° at 10 mm/s: 3.49 s).
        let run = parse_table(
            "t_s,angle_deg,dR_um\n0,0,1\n1.0,10,2\n2.0,10,3\n3.5,20,4\n",
            FILE,
            &setup(),
        )
        .unwrap();
        assert_eq!(run.t_s, [0.0, 1.0, 2.0, 3.5]);
        // So may it with times from the sample rate (17° at 10 mm/s: 2.97 s).
        let s = TableSetup { sample_rate_hz: Some(1.0), ..setup() };
        parse_table("angle_deg,dR_um\n0,1\n8.5,2\n8.5,3\n17,4\n", FILE, &s).unwrap();
        // Going back is an error either way.
        error_at(
            "t_s,angle_deg,dR_um\n0,0,1\n0.1,10,2\n0.2,9,3\n0.3,20,4\n",
            &setup(),
            4,
            "9 does not advance CCW",
        );
    }

    #[test]
    fn a_time_table_gets_its_angles_from_the_feed_and_direction() {
        let s = TableSetup { start_angle_deg: Some(90.0), direction: Direction::CW, ..setup() };
        // Times from 2.5 s, in ms; readings in mm.
        let text = "Time [ms]\tdR [mm]\r\n2500\t0.0015\r\n2600\t-0.002\r\n2700\t0.001\r\n";
        let run = parse_table(text, FILE, &s).unwrap();
        assert!(close(run.t_s[1], 0.1, 1e-12) && close(run.t_s[2], 0.2, 1e-12));
        assert_eq!(run.t_s[0], 0.0);
        // 10 mm/s on R = 100 mm: 0.1 rad/s, CW from 90°.
        for (i, t) in run.t_s.iter().enumerate() {
            let th = 90f64.to_radians() - 0.1 * t;
            assert!(close(run.axis(Axis::X).unwrap()[i], 300.0 + 100.0 * th.cos(), 1e-9));
            assert!(close(run.axis(Axis::Y).unwrap()[i], 200.0 + 100.0 * th.sin(), 1e-9));
        }
        assert!(close(run.dr_mm[0], 0.0015, 1e-15) && close(run.dr_mm[1], -0.002, 1e-15));
        assert_eq!(extra(&run, "table_columns"), "Time [ms], dR [mm]");
        assert_eq!(extra(&run, "table_reading_unit"), "mm (from column dR [mm])");
        assert_eq!(extra(&run, "table_t_s"), "the table's time minus 2.5 s, its first sample's");
        assert!(extra(&run, "table_angle").starts_with("from the feed and direction: θ = 90° −"));
        // The run writes and reads back.
        crate::csv::parse_run(&crate::csv::format_run(&run), "back.csv").unwrap();
        // Without the start angle: asked for.
        let e = parse_table(text, FILE, &setup()).unwrap_err();
        assert!(matches!(e, IoError::Setup { ref key, .. } if key == "start_angle_deg"), "{e:?}");
        assert!(
            e.to_string()
                .starts_with("data/table.csv: start_angle_deg: the table has no angle column")
        );
    }

    #[test]
    fn three_columns_without_a_header_row_are_time_angle_reading() {
        let text = "\u{feff}# t_s, angle_deg, dR_um\n0.0, 0, 4.5\n0.5, 2.8647889756541165, 4.25\n1.0, 5.729577951308233, 4.0\n";
        let run = parse_table(text, FILE, &setup()).unwrap();
        assert_eq!(run.t_s, [0.0, 0.5, 1.0]);
        assert!(close(run.axis(Axis::Y).unwrap()[2], 200.0 + 100.0 * 0.1f64.sin(), 1e-9));
        assert_eq!(run.lines, vec![2, 3, 4]);
        assert_eq!(
            extra(&run, "table_columns"),
            "1 (time), 2 (angle), 3 (reading) (no header row)"
        );
        assert_eq!(extra(&run, "table_reading_unit"), "µm (the default: the table does not say)");
        // Two columns without a header row: angle or time? Asked.
        error_at(
            "0,4.5\n1,4.25\n2,4.0\n",
            &setup(),
            1,
            "two columns and no header row: is the first the angle or the time?",
        );
        // A column order given by the header row.
        let run = parse_table(
            "reading_um,angle_deg,t_s\n4.5,0,0\n4.25,2.8647889756541165,0.5\n4.0,5.729577951308233,1\n",
            FILE,
            &setup(),
        )
        .unwrap();
        assert_eq!(run.t_s, [0.0, 0.5, 1.0]);
        assert!(close(run.dr_mm[2], 4e-3, 1e-15));
    }

    #[test]
    fn readings_alone_need_the_sample_rate_and_the_start_angle() {
        let text = "dR_um\n1\n2\n3\n4\n";
        let e = parse_table(text, FILE, &setup()).unwrap_err();
        assert!(matches!(e, IoError::Setup { ref key, .. } if key == "sample_rate_hz"), "{e:?}");
        let s = TableSetup { sample_rate_hz: Some(50.0), start_angle_deg: Some(-90.0), ..setup() };
        let run = parse_table(text, FILE, &s).unwrap();
        assert_eq!(run.t_s, [0.0, 0.02, 0.04, 0.06]);
        assert!(close(run.axis(Axis::Y).unwrap()[0], 100.0, 1e-9));
        assert!(extra(&run, "table_t_s").contains("50 Hz"));
        // A sample rate with an angle table: times from the rate, not the feed.
        let s = TableSetup { sample_rate_hz: Some(4.0), ..setup() };
        let run = parse_table("angle_deg,dR_um\n0,1\n1,2\n2,3\n", FILE, &s).unwrap();
        assert_eq!(run.t_s, [0.0, 0.25, 0.5]);
        // A sample rate or a start angle that the table contradicts: an error, not ignored.
        let s = TableSetup { sample_rate_hz: Some(4.0), ..setup() };
        let e = parse_table("t_s,angle_deg,dR_um\n0,0,1\n1,1,2\n2,2,3\n", FILE, &s).unwrap_err();
        assert_eq!(
            e.to_string(),
            "data/table.csv: sample_rate_hz: the table has a time column; give the sample rate \
             only for a table without one"
        );
        let s = TableSetup { start_angle_deg: Some(0.0), ..setup() };
        let e = parse_table("angle_deg,dR_um\n0,1\n1,2\n2,3\n", FILE, &s).unwrap_err();
        assert!(e.to_string().contains("start_angle_deg: the table has an angle column"), "{e}");
    }

    #[test]
    fn the_reading_unit_comes_from_the_column_name_or_the_set_up() {
        let rows = "0,1.5\n1,2.5\n2,-3.5\n";
        let unit_of = |name: &str, s: &TableSetup| {
            let run = parse_table(&format!("angle_deg,{name}\n{rows}"), FILE, s).unwrap();
            run.dr_mm[0] / 1.5
        };
        let s = setup();
        for (name, mm_per_unit) in [
            ("dR_um", 1e-3),
            ("dR_µm", 1e-3),
            ("dR (μm)", 1e-3),
            ("ΔR [µm]", 1e-3),
            ("reading_microns", 1e-3),
            ("radial deviation um", 1e-3),
            ("Reading", 1e-3),
            ("dr", 1e-3),
        ] {
            assert!(close(unit_of(name, &s), mm_per_unit, 1e-15), "{name}");
        }
        let small = "0,0.0015\n1,0.0025\n2,-0.0035\n";
        for name in ["dR_mm", "Reading [mm]", "deviation/mm", "DR_MM"] {
            let run = parse_table(&format!("angle_deg,{name}\n{small}"), FILE, &s).unwrap();
            assert!(close(run.dr_mm[0], 0.0015, 1e-15), "{name}");
        }
        // The set-up's unit, for a table that does not say it.
        let mm = TableSetup { reading_unit: Some(ReadingUnit::Millimetre), ..setup() };
        let run = parse_table(&format!("angle_deg,reading\n{small}"), FILE, &mm).unwrap();
        assert!(close(run.dr_mm[2], -0.0035, 1e-15));
        assert_eq!(extra(&run, "table_reading_unit"), "mm (from the set-up)");
        // Both say it and disagree: an error.
        error_at(
            &format!("angle_deg,dR_um\n{rows}"),
            &mm,
            1,
            "header row: column dR_um is in µm, but the set-up says mm",
        );
    }

    #[test]
    fn a_unit_that_cannot_be_told_is_asked_for() {
        let rows = "0,1.5\n1,2.5\n2,-3.5\n";
        for (name, what) in [
            ("dR_in", "\"in\" is not a unit this reader knows"),
            ("dR_nm", "\"nm\" is not a unit this reader knows"),
            ("dR_mm_um", "names two units (mm and um): which is it?"),
            ("angle_mm", "mm is not a unit of angle"),
            ("messwert", "cannot tell what column \"messwert\" holds"),
            ("value_um", "cannot tell what column \"value_um\" holds"),
            ("dR_time", "names both a reading and a time"),
        ] {
            let e = error_at(&format!("angle_deg,{name}\n{rows}"), &setup(), 1, what);
            assert!(matches!(e, IoError::Format { .. }), "{e:?}");
        }
        for (name, what) in [
            ("time_min", "\"min\" is not a unit this reader knows"),
            ("t_mm", "mm is not a unit of time"),
        ] {
            error_at(&format!("{name},dR_um\n{rows}"), &setup(), 1, what);
        }
        // Two columns of one quantity, or no reading at all.
        error_at(
            &format!("angle_deg,theta\n{rows}"),
            &setup(),
            1,
            "columns \"angle_deg\" and \"theta\" both hold the angle",
        );
        error_at(&format!("t_s,angle_deg\n{rows}"), &setup(), 1, "no column holds the reading");
        // No unit anywhere, and readings that look like mm: asked for, not guessed.
        error_at(
            "angle_deg,reading\n0,0.0015\n1,0.0025\n2,-0.0035\n",
            &setup(),
            1,
            "the table does not say the unit of its readings, and every reading is within ±0.5 µm",
        );
        error_at(
            "# no header\n0,0,0.0015\n1,1,0.0025\n2,2,-0.0035\n",
            &setup(),
            2,
            "does not say the unit",
        );
        // Said to be µm, they are refused all the same: no real run reads so flat.
        error_at(
            "angle_deg,reading_um\n0,0.0015\n1,0.0025\n2,-0.0035\n",
            &setup(),
            4,
            "column dR_um: every reading lies within ±0.5 µm (the largest, here, 0.0035 µm)",
        );
    }

    #[test]
    fn a_reading_beyond_a_ballbars_range_is_the_length_or_a_wrong_unit() {
        let e = error_at(
            "angle_deg,dR_mm\n0,0.01\n1,100.0123\n2,0.02\n",
            &setup(),
            3,
            "column dR_mm: 100.0123 mm is beyond a ballbar's range of ±1 mm: the reading is the \
             measured length minus radius_mm",
        );
        assert!(matches!(e, IoError::Sample { .. }));
        error_at(
            "angle_deg,reading\n0,10\n1,1500\n2,20\n",
            &setup(),
            3,
            "1500 µm (the table does not say its unit: µm) is beyond",
        );
    }

    #[test]
    fn a_decimal_comma_is_an_error_that_says_so() {
        // Semicolon-separated with decimal commas, as a German spreadsheet writes it.
        let e = error_at(
            "angle_deg;dR_um\n0;1,5\n1;2,5\n2;3,5\n",
            &setup(),
            2,
            "column dR_um: \"1,5\" has a decimal comma: this reader takes '.' as the decimal point",
        );
        assert!(matches!(e, IoError::Sample { .. }));
        // Without a header row: the first row.
        error_at("0;0;1,5\n1;1;2,5\n", &setup(), 1, "\"1,5\" has a decimal comma");
        // Tab-separated with decimal commas.
        error_at("0,0\t0\t1,5\n", &setup(), 1, "\"0,0\" has a decimal comma");
        // Comma-separated with decimal commas: the fields do not count up, and the message
        // says why that may be.
        error_at(
            "angle_deg,dR_um\n0,1,5\n",
            &setup(),
            2,
            "3 fields, but the header row (line 1) has 2 (numbers with a decimal comma? this \
             reader takes '.' as the decimal point)",
        );
    }

    #[test]
    fn every_bad_line_is_named_with_what_is_wrong() {
        let s = setup();
        let e = error_at("angle_deg,dR_um\n0,1\n1,abc\n2,3\n", &s, 3, "");
        assert_eq!(e.to_string(), "data/table.csv:3: column dR_um: \"abc\" is not a number");
        error_at("angle_deg,dR_um\n0,1\n1,\n2,3\n", &s, 3, "column dR_um: the value is missing");
        error_at(
            "angle_deg,dR_um\n0,1\nnan,2\n2,3\n",
            &s,
            3,
            "column angle_deg: \"nan\" is not a finite number",
        );
        error_at(
            "angle_deg,dR_um\n0,1\n1,2,3\n2,3\n",
            &s,
            3,
            "3 fields, but the header row (line 1) has 2",
        );
        error_at(
            "angle_deg;dR_um\n0;1\n1 2\n",
            &s,
            3,
            "1 fields, but the header row (line 1) has 2",
        );
        error_at(
            "dR_um\n1 2\n",
            &TableSetup { sample_rate_hz: Some(1.0), start_angle_deg: Some(0.0), ..setup() },
            2,
            "\"1 2\" is not a number (fields are separated by the first row's ',', ';' or tab)",
        );
        error_at("0,0,1\n1,1,2\n2,2,3,4\n", &s, 3, "4 fields, but the first row (line 1) has 3");
        error_at("a,b,c,d\n", &s, 1, "4 columns: a table has one to three");
        error_at("angle_deg,,dR_um\n", &s, 1, "header row: column 2 has no name");
        error_at("# only a comment\n\n", &s, 2, "the table has no rows");
        error_at("", &s, 1, "the table has no rows");
        // Quotes around names and values (spreadsheet programs write them) are not part of them.
        parse_table("\"angle_deg\",\"dR_um\"\n\"0\",1\n1,2\n2,\"3\"\n", FILE, &s).unwrap();
    }

    #[test]
    fn the_run_checks_apply_as_to_every_run() {
        // Times that do not increase: the run CSV's message, at the table's line.
        let e =
            error_at("t_s,angle_deg,dR_um\n0,0,1\n# pause\n0.2,1,2\n0.2,2,3\n", &setup(), 5, "");
        assert_eq!(
            e.to_string(),
            "data/table.csv:5: column t_s: 0.2 does not increase: the sample before (line 4) has 0.2"
        );
        // Fewer than 3 samples, at the last line.
        error_at(
            "angle_deg,dR_um\n0,1\n1,2\n# end\n",
            &setup(),
            4,
            "a run needs at least 3 samples; this file has 2",
        );
    }

    #[test]
    fn the_set_up_is_checked_first() {
        let text = "angle_deg,dR_um\n0,1\n1,2\n2,3\n";
        for (s, what) in [
            (
                TableSetup { plane: Plane::Free, ..setup() },
                "data/table.csv: plane: a table is a circle: plane XY, YZ or ZX",
            ),
            (
                TableSetup { radius_mm: -1.0, ..setup() },
                "data/table.csv: radius_mm: -1 is not a positive number",
            ),
            (
                TableSetup { feed_mm_per_min: f64::NAN, ..setup() },
                "data/table.csv: feed_mm_per_min: NaN is not a positive number",
            ),
            (
                TableSetup { sample_rate_hz: Some(0.0), ..setup() },
                "data/table.csv: sample_rate_hz: 0 is not a positive number",
            ),
            (
                TableSetup { pivot_mm: [0.0, f64::INFINITY, 0.0], ..setup() },
                "data/table.csv: pivot_mm: (0, inf, 0) is not three finite numbers",
            ),
            (
                TableSetup { started_at: "today".into(), ..setup() },
                "data/table.csv: started_at: \"today\" is not an ISO 8601 time",
            ),
            (
                TableSetup { run_id: Some("a\nb".into()), ..setup() },
                "data/table.csv: run_id: \"a\\nb\" is not a one-line text",
            ),
        ] {
            let e = parse_table(text, FILE, &s).unwrap_err();
            assert!(matches!(e, IoError::Setup { .. }), "{e:?}");
            assert!(e.to_string().starts_with(what), "{e}");
        }
        // The optional values reach the header.
        let s = TableSetup {
            machine: Some("column".into()),
            run_id: Some("xy-ccw-1".into()),
            table_ball_mm: Some([0.0, 0.0, 50.0]),
            tool_ball_mm: Some([0.0, 0.0, -100.0]),
            ..setup()
        };
        let h = parse_table(text, FILE, &s).unwrap().header;
        assert_eq!(h.machine.as_deref(), Some("column"));
        assert_eq!(h.run_id.as_deref(), Some("xy-ccw-1"));
        assert_eq!((h.table_ball_mm, h.tool_ball_mm), ([0.0, 0.0, 50.0], [0.0, 0.0, -100.0]));
        assert_eq!(h.defaulted, Default::default());
        // Not given: taken as 0, 0, 0, and marked as not given (the written run leaves the
        // keys out); given as 0, 0, 0: given.
        let h = parse_table(text, FILE, &setup()).unwrap().header;
        assert_eq!((h.table_ball_mm, h.tool_ball_mm), ([0.0; 3], [0.0; 3]));
        assert!(h.defaulted.table_ball_mm && h.defaulted.tool_ball_mm);
        let zero = TableSetup { tool_ball_mm: Some([0.0; 3]), ..setup() };
        let h = parse_table(text, FILE, &zero).unwrap().header;
        assert!(h.defaulted.table_ball_mm && !h.defaulted.tool_ball_mm);
    }

    #[test]
    fn read_table_reads_a_file() {
        let dir = crate::test_dir("table-read");
        let f = dir.join("t.csv");
        std::fs::write(&f, "angle_deg,dR_um\n0,1\n1,2\n2,3\n").unwrap();
        let run = read_table(&f, &setup()).unwrap();
        assert_eq!(run.source, f.to_string_lossy());
        let e = read_table(&dir.join("none.csv"), &setup()).unwrap_err();
        assert!(matches!(e, IoError::Io { .. }), "{e:?}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn no_input_makes_the_table_reader_panic() {
        let text = "# c\nt_s;angle_deg;dR_um\n0;0;1.5\n0.1;1;2\n0.2;2;3\n";
        let n_lines = text.lines().count();
        let s = setup();
        let check = |t: &str| {
            if let Err(e) = parse_table(t, FILE, &s) {
                let msg = e.to_string();
                assert!(msg.starts_with(&format!("{FILE}:")), "{msg}");
                let line = e.line().unwrap();
                assert!((1..=n_lines + 1).contains(&line), "{msg}");
            }
        };
        for (i, _) in text.char_indices() {
            check(&text[..i]);
        }
        for (i, c) in text.char_indices() {
            for r in ["", ",", ";", "\t", "\n", "\r", "#", " ", "é", "9", "-", "e", ".", "\""] {
                check(&format!("{}{r}{}", &text[..i], &text[i + c.len_utf8()..]));
            }
        }
    }
}

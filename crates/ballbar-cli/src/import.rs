//! `ballbar import`: run CSVs (`docs/run-format.md`) from what an engineer has: Renishaw
//! `.b5r` files (each run a run, everything the file says kept in the header) and plain tables
//! of angle (or time) and reading.
//!
//! Nothing is half-written and nothing is overwritten unasked: every input is read, every
//! target checked ([`crate::outputs`]) and every text made before the first file is written,
//! and the files are written all or none; an existing file is replaced only with `--force`, and
//! an input never.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use ballbar_io::table::{ReadingUnit, TableSetup};
use ballbar_model::{Direction, Plane, Run};

use crate::{Failure, Result, inputs};

/// The arguments of `ballbar import`.
#[derive(clap::Args, Debug)]
pub struct ImportArgs {
    /// `.b5r` files (or folders of them), or plain tables (with --plane, --radius-mm, --feed,
    /// --direction).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Output folder for the run CSVs.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    placement: inputs::Placement,
    /// How `.b5r` samples are placed on the circle: as the machine moved (by the programmed
    /// feed) or by the vendor's convention (its arc's samples spread evenly).
    #[arg(long, value_enum, default_value = "machine")]
    b5r_angles: inputs::Angles,
    /// Replace run CSVs that already exist in the output folder.
    #[arg(long)]
    force: bool,
    #[command(flatten)]
    table: crate::import::TableArgs,
}

/// The set-up of a plain table, which the table cannot say.
#[derive(clap::Args, Debug, Default)]
pub struct TableArgs {
    /// Plane of a plain table.
    #[arg(long, value_enum)]
    plane: Option<TablePlane>,
    /// Nominal bar length of a plain table, mm.
    #[arg(long)]
    radius_mm: Option<f64>,
    /// Programmed feed of a plain table, mm/min.
    #[arg(long, value_name = "MM_PER_MIN")]
    feed: Option<f64>,
    /// Direction of a plain table, seen from the positive third axis.
    #[arg(long, value_enum)]
    direction: Option<TableDirection>,
    /// When the table's first sample was taken (ISO 8601; default: the file's modification time).
    #[arg(long)]
    started_at: Option<String>,
    /// Sample rate of a table without times, Hz (otherwise times follow from the feed).
    #[arg(long)]
    sample_rate_hz: Option<f64>,
    /// Angle of the first sample of a table without angles, degrees.
    #[arg(long, allow_hyphen_values = true)]
    start_angle_deg: Option<f64>,
    /// The arc a plain table sweeps, degrees, when it is not a full circle (without it, a
    /// table that does not close its circle is refused as cut short).
    #[arg(long, value_name = "DEGREES")]
    arc_deg: Option<f64>,
    /// Unit of the readings when the table's column name does not say it.
    #[arg(long, value_enum)]
    reading_unit: Option<TableUnit>,
}

/// A table's plane (`XY`, `YZ`, `ZX`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
#[allow(clippy::upper_case_acronyms)]
enum TablePlane {
    #[value(name = "XY")]
    XY,
    #[value(name = "YZ")]
    YZ,
    #[value(name = "ZX")]
    ZX,
}

/// A table's direction.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
#[allow(clippy::upper_case_acronyms)]
enum TableDirection {
    #[value(name = "CW")]
    CW,
    #[value(name = "CCW")]
    CCW,
}

/// A table's reading unit.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum TableUnit {
    Um,
    Mm,
}

impl TableArgs {
    fn given(&self) -> bool {
        self.plane.is_some()
            || self.radius_mm.is_some()
            || self.feed.is_some()
            || self.direction.is_some()
            || self.started_at.is_some()
            || self.sample_rate_hz.is_some()
            || self.start_angle_deg.is_some()
            || self.arc_deg.is_some()
            || self.reading_unit.is_some()
    }
}

/// `ballbar import FILE... --out DIR`.
pub fn import(args: &ImportArgs, reg: &ballbar_plugin_host::Registry) -> Result<()> {
    let files = inputs::files(&args.files)?;
    let mut runs: Vec<Run> = Vec::new();
    let mut tables = Vec::new();
    for f in &files {
        if ballbar_io::b5r::is_b5r(f) {
            let test = ballbar_io::b5r::read_b5r(
                f,
                &ballbar_io::b5r::B5rOptions {
                    pivot_mm: args.placement.pivot,
                    tool_ball_mm: args.placement.tool_ball_mm,
                    angles: args.b5r_angles.spacing(),
                },
            )?;
            runs.extend(test.runs);
        } else {
            tables.push(f.clone());
        }
    }
    if !tables.is_empty() {
        runs.extend(read_tables(&tables, args)?);
    } else if args.table.given() {
        return Err(Failure::Usage(anyhow!(
            "--plane, --radius-mm, --feed, --direction, --started-at, --sample-rate-hz, --start-angle-deg, --arc-deg and --reading-unit describe plain tables, and none is among the inputs"
        )));
    }
    inputs::warn(&runs);
    // Every target checked and every text made before anything is written.
    let targets: Vec<PathBuf> =
        runs.iter().map(|r| args.out.join(format!("{}.csv", r.name()))).collect();
    for (k, t) in targets.iter().enumerate() {
        if let Some(j) = targets[..k].iter().position(|u| u == t) {
            return Err(Failure::Input(anyhow!(
                "{}: runs {} ({}) and {} ({}) would both be written there; nothing was written",
                t.display(),
                runs[j].name(),
                runs[j].source,
                runs[k].name(),
                runs[k].source
            )));
        }
    }
    let outputs: Vec<crate::outputs::Output> =
        targets.iter().map(|t| crate::outputs::Output::new(t, "--out")).collect();
    let read: Vec<PathBuf> = files.iter().cloned().chain(crate::outputs::loaded(reg)).collect();
    crate::outputs::check(&outputs, &read, args.force, "runs")?;
    let mut texts = Vec::with_capacity(runs.len());
    for (run, t) in runs.iter().zip(&targets) {
        let text = ballbar_io::run_text(run, t).map_err(|e| {
            Failure::Input(anyhow!(
                "{}: cannot be written as a run CSV ({e}); nothing was written",
                run.source
            ))
        })?;
        texts.push((t.clone(), text));
    }
    std::fs::create_dir_all(&args.out)
        .map_err(|e| anyhow!("{}: cannot create the folder: {e}", args.out.display()))?;
    crate::outputs::write_all(&texts, args.force)?;
    for (run, target) in runs.iter().zip(&targets) {
        let pivot = run.header.pivot_mm;
        outln!(
            "wrote {} ({} {} {}, {} samples, pivot {}, {}, {} mm)",
            target.display(),
            run.header.plane,
            run.header.direction.map_or("", |d| d.name()),
            Path::new(&run.source)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            run.len(),
            pivot[0],
            pivot[1],
            pivot[2]
        );
    }
    if runs.iter().any(|r| ballbar_io::b5r::is_b5r(Path::new(&r.source)))
        && args.placement.pivot.is_none()
    {
        outln!(
            "note: a .b5r file does not give the circle centre: the runs are placed at 0, 0, 0 mm (set it with --pivot X,Y,Z)"
        );
    }
    Ok(())
}

/// Plain tables with the set-up from the command line; every required value named at once.
fn read_tables(tables: &[PathBuf], args: &ImportArgs) -> Result<Vec<Run>> {
    let t = &args.table;
    let mut missing = Vec::new();
    if t.plane.is_none() {
        missing.push("--plane XY|YZ|ZX");
    }
    if t.direction.is_none() {
        missing.push("--direction CW|CCW");
    }
    if t.radius_mm.is_none() {
        missing.push("--radius-mm R");
    }
    if t.feed.is_none() {
        missing.push("--feed MM_PER_MIN");
    }
    if !missing.is_empty() {
        return Err(Failure::Usage(anyhow!(
            "{}: not a .b5r file, so a plain table of angle (or time) and reading; its set-up is not in it: give {} (docs/run-format.md)",
            tables[0].display(),
            missing.join(", ")
        )));
    }
    let plane = match t.plane {
        Some(TablePlane::YZ) => Plane::YZ,
        Some(TablePlane::ZX) => Plane::ZX,
        _ => Plane::XY,
    };
    let direction = match t.direction {
        Some(TableDirection::CW) => Direction::CW,
        _ => Direction::CCW,
    };
    let reading_unit = t.reading_unit.map(|u| match u {
        TableUnit::Um => ReadingUnit::Micrometre,
        TableUnit::Mm => ReadingUnit::Millimetre,
    });
    let mut runs = Vec::with_capacity(tables.len());
    for f in tables {
        let (started_at, source) = match &t.started_at {
            Some(s) => (s.clone(), "--started-at"),
            None => {
                // Only the order of runs in time rests on it (a drift across runs): the file's
                // modification time is the best the file says, and the user is told.
                let modified = std::fs::metadata(f)
                    .and_then(|m| m.modified())
                    .map_err(|e| anyhow!("{}: {e}", f.display()))?;
                let secs = modified
                    .duration_since(std::time::UNIX_EPOCH)
                    .map(|d| d.as_secs_f64())
                    .unwrap_or(0.0);
                eprintln!(
                    "note: {}: no --started-at: the run is dated by the file's modification time",
                    f.display()
                );
                (
                    ballbar_model::time::format_iso8601(secs),
                    "the file's modification time (--started-at to give the real time)",
                )
            }
        };
        let mut setup = TableSetup::new(
            plane,
            direction,
            t.radius_mm.unwrap_or_default(),
            t.feed.unwrap_or_default(),
            args.placement.pivot.unwrap_or([0.0; 3]),
            started_at,
        );
        if let Some(t) = args.placement.tool_ball_mm {
            setup.tool_ball_mm = Some(t);
        }
        setup.sample_rate_hz = t.sample_rate_hz;
        setup.start_angle_deg = t.start_angle_deg;
        setup.arc_deg = t.arc_deg;
        setup.reading_unit = reading_unit;
        setup.run_id =
            f.file_stem().map(|s| s.to_string_lossy().into_owned()).filter(|s| !s.is_empty());
        let mut run = ballbar_io::table::read_table(f, &setup)?;
        run.header.extra.push(("started_at_source".into(), source.into()));
        if args.placement.pivot.is_none() {
            run.header.extra.push(("pivot_source".into(), "default 0, 0, 0: a table does not give the circle centre (set it with --pivot X,Y,Z)".into()));
        }
        runs.push(run);
    }
    Ok(runs)
}

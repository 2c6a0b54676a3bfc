//! Measurements of the import: Renishaw `.b5r` files imported against reading the same runs as
//! run CSVs (the baseline, in the same process), and a three-file volumetric session (XY, YZ,
//! ZX, one file each) fitted from the `.b5r` files against the same fit from the CSVs.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, Direction, Run};

use crate::time;

/// A `.b5r` text of one plane's CCW and CW runs (each run's readings as the file's window,
/// 20 readings of over-shoot either side; angles from 0°, full circle, as the simulator ran them).
fn b5r_text(ccw: &Run, cw: &Run) -> String {
    let h = &ccw.header;
    let (u, v, _) = h.plane.axes().expect("planar");
    let mut s = String::with_capacity(64 * 1024);
    let _ = write!(
        s,
        "\u{feff}<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<TEST_DOCUMENT>\n<TEST_SPEC NAME=\"bench\" version=\"2.0\"><INSTRUMENT MANUFACTURER=\"Renishaw\" MODEL=\"QC20\"><DYNAMIC_BALLBAR>\n<NOMINAL_LENGTH>{r}</NOMINAL_LENGTH><PROGRAMMED_FEEDRATE>{f}</PROGRAMMED_FEEDRATE><START_ANGLE>0</START_ANGLE><END_ANGLE>0</END_ANGLE><OVERSHOOT_ANGLE>2</OVERSHOOT_ANGLE><TEST_RADIUS>{r}</TEST_RADIUS>\n<PLANE VIEW=\"+A+B\" TEST_PLANE=\"{p}\"><A_AXIS_NAME>{u}</A_AXIS_NAME><B_AXIS_NAME>{v}</B_AXIS_NAME></PLANE>\n</DYNAMIC_BALLBAR></INSTRUMENT></TEST_SPEC>\n<DATE_STARTED>20261121-100000</DATE_STARTED><MACHINE_TESTED NAME=\"bench\"/>\n<RUN_RESULTS>\n",
        r = h.radius_mm,
        f = h.feed_mm_per_min,
        p = h.plane.name(),
    );
    for run in [ccw, cw] {
        let over = 20;
        let rate = run.sample_rate_hz().unwrap_or(250.0);
        let _ = write!(
            s,
            "<BALLBAR_RUN><RUN_DIRECTION>{}</RUN_DIRECTION><START_INDEX>{over}</START_INDEX><END_INDEX>{}</END_INDEX><SAMPLE_RATE>{rate}</SAMPLE_RATE>\n<READINGS>",
            run.header.direction.map_or("CCW", Direction::name),
            over + run.len() - 1
        );
        for x in std::iter::repeat_n(run.dr_mm[0], over)
            .chain(run.dr_mm.iter().copied())
            .chain(std::iter::repeat_n(run.dr_mm[run.len() - 1], over))
        {
            let _ = write!(s, "{x:+.5} ");
        }
        s.push_str("</READINGS></BALLBAR_RUN>\n");
    }
    s.push_str("</RUN_RESULTS>\n</TEST_DOCUMENT>\n");
    s
}

/// Print the measurements. `runs` are simulated runs of three planes (CW and CCW of each, the
/// first of each plane and direction is used).
pub fn run(spec: &MachineSpec, runs: &[Run], dir: &Path) -> Result<()> {
    let reps = 7;
    let pick =
        |plane, d| runs.iter().find(|r| r.header.plane == plane && r.header.direction == Some(d));
    let mut b5r_files: Vec<PathBuf> = Vec::new();
    for plane in ballbar_model::Plane::PLANAR {
        let (ccw, cw) = (
            pick(plane, Direction::CCW).context("a CCW run")?,
            pick(plane, Direction::CW).context("a CW run")?,
        );
        let f = dir.join(format!("bench-{}.b5r", plane.name().to_lowercase()));
        std::fs::write(&f, b5r_text(ccw, cw))?;
        b5r_files.push(f);
    }
    // The same runs as run CSVs, through the importer: both paths hold the same samples.
    let csv_dir = dir.join("b5r-as-csv");
    std::fs::create_dir_all(&csv_dir)?;
    let mut csv_files: Vec<PathBuf> = Vec::new();
    for f in &b5r_files {
        for run in ballbar_io::b5r::read_b5r(f, &Default::default())?.runs {
            let p = csv_dir.join(format!("{}.csv", run.name()));
            ballbar_io::write_run(&run, &p, ballbar_io::Existing::Replace)?;
            csv_files.push(p);
        }
    }
    let size = |files: &[PathBuf]| {
        files.iter().map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0)).sum::<u64>() as f64
            / 1e6
    };
    let (csv_read, from_csv) = time(reps, || {
        ballbar_cli::read_runs(&csv_files, 1).map_err(|_| anyhow::anyhow!("read the CSVs"))
    });
    let from_csv = from_csv?;
    let (b5r_read, from_b5r) = time(reps, || {
        b5r_files
            .iter()
            .map(|f| ballbar_io::b5r::read_b5r(f, &Default::default()).map(|t| t.runs.len()))
            .sum::<Result<usize, _>>()
    });
    anyhow::ensure!(from_b5r? == from_csv.len(), "the .b5r files and the CSVs hold different runs");
    let samples: usize = from_csv.iter().map(Run::len).sum();
    // A calibrated bar on both paths (the .b5r default): the same model.
    let options = ModelOptions {
        bar_length: ballbar_model::BarLength::Known(0.0),
        ..ModelOptions::default()
    };
    let model = Model::new(spec.clone(), options)?;
    let fit_of = |files: &[PathBuf]| -> Result<f64> {
        let runs = ballbar_cli::read_runs(files, 2).map_err(|_| anyhow::anyhow!("read"))?;
        Ok(ballbar_fit::fit(&Design::new(&model, &runs)?, 2)?.sigma_mm)
    };
    let (fit_csv, s_csv) = time(reps, || fit_of(&csv_files));
    let (fit_b5r, s_b5r) = time(reps, || fit_of(&b5r_files));
    let (s_csv, s_b5r) = (s_csv?, s_b5r?);
    anyhow::ensure!(
        (s_csv - s_b5r).abs() <= 1e-3 * s_csv,
        "the two paths fit differently: σ {s_csv} vs {s_b5r} mm"
    );
    println!(
        "\n.b5r import ({} files, {} runs, {samples} samples; {:.2} MB of .b5r, {:.2} MB of CSV; median of {reps}):",
        b5r_files.len(),
        from_csv.len(),
        size(&b5r_files),
        size(&csv_files)
    );
    println!("{:<44} {:>9} {:>12}", "stage", "ms", "× baseline");
    for (name, ms, base) in [
        ("baseline: read the same runs as run CSVs", csv_read, csv_read),
        ("read the .b5r files (XML, checks)", b5r_read, csv_read),
        ("  per .b5r file", b5r_read / b5r_files.len() as f64, csv_read),
        ("baseline: three-plane session fit from CSVs", fit_csv, fit_csv),
        ("three-plane session fit from .b5r files", fit_b5r, fit_csv),
    ] {
        println!("{name:<44} {ms:>9.2} {:>12.2}", ms / base);
    }
    Ok(())
}

//! Measurements of scale: the peak memory of `fit` per sample on a long session, against the
//! peak of only reading the same runs (the baseline, measured the same way), and the wall time
//! of `diagnose` on sessions of 100 and 1,000 runs against the 12-run session.
//!
//! Peak memory is the kernel's high-water mark of the resident set (`VmHWM` in
//! `/proc/self/status`) of a child process (this executable, `bench-child`) that does one
//! step and reports it: the whole process as a user's `ballbar fit` sees it, allocator and
//! libraries included, with nothing measured before it in the same address space (a counting
//! allocator would need `unsafe`, which this workspace keeps to its plugin crates, and would
//! miss what faer and the allocator hold beyond the bytes asked for). Linux only: elsewhere
//! the memory part says so and is skipped.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ballbar_diagnose::{Options, diagnose};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, Plane};
use ballbar_sim::Truth;

/// The kernel's high-water mark of this process's resident set, bytes (`None` off Linux).
fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The child's side: `bench-child read|fit DIR` reads the run CSVs of `DIR` (and fits them,
/// with the column machine and the default options, as `ballbar fit` does) and prints its
/// peak resident set in bytes.
pub fn child(args: &[String]) -> Result<()> {
    let (Some(step), Some(dir)) = (args.first(), args.get(1)) else {
        bail!("usage: bench-child read|fit DIR");
    };
    let mut files: Vec<PathBuf> =
        std::fs::read_dir(dir)?.map(|e| e.map(|e| e.path())).collect::<Result<_, _>>()?;
    files.sort();
    let runs = ballbar_cli::read_runs(&files, 2).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    if step == "fit" {
        let model = Model::new(ballbar_model::machines::column(), ModelOptions::default())?;
        let design = Design::new(&model, &runs)?;
        let fit = ballbar_fit::fit(&design, 2)?;
        anyhow::ensure!(fit.sigma_mm.is_finite(), "fit without a finite σ");
    }
    println!("{}", peak_rss_bytes().context("no /proc/self/status")?);
    Ok(())
}

/// Run this executable's `bench-child` and read the peak it reports.
fn child_peak(step: &str, dir: &Path) -> Result<u64> {
    let out =
        Command::new(std::env::current_exe()?).arg("bench-child").arg(step).arg(dir).output()?;
    anyhow::ensure!(
        out.status.success(),
        "bench-child {step}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    Ok(String::from_utf8_lossy(&out.stdout).trim().parse()?)
}

/// Write `truth`'s simulated runs as CSV files into a fresh folder `dir`; the sample count.
fn write_session(spec: &MachineSpec, truth: &Truth, dir: &Path) -> Result<usize> {
    let _ = std::fs::remove_dir_all(dir);
    let sim = ballbar_sim::simulate(spec, truth, 0.0, 7)?;
    crate::write_runs(&sim.runs, dir)?;
    Ok(sim.runs.iter().map(|r| r.len()).sum())
}

/// The scale measurements (see the module's documentation).
pub fn run(spec: &MachineSpec, truth_template: &Truth, dir: &Path) -> Result<()> {
    println!("\nscale: peak resident memory of `fit` per sample (a child process each, VmHWM)");
    if peak_rss_bytes().is_none() {
        println!("  skipped: no /proc/self/status (the kernel's peak resident set is read there)");
    } else {
        println!(
            "{:<52} {:>9} {:>10} {:>10} {:>12}",
            "session", "samples", "read MB", "fit MB", "fit B/sample"
        );
        // A long session: the three planes CW and CCW at 100 mm/min and 1 kHz (377 s a run),
        // and the bench's 12-run session at 250 Hz.
        let mut long = truth_template.clone();
        long.sample_rate_hz = 1000.0;
        long.tests = Plane::PLANAR
            .into_iter()
            .map(|p| ballbar_sim::TestSpec {
                feed_mm_per_min: 100.0,
                repeats: 1,
                ..crate::bench_test(p)
            })
            .collect();
        let mut small = truth_template.clone();
        small.sample_rate_hz = 250.0;
        small.tests = Plane::PLANAR.into_iter().map(crate::bench_test).collect();
        let mut per_sample = Vec::new();
        for (name, truth) in [("12 runs, 250 Hz", &small), ("6 runs of 377 s at 1 kHz", &long)] {
            let d = dir.join("scale-session");
            let n = write_session(spec, truth, &d)?;
            let read = child_peak("read", &d)?;
            let fit = child_peak("fit", &d)?;
            let b = fit as f64 / n as f64;
            println!(
                "{name:<52} {n:>9} {:>10.1} {:>10.1} {b:>12.1}",
                read as f64 / 1e6,
                fit as f64 / 1e6
            );
            per_sample.push((name, b, fit as f64 / read as f64));
            let _ = std::fs::remove_dir_all(&d);
        }
        for (name, b, ratio) in per_sample {
            println!(
                "  {name}: fit peak {b:.0} B/sample, {ratio:.2}× the peak of reading the same runs"
            );
        }
    }
    println!(
        "\nscale: diagnose wall time against the 12-run session (2 threads, 50 Hz, R = 100 mm)"
    );
    println!("{:<30} {:>9} {:>10} {:>12}", "session", "samples", "s", "× 12 runs");
    let mut base = None;
    for repeats in [2, 17, 167] {
        let mut truth = truth_template.clone();
        truth.sample_rate_hz = 50.0;
        truth.tests = Plane::PLANAR
            .into_iter()
            .map(|p| ballbar_sim::TestSpec { repeats, ..crate::bench_test(p) })
            .collect();
        let runs = ballbar_sim::simulate(spec, &truth, 0.0, 5)?.runs;
        let n: usize = runs.iter().map(|r| r.len()).sum();
        let t = Instant::now();
        diagnose(
            spec,
            ModelOptions::default(),
            &ballbar_model::NoKernels,
            &runs,
            Options { threads: 2, ..Options::default() },
        )?;
        let s = t.elapsed().as_secs_f64();
        let b = *base.get_or_insert(s);
        println!("{:<30} {n:>9} {s:>10.2} {:>12.1}", format!("{} runs", runs.len()), s / b);
    }
    Ok(())
}

//! Measurements of the archive: size per 10,000 samples against the run CSV, record time,
//! read time, and replay throughput (read + refit) in runs per second for ~10,000-sample runs.
//! Baselines in the same process: writing and reading the same runs as CSV files.

use std::path::Path;

use anyhow::Result;
use ballbar_archive::{
    ArchivedFit, ArchivedMachine, ArchivedRun, Attachment, Existing, Session, SessionInfo,
};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, Run};

use crate::time;

/// Print the archive and report measurements.
pub fn run(
    spec: &MachineSpec,
    runs: &[Run],
    files: &[std::path::PathBuf],
    dir: &Path,
) -> Result<()> {
    let reps = 5;
    let samples: usize = runs.iter().map(Run::len).sum();
    let per10k = |x: f64| x / (samples as f64 / 1e4);
    let model = Model::new(spec.clone(), ModelOptions::default())?;
    let fit = ballbar_fit::fit(&Design::new(&model, runs)?, 2)?;
    let attachments: Vec<Attachment> = files
        .iter()
        .map(|f| Ok(Attachment::csv(&f.file_name().unwrap().to_string_lossy(), std::fs::read(f)?)))
        .collect::<Result<_>>()?;
    let csv_bytes: usize = attachments.iter().map(|a| a.data.len()).sum();
    let session = |with_fit: bool, with_files: bool| Session {
        info: SessionInfo::now("bench", &spec.name, "xtask bench"),
        runs: runs.iter().cloned().map(ArchivedRun::new).collect(),
        machine: with_fit.then(|| ArchivedMachine {
            spec: spec.clone(),
            options: ModelOptions::default(),
            plugin_name: spec.name.clone(),
            plugin_version: spec.version.clone(),
            machine_file: None,
        }),
        fit: with_fit.then(|| ArchivedFit::from_fit(&fit)),
        diagnosis: None,
        attachments: if with_files { attachments.clone() } else { vec![] },
    };
    let (raw, full) = (session(false, false), session(true, true));
    let path = dir.join("bench.mcap");
    // Baseline: the runs written as CSV files, then read back.
    let (csv_write, written) = time(reps, || {
        runs.iter()
            .zip(files)
            .try_for_each(|(r, f)| ballbar_io::write_run_rounded(r, f, Existing::Replace))
    });
    written?;
    let (csv_read, read) = time(reps, || ballbar_cli::read_runs(files, 1).map(|r| r.len()));
    anyhow::ensure!(
        read.is_ok_and(|n| n == runs.len()),
        "the CSV baseline failed to read the runs back"
    );
    let (write_raw, stats_raw) =
        time(reps, || ballbar_archive::write(&path, &raw, Existing::Replace));
    let stats_raw = stats_raw?;
    let (write_full, stats_full) =
        time(reps, || ballbar_archive::write(&path, &full, Existing::Replace));
    let stats_full = stats_full?;
    let (read_full, back) = time(reps, || ballbar_archive::read(&path));
    let back = back?;
    // Replay: read, rebuild the model from the archived description, refit.
    let (replay, rank) = time(reps, || -> Result<usize> {
        let s = ballbar_archive::read(&path)?;
        let m = s.machine.as_ref().expect("archived machine");
        let model = Model::new(m.spec.clone(), m.options)?;
        let runs: Vec<Run> = s.runs.into_iter().map(|r| r.run).collect();
        Ok(ballbar_fit::fit(&Design::new(&model, &runs)?, 2)?.rank)
    });
    rank?;
    let (fit_only, _) = time(reps, || {
        ballbar_fit::fit(&Design::new(&model, runs).expect("design"), 2).map(|f| f.rank)
    });
    assert_eq!(back.runs.len(), runs.len());
    println!(
        "\narchive ({} runs of {} samples, {samples} samples; median of {reps}; 1 writer thread, fit on 2)",
        runs.len(),
        samples / runs.len()
    );
    println!("{:<52} {:>12} {:>14}", "size", "bytes / 10k", "× CSV");
    for (name, b) in [
        ("run CSV files (baseline)", csv_bytes as f64),
        ("archive: raw runs", stats_raw.bytes as f64),
        ("archive: runs + CSV attachments + machine + fit", stats_full.bytes as f64),
    ] {
        println!("{name:<52} {:>12.0} {:>14.2}", per10k(b), b / csv_bytes as f64);
    }
    println!("{:<52} {:>12} {:>14}", "time", "ms / 10k", "× baseline");
    for (name, ms, base) in [
        ("write the CSV files (baseline)", csv_write, csv_write),
        ("record: raw runs", write_raw, csv_write),
        ("record: runs + attachments + machine + fit", write_full, csv_write),
        ("parse the CSV files (baseline)", csv_read, csv_read),
        ("read the full archive (CRCs checked)", read_full, csv_read),
    ] {
        println!("{name:<52} {:>12.2} {:>14.2}", per10k(ms), ms / base);
    }
    let rps = |ms: f64| runs.len() as f64 / (ms / 1e3);
    println!(
        "replay (read + rebuild the model + refit): {replay:.0} ms for {} runs = {:.0} runs/s (the fit alone from memory: {:.0} runs/s); target ≥ 50 runs/s",
        runs.len(),
        rps(replay),
        rps(fit_only)
    );
    let _ = std::fs::remove_file(&path);

    // The HTML report of the same 12 runs, diagnosed and archived as `diagnose --record`
    // archives them.
    let d = ballbar_diagnose::diagnose(
        spec,
        ModelOptions::default(),
        &ballbar_model::NoKernels,
        runs,
        ballbar_diagnose::Options::default(),
    )?;
    let diag = dir.join("diagnosed.mcap");
    let mut s = session(true, true);
    s.fit = Some(ArchivedFit::from_fit(&d.base));
    s.diagnosis = Some(serde_json::to_value(ballbar_cli::diagnosis::document(&d, runs))?);
    ballbar_archive::write(&diag, &s, Existing::Replace)?;
    let reg = ballbar_cli::registry(&[]).map_err(|_| anyhow::anyhow!("plugins"))?;
    let out = dir.join("report");
    let (read_ms, session) = time(reps, || ballbar_archive::read(&diag));
    let session = session?;
    let (build_ms, page) =
        time(reps, || ballbar_report::build("bench", &session, &ballbar_model::NoKernels, &[]));
    let page = page?;
    let (total_ms, written) =
        time(reps, || ballbar_cli::report_cmd(&diag, &out, None, true, &reg).is_ok());
    anyhow::ensure!(written, "report failed");
    println!(
        "report of the {} diagnosed runs: read the archive {read_ms:.0} ms, build the page (refit included) {build_ms:.0} ms, end to end with the write {total_ms:.0} ms (target < 500 ms); page {:.0} kB",
        runs.len(),
        page.html.len() as f64 / 1e3
    );
    Ok(())
}

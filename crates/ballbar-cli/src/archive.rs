//! The archive commands: `--record` on `fit` and `diagnose`, `record`, `replay`, `export`,
//! `history`. The recorder is an observer: it takes what a command computed (runs, machine,
//! fit, diagnosis JSON) and writes it with [`ballbar_archive::write`]; the fitting code knows
//! nothing of it.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use ballbar_archive::{
    ArchivedFit, ArchivedMachine, ArchivedRun, Attachment, Session, SessionInfo, TextFile,
};
use ballbar_fit::{Fit, fit};
use ballbar_model::machine::{Model, ModelOptions, TermSpec};
use ballbar_model::{Design, KernelSource, Run};
use ballbar_plugin_host::Registry;

use crate::{Failure, MachineArgs, Result, diagnosis, machine};

/// Relative agreement at which a replayed number is the archived one: the same code on the
/// same data reproduces the numbers to rounding; a number that differs by more was computed
/// differently.
pub const SAME: f64 = 1e-12;

/// The command line of the command being run (set by [`crate::main_with_args`]), for the
/// archive's metadata; arguments that are not UTF-8 are shown lossily.
pub static COMMAND: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// `args` as one line, quoting arguments with spaces.
pub fn command_text(args: &[std::ffi::OsString]) -> String {
    args.iter()
        .map(|a| {
            let a = a.to_string_lossy();
            if a.contains(' ') { format!("'{a}'") } else { a.into_owned() }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

fn command_line() -> String {
    COMMAND.get().cloned().unwrap_or_else(|| command_text(&std::env::args_os().collect::<Vec<_>>()))
}

/// The command's `--require-crc` (set by [`require_crc`] as the command line is read, as
/// [`COMMAND`] is): an archive whose records carry no checksums is then refused.
static REQUIRE_CRC: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Set the command's `--require-crc`.
pub fn require_crc(on: bool) {
    REQUIRE_CRC.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// Say when an archive's records carry no checksums (MCAP allows a CRC of 0, "not
/// computed": a file whose CRCs were set to 0 after editing reads as if intact), naming what no
/// checksum covers; with `--require-crc` that is an error, after which `outcome` says what was
/// not done.
pub(crate) fn checksums(
    path: &Path,
    sums: &ballbar_archive::Checksums,
    outcome: &str,
) -> Result<()> {
    let parts = sums.unchecked();
    if parts.is_empty() {
        return Ok(());
    }
    let what = format!(
        "{}: its records carry no checksums: damage cannot be detected in {}",
        path.display(),
        parts.join(", ")
    );
    if REQUIRE_CRC.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(Failure::Input(anyhow!("{what}; --require-crc refuses it: {outcome}")));
    }
    eprintln!("warning: {what}");
    Ok(())
}

/// Read a whole archive for a command: a damaged one is refused (saying that `export
/// --partial` recovers its intact runs, and `outcome`), one without checksums is said so
/// ([`checksums`]).
pub(crate) fn read_session(path: &Path, outcome: &str) -> Result<Session> {
    let (session, sums) = ballbar_archive::read_with_checksums(path)
        .map_err(|e| damaged_archive_error(path, e, outcome))?;
    checksums(path, &sums, outcome)?;
    Ok(session)
}

/// An archive error as a command failure (wrong input: exit 1).
fn archive_error(e: ballbar_archive::ArchiveError) -> Failure {
    Failure::Input(anyhow!(e))
}

/// The machine of a command as archived: its description, options, plugin and (for a user's
/// chain file) the file's text.
pub fn archived_machine(
    m: &crate::Machine,
    options: ModelOptions,
    args: &MachineArgs,
) -> Result<ArchivedMachine> {
    let machine_file = match &args.machine_file {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|e| anyhow!("{}: {e}", p.display()))?;
            let name = p
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| p.display().to_string());
            Some(TextFile { name, text })
        }
        None => None,
    };
    Ok(ArchivedMachine {
        spec: m.spec.clone(),
        options,
        plugin_name: m.plugin.name().to_string(),
        plugin_version: m.plugin.version().to_string(),
        machine_file,
    })
}

/// Write a session: the runs (and their files as attachments), and what was computed. The
/// archive (checked before any work by [`crate::outputs::check`]) replaces a file only with
/// `force`: an archive holds a session that may exist nowhere else (a fit of runs since
/// deleted), and one written over another loses it without a word; without `force` an archive
/// another command wrote there meanwhile is kept.
pub fn record(
    (out, force): (&Path, bool),
    runs: &[Run],
    machine: Option<ArchivedMachine>,
    fit: Option<&Fit>,
    diagnosis: Option<serde_json::Value>,
) -> Result<()> {
    let session = session(runs, machine, fit, diagnosis)?;
    let stats = ballbar_archive::write(out, &session, crate::outputs::existing(force)).map_err(
        |e| {
            let taken = matches!(&e, ballbar_archive::ArchiveError::Io { error, .. } if error.kind() == std::io::ErrorKind::AlreadyExists);
            Failure::Input(anyhow!("{e}{}", crate::outputs::appeared(taken, force)))
        },
    )?;
    eprintln!(
        "recorded {} runs ({} samples) in {} ({} bytes)",
        stats.runs,
        stats.samples,
        out.display(),
        stats.bytes
    );
    Ok(())
}

/// A session of the runs and what was computed, with the files the runs came from attached
/// (each file once: a `.b5r` file holds several runs).
pub fn session(
    runs: &[Run],
    machine: Option<ArchivedMachine>,
    fit: Option<&Fit>,
    diagnosis: Option<serde_json::Value>,
) -> Result<Session> {
    let mut attachments: Vec<Attachment> = Vec::with_capacity(runs.len());
    let mut archived = Vec::with_capacity(runs.len());
    let mut attached: Vec<&str> = Vec::new();
    for run in runs {
        let name = Path::new(&run.source)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| run.source.clone());
        let vendor = ballbar_io::b5r::is_b5r(Path::new(&run.source));
        if vendor {
            // The runs of a vendor file are exported as run CSVs named by their run id.
            archived
                .push(ArchivedRun { run: run.clone(), file_name: format!("{}.csv", run.name()) });
        } else {
            archived.push(ArchivedRun::new(run.clone()));
        }
        if attached.contains(&run.source.as_str()) {
            continue;
        }
        attached.push(&run.source);
        let bytes = std::fs::read(&run.source)
            .map_err(|e| anyhow!("{}: cannot read it again to archive it: {e}", run.source))?;
        // The file as attached must be the runs as fitted: a file changed since it was read is
        // not archived beside numbers it did not give.
        let text = std::str::from_utf8(&bytes).ok();
        let again: Vec<Run> = if vendor {
            // Read again as it was read: its circle centre and the spacing its header states.
            let angles = ballbar_io::b5r::SpacingMode::of(run)
                .map_or(Default::default(), ballbar_io::b5r::SpacingMode::reread_with);
            let options = ballbar_io::b5r::B5rOptions {
                pivot_mm: Some(run.header.pivot_mm),
                tool_ball_mm: None,
                angles,
            };
            text.and_then(|t| ballbar_io::b5r::parse_b5r(t, &run.source, &options).ok())
                .map(|t| t.runs)
                .unwrap_or_default()
        } else {
            text.and_then(|t| ballbar_io::parse_run(t, &run.source).ok()).into_iter().collect()
        };
        let ours = runs.iter().filter(|r| r.source == run.source);
        let unchanged = again.len() == ours.clone().count()
            && again
                .iter()
                .zip(ours)
                .all(|(a, r)| a.t_s == r.t_s && a.dr_mm == r.dr_mm && a.axes == r.axes);
        if !unchanged {
            return Err(Failure::Input(anyhow!(
                "{}: the file changed since it was read; nothing archived",
                run.source
            )));
        }
        attachments.push(if vendor {
            Attachment { name, media_type: "application/xml".into(), data: bytes }
        } else {
            Attachment::csv(&name, bytes)
        });
    }
    let machine_name = machine
        .as_ref()
        .map(|m| m.spec.name.clone())
        .or_else(|| runs.iter().find_map(|r| r.header.machine.clone()))
        .unwrap_or_default();
    Ok(Session {
        info: SessionInfo::now(env!("CARGO_PKG_VERSION"), &machine_name, &command_line()),
        runs: archived,
        machine,
        fit: fit.map(ArchivedFit::from_fit),
        diagnosis,
        attachments,
    })
}

/// `ballbar record RUN... --out FILE.mcap`: raw runs alone.
pub fn record_cmd(
    run_paths: &[PathBuf],
    placement: crate::inputs::Placement,
    angles: crate::inputs::Angles,
    out: &Path,
    force: bool,
    reg: &Registry,
) -> Result<()> {
    let read: Vec<PathBuf> =
        crate::inputs::files(run_paths)?.into_iter().chain(crate::outputs::loaded(reg)).collect();
    crate::outputs::check(&[crate::outputs::Output::new(out, "--out")], &read, force, "outputs")?;
    let inputs = crate::inputs::read(run_paths, 2, placement, angles.spacing())?;
    if let Some(note) = crate::inputs::pivot_note(&inputs) {
        eprintln!("{note}");
    }
    record((out, force), &inputs.runs, None, None, None)
}

/// A failed read of an archive as a command failure (exit 1), saying that `export --partial`
/// recovers its intact runs (or that none is intact) when it is damaged.
pub(crate) fn damaged_archive_error(
    path: &Path,
    e: ballbar_archive::ArchiveError,
    outcome: &str,
) -> Failure {
    let Some(readable) = e.readable() else { return archive_error(e) };
    let intact = readable.complete_runs();
    let hint = if intact == 0 {
        "no run is intact in it, so `ballbar export --partial` would recover none".to_string()
    } else {
        let noun = if intact == 1 { "run" } else { "runs" };
        format!(
            "`ballbar export {} --out DIR --partial` writes its {intact} intact {noun} and names what was lost",
            path.display()
        )
    };
    Failure::Input(anyhow!("{e}\n{outcome}; {hint}"))
}

/// `ballbar export FILE.mcap --out DIR [--partial]`: the runs back as run CSVs, each value as
/// archived ([`ballbar_io::exact_text`]: the text reads back bit for bit, or nothing is written).
///
/// A damaged archive (cut short, a checksum mismatch) is refused, exit 1, nothing written,
/// unless `partial`: then every run read whole is written, what was lost is named (runs
/// missing or cut short, machine, fit, residuals, diagnosis, attachments), and the command
/// succeeds (exit 0) when at least one run was written; a run cut short is never written.
pub fn export(path: &Path, out: &Path, partial: bool, force: bool, reg: &Registry) -> Result<()> {
    let (runs, damage, lost) = if partial {
        let r = ballbar_archive::read_partial(path).map_err(archive_error)?;
        checksums(path, &r.checksums, "nothing was written")?;
        let lost = r.lost();
        (r.runs, r.damage, lost)
    } else {
        let session = read_session(path, "nothing was written")?;
        (session.runs, None, Vec::new())
    };
    if let Some(e) = &damage
        && runs.is_empty()
    {
        return Err(Failure::Input(anyhow!(
            "{e}\nnothing was written: no run is intact in the archive"
        )));
    }
    let total = damage
        .as_ref()
        .and_then(|e| e.readable())
        .and_then(|r| r.runs_expected)
        .unwrap_or(runs.len());
    // Each run's text is read back before anything is written: a run that would not come back
    // bit for bit (a value a run CSV cannot hold) is an error, and no file is written.
    let mut texts: Vec<String> = Vec::with_capacity(runs.len());
    for r in &runs {
        let text = ballbar_io::exact_text(&r.run).map_err(|why| {
            Failure::Input(anyhow!(
                "{}: run {} cannot be exported as {}: {why}; nothing was written",
                path.display(),
                r.run.name(),
                r.file_name
            ))
        })?;
        texts.push(text);
    }
    let mut seen = std::collections::HashSet::new();
    for r in &runs {
        if !seen.insert(&r.file_name) {
            return Err(Failure::Input(anyhow!(
                "{}: two runs were read from files named {}; export would write one over the other",
                path.display(),
                r.file_name
            )));
        }
    }
    let targets: Vec<crate::outputs::Output> =
        runs.iter().map(|r| crate::outputs::Output::new(out.join(&r.file_name), "--out")).collect();
    let read: Vec<PathBuf> =
        std::iter::once(path.to_path_buf()).chain(crate::outputs::loaded(reg)).collect();
    crate::outputs::check(&targets, &read, force, "runs")?;
    let files: Vec<(PathBuf, String)> = targets.iter().map(|t| t.path.clone()).zip(texts).collect();
    std::fs::create_dir_all(out)
        .map_err(|e| anyhow!("{}: cannot create the folder: {e}", out.display()))?;
    crate::outputs::write_all(&files, force)?;
    match &damage {
        None => outln!("wrote {} runs from {} to {}", files.len(), path.display(), out.display()),
        Some(e) => {
            let names: Vec<&str> = runs.iter().map(|r| r.file_name.as_str()).collect();
            outln!(
                "wrote {} of the {total} runs of {} to {} ({}): {}",
                files.len(),
                path.display(),
                out.display(),
                names.join(", "),
                e.problem()
            );
            if lost.is_empty() {
                outln!(
                    "lost: nothing the archive announces (every run, and the machine, fit, diagnosis and attachments it holds, were read whole); only the end of the file is damaged"
                );
            } else {
                outln!("lost: {}", lost.join(", "));
            }
        }
    }
    Ok(())
}

/// One parameter's difference between the archive and the replay (display units).
struct Difference {
    id: String,
    unit: String,
    /// Value and u (display units), whether the fit estimates it, whether a gauge fixes it.
    archived: Option<(f64, f64, bool, bool)>,
    replayed: Option<(f64, f64, bool, bool)>,
}

/// Whether two numbers agree to [`SAME`] (both non-finite alike counts as agreeing).
fn same(a: f64, b: f64) -> bool {
    if !a.is_finite() || !b.is_finite() {
        return a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
    }
    (a - b).abs() <= SAME * a.abs().max(b.abs())
}

/// The parameters (values and uncertainties) that differ.
fn compare_fits(old: &ArchivedFit, new: &ArchivedFit) -> Vec<Difference> {
    let disp = |p: &ballbar_archive::FitParameter| {
        (p.value * p.display_factor, p.std_uncertainty * p.display_factor, p.estimable, p.fixed)
    };
    let mut out = Vec::new();
    for p in &old.parameters {
        match new.parameters.iter().find(|q| q.id == p.id) {
            Some(q) if same(p.value, q.value) && same(p.std_uncertainty, q.std_uncertainty) => {}
            Some(q) => out.push(Difference {
                id: p.id.clone(),
                unit: p.unit.clone(),
                archived: Some(disp(p)),
                replayed: Some(disp(q)),
            }),
            None => out.push(Difference {
                id: p.id.clone(),
                unit: p.unit.clone(),
                archived: Some(disp(p)),
                replayed: None,
            }),
        }
    }
    for q in new.parameters.iter().filter(|q| !old.parameters.iter().any(|p| p.id == q.id)) {
        out.push(Difference {
            id: q.id.clone(),
            unit: q.unit.clone(),
            archived: None,
            replayed: Some(disp(q)),
        });
    }
    out
}

/// What [`compare_json`] leaves out of the differences: what a newer version of this program
/// writes that the archive's version did not.
#[derive(Default)]
struct NotCompared {
    /// Fields the archived JSON does not have (added since its version).
    new_fields: Vec<String>,
    /// Texts for a reader ([`PROSE_KEYS`]) worded differently; every other string (a kind, an
    /// axis, a plane, a run, the base parameters an effect hides in) is compared.
    reworded: Vec<String>,
}

/// The keys of the diagnosis JSON whose strings are sentences for a reader, which a newer
/// version may word differently: not compared.
const PROSE_KEYS: [&str; 6] =
    ["description", "note", "notes", "why", "test_to_separate", "cross_validation"];

/// The differences between an archived JSON `a` and a recomputed `b`, each a line naming its
/// path: numbers beyond [`SAME`], identifiers, structure, fields `b` lacks; what `b` adds and
/// what it words differently go to `skipped`.
fn compare_json(
    path: &str,
    a: &serde_json::Value,
    b: &serde_json::Value,
    out: &mut Vec<String>,
    skipped: &mut NotCompared,
) {
    compare_under("", path, a, b, out, skipped);
}

/// [`compare_json`] of values under the object key `key` (the nearest one: an array's elements
/// are under their array's key).
fn compare_under(
    key: &str,
    path: &str,
    a: &serde_json::Value,
    b: &serde_json::Value,
    out: &mut Vec<String>,
    skipped: &mut NotCompared,
) {
    use serde_json::Value;
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap_or(f64::NAN), y.as_f64().unwrap_or(f64::NAN));
            if !same(x, y) {
                out.push(format!("{path}: {x} → {y}"));
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            if x.len() != y.len() {
                out.push(format!("{path}: {} entries → {}", x.len(), y.len()));
            }
            for (k, (p, q)) in x.iter().zip(y).enumerate() {
                compare_under(key, &format!("{path}[{k}]"), p, q, out, skipped);
            }
        }
        (Value::Object(x), Value::Object(y)) => {
            for (k, v) in x {
                match y.get(k) {
                    Some(w) => compare_under(k, &format!("{path}.{k}"), v, w, out, skipped),
                    None => out.push(format!("{path}.{k}: present → absent")),
                }
            }
            skipped
                .new_fields
                .extend(y.keys().filter(|k| !x.contains_key(*k)).map(|k| format!("{path}.{k}")));
        }
        (Value::String(x), Value::String(y)) if x != y && PROSE_KEYS.contains(&key) => {
            skipped.reworded.push(path.to_string())
        }
        _ if a == b => {}
        _ => out.push(format!("{path}: {a} → {b}")),
    }
}

/// `ballbar replay FILE.mcap [--machine …] [--json OUT]`: refit (and re-diagnose when the
/// archive holds a diagnosis) from the archived runs, with the archived machine or the one
/// given, and say what changed.
pub fn replay(
    path: &Path,
    other: Option<&MachineArgs>,
    threads: usize,
    json_out: Option<(&Path, bool)>,
    reg: &Registry,
) -> Result<()> {
    let outs = crate::outputs::files([(json_out.map(|j| j.0), "--json")]);
    let read: Vec<PathBuf> = std::iter::once(path.to_path_buf())
        .chain(other.and_then(|m| m.machine_file.clone()))
        .chain(crate::outputs::loaded(reg))
        .collect();
    crate::outputs::check(&outs, &read, json_out.is_some_and(|j| j.1), "outputs")?;
    let session = read_session(path, "a replay needs the whole archive: nothing was replayed")?;
    let runs: Vec<Run> = session.runs.iter().map(|r| r.run.clone()).collect();
    let info = &session.info;
    outln!(
        "archive {}: {} runs, recorded by ballbar {} ({})",
        path.display(),
        runs.len(),
        info.software_version,
        info.command
    );
    if let Some(note) = crate::inputs::geometry_note(&runs) {
        outln!("{note}");
    }
    // The model: the one given, or the archived description (a plugin is needed again only for
    // kernel terms).
    let (spec, options, kernels, described): (
        _,
        _,
        std::sync::Arc<dyn KernelSource + Send + Sync>,
        String,
    ) = match (other, &session.machine) {
        (Some(args), archived) => {
            let m = machine(args, reg)?;
            let options = archived.as_ref().map(|a| a.options).unwrap_or_default();
            let text = format!(
                "machine '{}' {} from plugin '{}' {} (given)",
                m.spec.name,
                m.spec.version,
                m.plugin.name(),
                m.plugin.version()
            );
            (m.spec.clone(), options, m.plugin.clone(), text)
        }
        (None, Some(a)) => {
            let needs = a.spec.terms.iter().any(|t| matches!(t, TermSpec::Kernel { .. }));
            let kernels: std::sync::Arc<dyn KernelSource + Send + Sync> = if needs {
                reg.find(&a.plugin_name).cloned().ok_or_else(|| {
                    Failure::Input(anyhow!("{}: the archived machine's kernel terms need plugin '{}' {}, which is not loaded (looked in: {})", path.display(), a.plugin_name, a.plugin_version, reg.searched_text()))
                })? as _
            } else {
                std::sync::Arc::new(ballbar_model::NoKernels)
            };
            let now = reg
                .find(&a.plugin_name)
                .map(|p| format!("; plugin now {}", p.version()))
                .unwrap_or_default();
            let text = format!(
                "machine '{}' {} as archived (plugin '{}' {}{now})",
                a.spec.name, a.spec.version, a.plugin_name, a.plugin_version
            );
            (a.spec.clone(), a.options, kernels, text)
        }
        (None, None) => {
            return Err(Failure::Input(anyhow!(
                "{}: the archive holds raw runs only (no machine); give --machine or --machine-file to fit them",
                path.display()
            )));
        }
    };
    outln!("{described}");
    let model = Model::with_kernels(spec.clone(), options, &*kernels)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    let failure = |e: ballbar_fit::FitError| match e {
        ballbar_fit::FitError::NonFinite => crate::inputs::no_finite_fit(e, &runs),
        e => Failure::Input(e.into()),
    };
    // As `fit` does: the backlash switches at the lagged reversals.
    let (design, _) =
        ballbar_fit::switch::switch_at_lagged_reversals(Design::new(&model, &runs)?, threads)
            .map_err(failure)?;
    let f = fit(&design, threads).map_err(failure)?;
    let new_fit = ArchivedFit::from_fit(&f);
    let mut report = serde_json::Map::new();
    match &session.fit {
        Some(old) => {
            let diffs = compare_fits(old, &new_fit);
            if diffs.is_empty() {
                outln!(
                    "fit: identical ({} parameters within {SAME:e} relative, values and uncertainties)",
                    old.parameters.len()
                );
            } else {
                outln!(
                    "fit: {} of {} parameters differ (display units; value ± standard uncertainty)",
                    diffs.len(),
                    old.parameters.len().max(new_fit.parameters.len())
                );
                outln!(
                    "  {:<22} {:>26} {:>26} {:>12}",
                    "parameter",
                    "archived",
                    "replayed",
                    "change"
                );
                // A parameter the fit does not estimate is worded as `fit` words it: its
                // value is a choice, not a result.
                let show = |v: Option<(f64, f64, bool, bool)>, unit: &str| match v {
                    Some((x, u, true, _)) => format!("{x:.4} ± {u:.4} {unit}"),
                    Some((_, _, false, fixed)) => {
                        ballbar_report::wording::not_estimated_archived(fixed).to_string()
                    }
                    None => "—".into(),
                };
                for d in &diffs {
                    let change = match (d.archived, d.replayed) {
                        (Some(a), Some(b)) if a.2 && b.2 => format!("{:+.4}", b.0 - a.0),
                        _ => String::new(),
                    };
                    outln!(
                        "  {:<22} {:>26} {:>26} {:>12}",
                        d.id,
                        show(d.archived, &d.unit),
                        show(d.replayed, &d.unit),
                        change
                    );
                }
            }
            let rows: Vec<serde_json::Value> = diffs
                .iter()
                .map(|d| serde_json::json!({"id": d.id, "unit": d.unit, "archived": d.archived.map(|v| [v.0, v.1]), "replayed": d.replayed.map(|v| [v.0, v.1])}))
                .collect();
            report.insert(
                "fit".into(),
                serde_json::json!({"identical": diffs.is_empty(), "differences": rows}),
            );
        }
        None => {
            outln!(
                "fit: the archive holds none; the replayed fit has {} parameters, σ {:.3} µm",
                new_fit.parameters.len(),
                f.sigma_mm * 1e3
            );
            report.insert("fit".into(), serde_json::json!({"identical": null, "differences": []}));
        }
    }
    if let Some(old) = &session.diagnosis {
        let d = ballbar_diagnose::diagnose(
            &spec,
            options,
            &*kernels,
            &runs,
            ballbar_diagnose::Options { threads, ..Default::default() },
        )
        .map_err(|e| Failure::Input(e.into()))?;
        let mut new = crate::to_value(&diagnosis::document(&d, &runs))?;
        // The comparison with a vendor's analysis is made beside the diagnosis from the input
        // files, not by it (the page rebuilds it from the attached files): left out here. What
        // was assumed is stated from the archived runs beside the diagnosis (in the report
        // below).
        let mut old = old.clone();
        for v in [&mut old, &mut new] {
            if let Some(o) = v.as_object_mut() {
                o.remove("vendor_comparison");
                o.remove("assumed");
            }
        }
        let mut diffs = Vec::new();
        let mut skipped = NotCompared::default();
        compare_json("", &old, &new, &mut diffs, &mut skipped);
        let not_compared = match (skipped.new_fields.len(), skipped.reworded.len()) {
            (0, 0) => String::new(),
            (n, w) => format!(
                "; not compared: {n} fields this version adds, {w} texts it words differently"
            ),
        };
        if diffs.is_empty() {
            outln!("diagnosis: identical (every number within {SAME:e} relative{not_compared})");
        } else {
            outln!("diagnosis: {} differences{not_compared}", diffs.len());
            for x in diffs.iter().take(40) {
                outln!("  {x}");
            }
            if diffs.len() > 40 {
                outln!("  … and {} more", diffs.len() - 40);
            }
        }
        report.insert(
            "diagnosis".into(),
            serde_json::json!({"identical": diffs.is_empty(), "differences": diffs, "not_compared": {"new_fields": skipped.new_fields, "reworded": skipped.reworded}}),
        );
    }
    report.insert("assumed".into(), crate::to_value(&ballbar_report::assumed::entries(&runs))?);
    if let Some((p, force)) = json_out {
        crate::write_json(p, &serde_json::Value::Object(report), force)?;
    }
    Ok(())
}

/// One archive's place in a machine's history.
struct Entry {
    file: PathBuf,
    /// The session's start (its earliest run), s since 1970, and as written.
    start_unix_s: f64,
    start: String,
    fit: ArchivedFit,
}

/// A change between consecutive sessions is flagged beyond this many combined standard
/// uncertainties: the rule is `ballbar_report::history`'s, shared with the report's trend plots.
pub use ballbar_report::history::HISTORY_K;

/// Whether the archive `file` is a session of its own in a history ([`history::Sessions`]):
/// `false`, with a note, for the same runs as a session taken before; a warning when it shares
/// some of its runs with one.
pub fn take_session(
    sessions: &mut ballbar_report::history::Sessions,
    file: &Path,
    s: &ballbar_archive::Session,
) -> bool {
    use ballbar_report::history::Taken;
    let runs: Vec<&Run> = s.runs.iter().map(|r| &r.run).collect();
    match sessions.take(&file.display().to_string(), &runs) {
        Taken::New => true,
        Taken::Shares(why) => {
            eprintln!("warning: {why}");
            true
        }
        Taken::Same(why) => {
            eprintln!("note: {why}");
            false
        }
    }
}

/// The archives of a folder (`*.mcap`), by name: what `history` and `report --history` read.
pub(crate) fn files_of(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| anyhow!("{}: cannot list the folder: {e}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|f| f.extension().is_some_and(|x| x == "mcap"))
        .collect();
    files.sort();
    Ok(files)
}

/// `ballbar history DIR [--csv]`: every archive of the folder, per machine in date order, each
/// machine parameter's values, changes flagged beyond their uncertainties, and its trend; an
/// archive of the same runs as another is one session, counted once.
pub fn history(dir: &Path, csv: bool) -> Result<()> {
    use ballbar_report::history::{self, Estimate};
    let files = files_of(dir)?;
    if files.is_empty() {
        return Err(Failure::Input(anyhow!(
            "{}: no *.mcap archives in this folder",
            dir.display()
        )));
    }
    let mut machines: Vec<(String, Vec<Entry>)> = Vec::new();
    let mut unreadable = 0;
    let mut sessions = history::Sessions::default();
    for file in files {
        // One damaged archive does not hide the others: it is named and left out.
        let s = match ballbar_archive::read_with_checksums(&file) {
            Ok((s, sums)) => {
                checksums(&file, &sums, "no history was written")?;
                s
            }
            Err(e) => {
                eprintln!("warning: left out of the history: {e}");
                unreadable += 1;
                continue;
            }
        };
        if s.fit.is_none() {
            eprintln!("note: {}: raw runs only (no fit), not in the history", file.display());
            continue;
        }
        if !take_session(&mut sessions, &file, &s) {
            continue;
        }
        let Some(fit) = s.fit else { continue };
        let first = s
            .runs
            .iter()
            .map(|r| &r.run.header)
            .min_by(|a, b| a.started_at_unix_s.total_cmp(&b.started_at_unix_s));
        let Some(first) = first else {
            return Err(Failure::Input(anyhow!("{}: the archive holds no runs", file.display())));
        };
        let name =
            s.machine.as_ref().map(|m| m.spec.name.clone()).unwrap_or(s.info.machine_name.clone());
        let entry = Entry {
            file,
            start_unix_s: first.started_at_unix_s,
            start: first.started_at.clone(),
            fit,
        };
        match machines.iter_mut().find(|m| m.0 == name) {
            Some(m) => m.1.push(entry),
            None => machines.push((name, vec![entry])),
        }
    }
    if machines.is_empty() {
        return Err(Failure::Input(anyhow!(
            "{}: no readable archive holds a fit ({unreadable} unreadable; record sessions with `fit --record` or `diagnose --record`)",
            dir.display()
        )));
    }
    let mut text = String::new();
    if csv {
        text.push_str("machine,parameter,unit,session_start,archive,value,std_uncertainty,estimable,change,significant\n");
    }
    for (name, entries) in &mut machines {
        entries.sort_by(|a, b| a.start_unix_s.total_cmp(&b.start_unix_s));
        // Machine parameters in the order of first appearance.
        let mut ids: Vec<(String, String)> = Vec::new();
        for e in entries.iter() {
            for p in e.fit.parameters.iter().take(e.fit.n_machine) {
                if !ids.iter().any(|x| x.0 == p.id) {
                    ids.push((p.id.clone(), p.unit.clone()));
                }
            }
        }
        if !csv {
            text.push_str(&format!(
                "machine {name}: {} sessions, {} to {}; value ± standard uncertainty; * a change beyond {HISTORY_K} combined uncertainties; trend: least-squares slope per 30 days\n",
                entries.len(),
                entries.first().map(|e| e.start.as_str()).unwrap_or(""),
                entries.last().map(|e| e.start.as_str()).unwrap_or("")
            ));
            text.push_str(&format!("  {:<10} {:<6}", "parameter", "unit"));
            for e in entries.iter() {
                text.push_str(&format!(" {:>22}", e.start.get(..10).unwrap_or(&e.start)));
            }
            text.push_str(&format!(" {:>14}\n", "trend/30 d"));
        }
        for (id, unit) in &ids {
            let values: Vec<Option<(f64, f64, bool)>> = entries
                .iter()
                .map(|e| {
                    e.fit.parameters.iter().take(e.fit.n_machine).find(|p| &p.id == id).map(|p| {
                        (
                            p.value * p.display_factor,
                            p.std_uncertainty * p.display_factor,
                            p.estimable,
                        )
                    })
                })
                .collect();
            let series: Vec<Option<Estimate>> = values
                .iter()
                .map(|v| v.map(|(value, u, estimable)| Estimate { value, u, estimable }))
                .collect();
            let mut cells = Vec::new();
            let mut pts = Vec::new();
            for ((e, v), c) in entries.iter().zip(&values).zip(history::changes(&series)) {
                let (change, flagged) = (c.map(|c| c.change), c.is_some_and(|c| c.flagged));
                if let Some(b) = v
                    && b.2
                {
                    pts.push((e.start_unix_s / 86_400.0, b.0));
                }
                if csv {
                    let (val, u, est) = v
                        .map(|x| (format!("{}", x.0), format!("{}", x.1), x.2.to_string()))
                        .unwrap_or_default();
                    let archive = e
                        .file
                        .file_name()
                        .map(|n| n.to_string_lossy().into_owned())
                        .unwrap_or_default();
                    let cells = [
                        csv_field(name),
                        csv_field(id),
                        csv_field(unit),
                        csv_field(&e.start),
                        csv_field(&archive),
                        val,
                        u,
                        est,
                        change.map(|d| d.to_string()).unwrap_or_default(),
                        flagged.to_string(),
                    ];
                    text.push_str(&cells.join(","));
                    text.push('\n');
                } else {
                    cells.push(match v {
                        Some((x, u, true)) => {
                            format!("{x:.3} ± {u:.3}{}", if flagged { " *" } else { "  " })
                        }
                        Some((_, _, false)) => {
                            let fixed = e
                                .fit
                                .parameters
                                .iter()
                                .find(|p| &p.id == id)
                                .is_some_and(|p| p.fixed);
                            format!("{}  ", ballbar_report::wording::not_estimated_archived(fixed))
                        }
                        None => "—  ".into(),
                    });
                }
            }
            if !csv {
                let trend =
                    slope(&pts).map(|s| format!("{:+.3}", s * 30.0)).unwrap_or_else(|| "—".into());
                text.push_str(&format!("  {:<10} {:<6}", id, unit));
                for c in &cells {
                    text.push_str(&format!(" {c:>22}"));
                }
                text.push_str(&format!(" {trend:>14}\n"));
            }
        }
    }
    out!("{text}");
    Ok(())
}

/// A CSV field, quoted when it holds a comma, a quote or a line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Least-squares slope of (x, y) points (`None` below three points or without spread in x).
fn slope(pts: &[(f64, f64)]) -> Option<f64> {
    if pts.len() < 3 {
        return None;
    }
    let n = pts.len() as f64;
    let (mx, my) =
        (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    (sxx > 0.0).then(|| pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum::<f64>() / sxx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_replay_compares_numbers_and_identifiers_not_what_a_newer_version_adds_or_rewords() {
        let old = serde_json::json!({"effects": [{"kind": "servo_mismatch", "value_um": 9.806, "description": "servo mismatch YZ"}], "removed": 1});
        let new = serde_json::json!({"effects": [{"kind": "servo_mismatch", "value_um": 9.806 * (1.0 + 1e-13), "description": "the sum of the plane terms", "std_uncertainties": {"value_um": 0.011}}]});
        let (mut diffs, mut skipped) = (Vec::new(), NotCompared::default());
        compare_json("", &old, &new, &mut diffs, &mut skipped);
        assert_eq!(diffs, vec![".removed: present → absent".to_string()]);
        assert_eq!(skipped.new_fields, vec![".effects[0].std_uncertainties".to_string()]);
        assert_eq!(skipped.reworded, vec![".effects[0].description".to_string()]);
        // An identifier with a space in it (a base parameter an effect hides in) is compared.
        let aliased = serde_json::json!({"aliased": [{"with": ["squareness XY"]}]});
        let mut diffs = Vec::new();
        compare_json(
            "",
            &aliased,
            &serde_json::json!({"aliased": [{"with": ["squareness ZX"]}]}),
            &mut diffs,
            &mut NotCompared::default(),
        );
        assert_eq!(
            diffs,
            vec![".aliased[0].with[0]: \"squareness XY\" → \"squareness ZX\"".to_string()]
        );
        // A number beyond 1e-12 relative and an identifier are differences.
        let changed = serde_json::json!({"effects": [{"kind": "backlash", "value_um": 9.807, "description": "servo mismatch YZ"}], "removed": 1});
        let mut diffs = Vec::new();
        compare_json("", &old, &changed, &mut diffs, &mut NotCompared::default());
        assert_eq!(
            diffs,
            vec![
                ".effects[0].kind: \"servo_mismatch\" → \"backlash\"".to_string(),
                ".effects[0].value_um: 9.806 → 9.807".to_string()
            ]
        );
    }
}

//! The `ballbar` command (`shared/spec/cli.md`): simulate, fit, predict, plugins. Exit codes:
//! 0 success, 1 wrong input (the message names file, line and problem), 2 usage, 3 internal.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, Context};
use ballbar_fit::saved::{SavedModel, SAVED_MODEL_FORMAT};
use ballbar_fit::{fit, metrics, quantity, Fit};
use ballbar_model::machine::{BarLength, MachineSpec, Model, ModelOptions, ServoVariant};
use ballbar_model::{paper, Design, Direction, ParamClass, Run, TermClass};
use clap::{Parser, Subcommand, ValueEnum};

mod report;

/// A failure and its exit code.
#[derive(Debug)]
pub enum Failure {
    /// The input is wrong: exit 1.
    Input(anyhow::Error),
    /// Something failed inside: exit 3.
    Internal(anyhow::Error),
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(e: E) -> Failure {
        Failure::Input(e.into())
    }
}

type Result<T> = std::result::Result<T, Failure>;

#[derive(Parser, Debug)]
#[command(name = "ballbar", version, about = "Ballbar volumetric error assessment of CNC machine tools")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
enum Servo {
    /// One lag per axis (ms): consistent across planes, grows with feed.
    Lag,
    /// The paper's three independent plane terms (µm).
    Paper,
}

#[derive(clap::Args, Debug)]
struct FitArgs {
    /// Machine type (`ballbar plugins` lists them).
    #[arg(long)]
    machine: String,
    /// Run files, or folders of `*.csv` run files.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    /// Write the fit as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Save the fitted model (RON) for `predict`.
    #[arg(long)]
    save_model: Option<PathBuf>,
    /// Servo model.
    #[arg(long, value_enum, default_value = "lag")]
    servo: Servo,
    /// A calibrated bar: its length error in µm (otherwise fitted, one bar for all runs).
    #[arg(long)]
    bar_length_um: Option<f64>,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    threads: usize,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Write run CSVs of a machine with known errors.
    Simulate {
        /// Machine type.
        #[arg(long)]
        machine: String,
        /// Truth file (RON): errors, tests, noise.
        #[arg(long)]
        truth: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Random seed (noise, centring).
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Fit the machine's base model (the paper's terms) to runs.
    Fit(FitArgs),
    /// Write each run with the saved model's prediction as a column `dR_model_um`.
    Predict {
        /// Saved model (from `fit --save-model`).
        #[arg(long)]
        model: PathBuf,
        /// Run files or folders.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
    },
    /// List the machine types available.
    Plugins {
        /// JSON output.
        #[arg(long)]
        json: bool,
    },
}

/// The machine types this build knows. They are linked in for now; loading them as plugins
/// at run time is the next step (issue #3).
pub fn machines() -> Vec<MachineSpec> {
    vec![ballbar_machine_column::machine(), ballbar_machine_horizontal::machine()]
}

fn machine(name: &str) -> Result<MachineSpec> {
    machines().into_iter().find(|m| m.name == name).ok_or_else(|| {
        let known: Vec<String> = machines().into_iter().map(|m| m.name).collect();
        Failure::Input(anyhow!("no machine type '{name}' (available: {})", known.join(", ")))
    })
}

/// Expand folders to their `*.csv` files (sorted) and read every run, in parallel.
pub fn read_runs(paths: &[PathBuf], threads: usize) -> Result<Vec<Run>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut in_dir: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("{}: cannot list the folder", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x == "csv"))
                .collect();
            in_dir.sort();
            if in_dir.is_empty() {
                return Err(Failure::Input(anyhow!("{}: no *.csv run files in this folder", p.display())));
            }
            files.extend(in_dir);
        } else {
            files.push(p.clone());
        }
    }
    let runs = ballbar_fit::par_map(files.len(), threads, |k| ballbar_io::read_run(&files[k]));
    runs.into_iter().map(|r| r.map_err(Failure::from)).collect()
}

/// Parse arguments, run, print errors, return the exit code.
pub fn main_with_args(args: impl IntoIterator<Item = OsString>) -> ExitCode {
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { 2 } else { 0 });
        }
    };
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure::Input(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(1)
        }
        Err(Failure::Internal(e)) => {
            eprintln!("internal error: {e:#}");
            ExitCode::from(3)
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate { machine: name, truth, out, seed } => simulate(&name, &truth, &out, seed),
        Command::Fit(args) => fit_cmd(&args),
        Command::Predict { model, runs, out } => predict(&model, &runs, &out),
        Command::Plugins { json } => plugins(json),
    }
}

fn simulate(name: &str, truth_path: &Path, out: &Path, seed: u64) -> Result<()> {
    let spec = machine(name)?;
    let truth: ballbar_sim::Truth = ballbar_io::ron_files::read_ron(truth_path)?;
    let start = ballbar_io::time::parse_iso8601(&truth.started_at)
        .map_err(|m| anyhow!("{}: started_at: {m}", truth_path.display()))?;
    let sim = ballbar_sim::simulate(&spec, &truth, start, seed).with_context(|| format!("{}", truth_path.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    for run in &sim.runs {
        let file = out.join(format!("{}.csv", run.name()));
        ballbar_io::write_run(run, &file)?;
    }
    println!("wrote {} runs of machine '{}' to {} (seed {seed})", sim.runs.len(), spec.name, out.display());
    Ok(())
}

fn options(args: &FitArgs) -> Result<ModelOptions> {
    let bar_length = match args.bar_length_um {
        Some(b) if b.is_finite() => BarLength::Known(b * 1e-3),
        Some(b) => return Err(Failure::Input(anyhow!("--bar-length-um {b} is not a finite number"))),
        None => BarLength::Fit,
    };
    let servo = match args.servo {
        Servo::Lag => ServoVariant::AxisLag,
        Servo::Paper => ServoVariant::PlaneMismatch,
    };
    Ok(ModelOptions { servo, bar_length })
}

fn fit_cmd(args: &FitArgs) -> Result<()> {
    let spec = machine(&args.machine)?;
    let opts = options(args)?;
    let runs = read_runs(&args.runs, args.threads)?;
    let model = Model::new(spec.clone(), opts).map_err(|e| Failure::Internal(e.into()))?;
    let design = Design::new(&model, &runs)?;
    let f = fit(&design, args.threads).map_err(|e| match e {
        ballbar_fit::FitError::TooFewSamples { .. } => Failure::Input(e.into()),
        other => Failure::Internal(other.into()),
    })?;
    let rep = report::FitReport::new(&model, &design, &f);
    print!("{}", rep.terminal());
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&rep.json()).map_err(|e| Failure::Internal(e.into()))?;
        ballbar_io::write_atomic(p, text.as_bytes())?;
    }
    if let Some(p) = &args.save_model {
        ballbar_io::ron_files::write_ron(&SavedModel::from_fit(&f, &spec, opts), p)?;
    }
    Ok(())
}

fn predict(model_path: &Path, run_paths: &[PathBuf], out: &Path) -> Result<()> {
    let saved: SavedModel = ballbar_io::ron_files::read_ron(model_path)?;
    if saved.format != SAVED_MODEL_FORMAT {
        return Err(Failure::Input(anyhow!("{}: format '{}' is not {SAVED_MODEL_FORMAT}", model_path.display(), saved.format)));
    }
    let model = Model::new(saved.machine.clone(), saved.options).with_context(|| format!("{}", model_path.display()))?;
    let files: Vec<PathBuf> = run_paths.to_vec();
    let runs = read_runs(&files, 2)?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the folder", out.display()))?;
    for run in &runs {
        let one = std::slice::from_ref(run);
        let design = Design::new(&model, one)?;
        let mut theta = vec![0.0; design.n_cols()];
        for p in &saved.parameters {
            let i = design
                .parameters
                .iter()
                .position(|q| q.id == p.id)
                .ok_or_else(|| anyhow!("{}: parameter {} is not in machine '{}'", model_path.display(), p.id, saved.machine.name))?;
            theta[i] = p.value;
        }
        // The run's own centring is unknown to the model: predicted as zero.
        let pred: Vec<f64> = design.exact_run(0, &theta)?.iter().map(|x| x * 1e3).collect();
        let src = Path::new(&run.source);
        let text = std::fs::read_to_string(src).with_context(|| format!("{}", src.display()))?;
        let with = ballbar_io::append_column(&text, &run.source, "dR_model_um", &pred)?;
        let name = src.file_name().ok_or_else(|| anyhow!("{}: not a file", src.display()))?;
        ballbar_io::write_atomic(&out.join(name), with.as_bytes())?;
    }
    println!("wrote {} runs with dR_model_um to {}", runs.len(), out.display());
    Ok(())
}

fn plugins(json: bool) -> Result<()> {
    let exe = std::env::current_exe().map(|p| p.display().to_string()).unwrap_or_default();
    let list = machines();
    if json {
        let v: Vec<serde_json::Value> = list
            .iter()
            .map(|m| serde_json::json!({"name": m.name, "version": m.version, "abi_version": null, "linked": "static", "path": exe, "description": m.description}))
            .collect();
        println!("{}", serde_json::to_string_pretty(&v).map_err(|e| Failure::Internal(e.into()))?);
    } else {
        println!("machine types (linked into this binary; run-time plugin loading is not built yet):");
        for m in &list {
            println!("  {:<12} {:<8} {}", m.name, m.version, m.description);
        }
    }
    Ok(())
}

/// Hint for a null combination: which extra test would separate it.
pub fn separation_hint(classes: &[ParamClass]) -> &'static str {
    let has = |c: ParamClass| classes.contains(&c);
    if classes.len() == 1 {
        return "has no effect on these tests: test in a plane where its axis moves";
    }
    if has(ParamClass::BarLength) && has(ParamClass::Term(TermClass::Positional)) {
        return "a second radius (scale grows with R, bar length does not), or a calibrated bar (--bar-length-um)";
    }
    if classes.iter().all(|c| *c == ParamClass::Term(TermClass::ServoLag)) {
        return "a common lag changes no radius to first order: runs at two feeds show its radius loss";
    }
    if classes.iter().any(|c| *c == ParamClass::Centring) {
        return "a test in a plane where these axes move (in this one they sit still, their errors act as a centring)";
    }
    "offset circle centres, another radius, or another tool length or ball height"
}

/// Paired CW/CCW runs (same plane, radius, feed, pivot), by index.
pub fn pairs(runs: &[Run]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut used = vec![false; runs.len()];
    for i in 0..runs.len() {
        if used[i] || runs[i].header.direction != Some(Direction::CW) {
            continue;
        }
        let h = &runs[i].header;
        if let Some(j) = (0..runs.len()).find(|&j| {
            let g = &runs[j].header;
            !used[j] && g.direction == Some(Direction::CCW) && g.plane == h.plane && g.radius_mm == h.radius_mm && g.feed_mm_per_min == h.feed_mm_per_min && g.pivot_mm == h.pivot_mm
        }) {
            used[i] = true;
            used[j] = true;
            out.push((i, j));
        }
    }
    out
}

/// The paper report of a fit at the first run's radius and feed.
pub fn paper_rows(model: &Model, f: &Fit, runs: &[Run]) -> (f64, f64, Vec<(ballbar_fit::QuantityEstimate, ballbar_fit::QuantityEstimate)>) {
    let (r, feed) = runs.first().map(|r| (r.header.radius_mm, r.header.feed_mm_per_min)).unwrap_or((150.0, 500.0));
    let rows = paper::report(model, r, feed)
        .iter()
        .filter_map(|row| Some((quantity(f, &row.paper)?, quantity(f, &row.vendor)?)))
        .collect();
    (r, feed, rows)
}

/// Figures of every run before and after the model.
pub fn run_figures(f: &Fit, runs: &[Run]) -> Vec<(metrics::CircleFigures, metrics::CircleFigures)> {
    runs.iter().enumerate().map(|(r, run)| (metrics::figures(run, &run.dr_mm), metrics::figures(run, &f.residuals[r]))).collect()
}

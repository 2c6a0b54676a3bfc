//! The `ballbar` command (`shared/spec/cli.md`): simulate, fit, diagnose, predict, import,
//! program (the part programs of the tests), plugins, and the archive commands record, replay,
//! export, history, report. Exit codes: 0 success, 1 wrong input (the message names file, line
//! and problem), 2 usage, 3 `verify`'s verdict (a compensated term not corrected), 4 internal.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, anyhow};
use ballbar_fit::saved::{SavedModel, SavedPlugin, SavedSession};
use ballbar_model::machine::{BarLength, MachineSpec, Model, ModelOptions, ServoVariant};
use ballbar_model::{Design, Run};
use ballbar_plugin_host::{Plugin, Registry, Search};
use clap::{Parser, Subcommand, ValueEnum};
use std::sync::Arc;

/// Where the text for a person goes: standard output, or standard error while standard output
/// carries the JSON (`--json -`).
static TEXT_TO_STDERR: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// `print!` that does not panic when stdout is closed (a pipe into `head`): the rest of the
/// output is for a reader who has gone. Goes to stderr under `--json -`.
macro_rules! out {
    ($($t:tt)*) => {{
        use std::io::Write as _;
        if crate::TEXT_TO_STDERR.load(std::sync::atomic::Ordering::Relaxed) {
            let _ = write!(std::io::stderr().lock(), $($t)*);
        } else {
            let _ = write!(std::io::stdout().lock(), $($t)*);
        }
    }};
}

/// `println!` likewise.
macro_rules! outln {
    ($($t:tt)*) => {{
        out!("{}\n", format_args!($($t)*))
    }};
}

/// Write a command's JSON to `path` (checked by [`outputs::check`]), atomically; `-` is
/// standard output (`cli.md`).
fn write_json(path: &Path, value: &impl serde::Serialize, force: bool) -> Result<()> {
    let text = serde_json::to_string_pretty(value).map_err(|e| Failure::Internal(e.into()))?;
    if path.as_os_str() == "-" {
        use std::io::Write as _;
        let mut stdout = std::io::stdout().lock();
        let _ = writeln!(stdout, "{text}");
        return Ok(());
    }
    outputs::write(path, text.as_bytes(), force)
}

/// A document as the JSON value an archive keeps.
fn to_value(document: &impl serde::Serialize) -> Result<serde_json::Value> {
    serde_json::to_value(document).map_err(|e| Failure::Internal(e.into()))
}

mod archive;
pub mod compensate;
pub mod diagnosis;
mod import;
pub mod inputs;
mod outputs;
mod program;
mod progress;
use ballbar_report::fit_report as report;

/// A failure and its exit code.
#[derive(Debug)]
pub enum Failure {
    /// The input is wrong: exit 1.
    Input(anyhow::Error),
    /// The command line is wrong in a way its parser cannot see (an option another one needs):
    /// exit 2, as for any usage error.
    Usage(anyhow::Error),
    /// Something failed inside: exit 4 (`cli.md`: any code but those of input, usage and
    /// `verify`'s verdicts, so that a failure is never read as a verdict).
    Internal(anyhow::Error),
    /// `verify`'s verdicts: a compensated term not corrected, or a term changed: exit 3.
    Verdict(anyhow::Error),
}

impl<E: Into<anyhow::Error>> From<E> for Failure {
    fn from(e: E) -> Failure {
        Failure::Input(e.into())
    }
}

type Result<T> = std::result::Result<T, Failure>;

/// `ballbar --version`: the crate's version and the commit it was built from (short hash,
/// `-dirty` when the binary's sources differed from it; `unknown commit` outside a git
/// checkout), set by `build.rs`.
pub const VERSION: &str =
    concat!(env!("CARGO_PKG_VERSION"), " (commit ", env!("BALLBAR_COMMIT"), ")");

#[derive(Parser, Debug)]
#[command(name = "ballbar", version = VERSION, about = "Ballbar volumetric error assessment of CNC machine tools")]
struct Cli {
    /// Load this machine plugin first (repeatable); then BALLBAR_PLUGIN_PATH, the executable's
    /// folder and ../lib/ballbar/plugins beside it are searched.
    #[arg(long = "plugin", global = true, value_name = "FILE")]
    plugins: Vec<PathBuf>,
    #[command(subcommand)]
    command: Command,
}

/// Which machine: a plugin's machine type, or a user's chain file read by a plugin.
#[derive(clap::Args, Debug, Clone)]
#[group(required = true, multiple = false)]
struct MachineArgs {
    /// Machine type (`ballbar plugins` lists them).
    #[arg(long)]
    machine: Option<String>,
    /// A user-defined machine: a RON chain file (see docs/plugins.md).
    #[arg(long, value_name = "FILE")]
    machine_file: Option<PathBuf>,
}

/// An optional machine (replay with another model).
#[derive(clap::Args, Debug, Clone)]
#[group(required = false, multiple = false)]
struct OptionalMachineArgs {
    /// Machine type (`ballbar plugins` lists them).
    #[arg(long)]
    machine: Option<String>,
    /// A user-defined machine: a RON chain file.
    #[arg(long, value_name = "FILE")]
    machine_file: Option<PathBuf>,
}

#[derive(ValueEnum, Clone, Copy, Debug)]
enum Servo {
    /// One lag per axis (ms): consistent across planes, grows with feed.
    Lag,
    /// The paper's three independent plane terms (µm).
    Paper,
}

/// Where the model's backlash and reversal transients switch.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum BacklashSwitch {
    /// At each axis's lagged reversal, found from the runs (the commanded reversal when the
    /// runs do not determine it, said so).
    Lagged,
    /// At the commanded reversal (to compare).
    Commanded,
}

#[derive(clap::Args, Debug)]
struct FitArgs {
    #[command(flatten)]
    machine: MachineArgs,
    /// Run files (run CSVs, Renishaw `.b5r` files), or folders of them.
    #[arg(required = true)]
    runs: Vec<PathBuf>,
    #[command(flatten)]
    placement: inputs::Placement,
    /// How `.b5r` samples are placed on the circle: as the machine moved (by the programmed
    /// feed) or by the vendor's convention (its arc's samples spread evenly).
    #[arg(long, value_enum, default_value = "machine")]
    b5r_angles: inputs::Angles,
    /// Write the command's JSON to FILE (fit: the fit, diagnose: the diagnosis; each command's
    /// help says which); `-` for standard output (the text for a person then goes to standard
    /// error).
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Save the fitted model (RON) for `predict`.
    #[arg(long)]
    save_model: Option<PathBuf>,
    /// Servo model.
    #[arg(long, value_enum, default_value = "lag")]
    servo: Servo,
    /// Where the backlash switches: at each axis's lagged reversal (its servo lag after the
    /// commanded one, found from the runs) or at the commanded reversal.
    #[arg(long, value_enum, default_value = "lagged")]
    backlash_switch: BacklashSwitch,
    /// A calibrated bar: its length error in µm (otherwise fitted, one bar for all runs).
    #[arg(long)]
    bar_length_um: Option<f64>,
    /// Worker threads (at least 1).
    #[arg(long, default_value_t = 2, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1024))]
    threads: usize,
    /// Archive the runs, the machine, the fit (and the diagnosis) in this MCAP file.
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    /// Replace the files this command writes (--json, --save-model, --record) if they exist
    /// (checked before any work); an input is never replaced.
    #[arg(long)]
    force: bool,
}

/// `fit --json`'s help: what its JSON is.
const FIT_JSON_HELP: &str = "Write the fit as JSON to FILE (format ballbar-fit/1: the paper's quantities, every parameter with its \
    uncertainty and polynomial basis, what the tests cannot separate, the runs' ISO 230-4 figures); `-` for standard output \
    (the text for a person then goes to standard error)";

/// `diagnose --json`'s help: what its JSON is.
const DIAGNOSE_JSON_HELP: &str = "Write the diagnosis as JSON to FILE (format ballbar-diagnosis/1, shared/spec/cli.md: where the gap \
    lies, the unmodelled effects named with their held-out evidence, those tried and declined, what the tests cannot separate; \
    not the fit: `fit --json` writes that); `-` for standard output (the text for a person then goes to standard error)";

#[derive(Subcommand, Debug)]
enum Command {
    /// Write run CSVs of a machine with known errors.
    Simulate {
        #[command(flatten)]
        machine: MachineArgs,
        /// Truth file (RON): errors, tests, noise.
        #[arg(long)]
        truth: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// Random seed (noise, centring).
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Run the machine with this LinuxCNC compensation active (a folder with linuxcnc.ini,
        /// or the INI file): its trims, applied as LinuxCNC applies them, added to the command.
        #[arg(long, value_name = "DIR")]
        compensation: Option<PathBuf>,
        /// Replace run files that exist in the output folder (checked before anything is written).
        #[arg(long)]
        force: bool,
    },
    /// Write a controller's compensation files (LinuxCNC, SINUMERIK, FANUC, HEIDENHAIN) from a
    /// saved model, with the trace predicted after them (shared/spec/compensate.md).
    Compensate(compensate::CompensateArgs),
    /// Compare the tests repeated with a compensation active with its prediction, term by term
    /// (exit 3 when a compensated term is not corrected or another term changed).
    Verify(compensate::VerifyArgs),
    /// Fit the machine's base model (the paper's terms) to runs.
    #[command(mut_arg("json", |a| a.help(FIT_JSON_HELP)))]
    Fit(FitArgs),
    /// Fit, then find where the model and the runs disagree, which unmodelled effect causes
    /// it, and how much of the excess above the noise it closes on held-out data.
    #[command(mut_arg("json", |a| a.help(DIAGNOSE_JSON_HELP)))]
    Diagnose(FitArgs),
    /// Write each run with the saved model's prediction as a column `dR_model_um`.
    Predict {
        /// Saved model (from `fit --save-model`).
        #[arg(long)]
        model: PathBuf,
        #[command(flatten)]
        placement: inputs::Placement,
        /// How `.b5r` samples are placed on the circle (as for `fit`).
        #[arg(long, value_enum, default_value = "machine")]
        b5r_angles: inputs::Angles,
        /// Run files or folders.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        /// Output folder (never one holding the inputs under the same names).
        #[arg(long)]
        out: PathBuf,
        /// Take runs that started more than an hour after the model's session ended as later
        /// runs of that session: their time-dependent terms evaluated from its start.
        #[arg(long)]
        same_session: bool,
        /// The start of the session the runs belong to (ISO 8601): the origin of the model's
        /// time-dependent terms instead of the model's own session start.
        #[arg(long, value_name = "ISO8601", conflicts_with = "same_session")]
        time_origin: Option<String>,
        /// Replace files that exist in the output folder (checked before anything is written).
        #[arg(long)]
        force: bool,
    },
    /// Archive raw runs (no fit) in an MCAP file.
    Record {
        /// Run files (run CSVs, `.b5r` files) or folders.
        #[arg(required = true)]
        runs: Vec<PathBuf>,
        #[command(flatten)]
        placement: inputs::Placement,
        /// How `.b5r` samples are placed on the circle (as for `fit`).
        #[arg(long, value_enum, default_value = "machine")]
        b5r_angles: inputs::Angles,
        /// The archive to write.
        #[arg(long, value_name = "FILE.mcap")]
        out: PathBuf,
        /// Replace the archive if it exists (it is never replaced otherwise).
        #[arg(long)]
        force: bool,
    },
    /// Refit (and re-diagnose) an archive from its raw runs and say what changed.
    Replay {
        /// The archive.
        archive: PathBuf,
        /// Refit with another machine instead of the archived one.
        #[command(flatten)]
        machine: OptionalMachineArgs,
        /// Write the comparison as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Worker threads (at least 1).
        #[arg(long, default_value_t = 2, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1024))]
        threads: usize,
        /// Replace the --json file if it exists (checked before any work); the archive is
        /// never replaced.
        #[arg(long)]
        force: bool,
        /// Refuse (exit 1) an archive whose records carry no checksums (MCAP allows a CRC of 0,
        /// "not computed": damage to them cannot be detected) instead of reading it with a
        /// warning.
        #[arg(long)]
        require_crc: bool,
    },
    /// Write an archive's runs back as run CSVs.
    Export {
        /// The archive.
        archive: PathBuf,
        /// Output folder.
        #[arg(long)]
        out: PathBuf,
        /// From a damaged archive (cut short, a checksum mismatch), write every run it holds
        /// whole and name what was lost (without it, a damaged archive is refused).
        #[arg(long)]
        partial: bool,
        /// Replace run files that exist in the output folder (checked before anything is
        /// written).
        #[arg(long)]
        force: bool,
        /// Refuse (exit 1) an archive whose records carry no checksums (MCAP allows a CRC of 0,
        /// "not computed": damage to them cannot be detected) instead of reading it with a
        /// warning.
        #[arg(long)]
        require_crc: bool,
    },
    /// Follow a machine over time: every archive of a folder, in date order.
    History {
        /// Folder of `*.mcap` archives.
        dir: PathBuf,
        /// CSV output (one row per parameter and session).
        #[arg(long)]
        csv: bool,
        /// Refuse (exit 1) an archive whose records carry no checksums (MCAP allows a CRC of 0,
        /// "not computed": damage to them cannot be detected) instead of reading it with a
        /// warning.
        #[arg(long)]
        require_crc: bool,
    },
    /// Write the HTML report of an archive (polar plots, parameters, ISO 230-4 figures, the
    /// diagnosis, trends over a folder of archives).
    Report {
        /// The archive; or run files (run CSVs, `.b5r` files, folders), diagnosed with
        /// --machine first.
        #[arg(required = true)]
        archive: Vec<PathBuf>,
        /// Output folder (the page is `index.html`).
        #[arg(long)]
        out: PathBuf,
        /// The machine, for run files (an archive names its own).
        #[command(flatten)]
        machine: OptionalMachineArgs,
        #[command(flatten)]
        placement: inputs::Placement,
        /// How `.b5r` samples are placed on the circle (as for `fit`).
        #[arg(long, value_enum, default_value = "machine")]
        b5r_angles: inputs::Angles,
        /// A folder of archives of the same machine: adds the trend plots.
        #[arg(long, value_name = "DIR")]
        history: Option<PathBuf>,
        /// A field of the page's session form, over what the runs' headers say (repeatable):
        /// machine_name, machine_serial, location, ballbar_model, ballbar_serial,
        /// ballbar_last_calibrated, ballbar_certificate, calibrator_serial, temperature_c,
        /// operator, test_date, checked_by (docs/report.md). A field nobody gives is printed
        /// empty, to fill in by hand.
        #[arg(long = "info", value_name = "KEY=VALUE", value_parser = parse_info)]
        info: Vec<(String, String)>,
        /// Tolerances to judge the session against (a RON file, docs/report.md): adds a
        /// pass/fail table with an overall verdict.
        #[arg(long, value_name = "FILE")]
        tolerance: Option<PathBuf>,
        /// A folder `ballbar compensate` wrote: adds the compensation section (what was
        /// compensated, what remains and why, each run's G predicted after).
        #[arg(long, value_name = "DIR")]
        compensation: Option<PathBuf>,
        /// A verification `ballbar verify --json` wrote: adds each run's G measured after and
        /// each term's verdict to the compensation section.
        #[arg(long, value_name = "FILE")]
        verification: Option<PathBuf>,
        /// Replace `index.html` in the output folder if it exists (checked before any work).
        #[arg(long)]
        force: bool,
        /// Refuse (exit 1) an archive (the report's, or one of --history) whose records carry no checksums (MCAP allows a CRC of 0,
        /// "not computed": damage to them cannot be detected) instead of reading it with a
        /// warning.
        #[arg(long)]
        require_crc: bool,
    },
    /// Write run CSVs from a Renishaw `.b5r` file (each run a run, everything the file says
    /// kept in the header), or from a plain table of angle (or time) and reading.
    Import(import::ImportArgs),
    /// Write the part program (ISO G-code) of each test, one `<run-id>.nc` per run: the
    /// commanded runs of a truth file (with --machine or --machine-file), or of run files.
    Program(program::ProgramArgs),
    /// List the machine types available.
    Plugins {
        /// Write the list as JSON to FILE (the plugins, what each provides, the problems and
        /// where it looked); `-` or no FILE for standard output, instead of the list for a person.
        #[arg(long, value_name = "FILE", num_args = 0..=1, default_missing_value = "-")]
        json: Option<PathBuf>,
        /// Replace the --json file if it exists; a plugin file is never replaced.
        #[arg(long)]
        force: bool,
    },
    /// Print the shell completion script for SHELL to standard output (README: Install).
    Completions {
        /// The shell.
        shell: clap_complete::Shell,
    },
}

/// A machine resolved through its plugin.
pub struct Machine {
    /// The description.
    pub spec: MachineSpec,
    /// The plugin that gave it (and provides its kernels).
    pub plugin: Arc<Plugin>,
}

impl Machine {
    /// The validated model with the plugin's kernels.
    pub fn model(&self, options: ModelOptions) -> Result<Model> {
        Model::with_kernels(self.spec.clone(), options, &*self.plugin)
            .map_err(|e| Failure::Input(anyhow!("{}: {e}", self.plugin.path().display())))
    }
}

/// Find the plugins, reporting the files that failed to load, and the files and folders
/// refused as others could have written them, as warnings.
pub fn registry(explicit: &[PathBuf]) -> Result<Registry> {
    let reg = Registry::discover(&Search::from_environment(explicit))?;
    for p in &reg.problems {
        eprintln!("warning: skipped a plugin file: {p}");
    }
    for r in &reg.refused {
        eprintln!("warning: {r}");
    }
    Ok(reg)
}

/// Nothing found: where it looked, and how to install the plugins.
fn no_plugins(reg: &Registry) -> anyhow::Error {
    let files = format!(
        "{}ballbar_machine_*{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    anyhow!(
        "found no machine plugins; looked in: {}{}. To install ballbar with its plugins, run `cargo xtask install` in its source tree \
         (the binary goes to ~/.local/bin, the plugins to ~/.local/{dir}; docs/plugins.md); or put the plugin files ({files}) \
         beside this binary or in ../{dir} from its folder, set BALLBAR_PLUGIN_PATH, or pass --plugin FILE",
        reg.searched_text(),
        reg.refused_text(),
        dir = ballbar_plugin_host::INSTALLED_PLUGIN_DIR,
    )
}

/// `ballbar completions SHELL`: the script, written whole to standard output (a reader gone
/// away, as `| head` does, is not an error).
fn completions(shell: clap_complete::Shell) -> Result<()> {
    use clap::CommandFactory as _;
    use std::io::Write as _;
    let mut script = Vec::new();
    clap_complete::generate(shell, &mut Cli::command(), "ballbar", &mut script);
    let _ = std::io::stdout().lock().write_all(&script);
    Ok(())
}

/// The machine a command names.
fn machine(args: &MachineArgs, reg: &Registry) -> Result<Machine> {
    if reg.plugins.is_empty() {
        return Err(Failure::Input(no_plugins(reg)));
    }
    if let Some(file) = &args.machine_file {
        let plugin = reg.machine_file_reader().cloned().ok_or_else(|| {
            Failure::Input(anyhow!(
                "{}: no loaded plugin reads machine files (the chain-file plugin); looked in: {}{}",
                file.display(),
                reg.searched_text(),
                reg.refused_text()
            ))
        })?;
        let spec = plugin.machine_from_file(file)?;
        return Ok(Machine { spec, plugin });
    }
    let name = args.machine.as_deref().unwrap_or_default();
    let plugin = reg.find(name).cloned().ok_or_else(|| {
        let known: Vec<&str> =
            reg.plugins.iter().filter(|p| !p.reads_machine_files()).map(|p| p.name()).collect();
        Failure::Input(anyhow!(
            "no machine type '{name}' (available: {}; user-defined machines: --machine-file FILE){}",
            known.join(", "),
            reg.refused_text()
        ))
    })?;
    let spec = plugin.machine()?;
    Ok(Machine { spec, plugin })
}

/// Every run of `paths` (run CSVs, `.b5r` files, folders of them), read in parallel; the
/// `.b5r` circles at the default centre.
pub fn read_runs(paths: &[PathBuf], threads: usize) -> Result<Vec<Run>> {
    inputs::read(paths, threads, inputs::Placement::default(), Default::default()).map(|i| i.runs)
}

/// Parse arguments, run, print errors, return the exit code.
pub fn main_with_args(args: impl IntoIterator<Item = OsString>) -> ExitCode {
    let args: Vec<OsString> = args.into_iter().collect();
    let _ = archive::COMMAND.set(archive::command_text(&args));
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
        Err(Failure::Usage(e)) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
        Err(Failure::Internal(e)) => {
            eprintln!("internal error: {e:#}");
            ExitCode::from(4)
        }
        Err(Failure::Verdict(e)) => {
            eprintln!("{e:#}");
            ExitCode::from(3)
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    let json_to_stdout = match &cli.command {
        Command::Fit(a) | Command::Diagnose(a) => a.json.as_deref(),
        Command::Replay { json, .. } => json.as_deref(),
        Command::Verify(a) => a.json.as_deref(),
        _ => None,
    }
    .is_some_and(|p| p.as_os_str() == "-");
    TEXT_TO_STDERR.store(json_to_stdout, std::sync::atomic::Ordering::Relaxed);
    // Completions need no plugin: no search, and no warning about a broken plugin file.
    if let Command::Completions { shell } = cli.command {
        return completions(shell);
    }
    let reg = registry(&cli.plugins)?;
    match cli.command {
        Command::Simulate { machine: m, truth, out, seed, compensation, force } => simulate(
            &machine(&m, &reg)?,
            (&truth, m.machine_file.as_deref()),
            (&out, compensation.as_deref()),
            seed,
            force,
            &reg,
        ),
        Command::Compensate(args) => compensate::compensate(&args, &reg),
        Command::Verify(args) => compensate::verify_cmd(&args, &reg),
        Command::Fit(args) => {
            progress::install_for_stderr();
            fit_cmd(&args, &reg)
        }
        Command::Diagnose(args) => {
            progress::install_for_stderr();
            diagnose_cmd(&args, &reg)
        }
        Command::Predict {
            model,
            placement,
            b5r_angles,
            runs,
            out,
            same_session,
            time_origin,
            force,
        } => {
            let clock = Clock { same_session, time_origin };
            predict(&model, &runs, placement, b5r_angles, &out, (&clock, force), &reg)
        }
        Command::Record { runs, placement, b5r_angles, out, force } => {
            archive::record_cmd(&runs, placement, b5r_angles, &out, force, &reg)
        }
        Command::Import(args) => import::import(&args, &reg),
        Command::Program(args) => program::program(&args, &reg),
        Command::Replay { archive: file, machine: m, json, threads, force, require_crc } => {
            archive::require_crc(require_crc);
            let given = (m.machine.is_some() || m.machine_file.is_some())
                .then_some(MachineArgs { machine: m.machine, machine_file: m.machine_file });
            let json = json.as_deref().map(|p| (p, force));
            archive::replay(&file, given.as_ref(), threads.max(1), json, &reg)
        }
        Command::Export { archive: file, out, partial, force, require_crc } => {
            archive::require_crc(require_crc);
            archive::export(&file, &out, partial, force, &reg)
        }
        Command::History { dir, csv, require_crc } => {
            archive::require_crc(require_crc);
            archive::history(&dir, csv)
        }
        Command::Report {
            archive: files,
            out,
            machine: m,
            placement,
            b5r_angles,
            history,
            info,
            tolerance,
            compensation,
            verification,
            force,
            require_crc,
        } => {
            archive::require_crc(require_crc);
            ballbar_report::session_info::check_given(&info)
                .map_err(|e| Failure::Usage(anyhow!(e)))?;
            // The tolerance file is read before any work: a typo in it stops the command at once.
            let tolerance_file: Vec<PathBuf> = tolerance.into_iter().collect();
            let tolerance =
                tolerance_file.first().map(|t| ballbar_report::tolerance::read(t)).transpose()?;
            // So are the compensation's documents.
            let (compensation, compensation_files) =
                compensate::report_input(compensation.as_deref(), verification.as_deref())?;
            let tolerance_file: Vec<PathBuf> =
                tolerance_file.into_iter().chain(compensation_files).collect();
            let options = ballbar_report::PageOptions { info, tolerance, compensation };
            let archive = (files.len() == 1 && files[0].extension().is_some_and(|x| x == "mcap"))
                .then(|| files[0].clone());
            let written = match archive {
                Some(file) => {
                    if m.machine.is_some()
                        || m.machine_file.is_some()
                        || !placement.is_empty()
                        || b5r_angles != inputs::Angles::Machine
                    {
                        return Err(Failure::Usage(anyhow!(
                            "{}: an archive names its machine and runs; --machine, --machine-file, --pivot, --tool-ball-mm and --b5r-angles are for run files",
                            file.display()
                        )));
                    }
                    let read = [vec![file.clone()], tolerance_file].concat();
                    check_page(&out, read, history.as_deref(), force, &reg)?;
                    report_page(&file, &out, history.as_deref(), &options, force, &reg)?
                }
                None => {
                    let given = MachineArgs { machine: m.machine, machine_file: m.machine_file };
                    if given.machine.is_none() && given.machine_file.is_none() {
                        return Err(Failure::Usage(anyhow!(
                            "the report of run files needs the machine: --machine NAME or --machine-file FILE (an archive, FILE.mcap, names its own)"
                        )));
                    }
                    let read: Vec<PathBuf> = inputs::files(&files)?
                        .into_iter()
                        .chain(given.machine_file.iter().cloned())
                        .chain(tolerance_file)
                        .collect();
                    check_page(&out, read, history.as_deref(), force, &reg)?;
                    report_runs(
                        &files,
                        &given,
                        placement,
                        b5r_angles,
                        (&out, force),
                        history.as_deref(),
                        &options,
                        &reg,
                    )?
                }
            };
            outln!("wrote {}", written.display());
            Ok(())
        }
        Command::Plugins { json, force } => plugins(json.as_deref(), force, &reg),
        Command::Completions { shell } => completions(shell),
    }
}

/// The runs of a truth file simulated on `machine` (what `simulate` writes; `program` takes their
/// commanded paths), errors naming the truth file.
fn simulation(
    machine: &Machine,
    truth_path: &Path,
    seed: u64,
    controller: Option<&ballbar_sim::controller::Controller>,
) -> Result<ballbar_sim::Simulation> {
    let truth: ballbar_sim::Truth = ballbar_io::ron_files::read_ron(truth_path)?;
    let start = ballbar_model::time::parse_iso8601(&truth.started_at)
        .map_err(|m| anyhow!("{}: started_at: {m}", truth_path.display()))?;
    let sim = ballbar_sim::simulate_controlled(
        &machine.spec,
        &*machine.plugin,
        &truth,
        start,
        seed,
        controller,
    )
    .with_context(|| format!("{}", truth_path.display()))?;
    Ok(sim)
}

fn simulate(
    machine: &Machine,
    (truth_path, machine_file): (&Path, Option<&Path>),
    (out, compensation): (&Path, Option<&Path>),
    seed: u64,
    force: bool,
    reg: &Registry,
) -> Result<()> {
    let spec = &machine.spec;
    let controller = compensation.map(compensate::simulated_controller).transpose()?;
    let sim = simulation(machine, truth_path, seed, controller.as_ref().map(|c| &c.0))?;
    let targets: Vec<PathBuf> =
        sim.runs.iter().map(|run| out.join(format!("{}.csv", run.name()))).collect();
    let read: Vec<PathBuf> = std::iter::once(truth_path.to_path_buf())
        .chain(machine_file.map(Path::to_path_buf))
        .chain(outputs::loaded(reg))
        .chain(controller.iter().flat_map(|c| c.1.iter().cloned()))
        .collect();
    let outs: Vec<outputs::Output> =
        targets.iter().map(|t| outputs::Output::new(t, "--out")).collect();
    outputs::check(&outs, &read, force, "runs")?;
    let files = sim
        .runs
        .iter()
        .zip(&targets)
        .map(|(run, file)| Ok((file.clone(), ballbar_io::run_text_rounded(run, file)?)))
        .collect::<Result<Vec<_>>>()?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("{}: cannot create the folder", out.display()))?;
    outputs::write_all(&files, force)?;
    outln!(
        "wrote {} runs of machine '{}' to {} (seed {seed})",
        sim.runs.len(),
        spec.name,
        out.display()
    );
    Ok(())
}

/// The model options of `fit` and `diagnose`, and the lines that say which choices the inputs
/// made (the `.b5r` circle centre, a calibrated bar).
///
/// A `.b5r` reading is the bar length minus its calibrated length (the vendor's calibrator sets
/// it, `vendor-b5r.md`): when every run comes from a `.b5r` file, the bar-length error is known
/// to be 0 and is not fitted, as the vendor's software does; otherwise, at one radius, the bar
/// length and a common scale of the axes could not be told apart.
fn options(args: &FitArgs, inputs: &inputs::Inputs) -> Result<(ModelOptions, Vec<String>)> {
    let mut notes: Vec<String> = inputs::pivot_note(inputs).into_iter().collect();
    notes.extend(inputs::geometry_note(&inputs.runs));
    let all_calibrated = !inputs.runs.is_empty()
        && inputs.vendor.iter().map(|v| v.runs.len()).sum::<usize>() == inputs.runs.len();
    let bar_length = match args.bar_length_um {
        Some(b) if b.is_finite() => BarLength::Known(b * 1e-3),
        Some(b) => {
            return Err(Failure::Input(anyhow!("--bar-length-um {b} is not a finite number")));
        }
        None if all_calibrated => {
            notes.push("bar length: the .b5r readings are relative to the bar's calibrated length, so its error is fixed at 0 µm (--bar-length-um to set another)".into());
            BarLength::Known(0.0)
        }
        None => BarLength::Fit,
    };
    let servo = match args.servo {
        Servo::Lag => ServoVariant::AxisLag,
        Servo::Paper => ServoVariant::PlaneMismatch,
    };
    Ok((ModelOptions { servo, bar_length }, notes))
}

/// The outputs of `fit` and `diagnose` against their inputs ([`outputs::check`]), before any
/// work.
fn check_fit_outputs(args: &FitArgs, reg: &Registry) -> Result<()> {
    let outs = outputs::files([
        (args.json.as_deref(), "--json"),
        (args.save_model.as_deref(), "--save-model"),
        (args.record.as_deref(), "--record"),
    ]);
    if outs.is_empty() {
        return Ok(());
    }
    let read: Vec<PathBuf> = inputs::files(&args.runs)?
        .into_iter()
        .chain(args.machine.machine_file.iter().cloned())
        .chain(outputs::loaded(reg))
        .collect();
    outputs::check(&outs, &read, args.force, "outputs")
}

/// Save a fitted model (checked by [`outputs::check`]).
fn save_model(saved: &SavedModel, path: &Path, force: bool) -> Result<()> {
    ballbar_io::ron_files::write_ron(saved, path, outputs::existing(force))
        .map_err(|e| outputs::written(e, force))
}

fn fit_cmd(args: &FitArgs, reg: &Registry) -> Result<()> {
    check_fit_outputs(args, reg)?;
    let m = machine(&args.machine, reg)?;
    let spec = m.spec.clone();
    let inputs = inputs::read(&args.runs, args.threads, args.placement, args.b5r_angles.spacing())?;
    inputs::check_machine(&inputs, &spec.name)?;
    let (opts, notes) = options(args, &inputs)?;
    let runs = &inputs.runs;
    let model = m.model(opts)?;
    let failure = |e: ballbar_fit::FitError| match e {
        ballbar_fit::FitError::NonFinite => inputs::no_finite_fit(e, runs),
        ballbar_fit::FitError::TooFewSamples { .. }
        | ballbar_fit::FitError::Model(_)
        | ballbar_fit::FitError::Diverged { .. } => Failure::Input(e.into()),
        other => Failure::Internal(other.into()),
    };
    // The backlash switches where the lagging axes reverse ([`ballbar_fit::switch`]).
    let (design, switch) = match args.backlash_switch {
        BacklashSwitch::Lagged => ballbar_fit::switch::switch_at_lagged_reversals(
            Design::new(&model, runs)?,
            args.threads,
        )
        .map_err(failure)?,
        BacklashSwitch::Commanded => {
            (Design::new(&model, runs)?, ballbar_fit::switch::Switch::commanded())
        }
    };
    let f = ballbar_fit::fit_factored(&design, args.threads);
    ballbar_model::progress::finish();
    let (f, fac) = f.map_err(failure)?;
    let assessment = ballbar_fit::alias::assess(&design, &f, &fac, args.threads)
        .map_err(|e| Failure::Internal(e.into()))?;
    drop(fac);
    let rep = report::FitReport::new(&model, &design, &f).with_aliases(&assessment);
    for note in &notes {
        outln!("{note}");
    }
    if let Some(line) = switch.describe() {
        outln!("{line}");
    }
    out!("{}", rep.terminal());
    out!("{}", ballbar_report::aliases::terminal(&f, &assessment));
    let comparison =
        vendor_comparison(&inputs, &model, &f, ballbar_report::vendor::Diagnosed::default());
    if let Some(p) = &args.json {
        let mut json = rep.json();
        json.assumed = ballbar_report::assumed::entries(runs);
        json.vendor_comparison = comparison;
        ballbar_report::aliases::fill(&mut json, &model, &f, &assessment, runs);
        write_json(p, &json, args.force)?;
    }
    if let Some(p) = &args.save_model {
        let mut saved = SavedModel::from_fit(&f, &spec, opts);
        saved.plugin = Some(SavedPlugin {
            name: m.plugin.name().to_string(),
            version: m.plugin.version().to_string(),
        });
        saved.session = Some(SavedSession::of_runs(runs));
        save_model(&saved, p, args.force)?;
    }
    if let Some(p) = &args.record {
        archive::record(
            (p, args.force),
            runs,
            Some(archive::archived_machine(&m, opts, &args.machine)?),
            Some(&f),
            None,
        )?;
    }
    Ok(())
}

fn diagnose_cmd(args: &FitArgs, reg: &Registry) -> Result<()> {
    check_fit_outputs(args, reg)?;
    let m = machine(&args.machine, reg)?;
    let inputs = inputs::read(&args.runs, args.threads, args.placement, args.b5r_angles.spacing())?;
    inputs::check_machine(&inputs, &m.spec.name)?;
    let (opts, notes) = options(args, &inputs)?;
    for note in &notes {
        outln!("{note}");
    }
    let (d, json) = diagnose_inputs(&m, opts, &inputs, (args.threads, args.backlash_switch))?;
    let runs = &inputs.runs;
    if let Some(p) = &args.json {
        write_json(p, &json, args.force)?;
    }
    if let Some(p) = &args.record {
        archive::record(
            (p, args.force),
            runs,
            Some(archive::archived_machine(&m, opts, &args.machine)?),
            Some(&d.base),
            Some(to_value(&json)?),
        )?;
    }
    if let Some(p) = &args.save_model {
        let mut saved = SavedModel::from_fit(&d.augmented, &m.spec, opts);
        saved.plugin = Some(SavedPlugin {
            name: m.plugin.name().to_string(),
            version: m.plugin.version().to_string(),
        });
        saved.effects = d.model_effects.clone();
        saved.session = Some(SavedSession::of_runs(runs));
        save_model(&saved, p, args.force)?;
    }
    Ok(())
}

/// Diagnose the runs, print the diagnosis (and the vendor's analysis of `.b5r` inputs beside
/// ours), and return it with its JSON (`vendor_comparison` included).
fn diagnose_inputs(
    m: &Machine,
    opts: ModelOptions,
    inputs: &inputs::Inputs,
    (threads, args_switch): (usize, BacklashSwitch),
) -> Result<(ballbar_diagnose::Diagnosis, ballbar_documents::diagnosis::Diagnosis)> {
    let runs = &inputs.runs;
    // Build the model once here, so that a bad description is an input error before any work.
    let model = m.model(opts)?;
    let d = ballbar_diagnose::diagnose(
        &m.spec,
        opts,
        &*m.plugin,
        runs,
        ballbar_diagnose::Options {
            threads,
            commanded_switch: args_switch == BacklashSwitch::Commanded,
            ..Default::default()
        },
    );
    ballbar_model::progress::finish();
    let d = d.map_err(|e| match e {
        ballbar_diagnose::DiagnoseError::Fit(ballbar_fit::FitError::NonFinite) => {
            inputs::no_finite_fit(e, runs)
        }
        ballbar_diagnose::DiagnoseError::Model(_)
        | ballbar_diagnose::DiagnoseError::Fit(
            ballbar_fit::FitError::TooFewSamples { .. }
            | ballbar_fit::FitError::Diverged { .. }
            | ballbar_fit::FitError::Model(_),
        ) => Failure::Input(e.into()),
        other => Failure::Internal(other.into()),
    })?;
    if let Some(line) = d.switch.describe() {
        outln!("{line}");
    }
    out!("{}", diagnosis::terminal(&d, runs));
    let mut json = diagnosis::document(&d, runs);
    json.assumed = ballbar_report::assumed::entries(runs);
    let mut comparison = Vec::new();
    for v in &inputs.vendor {
        let rms_after_um = ballbar_report::vendor::rms_um(&d.augmented.residuals, v.runs.clone());
        let diagnosed = ballbar_report::vendor::Diagnosed {
            rms_after_um: Some(rms_after_um),
            diagnosis: Some(&json),
        };
        let entries = ballbar_report::vendor::compare(
            &v.test,
            runs,
            v.runs.clone(),
            &model,
            &d.base,
            diagnosed,
        );
        out!("{}", ballbar_report::vendor::terminal(&v.test.source, &entries));
        comparison.extend(entries);
    }
    if !inputs.vendor.is_empty() {
        json.vendor_comparison = Some(ballbar_report::vendor::document(&comparison));
    }
    Ok((d, json))
}

/// The vendor's analysis of every `.b5r` input beside ours: printed, and returned as the
/// `vendor_comparison` entries (`None` without `.b5r` inputs).
fn vendor_comparison(
    inputs: &inputs::Inputs,
    model: &Model,
    f: &ballbar_fit::Fit,
    diagnosed: ballbar_report::vendor::Diagnosed,
) -> Option<Vec<ballbar_documents::VendorEntry>> {
    if inputs.vendor.is_empty() {
        return None;
    }
    let mut all = Vec::new();
    for v in &inputs.vendor {
        let entries = ballbar_report::vendor::compare(
            &v.test,
            &inputs.runs,
            v.runs.clone(),
            model,
            f,
            diagnosed,
        );
        out!("{}", ballbar_report::vendor::terminal(&v.test.source, &entries));
        all.extend(entries);
    }
    Some(ballbar_report::vendor::document(&all))
}

/// What `dR_model_um` leaves out, said after every `predict` (docs/run-format.md).
const PREDICT_NOTE: &str = "note: dR_model_um is the saved model's prediction for the run's path, feed and direction; it leaves out \
    the set-up eccentricity (each run's centring offset, which the fit estimates per run and does not save: a new set-up has its own), \
    so the measured dR_um minus dR_model_um keeps it as a once-per-revolution term: compare them about their least-squares circles";

/// How `predict` relates the runs' clock to the model's session (`--same-session`,
/// `--time-origin`).
struct Clock {
    same_session: bool,
    time_origin: Option<String>,
}

/// A run that starts more than this after the model's session ended is of another session, s.
/// Within a session the pauses between tests are minutes (re-seating the bar in another plane,
/// a change of feed or tool); a machine left idle for an hour has lost most of a thermal
/// growth with the time constants the diagnosis fits (10 to 80 min,
/// `ballbar_diagnose::GROWTH_TAU_MIN`: e^{-60/40} ≈ 0.22 of one of 40 min left), so its
/// runs after that pause are not on the curve the model's session followed.
const OTHER_SESSION_AFTER_S: f64 = 3600.0;

/// A run may start this much before the time origin and still be of its session, s: the
/// saved session's times are written to the millisecond.
const ORIGIN_RESOLUTION_S: f64 = 1e-3;

/// The time origin of `predict`'s time-dependent terms (Unix seconds) and what it says about
/// it; runs of another session refused unless the user said how they relate ([`Clock`]).
fn time_origin(
    model_path: &Path,
    saved: &SavedModel,
    runs: &[ballbar_model::Run],
    clock: &Clock,
) -> Result<(f64, Option<String>)> {
    let session = match &saved.session {
        Some(s) => {
            Some(s.unix_s().map_err(|m| Failure::Input(anyhow!("{}: {m}", model_path.display())))?)
        }
        None => None,
    };
    let time_dependent = saved.is_time_dependent();
    let (origin, from) = match (&clock.time_origin, session) {
        (Some(t), _) => {
            let origin = ballbar_model::time::parse_iso8601(t)
                .map_err(|m| Failure::Input(anyhow!("--time-origin: {m}")))?;
            (origin, format!("{t} (--time-origin)"))
        }
        (None, Some((start, _))) => (
            start,
            format!(
                "{}, the start of the model's session",
                saved.session.as_ref().map_or("", |s| &s.started_at)
            ),
        ),
        (None, None) => {
            let start = ballbar_model::design::session_start_unix_s(runs);
            let note = format!(
                "note: {}: the model does not say when its session started (saved without it); {} from the earliest run given, {} (--time-origin ISO8601 gives the session's start)",
                model_path.display(),
                if time_dependent {
                    "its time-dependent terms are evaluated"
                } else {
                    "it has no time-dependent term, so this does not change the prediction; time counted"
                },
                ballbar_model::time::format_iso8601(start)
            );
            return Ok((start, Some(note)));
        }
    };
    for run in runs.iter().filter(|_| time_dependent) {
        let h = &run.header;
        if h.started_at_unix_s < origin - ORIGIN_RESOLUTION_S {
            return Err(Failure::Input(anyhow!(
                "{}: run {} started at {}, before the time origin {from}: it is not a later run of that session (--time-origin gives the start of its own session)",
                run.source,
                run.name(),
                h.started_at
            )));
        }
    }
    if let (Some((_, end)), None, false, true) =
        (session, &clock.time_origin, clock.same_session, time_dependent)
    {
        for run in runs {
            let h = &run.header;
            if h.started_at_unix_s > end + OTHER_SESSION_AFTER_S {
                let s = saved.session.as_ref().expect("parsed above");
                return Err(Failure::Input(anyhow!(
                    "{}: run {} started at {}, {:.1} h after the model's session ({} to {}, {}) ended: a run of another session; the model's time-dependent terms need to know how it relates: --same-session takes it as a later run of the model's session (time counted from {}), --time-origin ISO8601 gives the start of its own session",
                    run.source,
                    run.name(),
                    h.started_at,
                    (h.started_at_unix_s - end) / 3600.0,
                    s.started_at,
                    s.ended_at,
                    model_path.display(),
                    s.started_at
                )));
            }
        }
    }
    let note = time_dependent.then(|| {
        let minutes = |r: &ballbar_model::Run| (r.header.started_at_unix_s - origin) / 60.0;
        let (lo, hi) = runs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), r| {
            (lo.min(minutes(r)), hi.max(minutes(r)))
        });
        format!(
            "time-dependent terms evaluated from {from}: the runs start {lo:.1} to {hi:.1} min after it"
        )
    });
    Ok((origin, note))
}

fn predict(
    model_path: &Path,
    run_paths: &[PathBuf],
    placement: inputs::Placement,
    b5r_angles: inputs::Angles,
    out: &Path,
    (clock, force): (&Clock, bool),
    reg: &Registry,
) -> Result<()> {
    let saved: SavedModel = ballbar_io::ron_files::read_ron(model_path)?;
    let model = compensate::model_of(&saved, model_path, reg)?;
    let runs = inputs::read(run_paths, 2, placement, b5r_angles.spacing())?.runs;
    let (origin, time_note) = time_origin(model_path, &saved, &runs, clock)?;
    // The fitted model's own switch lags: its backlash switches where the fit's did.
    let (switch_lags, switch_note) = saved.switch_lags();
    // Every output computed before the first is written: nothing half-written.
    let mut written: Vec<(PathBuf, String)> = Vec::with_capacity(runs.len());
    for run in &runs {
        let one = std::slice::from_ref(run);
        let design = Design::with_origin(&model, one, origin)?.with_switch_lags(switch_lags);
        let mut theta = vec![0.0; design.n_cols()];
        for p in &saved.parameters {
            let i = design.parameters.iter().position(|q| q.id == p.id).ok_or_else(|| {
                anyhow!(
                    "{}: parameter {} is not in machine '{}'",
                    model_path.display(),
                    p.id,
                    saved.machine.name
                )
            })?;
            theta[i] = p.value;
        }
        // The run's own centring is unknown to the model: predicted as zero.
        let pred: Vec<f64> = design.exact_run(0, &theta)?.iter().map(|x| x * 1e3).collect();
        let src = Path::new(&run.source);
        let (name, with) = if ballbar_io::b5r::is_b5r(src) {
            // A vendor file's run becomes a run CSV named by its run id, with the column.
            let name = format!("{}.csv", run.name());
            let text = ballbar_io::run_text(run, &out.join(&name))?;
            (name.clone(), ballbar_io::append_column(&text, &name, "dR_model_um", &pred)?)
        } else {
            let text =
                std::fs::read_to_string(src).with_context(|| format!("{}", src.display()))?;
            let name = src
                .file_name()
                .ok_or_else(|| anyhow!("{}: not a file", src.display()))?
                .to_string_lossy()
                .into_owned();
            (name, ballbar_io::append_column(&text, &run.source, "dR_model_um", &pred)?)
        };
        let target = out.join(&name);
        if written.iter().any(|(t, _)| *t == target) {
            return Err(Failure::Input(anyhow!(
                "{}: two runs would be written there; nothing was written",
                target.display()
            )));
        }
        written.push((target, with));
    }
    let targets: Vec<outputs::Output> =
        written.iter().map(|(t, _)| outputs::Output::new(t, "--out")).collect();
    let sources: Vec<PathBuf> = runs
        .iter()
        .map(|r| PathBuf::from(&r.source))
        .chain([model_path.to_path_buf()])
        .chain(outputs::loaded(reg))
        .collect();
    outputs::check(&targets, &sources, force, "runs")?;
    std::fs::create_dir_all(out)
        .with_context(|| format!("{}: cannot create the folder", out.display()))?;
    outputs::write_all(&written, force)?;
    outln!("wrote {} runs with dR_model_um to {}", runs.len(), out.display());
    if let Some(note) = time_note {
        outln!("{note}");
    }
    if let Some(note) = switch_note {
        outln!("note: {}: {note}", model_path.display());
    }
    if let Some(note) = inputs::geometry_note(&runs) {
        outln!("{note}");
    }
    outln!("{PREDICT_NOTE}");
    Ok(())
}

/// `ballbar plugins [--json [FILE]]`: the list for a person, or its JSON to FILE (`-` or no
/// FILE: standard output, and no list for a person).
fn plugins(json: Option<&Path>, force: bool, reg: &Registry) -> Result<()> {
    // A plugin file is an input of the command: `--json` never replaces one.
    let outs = outputs::files([(json, "--json")]);
    outputs::check(&outs, &outputs::loaded(reg), force, "outputs")?;
    // A machine plugin is asked for its description too (its `describe`, the one plugin
    // function listing calls: what a plugin provides is what it describes): one that cannot
    // give it is listed with its problem, and the command fails.
    let described: Vec<std::result::Result<Option<String>, String>> = reg
        .plugins
        .iter()
        .map(|p| {
            if p.reads_machine_files() {
                Ok(None)
            } else {
                p.machine().map(|m| Some(m.description)).map_err(|e| e.to_string())
            }
        })
        .collect();
    if let Some(path) = json {
        let v = serde_json::json!({
            "plugins": reg.plugins.iter().zip(&described).map(|(p, d)| serde_json::json!({
                "name": p.name(), "version": p.version(), "abi_version": p.abi_version(), "path": p.path().display().to_string(),
                "reads_machine_files": p.reads_machine_files(), "kernels": p.kernel_names(),
                "description": d.as_ref().ok().cloned().flatten(), "problem": d.as_ref().err(),
            })).collect::<Vec<_>>(),
            "problems": reg.problems.iter().map(|e| e.to_string()).collect::<Vec<_>>(),
            "refused": reg.refused.iter().map(|r| serde_json::json!({"path": r.path.display().to_string(), "folder": r.folder, "source": r.source, "reason": r.reason, "fix": r.fix})).collect::<Vec<_>>(),
            "shadowed": reg.shadowed.iter().map(|(f, n)| serde_json::json!({"name": n, "path": f.display().to_string()})).collect::<Vec<_>>(),
            "searched": reg.searched.iter().map(|s| serde_json::json!({"source": s.source, "path": s.path.display().to_string()})).collect::<Vec<_>>(),
        });
        write_json(path, &v, force)?;
    }
    if json.is_none_or(|p| p.as_os_str() != "-") {
        if reg.plugins.is_empty() {
            return Err(Failure::Input(no_plugins(reg)));
        }
        outln!("{:<14} {:<9} {:<4} {:<34} path", "plugin", "version", "ABI", "provides");
        for (p, d) in reg.plugins.iter().zip(&described) {
            let provides = if p.reads_machine_files() {
                "machines from --machine-file".to_string()
            } else {
                format!("machine type '{}'", p.name())
            };
            let provides = if p.kernel_names().is_empty() {
                provides
            } else {
                format!("{provides}, kernels {}", p.kernel_names().join(", "))
            };
            outln!(
                "{:<14} {:<9} {:<4} {:<34} {}",
                p.name(),
                p.version(),
                p.abi_version(),
                provides,
                p.path().display()
            );
            match d {
                Ok(Some(text)) => outln!("{:<14} {text}", ""),
                Ok(None) => {}
                Err(e) => outln!("{:<14} PROBLEM: {e}", ""),
            }
        }
        for (f, n) in &reg.shadowed {
            outln!("  (not used: {} — an earlier plugin is also named '{n}')", f.display());
        }
        outln!("searched: {}", reg.searched_text());
        for r in &reg.refused {
            outln!("{r}");
        }
    }
    if reg.plugins.is_empty() {
        return Err(Failure::Input(no_plugins(reg)));
    }
    if let Some(e) = described.iter().find_map(|d| d.as_ref().err()) {
        return Err(Failure::Input(anyhow!("{e}")));
    }
    Ok(())
}

/// `--info KEY=VALUE` of `report`: the key one of the session form's fields.
fn parse_info(s: &str) -> std::result::Result<(String, String), String> {
    let pair = ballbar_report::session_info::parse_pair(s)?;
    ballbar_report::session_info::check_given(std::slice::from_ref(&pair))?;
    Ok(pair)
}

/// `ballbar report RUN... --machine NAME --out DIR`: diagnose the runs with the default
/// options (as `diagnose` does) and write the page of that session, without an archive.
#[allow(clippy::too_many_arguments)]
fn report_runs(
    files: &[PathBuf],
    m: &MachineArgs,
    placement: inputs::Placement,
    b5r_angles: inputs::Angles,
    (out, force): (&Path, bool),
    history: Option<&Path>,
    page: &ballbar_report::PageOptions,
    reg: &Registry,
) -> Result<PathBuf> {
    let args = FitArgs {
        machine: m.clone(),
        runs: files.to_vec(),
        placement,
        b5r_angles,
        json: None,
        save_model: None,
        servo: Servo::Lag,
        backlash_switch: BacklashSwitch::Lagged,
        bar_length_um: None,
        threads: 2,
        record: None,
        force: false,
    };
    let machine = machine(m, reg)?;
    let inputs = inputs::read(files, args.threads, placement, args.b5r_angles.spacing())?;
    inputs::check_machine(&inputs, &machine.spec.name)?;
    let (opts, notes) = options(&args, &inputs)?;
    for note in &notes {
        outln!("{note}");
    }
    let (d, json) = diagnose_inputs(&machine, opts, &inputs, (args.threads, args.backlash_switch))?;
    let session = archive::session(
        &inputs.runs,
        Some(archive::archived_machine(&machine, opts, m)?),
        Some(&d.base),
        Some(to_value(&json)?),
    )?;
    let name = files.iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(" ");
    write_pages(&name, &session, &*machine.plugin, &history_sessions(history)?, (out, force), page)
}

/// The report's page, `out/index.html`, against the report's inputs (`read`, the archives of
/// `history`, the plugins) before any work ([`outputs::check`]).
fn check_page(
    out: &Path,
    read: Vec<PathBuf>,
    history: Option<&Path>,
    force: bool,
    reg: &Registry,
) -> Result<()> {
    let page = [outputs::Output::new(out.join("index.html"), "--out")];
    let read: Vec<PathBuf> = read
        .into_iter()
        .chain(history.map(archive::files_of).transpose()?.into_iter().flatten())
        .chain(outputs::loaded(reg))
        .collect();
    outputs::check(&page, &read, force, "outputs")
}

/// Build the HTML report of an archive into `out/index.html` (the CLI's `report` and `cargo
/// xtask report`); returns the page's path. An existing page is replaced only with `force`.
pub fn report_cmd(
    file: &Path,
    out: &Path,
    history: Option<&Path>,
    force: bool,
    reg: &Registry,
) -> Result<PathBuf> {
    check_page(out, vec![file.to_path_buf()], history, force, reg)?;
    let options = ballbar_report::PageOptions::default();
    report_page(file, out, history, &options, force, reg)
}

/// [`report_cmd`] with the session's fields and tolerances the user gives (`--info`,
/// `--tolerance`), its page checked by the caller ([`check_page`]).
fn report_page(
    file: &Path,
    out: &Path,
    history: Option<&Path>,
    options: &ballbar_report::PageOptions,
    force: bool,
    reg: &Registry,
) -> Result<PathBuf> {
    let session =
        archive::read_session(file, "a report needs the whole archive: nothing was written")?;
    // A plugin is needed again only for a machine's kernel terms.
    let needs = session.machine.as_ref().is_some_and(|m| {
        m.spec.terms.iter().any(|t| matches!(t, ballbar_model::machine::TermSpec::Kernel { .. }))
    });
    let plugin = match (&session.machine, needs) {
        (Some(m), true) => Some(reg.find(&m.plugin_name).cloned().ok_or_else(|| {
            Failure::Input(anyhow!("{}: the machine's kernel terms need plugin '{}' {}, which is not loaded (looked in: {})", file.display(), m.plugin_name, m.plugin_version, reg.searched_text()))
        })?),
        _ => None,
    };
    let kernels: &dyn ballbar_model::KernelSource = match &plugin {
        Some(p) => &**p,
        None => &ballbar_model::NoKernels,
    };
    let sessions = history_sessions(history)?;
    write_pages(&file.display().to_string(), &session, kernels, &sessions, (out, force), options)
}

/// The trend sessions of `history` (a folder of archives): a damaged archive is named and left
/// out, so that it does not hide the others' trends.
fn history_sessions(history: Option<&Path>) -> Result<Vec<(String, ballbar_archive::Session)>> {
    let mut sessions = Vec::new();
    if let Some(dir) = history {
        let mut taken = ballbar_report::history::Sessions::default();
        for f in archive::files_of(dir)? {
            match ballbar_archive::read_with_checksums(&f) {
                Ok((s, sums)) => {
                    archive::checksums(&f, &sums, "nothing was written")?;
                    if archive::take_session(&mut taken, &f, &s) {
                        sessions.push((f.display().to_string(), s));
                    }
                }
                Err(e) => eprintln!("warning: left out of the trends: {e}"),
            }
        }
    }
    Ok(sessions)
}

fn write_pages(
    name: &str,
    session: &ballbar_archive::Session,
    kernels: &dyn ballbar_model::KernelSource,
    sessions: &[(String, ballbar_archive::Session)],
    (out, force): (&Path, bool),
    options: &ballbar_report::PageOptions,
) -> Result<PathBuf> {
    let page = ballbar_report::build_with(name, session, kernels, sessions, options)?;
    if !page.refit_identical && session.fit.is_some() {
        eprintln!(
            "warning: {name}: the refit differs from the archived fit; the report shows the refit"
        );
    }
    std::fs::create_dir_all(out)
        .with_context(|| format!("{}: cannot create the folder", out.display()))?;
    let path = out.join("index.html");
    outputs::write(&path, page.html.as_bytes(), force)?;
    for line in &page.acceptance {
        outln!("{line}");
    }
    Ok(path)
}

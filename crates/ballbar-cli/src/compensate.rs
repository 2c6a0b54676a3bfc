//! `ballbar compensate` and `ballbar verify` (`../shared/spec/compensate.md`), and the
//! controller files `simulate --compensation DIR` runs the machine with.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, anyhow};
use ballbar_compensate::{Compensation, Estimate, Options, linuxcnc, verify};
use ballbar_fit::saved::{SAVED_MODEL_FORMAT, SavedModel};
use ballbar_model::{Axis, Design, Model, Run};
use ballbar_plugin_host::Registry;
use clap::ValueEnum;

use crate::{Failure, Result, inputs, outputs};

/// `compensate --help`'s text on the controllers.
pub const CONTROLLER_HELP: &str = "The controller whose files to write: linuxcnc \
    (linuxcnc.ini [JOINT_n] BACKLASH or COMP_FILE with COMP_FILE_TYPE = 1, joint-n.comp tables) or siemens \
    (AX_EEC.INI leadscrew error tables $AA_ENC_COMP, NC_CEC.INI sag/angularity tables $AN_CEC for a squareness or straightness, MD_COMP.INI MD32700, MD32710, SD41300 and MD32450 backlash) or fanuc \
    (FANUC.DAT parameter file: pitch error compensation Nos. 3620-3624 and data, backlash No. 1851) or heidenhain \
    (X.COM compensation value tables with the backlash as their negative direction and a squareness as another axis's column, CONFIG.CMA assigning them)";

/// The controllers of the contract.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Controller {
    /// LinuxCNC: joint compensation files and BACKLASH.
    Linuxcnc,
    /// Siemens SINUMERIK: leadscrew error tables and backlash machine data.
    Siemens,
    /// FANUC: pitch error compensation and backlash parameters.
    Fanuc,
    /// HEIDENHAIN TNC: nonlinear axis error compensation tables.
    Heidenhain,
}

/// `ballbar compensate`'s arguments.
#[derive(clap::Args, Debug)]
pub struct CompensateArgs {
    /// Saved model (`fit --save-model` or `diagnose --save-model`).
    #[arg(long)]
    pub model: PathBuf,
    /// The controller ([`CONTROLLER_HELP`]).
    #[arg(long, value_enum, help = CONTROLLER_HELP)]
    pub controller: Controller,
    /// Output folder: the controller's files, model.json, compensation.json.
    #[arg(long)]
    pub out: PathBuf,
    /// The tests the model was fitted to (run CSVs, `.b5r` files, folders), which will be
    /// repeated after compensation: the prediction is made for them, and a table covers the
    /// span they measured. Without them only a backlash is written and nothing is predicted.
    pub runs: Vec<PathBuf>,
    /// Where `.b5r` circles were (as for `fit`).
    #[command(flatten)]
    pub placement: inputs::Placement,
    /// The span a table covers, machine coordinates, mm (repeatable): `X=0:500`. Without it, the
    /// span the tests measured and no more; a scale is extended linearly, a higher degree held.
    #[arg(long, value_name = "AXIS=MIN:MAX")]
    pub travel: Vec<String>,
    /// The compensation active while the tests ran, files of the same controller (a folder
    /// with linuxcnc.ini, or the INI file; a folder with the SINUMERIK, FANUC or HEIDENHAIN
    /// files): the new files are its values plus the measured correction, and keep its tables
    /// of axes the model does not compensate.
    #[arg(long, value_name = "PATH")]
    pub existing: Option<PathBuf>,
    /// Controller joint numbers of the compensated axes where they are not trivkins' X=0, Y=1,
    /// Z=2 nor the --existing configuration's: `X=0,Y=2,Z=1`, or a subset (`X=0,Z=1` for a
    /// lathe); every compensated axis must be named.
    #[arg(long, value_name = "X=0,Y=1,Z=2")]
    pub joints: Option<String>,
    /// Write a term whose value depends on what the tests cannot separate (an alias), as
    /// fitted: its id (`EXX1`) or its kind (`scale`, `positional`, `backlash`); repeatable or
    /// comma-separated. Without it such a term is not written, and compensation.json says why.
    #[arg(long, value_name = "ID|TERM", value_delimiter = ',')]
    pub include_aliased: Vec<String>,
    /// Worker threads of the fit (at least 1).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Replace files that exist in the output folder.
    #[arg(long)]
    pub force: bool,
}

/// `ballbar verify`'s arguments.
#[derive(clap::Args, Debug)]
pub struct VerifyArgs {
    /// The folder `compensate` wrote (compensation.json and model.json are read from it).
    #[arg(long)]
    pub compensation: PathBuf,
    /// The same tests, repeated with the compensation active.
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Where `.b5r` circles were (as for `fit`).
    #[command(flatten)]
    pub placement: inputs::Placement,
    /// Write the verification (ballbar-verification/1) to FILE; `-` for standard output.
    #[arg(long, value_name = "FILE")]
    pub json: Option<PathBuf>,
    /// Worker threads of the fit (at least 1).
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Replace the --json file if it exists.
    #[arg(long)]
    pub force: bool,
}

/// The model of a saved file (`path`, for messages): its format checked, its machine
/// description as saved; the plugin only for kernel terms, warned of when its version is not
/// the one the model was saved with.
pub(crate) fn model_of(saved: &SavedModel, path: &Path, reg: &Registry) -> Result<Model> {
    if saved.format != SAVED_MODEL_FORMAT {
        return Err(Failure::Input(anyhow!(
            "{}: format '{}' is not {SAVED_MODEL_FORMAT}",
            path.display(),
            saved.format
        )));
    }
    let needs_kernels = saved
        .machine
        .terms
        .iter()
        .any(|t| matches!(t, ballbar_model::machine::TermSpec::Kernel { .. }));
    let model = match (&saved.plugin, needs_kernels) {
        (Some(sp), true) => {
            let plugin = reg.find(&sp.name).ok_or_else(|| {
                anyhow!(
                    "{}: the model's kernel terms need plugin '{}' {}, which is not loaded (looked in: {})",
                    path.display(),
                    sp.name,
                    sp.version,
                    reg.searched_text()
                )
            })?;
            if plugin.version() != sp.version {
                eprintln!(
                    "warning: {}: saved with plugin '{}' {}, used with version {}",
                    path.display(),
                    sp.name,
                    sp.version,
                    plugin.version()
                );
            }
            Model::with_effects(saved.machine.clone(), saved.options, &**plugin, &saved.effects)
        }
        _ => Model::with_effects(
            saved.machine.clone(),
            saved.options,
            &ballbar_model::NoKernels,
            &saved.effects,
        ),
    }
    .with_context(|| format!("{}", path.display()))?;
    Ok(model)
}

/// A saved model, RON (`fit --save-model`) or JSON (the copy `compensate` writes as
/// `DIR/model.json`), told apart by its content: JSON starts with `{`, RON with a struct.
pub(crate) fn read_saved_model(path: &Path) -> Result<SavedModel> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    if text.trim_start().starts_with('{') {
        serde_json::from_str(&text).map_err(|e| {
            Failure::Input(anyhow!(
                "{}:{}:{}: not a saved model (JSON): {e}",
                path.display(),
                e.line(),
                e.column()
            ))
        })
    } else {
        Ok(ballbar_io::ron_files::parse_ron(&text, path)?)
    }
}

/// The estimates of a saved model without runs to refit: its values as saved, no aliases (a
/// saved model does not carry them).
fn saved_estimates(model: &Model, saved: &SavedModel) -> Vec<Estimate> {
    model
        .parameters()
        .into_iter()
        .filter_map(|p| {
            let s = saved.parameters.iter().find(|s| s.id == p.id)?;
            Some(Estimate {
                id: p.id,
                class: p.class,
                unit: p.unit,
                value: s.value,
                u: s.std_uncertainty,
                estimable: s.estimable,
                aliases: Vec::new(),
            })
        })
        .collect()
}

/// Fit runs with a model; each machine parameter's estimate and, with `values` (a saved
/// model's, which replace the fit's values and uncertainties by id: `compensate`), the aliases
/// it is conditional on. Without `values` (`verify`, which compares values only) the aliases
/// are not assessed.
///
/// The backlash switches where the saved model's does (`values`' switch lags, as `predict`
/// evaluates it): the aliases assessed are those of the fit its values came from, and the
/// search for the switch, a third of the command's time, is not repeated. For `verify`, and a
/// model saved without its switch lags, it switches where `ballbar fit` would put it for these
/// runs. With the estimates, the switch lags the fit used (s, per axis).
fn estimates(
    model: &Model,
    runs: &[Run],
    threads: usize,
    values: Option<&SavedModel>,
) -> Result<(Vec<Estimate>, [f64; 6], FitCovariance)> {
    // Without the saved model's switch, as `ballbar fit` makes it (its default
    // `--backlash-switch lagged`): the backlash switching at the axes' lagged reversals where
    // these runs determine them, so that a term before and after compensation is fitted alike.
    let design = Design::new(model, runs)?;
    let design = match values.and_then(|s| s.switch_lags_s) {
        Some(lags) => design.with_switch_lags(lags),
        None => {
            ballbar_fit::switch::switch_at_lagged_reversals(design, threads.max(1))
                .map_err(|e| Failure::Input(e.into()))?
                .0
        }
    };
    let (fit, fac) = ballbar_fit::fit_factored(&design, threads.max(1)).map_err(|e| match e {
        ballbar_fit::FitError::NonFinite => inputs::no_finite_fit(e, runs),
        other => Failure::Input(other.into()),
    })?;
    let assessment = match values {
        Some(_) => Some(
            ballbar_fit::alias::assess(&design, &fit, &fac, threads.max(1))
                .map_err(|e| Failure::Internal(e.into()))?,
        ),
        None => None,
    };
    drop(fac);
    let mut out = Vec::new();
    for i in 0..fit.n_machine {
        let p = &fit.parameters[i];
        let q = ballbar_fit::alias::Quantity::Parameter(i);
        let Some(assessment) = &assessment else {
            out.push(plain_estimate(&fit, i));
            continue;
        };
        let aliases = assessment
            .conditional_on(q)
            .into_iter()
            .map(|k| {
                let a = &assessment.aliases[k];
                let alt = assessment.move_of(k, q).and_then(|m| m.alternative).map_or(
                    String::new(),
                    |v| {
                        format!(
                            " (if it holds, {} = {:.4} {})",
                            p.id,
                            v * p.unit.display_factor(),
                            p.unit.display_name()
                        )
                    },
                );
                format!(
                    "{}{alt}; separate with: {}",
                    a.candidate.description(),
                    a.candidate.test_to_separate()
                )
            })
            .collect();
        let (value, u, estimable) =
            match values.and_then(|s| s.parameters.iter().find(|s| s.id == p.id)) {
                Some(s) => (s.value, s.std_uncertainty, s.estimable),
                None => (fit.values[i], fit.std_uncertainty[i], fit.estimable[i]),
            };
        out.push(Estimate {
            id: p.id.clone(),
            class: p.class,
            unit: p.unit,
            value,
            u,
            estimable,
            aliases,
        });
    }
    Ok((out, design.switch_lags(), FitCovariance(std::sync::Arc::new(fit))))
}

/// A fit's covariance of its machine parameters, by id ([`ballbar_compensate::Covariance`]).
#[derive(Clone, Debug)]
struct FitCovariance(std::sync::Arc<ballbar_fit::Fit>);

impl ballbar_compensate::Covariance for FitCovariance {
    fn combination(&self, weights: &[(&str, f64)]) -> Option<(f64, bool)> {
        let fit = &self.0;
        let pairs: Vec<(usize, f64)> = weights
            .iter()
            .map(|&(id, w)| {
                (0..fit.n_machine).find(|&i| fit.parameters[i].id == id).map(|i| (i, w))
            })
            .collect::<Option<_>>()?;
        let f = fit.functional(&pairs);
        Some((f.std_uncertainty, f.estimable))
    }
}

/// Machine parameter `i` of `fit` as an estimate, its aliases not assessed.
fn plain_estimate(fit: &ballbar_fit::Fit, i: usize) -> Estimate {
    let p = &fit.parameters[i];
    Estimate {
        id: p.id.clone(),
        class: p.class,
        unit: p.unit,
        value: fit.values[i],
        u: fit.std_uncertainty[i],
        estimable: fit.estimable[i],
        aliases: Vec::new(),
    }
}

/// `AXIS=MIN:MAX`.
fn parse_travel(text: &str) -> Result<(Axis, [f64; 2])> {
    let bad =
        || Failure::Usage(anyhow!("--travel {text}: expected AXIS=MIN:MAX in mm, e.g. X=0:500"));
    let (a, span) = text.split_once('=').ok_or_else(bad)?;
    let axis = Axis::from_name(a.trim()).filter(|a| !a.is_rotary()).ok_or_else(bad)?;
    let (lo, hi) = span.split_once(':').ok_or_else(bad)?;
    let (lo, hi): (f64, f64) =
        (lo.trim().parse().map_err(|_| bad())?, hi.trim().parse().map_err(|_| bad())?);
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return Err(bad());
    }
    Ok((axis, [lo, hi]))
}

/// `X=0,Y=1,Z=2`.
fn parse_joints(text: &str) -> Result<BTreeMap<Axis, usize>> {
    let bad = || {
        Failure::Usage(anyhow!(
            "--joints {text}: expected AXIS=NUMBER pairs, each number 0 to {}, e.g. X=0,Y=1,Z=2",
            MAX_JOINT
        ))
    };
    text.split(',')
        .map(|pair| {
            let (a, n) = pair.split_once('=').ok_or_else(bad)?;
            let n: usize = n.trim().parse().map_err(|_| bad())?;
            if n > MAX_JOINT {
                return Err(bad());
            }
            Ok((Axis::from_name(a.trim()).ok_or_else(bad)?, n))
        })
        .collect()
}

/// The largest joint number `--joints` takes: LinuxCNC's `EMCMOT_MAX_JOINTS` is 16 (joints 0 to
/// 15), more than any of the controllers written here numbers its axes by.
const MAX_JOINT: usize = 15;

/// The LinuxCNC files of a folder (its `linuxcnc.ini`) or an INI file, compensation files
/// beside it; the files read, for the rule that no input is written.
fn read_linuxcnc(path: &Path) -> Result<(linuxcnc::Files, Vec<PathBuf>)> {
    let ini = if path.is_dir() { path.join("linuxcnc.ini") } else { path.to_path_buf() };
    let folder = ini.parent().map(Path::to_path_buf).unwrap_or_default();
    let text = std::fs::read_to_string(&ini).with_context(|| format!("{}", ini.display()))?;
    let read_files = std::cell::RefCell::new(vec![ini.clone()]);
    let read = |name: &str| {
        let p = folder.join(name);
        read_files.borrow_mut().push(p.clone());
        std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))
    };
    let files =
        linuxcnc::Files::parse(&text, &ini.display().to_string(), &read).map_err(|m| anyhow!(m))?;
    Ok((files, read_files.into_inner()))
}

/// A SINUMERIK, FANUC or HEIDENHAIN compensation read by the simulator's emulation of its
/// controller, as `compensate --existing` merges it.
#[derive(Debug)]
struct ExistingController(ballbar_sim::controller::Controller);

impl ballbar_compensate::tables::Existing for ExistingController {
    fn kind(&self) -> &str {
        use ballbar_sim::controller::Controller as C;
        match &self.0 {
            C::LinuxCnc(_) => "linuxcnc",
            C::Siemens(_) => "siemens",
            C::Fanuc(_) => "fanuc",
            C::Heidenhain(_) => "heidenhain",
        }
    }
    /// Its own compensation of `axis` only, as the trait asks (a table or a backlash): the
    /// simulator counts an axis that is only the output of cross-axis tables (a column of
    /// another axis's `.COM`, a CEC table's output) as compensated, as it must apply them to
    /// it; here that axis has nothing of its own, and its cross-axis correction is in
    /// `crosses`. Otherwise the axis's own terms would read as held at 0 by the existing
    /// files, and the writers would take it as an axis of theirs.
    fn has(&self, axis: Axis) -> bool {
        use ballbar_sim::controller::JointTrims;
        let cross_output = self.0.cross_tables().iter().any(|c| c.1 == axis);
        JointTrims::has(&self.0, axis)
            && (!cross_output
                || self.0.span(axis).is_some()
                || JointTrims::trim(&self.0, axis, 0.0, true)
                    != JointTrims::trim(&self.0, axis, 0.0, false))
    }
    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64 {
        ballbar_sim::controller::JointTrims::trim(&self.0, axis, q_mm, forward)
    }
    fn span_mm(&self, axis: Axis) -> Option<[f64; 2]> {
        self.0.span(axis)
    }
    fn crosses(&self) -> Vec<(Axis, Axis, [f64; 2])> {
        self.0.cross_tables()
    }
    fn cross_trim_mm(&self, input: Axis, output: Axis, q_mm: f64) -> f64 {
        self.0.cross_of(input, output, q_mm)
    }
}

/// The controller of `simulate --compensation DIR`, emulated by the simulator, and the files
/// it read: the folder's files say which controller they are for (`linuxcnc.ini`: LinuxCNC; NC
/// programs and INI files in upper case: Siemens; a `.DAT` parameter file: FANUC; a `.CMA`
/// assignment table: HEIDENHAIN), or a LinuxCNC
/// INI file given itself.
pub fn simulated_controller(
    dir: &Path,
) -> Result<(ballbar_sim::controller::Controller, Vec<PathBuf>)> {
    use ballbar_sim::controller::{Controller, kind_of};
    if dir.is_dir() {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .with_context(|| format!("{}", dir.display()))?
            .filter_map(|e| e.ok())
            .filter(|e| e.path().is_file())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        match kind_of(&names) {
            Some("linuxcnc") => {}
            Some("fanuc") => {
                let mut c = ballbar_sim::fanuc::Fanuc::default();
                let mut paths = Vec::new();
                for n in names.iter().filter(|n| n.ends_with(".DAT")) {
                    let p = dir.join(n);
                    let text =
                        std::fs::read_to_string(&p).with_context(|| format!("{}", p.display()))?;
                    if !paths.is_empty() {
                        return Err(Failure::Input(anyhow!(
                            "{}: more than one FANUC parameter file (.DAT) here",
                            dir.display()
                        )));
                    }
                    c = ballbar_sim::fanuc::Fanuc::parse(&text, &p.display().to_string())
                        .map_err(|m| anyhow!(m))?;
                    paths.push(p);
                }
                return Ok((Controller::Fanuc(c), paths));
            }
            Some("heidenhain") => {
                let cma = names.iter().find(|n| n.ends_with(".CMA")).cloned().unwrap_or_default();
                let p = dir.join(&cma);
                let text =
                    std::fs::read_to_string(&p).with_context(|| format!("{}", p.display()))?;
                let read_files = std::cell::RefCell::new(vec![p.clone()]);
                let read = |name: &str| {
                    let f = dir.join(name);
                    read_files.borrow_mut().push(f.clone());
                    std::fs::read_to_string(&f).map_err(|e| format!("{}: {e}", f.display()))
                };
                let c = ballbar_sim::heidenhain::Heidenhain::parse(
                    &text,
                    &p.display().to_string(),
                    &read,
                )
                .map_err(|m| anyhow!(m))?;
                return Ok((Controller::Heidenhain(c), read_files.into_inner()));
            }
            Some("siemens") => {
                let mut files = Vec::new();
                let mut paths = Vec::new();
                for n in
                    names.iter().filter(|n| [".INI", ".MPF", ".SPF"].iter().any(|e| n.ends_with(e)))
                {
                    let p = dir.join(n);
                    files.push((
                        p.display().to_string(),
                        std::fs::read_to_string(&p).with_context(|| format!("{}", p.display()))?,
                    ));
                    paths.push(p);
                }
                let c = ballbar_sim::siemens::Siemens::parse(&files).map_err(|m| anyhow!(m))?;
                return Ok((Controller::Siemens(c), paths));
            }
            _ => {
                return Err(Failure::Input(anyhow!(
                    "{}: no controller's compensation files here (linuxcnc.ini; a FANUC parameter file .DAT; a HEIDENHAIN assignment table .CMA; or a SINUMERIK's .INI/.MPF/.SPF programs)",
                    dir.display()
                )));
            }
        }
    }
    let (c, read) = simulated_linuxcnc(dir)?;
    Ok((Controller::LinuxCnc(c), read))
}

/// A LinuxCNC configuration (a folder's `linuxcnc.ini`, or the INI file) as the simulator
/// emulates it, and the files it read.
fn simulated_linuxcnc(dir: &Path) -> Result<(ballbar_sim::linuxcnc::LinuxCnc, Vec<PathBuf>)> {
    let ini = if dir.is_dir() { dir.join("linuxcnc.ini") } else { dir.to_path_buf() };
    let folder = ini.parent().map(Path::to_path_buf).unwrap_or_default();
    let text = std::fs::read_to_string(&ini).with_context(|| format!("{}", ini.display()))?;
    let read_files = std::cell::RefCell::new(vec![ini.clone()]);
    let read = |name: &str| {
        let p = folder.join(name);
        read_files.borrow_mut().push(p.clone());
        std::fs::read_to_string(&p).map_err(|e| format!("{}: {e}", p.display()))
    };
    let c = ballbar_sim::linuxcnc::LinuxCnc::parse(&text, &ini.display().to_string(), &read)
        .map_err(|m| anyhow!(m))?;
    Ok((c, read_files.into_inner()))
}

/// `ballbar compensate`: [`compensate_written`], then what was done, printed.
pub fn compensate(args: &CompensateArgs, reg: &Registry) -> Result<()> {
    let (comp, written) = compensate_written(args, reg)?;
    print_compensation(&comp);
    outln!(
        "wrote {} to {}",
        written
            .iter()
            .filter_map(|p| p.file_name())
            .map(|n| n.to_string_lossy())
            .collect::<Vec<_>>()
            .join(", "),
        args.out.display()
    );
    Ok(())
}

/// Everything `ballbar compensate` does but print: read, fit, make and write the files;
/// `compensation.json`'s content and the files written.
pub fn compensate_written(
    args: &CompensateArgs,
    reg: &Registry,
) -> Result<(Compensation, Vec<PathBuf>)> {
    let mut options = Options::default();
    for t in &args.travel {
        let (a, span) = parse_travel(t)?;
        options.travel.insert(a, span);
    }
    if let Some(j) = &args.joints {
        options.joints = parse_joints(j)?;
    }
    options.include_aliased = args.include_aliased.iter().map(|n| n.trim().to_string()).collect();
    let mut read: Vec<PathBuf> = inputs::files(&args.runs)?
        .into_iter()
        .chain([args.model.clone()])
        .chain(outputs::loaded(reg))
        .collect();
    let kind = match args.controller {
        Controller::Linuxcnc => "linuxcnc",
        Controller::Siemens => "siemens",
        Controller::Fanuc => "fanuc",
        Controller::Heidenhain => "heidenhain",
    };
    if let Some(e) = &args.existing {
        if kind == "linuxcnc" {
            let (files, paths) = read_linuxcnc(e)?;
            options.existing = Some(files);
            read.extend(paths);
        } else {
            // The emulations read a SINUMERIK's AX1, AX2, AX3 and a FANUC's axes 1, 2, 3 as X,
            // Y, Z: other numbers from --joints would merge one axis's table into another's.
            if let Some((a, n)) = options.joints.iter().find(|(a, n)| a.index() != **n)
                && kind != "heidenhain"
            {
                return Err(Failure::Input(anyhow!(
                    "--existing {} with --joints {a}={n}: the existing {kind} files are read with X, Y, Z as axes 1, 2, 3, so a table numbered otherwise would be merged into another axis's; merge them by hand, or give --joints in that order; nothing was written",
                    e.display()
                )));
            }
            // Read as the controller reads them: the simulator's emulation, which refuses what
            // the controller would, naming the file and line.
            let (c, paths) = simulated_controller(e).map_err(|f| match f {
                Failure::Input(m) => Failure::Input(anyhow!(
                    "--existing {}: {m:#}; nothing was written",
                    e.display()
                )),
                other => other,
            })?;
            let existing = ExistingController(c);
            if ballbar_compensate::tables::Existing::kind(&existing) != kind {
                return Err(Failure::Input(anyhow!(
                    "--existing {}: the files are {}'s, not {kind}'s; nothing was written",
                    e.display(),
                    ballbar_compensate::tables::Existing::kind(&existing)
                )));
            }
            options.existing_tables = Some(std::sync::Arc::new(existing));
            read.extend(paths);
        }
    }
    let main_file = match kind {
        "linuxcnc" => "linuxcnc.ini",
        "fanuc" => ballbar_compensate::fanuc::FILE,
        "heidenhain" => ballbar_compensate::heidenhain::ASSIGNMENT_FILE,
        _ => ballbar_compensate::siemens::MACHINE_DATA_FILE,
    };
    let fixed = [main_file, "model.json", "compensation.json"];
    let outs: Vec<outputs::Output> =
        fixed.iter().map(|n| outputs::Output::new(args.out.join(n), "--out")).collect();
    outputs::check(&outs, &read, args.force, "compensation")?;
    let saved = read_saved_model(&args.model)?;
    let model = model_of(&saved, &args.model, reg)?;
    let (runs, pivot) = if args.runs.is_empty() {
        (Vec::new(), None)
    } else {
        let given =
            inputs::read(&args.runs, args.threads.max(1), args.placement, Default::default())?;
        (given.runs, given.pivot)
    };
    let (est, lags, covariance) = if runs.is_empty() {
        (saved_estimates(&model, &saved), [0.0; 6], None)
    } else {
        let (est, lags, cov) = estimates(&model, &runs, args.threads, Some(&saved))?;
        (est, lags, Some(cov))
    };
    // A name `--include-aliased` gives that no term has would write nothing it asked for,
    // silently: refused before anything is written.
    let terms: Vec<(String, String)> = ballbar_compensate::terms(&saved, &est)
        .into_iter()
        .map(|(t, _)| (t.id.clone(), t.term.clone()))
        .collect();
    if let Some(why) = unknown_included(&options.include_aliased, &terms) {
        return Err(Failure::Usage(anyhow!("{why}; nothing was written")));
    }
    let reading = TraceReading { model: model.clone(), lags, threads: args.threads.max(1) };
    if !runs.is_empty() {
        options.reading = Some(std::sync::Arc::new(reading.clone()));
    }
    if let Some(c) = covariance {
        options.covariance = Some(std::sync::Arc::new(c));
    }
    let nothing =
        |m: String| Failure::Input(anyhow!("{}: {m}; nothing was written", args.model.display()));
    let (mut comp, texts) = if kind == "linuxcnc" {
        let (mut comp, files) =
            ballbar_compensate::linuxcnc(&saved, &est, &runs, &options).map_err(nothing)?;
        ballbar_compensate::predict(&mut comp, &files, options.existing.as_ref(), &runs);
        (comp, files.texts())
    } else {
        let (comp, files) =
            ballbar_compensate::tables::compensate(kind, &saved, &est, &runs, &options)
                .map_err(nothing)?;
        (comp, files.texts())
    };
    predict_unwritten(&mut comp, &saved, &est, &runs, &reading);
    // A table's nominals are machine coordinates: where the circles were placed matters.
    if let Some((p, false)) = pivot {
        comp.notes.push(format!(
            "the .b5r circles were placed at the default centre {}, {}, {} mm (a .b5r file does not give it): the tables' nominals are machine coordinates only if that is where the circles were; give it with --pivot X,Y,Z",
            p[0], p[1], p[2]
        ));
    }
    if let Some(n) = inputs::geometry_note(&runs) {
        comp.notes.push(n.trim_start_matches("note: ").to_string());
    }
    let mut written: Vec<(PathBuf, String)> =
        texts.into_iter().map(|(n, t)| (args.out.join(n), t)).collect();
    let model_json =
        serde_json::to_string_pretty(&saved).map_err(|e| Failure::Internal(e.into()))?;
    let comp_json = serde_json::to_string_pretty(&comp).map_err(|e| Failure::Internal(e.into()))?;
    written.push((args.out.join("model.json"), model_json + "\n"));
    written.push((args.out.join("compensation.json"), comp_json + "\n"));
    let outs: Vec<outputs::Output> =
        written.iter().map(|(p, _)| outputs::Output::new(p, "--out")).collect();
    outputs::check(&outs, &read, args.force, "compensation")?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("{}: cannot create the folder", args.out.display()))?;
    outputs::write_all(&written, args.force)?;
    Ok((comp, written.into_iter().map(|(p, _)| p).collect()))
}

/// The value a re-measurement should show of each term the files do not write: its value plus
/// what the files' change of the traces moves it by through the fit. A table's steps (FANUC's
/// detection unit) and an existing table replaced change the trace by more than the written
/// terms' shapes, and the fit takes part of that into the other terms. That move is the fit of
/// the change alone (each run's predicted trace minus its measured one) with the backlash
/// switching where the measured runs' fit put it (`reading`): the fit is linear in the parameters
/// to first order, so this is the fit of the predicted traces minus that of the measured ones,
/// within the second order of the errors (parts in 1e4 of the move). Without a prediction for
/// every run, or where that fit fails (a note says so), nothing is set (verify then compares
/// with before).
fn predict_unwritten(
    comp: &mut Compensation,
    saved: &SavedModel,
    before: &[Estimate],
    runs: &[Run],
    reading: &TraceReading,
) {
    if runs.is_empty() || comp.predicted_runs.len() != runs.len() {
        return;
    }
    let change: Vec<Run> = comp
        .predicted_runs
        .iter()
        .zip(runs)
        .map(|(p, m)| {
            let mut r = m.clone();
            r.dr_mm = p.dr_mm.iter().zip(&m.dr_mm).map(|(a, b)| a - b).collect();
            r
        })
        .collect();
    let plain = match ballbar_compensate::reading::Reading::read(reading, &change) {
        Ok(plain) => plain,
        Err(e) => {
            comp.notes.push(format!(
                "the terms the files do not write are predicted to stay as measured: the fit of the files' change of the traces failed ({e})"
            ));
            return;
        }
    };
    let moves = ballbar_compensate::moves(saved, before, &plain);
    for t in comp.terms.iter_mut().filter(|t| !t.compensated) {
        let (v, _, _) = t.value();
        if let Some(d) = moves.get(&t.id)
            && (v + d).is_finite()
        {
            t.predicted_after = Some(v + d);
        }
    }
}

/// The fit of a change of the traces (`ballbar_compensate::reading`): the model's design on the
/// runs, the backlash switching at the measured runs' fit's lags (`lags`, s per axis), each
/// machine parameter's estimate.
#[derive(Clone, Debug)]
struct TraceReading {
    model: Model,
    lags: [f64; 6],
    threads: usize,
}

impl ballbar_compensate::reading::Reading for TraceReading {
    fn read(&self, change: &[Run]) -> std::result::Result<Vec<Estimate>, String> {
        let design = Design::new(&self.model, change).map_err(|e| e.to_string())?;
        let fit = ballbar_fit::fit(&design.with_switch_lags(self.lags), self.threads)
            .map_err(|e| e.to_string())?;
        Ok((0..fit.n_machine).map(|i| plain_estimate(&fit, i)).collect())
    }
}

fn print_compensation(comp: &Compensation) {
    let name = match comp.controller.as_str() {
        "linuxcnc" => "LinuxCNC",
        "siemens" => "SINUMERIK",
        "fanuc" => "FANUC",
        "heidenhain" => "HEIDENHAIN",
        other => other,
    };
    outln!(
        "{name} compensation (values in the model's convention, u: standard uncertainty, k = 1)"
    );
    outln!(
        "  {:<15} {:<4} {:<6} {:>10} {:>8} {:<5} {:>10}  written",
        "term",
        "axis",
        "id",
        "value",
        "u",
        "unit",
        "after"
    );
    for t in &comp.terms {
        let (v, u, unit) = t.value();
        let after = t.predicted_after.map_or("-".to_string(), |p| format!("{p:.3}"));
        let what = if t.compensated {
            t.files.join(", ")
        } else {
            format!("no: {}", t.why.clone().unwrap_or_default())
        };
        outln!(
            "  {:<15} {:<4} {:<6} {:>10.3} {:>8.3} {:<5} {:>10}  {what}",
            t.term,
            t.axis,
            t.id,
            v,
            u,
            unit,
            after
        );
    }
    // A written term a repeat of the same tests could not be expected to verify, one line
    // each: written (it is significant), why a repeat may not show it (its u, or the
    // controller's resolution), and what `verify` will then say.
    for t in comp.terms.iter().filter(|t| t.compensated && t.verifiable_by_repeat == Some(false)) {
        let short = ballbar_compensate::unverifiable_reason(t, t.resolution(comp.resolution()));
        let then = match t.sessions_to_verify {
            Some(n) => format!(
                "{n} sessions measured both before (the model refitted on them and compensated again) and after would show it, a repeat after alone only where |c| > 6 u_before (verify gives the count), or read the parameter back from the controller"
            ),
            None => "no number of repeated sessions would show it: read the parameter back from the controller".to_string(),
        };
        outln!(
            "  {} ({} {}): written; a repeat of these tests may not show its correction ({short}): verify may read not_resolved; {then}",
            t.id,
            t.term,
            t.axis,
        );
    }
    outln!("Runs: predicted after, about the least-squares circle (µm)");
    for p in &comp.predicted {
        outln!(
            "  {:<12} RMS {:>7.2} → {:>7.2}   G {:>7.2} → {:>7.2}",
            p.run,
            p.rms_before_um,
            p.rms_after_um,
            p.g_before_um,
            p.g_after_um
        );
    }
    for n in &comp.notes {
        outln!("note: {n}");
    }
}

/// A JSON document of `path`, errors naming the file, line and column.
fn read_document<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<T> {
    let text = std::fs::read_to_string(path).with_context(|| format!("{}", path.display()))?;
    serde_json::from_str(&text).map_err(|e| {
        Failure::Input(anyhow!(
            "{}:{}:{}: not a readable {what}: {e}",
            path.display(),
            e.line(),
            e.column()
        ))
    })
}

/// The compensation section's documents for `ballbar report`: `DIR/compensation.json` and the
/// verification, checked for their format tags, and the files read.
pub fn report_input(
    dir: Option<&Path>,
    verification: Option<&Path>,
) -> Result<(ballbar_report::compensation::CompensationInput, Vec<PathBuf>)> {
    let mut input = ballbar_report::compensation::CompensationInput::default();
    let mut read = Vec::new();
    if let Some(dir) = dir {
        let p = dir.join("compensation.json");
        let c: Compensation = read_document(&p, ballbar_compensate::COMPENSATION_FORMAT)?;
        if c.format != ballbar_compensate::COMPENSATION_FORMAT {
            return Err(Failure::Input(anyhow!(
                "{}: format '{}' is not {}",
                p.display(),
                c.format,
                ballbar_compensate::COMPENSATION_FORMAT
            )));
        }
        input.compensation = Some(c);
        read.push(p);
    }
    if let Some(p) = verification {
        let v: verify::Verification = read_document(p, verify::VERIFICATION_FORMAT)?;
        if v.format != verify::VERIFICATION_FORMAT {
            return Err(Failure::Input(anyhow!(
                "{}: format '{}' is not {}",
                p.display(),
                v.format,
                verify::VERIFICATION_FORMAT
            )));
        }
        input.verification = Some(v);
        read.push(p.to_path_buf());
    }
    Ok((input, read))
}

/// `ballbar verify`: the verdicts ([`verification`]) printed, and written with `--json`; exit 3
/// (the verdicts say why) unless every compensated term is corrected and none changed.
pub fn verify_cmd(args: &VerifyArgs, reg: &Registry) -> Result<()> {
    let v = verification(args, reg)?;
    report_verification(args, &v)
}

/// Everything `ballbar verify` does but print and write: read the compensation folder, fit the
/// repeated tests with its model, and compare term by term.
pub fn verification(args: &VerifyArgs, reg: &Registry) -> Result<verify::Verification> {
    let dir = &args.compensation;
    let read_json = |name: &str| -> Result<String> {
        let p = dir.join(name);
        Ok(std::fs::read_to_string(&p).with_context(|| format!("{}", p.display()))?)
    };
    let comp: Compensation = serde_json::from_str(&read_json("compensation.json")?)
        .with_context(|| format!("{}", dir.join("compensation.json").display()))?;
    let model_path = dir.join("model.json");
    let saved = read_saved_model(&model_path)?;
    if let Some(p) = &args.json {
        let read: Vec<PathBuf> = inputs::files(&args.runs)?
            .into_iter()
            .chain([dir.join("compensation.json"), model_path.clone()])
            .collect();
        outputs::check(&[outputs::Output::new(p, "--json")], &read, args.force, "verification")?;
    }
    let model = model_of(&saved, &model_path, reg)?;
    let runs =
        inputs::read(&args.runs, args.threads.max(1), args.placement, Default::default())?.runs;
    let (est, _, cov) = estimates(&model, &runs, args.threads, None)?;
    let after: BTreeMap<String, (ballbar_compensate::Term, Estimate)> =
        ballbar_compensate::terms_with(&saved, &est, Some(&cov))
            .into_iter()
            .map(|(t, e)| (t.id.clone(), (t, e)))
            .collect();
    // Whether the tests before determined each term: the saved model's.
    let before_determined: BTreeMap<String, bool> =
        ballbar_compensate::terms(&saved, &saved_estimates(&model, &saved))
            .into_iter()
            .map(|(t, e)| (t.id, e.estimable))
            .collect();
    let mut notes = Vec::new();
    let repeated: Vec<(String, Option<String>)> = runs
        .iter()
        .map(|r| {
            let planar = ballbar_compensate::predictable(r);
            (r.name().to_string(), planar.then(|| r.header.plane.to_string()))
        })
        .collect();
    let names: Vec<String> = repeated.iter().map(|(n, _)| n.clone()).collect();
    if let Some(n) = verify::runs_mismatch(&comp.predicted, &repeated) {
        eprintln!("warning: {}: {n}", dir.join("compensation.json").display());
        notes.push(n);
    }
    let machines: Vec<(String, Option<String>)> =
        runs.iter().map(|r| (r.name().to_string(), r.header.machine.clone())).collect();
    if let Some(n) = verify::machine_mismatch(&saved.machine.name, &machines) {
        eprintln!("warning: {}: {n}", model_path.display());
        notes.push(n);
    }
    let mut terms = Vec::new();
    for t in &comp.terms {
        // A document written before a transient's parts were grouped into sides lists the
        // parts: each is compared as itself.
        let part = || {
            let e = est.iter().find(|e| e.id == t.id)?;
            Some((ballbar_compensate::term_of(&saved, e)?, e.clone()))
        };
        let (a, a_est) = after.get(&t.id).cloned().or_else(part).ok_or_else(|| {
            anyhow!(
                "{}: term {} is not in the fit of the runs given",
                dir.join("compensation.json").display(),
                t.id
            )
        })?;
        let comp_path = dir.join("compensation.json");
        let (b, ub, unit) =
            t.checked_value(&comp_path.display().to_string()).map_err(|m| anyhow!(m))?;
        let (av, ua, _) = a.value();
        let predicted = t.predicted_after.unwrap_or(b);
        let u = ub.hypot(ua);
        // The controller's resolution of the written values, in the term's unit.
        let resolution = t.resolution(comp.resolution());
        // A term the repeated tests or the tests before do not determine has no verdict on
        // its value: the refit's number for it is a gauge's choice.
        let before_estimable = before_determined
            .get(&t.id)
            .copied()
            .or_else(|| saved.parameters.iter().find(|p| p.id == t.id).map(|p| p.estimable));
        let measured = a_est.estimable && before_estimable.unwrap_or(true);
        let (verdict, share, factor) = if measured {
            verify::verdict_of(t.compensated, (b, predicted, av), (ub, ua), resolution)
        } else {
            (verify::NOT_MEASURED, None, None)
        };
        terms.push(verify::TermCheck {
            term: t.term.clone(),
            axis: t.axis.clone(),
            id: t.id.clone(),
            before: b,
            predicted_after: predicted,
            after: av,
            u,
            unit: unit.into(),
            compensated: t.compensated,
            verdict: verdict.into(),
            share,
            factor,
            sessions: (verdict == "not_resolved")
                .then(|| verify::sessions_to_resolve(predicted - b, ub, ua, resolution))
                .flatten(),
            verifiable_by_repeat: t.verifiable_by_repeat,
            measured_by: (!measured).then(|| {
                verify::tests_that_measure(&t.term, &t.axis, &t.id, &comp.predicted, &names)
            }),
        });
    }
    let mut run_checks = Vec::new();
    for p in &comp.predicted {
        if let Some(r) = runs.iter().find(|r| r.name() == p.run) {
            run_checks.push(verify::RunCheck {
                run: p.run.clone(),
                g_before_um: p.g_before_um,
                g_predicted_um: p.g_after_um,
                g_after_um: ballbar_fit::metrics::figures(r, &r.dr_mm).g * 1e3,
            });
        }
    }
    Ok(verify::Verification {
        format: verify::VERIFICATION_FORMAT.into(),
        terms,
        runs: run_checks,
        notes,
    })
}

/// The verification printed, written with `--json`, and its exit.
fn report_verification(args: &VerifyArgs, v: &verify::Verification) -> Result<()> {
    let dir = &args.compensation;
    outln!("Verification of {} (u: the comparison's standard uncertainty, k = 1)", dir.display());
    outln!(
        "  {:<15} {:<4} {:<6} {:>10} {:>10} {:>10} {:>8} {:<5} verdict",
        "term",
        "axis",
        "id",
        "before",
        "predicted",
        "after",
        "u",
        "unit"
    );
    for t in &v.terms {
        let extra = match (t.share, t.factor) {
            (_, Some(f)) => format!(" (×{f})"),
            (Some(s), _) => format!(" (share {s:.2})"),
            _ => String::new(),
        };
        // A term the repeat does not measure has no value after: the refit's is a gauge's.
        let (after, u) = if t.verdict == verify::NOT_MEASURED {
            ("-".to_string(), "-".to_string())
        } else {
            (format!("{:.3}", t.after), format!("{:.3}", t.u))
        };
        outln!(
            "  {:<15} {:<4} {:<6} {:>10.3} {:>10.3} {:>10} {:>8} {:<5} {}{extra}",
            t.term,
            t.axis,
            t.id,
            t.before,
            t.predicted_after,
            after,
            u,
            t.unit,
            t.verdict
        );
    }
    // What each verdict that needs an action means, in shop-floor words.
    for a in v.terms.iter().filter_map(verify::TermCheck::advice) {
        outln!("  ▸ {a}");
    }
    // The terms not compensated that the repeat does not measure: no verdict, no action.
    let unmeasured: Vec<&str> = v
        .terms
        .iter()
        .filter(|t| !t.compensated && t.verdict == verify::NOT_MEASURED)
        .map(|t| t.id.as_str())
        .collect();
    if !unmeasured.is_empty() {
        outln!(
            "  not measured by the repeated tests (their fit, or the model's, does not determine them; not compensated, so the verdict does not depend on them): {}",
            unmeasured.join(", ")
        );
    }
    for n in &v.notes {
        outln!("note: {n}");
    }
    for r in &v.runs {
        outln!(
            "  {:<12} G before {:>7.2}  predicted {:>7.2}  after {:>7.2} µm",
            r.run,
            r.g_before_um,
            r.g_predicted_um,
            r.g_after_um
        );
    }
    if let Some(p) = &args.json {
        crate::write_json(p, v, args.force)?;
    }
    if v.passed() {
        outln!("verified: every compensated term corrected as predicted, no other term changed");
        Ok(())
    } else {
        let bad: Vec<String> = v
            .terms
            .iter()
            .filter(|t| (t.compensated && t.verdict != "corrected") || t.verdict == "changed")
            .map(|t| format!("{} {} {}", t.id, t.term, t.verdict))
            .collect();
        Err(Failure::Verdict(anyhow!("not verified: {}", bad.join(", "))))
    }
}

/// The names of `--include-aliased` (`names`) that no term of the model (`terms`: each id and
/// kind) has, in words, or `None` when each names one (matched without regard to case, as
/// [`ballbar_compensate::Options`] matches them).
fn unknown_included(names: &[String], terms: &[(String, String)]) -> Option<String> {
    let unknown: Vec<&str> = names
        .iter()
        .filter(|n| {
            !terms
                .iter()
                .any(|(id, kind)| n.eq_ignore_ascii_case(id) || n.eq_ignore_ascii_case(kind))
        })
        .map(String::as_str)
        .collect();
    if unknown.is_empty() {
        return None;
    }
    let mut kinds: Vec<&str> = terms.iter().map(|t| t.1.as_str()).collect();
    kinds.sort_unstable();
    kinds.dedup();
    Some(format!(
        "--include-aliased {}: no term of this model has that id or kind (the kinds: {}; the ids as compensation.json lists them)",
        unknown.join(", "),
        kinds.join(", ")
    ))
}

#[cfg(test)]
mod tests {
    #[test]
    fn an_included_name_no_term_has_is_refused_with_the_kinds() {
        let terms: Vec<(String, String)> =
            [("EXX1", "scale"), ("BX", "backlash"), ("SQXY", "squareness")]
                .iter()
                .map(|(a, b)| (a.to_string(), b.to_string()))
                .collect();
        let names = |n: &[&str]| n.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(super::unknown_included(&names(&["exx1", "Scale", "backlash"]), &terms), None);
        let why = super::unknown_included(&names(&["scales", "EXX1", "FOO"]), &terms).unwrap();
        assert!(
            why.starts_with("--include-aliased scales, FOO: no term of this model")
                && why.contains("the kinds: backlash, scale, squareness"),
            "{why}"
        );
    }

    use super::*;
    use ballbar_compensate::tables::Existing as _;

    /// An existing HEIDENHAIN assignment whose only table of X carries a `Y` column (Y as a
    /// function of X) and a `Z` table of its own: Y has a cross-axis correction and nothing of
    /// its own, so `has` is false for it (the simulator's `has`, which must apply the column to
    /// Y, is true), and true for X and Z.
    #[test]
    fn an_axis_with_only_a_cross_axis_column_has_no_existing_compensation_of_its_own() {
        use ballbar_sim::controller::{Controller, JointTrims};
        let cma = "BEGIN CONFIG.CMA\nNR X Z ACTIVE\n0 X.COM Z.COM *\n[END]\n";
        let x = "BEGIN X.COM MM\nNR AXISPOS X Y\n0 +100.0 +0.001 +0.002\n1 +200.0 +0.003 +0.004\n[END]\n";
        let z = "BEGIN Z.COM MM\nNR AXISPOS Z\n0 -50.0 0.001\n1 0.0 0.002\n[END]\n";
        let h = ballbar_sim::heidenhain::Heidenhain::parse(cma, "CONFIG.CMA", &|n| match n {
            "X.COM" => Ok(x.into()),
            "Z.COM" => Ok(z.into()),
            _ => Err("no such file".into()),
        })
        .unwrap();
        let c = Controller::Heidenhain(h);
        assert!(JointTrims::has(&c, Axis::Y), "the simulator applies the column to Y");
        let e = ExistingController(c);
        assert_eq!(
            e.crosses().iter().map(|c| (c.0, c.1)).collect::<Vec<_>>(),
            [(Axis::X, Axis::Y)]
        );
        assert!(e.has(Axis::X) && e.has(Axis::Z));
        assert!(!e.has(Axis::Y));
        assert!(!e.has(Axis::A));
    }

    /// `--joints` takes joint numbers within LinuxCNC's 16 and refuses a larger one with a
    /// usage error (a number near usize::MAX would otherwise size the joint layout).
    #[test]
    fn joint_numbers_are_bounded() {
        let ok = parse_joints("X=0, Y=15").unwrap();
        assert_eq!((ok[&Axis::X], ok[&Axis::Y]), (0, 15));
        for bad in ["X=16", "X=4000000000", "X=18446744073709551615", "X=-1", "Q=1", "X"] {
            match parse_joints(bad) {
                Err(Failure::Usage(e)) => assert!(e.to_string().contains("0 to 15"), "{bad}: {e}"),
                other => panic!("{bad}: {other:?}"),
            }
        }
    }
}

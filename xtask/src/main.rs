//! Project chores. `cargo xtask bench`: timings of the fit pipeline, the plugin path, the
//! diagnosis, the archive and the report, and of scale (`bench_scale.rs`: the fit's peak memory
//! per sample, the diagnosis's time on 100 and 1,000 runs; `cargo xtask bench scale` alone; `cargo xtask bench targets`: the diagnosis's speed targets alone; `cargo xtask bench once [RATE_HZ [REPEATS]]`: one diagnosis of the targets' session (each plane and direction REPEATS times, 2 by default), for a profiler);
//! `cargo xtask fixtures`: regenerate the shipped
//! fixtures with the exact commands their README gives; `cargo xtask validate`: the
//! diagnosis's validation suite and its scoreboard; `cargo xtask report ARCHIVE --out DIR
//! [--history DIR]`: the HTML report (the same library call as `ballbar report`);
//! `cargo xtask dist [--out DIR]`, `cargo xtask install [--prefix DIR]` and `cargo xtask
//! uninstall [--prefix DIR]`: a release build laid out as `bin/ballbar` with its plugins in
//! `lib/ballbar/plugins` and its shell completions (`layout.rs`); `cargo xtask tidy`: formatting,
//! clippy and unused dependencies, the checks CI runs before the tests (`tidy.rs`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ballbar_model::machine::{Model, ModelOptions};
use ballbar_model::{Design, Direction, Plane};
use ballbar_sim::{TestSpec, Truth};

mod bench_archive;
mod bench_b5r;
mod bench_compensate;
mod bench_diagnose;
mod bench_five_axis;
mod bench_scale;
mod install;
mod tidy;
mod validate;

const USAGE: &str = "usage: cargo xtask bench [scale|targets|compensate|once [RATE_HZ [REPEATS]]] | cargo xtask fixtures | cargo xtask validate [--seeds N] | cargo xtask report ARCHIVE.mcap --out DIR [--history DIR] [--force] | cargo xtask dist [--out DIR] [--force] | cargo xtask install [--prefix DIR] [--plugins-only] [--force] | cargo xtask uninstall [--prefix DIR] | cargo xtask tidy";

/// A missing or unknown task is a usage error: the usage on standard error and exit 2, not an
/// error with a backtrace (`RUST_BACKTRACE=1` printed one for a plain `cargo xtask`).
fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("bench") if args.get(1).is_some_and(|a| a == "scale") => bench_scale_only(),
        Some("bench") if args.get(1).is_some_and(|a| a == "targets") => bench_targets_only(),
        Some("bench") if args.get(1).is_some_and(|a| a == "compensate") => bench_compensate_only(),
        Some("bench") if args.get(1).is_some_and(|a| a == "once") => bench_once(&args[2..]),
        Some("bench") => bench(),
        Some("bench-child") => bench_scale::child(&args[1..]),
        Some("fixtures") => fixtures(),
        Some("validate") => validate::validate(&args[1..]),
        Some("report") => report(&args[1..]),
        Some("tidy") => tidy::tidy(&args[1..]),
        Some(task @ ("dist" | "install" | "uninstall")) => return install::main(task, &args[1..]),
        _ => {
            eprintln!("{USAGE}");
            return std::process::ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::from(1)
        }
    }
}

/// `cargo xtask report ARCHIVE.mcap --out DIR [--history DIR] [--force]`: the HTML report,
/// built by the same library call as `ballbar report` (an existing page replaced only with
/// `--force`).
fn report(args: &[String]) -> Result<()> {
    let mut archive = None;
    let (mut out, mut history, mut force) = (None, None, false);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out = it.next().map(PathBuf::from),
            "--history" => history = it.next().map(PathBuf::from),
            "--force" => force = true,
            _ if archive.is_none() => archive = Some(PathBuf::from(a)),
            other => bail!("report: unexpected argument {other}"),
        }
    }
    let (Some(archive), Some(out)) = (archive, out) else {
        bail!("usage: cargo xtask report ARCHIVE.mcap --out DIR [--history DIR] [--force]")
    };
    let reg = match ballbar_cli::registry(&[]) {
        Ok(r) => r,
        Err(
            ballbar_cli::Failure::Input(e)
            | ballbar_cli::Failure::Usage(e)
            | ballbar_cli::Failure::Internal(e)
            | ballbar_cli::Failure::Verdict(e),
        ) => bail!("plugin search: {e:#}"),
    };
    let t = Instant::now();
    let path = match ballbar_cli::report_cmd(&archive, &out, history.as_deref(), force, &reg) {
        Ok(p) => p,
        Err(
            ballbar_cli::Failure::Input(e)
            | ballbar_cli::Failure::Usage(e)
            | ballbar_cli::Failure::Internal(e)
            | ballbar_cli::Failure::Verdict(e),
        ) => bail!("{e:#}"),
    };
    println!(
        "wrote {} ({} bytes) in {:.0} ms",
        path.display(),
        std::fs::metadata(&path)?.len(),
        t.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Regenerate the fixtures' runs (replacing them: that is the task's job).
fn fixtures() -> Result<()> {
    for m in ["column", "horizontal"] {
        let dir = root().join(format!("fixtures/{m}-paper"));
        let args: Vec<std::ffi::OsString> = ["ballbar", "simulate", "--machine", m, "--truth"]
            .iter()
            .map(|s| s.to_string())
            .chain([
                dir.join("truth.ron").display().to_string(),
                "--out".into(),
                dir.join("runs").display().to_string(),
                "--seed".into(),
                "1".into(),
                "--force".into(),
            ])
            .map(Into::into)
            .collect();
        let code = ballbar_cli::main_with_args(args);
        if code != std::process::ExitCode::SUCCESS {
            bail!("simulate {m} failed");
        }
    }
    Ok(())
}

/// `runs` written into `dir` (made if need be) as run CSVs at the simulator's resolution, one
/// file a run named by it; their paths.
fn write_runs(runs: &[ballbar_model::Run], dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)?;
    runs.iter()
        .map(|r| {
            let f = dir.join(format!("{}.csv", r.name()));
            ballbar_io::write_run_rounded(r, &f, ballbar_io::Existing::Replace)?;
            Ok(f)
        })
        .collect()
}

/// Median of `reps` timings of `f`, in ms.
fn time<T>(reps: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..reps {
        let t = Instant::now();
        last = Some(f());
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    (times[times.len() / 2], last.expect("reps ≥ 1"))
}

/// The benchmarks' test of one plane: CW and CCW, two repeats, R = 100 mm, F = 1000 mm/min.
fn bench_test(plane: Plane) -> TestSpec {
    TestSpec {
        plane,
        directions: vec![Direction::CW, Direction::CCW],
        radius_mm: 100.0,
        feed_mm_per_min: 1000.0,
        pivot_mm: [300.0, 200.0, -300.0],
        table_ball_mm: [0.0, 0.0, 50.0],
        tool_ball_mm: [0.0, 0.0, -100.0],
        repeats: 2,
        start_deg: 0.0,
        sweep_deg: 360.0,
        rotary: None,
    }
}

fn bench() -> Result<()> {
    // The workload: three planes, CW and CCW, two repeats, 250 Hz, R = 100, F = 1000.
    let test = bench_test;
    let mut truth: Truth =
        ballbar_io::ron_files::read_ron(&root().join("fixtures/column-paper/truth.ron"))?;
    truth.sample_rate_hz = 250.0;
    truth.tests = Plane::PLANAR.into_iter().map(test).collect();
    let spec = ballbar_model::machines::column();
    let sim = ballbar_sim::simulate(&spec, &truth, 0.0, 3)?;
    let dir = std::env::temp_dir().join(format!("ballbar-bench-{}", std::process::id()));
    let files = write_runs(&sim.runs, &dir)?;
    let samples: usize = sim.runs.iter().map(|r| r.len()).sum();
    let bytes: u64 = files.iter().map(|f| std::fs::metadata(f).map(|m| m.len()).unwrap_or(0)).sum();
    println!(
        "workload: {} runs, {samples} samples, {:.1} MB of CSV; median of 7, 2 threads",
        files.len(),
        bytes as f64 / 1e6
    );
    let reps = 7;
    // Baseline: reading the bytes of the files, the floor any parser stands on.
    let (base, _) = time(reps, || {
        files.iter().map(|f| std::fs::read(f).map(|b| b.len()).unwrap_or(0)).sum::<usize>()
    });
    let (parse, runs) =
        time(reps, || ballbar_cli::read_runs(&files, 2).map_err(|_| anyhow::anyhow!("parse")));
    let runs = runs?;
    let model = Model::new(spec.clone(), ModelOptions::default())?;
    let (prepare, design) = time(reps, || Design::new(&model, &runs));
    let design = design?;
    let fill = |design: &Design<'_>| {
        let mut s = ballbar_model::BlockScratch::default();
        let mut acc = 0.0;
        for (r, run) in runs.iter().enumerate() {
            let cols: Vec<usize> = (0..design.n_machine).chain(design.run_columns(r)).collect();
            let mut out = vec![0.0; run.len() * cols.len()];
            let mut targets = vec![0.0; run.len()];
            design.fill_run(r, &cols, &mut out, &mut targets, &mut s).expect("built-in terms");
            acc += out[0];
        }
        acc
    };
    let (build, _) = time(reps, || fill(&design));
    // The same on a design made from another (`Design::with_model`, as a diagnosis makes its
    // candidates' and final designs): it keeps the runs' geometry once evaluated.
    let other = Design::new(&model, &runs)?;
    let kept = other.with_model(&model)?;
    let (build_kept, _) = time(reps, || fill(&kept));
    let (solve, fit) = time(reps, || ballbar_fit::fit(&design, 2));
    let fit = fit.context("fit")?;
    // What the fit determines where the tests are and what it cannot tell (local values, the
    // candidates' projections through the fit's factorisation): its cost against the fit's.
    let (fitted, fac) = ballbar_fit::fit_factored(&design, 2)?;
    let (aliases, assessment) =
        time(reps, || ballbar_fit::alias::assess(&design, &fitted, &fac, 2));
    let assessment = assessment.context("aliases")?;
    drop(fac);
    let (exact, _) = time(reps, || {
        let mut s = ballbar_model::BlockScratch::default();
        (0..runs.len())
            .map(|r| design.exact_run_with(r, &fit.values, &mut s).expect("built-in terms")[0])
            .sum::<f64>()
    });
    let (e2e, _) = time(reps, || -> Result<usize> {
        let runs = ballbar_cli::read_runs(&files, 2).map_err(|_| anyhow::anyhow!("parse"))?;
        let model = Model::new(spec.clone(), ModelOptions::default())?;
        let design = Design::new(&model, &runs)?;
        Ok(ballbar_fit::fit(&design, 2)?.rank)
    });
    println!("{:<44} {:>9} {:>12}", "stage", "ms", "× baseline");
    for (name, ms) in [
        ("baseline: read the file bytes", base),
        ("parse 12 run CSVs (strict)", parse),
        ("design: check and prepare the runs", prepare),
        ("design matrix, single thread", build),
        ("  again, the runs' geometry kept", build_kept),
        ("exact readings at the fit, single thread", exact),
        ("fit: factor, solve, refine, uncertainty", solve),
        ("aliases: local values, candidates projected", aliases),
        ("end to end: parse + design + fit", e2e),
    ] {
        println!("{name:<44} {ms:>9.2} {:>12.1}", ms / base);
    }
    println!("fit: rank {} of {}, σ {:.3} µm", fit.rank, fit.parameters.len(), fit.sigma_mm * 1e3);
    println!(
        "aliases: {} candidates tried, {} aliases, {:.2} × the fit's time",
        assessment.candidates_tried,
        assessment.aliases.len(),
        aliases / solve
    );
    plugin_bench(&runs, &spec, reps)?;
    bench_diagnose::run(&spec, &truth)?;
    bench_compensate::run(&spec, &truth, &files, &dir)?;
    bench_archive::run(&spec, &runs, &files, &dir)?;
    bench_b5r::run(&spec, &runs, &dir)?;
    bench_five_axis::run()?;
    bench_scale::run(&spec, &truth, &dir)?;
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

/// `cargo xtask bench scale`: the scale measurements alone ([`bench_scale`]).
fn bench_scale_only() -> Result<()> {
    let truth: Truth =
        ballbar_io::ron_files::read_ron(&root().join("fixtures/column-paper/truth.ron"))?;
    let dir = std::env::temp_dir().join(format!("ballbar-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let out = bench_scale::run(&ballbar_model::machines::column(), &truth, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// `cargo xtask bench compensate`: `compensate` and `verify` alone ([`bench_compensate`]), on
/// the bench's 12-run session.
fn bench_compensate_only() -> Result<()> {
    let mut truth: Truth =
        ballbar_io::ron_files::read_ron(&root().join("fixtures/column-paper/truth.ron"))?;
    truth.sample_rate_hz = 250.0;
    truth.tests = Plane::PLANAR.into_iter().map(bench_test).collect();
    let spec = ballbar_model::machines::column();
    let sim = ballbar_sim::simulate(&spec, &truth, 0.0, 3)?;
    let dir = std::env::temp_dir().join(format!("ballbar-bench-{}", std::process::id()));
    let files = write_runs(&sim.runs, &dir)?;
    let out = bench_compensate::run(&spec, &truth, &files, &dir);
    let _ = std::fs::remove_dir_all(&dir);
    out
}

/// `cargo xtask bench targets`: the diagnosis's speed targets alone ([`bench_diagnose::targets`]).
fn bench_targets_only() -> Result<()> {
    let truth: Truth =
        ballbar_io::ron_files::read_ron(&root().join("fixtures/column-paper/truth.ron"))?;
    bench_diagnose::targets(&ballbar_model::machines::column(), &truth)
}

/// `cargo xtask bench once [RATE_HZ [REPEATS]]`: one diagnosis of the targets' session at the rate given
/// (250 Hz unless given), nothing else timed: the workload to run under a profiler
/// ([`bench_diagnose::once`]).
fn bench_once(args: &[String]) -> Result<()> {
    let rate = match args.first() {
        Some(a) => a.parse::<f64>().with_context(|| format!("RATE_HZ: not a number: {a}"))?,
        None => 250.0,
    };
    let repeats = match args.get(1) {
        Some(a) => a
            .parse::<u32>()
            .ok()
            .filter(|&r| r > 0)
            .with_context(|| format!("REPEATS: not a positive whole number: {a}"))?,
        None => 2,
    };
    let truth: Truth =
        ballbar_io::ron_files::read_ron(&root().join("fixtures/column-paper/truth.ron"))?;
    bench_diagnose::once(&ballbar_model::machines::column(), &truth, rate, repeats)
}

/// The column plugin's library as cargo built it beside (or below) this executable.
fn column_plugin_file() -> Result<PathBuf> {
    let exe = std::env::current_exe()?;
    let dir = exe.parent().context("executable folder")?;
    let name = format!(
        "{}ballbar_machine_column{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    );
    [dir.join(&name), dir.join("deps").join(&name)].into_iter().find(|p| p.is_file()).with_context(
        || {
            format!(
                "{name} not found beside {} (cargo builds it as a dependency of xtask)",
                exe.display()
            )
        },
    )
}

/// Measurements of the plugins: plugin load and description parse, and the fit with the
/// machine from the plugin against the same fit with the machine linked statically (baseline).
fn plugin_bench(
    runs: &[ballbar_model::Run],
    static_spec: &ballbar_model::machine::MachineSpec,
    reps: usize,
) -> Result<()> {
    let file = column_plugin_file()?;
    // The first load maps the library; later loads of the same file find it mapped.
    let t = Instant::now();
    let plugin = ballbar_plugin_host::Plugin::load(&file)?;
    let first_load = t.elapsed().as_secs_f64() * 1e3;
    let (reload, _) =
        time(reps, || ballbar_plugin_host::Plugin::load(&file).map(|p| p.name().len()));
    let (describe, spec) = time(reps, || plugin.machine());
    let spec = spec?;
    anyhow::ensure!(
        &spec == static_spec,
        "the plugin's description differs from the statically linked one"
    );
    let fit_with = |spec: &ballbar_model::machine::MachineSpec| -> Result<f64> {
        let model = Model::with_kernels(spec.clone(), ModelOptions::default(), &plugin)?;
        let design = Design::new(&model, runs)?;
        Ok(ballbar_fit::fit(&design, 2)?.sigma_mm)
    };
    // Interleaved, so that drift of the machine's speed hits both alike.
    let (mut st, mut pl) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        fit_with(static_spec)?;
        st.push(t.elapsed().as_secs_f64() * 1e3);
        let t = Instant::now();
        let spec = plugin.machine()?;
        fit_with(&spec)?;
        pl.push(t.elapsed().as_secs_f64() * 1e3);
    }
    st.sort_by(f64::total_cmp);
    pl.sort_by(f64::total_cmp);
    let (st, pl) = (st[reps / 2], pl[reps / 2]);
    println!("\nplugin path ({}):", file.display());
    println!("{:<44} {:>9} {:>12}", "stage", "ms", "× baseline");
    for (name, ms) in [
        ("baseline: fit, machine linked statically", st),
        ("fit, machine described by the plugin", pl),
        ("plugin: first load (dlopen + checks)", first_load),
        ("plugin: load again (mapped)", reload),
        ("plugin: describe + parse the RON", describe),
    ] {
        println!("{name:<44} {ms:>9.3} {:>12.4}", ms / st);
    }
    println!("plugin path costs {:+.1} % of the static fit", (pl / st - 1.0) * 100.0);
    Ok(())
}

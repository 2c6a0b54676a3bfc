//! The fit of a five-axis session: the A/C trunnion (`fixtures/machines/five-axis-ac-trunnion.ron`)
//! with its rotary truth (planar circles, C and A rotary tests, at 50 Hz) and two more C radial
//! heights, 24 runs, against the baseline of a three-plane session (planar circles only, CW and
//! CCW) of the same machine with the same number of samples (within 1 %), fitted with the same
//! model in the same process. The machine comes from `ballbar_machine_chain_file::parse` as
//! the chain-file plugin runs it (`Plugin::machine_from_file`), loaded as the `ballbar` command
//! loads it: xtask links no plugin.

use anyhow::{Context, Result, ensure};
use ballbar_model::machine::{Model, ModelOptions, ServoVariant};
use ballbar_model::path::BarDirection;
use ballbar_model::{Axis, BarLength, Design, Plane, Run};
use ballbar_sim::Truth;

use crate::{root, time};

/// The chain-file plugin's library as cargo built it beside (or below) this executable.
fn chain_file_plugin() -> Result<std::path::PathBuf> {
    let exe = std::env::current_exe()?;
    let dir = exe.parent().context("executable folder")?;
    let name = format!(
        "{}ballbar_machine_chain_file{}",
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

/// Print the measurements.
pub fn run() -> Result<()> {
    let reps = 7;
    // The chain file through `ballbar_machine_chain_file::parse`, run in the chain-file plugin
    // that cargo builds beside this executable (see the module's note).
    let machine = root().join("fixtures/machines/five-axis-ac-trunnion.ron");
    let plugin = ballbar_plugin_host::Plugin::load(&chain_file_plugin()?)?;
    let spec = plugin.machine_from_file(&machine)?;
    let truth: Truth = ballbar_io::ron_files::read_ron(
        &root().join("fixtures/machines/five-axis-ac-trunnion.rotary.truth.ron"),
    )?;
    ensure!(
        truth.servo == ServoVariant::AxisLag,
        "the rotary truth's servo is {:?}, not AxisLag",
        truth.servo
    );
    // The truth's options: one lag per axis, the bar calibrated at its simulated length.
    let options = ModelOptions {
        servo: truth.servo,
        bar_length: BarLength::Known(truth.bar_length_um * 1e-3),
    };
    let model = Model::new(spec.clone(), options)?;

    // Five-axis: the truth's 20 runs (3 planar pairs, C radial at 50 and 150 mm, C tangential,
    // C axial, A radial, A axial, A and C together) and C radial at 100 and 200 mm above the
    // face (the pivot's Z sets the height: 290 mm + h), 24 runs.
    let mut five = truth.clone();
    let radial = five
        .tests
        .iter()
        .find(|t| {
            t.rotary.as_ref().is_some_and(|r| {
                r.turns.len() == 1 && r.turns[0].axis == Axis::C && r.bar == BarDirection::Radial
            })
        })
        .context("a C radial test in the rotary truth")?
        .clone();
    for h in [100.0, 200.0] {
        let mut t = radial.clone();
        t.pivot_mm[2] = 290.0 + h;
        t.table_ball_mm[2] = h;
        five.tests.push(t);
    }
    let five_runs = ballbar_sim::simulate(&spec, &five, 0.0, 3)?.runs;
    ensure!(five_runs.len() == 24, "the five-axis session has {} runs, not 24", five_runs.len());
    let n5: usize = five_runs.iter().map(Run::len).sum();
    let n_free = five_runs.iter().filter(|r| r.header.plane == Plane::Free).count();

    // Three-plane baseline: the truth's planar circles, CW and CCW, 4 repeats (24 runs), at the
    // sampling rate that gives the five-axis session's sample count.
    let mut three = truth.clone();
    three.tests.retain(|t| t.plane != Plane::Free);
    for t in &mut three.tests {
        t.repeats = 4;
    }
    let n_at = |rate: f64| -> Result<(Vec<Run>, usize)> {
        let mut t = three.clone();
        t.sample_rate_hz = rate;
        let runs = ballbar_sim::simulate(&spec, &t, 0.0, 3)?.runs;
        let n = runs.iter().map(Run::len).sum();
        Ok((runs, n))
    };
    // Samples grow with the rate by the runs' durations: two corrections match them.
    let mut rate = truth.sample_rate_hz;
    for _ in 0..2 {
        rate *= n5 as f64 / n_at(rate)?.1 as f64;
    }
    let (three_runs, n3) = n_at(rate)?;
    ensure!(
        (n3 as f64 / n5 as f64 - 1.0).abs() < 0.01,
        "the baseline's {n3} samples are not within 1 % of the five-axis session's {n5}"
    );

    let fit_of = |runs: &[Run]| -> Result<ballbar_fit::Fit> {
        Ok(ballbar_fit::fit(&Design::new(&model, runs)?, 2)?)
    };
    // Interleaved, one `time` each, so that drift of the machine's speed (or other work on it)
    // hits both alike.
    let (mut t3, mut t5) = (Vec::new(), Vec::new());
    let (mut fit3, mut fit5) = (None, None);
    for _ in 0..reps {
        let (ms, f) = time(1, || fit_of(&three_runs));
        t3.push(ms);
        fit3 = Some(f);
        let (ms, f) = time(1, || fit_of(&five_runs));
        t5.push(ms);
        fit5 = Some(f);
    }
    t3.sort_by(f64::total_cmp);
    t5.sort_by(f64::total_cmp);
    let (base, five_ms) = (t3[reps / 2], t5[reps / 2]);
    let fit3 = fit3.expect("reps ≥ 1").context("three-plane fit")?;
    let fit5 = fit5.expect("reps ≥ 1").context("five-axis fit")?;

    println!(
        "\nfive-axis fit (A/C trunnion, R = 150 mm circles and R = 100 mm rotary tests at 1000 mm/min; median of {reps}, interleaved; 2 threads)"
    );
    println!(
        "five-axis: {} runs ({} planar, {n_free} rotary: C radial at 4 heights, C tangential, C axial, A radial, A axial, A and C together), {n5} samples at {} Hz",
        five_runs.len(),
        five_runs.len() - n_free,
        truth.sample_rate_hz
    );
    println!(
        "three-plane: {} runs (XY, YZ, ZX, CW and CCW, 4 repeats), {n3} samples at {rate:.2} Hz ({:+.2} %)",
        three_runs.len(),
        (n3 as f64 / n5 as f64 - 1.0) * 100.0
    );
    println!("{:<44} {:>9} {:>12}", "stage", "ms", "× baseline");
    for (name, ms) in [
        ("baseline: three-plane fit, same samples", base),
        ("five-axis fit: planar + C and A rotary", five_ms),
    ] {
        println!("{name:<44} {ms:>9.2} {:>12.2}", ms / base);
    }
    // Where the time goes: the design (checks, preparation), its factorisation (per-run QR on
    // 2 threads, stacked QR, SVD, gauges) and one exact evaluation of every run (the chain at
    // the fitted values, single thread); the chord refinement evaluates the chain once per step.
    let parts = |runs: &[Run], fit: &ballbar_fit::Fit| -> Result<[f64; 3]> {
        let (prepare, design) = time(reps, || Design::new(&model, runs));
        let design = design?;
        let (factor, fac) =
            time(reps, || ballbar_fit::Factorisation::new(&design, 2).map(|f| f.targets(0).len()));
        fac?;
        let (exact, _) = time(reps, || {
            let mut s = ballbar_model::BlockScratch::default();
            (0..runs.len())
                .map(|r| design.exact_run_with(r, &fit.values, &mut s).expect("built-in terms")[0])
                .sum::<f64>()
        });
        Ok([prepare, factor, exact])
    };
    let (p3, p5) = (parts(&three_runs, &fit3)?, parts(&five_runs, &fit5)?);
    for (i, name) in [
        "  design: check and prepare the runs",
        "  factor: QR per run, stacked QR, SVD, gauges",
        "  exact readings at the fit, single thread",
    ]
    .into_iter()
    .enumerate()
    {
        println!(
            "{name:<44} {:>9.2} {:>12.2}   (three-plane {:.2} ms)",
            p5[i],
            p5[i] / p3[i],
            p3[i]
        );
    }
    let cols = |f: &ballbar_fit::Fit| {
        format!(
            "{} parameters ({} machine), rank {} ({} fixed)",
            f.parameters.len(),
            f.n_machine,
            f.rank,
            f.parameters.len() - f.rank
        )
    };
    let kinds = |f: &ballbar_fit::Fit| {
        f.gauges.iter().map(|g| format!("{:?}", g.kind)).collect::<Vec<_>>().join(", ")
    };
    println!(
        "three-plane: {}, σ {:.3} µm, {} gauges: {}",
        cols(&fit3),
        fit3.sigma_mm * 1e3,
        fit3.gauges.len(),
        kinds(&fit3)
    );
    println!(
        "five-axis:   {}, σ {:.3} µm, condition number {:.3e}, {} gauges:",
        cols(&fit5),
        fit5.sigma_mm * 1e3,
        fit5.condition_number,
        fit5.gauges.len()
    );
    for g in &fit5.gauges {
        let what: String = if g.what.chars().count() > 80 {
            g.what.chars().take(79).chain(['…']).collect()
        } else {
            g.what.clone()
        };
        let ids: Vec<&str> = g.parameters.iter().map(|&i| fit5.parameters[i].id.as_str()).collect();
        let shown = if ids.len() > 3 {
            format!("{} … ({} parameters)", ids[..3].join(" "), ids.len())
        } else {
            ids.join(" ")
        };
        println!("  {:?}: {what} [{shown}]", g.kind);
    }
    let nonzero =
        |f: &ballbar_fit::Fit| f.values[..f.n_machine].iter().filter(|&&x| x != 0.0).count();
    println!(
        "five-axis / three-plane = {:.2}×: the same runs and samples; the factorisation costs {:.2}× ({} columns against {}: a 3-D centring per rotary run, across-bar gauges) and an exact evaluation of the chain {:.2}× (it skips zero terms: {} of the five-axis fit's {} machine values are non-zero, {} of the three-plane's, whose A and C stand still)",
        five_ms / base,
        p5[1] / p3[1],
        fit5.parameters.len(),
        fit3.parameters.len(),
        p5[2] / p3[2],
        nonzero(&fit5),
        fit5.n_machine,
        nonzero(&fit3),
    );
    Ok(())
}

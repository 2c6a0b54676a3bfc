//! Measurements of the diagnosis: `diagnose` on 12 runs (~110,000 samples) with the full
//! candidate library, and how its time grows with the samples and with the candidates; the
//! ratio of the diagnosis to the base fit on the same runs, in the same process; and the speed
//! targets ([`targets`]): the 12-run session at 250 Hz (~113,000 samples) within 1 s, a
//! real-rate session (three planes CW and CCW at 1 kHz, two repeats: ~450,000 samples) within
//! 3 s, each with the share of the backlash switch search.

use std::time::Instant;

use anyhow::Result;
use ballbar_diagnose::{Options, diagnose};
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, NoKernels, Plane};
use ballbar_sim::Truth;

/// The median time (ms) of `reps` calls.
fn median_ms(reps: usize, mut f: impl FnMut() -> Result<()>) -> Result<f64> {
    let mut t = Vec::new();
    for _ in 0..reps {
        let s = Instant::now();
        f()?;
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[t.len() / 2])
}

/// Time `diagnose` on the bench workload at several sampling rates and library sizes, and the
/// base fit it starts from (the model, the design and [`ballbar_fit::fit`], as `ballbar fit`
/// makes them) on the same runs: the diagnosis's cost in units of the fit's.
pub fn run(spec: &MachineSpec, truth_template: &Truth) -> Result<()> {
    let test = crate::bench_test;
    println!(
        "\ndiagnose (12 runs: three planes, CW and CCW, two repeats; R = 100 mm, 1000 mm/min; median of 3, the base fit of 7; 2 threads)"
    );
    println!(
        "{:<44} {:>9} {:>9} {:>12} {:>12}",
        "workload", "samples", "ms", "ms / 10k", "× base fit"
    );
    let mut full = None;
    for rate in [62.5, 125.0, 250.0] {
        let mut truth = truth_template.clone();
        truth.sample_rate_hz = rate;
        truth.tests = Plane::PLANAR.into_iter().map(test).collect();
        let runs = ballbar_sim::simulate(spec, &truth, 0.0, 3)?.runs;
        let n: usize = runs.iter().map(|r| r.len()).sum();
        // The base fit, from the model on, as `ballbar fit` and the diagnosis's first step
        // make it.
        let fit_ms = median_ms(7, || {
            let model = Model::new(spec.clone(), ModelOptions::default())?;
            let design = Design::new(&model, &runs)?;
            ballbar_fit::fit(&design, 2)?;
            Ok(())
        })?;
        let name = format!("{rate} Hz, base fit");
        println!(
            "{name:<44} {n:>9} {fit_ms:>9.1} {:>12.1} {:>12.1}",
            fit_ms / (n as f64 / 1e4),
            1.0
        );
        // Candidate libraries of growing size: one kind (reversal transients: 4 decay times × 3
        // ringing periods per axis, the best refined and tried per side), four kinds,
        // all of them (the full library).
        let few: Vec<String> = vec!["reversal_spike".into()];
        let some: Vec<String> = ["reversal_spike", "lateral_play", "cyclic_error", "thermal_drift"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        for (label, kinds) in [("1 kind", few), ("4 kinds", some), ("full library", vec![])] {
            let opts = Options { kinds, ..Options::default() };
            let mut screened = 0;
            let ms = median_ms(3, || {
                screened =
                    diagnose(spec, ModelOptions::default(), &NoKernels, &runs, opts.clone())?
                        .candidates_screened;
                Ok(())
            })?;
            let name = format!("{rate} Hz, {label} ({screened} candidates)");
            println!(
                "{name:<44} {n:>9} {ms:>9.1} {:>12.1} {:>12.1}",
                ms / (n as f64 / 1e4),
                ms / fit_ms
            );
            if rate == 250.0 && label == "full library" {
                full = Some((ms, fit_ms, n));
            }
        }
    }
    if let Some((ms, fit_ms, n)) = full {
        println!(
            "full library at {n} samples: {ms:.0} ms ({}); diagnose / base fit = {:.1}× ({fit_ms:.0} ms)",
            if ms < 1000.0 { "under the 1 s target" } else { "OVER the 1 s target" },
            ms / fit_ms
        );
    }
    targets(spec, truth_template)
}

/// The speed targets: `diagnose` (full library, 2 threads) on the 12-run session at 250 Hz
/// within 1 s and on a real-rate session (the same tests at 1 kHz) within 3 s; beside each,
/// the base fit on the same runs and the backlash switch search
/// ([`ballbar_fit::switch::switch_at_lagged_reversals`], which the diagnosis runs first) alone,
/// as times and as ratios to the base fit measured in the same process.
pub fn targets(spec: &MachineSpec, truth_template: &Truth) -> Result<()> {
    println!(
        "\ndiagnose, the speed targets (full library, 2 threads; median of 3, the base fit and the switch search of 5)"
    );
    println!(
        "{:<34} {:>8} {:>9} {:>9} {:>9} {:>9} {:>7} {:>9} {:>8}",
        "session",
        "samples",
        "fit ms",
        "switch ms",
        "× fit",
        "diag ms",
        "× fit",
        "switch %",
        "target"
    );
    for (label, rate, target_ms) in
        [("12 runs, 250 Hz", 250.0, 1000.0), ("12 runs, 1 kHz (real rate)", 1000.0, 3000.0)]
    {
        let mut truth = truth_template.clone();
        truth.sample_rate_hz = rate;
        truth.tests = Plane::PLANAR.into_iter().map(crate::bench_test).collect();
        let runs = ballbar_sim::simulate(spec, &truth, 0.0, 3)?.runs;
        let n: usize = runs.iter().map(|r| r.len()).sum();
        let model = Model::new(spec.clone(), ModelOptions::default())?;
        let fit_ms = median_ms(5, || {
            let model = Model::new(spec.clone(), ModelOptions::default())?;
            let design = Design::new(&model, &runs)?;
            ballbar_fit::fit(&design, 2)?;
            Ok(())
        })?;
        let mut found = None;
        let switch_ms = median_ms(5, || {
            let design = Design::new(&model, &runs)?;
            found = Some(ballbar_fit::switch::switch_at_lagged_reversals(design, 2)?.1);
            Ok(())
        })?;
        let ms = median_ms(3, || {
            diagnose(spec, ModelOptions::default(), &NoKernels, &runs, Options::default())?;
            Ok(())
        })?;
        println!(
            "{label:<34} {n:>8} {fit_ms:>9.0} {switch_ms:>9.0} {:>9.1} {ms:>9.0} {:>7.1} {:>8.0}% {:>8}",
            switch_ms / fit_ms,
            ms / fit_ms,
            100.0 * switch_ms / ms,
            if ms <= target_ms { format!("≤ {:.0} s", target_ms / 1e3) } else { "OVER".into() }
        );
        if let Some(s) = found.and_then(|s| s.describe()) {
            println!("  {s}");
        }
    }
    Ok(())
}

/// One diagnosis of the targets' session at `rate_hz` (the session simulated first), with its
/// time and a digest of everything it states: the workload alone, for a profiler (`perf
/// record`, `valgrind --tool=callgrind`), and a check that a change of speed left the
/// diagnosis as it was.
pub fn once(spec: &MachineSpec, truth_template: &Truth, rate_hz: f64, repeats: u32) -> Result<()> {
    let mut truth = truth_template.clone();
    truth.sample_rate_hz = rate_hz;
    truth.tests = Plane::PLANAR
        .into_iter()
        .map(|p| ballbar_sim::TestSpec { repeats, ..crate::bench_test(p) })
        .collect();
    let runs = ballbar_sim::simulate(spec, &truth, 0.0, 3)?.runs;
    let n: usize = runs.iter().map(|r| r.len()).sum();
    let s = Instant::now();
    let d = diagnose(spec, ModelOptions::default(), &NoKernels, &runs, Options::default())?;
    let ms = s.elapsed().as_secs_f64() * 1e3;
    // Everything the diagnosis states, to the last bit (Debug prints floats exactly), as one
    // hash: two builds whose hashes agree gave the same diagnosis.
    let stated = format!(
        "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{}\n{:?}\n{:?}\n{:?}",
        d.gap,
        d.effects,
        d.aliased,
        d.declined,
        d.notes,
        d.held_out,
        d.unexplained,
        d.schemes,
        d.candidates_screened,
        d.augmented.values,
        d.base.values,
        d.base_aliases,
    );
    println!(
        "diagnose, {} runs at {rate_hz} Hz ({n} samples): {ms:.0} ms, {} effects accepted (digest {:016x})",
        runs.len(),
        d.effects.len(),
        xtask::layout::fnv1a64(xtask::layout::FNV_OFFSET, stated.as_bytes())
    );
    Ok(())
}

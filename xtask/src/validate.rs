//! `cargo xtask validate`: the diagnosis's two validation sets, each simulated, diagnosed
//! without a hint and judged, with a scoreboard each.
//! - [`ballbar_validate::suite`]: per scenario the truth, the diagnosis, the held-out RMS
//!   before and after, the shrink against the truth's (an oracle with the true effects in the
//!   model) and the share of the truth's held-out gain the diagnosis closed.
//! - [`ballbar_validate::independent`]: effects whose shapes are not the candidates', held-out
//!   runs the diagnosis never saw (later in time, or an unseen feed or centre); per scenario
//!   the held-out base and augmented RMS, and the closure the diagnosis claims against the one
//!   the held-out runs measure.
//!
//! Fails (exit 1) when any scenario of either set fails.
//!
//! `cargo xtask validate --independent [NAME ...]`: the independent set alone, or only the
//! scenarios named, with its scoreboard.
//!
//! `cargo xtask validate --seeds N`: the independent set again under N seeds per scenario
//! (the scenario's own, then +1000, +2000, …: new noise, new centring, new phases), with each
//! scenario's pass rate and the failures' first check; one seed can pass by luck.

use std::time::Instant;

use anyhow::{Result, bail};
use ballbar_validate::{independent, suite as validation};

pub fn validate(args: &[String]) -> Result<()> {
    match args {
        [] => both(),
        [flag, names @ ..] if flag == "--independent" => independent_only(names),
        [flag, n] if flag == "--seeds" => {
            let n: u64 = n
                .parse()
                .map_err(|_| anyhow::anyhow!("--seeds takes a whole number of seeds, got {n:?}"))?;
            if n == 0 {
                bail!("--seeds takes at least 1");
            }
            seeds(n)
        }
        _ => bail!("usage: cargo xtask validate [--seeds N | --independent [NAME ...]]"),
    }
}

/// The independent set under `n` seeds per scenario. A seed that fails only its scenario's open
/// check (a class not yet fixed) is counted as open, not as passing, and does not fail the run.
fn seeds(n: u64) -> Result<()> {
    let start = Instant::now();
    let (mut total, mut passed, mut open) = (0, 0, 0);
    println!("{:<24} {:>6}  failures (seed: first failed check)", "scenario", "pass");
    for s in independent::scenarios() {
        let (mut fails, mut opens) = (Vec::new(), 0u64);
        for k in 0..n {
            let mut s = s.clone();
            s.seed += 1000 * k;
            let row = independent::run(&s, 2).map_err(|e| {
                anyhow::anyhow!("independent scenario {} seed {}: {e:#}", s.name, s.seed)
            })?;
            if row.open_only() {
                opens += 1;
            } else if row.failed()
                && let Some(c) = row.failures().first()
            {
                fails.push(format!("{}: {} ({})", s.seed, c.name, c.detail));
            }
        }
        let ok = n - fails.len() as u64 - opens;
        total += n;
        passed += ok;
        open += opens;
        let opens = if opens > 0 { format!("{opens} open; ") } else { String::new() };
        println!(
            "{:<24} {:>3}/{:<2}  {opens}{}",
            s.name,
            ok,
            n,
            fails.join("\n                                 ")
        );
    }
    println!(
        "{passed} of {total} scenario seeds pass, {open} open ({:.1} s)",
        start.elapsed().as_secs_f64()
    );
    if passed + open < total {
        bail!("{} scenario seeds fail", total - passed - open);
    }
    Ok(())
}

/// The independent set, or the scenarios of it named in `names`.
fn independent_only(names: &[String]) -> Result<()> {
    let all = independent::scenarios();
    if let Some(n) = names.iter().find(|n| all.iter().all(|s| s.name != n.as_str())) {
        bail!("no independent scenario {n:?}");
    }
    let chosen: Vec<_> =
        all.into_iter().filter(|s| names.is_empty() || names.iter().any(|n| n == s.name)).collect();
    let rows = independent_rows(&chosen)?;
    // What a failure needs to be read (and a scenario named on the command line, passed or
    // not): the noise floor, why the rest was declined, the folds.
    for r in rows.iter().filter(|r| !r.passed() || !names.is_empty()) {
        let d = &r.diagnosis_result;
        println!(
            "{}: base RMS {:.3} µm, noise floor {:.3} µm ({:?}, inflation {:.2}); held out {:?}",
            r.scenario,
            d.gap.base_rms_um,
            d.gap.noise_floor_um,
            d.gap.noise_source,
            d.gap.noise_inflation,
            d.held_out
        );
        for x in &d.declined {
            println!("  declined {}: {:?}", x.effect.describe(), x.verdict);
        }
        for a in &d.aliased {
            println!("  aliased {} with {:?}", a.effect.describe(), a.with);
        }
        println!("  schemes {:?}\n  unexplained {:?}", d.schemes, d.unexplained);
    }
    let mut failed = Vec::new();
    independent_verdict(&rows, &mut failed);
    if !failed.is_empty() {
        bail!("failing scenarios: {}", failed.join(", "));
    }
    Ok(())
}

fn both() -> Result<()> {
    let mut failed: Vec<String> = Vec::new();

    let start = Instant::now();
    let mut rows = Vec::new();
    for s in validation::scenarios() {
        let row =
            validation::run(&s, 2).map_err(|e| anyhow::anyhow!("scenario {}: {e:#}", s.name))?;
        eprintln!(
            "{:<28} {:>5.2} s  {}",
            s.name,
            row.seconds,
            if row.passed() { "pass" } else { "FAIL" }
        );
        rows.push(row);
    }
    println!("\n{}", validation::scoreboard(&rows));
    let first: Vec<&str> = rows.iter().filter(|r| !r.passed()).map(|r| r.scenario).collect();
    println!(
        "{} of {} scenarios pass ({:.1} s); held-out RMS in µm, shrink = 1 - after/before, truth = the oracle's shrink, closed = share of the oracle's held-out energy gain",
        rows.len() - first.len(),
        rows.len(),
        start.elapsed().as_secs_f64()
    );
    failed.extend(first.iter().map(|n| format!("suite/{n}")));

    let rows = independent_rows(&independent::scenarios())?;
    independent_verdict(&rows, &mut failed);

    if !failed.is_empty() {
        bail!("failing scenarios: {}", failed.join(", "));
    }
    Ok(())
}

/// Run the independent scenarios `scenarios`, printing each one's time and result.
fn independent_rows(scenarios: &[independent::Scenario]) -> Result<Vec<independent::Outcome>> {
    let mut rows = Vec::new();
    for s in scenarios {
        let row = independent::run(s, 2)
            .map_err(|e| anyhow::anyhow!("independent scenario {}: {e:#}", s.name))?;
        eprintln!(
            "{:<28} {:>5.2} s  {}",
            s.name,
            row.seconds,
            if row.passed() {
                "pass"
            } else if row.open_only() {
                "open"
            } else {
                "FAIL"
            }
        );
        rows.push(row);
    }
    Ok(rows)
}

/// Print the independent set's scoreboard and count; add the failed scenarios to `failed`.
fn independent_verdict(rows: &[independent::Outcome], failed: &mut Vec<String>) {
    println!("\nIndependent set: shapes the candidates do not have, held out by what comes next\n");
    println!("{}", independent::scoreboard(rows));
    let second: Vec<&str> = rows.iter().filter(|r| r.failed()).map(|r| r.scenario).collect();
    let open = rows.iter().filter(|r| r.open_only()).count();
    println!(
        "{} of {} independent scenarios pass, {open} open (failing only their open check, a class not yet fixed), {} fail ({:.1} s); held-out RMS in µm of the base and the augmented model fitted on the training runs; claimed = the diagnosis's held-out closure, measured = the held-out runs' (within {:.0} points), cl./ms. exc the same for the share of the excess above the noise floor (within the same)",
        rows.iter().filter(|r| r.passed()).count(),
        rows.len(),
        second.len(),
        rows.iter().map(|r| r.seconds).sum::<f64>(),
        independent::CLOSURE_TOLERANCE * 100.0
    );
    failed.extend(second.iter().map(|n| format!("independent/{n}")));
}

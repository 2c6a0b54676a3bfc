//! `cargo xtask validate`: issue #4's validation suite. Every scenario of
//! [`ballbar_validate::suite`] is simulated, diagnosed without a hint and judged; the
//! scoreboard says, per scenario, the truth, the diagnosis, the held-out RMS before and after,
//! the shrink against the truth's (an oracle with the true effects in the model) and the share
//! of the truth's held-out gain the diagnosis closed. Fails (exit 1) when any scenario fails.

use std::time::Instant;

use anyhow::{bail, Result};
use ballbar_validate::suite as validation;

pub fn validate() -> Result<()> {
    let start = Instant::now();
    let mut rows = Vec::new();
    for s in validation::scenarios() {
        let row = validation::run(&s, 2).map_err(|e| anyhow::anyhow!("scenario {}: {e:#}", s.name))?;
        eprintln!("{:<28} {:>5.2} s  {}", s.name, row.seconds, if row.passed() { "pass" } else { "FAIL" });
        rows.push(row);
    }
    println!("\n{}", validation::scoreboard(&rows));
    let failed: Vec<&str> = rows.iter().filter(|r| !r.passed()).map(|r| r.scenario).collect();
    println!(
        "{} of {} scenarios pass ({:.1} s); held-out RMS in µm, shrink = 1 - after/before, truth = the oracle's shrink, closed = share of the oracle's held-out energy gain",
        rows.len() - failed.len(),
        rows.len(),
        start.elapsed().as_secs_f64()
    );
    if !failed.is_empty() {
        bail!("failing scenarios: {}", failed.join(", "));
    }
    Ok(())
}

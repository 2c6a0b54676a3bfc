//! Measurements of closing the loop on the bench's 12-run session (three planes, CW and CCW, two
//! repeats, 250 Hz), for each controller: `compensate` (read the runs and the saved model, fit
//! at the model's backlash switch, assess the aliases, make, read back and write the
//! controller's files, predict each run) and `verify` (read the folder, find the backlash
//! switch and fit the repeated runs, compare term by term), each as the command runs it but for
//! its printing, against the base fit (parse, design, fit) in the same process. Target: under a
//! second each.

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow};
use ballbar_cli::compensate::{CompensateArgs, Controller, VerifyArgs};
use ballbar_fit::saved::SavedModel;
use ballbar_model::machine::{MachineSpec, Model, ModelOptions};
use ballbar_model::{Design, NoKernels};
use ballbar_sim::Truth;

/// Time `compensate` and `verify` on the session in `files` (simulated from `truth`), writing
/// into `dir`.
pub fn run(spec: &MachineSpec, truth: &Truth, files: &[PathBuf], dir: &Path) -> Result<()> {
    let reps = 5;
    let cli = |e: ballbar_cli::Failure| anyhow!("{e:?}");
    let reg = ballbar_cli::registry(&[]).map_err(cli)?;
    // The saved model, as `fit --save-model` makes it (the backlash switch at the lagged
    // reversals where the runs determine it).
    let runs = ballbar_cli::read_runs(files, 2).map_err(cli)?;
    let samples: usize = runs.iter().map(|r| r.len()).sum();
    let model = Model::new(spec.clone(), ModelOptions::default())?;
    let (design, _) =
        ballbar_fit::switch::switch_at_lagged_reversals(Design::new(&model, &runs)?, 2)?;
    let fit = ballbar_fit::fit(&design, 2)?;
    let model_path = dir.join("model.ron");
    ballbar_io::ron_files::write_ron(
        &SavedModel::from_fit(&fit, spec, ModelOptions::default()),
        &model_path,
        ballbar_io::Existing::Replace,
    )?;
    // The base fit, as the other benches time it.
    let (fit_ms, _) = crate::time(reps, || -> Result<usize> {
        let runs = ballbar_cli::read_runs(files, 2).map_err(cli)?;
        let model = Model::new(spec.clone(), ModelOptions::default())?;
        let design = Design::new(&model, &runs)?;
        Ok(ballbar_fit::fit(&design, 2)?.rank)
    });
    println!(
        "\ncompensate and verify (12 runs, {samples} samples; median of {reps}, 2 threads; target under 1 s each)"
    );
    println!(
        "{:<12} {:<44} {:>9} {:>12} {:>8}",
        "controller", "command", "ms", "× base fit", "target"
    );
    println!(
        "{:<12} {:<44} {fit_ms:>9.1} {:>12.2} {:>8}",
        "", "base fit: parse + design + fit", 1.0, ""
    );
    for controller in
        [Controller::Linuxcnc, Controller::Siemens, Controller::Fanuc, Controller::Heidenhain]
    {
        let name = format!("{controller:?}").to_lowercase();
        let comp_dir = dir.join(format!("comp-{name}"));
        let args = CompensateArgs {
            model: model_path.clone(),
            controller,
            out: comp_dir.clone(),
            runs: files.to_vec(),
            placement: Default::default(),
            travel: Vec::new(),
            existing: None,
            joints: None,
            include_aliased: vec!["scale".into()],
            threads: 2,
            force: true,
        };
        let (compensate_ms, comp) =
            crate::time(reps, || ballbar_cli::compensate::compensate_written(&args, &reg));
        let (comp, _) = comp.map_err(cli)?;
        // The session repeated with the files active (the simulator's emulation of this
        // controller, written from its documentation), another seed.
        let (emulated, _) =
            ballbar_cli::compensate::simulated_controller(&comp_dir).map_err(cli)?;
        let after =
            ballbar_sim::simulate_controlled(spec, &NoKernels, truth, 0.0, 4, Some(&emulated))?;
        let after_files = crate::write_runs(&after.runs, &dir.join(format!("after-{name}")))?;
        let vargs = VerifyArgs {
            compensation: comp_dir,
            runs: after_files,
            placement: Default::default(),
            json: None,
            threads: 2,
            force: false,
        };
        let (verify_ms, v) =
            crate::time(reps, || ballbar_cli::compensate::verification(&vargs, &reg));
        let v = v.map_err(cli)?;
        for (command, ms) in [
            ("compensate (fit, aliases, files, prediction)", compensate_ms),
            ("verify (fit of the repeated runs, verdicts)", verify_ms),
        ] {
            let target = if ms < 1000.0 { "met" } else { "MISSED" };
            println!("{name:<12} {command:<44} {ms:>9.1} {:>12.2} {target:>8}", ms / fit_ms);
        }
        println!(
            "{name:<12} compensated {} of {} terms; verification {}",
            comp.terms.iter().filter(|t| t.compensated).count(),
            comp.terms.len(),
            if v.passed() { "passed" } else { "NOT passed" }
        );
        // The written terms a repeat of these tests could not verify (flagged by `compensate`),
        // with |value|/u, the sessions that would and their verdicts; then every compensated
        // term's |value|/u and verdict.
        let flagged: Vec<String> = comp
            .terms
            .iter()
            .zip(&v.terms)
            .filter(|(t, _)| t.compensated && t.verifiable_by_repeat == Some(false))
            .map(|(t, c)| {
                let n = t.sessions_to_verify.map_or("-".to_string(), |n| n.to_string());
                format!(
                    "{} ({:.1} u, {n} sessions) {}",
                    t.id,
                    t.value().0.abs() / t.value().1,
                    c.verdict
                )
            })
            .collect();
        if !flagged.is_empty() {
            println!(
                "{name:<12} written, flagged not verifiable by a repeat: {}",
                flagged.join(", ")
            );
        }
        let verdicts: Vec<String> = comp
            .terms
            .iter()
            .zip(&v.terms)
            .filter(|(t, _)| t.compensated)
            .map(|(t, c)| {
                format!("{} {:.1} u {}", t.id, t.value().0.abs() / t.value().1, c.verdict)
            })
            .collect();
        println!("{name:<12} {}", verdicts.join(", "));
    }
    Ok(())
}

//! `compensate --existing`: a machine runs with a first compensation loaded, is re-measured,
//! compensated with `--existing` (the files that were active), and re-simulated with the merged
//! files through the simulator's own emulation of the controller: the earlier correction is kept
//! and the new one added. For the table controllers (SINUMERIK, FANUC, HEIDENHAIN) a first
//! compensation of half of each axis's backlash: the backlash goes (replacing the files would
//! leave the half that was active before: 1.9 µm on the fixture's 3.8) and the scales, written
//! only the second time, are corrected. For every controller, LinuxCNC too, a first compensation
//! of half of each axis's scale: the merged tables leave each scale as predicted, none at the
//! half the first files held.

use std::path::{Path, PathBuf};

use crate::common::*;
use crate::compensate::{
    copied_with, fit_and_compensate, fit_model, json, s, simulate, term, verify,
};

/// A copy of the saved model `from` with the values of the parameters `ids` multiplied by `f`
/// (their uncertainties kept).
fn scaled_terms(from: &Path, to: &Path, ids: &[&str], f: f64) {
    let text = std::fs::read_to_string(from).unwrap();
    let mut out = String::new();
    let mut in_scaled = false;
    for l in text.lines() {
        let t = l.trim();
        if t.starts_with("id: ") {
            in_scaled = ids.iter().any(|b| t.contains(&format!("\"{b}\"")));
        }
        match t.strip_prefix("value: ").and_then(|v| v.trim_end_matches(',').parse::<f64>().ok()) {
            Some(v) if in_scaled => {
                let indent = &l[..l.len() - l.trim_start().len()];
                out.push_str(&format!("{indent}value: {:e},\n", v * f));
                in_scaled = false;
            }
            _ => {
                out.push_str(l);
                out.push('\n');
            }
        }
    }
    std::fs::write(to, out).unwrap();
}

/// A copy of the saved model `from` with each backlash's value multiplied by `f`.
fn scaled_backlash(from: &Path, to: &Path, f: f64) {
    scaled_terms(from, to, &["BX", "BY", "BZ"], f);
}

/// The first compensation: half of each backlash (the fixture's model with its backlash
/// values halved; the scales are left out, as the default leaves a term an alias moves).
fn first_compensation(dir: &Path, controller: &str) -> PathBuf {
    let d = dir.join("first");
    let before = simulate(&d, "before", "1", None);
    let model = fit_model(&d, &before);
    let half = d.join("half.ron");
    scaled_backlash(&model, &half, 0.5);
    let comp = d.join("comp");
    let o = ballbar(&[
        "compensate",
        "--model",
        s(&half),
        "--controller",
        controller,
        "--out",
        s(&comp),
        s(&before),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let cj = json(&comp.join("compensation.json"));
    assert_eq!(term(&cj, "BX")["compensated"], true, "{cj:#}");
    assert_eq!(term(&cj, "EXX1")["compensated"], false, "{cj:#}");
    comp
}

/// The loop with an existing compensation; `resolution_um` the controller's step of a written
/// backlash (FANUC's detection unit; 1 nm elsewhere).
fn existing_is_merged(controller: &str, resolution_um: f64) {
    let dir = scratch(&format!("existing-{controller}"));
    let first = first_compensation(&dir, controller);
    let second = dir.join("second");
    let measured = simulate(&second, "before", "2", Some(&first));
    let comp = fit_and_compensate(
        &second,
        &measured,
        controller,
        &["--existing", s(&first), "--include-aliased", "scale"],
    );
    let cj = json(&comp.join("compensation.json"));
    for id in ["BX", "BY", "BZ"] {
        let t = term(&cj, id);
        let (value, was, written) = (
            t["value_um"].as_f64().unwrap(),
            t["existing"].as_f64().unwrap(),
            t["written"].as_f64().unwrap(),
        );
        // The first files held half the backlash (to the controller's step), the trace the
        // other half: the files carry both, to within the step.
        assert!(was > 0.9 && (value - was).abs() < resolution_um.max(0.1), "{t}");
        assert!((written - (was + value)).abs() <= 0.5 * resolution_um + 1e-3, "{t}");
    }
    // The scales were not in the first files: nothing of them existed.
    for id in ["EXX1", "EYY1", "EZZ1"] {
        let t = term(&cj, id);
        assert_eq!(t["compensated"], true, "{t}");
        assert!(t["existing"].as_f64().unwrap().abs() < 0.5, "{t}");
    }
    // The merged files alone, active.
    let after = simulate(&second, "after", "3", Some(&comp));
    let (_, v) = verify(&comp, &after, &second.join("verify.json"));
    // Every term the files correct ends as predicted, Z's scale too (determined to 0.021 ppm:
    // an axis the run does not move must hold its trim, or its out-of-plane error moves that
    // scale by 0.04 ppm, `docs/compensation.md`).
    for id in ["BX", "BY", "BZ", "EXX1", "EYY1", "EZZ1"] {
        assert_eq!(term(&v, id)["verdict"], "corrected", "{v:#}");
    }
    // Replacing the first files would leave their half, 1.9 µm, active no more.
    for id in ["BX", "BY", "BZ"] {
        let t = term(&v, id);
        assert!(t["after"].as_f64().unwrap().abs() < 0.5, "{t}");
    }
    for id in ["EXX1", "EYY1", "EZZ1"] {
        let t = term(&v, id);
        assert!(t["after"].as_f64().unwrap().abs() < 3.0, "{t}");
    }
}

#[test]
fn siemens_existing_tables_are_merged_not_replaced() {
    existing_is_merged("siemens", 1e-3);
}

#[test]
fn fanuc_existing_parameters_are_merged_not_replaced() {
    existing_is_merged("fanuc", 1.0);
}

#[test]
fn heidenhain_existing_tables_are_merged_not_replaced() {
    existing_is_merged("heidenhain", 1e-3);
}

/// Existing files the controller would refuse, or another controller's, are an error naming
/// the file, the line and what is wrong; nothing is written.
#[test]
fn existing_files_the_controller_would_refuse_are_an_error_naming_file_and_line() {
    let dir = scratch("existing-refused");
    let first = first_compensation(&dir, "heidenhain");
    let model = dir.join("first/model.ron");
    let before = dir.join("first/before");
    // A row whose AXISPOS is not above the previous one's (the TNC's tables ascend).
    let broken = dir.join("broken");
    let x = std::fs::read_to_string(first.join("X.COM")).unwrap();
    let mut lines: Vec<String> = x.lines().map(str::to_string).collect();
    lines[5] = lines[4].clone();
    copied_with(&first, &broken, "X.COM", &(lines.join("\n") + "\n"));
    let run = |controller: &str, existing: &Path, out: &str| {
        ballbar(&[
            "compensate",
            "--model",
            s(&model),
            "--controller",
            controller,
            "--out",
            s(&dir.join(out)),
            "--existing",
            s(existing),
            s(&before),
        ])
    };
    let o = run("heidenhain", &broken, "out-broken");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("X.COM:6: AXISPOS"), "{}", text(&o));
    assert!(!dir.join("out-broken").exists());
    // HEIDENHAIN's tables given as a SINUMERIK's existing compensation.
    let o = run("siemens", &first, "out-other");
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("heidenhain's, not siemens's"), "{}", text(&o));
    assert!(!dir.join("out-other").exists());
    // The emulations read a SINUMERIK's AX1..AX3 as X, Y, Z: joints numbered otherwise would
    // merge one axis's existing table into another's.
    let o = ballbar(&[
        "compensate",
        "--model",
        s(&model),
        "--controller",
        "siemens",
        "--out",
        s(&dir.join("out-joints")),
        "--existing",
        s(&first),
        "--joints",
        "X=1,Y=0,Z=2",
        s(&before),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("--joints X=1") && text(&o).contains("another axis's"),
        "{}",
        text(&o)
    );
    assert!(!dir.join("out-joints").exists());
}

/// A HEIDENHAIN compensation without the runs: the backlash alone, over the travel given
/// (`--travel`), since its BACKLASH column is a table's; without a travel, the option that would
/// write it is named. Loaded, the backlash goes.
#[test]
fn heidenhain_without_runs_writes_the_backlash_over_the_travel() {
    let dir = scratch("heidenhain-no-runs");
    let before = simulate(&dir, "before", "1", None);
    let model = fit_model(&dir, &before);
    let comp = dir.join("comp");
    let run = |extra: &[&str]| {
        let mut args =
            vec!["compensate", "--model", s(&model), "--controller", "heidenhain", "--out"];
        args.push(s(&comp));
        args.extend_from_slice(extra);
        ballbar(&args)
    };
    let o = run(&[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("--travel X=MIN:MAX --travel Y=MIN:MAX --travel Z=MIN:MAX"),
        "{}",
        text(&o)
    );
    assert!(!comp.exists());
    let o = run(&["--travel", "X=0:600", "--travel", "Y=0:400", "--travel", "Z=-600:0"]);
    assert!(o.status.success(), "{}", text(&o));
    let cj = json(&comp.join("compensation.json"));
    // Each axis's table over its travel: BACKLASH minus the axis's column is the fitted
    // backlash, every row.
    for (axis, id, ends) in
        [("X", "BX", [0.0, 600.0]), ("Y", "BY", [0.0, 400.0]), ("Z", "BZ", [-600.0, 0.0])]
    {
        let b = term(&cj, id)["value_um"].as_f64().unwrap() * 1e-3;
        let t = std::fs::read_to_string(comp.join(format!("{axis}.COM"))).unwrap();
        let rows: Vec<Vec<f64>> = t
            .lines()
            .skip(2)
            .take_while(|l| *l != "[END]")
            .map(|l| l.split_whitespace().take(4).map(|w| w.parse().unwrap()).collect())
            .collect();
        assert_eq!([rows[0][1], rows[rows.len() - 1][1]], ends, "{t}");
        assert!(rows.iter().all(|r| (r[3] - r[2] - b).abs() < 2e-6), "{t}");
        assert_eq!(term(&cj, id)["compensated"], true);
    }
    let after = simulate(&dir, "after", "2", Some(&comp));
    let (_, v) = verify(&comp, &after, &dir.join("verify.json"));
    for id in ["BX", "BY", "BZ"] {
        let t = term(&v, id);
        assert_eq!(t["verdict"], "corrected", "{t}");
        assert!(t["after"].as_f64().unwrap().abs() < 0.1, "{t}");
    }
}

/// The positional loop with an existing compensation: the machine runs with tables that correct
/// half of each axis's scale (the fixture's fitted scales halved, no backlash), is re-measured,
/// compensated with `--existing` and re-simulated with the merged files. `step_ppm` is a
/// table's step over the fixture's 300 mm: 0 where the step is 1 nm or finer (0.003 ppm), one
/// detection unit, 3.3 ppm, on FANUC. A step leaves the table off its line by up to half a step,
/// and a circle of diameter 2R reads a difference d between its ends as a scale of d/2R; through
/// the whole fit a staircase can read as more than that (the merged X table below: 10 ppm), which
/// the prediction carries.
fn existing_positional_table_is_merged(controller: &str, step_ppm: f64) {
    let dir = scratch(&format!("existing-positional-{controller}"));
    let before = simulate(&dir, "before", "1", None);
    let model = fit_model(&dir, &before);
    let half = dir.join("half.ron");
    scaled_terms(&model, &half, &["EXX1", "EYY1", "EZZ1"], 0.5);
    scaled_terms(&half, &half, &["BX", "BY", "BZ"], 0.0);
    let first = dir.join("first");
    let o = ballbar(&[
        "compensate",
        "--model",
        s(&half),
        "--controller",
        controller,
        "--include-aliased",
        "scale",
        "--out",
        s(&first),
        s(&before),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let full = json(&first.join("compensation.json"));
    // The full model's scales (the fixture's, 56, 89 and 73 ppm), and what the first files hold.
    let full_scale = |id: &str| {
        let t = term(&full, id);
        (2.0 * t["value_ppm"].as_f64().unwrap(), t["u_ppm"].as_f64().unwrap(), t)
    };
    let second = dir.join("second");
    let measured = simulate(&second, "measured", "2", Some(&first));
    let comp = fit_and_compensate(
        &second,
        &measured,
        controller,
        &["--existing", s(&first), "--include-aliased", "scale"],
    );
    let cj = json(&comp.join("compensation.json"));
    for id in ["EXX1", "EYY1", "EZZ1"] {
        let (whole, u_whole, first_term) = full_scale(id);
        let t = term(&cj, id);
        let f = |k: &str| t[k].as_f64().unwrap();
        let (value, u, was, written) = (f("value_ppm"), f("u_ppm"), f("existing"), f("written"));
        // The existing files read as the controller reads them hold what the first compensate
        // wrote (the same values; a nm's rounding over 300 mm is 0.003 ppm).
        let first_written = first_term["written"].as_f64().unwrap();
        assert!(
            (was - first_written).abs() < 0.01,
            "{id}: existing {was} ppm, written first {first_written} ppm"
        );
        // That is half the scale, to the table's steps.
        assert!(
            (was - 0.5 * whole).abs() < 0.01 + step_ppm,
            "{id}: existing {was} ppm, half of {whole} ppm"
        );
        // The trace saw what the first files left (two independent runs' noise, 3 u, and the
        // existing table's steps as the circles read them), and the files carry both.
        let noise = 3.0 * u.hypot(u_whole);
        assert!(
            (value - (whole - was)).abs() < noise + step_ppm,
            "{id}: measured {value} ppm, expected {whole} - {was} ppm (within {noise} + {step_ppm} ppm)"
        );
        // The merge takes the existing table as the circles read it, its steps too, so the
        // table written holds the machine's whole scale by its least-squares slope: within the
        // noise, the rounding's own slope being a few hundredths of a ppm (a sawtooth of half a
        // step, some 17 periods over the span at 56 ppm). Replacing the files would write half.
        assert!(
            (written - whole).abs() < noise,
            "{id}: written {written} ppm, the whole scale {whole} ppm (within {noise} ppm)"
        );
        assert!(
            (written - whole).abs() < 0.25 * 0.5 * whole,
            "{id}: written {written} ppm, half of {whole} ppm left"
        );
        assert_eq!(t["compensated"], true, "{t}");
    }
    // The merged files alone, active: every scale as predicted, and none left at the half the
    // first files held (what replacing them would leave: 28, 45, 37 ppm).
    let after = simulate(&second, "after", "3", Some(&comp));
    let (code, v) = verify(&comp, &after, &second.join("verify.json"));
    assert_eq!(code, 0, "{v:#}");
    for id in ["EXX1", "EYY1", "EZZ1", "BX", "BY", "BZ"] {
        let t = term(&v, id);
        assert_eq!(t["verdict"], "corrected", "{t}");
        let f = |k: &str| t[k].as_f64().unwrap();
        let (p, a, u) = (f("predicted_after"), f("after"), f("u"));
        // The prediction is the fit of the trace the controller will produce, its steps too.
        assert!((a - p).abs() <= 3.0 * u, "{id}: after {a}, predicted {p} (u {u})");
    }
    // Where the tables are their polynomials (every controller but FANUC), the circles read
    // what they leave as 0. A FANUC staircase is read at the circles' samples through the whole
    // fit, which on this fixture's weakly determined X scale (u 1.4 ppm) makes its steps up to
    // 10 ppm: that is predicted (checked above), and the written slope is the witness above.
    if step_ppm == 0.0 {
        for id in ["EXX1", "EYY1", "EZZ1"] {
            let t = term(&v, id);
            let (a, u) = (t["after"].as_f64().unwrap(), t["u"].as_f64().unwrap());
            let (whole, _, _) = full_scale(id);
            assert!(a.abs() <= 3.0 * u, "{id}: after {a} ppm (u {u})");
            assert!(a.abs() < 0.25 * 0.5 * whole, "{id}: after {a} ppm, half of {whole} ppm left");
        }
    }
}

#[test]
fn linuxcnc_existing_joint_tables_are_merged() {
    existing_positional_table_is_merged("linuxcnc", 0.0);
}

#[test]
fn siemens_existing_leadscrew_tables_are_merged() {
    existing_positional_table_is_merged("siemens", 0.0);
}

#[test]
fn fanuc_existing_pitch_error_tables_are_merged() {
    existing_positional_table_is_merged("fanuc", 1e-3 / 300.0 * 1e6);
}

#[test]
fn heidenhain_existing_axis_tables_are_merged() {
    existing_positional_table_is_merged("heidenhain", 0.0);
}

//! `compensate --existing` for the table controllers (SINUMERIK, FANUC, HEIDENHAIN): a machine
//! runs with a first compensation loaded (half of each axis's backlash), is re-measured,
//! compensated with `--existing` (the files that were active), and re-simulated with the merged
//! files through the simulator's own emulation of the controller: the earlier correction is kept
//! and the new one added, so the backlash goes (replacing the files would leave the half that
//! was active before: 1.9 µm on the fixture's 3.8) and the scales, written only the second
//! time, are corrected.

use std::path::{Path, PathBuf};

use crate::common::*;
use crate::compensate::{
    copied_with, fit_and_compensate, fit_model, json, s, simulate, term, verify,
};

/// A copy of the saved model `from` with each backlash's value multiplied by `f`.
fn scaled_backlash(from: &Path, to: &Path, f: f64) {
    let text = std::fs::read_to_string(from).unwrap();
    let mut out = String::new();
    let mut in_backlash = false;
    for l in text.lines() {
        let t = l.trim();
        if t.starts_with("id: ") {
            in_backlash = ["\"BX\"", "\"BY\"", "\"BZ\""].iter().any(|b| t.contains(b));
        }
        match t.strip_prefix("value: ").and_then(|v| v.trim_end_matches(',').parse::<f64>().ok()) {
            Some(v) if in_backlash => {
                let indent = &l[..l.len() - l.trim_start().len()];
                out.push_str(&format!("{indent}value: {:e},\n", v * f));
                in_backlash = false;
            }
            _ => {
                out.push_str(l);
                out.push('\n');
            }
        }
    }
    std::fs::write(to, out).unwrap();
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

//! The loop closed for LinuxCNC on the shipped fixture: simulate the paper's column machine →
//! `fit --save-model` → `compensate` → `simulate --compensation` (the simulator's own emulation
//! of LinuxCNC, not the compensate crate's code) → `verify`; and the wrong applications each
//! caught with its verdict.

use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::common::*;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn truth() -> PathBuf {
    root().join("fixtures/column-paper/truth.ron")
}

/// Simulate the fixture into `dir/NAME` with `seed`, with the compensation in `comp` active.
fn simulate(dir: &Path, name: &str, seed: &str, comp: Option<&Path>) -> PathBuf {
    let out = dir.join(name);
    let truth = truth();
    let mut args = vec!["simulate", "--machine", "column", "--truth", s(&truth), "--out", s(&out)];
    args.extend(["--seed", seed]);
    if let Some(c) = comp {
        args.extend(["--compensation", s(c)]);
    }
    let o = ballbar(&args);
    assert!(o.status.success(), "{}", text(&o));
    out
}

/// The measured session, its model and the LinuxCNC files: `dir/comp`.
fn compensated(dir: &Path) -> PathBuf {
    let before = simulate(dir, "before", "1", None);
    fit_and_compensate(dir, &before, &[])
}

/// `before` fitted with the paper's model (saved as `dir/model.ron`) and compensated for
/// LinuxCNC into `dir/comp` with `extra` options.
fn fit_and_compensate(dir: &Path, before: &Path, extra: &[&str]) -> PathBuf {
    let model = dir.join("model.ron");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "--servo",
        "paper",
        "--bar-length-um",
        "0",
        s(before),
        "--save-model",
        s(&model),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let comp = dir.join("comp");
    let mut args = vec!["compensate", "--model", s(&model), "--controller", "linuxcnc"];
    args.extend(["--out", s(&comp)]);
    args.extend_from_slice(extra);
    args.push(s(before));
    let o = ballbar(&args);
    assert!(o.status.success(), "{}", text(&o));
    comp
}

/// `verify`'s exit code and JSON.
fn verify(comp: &Path, runs: &Path, json: &Path) -> (i32, Value) {
    let o = ballbar(&["verify", "--compensation", s(comp), s(runs), "--json", s(json)]);
    let v: Value = serde_json::from_str(&std::fs::read_to_string(json).unwrap_or_default())
        .unwrap_or_else(|e| panic!("{e}: {}", text(&o)));
    (o.status.code().unwrap_or(-1), v)
}

/// A copy of the compensation with each table's trims mapped by `f`.
fn edited(comp: &Path, to: &Path, f: &dyn Fn(f64) -> f64) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(comp).unwrap() {
        let p = e.unwrap().path();
        let name = p.file_name().unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        let text = if p.extension().is_some_and(|x| x == "comp") {
            text.lines()
                .map(|l| {
                    let v: Vec<f64> = l.split_whitespace().map(|w| w.parse().unwrap()).collect();
                    format!("{:.6} {:.10} {:.10}\n", v[0], f(v[1]), f(v[2]))
                })
                .collect()
        } else {
            text
        };
        std::fs::write(to.join(name), text).unwrap();
    }
}

/// The verdicts of the compensated terms.
fn verdicts(v: &Value) -> Vec<(String, String)> {
    v["terms"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["compensated"].as_bool().unwrap())
        .map(|t| {
            (t["id"].as_str().unwrap().to_string(), t["verdict"].as_str().unwrap().to_string())
        })
        .collect()
}

#[test]
fn the_loop_closes_on_the_shipped_fixture() {
    let dir = scratch("compensate-loop");
    let comp = compensated(&dir);
    // The files: the INI's sections, and tables LinuxCNC reads whole (three numbers a line,
    // ascending, at most 256 lines).
    let ini = std::fs::read_to_string(comp.join("linuxcnc.ini")).unwrap();
    for n in 0..3 {
        assert!(
            ini.contains(&format!("[JOINT_{n}]\nCOMP_FILE = joint-{n}.comp\nCOMP_FILE_TYPE = 1\n")),
            "{ini}"
        );
        let table = std::fs::read_to_string(comp.join(format!("joint-{n}.comp"))).unwrap();
        let rows: Vec<Vec<f64>> = table
            .lines()
            .map(|l| l.split_whitespace().map(|w| w.parse::<f64>().unwrap()).collect())
            .collect();
        assert!(rows.len() <= 256 && rows.iter().all(|r| r.len() == 3));
        assert!(rows.windows(2).all(|w| w[1][0] > w[0][0]));
    }
    assert!(!ini.contains("BACKLASH"), "a joint with a table takes its backlash from it");
    let cj: Value =
        serde_json::from_str(&std::fs::read_to_string(comp.join("compensation.json")).unwrap())
            .unwrap();
    assert_eq!(cj["format"], "ballbar-compensation/1");
    let sq = cj["terms"].as_array().unwrap().iter().find(|t| t["id"] == "SQXY").unwrap();
    assert_eq!(sq["compensated"], false);
    // Each line of X's table is the trim derived by hand from the model's scale and backlash
    // (ppm and µm in compensation.json): -scale·X ± B/2, mm, to the written 0.1 nm (and the
    // printed digits of the JSON's values, far finer).
    let term =
        |id: &str| cj["terms"].as_array().unwrap().iter().find(|t| t["id"] == id).unwrap().clone();
    let scale = term("EXX1")["value_ppm"].as_f64().unwrap() * 1e-6;
    let half = term("BX")["value_um"].as_f64().unwrap() * 1e-3 / 2.0;
    for line in std::fs::read_to_string(comp.join("joint-0.comp")).unwrap().lines() {
        let v: Vec<f64> = line.split_whitespace().map(|w| w.parse().unwrap()).collect();
        assert!((v[1] - (-scale * v[0] + half)).abs() < 1e-7, "{line}");
        assert!((v[2] - (-scale * v[0] - half)).abs() < 1e-7, "{line}");
    }
    assert!(sq["why"].as_str().unwrap().contains("no cross-axis table"));
    // Re-measured with the files active (another seed: new noise and centring).
    let after = simulate(&dir, "after", "2", Some(&comp));
    let (code, v) = verify(&comp, &after, &dir.join("verify.json"));
    assert_eq!(code, 0, "{v:#}");
    assert_eq!(v["format"], "ballbar-verification/1");
    let term =
        |id: &str| v["terms"].as_array().unwrap().iter().find(|t| t["id"] == id).unwrap().clone();
    // Backlash below 1 µm, and the axes' scales within 3 ppm of each other.
    for id in ["BX", "BY", "BZ"] {
        let t = term(id);
        assert_eq!(t["verdict"], "corrected");
        assert!(t["after"].as_f64().unwrap().abs() < 1.0, "{t}");
        assert!(t["before"].as_f64().unwrap() > 2.5, "{t}");
    }
    let scales: Vec<f64> =
        ["EXX1", "EYY1", "EZZ1"].iter().map(|id| term(id)["after"].as_f64().unwrap()).collect();
    for a in &scales {
        for b in &scales {
            assert!((a - b).abs() < 3.0, "{scales:?}");
        }
    }
    // Each run's predicted G within 1 µm or 25 % of the re-measured one.
    let runs = v["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 6);
    for r in runs {
        let (p, a) = (r["G_predicted_um"].as_f64().unwrap(), r["G_after_um"].as_f64().unwrap());
        assert!((p - a).abs() < 1.0f64.max(0.25 * a), "{r}");
    }
    // What was not compensated is as it was.
    assert_eq!(term("SQXY")["verdict"], "not_compensated");
    // Nothing in the folder is replaced without --force.
    let before = std::fs::read_to_string(comp.join("joint-0.comp")).unwrap();
    let model = dir.join("model.ron");
    let o = ballbar(&[
        "compensate",
        "--model",
        s(&model),
        "--controller",
        "linuxcnc",
        "--out",
        s(&comp),
        s(&dir.join("before")),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(comp.join("joint-0.comp")).unwrap(), before);
}

#[test]
fn a_wrong_sign_a_file_not_loaded_and_a_unit_mistake_each_give_their_verdict() {
    let dir = scratch("compensate-wrong");
    let comp = compensated(&dir);
    let check = |name: &str, runs: &Path, comp: &Path, want: &str| {
        let (code, v) = verify(comp, runs, &dir.join(format!("{name}.json")));
        assert_eq!(code, 3, "{name}: {v:#}");
        let got = verdicts(&v);
        assert_eq!(got.len(), 6, "{got:?}");
        assert!(got.iter().all(|(_, verdict)| verdict == want), "{name}: {got:?}");
        v
    };
    // The sign flipped in the written tables: every term moves away, to about twice its size.
    let flipped = dir.join("flipped");
    edited(&comp, &flipped, &|x| -x);
    check("flipped", &simulate(&dir, "a-flipped", "3", Some(&flipped)), &flipped, "reversed");
    // The files not loaded: the machine as it was.
    check("unloaded", &simulate(&dir, "a-unloaded", "3", None), &comp, "unchanged");
    // A unit mistake: trims ten times too large, and a file in mm read by a controller set to
    // inches (25.4 times); each verdict gives the factor.
    for (name, factor) in [("ten", 10.0), ("inch", 25.4)] {
        let wrong = dir.join(name);
        edited(&comp, &wrong, &|x| x * factor);
        let v =
            check(name, &simulate(&dir, &format!("a-{name}"), "3", Some(&wrong)), &wrong, "scaled");
        for t in v["terms"].as_array().unwrap().iter().filter(|t| t["compensated"] == true) {
            assert_eq!(t["factor"].as_f64(), Some(factor), "{t}");
        }
    }
    // Trims a thousand times too small move a backlash by less than its uncertainty: it reads
    // as a file not loaded (no measurement can tell them apart). A thousand times too large is
    // beyond the bar's travel: the simulator refuses the readings, as a ballbar could not take
    // them.
    let small = dir.join("small");
    edited(&comp, &small, &|x| x / 1000.0);
    let (code, v) =
        verify(&small, &simulate(&dir, "a-small", "3", Some(&small)), &dir.join("small.json"));
    assert_eq!(code, 3);
    let bx = v["terms"].as_array().unwrap().iter().find(|t| t["id"] == "BX").unwrap();
    assert_eq!(bx["verdict"], "unchanged", "{bx}");
}

#[test]
fn a_controller_that_is_not_one_and_files_linuxcnc_would_misread_are_refused() {
    let dir = scratch("compensate-refused");
    let before = simulate(&dir, "before", "1", None);
    let model = dir.join("model.ron");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "--servo",
        "paper",
        "--bar-length-um",
        "0",
        s(&before),
        "--save-model",
        s(&model),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let run = |controller: &str, extra: &[&str]| {
        let mut args =
            vec!["compensate", "--model", s(&model), "--controller", controller, "--out"];
        let out = dir.join(format!("out-{controller}"));
        args.push(s(&out));
        args.extend(extra);
        args.push(s(&before));
        (ballbar(&args), out)
    };
    // Not a controller at all: a usage error.
    assert_eq!(run("okuma", &[]).0.status.code(), Some(2));
    // An existing table with a comment line: LinuxCNC would stop reading there; refused, naming
    // the line.
    let existing = dir.join("existing");
    std::fs::create_dir_all(&existing).unwrap();
    std::fs::write(
        existing.join("linuxcnc.ini"),
        "[JOINT_0]\nCOMP_FILE = x.comp\nCOMP_FILE_TYPE = 1\n",
    )
    .unwrap();
    std::fs::write(existing.join("x.comp"), "100 0 0\n# pitch\n200 0 0\n").unwrap();
    let (o, out) = run("linuxcnc", &["--existing", s(&existing)]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("x.comp:2:"), "{}", text(&o));
    assert!(!out.exists());
    // An existing table whose entries, merged with the new ones, would pass LinuxCNC's 256:
    // refused, nothing written.
    let many: String = (0..200).map(|k| format!("{:.3} 0 0\n", 150.5 + k as f64)).collect();
    std::fs::write(existing.join("x.comp"), many).unwrap();
    let (o, out) = run("linuxcnc", &["--existing", s(&existing)]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("256"), "{}", text(&o));
    assert!(!out.exists());
}

#[test]
fn an_existing_compensation_is_merged_with_the_measured_correction() {
    // The machine ran with half of X's backlash (3.8 µm in the fixture) already compensated.
    let dir = scratch("compensate-existing");
    let existing = dir.join("existing");
    std::fs::create_dir_all(&existing).unwrap();
    std::fs::write(existing.join("linuxcnc.ini"), "[JOINT_0]\nBACKLASH = 0.002\n").unwrap();
    let before = simulate(&dir, "before", "1", Some(&existing));
    let comp = fit_and_compensate(&dir, &before, &["--existing", s(&existing)]);
    let cj: Value =
        serde_json::from_str(&std::fs::read_to_string(comp.join("compensation.json")).unwrap())
            .unwrap();
    let bx = cj["terms"].as_array().unwrap().iter().find(|t| t["id"] == "BX").unwrap().clone();
    // The trace saw 3.8 - 2.0 = 1.8 µm; the files carry the 2.0 µm that was active plus that.
    let (measured, was, written) = (
        bx["value_um"].as_f64().unwrap(),
        bx["existing"].as_f64().unwrap(),
        bx["written"].as_f64().unwrap(),
    );
    assert!((measured - 1.8).abs() < 0.1, "{bx}");
    assert!((was - 2.0).abs() < 1e-6, "{bx}");
    assert!((written - (was + measured)).abs() < 1e-3, "{bx}");
    // The new files alone, active: the backlash is gone.
    let after = simulate(&dir, "after", "2", Some(&comp));
    let (code, v) = verify(&comp, &after, &dir.join("verify.json"));
    assert_eq!(code, 0, "{v:#}");
    let t = v["terms"].as_array().unwrap().iter().find(|t| t["id"] == "BX").unwrap().clone();
    assert!(t["after"].as_f64().unwrap().abs() < 0.1, "{t}");
}

#[test]
fn a_real_test_without_its_centre_is_compensated_with_the_default_centre_said() {
    let real = root().join("../shared/data/real/d2-xy-50mm-1500.b5r");
    if !real.is_file() {
        skip(
            Needs::SharedData,
            &format!("{} is not there (the shared real test file)", real.display()),
        );
        return;
    }
    let dir = scratch("compensate-real");
    let model = dir.join("model.ron");
    let o = ballbar(&["fit", "--machine", "column", s(&real), "--save-model", s(&model)]);
    assert!(o.status.success(), "{}", text(&o));
    let comp = dir.join("comp");
    let o = ballbar(&[
        "compensate",
        "--model",
        s(&model),
        "--controller",
        "linuxcnc",
        "--out",
        s(&comp),
        s(&real),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let cj: Value =
        serde_json::from_str(&std::fs::read_to_string(comp.join("compensation.json")).unwrap())
            .unwrap();
    // The .b5r file does not give the circle's centre: the notes say the tables assume 0, 0, 0.
    let notes: Vec<&str> =
        cj["notes"].as_array().unwrap().iter().map(|n| n.as_str().unwrap()).collect();
    assert!(
        notes.iter().any(|n| n.contains("default centre") && n.contains("--pivot")),
        "{notes:?}"
    );
    // Z does not move in an XY test: nothing of it is written, and the reason is given.
    let bz = cj["terms"].as_array().unwrap().iter().find(|t| t["id"] == "BZ").unwrap();
    assert_eq!(bz["compensated"], false);
    assert!(bz["why"].as_str().unwrap().contains("do not determine"), "{bz}");
    // Both runs of the file (CCW and CW) get a prediction.
    assert_eq!(cj["predicted"].as_array().unwrap().len(), 2);
    let ini = std::fs::read_to_string(comp.join("linuxcnc.ini")).unwrap();
    assert!(!ini.contains("[JOINT_2]"), "{ini}");
}

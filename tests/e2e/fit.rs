//! `fit`, `predict` and `simulate` on the shipped fixtures, and bad input.

use crate::common::*;

#[test]
fn fit_of_the_paper_fixtures_reports_the_papers_quantities() {
    for machine in ["column", "horizontal"] {
        let dir = scratch(&format!("fit-{machine}"));
        let json = dir.join("fit.json");
        let runs = format!("fixtures/{machine}-paper/runs");
        let o = ballbar(&[
            "fit",
            "--machine",
            machine,
            "--servo",
            "paper",
            "--bar-length-um",
            "0",
            &runs,
            "--json",
            json.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(v["format"], "ballbar-fit/1");
        assert_eq!(v["identifiability"]["rank"], v["identifiability"]["parameters"]);
        let truth: ballbar_sim::Truth = ron::from_str(
            &std::fs::read_to_string(root().join(format!("fixtures/{machine}-paper/truth.ron")))
                .unwrap(),
        )
        .unwrap();
        let p = truth.paper.unwrap();
        let q = v["paper"]["quantities"].as_array().unwrap();
        assert_eq!(q.len(), 24);
        let want = [
            ("X positional", p.positional_um[0]),
            ("Y straightness along X", p.straightness_um[0]),
            ("squareness YZ", p.squareness_urad[1]),
            ("backlash Z", p.backlash_um[2]),
            ("servo mismatch XY", p.servo_mismatch_um[0]),
        ];
        for (name, w) in want {
            let row = q.iter().find(|r| r["paper"]["name"] == name).unwrap();
            let (val, u) = (
                row["paper"]["value"].as_f64().unwrap(),
                row["paper"]["std_uncertainty"].as_f64().unwrap(),
            );
            assert!((val - w).abs() < 3.0 * u, "{machine} {name}: {val} ± {u} vs {w}");
        }
        // The fixtures carry 0.2 µm noise: that is what is left.
        let sigma = v["residual"]["sigma_um"].as_f64().unwrap();
        assert!((sigma - 0.2).abs() < 0.02, "{sigma}");
        for run in v["runs"].as_array().unwrap() {
            assert!(
                run["after"]["rms_um"].as_f64().unwrap() < 0.25
                    && run["before"]["rms_um"].as_f64().unwrap() > 10.0
            );
        }
    }
}

#[test]
fn the_default_model_reports_what_one_radius_cannot_separate() {
    let o = ballbar(&["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(out.contains("What these tests cannot separate"), "{out}");
    assert!(out.contains("a second radius"), "{out}");
    assert!(out.contains("not identifiable"), "{out}");
}

#[test]
fn save_model_then_predict_writes_the_runs_with_the_model_column() {
    let dir = scratch("predict");
    let model = dir.join("model.ron");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "--servo",
        "paper",
        "--bar-length-um",
        "0",
        "fixtures/column-paper/runs",
        "--save-model",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.join("pred");
    let o = ballbar(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        "fixtures/column-paper/runs/xy-ccw-1.csv",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let original =
        std::fs::read_to_string(root().join("fixtures/column-paper/runs/xy-ccw-1.csv")).unwrap();
    let written = std::fs::read_to_string(out.join("xy-ccw-1.csv")).unwrap();
    assert_eq!(original.lines().count(), written.lines().count());
    let cols: Vec<&str> =
        written.lines().find(|l| l.starts_with("t_s")).unwrap().split(',').collect();
    assert_eq!(cols.last(), Some(&"dR_model_um"));
    // The prediction follows the measurement up to the run's centring and the noise.
    let (mut se, mut n) = (0.0, 0.0);
    for l in written.lines().filter(|l| !l.starts_with('#') && !l.starts_with("t_s")) {
        let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        se += (f[4] - f[5]).powi(2);
        n += 1.0;
    }
    let rms = (se / n).sqrt();
    assert!(rms < 6.0, "measured vs predicted RMS {rms} µm (centring ≤ ~3σ of 3 µm)");
}

#[test]
fn simulate_writes_runs_that_fit_back_to_the_truth() {
    let dir = scratch("simulate");
    let o = ballbar(&[
        "simulate",
        "--machine",
        "horizontal",
        "--truth",
        "fixtures/horizontal-paper/truth.ron",
        "--out",
        dir.to_str().unwrap(),
        "--seed",
        "9",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 6);
    let o = ballbar(&[
        "fit",
        "--machine",
        "horizontal",
        "--servo",
        "paper",
        "--bar-length-um",
        "0",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn bad_input_is_exit_1_with_file_and_line_and_usage_is_exit_2() {
    let dir = scratch("bad");
    let good =
        std::fs::read_to_string(root().join("fixtures/column-paper/runs/xy-ccw-1.csv")).unwrap();
    let mut lines: Vec<String> = good.lines().map(String::from).collect();
    let k = lines.iter().position(|l| l.starts_with("t_s")).unwrap() + 5;
    lines[k] = lines[k].replacen(',', ",NaN,", 1).replacen(",NaN,", ",NaN", 1);
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let cases: Vec<(Vec<String>, String)> = vec![
        (
            vec!["fit".into(), "--machine".into(), "column".into(), bad.display().to_string()],
            format!("bad.csv:{}", k + 1),
        ),
        (
            vec![
                "fit".into(),
                "--machine".into(),
                "column".into(),
                dir.join("missing.csv").display().to_string(),
            ],
            "missing.csv".into(),
        ),
        (
            vec![
                "fit".into(),
                "--machine".into(),
                "lathe".into(),
                "fixtures/column-paper/runs".into(),
            ],
            "no machine type 'lathe'".into(),
        ),
        (
            vec![
                "predict".into(),
                "--model".into(),
                bad.display().to_string(),
                "fixtures/column-paper/runs".into(),
                "--out".into(),
                dir.display().to_string(),
            ],
            "bad.csv:1:".into(),
        ),
        (
            vec![
                "simulate".into(),
                "--machine".into(),
                "column".into(),
                "--truth".into(),
                bad.display().to_string(),
                "--out".into(),
                dir.display().to_string(),
            ],
            "bad.csv:1:".into(),
        ),
    ];
    for (args, what) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = ballbar(&a);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
        assert!(t.contains(&what), "{args:?}: expected '{what}' in: {t}");
        assert!(!t.contains("panicked"), "{t}");
    }
    let o = ballbar(&["fit"]);
    assert_eq!(o.status.code(), Some(2));
    let o = ballbar(&["frobnicate"]);
    assert_eq!(o.status.code(), Some(2));
}

#[test]
fn a_short_arc_that_cannot_constrain_the_model_is_an_error_not_a_result() {
    // The first 47 samples of one run (a 2° arc): the truncated fit keeps a condition number of
    // ~1e8 and the exact model runs away from the first-order solution. That must be an input
    // error that says so, not residuals of 1e35 µm reported as a fit.
    let dir = scratch("short-arc");
    let text_in =
        std::fs::read_to_string(root().join("fixtures/column-paper/runs/xy-cw-1.csv")).unwrap();
    let short: Vec<&str> = text_in.lines().take(60).collect();
    let f = dir.join("short.csv");
    std::fs::write(&f, short.join("\n")).unwrap();
    for cmd in ["fit", "diagnose"] {
        let o = ballbar(&[cmd, "--machine", "column", f.to_str().unwrap()]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{cmd}: {t}");
        assert!(t.contains("does not converge") || t.contains("cannot identify"), "{cmd}: {t}");
        assert!(!t.contains("panicked"), "{t}");
    }
}

/// A run's `machine:` header is checked against the machine it is fitted with: column runs
/// fitted as the horizontal machine, or runs of two machines in one fit, are refused naming a
/// file; runs without the header are taken as the machine given.
#[test]
fn runs_of_another_machine_are_refused_naming_the_file() {
    let o = ballbar(&["fit", "--machine", "horizontal", "fixtures/column-paper/runs"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("xy-ccw-1.csv: the run is of machine 'column' (its header's machine), but the fit is of machine 'horizontal'"), "{}", text(&o));
    let o = ballbar(&[
        "diagnose",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "fixtures/horizontal-paper/runs",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("the run is of machine 'horizontal'"), "{}", text(&o));
}

/// `--threads 0` is a usage error, not a silent default.
#[test]
fn zero_threads_is_a_usage_error() {
    for cmd in ["fit", "diagnose"] {
        let o =
            ballbar(&[cmd, "--machine", "column", "fixtures/column-paper/runs", "--threads", "0"]);
        assert_eq!(o.status.code(), Some(2), "{cmd}: {}", text(&o));
        assert!(text(&o).contains("0 is not in 1..=1024"), "{}", text(&o));
    }
}

/// `fit`'s labels read without a manual: the vendor-unit column says what it is; the
/// parameters state their polynomial basis and normalisation length, so that `EXX1` and
/// `X positional` can be related; no uncertainty of the paper's quantities reads 0.00 (Z
/// positional's is below 0.005 µm); and the JSON gives each polynomial parameter's
/// normalisation.
#[test]
fn the_fit_labels_its_columns_units_and_normalisation() {
    let dir = scratch("fit-labels");
    let json = dir.join("fit.json");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "--servo",
        "paper",
        "--bar-length-um",
        "0",
        "fixtures/column-paper/runs",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // The vendor-unit column.
    let header = t.lines().find(|l| l.trim_start().starts_with("quantity")).unwrap();
    assert!(header.ends_with("in Renishaw's units") && !header.contains("vendor"), "{header}");
    assert!(
        t.contains(
            "  in Renishaw's units: the same quantity as Renishaw's ballbar software states it"
        ),
        "{t}"
    );
    // The basis: EXX1 is the error at L = 250 mm, X positional the same error at R = 150 mm.
    assert!(
        t.contains("polynomial terms are θ·(q/L)^k in the axis position q, L = 250 mm for X, Y, Z"),
        "{t}"
    );
    let row = |start: &str| {
        t.lines()
            .find(|l| l.trim_start().starts_with(start))
            .unwrap_or_else(|| panic!("no {start}: {t}"))
    };
    assert!(
        row("EXX1 ").ends_with("positional error of X, degree 1: θ·(X/250 mm)"),
        "{}",
        row("EXX1 ")
    );
    assert!(row("EYX2 ").contains("θ·(X/250 mm)²"), "{}", row("EYX2 "));
    let number =
        |l: &str, k: usize| -> f64 { l.split_whitespace().nth(k).unwrap().parse().unwrap() };
    let (exx1, x) = (number(row("EXX1 "), 1), number(row("X positional"), 2));
    // Both printed to two significant digits of their u (0.11 and 0.064 µm): 0.01 µm covers it.
    assert!((exx1 * 150.0 / 250.0 - x).abs() < 0.01, "{exx1} {x}");
    let p = v["parameters"].as_array().unwrap().iter().find(|p| p["id"] == "EXX1").unwrap();
    assert_eq!(
        p["normalisation"],
        serde_json::json!({"axis": "X", "reference_mm": 0.0, "length_mm": 250.0, "degree": 1}),
        "{p}"
    );
    assert_eq!(p["basis"], "θ·(X/250 mm)");
    // Every u of the paper's table, as printed, is not zero and carries two significant
    // digits; Z positional's is below 0.005 µm.
    let z = row("Z positional");
    let u_text = z.split_whitespace().nth(3).unwrap();
    let u: f64 = u_text.parse().unwrap();
    assert!(u > 0.0 && u < 0.005, "{z}");
    for q in v["paper"]["quantities"].as_array().unwrap() {
        let name = q["paper"]["name"].as_str().unwrap();
        let l = row(&format!("{name} "));
        let printed: f64 =
            l.trim_start()[name.len()..].split_whitespace().nth(1).unwrap().parse().unwrap();
        let u = q["paper"]["std_uncertainty"].as_f64().unwrap();
        // Two significant digits: within 5 % of the value (0.5 in the second digit of ≥ 10).
        assert!(printed > 0.0 && (printed - u).abs() <= 0.05 * u, "{l}: u {u}");
    }
}

/// `predict` says that `dR_model_um` leaves out the set-up eccentricity.
#[test]
fn predict_says_what_the_prediction_leaves_out() {
    let dir = scratch("predict-note");
    let model = dir.join("model.ron");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--save-model",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ballbar(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        "fixtures/column-paper/runs/xy-cw-1.csv",
        "--out",
        dir.join("p").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("note: dR_model_um is the saved model's prediction for the run's path, feed and direction; it leaves out the set-up eccentricity"), "{}", text(&o));
}

/// The column fixture's runs copied to `dir` with the header lines of `keys` left out of the
/// runs whose file names start with `only` (`""`: all).
fn runs_without(dir: &std::path::Path, keys: &[&str], only: &str) -> std::path::PathBuf {
    let out = dir.join("runs");
    std::fs::create_dir_all(&out).unwrap();
    for e in std::fs::read_dir(root().join("fixtures/column-paper/runs")).unwrap() {
        let f = e.unwrap().path();
        if f.extension().is_none_or(|x| x != "csv") {
            continue;
        }
        let name = f.file_name().unwrap().to_string_lossy().into_owned();
        let text = std::fs::read_to_string(&f).unwrap();
        let kept: String = text
            .split_inclusive('\n')
            .filter(|l| {
                !(name.starts_with(only) && keys.iter().any(|k| l.starts_with(&format!("# {k}:"))))
            })
            .collect();
        if name.starts_with(only) {
            assert!(kept.len() < text.len(), "{name}: no key removed");
        }
        std::fs::write(out.join(&name), kept).unwrap();
    }
    out
}

/// X positional of a fit's JSON, µm.
fn x_positional_um(v: &serde_json::Value) -> f64 {
    let q = v["paper"]["quantities"].as_array().unwrap();
    q.iter().find(|r| r["paper"]["name"] == "X positional").unwrap()["paper"]["value"]
        .as_f64()
        .unwrap()
}

/// A run without `tool_ball_mm` is fitted with a tool length of 0, which moves the positional
/// and squareness values (on this fixture X positional from 8.47 to 12.06 µm, about 60 σ,
/// with the same residual σ): `fit`, `diagnose` and `predict` say so, naming the runs, and the
/// JSON lists it under `assumed`. A `table_ball_mm` left out changes no number (the pivot and
/// the tool ball place the table ball) and is not stated; with both keys given nothing is.
#[test]
fn a_tool_ball_not_given_is_stated_naming_the_runs_and_what_depends_on_it() {
    let fit = |runs: &std::path::Path, json: &std::path::Path| {
        let o = ballbar(&[
            "fit",
            "--machine",
            "column",
            "--servo",
            "paper",
            "--bar-length-um",
            "0",
            runs.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(json).unwrap()).unwrap();
        (text(&o), v)
    };
    let note = "note: tool_ball_mm is not given in all 6 runs: taken as 0, 0, 0 mm, a tool length of 0 mm; it is the Abbe arm of the angular errors: the positional and squareness values and the model's predictions depend on it";
    // Both keys given: no note, nothing assumed.
    let d = scratch("fit-defaults-given");
    let (t, given) = fit(&root().join("fixtures/column-paper/runs"), &d.join("fit.json"));
    assert!(!t.contains("tool_ball_mm") && !t.contains("note: "), "{t}");
    assert_eq!(given["assumed"], serde_json::json!([]), "{}", given["assumed"]);
    // Both left out of every run.
    let d = scratch("fit-defaults-none");
    let runs = runs_without(&d, &["table_ball_mm", "tool_ball_mm"], "");
    let (t, v) = fit(&runs, &d.join("fit.json"));
    assert!(t.lines().any(|l| l.starts_with(note)), "{t}");
    assert!(!t.contains("table_ball_mm"), "{t}");
    let a = v["assumed"].as_array().unwrap();
    assert_eq!(a.len(), 1, "{a:?}");
    assert_eq!(a[0]["key"], "tool_ball_mm");
    assert_eq!(a[0]["value_mm"], serde_json::json!([0.0, 0.0, 0.0]));
    assert_eq!(
        a[0]["runs"],
        serde_json::json!(["xy-ccw-1", "xy-cw-1", "yz-ccw-1", "yz-cw-1", "zx-ccw-1", "zx-cw-1"])
    );
    // What the note is about: the stated 100 mm tool against 0 moves X positional by 3.6 µm
    // (u 0.06 µm: anything above 1 µm is the default, not noise).
    let (x_given, x_default) = (x_positional_um(&given), x_positional_um(&v));
    assert!(
        (x_given - 8.47).abs() < 0.01 && (x_default - x_given).abs() > 1.0,
        "{x_given} {x_default}"
    );
    // The table ball alone left out: the same numbers, no note.
    let d = scratch("fit-defaults-table");
    let runs = runs_without(&d, &["table_ball_mm"], "");
    let (t, v) = fit(&runs, &d.join("fit.json"));
    assert!(!t.contains("note: "), "{t}");
    assert_eq!(v["assumed"], serde_json::json!([]));
    assert_eq!(x_positional_um(&v), x_given);
    // One run without its tool ball: named, with the count.
    let d = scratch("fit-defaults-one");
    let runs = runs_without(&d, &["tool_ball_mm"], "xy-cw");
    let (t, v) = fit(&runs, &d.join("fit.json"));
    assert!(
        t.contains("note: tool_ball_mm is not given in run xy-cw-1 (1 of 6): taken as 0, 0, 0 mm"),
        "{t}"
    );
    assert_eq!(v["assumed"][0]["runs"], serde_json::json!(["xy-cw-1"]));
    // diagnose says it too, terminal and JSON; predict says it.
    let json = d.join("diag.json");
    let model = d.join("model.ron");
    let o = ballbar(&[
        "diagnose",
        "--machine",
        "column",
        runs.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--save-model",
        model.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("note: tool_ball_mm is not given in run xy-cw-1 (1 of 6)"),
        "{}",
        text(&o)
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["assumed"][0]["key"], "tool_ball_mm", "{v}");
    let out = d.join("predicted");
    let o = ballbar(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        runs.join("xy-cw-1.csv").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("note: tool_ball_mm is not given in run xy-cw-1 (1 of 1)"),
        "{}",
        text(&o)
    );
    // The predicted copy still leaves the key out: read again, it is still stated.
    let copy = std::fs::read_to_string(out.join("xy-cw-1.csv")).unwrap();
    assert!(!copy.contains("tool_ball_mm"), "{copy}");
}

#[test]
fn simulate_predict_and_export_replace_no_file_without_force_and_never_an_input() {
    let dir = scratch("no-overwrite");
    let runs = dir.join("runs");
    let sim = |extra: &[&str]| {
        let mut a = vec![
            "simulate",
            "--machine",
            "column",
            "--truth",
            "fixtures/column-paper/truth.ron",
            "--out",
            runs.to_str().unwrap(),
            "--seed",
            "4",
        ];
        a.extend_from_slice(extra);
        ballbar(&a)
    };
    assert!(sim(&[]).status.success());
    let run = runs.join("xy-ccw-1.csv");
    std::fs::write(&run, "the engineer's own file").unwrap();
    // A second simulation into the folder: refused before anything is written.
    let o = sim(&[]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains(
            "already exists (and 5 more of the 6 runs); nothing was written (--force replaces them)"
        ),
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::read_to_string(&run).unwrap(), "the engineer's own file");
    assert!(sim(&["--force"]).status.success());
    assert!(std::fs::read_to_string(&run).unwrap().starts_with("# ballbar-run: 1"));

    // predict into the inputs' own folder would replace the runs it reads: never, even with --force.
    let model = dir.join("model.ron");
    assert!(
        ballbar(&[
            "fit",
            "--machine",
            "column",
            runs.to_str().unwrap(),
            "--save-model",
            model.to_str().unwrap()
        ])
        .status
        .success()
    );
    let before = std::fs::read_to_string(&run).unwrap();
    let o = ballbar(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
        "--force",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("xy-ccw-1.csv: is one of the inputs; nothing was written"),
        "{}",
        text(&o)
    );
    assert_eq!(std::fs::read_to_string(&run).unwrap(), before);
    let pred = dir.join("pred");
    assert!(
        ballbar(&[
            "predict",
            "--model",
            model.to_str().unwrap(),
            run.to_str().unwrap(),
            "--out",
            pred.to_str().unwrap()
        ])
        .status
        .success()
    );
    let o = ballbar(&[
        "predict",
        "--model",
        model.to_str().unwrap(),
        run.to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("--force replaces them"), "{}", text(&o));

    // export likewise.
    let arc = dir.join("s.mcap");
    assert!(
        ballbar(&["record", runs.to_str().unwrap(), "--out", arc.to_str().unwrap()])
            .status
            .success()
    );
    let back = dir.join("back");
    std::fs::create_dir_all(&back).unwrap();
    std::fs::write(back.join("xy-cw-1.csv"), "kept").unwrap();
    let o = ballbar(&["export", arc.to_str().unwrap(), "--out", back.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(back.join("xy-cw-1.csv")).unwrap(), "kept");
    assert_eq!(std::fs::read_dir(&back).unwrap().count(), 1, "nothing half-written");
    assert!(
        ballbar(&["export", arc.to_str().unwrap(), "--out", back.to_str().unwrap(), "--force"])
            .status
            .success()
    );
    assert_eq!(std::fs::read_dir(&back).unwrap().count(), 6);
}

/// The same measurement under another name counts once or not at all: a byte-identical copy
/// of a run, and a copy whose header was changed (another run id and start) but whose times
/// and readings are the run's, are refused by every command that reads runs, naming both
/// files. Fitted twice they would shrink the uncertainties; diagnosed, pass for a repeat
/// with a noise floor of 0.
#[test]
fn the_same_samples_under_another_name_are_refused_naming_both_files() {
    let dir = scratch("same-samples");
    let original = root().join("fixtures/column-paper/runs/xy-ccw-1.csv");
    let text_of = std::fs::read_to_string(&original).unwrap();
    let copy = dir.join("copy.csv");
    std::fs::write(&copy, &text_of).unwrap();
    let renamed = dir.join("renamed.csv");
    std::fs::write(
        &renamed,
        text_of
            .replace("# run_id: xy-ccw-1", "# run_id: xy-ccw-9")
            .replace("2026-11-21T10:02:53.097Z", "2026-11-21T15:00:00Z"),
    )
    .unwrap();
    let runs = "fixtures/column-paper/runs";
    let (model, out, archive) = (dir.join("m.ron"), dir.join("out"), dir.join("a.mcap"));
    assert!(
        ballbar(&["fit", "--machine", "column", runs, "--save-model", model.to_str().unwrap()])
            .status
            .success()
    );
    for other in [&copy, &renamed] {
        let other = other.to_str().unwrap();
        for args in [
            vec!["fit", "--machine", "column", runs, other],
            vec!["diagnose", "--machine", "column", runs, other],
            vec!["predict", "--model", model.to_str().unwrap(), runs, other, "--out"],
            vec!["record", runs, other, "--out", archive.to_str().unwrap()],
        ] {
            let mut args = args;
            if args[0] == "predict" {
                args.push(out.to_str().unwrap());
            }
            let o = ballbar(&args);
            assert_eq!(o.status.code(), Some(1), "{args:?}: {}", text(&o));
            let t = text(&o);
            assert!(
                t.contains(&format!("{other}: its samples are those of "))
                    && t.contains("xy-ccw-1.csv")
                    && t.contains("the same 5655 readings at the same times"),
                "{args:?}: {t}"
            );
        }
    }
    assert!(!out.exists() && !archive.exists());
}

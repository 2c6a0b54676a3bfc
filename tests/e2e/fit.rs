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
    // (It states its arc: a run that does not say so is refused as cut short, before any fit.)
    let short: Vec<&str> = text_in.lines().take(60).collect();
    let f = dir.join("short.csv");
    std::fs::write(&f, short.join("\n").replacen("t_s,", "# arc_deg: 2.9\nt_s,", 1)).unwrap();
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
    // A row without the mark of the aliases that move it (` †[0,2]`, said below the tables).
    let row = |start: &str| {
        t.lines()
            .find(|l| l.trim_start().starts_with(start))
            .map(|l| l.split(" †[").next().unwrap_or(l))
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
    assert!(text(&o).contains("--force replaces it"), "{}", text(&o));

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

/// A shipped run with `header` lines replaced (`(from, to)`) and each sample's fields mapped
/// by `sample` (column index, value) → value, written as `name` in `dir`.
fn altered(
    dir: &std::path::Path,
    name: &str,
    header: &[(&str, &str)],
    sample: impl Fn(usize, f64) -> f64,
) -> std::path::PathBuf {
    let text =
        std::fs::read_to_string(root().join("fixtures/column-paper/runs/xy-ccw-1.csv")).unwrap();
    let mut out = String::new();
    for l in text.lines() {
        if l.starts_with('#') || l.starts_with("t_s") {
            let l = header.iter().fold(l.to_string(), |l, (a, b)| l.replace(a, b));
            out.push_str(&l);
        } else {
            let fields: Vec<String> = l
                .split(',')
                .enumerate()
                .map(|(k, v)| format!("{:.6}", sample(k, v.parse().unwrap())))
                .collect();
            out.push_str(&fields.join(","));
        }
        out.push('\n');
    }
    let f = dir.join(name);
    std::fs::write(&f, out).unwrap();
    f
}

/// What a run's data say against its own header is an error naming the file and the likely
/// cause (exit 1), by every command that reads runs: the times scaled ×2 (squareness XY moved
/// from 21.3 to 39.3 µrad at the same residual), in milliseconds (a servo mismatch of -1000
/// ms), a feed in mm/s, readings in mm under dR_um (G 0.00, every tolerance passed), an XY
/// circle labelled YZ (a 9.1 µm bar-length error), CW labelled CCW (the labels swapped), a feed
/// of 1e12. The shipped runs themselves pass without a word.
#[test]
fn metadata_that_contradicts_the_data_is_an_error_naming_the_file_and_the_cause() {
    let dir = scratch("contradicts");
    let id = |_: usize, v: f64| v;
    let cases = [
        (
            altered(&dir, "twice.csv", &[], |k, v| if k == 0 { 2.0 * v } else { v }),
            "twice.csv:5667: column t_s: the samples span 226.16 s, but the path (942.3 mm) at feed_mm_per_min 500 takes 113.0800 s: t_s and feed_mm_per_min disagree by a factor of 2.000",
        ),
        (
            altered(&dir, "ms.csv", &[], |k, v| if k == 0 { 1000.0 * v } else { v }),
            "t_s looks like milliseconds (the column is in seconds)",
        ),
        (
            altered(
                &dir,
                "mm-per-s.csv",
                &[("feed_mm_per_min: 500", "feed_mm_per_min: 8.333333")],
                id,
            ),
            "mm-per-s.csv:6: header key \"feed_mm_per_min\": the samples span 113.08 s, but the path (942.3 mm) at feed_mm_per_min 8.333333 takes 6784.8003 s: feed_mm_per_min looks like mm/s (the key is in mm/min), or t_s like minutes",
        ),
        (
            altered(&dir, "mm.csv", &[], |k, v| if k == 4 { v * 1e-3 } else { v }),
            "column dR_um: every reading lies within ±0.5 µm",
        ),
        (
            altered(&dir, "yz.csv", &[("plane: XY", "plane: YZ")], id),
            "yz.csv:13: column X_mm: 450 is 150.000 mm off the pivot's 300, but a circle in plane YZ holds X at the pivot: the path lies in XY (is the header's plane wrong?)",
        ),
        (
            altered(&dir, "cw.csv", &[("direction: CCW", "direction: CW")], id),
            "cw.csv:4: header key \"direction\": CW, but the path's angle increases by 359.94° from 0.00° (angles from +X towards +Y): the run goes CCW",
        ),
        (
            altered(&dir, "fast.csv", &[("feed_mm_per_min: 500", "feed_mm_per_min: 1e12")], id),
            "fast.csv:6: header key \"feed_mm_per_min\": 1e12 mm/min is not the feed of a ballbar test (1 to 100000 mm/min)",
        ),
    ];
    for (file, what) in &cases {
        for cmd in ["fit", "diagnose"] {
            let o = ballbar(&[cmd, "--machine", "column", file.to_str().unwrap()]);
            assert_eq!(o.status.code(), Some(1), "{cmd} {}: {}", file.display(), text(&o));
            assert!(text(&o).contains(what), "{cmd}: expected {what:?} in {}", text(&o));
        }
    }
    // A feed override of 10 %: a stated warning, and the fit goes on.
    let slow = altered(&dir, "slow.csv", &[], |k, v| if k == 0 { 1.1 * v } else { v });
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "fixtures/column-paper/runs/xy-cw-1.csv",
        slow.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("warning: ")
            && text(&o).contains("slow.csv: the samples span 124.388 s")
            && text(&o).contains("a feed override"),
        "{}",
        text(&o)
    );
    // The shipped runs: no warning.
    let o = ballbar(&["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    assert!(o.status.success() && !text(&o).contains("warning"), "{}", text(&o));
}

/// A run CSV cut short is an error that says what was kept: cut at a line end (22 of 57
/// samples of a coarse run), or inside the last number without its line end (the last
/// reading "38" for 38.0826).
#[test]
fn a_run_csv_cut_short_is_an_error_saying_what_was_kept() {
    let dir = scratch("cut-short");
    // A coarse run: every 100th sample of the shipped one, 57 samples round the circle at 2 s.
    let run =
        std::fs::read_to_string(root().join("fixtures/column-paper/runs/xy-ccw-1.csv")).unwrap();
    let header: Vec<&str> = run.lines().take(12).collect();
    let samples: Vec<&str> = run.lines().skip(12).step_by(100).collect();
    assert_eq!(samples.len(), 57);
    let whole = format!("{}\n{}\n", header.join("\n"), samples.join("\n"));
    let f = dir.join("whole.csv");
    std::fs::write(&f, &whole).unwrap();
    assert!(ballbar(&["fit", "--machine", "column", f.to_str().unwrap()]).status.success());
    // Cut at a line end: the run format allows an arc without saying so, so a header that
    // states no arc cannot tell a partial arc from a cut; said, naming what was kept. With the
    // arc stated (a full circle, 360°), the same cut is an error.
    let cut = format!("{}\n{}\n", header.join("\n"), samples[..22].join("\n"));
    std::fs::write(&f, &cut).unwrap();
    let o = ballbar(&["fit", "--machine", "column", f.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("whole.csv:34: the samples sweep 133.69° (kept: 22 samples (lines 13-34), t_s 0 to 42 s): a partial arc, or a file cut short at a line end?"),
        "{}",
        text(&o)
    );
    let stated = format!(
        "{}\n# arc_deg: 360\n{}\n{}\n",
        header[..11].join("\n"),
        header[11],
        samples[..22].join("\n")
    );
    std::fs::write(&f, &stated).unwrap();
    let o = ballbar(&["fit", "--machine", "column", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(
        text(&o).contains("whole.csv:35: the run ends early: its samples sweep 133.69° of the 360° its header states (arc_deg) (kept: 22 samples (lines 14-35), t_s 0 to 42 s, from 0.00° to 133.69°): the file was cut short"),
        "{}",
        text(&o)
    );
    // Cut inside the last number of the 23rd sample.
    let last = samples[22];
    let at = last.rfind('.').unwrap();
    let inside = format!("{}\n{}\n{}", header.join("\n"), samples[..22].join("\n"), &last[..at]);
    std::fs::write(&f, &inside).unwrap();
    let o = ballbar(&["fit", "--machine", "column", f.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let reading = &last[last.rfind(',').unwrap() + 1..at];
    assert!(
        text(&o).contains(&format!("whole.csv:35: the last line has no line end and its dR_um \"{reading}\" has fewer digits than the line before's"))
            && text(&o).contains("the file looks cut inside a number (kept: 23 samples (lines 13-35)"),
        "{}",
        text(&o)
    );
}

/// Absurd values in a truth file or a table's set-up are refused, not simulated or imported: a
/// noise of 1e300 µm, a sample rate or a start angle of 1e±300, a feed of 1e12.
#[test]
fn absurd_values_of_a_truth_file_or_a_tables_set_up_are_refused() {
    let dir = scratch("absurd");
    let truth = std::fs::read_to_string(root().join("fixtures/column-paper/truth.ron")).unwrap();
    for (from, to, what) in [
        ("noise_um: 0.2,", "noise_um: 1e300,", "noise_um 1e300 µm is beyond a ballbar's noise"),
        (
            "sample_rate_hz: 50.0,",
            "sample_rate_hz: 1e300,",
            "sample_rate_hz 1e300 Hz is not a ballbar's sample rate",
        ),
        (
            "sample_rate_hz: 50.0,",
            "sample_rate_hz: 1e-300,",
            "sample_rate_hz 1e-300 Hz is not a ballbar's sample rate",
        ),
        (
            "radius_mm: 150.0, feed_mm_per_min: 500.0",
            "radius_mm: 150.0, feed_mm_per_min: 1e12",
            "feed_mm_per_min 1e12 mm/min is beyond a ballbar test's (1 to 100000 mm/min)",
        ),
    ] {
        assert!(truth.contains(from), "{from}");
        let t = dir.join("t.ron");
        std::fs::write(&t, truth.replacen(from, to, 1)).unwrap();
        let out = dir.join("runs");
        let o = ballbar(&[
            "simulate",
            "--machine",
            "column",
            "--truth",
            t.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_eq!(o.status.code(), Some(1), "{to}: {}", text(&o));
        assert!(text(&o).contains(what), "{}", text(&o));
        assert!(!out.exists());
    }
    let table = dir.join("readings.csv");
    std::fs::write(&table, "dR_um\n1.5\n2.5\n-3.5\n").unwrap();
    for (option, value, what) in [
        (
            "--sample-rate-hz",
            "1e300",
            "sample_rate_hz: 1e300 Hz is not a ballbar's sample rate (1 to 100000 Hz)",
        ),
        ("--sample-rate-hz", "1e-300", "sample_rate_hz: 1e-300 Hz is not a ballbar's sample rate"),
        (
            "--start-angle-deg",
            "1e300",
            "start_angle_deg: 1e300° is more than a turn (360°) either way",
        ),
    ] {
        let mut args = vec![
            "import",
            table.to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
            "--plane",
            "XY",
            "--direction",
            "CCW",
            "--radius-mm",
            "100",
            "--feed",
            "1000",
            "--started-at",
            "2026-11-21T10:00:00Z",
            "--arc-deg",
            "0.1",
        ];
        let (rate, angle) = ("--sample-rate-hz", "--start-angle-deg");
        for (o, v) in [(rate, "125"), (angle, "0")] {
            if o != option {
                args.extend([o, v]);
            }
        }
        args.extend([option, value]);
        let o = ballbar(&args);
        assert_eq!(o.status.code(), Some(1), "{option} {value}: {}", text(&o));
        assert!(text(&o).contains(what), "{}", text(&o));
    }
}

#[test]
fn no_progress_bar_is_drawn_when_standard_error_is_not_a_terminal() {
    // Here standard error is a pipe: the bar, which `fit` and `diagnose` draw on a terminal
    // from their first report on, must leave no trace (no carriage return, no erase, no step).
    for cmd in ["fit", "diagnose"] {
        let o = ballbar(&[cmd, "--machine", "column", "fixtures/column-paper/runs"]);
        assert!(o.status.success(), "{}", text(&o));
        let err = String::from_utf8_lossy(&o.stderr);
        for trace in ["\r", "\x1b[K", "factoring the runs", "screening", "%, about"] {
            assert!(!err.contains(trace), "{cmd}: {trace:?} on standard error: {err}");
        }
    }
}

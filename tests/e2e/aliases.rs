//! What a test determines and what it cannot tell: `fit` and `diagnose` on the shared real
//! file with the set-up metadata a user may give blindly (`--pivot`, `--tool-ball-mm`).

use std::path::{Path, PathBuf};

use crate::common::*;

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The shared real file, if present (`shared/data/real`, beside the repository).
fn real_file() -> Option<PathBuf> {
    let p = root().join("../shared/data/real/d2-xy-50mm-1500.b5r");
    if p.is_file() {
        Some(p)
    } else {
        skip(
            Needs::SharedData,
            &format!("{} is not there (the shared real test file)", p.display()),
        );
        None
    }
}

/// `(value, u)` of the local quantity `name` of the document's one test.
fn local(doc: &serde_json::Value, name: &str) -> (f64, f64) {
    let l = doc["local"]
        .as_array()
        .unwrap()
        .iter()
        .find(|l| l["name"] == name)
        .unwrap_or_else(|| panic!("no {name} in local"));
    (l["estimate"]["value"].as_f64().unwrap(), l["estimate"]["std_uncertainty"].as_f64().unwrap())
}

#[test]
fn the_real_files_local_values_do_not_move_with_the_pivot_and_its_squareness_says_it_does() {
    let Some(file) = real_file() else { return };
    let dir = scratch("aliases-real");
    let fit = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = dir.join(format!("{name}.json"));
        let mut args = vec!["fit", "--machine", "column", file.to_str().unwrap()];
        args.extend(extra);
        args.extend(["--json", out.to_str().unwrap()]);
        let o = ballbar(&args);
        assert!(o.status.success(), "{name}: {}", text(&o));
        json(&out)
    };
    let base = fit("default", &[]);
    let sq = |d: &serde_json::Value| {
        d["parameters"].as_array().unwrap().iter().find(|p| p["id"] == "SQXY").unwrap().clone()
    };
    // The local squareness is the global one at the default pivot (0, 0, 0), where the
    // polynomials' origin is the circle's: -3.1 µrad (issue's measurement) within 0.1 µrad.
    let (sq0, u0) = local(&base, "local squareness XY");
    assert!((sq0 + 3.1).abs() < 0.1 && (sq0 - sq(&base)["value"].as_f64().unwrap()).abs() < 0.05);
    // The scales are reported on one plane: the vendor-like local scale of Y is the 17.4 ppm
    // the issue measured.
    let (sy0, _) = local(&base, "local scale Y");
    assert!((sy0 - 17.4).abs() < 0.1, "{sy0}");
    // The vendor comparison compares what the test determines: its squareness and scales are
    // the local values (µrad = µm/m, ratio in ppm), whatever pivot and tool length are given.
    let vendor_ours = |d: &serde_json::Value, feature: &str| -> (f64, f64) {
        let e = d["vendor_comparison"]
            .as_array()
            .unwrap()
            .iter()
            .find(|e| e["feature"] == feature && e.get("run").is_none())
            .unwrap_or_else(|| panic!("no {feature}"));
        (e["ours"].as_f64().unwrap(), e["ours_u"].as_f64().unwrap())
    };
    let vendor_features = [
        ("AF_SQUARENESS", "local squareness XY"),
        ("AF_SCALE_ERROR_A", "local scale X"),
        ("AF_SCALE_ERROR_B", "local scale Y"),
    ];
    for (feature, name) in vendor_features {
        let (ours, _) = vendor_ours(&base, feature);
        let (v, u) = local(&base, name);
        assert!((ours - v).abs() < 1e-6 * u.max(1.0), "{feature} {ours} against {name} {v}");
    }
    // The mismatch by hand from the two local scales: (s_X − s_Y) · 2R, ppm × mm × 1e-3 = µm.
    let (mismatch, _) = vendor_ours(&base, "AF_SCALE_MISMATCH");
    let hand =
        (local(&base, "local scale X").0 - local(&base, "local scale Y").0) * 2.0 * 50.0 * 1e-3;
    assert!((mismatch - hand).abs() < 1e-3, "AF_SCALE_MISMATCH {mismatch} against {hand}");
    for pivot in ["300,200,-300", "-400,150,-200"] {
        let d = fit(&format!("pivot{pivot}"), &["--pivot", pivot]);
        for (feature, _) in
            vendor_features.iter().chain(&[("AF_GLOBAL_SCALE", ""), ("AF_SCALE_MISMATCH", "")])
        {
            let ((v0, u), (v1, _)) = (vendor_ours(&base, feature), vendor_ours(&d, feature));
            assert!(
                (v1 - v0).abs() < 0.1 * u,
                "--pivot {pivot}: vendor's {feature} ours {v0} → {v1} (u {u})"
            );
        }
        // Determined: the same within a tenth of u (the readings are the same; measured
        // within 0.06 u: the exact chain's second order, which the local values take in).
        for name in ["local scale X", "local scale Y", "local squareness XY"] {
            let (v0, u) = local(&base, name);
            let (v1, _) = local(&d, name);
            assert!((v1 - v0).abs() < 0.1 * u, "--pivot {pivot}: {name} {v0} → {v1} (u {u})");
        }
        // Not determined: the global squareness moves by hundreds of µrad and says so, in the
        // document a compensation writer reads: conditional on the pivot's aliases, each with
        // its sensitivity per 100 mm, which explains the move to within its own linearity.
        let p = sq(&d);
        let v = p["value"].as_f64().unwrap();
        assert!((v - sq0).abs() > 100.0 * u0, "--pivot {pivot}: SQXY {v}");
        let aliases = d["aliases"].as_array().unwrap();
        let on: Vec<&serde_json::Value> = p["conditional_on_aliases"]
            .as_array()
            .unwrap()
            .iter()
            .map(|k| &aliases[k.as_u64().unwrap() as usize])
            .collect();
        let pivots: Vec<&&serde_json::Value> = on.iter().filter(|a| a["kind"] == "pivot").collect();
        assert!(pivots.len() >= 2, "--pivot {pivot}: SQXY not flagged with X and Y: {on:?}");
        for a in pivots {
            let m = a["moves"].as_array().unwrap().iter().find(|m| m["quantity"] == "SQXY");
            assert!(m.is_some_and(|m| m["per_100_mm"].as_f64().is_some()), "{a}");
        }
    }
    // A tool length given (on one plane the tool's Abbe terms alias with the scales): the
    // local scales are still reported, and the same.
    let d = fit("tool", &["--tool-ball-mm", "0,0,-120"]);
    for (feature, _) in vendor_features {
        let ((v0, u), (v1, _)) = (vendor_ours(&base, feature), vendor_ours(&d, feature));
        assert!((v1 - v0).abs() < 0.1 * u, "tool: vendor's {feature} ours {v0} → {v1} (u {u})");
    }
    for name in ["local scale X", "local scale Y", "local squareness XY"] {
        let (v0, u) = local(&base, name);
        let (v1, _) = local(&d, name);
        assert!((v1 - v0).abs() < 0.1 * u, "tool: {name} {v0} → {v1} (u {u})");
    }
    let text_out = {
        let o = ballbar(&[
            "fit",
            "--machine",
            "column",
            file.to_str().unwrap(),
            "--pivot",
            "300,200,-300",
        ]);
        text(&o)
    };
    assert!(
        text_out.contains("local squareness XY") && text_out.contains("per 100 mm"),
        "{text_out}"
    );
}

#[test]
fn diagnose_lists_the_base_fits_aliases_with_what_they_move() {
    let Some(file) = real_file() else { return };
    let dir = scratch("aliases-diagnose");
    let out = dir.join("d.json");
    let o = ballbar(&[
        "diagnose",
        "--machine",
        "column",
        file.to_str().unwrap(),
        "--pivot",
        "300,200,-300",
        "--json",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let d = json(&out);
    let aliased = d["aliased"].as_array().unwrap();
    let pivot = aliased
        .iter()
        .find(|a| a["kind"] == "pivot" && a["axis"] == "X")
        .unwrap_or_else(|| panic!("no pivot alias in {aliased:?}"));
    assert!(pivot["moves"].as_array().unwrap().iter().any(|m| m["quantity"] == "SQXY"), "{pivot}");
    assert!(!pivot["test_to_separate"].as_str().unwrap().is_empty());
}

#[test]
fn a_quadratic_pitch_at_one_centre_is_named_with_the_squareness_it_leaves_if_it_holds() {
    // The simulator's machine: squareness XY 40 µrad and a quadratic positional error of X
    // (3 µm at ±150 mm: 8.33 µm at L = 250 mm), three planes at one centre. The base has no
    // such term and takes it for straightness of X's neighbours and a squareness ZX it does
    // not have; the fit must name the alias, and its alternative must give back ZX = 0.
    let dir = scratch("aliases-pitch");
    let truth = dir.join("truth.ron");
    let test = |plane: &str| {
        format!(
            "(plane: {plane}, directions: [CW, CCW], radius_mm: 150.0, feed_mm_per_min: 1000.0, pivot_mm: (0.0, 0.0, 0.0), tool_ball_mm: (0.0, 0.0, -100.0))"
        )
    };
    std::fs::write(
        &truth,
        format!(
            "(servo: AxisLag, errors: {{\"SQXY\": 40.0}}, effects: [(effect: PositionalHigherOrder(axis: X, degree: 2), value: {})], centring_sd_um: 3.0, noise_um: 0.1, sample_rate_hz: 50.0, started_at: \"2026-11-21T10:00:00Z\", pause_s: 60.0, tests: [{}, {}, {}])",
            3.0 * (250.0f64 / 150.0).powi(2),
            test("XY"),
            test("YZ"),
            test("ZX")
        ),
    )
    .unwrap();
    let runs = dir.join("runs");
    let o = ballbar(&[
        "simulate",
        "--machine",
        "column",
        "--truth",
        truth.to_str().unwrap(),
        "--out",
        runs.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.join("fit.json");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        runs.to_str().unwrap(),
        "--json",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let d = json(&out);
    let p = d["parameters"].as_array().unwrap().iter().find(|p| p["id"] == "SQZX").unwrap().clone();
    let (v, u) = (p["value"].as_f64().unwrap(), p["std_uncertainty"].as_f64().unwrap());
    // The silent answer: a squareness ZX far beyond its u where the machine has none.
    assert!(v.abs() > 20.0 * u, "SQZX {v} ± {u}");
    let aliases = d["aliases"].as_array().unwrap();
    let k = aliases
        .iter()
        .position(|a| a["kind"] == "positional_higher_order" && a["axis"] == "X")
        .unwrap_or_else(|| panic!("the pitch curvature of X not named: {aliases:?}"));
    assert!(p["conditional_on_aliases"].as_array().unwrap().contains(&serde_json::json!(k)));
    let m =
        aliases[k]["moves"].as_array().unwrap().iter().find(|m| m["quantity"] == "SQZX").unwrap();
    // Its alternative: ZX = 0 within three of the fit's own u (noise only: the simulated
    // machine has no straightness for the base to keep), and the u with the alias spans it.
    let alt = m["alternative"].as_f64().unwrap();
    assert!(alt.abs() < 3.0 * u, "alternative {alt} ± {u}");
    assert!(m["std_uncertainty_with_alias"].as_f64().unwrap() >= 0.5 * (v - alt).abs());
    assert!(!aliases[k]["test_to_separate"].as_str().unwrap().is_empty());
    // The local squareness ZX is the determined one: 0 within 3 u; SQXY's local value 40.
    let (l, lu) = local(&d, "local squareness ZX");
    assert!(l.abs() < 3.0 * lu, "local squareness ZX {l} ± {lu}");
    let (l, lu) = local(&d, "local squareness XY");
    assert!((l - 40.0).abs() < 3.0 * lu, "local squareness XY {l} ± {lu}");
}

//! `diagnose` on the shipped data: the JSON contract of shared/spec/cli.md, and the saved model
//! with the accepted effect replayed by `predict`.

use crate::common::*;

/// RMS (µm) of measured minus predicted over an XY run file written by `predict`, after removing
/// the least-squares circle centre and radius (the run's centring and mean are not part of
/// either model's prediction). A 3×3 solve of well-conditioned columns (1, cos θ, sin θ over a
/// full circle): test arithmetic, not the project's estimator.
fn rms_about_circle(path: &std::path::Path) -> f64 {
    let text = std::fs::read_to_string(path).unwrap();
    let pivot: Vec<f64> = text.lines().find(|l| l.starts_with("# pivot_mm:")).unwrap()[11..]
        .split(',')
        .map(|x| x.trim().parse().unwrap())
        .collect();
    let mut rows = Vec::new();
    for l in text.lines().filter(|l| !l.starts_with('#') && !l.starts_with("t_s")) {
        let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        let th = (f[2] - pivot[1]).atan2(f[1] - pivot[0]);
        rows.push(([1.0, th.cos(), th.sin()], f[4] - f[5]));
    }
    let mut m = [[0.0; 3]; 3];
    let mut v = [0.0; 3];
    for (x, y) in &rows {
        for i in 0..3 {
            v[i] += x[i] * y;
            for j in 0..3 {
                m[i][j] += x[i] * x[j];
            }
        }
    }
    // Gaussian elimination.
    for c in 0..3 {
        for r in c + 1..3 {
            let f = m[r][c] / m[c][c];
            for k in c..3 {
                m[r][k] -= f * m[c][k];
            }
            v[r] -= f * v[c];
        }
    }
    let mut b = [0.0; 3];
    for c in (0..3).rev() {
        b[c] = (v[c] - (c + 1..3).map(|k| m[c][k] * b[k]).sum::<f64>()) / m[c][c];
    }
    let ss: f64 =
        rows.iter().map(|(x, y)| (y - (0..3).map(|i| x[i] * b[i]).sum::<f64>()).powi(2)).sum();
    (ss / rows.len() as f64).sqrt()
}

#[test]
fn diagnose_finds_the_papers_inconsistent_servo_terms_and_its_saved_model_replays_them() {
    let dir = scratch("diagnose");
    let json = dir.join("d.json");
    let with = dir.join("with.ron");
    let base = dir.join("base.ron");
    // The paper's three plane servo mismatches (8.1, -2.0, 3.7 µm) do not sum to zero, so one
    // lag per axis cannot make them: the default model leaves a direction-odd gap.
    let o = ballbar(&[
        "diagnose",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--json",
        json.to_str().unwrap(),
        "--save-model",
        with.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["format"], "ballbar-diagnosis/1");
    assert_eq!(v["machine"], "column");
    let gap = &v["gap"];
    assert!(
        gap["base_rms_um"].as_f64().unwrap() > 1.0
            && (gap["noise_floor_um"].as_f64().unwrap() - 0.2).abs() < 0.02,
        "{gap}"
    );
    let w = gap["where"].as_array().unwrap();
    assert!(!w.is_empty());
    for item in w {
        assert!(
            item["plane"].is_string()
                && item["direction"].is_string()
                && item["sector_deg"].as_array().unwrap().len() == 2
                && item["share"].is_number()
        );
    }
    let effects = v["effects"].as_array().unwrap();
    assert_eq!(effects.len(), 1, "{effects:?}");
    let e = &effects[0];
    assert_eq!(e["kind"], "servo_mismatch");
    // The lags take the differences between planes; what is left is the sum of the three plane
    // terms, 8.1 - 2.0 + 3.7 = 9.8 µm, in whichever plane carries it (0.2 µm noise on 34k
    // samples: 0.1 µm is many standard uncertainties).
    let value = e["parameters"]["value_um"].as_f64().unwrap();
    assert!((value.abs() - 9.8).abs() < 0.1, "{value}");
    assert!(e["note"].as_str().unwrap().contains("sum M_XY + M_YZ + M_ZX"), "{e}");
    let (before, after) = (
        e["held_out_rms_before_um"].as_f64().unwrap(),
        e["held_out_rms_after_um"].as_f64().unwrap(),
    );
    assert!(after < before && (after - 0.2).abs() < 0.03, "{before} → {after}");
    // ISO 230-4 G of the held-out halves: the 45° ellipses of the gap (±2.3 µm) are gone, what
    // is left is the peak-to-valley of 0.2 µm white noise over ~2,800 samples (about 7σ).
    let (gb, ga) =
        (e["held_out_g_before_um"].as_f64().unwrap(), e["held_out_g_after_um"].as_f64().unwrap());
    assert!(gb > 3.0 && ga < 1.8 && ga > 0.8, "G {gb} → {ga}");
    for a in v["aliased"].as_array().unwrap() {
        assert!(
            a["kind"].is_string() && a["with"].is_array() && a["test_to_separate"].is_string(),
            "{a}"
        );
    }

    // predict with the diagnosis's model follows the measurement to the noise; with the base
    // fit's model it leaves the gap.
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--save-model",
        base.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for (model, lo, hi) in [(&with, 0.0, 0.3), (&base, 0.8, 2.0)] {
        let out = dir.join(model.file_stem().unwrap());
        let o = ballbar(&[
            "predict",
            "--model",
            model.to_str().unwrap(),
            "fixtures/column-paper/runs/xy-ccw-1.csv",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let r = rms_about_circle(&out.join("xy-ccw-1.csv"));
        assert!(r > lo && r < hi, "{}: {r} µm", model.display());
    }
}

/// The diagnosis's labels read without a manual. On the shipped column runs (one
/// `diagnose --json -`: the JSON on standard output, the text on standard error):
/// - its F statistic is a partial-F in three significant digits, explained as not ISO
///   230-4's F (never a bare `F 1108678`), in the declined list too;
/// - the plane term beside per-axis lags is named the sum of the three planes' terms (not
///   `servo mismatch ZX (independent plane term)`) in the text and the JSON;
/// - the effect's value has its unit and its uncertainty (not a bare `value_um 9.806`);
/// - the noise line and the gap's figures say what they are (no bare `inflation 1.0`,
///   `direction-odd`, `order per revolution`);
/// - the help of `diagnose --json` says it writes the diagnosis, `fit --json` the fit.
#[test]
fn the_diagnosis_names_its_statistics_and_the_sum_of_the_plane_terms() {
    let o =
        ballbar(&["diagnose", "--machine", "column", "fixtures/column-paper/runs", "--json", "-"]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {}", text(&o)));
    let t = String::from_utf8_lossy(&o.stderr).to_string();
    // The accepted effect's statistic, and the legend.
    let f = v["effects"][0]["f_statistic"].as_f64().unwrap();
    assert!(f > 1e5, "{f}");
    assert!(t.contains(&format!("partial-F {f:.2e}")), "{t}");
    assert!(!t.contains(&format!("F {f:.0}")), "{t}");
    assert!(t.contains("(partial-F: the variance an effect explains on all the data over the noise's, a test statistic, not ISO 230-4's F;"), "{t}");
    let declined = t
        .lines()
        .skip_while(|l| !l.starts_with("Tried and declined"))
        .skip(1)
        .take_while(|l| !l.is_empty())
        .collect::<Vec<_>>();
    assert!(!declined.is_empty() && declined.iter().all(|l| !l.contains(": F ")), "{declined:?}");
    assert!(
        declined
            .iter()
            .any(|l| l.contains("partial-F") && l.contains("(its 1e-6 false-alarm level)")),
        "{declined:?}"
    );
    // The sum of the three planes, named so in the text and in the JSON's description.
    let e = &v["effects"][0];
    assert_eq!(e["kind"], "servo_mismatch");
    let name = e["description"].as_str().unwrap();
    assert!(name.starts_with("servo mismatch beyond the per-axis lags: the sum M_XY + M_YZ + M_ZX of the three planes' terms"), "{name}");
    assert!(!name.contains("independent plane term"), "{name}");
    // Value ± u with its unit (the u is its coefficient's, to two significant digits).
    let (value, u) = (
        e["parameters"]["value_um"].as_f64().unwrap(),
        e["std_uncertainties"]["value_um"].as_f64().unwrap(),
    );
    assert!(u > 0.0 && u < 0.1, "{u}");
    // Two significant digits of u: the decimal places 1 - floor(log10 u).
    let d = (1 - u.log10().floor() as i32) as usize;
    assert!(
        t.contains(&format!("{name}: {value:.d$} ± {u:.d$} µm")),
        "{name}: {value} ± {u} in {t}"
    );
    assert!(!t.contains("value_um"), "{t}");
    // Other labels.
    for old in
        ["inflation 1.0", "direction-odd", "order per revolution", "held-out t ", "±2 jackknife SE"]
    {
        assert!(!t.contains(old), "'{old}' in {t}");
    }
    assert!(
        t.contains("RMS of the CW/CCW mean (the same in both directions)")
            && t.contains("of their half-difference (reversing with the direction)"),
        "{t}"
    );
    // Each command's help says what its JSON is.
    let help = |cmd: &str| text(&ballbar(&[cmd, "--help"]));
    let (d, f) = (help("diagnose"), help("fit"));
    assert!(
        d.contains("Write the diagnosis as JSON to FILE (format ballbar-diagnosis/1")
            && !d.contains("Write the fit"),
        "{d}"
    );
    assert!(
        f.contains("Write the fit as JSON to FILE (format ballbar-fit/1")
            && !f.contains("for diagnose: the diagnosis"),
        "{f}"
    );
}

/// The gap an engineer means, on the shipped column runs (`diagnose --json -`): the excess of
/// an RMS above the noise floor, `sqrt(r² − f²)`, and the share of it an effect closes,
/// `1 − excess(after)/excess(before)`, computed here from the JSON's own figures: each effect's
/// `held_out_excess_closed` from its held-out RMS before and after and `gap.noise_floor_um`,
/// `held_out.excess_closed` from its own, `gap.excess_um` from `gap.base_rms_um`; the text
/// states each in the one wording, with its interval (k = 1) and the floor's standard
/// uncertainty, and no share of a bare "gap" is left in it.
#[test]
fn the_share_closed_is_of_the_excess_above_the_noise_in_the_json_and_the_text() {
    let o =
        ballbar(&["diagnose", "--machine", "column", "fixtures/column-paper/runs", "--json", "-"]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {}", text(&o)));
    let t = String::from_utf8_lossy(&o.stderr).to_string();
    let num = |x: &serde_json::Value| x.as_f64().unwrap_or_else(|| panic!("not a number: {x}"));
    let excess = |r: f64, f: f64| (r * r - f * f).max(0.0).sqrt();
    // The JSON carries full f64 values and the formula is a handful of operations on them:
    // agreement to 1e-12 (relative to shares of order 1) leaves only rounding.
    let floor = num(&v["gap"]["noise_floor_um"]);
    let base = num(&v["gap"]["base_rms_um"]);
    assert!(floor > 0.0 && base > floor, "{floor} {base}");
    assert!((num(&v["gap"]["excess_um"]) - excess(base, floor)).abs() < 1e-12, "{}", v["gap"]);
    // The floor's standard uncertainty and its blocks, said in the text as in the JSON.
    let floor_u = num(&v["gap"]["noise_floor_u_um"]);
    let blocks = v["gap"]["noise_floor_blocks"].as_u64().unwrap();
    assert!(floor_u > 0.0 && floor_u < 0.05 * floor && blocks >= 2, "{}", v["gap"]);
    let two = |u: f64| {
        let decimals = (1 - u.log10().floor() as i32).max(0) as usize;
        format!("{u:.decimals$}")
    };
    assert!(
        t.contains(&format!(
            "noise floor {floor:.3} ± {} µm (u, k = 1: its spread with each of {blocks} blocks of its data left out in turn, {} degrees of freedom)",
            two(floor_u),
            blocks - 1
        )),
        "{t}"
    );
    // A share the held-out excess determines (the servo terms', far above the floor) carries
    // its interval, which holds it.
    let interval = |x: &serde_json::Value| {
        assert_eq!(x["determined"], true, "{x}");
        let i = [num(&x["interval"][0]), num(&x["interval"][1])];
        assert!(i[0] <= i[1] && i[1] <= 1.0, "{x}");
        i
    };
    let effects = v["effects"].as_array().unwrap();
    assert!(!effects.is_empty(), "the paper's servo terms are named: {t}");
    for e in effects {
        let (b, a) = (num(&e["held_out_rms_before_um"]), num(&e["held_out_rms_after_um"]));
        let closed = 1.0 - excess(a, floor) / excess(b, floor);
        assert!((num(&e["held_out_excess_closed"]) - closed).abs() < 1e-12, "{e}");
        let i = interval(&e["held_out_excess"]);
        assert!(i[0] <= closed + 1e-12 && closed <= i[1] + 1e-12, "{e}");
        assert!((num(&e["held_out_excess"]["excess_before_um"]) - excess(b, floor)).abs() < 1e-12);
        // The raw shrink is kept beside it, and is a different figure.
        assert!((num(&e["shrink"]) - (1.0 - a / b)).abs() < 1e-12, "{e}");
        let said = format!(
            "closes {:.0} % ({:.0}-{:.0} %, k = 1) of the excess above the noise (held-out RMS {b:.3} → {a:.3} µm, noise floor {floor:.3} ± {} µm)",
            100.0 * closed,
            100.0 * i[0],
            100.0 * i[1],
            two(floor_u)
        );
        assert!(t.contains(&said), "'{said}' in {t}");
    }
    let h = &v["held_out"];
    let (b, a, f) = (num(&h["rms_before_um"]), num(&h["rms_after_um"]), num(&h["noise_floor_um"]));
    let closed = 1.0 - excess(a, f) / excess(b, f);
    assert!((num(&h["excess_closed"]) - closed).abs() < 1e-12, "{h}");
    let i = interval(&h["excess"]);
    assert!(
        t.contains(&format!(
            ": closes {:.0} % ({:.0}-{:.0} %, k = 1) of the excess above the noise (held-out RMS {b:.3} → {a:.3} µm, noise floor {f:.3} ± {} µm)",
            100.0 * closed,
            100.0 * i[0],
            100.0 * i[1],
            two(num(&h["noise_floor_u_um"]))
        )),
        "{t}"
    );
    // How a change of the runs' mean radius was treated: a candidate of its own, its status
    // among the effects named, declined or aliased, in the JSON and the text alike.
    let rr = &v["run_radius"];
    assert_eq!(rr["treatment"], "candidate", "{rr}");
    let named = effects.iter().any(|e| e["kind"] == "bar_length_drift");
    let status = rr["status"].as_str().unwrap();
    assert_eq!(named, status == "named", "{rr}");
    assert!(["named", "declined", "aliased", "not_tried"].contains(&status), "{rr}");
    assert!(t.contains(&format!("the runs' mean radius: {}", rr["description"].as_str().unwrap())));
    for old in ["of the gap closed", "% closed;", "held-out gap"] {
        assert!(!t.contains(old), "'{old}' in {t}");
    }
    // A near miss, where there is one, says its share on the same scale: the JSON's energy
    // share converted, 1 − sqrt(1 − share).
    for d in v["declined"].as_array().unwrap() {
        if d["why"]["test"] == "material" {
            let share = num(&d["why"]["share_of_excess"]);
            let closed = 1.0 - (1.0 - share).max(0.0).sqrt();
            assert!((num(&d["why"]["excess_closed"]) - closed).abs() < 1e-12, "{d}");
        }
    }
}

/// The report page of the same diagnosis: the statistic is a partial-F, and the gap's shares
/// are percentages as on the terminal (16.7 %, not `0.167`).
#[test]
fn the_report_of_the_diagnosis_says_partial_f_and_shares_in_percent() {
    let dir = scratch("diagnose-report");
    let o = ballbar(&[
        "report",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let h = std::fs::read_to_string(dir.join("index.html")).unwrap();
    let section = &h[h.find("<section id=\"diagnosis\">").unwrap()..];
    let section = &section[..section.find("</section>").unwrap()];
    assert!(section.contains("<th>partial-F</th>") && !section.contains("<th>F</th>"), "{section}");
    assert!(section.contains("not ISO 230-4's radial deviation F"), "{section}");
    // The effect in shop-floor words above the statistics, the same sentence as the terminal's.
    let o = ballbar(&["diagnose", "--machine", "column", "fixtures/column-paper/runs"]);
    let sentence = text(&o)
        .lines()
        .find_map(|l| l.trim_start().strip_prefix("▸ ").map(str::to_string))
        .expect("a shop-floor line in the terminal");
    assert!(sentence.contains("Match the axes' position-loop gains (kv)"), "{sentence}");
    let actions = &section[section.find("<ol id=\"actions\">").expect("the actions list")..];
    assert!(actions.contains(&format!("<li>{}</li>", sentence)), "{actions}");
    // Six planes and directions at one sixth each: one pattern, one row.
    let table = &section[section.find("<table id=\"where\"").unwrap()..];
    let table = &table[..table.find("</table>").unwrap()];
    assert_eq!(table.matches("<tr>").count(), 2, "{table}");
    assert!(
        table.contains("<td>XY, YZ, ZX; CW and CCW</td><td>the whole circle</td>")
            && table.contains(">16.7 % each, 100.0 % together</td>"),
        "{table}"
    );
    assert!(!table.contains(">0.167<"), "{table}");
    assert!(
        section.contains("servo mismatch beyond the per-axis lags: the sum M_XY + M_YZ + M_ZX"),
        "{section}"
    );
}

/// The drift over the session and a run's closure, as `diagnose` states them: `(the terminal's
/// drift line, gap.trend of the JSON)`.
fn drift_of(inputs: &[&str]) -> (String, serde_json::Value) {
    let mut args = vec!["diagnose", "--machine", "column", "--json", "-"];
    args.extend_from_slice(inputs);
    let o = ballbar(&args);
    assert!(o.status.success(), "{}", text(&o));
    let line = String::from_utf8_lossy(&o.stderr)
        .lines()
        .find(|l| l.contains("drift over the session"))
        .expect("a drift line")
        .to_string();
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    (line, v["gap"]["trend"].clone())
}

/// A drift needs a test run again later: without a repeat, the run means differ by plane and
/// direction as much as by time, and two points fit any line. The shared real file (one XY
/// circle CCW then CW, two minutes, both starting and ending at X's reversal) gave "+27.92
/// µm/h" from the two runs' means; the shipped fixture (six tests, once each) a figure too.
/// Neither is printed now: the line says why, the JSON holds `null` and says why too. The
/// closure of the runs, which the data do measure, comes with its standard uncertainty.
#[test]
fn no_drift_figure_without_a_repeated_test_and_the_closure_with_its_uncertainty() {
    let real = root().join("../shared/data/real/d2-xy-50mm-1500.b5r");
    let mut cases = vec![vec!["fixtures/column-paper/runs".to_string()]];
    if real.is_file() {
        cases.push(vec![real.to_string_lossy().into_owned()]);
    } else {
        skip(
            Needs::SharedData,
            &format!("{} is not there (the shared real test file)", real.display()),
        );
    }
    for inputs in cases {
        let args: Vec<&str> = inputs.iter().map(String::as_str).collect();
        let (line, trend) = drift_of(&args);
        assert!(!line.contains("µm/h"), "{inputs:?}: {line}");
        assert!(line.contains("drift over the session: not determined"), "{line}");
        assert!(line.contains("no test is repeated"), "{line}");
        assert!(trend["slope_um_per_h"].is_null(), "{trend}");
        assert!(trend["slope_std_uncertainty_um_per_h"].is_null(), "{trend}");
        assert!(trend["note"].as_str().unwrap().contains("no test is repeated"), "{trend}");
        // The closure: a number with a positive uncertainty, on the line as value ± u.
        let (c, u) = (
            trend["closure_um"].as_f64().unwrap(),
            trend["closure_std_uncertainty_um"].as_f64().unwrap(),
        );
        assert!(c.is_finite() && u > 0.0, "{trend}");
        assert!(line.contains(&format!("{c:+.3} ± {u:.3} µm")), "{line} / {trend}");
    }
}

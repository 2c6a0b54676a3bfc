//! The HTML report (issue #6) through the binary: its sections and numbers against the
//! archive's, the page in a real headless browser, trends over a folder of archives.

use std::path::Path;

use crate::common::*;

const RUNS: &str = "fixtures/column-paper/runs";

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "exit {:?}: {}", o.status.code(), text(o));
}

/// The `data-v` numbers of the `<tr …{key}="{value}"…>` row of a page.
fn row_numbers(html: &str, key: &str, value: &str) -> Vec<f64> {
    let tag = format!("<tr {key}=\"{value}\"");
    let i = html.find(&tag).unwrap_or_else(|| panic!("no row {tag}"));
    let row = &html[i..i + html[i..].find("</tr>").unwrap()];
    row.split("data-v=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect()
}

fn same(a: f64, b: f64) -> bool {
    // The page is the refit, which reproduces the archive to 1e-12 relative (replay's bound).
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// Record a diagnosis of the shipped runs and report it.
fn diagnosed_report(name: &str) -> (std::path::PathBuf, String, ballbar_archive::Session) {
    let d = scratch(name);
    let arc = d.join("s.mcap");
    ok(&ballbar(&["diagnose", "--machine", "column", RUNS, "--record", arc.to_str().unwrap()]));
    let out = d.join("report");
    ok(&ballbar(&["report", arc.to_str().unwrap(), "--out", out.to_str().unwrap()]));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let session = ballbar_archive::read(&arc).unwrap();
    (out, html, session)
}

#[test]
fn the_report_has_every_section_and_the_archives_numbers() {
    let (_, html, s) = diagnosed_report("report-numbers");
    for id in ["summary", "polar", "parameters", "iso", "diagnosis"] {
        assert!(html.contains(&format!("<section id=\"{id}\">")), "section {id}");
    }
    assert!(html.contains("identical to the archived fit"));
    // Every estimable machine parameter: value and uncertainty equal the archived fit's.
    let fit = s.fit.as_ref().unwrap();
    let mut checked = 0;
    for p in fit.parameters.iter().take(fit.n_machine) {
        let v = row_numbers(&html, "data-id", &p.id);
        if p.estimable {
            assert_eq!(v.len(), 2, "{}", p.id);
            assert!(same(v[0], p.value * p.display_factor) && same(v[1], p.std_uncertainty * p.display_factor), "{}: page {v:?}, archive {} ± {}", p.id, p.value * p.display_factor, p.std_uncertainty * p.display_factor);
            checked += 1;
        } else {
            assert!(v.is_empty(), "{} is not estimable", p.id);
        }
    }
    assert!(checked >= 10, "{checked} estimable parameters checked");
    // The diagnosis: each accepted effect with the archived shrink; the ISO figures of each run
    // after the model equal the archived diagnosis's figures of the base model.
    let d = s.diagnosis.as_ref().unwrap();
    let effects = d["effects"].as_array().unwrap();
    assert!(!effects.is_empty());
    for e in effects {
        let key = format!("{}\" data-axis=\"{}", e["kind"].as_str().unwrap(), e["axis"].as_str().unwrap_or(""));
        let v = row_numbers(&html, "data-kind", &key);
        assert_eq!(v, [e["shrink"].as_f64().unwrap()], "{e}");
    }
    assert_eq!(html.matches("<rect class=\"bar\"").count(), effects.len());
    for r in d["runs"].as_array().unwrap() {
        let v = row_numbers(&html, "data-run", r["run"].as_str().unwrap());
        // The page's columns: RMS before, after, G before, after, F max and min before, F
        // max and min after. The diagnosis's "before" is after the base model: the page's "after".
        assert!(same(v[1], r["rms_before_um"].as_f64().unwrap()) && same(v[3], r["g_before_um"].as_f64().unwrap()), "{r}: {v:?}");
    }
    // The paper's quantities and the ISO figures before and after equal those of `fit --json` on
    // the same runs with the same model (the archive's machine and options).
    let d2 = scratch("report-numbers-fit");
    let fj = d2.join("fit.json");
    ok(&ballbar(&["fit", "--machine", "column", RUNS, "--json", fj.to_str().unwrap()]));
    let fit: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&fj).unwrap()).unwrap();
    let mut quantities = 0;
    for q in fit["paper"]["quantities"].as_array().unwrap() {
        let name = q["paper"]["name"].as_str().unwrap();
        let v = row_numbers(&html, "data-name", name);
        if q["paper"]["estimable"] == true {
            let want = [q["paper"]["value"].as_f64().unwrap(), q["paper"]["std_uncertainty"].as_f64().unwrap(), q["vendor"]["value"].as_f64().unwrap(), q["vendor"]["std_uncertainty"].as_f64().unwrap()];
            assert!(v.len() == 4 && v.iter().zip(want).all(|(a, b)| same(*a, b)), "{name}: page {v:?}, fit {want:?}");
            quantities += 1;
        } else {
            assert!(v.is_empty(), "{name}");
        }
    }
    assert!(quantities >= 10, "{quantities}");
    for r in fit["runs"].as_array().unwrap() {
        let v = row_numbers(&html, "data-run", r["run"].as_str().unwrap());
        let (b, a) = (&r["before"], &r["after"]);
        let want = [&b["rms_um"], &a["rms_um"], &b["g_um"], &a["g_um"], &b["f_max_um"], &b["f_min_um"], &a["f_max_um"], &a["f_min_um"]].map(|x| x.as_f64().unwrap());
        assert!(v.iter().zip(want).all(|(p, q)| same(*p, q)), "{r}: page {v:?}");
    }
    let hyst = fit["hysteresis"].as_array().unwrap();
    assert!(!hyst.is_empty());
    for h in hyst {
        let want = format!("<td>{}</td><td>{}</td><td class=\"num\" data-v=\"{}\"", h["cw"].as_str().unwrap(), h["ccw"].as_str().unwrap(), h["before_um"].as_f64().unwrap());
        assert!(html.contains(&want), "{want}");
    }
    // One polar figure per CW/CCW pair; each run drawn measured, model and residual.
    assert_eq!(html.matches("<figure class=\"polar-pair\"").count(), 3);
    for run in &s.runs {
        let dir = run.run.header.direction.unwrap().name().to_lowercase();
        for what in ["measured", "model", "residual"] {
            assert!(html.contains(&format!("class=\"trace {what} {dir}\" data-run=\"{}\"", run.run.name())), "{what} {}", run.run.name());
        }
    }
}

/// Debian's chromium (`/usr/bin/chromium`, what `.ci/run` installs), headless, with the flags
/// this machine needs (no network, no sandbox as root, a fresh profile), its console on
/// stderr, killed after 120 s: `None` when it is not installed.
fn chromium(args: &[&str], profile: &Path) -> Option<std::process::Output> {
    let exe = Path::new("/usr/bin/chromium");
    if !exe.exists() {
        return None;
    }
    let mut cmd = std::process::Command::new(exe);
    cmd.args(["--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic", "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync", "--enable-logging=stderr", "--v=0"]);
    cmd.arg(format!("--user-data-dir={}", profile.display()));
    let out_file = profile.with_extension("stdout");
    let err_file = profile.with_extension("stderr");
    let mut child = cmd
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::fs::File::create(&out_file).unwrap())
        .stderr(std::fs::File::create(&err_file).unwrap())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if start.elapsed() > std::time::Duration::from_secs(120) {
            let _ = child.kill();
            panic!("chromium did not finish in 120 s");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    Some(std::process::Output { status, stdout: std::fs::read(&out_file).unwrap(), stderr: std::fs::read(&err_file).unwrap() })
}

/// The errors the page's console reported (an SVG attribute the browser could not parse, say).
fn console_errors(o: &std::process::Output) -> Vec<String> {
    String::from_utf8_lossy(&o.stderr).lines().filter(|l| l.contains(":CONSOLE") && l.contains("Error")).map(str::to_string).collect()
}

#[test]
fn the_report_renders_in_a_headless_browser_with_one_polar_plot_per_run_and_direction() {
    let (out, _, s) = diagnosed_report("report-browser");
    let page = format!("file://{}", out.join("index.html").display());
    let shot = out.join("page.png");
    let profile = out.join("profile");
    let Some(o) = chromium(&["--window-size=1400,2400", &format!("--screenshot={}", shot.display()), &page], &profile) else {
        skip(Needs::Chromium, "the report's browser test: no chromium at /usr/bin/chromium (install Debian's with `apt-get install chromium`; .ci/run installs it)");
        return;
    };
    assert!(o.status.success(), "{}", text(&o));
    assert!(console_errors(&o).is_empty(), "the browser reported: {:?}", console_errors(&o));
    let png = std::fs::read(&shot).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 50_000, "a screenshot of {} bytes", png.len());
    // The DOM as the browser built it: the SVGs were parsed as SVG (their elements are there).
    let o = chromium(&["--dump-dom", &page], &profile).unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let dom = String::from_utf8_lossy(&o.stdout);
    assert_eq!(dom.matches("<svg class=\"polar raw\"").count(), 3, "one raw plot per pair");
    assert_eq!(dom.matches("<svg class=\"polar after\"").count(), 3);
    for run in &s.runs {
        let dir = run.run.header.direction.unwrap().name().to_lowercase();
        assert_eq!(dom.matches(&format!("class=\"trace measured {dir}\" data-run=\"{}\"", run.run.name())).count(), 1, "{}", run.run.name());
    }
    // The console check can fail: a path the browser cannot parse is reported.
    let bad = out.join("bad.html");
    std::fs::write(&bad, r#"<!DOCTYPE html><html><body><svg width="9" height="9"><path d="M NaN 1 L 2 3"/></svg></body></html>"#).unwrap();
    let o = chromium(&["--dump-dom", &format!("file://{}", bad.display())], &out.join("profile2")).unwrap();
    assert_eq!(console_errors(&o).len(), 1, "{}", text(&o));
}

#[test]
fn a_report_with_a_history_plots_each_parameters_trend() {
    let d = scratch("report-trends");
    let truth = std::fs::read_to_string(root().join("fixtures/column-paper/truth.ron")).unwrap();
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    for (k, (date, sq)) in [("2026-01-05T08:00:00Z", 20.9), ("2026-02-05T08:00:00Z", 30.9), ("2026-03-05T08:00:00Z", 40.9)].iter().enumerate() {
        let t = truth.replace("squareness_urad: (20.9,", &format!("squareness_urad: ({sq},")).replace("2026-11-21T10:00:00Z", date);
        let tf = d.join(format!("t{k}.ron"));
        std::fs::write(&tf, t).unwrap();
        let runs = d.join(format!("runs{k}"));
        ok(&ballbar(&["simulate", "--machine", "column", "--truth", tf.to_str().unwrap(), "--out", runs.to_str().unwrap(), "--seed", &k.to_string()]));
        ok(&ballbar(&["fit", "--machine", "column", "--servo", "paper", runs.to_str().unwrap(), "--record", hist.join(format!("{k}.mcap")).to_str().unwrap()]));
    }
    // Another machine's session and a damaged archive in the folder: left out (the damaged one
    // named).
    ok(&ballbar(&["fit", "--machine", "horizontal", "fixtures/horizontal-paper/runs", "--record", hist.join("other.mcap").to_str().unwrap()]));
    std::fs::write(hist.join("bad.mcap"), b"not an archive").unwrap();
    let out = d.join("report");
    let o = ballbar(&["report", hist.join("2.mcap").to_str().unwrap(), "--out", out.to_str().unwrap(), "--history", hist.to_str().unwrap()]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("bad.mcap"), "{}", text(&o));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("<section id=\"trends\"><h2>Trends of machine column over 3 sessions"));
    let i = html.find("<svg class=\"trend\" data-id=\"SQXY\"").expect("a trend of SQXY");
    let svg = &html[i..i + html[i..].find("</svg>").unwrap()];
    let values: Vec<f64> = svg.split("data-value=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect();
    assert_eq!(values.len(), 3);
    assert!(values[0] < values[1] && values[1] < values[2], "{values:?}");
    assert!((values[2] - values[0] - 20.0).abs() < 3.0, "{values:?}");
    assert_eq!(svg.matches("class=\"errorbar\"").count(), 3);
}

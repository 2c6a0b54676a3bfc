//! `ballbar history` and the report's trend plots: the changes the history flags (beyond 2
//! combined standard uncertainties) are exactly those marked on the plots, and each plot's
//! value axis holds every error bar.

use std::collections::BTreeMap;

use crate::common::*;
use crate::five_axis::plots::{attr, elements, num, svgs};

fn ok(o: &std::process::Output) {
    assert_eq!(o.status.code(), Some(0), "{}", text(o));
}

/// Three sessions of the column machine: SQXY steps by 10 µrad (the paper's squareness XY,
/// with a new seed: far beyond 2 combined uncertainties, 2√2 × 0.5 µrad), then by 0.3 µrad
/// (the same seed, so the same noise: the change is the 0.3 µrad alone, within them).
#[test]
fn the_changes_history_flags_are_exactly_those_marked_on_the_trend_plots() {
    let d = scratch("history-flags");
    let truth = std::fs::read_to_string(root().join("fixtures/column-paper/truth.ron")).unwrap();
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    let sessions = [
        ("2026-01-05T08:00:00Z", 20.9, "1"),
        ("2026-02-05T08:00:00Z", 30.9, "2"),
        ("2026-03-05T08:00:00Z", 31.2, "2"),
    ];
    for (k, (date, sq, seed)) in sessions.iter().enumerate() {
        let t = truth
            .replace("squareness_urad: (20.9,", &format!("squareness_urad: ({sq},"))
            .replace("2026-11-21T10:00:00Z", date);
        assert_ne!(t, truth);
        let tf = d.join(format!("t{k}.ron"));
        std::fs::write(&tf, t).unwrap();
        let runs = d.join(format!("runs{k}"));
        ok(&ballbar(&[
            "simulate",
            "--machine",
            "column",
            "--truth",
            tf.to_str().unwrap(),
            "--out",
            runs.to_str().unwrap(),
            "--seed",
            seed,
        ]));
        ok(&ballbar(&[
            "fit",
            "--machine",
            "column",
            "--servo",
            "paper",
            "--bar-length-um",
            "0",
            runs.to_str().unwrap(),
            "--record",
            hist.join(format!("{k}.mcap")).to_str().unwrap(),
        ]));
    }

    // `history --csv`: per parameter, per session (in date order), value, u and the flag.
    let o = ballbar(&["history", hist.to_str().unwrap(), "--csv"]);
    ok(&o);
    let csv = String::from_utf8(o.stdout).unwrap();
    let mut rows: BTreeMap<String, Vec<(String, Option<(f64, f64)>, bool)>> = BTreeMap::new();
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        // machine,parameter,unit,session_start,archive,value,std_uncertainty,estimable,change,significant
        let value = (f[7] == "true").then(|| (f[5].parse().unwrap(), f[6].parse().unwrap()));
        rows.entry(f[1].to_string()).or_default().push((
            f[3][..10].to_string(),
            value,
            f[9] == "true",
        ));
    }
    let sq = &rows["SQXY"];
    assert_eq!(sq.iter().map(|r| r.2).collect::<Vec<_>>(), [false, true, false], "SQXY: {sq:?}");
    // The second step is real but within the noise: 0.3 µrad, to the simulation's exactness.
    let (v1, v2) = (sq[1].1.unwrap().0, sq[2].1.unwrap().0);
    assert!((v2 - v1 - 0.3).abs() < 0.05, "{v1} → {v2}");
    // The terminal table marks the same with `*`.
    let o = ballbar(&["history", hist.to_str().unwrap()]);
    ok(&o);
    let table = String::from_utf8(o.stdout).unwrap();
    let line = table.lines().find(|l| l.trim_start().starts_with("SQXY ")).unwrap();
    assert_eq!(line.matches(" *").count(), 1, "{line}");

    // The report's trends: every point's flag is the history's, and the marked segments are
    // exactly the flagged changes, from the session before to the flagged one.
    let out = d.join("report");
    ok(&ballbar(&[
        "report",
        hist.join("2.mcap").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--history",
        hist.to_str().unwrap(),
    ]));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    let mut plots = 0;
    for (id, sessions) in &rows {
        let Some(svg) = svgs(&html, &format!("trend\" data-id=\"{id}")).pop() else {
            assert!(sessions.iter().filter(|s| s.1.is_some()).count() < 2, "{id}: no trend plot");
            continue;
        };
        plots += 1;
        let points = elements(svg, "<circle class=\"point\"");
        let estimable: Vec<&(String, Option<(f64, f64)>, bool)> =
            sessions.iter().filter(|s| s.1.is_some()).collect();
        assert_eq!(points.len(), estimable.len(), "{id}");
        for (p, s) in points.iter().zip(&estimable) {
            assert_eq!(attr(p, "data-date"), s.0, "{id}");
            assert_eq!(
                attr(p, "data-flagged") == "true",
                s.2,
                "{id} {}: the plot and `history` disagree",
                s.0
            );
        }
        let marked: Vec<(&str, &str)> = elements(svg, "<line class=\"change flagged\"")
            .into_iter()
            .map(|e| (attr(e, "data-from-date"), attr(e, "data-to-date")))
            .collect();
        let flagged: Vec<(&str, &str)> = sessions
            .windows(2)
            .filter(|w| w[1].2)
            .map(|w| (w[0].0.as_str(), w[1].0.as_str()))
            .collect();
        assert_eq!(marked, flagged, "{id}");
        // The value axis holds every ±2u bar (the CSV's values at full precision).
        let (low, high) = (num(svg, "data-low"), num(svg, "data-high"));
        for s in &estimable {
            let (v, u) = s.1.unwrap();
            assert!(
                low <= v - 2.0 * u && v + 2.0 * u <= high,
                "{id}: {v} ± {} outside {low}..{high}",
                2.0 * u
            );
        }
    }
    assert!(plots >= 10, "{plots} trend plots");
    assert_eq!(
        svgs(&html, "trend\" data-id=\"SQXY")[0].matches("class=\"change flagged\"").count(),
        1
    );
}

/// A copied archive is the same session: `history` (and the report's trends) count it once,
/// and say which file was left out and why.
#[test]
fn a_copied_archive_is_one_session_not_two() {
    let d = scratch("history-copy");
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    ok(&ballbar(&[
        "fit",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--record",
        hist.join("a.mcap").to_str().unwrap(),
    ]));
    std::fs::copy(hist.join("a.mcap"), hist.join("b-copy.mcap")).unwrap();
    let o = ballbar(&["history", hist.to_str().unwrap()]);
    ok(&o);
    let t = text(&o);
    assert!(t.contains("machine column: 1 sessions"), "{t}");
    assert!(
        t.contains("b-copy.mcap: the same runs as")
            && t.contains("a.mcap")
            && t.contains("counted once"),
        "{t}"
    );
    let o = ballbar(&["history", hist.to_str().unwrap(), "--csv"]);
    ok(&o);
    let csv = String::from_utf8(o.stdout).unwrap();
    assert!(!csv.contains("b-copy.mcap") && csv.contains("a.mcap"), "{csv}");
    // The report's trends: one session, so no trend plot (a trend needs two).
    let out = d.join("report");
    let o = ballbar(&[
        "report",
        hist.join("a.mcap").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--history",
        hist.to_str().unwrap(),
    ]);
    ok(&o);
    assert!(text(&o).contains("b-copy.mcap: the same runs as"), "{}", text(&o));
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(!html.contains("<svg class=\"trend\""), "a trend of one session counted twice");
}

/// What the fit does not estimate reads the same in `fit` and in `history`: the default model
/// at one radius has each servo lag `not identifiable` and the bar length `fixed at 0`.
#[test]
fn fit_and_history_word_what_the_fit_does_not_estimate_alike() {
    let d = scratch("history-wording");
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    let arc = hist.join("a.mcap");
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        "fixtures/column-paper/runs",
        "--record",
        arc.to_str().unwrap(),
    ]);
    ok(&o);
    let fit = text(&o);
    let o = ballbar(&["history", hist.to_str().unwrap()]);
    ok(&o);
    let history = text(&o);
    let row = |t: &str, id: &str| -> String {
        t.lines()
            .find(|l| l.trim_start().starts_with(&format!("{id} ")))
            .unwrap_or_else(|| panic!("{id} in\n{t}"))
            .to_string()
    };
    for t in [&fit, &history] {
        for id in ["TX", "TY", "TZ"] {
            assert!(row(t, id).contains("not identifiable"), "{}", row(t, id));
        }
        assert!(row(t, "BAR").contains("fixed at 0"), "{}", row(t, "BAR"));
        assert!(!t.contains("not estimable") && !t.contains("0 fixed"), "{t}");
    }
}

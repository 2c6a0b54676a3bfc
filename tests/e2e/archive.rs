//! The MCAP archive commands: record, export, replay, history, and the safety of the recorder
//! and of the reader, driven through the binary.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::common::*;

const RUNS: &str = "fixtures/column-paper/runs";

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "exit {:?}: {}", o.status.code(), text(o));
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// The shipped runs' files.
fn fixture_runs() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(root().join(RUNS))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .collect();
    v.sort();
    v
}

#[test]
fn raw_runs_recorded_and_exported_are_the_files_that_went_in() {
    let d = scratch("archive-export");
    let arc = d.join("raw.mcap");
    ok(&ballbar(&["record", RUNS, "--out", arc.to_str().unwrap()]));
    let out = d.join("out");
    ok(&ballbar(&["export", arc.to_str().unwrap(), "--out", out.to_str().unwrap()]));
    for f in fixture_runs() {
        let back = out.join(f.file_name().unwrap());
        // The fixture files were written by the same CSV writer: byte for byte.
        assert_eq!(std::fs::read(&f).unwrap(), std::fs::read(&back).unwrap(), "{}", back.display());
    }
    // A raw archive has nothing to compare a replay with and no machine: said so, exit 1.
    let o = ballbar(&["replay", arc.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("raw runs only"), "{}", text(&o));
}

/// A run 0.5 µs a sample (a 2 MHz logger) with readings of 10 decimals, as its file holds it.
fn fast_run_text() -> String {
    use std::fmt::Write as _;
    let mut text = String::from(
        "# ballbar-run: 1\n# plane: XY\n# direction: CCW\n# radius_mm: 100\n\
         # feed_mm_per_min: 1000\n# pivot_mm: 0, 0, 0\n# tool_ball_mm: 0, 0, -100\n\
         # started_at: 2026-11-21T10:00:00Z\n# run_id: fast\nt_s,X_mm,Y_mm,dR_um\n",
    );
    for k in 0..400 {
        let t = format!("0.{:07}", 5 * k);
        let th = 1000.0 / 60.0 * t.parse::<f64>().unwrap() / 100.0;
        let reading = 46.363_712_345_6 + 0.000_012_345_678_9 * k as f64;
        let _ = writeln!(text, "{t},{},{},{reading:.10}", 100.0 * th.cos(), 100.0 * th.sin());
    }
    text
}

/// `a` and `b` hold the same header and the same samples, bit for bit.
#[track_caller]
pub(crate) fn assert_same_run(a: &ballbar_model::Run, b: &ballbar_model::Run) {
    assert_eq!(a.header, b.header);
    let same = |what: &str, x: &[f64], y: &[f64]| {
        assert_eq!(x.len(), y.len(), "{what} of {}", b.source);
        if let Some(k) = x.iter().zip(y).position(|(p, q)| p.to_bits() != q.to_bits()) {
            panic!("{what} of {}, sample {k}: {} and {}", b.source, x[k], y[k]);
        }
    };
    same("t_s", &a.t_s, &b.t_s);
    for axis in ballbar_model::Axis::ALL {
        assert_eq!(a.axis(axis).is_some(), b.axis(axis).is_some(), "{axis} of {}", b.source);
        if let (Some(x), Some(y)) = (a.axis(axis), b.axis(axis)) {
            same(axis.column_name(), x, y);
        }
    }
    same("dR", &a.dr_mm, &b.dr_mm);
}

/// What was recorded is what `export` writes, exactly: times 0.5 µs apart (at 6 decimals
/// they would repeat, and the file would not read back) and readings of 10 decimals (at 4,
/// 46.3637123456 would come back as 46.3637).
#[test]
fn an_export_writes_every_recorded_value_exactly() {
    let d = scratch("archive-export-exact");
    let run = d.join("fast.csv");
    std::fs::write(&run, fast_run_text()).unwrap();
    let arc = d.join("fast.mcap");
    ok(&ballbar(&["record", run.to_str().unwrap(), "--out", arc.to_str().unwrap()]));
    let out = d.join("out");
    ok(&ballbar(&["export", arc.to_str().unwrap(), "--out", out.to_str().unwrap()]));
    let exported = out.join("fast.csv");
    let text = std::fs::read_to_string(&exported).unwrap();
    assert!(text.contains("\n0.0000005,") && text.contains(",46.3637123456\n"), "{text}");
    let back = ballbar_io::read_run(&exported).unwrap_or_else(|e| panic!("{e}"));
    assert_same_run(&ballbar_io::read_run(&run).unwrap(), &back);
    for r in ballbar_archive::read(&arc).unwrap().runs {
        assert_same_run(&r.run, &back);
    }
}

/// An archived value that no run CSV can hold (a reading in mm that is no µm number times
/// 1e-3, which only a run from no file has) is refused by name, and nothing is written.
#[test]
fn an_export_that_would_not_read_back_is_refused_and_writes_nothing() {
    let d = scratch("archive-export-inexact");
    let mut run = ballbar_io::parse_run(&fast_run_text(), "fast.csv").unwrap();
    // The first reading from 46.4 µm up for which no µm number within a few ulps converts back.
    let holdable = |mm: f64| {
        let (mut up, mut down) = (mm * 1e3, mm * 1e3);
        (0..8).any(|_| {
            let hit = up * 1e-3 == mm || down * 1e-3 == mm;
            (up, down) = (up.next_up(), down.next_down());
            hit
        })
    };
    let mut mm = 0.0464;
    while holdable(mm) {
        mm = mm.next_up();
    }
    run.dr_mm[7] = mm;
    let session = ballbar_archive::Session {
        info: ballbar_archive::SessionInfo::now("test", "", "test"),
        runs: vec![ballbar_archive::ArchivedRun::new(run)],
        machine: None,
        fit: None,
        diagnosis: None,
        attachments: Vec::new(),
    };
    let arc = d.join("made.mcap");
    ballbar_archive::write(&arc, &session, ballbar_io::Existing::Keep).unwrap();
    let out = d.join("out");
    let o = ballbar(&["export", arc.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    for what in [
        arc.to_str().unwrap(),
        "run fast cannot be exported as fast.csv",
        "line 18: column dR_um",
        "nothing was written",
    ] {
        assert!(t.contains(what), "expected {what:?} in: {t}");
    }
    assert!(!out.join("fast.csv").exists(), "{t}");
}

#[test]
fn a_replay_reproduces_the_fit_and_the_diagnosis_and_another_model_shows_its_differences() {
    let d = scratch("archive-replay");
    let arc = d.join("session.mcap");
    ok(&ballbar(&["diagnose", "--machine", "column", RUNS, "--record", arc.to_str().unwrap()]));
    let rep = d.join("replay.json");
    let o = ballbar(&["replay", arc.to_str().unwrap(), "--json", rep.to_str().unwrap()]);
    ok(&o);
    assert!(
        text(&o).contains("fit: identical") && text(&o).contains("diagnosis: identical"),
        "{}",
        text(&o)
    );
    let r = json(&rep);
    assert_eq!(r["fit"]["identical"], true, "{r}");
    assert_eq!(r["diagnosis"]["identical"], true, "{r}");
    // Another model (the horizontal machine's chain) on the same runs: every parameter that
    // depends on the chain moves, and the replay lists them.
    let rep2 = d.join("other.json");
    let o = ballbar(&[
        "replay",
        arc.to_str().unwrap(),
        "--machine",
        "horizontal",
        "--json",
        rep2.to_str().unwrap(),
    ]);
    ok(&o);
    let r = json(&rep2);
    assert_eq!(r["fit"]["identical"], false, "{r}");
    let diffs = r["fit"]["differences"].as_array().unwrap();
    let sq = diffs.iter().find(|x| x["id"] == "SQXY").expect("SQXY differs");
    let (a, b) = (sq["archived"][0].as_f64().unwrap(), sq["replayed"][0].as_f64().unwrap());
    assert!((a - b).abs() > 1.0, "{sq}");
    assert!(text(&o).contains("machine 'horizontal'"), "{}", text(&o));
}

#[test]
fn a_damaged_archive_is_an_error_that_says_what_is_wrong() {
    let d = scratch("archive-damaged");
    let arc = d.join("s.mcap");
    ok(&ballbar(&["fit", "--machine", "column", RUNS, "--record", arc.to_str().unwrap()]));
    let bytes = std::fs::read(&arc).unwrap();
    // Cut in half.
    let cut = d.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let o = ballbar(&["replay", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("cut.mcap") && t.contains("truncated") && t.contains("readable"), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    // One flipped byte a quarter in: inside the compressed chunks of the runs.
    let mut flipped = bytes.clone();
    flipped[bytes.len() / 4] ^= 0x5a;
    let bad = d.join("flipped.mcap");
    std::fs::write(&bad, &flipped).unwrap();
    let o = ballbar(&["export", bad.to_str().unwrap(), "--out", d.join("x").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let t = text(&o);
    assert!(t.contains("flipped.mcap") && t.contains("damaged"), "{t}");
    assert!(
        !d.join("x").exists() || std::fs::read_dir(d.join("x")).unwrap().next().is_none(),
        "nothing exported from a damaged archive"
    );
}

#[test]
fn a_recorder_killed_while_writing_leaves_no_file_under_the_final_name() {
    let d = scratch("archive-kill");
    let arc = d.join("s.mcap");
    // The writer pauses a minute after each run while this test watches the folder.
    let mut child = std::process::Command::new(exe())
        .args(["record", RUNS, "--out", arc.to_str().unwrap()])
        .current_dir(root())
        .env("BALLBAR_PLUGIN_PATH", bundled_plugin_path())
        .env("BALLBAR_ARCHIVE_TEST_PAUSE_MS", "60000")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = Instant::now();
    loop {
        let tmp = std::fs::read_dir(&d)
            .unwrap()
            .filter_map(|e| e.ok())
            .find(|e| e.file_name().to_string_lossy().ends_with(".tmp"));
        if tmp.is_some_and(|e| e.metadata().map(|m| m.len() > 1000).unwrap_or(false)) {
            break;
        }
        assert!(child.try_wait().unwrap().is_none(), "the recorder ended before it was killed");
        assert!(start.elapsed() < Duration::from_secs(60), "the recorder never started writing");
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!arc.exists(), "a half archive under the final name");
}

#[test]
fn history_over_three_sessions_shows_a_drifting_squareness() {
    let d = scratch("archive-history");
    let truth = std::fs::read_to_string(root().join("fixtures/column-paper/truth.ron")).unwrap();
    let sessions = [
        ("2026-01-05T08:00:00Z", 20.9),
        ("2026-02-05T08:00:00Z", 30.9),
        ("2026-03-05T08:00:00Z", 40.9),
    ];
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    // Recorded out of date order (file names sort the other way): history orders by the runs' dates.
    for (k, (date, sq)) in sessions.iter().enumerate() {
        let t = truth
            .replace("squareness_urad: (20.9,", &format!("squareness_urad: ({sq},"))
            .replace("2026-11-21T10:00:00Z", date);
        assert_ne!(t, truth);
        let tf = d.join(format!("truth-{k}.ron"));
        std::fs::write(&tf, t).unwrap();
        let runs = d.join(format!("runs-{k}"));
        ok(&ballbar(&[
            "simulate",
            "--machine",
            "column",
            "--truth",
            tf.to_str().unwrap(),
            "--out",
            runs.to_str().unwrap(),
            "--seed",
            &k.to_string(),
        ]));
        let arc = hist.join(format!("{}-session.mcap", 9 - k));
        ok(&ballbar(&[
            "fit",
            "--machine",
            "column",
            "--servo",
            "paper",
            runs.to_str().unwrap(),
            "--record",
            arc.to_str().unwrap(),
        ]));
    }
    // A raw recording and a damaged archive in the folder are named and left out.
    ok(&ballbar(&["record", RUNS, "--out", hist.join("raw.mcap").to_str().unwrap()]));
    let whole = std::fs::read(hist.join("9-session.mcap")).unwrap();
    std::fs::write(hist.join("damaged.mcap"), &whole[..whole.len() / 3]).unwrap();
    let o = ballbar(&["history", hist.to_str().unwrap(), "--csv"]);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("raw runs only") && err.contains("damaged.mcap") && err.contains("truncated"),
        "{}",
        text(&o)
    );
    let csv = String::from_utf8_lossy(&o.stdout).to_string();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .filter(|r: &Vec<&str>| r[1] == "SQXY")
        .collect();
    assert_eq!(rows.len(), 3, "{csv}");
    for (row, (date, sq)) in rows.iter().zip(&sessions) {
        assert_eq!(row[3], *date, "{csv}");
        let (v, u): (f64, f64) = (row[5].parse().unwrap(), row[6].parse().unwrap());
        // The fitted squareness within 4 standard uncertainties of its truth.
        assert!((v - sq).abs() < 4.0 * u, "{row:?}");
    }
    // The 10 µrad steps are flagged; a parameter that did not change is not (BX).
    assert_eq!(rows[0][9], "false");
    assert_eq!((rows[1][9], rows[2][9]), ("true", "true"), "{csv}");
    let bx: Vec<&str> = csv
        .lines()
        .filter(|l| l.split(',').nth(1) == Some("BX"))
        .map(|l| l.split(',').nth(9).unwrap())
        .collect();
    assert_eq!(bx, ["false", "false", "false"], "{csv}");
    // The table form shows the trend.
    let o = ballbar(&["history", hist.to_str().unwrap()]);
    ok(&o);
    let t = String::from_utf8_lossy(&o.stdout).to_string();
    let line = t.lines().find(|l| l.trim_start().starts_with("SQXY")).unwrap();
    assert!(line.matches(" *").count() == 2, "{line}");
}

#[test]
fn a_user_defined_machine_is_archived_with_its_chain_file_and_replays_without_it() {
    let d = scratch("archive-chain-file");
    let runs = d.join("runs");
    ok(&ballbar(&[
        "simulate",
        "--machine-file",
        "fixtures/machines/gantry.ron",
        "--truth",
        "fixtures/machines/gantry.truth.ron",
        "--out",
        runs.to_str().unwrap(),
    ]));
    // The chain file is read from a copy that is deleted before the replay.
    let chain = d.join("my-gantry.ron");
    std::fs::copy(root().join("fixtures/machines/gantry.ron"), &chain).unwrap();
    let arc = d.join("g.mcap");
    ok(&ballbar(&[
        "fit",
        "--machine-file",
        chain.to_str().unwrap(),
        runs.to_str().unwrap(),
        "--record",
        arc.to_str().unwrap(),
    ]));
    std::fs::remove_file(&chain).unwrap();
    let o = ballbar(&["replay", arc.to_str().unwrap()]);
    ok(&o);
    assert!(text(&o).contains("fit: identical"), "{}", text(&o));
}

#[cfg(unix)]
#[test]
fn an_archive_path_that_is_not_utf8_is_written_without_a_panic() {
    use std::os::unix::ffi::OsStrExt;
    let d = scratch("archive-non-utf8");
    let out = d.join(std::ffi::OsStr::from_bytes(b"s\xff.mcap"));
    let o = std::process::Command::new(exe())
        .arg("record")
        .arg(RUNS)
        .arg("--out")
        .arg(&out)
        .current_dir(root())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    assert!(out.exists());
}

#[test]
fn the_python_mcap_reader_reads_the_archive() {
    // Another MCAP implementation (the `mcap` package from PyPI, which .ci/run installs) reads
    // the file with its CRCs checked: every run's samples as JSON messages on their channel.
    let python_has_mcap = std::process::Command::new("python3")
        .args(["-c", "import mcap"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !python_has_mcap {
        skip(
            Needs::PythonMcap,
            "the Python mcap reader test: python3 with the mcap package is not available (`pip install mcap`; .ci/run installs it)",
        );
        return;
    }
    let d = scratch("archive-python");
    let arc = d.join("s.mcap");
    ok(&ballbar(&["fit", "--machine", "column", RUNS, "--record", arc.to_str().unwrap()]));
    let script = r#"
import json, sys
from mcap.reader import make_reader
counts, first = {}, {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, validate_crcs=True)
    for schema, channel, message in reader.iter_messages():
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        if channel.topic.endswith("/samples") and channel.topic not in first:
            first[channel.topic] = json.loads(message.data)
    meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    att = [a.name for a in reader.iter_attachments()]
print(json.dumps({"counts": counts, "first": first, "meta": meta, "attachments": att}))
"#;
    let o = std::process::Command::new("python3")
        .args(["-c", script, arc.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["meta"]["ballbar"]["schema_version"], "1", "{v}");
    for f in fixture_runs() {
        let text_csv = std::fs::read_to_string(&f).unwrap();
        let rows: Vec<&str> =
            text_csv.lines().filter(|l| !l.starts_with('#') && !l.starts_with("t_s")).collect();
        let name = f.file_stem().unwrap().to_str().unwrap();
        let topic = format!("/runs/{name}/samples");
        assert_eq!(v["counts"][&topic].as_u64(), Some(rows.len() as u64), "{topic}");
        // The first sample's reading equals the file's (the dR_um column, last).
        let dr: f64 = rows[0].split(',').next_back().unwrap().parse().unwrap();
        assert_eq!(v["first"][&topic]["dr_um"].as_f64(), Some(dr), "{topic}");
        assert!(v["attachments"].as_array().unwrap().iter().any(|a| a == &format!("{name}.csv")));
    }
}

/// An archive is never replaced without `--force`: `record --out` over a fitted session's
/// archive, and `fit --record` over an archive, stop before any work, naming the file, and
/// leave it as it was; with `--force` they replace it.
#[test]
fn an_archive_is_not_replaced_without_force() {
    let d = scratch("archive-force");
    let arc = d.join("session.mcap");
    let a = arc.to_str().unwrap();
    ok(&ballbar(&["fit", "--machine", "column", RUNS, "--record", a]));
    let before = std::fs::read(&arc).unwrap();
    for args in [
        vec!["record", RUNS, "--out", a],
        vec!["fit", "--machine", "column", RUNS, "--record", a],
        vec!["diagnose", "--machine", "column", RUNS, "--record", a],
    ] {
        let o = ballbar(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {}", text(&o));
        assert!(
            text(&o).contains(
                "session.mcap: already exists; nothing was written (--force replaces it)"
            ),
            "{}",
            text(&o)
        );
        assert_eq!(std::fs::read(&arc).unwrap(), before, "{args:?} changed the archive");
    }
    ok(&ballbar(&["record", RUNS, "--out", a, "--force"]));
    assert_ne!(std::fs::read(&arc).unwrap(), before, "--force replaces it");
}

/// A damaged archive's runs can be recovered. A recording cut at several points: `export`
/// refuses it (exit 1, nothing written) and says that `--partial` exists; `export --partial`
/// writes every run the file still holds whole, each byte for byte the file that went in,
/// never a run cut short, says how many of how many it wrote and names what was lost (runs,
/// the fit, the diagnosis, attachments), exit 0; with no run whole, exit 1. The reader's
/// message says what the file holds, not that runs "were read" by a command that then wrote
/// nothing.
#[test]
fn a_cut_archive_is_refused_by_export_and_its_whole_runs_are_recovered_with_partial() {
    let d = scratch("archive-partial");
    let arc = d.join("s.mcap");
    ok(&ballbar(&["diagnose", "--machine", "column", RUNS, "--record", arc.to_str().unwrap()]));
    let bytes = std::fs::read(&arc).unwrap();
    let originals = fixture_runs();
    let mut last_written = 0;
    for (k, fraction) in [0.2, 0.35, 0.5, 0.7, 0.9, 1.0].into_iter().enumerate() {
        let len = ((bytes.len() as f64 * fraction) as usize).min(bytes.len() - 1);
        let cut = d.join(format!("cut-{k}.mcap"));
        std::fs::write(&cut, &bytes[..len]).unwrap();
        // Without --partial: refused, nothing written, --partial named.
        let refused = d.join(format!("refused-{k}"));
        let o = ballbar(&["export", cut.to_str().unwrap(), "--out", refused.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "cut at {len}: {}", text(&o));
        let t = text(&o);
        assert!(
            t.contains("truncated") && t.contains("nothing was written") && t.contains("--partial"),
            "{t}"
        );
        assert!(!t.contains("were read"), "{t}");
        assert!(!refused.exists(), "{t}");
        // A report of it likewise points at --partial.
        let o = ballbar(&["report", cut.to_str().unwrap(), "--out", refused.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(1), "cut at {len}: {}", text(&o));
        let t = text(&o);
        assert!(
            t.contains("a report needs the whole archive: nothing was written")
                && t.contains("--partial"),
            "{t}"
        );
        assert!(!refused.exists(), "{t}");
        // With --partial: the whole runs, byte for byte, and what was lost.
        let out = d.join(format!("partial-{k}"));
        let o = ballbar(&[
            "export",
            cut.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--partial",
        ]);
        ok(&o);
        let t = text(&o);
        let mut written: Vec<String> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        written.sort();
        let n = written.len();
        assert!(n >= 1 && n >= last_written, "cut at {len}: {n} runs after {last_written}: {t}");
        last_written = n;
        assert!(t.contains(&format!("wrote {n} of the 6 runs of ")), "{t}");
        for (name, original) in written.iter().zip(&originals) {
            // The runs of the session in order: a recovered run is the original file.
            assert_eq!(name, &original.file_name().unwrap().to_string_lossy().into_owned());
            assert_eq!(
                std::fs::read(out.join(name)).unwrap(),
                std::fs::read(original).unwrap(),
                "cut at {len}: {name}"
            );
        }
        let lost = t
            .lines()
            .find(|l| l.starts_with("lost: "))
            .unwrap_or_else(|| panic!("no lost line: {t}"));
        if n < 6 {
            // The runs not written are named as lost (the one cut short, and those after it),
            // and with them the fit and the diagnosis that come after the runs.
            assert!(lost.contains("more run") || lost.contains("the rest of run"), "{lost}");
            assert!(lost.contains("fit") && lost.contains("diagnosis"), "{lost}");
        }
        if fraction == 1.0 {
            // Cut in the index after the data: nothing of the session is lost.
            assert!(lost.starts_with("lost: nothing the archive announces"), "{lost}");
        } else {
            // The attachments come last in the data: a cut before the end loses some.
            assert!(lost.contains("attachment"), "{lost}");
        }
    }
    assert_eq!(last_written, 6, "a cut 1 byte before the end keeps every run");
    // A cut before any run is whole: --partial has nothing to write, exit 1.
    let cut = d.join("early.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 50]).unwrap();
    let out = d.join("early");
    let o =
        ballbar(&["export", cut.to_str().unwrap(), "--out", out.to_str().unwrap(), "--partial"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("no run is intact"), "{}", text(&o));
    assert!(!out.exists());
    // A whole archive: --partial is a plain export.
    let out = d.join("whole");
    let o =
        ballbar(&["export", arc.to_str().unwrap(), "--out", out.to_str().unwrap(), "--partial"]);
    ok(&o);
    assert!(text(&o).contains("wrote 6 runs from") && !text(&o).contains("lost"), "{}", text(&o));
}

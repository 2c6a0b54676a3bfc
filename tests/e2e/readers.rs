//! Input that no ballbar gives, through every command that reads it: a run id too long for a
//! report's column, a reading of 1e300, and archives whose records carry no checksums.

use std::path::{Path, PathBuf};

use crate::common::*;

const XY: [&str; 2] =
    ["fixtures/column-paper/runs/xy-ccw-1.csv", "fixtures/column-paper/runs/xy-cw-1.csv"];

/// The XY pair of the shipped runs in a scratch folder, with `change` applied to the text of
/// xy-ccw-1.csv; returns the folder.
fn xy_pair(name: &str, change: impl Fn(&str) -> String) -> PathBuf {
    let d = scratch(name);
    let runs = d.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    for f in XY {
        let text = std::fs::read_to_string(root().join(f)).unwrap();
        let text = if f.ends_with("xy-ccw-1.csv") { change(&text) } else { text };
        std::fs::write(runs.join(Path::new(f).file_name().unwrap()), text).unwrap();
    }
    d
}

/// `text` with the `dR_um` of sample line `ln` (1-based) replaced by `value`.
fn with_reading(text: &str, ln: usize, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let at = lines[ln - 1].rfind(',').unwrap();
    lines[ln - 1].replace_range(at + 1.., value);
    lines.join("\n") + "\n"
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Exit 1, the message containing each of `what`, no panic.
fn input_error(o: &std::process::Output, what: &[&str]) {
    let t = text(o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    for w in what {
        assert!(t.contains(w), "expected {w:?} in: {t}");
    }
}

/// A run_id of 65,536 characters made `fit` exit 101 ("Formatting argument out of range"): it
/// is refused where it is written, naming the file and the line.
#[test]
fn a_run_id_of_65536_characters_is_an_input_error_not_a_panic() {
    let d = xy_pair("readers-long-id", |t| {
        t.replace("# run_id: xy-ccw-1", &format!("# run_id: {}", "r".repeat(65_536)))
    });
    let runs = d.join("runs");
    let o = ballbar(&["fit", "--machine", "column", s(&runs)]);
    input_error(&o, &["xy-ccw-1.csv:11: the line is 65546 bytes long"]);
    assert!(text(&o).len() < 2000, "the message does not repeat the id");
    // A run id a file name can hold is fitted, its row in the table at a bounded width.
    let d = xy_pair("readers-long-id-ok", |t| {
        t.replace("# run_id: xy-ccw-1", &format!("# run_id: {}-ccw", "r".repeat(236)))
    });
    let o = ballbar(&["fit", "--machine", "column", s(&d.join("runs"))]);
    assert!(o.status.success(), "{}", text(&o));
    let t = text(&o);
    let row = t.lines().find(|l| l.contains("r…r")).expect("the shortened run name");
    assert!(row.contains("rrrr-ccw ") && row.chars().count() < 160, "{row}");
}

/// One `dR_um` of 1e300 gave "residual σ NaN" with exit 0 from `fit`: every command that reads
/// runs refuses it at its line.
#[test]
fn a_reading_of_1e300_is_refused_at_its_line_by_every_command() {
    let d = xy_pair("readers-huge", |t| with_reading(t, 40, "1e300"));
    let runs = d.join("runs");
    let at = ["xy-ccw-1.csv:40: column dR_um: 1e300 µm is not a ballbar reading"];
    input_error(&ballbar(&["fit", "--machine", "column", s(&runs)]), &at);
    input_error(&ballbar(&["diagnose", "--machine", "column", s(&runs)]), &at);
    let out = d.join("report");
    input_error(&ballbar(&["report", "--machine", "column", s(&runs), "--out", s(&out)]), &at);
    assert!(!out.join("index.html").exists());
    // predict, with a model of the sound runs.
    let model = d.join("model.ron");
    let sound = xy_pair("readers-huge-sound", |t| t.to_string());
    let o =
        ballbar(&["fit", "--machine", "column", s(&sound.join("runs")), "--save-model", s(&model)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ballbar(&["predict", "--model", s(&model), s(&runs), "--out", s(&d.join("p"))]);
    input_error(&o, &at);
    // An archive edited to hold one (its writer takes what it is given): replay, report and
    // export refuse it, naming the run, the file it came from and the line.
    let mut session_runs: Vec<ballbar_model::Run> =
        XY.iter().map(|f| ballbar_io::read_run(&root().join(f)).unwrap()).collect();
    session_runs[0].dr_mm[27] = 1e300;
    let session = ballbar_archive::Session {
        info: ballbar_archive::SessionInfo::now("test", "column", "edited"),
        runs: session_runs.into_iter().map(ballbar_archive::ArchivedRun::new).collect(),
        machine: Some(ballbar_archive::ArchivedMachine {
            spec: ballbar_model::machines::column(),
            options: Default::default(),
            plugin_name: "column".into(),
            plugin_version: "0.1.0".into(),
            machine_file: None,
        }),
        fit: None,
        diagnosis: None,
        attachments: vec![],
    };
    let arc = d.join("edited.mcap");
    ballbar_archive::write(&arc, &session, ballbar_io::Existing::Replace).unwrap();
    let at =
        ["run 1 (xy-ccw-1)", "xy-ccw-1.csv:40: column dR_um: 1e303 µm is not a ballbar reading"];
    input_error(&ballbar(&["replay", s(&arc)]), &at);
    input_error(&ballbar(&["report", s(&arc), "--out", s(&out)]), &at);
    input_error(&ballbar(&["export", s(&arc), "--out", s(&d.join("x"))]), &at);
}

/// `bytes` of an MCAP file with every CRC set to 0 (chunks, attachments, the data section,
/// the summary), as an editor that does not recompute them leaves it: MCAP reads 0 as "not
/// computed". Records: opcode (1 byte), length (8, little-endian), body.
fn without_crcs(bytes: &[u8]) -> Vec<u8> {
    const FOOTER: u8 = 0x02;
    const CHUNK: u8 = 0x06;
    const ATTACHMENT: u8 = 0x09;
    const DATA_END: u8 = 0x0f;
    let mut out = bytes.to_vec();
    let mut at = 8;
    while at + 9 <= out.len() - 8 {
        let len = u64::from_le_bytes(out[at + 1..at + 9].try_into().unwrap()) as usize;
        let body = at + 9..at + 9 + len;
        let crc = match out[at] {
            CHUNK => Some(body.start + 24),
            ATTACHMENT => Some(body.end - 4),
            DATA_END => Some(body.start),
            FOOTER => Some(body.start + 16),
            _ => None,
        };
        if let Some(c) = crc {
            out[c..c + 4].fill(0);
        }
        at = body.end;
    }
    out
}

/// An archive whose CRCs were set to 0 after editing passed `export` without a word: every
/// command that reads an archive says its records carry no checksums, and `--require-crc`
/// refuses it.
#[test]
fn an_archive_without_checksums_is_said_so_and_refused_with_require_crc() {
    let d = scratch("readers-no-crc");
    let hist = d.join("history");
    std::fs::create_dir_all(&hist).unwrap();
    let good = hist.join("a.mcap");
    let o = ballbar(&["fit", "--machine", "column", XY[0], XY[1], "--record", s(&good)]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ballbar(&["export", s(&good), "--out", s(&d.join("good")), "--require-crc"]);
    assert!(o.status.success() && !text(&o).contains("checksum"), "{}", text(&o));

    // Another session (the YZ pair), its CRCs set to 0.
    let other = d.join("yz.mcap");
    let yz = ["fixtures/column-paper/runs/yz-ccw-1.csv", "fixtures/column-paper/runs/yz-cw-1.csv"];
    let o = ballbar(&["fit", "--machine", "column", yz[0], yz[1], "--record", s(&other)]);
    assert!(o.status.success(), "{}", text(&o));
    let arc = hist.join("b.mcap");
    std::fs::write(&arc, without_crcs(&std::fs::read(&other).unwrap())).unwrap();
    let warning = "b.mcap: its records carry no checksums: damage cannot be detected in the records outside chunks";
    // Read with a warning.
    let out = d.join("out");
    let o = ballbar(&["export", s(&arc), "--out", s(&out)]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains(&format!("warning: {}", s(&arc))) && text(&o).contains(warning));
    for args in [
        vec!["export", s(&arc), "--out", s(&d.join("out2")), "--partial"],
        vec!["replay", s(&arc)],
        vec!["history", s(&hist)],
        vec!["report", s(&arc), "--out", s(&d.join("page"))],
        vec!["report", s(&good), "--out", s(&d.join("page2")), "--history", s(&hist)],
    ] {
        let o = ballbar(&args);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(warning), "{args:?}: {}", text(&o));
    }
    // Refused with --require-crc, nothing written.
    let refused = d.join("refused");
    for args in [
        vec!["export", s(&arc), "--out", s(&refused), "--require-crc"],
        vec!["export", s(&arc), "--out", s(&refused), "--partial", "--require-crc"],
        vec!["replay", s(&arc), "--require-crc"],
        vec!["history", s(&hist), "--require-crc"],
        vec!["report", s(&arc), "--out", s(&refused), "--require-crc"],
        vec!["report", s(&good), "--out", s(&refused), "--history", s(&hist), "--require-crc"],
    ] {
        input_error(&ballbar(&args), &[warning, "--require-crc refuses it"]);
        assert!(!refused.exists(), "{args:?} wrote {}", refused.display());
    }
}

/// The first ```csv block after `heading` in `docs/run-format.md`.
fn doc_csv_block(heading: &str) -> String {
    let doc = std::fs::read_to_string(root().join("docs/run-format.md")).unwrap();
    let from = doc.find(heading).unwrap_or_else(|| panic!("{heading:?} in docs/run-format.md"));
    let block = &doc[from..];
    let open = block.find("```csv\n").expect("a csv block") + "```csv\n".len();
    let close = open + block[open..].find("```").expect("the block's end");
    block[open..close].to_string()
}

/// The minimal example of `docs/run-format.md`, as the page gives it (no `Z_mm`: the axis sits
/// at the pivot), runs on the column machine, whose chain has Z: a model fitted on the shipped
/// runs predicts it, and predicts the same as for the example with the column `Z_mm` written
/// out at the pivot's Z.
#[test]
fn the_minimal_example_of_docs_run_format_runs_on_a_column_machine() {
    let d = scratch("doc-minimal-example");
    let example = doc_csv_block("### A minimal example");
    assert!(!example.contains("Z_mm"), "the example leaves Z out:\n{example}");
    let with_z: String = example
        .lines()
        .map(|l| match l {
            "t_s,X_mm,Y_mm,dR_um" => "t_s,X_mm,Y_mm,Z_mm,dR_um".to_string(),
            l if l.starts_with('#') => l.to_string(),
            l => {
                let f: Vec<&str> = l.split(',').collect();
                format!("{},{},{},0,{}", f[0], f[1], f[2], f[3])
            }
        })
        .map(|l| l + "\n")
        .collect();
    for (dir, text) in [("given", &example), ("with-z", &with_z)] {
        std::fs::create_dir_all(d.join(dir)).unwrap();
        std::fs::write(d.join(dir).join("minimal.csv"), text).unwrap();
    }
    let model = d.join("model.ron");
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
        s(&model),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let predicted = |dir: &str| -> Vec<f64> {
        let out = d.join(format!("{dir}-predicted"));
        let run = d.join(dir).join("minimal.csv");
        let o = ballbar(&["predict", "--model", s(&model), "--out", s(&out), s(&run)]);
        assert!(o.status.success(), "{dir}: {}", text(&o));
        let written = std::fs::read_to_string(out.join("minimal.csv")).unwrap();
        let mut lines = written.lines().skip_while(|l| l.starts_with('#'));
        let columns: Vec<&str> = lines.next().unwrap().split(',').collect();
        let k = columns.iter().position(|c| *c == "dR_model_um").expect("dR_model_um");
        lines.map(|l| l.split(',').nth(k).unwrap().parse().unwrap()).collect()
    };
    let given = predicted("given");
    assert_eq!(given.len(), 4);
    // The model's prediction is µm-sized on the shipped machine (the column's errors are tens
    // of µm): a prediction, not zeros.
    assert!(given.iter().all(|v| v.abs() > 0.1), "{given:?}");
    assert_eq!(given, predicted("with-z"));
}

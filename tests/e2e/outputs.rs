//! Every file a command writes obeys one rule: never an input of the same command (not even
//! with `--force`), never an existing file without `--force`, never two outputs of one command
//! on one file; a file replaced with `--force` keeps its permission bits; a set of files is
//! written whole or not at all; leftovers of a stopped writer are named; no written header
//! holds a line break that another reader would take as the end of a line.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use crate::common::*;

const RUNS: &str = "fixtures/column-paper/runs";

/// Copies of the fixture runs in `dir/runs`, so that a test may point outputs at them.
fn copied_runs(dir: &Path) -> PathBuf {
    let runs = dir.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    for e in std::fs::read_dir(root().join(RUNS)).unwrap() {
        let p = e.unwrap().path();
        std::fs::copy(&p, runs.join(p.file_name().unwrap())).unwrap();
    }
    runs
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `args` fails with exit 1 and a message that names `file` (as given) and says `why`, and
/// `file` keeps every byte.
fn refused(args: &[&str], file: &Path, why: &str) {
    let before = std::fs::read(file).unwrap();
    let o = ballbar(args);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
    assert!(t.contains(&format!("{}: {why}", file.display())), "{args:?}: {t}");
    assert!(!t.contains("panicked"), "{args:?}: {t}");
    assert_eq!(std::fs::read(file).unwrap(), before, "{args:?} changed {}", file.display());
}

/// The names in `dir` that look like a writer's temporary files (`.NAME.PID.N.tmp`).
fn temporaries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with('.') && n.ends_with(".tmp"))
        .collect()
}

/// The fit and diagnose output options, `plugins --json`, `replay --json`, `record`,
/// `report`, `import`, `program`, `simulate`, `predict` and `export`, each pointed at one of
/// its own command's inputs with `--force`: refused before any work, the input as it was.
#[test]
fn no_output_replaces_an_input_of_its_command_even_with_force() {
    let d = scratch("outputs-inputs");
    let runs = copied_runs(&d);
    let run = runs.join("xy-ccw-1.csv");
    let arc = d.join("session.mcap");
    assert!(ballbar(&["record", s(&runs), "--out", s(&arc)]).status.success());
    let model = d.join("model.ron");
    let o = ballbar(&["fit", "--machine", "column", RUNS, "--save-model", s(&model)]);
    assert!(o.status.success(), "{}", text(&o));
    // A plugin the command loads is one of its inputs too.
    let plugin = d.join(format!(
        "{}ballbar_machine_column{}",
        std::env::consts::DLL_PREFIX,
        std::env::consts::DLL_SUFFIX
    ));
    std::fs::copy(plugin_file("ballbar_machine_column"), &plugin).unwrap();
    // A run file named as the report's page, and as a program, and a truth file named as a
    // run the simulation writes.
    let page_dir = d.join("page");
    std::fs::create_dir_all(&page_dir).unwrap();
    let page = page_dir.join("index.html");
    std::fs::copy(&run, &page).unwrap();
    let nc = d.join("xy-ccw-1.nc");
    std::fs::copy(&run, &nc).unwrap();
    let truth = d.join("sim").join("xy-ccw-1.csv");
    std::fs::create_dir_all(truth.parent().unwrap()).unwrap();
    std::fs::copy(root().join("fixtures/column-paper/truth.ron"), &truth).unwrap();
    // A plain table imported into its own folder under its own name.
    let table = d.join("table.csv");
    let mut t = String::from("angle_deg,dR_um\n");
    for k in 0..360 {
        let _ = writeln!(t, "{k},{:.3}", 0.5 * f64::from(k).to_radians().sin());
    }
    std::fs::write(&table, t).unwrap();

    let why = "is one of the inputs";
    let fit = |option: &str, target: &Path| {
        refused(
            &["fit", "--machine", "column", s(&runs), option, s(target), "--force"],
            target,
            why,
        )
    };
    fit("--json", &run);
    fit("--save-model", &run);
    fit("--record", &run);
    refused(
        &["diagnose", "--machine", "column", s(&runs), "--json", s(&run), "--force"],
        &run,
        why,
    );
    refused(
        &["diagnose", "--machine", "column", s(&runs), "--save-model", s(&run), "--force"],
        &run,
        why,
    );
    refused(&["record", s(&runs), "--out", s(&run), "--force"], &run, why);
    refused(&["replay", s(&arc), "--json", s(&arc), "--force"], &arc, why);
    refused(&["plugins", "--plugin", s(&plugin), "--json", s(&plugin), "--force"], &plugin, why);
    refused(
        &["report", "--machine", "column", s(&page), "--out", s(&page_dir), "--force"],
        &page,
        why,
    );
    refused(&["predict", "--model", s(&model), s(&run), "--out", s(&runs), "--force"], &run, why);
    refused(&["program", s(&nc), "--out", s(&d), "--force"], &nc, why);
    refused(
        &[
            "simulate",
            "--machine",
            "column",
            "--truth",
            s(&truth),
            "--out",
            s(truth.parent().unwrap()),
            "--force",
        ],
        &truth,
        why,
    );
    refused(
        &[
            "import",
            s(&table),
            "--plane",
            "XY",
            "--direction",
            "CCW",
            "--radius-mm",
            "100",
            "--feed",
            "1000",
            "--started-at",
            "2026-03-01T09:00:00Z",
            "--out",
            s(&d),
            "--force",
        ],
        &table,
        why,
    );
    // An archive named as a run it holds, exported into its own folder.
    let named_as_run = runs.join("xy-cw-1.csv");
    let arc_as_run = d.join("xy-cw-1.csv");
    assert!(
        ballbar(&["record", s(&named_as_run), "--out", s(&arc_as_run)]).status.success(),
        "an archive may have any name"
    );
    refused(&["export", s(&arc_as_run), "--out", s(&d), "--force"], &arc_as_run, why);
}

/// Each output option pointed at an existing file without `--force`: refused before any work,
/// naming the file, which keeps every byte; with `--force` the file is replaced.
#[test]
fn no_output_replaces_an_existing_file_without_force() {
    let d = scratch("outputs-existing");
    let (arc, model) = (d.join("session.mcap"), d.join("model.ron"));
    let o = ballbar(&[
        "fit",
        "--machine",
        "column",
        RUNS,
        "--save-model",
        s(&model),
        "--record",
        s(&arc),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let mine = d.join("notes.txt");
    std::fs::write(&mine, "the engineer's own notes\n").unwrap();
    let why = "already exists";
    for option in ["--json", "--save-model", "--record"] {
        for command in ["fit", "diagnose"] {
            refused(&[command, "--machine", "column", RUNS, option, s(&mine)], &mine, why);
        }
    }
    refused(&["record", RUNS, "--out", s(&mine)], &mine, why);
    refused(&["replay", s(&arc), "--json", s(&mine)], &mine, why);
    refused(&["plugins", "--json", s(&mine)], &mine, why);
    // Folders of outputs with one of the names taken.
    let out = d.join("out");
    std::fs::create_dir_all(&out).unwrap();
    let taken = |name: &str| {
        let f = out.join(name);
        std::fs::write(&f, "taken\n").unwrap();
        f
    };
    let page = taken("index.html");
    refused(&["report", s(&arc), "--out", s(&out)], &page, why);
    let run = taken("xy-ccw-1.csv");
    refused(
        &[
            "simulate",
            "--machine",
            "column",
            "--truth",
            "fixtures/column-paper/truth.ron",
            "--out",
            s(&out),
        ],
        &run,
        why,
    );
    refused(&["predict", "--model", s(&model), RUNS, "--out", s(&out)], &run, why);
    refused(&["export", s(&arc), "--out", s(&out)], &run, why);
    let nc = taken("xy-ccw-1.nc");
    refused(&["program", RUNS, "--out", s(&out)], &nc, why);

    // With --force they are replaced.
    let o = ballbar(&["replay", s(&arc), "--json", s(&mine), "--force"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(std::fs::read_to_string(&mine).unwrap().starts_with('{'));
    let o = ballbar(&["report", s(&arc), "--out", s(&out), "--force"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(std::fs::read_to_string(&page).unwrap().contains("<html"));
    assert!(temporaries(&d).is_empty() && temporaries(&out).is_empty());
}

/// Two outputs of one command on one file (directly or through a link): refused before any
/// work; the one written later would replace the other.
#[test]
fn two_outputs_of_one_command_are_never_one_file() {
    let d = scratch("outputs-twice");
    let f = d.join("out.json");
    for other in ["--save-model", "--record"] {
        let o = ballbar(&["fit", "--machine", "column", RUNS, "--json", s(&f), other, s(&f)]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{t}");
        assert!(t.contains("out.json: is named by both --json and") && t.contains(other), "{t}");
        assert!(!f.exists(), "nothing was written");
    }
    #[cfg(unix)]
    {
        let link = d.join("link.ron");
        std::os::unix::fs::symlink("out.json", &link).unwrap();
        let o = ballbar(&[
            "diagnose",
            "--machine",
            "column",
            RUNS,
            "--json",
            s(&f),
            "--save-model",
            s(&link),
            "--force",
        ]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{t}");
        assert!(t.contains("is named by both --json and --save-model"), "{t}");
    }
}

/// `--force` replaces a file's content, not its permission bits: a 0600 file stays 0600, a
/// 0640 one 0640 (the umask would give a new file 0644).
#[cfg(unix)]
#[test]
fn a_replaced_file_keeps_its_permission_bits() {
    use std::os::unix::fs::PermissionsExt as _;
    let d = scratch("outputs-mode");
    let arc = d.join("session.mcap");
    assert!(ballbar(&["record", RUNS, "--out", s(&arc)]).status.success());
    for mode in [0o600, 0o640] {
        let f = d.join(format!("private-{mode:o}.json"));
        std::fs::write(&f, "{}").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(mode)).unwrap();
        let o = ballbar(&["plugins", "--json", s(&f), "--force"]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(std::fs::read_to_string(&f).unwrap().contains("\"plugins\""));
        let m = std::fs::metadata(&f).unwrap().permissions().mode() & 0o7777;
        assert_eq!(m, mode, "plugins --json --force: mode {m:o}, was {mode:o}");
        // The archive writer likewise.
        std::fs::set_permissions(&arc, std::fs::Permissions::from_mode(mode)).unwrap();
        let o = ballbar(&["record", RUNS, "--out", s(&arc), "--force"]);
        assert!(o.status.success(), "{}", text(&o));
        let m = std::fs::metadata(&arc).unwrap().permissions().mode() & 0o7777;
        assert_eq!(m, mode, "record --force: mode {m:o}, was {mode:o}");
    }
}

/// A writer stopped before it renamed its temporary file (killed, a power cut) leaves
/// `.NAME.PID.N.tmp` behind: the next command that writes into that folder names it, and
/// leaves it (it is not this process's to remove).
#[test]
fn the_leftovers_of_a_stopped_writer_are_named_by_the_next_write_into_their_folder() {
    let d = scratch("outputs-leftovers");
    // Process ids on Linux stay below 2^22: this one is not running.
    let stale = d.join(".plugins.json.4000000000.0.tmp");
    std::fs::write(&stale, "half a file").unwrap();
    let o = ballbar(&["plugins", "--json", s(&d.join("plugins.json"))]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    assert!(
        t.contains(&stale.display().to_string()) && t.contains("not running"),
        "the leftover is named: {t}"
    );
    assert_eq!(std::fs::read(&stale).unwrap(), b"half a file", "and left as it was");
}

/// A `.b5r` test of two runs (CCW, CW) at R = 100 mm, 1000 mm/min, 125 Hz (4712 readings a
/// circle, 20 of over-shoot either side), every reading 1 µm, with `operator` as the file's
/// OPERATOR element (XML text, escaped by the caller).
fn b5r(operator: &str) -> String {
    let (n, over) = (4712usize, 20usize);
    let mut s = format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<TEST_DOCUMENT>\n  <TEST_SPEC NAME=\"t\" version=\"2.0\">\n    <INSTRUMENT MANUFACTURER=\"Renishaw\" MODEL=\"QC20\">\n      <DYNAMIC_BALLBAR>\n        <NOMINAL_LENGTH>100</NOMINAL_LENGTH>\n        <PROGRAMMED_FEEDRATE>1000</PROGRAMMED_FEEDRATE>\n        <START_ANGLE>0</START_ANGLE>\n        <END_ANGLE>0</END_ANGLE>\n        <OVERSHOOT_ANGLE>5</OVERSHOOT_ANGLE>\n        <PLANE VIEW=\"+A+B\" TEST_PLANE=\"XY\"><A_AXIS_NAME>X</A_AXIS_NAME><B_AXIS_NAME>Y</B_AXIS_NAME></PLANE>\n      </DYNAMIC_BALLBAR>\n    </INSTRUMENT>\n  </TEST_SPEC>\n  <OPERATOR>{operator}</OPERATOR>\n  <DATE_STARTED>20260301-090000</DATE_STARTED>\n  <MACHINE_TESTED NAME=\"VMC 7\" />\n  <RUN_RESULTS>\n"
    );
    let readings = "+0.00100 ".repeat(n + 2 * over);
    for dir in ["CCW", "CW"] {
        let _ = write!(
            s,
            "    <BALLBAR_RUN><RUN_DIRECTION>{dir}</RUN_DIRECTION><START_INDEX>{over}</START_INDEX><END_INDEX>{}</END_INDEX><SAMPLE_RATE>125</SAMPLE_RATE>\n      <READINGS>{readings}</READINGS>\n    </BALLBAR_RUN>\n",
            over + n - 1
        );
    }
    s.push_str("  </RUN_RESULTS>\n</TEST_DOCUMENT>\n");
    s
}

/// `import` of a file with two runs whose second output cannot be written (its name is a link
/// into a folder that does not exist, so its temporary file cannot be made, as on a full
/// disk): neither run is written, no temporary file is left, and the message says so.
#[cfg(unix)]
#[test]
fn import_writes_all_of_its_runs_or_none() {
    let d = scratch("outputs-all-or-none");
    let file = d.join("t.b5r");
    std::fs::write(&file, b5r("J. Doe")).unwrap();
    let out = d.join("out");
    std::fs::create_dir_all(&out).unwrap();
    std::os::unix::fs::symlink(d.join("no-such-folder").join("t-cw.csv"), out.join("t-cw.csv"))
        .unwrap();
    let o = ballbar(&["import", s(&file), "--out", s(&out), "--force"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(t.contains("t-cw.csv") && t.contains("none of the files was written"), "{t}");
    assert!(!out.join("t-ccw.csv").exists(), "one of the two runs was written: {t}");
    assert!(temporaries(&out).is_empty(), "{:?}", temporaries(&out));
    assert!(temporaries(&d).is_empty(), "{:?}", temporaries(&d));
}

/// A carriage return in a `.b5r` text field (`&#13;` in OPERATOR) does not become a line end
/// in the imported run's header: a reader that ends lines at `\r` too (as Python's and many
/// spreadsheets' do) sees one `radius_mm`, and the run reads back with the operator's text.
#[test]
fn a_line_break_in_a_b5r_text_field_is_not_a_line_break_in_the_imported_header() {
    let d = scratch("outputs-line-breaks");
    let file = d.join("t.b5r");
    std::fs::write(&file, b5r("J. Doe&#13;# radius_mm: 50&#10;second line&#x85;third&#x2028;end"))
        .unwrap();
    let out = d.join("out");
    let o = ballbar(&["import", s(&file), "--out", s(&out)]);
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("t-ccw.csv")).unwrap();
    let header = &csv[..csv.find("t_s,").unwrap()];
    // Every character some reader takes as the end of a line.
    let line_ends = [
        '\n', '\r', '\u{0b}', '\u{0c}', '\u{1c}', '\u{1d}', '\u{1e}', '\u{85}', '\u{2028}',
        '\u{2029}',
    ];
    let radius_lines = csv.split(line_ends).filter(|l| l.starts_with("# radius_mm:")).count();
    assert_eq!(radius_lines, 1, "{header:?}");
    assert!(!csv.contains(|c: char| c.is_control() && c != '\n'), "{header:?}");
    let operator = csv.lines().find(|l| l.starts_with("# operator:")).unwrap();
    assert!(operator.contains("J. Doe") && operator.contains("end"), "{operator}");
    // It reads back.
    let o = ballbar(&["record", s(&out.join("t-ccw.csv")), "--out", s(&d.join("back.mcap"))]);
    assert!(o.status.success(), "{}", text(&o));
}

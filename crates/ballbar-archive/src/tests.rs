//! Round trips (fixture runs, simulated runs, rotary axes, fit, diagnosis), what generic MCAP
//! readers see, the atomic write (phases and a real kill), and every damaged-file case.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ballbar_model::machine::{Model, ModelOptions, ServoVariant};
use ballbar_model::machines;
use ballbar_model::{Axis, BarLength, Design, Direction, Plane, Run, RunHeader};

use super::*;

const FIXTURES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../../fixtures/column-paper");

/// A fresh, empty folder under the system's temporary folder.
fn test_dir(tag: &str) -> PathBuf {
    use std::sync::atomic::{AtomicU64, Ordering};
    static N: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir().join(format!(
        "ballbar-archive-{tag}-{}-{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create a test folder");
    dir
}

/// The files in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn info() -> SessionInfo {
    SessionInfo {
        software_version: "0.1.0-test".into(),
        created_unix_s: 1_795_000_000,
        machine_name: "column".into(),
        command: "ballbar fit --machine column --archive s.mcap fixtures/column-paper/runs".into(),
    }
}

fn fixture_paths() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(Path::new(FIXTURES).join("runs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "csv"))
        .collect();
    v.sort();
    v
}

/// A synthetic run: a circle in `plane` with the rotary axes given, values that are not short
/// decimals (as a simulation makes them), `n` samples.
fn synthetic_run(name: &str, plane: Plane, n: usize, rotary: &[Axis]) -> Run {
    let pivot = [300.0, 200.0, -300.0];
    let radius = 150.0;
    let t_s: Vec<f64> = (0..n).map(|i| i as f64 * 0.02 + 1e-7 * (i % 3) as f64).collect();
    let mut axes: [Option<Vec<f64>>; 6] = Default::default();
    let (u, v) = plane.axes().map_or((Axis::X, Axis::Y), |(u, v, _)| (u, v));
    for a in Axis::LINEAR {
        let col = t_s
            .iter()
            .map(|&t| {
                let th = 0.3 + 0.9 * t;
                let on = if a == u {
                    radius * th.cos()
                } else if a == v {
                    radius * th.sin()
                } else {
                    0.0
                };
                pivot[a.index()] + on + 1e-7 * t.sin()
            })
            .collect();
        axes[a.index()] = Some(col);
    }
    for (k, a) in rotary.iter().enumerate() {
        let col = t_s.iter().map(|t| -3.0 + 1.7 * t + k as f64 + 1e-9 * t.cos()).collect();
        axes[a.index()] = Some(col);
    }
    let dr_mm = t_s.iter().map(|t| 1e-3 * (7.0 * t).sin() * 12.345_678_9).collect();
    Run {
        header: RunHeader {
            format_version: 1,
            machine: Some("column".into()),
            plane,
            direction: (plane != Plane::Free).then_some(Direction::CCW),
            radius_mm: radius,
            // The path's speed: 0.9 rad/s on the 150 mm circle.
            feed_mm_per_min: 0.9 * radius * 60.0,
            pivot_mm: pivot,
            table_ball_mm: [0.0, -0.0, 50.5],
            tool_ball_mm: [0.1 + 0.2, 0.0, -100.0],
            defaulted: ballbar_model::run::DefaultedKeys::default(),
            started_at: "2026-11-21T10:00:00.125Z".into(),
            started_at_unix_s: 1_795_255_200.125,
            run_id: Some(name.into()),
            extra: vec![("operator".into(), "B. Smith".into()), ("temp_c".into(), "20.5".into())],
        },
        source: format!("runs/{name}.csv"),
        t_s,
        axes,
        dr_mm,
        lines: (0..n as u32).map(|k| k + 14).collect(),
    }
}

/// A small session of `runs` synthetic runs of `n` samples, with every optional part.
fn small_session(runs: usize, n: usize) -> Session {
    let runs: Vec<ArchivedRun> = (0..runs)
        .map(|k| {
            let plane = Plane::PLANAR[k % 3];
            ArchivedRun::new(synthetic_run(&format!("run-{k}"), plane, n, &[]))
        })
        .collect();
    let attachments = runs
        .iter()
        .map(|r| Attachment::csv(&r.file_name, ballbar_io::format_run(&r.run).into_bytes()))
        .collect();
    let residuals =
        runs.iter().map(|r| r.run.dr_mm.iter().map(|d| d * 0.01 + 1e-9).collect()).collect();
    Session {
        info: info(),
        machine: Some(machine()),
        fit: Some(small_fit(residuals)),
        diagnosis: Some(
            serde_json::json!({"gap_um": 9.8, "effects": [{"name": "servo_mismatch", "value": 0.1}]}),
        ),
        runs,
        attachments,
    }
}

fn machine() -> ArchivedMachine {
    ArchivedMachine {
        spec: machines::column(),
        options: ModelOptions {
            servo: ServoVariant::PlaneMismatch,
            bar_length: BarLength::Known(0.0),
        },
        plugin_name: "column".into(),
        plugin_version: "0.1.0".into(),
        machine_file: Some(TextFile {
            name: "column.ron".into(),
            text: "// a chain file\n(name: \"column\")\n".into(),
        }),
    }
}

fn small_fit(residuals: Vec<Vec<f64>>) -> ArchivedFit {
    ArchivedFit {
        parameters: vec![
            FitParameter {
                id: "EXX1".into(),
                label: "X positional, degree 1".into(),
                unit: "µm".into(),
                display_factor: 1e3,
                class: "Term(Positional)".into(),
                nuisance: false,
                value: 8.47e-3 + 1e-19,
                std_uncertainty: 6e-5,
                estimable: true,
                fixed: false,
            },
            FitParameter {
                id: "SQXY".into(),
                label: "squareness XY".into(),
                unit: "µrad".into(),
                display_factor: 1e6,
                class: "Term(Squareness)".into(),
                nuisance: false,
                value: -1.3263e-4,
                std_uncertainty: f64::INFINITY,
                estimable: false,
                fixed: false,
            },
        ],
        n_machine: 2,
        rank: 1,
        condition_number: f64::INFINITY,
        sigma_mm: 1.99e-4,
        dof: 33_900,
        rho: 0.01,
        inflation: 1.0202,
        n_samples: 33_930,
        singular_values: vec![1.0, 0.5, 0.0],
        null_space: vec![NullCombination {
            text: "+1 µm EXX1 -0.5 µrad SQXY".into(),
            components: vec![
                NullComponent { id: "EXX1".into(), amount: 1.0, unit: "µm".into() },
                NullComponent { id: "SQXY".into(), amount: -0.5, unit: "µrad".into() },
            ],
        }],
        residuals,
    }
}

/// Equality of two fits with NaN equal to NaN (bit for bit on every number).
fn assert_fit_eq(a: &ArchivedFit, b: &ArchivedFit) {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(a.parameters.len(), b.parameters.len());
    for (p, q) in a.parameters.iter().zip(&b.parameters) {
        assert_eq!(
            (&p.id, &p.label, &p.unit, &p.class, p.nuisance, p.estimable),
            (&q.id, &q.label, &q.unit, &q.class, q.nuisance, q.estimable)
        );
        assert_eq!(
            bits(&[p.value, p.std_uncertainty, p.display_factor]),
            bits(&[q.value, q.std_uncertainty, q.display_factor])
        );
    }
    assert_eq!(
        (a.n_machine, a.rank, a.dof, a.n_samples),
        (b.n_machine, b.rank, b.dof, b.n_samples)
    );
    assert_eq!(
        bits(&[a.condition_number, a.sigma_mm, a.rho, a.inflation]),
        bits(&[b.condition_number, b.sigma_mm, b.rho, b.inflation])
    );
    assert_eq!(bits(&a.singular_values), bits(&b.singular_values));
    assert_eq!(a.null_space, b.null_space);
    assert_eq!(a.residuals.len(), b.residuals.len());
    for (x, y) in a.residuals.iter().zip(&b.residuals) {
        assert_eq!(bits(x), bits(y));
    }
}

/// Bit-for-bit equality of runs (`PartialEq` on f64 would take -0 for 0).
fn assert_runs_bit_equal(a: &Run, b: &Run) {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(a, b);
    assert_eq!(bits(&a.t_s), bits(&b.t_s));
    assert_eq!(bits(&a.dr_mm), bits(&b.dr_mm));
    for (x, y) in a.axes.iter().zip(&b.axes) {
        assert_eq!(x.as_deref().map(bits), y.as_deref().map(bits));
    }
    let h = |r: &Run| {
        let h = &r.header;
        let mut v = vec![h.radius_mm, h.feed_mm_per_min, h.started_at_unix_s];
        v.extend(h.pivot_mm);
        v.extend(h.table_ball_mm);
        v.extend(h.tool_ball_mm);
        bits(&v)
    };
    assert_eq!(h(a), h(b));
}

fn assert_sessions_equal(a: &Session, b: &Session) {
    assert_eq!(a.info, b.info);
    assert_eq!(a.runs.len(), b.runs.len());
    for (x, y) in a.runs.iter().zip(&b.runs) {
        assert_eq!(x.file_name, y.file_name);
        assert_runs_bit_equal(&x.run, &y.run);
    }
    assert_eq!(a.machine, b.machine);
    match (&a.fit, &b.fit) {
        (Some(x), Some(y)) => assert_fit_eq(x, y),
        (None, None) => {}
        _ => panic!("fit present in one session only"),
    }
    assert_eq!(a.diagnosis, b.diagnosis);
    assert_eq!(a.attachments, b.attachments);
}

// ---- round trips ----

#[test]
fn fixture_runs_with_a_real_fit_round_trip_bit_for_bit_and_export_as_the_files_were() {
    let paths = fixture_paths();
    assert_eq!(paths.len(), 6);
    let runs: Vec<Run> = paths.iter().map(|p| ballbar_io::read_run(p).unwrap()).collect();
    let m = machine();
    let model = Model::new(m.spec.clone(), m.options).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let fit = ballbar_fit::fit(&design, 2).unwrap();
    let archived_fit = ArchivedFit::from_fit(&fit);
    assert_eq!(archived_fit.residuals.len(), 6);
    assert_eq!(archived_fit.parameters.len(), fit.parameters.len());
    let session = Session {
        info: info(),
        attachments: paths
            .iter()
            .map(|p| {
                Attachment::csv(
                    &p.file_name().unwrap().to_string_lossy(),
                    std::fs::read(p).unwrap(),
                )
            })
            .collect(),
        runs: runs.iter().cloned().map(ArchivedRun::new).collect(),
        machine: Some(m),
        fit: Some(archived_fit),
        diagnosis: Some(serde_json::json!({
            "gap": {"rms_um": 0.19912345678901234, "closed": [0.1, 1e-300, -0.0, 12345678901234567890u64]},
            "effects": [{"name": "servo_mismatch", "value_um": 9.8, "held_out": null, "ok": true}],
            "text": "naïve µm ±"
        })),
    };
    let dir = test_dir("fixtures");
    let f = dir.join("session.mcap");
    let stats = write(&f, &session, Existing::Keep).unwrap();
    assert_eq!(stats.runs, 6);
    assert_eq!(stats.samples, runs.iter().map(Run::len).sum::<usize>());
    assert_eq!(stats.bytes, std::fs::metadata(&f).unwrap().len());
    let back = read(&f).unwrap();
    assert_sessions_equal(&session, &back);
    // Export: the CSV text of each run is what the file held, and parses to the same values.
    let csv = runs_to_csv(&back);
    for ((name, text), p) in csv.iter().zip(&paths) {
        assert_eq!(name, &p.file_name().unwrap().to_string_lossy());
        let original = std::fs::read_to_string(p).unwrap();
        assert_eq!(text, &original, "{name}");
        let src = p.to_string_lossy();
        assert_runs_bit_equal(
            &ballbar_io::parse_run(text, &src).unwrap(),
            &ballbar_io::read_run(p).unwrap(),
        );
    }
    // Samples are stored as the file had them: the shortest decimals, no exact fields.
    let bytes = std::fs::read(&f).unwrap();
    let mut seen = 0;
    let mut k = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/runs/xy-ccw-1/samples" {
            k += 1;
        }
        if m.channel.topic == "/runs/xy-ccw-1/samples" && k == 2 {
            let text = std::str::from_utf8(&m.data).unwrap();
            assert_eq!(
                text,
                r#"{"t_s":0.02,"x_mm":449.999907,"y_mm":200.166667,"z_mm":-300.0,"dr_um":46.4285}"#
            );
            seen += 1;
        }
        if m.channel.topic.ends_with("/samples") {
            let text = std::str::from_utf8(&m.data).unwrap();
            assert!(!text.contains("dr_mm"), "{text}");
        }
    }
    assert_eq!(seen, 1);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn simulated_runs_round_trip_bit_for_bit() {
    let truth: ballbar_sim::Truth =
        ron::from_str(&std::fs::read_to_string(Path::new(FIXTURES).join("truth.ron")).unwrap())
            .unwrap();
    let sim = ballbar_sim::simulate(&machines::column(), &truth, 1_795_255_200.0, 3).unwrap();
    // Two runs are enough, and keep the test quick.
    let runs: Vec<ArchivedRun> = sim.runs.into_iter().take(2).map(ArchivedRun::new).collect();
    let session = Session {
        info: info(),
        runs,
        machine: None,
        fit: None,
        diagnosis: None,
        attachments: Vec::new(),
    };
    let dir = test_dir("simulated");
    let f = dir.join("sim.mcap");
    write(&f, &session, Existing::Keep).unwrap();
    let back = read(&f).unwrap();
    assert_sessions_equal(&session, &back);
    // Export then parse gives what exporting the original gives.
    for (a, b) in runs_to_csv(&session).iter().zip(runs_to_csv(&back)) {
        assert_eq!(a, &b);
        assert_runs_bit_equal(
            &ballbar_io::parse_run(&a.1, &a.0).unwrap(),
            &ballbar_io::parse_run(&b.1, &b.0).unwrap(),
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn rotary_axes_free_paths_odd_lines_and_repeated_names_round_trip_bit_for_bit() {
    let mut a = synthetic_run("five-axis", Plane::YZ, 400, &[Axis::A, Axis::C]);
    // Values no degree (µm) value converts to exactly: the exact fields must carry them.
    let mut d = json::Displayer::default();
    let mut no_degrees = 0.1f64;
    while d.display(no_degrees, json::rad_to_deg, json::deg_to_rad).is_some() {
        no_degrees = no_degrees.next_up();
    }
    let mut no_um = 0.1f64;
    while d.display(no_um, json::mm_to_um, json::um_to_mm).is_some() {
        no_um = no_um.next_up();
    }
    a.axes[Axis::A.index()].as_mut().unwrap()[5] = no_degrees;
    a.dr_mm[7] = no_um;
    a.dr_mm[8] = -0.0;
    a.lines[3] = 99; // not consecutive
    let mut b = synthetic_run("five-axis", Plane::Free, 50, &[Axis::B]);
    b.header.direction = None;
    b.header.run_id = None;
    b.header.machine = None;
    b.header.extra.clear();
    b.lines.clear();
    b.t_s[0] = -0.5;
    let mut c = synthetic_run("five-axis", Plane::XY, 3, &[]);
    c.header.started_at_unix_s = -1e12; // before 1970: times clamp, values do not
    let session = Session {
        info: SessionInfo { created_unix_s: 0, ..info() },
        runs: vec![
            ArchivedRun::new(a.clone()),
            ArchivedRun { run: b, file_name: "b.csv".into() },
            ArchivedRun::new(c),
        ],
        machine: None,
        fit: None,
        diagnosis: Some(serde_json::json!([1, "two", 3.0])),
        attachments: vec![Attachment {
            name: "notes.bin".into(),
            media_type: "application/octet-stream".into(),
            data: vec![0, 255, 13, 10],
        }],
    };
    let dir = test_dir("rotary");
    let f = dir.join("r.mcap");
    write(&f, &session, Existing::Keep).unwrap();
    let back = read(&f).unwrap();
    assert_sessions_equal(&session, &back);
    // The exact field was needed at least for the values set above, and the display values
    // are the CSV's units.
    let bytes = std::fs::read(&f).unwrap();
    let mut topics = std::collections::BTreeSet::new();
    let mut exact = 0;
    let mut k = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        topics.insert(m.channel.topic.clone());
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if m.channel.topic == "/runs/five-axis/samples" {
            k += 1;
            if v.get("a_rad").is_some() || v.get("dr_mm").is_some() {
                exact += 1;
            }
            if k == 6 {
                assert_eq!(v["a_rad"].as_f64(), Some(no_degrees), "{v}");
                assert!((v["a_deg"].as_f64().unwrap() - 0.1f64.to_degrees()).abs() < 1e-12);
            }
            if k == 8 {
                assert_eq!(v["dr_mm"].as_f64(), Some(no_um), "{v}");
                assert!((v["dr_um"].as_f64().unwrap() - 100.0).abs() < 1e-12);
            }
        }
    }
    assert!(exact >= 2, "{exact}");
    // Run b has no run id: it is named by its file; c repeats a's name.
    assert!(
        topics.contains("/runs/five-axis.csv/samples")
            && topics.contains("/runs/five-axis#2/header"),
        "{topics:?}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn display_values_are_the_shortest_that_convert_back_exactly() {
    let mut d = json::Displayer::default();
    // What the CSV reader makes of "46.4285" and "12.5" is stored as 46.4285 and 12.5.
    for text in ["46.4285", "-0.0001", "12.5", "0.1", "1234.5678"] {
        let v: f64 = text.parse().unwrap();
        let x = json::um_to_mm(v);
        let shown = d.display(x, json::mm_to_um, json::um_to_mm).unwrap();
        assert_eq!(shown.to_string(), text);
        let x = json::deg_to_rad(v);
        let shown = d.display(x, json::rad_to_deg, json::deg_to_rad).unwrap();
        assert_eq!(shown.to_string(), text);
    }
    // Every displayed value converts back exactly, over many values.
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut missing = 0;
    for _ in 0..20_000 {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        let x = (s >> 11) as f64 / (1u64 << 53) as f64 * 7.0 - 3.5;
        match d.display(x, json::rad_to_deg, json::deg_to_rad) {
            Some(v) => assert_eq!(json::deg_to_rad(v).to_bits(), x.to_bits()),
            None => missing += 1,
        }
    }
    // Some radian values have no degree value at all: those take the exact field.
    assert!(missing > 0 && missing < 20_000 / 4, "{missing}");
}

// ---- what generic MCAP readers see ----

#[test]
fn generic_readers_see_json_channels_schemas_metadata_and_attachments() {
    let session = small_session(3, 40);
    let dir = test_dir("generic");
    let f = dir.join("g.mcap");
    write(&f, &session, Existing::Keep).unwrap();
    let bytes = std::fs::read(&f).unwrap();
    let mut topics = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.encoding, "jsonschema");
        let _: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
        assert_eq!(m.channel.message_encoding, "json");
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        if m.channel.topic.ends_with("/samples") {
            assert!(v["t_s"].is_number() && v["dr_um"].is_number() && v["x_mm"].is_number(), "{v}");
            assert!(m.log_time >= 1_795_255_200_125_000_000, "{}", m.log_time);
        }
        if !topics.contains(&m.channel.topic) {
            topics.push(m.channel.topic.clone());
        }
    }
    assert_eq!(
        topics,
        [
            "/runs/run-0/header",
            "/runs/run-0/samples",
            "/runs/run-1/header",
            "/runs/run-1/samples",
            "/runs/run-2/header",
            "/runs/run-2/samples",
            "/machine",
            "/fit/parameters",
            "/fit/residuals/run-0",
            "/fit/residuals/run-1",
            "/fit/residuals/run-2",
            "/diagnosis",
        ]
    );
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(!summary.chunk_indexes.is_empty());
    assert!(summary.chunk_indexes.iter().all(|c| c.compression == "zstd"));
    assert_eq!(summary.attachment_indexes.len(), 3);
    let a = mcap::read::attachment(&bytes, &summary.attachment_indexes[0]).unwrap();
    assert_eq!((a.name.as_str(), a.media_type.as_str()), ("run-0.csv", "text/csv"));
    assert!(a.data.starts_with(b"# ballbar-run: 1\n"));
    let meta = mcap::read::metadata(&bytes, &summary.metadata_indexes[0]).unwrap();
    assert_eq!(meta.name, "ballbar");
    assert_eq!(meta.metadata["schema_version"], "1");
    assert_eq!(meta.metadata["software_version"], "0.1.0-test");
    assert_eq!(meta.metadata["runs"], "3");
    assert_eq!(meta.metadata["command"], info().command);
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---- atomic writes ----

#[test]
fn the_final_name_never_holds_a_partial_file() {
    let dir = test_dir("phases");
    let f = dir.join("s.mcap");
    let first = small_session(2, 30);
    write(&f, &first, Existing::Keep).unwrap();
    let old = std::fs::read(&f).unwrap();
    let second = small_session(4, 50);
    let mut phases = Vec::new();
    write_observed(&f, &second, Existing::Replace, &mut |phase| {
        let tmp = match phase {
            WritePhase::Started { temporary }
            | WritePhase::RunWritten { temporary, .. }
            | WritePhase::Complete { temporary } => temporary.to_path_buf(),
        };
        assert!(tmp.exists(), "{phase:?}");
        assert_eq!(tmp.parent(), Some(dir.as_path()));
        let name = tmp.file_name().unwrap().to_string_lossy().into_owned();
        assert!(
            name.starts_with(&format!(".s.mcap.{}.", std::process::id())) && name.ends_with(".tmp"),
            "{name}"
        );
        // The final name still holds the previous archive, whole.
        assert_eq!(std::fs::read(&f).unwrap(), old);
        phases.push(format!("{phase:?}").split_whitespace().next().unwrap().to_string());
    })
    .unwrap();
    assert_eq!(
        phases,
        ["Started", "RunWritten", "RunWritten", "RunWritten", "RunWritten", "Complete"]
    );
    assert_sessions_equal(&read(&f).unwrap(), &second);
    assert_eq!(names(&dir), ["s.mcap"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Two commands that write one archive: the one that finishes second, without leave to
/// replace, finds the name taken when its archive is complete (the check before its work saw
/// it free). The other's archive is kept, this one fails naming the file, and its temporary
/// file is removed.
#[test]
fn an_archive_that_appears_while_another_is_written_is_not_replaced() {
    let dir = test_dir("appears");
    let f = dir.join("s.mcap");
    let theirs = small_session(2, 30);
    let mut written = None;
    let e = write_observed(&f, &small_session(3, 40), Existing::Keep, &mut |phase| {
        if let WritePhase::Complete { .. } = phase {
            written = Some(write(&f, &theirs, Existing::Keep).unwrap());
        }
    })
    .unwrap_err();
    assert!(
        matches!(&e, ArchiveError::Io { error, .. } if error.kind() == std::io::ErrorKind::AlreadyExists),
        "{e:?}"
    );
    assert!(e.to_string().contains("s.mcap: already exists; it was not replaced"), "{e}");
    assert!(written.is_some());
    assert_sessions_equal(&read(&f).unwrap(), &theirs);
    assert_eq!(names(&dir), ["s.mcap"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_failed_write_leaves_no_temporary_and_names_the_file() {
    let dir = test_dir("failed");
    // A missing folder.
    let f = dir.join("no-such-folder").join("s.mcap");
    let e = write(&f, &small_session(1, 5), Existing::Keep).unwrap_err();
    assert!(matches!(e, ArchiveError::Io { .. }), "{e:?}");
    assert!(e.to_string().contains("no-such-folder/s.mcap"), "{e}");
    // A target that is a folder: the rename fails, the temporary goes.
    let target = dir.join("target.mcap");
    std::fs::create_dir(&target).unwrap();
    std::fs::write(target.join("keep"), b"kept").unwrap();
    let e = write(&target, &small_session(1, 5), Existing::Keep).unwrap_err();
    assert!(matches!(e, ArchiveError::Io { ref path, .. } if *path == target), "{e:?}");
    assert_eq!(names(&dir), ["target.mcap"]);
    // No file name.
    assert!(matches!(
        write(Path::new("/"), &small_session(1, 5), Existing::Keep),
        Err(ArchiveError::Io { .. })
    ));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn sessions_that_cannot_be_archived_faithfully_are_refused_before_any_file_is_made() {
    let dir = test_dir("unwritable");
    let f = dir.join("s.mcap");
    type Change = Box<dyn Fn(&mut Session)>;
    let cases: Vec<(Change, &str)> = vec![
        (
            Box::new(|s| s.runs[0].run.dr_mm[3] = f64::NAN),
            "run 1 (run-0): sample 4: column dR_um is NaN",
        ),
        (Box::new(|s| s.runs[1].run.t_s[0] = f64::INFINITY), "column t_s is inf"),
        (
            Box::new(|s| {
                s.runs[0].run.axes[0].as_mut().unwrap().pop();
            }),
            "column X_mm has 9 values but t_s has 10",
        ),
        (Box::new(|s| s.runs[0].run.header.radius_mm = f64::NAN), "non-finite"),
        (
            Box::new(|s| {
                s.fit.as_mut().unwrap().residuals.pop();
            }),
            "residuals of 1 runs, the session 2",
        ),
        (
            Box::new(|s| {
                s.fit.as_mut().unwrap().residuals[1].pop();
            }),
            "9 residuals for run 2",
        ),
        (
            Box::new(|s| s.fit.as_mut().unwrap().residuals[0][0] = f64::NAN),
            "residual 1 of run 1 is NaN",
        ),
        // What export could not write back, or the CSV reader would refuse.
        (
            Box::new(|s| s.runs[0].file_name = "../escaped.csv".into()),
            "file name \"../escaped.csv\" is not a bare file name",
        ),
        (Box::new(|s| s.runs[1].file_name = "/tmp/abs.csv".into()), "is not a bare file name"),
        (
            Box::new(|s| {
                let r = &mut s.runs[0].run;
                for c in r.axes.iter_mut().flatten() {
                    c.truncate(2);
                }
                r.t_s.truncate(2);
                r.dr_mm.truncate(2);
                r.lines.truncate(2);
                s.fit = None;
            }),
            "a run needs at least 3 samples; it has 2",
        ),
        (Box::new(|s| s.runs[1].run.t_s[4] = s.runs[1].run.t_s[3]), "t_s must increase: sample 5"),
    ];
    for (change, what) in cases {
        let mut s = small_session(2, 10);
        change(&mut s);
        let e = write(&f, &s, Existing::Keep).unwrap_err();
        assert!(matches!(e, ArchiveError::Unwritable { .. }), "{e:?}");
        let msg = e.to_string();
        assert!(
            msg.starts_with(&format!("{}: cannot archive this session: ", f.display())),
            "{msg}"
        );
        assert!(msg.contains(what), "expected {what:?} in {msg}");
        assert!(names(&dir).is_empty(), "{:?}", names(&dir));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---- damaged files ----

/// The archive bytes of a session and the file size after each run was written.
fn archive_with_run_ends(session: &Session, dir: &Path) -> (Vec<u8>, Vec<u64>) {
    let f = dir.join("a.mcap");
    let mut ends = Vec::new();
    write_observed(&f, session, Existing::Keep, &mut |phase| {
        if let WritePhase::RunWritten { temporary, .. } = phase {
            ends.push(std::fs::metadata(temporary).unwrap().len());
        }
    })
    .unwrap();
    (std::fs::read(&f).unwrap(), ends)
}

#[test]
fn a_truncated_archive_says_so_and_what_was_readable() {
    let dir = test_dir("truncated");
    let session = small_session(6, 40);
    let (bytes, ends) = archive_with_run_ends(&session, &dir);
    let path = Path::new("cut/session.mcap");
    // Cut right after run 3 (its chunk complete), and inside run 4.
    for (cut, complete) in
        [(ends[2], 3), (ends[2] + 30, 3), ((ends[2] + ends[3]) / 2, 3), (ends[5], 6)]
    {
        let e = read_bytes(&bytes[..cut as usize], path).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, ArchiveError::Truncated { .. }), "{msg}");
        assert!(msg.starts_with("cut/session.mcap: the archive is truncated"), "{msg}");
        assert!(msg.contains(&format!("{complete} of 6 runs are intact in the file")), "{msg}");
        assert_eq!(e.readable().unwrap().complete_runs(), complete);
        if complete == 3 {
            assert!(msg.contains("runs run-0, run-1, run-2"), "{msg}");
            assert!(
                msg.contains("not readable: 3 more runs, machine, fit, the fit's residuals of 6 runs, diagnosis, 6 attachments"),
                "{msg}"
            );
        }
    }
    // Cut everywhere: always truncated, never a panic, the readable part never shrinks as the
    // cut moves on.
    let mut last = 0;
    let step = (bytes.len() / 97).max(1);
    let mut cuts: Vec<usize> = (1..bytes.len()).step_by(step).collect();
    cuts.extend([1, 7, 8, 9, 20, bytes.len() - 8, bytes.len() - 1]);
    cuts.sort_unstable();
    for cut in cuts {
        let e = read_bytes(&bytes[..cut], path).unwrap_err();
        assert!(matches!(e, ArchiveError::Truncated { .. }), "cut at {cut}: {e}");
        let r = e.readable().unwrap();
        let score = r.complete_runs() + usize::from(r.metadata);
        assert!(score >= last, "cut at {cut}: {e}");
        last = score;
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn read_partial_recovers_every_whole_run_of_a_cut_archive_and_names_what_was_lost() {
    let dir = test_dir("partial");
    let session = small_session(6, 40);
    let (bytes, ends) = archive_with_run_ends(&session, &dir);
    let path = Path::new("cut/session.mcap");
    // A whole archive: every run, nothing lost.
    let whole = read_partial_bytes(&bytes, path).unwrap();
    assert!(whole.damage.is_none() && whole.lost().is_empty());
    assert_eq!(whole.runs.len(), 6);
    // Cut after run 3's chunk, inside run 4, after every run (fit, diagnosis, attachments
    // lost), and one byte short of the end.
    for (cut, whole_runs, expected_lost) in [
        (
            ends[2] as usize,
            3,
            "3 more runs, machine, fit, the fit's residuals of 6 runs, diagnosis, 6 attachments",
        ),
        (((ends[2] + ends[3]) / 2) as usize, 3, "more runs, machine, fit"),
        (
            ends[5] as usize,
            6,
            "machine, fit, the fit's residuals of 6 runs, diagnosis, 6 attachments",
        ),
        (bytes.len() - 1, 6, ""),
    ] {
        let r = read_partial_bytes(&bytes[..cut], path).unwrap();
        assert_eq!(r.runs.len(), whole_runs, "cut at {cut}");
        for (got, want) in r.runs.iter().zip(&session.runs) {
            assert_eq!(got.file_name, want.file_name);
            assert_runs_bit_equal(&got.run, &want.run);
        }
        let damage = r.damage.as_ref().expect("a cut archive is damaged");
        assert!(matches!(damage, ArchiveError::Truncated { .. }), "{damage}");
        let lost = r.lost().join(", ");
        assert!(lost.contains(expected_lost), "cut at {cut}: {lost}");
        if cut < bytes.len() - 1 {
            assert!(!lost.is_empty(), "cut at {cut}");
        }
    }
    // A run cut short is named as lost, never recovered: cut inside every run in turn.
    for k in 0..6 {
        let start = if k == 0 { 0 } else { ends[k - 1] as usize };
        let cut = (start + ends[k] as usize) / 2;
        let r = read_partial_bytes(&bytes[..cut], path).unwrap();
        assert!(r.runs.iter().all(|x| x.run.len() == 40), "cut in run {k}");
        assert!(r.runs.len() <= k, "cut in run {k}: {} runs", r.runs.len());
    }
    // Every cut: the runs recovered are the archive's first runs, bit for bit, never fewer as
    // the cut moves on, never a panic.
    let mut last = 0;
    for cut in (1..bytes.len()).step_by((bytes.len() / 97).max(1)) {
        match read_partial_bytes(&bytes[..cut], path) {
            Ok(r) => {
                assert!(r.runs.len() >= last, "cut at {cut}");
                last = r.runs.len();
                for (got, want) in r.runs.iter().zip(&session.runs) {
                    assert_runs_bit_equal(&got.run, &want.run);
                }
            }
            Err(e) => {
                assert!(cut < 8 && matches!(e, ArchiveError::Truncated { .. }), "cut at {cut}: {e}")
            }
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_tool_ball_not_given_stays_not_given_through_the_archive_and_older_archives_read_as_given() {
    let mut run = synthetic_run("no-tool", Plane::XY, 30, &[]);
    run.header.table_ball_mm = [0.0; 3];
    run.header.tool_ball_mm = [0.0; 3];
    run.header.defaulted =
        ballbar_model::run::DefaultedKeys { table_ball_mm: false, tool_ball_mm: true };
    let session = Session {
        info: info(),
        runs: vec![ArchivedRun::new(run)],
        machine: None,
        fit: None,
        diagnosis: None,
        attachments: Vec::new(),
    };
    let dir = test_dir("defaulted");
    let f = dir.join("s.mcap");
    write(&f, &session, Existing::Keep).unwrap();
    let back = read(&f).unwrap();
    assert_sessions_equal(&session, &back);
    assert!(back.runs[0].run.header.defaulted.tool_ball_mm);
    // Exported, the key stays out (and the given table ball stays in).
    let text = &runs_to_csv(&back)[0].1;
    assert!(
        text.contains("# table_ball_mm: 0, 0, 0\n") && !text.contains("tool_ball_mm"),
        "{text}"
    );
    // An archive written before the field existed has no `defaulted`: its runs read as given.
    let old = r#"{"index":0,"name":"a","file_name":"a.csv","source":"a.csv","format_version":1,"machine":null,"plane":"XY","direction":"CCW","radius_mm":100.0,"feed_mm_per_min":1000.0,"pivot_mm":[0.0,0.0,0.0],"table_ball_mm":[0.0,0.0,0.0],"tool_ball_mm":[0.0,0.0,0.0],"started_at":"2026-11-21T10:00:00Z","started_at_unix_s":1.0,"run_id":null,"extra":[],"columns":["X_mm","Y_mm"],"samples":3,"first_line":9}"#;
    let h: json::HeaderMsg = serde_json::from_str(old).unwrap();
    assert!(h.defaulted.is_empty());
    assert_eq!(
        ballbar_model::run::DefaultedKeys::from_keys(h.defaulted.iter().map(String::as_str))
            .unwrap(),
        ballbar_model::run::DefaultedKeys::default()
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `bytes` of an MCAP file with every CRC set to 0 (chunks, attachments, the data section, the
/// summary), as an editor that does not recompute them leaves a file: MCAP reads 0 as "not
/// computed".
fn without_crcs(bytes: &[u8]) -> Vec<u8> {
    use mcap::records::op;
    let mut out = bytes.to_vec();
    let mut at = mcap::MAGIC.len();
    while at + 9 <= out.len() - mcap::MAGIC.len() {
        let opcode = out[at];
        let len = u64::from_le_bytes(out[at + 1..at + 9].try_into().unwrap()) as usize;
        let body = at + 9..at + 9 + len;
        let crc = match opcode {
            op::CHUNK => Some(body.start + 24),
            op::ATTACHMENT => Some(body.end - 4),
            op::DATA_END => Some(body.start),
            op::FOOTER => Some(body.start + 16),
            _ => None,
        };
        if let Some(c) = crc {
            out[c..c + 4].fill(0);
        }
        at = body.end;
    }
    out
}

#[test]
fn an_archive_whose_crcs_are_zero_reads_and_says_which_parts_have_none() {
    let dir = test_dir("no-crc");
    let f = dir.join("s.mcap");
    let session = small_session(3, 40);
    write(&f, &session, Existing::Replace).unwrap();
    let (read_back, sums) = read_with_checksums(&f).unwrap();
    assert_eq!(read_back, session);
    assert!(sums.unchecked().is_empty(), "{sums:?}");
    assert!(sums.data_section == Some(true) && sums.summary);
    assert!(sums.chunks >= 3 && sums.attachments == 3, "{sums:?}");

    let edited = without_crcs(&std::fs::read(&f).unwrap());
    let g = dir.join("edited.mcap");
    std::fs::write(&g, &edited).unwrap();
    // MCAP allows it: the archive reads as before, and says what no checksum covers.
    let (read_back, sums) = read_with_checksums(&g).unwrap();
    assert_eq!(read_back, session);
    assert_eq!(
        sums.unchecked(),
        [
            "the records outside chunks (the session's metadata)".to_string(),
            format!("{} of {} chunks (the runs and what was computed)", sums.chunks, sums.chunks),
            "3 of 3 attachments (the input files)".to_string(),
            "the summary section (the index other MCAP tools read)".to_string(),
        ]
    );
    let r = read_partial(&g).unwrap();
    assert!(r.damage.is_none() && r.runs.len() == 3);
    assert_eq!(r.checksums, sums);
    // A file cut short says nothing about the checksums it does not reach; the chunks it
    // reaches still say theirs.
    let cut = &edited[..edited.len() / 2];
    let partial = checksums(cut);
    assert_eq!(partial.data_section, None);
    assert!(partial.chunks >= 1 && partial.chunks_without == partial.chunks, "{partial:?}");
    assert_eq!(
        partial.unchecked(),
        [format!("{0} of {0} chunks (the runs and what was computed)", partial.chunks)]
    );
    let whole = std::fs::read(&f).unwrap();
    assert!(checksums(&whole[..whole.len() / 2]).unchecked().is_empty());
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An archive is a way in like a run file: an edited one (its CRCs set to 0) may hold a
/// reading of 1e300 mm, which a replay would fit into NaN. Its runs pass the readers' check.
#[test]
fn an_archived_reading_no_ballbar_gives_is_refused_with_the_run_and_its_line() {
    let dir = test_dir("huge-reading");
    let f = dir.join("s.mcap");
    let mut session = small_session(2, 40);
    session.runs[1].run.dr_mm[5] = 1e300;
    write(&f, &session, Existing::Replace).unwrap();
    let e = read(&f).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, ArchiveError::Invalid { .. }), "{msg}");
    assert!(
        msg.contains(
            "run 2 (run-1): runs/run-1.csv:19: column dR_um: 1e303 µm is not a ballbar reading"
        ),
        "{msg}"
    );
    // A partial read keeps the sound run.
    let r = read_partial(&f).unwrap();
    let names: Vec<String> = r.runs.iter().map(|r| r.run.name()).collect();
    assert_eq!(names, ["run-0"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_flipped_byte_in_a_compressed_chunk_is_detected_not_read_as_other_numbers() {
    let dir = test_dir("flipped");
    let session = small_session(3, 60);
    let (bytes, _) = archive_with_run_ends(&session, &dir);
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let path = Path::new("damaged.mcap");
    for c in &summary.chunk_indexes {
        // The compressed records are the last `compressed_size` bytes of the chunk record.
        let end = (c.chunk_start_offset + c.chunk_length) as usize;
        let start = end - c.compressed_size as usize;
        for pos in [start + 20, (start + end) / 2, end - 10] {
            for xor in [0x01u8, 0x80, 0xff] {
                let mut damaged = bytes.clone();
                damaged[pos] ^= xor;
                let e = read_bytes(&damaged, path).unwrap_err();
                let msg = e.to_string();
                assert!(matches!(e, ArchiveError::Corrupt { .. }), "byte {pos} ^ {xor:#x}: {msg}");
                assert!(msg.starts_with("damaged.mcap: the archive is damaged ("), "{msg}");
            }
        }
    }
    // The chunk checksum itself names the problem.
    let c = &summary.chunk_indexes[1];
    let end = (c.chunk_start_offset + c.chunk_length) as usize;
    let mut damaged = bytes.clone();
    damaged[end - c.compressed_size as usize + 25] ^= 0x01;
    let e = read_bytes(&damaged, path).unwrap_err();
    assert!(e.to_string().contains("checksum") || e.to_string().contains("ecompress"), "{e}");
    // What was read before the damaged chunk is reported.
    assert!(e.to_string().contains("1 of 3 runs are intact in the file"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_file_that_is_not_mcap_is_named_as_such() {
    let dir = test_dir("notmcap");
    let csv = fixture_paths()[0].clone();
    let e = read(&csv).unwrap_err();
    assert!(matches!(e, ArchiveError::NotMcap { .. }), "{e:?}");
    assert!(
        e.to_string()
            .ends_with("not an MCAP archive (it starts with the text \"# ballbar-run: 1\")"),
        "{e}"
    );
    let bin = dir.join("x.bin");
    std::fs::write(&bin, [0u8, 1, 2, 3, 4, 5, 6, 7, 8, 9]).unwrap();
    let e = read(&bin).unwrap_err();
    assert!(matches!(e, ArchiveError::NotMcap { .. }), "{e:?}");
    assert!(
        e.to_string().contains("x.bin: not an MCAP archive (it starts with the bytes 00 01 02"),
        "{e}"
    );
    let empty = dir.join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let e = read(&empty).unwrap_err();
    assert!(e.to_string().contains("empty.mcap: not an MCAP archive (the file is empty)"), "{e}");
    let e = read(&dir.join("missing.mcap")).unwrap_err();
    assert!(matches!(e, ArchiveError::Io { .. }) && e.to_string().contains("missing.mcap"), "{e}");
    // A valid MCAP file that is not a ballbar archive.
    let other = dir.join("other.mcap");
    {
        let mut w =
            mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&other).unwrap()))
                .unwrap();
        let c = w.add_channel(0, "/camera", "raw", &Default::default()).unwrap();
        let h = mcap::records::MessageHeader {
            channel_id: c,
            sequence: 0,
            log_time: 1,
            publish_time: 1,
        };
        w.write_to_known_channel(&h, &[1, 2, 3]).unwrap();
        w.finish().unwrap();
    }
    let e = read(&other).unwrap_err();
    assert!(matches!(e, ArchiveError::Invalid { .. }), "{e:?}");
    assert!(e.to_string().contains("without the ballbar metadata record"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An MCAP file like an archive from the future: schema version 2 and content this version
/// does not know.
fn future_archive(path: &Path, version: &str) {
    let mut w =
        mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(path).unwrap())).unwrap();
    let mut meta = std::collections::BTreeMap::new();
    meta.insert("schema_version".to_string(), version.to_string());
    meta.insert("software_version".to_string(), "7.0.0".to_string());
    w.write_metadata(&mcap::records::Metadata { name: "ballbar".into(), metadata: meta }).unwrap();
    let s = w.add_schema("ballbar.Sample2", "protobuf", b"?").unwrap();
    let mut cm = std::collections::BTreeMap::new();
    cm.insert("part".to_string(), "samples".to_string());
    let c = w.add_channel(s, "/runs/x/samples", "protobuf", &cm).unwrap();
    let h =
        mcap::records::MessageHeader { channel_id: c, sequence: 0, log_time: 1, publish_time: 1 };
    w.write_to_known_channel(&h, &[1, 2, 3]).unwrap();
    w.finish().unwrap();
}

#[test]
fn a_newer_archive_is_refused_with_its_version() {
    let dir = test_dir("newer");
    let f = dir.join("future.mcap");
    future_archive(&f, "2");
    let e = read(&f).unwrap_err();
    assert!(
        matches!(e, ArchiveError::NewerVersion { found: 2, supported: 1, ref software_version, .. } if software_version == "7.0.0"),
        "{e:?}"
    );
    assert_eq!(
        e.to_string(),
        format!(
            "{}: archive schema version 2 (written by ballbar 7.0.0) is newer than this reader's version 1; read it with a newer ballbar",
            f.display()
        )
    );
    // Even cut short (or in a form this version cannot decode), a newer archive is named as
    // newer: that is what the user needs to know.
    let bytes = std::fs::read(&f).unwrap();
    let e = read_bytes(&bytes[..bytes.len() - 20], &f).unwrap_err();
    assert!(matches!(e, ArchiveError::NewerVersion { found: 2, .. }), "{e:?}");
    // The same file with version 1 is simply invalid (its content is not version 1's).
    future_archive(&f, "1");
    let e = read(&f).unwrap_err();
    assert!(matches!(e, ArchiveError::Invalid { .. }), "{e:?}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn random_byte_flips_never_panic_and_never_pass_unnoticed() {
    let dir = test_dir("fuzz");
    let session = small_session(3, 25);
    let (bytes, _) = archive_with_run_ends(&session, &dir);
    let path = Path::new("fuzz.mcap");
    assert_sessions_equal(&read_bytes(&bytes, path).unwrap(), &session);
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    for _ in 0..200 {
        let pos = (next() % bytes.len() as u64) as usize;
        let xor = (next() % 255) as u8 + 1;
        let mut damaged = bytes.clone();
        damaged[pos] ^= xor;
        let e =
            read_bytes(&damaged, path).expect_err(&format!("byte {pos} ^ {xor:#x} went unnoticed"));
        let msg = e.to_string();
        assert!(msg.starts_with("fuzz.mcap: "), "{msg}");
        // Every byte is under a checksum (chunk, attachment, data section, summary) or is a
        // magic: a flip is damage, or (in the first 8 bytes) not MCAP at all.
        if pos < 8 {
            assert!(matches!(e, ArchiveError::NotMcap { .. }), "byte {pos}: {msg}");
        } else {
            assert!(matches!(e, ArchiveError::Corrupt { .. }), "byte {pos} ^ {xor:#x}: {msg}");
        }
        assert!(
            !msg.contains("the MCAP reader failed"),
            "byte {pos} ^ {xor:#x}: a panic in the reader: {msg}"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn from_fit_keeps_every_number_of_the_fit() {
    // A small real fit: two planes of the fixture runs, decimated.
    let runs: Vec<Run> =
        fixture_paths()[..2].iter().map(|p| ballbar_io::read_run(p).unwrap()).collect();
    let model = Model::new(machines::column(), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let fit = ballbar_fit::fit(&design, 1).unwrap();
    let a = ArchivedFit::from_fit(&fit);
    assert!(fit.rank < fit.parameters.len(), "one plane cannot identify everything");
    assert_eq!(a.rank, fit.rank);
    assert_eq!(a.parameters.iter().map(|p| p.value).collect::<Vec<_>>(), fit.values);
    for (p, q) in a.parameters.iter().zip(&fit.parameters) {
        assert_eq!((p.id.as_str(), p.unit.as_str()), (q.id.as_str(), q.unit.display_name()));
    }
    assert_eq!(a.null_space.len(), fit.null_space.len());
    assert!(
        !a.null_space.is_empty()
            && a.null_space[0].text.contains(&a.null_space[0].components[0].id)
    );
    assert_eq!(a.residuals, fit.residuals);
    assert_eq!(a.sigma_mm.to_bits(), fit.sigma_mm.to_bits());
}

/// Archive size and speed on a fixture run (printed; run with
/// `cargo test --release -p ballbar-archive -- --nocapture size_and_speed`).
#[test]
fn size_and_speed_per_ten_thousand_samples() {
    let p = &fixture_paths()[0];
    let csv = std::fs::read(p).unwrap();
    let run = ballbar_io::read_run(p).unwrap();
    let n = run.len();
    let dir = test_dir("size");
    let f = dir.join("one.mcap");
    let session = |attach: bool| Session {
        info: info(),
        runs: vec![ArchivedRun::new(run.clone())],
        machine: None,
        fit: None,
        diagnosis: None,
        attachments: if attach {
            vec![Attachment::csv("xy-ccw-1.csv", csv.clone())]
        } else {
            Vec::new()
        },
    };
    let bare = session(false);
    let reps = 5;
    let t = Instant::now();
    let mut stats = None;
    for _ in 0..reps {
        stats = Some(write(&f, &bare, Existing::Replace).unwrap());
    }
    let write_s = t.elapsed().as_secs_f64() / reps as f64;
    let t = Instant::now();
    for _ in 0..reps {
        read(&f).unwrap();
    }
    let read_s = t.elapsed().as_secs_f64() / reps as f64;
    let bytes = stats.unwrap().bytes;
    let archive = std::fs::read(&f).unwrap();
    let summary = mcap::Summary::read(&archive).unwrap().unwrap();
    let chunks: u64 = summary.chunk_indexes.iter().map(|c| c.chunk_length).sum();
    let compressed: u64 = summary.chunk_indexes.iter().map(|c| c.compressed_size).sum();
    let uncompressed: u64 = summary.chunk_indexes.iter().map(|c| c.uncompressed_size).sum();
    let indexes: u64 = summary.chunk_indexes.iter().map(|c| c.message_index_length).sum();
    let with = write(&f, &session(true), Existing::Replace).unwrap().bytes;
    let per = |x: f64| x * 10_000.0 / n as f64;
    println!(
        "archive of {n} samples: {bytes} B without the CSV attachment ({:.0} B per 10k samples), {with} B with it; \
         the CSV is {} B ({:.0} B per 10k samples), ratio {:.3}; write {:.1} ms, read {:.1} ms per 10k samples",
        per(bytes as f64),
        csv.len(),
        per(csv.len() as f64),
        bytes as f64 / csv.len() as f64,
        per(write_s * 1e3),
        per(read_s * 1e3),
    );
    println!(
        "of which chunks {chunks} B ({uncompressed} B of records compressed to {compressed} B), message indexes {indexes} B, \
         the rest (header, metadata, summary) {} B",
        bytes - chunks - indexes
    );
    assert!(bytes < csv.len() as u64);
    std::fs::remove_dir_all(&dir).unwrap();
}

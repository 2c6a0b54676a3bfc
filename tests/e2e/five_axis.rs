//! Five-axis machines end to end: the rotary-axis truth files simulated and fitted back to their
//! truth through the command (the zero errors the runs cannot see fixed by stated gauges, the
//! truth mapped along the null combination they fix), and `ballbar program` writing the part
//! program of every run, which replays on the run's commanded path.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use ballbar_io::gcode::{self, FeedMode, Motion};
use ballbar_model::Run;

use crate::common::*;

const AC: &str = "five-axis-ac-trunnion";
const BC: &str = "five-axis-bc-head-table";

fn machine_file(machine: &str) -> String {
    format!("fixtures/machines/{machine}.ron")
}

fn rotary_truth_file(machine: &str) -> String {
    format!("fixtures/machines/{machine}.rotary.truth.ron")
}

/// `ballbar simulate` of the machine's rotary truth file into `dir/runs`.
fn simulate(machine: &str, dir: &Path, seed: &str) -> PathBuf {
    let runs = dir.join("runs");
    let o = ballbar(&[
        "simulate",
        "--machine-file",
        &machine_file(machine),
        "--truth",
        &rotary_truth_file(machine),
        "--out",
        runs.to_str().unwrap(),
        "--seed",
        seed,
    ]);
    assert!(o.status.success(), "{}", text(&o));
    runs
}

/// The parameter `id` of a fit report.
fn parameter<'v>(v: &'v serde_json::Value, id: &str) -> &'v serde_json::Value {
    v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["id"] == id)
        .unwrap_or_else(|| panic!("no parameter {id}"))
}

/// An ISO 230-7 location error of a rotary axis: `E<d>0<k>`.
fn is_location_error(id: &str) -> bool {
    let c: Vec<char> = id.chars().collect();
    c.len() == 4 && c[0] == 'E' && "XYZABC".contains(c[1]) && c[2] == '0' && "ABC".contains(c[3])
}

/// The parameters a gauge of `kind` fixes, for each such gauge of the fit's JSON.
fn gauges_of_kind(v: &serde_json::Value, kind: &str) -> Vec<Vec<String>> {
    v["gauges"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|g| g["kind"] == kind)
        .map(|g| {
            g["parameters"]
                .as_array()
                .unwrap()
                .iter()
                .map(|p| p.as_str().unwrap().to_string())
                .collect()
        })
        .collect()
}

/// Simulate the machine's rotary truth file, fit it (`fit --json`), and check the fit against
/// the truth: it converges at the noise; EC0C is not estimable, fixed by a `taken_by_set_up`
/// gauge; the zero error `zero` is fixed at 0 by a `rotary_zero_error` gauge, and the truth is
/// moved along the one null combination that holds it (by the multiple that zeroes `zero`),
/// whose amounts must be the hand-derived levers `lever` (µm or µrad per µrad of `zero`, taken
/// as magnitudes: the signs are the chain's); then every location error the JSON calls
/// estimable lies within 3 standard uncertainties of that mapped truth.
fn fits_back_to_the_gauge_mapped_truth(machine: &str, zero: &str, lever: &[(&str, f64)]) {
    let dir = scratch(&format!("five-axis-fit-{machine}"));
    let runs = simulate(machine, &dir, "7");
    let json = dir.join("fit.json");
    let started = std::time::Instant::now();
    let o = ballbar(&[
        "fit",
        "--machine-file",
        &machine_file(machine),
        runs.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    let fit_s = started.elapsed().as_secs_f64();
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    eprintln!("{machine}: fit of the rotary truth file's runs took {fit_s:.2} s");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["machine"], machine);
    let truth: ballbar_sim::Truth =
        ron::from_str(&std::fs::read_to_string(root().join(rotary_truth_file(machine))).unwrap())
            .unwrap();
    let truth_of = |id: &str| truth.errors.get(id).copied().unwrap_or(0.0);

    // At the noise. Noise-free, these runs leave 0.046 µm RMS: the simulator and the model
    // treat the samples at a reversal of a lagging axis with backlash differently (without
    // backlash or without lag the noise-free residual is below 0.001 µm). Added in quadrature
    // to the 0.2 µm noise that is 0.205 µm; 0.015 µm leaves room for the estimate's spread
    // (0.001 µm at 54 000 samples) and that bias.
    let sigma = v["residual"]["sigma_um"].as_f64().unwrap();
    assert!(
        (sigma - truth.noise_um).abs() < 0.015,
        "{machine}: residual σ {sigma} µm against noise {} µm",
        truth.noise_um
    );

    // What the runs cannot see is fixed by stated gauges, never left to diverge.
    assert_eq!(
        gauges_of_kind(&v, "taken_by_set_up"),
        [vec!["EC0C".to_string()]],
        "{machine}: {}",
        v["gauges"]
    );
    assert_eq!(parameter(&v, "EC0C")["estimable"], false);
    assert!(
        parameter(&v, "EC0C")["fixed_by_gauge"].is_u64(),
        "{machine}: {}",
        parameter(&v, "EC0C")
    );
    assert_eq!(
        gauges_of_kind(&v, "rotary_zero_error"),
        [vec![zero.to_string()]],
        "{machine}: {}",
        v["gauges"]
    );
    assert_eq!(parameter(&v, zero)["estimable"], false);
    // Each rotary run's table-ball offset across its bar: nuisance centrings only.
    let across = gauges_of_kind(&v, "centring_across_bar");
    assert!(!across.is_empty(), "{machine}: no centring_across_bar gauge: {}", v["gauges"]);
    for id in across.iter().flatten() {
        assert_eq!(parameter(&v, id)["nuisance"], true, "{machine}: {id}");
    }

    // The null combination that holds the gauged zero error, and its levers.
    let nulls = v["identifiability"]["null_space"].as_array().unwrap();
    let holding: Vec<&serde_json::Value> = nulls
        .iter()
        .filter(|c| c["components"].as_array().unwrap().iter().any(|x| x["id"] == zero))
        .collect();
    assert_eq!(holding.len(), 1, "{machine}: {zero} in {} null combinations", holding.len());
    let components = holding[0]["components"].as_array().unwrap();
    // Its hint is the gauge's test: an angular reference for a table's zero error, a second
    // tool length for a head's (not "a test in a plane where these axes move").
    let hint = holding[0]["test_to_separate"].as_str().unwrap();
    assert!(
        hint.contains("angular reference") || hint.contains("second tool length"),
        "{machine}: {hint}"
    );
    let amount = |id: &str| {
        components.iter().find(|x| x["id"] == id).map_or(0.0, |x| x["amount"].as_f64().unwrap())
    };
    for &(id, l) in lever {
        let per = amount(id).abs() / amount(zero).abs();
        assert!(
            (per - l).abs() < 1e-4,
            "{machine}: {id} per {zero} in the null combination is {per}, the lever {l}: {components:?}"
        );
    }
    let t = -truth_of(zero) / amount(zero);
    let expected = |id: &str| truth_of(id) + t * amount(id);
    assert!(expected(zero).abs() < 1e-12);

    let mut estimable = Vec::new();
    for p in v["parameters"].as_array().unwrap() {
        let id = p["id"].as_str().unwrap();
        if !is_location_error(id) || p["estimable"] != true {
            continue;
        }
        let (got, u) = (p["value"].as_f64().unwrap(), p["std_uncertainty"].as_f64().unwrap());
        let want = expected(id);
        assert!(
            (got - want).abs() <= 3.0 * u,
            "{machine} {id}: {got:.4} ± {u:.4} against the gauge-mapped truth {want:.4} (truth {})",
            truth_of(id)
        );
        estimable.push(id.to_string());
    }
    // Not vacuous: every location error but the two zero errors is estimated.
    let all: Vec<&str> = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|p| p["id"].as_str())
        .filter(|id| is_location_error(id))
        .collect();
    assert_eq!(all.len(), 10, "{machine}: {all:?}");
    assert_eq!(estimable.len(), 8, "{machine}: {estimable:?}");
}

/// The A/C trunnion: EA0A turns the trunnion and the C table on it about the A line; EA0C turns
/// the table the same way about C's pivot, 60 mm below the A line (turning about a point 60 mm
/// higher is turning about the lower one plus a shift of 60 mm × ε along Y). So with EA0A
/// fixed at 0, EA0C carries it one for one and EY0C moves by 0.060 µm per µrad.
#[test]
fn the_ac_trunnion_rotary_truth_fits_back_with_ea0a_gauged() {
    fits_back_to_the_gauge_mapped_truth(AC, "EA0A", &[("EA0C", 1.0), ("EY0C", 0.060)]);
}

/// The B/C head-table machine: EB0B turns the head by ε, and the tool ball, 250 mm below the B
/// line in this truth file's tests (the gauge point is on the B line: 150 mm pivot length plus
/// a 100 mm tool, `tool_ball_mm` z = -250), moves by 250 mm × ε along X as an X offset of the
/// B line does, and as the same X offset of C does in the C runs: 0.250 µm per µrad for each.
#[test]
fn the_bc_head_table_rotary_truth_fits_back_with_eb0b_gauged() {
    let truth: ballbar_sim::Truth =
        ron::from_str(&std::fs::read_to_string(root().join(rotary_truth_file(BC))).unwrap())
            .unwrap();
    // The lever is the B line to the tool ball: every test of the file uses the same tool.
    assert!(truth.tests.iter().all(|t| t.tool_ball_mm == [0.0, 0.0, -250.0]));
    fits_back_to_the_gauge_mapped_truth(BC, "EB0B", &[("EX0B", 0.250), ("EX0C", 0.250)]);
}

/// Every file of `dir` and its bytes.
fn contents(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| {
            (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap())
        })
        .collect()
}

/// Position tolerance of a replayed block end against a sample: mm for X, Y, Z, degrees for
/// A, B, C. The words have 4 decimals (rounding by up to 0.5e-4) and the run files 6.
const ON_PATH: f64 = 1e-4;

/// Does program point `p` sit on sample `k` of `run` (every axis of the run)?
fn on_sample(p: &gcode::ProgramPoint, run: &Run, k: usize) -> bool {
    (0..6).all(|i| match (&run.axes[i], p.axes[i]) {
        (None, _) => true,
        (Some(c), Some(w)) => {
            let sample = if i >= 3 { c[k].to_degrees() } else { c[k] };
            (w - sample).abs() <= ON_PATH
        }
        (Some(_), None) => false,
    })
}

/// Replay the program of `run` and check that it runs the run's commanded path: a rotary run's
/// measured blocks (`G1` in inverse time) end on samples, in the run's order, the last on its
/// last sample or, for a run of whole turns that its sampling stops short of, on the whole turn
/// (its turning axis's word the start's plus 360° a turn), the lead-in ending on its first; a
/// planar run's arcs lie on its circle: a feed-in arc ending on its first sample, the data arc
/// (a full circle) back to it, an over-shoot arc, a dwell, and the same three arcs the other
/// way.
fn replays_on_its_path(name: &str, program: &str, run: &Run) {
    let points = gcode::parse(program).unwrap_or_else(|e| panic!("{name}: {e}"));
    let n = run.t_s.len();
    let first_measured = points
        .iter()
        .position(|p| {
            matches!(p.motion, Motion::Arc { .. }) || p.feed_mode == FeedMode::InverseTime
        })
        .unwrap_or_else(|| panic!("{name}: no measured move"));
    let measured = &points[first_measured..];
    if run.header.plane.name() == "free" {
        // The lead-in ends at the first sample (its last move is the G1 of Z down at the feed).
        assert!(
            first_measured > 0 && on_sample(&points[first_measured - 1], run, 0),
            "{name}: the lead-in does not end at the first sample"
        );
        let mut k = 0;
        let mut blocks = 0;
        for (b, p) in measured.iter().enumerate() {
            assert!(
                p.block_end && p.motion == Motion::Linear && p.feed_mode == FeedMode::InverseTime,
                "{name}: line {}: {p:?}",
                p.line
            );
            assert!(p.duration_s.is_some_and(|d| d > 0.0), "{name}: line {}", p.line);
            blocks += 1;
            // The next sample it lies on, after the last block's.
            match (k + 1..n).find(|&j| on_sample(p, run, j)) {
                Some(next) => k = next,
                None if b + 1 == measured.len() => {
                    // The whole turn the samples stop short of.
                    let closes = (3..6).any(|i| {
                        let (Some(c), Some(w)) = (&run.axes[i], p.axes[i]) else { return false };
                        let turns = ((w - c[0].to_degrees()) / 360.0).round();
                        turns != 0.0 && (w - c[0].to_degrees() - 360.0 * turns).abs() <= ON_PATH
                    });
                    assert!(closes, "{name}: line {}: {:?} ends on no whole turn", p.line, p.axes);
                    k = n - 1;
                }
                None => panic!(
                    "{name}: line {}: {:?} lies on no sample after sample {k}",
                    p.line, p.axes
                ),
            }
        }
        assert_eq!(k, n - 1, "{name}: the last block does not end on the last sample");
        assert!(blocks > 100, "{name}: {blocks} blocks");
    } else {
        let pivot = run.header.pivot_mm;
        let (u, v) = match run.header.plane.name() {
            "XY" => (0, 1),
            "YZ" => (1, 2),
            _ => (2, 0),
        };
        let on_circle = |p: &gcode::ProgramPoint| {
            let r = (p.axes[u].unwrap() - pivot[u]).hypot(p.axes[v].unwrap() - pivot[v]);
            (r - run.header.radius_mm).abs() <= 1e-3
        };
        assert!(on_circle(&points[first_measured - 1]), "{name}: the lead-in ends off the circle");
        let ends: Vec<&gcode::ProgramPoint> = measured.iter().filter(|p| p.block_end).collect();
        // Feed-in, the full circle, over-shoot, dwell, and the three arcs back.
        assert_eq!(ends.len(), 7, "{name}");
        for p in measured {
            let arc = matches!(p.motion, Motion::Arc { .. });
            assert!(arc || p.motion == Motion::Dwell, "{name}: line {}", p.line);
            assert!(on_circle(p), "{name}: line {}: off the circle", p.line);
        }
        assert!(on_sample(ends[0], run, 0), "{name}: the feed-in arc does not end on the start");
        assert!(on_sample(ends[1], run, 0), "{name}: the circle does not close on its start");
        assert_eq!(ends[3].motion, Motion::Dwell, "{name}");
        assert!(on_sample(ends[5], run, 0), "{name}: the circle back does not close");
    }
}

/// `ballbar program` on the machine's rotary truth file: one `<run-id>.nc` per simulated run (the
/// same ids as `simulate`), each replaying on its run's commanded path, a line per program with
/// the header's chord figure for rotary runs; the run files give the same programs; with
/// `refusal`, again without `--force` it refuses and leaves every file as it was, and with it
/// writes the same programs again.
fn program_replays_on_the_simulated_paths(machine: &str, refusal: bool) {
    let dir = scratch(&format!("five-axis-program-{machine}"));
    let runs = simulate(machine, &dir, "0");
    let out = dir.join("programs");
    let args = [
        "program",
        "--machine-file",
        &machine_file(machine),
        "--truth",
        &rotary_truth_file(machine),
        "--out",
        out.to_str().unwrap(),
    ];
    let started = std::time::Instant::now();
    let o = ballbar(&args);
    eprintln!("{machine}: program took {:.2} s", started.elapsed().as_secs_f64());
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();

    // One program per run, named by the run's id, and a line for each.
    let csvs = contents(&runs);
    let programs = contents(&out);
    let ids: Vec<&str> = csvs.keys().map(|k| k.strip_suffix(".csv").unwrap()).collect();
    let names: Vec<&str> =
        programs.keys().map(|k| k.strip_suffix(".nc").unwrap_or_else(|| panic!("{k}"))).collect();
    assert_eq!(names, ids, "{machine}");
    assert_eq!(ids.len(), 20);
    let mut rotary = 0;
    for (file, bytes) in &programs {
        let name = file.strip_suffix(".nc").unwrap();
        let run: Run = ballbar_io::read_run(&runs.join(format!("{name}.csv"))).unwrap();
        let line = stdout
            .lines()
            .find(|l| {
                l.starts_with("wrote ") && l.contains(&format!("{}:", out.join(file).display()))
            })
            .unwrap_or_else(|| panic!("no line for {file}: {stdout}"));
        let program = std::str::from_utf8(bytes).unwrap();
        if run.header.plane.name() == "free" {
            rotary += 1;
            // The chord figure the header states, on the program's line.
            let chord = program
                .lines()
                .find(|l| l.starts_with("(between block ends the axes follow chords up to "))
                .unwrap_or_else(|| panic!("{file}: no chord line"));
            assert!(line.contains(chord.trim_start_matches('(').trim_end_matches(')')), "{line}");
        }
        replays_on_its_path(file, program, &run);
    }
    assert_eq!(rotary, 14, "{machine}");
    assert_eq!(stdout.lines().filter(|l| l.starts_with("wrote ")).count(), 20, "{stdout}");

    // The run files are the commanded paths: the same programs from them, block for block,
    // to the last digit of a word (a coordinate the run file holds to 1e-6 can sit on the
    // half of a 1e-4 word, which its value in memory and its value read back from the file
    // can round either way).
    let from_files = dir.join("from-files");
    let o = ballbar(&["program", runs.to_str().unwrap(), "--out", from_files.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let again = contents(&from_files);
    assert_eq!(again.keys().collect::<Vec<_>>(), programs.keys().collect::<Vec<_>>());
    for (file, bytes) in &programs {
        let a = gcode::parse(std::str::from_utf8(bytes).unwrap()).unwrap();
        let b = gcode::parse(std::str::from_utf8(&again[file]).unwrap()).unwrap();
        assert_eq!(a.len(), b.len(), "{file}");
        for (p, q) in a.iter().zip(&b) {
            assert_eq!(
                (p.line, p.motion, p.feed_mode, p.block_end),
                (q.line, q.motion, q.feed_mode, q.block_end),
                "{file}"
            );
            for (x, y) in p.axes.iter().zip(&q.axes) {
                assert!(
                    x.zip(*y).map_or(x == y, |(x, y)| (x - y).abs() <= 1.0001e-4),
                    "{file}: line {}: {:?} against {:?}",
                    p.line,
                    p.axes,
                    q.axes
                );
            }
            let (dp, dq) = (p.duration_s.unwrap_or(0.0), q.duration_s.unwrap_or(0.0));
            assert!(
                (dp - dq).abs() <= 1e-6 * dp.abs().max(1.0),
                "{file}: line {}: {dp} s against {dq} s",
                p.line
            );
        }
    }

    if !refusal {
        return;
    }
    // Again without --force: refused, naming a file that exists, nothing touched.
    let modified = |d: &Path| -> Vec<std::time::SystemTime> {
        std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().metadata().unwrap().modified().unwrap())
            .collect()
    };
    let before = modified(&out);
    let o = ballbar(&args);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    assert!(
        t.contains("already exists") && t.contains(&out.display().to_string()) && t.contains(".nc"),
        "{t}"
    );
    assert!(t.contains("--force"), "{t}");
    assert!(!t.contains("panicked"), "{t}");
    assert!(contents(&out) == programs, "{machine}: a refused run changed the programs");
    assert_eq!(modified(&out), before);
    // With --force it writes them again (the same).
    let mut forced = args.to_vec();
    forced.push("--force");
    let o = ballbar(&forced);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(contents(&out) == programs);
}

#[test]
fn program_of_the_ac_trunnion_rotary_truth_replays_on_its_paths_and_overwrites_nothing() {
    program_replays_on_the_simulated_paths(AC, true);
}

#[test]
fn program_of_the_bc_head_table_rotary_truth_replays_on_its_paths() {
    program_replays_on_the_simulated_paths(BC, false);
}

/// Usage errors exit 2 and say what is missing; a bad option value names its flag.
#[test]
fn program_usage_errors_exit_2() {
    let dir = scratch("five-axis-program-usage");
    let out = dir.join("p");
    let out = out.to_str().unwrap();
    let truth = rotary_truth_file(AC);
    let file = machine_file(AC);
    let cases: [(Vec<&str>, &str); 4] = [
        (vec!["program", "--out", out], "RUNS"),
        (vec!["program", "--truth", &truth, "--out", out], "--machine NAME or --machine-file FILE"),
        (
            vec!["program", "--machine-file", &file, "fixtures/column-paper/runs", "--out", out],
            "--truth",
        ),
        (
            vec![
                "program",
                "--machine-file",
                &file,
                "--truth",
                &truth,
                "--out",
                out,
                "--max-step-deg",
                "0",
            ],
            "--max-step-deg",
        ),
    ];
    for (args, want) in cases {
        let o = ballbar(&args);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {t}");
        assert!(t.contains(want), "{args:?}: expected '{want}' in: {t}");
        assert!(!t.contains("panicked"), "{t}");
    }
    assert!(!Path::new(out).exists(), "a usage error wrote {out}");
}

/// Reading the report's SVG: start tags, attributes, plots, polylines.
pub mod plots {
    /// The start tags (`<el …`, up to `>`) in `html` that begin with `start`.
    pub fn elements<'a>(html: &'a str, start: &str) -> Vec<&'a str> {
        html.match_indices(start).map(|(i, _)| &html[i..i + html[i..].find('>').unwrap()]).collect()
    }

    /// The whole `<svg class="{class}"…>…</svg>` elements.
    pub fn svgs<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
        let start = format!("<svg class=\"{class}\"");
        html.match_indices(&start)
            .map(|(i, _)| &html[i..i + html[i..].find("</svg>").unwrap()])
            .collect()
    }

    /// An attribute's text.
    pub fn attr<'a>(el: &'a str, name: &str) -> &'a str {
        let k = format!(" {name}=\"");
        let i = el.find(&k).unwrap_or_else(|| panic!("no {name} in {}", &el[..el.len().min(300)]))
            + k.len();
        &el[i..i + el[i..].find('"').unwrap()]
    }

    /// An attribute's number.
    pub fn num(el: &str, name: &str) -> f64 {
        attr(el, name)
            .parse()
            .unwrap_or_else(|_| panic!("{name} is not a number in {}", &el[..el.len().min(300)]))
    }

    /// The numbers of a path's `d`, commands left out.
    pub fn numbers(d: &str) -> Vec<f64> {
        d.replace(['M', 'L', 'A', 'Z'], " ")
            .split_whitespace()
            .map(|x| x.parse().unwrap())
            .collect()
    }

    /// The points of a `d` of `M`/`L` commands.
    pub fn points(d: &str) -> Vec<(f64, f64)> {
        numbers(d).chunks(2).map(|c| (c[0], c[1])).collect()
    }

    /// `a - b` wrapped to -180..180°.
    pub fn wrapped(a: f64, b: f64) -> f64 {
        (a - b + 180.0).rem_euclid(360.0) - 180.0
    }
}

/// The polar plot geometry the page states on each `<svg>`: centre, nominal radius, px per
/// division, divisions each way.
struct PolarFrame {
    c: f64,
    r0: f64,
    div: f64,
    n: f64,
    scale: f64,
}

impl PolarFrame {
    fn of(svg: &str) -> PolarFrame {
        use plots::num;
        assert_eq!(num(svg, "data-cx"), num(svg, "data-cy"));
        PolarFrame {
            c: num(svg, "data-cx"),
            r0: num(svg, "data-r0"),
            div: num(svg, "data-div"),
            n: num(svg, "data-n-div"),
            scale: num(svg, "data-scale-um"),
        }
    }

    /// Angle (°, -180..180) and radius (px) of a point.
    fn polar(&self, (x, y): (f64, f64)) -> (f64, f64) {
        ((self.c - y).atan2(x - self.c).to_degrees(), (x - self.c).hypot(self.c - y))
    }
}

/// The deviation of a run's reading at `deg` of `angle` (degrees per sample), µm: linear
/// between the two consecutive samples that bracket it on the run's first passage.
fn reading_at(angle: &[f64], dr_mm: &[f64], deg: f64, wrap: bool) -> f64 {
    for i in 0..angle.len() - 1 {
        let (oa, ob) = if wrap {
            let oa = plots::wrapped(angle[i], deg);
            (oa, oa + plots::wrapped(angle[i + 1], angle[i]))
        } else {
            (angle[i] - deg, angle[i + 1] - deg)
        };
        if oa.min(ob) <= 0.0 && oa.max(ob) >= 0.0 && oa != ob {
            return (dr_mm[i] + -oa / (ob - oa) * (dr_mm[i + 1] - dr_mm[i])) * 1e3;
        }
    }
    panic!("the run does not pass {deg}°")
}

/// The report's plots of a five-axis session, end to end: simulated, diagnosed and reported
/// through the binary. Each arc where the diagnosis places the gap is on the measured plot of
/// its own run (a planar entry on its plane's pair, along the runs of its direction; a rotary
/// run's on that run's rotary plot, in its axis's degrees), its ends at the sector's angles
/// and on the run's trace, every point inside the rings and clear of the axis labels. All
/// planar plots of a kind share one µm/div, the rotary plots theirs; every trace's start is
/// marked at its first sample, its arrow along the run's direction.
#[test]
fn a_five_axis_report_draws_each_gap_arc_along_its_runs_trace_on_its_plot_with_common_scales_and_start_marks()
 {
    use plots::*;
    let dir = scratch("five-axis-report-plots");
    let runs_dir = simulate(AC, &dir, "7");
    let (json, archive, out) = (dir.join("d.json"), dir.join("s.mcap"), dir.join("report"));
    let o = ballbar(&[
        "diagnose",
        "--machine-file",
        &machine_file(AC),
        runs_dir.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
        "--record",
        archive.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let o = ballbar(&["report", archive.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let h = std::fs::read_to_string(out.join("index.html")).unwrap();
    let d: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let runs: BTreeMap<String, Run> = std::fs::read_dir(&runs_dir)
        .unwrap()
        .map(|e| ballbar_io::csv::read_run(&e.unwrap().path()).unwrap())
        .map(|r| (r.name(), r))
        .collect();
    // A planar run's angle per sample, degrees: its plane's first axis right, second up.
    let plane_deg = |r: &Run| -> Vec<f64> {
        let (u, v, _) = r.header.plane.axes().unwrap();
        let (cu, cv, p) = (r.axis(u).unwrap(), r.axis(v).unwrap(), r.header.pivot_mm);
        cu.iter()
            .zip(cv)
            .map(|(a, b)| (b - p[v.index()]).atan2(a - p[u.index()]).to_degrees())
            .collect()
    };
    let measured_plots: Vec<&str> = ["polar raw", "rotary-polar raw", "rotary-cartesian raw"]
        .iter()
        .flat_map(|c| svgs(&h, c))
        .collect();
    let plot_of = |run: &str| -> Vec<&str> {
        measured_plots
            .iter()
            .copied()
            .filter(|s| {
                s.contains("class=\"trace measured") && s.contains(&format!("data-run=\"{run}\""))
            })
            .collect()
    };

    // The diagnosis of this session places arcs on planar pairs and on rotary runs.
    let where_ = d["gap"]["where"].as_array().unwrap();
    let arcs: Vec<&serde_json::Value> = where_
        .iter()
        .filter(|w| !(w["sector_deg"][0] == 0.0 && w["sector_deg"][1] == 360.0))
        .collect();
    assert!(
        arcs.iter().any(|w| w["plane"] == "free") && arcs.iter().any(|w| w["plane"] != "free"),
        "{where_:?}"
    );
    let mut drawn = 0;
    for w in &arcs {
        let (from, to) =
            (w["sector_deg"][0].as_f64().unwrap(), w["sector_deg"][1].as_f64().unwrap());
        // The runs it belongs to: a rotary entry's run; a planar entry's runs of its plane and direction.
        let names: Vec<&String> = match w["run"].as_str() {
            Some(run) => vec![runs.keys().find(|k| *k == run).unwrap()],
            None => runs
                .iter()
                .filter(|(_, r)| {
                    r.header.plane.name() == w["plane"]
                        && r.header.direction.map(|d| d.name()) == w["direction"].as_str()
                })
                .map(|(k, _)| k)
                .collect(),
        };
        assert!(!names.is_empty(), "{w}");
        for name in names {
            let run = &runs[name];
            let homes = plot_of(name);
            assert_eq!(homes.len(), 1, "{name}: the measured plot that draws it");
            let home = homes[0];
            let el = elements(home, "<path class=\"where ")
                .into_iter()
                .find(|e| {
                    attr(e, "data-run") == name
                        && num(e, "data-from-deg") == from
                        && num(e, "data-to-deg") == to
                })
                .unwrap_or_else(|| panic!("{name}: no arc {from}..{to}° on its plot"));
            drawn += 1;
            let pts = points(attr(el, "d"));
            if home.starts_with("<svg class=\"rotary-cartesian") {
                // A partial sweep: x is the axis's angle across the box, ΔR up from its middle.
                let [left, top, right, bottom] =
                    ["data-left", "data-top", "data-right", "data-bottom"].map(|a| num(home, a));
                let (lo, hi, scale) = (
                    num(home, "data-from-deg"),
                    num(home, "data-to-deg"),
                    num(home, "data-scale-um"),
                );
                let axis = ballbar_model::Axis::from_name(w["axis"].as_str().unwrap()).unwrap();
                let angle: Vec<f64> =
                    run.axis(axis).unwrap().iter().map(|a| a.to_degrees()).collect();
                for (end, deg) in [(pts[0], from.max(lo)), (*pts.last().unwrap(), to.min(hi))] {
                    // 0.01 px as written: 0.003° along x, 0.01 px in y; 0.02 for both.
                    assert!(
                        (lo + (end.0 - left) / (right - left) * (hi - lo) - deg).abs() < 0.02,
                        "{name}: an end off {deg}°"
                    );
                    let y = (top + bottom) / 2.0
                        - reading_at(&angle, &run.dr_mm, deg, false) / scale * (bottom - top) / 6.0;
                    assert!((end.1 - y).abs() < 0.02, "{name}: an end off the trace");
                }
                assert!(
                    pts.iter()
                        .all(|&(x, y)| (left..=right).contains(&x) && (top..=bottom).contains(&y)),
                    "{name}: outside the box"
                );
                continue;
            }
            let f = PolarFrame::of(home);
            let (inner, outer) = (f.r0 - f.n * f.div, f.r0 + f.n * f.div);
            // The angle the plot turns with: a rotary run's axis coordinate, a planar run's angle in its plane.
            let angle: Vec<f64> = match w["axis"].as_str() {
                Some(a) => run
                    .axis(ballbar_model::Axis::from_name(a).unwrap())
                    .unwrap()
                    .iter()
                    .map(|x| x.to_degrees())
                    .collect(),
                None => plane_deg(run),
            };
            for (end, deg) in [(pts[0], from), (*pts.last().unwrap(), to)] {
                // The written points are rounded to 0.01 px, at least 40 px from the centre: 0.015°.
                let (a, r) = f.polar(end);
                assert!(
                    wrapped(a, deg).abs() < 0.05,
                    "{name}: an end at {a}°, the sector's at {deg}°"
                );
                assert!(
                    (inner - 0.01..=outer + 0.01).contains(&r),
                    "{name}: an end at {r} px, outside the rings {inner}..{outer}"
                );
                if w["axis"].is_string() {
                    // A rotary trace is drawn as read (nothing taken out): on it to the 0.01 px written.
                    let want = f.r0 + reading_at(&angle, &run.dr_mm, deg, true) / f.scale * f.div;
                    assert!(
                        (r - want).abs() < 0.02,
                        "{name}: an end at {r} px, the trace at {want} px"
                    );
                } else {
                    // A planar trace has the set-up's first harmonic taken out: the end on the
                    // drawn trace, within the radii it is drawn at within a degree of it
                    // (± a pixel: the drawn trace is decimated).
                    let trace = elements(home, "<path class=\"trace measured")
                        .into_iter()
                        .find(|e| attr(e, "data-run") == name)
                        .unwrap();
                    let near: Vec<f64> = points(attr(trace, "d"))
                        .into_iter()
                        .map(|p| f.polar(p))
                        .filter(|(b, _)| wrapped(*b, deg).abs() < 1.0)
                        .map(|(_, r)| r)
                        .collect();
                    assert!(!near.is_empty());
                    let (lo, hi) =
                        near.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, u), &r| {
                            (l.min(r), u.max(r))
                        });
                    assert!(
                        r >= lo - 1.0 && r <= hi + 1.0,
                        "{name}: an end at {r} px, the trace at {lo}..{hi} px"
                    );
                }
            }
            let span = (to - from).rem_euclid(360.0);
            // Clear of the axis labels: no point within the arc's half width (4 px) of a
            // label's box (7 px a character, generous for 11 px text; 11 px above the
            // baseline, 3 below).
            let labels: Vec<[f64; 4]> = home
                .split("<text class=\"axis\"")
                .skip(1)
                .map(|t| {
                    let (x, y) = (num(t, "x"), num(t, "y"));
                    let w = 7.0
                        * t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].chars().count()
                            as f64;
                    let left = if t.contains("text-anchor=\"end\"") { x - w } else { x };
                    [left, y - 11.0, left + w, y + 3.0]
                })
                .collect();
            assert!(labels.len() >= 2);
            for &p in &pts {
                let (a, r) = f.polar(p);
                assert!((inner - 0.01..=outer + 0.01).contains(&r), "{name}: a point at {r} px");
                let along = wrapped(a, from);
                assert!(
                    (if along < -0.05 { along + 360.0 } else { along }) <= span + 0.05,
                    "{name}: a point at {a}° outside {from}..{to}°"
                );
                for b in &labels {
                    let (dx, dy) = (
                        (b[0] - p.0).max(p.0 - b[2]).max(0.0),
                        (b[1] - p.1).max(p.1 - b[3]).max(0.0),
                    );
                    assert!(dx.hypot(dy) > 4.0, "{name}: a point {p:?} on an axis label {b:?}");
                }
            }
        }
    }
    assert!(drawn >= arcs.len());
    // No arc on a plot after the model.
    for class in ["polar after", "rotary-polar after", "rotary-cartesian after"] {
        assert!(svgs(&h, class).iter().all(|s| !s.contains("class=\"where")), "{class}");
    }

    // Scales: one µm/div for every planar plot of a kind, one for every rotary plot of
    // a kind (polar and Cartesian), each stated once for its set.
    for (classes, stated) in [
        (vec!["polar raw"], 0),
        (vec!["polar after"], 0),
        (vec!["rotary-polar raw", "rotary-cartesian raw"], 1),
        (vec!["rotary-polar after", "rotary-cartesian after"], 1),
    ] {
        let scales: Vec<f64> =
            classes.iter().flat_map(|c| svgs(&h, c)).map(|s| num(s, "data-scale-um")).collect();
        assert!(
            scales.len() >= 3 && scales.iter().all(|x| *x == scales[0]),
            "{classes:?}: {scales:?}"
        );
        let p = elements(&h, "<p class=\"scales\"")[stated];
        let key =
            if classes[0].ends_with("raw") { "data-raw-scale-um" } else { "data-after-scale-um" };
        assert_eq!(num(p, key), scales[0], "{classes:?}");
    }

    // Start and direction: on every plot, each run's dot at its first sample's angle,
    // its arrow along the run's direction (CCW: the angle increasing).
    for plot in ["polar raw", "polar after", "rotary-polar raw", "rotary-polar after"]
        .iter()
        .flat_map(|c| svgs(&h, c))
    {
        let f = PolarFrame::of(plot);
        let dots = elements(plot, "<circle class=\"start ");
        assert!(!dots.is_empty());
        for dot in dots {
            let name = attr(dot, "data-run");
            let run = &runs[name];
            let angle: Vec<f64> = if run.header.plane.axes().is_some() {
                plane_deg(run)
            } else {
                run.axis(ballbar_model::Axis::from_name(attr(plot, "data-axis")).unwrap())
                    .unwrap()
                    .iter()
                    .map(|x| x.to_degrees())
                    .collect()
            };
            let (a, _) = f.polar((num(dot, "cx"), num(dot, "cy")));
            assert!(
                wrapped(a, angle[0]).abs() < 0.05,
                "{name}: the start mark at {a}°, the first sample at {}°",
                angle[0]
            );
            let arrow = elements(plot, "<path class=\"arrow ")
                .into_iter()
                .find(|e| attr(e, "data-run") == name)
                .unwrap();
            let n = numbers(attr(arrow, "d"));
            let (a0, a1) = (f.polar((n[0], n[1])).0, f.polar((n[7], n[8])).0);
            assert!(wrapped(a0, angle[0]).abs() < 0.05, "{name}: the arrow from {a0}°");
            let increasing = match run.header.direction {
                Some(d) => d.name() == "CCW",
                None => angle[angle.len() - 1] > angle[0],
            };
            assert_eq!(
                wrapped(a1, a0) > 0.0,
                increasing,
                "{name}: the arrow turns from {a0}° to {a1}°, the run is {:?}",
                run.header.direction
            );
        }
        // The word `start` readable: on the ray of its dot, off the trace there by more than
        // the text's height (11 px) along the ray, its ink (about 24 × 8 px at the page's 11 px
        // font, centred 4 px above the baseline) clear of its dot (3.5 px) and of every point
        // of every trace (some 1440 a turn at ≤ 160 px: ≤ 0.7 px apart, so a trace through
        // the ink leaves a point in it).
        let drawn: Vec<(f64, f64)> = elements(plot, "<path class=\"trace ")
            .into_iter()
            .flat_map(|p| points(attr(p, "d")))
            .collect();
        let labels = elements(plot, "<text class=\"start-label\"");
        assert!(!labels.is_empty(), "no start label");
        for label in labels {
            let name = attr(label, "data-run");
            let dot = elements(plot, "<circle class=\"start ")
                .into_iter()
                .find(|c| attr(c, "data-run") == name)
                .unwrap();
            let (dx, dy) = (num(dot, "cx"), num(dot, "cy"));
            let (x, y) = (num(label, "x"), num(label, "y") - 4.0);
            let ((a, r), (a_dot, r_dot)) = (f.polar((x, y)), f.polar((dx, dy)));
            assert!(
                wrapped(a, a_dot).abs() < 0.5 && (r - r_dot).abs() > 11.0,
                "{name}: the label at {a}°, {r} px; its dot at {a_dot}°, {r_dot} px"
            );
            assert!(
                ((dx - x).abs() - 12.0).max(0.0).hypot(((dy - y).abs() - 4.0).max(0.0)) > 3.5,
                "{name}: the label over its dot"
            );
            let under: Vec<_> = drawn
                .iter()
                .filter(|(px, py)| (px - x).abs() < 12.0 && (py - y).abs() < 4.0)
                .collect();
            assert!(under.is_empty(), "{name}: traces through the label at ({x}, {y}): {under:?}");
        }
    }
}

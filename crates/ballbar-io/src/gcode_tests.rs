//! Tests of the part program: programs written from commanded runs (planar circles and arcs
//! from `CircleTest`, rotary tests from `RotaryTest` on the A/C trunnion chain file) are read
//! back and replayed against the runs; bad programs fail at their line.
//!
//! Tolerances: the words have 4 decimals, so a written coordinate is within 0.5e-4 mm (or
//! degree) of the run's, and a point in a plane within 0.71e-4 mm: positions are checked to
//! 1e-4 mm / 1e-4°. The nominal chain turns the rounding of five words into at most a few
//! 1e-4 mm of bar length (a 0.5e-4° rotary word moves a ball 200 mm away by 1.7e-4 mm): 1e-3 mm.
//! Times: the F words of inverse time keep 8 significant digits or more over a run of ~100 s:
//! 1 ms.

use ballbar_model::path::{BarDirection, CircleTest, RotaryTest, Turn};
use ballbar_model::{Axis, Direction, KinematicChain, Model, ModelOptions, Plane, Run};

use super::*;

/// Positions, mm and degrees (see the module's note).
const POSITION_TOL: f64 = 1e-4;
/// Bar length through the nominal chain, mm.
const BAR_TOL_MM: f64 = 1e-3;
/// Run time, s.
const TIME_TOL_S: f64 = 1e-3;

fn circle(
    plane: Plane,
    direction: Direction,
    radius_mm: f64,
    pivot_mm: [f64; 3],
    start_deg: f64,
    sweep_deg: f64,
) -> CircleTest {
    CircleTest {
        plane,
        direction,
        radius_mm,
        feed_mm_per_min: 1000.0,
        pivot_mm,
        table_ball_mm: [0.0, 0.0, 50.0],
        tool_ball_mm: [0.0, 0.0, -100.0],
        sample_rate_hz: 250.0,
        start_deg,
        sweep_deg,
    }
}

/// The same test sampled so that its last sample falls at the end of the sweep (a whole number
/// of sample intervals in the duration, near 250 Hz).
fn ending_on_a_sample(mut test: CircleTest) -> CircleTest {
    let intervals = (test.duration_s() * 250.0).round();
    test.sample_rate_hz = intervals / test.duration_s();
    test
}

fn sample(run: &Run, k: usize) -> [f64; 6] {
    let mut q = [0.0; 6];
    for a in Axis::ALL {
        if let Some(c) = run.axis(a) {
            q[a.index()] = if a.is_rotary() { c[k].to_degrees() } else { c[k] };
        }
    }
    q
}

fn position(p: &ProgramPoint) -> [f64; 6] {
    let mut q = [0.0; 6];
    for a in Axis::ALL {
        q[a.index()] = p.axis(a).unwrap_or(0.0);
    }
    q
}

/// Every axis of the run at sample `k` equals the point's, within the words' rounding.
fn assert_at_sample(p: &ProgramPoint, run: &Run, k: usize, what: &str) {
    let q = sample(run, k);
    for a in Axis::ALL {
        if run.axis(a).is_some() {
            let got = p.axis(a).unwrap_or_else(|| panic!("{what}: no {a} at line {}", p.line));
            assert!(
                (got - q[a.index()]).abs() <= POSITION_TOL,
                "{what}: {a} {got} at line {}, the run's sample {k} has {}",
                p.line,
                q[a.index()]
            );
        }
    }
}

/// The lines of the program that hold the given code as a word (not in a comment).
fn blocks_with<'a>(text: &'a str, code: &str) -> Vec<&'a str> {
    text.lines()
        .filter(|l| l.split('(').next().unwrap_or("").split_whitespace().any(|w| w == code))
        .collect()
}

/// What every program must be: ASCII, the safe preamble before any motion, no spindle and no
/// tool, `M0` before the measured move (after the lead-in), `M30` at the end, no `-0.0000`.
fn assert_safe_program(text: &str, first_measured_line: usize) {
    assert!(text.is_ascii(), "controllers take ASCII:\n{text}");
    assert!(!text.contains("-0.0000"), "a negative zero:\n{text}");
    let lines: Vec<&str> = text.lines().collect();
    let preamble =
        lines.iter().position(|l| *l == "G90 G21 G40 G49 G80").expect("the safe preamble");
    let first_motion =
        lines.iter().position(|l| l.starts_with("G0 ") || l.starts_with("G1 ")).expect("a motion");
    assert!(preamble < first_motion, "the preamble comes before any motion");
    let stop = lines.iter().position(|l| l.starts_with("M0 (")).expect("M0 with its comment");
    assert!(lines[stop].contains("ballbar"), "M0 says to start the ballbar: {}", lines[stop]);
    assert!(
        first_motion < stop && stop + 1 < first_measured_line,
        "M0 between the lead-in and the measured move"
    );
    assert_eq!(lines.iter().filter(|l| l.starts_with("M0")).count(), 1);
    assert_eq!(lines[lines.len() - 2], "M30");
    for l in &lines {
        let code = l.split('(').next().unwrap_or("");
        for w in code.split_whitespace() {
            assert!(!matches!(w.chars().next(), Some('S' | 'T')), "no spindle speed, no tool: {l}");
            assert!(
                !matches!(w, "M3" | "M03" | "M4" | "M04" | "M6" | "M06"),
                "no spindle start, no tool change: {l}"
            );
        }
    }
}

/// The angle turned from `a` to `b` about the plane's normal axis through `centre`, rad,
/// positive counter-clockwise seen from the normal's + end: from the 3-D cross product with
/// ISO 841's axis vectors, independently of the program's plane frames.
fn turn_about_normal(plane: Plane, centre: &[f64; 3], a: &[f64; 6], b: &[f64; 6]) -> f64 {
    let normal = match plane {
        Plane::XY => [0.0, 0.0, 1.0],
        Plane::YZ => [1.0, 0.0, 0.0],
        _ => [0.0, 1.0, 0.0],
    };
    let ra: Vec<f64> = (0..3).map(|k| a[k] - centre[k]).collect();
    let rb: Vec<f64> = (0..3).map(|k| b[k] - centre[k]).collect();
    let cross = [
        ra[1] * rb[2] - ra[2] * rb[1],
        ra[2] * rb[0] - ra[0] * rb[2],
        ra[0] * rb[1] - ra[1] * rb[0],
    ];
    let sin = (0..3).map(|k| cross[k] * normal[k]).sum::<f64>();
    let cos = (0..3).map(|k| ra[k] * rb[k]).sum::<f64>();
    sin.atan2(cos)
}

/// The points of a replayed program grouped by block (each group ends at a block end).
fn by_block(points: &[ProgramPoint]) -> Vec<&[ProgramPoint]> {
    let mut blocks = Vec::new();
    let mut from = 0;
    for (k, p) in points.iter().enumerate() {
        if p.block_end {
            blocks.push(&points[from..=k]);
            from = k + 1;
        }
    }
    blocks
}

/// The angle the arc points of `block` turn about the pivot, from `from`, rad (signed,
/// counter-clockwise seen from the plane's normal positive); each point on the commanded
/// circle and in the plane, turning as `direction` says by at most the reader's step.
fn arc_turn(run: &Run, block: &[ProgramPoint], from: [f64; 6], direction: Direction) -> f64 {
    let h = &run.header;
    let (u, v, w) = h.plane.axes().unwrap();
    let mut swept = 0.0;
    let mut last = from;
    for p in block {
        assert_eq!(p.motion, Motion::Arc { plane: h.plane, direction }, "line {}", p.line);
        let q = position(p);
        let r = (q[u.index()] - h.pivot_mm[u.index()]).hypot(q[v.index()] - h.pivot_mm[v.index()]);
        assert!(
            (r - h.radius_mm).abs() <= POSITION_TOL,
            "line {}: {r} mm from the pivot in the plane, the radius is {}",
            p.line,
            h.radius_mm
        );
        assert!(
            (q[w.index()] - h.pivot_mm[w.index()]).abs() <= POSITION_TOL,
            "line {}: off the plane",
            p.line
        );
        let turn = turn_about_normal(h.plane, &h.pivot_mm, &last, &q);
        assert!(
            turn * direction.angular_sign() > 0.0,
            "line {}: turns {turn} rad, against {direction}",
            p.line
        );
        assert!(turn.abs() <= ARC_POINT_STEP_DEG.to_radians() + 1e-12, "a point every 1° or less");
        swept += turn;
        last = q;
    }
    swept
}

/// A planar program replayed, as a ballbar's capture runs it: the lead-in ends at the start
/// of the feed-in arc, which turns `overshoot_deg` the run's way and ends at the run's first
/// sample; the data arc (`data_blocks` blocks) turns the run's way, ends at `end_sample` and
/// sweeps what the run sweeps from its first sample to that one, timed as the run; an
/// over-shoot arc of `overshoot_deg`; a dwell of [`DWELL_S`] where it ends; then the same
/// arcs the other way, back to the lead-in's end. Every arc point on the commanded circle.
/// Returns the points.
fn check_planar_replay(
    run: &Run,
    text: &str,
    end_sample: usize,
    data_blocks: usize,
    overshoot_deg: f64,
) -> Vec<ProgramPoint> {
    let h = &run.header;
    let points = parse(text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let first = points.iter().position(|p| matches!(p.motion, Motion::Arc { .. })).expect("an arc");
    assert_safe_program(text, points[first].line);
    let start = position(&points[first - 1]);
    let blocks = by_block(&points[first..]);
    // The words' rounding turns each end by at most 0.71e-4 mm / R.
    let angle_tol = 2.0 * 0.71e-4 / h.radius_mm;
    let o = overshoot_deg.to_radians();
    let direction = h.direction.unwrap();
    let reverse = match direction {
        Direction::CW => Direction::CCW,
        Direction::CCW => Direction::CW,
    };
    let d = direction.angular_sign();
    assert_eq!(blocks.len(), 2 * (data_blocks + 2) + 1, "blocks after the lead-in:\n{text}");
    let last_of = |b: &[ProgramPoint]| position(b.last().unwrap());

    // The feed-in arc, to the run's first sample.
    let feed_in = arc_turn(run, blocks[0], start, direction);
    assert!((feed_in - d * o).abs() <= angle_tol, "the feed-in arc turns {feed_in} rad");
    assert_at_sample(blocks[0].last().unwrap(), run, 0, "the feed-in arc's end");

    // The data arc.
    let data: Vec<ProgramPoint> = blocks[1..=data_blocks].concat();
    let swept = arc_turn(run, &data, last_of(blocks[0]), direction);
    assert_at_sample(data.last().unwrap(), run, end_sample, "the data arc's end");
    // The run's own sweep, summed the same way over its samples.
    let run_swept = |to: usize| {
        (1..=to)
            .map(|k| turn_about_normal(h.plane, &h.pivot_mm, &sample(run, k - 1), &sample(run, k)))
            .sum::<f64>()
    };
    if end_sample == 0 {
        // A closed circle: the run's samples stop short of the turn by less than a step.
        let run_swept = run_swept(run.len() - 1);
        let step = h.feed_mm_per_s() / h.radius_mm / run.sample_rate_hz().unwrap();
        let short = swept.abs() - run_swept.abs();
        assert!(
            (swept.abs() - std::f64::consts::TAU).abs() < 1e-9 && short > 0.0 && short < step,
            "a full turn: {swept} rad, the run {run_swept}"
        );
    } else {
        let run_swept = run_swept(end_sample);
        assert!(
            (swept - run_swept).abs() <= angle_tol,
            "the arc sweeps {swept} rad, the run {run_swept}"
        );
        let duration: f64 = data.iter().map(|p| p.duration_s.unwrap()).sum();
        assert!(
            (duration - (run.t_s[end_sample] - run.t_s[0])).abs() <= TIME_TOL_S,
            "the arc takes {duration} s at its feed"
        );
    }

    // The over-shoot, the dwell where it ends, and the way back.
    let k = data_blocks + 1;
    let over = arc_turn(run, blocks[k], position(data.last().unwrap()), direction);
    assert!((over - d * o).abs() <= angle_tol, "the over-shoot arc turns {over} rad");
    let dwell = blocks[k + 1];
    assert!(
        dwell.len() == 1
            && dwell[0].motion == Motion::Dwell
            && dwell[0].duration_s == Some(DWELL_S)
            && position(&dwell[0]) == last_of(blocks[k]),
        "a dwell where the over-shoot ends: {dwell:?}"
    );
    let back_in = arc_turn(run, blocks[k + 2], last_of(blocks[k]), reverse);
    assert!((back_in + d * o).abs() <= angle_tol, "the reverse feed-in turns {back_in} rad");
    let back: Vec<ProgramPoint> = blocks[k + 3..k + 3 + data_blocks].concat();
    let back_swept = arc_turn(run, &back, last_of(blocks[k + 2]), reverse);
    assert!((back_swept + swept).abs() <= angle_tol, "the reverse data arc turns {back_swept}");
    assert_at_sample(back.last().unwrap(), run, 0, "the reverse data arc's end");
    let back_over =
        arc_turn(run, blocks[k + 3 + data_blocks], position(back.last().unwrap()), reverse);
    assert!((back_over + d * o).abs() <= angle_tol, "the reverse over-shoot turns {back_over}");
    let end = last_of(blocks[k + 3 + data_blocks]);
    assert!(
        (0..6).all(|i| (end[i] - start[i]).abs() <= POSITION_TOL),
        "the reverse over-shoot ends where the feed-in began: {end:?} against {start:?}"
    );
    points
}

#[test]
fn an_xy_ccw_full_circle_replays_on_its_circle() {
    let test = ending_on_a_sample(circle(
        Plane::XY,
        Direction::CCW,
        100.0,
        [300.0, 200.0, -300.0],
        0.0,
        360.0,
    ));
    let run = test.run("2026-11-21T10:00:00Z", 0.0, "xy-ccw-1", "column");
    let text = program(&run, &ProgramOptions::default()).unwrap();
    check_planar_replay(&run, &text, run.len() - 1, 1, 180.0);
    // The last sample is the start again: one full-circle block, G3 in G17, centre from the
    // start, between the half-turn feed-in and over-shoot arcs; then the same arcs in G2.
    assert_eq!(
        blocks_with(&text, "G3"),
        [
            "G3 X400.0000 Y200.0000 I100.0000 J0.0000 F1000.0000",
            "G3 X400.0000 Y200.0000 I-100.0000 J0.0000 F1000.0000",
            "G3 X200.0000 Y200.0000 I-100.0000 J0.0000",
        ]
    );
    assert_eq!(
        blocks_with(&text, "G2"),
        [
            "G2 X400.0000 Y200.0000 I100.0000 J0.0000",
            "G2 X400.0000 Y200.0000 I-100.0000 J0.0000",
            "G2 X200.0000 Y200.0000 I-100.0000 J0.0000",
        ]
    );
    assert_eq!(blocks_with(&text, "G17").len(), 1);
    assert_eq!(blocks_with(&text, "G4"), ["G4 P1.0000 (dwell, s)"]);
    for comment in [
        "(machine: column)",
        "(run: xy-ccw-1)",
        "(plane: XY, direction CCW)",
        "(radius, the bar length: 100.0000 mm; feed: 1000.0000 mm/min)",
        "(pivot, where the balls meet: X300.0000 Y200.0000 Z-300.0000 mm)",
        "(arc: from 0.0000 deg, +X towards +Y; a full 360.0000 deg CCW: G3 in G17)",
        "(over-shoot: 180.0000 deg, a feed-in arc before the data arc and an over-shoot arc after it; feed: 1000.0000 mm/min)",
        "(both directions, as the ballbar's capture takes a test: CCW [this run], a dwell of 1.0000 s, then CW back over the same arcs)",
    ] {
        assert!(text.contains(comment), "{comment} in\n{text}");
    }
    // The lead-in: Z clear, X Y at the feed-in arc's start half a turn before, down at the feed.
    assert!(
        text.contains("G0 Z-280.0000\nG0 X200.0000 Y200.0000\nG1 Z-300.0000 F1000.0000\nM0"),
        "{text}"
    );
}

#[test]
fn a_zx_cw_partial_arc_ends_at_its_end_point() {
    // G2 in G18 is clockwise seen from +Y (ISO 6983), the run format's CW in ZX: the angle from
    // +Z towards +X decreases. `turn_about_normal` checks the sense in 3-D.
    let test = circle(Plane::ZX, Direction::CW, 150.0, [120.5, -40.25, -200.0], 30.0, 220.0);
    let run = test.run("2026-11-21T10:00:00Z", 0.0, "zx-cw-arc", "column");
    let text = program(&run, &ProgramOptions::default()).unwrap();
    // A partial arc: 2° of feed-in and over-shoot.
    let points = check_planar_replay(&run, &text, run.len() - 1, 1, 2.0);
    let arcs = blocks_with(&text, "G2");
    assert_eq!(arcs.len(), 3, "{text}");
    assert!(
        arcs[1].starts_with("G2 X")
            && arcs[1].contains(" Z-")
            && arcs[1].contains(" I")
            && arcs[1].contains(" K")
            && !arcs[1].contains(" J"),
        "ZX words, X before Z: {}",
        arcs[1]
    );
    assert_eq!(blocks_with(&text, "G18").len(), 1);
    // Starting at 30° from +Z towards +X, clockwise seen from +Y: X falls, Z rises.
    let first = points.iter().position(|p| matches!(p.motion, Motion::Arc { .. })).unwrap();
    let (a, b) = (&points[first - 1], &points[first]);
    assert!(
        b.axis(Axis::X).unwrap() < a.axis(Axis::X).unwrap()
            && b.axis(Axis::Z).unwrap() > a.axis(Axis::Z).unwrap()
    );
}

#[test]
fn a_yz_circle_from_circle_test_replays_on_its_circle() {
    let test = ending_on_a_sample(CircleTest {
        feed_mm_per_min: 600.0,
        ..circle(Plane::YZ, Direction::CW, 50.0, [-50.0, 25.0, 75.5], 90.0, 360.0)
    });
    let run = test.run("2026-11-21T10:00:00Z", 0.0, "yz-cw-1", "column");
    let text = program(&run, &ProgramOptions::default()).unwrap();
    check_planar_replay(&run, &text, run.len() - 1, 1, 180.0);
    assert_eq!(blocks_with(&text, "G2")[1], "G2 Y25.0000 Z125.5000 J0.0000 K-50.0000 F600.0000");
    assert_eq!(blocks_with(&text, "G19").len(), 1);
}

#[test]
fn a_full_circle_cut_short_by_its_sampling_closes_the_turn() {
    // At 250 Hz the last sample falls 0.78 of a step short of the turn.
    let run = circle(Plane::XY, Direction::CW, 100.0, [300.0, 200.0, -300.0], 0.0, 360.0).run(
        "2026-11-21T10:00:00Z",
        0.0,
        "xy-cw-1",
        "column",
    );
    let step = (1000.0 / 60.0 / 100.0 / 250.0_f64).to_degrees();
    let short = 360.0 - (run.t_s[run.len() - 1] * 1000.0 / 60.0 / 100.0).to_degrees();
    assert!(short > 0.5 * step && short < step, "the run stops {short}° short of the turn");
    let text = program(&run, &ProgramOptions::default()).unwrap();
    check_planar_replay(&run, &text, 0, 1, 180.0);
    assert_eq!(blocks_with(&text, "G2")[1], "G2 X400.0000 Y200.0000 I-100.0000 J0.0000 F1000.0000");
}

#[test]
fn an_arc_of_more_than_a_turn_is_whole_circles_then_the_rest() {
    let run = circle(Plane::XY, Direction::CCW, 80.0, [0.0, 0.0, 0.0], 45.0, 540.0).run(
        "2026-11-21T10:00:00Z",
        0.0,
        "xy-ccw-540",
        "column",
    );
    let text = program(&run, &ProgramOptions::default()).unwrap();
    check_planar_replay(&run, &text, run.len() - 1, 2, 2.0);
    let arcs = blocks_with(&text, "G3");
    assert_eq!(arcs.len(), 4, "feed-in, a turn, the rest, over-shoot:\n{text}");
    assert!(arcs[1].starts_with("G3 X56.5685 Y56.5685 I-56.5685 J-56.5685 F"), "{}", arcs[1]);
    assert!(!arcs[2].contains('F'), "the feed is modal: {}", arcs[2]);
}

fn ac_trunnion() -> KinematicChain {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures/machines/five-axis-ac-trunnion.ron");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let spec = ballbar_machine_chain_file::parse(&text)
        .unwrap_or_else(|e| panic!("{}:{e}", path.display()));
    Model::new(spec, ModelOptions::default()).unwrap().chain
}

/// A rotary test on the A/C trunnion: the table ball 100 mm from the C axis line and 50 mm above
/// the table (with A and C at 0 the table frame is the base's, its origin at X = Y = 0 and
/// 190 mm above the slide: Z = 340 - 100 of tool length - 190), the bar radial, 100 mm.
fn rotary(turns: Vec<Turn>) -> RotaryTest {
    RotaryTest {
        turns,
        hold: Vec::new(),
        bar: BarDirection::Radial,
        radius_mm: 100.0,
        feed_mm_per_min: 1000.0,
        pivot_mm: [100.0, 0.0, 340.0],
        tool_ball_mm: [0.0, 0.0, -100.0],
        sample_rate_hz: 50.0,
    }
}

/// The inverse-time F words of the program, 1/min.
fn inverse_time_feeds(text: &str) -> Vec<f64> {
    let lines: Vec<&str> = text.lines().collect();
    let from = lines.iter().position(|l| l.starts_with("G93")).expect("G93");
    let to = from + lines[from..].iter().position(|l| *l == "G94").expect("G94 after G93");
    lines[from + 1..to]
        .iter()
        .map(|l| {
            let f = l
                .split_whitespace()
                .find_map(|w| w.strip_prefix('F'))
                .unwrap_or_else(|| panic!("an F word on {l}"));
            f.parse().unwrap()
        })
        .collect()
}

/// A rotary program replayed: the lead-in ends at the run's first sample; each G93 block ends
/// at the run's sample at the block's time, each within the step; the last at the last sample
/// or, where the run's turning axis stops short of a whole turn, at the whole turn (its word exactly the start's plus 360° per turn) in less than two steps' time;
/// the F words time the run; the nominal chain puts the balls R apart at every block end.
/// Returns the program's largest chord distance as its header states it, mm, and the largest
/// rotary motion of a block, degrees.
fn check_rotary_replay(
    chain: &KinematicChain,
    run: &Run,
    text: &str,
    options: &ProgramOptions,
) -> (f64, f64) {
    let points = parse(text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    let first =
        points.iter().position(|p| p.feed_mode == FeedMode::InverseTime).expect("G93 blocks");
    assert_safe_program(text, points[first].line);
    assert_at_sample(&points[first - 1], run, 0, "the lead-in's end");
    let blocks = &points[first..];
    assert!(
        blocks.iter().all(|p| p.feed_mode == FeedMode::InverseTime && p.motion == Motion::Linear),
        "the measured move is G1 in G93 alone"
    );
    let rotary: Vec<Axis> =
        Axis::ALL.into_iter().filter(|a| a.is_rotary() && run.axis(*a).is_some()).collect();
    assert!(!rotary.is_empty());
    let balls = chain.ball_setup(&run.header.pivot_mm, &run.header.tool_ball_mm);
    let (mut time, mut last) = (run.t_s[0], position(&points[first - 1]));
    let (mut last_index, mut largest) = (0, 0.0_f64);
    let t_end = run.t_s[run.len() - 1];
    let step_s = 1.0 / run.sample_rate_hz().unwrap();
    let mut closing_s = 0.0;
    for (b, p) in blocks.iter().enumerate() {
        time += p.duration_s.expect("a G93 block is timed");
        if b + 1 == blocks.len() && time > t_end + TIME_TOL_S {
            // The block that closes the whole turn, after the last sample.
            closing_s = time - t_end;
            assert!(
                closing_s < 1.5 * step_s,
                "line {}: {closing_s} s after the last sample",
                p.line
            );
            let closes = rotary.iter().any(|a| {
                let (c0, q) = (sample(run, 0)[a.index()], position(p)[a.index()]);
                let turns = ((q - c0) / 360.0).round();
                turns != 0.0 && (q - c0 - 360.0 * turns).abs() <= POSITION_TOL
            });
            assert!(closes, "line {}: {:?} closes no whole turn", p.line, p.axes);
        } else {
            let k = run.t_s.partition_point(|&t| t < time - 0.5 / run.sample_rate_hz().unwrap());
            assert!(
                k < run.len() && (run.t_s[k] - time).abs() <= TIME_TOL_S,
                "line {}: no sample at {time} s",
                p.line
            );
            assert!(k > last_index, "line {}: the blocks go forward through the run", p.line);
            assert_at_sample(p, run, k, "a block's end");
            last_index = k;
        }
        let q = position(p);
        let motion =
            rotary.iter().map(|a| (q[a.index()] - last[a.index()]).abs()).fold(0.0, f64::max);
        assert!(
            motion <= options.max_step_deg + POSITION_TOL,
            "line {}: {motion}° of rotary motion in one block",
            p.line
        );
        largest = largest.max(motion);
        let mut q_rad = q;
        for a in &rotary {
            q_rad[a.index()] = q[a.index()].to_radians();
        }
        let pose = chain.pose(&q_rad, &balls, None, None);
        let bar = (pose.tool_ball - pose.table_ball).norm();
        assert!(
            (bar - run.header.radius_mm).abs() <= BAR_TOL_MM,
            "line {}: the balls are {bar} mm apart",
            p.line
        );
        last = q;
    }
    if closing_s == 0.0 {
        assert_eq!(last_index, run.len() - 1, "the last sample is a block's end");
    }
    let duration = run.t_s[run.len() - 1] - run.t_s[0] + closing_s;
    let by_f: f64 = inverse_time_feeds(text).iter().map(|f| 60.0 / f).sum();
    assert!((by_f - duration).abs() <= TIME_TOL_S, "Σ 60/F = {by_f} s, the run takes {duration} s");
    assert_eq!(inverse_time_feeds(text).len(), blocks.len());
    let header =
        text.lines().find(|l| l.contains("chords up to")).expect("the chord in the header");
    let chord = header
        .split("chords up to ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .expect("a chord in mm");
    (chord, largest)
}

#[test]
fn a_c_radial_full_turn_replays_the_run_block_by_block() {
    let chain = ac_trunnion();
    let test = rotary(vec![Turn { axis: Axis::C, start_deg: 0.0, sweep_deg: 360.0 }]);
    let run =
        test.run(&chain, "2026-11-21T10:00:00Z", 0.0, "c-radial", "five-axis-ac-trunnion").unwrap();
    // The default step (0.1°: one block per sample here) leaves a chord below a ballbar's noise:
    // 200 (1 − cos(0.0955°/2)) mm = 0.07 µm.
    let fine = program(&run, &ProgramOptions::default()).unwrap();
    let (chord, _) = check_rotary_replay(&chain, &run, &fine, &ProgramOptions::default());
    assert!(chord <= 1e-4, "chord {chord} mm at the default step");
    let options = ProgramOptions { max_step_deg: 1.0, ..ProgramOptions::default() };
    let text = program(&run, &options).unwrap();
    let (chord, largest) = check_rotary_replay(&chain, &run, &text, &options);
    // Each block ≤ 1° of C over 360°. C moves 0.0955° per sample (a 200 mm circle at
    // 1000 mm/min, 50 Hz), so the greedy blocks are 10 samples, 0.955°.
    let blocks = inverse_time_feeds(&text).len();
    assert!((360..=400).contains(&blocks), "{blocks} blocks");
    assert!(largest > 0.9, "blocks of {largest}°");
    // The tool ball circles 200 mm from the C axis line: a chord of Δ lies 200 (1 - cos Δ/2)
    // inside the arc at its middle (7.3 µm at 0.955°), and a sample within half a sample step
    // of the middle (0.048° of C) sees at least 95 % of it.
    let sagitta = |deg: f64| 200.0 * (1.0 - (deg / 2.0).to_radians().cos());
    assert!(
        chord <= sagitta(largest) + POSITION_TOL && chord >= 0.95 * sagitta(largest),
        "chord {chord} mm, the sagitta {}",
        sagitta(largest)
    );
    // The A axis of the chain is written too, held at 0; C is unwrapped to 360 and ends at the
    // whole turn, where the tool ball is back at its start, not at the last sample (the
    // sampling stops up to a step short of the turn).
    let last = text.lines().rfind(|l| l.starts_with("G1 X")).unwrap();
    assert!(last.starts_with("G1 X200.0000 Y0.0000 Z340.0000 A0.0000 C360.0000 F"), "{last}");
    assert!(text.contains("(C: from 0.0000 to 360.0000 deg)"), "{text}");
    // Half the step, a quarter of the chord.
    let fine = ProgramOptions { max_step_deg: 0.5, ..ProgramOptions::default() };
    let (fine_chord, fine_largest) =
        check_rotary_replay(&chain, &run, &program(&run, &fine).unwrap(), &fine);
    assert!(
        fine_chord <= sagitta(fine_largest) + POSITION_TOL
            && fine_chord >= 0.95 * sagitta(fine_largest),
        "chord {fine_chord} mm at {fine_largest}°"
    );
    assert!((fine_chord / chord - 0.25).abs() < 0.03, "{fine_chord} against {chord}");
}

#[test]
fn an_a_and_c_turn_together_replays_the_run_block_by_block() {
    let chain = ac_trunnion();
    let test = rotary(vec![
        Turn { axis: Axis::C, start_deg: -90.0, sweep_deg: 360.0 },
        Turn { axis: Axis::A, start_deg: 0.0, sweep_deg: -45.0 },
    ]);
    let run = test
        .run(&chain, "2026-11-21T10:00:00Z", 0.0, "ac-together", "five-axis-ac-trunnion")
        .unwrap();
    let options = ProgramOptions::default();
    let text = program(&run, &options).unwrap();
    check_rotary_replay(&chain, &run, &text, &options);
    assert!(
        text.contains("(A: from 0.0000 to -45.0000 deg)")
            && text.contains("(C: from -90.0000 to 270.0000 deg)"),
        "{text}"
    );
    assert!(
        text.contains("G0 A0.0000 C-90.0000\n"),
        "the rotary axes reach the start before X and Y:\n{text}"
    );
}

#[test]
fn parse_errors_name_the_line_and_the_problem() {
    let cases: [(&str, usize, &str); 17] = [
        ("G0 X0\nG4\n", 2, "G4 (dwell) takes its time in seconds as P"),
        ("G1 X10 F100 P2\n", 1, "P belongs to G4 alone"),
        ("G0 X0\nG4 P1 X5\n", 2, "G4 (dwell) with a motion or axis words"),
        ("G90\nG1 X10 F100\nG1 Q5\n", 3, "unknown word Q5"),
        ("G17 G90\nG1 X10 Y0 F100\nG2 X0 Y10\n", 3, "G2 without centre"),
        ("G17\nG1 X10 Y0 F100\nG3 X0 Y10 K5\n", 3, "K is not a centre word of the XY plane"),
        ("G1 X10 F100\nG2 X0 Y10 I-10\n", 2, "unknown position"),
        ("G1 X10 Y0 F100\nG2 X0 Y-10.5 I-10\n", 2, "from its centre"),
        ("(a comment\nG1 X1 F1\n", 1, "does not close"),
        ("G1 X1 (a (nested) comment)\n", 1, "a comment inside a comment"),
        ("G91\n", 1, "G91"),
        ("G0 X0\nM3\n", 2, "no spindle"),
        ("G43.4 H1\n", 1, "G43.4 is not in the subset"),
        ("G0 X0\nX10\nG93\nG1 X5\n", 4, "without its F word"),
        ("X10\n", 1, "without a motion"),
        ("G1 X10\n", 1, "without a feed"),
        ("G1 X\n", 1, "X without a value"),
    ];
    for (text, line, what) in cases {
        let e = parse(text).expect_err(text);
        assert_eq!(e.line(), Some(line), "{text:?}: {e}");
        let message = e.to_string();
        assert!(
            message.starts_with(&format!("line {line}: ")) && message.contains(what),
            "{text:?}: expected {what:?} at line {line}, got {message}"
        );
    }
}

#[test]
fn parse_reads_comments_modes_and_the_end_of_the_program() {
    let text = "%\n(header; with a semicolon)\nN10 G90 G21 G17 G94 ; a note\ng0 x1 y2 z3 a4\nG1X1.5Y-.5F600(inline)\nG3 X-1.5 Y-.5 I-1.5 J0\nM30\nG1 X99 Q1\n%\n";
    let points = parse(text).unwrap();
    assert_eq!(points.len(), 2 + 180, "G0, G1 and a half circle in 1° steps; nothing after M30");
    assert_eq!(points[0].axes, [Some(1.0), Some(2.0), Some(3.0), Some(4.0), None, None]);
    assert_eq!(points[0].duration_s, None, "a rapid is the controller's");
    assert_eq!(points[1].motion, Motion::Linear);
    assert!((points[1].duration_s.unwrap() - (0.5_f64.hypot(2.5) / 600.0 * 60.0)).abs() < 1e-12);
    let top = &points[2 + 89];
    assert!(
        (top.axis(Axis::X).unwrap()).abs() < 1e-12
            && (top.axis(Axis::Y).unwrap() - 1.0).abs() < 1e-12,
        "CCW from +X through +Y: {top:?}"
    );
    assert_eq!(points.last().unwrap().axis(Axis::X), Some(-1.5));
    assert!(points.last().unwrap().block_end && !top.block_end);
}

#[test]
fn g2_and_g3_turn_as_iso_6983_says_in_every_plane() {
    // Seen from the + end of the plane's normal, G2 is clockwise and G3 counter-clockwise: a
    // negative and a positive turn about +Z (G17), +Y (G18), +X (G19). From a start on the
    // plane's first axis (+X in G17, +Z in G18, +Y in G19) a G3 heads for its second (+Y, +X,
    // +Z), a G2 away from it.
    let cases = [
        ("G17", Plane::XY, "X10 Y0 Z0", "I-10", Axis::Y),
        ("G18", Plane::ZX, "X0 Y0 Z10", "K-10", Axis::X),
        ("G19", Plane::YZ, "X0 Y10 Z0", "J-10", Axis::Z),
    ];
    for (code, plane, start, centre, second) in cases {
        for (arc, sign) in [("G2", -1.0), ("G3", 1.0)] {
            let text = format!("{code} G90 G94\nG0 {start}\n{arc} {start} {centre} F100\n");
            let points = parse(&text).unwrap();
            let turn =
                turn_about_normal(plane, &[0.0; 3], &position(&points[0]), &position(&points[1]));
            assert!(turn * sign > 0.0, "{code} {arc}: turns {turn} rad about the normal");
            assert!(points[1].axis(second).unwrap() * sign > 0.0, "{code} {arc}: {:?}", points[1]);
            assert_eq!(points.len(), 1 + 360, "a full circle, 1° a point");
        }
    }
}

#[test]
fn programs_are_refused_for_runs_and_options_they_cannot_be() {
    let run = circle(Plane::XY, Direction::CCW, 100.0, [0.0; 3], 0.0, 90.0).run(
        "2026-11-21T10:00:00Z",
        0.0,
        "xy",
        "column",
    );
    let bad_step = ProgramOptions { max_step_deg: 0.0, ..ProgramOptions::default() };
    assert!(matches!(
        program(&run, &bad_step),
        Err(GcodeError::Options { option: "max_step_deg", .. })
    ));
    let mut reversed = run.clone();
    reversed.header.direction = Some(Direction::CW);
    let e = program(&reversed, &ProgramOptions::default()).unwrap_err().to_string();
    assert!(
        e.starts_with("run xy: xy.csv:14: ") && e.contains("against the run's direction"),
        "{e}"
    );
    let mut free = run.clone();
    free.header.plane = Plane::Free;
    let e = program(&free, &ProgramOptions::default()).unwrap_err().to_string();
    assert!(e.contains("without a rotary axis"), "{e}");
    let mut helix = run.clone();
    helix.axes[2].as_mut().unwrap()[5] += 0.01;
    let e = program(&helix, &ProgramOptions::default()).unwrap_err().to_string();
    assert!(e.contains("not a planar circle"), "{e}");
    let mut nan = run;
    nan.axes[0].as_mut().unwrap()[3] = f64::NAN;
    assert!(program(&nan, &ProgramOptions::default()).is_err());
}

#[test]
fn words_have_four_decimals_and_comments_stay_comments() {
    assert_eq!(fmt4(-0.00004), "0.0000");
    assert_eq!(fmt4(-1.23456), "-1.2346");
    assert_eq!(fmt4(12.5), "12.5000");
    assert_eq!(fmt4(-0.5), "-0.5000");
    assert_eq!(fmt_inverse_time(600.0), "600.0000");
    assert_eq!(fmt_inverse_time(0.06), "0.060000");
    let mut run = circle(Plane::XY, Direction::CCW, 100.0, [0.0; 3], 0.0, 90.0).run(
        "2026-11-21T10:00:00Z",
        0.0,
        "xy (2)",
        "mill (bay 3); é",
    );
    run.header.pivot_mm = [-0.00001, 0.0, 0.0];
    let text = program(&run, &ProgramOptions::default()).unwrap();
    assert!(
        text.contains("(machine: mill [bay 3]; ?)") && text.contains("(run: xy [2])"),
        "{text}"
    );
    assert!(text.is_ascii() && !text.contains("-0.0000"));
    parse(&text).unwrap();
}

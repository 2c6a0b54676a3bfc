//! Bounded fuzzing of every reader of this crate: seeded random mutations of a small valid
//! input (flipped bits, bytes replaced, cuts, lines duplicated, deleted or repeated, numbers
//! made huge, tiny or not numbers) must each give a valid result or a clean error at a line of
//! the input, never a panic. The inputs stay a few kilobytes, so that each reader's time is
//! bounded by its input's size (no timing is asserted); the seeds make every run the same.

use crate::IoError;
use crate::b5r::{B5rOptions, parse_b5r};
use crate::check::MAX_READING_FRACTION;
use crate::csv::parse_run;
use crate::table::{TableSetup, parse_table};

/// Mutated inputs per reader: a second or two each in a debug build.
const CASES: usize = 10_000;

/// SplitMix64: a small generator, seeded, the same sequence everywhere.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// A number in `0..n` (`n` > 0).
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
}

/// Bytes a mutation puts in: structure of the formats (separators, line ends, markup) and bytes
/// that are not text.
const BYTES: &[u8] = b"\0\n\r,;\t#:.-+eE09 \"'<>=/&x\xff\xc3";

/// Numbers a mutation puts in place of one: beyond any range, at the edges of f64, not numbers.
const NUMBERS: &[&str] = &[
    "1e300",
    "-1e308",
    "1e309",
    "1e-320",
    "0",
    "-0",
    "nan",
    "inf",
    "-inf",
    "99999999999999999999999",
    "0.0000000000000000000001",
    "1,5",
    "",
    "1e",
    "--1",
    "0x10",
];

/// The byte ranges of the numbers in `b` (runs of digits, `.`, `e`, `E`, `+`, `-` holding a
/// digit).
fn numbers(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &c) in b.iter().chain(std::iter::once(&b' ')).enumerate() {
        let part = c.is_ascii_digit() || matches!(c, b'.' | b'e' | b'E' | b'+' | b'-');
        match (start, part) {
            (None, true) => start = Some(i),
            (Some(s), false) => {
                if b[s..i].iter().any(u8::is_ascii_digit) {
                    out.push(s..i);
                }
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// The byte ranges of the lines of `b`, each with its `\n`.
fn lines(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < b.len() {
        out.push(start..b.len());
    }
    out
}

/// One to three mutations of `input`.
fn mutate(input: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = input.to_vec();
    for _ in 0..1 + rng.below(3) {
        if b.is_empty() {
            break;
        }
        let at = rng.below(b.len());
        match rng.below(8) {
            0 => b[at] ^= 1 << rng.below(8),
            1 => b[at] = BYTES[rng.below(BYTES.len())],
            2 => b.truncate(at),
            3..=5 => {
                let ls = lines(&b);
                let l = ls[rng.below(ls.len())].clone();
                let line = b[l.clone()].to_vec();
                match rng.below(3) {
                    0 => {
                        b.splice(l.start..l.start, line);
                    }
                    1 => {
                        b.drain(l);
                    }
                    _ => {
                        // A line repeated: the input stays a few kilobytes.
                        let copies = 1 + rng.below(20);
                        let to = ls[rng.below(ls.len())].start;
                        b.splice(to..to, line.repeat(copies));
                    }
                }
            }
            _ => {
                let ns = numbers(&b);
                if !ns.is_empty() {
                    let n = ns[rng.below(ns.len())].clone();
                    b.splice(n, NUMBERS[rng.below(NUMBERS.len())].bytes());
                }
            }
        }
    }
    b
}

/// Run `read` on `CASES` mutations of `input` (seed `seed`), as text (invalid UTF-8 replaced,
/// as a reader of a file would refuse it at its line: the text readers take `&str`).
fn fuzz(input: &str, seed: u64, mut read: impl FnMut(&str)) {
    let mut rng = Rng(seed);
    for _ in 0..CASES {
        let bytes = mutate(input.as_bytes(), &mut rng);
        read(&String::from_utf8_lossy(&bytes));
    }
}

/// A clean error of a reader of `file`: its message starts with the file's name, and a line it
/// names lies within the text (one past its last line for an error at its end).
fn clean(e: &IoError, file: &str, text: &str) {
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("{file}:")), "{msg}");
    if let Some(line) = e.line() {
        let n = text.split('\n').count();
        assert!((1..=n + 1).contains(&line), "line {line} of {n}: {msg}");
    }
    assert!(msg.len() < 1000, "a message of {} bytes: {msg:.200}", msg.len());
}

/// A run a reader returned holds what [`crate::check::check_run`] accepts.
fn sound(run: &ballbar_model::Run) {
    crate::check::check_run(run).unwrap();
    let bound = MAX_READING_FRACTION * run.header.radius_mm;
    assert!(run.dr_mm.iter().all(|d| d.is_finite() && d.abs() <= bound));
}

fn run_text() -> String {
    let mut s = String::from(
        "# ballbar-run: 1\n# machine: column\n# plane: XY\n# direction: CCW\n# radius_mm: 100\n\
         # feed_mm_per_min: 1000\n# pivot_mm: 300, 200, -300\n# tool_ball_mm: 0, 0, -100\n\
         # started_at: 2026-11-21T10:00:00Z\n# run_id: xy-ccw-1\nt_s,X_mm,Y_mm,Z_mm,dR_um\n",
    );
    for i in 0..12 {
        let t = 0.01 * i as f64;
        let th = 1000.0 / 60.0 * t / 100.0;
        s.push_str(&format!(
            "{t:.3},{:.6},{:.6},-300.000000,{:.4}\n",
            300.0 + 100.0 * th.cos(),
            200.0 + 100.0 * th.sin(),
            0.5 + (7.0 * t).sin()
        ));
    }
    s
}

#[test]
fn the_run_csv_reader_gives_a_run_or_a_clean_error_on_any_mutation() {
    const FILE: &str = "runs/fuzz.csv";
    let mut read = 0;
    fuzz(&run_text(), 1, |text| match parse_run(text, FILE) {
        Ok(run) => {
            sound(&run);
            read += 1;
        }
        Err(e) => clean(&e, FILE, text),
    });
    // Some mutations leave a valid run (a changed reading, a digit): the sound branch ran.
    assert!(read > 0);
}

#[test]
fn the_table_reader_gives_a_run_or_a_clean_error_on_any_mutation() {
    const FILE: &str = "data/fuzz.csv";
    let mut text = String::from("# exported\nt_s;angle_deg;dR_um\n");
    for i in 0..12 {
        text.push_str(&format!("{:.2};{};{:.3}\n", 0.1 * i as f64, 2 * i, 1.5 - 0.1 * i as f64));
    }
    let setup = TableSetup::new(
        ballbar_model::Plane::XY,
        ballbar_model::Direction::CCW,
        100.0,
        1000.0,
        [300.0, 200.0, -300.0],
        "2026-11-21T10:00:00Z",
    );
    let mut read = 0;
    fuzz(&text, 2, |t| match parse_table(t, FILE, &setup) {
        Ok(run) => {
            sound(&run);
            read += 1;
        }
        Err(e) => clean(&e, FILE, t),
    });
    assert!(read > 0);
}

#[test]
fn the_b5r_reader_gives_runs_or_a_clean_error_on_any_mutation() {
    const FILE: &str = "fuzz.b5r";
    let mut text = String::from(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<TEST_DOCUMENT>\n<TEST_SPEC NAME=\"t\" version=\"2.0\">\n\
         <INSTRUMENT MODEL=\"QC20\"><DYNAMIC_BALLBAR>\n<NOMINAL_LENGTH>100</NOMINAL_LENGTH>\n\
         <PROGRAMMED_FEEDRATE>11781</PROGRAMMED_FEEDRATE>\n<START_ANGLE>0</START_ANGLE>\n\
         <END_ANGLE>90</END_ANGLE>\n<OVERSHOOT_ANGLE>2</OVERSHOOT_ANGLE>\n\
         <PLANE VIEW=\"+A+B\" TEST_PLANE=\"XY\"><A_AXIS_NAME>X</A_AXIS_NAME><B_AXIS_NAME>Y</B_AXIS_NAME></PLANE>\n\
         <SAMPLE_RATE>10</SAMPLE_RATE>\n</DYNAMIC_BALLBAR></INSTRUMENT>\n</TEST_SPEC>\n\
         <OPERATOR>J. Doe</OPERATOR>\n<DATE_STARTED>20250904-161049</DATE_STARTED>\n\
         <MACHINE_TESTED NAME=\"VMC 7\" />\n<RUN_RESULTS>\n",
    );
    for dir in ["CCW", "CW"] {
        text.push_str(&format!(
            "<BALLBAR_RUN>\n<RUN_DIRECTION>{dir}</RUN_DIRECTION>\n<START_INDEX>1</START_INDEX>\n\
             <END_INDEX>8</END_INDEX>\n<SAMPLE_RATE>10</SAMPLE_RATE>\n\
             <READINGS>0.5 0.0011 0.0012 0.0013 0.0012 0.0011 0.0010 0.0009 0.0008 0.5</READINGS>\n\
             <FEATURE NAME=\"AF_CIRCULARITY\" DT=\"UT_LENGTH_MM\">0.0060</FEATURE>\n</BALLBAR_RUN>\n"
        ));
    }
    text.push_str(
        "</RUN_RESULTS>\n<ANALYSIS NAME=\"RENISHAW_DIAGNOSTICS\" version=\"2.1\">\n\
         <FEATURE NAME=\"AF_SQUARENESS\" DT=\"UT_SQUARENESS\">-10.3</FEATURE>\n\
         <SIMULATION NAME=\"AF_SIMULATED_READINGS_CCW\">0.001 0.002 0.003</SIMULATION>\n\
         </ANALYSIS>\n</TEST_DOCUMENT>\n",
    );
    let mut read = 0;
    fuzz(&text, 3, |t| match parse_b5r(t, FILE, &B5rOptions::default()) {
        Ok(test) => {
            test.runs.iter().for_each(sound);
            read += 1;
        }
        Err(e) => clean(&e, FILE, t),
    });
    assert!(read > 0);
}

#[test]
fn the_gcode_reader_gives_points_or_an_error_at_a_line_on_any_mutation() {
    let run = parse_run(&run_text(), "runs/fuzz.csv").unwrap();
    let program = crate::gcode::program(&run, &Default::default()).unwrap();
    let mut read = 0;
    fuzz(&program, 4, |t| match crate::gcode::parse(t) {
        Ok(_) => read += 1,
        Err(e) => {
            let n = t.split('\n').count();
            assert!(e.line().is_some_and(|l| (1..=n).contains(&l)), "{e}");
        }
    });
    assert!(read > 0);
}

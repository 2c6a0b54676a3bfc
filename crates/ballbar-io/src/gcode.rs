//! The part program (ISO 6983 G-code) that makes a machine run a ballbar test, written from a
//! commanded [`Run`] ([`program`]), and a reader of the subset it writes ([`parse`]) so that a
//! program can be replayed against the run it came from.
//!
//! # What [`program`] writes
//!
//! Every program: header comments saying what it is (machine, run id, plane, radius, feed,
//! pivot, balls), the safe preamble `G90 G21 G40 G49 G80` and the work offset `G54`, no tool
//! change and no spindle start (the ballbar must not turn), a lead-in to the start point, `M0`
//! with a comment to fit the ballbar and start its capture, the measured move, `M30`. Numbers
//! have 4 decimals (mm and degrees, 0.1 µm and 0.36″), never `-0.0000`.
//!
//! The lead-in: `G0` of Z to `clearance_mm` above the start, `G0` of the rotary axes, `G0` of
//! X and Y, then `G1` of Z down to the start at the run's feed. +Z is the tool leaving the
//! workpiece (ISO 841) on every machine type, so that is the one direction a generic program
//! can clear in; the path from the current position to the clearance point is the operator's
//! to check.
//!
//! **Planar runs** (`XY`, `YZ`, `ZX`): the plane select (`G17`, `G19`, `G18`) and circular
//! interpolation `G2`/`G3` about the pivot, the centre as `I`/`J`/`K` (incremental from the
//! arc's start: the ISO default, whatever `G90`), the feed `F` in mm/min. `G2` is clockwise and
//! `G3` counter-clockwise seen from the positive third axis: from +Z in `G17`, from +X in
//! `G19`, from +Y in `G18`. That is the run format's `direction` in every plane; in `ZX` its
//! angle runs from +Z towards +X, a positive turn about +Y, so `CCW` is `G3` in `G18` too.
//! (An operator in front of a vertical machine sees the ZX plane from -Y, where a `G2` looks
//! anticlockwise: the program follows the standard, not that view.) The data arc, the run's
//! commanded path, starts at the run's first sample; a partial arc ends at the run's last
//! sample; a run whose samples close a whole turn (to within 1.5 of its sample steps: sampling
//! stops the run up to one step short of the turn) is a full circle, ending where it started,
//! one block per turn. Around it, the moves a ballbar's capture routine (Renishaw QC10/QC20)
//! expects of a test, as the vendor's own test program makes them: the ballbar is fitted at
//! the start of a feed-in arc of [`ProgramOptions::overshoot_deg`] on the same circle before
//! the data arc, and an over-shoot arc as long follows it (the vendor's `.b5r` readings hold
//! both, `OVERSHOOT_ANGLE` each, around `START_INDEX ..= END_INDEX`); a dwell of [`DWELL_S`]
//! (`G4 P1.0000`), then the same arcs in the other direction, so that one program gives the
//! capture both runs of the test, this run's direction first. The header states the arc, the
//! over-shoot and the feed.
//!
//! **Free runs** (rotary tests, [`ballbar_model::path::RotaryTest`]): `G1` blocks with every
//! axis of the run as a word (X, Y, Z in mm; A, B, C in degrees), one block every
//! [`ProgramOptions::max_step_deg`] of the largest rotary motion, through the run's own samples
//! (the last sample always). The feed is inverse time, `G93`, with `F = 60 / Δt` per block
//! (1/min) from the run's time between its samples, so the path is timed as simulated whatever
//! the controller's rule for the feed of combined linear and rotary motion; then `G94` again.
//! Between its ends the controller interpolates every axis linearly in time: X, Y, Z then
//! follow the chord of the path, a distance up to `r(1 - cos(Δ/2)) ≈ rΔ²/8` from it for a ball
//! `r` from the rotary axis line and blocks of `Δ` rad (9.5 µm at 250 mm and 1°), seen in the
//! ballbar reading as far as it lies along the bar (all of it for a radial bar). The header
//! states the largest chord distance of the program; halve the step to quarter it.
//!
//! # What a user adapts per controller
//!
//! - **Work offset.** The program's coordinates are the run's axis coordinates, the model's
//!   machine coordinates: its error terms use the absolute positions along each axis's travel,
//!   and a rotary test's chain places the rotary axis lines in them. So `G54` should be a zero
//!   offset (more exactly: the frame the chain file is written in), and the run's pivot the
//!   machine position at which the tool ball sits on the table ball (touched off on the centre
//!   ball). A `G54` shifted by `d` moves a planar circle by `d`, harmless if the centre ball is
//!   there too, but it does not move a rotary axis line: after a turn `θ` the tool ball misses
//!   the bar's end by `2|d⊥| sin(θ/2)` (`d⊥` the shift across the turning axis), up to twice
//!   the shift half a turn on.
//! - **TCP / RTCP off.** The program is written in machine-axis coordinates solved from the
//!   nominal chain: tool centre point control (Fanuc `G43.4`/`G43.5`, Siemens `TRAORI`,
//!   Heidenhain `M128`/`FUNCTION TCPM`) must be off, or the controller would solve the chain a
//!   second time. `G49` cancels it on Fanuc-like controllers; elsewhere use `TRAFOOF` (Siemens),
//!   `M129`/`FUNCTION RESET TCPM` (Heidenhain). No tool length compensation either: the run's
//!   coordinates are of the spindle gauge point, the tool ball's offset is in the chain.
//! - **Rotary wrap.** Rotary words are the run's continuous angles (`C0` to `C360`, or `C-30` to
//!   `C330`), never folded into 0–360°. A C axis with roll-over or shortest-path positioning
//!   (Fanuc's roll-over parameters, Siemens modulo axes and `DC`/`ACP`/`ACN`, Heidenhain `M126`)
//!   may fold the words or take the short way round: set it to linear (non-modulo) counting for
//!   the test, or check that the absolute words keep turning the intended way. The blocks are
//!   at most `max_step_deg` apart, far below half a turn, so shortest-path positioning between
//!   consecutive words takes the intended way as long as the count is not folded.
//! - **Inverse time.** `G93` is the ISO way to time a block of combined linear and rotary
//!   motion (Fanuc as an option, Haas, LinuxCNC, Siemens). A controller without it needs `G94`
//!   and an `F` per block computed with its own rule for combined motion; the run's timing is
//!   what to match. The last block is shorter than the others (the run's tail): its `F` is
//!   larger, its speed the same.
//! - **Block rate.** At 1° a rotary test at 1000 mm/min and 250 mm from the axis line runs about
//!   4 blocks per second, far below any controller's limit; finer steps shrink the chord error
//!   but raise the rate. Smoothing modes (Fanuc `G5.1`/`G5.4`, Siemens `G64`/`CYCLE832`,
//!   Heidenhain cycle 32) round the corners between blocks and change the path: use the
//!   tightest tolerance for the test.
//! - **The vendor's capture moves.** The feed-in and over-shoot arcs are arcs on the test
//!   circle, of the over-shoot the capture software is set to (`--overshoot-deg`, 180° for a
//!   full circle and 2° for a partial arc by default); a capture set up for a radial feed-in
//!   move instead wants that move added as its manual says. A rotary test's program is the run
//!   itself, with no over-shoot.
//! - **Dwell.** `G4 P1.0000` is one second where `P` is seconds (ISO 6983, LinuxCNC, Haas,
//!   Siemens `G4 F1`); Fanuc-like controllers read `P` in milliseconds: write `G4 X1.0` there.
//! - **Program framing.** A program number (`O`), a different start (`%`) or end (`M2`) are the
//!   controller's.
//!
//! # What [`parse`] reads
//!
//! The subset written here: modal `G0`, `G1`, `G2`, `G3`, `G17`, `G18`, `G19`, `G90`, `G93`,
//! `G94` (and the preamble's `G21`, `G40`, `G49`, `G80`, `G54`–`G59`, which change no position),
//! the dwell `G4 P<seconds>` (a point where the axes rest, [`Motion::Dwell`]), words X Y Z A B C
//! I J K F, block numbers `N`, a program number `O`, `M0`, `M1`, `M2`, `M30`
//! (the program ends at `M2`/`M30`), `%` lines, comments in parentheses and after `;`. It gives
//! the position reached at the end of each motion block ([`ProgramPoint`]), and along an arc a
//! point every 1° or less. Anything else (`G91`, `G20`, `G43.4`, `R`, `S`, `T`, `M3`, ...) is an
//! error naming the 1-based line: a replay that skipped it would not be the program.

use ballbar_model::{Axis, Direction, Plane, Run};

/// The resolution of the words written, per unit (mm or degree): 4 decimals.
const TICKS_PER_UNIT: f64 = 1e4;

/// The largest value a coordinate word may have, mm or degrees: no machine has a 100 km axis,
/// and the integer arithmetic of the words stays exact far beyond it.
const MAX_WORD: f64 = 1e8;

/// How far the end of an arc may be from its centre, compared with its start, mm. The words'
/// rounding to 4 decimals moves each point by up to 0.7e-4 mm in the plane, the centre as much:
/// 1 µm is seven times that and still far below anything a ballbar would show as a spiral.
pub const ARC_RADIUS_TOLERANCE_MM: f64 = 1e-3;

/// The largest angle between two points that [`parse`] gives along an arc, degrees.
pub const ARC_POINT_STEP_DEG: f64 = 1.0;

/// How far a planar run's third axis may move from its first sample, mm: the program holds it,
/// and a run whose third axis moves more than the program's resolution is not a planar circle
/// (the commanded runs hold it exactly; 1 µm leaves room for a file's rounding).
const PLANAR_THIRD_AXIS_TOLERANCE_MM: f64 = 1e-3;

/// How far a step between samples may turn against the run's direction, rad: the rounding of
/// the run's coordinates to 1e-6 mm turns a sample by 1e-7 rad at a radius of 10 mm.
const ANGLE_JITTER_RAD: f64 = 1e-6;

/// How a held rotary axis of a planar run may move, rad (the run file's 1e-6° resolution,
/// with room).
const HELD_ROTARY_TOLERANCE_RAD: f64 = 1e-7;

/// Options of [`program`].
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub struct ProgramOptions {
    /// Free runs: the largest rotary motion of one block, degrees (default 0.1). The block ends
    /// are the run's samples, each the farthest from the last one within this step. Between
    /// block ends the controller moves every axis linearly, so X, Y, Z cut the arc by up to
    /// r (1 − cos(Δ/2)): 9.5 µm at r = 250 mm for 1°, which a radial bar reads in full and a
    /// fit would take for machine error; 0.1° leaves 0.1 µm, below a ballbar's noise, at
    /// 10 blocks per degree (80 blocks/s at 1000 mm/min and r = 120 mm).
    pub max_step_deg: f64,
    /// The lead-in clears in +Z by this much above the start point before it moves the other
    /// axes, mm (default 20).
    pub clearance_mm: f64,
    /// Planar runs: the over-shoot, degrees, of the feed-in arc before the data arc and of the
    /// arc after it, in each direction; `None` for the default: [`FULL_CIRCLE_OVERSHOOT_DEG`]
    /// for a full circle, [`PARTIAL_ARC_OVERSHOOT_DEG`] for a partial arc.
    pub overshoot_deg: Option<f64>,
}

impl Default for ProgramOptions {
    fn default() -> Self {
        ProgramOptions { max_step_deg: 0.1, clearance_mm: 20.0, overshoot_deg: None }
    }
}

/// The default over-shoot of a full circle, degrees: the real Renishaw file's
/// (`OVERSHOOT_ANGLE` 180; its readings hold 789 samples before `START_INDEX` and 789 after
/// `END_INDEX`, 180.9° each at 125 Hz, 1500 mm/min and R = 50 mm).
pub const FULL_CIRCLE_OVERSHOOT_DEG: f64 = 180.0;

/// The default over-shoot of a partial arc, degrees: the smallest the vendor's files hold
/// (`shared/spec/vendor-b5r.md`: 2-180°), since an arc is partial where the whole circle does
/// not fit the machine.
pub const PARTIAL_ARC_OVERSHOOT_DEG: f64 = 2.0;

/// The dwell between the two directions of a planar test, s: the machine comes to rest before
/// it reverses, so the capture sees one run end and the next begin.
pub const DWELL_S: f64 = 1.0;

/// Why a program cannot be written or read.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GcodeError {
    /// The run cannot be written as a program (columns missing or of the wrong length, values
    /// not finite, samples that go against the run's direction, a free run without a rotary
    /// axis that turns, ...).
    #[error("run {run}: {message}")]
    Run {
        /// The run's name ([`Run::name`]).
        run: String,
        /// What is wrong.
        message: String,
    },
    /// An option of [`ProgramOptions`] is out of its range.
    #[error("program option {option}: {message}")]
    Options {
        /// The field's name.
        option: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A line of a program is not in the subset that [`parse`] reads, or is wrong.
    #[error("line {line}: {message}")]
    Line {
        /// 1-based line.
        line: usize,
        /// What is wrong.
        message: String,
    },
}

impl GcodeError {
    /// The 1-based line of a program the error is about, for [`GcodeError::Line`].
    pub fn line(&self) -> Option<usize> {
        match self {
            GcodeError::Line { line, .. } => Some(*line),
            GcodeError::Run { .. } | GcodeError::Options { .. } => None,
        }
    }
}

/// The motion of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    /// `G0`: positioning at rapid traverse.
    Rapid,
    /// `G1`: linear interpolation.
    Linear,
    /// `G4`: a dwell, the axes at rest for the block's `P` seconds.
    Dwell,
    /// `G2` (clockwise) or `G3` (counter-clockwise) in `plane`, seen from the plane's positive
    /// third axis, as the run format's directions are.
    Arc {
        /// `G17` (XY), `G18` (ZX), `G19` (YZ).
        plane: Plane,
        /// `G2`: [`Direction::CW`]; `G3`: [`Direction::CCW`].
        direction: Direction,
    },
}

/// The feed mode of a block.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FeedMode {
    /// `G94`: F is the path speed, mm/min.
    UnitsPerMinute,
    /// `G93`: F is the inverse of the block's time, 1/min.
    InverseTime,
}

/// A position the program reaches: the end of a motion block, or a point along an arc.
#[derive(Clone, Debug, PartialEq)]
pub struct ProgramPoint {
    /// The 1-based line of the block.
    pub line: usize,
    /// The block's motion.
    pub motion: Motion,
    /// The feed mode of the block.
    pub feed_mode: FeedMode,
    /// Axis positions in [`Axis::ALL`] order, mm and degrees as written; `None` for an axis that
    /// no block before has given.
    pub axes: [Option<f64>; 6],
    /// Time from the previous point to this one, s, where the program alone fixes it: a `G93`
    /// block (`60/F`, shared along an arc by angle), a `G94` move of linear axes alone
    /// (length/F). `None` for `G0` and for a `G94` move of a rotary axis, which each controller
    /// times by its own rule.
    pub duration_s: Option<f64>,
    /// True for the point at the end of its block (every `G0`/`G1` point, an arc's last).
    pub block_end: bool,
}

impl ProgramPoint {
    /// The position of one axis, mm or degrees.
    pub fn axis(&self, axis: Axis) -> Option<f64> {
        self.axes[axis.index()]
    }
}

// ---------------------------------------------------------------------------------------------
// Writing.

/// A value in ten-thousandths of its unit.
fn ticks(v: f64) -> i64 {
    (v * TICKS_PER_UNIT).round() as i64
}

/// Ten-thousandths written with 4 decimals; zero is never negative.
fn fmt_ticks(t: i64) -> String {
    let sign = if t < 0 { "-" } else { "" };
    let a = t.unsigned_abs();
    format!("{sign}{}.{:04}", a / 10_000, a % 10_000)
}

/// A value written with 4 decimals, never `-0.0000`.
fn fmt4(v: f64) -> String {
    fmt_ticks(ticks(v))
}

/// An inverse-time feed, 1/min: 4 decimals, and more below 1/min so that the block's time
/// keeps five significant digits.
fn fmt_inverse_time(f: f64) -> String {
    let extra = (-f.log10().floor()).clamp(0.0, 4.0) as usize;
    format!("{:.*}", 4 + extra, f)
}

/// Text for a comment: parentheses would end it early, line breaks would end the block, and
/// controllers take ASCII alone.
fn comment_text(s: &str) -> String {
    s.chars()
        .map(|c| match c {
            '(' => '[',
            ')' => ']',
            c if c.is_ascii_control() => ' ',
            c if !c.is_ascii() => '?',
            c => c,
        })
        .collect()
}

/// The word letter of the centre offset along an axis.
fn centre_letter(axis: Axis) -> char {
    match axis {
        Axis::X => 'I',
        Axis::Y => 'J',
        _ => 'K',
    }
}

/// The plane-select code of a plane.
fn plane_code(plane: Plane) -> &'static str {
    match plane {
        Plane::XY => "G17",
        Plane::ZX => "G18",
        _ => "G19",
    }
}

/// Write the part program that runs `run` (see the module documentation).
///
/// Errors: options out of range; a run with fewer than two samples, columns of the wrong length,
/// values that are not finite or not positive where they must be; a planar run without
/// direction, without one of its in-plane axes, whose third axis or held rotary axes move, or
/// whose samples turn against its direction; a free run without a rotary axis that turns, or
/// whose time does not increase.
pub fn program(run: &Run, options: &ProgramOptions) -> Result<String, GcodeError> {
    check_options(options)?;
    let fail = |message: String| GcodeError::Run { run: run.name(), message };
    check_run(run).map_err(fail)?;
    let mut out = Program::default();
    out.header(run);
    match run.header.plane {
        Plane::Free => free(run, options, &mut out).map_err(fail)?,
        plane => planar(run, plane, options, &mut out).map_err(fail)?,
    }
    out.line("(remove the ballbar before the machine moves again)");
    out.line("M30");
    out.line("%");
    Ok(out.text)
}

fn check_options(options: &ProgramOptions) -> Result<(), GcodeError> {
    // Below 0.001° the 4-decimal rotary words (1e-4°) would be a tenth of a step; beyond 90° a
    // chord of the path is no longer anything like the path.
    if !(options.max_step_deg.is_finite() && (0.001..=90.0).contains(&options.max_step_deg)) {
        return Err(GcodeError::Options {
            option: "max_step_deg",
            message: format!("{} is not between 0.001 and 90 degrees", options.max_step_deg),
        });
    }
    if !(options.clearance_mm.is_finite() && (0.0..=MAX_WORD).contains(&options.clearance_mm)) {
        return Err(GcodeError::Options {
            option: "clearance_mm",
            message: format!("{} is not a distance of 0 mm or more", options.clearance_mm),
        });
    }
    // Below 0.01° the feed-in arc's ends would be a few word steps apart on a small circle (an
    // arc whose ends meet is a full circle); beyond 180° the over-shoots of the two directions
    // would overlap the data arc by more than the vendor's do.
    if let Some(o) = options.overshoot_deg
        && !(o.is_finite() && (0.01..=180.0).contains(&o))
    {
        return Err(GcodeError::Options {
            option: "overshoot_deg",
            message: format!("{o} is not between 0.01 and 180 degrees"),
        });
    }
    Ok(())
}

fn check_run(run: &Run) -> Result<(), String> {
    let n = run.len();
    if n < 2 {
        return Err(format!("{n} samples: a program needs at least two"));
    }
    if run.t_s.iter().any(|t| !t.is_finite()) {
        return Err("a time is not finite".into());
    }
    for a in Axis::ALL {
        if let Some(c) = run.axis(a) {
            if c.len() != n {
                return Err(format!(
                    "column {} has {} values for {n} times",
                    a.column_name(),
                    c.len()
                ));
            }
            let limit = if a.is_rotary() { MAX_WORD.to_radians() } else { MAX_WORD };
            if let Some(k) = c.iter().position(|v| !(v.is_finite() && v.abs() <= limit)) {
                return Err(format!(
                    "{}: {} is {}, not a finite coordinate within {MAX_WORD:e}",
                    at(run, k),
                    a.column_name(),
                    c[k]
                ));
            }
        }
    }
    let h = &run.header;
    if !(h.feed_mm_per_min.is_finite() && h.feed_mm_per_min > 0.0) {
        return Err(format!("feed_mm_per_min is {}, not a positive feed", h.feed_mm_per_min));
    }
    if !(h.radius_mm.is_finite() && h.radius_mm > 0.0) {
        return Err(format!("radius_mm is {}, not a positive radius", h.radius_mm));
    }
    if h.pivot_mm.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_WORD)) {
        return Err(format!("pivot_mm {:?} is not a finite position", h.pivot_mm));
    }
    Ok(())
}

/// The program's text, a line at a time.
#[derive(Default)]
struct Program {
    text: String,
}

impl Program {
    fn line(&mut self, s: impl AsRef<str>) {
        self.text.push_str(s.as_ref());
        self.text.push('\n');
    }

    fn comment(&mut self, s: impl AsRef<str>) {
        let s = comment_text(s.as_ref());
        self.line(format!("({s})"));
    }

    fn header(&mut self, run: &Run) {
        let h = &run.header;
        let xyz = |p: &[f64; 3]| format!("X{} Y{} Z{}", fmt4(p[0]), fmt4(p[1]), fmt4(p[2]));
        self.line("%");
        self.comment("BALLBAR TEST - part program written by ballbar from a commanded run");
        self.comment(format!("machine: {}", h.machine.as_deref().unwrap_or("not named")));
        self.comment(format!("run: {}", run.name()));
        let direction = h.direction.map(|d| format!(", direction {d}")).unwrap_or_default();
        self.comment(format!("plane: {}{direction}", h.plane));
        self.comment(format!(
            "radius, the bar length: {} mm; feed: {} mm/min",
            fmt4(h.radius_mm),
            fmt4(h.feed_mm_per_min)
        ));
        self.comment(format!("pivot, where the balls meet: {} mm", xyz(&h.pivot_mm)));
        self.comment(format!("table ball: {} mm in the table frame", xyz(&h.table_ball_mm)));
        self.comment(format!(
            "tool ball: {} mm from the spindle gauge point",
            xyz(&h.tool_ball_mm)
        ));
        self.comment(
            "machine-axis coordinates in G54 as the run's: no tool length compensation, TCPM off",
        );
        self.comment("no tool change, no spindle: the ballbar must not turn");
        self.line("G90 G21 G40 G49 G80");
        self.line("G54");
    }

    /// The lead-in to `start` (every axis the program gives, in [`Axis::ALL`] order): Z clear,
    /// rotary axes, X and Y, then Z down at the feed. Without a Z word, one rapid move.
    fn lead_in(&mut self, start: &[Option<i64>; 6], clearance_mm: f64, feed_mm_per_min: f64) {
        let axis_words = |axes: &[Axis]| -> String {
            axes.iter()
                .filter_map(|&a| start[a.index()].map(|t| format!("{}{}", a.name(), fmt_ticks(t))))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let rotary: Vec<Axis> = [Axis::A, Axis::B, Axis::C]
            .into_iter()
            .filter(|a| start[a.index()].is_some())
            .collect();
        let Some(z) = start[Axis::Z.index()] else {
            self.comment(
                "lead-in: to the start point, the ballbar not fitted; check the way there",
            );
            self.line(format!("G0 {}", axis_words(&Axis::ALL)));
            return;
        };
        self.comment(format!(
            "lead-in: Z {} mm clear above the start, then the other axes, then down at the feed",
            fmt4(clearance_mm)
        ));
        self.comment("the ballbar not fitted; check the way there");
        self.line(format!("G0 Z{}", fmt_ticks(z + ticks(clearance_mm))));
        if !rotary.is_empty() {
            self.line(format!("G0 {}", axis_words(&rotary)));
        }
        let xy = axis_words(&[Axis::X, Axis::Y]);
        if !xy.is_empty() {
            self.line(format!("G0 {xy}"));
        }
        self.line(format!("G1 Z{} F{}", fmt_ticks(z), fmt4(feed_mm_per_min)));
    }

    fn start_ballbar(&mut self) {
        self.line("M0 (fit the ballbar and start its data capture, then cycle start)");
    }
}

/// Where sample `k` of a run comes from: its file and line, for messages.
fn at(run: &Run, k: usize) -> String {
    match run.lines.get(k) {
        Some(line) => format!("{}:{line}", run.source),
        None => format!("sample {}", k + 1),
    }
}

/// The angle of each sample about the pivot in the plane (from +U towards +V), unwrapped, and
/// the largest step between samples, rad. Each step must turn the run's way (within the
/// coordinates' rounding) and by less than a quarter turn (else the way round is ambiguous).
fn unwrapped_angles(
    u: &[f64],
    v: &[f64],
    centre: (f64, f64),
    sign: f64,
    at: &dyn Fn(usize) -> String,
) -> Result<(Vec<f64>, f64), String> {
    use std::f64::consts::{FRAC_PI_2, PI, TAU};
    let mut angles = Vec::with_capacity(u.len());
    let mut largest: f64 = 0.0;
    for k in 0..u.len() {
        let raw = (v[k] - centre.1).atan2(u[k] - centre.0);
        let Some(&last) = angles.last() else {
            angles.push(raw);
            continue;
        };
        let step = (raw - last + PI).rem_euclid(TAU) - PI;
        if step.abs() >= FRAC_PI_2 {
            return Err(format!(
                "{}: {:.1}° about the pivot from the sample before: the way round is ambiguous",
                at(k),
                step.abs().to_degrees()
            ));
        }
        if step * sign < -ANGLE_JITTER_RAD {
            return Err(format!(
                "{}: the sample turns {:.6}° against the run's direction",
                at(k),
                step.abs().to_degrees()
            ));
        }
        largest = largest.max(step.abs());
        angles.push(last + step);
    }
    Ok((angles, largest))
}

/// The whole number of turns a sweep of `sweep_rad` (≥ 0) closes, where it is within 1.5 of
/// its largest sample step `step_rad` of one: sampled at a fixed rate, a test of whole turns
/// stops up to one step short of its end (the last sample at or before it), and the rounding
/// of the samples' coordinates adds less than half a step. `None` for a partial arc.
fn whole_turns(sweep_rad: f64, step_rad: f64) -> Option<f64> {
    let turn = std::f64::consts::TAU;
    let whole = (sweep_rad / turn).round();
    (whole >= 1.0 && (sweep_rad - whole * turn).abs() <= 1.5 * step_rad).then_some(whole)
}

/// A free run whose turning rotary axis stops short of a whole number of turns
/// ([`whole_turns`]), with a last sample at the whole turn: the turning axis exactly there,
/// the other axes continued at their last step's rate for the time it takes at its own (or,
/// where no other rotary axis turns, back at their first sample, since the commanded X, Y, Z
/// of a single turn are a function of its angle). The axis and the degrees the samples stop
/// short; `None` when no axis does.
fn closing_whole_turn(run: &Run) -> Option<(Run, Axis, f64)> {
    let n = run.len();
    if n < 3 {
        return None;
    }
    let turning = |c: &[f64]| c.iter().any(|x| (x - c[0]).abs() > HELD_ROTARY_TOLERANCE_RAD);
    let rotary: Vec<(Axis, &[f64])> = [Axis::A, Axis::B, Axis::C]
        .into_iter()
        .filter_map(|a| run.axis(a).map(|c| (a, c)))
        .filter(|(_, c)| turning(c))
        .collect();
    let (axis, c, whole) = rotary.iter().find_map(|&(a, c)| {
        let step = c.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
        whole_turns((c[n - 1] - c[0]).abs(), step).map(|whole| (a, c, whole))
    })?;
    let sign = (c[n - 1] - c[0]).signum();
    let end = c[0] + sign * whole * std::f64::consts::TAU;
    let gap = (end - c[n - 1]) * sign;
    let dt_last = run.t_s[n - 1] - run.t_s[n - 2];
    let rate = (c[n - 1] - c[n - 2]) / dt_last;
    let dt = (end - c[n - 1]) / rate;
    // Already at the whole turn to the words' resolution, or no step to time the rest by.
    if gap * 180.0 / std::f64::consts::PI < 0.5 / TICKS_PER_UNIT || !(dt.is_finite() && dt > 0.0) {
        return None;
    }
    let alone = rotary.len() == 1;
    let mut closed = run.clone();
    closed.t_s.push(run.t_s[n - 1] + dt);
    for b in Axis::ALL {
        let Some(col) = closed.axes[b.index()].as_mut() else { continue };
        let value = if b == axis {
            end
        } else if alone {
            col[0]
        } else {
            col[n - 1] + (col[n - 1] - col[n - 2]) / dt_last * dt
        };
        col.push(value);
    }
    closed.dr_mm.push(run.dr_mm[n - 1]);
    if let Some(&line) = run.lines.last() {
        closed.lines.push(line);
    }
    Some((closed, axis, gap.to_degrees()))
}

fn planar(
    run: &Run,
    plane: Plane,
    options: &ProgramOptions,
    out: &mut Program,
) -> Result<(), String> {
    let h = &run.header;
    let (u, v, w) = plane.axes().ok_or("not a planar run")?;
    let direction = h.direction.ok_or("a planar run needs its direction")?;
    let cu =
        run.axis(u).ok_or_else(|| format!("the {plane} plane needs column {}", u.column_name()))?;
    let cv =
        run.axis(v).ok_or_else(|| format!("the {plane} plane needs column {}", v.column_name()))?;
    let last = run.len() - 1;
    let w0 = run.axis(w).map(|c| c[0]).unwrap_or(h.pivot_mm[w.index()]);
    if let Some(c) = run.axis(w)
        && let Some(k) = c.iter().position(|x| (x - w0).abs() > PLANAR_THIRD_AXIS_TOLERANCE_MM)
    {
        return Err(format!(
            "{}: {} moves {:.4} mm from its first value: not a planar circle",
            at(run, k),
            w.column_name(),
            c[k] - w0
        ));
    }
    let mut start: [Option<i64>; 6] = [None; 6];
    start[u.index()] = Some(ticks(cu[0]));
    start[v.index()] = Some(ticks(cv[0]));
    start[w.index()] = Some(ticks(w0));
    for a in [Axis::A, Axis::B, Axis::C] {
        if let Some(c) = run.axis(a) {
            if let Some(k) = c.iter().position(|x| (x - c[0]).abs() > HELD_ROTARY_TOLERANCE_RAD) {
                return Err(format!(
                    "{}: {} turns in a planar run (the program holds it)",
                    at(run, k),
                    a.column_name()
                ));
            }
            start[a.index()] = Some(ticks(c[0].to_degrees()));
        }
    }

    let sign = direction.angular_sign();
    let (pu, pv) = (h.pivot_mm[u.index()], h.pivot_mm[v.index()]);
    let (angles, largest_step) = unwrapped_angles(cu, cv, (pu, pv), sign, &|k| at(run, k))?;
    let sweep = angles[last] - angles[0];
    let turn = std::f64::consts::TAU;
    // A whole number of turns, cut short by the sampling: closed at the start.
    let closed_turns = whole_turns(sweep.abs(), largest_step);
    let (closed, whole) = (closed_turns.is_some(), closed_turns.unwrap_or(0.0));
    let full_turns = if closed { whole as usize } else { (sweep.abs() / turn).floor() as usize };

    let (su, sv) = (ticks(cu[0]), ticks(cv[0]));
    let (eu, ev) = (ticks(cu[last]), ticks(cv[last]));
    if !closed && (eu, ev) == (su, sv) {
        return Err(format!(
            "the arc ({:.6}°) ends where it starts at the program's 0.0001 mm: it would run as a full circle",
            sweep.to_degrees()
        ));
    }
    let code = match direction {
        Direction::CW => "G2",
        Direction::CCW => "G3",
    };

    let (reverse, reverse_code) = match direction {
        Direction::CW => (Direction::CCW, "G3"),
        Direction::CCW => (Direction::CW, "G2"),
    };
    let overshoot_deg = options.overshoot_deg.unwrap_or(if closed {
        FULL_CIRCLE_OVERSHOOT_DEG
    } else {
        PARTIAL_ARC_OVERSHOOT_DEG
    });
    // The over-shoot arcs lie on the data arc's circle as written: the radius of its start
    // word about the pivot's, so that every arc's ends agree with its centre to the words.
    let radius = ((su - ticks(pu)) as f64).hypot((sv - ticks(pv)) as f64) / TICKS_PER_UNIT;
    let on_circle =
        |angle: f64| (ticks(pu + radius * angle.cos()), ticks(pv + radius * angle.sin()));
    let o = overshoot_deg.to_radians();
    let end_angle = if closed { angles[0] + sign * whole * turn } else { angles[last] };
    let feed_in_start = on_circle(angles[0] - sign * o);
    let overshoot_end = on_circle(end_angle + sign * o);
    let data_end = if closed { (su, sv) } else { (eu, ev) };

    out.comment(format!(
        "arc: from {} deg, +{u} towards +{v}; {} {} deg {direction}: {code} in {}",
        fmt4(angles[0].to_degrees().rem_euclid(360.0)),
        if closed { "a full" } else { "a sweep of" },
        fmt4(if closed { whole * 360.0 } else { sweep.abs().to_degrees() }),
        plane_code(plane)
    ));
    out.comment(format!(
        "over-shoot: {} deg, a feed-in arc before the data arc and an over-shoot arc after it; feed: {} mm/min",
        fmt4(overshoot_deg),
        fmt4(h.feed_mm_per_min)
    ));
    out.comment(format!(
        "both directions, as the ballbar's capture takes a test: {direction} (this run), a dwell of {} s, then {reverse} back over the same arcs",
        fmt4(DWELL_S)
    ));
    out.line(format!("{} G94", plane_code(plane)));
    start[u.index()] = Some(feed_in_start.0);
    start[v.index()] = Some(feed_in_start.1);
    out.lead_in(&start, options.clearance_mm, h.feed_mm_per_min);
    out.start_ballbar();
    // Words in the usual order, X Y Z then I J K (G18's plane is Z then X).
    let pair = |a: (Axis, String), b: (Axis, String), letter: fn(Axis) -> String| {
        let (first, second) = if a.0.index() < b.0.index() { (a, b) } else { (b, a) };
        format!("{}{} {}{}", letter(first.0), first.1, letter(second.0), second.1)
    };
    let name = |a: Axis| a.name().to_string();
    // An arc block from `from` to `to` about the pivot: the centre words incremental from its
    // start (the ISO default).
    let (cpu, cpv) = (ticks(pu), ticks(pv));
    let arc = |code: &str, from: (i64, i64), to: (i64, i64), feed: &str| {
        let centre = pair((u, fmt_ticks(cpu - from.0)), (v, fmt_ticks(cpv - from.1)), |a| {
            centre_letter(a).to_string()
        });
        format!("{code} {} {centre}{feed}", pair((u, fmt_ticks(to.0)), (v, fmt_ticks(to.1)), name))
    };
    let feed = format!(" F{}", fmt4(h.feed_mm_per_min));
    out.comment(format!("{direction}: feed-in arc"));
    out.line(arc(code, feed_in_start, (su, sv), &feed));
    out.comment(format!("{direction}: data arc, the run's commanded path"));
    for k in 0..full_turns {
        out.line(arc(code, (su, sv), (su, sv), if k == 0 { &feed } else { "" }));
    }
    if !closed {
        out.line(arc(code, (su, sv), (eu, ev), if full_turns == 0 { &feed } else { "" }));
    }
    out.comment(format!("{direction}: over-shoot arc"));
    out.line(arc(code, data_end, overshoot_end, ""));
    out.line(format!("G4 P{} (dwell, s)", fmt4(DWELL_S)));
    out.comment(format!("{reverse}: feed-in arc"));
    out.line(arc(reverse_code, overshoot_end, data_end, ""));
    out.comment(format!("{reverse}: data arc"));
    for _ in 0..full_turns {
        out.line(arc(reverse_code, data_end, data_end, ""));
    }
    if !closed {
        out.line(arc(reverse_code, data_end, (su, sv), ""));
    }
    out.comment(format!("{reverse}: over-shoot arc"));
    out.line(arc(reverse_code, (su, sv), feed_in_start, ""));
    Ok(())
}

fn free(run: &Run, options: &ProgramOptions, out: &mut Program) -> Result<(), String> {
    let h = &run.header;
    let closing = closing_whole_turn(run);
    let run = closing.as_ref().map_or(run, |(closed, _, _)| closed);
    let n = run.len();
    let axes: Vec<(Axis, &[f64])> =
        Axis::ALL.into_iter().filter_map(|a| run.axis(a).map(|c| (a, c))).collect();
    let rotary: Vec<(Axis, &[f64])> = axes.iter().copied().filter(|(a, _)| a.is_rotary()).collect();
    if rotary.is_empty() {
        return Err("a free run without a rotary axis column: the program's blocks follow the rotary motion".into());
    }
    if let Some(k) = (1..n).find(|&k| run.t_s[k] <= run.t_s[k - 1]) {
        return Err(format!("{}: the time does not increase", at(run, k)));
    }
    let turning =
        rotary.iter().any(|(_, c)| c.iter().any(|x| (x - c[0]).abs() > HELD_ROTARY_TOLERANCE_RAD));
    if !turning {
        return Err("no rotary axis turns: write it as a planar run".into());
    }
    let step = options.max_step_deg.to_radians() * (1.0 + 1e-12);
    let rotary_motion =
        |j: usize, k: usize| rotary.iter().map(|(_, c)| (c[k] - c[j]).abs()).fold(0.0, f64::max);
    // Greedy: from each block end, the farthest sample within the step (at least the next one).
    let mut ends = Vec::new();
    let mut j = 0;
    while j < n - 1 {
        let mut k = j + 1;
        while k + 1 < n && rotary_motion(j, k + 1) <= step {
            k += 1;
        }
        ends.push(k);
        j = k;
    }
    // The chord: the samples between block ends against the linear-in-time interpolation.
    let (mut chord_mm, mut chord_deg): (f64, f64) = (0.0, 0.0);
    let mut j = 0;
    for &k in &ends {
        for i in j + 1..k {
            let f = (run.t_s[i] - run.t_s[j]) / (run.t_s[k] - run.t_s[j]);
            let mut d2 = 0.0;
            for &(a, c) in &axes {
                let miss = c[i] - (c[j] + f * (c[k] - c[j]));
                if a.is_rotary() {
                    chord_deg = chord_deg.max(miss.abs().to_degrees());
                } else {
                    d2 += miss * miss;
                }
            }
            chord_mm = chord_mm.max(d2.sqrt());
        }
        // Between two samples the run's path itself bends too: a circle of radius r stepped by
        // Δ has the second difference |P₋ − 2P + P₊| = 2r(1 − cos Δ) ≈ rΔ², and the chord of
        // one step lies r(1 − cos Δ/2) ≈ rΔ²/8 from its arc, an eighth of that second
        // difference (at the default step every sample is a block end, and the samples alone
        // would state no chord at all).
        // (Over the run's own samples, evenly spaced in time: not at the sample that closes a
        // whole turn, which follows the last one after less than a step.)
        for i in [j, k] {
            if i >= 1 && i + 1 < n - usize::from(closing.is_some()) {
                let d2: f64 = axes
                    .iter()
                    .filter(|(a, _)| !a.is_rotary())
                    .map(|(_, c)| (c[i - 1] - 2.0 * c[i] + c[i + 1]).powi(2))
                    .sum();
                chord_mm = chord_mm.max(d2.sqrt() / 8.0);
            }
        }
        j = k;
    }

    for &(a, c) in &rotary {
        out.comment(format!(
            "{a}: from {} to {} deg",
            fmt4(c[0].to_degrees()),
            fmt4(c[n - 1].to_degrees())
        ));
    }
    if let Some((_, axis, short_deg)) = &closing {
        out.comment(format!(
            "the run's samples stop {} deg of {axis} short of its whole turn: the last block closes it at the last step's rate",
            fmt4(*short_deg)
        ));
    }
    out.comment(format!(
        "{} G1 blocks in inverse time, at most {} deg of rotary motion each",
        ends.len(),
        fmt4(options.max_step_deg)
    ));
    out.comment(format!(
        "between block ends the axes follow chords up to {} mm in X Y Z and {} deg from the run",
        fmt4(chord_mm),
        fmt4(chord_deg)
    ));
    out.line("G17 G94");
    let word = |a: Axis, v: f64| if a.is_rotary() { ticks(v.to_degrees()) } else { ticks(v) };
    let mut start: [Option<i64>; 6] = [None; 6];
    for &(a, c) in &axes {
        start[a.index()] = Some(word(a, c[0]));
    }
    out.lead_in(&start, options.clearance_mm, h.feed_mm_per_min);
    out.start_ballbar();
    out.line("G93 (inverse time: F is 1/min, each block timed as the run)");
    let mut j = 0;
    for &k in &ends {
        let f = 60.0 / (run.t_s[k] - run.t_s[j]);
        if !(f.is_finite() && f >= 1e-4) {
            return Err(format!(
                "{} to {}: a block of {:.3} s, beyond the program's inverse-time feed",
                at(run, j),
                at(run, k),
                run.t_s[k] - run.t_s[j]
            ));
        }
        let words: Vec<String> = axes
            .iter()
            .map(|&(a, c)| format!("{}{}", a.name(), fmt_ticks(word(a, c[k]))))
            .collect();
        out.line(format!("G1 {} F{}", words.join(" "), fmt_inverse_time(f)));
        j = k;
    }
    out.line("G94");
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Reading.

/// The modal state of the reader.
struct Reader {
    motion: Option<u32>,
    plane: Plane,
    inverse_time: bool,
    /// The modal feed in `G94`, mm/min.
    feed: Option<f64>,
    position: [Option<f64>; 6],
    points: Vec<ProgramPoint>,
}

/// One word: its letter (upper case), its value, and the text as written (for messages).
struct Word {
    letter: char,
    value: f64,
    text: String,
}

/// The words of one line, without its comments.
fn words(raw: &str, line: usize) -> Result<Vec<Word>, GcodeError> {
    let err = |message: String| GcodeError::Line { line, message };
    let chars: Vec<char> = raw.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < chars.len() {
        let c = chars[i];
        match c {
            c if c.is_whitespace() => i += 1,
            '(' => match chars[i + 1..].iter().position(|&d| d == ')' || d == '(') {
                Some(p) if chars[i + 1 + p] == ')' => i += p + 2,
                Some(_) => return Err(err("a comment inside a comment".into())),
                None => return Err(err("a comment that does not close".into())),
            },
            ')' => return Err(err("a ')' outside a comment".into())),
            ';' => break,
            '%' if out.is_empty() && chars[i + 1..].iter().all(|d| d.is_whitespace()) => break,
            c if c.is_ascii_alphabetic() => {
                let letter = c.to_ascii_uppercase();
                let mut k = i + 1;
                while k < chars.len() && chars[k].is_whitespace() {
                    k += 1;
                }
                let from = k;
                while k < chars.len()
                    && (chars[k].is_ascii_digit() || matches!(chars[k], '.' | '+' | '-'))
                {
                    k += 1;
                }
                let number: String = chars[from..k].iter().collect();
                let text = format!("{letter}{number}");
                let value: f64 = number.parse().map_err(|_| {
                    if number.is_empty() {
                        err(format!("word {letter} without a value"))
                    } else {
                        err(format!("word {text}: {number:?} is not a number"))
                    }
                })?;
                if !value.is_finite() {
                    return Err(err(format!("word {text}: not a finite number")));
                }
                out.push(Word { letter, value, text });
                i = k;
            }
            c => return Err(err(format!("unexpected character {c:?}"))),
        }
    }
    Ok(out)
}

/// The in-plane axes and the centre words of an arc plane: (U, V, W), the centre letters of U
/// and V.
fn arc_frame(plane: Plane) -> ((Axis, Axis, Axis), (char, char)) {
    let axes = plane.axes().unwrap_or((Axis::X, Axis::Y, Axis::Z));
    (axes, (centre_letter(axes.0), centre_letter(axes.1)))
}

impl Reader {
    fn block(&mut self, raw: &str, line: usize) -> Result<bool, GcodeError> {
        let err = |message: String| GcodeError::Line { line, message };
        let words = words(raw, line)?;
        let mut target: [Option<f64>; 6] = [None; 6];
        let mut centre: [Option<f64>; 3] = [None; 3];
        let mut feed: Option<f64> = None;
        let mut motion: Option<u32> = None;
        let mut dwell = false;
        let mut dwell_s: Option<f64> = None;
        let mut end = false;
        let once = |slot: &mut Option<f64>, w: &Word| -> Result<(), GcodeError> {
            if slot.is_some() {
                return Err(err(format!("{} is given twice in the block", w.letter)));
            }
            *slot = Some(w.value);
            Ok(())
        };
        for w in &words {
            let integer = (w.value.fract() == 0.0 && w.value >= 0.0).then_some(w.value as u32);
            match w.letter {
                'G' => match integer {
                    Some(code @ 0..=3) => {
                        if motion.is_some() {
                            return Err(err(format!("two motions in one block ({})", w.text)));
                        }
                        motion = Some(code);
                    }
                    Some(4) => dwell = true,
                    Some(17) => self.plane = Plane::XY,
                    Some(18) => self.plane = Plane::ZX,
                    Some(19) => self.plane = Plane::YZ,
                    Some(93 | 94) => {
                        let inverse = integer == Some(93);
                        if inverse != self.inverse_time {
                            // A change of feed mode leaves no feed in force (RS274/NGC).
                            self.feed = None;
                        }
                        self.inverse_time = inverse;
                    }
                    Some(90 | 21 | 40 | 49 | 80 | 54..=59) => {}
                    Some(91) => return Err(err("G91 (incremental positions) is not in the subset: positions are absolute, G90".into())),
                    Some(20) => return Err(err("G20 (inch) is not in the subset: the program is in mm, G21".into())),
                    _ => return Err(err(format!("{} is not in the subset read here (G0 G1 G2 G3 G4 G17 G18 G19 G90 G93 G94, and G21 G40 G49 G80 G54-G59)", w.text))),
                },
                'M' => match integer {
                    Some(0 | 1) => {}
                    Some(2 | 30) => end = true,
                    Some(3 | 4 | 6) => return Err(err(format!("{} is not in the subset: no spindle, no tool change (the ballbar must not turn)", w.text))),
                    _ => return Err(err(format!("{} is not in the subset (M0 M1 M2 M30)", w.text))),
                },
                'N' | 'O' => {}
                'P' => {
                    if w.value < 0.0 {
                        return Err(err(format!("{}: a dwell cannot be negative", w.text)));
                    }
                    once(&mut dwell_s, w)?;
                }
                'F' => {
                    if w.value <= 0.0 {
                        return Err(err(format!("{}: the feed must be positive", w.text)));
                    }
                    once(&mut feed, w)?;
                }
                'I' | 'J' | 'K' => {
                    let k = (w.letter as u8 - b'I') as usize;
                    once(&mut centre[k], w)?;
                }
                letter => match Axis::from_name(&letter.to_string()) {
                    Some(a) => once(&mut target[a.index()], w)?,
                    None => {
                        return Err(err(format!("unknown word {}: the reader takes G, M, N, O, X, Y, Z, A, B, C, I, J, K, F and P", w.text)));
                    }
                },
            }
        }
        if dwell || dwell_s.is_some() {
            // G4 is not modal: the block dwells, in seconds (P), and moves nothing.
            let Some(p) = dwell_s.filter(|_| dwell) else {
                return Err(err(
                    "G4 (dwell) takes its time in seconds as P, and P belongs to G4 alone".into(),
                ));
            };
            if motion.is_some()
                || target.iter().any(Option::is_some)
                || centre.iter().any(Option::is_some)
            {
                return Err(err("G4 (dwell) with a motion or axis words in its block".into()));
            }
            self.points.push(ProgramPoint {
                line,
                motion: Motion::Dwell,
                feed_mode: if self.inverse_time {
                    FeedMode::InverseTime
                } else {
                    FeedMode::UnitsPerMinute
                },
                axes: self.position,
                duration_s: Some(p),
                block_end: true,
            });
            return Ok(end);
        }
        if let Some(m) = motion {
            self.motion = Some(m);
        }
        if let (Some(f), false) = (feed, self.inverse_time) {
            self.feed = Some(f);
        }
        let has_axes = target.iter().any(Option::is_some);
        let has_centre = centre.iter().any(Option::is_some);
        let full_circle_at_the_start = has_centre && matches!(self.motion, Some(2 | 3));
        if !(has_axes || full_circle_at_the_start) {
            if has_centre {
                return Err(err("I, J, K only in a G2 or G3 block".into()));
            }
            return Ok(end);
        }
        let Some(code) = self.motion else {
            return Err(err("axis words without a motion (G0, G1, G2 or G3)".into()));
        };
        if code < 2 && has_centre {
            return Err(err("I, J, K only in a G2 or G3 block".into()));
        }
        let feed_mode =
            if self.inverse_time { FeedMode::InverseTime } else { FeedMode::UnitsPerMinute };
        let (inverse_time, modal_feed) = (self.inverse_time, self.feed);
        // The block's time, where the program fixes it.
        let block_time = |length_mm: Option<f64>| -> Result<Option<f64>, GcodeError> {
            if code == 0 {
                return Ok(None);
            }
            if inverse_time {
                let f = feed.ok_or_else(|| {
                    err(format!("G{code} in inverse time (G93) without its F word"))
                })?;
                return Ok(Some(60.0 / f));
            }
            let f = modal_feed.ok_or_else(|| err(format!("G{code} without a feed F")))?;
            Ok(length_mm.map(|l| l / f * 60.0))
        };
        let mut end_position = self.position;
        for (k, t) in target.iter().enumerate() {
            if t.is_some() {
                end_position[k] = *t;
            }
        }
        if code < 2 {
            // The length of a move of linear axes alone, if every moved axis was known before.
            let mut length = Some(0.0);
            for a in Axis::ALL {
                let (from, to) = (self.position[a.index()], end_position[a.index()]);
                if target[a.index()].is_none() || from == to {
                    continue;
                }
                length = match (a.is_rotary(), from, to) {
                    (false, Some(f), Some(t)) => length.map(|l: f64| l + (t - f) * (t - f)),
                    _ => None,
                };
            }
            let duration_s = block_time(length.map(f64::sqrt))?;
            let motion = if code == 0 { Motion::Rapid } else { Motion::Linear };
            self.points.push(ProgramPoint {
                line,
                motion,
                feed_mode,
                axes: end_position,
                duration_s,
                block_end: true,
            });
            self.position = end_position;
            return Ok(end);
        }
        self.arc(line, code, &target, &centre, end_position, feed_mode, block_time)?;
        Ok(end)
    }

    #[allow(clippy::too_many_arguments, reason = "one block's parts, passed once")]
    fn arc(
        &mut self,
        line: usize,
        code: u32,
        target: &[Option<f64>; 6],
        centre: &[Option<f64>; 3],
        end_position: [Option<f64>; 6],
        feed_mode: FeedMode,
        block_time: impl Fn(Option<f64>) -> Result<Option<f64>, GcodeError>,
    ) -> Result<(), GcodeError> {
        use std::f64::consts::TAU;
        let err = |message: String| GcodeError::Line { line, message };
        let plane = self.plane;
        let ((u, v, w), (lu, lv)) = arc_frame(plane);
        let direction = if code == 2 { Direction::CW } else { Direction::CCW };
        if let Some(a) =
            [Axis::A, Axis::B, Axis::C].into_iter().find(|a| target[a.index()].is_some())
        {
            return Err(err(format!("{a} in an arc block is not in the subset")));
        }
        for (k, letter) in ['I', 'J', 'K'].into_iter().enumerate() {
            if centre[k].is_some() && letter != lu && letter != lv {
                return Err(err(format!(
                    "{letter} is not a centre word of the {plane} plane ({}: {lu}, {lv})",
                    plane_code(plane)
                )));
            }
        }
        let offset = |letter: char| centre[(letter as u8 - b'I') as usize];
        if offset(lu).is_none() && offset(lv).is_none() {
            return Err(err(format!(
                "G{code} without centre: the {plane} plane ({}) needs {lu} and/or {lv}",
                plane_code(plane)
            )));
        }
        let known = |a: Axis| {
            self.position[a.index()]
                .ok_or_else(|| err(format!("an arc from an unknown position: no {a} before it")))
        };
        let (su, sv) = (known(u)?, known(v)?);
        let (eu, ev) =
            (end_position[u.index()].unwrap_or(su), end_position[v.index()].unwrap_or(sv));
        let (sw, ew) = match (self.position[w.index()], target[w.index()]) {
            (Some(s), Some(e)) => (Some(s), Some(e)),
            (s, None) => (s, s),
            (None, Some(_)) => return Err(err(format!("a helical arc from an unknown {w}"))),
        };
        let (cu, cv) = (su + offset(lu).unwrap_or(0.0), sv + offset(lv).unwrap_or(0.0));
        let (r0, r1) = ((su - cu).hypot(sv - cv), (eu - cu).hypot(ev - cv));
        if r0 < 1.0 / TICKS_PER_UNIT {
            return Err(err("the arc's centre is its start point: radius zero".into()));
        }
        if (r1 - r0).abs() > ARC_RADIUS_TOLERANCE_MM {
            return Err(err(format!(
                "the arc's end is {r1:.4} mm from its centre and its start {r0:.4} mm: more than {ARC_RADIUS_TOLERANCE_MM} mm apart"
            )));
        }
        let (a0, a1) = ((sv - cv).atan2(su - cu), (ev - cv).atan2(eu - cu));
        let closed = (eu - su).hypot(ev - sv) < 0.5 / TICKS_PER_UNIT;
        let sweep = match (closed, direction) {
            (true, Direction::CCW) => TAU,
            (true, Direction::CW) => -TAU,
            (false, Direction::CCW) => (a1 - a0).rem_euclid(TAU),
            (false, Direction::CW) => -(a0 - a1).rem_euclid(TAU),
        };
        let helix = match (sw, ew) {
            (Some(s), Some(e)) => e - s,
            _ => 0.0,
        };
        let length = (sweep.abs() * 0.5 * (r0 + r1)).hypot(helix);
        let duration = block_time(Some(length))?;
        let segments = ((sweep.abs().to_degrees() / ARC_POINT_STEP_DEG).ceil() as usize).max(1);
        for s in 1..=segments {
            let f = s as f64 / segments as f64;
            let mut axes = self.position;
            if s == segments {
                axes = end_position;
                axes[u.index()] = Some(eu);
                axes[v.index()] = Some(ev);
            } else {
                let (a, r) = (a0 + f * sweep, r0 + f * (r1 - r0));
                axes[u.index()] = Some(cu + r * a.cos());
                axes[v.index()] = Some(cv + r * a.sin());
                axes[w.index()] = sw.zip(ew).map(|(s, e)| s + f * (e - s));
            }
            let duration_s = duration.map(|d| d / segments as f64);
            self.points.push(ProgramPoint {
                line,
                motion: Motion::Arc { plane, direction },
                feed_mode,
                axes,
                duration_s,
                block_end: s == segments,
            });
        }
        self.position = end_position;
        self.position[u.index()] = Some(eu);
        self.position[v.index()] = Some(ev);
        Ok(())
    }
}

/// Read a program of the subset [`program`] writes (see the module documentation): the
/// positions it reaches, in order, in mm and degrees; along an arc a point every
/// [`ARC_POINT_STEP_DEG`] or less, the arc's centre from its I/J/K words (incremental from the
/// arc's start). Reading stops at `M2` or `M30`.
///
/// Errors name the 1-based line and what is wrong: a word or code outside the subset, a word
/// without a number or given twice, axis words without a motion, an arc without centre, from an
/// unknown position or whose end is not on its circle, a `G1`/`G2`/`G3` without a feed (in
/// `G93`, without its own F), a comment that does not close.
pub fn parse(text: &str) -> Result<Vec<ProgramPoint>, GcodeError> {
    let mut reader = Reader {
        motion: None,
        plane: Plane::XY,
        inverse_time: false,
        feed: None,
        position: [None; 6],
        points: Vec::new(),
    };
    for (k, raw) in text.lines().enumerate() {
        if reader.block(raw, k + 1)? {
            break;
        }
    }
    Ok(reader.points)
}

#[cfg(test)]
#[path = "gcode_tests.rs"]
mod tests;

//! An exact simulator of ballbar tests on a machine with known errors.
//!
//! "Exact" means no linearisation: every joint's error motion is applied as a rigid transform
//! (rotation by its rotation vector), the balls are placed through the full chain, and the
//! reading is the distance between them. Servo lag is simulated in the time domain: each axis's
//! actual position is its command passed through a first-order position loop
//! `dq/dt = (q_cmd - q)/τ`; for a circle integrated exactly for a command that is linear over
//! each of 8 sub-steps per sample, from a lead-in of 20 τ along the same circle (the start
//! transient then decays to e⁻²⁰).
//! The other error terms are evaluated at the axes' actual state (backlash switches when the
//! lagging axis reverses). The paper's plane servo terms, bar length, centring offsets and
//! noise are added as the model states them.
//!
//! # Rotary-axis tests
//! A `plane: Free` test of a truth file is a rotary-axis test ([`RotarySpec`], run by
//! [`ballbar_model::path::RotaryTest`]): its commanded path exists only as the run's columns,
//! so servo lag filters the columns themselves. Between samples the command is the cubic
//! Hermite curve through them with the model's central-difference velocities as slopes
//! (three-point one-sided differences at the two ends), and the filter is integrated exactly
//! over it: on a sample interval with command `p(s)`, a cubic, the response is
//! $$ q(s) = q_p(s) + (q(0) - q_p(0))\, e^{-s/τ}, \qquad q_p = p - τ p' + τ^2 p'' - τ^3 p''' . $$
//! The lead-in is the first sample's velocity extrapolated backwards, a ramp, whose steady
//! state `q = p(0) - τ p'(0)` the filter starts from (a lead-in of 20 τ reaches it to e⁻²⁰). A
//! chord between samples instead (linear interpolation) would lag by τ times the backward
//! difference, not the central one: τ h a/2 off, 25 nm at 50 Hz on a 100 mm circle at
//! 1000 mm/min with τ = 1 ms; the cubic is 0.05 nm off the exact response there (tested).
//! The centring of a free run is a 3-D offset of the table ball in the table frame.
//!
//! # Noise
//! The reading noise is white by default: an independent normal sample of standard deviation
//! `noise_um` at every sample. With `noise_correlation_ms = τ_c > 0` it is coloured: a sampled
//! Ornstein-Uhlenbeck process of the same standard deviation and correlation time τ_c, realised
//! exactly at the sample times (not by an Euler step), so its autocorrelation at lag `Δt` is
//! exactly `e^{-Δt/τ_c}`:
//! $$ e_0 = σ z_0, \qquad e_i = ρ_i e_{i-1} + σ \sqrt{1 - ρ_i^2}\, z_i, \qquad ρ_i = e^{-(t_i - t_{i-1})/τ_c}, $$
//! with `z_i` independent standard normal samples of the seeded generator. Each run starts from
//! the stationary distribution (runs are independent: the pauses between runs are much longer
//! than any correlation time of a bar's reading). Both variants draw one normal sample per
//! reading, so the generator's stream is consumed alike with and without correlation, and
//! white noise is `σ z_i` itself.

use std::collections::BTreeMap;

use ballbar_model::Effect;
use ballbar_model::design::{
    ExactScratch, ReadingSample, exact_length, fill_q, reading_basis, reversal_times, since_last,
    start_reversal, velocity_and_direction,
};
use ballbar_model::machine::{BarLength, MachineSpec, Model, ModelOptions, ServoVariant};
use ballbar_model::machine::{ReadingTerm, reading_id};
use ballbar_model::paper::{PaperValues, parameters_from_paper};
use ballbar_model::path::{BarDirection, CircleTest, RotaryTest, Turn};
use ballbar_model::plausible;
use ballbar_model::{Axis, Direction, JointState, ModelError, Plane, Run};
use serde::{Deserialize, Serialize};

pub mod controller;
pub mod fanuc;
pub mod heidenhain;
pub mod linuxcnc;
pub mod rng;
pub mod siemens;

use controller::JointTrims;

use rng::Rng;

/// One kind of test in a truth file; each direction and repeat becomes a run.
///
/// A planar test (`XY`, `YZ`, `ZX`) is a circle or an arc ([`CircleTest`]). A `Free` test is a
/// rotary-axis test and needs `rotary` ([`RotarySpec`]); its circle fields `start_deg` and
/// `sweep_deg` keep their defaults, and its run ids read `c-radial-ccw-1`, `ac-axial-cw-1`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestSpec {
    /// Plane; `Free` for a rotary-axis test.
    pub plane: Plane,
    /// Directions to run, in order. For a rotary test `CCW` runs the sweeps as given and `CW`
    /// the same arcs backwards.
    pub directions: Vec<Direction>,
    /// Radius (nominal bar length), mm.
    pub radius_mm: f64,
    /// Feed, mm/min (of a rotary test: the speed of the commanded X, Y, Z point).
    pub feed_mm_per_min: f64,
    /// Pivot: the X, Y, Z at which the tool ball sits on the table ball (rotary axes at 0), mm.
    pub pivot_mm: [f64; 3],
    /// Table ball, mm. The chain places the table ball from the pivot; a rotary test checks a
    /// non-zero value against that place (within [`TABLE_BALL_TOLERANCE_MM`]).
    #[serde(default)]
    pub table_ball_mm: [f64; 3],
    /// Tool ball, mm.
    #[serde(default)]
    pub tool_ball_mm: [f64; 3],
    /// How many times each direction is run.
    #[serde(default = "one")]
    pub repeats: u32,
    /// Start angle of a circle, degrees.
    #[serde(default)]
    pub start_deg: f64,
    /// Sweep of a circle, degrees.
    #[serde(default = "full")]
    pub sweep_deg: f64,
    /// The rotary axes' motion of a `Free` test (and only of one). Written as a plain struct,
    /// `rotary: (turns: [(axis: C, start_deg: 0.0, sweep_deg: 360.0)], bar: Radial)`
    /// (`Some(...)` is read too); left out for a planar test.
    #[serde(default, skip_serializing_if = "Option::is_none", with = "bare_option")]
    pub rotary: Option<RotarySpec>,
}

fn one() -> u32 {
    1
}
fn full() -> f64 {
    360.0
}

/// A rotary-axis test (ISO 10791-6 style) of a truth file: the axes that turn, those held, and
/// how the bar lies ([`ballbar_model::path::RotaryTest`] has the conventions).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RotarySpec {
    /// The turning axes (at least one), together; the first sets the bar's direction.
    pub turns: Vec<TurnSpec>,
    /// Rotary axes held at a non-zero angle, `(axis, degrees)`; the others stay at 0.
    #[serde(default)]
    pub hold: Vec<(Axis, f64)>,
    /// The bar's direction relative to the first turning axis, fixed in the table frame.
    pub bar: BarDirection,
}

/// One turning axis of a [`RotarySpec`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TurnSpec {
    /// The rotary axis.
    pub axis: Axis,
    /// Axis coordinate at the start of a `CCW` run, degrees.
    pub start_deg: f64,
    /// Signed sweep of a `CCW` run, degrees.
    pub sweep_deg: f64,
}

impl RotarySpec {
    /// The commanded test of one direction: `CCW` runs each sweep as given, `CW` the same arcs
    /// backwards (each turning axis from `start + sweep`, by `-sweep`).
    pub fn test(&self, spec: &TestSpec, direction: Direction, sample_rate_hz: f64) -> RotaryTest {
        let turns = self
            .turns
            .iter()
            .map(|t| match direction {
                Direction::CCW => {
                    Turn { axis: t.axis, start_deg: t.start_deg, sweep_deg: t.sweep_deg }
                }
                Direction::CW => Turn {
                    axis: t.axis,
                    start_deg: t.start_deg + t.sweep_deg,
                    sweep_deg: -t.sweep_deg,
                },
            })
            .collect();
        RotaryTest {
            turns,
            hold: self.hold.clone(),
            bar: self.bar,
            radius_mm: spec.radius_mm,
            feed_mm_per_min: spec.feed_mm_per_min,
            pivot_mm: spec.pivot_mm,
            tool_ball_mm: spec.tool_ball_mm,
            sample_rate_hz,
        }
    }

    /// The stem of its runs' ids: the turning axes in axis order, the bar, the direction
    /// (`c-radial-ccw`, `ac-axial-cw`).
    fn stem(&self, direction: Direction) -> String {
        let mut axes: Vec<Axis> = self.turns.iter().map(|t| t.axis).collect();
        axes.sort();
        axes.dedup();
        let axes: String = axes.iter().map(|a| a.name().to_lowercase()).collect();
        let bar = match self.bar {
            BarDirection::Radial => "radial",
            BarDirection::Tangential => "tangential",
            BarDirection::Axial => "axial",
        };
        format!("{axes}-{bar}-{}", direction.name().to_lowercase())
    }
}

/// How far a rotary test's `table_ball_mm`, when given, may lie from where the pivot places the
/// table ball, mm: the run format's tolerance, the one the fit checks runs against.
pub const TABLE_BALL_TOLERANCE_MM: f64 = ballbar_model::design::FREE_TABLE_BALL_TOLERANCE_MM;

/// An optional field written without RON's `Some(...)`: `rotary: (turns: ...)`. Reads the plain
/// value, `Some(value)` and `None`; writes the plain value (the field is left out when `None`).
mod bare_option {
    use serde::de::{DeserializeOwned, MapAccess, Visitor};
    use serde::{Deserializer, Serialize, Serializer};

    pub fn serialize<T: Serialize, S: Serializer>(
        value: &Option<T>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        match value {
            Some(v) => v.serialize(s),
            None => s.serialize_none(),
        }
    }

    pub fn deserialize<'de, T: DeserializeOwned, D: Deserializer<'de>>(
        d: D,
    ) -> Result<Option<T>, D::Error> {
        struct Bare<T>(std::marker::PhantomData<T>);
        impl<'de, T: DeserializeOwned> Visitor<'de> for Bare<T> {
            type Value = Option<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a struct (turns: [...], bar: ...)")
            }
            fn visit_map<M: MapAccess<'de>>(self, map: M) -> Result<Option<T>, M::Error> {
                T::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(Some)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Option<T>, D::Error> {
                T::deserialize(d).map(Some)
            }
            fn visit_none<E: serde::de::Error>(self) -> Result<Option<T>, E> {
                Ok(None)
            }
            fn visit_unit<E: serde::de::Error>(self) -> Result<Option<T>, E> {
                Ok(None)
            }
        }
        d.deserialize_any(Bare(std::marker::PhantomData))
    }
}

/// A truth file: the machine's errors and the test set-up.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Truth {
    /// Servo model of the truth.
    #[serde(default)]
    pub servo: ServoVariant,
    /// Parameter values by id, in display units (µm, µrad, ms).
    #[serde(default)]
    pub errors: BTreeMap<String, f64>,
    /// The paper's quantities, converted to parameters (added to `errors`).
    #[serde(default)]
    pub paper: Option<PaperValues>,
    /// Bar-length error, µm.
    #[serde(default)]
    pub bar_length_um: f64,
    /// Standard deviation of each run's random offset of the table ball, µm: per in-plane axis
    /// of a circle, per X, Y, Z (table frame) of a rotary test.
    #[serde(default)]
    pub centring_sd_um: f64,
    /// Reading noise, µm (standard deviation); white unless `noise_correlation_ms` is set.
    #[serde(default)]
    pub noise_um: f64,
    /// Correlation time of the reading noise, ms: 0 (the default) for white noise, else the
    /// noise is an AR(1) (Ornstein-Uhlenbeck) process with this correlation time (module docs).
    #[serde(default)]
    pub noise_correlation_ms: f64,
    /// Sampling rate, Hz.
    pub sample_rate_hz: f64,
    /// Session start, ISO 8601.
    pub started_at: String,
    /// Pause between runs, s.
    #[serde(default)]
    pub pause_s: f64,
    /// The tests.
    pub tests: Vec<TestSpec>,
    /// Effects the machine has beyond its description's terms (what a diagnosis should find).
    #[serde(default)]
    pub effects: Vec<TruthEffect>,
}

/// An effect of a simulated machine and its size.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TruthEffect {
    /// The effect (with its non-linear parameters).
    pub effect: Effect,
    /// Its size in the display unit of its coefficient (µm, µrad, µm/h, ms²); for a cyclic
    /// error the amplitude, µm.
    pub value: f64,
    /// The phase of a cyclic error, degrees: `Δ = A sin(2π q/p + φ)`.
    #[serde(default)]
    pub phase_deg: f64,
}

/// Errors of simulation.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// The machine or a parameter is wrong.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The truth is inconsistent.
    #[error("truth: {0}")]
    Truth(String),
}

/// Simulated runs and what was put into them.
#[derive(Clone, Debug)]
pub struct Simulation {
    /// The runs.
    pub runs: Vec<Run>,
    /// Parameter values used, internal units.
    pub parameters: Vec<(String, f64)>,
    /// Pivot offset of each run (table frame), mm.
    pub centring_mm: Vec<[f64; 3]>,
}

/// The reading noise of a truth, internal units (module docs).
#[derive(Clone, Copy, Debug)]
struct Noise {
    /// Standard deviation, mm.
    sd_mm: f64,
    /// Correlation time, s (0: white).
    correlation_s: f64,
}

impl Noise {
    /// The noise at time `t_s` of a run, given the previous sample's `(time, noise)` (`None` at
    /// the run's start), which it updates. One normal draw per call when `sd_mm > 0`.
    fn next(&self, rng: &mut Rng, t_s: f64, last: &mut Option<(f64, f64)>) -> f64 {
        if self.sd_mm <= 0.0 {
            return 0.0;
        }
        let z = rng.normal();
        let e = match *last {
            Some((t0, e0)) if self.correlation_s > 0.0 => {
                let rho = (-(t_s - t0) / self.correlation_s).exp();
                rho * e0 + self.sd_mm * (1.0 - rho * rho).sqrt() * z
            }
            _ => self.sd_mm * z,
        };
        *last = Some((t_s, e));
        e
    }
}

/// A joint's state per sample: (q, velocity, direction), actual motion.
type AxisTrace = Vec<(f64, f64, f64)>;

/// A run's commanded path as the lag filter reads it.
#[derive(Clone, Copy, Debug)]
enum Command<'a> {
    /// A planar circle: its closed form, at any time.
    Circle(&'a CircleTest),
    /// A free path (a rotary test): the run's columns, at the samples only.
    Columns,
}

/// The actual motion of one axis: the command, or the command through a first-order lag τ.
fn axis_trace(
    command: Command<'_>,
    run: &Run,
    axis: Axis,
    tau: f64,
    controller: Option<&dyn JointTrims>,
) -> AxisTrace {
    let col = run.axis(axis).expect("a simulated run has a column for every axis of the chain");
    let controller = controller.filter(|c| c.has(axis));
    // The controller's correction added to the commanded joint position (module `controller`):
    // the trim of the commanded velocity's direction (the model's central differences of the
    // samples, between which the servo cycles' commands are not known); at rest the last one,
    // and before the joint moves in the run the one its positioning move left
    // ([`JointTrims::positioned`]): an axis the run does not move is compensated too.
    // Cross-axis tables add to it what the other axes' commanded positions give.
    let commanded_at = |i: usize| {
        let mut p = [0.0; 6];
        for a in Axis::ALL {
            if let Some(c) = run.axis(a) {
                p[a.index()] = c[i];
            }
        }
        p
    };
    let trimmed: Option<Vec<f64>> = controller.map(|c| {
        let mut corr = col.first().map_or(0.0, |&q| c.positioned(axis, q));
        (0..col.len())
            .map(|i| {
                let (v, _) = velocity_and_direction(&run.t_s, col, i);
                corr = c.servo_cycle(axis, col[i], v, corr);
                col[i] + corr + c.cross(axis, &commanded_at(i))
            })
            .collect()
    });
    let with_trims = |mut trace: AxisTrace| {
        if let Some(t) = &trimmed {
            for (s, q) in trace.iter_mut().zip(t) {
                s.0 = *q;
            }
        }
        trace
    };
    let test = match command {
        Command::Circle(test) => test,
        Command::Columns if tau <= 0.0 => return with_trims(commanded_trace(&run.t_s, col)),
        Command::Columns => {
            return column_lag_trace(&run.t_s, trimmed.as_deref().unwrap_or(col), tau);
        }
    };
    if tau <= 0.0 {
        return with_trims(commanded_trace(&run.t_s, col));
    }
    let k = axis.index();
    // The controller's correction as its servo cycle computes it: the commanded velocity is
    // the change of the command over the last servo period, and at rest (no change) the last
    // correction is kept. `cmd` is called at non-decreasing times (a time again only with the
    // same result), so the correction carried between calls is the previous cycle's.
    let lead = 20.0 * tau;
    let corr = std::cell::Cell::new(
        controller.map_or(0.0, |c| c.positioned(axis, test.position(-lead)[k])),
    );
    let cmd = |t: f64| {
        let p = test.position(t);
        let q = p[k];
        match controller {
            None => q,
            Some(c) => {
                let v = q - test.position(t - c.servo_period_s())[k];
                corr.set(c.servo_cycle(axis, q, v, corr.get()));
                q + corr.get() + c.cross(axis, &p)
            }
        }
    };
    // Sub-steps: the command is linear over each, a chord that bows in from the circle by up to
    // R (ω h)²/8; the lagging position follows the chords, off the exact response by about
    // R ω² h τ/2 when h ≫ τ and R ω² h²/12 when h ≪ τ: 1.3e-6 mm at 50 Hz (h = 2.5 ms),
    // R = 100 mm, 1000 mm/min, τ = 1 ms; 1.4e-8 mm at 500 Hz.
    let substeps = 8;
    let h_nominal = 1.0 / (test.sample_rate_hz * substeps as f64);
    let mut t = -lead;
    let mut q = cmd(t);
    let step = |t0: f64, t1: f64, q: &mut f64| {
        let (a, b) = (cmd(t0), cmd(t1));
        let h = t1 - t0;
        let slope = (b - a) / h;
        // Exact solution of dq/dt = (a + slope s - q)/τ over s ∈ [0, h].
        let decay = (-h / tau).exp();
        *q = b - slope * tau + (*q - a + slope * tau) * decay;
    };
    while t < 0.0 {
        let t1 = (t + h_nominal).min(0.0);
        step(t, t1, &mut q);
        t = t1;
    }
    let mut out = Vec::with_capacity(run.len());
    for i in 0..run.len() {
        let ti = run.t_s[i];
        while t < ti {
            let t1 = (t + h_nominal).min(ti);
            step(t, t1, &mut q);
            t = t1;
        }
        let v = (cmd(ti) - q) / tau;
        // Direction from the motor's velocity; below 1e-9 mm/s it is at rest (a reversal).
        let d = if v > 1e-9 {
            1.0
        } else if v < -1e-9 {
            -1.0
        } else {
            0.0
        };
        out.push((q, v, d));
    }
    out
}

/// The commanded motion of an axis without lag: the column, its velocity by central
/// differences (the model's).
fn commanded_trace(t: &[f64], col: &[f64]) -> AxisTrace {
    (0..col.len())
        .map(|i| {
            let (v, d) = velocity_and_direction(t, col, i);
            (col[i], v, d)
        })
        .collect()
}

/// The slope at `t[at]` of the parabola through three samples.
fn parabola_slope(t: [f64; 3], q: [f64; 3], at: f64) -> f64 {
    let [t0, t1, t2] = t;
    let [q0, q1, q2] = q;
    q0 * (2.0 * at - t1 - t2) / ((t0 - t1) * (t0 - t2))
        + q1 * (2.0 * at - t0 - t2) / ((t1 - t0) * (t1 - t2))
        + q2 * (2.0 * at - t0 - t1) / ((t2 - t0) * (t2 - t1))
}

/// The slopes of the Hermite curve through a column (module docs): central differences inside
/// (the model's velocities), the parabola through the three end samples at each end; one
/// chord's slope for two samples, 0 for one.
fn column_slopes(t: &[f64], q: &[f64]) -> Vec<f64> {
    let n = q.len();
    match n {
        0 => Vec::new(),
        1 => vec![0.0],
        2 => vec![(q[1] - q[0]) / (t[1] - t[0]); 2],
        _ => (0..n)
            .map(|i| {
                if i == 0 {
                    parabola_slope([t[0], t[1], t[2]], [q[0], q[1], q[2]], t[0])
                } else if i + 1 == n {
                    parabola_slope(
                        [t[n - 3], t[n - 2], t[n - 1]],
                        [q[n - 3], q[n - 2], q[n - 1]],
                        t[n - 1],
                    )
                } else {
                    (q[i + 1] - q[i - 1]) / (t[i + 1] - t[i - 1])
                }
            })
            .collect(),
    }
}

/// The actual motion of an axis whose command is known at the samples only (a free run): the
/// first-order lag τ integrated exactly over the Hermite curve through the column, from the
/// steady state of the lead-in ramp (module docs). Position, velocity `(p - q)/τ` and its
/// direction at each sample, as [`axis_trace`] gives them for a circle.
fn column_lag_trace(t: &[f64], col: &[f64], tau: f64) -> AxisTrace {
    let m = column_slopes(t, col);
    let Some(&first) = col.first() else {
        return Vec::new();
    };
    let mut q = first - tau * m[0];
    let mut out = Vec::with_capacity(col.len());
    for i in 0..col.len() {
        if i > 0 {
            // p(s) = p0 + m0 s + a2 s² + a3 s³ on s ∈ [0, h]; q_p = p - τ p' + τ² p'' - τ³ p'''.
            let (p0, p1, m0, m1) = (col[i - 1], col[i], m[i - 1], m[i]);
            let h = t[i] - t[i - 1];
            let chord = (p1 - p0) / h;
            let a2 = (3.0 * chord - 2.0 * m0 - m1) / h;
            let a3 = (m0 + m1 - 2.0 * chord) / (h * h);
            let tau2 = tau * tau;
            let qp0 = p0 - tau * m0 + 2.0 * tau2 * a2 - 6.0 * tau2 * tau * a3;
            let qp1 = p1 - tau * m1 + tau2 * (2.0 * a2 + 6.0 * a3 * h) - 6.0 * tau2 * tau * a3;
            q = qp1 + (q - qp0) * (-h / tau).exp();
        }
        let v = (col[i] - q) / tau;
        // Direction from the motor's velocity; below 1e-9 mm/s it is at rest (a reversal).
        let d = if v > 1e-9 {
            1.0
        } else if v < -1e-9 {
            -1.0
        } else {
            0.0
        };
        out.push((q, v, d));
    }
    out
}

/// Simulate every run of a truth on a machine.
pub fn simulate(
    spec: &MachineSpec,
    truth: &Truth,
    start_unix_s: f64,
    seed: u64,
) -> Result<Simulation, SimError> {
    simulate_with_kernels(spec, &ballbar_model::NoKernels, truth, start_unix_s, seed)
}

/// [`simulate`] for a machine whose description names plugin kernels.
pub fn simulate_with_kernels(
    spec: &MachineSpec,
    kernels: &dyn ballbar_model::KernelSource,
    truth: &Truth,
    start_unix_s: f64,
    seed: u64,
) -> Result<Simulation, SimError> {
    simulate_controlled(spec, kernels, truth, start_unix_s, seed, None::<&linuxcnc::LinuxCnc>)
}

/// [`simulate_with_kernels`] with a controller's compensation active: each joint's trim is
/// added to its commanded position before the lag and the machine's errors act (module
/// [`controller`]). The random draws are those of the same seed without it.
pub fn simulate_controlled<C: JointTrims>(
    spec: &MachineSpec,
    kernels: &dyn ballbar_model::KernelSource,
    truth: &Truth,
    start_unix_s: f64,
    seed: u64,
    controller: Option<&C>,
) -> Result<Simulation, SimError> {
    let controller: Option<&dyn JointTrims> = controller.map(|c| c as &dyn JointTrims);
    let effects: Vec<Effect> = truth.effects.iter().map(|e| e.effect.clone()).collect();
    let model = Model::with_effects(
        spec.clone(),
        ModelOptions { servo: truth.servo, bar_length: BarLength::Fit },
        kernels,
        &effects,
    )?;
    let params = model.parameters();
    let mut values: BTreeMap<String, f64> = BTreeMap::new();
    if let Some(p) = &truth.paper {
        for (id, v) in parameters_from_paper(&model, p)? {
            values.insert(id, v);
        }
    }
    for (id, v) in &truth.errors {
        let p = params
            .iter()
            .find(|p| &p.id == id)
            .ok_or_else(|| SimError::Model(ModelError::UnknownParameter { id: id.clone() }))?;
        if !v.is_finite() {
            return Err(SimError::Truth(format!("error {id} is not finite")));
        }
        values.insert(id.clone(), v / p.unit.display_factor());
    }
    for (te, ids) in truth.effects.iter().zip(&model.effect_ids) {
        if !te.value.is_finite() || !te.phase_deg.is_finite() {
            return Err(SimError::Truth(format!(
                "effect {}: value and phase must be finite",
                te.effect.describe()
            )));
        }
        let unit = |id: &str| {
            params.iter().find(|p| p.id == id).map(|p| p.unit.display_factor()).unwrap_or(1.0)
        };
        if let Effect::BarLengthDrift = te.effect {
            return Err(SimError::Truth(
                "effect bar length drift: each run's bar has its own length, which a truth file does not state; give the bar's one error as bar_length_um".into(),
            ));
        }
        if let Effect::Vibration { .. } = te.effect {
            // Per run, below: each run's phase is its own.
            continue;
        }
        if let Effect::CyclicError { .. } = te.effect {
            // A sin(x + φ) = A cos φ sin x + A sin φ cos x.
            let phi = te.phase_deg.to_radians();
            values.insert(ids[0].clone(), te.value * phi.cos() / unit(&ids[0]));
            values.insert(ids[1].clone(), te.value * phi.sin() / unit(&ids[1]));
        } else {
            for id in ids {
                values.insert(id.clone(), te.value / unit(id));
            }
        }
    }
    if values.contains_key("BAR") {
        return Err(SimError::Truth("give the bar-length error as bar_length_um".into()));
    }
    if !(truth.sample_rate_hz > 0.0 && truth.sample_rate_hz.is_finite()) {
        return Err(SimError::Truth("sample_rate_hz must be positive".into()));
    }
    let (low, high) = plausible::SAMPLE_RATE_HZ;
    if !(low..=high).contains(&truth.sample_rate_hz) {
        return Err(SimError::Truth(format!(
            "sample_rate_hz {:e} Hz is not a ballbar's sample rate ({low} to {high} Hz)",
            truth.sample_rate_hz
        )));
    }
    if !(truth.noise_um >= 0.0
        && truth.noise_um.is_finite()
        && truth.noise_correlation_ms >= 0.0
        && truth.noise_correlation_ms.is_finite())
    {
        return Err(SimError::Truth(
            "noise_um and noise_correlation_ms must be finite and not negative".into(),
        ));
    }
    if truth.noise_um > plausible::MAX_NOISE_UM {
        return Err(SimError::Truth(format!(
            "noise_um {:e} µm is beyond a ballbar's noise (at most {} µm: a ballbar's own is 0.1 µm, and the bar's range is ±1 mm)",
            truth.noise_um,
            plausible::MAX_NOISE_UM
        )));
    }
    let noise =
        Noise { sd_mm: truth.noise_um * 1e-3, correlation_s: truth.noise_correlation_ms * 1e-3 };
    let theta = |id: &str| values.get(id).copied().unwrap_or(0.0);
    // Run terms (a vibration): amplitude A in mm per term pair (sine, cosine parts); each run
    // draws its phase φ, uniform, so that the run reads A sin(2π f t + φ).
    let vibration_mm: Vec<f64> = truth
        .effects
        .iter()
        .filter(|te| matches!(te.effect, Effect::Vibration { .. }))
        .map(|te| te.value * 1e-3)
        .collect();
    let mut rng = Rng::new(seed);
    let mut runs = Vec::new();
    let mut centring_mm = Vec::new();
    let mut clock = start_unix_s;
    let mut counter: BTreeMap<String, u32> = BTreeMap::new();
    for (k, test) in truth.tests.iter().enumerate() {
        let rotary = rotary_of(k, test)?;
        for _ in 0..test.repeats {
            for &dir in &test.directions {
                let started_at = ballbar_model::time::format_iso8601(clock);
                let mut next_id = |stem: String| {
                    let n = counter.entry(stem.clone()).and_modify(|c| *c += 1).or_insert(1);
                    format!("{stem}-{n}")
                };
                let (mut run, circle) = match rotary {
                    None => {
                        let circle = CircleTest {
                            plane: test.plane,
                            direction: dir,
                            radius_mm: test.radius_mm,
                            feed_mm_per_min: test.feed_mm_per_min,
                            pivot_mm: test.pivot_mm,
                            table_ball_mm: test.table_ball_mm,
                            tool_ball_mm: test.tool_ball_mm,
                            sample_rate_hz: truth.sample_rate_hz,
                            start_deg: test.start_deg,
                            sweep_deg: test.sweep_deg,
                        };
                        let id = next_id(format!(
                            "{}-{}",
                            test.plane.name().to_lowercase(),
                            dir.name().to_lowercase()
                        ));
                        let mut run = circle.run(&started_at, clock, &id, &spec.name);
                        // Planar tests hold the machine's rotary axes at zero: their columns are written.
                        for a in model.chain.axes().into_iter().filter(|a| a.is_rotary()) {
                            run.axes[a.index()] = Some(vec![0.0; run.len()]);
                        }
                        (run, Some(circle))
                    }
                    Some(r) => {
                        let id = next_id(r.stem(dir));
                        let run = r
                            .test(test, dir, truth.sample_rate_hz)
                            .run(&model.chain, &started_at, clock, &id, &spec.name)
                            .map_err(|e| SimError::Truth(format!("tests[{k}] ({id}): {e}")))?;
                        check_table_ball(k, test, &run)?;
                        (run, None)
                    }
                };
                let mut e = [0.0; 3];
                match test.plane.axes() {
                    Some((ua, va, _)) => {
                        e[ua.index()] = rng.normal() * truth.centring_sd_um * 1e-3;
                        e[va.index()] = rng.normal() * truth.centring_sd_um * 1e-3;
                    }
                    // A free run's table ball is off in every direction (table frame).
                    None => {
                        e.iter_mut().for_each(|x| *x = rng.normal() * truth.centring_sd_um * 1e-3)
                    }
                }
                let mut run_coeffs = Vec::with_capacity(model.run_terms.len());
                for a in &vibration_mm {
                    let phi = std::f64::consts::TAU * rng.uniform();
                    run_coeffs.extend([a * phi.cos(), a * phi.sin()]);
                }
                let state = RunState {
                    centring: e,
                    run_coeffs: &run_coeffs,
                    bar_mm: truth.bar_length_um * 1e-3,
                    session_offset_s: clock - start_unix_s,
                    controller,
                };
                let command = circle.as_ref().map_or(Command::Columns, Command::Circle);
                fill_readings(&model, command, &mut run, &theta, &state, noise, &mut rng)?;
                // A circle lasts its sweep; a free run its samples (its path ends within one
                // sample interval after the last).
                let duration_s = match &circle {
                    Some(c) => c.duration_s(),
                    None => run.t_s.last().copied().unwrap_or(0.0),
                };
                clock += duration_s + truth.pause_s;
                centring_mm.push(e);
                runs.push(run);
            }
        }
    }
    Ok(Simulation { runs, parameters: values.into_iter().collect(), centring_mm })
}

/// The rotary motion of test `k` of a truth: `Some` for a free test, `None` for a planar one;
/// an error when the two do not go together or a field does not belong to the test's kind.
fn rotary_of(k: usize, test: &TestSpec) -> Result<Option<&RotarySpec>, SimError> {
    let bad =
        |what: String| Err(SimError::Truth(format!("tests[{k}] ({} test): {what}", test.plane)));
    if !(test.radius_mm > 0.0 && test.feed_mm_per_min > 0.0 && test.sweep_deg > 0.0) {
        return bad("radius_mm, feed_mm_per_min and sweep_deg must be positive".into());
    }
    for (key, value, (low, high), unit) in [
        ("feed_mm_per_min", test.feed_mm_per_min, plausible::FEED_MM_PER_MIN, "mm/min"),
        ("radius_mm", test.radius_mm, plausible::RADIUS_MM, "mm"),
    ] {
        if !(low..=high).contains(&value) {
            return bad(format!(
                "{key} {value:e} {unit} is beyond a ballbar test's ({low} to {high} {unit})"
            ));
        }
    }
    let turn = plausible::MAX_START_ANGLE_DEG;
    if !(-turn..=turn).contains(&test.start_deg) {
        return bad(format!(
            "start_deg {:e}° is more than a turn ({turn}°) either way",
            test.start_deg
        ));
    }
    match (test.plane, &test.rotary) {
        (Plane::Free, None) => bad("a free test is a rotary-axis test and needs `rotary: (turns: [(axis: C, start_deg: 0.0, sweep_deg: 360.0)], bar: Radial)`".into()),
        (Plane::Free, Some(r)) => {
            if test.start_deg != 0.0 || test.sweep_deg != full() {
                return bad(format!(
                    "start_deg {} and sweep_deg {} are a circle's; a rotary test gives its angles in rotary.turns (leave them out)",
                    test.start_deg, test.sweep_deg
                ));
            }
            Ok(Some(r))
        }
        (_, Some(_)) => bad("`rotary` is for free tests (plane: Free); a planar circle has no rotary motion".into()),
        (_, None) => Ok(None),
    }
}

/// A rotary test's `table_ball_mm`, when given (not zero), is where the pivot put the table
/// ball (the run header's), within [`TABLE_BALL_TOLERANCE_MM`].
fn check_table_ball(k: usize, test: &TestSpec, run: &Run) -> Result<(), SimError> {
    let given = nalgebra::Vector3::from(test.table_ball_mm);
    let placed = nalgebra::Vector3::from(run.header.table_ball_mm);
    let off_mm = (given - placed).norm();
    if given != nalgebra::Vector3::zeros() && (off_mm > TABLE_BALL_TOLERANCE_MM || off_mm.is_nan())
    {
        let show = |v: &nalgebra::Vector3<f64>| format!("({:.3}, {:.3}, {:.3})", v.x, v.y, v.z);
        return Err(SimError::Truth(format!(
            "tests[{k}] (free test): table_ball_mm {} is not where pivot_mm and tool_ball_mm place the table ball, {} (table frame, mm): give that within {TABLE_BALL_TOLERANCE_MM} mm, or leave table_ball_mm out",
            show(&given),
            show(&placed)
        )));
    }
    Ok(())
}

/// What one run of a simulation has of its own.
struct RunState<'a> {
    /// Centring offset of the table ball, mm.
    centring: [f64; 3],
    /// The run's coefficients of the model's run terms.
    run_coeffs: &'a [f64],
    /// Bar-length error, mm.
    bar_mm: f64,
    /// The run's start after the session's, s.
    session_offset_s: f64,
    /// The controller's compensation active while the machine runs.
    controller: Option<&'a dyn JointTrims>,
}

fn fill_readings(
    model: &Model,
    command: Command<'_>,
    run: &mut Run,
    theta: &dyn Fn(&str) -> f64,
    state: &RunState<'_>,
    noise: Noise,
    rng: &mut Rng,
) -> Result<(), ModelError> {
    let RunState { centring, run_coeffs, bar_mm, session_offset_s, controller } = *state;
    let chain = &model.chain;
    let axes = chain.axes();
    let lag_of = |a: Axis| theta(&format!("T{a}"));
    let traces: Vec<(Axis, AxisTrace)> = axes
        .iter()
        .map(|&a| {
            // Every axis with a lag term lags, rotary ones too (a `TC` of a chain file).
            let tau = if model.options.servo == ServoVariant::AxisLag { lag_of(a) } else { 0.0 };
            (a, axis_trace(command, run, a, tau, controller))
        })
        .collect();
    // Reversals of the actual (lagging) motion, for effects that follow them; the machine moved
    // along its lead-in before the run, so a reversal just before the first sample counts too.
    let reversals: Vec<Vec<f64>> = traces
        .iter()
        .map(|(_, tr)| {
            let (v, d): (Vec<f64>, Vec<f64>) = tr.iter().map(|&(_, v, d)| (v, d)).unzip();
            let q: Vec<f64> = tr.iter().map(|&(q, _, _)| q).collect();
            let mut times = reversal_times(&run.t_s, &v, &d);
            if let Some(r) = start_reversal(&run.t_s, &q) {
                times.insert(0, r);
            }
            times
        })
        .collect();
    let h = run.header.clone();
    let balls = chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
    let centring = nalgebra::Vector3::from(centring);
    let coeffs: Vec<f64> = model.terms.iter().map(|t| theta(t.term.id())).collect();
    let feed = h.feed_mm_per_s();
    let d_sign = h.direction.map(|d| d.paper_sign()).unwrap_or(0.0);
    let mut scratch = ExactScratch::default();
    let mut last_noise: Option<(f64, f64)> = None;
    for i in 0..run.len() {
        let mut q = [0.0; 6];
        fill_q(run, i, &mut q);
        let mut states = [JointState::default(); 6];
        let t = run.t_s[i];
        for ((a, tr), rev) in traces.iter().zip(&reversals) {
            let (qa, v, d) = tr[i];
            q[a.index()] = qa;
            states[a.index()] = JointState {
                q: qa,
                velocity: v,
                direction: d,
                t_s: t,
                feed_mm_per_s: feed,
                since_reversal_s: since_last(rev, t),
                session_t_s: session_offset_s + t,
            };
        }
        // Lag is realised by the time-domain filter above, not as an error motion.
        let length = exact_length(
            model,
            &q,
            &states,
            &balls,
            &centring,
            &coeffs,
            run_coeffs,
            true,
            &mut scratch,
        )?;
        // Reading terms use the nominal relative vector of the commanded path.
        let mut qc = [0.0; 6];
        fill_q(run, i, &mut qc);
        let nominal = chain.pose(&qc, &balls, None, None);
        let d = nominal.tool_ball - nominal.table_ball;
        let mut reading = 0.0;
        let rs = ReadingSample {
            plane: h.plane,
            paper_sign: d_sign,
            d: &d,
            radius_mm: h.radius_mm,
            feed_mm_per_s: feed,
            session_t_s: session_offset_s + t,
        };
        for rt in &model.reading_terms {
            // The bar-length error comes from the truth's bar_length_um, below.
            if *rt != ReadingTerm::BarLength {
                reading += theta(&reading_id(rt)) * reading_basis(rt, &rs);
            }
        }
        let e = noise.next(rng, t, &mut last_noise);
        run.dr_mm[i] = length - h.radius_mm + bar_mm + reading + e;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::path::BarDirection;

    /// The column machine without error terms: the reading is the noise alone (plus the
    /// rounding of commanded positions to 1 nm).
    fn perfect() -> MachineSpec {
        MachineSpec { terms: vec![], ..ballbar_model::machines::column() }
    }

    fn truth(noise_um: f64, correlation_ms: f64) -> Truth {
        Truth {
            servo: ServoVariant::AxisLag,
            errors: BTreeMap::new(),
            paper: None,
            bar_length_um: 0.0,
            centring_sd_um: 0.0,
            noise_um,
            noise_correlation_ms: correlation_ms,
            sample_rate_hz: 1000.0,
            started_at: "2026-11-21T10:00:00Z".into(),
            pause_s: 0.0,
            tests: vec![TestSpec {
                plane: Plane::XY,
                directions: vec![Direction::CW, Direction::CCW],
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: [300.0, 200.0, -300.0],
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0, 0.0, -100.0],
                repeats: 1,
                start_deg: 0.0,
                sweep_deg: 360.0,
                rotary: None,
            }],
            effects: vec![],
        }
    }

    /// Standard deviation and autocorrelations at lags 1 and 2 of the readings, pooled over runs.
    fn moments(runs: &[Run]) -> (f64, f64, f64, usize) {
        let (mut s0, mut s1, mut s2, mut n) = (0.0, 0.0, 0.0, 0);
        for r in runs {
            let x = &r.dr_mm;
            s0 += x.iter().map(|v| v * v).sum::<f64>();
            s1 += x.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
            s2 += x.windows(3).map(|w| w[0] * w[2]).sum::<f64>();
            n += x.len();
        }
        ((s0 / n as f64).sqrt(), s1 / s0, s2 / s0, n)
    }

    #[test]
    fn correlated_noise_is_an_exact_ar1_process_and_white_noise_is_unchanged() {
        let spec = perfect();
        // White: correlation 0 is the default, and draws the same stream as before the option
        // existed (one normal sample per reading, scaled): the readings equal σ z of a fresh
        // generator of the same seed.
        let white = simulate(&spec, &truth(0.5, 0.0), 0.0, 7).unwrap().runs;
        let parsed: Truth = ron::from_str(
            "(noise_um: 0.5, sample_rate_hz: 1000.0, started_at: \"2026-11-21T10:00:00Z\", tests: [(plane: XY, directions: [CW, CCW], radius_mm: 100.0, feed_mm_per_min: 1000.0, pivot_mm: (300.0, 200.0, -300.0), tool_ball_mm: (0.0, 0.0, -100.0))])",
        )
        .unwrap();
        assert_eq!(parsed.noise_correlation_ms, 0.0);
        let mut rng = Rng::new(7);
        // The two centring draws per run come first (zero here, but drawn).
        for r in &white {
            rng.normal();
            rng.normal();
            for &x in &r.dr_mm {
                // Rounding of the commanded positions to 1 nm moves the length by < 1e-6 mm.
                let z = rng.normal() * 0.5e-3;
                assert!((x - z).abs() < 2e-6, "{x} vs {z}");
            }
        }

        // Correlated: 20 ms at 1 kHz, ρ = e^{-1/20}, n ≈ 75k samples. Sampling errors of an
        // AR(1) process (Bartlett): var(r_k) ≈ ((1+ρ²)(1-ρ^{2k})/(1-ρ²) - 2kρ^{2k})/n, so
        // 0.0011 at lag 1 and 0.0022 at lag 2; the standard deviation has a relative standard
        // error ½√(2(1+ρ²)/((1-ρ²)n)) ≈ 0.012. The bounds are five standard errors.
        let tau = 20.0;
        let runs = simulate(&spec, &truth(0.5, tau), 0.0, 7).unwrap().runs;
        let (sd, r1, r2, n) = moments(&runs);
        let rho: f64 = (-1.0 / tau).exp();
        let n = n as f64;
        let bartlett = |k: i32| {
            (((1.0 + rho * rho) * (1.0 - rho.powi(2 * k)) / (1.0 - rho * rho)
                - 2.0 * f64::from(k) * rho.powi(2 * k))
                / n)
                .sqrt()
        };
        let se_sd = 0.5 * (2.0 * (1.0 + rho * rho) / ((1.0 - rho * rho) * n)).sqrt();
        assert!((sd / 0.5e-3 - 1.0).abs() < 5.0 * se_sd, "σ {sd}");
        assert!((r1 - rho).abs() < 5.0 * bartlett(1), "lag 1: {r1} vs {rho}");
        // Exact discretisation: the lag-two autocorrelation is ρ² (an Euler step of the process
        // would give a different variance and lag structure).
        assert!((r2 - rho * rho).abs() < 5.0 * bartlett(2), "lag 2: {r2} vs {}", rho * rho);
        // And white noise has no lag-one correlation (standard error 1/√n ≈ 0.0036).
        let (_, w1, _, nw) = moments(&white);
        assert!(w1.abs() < 5.0 / (nw as f64).sqrt(), "white lag 1: {w1}");
        // Negative values are refused.
        let mut bad = truth(0.5, -1.0);
        assert!(simulate(&spec, &bad, 0.0, 1).is_err());
        bad.noise_correlation_ms = f64::NAN;
        assert!(simulate(&spec, &bad, 0.0, 1).is_err());
    }

    // ---- Rotary-axis (free) tests ----

    const AC_MACHINE: &str = include_str!("../../../fixtures/machines/five-axis-ac-trunnion.ron");
    const BC_MACHINE: &str = include_str!("../../../fixtures/machines/five-axis-bc-head-table.ron");
    const AC_TRUTH: &str =
        include_str!("../../../fixtures/machines/five-axis-ac-trunnion.rotary.truth.ron");
    const BC_TRUTH: &str =
        include_str!("../../../fixtures/machines/five-axis-bc-head-table.rotary.truth.ron");

    /// The trunnion's table ball 100 mm out on +X, 50 mm above the C table's face (the C
    /// frame's origin): with A = C = 0 the face is at X = Y = 0, 190 mm above the Z head's
    /// reference, so with a 100 mm tool the pivot is (100, 0, 290 + 50).
    const AC_PIVOT: [f64; 3] = [100.0, 0.0, 340.0];
    const AC_BALL: [f64; 3] = [100.0, 0.0, 50.0];
    const TOOL: [f64; 3] = [0.0, 0.0, -100.0];

    fn chain_file(text: &str) -> MachineSpec {
        ballbar_machine_chain_file::parse(text).unwrap()
    }

    /// A rotary test of R = 100 mm at 1000 mm/min.
    fn free(pivot_mm: [f64; 3], turns: &[(Axis, f64, f64)], bar: BarDirection) -> TestSpec {
        TestSpec {
            plane: Plane::Free,
            directions: vec![Direction::CCW, Direction::CW],
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm,
            table_ball_mm: [0.0; 3],
            tool_ball_mm: TOOL,
            repeats: 1,
            start_deg: 0.0,
            sweep_deg: 360.0,
            rotary: Some(RotarySpec {
                turns: turns
                    .iter()
                    .map(|&(axis, start_deg, sweep_deg)| TurnSpec { axis, start_deg, sweep_deg })
                    .collect(),
                hold: vec![],
                bar,
            }),
        }
    }

    /// A truth of `tests` at 50 Hz without errors, noise or centring.
    fn quiet(tests: Vec<TestSpec>) -> Truth {
        Truth { sample_rate_hz: 50.0, noise_um: 0.0, tests, ..truth(0.0, 0.0) }
    }

    #[test]
    fn the_rotary_truth_files_simulate_and_read_the_bar_length_without_errors() {
        for (machine, text) in [(AC_MACHINE, AC_TRUTH), (BC_MACHINE, BC_TRUTH)] {
            let spec = chain_file(machine);
            let truth: Truth = ron::from_str(text).unwrap();
            let sim = simulate(&spec, &truth, 0.0, 3).unwrap();
            let ids: Vec<String> = sim.runs.iter().map(Run::name).collect();
            let head = if spec.name.contains("trunnion") { "a" } else { "b" };
            for id in [
                "xy-cw-1",
                "c-radial-ccw-1",
                "c-radial-ccw-2",
                "c-radial-cw-2",
                "c-tangential-cw-1",
                "c-axial-ccw-1",
            ]
            .into_iter()
            .map(String::from)
            .chain([
                format!("{head}-radial-ccw-1"),
                format!("{head}-axial-cw-1"),
                format!("{}-radial-cw-1", if head == "a" { "ac" } else { "bc" }),
            ]) {
                assert!(ids.contains(&id), "{}: no run {id} in {ids:?}", spec.name);
            }
            assert_eq!(sim.runs.len(), 20);
            for (run, e) in sim.runs.iter().zip(&sim.centring_mm) {
                if run.header.plane == Plane::Free {
                    // Each rotary test gives the place of its table ball, checked against the pivot.
                    assert!(run.header.table_ball_mm != [0.0; 3], "{}", run.name());
                    assert!(
                        e.iter().all(|&x| x != 0.0),
                        "{}: a free run's centring is 3-D: {e:?}",
                        run.name()
                    );
                }
            }

            // Without errors, noise and centring the bar reads its length, but for the rounding
            // of the commanded coordinates: X, Y, Z to 1e-6 mm (≤ 0.5e-6 mm each along the
            // bar, 0.87e-6 mm together) and each rotary axis that moves to 1e-6° (0.5e-6° =
            // 8.7e-9 rad, which moves a ball at most 250 mm from its line, the B head's tool
            // ball, by 2.2e-6 mm; across a radial bar only to second order).
            let quiet =
                Truth { errors: BTreeMap::new(), centring_sd_um: 0.0, noise_um: 0.0, ..truth };
            let sim = simulate(&spec, &quiet, 0.0, 3).unwrap();
            for run in &sim.runs {
                let turning = [Axis::A, Axis::B, Axis::C]
                    .into_iter()
                    .filter(|&a| run.axis(a).is_some_and(|c| c.iter().any(|&x| x != c[0])))
                    .count();
                let bound = 0.87e-6 + turning as f64 * 250.0 * 0.5e-6_f64.to_radians();
                let worst = run.dr_mm.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
                assert!(worst < bound, "{} {}: |ΔR| up to {worst:e} mm", spec.name, run.name());
            }
        }
    }

    #[test]
    fn a_location_error_of_c_reads_the_closed_form_of_a_radial_test() {
        // The A/C trunnion, C a full turn at A = 0, bar radial, the table ball r = 100 mm out on
        // +X at h = 50 mm above the C frame's origin (the point C's tilts pivot about), R = 100
        // mm; one location error at a time, no centring, no noise, no lag.
        //
        // By hand. C is on the workpiece branch (σ = -1): the table turns physically by -C,
        // P = Rz(-C), so the bar, radial and fixed in the table, points along
        // u = P x = (cos C, -sin C, 0), and the ball sits at a = P (r, 0, h) from C's origin.
        // ISO 230-7 as the model states it: the location errors move C's line, the table being
        // where the nominal chain puts it at C = 0 and turning about the moved line; so the
        // ball moves by Δp = (I - P) δ for an offset δ, and by the rotation (ε - P ε) about
        // C's origin for a tilt ε. The tool follows its nominal path: the bar reads exactly
        // |R u - Δp| - R, 0 at C = 0 (the brief's ΔR(0), the ball set there). To first order,
        // -u·Δp = x·δ - u·δ: δ (1 - cos C) for E_X0C, δ sin C for E_Y0C; and for the tilts
        // -u·((ε - P ε) × a) = ε h (1 - cos C) for E_B0C, -ε h sin C for E_A0C. With φ = -C, the
        // table's physical angle, that is the domain brief's
        //   ΔR(C) - ΔR(0) = (E_X0C + h E_B0C)(1 - cos φ) - (E_Y0C - h E_A0C) sin φ;
        // with ISO 841's C in place of φ its sin term would have the wrong sign.
        let spec = chain_file(AC_MACHINE);
        let (r, h, big_r) = (100.0, AC_BALL[2], 100.0);
        let test = free(AC_PIVOT, &[(Axis::C, 0.0, 360.0)], BarDirection::Radial);
        let base = simulate(&spec, &quiet(vec![test.clone()]), 0.0, 1).unwrap();
        assert_eq!(
            base.runs[0].header.table_ball_mm, AC_BALL,
            "the ball where the pivot puts it (by hand above)"
        );
        let (mut worst_exact, mut worst_linear) = (0.0_f64, 0.0_f64);
        for (id, value) in [("EX0C", 8.0), ("EY0C", -5.0), ("EA0C", 15.0), ("EB0C", -10.0)] {
            let mut truth = quiet(vec![test.clone()]);
            truth.errors.insert(id.into(), value);
            let sim = simulate(&spec, &truth, 0.0, 1).unwrap();
            // Display units: µm for offsets, µrad for tilts.
            let (ex, ey, ea, eb) = match id {
                "EX0C" => (value * 1e-3, 0.0, 0.0, 0.0),
                "EY0C" => (0.0, value * 1e-3, 0.0, 0.0),
                "EA0C" => (0.0, 0.0, value * 1e-6, 0.0),
                _ => (0.0, 0.0, 0.0, value * 1e-6),
            };
            let exact = |c: f64| {
                let p = nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::z_axis(), -c);
                let u = p * nalgebra::Vector3::x();
                let a = p * nalgebra::Vector3::new(r, 0.0, h);
                let (delta, eps) =
                    (nalgebra::Vector3::new(ex, ey, 0.0), nalgebra::Vector3::new(ea, eb, 0.0));
                let turn = nalgebra::Rotation3::from_scaled_axis(eps - p * eps);
                let dp = (delta - p * delta) + (turn * a - a);
                ((u * big_r - dp).norm() - big_r, dp.norm())
            };
            let linear = |c: f64| {
                let phi = -c;
                (ex + h * eb) * (1.0 - phi.cos()) - (ey - h * ea) * phi.sin()
            };
            for (run, base) in sim.runs.iter().zip(&base.runs) {
                for (i, &c) in run.axis(Axis::C).unwrap().iter().enumerate() {
                    // Less the error-free run, which holds the rounding of the commanded
                    // coordinates (ρ ≤ 1e-6 mm): what is left differs from the closed form by
                    // ≈ ρ |Δp| / R < 1e-10 mm; float rounding of 300 mm lengths is 1e-13 mm.
                    // So 1e-9 mm (1e-6 µm).
                    let sim_dr = run.dr_mm[i] - base.dr_mm[i];
                    let (want, dp) = exact(c);
                    worst_exact = worst_exact.max((sim_dr - want).abs());
                    assert!(
                        (sim_dr - want).abs() < 1e-9,
                        "{id} {} C = {:.3}°: {sim_dr:e} vs {want:e}",
                        run.name(),
                        c.to_degrees()
                    );
                    // The brief's linear form holds to the second order of |Δp| / R: the
                    // bar's (|Δp|² / 2R at most) and the tilt's rotation (|ε - P ε|² |a| / 2
                    // < |Δp|² / 2R here, |a| > R).
                    worst_linear = worst_linear.max((sim_dr - linear(c)).abs());
                    assert!(
                        (sim_dr - linear(c)).abs() < dp * dp / big_r + 1e-9,
                        "{id} {} at C = {:.3}°: {sim_dr:e} vs {:e}",
                        run.name(),
                        c.to_degrees(),
                        linear(c)
                    );
                }
            }
            // The reading is relative to the ball set at C = 0: none there.
            assert!((sim.runs[0].dr_mm[0] - base.runs[0].dr_mm[0]).abs() < 1e-12, "{id} at C = 0");
        }
        println!(
            "radial C test, one location error at a time: simulated less the exact closed form up to {:.1e} µm, less the linear form up to {:.1e} µm",
            worst_exact * 1e3,
            worst_linear * 1e3
        );
    }

    /// An XY circle of R = 100 mm about (300, 200, -300) at 1000 mm/min, 50 Hz, CCW.
    fn xy_circle() -> CircleTest {
        CircleTest {
            plane: Plane::XY,
            direction: Direction::CCW,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm: [300.0, 200.0, -300.0],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: TOOL,
            sample_rate_hz: 50.0,
            start_deg: 0.0,
            sweep_deg: 360.0,
        }
    }

    #[test]
    fn the_controller_applies_no_trim_before_a_joint_moves_and_keeps_the_last_at_rest() {
        // A free run of X: at rest at 100 mm, down to 90 mm, at rest, then up to 95 mm, with
        // BACKLASH = 4 µm. LinuxCNC's correction (control.c): 0 until the joint first moves,
        // -2 µm moving down and kept at rest after it, +2 µm moving up.
        let mut run = xy_circle().run("2026-11-21T10:00:00Z", 0.0, "free", "perfect");
        run.header.plane = Plane::Free;
        let x: Vec<f64> = [vec![100.0; 5], (1..=10).map(|k| 100.0 - k as f64).collect()]
            .into_iter()
            .chain([vec![90.0; 5], (1..=5).map(|k| 90.0 + k as f64).collect()])
            .flatten()
            .collect();
        let n = x.len();
        run.t_s.truncate(n);
        run.dr_mm.truncate(n);
        run.lines.truncate(n);
        for a in Axis::LINEAR {
            run.axes[a.index()] = Some(vec![run.axis(a).unwrap()[0]; n]);
        }
        run.axes[0] = Some(x.clone());
        let c = linuxcnc::LinuxCnc::parse("[JOINT_0]\nBACKLASH = 0.004\n", "m.ini", &|_| {
            Err(String::new())
        })
        .unwrap();
        let trace = axis_trace(Command::Columns, &run, Axis::X, 0.0, Some(&c));
        let trims: Vec<f64> =
            trace.iter().zip(&x).map(|(s, q)| ((s.0 - q) * 1e6).round()).collect();
        // The model's central differences: the first sample moving is the one before the
        // motion's first step (index 4), the last at rest after it index 15; the rise starts at
        // index 19.
        let want: Vec<f64> = (0..n)
            .map(|i| match i {
                0..=3 => 0.0,
                4..=18 => -2000.0,
                _ => 2000.0,
            })
            .collect();
        assert_eq!(trims, want);
    }

    #[test]
    fn an_axis_the_run_does_not_move_holds_the_trim_its_positioning_left() {
        // An XY circle at Z = -300 mm with a LinuxCNC table on Z (joint 2): a scale, trims
        // 0.010 mm at -400 and 0.030 mm at -200 forward, 4 µm less reverse. Z never moves in
        // the run; the machine was positioned there before it, so the controller applies the
        // trim at -300 mm (interpolated: 0.020 forward, 0.016 reverse), and with the machine's
        // backlash of an axis at rest at the middle of its play (direction 0), their mean,
        // 0.018 mm, at every sample; without a lag and with τ = 1 ms alike.
        let test = xy_circle();
        let run = test.run("2026-11-21T10:00:00Z", 0.0, "xy", "perfect");
        let ini = "[JOINT_2]\nCOMP_FILE = z.comp\nCOMP_FILE_TYPE = 1\n";
        let c = linuxcnc::LinuxCnc::parse(ini, "m.ini", &|_| {
            Ok("-400.0 0.010 0.006\n-200.0 0.030 0.026\n".into())
        })
        .unwrap();
        for (command, tau) in [(Command::Columns, 0.0), (Command::Circle(&test), 1e-3)] {
            let trace = axis_trace(command, &run, Axis::Z, tau, Some(&c));
            let z = run.axis(Axis::Z).unwrap();
            for (s, q) in trace.iter().zip(z) {
                // Interpolation and the mean are exact but for rounding: 1e-12 mm.
                assert!((s.0 - q - 0.018).abs() < 1e-12, "τ = {tau}: trim {} mm", s.0 - q);
            }
        }
    }

    #[test]
    fn the_lag_filter_of_a_free_run_is_the_circles() {
        // A circle's command as a free run: the columns at the samples, unrounded (rounding to
        // 1e-6 mm would by itself move the command by up to 0.5e-6 mm). It starts at 30° so
        // that neither axis reverses at the first sample.
        let tau = 1e-3;
        let (big_r, feed) = (100.0, 1000.0);
        let circle = |rate: f64| CircleTest {
            plane: Plane::XY,
            direction: Direction::CCW,
            radius_mm: big_r,
            feed_mm_per_min: feed,
            pivot_mm: [300.0, 200.0, -300.0],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: TOOL,
            sample_rate_hz: rate,
            start_deg: 30.0,
            sweep_deg: 360.0,
        };
        let as_free = |c: &CircleTest| {
            let mut run = c.run("2026-11-21T10:00:00Z", 0.0, "free", "perfect");
            run.header.plane = Plane::Free;
            for a in Axis::LINEAR {
                run.axes[a.index()] =
                    Some(run.t_s.iter().map(|&t| c.position(t)[a.index()]).collect());
            }
            run
        };
        let w = feed / 60.0 / big_r;
        // The linear lead-in misses the path's curvature: the state at the first sample is off
        // by τ² a (a = R ω² along the axis), decaying as e^{-t/τ}.
        let lead_in = |t: f64| tau * tau * big_r * w * w * (-t / tau).exp();

        // At the truth files' 50 Hz, against the exact response of the first-order lag to the
        // circle: x = R/√(1+ω²τ²) cos(θ - atan ωτ) from the pivot (the planar lead-in's start
        // transient is e⁻²⁰ τ v ≈ 4e-11 mm). The Hermite curve with central-difference slopes
        // errs by the slopes' h² R ω³/6 (h² R ω³/3 at the ends) times τ and the curve's h⁴
        // term: 3e-8 mm inside, 5e-8 mm at the last sample (its slope one-sided). 1e-7 mm.
        let c50 = circle(50.0);
        let free50 = as_free(&c50);
        let gain = 1.0 / (1.0 + (w * tau).powi(2)).sqrt();
        let mut worst = 0.0_f64;
        for (a, k) in [(Axis::X, 0), (Axis::Y, 1)] {
            let trace = axis_trace(Command::Columns, &free50, a, tau, None);
            for (i, &(q, _, _)) in trace.iter().enumerate() {
                let t = free50.t_s[i];
                let th = 30f64.to_radians() + w * t - (w * tau).atan();
                let exact =
                    c50.pivot_mm[k] + big_r * gain * if k == 0 { th.cos() } else { th.sin() };
                if i > 0 {
                    worst = worst.max((q - exact).abs());
                }
                assert!((q - exact).abs() < 1e-7 + lead_in(t), "{a} at {t} s: {q} vs {exact}");
            }
        }
        println!("lag filter of a free run at 50 Hz: up to {worst:.1e} mm from the exact response");

        // Against the planar filter, at 500 Hz: its chords over 8 sub-steps of h/8 bow in by
        // R ω² (h/8)²/12 = 1.4e-8 mm on average, the cubic's error is 1e-9 mm. 1e-7 mm.
        let c500 = circle(500.0);
        let free500 = as_free(&c500);
        let planar_run = c500.run("2026-11-21T10:00:00Z", 0.0, "planar", "perfect");
        for a in [Axis::X, Axis::Y] {
            let planar = axis_trace(Command::Circle(&c500), &planar_run, a, tau, None);
            let columns = axis_trace(Command::Columns, &free500, a, tau, None);
            for (i, (p, c)) in planar.iter().zip(&columns).enumerate() {
                let t = free500.t_s[i];
                assert!(
                    (p.0 - c.0).abs() < 1e-7 + lead_in(t),
                    "{a} at {t} s: planar {} vs free {}",
                    p.0,
                    c.0
                );
                // The velocity (p - q)/τ and its direction: the same motion.
                assert!(
                    (p.1 - c.1).abs() < (1e-7 + lead_in(t)) / tau,
                    "{a} at {t} s: velocity {} vs {}",
                    p.1,
                    c.1
                );
                assert_eq!(p.2, c.2, "{a} at {t} s: direction");
            }
        }
        // Without lag a free run's axes move as commanded (the model's velocities).
        let still = axis_trace(Command::Columns, &free50, Axis::X, 0.0, None);
        assert!(still.iter().zip(free50.axis(Axis::X).unwrap()).all(|(s, &q)| s.0 == q));
    }

    #[test]
    fn a_rotary_test_reads_from_ron_and_runs_each_direction() {
        // The plain struct, as the truth files write it, and RON's Some(...).
        let entry = "(plane: Free, directions: [CCW, CW], radius_mm: 100.0, feed_mm_per_min: 1000.0, pivot_mm: (100.0, 0.0, 340.0), tool_ball_mm: (0.0, 0.0, -100.0), rotary: ROTARY)";
        let rotary = "(turns: [(axis: C, start_deg: 0.0, sweep_deg: 360.0)], hold: [(A, -30.0)], bar: Radial)";
        let plain: TestSpec = ron::from_str(&entry.replace("ROTARY", rotary)).unwrap();
        let some: TestSpec =
            ron::from_str(&entry.replace("ROTARY", &format!("Some({rotary})"))).unwrap();
        assert_eq!(plain, some);
        let r = plain.rotary.as_ref().unwrap();
        assert_eq!(
            (r.turns[0], r.hold.clone(), r.bar),
            (
                TurnSpec { axis: Axis::C, start_deg: 0.0, sweep_deg: 360.0 },
                vec![(Axis::A, -30.0)],
                BarDirection::Radial
            )
        );
        // Written back and read again; a planar entry is written without `rotary`.
        let text = ron::to_string(&plain).unwrap();
        assert_eq!(ron::from_str::<TestSpec>(&text).unwrap(), plain);
        let planar = &truth(0.0, 0.0).tests[0];
        let text = ron::to_string(planar).unwrap();
        assert!(!text.contains("rotary"), "{text}");
        assert_eq!(&ron::from_str::<TestSpec>(&text).unwrap(), planar);
        // An unknown field of the rotary struct is refused.
        assert!(
            ron::from_str::<TestSpec>(&entry.replace("ROTARY", &rotary.replace("bar:", "bars:")))
                .is_err()
        );

        let spec = chain_file(AC_MACHINE);
        let mut truth = quiet(vec![plain]);
        truth.centring_sd_um = 3.0;
        let sim = simulate(&spec, &truth, 0.0, 5).unwrap();
        let ids: Vec<String> = sim.runs.iter().map(Run::name).collect();
        assert_eq!(ids, ["c-radial-ccw-1", "c-radial-cw-1"]);
        let c_deg = |run: &Run, i: usize| run.axis(Axis::C).unwrap()[i].to_degrees();
        let (ccw, cw) = (&sim.runs[0], &sim.runs[1]);
        assert_eq!(
            (ccw.header.direction, cw.header.direction),
            (Some(Direction::CCW), Some(Direction::CW))
        );
        // CCW from 0° up, CW the same arc back from 360°; samples every 20 ms along the path, so
        // each ends within one sample's 0.1° of the other's start.
        assert!(c_deg(ccw, 0).abs() < 1e-9 && (c_deg(cw, 0) - 360.0).abs() < 1e-9);
        assert!(
            (c_deg(ccw, ccw.len() - 1) - 360.0).abs() < 0.1 && c_deg(cw, cw.len() - 1).abs() < 0.1
        );
        assert_eq!(ccw.len(), cw.len());
        // The held axis stays at its angle; the centring is drawn in X, Y and Z.
        for run in &sim.runs {
            assert!(
                run.axis(Axis::A).unwrap().iter().all(|&a| (a.to_degrees() + 30.0).abs() < 1e-9)
            );
        }
        assert!(sim.centring_mm.iter().all(|e| e.iter().all(|&x| x != 0.0)));
        // And read: a centring of a few µm against an R of 100 mm.
        assert!(sim.runs.iter().all(|r| r.dr_mm.iter().all(|x| x.abs() < 0.05)));
    }

    #[test]
    fn bad_free_tests_are_refused_naming_the_test() {
        let spec = chain_file(AC_MACHINE);
        let circle = truth(0.0, 0.0).tests.remove(0);
        let good = free(AC_PIVOT, &[(Axis::C, 0.0, 360.0)], BarDirection::Radial);
        // The second test (tests[1]) is the bad one.
        let refused =
            |bad: TestSpec| match simulate(&spec, &quiet(vec![circle.clone(), bad]), 0.0, 1) {
                Err(SimError::Truth(m)) => m,
                other => panic!("expected a truth error, got {other:?}"),
            };
        let with = |f: &dyn Fn(&mut TestSpec)| {
            let mut t = good.clone();
            f(&mut t);
            t
        };
        let turning = |axis: Axis| with(&|t| t.rotary.as_mut().unwrap().turns[0].axis = axis);
        let cases: Vec<(TestSpec, &[&str])> = vec![
            (with(&|t| t.rotary = None), &["tests[1]", "needs `rotary"]),
            (with(&|t| t.plane = Plane::XY), &["tests[1]", "`rotary` is for free tests"]),
            (with(&|t| t.start_deg = 10.0), &["tests[1]", "start_deg 10", "rotary.turns"]),
            (with(&|t| t.sweep_deg = 180.0), &["tests[1]", "sweep_deg 180"]),
            // From the path (RotaryTest::run): the run's id names the direction.
            (
                turning(Axis::X),
                &["tests[1] (x-radial-ccw-1)", "X is not a rotary axis of this machine"],
            ),
            (turning(Axis::B), &["tests[1]", "B is not a rotary axis of this machine"]),
            (with(&|t| t.rotary.as_mut().unwrap().turns.clear()), &["tests[1]", "no turning axis"]),
            // The ball on the C axis line: no radial direction.
            (with(&|t| t.pivot_mm = [0.0, 0.0, 340.0]), &["tests[1]", "from the C axis line"]),
            (
                with(&|t| t.table_ball_mm = [100.0, 0.0, 60.0]),
                &["tests[1]", "table_ball_mm (100.000, 0.000, 60.000)", "(100.000, 0.000, 50.000)"],
            ),
            (with(&|t| t.radius_mm = -1.0), &["tests[1]", "must be positive"]),
        ];
        for (bad, words) in cases {
            let m = refused(bad);
            for w in words {
                assert!(m.contains(w), "'{w}' not in: {m}");
            }
        }
        // The table ball given where the pivot puts it (within 0.01 mm) is accepted.
        let given = with(&|t| t.table_ball_mm = [100.004, 0.0, 49.995]);
        assert!(simulate(&spec, &quiet(vec![given]), 0.0, 1).is_ok());
    }
}

//! An exact simulator of ballbar tests on a machine with known errors.
//!
//! "Exact" means no linearisation: every joint's error motion is applied as a rigid transform
//! (rotation by its rotation vector), the balls are placed through the full chain, and the
//! reading is the distance between them. Servo lag is simulated in the time domain: each axis's
//! actual position is its command passed through a first-order position loop
//! `dq/dt = (q_cmd - q)/τ`, integrated exactly for a command that is linear over each sub-step,
//! from a lead-in of 20 τ along the same circle (the start transient then decays to e⁻²⁰).
//! The other error terms are evaluated at the axes' actual state (backlash switches when the
//! lagging axis reverses). The paper's plane servo terms, bar length, centring offsets and
//! noise are added as the model states them.
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
//! reading, so white noise is the same stream as before this option existed.

use std::collections::BTreeMap;

use ballbar_model::design::{exact_length, fill_q, reading_basis, reversal_times, since_last, start_reversal, velocity_and_direction, ExactScratch, ReadingSample};
use ballbar_model::machine::{reading_id, ReadingTerm};
use ballbar_model::Effect;
use ballbar_model::machine::{BarLength, MachineSpec, Model, ModelOptions, ServoVariant};
use ballbar_model::paper::{parameters_from_paper, PaperValues};
use ballbar_model::path::CircleTest;
use ballbar_model::{Axis, Direction, JointState, ModelError, Plane, Run};
use serde::{Deserialize, Serialize};

pub mod rng;

use rng::Rng;

/// One kind of test in a truth file; each direction and repeat becomes a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TestSpec {
    /// Plane.
    pub plane: Plane,
    /// Directions to run, in order.
    pub directions: Vec<Direction>,
    /// Radius, mm.
    pub radius_mm: f64,
    /// Feed, mm/min.
    pub feed_mm_per_min: f64,
    /// Pivot, mm.
    pub pivot_mm: [f64; 3],
    /// Table ball, mm.
    #[serde(default)]
    pub table_ball_mm: [f64; 3],
    /// Tool ball, mm.
    #[serde(default)]
    pub tool_ball_mm: [f64; 3],
    /// How many times each direction is run.
    #[serde(default = "one")]
    pub repeats: u32,
    /// Start angle, degrees.
    #[serde(default)]
    pub start_deg: f64,
    /// Sweep, degrees.
    #[serde(default = "full")]
    pub sweep_deg: f64,
}

fn one() -> u32 {
    1
}
fn full() -> f64 {
    360.0
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
    /// Standard deviation of each run's random pivot offset per in-plane axis, µm.
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

/// The actual motion of one axis: the command, or the command through a first-order lag τ.
fn axis_trace(test: &CircleTest, run: &Run, axis: Axis, tau: f64) -> AxisTrace {
    let col = run.axis(axis).expect("circle runs have X, Y, Z");
    if tau <= 0.0 {
        return (0..run.len())
            .map(|i| {
                let (v, d) = velocity_and_direction(&run.t_s, col, i);
                (col[i], v, d)
            })
            .collect();
    }
    let k = axis.index();
    let cmd = |t: f64| test.position(t)[k];
    // Sub-steps: the chord error of linear interpolation over h is R (ω h)²/8; with 8 sub-steps
    // per sample at ≥ 25 Hz and ω ≤ 1 rad/s it stays below 1e-8 mm.
    let substeps = 8;
    let h_nominal = 1.0 / (test.sample_rate_hz * substeps as f64);
    let lead = 20.0 * tau;
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
        let d = if v > 1e-9 { 1.0 } else if v < -1e-9 { -1.0 } else { 0.0 };
        out.push((q, v, d));
    }
    out
}

/// Simulate every run of a truth on a machine.
pub fn simulate(spec: &MachineSpec, truth: &Truth, start_unix_s: f64, seed: u64) -> Result<Simulation, SimError> {
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
    let effects: Vec<Effect> = truth.effects.iter().map(|e| e.effect.clone()).collect();
    let model = Model::with_effects(spec.clone(), ModelOptions { servo: truth.servo, bar_length: BarLength::Fit }, kernels, &effects)?;
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
            return Err(SimError::Truth(format!("effect {}: value and phase must be finite", te.effect.describe())));
        }
        let unit = |id: &str| params.iter().find(|p| p.id == id).map(|p| p.unit.display_factor()).unwrap_or(1.0);
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
    if !(truth.noise_um >= 0.0 && truth.noise_um.is_finite() && truth.noise_correlation_ms >= 0.0 && truth.noise_correlation_ms.is_finite()) {
        return Err(SimError::Truth("noise_um and noise_correlation_ms must be finite and not negative".into()));
    }
    let noise = Noise { sd_mm: truth.noise_um * 1e-3, correlation_s: truth.noise_correlation_ms * 1e-3 };
    let theta = |id: &str| values.get(id).copied().unwrap_or(0.0);
    // Run terms (a vibration): amplitude A in mm per term pair (sine, cosine parts); each run
    // draws its phase φ, uniform, so that the run reads A sin(2π f t + φ).
    let vibration_mm: Vec<f64> = truth.effects.iter().filter(|te| matches!(te.effect, Effect::Vibration { .. })).map(|te| te.value * 1e-3).collect();
    let mut rng = Rng::new(seed);
    let mut runs = Vec::new();
    let mut centring_mm = Vec::new();
    let mut clock = start_unix_s;
    let mut counter: BTreeMap<String, u32> = BTreeMap::new();
    for test in &truth.tests {
        if test.plane == Plane::Free {
            return Err(SimError::Truth("free-path tests are not simulated yet; use XY, YZ or ZX".into()));
        }
        if !(test.radius_mm > 0.0 && test.feed_mm_per_min > 0.0 && test.sweep_deg > 0.0) {
            return Err(SimError::Truth("radius_mm, feed_mm_per_min and sweep_deg must be positive".into()));
        }
        for _ in 0..test.repeats {
            for &dir in &test.directions {
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
                let stem = format!("{}-{}", test.plane.name().to_lowercase(), dir.name().to_lowercase());
                let n = counter.entry(stem.clone()).and_modify(|c| *c += 1).or_insert(1);
                let id = format!("{stem}-{n}");
                let mut run = circle.run(&ballbar_io::time::format_iso8601(clock), clock, &id, &spec.name);
                // Planar tests hold the machine's rotary axes at zero: their columns are written.
                for a in model.chain.axes().into_iter().filter(|a| a.is_rotary()) {
                    run.axes[a.index()] = Some(vec![0.0; run.len()]);
                }
                let mut e = [0.0; 3];
                let (ua, va, _) = test.plane.axes().expect("planar");
                e[ua.index()] = rng.normal() * truth.centring_sd_um * 1e-3;
                e[va.index()] = rng.normal() * truth.centring_sd_um * 1e-3;
                let mut run_coeffs = Vec::with_capacity(model.run_terms.len());
                for a in &vibration_mm {
                    let phi = std::f64::consts::TAU * rng.uniform();
                    run_coeffs.extend([a * phi.cos(), a * phi.sin()]);
                }
                let state = RunState { centring: e, run_coeffs: &run_coeffs, bar_mm: truth.bar_length_um * 1e-3, session_offset_s: clock - start_unix_s };
                fill_readings(&model, &circle, &mut run, &theta, &state, noise, &mut rng)?;
                clock += circle.duration_s() + truth.pause_s;
                centring_mm.push(e);
                runs.push(run);
            }
        }
    }
    Ok(Simulation { runs, parameters: values.into_iter().collect(), centring_mm })
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
}

fn fill_readings(
    model: &Model,
    circle: &CircleTest,
    run: &mut Run,
    theta: &dyn Fn(&str) -> f64,
    state: &RunState<'_>,
    noise: Noise,
    rng: &mut Rng,
) -> Result<(), ModelError> {
    let RunState { centring, run_coeffs, bar_mm, session_offset_s } = *state;
    let chain = &model.chain;
    let axes = chain.axes();
    let lag_of = |a: Axis| theta(&format!("T{a}"));
    let traces: Vec<(Axis, AxisTrace)> = axes
        .iter()
        .map(|&a| {
            let tau = if model.options.servo == ServoVariant::AxisLag && !a.is_rotary() { lag_of(a) } else { 0.0 };
            (a, axis_trace(circle, run, a, tau))
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
        let length = exact_length(model, &q, &states, &balls, &centring, &coeffs, run_coeffs, true, &mut scratch)?;
        // Reading terms use the nominal relative vector of the commanded path.
        let mut qc = [0.0; 6];
        fill_q(run, i, &mut qc);
        let nominal = chain.pose(&qc, &balls, None, None);
        let d = nominal.tool_ball - nominal.table_ball;
        let mut reading = 0.0;
        let rs = ReadingSample { plane: h.plane, paper_sign: d_sign, d: &d, radius_mm: h.radius_mm, feed_mm_per_s: feed, session_t_s: session_offset_s + t };
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
    use ballbar_model::machine::{linear, AxisNorm};

    /// A three-axis machine without error terms: the reading is the noise alone (plus the
    /// rounding of commanded positions to 1 nm).
    fn perfect() -> MachineSpec {
        MachineSpec {
            name: "perfect".into(),
            version: "1".into(),
            description: "no errors".into(),
            tool: vec![linear("Z", Axis::Z, [0.0; 3])],
            workpiece: vec![linear("Y", Axis::Y, [0.0; 3]), linear("X", Axis::X, [0.0; 3])],
            normalisation: Axis::LINEAR.iter().map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: 250.0 }).collect(),
            terms: vec![],
        }
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
        let bartlett = |k: i32| (((1.0 + rho * rho) * (1.0 - rho.powi(2 * k)) / (1.0 - rho * rho) - 2.0 * f64::from(k) * rho.powi(2 * k)) / n).sqrt();
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
}

//! The independent set's perturbations: physical error sources written out by hand, per
//! sample, from a run's commanded axis columns, its times and its header, and added to the
//! runs' readings after the shared simulator has simulated the base machine. None of them goes
//! through `ballbar_model`'s terms or effects: their shapes are not the candidates' shapes, and
//! their code is not the diagnosis's code.
//!
//! # From an error vector to the reading
//! `δ` is the error of the tool relative to the workpiece in machine coordinates (mm), the
//! commanded machine coordinates `q` of the run's axis columns (X, Y, Z; an absent column is
//! the pivot's coordinate). The pivot `p` (`pivot_mm`) is where the tool ball would sit on the
//! table ball, so `q − p` is the commanded vector from the table ball to the tool ball, of
//! length `R`, and the bar's direction is `û = (q − p)/|q − p|`. The balls are displaced by
//! `δ`, so to first order (the second order is `|δ|²/2R`, below 1e-4 µm for the micrometres
//! here) the bar reads longer by
//! $$ ΔR_{extra} = \hat u \cdot δ, $$
//! positive when the bar is longer. Each perturbation below gives `δ` (one component, along
//! one axis `a`: `ΔR = û_a δ_a`), or adds to the reading directly (noise).
//!
//! # Velocities and reversals
//! An axis's commanded velocity `v_a` at a sample is the central difference of its positions
//! (one-sided at a run's ends). Its reversals are where the velocity changes sign: between the
//! midpoints of two sample intervals whose differences have opposite signs, at the zero of the
//! line through the two midpoint velocities. A run never starts from rest (the machine ran a
//! lead-in along the path): when the first two interval velocities have the same sign and the
//! speed grows, the line through them, extrapolated back, gives a reversal just before the
//! first sample if it lies within [`START_REVERSAL_SAMPLES`] sample intervals (on a circle the
//! axis velocity is linear in time through a reversal, so this is its time).

use ballbar_model::{Axis, Run};
use ballbar_sim::rng::Rng;

/// The feed at which feed-dependent sizes are stated, mm/min.
pub const REFERENCE_FEED_MM_PER_MIN: f64 = 1000.0;

/// How far before the first sample a reversal is still taken into a run, in sample intervals
/// (a spike lasts tens of milliseconds: several samples at 125 Hz).
pub const START_REVERSAL_SAMPLES: f64 = 5.0;

/// Two positions closer than this are the same (the run files' coordinates resolve 1e-6 mm):
/// the axis did not move over the interval.
const STILL_MM: f64 = 0.5e-6;

/// The strain of a warming ball screw against session time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Growth {
    /// `g(t) = r t`: a screw warming at a steady rate (early in a warm-up), `r` in ppm per hour.
    Linear {
        /// `r`, ppm/h.
        ppm_per_h: f64,
    },
    /// `g(t) = G (1 − e^{−t/T})`: a screw reaching a thermal equilibrium with time constant `T`.
    Saturating {
        /// `G`, ppm.
        ppm: f64,
        /// `T`, minutes.
        time_constant_min: f64,
    },
}

impl Growth {
    /// The strain (dimensionless) at session time `t_s` (s since the session's first run
    /// started).
    pub fn strain(&self, t_s: f64) -> f64 {
        match *self {
            Growth::Linear { ppm_per_h } => ppm_per_h * 1e-6 * t_s / 3600.0,
            Growth::Saturating { ppm, time_constant_min } => {
                ppm * 1e-6 * (1.0 - (-t_s / (time_constant_min * 60.0)).exp())
            }
        }
    }
}

/// A perturbation of the simulated runs (module docs; each variant's derivation with it).
#[derive(Clone, Debug, PartialEq)]
pub enum Perturbation {
    /// Thermal growth of the ball screw of linear axis `a`, fixed axially at its bearing
    /// `q_b`, one end of the axis's travel. Warming by `ΔT` strains the screw by `g = α ΔT`
    /// (steel: 11.5 ppm/K); the nut at commanded position `q_a` sits a screw length `q_a − q_b`
    /// from the bearing, which grew by `g (q_a − q_b)`: the axis travels further than commanded
    /// away from its bearing, and
    /// $$ δ_a = g(t)\,(q_a − q_b), \qquad t = t_{start} − t_{session\,start} + t_s. $$
    /// On a circle of radius `R` about `p` in the plane of `a` (angle `θ` from `a`):
    /// `q_a − q_b = (p_a − q_b) + R cos θ`, `û_a = cos θ`, so
    /// `ΔR = g (p_a − q_b) cos θ + g R cos² θ`: a first harmonic (the centring takes it up, but
    /// for its change within a run) and a scale `g R/2 (1 + cos 2θ)` that follows the session's
    /// clock, not the library's offset drift `δ_a = r t` (a first harmonic only) or bar growth.
    ThermalGrowth {
        /// `a`.
        axis: Axis,
        /// `q_b`, mm (machine coordinate of the fixed bearing).
        bearing_mm: f64,
        /// `g(t)`.
        growth: Growth,
    },
    /// A reversal spike whose height grows with the feed and that recovers algebraically.
    /// At a reversal of axis `a` at `t_r`, to the new direction `s = sign(v_a)`, friction
    /// reverses and the carriage sticks while the command moves on: the carriage lags the
    /// command in the new direction, `δ_a = −s h(t − t_r)`, pointing outward on a circle (at
    /// X's positive end, `s = −1` and `δ_X = +h`: the bar is longer), as the library's spike
    /// (`ballbar_model::term::Shape::ReversalSpike`: `−sign(dq/dt) e^{−t/τ}`, positive height
    /// outward). The impulse the loop must make up grows with the acceleration at the
    /// reversal (`F²/R` on a circle), and the loop's integrator recovers it with a heavy
    /// tail, not exponentially:
    /// $$ h(t) = h_{ref} (F/F_{ref})^{n} / (1 + t/τ)^2 $$
    /// for `t ≥ t_r`, following the axis's last reversal only (the tail of the one before is
    /// below 1e-4 of its height by then: reversals are a quarter of a circle apart, seconds).
    FeedSpike {
        /// `a`.
        axis: Axis,
        /// `h_ref`, µm, at [`REFERENCE_FEED_MM_PER_MIN`].
        height_um: f64,
        /// `n`.
        exponent: f64,
        /// `τ`, ms.
        tau_ms: f64,
    },
    /// Stick-slip from a Stribeck friction law. Friction on the carriage of axis `a` at speed
    /// `v_a` is `F_f = sign(v_a) [F_c + (F_s − F_c) e^{−(v_a/v_s)²}]` (Coulomb `F_c`, break-away
    /// `F_s`, Stribeck speed `v_s`); the position loop of stiffness `k` holds it with a
    /// deflection against the motion, `δ_a = −F_f/k`:
    /// $$ δ_a = −\mathrm{sign}(v_a)\,[C + S e^{−(v_a/v_s)^2}], \qquad C = F_c/k,\ S = (F_s − F_c)/k. $$
    /// The Coulomb part `C` is a backlash step, which the column machine's base model has
    /// (its paper terms include backlash): it is absorbed there. The Stribeck part is a
    /// Gaussian in velocity, where the library's stick-slip is a triangle, `max(0, 1 − |v|/v_c)`.
    Stribeck {
        /// `a`.
        axis: Axis,
        /// `S`, µm.
        stribeck_um: f64,
        /// `C`, µm.
        coulomb_um: f64,
        /// `v_s`, mm/min.
        speed_mm_per_min: f64,
    },
    /// Lateral play with finite stiffness. The carriage of axis `b` has a clearance `L` across
    /// its guide in direction `a`; the drag of its motion pushes it to one side of the
    /// clearance against a preload of finite stiffness, a drag that grows smoothly with the
    /// speed (viscous-regularised Coulomb friction, `tanh(v_b/v_0)`), so the carriage crosses
    /// the clearance over a few samples when `b` reverses instead of jumping:
    /// $$ δ_a = −(L/2) \tanh(v_b/v_0), $$
    /// which tends to the library's step `−(L/2) sign(v_b)` as `v_0 → 0`.
    SoftLateralPlay {
        /// `a`, the direction of the error.
        axis: Axis,
        /// `b`, whose reversals switch it.
        switched_by: Axis,
        /// `L`, µm.
        play_um: f64,
        /// `v_0`, mm/min.
        switch_mm_per_min: f64,
    },
    /// A structural mode of frequency `f` excited by the drives, with a forcing (and so an
    /// amplitude) proportional to the feed, and a phase `φ` of each run's own (a run does not
    /// start in step with the vibration), uniform on [0, 2π):
    /// $$ δ_a = A_{ref} (F/F_{ref}) \sin(2π f t + φ). $$
    FeedVibration {
        /// `a`.
        axis: Axis,
        /// `A_ref`, µm, at [`REFERENCE_FEED_MM_PER_MIN`].
        amplitude_um: f64,
        /// `f`, Hz.
        frequency_hz: f64,
    },
    /// A reversal spike that rings and recovers algebraically, on one side of the reversals
    /// or both. The carriage sticks at the reversal as for [`Perturbation::FeedSpike`], and
    /// the loop's overshoot rings at the axis's structural mode `f` while the integrator's
    /// heavy tail recovers it:
    /// $$ δ_a = −s\,h \cos(2π f (t − t_r)) / (1 + (t − t_r)/τ)^2 $$
    /// for `t ≥ t_r` after the axis's last reversal (to direction `s`), where the library's
    /// transient decays as `e^{−t/τ}` with a sine's phase. `side`: only after the reversals to
    /// that direction (`Some(+1.0)`: at the axis's negative end, where it turns to move
    /// positive), else after every reversal.
    RingingSpike {
        /// `a`.
        axis: Axis,
        /// `h`, µm.
        height_um: f64,
        /// `τ`, ms.
        tau_ms: f64,
        /// `f`, Hz.
        ring_hz: f64,
        /// The direction after the reversals it follows, or `None` for both.
        side: Option<f64>,
    },
    /// A cyclic error of a ball screw's lead with a second harmonic: the nut's position error
    /// along axis `a` repeats every screw pitch `p`, the lead's wobble `A₁` and the thread's
    /// form `A₂` at twice the rate, at a phase of 60° to it:
    /// $$ δ_a = A_1 \sin(2π q_a/p) + A_2 \sin(4π q_a/p + π/3), $$
    /// where the library's cyclic error is one sinusoid of one pitch.
    CyclicWaviness {
        /// `a`.
        axis: Axis,
        /// `p`, mm.
        pitch_mm: f64,
        /// `A₁`, µm.
        first_um: f64,
        /// `A₂`, µm.
        second_um: f64,
    },
    /// A slow drift of the bar's own length, not of the machine: the bar's temperature follows
    /// the shop's air, which swings with the heating's cycles. Two swings of periods `P₁`,
    /// `P₂` on the session's clock `t` (s since the session's first run started):
    /// $$ ΔR = D_1 \sin(2π t/P_1 + φ_1) + D_2 \sin(2π t/P_2 + φ_2), $$
    /// added to the reading (a longer bar reads longer in every direction). Within a run of
    /// tens of seconds it is a slow ramp; from run to run it wanders without a trend, where the
    /// library's bar growth is linear or saturating in session time.
    BarDrift {
        /// `D₁`, `D₂`, µm.
        amplitude_um: [f64; 2],
        /// `P₁`, `P₂`, minutes.
        period_min: [f64; 2],
        /// `φ₁`, `φ₂`, degrees.
        phase_deg: [f64; 2],
    },
    /// White reading noise of standard deviation `σ`, added to the reading itself (it is the
    /// instrument's, not a displacement of the balls): `ΔR += σ z`, `z` standard normal.
    WhiteNoise {
        /// `σ`, µm.
        sd_um: f64,
    },
}

impl Perturbation {
    /// A one-line description with its sizes.
    pub fn describe(&self) -> String {
        match self {
            Perturbation::ThermalGrowth { axis, bearing_mm, growth } => {
                let g = match growth {
                    Growth::Linear { ppm_per_h } => format!("linear {ppm_per_h} ppm/h"),
                    Growth::Saturating { ppm, time_constant_min } => {
                        format!("saturating {ppm} ppm (1 − e^(−t/{time_constant_min} min))")
                    }
                };
                format!("thermal growth of {axis}, {g}, bearing at {axis} = {bearing_mm} mm")
            }
            Perturbation::FeedSpike { axis, height_um, exponent, tau_ms } => {
                format!(
                    "reversal spike of {axis}, {height_um} µm at {REFERENCE_FEED_MM_PER_MIN} mm/min ∝ F^{exponent}, recovery 1/(1 + t/{tau_ms} ms)²"
                )
            }
            Perturbation::Stribeck { axis, stribeck_um, coulomb_um, speed_mm_per_min } => {
                format!(
                    "Stribeck stick-slip of {axis}, {stribeck_um} µm e^(−(v/{speed_mm_per_min} mm/min)²) + Coulomb {coulomb_um} µm"
                )
            }
            Perturbation::SoftLateralPlay { axis, switched_by, play_um, switch_mm_per_min } => {
                format!(
                    "lateral play of {axis} switched by {switched_by}, {play_um} µm, tanh(v/{switch_mm_per_min} mm/min)"
                )
            }
            Perturbation::FeedVibration { axis, amplitude_um, frequency_hz } => {
                format!(
                    "vibration of {axis} at {frequency_hz} Hz, {amplitude_um} µm at {REFERENCE_FEED_MM_PER_MIN} mm/min ∝ F, phase per run"
                )
            }
            Perturbation::RingingSpike { axis, height_um, tau_ms, ring_hz, side } => {
                let side = match side {
                    Some(s) if *s > 0.0 => " after the reversals at the negative end",
                    Some(_) => " after the reversals at the positive end",
                    None => "",
                };
                format!(
                    "ringing reversal spike of {axis}{side}, {height_um} µm cos(2π {ring_hz} Hz t)/(1 + t/{tau_ms} ms)²"
                )
            }
            Perturbation::CyclicWaviness { axis, pitch_mm, first_um, second_um } => format!(
                "cyclic error of {axis}, pitch {pitch_mm} mm: {first_um} µm and {second_um} µm at twice the rate"
            ),
            Perturbation::BarDrift { amplitude_um, period_min, .. } => format!(
                "slow drift of the bar, {} µm and {} µm swings of {} and {} min",
                amplitude_um[0], amplitude_um[1], period_min[0], period_min[1]
            ),
            Perturbation::WhiteNoise { sd_um } => format!("white noise {sd_um} µm"),
        }
    }
}

/// The unit bar direction `û = (q − p)/|q − p|` at sample `i` from the commanded linear axes
/// (an absent column: the pivot's coordinate).
pub fn bar_direction(run: &Run, i: usize) -> [f64; 3] {
    let p = run.header.pivot_mm;
    let mut d = [0.0; 3];
    for a in Axis::LINEAR {
        d[a.index()] = run.axis(a).map(|c| c[i] - p[a.index()]).unwrap_or(0.0);
    }
    let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    if n > 0.0 { [d[0] / n, d[1] / n, d[2] / n] } else { [0.0; 3] }
}

/// The commanded velocity of an axis at each sample, mm/s: central differences, one-sided at
/// the ends; zero where the axis did not move (or is absent).
pub fn velocity(run: &Run, axis: Axis) -> Vec<f64> {
    let n = run.len();
    let Some(q) = run.axis(axis) else { return vec![0.0; n] };
    if n < 2 {
        return vec![0.0; n];
    }
    (0..n)
        .map(|i| {
            let (a, b) = if i == 0 {
                (0, 1)
            } else if i + 1 == n {
                (n - 2, n - 1)
            } else {
                (i - 1, i + 1)
            };
            let dq = q[b] - q[a];
            if dq.abs() < STILL_MM { 0.0 } else { dq / (run.t_s[b] - run.t_s[a]) }
        })
        .collect()
}

/// A reversal of an axis: its time (s from the run's start) and the direction of motion after
/// it (±1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reversal {
    /// Time, s.
    pub t_s: f64,
    /// Direction after it, ±1.
    pub direction: f64,
}

/// The reversals of an axis in a run (module docs), ascending in time.
pub fn reversals(run: &Run, axis: Axis) -> Vec<Reversal> {
    let Some(q) = run.axis(axis) else { return vec![] };
    let t = &run.t_s;
    let n = run.len();
    if n < 3 {
        return vec![];
    }
    // Interval velocities at the intervals' midpoints; zero over an interval without motion.
    let mid: Vec<(f64, f64)> = (0..n - 1)
        .map(|k| {
            let dq = q[k + 1] - q[k];
            let w = if dq.abs() < STILL_MM { 0.0 } else { dq / (t[k + 1] - t[k]) };
            (0.5 * (t[k] + t[k + 1]), w)
        })
        .collect();
    let mut out = Vec::new();
    // Before the first sample: the speed grows from a zero just before it.
    let ((m0, w0), (m1, w1)) = (mid[0], mid[1]);
    if w0 != 0.0 && w0.signum() == w1.signum() && w1.abs() > w0.abs() {
        let zero = m0 - w0 * (m1 - m0) / (w1 - w0);
        let dt = t[1] - t[0];
        if zero >= t[0] - START_REVERSAL_SAMPLES * dt {
            out.push(Reversal { t_s: zero, direction: w0.signum() });
        }
    }
    // Inside: consecutive moving intervals of opposite sense.
    let mut last: Option<(f64, f64)> = None;
    for &(m, w) in &mid {
        if w == 0.0 {
            continue;
        }
        if let Some((ml, wl)) = last
            && wl.signum() != w.signum()
        {
            out.push(Reversal { t_s: ml + (m - ml) * wl / (wl - w), direction: w.signum() });
        }
        last = Some((m, w));
    }
    out
}

/// The last of `revs` (ascending) at or before `t`, if any.
fn last_reversal(revs: &[Reversal], t: f64) -> Option<Reversal> {
    let k = revs.partition_point(|r| r.t_s <= t);
    k.checked_sub(1).map(|k| revs[k])
}

/// The reading's change (mm per sample) by one perturbation in one run. `session_start_unix_s`
/// is the session's first start (the thermal clock's zero); `rng` draws a vibration's phase
/// (one draw per run) and white noise (one normal draw per sample); the other perturbations
/// draw nothing.
pub fn extra_mm(p: &Perturbation, run: &Run, session_start_unix_s: f64, rng: &mut Rng) -> Vec<f64> {
    let n = run.len();
    let u = |i: usize, a: Axis| bar_direction(run, i)[a.index()];
    let feed_ratio = run.header.feed_mm_per_min / REFERENCE_FEED_MM_PER_MIN;
    match *p {
        Perturbation::ThermalGrowth { axis, bearing_mm, growth } => {
            let Some(q) = run.axis(axis) else { return vec![0.0; n] };
            let start = run.header.started_at_unix_s - session_start_unix_s;
            (0..n)
                .map(|i| u(i, axis) * growth.strain(start + run.t_s[i]) * (q[i] - bearing_mm))
                .collect()
        }
        Perturbation::FeedSpike { axis, height_um, exponent, tau_ms } => {
            let h = height_um * 1e-3 * feed_ratio.powf(exponent);
            let tau = tau_ms * 1e-3;
            let revs = reversals(run, axis);
            (0..n)
                .map(|i| {
                    let t = run.t_s[i];
                    let Some(r) = last_reversal(&revs, t) else { return 0.0 };
                    let x = 1.0 + (t - r.t_s) / tau;
                    u(i, axis) * (-r.direction * h / (x * x))
                })
                .collect()
        }
        Perturbation::Stribeck { axis, stribeck_um, coulomb_um, speed_mm_per_min } => {
            let v = velocity(run, axis);
            let vs = speed_mm_per_min / 60.0;
            (0..n)
                .map(|i| {
                    let s = if v[i] > 0.0 {
                        1.0
                    } else if v[i] < 0.0 {
                        -1.0
                    } else {
                        0.0
                    };
                    let x = v[i] / vs;
                    u(i, axis) * (-s * (coulomb_um + stribeck_um * (-x * x).exp()) * 1e-3)
                })
                .collect()
        }
        Perturbation::SoftLateralPlay { axis, switched_by, play_um, switch_mm_per_min } => {
            let v = velocity(run, switched_by);
            let v0 = switch_mm_per_min / 60.0;
            (0..n).map(|i| u(i, axis) * (-0.5 * play_um * 1e-3 * (v[i] / v0).tanh())).collect()
        }
        Perturbation::FeedVibration { axis, amplitude_um, frequency_hz } => {
            let phase = std::f64::consts::TAU * rng.uniform();
            let a = amplitude_um * 1e-3 * feed_ratio;
            (0..n)
                .map(|i| {
                    u(i, axis)
                        * a
                        * (std::f64::consts::TAU * frequency_hz * run.t_s[i] + phase).sin()
                })
                .collect()
        }
        Perturbation::RingingSpike { axis, height_um, tau_ms, ring_hz, side } => {
            let (h, tau) = (height_um * 1e-3, tau_ms * 1e-3);
            let revs = reversals(run, axis);
            (0..n)
                .map(|i| {
                    let t = run.t_s[i];
                    let Some(r) = last_reversal(&revs, t) else { return 0.0 };
                    if side.is_some_and(|s| s != r.direction) {
                        return 0.0;
                    }
                    let dt = t - r.t_s;
                    let x = 1.0 + dt / tau;
                    let ring = (std::f64::consts::TAU * ring_hz * dt).cos();
                    u(i, axis) * (-r.direction * h * ring / (x * x))
                })
                .collect()
        }
        Perturbation::CyclicWaviness { axis, pitch_mm, first_um, second_um } => {
            let Some(q) = run.axis(axis) else { return vec![0.0; n] };
            let w = std::f64::consts::TAU / pitch_mm;
            (0..n)
                .map(|i| {
                    let d = first_um * (w * q[i]).sin()
                        + second_um * (2.0 * w * q[i] + std::f64::consts::FRAC_PI_3).sin();
                    u(i, axis) * d * 1e-3
                })
                .collect()
        }
        Perturbation::BarDrift { amplitude_um, period_min, phase_deg } => {
            let start = run.header.started_at_unix_s - session_start_unix_s;
            (0..n)
                .map(|i| {
                    let t = start + run.t_s[i];
                    (0..2)
                        .map(|k| {
                            let w = std::f64::consts::TAU / (period_min[k] * 60.0);
                            amplitude_um[k] * 1e-3 * (w * t + phase_deg[k].to_radians()).sin()
                        })
                        .sum::<f64>()
                })
                .collect()
        }
        Perturbation::WhiteNoise { sd_um } => (0..n).map(|_| sd_um * 1e-3 * rng.normal()).collect(),
    }
}

/// Add the perturbations to the runs of one session (in the order simulated), with a
/// generator seeded by `seed`: run after run, each perturbation in turn.
pub fn apply(perturbations: &[Perturbation], runs: &mut [Run], seed: u64) {
    let session_start =
        runs.iter().map(|r| r.header.started_at_unix_s).fold(f64::INFINITY, f64::min);
    let mut rng = Rng::new(seed);
    for run in runs.iter_mut() {
        for p in perturbations {
            let extra = extra_mm(p, run, session_start, &mut rng);
            for (x, e) in run.dr_mm.iter_mut().zip(extra) {
                *x += e;
            }
        }
    }
}

//! Effects that a base model may lack (domain brief §4): the candidate library of the
//! sim-to-real diagnosis, and what a truth file may add to a simulated machine.
//!
//! An [`Effect`] is a set of columns: error terms on the chain (through the same
//! [`ErrorTerm`](crate::ErrorTerm) trait as the base model) or terms on the reading. Its
//! non-linear parameter (decay time, pitch, speed) is fixed in the description; the diagnosis
//! profiles it over a grid. Formulas, with `u` the effect's axis and `s = sign(du/dt)`:
//! - reversal spike: `Δu = -A s e^{-(t - t_r)/τ}` after each reversal of `u` at `t_r`: an
//!   outward spike, wider at lower feed in angle (id `SPX`, A in mm);
//! - reversal transient (also `reversal_spike` in the diagnosis JSON): a spike that rises
//!   over a finite time and may ring, `Δu = -s Σ_k a_k h_k(t - t_r)` after each reversal, with
//!   the three parts `h_k` of [`crate::term::transient`]: `e^{-x}`, `e^{-x} sin φ/(ωτ)`,
//!   `e^{-x} 2(1 - cos φ)/(ωτ)²` (`x = t/τ`, `φ = ωt`; `e^{-x}`, `x e^{-x}`, `x² e^{-x}` without
//!   ringing), the free response of a third-order servo loop whose modes decay alike. Linear in
//!   the `a_k`, so the rise and the ringing's phase are fitted; τ and the period `2π/ω` are
//!   profiled. With `per_side`, one set `a_k` per side: the reversal at the positive end of the
//!   axis's travel (`POS`: its motion turns + → −, X at θ = 0° of a circle) and at the
//!   negative end (`NEG`: − → +, X at 180°). The term reads the turn (the direction of motion
//!   after the reversal), which is where the friction reverses and needs no circle centre; on
//!   a circle it is the same as the sign of the position about the centre. Friction, preload
//!   and the drive need not be alike at the two ends: a real machine's spikes differ (ids
//!   `SPXP0`, `SPXP1`, `SPXP2`, `SPXN0`, ...; `SPX0`.. for one set; coefficients in mm, the
//!   spike outward at both ends for a positive height);
//! - lateral play: `Δu = -(L/2) sign(dv/dt)`: a step of `u` switched by the reversals of `v`
//!   (the play of the `v` carriage across its motion; id `LPXY` for u = X, v = Y);
//! - cyclic error: `Δu = a sin(2π q_u/p) + b cos(2π q_u/p)`, locked to the absolute axis
//!   position (a lead screw of pitch p; ids `CSX`, `CCX`);
//! - vibration: `Δu = a_k sin(2π f t) + b_k cos(2π f t)` with `t` the run's time: a ripple
//!   locked to time, whose phase is each run's own (a run does not start in step with the
//!   machine's vibration), so one pair of coefficients per run `k` (ids `VSX@run`, `VCX@run`);
//!   its frequency in Hz stays put across feeds, where a cyclic error's scales with the feed;
//! - thermal drift: `Δu = g t` with `t` the time since the session's start (id `DX`, g in
//!   mm/s); of the bar: `ΔR = g t` (id `DBAR`);
//! - thermal growth of an axis: `Δu = θ g(t) q_u`, the axis's scale growing with the session
//!   time `t` (a ball screw warming from its fixed bearing), linearly (`g = t`, θ in 1/s,
//!   shown in ppm/h) or saturating (`g = 1 - e^{-t/τ}`, θ the scale reached, shown in ppm)
//!   (id `TGX`). Where the bearing sits is hardly seen by circles: about a bearing `q_b` the
//!   difference is an offset `-θ g(t) q_b`, which each run's centring takes but for its change
//!   within the run (for a linear growth exactly the offset drift `ThermalDrift`, a candidate
//!   of its own, at 15 ppm/h and 500 mm about 0.1 µm over a 50 s run); on a circle the growth is `θ g R cos²` of the angle
//!   from the axis: a second harmonic and a radius change in the planes of `u` only, which is
//!   how it differs from the bar's growth (every plane, no harmonic) and from an offset drift
//!   (a first harmonic that the centring takes but for its change within a run);
//! - a size that grows with the feed (`FeedScaled`): another effect's columns times
//!   `(F/F_ref)^p`, `F` the run's programmed feed, `p` profiled (a spike's height, a
//!   stick-slip's step; the ids of the effect scaled);
//! - stick-slip: `Δu = -S s max(0, 1 - |du/dt|/v_c)`: a step that builds up while the axis is
//!   slower than `v_c` around its reversals, so wider at low feed (id `SSX`);
//! - servo radius loss: a common position-loop lag τ shrinks the circle by `V²τ²/(2R)`:
//!   `ΔR = -c V²/(2R)` with `c = τ²` (id `LOSS`, s²);
//! - bar length drift: `ΔR = θ_k` in run `k`, one constant per run (ids `BAR@run`): the
//!   bar's own length changing between runs (its temperature, a recalibration). A run's own
//!   coefficient, as a vibration's phase: a held-out run refits it. In a circle test every
//!   change of the mean radius is this shape: a common thermal growth of the axes `s(t)` reads
//!   `s R` in every plane, a common servo lag's loss `V²τ²/(2R)` a constant per feed, a bar
//!   growing with time `g t`; what separates the bar from the machine is the bar re-measured
//!   in its calibrator, or a law of the machine (in time, in the feed) that predicts runs it
//!   was not fitted on, which a constant per run never does;
//! - higher-order positional and straightness: polynomial terms of degree 3, 4 (ids as the
//!   base: `EXX3`, `EYX3`); independent angular errors with their Abbe arms (`EBX1`: pitch of
//!   X); bar length (`BAR`); and the paper's own terms where a base model lacks them.

use serde::{Deserialize, Serialize};

use crate::axis::{Axis, Plane};
use crate::term_spec::{ReadingTerm, TermSpec};

/// An effect with its non-linear parameters fixed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Effect {
    /// Outward spike after each reversal of `axis`, decaying with `tau_ms`.
    ReversalSpike {
        /// The axis.
        axis: Axis,
        /// Decay time, ms.
        tau_ms: f64,
    },
    /// A spike after each reversal of `axis` that rises over a finite time and may ring:
    /// three linear parts (module docs), one set per side of the travel with `per_side`. Its
    /// kind in the diagnosis is `reversal_spike`, as [`Effect::ReversalSpike`]'s.
    ReversalTransient {
        /// The axis.
        axis: Axis,
        /// Decay time, ms.
        tau_ms: f64,
        /// Ringing period, ms (`None`: no ringing, the parts `e^{-x}`, `x e^{-x}`, `x² e^{-x}`).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        period_ms: Option<f64>,
        /// One set of coefficients per side (the reversal at the positive end of the axis's
        /// travel, and at the negative end).
        #[serde(default)]
        per_side: bool,
    },
    /// Error along `axis` switched by the reversals of `switched_by`.
    LateralPlay {
        /// The direction of the error.
        axis: Axis,
        /// The axis whose reversals switch it.
        switched_by: Axis,
    },
    /// Ripple locked to the absolute position of `axis`.
    CyclicError {
        /// The axis.
        axis: Axis,
        /// Pitch, mm.
        pitch_mm: f64,
    },
    /// A ripple of `axis` locked to time, with each run's own phase.
    Vibration {
        /// The axis.
        axis: Axis,
        /// Frequency, Hz.
        frequency_hz: f64,
    },
    /// Linear drift with session time: of `axis`, or of the bar (`None`).
    ThermalDrift {
        /// The drifting axis, or `None` for the bar.
        axis: Option<Axis>,
    },
    /// The scale of `axis` growing with session time (a warming ball screw), linearly or
    /// saturating with a time constant.
    ThermalGrowth {
        /// The axis.
        axis: Axis,
        /// τ, minutes (`None`: linear growth).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        time_constant_min: Option<f64>,
    },
    /// Another effect whose size grows with the feed as `(F/F_ref)^p`.
    FeedScaled {
        /// The effect scaled (chain terms only).
        effect: Box<Effect>,
        /// `p`.
        exponent: f64,
        /// `F_ref`, mm/min: the feed at which the reported size holds.
        reference_mm_per_min: f64,
    },
    /// A step building up at low axis speed near reversals.
    StickSlip {
        /// The axis.
        axis: Axis,
        /// The speed below which it acts, mm/min.
        speed_mm_per_min: f64,
    },
    /// The radius loss of a common servo lag, visible across feeds.
    ServoRadiusLoss,
    /// A positional polynomial term of `degree`.
    PositionalHigherOrder {
        /// The axis.
        axis: Axis,
        /// Degree (3, 4).
        degree: u32,
    },
    /// A straightness polynomial term of `degree` (angles tied).
    StraightnessHigherOrder {
        /// The moving axis.
        axis: Axis,
        /// The error direction.
        toward: Axis,
        /// Degree (3, 4).
        degree: u32,
    },
    /// An angular error motion of `axis` about `about`, linear in position, not tied to a
    /// straightness: it shows through Abbe arms (tool length, ball height).
    AngularError {
        /// The moving axis.
        axis: Axis,
        /// The rotation direction.
        about: Axis,
    },
    /// One bar-length error for all runs.
    BarLength,
    /// The bar's length changing from run to run: one constant `ΔR` per run.
    BarLengthDrift,
    /// Backlash of an axis.
    Backlash {
        /// The axis.
        axis: Axis,
    },
    /// The paper's independent servo-mismatch term of a plane.
    ServoMismatch {
        /// The plane.
        plane: Plane,
    },
    /// A harmonic of a rotary axis's angular positioning error (`E<k><k>_S<n>`, `_C<n>`):
    /// `ε = a sin nq + b cos nq` about its own line. A tangential bar sees it in full, a
    /// radial one not at all.
    RotaryPositioning {
        /// The rotary axis.
        axis: Axis,
        /// The harmonic (per revolution).
        harmonic: u32,
    },
    /// A harmonic of a rotary axis's run-out along `direction` (radial: perpendicular to the
    /// axis; axial: along it).
    RotaryRunout {
        /// The rotary axis.
        axis: Axis,
        /// The direction of the run-out (X, Y, Z).
        direction: Axis,
        /// The harmonic.
        harmonic: u32,
    },
    /// The servo lag of a rotary axis (`T<k>`: its angle behind its command by `τ dq/dt`), which
    /// the base model of a chain file without it lacks.
    RotaryLag {
        /// The rotary axis.
        axis: Axis,
    },
    /// A harmonic of a rotary axis's wobble (tilt error motion) about `about`.
    RotaryWobble {
        /// The rotary axis.
        axis: Axis,
        /// The rotation direction (A, B, C).
        about: Axis,
        /// The harmonic.
        harmonic: u32,
    },
}

/// Where an effect's column lives.
#[derive(Clone, Debug, PartialEq)]
pub enum EffectPart {
    /// Chain terms, built like a machine description's.
    Terms(TermSpec),
    /// A reading term.
    Reading(ReadingTerm),
    /// Chain terms with one coefficient per run ([`Model::run_terms`](crate::Model::run_terms)).
    PerRun(TermSpec),
    /// A reading term with one coefficient per run
    /// ([`Model::run_reading_terms`](crate::Model::run_reading_terms)).
    PerRunReading(ReadingTerm),
}

/// An effect parameter as reported: name with unit (`amplitude_um`), value.
pub type Reported = Vec<(String, f64)>;

impl Effect {
    /// The kind's name in the diagnosis JSON (`shared/spec/cli.md`).
    pub fn kind(&self) -> &'static str {
        match self {
            Effect::ReversalSpike { .. } | Effect::ReversalTransient { .. } => "reversal_spike",
            Effect::LateralPlay { .. } => "lateral_play",
            Effect::CyclicError { .. } => "cyclic_error",
            Effect::Vibration { .. } => "vibration",
            Effect::ThermalDrift { .. } => "thermal_drift",
            Effect::ThermalGrowth { .. } => "thermal_growth",
            Effect::FeedScaled { effect, .. } => effect.kind(),
            Effect::StickSlip { .. } => "stick_slip",
            Effect::ServoRadiusLoss => "servo_lag",
            Effect::PositionalHigherOrder { .. } => "positional_higher_order",
            Effect::StraightnessHigherOrder { .. } => "straightness_higher_order",
            Effect::AngularError { .. } => "angular_error",
            Effect::BarLength => "bar_length",
            Effect::BarLengthDrift => "bar_length_drift",
            Effect::Backlash { .. } => "backlash",
            Effect::ServoMismatch { .. } => "servo_mismatch",
            Effect::RotaryPositioning { .. } => "rotary_positioning",
            Effect::RotaryRunout { .. } => "rotary_runout",
            Effect::RotaryWobble { .. } => "rotary_wobble",
            Effect::RotaryLag { .. } => "rotary_lag",
        }
    }

    /// The axis (or pair, or none) that carries the effect, as the JSON names it.
    pub fn axis_label(&self) -> Option<String> {
        match self {
            Effect::ReversalSpike { axis, .. }
            | Effect::ReversalTransient { axis, .. }
            | Effect::CyclicError { axis, .. }
            | Effect::Vibration { axis, .. }
            | Effect::StickSlip { axis, .. }
            | Effect::PositionalHigherOrder { axis, .. }
            | Effect::StraightnessHigherOrder { axis, .. }
            | Effect::AngularError { axis, .. }
            | Effect::Backlash { axis }
            | Effect::RotaryPositioning { axis, .. }
            | Effect::RotaryRunout { axis, .. }
            | Effect::RotaryWobble { axis, .. }
            | Effect::RotaryLag { axis }
            | Effect::ThermalGrowth { axis, .. } => Some(axis.name().to_string()),
            Effect::FeedScaled { effect, .. } => effect.axis_label(),
            Effect::LateralPlay { axis, switched_by } => Some(format!("{axis}{switched_by}")),
            Effect::ThermalDrift { axis } => axis.map(|a| a.name().to_string()),
            Effect::ServoMismatch { plane } => Some(plane.name().to_string()),
            Effect::ServoRadiusLoss | Effect::BarLength | Effect::BarLengthDrift => None,
        }
    }

    /// True for an effect that changes with the session's time (a thermal growth or drift):
    /// what it claims to gain is a claim about later runs.
    pub fn is_time_dependent(&self) -> bool {
        match self {
            Effect::ThermalDrift { .. } | Effect::ThermalGrowth { .. } => true,
            Effect::FeedScaled { effect, .. } => effect.is_time_dependent(),
            _ => false,
        }
    }

    /// A one-line description.
    pub fn describe(&self) -> String {
        match self {
            Effect::ReversalSpike { axis, tau_ms } => {
                format!("reversal spike of {axis} (τ = {tau_ms:.0} ms)")
            }
            Effect::ReversalTransient { axis, tau_ms, period_ms, per_side } => format!(
                "reversal spike of {axis}{} (rise and decay τ = {tau_ms:.0} ms{})",
                if *per_side { ", per side" } else { "" },
                period_ms.map(|p| format!(", ringing period {p:.0} ms")).unwrap_or_default()
            ),
            Effect::LateralPlay { axis, switched_by } => {
                format!("lateral play: {axis} switched by the reversals of {switched_by}")
            }
            Effect::CyclicError { axis, pitch_mm } => {
                format!("cyclic error of {axis} (pitch {pitch_mm:.2} mm)")
            }
            Effect::Vibration { axis, frequency_hz } => {
                format!("vibration of {axis} at {frequency_hz:.2} Hz (phase per run)")
            }
            Effect::ThermalDrift { axis: Some(a) } => format!("thermal drift of {a}"),
            Effect::ThermalDrift { axis: None } => "thermal growth of the bar".into(),
            Effect::ThermalGrowth { axis, time_constant_min: None } => {
                format!("thermal growth of {axis} (scale growing linearly with time)")
            }
            Effect::ThermalGrowth { axis, time_constant_min: Some(t) } => {
                format!("thermal growth of {axis} (scale saturating, τ = {t:.0} min)")
            }
            Effect::FeedScaled { effect, exponent, reference_mm_per_min } => {
                format!(
                    "{}, size ∝ feed^{exponent:.2} (as stated at {reference_mm_per_min:.0} mm/min)",
                    effect.describe()
                )
            }
            Effect::StickSlip { axis, speed_mm_per_min } => {
                format!("stick-slip of {axis} (below {speed_mm_per_min:.0} mm/min)")
            }
            Effect::ServoRadiusLoss => "servo-lag radius loss (common lag)".into(),
            Effect::PositionalHigherOrder { axis, degree } => {
                format!("positional error of {axis}, degree {degree}")
            }
            Effect::StraightnessHigherOrder { axis, toward, degree } => {
                format!("straightness of {axis} in {toward}, degree {degree}")
            }
            Effect::AngularError { axis, about } => {
                format!("angular error of {axis} about {about} (Abbe)")
            }
            Effect::BarLength => "bar-length error".into(),
            Effect::BarLengthDrift => "bar length drift (each run's own mean radius)".into(),
            Effect::Backlash { axis } => format!("backlash of {axis}"),
            Effect::ServoMismatch { plane } => {
                format!("servo mismatch {plane} (independent plane term)")
            }
            Effect::RotaryPositioning { axis, harmonic } => {
                format!("angular positioning error of {axis}, {harmonic} per revolution")
            }
            Effect::RotaryRunout { axis, direction, harmonic } => {
                format!("run-out of {axis} along {direction}, {harmonic} per revolution")
            }
            Effect::RotaryWobble { axis, about, harmonic } => {
                format!("wobble of {axis} about {about}, {harmonic} per revolution")
            }
            Effect::RotaryLag { axis } => format!("servo lag of {axis}"),
        }
    }

    /// The columns the effect adds.
    pub fn parts(&self) -> Vec<EffectPart> {
        match self {
            Effect::ReversalSpike { axis, tau_ms } => {
                vec![EffectPart::Terms(TermSpec::ReversalSpike { axis: *axis, tau_ms: *tau_ms })]
            }
            Effect::ReversalTransient { axis, tau_ms, period_ms, per_side } => {
                vec![EffectPart::Terms(TermSpec::ReversalTransient {
                    axis: *axis,
                    tau_ms: *tau_ms,
                    period_ms: *period_ms,
                    per_side: *per_side,
                })]
            }
            Effect::LateralPlay { axis, switched_by } => {
                vec![EffectPart::Terms(TermSpec::LateralPlay {
                    axis: *axis,
                    switched_by: *switched_by,
                })]
            }
            Effect::CyclicError { axis, pitch_mm } => {
                vec![EffectPart::Terms(TermSpec::Cyclic { axis: *axis, pitch_mm: *pitch_mm })]
            }
            Effect::Vibration { axis, frequency_hz } => {
                vec![EffectPart::PerRun(TermSpec::Vibration {
                    axis: *axis,
                    frequency_hz: *frequency_hz,
                })]
            }
            Effect::ThermalDrift { axis: Some(a) } => {
                vec![EffectPart::Terms(TermSpec::Drift { axis: *a })]
            }
            Effect::ThermalDrift { axis: None } => {
                vec![EffectPart::Reading(ReadingTerm::BarGrowth)]
            }
            Effect::ThermalGrowth { axis, time_constant_min } => {
                vec![EffectPart::Terms(TermSpec::ThermalGrowth {
                    axis: *axis,
                    time_constant_min: *time_constant_min,
                })]
            }
            Effect::FeedScaled { effect, exponent, reference_mm_per_min } => effect
                .parts()
                .into_iter()
                .map(|p| {
                    let scale = |t: TermSpec| TermSpec::FeedScaled {
                        term: Box::new(t),
                        exponent: *exponent,
                        reference_mm_per_min: *reference_mm_per_min,
                    };
                    match p {
                        EffectPart::Terms(t) => EffectPart::Terms(scale(t)),
                        EffectPart::PerRun(t) => EffectPart::PerRun(scale(t)),
                        // A reading term has no joint state to scale by: left as it is (the
                        // library scales chain terms only).
                        EffectPart::Reading(r) => EffectPart::Reading(r),
                        EffectPart::PerRunReading(r) => EffectPart::PerRunReading(r),
                    }
                })
                .collect(),
            Effect::StickSlip { axis, speed_mm_per_min } => {
                vec![EffectPart::Terms(TermSpec::StickSlip {
                    axis: *axis,
                    speed_mm_per_min: *speed_mm_per_min,
                })]
            }
            Effect::ServoRadiusLoss => vec![EffectPart::Reading(ReadingTerm::RadiusLoss)],
            Effect::PositionalHigherOrder { axis, degree } => {
                vec![EffectPart::Terms(TermSpec::Positional {
                    axis: *axis,
                    degrees: vec![*degree],
                })]
            }
            Effect::StraightnessHigherOrder { axis, toward, degree } => {
                vec![EffectPart::Terms(TermSpec::Straightness {
                    axis: *axis,
                    toward: *toward,
                    degrees: vec![*degree],
                    tie_angles: true,
                })]
            }
            Effect::AngularError { axis, about } => vec![EffectPart::Terms(TermSpec::Angular {
                axis: *axis,
                about: *about,
                degrees: vec![1],
            })],
            Effect::BarLength => vec![EffectPart::Reading(ReadingTerm::BarLength)],
            Effect::BarLengthDrift => vec![EffectPart::PerRunReading(ReadingTerm::BarLength)],
            Effect::Backlash { axis } => {
                vec![EffectPart::Terms(TermSpec::Backlash { axis: *axis })]
            }
            Effect::ServoMismatch { plane } => {
                vec![EffectPart::Reading(ReadingTerm::PlaneMismatch(*plane))]
            }
            Effect::RotaryPositioning { axis, harmonic } => {
                vec![EffectPart::Terms(TermSpec::RotaryPositioning {
                    axis: *axis,
                    harmonics: vec![*harmonic],
                })]
            }
            Effect::RotaryRunout { axis, direction, harmonic } => {
                vec![EffectPart::Terms(TermSpec::RotaryRunout {
                    axis: *axis,
                    direction: *direction,
                    harmonics: vec![*harmonic],
                })]
            }
            Effect::RotaryWobble { axis, about, harmonic } => {
                vec![EffectPart::Terms(TermSpec::RotaryWobble {
                    axis: *axis,
                    about: *about,
                    harmonics: vec![*harmonic],
                })]
            }
            Effect::RotaryLag { axis } => {
                vec![EffectPart::Terms(TermSpec::ServoLag { axis: *axis })]
            }
        }
    }

    /// The effect's reported parameters from its fitted coefficients (internal units, in the
    /// order of its columns; for a per-run effect, run after run: `a_1, b_1, a_2, b_2, …`).
    pub fn report(&self, coeffs: &[f64]) -> Reported {
        let um = |x: f64| x * 1e3;
        let c0 = coeffs.first().copied().unwrap_or(0.0);
        match self {
            Effect::ReversalSpike { tau_ms, .. } => {
                vec![("amplitude_um".into(), um(c0)), ("tau_ms".into(), *tau_ms)]
            }
            Effect::ReversalTransient { tau_ms, period_ms, per_side, .. } => {
                // Per side (or for both): the height of the fitted transient at its peak.
                let side = |k: usize| {
                    let a: Vec<f64> =
                        (0..3).map(|p| coeffs.get(3 * k + p).copied().unwrap_or(0.0)).collect();
                    transient_peak(*tau_ms, *period_ms, [a[0], a[1], a[2]])
                };
                let mut out = Vec::new();
                // With a height per side, `amplitude_um` is the larger one's (the spike's size
                // as one number, cli.md's field).
                let (larger, sides) = if *per_side {
                    let (p, n) = (side(0), side(1));
                    (if p.0.abs() >= n.0.abs() { p } else { n }, Some((p.0, n.0)))
                } else {
                    (side(0), None)
                };
                out.push(("amplitude_um".into(), um(larger.0)));
                if let Some((p, n)) = sides {
                    out.push(("amplitude_pos_um".into(), um(p)));
                    out.push(("amplitude_neg_um".into(), um(n)));
                }
                let at = larger.1;
                out.push(("tau_ms".into(), *tau_ms));
                if let Some(p) = period_ms {
                    out.push(("period_ms".into(), *p));
                }
                // The time from the reversal to the peak (of the larger side).
                out.push(("peak_ms".into(), at));
                out
            }
            Effect::LateralPlay { .. } => vec![("play_um".into(), um(c0))],
            Effect::CyclicError { pitch_mm, .. } => {
                let (a, b) = (c0, coeffs.get(1).copied().unwrap_or(0.0));
                // a sin x + b cos x = A sin(x + φ): A = hypot(a, b), φ = atan2(b, a).
                vec![
                    ("amplitude_um".into(), um(a.hypot(b))),
                    ("phase_deg".into(), b.atan2(a).to_degrees()),
                    ("pitch_mm".into(), *pitch_mm),
                ]
            }
            Effect::Vibration { frequency_hz, .. } => {
                // The RMS over runs of each run's amplitude hypot(a_k, b_k). Noise adds its
                // variance: E[a² + b²] = A² + u_a² + u_b², a bias of u²/A, below 0.1 % for a
                // micrometre vibration fitted on a run of thousands of samples.
                let runs = coeffs.len() / 2;
                let ms = coeffs.chunks_exact(2).map(|c| c[0] * c[0] + c[1] * c[1]).sum::<f64>()
                    / runs.max(1) as f64;
                vec![("amplitude_um".into(), um(ms.sqrt())), ("frequency_hz".into(), *frequency_hz)]
            }
            Effect::ThermalDrift { .. } => vec![("rate_um_per_h".into(), c0 * 1e3 * 3600.0)],
            Effect::BarLengthDrift => {
                // The runs' offsets about their mean: the mean itself is a common scale of the
                // axes at one radius (or the session's bar length), which the base holds.
                let n = coeffs.len().max(1) as f64;
                let mean = coeffs.iter().sum::<f64>() / n;
                let spread = (coeffs.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / n).sqrt();
                let (lo, hi) = coeffs
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &c| (a.min(c), b.max(c)));
                vec![
                    ("spread_um".into(), um(spread)),
                    ("range_um".into(), if coeffs.is_empty() { 0.0 } else { um(hi - lo) }),
                ]
            }
            Effect::ThermalGrowth { time_constant_min: None, .. } => {
                vec![("rate_ppm_per_h".into(), c0 * 1e6 * 3600.0)]
            }
            Effect::ThermalGrowth { time_constant_min: Some(t), .. } => {
                vec![("growth_ppm".into(), c0 * 1e6), ("time_constant_min".into(), *t)]
            }
            Effect::FeedScaled { effect, exponent, reference_mm_per_min } => {
                let mut out = effect.report(coeffs);
                out.push(("feed_exponent".into(), *exponent));
                out.push(("reference_feed_mm_per_min".into(), *reference_mm_per_min));
                out
            }
            Effect::StickSlip { speed_mm_per_min, .. } => vec![
                ("amplitude_um".into(), um(c0)),
                ("speed_mm_per_min".into(), *speed_mm_per_min),
            ],
            Effect::ServoRadiusLoss => vec![
                ("common_lag_ms".into(), c0.max(0.0).sqrt() * 1e3),
                ("lag_squared_ms2".into(), c0 * 1e6),
            ],
            // A rotary axis's backlash is an angle.
            Effect::Backlash { axis } if axis.is_rotary() => vec![("value_urad".into(), c0 * 1e6)],
            Effect::PositionalHigherOrder { .. }
            | Effect::StraightnessHigherOrder { .. }
            | Effect::BarLength
            | Effect::Backlash { .. }
            | Effect::ServoMismatch { .. } => {
                vec![("value_um".into(), um(c0))]
            }
            Effect::AngularError { .. } => vec![("value_urad".into(), c0 * 1e6)],
            Effect::RotaryLag { .. } => vec![("lag_ms".into(), c0 * 1e3)],
            // `a sin nq + b cos nq` = A sin(nq + φ): the amplitude and the phase.
            Effect::RotaryPositioning { .. }
            | Effect::RotaryWobble { .. }
            | Effect::RotaryRunout { .. } => {
                let (a, b) = (c0, coeffs.get(1).copied().unwrap_or(0.0));
                let amplitude = a.hypot(b);
                let phase_deg = b.atan2(a).to_degrees();
                let amp = if matches!(self, Effect::RotaryRunout { .. }) {
                    ("amplitude_um".to_string(), um(amplitude))
                } else {
                    ("amplitude_urad".to_string(), amplitude * 1e6)
                };
                vec![amp, ("phase_deg".into(), phase_deg)]
            }
        }
    }

    /// The reported parameters that are linear in the effect's coefficients once its shape is
    /// fitted: each with its weights over the coefficients (`coeffs` as in [`Effect::report`];
    /// display units), so that a fit's covariance gives their standard uncertainty. A spike's
    /// height per side is `Σ_k a_k h_k(t*)`, its parts at the fitted peak `t*` (the peak time
    /// itself moves with the coefficients; to first order the height does not, as `h` is flat
    /// there). Empty for the other effects (their reported values are coefficients, whose
    /// uncertainties the fit gives directly, or not linear).
    pub fn linear_parameters(&self, coeffs: &[f64]) -> Vec<(String, Vec<f64>)> {
        use crate::term::{TransientPart, transient};
        if let Effect::FeedScaled { effect, .. } = self {
            return effect.linear_parameters(coeffs);
        }
        let Effect::ReversalTransient { tau_ms, period_ms, per_side, .. } = self else {
            return vec![];
        };
        let omega = period_ms.map(|p| std::f64::consts::TAU / (p * 1e-3)).unwrap_or(0.0);
        // Per side: its height, and the weights that make it.
        let sides: Vec<(f64, Vec<f64>)> = (0..if *per_side { 2 } else { 1 })
            .map(|k| {
                let a: Vec<f64> =
                    (0..3).map(|p| coeffs.get(3 * k + p).copied().unwrap_or(0.0)).collect();
                let (h, t_ms) = transient_peak(*tau_ms, *period_ms, [a[0], a[1], a[2]]);
                let mut w = vec![0.0; coeffs.len()];
                for (p, part) in TransientPart::ALL.into_iter().enumerate() {
                    if let Some(x) = w.get_mut(3 * k + p) {
                        *x = 1e3 * transient(t_ms * 1e-3, tau_ms * 1e-3, omega, part);
                    }
                }
                (h, w)
            })
            .collect();
        // `amplitude_um`: the larger side's (as `report` says).
        let larger = if sides.len() == 2 && sides[1].0.abs() > sides[0].0.abs() { 1 } else { 0 };
        let mut out = vec![("amplitude_um".to_string(), sides[larger].1.clone())];
        if *per_side {
            out.push(("amplitude_pos_um".into(), sides[0].1.clone()));
            out.push(("amplitude_neg_um".into(), sides[1].1.clone()));
        }
        out
    }

    /// A typical size of the effect's coefficient(s) on a machine worth measuring, internal
    /// units (domain brief §4: spikes 2-15 µm, cyclic 0.5-3 µm, backlash 1-10 µm, squareness
    /// 5-50 µrad, servo mismatch 0.1-2 ms; the lower ends, so that "aliased" means that even an
    /// effect of ordinary size would not show). It decides only what is called aliased: an
    /// effect whose size the data determine is fitted and judged at that size.
    pub fn typical_size(&self) -> f64 {
        match self {
            Effect::ReversalSpike { .. } | Effect::ReversalTransient { .. } => 2e-3,
            // 10 µrad of a rotary axis (ISO 230-2 tables: a few arc-seconds).
            Effect::Backlash { axis } if axis.is_rotary() => 10e-6,
            Effect::LateralPlay { .. } | Effect::Backlash { .. } => 1e-3,
            // Rotary tables of a machine in service: positioning and wobble harmonics of a few
            // arc-seconds (5 µrad = 1 arc-second), run-out of a micrometre.
            Effect::RotaryPositioning { .. } | Effect::RotaryWobble { .. } => 5e-6,
            Effect::RotaryRunout { .. } => 1e-3,
            // 1 ms, as the linear axes' residual lag with feed-forward.
            Effect::RotaryLag { .. } => 1e-3,
            Effect::CyclicError { .. } | Effect::Vibration { .. } => 0.5e-3,
            // 2 µm/h, in mm/s.
            Effect::ThermalDrift { .. } => 2e-3 / 3600.0,
            Effect::StickSlip { .. } => 1e-3,
            // 2 ppm/h (a warming screw: 5-20 ppm over an hour or two), in 1/s; 5 ppm.
            Effect::ThermalGrowth { time_constant_min: None, .. } => 2e-6 / 3600.0,
            Effect::ThermalGrowth { .. } => 5e-6,
            Effect::FeedScaled { effect, .. } => effect.typical_size(),
            // A common lag of 1 ms: τ² = 1e-6 s².
            Effect::ServoRadiusLoss => 1e-6,
            Effect::PositionalHigherOrder { .. } | Effect::StraightnessHigherOrder { .. } => 1e-3,
            Effect::AngularError { .. } => 5e-6,
            Effect::BarLength | Effect::ServoMismatch { .. } => 1e-3,
            // A bar's length follows its temperature: 1 K is 1.2 µm on 100 mm of steel, so a
            // few tenths of a µm between runs as the shop's air swings.
            Effect::BarLengthDrift => 0.2e-3,
        }
    }

    /// Which extra test would separate the effect from the base model when it is aliased.
    pub fn separating_test(&self) -> &'static str {
        match self {
            Effect::AngularError { .. } => {
                "a second tool length or ball height (the Abbe arm changes, squareness and straightness do not)"
            }
            Effect::PositionalHigherOrder { .. } | Effect::StraightnessHigherOrder { .. } => {
                "circles at offset centres or another radius"
            }
            Effect::ServoRadiusLoss => {
                "runs at two feeds (the loss grows with the feed squared, bar length and scale do not)"
            }
            Effect::BarLength => "a second radius or a calibrated bar",
            Effect::BarLengthDrift => {
                "the bar re-measured in its calibrator between runs (the machine's radius changes do not move it), or runs whose radius a law of the machine predicts (a growth in time, a loss with the feed): a constant per run predicts none"
            }
            Effect::ThermalDrift { .. } => {
                "longer runs (a drift shows as the start and end of a run not meeting), or runs that share one set-up of the table ball"
            }
            Effect::ServoMismatch { .. } => "runs at two feeds",
            Effect::ThermalGrowth { .. } => {
                "runs spread over the warm-up, each plane of the axis repeated at its start and end (the growth changes the axis's scale between them, an error of the bar changes every plane)"
            }
            Effect::FeedScaled { effect, .. } => effect.separating_test(),
            Effect::CyclicError { .. }
            | Effect::ReversalSpike { .. }
            | Effect::ReversalTransient { .. }
            | Effect::StickSlip { .. } => "runs at two feeds",
            Effect::Vibration { .. } => {
                "runs at two feeds (a vibration keeps its frequency in Hz, a ripple locked to position or angle scales with the feed)"
            }
            Effect::LateralPlay { .. } | Effect::Backlash { .. } => {
                "both directions in every plane"
            }
            Effect::RotaryPositioning { .. } => {
                "a tangential run of the axis over a full turn (a radial bar does not see its angle)"
            }
            Effect::RotaryRunout { .. } | Effect::RotaryWobble { .. } => {
                "radial and axial runs of the axis at two ball heights"
            }
            Effect::RotaryLag { .. } => {
                "none at constant speed (the lag holds the axis a constant angle behind, a re-seated ball): a sweep that starts or reverses within the run shows it"
            }
        }
    }
}

/// The peak of a reversal transient `Σ_k a_k h_k` ([`crate::term::transient`]): its value of
/// largest magnitude after the reversal (signed, the coefficients' unit) and the time from the
/// reversal to it, ms. Searched on a grid of 1/3200 of 8τ (or of two periods of the ringing,
/// if longer), then refined by a parabola: far inside a sample of any real trace.
pub fn transient_peak(tau_ms: f64, period_ms: Option<f64>, a: [f64; 3]) -> (f64, f64) {
    use crate::term::{TransientPart, transient};
    let tau = tau_ms * 1e-3;
    let omega = period_ms.map(|p| std::f64::consts::TAU / (p * 1e-3)).unwrap_or(0.0);
    let h = |t: f64| {
        TransientPart::ALL.iter().zip(a).map(|(&p, c)| c * transient(t, tau, omega, p)).sum::<f64>()
    };
    let span = (8.0 * tau).max(period_ms.map(|p| 2e-3 * p).unwrap_or(0.0));
    let n = 3200;
    let dt = span / n as f64;
    let (mut best, mut at) = (0, h(0.0).abs());
    for i in 1..=n {
        let v = h(i as f64 * dt).abs();
        if v > at {
            (best, at) = (i, v);
        }
    }
    let mut t = best as f64 * dt;
    if best > 0 && best < n {
        let (l, c, r) = (h(t - dt).abs(), h(t).abs(), h(t + dt).abs());
        let den = l - 2.0 * c + r;
        if den < 0.0 {
            t += (0.5 * (l - r) / den).clamp(-0.5, 0.5) * dt;
        }
    }
    (h(t), t * 1e3)
}

#[cfg(test)]
mod tests {
    use super::transient_peak;

    #[test]
    fn a_transients_peak_is_found_where_the_formulas_put_it() {
        // Without ringing: x e^{-x} peaks at t = τ (1/e), x² e^{-x} at 2τ (4/e²).
        let (h, t) = transient_peak(40.0, None, [0.0, 1.0, 0.0]);
        assert!((h - (-1.0f64).exp()).abs() < 1e-9 && (t - 40.0).abs() < 0.01, "{h} {t}");
        let (h, t) = transient_peak(40.0, None, [0.0, 0.0, 2.0]);
        assert!((h - 8.0 * (-2.0f64).exp()).abs() < 1e-9 && (t - 80.0).abs() < 0.01, "{h} {t}");
        // A decay from the reversal: its start; signed.
        let (h, t) = transient_peak(40.0, Some(100.0), [-2.0, 0.0, 0.0]);
        assert!((h + 2.0).abs() < 1e-12 && t == 0.0, "{h} {t}");
    }
}

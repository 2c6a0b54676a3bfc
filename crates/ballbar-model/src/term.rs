//! Error terms: one unknown coefficient each, times a basis function of a joint's state.
//!
//! An error term attached to joint `j` says that the joint's error motion (module
//! [`crate::chain`]) is `e_j = θ · b(state)`, with `θ` the unknown coefficient and `b` a 6-vector
//! `(δx, δy, δz, εx, εy, εz)` in the joint frame. A machine's error model is a list of such terms;
//! several terms on one joint add up. Everything stays linear in the coefficients, so every
//! sample of every run gives one row of the design matrix.
//!
//! # The built-in terms and their signs
//! With `s = (q - q_ref)/L` the normalised absolute axis position (`q_ref`, `L` fixed per axis by
//! the machine, not by the test), `a` the joint's direction and `e_k` the error direction:
//! - positional `EXX1`: `δ_X = θ s` (θ in mm: the error at distance `L` from `q_ref`);
//! - straightness `EYX2`: `δ_Y = θ s²`, with the rigid-guideway angle tied to it,
//!   `ε = (a × e_Y) ∂δ_Y/∂q`, so `ε_Z(X) = +∂δ_Y/∂X`, `ε_Y(X) = -∂δ_Z/∂X`,
//!   `ε_Z(Y) = -∂δ_X/∂Y`, `ε_X(Y) = +∂δ_Z/∂Y`, `ε_Y(Z) = +∂δ_X/∂Z`, `ε_X(Z) = -∂δ_Y/∂Z`;
//! - squareness (the paper's definitions, θ in rad): `SQXY`: `δ_Y = -θ (X - X_ref)` on X;
//!   `SQZX`: `δ_X = -θ (Z - Z_ref)` on Z; `SQYZ`: `δ_Y = -θ (Z - Z_ref)` on Z;
//! - backlash `BX`: `δ_X = -(θ/2) sign(dX/dt)` (θ in mm), the direction of the lagging axis:
//!   [`JointState::direction`] switches at its lagged reversal, a switch lag τ after the
//!   commanded one (`Design::with_switch_lags`; `ballbar_fit::switch` takes τ from the fit),
//!   and so does the clock of the reversal transients below ([`JointState::since_reversal_s`]);
//! - servo lag `TX`: `δ_X = -θ dX/dt` (θ in s: the axis lags its command by θ);
//! - angular error motion `ECX1` (yaw of X; `EAX`, `EBX` roll and pitch): `ε_Z = θ s` (θ in
//!   rad), not tied to a straightness;
//! - rotary-axis location errors (ISO 230-7) `EX0C`, `EY0C` (mm), `EA0C`, `EB0C`, `EC0C` (rad):
//!   the displacement and tilt of the axis average line, and the zero-position error, stated
//!   *physically* as ISO 230-7 states them (the motion of the axis line in the parent frame,
//!   whichever branch carries it). In the joint frame the basis is `σ Rᵀ(σq) m`: the chain's
//!   tool-relative-to-workpiece sign `σ`, turned back by the joint's own rotation, since the
//!   axis line does not turn with the axis;
//! - rotary-axis error motions (ISO 230-7, ISO 230-1 names `E<d><k>`), each one harmonic
//!   `h(q) = sin(nq)` (`_S<n>`) or `cos(nq)` (`_C<n>`) of the axis angle `q` (rad, n ≥ 1):
//!   - radial and axial run-out `EXC_S1`, `EYC_C2`, `EZC_S1` (mm) and tilt error motion
//!     (wobble) `EAC_S1`, `EBC_C1` (rad): stated *physically*, as the location errors are, as
//!     the motion `m h(q)` of the body the axis carries relative to its nominal pose, in the
//!     parent frame (not turning with the axis), tilts about the joint's origin: in the joint
//!     frame `σ Rᵀ(σq) m h(q)`. `+EXC` moves a C table (or a C head) by +X whichever branch
//!     carries it;
//!   - angular positioning error `ECC_S1`, `ECC_C1` (rad): an error of the axis coordinate,
//!     `ε_C(q) = Σ a_n sin nq + b_n cos nq`, the actual angle minus the commanded one (ISO
//!     230-2), in the sense of the coordinate (ISO 841: tool relative to workpiece), as the
//!     linear axes' positional errors are: the body turns as if the axis read `q + ε`, so a
//!     table physically turns by `-ε` (unlike the zero error `EC0C`, stated physically);
//! - rotary backlash `BC`: `ε_C = -(θ/2) sign(dC/dt)` (θ in rad) and rotary servo lag `TC`:
//!   `ε_C = -θ dC/dt` (θ in s), about the joint's own line, in the coordinate's sense as the
//!   linear axes' backlash and lag;
//! - reversal transient `SPX0`, `SPX1`, `SPX2` (per side `SPXP0`.. and `SPXN0`..):
//!   `δ_X = -θ s h_k(t - t_r)` after each reversal at `t_r` (of that side: `P` the reversal at
//!   the positive end, where the motion turns + → −, `N` at the negative end), `s` the
//!   direction after it, `h_k` part `k` of a damped transient ([`transient`]); θ > 0 is
//!   outward at both ends (θ in mm);
//! - thermal growth `TGX` (effect): `δ_X = θ g(t) X`, `t` the session time (since the first
//!   run's start), `g = t` (θ a scale per second, shown in ppm/h) or `g = 1 - e^{-t/τ}` (θ the
//!   scale it saturates at, shown in ppm); θ > 0: the axis grows (moves further than commanded
//!   away from its origin). About a fixed point `X_b` instead, the difference `-θ g(t) X_b` is an
//!   offset that each run's centring takes but for its change within the run (for a linear
//!   growth, the offset drift `DX`): circles hardly see where the fixed bearing is;
//! - a term scaled by the feed (`FeedScaled`): the inner term's basis times `(F/F_ref)^p`, `F`
//!   the run's programmed feed;
//! - constant `Constant`: `e = θ b` for a fixed 6-vector `b`;
//! - plugin kernels: the basis comes from a compiled plugin ([`BasisKernel`]).

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::chain::ErrorMotion;

/// The state of one joint at one sample, in internal units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JointState {
    /// Axis coordinate: mm (linear) or rad (rotary).
    pub q: f64,
    /// Axis velocity: mm/s or rad/s.
    pub velocity: f64,
    /// Direction of motion: +1, -1, or 0 at rest / at a reversal. In a design, the lagging
    /// axis's: it switches a switch lag after the commanded reversal (0 by default).
    pub direction: f64,
    /// Time since the start of the run, s.
    pub t_s: f64,
    /// Programmed path feed, mm/s.
    pub feed_mm_per_s: f64,
    /// Time since this axis last reversed within the run, s (∞ before its first reversal); in
    /// a design, since its lagged reversal, as [`JointState::direction`].
    pub since_reversal_s: f64,
    /// Time since the start of the session (the first run's start), s.
    pub session_t_s: f64,
}

impl Default for JointState {
    fn default() -> JointState {
        JointState {
            q: 0.0,
            velocity: 0.0,
            direction: 0.0,
            t_s: 0.0,
            feed_mm_per_s: 0.0,
            since_reversal_s: f64::INFINITY,
            session_t_s: 0.0,
        }
    }
}

/// The physical dimension of a coefficient; inside in mm, rad, s.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Unit {
    /// Internal mm, shown in µm.
    Length,
    /// Internal rad, shown in µrad.
    Angle,
    /// Internal s, shown in ms.
    Time,
    /// Internal mm/s, shown in µm/h (drifts).
    Rate,
    /// Internal s², shown in ms² (the square of a lag).
    TimeSquared,
    /// Internal mm/mm (a scale), shown in ppm (µm/m): a thermal growth's size.
    Ratio,
    /// Internal 1/s (a scale per second), shown in ppm/h: a thermal growth's rate.
    RatioRate,
}

impl Unit {
    /// Factor from internal to display units.
    pub fn display_factor(self) -> f64 {
        match self {
            Unit::Length => 1e3,
            Unit::Angle => 1e6,
            Unit::Time => 1e3,
            Unit::Rate => 1e3 * 3600.0,
            Unit::TimeSquared => 1e6,
            Unit::Ratio => 1e6,
            Unit::RatioRate => 1e6 * 3600.0,
        }
    }

    /// Display unit name.
    pub fn display_name(self) -> &'static str {
        match self {
            Unit::Length => "µm",
            Unit::Angle => "µrad",
            Unit::Time => "ms",
            Unit::Rate => "µm/h",
            Unit::TimeSquared => "ms²",
            Unit::Ratio => "ppm",
            Unit::RatioRate => "ppm/h",
        }
    }
}

/// What kind of error a term models (for reports, identifiability hints and the simulator).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TermClass {
    /// Positional error along the axis.
    Positional,
    /// Straightness across the axis (with tied pitch/yaw).
    Straightness,
    /// Squareness between two linear axes.
    Squareness,
    /// Reversal lost motion.
    Backlash,
    /// Position-loop lag of an axis (the simulator realises it as a time-domain filter).
    ServoLag,
    /// Angular error motion of a linear axis (roll, pitch, yaw) not tied to a straightness.
    Angular,
    /// ISO 230-7 location error of a rotary axis.
    RotaryLocation,
    /// Error motion of a rotary axis as a harmonic of its angle: positioning, run-out, tilt
    /// (ISO 230-7).
    RotaryMotion,
    /// An effect of the diagnosis's library (spike, play, cyclic, drift, stick-slip).
    Effect,
    /// Anything else (constant location errors, plugin terms).
    Other,
}

/// One unknown coefficient times a 6-vector basis function of a joint's state.
pub trait ErrorTerm: Send + Sync + std::fmt::Debug {
    /// Short identifier, unique within a machine (`EYX2`).
    fn id(&self) -> &str;
    /// Human description.
    fn label(&self) -> &str;
    /// Dimension of the coefficient.
    fn unit(&self) -> Unit;
    /// What the term models.
    fn class(&self) -> TermClass;
    /// The error motion per unit coefficient at each of `states`, into `out` (as long as
    /// `states`). Built-in terms evaluate the batch in one tight loop; a plugin kernel crosses
    /// the plugin boundary once per batch, and its failure is an error, not a crash.
    fn basis_batch(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), TermError>;

    /// For a term whose error motion has one component only (a built-in term's along its
    /// direction): that component at each of `states` into `out` (as long as `states`), the
    /// same numbers as [`ErrorTerm::basis_batch`]'s, and its index (0-2 translation, 3-5
    /// rotation). `None` (the default) for any other term: the caller uses `basis_batch`.
    /// A design fills a column from it without writing and reading five zeros per sample.
    fn component_batch(
        &self,
        _states: &[JointState],
        _out: &mut [f64],
    ) -> Option<Result<usize, TermError>> {
        None
    }

    /// The error motion per unit coefficient at one joint state.
    fn basis(&self, state: &JointState) -> Result<ErrorMotion, TermError> {
        let mut out = [[0.0; 6]];
        self.basis_batch(std::slice::from_ref(state), &mut out)?;
        Ok(out[0])
    }
}

/// An error term could not be evaluated (a plugin kernel failed).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("error term {term}: {message}")]
pub struct TermError {
    /// The term's id.
    pub term: String,
    /// What went wrong.
    pub message: String,
}

/// The shapes of the built-in terms (module docs give the formulas).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Shape {
    /// `δ_dir = s^power`, `s = (q - reference)/length`; with `tie`, the rotation
    /// `ε = tie · d(s^power)/dq` where `tie = a × e_dir`.
    Polynomial {
        /// Error direction 0, 1, 2 (x, y, z of the joint frame).
        dir: usize,
        /// Polynomial degree, ≥ 1.
        power: u32,
        /// `q_ref`, mm.
        reference: f64,
        /// `L`, mm.
        length: f64,
        /// Tied rotation axis `a × e_dir`, if pitch/yaw follow the straightness.
        tie: Option<[f64; 3]>,
    },
    /// `δ_dir = -(q - reference)`: squareness, coefficient in rad.
    Squareness {
        /// Error direction.
        dir: usize,
        /// `q_ref`, mm.
        reference: f64,
    },
    /// `δ_dir = -sign(dq/dt)/2`: backlash, coefficient in mm.
    Backlash {
        /// Error direction (the axis's own).
        dir: usize,
    },
    /// `δ_dir = -dq/dt`: servo lag, coefficient in s.
    ServoLag {
        /// Error direction (the axis's own).
        dir: usize,
    },
    /// A constant error motion per unit coefficient.
    Constant {
        /// The 6-vector.
        motion: ErrorMotion,
    },
    /// `δ_dir = -sign(dq/dt) e^{-(t - t_r)/τ}` after the axis's last reversal at `t_r`.
    ReversalSpike {
        /// Error direction (the axis's own).
        dir: usize,
        /// Decay time τ, s.
        tau_s: f64,
    },
    /// `δ_dir = -s · [side] · h(t - t_r)` after the axis's last reversal at `t_r`, `s` the
    /// direction after it and `h` one part of a damped transient ([`transient`]).
    ReversalTransient {
        /// Error direction (the axis's own).
        dir: usize,
        /// Decay time τ, s.
        tau_s: f64,
        /// Angular frequency ω of the ringing, rad/s (0: none).
        omega: f64,
        /// Which part of the transient.
        part: TransientPart,
        /// Which reversals it follows.
        side: ReversalSide,
    },
    /// `δ_dir = sin(2π x/λ)` (or cos), `x` the axis position (mm) or the run time (s).
    Periodic {
        /// Error direction.
        dir: usize,
        /// λ: pitch (mm) or period (s).
        wavelength: f64,
        /// Cosine instead of sine.
        cosine: bool,
        /// What `x` is.
        of: Periodic,
    },
    /// `δ_dir = t_session`.
    Drift {
        /// Error direction.
        dir: usize,
    },
    /// `δ_dir = g(t_session) q`: the axis's scale growing with session time, about the axis
    /// origin (`g = t` with no time constant, else `g = 1 - e^{-t/τ}`).
    Growth {
        /// Error direction.
        dir: usize,
        /// τ, s (`None`: linear growth).
        tau_s: Option<f64>,
    },
    /// `δ_dir = -sign(dq/dt) max(0, 1 - |dq/dt|/v_c)`.
    StickSlip {
        /// Error direction.
        dir: usize,
        /// `v_c`, mm/s.
        speed: f64,
    },
    /// A rotary axis's location error: the constant motion `motion` of the axis line in the
    /// parent frame (about the joint's origin), seen in the joint frame after the nominal
    /// motion: `sign · (Rᵀ(direction, sign · q) · m − m)` for the offsets and tilts (the line
    /// moves, the body is nominal at the axis's zero), `sign · m` for the zero error (the
    /// rotation about the axis's own line: the body turned at every position).
    RotaryLocation {
        /// The 6-vector in the parent frame (physical sense).
        motion: ErrorMotion,
        /// Unit rotation axis of the joint.
        direction: [f64; 3],
        /// The branch sign σ.
        sign: f64,
    },
    /// A rotary axis's error motion, one harmonic of its angle: the motion `motion` of the
    /// body the axis carries relative to its nominal pose, in the parent frame about the
    /// joint's origin (physical sense), times `h(q) = sin(order · q)` (or cos), seen in the
    /// joint frame after the nominal motion: `sign · Rᵀ(direction, sign · q) · motion · h(q)`.
    /// A positioning error (a rotation about the axis's own line, in the coordinate's sense)
    /// is the physical rotation `sign · direction`.
    RotaryHarmonic {
        /// The 6-vector in the parent frame (physical sense), per unit coefficient.
        motion: ErrorMotion,
        /// Unit rotation axis of the joint.
        direction: [f64; 3],
        /// The branch sign σ.
        sign: f64,
        /// The harmonic's order n ≥ 1.
        order: u32,
        /// Cosine instead of sine.
        cosine: bool,
    },
    /// `ε = -sign(dq/dt)/2` about the joint's own line: a rotary axis's backlash, coefficient in
    /// rad (the coordinate's sense).
    RotaryBacklash {
        /// Unit rotation axis of the joint.
        direction: [f64; 3],
    },
    /// `ε = -dq/dt` about the joint's own line: a rotary axis's servo lag, coefficient in s
    /// (the coordinate's sense).
    RotaryServoLag {
        /// Unit rotation axis of the joint.
        direction: [f64; 3],
    },
}

/// One part of a reversal transient, per unit coefficient, `t` the time since the reversal,
/// `x = t/τ`, `φ = ωt`, `k = ωτ` ([`transient`]). The three span the free response of a
/// servo loop of third order (a PID-controlled axis, or a PI loop with a drive's own lag)
/// whose three modes decay alike: `e^{-x}`, `e^{-x} cos φ`, `e^{-x} sin φ`; a friction step at
/// the reversal excites them so that the spike rises from zero over a finite time, peaks, and
/// rings when `ω > 0`. The parts are chosen so that they stay apart as `ω → 0` (no ringing),
/// where they become `e^{-x}`, `x e^{-x}`, `x² e^{-x}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum TransientPart {
    /// `e^{-x}`: the part that starts at its full height.
    Decay,
    /// `e^{-x} sin(φ)/k` (`x e^{-x}` at ω = 0): starts at zero, rising linearly.
    Sine,
    /// `e^{-x} 2(1 - cos φ)/k²` (`x² e^{-x}` at ω = 0): starts at zero with zero slope.
    Versine,
}

impl TransientPart {
    /// The three parts, in the order of a transient's coefficients.
    pub const ALL: [TransientPart; 3] =
        [TransientPart::Decay, TransientPart::Sine, TransientPart::Versine];
}

/// The reversals of an axis a transient follows. A reversal is named by the end of the
/// axis's travel where it happens, which is also the turn of its motion there: at the positive
/// end the axis turns from moving + to moving −, at the negative end from − to +. The term
/// reads the turn (the direction after the reversal), which needs no circle centre.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
pub enum ReversalSide {
    /// Every reversal.
    #[default]
    Both,
    /// The reversal at the positive end (motion + → −; X at θ = 0° of a circle).
    Positive,
    /// The reversal at the negative end (motion − → +; X at θ = 180°).
    Negative,
}

impl ReversalSide {
    /// 1 when a sample whose direction of motion (after the reversal) is `direction` follows a
    /// reversal of this side, else 0.
    #[inline]
    pub fn gate(self, direction: f64) -> f64 {
        match self {
            ReversalSide::Both => 1.0,
            ReversalSide::Positive => f64::from(u8::from(direction < 0.0)),
            ReversalSide::Negative => f64::from(u8::from(direction > 0.0)),
        }
    }
}

/// A part of a reversal transient ([`TransientPart`]) at `t` s after the reversal, decay time
/// `tau_s`, ringing at `omega` rad/s (0: none); 0 for `t` < 0 or not finite (before the axis's
/// first reversal). Each part is continuous in `ω` down to 0.
#[inline]
pub fn transient(t: f64, tau_s: f64, omega: f64, part: TransientPart) -> f64 {
    if !(t >= 0.0 && t.is_finite()) {
        return 0.0;
    }
    let x = t / tau_s;
    if x > 60.0 {
        return 0.0;
    }
    let decay = (-x).exp();
    let phi = omega * t;
    let k = omega * tau_s;
    // Below φ = 1e-4 the series: sin φ/k = x (1 - φ²/6), 2(1 - cos φ)/k² = x² (1 - φ²/12),
    // both to 1e-17 relative.
    let small = phi.abs() < 1e-4;
    match part {
        TransientPart::Decay => decay,
        TransientPart::Sine => {
            decay * if small { x * (1.0 - phi * phi / 6.0) } else { phi.sin() / k }
        }
        TransientPart::Versine => {
            // 1 - cos φ = 2 sin²(φ/2), without the cancellation near φ = 0.
            decay
                * if small {
                    x * x * (1.0 - phi * phi / 12.0)
                } else {
                    4.0 * (0.5 * phi).sin().powi(2) / (k * k)
                }
        }
    }
}

/// The terms of a reversal transient of `axis` (error direction `dir` of its joint): its three
/// parts ([`TransientPart`], ids ending `0`, `1`, `2`) after every reversal (`SPX0`, `SPX1`,
/// `SPX2` for X), or after each side's reversals (`SPXP0`, `SPXP1`, `SPXP2` at the positive
/// end, `SPXN0`, ... at the negative end). `period_ms`: the ringing's period (`None`: none). An
/// error names what is wrong.
pub fn reversal_transient_terms(
    axis: crate::axis::Axis,
    dir: usize,
    tau_ms: f64,
    period_ms: Option<f64>,
    per_side: bool,
) -> Result<Vec<BuiltinTerm>, String> {
    if !(tau_ms > 0.0 && tau_ms.is_finite()) {
        return Err(format!("reversal transient of {axis}: tau_ms must be positive"));
    }
    if period_ms.is_some_and(|p| !(p > 0.0 && p.is_finite())) {
        return Err(format!(
            "reversal transient of {axis}: period_ms must be positive (or absent: no ringing)"
        ));
    }
    let omega = period_ms.map(|p| std::f64::consts::TAU / (p * 1e-3)).unwrap_or(0.0);
    let sides: &[(ReversalSide, &str, &str)] = if per_side {
        &[
            (ReversalSide::Positive, "P", " at the positive end"),
            (ReversalSide::Negative, "N", " at the negative end"),
        ]
    } else {
        &[(ReversalSide::Both, "", "")]
    };
    let ringing = period_ms.map(|p| format!(", ringing period {p:.1} ms")).unwrap_or_default();
    let mut out = Vec::new();
    for &(side, tag, where_) in sides {
        for (k, part) in TransientPart::ALL.into_iter().enumerate() {
            out.push(BuiltinTerm {
                id: format!("SP{axis}{tag}{k}"),
                label: format!(
                    "reversal transient of {axis}{where_}, part {k} (τ = {tau_ms:.1} ms{ringing})"
                ),
                unit: Unit::Length,
                class: TermClass::Effect,
                shape: Shape::ReversalTransient { dir, tau_s: tau_ms * 1e-3, omega, part, side },
            });
        }
    }
    Ok(out)
}

/// The variable of a periodic term.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Periodic {
    /// The absolute axis position, mm.
    Position,
    /// The time since the run's start, s.
    RunTime,
}

/// A built-in error term.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BuiltinTerm {
    /// Identifier.
    pub id: String,
    /// Description.
    pub label: String,
    /// Coefficient dimension.
    pub unit: Unit,
    /// Kind.
    pub class: TermClass,
    /// Basis function.
    pub shape: Shape,
}

impl BuiltinTerm {
    /// The one component of the shape's error motion, for a shape that has one (every shape
    /// along a direction: a polynomial without tied angles, squareness, backlash, lag, spikes
    /// and transients, periodic terms, drift, growth, stick-slip); `None` otherwise.
    fn single_component(&self) -> Option<usize> {
        match &self.shape {
            Shape::Polynomial { dir, tie: None, .. }
            | Shape::Squareness { dir, .. }
            | Shape::Backlash { dir }
            | Shape::ServoLag { dir }
            | Shape::ReversalSpike { dir, .. }
            | Shape::ReversalTransient { dir, .. }
            | Shape::Periodic { dir, .. }
            | Shape::Drift { dir }
            | Shape::Growth { dir, .. }
            | Shape::StickSlip { dir, .. } => Some(*dir),
            _ => None,
        }
    }

    /// `put(i, value)` of the one component at each of `states`, for a shape of
    /// [`BuiltinTerm::single_component`] (nothing for another): the one place these shapes'
    /// values are computed, so that [`ErrorTerm::basis_batch`] and
    /// [`ErrorTerm::component_batch`] give the same numbers.
    #[inline(always)]
    fn component_values(&self, states: &[JointState], mut put: impl FnMut(usize, f64)) {
        // One match per batch, a tight loop per shape.
        match &self.shape {
            Shape::Polynomial { power, reference, length, tie: None, .. } => {
                for (i, st) in states.iter().enumerate() {
                    let s = (st.q - reference) / length;
                    put(i, if *power == 0 { 1.0 } else { pow(s, *power - 1) * s });
                }
            }
            Shape::Squareness { reference, .. } => {
                for (i, st) in states.iter().enumerate() {
                    put(i, -(st.q - reference));
                }
            }
            Shape::Backlash { .. } => {
                for (i, st) in states.iter().enumerate() {
                    put(i, -0.5 * st.direction);
                }
            }
            Shape::ServoLag { .. } => {
                for (i, st) in states.iter().enumerate() {
                    put(i, -st.velocity);
                }
            }
            Shape::ReversalSpike { tau_s, .. } => {
                for (i, st) in states.iter().enumerate() {
                    // ∞ before the first reversal: e^{-∞} = 0.
                    put(i, -st.direction * (-st.since_reversal_s / tau_s).exp());
                }
            }
            Shape::ReversalTransient { tau_s, omega, part, side, .. } => {
                for (i, st) in states.iter().enumerate() {
                    // ∞ before the first reversal: nothing.
                    put(
                        i,
                        -st.direction
                            * side.gate(st.direction)
                            * transient(st.since_reversal_s, *tau_s, *omega, *part),
                    );
                }
            }
            Shape::Periodic { wavelength, cosine, of, .. } => {
                let k = std::f64::consts::TAU / wavelength;
                for (i, st) in states.iter().enumerate() {
                    let x = match of {
                        Periodic::Position => st.q,
                        Periodic::RunTime => st.t_s,
                    };
                    put(i, if *cosine { (k * x).cos() } else { (k * x).sin() });
                }
            }
            Shape::Drift { .. } => {
                for (i, st) in states.iter().enumerate() {
                    put(i, st.session_t_s);
                }
            }
            Shape::Growth { tau_s, .. } => {
                for (i, st) in states.iter().enumerate() {
                    let g = match tau_s {
                        None => st.session_t_s,
                        Some(tau) => -(-st.session_t_s / tau).exp_m1(),
                    };
                    put(i, g * st.q);
                }
            }
            Shape::StickSlip { speed, .. } => {
                for (i, st) in states.iter().enumerate() {
                    put(i, -st.direction * (1.0 - st.velocity.abs() / speed).max(0.0));
                }
            }
            _ => {}
        }
    }
}

impl ErrorTerm for BuiltinTerm {
    fn component_batch(
        &self,
        states: &[JointState],
        out: &mut [f64],
    ) -> Option<Result<usize, TermError>> {
        let dir = self.single_component()?;
        let n = out.len().min(states.len());
        self.component_values(&states[..n], |i, v| out[i] = v);
        Some(Ok(dir))
    }
    fn id(&self) -> &str {
        &self.id
    }
    fn label(&self) -> &str {
        &self.label
    }
    fn unit(&self) -> Unit {
        self.unit
    }
    fn class(&self) -> TermClass {
        self.class
    }
    fn basis_batch(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), TermError> {
        // A shape of one component: the values of `component_batch`, the same numbers.
        if let Some(dir) = self.single_component() {
            let n = out.len().min(states.len());
            self.component_values(&states[..n], |i, v| {
                let e = &mut out[i];
                *e = [0.0; 6];
                e[dir] = v;
            });
            return Ok(());
        }
        // One match per batch, a tight loop per shape.
        match &self.shape {
            Shape::Polynomial { dir, power, reference, length, tie } => {
                for (e, st) in out.iter_mut().zip(states) {
                    *e = [0.0; 6];
                    let s = (st.q - reference) / length;
                    // s^(p-1) serves the value and the tied derivative p s^(p-1) / L.
                    let lower = if *power == 0 { 0.0 } else { pow(s, *power - 1) };
                    e[*dir] = if *power == 0 { 1.0 } else { lower * s };
                    if let Some(t) = tie {
                        let ds = f64::from(*power) * lower / length;
                        e[3] = t[0] * ds;
                        e[4] = t[1] * ds;
                        e[5] = t[2] * ds;
                    }
                }
            }
            Shape::Constant { motion } => out.iter_mut().for_each(|e| *e = *motion),
            // The shapes of one component, evaluated above.
            Shape::Squareness { .. }
            | Shape::Backlash { .. }
            | Shape::ServoLag { .. }
            | Shape::ReversalSpike { .. }
            | Shape::ReversalTransient { .. }
            | Shape::Periodic { .. }
            | Shape::Drift { .. }
            | Shape::Growth { .. }
            | Shape::StickSlip { .. } => unreachable!("a shape of one component"),
            Shape::RotaryLocation { motion, direction, sign } => {
                let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::from(*direction));
                let t = nalgebra::Vector3::new(motion[0], motion[1], motion[2]);
                let r = nalgebra::Vector3::new(motion[3], motion[4], motion[5]);
                // The zero error (a rotation about the axis's own line) turns the carried body
                // by a constant angle at every position; the offsets and tilts move the line
                // about which it turns, the body staying where the nominal chain puts it at the
                // axis's zero: E(m) R(q) E(m)⁻¹, whose error after the nominal motion is
                // Rᵀ(q) m − m to first order.
                let own = axis.into_inner() * axis.dot(&r);
                let tilt = r - own;
                for (e, st) in out.iter_mut().zip(states) {
                    let back = nalgebra::Rotation3::from_axis_angle(&axis, -sign * st.q);
                    let bt = (back * t - t) * *sign;
                    let br = (back * tilt - tilt + own) * *sign;
                    *e = [bt.x, bt.y, bt.z, br.x, br.y, br.z];
                }
            }
            Shape::RotaryHarmonic { motion, direction, sign, order, cosine } => {
                let axis = nalgebra::Unit::new_normalize(nalgebra::Vector3::from(*direction));
                let t = nalgebra::Vector3::new(motion[0], motion[1], motion[2]);
                let r = nalgebra::Vector3::new(motion[3], motion[4], motion[5]);
                let n = f64::from(*order);
                for (e, st) in out.iter_mut().zip(states) {
                    // The body's motion in the parent frame about the joint's origin (which the
                    // nominal rotation leaves in place), turned into the joint frame: Rᵀ m h.
                    let h = if *cosine { (n * st.q).cos() } else { (n * st.q).sin() };
                    let back = nalgebra::Rotation3::from_axis_angle(&axis, -sign * st.q);
                    let bt = back * t * (sign * h);
                    let br = back * r * (sign * h);
                    *e = [bt.x, bt.y, bt.z, br.x, br.y, br.z];
                }
            }
            Shape::RotaryBacklash { direction } => {
                for (e, st) in out.iter_mut().zip(states) {
                    let k = -0.5 * st.direction;
                    *e = [0.0, 0.0, 0.0, direction[0] * k, direction[1] * k, direction[2] * k];
                }
            }
            Shape::RotaryServoLag { direction } => {
                for (e, st) in out.iter_mut().zip(states) {
                    let k = -st.velocity;
                    *e = [0.0, 0.0, 0.0, direction[0] * k, direction[1] * k, direction[2] * k];
                }
            }
        }
        Ok(())
    }
}

/// A term whose basis is another term's times `(F/F_ref)^p`, `F` the run's programmed feed: an
/// effect whose size grows with the feed (a reversal spike's height, a stick-slip's step).
#[derive(Debug)]
pub struct FeedScaledTerm {
    /// The term scaled.
    pub inner: Arc<dyn ErrorTerm>,
    /// `p`.
    pub exponent: f64,
    /// `F_ref`, mm/s.
    pub reference_mm_per_s: f64,
}

impl ErrorTerm for FeedScaledTerm {
    fn id(&self) -> &str {
        self.inner.id()
    }
    fn label(&self) -> &str {
        self.inner.label()
    }
    fn unit(&self) -> Unit {
        self.inner.unit()
    }
    fn class(&self) -> TermClass {
        self.inner.class()
    }
    fn basis_batch(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), TermError> {
        self.inner.basis_batch(states, out)?;
        for (e, st) in out.iter_mut().zip(states) {
            let k = (st.feed_mm_per_s / self.reference_mm_per_s).powf(self.exponent);
            e.iter_mut().for_each(|x| *x *= k);
        }
        Ok(())
    }
}

/// A basis function evaluated by compiled code outside this crate (a machine plugin's native
/// error-term kernel): the error motion per unit coefficient for a batch of joint states.
pub trait BasisKernel: Send + Sync + std::fmt::Debug {
    /// Fill `out` (as long as `states`); an `Err` carries the kernel's message.
    fn evaluate(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), String>;
}

/// Where [`crate::Model`] finds the kernels that a machine description names.
pub trait KernelSource {
    /// The kernel called `name`, if this source has it.
    fn kernel(&self, name: &str) -> Option<Arc<dyn BasisKernel>>;
}

/// A source with no kernels (machines of built-in terms only).
#[derive(Clone, Copy, Debug, Default)]
pub struct NoKernels;

impl KernelSource for NoKernels {
    fn kernel(&self, _name: &str) -> Option<Arc<dyn BasisKernel>> {
        None
    }
}

/// An error term whose basis is a plugin kernel.
#[derive(Clone, Debug)]
pub struct KernelTerm {
    /// Identifier.
    pub id: String,
    /// Description.
    pub label: String,
    /// Coefficient dimension.
    pub unit: Unit,
    /// Kind.
    pub class: TermClass,
    /// The kernel's name.
    pub kernel_name: String,
    /// The kernel.
    pub kernel: Arc<dyn BasisKernel>,
}

impl ErrorTerm for KernelTerm {
    fn id(&self) -> &str {
        &self.id
    }
    fn label(&self) -> &str {
        &self.label
    }
    fn unit(&self) -> Unit {
        self.unit
    }
    fn class(&self) -> TermClass {
        self.class
    }
    fn basis_batch(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), TermError> {
        self.kernel.evaluate(states, out).map_err(|message| TermError {
            term: self.id.clone(),
            message: format!("kernel '{}': {message}", self.kernel_name),
        })?;
        if let Some(k) = out.iter().position(|e| e.iter().any(|x| !x.is_finite())) {
            return Err(TermError {
                term: self.id.clone(),
                message: format!(
                    "kernel '{}' returned a non-finite value at batch index {k}",
                    self.kernel_name
                ),
            });
        }
        Ok(())
    }
}

/// `x^n` by repeated multiplication (polynomial degrees are small; `powi` is a library call).
#[inline]
fn pow(x: f64, n: u32) -> f64 {
    (0..n).fold(1.0, |acc, _| acc * x)
}

/// A term bound to a joint of the chain.
#[derive(Clone, Debug)]
pub struct BoundTerm {
    /// Branch of the joint.
    pub branch: crate::chain::Branch,
    /// Index of the joint in its branch.
    pub joint: usize,
    /// The machine axis that drives the joint (whose state the basis reads).
    pub axis: crate::axis::Axis,
    /// The term.
    pub term: Arc<dyn ErrorTerm>,
}

#[cfg(test)]
mod transient_tests {
    use super::{
        ErrorTerm, JointState, ReversalSide, TransientPart, reversal_transient_terms, transient,
    };
    use crate::axis::Axis;

    #[test]
    fn the_three_parts_span_a_damped_oscillation_and_stay_apart_without_ringing() {
        let (tau, omega) = (0.04, 50.0);
        let k = omega * tau;
        for i in 0..200 {
            let t = i as f64 * 1e-3;
            let d = (-t / tau).exp();
            let [a, b, c] = TransientPart::ALL.map(|p| transient(t, tau, omega, p));
            // e^{-x} cos φ = part 0 - (k²/2) part 2; e^{-x} sin φ = k part 1.
            assert!((d * (omega * t).cos() - (a - 0.5 * k * k * c)).abs() < 1e-14, "{t}");
            assert!((d * (omega * t).sin() - k * b).abs() < 1e-14, "{t}");
            // Without ringing: e^{-x}, x e^{-x}, x² e^{-x}, and the limit is continuous.
            let x = t / tau;
            let z = TransientPart::ALL.map(|p| transient(t, tau, 0.0, p));
            assert!(
                (z[0] - d).abs() < 1e-15
                    && (z[1] - x * d).abs() < 1e-15
                    && (z[2] - x * x * d).abs() < 1e-15,
                "{t}"
            );
            let near = TransientPart::ALL.map(|p| transient(t, tau, 1e-6, p));
            for (u, w) in near.iter().zip(&z) {
                assert!((u - w).abs() < 1e-12, "{t}: {near:?} against {z:?}");
            }
        }
        // Nothing before the axis's first reversal (∞), nor before a reversal.
        for p in TransientPart::ALL {
            assert_eq!(transient(f64::INFINITY, tau, omega, p), 0.0);
            assert_eq!(transient(-1e-3, tau, omega, p), 0.0);
        }
    }

    #[test]
    fn each_side_follows_only_its_own_reversals_and_is_outward() {
        let terms = reversal_transient_terms(Axis::X, 0, 30.0, None, true).unwrap();
        let ids: Vec<&str> = terms.iter().map(|t| t.id()).collect();
        assert_eq!(ids, ["SPXP0", "SPXP1", "SPXP2", "SPXN0", "SPXN1", "SPXN2"]);
        // 10 ms after a reversal at the positive end X moves − (direction −1): the positive
        // side's part 0 is +e^{-1/3} (outward, +X), the negative side's nothing; after the
        // negative end (+1) the other way round, −e^{-1/3}.
        let e = (-1.0f64 / 3.0).exp();
        for (direction, pos, neg) in [(-1.0, e, 0.0), (1.0, 0.0, -e)] {
            let st = JointState { direction, since_reversal_s: 0.01, ..Default::default() };
            assert!((terms[0].basis(&st).unwrap()[0] - pos).abs() < 1e-15, "{direction}");
            assert!((terms[3].basis(&st).unwrap()[0] - neg).abs() < 1e-15, "{direction}");
        }
        assert_eq!(ReversalSide::Both.gate(0.0), 1.0);
        assert_eq!(ReversalSide::Positive.gate(0.0) + ReversalSide::Negative.gate(0.0), 0.0);
        let both = reversal_transient_terms(Axis::Y, 1, 30.0, Some(100.0), false).unwrap();
        assert_eq!(both.iter().map(|t| t.id()).collect::<Vec<_>>(), ["SPY0", "SPY1", "SPY2"]);
        assert!(reversal_transient_terms(Axis::X, 0, 0.0, None, true).is_err());
        assert!(reversal_transient_terms(Axis::X, 0, 10.0, Some(-1.0), true).is_err());
    }
}

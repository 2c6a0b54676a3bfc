//! The error terms as machine descriptions and effects name them, before a model binds them to
//! its chain: the chain terms of a description ([`TermSpec`], with the bounds of their degrees
//! and harmonics) and the terms that act on the reading ([`ReadingTerm`]). Machine
//! descriptions ([`crate::machine`]) and effects ([`crate::effect`]) are both made of them, so
//! its code uses neither (the dependencies go one way); `crate::machine` re-exports its items.

use serde::{Deserialize, Serialize};

use crate::axis::{Axis, Plane};
use crate::term::{TermClass, Unit};

/// Highest polynomial degree of an error term. Ballbar circles span a fraction of an axis's
/// travel: a degree beyond a few is not identifiable from them, and an unbounded one would make
/// the basis evaluation (repeated multiplication) run without end on a typo.
pub const MAX_DEGREE: u32 = 12;

/// Highest harmonic order of a rotary error motion: one wave per degree. A ballbar's filtered
/// reading cannot resolve shorter waves of the angle, and the bound catches a typo.
pub const MAX_HARMONIC: u32 = 360;

/// An error term as written in a machine description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum TermSpec {
    /// Positional error of `axis`, one term per degree in `degrees` (id `EXX1`, ...).
    Positional {
        /// The axis.
        axis: Axis,
        /// Polynomial degrees, each ≥ 1.
        degrees: Vec<u32>,
    },
    /// Straightness of `axis` in direction `toward` (id `EYX2` for X toward Y), with pitch/yaw
    /// tied to it when `tie_angles`.
    Straightness {
        /// The moving axis.
        axis: Axis,
        /// The error direction.
        toward: Axis,
        /// Degrees, each ≥ 2 (the linear part is squareness).
        degrees: Vec<u32>,
        /// Rigid-guideway assumption: pitch and yaw are derivatives of the straightness.
        tie_angles: bool,
    },
    /// Squareness: on joint `axis`, `δ_toward = -θ (q - q_ref)`. `id` as the paper names the
    /// plane (`SQXY`, `SQYZ`, `SQZX`).
    Squareness {
        /// Identifier.
        id: String,
        /// The axis whose motion carries the error.
        axis: Axis,
        /// The error direction.
        toward: Axis,
    },
    /// Backlash of an axis (id `BX`; `BC` of a rotary axis: an angle, in the coordinate's
    /// sense).
    Backlash {
        /// The axis.
        axis: Axis,
    },
    /// Position-loop lag of an axis (id `TX`; `TC` of a rotary axis). With
    /// [`ServoVariant::PlaneMismatch`](crate::machine::ServoVariant::PlaneMismatch) the linear
    /// axes' lags are replaced by the paper's plane terms; a rotary axis's lag stays (those terms
    /// act on planar runs only).
    ServoLag {
        /// The axis.
        axis: Axis,
    },
    /// Angular error motion of a linear axis about `about` (X: roll of an X axis, ...), one
    /// term per degree, not tied to a straightness (id `ECX1`: about Z, of X, degree 1).
    Angular {
        /// The moving (linear) axis.
        axis: Axis,
        /// The direction the rotation is about: X, Y or Z.
        about: Axis,
        /// Polynomial degrees, each ≥ 1 (a constant angle of a carriage is a location, not a
        /// motion error: to first order it moves the ball by a constant).
        degrees: Vec<u32>,
    },
    /// ISO 230-7 location errors of a rotary axis: for a C axis `X`, `Y` (offsets of the axis
    /// line, µm), `A`, `B` (its tilts, µrad) and `C` (zero position, µrad); ids `EX0C`, ...
    RotaryLocation {
        /// The rotary axis.
        axis: Axis,
        /// The error directions (the `d` of ISO's `E_d0k`).
        components: Vec<Axis>,
    },
    /// Angular positioning error motion of a rotary axis (ISO 230-7 `E_CC` for C), the actual
    /// angle minus the commanded one, in the coordinate's sense: `ε(q) = Σ_n a_n sin nq + b_n
    /// cos nq`, two terms per harmonic (ids `ECC_S1`, `ECC_C1`, ...).
    RotaryPositioning {
        /// The rotary axis.
        axis: Axis,
        /// Harmonic orders, each from 1 to [`MAX_HARMONIC`].
        harmonics: Vec<u32>,
    },
    /// Run-out of a rotary axis along `direction` of the parent frame (X, Y, Z): radial across
    /// its line, axial along it (ISO 230-7 `E_XC`, `E_YC`, `E_ZC` for C), stated physically,
    /// two terms per harmonic of its angle (ids `EXC_S1`, `EXC_C1`, ...).
    RotaryRunout {
        /// The rotary axis.
        axis: Axis,
        /// The direction of the displacement: X, Y or Z.
        direction: Axis,
        /// Harmonic orders, each from 1 to [`MAX_HARMONIC`].
        harmonics: Vec<u32>,
    },
    /// Tilt error motion (wobble) of a rotary axis about a direction of the parent frame across
    /// its line (ISO 230-7 `E_AC`, `E_BC` for C), stated physically, pivoting about the joint's
    /// origin, two terms per harmonic of its angle (ids `EAC_S1`, `EAC_C1`, ...).
    RotaryWobble {
        /// The rotary axis.
        axis: Axis,
        /// The direction the tilt is about: A, B or C (about X, Y, Z; X, Y, Z are read as
        /// them), not the axis's own.
        about: Axis,
        /// Harmonic orders, each from 1 to [`MAX_HARMONIC`].
        harmonics: Vec<u32>,
    },
    /// Reversal spike of an axis (effect; id `SPX`): `δ = -sign(dq/dt) e^{-(t - t_r)/τ}`.
    ReversalSpike {
        /// The axis.
        axis: Axis,
        /// Decay time, ms.
        tau_ms: f64,
    },
    /// Reversal transient of an axis (effect; ids `SPX0`, `SPX1`, `SPX2`, per side `SPXP0`..,
    /// `SPXN0`..): the three parts of a damped transient after each reversal
    /// ([`crate::term::reversal_transient_terms`]).
    ReversalTransient {
        /// The axis.
        axis: Axis,
        /// Decay time, ms.
        tau_ms: f64,
        /// Ringing period, ms (`None`: no ringing).
        #[serde(default)]
        period_ms: Option<f64>,
        /// One set of coefficients per side of the axis's travel.
        #[serde(default)]
        per_side: bool,
    },
    /// Lateral play (effect; id `LPXY`): an error along `axis` of the `switched_by` carriage,
    /// `δ = -sign(d q_switched_by/dt)/2`.
    LateralPlay {
        /// The error direction.
        axis: Axis,
        /// The axis whose reversals switch it (and whose joint carries it).
        switched_by: Axis,
    },
    /// Cyclic error (effect; ids `CSX`, `CCX`): `δ = sin, cos (2π q/p)`.
    Cyclic {
        /// The axis.
        axis: Axis,
        /// Pitch, mm.
        pitch_mm: f64,
    },
    /// Vibration of an axis (effect; ids `VSX`, `VCX`): `δ = sin, cos (2π f t)`, `t` the run's
    /// time. A model holds it per run (its phase is the run's own,
    /// [`Model::run_terms`](crate::Model::run_terms)).
    Vibration {
        /// The axis.
        axis: Axis,
        /// Frequency, Hz.
        frequency_hz: f64,
    },
    /// Thermal drift of an axis with session time (effect; id `DX`, mm/s).
    Drift {
        /// The axis.
        axis: Axis,
    },
    /// Thermal growth of an axis (effect; id `TGX`): `δ = g(t) q`, the axis's scale growing with
    /// session time, linearly (no time constant; ppm/h) or saturating `1 - e^{-t/τ}` (ppm).
    ThermalGrowth {
        /// The axis.
        axis: Axis,
        /// τ, minutes (`None`: linear growth).
        #[serde(default)]
        time_constant_min: Option<f64>,
    },
    /// A term whose size grows with the feed: its basis times `(F/F_ref)^p` (effect; the inner
    /// term's ids).
    FeedScaled {
        /// The term scaled.
        term: Box<TermSpec>,
        /// `p`.
        exponent: f64,
        /// `F_ref`, mm/min.
        reference_mm_per_min: f64,
    },
    /// Stick-slip (effect; id `SSX`): `δ = -sign(dq/dt) max(0, 1 - |dq/dt|/v_c)`.
    StickSlip {
        /// The axis.
        axis: Axis,
        /// `v_c`, mm/min.
        speed_mm_per_min: f64,
    },
    /// A term whose basis is a compiled plugin's kernel.
    Kernel {
        /// Identifier, unique in the machine.
        id: String,
        /// Description.
        label: String,
        /// The axis whose joint carries the error.
        axis: Axis,
        /// The kernel's name, as the plugin declares it.
        kernel: String,
        /// Coefficient dimension.
        unit: Unit,
        /// Kind of error.
        class: TermClass,
    },
}

/// Measurement-level terms: they act on the reading, not through the chain.
#[derive(Clone, Debug, PartialEq)]
pub enum ReadingTerm {
    /// `ΔR = θ (d_u/R)(d_v/R) D` in runs of `plane` (the paper's servo mismatch).
    PlaneMismatch(Plane),
    /// `ΔR = θ`: bar-length error.
    BarLength,
    /// `ΔR = θ t` with `t` the session time: thermal growth of the bar (θ in mm/s).
    BarGrowth,
    /// `ΔR = -θ V²/(2R)`: the radius loss of a common servo lag τ, θ = τ² (s²).
    RadiusLoss,
}

/// The parameter id of a reading term.
pub fn reading_id(r: &ReadingTerm) -> String {
    match r {
        ReadingTerm::PlaneMismatch(p) => format!("M{}", p.name()),
        ReadingTerm::BarLength => "BAR".into(),
        ReadingTerm::BarGrowth => "DBAR".into(),
        ReadingTerm::RadiusLoss => "LOSS".into(),
    }
}

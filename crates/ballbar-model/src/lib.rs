//! The volumetric error model of a machine tool as a ballbar sees it: kinematic chain, error
//! terms, design matrix. Pure maths, no IO.
//!
//! # Units
//! Inside: mm, rad, s (and mm/s for feeds). Run files and reports use µm, µrad, ms, mm/min and
//! degrees; conversions happen at those edges only ([`term::Unit`]).
//!
//! # Sign conventions (each one tested in this crate)
//! - **Machine coordinates** are the position of the tool relative to the workpiece (ISO 841): a
//!   table axis physically moves the table the other way ([`chain`]).
//! - **Error motions** are stated as the error of the tool relative to the workpiece (ISO 230-1),
//!   whichever branch carries the axis ([`chain`]).
//! - **ΔR** is measured bar length minus nominal: positive when the balls are farther apart than
//!   R. To first order `ΔR = û·Δ` with `Δ` the tool-ball error relative to the table ball.
//! - **Planes and directions**: in plane `UV` the angle runs from +U towards +V (XY from +X, YZ
//!   from +Y, ZX from +Z), seen from the positive third axis; CCW is increasing angle. The
//!   paper's direction sign is `D = +1` for CW, `D = -1` for CCW ([`axis::Direction`]).
//! - **Squareness** follows the paper: `ΔY = -α X` (XY), `ΔX = -β₁ Z` (ZX), `ΔY = -β₂ Z` (YZ), so
//!   a positive α shortens the bar at 45° and 225° in XY and lengthens it at 135° and 315°: an
//!   ellipse with its major axis at 135°, the same CW and CCW.
//! - **Backlash** `ΔX = -(B/2) sign(dX/dt)`: a positive B makes a step at each X reversal
//!   (θ = 0°, 180° in XY), the same shape in both directions. `dX/dt` is the lagging axis's:
//!   the step comes when the axis reverses, its switch lag (its servo lag) after the commanded
//!   reversal ([`Design::with_switch_lags`]); reversal transients count time from the same
//!   moment.
//! - **Servo lag**: an axis lagging its command by τ errs by `-τ dX/dt`. A lag difference in XY
//!   gives `ΔR = V (τ_X - τ_Y) u v` for CCW and the opposite sign for CW: an ellipse at 45° that
//!   flips with direction and grows with the feed V.
//! - **Scale** (positional, degree 1): `ΔX = θ s_X`; a positive θ on X alone stretches the
//!   circle along X (ellipse along the axes, the same both directions).
//! - **Centring**: the table ball displaced by `e` (in the table frame, so it turns with a
//!   rotary table) from where the run file says: `ΔR = -û·R_table e`.
//! - **Bar length**: a bar longer than nominal by `b`: `ΔR = +b`.
//! - **Local scale and squareness** of a test ([`local`]): the linear part `J = ∂Δ/∂q` of the
//!   error field at the circle's centre, at the run's tool offset. Local scale of `U` in plane
//!   `UV` is `J_UU` (positive stretches the circle along `U`); local squareness `UV` is
//!   `-(J_UV + J_VU)`, the squareness convention above (a pure `SQXY` of α has local
//!   squareness α). A circle there reads `ΔR = R n·J n` for a linear field.

pub mod axis;
pub mod chain;
pub mod design;
pub mod effect;
pub mod local;
pub mod machine;
pub mod machines;
pub mod paper;
pub mod parallel;
pub mod path;
pub mod plausible;
pub mod progress;
pub mod run;
pub mod term;
mod term_spec;
pub mod time;

pub use axis::{Axis, Direction, Plane};
pub use chain::{Branch, KinematicChain};
pub use design::{BlockScratch, Design, ExactScratch, RowScratch};
pub use effect::Effect;
pub use machine::{BarLength, MachineSpec, Model, ModelOptions, ServoVariant};
pub use run::{Run, RunHeader};
pub use term::{
    BasisKernel, ErrorTerm, JointState, KernelSource, NoKernels, TermClass, TermError, Unit,
};

/// A column of the design matrix: one unknown.
#[derive(Clone, Debug, PartialEq)]
pub struct Parameter {
    /// Identifier (`EXX1`, `SQXY`, `CX@xy-ccw-1`).
    pub id: String,
    /// Description.
    pub label: String,
    /// Dimension.
    pub unit: Unit,
    /// What it is.
    pub class: ParamClass,
}

/// What a parameter is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ParamClass {
    /// A chain error term.
    Term(TermClass),
    /// The paper's per-plane servo mismatch.
    PlaneMismatch,
    /// The bar-length error.
    BarLength,
    /// A per-run centring offset (nuisance).
    Centring,
    /// A run's own coefficient of a run term (a vibration's phase parts): a nuisance of the run.
    RunTerm(TermClass),
}

impl ParamClass {
    /// True for nuisance parameters (centring, a run's own coefficients).
    pub fn is_nuisance(self) -> bool {
        matches!(self, ParamClass::Centring | ParamClass::RunTerm(_))
    }
}

/// Errors of model construction and design.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ModelError {
    /// The machine description is inconsistent.
    #[error("invalid machine description: {message}")]
    InvalidMachine {
        /// What is wrong.
        message: String,
    },
    /// A run lacks an axis column the machine needs.
    #[error(
        "{source_name}: the run has no column for axis {axis}, which machine '{machine}' needs"
    )]
    MissingAxis {
        /// The run's file.
        source_name: String,
        /// The missing axis.
        axis: Axis,
        /// Machine name.
        machine: String,
    },
    /// The chain puts the balls farther from each other than the run's radius allows.
    #[error(
        "{source_name}:{line}: the machine's chain puts the balls {distance_mm:.3} mm apart, but the run's radius is {radius_mm} mm (check pivot_mm, table_ball_mm, tool_ball_mm)"
    )]
    RadiusMismatch {
        /// The run's file.
        source_name: String,
        /// Line of the sample.
        line: u32,
        /// Nominal distance from the chain.
        distance_mm: f64,
        /// The run's radius.
        radius_mm: f64,
    },
    /// A free run's `table_ball_mm` disagrees with where its `pivot_mm` puts the table ball.
    #[error(
        "{source_name}: pivot_mm puts the table ball at {from_pivot_mm:?} mm in the table frame (through the machine's nominal chain, every rotary axis at 0), but table_ball_mm says {given_mm:?} mm, {distance_mm:.3} mm away: a free run's pivot places the ball, and table_ball_mm, where given, must agree with it to 0.01 mm"
    )]
    TableBallMismatch {
        /// The run's file.
        source_name: String,
        /// Where the pivot puts the ball.
        from_pivot_mm: [f64; 3],
        /// The header's `table_ball_mm`.
        given_mm: [f64; 3],
        /// Their distance.
        distance_mm: f64,
    },
    /// An error term could not be evaluated (a plugin kernel failed).
    #[error(transparent)]
    Term(#[from] crate::term::TermError),
    /// A parameter id is not in the model.
    #[error("parameter '{id}' is not in this model")]
    UnknownParameter {
        /// The id.
        id: String,
    },
}

#[cfg(test)]
mod tests;

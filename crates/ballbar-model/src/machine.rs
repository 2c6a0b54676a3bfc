//! A machine described as data: the chain of joints and the error terms to model. This is what a
//! machine plugin provides and what a saved model carries, so that a model file alone can
//! predict. Raw description first (serde), then validated into a [`Model`](crate::Model). The
//! error terms' own descriptions ([`TermSpec`], [`ReadingTerm`]) are re-exported from a module
//! below both this one and the effects, which are made of them too.

use std::sync::Arc;

use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

use crate::ModelError;
use crate::axis::{Axis, Plane};
use crate::chain::{Branch, Joint, JointKind, KinematicChain};
use crate::effect::{Effect, EffectPart};
use crate::term::{
    BoundTerm, BuiltinTerm, ErrorTerm, KernelSource, KernelTerm, Periodic, Shape, TermClass, Unit,
};

pub use crate::term_spec::{MAX_DEGREE, MAX_HARMONIC, ReadingTerm, TermSpec, reading_id};

/// A joint as written in a machine description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointSpec {
    /// Human name.
    pub name: String,
    /// Driving machine axis.
    pub axis: Axis,
    /// Linear or rotary.
    pub kind: JointKind,
    /// Direction of motion (or rotation axis) in the parent frame; normalised on validation.
    pub direction: [f64; 3],
    /// Origin of the joint frame in the parent frame at zero coordinate, mm.
    pub origin_mm: [f64; 3],
}

/// Normalisation of one axis's error polynomials: `s = (q - reference_mm)/length_mm`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisNorm {
    /// The axis.
    pub axis: Axis,
    /// Fixed machine reference position, mm.
    pub reference_mm: f64,
    /// Fixed normalisation length (half the travel, say), mm.
    pub length_mm: f64,
}

/// The paper's error set on the given axes of Pahk, Kim & Moon (1997): positional (degree 1) and straightness (degree 2, angles tied)
/// of each axis, squareness XY, YZ, ZX, backlash and servo lag of each axis.
pub fn paper_terms() -> Vec<TermSpec> {
    let mut t = Vec::new();
    for a in Axis::LINEAR {
        t.push(TermSpec::Positional { axis: a, degrees: vec![1] });
    }
    for (axis, toward) in [
        (Axis::X, Axis::Y),
        (Axis::X, Axis::Z),
        (Axis::Y, Axis::X),
        (Axis::Y, Axis::Z),
        (Axis::Z, Axis::X),
        (Axis::Z, Axis::Y),
    ] {
        t.push(TermSpec::Straightness { axis, toward, degrees: vec![2], tie_angles: true });
    }
    t.push(TermSpec::Squareness { id: "SQXY".into(), axis: Axis::X, toward: Axis::Y });
    t.push(TermSpec::Squareness { id: "SQYZ".into(), axis: Axis::Z, toward: Axis::Y });
    t.push(TermSpec::Squareness { id: "SQZX".into(), axis: Axis::Z, toward: Axis::X });
    for a in Axis::LINEAR {
        t.push(TermSpec::Backlash { axis: a });
    }
    for a in Axis::LINEAR {
        t.push(TermSpec::ServoLag { axis: a });
    }
    t
}

/// Linear joint along a machine axis.
pub fn linear(name: &str, axis: Axis, origin_mm: [f64; 3]) -> JointSpec {
    JointSpec {
        name: name.into(),
        axis,
        kind: JointKind::Linear,
        direction: axis.unit_vector(),
        origin_mm,
    }
}

/// A machine: chain and error set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MachineSpec {
    /// Machine type name (`column`).
    pub name: String,
    /// Version of the description.
    pub version: String,
    /// One line for `ballbar plugins` and reports.
    pub description: String,
    /// Joints from the base to the spindle.
    pub tool: Vec<JointSpec>,
    /// Joints from the base to the table.
    pub workpiece: Vec<JointSpec>,
    /// Normalisation of each linear axis.
    pub normalisation: Vec<AxisNorm>,
    /// The error terms to model.
    pub terms: Vec<TermSpec>,
}

/// How the servo terms are modelled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum ServoVariant {
    /// One lag per axis (s): mismatch grows with feed and the three planes stay consistent.
    #[default]
    AxisLag,
    /// The paper's three independent plane coefficients `Mxy, Myz, Mzx` (mm), `ΔR = M u v D`.
    PlaneMismatch,
}

/// Whether the bar-length error is fitted or known from calibration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
pub enum BarLength {
    /// One unknown bar-length error shared by all runs.
    #[default]
    Fit,
    /// A calibrated bar: its length error (mm) is known and subtracted.
    Known(f64),
}

/// Options that select the model variant.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
pub struct ModelOptions {
    /// Servo terms.
    pub servo: ServoVariant,
    /// Bar length.
    pub bar_length: BarLength,
}

/// A validated machine model: chain, bound terms, reading terms.
#[derive(Clone, Debug)]
pub struct Model {
    /// The description it was built from.
    pub spec: MachineSpec,
    /// Variant options.
    pub options: ModelOptions,
    /// The chain.
    pub chain: KinematicChain,
    /// Chain error terms.
    pub terms: Vec<BoundTerm>,
    /// Reading terms.
    pub reading_terms: Vec<ReadingTerm>,
    /// The effects added to the machine's own terms, in order.
    pub effects: Vec<Effect>,
    /// The parameter ids of each effect, in the effect's column order (for an effect of
    /// [`Model::run_terms`], the term ids; each run's parameter is `ID@run`).
    pub effect_ids: Vec<Vec<String>>,
    /// Chain terms with one coefficient per run (a vibration's phase is the run's own): a
    /// design gives each run its own columns of them, after the run's centring.
    pub run_terms: Vec<BoundTerm>,
    /// Reading terms with one coefficient per run (a bar length of each run's own): a design
    /// gives each run its own columns of them, after its coefficients of [`Model::run_terms`]
    /// (parameter `ID@run`, [`reading_id`]).
    pub run_reading_terms: Vec<ReadingTerm>,
}

/// The linear direction along a rotary axis's own line (A: X, B: Y, C: Z).
fn own_line(axis: Axis) -> Axis {
    Axis::LINEAR[axis.index() % 3]
}

/// The terms of a rotary error motion `E<what><axis>`: a sine and a cosine term per harmonic.
#[allow(clippy::too_many_arguments)]
fn harmonic_terms(
    axis: Axis,
    what: Axis,
    harmonics: &[u32],
    name: &str,
    unit: Unit,
    motion: crate::chain::ErrorMotion,
    joint: &Joint,
    sign: f64,
) -> Result<Vec<BuiltinTerm>, ModelError> {
    if harmonics.is_empty() {
        return Err(ModelError::InvalidMachine {
            message: format!("{name}: give at least one harmonic"),
        });
    }
    let mut out = Vec::with_capacity(2 * harmonics.len());
    for (i, &n) in harmonics.iter().enumerate() {
        if !(1..=MAX_HARMONIC).contains(&n) {
            return Err(ModelError::InvalidMachine {
                message: format!(
                    "{name}: harmonic {n} is not from 1 to {MAX_HARMONIC} (harmonic 0, a constant, is a location error)"
                ),
            });
        }
        if harmonics[..i].contains(&n) {
            return Err(ModelError::InvalidMachine {
                message: format!("{name}: harmonic {n} is listed twice"),
            });
        }
        let d = joint.direction;
        for (tag, part, cosine) in [("S", "sine", false), ("C", "cosine", true)] {
            out.push(BuiltinTerm {
                id: format!("E{what}{axis}_{tag}{n}"),
                label: format!("{name}, harmonic {n} of {axis}, {part} part"),
                unit,
                class: TermClass::RotaryMotion,
                shape: Shape::RotaryHarmonic {
                    motion,
                    direction: [d.x, d.y, d.z],
                    sign,
                    order: n,
                    cosine,
                },
            });
        }
    }
    Ok(out)
}

/// Build the bound terms of `list` on a validated chain.
fn bind_terms(
    spec: &MachineSpec,
    chain: &KinematicChain,
    options: ModelOptions,
    kernels: &dyn KernelSource,
    list: &[TermSpec],
) -> Result<Vec<BoundTerm>, ModelError> {
    let find = |axis: Axis| -> Result<(Branch, usize, &Joint), ModelError> {
        for branch in [Branch::Tool, Branch::Workpiece] {
            if let Some((i, j)) =
                chain.branch(branch).iter().enumerate().find(|(_, j)| j.axis == axis)
            {
                return Ok((branch, i, j));
            }
        }
        Err(ModelError::InvalidMachine {
            message: format!("a term refers to axis {axis}, which drives no joint"),
        })
    };
    let norm = |axis: Axis| -> Result<(f64, f64), ModelError> {
        // Lengths below a micrometre are typos (a normalisation length is an axis's travel
        // scale), and would overflow polynomial bases to infinity.
        spec.normalisation
            .iter()
            .find(|n| n.axis == axis)
            .filter(|n| {
                n.length_mm >= 1e-3 && n.length_mm.is_finite() && n.reference_mm.is_finite()
            })
            .map(|n| (n.reference_mm, n.length_mm))
            .ok_or_else(|| ModelError::InvalidMachine {
                message: format!(
                    "axis {axis} needs a normalisation with a finite length_mm of at least 0.001"
                ),
            })
    };
    let linear_dir = |axis: Axis, what: &str| -> Result<usize, ModelError> {
        if axis.is_rotary() {
            return Err(ModelError::InvalidMachine {
                message: format!("{what}: {axis} is not a linear direction"),
            });
        }
        Ok(axis.index())
    };
    let rotary_joint = |axis: Axis, what: &str| -> Result<(Branch, usize, &Joint), ModelError> {
        let (b, j, joint) = find(axis)?;
        if joint.kind != JointKind::Rotary {
            return Err(ModelError::InvalidMachine {
                message: format!("{what} of {axis}: {axis} is not a rotary axis"),
            });
        }
        Ok((b, j, joint))
    };
    let mut terms = Vec::new();
    let mut push = |branch: Branch, joint: usize, t: Arc<dyn ErrorTerm>| {
        let axis = chain.branch(branch)[joint].axis;
        terms.push(BoundTerm { branch, joint, axis, term: t })
    };
    for t in list {
        match t {
            TermSpec::Positional { axis, degrees } => {
                let (b, j, _) = find(*axis)?;
                let (reference, length) = norm(*axis)?;
                let dir = linear_dir(*axis, "positional")?;
                for &p in degrees {
                    if !(1..=MAX_DEGREE).contains(&p) {
                        return Err(ModelError::InvalidMachine {
                            message: format!(
                                "positional {axis}: degree {p} is not from 1 to {MAX_DEGREE}"
                            ),
                        });
                    }
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            id: format!("E{axis}{axis}{p}"),
                            label: format!("positional error of {axis}, degree {p}"),
                            unit: Unit::Length,
                            class: TermClass::Positional,
                            shape: Shape::Polynomial {
                                dir,
                                power: p,
                                reference,
                                length,
                                tie: None,
                            },
                        }),
                    );
                }
            }
            TermSpec::Straightness { axis, toward, degrees, tie_angles } => {
                let (b, j, joint) = find(*axis)?;
                let (reference, length) = norm(*axis)?;
                let dir = linear_dir(*toward, "straightness")?;
                if toward == axis {
                    return Err(ModelError::InvalidMachine {
                        message: format!("straightness of {axis} toward itself"),
                    });
                }
                let mut e = Vector3::zeros();
                e[dir] = 1.0;
                let tie = tie_angles.then(|| {
                    let t = joint.direction.cross(&e);
                    [t.x, t.y, t.z]
                });
                for &p in degrees {
                    if !(2..=MAX_DEGREE).contains(&p) {
                        return Err(ModelError::InvalidMachine {
                            message: format!(
                                "straightness {axis}→{toward}: degree {p} is not from 2 (the linear part is squareness) to {MAX_DEGREE}"
                            ),
                        });
                    }
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            id: format!("E{toward}{axis}{p}"),
                            label: format!(
                                "straightness of {axis} in {toward}, degree {p}{}",
                                if *tie_angles { ", angle tied" } else { "" }
                            ),
                            unit: Unit::Length,
                            class: TermClass::Straightness,
                            shape: Shape::Polynomial { dir, power: p, reference, length, tie },
                        }),
                    );
                }
            }
            TermSpec::Squareness { id, axis, toward } => {
                let (b, j, _) = find(*axis)?;
                let (reference, _) = norm(*axis)?;
                let dir = linear_dir(*toward, "squareness")?;
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: id.clone(),
                        label: format!("squareness {id}: {toward} error proportional to {axis}"),
                        unit: Unit::Angle,
                        class: TermClass::Squareness,
                        shape: Shape::Squareness { dir, reference },
                    }),
                );
            }
            TermSpec::Backlash { axis } => {
                let (b, j, joint) = find(*axis)?;
                let (unit, shape) = if axis.is_rotary() {
                    let d = joint.direction;
                    (Unit::Angle, Shape::RotaryBacklash { direction: [d.x, d.y, d.z] })
                } else {
                    (Unit::Length, Shape::Backlash { dir: linear_dir(*axis, "backlash")? })
                };
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("B{axis}"),
                        label: format!("backlash of {axis}"),
                        unit,
                        class: TermClass::Backlash,
                        shape,
                    }),
                );
            }
            TermSpec::ServoLag { axis } => {
                // The paper's plane terms replace the linear axes' lags; nothing replaces a
                // rotary axis's.
                if options.servo == ServoVariant::PlaneMismatch && !axis.is_rotary() {
                    continue;
                }
                let (b, j, joint) = find(*axis)?;
                let shape = if axis.is_rotary() {
                    let d = joint.direction;
                    Shape::RotaryServoLag { direction: [d.x, d.y, d.z] }
                } else {
                    Shape::ServoLag { dir: linear_dir(*axis, "servo lag")? }
                };
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("T{axis}"),
                        label: format!("servo lag of {axis}"),
                        unit: Unit::Time,
                        class: TermClass::ServoLag,
                        shape,
                    }),
                );
            }
            TermSpec::RotaryPositioning { axis, harmonics } => {
                let (b, j, joint) = rotary_joint(*axis, "angular positioning error")?;
                // The coordinate's error ε turns the body physically by σ ε about its line.
                let d = joint.direction * b.sign();
                let motion = [0.0, 0.0, 0.0, d.x, d.y, d.z];
                for t in harmonic_terms(
                    *axis,
                    *axis,
                    harmonics,
                    &format!("angular positioning error of {axis}"),
                    Unit::Angle,
                    motion,
                    joint,
                    b.sign(),
                )? {
                    push(b, j, Arc::new(t));
                }
            }
            TermSpec::RotaryRunout { axis, direction, harmonics } => {
                let (b, j, joint) = rotary_joint(*axis, "run-out")?;
                let dir = linear_dir(*direction, &format!("run-out of {axis}"))?;
                let mut motion = [0.0; 6];
                motion[dir] = 1.0;
                let name = if *direction == own_line(*axis) {
                    format!("axial run-out of {axis}")
                } else {
                    format!("radial run-out of {axis} in {direction}")
                };
                for t in harmonic_terms(
                    *axis,
                    *direction,
                    harmonics,
                    &name,
                    Unit::Length,
                    motion,
                    joint,
                    b.sign(),
                )? {
                    push(b, j, Arc::new(t));
                }
            }
            TermSpec::RotaryWobble { axis, about, harmonics } => {
                let (b, j, joint) = rotary_joint(*axis, "tilt error motion")?;
                // X, Y, Z are read as the rotations about them, A, B, C.
                let rot = if about.is_rotary() { *about } else { Axis::ALL[about.index() + 3] };
                if rot == *axis {
                    return Err(ModelError::InvalidMachine {
                        message: format!(
                            "tilt error motion of {axis} about its own line: that is its angular positioning error (RotaryPositioning, E{axis}{axis})"
                        ),
                    });
                }
                let mut motion = [0.0; 6];
                motion[rot.index()] = 1.0;
                let name = format!("tilt error motion of {axis} about {}", own_line(rot));
                for t in harmonic_terms(
                    *axis,
                    rot,
                    harmonics,
                    &name,
                    Unit::Angle,
                    motion,
                    joint,
                    b.sign(),
                )? {
                    push(b, j, Arc::new(t));
                }
            }
            TermSpec::Angular { axis, about, degrees } => {
                let (b, j, joint) = find(*axis)?;
                if joint.kind != JointKind::Linear {
                    return Err(ModelError::InvalidMachine {
                        message: format!(
                            "angular error motion of {axis}: only linear axes have them here (rotary axes: RotaryPositioning, RotaryWobble)"
                        ),
                    });
                }
                let (reference, length) = norm(*axis)?;
                let dir = 3 + linear_dir(*about, "angular error: about")?;
                let rot = ["A", "B", "C"][dir - 3];
                for &p in degrees {
                    if !(1..=MAX_DEGREE).contains(&p) {
                        return Err(ModelError::InvalidMachine {
                            message: format!(
                                "angular error of {axis} about {about}: degree {p} is not from 1 to {MAX_DEGREE}"
                            ),
                        });
                    }
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            id: format!("E{rot}{axis}{p}"),
                            label: format!(
                                "angular error motion of {axis} about {about}, degree {p}"
                            ),
                            unit: Unit::Angle,
                            class: TermClass::Angular,
                            shape: Shape::Polynomial {
                                dir,
                                power: p,
                                reference,
                                length,
                                tie: None,
                            },
                        }),
                    );
                }
            }
            TermSpec::RotaryLocation { axis, components } => {
                let (b, j, joint) = find(*axis)?;
                if joint.kind != JointKind::Rotary {
                    return Err(ModelError::InvalidMachine {
                        message: format!("location errors of {axis}: {axis} is not a rotary axis"),
                    });
                }
                let own = match axis {
                    Axis::A => Axis::X,
                    Axis::B => Axis::Y,
                    _ => Axis::Z,
                };
                for &c in components {
                    if c == own {
                        return Err(ModelError::InvalidMachine {
                            message: format!(
                                "location error E{c}0{axis}: an offset along the axis's own line is not a location error (ISO 230-7)"
                            ),
                        });
                    }
                    let mut motion = [0.0; 6];
                    // The component in the joint's frame: X/Y/Z offsets, A/B/C tilts about
                    // X/Y/Z (the frames are parallel to the machine axes at zero).
                    motion[c.index()] = 1.0;
                    let d = joint.direction;
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            id: format!("E{c}0{axis}"),
                            label: if c.is_rotary() {
                                if c == *axis {
                                    format!("zero position error of {axis}")
                                } else {
                                    format!(
                                        "tilt of the {axis} axis line about {}",
                                        ["X", "Y", "Z"][c.index() - 3]
                                    )
                                }
                            } else {
                                format!("{c} offset of the {axis} axis line")
                            },
                            unit: if c.is_rotary() { Unit::Angle } else { Unit::Length },
                            class: TermClass::RotaryLocation,
                            shape: Shape::RotaryLocation {
                                motion,
                                direction: [d.x, d.y, d.z],
                                sign: b.sign(),
                            },
                        }),
                    );
                }
            }
            TermSpec::ReversalSpike { axis, tau_ms } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "reversal spike")?;
                if !(*tau_ms > 0.0 && tau_ms.is_finite()) {
                    return Err(ModelError::InvalidMachine {
                        message: format!("reversal spike of {axis}: tau_ms must be positive"),
                    });
                }
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("SP{axis}"),
                        label: format!("reversal spike of {axis} (τ = {tau_ms} ms)"),
                        unit: Unit::Length,
                        class: TermClass::Effect,
                        shape: Shape::ReversalSpike { dir, tau_s: tau_ms * 1e-3 },
                    }),
                );
            }
            TermSpec::ReversalTransient { axis, tau_ms, period_ms, per_side } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "reversal transient")?;
                for t in crate::term::reversal_transient_terms(
                    *axis, dir, *tau_ms, *period_ms, *per_side,
                )
                .map_err(|message| ModelError::InvalidMachine { message })?
                {
                    push(b, j, Arc::new(t));
                }
            }
            TermSpec::LateralPlay { axis, switched_by } => {
                let (b, j, _) = find(*switched_by)?;
                let dir = linear_dir(*axis, "lateral play")?;
                linear_dir(*switched_by, "lateral play")?;
                if axis == switched_by {
                    return Err(ModelError::InvalidMachine {
                        message: format!("lateral play of {axis} switched by itself is backlash"),
                    });
                }
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("LP{axis}{switched_by}"),
                        label: format!(
                            "lateral play: {axis} switched by the reversals of {switched_by}"
                        ),
                        unit: Unit::Length,
                        class: TermClass::Effect,
                        shape: Shape::Backlash { dir },
                    }),
                );
            }
            TermSpec::Cyclic { axis, pitch_mm } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "cyclic error")?;
                if !(*pitch_mm > 0.0 && pitch_mm.is_finite()) {
                    return Err(ModelError::InvalidMachine {
                        message: format!("cyclic error of {axis}: pitch_mm must be positive"),
                    });
                }
                for (id, cosine) in [(format!("CS{axis}"), false), (format!("CC{axis}"), true)] {
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            label: format!(
                                "cyclic error of {axis}, pitch {pitch_mm} mm, {} part",
                                if cosine { "cosine" } else { "sine" }
                            ),
                            id,
                            unit: Unit::Length,
                            class: TermClass::Effect,
                            shape: Shape::Periodic {
                                dir,
                                wavelength: *pitch_mm,
                                cosine,
                                of: Periodic::Position,
                            },
                        }),
                    );
                }
            }
            TermSpec::Vibration { axis, frequency_hz } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "vibration")?;
                if !(*frequency_hz > 0.0 && frequency_hz.is_finite()) {
                    return Err(ModelError::InvalidMachine {
                        message: format!("vibration of {axis}: frequency_hz must be positive"),
                    });
                }
                for (id, cosine) in [(format!("VS{axis}"), false), (format!("VC{axis}"), true)] {
                    push(
                        b,
                        j,
                        Arc::new(BuiltinTerm {
                            label: format!(
                                "vibration of {axis} at {frequency_hz:.3} Hz, {} part",
                                if cosine { "cosine" } else { "sine" }
                            ),
                            id,
                            unit: Unit::Length,
                            class: TermClass::Effect,
                            shape: Shape::Periodic {
                                dir,
                                wavelength: 1.0 / frequency_hz,
                                cosine,
                                of: Periodic::RunTime,
                            },
                        }),
                    );
                }
            }
            TermSpec::Drift { axis } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "drift")?;
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("D{axis}"),
                        label: format!("thermal drift of {axis} with session time"),
                        unit: Unit::Rate,
                        class: TermClass::Effect,
                        shape: Shape::Drift { dir },
                    }),
                );
            }
            TermSpec::ThermalGrowth { axis, time_constant_min } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "thermal growth")?;
                if time_constant_min.is_some_and(|t| !(t > 0.0 && t.is_finite())) {
                    return Err(ModelError::InvalidMachine {
                        message: format!(
                            "thermal growth of {axis}: time_constant_min must be positive"
                        ),
                    });
                }
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("TG{axis}"),
                        label: match time_constant_min {
                            None => format!("thermal growth of {axis}, linear in time"),
                            Some(t) => {
                                format!("thermal growth of {axis}, saturating (τ = {t:.1} min)")
                            }
                        },
                        unit: if time_constant_min.is_some() {
                            Unit::Ratio
                        } else {
                            Unit::RatioRate
                        },
                        class: TermClass::Effect,
                        shape: Shape::Growth { dir, tau_s: time_constant_min.map(|t| t * 60.0) },
                    }),
                );
            }
            TermSpec::FeedScaled { term, exponent, reference_mm_per_min } => {
                if !(exponent.is_finite()
                    && *reference_mm_per_min > 0.0
                    && reference_mm_per_min.is_finite())
                {
                    return Err(ModelError::InvalidMachine { message: "a feed-scaled term needs a finite exponent and a positive reference feed".into() });
                }
                let inner =
                    bind_terms(spec, chain, options, kernels, std::slice::from_ref(term.as_ref()))?;
                for t in inner {
                    let scaled = crate::term::FeedScaledTerm {
                        inner: t.term,
                        exponent: *exponent,
                        reference_mm_per_s: reference_mm_per_min / 60.0,
                    };
                    push(t.branch, t.joint, Arc::new(scaled));
                }
            }
            TermSpec::StickSlip { axis, speed_mm_per_min } => {
                let (b, j, _) = find(*axis)?;
                let dir = linear_dir(*axis, "stick-slip")?;
                if !(*speed_mm_per_min > 0.0 && speed_mm_per_min.is_finite()) {
                    return Err(ModelError::InvalidMachine {
                        message: format!("stick-slip of {axis}: speed_mm_per_min must be positive"),
                    });
                }
                push(
                    b,
                    j,
                    Arc::new(BuiltinTerm {
                        id: format!("SS{axis}"),
                        label: format!("stick-slip of {axis} below {speed_mm_per_min} mm/min"),
                        unit: Unit::Length,
                        class: TermClass::Effect,
                        shape: Shape::StickSlip { dir, speed: speed_mm_per_min / 60.0 },
                    }),
                );
            }
            TermSpec::Kernel { id, label, axis, kernel, unit, class } => {
                let (b, j, _) = find(*axis)?;
                let k = kernels.kernel(kernel).ok_or_else(|| ModelError::InvalidMachine {
                    message: format!("term {id} needs the kernel '{kernel}', which the machine's plugin does not provide"),
                })?;
                push(
                    b,
                    j,
                    Arc::new(KernelTerm {
                        id: id.clone(),
                        label: label.clone(),
                        unit: *unit,
                        class: *class,
                        kernel_name: kernel.clone(),
                        kernel: k,
                    }),
                );
            }
        }
    }
    Ok(terms)
}

fn unit3(v: [f64; 3], what: &str) -> Result<Vector3<f64>, ModelError> {
    let v = Vector3::from(v);
    let n = v.norm();
    if !n.is_finite() || n < 1e-12 {
        return Err(ModelError::InvalidMachine {
            message: format!("{what}: direction must be a non-zero finite vector"),
        });
    }
    Ok(v / n)
}

impl Model {
    /// Validate a description of built-in terms and build the model.
    pub fn new(spec: MachineSpec, options: ModelOptions) -> Result<Model, ModelError> {
        Model::with_kernels(spec, options, &crate::term::NoKernels)
    }

    /// Validate a description and build the model; `Kernel` terms take their basis from
    /// `kernels` (the loaded plugins).
    pub fn with_kernels(
        spec: MachineSpec,
        options: ModelOptions,
        kernels: &dyn KernelSource,
    ) -> Result<Model, ModelError> {
        Model::with_effects(spec, options, kernels, &[])
    }

    /// [`Model::with_kernels`] with `effects` added after the machine's own terms (the
    /// diagnosis's accepted effects, a truth's simulated ones).
    pub fn with_effects(
        spec: MachineSpec,
        options: ModelOptions,
        kernels: &dyn KernelSource,
        effects: &[Effect],
    ) -> Result<Model, ModelError> {
        let joints = |list: &[JointSpec]| -> Result<Vec<Joint>, ModelError> {
            list.iter()
                .map(|j| {
                    if j.axis.is_rotary() != (j.kind == JointKind::Rotary) {
                        return Err(ModelError::InvalidMachine {
                            message: format!(
                                "joint '{}': axis {} cannot drive a {:?} joint",
                                j.name, j.axis, j.kind
                            ),
                        });
                    }
                    if j.origin_mm.iter().any(|x| !x.is_finite()) {
                        return Err(ModelError::InvalidMachine {
                            message: format!("joint '{}': origin must be finite", j.name),
                        });
                    }
                    Ok(Joint {
                        name: j.name.clone(),
                        axis: j.axis,
                        kind: j.kind,
                        direction: unit3(j.direction, &format!("joint '{}'", j.name))?,
                        origin: Vector3::from(j.origin_mm),
                    })
                })
                .collect()
        };
        let chain =
            KinematicChain { tool: joints(&spec.tool)?, workpiece: joints(&spec.workpiece)? };
        let mut seen = std::collections::HashSet::new();
        for a in chain.tool.iter().chain(&chain.workpiece).map(|j| j.axis) {
            if !seen.insert(a) {
                return Err(ModelError::InvalidMachine {
                    message: format!("axis {a} drives more than one joint"),
                });
            }
        }
        if spec.terms.iter().any(|t| matches!(t, TermSpec::Vibration { .. })) {
            return Err(ModelError::InvalidMachine {
                message: "a vibration has each run's own phase: it is an effect (Effect::Vibration), not a term of the machine".into(),
            });
        }
        let mut terms = bind_terms(&spec, &chain, options, kernels, &spec.terms)?;
        let mut reading_terms = Vec::new();
        if options.servo == ServoVariant::PlaneMismatch {
            reading_terms.extend(Plane::PLANAR.into_iter().map(ReadingTerm::PlaneMismatch));
        }
        if options.bar_length == BarLength::Fit {
            reading_terms.push(ReadingTerm::BarLength);
        }
        // Effects: their chain terms follow the machine's, their reading terms the machine's
        // reading terms; which parameters each effect owns is kept by id.
        let mut effect_ids = Vec::with_capacity(effects.len());
        let mut run_terms = Vec::new();
        let mut run_reading_terms = Vec::new();
        for e in effects {
            let mut ids = Vec::new();
            for part in e.parts() {
                match part {
                    EffectPart::Terms(t) => {
                        let bound =
                            bind_terms(&spec, &chain, options, kernels, std::slice::from_ref(&t))?;
                        ids.extend(bound.iter().map(|b| b.term.id().to_string()));
                        terms.extend(bound);
                    }
                    EffectPart::PerRun(t) => {
                        let bound =
                            bind_terms(&spec, &chain, options, kernels, std::slice::from_ref(&t))?;
                        ids.extend(bound.iter().map(|b| b.term.id().to_string()));
                        run_terms.extend(bound);
                    }
                    EffectPart::PerRunReading(r) => {
                        if run_reading_terms.contains(&r) {
                            return Err(ModelError::InvalidMachine {
                                message: format!(
                                    "effect {}: the model already has it",
                                    e.describe()
                                ),
                            });
                        }
                        ids.push(reading_id(&r));
                        run_reading_terms.push(r)
                    }
                    EffectPart::Reading(r) => {
                        if reading_terms.contains(&r) {
                            return Err(ModelError::InvalidMachine {
                                message: format!(
                                    "effect {}: the model already has it",
                                    e.describe()
                                ),
                            });
                        }
                        ids.push(reading_id(&r));
                        reading_terms.push(r)
                    }
                }
            }
            effect_ids.push(ids);
        }
        let mut ids = std::collections::HashSet::new();
        for t in terms.iter().chain(&run_terms) {
            if !ids.insert(t.term.id().to_string()) {
                return Err(ModelError::InvalidMachine {
                    message: format!("term id {} appears twice", t.term.id()),
                });
            }
        }
        Ok(Model {
            spec,
            options,
            chain,
            terms,
            reading_terms,
            effects: effects.to_vec(),
            effect_ids,
            run_terms,
            run_reading_terms,
        })
    }

    /// The machine parameters (chain terms, then reading terms), in column order.
    pub fn parameters(&self) -> Vec<crate::Parameter> {
        let mut out: Vec<crate::Parameter> = self
            .terms
            .iter()
            .map(|t| crate::Parameter {
                id: t.term.id().to_string(),
                label: t.term.label().to_string(),
                unit: t.term.unit(),
                class: crate::ParamClass::Term(t.term.class()),
            })
            .collect();
        for r in &self.reading_terms {
            out.push(match r {
                ReadingTerm::PlaneMismatch(p) => crate::Parameter {
                    id: reading_id(r),
                    label: format!("servo mismatch {p} (the paper's plane term)"),
                    unit: Unit::Length,
                    class: crate::ParamClass::PlaneMismatch,
                },
                ReadingTerm::BarLength => crate::Parameter {
                    id: "BAR".into(),
                    label: "bar-length error (one bar for all runs)".into(),
                    unit: Unit::Length,
                    class: crate::ParamClass::BarLength,
                },
                ReadingTerm::BarGrowth => crate::Parameter {
                    id: "DBAR".into(),
                    label: "thermal growth of the bar with session time".into(),
                    unit: Unit::Rate,
                    class: crate::ParamClass::Term(TermClass::Effect),
                },
                ReadingTerm::RadiusLoss => crate::Parameter {
                    id: "LOSS".into(),
                    label: "servo radius loss, the square of a common lag".into(),
                    unit: Unit::TimeSquared,
                    class: crate::ParamClass::Term(TermClass::Effect),
                },
            });
        }
        out
    }

    /// The normalisation length (mm) of the axis that carries term `id`.
    pub fn polynomial_length(&self, id: &str) -> Option<f64> {
        self.terms.iter().find(|t| t.term.id() == id).and_then(|t| {
            // The length was taken from the spec's normalisation of the term's axis.
            let axis = self.chain.branch(t.branch)[t.joint].axis;
            self.spec.normalisation.iter().find(|n| n.axis == axis).map(|n| n.length_mm)
        })
    }
}

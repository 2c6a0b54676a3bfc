//! The kinematic chain: two branches of joints from the machine base, one carrying the tool,
//! one carrying the workpiece, and the first-order sensitivity of the ball-to-ball distance to a
//! small error motion of any joint.
//!
//! # Frames and signs
//! Each joint `j` has a frame. Its pose in its parent (the previous joint of the branch, or the
//! base) is
//! $$ {}^{p}T_{j}(q) = \mathrm{Trans}(o_j)\, M_j(\sigma q)\, E_j , $$
//! where `o_j` is the joint's `origin_mm`, `M_j` the nominal motion (translation along the unit
//! `direction` for a linear joint, rotation about it for a rotary joint), `q` the machine axis
//! coordinate, and `E_j` the joint's small error motion. `σ = +1` on the tool branch and `σ = -1`
//! on the workpiece branch: machine coordinates are the motion of the tool *relative to the
//! workpiece*, so a table that carries the workpiece moves the other way (ISO 841).
//!
//! Error motions are stated as ISO 230-1 states them: as the error of the tool relative to the
//! workpiece. A joint on the tool branch physically moves by its error motion `e = (δ, ε)`; a
//! joint on the workpiece branch physically moves by `-e`. Both then change the relative vector
//! `d = P_tool - P_table` by the same `J_j e`, with
//! $$ J_j = [\, R_{0j},\; -[p - o_j]_\times R_{0j} \,], $$
//! `R_{0j}`, `o_j` the joint frame's nominal orientation and origin in the base frame and `p` the
//! ball carried by that branch. So a parameter means the same thing on either branch.
//!
//! The ball-bar reading changes, to first order, by `ΔR = û · Δd` (`û = d/|d|`, paper eq. 3).

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use crate::axis::Axis;

/// Linear or rotary joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum JointKind {
    /// Translates along its direction; coordinate in mm.
    Linear,
    /// Rotates about its direction through its origin; coordinate in rad inside.
    Rotary,
}

/// Which branch a joint belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Branch {
    /// From the base to the spindle (tool ball).
    Tool,
    /// From the base to the table (table ball).
    Workpiece,
}

impl Branch {
    /// `σ`: +1 on the tool branch, -1 on the workpiece branch.
    pub fn sign(self) -> f64 {
        match self {
            Branch::Tool => 1.0,
            Branch::Workpiece => -1.0,
        }
    }
}

/// One joint of a branch.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// Human name (`"X table"`).
    pub name: String,
    /// The machine axis that drives it.
    pub axis: Axis,
    /// Linear or rotary.
    pub kind: JointKind,
    /// Unit direction of motion (or of the rotation axis) in the parent frame.
    pub direction: Vector3<f64>,
    /// Origin of the joint frame in the parent frame at zero axis coordinate, mm.
    pub origin: Vector3<f64>,
}

impl Joint {
    /// The nominal pose of the joint frame in its parent for axis coordinate `q` on `branch`,
    /// without error motion.
    pub fn nominal(&self, branch: Branch, q: f64) -> Isometry3<f64> {
        let s = branch.sign() * q;
        match self.kind {
            JointKind::Linear => Isometry3::from_parts(
                Translation3::from(self.origin + self.direction * s),
                UnitQuaternion::identity(),
            ),
            JointKind::Rotary => Isometry3::from_parts(
                Translation3::from(self.origin),
                UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(self.direction), s),
            ),
        }
    }
}

/// The two branches of a machine.
#[derive(Clone, Debug, PartialEq)]
pub struct KinematicChain {
    /// Base to spindle; the last frame is the spindle frame, its origin the gauge point.
    pub tool: Vec<Joint>,
    /// Base to table; the last frame is the table frame, its origin the table reference point
    /// when the axis coordinates are zero.
    pub workpiece: Vec<Joint>,
}

/// A small error motion: translation δ (mm) and rotation ε (rad) of a joint frame, in that frame.
pub type ErrorMotion = [f64; 6];

/// The exact rigid transform of a small error motion (rotation by the rotation vector ε).
pub fn error_transform(e: &ErrorMotion) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(e[0], e[1], e[2]),
        rotation_vector_quaternion(e[3], e[4], e[5]),
    )
}

/// The unit quaternion of the rotation vector `(x, y, z)`: `(cos(φ/2), sin(φ/2) n)`. Error
/// motions are tiny (|φ| ≲ 1e-3 rad), where the Taylor series to φ⁴ is exact to rounding: the
/// first omitted terms are φ⁶/46080 and φ⁶/645120 relative, < 1e-22 at φ = 1e-3. Larger
/// rotations take the closed form.
#[inline]
fn rotation_vector_quaternion(x: f64, y: f64, z: f64) -> UnitQuaternion<f64> {
    let phi2 = x * x + y * y + z * z;
    if phi2 < 1e-6 {
        let (w, k) =
            (1.0 - phi2 / 8.0 + phi2 * phi2 / 384.0, 0.5 - phi2 / 48.0 + phi2 * phi2 / 3840.0);
        UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(w, k * x, k * y, k * z))
    } else {
        UnitQuaternion::from_scaled_axis(Vector3::new(x, y, z))
    }
}

/// Nominal pose of every joint frame of a chain at one machine state, and the two balls.
#[derive(Clone, Debug, Default)]
pub struct ChainPose {
    /// Base-frame pose of each tool-branch joint frame.
    pub base_from_tool_joint: Vec<Isometry3<f64>>,
    /// Base-frame pose of each workpiece-branch joint frame.
    pub base_from_work_joint: Vec<Isometry3<f64>>,
    /// Tool-ball centre in the base frame, mm.
    pub tool_ball: Vector3<f64>,
    /// Table-ball centre in the base frame, mm.
    pub table_ball: Vector3<f64>,
}

/// Where the balls sit: the tool ball in the spindle frame, the table ball in the table frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BallSetup {
    /// Tool-ball centre in the spindle frame (from the gauge point), mm.
    pub tool_ball: Vector3<f64>,
    /// Table-ball centre in the last workpiece frame, mm: the work offset plus the run's
    /// `table_ball_mm` (see [`KinematicChain::ball_setup`]).
    pub table_ball: Vector3<f64>,
}

impl KinematicChain {
    /// Joints of one branch.
    pub fn branch(&self, branch: Branch) -> &[Joint] {
        match branch {
            Branch::Tool => &self.tool,
            Branch::Workpiece => &self.workpiece,
        }
    }

    /// Every axis that drives a joint, in axis order, without repeats.
    pub fn axes(&self) -> Vec<Axis> {
        let mut v: Vec<Axis> = self.tool.iter().chain(&self.workpiece).map(|j| j.axis).collect();
        v.sort();
        v.dedup();
        v
    }

    /// Poses of one branch at machine coordinates `q` (indexed by [`Axis::index`]), optionally
    /// with an exact error motion after each joint (`errors[j]`, relative-to-workpiece sense as
    /// in the module docs).
    pub fn branch_poses(
        &self,
        branch: Branch,
        q: &[f64; 6],
        errors: Option<&[ErrorMotion]>,
    ) -> Vec<Isometry3<f64>> {
        let mut out = Vec::with_capacity(self.branch(branch).len());
        self.branch_poses_into(branch, q, errors, &mut out);
        out
    }

    /// [`KinematicChain::branch_poses`] into a reused buffer (no allocation once it has grown).
    pub fn branch_poses_into(
        &self,
        branch: Branch,
        q: &[f64; 6],
        errors: Option<&[ErrorMotion]>,
        out: &mut Vec<Isometry3<f64>>,
    ) {
        out.clear();
        let mut pose = Isometry3::identity();
        let s = branch.sign();
        for (j, joint) in self.branch(branch).iter().enumerate() {
            match joint.kind {
                // A translation composes without a quaternion product.
                JointKind::Linear => {
                    let t = joint.origin + joint.direction * (s * q[joint.axis.index()]);
                    pose.translation.vector += pose.rotation * t;
                }
                JointKind::Rotary => pose *= joint.nominal(branch, q[joint.axis.index()]),
            }
            if let Some(errs) = errors {
                let e = errs[j];
                if e.iter().any(|&x| x != 0.0) {
                    let physical = [s * e[0], s * e[1], s * e[2], s * e[3], s * e[4], s * e[5]];
                    pose *= error_transform(&physical);
                }
            }
            out.push(pose);
        }
    }

    /// The nominal (or, with errors, the exact erroneous) poses and ball centres.
    pub fn pose(
        &self,
        q: &[f64; 6],
        balls: &BallSetup,
        tool_errors: Option<&[ErrorMotion]>,
        work_errors: Option<&[ErrorMotion]>,
    ) -> ChainPose {
        let mut out = ChainPose::default();
        self.pose_into(q, balls, tool_errors, work_errors, &mut out);
        out
    }

    /// [`KinematicChain::pose`] into a reused [`ChainPose`] (no allocation once it has grown).
    pub fn pose_into(
        &self,
        q: &[f64; 6],
        balls: &BallSetup,
        tool_errors: Option<&[ErrorMotion]>,
        work_errors: Option<&[ErrorMotion]>,
        out: &mut ChainPose,
    ) {
        self.branch_poses_into(Branch::Tool, q, tool_errors, &mut out.base_from_tool_joint);
        self.branch_poses_into(Branch::Workpiece, q, work_errors, &mut out.base_from_work_joint);
        let tool_end = out.base_from_tool_joint.last().copied().unwrap_or_else(Isometry3::identity);
        let work_end = out.base_from_work_joint.last().copied().unwrap_or_else(Isometry3::identity);
        out.tool_ball = (tool_end * nalgebra::Point3::from(balls.tool_ball)).coords;
        out.table_ball = (work_end * nalgebra::Point3::from(balls.table_ball)).coords;
    }

    /// Ball positions of a run: the tool ball as given, and the table ball placed so that the
    /// balls coincide at the pivot (axis coordinates `pivot` with rotary axes at zero). That
    /// placement is the run's work offset (G54): the table reference point is where the run
    /// file says it is, relative to the table ball.
    pub fn ball_setup(&self, pivot: &[f64; 3], tool_ball: &[f64; 3]) -> BallSetup {
        let tool_ball = Vector3::from(*tool_ball);
        let mut q = [0.0; 6];
        q[..3].copy_from_slice(pivot);
        let tool = self.branch_poses(Branch::Tool, &q, None);
        let work = self.branch_poses(Branch::Workpiece, &q, None);
        let tool_end = tool.last().copied().unwrap_or_else(Isometry3::identity);
        let work_end = work.last().copied().unwrap_or_else(Isometry3::identity);
        let p_tool = tool_end * nalgebra::Point3::from(tool_ball);
        let table_ball = (work_end.inverse() * p_tool).coords;
        BallSetup { tool_ball, table_ball }
    }
}

/// The first-order sensitivity of ΔR to the error motion of one joint: `ΔR = g_t·δ + g_r·ε`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct JointSensitivity {
    /// Sensitivity to the translation δ (in the joint frame), dimensionless.
    pub translation: [f64; 3],
    /// Sensitivity to the rotation ε (in the joint frame), mm per rad.
    pub rotation: [f64; 3],
}

impl JointSensitivity {
    /// ΔR for an error motion.
    #[inline]
    pub fn apply(&self, e: &ErrorMotion) -> f64 {
        self.translation[0] * e[0]
            + self.translation[1] * e[1]
            + self.translation[2] * e[2]
            + self.rotation[0] * e[3]
            + self.rotation[1] * e[4]
            + self.rotation[2] * e[5]
    }
}

/// Sensitivities of ΔR to every joint's error motion at one pose.
///
/// With `û` the unit bar direction, `R` and `o` the joint frame's orientation and origin, `p`
/// the ball of the joint's branch: `g_t = Rᵀ û`, `g_r = Rᵀ ((p - o) × û)`, since
/// `û · ((R ε) × (p - o)) = (R ε) · ((p - o) × û)`.
pub fn sensitivities(
    pose: &ChainPose,
    tool: &mut Vec<JointSensitivity>,
    work: &mut Vec<JointSensitivity>,
) -> Vector3<f64> {
    let d = pose.tool_ball - pose.table_ball;
    sensitivities_along(pose, &(d / d.norm()), tool, work);
    d
}

/// Sensitivities of `u·Δ` to every joint's error motion at one pose, for any unit direction
/// `u` (the bar's direction in [`sensitivities`]; a base axis for the components of `Δ`).
pub fn sensitivities_along(
    pose: &ChainPose,
    u: &Vector3<f64>,
    tool: &mut Vec<JointSensitivity>,
    work: &mut Vec<JointSensitivity>,
) {
    let u = *u;
    let one = |frame: &Isometry3<f64>, ball: &Vector3<f64>| {
        let rt: Matrix3<f64> = frame.rotation.to_rotation_matrix().into_inner().transpose();
        let gt = rt * u;
        let arm = ball - frame.translation.vector;
        let gr = rt * arm.cross(&u);
        JointSensitivity { translation: [gt.x, gt.y, gt.z], rotation: [gr.x, gr.y, gr.z] }
    };
    tool.clear();
    work.clear();
    tool.extend(pose.base_from_tool_joint.iter().map(|f| one(f, &pose.tool_ball)));
    work.extend(pose.base_from_work_joint.iter().map(|f| one(f, &pose.table_ball)));
}

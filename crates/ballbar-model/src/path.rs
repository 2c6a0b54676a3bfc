//! Commanded paths of ballbar tests: the nominal circle a CNC program would run.

use nalgebra::{Matrix3, Vector3};

use crate::axis::{Axis, Direction, Plane};
use crate::chain::{BallSetup, Branch, KinematicChain};
use crate::design::table_rotation;
use crate::run::{Run, RunHeader};

/// Resolution of axis coordinates in run files, mm: commanded paths are rounded to it so that a
/// simulated run and the file written from it carry the same path.
pub const POSITION_RESOLUTION_MM: f64 = 1e-6;

/// A planar circle test.
#[derive(Clone, Debug, PartialEq)]
pub struct CircleTest {
    /// Plane (not `Free`).
    pub plane: Plane,
    /// Direction.
    pub direction: Direction,
    /// Radius, mm.
    pub radius_mm: f64,
    /// Feed, mm/min.
    pub feed_mm_per_min: f64,
    /// Pivot, mm.
    pub pivot_mm: [f64; 3],
    /// Table ball, mm.
    pub table_ball_mm: [f64; 3],
    /// Tool ball, mm.
    pub tool_ball_mm: [f64; 3],
    /// Sampling rate, Hz.
    pub sample_rate_hz: f64,
    /// Start angle, degrees from +U.
    pub start_deg: f64,
    /// Swept angle, degrees (360 for a full circle, 220 for a partial arc).
    pub sweep_deg: f64,
}

impl CircleTest {
    /// Angular speed, rad/s.
    pub fn omega(&self) -> f64 {
        self.feed_mm_per_min / 60.0 / self.radius_mm
    }

    /// Duration of the sweep, s.
    pub fn duration_s(&self) -> f64 {
        self.sweep_deg.to_radians() / self.omega()
    }

    /// The nominal (unrounded) axis coordinates at time `t` (may be negative: lead-in).
    pub fn position(&self, t: f64) -> [f64; 6] {
        let (u, v, _) = self.plane.axes().expect("planar circle");
        let th = self.start_deg.to_radians() + self.direction.angular_sign() * self.omega() * t;
        let mut q = [0.0; 6];
        q[..3].copy_from_slice(&self.pivot_mm);
        q[u.index()] += self.radius_mm * th.cos();
        q[v.index()] += self.radius_mm * th.sin();
        q
    }

    /// The commanded run: samples at the sampling rate over the sweep, positions rounded to
    /// [`POSITION_RESOLUTION_MM`], `dr_mm` zero. Axes X, Y, Z are present.
    pub fn run(
        &self,
        started_at: &str,
        started_at_unix_s: f64,
        run_id: &str,
        machine: &str,
    ) -> Run {
        let n = (self.duration_s() * self.sample_rate_hz + 1e-9).floor() as usize + 1;
        let mut t_s = Vec::with_capacity(n);
        let mut cols: [Vec<f64>; 3] = Default::default();
        for k in 0..n {
            let t = k as f64 / self.sample_rate_hz;
            let q = self.position(t);
            t_s.push(t);
            for a in Axis::LINEAR {
                cols[a.index()]
                    .push((q[a.index()] / POSITION_RESOLUTION_MM).round() * POSITION_RESOLUTION_MM);
            }
        }
        let [x, y, z] = cols;
        commanded(
            RunHeader {
                format_version: 1,
                machine: Some(machine.to_string()),
                plane: self.plane,
                direction: Some(self.direction),
                radius_mm: self.radius_mm,
                feed_mm_per_min: self.feed_mm_per_min,
                pivot_mm: self.pivot_mm,
                table_ball_mm: self.table_ball_mm,
                tool_ball_mm: self.tool_ball_mm,
                defaulted: crate::run::DefaultedKeys::default(),
                started_at: started_at.to_string(),
                started_at_unix_s,
                run_id: Some(run_id.to_string()),
                // A partial arc states its arc, so that a reader tells it from a circle cut short.
                extra: if self.sweep_deg == 360.0 {
                    Vec::new()
                } else {
                    vec![("arc_deg".to_string(), self.sweep_deg.to_string())]
                },
            },
            t_s,
            [Some(x), Some(y), Some(z), None, None, None],
        )
    }
}

/// How the bar lies in a rotary test, relative to the first turning axis at the path's start;
/// it then stays fixed in the table frame (ISO 10791-6: the tool ball follows the table ball).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BarDirection {
    /// Perpendicular to the axis line, outward through the table ball: the tool ball is
    /// farther from the axis than the table ball.
    Radial,
    /// Along the tool ball's motion relative to the table ball as the axis coordinate
    /// increases (the + sense of ISO 841 machine coordinates, whichever branch turns).
    Tangential,
    /// Along the axis's + direction (the rotation axis as the chain carries it).
    Axial,
}

/// One rotary axis turning in a rotary test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Turn {
    /// The rotary axis.
    pub axis: Axis,
    /// Axis coordinate at the start, degrees.
    pub start_deg: f64,
    /// Signed sweep, degrees: the coordinate goes from `start_deg` to `start_deg + sweep_deg`.
    pub sweep_deg: f64,
}

/// A rotary-axis ballbar test (ISO 10791-6 style, BK1/BK2; BK4 with two turning axes): one or
/// more rotary axes turn together, each linearly along the path, the others held, and the
/// linear axes move so that the tool ball stays on the bar's far end, the bar fixed in the
/// table frame. The path is the machine's nominal chain solved exactly for X, Y, Z at each
/// sample.
///
/// Conventions (the run format's `plane: free`): `pivot_mm` is the (X, Y, Z) at which the tool
/// ball sits on the table ball with every rotary axis at 0, which places the table ball on the
/// table; `feed_mm_per_min` is the speed of the commanded (X, Y, Z) point, so the samples are
/// spaced evenly along its path; `direction` is the sense of the turning axis (`CCW` when its
/// sweep is positive), left out when several turn together.
#[derive(Clone, Debug, PartialEq)]
pub struct RotaryTest {
    /// The turning axes (at least one); every other rotary axis of the chain is held at the
    /// angle in `hold` or at 0.
    pub turns: Vec<Turn>,
    /// Rotary axes held at a non-zero angle, degrees.
    pub hold: Vec<(Axis, f64)>,
    /// The bar's direction at the start, relative to the first turning axis.
    pub bar: BarDirection,
    /// Nominal bar length, mm.
    pub radius_mm: f64,
    /// Speed of the commanded (X, Y, Z) point, mm/min.
    pub feed_mm_per_min: f64,
    /// (X, Y, Z) at which the balls coincide with every rotary axis at 0, mm.
    pub pivot_mm: [f64; 3],
    /// Tool ball in the spindle frame, mm.
    pub tool_ball_mm: [f64; 3],
    /// Sampling rate, Hz.
    pub sample_rate_hz: f64,
}

/// Why a rotary test has no path.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PathError {
    /// Something of the test itself.
    #[error("rotary test: {0}")]
    Test(String),
}

/// The rounding of rotary coordinates in run files: 1e-6 degree (µrad/57), far below any
/// rotary error a ballbar sees.
pub const ANGLE_RESOLUTION_DEG: f64 = 1e-6;

impl RotaryTest {
    fn check(&self, chain: &KinematicChain) -> Result<(), PathError> {
        let axes = chain.axes();
        if self.turns.is_empty() {
            return Err(PathError::Test("no turning axis".into()));
        }
        for (k, t) in self.turns.iter().enumerate() {
            if !t.axis.is_rotary() || !axes.contains(&t.axis) {
                return Err(PathError::Test(format!(
                    "{} is not a rotary axis of this machine (its axes: {})",
                    t.axis,
                    names(&axes)
                )));
            }
            if self.turns[..k].iter().any(|o| o.axis == t.axis)
                || self.hold.iter().any(|h| h.0 == t.axis)
            {
                return Err(PathError::Test(format!("{} is given twice", t.axis)));
            }
            if !(t.sweep_deg.is_finite() && t.sweep_deg != 0.0 && t.start_deg.is_finite()) {
                return Err(PathError::Test(format!(
                    "{}'s start and sweep must be finite and the sweep not zero",
                    t.axis
                )));
            }
        }
        for &(a, deg) in &self.hold {
            if !a.is_rotary() || !axes.contains(&a) || !deg.is_finite() {
                return Err(PathError::Test(format!(
                    "held axis {a} is not a rotary axis of this machine, or its angle is not finite"
                )));
            }
        }
        if !(self.radius_mm > 0.0 && self.feed_mm_per_min > 0.0 && self.sample_rate_hz > 0.0) {
            return Err(PathError::Test(
                "radius_mm, feed_mm_per_min and sample_rate_hz must be positive".into(),
            ));
        }
        Ok(())
    }

    /// The machine coordinates (rotary in rad) at path parameter `s` ∈ [0, 1], X, Y, Z not yet
    /// solved (at the pivot).
    fn rotary_at(&self, s: f64) -> [f64; 6] {
        let mut q = [0.0; 6];
        q[..3].copy_from_slice(&self.pivot_mm);
        for &(a, deg) in &self.hold {
            q[a.index()] = deg.to_radians();
        }
        for t in &self.turns {
            q[t.axis.index()] = (t.start_deg + s * t.sweep_deg).to_radians();
        }
        q
    }

    /// The bar direction in the table frame, and the ball set-up.
    fn geometry(&self, chain: &KinematicChain) -> Result<(BallSetup, Vector3<f64>), PathError> {
        let balls = chain.ball_setup(&self.pivot_mm, &self.tool_ball_mm);
        let q = self.rotary_at(0.0);
        let pose = chain.pose(&q, &balls, None, None);
        let first = self.turns[0].axis;
        let (branch, j) = chain
            .tool
            .iter()
            .position(|j| j.axis == first)
            .map(|j| (Branch::Tool, j))
            .or_else(|| {
                chain.workpiece.iter().position(|j| j.axis == first).map(|j| (Branch::Workpiece, j))
            })
            .expect("checked: the axis drives a joint");
        let (frame, joint) = match branch {
            Branch::Tool => (pose.base_from_tool_joint[j], &chain.tool[j]),
            Branch::Workpiece => (pose.base_from_work_joint[j], &chain.workpiece[j]),
        };
        // The frame after a rotary joint's nominal motion has its origin on the axis line and
        // the joint's direction along it.
        let axis = (frame.rotation * joint.direction).normalize();
        let centre = frame.translation.vector;
        let arm = pose.table_ball - centre;
        let radial = arm - axis * axis.dot(&arm);
        let u0 = match self.bar {
            BarDirection::Axial => axis,
            BarDirection::Radial | BarDirection::Tangential => {
                if radial.norm() < MIN_ARM_MM {
                    return Err(PathError::Test(format!(
                        "the table ball is {:.3} mm from the {first} axis line: a radial or tangential bar needs it at least {MIN_ARM_MM} mm away",
                        radial.norm()
                    )));
                }
                let radial = radial.normalize();
                match self.bar {
                    BarDirection::Radial => radial,
                    // The tool ball's motion relative to the table ball as the coordinate
                    // increases, the linear axes held (ISO 841: machine coordinates are the
                    // tool's motion relative to the workpiece, so a table axis turns the table
                    // the other way and the tool goes round it in the + sense; a head axis
                    // swings the tool ball itself).
                    _ => {
                        let mut q1 = q;
                        q1[first.index()] += 1e-6;
                        let p1 = chain.pose(&q1, &balls, None, None);
                        let moved =
                            (p1.tool_ball - p1.table_ball) - (pose.tool_ball - pose.table_ball);
                        let t = moved - axis * axis.dot(&moved);
                        if t.norm() < 1e-9 * MIN_ARM_MM {
                            return Err(PathError::Test(format!(
                                "turning {first} does not move the tool ball relative to the table ball: no tangential direction"
                            )));
                        }
                        t.normalize()
                    }
                }
            }
        };
        let table = table_rotation(&pose);
        Ok((balls, table.inverse() * u0))
    }

    /// X, Y, Z at the rotary coordinates of `q` that put the tool ball at the bar's far end:
    /// the balls' difference is affine in X, Y, Z at fixed rotary coordinates (linear joints
    /// translate), so Newton's step from the pivot is exact; a second removes its rounding.
    fn solve_xyz(
        &self,
        chain: &KinematicChain,
        balls: &BallSetup,
        u_table: &Vector3<f64>,
        q: &mut [f64; 6],
    ) -> Result<(), PathError> {
        let miss = |q: &[f64; 6]| {
            let p = chain.pose(q, balls, None, None);
            p.tool_ball - (p.table_ball + table_rotation(&p) * u_table * self.radius_mm)
        };
        for _ in 0..2 {
            let f0 = miss(q);
            let mut jac = Matrix3::zeros();
            for a in 0..3 {
                let mut qa = *q;
                qa[a] += 1.0;
                jac.set_column(a, &(miss(&qa) - f0));
            }
            let step = jac.try_inverse().ok_or_else(|| PathError::Test("the linear axes cannot move the tool ball relative to the table ball in every direction".into()))? * f0;
            for a in 0..3 {
                q[a] -= step[a];
            }
        }
        Ok(())
    }

    /// The commanded run: X, Y, Z solved at each sample, every rotary axis of the chain as a
    /// column (turning, held or at 0), samples evenly spaced in time along the (X, Y, Z) path
    /// at the feed, positions rounded to [`POSITION_RESOLUTION_MM`] and
    /// [`ANGLE_RESOLUTION_DEG`]; `dr_mm` zero.
    pub fn run(
        &self,
        chain: &KinematicChain,
        started_at: &str,
        started_at_unix_s: f64,
        run_id: &str,
        machine: &str,
    ) -> Result<Run, PathError> {
        self.check(chain)?;
        let (balls, u_table) = self.geometry(chain)?;
        let at = |s: f64| -> Result<[f64; 6], PathError> {
            let mut q = self.rotary_at(s);
            self.solve_xyz(chain, &balls, &u_table, &mut q)?;
            Ok(q)
        };
        // Arc length of the (X, Y, Z) path on a fine grid of the parameter: one step per 0.05°
        // of the largest sweep, at least 2,000 (the chord of a 0.05° step is 1e-8 relative
        // short of its arc: far below the feed's precision).
        let largest = self.turns.iter().map(|t| t.sweep_deg.abs()).fold(0.0, f64::max);
        let steps = ((largest / 0.05).ceil() as usize).max(2000);
        let mut length = Vec::with_capacity(steps + 1);
        length.push(0.0);
        let mut last = at(0.0)?;
        for k in 1..=steps {
            let q = at(k as f64 / steps as f64)?;
            let d =
                ((q[0] - last[0]).powi(2) + (q[1] - last[1]).powi(2) + (q[2] - last[2]).powi(2))
                    .sqrt();
            length.push(length[k - 1] + d);
            last = q;
        }
        let total = length[steps];
        if total < MIN_ARM_MM {
            return Err(PathError::Test(format!(
                "the commanded (X, Y, Z) point moves {total:.3} mm over the whole test: the feed, its speed, cannot time it (put the table ball off the axis line)"
            )));
        }
        let duration = total / (self.feed_mm_per_min / 60.0);
        let n = (duration * self.sample_rate_hz + 1e-9).floor() as usize + 1;
        let axes = chain.axes();
        let mut cols: [Vec<f64>; 6] = Default::default();
        let mut t_s = Vec::with_capacity(n);
        for k in 0..n {
            let t = k as f64 / self.sample_rate_hz;
            // The parameter at this arc length (linear between grid points).
            let target = (t / duration).min(1.0) * total;
            let i = length.partition_point(|&l| l < target).clamp(1, steps);
            let (l0, l1) = (length[i - 1], length[i]);
            let s = ((i - 1) as f64 + if l1 > l0 { (target - l0) / (l1 - l0) } else { 0.0 })
                / steps as f64;
            let q = at(s)?;
            t_s.push(t);
            for a in &axes {
                let v = if a.is_rotary() {
                    (q[a.index()].to_degrees() / ANGLE_RESOLUTION_DEG).round()
                        * ANGLE_RESOLUTION_DEG
                } else {
                    (q[a.index()] / POSITION_RESOLUTION_MM).round() * POSITION_RESOLUTION_MM
                };
                cols[a.index()].push(if a.is_rotary() { v.to_radians() } else { v });
            }
        }
        let mut columns: [Option<Vec<f64>>; 6] = Default::default();
        for a in Axis::ALL {
            if axes.contains(&a) || !a.is_rotary() {
                columns[a.index()] = Some(std::mem::take(&mut cols[a.index()]));
            }
        }
        let direction = (self.turns.len() == 1)
            .then(|| if self.turns[0].sweep_deg > 0.0 { Direction::CCW } else { Direction::CW });
        Ok(commanded(
            RunHeader {
                format_version: 1,
                machine: Some(machine.to_string()),
                plane: Plane::Free,
                direction,
                radius_mm: self.radius_mm,
                feed_mm_per_min: self.feed_mm_per_min,
                pivot_mm: self.pivot_mm,
                table_ball_mm: balls.table_ball.into(),
                tool_ball_mm: self.tool_ball_mm,
                defaulted: crate::run::DefaultedKeys::default(),
                started_at: started_at.to_string(),
                started_at_unix_s,
                run_id: Some(run_id.to_string()),
                extra: Vec::new(),
            },
            t_s,
            columns,
        ))
    }
}

/// A commanded run: the path's samples, readings zero, its source `<run_id>.csv` with the
/// samples on the lines after a run file's header.
fn commanded(header: RunHeader, t_s: Vec<f64>, axes: [Option<Vec<f64>>; 6]) -> Run {
    let n = t_s.len();
    let id = header.run_id.clone().unwrap_or_default();
    Run {
        header,
        source: format!("{id}.csv"),
        lines: (0..n as u32).map(|k| k + 13).collect(),
        dr_mm: vec![0.0; n],
        t_s,
        axes,
    }
}

/// A radial or tangential bar needs the table ball this far from the axis line, and the
/// commanded point must move this far, mm: below it the direction (or the timing) is set by
/// rounding.
pub const MIN_ARM_MM: f64 = 1.0;

fn names(axes: &[Axis]) -> String {
    axes.iter().map(|a| a.name()).collect::<Vec<_>>().join(", ")
}

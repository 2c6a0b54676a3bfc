//! Commanded paths of ballbar tests: the nominal circle a CNC program would run.

use crate::axis::{Axis, Direction, Plane};
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
    pub fn run(&self, started_at: &str, started_at_unix_s: f64, run_id: &str, machine: &str) -> Run {
        let n = (self.duration_s() * self.sample_rate_hz + 1e-9).floor() as usize + 1;
        let mut t_s = Vec::with_capacity(n);
        let mut cols: [Vec<f64>; 3] = Default::default();
        for k in 0..n {
            let t = k as f64 / self.sample_rate_hz;
            let q = self.position(t);
            t_s.push(t);
            for a in Axis::LINEAR {
                cols[a.index()].push((q[a.index()] / POSITION_RESOLUTION_MM).round() * POSITION_RESOLUTION_MM);
            }
        }
        let [x, y, z] = cols;
        Run {
            header: RunHeader {
                format_version: 1,
                machine: Some(machine.to_string()),
                plane: self.plane,
                direction: Some(self.direction),
                radius_mm: self.radius_mm,
                feed_mm_per_min: self.feed_mm_per_min,
                pivot_mm: self.pivot_mm,
                table_ball_mm: self.table_ball_mm,
                tool_ball_mm: self.tool_ball_mm,
                started_at: started_at.to_string(),
                started_at_unix_s,
                run_id: Some(run_id.to_string()),
                extra: Vec::new(),
            },
            source: format!("{run_id}.csv"),
            lines: (0..n as u32).map(|k| k + 13).collect(),
            dr_mm: vec![0.0; n],
            t_s,
            axes: [Some(x), Some(y), Some(z), None, None, None],
        }
    }
}

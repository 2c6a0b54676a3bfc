//! The design matrix of a set of runs: one row per sample, one column per parameter (machine
//! parameters first, then the per-run centring nuisances), so that `ΔR ≈ A θ`.

use nalgebra::Vector3;

use crate::axis::{Axis, Plane};
use crate::chain::{sensitivities, BallSetup, Branch, JointSensitivity};
use crate::machine::{BarLength, Model, ReadingTerm};
use crate::run::Run;
use crate::term::{JointState, Unit};
use crate::{ModelError, ParamClass, Parameter};

/// Tolerance on the nominal ball distance against the run's radius: the run-format spec's 1 mm.
const RADIUS_TOLERANCE_MM: f64 = 1.0;

/// Direction dead band, mm (or rad): run files carry 1e-6 mm, so a two-sample difference
/// smaller than this is zero motion (a reversal sample), not noise.
const DIRECTION_DEAD_BAND: f64 = 1e-9;

/// A run prepared for row evaluation.
#[derive(Clone, Debug)]
struct Prepared {
    balls: BallSetup,
    centring: Vec<Axis>,
    first_centring_column: usize,
}

/// The design of a model over a set of runs.
#[derive(Debug)]
pub struct Design<'a> {
    /// The model.
    pub model: &'a Model,
    /// The runs, in order.
    pub runs: &'a [Run],
    /// All parameters: machine parameters then centring per run.
    pub parameters: Vec<Parameter>,
    /// Number of machine parameters (the leading columns).
    pub n_machine: usize,
    prepared: Vec<Prepared>,
    chain_axes: Vec<Axis>,
    linear_only: bool,
}

/// Scratch space reused across rows.
#[derive(Debug, Default)]
pub struct RowScratch {
    tool: Vec<JointSensitivity>,
    work: Vec<JointSensitivity>,
}

/// The centring axes of a run: the two in-plane axes of a planar test, X, Y, Z of a free path.
fn centring_axes(plane: Plane) -> Vec<Axis> {
    match plane.axes() {
        Some((u, v, _)) => vec![u, v],
        None => Axis::LINEAR.to_vec(),
    }
}

/// Axis velocity by central difference (one-sided at the ends) and its direction sign.
#[inline]
pub fn velocity_and_direction(t: &[f64], q: &[f64], i: usize) -> (f64, f64) {
    let n = q.len();
    if n < 2 {
        return (0.0, 0.0);
    }
    let (a, b) = if i == 0 { (0, 1) } else if i + 1 == n { (n - 2, n - 1) } else { (i - 1, i + 1) };
    let dq = q[b] - q[a];
    let v = dq / (t[b] - t[a]);
    let dir = if dq > DIRECTION_DEAD_BAND {
        1.0
    } else if dq < -DIRECTION_DEAD_BAND {
        -1.0
    } else {
        0.0
    };
    (v, dir)
}

impl<'a> Design<'a> {
    /// Prepare the design; checks that every run has the axes the chain needs and that the
    /// chain's nominal ball distance matches each run's radius.
    pub fn new(model: &'a Model, runs: &'a [Run]) -> Result<Design<'a>, ModelError> {
        let mut parameters = model.parameters();
        let n_machine = parameters.len();
        let chain_axes = model.chain.axes();
        let mut prepared = Vec::with_capacity(runs.len());
        for run in runs {
            for &a in &chain_axes {
                if run.axis(a).is_none() {
                    return Err(ModelError::MissingAxis { source_name: run.source.clone(), axis: a, machine: model.spec.name.clone() });
                }
            }
            let h = &run.header;
            let balls = model.chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
            let mut q = [0.0; 6];
            for i in 0..run.len() {
                fill_q(run, i, &mut q);
                let pose = model.chain.pose(&q, &balls, None, None);
                let dist = (pose.tool_ball - pose.table_ball).norm();
                if (dist - h.radius_mm).abs() > RADIUS_TOLERANCE_MM || !dist.is_finite() {
                    return Err(ModelError::RadiusMismatch {
                        source_name: run.source.clone(),
                        line: run.lines.get(i).copied().unwrap_or(0),
                        distance_mm: dist,
                        radius_mm: h.radius_mm,
                    });
                }
            }
            let centring = centring_axes(h.plane);
            let first = parameters.len();
            for a in &centring {
                parameters.push(Parameter {
                    id: format!("C{a}@{}", run.name()),
                    label: format!("centring offset {a} of run {}", run.name()),
                    unit: Unit::Length,
                    class: ParamClass::Centring,
                });
            }
            prepared.push(Prepared { balls, centring, first_centring_column: first });
        }
        let linear_only = chain_axes.iter().all(|a| !a.is_rotary()) && Axis::LINEAR.iter().all(|a| chain_axes.contains(a));
        Ok(Design { model, runs, parameters, n_machine, prepared, chain_axes, linear_only })
    }

    /// Number of columns.
    pub fn n_cols(&self) -> usize {
        self.parameters.len()
    }

    /// Total number of rows (samples of all runs).
    pub fn n_rows(&self) -> usize {
        self.runs.iter().map(Run::len).sum()
    }

    /// The columns of run `r`'s centring parameters.
    pub fn centring_columns(&self, r: usize) -> std::ops::Range<usize> {
        let p = &self.prepared[r];
        p.first_centring_column..p.first_centring_column + p.centring.len()
    }

    /// Fill `out` (length [`Design::n_cols`]) with row `i` of run `r` and return the target: the
    /// measured ΔR in mm, less a known bar-length error.
    pub fn row(&self, r: usize, i: usize, scratch: &mut RowScratch, out: &mut [f64]) -> f64 {
        out.fill(0.0);
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let h = &run.header;
        let mut q = [0.0; 6];
        fill_q(run, i, &mut q);
        let pose = self.model.chain.pose(&q, &prep.balls, None, None);
        let d = sensitivities(&pose, &mut scratch.tool, &mut scratch.work);
        let states = self.states(r, i);
        for (k, bt) in self.model.terms.iter().enumerate() {
            let joint = &self.model.chain.branch(bt.branch)[bt.joint];
            let sens = match bt.branch {
                Branch::Tool => &scratch.tool[bt.joint],
                Branch::Workpiece => &scratch.work[bt.joint],
            };
            out[k] = sens.apply(&bt.term.basis(&states[joint.axis.index()]));
        }
        let mut k = self.model.terms.len();
        let dn = d.norm();
        for rt in &self.model.reading_terms {
            out[k] = reading_basis(rt, h.plane, h.direction.map(|d| d.paper_sign()).unwrap_or(0.0), &d, h.radius_mm);
            k += 1;
        }
        // Centring: the table ball sits at its nominal place plus e, so d shrinks by e.
        let u: Vector3<f64> = d / dn;
        for (c, a) in prep.centring.iter().enumerate() {
            out[prep.first_centring_column + c] = -u[a.index()];
        }
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        run.dr_mm[i] - known
    }

    /// The commanded joint states of sample `i` of run `r`.
    pub fn states(&self, r: usize, i: usize) -> [JointState; 6] {
        let run = &self.runs[r];
        let feed = run.header.feed_mm_per_s();
        let t = run.t_s[i];
        let mut states = [JointState::default(); 6];
        for &a in &self.chain_axes {
            let col = run.axis(a).expect("checked in Design::new");
            let (v, dir) = velocity_and_direction(&run.t_s, col, i);
            states[a.index()] = JointState { q: col[i], velocity: v, direction: dir, t_s: t, feed_mm_per_s: feed };
        }
        // A ballbar path keeps |d| = R, so the commanded relative velocity is tangential. The
        // finite difference has an O(h) radial part at a run's two end samples (one-sided); left
        // there, it would make a common servo lag look (weakly) identifiable. On machines of
        // linear axes, d = q - pivot: project the velocity onto the tangent plane.
        if self.linear_only && run.header.plane != Plane::Free {
            let p = run.header.pivot_mm;
            let d = Vector3::new(states[0].q - p[0], states[1].q - p[1], states[2].q - p[2]);
            let v = Vector3::new(states[0].velocity, states[1].velocity, states[2].velocity);
            let dn2 = d.norm_squared();
            if dn2 > 0.0 {
                let vt = v - d * (v.dot(&d) / dn2);
                for k in 0..3 {
                    states[k].velocity = vt[k];
                }
            }
        }
        states
    }

    /// The model's ΔR (mm) at sample `i` of run `r` without linearisation: every error motion
    /// applied as a rigid transform, the centring as a displacement of the table ball, the
    /// distance taken exactly ([`exact_length`]); reading terms and bar length added.
    pub fn exact(&self, r: usize, i: usize, theta: &[f64]) -> f64 {
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let h = &run.header;
        let mut q = [0.0; 6];
        fill_q(run, i, &mut q);
        let states = self.states(r, i);
        let mut e = Vector3::zeros();
        for (c, a) in prep.centring.iter().enumerate() {
            e[a.index()] = theta[prep.first_centring_column + c];
        }
        let length = exact_length(self.model, &q, &states, &prep.balls, &e, &|k| theta[k], false);
        let nominal = self.model.chain.pose(&q, &prep.balls, None, None);
        let d = nominal.tool_ball - nominal.table_ball;
        let mut reading = length - h.radius_mm;
        let paper_sign = h.direction.map(|d| d.paper_sign()).unwrap_or(0.0);
        for (k, rt) in self.model.reading_terms.iter().enumerate() {
            reading += theta[self.model.terms.len() + k] * reading_basis(rt, h.plane, paper_sign, &d, h.radius_mm);
        }
        if let BarLength::Known(b) = self.model.options.bar_length {
            reading += b;
        }
        reading
    }

    /// The model's ΔR (mm) at every sample of run `r` for parameters `theta` (all columns).
    pub fn predict_run(&self, r: usize, theta: &[f64]) -> Vec<f64> {
        let mut scratch = RowScratch::default();
        let mut row = vec![0.0; self.n_cols()];
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        (0..self.runs[r].len())
            .map(|i| {
                self.row(r, i, &mut scratch, &mut row);
                row.iter().zip(theta).map(|(a, b)| a * b).sum::<f64>() + known
            })
            .collect()
    }
}

/// The exact ball distance (mm) at machine state `q`: each chain term `k` contributes the error
/// motion `coeff(k) · basis_k(state)` to its joint, applied as a rigid transform; the table ball
/// is displaced by `centring` (base frame). With `skip_lag`, servo-lag terms are left out (a
/// simulator realises them in the time domain instead).
pub fn exact_length(
    model: &Model,
    q: &[f64; 6],
    states: &[JointState; 6],
    balls: &BallSetup,
    centring: &Vector3<f64>,
    coeff: &dyn Fn(usize) -> f64,
    skip_lag: bool,
) -> f64 {
    let chain = &model.chain;
    let mut tool = vec![[0.0; 6]; chain.tool.len()];
    let mut work = vec![[0.0; 6]; chain.workpiece.len()];
    for (k, bt) in model.terms.iter().enumerate() {
        if skip_lag && bt.term.class() == crate::TermClass::ServoLag {
            continue;
        }
        let c = coeff(k);
        if c == 0.0 {
            continue;
        }
        let axis = chain.branch(bt.branch)[bt.joint].axis;
        let b = bt.term.basis(&states[axis.index()]);
        let target = match bt.branch {
            Branch::Tool => &mut tool[bt.joint],
            Branch::Workpiece => &mut work[bt.joint],
        };
        for (t, bk) in target.iter_mut().zip(b) {
            *t += c * bk;
        }
    }
    let pose = chain.pose(q, balls, Some(&tool), Some(&work));
    (pose.tool_ball - (pose.table_ball + centring)).norm()
}

/// The basis of a reading term at one sample.
pub fn reading_basis(rt: &ReadingTerm, plane: Plane, paper_sign: f64, d: &Vector3<f64>, radius_mm: f64) -> f64 {
    match rt {
        ReadingTerm::BarLength => 1.0,
        ReadingTerm::PlaneMismatch(p) => {
            if *p != plane {
                return 0.0;
            }
            let (ua, va, _) = p.axes().expect("planar");
            (d[ua.index()] / radius_mm) * (d[va.index()] / radius_mm) * paper_sign
        }
    }
}

/// The machine state of sample `i` (axes the run lacks stay 0).
pub fn fill_q(run: &Run, i: usize, q: &mut [f64; 6]) {
    for a in Axis::ALL {
        q[a.index()] = run.axis(a).map(|c| c[i]).unwrap_or(0.0);
    }
}

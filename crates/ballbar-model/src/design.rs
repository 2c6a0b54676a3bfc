//! The design matrix of a set of runs: one row per sample, one column per parameter (machine
//! parameters first, then the per-run centring nuisances), so that `ΔR ≈ A θ`.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

use nalgebra::Vector3;

use crate::axis::{Axis, Plane};
use crate::chain::{BallSetup, Branch, ChainPose, ErrorMotion, JointSensitivity, sensitivities};
use crate::machine::{BarLength, Model, ReadingTerm, reading_id};
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
    /// The first column of the run's own coefficients of the model's run terms (after its
    /// centring).
    first_run_term_column: usize,
    /// Commanded reversal times of each axis within the run, s, ascending.
    reversals: [Vec<f64>; 6],
    /// Each axis's direction of motion after its last commanded reversal (its last sample's
    /// that moves; 0 for an axis at rest throughout).
    final_direction: [f64; 6],
    /// The run's start less the design's time origin ([`Design::origin_unix_s`]), s.
    session_offset_s: f64,
    /// Every rotary axis of the chain reads zero throughout the run (none for a machine of
    /// linear axes), as planar tests hold them: the balls then sit as `ball_setup` placed them.
    rotary_at_zero: bool,
    /// The run's geometry, shared with the designs made from this one
    /// ([`Design::with_model`]: same chain, same runs).
    geometry: Arc<Geometry>,
}

/// What every evaluation of a run needs and no parameter changes: the joint states and the
/// nominal pose's sensitivities of each sample, the bulk of a chain's cost per sample. A
/// design evaluates them chunk by chunk, as it needs them. Once another design of the same
/// runs is made ([`Design::with_model`]: a diagnosis evaluates the same runs a dozen times,
/// under the candidates', the folds' and the final model), they are kept, evaluated once for
/// all of them: about 360 bytes a sample for a three-axis chain, for the designs' life.
#[derive(Default)]
struct Geometry {
    /// The geometry is kept once evaluated.
    keep: AtomicBool,
    /// Per axis (the chain's), per sample: [`Design::states`].
    states: OnceLock<[Vec<JointState>; 6]>,
    /// Per sample: the sensitivities, the nominal `d`, the bar direction in the table frame.
    nominal: OnceLock<Nominal>,
}

/// The nominal pose's part of a run's [`Geometry`], or of a chunk of it.
#[derive(Debug, Default)]
struct Nominal {
    /// Sensitivities, `[sample * joints + joint]`.
    tool: Vec<JointSensitivity>,
    work: Vec<JointSensitivity>,
    /// Nominal relative vector `d` per sample.
    d: Vec<Vector3<f64>>,
    /// The unit bar direction in the table frame per sample (centring sensitivities).
    u_table: Vec<Vector3<f64>>,
}

impl std::fmt::Debug for Geometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Geometry")
            .field("keep", &self.keep.load(Ordering::Relaxed))
            .field("states", &self.states.get().is_some())
            .field("nominal", &self.nominal.get().is_some())
            .finish()
    }
}

/// A chunk's samples of a run's geometry: from the kept geometry, or evaluated into the
/// scratch.
struct ChunkGeometry<'g> {
    /// Per axis (empty for an axis the chain lacks).
    states: [&'g [JointState]; 6],
    /// Sensitivities, `[sample * joints + joint]`, the chunk's first sample first.
    tool: &'g [JointSensitivity],
    work: &'g [JointSensitivity],
    d: &'g [Vector3<f64>],
    u_table: &'g [Vector3<f64>],
}

impl<'g> ChunkGeometry<'g> {
    /// Samples `start..start + len` of the kept geometry where there is one, else the
    /// scratch's chunk (which then holds those samples). A part neither kept nor loaded (the
    /// nominal pose's, for an exact evaluation without reading terms) is whatever the scratch
    /// last held: not to be read.
    #[allow(clippy::too_many_arguments)]
    fn of(
        kept_states: Option<&'g [Vec<JointState>; 6]>,
        kept_nominal: Option<&'g Nominal>,
        chunk_states: &'g [Vec<JointState>; 6],
        chunk_nominal: &'g Nominal,
        start: usize,
        len: usize,
        nt: usize,
        nw: usize,
    ) -> ChunkGeometry<'g> {
        // An axis the chain lacks has no states: an empty slice, as in the chunk.
        let states = std::array::from_fn(|a| match kept_states {
            Some(k) => k[a].get(start..start + len).unwrap_or(&[]),
            None => &chunk_states[a][..],
        });
        match kept_nominal {
            Some(n) => ChunkGeometry {
                states,
                tool: &n.tool[start * nt..(start + len) * nt],
                work: &n.work[start * nw..(start + len) * nw],
                d: &n.d[start..start + len],
                u_table: &n.u_table[start..start + len],
            },
            None => ChunkGeometry {
                states,
                tool: &chunk_nominal.tool,
                work: &chunk_nominal.work,
                d: &chunk_nominal.d,
                u_table: &chunk_nominal.u_table,
            },
        }
    }
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
    /// X, Y and Z all drive joints of the chain.
    has_xyz: bool,
    /// The session's start, Unix seconds: the time origin of every time-dependent term.
    origin_unix_s: f64,
    /// Per axis, s: the servo lag at whose delay the axis's direction switches
    /// ([`Design::with_switch_lags`]); 0, the commanded reversal, unless set.
    switch_lag_s: [f64; 6],
}

/// The start of the session these runs make up when nothing else says when it started: the
/// earliest run's `started_at` (Unix seconds; +∞ for no runs). [`Design::new`] takes it as the
/// time origin; a saved model records it, so that later runs are evaluated from it.
pub fn session_start_unix_s(runs: &[Run]) -> f64 {
    runs.iter().map(|r| r.header.started_at_unix_s).fold(f64::INFINITY, f64::min)
}

/// The end of the session these runs make up: the latest end (`started_at` plus the last
/// sample's time) of a run, Unix seconds (−∞ for no runs).
pub fn session_end_unix_s(runs: &[Run]) -> f64 {
    runs.iter()
        .map(|r| r.header.started_at_unix_s + r.t_s.last().copied().unwrap_or(0.0))
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Scratch space reused across rows.
#[derive(Debug, Default)]
pub struct RowScratch {
    tool: Vec<JointSensitivity>,
    work: Vec<JointSensitivity>,
    pose: ChainPose,
}

/// Samples evaluated together by [`Design::fill_run`] and [`Design::exact_run`]: each term's
/// basis is computed for a whole chunk in one call (a tight loop, and one crossing of the
/// boundary for a plugin's kernel) before the sensitivities are applied.
const CHUNK: usize = 256;

/// Scratch space of the chunked evaluations.
#[derive(Debug, Default)]
pub struct BlockScratch {
    row: RowScratch,
    /// Joint states per axis, per sample of the chunk (when the run's are not kept).
    states: [Vec<JointState>; 6],
    /// The chunk's nominal geometry (when the run's is not kept).
    nominal: Nominal,
    /// One term's basis per sample.
    basis: Vec<ErrorMotion>,
    /// Error motions, `[sample * joints + joint]`.
    tool_err: Vec<ErrorMotion>,
    work_err: Vec<ErrorMotion>,
    exact: ExactScratch,
}

/// Scratch space reused across exact evaluations ([`exact_length`]).
#[derive(Debug, Default)]
pub struct ExactScratch {
    tool: Vec<ErrorMotion>,
    work: Vec<ErrorMotion>,
    pose: ChainPose,
}

/// The table frame's orientation in the base frame (identity for a chain without workpiece
/// joints): centring offsets are displacements of the table ball in the table frame, so that
/// they turn with a rotary table.
#[inline]
pub(crate) fn table_rotation(pose: &ChainPose) -> nalgebra::UnitQuaternion<f64> {
    pose.base_from_work_joint
        .last()
        .map(|f| f.rotation)
        .unwrap_or_else(nalgebra::UnitQuaternion::identity)
}

/// The times (s, ascending) at which an axis reverses: where its direction of motion changes
/// sign, interpolated to the zero crossing of the velocity between the two samples.
pub fn reversal_times(t: &[f64], velocity: &[f64], direction: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    let mut last: Option<usize> = None;
    for i in 0..t.len() {
        if direction[i] == 0.0 {
            continue;
        }
        if let Some(j) = last
            && direction[j] != direction[i]
        {
            let (vj, vi) = (velocity[j], velocity[i]);
            let frac = if vj != vi { (vj / (vj - vi)).clamp(0.0, 1.0) } else { 0.5 };
            out.push(t[j] + frac * (t[i] - t[j]));
        }
        last = Some(i);
    }
    out
}

/// A reversal just before a run's first sample, s: the machine was already moving along its
/// lead-in (a ballbar run never starts from rest), so an axis whose speed grows from near zero
/// over the first samples reversed just before them. The velocity of the first two sample
/// intervals, extrapolated linearly back to zero, gives the time; it counts when it lies within
/// [`START_REVERSAL_SAMPLES`] sample intervals before the first sample. On a circle, whose axis
/// velocity is linear in time near a reversal (to 0.03 % within 1° of it), this is exact: a
/// full-circle run of a Renishaw file starts half a sample after the reversal at its start
/// angle (`t₀ − Δt/2`). `None` otherwise.
pub fn start_reversal(t: &[f64], q: &[f64]) -> Option<f64> {
    if t.len() < 3 {
        return None;
    }
    let (dt1, dt2) = (t[1] - t[0], t[2] - t[1]);
    let (v1, v2) = ((q[1] - q[0]) / dt1, (q[2] - q[1]) / dt2);
    let (t1, t2) = (t[0] + dt1 / 2.0, t[1] + dt2 / 2.0);
    // Same sense, speed growing: the zero of the line through (t1, v1), (t2, v2) lies before t1.
    if !(v1 * v2 > 0.0 && v2.abs() > v1.abs()) || (q[1] - q[0]).abs() <= DIRECTION_DEAD_BAND {
        return None;
    }
    let zero = t1 - v1 * (t2 - t1) / (v2 - v1);
    (zero >= t[0] - START_REVERSAL_SAMPLES * dt1 && zero <= t[0]).then_some(zero)
}

/// How far before a run's first sample a reversal is still taken into the run, in sample
/// intervals: a spike after it lasts 20-150 ms (domain brief §4), several samples at any bar's
/// rate, so one a few samples before the run still shows in it; farther back, the linear
/// extrapolation of the axis velocity would stretch beyond the few samples that support it.
pub const START_REVERSAL_SAMPLES: f64 = 5.0;

/// Time since the last of `reversals` at or before `t` (∞ if none).
#[inline]
pub fn since_last(reversals: &[f64], t: f64) -> f64 {
    let k = reversals.partition_point(|&r| r <= t);
    if k == 0 { f64::INFINITY } else { t - reversals[k - 1] }
}

/// A free run's `table_ball_mm` and the table ball its pivot places may differ by this, mm
/// (the run format: 0.01 mm, a set-up's rounding in a header, far above the 1e-6 mm of the
/// coordinates).
pub const FREE_TABLE_BALL_TOLERANCE_MM: f64 = 0.01;

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
    let (a, b) = if i == 0 {
        (0, 1)
    } else if i + 1 == n {
        (n - 2, n - 1)
    } else {
        (i - 1, i + 1)
    };
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
    /// Prepare the design with the runs' own session start ([`session_start_unix_s`], the
    /// earliest run's) as the time origin: for runs that are a whole session, or its start.
    /// Runs evaluated under a model fitted on earlier runs take that model's origin
    /// ([`Design::with_origin`]).
    pub fn new(model: &'a Model, runs: &'a [Run]) -> Result<Design<'a>, ModelError> {
        Design::with_origin(model, runs, session_start_unix_s(runs))
    }

    /// Prepare the design; checks that every run has the axes the chain needs and that the
    /// chain's nominal ball distance matches each run's radius. Every time-dependent term
    /// (`JointState::session_t_s`, the bar's growth) is evaluated at the time since
    /// `origin_unix_s` (Unix seconds), whichever runs are given.
    pub fn with_origin(
        model: &'a Model,
        runs: &'a [Run],
        origin_unix_s: f64,
    ) -> Result<Design<'a>, ModelError> {
        let mut parameters = model.parameters();
        let n_machine = parameters.len();
        let chain_axes = model.chain.axes();
        let mut prepared = Vec::with_capacity(runs.len());
        let session_start = origin_unix_s;
        for run in runs {
            for &a in &chain_axes {
                if run.axis(a).is_none() {
                    return Err(ModelError::MissingAxis {
                        source_name: run.source.clone(),
                        axis: a,
                        machine: model.spec.name.clone(),
                    });
                }
            }
            let h = &run.header;
            let balls = model.chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
            // A free run's pivot places the table ball; its table_ball_mm is informative (the
            // run format) and, where given (not all zero, the format's default), must agree.
            if h.plane == Plane::Free && h.table_ball_mm != [0.0; 3] {
                let given = Vector3::from(h.table_ball_mm);
                let distance_mm = (given - balls.table_ball).norm();
                if distance_mm > FREE_TABLE_BALL_TOLERANCE_MM {
                    return Err(ModelError::TableBallMismatch {
                        source_name: run.source.clone(),
                        from_pivot_mm: balls.table_ball.into(),
                        given_mm: h.table_ball_mm,
                        distance_mm,
                    });
                }
            }
            let mut q = [0.0; 6];
            let mut pose = ChainPose::default();
            for i in 0..run.len() {
                fill_q(run, i, &mut q);
                model.chain.pose_into(&q, &balls, None, None, &mut pose);
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
            let first_run_term_column = parameters.len();
            parameters.extend(run_term_parameters(model, run));
            let mut reversals: [Vec<f64>; 6] = Default::default();
            let mut final_direction = [0.0; 6];
            for &a in &chain_axes {
                let col = run.axis(a).expect("checked above");
                let (v, d): (Vec<f64>, Vec<f64>) =
                    (0..run.len()).map(|i| velocity_and_direction(&run.t_s, col, i)).unzip();
                final_direction[a.index()] =
                    d.iter().rev().copied().find(|&x| x != 0.0).unwrap_or(0.0);
                let mut times = reversal_times(&run.t_s, &v, &d);
                if let Some(r) = start_reversal(&run.t_s, col) {
                    times.insert(0, r);
                }
                reversals[a.index()] = times;
            }
            let session_offset_s = run.header.started_at_unix_s - session_start;
            let rotary_at_zero = chain_axes
                .iter()
                .filter(|a| a.is_rotary())
                .all(|&a| run.axis(a).expect("checked above").iter().all(|&x| x == 0.0));
            prepared.push(Prepared {
                balls,
                centring,
                first_centring_column: first,
                first_run_term_column,
                reversals,
                final_direction,
                session_offset_s,
                rotary_at_zero,
                geometry: Arc::default(),
            });
        }
        let has_xyz = Axis::LINEAR.iter().all(|a| chain_axes.contains(a));
        Ok(Design {
            model,
            runs,
            parameters,
            n_machine,
            prepared,
            chain_axes,
            has_xyz,
            origin_unix_s,
            switch_lag_s: [0.0; 6],
        })
    }

    /// The same design with each axis's direction of motion, and the clock of its reversal
    /// transients, switching at its lagged reversal: `lags_s[a]` (s, ≥ 0, the axis's servo lag)
    /// after the commanded one. A first-order lag τ following a command whose velocity is linear
    /// in time near a reversal, `q = a (t - t_r)²/2` (a circle's axis, to 0.03 % within 1° of
    /// it), settles to `a (t - t_r - τ)²/2 + a τ²/2`: the lagged axis reverses exactly τ after
    /// the command, which is when its backlash switches (the simulator's actual axis does).
    /// The runs' geometry is evaluated afresh (its joint states change); the model's columns
    /// are the same.
    pub fn with_switch_lags(mut self, lags_s: [f64; 6]) -> Design<'a> {
        // A negative or non-finite lag is no physical axis: the commanded reversal.
        self.switch_lag_s = lags_s.map(|l| if l.is_finite() && l > 0.0 { l } else { 0.0 });
        for p in &mut self.prepared {
            let keep = p.geometry.keep.load(Ordering::Relaxed);
            p.geometry = Arc::default();
            p.geometry.keep.store(keep, Ordering::Relaxed);
        }
        self
    }

    /// The same design at other switch lags ([`Design::with_switch_lags`]), its geometry
    /// evaluated afresh and not kept: for evaluating a few of its rows at one lag after
    /// another ([`Design::switch_rows`]) while this design stays as it is.
    pub fn at_switch_lags(&self, lags_s: [f64; 6]) -> Design<'a> {
        let prepared = self
            .prepared
            .iter()
            .map(|p| Prepared { geometry: Arc::default(), ..p.clone() })
            .collect();
        Design {
            model: self.model,
            runs: self.runs,
            parameters: self.parameters.clone(),
            n_machine: self.n_machine,
            prepared,
            chain_axes: self.chain_axes.clone(),
            has_xyz: self.has_xyz,
            origin_unix_s: self.origin_unix_s,
            switch_lag_s: self.switch_lag_s,
        }
        .with_switch_lags(lags_s)
    }

    /// The samples of run `r` (ranges, ascending and disjoint) whose directions of motion can
    /// differ between two sets of switch lags in `[0, max_lag_s]`: for each reversal `x` of a
    /// chain axis, the samples from the last before `x` to the first after `x + max_lag_s`
    /// (a lagged axis's direction at `t` is the command's at `t - τ`), and each sample where
    /// a moving axis's commanded direction is 0 (at the commanded reversal, τ = 0, it has
    /// none). Elsewhere every axis's direction is the same at any such lags; its time since
    /// the last reversal is not.
    pub fn switch_rows(&self, r: usize, max_lag_s: f64) -> Vec<std::ops::Range<usize>> {
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let t = &run.t_s;
        let n = t.len();
        let mut inside = vec![false; n];
        for &a in &self.chain_axes {
            let col = run.axis(a).expect("checked in Design::new");
            if prep.final_direction[a.index()] != 0.0 || !prep.reversals[a.index()].is_empty() {
                for (i, x) in inside.iter_mut().enumerate() {
                    *x |= velocity_and_direction(t, col, i).1 == 0.0;
                }
            }
            for &x in &prep.reversals[a.index()] {
                let lo = t.partition_point(|&s| s < x).saturating_sub(1);
                let hi = (t.partition_point(|&s| s <= x + max_lag_s) + 1).min(n);
                inside[lo..hi.max(lo)].fill(true);
            }
        }
        let mut out: Vec<std::ops::Range<usize>> = Vec::new();
        for (i, &x) in inside.iter().enumerate() {
            if !x {
                continue;
            }
            match out.last_mut() {
                Some(last) if last.end == i => last.end = i + 1,
                _ => out.push(i..i + 1),
            }
        }
        out
    }

    /// Per axis, s: the lag after the commanded reversal at which its direction switches
    /// (all 0 unless [`Design::with_switch_lags`] set them).
    pub fn switch_lags(&self) -> [f64; 6] {
        self.switch_lag_s
    }

    /// The time origin of the design's time-dependent terms, Unix seconds.
    pub fn origin_unix_s(&self) -> f64 {
        self.origin_unix_s
    }

    /// The same runs under another model of the same chain (the base model with effects added,
    /// say): the runs' preparation (checks, ball placement, reversals) is reused, and from now
    /// on their geometry is kept for both ([`Design::keep_geometry`]). Each run's columns (its
    /// centring, then its coefficients of the new model's run terms) follow the new model's
    /// machine parameters.
    pub fn with_model<'b>(&'b self, model: &'b Model) -> Result<Design<'b>, ModelError> {
        if model.chain != self.model.chain {
            return Err(ModelError::InvalidMachine {
                message: "Design::with_model needs a model of the same chain".into(),
            });
        }
        let mut parameters = model.parameters();
        let n_machine = parameters.len();
        // From now on the runs' geometry serves two designs: keep it once evaluated.
        self.keep_geometry();
        let mut prepared = self.prepared.clone();
        for (r, p) in prepared.iter_mut().enumerate() {
            let first = parameters.len();
            parameters.extend(self.parameters[self.centring_columns(r)].iter().cloned());
            p.first_centring_column = first;
            p.first_run_term_column = parameters.len();
            parameters.extend(run_term_parameters(model, &self.runs[r]));
        }
        Ok(Design {
            model,
            runs: self.runs,
            parameters,
            n_machine,
            prepared,
            chain_axes: self.chain_axes.clone(),
            has_xyz: self.has_xyz,
            origin_unix_s: self.origin_unix_s,
            switch_lag_s: self.switch_lag_s,
        })
    }

    /// Keep the runs' geometry (the joint states and the nominal pose's sensitivities of each
    /// sample) once evaluated, for this design and those made from it: for a caller that will
    /// evaluate the same runs again (a diagnosis, from its base fit on). [`Design::with_model`]
    /// does this itself. About 360 bytes a sample for a three-axis chain, for the designs' life.
    pub fn keep_geometry(&self) {
        for p in &self.prepared {
            p.geometry.keep.store(true, Ordering::Relaxed);
        }
    }

    /// Whether the runs' geometry is kept ([`Design::keep_geometry`]): the caller evaluates the
    /// same runs again and again, and a factorisation of the design keeps its rows too.
    pub fn keeps_geometry(&self) -> bool {
        self.prepared.iter().any(|p| p.geometry.keep.load(Ordering::Relaxed))
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

    /// What a reading term sees at time `t_s` of run `r`, with the nominal relative vector `d`.
    fn reading_sample<'d>(&self, r: usize, d: &'d Vector3<f64>, t_s: f64) -> ReadingSample<'d> {
        let h = &self.runs[r].header;
        ReadingSample {
            plane: h.plane,
            paper_sign: h.direction.map(|d| d.paper_sign()).unwrap_or(0.0),
            d,
            radius_mm: h.radius_mm,
            feed_mm_per_s: h.feed_mm_per_s(),
            session_t_s: self.prepared[r].session_offset_s + t_s,
        }
    }

    /// The columns of run `r`'s coefficients of the model's run terms.
    pub fn run_term_columns(&self, r: usize) -> std::ops::Range<usize> {
        let p = &self.prepared[r];
        p.first_run_term_column
            ..p.first_run_term_column
                + self.model.run_terms.len()
                + self.model.run_reading_terms.len()
    }

    /// All of run `r`'s own columns: its centring, then its run-term coefficients (contiguous).
    pub fn run_columns(&self, r: usize) -> std::ops::Range<usize> {
        self.centring_columns(r).start..self.run_term_columns(r).end
    }

    /// The run that owns column `j` (`None` for a machine parameter).
    pub fn run_of_column(&self, j: usize) -> Option<usize> {
        (j >= self.n_machine)
            .then(|| (0..self.runs.len()).find(|&r| self.run_columns(r).contains(&j)))
            .flatten()
    }

    /// Fill `out` (length [`Design::n_cols`]) with row `i` of run `r` and return the target: the
    /// measured ΔR in mm, less a known bar-length error.
    pub fn row(
        &self,
        r: usize,
        i: usize,
        scratch: &mut RowScratch,
        out: &mut [f64],
    ) -> Result<f64, ModelError> {
        out.fill(0.0);
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let mut q = [0.0; 6];
        fill_q(run, i, &mut q);
        self.model.chain.pose_into(&q, &prep.balls, None, None, &mut scratch.pose);
        let d = sensitivities(&scratch.pose, &mut scratch.tool, &mut scratch.work);
        let states = self.states(r, i);
        for (k, bt) in self.model.terms.iter().enumerate() {
            let sens = match bt.branch {
                Branch::Tool => &scratch.tool[bt.joint],
                Branch::Workpiece => &scratch.work[bt.joint],
            };
            out[k] = sens.apply(&bt.term.basis(&states[bt.axis.index()])?);
        }
        for (k, bt) in self.model.run_terms.iter().enumerate() {
            let sens = match bt.branch {
                Branch::Tool => &scratch.tool[bt.joint],
                Branch::Workpiece => &scratch.work[bt.joint],
            };
            out[prep.first_run_term_column + k] =
                sens.apply(&bt.term.basis(&states[bt.axis.index()])?);
        }
        let first_reading = prep.first_run_term_column + self.model.run_terms.len();
        for (k, rt) in self.model.run_reading_terms.iter().enumerate() {
            let rs = self.reading_sample(r, &d, run.t_s[i]);
            out[first_reading + k] = reading_basis(rt, &rs);
        }
        let dn = d.norm();
        for (k, rt) in (self.model.terms.len()..).zip(&self.model.reading_terms) {
            let rs = self.reading_sample(r, &d, run.t_s[i]);
            out[k] = reading_basis(rt, &rs);
        }
        // Centring: the table ball sits at its nominal place plus e (table frame), so d
        // shrinks by R e.
        let u: Vector3<f64> = d / dn;
        let back = table_rotation(&scratch.pose).inverse() * u;
        for (c, a) in prep.centring.iter().enumerate() {
            out[prep.first_centring_column + c] = -back[a.index()];
        }
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        Ok(run.dr_mm[i] - known)
    }

    /// The commanded joint states of sample `i` of run `r`; the direction of motion and the
    /// time since the last reversal are those of the axis lagging its command by its switch lag
    /// ([`Design::with_switch_lags`]; the commanded ones when it is 0).
    pub fn states(&self, r: usize, i: usize) -> [JointState; 6] {
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let feed = run.header.feed_mm_per_s();
        let t = run.t_s[i];
        let mut states = [JointState::default(); 6];
        for &a in &self.chain_axes {
            let col = run.axis(a).expect("checked in Design::new");
            let (v, dir) = velocity_and_direction(&run.t_s, col, i);
            let reversals = &prep.reversals[a.index()];
            let lag = self.switch_lag_s[a.index()];
            // The lagged axis at t is the commanded one at t - τ: its direction is the last
            // one's, flipped once for every commanded reversal after t - τ, and its last
            // reversal the last commanded one before t - τ, τ later. With τ = 0 the commanded
            // direction, which is 0 at a sample at rest.
            let (dir, since) = if lag > 0.0 {
                let later = reversals.len() - reversals.partition_point(|&x| x <= t - lag);
                let d = prep.final_direction[a.index()];
                (if later.is_multiple_of(2) { d } else { -d }, since_last(reversals, t - lag))
            } else {
                (dir, since_last(reversals, t))
            };
            states[a.index()] = JointState {
                q: col[i],
                velocity: v,
                direction: dir,
                t_s: t,
                feed_mm_per_s: feed,
                since_reversal_s: since,
                session_t_s: prep.session_offset_s + t,
            };
        }
        // A ballbar path keeps |d| = R, so the commanded relative velocity is tangential. The
        // finite difference has an O(h) radial part at a run's two end samples (one-sided); left
        // there, it would make a common servo lag look (weakly) identifiable. On machines of
        // linear axes, and on any machine in a run that holds its rotary axes at zero (a planar
        // test of a five-axis machine), d = q - pivot: project the velocity onto the tangent
        // plane.
        if self.has_xyz && prep.rotary_at_zero && run.header.plane != Plane::Free {
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
    /// applied as a rigid transform, the centring as a displacement of the table ball (in the
    /// table frame), the
    /// distance taken exactly ([`exact_length`]); reading terms and bar length added.
    pub fn exact(&self, r: usize, i: usize, theta: &[f64]) -> Result<f64, ModelError> {
        self.exact_with(r, i, theta, &mut ExactScratch::default())
    }

    /// [`Design::exact`] with reused scratch space.
    pub fn exact_with(
        &self,
        r: usize,
        i: usize,
        theta: &[f64],
        scratch: &mut ExactScratch,
    ) -> Result<f64, ModelError> {
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
        let run_coeffs = &theta[self.run_term_columns(r)];
        let length = exact_length(
            self.model,
            &q,
            &states,
            &prep.balls,
            &e,
            theta,
            run_coeffs,
            false,
            scratch,
        )?;
        let mut reading = length - h.radius_mm;
        let n_terms = self.model.terms.len();
        if !self.model.reading_terms.is_empty() {
            let mut d = None;
            for (k, rt) in self.model.reading_terms.iter().enumerate() {
                let c = theta[n_terms + k];
                if c == 0.0 {
                    continue;
                }
                let d = *d.get_or_insert_with(|| {
                    let nominal = self.model.chain.pose(&q, &prep.balls, None, None);
                    nominal.tool_ball - nominal.table_ball
                });
                let rs = self.reading_sample(r, &d, run.t_s[i]);
                reading += c * reading_basis(rt, &rs);
            }
        }
        let first_reading = self.model.run_terms.len();
        for (k, rt) in self.model.run_reading_terms.iter().enumerate() {
            let c = run_coeffs[first_reading + k];
            if c != 0.0 {
                let nominal = self.model.chain.pose(&q, &prep.balls, None, None);
                let d = nominal.tool_ball - nominal.table_ball;
                reading += c * reading_basis(rt, &self.reading_sample(r, &d, run.t_s[i]));
            }
        }
        if let BarLength::Known(b) = self.model.options.bar_length {
            reading += b;
        }
        Ok(reading)
    }

    /// The joint states of every sample of run `r`, per chain axis ([`Design::states`]), when
    /// the run's geometry is kept (evaluated on first use); `None` otherwise.
    fn kept_states(&self, r: usize) -> Option<&[Vec<JointState>; 6]> {
        let g = &self.prepared[r].geometry;
        g.keep.load(Ordering::Relaxed).then(|| {
            g.states.get_or_init(|| {
                let mut out: [Vec<JointState>; 6] = Default::default();
                self.load_states(r, 0, self.runs[r].len(), &mut out);
                out
            })
        })
    }

    /// The nominal pose's sensitivities, `d` and bar direction of every sample of run `r`,
    /// when the run's geometry is kept (evaluated on first use); `None` otherwise.
    fn kept_nominal(&self, r: usize) -> Option<&Nominal> {
        let g = &self.prepared[r].geometry;
        g.keep.load(Ordering::Relaxed).then(|| {
            g.nominal.get_or_init(|| {
                let mut out = Nominal::default();
                self.load_nominal(r, 0, self.runs[r].len(), &mut out, &mut RowScratch::default());
                out
            })
        })
    }

    /// The states ([`Design::states`]) of samples `start..start + len` of run `r`, per chain
    /// axis, into `out`.
    fn load_states(&self, r: usize, start: usize, len: usize, out: &mut [Vec<JointState>; 6]) {
        for st in out.iter_mut() {
            st.clear();
        }
        for &a in &self.chain_axes {
            out[a.index()].reserve(len);
        }
        for i in start..start + len {
            let states = self.states(r, i);
            for &a in &self.chain_axes {
                out[a.index()].push(states[a.index()]);
            }
        }
    }

    /// The nominal `d`, the sensitivities and the bar direction in the table frame of samples
    /// `start..start + len` of run `r`, into `out`.
    fn load_nominal(
        &self,
        r: usize,
        start: usize,
        len: usize,
        out: &mut Nominal,
        row: &mut RowScratch,
    ) {
        let prep = &self.prepared[r];
        let (nt, nw) = (self.model.chain.tool.len(), self.model.chain.workpiece.len());
        out.tool.clear();
        out.work.clear();
        out.d.clear();
        out.u_table.clear();
        out.tool.reserve(len * nt);
        out.work.reserve(len * nw);
        let mut q = [0.0; 6];
        for i in start..start + len {
            fill_q(&self.runs[r], i, &mut q);
            self.model.chain.pose_into(&q, &prep.balls, None, None, &mut row.pose);
            let d = sensitivities(&row.pose, &mut row.tool, &mut row.work);
            out.tool.extend_from_slice(&row.tool[..nt]);
            out.work.extend_from_slice(&row.work[..nw]);
            out.u_table.push(table_rotation(&row.pose).inverse() * (d / d.norm()));
            out.d.push(d);
        }
    }

    /// [`Design::load_nominal`]'s bar vectors `d` alone, all that the reading terms of an exact
    /// evaluation read of the nominal geometry (the same numbers: `d` is the nominal pose's,
    /// before the sensitivities); the chunk's other nominal parts are left empty.
    fn load_bar_vectors(
        &self,
        r: usize,
        start: usize,
        len: usize,
        out: &mut Nominal,
        row: &mut RowScratch,
    ) {
        let prep = &self.prepared[r];
        out.tool.clear();
        out.work.clear();
        out.d.clear();
        out.u_table.clear();
        let mut q = [0.0; 6];
        for i in start..start + len {
            fill_q(&self.runs[r], i, &mut q);
            self.model.chain.pose_into(&q, &prep.balls, None, None, &mut row.pose);
            out.d.push(row.pose.tool_ball - row.pose.table_ball);
        }
    }

    /// Every row of run `r`, restricted to the columns `cols` (global indices), column-major
    /// into `out` (`run length × cols.len()`), and the targets (as [`Design::row`] returns
    /// them) into `targets`. The same numbers as [`Design::row`], evaluated in chunks.
    pub fn fill_run(
        &self,
        r: usize,
        cols: &[usize],
        out: &mut [f64],
        targets: &mut [f64],
        scratch: &mut BlockScratch,
    ) -> Result<(), ModelError> {
        self.fill_rows(r, 0..self.runs[r].len(), cols, out, targets, scratch)
    }

    /// [`Design::fill_run`] for the samples `rows` of run `r` only: `out` is
    /// `rows.len() × cols.len()`, column-major, `targets` `rows.len()` long. The same numbers
    /// as the whole run's rows (a fit that streams a long run through a bounded buffer).
    pub fn fill_rows(
        &self,
        r: usize,
        rows: std::ops::Range<usize>,
        cols: &[usize],
        out: &mut [f64],
        targets: &mut [f64],
        scratch: &mut BlockScratch,
    ) -> Result<(), ModelError> {
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let (first, end) = (rows.start, rows.end.min(run.len()));
        let m = end.saturating_sub(first);
        assert_eq!(out.len(), m * cols.len(), "fill_rows: output size");
        assert_eq!(targets.len(), m, "fill_rows: targets size");
        let mut position = vec![usize::MAX; self.n_cols()];
        for (c, &j) in cols.iter().enumerate() {
            position[j] = c;
        }
        let (nt, nw) = (self.model.chain.tool.len(), self.model.chain.workpiece.len());
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        let (kept_states, kept_nominal) = (self.kept_states(r), self.kept_nominal(r));
        let BlockScratch { row, states: chunk_states, nominal: chunk_nominal, basis, .. } = scratch;
        let mut start = first;
        while start < end {
            let len = CHUNK.min(end - start);
            // The chunk's place in `out` and `targets`.
            let at = start - first;
            if kept_states.is_none() {
                self.load_states(r, start, len, chunk_states);
            }
            if kept_nominal.is_none() {
                self.load_nominal(r, start, len, chunk_nominal, row);
            }
            let g = ChunkGeometry::of(
                kept_states,
                kept_nominal,
                chunk_states,
                chunk_nominal,
                start,
                len,
                nt,
                nw,
            );
            let chain_terms = self.model.terms.iter().enumerate();
            let run_terms = self
                .model
                .run_terms
                .iter()
                .enumerate()
                .map(|(k, bt)| (prep.first_run_term_column + k, bt));
            for (k, bt) in chain_terms.chain(run_terms) {
                let c = position[k];
                if c == usize::MAX {
                    continue;
                }
                let (sens, stride) = match bt.branch {
                    Branch::Tool => (g.tool, nt),
                    Branch::Workpiece => (g.work, nw),
                };
                let column = &mut out[c * m + at..c * m + at + len];
                // A term of one component writes it into the column, which its sensitivity
                // then scales in place: the numbers of the six-component path below.
                if let Some(k) = bt.term.component_batch(g.states[bt.axis.index()], column) {
                    apply_component_in_place(&sens[bt.joint..], stride, column, k?);
                    continue;
                }
                // Zeroed: a kernel that leaves entries unwritten must not reuse another term's
                // (a fill, which the compiler makes one store of zeros, not a push per entry).
                basis.resize(len, [0.0; 6]);
                basis.fill([0.0; 6]);
                bt.term.basis_batch(g.states[bt.axis.index()], basis)?;
                apply_sensitivities(&sens[bt.joint..], stride, basis, column);
            }
            for (k, rt) in self.model.reading_terms.iter().enumerate() {
                let c = position[self.model.terms.len() + k];
                if c == usize::MAX {
                    continue;
                }
                for ii in 0..len {
                    let rs = self.reading_sample(r, &g.d[ii], run.t_s[start + ii]);
                    out[c * m + at + ii] = reading_basis(rt, &rs);
                }
            }
            let first_reading = prep.first_run_term_column + self.model.run_terms.len();
            for (k, rt) in self.model.run_reading_terms.iter().enumerate() {
                let c = position[first_reading + k];
                if c == usize::MAX {
                    continue;
                }
                for ii in 0..len {
                    let rs = self.reading_sample(r, &g.d[ii], run.t_s[start + ii]);
                    out[c * m + at + ii] = reading_basis(rt, &rs);
                }
            }
            for (ca, a) in prep.centring.iter().enumerate() {
                let c = position[prep.first_centring_column + ca];
                if c == usize::MAX {
                    continue;
                }
                for ii in 0..len {
                    out[c * m + at + ii] = -g.u_table[ii][a.index()];
                }
            }
            for ii in 0..len {
                targets[at + ii] = run.dr_mm[start + ii] - known;
            }
            start += len;
        }
        // Columns of other runs' nuisances are zero here.
        for (c, &j) in cols.iter().enumerate() {
            let ours = j < self.n_machine || self.run_columns(r).contains(&j);
            if !ours {
                out[c * m..(c + 1) * m].fill(0.0);
            }
        }
        Ok(())
    }

    /// [`Design::exact`] at every sample of run `r`, evaluated in chunks.
    pub fn exact_run(&self, r: usize, theta: &[f64]) -> Result<Vec<f64>, ModelError> {
        self.exact_run_with(r, theta, &mut BlockScratch::default())
    }

    /// [`Design::exact_run`] with reused scratch space.
    pub fn exact_run_with(
        &self,
        r: usize,
        theta: &[f64],
        scratch: &mut BlockScratch,
    ) -> Result<Vec<f64>, ModelError> {
        let run = &self.runs[r];
        let prep = &self.prepared[r];
        let h = &run.header;
        let m = run.len();
        let chain = &self.model.chain;
        let (nt, nw) = (chain.tool.len(), chain.workpiece.len());
        let n_terms = self.model.terms.len();
        let mut e = Vector3::zeros();
        for (c, a) in prep.centring.iter().enumerate() {
            e[a.index()] = theta[prep.first_centring_column + c];
        }
        let first_run_reading = prep.first_run_term_column + self.model.run_terms.len();
        let readings =
            self.model.reading_terms.iter().enumerate().any(|(k, _)| theta[n_terms + k] != 0.0)
                || (0..self.model.run_reading_terms.len())
                    .any(|k| theta[first_run_reading + k] != 0.0);
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        let kept_states = self.kept_states(r);
        let kept_nominal = if readings { self.kept_nominal(r) } else { None };
        let BlockScratch {
            row,
            states: chunk_states,
            nominal: chunk_nominal,
            basis,
            tool_err,
            work_err,
            exact,
        } = scratch;
        let mut out = Vec::with_capacity(m);
        let mut q = [0.0; 6];
        let mut start = 0;
        while start < m {
            let len = CHUNK.min(m - start);
            if kept_states.is_none() {
                self.load_states(r, start, len, chunk_states);
            }
            if readings && kept_nominal.is_none() {
                self.load_bar_vectors(r, start, len, chunk_nominal, row);
            }
            let g = ChunkGeometry::of(
                kept_states,
                kept_nominal,
                chunk_states,
                chunk_nominal,
                start,
                len,
                nt,
                nw,
            );
            tool_err.clear();
            tool_err.resize(len * nt, [0.0; 6]);
            work_err.clear();
            work_err.resize(len * nw, [0.0; 6]);
            let chain_terms = self.model.terms.iter().enumerate();
            let run_terms = self
                .model
                .run_terms
                .iter()
                .enumerate()
                .map(|(k, bt)| (prep.first_run_term_column + k, bt));
            for (k, bt) in chain_terms.chain(run_terms) {
                let c = theta[k];
                if c == 0.0 {
                    continue;
                }
                // Zeroed: a kernel that leaves entries unwritten must not reuse another term's
                // (a fill, which the compiler makes one store of zeros, not a push per entry).
                basis.resize(len, [0.0; 6]);
                basis.fill([0.0; 6]);
                bt.term.basis_batch(g.states[bt.axis.index()], basis)?;
                let (errs, stride) = match bt.branch {
                    Branch::Tool => (&mut *tool_err, nt),
                    Branch::Workpiece => (&mut *work_err, nw),
                };
                accumulate_motions(c, basis, &mut errs[bt.joint..], stride);
            }
            for ii in 0..len {
                let i = start + ii;
                fill_q(run, i, &mut q);
                let pose = &mut exact.pose;
                chain.pose_into(
                    &q,
                    &prep.balls,
                    Some(&tool_err[ii * nt..(ii + 1) * nt]),
                    Some(&work_err[ii * nw..(ii + 1) * nw]),
                    pose,
                );
                let mut reading = (pose.tool_ball - (pose.table_ball + table_rotation(pose) * e))
                    .norm()
                    - h.radius_mm;
                if readings {
                    for (k, rt) in self.model.reading_terms.iter().enumerate() {
                        let rs = self.reading_sample(r, &g.d[ii], run.t_s[i]);
                        reading += theta[n_terms + k] * reading_basis(rt, &rs);
                    }
                }
                for (k, rt) in self.model.run_reading_terms.iter().enumerate() {
                    let c = theta[first_run_reading + k];
                    if c != 0.0 {
                        let rs = self.reading_sample(r, &g.d[ii], run.t_s[i]);
                        reading += c * reading_basis(rt, &rs);
                    }
                }
                out.push(reading + known);
            }
            start += len;
        }
        Ok(out)
    }

    /// The model's ΔR (mm) at every sample of run `r` for parameters `theta` (all columns).
    pub fn predict_run(&self, r: usize, theta: &[f64]) -> Result<Vec<f64>, ModelError> {
        let mut scratch = RowScratch::default();
        let mut row = vec![0.0; self.n_cols()];
        let known = match self.model.options.bar_length {
            BarLength::Known(b) => b,
            BarLength::Fit => 0.0,
        };
        (0..self.runs[r].len())
            .map(|i| {
                self.row(r, i, &mut scratch, &mut row)?;
                Ok(row.iter().zip(theta).map(|(a, b)| a * b).sum::<f64>() + known)
            })
            .collect()
    }
}

/// The components (translation x, y, z, rotation x, y, z) that are not zero in some motion of
/// `basis`: a term's basis is mostly one component (a positional error's δ along its axis).
/// Each component's bits are or-ed over the motions with the sign bit shifted out (a value
/// is not zero exactly when those bits are not all zero, a NaN included): integer operations
/// the compiler takes several of at once.
#[inline]
fn used_components(basis: &[ErrorMotion]) -> [bool; 6] {
    let mut bits = [0u64; 6];
    for e in basis {
        for (b, x) in bits.iter_mut().zip(e) {
            *b |= x.to_bits() << 1;
        }
    }
    bits.map(|b| b != 0)
}

/// `out[i] = sens[i · stride].apply(basis[i])`: ΔR of each sample's motion, its joint's
/// sensitivity taken every `stride` entries. A component that is zero in every motion is
/// left out: it adds exact zeros, so the sums are the same numbers (to the sign of a zero).
#[inline]
fn apply_sensitivities(
    sens: &[JointSensitivity],
    stride: usize,
    basis: &[ErrorMotion],
    out: &mut [f64],
) {
    let basis = &basis[..out.len()];
    let used = used_components(basis);
    match used.iter().filter(|&&u| u).count() {
        0 => out.fill(0.0),
        // One loop per component, so that the component is a constant in it.
        1 => match used.iter().position(|&u| u).expect("one component") {
            0 => apply_component(sens, stride, basis, out, 0, |s| s.translation[0]),
            1 => apply_component(sens, stride, basis, out, 1, |s| s.translation[1]),
            2 => apply_component(sens, stride, basis, out, 2, |s| s.translation[2]),
            3 => apply_component(sens, stride, basis, out, 3, |s| s.rotation[0]),
            4 => apply_component(sens, stride, basis, out, 4, |s| s.rotation[1]),
            _ => apply_component(sens, stride, basis, out, 5, |s| s.rotation[2]),
        },
        _ => {
            for ((s, e), x) in sens.iter().step_by(stride).zip(basis).zip(out.iter_mut()) {
                *x = s.apply(e);
            }
        }
    }
}

/// [`apply_sensitivities`] of motions with one component `k`, its values in `out` on entry:
/// the same numbers (a column of zeros, of either sign, is `+0` as there).
fn apply_component_in_place(sens: &[JointSensitivity], stride: usize, out: &mut [f64], k: usize) {
    if out.iter().all(|x| x.to_bits() << 1 == 0) {
        out.fill(0.0);
        return;
    }
    // One loop per component, so that the component is a constant in it.
    let scale = |g: fn(&JointSensitivity) -> f64, out: &mut [f64]| {
        for (s, x) in sens.iter().step_by(stride).zip(out.iter_mut()) {
            *x *= g(s);
        }
    };
    match k {
        0 => scale(|s| s.translation[0], out),
        1 => scale(|s| s.translation[1], out),
        2 => scale(|s| s.translation[2], out),
        3 => scale(|s| s.rotation[0], out),
        4 => scale(|s| s.rotation[1], out),
        _ => scale(|s| s.rotation[2], out),
    }
}

/// [`apply_sensitivities`] of motions with one component `k`, whose sensitivity `g` reads.
#[inline(always)]
fn apply_component(
    sens: &[JointSensitivity],
    stride: usize,
    basis: &[ErrorMotion],
    out: &mut [f64],
    k: usize,
    g: impl Fn(&JointSensitivity) -> f64,
) {
    for ((s, e), x) in sens.iter().step_by(stride).zip(basis).zip(out.iter_mut()) {
        *x = g(s) * e[k];
    }
}

/// `errs[i · stride] += c · basis[i]` per sample; components zero in every motion of the
/// chunk are skipped (adding `c · 0` changes no sum).
#[inline]
fn accumulate_motions(c: f64, basis: &[ErrorMotion], errs: &mut [ErrorMotion], stride: usize) {
    let used = used_components(basis);
    for (ii, b) in basis.iter().enumerate() {
        let target = &mut errs[ii * stride];
        for k in 0..6 {
            if used[k] {
                target[k] += c * b[k];
            }
        }
    }
}

/// The exact ball distance (mm) at machine state `q`: each chain term `k` contributes the error
/// motion `coeffs[k] · basis_k(state)` to its joint, applied as a rigid transform; the table ball
/// is displaced by `centring` (in the table frame); the model's run terms contribute with the
/// run's own `run_coeffs`. With `skip_lag`, servo-lag terms are left out (a simulator realises
/// Add `c` times term `bt`'s error motion at its joint's state to the joint's motion on its
/// branch (`tool` and `work`: one 6-vector per joint of each branch).
pub(crate) fn add_motion(
    bt: &crate::term::BoundTerm,
    c: f64,
    states: &[JointState; 6],
    tool: &mut [[f64; 6]],
    work: &mut [[f64; 6]],
) -> Result<(), ModelError> {
    let b = bt.term.basis(&states[bt.axis.index()])?;
    let target = match bt.branch {
        Branch::Tool => &mut tool[bt.joint],
        Branch::Workpiece => &mut work[bt.joint],
    };
    for (t, bk) in target.iter_mut().zip(b) {
        *t += c * bk;
    }
    Ok(())
}

/// them in the time domain instead).
#[allow(clippy::too_many_arguments)]
pub fn exact_length(
    model: &Model,
    q: &[f64; 6],
    states: &[JointState; 6],
    balls: &BallSetup,
    centring: &Vector3<f64>,
    coeffs: &[f64],
    run_coeffs: &[f64],
    skip_lag: bool,
    scratch: &mut ExactScratch,
) -> Result<f64, ModelError> {
    let chain = &model.chain;
    let (tool, work) = (&mut scratch.tool, &mut scratch.work);
    tool.clear();
    tool.resize(chain.tool.len(), [0.0; 6]);
    work.clear();
    work.resize(chain.workpiece.len(), [0.0; 6]);
    let run_terms = model.run_terms.iter().zip(run_coeffs);
    for (bt, &c) in model.terms.iter().zip(coeffs).chain(run_terms) {
        if skip_lag && bt.term.class() == crate::TermClass::ServoLag {
            continue;
        }
        if c == 0.0 {
            continue;
        }
        add_motion(bt, c, states, tool, work)?;
    }
    chain.pose_into(q, balls, Some(tool), Some(work), &mut scratch.pose);
    let pose = &scratch.pose;
    Ok((pose.tool_ball - (pose.table_ball + table_rotation(pose) * centring)).norm())
}

/// The parameters of a run's own coefficients of the model's run terms (`VSX@run`, ...).
fn run_term_parameters(model: &Model, run: &Run) -> Vec<Parameter> {
    model
        .run_terms
        .iter()
        .map(|t| Parameter {
            id: format!("{}@{}", t.term.id(), run.name()),
            label: format!("{} in run {}", t.term.label(), run.name()),
            unit: t.term.unit(),
            class: ParamClass::RunTerm(t.term.class()),
        })
        .chain(model.run_reading_terms.iter().map(|rt| Parameter {
            id: format!("{}@{}", reading_id(rt), run.name()),
            label: format!("{} in run {}", run_reading_label(rt), run.name()),
            unit: Unit::Length,
            class: ParamClass::RunTerm(crate::TermClass::Effect),
        }))
        .collect()
}

/// The label of a reading term that has one coefficient per run.
fn run_reading_label(rt: &ReadingTerm) -> &'static str {
    match rt {
        ReadingTerm::BarLength => "bar length",
        ReadingTerm::PlaneMismatch(_) => "servo mismatch",
        ReadingTerm::BarGrowth => "bar growth",
        ReadingTerm::RadiusLoss => "servo radius loss",
    }
}

/// What a reading term sees at one sample.
#[derive(Clone, Copy, Debug)]
pub struct ReadingSample<'a> {
    /// The run's plane.
    pub plane: Plane,
    /// The paper's direction sign `D` (+1 CW, -1 CCW, 0 for free paths).
    pub paper_sign: f64,
    /// The nominal relative vector `d` (tool ball less table ball), mm.
    pub d: &'a Vector3<f64>,
    /// The run's radius, mm.
    pub radius_mm: f64,
    /// The programmed feed, mm/s.
    pub feed_mm_per_s: f64,
    /// Time since the session's start, s.
    pub session_t_s: f64,
}

/// The basis of a reading term at one sample.
pub fn reading_basis(rt: &ReadingTerm, s: &ReadingSample<'_>) -> f64 {
    match rt {
        ReadingTerm::BarLength => 1.0,
        ReadingTerm::PlaneMismatch(p) => {
            if *p != s.plane {
                return 0.0;
            }
            let (ua, va, _) = p.axes().expect("planar");
            (s.d[ua.index()] / s.radius_mm) * (s.d[va.index()] / s.radius_mm) * s.paper_sign
        }
        ReadingTerm::BarGrowth => s.session_t_s,
        ReadingTerm::RadiusLoss => -s.feed_mm_per_s * s.feed_mm_per_s / (2.0 * s.radius_mm),
    }
}

/// The machine state of sample `i` (axes the run lacks stay 0).
pub fn fill_q(run: &Run, i: usize, q: &mut [f64; 6]) {
    for a in Axis::ALL {
        q[a.index()] = run.axis(a).map(|c| c[i]).unwrap_or(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::ModelOptions;
    use crate::path::CircleTest;
    use crate::{Direction, Effect, NoKernels};

    #[test]
    fn a_kept_geometry_gives_the_numbers_of_the_evaluation_chunk_by_chunk() {
        // The paper's terms, a run term (a vibration) and a reading term that reads `d`; two
        // runs. A design of its own evaluates each chunk's geometry as it goes; one made
        // from another (`with_model`) keeps it, and evaluates from it the second time: all
        // three give the same numbers, bit for bit.
        let spec = crate::machines::column();
        let vib = [Effect::Vibration { axis: Axis::X, frequency_hz: 17.0 }];
        let mut model =
            Model::with_effects(spec, ModelOptions::default(), &NoKernels, &vib).unwrap();
        model.reading_terms.push(ReadingTerm::PlaneMismatch(Plane::XY));
        let circle = |direction, feed_mm_per_min| CircleTest {
            plane: Plane::XY,
            direction,
            radius_mm: 100.0,
            feed_mm_per_min,
            pivot_mm: [300.0, 200.0, -300.0],
            table_ball_mm: [0.0, 0.0, 50.0],
            tool_ball_mm: [0.0, 0.0, -100.0],
            sample_rate_hz: 100.0,
            start_deg: 0.0,
            sweep_deg: 360.0,
        };
        let runs = vec![
            circle(Direction::CW, 1000.0).run("2026-11-21T10:00:00Z", 0.0, "a", "t"),
            circle(Direction::CCW, 2500.0).run("2026-11-21T10:01:00Z", 60.0, "b", "t"),
        ];
        let alone = Design::new(&model, &runs).unwrap();
        let first = Design::new(&model, &runs).unwrap();
        let kept = first.with_model(&model).unwrap();
        let n = alone.n_cols();
        let theta: Vec<f64> = (0..n)
            .map(|j| {
                1e-5 * ((j as f64 * 0.7).sin() + 0.2) / alone.parameters[j].unit.display_factor()
                    * 1e3
            })
            .collect();
        let cols: Vec<usize> = (0..n).collect();
        let mut scratch = BlockScratch::default();
        for (r, run) in runs.iter().enumerate() {
            let m = run.len();
            let mut evaluate = |d: &Design<'_>| {
                let (mut block, mut targets) = (vec![0.0; m * n], vec![0.0; m]);
                d.fill_run(r, &cols, &mut block, &mut targets, &mut scratch).unwrap();
                (block, targets, d.exact_run_with(r, &theta, &mut scratch).unwrap())
            };
            let reference = evaluate(&alone);
            assert!(
                alone.prepared[r].geometry.states.get().is_none(),
                "a design alone keeps nothing"
            );
            assert_eq!(evaluate(&kept), reference, "run {r}: the geometry evaluated and kept");
            assert!(first.prepared[r].geometry.nominal.get().is_some(), "kept for both designs");
            assert_eq!(evaluate(&first), reference, "run {r}: from the kept geometry");
        }
    }
}

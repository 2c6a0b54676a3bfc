//! Least-squares identification of a ballbar error model.
//!
//! # Method
//! The design `A` (one row per sample, [`ballbar_model::Design`]) and the readings `b` are
//! factored run by run: each run's block `[A_r | b_r]` is QR-factored on a worker thread, its
//! own columns (centring) first, and the machine columns' triangles are stacked and factored
//! again (a tall-skinny QR; the runs' own columns are eliminated by their own triangles, so the
//! stacked system never holds a column per run). That gives `[A | b] = Q [R  c; 0  ρ]` without
//! ever forming `AᵀA`. Columns are then scaled to unit norm
//! (`‖A_j‖ = ‖R_j‖`, since `Q` is orthonormal), `R D = U S Vᵀ` is decomposed, and singular values
//! below [`RANK_TOLERANCE`] · σ_max are truncated:
//! $$ \hat θ = D V_r S_r^{-1} U_r^ᵀ c . $$
//! The truncated right singular vectors span the combinations of parameters the tests cannot
//! separate; they are reported, rotated to reduced row-echelon form so that each names a few
//! parameters. A parameter (or a linear functional of them) is estimable when it is orthogonal
//! to that null space; only estimable quantities get values.
//!
//! What the runs cannot determine is *gauged* before the refinement ([`gauge`]): the terms of an
//! axis that does not move and parameters that act on no reading are fixed at 0, the lag
//! common to the moving axes is fixed by a mean lag of 0, the bar length that one radius cannot
//! tell from the common scale is taken at its nominal length, and kept directions that the runs
//! do not determine (aliased to within the coordinates' resolution, or uncertain beyond the
//! regime in which the first-order design describes the chain) are truncated. Each gauge is a
//! linear constraint on the solution, imposed by projecting it out of the scaled `R` before the
//! SVD; each is stated in [`Fit::gauges`]. Estimability is then relative to those choices, and
//! [`Fit::depends_on`] says which values hold only for one of them (the positional errors under
//! the bar's nominal length); [`Fit::null_space`] still lists everything the runs cannot
//! separate.
//!
//! Standard uncertainties: `Cov = s² D V_r S_r^{-2} V_rᵀ D` with `s² = RSS/(m - rank)`, inflated
//! by `(1+ρ)/(1-ρ)` where ρ is the lag-one autocorrelation of the residuals within runs (an AR(1)
//! effective-sample-size correction: neighbouring samples of a trace are not independent).
//!
//! # Memory
//! Bounded per sample: a run's block is never held whole. It is generated chunk by chunk
//! ([`ballbar_model::Design::fill_rows`], 4096 rows) and factored by rows (each chunk stacked
//! under the running triangle and factored again), so a worker holds one chunk; of a run, only
//! its triangle `R_r`, `Q_rᵀ b_r` and its targets are kept. Where another right-hand side is
//! needed (the refinement's misfit against the exact chain, or [`Factorisation::solve`]), the
//! rows are generated and factored again (the same `R_r` to the last bit) with that side carried
//! along; `A θ` ([`Factorisation::apply`]) is the generated rows times θ. The price is a QR of
//! the data per refinement pass. What stays per sample: the runs, their targets and the
//! residuals ([`Fit::residuals`]); per run, its triangle; and, whatever the samples, the
//! `n × n` matrices of the SVD and the gauges (`n` parameters: two centring offsets per run
//! make `n` grow with the runs).

use ballbar_model::parallel::par_map;
use ballbar_model::{BlockScratch, Design, Parameter};
use faer::Mat;

pub mod alias;
pub mod gauge;
pub mod local;
pub mod metrics;
pub mod saved;
pub mod switch;

pub use gauge::{Gauge, GaugeKind};

/// Relative singular-value cut-off of the column-scaled design. Exactly aliased columns leave
/// singular values at rounding level, ~1e-15·√m ≈ 1e-13 relative; genuinely separable but weakly
/// conditioned designs of ballbar tests stay above 1e-7. 1e-9 sits between with margin both ways.
pub const RANK_TOLERANCE: f64 = 1e-9;

/// Components of a null-space combination below this (relative to its largest) are dropped
/// from the printed combination: they are rounding noise of the rotation.
const COMBINATION_DROP: f64 = 1e-6;

/// Errors of identification.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum FitError {
    /// Too few samples, or samples that determine none of the machine parameters (an arc of a
    /// few degrees).
    #[error("{samples} samples cannot identify {parameters} parameters")]
    TooFewSamples {
        /// Samples.
        samples: usize,
        /// Parameters.
        parameters: usize,
    },
    /// The SVD did not converge.
    #[error("the singular value decomposition did not converge")]
    Svd,
    /// The model could not be evaluated (a plugin kernel failed).
    #[error(transparent)]
    Model(#[from] ballbar_model::ModelError),
    /// The chord refinement moved away from the first-order solution instead of converging.
    #[error(
        "the exact model does not converge from the first-order solution (the update grew from {last_mm:.2e} to {next_mm:.2e} mm RMS): these runs hardly constrain some parameters (condition number {condition_number:.1e}); use full circles, more planes, or fewer terms"
    )]
    Diverged {
        /// The RMS change of the previous update, mm.
        last_mm: f64,
        /// The RMS change of this update, mm.
        next_mm: f64,
        /// Condition number of the kept singular values.
        condition_number: f64,
    },
    /// Non-finite data reached the solver, or the data are of magnitudes whose squares
    /// overflow: there is no finite solution.
    #[error(
        "the fit has no finite solution: a value in the runs (a reading, a coordinate, the radius, the pivot or a time) is too large for its arithmetic"
    )]
    NonFinite,
}

/// A combination of parameters that the tests cannot separate: moving the parameters together
/// by these amounts (display units) changes no reading.
#[derive(Clone, Debug, PartialEq)]
pub struct NullCombination {
    /// `(parameter index, amount in the parameter's display unit)`, the largest amount ±1.
    pub components: Vec<(usize, f64)>,
}

/// The result of a fit.
#[derive(Clone, Debug)]
pub struct Fit {
    /// The parameters, in column order.
    pub parameters: Vec<Parameter>,
    /// Number of machine parameters (leading columns).
    pub n_machine: usize,
    /// Estimates, internal units (for what the runs cannot determine, the gauges' values and
    /// otherwise minimum-norm: see `estimable`, `gauges`).
    pub values: Vec<f64>,
    /// Standard uncertainties, internal units.
    pub std_uncertainty: Vec<f64>,
    /// Whether each parameter is estimable on its own, given the gauges' choices.
    pub estimable: Vec<bool>,
    /// Numerical rank.
    pub rank: usize,
    /// Singular values of the column-scaled design, descending.
    pub singular_values: Vec<f64>,
    /// σ_max / σ_min over the kept singular values.
    pub condition_number: f64,
    /// Combinations the tests cannot separate (before the gauges' choices).
    pub null_space: Vec<NullCombination>,
    /// The choices made for what these runs cannot determine ([`gauge`]), in the order made.
    pub gauges: Vec<Gauge>,
    /// Residual standard deviation, mm.
    pub sigma_mm: f64,
    /// Degrees of freedom `m - rank`.
    pub dof: usize,
    /// Lag-one autocorrelation of residuals within runs.
    pub rho: f64,
    /// Variance inflation applied to the covariance, `(1+ρ)/(1-ρ)` (≥ 1).
    pub inflation: f64,
    /// Residual (reading - model) per run and sample, mm.
    pub residuals: Vec<Vec<f64>>,
    /// Number of samples.
    pub n_samples: usize,
    /// Per axis (X, Y, Z, A, B, C), s: where the fitted design's backlash and reversal
    /// transients switch, after the commanded reversal (`Design::with_switch_lags`; all 0:
    /// the commanded reversal). Part of the fitted model: a prediction from it switches there.
    pub switch_lags_s: [f64; 6],
    /// Scaled covariance factor: `Cov = W Wᵀ`, W = n × rank (internal units).
    cov_factor: Mat<f64>,
    /// Null-space basis in scaled coordinates (n × (n - rank)).
    null_scaled: Mat<f64>,
    /// Column scales D.
    scale: Vec<f64>,
    /// Per gauge, the unseen direction (scaled) whose value its choice sets, where that is
    /// not simply the parameters it fixes: the functionals with a part along it hold for it.
    dependence: Vec<Option<Vec<f64>>>,
}

/// A linear functional's estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Value.
    pub value: f64,
    /// Standard uncertainty.
    pub std_uncertainty: f64,
    /// False when the tests cannot determine it.
    pub estimable: bool,
}

impl Fit {
    /// Estimate `Σ c_i θ_i` for `(parameter index, c_i)` pairs.
    pub fn functional(&self, coeffs: &[(usize, f64)]) -> Estimate {
        let n = self.values.len();
        let mut c = vec![0.0; n];
        for &(i, f) in coeffs {
            c[i] += f;
        }
        let value = c.iter().zip(&self.values).map(|(a, b)| a * b).sum();
        let cs: Vec<f64> = c.iter().zip(&self.scale).map(|(a, d)| a * d).collect();
        let norm = cs.iter().map(|x| x * x).sum::<f64>().sqrt();
        let mut leak = 0.0;
        for k in 0..self.null_scaled.ncols() {
            let p: f64 = (0..n).map(|i| cs[i] * self.null_scaled[(i, k)]).sum();
            leak += p * p;
        }
        let estimable = norm == 0.0 || leak.sqrt() <= 1e-6 * norm;
        let mut var = 0.0;
        for k in 0..self.cov_factor.ncols() {
            let p: f64 = (0..n).map(|i| c[i] * self.cov_factor[(i, k)]).sum();
            var += p * p;
        }
        Estimate { value, std_uncertainty: var.sqrt(), estimable }
    }

    /// The gauges (indices into [`Fit::gauges`]) whose choice the value of `Σ c_i θ_i` depends
    /// on: empty for a functional the runs determine whatever the choices (or that they do not
    /// determine at all, see [`Fit::functional`]).
    pub fn depends_on(&self, coeffs: &[(usize, f64)]) -> Vec<usize> {
        let mut cs = vec![0.0; self.values.len()];
        for &(i, f) in coeffs {
            cs[i] += f * self.scale[i];
        }
        let norm = cs.iter().map(|x| x * x).sum::<f64>().sqrt();
        self.dependence
            .iter()
            .enumerate()
            .filter_map(|(g, p)| {
                let p = p.as_ref()?;
                let along: f64 = cs.iter().zip(p).map(|(a, b)| a * b).sum();
                (norm > 0.0 && along.abs() > gauge::SUBSPACE_TOLERANCE * norm).then_some(g)
            })
            .collect()
    }

    /// Index of a parameter by id.
    pub fn index(&self, id: &str) -> Option<usize> {
        self.parameters.iter().position(|p| p.id == id)
    }

    /// RMS of the residuals of run `r`, mm.
    pub fn run_rms(&self, r: usize) -> f64 {
        metrics::rms(&self.residuals[r])
    }
}

/// `out[i] += Σ_j a[i, j] x[j]` for a column-major `a` of `out.len()` rows, each row's sum
/// taken in column order from −0.0: bit for bit the value of the iterator sum
/// `(0..n).map(|j| a[(i, j)] * x[j]).sum::<f64>()` (whose start is −0.0), added to `out[i]`
/// (start `out` at −0.0 for the sum itself), but read column by column, contiguously: the
/// row-by-row sum reads `a` at a stride of its column length, from memory each time.
pub fn add_product_in_column_order(a: &[f64], x: impl Fn(usize) -> f64, out: &mut [f64]) {
    let rows = out.len();
    if rows == 0 {
        return;
    }
    let mut sum = vec![-0.0; rows];
    for (j, col) in a.chunks_exact(rows).enumerate() {
        let xj = x(j);
        for (s, &v) in sum.iter_mut().zip(col) {
            *s += v * xj;
        }
    }
    for (o, s) in out.iter_mut().zip(sum) {
        *o += s;
    }
}

/// Clear the upper halves of the vector registers after a call into faer: `vzeroupper`, on x86
/// with AVX (nothing elsewhere).
///
/// faer's x86 matrix-product kernels (the assembly of `private-gemm-x86` 0.1, behind its QR,
/// Householder applications, SVD and matrix products) return with the upper halves of the
/// wide (AVX, AVX-512) registers in use. This workspace is built for baseline x86-64, so its own
/// floating-point loops are SSE instructions, and on a core whose upper state is dirty every
/// one of them pays for the mixed state, until something clears it: measured 4.5× on the
/// diagnosis's loop of products, and a quarter of the whole diagnosis's processor time.
/// Every call into faer here that can reach those kernels is followed by this. It runs,
/// through faer's own dispatch (pulp), a function compiled for AVX that touches a wide
/// register, which the compiler ends with `vzeroupper`.
pub fn clear_upper_registers() {
    use faer::traits::pulp::{Arch, Simd, WithSimd};
    struct Touch;
    impl WithSimd for Touch {
        type Output = ();
        #[inline(always)]
        fn with_simd<S: Simd>(self, simd: S) {
            std::hint::black_box(simd.splat_f64s(0.0));
        }
    }
    Arch::new().dispatch(Touch);
}

/// Apply `Qᵀ` of a Householder QR to the columns of `v` in place.
pub fn apply_qt(qr: &faer::linalg::solvers::Qr<f64>, v: &mut Mat<f64>) {
    apply_qt_in_place(qr, v.as_mut());
}

/// [`apply_qt`] on a view (the rows of a unit in a larger buffer, say): the blocked
/// Householder sequence applied by matrix products.
pub fn apply_qt_in_place(qr: &faer::linalg::solvers::Qr<f64>, v: faer::MatMut<'_, f64>) {
    apply_householder(qr, v);
}

/// A QR's blocked Householder sequence applied to `v` on the left, transposed: `Qᵀ v`.
fn apply_householder(qr: &faer::linalg::solvers::Qr<f64>, v: faer::MatMut<'_, f64>) {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::householder as hh;
    let (basis, coeff) = (qr.Q_basis(), qr.Q_coeff());
    let (rows, block, cols) = (basis.nrows(), coeff.nrows(), v.ncols());
    let req = hh::apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>(
        rows, block, cols,
    );
    let mut buf = MemBuffer::new(req);
    let stack = MemStack::new(&mut buf);
    hh::apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
        basis,
        coeff,
        faer::Conj::No,
        v,
        faer::Par::Seq,
        stack,
    );
    clear_upper_registers();
}

/// The minimum-norm truncated least-squares solution of a small dense system `a x ≈ y`
/// (columns scaled to unit norm, SVD, singular values below [`RANK_TOLERANCE`] · σ_max
/// dropped, as in [`fit`]); returns the solution and the numerical rank. Zero columns get 0.
///
/// faer's bidiagonal SVD (0.24) can fail to converge on an ordinary rank-deficient system
/// (seen on the base model plus a candidate effect fitted on runs at two centres, which leave
/// an exact null space). Then the same system is first reduced by a column-pivoted QR,
/// `A P = Q R`, which puts the rank deficiency at the end of `R`, and solved there
/// ([`lstsq_pivoted`]): the truncated minimum-norm solution is unchanged, since the scaled
/// SVD only turns by `Qᵀ` on the left and `P` on the right, and `x = P z` (tested).
pub fn lstsq(a: faer::MatRef<'_, f64>, y: &[f64]) -> Result<(Vec<f64>, usize), FitError> {
    match lstsq_svd(a, y) {
        Err(FitError::Svd) => lstsq_pivoted(a, y),
        other => other,
    }
}

/// [`lstsq`] of the system reduced by a column-pivoted QR.
pub fn lstsq_pivoted(a: faer::MatRef<'_, f64>, y: &[f64]) -> Result<(Vec<f64>, usize), FitError> {
    let (m, n) = (a.nrows(), a.ncols());
    if m < n
        || a.col_iter().any(|c| c.iter().any(|x| !x.is_finite()))
        || y.iter().any(|x| !x.is_finite())
    {
        return lstsq_svd(a, y);
    }
    let qr = a.col_piv_qr();
    let mut qy = Mat::<f64>::from_fn(m, 1, |i, _| y[i]);
    {
        use faer::dyn_stack::{MemBuffer, MemStack};
        use faer::linalg::householder as hh;
        let (basis, coeff) = (qr.Q_basis(), qr.Q_coeff());
        let req = hh::apply_block_householder_sequence_transpose_on_the_left_in_place_scratch::<f64>(
            basis.nrows(),
            coeff.nrows(),
            1,
        );
        let mut buf = MemBuffer::new(req);
        hh::apply_block_householder_sequence_transpose_on_the_left_in_place_with_conj(
            basis,
            coeff,
            faer::Conj::No,
            qy.as_mut(),
            faer::Par::Seq,
            MemStack::new(&mut buf),
        );
    }
    clear_upper_registers();
    let r = qr.thin_R();
    let top: Vec<f64> = (0..n).map(|i| qy[(i, 0)]).collect();
    let (z, rank) = lstsq_svd(r, &top)?;
    // Column j of A P is column fwd[j] of A.
    let (fwd, _) = qr.P().arrays();
    let mut x = vec![0.0; n];
    for (j, &p) in fwd.iter().enumerate() {
        x[p] = z[j];
    }
    Ok((x, rank))
}

/// [`lstsq`] by the SVD alone (no fallback).
pub fn lstsq_svd(a: faer::MatRef<'_, f64>, y: &[f64]) -> Result<(Vec<f64>, usize), FitError> {
    let norms: Vec<f64> =
        (0..a.ncols()).map(|j| a.col(j).iter().map(|x| x * x).sum::<f64>().sqrt()).collect();
    lstsq_svd_scaled(a, y, &norms)
}

/// [`lstsq`] of a system whose columns are scaled by given norms rather than their own: for a
/// system reduced from a larger one (another block's columns eliminated), whose columns are
/// scaled as in the larger system, so that a column the eliminated ones explained (left at
/// rounding level) stays at rounding level instead of being scaled up to look estimable.
/// Falls back to [`lstsq_pivoted`] (its own scaling) where the SVD does not converge.
pub fn lstsq_with_norms(
    a: faer::MatRef<'_, f64>,
    y: &[f64],
    norms: &[f64],
) -> Result<(Vec<f64>, usize), FitError> {
    match lstsq_svd_scaled(a, y, norms) {
        Err(FitError::Svd) => lstsq_pivoted(a, y),
        other => other,
    }
}

/// [`lstsq_svd`] with the columns scaled by `1 / norms` (0 for a norm of 0).
fn lstsq_svd_scaled(
    a: faer::MatRef<'_, f64>,
    y: &[f64],
    norms: &[f64],
) -> Result<(Vec<f64>, usize), FitError> {
    let (m, n) = (a.nrows(), a.ncols());
    if n == 0 {
        return Ok((vec![], 0));
    }
    if a.col_iter().any(|c| c.iter().any(|x| !x.is_finite())) || y.iter().any(|x| !x.is_finite()) {
        return Err(FitError::NonFinite);
    }
    let scale: Vec<f64> = norms.iter().map(|&x| if x > 0.0 { 1.0 / x } else { 0.0 }).collect();
    let scaled = Mat::<f64>::from_fn(m, n, |i, j| a[(i, j)] * scale[j]);
    let svd = scaled.as_ref().thin_svd();
    clear_upper_registers();
    let svd = svd.map_err(|_| FitError::Svd)?;
    let sv = svd.S().column_vector();
    let k = sv.nrows();
    let smax = (0..k).map(|i| sv[i]).fold(0.0, f64::max);
    let (u, v) = (svd.U(), svd.V());
    let mut x = vec![0.0; n];
    let mut rank = 0;
    for i in 0..k {
        if smax == 0.0 || sv[i] <= RANK_TOLERANCE * smax {
            continue;
        }
        rank += 1;
        let coef: f64 = (0..m).map(|r| u[(r, i)] * y[r]).sum::<f64>() / sv[i];
        for (j, xj) in x.iter_mut().enumerate() {
            *xj += v[(j, i)] * coef;
        }
    }
    for (xj, sj) in x.iter_mut().zip(&scale) {
        *xj *= sj;
    }
    Ok((x, rank))
}

/// Rows of a run's block generated and factored together: a run is streamed through a buffer
/// of this many rows (at least four times its columns) instead of being held whole. 4096 rows
/// of 40 columns are 1.3 MB a worker; the extra rows of the running `R` stacked on each chunk
/// cost `n / 4096` (1 %) of the QR's work.
const CHUNK_ROWS: usize = 4096;

/// What [`Factorisation::weak_directions`] finds: the weak directions, the common lag's weakness
/// and the first-order residual's sums ([`Factorisation::first_order_residual`]).
type WeakDirections =
    Result<(Vec<(usize, gauge::Weakness)>, Option<gauge::LagWeakness>, (f64, f64)), FitError>;

/// One run's part of the factorisation: what later steps need of its block, whose rows are
/// regenerated from the run whenever they are needed again, unless the design keeps its
/// geometry ([`Design::keeps_geometry`]: a caller that evaluates the same runs again and
/// again, the diagnosis): then they are kept as first generated.
struct RunFactor {
    /// The global column of each column of the block: the run's own columns (its centring and
    /// run-term coefficients) first, then the machine parameters `0..n_machine`.
    cols: Vec<usize>,
    /// How many of `cols` are the run's own.
    n_own: usize,
    /// `R_r` of the block's QR (`cols.len()` square, upper triangular).
    r: Mat<f64>,
    /// The top of `Q_rᵀ b_r`.
    qtb: Vec<f64>,
    /// The targets `b_r`, mm.
    b: Vec<f64>,
    /// The block's rows, column-major (`b.len()` rows, `cols.len()` columns), where the design
    /// keeps its geometry; empty otherwise.
    rows: Vec<f64>,
    /// With the rows, each chunk's QR as [`stream_qr`] made it (the running `R` stacked on the
    /// chunk's rows): a later pass applies their `Qᵀ` to its right-hand sides instead of
    /// factoring the same rows again, which gives the same factors (the same numbers through
    /// the same arithmetic) at the cost of the QR. About as large as the rows.
    qrs: Vec<faer::linalg::solvers::Qr<f64>>,
}

impl RunFactor {
    /// The kept rows and targets, and each chunk's QR, if kept.
    fn kept(&self) -> Option<Kept<'_>> {
        (!self.rows.is_empty()).then_some(Kept {
            rows: &self.rows,
            targets: &self.b,
            qrs: &self.qrs,
        })
    }
}

/// A run's rows as a [`Factorisation`] kept them ([`RunFactor::kept`]), for [`stream_qr`].
#[derive(Clone, Copy)]
struct Kept<'k> {
    /// The rows, column-major.
    rows: &'k [f64],
    /// The targets.
    targets: &'k [f64],
    /// Each chunk's QR.
    qrs: &'k [faer::linalg::solvers::Qr<f64>],
}

/// The QR of run `r`'s block (columns `cols`) streamed chunk by chunk: each chunk of
/// [`CHUNK_ROWS`] rows is generated ([`Design::fill_rows`]), stacked under the running `R`
/// and factored again (a row-block Householder QR), so that no more than one chunk is held.
/// `rhs(start, a, b, y)` writes the chunk's right-hand sides `y` (`len × k`) from its rows
/// `a` and targets `b`; their `Qᵀ` is carried along. A run with fewer rows than columns is
/// padded with zero rows (which change no least-squares problem). Returns `R` (square), the
/// top of `Qᵀ y` and whether every entry was finite (`false`: the factors are not computed).
/// The rows are read from `kept` (the run's rows column-major, its targets and each chunk's
/// QR, as an earlier call kept them in `keep_rows`) instead of generated when given, and each
/// chunk's kept QR is applied instead of factoring it again: the same numbers. The `R`
/// returned is then not computed (zero): a caller with kept rows has it.
#[allow(clippy::too_many_arguments)]
fn stream_qr(
    design: &Design<'_>,
    r: usize,
    cols: &[usize],
    k: usize,
    rhs: &mut dyn FnMut(usize, faer::MatRef<'_, f64>, &[f64], faer::MatMut<'_, f64>),
    mut keep_b: Option<&mut Vec<f64>>,
    kept: Option<Kept<'_>>,
    mut keep_rows: Option<(&mut Vec<f64>, &mut Vec<faer::linalg::solvers::Qr<f64>>)>,
) -> Result<(Mat<f64>, Mat<f64>, bool), FitError> {
    let m = design.runs[r].len();
    let nc = cols.len();
    let chunk = CHUNK_ROWS.max(4 * nc);
    let mut scratch = BlockScratch::default();
    let mut abuf = vec![0.0; chunk.min(m) * nc];
    let mut bbuf = vec![0.0; chunk.min(m)];
    let mut rr = Mat::<f64>::zeros(nc, nc);
    let mut top = Mat::<f64>::zeros(nc, k);
    let mut started = false;
    let mut start = 0;
    if let Some((keep, qrs)) = keep_rows.as_mut() {
        keep.clear();
        keep.resize(m * nc, 0.0);
        qrs.clear();
    }
    let mut n_chunk = 0;
    while start < m || !started {
        let len = chunk.min(m - start);
        let (a, b) = (&mut abuf[..len * nc], &mut bbuf[..len]);
        match kept {
            Some(Kept { rows, targets, .. }) => {
                for (j, col) in a.chunks_exact_mut(len.max(1)).enumerate().take(nc) {
                    col[..len].copy_from_slice(&rows[j * m + start..j * m + start + len]);
                }
                b.copy_from_slice(&targets[start..start + len]);
            }
            None => design.fill_rows(r, start..start + len, cols, a, b, &mut scratch)?,
        }
        if !(a.iter().all(|x| x.is_finite()) && b.iter().all(|x| x.is_finite())) {
            return Ok((rr, top, false));
        }
        if let Some(keep) = keep_b.as_deref_mut() {
            keep.extend_from_slice(b);
        }
        if let Some((keep, _)) = keep_rows.as_mut() {
            for (j, col) in a.chunks_exact(len.max(1)).enumerate().take(nc) {
                keep[j * m + start..j * m + start + len].copy_from_slice(&col[..len]);
            }
        }
        let a = faer::MatRef::from_column_major_slice(a, len, nc);
        let off = if started { nc } else { 0 };
        let rows = (off + len).max(nc);
        let mut y = Mat::<f64>::zeros(rows, k);
        if started {
            y.as_mut().subrows_mut(0, nc).copy_from(&top);
        }
        rhs(start, a, b, y.as_mut().subrows_mut(off, len));
        match kept.and_then(|k| k.qrs.get(n_chunk)) {
            // The chunk's QR as the first pass made it from the same rows.
            Some(qr) => apply_qt(qr, &mut y),
            None => {
                let mut st = Mat::<f64>::zeros(rows, nc);
                if started {
                    st.as_mut().subrows_mut(0, nc).copy_from(&rr);
                }
                st.as_mut().subrows_mut(off, len).copy_from(a);
                let qr = st.as_ref().qr();
                clear_upper_registers();
                apply_qt(&qr, &mut y);
                let rf = qr.thin_R();
                rr = Mat::<f64>::from_fn(nc, nc, |i, j| if i <= j { rf[(i, j)] } else { 0.0 });
                if let Some((_, qrs)) = keep_rows.as_mut() {
                    qrs.push(qr);
                }
            }
        }
        top = y.as_ref().subrows(0, nc).to_owned();
        started = true;
        start += len;
        n_chunk += 1;
    }
    Ok((rr, top, true))
}

/// The SVD `A = U diag(s) Vᵀ` of a square matrix by one-sided Jacobi rotations (Hestenes):
/// pairs of columns of `A V` are rotated until every pair is orthogonal to 1e-15 of their
/// norms; the singular values are then the column norms, `U` the normalised columns (a zero
/// column stays zero: it belongs to the null space, which `V` spans). A column whose norm has
/// fallen to rounding of the whole matrix (`‖·‖ ≤ 1e-15 ‖A‖_F`, invariant under the rotations)
/// is a null direction: it is not rotated further (its rounding noise would never become
/// orthogonal). Accurate to rounding relative to the largest singular value whatever the rank;
/// `None` if 60 sweeps do not converge.
pub fn jacobi_svd(a: faer::MatRef<'_, f64>) -> Option<(Mat<f64>, Vec<f64>, Mat<f64>)> {
    let n = a.ncols();
    let m = a.nrows();
    let mut w = a.to_owned();
    let mut v = Mat::<f64>::identity(n, n);
    let frob2: f64 = (0..n).map(|j| (0..m).map(|i| a[(i, j)] * a[(i, j)]).sum::<f64>()).sum();
    let negligible = 1e-30 * frob2;
    for _ in 0..60 {
        let mut rotated = false;
        for p in 0..n {
            for q in p + 1..n {
                let (mut alpha, mut beta, mut gamma) = (0.0, 0.0, 0.0);
                for i in 0..m {
                    alpha += w[(i, p)] * w[(i, p)];
                    beta += w[(i, q)] * w[(i, q)];
                    gamma += w[(i, p)] * w[(i, q)];
                }
                if gamma == 0.0
                    || alpha.min(beta) <= negligible
                    || gamma.abs() <= 1e-15 * (alpha * beta).sqrt()
                {
                    continue;
                }
                rotated = true;
                let zeta = (beta - alpha) / (2.0 * gamma);
                // The smaller root of t² + 2ζt - 1 = 0 (ζ = 0: t = 1, a 45° rotation).
                let t = zeta.signum() / (zeta.abs() + (1.0 + zeta * zeta).sqrt());
                let c = 1.0 / (1.0 + t * t).sqrt();
                let s = c * t;
                for i in 0..m {
                    let (x, y) = (w[(i, p)], w[(i, q)]);
                    w[(i, p)] = c * x - s * y;
                    w[(i, q)] = s * x + c * y;
                }
                for i in 0..n {
                    let (x, y) = (v[(i, p)], v[(i, q)]);
                    v[(i, p)] = c * x - s * y;
                    v[(i, q)] = s * x + c * y;
                }
            }
        }
        if !rotated {
            let s: Vec<f64> =
                (0..n).map(|j| (0..m).map(|i| w[(i, j)] * w[(i, j)]).sum::<f64>().sqrt()).collect();
            let u =
                Mat::<f64>::from_fn(m, n, |i, j| if s[j] > 0.0 { w[(i, j)] / s[j] } else { 0.0 });
            return Some((u, s, v));
        }
    }
    None
}

/// The factorisation of a design, reusable for any right-hand side: per-run Householder QR,
/// the runs' own columns eliminated run by run and the machine columns' triangles stacked and
/// factored again, SVD of the column-scaled R under the gauges.
///
/// # Memory
/// Nothing of the size of the data is kept but the targets: each run's block is generated and
/// factored in chunks of 4096 rows (`stream_qr`), and of it only `R_r` and
/// `Q_rᵀ b_r` are kept. A right-hand side other than the targets ([`Factorisation::solve`]) or
/// a product `A θ` ([`Factorisation::apply`]) regenerates the run's rows from the run (and,
/// for `solve`, factors them again: the same `R_r` to the last bit, since the same rows go
/// through the same arithmetic): memory per sample is bounded by the runs, the targets and
/// what the caller holds, at the cost of a QR per `solve`. A design that keeps its geometry
/// ([`Design::keep_geometry`]: a caller that evaluates the same runs again and again, as the
/// diagnosis does) has its rows kept too, as first generated, with each chunk's QR (each
/// about 8 bytes a sample per column of the run's block, for the factorisation's life): later
/// passes read the rows instead of generating them again and apply the kept QRs' `Qᵀ` instead
/// of factoring the rows again, the same numbers.
///
/// The stacked system has the block-angular shape of a set of runs: a run's own columns
/// (its centring) appear in its block only. Each run's block is factored with its own
/// columns first, `R_r = [T_r S_r; 0 U_r]`; then `[diag(T_r) S; 0 R_m]`, with `R_m` the QR of
/// the stacked `U_r` (machine columns only), is a triangular factor of the whole design. The
/// stacked matrix is never formed: its size grew with the square of the number of runs.
pub struct Factorisation<'d> {
    design: &'d Design<'d>,
    /// Everything else: what [`Factorisation::detach`] keeps.
    f: Factors,
}

/// A factorisation detached from its design ([`Factorisation::detach`]), to be taken up again
/// on the same design ([`fit_prefactored`]): the backlash switch search factors the design it
/// ends on, and the fit that follows need not factor it again.
pub struct Prefactored {
    f: Factors,
    /// The shape and switch lags of the design it factored, checked when it is taken up.
    shape: (usize, usize, [f64; 6]),
}

impl<'d> std::ops::Deref for Factorisation<'d> {
    type Target = Factors;
    fn deref(&self) -> &Factors {
        &self.f
    }
}

impl<'d> std::ops::DerefMut for Factorisation<'d> {
    fn deref_mut(&mut self) -> &mut Factors {
        &mut self.f
    }
}

/// The factors of a [`Factorisation`], apart from the design they factor.
#[doc(hidden)]
pub struct Factors {
    threads: usize,
    n: usize,
    runs: Vec<RunFactor>,
    /// QR of the runs' stacked machine triangles `U_r`.
    machine: faer::linalg::solvers::Qr<f64>,
    /// A triangular factor of the design up to a row order (`‖A x‖ = ‖M x‖`), columns in the
    /// design's order: per run its own rows, then the machine rows.
    m_factor: Mat<f64>,
    /// `Qᵀ b` rotated as [`Factorisation::rotate`] rotates, the rows of `m_factor`.
    c_targets: Vec<f64>,
    scale: Vec<f64>,
    zero_col: Vec<bool>,
    u: Mat<f64>,
    v: Mat<f64>,
    s: Vec<f64>,
    kept: Vec<usize>,
    nulls: Vec<usize>,
    order: Vec<usize>,
    /// The gauges, with their constraints ([`gauge`]).
    gauges: Vec<gauge::Pending>,
    /// Orthonormal basis (scaled coordinates) of what the solution does not determine, given
    /// the gauges: estimability is orthogonality to it.
    undetermined: Vec<Vec<f64>>,
    /// Orthonormal basis (scaled coordinates) of what the runs cannot separate, before the
    /// gauges' choices: the reported null combinations.
    unseen: Vec<Vec<f64>>,
    /// The residual of [`Factorisation::solve_targets`]: its sum of squares (mm²) and the sum
    /// of the products of its neighbours within runs, as the gauges' last look at the
    /// first-order solution computed them ([`Factorisation::first_order_residual`]); `None`
    /// when the gauges truncated directions after it.
    first_residual: Option<(f64, f64)>,
}

impl<'d> Factorisation<'d> {
    /// Build the design blocks, factor them (`threads` workers) and decide the gauges.
    pub fn new(design: &'d Design<'d>, threads: usize) -> Result<Factorisation<'d>, FitError> {
        let n = design.n_cols();
        let m = design.n_rows();
        let nm = design.n_machine;
        if m <= n {
            return Err(FitError::TooFewSamples { samples: m, parameters: n });
        }
        let done = std::sync::atomic::AtomicUsize::new(0);
        let n_runs = design.runs.len();
        let runs = par_map(n_runs, threads, |r| -> Result<Option<RunFactor>, FitError> {
            let cols: Vec<usize> = design.run_columns(r).chain(0..nm).collect();
            let n_own = cols.len() - nm;
            let mut b = Vec::with_capacity(design.runs[r].len());
            let (mut rows, mut qrs) = (Vec::new(), Vec::new());
            let (rr, top, finite) = stream_qr(
                design,
                r,
                &cols,
                1,
                &mut |_, _, b, mut y| {
                    for (i, x) in b.iter().enumerate() {
                        y[(i, 0)] = *x;
                    }
                },
                Some(&mut b),
                None,
                design.keeps_geometry().then_some((&mut rows, &mut qrs)),
            )?;
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            ballbar_model::progress::update("fit: factoring the runs", d, n_runs);
            Ok(finite.then(|| RunFactor {
                cols,
                n_own,
                r: rr,
                qtb: (0..top.nrows()).map(|i| top[(i, 0)]).collect(),
                b,
                rows,
                qrs,
            }))
        });
        let runs: Vec<RunFactor> = match runs.into_iter().collect::<Result<Option<Vec<_>>, _>>()? {
            Some(runs) => runs,
            None => return Err(FitError::NonFinite),
        };
        let stacked_rows: usize = runs.iter().map(|f| f.cols.len() - f.n_own).sum();
        let mut stacked = Mat::<f64>::zeros(stacked_rows.max(nm), nm);
        let mut at = 0;
        for f in &runs {
            let own = f.n_own;
            for i in own..f.cols.len() {
                for j in own..f.cols.len() {
                    stacked[(at + i - own, f.cols[j])] = f.r[(i, j)];
                }
            }
            at += f.cols.len() - own;
        }
        let machine = stacked.as_ref().qr();
        clear_upper_registers();
        drop(stacked);
        // M: per run its own rows [T_r S_r], then R_m; columns in the design's order.
        let mut m_factor = Mat::<f64>::zeros(n, n);
        let mut row = 0;
        for f in &runs {
            for i in 0..f.n_own {
                for (k, &j) in f.cols.iter().enumerate() {
                    m_factor[(row, j)] = f.r[(i, k)];
                }
                row += 1;
            }
        }
        let rm = machine.thin_R();
        for i in 0..rm.nrows().min(nm) {
            for j in i..nm {
                m_factor[(row + i, j)] = rm[(i, j)];
            }
        }
        let r = m_factor.as_ref();
        // ‖A_j‖ = ‖M_j‖ since Q is orthonormal.
        let norms: Vec<f64> =
            (0..n).map(|j| (0..n).map(|i| r[(i, j)].powi(2)).sum::<f64>().sqrt()).collect(); // A run's own column that is zero in exact arithmetic (a vibration of an axis that stands
        // still in the run) may come out at rounding level on a chain with rotary joints:
        // scaled to unit norm, its rounding noise would look estimable. Below 1e-9 of the largest
        // column of the same term in another run, it is zero.
        let term_of = |j: usize| {
            let p = &design.parameters[j];
            matches!(p.class, ballbar_model::ParamClass::RunTerm(_))
                .then(|| p.id.split('@').next().unwrap_or(&p.id))
        };
        // A run's centring column across its bar at every sample (the table ball's offset along a
        // rotary run's axis under a radial bar) is rounding too: below [`gauge::ACROSS_BAR`] of
        // the run's largest centring column, it is zero.
        let run_centring = |j: usize| {
            design
                .run_of_column(j)
                .filter(|&r| design.centring_columns(r).contains(&j))
                .map(|r| design.centring_columns(r))
        };
        let zero_col: Vec<bool> = (0..n)
            .map(|j| {
                norms[j] == 0.0
                    || term_of(j).is_some_and(|t| {
                        let largest = (0..n)
                            .filter(|&k| term_of(k) == Some(t))
                            .map(|k| norms[k])
                            .fold(0.0, f64::max);
                        norms[j] <= 1e-9 * largest
                    })
                    || run_centring(j).is_some_and(|cols| {
                        norms[j] <= gauge::ACROSS_BAR * cols.map(|k| norms[k]).fold(0.0, f64::max)
                    })
            })
            .collect();
        let scale: Vec<f64> =
            norms.iter().zip(&zero_col).map(|(&x, &z)| if z { 1.0 } else { 1.0 / x }).collect();
        let rs =
            Mat::<f64>::from_fn(n, n, |i, j| if zero_col[j] { 0.0 } else { r[(i, j)] * scale[j] });
        let mut fac = Factorisation {
            design,
            f: Factors {
                threads,
                n,
                runs,
                machine,
                m_factor,
                c_targets: Vec::new(),
                scale,
                zero_col,
                u: Mat::zeros(0, 0),
                v: Mat::zeros(0, 0),
                s: Vec::new(),
                kept: Vec::new(),
                nulls: Vec::new(),
                order: Vec::new(),
                gauges: Vec::new(),
                undetermined: Vec::new(),
                unseen: Vec::new(),
                first_residual: None,
            },
        };
        let tops: Vec<&[f64]> = fac.runs.iter().map(|f| f.qtb.as_slice()).collect();
        fac.c_targets = fac.rotate_tops(&tops);
        fac.gauge(design, threads, &rs)?;
        Ok(fac)
    }

    /// The SVD of the scaled `R` with the constraints (an orthonormal set, scaled coordinates)
    /// projected out, `R_s (I - C Cᵀ)`: the constrained directions become null, so the
    /// minimum-norm solution satisfies them. Sets the singular triplets and the truncation.
    fn decompose(&mut self, rs: &Mat<f64>, constraints: &[Vec<f64>]) -> Result<(), FitError> {
        let n = self.n;
        let mut a = rs.clone();
        for c in constraints {
            let ac: Vec<f64> = (0..n).map(|i| (0..n).map(|j| a[(i, j)] * c[j]).sum()).collect();
            for i in 0..n {
                for j in 0..n {
                    a[(i, j)] -= ac[i] * c[j];
                }
            }
        }
        let svd = a.as_ref().thin_svd();
        clear_upper_registers();
        let (u, s, v) = match svd {
            Ok(svd) => (
                svd.U().to_owned(),
                (0..n).map(|k| svd.S().column_vector()[k]).collect(),
                svd.V().to_owned(),
            ),
            // faer's SVD can fail to converge on some rank-deficient systems: one-sided Jacobi
            // converges on any matrix (slower, and n is small here).
            Err(_) => jacobi_svd(a.as_ref()).ok_or(FitError::Svd)?,
        };
        let s: Vec<f64> = s;
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| s[b].total_cmp(&s[a]));
        let smax = s[order[0]];
        self.kept = order.iter().copied().filter(|&k| s[k] > RANK_TOLERANCE * smax).collect();
        self.nulls = order.iter().copied().filter(|&k| s[k] <= RANK_TOLERANCE * smax).collect();
        (self.u, self.s, self.v, self.order) = (u, s, v, order);
        Ok(())
    }

    /// Right singular vector `k` (scaled coordinates).
    fn vcol(&self, k: usize) -> Vec<f64> {
        (0..self.n).map(|i| self.v[(i, k)]).collect()
    }

    /// Decide the gauges ([`gauge`]) and leave the decomposition that satisfies them: the
    /// structural ones first; then, from what that decomposition cannot see, the common lag
    /// and the bar length; last, the kept directions the runs determine too weakly, which are
    /// truncated.
    fn gauge(
        &mut self,
        design: &Design<'_>,
        threads: usize,
        rs: &Mat<f64>,
    ) -> Result<(), FitError> {
        let n = self.n;
        let c = self.c_targets.clone();
        let mut pending = gauge::structural(design, &self.zero_col);
        let block_views: Vec<(&[usize], faer::MatRef<'_, f64>)> =
            self.runs.iter().map(|f| (f.cols.as_slice(), f.r.as_ref())).collect();
        let mut fixed = vec![false; n];
        pending.iter().flat_map(|p| &p.gauge.parameters).for_each(|&j| fixed[j] = true);
        pending.extend(gauge::set_up(design, &block_views, &self.scale, &self.zero_col, &fixed));
        // Machine columns small enough to be rounding: the exact chain decides.
        let mut taken = vec![false; n];
        pending.iter().flat_map(|p| &p.gauge.parameters).for_each(|&j| taken[j] = true);
        let norm = |j: usize| if self.zero_col[j] { 0.0 } else { 1.0 / self.scale[j] };
        let suspects: Vec<usize> = (0..design.n_machine)
            .filter(|&j| {
                let unit = design.parameters[j].unit;
                let largest = (0..design.n_machine)
                    .filter(|&k| design.parameters[k].unit == unit)
                    .map(norm)
                    .fold(0.0, f64::max);
                !taken[j] && norm(j) > 0.0 && norm(j) < gauge::SUSPECT_COLUMN_RATIO * largest
            })
            .collect();
        if !suspects.is_empty() {
            let rmin = design.runs.iter().map(|r| r.header.radius_mm).fold(f64::INFINITY, f64::min);
            let alias_limit = gauge::ALIAS_RESOLUTION_FACTOR * gauge::POSITION_RESOLUTION_MM / rmin;
            let first = |_: usize, theta: &[f64]| {
                par_map(self.runs.len(), threads, |r| self.apply(r, theta)).into_iter().collect()
            };
            let exact = |theta: &[f64]| {
                par_map(self.runs.len(), threads, |r| design.exact_run(r, theta))
                    .into_iter()
                    .collect()
            };
            let found = gauge::rounding_only(design, &suspects, alias_limit, &first, &exact)?;
            if !found.is_empty() {
                pending.push(gauge::rounding_gauge(design, &found));
            }
        }
        for pass in 0..2 {
            let constraints = gauge::orthonormal(pending.iter().flat_map(|p| &p.conditions));
            self.decompose(rs, &constraints)?;
            let (weak, lag_weak, sums) = self.weak_directions(design, threads, &c)?;
            if pass == 0 {
                let mut unseen: Vec<Vec<f64>> = self.nulls.iter().map(|&k| self.vcol(k)).collect();
                unseen.extend(weak.iter().map(|&(k, _)| self.vcol(k)));
                let unseen = gauge::orthonormal(&unseen);
                let mut taken = vec![false; n];
                pending.iter().flat_map(|p| &p.gauge.parameters).for_each(|&j| taken[j] = true);
                let more = gauge::lag_and_bar(
                    design,
                    &self.scale,
                    &self.zero_col,
                    &unseen,
                    &taken,
                    lag_weak,
                );
                if !more.is_empty() {
                    pending.extend(more);
                    continue;
                }
            }
            // The decomposition is final unless weak directions are truncated below: then
            // the first-order solution is another, and its residual is computed when asked.
            self.first_residual = weak.is_empty().then_some(sums);
            let mut taken = vec![false; n];
            pending
                .iter()
                .filter(|p| p.gauge.fixes_each())
                .flat_map(|p| &p.gauge.parameters)
                .for_each(|&j| taken[j] = true);
            for (k, why) in weak {
                pending.push(gauge::weak(design, &self.scale, &taken, &self.vcol(k), why));
                self.kept.retain(|&x| x != k);
                self.nulls.push(k);
            }
            break;
        }
        // The null directions of the final system that no gauge constrains: what the runs
        // cannot see and nothing fixed (the constrained directions are null by construction).
        let constraints = gauge::orthonormal(pending.iter().flat_map(|p| &p.conditions));
        let free: Vec<Vec<f64>> = self
            .nulls
            .iter()
            .map(|&k| {
                let v = self.vcol(k);
                let p = gauge::project(&v, &constraints);
                v.iter().zip(&p).map(|(a, b)| a - b).collect()
            })
            .collect();
        self.undetermined = gauge::orthonormal(pending.iter().flat_map(|p| &p.fixed).chain(&free));
        self.unseen = gauge::orthonormal(pending.iter().flat_map(|p| &p.unseen).chain(&free));
        self.gauges = pending;
        Ok(())
    }

    /// The kept directions the runs do not determine ([`gauge`]'s two criteria), judged on the
    /// first-order solution of the current decomposition: its residual gives the noise σ and
    /// the lag-one autocorrelation that inflates the uncertainties, as in [`fit`].
    fn weak_directions(&self, design: &Design<'_>, threads: usize, c: &[f64]) -> WeakDirections {
        if self.kept.is_empty() {
            return Ok((Vec::new(), None, (0.0, 0.0)));
        }
        let m = design.n_rows();
        let theta = self.solve_rotated(c);
        let residuals = par_map(self.runs.len(), threads, |r| {
            let lin = self.apply(r, &theta)?;
            Ok(self.runs[r].b.iter().zip(&lin).map(|(b, a)| b - a).collect())
        });
        let residuals: Vec<Vec<f64>> =
            residuals.into_iter().collect::<Result<_, ballbar_model::ModelError>>()?;
        let (mut rss, mut num) = (0.0, 0.0);
        for res in &residuals {
            rss += res.iter().map(|x| x * x).sum::<f64>();
            num += res.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
        }
        let rho = if rss > 0.0 { (num / rss).clamp(-0.99, 0.99) } else { 0.0 };
        let inflation = if rho > 0.0 { (1.0 + rho) / (1.0 - rho) } else { 1.0 };
        let sigma = (rss / (m - self.kept.len()) as f64).sqrt().max(gauge::READING_RESOLUTION_MM);
        let rmin = design.runs.iter().map(|r| r.header.radius_mm).fold(f64::INFINITY, f64::min);
        let smax = self.s[self.order[0]];
        let alias_limit = (gauge::ALIAS_RESOLUTION_FACTOR * gauge::POSITION_RESOLUTION_MM / rmin)
            .max(RANK_TOLERANCE);
        let limit_mm = (2.0 * rmin * sigma).sqrt();
        let mut out = Vec::new();
        for &k in &self.kept {
            let relative = self.s[k] / smax;
            if relative <= alias_limit {
                out.push((k, gauge::Weakness::Aliased { relative, limit: alias_limit }));
                continue;
            }
            // One standard uncertainty along v_k is σ/s_k in scaled units; parameter j's share
            // of the readings is then |v_jk| σ/s_k in norm over the m samples (a scaled column
            // has unit norm), |v_jk| σ/(s_k √m) RMS per sample.
            let vmax = (0..self.n).map(|j| self.v[(j, k)].abs()).fold(0.0, f64::max);
            let share_mm = inflation.sqrt() * sigma * vmax / (self.s[k] * (m as f64).sqrt());
            if share_mm > limit_mm {
                out.push((k, gauge::Weakness::Nonlinear { share_mm, limit_mm }));
            }
        }
        Ok((out, self.lag_weakness(design, sigma * inflation.sqrt(), limit_mm), (rss, num)))
    }

    /// The lag common to the linear axes, when the runs determine it only weakly: a rotary run
    /// sees it against the rotary axes (which have no lag term) through the bar's part along
    /// the path, and a set of such runs may pin it to no better than tens of ms. Its first-order
    /// share of the readings is then small, but one standard uncertainty shifts the ball along
    /// its path by the feed times it, beyond `limit_mm` (√(2Rσ), where the second order of the
    /// shift reaches the noise): a value drawn that far along it biases everything the shift's
    /// second order resembles (a common scale: seen, 30 u of the positional errors).
    fn lag_weakness(
        &self,
        design: &Design<'_>,
        sd: f64,
        limit_mm: f64,
    ) -> Option<gauge::LagWeakness> {
        let lags: Vec<usize> = (0..design.model.terms.len())
            .filter(|&j| {
                design.parameters[j].class
                    == ballbar_model::ParamClass::Term(ballbar_model::TermClass::ServoLag)
                    && !self.zero_col[j]
            })
            .collect();
        if lags.len() < 2 {
            return None;
        }
        // The mean lag in scaled coordinates, a·z with a_j = scale_j / L; its variance
        // σ² Σ_k (a·v_k / s_k)² over the kept directions.
        let var: f64 = self
            .kept
            .iter()
            .map(|&k| {
                let av: f64 =
                    lags.iter().map(|&j| self.scale[j] / lags.len() as f64 * self.v[(j, k)]).sum();
                (av / self.s[k]).powi(2)
            })
            .sum();
        let u_s = sd * var.sqrt();
        let feed = design.runs.iter().map(|r| r.header.feed_mm_per_s()).fold(0.0, f64::max);
        let shift_mm = feed * u_s;
        (shift_mm > limit_mm).then_some(gauge::LagWeakness { u_s, shift_mm, limit_mm })
    }

    /// The rotated right-hand side from each run's top of `Q_rᵀ y_r` (in the order of its
    /// `cols`): its own entries as they are, its machine entries stacked and turned by the
    /// machine QR; in the row order of `m_factor`.
    fn rotate_tops(&self, tops: &[&[f64]]) -> Vec<f64> {
        let nm = self.design.n_machine;
        let mut out = Vec::with_capacity(self.n);
        let mut stacked = Mat::<f64>::zeros(self.machine.Q_basis().nrows(), 1);
        let mut at = 0;
        for (f, t) in self.runs.iter().zip(tops) {
            out.extend_from_slice(&t[..f.n_own]);
            for (i, x) in t[f.n_own..].iter().enumerate() {
                stacked[(at + i, 0)] = *x;
            }
            at += f.cols.len() - f.n_own;
        }
        apply_qt(&self.machine, &mut stacked);
        out.extend((0..nm).map(|i| stacked[(i, 0)]));
        out
    }

    /// `Qᵀ y` of the whole factorisation, its first `n` entries, for each set of right-hand
    /// sides `rhs[k]` (one vector per run): each run's rows regenerated and factored again once
    /// for all of them, `threads` runs at a time.
    fn rotate_many(&self, rhs: &[&[Vec<f64>]]) -> Result<Vec<Vec<f64>>, FitError> {
        let k = rhs.len();
        let tops = par_map(self.runs.len(), self.threads, |r| -> Result<Vec<Vec<f64>>, FitError> {
            let f = &self.runs[r];
            let (_, top, _) = stream_qr(
                self.design,
                r,
                &f.cols,
                k,
                &mut |start, _, _, mut out| {
                    for (c, y) in rhs.iter().enumerate() {
                        for i in 0..out.nrows() {
                            out[(i, c)] = y[r][start + i];
                        }
                    }
                },
                None,
                f.kept(),
                None,
            )?;
            Ok((0..k).map(|c| (0..top.nrows()).map(|i| top[(i, c)]).collect()).collect())
        });
        let tops = tops.into_iter().collect::<Result<Vec<_>, _>>()?;
        Ok((0..k)
            .map(|c| {
                let views: Vec<&[f64]> = tops.iter().map(|t| t[c].as_slice()).collect();
                self.rotate_tops(&views)
            })
            .collect())
    }

    /// One pass over run `r` for the refinement at `theta`: the exact readings (less a known
    /// bar length), the linearised ones `A_r θ`, and the top of `Q_rᵀ (exact - A_r θ)`.
    fn refinement_pass(
        &self,
        r: usize,
        theta: &[f64],
        known: f64,
    ) -> Result<(Vec<f64>, Vec<f64>, Vec<f64>), FitError> {
        let mut exact = self.design.exact_run(r, theta)?;
        exact.iter_mut().for_each(|x| *x -= known);
        let f = &self.runs[r];
        let compact: Vec<f64> = f.cols.iter().map(|&j| theta[j]).collect();
        let mut lin = vec![0.0; exact.len()];
        let (_, top, _) = stream_qr(
            self.design,
            r,
            &f.cols,
            1,
            &mut |start, a, _, mut out| {
                let lin = &mut lin[start..start + a.nrows()];
                lin.fill(-0.0);
                for j in 0..a.ncols() {
                    let (col, x) = (a.col(j), compact[j]);
                    for (i, l) in lin.iter_mut().enumerate() {
                        *l += col[i] * x;
                    }
                }
                for (i, l) in lin.iter().enumerate() {
                    out[(i, 0)] = exact[start + i] - l;
                }
            },
            None,
            f.kept(),
            None,
        )?;
        Ok((exact, lin, (0..top.nrows()).map(|i| top[(i, 0)]).collect()))
    }

    /// The truncated solution for rotated right-hand side `c`, internal units.
    fn solve_rotated(&self, c: &[f64]) -> Vec<f64> {
        let n = self.n;
        let mut theta = vec![0.0; n];
        for &k in &self.kept {
            let coef: f64 = (0..n).map(|i| self.u[(i, k)] * c[i]).sum::<f64>() / self.s[k];
            for (i, t) in theta.iter_mut().enumerate() {
                *t += self.v[(i, k)] * coef;
            }
        }
        for i in 0..n {
            theta[i] = if self.zero_col[i] { 0.0 } else { theta[i] * self.scale[i] };
        }
        theta
    }

    /// The minimum-norm truncated least-squares solution for right-hand sides `rhs` (one vector
    /// per run, as long as the run), under the gauges. Each call regenerates and factors the
    /// runs' rows again ([`Factorisation`], "Memory"): for several right-hand sides,
    /// [`Factorisation::solve_many`] does it once; the targets' solution is
    /// [`Factorisation::solve_targets`], which does not. An error only where a plugin's kernel
    /// fails on rows it evaluated before.
    pub fn solve(&self, rhs: &[Vec<f64>]) -> Result<Vec<f64>, FitError> {
        Ok(self.solve_many(&[rhs])?.pop().unwrap_or_default())
    }

    /// [`Factorisation::solve`] of several sets of right-hand sides, in one pass over the rows.
    pub fn solve_many(&self, rhs: &[&[Vec<f64>]]) -> Result<Vec<Vec<f64>>, FitError> {
        Ok(self.rotate_many(rhs)?.iter().map(|c| self.solve_rotated(c)).collect())
    }

    /// The norm of column `j` of the design, ‖A_j‖ (0 for a column that is all zero).
    pub fn column_norm(&self, j: usize) -> f64 {
        if self.zero_col[j] { 0.0 } else { 1.0 / self.scale[j] }
    }

    /// [`Factorisation::solve`] for the targets ([`Factorisation::targets`]), from the
    /// factorisation as kept.
    pub fn solve_targets(&self) -> Vec<f64> {
        self.solve_rotated(&self.c_targets)
    }

    /// `A θ` for run `r`: its rows regenerated chunk by chunk. An error only where a plugin's
    /// kernel fails on rows it evaluated before.
    pub fn apply(&self, r: usize, theta: &[f64]) -> Result<Vec<f64>, ballbar_model::ModelError> {
        Ok(self.apply_many(r, &[theta])?.pop().unwrap_or_default())
    }

    /// `A θ_k` for run `r` and every `θ_k` of `thetas`, in one pass over its rows.
    pub fn apply_many(
        &self,
        r: usize,
        thetas: &[&[f64]],
    ) -> Result<Vec<Vec<f64>>, ballbar_model::ModelError> {
        let f = &self.runs[r];
        let nc = f.cols.len();
        let m = f.b.len();
        let compact: Vec<Vec<f64>> =
            thetas.iter().map(|t| f.cols.iter().map(|&j| t[j]).collect()).collect();
        if let Some(Kept { rows, .. }) = f.kept() {
            // Each row's sum as below (in column order from −0.0), from the rows as kept, a
            // block of rows at a time for every θ_k: the block is read from memory once, not
            // once per θ_k.
            const BLOCK: usize = 512;
            let mut out: Vec<Vec<f64>> = compact.iter().map(|_| vec![-0.0; m]).collect();
            let mut start = 0;
            while start < m {
                let len = BLOCK.min(m - start);
                for (o, c) in out.iter_mut().zip(&compact) {
                    let o = &mut o[start..start + len];
                    for (j, &xj) in c.iter().enumerate() {
                        let col = &rows[j * m + start..j * m + start + len];
                        for (s, &v) in o.iter_mut().zip(col) {
                            *s += v * xj;
                        }
                    }
                }
                start += len;
            }
            return Ok(out);
        }
        let chunk = CHUNK_ROWS.min(m);
        let mut abuf = vec![0.0; chunk * nc];
        let mut bbuf = vec![0.0; chunk];
        let mut scratch = BlockScratch::default();
        let mut out: Vec<Vec<f64>> = thetas.iter().map(|_| Vec::with_capacity(m)).collect();
        let mut start = 0;
        while start < m {
            let len = chunk.min(m - start);
            let (a, b) = (&mut abuf[..len * nc], &mut bbuf[..len]);
            self.design.fill_rows(r, start..start + len, &f.cols, a, b, &mut scratch)?;
            for (o, c) in out.iter_mut().zip(&compact) {
                let at = o.len();
                o.resize(at + len, -0.0);
                add_product_in_column_order(a, |j| c[j], &mut o[at..]);
            }
            start += len;
        }
        Ok(out)
    }

    /// The readings (targets) of run `r`, mm.
    pub fn targets(&self, r: usize) -> &[f64] {
        &self.runs[r].b
    }

    /// The residual `b - A θ` of the first-order solution `θ` ([`Factorisation::solve_targets`]):
    /// its sum of squares (mm²) and the sum of the products of neighbouring residuals within
    /// each run (the numerator of their lag-one autocorrelation). The gauges' last check of
    /// the solution already computed both, and they are returned as it summed them; only when
    /// it truncated weak directions afterwards are the runs' rows regenerated for them.
    pub fn first_order_residual(&self) -> Result<(f64, f64), FitError> {
        if let Some(sums) = self.first_residual {
            return Ok(sums);
        }
        let theta = self.solve_targets();
        let sums: Vec<Result<(f64, f64), FitError>> = par_map(self.runs.len(), self.threads, |r| {
            let model = self.apply(r, &theta)?;
            let e: Vec<f64> = self.runs[r].b.iter().zip(&model).map(|(b, m)| b - m).collect();
            Ok((e.iter().map(|x| x * x).sum(), e.windows(2).map(|w| w[0] * w[1]).sum()))
        });
        let (mut rss, mut lag1) = (0.0, 0.0);
        for s in sums {
            let (a, b) = s?;
            rss += a;
            lag1 += b;
        }
        Ok((rss, lag1))
    }
}

/// At most this many chord (fixed-Jacobian Gauss-Newton) refinements: each shrinks the
/// second-order misfit by ~|Δ|/R ≈ 1e-3, so two or three reach the tolerance.
const MAX_REFINEMENTS: usize = 6;

/// Refinement stops when an update changes the model's readings by less than this RMS, mm
/// (0.01 nm: far below any bar's resolution), or when the next update, extrapolated from the
/// linear convergence of the last two, would.
const REFINEMENT_TOLERANCE_MM: f64 = 1e-8;

/// Fit the design: truncated-SVD least squares on the first-order design, refined against the
/// exact chain (the readings are compared with [`Design::exact`], not with their
/// linearisation). `threads` workers factor the runs (≥ 1).
pub fn fit(design: &Design<'_>, threads: usize) -> Result<Fit, FitError> {
    fit_factored(design, threads).map(|(f, _)| f)
}

impl<'d> Factorisation<'d> {
    /// The factors without the design, to be taken up again on it ([`fit_prefactored`]).
    pub fn detach(self) -> Prefactored {
        let d = self.design;
        Prefactored { f: self.f, shape: (d.n_rows(), d.n_cols(), d.switch_lags()) }
    }
}

/// The shape and switch lags of a design, as [`Prefactored`] records them.
pub(crate) fn shape_of(design: &Design<'_>) -> (usize, usize, [f64; 6]) {
    (design.n_rows(), design.n_cols(), design.switch_lags())
}

/// [`fit`], and the factorisation it solved with, for further right-hand sides on the same
/// design (the projections of [`alias`]).
pub fn fit_factored<'d>(
    design: &'d Design<'d>,
    threads: usize,
) -> Result<(Fit, Factorisation<'d>), FitError> {
    fit_prefactored(design, None, threads)
}

/// [`fit_factored`] from the design's factorisation where one is given
/// ([`switch::switch_and_factor`]: the same design, factored by the switch search as it ended):
/// the same fit without factoring the design again. A factorisation of a design of another
/// shape or other switch lags is not used; the design is factored.
pub fn fit_prefactored<'d>(
    design: &'d Design<'d>,
    pre: Option<Prefactored>,
    threads: usize,
) -> Result<(Fit, Factorisation<'d>), FitError> {
    let fac = match pre.filter(|p| p.shape == shape_of(design)) {
        Some(p) => Factorisation { design, f: p.f },
        None => Factorisation::new(design, threads)?,
    };
    let n = fac.n;
    // Runs that determine no machine parameter at all (an arc of a few degrees) leave nothing to
    // report: every parameter would be gauged or undetermined. That is an input error.
    let determined = |j: usize| {
        fac.undetermined.iter().map(|b| b[j] * b[j]).sum::<f64>().sqrt()
            <= gauge::SUBSPACE_TOLERANCE
    };
    if design.n_machine > 0 && !(0..design.n_machine).any(determined) {
        return Err(FitError::TooFewSamples {
            samples: design.n_rows(),
            parameters: design.n_machine,
        });
    }
    let n_runs = design.runs.len();
    let m = design.n_rows();
    let targets: Vec<&[f64]> = (0..n_runs).map(|r| fac.targets(r)).collect();
    let known = match design.model.options.bar_length {
        ballbar_model::BarLength::Known(b) => b,
        ballbar_model::BarLength::Fit => 0.0,
    };
    // Per run: the exact readings, their linearisation at θ, and the top of Qᵀ of their
    // difference, in one pass over the run's rows.
    let pass = std::sync::atomic::AtomicUsize::new(0);
    let evaluate = |theta: &[f64]| -> Result<Vec<(Vec<f64>, Vec<f64>, Vec<f64>)>, FitError> {
        let done = std::sync::atomic::AtomicUsize::new(0);
        let what = format!(
            "fit: against the exact chain, pass {}",
            pass.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1
        );
        par_map(n_runs, threads, |r| {
            let out = fac.refinement_pass(r, theta, known);
            let d = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            ballbar_model::progress::update(&what, d, n_runs);
            out
        })
        .into_iter()
        .collect()
    };
    let mut values = fac.solve_targets();
    let mut at_theta = values.clone();
    let mut at = evaluate(&values)?;
    let mut last_change = f64::INFINITY;
    let mut exact: Option<Vec<Vec<f64>>> = None;
    for _ in 0..MAX_REFINEMENTS {
        // Solve A θ = b - (f(θ) - A θ): the fixed point is f(θ) ≈ b in the least-squares sense.
        // Qᵀ is linear: Qᵀ b (kept) less Qᵀ (f(θ) - A θ) (from the pass).
        let tops: Vec<&[f64]> = at.iter().map(|(_, _, t)| t.as_slice()).collect();
        let c_misfit = fac.rotate_tops(&tops);
        let c: Vec<f64> = fac.c_targets.iter().zip(&c_misfit).map(|(b, d)| b - d).collect();
        values = fac.solve_rotated(&c);
        // RMS change of the linearised readings: ‖A Δθ‖ / √m = ‖M Δθ‖ / √m, M the triangular
        // factor (Q is orthonormal).
        let delta: Vec<f64> = values.iter().zip(&at_theta).map(|(a, b)| a - b).collect();
        let change = ((0..n)
            .map(|i| (0..n).map(|j| fac.m_factor[(i, j)] * delta[j]).sum::<f64>().powi(2))
            .sum::<f64>()
            / m as f64)
            .sqrt();
        // The chord iteration converges linearly: the next change is about change · (change /
        // last change), and so is the error of taking f(θ + Δθ) ≈ f(θ) + A Δθ instead of a
        // new exact evaluation. Below the tolerance, that update is the exact readings to
        // within it, and one evaluation of the chain is saved.
        // A growing update is not a slow convergence but a divergence: the exact chain is far
        // from its linearisation at these parameters (1 nm: far above rounding).
        if last_change.is_finite() && change > last_change && change > 1e-6 {
            let (a, b) = (fac.kept.first().map(|&k| fac.s[k]), fac.kept.last().map(|&k| fac.s[k]));
            let condition_number = match (a, b) {
                (Some(a), Some(b)) => a / b,
                _ => f64::INFINITY,
            };
            return Err(FitError::Diverged {
                last_mm: last_change,
                next_mm: change,
                condition_number,
            });
        }
        let predicted =
            if last_change.is_finite() { change * (change / last_change).min(1.0) } else { change };
        last_change = change;
        if change < REFINEMENT_TOLERANCE_MM || predicted < REFINEMENT_TOLERANCE_MM {
            let step = par_map(n_runs, threads, |r| fac.apply(r, &delta));
            let step = step.into_iter().collect::<Result<Vec<Vec<f64>>, _>>()?;
            exact = Some(
                at.iter()
                    .zip(&step)
                    .map(|((e, _, _), d)| e.iter().zip(d).map(|(e, d)| e + d).collect())
                    .collect(),
            );
            break;
        }
        at = evaluate(&values)?;
        at_theta = values.clone();
    }
    let exact: Vec<Vec<f64>> = exact.unwrap_or_else(|| at.into_iter().map(|(e, _, _)| e).collect());
    let residuals: Vec<Vec<f64>> = (0..n_runs)
        .map(|r| targets[r].iter().zip(&exact[r]).map(|(b, f)| b - f).collect())
        .collect();
    let rank = fac.kept.len();
    let rss: f64 = residuals.iter().flatten().map(|r| r * r).sum();
    let dof = m - rank;
    let sigma2 = rss / dof as f64;
    // A value whose square overflows (a reading of 1e300 is a finite number) leaves no finite
    // solution: that is an error, never a fit of NaN.
    if !(sigma2.is_finite() && values.iter().all(|v| v.is_finite())) {
        return Err(FitError::NonFinite);
    }
    let (mut num, mut den) = (0.0, 0.0);
    for res in &residuals {
        for w in res.windows(2) {
            num += w[0] * w[1];
        }
        den += res.iter().map(|r| r * r).sum::<f64>();
    }
    let rho = if den > 0.0 { (num / den).clamp(-0.99, 0.99) } else { 0.0 };
    let inflation = if rho > 0.0 { (1.0 + rho) / (1.0 - rho) } else { 1.0 };
    let sd = (sigma2 * inflation).sqrt();
    let (scale, v, s) = (&fac.scale, &fac.v, &fac.s);
    let cov_factor = Mat::<f64>::from_fn(n, rank, |i, kk| {
        let k = fac.kept[kk];
        scale[i] * v[(i, k)] / s[k] * sd
    });
    // Estimability is orthogonality to what the solution leaves undetermined under the gauges;
    // the reported combinations are what the runs cannot separate before any choice.
    let basis = |b: &[Vec<f64>]| Mat::<f64>::from_fn(n, b.len(), |i, k| b[k][i]);
    let null_scaled = basis(&fac.undetermined);
    let std_uncertainty: Vec<f64> =
        (0..n).map(|i| (0..rank).map(|k| cov_factor[(i, k)].powi(2)).sum::<f64>().sqrt()).collect();
    let estimable: Vec<bool> = (0..n)
        .map(|i| {
            (0..null_scaled.ncols()).map(|k| null_scaled[(i, k)].powi(2)).sum::<f64>().sqrt()
                <= gauge::SUBSPACE_TOLERANCE
        })
        .collect();
    let null_space = null_combinations(&basis(&fac.unseen), scale, design);
    let dependence: Vec<Option<Vec<f64>>> =
        fac.gauges.iter().map(|p| p.dependence.clone()).collect();
    // A machine parameter holds for a choice when it is estimable only because of it.
    let gauges: Vec<Gauge> = fac
        .gauges
        .iter()
        .map(|p| {
            let mut g = p.gauge.clone();
            if let Some(dir) = &p.dependence {
                g.conditional = (0..design.n_machine)
                    .filter(|&j| {
                        estimable[j]
                            && !design.parameters[j].class.is_nuisance()
                            && dir[j].abs() > gauge::SUBSPACE_TOLERANCE
                    })
                    .collect();
            }
            g
        })
        .collect();
    let condition_number = match (fac.kept.first(), fac.kept.last()) {
        (Some(&a), Some(&b)) => s[a] / s[b],
        _ => f64::INFINITY,
    };
    let fit = Fit {
        parameters: design.parameters.clone(),
        n_machine: design.n_machine,
        values,
        std_uncertainty,
        estimable,
        rank,
        singular_values: fac.order.iter().map(|&k| s[k]).collect(),
        condition_number,
        null_space,
        gauges,
        sigma_mm: sigma2.sqrt(),
        dof,
        rho,
        inflation,
        residuals,
        n_samples: m,
        switch_lags_s: design.switch_lags(),
        cov_factor,
        null_scaled,
        scale: scale.clone(),
        dependence,
    };
    Ok((fit, fac))
}

/// Rotate the null-space basis to reduced row-echelon form (pivoting on the largest entry),
/// express it in display units and normalise each combination to a largest amount of ±1.
fn null_combinations(
    null_scaled: &Mat<f64>,
    scale: &[f64],
    design: &Design<'_>,
) -> Vec<NullCombination> {
    let n = null_scaled.nrows();
    let k = null_scaled.ncols();
    // Rows of `b` are the null vectors in display units.
    let mut b: Vec<Vec<f64>> = (0..k)
        .map(|c| {
            (0..n)
                .map(|i| {
                    null_scaled[(i, c)] * scale[i] * design.parameters[i].unit.display_factor()
                })
                .collect()
        })
        .collect();
    let mut used = vec![false; n];
    for r in 0..k {
        // Pivot: the largest entry of row r among unused columns, after normalising row r.
        let (piv, _) = (0..n)
            .filter(|&j| !used[j])
            .map(|j| (j, b[r][j].abs()))
            .fold((usize::MAX, 0.0), |acc, x| if x.1 > acc.1 { x } else { acc });
        if piv == usize::MAX {
            continue;
        }
        used[piv] = true;
        let p = b[r][piv];
        for x in b[r].iter_mut() {
            *x /= p;
        }
        for rr in 0..k {
            if rr != r {
                let f = b[rr][piv];
                if f != 0.0 {
                    let (src, dst) = if rr < r {
                        let (lo, hi) = b.split_at_mut(r);
                        (&hi[0], &mut lo[rr])
                    } else {
                        let (lo, hi) = b.split_at_mut(rr);
                        (&lo[r], &mut hi[0])
                    };
                    for j in 0..n {
                        dst[j] -= f * src[j];
                    }
                }
            }
        }
    }
    b.into_iter()
        .map(|row| {
            let mx = row.iter().fold(0.0f64, |a, x| a.max(x.abs()));
            let components = row
                .iter()
                .enumerate()
                .filter(|(_, x)| x.abs() > COMBINATION_DROP * mx)
                .map(|(i, x)| (i, x / mx))
                .collect();
            NullCombination { components }
        })
        .collect()
}

/// A reported quantity with its estimate.
#[derive(Clone, Debug, PartialEq)]
pub struct QuantityEstimate {
    /// Name.
    pub name: String,
    /// Display unit.
    pub unit: &'static str,
    /// Estimate in that unit.
    pub estimate: Estimate,
}

/// Estimate a reported quantity (a linear functional over parameter ids); `None` when the fit
/// lacks one of its parameters.
pub fn quantity(fit: &Fit, q: &ballbar_model::paper::Quantity) -> Option<QuantityEstimate> {
    let coeffs: Option<Vec<(usize, f64)>> =
        q.terms.iter().map(|(id, f)| fit.index(id).map(|i| (i, *f))).collect();
    Some(QuantityEstimate {
        name: q.name.clone(),
        unit: q.unit,
        estimate: fit.functional(&coeffs?),
    })
}

#[cfg(test)]
mod alias_tests;
#[cfg(test)]
mod rotary_tests;
#[cfg(test)]
mod tests;

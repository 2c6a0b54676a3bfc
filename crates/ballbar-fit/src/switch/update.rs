//! The first-order residual at other switch lags from one factorisation: only the backlash
//! columns depend on the lags, and only on the rows near the reversals.
//!
//! Split the design's columns into the backlash columns `S` (the terms of class
//! [`TermClass::Backlash`], whose basis is the lagging axis's direction) and the rest `F`,
//! which no switch lag moves. The residual of `[F S(c)]` is the residual of `F` less its part
//! along `S(c)` outside `F`'s span:
//!
//! ```text
//! RSS(c) = ‖b‖² − ‖Wᵀb‖² − tᵀ G⁺ t,   t = Sᵀb − (WᵀS)ᵀ(Wᵀb),   G = SᵀS − (WᵀS)ᵀ(WᵀS)
//! ```
//!
//! with `W` an orthonormal basis of `F`'s span. The factorisation at the reference lags,
//! `A = Q M` with `M` triangular, gives it without touching the rows: `W = Q U_K`, `U_K` the
//! kept left singular vectors of `M_F` (column-scaled, truncated at [`RANK_TOLERANCE`] as
//! the fit truncates), so `Wᵀb = U_Kᵀ Qᵀb`, `WᵀS_ref = U_Kᵀ M_S`, `S_refᵀS_ref = M_Sᵀ M_S`
//! and `S_refᵀb = M_Sᵀ Qᵀb`. At another lag `S(c) = S_ref + D`, `D` non-zero only on the
//! rows [`Design::switch_rows`] names (a few per cent of them): `WᵀD = Σ⁻¹V_Kᵀ F_sᵀ D` from
//! those rows of `F` (`F_s = Q U Σ Vᵀ`), and every product with `S` takes `D`'s rows only.
//! Each lag then costs the rows near the reversals, not a factorisation of the design.
//!
//! The `k × k` matrix `G` (k the backlash columns, at most six) is the Gram matrix of the
//! backlash columns' part outside `F`, as the diagnosis's engine forms a candidate's: it is
//! used to compare switch lags with one another and, where a first round's best switch is far
//! from determined, for its Δχ² against the commanded reversal (both residuals from these
//! sums; the noise and the autocorrelation from the commanded fit's factorisation); a switch
//! that goes on is judged by full factorisations ([`super::switch_at_lagged_reversals`]).

use ballbar_model::parallel::par_map;
use ballbar_model::{BlockScratch, Design, TermClass};
use faer::Mat;

use crate::{Factorisation, FitError, RANK_TOLERANCE, clear_upper_registers, jacobi_svd};

/// A backlash column whose part outside `F` holds less than this share of its energy is taken
/// as inside `F`'s span. `G = SᵀS − (WᵀS)ᵀ(WᵀS)` is a difference of sums over ~1e5 rows, each
/// rounded to ~1e-16 of `‖S‖²`: its rounding is ~1e-13 of `SᵀS` at the most, so a share of
/// 1e-12 (a part outside of 1e-6 of the column's norm) is the smallest that rounding cannot
/// make or unmake. The same bound truncates `G`'s singular values (relative to its largest,
/// columns scaled to unit diagonal).
const GRAM_SHARE: f64 = 1e-12;

/// The backlash columns and the sums at the reference lags; the rows near the reversals.
pub(super) struct SwitchUpdate {
    /// The largest switch lag the rows cover, s.
    max_lag_s: f64,
    /// The backlash columns (design columns).
    s_cols: Vec<usize>,
    /// Per run, the rows near its reversals.
    windows: Vec<Vec<std::ops::Range<usize>>>,
    /// Per window row (runs in order, rows ascending): `Wᵀ F_i`-weights, `kk` per row (the row
    /// of `F` mapped by `Σ⁻¹V_Kᵀ` of the scaled columns: `WᵀD = Σ_i fw_i D_i`).
    fw: Vec<f64>,
    /// Per window row, `S_ref`'s `k` entries.
    s_ref: Vec<f64>,
    /// Per window row, the target.
    b: Vec<f64>,
    /// `Wᵀ S_ref`, `kk × k`.
    ws0: Mat<f64>,
    /// `S_refᵀ S_ref`, `k × k`.
    ss0: Mat<f64>,
    /// `S_refᵀ b`.
    sb0: Vec<f64>,
    /// `Wᵀ b`.
    wb: Vec<f64>,
    /// `‖b‖² − ‖Wᵀb‖²`: the residual of `F` alone, mm².
    rss_f: f64,
}

/// Whether the update applies to the design's model: every term but the backlash is one whose
/// basis reads no direction and no time since a reversal (an effect or a plugin's term may).
pub(super) fn applies(design: &Design<'_>) -> bool {
    design
        .model
        .terms
        .iter()
        .chain(&design.model.run_terms)
        .all(|bt| !matches!(bt.term.class(), TermClass::Effect | TermClass::Other))
}

impl SwitchUpdate {
    /// The sums of `fac` (a factorisation of `design`, at the reference lags) for lags up to
    /// `max_lag_s`. `None` when the design has no backlash column or the SVD of `F`'s factor
    /// does not converge (the caller then factors the design at each lag).
    pub(super) fn new(
        design: &Design<'_>,
        fac: &Factorisation<'_>,
        max_lag_s: f64,
        threads: usize,
    ) -> Result<Option<SwitchUpdate>, FitError> {
        let n = fac.n;
        let s_cols: Vec<usize> = (0..design.model.terms.len())
            .filter(|&j| design.model.terms[j].term.class() == TermClass::Backlash)
            .collect();
        if s_cols.is_empty() {
            return Ok(None);
        }
        let k = s_cols.len();
        let mut is_s = vec![false; n];
        s_cols.iter().for_each(|&j| is_s[j] = true);
        let f_cols: Vec<usize> = (0..n).filter(|&j| !is_s[j]).collect();
        let m = &fac.m_factor;
        // Scaled as the fit scales them; a column it takes as zero is left out.
        let f_scale: Vec<f64> =
            f_cols.iter().map(|&j| if fac.zero_col[j] { 0.0 } else { fac.scale[j] }).collect();
        let mf = Mat::<f64>::from_fn(n, f_cols.len(), |i, c| m[(i, f_cols[c])] * f_scale[c]);
        let svd = mf.as_ref().thin_svd();
        clear_upper_registers();
        let Ok(svd) = svd else { return Ok(None) };
        let (u, v) = (svd.U(), svd.V());
        let s: Vec<f64> = (0..svd.S().column_vector().nrows()).map(|i| svd.S()[i]).collect();
        let smax = s.iter().fold(0.0f64, |a, &x| a.max(x));
        let kept: Vec<usize> = (0..s.len()).filter(|&i| s[i] > RANK_TOLERANCE * smax).collect();
        let kk = kept.len();
        let c = &fac.c_targets;
        let wb: Vec<f64> = kept.iter().map(|&q| (0..n).map(|i| u[(i, q)] * c[i]).sum()).collect();
        let ws0 = Mat::<f64>::from_fn(kk, k, |a, b| {
            (0..n).map(|i| u[(i, kept[a])] * m[(i, s_cols[b])]).sum()
        });
        let ss0 = Mat::<f64>::from_fn(k, k, |a, b| {
            (0..n).map(|i| m[(i, s_cols[a])] * m[(i, s_cols[b])]).sum()
        });
        let sb0: Vec<f64> =
            s_cols.iter().map(|&j| (0..n).map(|i| m[(i, j)] * c[i]).sum()).collect();
        let bb: f64 = fac.runs.iter().flat_map(|f| &f.b).map(|x| x * x).sum();
        let rss_f = bb - wb.iter().map(|x| x * x).sum::<f64>();
        // Σ⁻¹ V_Kᵀ diag(scale), per design column (0 for the backlash columns).
        let mut f_pos = vec![usize::MAX; n];
        f_cols.iter().enumerate().for_each(|(p, &j)| f_pos[j] = p);
        let map = |q: usize, j: usize| {
            let p = f_pos[j];
            if p == usize::MAX { 0.0 } else { v[(p, kept[q])] * f_scale[p] / s[kept[q]] }
        };
        let windows: Vec<Vec<std::ops::Range<usize>>> =
            (0..design.runs.len()).map(|r| design.switch_rows(r, max_lag_s)).collect();
        let per_run = par_map(design.runs.len(), threads, |r| -> Result<_, FitError> {
            let cols: Vec<usize> = design.run_columns(r).chain(0..design.n_machine).collect();
            let weights: Vec<f64> = (0..kk)
                .flat_map(|q| cols.iter().map(move |&j| (q, j)))
                .map(|(q, j)| map(q, j))
                .collect();
            let (mut fw, mut s_ref, mut b) = (Vec::new(), Vec::new(), Vec::new());
            let mut scratch = BlockScratch::default();
            for w in &windows[r] {
                let len = w.len();
                let mut a = vec![0.0; len * cols.len()];
                let mut t = vec![0.0; len];
                design.fill_rows(r, w.clone(), &cols, &mut a, &mut t, &mut scratch)?;
                for i in 0..len {
                    for q in 0..kk {
                        let wq = &weights[q * cols.len()..(q + 1) * cols.len()];
                        fw.push((0..cols.len()).map(|c| wq[c] * a[c * len + i]).sum::<f64>());
                    }
                    for &j in &s_cols {
                        let c = cols.iter().position(|&x| x == j).expect("machine column");
                        s_ref.push(a[c * len + i]);
                    }
                }
                b.extend_from_slice(&t);
            }
            Ok((fw, s_ref, b))
        });
        let (mut fw, mut s_ref, mut b) = (Vec::new(), Vec::new(), Vec::new());
        for run in per_run {
            let (f, s, t) = run?;
            fw.extend(f);
            s_ref.extend(s);
            b.extend(t);
        }
        Ok(Some(SwitchUpdate {
            max_lag_s,
            s_cols,
            windows,
            fw,
            s_ref,
            b,
            ws0,
            ss0,
            sb0,
            wb,
            rss_f,
        }))
    }

    /// The largest switch lag whose residual [`SwitchUpdate::rss`] gives, s.
    pub(super) fn max_lag_s(&self) -> f64 {
        self.max_lag_s
    }

    /// The first-order residual sum of squares (mm²) of `design` at switch lags `lags_s`
    /// (each in `[0, max_lag_s]`): the backlash columns evaluated on the rows near the
    /// reversals only.
    pub(super) fn rss(
        &self,
        design: &Design<'_>,
        lags_s: [f64; 6],
        threads: usize,
    ) -> Result<f64, FitError> {
        let k = self.s_cols.len();
        let kk = self.wb.len();
        let at = design.at_switch_lags(lags_s);
        let per_run = par_map(design.runs.len(), threads, |r| -> Result<Vec<f64>, FitError> {
            let mut out = Vec::new();
            let mut scratch = BlockScratch::default();
            for w in &self.windows[r] {
                let len = w.len();
                let mut a = vec![0.0; len * k];
                let mut t = vec![0.0; len];
                at.fill_rows(r, w.clone(), &self.s_cols, &mut a, &mut t, &mut scratch)?;
                out.extend(
                    (0..len).flat_map(|i| (0..k).map(move |c| (i, c))).map(|(i, c)| a[c * len + i]),
                );
            }
            Ok(out)
        });
        let mut s_new = Vec::with_capacity(self.s_ref.len());
        for run in per_run {
            s_new.extend(run?);
        }
        // The changes D = S(c) − S_ref, row by row, into the sums.
        let (mut ws, mut ss, mut sb) = (self.ws0.clone(), self.ss0.clone(), self.sb0.clone());
        for (i, &bi) in self.b.iter().enumerate() {
            let (s0, s1) = (&self.s_ref[i * k..(i + 1) * k], &s_new[i * k..(i + 1) * k]);
            if s0 == s1 {
                continue;
            }
            let f = &self.fw[i * kk..(i + 1) * kk];
            for a in 0..k {
                let d = s1[a] - s0[a];
                if d == 0.0 {
                    continue;
                }
                sb[a] += d * bi;
                for q in 0..kk {
                    ws[(q, a)] += f[q] * d;
                }
                // S₁ᵀS₁ − S₀ᵀS₀ = S₀ᵀD + DᵀS₀ + DᵀD = S₁ᵀD + DᵀS₀, entry by entry.
                for c in 0..k {
                    ss[(a, c)] += d * s0[c];
                    ss[(c, a)] += s1[c] * d;
                }
            }
        }
        let t: Vec<f64> =
            (0..k).map(|a| sb[a] - (0..kk).map(|q| ws[(q, a)] * self.wb[q]).sum::<f64>()).collect();
        let g = Mat::<f64>::from_fn(k, k, |a, c| {
            ss[(a, c)] - (0..kk).map(|q| ws[(q, a)] * ws[(q, c)]).sum::<f64>()
        });
        Ok(self.rss_f - explained(&g, &ss, &t)?)
    }
}

/// `tᵀ G⁺ t`: what the backlash columns' part outside `F` explains of `F`'s residual; a
/// column whose part outside is below [`GRAM_SHARE`] of `SᵀS`'s diagonal is left out, and the
/// rest is solved in columns scaled to unit diagonal, truncated at [`GRAM_SHARE`].
fn explained(g: &Mat<f64>, ss: &Mat<f64>, t: &[f64]) -> Result<f64, FitError> {
    let live: Vec<usize> =
        (0..t.len()).filter(|&a| g[(a, a)] > GRAM_SHARE * ss[(a, a)] && ss[(a, a)] > 0.0).collect();
    if live.is_empty() {
        return Ok(0.0);
    }
    let d: Vec<f64> = live.iter().map(|&a| g[(a, a)].sqrt()).collect();
    let gs =
        Mat::<f64>::from_fn(live.len(), live.len(), |i, j| g[(live[i], live[j])] / (d[i] * d[j]));
    let ts: Vec<f64> = live.iter().zip(&d).map(|(&a, di)| t[a] / di).collect();
    let (u, s, _) = jacobi_svd(gs.as_ref()).ok_or(FitError::Svd)?;
    let smax = s.iter().fold(0.0f64, |a, &x| a.max(x));
    Ok((0..s.len())
        .filter(|&q| s[q] > GRAM_SHARE * smax)
        .map(|q| {
            let p: f64 = (0..ts.len()).map(|i| u[(i, q)] * ts[i]).sum();
            p * p / s[q]
        })
        .sum())
}

#[cfg(test)]
mod tests {
    use ballbar_model::machine::{Model, ModelOptions};
    use ballbar_model::machines;
    use ballbar_sim::{Truth, simulate};

    use super::super::first_order;
    use super::*;

    /// The residual from the reference factorisation's sums equals the residual of the design
    /// factored at each lag: at the reference, at the commanded reversal, and at lags up to
    /// the bound, each axis apart. Both are sums over ~34,000 samples of a residual the
    /// rounding of a QR leaves at ~1e-15 relative; the Gram matrix's subtraction loses a few
    /// digits more (its condition, the backlash columns against the rest, is below 1e3 here):
    /// 1e-9 of the sum is far inside the Δχ² = 1 that separates two switch lags (1/m ≈ 3e-5).
    #[test]
    fn the_residual_from_the_sums_is_the_factorisations_at_every_lag() {
        let spec = machines::column();
        let mut truth: Truth =
            ron::from_str(include_str!("../../../../fixtures/column-paper/truth.ron")).unwrap();
        truth.noise_um = 0.2;
        let runs = simulate(&spec, &truth, 0.0, 11).unwrap().runs;
        let model = Model::new(spec, ModelOptions::default()).unwrap();
        let reference = [0.004, 0.0025, 0.003, 0.0, 0.0, 0.0];
        let design = Design::new(&model, &runs).unwrap().with_switch_lags(reference);
        assert!(applies(&design));
        let fac = Factorisation::new(&design, 2).unwrap();
        let sums = SwitchUpdate::new(&design, &fac, 0.12, 2).unwrap().unwrap();
        let rows: usize = sums.windows.iter().flatten().map(|w| w.len()).sum();
        assert!(
            rows * 10 < design.n_rows(),
            "{rows} of {} rows near the reversals",
            design.n_rows()
        );
        let mut seen = Vec::new();
        for lags in [
            reference,
            [0.0; 6],
            [0.0001, 0.0, 0.0, 0.0, 0.0, 0.0],
            [0.01, 0.012, 0.011, 0.0, 0.0, 0.0],
            [0.05, 0.02, 0.0, 0.0, 0.0, 0.0],
            [0.12, 0.11, 0.1, 0.0, 0.0, 0.0],
        ] {
            let full = first_order(&design.at_switch_lags(lags), None, 2).unwrap().rss;
            let fast = sums.rss(&design, lags, 2).unwrap();
            assert!((fast - full).abs() <= 1e-9 * full, "{lags:?}: {fast} against {full}");
            seen.push(full);
        }
        // The lags matter: a misplaced switch of 3 µm of backlash puts its step on the
        // samples between, a change of the residual a million times the tolerance above.
        let (lo, hi) = seen.iter().fold((f64::INFINITY, 0.0f64), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi - lo > 1e-3 * lo, "{seen:?}");
    }
}

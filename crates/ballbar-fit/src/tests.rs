//! Known-answer tests: the chain model against the paper's basis, and recovery of the paper's
//! machines from simulated runs.

use ballbar_model::machine::{MachineSpec, Model, ModelOptions, ServoVariant};
use ballbar_model::machines;
use ballbar_model::paper::{self, PaperValues};
use ballbar_model::{Axis, BarLength, Design, Plane, RowScratch, Run};
use ballbar_sim::{Truth, simulate};
use faer::Mat;

use super::*;

fn truth(machine: &str) -> Truth {
    let text = match machine {
        "column" => include_str!("../../../fixtures/column-paper/truth.ron"),
        _ => include_str!("../../../fixtures/horizontal-paper/truth.ron"),
    };
    ron::from_str(text).unwrap()
}

fn spec(machine: &str) -> MachineSpec {
    match machine {
        "column" => machines::column(),
        _ => machines::horizontal(),
    }
}

const PAPER: ModelOptions =
    ModelOptions { servo: ServoVariant::PlaneMismatch, bar_length: BarLength::Known(0.0) };

fn runs(machine: &str, noise_um: f64, seed: u64) -> Vec<Run> {
    let mut t = truth(machine);
    t.noise_um = noise_um;
    simulate(&spec(machine), &t, 0.0, seed).unwrap().runs
}

/// Interior samples of a run: at the two end samples the commanded velocity is a one-sided
/// difference, not the exact derivative the paper's basis assumes, so span checks leave them out.
fn interior(run: &Run) -> std::ops::Range<usize> {
    1..run.len() - 1
}

/// Dense design matrix (machine columns, then centring) over interior samples, for span checks.
fn dense(design: &Design<'_>) -> Mat<f64> {
    let rows: usize = design.runs.iter().map(|r| interior(r).len()).sum();
    let mut a = Mat::<f64>::zeros(rows, design.n_cols());
    let mut row = vec![0.0; design.n_cols()];
    let mut s = RowScratch::default();
    let mut k = 0;
    for r in 0..design.runs.len() {
        for i in interior(&design.runs[r]) {
            design.row(r, i, &mut s, &mut row).unwrap();
            for (j, v) in row.iter().enumerate() {
                a[(k, j)] = *v;
            }
            k += 1;
        }
    }
    a
}

/// Orthonormal basis of the column space (SVD, relative cut-off 1e-10).
fn column_space(a: &Mat<f64>) -> Mat<f64> {
    let svd = a.as_ref().thin_svd().unwrap();
    let s = svd.S().column_vector();
    let smax = (0..s.nrows()).map(|k| s[k]).fold(0.0, f64::max);
    let keep: Vec<usize> = (0..s.nrows()).filter(|&k| s[k] > 1e-10 * smax).collect();
    Mat::from_fn(a.nrows(), keep.len(), |i, j| svd.U()[(i, keep[j])])
}

/// ‖p - P p‖ / ‖p‖ for the projector onto span(q).
fn residual(q: &Mat<f64>, p: &[f64]) -> f64 {
    let mut r = p.to_vec();
    for j in 0..q.ncols() {
        let c: f64 = (0..q.nrows()).map(|i| q[(i, j)] * p[i]).sum();
        for (i, x) in r.iter_mut().enumerate() {
            *x -= c * q[(i, j)];
        }
    }
    let n = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    n(&r) / n(p)
}

fn hstack(a: &Mat<f64>, b: &Mat<f64>) -> Mat<f64> {
    Mat::from_fn(a.nrows(), a.ncols() + b.ncols(), |i, j| {
        if j < a.ncols() { a[(i, j)] } else { b[(i, j - a.ncols())] }
    })
}

fn col(a: &Mat<f64>, j: usize) -> Vec<f64> {
    (0..a.nrows()).map(|i| a[(i, j)]).collect()
}

/// The paper's 18 basis columns and the nuisance columns (per-run centring, constant).
fn paper_and_nuisance(runs: &[Run]) -> (Mat<f64>, Mat<f64>) {
    let m: usize = runs.iter().map(|r| interior(r).len()).sum();
    let mut p = Mat::<f64>::zeros(m, 18);
    let mut nu = Mat::<f64>::zeros(m, 2 * runs.len() + 1);
    let mut k = 0;
    for (r, run) in runs.iter().enumerate() {
        let (ua, va, _) = run.header.plane.axes().unwrap();
        for i in interior(run) {
            for (j, b) in paper::basis(run, i).iter().enumerate() {
                p[(k, j)] = *b;
            }
            for (c, a) in [ua, va].into_iter().enumerate() {
                nu[(k, 2 * r + c)] = run.axis(a).unwrap()[i] - run.header.pivot_mm[a.index()];
            }
            nu[(k, 2 * runs.len())] = 1.0;
            k += 1;
        }
    }
    (p, nu)
}

fn nominal_runs(machine: &str) -> Vec<Run> {
    let mut t = truth(machine);
    t.paper = None;
    t.noise_um = 0.0;
    t.centring_sd_um = 0.0;
    t.sample_rate_hz = 10.0;
    let mut runs = simulate(&spec(machine), &t, 0.0, 1).unwrap().runs;
    // Exact circle coordinates, not the 1e-6 mm of a run file: the span check works at 1e-9.
    for run in &mut runs {
        let h = run.header.clone();
        let c = ballbar_model::path::CircleTest {
            plane: h.plane,
            direction: h.direction.unwrap(),
            radius_mm: h.radius_mm,
            feed_mm_per_min: h.feed_mm_per_min,
            pivot_mm: h.pivot_mm,
            table_ball_mm: h.table_ball_mm,
            tool_ball_mm: h.tool_ball_mm,
            sample_rate_hz: 10.0,
            start_deg: 0.0,
            sweep_deg: 360.0,
        };
        for i in 0..run.len() {
            let q = c.position(run.t_s[i]);
            for a in ballbar_model::Axis::LINEAR {
                run.axes[a.index()].as_mut().unwrap()[i] = q[a.index()];
            }
        }
    }
    runs
}

fn span_check(machine: &str) {
    let runs = nominal_runs(machine);
    let (p, nu) = paper_and_nuisance(&runs);
    // Paper's servo variant: the chain terms plus the three plane terms span exactly the paper's
    // 18 functions, modulo centring and a constant.
    let model = Model::new(
        spec(machine),
        ModelOptions { servo: ServoVariant::PlaneMismatch, bar_length: BarLength::Fit },
    )
    .unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let a = dense(&design);
    let chain_machine = Mat::from_fn(a.nrows(), design.n_machine, |i, j| a[(i, j)]);
    let chain_span = column_space(&hstack(&chain_machine, &nu));
    let paper_span = column_space(&hstack(&p, &nu));
    for j in 0..18 {
        let r = residual(&chain_span, &col(&p, j));
        assert!(
            r < 1e-9,
            "{machine}: paper basis {} is not in the chain's span: {r:e}",
            paper::BASIS_NAMES[j]
        );
    }
    for j in 0..design.n_machine {
        let r = residual(&paper_span, &col(&chain_machine, j));
        assert!(
            r < 1e-9,
            "{machine}: chain column {} is not in the paper's span: {r:e}",
            design.parameters[j].id
        );
    }
    // Per-axis lags: every lag column lies in the paper's span, but the three servo functions
    // are tied: differences of the plane terms are reachable, their sum is not.
    let model = Model::new(spec(machine), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let a = dense(&design);
    let chain_machine = Mat::from_fn(a.nrows(), design.n_machine, |i, j| a[(i, j)]);
    for j in 0..design.n_machine {
        let r = residual(&paper_span, &col(&chain_machine, j));
        assert!(
            r < 1e-9,
            "{machine} (lags): chain column {} is not in the paper's span: {r:e}",
            design.parameters[j].id
        );
    }
    let lag_span = column_space(&hstack(&chain_machine, &nu));
    let (xy, yz, zx) = (col(&p, 15), col(&p, 16), col(&p, 17));
    let diff: Vec<f64> = xy.iter().zip(&yz).map(|(a, b)| a - b).collect();
    let sum: Vec<f64> = xy.iter().zip(&yz).zip(&zx).map(|((a, b), c)| a + b + c).collect();
    assert!(residual(&lag_span, &diff) < 1e-9, "M_XY - M_YZ must be reachable with lags");
    assert!(residual(&lag_span, &sum) > 0.1, "M_XY + M_YZ + M_ZX must not be reachable with lags");
}

#[test]
fn column_chain_spans_the_papers_eq39_basis() {
    span_check("column");
}

#[test]
fn horizontal_chain_spans_the_papers_eq40_basis() {
    span_check("horizontal");
}

/// The 24 quantities of a fit, by name.
fn reported(fit: &Fit, model: &Model, p: &PaperValues) -> Vec<QuantityEstimate> {
    paper::report(model, p.radius_mm, p.feed_mm_per_min)
        .iter()
        .map(|row| quantity(fit, &row.paper).unwrap())
        .collect()
}

/// The paper's table as the known answer, by row name; angular rows derived from the
/// straightness rows with the documented signs (2 d / R).
fn expected(p: &PaperValues) -> Vec<(String, f64)> {
    let mut e = Vec::new();
    for (k, a) in ["X", "Y", "Z"].iter().enumerate() {
        e.push((format!("{a} positional"), p.positional_um[k]));
    }
    let st = [("Y", "X"), ("Z", "X"), ("X", "Y"), ("Z", "Y"), ("X", "Z"), ("Y", "Z")];
    for (k, (t, a)) in st.iter().enumerate() {
        e.push((format!("{t} straightness along {a}"), p.straightness_um[k]));
    }
    let angle = [("Z", 1.0), ("Y", -1.0), ("Z", -1.0), ("X", 1.0), ("Y", 1.0), ("X", -1.0)];
    for (k, (about, sign)) in angle.iter().enumerate() {
        e.push((
            format!("{about} angular along {}", st[k].1),
            sign * 2.0 * p.straightness_um[k] / p.radius_mm * 1e3,
        ));
    }
    for (k, pl) in ["XY", "YZ", "ZX"].iter().enumerate() {
        e.push((format!("squareness {pl}"), p.squareness_urad[k]));
    }
    for (k, a) in ["X", "Y", "Z"].iter().enumerate() {
        e.push((format!("backlash {a}"), p.backlash_um[k]));
    }
    for (k, pl) in ["XY", "YZ", "ZX"].iter().enumerate() {
        e.push((format!("servo mismatch {pl}"), p.servo_mismatch_um[k]));
    }
    e
}

fn recover(
    machine: &str,
    noise_um: f64,
    seed: u64,
) -> (Vec<QuantityEstimate>, Vec<(String, f64)>, Fit) {
    let runs = runs(machine, noise_um, seed);
    let model = Model::new(spec(machine), PAPER).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    let p = truth(machine).paper.unwrap();
    (reported(&f, &model, &p), expected(&p), f)
}

fn noise_free(machine: &str) {
    let (got, want, f) = recover(machine, 0.0, 7);
    assert_eq!(f.rank, f.parameters.len(), "{machine}: the paper's tests identify every parameter");
    assert!(f.gauges.is_empty(), "{machine}: nothing left to a choice: {:?}", f.gauges);
    assert_eq!(got.len(), 24);
    for (q, (name, w)) in got.iter().zip(&want) {
        assert_eq!(&q.name, name);
        assert!(q.estimate.estimable, "{name}");
        // The known answer within 0.05 µm / 0.5 µrad: what remains is the simulator's exact
        // geometry against the first-order model (second-order terms ~ (20 µm)²/R ≈ 0.003 µm)
        // and the reading resolution.
        let tol = if q.unit == "µrad" { 0.5 } else { 0.05 };
        assert!(
            (q.estimate.value - w).abs() < tol,
            "{machine} {name}: {} vs {w} {}",
            q.estimate.value,
            q.unit
        );
    }
}

#[test]
fn the_fits_residuals_are_against_the_exact_chain() {
    // The refinement stops with a linearised last update (lib.rs); its residuals must still
    // equal reading minus the exact model to within the refinement tolerance, 1e-8 mm RMS, and
    // nowhere by more than 1e-6 mm (1 % of a bar's 0.1 µm resolution).
    let runs = runs("horizontal", 0.2, 3);
    let model = Model::new(spec("horizontal"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    let (mut worst, mut sum2, mut m): (f64, f64, usize) = (0.0, 0.0, 0);
    for (r, run) in runs.iter().enumerate() {
        let exact = design.exact_run(r, &f.values).unwrap();
        for i in 0..run.len() {
            let d = run.dr_mm[i] - exact[i] - f.residuals[r][i];
            worst = worst.max(d.abs());
            sum2 += d * d;
            m += 1;
        }
    }
    let rms = (sum2 / m as f64).sqrt();
    assert!(rms < 1e-8 && worst < 1e-6, "difference RMS {rms:e} mm, largest {worst:e} mm");
}

/// A reading of 1e300 mm is a finite number whose square is not: the fit's sums overflowed
/// and it returned a residual σ of NaN and NaN parameters, which `fit` printed with exit 0. The
/// readers refuse such a reading; the fit, which takes runs from anywhere, says it has no
/// finite solution.
#[test]
fn readings_whose_squares_overflow_are_an_error_not_a_fit_of_nan() {
    let mut runs = runs("column", 0.0, 3);
    runs[0].dr_mm[10] = 1e300;
    let model = Model::new(spec("column"), PAPER).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    match fit(&design, 2) {
        Err(FitError::NonFinite) => {}
        Err(e) => panic!("{e}"),
        Ok(f) => panic!("a fit of σ {} mm, values {:?}", f.sigma_mm, &f.values[..3]),
    }
}

#[test]
fn column_machine_noise_free_recovers_the_papers_24_quantities() {
    noise_free("column");
}

#[test]
fn horizontal_machine_noise_free_recovers_the_papers_24_quantities() {
    noise_free("horizontal");
}

fn noisy(machine: &str) {
    let (got, want, f) = recover(machine, 0.2, 11);
    // The residual is the noise: its standard deviation is recovered within 5 %.
    assert!((f.sigma_mm * 1e3 - 0.2).abs() < 0.01, "{machine}: sigma {}", f.sigma_mm * 1e3);
    for (q, (name, w)) in got.iter().zip(&want) {
        let u = q.estimate.std_uncertainty;
        assert!(u > 0.0 && u.is_finite());
        assert!(
            (q.estimate.value - w).abs() < 3.0 * u,
            "{machine} {name}: {} ± {u} vs {w}",
            q.estimate.value
        );
    }
}

#[test]
fn column_machine_with_noise_recovers_within_three_standard_uncertainties() {
    noisy("column");
}

#[test]
fn horizontal_machine_with_noise_recovers_within_three_standard_uncertainties() {
    noisy("horizontal");
}

#[test]
fn a_fitted_model_predicts_held_out_repeats_to_within_ten_percent_of_the_noise_floor() {
    for machine in ["column", "horizontal"] {
        let train = runs(machine, 0.2, 21);
        let model = Model::new(spec(machine), PAPER).unwrap();
        let design = Design::new(&model, &train).unwrap();
        let f = fit(&design, 2).unwrap();
        // New session: new noise, new centring. Predict with the machine parameters only.
        let test = runs(machine, 0.2, 22);
        let held = Design::new(&model, &test).unwrap();
        let mut theta = f.values[..f.n_machine].to_vec();
        theta.resize(held.n_cols(), 0.0);
        for (r, run) in test.iter().enumerate() {
            let pred = held.predict_run(r, &theta).unwrap();
            let res: Vec<f64> = run.dr_mm.iter().zip(&pred).map(|(a, b)| a - b).collect();
            let th = metrics::angles(run).unwrap();
            // The run's own centring is a set-up nuisance no model can know: remove it.
            let rms = metrics::rms(&metrics::without_centring(&th, &res)) * 1e3;
            assert!(rms < 1.1 * 0.2, "{machine} {}: held-out RMS {rms} µm", run.name());
            let before = metrics::rms(&metrics::without_centring(&th, &run.dr_mm)) * 1e3;
            assert!(before > 5.0 * rms, "the model explains the trace: {before} → {rms}");
        }
    }
}

#[test]
fn one_plane_reports_what_it_cannot_separate_instead_of_inventing_values() {
    let all = runs("column", 0.2, 3);
    let xy: Vec<Run> = all.into_iter().filter(|r| r.header.plane == Plane::XY).collect();
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &xy).unwrap();
    let f = fit(&design, 2).unwrap();
    assert!(f.rank < f.parameters.len());
    assert!(!f.null_space.is_empty());
    let est = |id: &str| f.estimable[f.index(id).unwrap()];
    // Z-axis terms never act in an XY circle; X/Y terms that do act are separable.
    for id in ["EZZ1", "EXZ2", "BZ", "SQYZ", "SQZX"] {
        assert!(!est(id), "{id} cannot come from an XY test");
    }
    for id in ["SQXY", "BX", "BY", "EYX2", "EXY2"] {
        assert!(est(id), "{id} is identified by an XY test");
    }
    // Scale of X and Y together is a bar-length change at one radius: the direction
    // EXX1 = EYY1 = c, BAR = -c R/L (plus a centring) changes no reading, so the common scale is
    // not estimable, and some reported null combination involves the bar length.
    let sx = f.index("EXX1").unwrap();
    let sy = f.index("EYY1").unwrap();
    let bar = f.index("BAR").unwrap();
    let mut z = vec![0.0; design.n_cols()];
    z[sx] = 1e-3;
    z[sy] = 1e-3;
    z[bar] = -1e-3 * 150.0 / 250.0;
    let pred: Vec<f64> = (0..xy.len()).flat_map(|r| design.predict_run(r, &z).unwrap()).collect();
    let th: Vec<f64> = xy.iter().flat_map(|r| metrics::angles(r).unwrap()).collect();
    // What remains is a first harmonic (a centring), nothing else.
    // Predictions are ~1e-3 mm; 1e-10 mm is rounding of the 8-term sums.
    let left = metrics::rms(&metrics::without_centring(&th, &pred));
    assert!(left < 1e-10, "{left}");
    assert!(
        !f.functional(&[(sx, 1.0), (sy, 1.0)]).estimable,
        "the common scale is aliased with the bar"
    );
    assert!(f.null_space.iter().any(|c| c.components.iter().any(|x| x.0 == bar)));
    // The common lag is invisible; the lag difference is the servo mismatch.
    let (tx, ty) = (f.index("TX").unwrap(), f.index("TY").unwrap());
    assert!(!f.estimable[tx]);
    assert!(f.functional(&[(tx, 1.0), (ty, -1.0)]).estimable);
}

#[test]
fn per_axis_lags_are_recovered_from_a_time_domain_simulation() {
    // The physical servo variant: lags of 30, 33 and 36 ms, simulated as first-order position
    // loops in the time domain, at 1000 mm/min (a lag of 0.5 mm). The model is first order in the
    // lag; the filter's second-order amplitude and phase (R ω² τ² ≈ 1.8 µm, times ωτ ≈ 0.4 % for
    // its 45° part) stay below the tolerances here. At 2000 mm/min they move the squareness by
    // ~0.6 µrad: a servo-lag effect for the diagnosis, not for the base model.
    let mut t = truth("column");
    t.paper = None;
    t.servo = ServoVariant::AxisLag;
    t.noise_um = 0.1;
    t.sample_rate_hz = 100.0;
    // No backlash here: with lag, a backlash switches when the lagging axis reverses, τ after
    // the command, which the first-order model does not contain (a gap for the diagnosis).
    for (k, v) in [("TX", 30.0), ("TY", 33.0), ("TZ", 36.0), ("SQXY", 20.0), ("EYX2", 2.0)] {
        t.errors.insert(k.into(), v);
    }
    for test in &mut t.tests {
        test.feed_mm_per_min = 1000.0;
    }
    let runs = simulate(&spec("column"), &t, 0.0, 5).unwrap().runs;
    let model = Model::new(
        spec("column"),
        ModelOptions { bar_length: BarLength::Fit, ..ModelOptions::default() },
    )
    .unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    let i = |id: &str| f.index(id).unwrap();
    let d = f.functional(&[(i("TY"), 1.0), (i("TX"), -1.0)]);
    // 3 ms lag difference. The first-order model leaves the lag's second-order radius loss
    // (V²τ²/2R ≈ 4 µm, constant: taken by the bar length) and the delayed backlash switch;
    // 0.05 ms is 2 % of the difference.
    assert!(d.estimable && (d.value * 1e3 - 3.0).abs() < 0.05, "TY - TX = {} ms", d.value * 1e3);
    let d = f.functional(&[(i("TZ"), 1.0), (i("TY"), -1.0)]);
    assert!((d.value * 1e3 - 3.0).abs() < 0.05, "TZ - TY = {} ms", d.value * 1e3);
    let sq = f.values[i("SQXY")] * 1e6;
    assert!((sq - 20.0).abs() < 0.5, "SQXY {sq}");
}

#[test]
fn effects_simulated_in_the_time_domain_are_recovered_by_a_model_that_has_them() {
    use ballbar_model::Effect;
    use ballbar_sim::TruthEffect;
    // The simulator realises effects on the actual (lagging) motion; the model evaluates them
    // on the commanded path. A model that contains the effects must recover their sizes.
    let effects = vec![
        TruthEffect {
            effect: Effect::ReversalSpike { axis: Axis::X, tau_ms: 60.0 },
            value: 6.0,
            phase_deg: 0.0,
        },
        TruthEffect {
            effect: Effect::CyclicError { axis: Axis::Y, pitch_mm: 10.0 },
            value: 1.5,
            phase_deg: 30.0,
        },
        TruthEffect { effect: Effect::ThermalDrift { axis: None }, value: 20.0, phase_deg: 0.0 },
        TruthEffect {
            effect: Effect::LateralPlay { axis: Axis::Z, switched_by: Axis::Y },
            value: 3.0,
            phase_deg: 0.0,
        },
    ];
    let mut t = truth("column");
    t.effects = effects.clone();
    let runs = simulate(&spec("column"), &t, 0.0, 5).unwrap().runs;
    let list: Vec<Effect> = effects.iter().map(|e| e.effect.clone()).collect();
    let model =
        Model::with_effects(spec("column"), PAPER, &ballbar_model::NoKernels, &list).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    let value = |id: &str| {
        let i = f.index(id).unwrap();
        assert!(f.estimable[i], "{id}");
        (
            f.values[i] * f.parameters[i].unit.display_factor(),
            f.std_uncertainty[i] * f.parameters[i].unit.display_factor(),
        )
    };
    // 0.2 µm noise: within 4 standard uncertainties, or 3 % where the model's commanded-path
    // reversal times differ from the simulated lagging axis (lags of 0.1 ms against τ = 60 ms).
    let close = |id: &str, want: f64| {
        let (v, u) = value(id);
        assert!((v - want).abs() < (4.0 * u).max(0.03 * want.abs()), "{id}: {v} ± {u} vs {want}");
    };
    close("SPX", 6.0);
    close("CSY", 1.5 * 30f64.to_radians().cos());
    close("CCY", 1.5 * 30f64.to_radians().sin());
    close("DBAR", 20.0);
    close("LPZY", 3.0);
    // And the base terms stay where the truth has them.
    assert!(f.sigma_mm * 1e3 < 0.21, "σ {} µm", f.sigma_mm * 1e3);
}

#[test]
fn the_jacobi_svd_fallback_agrees_with_faer_on_a_rank_deficient_matrix() {
    // 14 × 14 upper triangular (the fit's scaled R), columns of scales 1e-3..1e3, column 5 a
    // combination of columns 1 and 2, column 9 zero: rank 12.
    let n = 14;
    let mut a = Mat::<f64>::from_fn(n, n, |i, j| {
        if i <= j {
            ((i * 31 + j * 17) as f64 * 0.37).sin() * 10f64.powi(j as i32 % 7 - 3)
        } else {
            0.0
        }
    });
    for i in 0..n {
        a[(i, 5)] = 2.0 * a[(i, 1)] - 0.5 * a[(i, 2)];
        a[(i, 9)] = 0.0;
    }
    let (u, s, v) = jacobi_svd(a.as_ref()).expect("converges");
    let faer_svd = a.as_ref().thin_svd().expect("faer converges here");
    let mut ours = s.clone();
    ours.sort_by(|x, y| y.total_cmp(x));
    let theirs: Vec<f64> = (0..n).map(|k| faer_svd.S().column_vector()[k]).collect();
    let smax = theirs[0];
    for (x, y) in ours.iter().zip(&theirs) {
        // Both backward stable: singular values agree to rounding of the largest.
        assert!((x - y).abs() <= 1e-12 * smax, "{ours:?} vs {theirs:?}");
    }
    let rank = |v: &[f64]| v.iter().filter(|&&x| x > RANK_TOLERANCE * smax).count();
    assert_eq!(rank(&ours), rank(&theirs));
    // The dependent and the zero column: at least two singular values are zero to rounding.
    assert!(ours[n - 2] <= 1e-12 * smax, "{ours:?}");
    // U diag(s) Vᵀ = A, and V is orthogonal.
    for i in 0..n {
        for j in 0..n {
            let back: f64 = (0..n).map(|k| u[(i, k)] * s[k] * v[(j, k)]).sum();
            assert!((back - a[(i, j)]).abs() <= 1e-12 * smax, "({i},{j})");
            let vv: f64 = (0..n).map(|k| v[(k, i)] * v[(k, j)]).sum();
            assert!((vv - if i == j { 1.0 } else { 0.0 }).abs() < 1e-12);
        }
    }
}

#[test]
fn the_jacobi_svd_converges_on_the_scaled_r_of_a_rank_deficient_design() {
    // What the fit hands it: the R factor of a tall matrix with exactly dependent columns,
    // columns scaled to unit norm. The dependent columns leave rounding noise in R, which
    // never becomes orthogonal to anything: those columns must be recognised as null.
    for n in [14, 40] {
        let m = 3 * n;
        // Column 7 zero, column 3 = column 1 - column 2: rank n - 2.
        let mut a = Mat::<f64>::from_fn(m, n, |i, j| {
            if j == 7 {
                0.0
            } else {
                ((i * (j + 3) + 11 * j) as f64 * 0.137).sin() * (1.0 + j as f64)
            }
        });
        for i in 0..m {
            a[(i, 3)] = a[(i, 1)] - a[(i, 2)];
        }
        let r = a.as_ref().qr().thin_R().to_owned();
        let norms: Vec<f64> =
            (0..n).map(|j| (0..n).map(|i| r[(i, j)] * r[(i, j)]).sum::<f64>().sqrt()).collect();
        let rs = Mat::<f64>::from_fn(
            n,
            n,
            |i, j| if norms[j] > 0.0 { r[(i, j)] / norms[j] } else { 0.0 },
        );
        let (u, s, v) =
            jacobi_svd(rs.as_ref()).unwrap_or_else(|| panic!("n = {n}: did not converge"));
        let smax = s.iter().copied().fold(0.0, f64::max);
        assert_eq!(
            s.iter().filter(|&&x| x > RANK_TOLERANCE * smax).count(),
            n - 2,
            "n = {n}: {s:?}"
        );
        for i in 0..n {
            for j in 0..n {
                let back: f64 = (0..n).map(|k| u[(i, k)] * s[k] * v[(j, k)]).sum();
                assert!((back - rs[(i, j)]).abs() <= 1e-12 * smax, "n = {n} ({i},{j})");
            }
        }
    }
}

#[test]
fn a_runs_own_column_at_rounding_level_is_not_estimable() {
    // A vibration of X fitted on the column machine's runs, where the X coordinate of the YZ
    // runs jitters by 1e-13 mm (what a chain with rotary joints leaves of an exact zero): the
    // YZ runs' vibration columns are ~1e-15 of the XY runs'. Scaled to unit norm their rounding
    // noise would be "estimable"; they must be zero columns, not estimable, valued 0.
    let mut rs = runs("column", 0.1, 3);
    for r in rs.iter_mut().filter(|r| r.header.plane == Plane::YZ) {
        for (i, x) in r.axes[Axis::X.index()].as_mut().unwrap().iter_mut().enumerate() {
            *x += if i % 2 == 0 { 1e-13 } else { -1e-13 };
        }
    }
    let base = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let vib = [ballbar_model::Effect::Vibration { axis: Axis::X, frequency_hz: 13.0 }];
    let model =
        Model::with_effects(base.spec.clone(), base.options, &ballbar_model::NoKernels, &vib)
            .unwrap();
    let design = Design::new(&model, &rs).unwrap();
    let f = fit(&design, 2).unwrap();
    let mut seen = (0, 0);
    for (i, p) in f.parameters.iter().enumerate() {
        let Some((_, run)) =
            p.id.split_once('@').filter(|(t, _)| t.starts_with("VSX") || t.starts_with("VCX"))
        else {
            continue;
        };
        let plane = rs.iter().find(|r| r.name() == run).unwrap().header.plane;
        if plane == Plane::YZ {
            assert!(
                !f.estimable[i] && f.values[i] == 0.0,
                "{}: {} estimable {}",
                p.id,
                f.values[i],
                f.estimable[i]
            );
            seen.0 += 1;
        } else {
            assert!(f.estimable[i], "{}", p.id);
            seen.1 += 1;
        }
    }
    assert!(seen.0 >= 2 && seen.1 >= 4, "{seen:?}");
}

// What the runs cannot determine is gauged, and the fit says so (the default options on the
// tests a vendor's software accepts, from one plane at one radius upwards).

/// A column machine with per-axis lags (display units: µm, µrad, ms) and no bar-length error.
/// The lags are those of a machine with feed-forward (1.0 to 1.4 ms): their common part's
/// radius loss, V²τ²/(2R) ≈ 0.01 µm at 1500 mm/min and R = 50 mm, is far below the
/// uncertainties, so the scale the nominal bar gives the positional errors is the truth's.
fn lag_truth(
    tests: Vec<ballbar_sim::TestSpec>,
    noise_um: f64,
    correlation_ms: f64,
    rate_hz: f64,
) -> Truth {
    let errors = [
        ("EXX1", 10.0),
        ("EYY1", 3.0),
        ("EZZ1", 6.0),
        ("EYX2", 2.5),
        ("EZX2", 2.7),
        ("EXY2", 2.6),
        ("EZY2", -0.6),
        ("EXZ2", 1.5),
        ("EYZ2", 0.5),
        ("SQXY", -9.0),
        ("SQYZ", 30.0),
        ("SQZX", -20.0),
        ("BX", 1.5),
        ("BY", 0.8),
        ("BZ", 1.0),
        ("TX", 1.0),
        ("TY", 1.4),
        ("TZ", 1.2),
    ];
    Truth {
        servo: ServoVariant::AxisLag,
        errors: errors.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        paper: None,
        bar_length_um: 0.0,
        centring_sd_um: 30.0,
        noise_um,
        noise_correlation_ms: correlation_ms,
        sample_rate_hz: rate_hz,
        started_at: "2026-11-21T10:00:00Z".into(),
        pause_s: 60.0,
        tests,
        effects: Vec::new(),
    }
}

/// Where a test is run: radius (mm), feed (mm/min), pivot (mm), table and tool ball (mm).
type SetUp = (f64, f64, [f64; 3], [f64; 3], [f64; 3]);

/// One run of a test: `sweep_deg` from `from_deg` in direction `dir` (a CW arc runs from the
/// other end, so that both directions cover the same arc).
fn arc(
    plane: Plane,
    dir: ballbar_model::Direction,
    at: SetUp,
    from_deg: f64,
    sweep_deg: f64,
) -> ballbar_sim::TestSpec {
    let (radius_mm, feed_mm_per_min, pivot_mm, table_ball_mm, tool_ball_mm) = at;
    let start_deg =
        if dir == ballbar_model::Direction::CW { from_deg + sweep_deg } else { from_deg };
    ballbar_sim::TestSpec {
        plane,
        directions: vec![dir],
        radius_mm,
        feed_mm_per_min,
        pivot_mm,
        table_ball_mm,
        tool_ball_mm,
        repeats: 1,
        start_deg,
        sweep_deg,
        rotary: None,
    }
}

/// The shop-floor set-up: R = 50 mm, 1500 mm/min, pivot at the origin, both balls on their
/// gauge points.
const SHOP: SetUp = (50.0, 1500.0, [0.0; 3], [0.0; 3], [0.0; 3]);

/// The shop-floor XY test: R = 50 mm, 1500 mm/min, CW and CCW, pivot at the origin with both
/// balls on their gauge points, sampled at 125 Hz, over `sweep_deg` from `from_deg`.
fn xy_test(from_deg: f64, sweep_deg: f64) -> Vec<ballbar_sim::TestSpec> {
    use ballbar_model::Direction::{CCW, CW};
    [CW, CCW].into_iter().map(|d| arc(Plane::XY, d, SHOP, from_deg, sweep_deg)).collect()
}

/// The shop-floor noise: 0.4 µm with a lag-one autocorrelation of 0.85 at 125 Hz (an
/// Ornstein-Uhlenbeck correlation time of 8 ms / -ln 0.85 = 49 ms).
fn shop_floor(tests: Vec<ballbar_sim::TestSpec>) -> Truth {
    lag_truth(tests, 0.4, -8.0 / 0.85f64.ln(), 125.0)
}

/// Every estimable machine parameter of `f` within 3 standard uncertainties of the truth
/// (backlash 0.05 µm more: the simulator switches it when the lagging axis reverses, the
/// model when the command does); returns how many were checked.
fn estimable_match_truth(f: &Fit, t: &Truth) -> usize {
    let mut checked = 0;
    for i in 0..f.n_machine {
        let p = &f.parameters[i];
        if !f.estimable[i] {
            continue;
        }
        let k = p.unit.display_factor();
        let want = t.errors.get(&p.id).copied().unwrap_or(0.0);
        let (got, u) = (f.values[i] * k, f.std_uncertainty[i] * k);
        let allowance =
            if p.class == ballbar_model::ParamClass::Term(ballbar_model::TermClass::Backlash) {
                0.05
            } else {
                0.0
            };
        assert!(u > 0.0 && u.is_finite(), "{}: u {u}", p.id);
        assert!((got - want).abs() <= 3.0 * u + allowance, "{}: {got} ± {u} vs truth {want}", p.id);
        checked += 1;
    }
    checked
}

fn gauge_of(f: &Fit, kind: GaugeKind) -> Option<(usize, &Gauge)> {
    f.gauges.iter().enumerate().find(|(_, g)| g.kind == kind)
}

fn ids_of(f: &Fit, cols: &[usize]) -> Vec<String> {
    let mut v: Vec<String> = cols.iter().map(|&j| f.parameters[j].id.clone()).collect();
    v.sort();
    v
}

#[test]
fn one_plane_at_one_radius_and_one_feed_fits_with_the_default_options() {
    let truth = shop_floor(xy_test(0.0, 360.0));
    let runs = simulate(&spec("column"), &truth, 0.0, 4).unwrap().runs;
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();

    // The failure mode of the real test: a plain truncation at RANK_TOLERANCE keeps the bar
    // length against the common scale (an alias of the nominal circle that the 1e-6 mm rounding
    // of the coordinates breaks at ~2e-9) and gives the bar an absurd length.
    let a = dense(&design);
    let y: Vec<f64> = runs.iter().flat_map(|r| interior(r).map(|i| r.dr_mm[i])).collect();
    let (x, rank) = lstsq_svd(a.as_ref(), &y).unwrap();
    let bar = design.parameters.iter().position(|p| p.id == "BAR").unwrap();
    assert_eq!(rank, 13, "the plain truncation keeps the alias");
    assert!(x[bar].abs() > 1.0, "the plain truncation's bar-length error {} mm", x[bar]);

    let f = fit(&design, 2).unwrap();
    // The noise is what the truth says (0.4 µm, lag-one autocorrelation 0.85).
    assert!(
        (f.sigma_mm * 1e3 - 0.4).abs() < 0.04 && (f.rho - 0.85).abs() < 0.05,
        "σ {} µm, ρ {}",
        f.sigma_mm * 1e3,
        f.rho
    );
    assert_eq!(f.rank, 12);
    assert!(f.condition_number < 100.0, "condition number {}", f.condition_number);

    // What was fixed, and why.
    let kinds: Vec<GaugeKind> = f.gauges.iter().map(|g| g.kind).collect();
    assert_eq!(
        kinds,
        [
            GaugeKind::AxisAtRest(Axis::Z),
            GaugeKind::NoEffect,
            GaugeKind::CommonLag,
            GaugeKind::BarLength
        ]
    );
    let (_, z) = gauge_of(&f, GaugeKind::AxisAtRest(Axis::Z)).unwrap();
    assert_eq!(z.what, "axis Z does not move in these runs");
    assert_eq!(ids_of(&f, &z.parameters), ["BZ", "EXZ2", "EYZ2", "EZZ1", "SQYZ", "SQZX", "TZ"]);
    assert_eq!(
        ids_of(&f, &gauge_of(&f, GaugeKind::NoEffect).unwrap().1.parameters),
        ["EZX2", "EZY2"]
    );
    assert_eq!(ids_of(&f, &gauge_of(&f, GaugeKind::CommonLag).unwrap().1.parameters), ["TX", "TY"]);
    let (gb, b) = gauge_of(&f, GaugeKind::BarLength).unwrap();
    assert_eq!(ids_of(&f, &b.parameters), ["BAR"]);
    assert_eq!(ids_of(&f, &b.conditional), ["EXX1", "EYY1"]);
    assert!(
        b.what.contains("common scale") && b.separate_by.contains("a second radius"),
        "{}",
        b.what
    );

    // The fixed values are the stated ones; what they fix is not estimable.
    let i = |id: &str| f.index(id).unwrap();
    for id in ["EZZ1", "EXZ2", "EYZ2", "SQYZ", "SQZX", "BZ", "TZ", "EZX2", "EZY2", "BAR"] {
        assert_eq!(f.values[i(id)], 0.0, "{id}");
        assert!(!f.estimable[i(id)], "{id}");
    }
    assert!(
        (f.values[i("TX")] + f.values[i("TY")]).abs() < 1e-12,
        "mean lag {} s",
        (f.values[i("TX")] + f.values[i("TY")]) / 2.0
    );
    assert!(!f.estimable[i("TX")] && !f.estimable[i("TY")]);

    // What is identified matches the truth: squareness, straightness, backlash, and the scales
    // given the nominal bar (the truth's bar is nominal).
    for id in ["EXX1", "EYY1", "EYX2", "EXY2", "SQXY", "BX", "BY"] {
        assert!(f.estimable[i(id)], "{id}");
    }
    assert_eq!(estimable_match_truth(&f, &truth), 7);
    // The lag difference is the servo mismatch: -0.4 ms.
    let d = f.functional(&[(i("TX"), 1.0), (i("TY"), -1.0)]);
    assert!(
        d.estimable && (d.value * 1e3 + 0.4).abs() < 3.0 * d.std_uncertainty * 1e3,
        "TX - TY = {} ± {} ms",
        d.value * 1e3,
        d.std_uncertainty * 1e3
    );
    assert!(f.depends_on(&[(i("TX"), 1.0), (i("TY"), -1.0)]).is_empty());
    // The scales hold for the nominal bar, the squareness for any choice.
    assert_eq!(f.depends_on(&[(i("EXX1"), 1.0)]), [gb]);
    assert_eq!(f.depends_on(&[(i("EXX1"), 1.0), (i("EYY1"), -1.0)]), Vec::<usize>::new());
    assert!(f.depends_on(&[(i("SQXY"), 1.0)]).is_empty());
    // And what the runs cannot separate is still listed: the bar against the common scale.
    assert!(f.null_space.iter().any(|c| c.components.iter().any(|x| x.0 == bar)
        && c.components.iter().any(|x| x.0 == i("EXX1"))));
    assert!(f.null_space.iter().any(|c| c.components.len() == 2
        && c.components.iter().all(|x| x.0 == i("TX") || x.0 == i("TY"))));
}

#[test]
fn a_partial_arc_in_one_plane_fits_with_the_default_options() {
    // 220° from -20° (the arc a vendor's software runs where a full circle cannot be), CW and
    // CCW over the same arc, the shop-floor noise.
    let truth = shop_floor(xy_test(-20.0, 220.0));
    let runs = simulate(&spec("column"), &truth, 0.0, 6).unwrap().runs;
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    assert!(f.condition_number < 1e3, "condition number {}", f.condition_number);
    for kind in [GaugeKind::AxisAtRest(Axis::Z), GaugeKind::CommonLag, GaugeKind::BarLength] {
        assert!(gauge_of(&f, kind).is_some(), "{kind:?}: {:?}", f.gauges);
    }
    let i = |id: &str| f.index(id).unwrap();
    for id in ["SQXY", "EYX2", "EXY2", "EXX1", "EYY1"] {
        assert!(f.estimable[i(id)], "{id}");
    }
    assert!(estimable_match_truth(&f, &truth) >= 5);
}

#[test]
fn three_planes_at_one_radius_fit_with_the_default_options_with_full_circles_or_220_degree_arcs() {
    use ballbar_model::Direction::{CCW, CW};
    // The paper's set-up (pivot away from the axes' references, table ball 50 mm high, a
    // 100 mm tool), R = 150 mm, 1000 mm/min; the vertical planes as full circles, then as the
    // 220° arcs above the table.
    let paper: SetUp =
        (150.0, 1000.0, [300.0, 200.0, -300.0], [0.0, 0.0, 50.0], [0.0, 0.0, -100.0]);
    for sweep in [360.0, 220.0] {
        let mut tests = Vec::new();
        for d in [CW, CCW] {
            tests.push(arc(Plane::XY, d, paper, 0.0, 360.0));
        }
        for plane in [Plane::YZ, Plane::ZX] {
            for d in [CW, CCW] {
                tests.push(arc(plane, d, paper, -20.0, sweep));
            }
        }
        let truth = lag_truth(tests, 0.2, 0.0, 50.0);
        let runs = simulate(&spec("column"), &truth, 0.0, 8).unwrap().runs;
        let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
        let design = Design::new(&model, &runs).unwrap();
        let f = fit(&design, 2).unwrap();
        // Only the common lag and the bar length are left to a choice; everything else is
        // identified and matches the truth.
        let kinds: Vec<GaugeKind> = f.gauges.iter().map(|g| g.kind).collect();
        assert_eq!(kinds, [GaugeKind::CommonLag, GaugeKind::BarLength], "{sweep}°");
        assert_eq!(ids_of(&f, &f.gauges[1].conditional), ["EXX1", "EYY1", "EZZ1"], "{sweep}°");
        let fixed = ["TX", "TY", "TZ", "BAR"];
        for k in 0..f.n_machine {
            assert_eq!(
                f.estimable[k],
                !fixed.contains(&f.parameters[k].id.as_str()),
                "{sweep}°: {}",
                f.parameters[k].id
            );
        }
        assert_eq!(estimable_match_truth(&f, &truth), f.n_machine - 4, "{sweep}°");
        let i = |id: &str| f.index(id).unwrap();
        for (a, b, want) in [("TY", "TX", 0.4), ("TZ", "TY", -0.2)] {
            let d = f.functional(&[(i(a), 1.0), (i(b), -1.0)]);
            assert!(
                d.estimable && (d.value * 1e3 - want).abs() < 3.0 * d.std_uncertainty * 1e3,
                "{sweep}°: {a} - {b} = {} ± {} ms",
                d.value * 1e3,
                d.std_uncertainty * 1e3
            );
        }
    }
}

#[test]
fn an_out_of_plane_error_seen_only_through_rounded_coordinates_is_fixed_not_fitted() {
    // The XY test with a Z column that jitters by its last digit (±1e-6 mm) around the pivot:
    // the straightness of X and Y toward Z then have columns at 2e-8 of their size, which,
    // scaled to unit norm, looked as well determined as any other, took ~1e4 mm and made the
    // refinement diverge (4e6 mm).
    let truth = shop_floor(xy_test(0.0, 360.0));
    let mut runs = simulate(&spec("column"), &truth, 0.0, 4).unwrap().runs;
    for run in &mut runs {
        for (k, z) in run.axes[Axis::Z.index()].as_mut().unwrap().iter_mut().enumerate() {
            *z += [1e-6, -1e-6, 0.0][(k * 7) % 3];
        }
    }
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    // Z still does not move; X's and Y's errors toward Z act only through the rounding.
    assert!(gauge_of(&f, GaugeKind::AxisAtRest(Axis::Z)).is_some());
    let (_, g) = gauge_of(&f, GaugeKind::NoEffect).unwrap();
    assert_eq!(ids_of(&f, &g.parameters), ["EZX2", "EZY2"]);
    assert!(g.what.contains("rounding"), "{}", g.what);
    assert_eq!(estimable_match_truth(&f, &truth), 7);
}

#[test]
fn a_weakly_determined_combination_is_truncated_and_said_so() {
    use ballbar_model::Direction::{CCW, CW};
    // The XY circles and, in YZ, only 20° arcs: the runs determine the XY plane's errors, but
    // what only the short YZ arcs see, some combinations only with an uncertainty whose
    // displacement would leave the linear regime. Those are left out (a weak gauge) instead of
    // taking values that throw the exact chain off; the rest is unaffected.
    let mut tests = xy_test(0.0, 360.0);
    for d in [CW, CCW] {
        tests.push(arc(Plane::YZ, d, SHOP, 30.0, 20.0));
    }
    let truth = shop_floor(tests);
    let runs = simulate(&spec("column"), &truth, 0.0, 3).unwrap().runs;
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let f = fit(&design, 2).unwrap();
    let (_, w) =
        gauge_of(&f, GaugeKind::Weak).unwrap_or_else(|| panic!("a weak gauge: {:#?}", f.gauges));
    assert!(w.why.contains("second-order"), "{}", w.why);
    assert!(gauge_of(&f, GaugeKind::AxisAtRest(Axis::Z)).is_none(), "Z moves in the YZ arcs");
    for id in ["SQXY", "EYX2", "EXY2", "BX", "BY"] {
        assert!(f.estimable[f.index(id).unwrap()], "{id}");
    }
    assert!(estimable_match_truth(&f, &truth) >= 5);
}

#[test]
fn an_arc_of_a_few_degrees_that_identifies_nothing_is_an_error() {
    let mut truth = shop_floor(xy_test(0.0, 2.0));
    truth.tests.truncate(1);
    let runs = simulate(&spec("column"), &truth, 0.0, 3).unwrap().runs;
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let e = fit(&design, 2).unwrap_err();
    assert!(matches!(e, FitError::TooFewSamples { .. }), "{e}");
}

#[test]
fn the_streamed_factorisation_is_a_factor_of_the_whole_design() {
    // Runs of 5655 samples, more than one chunk of rows each (CHUNK_ROWS): the kept triangle M
    // must give ‖M x‖ = ‖A x‖ for any x (MᵀM = AᵀA), A the whole design row by row; `apply`
    // must be A's rows times x; and a right-hand side solved by regenerating and factoring the
    // rows again must give the solution from the kept `Qᵀ b` (the same R to rounding). The
    // tolerances are rounding of sums over 34,000 rows of a design of condition ~1e3: 1e-12
    // relative (seen ~1e-15).
    let runs = runs("column", 0.2, 5);
    assert!(runs.iter().all(|r| r.len() > CHUNK_ROWS));
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let fac = Factorisation::new(&design, 2).unwrap();
    let n = design.n_cols();
    let mut rng = ballbar_sim::rng::Rng::new(11);
    let mut row = vec![0.0; n];
    let mut s = RowScratch::default();
    for _ in 0..3 {
        let x: Vec<f64> = (0..n).map(|_| rng.normal() * 1e-3).collect();
        let mut ax2 = 0.0;
        for r in 0..runs.len() {
            let applied = fac.apply(r, &x).unwrap();
            for i in 0..runs[r].len() {
                design.row(r, i, &mut s, &mut row).unwrap();
                let v: f64 = row.iter().zip(&x).map(|(a, b)| a * b).sum();
                assert!((applied[i] - v).abs() <= 1e-12 * v.abs().max(1e-6), "apply {r} {i}");
                ax2 += v * v;
            }
        }
        let mx2: f64 =
            (0..n).map(|i| (0..n).map(|j| fac.m_factor[(i, j)] * x[j]).sum::<f64>().powi(2)).sum();
        assert!(
            (ax2.sqrt() - mx2.sqrt()).abs() <= 1e-12 * ax2.sqrt(),
            "‖Ax‖ {} ‖Mx‖ {}",
            ax2.sqrt(),
            mx2.sqrt()
        );
    }
    let targets: Vec<Vec<f64>> = (0..runs.len()).map(|r| fac.targets(r).to_vec()).collect();
    let (again, kept) = (fac.solve(&targets).unwrap(), fac.solve_targets());
    let scale = kept.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    for (a, b) in again.iter().zip(&kept) {
        assert!((a - b).abs() <= 1e-12 * scale, "{again:?} {kept:?}");
    }
}

/// A design that keeps its geometry has its rows kept by its factorisation, read instead of
/// generated again: the fit, a solve, `A θ` and their residual must be those of a design that
/// does not, to the last bit (the same rows through the same arithmetic); runs longer than a
/// chunk, so that the kept rows are read across chunks.
#[test]
fn kept_rows_give_the_numbers_of_rows_generated_again() {
    let runs = runs("column", 0.2, 5);
    assert!(runs.iter().all(|r| r.len() > CHUNK_ROWS));
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let plain = Design::new(&model, &runs).unwrap();
    let keeping = Design::new(&model, &runs).unwrap();
    keeping.keep_geometry();
    let (fit_p, fac_p) = fit_factored(&plain, 2).unwrap();
    let (fit_k, fac_k) = fit_factored(&keeping, 2).unwrap();
    assert!(fac_k.runs.iter().all(|f| f.kept().is_some()));
    assert!(fac_p.runs.iter().all(|f| f.kept().is_none()));
    assert_eq!(fit_p.values, fit_k.values);
    assert_eq!(fit_p.residuals, fit_k.residuals);
    assert_eq!(fit_p.std_uncertainty, fit_k.std_uncertainty);
    let rhs: Vec<Vec<f64>> = runs.iter().map(|r| r.t_s.iter().map(|t| t.sin()).collect()).collect();
    assert_eq!(fac_p.solve(&rhs).unwrap(), fac_k.solve(&rhs).unwrap());
    for r in 0..runs.len() {
        assert_eq!(fac_p.apply(r, &fit_p.values).unwrap(), fac_k.apply(r, &fit_k.values).unwrap());
    }
    assert_eq!(fac_p.first_order_residual().unwrap(), fac_k.first_order_residual().unwrap());
    // Each chunk's QR is kept with the rows (the solve above applied them), and `A θ` of
    // several θ at once, block by block over the kept rows, is each θ's alone.
    assert!(fac_k.runs.iter().all(|f| f.qrs.len() == f.b.len().div_ceil(CHUNK_ROWS)));
    assert!(fac_p.runs.iter().all(|f| f.qrs.is_empty()));
    let other: Vec<f64> = fit_p.values.iter().map(|x| 2.0 * x + 1e-3).collect();
    for r in 0..runs.len() {
        let both = fac_k.apply_many(r, &[&fit_k.values, &other]).unwrap();
        assert_eq!(both[0], fac_p.apply(r, &fit_p.values).unwrap());
        assert_eq!(both[1], fac_p.apply(r, &other).unwrap());
    }
}

/// The fit that takes up the switch search's factorisation is the fit that factors the design
/// again, to the last bit (the same design factored by the same arithmetic); a factorisation
/// of the design at other switch lags is not taken up.
#[test]
fn the_switch_searchs_factorisation_gives_the_fit_of_a_fresh_one() {
    let runs = runs("column", 0.2, 5);
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let plain = Design::new(&model, &runs).unwrap();
    plain.keep_geometry();
    let (design, switch, pre) = switch::switch_and_factor(plain, 2).unwrap();
    assert!(switch.rounds > 0);
    let pre = pre.expect("the search factored the design it returns");
    let (again, _) = fit_factored(&design, 2).unwrap();
    let (taken, _) = fit_prefactored(&design, Some(pre), 2).unwrap();
    assert_eq!(taken.values, again.values);
    assert_eq!(taken.residuals, again.residuals);
    assert_eq!(taken.std_uncertainty, again.std_uncertainty);
    assert_eq!(taken.rank, again.rank);
    // Another design's factorisation (other switch lags) is not used.
    let other = design.at_switch_lags([0.01, 0.01, 0.01, 0.0, 0.0, 0.0]);
    let wrong = Factorisation::new(&design, 2).unwrap().detach();
    let (fresh, _) = fit_factored(&other, 2).unwrap();
    let (given, _) = fit_prefactored(&other, Some(wrong), 2).unwrap();
    assert_eq!(given.values, fresh.values);
    assert_ne!(given.residuals, again.residuals);
}

/// A machine without backlash gives the switch timing nothing to go by: the first round's best
/// switch improves χ² by less than half the threshold (from the round's sums), so the search
/// stops there, not determined, the design at the commanded reversal with the commanded fit's
/// factorisation, which the fit takes up to the last bit. (A switch the runs determine goes on
/// to the fit at it: `tests/e2e/switch.rs`, and the independent set's two-feed session.)
#[test]
fn a_switch_far_from_determined_stops_after_one_round_at_the_commanded_reversal() {
    let model = Model::new(spec("column"), ModelOptions::default()).unwrap();
    let mut t = truth("column");
    t.noise_um = 0.2;
    t.paper.as_mut().unwrap().backlash_um = [0.0; 3];
    let runs = simulate(&spec("column"), &t, 0.0, 5).unwrap().runs;
    let (design, switch, pre) =
        switch::switch_and_factor(Design::new(&model, &runs).unwrap(), 2).unwrap();
    assert!(!switch.determined && switch.rounds == 1, "{switch:?}");
    assert!(switch.delta_chi2 < switch::SWITCH_DETERMINED_CHI2 / 2.0, "{switch:?}");
    assert_eq!(design.switch_lags(), [0.0; 6]);
    // The search stopped at the commanded reversal: its autocorrelation is the commanded fit's
    // (a search that went on reports it at the best switch, other lags), and the factorisation
    // handed on is of the design returned.
    let (rss, lag1) = Factorisation::new(&design, 2).unwrap().first_order_residual().unwrap();
    assert_eq!(switch.rho, lag1 / rss);
    assert_eq!(pre.as_ref().map(|p| p.shape), Some(crate::shape_of(&design)));
    let (taken, _) = fit_prefactored(&design, pre, 2).unwrap();
    let (again, _) = fit_factored(&design, 2).unwrap();
    assert_eq!(taken.values, again.values);
    assert_eq!(taken.residuals, again.residuals);
}

/// The first-order residual's sums that the factorisation keeps from its gauges' last check
/// are those of `b - A θ` at its solution, computed here from the runs' rows: to the last bit,
/// since the switch search compares them between switch lags whose residuals tie exactly.
#[test]
fn the_kept_first_order_residual_is_the_solutions_own() {
    for (machine, options) in [("column", ModelOptions::default()), ("horizontal", PAPER)] {
        let runs = runs(machine, 0.2, 11);
        let model = Model::new(spec(machine), options).unwrap();
        let design = Design::new(&model, &runs).unwrap();
        let fac = Factorisation::new(&design, 2).unwrap();
        let theta = fac.solve_targets();
        let (mut rss, mut lag1) = (0.0, 0.0);
        for r in 0..runs.len() {
            let model = fac.apply(r, &theta).unwrap();
            let e: Vec<f64> = fac.targets(r).iter().zip(&model).map(|(b, m)| b - m).collect();
            rss += e.iter().map(|x| x * x).sum::<f64>();
            lag1 += e.windows(2).map(|w| w[0] * w[1]).sum::<f64>();
        }
        // 0.2 µm of noise on ~34,000 samples: a sum of squares near 1.4e-3 mm², far from 0.
        assert!(rss > 1e-4, "{machine}: rss {rss}");
        assert_eq!(fac.first_order_residual().unwrap(), (rss, lag1), "{machine}");
    }
}

/// The gauges of a fit of `runs` on `spec` with the default model.
fn gauges_of(spec: MachineSpec, runs: &[Run]) -> Vec<gauge::Gauge> {
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    fit(&Design::new(&model, runs).unwrap(), 2).unwrap().gauges
}

#[test]
fn a_three_axis_machine_is_told_only_tests_it_can_run() {
    // The column machine's three planes as 90° arcs: no axis reverses on them, so each
    // backlash acts as a re-seated ball. The machine has no rotary axis: the advice is a path
    // over which X, Y and Z reverse, never a rotary test.
    let mut t = truth("column");
    for test in &mut t.tests {
        test.sweep_deg = 90.0;
    }
    let runs = simulate(&machines::column(), &t, 0.0, 1).unwrap().runs;
    let gauges = gauges_of(machines::column(), &runs);
    let seated = gauges
        .iter()
        .find(|g| g.kind == gauge::GaugeKind::SetUp)
        .unwrap_or_else(|| panic!("a re-seated ball among {gauges:?}"));
    assert_eq!(
        seated.separate_by,
        "a full circle, or an arc across the reversals of X, Y, Z: over it the axes move both ways and over more of their travel, where these terms are no longer a constant"
    );
    for g in &gauges {
        assert!(!g.separate_by.contains("rotary"), "{}: {}", g.what, g.separate_by);
    }
}

#[test]
fn a_five_axis_machine_is_told_to_turn_its_own_rotary_axis() {
    // The A/C trunnion's planar tests (A and C held at 0): the advice for an axis at rest turns
    // that axis, and for terms seen only as a re-seated ball it names the tests by axis: a
    // rotary test that turns C for C's location error, a path across X's reversals for X's
    // backlash.
    let spec = ballbar_machine_chain_file::parse(include_str!(
        "../../../fixtures/machines/five-axis-ac-trunnion.ron"
    ))
    .unwrap();
    let t: Truth =
        ron::from_str(include_str!("../../../fixtures/machines/five-axis-ac-trunnion.truth.ron"))
            .unwrap();
    let runs = simulate(&spec, &t, 0.0, 1).unwrap().runs;
    let gauges = gauges_of(spec.clone(), &runs);
    let at_rest = |a: Axis| {
        gauges
            .iter()
            .find(|g| g.kind == gauge::GaugeKind::AxisAtRest(a))
            .unwrap_or_else(|| panic!("{a} at rest in {gauges:?}"))
    };
    assert_eq!(at_rest(Axis::C).separate_by, "a test that turns C");
    assert_eq!(at_rest(Axis::A).separate_by, "a test that turns A");
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    let design = Design::new(&model, &runs).unwrap();
    let index = |id: &str| design.parameters.iter().position(|p| p.id == id).unwrap();
    assert_eq!(
        gauge::seated_separation(&design, &[index("EX0C"), index("BX")]),
        "a rotary test that turns C (the bar radial at two heights, tangential, axial); a full circle, or an arc across the reversals of X: over it the axes move both ways and over more of their travel, where these terms are no longer a constant"
    );
}

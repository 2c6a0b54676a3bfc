//! The vendor's own computation on a `.b5r` file's readings: a small least-squares fit in the
//! vendor's frame (angle θ from +A towards +B, reading = bar length minus the calibrated
//! length), with its term set, separate from the machine model. It gives `ours_as_vendor`
//! (`shared/spec/cli.md`) and, on the samples placed another way, how far each convention
//! moves a feature.
//!
//! # The term set
//! Per run `k`: a radius `c₀ₖ` and a centre offset `(aₖ, bₖ)`, the reading being the exact
//! length of a bar whose pivot is off the circle's centre by `(aₖ, bₖ)`:
//!
//! ```text
//! ΔR(θ) = c₀ₖ + aₖ cos θ + bₖ sin θ + (e² − (e·û)²) / (2R) + Σ terms
//! ```
//!
//! with `e = (aₖ, bₖ)`, `û = (cos θ, sin θ)`. The second-order eccentricity term is what makes
//! the shared real file's squareness the vendor's: with its 56 µm set-up offset it adds
//! `e² sin 2φ / (4R)` = 0.014 µm to the sin 2θ coefficient, 0.56 µm/m of squareness, and the
//! vendor's own fitted model (`SIMULATION AF_SIMULATED_READINGS_CCW/_CW`), fitted with this
//! term set, gives −10.32 µm/m against its printed −10.3 (−9.76 without it). It is applied by
//! fixed-point iteration on the fitted centre ([`ECCENTRICITY_ITERATIONS`]).
//!
//! The common terms (both runs), [`TermSet`]:
//! - full circle: `cos 2θ`, `sin 2θ` (per-axis scales `s_A`, `s_B`: `R (s_A − s_B)/2 cos 2θ`;
//!   squareness α: `−α R/2 sin 2θ`); `cos 3θ`, `sin 3θ` (straightness: `AF_STRAIGHTNESS_A` =
//!   4 × the sin 3θ coefficient, `_B` = −4 × the cos 3θ coefficient); the direction-odd
//!   `d sin 2θ`, `d cos 2θ` (`d` = +1 CCW in the (A, B) frame: lag difference τ_A − τ_B =
//!   2 m / V for the `d sin 2θ` coefficient m; only with runs in both directions); the backlash
//!   steps `cos θ sgn v_A` and
//!   `sin θ sgn v_B` (backlash = −2 × the coefficient: an axis that lags its direction by b/2).
//! - partial arc (`vendor-b5r.md`): one scale common to both axes (no `cos 2θ`: the vendor's
//!   `AF_SCALE_ERROR_A/B` are equal there), `sin 2θ` and the 3θ pair; no reversal terms.
//!
//! The global scale is the mean of the runs' `c₀` (the readings are relative to the calibrated
//! length, so a radius error is a scale: `(s_A + s_B)/2 · R`).
//!
//! What this does not reproduce on the shared real file: the vendor's squareness to its
//! printed digits (−9.95 against −10.3), its scales (41.0 and 9.9 against 40.4 and 10.3 ppm),
//! scale mismatch (3.11 against 3.0) and B straightness (1.06 against 1.0). Its model trace
//! has its squareness in this term set (−10.32; not its scales: 39.7 and 10.5 ppm); its
//! reversal spikes, lateral play and cyclic error are not in this term set.
//!
//! # What the vendor's fit is not (measured on the shared file, so as not to redo it)
//! Numbers are this fit's squareness on the readings (µm/m) unless said; the vendor prints
//! −10.3, and the readings' own value is −9.95.
//! - The placement is the vendor's: its `AF_CALCULATED_FEEDRATE` (1493.2) is 2πR·f·60/n =
//!   1493.16 with n the window's samples (n − 1 gives 1494.11; `ballbar-io`'s b5r tests check
//!   it). The squareness moves 0.96 µm/m per sample of that divisor (n − 1: −8.99, n + 1:
//!   −10.91): the −10.3 needs n + 0.37, a feed of 1492.8 where the vendor prints 1493.2, and
//!   scales of 40.95 and 9.53 ppm. A shift of both runs by up to ±3 samples, or of the window
//!   by one sample, moves it by less than 0.03; a shift of one run against the other by 3
//!   samples would (0.12 µm/m a sample), but the trace lines up with the readings within half
//!   a sample in both runs.
//! - The samples: a moving average of 3 to 15 samples (`AVERAGING`) leaves it (within 0.01);
//!   so do a common CW/CCW profile (−9.95) and angle grids of 360 to 1500 points (−9.89 to
//!   −9.97). Decimation by 2 to 10 scatters it between −9.88 and −10.37 (the −10.37, with
//!   scales 40.4 and 10.1, is one phase of a decimation by 5; its other phases give −9.96 and
//!   −10.08): the readings' own noise in this coefficient. Over-shoot samples added move it
//!   away (100 at each end: −7.8).
//! - The columns: lateral play (sin θ sgn v_A, cos θ sgn v_B), cyclic error at the file's
//!   pitches (16 and 18 mm, per axis and direction), a triangle per reversal (half-width 0.5°
//!   to 5°), the trace's own shapes within 8 to 25 samples of each reversal, a radius or centre
//!   drift in time common to the runs, one centre (or one circle) for both runs instead of one
//!   per run: −9.85 to −9.95 with every set. The parametric shapes are symmetric about the
//!   reversals or odd in the direction and hold no direction-even sin 2θ: with both runs, the
//!   common sin 2θ stays the readings' own. They move the scales (40.4 to 41.1, 8.9 to 9.9 ppm)
//!   and the B straightness (0.91 to 1.07) without reproducing the three together.
//! - The estimator: Huber and bisquare reweighting (scale 0.1 to 0.5 µm: −8.0 to −9.88) and
//!   an L1 fit (−9.51) move it away from the vendor's.
//! - The residual readings − trace has, in both runs alike, a mean of +0.020 and +0.018 µm, a
//!   sin θ content of +0.018 and +0.021 µm, cos 2θ +0.048 and +0.049 µm, sin 2θ −0.010 and
//!   −0.008 µm; none of them vanishes over the samples away from the reversals (2° to 30°),
//!   away from the window's ends (5 to 40 samples) or where it is below 0.3 to 1.5 µm. A least
//!   squares with a free radius per run leaves a zero mean on the samples it fits, so the
//!   trace is no ordinary least squares of any subset of these readings with a radius per run;
//!   either the vendor fits other values than `READINGS` (a correction common to both
//!   directions, smooth in θ) or the trace is not the model it took its printed values from.
//!   Binned by 6° that residual is one profile in both runs, up to ±0.4 µm (harmonics 4 to 8
//!   of about 0.1 µm each): waviness the vendor's model leaves, whose low harmonics its
//!   estimate does not take up as a least squares would. Its RMS over the window, 0.246 µm,
//!   is consistent with the printed `RMS` (0.2).
//! - The reversal spikes from its model trace: the trace minus its smooth part (this term set
//!   with the lateral-play columns, fitted to the trace away from ±20° of the four reversals;
//!   0.10 µm RMS left there), its peak within −1° to +4° of each reversal in the direction of
//!   travel, CCW / CW: 2.71 / 2.28 µm at θ = 0° (A's positive end), 5.10 / 3.44 at 180° (A's
//!   negative end), 1.56 / 2.26 at 90° (B's positive end), 2.39 / 3.06 at 270°. The mean of
//!   the two directions gives A_NEG 4.27 (printed 4.2) but A_POS 2.50 where the vendor prints
//!   −0.2, B_POS 1.91 (2.7), B_NEG 2.72 (3.2); the peak above the level 3° to 10° before the
//!   reversal, or above the level 5° to 12° after it, does not reproduce them either (A_POS
//!   2.42 / 1.45 and 1.94 / 1.57). The spikes are one to three samples (0.23° each) wide,
//!   so their height depends on the window and the baseline, which the file does not give;
//!   the readings' own peaks there are larger still (5.1 µm at θ = 0° in both runs). Which
//!   baseline or shape makes the vendor's −0.2 at A's positive end is not found: the spikes,
//!   the lateral play and the cyclic error (whose printed sizes are near the readings' noise)
//!   are not reproduced, and neither is the ranking's share and rank, which need every one.

use ballbar_fit::FitError;
use faer::Mat;

/// Iterations of the second-order eccentricity term: it is `e²/(2R)` ≈ 3e-5 mm on the shared
/// file and its change with the centre's is `e/R` ≈ 1e-3 of that per iteration, so after three
/// the term is fixed to 1e-14 mm, far below the readings' 1e-5 mm resolution.
pub const ECCENTRICITY_ITERATIONS: usize = 3;

/// One run's samples: the angle of each in the (A, B) frame (radians) and its reading (mm).
#[derive(Clone, Debug)]
pub struct Samples<'a> {
    /// θ of each sample, rad, from +A towards +B.
    pub theta: Vec<f64>,
    /// The readings, mm.
    pub dr_mm: &'a [f64],
}

/// Which common terms the fit holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TermSet {
    /// A scale per axis (`cos 2θ`); false: one scale common to both axes.
    pub per_axis_scales: bool,
    /// The 3θ pair.
    pub three_theta: bool,
    /// The direction-odd 2θ pair and the backlash steps.
    pub reversals: bool,
}

impl TermSet {
    /// The vendor's term set for a full circle (`full`) or a partial arc.
    pub fn vendor(full: bool) -> TermSet {
        TermSet { per_axis_scales: full, three_theta: true, reversals: full }
    }

    /// In words, for notes.
    pub fn describe(self) -> String {
        format!(
            "{}{}{}",
            if self.per_axis_scales { "a scale per axis" } else { "one scale common to both axes" },
            if self.three_theta { ", the 3θ term" } else { ", no 3θ term" },
            if self.reversals { ", backlash and servo terms" } else { "" }
        )
    }
}

/// The vendor's features as this fit gives them, in the vendor's units and signs.
#[derive(Clone, Debug, PartialEq)]
pub struct VendorFit {
    /// `AF_CENTRE_OFFSET_A/B`, µm: the mean of the runs' centre offsets.
    pub centre_um: [f64; 2],
    /// The centre offset of each run, µm.
    pub run_centres_um: Vec<[f64; 2]>,
    /// `AF_BEST_RADIUS`, mm: nominal R plus the mean of the runs' `c₀`.
    pub best_radius_mm: f64,
    /// `AF_GLOBAL_SCALE`, µm.
    pub global_scale_um: f64,
    /// `AF_SCALE_ERROR_A/B`, ppm.
    pub scale_ppm: [f64; 2],
    /// `AF_SCALE_MISMATCH`, µm (`None` without per-axis scales).
    pub scale_mismatch_um: Option<f64>,
    /// `AF_SQUARENESS`, µm/m.
    pub squareness_um_per_m: f64,
    /// `AF_STRAIGHTNESS_A/B`, µm (`None` without the 3θ pair).
    pub straightness_um: Option<[f64; 2]>,
    /// `AF_SERVO_MISMATCH`, ms: τ_A − τ_B (`None` without the reversal terms or without runs
    /// in both directions).
    pub servo_mismatch_ms: Option<f64>,
    /// `AF_BACKLASH_A/B_GLOBAL`, µm (`None` without the reversal terms).
    pub backlash_um: Option<[f64; 2]>,
    /// RMS of the readings minus this fit, µm.
    pub rms_um: f64,
    /// Columns, and the rank the fit found.
    pub columns: usize,
    /// See `columns`.
    pub rank: usize,
    /// Condition number of the column-scaled design.
    pub condition: f64,
}

/// The fit of `runs` at nominal radius `r_mm` and feed `feed_mm_per_min` with `terms`.
pub fn fit(
    runs: &[Samples],
    r_mm: f64,
    feed_mm_per_min: f64,
    terms: TermSet,
) -> Result<VendorFit, FitError> {
    let nruns = runs.len();
    let m: usize = runs.iter().map(|r| r.theta.len()).sum();
    // Column layout: 3 per run, then the common terms.
    let mut common: Vec<&str> = Vec::new();
    if terms.per_axis_scales {
        common.push("cos2");
    }
    common.push("sin2");
    if terms.three_theta {
        common.extend(["cos3", "sin3"]);
    }
    // The direction-odd pair needs both directions: in runs of one direction it is the
    // direction-even pair itself.
    let both = runs.iter().any(|r| direction(&r.theta) > 0.0)
        && runs.iter().any(|r| direction(&r.theta) < 0.0);
    if terms.reversals && both {
        common.extend(["dsin2", "dcos2"]);
    }
    if terms.reversals {
        common.extend(["blA", "blB"]);
    }
    let ncols = 3 * nruns + common.len();
    let mut a = Mat::<f64>::zeros(m, ncols);
    let mut row = 0;
    for (k, run) in runs.iter().enumerate() {
        let d = direction(&run.theta);
        for &t in &run.theta {
            let (s, c) = t.sin_cos();
            a[(row, 3 * k)] = 1.0;
            a[(row, 3 * k + 1)] = c;
            a[(row, 3 * k + 2)] = s;
            for (j, name) in common.iter().enumerate() {
                a[(row, 3 * nruns + j)] = match *name {
                    "cos2" => (2.0 * t).cos(),
                    "sin2" => (2.0 * t).sin(),
                    "cos3" => (3.0 * t).cos(),
                    "sin3" => (3.0 * t).sin(),
                    "dsin2" => d * (2.0 * t).sin(),
                    "dcos2" => d * (2.0 * t).cos(),
                    // v_A = −d R ω sin θ, v_B = d R ω cos θ.
                    "blA" => c * sign(-d * s),
                    _ => s * sign(d * c),
                };
            }
            row += 1;
        }
    }
    let y: Vec<f64> = runs.iter().flat_map(|r| r.dr_mm.iter().copied()).collect();
    let mut target = y.clone();
    let mut x = vec![0.0; ncols];
    let mut rank = 0;
    for _ in 0..=ECCENTRICITY_ITERATIONS {
        let (sol, r) = ballbar_fit::lstsq_pivoted(a.as_ref(), &target)?;
        x = sol;
        rank = r;
        // The reading less the second-order eccentricity of the fitted centre.
        let mut i = 0;
        for (k, run) in runs.iter().enumerate() {
            let (ea, eb) = (x[3 * k + 1], x[3 * k + 2]);
            for &t in &run.theta {
                let eu = ea * t.cos() + eb * t.sin();
                target[i] = y[i] - (ea * ea + eb * eb - eu * eu) / (2.0 * r_mm);
                i += 1;
            }
        }
    }
    let residual: Vec<f64> =
        (0..m).map(|i| target[i] - (0..ncols).map(|j| a[(i, j)] * x[j]).sum::<f64>()).collect();
    let coef = |name: &str| common.iter().position(|c| *c == name).map(|j| x[3 * nruns + j] * 1e3);
    let mean = |f: &dyn Fn(usize) -> f64| (0..nruns).map(f).sum::<f64>() / nruns as f64;
    let global = mean(&|k| x[3 * k]) * 1e3;
    let c2 = coef("cos2").unwrap_or(0.0);
    let s2 = coef("sin2").unwrap_or(0.0);
    // µm over mm × 1e3: ppm and µm/m.
    let per_mm = 1e3 / r_mm;
    let v_mm_per_s = feed_mm_per_min / 60.0;
    let fit = VendorFit {
        centre_um: [mean(&|k| x[3 * k + 1]) * 1e3, mean(&|k| x[3 * k + 2]) * 1e3],
        run_centres_um: (0..nruns).map(|k| [x[3 * k + 1] * 1e3, x[3 * k + 2] * 1e3]).collect(),
        best_radius_mm: r_mm + global * 1e-3,
        global_scale_um: global,
        scale_ppm: [(global + c2) * per_mm, (global - c2) * per_mm],
        scale_mismatch_um: coef("cos2").map(|c| 4.0 * c),
        squareness_um_per_m: -2.0 * s2 * per_mm,
        straightness_um: match (coef("sin3"), coef("cos3")) {
            (Some(s3), Some(c3)) => Some([4.0 * s3, -4.0 * c3]),
            _ => None,
        },
        servo_mismatch_ms: coef("dsin2").map(|m| 2.0 * m / v_mm_per_s),
        backlash_um: match (coef("blA"), coef("blB")) {
            (Some(ba), Some(bb)) => Some([-2.0 * ba, -2.0 * bb]),
            _ => None,
        },
        rms_um: ballbar_fit::metrics::rms(&residual) * 1e3,
        columns: ncols,
        rank,
        condition: condition(&a),
    };
    Ok(fit)
}

/// +1 where the angles increase (CCW in the (A, B) frame), −1 where they decrease.
fn direction(theta: &[f64]) -> f64 {
    match (theta.first(), theta.last()) {
        (Some(a), Some(b)) if b < a => -1.0,
        _ => 1.0,
    }
}

fn sign(x: f64) -> f64 {
    if x >= 0.0 { 1.0 } else { -1.0 }
}

/// The condition number of the design with its columns scaled to unit norm (the scaling the
/// rank decision uses).
fn condition(a: &Mat<f64>) -> f64 {
    let n = a.ncols();
    let norms: Vec<f64> =
        (0..n).map(|j| a.col(j).iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300)).collect();
    let scaled = Mat::<f64>::from_fn(a.nrows(), n, |i, j| a[(i, j)] / norms[j]);
    let svd = scaled.as_ref().thin_svd();
    ballbar_fit::clear_upper_registers();
    match svd {
        Ok(svd) => {
            let s = svd.S().column_vector();
            let (mut hi, mut lo) = (0.0f64, f64::INFINITY);
            for i in 0..s.nrows() {
                hi = hi.max(s[i]);
                lo = lo.min(s[i]);
            }
            hi / lo
        }
        Err(_) => f64::INFINITY,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One run, CCW: no servo term (it would be the squareness's own column), the squareness,
    /// scales and backlash by hand. The readings: a centre (20, −10) µm off, exactly; scales
    /// 30 and 10 ppm, squareness 20 µm/m, backlash of A 2 µm (ΔA = −(b/2) sgn v_A), at R = 100
    /// mm, on 3600 samples over the turn.
    #[test]
    fn one_direction_fits_without_the_servo_term_to_the_hand_values() {
        let (r, n) = (100.0f64, 3600);
        let theta: Vec<f64> =
            (0..n).map(|i| (i as f64 + 0.5) / n as f64 * std::f64::consts::TAU).collect();
        let y: Vec<f64> = theta
            .iter()
            .map(|&t| {
                let (s, c) = t.sin_cos();
                let ecc = (r * c + 0.020).hypot(r * s - 0.010) - r;
                let v_a = -s;
                ecc + 30e-6 * r * c * c + 10e-6 * r * s * s
                    - 20e-6 * r * s * c
                    - 0.001 * c * if v_a >= 0.0 { 1.0 } else { -1.0 }
            })
            .collect();
        let f = fit(&[Samples { theta, dr_mm: &y }], r, 1000.0, TermSet::vendor(true)).unwrap();
        assert_eq!((f.rank, f.columns, f.servo_mismatch_ms), (9, 9, None));
        // Exact readings: to the second order's neglected e³/R² ≈ 1e-11 mm, far inside 1e-6.
        assert!((f.squareness_um_per_m - 20.0).abs() < 1e-6, "{f:?}");
        assert!((f.scale_ppm[0] - 30.0).abs() < 1e-6 && (f.scale_ppm[1] - 10.0).abs() < 1e-6);
        let [ba, bb] = f.backlash_um.unwrap();
        assert!((ba - 2.0).abs() < 1e-6 && bb.abs() < 1e-6, "{f:?}");
        assert!((f.centre_um[0] - 20.0).abs() < 1e-6 && (f.centre_um[1] + 10.0).abs() < 1e-6);
    }

    /// The vendor's own fitted model of the shared real file (`SIMULATION
    /// AF_SIMULATED_READINGS_CCW/_CW`, mm, on its window) fitted with this term set: the
    /// strongest evidence of the term set, since the trace is the vendor's model itself.
    #[test]
    fn the_vendors_model_trace_has_its_squareness_in_this_term_set() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../../shared/data/real/d2-xy-50mm-1500.b5r");
        if !path.is_file() {
            use std::io::Write as _;
            let _ = std::io::stderr().lock().write_all(
                format!("\nSKIPPED: {} is not there (the shared real test file)\n", path.display())
                    .as_bytes(),
            );
            return;
        }
        let test = ballbar_io::b5r::read_b5r(&path, &Default::default()).expect("reads");
        let diag = test.diagnostics().expect("the vendor's diagnostics");
        let traces: Vec<Vec<f64>> = test
            .runs
            .iter()
            .map(|run| {
                let dir = run
                    .header
                    .extra
                    .iter()
                    .find(|(k, _)| k == "vendor_direction")
                    .map(|(_, v)| v.clone())
                    .expect("the file's direction");
                let name = format!("AF_SIMULATED_READINGS_{dir}");
                diag.simulations.iter().find(|(n, _)| *n == name).expect("a trace").1.clone()
            })
            .collect();
        let samples: Vec<Samples> = test
            .vendor_angles_deg
            .iter()
            .zip(&traces)
            .map(|(deg, y)| Samples {
                theta: deg.iter().map(|d| d.to_radians()).collect(),
                dr_mm: y,
            })
            .collect();
        let f = fit(&samples, 50.0, 1500.0, TermSet::vendor(true)).expect("fits");
        let vendor = |name: &str| diag.feature(name).expect(name).value;
        // Within half the vendor's printed step (0.05 µm/m, µm): −10.32 against its −10.3
        // (a plain circle's harmonics give −9.76: the 56 µm set-up offset's second order);
        // the straightness of A, the centre and the radius likewise.
        assert!((f.squareness_um_per_m - vendor("AF_SQUARENESS")).abs() <= 0.05, "{f:?}");
        let [sa, _] = f.straightness_um.expect("full circle");
        assert!((sa - vendor("AF_STRAIGHTNESS_A")).abs() <= 0.05, "{f:?}");
        assert!((f.centre_um[0] - vendor("AF_CENTRE_OFFSET_A")).abs() <= 0.05, "{f:?}");
        assert!((f.centre_um[1] - vendor("AF_CENTRE_OFFSET_B")).abs() <= 0.05, "{f:?}");
        assert!((f.best_radius_mm - vendor("AF_BEST_RADIUS")).abs() <= 0.00005, "{f:?}");
        assert_eq!((f.rank, f.columns), (14, 14));
        // The rest of the vendor's model (spikes, lateral play, cyclic error) is outside this
        // term set: its scales come out 39.7 and 10.5 ppm against the 40.4 and 10.3 the vendor
        // prints, the B straightness 1.09 against 1.0 (its reversal terms hold 2θ and 3θ
        // content); the trace is left with 0.30 µm RMS.
        assert!(f.rms_um > 0.2 && f.rms_um < 0.4, "{f:?}");
    }
}

//! The vendor's reversal spikes (`AF_REVERSAL_SPIKES_{A,B}_{POS,NEG}`) read off a `.b5r`
//! file's readings by a rule inferred from its model trace of the shared real file
//! ([`crate::vendor_fit`]'s module documentation, "The vendor's reversal model", gives the
//! evidence). The rule's local baseline (a cubic and a step over the trace's window) was chosen
//! on that file among 18 variants, the one that gives B's printed spikes on its readings; the
//! same rule on the vendor's own noise-free trace gives them 0.08 µm low, so it is near the
//! vendor's rule, not the rule itself, and A's reversals hold a shape it does not model.
//!
//! # The rule
//! Around each reversal of an axis (θ a multiple of 90° in the (A, B) frame, the samples placed
//! at the programmed feed: the trace's spikes start there, not on the vendor's even spread),
//! the readings of a window of [`HALF_WINDOW_SAMPLES`] samples either side are fitted by least squares
//! with a cubic in the sample index (the circle's own curvature over the window), a step at the
//! reversal and the spike's shape [`shape`] starting at it; the spike is the shape's
//! coefficient, µm (positive: the bar longer). A run gives one value per reversal whose window
//! holds the whole shape and [`MIN_BEFORE_SAMPLES`] samples before the reversal; the feature is the mean
//! of the runs' values at that reversal (POS: the axis's positive end).
//!
//! What the file cannot tell: whether the shape's rise ([`RISE_SAMPLES`]) and the window are
//! counts of samples, a time or an arc (the shared file has one rate, feed and radius: 3.5
//! samples are 28 ms, 0.80° and 0.70 mm of path there).

use ballbar_fit::FitError;
use faer::Mat;

use crate::vendor_fit::Samples;

/// The spike's rise from the reversal to its peak, samples: the four spikes of B in the
/// vendor's model trace of the shared file rise over 3.44 to 3.58 samples (best fits of the
/// shape with a cubic and a step to each; mean 3.5).
pub const RISE_SAMPLES: f64 = 3.5;

/// Samples either side of the reversal in the fit: the vendor's model trace of the shared file
/// is a separate least squares of the readings over windows of 79 samples at fixed samples
/// about each reversal (the readings less the trace sum to −0.02 to 0.04 µm over each such
/// window and average −0.12 µm a sample just outside it), so 39 either side of the
/// (fractional) reversal: 78 or 79 samples.
pub const HALF_WINDOW_SAMPLES: usize = 39;

/// Samples a window must hold before the reversal: three determine the level the step leaves
/// (with the cubic's four columns fitted over the whole window).
pub const MIN_BEFORE_SAMPLES: f64 = 3.0;

/// The spike's shape at `x` samples after the reversal, peak 1: a linear rise over
/// [`RISE_SAMPLES`] (T), a fall at the same rate over 0.75 T to a quarter, then at a third of
/// that rate over 0.75 T to 0 (the vendor's model trace of the shared file: B's four spikes
/// fall at their rise's rate for 2.6 samples and at a third of it for 2.6 more, to 0.01 µm).
pub fn shape(x: f64) -> f64 {
    let t = RISE_SAMPLES;
    if x <= 0.0 {
        0.0
    } else if x <= t {
        x / t
    } else if x <= 1.75 * t {
        1.0 - (x - t) / t
    } else if x <= 2.5 * t {
        0.25 - (x - 1.75 * t) / (3.0 * t)
    } else {
        0.0
    }
}

/// The samples after the reversal over which [`shape`] is not 0.
pub const SPAN_SAMPLES: f64 = 2.5 * RISE_SAMPLES;

/// A run's samples placed at the programmed feed (`feed_mm_per_min` on a circle of `r_mm` at
/// `rate_hz`), centred on the vendor's placement `vendor_deg` (its even spread over the arc):
/// radians.
pub fn feed_placement(
    vendor_deg: &[f64],
    r_mm: f64,
    feed_mm_per_min: f64,
    rate_hz: f64,
) -> Vec<f64> {
    let n = vendor_deg.len();
    if n < 2 {
        return vendor_deg.iter().map(|d| d.to_radians()).collect();
    }
    let even = (vendor_deg[n - 1] - vendor_deg[0]).abs() / (n - 1) as f64;
    let step = (feed_mm_per_min / 60.0 / r_mm).to_degrees() / rate_hz;
    let mid = vendor_deg.iter().sum::<f64>() / n as f64;
    vendor_deg.iter().map(|d| (mid + (d - mid) * step / even).to_radians()).collect()
}

/// One reversal's spike in one run.
#[derive(Clone, Debug, PartialEq)]
pub struct Spike {
    /// The run's index.
    pub run: usize,
    /// 0: A, 1: B.
    pub axis: usize,
    /// The reversal at the axis's positive end.
    pub pos: bool,
    /// Where the reversal falls, in samples of the run (fractional).
    pub at_sample: f64,
    /// The spike's height, µm.
    pub height_um: f64,
    /// The window's samples.
    pub samples: usize,
}

/// Each reversal's spike in each of `runs` (the samples placed at the programmed feed).
pub fn spikes(runs: &[Samples]) -> Result<Vec<Spike>, FitError> {
    use std::f64::consts::FRAC_PI_2;
    let mut out = Vec::new();
    for (k, run) in runs.iter().enumerate() {
        let n = run.theta.len();
        let (Some(&t0), Some(&t1)) = (run.theta.first(), run.theta.get(1)) else { continue };
        let step = t1 - t0;
        // Evenly spaced finite angles only (the reader's): an infinite one would make the
        // reversals' range endless.
        if step == 0.0 || !step.is_finite() || n != run.dr_mm.len() || !run.theta[n - 1].is_finite()
        {
            continue;
        }
        // Two reversals closer than a window and a spike: each window would hold the other's
        // spike, which the fit does not model.
        if FRAC_PI_2 / step.abs() < HALF_WINDOW_SAMPLES as f64 + SPAN_SAMPLES {
            continue;
        }
        let last = run.theta[n - 1];
        let (lo_t, hi_t) = (t0.min(last), t0.max(last));
        let (m0, m1) = ((lo_t / FRAC_PI_2).ceil() as i64, (hi_t / FRAC_PI_2).floor() as i64);
        for m in m0..=m1 {
            let p = (m as f64 * FRAC_PI_2 - t0) / step;
            let h = HALF_WINDOW_SAMPLES as f64;
            let lo = (p - h).ceil().max(0.0) as usize;
            let hi = ((p + h).floor() as usize).min(n - 1);
            if p - (lo as f64) < MIN_BEFORE_SAMPLES || (hi as f64) - p < SPAN_SAMPLES {
                continue;
            }
            let rows = hi - lo + 1;
            let a = Mat::<f64>::from_fn(rows, 6, |i, j| {
                let x = (lo + i) as f64 - p;
                let u = x / h;
                match j {
                    0 => 1.0,
                    1 => u,
                    2 => u * u,
                    3 => u * u * u,
                    4 => {
                        if x >= 0.0 {
                            1.0
                        } else {
                            0.0
                        }
                    }
                    _ => shape(x),
                }
            });
            let y: Vec<f64> = run.dr_mm[lo..=hi].to_vec();
            let (x, rank) = ballbar_fit::lstsq_pivoted(a.as_ref(), &y)?;
            if rank < 6 {
                continue;
            }
            let q = m.rem_euclid(4);
            out.push(Spike {
                run: k,
                axis: (q % 2) as usize,
                pos: q < 2,
                at_sample: p,
                height_um: x[5] * 1e3,
                samples: rows,
            });
        }
    }
    Ok(out)
}

/// The spike of `axis` at its `pos` end: the mean of the runs' values there, and how many.
pub fn feature(spikes: &[Spike], axis: usize, pos: bool) -> Option<(f64, usize)> {
    let v: Vec<f64> =
        spikes.iter().filter(|s| s.axis == axis && s.pos == pos).map(|s| s.height_um).collect();
    if v.is_empty() {
        return None;
    }
    Some((v.iter().sum::<f64>() / v.len() as f64, v.len()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shape at its corners, by hand: 0 at the reversal, 1 at T = 3.5, a quarter at
    /// 1.75 T = 6.125, 0 at 2.5 T = 8.75; half-way up at 1.75, and between the corners on the
    /// lines joining them.
    #[test]
    fn the_shape_by_hand() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(shape(-1.0), 0.0) && close(shape(0.0), 0.0));
        assert!(close(shape(1.75), 0.5) && close(shape(3.5), 1.0));
        // Half-way down the steep fall: (1 + 0.25)/2.
        assert!(close(shape((3.5 + 6.125) / 2.0), 0.625));
        assert!(close(shape(6.125), 0.25));
        // Half-way down the slow fall.
        assert!(close(shape((6.125 + 8.75) / 2.0), 0.125));
        assert!(close(shape(8.75), 0.0) && close(shape(20.0), 0.0));
    }

    /// Readings of a cubic, steps and spikes of known heights at the reversals (CCW from 180°,
    /// 1578 samples a turn, the reversals at fractional samples): each spike comes back exactly
    /// (to 1e-9 µm: the least squares of exact columns, rounded only in f64), and a run that
    /// starts on a reversal gives none there (no samples before it).
    #[test]
    fn known_spikes_come_back_exactly() {
        use std::f64::consts::PI;
        let n = 1578;
        let step = 2.0 * PI / n as f64;
        // Start 1.3 samples before 180°, so each reversal falls between samples.
        let theta: Vec<f64> = (0..n).map(|i| PI - 1.3 * step + i as f64 * step).collect();
        // (angle, height µm, step µm): 270° B NEG, 0° A POS, 90° B POS, 180° A NEG.
        let want = [(1.5 * PI, 3.2, 0.4), (2.0 * PI, -0.2, -1.0), (2.5 * PI, 2.7, 0.1)];
        let y: Vec<f64> = theta
            .iter()
            .map(|&t| {
                let mut v = 0.001 + 0.002 * (t - PI) - 0.0005 * (t - PI).powi(3);
                for (at, h, s) in want {
                    let x = (t - at) / step;
                    v += 1e-3 * (h * shape(x) + if x >= 0.0 { s } else { 0.0 });
                }
                v
            })
            .collect();
        let got = spikes(&[Samples { theta, dr_mm: &y }]).expect("fits");
        // 180° at the start (1.3 samples before it: fewer than MIN_BEFORE_SAMPLES) and at the end (no
        // room for the shape) give none.
        assert_eq!(got.len(), 3, "{got:?}");
        for (s, (_, h, _)) in got.iter().zip(want) {
            assert!((s.height_um - h).abs() < 1e-9, "{s:?} against {h}");
        }
        let keys: Vec<(usize, bool)> = got.iter().map(|s| (s.axis, s.pos)).collect();
        assert_eq!(keys, [(1, false), (0, true), (1, true)]);
        assert!((got[0].at_sample - (1.3 + n as f64 / 4.0)).abs() < 1e-9, "{:?}", got[0]);
        assert_eq!(feature(&got, 1, true), Some((got[2].height_um, 1)));
        assert_eq!(feature(&got, 0, false), None);
    }

    /// A CW run reaches each reversal from the other side: the same spikes, read with the
    /// angles decreasing, come back as well.
    #[test]
    fn a_cw_run_gives_its_spikes_too() {
        use std::f64::consts::PI;
        let n = 1578;
        let step = 2.0 * PI / n as f64;
        let theta: Vec<f64> = (0..n).map(|i| PI + 1.3 * step - i as f64 * step).collect();
        let y: Vec<f64> = theta
            .iter()
            .map(|&t| {
                // B POS at 90°, reached 1.3 + 394.5 samples in.
                let x = (PI / 2.0 - t) / step;
                1e-3 * 2.5 * shape(x)
            })
            .collect();
        let got = spikes(&[Samples { theta, dr_mm: &y }]).expect("fits");
        let (h, count) = feature(&got, 1, true).expect("B POS");
        assert_eq!(count, 1);
        assert!((h - 2.5).abs() < 1e-9, "{got:?}");
        for s in got.iter().filter(|s| !(s.axis == 1 && s.pos)) {
            assert!(s.height_um.abs() < 1e-9, "{s:?}");
        }
    }

    /// The runs of the shared real file, readings or the vendor's model trace, on the
    /// programmed feed's placement.
    fn shared_spikes(trace: bool) -> Option<Vec<Spike>> {
        let test = crate::vendor_fit::tests::shared_file()?;
        let diag = test.diagnostics().expect("the vendor's diagnostics");
        let ys: Vec<&[f64]> = if trace {
            crate::vendor_fit::model_traces(&test.runs, diag).expect("a trace per run")
        } else {
            test.runs.iter().map(|r| r.dr_mm.as_slice()).collect()
        };
        let runs: Vec<Samples> = test
            .vendor_angles_deg
            .iter()
            .zip(&test.runs)
            .zip(ys)
            .map(|((deg, run), y)| Samples {
                theta: feed_placement(
                    deg,
                    run.header.radius_mm,
                    run.header.feed_mm_per_min,
                    run.sample_rate_hz().expect("a rate"),
                ),
                dr_mm: y,
            })
            .collect();
        Some(spikes(&runs).expect("fits"))
    }

    /// The shared real file's readings by the rule: B's spikes as the vendor prints them (3.2
    /// and 2.7 µm), within half its printed step (0.05 µm), from the runs' 3.15 and 3.23 (NEG)
    /// and 2.71 and 2.76 (POS); A's not (4.68 against 4.2 at its negative end, where the window
    /// is cut by the arc's start, 3.60 against −0.2 at its positive end): the numbers
    /// `vendor_fit`'s documentation states, to their printed digits (± 0.005).
    #[test]
    fn the_shared_files_spikes_of_b_are_the_vendors() {
        let Some(s) = shared_spikes(false) else { return };
        let test = crate::vendor_fit::tests::shared_file().expect("read above");
        let diag = test.diagnostics().expect("the vendor's diagnostics");
        let vendor = |name: &str| diag.feature(name).expect(name).value;
        let (b_neg, k) = feature(&s, 1, false).expect("B NEG");
        assert_eq!(k, 2);
        assert!((b_neg - vendor("AF_REVERSAL_SPIKES_B_NEG")).abs() <= 0.05, "{s:?}");
        let (b_pos, k) = feature(&s, 1, true).expect("B POS");
        assert_eq!(k, 2);
        assert!((b_pos - vendor("AF_REVERSAL_SPIKES_B_POS")).abs() <= 0.05, "{s:?}");
        let (a_neg, _) = feature(&s, 0, false).expect("A NEG");
        let (a_pos, _) = feature(&s, 0, true).expect("A POS");
        for (got, want) in [(b_neg, 3.19), (b_pos, 2.73), (a_neg, 4.68), (a_pos, 3.60)] {
            assert!((got - want).abs() <= 0.005, "{got} against the documented {want}: {s:?}");
        }
        assert!((a_pos - vendor("AF_REVERSAL_SPIKES_A_POS")).abs() > 3.0, "{s:?}");
        // Each reversal in each run: 180° at the arc's start (3.1 samples in: its window cut
        // to 43 samples) but not at its end (no room for the shape), the others whole.
        assert_eq!(s.len(), 8, "{s:?}");
        assert!(s.iter().all(|x| x.samples == 78 || (x.samples == 43 && x.axis == 0 && !x.pos)));
    }

    /// The same rule on the vendor's own model trace: its B spikes are this shape to within a
    /// sample's start (3.17 and 3.07 at B's negative end, 2.56 and 2.68 at its positive end:
    /// the CW run's B NEG spike starts 0.6 samples after the reversal, where the rule's
    /// shape starts at it), and at A's positive end it holds no spike of this shape.
    #[test]
    fn the_vendors_model_trace_by_the_same_rule() {
        let Some(s) = shared_spikes(true) else { return };
        let of = |axis: usize, pos: bool| -> Vec<f64> {
            let mut v: Vec<(usize, f64)> = s
                .iter()
                .filter(|x| x.axis == axis && x.pos == pos)
                .map(|x| (x.run, x.height_um))
                .collect();
            v.sort_by_key(|x| x.0);
            v.into_iter().map(|x| x.1).collect()
        };
        let near = |got: Vec<f64>, want: &[f64]| {
            assert_eq!(got.len(), want.len(), "{got:?}");
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() <= 0.005, "{got:?} against {want:?}");
            }
        };
        near(of(1, false), &[3.17, 3.07]);
        near(of(1, true), &[2.56, 2.68]);
        near(of(0, true), &[2.03, 2.91]);
    }

    /// The evidence of the window: the vendor's model trace of the shared file is a least
    /// squares of the readings over 79 samples about each reversal of B and A's positive end
    /// (its samples 356 to 434 and 755 to 833, both runs): the readings minus the trace sum to
    /// within 0.05 µm of 0 over each (a sum of 79 values rounded to 0.01 µm: their rounding's
    /// sum has a standard deviation of 0.026), where just outside the windows they are
    /// −0.11 µm a sample in the CCW run (−9 µm over 79 samples).
    #[test]
    fn the_vendors_model_is_a_least_squares_over_each_reversals_window() {
        let Some(test) = crate::vendor_fit::tests::shared_file() else { return };
        let diag = test.diagnostics().expect("the vendor's diagnostics");
        let traces = crate::vendor_fit::model_traces(&test.runs, diag).expect("a trace per run");
        for (run, trace) in test.runs.iter().zip(&traces) {
            let r: Vec<f64> =
                run.dr_mm.iter().zip(trace.iter()).map(|(y, t)| (y - t) * 1e3).collect();
            for (lo, hi) in [(356, 434), (755, 833)] {
                let sum: f64 = r[lo..=hi].iter().sum();
                assert!(sum.abs() < 0.05, "{lo}..{hi}: {sum}");
            }
        }
        let ccw: Vec<f64> =
            test.runs[0].dr_mm.iter().zip(traces[0].iter()).map(|(y, t)| (y - t) * 1e3).collect();
        let outside = ccw[435..474].iter().sum::<f64>() / 39.0;
        assert!((outside - -0.11).abs() < 0.02, "{outside}");
    }
}

//! ISO 230-4 figures of a circular test: circular deviation G, radial deviation F, circular
//! hysteresis H, and the RMS of a trace.

use ballbar_model::Run;

/// Root mean square.
pub fn rms(x: &[f64]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

/// The angle (rad, from +U towards +V) of every sample of a planar run; `None` for free paths.
pub fn angles(run: &Run) -> Option<Vec<f64>> {
    let (u, v, _) = run.header.plane.axes()?;
    let (cu, cv) = (run.axis(u)?, run.axis(v)?);
    let p = run.header.pivot_mm;
    Some(cu.iter().zip(cv).map(|(a, b)| (b - p[v.index()]).atan2(a - p[u.index()])).collect())
}

/// Remove the least-squares circle (mean radius and centre: `c0 + a cosθ + b sinθ`) from a
/// radial trace; returns the deviations about it.
pub fn about_lsq_circle(theta: &[f64], dr: &[f64]) -> Vec<f64> {
    let x = lsq_circle(theta, dr);
    theta.iter().zip(dr).map(|(&t, &y)| y - x[0] - x[1] * t.cos() - x[2] * t.sin()).collect()
}

/// The least-squares circle `[c0, a, b]` of a radial trace, `c0 + a cosθ + b sinθ` (mm): the
/// mean radial deviation and the centre offset (ISO 230-4; a vendor's "centre offset" and "best
/// radius" R + c0).
pub fn lsq_circle(theta: &[f64], dr: &[f64]) -> [f64; 3] {
    // 3×3 normal equations of three well-conditioned columns (1, cos, sin) of a circle: the
    // matrix is close to diag(n, n/2, n/2) for any arc over ~90°, so this small solve is safe.
    let mut m = [[0.0; 3]; 3];
    let mut rhs = [0.0; 3];
    for (&t, &y) in theta.iter().zip(dr) {
        let f = [1.0, t.cos(), t.sin()];
        for i in 0..3 {
            rhs[i] += f[i] * y;
            for j in 0..3 {
                m[i][j] += f[i] * f[j];
            }
        }
    }
    solve3(m, rhs).unwrap_or([rhs[0] / theta.len().max(1) as f64, 0.0, 0.0])
}

fn solve3(m: [[f64; 3]; 3], b: [f64; 3]) -> Option<[f64; 3]> {
    let det = |a: [[f64; 3]; 3]| {
        a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1])
            - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0])
            + a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])
    };
    let d = det(m);
    if d.abs() < 1e-300 {
        return None;
    }
    let mut x = [0.0; 3];
    for (k, xk) in x.iter_mut().enumerate() {
        let mut mk = m;
        for i in 0..3 {
            mk[i][k] = b[i];
        }
        *xk = det(mk) / d;
    }
    Some(x)
}

/// Figures of one trace, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CircleFigures {
    /// RMS about the nominal circle.
    pub rms: f64,
    /// Circular deviation G: max - min about the least-squares circle.
    pub g: f64,
    /// Largest radial deviation from the nominal radius (F max).
    pub f_max: f64,
    /// Smallest radial deviation (F min).
    pub f_min: f64,
}

/// ISO 230-4 figures of a radial trace `dr` (mm) of a planar run.
pub fn figures(run: &Run, dr: &[f64]) -> CircleFigures {
    let rms = rms(dr);
    let f_max = dr.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let f_min = dr.iter().copied().fold(f64::INFINITY, f64::min);
    let g = match angles(run) {
        Some(th) => {
            let c = about_lsq_circle(&th, dr);
            c.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - c.iter().copied().fold(f64::INFINITY, f64::min)
        }
        None => f_max - f_min,
    };
    CircleFigures { rms, g, f_max, f_min }
}

/// Circular hysteresis H (mm) of a CW/CCW pair: both traces about one common least-squares
/// circle, resampled on a 1° grid by nearest sample, the largest |CW - CCW| where both runs have
/// a sample within 1°.
pub fn hysteresis(a: &Run, dra: &[f64], b: &Run, drb: &[f64]) -> Option<f64> {
    let (ta, tb) = (angles(a)?, angles(b)?);
    let mut th = ta.clone();
    th.extend(&tb);
    let mut all = dra.to_vec();
    all.extend(drb);
    let centred = about_lsq_circle(&th, &all);
    let (ca, cb) = centred.split_at(dra.len());
    let grid = |t: &[f64], c: &[f64]| {
        let mut best = vec![(f64::INFINITY, 0.0); 360];
        for (&ang, &val) in t.iter().zip(c) {
            let deg = ang.to_degrees().rem_euclid(360.0);
            let k = (deg.round() as usize) % 360;
            let dist = (deg - deg.round()).abs();
            if dist < best[k].0 {
                best[k] = (dist, val);
            }
        }
        best
    };
    let (ga, gb) = (grid(&ta, ca), grid(&tb, cb));
    let mut h: Option<f64> = None;
    for k in 0..360 {
        if ga[k].0 <= 1.0 && gb[k].0 <= 1.0 {
            let d = (ga[k].1 - gb[k].1).abs();
            h = Some(h.map_or(d, |x: f64| x.max(d)));
        }
    }
    h
}

/// Paired CW/CCW runs (same plane, radius, feed, pivot), by index.
pub fn pairs(runs: &[Run]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut used = vec![false; runs.len()];
    for i in 0..runs.len() {
        if used[i] || runs[i].header.direction != Some(ballbar_model::Direction::CW) {
            continue;
        }
        let h = &runs[i].header;
        if let Some(j) = (0..runs.len()).find(|&j| {
            let g = &runs[j].header;
            !used[j]
                && g.direction == Some(ballbar_model::Direction::CCW)
                && g.plane == h.plane
                && g.radius_mm == h.radius_mm
                && g.feed_mm_per_min == h.feed_mm_per_min
                && g.pivot_mm == h.pivot_mm
        }) {
            used[i] = true;
            used[j] = true;
            out.push((i, j));
        }
    }
    out
}

/// Remove only the first harmonic `a cosθ + b sinθ` (a centring offset) from a radial trace,
/// keeping its mean (which carries bar length, scale and radius loss).
pub fn without_centring(theta: &[f64], dr: &[f64]) -> Vec<f64> {
    let (a, b) = first_harmonic(theta, dr);
    theta.iter().zip(dr).map(|(&t, &y)| y - a * t.cos() - b * t.sin()).collect()
}

/// The least-squares first harmonic `(a, b)` of a radial trace, `a cosθ + b sinθ` (zero when
/// the angles do not determine it).
pub fn first_harmonic(theta: &[f64], dr: &[f64]) -> (f64, f64) {
    // Two near-orthogonal columns over a full circle (Gram matrix ≈ diag(n/2, n/2)).
    let (mut cc, mut cs, mut ss, mut yc, mut ys) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&t, &y) in theta.iter().zip(dr) {
        let (c, s) = (t.cos(), t.sin());
        cc += c * c;
        cs += c * s;
        ss += s * s;
        yc += y * c;
        ys += y * s;
    }
    let det = cc * ss - cs * cs;
    if det.abs() < 1e-300 {
        return (0.0, 0.0);
    }
    ((yc * ss - ys * cs) / det, (ys * cc - yc * cs) / det)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::path::CircleTest;
    use ballbar_model::{Direction, Plane};

    fn circle(direction: Direction) -> Run {
        CircleTest {
            plane: Plane::XY,
            direction,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm: [0.0, 0.0, 0.0],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: [0.0; 3],
            sample_rate_hz: 200.0,
            start_deg: 0.0,
            sweep_deg: 360.0,
        }
        .run("2026-11-21T10:00:00Z", 0.0, "t", "test")
    }

    #[test]
    fn g_f_and_h_of_known_traces() {
        // A 45° ellipse of amplitude a plus a centring offset c cosθ and a constant k:
        // G (about the LSQ circle) = 2a; F max/min = k ± (a + c) at most; H of a trace that
        // flips sign with direction = max |a sin2θ - (-a sin2θ)| = 2a.
        let (a, c, k) = (2e-3, 5e-3, 1e-3);
        let ccw = circle(Direction::CCW);
        let cw = circle(Direction::CW);
        let trace = |run: &Run, sign: f64| -> Vec<f64> {
            angles(run)
                .unwrap()
                .iter()
                .map(|t| k + sign * a * (2.0 * t).sin() + c * t.cos())
                .collect()
        };
        let (dccw, dcw) = (trace(&ccw, 1.0), trace(&cw, -1.0));
        let f = figures(&ccw, &dccw);
        // 200 Hz over 37.7 s: the sampled extremes miss the true ones by < 1e-6 relative.
        assert!((f.g - 2.0 * a).abs() < 1e-8, "G {}", f.g);
        assert!(f.f_max <= k + a + c + 1e-12 && f.f_max > k + c);
        assert!(f.f_min >= k - a - c - 1e-12);
        let rms_expect = (k * k + a * a / 2.0 + c * c / 2.0).sqrt();
        // The closing sample repeats the start (7,540 samples): a bias below 1e-3 relative.
        assert!((f.rms - rms_expect).abs() < 1e-3 * rms_expect, "{} {rms_expect}", f.rms);
        let h = hysteresis(&cw, &dcw, &ccw, &dccw).unwrap();
        // Nearest samples within 1°: sin 2θ at ≤ 0.05° off → relative error < 2e-3.
        assert!((h - 2.0 * a).abs() < 2e-3 * 2.0 * a, "H {h}");
        let same = hysteresis(&cw, &trace(&cw, 1.0), &ccw, &dccw).unwrap();
        // Nearest samples ≤ 0.05° apart: |a sin2θ| changes by ≤ 2a · 8.7e-4.
        assert!(same < 2e-3 * a, "no hysteresis when CW = CCW: {same}");
    }
}

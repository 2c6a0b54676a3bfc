//! The backlash switches at the model's own lagged reversal, end to end: `fit`, `diagnose` and
//! `predict` with its saved model, on readings written here from a formula (not the
//! simulator).

use crate::common::*;

/// XY circles about (300, 200, -300) mm, R 100 mm, 5000 mm/min, 1 kHz, CCW and CW from 0°,
/// whose axes follow the command delayed by their servo lags (`X(t) = X_c(t - τ_X)`, τ_X 2 ms,
/// τ_Y 3 ms) and whose backlash switches when that lagged position reverses,
/// `δ_X = -(B_X/2) sign(dX_c/dt (t - τ_X))` (B_X 8 µm, B_Y 6 µm): the reading is the exact
/// distance less R plus white noise of 0.1 µm (seeded). The columns are the commanded
/// positions. Returns the folder.
fn write_runs(dir: &std::path::Path) -> std::path::PathBuf {
    let runs = dir.join("runs");
    std::fs::create_dir_all(&runs).unwrap();
    let (r, feed, rate) = (100.0_f64, 5000.0_f64, 1000.0_f64);
    let (tau_x, tau_y, b_x, b_y, noise_mm) = (0.002, 0.003, 0.008, 0.006, 1e-4);
    let omega = feed / 60.0 / r;
    let n = (2.0 * std::f64::consts::PI / omega * rate).round() as usize;
    let mut rng = ballbar_sim::rng::Rng::new(23);
    for (k, (dir_name, sign)) in [("CCW", 1.0), ("CW", -1.0)].into_iter().enumerate() {
        let w = sign * omega;
        let mut text = format!(
            "# ballbar-run: 1\n# machine: column\n# plane: XY\n# direction: {dir_name}\n# radius_mm: 100\n# feed_mm_per_min: 5000\n# pivot_mm: 300, 200, -300\n# table_ball_mm: 0, 0, 0\n# tool_ball_mm: 0, 0, 0\n# started_at: 2026-11-28T08:0{k}:00Z\n# run_id: xy-{}\nt_s,X_mm,Y_mm,Z_mm,dR_um\n",
            dir_name.to_lowercase()
        );
        for i in 0..n {
            let t = i as f64 / rate;
            let th = w * t;
            // Each axis at the command's angle of its lagged time, its velocity there.
            let (ax, ay) = (w * (t - tau_x), w * (t - tau_y));
            let (vx, vy) = (-r * w * ax.sin(), r * w * ay.cos());
            let dx = r * ax.cos() - 0.5 * b_x * vx.signum();
            let dy = r * ay.sin() - 0.5 * b_y * vy.signum();
            let dr_um = (dx.hypot(dy) - r + noise_mm * rng.normal()) * 1e3;
            text += &format!(
                "{t:.6},{:.6},{:.6},-300.000000,{dr_um:.6}\n",
                300.0 + r * th.cos(),
                200.0 + r * th.sin()
            );
        }
        std::fs::write(runs.join(format!("xy-{}.csv", dir_name.to_lowercase())), text).unwrap();
    }
    runs
}

/// Per run file written by `predict`: the angle of each sample about the pivot, its time, and
/// the measured minus predicted reading about its least-squares circle (µm): the run's
/// centring, which the saved model leaves out, removed by a 3×3 solve of (1, cos θ, sin θ)
/// over a full circle (test arithmetic, not the project's estimator).
fn predicted_residual(path: &std::path::Path) -> Vec<(f64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut rows = Vec::new();
    for l in text.lines().filter(|l| !l.starts_with('#') && !l.starts_with("t_s")) {
        let f: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
        let th = (f[2] - 200.0).atan2(f[1] - 300.0);
        rows.push((f[0], [1.0, th.cos(), th.sin()], f[4] - f[5]));
    }
    let mut m = [[0.0; 3]; 3];
    let mut v = [0.0; 3];
    for (_, x, y) in &rows {
        for i in 0..3 {
            v[i] += x[i] * y;
            for j in 0..3 {
                m[i][j] += x[i] * x[j];
            }
        }
    }
    for c in 0..3 {
        for r in c + 1..3 {
            let f = m[r][c] / m[c][c];
            for k in c..3 {
                m[r][k] -= f * m[c][k];
            }
            v[r] -= f * v[c];
        }
    }
    let mut b = [0.0; 3];
    for c in (0..3).rev() {
        b[c] = (v[c] - (c + 1..3).map(|k| m[c][k] * b[k]).sum::<f64>()) / m[c][c];
    }
    rows.iter().map(|(t, x, y)| (*t, y - (0..3).map(|i| x[i] * b[i]).sum::<f64>())).collect()
}

/// The largest |residual| (µm) within 10 ms after a commanded reversal of X or Y (0°, 90°,
/// 180°, 270°: every quarter turn, t = k·T/4 from the start at 0°), where a backlash switched
/// at the wrong time leaves its step; and the largest elsewhere.
fn worst_after_reversals(res: &[(f64, f64)]) -> (f64, f64) {
    let quarter = 2.0 * std::f64::consts::PI / (5000.0 / 60.0 / 100.0) / 4.0;
    let (mut near, mut far): (f64, f64) = (0.0, 0.0);
    for &(t, e) in res {
        let since = t - (t / quarter).floor() * quarter;
        if since < 0.01 { near = near.max(e.abs()) } else { far = far.max(e.abs()) }
    }
    (near, far)
}

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn backlash_switching_at_the_lagged_reversal_leaves_no_spike_and_predict_replays_the_fit() {
    let dir = scratch("switch");
    let runs = write_runs(&dir);
    let runs = runs.to_str().unwrap();
    let mut residuals = Vec::new();
    for switch in ["lagged", "commanded"] {
        let (fit_json, model) =
            (dir.join(format!("{switch}.json")), dir.join(format!("{switch}.ron")));
        let o = ballbar(&[
            "fit",
            "--machine",
            "column",
            runs,
            "--backlash-switch",
            switch,
            "--json",
            fit_json.to_str().unwrap(),
            "--save-model",
            model.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        if switch == "lagged" {
            // The switch lags found: 2 and 3 ms in truth.
            let out = text(&o);
            let line = out.lines().find(|l| l.starts_with("backlash switch:")).unwrap();
            assert!(line.contains("at each axis's lagged reversal"), "{line}");
            let ms = |axis: &str| -> f64 {
                let i = line.find(&format!("{axis} ")).unwrap() + axis.len() + 1;
                line[i..].split(' ').next().unwrap().parse().unwrap()
            };
            // Their difference is the servo mismatch's, 1 ms; the common lag is pinned by the
            // switch timing only to its u (the staircase's steps: the reversals' phases
            // against the 1 ms samples), within a sample interval here: the truth within 2u.
            let i = line.find("common lag ").unwrap() + "common lag ".len();
            let f: Vec<&str> = line[i..].split(' ').collect();
            let u: f64 = f[2].parse().unwrap();
            assert!(u < 1.0, "{line}");
            assert!((ms("Y") - ms("X") - 1.0).abs() < 0.05, "{line}");
            assert!((ms("X") - 2.0).abs() < 2.0 * u, "{line}");
        }
        let fitted = json(&fit_json);
        let out = dir.join(format!("predicted-{switch}"));
        let o = ballbar(&[
            "predict",
            "--model",
            model.to_str().unwrap(),
            runs,
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(!text(&o).contains("does not say where its backlash switches"), "{}", text(&o));
        for run in fitted["runs"].as_array().unwrap() {
            let file = std::path::Path::new(run["file"].as_str().unwrap()).file_name().unwrap();
            let res = predicted_residual(&out.join(file));
            let g = res.iter().map(|r| r.1).fold(f64::NEG_INFINITY, f64::max)
                - res.iter().map(|r| r.1).fold(f64::INFINITY, f64::min);
            // predict with the saved model reproduces the fit's residual but for two things,
            // each bounded here: (1) dR_model_um is written to 4 decimals, so the largest and
            // the smallest residual each move by up to 5e-5 µm: 1e-4 µm of G; (2) predict
            // leaves the run's centring e out and this test removes it as a circle, linearly,
            // while the fit moves the table ball by e in the exact chain: the two differ by
            // the distance's second order, |p + δ - e| - |p + δ| + û·e = (û - û')·e + O(|e|²/R)
            // (û' the direction of p + δ, |û - û'| ≤ |δ|/R), whose span is at most
            // 2 |e| |δ| / R + |e|²/R, δ the model's displacement: the lags' differences' -τ v,
            // each axis ±0.5 ms (the 1 ms difference, its 5 % checked above) at v = 5000
            // mm/min, and half the backlash, (4, 3) µm. |e| ≈ 0.7 µm: a bound of about 7.9e-4
            // µm; measured up to 2.4e-4 µm, which the rounding alone (1e-4 µm) does not
            // allow. A replay without the saved switch lags misses by the backlash step,
            // micrometres.
            let fit_g = run["after"]["g_um"].as_f64().unwrap();
            let id = run["run"].as_str().unwrap();
            let centring_um = |axis: &str| {
                fitted["parameters"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|p| p["id"] == format!("C{axis}@{id}"))
                    .and_then(|p| p["value"].as_f64())
                    .unwrap()
            };
            let e_mm = centring_um("X").hypot(centring_um("Y")) * 1e-3;
            let delta_mm = 0.5 * 1.05e-3 * 5000.0 / 60.0 + 0.005;
            let bound_um = 1e-4 + (2.0 * e_mm * delta_mm + e_mm * e_mm) / 100.0 * 1e3;
            assert!(
                (g - fit_g).abs() < bound_um,
                "{switch} {file:?}: predict G {g} fit G {fit_g}, bound {bound_um}"
            );
            residuals.push((switch, worst_after_reversals(&res)));
        }
    }
    eprintln!("largest |residual| within 10 ms after / elsewhere (µm): {residuals:?}");
    for (switch, (near, far)) in residuals {
        // 0.1 µm noise over 7,540 samples: its largest is about 4σ, 0.4 µm. Switched at the
        // command, the 2-3 samples after each reversal carry the whole step (6-8 µm).
        assert!(far < 0.6, "{switch}: {far} µm away from the reversals");
        if switch == "lagged" {
            assert!(near < 0.6, "{switch}: {near} µm after the reversals");
        } else {
            assert!(near > 4.0, "{switch}: {near} µm after the reversals");
        }
    }

    // diagnose names no reversal spike at the lagged switch; at the commanded one it would.
    for (switch, spikes) in [("lagged", false), ("commanded", true)] {
        let d = dir.join(format!("diagnosis-{switch}.json"));
        let o = ballbar(&[
            "diagnose",
            "--machine",
            "column",
            runs,
            "--backlash-switch",
            switch,
            "--json",
            d.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        let kinds: Vec<String> = json(&d)["effects"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["kind"].as_str().unwrap().to_string())
            .collect();
        assert_eq!(kinds.iter().any(|k| k == "reversal_spike"), spikes, "{switch}: {kinds:?}");
    }
}

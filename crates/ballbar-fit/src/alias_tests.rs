//! Aliases and local quantities on readings written by hand: a quadratic positional error of
//! X that the base model (positional degree 1, straightness degree 2 with tied angles) takes
//! for straightness and squareness at one centre.

use ballbar_model::machines::column;
use ballbar_model::path::CircleTest;
use ballbar_model::{BarLength, Design, Direction, Model, ModelOptions, Plane, Run, ServoVariant};

use crate::alias::{Candidate, Quantity, assess};
use crate::fit_factored;
use ballbar_model::{Axis, Effect};

/// Positional curvature of X: δX = P2 X², 3 µm at X = ±150 mm.
const P2: f64 = 3e-3 / (150.0 * 150.0);
/// Squareness XY, the model's convention (δY = -α X), rad.
const ALPHA: f64 = 40e-6;
/// Noise of the readings, mm (0.1 µm, a good bar's).
const NOISE_MM: f64 = 1e-4;

/// A seeded normal variate (xorshift64*, Box-Muller).
struct Normal(u64);
impl Normal {
    fn uniform(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }
    fn next(&mut self) -> f64 {
        let (a, b) = (self.uniform(), self.uniform());
        (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
    }
}

/// Three planes, CW and CCW, at one centre; readings of the field δ = (P2 X², -α X, 0) (X the
/// absolute machine coordinate), taken exactly: ΔR = |d + δ| - R with d = q - pivot.
fn runs(pivot: [f64; 3], seed: u64) -> Vec<Run> {
    let mut noise = Normal(seed);
    let mut out = Vec::new();
    for (k, plane) in Plane::PLANAR.into_iter().enumerate() {
        for (j, direction) in [Direction::CCW, Direction::CW].into_iter().enumerate() {
            let test = CircleTest {
                plane,
                direction,
                radius_mm: 150.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: pivot,
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0; 3],
                sample_rate_hz: 40.0,
                start_deg: 0.0,
                sweep_deg: 360.0,
            };
            let start = 1.8e9 + 100.0 * (2 * k + j) as f64;
            let mut run = test.run(
                "2027-01-15T08:00:00Z",
                start,
                &format!("{plane}-{direction:?}"),
                "column",
            );
            for i in 0..run.len() {
                let q: Vec<f64> = (0..3).map(|a| run.axes[a].as_ref().unwrap()[i]).collect();
                let d: Vec<f64> = (0..3).map(|a| q[a] - pivot[a]).collect();
                let delta = [P2 * q[0] * q[0], -ALPHA * q[0], 0.0];
                let len = (0..3).map(|a| (d[a] + delta[a]).powi(2)).sum::<f64>().sqrt();
                run.dr_mm[i] = len - 150.0 + NOISE_MM * noise.next();
            }
            out.push(run);
        }
    }
    out
}

/// The index of the alias that is X's positional curvature (degree 2), if it is named.
fn x_curvature(a: &crate::alias::Assessment) -> Option<usize> {
    let x2 = Candidate::Term(Effect::PositionalHigherOrder { axis: Axis::X, degree: 2 });
    a.aliases.iter().position(|al| al.candidate == x2)
}

const OPTIONS: ModelOptions =
    ModelOptions { servo: ServoVariant::AxisLag, bar_length: BarLength::Known(0.0) };

#[test]
fn a_quadratic_pitch_is_named_with_the_squareness_it_would_leave_and_the_local_values_by_hand() {
    let model = Model::new(column(), OPTIONS).unwrap();
    let pivot = [100.0, 50.0, -80.0];
    let runs = runs(pivot, 7);
    let design = Design::new(&model, &runs).unwrap();
    let (fit, fac) = fit_factored(&design, 2).unwrap();
    let a = assess(&design, &fit, &fac, 2).unwrap();
    let sq = fit.index("SQXY").unwrap();
    let (v, u) = (fit.values[sq], fit.std_uncertainty[sq]);
    eprintln!("SQXY {:.2} ± {:.2} µrad", v * 1e6, u * 1e6);
    for al in &a.aliases {
        eprintln!(
            "{} share {:.2e} chi2 {:.2e} with {:?} alt {:?}",
            al.candidate.description(),
            al.visible_share,
            al.chi2_at_plausible,
            al.with,
            al.alternative
        );
        for m in &al.moves {
            eprintln!("   {} {:.3e} → {:?} per {:.3e}", m.name, m.value, m.alternative, m.per_unit);
        }
    }
    // The base alone takes the curvature for straightness and tilts the squareness by far more
    // than its u: the case this module exists for.
    assert!((v - ALPHA).abs() > 10.0 * u, "SQXY {v} ± {u}");
    // The alias is named, SQXY among what it moves, and the alternative is the truth within
    // its u (the hand-written field has no straightness, so the alternative is exact but for
    // the noise): three standard uncertainties.
    let k = x_curvature(&a).expect("the positional curvature of X named");
    let m = a.move_of(k, Quantity::Parameter(sq)).expect("SQXY moved by it");
    let alt = m.alternative.unwrap();
    assert!((alt - ALPHA).abs() < 3.0 * u, "alternative {alt} against {ALPHA} ± {u}");
    assert!(m.u_with_spread >= 0.5 * (alt - v).abs());
    assert!(a.conditional_on(Quantity::Parameter(sq)).contains(&k));
    // Local quantities at the centre, by hand: J_XX = 2 P2 Xc, J_YX = -α, J_XY = 0; no error
    // of Y or Z. Tolerance: 3 u (noise only; the field is the model's class locally).
    let want = |name: &str| match name {
        "local scale X" => 2.0 * P2 * pivot[0],
        "local squareness XY" => ALPHA,
        _ => 0.0,
    };
    for l in &a.local {
        assert!(l.estimate.estimable, "{} not determined", l.name);
        let w = want(&l.name);
        assert!(
            (l.estimate.value - w).abs() < 3.0 * l.estimate.std_uncertainty.max(1e-9),
            "{}: {} ± {} against {w}",
            l.name,
            l.estimate.value,
            l.estimate.std_uncertainty
        );
    }
}

/// The set-up moved as a user's metadata can move it: pivot and coordinates together by
/// `shift` mm, the tool longer by `longer` mm. The readings stay the readings.
fn moved(runs: &[Run], shift: [f64; 3], longer: f64) -> Vec<Run> {
    let mut out = runs.to_vec();
    for r in &mut out {
        for a in 0..3 {
            r.header.pivot_mm[a] += shift[a];
            if let Some(c) = r.axes[a].as_mut() {
                c.iter_mut().for_each(|x| *x += shift[a]);
            }
        }
        r.header.tool_ball_mm[2] -= longer;
    }
    out
}

/// What a test determines does not move with metadata it cannot check; what moves is flagged.
/// For each set-up change (the pivot with the coordinates by (100, 60, -80) mm; the tool
/// 100 mm longer): every local quantity the original fit determines is determined after it and
/// unchanged within `0.1 u + SECOND_ORDER |v|`; every machine parameter that moves by more than
/// `0.5 u + SECOND_ORDER |v|` is conditional on a metadata alias in both assessments (each
/// alias is listed when 100 mm of it moves a value by a tenth of its u; the shifts here
/// combine at most three such moves along the axes, or the tool's one).
///
/// The local values are the exact field's, with the second-order part of the reading that a
/// circle sees (`ballbar_model::local::exact_local_value`): measured, a shift leaves them
/// within 0.3 u on one plane, a partial arc and the gantry; on three planes and several
/// centres with the paper's options (whose u of a scale is 0.015 ppm) the scales still move by
/// up to 5.4e-4 of their value (0.04 ppm, up to 5 u), a remainder of higher order that this
/// test bounds rather than explains: [`SECOND_ORDER`] = 1e-3 of the value, far below the
/// 0.1 ppm and 0.1 µm/m a vendor prints.
const SECOND_ORDER: f64 = 1e-3;

fn invariance(
    spec: &ballbar_model::MachineSpec,
    options: ModelOptions,
    runs: &[Run],
    what: &str,
) -> usize {
    let mut moved_flagged = 0;
    let model = Model::new(spec.clone(), options).unwrap();
    let assess_runs = |runs: &[Run]| {
        let design = Design::new(&model, runs).unwrap();
        let (fit, fac) = fit_factored(&design, 2).unwrap();
        let a = assess(&design, &fit, &fac, 2).unwrap();
        (fit, a)
    };
    let (f0, a0) = assess_runs(runs);
    assert!(!a0.local.is_empty(), "{what}: no local quantities");
    for (shift, longer) in [([100.0, 60.0, -80.0], 0.0), ([0.0; 3], 100.0)] {
        let (f1, a1) = assess_runs(&moved(runs, shift, longer));
        assert_eq!(a0.local.len(), a1.local.len());
        for (l0, l1) in a0.local.iter().zip(&a1.local) {
            assert!(l0.estimate.estimable, "{what}: {} not determined", l0.name);
            assert!(
                l1.estimate.estimable,
                "{what}: {} not determined after {shift:?} {longer}",
                l1.name
            );
            let (v0, v1, u) = (l0.estimate.value, l1.estimate.value, l0.estimate.std_uncertainty);
            assert!(
                (v1 - v0).abs() <= 0.1 * u + SECOND_ORDER * v0.abs(),
                "{what}, {shift:?} {longer}: {} {} moved {v0} → {v1} (u {u})",
                l0.name,
                l0.test_text()
            );
        }
        let metadata = |a: &crate::alias::Assessment, j: usize| {
            a.conditional_on(Quantity::Parameter(j))
                .iter()
                .any(|&k| a.aliases[k].candidate.is_metadata())
        };
        for j in 0..f0.n_machine {
            if !(f0.estimable[j] && f1.estimable[j]) || f0.parameters[j].class.is_nuisance() {
                continue;
            }
            let (v0, v1, u) = (f0.values[j], f1.values[j], f0.std_uncertainty[j]);
            if (v1 - v0).abs() > 0.5 * u + SECOND_ORDER * v0.abs() {
                assert!(
                    metadata(&a0, j) && metadata(&a1, j),
                    "{what}, {shift:?} {longer}: {} moved {v0} → {v1} (u {u}) unflagged",
                    f0.parameters[j].id
                );
                moved_flagged += 1;
            }
        }
    }
    moved_flagged
}

/// Runs of a fixture truth, its tests replaced by `tests` (plane, pivot, tool, sweep).
fn simulated(
    spec: &ballbar_model::MachineSpec,
    truth: &str,
    tests: &[(Plane, [f64; 3], [f64; 3], f64)],
) -> Vec<Run> {
    let mut t: ballbar_sim::Truth = ron::from_str(truth).unwrap();
    let proto = t.tests[0].clone();
    t.tests = tests
        .iter()
        .map(|&(plane, pivot_mm, tool_ball_mm, sweep_deg)| ballbar_sim::TestSpec {
            plane,
            pivot_mm,
            tool_ball_mm,
            sweep_deg,
            ..proto.clone()
        })
        .collect();
    ballbar_sim::simulate(spec, &t, 0.0, 11).unwrap().runs
}

const COLUMN_TRUTH: &str = include_str!("../../../fixtures/column-paper/truth.ron");
const HORIZONTAL_TRUTH: &str = include_str!("../../../fixtures/horizontal-paper/truth.ron");
const GANTRY_TRUTH: &str = include_str!("../../../fixtures/machines/gantry.truth.ron");

#[test]
fn what_each_shape_determines_does_not_move_with_the_pivot_or_the_tool_length() {
    let c = [300.0, 200.0, -300.0];
    let tool = [0.0, 0.0, -100.0];
    let three = |c: [f64; 3], tool: [f64; 3]| {
        vec![(Plane::XY, c, tool, 360.0), (Plane::YZ, c, tool, 360.0), (Plane::ZX, c, tool, 360.0)]
    };
    let paper =
        ModelOptions { servo: ServoVariant::PlaneMismatch, bar_length: BarLength::Known(0.0) };
    let column = column();
    let horizontal = ballbar_model::machines::horizontal();
    let shapes: Vec<(
        &str,
        &ballbar_model::MachineSpec,
        &str,
        Vec<(Plane, [f64; 3], [f64; 3], f64)>,
    )> = vec![
        ("column, one plane", &column, COLUMN_TRUTH, vec![(Plane::XY, c, tool, 360.0)]),
        ("column, three planes at one centre", &column, COLUMN_TRUTH, three(c, tool)),
        ("column, a partial arc", &column, COLUMN_TRUTH, vec![(Plane::XY, c, tool, 220.0)]),
        ("column, several centres", &column, COLUMN_TRUTH, {
            let mut t = three(c, tool);
            t.push((Plane::XY, [c[0] + 150.0, c[1], c[2]], tool, 360.0));
            t.push((Plane::XY, [c[0], c[1] + 150.0, c[2]], tool, 360.0));
            t
        }),
        ("horizontal, three planes at one centre", &horizontal, HORIZONTAL_TRUTH, three(c, tool)),
        ("horizontal, one plane", &horizontal, HORIZONTAL_TRUTH, vec![(Plane::YZ, c, tool, 360.0)]),
    ];
    for (what, spec, truth, tests) in shapes {
        let runs = simulated(spec, truth, &tests);
        let moved = invariance(spec, paper, &runs, what) + invariance(spec, OPTIONS, &runs, what);
        // One plane at one centre: its global squareness and scales move with the pivot (the
        // failure this guards against); the test must see them move, and flagged.
        if what.ends_with("one plane") {
            assert!(moved > 0, "{what}: nothing moved with the set-up: the check saw nothing");
        }
    }
    // A chain-file machine with angular terms of its own (the gantry's bridge yaw and carriage
    // roll), at its fixture's shape: three planes, a second tool length and a second centre.
    let gantry =
        ballbar_machine_chain_file::parse(include_str!("../../../fixtures/machines/gantry.ron"))
            .unwrap();
    let t: ballbar_sim::Truth = ron::from_str(GANTRY_TRUTH).unwrap();
    let runs = ballbar_sim::simulate(&gantry, &t, 0.0, 11).unwrap().runs;
    invariance(&gantry, OPTIONS, &runs, "gantry, the fixture's shape");
    // The five-axis machines' planar tests (their fixtures' shape: three planes at one centre,
    // rotary axes held at 0), where a rotary axis's location errors act as a re-seated ball.
    for (machine, truth) in [
        (
            include_str!("../../../fixtures/machines/five-axis-ac-trunnion.ron"),
            include_str!("../../../fixtures/machines/five-axis-ac-trunnion.truth.ron"),
        ),
        (
            include_str!("../../../fixtures/machines/five-axis-bc-head-table.ron"),
            include_str!("../../../fixtures/machines/five-axis-bc-head-table.truth.ron"),
        ),
    ] {
        let spec = ballbar_machine_chain_file::parse(machine).unwrap();
        let t: ballbar_sim::Truth = ron::from_str(truth).unwrap();
        let runs = ballbar_sim::simulate(&spec, &t, 0.0, 11).unwrap().runs;
        invariance(&spec, OPTIONS, &runs, &format!("{}, the fixture's planar shape", spec.name));
    }
}

/// One XY circle pair at the origin, R 50, readings of a positional curvature of X alone,
/// δX = 12 µm (X/250 mm)², with white noise of 0.4 µm: the shop-floor one-plane test, where
/// the noise hides a curvature of plausible size but not the one there.
fn one_plane_pitch_runs(seed: u64) -> Vec<Run> {
    let mut noise = Normal(seed);
    let p = 12e-3 / (250.0 * 250.0);
    [Direction::CCW, Direction::CW]
        .into_iter()
        .enumerate()
        .map(|(j, direction)| {
            let test = CircleTest {
                plane: Plane::XY,
                direction,
                radius_mm: 50.0,
                feed_mm_per_min: 1500.0,
                pivot_mm: [0.0; 3],
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0; 3],
                sample_rate_hz: 50.0,
                start_deg: 0.0,
                sweep_deg: 360.0,
            };
            let mut run = test.run(
                "2027-01-15T08:00:00Z",
                1.8e9 + 100.0 * j as f64,
                &format!("xy-{j}"),
                "column",
            );
            for i in 0..run.len() {
                let q: Vec<f64> = (0..3).map(|a| run.axes[a].as_ref().unwrap()[i]).collect();
                let d = [q[0] + p * q[0] * q[0], q[1], q[2]];
                let len = d.iter().map(|x| x * x).sum::<f64>().sqrt();
                run.dr_mm[i] = len - 50.0 + 4e-4 * noise.next();
            }
            run
        })
        .collect()
}

/// The class of the silent alias at shop-floor noise: the curvature's plausible size (1 µm)
/// moves the straightness that carries it by less than that straightness's u, so a rule of
/// "moves at its plausible size" named nothing, though the fitted straightness is many u from
/// zero and the curvature that would replace it is as consistent with the readings. The alias
/// is named whenever the alternative the runs cannot refuse moves a reported value by more
/// than its u; its size is the truth within the carrier's own relative uncertainty.
#[test]
fn a_curvature_hidden_by_the_noise_at_its_plausible_size_is_named_when_its_alternative_is_not() {
    let model = Model::new(column(), OPTIONS).unwrap();
    let runs = one_plane_pitch_runs(11);
    let design = Design::new(&model, &runs).unwrap();
    let (fit, fac) = fit_factored(&design, 2).unwrap();
    let a = assess(&design, &fit, &fac, 2).unwrap();
    let k = x_curvature(&a).expect("the positional curvature of X named");
    let al = &a.aliases[k];
    let (j, size) = al.alternative.expect("an alternative: the curvature in the carrier's place");
    let (v, u) = (fit.values[j], fit.std_uncertainty[j]);
    let m = a.move_of(k, Quantity::Parameter(j)).expect("the carrier moved by it");
    // Why the plausible-size rule was silent here: 1 µm moves the carrier by less than its u.
    assert!(
        (al.candidate.plausible_size() * m.per_unit).abs() < u,
        "{} moves {} per unit against u {u}",
        fit.parameters[j].id,
        m.per_unit
    );
    // The carrier is many u from zero, and zero under the alternative.
    assert!(v.abs() > 3.0 * u, "{} {v} ± {u}", fit.parameters[j].id);
    assert!(m.alternative.unwrap().abs() < 1e-3 * v.abs());
    assert!(a.conditional_on(Quantity::Parameter(j)).contains(&k));
    // The alternative's size is the truth, 12 µm, but for the noise: within 3 of the carrier's
    // relative uncertainties (the size is the carrier's value over its projection).
    let rel = u / v.abs();
    assert!((size - 12e-3).abs() < 3.0 * rel * 12e-3, "{size} mm against 0.012 (± {rel} relative)");
}

//! Unit tests of the sign conventions and of the chain's first-order sensitivities.

use crate::axis::{Axis, Direction, Plane};
use crate::chain::{Branch, ErrorMotion, JointKind, sensitivities};
use crate::machine::{JointSpec, MachineSpec, Model, ModelOptions, TermSpec};
use crate::path::CircleTest;
use crate::{Design, JointState, RowScratch, Run};

fn joint(name: &str, axis: Axis, kind: JointKind, dir: [f64; 3], origin: [f64; 3]) -> JointSpec {
    JointSpec { name: name.into(), axis, kind, direction: dir, origin_mm: origin }
}

/// The column machine (table X over saddle Y, head Z) with the given terms.
fn column(terms: Vec<TermSpec>) -> Model {
    let spec = MachineSpec { terms, ..crate::machines::column() };
    Model::new(spec, ModelOptions::default()).unwrap()
}

fn xy(direction: Direction, feed: f64) -> Run {
    circle_xy(direction, feed).run("2026-11-21T10:00:00Z", 0.0, "t", "test")
}

/// The XY circle of [`xy`].
fn circle_xy(direction: Direction, feed: f64) -> CircleTest {
    CircleTest {
        plane: Plane::XY,
        direction,
        radius_mm: 100.0,
        feed_mm_per_min: feed,
        pivot_mm: [300.0, 200.0, -300.0],
        table_ball_mm: [0.0, 0.0, 50.0],
        tool_ball_mm: [0.0, 0.0, -100.0],
        sample_rate_hz: 100.0,
        start_deg: 0.0,
        sweep_deg: 360.0,
    }
}

/// ΔR (mm) along a run for one unit... of parameter `id` set to `value`.
fn response(model: &Model, run: Run, id: &str, value: f64) -> (Run, Vec<f64>) {
    let runs = vec![run];
    let d = Design::new(model, &runs).unwrap();
    let col = d.parameters.iter().position(|p| p.id == id).unwrap();
    let mut theta = vec![0.0; d.n_cols()];
    theta[col] = value;
    let pred = d.predict_run(0, &theta).unwrap();
    let [run] = <[Run; 1]>::try_from(runs).unwrap();
    (run, pred)
}

/// The sample nearest to angle `deg` (from +U) of a planar run.
fn at(run: &Run, pred: &[f64], deg: f64) -> f64 {
    let (u, v, _) = run.header.plane.axes().unwrap();
    let h = &run.header;
    let best = (0..run.len())
        .min_by(|&a, &b| {
            let ang = |i: usize| {
                let du = run.axis(u).unwrap()[i] - h.pivot_mm[u.index()];
                let dv = run.axis(v).unwrap()[i] - h.pivot_mm[v.index()];
                let d = dv.atan2(du).to_degrees() - deg;
                (d + 540.0).rem_euclid(360.0) - 180.0
            };
            ang(a).abs().total_cmp(&ang(b).abs())
        })
        .unwrap();
    pred[best]
}

#[test]
fn squareness_is_a_45_degree_ellipse_the_same_both_directions() {
    let m =
        column(vec![TermSpec::Squareness { id: "SQXY".into(), axis: Axis::X, toward: Axis::Y }]);
    let alpha = 50e-6; // rad
    for dir in [Direction::CW, Direction::CCW] {
        let (run, p) = response(&m, xy(dir, 1000.0), "SQXY", alpha);
        // ΔY = -α X with X = X_c + R cosθ: the X_c part is a first harmonic (a centring), the
        // rest -α R sinθ cosθ, extremes ∓α R/2 at 45° / 135°. The second harmonic is the part
        // even under θ → θ + 180°.
        let even = |deg: f64| (at(&run, &p, deg) + at(&run, &p, deg + 180.0)) / 2.0;
        let expect = alpha * 100.0 / 2.0;
        for (deg, sign) in [(45.0, -1.0), (135.0, 1.0)] {
            assert!(
                (even(deg) - sign * expect).abs() < 1e-3 * expect,
                "{dir} {deg}: {} vs {}",
                even(deg),
                sign * expect
            );
        }
        // Zero crossings: the nearest sample is within 0.05° (100 Hz), where the first-harmonic
        // part (α X_c ≈ 18 µm) contributes up to 18 µm · sin 0.05° ≈ 0.016 µm.
        assert!(even(0.0).abs() < 0.02 * expect && even(90.0).abs() < 0.02 * expect);
    }
}

#[test]
fn servo_lag_difference_is_a_45_degree_ellipse_that_flips_with_direction_and_grows_with_feed() {
    let m = column(vec![TermSpec::ServoLag { axis: Axis::X }]);
    let tau = 2e-3; // s: X lags 2 ms more than Y
    let mut amp = Vec::new();
    for feed in [1000.0, 2000.0] {
        let v = feed / 60.0;
        let (ccw_run, ccw) = response(&m, xy(Direction::CCW, feed), "TX", tau);
        let (cw_run, cw) = response(&m, xy(Direction::CW, feed), "TX", tau);
        // CCW: ΔR = V τ_X u v, +V τ/2 at 45°.
        let a = at(&ccw_run, &ccw, 45.0);
        assert!((a - v * tau / 2.0).abs() < 1e-2 * v * tau, "{a}");
        assert!((at(&cw_run, &cw, 45.0) + a).abs() < 1e-2 * a.abs(), "flips with direction");
        assert!((at(&ccw_run, &ccw, 135.0) + a).abs() < 1e-2 * a.abs(), "ellipse at 45°");
        amp.push(a);
    }
    assert!((amp[1] / amp[0] - 2.0).abs() < 1e-2, "proportional to feed: {amp:?}");
}

#[test]
fn backlash_steps_at_its_axis_reversals() {
    let m = column(vec![TermSpec::Backlash { axis: Axis::X }]);
    let b = 4e-3; // mm
    for dir in [Direction::CW, Direction::CCW] {
        let (run, p) = response(&m, xy(dir, 1000.0), "BX", b);
        // X reverses at 0° and 180°: the step across each reversal is B in size, and the value
        // near 90° (X moving fastest) is zero because u = 0 there.
        for rev in [0.0, 180.0] {
            let before = at(&run, &p, rev - 3.0);
            let after = at(&run, &p, rev + 3.0);
            assert!(
                ((before - after).abs() - b).abs() < 0.01 * b,
                "{dir} step at {rev}: {before} {after}"
            );
        }
        assert!(at(&run, &p, 90.0).abs() < 0.01 * b);
        // Y's reversals show nothing.
        assert!((at(&run, &p, 89.5) - at(&run, &p, 90.5)).abs() < 0.02 * b);
    }
}

#[test]
fn scale_error_is_an_ellipse_along_the_axes_the_same_both_directions() {
    let m = column(vec![TermSpec::Positional { axis: Axis::X, degrees: vec![1] }]);
    let theta = 10e-3 * 250.0 / 1000.0; // 10 µm/m scale... at L = 250 mm: 2.5e-3 mm
    for dir in [Direction::CW, Direction::CCW] {
        let (run, p) = response(&m, xy(dir, 1000.0), "EXX1", theta);
        // ΔX = θ X/L: ΔR = θ (X/L) cosθ; about the centre the u² part is θ R/L at 0° and 180°.
        let quad = |deg: f64| at(&run, &p, deg);
        let ellipse = (quad(0.0) + quad(180.0)) / 2.0 - (quad(90.0) + quad(270.0)) / 2.0;
        assert!((ellipse - theta * 100.0 / 250.0).abs() < 1e-3 * ellipse, "{ellipse}");
    }
}

#[test]
fn centring_and_bar_length_signs() {
    let m = column(vec![]);
    let (run, p) = response(&m, xy(Direction::CCW, 1000.0), "CX@t", 1e-3);
    // Table ball displaced +X by 1 µm: at 0° the tool ball is at +X, so the bar shortens.
    assert!((at(&run, &p, 0.0) + 1e-3).abs() < 1e-9 && (at(&run, &p, 180.0) - 1e-3).abs() < 1e-9);
    let (_, p) = response(&m, xy(Direction::CCW, 1000.0), "BAR", 2e-3);
    assert!(p.iter().all(|x| (x - 2e-3).abs() < 1e-12));
}

#[test]
fn straightness_ties_pitch_and_yaw_with_the_documented_signs() {
    // A linear X joint with straightness toward Y: ε_Z = +∂δ_Y/∂X; toward Z: ε_Y = -∂δ_Z/∂X.
    let m = column(vec![
        TermSpec::Straightness {
            axis: Axis::X,
            toward: Axis::Y,
            degrees: vec![2],
            tie_angles: true,
        },
        TermSpec::Straightness {
            axis: Axis::X,
            toward: Axis::Z,
            degrees: vec![2],
            tie_angles: true,
        },
        TermSpec::Straightness {
            axis: Axis::Y,
            toward: Axis::X,
            degrees: vec![2],
            tie_angles: true,
        },
    ]);
    let st = crate::JointState { q: 125.0, ..Default::default() };
    let b = |id: &str| m.terms.iter().find(|t| t.term.id() == id).unwrap().term.basis(&st).unwrap();
    let s = 125.0 / 250.0;
    let dsdq = 2.0 * s / 250.0;
    assert_eq!(b("EYX2"), [0.0, s * s, 0.0, 0.0, 0.0, dsdq]);
    assert_eq!(b("EZX2"), [0.0, 0.0, s * s, 0.0, -dsdq, 0.0]);
    assert_eq!(b("EXY2"), [s * s, 0.0, 0.0, 0.0, 0.0, -dsdq]);
}

/// Exact ball distance with error motions on every joint.
fn exact_distance(model: &Model, q: &[f64; 6], run: &Run, errs: &[Vec<ErrorMotion>; 2]) -> f64 {
    let h = &run.header;
    let balls = model.chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
    let p = model.chain.pose(q, &balls, Some(&errs[0]), Some(&errs[1]));
    (p.tool_ball - p.table_ball).norm()
}

#[test]
fn chain_sensitivities_match_finite_differences_of_the_exact_chain_with_rotary_joints() {
    // A five-axis chain: tool branch X, Z, B head (pivot 150 mm above the gauge point);
    // workpiece branch Y, then an A trunnion and a C table offset from the A axis.
    let spec = MachineSpec {
        name: "fd".into(),
        version: "0".into(),
        description: "".into(),
        tool: vec![
            joint("X", Axis::X, JointKind::Linear, [1., 0., 0.], [10., 0., 0.]),
            joint("Z", Axis::Z, JointKind::Linear, [0., 0., 1.], [0., 5., 400.]),
            joint("B", Axis::B, JointKind::Rotary, [0., 1., 0.], [0., 0., 150.]),
            joint("spindle", Axis::A, JointKind::Rotary, [1., 0.2, 0.], [0., 0., -150.]),
        ],
        workpiece: vec![
            joint("Y", Axis::Y, JointKind::Linear, [0., 1., 0.], [0., 0., 0.]),
            joint("C", Axis::C, JointKind::Rotary, [0.01, 0., 1.], [20., -30., 80.]),
        ],
        normalisation: vec![],
        terms: vec![],
    };
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    let mut run = xy(Direction::CCW, 1000.0);
    run.header.tool_ball_mm = [3.0, -2.0, -120.0];
    let q = [310.0, 180.0, -295.0, 0.3, -0.4, 1.1];
    // The nominal ball distance at this q is whatever the chain gives; derivatives are what count.
    let balls = model.chain.ball_setup(&run.header.pivot_mm, &run.header.tool_ball_mm);
    let pose = model.chain.pose(&q, &balls, None, None);
    let (mut st, mut sw) = (Vec::new(), Vec::new());
    sensitivities(&pose, &mut st, &mut sw);
    let zero = || [vec![[0.0; 6]; 4], vec![[0.0; 6]; 2]];
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    for (bi, branch) in [Branch::Tool, Branch::Workpiece].into_iter().enumerate() {
        let n = model.chain.branch(branch).len();
        for j in 0..n {
            for c in 0..6 {
                let mut plus = zero();
                let mut minus = zero();
                plus[bi][j][c] = h;
                minus[bi][j][c] = -h;
                let fd = (exact_distance(&model, &q, &run, &plus)
                    - exact_distance(&model, &q, &run, &minus))
                    / (2.0 * h);
                let sens = if bi == 0 { &st[j] } else { &sw[j] };
                let mut e = [0.0; 6];
                e[c] = 1.0;
                let an = sens.apply(&e);
                // Central differences of a smooth function at h = 1e-6: error ~h² · (second
                // derivative ~ arm²/R ~ 1e3) ~ 1e-9 plus rounding ~1e-16·400/1e-6 ~ 4e-8.
                worst = worst.max((fd - an).abs());
                assert!(
                    (fd - an).abs() < 1e-6 * (1.0 + an.abs()),
                    "branch {bi} joint {j} comp {c}: fd {fd} analytic {an}"
                );
            }
        }
    }
    assert!(worst > 0.0);
}

#[test]
fn ball_setup_puts_the_balls_together_at_the_pivot_and_r_apart_on_the_circle() {
    let m = column(vec![]);
    let run = xy(Direction::CCW, 1000.0);
    let h = &run.header;
    let balls = m.chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
    let mut q = [0.0; 6];
    q[..3].copy_from_slice(&h.pivot_mm);
    let p = m.chain.pose(&q, &balls, None, None);
    assert!((p.tool_ball - p.table_ball).norm() < 1e-9);
    let mut scratch = RowScratch::default();
    let runs = vec![run];
    let d = Design::new(&m, &runs).unwrap();
    let mut row = vec![0.0; d.n_cols()];
    d.row(0, 10, &mut scratch, &mut row).unwrap();
    let q10 = [runs[0].axis(Axis::X).unwrap()[10], runs[0].axis(Axis::Y).unwrap()[10]];
    let r = ((q10[0] - 300.0).powi(2) + (q10[1] - 200.0).powi(2)).sqrt();
    assert!((r - 100.0).abs() < 1e-5);
}

#[test]
fn a_bad_machine_description_is_an_error_not_a_panic() {
    let mut spec = column(vec![]).spec;
    spec.tool[0].direction = [0.0, 0.0, 0.0];
    let e = Model::new(spec, ModelOptions::default()).unwrap_err();
    assert!(e.to_string().contains("non-zero"), "{e}");
    let mut spec = column(vec![]).spec;
    spec.terms.push(TermSpec::Backlash { axis: Axis::C });
    assert!(Model::new(spec, ModelOptions::default()).is_err());
}

#[test]
fn the_small_rotation_series_equals_the_closed_form() {
    use nalgebra::{UnitQuaternion, Vector3};
    // Below |φ| = 1e-3 the error transform uses a Taylor series (chain.rs); it must agree with
    // the closed form to rounding (a few 1e-16) on both sides of the switch.
    for phi in [1e-12, 1e-7, 1e-4, 9.99e-4, 1.001e-3, 0.3] {
        for dir in [[1.0, 0.0, 0.0], [0.0, 0.6, -0.8], [0.48, -0.6, 0.64]] {
            let v = Vector3::new(dir[0], dir[1], dir[2]) * phi;
            let got = crate::chain::error_transform(&[0.1, -0.2, 0.3, v.x, v.y, v.z]);
            let want = UnitQuaternion::from_scaled_axis(v);
            let diff = (got.rotation.coords - want.coords).norm();
            assert!(diff < 4e-16, "φ = {phi}: {diff:e}");
            assert_eq!(got.translation.vector, Vector3::new(0.1, -0.2, 0.3));
        }
    }
}

#[test]
fn chunked_evaluation_equals_the_sample_by_sample_one() {
    // `fill_run` and `exact_run` (chunks of 256, batched bases) must give the numbers of
    // `row` and `exact` bit for bit up to summation order: 1e-15 relative.
    let base = column(crate::machine::paper_terms());
    // With a run term (a vibration: a pair of columns per run) too.
    let vib = [crate::Effect::Vibration { axis: Axis::X, frequency_hz: 17.0 }];
    let mut model =
        Model::with_effects(base.spec.clone(), base.options, &crate::NoKernels, &vib).unwrap();
    model.reading_terms.push(crate::machine::ReadingTerm::PlaneMismatch(Plane::XY));
    let runs = vec![xy(Direction::CW, 1000.0), xy(Direction::CCW, 2500.0)];
    let d = Design::new(&model, &runs).unwrap();
    let n = d.n_cols();
    // A machine state with every parameter non-zero, ~10 µm / 50 µrad / 1 ms.
    let theta: Vec<f64> = (0..n)
        .map(|j| {
            1e-2 * ((j as f64 * 0.7).sin() + 0.2)
                * d.parameters[j].unit.display_factor().recip()
                * 1e3
        })
        .collect();
    let mut scratch = crate::BlockScratch::default();
    for r in 0..runs.len() {
        let m = runs[r].len();
        let cols: Vec<usize> = (0..n).collect();
        let mut block = vec![0.0; m * n];
        let mut targets = vec![0.0; m];
        d.fill_run(r, &cols, &mut block, &mut targets, &mut scratch).unwrap();
        let mut row = vec![0.0; n];
        let mut rs = RowScratch::default();
        let exact = d.exact_run_with(r, &theta, &mut scratch).unwrap();
        for i in 0..m {
            let b = d.row(r, i, &mut rs, &mut row).unwrap();
            assert_eq!(b, targets[i]);
            for j in 0..n {
                assert!(
                    (row[j] - block[j * m + i]).abs() <= 1e-15 * row[j].abs().max(1.0),
                    "run {r} row {i} col {j}"
                );
            }
            let one = d.exact(r, i, &theta).unwrap();
            assert!(
                (one - exact[i]).abs() < 1e-15 * d.runs[r].header.radius_mm,
                "exact {r} {i}: {one} {}",
                exact[i]
            );
        }
    }
}

/// A term that hides its single component: the design fills its columns through
/// `basis_batch` and the six-component path.
#[derive(Debug)]
struct SixComponents(std::sync::Arc<dyn crate::ErrorTerm>);

impl crate::ErrorTerm for SixComponents {
    fn id(&self) -> &str {
        self.0.id()
    }
    fn label(&self) -> &str {
        self.0.label()
    }
    fn unit(&self) -> crate::Unit {
        self.0.unit()
    }
    fn class(&self) -> crate::term::TermClass {
        self.0.class()
    }
    fn basis_batch(
        &self,
        states: &[JointState],
        out: &mut [ErrorMotion],
    ) -> Result<(), crate::term::TermError> {
        self.0.basis_batch(states, out)
    }
}

#[test]
fn a_column_of_one_component_is_the_six_component_paths_to_the_bit() {
    // Every built-in shape of one component (the paper's polynomials, squareness, backlash,
    // lag; spikes and transients with ringing per side, cyclic and vibration, drift, growth
    // with and without a time constant, stick-slip): `fill_run` takes its values from
    // `component_batch` and scales them in place; the same terms hiding that (`basis_batch`
    // only) go through the six components. The columns must agree bit for bit (zeros' signs
    // included), as the diagnosis's digests do.
    let base = column(crate::machine::paper_terms());
    let effects = [
        crate::Effect::ReversalSpike { axis: Axis::X, tau_ms: 20.0 },
        crate::Effect::ReversalTransient {
            axis: Axis::Y,
            tau_ms: 30.0,
            period_ms: Some(40.0),
            per_side: true,
        },
        crate::Effect::CyclicError { axis: Axis::X, pitch_mm: 5.0 },
        crate::Effect::Vibration { axis: Axis::Y, frequency_hz: 17.0 },
        crate::Effect::ThermalDrift { axis: Some(Axis::X) },
        crate::Effect::ThermalGrowth { axis: Axis::Y, time_constant_min: None },
        crate::Effect::ThermalGrowth { axis: Axis::X, time_constant_min: Some(20.0) },
        crate::Effect::StickSlip { axis: Axis::X, speed_mm_per_min: 300.0 },
        crate::Effect::StickSlip { axis: Axis::Z, speed_mm_per_min: 300.0 },
    ];
    let fast =
        Model::with_effects(base.spec.clone(), base.options, &crate::NoKernels, &effects).unwrap();
    let mut slow = fast.clone();
    for t in slow.terms.iter_mut().chain(slow.run_terms.iter_mut()) {
        t.term = std::sync::Arc::new(SixComponents(t.term.clone()));
    }
    let single = fast
        .terms
        .iter()
        .chain(&fast.run_terms)
        .filter(|t| t.term.component_batch(&[JointState::default()], &mut [0.0]).is_some())
        .count();
    assert!(single >= 20, "{single} terms of one component");
    let runs = vec![xy(Direction::CW, 1000.0), xy(Direction::CCW, 2500.0)];
    let (df, ds) = (Design::new(&fast, &runs).unwrap(), Design::new(&slow, &runs).unwrap());
    let n = df.n_cols();
    let cols: Vec<usize> = (0..n).collect();
    let mut scratch = crate::BlockScratch::default();
    for r in 0..runs.len() {
        let m = runs[r].len();
        let (mut a, mut b, mut t) = (vec![0.0; m * n], vec![0.0; m * n], vec![0.0; m]);
        df.fill_run(r, &cols, &mut a, &mut t, &mut scratch).unwrap();
        ds.fill_run(r, &cols, &mut b, &mut t, &mut scratch).unwrap();
        for (k, (x, y)) in a.iter().zip(&b).enumerate() {
            assert_eq!(x.to_bits(), y.to_bits(), "run {r} column {} row {}: {x} {y}", k / m, k % m);
        }
        // Some columns are zero in this run (stick-slip of Z in an XY run): both +0.
        assert!((0..n).any(|c| a[c * m..(c + 1) * m].iter().all(|x| x.to_bits() == 0)));
    }
}

#[test]
fn rows_of_a_run_filled_by_parts_are_the_rows_of_the_whole_run() {
    // `fill_rows` over any range (here starting mid-chunk and crossing chunk boundaries of 256)
    // gives exactly the whole run's rows there: a fit streams a run through it.
    let base = column(crate::machine::paper_terms());
    let vib = [crate::Effect::Vibration { axis: Axis::X, frequency_hz: 17.0 }];
    let model =
        Model::with_effects(base.spec.clone(), base.options, &crate::NoKernels, &vib).unwrap();
    let runs = vec![xy(Direction::CW, 1000.0)];
    let d = Design::new(&model, &runs).unwrap();
    let n = d.n_cols();
    let m = runs[0].len();
    let cols: Vec<usize> = (0..n).rev().collect();
    let mut scratch = crate::BlockScratch::default();
    let (mut whole, mut whole_b) = (vec![0.0; m * n], vec![0.0; m]);
    d.fill_run(0, &cols, &mut whole, &mut whole_b, &mut scratch).unwrap();
    for range in [0..m, 100..700, 255..257, m - 3..m, 5..5] {
        let len = range.len();
        let (mut part, mut part_b) = (vec![0.0; len * n], vec![0.0; len]);
        d.fill_rows(0, range.clone(), &cols, &mut part, &mut part_b, &mut scratch).unwrap();
        for i in 0..len {
            assert_eq!(part_b[i], whole_b[range.start + i], "{range:?} target {i}");
            for c in 0..n {
                assert_eq!(part[c * len + i], whole[c * m + range.start + i], "{range:?} {i} {c}");
            }
        }
    }
}

#[test]
fn rotary_location_errors_move_the_axis_line_physically_whatever_the_angle() {
    // A C table on a Y saddle; tool on Z. ISO 230-7: E_X0C shifts the C axis line by +X,
    // E_A0C tilts it about X through the joint origin; the table is where the nominal chain
    // puts it at C = 0, and turns about the moved line: a point v from the line moves by
    // (I − R) o for an offset o, by ε × (R v₀) − R (ε × v₀) for a tilt ε (v₀ = Rᵀ v, the
    // point at C = 0), R the table's physical rotation. The zero error E_C0C turns the table
    // by ε about its own line at every C: ε × v. Stated physically, on the workpiece branch.
    let origin = [20.0, -30.0, 80.0];
    let spec = MachineSpec {
        name: "c-table".into(),
        version: "0".into(),
        description: "".into(),
        tool: vec![joint("Z", Axis::Z, JointKind::Linear, [0., 0., 1.], [0., 0., 0.])],
        workpiece: vec![
            joint("Y", Axis::Y, JointKind::Linear, [0., 1., 0.], [0., 0., 0.]),
            joint("C", Axis::C, JointKind::Rotary, [0., 0., 1.], origin),
        ],
        normalisation: vec![],
        terms: vec![TermSpec::RotaryLocation {
            axis: Axis::C,
            components: vec![Axis::X, Axis::Y, Axis::A, Axis::B, Axis::C],
        }],
    };
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    let ids: Vec<&str> = model.terms.iter().map(|t| t.term.id()).collect();
    assert_eq!(ids, ["EX0C", "EY0C", "EA0C", "EB0C", "EC0C"]);
    let balls = crate::chain::BallSetup {
        tool_ball: nalgebra::Vector3::zeros(),
        table_ball: nalgebra::Vector3::new(60.0, 10.0, 25.0),
    };
    for c_rad in [0.0, 0.7, -2.0] {
        let q = [0.0, 40.0, 0.0, 0.0, 0.0, c_rad];
        let nominal = model.chain.pose(&q, &balls, None, None).table_ball;
        let o = nalgebra::Vector3::from(origin) + nalgebra::Vector3::new(0.0, -40.0, 0.0);
        let pose = model.chain.pose(&q, &balls, None, None);
        let r = pose.base_from_work_joint.last().unwrap().rotation;
        let v = nominal - o;
        let v0 = r.inverse() * v;
        let offset = |t: nalgebra::Vector3<f64>| t - r * t;
        let tilt = |e: nalgebra::Vector3<f64>| e.cross(&v) - r * e.cross(&v0);
        for (k, physical) in [
            (0, offset(nalgebra::Vector3::new(1e-3, 0.0, 0.0))),
            (1, offset(nalgebra::Vector3::new(0.0, 1e-3, 0.0))),
            (2, tilt(nalgebra::Vector3::new(1e-5, 0.0, 0.0))),
            (3, tilt(nalgebra::Vector3::new(0.0, 1e-5, 0.0))),
            (4, nalgebra::Vector3::new(0.0, 0.0, 1e-5).cross(&v)),
        ] {
            let value = if k < 2 { 1e-3 } else { 1e-5 };
            let st = JointState { q: c_rad, ..Default::default() };
            let b = model.terms[k].term.basis(&st).unwrap();
            let e: ErrorMotion = std::array::from_fn(|i| b[i] * value);
            let moved = model.chain.pose(&q, &balls, None, Some(&[[0.0; 6], e])).table_ball;
            // First order in 1e-5 rad: the exact transform differs by ~|ε|²·arm ≈ 1e-8 mm.
            assert!(
                (moved - nominal - physical).norm() < 1e-8,
                "{} at C = {c_rad}: {:?} vs {:?}",
                ids[k],
                moved - nominal,
                physical
            );
        }
    }
    let bad = MachineSpec {
        terms: vec![TermSpec::RotaryLocation { axis: Axis::C, components: vec![Axis::Z] }],
        ..model.spec.clone()
    };
    assert!(Model::new(bad, ModelOptions::default()).unwrap_err().to_string().contains("EZ0C"));
}

#[test]
fn angular_error_motions_are_untied_rotations_of_a_linear_axis() {
    let m = column(vec![TermSpec::Angular { axis: Axis::X, about: Axis::Z, degrees: vec![1, 2] }]);
    let ids: Vec<&str> = m.terms.iter().map(|t| t.term.id()).collect();
    assert_eq!(ids, ["ECX1", "ECX2"]);
    assert_eq!(m.terms[0].term.unit(), crate::Unit::Angle);
    let st = JointState { q: 125.0, ..Default::default() };
    // s = 125/250 = 0.5: ε_Z = s and s².
    assert_eq!(m.terms[0].term.basis(&st).unwrap(), [0.0, 0.0, 0.0, 0.0, 0.0, 0.5]);
    assert_eq!(m.terms[1].term.basis(&st).unwrap(), [0.0, 0.0, 0.0, 0.0, 0.0, 0.25]);
}

/// ΔR (mm) along a run of the column machine with one effect whose coefficients are `values`.
fn effect_response(effect: crate::Effect, run: Run, values: &[f64]) -> (Run, Vec<f64>) {
    let base = column(vec![]);
    let m = Model::with_effects(
        base.spec.clone(),
        ModelOptions::default(),
        &crate::NoKernels,
        &[effect],
    )
    .unwrap();
    let runs = vec![run];
    let d = Design::new(&m, &runs).unwrap();
    let mut theta = vec![0.0; d.n_cols()];
    // A run term's parameter is `ID@run`.
    let run_id = format!("@{}", runs[0].name());
    for (id, v) in m.effect_ids[0].iter().zip(values) {
        theta[d
            .parameters
            .iter()
            .position(|p| &p.id == id || p.id == format!("{id}{run_id}"))
            .unwrap()] = *v;
    }
    let pred = d.predict_run(0, &theta).unwrap();
    let [run] = <[Run; 1]>::try_from(runs).unwrap();
    (run, pred)
}

#[test]
fn a_reversal_spike_is_outward_after_each_reversal_and_decays() {
    use crate::Effect;
    let a = 6e-3; // mm
    for dir in [Direction::CW, Direction::CCW] {
        let (run, p) = effect_response(
            Effect::ReversalSpike { axis: Axis::X, tau_ms: 60.0 },
            xy(dir, 1000.0),
            &[a],
        );
        // X reverses at 0° and 180° (at 1000 mm/min on R = 100: 0.167 rad/s, 60 ms ≈ 0.57°).
        // The run starts and ends at 0°, so only the reversal at 180° lies inside it (a real
        // test's lead-in arc would show the other). Just after it the bar is longer by ≈ A
        // (the tool is pushed outward) and, 5 τ later (2.9°), the spike is below 1 %.
        let after = if dir == Direction::CCW { 0.2 } else { -0.2 };
        {
            let rev = 180.0;
            let just = at(&run, &p, rev + after);
            assert!(just > 0.6 * a && just <= a * 1.0001, "{dir} at {rev}: {just}");
            assert!(at(&run, &p, rev + 15.0 * after).abs() < 0.01 * a);
            // Before the reversal (the other side) nothing: the spike follows the reversal.
            assert!(at(&run, &p, rev - 3.0 * after).abs() < 1e-3 * a, "{dir} before {rev}");
        }
    }
}

#[test]
fn lateral_play_steps_x_at_the_reversals_of_y() {
    use crate::Effect;
    let l = 4e-3;
    let (run, p) = effect_response(
        Effect::LateralPlay { axis: Axis::X, switched_by: Axis::Y },
        xy(Direction::CCW, 1000.0),
        &[l],
    );
    // ΔX = -(L/2) sign(dY/dt): Y reverses at 90° and 270°, where X = X_c: the step in ΔR is
    // û_X·ΔX, zero at 90° itself (û ⟂ X) — the play shows as a first-harmonic step: ΔR at 0°
    // is -(L/2)·sign(dY/dt) = -L/2 (CCW at 0°: Y increasing), at 180° +L/2... with û_X = -1.
    assert!((at(&run, &p, 0.0) + l / 2.0).abs() < 1e-3 * l, "{}", at(&run, &p, 0.0));
    assert!((at(&run, &p, 180.0) + l / 2.0).abs() < 1e-3 * l, "{}", at(&run, &p, 180.0));
    // And the switch: between 85° and 95° dY/dt changes sign, so ΔX flips; ΔR = û_X ΔX with
    // û_X = cos θ ≈ ±0.087 there.
    let (b, c) = (at(&run, &p, 85.0), at(&run, &p, 95.0));
    assert!(
        (b + l / 2.0 * 85f64.to_radians().cos()).abs() < 1e-3 * l
            && (c - l / 2.0 * 95f64.to_radians().cos()).abs() < 1e-3 * l,
        "{b} {c}"
    );
}

#[test]
fn a_cyclic_error_is_locked_to_the_axis_position() {
    use crate::Effect;
    let c = 1.5e-3;
    let pitch = 10.0;
    // The sine part: ΔX = C sin(2π X/p). At 0° X = 400 mm (a whole number of pitches) and
    // ΔX = 0; ΔR = û_X ΔX there. The same at 1000 and 3000 mm/min: locked to position.
    for feed in [1000.0, 3000.0] {
        let (run, p) = effect_response(
            Effect::CyclicError { axis: Axis::X, pitch_mm: pitch },
            xy(Direction::CCW, feed),
            &[c, 0.0],
        );
        let x = run.axis(Axis::X).unwrap();
        for i in (0..run.len()).step_by(97) {
            let ux = (x[i] - 300.0) / 100.0;
            let want = ux * c * (std::f64::consts::TAU * x[i] / pitch).sin();
            assert!((p[i] - want).abs() < 1e-4 * c, "feed {feed} sample {i}: {} vs {want}", p[i]);
        }
    }
}

#[test]
fn a_vibration_is_locked_to_the_run_clock_with_each_run_its_own_phase() {
    use crate::Effect;
    let (a, b) = (0.8e-3, -0.3e-3);
    let f = 23.5;
    // ΔX = a sin(2π f t) + b cos(2π f t), t the run's own clock: ΔR = û_X ΔX, whatever the feed.
    for feed in [1000.0, 3000.0] {
        let (run, p) = effect_response(
            Effect::Vibration { axis: Axis::X, frequency_hz: f },
            xy(Direction::CCW, feed),
            &[a, b],
        );
        let x = run.axis(Axis::X).unwrap();
        for i in (0..run.len()).step_by(31) {
            let w = std::f64::consts::TAU * f * run.t_s[i];
            let want = (x[i] - 300.0) / 100.0 * (a * w.sin() + b * w.cos());
            assert!((p[i] - want).abs() < 1e-4 * a, "feed {feed} sample {i}: {} vs {want}", p[i]);
        }
    }
    // Two runs: two pairs of columns, after each run's centring, each zero in the other run.
    let base = column(vec![]);
    let m = Model::with_effects(
        base.spec.clone(),
        ModelOptions::default(),
        &crate::NoKernels,
        &[Effect::Vibration { axis: Axis::Y, frequency_hz: f }],
    )
    .unwrap();
    assert_eq!(m.run_terms.len(), 2);
    assert_eq!(m.effect_ids[0], ["VSY", "VCY"]);
    let mut r2 = xy(Direction::CW, 1000.0);
    r2.header.run_id = Some("second".into());
    let runs = vec![xy(Direction::CCW, 1000.0), r2];
    let d = Design::new(&m, &runs).unwrap();
    let ids: Vec<&str> = d.parameters.iter().map(|p| p.id.as_str()).collect();
    assert_eq!(d.n_machine, 1, "{ids:?}"); // the bar length only
    assert_eq!(d.run_term_columns(1), 7..9, "{ids:?}");
    assert_eq!(ids[7], "VSY@second");
    assert_eq!(d.run_of_column(7), Some(1));
    assert_eq!(d.run_of_column(0), None);
    assert!(d.parameters[7].class.is_nuisance());
    let cols: Vec<usize> = (0..d.n_cols()).collect();
    let mlen = runs[0].len();
    let mut block = vec![0.0; mlen * cols.len()];
    let mut t = vec![0.0; mlen];
    d.fill_run(0, &cols, &mut block, &mut t, &mut crate::BlockScratch::default()).unwrap();
    let energy = |c: usize| block[c * mlen..(c + 1) * mlen].iter().map(|x| x * x).sum::<f64>();
    assert!(energy(3) > 0.0 && energy(4) > 0.0 && energy(7) == 0.0 && energy(8) == 0.0);
    // As a machine's own term (one phase for all runs) it is refused.
    let bad = MachineSpec {
        terms: vec![TermSpec::Vibration { axis: Axis::X, frequency_hz: f }],
        ..base.spec.clone()
    };
    assert!(
        Model::new(bad, ModelOptions::default())
            .unwrap_err()
            .to_string()
            .contains("each run's own phase")
    );
}

#[test]
fn a_runs_own_bar_length_is_one_constant_of_its_reading_and_none_of_anothers() {
    use crate::Effect;
    // ΔR = c in every sample of the run, whatever the direction or feed.
    let c = 0.3e-3;
    for feed in [500.0, 2000.0] {
        let (_, p) = effect_response(Effect::BarLengthDrift, xy(Direction::CW, feed), &[c]);
        assert!(p.iter().all(|x| (x - c).abs() < 1e-15), "feed {feed}: {:?}", &p[..3]);
    }
    // Two runs: one column each, after the run's centring, `BAR@run`, a nuisance; each 1 in its
    // run (the row, the chunked block and the exact value agree) and 0 in the other.
    let base = column(vec![]);
    let m = Model::with_effects(
        base.spec.clone(),
        ModelOptions::default(),
        &crate::NoKernels,
        &[Effect::BarLengthDrift],
    )
    .unwrap();
    assert_eq!((m.run_terms.len(), m.run_reading_terms.len()), (0, 1));
    assert_eq!(m.effect_ids[0], ["BAR"]);
    let mut r2 = xy(Direction::CW, 1000.0);
    r2.header.run_id = Some("second".into());
    let runs = vec![xy(Direction::CCW, 1000.0), r2];
    let d = Design::new(&m, &runs).unwrap();
    let ids: Vec<&str> = d.parameters.iter().map(|p| p.id.as_str()).collect();
    assert_eq!(d.run_term_columns(1), 6..7, "{ids:?}");
    assert_eq!(ids[6], "BAR@second");
    assert!(d.parameters[6].class.is_nuisance());
    let cols: Vec<usize> = (0..d.n_cols()).collect();
    let m1 = runs[1].len();
    let mut block = vec![0.0; m1 * cols.len()];
    let mut t = vec![0.0; m1];
    d.fill_run(1, &cols, &mut block, &mut t, &mut crate::BlockScratch::default()).unwrap();
    assert!(block[6 * m1..7 * m1].iter().all(|&x| x == 1.0));
    assert!(block[3 * m1..4 * m1].iter().all(|&x| x == 0.0), "run 0's column in run 1");
    let mut row = vec![0.0; d.n_cols()];
    d.row(1, 17, &mut crate::RowScratch::default(), &mut row).unwrap();
    assert_eq!((row[3], row[6]), (0.0, 1.0));
    let mut theta = vec![0.0; d.n_cols()];
    theta[6] = c;
    let exact = d.exact_run(1, &theta).unwrap();
    assert!((exact[17] - d.exact(1, 17, &theta).unwrap()).abs() < 1e-15);
    theta[6] = 0.0;
    let without = d.exact_run(1, &theta).unwrap();
    assert!(exact.iter().zip(&without).all(|(a, b)| (a - b - c).abs() < 1e-12));
}

#[test]
fn stick_slip_acts_near_reversals_and_widens_at_low_feed() {
    use crate::Effect;
    let s = 2e-3;
    let width = |feed: f64| {
        let (_, p) = effect_response(
            Effect::StickSlip { axis: Axis::X, speed_mm_per_min: 200.0 },
            xy(Direction::CCW, feed),
            &[s],
        );
        p.iter().filter(|x| x.abs() > 0.1 * s).count() as f64 / p.len() as f64
    };
    // X is slower than 200 mm/min where |sin θ| < 200/F: a share ≈ (2/π) asin(200/F) of the
    // circle, less the part where the step is below 10 %.
    let (lo, hi) = (width(500.0), width(2000.0));
    assert!(lo > 2.0 * hi && hi > 0.0 && lo < 0.3, "{lo} {hi}");
}

#[test]
fn drifts_follow_the_session_clock() {
    use crate::Effect;
    let g = 1e-3 / 3600.0; // 1 µm/h in mm/s
    let mut run = xy(Direction::CCW, 1000.0);
    run.header.started_at_unix_s = 0.0;
    let (_, bar) = effect_response(Effect::ThermalDrift { axis: None }, run.clone(), &[g]);
    // The bar grows by g·t: at the last sample t = run duration.
    let t_end = *run.t_s.last().unwrap();
    assert!((bar.last().unwrap() - g * t_end).abs() < 1e-15 && bar[0] == 0.0);
    let (_, x) = effect_response(Effect::ThermalDrift { axis: Some(Axis::X) }, run.clone(), &[g]);
    // ΔX = g t: ΔR = û_X g t; at the last sample (back at 0°, û_X = 1).
    // The last sample is within 0.1° of 0°: û_X = cos θ differs from 1 by < 2e-6.
    assert!((x.last().unwrap() - g * t_end).abs() < 2e-6 * g * t_end);
}

#[test]
fn a_run_that_starts_just_after_a_reversal_has_it() {
    use crate::design::start_reversal;
    // X = R cos θ on a circle at ω; samples every Δt from θ₀.
    let (r, omega, dt) = (50.0, 0.5, 0.008);
    let run = |theta0: f64| -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..20).map(|i| f64::from(i) * dt).collect();
        let x = t.iter().map(|t| r * (theta0 + omega * t).cos()).collect();
        (t, x)
    };
    // Half a sample after the reversal at 180° (a Renishaw full circle): t₀ − Δt/2.
    let (t, x) = run(std::f64::consts::PI + omega * dt / 2.0);
    let at = start_reversal(&t, &x).expect("a reversal before the first sample");
    assert!((at + dt / 2.0).abs() < 1e-3 * dt, "{at}");
    // Exactly at the reversal: t₀.
    let (t, x) = run(0.0);
    assert!(start_reversal(&t, &x).expect("at the first sample").abs() < 1e-3 * dt);
    // Two samples after it: found, two samples back.
    let (t, x) = run(std::f64::consts::PI + 2.0 * omega * dt);
    let at = start_reversal(&t, &x).expect("two samples back");
    assert!((at + 2.0 * dt).abs() < 1e-2 * dt, "{at}");
    // Eight samples after it: beyond the reach of the extrapolation; none.
    let (t, x) = run(std::f64::consts::PI + 8.0 * omega * dt);
    assert_eq!(start_reversal(&t, &x), None);
    // Far from any reversal (Y at θ = 0 moves at full speed): none.
    let t: Vec<f64> = (0..20).map(|i| f64::from(i) * dt).collect();
    let y: Vec<f64> = t.iter().map(|t| r * (omega * t).sin()).collect();
    assert_eq!(start_reversal(&t, &y), None);
}

#[test]
fn a_reversal_transient_per_side_is_outward_at_each_end_with_its_own_height_and_shape() {
    use crate::Effect;
    use crate::design::{reversal_times, since_last, start_reversal, velocity_and_direction};
    use crate::term::{TransientPart, transient};
    let (tau_ms, period_ms) = (40.0, 120.0);
    let effect = Effect::ReversalTransient {
        axis: Axis::X,
        tau_ms,
        period_ms: Some(period_ms),
        per_side: true,
    };
    // The positive end (X at 0°, where X turns + → −): a rise from zero (the sine part), 3 µm;
    // the negative end (180°): a decaying start (part 0), 2 µm, and some of part 2.
    let coeffs = [0.0, 3e-3, 0.0, 2e-3, 0.0, 0.5e-3];
    for dir in [Direction::CCW, Direction::CW] {
        // From 90°: both reversals of X lie inside the run.
        let circle = CircleTest { start_deg: 90.0, ..circle_xy(dir, 1000.0) };
        let (run, p) = effect_response(
            effect.clone(),
            circle.run("2026-11-21T10:00:00Z", 0.0, "t", "test"),
            &coeffs,
        );
        let x = run.axis(Axis::X).unwrap();
        let n = run.len();
        let (v, d): (Vec<f64>, Vec<f64>) =
            (0..n).map(|i| velocity_and_direction(&run.t_s, x, i)).unzip();
        let mut rev = reversal_times(&run.t_s, &v, &d);
        rev.extend(start_reversal(&run.t_s, x));
        rev.sort_by(f64::total_cmp);
        assert_eq!(rev.len(), 2, "{dir}: {rev:?}");
        let omega = std::f64::consts::TAU / (period_ms * 1e-3);
        let (mut seen_pos, mut seen_neg) = (0.0f64, 0.0f64);
        for i in 0..n {
            let t = since_last(&rev, run.t_s[i]);
            let h = |a: &[f64]| {
                TransientPart::ALL
                    .iter()
                    .zip(a)
                    .map(|(&part, c)| c * transient(t, tau_ms * 1e-3, omega, part))
                    .sum::<f64>()
            };
            // ΔX = -s Σ a_k h_k: outward (+X) after the positive end, where s = -1; (−X) after
            // the negative end. ΔR = û_X ΔX, û_X = ±1 there: the bar longer at both ends.
            let dx = if d[i] < 0.0 {
                h(&coeffs[..3])
            } else if d[i] > 0.0 {
                -h(&coeffs[3..])
            } else {
                0.0
            };
            let ux = (x[i] - run.header.pivot_mm[0]) / run.header.radius_mm;
            assert!(
                (p[i] - ux * dx).abs() < 1e-9,
                "{dir} sample {i}: {} against {}",
                p[i],
                ux * dx
            );
            if t.is_finite() && t < 0.3 {
                if d[i] < 0.0 {
                    seen_pos = seen_pos.max(p[i])
                } else {
                    seen_neg = seen_neg.max(p[i])
                }
            }
        }
        // Each end its own height: the sine part peaks at 3 µm · e^{-t*/τ} sin(ωt*)/(ωτ) (0.25
        // of 3 µm, 21 ms after the reversal; the samples, 10 ms apart, catch it within 5 %),
        // the negative end starts at 2 µm (its first sample, within 10 ms of the reversal, at
        // least e^{-10/40} = 0.78 of that).
        let (peak_pos, at_pos) =
            crate::effect::transient_peak(tau_ms, Some(period_ms), [0.0, 3e-3, 0.0]);
        assert!(
            (seen_pos - peak_pos).abs() < 0.05 * peak_pos && at_pos > 5.0,
            "{dir}: positive end {seen_pos} against {peak_pos} at {at_pos} ms"
        );
        assert!(
            seen_neg > 0.78 * 2e-3 && seen_neg <= 2.0e-3 * (1.0 + 1e-9) + 0.5e-3,
            "{dir}: negative end {seen_neg}"
        );
    }
    // The reported heights are the fitted transients' peaks, linear in the coefficients at
    // their peaks.
    let r = effect.report(&coeffs);
    let get = |k: &str| r.iter().find(|p| p.0 == k).unwrap().1;
    let (peak_neg, _) = crate::effect::transient_peak(tau_ms, Some(period_ms), [2e-3, 0.0, 0.5e-3]);
    assert!(
        (get("amplitude_pos_um")
            - 3.0 * crate::effect::transient_peak(tau_ms, Some(period_ms), [0.0, 1.0, 0.0]).0)
            .abs()
            < 1e-9
    );
    assert!((get("amplitude_neg_um") - 1e3 * peak_neg).abs() < 1e-9);
    for (name, w) in effect.linear_parameters(&coeffs) {
        let lin: f64 = w.iter().zip(&coeffs).map(|(a, b)| a * b).sum();
        assert!(
            (lin - get(&name)).abs() < 1e-9 * get(&name).abs(),
            "{name}: {lin} against {}",
            get(&name)
        );
    }
}

#[test]
fn thermal_growth_scales_the_axis_with_the_session_clock_about_its_origin() {
    use crate::Effect;
    // Two XY runs, the second 30 min after the first; X grows by θ g(t) X (module docs).
    let first = xy(Direction::CCW, 1000.0);
    let mut later = xy(Direction::CCW, 1000.0);
    later.header.started_at_unix_s = first.header.started_at_unix_s + 1800.0;
    later.header.run_id = Some("later".into());
    for (tc, theta) in [(None, 10e-6 / 3600.0), (Some(20.0), 15e-6)] {
        let base = column(vec![]);
        let m = Model::with_effects(
            base.spec.clone(),
            ModelOptions::default(),
            &crate::NoKernels,
            &[Effect::ThermalGrowth { axis: Axis::X, time_constant_min: tc }],
        )
        .unwrap();
        let runs = vec![first.clone(), later.clone()];
        let d = Design::new(&m, &runs).unwrap();
        let mut v = vec![0.0; d.n_cols()];
        v[d.parameters.iter().position(|p| p.id == "TGX").unwrap()] = theta;
        let pred = d.predict_run(1, &v).unwrap();
        // By hand: ΔR = û_X ΔX = cos φ · θ g(t) · (300 + 100 cos φ) at angle φ from +X about the
        // pivot (300, 200), t = 1800 s + the run's own time.
        let r = &runs[1];
        for i in (0..r.len()).step_by(97) {
            let t = 1800.0 + r.t_s[i];
            let g = match tc {
                None => t,
                Some(m) => 1.0 - (-t / (m * 60.0)).exp(),
            };
            let (x, y) = (r.axis(Axis::X).unwrap()[i], r.axis(Axis::Y).unwrap()[i]);
            let cos = (x - 300.0) / (x - 300.0).hypot(y - 200.0);
            let want = cos * theta * g * x;
            assert!(
                (pred[i] - want).abs() < 1e-9 * (1.0 + want.abs()) + 1e-12,
                "{tc:?} sample {i}: {} vs {want}",
                pred[i]
            );
        }
        // Positive θ: the axis grows, the bar reads longer where the tool is at +X of the pivot.
        assert!(at(r, &pred, 0.0) > 0.0 && at(r, &pred, 180.0) < 0.0);
        // The later run alone, with the session's origin given, is the same run of the session
        // (bit for bit: the same arithmetic); alone with its own start as the origin, its
        // clock restarts at 0 and the growth is g(run time), not g(1800 s + run time).
        let alone = vec![later.clone()];
        let origin = crate::design::session_start_unix_s(&runs);
        assert_eq!(origin, first.header.started_at_unix_s);
        let d1 = Design::with_origin(&m, &alone, origin).unwrap();
        assert_eq!(d1.origin_unix_s(), origin);
        let mut v1 = vec![0.0; d1.n_cols()];
        v1[d1.parameters.iter().position(|p| p.id == "TGX").unwrap()] = theta;
        assert_eq!(d1.predict_run(0, &v1).unwrap(), pred);
        let own = Design::new(&m, &alone).unwrap();
        assert_eq!(own.origin_unix_s(), later.header.started_at_unix_s);
        let restarted = own.predict_run(0, &v1).unwrap();
        let i = (0..r.len()).max_by(|&a, &b| pred[a].abs().total_cmp(&pred[b].abs())).unwrap();
        assert!(restarted[i].abs() < 0.5 * pred[i].abs(), "{} vs {}", restarted[i], pred[i]);
    }
    // The display units: ppm/h for the linear rate, ppm for the saturated size.
    let lin =
        Effect::ThermalGrowth { axis: Axis::X, time_constant_min: None }.report(&[10e-6 / 3600.0]);
    assert!((lin[0].1 - 10.0).abs() < 1e-9 && lin[0].0 == "rate_ppm_per_h");
    let sat =
        Effect::ThermalGrowth { axis: Axis::X, time_constant_min: Some(20.0) }.report(&[15e-6]);
    assert!((sat[0].1 - 15.0).abs() < 1e-9 && sat[1] == ("time_constant_min".to_string(), 20.0));
}

#[test]
fn a_feed_scaled_effect_is_the_effect_times_the_feed_ratio_to_its_exponent() {
    use crate::Effect;
    let plain = Effect::StickSlip { axis: Axis::X, speed_mm_per_min: 200.0 };
    let scaled = Effect::FeedScaled {
        effect: Box::new(plain.clone()),
        exponent: 0.8,
        reference_mm_per_min: 1000.0,
    };
    assert_eq!((scaled.kind(), scaled.axis_label()), (plain.kind(), plain.axis_label()));
    for feed in [500.0, 1000.0, 2500.0] {
        let (_, p) = effect_response(plain.clone(), xy(Direction::CW, feed), &[2e-3]);
        let (_, q) = effect_response(scaled.clone(), xy(Direction::CW, feed), &[2e-3]);
        let k = (feed / 1000.0f64).powf(0.8);
        assert!(p.iter().any(|x| x.abs() > 1e-4));
        for (a, b) in p.iter().zip(&q) {
            assert!((b - k * a).abs() < 1e-12, "{feed}: {b} vs {k} × {a}");
        }
    }
    let r = scaled.report(&[2e-3]);
    assert!(
        r.iter().any(|(n, v)| n == "feed_exponent" && *v == 0.8)
            && r.iter().any(|(n, v)| n == "amplitude_um" && (*v - 2.0).abs() < 1e-12)
    );
}

/// A five-axis machine with a rotary axis on each branch: tool branch X, Z, then a B head
/// (its line along Y, 150 mm above the ram's reference point); workpiece branch Y, then a C
/// table whose line is off the base's origin. The error terms are `terms`.
fn head_table(terms: Vec<TermSpec>) -> Model {
    let spec = MachineSpec {
        name: "b-head-c-table".into(),
        version: "0".into(),
        description: "".into(),
        tool: vec![
            joint("X", Axis::X, JointKind::Linear, [1., 0., 0.], [0., 0., 0.]),
            joint("Z", Axis::Z, JointKind::Linear, [0., 0., 1.], [0., 0., 0.]),
            joint("B", Axis::B, JointKind::Rotary, [0., 1., 0.], [0., 0., 150.]),
        ],
        workpiece: vec![
            joint("Y", Axis::Y, JointKind::Linear, [0., 1., 0.], [0., 0., 0.]),
            joint("C", Axis::C, JointKind::Rotary, [0., 0., 1.], [20.0, -30.0, 80.0]),
        ],
        normalisation: vec![],
        terms,
    };
    Model::new(spec, ModelOptions::default()).unwrap()
}

/// Where one bound term (`k`) at `value` moves the ball its branch carries, exactly (mm, base
/// frame), at machine coordinates `q` and joint state `st` of its axis; and the nominal ball
/// with the frame origin of the term's joint (on the axis line).
fn moved_ball(
    model: &Model,
    k: usize,
    value: f64,
    q: &[f64; 6],
    st: &JointState,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>, nalgebra::Vector3<f64>) {
    let balls = crate::chain::BallSetup {
        tool_ball: nalgebra::Vector3::new(5.0, -8.0, -120.0),
        table_ball: nalgebra::Vector3::new(60.0, 10.0, 25.0),
    };
    let bt = &model.terms[k];
    let b = bt.term.basis(st).unwrap();
    let mut errs =
        [vec![[0.0; 6]; model.chain.tool.len()], vec![[0.0; 6]; model.chain.workpiece.len()]];
    let bi = usize::from(bt.branch == Branch::Workpiece);
    errs[bi][bt.joint] = std::array::from_fn(|i| b[i] * value);
    let nominal = model.chain.pose(q, &balls, None, None);
    let moved = model.chain.pose(q, &balls, Some(&errs[0]), Some(&errs[1]));
    let (ball, moved_ball, frame) = match bt.branch {
        Branch::Tool => {
            (nominal.tool_ball, moved.tool_ball, nominal.base_from_tool_joint[bt.joint])
        }
        Branch::Workpiece => {
            (nominal.table_ball, moved.table_ball, nominal.base_from_work_joint[bt.joint])
        }
    };
    (moved_ball - ball, ball, frame.translation.vector)
}

#[test]
fn rotary_error_motions_move_the_body_physically_and_positioning_is_the_coordinates() {
    // ISO 230-7 error motions of the C table (workpiece branch, σ = -1) and the B head (tool
    // branch, σ = +1). Run-out and tilt are stated physically, in the parent frame (here the
    // base's orientation: the parents are linear joints), as the location errors are: run-out
    // `EXC` of size δ h(q) moves the body by +X δ h(q) whichever branch carries it; a tilt
    // `EAC` of size ε h(q) turns it about +X through the joint's origin o, a point p moving by
    // Rot(ε h) (p − o) − (p − o). The positioning error, backlash and lag are errors of the
    // coordinate (as the linear axes' positional error, backlash and lag): the body is where
    // the nominal chain puts it at the coordinate q + ε — a table therefore physically turns
    // by −ε about +Z, a head by +ε about +Y.
    use nalgebra::{Rotation3, Vector3};
    let c_terms = vec![
        TermSpec::RotaryPositioning { axis: Axis::C, harmonics: vec![1, 2] },
        TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::X, harmonics: vec![1] },
        TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::Y, harmonics: vec![2] },
        TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::Z, harmonics: vec![3] },
        TermSpec::RotaryWobble { axis: Axis::C, about: Axis::A, harmonics: vec![1] },
        TermSpec::RotaryWobble { axis: Axis::C, about: Axis::Y, harmonics: vec![2] },
        TermSpec::Backlash { axis: Axis::C },
        TermSpec::ServoLag { axis: Axis::C },
    ];
    let b_terms = vec![
        TermSpec::RotaryPositioning { axis: Axis::B, harmonics: vec![1] },
        TermSpec::RotaryRunout { axis: Axis::B, direction: Axis::X, harmonics: vec![2] },
        TermSpec::RotaryRunout { axis: Axis::B, direction: Axis::Y, harmonics: vec![1] },
        TermSpec::RotaryWobble { axis: Axis::B, about: Axis::C, harmonics: vec![1] },
        TermSpec::Backlash { axis: Axis::B },
        TermSpec::ServoLag { axis: Axis::B },
    ];
    let model = head_table([c_terms, b_terms].concat());
    let ids: Vec<&str> = model.terms.iter().map(|t| t.term.id()).collect();
    #[rustfmt::skip]
    assert_eq!(ids, [
        "ECC_S1", "ECC_C1", "ECC_S2", "ECC_C2", "EXC_S1", "EXC_C1", "EYC_S2", "EYC_C2", "EZC_S3", "EZC_C3",
        "EAC_S1", "EAC_C1", "EBC_S2", "EBC_C2", "BC", "TC",
        "EBB_S1", "EBB_C1", "EXB_S2", "EXB_C2", "EYB_S1", "EYB_C1", "ECB_S1", "ECB_C1", "BB", "TB",
    ]);
    let units: Vec<&str> = model.terms.iter().map(|t| t.term.unit().display_name()).collect();
    assert_eq!(
        &units[..16],
        [
            "µrad", "µrad", "µrad", "µrad", "µm", "µm", "µm", "µm", "µm", "µm", "µrad", "µrad",
            "µrad", "µrad", "µrad", "ms"
        ]
    );
    let (x, y, z) = (Vector3::x(), Vector3::y(), Vector3::z());
    let harmonic = |id: &str, q: f64| -> f64 {
        let (kind, n) =
            id.split_once('_').map(|(_, h)| (&h[..1], h[1..].parse::<f64>().unwrap())).unwrap();
        if kind == "S" { (n * q).sin() } else { (n * q).cos() }
    };
    // (velocity, direction) of the turning axis: both senses.
    for (angle, velocity, direction) in [(0.3, 0.2, 1.0), (1.7, -0.15, -1.0), (-2.4, 0.05, 1.0)] {
        let mut q = [310.0, 40.0, -280.0, 0.0, 0.0, 0.0];
        q[Axis::B.index()] = 0.6 * angle;
        q[Axis::C.index()] = angle;
        for (k, bt) in model.terms.iter().enumerate() {
            let id = bt.term.id();
            let a = q[bt.axis.index()];
            let st = JointState { q: a, velocity, direction, ..Default::default() };
            let (own, sigma) = if bt.axis == Axis::C { (z, -1.0) } else { (y, 1.0) };
            // 1 µm, 1 µrad, 0.05 ms (10 µrad at 0.2 rad/s): small enough for first order where
            // the statement is first order, and exact statements are checked exactly.
            let value = match bt.term.unit() {
                crate::Unit::Length => 1e-3,
                crate::Unit::Time => 5e-5,
                _ => 1e-6,
            };
            let (moved, p, o) = moved_ball(&model, k, value, &q, &st);
            let arm = p - o;
            // The coordinate's error ε, for the terms that are one.
            let coordinate_error = match id {
                "BC" | "BB" => Some(-0.5 * value * direction),
                "TC" | "TB" => Some(-value * velocity),
                _ if id.starts_with("ECC") || id.starts_with("EBB") => {
                    Some(value * harmonic(id, a))
                }
                _ => None,
            };
            let want = if let Some(eps) = coordinate_error {
                // Exactly the nominal chain at q + ε (a rotation about the axis's own line
                // composes with its nominal one).
                let mut q2 = q;
                q2[bt.axis.index()] += eps;
                let (_, p2, _) = moved_ball(&model, k, 0.0, &q2, &st);
                let at_q_plus_eps = p2 - p;
                // And physically a turn of σ ε about the line: first order, ε ≤ 1e-5 rad over
                // an arm ≤ 300 mm: second order ≤ 1.5e-8 mm.
                let physical = (own * (sigma * eps)).cross(&arm);
                assert!(
                    (at_q_plus_eps - physical).norm() < 2e-8,
                    "{id} at {angle}: {at_q_plus_eps:?} vs {physical:?}"
                );
                at_q_plus_eps
            } else {
                let h = harmonic(id, a);
                let d = [x, y, z][["X", "Y", "Z", "A", "B", "C"]
                    .iter()
                    .position(|l| id[1..2] == **l)
                    .unwrap()
                    % 3];
                if bt.term.unit() == crate::Unit::Length {
                    d * (value * h)
                } else {
                    Rotation3::from_scaled_axis(d * (value * h)) * arm - arm
                }
            };
            // The run-outs and tilts are exact rigid motions of the body; the coordinate's
            // errors too: rounding of a few 1e-13 mm.
            assert!(
                (moved - want).norm() < 1e-11,
                "{id} at {angle}: moved {moved:?}, want {want:?}"
            );
            // The displacement is as large as the coefficient makes it (no term is idle here
            // unless its harmonic or its state is zero).
            let scale = if bt.term.unit() == crate::Unit::Length { 1.0 } else { arm.norm() };
            assert!(want.norm() <= value * scale.max(1.0) * 1.0001 + 1e-15, "{id}");
        }
    }
}

#[test]
fn a_rotary_axis_s_error_motions_are_checked_when_the_model_is_built() {
    let model = head_table(vec![]);
    let build = |t: TermSpec| {
        Model::new(MachineSpec { terms: vec![t], ..model.spec.clone() }, ModelOptions::default())
            .map(|_| ())
            .map_err(|e| e.to_string())
    };
    let cases = [
        (
            TermSpec::RotaryPositioning { axis: Axis::X, harmonics: vec![1] },
            "X is not a rotary axis",
        ),
        (
            TermSpec::RotaryPositioning { axis: Axis::A, harmonics: vec![1] },
            "axis A, which drives no joint",
        ),
        (TermSpec::RotaryPositioning { axis: Axis::C, harmonics: vec![] }, "at least one harmonic"),
        (
            TermSpec::RotaryPositioning { axis: Axis::C, harmonics: vec![0] },
            "harmonic 0 is not from 1 to 360",
        ),
        (
            TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::X, harmonics: vec![2, 1, 2] },
            "harmonic 2 is listed twice",
        ),
        (
            TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::A, harmonics: vec![1] },
            "A is not a linear direction",
        ),
        (
            TermSpec::RotaryWobble { axis: Axis::C, about: Axis::C, harmonics: vec![1] },
            "its angular positioning error",
        ),
        (
            TermSpec::RotaryWobble { axis: Axis::C, about: Axis::Z, harmonics: vec![1] },
            "its angular positioning error",
        ),
        (
            TermSpec::RotaryWobble { axis: Axis::Y, about: Axis::A, harmonics: vec![1] },
            "Y is not a rotary axis",
        ),
    ];
    for (t, says) in cases {
        let e = build(t.clone()).unwrap_err();
        assert!(e.contains(says), "{t:?}: {e}");
    }
    // X, Y, Z name the tilt's direction as A, B, C do: the same term.
    let by = |about| {
        head_table(vec![TermSpec::RotaryWobble { axis: Axis::C, about, harmonics: vec![1] }])
    };
    assert_eq!(by(Axis::X).terms[0].term.id(), "EAC_S1");
    let st = JointState { q: 0.7, ..Default::default() };
    assert_eq!(
        by(Axis::X).terms[1].term.basis(&st).unwrap(),
        by(Axis::A).terms[1].term.basis(&st).unwrap()
    );
    // With the paper's plane mismatch terms the linear axes' lags go; a rotary axis's stays.
    let lags = vec![TermSpec::ServoLag { axis: Axis::X }, TermSpec::ServoLag { axis: Axis::C }];
    let paper =
        ModelOptions { servo: crate::ServoVariant::PlaneMismatch, ..ModelOptions::default() };
    let m = Model::new(MachineSpec { terms: lags, ..model.spec.clone() }, paper).unwrap();
    assert_eq!(m.terms.iter().map(|t| t.term.id()).collect::<Vec<_>>(), ["TC"]);
    assert_eq!(m.terms[0].term.class(), crate::TermClass::ServoLag);
}

/// A rotary test of `model` (50 Hz, R = 100 mm, 1000 mm/min).
fn rotary_run(
    model: &Model,
    turns: &[(Axis, f64, f64)],
    bar: crate::path::BarDirection,
    pivot: [f64; 3],
    k: usize,
) -> Run {
    let t = crate::path::RotaryTest {
        turns: turns
            .iter()
            .map(|&(axis, start_deg, sweep_deg)| crate::path::Turn { axis, start_deg, sweep_deg })
            .collect(),
        hold: vec![],
        bar,
        radius_mm: 100.0,
        feed_mm_per_min: 1000.0,
        pivot_mm: pivot,
        tool_ball_mm: [0.0, 0.0, -100.0],
        sample_rate_hz: 50.0,
    };
    t.run(
        &model.chain,
        "2026-12-02T09:00:00Z",
        1_796_202_000.0 + 100.0 * k as f64,
        &format!("rotary-{k}"),
        &model.spec.name,
    )
    .unwrap()
}

/// Every error motion of `axes` (positioning, run-out in X, Y, Z, the two tilts, backlash,
/// lag), harmonics 1 to 3, and every location error.
fn every_rotary_motion(axes: &[Axis]) -> Vec<TermSpec> {
    let mut t = Vec::new();
    for &a in axes {
        let h = vec![1, 2, 3];
        t.push(TermSpec::RotaryPositioning { axis: a, harmonics: h.clone() });
        for d in Axis::LINEAR {
            t.push(TermSpec::RotaryRunout { axis: a, direction: d, harmonics: h.clone() });
        }
        for about in [Axis::A, Axis::B, Axis::C].into_iter().filter(|&r| r != a) {
            t.push(TermSpec::RotaryWobble { axis: a, about, harmonics: h.clone() });
        }
        t.push(TermSpec::Backlash { axis: a });
        t.push(TermSpec::ServoLag { axis: a });
        // And its location errors: the offsets off its own line, the tilts, the zero error.
        let own = Axis::LINEAR[a.index() - 3];
        let components = Axis::ALL.into_iter().filter(|&c| c != own).collect();
        t.push(TermSpec::RotaryLocation { axis: a, components });
    }
    t
}

/// The first-order design column of every rotary error motion against a central difference
/// of the exact chain (`Design::exact_run`), on rotary tests: the A/C trunnion (C tangential,
/// radial, axial; A radial over −90° to +30°; A and C together) and a B head over a C table (B
/// tangential, B and C together, C axial). Steps: 1 µm, 1 µrad, 0.01 ms (at most 0.3 rad/s: 3 µrad):
/// the central difference's error is of the third order, (arm·ε)³/R² ≈ 1e-14 mm over 2h, and
/// the rounding of the exact distance 1e-13 mm over 2h = 2e-6 (2e-8 s): 5e-8 mm per unit;
/// 1e-7 of the column's largest entry (or of 1 per µm, R per rad, 10 mm/s per s) is above both
/// and far below any error of a basis's frame or sign, which shows at the column's own size.
#[test]
fn rotary_error_motion_columns_are_the_exact_chain_s_derivative() {
    use crate::path::BarDirection::{Axial, Radial, Tangential};
    let trunnion = MachineSpec {
        name: "ac".into(),
        version: "0".into(),
        description: "".into(),
        tool: vec![joint("Z head", Axis::Z, JointKind::Linear, [0., 0., 1.], [0., 0., 0.])],
        workpiece: vec![
            joint("Y saddle", Axis::Y, JointKind::Linear, [0., 1., 0.], [0., 0., 0.]),
            joint("X slide", Axis::X, JointKind::Linear, [1., 0., 0.], [0., 0., 0.]),
            joint("A trunnion", Axis::A, JointKind::Rotary, [1., 0., 0.], [0., 0., 250.]),
            joint("C table", Axis::C, JointKind::Rotary, [0., 0., 1.], [0., 0., -60.]),
        ],
        normalisation: vec![],
        terms: every_rotary_motion(&[Axis::A, Axis::C]),
    };
    let ac = Model::new(trunnion, ModelOptions::default()).unwrap();
    let bc = head_table(every_rotary_motion(&[Axis::B, Axis::C]));
    let off = [420.0, 250.0, -300.0];
    let ac_runs = vec![
        rotary_run(&ac, &[(Axis::C, 0.0, 360.0)], Tangential, off, 0),
        rotary_run(&ac, &[(Axis::C, 30.0, -360.0)], Radial, [off[0], off[1], off[2] + 40.0], 1),
        rotary_run(&ac, &[(Axis::C, 0.0, 360.0)], Axial, off, 2),
        rotary_run(&ac, &[(Axis::A, -90.0, 120.0)], Radial, [off[0], off[1] + 50.0, off[2]], 3),
        rotary_run(&ac, &[(Axis::A, -60.0, 90.0), (Axis::C, 0.0, 360.0)], Radial, off, 4),
    ];
    let bc_pivot = [400.0, 300.0, -300.0];
    let bc_runs = vec![
        rotary_run(
            &bc,
            &[(Axis::B, -60.0, 120.0)],
            Tangential,
            [bc_pivot[0] + 120.0, bc_pivot[1], bc_pivot[2]],
            5,
        ),
        rotary_run(
            &bc,
            &[(Axis::B, 45.0, -90.0), (Axis::C, 0.0, 360.0)],
            Axial,
            [bc_pivot[0] + 120.0, bc_pivot[1], bc_pivot[2]],
            6,
        ),
        rotary_run(
            &bc,
            &[(Axis::C, 0.0, 360.0)],
            Axial,
            [bc_pivot[0] + 120.0, bc_pivot[1], bc_pivot[2]],
            7,
        ),
    ];
    for (model, runs) in [(&ac, ac_runs), (&bc, bc_runs)] {
        let design = Design::new(model, &runs).unwrap();
        let n = design.n_cols();
        let cols: Vec<usize> = (0..model.terms.len()).collect();
        let mut seen = vec![false; cols.len()];
        for (r, run) in runs.iter().enumerate() {
            let m = run.len();
            let mut block = vec![0.0; m * cols.len()];
            let mut targets = vec![0.0; m];
            design
                .fill_run(r, &cols, &mut block, &mut targets, &mut crate::BlockScratch::default())
                .unwrap();
            for (k, &j) in cols.iter().enumerate() {
                let unit = design.parameters[j].unit;
                let h = if unit == crate::Unit::Time { 1e-5 } else { 1.0 / unit.display_factor() };
                let mut theta = vec![0.0; n];
                theta[j] = h;
                let plus = design.exact_run(r, &theta).unwrap();
                theta[j] = -h;
                let minus = design.exact_run(r, &theta).unwrap();
                let col = &block[k * m..(k + 1) * m];
                let largest = col.iter().fold(0.0f64, |a, x| a.max(x.abs()));
                let worst = (0..m)
                    .map(|i| ((plus[i] - minus[i]) / (2.0 * h) - col[i]).abs())
                    .fold(0.0, f64::max);
                let typical = match unit {
                    crate::Unit::Length => 1.0,
                    crate::Unit::Time => 10.0,
                    _ => run.header.radius_mm,
                };
                let id = &design.parameters[j].id;
                assert!(
                    worst <= 1e-7 * largest.max(typical),
                    "{} {id}: first order off by {worst:e} (largest {largest:e})",
                    run.name()
                );
                seen[k] |= largest > 1e-3 * typical;
            }
        }
        // Every term acts in some run, so that no column passes by being zero everywhere.
        let idle: Vec<&str> =
            cols.iter().filter(|&&k| !seen[k]).map(|&j| design.parameters[j].id.as_str()).collect();
        assert!(idle.is_empty(), "{}: columns zero in every run: {idle:?}", model.spec.name);
    }
}

#[test]
fn the_first_harmonic_that_turns_with_a_table_is_a_re_seated_ball() {
    // On a C table (σ = -1) the run-out EXC_C1 = 1 with EYC_S1 = -1 moves the table by
    // (cos q, -sin q) in the frame that does not turn: in the table's own frame a constant
    // (1, 0), the table ball re-seated (its centring). So do EXC_S1 = EYC_C1 = 1 (0, 1), and the
    // tilts EAC_C1 = -EBC_S1. On a head (σ = +1) the turning part has the other sign.
    let terms = vec![
        TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::X, harmonics: vec![1] },
        TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::Y, harmonics: vec![1] },
        TermSpec::RotaryWobble { axis: Axis::C, about: Axis::A, harmonics: vec![1] },
        TermSpec::RotaryWobble { axis: Axis::C, about: Axis::B, harmonics: vec![1] },
        TermSpec::RotaryRunout { axis: Axis::B, direction: Axis::Z, harmonics: vec![1] },
        TermSpec::RotaryRunout { axis: Axis::B, direction: Axis::X, harmonics: vec![1] },
    ];
    let model = head_table(terms);
    let basis = |id: &str, q: f64| {
        let t = model.terms.iter().find(|t| t.term.id() == id).unwrap();
        t.term.basis(&JointState { q, ..Default::default() }).unwrap()
    };
    let combine = |a: &[(f64, &str)], q: f64| -> ErrorMotion {
        std::array::from_fn(|i| a.iter().map(|(w, id)| w * basis(id, q)[i]).sum())
    };
    // In the joint frame, as the chain applies it (σ times the physical motion).
    for q in [0.0, 0.4, 2.0, -2.9] {
        let close = |got: ErrorMotion, want: ErrorMotion| {
            got.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-15)
        };
        let c = combine(&[(1.0, "EXC_C1"), (-1.0, "EYC_S1")], q);
        assert!(close(c, [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0]), "{q}: {c:?}");
        let c = combine(&[(1.0, "EXC_S1"), (1.0, "EYC_C1")], q);
        assert!(close(c, [0.0, -1.0, 0.0, 0.0, 0.0, 0.0]), "{q}: {c:?}");
        let c = combine(&[(1.0, "EAC_C1"), (-1.0, "EBC_S1")], q);
        assert!(close(c, [0.0, 0.0, 0.0, -1.0, 0.0, 0.0]), "{q}: {c:?}");
        // B turns about Y: from Z toward X. Its turning part: EZB_C1 = EXB_S1 (σ = +1).
        let c = combine(&[(1.0, "EZB_C1"), (1.0, "EXB_S1")], q);
        assert!(close(c, [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]), "{q}: {c:?}");
        // The other half turns against the axis: not constant in its frame.
        let c = combine(&[(1.0, "EXC_C1"), (1.0, "EYC_S1")], q);
        assert!((c[0] - (-(2.0 * q).cos())).abs() < 1e-15, "{q}: {c:?}");
    }
}

/// Outside the rows [`Design::switch_rows`] names, every axis's direction is the same at any
/// switch lags up to its bound (the commanded reversal, τ = 0, among them): the switch search
/// re-evaluates only those rows. Inside them it does change (the rows are not all of them for
/// nothing), and they are a few per cent of the run.
#[test]
fn switch_lags_change_directions_only_on_the_rows_near_the_reversals() {
    let model = Model::new(crate::machines::column(), ModelOptions::default()).unwrap();
    let runs = vec![xy(Direction::CW, 1000.0), xy(Direction::CCW, 2000.0)];
    let design = Design::new(&model, &runs).unwrap();
    let max = 0.05;
    let lag_sets = [
        [0.0; 6],
        [max, max, max, 0.0, 0.0, 0.0],
        [0.003, 0.0, 0.0, 0.0, 0.0, 0.0],
        [0.011, 0.027, 0.0, 0.0, 0.0, 0.0],
        [0.0, 0.049, 0.0, 0.0, 0.0, 0.0],
    ];
    let designs: Vec<Design<'_>> = lag_sets.iter().map(|&l| design.at_switch_lags(l)).collect();
    for r in 0..runs.len() {
        let rows = design.switch_rows(r, max);
        let near = |i: usize| rows.iter().any(|w| w.contains(&i));
        let mut changed = 0;
        for i in 0..runs[r].len() {
            let dirs: Vec<[f64; 2]> = designs
                .iter()
                .map(|d| {
                    let s = d.states(r, i);
                    [s[0].direction, s[1].direction]
                })
                .collect();
            let same = dirs.iter().all(|d| d == &dirs[0]);
            assert!(same || near(i), "run {r} sample {i}: {dirs:?} outside {rows:?}");
            changed += usize::from(!same);
        }
        let inside: usize = rows.iter().map(|w| w.len()).sum();
        assert!(
            changed > 0 && inside * 10 < runs[r].len(),
            "run {r}: {changed} changed, {inside} rows of {}",
            runs[r].len()
        );
    }
}

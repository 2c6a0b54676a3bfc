//! The model's convention mapped to LinuxCNC's trims, by hand; what is not written and why; the
//! prediction against a trace derived by hand.

use super::*;
use crate::tables::fixtures::{BACK, POS, circle, estimate, model};

#[test]
fn a_scale_and_a_backlash_become_the_trims_derived_by_hand() {
    // EXX1 = 10 µm at L = 250 mm: δX = 0.010·X/250 (40 ppm, the axis goes too far);
    // BX = 4 µm: δX = -0.002 moving up, +0.002 moving down. Trim = -δ: at X = 250 mm, moving
    // up, -0.010 + 0.002 = -0.008 mm; moving down, -0.010 - 0.002 = -0.012 mm.
    let m = model(&[("EXX1", 0.010, 1e-5), ("BX", 0.004, 1e-5)]);
    let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
    let runs = [circle()];
    let (comp, files) = linuxcnc(&m, &est, &runs, &Options::default()).unwrap();
    let linuxcnc::Joint::Table { file, table } = &files.joints[&0] else { panic!("no table") };
    assert_eq!(file, "joint-0.comp");
    // The measured span of X is that of the samples, 200..400 mm to within the sample nearest
    // X = 200 (0.13 µm: 50 Hz at 1000 mm/min is 0.33 mm apart along the circle); 1 mm apart:
    // 201 entries.
    let e = table.entries();
    assert_eq!(e.len(), 201);
    assert!((e[0].nominal - 200.0).abs() < 1e-3 && e[200].nominal == 400.0, "{:?}", e[0]);
    // At X = 250 mm by interpolation, to the written trims' rounding (half of 0.1 nm).
    let res = linuxcnc::TRIM_RESOLUTION_MM / 2.0;
    assert!((table.trim(250.0, true) - (-0.008)).abs() <= res, "{}", table.trim(250.0, true));
    assert!((table.trim(250.0, false) - (-0.012)).abs() <= res);
    // No BACKLASH for a joint with a table; Y is not compensated.
    let ini = files.ini_text();
    assert!(!ini.contains("BACKLASH") && !ini.contains("[JOINT_1]"), "{ini}");
    let scale = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
    assert_eq!(scale.term, "scale");
    assert!((scale.value_ppm.unwrap() - 40.0).abs() < 1e-9);
    assert!(scale.compensated && scale.extended == Some(false));
    // From the table as written: what it applies, and the axis moves with its scale where the
    // trim sends it: 40 ppm less 40 ppm less their product, -40e-6 × 40 ppm = -0.0016 ppm (to
    // the trims' 0.1 nm over the 200 mm span, 0.0005 ppm).
    let p = scale.predicted_after.unwrap();
    assert!((p - (-0.0016)).abs() < 5e-4, "{scale:?}");
    let b = comp.terms.iter().find(|t| t.id == "BX").unwrap();
    assert!(b.predicted_after.unwrap().abs() < 1e-3, "{b:?}");
}

#[test]
fn a_backlash_alone_is_linuxcncs_backlash_and_existing_values_are_added() {
    let m = model(&[("BY", 0.003, 1e-5)]);
    let est = [estimate("BY", BACK, 0.003, 1e-5)];
    let (_, files) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    assert_eq!(files.joints[&1], linuxcnc::Joint::Backlash(0.003));
    // A negative backlash (an overshoot at the reversals) is not a BACKLASH: a table's two
    // directions take it, -B/2 up and +B/2 down.
    let neg = [estimate("BY", BACK, -0.001, 1e-5)];
    let (_, files) = linuxcnc(&m, &neg, &[circle()], &Options::default()).unwrap();
    let linuxcnc::Joint::Table { table, .. } = &files.joints[&1] else { panic!("no table") };
    assert!((table.trim(200.0, true) - (-0.0005)).abs() < 1e-9);
    assert!((table.trim(200.0, false) - 0.0005).abs() < 1e-9);
    // An existing BACKLASH of 5 µm left 3 µm: the new value is 8 µm, and the prediction says
    // what was there before.
    let mut existing = linuxcnc::Files { coordinates: "XYZ".into(), ..Default::default() };
    existing.joints.insert(1, linuxcnc::Joint::Backlash(0.005));
    let options = Options { existing: Some(existing), ..Default::default() };
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    assert_eq!(files.joints[&1], linuxcnc::Joint::Backlash(0.008));
    let t = &comp.terms[0];
    assert!((t.existing.unwrap() - 5.0).abs() < 1e-9 && (t.written.unwrap() - 8.0).abs() < 1e-9);
    assert!(t.predicted_after.unwrap().abs() < 1e-9);
    // A table the existing configuration holds for a joint not compensated now is kept, written
    // into the output folder under this writer's name: never under the existing name, which
    // may be a path out of the folder or the machine's own file.
    let mut existing = linuxcnc::Files { coordinates: "XYZ".into(), ..Default::default() };
    let kept = linuxcnc::Table::parse("0 0.001 0.002\n100 0.003 0.004\n", "z.comp", 1).unwrap().0;
    existing.joints.insert(
        2,
        linuxcnc::Joint::Table { file: "/etc/linuxcnc/machine/z.comp".into(), table: kept.clone() },
    );
    let options = Options { existing: Some(existing), ..Default::default() };
    let (_, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    assert_eq!(
        files.joints[&2],
        linuxcnc::Joint::Table { file: linuxcnc::comp_file_name(2), table: kept }
    );
    assert!(files.texts().iter().all(|(name, _)| !name.contains('/')), "{:?}", files.texts());
}

#[test]
fn what_is_not_significant_aliased_or_cross_axis_is_not_written_and_says_why() {
    let m = model(&[]);
    let mut curvature = estimate("EXX2", POS, 0.002, 1e-5);
    curvature.aliases = vec!["straightness of X toward Z, degree 2".into()];
    let est = [
        estimate("EYY1", POS, 0.0001, 0.0001),
        curvature,
        estimate("EYX2", ParamClass::Term(TermClass::Straightness), 0.003, 1e-5),
        Estimate {
            unit: Unit::Angle,
            ..estimate("SQXY", ParamClass::Term(TermClass::Squareness), 2e-5, 1e-7)
        },
        estimate("MXY", ParamClass::PlaneMismatch, 0.008, 1e-5),
    ];
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    assert!(files.joints.is_empty());
    assert!(comp.terms.iter().all(|t| !t.compensated));
    let why = |id: &str| comp.terms.iter().find(|t| t.id == id).unwrap().why.clone().unwrap();
    assert!(why("EYY1").contains("not significant"));
    assert!(why("EXX2").contains("cannot separate"));
    assert!(why("EYX2").contains("no cross-axis table"));
    assert!(why("SQXY").contains("no cross-axis table"));
    assert!(why("MXY").starts_with("advice"));
    let sq = comp.terms.iter().find(|t| t.id == "SQXY").unwrap();
    assert_eq!(
        (sq.term.as_str(), sq.axis.as_str(), sq.value_urad),
        ("squareness", "XY", Some(20.0))
    );
}

/// Between significant and verifiable: a scale of 5 u is significant (≥ 2u), so written, but a
/// repeat of the same tests, refitting with u as large, resolves a correction only beyond 6√2 u
/// = 8.49 u (`verify::RESOLVED_IN_U` with the two fits' u combined): it is flagged,
/// `verifiable_by_repeat: false`, with the sessions that would verify it, `72 u²/value²` =
/// 72/25 = 2.88, so 3. A scale of 9 u is written unflagged; one of 1.9 u is not written.
#[test]
fn a_significant_correction_a_repeat_could_not_verify_is_written_and_flagged_with_its_sessions() {
    assert!((VERIFIABLE_IN_U - 6.0 * 2f64.sqrt()).abs() < 1e-12);
    let m = model(&[]);
    let est = [estimate("EYY1", POS, 0.0005, 0.0001), estimate("EXX1", POS, 0.0009, 0.0001)];
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    let y = comp.terms.iter().find(|t| t.id == "EYY1").unwrap();
    assert!(y.compensated && y.why.is_none() && files.joints.contains_key(&1), "{y:?}");
    assert_eq!((y.verifiable_by_repeat, y.sessions_to_verify), (Some(false), Some(3)), "{y:?}");
    let x = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
    assert!(x.compensated && x.why.is_none(), "{x:?}");
    assert_eq!((x.verifiable_by_repeat, x.sessions_to_verify), (None, None), "{x:?}");
    // Below 2u: not written, and not flagged (nothing is written to verify).
    let est = [estimate("EYY1", POS, 0.00019, 0.0001)];
    let (comp, _) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    let y = comp.terms.iter().find(|t| t.id == "EYY1").unwrap();
    assert!(!y.compensated && y.verifiable_by_repeat.is_none(), "{y:?}");
    assert!(y.why.as_deref().unwrap().starts_with("not significant"), "{y:?}");
}

/// The sessions that verify a correction, by hand: without a resolution `n = ⌈72 u²/value²⌉`.
/// 6.1 u: 72/37.21 = 1.93, so 2; 2.2 u: 72/4.84 = 14.9, so 15; 8.49 u and beyond: 1; the sign
/// does not matter; a value of 0 or a u not finite: none. At a resolution `res` the bound is
/// `min(|v|/6, (|v| − res)/3)` on `√(2u²/n)`: FANUC's 1 µm with a backlash of 1.2 µm, u 0.1:
/// min(0.2, 0.0667)² = 0.00444, 2 × 0.01/0.00444 = 4.5, so 5; of 1.5 µm: min(0.25, 0.1667)²
/// = 0.0278, 0.02/0.0278 = 0.72, so 1; of 0.9 µm, below the unit: none.
#[test]
fn the_sessions_that_verify_a_correction_are_derived_by_hand() {
    assert_eq!(sessions_to_verify(6.1, 1.0, 0.0), Some(2));
    assert_eq!(sessions_to_verify(-0.022, 0.01, 0.0), Some(15));
    assert_eq!(sessions_to_verify(9.0, 1.0, 0.0), Some(1));
    assert_eq!(sessions_to_verify(0.0, 1.0, 0.0), None);
    assert_eq!(sessions_to_verify(1.0, f64::NAN, 0.0), None);
    assert_eq!(sessions_to_verify(1.2, 0.1, 1.0), Some(5));
    assert_eq!(sessions_to_verify(-1.5, 0.1, 1.0), Some(1));
    assert_eq!(sessions_to_verify(0.9, 0.1, 1.0), None);
}

/// The reason a flagged term gives, each branch by hand on a term of value 1.2 µm: u 0.2 µm
/// at a fine resolution is 6.0 u < 8.5 u; u 0.1 µm at a resolution of 0.9 µm is 12 u, but only
/// (1.2 − 0.9)/0.1 = 3.0 u above it (< 4.2 u: the resolution's bound, (1.2 − 0.9)/3 = 0.1,
/// is below 1.2/6 = 0.2); a u not finite says so.
#[test]
fn a_flagged_terms_reason_names_the_bound_it_misses() {
    let e = estimate("BX", BACK, 0.0012, 0.0002);
    let mut t = Term {
        value_um: Some(1.2),
        u_um: Some(0.2),
        ..entry(&e, "backlash", "X".into(), None, 250.0)
    };
    assert_eq!(unverifiable_reason(&t, 1e-4), "|c| = 6.0 u < 8.5 u");
    t.u_um = Some(0.1);
    assert_eq!(
        unverifiable_reason(&t, 0.9),
        "|c| = 12.0 u, but above the controller's resolution of 0.900 µm by only 3.0 u < 4.2 u"
    );
    t.u_um = Some(f64::NAN);
    assert_eq!(unverifiable_reason(&t, 0.9), "its uncertainty is not known");
}

/// The flag at the files' resolution: a backlash of 1.2 µm with u 0.1 µm (12 u) is written by
/// LinuxCNC to 0.1 nm, unflagged; FANUC writes it in its detection unit as 1 µm, a correction
/// not above that unit, which no number of repeats tells from nothing loaded (as `verify`
/// computes it): flagged without sessions. One of 2.3 µm (23 u) written as 2 µm is a
/// correction of 2 µm: min(2/6, (2 − 1)/3)² = 0.111 against 2u² = 0.02, one session, unflagged.
#[test]
fn a_correction_near_the_controllers_resolution_is_flagged_with_its_sessions() {
    let flag = |controller: &str, backlash_mm: f64| {
        let m = model(&[("BX", backlash_mm, 1e-4)]);
        let est = [estimate("BX", BACK, backlash_mm, 1e-4)];
        let (runs, options) = ([circle()], Options::default());
        let comp = if controller == "linuxcnc" {
            linuxcnc(&m, &est, &runs, &options).unwrap().0
        } else {
            crate::tables::compensate(controller, &m, &est, &runs, &options).unwrap().0
        };
        let b = comp.terms.iter().find(|t| t.id == "BX").unwrap().clone();
        assert!(b.compensated, "{b:?}");
        if controller == "fanuc" && b.verifiable_by_repeat.is_some() {
            // The reason in words: the resolution, not the u (12 u).
            assert_eq!(
                unverifiable_reason(&b, b.resolution(comp.resolution())),
                "|c| = 1.000 µm is not above the controller's resolution of 1.000 µm"
            );
        }
        (b.verifiable_by_repeat, b.sessions_to_verify, b.correction())
    };
    let (v, n, c) = flag("linuxcnc", 0.0012);
    assert_eq!((v, n), (None, None), "{c}");
    let (v, n, c) = flag("fanuc", 0.0012);
    assert_eq!((v, n), (Some(false), None));
    assert!((c.abs() - 1.0).abs() < 1e-9, "the correction applied: {c}");
    assert_eq!(sessions_to_verify(1.0 + 1e-15, 0.1, 1.0), None, "one unit to rounding");
    let (v, n, c) = flag("fanuc", 0.0023);
    assert_eq!((v, n), (None, None), "{c}");
}

#[test]
fn a_travel_beyond_the_tests_extends_a_pure_slope_and_holds_a_curvature_with_its_slope() {
    let m = model(&[]);
    let options = Options { travel: [(Axis::X, [0.0, 500.0])].into(), ..Default::default() };
    // A scale alone: extended linearly, -0.010·X/250.
    let est = [estimate("EXX1", POS, 0.010, 1e-5)];
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    let linuxcnc::Joint::Table { table, .. } = &files.joints[&0] else { panic!() };
    // 500 mm at 1 mm would be 501 entries: 256, 500/255 mm apart.
    assert_eq!(table.entries().len(), 256);
    assert!(table.trim(0.0, true).abs() < 1e-7);
    assert!((table.trim(500.0, true) - (-0.020)).abs() < 1e-7);
    let scale = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
    assert_eq!((scale.extended, scale.span_mm), (Some(true), Some([0.0, 500.0])));
    assert!(comp.notes.iter().any(|n| n.contains("extended linearly")), "{:?}", comp.notes);
    // A scale with a curvature: neither is extended; past the measured 200..400 mm the table
    // holds the polynomial's values there: at X = 0, -(0.010·0.8 + 0.002·0.8²); at X = 500,
    // -(0.010·1.6 + 0.002·1.6²) (the measured ends are the samples', within 0.13 µm of 200
    // and 400 mm: 5e-9 mm of trim).
    let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("EXX2", POS, 0.002, 1e-5)];
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    let linuxcnc::Joint::Table { table, .. } = &files.joints[&0] else { panic!() };
    assert!((table.trim(0.0, true) - -(0.008 + 0.002 * 0.64)).abs() < 1e-7);
    assert!((table.trim(500.0, true) - -(0.016 + 0.002 * 2.56)).abs() < 1e-7);
    for id in ["EXX1", "EXX2"] {
        let t = comp.terms.iter().find(|t| t.id == id).unwrap();
        assert_eq!(t.extended, Some(false), "{t:?}");
    }
    assert!(comp.notes.iter().any(|n| n.contains("none of it is extended")), "{:?}", comp.notes);
    // A degree 2 written: its prediction is first order in the trim, and a note names it (a
    // scale alone, exact, has none).
    let order = |c: &Compensation| c.notes.iter().find(|n| n.contains("first order")).cloned();
    assert!(
        order(&comp).is_some_and(|n| n.contains("EXX2") && !n.contains("EXX1")),
        "{:?}",
        comp.notes
    );
    let (scale_only, _) =
        linuxcnc(&m, &[estimate("EXX1", POS, 0.010, 1e-5)], &[circle()], &options).unwrap();
    assert_eq!(order(&scale_only), None);
}

#[test]
fn an_aliased_term_is_written_only_when_the_user_names_it() {
    let m = model(&[]);
    let mut scale = estimate("EXX1", POS, 0.010, 1e-5);
    scale.aliases = vec!["positional error of X, degree 2 (if it holds, EXX1 = 4 µm)".into()];
    let est = [scale, estimate("BX", BACK, 0.004, 1e-5)];
    // By default: the backlash alone (a BACKLASH), the scale not written, with why.
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    assert_eq!(files.joints[&0], linuxcnc::Joint::Backlash(0.004));
    let t = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
    assert!(!t.compensated);
    let why = t.why.clone().unwrap();
    assert!(why.contains("degree 2") && why.contains("--include-aliased EXX1"), "{why}");
    // Named, by id or by term: written as fitted, and a note says so.
    for name in ["exx1", "scale"] {
        let options = Options { include_aliased: vec![name.into()], ..Default::default() };
        let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
        assert!(matches!(files.joints[&0], linuxcnc::Joint::Table { .. }));
        assert!(comp.terms.iter().find(|t| t.id == "EXX1").unwrap().compensated);
        assert!(comp.notes.iter().any(|n| n.contains("EXX1") && n.contains("--include-aliased")));
    }
}

#[test]
fn joints_come_from_the_flag_or_the_existing_layout_and_a_gantry_is_refused() {
    let m = model(&[]);
    let est = [estimate("BY", BACK, 0.003, 1e-5)];
    // A subset: Y alone, on joint 0 (a machine of one or two joints).
    let options = Options { joints: [(Axis::Y, 0)].into(), ..Default::default() };
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    assert_eq!(files.joints[&0], linuxcnc::Joint::Backlash(0.003));
    assert_eq!(comp.joints["Y"], 0);
    // A compensated axis the flag leaves out: refused, naming it.
    let options = Options { joints: [(Axis::X, 0)].into(), ..Default::default() };
    let m2 = linuxcnc(&m, &est, &[circle()], &options).unwrap_err();
    assert!(m2.contains("Y=<joint number>"), "{m2}");
    let none = |_: &str| Err(String::new());
    let existing = |ini: &str| Options {
        existing: Some(linuxcnc::Files::parse(ini, "m.ini", &none).unwrap()),
        ..Default::default()
    };
    // The existing configuration's layout: Y is joint 2 of X Z Y.
    let options = existing("[KINS]\nKINEMATICS = trivkins coordinates=XZY\n");
    let (comp, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    assert_eq!((comp.joints["Y"], files.joints.keys().copied().collect::<Vec<_>>()), (2, vec![2]));
    // A gantry: Y on joints 1 and 2. Refused, naming the joints and what to pass; --joints
    // picks one.
    let options = existing("[KINS]\nKINEMATICS = trivkins coordinates=XYYZ\n");
    let m3 = linuxcnc(&m, &est, &[circle()], &options).unwrap_err();
    assert!(m3.contains("joints 1 and 2") && m3.contains("--joints Y=1"), "{m3}");
    let options = Options { joints: [(Axis::Y, 2)].into(), ..options };
    let (_, files) = linuxcnc(&m, &est, &[circle()], &options).unwrap();
    assert_eq!(files.joints[&2], linuxcnc::Joint::Backlash(0.003));
    // A joint the layout gives another axis: refused.
    let options = Options { joints: [(Axis::Y, 3)].into(), ..options };
    assert!(linuxcnc(&m, &est, &[circle()], &options).unwrap_err().contains("axis Z"));
    // A kinematics whose joints are not trivkins': --joints is needed.
    let options = existing("[KINS]\nKINEMATICS = xyzac-trt-kins\n");
    assert!(linuxcnc(&m, &est, &[circle()], &options).unwrap_err().contains("--joints"));
}

#[test]
fn without_runs_only_the_backlash_is_written_and_nothing_is_predicted() {
    let m = model(&[]);
    let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
    let (mut comp, files) = linuxcnc(&m, &est, &[], &Options::default()).unwrap();
    assert_eq!(files.joints[&0], linuxcnc::Joint::Backlash(0.004));
    let t = comp.terms.iter().find(|t| t.id == "EXX1").unwrap();
    assert!(!t.compensated && t.why.clone().unwrap().contains("no runs"), "{t:?}");
    let b = comp.terms.iter().find(|t| t.id == "BX").unwrap();
    assert!(b.compensated && b.predicted_after.unwrap().abs() < 1e-9, "{b:?}");
    predict(&mut comp, &files, None, &[]);
    assert!(comp.predicted.is_empty());
    // A negative backlash without a span: a one-entry table, held everywhere.
    let est = [estimate("BX", BACK, -0.002, 1e-5)];
    let (_, files) = linuxcnc(&m, &est, &[], &Options::default()).unwrap();
    let linuxcnc::Joint::Table { table, .. } = &files.joints[&0] else { panic!() };
    assert_eq!(table.entries().len(), 1);
    assert_eq!((table.trim(-300.0, true), table.trim(900.0, false)), (-0.001, 0.001));
}

#[test]
fn a_missing_uncertainty_is_an_error_naming_the_file_and_term() {
    let m = model(&[]);
    let est = [estimate("BX", BACK, 0.004, 1e-5)];
    let (comp, _) = linuxcnc(&m, &est, &[circle()], &Options::default()).unwrap();
    let mut t = comp.terms[0].clone();
    assert_eq!(t.checked_value("c.json").unwrap().2, "µm");
    t.u_um = None;
    let e = t.checked_value("c.json").unwrap_err();
    assert!(e.starts_with("c.json: term BX") && e.contains("u_um"), "{e}");
}

#[test]
fn the_prediction_cancels_a_trace_derived_by_hand() {
    // A CCW XY circle with X 40 ppm long and a 4 µm X backlash, first order:
    // ΔR = cosφ·δX, δX = 0.010·X/250 - 0.002·sign(dX/dt), dX/dt = -R ω sinφ.
    let m = model(&[]);
    let est = [estimate("EXX1", POS, 0.010, 1e-5), estimate("BX", BACK, 0.004, 1e-5)];
    let mut run = circle();
    let phi = ballbar_fit::metrics::angles(&run).unwrap();
    let x = run.axis(Axis::X).unwrap().to_vec();
    for i in 0..run.len() {
        let up = -phi[i].sin() > 0.0;
        let dx = 0.010 * x[i] / 250.0 - if up { 0.002 } else { -0.002 };
        run.dr_mm[i] = phi[i].cos() * dx;
    }
    let (mut comp, files) =
        linuxcnc(&m, &est, std::slice::from_ref(&run), &Options::default()).unwrap();
    predict(&mut comp, &files, None, std::slice::from_ref(&run));
    let p = &comp.predicted[0];
    // Before: the 40 ppm ellipse alone has G = R·40e-6 = 4 µm (ΔR = 0.0016 cos²φ about the
    // centre's part); the backlash's steps at φ = 0, 180° add to it.
    assert!(p.g_before_um > 4.0, "{p:?}");
    // After: the table is linear between nominals as the scale is, and the directions agree
    // with the sign above at every sample: what is left is the trims' rounding to 0.1 nm.
    assert!(p.g_after_um < 1e-3 && p.rms_after_um < 1e-3, "{p:?}");
}

/// What a change of the traces moves: a term of one parameter by the change's own value (the
/// fit is linear); a transient's side by its height with the change less its height before,
/// since a height is no linear function of its parts. X's transient both sides: `e^{-x}` of 2
/// µm before (height 2 µm at the reversal), the change `x e^{-x}` of 2e µm: the sum's peak is
/// where `(2 + 2e·x) e^{-x}` is largest, `x = 1 − 1/e`, height `2e·e^{-(1 − 1/e)}` = 2.889 µm:
/// a move of 0.889 µm, where the change's own height (2 µm, at `x = 1`) would say 2.
#[test]
fn a_transients_height_moves_by_its_peak_with_the_change() {
    let fx = ballbar_model::ParamClass::Term(ballbar_model::TermClass::Effect);
    let e = std::f64::consts::E;
    let mut m = model(&[("SPX0", 2e-3, 1e-5), ("SPX1", 0.0, 1e-5), ("SPX2", 0.0, 1e-5)]);
    m.effects = vec![ballbar_model::Effect::ReversalTransient {
        axis: Axis::X,
        tau_ms: 10.0,
        period_ms: None,
        per_side: false,
    }];
    let before = [
        estimate("SPX0", fx, 2e-3, 1e-5),
        estimate("SPX1", fx, 0.0, 1e-5),
        estimate("SPX2", fx, 0.0, 1e-5),
        estimate("BX", BACK, 3e-3, 1e-5),
    ];
    let change = [
        estimate("SPX0", fx, 0.0, 1e-5),
        estimate("SPX1", fx, 2e-3 * e, 1e-5),
        estimate("SPX2", fx, 0.0, 1e-5),
        estimate("BX", BACK, -0.5e-3, 1e-5),
    ];
    let moves = moves(&m, &before, &change);
    let hand = 2.0 * e * (-(1.0 - 1.0 / e)).exp() - 2.0;
    assert!((moves["SPX"] - hand).abs() < 1e-5 && (hand - 0.889).abs() < 1e-3, "{moves:?}");
    assert_eq!(moves["BX"], -0.5);
    assert!(!moves.contains_key("SPX0"), "{moves:?}");
}

//! How much the advice terms ask of a controller's tuning. A servo mismatch and a reversal spike
//! are no table: each controller's `why` names the parameter that acts on them, and this module
//! adds the amount, computed from the model, in physical units that hold for any controller.
//!
//! # Servo mismatch
//! A position loop of gain `Kv` (1/s) follows its command with a lag `τ = 1/Kv`; with velocity
//! feed-forward of fraction `f`, `τ = (1 − f)/Kv`. The axes of a plane draw a circle without the
//! mismatch's ellipse when their lags are equal. The model gives them as the axes' own lags
//! (`T<axis>`, s) or as the paper's plane mismatch `M<plane>` (mm), which is `v (τ_b − τ_a)` at
//! the path speed `v` for the plane's axes `a`, `b` (`ballbar_model::paper`, the rows of the
//! servo mismatch): `τ_b − τ_a = M / v`, at the feed of that plane's runs. Shortening an axis's
//! lag by `Δ` takes its gain to `Kv / (1 − Δ Kv)`, or its feed-forward fraction up by `Δ Kv`.
//!
//! # Reversal spike
//! After a reversal the axis sticks and falls behind its command by a spike of height `h` that it
//! makes up over about `τ`. The controllers' reversal compensation adds a pulse to the velocity
//! command at the reversal; the motion it supplies (the pulse's area, amplitude × duration) is
//! what the spike lost, so `h` is the starting value of that area (HEIDENHAIN's technical manual
//! for the reversal peaks' compensation: "The reversal peak height resulting without
//! compensation is a suitable starting value"), over a duration of about `τ`: an amplitude of
//! `h / τ` (SINUMERIK's friction compensation: MD32520 the amplitude in mm/min, MD32540 its time
//! constant in s). The circularity test after it tunes both.
//!
//! # Rotary location
//! ISO 230-7 names a rotary axis's location errors `E<d>0<axis>`: an offset of the axis's
//! average line along `d` = X, Y, Z; a tilt of it about `d` = A, B, C; about its own line, its
//! zero. The model states each in the physical sense (`ballbar_model::term`'s
//! `Shape::RotaryLocation`): the line lies `+e` along (or turned `+e` about) the direction
//! from where the nominal chain puts it. A controller's kinematics describe where the axis is,
//! so the correction adds `e` to the kinematics' location (or orientation) of the axis. A zero
//! error turns the carried body by `e` at every position; in the axis's own coordinate that is
//! `σ e` further than commanded (`σ` the branch sign: +1 on the tool's, −1 on the workpiece's, as
//! `ballbar_model`'s chain states it), which `σ e` taken off the axis's position corrects.
//!
//! # What the amounts hold
//! An amount is the model's value taken as it is. Where that value is not significant (below
//! twice its uncertainty), no change is asked; where it depends on what the tests cannot
//! separate, the amount says so and names the aliases, as a table's term would.

use ballbar_fit::saved::SavedModel;
use ballbar_model::machine::TermSpec;
use ballbar_model::{Axis, Effect, Run};

use crate::{Estimate, Term};

/// Each advice term's `why` followed by the amount it asks for, where the model gives one.
pub(crate) fn amend(entries: &mut [(Term, Estimate)], model: &SavedModel, runs: &[Run]) {
    let lags: Vec<(String, f64, f64)> = entries
        .iter()
        .filter(|(t, e)| t.term == "servo_mismatch" && t.axis.len() == 1 && e.estimable)
        .map(|(t, e)| (t.axis.clone(), e.value, e.u))
        .collect();
    for (t, e) in entries.iter_mut() {
        if !e.estimable {
            continue;
        }
        let amount = match t.term.as_str() {
            "servo_mismatch" if t.axis.len() == 1 => axis_lag(&t.axis, &lags),
            "servo_mismatch" => plane_mismatch(&t.axis, e.value, runs),
            "reversal_spike" => spike(&t.id, model),
            "rotary_location" => rotary(&t.id, e, model),
            _ => None,
        };
        let (Some(amount), Some(why)) = (amount, t.why.as_mut()) else {
            continue;
        };
        let f = e.unit.display_factor();
        if e.value.abs() < 2.0 * e.u {
            why.push_str(&format!(
                "; no change asked: {} {:.3} is below twice its standard uncertainty ({:.3})",
                t.id,
                e.value * f,
                e.u * f
            ));
            continue;
        }
        why.push_str("; by how much");
        if !e.aliases.is_empty() {
            why.push_str(&format!(
                ", if the model's value holds (it depends on what these tests cannot separate: {})",
                e.aliases.join("; ")
            ));
        }
        why.push_str(": ");
        why.push_str(&amount);
    }
}

/// The gain and feed-forward changes that shorten a lag by `delta_s`, in words.
fn shorten(axis: &str, delta_s: f64) -> String {
    let d = delta_s;
    format!(
        "shorten {axis}'s lag by {:.3} ms: its gain Kv (1/s) to Kv / (1 − {d:.6} s × Kv) while {d:.6} s × Kv < 1, or its velocity feed-forward fraction up by {d:.6} s × Kv",
        d * 1e3
    )
}

/// An axis's own lag against the others' (`lags`: axis, s, u).
fn axis_lag(axis: &str, lags: &[(String, f64, f64)]) -> Option<String> {
    let own = lags.iter().find(|(a, ..)| a == axis)?.1;
    if lags.len() < 2 {
        return None;
    }
    let listed: Vec<String> =
        lags.iter().map(|(a, v, u)| format!("{a} {:.3} ± {:.3} ms", v * 1e3, u * 1e3)).collect();
    let shortest = lags.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let longest = lags.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let to_shortest = if shortest.0 == axis {
        format!("{axis} has the shortest lag: the others match it")
    } else {
        format!("to match {} (the shortest), {}", shortest.0, shorten(axis, own - shortest.1))
    };
    let to_longest = if longest.0 == axis {
        format!("{axis} has the longest: matching it, the others lengthen theirs")
    } else {
        format!(
            "or, to match {} (the longest: no gain raised), lengthen {axis}'s by {:.3} ms (its Kv to Kv / (1 + {:.6} s × Kv))",
            longest.0,
            (longest.1 - own) * 1e3,
            longest.1 - own
        )
    };
    Some(format!(
        "the axes' fitted lags {} (a lag is 1/Kv without feed-forward); {to_shortest}; {to_longest}",
        listed.join(", ")
    ))
}

/// A plane's mismatch `m_mm` as the lag difference of its axes at its runs' feed.
fn plane_mismatch(plane: &str, m_mm: f64, runs: &[Run]) -> Option<String> {
    let mut axes = plane.chars().map(|c| c.to_string());
    let (a, b) = (axes.next()?, axes.next()?);
    let mut feeds: Vec<f64> = runs
        .iter()
        .filter(|r| r.header.plane.to_string() == plane)
        .map(|r| r.header.feed_mm_per_min)
        .collect();
    feeds.sort_by(f64::total_cmp);
    feeds.dedup();
    let [feed] = feeds[..] else {
        // No run of the plane, or several feeds: the paper's constant mismatch is a lag
        // difference only at one feed.
        return None;
    };
    // M = v (τ_b − τ_a) (module docs).
    let lag_b_minus_a_s = m_mm / (feed / 60.0);
    let (late, early) = if lag_b_minus_a_s >= 0.0 { (b, a) } else { (a, b) };
    let d = lag_b_minus_a_s.abs();
    Some(format!(
        "{late} lags {early} by {:.3} ms (the mismatch {:.2} µm at the runs' F {feed} mm/min); {}, or lengthen {early}'s by as much (its Kv to Kv / (1 + {d:.6} s × Kv))",
        d * 1e3,
        m_mm * 1e3,
        shorten(&late, d)
    ))
}

/// A reversal spike's height and time, and the pulse that would supply what it lost.
///
/// The spike is one parameter, `SP<axis>` (a machine's term or the diagnosis's effect); a
/// transient is three or six parts, `SP<axis>0..2` or `SP<axis>P0..N2`, whose amount is given
/// once, on its first part's entry, for the parts together. A spike whose size scales with the
/// feed gets none (its height depends on the feed).
fn spike(id: &str, model: &SavedModel) -> Option<String> {
    let axis = Axis::from_name(id.get(2..3)?)?;
    let spike_id = format!("SP{axis}");
    let value = |id: &str| model.parameters.iter().find(|p| p.id == id).map(|p| p.value);
    let reported = if id == spike_id {
        let tau_ms = model
            .machine
            .terms
            .iter()
            .find_map(|t| match t {
                TermSpec::ReversalSpike { axis: a, tau_ms } if *a == axis => Some(*tau_ms),
                _ => None,
            })
            .or_else(|| {
                model.effects.iter().find_map(|e| match e {
                    Effect::ReversalSpike { axis: a, tau_ms } if *a == axis => Some(*tau_ms),
                    _ => None,
                })
            })?;
        vec![("amplitude_um".to_string(), value(id)? * 1e3), ("tau_ms".into(), tau_ms)]
    } else {
        let transient = model
            .effects
            .iter()
            .find(|e| matches!(e, Effect::ReversalTransient { axis: a, .. } if *a == axis))?;
        let Effect::ReversalTransient { per_side, .. } = transient else {
            return None;
        };
        let tags: &[&str] = if *per_side { &["P", "N"] } else { &[""] };
        if id != format!("{spike_id}{}0", tags[0]) {
            return None;
        }
        let spike_id = &spike_id;
        let coeffs = tags
            .iter()
            .flat_map(|tag| (0..3).map(move |k| format!("{spike_id}{tag}{k}")))
            .map(|p| value(&p))
            .collect::<Option<Vec<f64>>>()?;
        transient.report(&coeffs)
    };
    let get = |k: &str| reported.iter().find(|(n, _)| n == k).map(|(_, v)| *v);
    let (h_um, tau_ms) = (get("amplitude_um")?, get("tau_ms")?);
    let side = match (get("amplitude_pos_um"), get("amplitude_neg_um")) {
        (Some(p), Some(n)) => {
            format!(
                " ({p:.2} µm after the reversal at {axis}'s positive end, {n:.2} at its negative)"
            )
        }
        _ => String::new(),
    };
    let direction = if h_um >= 0.0 {
        "the axis falls behind after its reversal: a pulse in its new direction"
    } else {
        "the axis runs ahead after its reversal: a pulse against its new direction, or less of the one active"
    };
    // Amplitude × duration = height: µm / ms = mm/s, × 60 for mm/min.
    let amplitude_mm_per_min = h_um.abs() / tau_ms * 60.0;
    Some(format!(
        "a spike of {h_um:.2} µm{side} made up over about {tau_ms:.1} ms; {direction} supplying {:.2} µm of motion (the reversal compensation's strength, a starting value) over about {tau_ms:.1} ms ({:.4} s), an amplitude of {amplitude_mm_per_min:.1} mm/min",
        h_um.abs(),
        tau_ms * 1e-3
    ))
}

/// A rotary axis's location error `id` (`E<d>0<axis>`) as the kinematics' correction.
fn rotary(id: &str, e: &Estimate, model: &SavedModel) -> Option<String> {
    let d = id.get(1..2)?;
    let axis = id.get(3..4)?;
    let on =
        |joints: &[ballbar_model::machine::JointSpec]| joints.iter().any(|j| j.axis.name() == axis);
    // σ: the branch sign of the axis (module docs).
    let sigma = if on(&model.machine.tool) {
        1.0
    } else if on(&model.machine.workpiece) {
        -1.0
    } else {
        return None;
    };
    let f = e.unit.display_factor();
    let unit = e.unit.display_name();
    let (v, u) = (e.value * f, e.u * f);
    Some(match d {
        "X" | "Y" | "Z" => format!(
            "ISO 230-7 {id} = {v:.2} ± {u:.2} {unit}: {axis}'s axis line lies {v:.2} {unit} along +{d} from where the kinematics put it; add {v:.2} {unit} to {axis}'s {d} location in the kinematics"
        ),
        _ if d == axis => format!(
            "ISO 230-7 {id} = {v:.2} ± {u:.2} {unit} (the carried body turned so at every position): on the {} {axis} stands {:.2} {unit} further than commanded in its own coordinate; take {:.2} {unit} off its position (its zero offset)",
            if sigma > 0.0 { "tool's branch" } else { "workpiece's branch" },
            sigma * v,
            sigma * v
        ),
        _ => format!(
            "ISO 230-7 {id} = {v:.2} ± {u:.2} {unit}: {axis}'s axis line is tilted {v:.2} {unit} about +{d} from where the kinematics put it; add {v:.2} {unit} about {d} to {axis}'s orientation in the kinematics"
        ),
    })
}

#[cfg(test)]
mod tests {
    use ballbar_model::{ParamClass, TermClass};

    use super::*;
    use crate::tables::fixtures::{circle, estimate, model};
    use crate::{Options, linuxcnc};

    /// The `why` of `id` when `est` and the model `m` are compensated for LinuxCNC on the
    /// fixtures' XY circle (F 1000 mm/min).
    fn why(m: &SavedModel, est: &[Estimate], id: &str) -> String {
        let (comp, _) = linuxcnc(m, est, &[circle()], &Options::default()).unwrap();
        comp.terms.iter().find(|t| t.id == id).unwrap().why.clone().unwrap()
    }

    #[test]
    fn a_plane_mismatch_is_the_lag_difference_at_the_runs_feed() {
        // M = v (τ_Y − τ_X): 8.0 µm at F 1000 mm/min (16.667 mm/s) is 0.48 ms, Y the later;
        // −8.0 µm, X the later.
        let est = |m_mm: f64| [estimate("MXY", ParamClass::PlaneMismatch, m_mm, 1e-5)];
        let w = why(&model(&[]), &est(0.008), "MXY");
        assert!(w.starts_with("advice") && w.contains("Y lags X by 0.480 ms"), "{w}");
        assert!(w.contains("shorten Y's lag by 0.480 ms") && w.contains("1 − 0.000480 s × Kv"));
        let w = why(&model(&[]), &est(-0.008), "MXY");
        assert!(w.contains("X lags Y by 0.480 ms"), "{w}");
        // No runs of the plane: no lag can be said.
        assert_eq!(plane_mismatch("YZ", 0.008, &[circle()]), None);
    }

    #[test]
    fn the_plane_mismatch_sign_is_the_models_own_lag_of_y_behind_x() {
        // The model's own traces on the fixtures' XY circle (CCW, F 1000, R 100): Y lagging by
        // τ = 0.48 ms (the axis-lag variant's TY) against MXY = v τ = 8 µm (the paper's plane
        // term). They must be one shape, the same way round, for `plane_mismatch`'s "Y lags X".
        use ballbar_model::{Design, Model, ModelOptions, ServoVariant};
        let runs = [circle()];
        let trace = |servo, id: &str, value: f64| {
            let options = ModelOptions { servo, ..Default::default() };
            let model = Model::new(ballbar_model::machines::column(), options).unwrap();
            let design = Design::new(&model, &runs).unwrap();
            let mut theta = vec![0.0; design.n_cols()];
            theta[model.parameters().iter().position(|p| p.id == id).unwrap()] = value;
            design.exact_run(0, &theta).unwrap()
        };
        let lag = trace(ServoVariant::AxisLag, "TY", 0.48e-3);
        let m = trace(ServoVariant::PlaneMismatch, "MXY", 0.008);
        // The lag's trace regressed on the plane term's: 1 but for the lag's second order,
        // (v τ)² / R = 6e-7 of the 8 µm amplitude.
        let k = lag.iter().zip(&m).map(|(a, b)| a * b).sum::<f64>()
            / m.iter().map(|b| b * b).sum::<f64>();
        assert!((k - 1.0).abs() < 1e-3, "{k}");
        let w = why(&model(&[]), &[estimate("MXY", ParamClass::PlaneMismatch, 0.008, 1e-5)], "MXY");
        assert!(w.contains("Y lags X by 0.480 ms"), "{w}");
    }

    #[test]
    fn axis_lags_are_matched_to_the_shortest_or_the_longest() {
        let lags = vec![
            ("X".into(), 0.6e-3, 0.01e-3),
            ("Y".into(), 0.1e-3, 0.01e-3),
            ("Z".into(), 0.35e-3, 0.01e-3),
        ];
        let x = axis_lag("X", &lags).unwrap();
        // X shortens by 0.5 ms to match Y; it is the longest itself.
        assert!(x.contains("to match Y (the shortest), shorten X's lag by 0.500 ms"), "{x}");
        assert!(x.contains("X has the longest"), "{x}");
        let z = axis_lag("Z", &lags).unwrap();
        assert!(z.contains("shorten Z's lag by 0.250 ms"), "{z}");
        assert!(z.contains("lengthen Z's by 0.250 ms"), "{z}");
        assert_eq!(axis_lag("X", &lags[..1]), None);
    }

    #[test]
    fn a_spike_asks_for_its_height_of_motion_over_its_time() {
        // 3 µm made up over 15 ms: 3 µm of motion, 0.2 mm/s = 12 mm/min over 15 ms.
        let mut m = model(&[("SPX", 0.003, 1e-5)]);
        m.effects = vec![Effect::ReversalSpike { axis: Axis::X, tau_ms: 15.0 }];
        let est = [estimate("SPX", ParamClass::Term(TermClass::Effect), 0.003, 1e-5)];
        let w = why(&m, &est, "SPX");
        assert!(w.contains("a spike of 3.00 µm made up over about 15.0 ms"), "{w}");
        assert!(w.contains("a pulse in its new direction supplying 3.00 µm"), "{w}");
        assert!(w.contains("an amplitude of 12.0 mm/min"), "{w}");
    }

    #[test]
    fn a_rotary_location_is_corrected_where_the_axis_is() {
        use ballbar_model::Unit;
        use ballbar_model::chain::JointKind;
        use ballbar_model::machine::JointSpec;
        // C on the workpiece's branch (a table), B on the tool's (a head).
        let mut m = model(&[]);
        let rotary = |name: &str, axis, direction| JointSpec {
            name: name.into(),
            axis,
            kind: JointKind::Rotary,
            direction,
            origin_mm: [0.0; 3],
        };
        m.machine.workpiece.push(rotary("C table", Axis::C, [0.0, 0.0, 1.0]));
        m.machine.tool.push(rotary("B head", Axis::B, [0.0, 1.0, 0.0]));
        let class = ParamClass::Term(TermClass::RotaryLocation);
        let angle =
            |id: &str, v: f64| Estimate { unit: Unit::Angle, ..estimate(id, class, v, 1e-6) };
        // An offset of 12 µm along X: the kinematics move C's line +12 µm in X.
        let w = super::rotary("EX0C", &estimate("EX0C", class, 0.012, 0.001), &m).unwrap();
        assert!(w.contains("lies 12.00 µm along +X") && w.contains("add 12.00 µm to C's X"), "{w}");
        // A zero error turning the body +30 µrad: on the table (σ = −1) C stands 30 µrad short
        // in its own coordinate, so 30 µrad is added; on the head (σ = +1) B stands 30 µrad
        // further, taken off.
        let w = super::rotary("EC0C", &angle("EC0C", 30e-6), &m).unwrap();
        assert!(
            w.contains("C stands -30.00 µrad further") && w.contains("take -30.00 µrad"),
            "{w}"
        );
        let w = super::rotary("EB0B", &angle("EB0B", 30e-6), &m).unwrap();
        assert!(w.contains("B stands 30.00 µrad further") && w.contains("take 30.00 µrad"), "{w}");
        // A tilt of 20 µrad about A.
        let w = super::rotary("EA0C", &angle("EA0C", 20e-6), &m).unwrap();
        assert!(w.contains("tilted 20.00 µrad about +A"), "{w}");
        // An axis the machine does not have: no amount.
        assert_eq!(super::rotary("EX0A", &angle("EX0A", 1e-6), &m), None);
    }

    #[test]
    fn an_amount_not_significant_or_aliased_says_so() {
        // MXY 8 µm with u 5 µm: not significant, no change asked.
        let w =
            why(&model(&[]), &[estimate("MXY", ParamClass::PlaneMismatch, 0.008, 0.005)], "MXY");
        assert!(w.contains("no change asked") && !w.contains("by how much"), "{w}");
        // Aliased: the amount is conditional, naming the alias.
        let mut e = estimate("MXY", ParamClass::PlaneMismatch, 0.008, 1e-5);
        e.aliases = vec!["a lag of the bar".into()];
        let w = why(&model(&[]), &[e], "MXY");
        assert!(w.contains("if the model's value holds") && w.contains("a lag of the bar"), "{w}");
        assert!(w.contains("Y lags X by 0.480 ms"), "{w}");
    }

    #[test]
    fn a_transients_amount_is_given_once_for_its_parts_together() {
        // A transient of X per side: six parts, the amount on SPXP0's entry alone.
        let mut m = model(&[
            ("SPXP0", 0.002, 1e-5),
            ("SPXP1", 0.0, 1e-5),
            ("SPXP2", 0.0, 1e-5),
            ("SPXN0", 0.001, 1e-5),
            ("SPXN1", 0.0, 1e-5),
            ("SPXN2", 0.0, 1e-5),
        ]);
        m.effects = vec![Effect::ReversalTransient {
            axis: Axis::X,
            tau_ms: 10.0,
            period_ms: None,
            per_side: true,
        }];
        let fx = ParamClass::Term(TermClass::Effect);
        let est: Vec<Estimate> =
            m.parameters.iter().map(|p| estimate(&p.id, fx, p.value.max(1e-4), 1e-5)).collect();
        let first = why(&m, &est, "SPXP0");
        // The parts' peak, by the model's own report (e^{-x} of 2 µm peaks at the reversal).
        assert!(first.contains("a spike of 2.00 µm (2.00 µm after the reversal at X's positive end, 1.00 at its negative)"), "{first}");
        for id in ["SPXP1", "SPXN0"] {
            let w = why(&m, &est, id);
            assert!(!w.contains("by how much"), "{id}: {w}");
        }
    }
}

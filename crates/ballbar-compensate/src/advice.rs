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
//! Where the axes' own lags are a gauge's choice (`fit`'s default: a lag common to the axes
//! changes no radius, so their mean is taken as 0), their differences are what the tests
//! determine: the advice is built from those, each with its u from the fit's covariance
//! ([`crate::Covariance`]), a change asked only where it is at least twice its u.
//!
//! # Reversal spike
//! After a reversal the axis sticks and falls behind its command by a spike of height `h` that it
//! makes up over about `τ`. The controllers' reversal compensation adds a pulse to the velocity
//! command at the reversal; the motion it supplies (the pulse's area, amplitude × duration) is
//! what the spike lost, so `h` is the starting value of that area (HEIDENHAIN's technical manual
//! for the reversal peaks' compensation: "The reversal peak height resulting without
//! compensation is a suitable starting value"), over a duration of about `τ`: an amplitude of
//! `h / τ` (SINUMERIK's friction compensation: MD32520 the amplitude in mm/min, MD32540 its time
//! constant in s). The circularity test after it tunes both. A transient fitted per side has
//! one amount per side, its height the one the diagnosis reports for that side (the
//! transient's parts combined at its peak, [`crate::terms_with`]), and is judged significant on
//! that height against its u.
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

use crate::{Covariance, Estimate, Term};

/// Each advice term's `why` followed by the amount it asks for, where the model gives one. An
/// axis's servo lag the tests do not determine by itself (the lag common to the axes is a
/// gauge's choice) gets its differences from the other axes' lags where those are determined
/// (`cov`, [`lag_differences`]), with `why_not("servo_mismatch")`, the controller's parameter.
pub(crate) fn amend(
    entries: &mut [(Term, Estimate)],
    model: &SavedModel,
    runs: &[Run],
    cov: Option<&dyn Covariance>,
    why_not: &dyn Fn(&str) -> String,
) {
    let lags: Vec<(String, f64, f64)> = entries
        .iter()
        .filter(|(t, e)| t.term == "servo_mismatch" && t.axis.len() == 1 && e.estimable)
        .map(|(t, e)| (t.axis.clone(), e.value, e.u))
        .collect();
    let all_lags: Vec<Lag> = entries
        .iter()
        .filter(|(t, _)| t.term == "servo_mismatch" && t.axis.len() == 1)
        .map(|(t, e)| Lag { axis: t.axis.clone(), id: e.id.clone(), value_s: e.value })
        .collect();
    for (t, e) in entries.iter_mut() {
        if !e.estimable {
            if t.term == "servo_mismatch" && t.axis.len() == 1 {
                let amount = cov.and_then(|c| lag_differences(&t.axis, &all_lags, c));
                if let (Some(amount), Some(why)) = (amount, t.why.as_mut()) {
                    why.push_str(&format!(
                        "; its differences from the other axes' lags are determined (the servo mismatch): {}; by how much: {amount}",
                        why_not(&t.term)
                    ));
                }
            }
            continue;
        }
        let amount = match t.term.as_str() {
            "servo_mismatch" if t.axis.len() == 1 => axis_lag(&t.axis, &lags),
            "servo_mismatch" => plane_mismatch(&t.axis, e.value, runs),
            "reversal_spike" => spike(&t.id, e, model),
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

/// An axis's servo lag as the model has it: its axis, parameter and value (s, a gauge's where
/// the tests do not determine it).
struct Lag {
    axis: String,
    id: String,
    value_s: f64,
}

/// An axis's lag against the others' where only their differences are determined (the lag the
/// axes share is a gauge's choice): the axes whose lag differs from `axis`'s by a determined
/// amount (`cov`), each difference with its u from the covariance, and the change that matches
/// `axis` to the shortest and to the longest, each asked only where it is at least twice its
/// u. `None` where no other axis's lag differs from it by a determined amount.
fn lag_differences(axis: &str, lags: &[Lag], cov: &dyn Covariance) -> Option<String> {
    let own = lags.iter().find(|l| l.axis == axis)?;
    // `(T_b − T_a, u)`, s, where determined.
    let difference = |a: &Lag, b: &Lag| -> Option<(f64, f64)> {
        let (u, determined) = cov.combination(&[(&b.id, 1.0), (&a.id, -1.0)])?;
        (determined && u.is_finite()).then_some((b.value_s - a.value_s, u))
    };
    let group: Vec<&Lag> =
        lags.iter().filter(|l| l.axis == axis || difference(own, l).is_some()).collect();
    if group.len() < 2 {
        return None;
    }
    let mut listed = Vec::new();
    for (i, a) in group.iter().enumerate() {
        for b in &group[i + 1..] {
            let (d, u) = difference(a, b)?;
            listed.push(format!("{} − {} {:.3} ± {:.3} ms", b.axis, a.axis, d * 1e3, u * 1e3));
        }
    }
    let by = |f: fn(&f64, &f64) -> std::cmp::Ordering| {
        group.iter().copied().min_by(|a, b| f(&a.value_s, &b.value_s))
    };
    let shortest = by(f64::total_cmp)?;
    let longest = by(|a, b| b.total_cmp(a))?;
    let unasked = |other: &Lag, d: f64, u: f64| {
        format!(
            "no change asked to match {}: {axis}'s lag differs from it by {:.3} ± {:.3} ms, below twice its standard uncertainty",
            other.axis,
            d * 1e3,
            u * 1e3
        )
    };
    let to_shortest = if shortest.axis == axis {
        format!("{axis} has the shortest lag: the others match it")
    } else {
        let (d, u) = difference(shortest, own)?;
        if d < 2.0 * u {
            unasked(shortest, d, u)
        } else {
            format!("to match {} (the shortest), {}", shortest.axis, shorten(axis, d, Some(u)))
        }
    };
    let to_longest = if longest.axis == axis {
        format!("{axis} has the longest: matching it, the others lengthen theirs")
    } else {
        let (d, u) = difference(own, longest)?;
        if d < 2.0 * u {
            unasked(longest, d, u)
        } else {
            format!(
                "or, to match {} (the longest: no gain raised), lengthen {axis}'s by {:.3} ± {:.3} ms (its Kv to Kv / (1 + {d:.6} s × Kv))",
                longest.axis,
                d * 1e3,
                u * 1e3
            )
        }
    };
    Some(format!(
        "the lag differences these tests determine (the lag the axes share is not: a gauge's choice) {}; {to_shortest}; {to_longest}",
        listed.join(", ")
    ))
}

/// The gain and feed-forward changes that shorten a lag by `delta_s`, in words, with its
/// standard uncertainty `u_s` where given.
fn shorten(axis: &str, delta_s: f64, u_s: Option<f64>) -> String {
    let d = delta_s;
    let u = u_s.map_or(String::new(), |u| format!(" ± {:.3}", u * 1e3));
    format!(
        "shorten {axis}'s lag by {:.3}{u} ms: its gain Kv (1/s) to Kv / (1 − {d:.6} s × Kv) while {d:.6} s × Kv < 1, or its velocity feed-forward fraction up by {d:.6} s × Kv",
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
        format!("to match {} (the shortest), {}", shortest.0, shorten(axis, own - shortest.1, None))
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
        shorten(&late, d, None)
    ))
}

/// A reversal spike's height and time, and the pulse that would supply what it lost.
///
/// The spike is one parameter, `SP<axis>` (a machine's term or the diagnosis's effect), or one
/// side of a transient, `SP<axis>P` or `SP<axis>N` (`SP<axis>` for one fitted for both sides),
/// whose height `e` carries as [`crate::terms_with`] made it from the transient's parts: the
/// height `diagnose` reports for that side. A spike whose size scales with the feed gets none
/// (its height depends on the feed).
fn spike(id: &str, e: &Estimate, model: &SavedModel) -> Option<String> {
    let axis = Axis::from_name(id.get(2..3)?)?;
    let side = id.get(3..)?;
    let spike_tau = model
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
        });
    let (tau_ms, at) = match (spike_tau, side) {
        (Some(tau_ms), "") => (tau_ms, String::new()),
        _ => {
            let (effect, feed_scaled) = crate::transient_of(model, axis)?;
            let Effect::ReversalTransient { tau_ms, .. } = effect else { return None };
            if feed_scaled {
                return None;
            }
            let at = match side {
                "P" => format!(" after the reversal at {axis}'s positive end"),
                "N" => format!(" after the reversal at {axis}'s negative end"),
                _ => String::new(),
            };
            (tau_ms, at)
        }
    };
    let h_um = e.value * 1e3;
    let direction = if h_um >= 0.0 {
        "the axis falls behind after its reversal: a pulse in its new direction"
    } else {
        "the axis runs ahead after its reversal: a pulse against its new direction, or less of the one active"
    };
    // Amplitude × duration = height: µm / ms = mm/s, × 60 for mm/min.
    let amplitude_mm_per_min = h_um.abs() / tau_ms * 60.0;
    Some(format!(
        "a spike of {h_um:.2} ± {:.2} µm{at} made up over about {tau_ms:.1} ms; {direction} supplying {:.2} µm of motion (the reversal compensation's strength, a starting value) over about {tau_ms:.1} ms ({:.4} s), an amplitude of {amplitude_mm_per_min:.1} mm/min",
        e.u * 1e3,
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
        assert!(w.contains("a spike of 3.00 ± 0.01 µm made up over about 15.0 ms"), "{w}");
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

    /// A covariance given by hand for the tests: `ids`' covariance matrix `c` (internal units),
    /// and the directions the tests leave undetermined (a combination is determined when it is
    /// orthogonal to each).
    #[derive(Debug)]
    struct Hand {
        ids: Vec<&'static str>,
        c: Vec<Vec<f64>>,
        null: Vec<Vec<f64>>,
    }

    impl Covariance for Hand {
        fn combination(&self, weights: &[(&str, f64)]) -> Option<(f64, bool)> {
            let mut w = vec![0.0; self.ids.len()];
            for &(id, x) in weights {
                w[self.ids.iter().position(|i| *i == id)?] += x;
            }
            let var: f64 = (0..w.len())
                .flat_map(|i| (0..w.len()).map(move |j| (i, j)))
                .map(|(i, j)| w[i] * self.c[i][j] * w[j])
                .sum();
            let determined =
                self.null.iter().all(|n| n.iter().zip(&w).map(|(a, b)| a * b).sum::<f64>() == 0.0);
            Some((var.sqrt(), determined))
        }
    }

    /// The `why` of `id` when `est` and the model `m` are compensated for LinuxCNC on the
    /// fixtures' XY circle with the covariance `cov` (the CLI's fit's, [`Options::covariance`]).
    fn why_with(
        m: &SavedModel,
        est: &[Estimate],
        cov: Option<Hand>,
        id: &str,
    ) -> (crate::Term, Vec<String>) {
        let options =
            Options { covariance: cov.map(|c| std::sync::Arc::new(c) as _), ..Options::default() };
        let (comp, _) = linuxcnc(m, est, &[circle()], &options).unwrap();
        let t = comp.terms.iter().find(|t| t.id == id).unwrap().clone();
        (t, comp.terms.iter().map(|t| t.id.clone()).collect())
    }

    /// The per-axis lags of fit's default servo model: each one a gauge's choice (their mean is
    /// taken as 0), their differences determined. TX 0, TY 0.5 ms, TZ 0.1 ms, each with σ 0.02
    /// ms and independent (`u(T_b − T_a) = √2 × 0.02 = 0.028 ms`), the common lag (1, 1, 1)
    /// undetermined: X is the shortest, Y the longest by 0.500 ± 0.028 ms, Z 0.100 ± 0.028 ms
    /// behind X (3.5 u: asked); with TZ 0.04 ms, Z − X 0.040 ± 0.028 ms is below 2u and not
    /// asked. Without the covariance (no runs) no difference can be said, as before.
    #[test]
    fn undetermined_axis_lags_are_advised_by_their_determined_differences() {
        let lag = ParamClass::Term(TermClass::ServoLag);
        let est = |tz: f64| -> Vec<Estimate> {
            [("TX", 0.0), ("TY", 0.5e-3), ("TZ", tz)]
                .into_iter()
                .map(|(id, v)| Estimate {
                    unit: ballbar_model::Unit::Time,
                    estimable: false,
                    ..estimate(id, lag, v, 0.035e-3)
                })
                .collect()
        };
        let s2 = 0.02e-3f64.powi(2);
        let hand = || Hand {
            ids: vec!["TX", "TY", "TZ"],
            c: vec![vec![s2, 0.0, 0.0], vec![0.0, s2, 0.0], vec![0.0, 0.0, s2]],
            null: vec![vec![1.0, 1.0, 1.0]],
        };
        let m = model(&[]);
        let (x, _) = why_with(&m, &est(0.1e-3), Some(hand()), "TX");
        let x = x.why.unwrap();
        assert!(x.starts_with("the tests do not determine it (a gauge's choice fixes it); its differences from the other axes' lags are determined"), "{x}");
        assert!(x.contains("match the axes' position-loop response"), "{x}");
        assert!(
            x.contains("Y − X 0.500 ± 0.028 ms, Z − X 0.100 ± 0.028 ms, Z − Y -0.400 ± 0.028 ms"),
            "{x}"
        );
        assert!(x.contains("X has the shortest lag: the others match it"), "{x}");
        assert!(x.contains("to match Y (the longest: no gain raised), lengthen X's by 0.500 ± 0.028 ms (its Kv to Kv / (1 + 0.000500 s × Kv))"), "{x}");
        let (y, _) = why_with(&m, &est(0.1e-3), Some(hand()), "TY");
        let y = y.why.unwrap();
        assert!(y.contains("to match X (the shortest), shorten Y's lag by 0.500 ± 0.028 ms: its gain Kv (1/s) to Kv / (1 − 0.000500 s × Kv)"), "{y}");
        assert!(y.contains("Y has the longest"), "{y}");
        let (z, _) = why_with(&m, &est(0.1e-3), Some(hand()), "TZ");
        let z = z.why.unwrap();
        assert!(z.contains("shorten Z's lag by 0.100 ± 0.028 ms"), "{z}");
        assert!(z.contains("lengthen Z's by 0.400 ± 0.028 ms"), "{z}");
        let (z, _) = why_with(&m, &est(0.04e-3), Some(hand()), "TZ");
        let z = z.why.unwrap();
        assert!(z.contains("no change asked to match X: Z's lag differs from it by 0.040 ± 0.028 ms, below twice its standard uncertainty"), "{z}");
        // Z at rest (an XY test): its lag is fixed by itself, so its differences are not
        // determined either; X and Y keep theirs.
        let xy = Hand { null: vec![vec![1.0, 1.0, 0.0], vec![0.0, 0.0, 1.0]], ..hand() };
        let (z, _) = why_with(&m, &est(0.1e-3), Some(xy), "TZ");
        assert_eq!(z.why.unwrap(), "the tests do not determine it (a gauge's choice fixes it)");
        let xy = Hand { null: vec![vec![1.0, 1.0, 0.0], vec![0.0, 0.0, 1.0]], ..hand() };
        let (x, _) = why_with(&m, &est(0.1e-3), Some(xy), "TX");
        let x = x.why.unwrap();
        assert!(x.contains("Y − X 0.500 ± 0.028 ms;") && !x.contains("Z −"), "{x}");
        let (x, _) = why_with(&m, &est(0.1e-3), None, "TX");
        assert_eq!(x.why.unwrap(), "the tests do not determine it (a gauge's choice fixes it)");
    }

    /// A reversal transient per side is one term per side, its value the height the model
    /// reports at the peak and its u that of the combination, judged on that height. X's
    /// positive side is `x e^{-x}` alone (SPXP1 = 2e µm): its height is `SPXP1/e` = 2 µm at
    /// `x = 1`, where each part's weight is `e^{-1}` (`e^{-x}`, `x e^{-x}`, `x² e^{-x}` at 1);
    /// its negative side `e^{-x}` of 1 µm, at the reversal. With σ 1 µm for each of the
    /// positive side's parts and a correlation of -0.45 between each two, `u² = e^{-2} σ² (3 −
    /// 6 × 0.45)`: u = 0.201 µm, where the parts' bound `3 e^{-1} σ` is 1.104 µm and the first
    /// part, SPXP0, is 0 ± 1 µm (which asked no change before).
    #[test]
    fn a_transient_is_one_term_per_side_judged_on_its_height() {
        let e1 = (-1.0f64).exp();
        let a = 2e-3 / e1;
        let mut m = model(&[
            ("SPXP0", 0.0, 1e-3),
            ("SPXP1", a, 1e-3),
            ("SPXP2", 0.0, 1e-3),
            ("SPXN0", 1e-3, 1e-5),
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
            m.parameters.iter().map(|p| estimate(&p.id, fx, p.value, p.std_uncertainty)).collect();
        let (s, r) = (1e-3f64, -0.45);
        let mut c = vec![vec![0.0; 6]; 6];
        for (i, row) in c.iter_mut().enumerate() {
            for (j, x) in row.iter_mut().enumerate() {
                *x = match (i < 3, j < 3) {
                    (true, true) if i == j => s * s,
                    (true, true) => r * s * s,
                    _ if i == j => 1e-10,
                    _ => 0.0,
                };
            }
        }
        let hand = Hand {
            ids: vec!["SPXP0", "SPXP1", "SPXP2", "SPXN0", "SPXN1", "SPXN2"],
            c,
            null: vec![],
        };
        let (p, ids) = why_with(&m, &est, Some(hand), "SPXP");
        assert_eq!(
            ids.iter().filter(|i| i.starts_with("SP")).collect::<Vec<_>>(),
            ["SPXP", "SPXN"]
        );
        let (v, u, unit) = p.value();
        assert_eq!((p.term.as_str(), p.axis.as_str(), unit), ("reversal_spike", "X", "µm"));
        assert!((v - 2.0).abs() < 1e-6, "{v}");
        let u_hand = e1 * 1.0 * (3.0f64 - 6.0 * 0.45).sqrt();
        assert!((u - u_hand).abs() < 1e-6 && (u - 0.201).abs() < 1e-3, "{u} {u_hand}");
        let w = p.why.unwrap();
        assert!(w.contains("by how much: a spike of 2.00 ± 0.20 µm after the reversal at X's positive end made up over about 10.0 ms"), "{w}");
        assert!(w.contains("supplying 2.00 µm of motion") && w.contains("12.0 mm/min"), "{w}");
        let (n, _) = why_with(&m, &est, None, "SPXN");
        assert!((n.value().0 - 1.0).abs() < 1e-9, "{n:?}");
        assert!(
            n.why
                .unwrap()
                .contains("a spike of 1.00 ± 0.01 µm after the reversal at X's negative end")
        );
        // Without the covariance (no runs to refit) the u is the parts' bound, Σ |w_k| u_k,
        // which the height, 2 µm, is not twice: no change is asked on it.
        let (p, _) = why_with(&m, &est, None, "SPXP");
        assert!((p.value().1 - 3.0 * e1).abs() < 1e-6, "{p:?}");
        let w = p.why.unwrap();
        assert!(
            w.contains(
                "no change asked: SPXP 2.000 is below twice its standard uncertainty (1.104)"
            ),
            "{w}"
        );
    }
}

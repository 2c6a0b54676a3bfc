//! An accepted effect in shop-floor words: what is physically wrong, on which axis, how big,
//! and what to do next (adjust, compensate, re-test). One sentence per effect, written from
//! the effect's kind, axis and fitted parameters (`diagnose`'s terminal and the report's page
//! both say it, above the statistics).
//!
//! The sizes are the fitted parameters as the diagnosis gives them; the G figures are the
//! held-out ISO 230-4 circular deviations before and after the effect, so "how big" is
//! against what the test measures. A tolerance, where the user gives one, is the report's
//! acceptance table, whose checks take their actions from here too (the kinds `squareness`,
//! `scale`, `scale_mismatch`, and a servo mismatch given as `lag_difference_ms`, with the
//! check's value as the size and no G).

use std::collections::BTreeMap;

use crate::diagnosis::Subject;

/// What one sentence is written from.
pub struct Facts<'a> {
    /// The effect's kind, axis and switching axis.
    pub subject: &'a Subject,
    /// Its parameters, `<name>_<unit>` as the diagnosis gives them.
    pub parameters: &'a BTreeMap<String, f64>,
    /// Held-out G without and with it, µm.
    pub g_before_um: f64,
    /// See `g_before_um`.
    pub g_after_um: f64,
}

/// The sentence: the fault, its size, the action, and what correcting it does to G.
pub fn shop_floor(f: &Facts<'_>) -> String {
    let p = |k: &str| f.parameters.get(k).copied().filter(|v| v.is_finite());
    let axis = f.subject.axis.as_deref().unwrap_or("the machine");
    let um = |k: &str| p(k).map_or("an unknown size".to_string(), |v| format!("{:.1} µm", v.abs()));
    let fault = match f.subject.kind.as_str() {
        "reversal_spike" => {
            let sides = match (p("amplitude_pos_um"), p("amplitude_neg_um")) {
                (Some(a), Some(b)) => format!(
                    " ({:.1} µm at its positive end, {:.1} µm at its negative end)",
                    a.abs(),
                    b.abs()
                ),
                _ => String::new(),
            };
            format!(
                "Axis {axis} overshoots where it reverses: a spike of {}{sides}{}. Adjust {axis}'s reversal (friction or quadrant-glitch) compensation in its drive, then repeat this test at the same feed",
                um("amplitude_um"),
                p("tau_ms").map_or(String::new(), |t| format!(", dying away in about {t:.0} ms"))
            )
        }
        "lateral_play" => format!(
            "Axis {axis} shifts sideways by {} when {} reverses: play in {axis}'s guideways or bearings. Check {axis}'s gibs and way preload and adjust them; it cannot be compensated",
            um("play_um"),
            f.subject.switched_by.as_deref().unwrap_or("another axis")
        ),
        "cyclic_error" => format!(
            "Axis {axis} has a ripple of {} that repeats every {} of its travel. Compare that pitch with {axis}'s screw lead and its encoder's period: a worn screw or support bearing is repaired, an encoder error compensated",
            um("amplitude_um"),
            p("pitch_mm").map_or("few millimetres".into(), |v| format!("{v:.2} mm"))
        ),
        "vibration" => format!(
            "A vibration of {} at {} on {axis}. Check {axis}'s drive tuning (velocity loop) and what is loose on the machine; repeat the test at another feed to see whether it follows the motion",
            um("amplitude_um"),
            p("frequency_hz").map_or("a steady frequency".into(), |v| format!("{v:.1} Hz"))
        ),
        "stick_slip" => format!(
            "Axis {axis} sticks and slips at low speed (below {}), by {}. Check the lubrication of {axis}'s ways and its friction compensation",
            p("speed_mm_per_min").map_or("a slow feed".into(), |v| format!("{v:.0} mm/min")),
            um("amplitude_um")
        ),
        "thermal_drift" => match (p("rate_um_per_h"), p("rate_ppm_per_h"), p("growth_ppm")) {
            (Some(r), ..) => format!(
                "The readings drift by {:.1} µm an hour as the machine or the bar warms. Warm the machine up before testing, keep the bar out of the hand, and repeat the test cycle later to measure the growth",
                r.abs()
            ),
            (None, Some(r), _) => format!(
                "Axis {axis} grows by {:.1} ppm an hour as it warms. Warm the machine up before testing; a growth that remains is for the controller's thermal compensation",
                r.abs()
            ),
            (None, None, Some(g)) => format!(
                "Axis {axis} grows by {:.1} ppm as it warms{}. Warm the machine up before testing; a growth that remains is for the controller's thermal compensation",
                g.abs(),
                p("time_constant_min").map_or(String::new(), |t| format!(", settling in about {t:.0} min"))
            ),
            _ => "The readings drift as the machine or the bar warms. Warm the machine up before testing and repeat the test cycle later".into(),
        },
        "servo_lag" => format!(
            "The axes lag the command by {} in common, which shrinks the circle more at higher feed. Nothing is wrong in the geometry; the controller's feed-forward reduces it",
            p("common_lag_ms").map_or("a few milliseconds".into(), |v| format!("{v:.1} ms"))
        ),
        "servo_mismatch" => format!(
            "Two axes follow the command with different lags ({} seen in {axis}): the circle leans into an oval. Match the axes' position-loop gains (kv) in the controller",
            match (p("value_um"), p("lag_difference_ms")) {
                (Some(v), _) => format!("{:.1} µm at the test's feed,", v.abs()),
                (None, Some(t)) => format!("{:.3} ms apart,", t.abs()),
                _ => "an unknown size,".into(),
            }
        ),
        "squareness" => format!(
            "Axes {axis} are out of square by {}: the angle between their ways. Realign them (shim the column or the ways); a controller's cross-axis compensation can take it (`ballbar compensate --controller siemens` writes a SINUMERIK CEC table; its LinuxCNC, FANUC and HEIDENHAIN files hold none)",
            p("value_um_per_m").map_or("an unknown angle".into(), |v| format!("{:.1} µm/m", v.abs()))
        ),
        "scale" => format!(
            "Axis {axis} travels {} too far or too short (µm per metre of travel): a positional error of its scale or screw. Let the machine reach its working temperature, then compensate it (ballbar compensate writes a pitch-error table) or check the axis's encoder setting",
            p("value_ppm").map_or("an unknown amount".into(), |v| format!("{:.1} ppm", v.abs()))
        ),
        "scale_mismatch" => format!(
            "The axes {axis} differ in scale by {}: the circle is stretched into an oval along one of them. Compensate each axis's scale (ballbar compensate writes a pitch-error table per axis) after the machine reaches its working temperature",
            p("value_ppm").map_or("an unknown amount".into(), |v| format!("{:.1} ppm", v.abs()))
        ),
        "positional_higher_order" => format!(
            "Axis {axis}'s position error is not a straight line along its travel ({}): its screw's pitch error. Measure {axis} with a laser and compensate with a pitch-error table",
            um("value_um")
        ),
        "straightness_higher_order" => format!(
            "Axis {axis} moves on a curved path ({}): a straightness error of its ways. Measure it with a straightedge or laser; realign the ways or compensate where the controller has cross-axis tables",
            um("value_um")
        ),
        "angular_error" => format!(
            "Axis {axis} tilts as it moves ({}): an angular error of its ways, seen through the tool's offset. Measure it with a level or a laser's angular optics",
            p("value_urad").map_or("an unknown angle".into(), |v| format!("{:.0} µrad", v.abs()))
        ),
        "backlash" => format!(
            "Axis {axis} loses {} each time it reverses: backlash. Set it in the controller's backlash compensation (ballbar compensate), or adjust the nut's preload if it is large",
            um("value_um")
        ),
        "bar_length" => format!(
            "The bar reads {} long or short of its calibration: a set-up error, not the machine's. Recalibrate the bar and let it reach the machine's temperature",
            um("value_um")
        ),
        "bar_length_drift" => format!(
            "Each run reads a radius of its own, {} RMS from run to run ({} from the shortest to the longest): the bar's length changing with its temperature, or a common growth of the axes, which a circle test reads alike. Let the bar reach the machine's temperature and check it in its calibrator between runs; if it holds, the machine's radius is what moves",
            um("spread_um"),
            um("range_um")
        ),
        "centring" => "The circle is off the bar's pivot: a set-up error, not the machine's. Recentre the pivot before the next test".into(),
        _ => format!("{}: {}", f.subject.kind.replace('_', " "), axis),
    };
    let g = if f.g_before_um.is_finite() && f.g_after_um.is_finite() {
        // Unchanged at the printed tenth: said so, not "from 5.3 to 5.3".
        if (f.g_before_um - f.g_after_um).abs() < 0.05 {
            format!(
                "; correcting it hardly changes the circular deviation G ({:.1} µm)",
                f.g_before_um
            )
        } else {
            format!(
                "; correcting it takes the circular deviation G from {:.1} to {:.1} µm on runs it was not fitted to",
                f.g_before_um, f.g_after_um
            )
        }
    } else {
        String::new()
    };
    format!("{fault}{g}.")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn say(kind: &str, axis: Option<&str>, params: &[(&str, f64)]) -> String {
        let subject = Subject {
            kind: kind.into(),
            axis: axis.map(str::to_string),
            switched_by: Some("Y".into()),
        };
        let parameters: BTreeMap<String, f64> =
            params.iter().map(|(k, v)| (k.to_string(), *v)).collect();
        shop_floor(&Facts {
            subject: &subject,
            parameters: &parameters,
            g_before_um: 7.03,
            g_after_um: 1.44,
        })
    }

    /// Each sentence names the axis, the size from the parameters (as given, in µm to a
    /// tenth), an action, and G before and after.
    #[test]
    fn a_sentence_names_the_fault_its_size_the_action_and_g() {
        let s = say(
            "reversal_spike",
            Some("X"),
            &[
                ("amplitude_um", -4.26),
                ("amplitude_pos_um", 2.1),
                ("amplitude_neg_um", -4.26),
                ("tau_ms", 41.0),
            ],
        );
        assert_eq!(
            s,
            "Axis X overshoots where it reverses: a spike of 4.3 µm (2.1 µm at its positive end, 4.3 µm at its negative end), dying away in about 41 ms. Adjust X's reversal (friction or quadrant-glitch) compensation in its drive, then repeat this test at the same feed; correcting it takes the circular deviation G from 7.0 to 1.4 µm on runs it was not fitted to."
        );
        let s = say("lateral_play", Some("X"), &[("play_um", 0.23)]);
        assert!(s.ends_with("; correcting it takes the circular deviation G from 7.0 to 1.4 µm on runs it was not fitted to."), "{s}");
        assert!(s.starts_with("Axis X shifts sideways by 0.2 µm when Y reverses"), "{s}");
        let s = say("cyclic_error", Some("Y"), &[("amplitude_um", 0.8), ("pitch_mm", 5.0)]);
        assert!(s.contains("a ripple of 0.8 µm that repeats every 5.00 mm"), "{s}");
        let s = say("servo_mismatch", Some("ZX"), &[("value_um", 9.8058)]);
        assert!(s.contains("(9.8 µm at the test's feed, seen in ZX)") && s.contains("kv"), "{s}");
        let s = say("servo_mismatch", Some("XY"), &[("lag_difference_ms", -0.97371)]);
        assert!(s.contains("(0.974 ms apart, seen in XY)"), "{s}");
        let s = say("squareness", Some("X and Y"), &[("value_um_per_m", -132.63)]);
        assert!(s.starts_with("Axes X and Y are out of square by 132.6 µm/m"), "{s}");
        assert!(
            s.contains(
                "writes a SINUMERIK CEC table; its LinuxCNC, FANUC and HEIDENHAIN files hold none"
            ),
            "{s}"
        );
        let s = say("scale", Some("X"), &[("value_ppm", 56.48)]);
        assert!(s.starts_with("Axis X travels 56.5 ppm too far or too short"), "{s}");
        assert!(s.contains("ballbar compensate writes a pitch-error table"), "{s}");
        let s = say("scale_mismatch", Some("X and Y"), &[("value_ppm", -32.5)]);
        assert!(s.starts_with("The axes X and Y differ in scale by 32.5 ppm"), "{s}");
        let s = say("thermal_drift", None, &[("rate_um_per_h", -3.04)]);
        assert!(s.starts_with("The readings drift by 3.0 µm an hour"), "{s}");
    }

    /// G unchanged at its printed tenth is said so.
    #[test]
    fn an_unchanged_g_is_said_so() {
        let subject =
            Subject { kind: "lateral_play".into(), axis: Some("X".into()), switched_by: None };
        let parameters = BTreeMap::from([("play_um".to_string(), 0.2)]);
        let s = shop_floor(&Facts {
            subject: &subject,
            parameters: &parameters,
            g_before_um: 5.31,
            g_after_um: 5.29,
        });
        assert!(
            s.ends_with("; correcting it hardly changes the circular deviation G (5.3 µm)."),
            "{s}"
        );
    }

    /// A parameter the effect lacks is said to be unknown, never printed as a number.
    #[test]
    fn a_missing_size_is_said_not_invented() {
        let s = say("backlash", Some("Z"), &[]);
        assert!(s.contains("loses an unknown size"), "{s}");
        assert!(!s.contains("NaN") && !s.contains(" 0.0 µm"), "{s}");
    }
}

//! The validation suite, one test per scenario of [`crate::suite::scenarios`]: each simulates
//! a machine with effects the base model lacks, diagnoses it without any hint, and asserts
//! that the diagnosis found what was withheld. The checks and their tolerances are in
//! [`crate::suite`], next to their justification, so that `cargo xtask validate` and these
//! tests judge alike:
//! - kind and axis: the withheld effect is among the accepted effects, and nothing else is;
//! - `where`: the gap's planes hold at least [`crate::suite::WHERE_IN_PLANES`] of the listed
//!   share, the largest entry and every plane of the effect; arcs at the axis's reversals for
//!   effects tied to reversals;
//! - held-out shrink: positive, and within [`crate::suite::GAP_CLOSED`] of the truth's (an oracle:
//!   the same held-out evaluation with the true effect in the model);
//! - parameters: linear coefficients within [`crate::suite::K_SIGMA`] standard uncertainties plus
//!   the bias of a non-linear parameter off its true value; decay times and speeds within half
//!   a grid step of the truth; pitches within half a periodogram step; phases within what the
//!   pitch error moves them.
//!
//! Each test also states, directly on the diagnosis, the kind and axis it must find, so that it
//! reads on its own.

use crate::suite::{self as validation, Outcome};
use ballbar_diagnose::Accepted;

/// Run a scenario and print its checks (shown when the test fails).
fn outcome(name: &str) -> Outcome {
    let s = validation::scenarios()
        .into_iter()
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("no scenario {name}"));
    let o = validation::run(&s, 2).unwrap_or_else(|e| panic!("{name}: {e}"));
    eprintln!("{name} ({:.1} s): {} → {}", o.seconds, o.truth, o.diagnosis);
    for c in &o.checks {
        eprintln!("  {} {}: {}", if c.pass { "ok  " } else { "FAIL" }, c.name, c.detail);
    }
    o
}

/// Every check passed, and the named ones were made (a check that was not made cannot fail).
fn passes(o: &Outcome, required: &[&str]) {
    checks_pass(o.scenario, &o.checks, required);
}

/// A scenario's checks (of either validation set) all passed, and the named ones were made.
pub(crate) fn checks_pass(scenario: &str, checks: &[crate::suite::Check], required: &[&str]) {
    for r in required {
        assert!(
            checks.iter().any(|c| c.name.starts_with(r)),
            "{scenario}: no check '{r}' was made"
        );
    }
    let failed: Vec<String> =
        crate::suite::failed(checks).iter().map(|c| format!("{}: {}", c.name, c.detail)).collect();
    assert!(failed.is_empty(), "{scenario}: {}", failed.join("; "));
}

/// The accepted effect of a given kind and axis.
fn found<'a>(o: &'a Outcome, kind: &str, axis: Option<&str>) -> &'a Accepted {
    o.diagnosis_result
        .effects
        .iter()
        .find(|e| e.effect.kind() == kind && e.effect.axis_label().as_deref() == axis)
        .unwrap_or_else(|| {
            panic!(
                "{}: no {kind} {axis:?} among the accepted effects ({})",
                o.scenario, o.diagnosis
            )
        })
}

const KIND: &str = "kind and axis";
const ONLY: &str = "no other effect";
const PLANES: &str = "where: planes";
const ARCS: &str = "where: reversal arcs";
const SHRINK: &str = "held-out shrink";
const BASELINE: &str = "held-out baseline";

#[test]
fn reversal_spike_of_y() {
    let o = outcome("reversal-spike-y");
    found(&o, "reversal_spike", Some("Y"));
    passes(
        &o,
        &[
            KIND,
            ONLY,
            PLANES,
            ARCS,
            SHRINK,
            BASELINE,
            "parameter amplitude_pos_um",
            "parameter amplitude_neg_um",
            "parameter tau_ms",
            "shape at the positive end",
            "shape at the negative end",
        ],
    );
}

#[test]
fn small_short_reversal_spike_of_x() {
    let o = outcome("reversal-spike-x");
    found(&o, "reversal_spike", Some("X"));
    passes(
        &o,
        &[
            KIND,
            ONLY,
            PLANES,
            ARCS,
            SHRINK,
            BASELINE,
            "parameter amplitude_pos_um",
            "parameter amplitude_neg_um",
            "parameter tau_ms",
            "shape at the positive end",
            "shape at the negative end",
        ],
    );
}

#[test]
fn lateral_play_of_x_switched_by_y() {
    let o = outcome("lateral-play-xy");
    found(&o, "lateral_play", Some("XY"));
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter play_um"]);
}

#[test]
fn cyclic_error_of_x() {
    let o = outcome("cyclic-x");
    found(&o, "cyclic_error", Some("X"));
    passes(
        &o,
        &[
            KIND,
            ONLY,
            PLANES,
            SHRINK,
            BASELINE,
            "parameter amplitude_um",
            "parameter pitch_mm",
            "parameter phase_deg",
        ],
    );
}

#[test]
fn vibration_of_y_with_repeats_held_out_whole() {
    let o = outcome("vibration-y");
    found(&o, "vibration", Some("Y"));
    passes(
        &o,
        &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter amplitude_um", "parameter frequency_hz"],
    );
}

#[test]
fn vibration_of_z_with_quarters_of_runs_held_out() {
    let o = outcome("vibration-z-quarters");
    found(&o, "vibration", Some("Z"));
    passes(
        &o,
        &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter amplitude_um", "parameter frequency_hz"],
    );
}

#[test]
fn a_bar_length_error_is_aliased_at_one_radius_and_found_with_two() {
    let o = outcome("bar-length-one-radius");
    assert!(o.diagnosis_result.effects.is_empty(), "{}", o.diagnosis);
    assert!(
        o.diagnosis_result.aliased.iter().any(|a| a.effect == ballbar_model::Effect::BarLength),
        "{}",
        o.diagnosis
    );
    passes(&o, &["aliased"]);
    let o = outcome("bar-length-two-radii");
    found(&o, "bar_length", None);
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter value_um"]);
}

#[test]
fn thermal_drift_of_z() {
    let o = outcome("thermal-drift-z");
    found(&o, "thermal_drift", Some("Z"));
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter rate_um_per_h"]);
}

#[test]
fn thermal_growth_of_the_bar() {
    let o = outcome("thermal-drift-bar");
    found(&o, "thermal_drift", None);
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter rate_um_per_h"]);
}

#[test]
fn stick_slip_of_y_at_low_feed() {
    let o = outcome("stick-slip-y");
    found(&o, "stick_slip", Some("Y"));
    passes(
        &o,
        &[
            KIND,
            ONLY,
            PLANES,
            ARCS,
            SHRINK,
            BASELINE,
            "parameter amplitude_um",
            "parameter speed_mm_per_min",
        ],
    );
}

#[test]
fn servo_radius_loss_across_two_feeds() {
    let o = outcome("servo-radius-loss");
    found(&o, "servo_lag", None);
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter lag_squared_ms2"]);
}

#[test]
fn cubic_positional_error_of_x_at_two_centres() {
    let o = outcome("positional-cubic-x");
    found(&o, "positional_higher_order", Some("X"));
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter value_um"]);
}

#[test]
fn cubic_straightness_of_x_in_y_at_two_centres() {
    let o = outcome("straightness-cubic-yx");
    found(&o, "straightness_higher_order", Some("X"));
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter value_um"]);
}

#[test]
fn angular_error_at_one_tool_length_is_aliased() {
    let o = outcome("angular-z-one-tool-length");
    let d = &o.diagnosis_result;
    assert!(d.effects.is_empty(), "{}", o.diagnosis);
    let a = d.aliased.iter().find(|a| {
        a.effect.kind() == "angular_error" && a.effect.axis_label().as_deref() == Some("Z")
    });
    assert!(
        a.is_some_and(|a| !a.with.is_empty() && a.test_to_separate.contains("tool length")),
        "{}",
        o.diagnosis
    );
    passes(&o, &["no effect", "aliased: angular_error Z"]);
}

#[test]
fn angular_error_with_a_second_tool_length_is_named() {
    let o = outcome("angular-z-two-tool-lengths");
    let e = found(&o, "angular_error", Some("Z"));
    assert_eq!(
        e.effect,
        ballbar_model::Effect::AngularError {
            axis: ballbar_model::Axis::Z,
            about: ballbar_model::Axis::Y
        }
    );
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter value_urad"]);
}

#[test]
fn two_effects_at_once() {
    let o = outcome("spike-x-and-cyclic-y");
    found(&o, "reversal_spike", Some("X"));
    found(&o, "cyclic_error", Some("Y"));
    assert_eq!(o.diagnosis_result.effects.len(), 2, "{}", o.diagnosis);
    passes(
        &o,
        &[
            "kind and axis: reversal_spike X",
            "kind and axis: cyclic_error Y",
            ONLY,
            PLANES,
            SHRINK,
            BASELINE,
            "parameter tau_ms",
            "parameter pitch_mm",
        ],
    );
}

#[test]
fn null_with_correlated_noise_finds_nothing() {
    let o = outcome("null-correlated-noise");
    assert!(o.diagnosis_result.effects.is_empty(), "{}", o.diagnosis);
    // The noise is what the scenario says it is: correlated, and the diagnosis measured it so.
    assert!(
        o.diagnosis_result.gap.noise_lag1_autocorrelation > 0.5,
        "ρ {}",
        o.diagnosis_result.gap.noise_lag1_autocorrelation
    );
    passes(&o, &["no effect"]);
}

#[test]
fn the_papers_column_data_with_per_axis_lags_needs_a_plane_mismatch() {
    let o = outcome("paper-column-axis-lags");
    let d = &o.diagnosis_result;
    assert_eq!(d.effects.len(), 1, "{}", o.diagnosis);
    // Any one plane's term completes the three lags: which plane is not identifiable.
    assert_eq!(d.effects[0].effect.kind(), "servo_mismatch");
    passes(&o, &[KIND, ONLY, PLANES, SHRINK, BASELINE, "parameter value_um"]);
}

#[test]
fn every_scenario_has_a_test() {
    // The scenarios above, by name: a scenario added to the suite needs its test.
    let tested = [
        "reversal-spike-y",
        "reversal-spike-x",
        "lateral-play-xy",
        "cyclic-x",
        "thermal-drift-z",
        "thermal-drift-bar",
        "bar-length-one-radius",
        "bar-length-two-radii",
        "stick-slip-y",
        "servo-radius-loss",
        "positional-cubic-x",
        "straightness-cubic-yx",
        "angular-z-one-tool-length",
        "angular-z-two-tool-lengths",
        "spike-x-and-cyclic-y",
        "vibration-y",
        "vibration-z-quarters",
        "null-correlated-noise",
        "paper-column-axis-lags",
    ];
    let names: Vec<&str> = validation::scenarios().iter().map(|s| s.name).collect();
    assert_eq!(names, tested);
}

//! Withheld-effect scenarios at the library level (the validation suite is in `validation.rs`).

use ballbar_model::machine::{MachineSpec, ModelOptions, ServoVariant};
use ballbar_model::{Axis, BarLength, Effect, NoKernels};
use ballbar_sim::{simulate, Truth, TruthEffect};

use super::*;

#[path = "../../../plugins/column/src/spec.rs"]
mod column_spec;

fn truth(effects: Vec<TruthEffect>, repeats: u32) -> Truth {
    let mut t: Truth = ron::from_str(include_str!("../../../fixtures/column-paper/truth.ron")).unwrap();
    for test in &mut t.tests {
        test.repeats = repeats;
    }
    t.effects = effects;
    t.sample_rate_hz = 125.0;
    t
}

const PAPER: ModelOptions = ModelOptions { servo: ServoVariant::PlaneMismatch, bar_length: BarLength::Known(0.0) };

fn run(effects: Vec<TruthEffect>, seed: u64) -> Diagnosis {
    let spec: MachineSpec = column_spec::machine();
    let runs = simulate(&spec, &truth(effects, 2), 0.0, seed).unwrap().runs;
    let t = std::time::Instant::now();
    let d = diagnose(&spec, PAPER, &NoKernels, &runs, Options::default()).unwrap();
    eprintln!("diagnose {:?} ({} runs, {} samples)", t.elapsed(), runs.len(), d.base.n_samples);
    eprintln!("gap {:?} {:?}", d.gap.base_rms_um, d.gap.where_);
    for e in &d.effects {
        eprintln!("effect {} {:?} {:?} ho {:.3} → {:.3} F {:.1} t {:.1}", e.effect.kind(), e.effect.axis_label(), e.parameters, e.held_out_rms_before_um, e.held_out_rms_after_um, e.f_statistic, e.held_out_t);
    }
    for a in &d.aliased {
        eprintln!("aliased {} {:?} with {:?}", a.effect.kind(), a.effect.axis_label(), a.with);
    }
    d
}

#[test]
fn experiment_spike() {
    let d = run(vec![TruthEffect { effect: Effect::ReversalSpike { axis: Axis::Y, tau_ms: 60.0 }, value: 6.0, phase_deg: 0.0 }], 1);
    assert_eq!(d.effects[0].effect.kind(), "reversal_spike");
}

#[test]
fn experiment_null() {
    let d = run(vec![], 2);
    assert!(d.effects.is_empty());
}

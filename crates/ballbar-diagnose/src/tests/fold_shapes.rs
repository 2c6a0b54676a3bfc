//! A candidate's non-linear parameters chosen inside each fold on its training alone
//! ([`crate::selection::fold_variants`]): the held-out runs never choose the shape they are
//! scored with, and a shape the training cannot determine leaves the fold unable to judge it.

use std::f64::consts::TAU;

use ballbar_model::machine::Model;
use ballbar_model::path::CircleTest;
use ballbar_model::{Axis, Direction, Effect, Plane, Run};

use crate::selection::{Variants, fold_variants};

/// An XY circle of R 100 about (300, 200) at `feed`, 125 Hz.
fn circle(direction: Direction, feed_mm_per_min: f64, id: &str) -> Run {
    CircleTest {
        plane: Plane::XY,
        direction,
        radius_mm: 100.0,
        feed_mm_per_min,
        pivot_mm: [300.0, 200.0, -300.0],
        table_ball_mm: [0.0; 3],
        tool_ball_mm: [0.0; 3],
        sample_rate_hz: 125.0,
        start_deg: 0.0,
        sweep_deg: 360.0,
    }
    .run("2026-11-21T10:00:00Z", 0.0, id, "column")
}

/// Whole runs as units.
fn whole(runs: &[Run]) -> Vec<(usize, std::ops::Range<usize>, Option<usize>)> {
    runs.iter().enumerate().map(|(r, run)| (r, 0..run.len(), None)).collect()
}

/// Two runs, each with a line of its own in its residual: 1 µm at 20 Hz in the first, 2 µm at
/// 35 Hz in the second (and nothing else). On all data the largest peak of X is the second
/// run's 35 Hz; a fold that trains on the first run alone must take its own 20 Hz, and the
/// fold that trains on the second, 35 Hz. The grid step is at most half of 1/(run duration)
/// (37.7 s: 0.013 Hz) and the peak is refined between bins, so 0.05 Hz holds either with room;
/// the two lines are 15 Hz apart, far beyond any leakage of the other.
#[test]
fn a_vibrations_frequency_is_chosen_on_each_folds_training_runs_alone() {
    let model = Model::new(ballbar_model::machines::column(), Default::default()).unwrap();
    let runs = vec![circle(Direction::CW, 1000.0, "a"), circle(Direction::CCW, 1000.0, "b")];
    let lines = [(1e-3, 20.0), (2e-3, 35.0)];
    let residuals: Vec<Vec<f64>> = runs
        .iter()
        .zip(lines)
        .map(|(run, (a, f))| (0..run.len()).map(|i| a * (TAU * f * run.t_s[i]).sin()).collect())
        .collect();
    let all = crate::library::vibration_candidates(&model, &runs, &residuals);
    let top = all
        .iter()
        .find(|e| matches!(e, Effect::Vibration { axis: Axis::X, .. }))
        .expect("a vibration of X")
        .clone();
    let freq = |e: &Option<Effect>| match e {
        Some(Effect::Vibration { frequency_hz, .. }) => *frequency_hz,
        other => panic!("not a vibration: {other:?}"),
    };
    assert!((freq(&Some(top.clone())) - 35.0).abs() < 0.05, "{top:?}");
    let trainings = vec![vec![0], vec![1]];
    let out = fold_variants(
        std::slice::from_ref(&top),
        (&[], &[]),
        1e-8,
        &trainings,
        &whole(&runs),
        (&model, &runs, &residuals),
        2,
    );
    assert!((freq(&out[0][0]) - 20.0).abs() < 0.05, "trained on the first run: {:?}", out[0][0]);
    assert!((freq(&out[0][1]) - 35.0).abs() < 0.05, "trained on the second run: {:?}", out[0][1]);
}

/// A size's exponent of the feed cannot be chosen on a training of one feed (its columns at
/// every exponent are then one column scaled): the fold's shape is `None`. On a training of two
/// feeds it is chosen there, from the gains given for that training alone: the grid point
/// with the larger gain, here the exponent 1 (its neighbours 0 and 2 have no gain stated, so
/// no parabola refines it).
#[test]
fn a_feed_exponent_is_not_chosen_on_a_training_of_one_feed() {
    let model = Model::new(ballbar_model::machines::column(), Default::default()).unwrap();
    let runs = vec![
        circle(Direction::CW, 1000.0, "a"),
        circle(Direction::CW, 2000.0, "b"),
        circle(Direction::CCW, 1000.0, "c"),
    ];
    let residuals: Vec<Vec<f64>> = runs.iter().map(|r| vec![0.0; r.len()]).collect();
    let inner = Effect::StickSlip { axis: Axis::X, speed_mm_per_min: 80.0 };
    let scaled = |p: f64| Effect::FeedScaled {
        effect: Box::new(inner.clone()),
        exponent: p,
        reference_mm_per_min: 1000.0,
    };
    let usable = vec![inner.clone(), scaled(1.0)];
    // Training 0: runs a and c (one feed); training 1: runs a and b (two feeds). Gains per
    // training: the scaled one larger on both.
    let gains = vec![(0, vec![1.0, 1.0]), (1, vec![2.0, 2.0])];
    let trainings = vec![vec![0, 2], vec![0, 1]];
    let out = fold_variants(
        std::slice::from_ref(&scaled(1.0)),
        (&usable, &gains),
        1e-8,
        &trainings,
        &whole(&runs),
        (&model, &runs, &residuals),
        2,
    );
    assert_eq!(out[0][0], None, "one feed cannot choose the exponent");
    assert_eq!(out[0][1], Some(scaled(1.0)), "two feeds choose it");
    // The effect of one size is chosen on one feed too, among the grid points of one size
    // (the scaled one's larger gain does not count there).
    let out = fold_variants(
        std::slice::from_ref(&inner),
        (&usable, &gains),
        1e-8,
        &trainings,
        &whole(&runs),
        (&model, &runs, &residuals),
        2,
    );
    assert_eq!(out[0][0], Some(inner.clone()));
    assert_eq!(out[0][1], Some(scaled(1.0)), "on two feeds the larger gain: the scaled one");
}

/// The evaluator's columns of a set in a fold: each judged effect's all-data columns replaced
/// by its fold's, other columns kept, and a fold whose shape is not determined not able to
/// judge the effect.
#[test]
fn a_folds_columns_are_its_trainings_shapes() {
    // Judged effects 0 (columns 0, 1) and 1 (column 2); column 5 belongs to neither (a
    // fold's shape). One scheme of two folds.
    let columns = vec![vec![0, 1], vec![2]];
    let fold_cols =
        vec![vec![vec![Some(vec![5, 6]), Some(vec![0, 1])]], vec![vec![Some(vec![2]), None]]];
    let v = Variants::new(&columns, fold_cols);
    assert_eq!(v.in_fold(0, 0, &[0, 1, 2]), vec![5, 6, 2]);
    assert_eq!(v.in_fold(0, 1, &[2, 0, 1]), vec![2, 0, 1], "undetermined: the all-data shape");
    assert_eq!(v.in_fold(0, 0, &[7]), vec![7]);
    assert!(v.determined(0, 0, &[0, 1, 2]));
    assert!(!v.determined(0, 1, &[2]));
    assert!(v.determined(0, 1, &[0, 1]));
}

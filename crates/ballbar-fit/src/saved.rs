//! The saved model (`--save-model`, RON): the machine description, the model options and the
//! fitted machine parameters, enough for `predict` to replay the model without the plugin.

use ballbar_model::Unit;
use ballbar_model::machine::{MachineSpec, ModelOptions};
use serde::{Deserialize, Serialize};

/// Format tag of saved models.
pub const SAVED_MODEL_FORMAT: &str = "ballbar-model/1";

/// One fitted machine parameter, internal units (mm, rad, s).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedParameter {
    /// Identifier.
    pub id: String,
    /// Value in internal units (where not estimable, the gauge's or the minimum-norm value).
    pub value: f64,
    /// Dimension.
    pub unit: Unit,
    /// Standard uncertainty, internal units.
    pub std_uncertainty: f64,
    /// Whether the tests determined it.
    pub estimable: bool,
}

/// A saved model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedModel {
    /// [`SAVED_MODEL_FORMAT`].
    pub format: String,
    /// The machine.
    pub machine: MachineSpec,
    /// Model variant.
    pub options: ModelOptions,
    /// Machine parameters (no per-run nuisances).
    pub parameters: Vec<SavedParameter>,
    /// The plugin that provided the machine (needed again only for its kernel terms).
    #[serde(default)]
    pub plugin: Option<SavedPlugin>,
    /// Effects added to the machine's terms (a diagnosis's accepted effects), in column order.
    #[serde(default)]
    pub effects: Vec<ballbar_model::Effect>,
    /// The clock of the session the model was fitted on: the origin of its time-dependent
    /// terms. `None` in a model file written without it (it then reads as no origin known).
    #[serde(default)]
    pub session: Option<SavedSession>,
    /// Per axis (X, Y, Z, A, B, C), s: the switch lags of the fitted model, where its backlash
    /// and reversal transients switch after the commanded reversal
    /// (`Design::with_switch_lags`). `None` in a model file written without them: it reads as
    /// the commanded reversal ([`SavedModel::switch_lags`]).
    #[serde(default)]
    pub switch_lags_s: Option<[f64; 6]>,
}

/// The session a model was fitted on, as its runs' headers give it (`started_at`, or a `.b5r`
/// file's timestamps as the reader gives them): ISO 8601 UTC times, to the millisecond.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedSession {
    /// The session's start, the earliest run's `started_at`: the time origin of every
    /// time-dependent term (`Design::with_origin`).
    pub started_at: String,
    /// The session's end: the latest end of a run (its start plus its last sample's time).
    pub ended_at: String,
}

impl SavedSession {
    /// The session of these runs.
    pub fn of_runs(runs: &[ballbar_model::Run]) -> SavedSession {
        use ballbar_model::design::{session_end_unix_s, session_start_unix_s};
        SavedSession {
            started_at: ballbar_model::time::format_iso8601(session_start_unix_s(runs)),
            ended_at: ballbar_model::time::format_iso8601(session_end_unix_s(runs)),
        }
    }

    /// Start and end, Unix seconds; an error message naming the field that is not an ISO
    /// 8601 time.
    pub fn unix_s(&self) -> Result<(f64, f64), String> {
        let parse = |key: &str, v: &str| {
            ballbar_model::time::parse_iso8601(v).map_err(|m| format!("session.{key}: {m}"))
        };
        let (start, end) =
            (parse("started_at", &self.started_at)?, parse("ended_at", &self.ended_at)?);
        if end < start {
            return Err(format!(
                "session.ended_at {} is before session.started_at {}",
                self.ended_at, self.started_at
            ));
        }
        Ok((start, end))
    }
}

/// The plugin a model was fitted with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SavedPlugin {
    /// Plugin (machine type) name.
    pub name: String,
    /// Plugin version.
    pub version: String,
}

impl SavedModel {
    /// The machine part of a fit. Non-estimable parameters are saved with the values the fit's
    /// gauges (or the minimum norm) gave them: the prediction of any reading the tests
    /// constrain does not depend on them.
    pub fn from_fit(fit: &crate::Fit, machine: &MachineSpec, options: ModelOptions) -> SavedModel {
        SavedModel {
            format: SAVED_MODEL_FORMAT.into(),
            machine: machine.clone(),
            options,
            parameters: (0..fit.n_machine)
                .map(|i| SavedParameter {
                    id: fit.parameters[i].id.clone(),
                    value: fit.values[i],
                    unit: fit.parameters[i].unit,
                    std_uncertainty: fit.std_uncertainty[i],
                    estimable: fit.estimable[i],
                })
                .collect(),
            plugin: None,
            effects: Vec::new(),
            session: None,
            switch_lags_s: Some(fit.switch_lags_s),
        }
    }

    /// The switch lags a prediction uses, and a note when the file does not carry them (the
    /// commanded reversal is then taken).
    pub fn switch_lags(&self) -> ([f64; 6], Option<&'static str>) {
        match self.switch_lags_s {
            Some(l) => (l, None),
            None => (
                [0.0; 6],
                Some(
                    "the model does not say where its backlash switches (saved without its switch lags): it switches at the commanded reversal",
                ),
            ),
        }
    }

    /// True if any of the model's effects changes with the session's time (a thermal growth
    /// or drift): its prediction then depends on the time origin.
    pub fn is_time_dependent(&self) -> bool {
        self.effects.iter().any(ballbar_model::Effect::is_time_dependent)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> SavedModel {
        SavedModel {
            format: SAVED_MODEL_FORMAT.into(),
            machine: ballbar_model::machines::column(),
            options: ModelOptions::default(),
            parameters: vec![SavedParameter {
                id: "EXX1".into(),
                value: 1e-3,
                unit: Unit::Length,
                std_uncertainty: 1e-5,
                estimable: true,
            }],
            plugin: None,
            effects: vec![ballbar_model::Effect::ThermalGrowth {
                axis: ballbar_model::Axis::X,
                time_constant_min: Some(20.0),
            }],
            session: Some(SavedSession {
                started_at: "2026-11-21T10:00:00Z".into(),
                ended_at: "2026-11-21T10:41:30.250Z".into(),
            }),
            switch_lags_s: Some([0.002, 0.003, 0.0, 0.0, 0.0, 0.0]),
        }
    }

    #[test]
    fn a_model_carries_its_switch_lags_and_one_written_without_them_switches_at_the_command() {
        let m = model();
        let text = ron::ser::to_string_pretty(&m, ron::ser::PrettyConfig::default()).unwrap();
        let back: SavedModel = ron::from_str(&text).unwrap();
        assert_eq!(back.switch_lags(), ([0.002, 0.003, 0.0, 0.0, 0.0, 0.0], None));
        // A file written without them (an older version's): the commanded reversal, said.
        let mut old = m.clone();
        old.switch_lags_s = None;
        let text = ron::ser::to_string_pretty(&old, ron::ser::PrettyConfig::default()).unwrap();
        assert!(text.contains("switch_lags_s: None"), "{text}");
        let old_text: String = text
            .lines()
            .filter(|l| !l.trim_start().starts_with("switch_lags_s:"))
            .collect::<Vec<_>>()
            .join("\n");
        assert!(!old_text.contains("switch_lags"), "{old_text}");
        let read: SavedModel = ron::from_str(&old_text).unwrap();
        assert_eq!(read, old);
        let (lags, note) = read.switch_lags();
        assert_eq!(lags, [0.0; 6]);
        assert!(note.unwrap().contains("commanded reversal"));
    }

    #[test]
    fn a_model_carries_its_session_and_one_written_without_it_reads_as_no_origin() {
        let m = model();
        let text = ron::ser::to_string_pretty(&m, ron::ser::PrettyConfig::default()).unwrap();
        assert!(text.contains("started_at: \"2026-11-21T10:00:00Z\""), "{text}");
        let back: SavedModel = ron::from_str(&text).unwrap();
        assert_eq!(back, m);
        // 2026-11-21T10:00:00Z is 1 795 255 200 s after the epoch; the end 41 min 30.25 s later.
        let (start, end) = back.session.as_ref().unwrap().unix_s().unwrap();
        assert_eq!((start, end), (1_795_255_200.0, 1_795_255_200.0 + 2490.25));
        assert!(back.is_time_dependent());
        // A model file written without the session (an older version's): no origin known.
        let mut old = m.clone();
        old.session = None;
        let old_text = ron::ser::to_string_pretty(&old, ron::ser::PrettyConfig::default())
            .unwrap()
            .lines()
            .filter(|l| !l.trim_start().starts_with("session:"))
            .collect::<Vec<_>>()
            .join("\n");
        assert!(!old_text.contains("session"), "{old_text}");
        let read: SavedModel = ron::from_str(&old_text).unwrap();
        assert_eq!(read.session, None);
        assert_eq!(read, old);
    }

    #[test]
    fn a_session_of_runs_is_their_earliest_start_to_their_latest_end_and_bad_times_are_named() {
        let c = |deg: f64| ballbar_model::path::CircleTest {
            plane: ballbar_model::Plane::XY,
            direction: ballbar_model::Direction::CCW,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm: [0.0; 3],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: [0.0; 3],
            sample_rate_hz: 100.0,
            start_deg: deg,
            sweep_deg: 360.0,
        };
        // Two runs given later one first: 10:00:00 and 10:05:00, each of 2π·100 mm / (1000/60
        // mm/s) = 37.7 s.
        let a = c(0.0).run("2026-11-21T10:05:00Z", 1_795_255_500.0, "a", "test");
        let b = c(0.0).run("2026-11-21T10:00:00Z", 1_795_255_200.0, "b", "test");
        let s = SavedSession::of_runs(&[a.clone(), b]);
        assert_eq!(s.started_at, "2026-11-21T10:00:00Z");
        let end = 1_795_255_200.0 + 300.0 + a.t_s.last().unwrap();
        assert_eq!(s.ended_at, ballbar_model::time::format_iso8601(end));
        let (t0, t1) = s.unix_s().unwrap();
        // The end is written to the millisecond: 0.5 ms.
        assert!(t0 == 1_795_255_200.0 && (t1 - end).abs() <= 5e-4, "{t0} {t1} {end}");
        let bad = SavedSession { started_at: "today".into(), ended_at: s.ended_at.clone() };
        let e = bad.unix_s().unwrap_err();
        assert!(e.starts_with("session.started_at: \"today\" is not an ISO 8601 time"), "{e}");
        let reversed = SavedSession { started_at: s.ended_at.clone(), ended_at: s.started_at };
        assert!(reversed.unix_s().unwrap_err().contains("is before session.started_at"));
    }
}

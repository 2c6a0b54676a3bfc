//! A machine parameter over a machine's sessions: the one rule that flags a change between
//! consecutive sessions, used by `ballbar history` (its `*` and the CSV's `significant`) and by
//! the report's trend plots (the changes marked on them), so that both flag the same changes.
//!
//! # The rule
//! Between consecutive sessions `a` and `b` (in date order) where both determined the parameter,
//! the change `d = x_b - x_a` is flagged when `|d| > k u_c` with the combined standard
//! uncertainty `u_c = √(u_a² + u_b²)` (the two fits are independent) and `k` = [`HISTORY_K`].
//! A session that did not determine the parameter (or whose fit has no such parameter) breaks
//! the chain: no change is stated into it or out of it.

/// The sessions already taken into a history, by their runs' measurements
/// (`Run::sample_digest`), so that one session is counted once: a copied archive (or another
/// archive of the same runs, a refit) would otherwise count as a second session and bend the
/// trend, and its agreement with the first would pass for a machine that did not change.
#[derive(Debug, Default)]
pub struct Sessions {
    /// Each session taken: its name and its runs' digests, sorted.
    taken: Vec<(String, Vec<u64>)>,
}

/// What [`Sessions::take`] decided about a session.
#[derive(Debug, PartialEq, Eq)]
pub enum Taken {
    /// A session of its own: take it.
    New,
    /// A session of its own that shares some runs with one taken before: take it, and say so
    /// (its values and that session's are not independent).
    Shares(String),
    /// The same runs as a session taken before: leave it out, and say so.
    Same(String),
}

impl Sessions {
    /// Whether the session `name` with `runs` is a new one; a new one is remembered. The message
    /// of [`Taken::Shares`] and [`Taken::Same`] names both sessions.
    pub fn take(&mut self, name: &str, runs: &[&ballbar_model::Run]) -> Taken {
        let mut digests: Vec<u64> = runs.iter().map(|r| r.sample_digest()).collect();
        digests.sort_unstable();
        digests.dedup();
        if let Some((first, _)) = self.taken.iter().find(|(_, d)| *d == digests) {
            return Taken::Same(format!(
                "{name}: the same runs as {first} (the same {} measurements): one session, counted once ({first})",
                digests.len()
            ));
        }
        let shared = self.taken.iter().find_map(|(first, d)| {
            let n = digests.iter().filter(|x| d.binary_search(x).is_ok()).count();
            (n > 0).then(|| (first.clone(), n))
        });
        self.taken.push((name.to_string(), digests.clone()));
        match shared {
            Some((first, n)) => Taken::Shares(format!(
                "{name}: {n} of its {} runs are also in {first}: the two sessions' values are not independent, and a change between them is understated",
                digests.len()
            )),
            None => Taken::New,
        }
    }
}

/// A change between consecutive sessions is flagged when it exceeds this many combined
/// standard uncertainties (k = 2, about 95 % for normal errors).
pub const HISTORY_K: f64 = 2.0;

/// One session's estimate of a parameter, display units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// Value.
    pub value: f64,
    /// Standard uncertainty (k = 1).
    pub u: f64,
    /// Whether the session's fit determined it.
    pub estimable: bool,
}

/// The change into a session from the one before it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Change {
    /// Value now minus value before, display units.
    pub change: f64,
    /// Combined standard uncertainty of the change, `√(u_a² + u_b²)`.
    pub combined_u: f64,
    /// Beyond [`HISTORY_K`] combined standard uncertainties.
    pub flagged: bool,
}

/// The change into each session of `series` (sessions in date order; `None`: the session's fit
/// has no such parameter): `None` for the first session and wherever either side did not
/// determine the parameter.
pub fn changes(series: &[Option<Estimate>]) -> Vec<Option<Change>> {
    let mut out = Vec::with_capacity(series.len());
    let mut prev: Option<Estimate> = None;
    for now in series {
        out.push(match (prev, now) {
            (Some(a), Some(b)) if a.estimable && b.estimable => {
                let change = b.value - a.value;
                let combined_u = a.u.hypot(b.u);
                Some(Change { change, combined_u, flagged: change.abs() > HISTORY_K * combined_u })
            }
            _ => None,
        });
        prev = *now;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::{Direction, Plane, Run, RunHeader};

    /// A run of three samples whose readings are `r` µm, under the name `id`.
    fn run(id: &str, r: [f64; 3]) -> Run {
        Run {
            header: RunHeader {
                format_version: 1,
                machine: None,
                plane: Plane::XY,
                direction: Some(Direction::CCW),
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: [0.0; 3],
                table_ball_mm: [0.0; 3],
                tool_ball_mm: [0.0; 3],
                defaulted: Default::default(),
                started_at: "2026-11-21T10:00:00Z".into(),
                started_at_unix_s: 0.0,
                run_id: Some(id.into()),
                extra: Vec::new(),
            },
            source: format!("{id}.csv"),
            t_s: vec![0.0, 0.1, 0.2],
            axes: Default::default(),
            dr_mm: r.iter().map(|x| x * 1e-3).collect(),
            lines: vec![13, 14, 15],
        }
    }

    #[test]
    fn a_session_of_the_same_runs_is_left_out_and_one_sharing_some_is_named() {
        let (a, b, c) = (run("a", [1.0, 2.0, 3.0]), run("b", [4.0, 5.0, 6.0]), run("c", [7.0; 3]));
        let mut s = Sessions::default();
        assert_eq!(s.take("1.mcap", &[&a, &b]), Taken::New);
        // The same runs in another order and under other names: the same session.
        let (a2, b2) = (run("a2", [1.0, 2.0, 3.0]), run("b2", [4.0, 5.0, 6.0]));
        let Taken::Same(why) = s.take("2.mcap", &[&b2, &a2]) else { panic!() };
        assert!(why.starts_with("2.mcap: the same runs as 1.mcap (the same 2 measurements)"));
        // One run shared: a session of its own, said to depend on the other.
        let Taken::Shares(why) = s.take("3.mcap", &[&a, &c]) else { panic!() };
        assert!(why.starts_with("3.mcap: 1 of its 2 runs are also in 1.mcap"), "{why}");
        // A reading that differs by 1e-3 µm is another measurement.
        assert_eq!(s.take("4.mcap", &[&run("d", [1.0, 2.0, 3.001])]), Taken::New);
    }
}

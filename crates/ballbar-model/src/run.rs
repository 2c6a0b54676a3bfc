//! A ballbar run in memory: one circle (or arc, or free path) in one plane, one direction, one
//! feed. Values are in the crate's internal units (mm, rad, s); the run-CSV edge converts.

use crate::axis::{Axis, Direction, Plane};

/// The header of a run: the test set-up.
#[derive(Clone, Debug, PartialEq)]
pub struct RunHeader {
    /// Format version from `# ballbar-run:`.
    pub format_version: u32,
    /// Informative machine type name.
    pub machine: Option<String>,
    /// Test plane.
    pub plane: Plane,
    /// Contouring direction; `None` only for free (five-axis) paths.
    pub direction: Option<Direction>,
    /// Nominal bar length R, mm.
    pub radius_mm: f64,
    /// Programmed feed, mm/min.
    pub feed_mm_per_min: f64,
    /// Axis coordinates (X, Y, Z) at which the tool ball would sit on the table ball, mm.
    pub pivot_mm: [f64; 3],
    /// Table-ball centre in the table frame from the table reference point, mm.
    pub table_ball_mm: [f64; 3],
    /// Tool-ball centre from the spindle gauge point in the spindle frame, mm (z = -tool length).
    pub tool_ball_mm: [f64; 3],
    /// Which of the two ball positions the run did not give and were taken at their default,
    /// 0, 0, 0 (a run CSV without the key, a `.b5r` file): told apart from a value given as
    /// 0, 0, 0 so that the output can say what was assumed ([`defaulted_geometry`]).
    pub defaulted: DefaultedKeys,
    /// `started_at` as written (ISO 8601).
    pub started_at: String,
    /// `started_at` as seconds since 1970-01-01T00:00:00Z.
    pub started_at_unix_s: f64,
    /// Free-text run identifier.
    pub run_id: Option<String>,
    /// Header keys this version does not know, kept in order.
    pub extra: Vec<(String, String)>,
}

/// The optional geometry keys of a run header that were not given (their value is the
/// format's default, 0, 0, 0). `Default` is "both given".
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DefaultedKeys {
    /// `table_ball_mm` was not given.
    pub table_ball_mm: bool,
    /// `tool_ball_mm` was not given.
    pub tool_ball_mm: bool,
}

impl DefaultedKeys {
    /// Both keys not given (a `.b5r` file gives neither ball position).
    pub const BOTH: DefaultedKeys = DefaultedKeys { table_ball_mm: true, tool_ball_mm: true };

    /// The names of the keys not given, in header order.
    pub fn keys(self) -> Vec<&'static str> {
        [("table_ball_mm", self.table_ball_mm), ("tool_ball_mm", self.tool_ball_mm)]
            .into_iter()
            .filter(|k| k.1)
            .map(|k| k.0)
            .collect()
    }

    /// From key names (as [`DefaultedKeys::keys`] gives them); `Err` names one it does not know.
    pub fn from_keys<'a>(keys: impl IntoIterator<Item = &'a str>) -> Result<DefaultedKeys, String> {
        let mut d = DefaultedKeys::default();
        for k in keys {
            match k {
                "table_ball_mm" => d.table_ball_mm = true,
                "tool_ball_mm" => d.tool_ball_mm = true,
                other => return Err(format!("{other:?} is not a header key with a default")),
            }
        }
        Ok(d)
    }
}

/// A default taken for runs that changes a result: which key, in which runs, at what value.
///
/// Only `tool_ball_mm` is ever one. The tool ball's offset from the spindle gauge point is the
/// Abbe arm of the angular errors: with another tool length the same readings give other
/// positional and squareness values (on the column fixture, X positional 8.47 µm with the
/// stated 100 mm tool, 12.06 µm with 0), and in a free run it also places the table ball
/// (`pivot_mm` is where the tool ball sits on it). `table_ball_mm` changes nothing: the
/// model places the table ball where the tool ball meets it at `pivot_mm` (the key is
/// informative, and checked against that place in a free run), so its absence is not stated.
#[derive(Clone, Debug, PartialEq)]
pub struct DefaultedGeometry {
    /// The header key (`tool_ball_mm`).
    pub key: &'static str,
    /// The value taken, mm.
    pub value_mm: [f64; 3],
    /// The names of the runs that did not give it ([`Run::name`]).
    pub runs: Vec<String>,
    /// How many runs there are in all.
    pub of: usize,
    /// Some of those runs are free (rotary) runs, whose table ball it places.
    pub free: bool,
    /// Some of those runs come from `.b5r` files, which cannot give it.
    pub vendor: bool,
}

/// The defaults taken for `runs` that change a result (see [`DefaultedGeometry`]): empty when
/// every run gives its tool ball.
pub fn defaulted_geometry<'a>(runs: impl IntoIterator<Item = &'a Run>) -> Vec<DefaultedGeometry> {
    let runs: Vec<&Run> = runs.into_iter().collect();
    let without: Vec<&Run> =
        runs.iter().copied().filter(|r| r.header.defaulted.tool_ball_mm).collect();
    if without.is_empty() {
        return Vec::new();
    }
    vec![DefaultedGeometry {
        key: "tool_ball_mm",
        value_mm: without[0].header.tool_ball_mm,
        runs: without.iter().map(|r| r.name()).collect(),
        of: runs.len(),
        free: without.iter().any(|r| r.header.plane == crate::Plane::Free),
        vendor: without.iter().any(|r| r.source.to_ascii_lowercase().ends_with(".b5r")),
    }]
}

impl RunHeader {
    /// Feed in mm/s (the internal unit).
    pub fn feed_mm_per_s(&self) -> f64 {
        self.feed_mm_per_min / 60.0
    }
}

/// One run: header and samples, column-wise.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// Test set-up.
    pub header: RunHeader,
    /// Where the run came from (a file path), for messages.
    pub source: String,
    /// Seconds since `started_at`, strictly increasing.
    pub t_s: Vec<f64>,
    /// Commanded axis coordinates, one column per axis present (mm for linear axes, rad for
    /// rotary axes); `None` for an axis the run does not have.
    pub axes: [Option<Vec<f64>>; 6],
    /// Measured bar length minus nominal R, in mm (the file holds µm).
    pub dr_mm: Vec<f64>,
    /// The 1-based line number in `source` of each sample, for messages.
    pub lines: Vec<u32>,
}

impl Run {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    /// True when the run has no samples.
    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }

    /// The column of an axis, if present.
    pub fn axis(&self, axis: Axis) -> Option<&[f64]> {
        self.axes[axis.index()].as_deref()
    }

    /// The mean sampling rate, Hz: (samples - 1)/duration; `None` below two samples or without
    /// a positive duration.
    pub fn sample_rate_hz(&self) -> Option<f64> {
        let n = self.len();
        (n >= 2)
            .then(|| (n - 1) as f64 / (self.t_s[n - 1] - self.t_s[0]))
            .filter(|r| r.is_finite() && *r > 0.0)
    }

    /// The measurement itself, as a key: the times and readings, quantised to 1 µs and
    /// 1e-4 µm ([`Run::sample_key`]), hashed (FNV-1a, 64 bits). Equal for the same samples
    /// under another header (another name, run id, start or pivot) and for one measurement
    /// read from two formats (a `.b5r` file and the run CSV imported from it: the reading's mm
    /// and its µm in the CSV agree at that resolution); the axis coordinates are left out, since
    /// a `.b5r` run's depend on `--pivot`. Real readings agree with another run's at every
    /// sample to 1e-4 µm only when they are the same readings; two digests that agree are
    /// confirmed with [`Run::same_samples`].
    pub fn sample_digest(&self) -> u64 {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: i64| {
            for b in x.to_le_bytes() {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        eat(self.len() as i64);
        for i in 0..self.len() {
            let (t, r) = self.sample_key(i);
            eat(t);
            eat(r);
        }
        h
    }

    /// Sample `i`'s time in µs and reading in 1e-4 µm, rounded: finer than any ballbar
    /// resolves (0.1 µm, a sample every 1 ms or more), coarser than the round-off between a
    /// reading in mm and the same reading written in µm.
    pub fn sample_key(&self, i: usize) -> (i64, i64) {
        ((self.t_s[i] * 1e6).round() as i64, (self.dr_mm[i] * 1e7).round() as i64)
    }

    /// Whether two runs hold the same samples: the same number, each time and reading equal at
    /// the resolution of [`Run::sample_key`].
    pub fn same_samples(&self, other: &Run) -> bool {
        self.len() == other.len()
            && (0..self.len()).all(|i| self.sample_key(i) == other.sample_key(i))
    }

    /// A short name for messages and tables: the run id, else the file name.
    pub fn name(&self) -> String {
        if let Some(id) = &self.header.run_id {
            return id.clone();
        }
        std::path::Path::new(&self.source)
            .file_name()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| self.source.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::axis::{Direction, Plane};

    /// A run without samples, with the tool ball `tool` (`None`: left out).
    fn run(name: &str, plane: Plane, tool: Option<[f64; 3]>) -> Run {
        Run {
            header: RunHeader {
                format_version: 1,
                machine: None,
                plane,
                direction: Some(Direction::CCW),
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: [0.0; 3],
                table_ball_mm: [0.0; 3],
                tool_ball_mm: tool.unwrap_or([0.0; 3]),
                // The table ball is never stated: it changes no result.
                defaulted: DefaultedKeys { table_ball_mm: true, tool_ball_mm: tool.is_none() },
                started_at: "2026-11-21T10:00:00Z".into(),
                started_at_unix_s: 0.0,
                run_id: Some(name.into()),
                extra: Vec::new(),
            },
            source: format!("{name}.csv"),
            t_s: Vec::new(),
            axes: Default::default(),
            dr_mm: Vec::new(),
            lines: Vec::new(),
        }
    }

    #[test]
    fn a_tool_ball_not_given_is_found_naming_the_runs_and_one_given_as_zero_is_not() {
        let given =
            [run("a", Plane::XY, Some([0.0, 0.0, -100.0])), run("b", Plane::XY, Some([0.0; 3]))];
        assert_eq!(defaulted_geometry(&given), Vec::new());
        let all: Vec<Run> = (0..6).map(|k| run(&format!("r{k}"), Plane::XY, None)).collect();
        let d = defaulted_geometry(&all);
        assert_eq!(d.len(), 1);
        assert_eq!(
            (d[0].key, d[0].runs.len(), d[0].of, d[0].free, d[0].vendor),
            ("tool_ball_mm", 6, 6, false, false)
        );
        let mixed = [
            run("a", Plane::XY, Some([0.0, 0.0, -100.0])),
            run("b", Plane::YZ, None),
            run("c", Plane::Free, None),
        ];
        let d = &defaulted_geometry(&mixed)[0];
        assert_eq!(d.runs, ["b", "c"]);
        assert!(d.free);
    }

    #[test]
    fn defaulted_keys_read_back_from_their_names() {
        for d in [
            DefaultedKeys::default(),
            DefaultedKeys::BOTH,
            DefaultedKeys { table_ball_mm: false, tool_ball_mm: true },
        ] {
            assert_eq!(DefaultedKeys::from_keys(d.keys()), Ok(d));
        }
        assert!(DefaultedKeys::from_keys(["pivot_mm"]).is_err());
    }
}

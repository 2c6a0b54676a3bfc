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
    /// `started_at` as written (ISO 8601).
    pub started_at: String,
    /// `started_at` as seconds since 1970-01-01T00:00:00Z.
    pub started_at_unix_s: f64,
    /// Free-text run identifier.
    pub run_id: Option<String>,
    /// Header keys this version does not know, kept in order.
    pub extra: Vec<(String, String)>,
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
        (n >= 2).then(|| (n - 1) as f64 / (self.t_s[n - 1] - self.t_s[0])).filter(|r| r.is_finite() && *r > 0.0)
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

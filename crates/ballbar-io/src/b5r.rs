//! Renishaw ballbar files (`.b5r`, `shared/spec/vendor-b5r.md`): each `BALLBAR_RUN` becomes a
//! [`Run`], and the vendor's own analysis (its features, its fitted model's readings) is kept
//! beside the runs for comparison.
//!
//! What the file gives and what it does not:
//! - `READINGS` is the bar length minus the calibrated length, mm, with the lead-in and
//!   lead-out over-shoot; the analysed arc is `READINGS[START_INDEX ..= END_INDEX]`, and only
//!   that window becomes the run. (On the shared real file the over-shoot readings sit up to
//!   1.6 µm off the arc's circle, drifting: the machine starting and stopping, not the arc.)
//! - Angles: in the plane's (A, B) frame from +A towards +B, CCW increasing from START_ANGLE,
//!   CW decreasing from END_ANGLE (the CW run of a partial arc starts at END_ANGLE);
//!   `arc = (END - START) mod 360`, 360 when that is 0. The spacing is the machine's: by the
//!   programmed feed, centred on the window, where the window agrees with it (the vendor's own
//!   even spread over the window otherwise; [`sample_spacing`] says why, and both depart from
//!   `vendor-b5r.md`'s `i·arc/(n-1)`). Either reproduces the file's `AF_CENTRE_OFFSET_A/B`,
//!   `AF_BEST_RADIUS` to 0.1 µm and its circularity to 0.1 µm on the shared real file (test
//!   `real_file_reproduces_the_vendor_circle`). Partial arcs are read the same way, unverified
//!   on a real partial-arc file.
//! - Samples are equally spaced at the run's `SAMPLE_RATE`: `t_i = i / rate`.
//! - The circle centre in machine coordinates is not in the file: it comes from
//!   [`B5rOptions::pivot_mm`], and the run's header says which (`pivot_source`).
//! - The vendor's axis names map to ours: a plane whose (A, B) is our (V, U) (say `ZX` with
//!   A = X, B = Z) has its angle, and so its direction, reversed against ours.
//!
//! Every problem is an [`IoError::Format`] naming the file, the line of the element and what
//! is wrong; nothing is skipped silently.

use std::path::Path;

use ballbar_model::{Axis, Direction, Plane, Run, RunHeader};

use crate::IoError;
use crate::csv::quoted;

/// Where the circle centre comes from when the file does not give it.
pub const DEFAULT_PIVOT_MM: [f64; 3] = [0.0, 0.0, 0.0];

/// Most attributes an element of a `.b5r` file may have. The vendor's elements have at most
/// three; the XML parser compares each attribute with the element's others (to refuse one given
/// twice), so their number is bounded before it runs: 100,000 attributes took it 45 s.
pub const MAX_ATTRIBUTES: usize = 64;

/// Most runs (`BALLBAR_RUN` elements) a `.b5r` file may hold: a test is one CW and one CCW
/// run, a few more with repeats.
pub const MAX_RUNS: usize = 100;

/// Options of the import that the file cannot answer.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct B5rOptions {
    /// The circle centre in machine coordinates (X, Y, Z), mm; `None`: [`DEFAULT_PIVOT_MM`].
    pub pivot_mm: Option<[f64; 3]>,
    /// The tool-ball centre from the spindle gauge point in the spindle frame (z = minus the
    /// tool length), mm; `None`: not given (the runs' `tool_ball_mm` is then 0, 0, 0 and
    /// stated as left out).
    pub tool_ball_mm: Option<[f64; 3]>,
    /// How the samples are placed on the arc.
    pub angles: AngleSpacing,
}

/// How a run's samples are placed on its arc ([`sample_spacing`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AngleSpacing {
    /// As the machine moved: by the programmed feed, centred on the analysed arc, where the
    /// arc's sample count agrees with it to [`FEED_AGREEMENT`] (evenly over the arc otherwise).
    #[default]
    Machine,
    /// The vendor's convention: the analysed arc's samples spread evenly over it.
    Vendor,
}

/// A unit code of the vendor (`DT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VendorUnit {
    /// `UT_LENGTH_MM`.
    Mm,
    /// `UT_LENGTH_UM`.
    Um,
    /// `UT_LENGTH_M`.
    M,
    /// `UT_FEEDRATE`, mm/min.
    MmPerMin,
    /// `UT_SPEED`, mm/s.
    MmPerS,
    /// `UT_SCALE_ERROR`, ppm.
    Ppm,
    /// `UT_SQUARENESS`, µm/m.
    UmPerM,
    /// `UT_SERVO_MISMATCH`, ms.
    Ms,
    /// `UT_ANGLE`, degrees.
    Degrees,
    /// `UT_PERCENT`.
    Percent,
    /// `UT_RANKING`.
    Rank,
}

impl VendorUnit {
    /// The unit of a `DT` code.
    pub fn from_code(code: &str) -> Option<VendorUnit> {
        Some(match code {
            "UT_LENGTH_MM" => VendorUnit::Mm,
            "UT_LENGTH_UM" => VendorUnit::Um,
            "UT_LENGTH_M" => VendorUnit::M,
            "UT_FEEDRATE" => VendorUnit::MmPerMin,
            "UT_SPEED" => VendorUnit::MmPerS,
            "UT_SCALE_ERROR" => VendorUnit::Ppm,
            "UT_SQUARENESS" => VendorUnit::UmPerM,
            "UT_SERVO_MISMATCH" => VendorUnit::Ms,
            "UT_ANGLE" => VendorUnit::Degrees,
            "UT_PERCENT" => VendorUnit::Percent,
            "UT_RANKING" => VendorUnit::Rank,
            _ => return None,
        })
    }

    /// The unit's symbol for tables.
    pub fn symbol(self) -> &'static str {
        match self {
            VendorUnit::Mm => "mm",
            VendorUnit::Um => "µm",
            VendorUnit::M => "m",
            VendorUnit::MmPerMin => "mm/min",
            VendorUnit::MmPerS => "mm/s",
            VendorUnit::Ppm => "ppm",
            VendorUnit::UmPerM => "µm/m",
            VendorUnit::Ms => "ms",
            VendorUnit::Degrees => "°",
            VendorUnit::Percent => "%",
            VendorUnit::Rank => "rank",
        }
    }

    /// The factor from this unit to µm, for lengths.
    pub fn to_um(self) -> Option<f64> {
        match self {
            VendorUnit::Mm => Some(1e3),
            VendorUnit::Um => Some(1.0),
            VendorUnit::M => Some(1e6),
            _ => None,
        }
    }
}

/// One `FEATURE` of the vendor: a named value in the unit of its `DT`.
#[derive(Clone, Debug, PartialEq)]
pub struct VendorFeature {
    /// The vendor's name (`AF_SQUARENESS`).
    pub name: String,
    /// The value, in `unit`.
    pub value: f64,
    /// The unit (`DT`).
    pub unit: VendorUnit,
    /// False where the vendor marks the value `VALID="False"` (it does not trust it).
    pub valid: bool,
    /// The 1-based line of the element in the file.
    pub line: usize,
}

impl VendorFeature {
    /// The value in µm, for a length.
    pub fn um(&self) -> Option<f64> {
        self.unit.to_um().map(|f| self.value * f)
    }
}

/// One `ANALYSIS` element: the vendor's results under one standard or method.
#[derive(Clone, Debug, PartialEq)]
pub struct VendorAnalysis {
    /// `RENISHAW_DIAGNOSTICS`, `ISO230_4`, `ANSI_B_5_54`, ...
    pub name: String,
    /// The `version` attribute, where given.
    pub version: Option<String>,
    /// The features, in file order.
    pub features: Vec<VendorFeature>,
    /// The vendor's fitted model's readings (`SIMULATION`), by name, mm.
    pub simulations: Vec<(String, Vec<f64>)>,
}

impl VendorAnalysis {
    /// The feature named `name`, if present.
    pub fn feature(&self, name: &str) -> Option<&VendorFeature> {
        self.features.iter().find(|f| f.name == name)
    }
}

/// What one `.b5r` file holds: its runs (the analysed windows) and the vendor's analysis.
#[derive(Clone, Debug, PartialEq)]
pub struct B5rTest {
    /// The file, as given.
    pub source: String,
    /// The test plane, in the project's names.
    pub plane: Plane,
    /// The vendor's A and B axes.
    pub axis_a: Axis,
    /// See `axis_a`.
    pub axis_b: Axis,
    /// One run per `BALLBAR_RUN`, in file order: the analysed arc.
    pub runs: Vec<Run>,
    /// The vendor's own angle of each sample of each run, degrees in the plane's (A, B) frame:
    /// its window spread evenly, sample i at the middle of its 1/n of the arc. It reproduces the
    /// vendor's features (the circle, its ISO 230-4 locations); the runs' coordinates follow
    /// the machine's motion ([`sample_spacing`]).
    pub vendor_angles_deg: Vec<Vec<f64>>,
    /// Every reading of each run, mm, the lead-in and lead-out over-shoot included, and the
    /// analysed arc's first index in them (`START_INDEX`): the over-shoot holds reversals that
    /// time the machine's motion ([`feed_factor`]).
    pub readings_mm: Vec<(Vec<f64>, usize)>,
    /// The per-run features (`RUN_RESULTS/BALLBAR_RUN/FEATURE`), one list per run.
    pub run_features: Vec<Vec<VendorFeature>>,
    /// The `ANALYSIS` elements, in file order.
    pub analyses: Vec<VendorAnalysis>,
}

impl B5rTest {
    /// The first analysis named `name` (with `version`, if given).
    pub fn analysis(&self, name: &str, version: Option<&str>) -> Option<&VendorAnalysis> {
        self.analyses
            .iter()
            .find(|a| a.name == name && (version.is_none() || a.version.as_deref() == version))
    }

    /// The vendor's diagnostics (`RENISHAW_DIAGNOSTICS`), if the file has them.
    pub fn diagnostics(&self) -> Option<&VendorAnalysis> {
        self.analysis("RENISHAW_DIAGNOSTICS", None)
    }
}

/// True when `path` names a `.b5r` file (by its extension, any case).
pub fn is_b5r(path: &Path) -> bool {
    path.extension().is_some_and(|x| x.eq_ignore_ascii_case("b5r"))
}

/// Read a `.b5r` file.
pub fn read_b5r(path: &Path, options: &B5rOptions) -> Result<B5rTest, IoError> {
    let bytes =
        std::fs::read(path).map_err(|error| IoError::Io { path: path.to_path_buf(), error })?;
    let text = std::str::from_utf8(&bytes).map_err(|e| {
        let line = 1 + bytes[..e.valid_up_to()].iter().filter(|&&b| b == b'\n').count();
        IoError::Format {
            path: path.to_path_buf(),
            line,
            message: "the text is not UTF-8 (a .b5r file is UTF-8 XML)".into(),
        }
    })?;
    parse_b5r(text, &path.to_string_lossy(), options)
}

/// The XML document with the file's name, for errors at elements.
struct Doc<'a> {
    source: &'a str,
    /// The byte offset of each line end (`\n`) of the text, in order: an element's line is
    /// found by a binary search (roxmltree's `text_pos_at` counts from the start of the text,
    /// which for a line per element made reading quadratic in the file's size).
    line_ends: Vec<usize>,
}

type Node<'a, 'input> = roxmltree::Node<'a, 'input>;

impl<'a, 'input> Doc<'a> {
    fn line(&self, node: Node) -> usize {
        1 + self.line_ends.partition_point(|&end| end < node.range().start)
    }

    fn error(&self, node: Node, message: impl Into<String>) -> IoError {
        IoError::Format { path: self.source.into(), line: self.line(node), message: message.into() }
    }

    /// The element's path from the root, for messages: `RUN_RESULTS/BALLBAR_RUN[2]/READINGS`.
    fn path(&self, node: Node) -> String {
        let mut parts = Vec::new();
        let mut at = Some(node);
        while let Some(n) = at.filter(|n| n.is_element() && n.parent_element().is_some()) {
            let name = n.tag_name().name();
            let same: Vec<Node> = n
                .parent_element()
                .map(|p| p.children().filter(|c| c.has_tag_name(name)).collect())
                .unwrap_or_default();
            if same.len() > 1 {
                let k = same.iter().position(|c| *c == n).unwrap_or(0) + 1;
                parts.push(format!("{name}[{k}]"));
            } else {
                parts.push(name.to_string());
            }
            at = n.parent_element();
        }
        parts.reverse();
        parts.join("/")
    }

    /// The child element `name`, required.
    fn child(&self, parent: Node<'a, 'input>, name: &str) -> Result<Node<'a, 'input>, IoError> {
        parent.children().find(|c| c.has_tag_name(name)).ok_or_else(|| {
            self.error(parent, format!("element {} has no {name} element", self.path(parent)))
        })
    }

    /// The trimmed text of an element (empty when it has none).
    fn text(&self, node: Node<'a, 'input>) -> &'a str {
        node.text().unwrap_or("").trim()
    }

    /// The child's text as a finite number.
    fn number(&self, parent: Node<'a, 'input>, name: &str) -> Result<f64, IoError> {
        let node = self.child(parent, name)?;
        self.parse_number(node, self.text(node))
    }

    fn parse_number(&self, node: Node, text: &str) -> Result<f64, IoError> {
        match text.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            _ if text.is_empty() => Err(self.error(
                node,
                format!("element {} is empty; a number was expected", self.path(node)),
            )),
            _ => Err(self.error(
                node,
                format!("element {}: {} is not a finite number", self.path(node), quoted(text)),
            )),
        }
    }

    /// The child's text as a non-negative integer.
    fn index(&self, parent: Node<'a, 'input>, name: &str) -> Result<usize, IoError> {
        let node = self.child(parent, name)?;
        let text = self.text(node);
        text.parse::<usize>().map_err(|_| {
            self.error(
                node,
                format!(
                    "element {}: {} is not a non-negative whole number",
                    self.path(node),
                    quoted(text)
                ),
            )
        })
    }

    /// A whitespace-separated list of finite numbers.
    fn numbers(&self, node: Node<'a, 'input>) -> Result<Vec<f64>, IoError> {
        let text = self.text(node);
        let mut out = Vec::with_capacity(text.len() / 9 + 1);
        for (k, word) in text.split_ascii_whitespace().enumerate() {
            match word.parse::<f64>() {
                Ok(v) if v.is_finite() => out.push(v),
                _ => {
                    return Err(self.error(
                        node,
                        format!(
                            "element {}: value {} ({}) is not a finite number",
                            self.path(node),
                            k + 1,
                            quoted(word)
                        ),
                    ));
                }
            }
        }
        Ok(out)
    }

    /// A `FEATURE` element.
    fn feature(&self, node: Node<'a, 'input>) -> Result<VendorFeature, IoError> {
        let name = node.attribute("NAME").ok_or_else(|| {
            self.error(node, format!("element {} has no NAME attribute", self.path(node)))
        })?;
        let code = node.attribute("DT").ok_or_else(|| {
            self.error(
                node,
                format!("feature {name} ({}) has no DT attribute (its unit)", self.path(node)),
            )
        })?;
        let unit = VendorUnit::from_code(code).ok_or_else(|| {
            self.error(
                node,
                format!("feature {name} ({}): unknown unit DT={}", self.path(node), quoted(code)),
            )
        })?;
        let text = self.text(node);
        let value = self.parse_number(node, text).map_err(|_| {
            self.error(
                node,
                format!(
                    "feature {name} ({}): {} is not a finite number",
                    self.path(node),
                    quoted(text)
                ),
            )
        })?;
        let valid = !node.attribute("VALID").is_some_and(|v| v.eq_ignore_ascii_case("false"));
        Ok(VendorFeature { name: name.to_string(), value, unit, valid, line: self.line(node) })
    }

    fn features(&self, parent: Node<'a, 'input>) -> Result<Vec<VendorFeature>, IoError> {
        parent.children().filter(|c| c.has_tag_name("FEATURE")).map(|c| self.feature(c)).collect()
    }
}

/// `YYYYMMDD-HHMMSS` as `YYYY-MM-DDTHH:MM:SS` (no zone: the file has none).
fn vendor_date(text: &str) -> Option<String> {
    let b = text.as_bytes();
    let digits = |r: std::ops::Range<usize>| {
        b.get(r.clone()).is_some_and(|s| s.iter().all(u8::is_ascii_digit))
    };
    (b.len() == 15 && b[8] == b'-' && digits(0..8) && digits(9..15)).then(|| {
        format!(
            "{}-{}-{}T{}:{}:{}",
            &text[0..4],
            &text[4..6],
            &text[6..8],
            &text[9..11],
            &text[11..13],
            &text[13..15]
        )
    })
}

/// The first element (start tag) of `text` with more than [`MAX_ATTRIBUTES`] attributes, as
/// the byte offset of its `<`. One pass: comments, CDATA sections, processing instructions,
/// declarations and end tags are skipped, quoted attribute values too (they may hold `=` and
/// `>`); in a start tag each `=` outside quotes is an attribute. Text that is not well-formed
/// gives some answer or none; the XML parser then says what is wrong with it.
fn crowded_element(text: &str) -> Option<usize> {
    let b = text.as_bytes();
    let find = |from: usize, pattern: &[u8]| {
        b.get(from..)?.windows(pattern.len()).position(|w| w == pattern).map(|p| from + p)
    };
    let mut at = 0;
    while let Some(start) = find(at, b"<") {
        let rest = &b[start..];
        let skip_past = |pattern: &[u8]| find(start, pattern).map(|p| p + pattern.len());
        let next = if rest.starts_with(b"<!--") {
            skip_past(b"-->")
        } else if rest.starts_with(b"<![CDATA[") {
            skip_past(b"]]>")
        } else if rest.starts_with(b"<?") {
            skip_past(b"?>")
        } else if rest.starts_with(b"<!") || rest.starts_with(b"</") {
            skip_past(b">")
        } else {
            let mut attributes = 0;
            let mut quote = None;
            let mut end = None;
            for (k, &c) in rest.iter().enumerate().skip(1) {
                match (quote, c) {
                    (Some(q), c) if c == q => quote = None,
                    (Some(_), _) => {}
                    (None, b'"' | b'\'') => quote = Some(c),
                    (None, b'=') => {
                        attributes += 1;
                        if attributes > MAX_ATTRIBUTES {
                            return Some(start);
                        }
                    }
                    (None, b'>') => {
                        end = Some(start + k + 1);
                        break;
                    }
                    (None, _) => {}
                }
            }
            end
        };
        at = next?;
    }
    None
}

/// Parse `.b5r` text. `source` names the file in messages and becomes each run's source.
pub fn parse_b5r(text: &str, source: &str, options: &B5rOptions) -> Result<B5rTest, IoError> {
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let line_ends: Vec<usize> =
        text.bytes().enumerate().filter(|&(_, c)| c == b'\n').map(|(i, _)| i).collect();
    if let Some(at) = crowded_element(text) {
        return Err(IoError::Format {
            path: source.into(),
            line: 1 + line_ends.partition_point(|&end| end < at),
            message: format!(
                "an element with more than {MAX_ATTRIBUTES} attributes: not a Renishaw ballbar file (its elements have a few)"
            ),
        });
    }
    let doc = roxmltree::Document::parse(text).map_err(|e| IoError::Format {
        path: source.into(),
        line: e.pos().row as usize,
        message: format!("not a readable .b5r file (XML): {e}"),
    })?;
    let d = Doc { source, line_ends };
    let root = doc.root_element();
    if !root.has_tag_name("TEST_DOCUMENT") {
        return Err(d.error(
            root,
            format!(
                "the root element is {}, not TEST_DOCUMENT: not a Renishaw ballbar file",
                root.tag_name().name()
            ),
        ));
    }
    let spec = d.child(root, "TEST_SPEC")?;
    let instrument = d.child(spec, "INSTRUMENT")?;
    let bar = d.child(instrument, "DYNAMIC_BALLBAR")?;

    let radius_mm = d.number(bar, "NOMINAL_LENGTH")?;
    if radius_mm <= 0.0 {
        return Err(d.error(
            d.child(bar, "NOMINAL_LENGTH")?,
            format!("NOMINAL_LENGTH {radius_mm} is not a positive length"),
        ));
    }
    if let Some(node) = bar.children().find(|c| c.has_tag_name("TEST_RADIUS")) {
        let test_radius = d.parse_number(node, d.text(node))?;
        if (test_radius - radius_mm).abs() > crate::csv::RADIUS_TOLERANCE_MM {
            return Err(d.error(
                node,
                format!("TEST_RADIUS {test_radius} mm and NOMINAL_LENGTH {radius_mm} mm differ by more than 1 mm: the circle is not the bar's"),
            ));
        }
    }
    let feed_mm_per_min = d.number(bar, "PROGRAMMED_FEEDRATE")?;
    if feed_mm_per_min <= 0.0 {
        return Err(d.error(
            d.child(bar, "PROGRAMMED_FEEDRATE")?,
            format!("PROGRAMMED_FEEDRATE {feed_mm_per_min} is not a positive feed"),
        ));
    }
    let start_deg = d.number(bar, "START_ANGLE")?;
    let end_deg = d.number(bar, "END_ANGLE")?;
    let turn = ballbar_model::plausible::MAX_START_ANGLE_DEG;
    for (name, angle) in [("START_ANGLE", start_deg), ("END_ANGLE", end_deg)] {
        if angle.abs() > turn {
            return Err(d.error(
                d.child(bar, name)?,
                format!(
                    "{name} {}° is more than a turn ({turn}°) either way",
                    crate::check::shown(angle)
                ),
            ));
        }
    }
    let arc_deg = match (end_deg - start_deg).rem_euclid(360.0) {
        0.0 => 360.0,
        a => a,
    };
    let overshoot_deg = bar
        .children()
        .find(|c| c.has_tag_name("OVERSHOOT_ANGLE"))
        .map(|n| d.parse_number(n, d.text(n)))
        .transpose()?;

    // The plane and its axes.
    let plane_node = d.child(bar, "PLANE")?;
    let plane_name = plane_node
        .attribute("TEST_PLANE")
        .ok_or_else(|| d.error(plane_node, "element PLANE has no TEST_PLANE attribute"))?;
    let plane = Plane::from_name(plane_name).filter(|p| *p != Plane::Free).ok_or_else(|| {
        d.error(plane_node, format!("TEST_PLANE={} is not XY, YZ or ZX", quoted(plane_name)))
    })?;
    let (u, v, _) = plane.axes().expect("a planar plane has axes");
    let axis_named = |name: &str| -> Result<Axis, IoError> {
        let node = d.child(plane_node, name)?;
        let text = d.text(node);
        Axis::from_name(text).filter(|a| !a.is_rotary()).ok_or_else(|| {
            d.error(
                node,
                format!(
                    "element {}: {} is not a linear axis X, Y or Z",
                    d.path(node),
                    quoted(text)
                ),
            )
        })
    };
    let axis_a = axis_named("A_AXIS_NAME")?;
    let axis_b = axis_named("B_AXIS_NAME")?;
    // Our angle runs from +U towards +V: a vendor (A, B) = (V, U) turns the other way.
    let reversed = match (axis_a, axis_b) {
        (a, b) if a == u && b == v => false,
        (a, b) if a == v && b == u => true,
        (a, b) => {
            return Err(d.error(
                plane_node,
                format!("TEST_PLANE=\"{plane_name}\" with A = {} and B = {}: the axes are not the plane's", a.name(), b.name()),
            ));
        }
    };
    let pivot_mm = options.pivot_mm.unwrap_or(DEFAULT_PIVOT_MM);

    // What the file says about the test, kept in every run's header.
    let mut info: Vec<(String, String)> = Vec::new();
    // A header value is one line: a text of several (a comment) keeps its lines, joined by " / ".
    let mut keep = |key: &str, value: Option<&str>| {
        let one_line = value.map(crate::csv::one_line);
        if let Some(v) = one_line.filter(|v| !v.is_empty()) {
            info.push((key.to_string(), v));
        }
    };
    let text_at = |parent: Node, path: &[&str]| -> Option<String> {
        let mut at = parent;
        for name in path {
            at = at.children().find(|c| c.has_tag_name(*name))?;
        }
        Some(at.text().unwrap_or("").trim().to_string())
    };
    keep("vendor_file", Path::new(source).file_name().and_then(|s| s.to_str()));
    keep("vendor_test_name", spec.attribute("NAME"));
    keep("vendor_format_version", spec.attribute("version"));
    keep(
        "machine_name",
        root.children()
            .find(|c| c.has_tag_name("MACHINE_TESTED"))
            .and_then(|n| n.attribute("NAME")),
    );
    keep("operator", text_at(root, &["OPERATOR"]).as_deref());
    keep("comment", text_at(root, &["COMMENT"]).as_deref());
    keep("date_started", text_at(root, &["DATE_STARTED"]).as_deref());
    keep("date_completed", text_at(root, &["DATE_COMPLETED"]).as_deref());
    keep("instrument_model", instrument.attribute("MODEL"));
    keep("ballbar_model", text_at(root, &["EQUIPMENT", "BALLBAR", "MODEL"]).as_deref());
    keep("ballbar_serial", text_at(root, &["EQUIPMENT", "BALLBAR", "SERIAL_NUMBER"]).as_deref());
    keep(
        "ballbar_scale_factor",
        text_at(root, &["EQUIPMENT", "BALLBAR", "SCALE_FACTOR"]).as_deref(),
    );
    keep(
        "ballbar_certificate",
        text_at(root, &["EQUIPMENT", "BALLBAR", "CERTIFICATE_NUMBER"]).as_deref(),
    );
    keep(
        "ballbar_last_calibrated",
        text_at(root, &["EQUIPMENT", "BALLBAR", "LAST_CALIBRATED"]).as_deref(),
    );
    keep("calibrator_model", text_at(root, &["EQUIPMENT", "CALIBRATOR", "MODEL"]).as_deref());
    keep(
        "calibrator_serial",
        text_at(root, &["EQUIPMENT", "CALIBRATOR", "SERIAL_NUMBER"]).as_deref(),
    );
    keep(
        "calibrated_length_mm",
        text_at(root, &["EQUIPMENT", "CALIBRATOR", "CALIBRATED_LENGTH"]).as_deref(),
    );
    keep(
        "calibrator_temperature_c",
        text_at(root, &["EQUIPMENT", "CALIBRATOR", "TEMPERATURE"]).as_deref(),
    );
    keep(
        "calibrator_last_calibrated",
        text_at(root, &["EQUIPMENT", "CALIBRATOR", "LAST_CALIBRATED"]).as_deref(),
    );
    let software = [
        text_at(root, &["EQUIPMENT", "SOFTWARE", "TITLE"]),
        text_at(root, &["EQUIPMENT", "SOFTWARE", "VERSION"]),
    ]
    .into_iter()
    .flatten()
    .filter(|s| !s.is_empty())
    .collect::<Vec<_>>()
    .join(" ");
    keep("vendor_software", Some(&software));
    keep("start_angle_deg", Some(&start_deg.to_string()));
    keep("end_angle_deg", Some(&end_deg.to_string()));
    keep("arc_deg", Some(&arc_deg.to_string()));
    keep("overshoot_deg", overshoot_deg.map(|o| o.to_string()).as_deref());
    keep(
        "vendor_plane",
        Some(&format!(
            "{plane_name} A={} B={}{}",
            axis_a.name(),
            axis_b.name(),
            plane_node.attribute("VIEW").map(|v| format!(" VIEW={v}")).unwrap_or_default()
        )),
    );
    keep("requested_sample_rate_hz", text_at(bar, &["SAMPLE_RATE"]).as_deref());
    keep(
        "averaging",
        bar.children().find(|c| c.has_tag_name("AVERAGING")).and_then(|n| n.attribute("ENABLED")),
    );
    keep(
        "temp_material_coefficient_ppm_per_c",
        text_at(bar, &["TEMP_MATERIAL_COEFFICIENT"]).as_deref(),
    );
    keep(
        "pivot_source",
        Some(if options.pivot_mm.is_some() {
            "given by the user (--pivot); the .b5r file does not give the circle centre"
        } else {
            "default 0, 0, 0: the .b5r file does not give the circle centre (set it with --pivot X,Y,Z)"
        }),
    );

    // The start of the test: local time of the test's PC, zone unknown.
    let started_node = root.children().find(|c| c.has_tag_name("DATE_STARTED"));
    let test_start_s = match started_node {
        Some(node) => {
            let t = d.text(node);
            let iso = vendor_date(t).ok_or_else(|| {
                d.error(node, format!("DATE_STARTED {} is not YYYYMMDD-HHMMSS", quoted(t)))
            })?;
            ballbar_model::time::parse_iso8601(&format!("{iso}Z"))
                .map_err(|m| d.error(node, format!("DATE_STARTED {}: {m}", quoted(t))))?
        }
        None => {
            return Err(
                d.error(root, "the file has no DATE_STARTED element (when the test was made)")
            );
        }
    };

    // The runs.
    let results = d.child(root, "RUN_RESULTS")?;
    let run_nodes: Vec<Node> =
        results.children().filter(|c| c.has_tag_name("BALLBAR_RUN")).collect();
    if run_nodes.is_empty() {
        return Err(d.error(results, "RUN_RESULTS has no BALLBAR_RUN: the file holds no run"));
    }
    if run_nodes.len() > MAX_RUNS {
        return Err(d.error(
            run_nodes[MAX_RUNS],
            format!(
                "RUN_RESULTS has {} BALLBAR_RUN elements; a test has at most {MAX_RUNS}",
                run_nodes.len()
            ),
        ));
    }
    let mut runs = Vec::with_capacity(run_nodes.len());
    let mut run_features = Vec::with_capacity(run_nodes.len());
    let mut vendor_angles = Vec::with_capacity(run_nodes.len());
    let mut all_readings = Vec::with_capacity(run_nodes.len());
    // Seconds from the test's start to the first reading of the run: the runs follow each other
    // (readings with over-shoot, one after the other); pauses between runs are not recorded.
    let mut elapsed_s = 0.0;
    for (k, &node) in run_nodes.iter().enumerate() {
        let dir_node = d.child(node, "RUN_DIRECTION")?;
        let vendor_direction = match d.text(dir_node) {
            "CW" => Direction::CW,
            "CCW" => Direction::CCW,
            other => {
                return Err(
                    d.error(dir_node, format!("RUN_DIRECTION {} is not CW or CCW", quoted(other)))
                );
            }
        };
        let direction = if reversed { vendor_direction.reversed() } else { vendor_direction };
        let start = d.index(node, "START_INDEX")?;
        let end = d.index(node, "END_INDEX")?;
        let rate_node = d.child(node, "SAMPLE_RATE")?;
        let rate_hz = d.parse_number(rate_node, d.text(rate_node))?;
        if rate_hz <= 0.0 {
            return Err(d.error(rate_node, format!("SAMPLE_RATE {rate_hz} is not a positive rate")));
        }
        let (low, high) = ballbar_model::plausible::SAMPLE_RATE_HZ;
        if !(low..=high).contains(&rate_hz) {
            return Err(d.error(
                rate_node,
                format!(
                    "SAMPLE_RATE {} Hz is not a ballbar's sample rate ({low} to {high} Hz)",
                    crate::check::shown(rate_hz)
                ),
            ));
        }
        let readings_node = d.child(node, "READINGS")?;
        let readings = d.numbers(readings_node)?;
        if start > end || end >= readings.len() {
            return Err(d.error(
                readings_node,
                format!(
                    "run {} ({}): START_INDEX {start} and END_INDEX {end} do not lie within the {} readings",
                    k + 1,
                    d.text(dir_node),
                    readings.len()
                ),
            ));
        }
        let n = end - start + 1;
        if n < crate::csv::MIN_SAMPLES {
            return Err(d.error(
                readings_node,
                format!(
                    "run {}: the analysed arc has {n} readings; a run needs at least {}",
                    k + 1,
                    crate::csv::MIN_SAMPLES
                ),
            ));
        }
        // The speed the analysed arc implies against the programmed feed: an override moves
        // it, within what a controller's override reaches; far outside, the arc (START_ANGLE,
        // END_ANGLE) and the samples do not describe one motion, and no placement of them is
        // a circle test.
        let by_feed_deg = (feed_mm_per_min / 60.0 / radius_mm).to_degrees() / rate_hz;
        let ratio = arc_deg / n as f64 / by_feed_deg;
        let (lo, hi) = FEED_OVERRIDE_RANGE;
        if !(lo..=hi).contains(&ratio) {
            return Err(d.error(
                node,
                format!(
                    "run {} ({}): its {n} analysed readings at {} Hz over the {}° arc imply {:.1} mm/min, {:.1} % of the programmed {} mm/min, beyond any feed override ({:.0} % to {:.0} %): the arc (START_ANGLE, END_ANGLE) or the readings do not belong to this test",
                    k + 1,
                    d.text(dir_node),
                    crate::check::shown(rate_hz),
                    crate::check::shown(arc_deg),
                    feed_mm_per_min * ratio,
                    ratio * 100.0,
                    crate::check::shown(feed_mm_per_min),
                    lo * 100.0,
                    hi * 100.0
                ),
            ));
        }
        let (step, mode, spacing) =
            sample_spacing(arc_deg, n, radius_mm, feed_mm_per_min, rate_hz, options.angles);
        let mut xyz: [Vec<f64>; 3] = Default::default();
        for c in &mut xyz {
            c.reserve_exact(n);
        }
        // The vendor's own angle of each sample (its even spread, sample i at the middle of its
        // 1/n of the arc), for its features: in the (A, B) frame.
        let even = arc_deg / n as f64;
        vendor_angles.push(
            (0..n)
                .map(|i| match vendor_direction {
                    Direction::CCW => start_deg + (i as f64 + 0.5) * even,
                    Direction::CW => end_deg - (i as f64 + 0.5) * even,
                })
                .collect::<Vec<f64>>(),
        );
        for i in 0..n {
            // From the middle of the arc, so that the two spacings agree there.
            let along = arc_deg / 2.0 + (i as f64 - (n as f64 - 1.0) / 2.0) * step;
            let theta_deg = match vendor_direction {
                Direction::CCW => start_deg + along,
                Direction::CW => end_deg - along,
            };
            let (s, c) = theta_deg.to_radians().sin_cos();
            let mut p = pivot_mm;
            p[axis_a.index()] += radius_mm * c;
            p[axis_b.index()] += radius_mm * s;
            for (col, x) in xyz.iter_mut().zip(p) {
                col.push(x);
            }
        }
        let started = test_start_s + elapsed_s + start as f64 / rate_hz;
        elapsed_s += readings.len() as f64 / rate_hz;
        let mut extra = info.clone();
        let temperature = text_at(node, &["RUN_TEMPERATURE"])
            .map(|t| crate::csv::one_line(&t))
            .filter(|t| !t.is_empty());
        if let Some(t) = temperature {
            extra.push(("run_temperature_c".into(), t));
        }
        extra.push(("sample_rate_hz".into(), rate_hz.to_string()));
        extra.push(("angle_spacing".into(), spacing));
        extra.push(("angle_spacing_mode".into(), mode.name().into()));
        // The file's own name of the direction (its A towards B), where ours differs.
        extra.push(("vendor_direction".into(), vendor_direction.name().to_string()));
        extra.push((
            "readings_window".into(),
            format!("{start}..={end} of {} (over-shoot left out)", readings.len()),
        ));
        extra.push((
            "started_at_source".into(),
            "DATE_STARTED (the test PC's local time, zone not in the file, written as UTC) plus the readings of the runs before it (pauses between runs are not in the file: a later run may have started later)".into(),
        ));
        let line = d.line(readings_node);
        let header = RunHeader {
            format_version: crate::csv::FORMAT_VERSION,
            machine: None,
            plane,
            direction: Some(direction),
            radius_mm,
            feed_mm_per_min,
            pivot_mm,
            table_ball_mm: [0.0; 3],
            tool_ball_mm: options.tool_ball_mm.unwrap_or([0.0; 3]),
            // The file gives neither ball's position; the tool ball may come from the options.
            defaulted: ballbar_model::run::DefaultedKeys {
                table_ball_mm: true,
                tool_ball_mm: options.tool_ball_mm.is_none(),
            },
            started_at: ballbar_model::time::format_iso8601(started),
            started_at_unix_s: started,
            run_id: None, // named below, when every run's direction is known
            extra,
        };
        let [x, y, z] = xyz;
        let mut axes: [Option<Vec<f64>>; 6] = Default::default();
        axes[0] = Some(x);
        axes[1] = Some(y);
        axes[2] = Some(z);
        let run = Run {
            header,
            source: source.to_string(),
            t_s: (0..n).map(|i| i as f64 / rate_hz).collect(),
            axes,
            // Readings in mm, as a run CSV can carry them in µm: a run read here is written
            // (imported, exported) exactly.
            dr_mm: readings[start..=end].iter().map(|&r| crate::csv::reading_mm(r)).collect(),
            lines: vec![u32::try_from(line).unwrap_or(u32::MAX); n],
        };
        crate::check::check_run(&run)?;
        all_readings.push((readings.iter().map(|&r| crate::csv::reading_mm(r)).collect(), start));
        runs.push(run);
        run_features.push(d.features(node)?);
    }

    name_runs(&mut runs, source);

    let mut analyses = Vec::new();
    for node in root.children().filter(|c| c.has_tag_name("ANALYSIS")) {
        let name = node
            .attribute("NAME")
            .ok_or_else(|| d.error(node, "an ANALYSIS element has no NAME attribute"))?;
        let mut simulations = Vec::new();
        for sim in node.children().filter(|c| c.has_tag_name("SIMULATION")) {
            let sim_name = sim.attribute("NAME").ok_or_else(|| {
                d.error(sim, format!("a SIMULATION of {name} has no NAME attribute"))
            })?;
            simulations.push((sim_name.to_string(), d.numbers(sim)?));
        }
        analyses.push(VendorAnalysis {
            name: name.to_string(),
            version: node.attribute("version").map(str::to_string),
            features: d.features(node)?,
            simulations,
        });
    }
    Ok(B5rTest {
        source: source.to_string(),
        plane,
        axis_a,
        axis_b,
        runs,
        vendor_angles_deg: vendor_angles,
        readings_mm: all_readings,
        run_features,
        analyses,
    })
}

/// Largest relative difference between the feed the analysed arc implies (its n samples over
/// `arc` at the run's rate) and the programmed feed for the samples to be spaced by the
/// programmed feed: the vendor picks its window to whole samples around reversals it detects,
/// which on the shared real file makes it 0.45 % long (1578 samples where the programmed feed
/// turns the circle in 1570.8); a machine running at another feed (an override) is further off.
pub const FEED_AGREEMENT: f64 = 0.01;

/// The speeds, as a share of the programmed feed, that an analysed arc may imply (its samples
/// over its arc at the run's rate): a feed override's reach. The controllers' overrides go to
/// 120 % (SINUMERIK), 150 % (HEIDENHAIN) and 254 % (FANUC's override signals); 1 % at the
/// bottom, below which a test would be programmed at its feed, not overridden to it. A file
/// outside is refused: its arc and its readings are not one motion (a 0.5° arc holding 2880
/// readings at 1500 mm/min implies 2.3 mm/min), and a fit of it fails with nothing to say why.
pub const FEED_OVERRIDE_RANGE: (f64, f64) = (0.01, 2.55);

/// The angle between samples (degrees) and how it was chosen, for the header.
///
/// The vendor spaces its window's n samples evenly over the arc (`arc/n`, sample i at the middle
/// of its share): that reproduces its ISO 230-4 max/min locations on the shared real file to
/// 1e-5° (`vendor-b5r.md`'s `i·arc/(n−1)` is half a sample off). But the machine moved at the
/// programmed feed: on that file, with the window spread evenly, X's reversal spike falls 6
/// samples after its reversal at the start, 2 at 0° and one before it at the end, and the base
/// model leaves 0.427 µm; with the feed's spacing, the spikes sit where the reversals are and it
/// leaves 0.382 µm (the least of any spacing tried, 1570-1572 samples a turn). So where the
/// window agrees with the programmed feed to [`FEED_AGREEMENT`], the samples are spaced by the
/// feed, centred on the window; otherwise (an override) evenly over the window.
///
/// The geometry says the same, away from the spikes: fitting the readings farther than 12
/// samples from any reversal (per-run circle, 2θ, 3θ, direction-odd 2θ, backlash steps) leaves
/// 0.226 µm at 1570.8 samples a turn (the programmed feed), the least of any spacing, and
/// 0.249 µm at the vendor's 1578. Its squareness moves with the spacing (−2.5 µm/m at 1570.8,
/// −9.4 at 1578: the angles' drift, ±0.8° at the ends, couples the 56 µm set-up eccentricity
/// into the 2θ terms), which is why ours differs from the vendor's −10.3 on that file.
/// [`AngleSpacing::Vendor`] reads with the vendor's convention.
fn sample_spacing(
    arc_deg: f64,
    n: usize,
    radius_mm: f64,
    feed_mm_per_min: f64,
    rate_hz: f64,
    angles: AngleSpacing,
) -> (f64, SpacingMode, String) {
    let even = arc_deg / n as f64;
    let by_feed = (feed_mm_per_min / 60.0 / radius_mm).to_degrees() / rate_hz;
    let implied_feed = feed_mm_per_min * even / by_feed;
    if angles == AngleSpacing::Vendor {
        return (
            even,
            SpacingMode::Vendor,
            format!(
                "evenly over the analysed arc, {even:.6}° a sample, the vendor's convention (asked for); its {n} samples imply {implied_feed:.1} mm/min"
            ),
        );
    }
    if (even / by_feed - 1.0).abs() <= FEED_AGREEMENT {
        (
            by_feed,
            SpacingMode::Feed,
            format!(
                "by the programmed feed, {by_feed:.6}° a sample, centred on the analysed arc (its {n} samples imply {implied_feed:.1} mm/min, within {:.0} %)",
                FEED_AGREEMENT * 100.0
            ),
        )
    } else {
        (
            even,
            SpacingMode::Even,
            format!(
                "evenly over the analysed arc, {even:.6}° a sample: its {n} samples imply {implied_feed:.1} mm/min, more than {:.0} % from the programmed feed",
                FEED_AGREEMENT * 100.0
            ),
        )
    }
}

/// The machine's speed along the arc as a factor of the programmed feed, timed by the trace
/// itself: each reversal of an axis (θ a multiple of 90° in the (A, B) frame, over-shoot
/// included) leaves a sharp feature in the readings (a step, a spike); its sample is found as
/// the largest second difference within [`REVERSAL_SEARCH_SAMPLES`] of where the programmed
/// feed puts the reversal, and the samples found are regressed on those predicted (an
/// intercept per run: the feature follows the reversal by a few samples of servo delay, the
/// same at every reversal). The slope is 1/factor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeedFactor {
    /// The speed over the programmed feed's.
    pub factor: f64,
    /// Its standard uncertainty: the regression's, from the scatter of the samples found about
    /// the line, at least the ±½-sample rounding of a sample index (variance 1/12).
    pub u: f64,
    /// Reversals found.
    pub reversals: usize,
}

/// How far (samples) from the programmed feed's place a reversal is looked for: the servo delay
/// (3-4 samples on the shared real file) plus the drift of a feed off by
/// [`FEED_AGREEMENT`] over the 1.5 turns a run with 180° of over-shoot spans at 1500 samples a
/// turn (11 samples).
pub const REVERSAL_SEARCH_SAMPLES: usize = 15;

/// A reversal's second difference must exceed this many times the run's median absolute second
/// difference (the noise's; at least the 0.1 µm resolution) to be taken as found: below it the
/// largest value in the search window may be noise (on the shared real file the median is
/// 0.13 µm, the reversals' 0.85-2.2 µm).
pub const REVERSAL_CONTRAST: f64 = 4.0;

/// [`FeedFactor`] of a test whose runs are `runs` (its [`B5rTest::runs`], or the same runs once
/// taken from it), `None` where fewer than three reversals stand out of the noise or no run has
/// two.
pub fn feed_factor(test: &B5rTest, runs: &[Run]) -> Option<FeedFactor> {
    let w = REVERSAL_SEARCH_SAMPLES as f64;
    // (run, predicted sample, sample found)
    let mut found: Vec<(usize, f64, f64)> = Vec::new();
    for (k, ((readings, start), run)) in test.readings_mm.iter().zip(runs).enumerate() {
        let angles = test.vendor_angles_deg.get(k)?;
        let n = run.len();
        let (rate, r, feed) =
            (run.sample_rate_hz()?, run.header.radius_mm, run.header.feed_mm_per_min);
        if n < 2 || readings.len() < 3 || r <= 0.0 || feed <= 0.0 {
            continue;
        }
        let step = (feed / 60.0 / r).to_degrees() / rate;
        let d = if angles[n - 1] < angles[0] { -1.0 } else { 1.0 };
        let even = (angles[n - 1] - angles[0]).abs() / (n - 1) as f64;
        // Where the analysed arc's travel starts (θ of travel 0) and its middle sample.
        let theta0 = angles[0] - d * 0.5 * even;
        let arc = even * n as f64;
        let mid = *start as f64 + (n as f64 - 1.0) / 2.0;
        let at = |travel: f64| mid + (travel - arc / 2.0) / step;
        let d2: Vec<f64> = readings.windows(3).map(|v| (v[2] - 2.0 * v[1] + v[0]).abs()).collect();
        let mut sorted = d2.clone();
        sorted.sort_by(f64::total_cmp);
        // At least the readings' 0.1 µm resolution: a smooth trace, quantised, has second
        // differences of up to two quanta with no feature at all.
        let noise = sorted[sorted.len() / 2].max(1e-4);
        let last = readings.len() as f64 - 2.0;
        // Travel of the first and the last reading.
        let (lo, hi) = ((0.0 - mid) * step + arc / 2.0, (last + 1.0 - mid) * step + arc / 2.0);
        let (t1, t2) = (theta0 + d * lo, theta0 + d * hi);
        let m0 = (t1.min(t2) / 90.0).floor() as i64;
        let m1 = (t1.max(t2) / 90.0).ceil() as i64;
        for m in m0..=m1 {
            let travel = d * (90.0 * m as f64 - theta0);
            let j = at(travel);
            if j - w < 1.0 || j + w > last {
                continue;
            }
            let (a, b) = ((j - w).floor() as usize, (j + w).ceil() as usize);
            // d2[i] is the second difference centred on reading i + 1.
            let Some((i, v)) = (a - 1..b).map(|i| (i, d2[i])).max_by(|x, y| x.1.total_cmp(&y.1))
            else {
                continue;
            };
            if v > REVERSAL_CONTRAST * noise {
                found.push((k, j, (i + 1) as f64));
            }
        }
    }
    // Common slope, an intercept per run.
    let runs: Vec<usize> = {
        let mut v: Vec<usize> = found.iter().map(|f| f.0).collect();
        v.dedup();
        v
    };
    let centred = |k: usize| {
        let pts: Vec<(f64, f64)> = found.iter().filter(|f| f.0 == k).map(|f| (f.1, f.2)).collect();
        let n = pts.len() as f64;
        let (mx, my) =
            (pts.iter().map(|p| p.0).sum::<f64>() / n, pts.iter().map(|p| p.1).sum::<f64>() / n);
        pts.into_iter().map(move |(x, y)| (x - mx, y - my))
    };
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for &k in &runs {
        for (x, y) in centred(k) {
            sxy += x * y;
            sxx += x * x;
        }
    }
    let dof = found.len() as i64 - runs.len() as i64 - 1;
    if found.len() < 3 || dof < 1 || sxx <= 0.0 {
        return None;
    }
    let slope = sxy / sxx;
    let ss: f64 = runs.iter().flat_map(|&k| centred(k)).map(|(x, y)| (y - slope * x).powi(2)).sum();
    let var = (ss / dof as f64).max(1.0 / 12.0);
    let u_slope = (var / sxx).sqrt();
    Some(FeedFactor { factor: 1.0 / slope, u: u_slope / (slope * slope), reversals: found.len() })
}

/// How a run's samples were placed, as its header states it (`angle_spacing_mode`), so that a
/// program reading the run back (the recorder, the report) reads the file the same way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpacingMode {
    /// By the programmed feed, centred on the arc (`feed`).
    Feed,
    /// Evenly over the arc because the feed disagrees (`even`).
    Even,
    /// Evenly over the arc, asked for (`vendor`).
    Vendor,
}

impl SpacingMode {
    /// The header value.
    pub fn name(self) -> &'static str {
        match self {
            SpacingMode::Feed => "feed",
            SpacingMode::Even => "even",
            SpacingMode::Vendor => "vendor",
        }
    }

    /// The mode a run's header states, if it states one.
    pub fn of(run: &Run) -> Option<SpacingMode> {
        let v = run.header.extra.iter().find(|(k, _)| k == "angle_spacing_mode")?;
        [SpacingMode::Feed, SpacingMode::Even, SpacingMode::Vendor]
            .into_iter()
            .find(|m| m.name() == v.1)
    }

    /// The reader's option that reads a file again as a run with this mode was read.
    pub fn reread_with(self) -> AngleSpacing {
        match self {
            SpacingMode::Vendor => AngleSpacing::Vendor,
            SpacingMode::Feed | SpacingMode::Even => AngleSpacing::Machine,
        }
    }
}

/// Run ids from the file name: `<stem>-<direction>` (our direction), with the run's number
/// where a direction repeats, so that the runs of several files keep apart in tables,
/// archives and exports.
fn name_runs(runs: &mut [Run], source: &str) {
    let stem = Path::new(source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "b5r".into());
    let directions: Vec<&'static str> =
        runs.iter().map(|r| r.header.direction.map_or("run", Direction::name)).collect();
    let mut count: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    for d in &directions {
        *count.entry(d).or_default() += 1;
    }
    for (k, run) in runs.iter_mut().enumerate() {
        let d = directions[k];
        let repeated = count[d] > 1;
        let id = if repeated {
            format!("{stem}-{}-{}", d.to_lowercase(), k + 1)
        } else {
            format!("{stem}-{}", d.to_lowercase())
        };
        run.header.run_id = Some(id);
    }
}

#[cfg(test)]
mod tests;

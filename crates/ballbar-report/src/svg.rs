//! Inline SVG figures: polar plots of ballbar traces, the held-out shrink bar chart, trend
//! plots. Plain strings, no dependencies; every element a test or a stylesheet needs has a
//! class and data attributes.
//!
//! # The polar plot
//! The nominal circle is the ring at [`R0`] px; the radial deviation is drawn outward at
//! [`DIV`] px per division of the stated scale (µm per division), [`N_DIV`] divisions each way.
//! Angles are those of the run's plane: its first axis to the right, its second up (XY: +X
//! right, +Y up; YZ: +Y right, +Z up; ZX: +Z right, +X up), counter-clockwise positive, so
//! that a point at angle θ with deviation d sits at `x = C + r cos θ`, `y = C - r sin θ`,
//! `r = R0 + d/scale · DIV` (SVG's y points down). A rotary run's polar plot is the same with
//! θ the rotary axis's coordinate ([`Angles::Rotary`]). The axis labels are two arrows in the
//! top right corner ([`AXES_AT`]), outside the rings, where no trace or arc is drawn.
//!
//! A run's trace is marked where it starts (a dot on its first sample) and with an arrow of
//! [`ARROW_DEG`] from that angle, just inside the innermost ring, in the sense its angle moves
//! ([`increasing`], from the samples). The word `start` goes on the ray of that angle, as near
//! the dot as it can with no trace in its box ([`polar_label_at`]), drawn last with a white
//! halo. Where the diagnosis places the gap, an arc
//! follows the trace of its run over the sector ([`along`]), at the trace's deviation (held
//! within the rings).
//!
//! # The Cartesian plot
//! A partial sweep of a rotary axis: ΔR up at the same µm per division ([`N_DIV`] divisions
//! each side of the zero line), the axis's coordinate along x from the sweep's least angle at
//! the box's left edge ([`CART_BOX`]) to its greatest at the right edge. Start, direction and
//! arcs as on the polar plot (the word `start` above the dot, the arrow near the box's top,
//! along x).
//!
//! # The trend plot
//! A parameter's value per session with ±2u bars against the date ([`trend`]): the value axis
//! holds every bar, spans at least [`TREND_MIN_SPAN_U`] standard uncertainties and reaches zero
//! where that is sensible ([`trend_axis`]), with round ticks; the dates on round days or months
//! ([`date_ticks`]); the changes `ballbar history` flags ([`crate::history`]) drawn over the line.

use std::fmt::Write;

/// Width and height of a polar plot, px.
pub const SIZE: f64 = 340.0;
/// Its centre, px.
pub const C: f64 = SIZE / 2.0;
/// Radius of the nominal circle, px.
pub const R0: f64 = 100.0;
/// Pixels per division.
pub const DIV: f64 = 20.0;
/// Divisions inside and outside the nominal circle.
pub const N_DIV: usize = 3;
/// About this many points per drawn trace: the samples are cut into windows of equal count
/// and each window keeps its smallest and its largest deviation, in order, so that a spike a
/// sample or two wide (a reversal spike at 1 kHz) is drawn whatever the decimation.
pub const MAX_POINTS: usize = 1440;

/// The samples a trace keeps: per window, the indices of its extremes, in order.
pub fn decimate(values: &[f64]) -> Vec<usize> {
    let n = values.len();
    let window = (2 * n).div_ceil(MAX_POINTS).max(1);
    let mut out = Vec::with_capacity(2 * n / window + 2);
    let mut start = 0;
    while start < n {
        let end = (start + window).min(n);
        let (mut lo, mut hi) = (start, start);
        for i in start..end {
            if values[i] < values[lo] {
                lo = i;
            }
            if values[i] > values[hi] {
                hi = i;
            }
        }
        let (a, b) = (lo.min(hi), lo.max(hi));
        out.push(a);
        if b != a {
            out.push(b);
        }
        start = end;
    }
    if out.last() != Some(&(n - 1)) && n > 0 {
        out.push(n - 1);
    }
    out
}

/// HTML/XML text escape.
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// A scale of 1, 2 or 5 × 10ᵏ µm per division with `max_abs_um` within `N_DIV` divisions.
pub fn nice_scale(max_abs_um: f64) -> f64 {
    let need = (max_abs_um / N_DIV as f64).max(1e-3);
    let e = need.log10().floor();
    let base = 10f64.powf(e);
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * base)
        .find(|s| *s >= need * (1.0 - 1e-12))
        .unwrap_or(10.0 * base)
}

/// Each trace as one decimated `<path>`, its samples placed by `at(θ rad, ΔR µm) -> (x, y)`.
fn trace_paths(s: &mut String, traces: &[Trace<'_>], at: impl Fn(f64, f64) -> (f64, f64)) {
    for t in traces {
        let n = t.theta.len().min(t.value_um.len());
        if n == 0 {
            continue;
        }
        let keep = decimate(&t.value_um[..n]);
        let mut d = String::with_capacity(16 * keep.len());
        for (k, &i) in keep.iter().enumerate() {
            let (x, y) = at(t.theta[i], t.value_um[i]);
            let _ = write!(d, "{}{x:.2} {y:.2}", if k == 0 { "M" } else { " L" });
        }
        let _ = write!(s, r#"<path class="{}" data-run="{}" d="{d}"/>"#, t.class, esc(t.run));
    }
}

/// One trace on a plot (polar or against the angle).
pub struct Trace<'a> {
    /// Classes (`trace measured cw`).
    pub class: &'static str,
    /// The run's name.
    pub run: &'a str,
    /// Angles, rad.
    pub theta: &'a [f64],
    /// Deviations, µm.
    pub value_um: &'a [f64],
    /// Mark its first sample (`start`) and its direction of travel (an arrow): one trace of
    /// each run per plot (the measured or the residual one, not the model drawn over it).
    pub mark_start: bool,
}

/// The direction colour class of a trace's classes (`cw`, `ccw`, `nodir`).
fn dir_class(class: &str) -> &str {
    class.split(' ').find(|c| matches!(*c, "cw" | "ccw" | "nodir")).unwrap_or("nodir")
}

/// The fill of an arrow head of that direction class, as the page's stylesheet strokes the
/// traces (a presentation attribute: the stylesheet sets strokes only).
fn head_fill(dir: &str) -> &'static str {
    match dir {
        "cw" => "#1f4fbf",
        "ccw" => "#c0392b",
        _ => "#555",
    }
}

/// The sense a trace travels in, from its samples: `Some(true)` when its angle increases
/// (counter-clockwise on a polar plot, rightward on a Cartesian one), from the sum of the
/// steps between consecutive samples (each wrapped to ±180°, so that a run through 0° counts
/// its true travel); `None` when it does not move.
pub fn increasing(theta: &[f64]) -> Option<bool> {
    let tau = std::f64::consts::TAU;
    let travel: f64 = theta
        .windows(2)
        .map(|w| (w[1] - w[0] + std::f64::consts::PI).rem_euclid(tau) - std::f64::consts::PI)
        .sum();
    (travel.abs() > 1e-9).then_some(travel > 0.0)
}

/// A highlighted arc (where the gap lies), drawn along the trace of its run.
#[derive(Clone, Debug)]
pub struct Arc {
    /// From, degrees (counter-clockwise to `to_deg`).
    pub from_deg: f64,
    /// To, degrees.
    pub to_deg: f64,
    /// Whether the angles are taken modulo 360° (a plane, a whole turn of a rotary axis): the
    /// arc then runs counter-clockwise from `from_deg` to `to_deg`, through 0° when `to_deg`
    /// is the smaller; otherwise (a partial sweep) from `from_deg` up to `to_deg` in the
    /// axis's own degrees.
    pub wrap: bool,
    /// Direction of the runs it belongs to (`CW`, `CCW`, `-`).
    pub direction: String,
    /// The run it is drawn along (the plot's first trace of that run).
    pub run: String,
    /// Its share of the gap.
    pub share: f64,
}

/// Angles along an arc are drawn this far apart at most, degrees.
pub const ARC_STEP_DEG: f64 = 0.5;

/// The trace's deviation along an arc, as (angle °, deviation µm): at both ends of the arc and
/// every [`ARC_STEP_DEG`] or less between them, each interpolated linearly between the two
/// consecutive samples whose angles bracket it (the run's first passage over it). Angles the
/// run does not pass are left out (`None`).
pub fn along(t: &Trace<'_>, arc: &Arc) -> Vec<(f64, Option<f64>)> {
    let span = if arc.wrap {
        let s = (arc.to_deg - arc.from_deg).rem_euclid(360.0);
        if s == 0.0 { 360.0 } else { s }
    } else {
        arc.to_deg - arc.from_deg
    };
    if span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return vec![];
    }
    let m = (span / ARC_STEP_DEG).ceil().max(1.0) as usize;
    let step = span / m as f64;
    let mut vals: Vec<Option<f64>> = vec![None; m + 1];
    let n = t.theta.len().min(t.value_um.len());
    let shifts: &[f64] = if arc.wrap { &[0.0, 360.0, -360.0] } else { &[0.0] };
    for i in 0..n.saturating_sub(1) {
        let (a, b) = (t.theta[i].to_degrees(), t.theta[i + 1].to_degrees());
        let (oa, ob) = if arc.wrap {
            let oa = (a - arc.from_deg).rem_euclid(360.0);
            (oa, oa + ((b - a + 180.0).rem_euclid(360.0) - 180.0))
        } else {
            (a - arc.from_deg, b - arc.from_deg)
        };
        for &shift in shifts {
            let (lo, hi) = (oa.min(ob) + shift, oa.max(ob) + shift);
            if hi < -1e-9 || lo > span + 1e-9 {
                continue;
            }
            let k0 = ((lo / step) - 1e-9).ceil().max(0.0) as usize;
            let k1 = (((hi / step) + 1e-9).floor().max(0.0) as usize).min(m);
            for (k, v) in vals.iter_mut().enumerate().take(k1 + 1).skip(k0) {
                if v.is_none() {
                    let f = if ob == oa {
                        0.0
                    } else {
                        ((k as f64 * step - oa - shift) / (ob - oa)).clamp(0.0, 1.0)
                    };
                    *v = Some(t.value_um[i] + f * (t.value_um[i + 1] - t.value_um[i]));
                }
            }
        }
    }
    vals.into_iter().enumerate().map(|(k, v)| (arc.from_deg + k as f64 * step, v)).collect()
}

/// `d` of a polyline through the points, a new subpath after each gap (`None`).
fn polyline(pts: impl IntoIterator<Item = Option<(f64, f64)>>) -> String {
    let mut d = String::new();
    let mut pen = false;
    for p in pts {
        match p {
            Some((x, y)) => {
                let _ = write!(
                    d,
                    "{}{}{x:.2} {y:.2}",
                    if d.is_empty() { "" } else { " " },
                    if pen { "L" } else { "M" }
                );
                pen = true;
            }
            None => pen = false,
        }
    }
    d
}

/// The arcs, each along the first trace of its run: `at(θ rad, ΔR µm)` places a point (inside
/// the plot's rings or box).
fn arc_paths(
    s: &mut String,
    arcs: &[Arc],
    traces: &[Trace<'_>],
    at: impl Fn(f64, f64) -> (f64, f64),
) {
    for a in arcs {
        let Some(t) = traces.iter().find(|t| t.run == a.run) else { continue };
        let d =
            polyline(along(t, a).into_iter().map(|(deg, v)| v.map(|v| at(deg.to_radians(), v))));
        if d.is_empty() {
            continue;
        }
        let _ = write!(
            s,
            r#"<path class="where {}" data-run="{}" data-from-deg="{}" data-to-deg="{}" data-share="{}" stroke-linecap="butt" d="{d}"/>"#,
            esc(&a.direction.to_lowercase()),
            esc(&a.run),
            a.from_deg,
            a.to_deg,
            a.share
        );
    }
}

/// What a polar plot's angle is, and how its directions are labelled.
pub enum Angles<'a> {
    /// The angle in a plane: its axes' names (right, up), labelled `+X`, `+Y`.
    Plane(&'a str, &'a str),
    /// A rotary axis's coordinate (its name): labelled `C 0°` (right) and `C 90°` (up).
    Rotary(&'a str),
}

/// A polar plot.
pub struct Polar<'a> {
    /// Classes of the `<svg>` (`polar raw`).
    pub class: &'static str,
    /// Title line.
    pub title: String,
    /// What the angle is.
    pub angles: Angles<'a>,
    /// µm per division.
    pub scale_um: f64,
    /// Traces.
    pub traces: Vec<Trace<'a>>,
    /// Highlighted arcs.
    pub arcs: Vec<Arc>,
    /// Lines written in the plot's top left corner, each with the class of its colour (`cw`,
    /// `ccw`, `nodir`): the runs' circular deviations G.
    pub legend: Vec<(&'static str, String)>,
    /// The key of the traces' line styles, in the bottom left corner: each a short line
    /// drawn with a trace's classes (`trace model cw`: dashed, in its direction's colour) and
    /// what it is (`model`). Empty: no key.
    pub keys: Vec<(&'static str, String)>,
}

/// The direction at which the rings' values are written (rad from +u towards +v): between
/// the 45° and 90° spokes, clear of the axes' glyph (top right, outside the rings) and of the
/// `start` labels (at the runs' first samples, usually 0° or 180°).
const RING_LABEL_THETA: f64 = 67.5 * std::f64::consts::PI / 180.0;

/// A ring's value for its label: signed, in the plot's µm (`+2`, `0`, `−2`).
pub fn ring_value(k_from_nominal: i64, scale_um: f64) -> String {
    let v = fmt_scale(k_from_nominal.unsigned_abs() as f64 * scale_um);
    match k_from_nominal.signum() {
        1 => format!("+{v}"),
        -1 => format!("−{v}"),
        _ => "0".into(),
    }
}

/// The point of a deviation at an angle.
pub fn point(theta: f64, value_um: f64, scale_um: f64) -> (f64, f64) {
    let r = (R0 + value_um / scale_um * DIV).clamp(2.0, C - 2.0);
    (C + r * theta.cos(), C - r * theta.sin())
}

/// The point of a deviation at an angle, inside the rings (a deviation beyond the last
/// division on the outermost or innermost ring).
pub fn point_in_rings(theta: f64, value_um: f64, scale_um: f64) -> (f64, f64) {
    let r = (R0 + value_um / scale_um * DIV).clamp(INNER, OUTER);
    (C + r * theta.cos(), C - r * theta.sin())
}

/// The radius of the outermost ring, px.
pub const OUTER: f64 = R0 + N_DIV as f64 * DIV;
/// The radius of the innermost ring, px.
pub const INNER: f64 = R0 - N_DIV as f64 * DIV;

/// The corner of a polar plot where its axis labels are, outside the outermost ring: the
/// origin of the two direction arrows (right, up), px.
pub const AXES_AT: (f64, f64) = (SIZE - 50.0, 34.0);

/// A direction arrow spans this much of its circle, degrees.
pub const ARROW_DEG: f64 = 40.0;

/// A run's direction arrow as a plot draws it: its path's `d`, the data attributes it adds to
/// the run and the sense, and its head's corners (the tip first).
struct Arrow {
    d: String,
    data: String,
    head: [(f64, f64); 3],
}

/// The box the word `start` takes at the page's 11 px font (about 24 × 8 px of ink), with a
/// margin of 2 px: width and height, px.
pub const LABEL_BOX: (f64, f64) = (28.0, 12.0);

/// The `start` label's baseline is this far below its box's centre, px (the 11 px font's ink
/// centred on it).
const LABEL_BASELINE: f64 = 4.0;

/// The start marks of the traces that have them, as both plots draw them: a dot on the first
/// sample (`at(θ rad, ΔR µm)` places it), an arrow along the run's sense of travel (`arrow(k,
/// first sample's angle, dot, increasing)` shapes that of the `k`-th marked run) with its head,
/// and the word `start` beside the first dot at a place (`label_at(dot, first sample's angle)`
/// gives its box's centre), drawn last with a white halo so that nothing lies over it.
fn start_marks(
    s: &mut String,
    traces: &[Trace<'_>],
    at: impl Fn(f64, f64) -> (f64, f64),
    label_at: impl Fn((f64, f64), f64) -> (f64, f64),
    arrow: impl Fn(usize, f64, (f64, f64), bool) -> Arrow,
) {
    let mut dots: Vec<(f64, f64)> = Vec::new();
    let mut labels = String::new();
    for (k, t) in traces
        .iter()
        .filter(|t| t.mark_start && !t.theta.is_empty() && !t.value_um.is_empty())
        .enumerate()
    {
        let dir = dir_class(t.class);
        let th = t.theta[0];
        let (x, y) = at(th, t.value_um[0]);
        let deg0 = th.to_degrees();
        let _ = write!(
            s,
            r#"<circle class="start {dir}" data-run="{}" data-deg="{deg0}" cx="{x:.2}" cy="{y:.2}" r="3.5" fill="{}"/>"#,
            esc(t.run),
            head_fill(dir)
        );
        if !dots.iter().any(|&(a, b)| (a - x).hypot(b - y) < 14.0) {
            dots.push((x, y));
            let (lx, ly) = label_at((x, y), th);
            let _ = write!(
                labels,
                r##"<text class="start-label" data-run="{}" text-anchor="middle" stroke="#fff" stroke-width="3" stroke-linejoin="round" paint-order="stroke" x="{lx:.1}" y="{:.1}">start</text>"##,
                esc(t.run),
                ly + LABEL_BASELINE
            );
        }
        let Some(up) = increasing(t.theta) else { continue };
        let a = arrow(k, th, (x, y), up);
        let _ = write!(
            s,
            r#"<path class="arrow {dir}" data-run="{}" data-sense="{}"{} fill="none" stroke-width="1.4" d="{}"/>"#,
            esc(t.run),
            if up { "ccw" } else { "cw" },
            a.data,
            a.d
        );
        let [(x0, y0), (x1, y1), (x2, y2)] = a.head;
        let _ = write!(
            s,
            r#"<path class="arrow-head {dir}" data-run="{}" fill="{}" d="M {x0:.2} {y0:.2} L {x1:.2} {y1:.2} L {x2:.2} {y2:.2} Z"/>"#,
            esc(t.run),
            head_fill(dir)
        );
    }
    s.push_str(&labels);
}

/// The polar plot's arrows: an arc of [`ARROW_DEG`] just inside the innermost ring from the
/// first sample's angle (one ring of arrows per run), its head a triangle at the arc's end
/// along its tangent.
fn polar_arrow(k: usize, th: f64, up: bool) -> Arrow {
    let ra = (INNER - 8.0 - 8.0 * k as f64).max(6.0);
    let end = th + (if up { ARROW_DEG } else { -ARROW_DEG }).to_radians();
    let (x0, y0) = (C + ra * th.cos(), C - ra * th.sin());
    let (x1, y1) = (C + ra * end.cos(), C - ra * end.sin());
    // Counter-clockwise on the page (y down) is sweep flag 0.
    let d = format!("M {x0:.2} {y0:.2} A {ra} {ra} 0 0 {} {x1:.2} {y1:.2}", u8::from(!up));
    let data =
        format!(r#" data-from-deg="{}" data-to-deg="{}""#, th.to_degrees(), end.to_degrees());
    // The head along the arc's tangent (the page's y points down).
    let sign = if up { 1.0 } else { -1.0 };
    let (tx, ty) = (-sign * end.sin(), -sign * end.cos());
    let (nx, ny) = (end.cos(), -end.sin());
    Arrow {
        d,
        data,
        head: [
            (x1 + 6.0 * tx, y1 + 6.0 * ty),
            (x1 + 3.5 * nx, y1 + 3.5 * ny),
            (x1 - 3.5 * nx, y1 - 3.5 * ny),
        ],
    }
}

/// Where the polar plot's `start` label goes: the centre of its box ([`LABEL_BOX`]) on the ray
/// of the first sample's angle `th`, as near the dot at `dot` as it can be with no point of any
/// trace (`points`, px) and not the dot itself in its box, the box within the plot, outside the
/// innermost ring (where the arrows are) and clear of the axis labels ([`AXES_AT`]). When no
/// place on the ray is clear, the place with the fewest points in its box.
pub fn polar_label_at(dot: (f64, f64), th: f64, points: &[(f64, f64)]) -> (f64, f64) {
    let (w, h) = (LABEL_BOX.0 / 2.0, LABEL_BOX.1 / 2.0);
    let (c, s) = (th.cos(), th.sin());
    // The box's extent along the ray: no point of it nearer the centre than r − reach.
    let reach = c.abs() * w + s.abs() * h;
    let r_dot = (dot.0 - C).hypot(dot.1 - C);
    // The points near the ray (within the box's half diagonal of it), the dot among them.
    let near = w.hypot(h) + 4.0;
    let mut on_ray: Vec<(f64, f64)> = points
        .iter()
        .copied()
        .filter(|&(x, y)| ((x - C) * s + (y - C) * c).abs() <= near)
        .collect();
    on_ray.push(dot);
    let inside = |(x, y): (f64, f64), (cx, cy): (f64, f64), pad: f64| {
        (x - cx).abs() <= w + pad && (y - cy).abs() <= h + pad
    };
    let (ax, ay) = AXES_AT;
    let mut best: Option<(usize, f64, (f64, f64))> = None;
    let mut r = INNER + reach;
    while r <= OUTER + reach {
        let centre = (C + r * c, C - r * s);
        let (cx, cy) = centre;
        let in_plot =
            cx - w >= 2.0 && cx + w <= SIZE - 2.0 && cy - h >= 2.0 && cy + h <= SIZE - 2.0;
        // The axis labels' corner: from the `+Y` label's left to the edge, above the `+X` label's foot.
        let on_axes = cx + w >= ax - 30.0 && cy - h <= ay + 18.0;
        if in_plot && !on_axes {
            // The dot (3.5 px) and the traces' strokes (1.4 px at most) count to their edge.
            let hits = on_ray
                .iter()
                .filter(|&&p| inside(p, centre, if p == dot { 3.5 } else { 1.0 }))
                .count();
            let better = match best {
                None => true,
                Some((n, rb, _)) => {
                    hits < n || (hits == n && (r - r_dot).abs() < (rb - r_dot).abs())
                }
            };
            if better {
                best = Some((hits, r, centre));
            }
        }
        r += 0.5;
    }
    best.map_or((C + (INNER + reach) * c, C - (INNER + reach) * s), |(_, _, p)| p)
}

/// The axis labels of a polar plot in its top right corner, outside the rings: an arrow right
/// labelled with the first axis (`+X`, or `C 0°`), an arrow up labelled with the second (`+Y`,
/// or `C 90°`).
fn axes_glyph(s: &mut String, angles: &Angles<'_>) {
    let (right, up) = match angles {
        Angles::Plane(u, v) => (format!("+{u}"), format!("+{v}")),
        Angles::Rotary(a) => (format!("{a} 0°"), format!("{a} 90°")),
    };
    let (ox, oy) = AXES_AT;
    let _ = write!(
        s,
        r##"<g class="axes"><path fill="none" stroke="#555" d="M {ox} {oy} H {} M {ox} {oy} V {}"/><path fill="#555" d="M {} {oy} l -6 -3 v 6 Z M {ox} {} l -3 6 h 6 Z"/>"##,
        ox + 36.0,
        oy - 28.0,
        ox + 40.0,
        oy - 32.0
    );
    let _ = write!(
        s,
        r#"<text class="axis" text-anchor="end" x="{}" y="{}">{}</text>"#,
        SIZE - 4.0,
        oy + 14.0,
        esc(&right)
    );
    let _ = write!(
        s,
        r#"<text class="axis" text-anchor="end" x="{}" y="{}">{}</text></g>"#,
        ox - 5.0,
        oy - 20.0,
        esc(&up)
    );
}

/// The SVG of a polar plot.
pub fn polar(p: &Polar<'_>) -> String {
    let mut s = String::new();
    let axis = match p.angles {
        Angles::Rotary(a) => format!(r#" data-axis="{}""#, esc(a)),
        Angles::Plane(..) => String::new(),
    };
    let _ = write!(
        s,
        r#"<svg class="{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {SIZE} {}" width="{SIZE}" height="{}" data-scale-um="{}" data-r0="{R0}" data-div="{DIV}" data-n-div="{N_DIV}" data-cx="{C}" data-cy="{C}"{axis}>"#,
        p.class,
        SIZE + 24.0,
        SIZE + 24.0,
        p.scale_um
    );
    let _ = write!(s, "<title>{}</title>", esc(&p.title));
    // Rings: the nominal circle bold, divisions thin.
    for k in 0..=2 * N_DIV {
        let r = R0 + (k as f64 - N_DIV as f64) * DIV;
        let class = if k == N_DIV { "ring nominal" } else { "ring" };
        let _ = write!(s, r#"<circle class="{class}" cx="{C}" cy="{C}" r="{r}"/>"#);
    }
    for deg in (0..360).step_by(45) {
        let (x, y) = point((deg as f64).to_radians(), N_DIV as f64 * p.scale_um, p.scale_um);
        let _ = write!(s, r#"<line class="spoke" x1="{C}" y1="{C}" x2="{x:.1}" y2="{y:.1}"/>"#);
    }
    axes_glyph(&mut s, &p.angles);
    arc_paths(&mut s, &p.arcs, &p.traces, |theta, v| point_in_rings(theta, v, p.scale_um));
    trace_paths(&mut s, &p.traces, |theta, v| point(theta, v, p.scale_um));
    // Every trace's points (the model's too), for the `start` label to keep clear of.
    let points: Vec<(f64, f64)> = p
        .traces
        .iter()
        .flat_map(|t| t.theta.iter().zip(t.value_um).map(|(&th, &v)| point(th, v, p.scale_um)))
        .collect();
    start_marks(
        &mut s,
        &p.traces,
        |theta, v| point(theta, v, p.scale_um),
        |dot, th| polar_label_at(dot, th, &points),
        |k, th, _, up| polar_arrow(k, th, up),
    );
    // Each ring's value in µm from the nominal circle (the bold ring, 0), on a white halo, over
    // the traces, so that no trace hides it.
    for k in 0..=2 * N_DIV {
        let from_nominal = k as i64 - N_DIV as i64;
        let r = R0 + from_nominal as f64 * DIV;
        let (x, y) = (C + r * RING_LABEL_THETA.cos(), C - r * RING_LABEL_THETA.sin());
        let _ = write!(
            s,
            r#"<text class="ring-value" x="{x:.1}" y="{:.1}" data-um="{}">{}</text>"#,
            y + 3.0,
            from_nominal as f64 * p.scale_um,
            ring_value(from_nominal, p.scale_um)
        );
    }
    for (k, (class, line)) in p.legend.iter().enumerate() {
        let _ = write!(
            s,
            r#"<text class="legend {}" x="4" y="{}">{}</text>"#,
            dir_class(class),
            12.0 + 14.0 * k as f64,
            esc(line)
        );
    }
    // The key above the caption, clear of the rings (the corner lies beyond the outermost).
    let n = p.keys.len();
    for (k, (class, what)) in p.keys.iter().enumerate() {
        let y = SIZE + 4.0 - 14.0 * (n - 1 - k) as f64;
        let _ = write!(
            s,
            r#"<g class="key"><path class="key-line {class}" d="M 4 {:.1} H 28"/><text class="key" x="32" y="{y:.1}">{}</text></g>"#,
            y - 4.0,
            esc(what)
        );
    }
    let _ = write!(
        s,
        r#"<text class="caption" x="4" y="{}">{}</text>"#,
        SIZE + 18.0,
        esc(&format!(
            "{} µm/div; rings in µm from the nominal circle (bold)",
            fmt_scale(p.scale_um)
        ))
    );
    s.push_str("</svg>");
    s
}

/// Width of a Cartesian plot, px (its height is a polar plot's, so that they line up).
pub const CART_W: f64 = 480.0;
/// Its height, px.
pub const CART_H: f64 = SIZE + 24.0;
/// The plot box of a Cartesian plot (left, top, right, bottom), px: room left of it for the
/// ΔR ticks and label, under it for the angle ticks, the angle label and the scale.
pub const CART_BOX: [f64; 4] = [62.0, 14.0, CART_W - 14.0, CART_H - 58.0];

/// ΔR against a rotary axis's coordinate over a partial sweep.
pub struct Cartesian<'a> {
    /// Classes of the `<svg>` (`rotary-cartesian raw`).
    pub class: &'static str,
    /// Title line.
    pub title: String,
    /// The rotary axis's name (the x label: `C (°)`).
    pub axis: &'a str,
    /// The angles at the box's left and right edges, degrees.
    pub range_deg: (f64, f64),
    /// µm per division ([`N_DIV`] divisions each side of zero, as a polar plot's).
    pub scale_um: f64,
    /// Traces (their `theta`, rad, is the axis's coordinate).
    pub traces: Vec<Trace<'a>>,
    /// Highlighted arcs (`wrap` false: in the axis's degrees).
    pub arcs: Vec<Arc>,
}

/// A step of the angle ticks, degrees: at most 8 intervals over `span`.
fn angle_step(span: f64) -> f64 {
    [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0]
        .into_iter()
        .find(|s| span / s <= 8.0 + 1e-9)
        .unwrap_or(360.0)
}

/// The SVG of a Cartesian plot: the box, ΔR at `scale_um` per division from -[`N_DIV`] to
/// +[`N_DIV`] divisions (the zero line bold), the angle from `range_deg.0` at the box's left
/// edge to `range_deg.1` at its right, ticks and labels with units, the scale stated. Every
/// point is inside the box (a deviation beyond the last division is drawn on the box's edge,
/// which the scale's choice prevents).
pub fn cartesian(p: &Cartesian<'_>) -> String {
    let [left, top, right, bottom] = CART_BOX;
    let (from, to) = if p.range_deg.1 > p.range_deg.0 {
        p.range_deg
    } else {
        (p.range_deg.0 - 1.0, p.range_deg.0 + 1.0)
    };
    let div = (bottom - top) / (2 * N_DIV) as f64;
    let mid = (top + bottom) / 2.0;
    let x = |deg: f64| (left + (deg - from) / (to - from) * (right - left)).clamp(left, right);
    let y = |um: f64| (mid - um / p.scale_um * div).clamp(top, bottom);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg class="{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {CART_W} {CART_H}" width="{CART_W}" height="{CART_H}" data-scale-um="{}" data-axis="{}" data-from-deg="{from}" data-to-deg="{to}" data-left="{left}" data-top="{top}" data-right="{right}" data-bottom="{bottom}">"#,
        p.class,
        p.scale_um,
        esc(p.axis)
    );
    let _ = write!(s, "<title>{}</title>", esc(&p.title));
    for k in -(N_DIV as i32)..=N_DIV as i32 {
        let yk = mid - k as f64 * div;
        let class = if k == 0 { "zero" } else { "grid" };
        let _ = write!(
            s,
            r#"<line class="{class}" x1="{left}" y1="{yk:.2}" x2="{right}" y2="{yk:.2}"/>"#
        );
        let label = if k == 0 {
            "0".to_string()
        } else {
            format!(
                "{}{}",
                if k > 0 { "+" } else { "-" },
                fmt_scale(k.unsigned_abs() as f64 * p.scale_um)
            )
        };
        let _ = write!(
            s,
            r#"<text class="tick" text-anchor="end" x="{}" y="{:.2}">{label}</text>"#,
            left - 4.0,
            yk + 4.0
        );
    }
    let step = angle_step(to - from);
    let first = (from / step - 1e-9).ceil() as i64;
    let last = (to / step + 1e-9).floor() as i64;
    for k in first..=last {
        let deg = k as f64 * step;
        let xk = x(deg);
        let _ = write!(
            s,
            r#"<line class="grid angle" data-deg="{deg}" x1="{xk:.2}" y1="{top}" x2="{xk:.2}" y2="{bottom}"/>"#
        );
        let _ = write!(
            s,
            r#"<text class="tick" text-anchor="middle" x="{xk:.2}" y="{}">{deg}°</text>"#,
            bottom + 14.0
        );
    }
    let _ = write!(
        s,
        r#"<rect class="frame" x="{left}" y="{top}" width="{}" height="{}"/>"#,
        right - left,
        bottom - top
    );
    arc_paths(&mut s, &p.arcs, &p.traces, |theta, v| (x(theta.to_degrees()), y(v)));
    trace_paths(&mut s, &p.traces, |theta, v| (x(theta.to_degrees()), y(v)));
    // The label above the dot, inside the box.
    let label_at = |(dx, dy): (f64, f64), _| {
        (dx.clamp(left + 14.0, right - 14.0), (dy - 7.0).max(top + 10.0) - LABEL_BASELINE)
    };
    start_marks(
        &mut s,
        &p.traces,
        |theta, v| (x(theta.to_degrees()), y(v)),
        label_at,
        |k, _, (dx, _), up| cartesian_arrow(k, dx, up),
    );
    let _ = write!(
        s,
        r#"<text class="axis-label" text-anchor="middle" x="{}" y="{}">{} (°)</text>"#,
        (left + right) / 2.0,
        bottom + 32.0,
        esc(p.axis)
    );
    let _ = write!(
        s,
        r#"<text class="axis-label" text-anchor="middle" transform="rotate(-90 14 {mid})" x="14" y="{mid}">ΔR (µm)</text>"#
    );
    let _ = write!(
        s,
        r#"<text class="caption" x="4" y="{}">{}</text>"#,
        CART_H - 6.0,
        esc(&format!("ΔR {} µm/div; {} {}°/div", fmt_scale(p.scale_um), p.axis, step))
    );
    s.push_str("</svg>");
    s
}

/// The Cartesian plot's arrows: from the start's x into the box, 30 px along the travel (right
/// when the angle increases), the head 6 px beyond, near the top of the box (one row per run).
fn cartesian_arrow(k: usize, x: f64, up: bool) -> Arrow {
    let [left, top, right, _] = CART_BOX;
    let ya = top + 8.0 + 8.0 * k as f64;
    let sign = if up { 1.0 } else { -1.0 };
    let x0 = x.clamp(left + 4.0, right - 4.0);
    let x1 = (x0 + sign * 30.0).clamp(left + 4.0, right - 4.0);
    Arrow {
        d: format!("M {x0:.2} {ya:.2} L {x1:.2} {ya:.2}"),
        data: String::new(),
        head: [(x1 + sign * 6.0, ya), (x1, ya - 3.5), (x1, ya + 3.5)],
    }
}

/// A scale for the caption (no trailing zeros).
pub fn fmt_scale(x: f64) -> String {
    let t = format!("{x:.3}");
    t.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// One bar of the shrink chart.
pub struct Bar {
    /// Label.
    pub label: String,
    /// Shrink, fraction.
    pub value: f64,
    /// Its interval.
    pub interval: [f64; 2],
}

/// The held-out shrink of each accepted effect as horizontal bars with their intervals, 0 to
/// 100 %: each bar under its label, which has the plot's whole width (a label beside the bar
/// would be overdrawn by it, or cut); a label longer than the width holds is shortened with
/// `…`, the whole of it in the row's `<title>` (and in the effects table above the chart).
pub fn shrink_bars(bars: &[Bar]) -> String {
    let (w, left, row) = (680.0, 4.0, 40.0);
    let h = row * bars.len() as f64 + 30.0;
    let x = |f: f64| left + f.clamp(0.0, 1.0) * (w - left - 50.0);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg class="shrink-bars" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">"#
    );
    for pct in [0.0, 0.25, 0.5, 0.75, 1.0] {
        let _ = write!(
            s,
            r#"<line class="grid" x1="{0:.1}" y1="4" x2="{0:.1}" y2="{1}"/><text class="tick" x="{0:.1}" y="{2}" text-anchor="{4}">{3:.0} %</text>"#,
            x(pct),
            h - 22.0,
            h - 8.0,
            pct * 100.0,
            if pct == 0.0 { "start" } else { "middle" }
        );
    }
    for (k, b) in bars.iter().enumerate() {
        let y = 4.0 + k as f64 * row;
        let _ = write!(
            s,
            r#"<g class="shrink-row"><title>{}</title><text class="label" x="{left}" y="{:.1}">{}</text>"#,
            esc(&b.label),
            y + 12.0,
            esc(&shortened(&b.label, BAR_LABEL_CHARS))
        );
        let (top, height) = (y + 17.0, row - 22.0);
        let _ = write!(
            s,
            r#"<rect class="bar" data-shrink="{}" x="{left}" y="{top:.1}" width="{:.1}" height="{height}"/>"#,
            b.value,
            x(b.value) - left,
        );
        let ym = top + height / 2.0;
        let _ = write!(
            s,
            r#"<line class="interval" x1="{:.1}" y1="{ym:.1}" x2="{:.1}" y2="{ym:.1}"/></g>"#,
            x(b.interval[0]),
            x(b.interval[1])
        );
    }
    s.push_str("</svg>");
    s
}

/// The characters of a bar's label that the chart's width holds at 11 px (about 6 px a
/// character over 680 px).
pub const BAR_LABEL_CHARS: usize = 110;

/// `text` cut to at most `max` characters at a word, `…` added where it was cut.
pub fn shortened(text: &str, max: usize) -> String {
    if text.chars().count() <= max {
        return text.to_string();
    }
    let mut out = String::new();
    for word in text.split(' ') {
        let next = if out.is_empty() {
            word.chars().count()
        } else {
            out.chars().count() + 1 + word.chars().count()
        };
        if next + 2 > max {
            break;
        }
        if !out.is_empty() {
            out.push(' ');
        }
        out.push_str(word);
    }
    if out.is_empty() {
        out = text.chars().take(max.saturating_sub(2)).collect();
    }
    out.push_str(" …");
    out
}

/// One point of a trend plot.
pub struct TrendPoint {
    /// Seconds since 1970 (the session's start).
    pub unix_s: f64,
    /// Value, display units.
    pub value: f64,
    /// Standard uncertainty (k = 1), display units.
    pub u: f64,
    /// The change from the point before, when the history's rule flags it
    /// ([`crate::history::changes`]): the change and its combined standard uncertainty.
    pub flagged: Option<(f64, f64)>,
}

/// A trend plot's value axis spans at least this many times the largest standard uncertainty
/// of its points: a change the history flags (beyond 2√2 u for two equal uncertainties) then
/// takes less than a third of the height, so that noise does not fill the plot and look like
/// drift.
pub const TREND_MIN_SPAN_U: f64 = 10.0;

/// The round tick step cuts the span into at most this many intervals ([`tick_step`]); the
/// axis ends are then rounded outward to the step, which adds up to two more: a trend plot has
/// 3 to 8 intervals between its value ticks.
const TREND_TICKS: f64 = 6.0;

/// The plot box of a trend plot (left, top, right, bottom), px, in a [`TREND_W`] × [`TREND_H`]
/// plot: room left for the value ticks, under it for the dates.
pub const TREND_BOX: [f64; 4] = [64.0, 24.0, TREND_W - 16.0, TREND_H - 34.0];
/// Width of a trend plot, px.
pub const TREND_W: f64 = 420.0;
/// Height of a trend plot, px.
pub const TREND_H: f64 = 200.0;

/// A round step (1, 2 or 5 × 10ᵏ) that cuts `span` into at most [`TREND_TICKS`] intervals.
pub fn tick_step(span: f64) -> f64 {
    let need = (span / TREND_TICKS).max(1e-12);
    let base = 10f64.powf(need.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * base)
        .find(|s| *s >= need * (1.0 - 1e-12))
        .unwrap_or(10.0 * base)
}

/// The value axis of a trend plot: `(low, high, step)`, the low and high ends multiples of the
/// step. It holds every ±2u bar; it spans at least [`TREND_MIN_SPAN_U`] × the largest u
/// (centred on the bars); it reaches zero when zero is no farther from the bars than their own
/// span (a parameter near zero is read against zero; one far from it keeps its detail).
pub fn trend_axis(pts: &[TrendPoint]) -> (f64, f64, f64) {
    let (mut lo, mut hi) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
        (a.min(p.value - 2.0 * p.u), b.max(p.value + 2.0 * p.u))
    });
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0, 0.2);
    }
    let u_max = pts.iter().fold(0.0f64, |a, p| a.max(p.u));
    // Without uncertainties: the spread, or (none either) a tenth of the value, or 1.
    let min_span = if u_max > 0.0 {
        TREND_MIN_SPAN_U * u_max
    } else if hi > lo {
        0.0
    } else if lo != 0.0 {
        0.1 * lo.abs()
    } else {
        1.0
    };
    if hi - lo < min_span {
        let mid = (lo + hi) / 2.0;
        (lo, hi) = (mid - min_span / 2.0, mid + min_span / 2.0);
    }
    if lo > 0.0 && lo <= hi - lo {
        lo = 0.0;
    } else if hi < 0.0 && -hi <= hi - lo {
        hi = 0.0;
    }
    let step = tick_step(hi - lo);
    // Ends on the step's multiples (a value on a multiple, to rounding, is its own end).
    ((lo / step + 1e-9).floor() * step, (hi / step - 1e-9).ceil() * step, step)
}

/// Decimals that show a step of the ticks.
fn tick_decimals(step: f64) -> usize {
    (-(step.log10() + 1e-9).floor()).max(0.0) as usize
}

/// The date (`YYYY-MM-DD`, UTC) of a time in seconds since 1970.
fn date_of(unix_s: f64) -> String {
    ballbar_model::time::format_iso8601(unix_s).get(..10).unwrap_or_default().to_string()
}

/// The date ticks over `[t0, t1]` (s since 1970): as (s, label), at most 6, on round dates
/// (whole days apart, weeks, or the first of every 1, 2, 3, 6 or 12 months).
pub fn date_ticks(t0: f64, t1: f64) -> Vec<(f64, String)> {
    use ballbar_model::time::{format_iso8601, parse_iso8601};
    let day = 86_400.0;
    let span_days = (t1 - t0) / day;
    for step in [1.0, 2.0, 7.0, 14.0] {
        if span_days / step <= 5.0 + 1e-9 {
            let first = (t0 / day / step).ceil() as i64;
            let last = (t1 / day / step).floor() as i64;
            return (first..=last)
                .map(|k| k as f64 * step * day)
                .map(|t| (t, date_of(t)))
                .collect();
        }
    }
    let months = [1, 2, 3, 6, 12, 24, 60, 120]
        .into_iter()
        .find(|m| span_days / (30.44 * *m as f64) <= 5.0)
        .unwrap_or(240);
    let start = format_iso8601(t0);
    let (mut y, mut m): (i64, i64) =
        (start[..4].parse().unwrap_or(1970), start[5..7].parse().unwrap_or(1));
    let mut out = Vec::new();
    loop {
        // The first of the month on the step's grid (months counted from year 0).
        let index = y * 12 + (m - 1);
        if index % months == 0 {
            let t = parse_iso8601(&format!("{y:04}-{m:02}-01T00:00:00Z")).unwrap_or(f64::NAN);
            if t > t1 || !t.is_finite() {
                break;
            }
            if t >= t0 {
                out.push((t, date_of(t)));
            }
        }
        m += 1;
        if m > 12 {
            (y, m) = (y + 1, 1);
        }
        if y > 9999 {
            break;
        }
    }
    out
}

/// A parameter over time: points with ±2u bars (k = 2) against the session dates, a value axis
/// with round ticks that holds every bar ([`trend_axis`]), date ticks, and the changes the
/// history flags drawn as a thick segment from the point before with the change written over it.
pub fn trend(id: &str, unit: &str, pts: &[TrendPoint]) -> String {
    let [left, top, right, bottom] = TREND_BOX;
    let (t0, t1) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.unix_s), b.max(p.unix_s)));
    // A day either side at least, and a twentieth of the span, so that no point sits on the edge.
    let pad = ((t1 - t0) / 20.0).max(86_400.0);
    let (t0, t1) = (t0 - pad, t1 + pad);
    let (v0, v1, step) = trend_axis(pts);
    let x = |t: f64| left + (t - t0) / (t1 - t0) * (right - left);
    let y = |v: f64| bottom - (v - v0) / (v1 - v0) * (bottom - top);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg class="trend" data-id="{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {TREND_W} {TREND_H}" width="{TREND_W}" height="{TREND_H}" data-left="{left}" data-top="{top}" data-right="{right}" data-bottom="{bottom}" data-low="{v0}" data-high="{v1}">"#,
        esc(id)
    );
    let _ = write!(s, "<title>{} ({})</title>", esc(id), esc(unit));
    let _ =
        write!(s, r#"<text class="label" x="4" y="14">{} ({}), ±2u</text>"#, esc(id), esc(unit));
    let decimals = tick_decimals(step);
    let n = ((v1 - v0) / step).round() as i64;
    for k in 0..=n {
        let v = v0 + k as f64 * step;
        let class = if v.abs() < step * 1e-9 { "grid zero" } else { "grid" };
        let _ = write!(
            s,
            r#"<line class="{class}" data-tick="{v}" x1="{left}" y1="{0:.1}" x2="{right}" y2="{0:.1}"/><text class="tick" text-anchor="end" x="{1}" y="{2:.1}">{v:.decimals$}</text>"#,
            y(v),
            left - 4.0,
            y(v) + 4.0
        );
    }
    for (t, label) in date_ticks(t0, t1) {
        let _ = write!(
            s,
            r#"<line class="grid date" data-date="{label}" x1="{0:.1}" y1="{top}" x2="{0:.1}" y2="{bottom}"/><text class="tick" style="font-size:9.5px" text-anchor="middle" x="{0:.1}" y="{1}">{label}</text>"#,
            x(t),
            bottom + 14.0
        );
    }
    let _ = write!(
        s,
        r#"<rect class="frame" x="{left}" y="{top}" width="{}" height="{}"/>"#,
        right - left,
        bottom - top
    );
    let mut line = String::new();
    for (k, p) in pts.iter().enumerate() {
        let (px, py) = (x(p.unix_s), y(p.value));
        let _ = write!(line, "{}{px:.1} {py:.1}", if k == 0 { "M" } else { " L" });
    }
    let _ = write!(s, r#"<path class="trend-line" d="{line}"/>"#);
    for (k, p) in pts.iter().enumerate() {
        let Some((change, u_c)) = p.flagged else { continue };
        let Some(before) = k.checked_sub(1).map(|j| &pts[j]) else { continue };
        let (xa, ya, xb, yb) = (x(before.unix_s), y(before.value), x(p.unix_s), y(p.value));
        let _ = write!(
            s,
            r##"<line class="change flagged" data-from-date="{}" data-to-date="{}" data-change="{change}" data-combined-u="{u_c}" stroke="#d35400" stroke-width="3" stroke-opacity="0.7" x1="{xa:.1}" y1="{ya:.1}" x2="{xb:.1}" y2="{yb:.1}"/>"##,
            date_of(before.unix_s),
            date_of(p.unix_s)
        );
        let d = tick_decimals(step) + 1;
        let _ = write!(
            s,
            r##"<text class="change-label" fill="#d35400" text-anchor="middle" x="{:.1}" y="{:.1}">{change:+.d$}</text>"##,
            ((xa + xb) / 2.0).clamp(left + 20.0, right - 20.0),
            (ya.min(yb) - 6.0).max(top + 10.0)
        );
    }
    for p in pts {
        let (px, py) = (x(p.unix_s), y(p.value));
        let _ = write!(
            s,
            r#"<line class="errorbar" x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}"/>"#,
            y(p.value - 2.0 * p.u),
            y(p.value + 2.0 * p.u)
        );
        let _ = write!(
            s,
            r#"<circle class="point" data-value="{}" data-u="{}" data-date="{}" data-flagged="{}" cx="{px:.1}" cy="{py:.1}" r="3"/>"#,
            p.value,
            p.u,
            date_of(p.unix_s),
            p.flagged.is_some()
        );
    }
    s.push_str("</svg>");
    s
}

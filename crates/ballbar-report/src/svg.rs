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
//! θ the rotary axis's coordinate ([`Angles::Rotary`]).
//!
//! # The Cartesian plot
//! A partial sweep of a rotary axis: ΔR up at the same µm per division ([`N_DIV`] divisions
//! each side of the zero line), the axis's coordinate along x from the sweep's least angle at
//! the box's left edge ([`CART_BOX`]) to its greatest at the right edge.

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
    [1.0, 2.0, 5.0, 10.0].iter().map(|m| m * base).find(|s| *s >= need * (1.0 - 1e-12)).unwrap_or(10.0 * base)
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
}

/// A highlighted arc (where the gap lies).
pub struct Arc {
    /// From, degrees (counter-clockwise to `to_deg`).
    pub from_deg: f64,
    /// To, degrees.
    pub to_deg: f64,
    /// Direction of the runs it belongs to (`CW`, `CCW`).
    pub direction: String,
    /// Its share of the gap.
    pub share: f64,
}

/// What a polar plot's angle is, and how its directions are labelled.
pub enum Angles<'a> {
    /// The angle in a plane: its axes' names (right, up), labelled `+X`, `+Y`.
    Plane(&'a str, &'a str),
    /// A rotary axis's coordinate (its name): `C 0°` right, `C 90°` up, `180°` left, `270°`
    /// down, each label inside the plot.
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
}

/// The point of a deviation at an angle.
pub fn point(theta: f64, value_um: f64, scale_um: f64) -> (f64, f64) {
    let r = (R0 + value_um / scale_um * DIV).clamp(2.0, C - 2.0);
    (C + r * theta.cos(), C - r * theta.sin())
}

/// The SVG of a polar plot.
pub fn polar(p: &Polar<'_>) -> String {
    let mut s = String::new();
    let axis = match p.angles {
        Angles::Rotary(a) => format!(r#" data-axis="{}""#, esc(a)),
        Angles::Plane(..) => String::new(),
    };
    let _ = write!(s, r#"<svg class="{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {SIZE} {}" width="{SIZE}" height="{}" data-scale-um="{}" data-r0="{R0}" data-div="{DIV}" data-cx="{C}" data-cy="{C}"{axis}>"#, p.class, SIZE + 24.0, SIZE + 24.0, p.scale_um);
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
    match p.angles {
        Angles::Plane(u, v) => {
            let _ = write!(s, r#"<text class="axis" x="{}" y="{}">+{}</text>"#, SIZE - 16.0, C - 4.0, esc(u));
            let _ = write!(s, r#"<text class="axis" x="{}" y="12">+{}</text>"#, C + 4.0, esc(v));
        }
        Angles::Rotary(a) => {
            let a = esc(a);
            let _ = write!(s, r#"<text class="axis" text-anchor="end" x="{}" y="{}">{a} 0°</text>"#, SIZE - 2.0, C - 4.0);
            let _ = write!(s, r#"<text class="axis" x="{}" y="12">{a} 90°</text>"#, C + 4.0);
            // Under its spoke, so that it does not read on with the 0° label of a plot beside it.
            let _ = write!(s, r#"<text class="axis" x="2" y="{}">180°</text>"#, C + 14.0);
            let _ = write!(s, r#"<text class="axis" x="{}" y="{}">270°</text>"#, C + 4.0, SIZE + 4.0);
        }
    }
    for a in &p.arcs {
        let r = R0 + (N_DIV as f64 + 0.35) * DIV;
        let (a0, a1) = (a.from_deg.to_radians(), a.to_deg.to_radians());
        let span = (a.to_deg - a.from_deg).rem_euclid(360.0);
        let (x0, y0) = (C + r * a0.cos(), C - r * a0.sin());
        let (x1, y1) = (C + r * a1.cos(), C - r * a1.sin());
        // Counter-clockwise on the page (y down): sweep flag 0.
        let _ = write!(
            s,
            r#"<path class="where {}" data-from-deg="{}" data-to-deg="{}" data-share="{}" d="M {x0:.1} {y0:.1} A {r} {r} 0 {} 0 {x1:.1} {y1:.1}"/>"#,
            esc(&a.direction.to_lowercase()),
            a.from_deg,
            a.to_deg,
            a.share,
            u8::from(span > 180.0)
        );
    }
    trace_paths(&mut s, &p.traces, |theta, v| point(theta, v, p.scale_um));
    let _ = write!(s, r#"<text class="caption" x="4" y="{}">{}</text>"#, SIZE + 18.0, esc(&format!("{} µm/div", fmt_scale(p.scale_um))));
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
}

/// A step of the angle ticks, degrees: at most 8 intervals over `span`.
fn angle_step(span: f64) -> f64 {
    [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0].into_iter().find(|s| span / s <= 8.0 + 1e-9).unwrap_or(360.0)
}

/// The SVG of a Cartesian plot: the box, ΔR at `scale_um` per division from -[`N_DIV`] to
/// +[`N_DIV`] divisions (the zero line bold), the angle from `range_deg.0` at the box's left
/// edge to `range_deg.1` at its right, ticks and labels with units, the scale stated. Every
/// point is inside the box (a deviation beyond the last division is drawn on the box's edge,
/// which the scale's choice prevents).
pub fn cartesian(p: &Cartesian<'_>) -> String {
    let [left, top, right, bottom] = CART_BOX;
    let (from, to) = if p.range_deg.1 > p.range_deg.0 { p.range_deg } else { (p.range_deg.0 - 1.0, p.range_deg.0 + 1.0) };
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
        let _ = write!(s, r#"<line class="{class}" x1="{left}" y1="{yk:.2}" x2="{right}" y2="{yk:.2}"/>"#);
        let label = if k == 0 { "0".to_string() } else { format!("{}{}", if k > 0 { "+" } else { "-" }, fmt_scale(k.unsigned_abs() as f64 * p.scale_um)) };
        let _ = write!(s, r#"<text class="tick" text-anchor="end" x="{}" y="{:.2}">{label}</text>"#, left - 4.0, yk + 4.0);
    }
    let step = angle_step(to - from);
    let first = (from / step - 1e-9).ceil() as i64;
    let last = (to / step + 1e-9).floor() as i64;
    for k in first..=last {
        let deg = k as f64 * step;
        let xk = x(deg);
        let _ = write!(s, r#"<line class="grid angle" data-deg="{deg}" x1="{xk:.2}" y1="{top}" x2="{xk:.2}" y2="{bottom}"/>"#);
        let _ = write!(s, r#"<text class="tick" text-anchor="middle" x="{xk:.2}" y="{}">{deg}°</text>"#, bottom + 14.0);
    }
    let _ = write!(s, r#"<rect class="frame" x="{left}" y="{top}" width="{}" height="{}"/>"#, right - left, bottom - top);
    trace_paths(&mut s, &p.traces, |theta, v| (x(theta.to_degrees()), y(v)));
    let _ = write!(s, r#"<text class="axis-label" text-anchor="middle" x="{}" y="{}">{} (°)</text>"#, (left + right) / 2.0, bottom + 32.0, esc(p.axis));
    let _ = write!(s, r#"<text class="axis-label" text-anchor="middle" transform="rotate(-90 14 {mid})" x="14" y="{mid}">ΔR (µm)</text>"#);
    let _ = write!(
        s,
        r#"<text class="caption" x="4" y="{}">{}</text>"#,
        CART_H - 6.0,
        esc(&format!("ΔR {} µm/div; {} {}°/div", fmt_scale(p.scale_um), p.axis, step))
    );
    s.push_str("</svg>");
    s
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
/// 100 %.
pub fn shrink_bars(bars: &[Bar]) -> String {
    let (w, label_w, row) = (680.0, 260.0, 26.0);
    let h = row * bars.len() as f64 + 30.0;
    let x = |f: f64| label_w + f.clamp(0.0, 1.0) * (w - label_w - 50.0);
    let mut s = String::new();
    let _ = write!(s, r#"<svg class="shrink-bars" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">"#);
    for pct in [0.0, 0.25, 0.5, 0.75, 1.0] {
        let _ = write!(s, r#"<line class="grid" x1="{0:.1}" y1="4" x2="{0:.1}" y2="{1}"/><text class="tick" x="{0:.1}" y="{2}">{3:.0} %</text>"#, x(pct), h - 22.0, h - 8.0, pct * 100.0);
    }
    for (k, b) in bars.iter().enumerate() {
        let y = 6.0 + k as f64 * row;
        let _ = write!(s, r#"<text class="label" x="4" y="{:.1}">{}</text>"#, y + 14.0, esc(&b.label));
        let _ = write!(s, r#"<rect class="bar" data-shrink="{}" x="{label_w}" y="{y:.1}" width="{:.1}" height="{}"/>"#, b.value, x(b.value) - label_w, row - 8.0);
        let ym = y + (row - 8.0) / 2.0;
        let _ = write!(s, r#"<line class="interval" x1="{:.1}" y1="{ym:.1}" x2="{:.1}" y2="{ym:.1}"/>"#, x(b.interval[0]), x(b.interval[1]));
    }
    s.push_str("</svg>");
    s
}

/// One point of a trend plot.
pub struct TrendPoint {
    /// Days since 1970.
    pub day: f64,
    /// Date label.
    pub label: String,
    /// Value and standard uncertainty, display units.
    pub value: f64,
    /// Standard uncertainty.
    pub u: f64,
}

/// A parameter over time: points with ±2u bars (k = 2), dates along x.
pub fn trend(id: &str, unit: &str, pts: &[TrendPoint]) -> String {
    let (w, h, m) = (420.0, 180.0, 44.0);
    let (d0, d1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.day), b.max(p.day)));
    let (v0, v1) = pts.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.value - 2.0 * p.u), b.max(p.value + 2.0 * p.u)));
    let pad = ((v1 - v0) * 0.1).max(1e-9);
    let (v0, v1) = (v0 - pad, v1 + pad);
    let x = |d: f64| if d1 > d0 { m + (d - d0) / (d1 - d0) * (w - 2.0 * m) } else { w / 2.0 };
    let y = |v: f64| h - 28.0 - (v - v0) / (v1 - v0) * (h - 40.0);
    let mut s = String::new();
    let _ = write!(s, r#"<svg class="trend" data-id="{}" xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}">"#, esc(id));
    let _ = write!(s, "<title>{} ({})</title>", esc(id), esc(unit));
    let _ = write!(s, r#"<text class="label" x="4" y="14">{} ({})</text>"#, esc(id), esc(unit));
    for v in [v0 + pad, v1 - pad] {
        let _ = write!(s, r#"<line class="grid" x1="{m}" y1="{0:.1}" x2="{1}" y2="{0:.1}"/><text class="tick" x="2" y="{2:.1}">{3:.3}</text>"#, y(v), w - m, y(v) + 4.0, v);
    }
    let mut line = String::new();
    for (k, p) in pts.iter().enumerate() {
        let (px, py) = (x(p.day), y(p.value));
        let _ = write!(line, "{}{px:.1} {py:.1}", if k == 0 { "M" } else { " L" });
        let _ = write!(s, r#"<line class="errorbar" x1="{px:.1}" y1="{:.1}" x2="{px:.1}" y2="{:.1}"/>"#, y(p.value - 2.0 * p.u), y(p.value + 2.0 * p.u));
        let _ = write!(s, r#"<circle class="point" data-value="{}" data-u="{}" cx="{px:.1}" cy="{py:.1}" r="3"/>"#, p.value, p.u);
        let _ = write!(s, r#"<text class="tick" x="{:.1}" y="{}">{}</text>"#, px - 28.0, h - 8.0, esc(&p.label));
    }
    let _ = write!(s, r#"<path class="trend-line" d="{line}"/>"#);
    s.push_str("</svg>");
    s
}

//! The page's section for the rotary-axis tests of a five-axis session (`<section id="rotary">`,
//! present only when the session has rotary runs): runs of `plane: free` in which rotary axes
//! turn and X, Y, Z follow so that the bar stays fixed on the table
//! (`ballbar_model::path::RotaryTest`).
//!
//! - Per test (CW and CCW overlaid, like the planar pairs): ΔR against the coordinate of the
//!   turning axis, a polar plot for a full turn (at least [`FULL_TURN_DEG`]) and a Cartesian
//!   plot for a partial sweep, measured with the model over it and the residual after the
//!   model; every measured plot of the section at one µm/division and every plot after the
//!   model at another (stated once), so that the tests compare by eye; each run's start and
//!   direction of travel marked; the diagnosis's `where` entries of a run (by its name, in its
//!   turning axis's degrees) drawn along its measured trace. With two axes turning the run is
//!   drawn against the one that sweeps the most (a run file does not record which axis the test
//!   named first; in the shipped BK4 tests that is the first). Nothing is taken out of a rotary trace: the bar
//!   stays fixed on the table, so the set-up shows only as a constant (the ball's offset along
//!   the bar), and a first harmonic in the angle is the axis line's own offset or tilt.
//! - The bar's direction (radial, tangential, axial to the plotted axis) is read from the run's
//!   geometry, the nominal chain at its first sample, within [`BAR_TOLERANCE_DEG`]; otherwise
//!   the run is called a rotary run.
//! - `location-errors`: every ISO 230-7 location error (`E<d>0<k>`) grouped by rotary axis, with
//!   its value, standard uncertainty and unit where the runs determine it, the choices it holds
//!   for, and for the others the gauge or the combination that explains why not.
//! - `rotary-notes`: the fit's choices that concern the rotary axes, in plain words.

use std::fmt::Write;

use ballbar_documents::diagnosis::{Diagnosis, Where};
use ballbar_fit::gauge::AXIS_AT_REST_RAD;
use ballbar_fit::{Fit, Gauge, GaugeKind, NullCombination};
use ballbar_model::machine::Model;
use ballbar_model::{Axis, Direction, Plane, Run};

use crate::fit_report::{fixed_by, null_hint};
use crate::svg::{self, Angles, Arc, Cartesian, Polar, Trace, esc, nice_scale};

/// A sweep of at least this is a full turn, drawn as a polar plot, degrees.
pub const FULL_TURN_DEG: f64 = 359.0;

/// The bar is radial, tangential or axial when within this of that direction, degrees: a
/// set-up a few degrees off is still that test; the shipped tests are exact.
pub const BAR_TOLERANCE_DEG: f64 = 5.0;

/// A radial or tangential direction needs the table ball this far from the axis line, mm
/// (`ballbar_model::path::MIN_ARM_MM`).
const MIN_ARM_MM: f64 = 1.0;

/// How the bar lies relative to the plotted axis's line at the run's first sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Bar {
    Radial,
    Tangential,
    Axial,
}

impl Bar {
    fn name(self) -> &'static str {
        match self {
            Bar::Radial => "radial",
            Bar::Tangential => "tangential",
            Bar::Axial => "axial",
        }
    }
}

/// A rotary run as the page draws it.
pub(crate) struct RotaryRun {
    /// Its index in the session.
    pub index: usize,
    /// The turning axes with their coordinate's least and greatest value, degrees; the plotted
    /// one (the largest sweep) first.
    pub turning: Vec<(Axis, f64, f64)>,
    /// The other rotary axes of the run with their angle, degrees.
    pub held: Vec<(Axis, f64)>,
    /// The plotted axis's sense: CCW when its coordinate increases.
    pub sense: Direction,
    /// The bar's direction, when it is one of the three.
    pub bar: Option<Bar>,
}

impl RotaryRun {
    /// The plotted axis.
    pub fn axis(&self) -> Axis {
        self.turning[0].0
    }

    /// Its least and greatest coordinate, degrees.
    pub fn range_deg(&self) -> (f64, f64) {
        (self.turning[0].1, self.turning[0].2)
    }
}

/// The run's rotary description: `None` for a planar run, or a free run in which no rotary
/// axis turns.
pub(crate) fn rotary_run(model: &Model, run: &Run, index: usize) -> Option<RotaryRun> {
    if run.header.plane != Plane::Free || run.is_empty() {
        return None;
    }
    let mut turning = Vec::new();
    let mut held = Vec::new();
    for a in Axis::ALL.into_iter().filter(|a| a.is_rotary()) {
        let Some(c) = run.axis(a) else { continue };
        let (lo, hi) =
            c.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| (l.min(x), h.max(x)));
        if hi - lo > AXIS_AT_REST_RAD {
            turning.push((a, run_file_deg(lo), run_file_deg(hi)));
        } else {
            held.push((a, c[0].to_degrees()));
        }
    }
    // The largest sweep first; a stable sort keeps axis order between equal sweeps.
    turning.sort_by(|a, b| (b.2 - b.1).total_cmp(&(a.2 - a.1)));
    let &(axis, ..) = turning.first()?;
    let c = run.axis(axis)?;
    let sense = if c[c.len() - 1] >= c[0] { Direction::CCW } else { Direction::CW };
    Some(RotaryRun { index, bar: bar_direction(model, run, axis), turning, held, sense })
}

/// An angle in degrees as a run file gives it (to 1e-6°: `ballbar_model::path::ANGLE_RESOLUTION_DEG`),
/// so that a sweep to 30° is 30°, not 29.999999999999996° after the trip through radians.
fn run_file_deg(rad: f64) -> f64 {
    (rad.to_degrees() * 1e6).round() / 1e6
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn unit(a: [f64; 3], min_norm: f64) -> Option<[f64; 3]> {
    let n = dot(a, a).sqrt();
    (n >= min_norm && n.is_finite()).then(|| [a[0] / n, a[1] / n, a[2] / n])
}

/// The bar against `axis`'s line at the run's first sample, from the nominal chain: axial
/// along the line, radial along the perpendicular from it through the table ball, tangential
/// across both.
fn bar_direction(model: &Model, run: &Run, axis: Axis) -> Option<Bar> {
    let chain = &model.chain;
    let mut q = [0.0; 6];
    for a in Axis::ALL {
        if let Some(c) = run.axis(a) {
            q[a.index()] = *c.first()?;
        }
    }
    let h = &run.header;
    let balls = chain.ball_setup(&h.pivot_mm, &h.tool_ball_mm);
    let pose = chain.pose(&q, &balls, None, None);
    // The frame after a rotary joint's nominal motion has its origin on the axis line and the
    // joint's direction along it.
    let (frame, joint) = match chain.tool.iter().position(|j| j.axis == axis) {
        Some(j) => (pose.base_from_tool_joint[j], &chain.tool[j]),
        None => {
            let j = chain.workpiece.iter().position(|j| j.axis == axis)?;
            (pose.base_from_work_joint[j], &chain.workpiece[j])
        }
    };
    let d = frame.rotation * joint.direction;
    let line = unit([d.x, d.y, d.z], 1e-12)?;
    let c = frame.translation.vector;
    let centre = [c.x, c.y, c.z];
    let table = [pose.table_ball.x, pose.table_ball.y, pose.table_ball.z];
    let tool = [pose.tool_ball.x, pose.tool_ball.y, pose.tool_ball.z];
    let bar = unit(sub(tool, table), 1e-9)?;
    let cos = BAR_TOLERANCE_DEG.to_radians().cos();
    if dot(bar, line).abs() >= cos {
        return Some(Bar::Axial);
    }
    let arm = sub(table, centre);
    let along = dot(arm, line);
    let radial = unit(sub(arm, [line[0] * along, line[1] * along, line[2] * along]), MIN_ARM_MM)?;
    if dot(bar, radial).abs() >= cos {
        Some(Bar::Radial)
    } else if dot(bar, cross(line, radial)).abs() >= cos {
        Some(Bar::Tangential)
    } else {
        None
    }
}

/// An angle for a title: whole degrees when it is one, else to 0.1°.
fn deg(x: f64) -> String {
    if (x - x.round()).abs() < 0.05 { format!("{:.0}", x.round() + 0.0) } else { format!("{x:.1}") }
}

/// Two sweeps of one test cover the same angles to within this share of the sweep, or a
/// degree: a run's last sample falls short of the sweep's end by up to a sample's step
/// (0.1° at 50 Hz in the shipped tests), at the start or the end depending on the sense.
const SAME_SWEEP: f64 = 0.01;

/// The runs that make one figure: a CW run with the first unused CCW run of the same test
/// (the same turning axes over the same angles, held axes, bar, balls, radius and feed), then
/// the lone runs; ordered by the number of turning axes, the plotted axis, the first run.
fn groups(runs: &[Run], rotary: &[RotaryRun]) -> Vec<Vec<usize>> {
    let key = |r: &RotaryRun| {
        let h = &runs[r.index].header;
        let turning: Vec<Axis> = r.turning.iter().map(|t| t.0).collect();
        let held: Vec<String> = r.held.iter().map(|(a, x)| format!("{a}{x:.2}")).collect();
        format!(
            "{turning:?}{held:?}{:?}{:?}{:?}{:?}{}{}",
            r.bar, h.pivot_mm, h.table_ball_mm, h.tool_ball_mm, h.radius_mm, h.feed_mm_per_min
        )
    };
    let same_sweep = |a: &RotaryRun, b: &RotaryRun| {
        a.turning.iter().zip(&b.turning).all(|(&(_, lo, hi), &(_, lo2, hi2))| {
            let tol = (SAME_SWEEP * (hi - lo).abs().max((hi2 - lo2).abs())).max(1.0);
            (lo - lo2).abs() <= tol && (hi - hi2).abs() <= tol
        })
    };
    let keys: Vec<String> = rotary.iter().map(key).collect();
    let mut used = vec![false; rotary.len()];
    let mut out = Vec::new();
    for i in 0..rotary.len() {
        if used[i] || rotary[i].sense != Direction::CW {
            continue;
        }
        if let Some(j) = (0..rotary.len()).find(|&j| {
            !used[j]
                && rotary[j].sense == Direction::CCW
                && keys[j] == keys[i]
                && same_sweep(&rotary[i], &rotary[j])
        }) {
            used[i] = true;
            used[j] = true;
            out.push(vec![i, j]);
        }
    }
    out.extend((0..rotary.len()).filter(|&i| !used[i]).map(|i| vec![i]));
    out.sort_by_key(|g| {
        (rotary[g[0]].turning.len(), rotary[g[0]].axis(), g.iter().map(|&i| rotary[i].index).min())
    });
    out
}

/// The title of a figure: the turning axes and their angles, the axes held, the bar, the
/// ball's height, radius and feed.
pub(crate) fn title(run: &Run, r: &RotaryRun, range: (f64, f64)) -> String {
    let axis = r.axis();
    let mut what = if r.turning.len() == 1 {
        format!("{axis} turning over {}…{}°", deg(range.0), deg(range.1))
    } else {
        let names: Vec<&str> = r.turning.iter().map(|t| t.0.name()).collect();
        let spans: Vec<String> = r
            .turning
            .iter()
            .map(|(a, lo, hi)| format!("{a} over {}…{}°", deg(*lo), deg(*hi)))
            .collect();
        format!(
            "{} turning together ({}), drawn against {axis}",
            names.join(" and "),
            spans.join(", ")
        )
    };
    for (a, x) in &r.held {
        let _ = write!(what, ", {a} at {}°", deg(*x));
    }
    let bar = match r.bar {
        Some(b) if r.turning.len() == 1 => format!("{} bar", b.name()),
        Some(b) => format!("{} bar (to {axis})", b.name()),
        None => format!("rotary run (the bar neither radial, tangential nor axial to {axis})"),
    };
    let h = &run.header;
    format!(
        "{what}, {bar}, ball at pivot Z {} mm ({} mm up in the table frame), R {} mm, F {} mm/min",
        h.pivot_mm[2], h.table_ball_mm[2], h.radius_mm, h.feed_mm_per_min
    )
}

fn trace_class(what: &str, sense: Direction) -> &'static str {
    match (what, sense) {
        ("measured", Direction::CW) => "trace measured cw",
        ("measured", Direction::CCW) => "trace measured ccw",
        ("model", Direction::CW) => "trace model cw",
        ("model", Direction::CCW) => "trace model ccw",
        (_, Direction::CW) => "trace residual cw",
        (_, Direction::CCW) => "trace residual ccw",
    }
}

/// One run's curves, µm: measured, model (measured minus residual), residual.
struct Curves {
    r: usize,
    name: String,
    theta: Vec<f64>,
    measured: Vec<f64>,
    model: Vec<f64>,
    residual: Vec<f64>,
}

/// The section: nothing when the session has no rotary run. `diag` is the archived diagnosis:
/// its `where` entries of a rotary run are drawn along that run's trace.
pub(crate) fn section(
    h: &mut String,
    model: &Model,
    runs: &[Run],
    f: &Fit,
    diag: Option<&Diagnosis>,
) {
    let rotary: Vec<RotaryRun> =
        runs.iter().enumerate().filter_map(|(i, run)| rotary_run(model, run, i)).collect();
    if rotary.is_empty() {
        return;
    }
    let figures: Vec<Figure> =
        groups(runs, &rotary).into_iter().map(|g| Figure::new(runs, f, &rotary, g)).collect();
    // One scale for every measured plot and one for every plot after the model, polar and
    // Cartesian alike: the largest any of them needs, so that the tests compare by eye.
    let curves = || figures.iter().flat_map(|fig| &fig.curves);
    let raw_scale =
        nice_scale(crate::cells::max_abs(curves().flat_map(|c| [&c.measured, &c.model])));
    let res_scale = nice_scale(crate::cells::max_abs(curves().map(|c| &c.residual)));
    let _ = write!(
        h,
        r#"<section id="rotary"><h2>Rotary-axis tests</h2><p>ΔR of each rotary run (a rotary axis turning, X, Y and Z following so that the bar stays fixed on the table) against the coordinate of its turning axis; with two axes turning, against the one that sweeps the most. A full turn (at least {FULL_TURN_DEG}°) is a polar plot, the coordinate counter-clockwise from the right (0° right, 90° up), ΔR outward from the bold ring at the stated µm/division as in the planar plots; a partial sweep is ΔR against the angle in degrees at the same µm/division. Left: measured (solid) with the model's prediction (dashed); right: after the model. CW blue, CCW red: CCW is the plotted axis's coordinate increasing. Each run's first sample is marked <i>start</i>, and an arrow shows its direction of travel (inside the innermost ring of a polar plot, at the top of a Cartesian one). Highlighted arcs: where the diagnosis places the gap, along the trace of the run it concerns. Nothing is taken out of these traces: the bar stays fixed on the table, so the set-up shows only as a constant (the ball's offset along the bar), and a first harmonic in the angle is the axis line's offset or tilt itself. The bar's direction is read from each run's geometry (the nominal chain at its first sample, within {BAR_TOLERANCE_DEG}°), not from its name.</p>"#
    );
    let _ = write!(
        h,
        r#"<p class="scales" data-raw-scale-um="{raw_scale}" data-after-scale-um="{res_scale}">Scales, the same on every rotary test so that they compare by eye: measured and model at <b>{} µm/div</b>, after the model at <b>{} µm/div</b>.</p>"#,
        svg::fmt_scale(raw_scale),
        svg::fmt_scale(res_scale)
    );
    let where_: &[Where] = diag.map_or(&[], |d| &d.gap.where_);
    for fig in &figures {
        fig.draw(h, runs, &rotary, (raw_scale, res_scale), where_);
    }
    let free_only: Vec<String> = runs
        .iter()
        .enumerate()
        .filter(|(i, run)| run.header.plane == Plane::Free && !rotary.iter().any(|r| r.index == *i))
        .map(|(_, run)| run.name())
        .collect();
    if !free_only.is_empty() {
        let _ = write!(
            h,
            r#"<p class="na" id="free-not-rotary">Free runs in which no rotary axis turns (not drawn: there is no angle to draw them against): {}.</p>"#,
            esc(&free_only.join(", "))
        );
    }
    location_errors(h, model, f);
    notes(h, f);
    h.push_str("</section>");
}

/// One figure of the section: a test's runs (indices into the rotary runs), their plotted
/// axis and the range of its coordinate, degrees.
struct Figure {
    g: Vec<usize>,
    axis: Axis,
    range: (f64, f64),
    curves: Vec<Curves>,
}

impl Figure {
    fn new(runs: &[Run], f: &Fit, rotary: &[RotaryRun], g: Vec<usize>) -> Figure {
        let axis = rotary[g[0]].axis();
        let range = g
            .iter()
            .map(|&i| rotary[i].range_deg())
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (lo, hi)| (a.min(lo), b.max(hi)));
        let curves = g
            .iter()
            .map(|&i| {
                let r = rotary[i].index;
                let run = &runs[r];
                Curves {
                    r: i,
                    name: run.name(),
                    theta: run.axis(axis).expect("a turning axis has its column").to_vec(),
                    measured: run.dr_mm.iter().map(|x| x * 1e3).collect(),
                    model: run
                        .dr_mm
                        .iter()
                        .zip(&f.residuals[r])
                        .map(|(x, e)| (x - e) * 1e3)
                        .collect(),
                    residual: f.residuals[r].iter().map(|x| x * 1e3).collect(),
                }
            })
            .collect();
        Figure { g, axis, range, curves }
    }

    /// Whether the figure is a polar plot (a full turn).
    fn full(&self) -> bool {
        self.range.1 - self.range.0 >= FULL_TURN_DEG
    }

    /// The gap's arcs on this figure: the `where` entries of its runs (by run name) about its
    /// plotted axis, except one that covers the whole turn or the whole sweep (the run's own
    /// entry: the gap spread over it).
    fn arcs(&self, where_: &[Where]) -> Vec<Arc> {
        let full = self.full();
        let mut arcs = Vec::new();
        for c in &self.curves {
            for w in where_.iter().filter(|w| {
                w.plane == Plane::Free.name()
                    && w.run.as_deref() == Some(c.name.as_str())
                    && w.axis.as_deref() == Some(self.axis.name())
            }) {
                let [a, b] = w.sector_deg;
                let whole = if full {
                    a == 0.0 && b == 360.0
                } else {
                    a <= self.range.0 + 1e-6 && b >= self.range.1 - 1e-6
                };
                if !(a.is_finite() && b.is_finite()) || whole {
                    continue;
                }
                arcs.push(Arc {
                    from_deg: a,
                    to_deg: b,
                    wrap: full,
                    direction: if w.direction.is_empty() {
                        "-".into()
                    } else {
                        w.direction.clone()
                    },
                    run: c.name.clone(),
                    share: w.share,
                });
            }
        }
        arcs
    }

    fn draw(
        &self,
        h: &mut String,
        runs: &[Run],
        rotary: &[RotaryRun],
        (raw_scale, res_scale): (f64, f64),
        where_: &[Where],
    ) {
        let first = &rotary[self.g[0]];
        let (axis, range, full) = (self.axis, self.range, self.full());
        let names: Vec<String> = self
            .curves
            .iter()
            .map(|c| format!("{} {}", c.name, rotary[c.r].sense.name()))
            .collect();
        let title = format!("{}: {}", title(&runs[first.index], first, range), names.join(" / "));
        let mut raw = Vec::new();
        let mut after = Vec::new();
        for c in &self.curves {
            let sense = rotary[c.r].sense;
            raw.push(Trace {
                class: trace_class("measured", sense),
                run: &c.name,
                theta: &c.theta,
                value_um: &c.measured,
                mark_start: true,
            });
            raw.push(Trace {
                class: trace_class("model", sense),
                run: &c.name,
                theta: &c.theta,
                value_um: &c.model,
                mark_start: false,
            });
            after.push(Trace {
                class: trace_class("residual", sense),
                run: &c.name,
                theta: &c.theta,
                value_um: &c.residual,
                mark_start: true,
            });
        }
        let arcs = self.arcs(where_);
        let run_ids: Vec<&str> = self.curves.iter().map(|c| c.name.as_str()).collect();
        let _ = write!(
            h,
            r#"<figure class="rotary-pair" data-runs="{}" data-axis="{axis}" data-plot="{}" data-bar="{}" data-from-deg="{}" data-to-deg="{}">"#,
            esc(&run_ids.join(",")),
            if full { "polar" } else { "cartesian" },
            first.bar.map_or("unknown", Bar::name),
            range.0,
            range.1
        );
        let (raw_title, after_title) =
            (format!("{title}: measured and model"), format!("{title}: after the model"));
        if full {
            let angles = |a: Axis| Angles::Rotary(a.name());
            h.push_str(&svg::polar(&Polar {
                class: "rotary-polar raw",
                title: raw_title,
                angles: angles(axis),
                scale_um: raw_scale,
                traces: raw,
                arcs,
                legend: vec![],
                keys: vec![],
            }));
            h.push_str(&svg::polar(&Polar {
                class: "rotary-polar after",
                title: after_title,
                angles: angles(axis),
                scale_um: res_scale,
                traces: after,
                arcs: vec![],
                legend: vec![],
                keys: vec![],
            }));
        } else {
            h.push_str(&svg::cartesian(&Cartesian {
                class: "rotary-cartesian raw",
                title: raw_title,
                axis: axis.name(),
                range_deg: range,
                scale_um: raw_scale,
                traces: raw,
                arcs,
            }));
            h.push_str(&svg::cartesian(&Cartesian {
                class: "rotary-cartesian after",
                title: after_title,
                axis: axis.name(),
                range_deg: range,
                scale_um: res_scale,
                traces: after,
                arcs: vec![],
            }));
        }
        let _ = write!(
            h,
            "<figcaption>{}: measured (solid) and model (dashed); after the model. CW blue, CCW red (the sense of {axis}).</figcaption></figure>",
            esc(&title)
        );
    }
}

/// The direction `d` and the rotary axis `k` of an ISO 230-7 location error id `E<d>0<k>`.
pub(crate) fn location_parts(id: &str) -> Option<(Axis, Axis)> {
    let b = id.as_bytes();
    if !(id.is_ascii() && b.len() == 4 && b[0] == b'E' && b[2] == b'0') {
        return None;
    }
    Some((Axis::from_name(&id[1..2])?, Axis::from_name(&id[3..4]).filter(|k| k.is_rotary())?))
}

/// The rotary axis of a location error id.
pub(crate) fn location_axis(id: &str) -> Option<Axis> {
    location_parts(id).map(|p| p.1)
}

/// The machine parameters that are location errors, with their axis.
fn location_params(f: &Fit) -> Vec<(usize, Axis)> {
    (0..f.n_machine).filter_map(|i| location_axis(&f.parameters[i].id).map(|k| (i, k))).collect()
}

/// A gauge's choice in a few words, with its kind.
fn choice_short(f: &Fit, g: &Gauge) -> String {
    let ids = |cols: &[usize]| {
        cols.iter().map(|&j| f.parameters[j].id.as_str()).collect::<Vec<_>>().join(", ")
    };
    let text = match g.kind {
        GaugeKind::BarLength => "the bar at its nominal length (BAR = 0)".to_string(),
        GaugeKind::CommonLag => format!("the mean lag of {} taken as 0", ids(&g.parameters)),
        GaugeKind::Weak => "0 along a weakly determined combination".to_string(),
        GaugeKind::AcrossBar => "the table ball's offset across the bar taken as 0".to_string(),
        _ => format!("{} taken as 0", ids(&g.parameters)),
    };
    format!("{text} ({})", g.kind.name())
}

/// True when a gauge fixes one of the combination's parameters: the choice settles it.
fn settled(f: &Fit, c: &NullCombination) -> bool {
    c.components.iter().any(|&(i, _)| fixed_by(f, i).is_some())
}

/// A combination the runs cannot separate: its machine parameters with their amounts, how many
/// runs' set-ups take part, and the test that would separate it.
fn combination(f: &Fit, c: &NullCombination) -> (String, String) {
    let machine: Vec<String> = c
        .components
        .iter()
        .filter(|&&(i, _)| i < f.n_machine || !f.parameters[i].class.is_nuisance())
        .map(|&(i, a)| {
            format!("{} {:+.3} {}", f.parameters[i].id, a, f.parameters[i].unit.display_name())
        })
        .collect();
    let nuisance = c
        .components
        .iter()
        .filter(|&&(i, _)| i >= f.n_machine && f.parameters[i].class.is_nuisance())
        .count();
    let mut text = machine.join(", ");
    if nuisance > 0 {
        let _ = write!(text, ", with {nuisance} set-up parameter(s) of the runs (centring)");
    }
    // An offset and a tilt of one axis line at one ball height: another height separates them.
    let loc: Vec<(Axis, Axis)> =
        c.components.iter().filter_map(|&(i, _)| location_parts(&f.parameters[i].id)).collect();
    let offset_and_tilt = loc.iter().any(|&(d, k)| {
        !d.is_rotary() && loc.iter().any(|&(e, l)| l == k && e.is_rotary() && e != k)
    });
    let hint = if offset_and_tilt {
        let k = loc[0].1;
        format!(
            "a radial run of {k} at a second ball height (an offset and a tilt of its line act alike at one height)"
        )
    } else {
        null_hint(f, c)
    };
    (text, hint)
}

fn location_errors(h: &mut String, model: &Model, f: &Fit) {
    let params = location_params(f);
    h.push_str(r#"<h3>Location errors (ISO 230-7)</h3>"#);
    if params.is_empty() {
        h.push_str(r#"<p class="na" id="location-errors">The machine's model has no location errors of its rotary axes (E<sub>d</sub>0<sub>k</sub>).</p>"#);
        return;
    }
    h.push_str(r#"<p>Offsets (µm) and tilts (µrad) of each rotary axis's line and its zero error, as ISO 230-7 states them (<code>docs/chain-files.md</code>); standard uncertainties, k = 1. <b>yes*</b>: determined, for the choice stated (what the runs leave open, fixed by the fit).</p><table id="location-errors"><tr><th>id</th><th>what</th><th>value</th><th>u</th><th>unit</th><th>estimable</th><th>choice it holds for, or why not</th></tr>"#);
    let mut axes: Vec<Axis> = params.iter().map(|p| p.1).collect();
    axes.sort();
    axes.dedup();
    for k in axes {
        let joint = model
            .chain
            .tool
            .iter()
            .map(|j| (j, "tool"))
            .chain(model.chain.workpiece.iter().map(|j| (j, "workpiece")))
            .find(|(j, _)| j.axis == k)
            .map(|(j, b)| format!(": joint '{}' ({b} branch)", j.name))
            .unwrap_or_default();
        let _ = write!(
            h,
            r#"<tr class="axis-group" data-axis="{k}"><th colspan="7">{k} axis{}</th></tr>"#,
            esc(&joint)
        );
        for &(i, _) in params.iter().filter(|p| p.1 == k) {
            let p = &f.parameters[i];
            let factor = p.unit.display_factor();
            let (cells, estimable, why) = if f.estimable[i] {
                let held = f.depends_on(&[(i, 1.0)]);
                let why = held
                    .iter()
                    .map(|&g| choice_short(f, &f.gauges[g]))
                    .collect::<Vec<_>>()
                    .join("; ");
                (
                    format!(
                        "{}{}",
                        crate::cells::td(f.values[i] * factor, 3),
                        crate::cells::td(f.std_uncertainty[i] * factor, 3)
                    ),
                    if held.is_empty() { "yes" } else { "yes*" },
                    if held.is_empty() { String::new() } else { format!("holds for: {why}") },
                )
            } else if let Some(g) = fixed_by(f, i) {
                let g = &f.gauges[g];
                (
                    format!(
                        r#"<td class="na">{}</td><td class="na">—</td>"#,
                        crate::wording::FIXED_AT_0
                    ),
                    "no",
                    format!(
                        "{} ({}): {}; to determine it: {}",
                        g.what,
                        g.kind.name(),
                        g.choice,
                        g.separate_by
                    ),
                )
            } else {
                // The combinations it is in, those a gauge does not settle first (a settled one
                // is the gauge's, stated where its parameter is).
                let of_i: Vec<&NullCombination> = f
                    .null_space
                    .iter()
                    .filter(|c| c.components.iter().any(|&(j, _)| j == i))
                    .collect();
                let open: Vec<&NullCombination> =
                    of_i.iter().copied().filter(|c| !settled(f, c)).collect();
                let combos: Vec<String> = (if open.is_empty() { of_i } else { open })
                    .into_iter()
                    .map(|c| {
                        let (text, hint) = combination(f, c);
                        format!("{text}: moving them together changes no reading (null_space); separate with: {hint}")
                    })
                    .collect();
                let why = if combos.is_empty() {
                    "not determined by these runs".to_string()
                } else {
                    combos.join("; ")
                };
                (r#"<td class="na">—</td><td class="na">—</td>"#.to_string(), "no", why)
            };
            let _ = write!(
                h,
                r#"<tr data-id="{}" data-axis="{k}" data-estimable="{}"><td>{}</td><td>{}</td>{cells}<td>{}</td><td>{estimable}</td><td>{}</td></tr>"#,
                esc(&p.id),
                f.estimable[i],
                esc(&p.id),
                esc(&p.label),
                esc(p.unit.display_name()),
                esc(&why)
            );
        }
    }
    h.push_str("</table>");
}

/// The text with its first letter in upper case.
fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

/// What a gauge is, in a few plain words.
fn heading(kind: GaugeKind) -> &'static str {
    match kind {
        GaugeKind::AcrossBar => "Where the table ball sits across the bar",
        GaugeKind::SetUp => "What every run sees only as a re-seated ball",
        GaugeKind::ZeroError => "A zero error seen only together with other location errors",
        GaugeKind::AxisAtRest(_) => "An axis that did not move",
        GaugeKind::BarLength => "The bar's length against the axes' common scale",
        GaugeKind::CommonLag => "The lag common to the linear axes",
        GaugeKind::NoEffect => "Errors these runs do not see",
        GaugeKind::Weak => "A combination the runs determine too weakly",
    }
}

fn notes(h: &mut String, f: &Fit) {
    let loc: Vec<usize> = location_params(f).into_iter().map(|p| p.0).collect();
    let touches = |cols: &[usize]| cols.iter().any(|j| loc.contains(j));
    h.push_str(r#"<h3>Identifiability notes for the rotary runs</h3><p>What the rotary runs cannot determine and the choice the fit made for it; the values marked yes* above hold for these choices.</p><ul id="rotary-notes">"#);
    let mut any = false;
    for g in &f.gauges {
        let relevant = match g.kind {
            GaugeKind::AcrossBar
            | GaugeKind::SetUp
            | GaugeKind::ZeroError
            | GaugeKind::CommonLag => true,
            GaugeKind::AxisAtRest(a) => a.is_rotary() || touches(&g.parameters),
            _ => touches(&g.parameters) || touches(&g.conditional),
        };
        if !relevant {
            continue;
        }
        any = true;
        let _ = write!(
            h,
            r#"<li data-kind="{}"><b>{}</b> ({}). {}: {}. Why: {}. To determine it: {}.</li>"#,
            g.kind.name(),
            heading(g.kind),
            g.kind.name(),
            esc(&capitalised(&g.what)),
            esc(&g.choice),
            esc(&g.why),
            esc(&g.separate_by)
        );
    }
    // Combinations of location errors that no choice settles (one set of runs at one height).
    for c in &f.null_space {
        if settled(f, c) || !c.components.iter().any(|(i, _)| loc.contains(i)) {
            continue;
        }
        any = true;
        let (text, hint) = combination(f, c);
        let _ = write!(
            h,
            r#"<li data-kind="null_space"><b>Location errors these runs cannot tell apart</b>. Moving {} together changes no reading: none of them is reported. To separate them: {}.</li>"#,
            esc(&text),
            esc(&hint)
        );
    }
    if !any {
        h.push_str("<li>The fit fixed nothing of the rotary axes: these runs determine every location error of the model.</li>");
    }
    h.push_str("</ul>");
}

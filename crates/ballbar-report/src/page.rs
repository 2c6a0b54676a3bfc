//! The HTML report of an archived session: one self-contained page (inline CSS and SVG, no
//! script, no network) a metrology engineer prints for the machine's file.
//!
//! # Sections (each a `<section id=…>`)
//! - `summary`: the session's form ([`crate::session_info`]: machine and its serial, ballbar
//!   and its calibration, temperature, operator, date of the test; from `--info` and the runs'
//!   headers, a blank line to fill in by hand for what nobody gave), then the machine, plugin,
//!   dates, software, the model's choices, what was assumed, the refit check;
//! - `tolerance` (with `--tolerance`, [`crate::tolerance`]): the pass/fail table, one row per
//!   limit and plane, axis or run it applies to (value, U, limit, PASS / FAIL / UNDECIDED or
//!   NOT CHECKED with why), and the session's overall verdict;
//! - `polar`: per CW/CCW pair (or lone run) two polar plots: the measured trace with the
//!   model's prediction drawn over it, and the residual after the model (the paper's figures 6
//!   and 7), and beneath them the vendor's single plot per run (`polar single`: its measured
//!   trace and the model's together, at the measured plots' scale, with its G and a key of
//!   the two lines). One µm/division per kind of plot, the largest any plane needs (one for every
//!   measured plot, one for every plot after the model), stated above the figures, so that the
//!   planes compare by eye. The measured trace's least-squares first harmonic (the set-up's
//!   eccentricity, however the model would split it between centring and machine terms) is
//!   taken out of the measured and the model curve alike. Each run's first sample is marked
//!   (a dot and the word `start`, placed clear of the traces) with an arrow along its
//!   direction of travel; where the diagnosis places the gap, arcs are highlighted along the
//!   trace of the runs concerned;
//! - `rotary` (only with rotary runs, the `rotary` module): ΔR of each rotary run against its
//!   turning axis's coordinate (polar for a full turn, Cartesian for a partial sweep, at one
//!   µm/division per kind of plot over all rotary tests, with the same start marks, arrows and
//!   arcs), the ISO 230-7 location errors grouped by rotary axis with what explains those not
//!   determined, and the fit's choices for the rotary axes in plain words;
//! - `parameters`: the paper's quantities with vendor-comparable units and uncertainties (u to
//!   two significant digits, the value to the same place), every machine parameter with the
//!   normalisation its basis uses, what the tests cannot separate and the test that would;
//! - `local`: what each test determines where it is (the local scales and squareness at the
//!   circle's centre, which no pivot or tool length given moves) and each alias of the base
//!   model with the values it moves, their alternatives and the test that separates them
//!   ([`crate::aliases`]; the terminal's two sections, the JSON's `local` and `aliases`);
//! - `iso`: ISO 230-4 G, F and H per run before and after the model;
//! - `compensation` (with `--compensation` and/or `--verification`, [`crate::compensation`]):
//!   what was compensated and what remains with why, each run's G before, predicted and
//!   measured after, each term's verdict;
//! - `vendor` (with `.b5r` files): the vendor's own analysis beside ours, our u to two
//!   significant digits;
//! - `diagnosis`: the archived diagnosis: noise floor, where, what the gap is locked to, the
//!   accepted effects with their evidence, the held-out shrink as bars, the aliased effects;
//! - `trends` (with a history): each machine parameter over the sessions with ±2u bars, on an
//!   honest value axis (round ticks, holding every bar, spanning at least ten standard
//!   uncertainties so that noise does not look like drift, reaching zero where sensible) and
//!   dated ticks, the changes `ballbar history` flags marked on the line with their size.
//!
//! # Print
//! The page prints on A4 and Letter (`page_rule`: margins that fit both, the paper left to
//! the printer, the page's own footer with the title in place of a browser's URL). After the
//! sections are written, `print_layout` gives every table with a header row a `<thead>`
//! (repeated on each printed page) and keeps a table that fits on a page whole.
//!
//! Numbers are the refit's (from the archived runs and machine; it must reproduce the archived
//! fit, and the summary says whether it did) and the archived diagnosis's. Every number a test
//! checks is also in a `data-v` attribute at full precision.

use std::fmt::Write;

use ballbar_archive::{ArchivedFit, Session};
use ballbar_documents::VendorEntry;
use ballbar_documents::diagnosis::{Diagnosis, Where};
use ballbar_fit::{Fit, fit_factored, metrics};
use ballbar_model::machine::Model;
use ballbar_model::{Design, KernelSource, Run};
use serde::Deserialize;

use crate::ReportError;
use crate::cells::{max_abs, td};
use crate::fit_report::{null_hint, pairs, paper_rows, run_figures};
use crate::svg::{self, Angles, Arc, Polar, Trace, esc, nice_scale};

/// What the user adds to the page: the session's particulars (`--info KEY=VALUE`, keys of
/// [`crate::session_info::FIELDS`]) and the tolerances to judge it against (`--tolerance`).
#[derive(Clone, Debug, Default)]
pub struct PageOptions {
    /// `(key, value)` pairs given on the command line (checked by
    /// [`crate::session_info::check_given`]), over what the runs' headers say.
    pub info: Vec<(String, String)>,
    /// The tolerance file, read ([`crate::tolerance::read`]).
    pub tolerance: Option<crate::tolerance::ToleranceFile>,
    /// A compensation and its verification (`--compensation DIR`, `--verification FILE`).
    pub compensation: crate::compensation::CompensationInput,
}

/// A built page.
pub struct Page {
    /// The HTML.
    pub html: String,
    /// Whether the refit reproduced the archived fit (to 1e-12 relative).
    pub refit_identical: bool,
    /// With a tolerance file, the acceptance for the terminal: the overall verdict, then each
    /// check's shop-floor line, as the page states them ([`crate::tolerance::terminal_lines`]).
    pub acceptance: Vec<String>,
}

/// Relative agreement of the refit with the archived fit (the replay's 1e-12).
const SAME: f64 = 1e-12;

fn um(x_mm: f64) -> f64 {
    x_mm * 1e3
}

fn same(a: f64, b: f64) -> bool {
    (a.is_nan() && b.is_nan()) || a == b || (a - b).abs() <= SAME * a.abs().max(b.abs())
}

/// Build the page of an archived session. `kernels` serves the kernel terms of a plugin's
/// machine (`NoKernels` otherwise); `history` holds the sessions (name, archive) whose fits make
/// the trend plots (empty: no trend section).
pub fn build(
    name: &str,
    session: &Session,
    kernels: &dyn KernelSource,
    history: &[(String, Session)],
) -> Result<Page, ReportError> {
    build_with(name, session, kernels, history, &PageOptions::default())
}

/// [`build`] with what the user adds: the session's particulars and the tolerances.
pub fn build_with(
    name: &str,
    session: &Session,
    kernels: &dyn KernelSource,
    history: &[(String, Session)],
    options: &PageOptions,
) -> Result<Page, ReportError> {
    let err = |message: String| ReportError::Archive { archive: name.to_string(), message };
    let machine = session.machine.as_ref().ok_or_else(|| err("the archive holds raw runs only (no machine, no fit): record the session with `fit --record` or `diagnose --record`".into()))?;
    let runs: Vec<Run> = session.runs.iter().map(|r| r.run.clone()).collect();
    let model = Model::with_kernels(machine.spec.clone(), machine.options, kernels)
        .map_err(|e| err(e.to_string()))?;
    let design = Design::new(&model, &runs).map_err(|e| err(e.to_string()))?;
    // As `ballbar fit` does: the backlash switches at the lagged reversals.
    let (design, _) = ballbar_fit::switch::switch_at_lagged_reversals(design, 2)
        .map_err(|e| err(e.to_string()))?;
    let (f, fac) = fit_factored(&design, 2).map_err(|e| err(e.to_string()))?;
    let assessment =
        ballbar_fit::alias::assess(&design, &f, &fac, 2).map_err(|e| err(e.to_string()))?;
    drop(fac);
    let refit_identical = session.fit.as_ref().is_some_and(|a| identical(a, &f));
    let diag: Option<Diagnosis> = match &session.diagnosis {
        Some(v) => Some(Diagnosis::deserialize(v).map_err(|e| {
            err(format!(
                "its diagnosis is not a readable {} document: {e}",
                ballbar_documents::diagnosis::FORMAT
            ))
        })?),
        None => None,
    };
    let diag = diag.as_ref();

    let run_refs: Vec<&Run> = runs.iter().collect();
    let info = crate::session_info::fields(&run_refs, &options.info, Some(&machine.spec.name));
    // The title (and each printed page's footer) is the form's: the machine (the archived
    // machine's name unless given or in the runs), its serial number where known, and the date
    // of the test (the first run's start unless given): a browser that prints its own header
    // shows it, and it names the PDF.
    let known = |key: &str| crate::session_info::known(&info, key);
    let serial = known("machine_serial").map(|s| format!(" (serial {s})")).unwrap_or_default();
    let title = format!(
        "Ballbar report — {}{serial} — {}",
        known("machine_name").unwrap_or(&machine.spec.name),
        known("test_date").unwrap_or_default()
    );
    let mut h = String::with_capacity(1 << 20);
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">");
    let _ = write!(
        h,
        "<title>{}</title><style>{CSS}{LAYOUT_CSS}{}</style><style>{}</style></head><body>",
        esc(&title),
        crate::vendor_table::CSS,
        page_rule(&title)
    );
    summary(&mut h, name, session, &f, refit_identical, &info);
    let mut acceptance = Vec::new();
    if let Some(t) = &options.tolerance {
        let checks = crate::tolerance::evaluate(&t.limits, &model, &f, &runs, diag);
        crate::tolerance::section(&mut h, t, &checks, diag);
        acceptance = crate::tolerance::terminal_lines(t, &checks);
    }
    polar_section(&mut h, &design, &f, diag);
    crate::rotary::section(&mut h, &model, &runs, &f, diag);
    parameters(&mut h, &model, &f, &runs);
    crate::aliases::page_section(&mut h, &f, &assessment);
    iso(&mut h, &f, &runs);
    crate::compensation::section(&mut h, &options.compensation);
    vendor_section(&mut h, session, diag, &runs, &model, &f);
    diagnosis(&mut h, diag);
    if !history.is_empty() {
        trends(&mut h, &machine.spec.name, history);
    }
    h.push_str("</body></html>\n");
    Ok(Page { html: print_layout(&h), refit_identical, acceptance })
}

/// The refit against the archived fit: every parameter's value and uncertainty.
fn identical(a: &ArchivedFit, f: &Fit) -> bool {
    a.parameters.len() == f.parameters.len()
        && a.parameters.iter().zip(&f.parameters).enumerate().all(|(i, (p, q))| {
            p.id == q.id
                && same(p.value, f.values[i])
                && same(p.std_uncertainty, f.std_uncertainty[i])
        })
}

fn summary(
    h: &mut String,
    name: &str,
    s: &Session,
    f: &Fit,
    refit_identical: bool,
    info: &[(crate::session_info::FieldSpec, crate::session_info::Value)],
) {
    let m = s.machine.as_ref().expect("checked");
    let runs: Vec<&Run> = s.runs.iter().map(|r| &r.run).collect();
    let samples: usize = runs.iter().map(|r| r.len()).sum();
    let _ = write!(
        h,
        r#"<section id="summary"><h1>Ballbar report: machine {}</h1>"#,
        esc(&m.spec.name)
    );
    crate::session_info::html(h, info);
    h.push_str(r#"<table class="facts">"#);
    let rows = [
        ("machine", format!("{} {} — {}", m.spec.name, m.spec.version, m.spec.description)),
        ("plugin", format!("{} {}", m.plugin_name, m.plugin_version)),
        ("session", format!("{} ({} runs, {samples} samples)", crate::session_info::first_start(&runs).unwrap_or_default(), runs.len())),
        ("archive", format!("{name}, recorded by ballbar {} ({})", s.info.software_version, s.info.command)),
        (
            "model",
            format!(
                "servo: {}; bar length: {}",
                match m.options.servo {
                    ballbar_model::ServoVariant::AxisLag => "one lag per axis",
                    ballbar_model::ServoVariant::PlaneMismatch => "the paper's plane mismatch terms",
                },
                crate::wording::bar_length(m.options.bar_length, f)
            ),
        ),
        ("fit", format!("rank {} of {}, condition number {:.3e}, residual σ {:.3} µm (lag-1 autocorrelation {:.2})", f.rank, f.parameters.len(), f.condition_number, um(f.sigma_mm), f.rho)),
        (
            "fixed by the tests' limits",
            if f.gauges.is_empty() {
                "nothing: these tests determine every parameter of the model".to_string()
            } else {
                f.gauges.iter().map(|g| format!("{}: {} (to determine it: {})", g.what, g.choice, g.separate_by)).collect::<Vec<_>>().join("; ")
            },
        ),
        ("assumed", crate::assumed::note(runs.iter().copied()).unwrap_or_else(|| "nothing: every run gives the ball positions its results depend on".to_string())),
        (
            "refit",
            match (&s.fit, refit_identical) {
                (Some(_), true) => "refitted from the archived runs: identical to the archived fit (every value and uncertainty within 1e-12)".to_string(),
                (Some(_), false) => "refitted from the archived runs: DIFFERS from the archived fit (another software version?); the page shows the refit".to_string(),
                (None, _) => "the archive holds no fit; the page shows a fit of the archived runs".to_string(),
            },
        ),
    ];
    for (k, v) in rows {
        let _ = write!(h, "<tr><th>{k}</th><td class=\"{k}\">{}</td></tr>", esc(&v));
    }
    h.push_str("</table></section>");
}

/// One planar run's curves in a polar figure, µm: measured and model with the set-up's
/// eccentricity taken out, and the residual.
struct PolarCurves {
    r: usize,
    theta: Vec<f64>,
    measured: Vec<f64>,
    model: Vec<f64>,
    residual: Vec<f64>,
}

/// The gap's arcs of one planar figure: each `where` entry of its plane (not a whole plane,
/// not a free run's), along the figure's runs of the entry's direction.
fn planar_arcs(where_: &[Where], plane: &str, runs: &[(String, &str)]) -> Vec<Arc> {
    let mut arcs = Vec::new();
    for w in where_.iter().filter(|w| w.plane == plane && w.run.is_none()) {
        // A sector of two numbers, not the whole plane (that is the plane's entry).
        let [a, b] = w.sector_deg;
        if !(a.is_finite() && b.is_finite()) || (a == 0.0 && b == 360.0) {
            continue;
        }
        let direction = w.direction.as_str();
        for (name, _) in runs.iter().filter(|(_, d)| *d == direction) {
            arcs.push(Arc {
                from_deg: a,
                to_deg: b,
                wrap: true,
                direction: direction.to_string(),
                run: name.clone(),
                share: w.share,
            });
        }
    }
    arcs
}

fn polar_section(h: &mut String, design: &Design<'_>, f: &Fit, diag: Option<&Diagnosis>) {
    let runs = design.runs;
    // Groups: CW/CCW pairs, then lone runs.
    let mut groups: Vec<Vec<usize>> = pairs(runs).into_iter().map(|(a, b)| vec![a, b]).collect();
    for r in 0..runs.len() {
        if !groups.iter().any(|g| g.contains(&r)) {
            groups.push(vec![r]);
        }
    }
    groups.sort_by_key(|g| g[0]);
    let figures: Vec<Vec<PolarCurves>> = groups
        .iter()
        .filter(|g| runs[g[0]].header.plane.axes().is_some())
        .map(|g| {
            g.iter()
                .filter_map(|&r| {
                    let theta = metrics::angles(&runs[r])?;
                    // The set-up's eccentricity: the measured trace's first harmonic, taken out
                    // of the measured and the model curve alike (the fitted centring would move
                    // with the model: it takes what the machine terms leave of the first
                    // harmonic).
                    let run = &runs[r];
                    let (a, b) = metrics::first_harmonic(&theta, &run.dr_mm);
                    let ecc = |i: usize| a * theta[i].cos() + b * theta[i].sin();
                    let measured: Vec<f64> =
                        (0..run.len()).map(|i| um(run.dr_mm[i] - ecc(i))).collect();
                    let model: Vec<f64> = (0..run.len())
                        .map(|i| um(run.dr_mm[i] - f.residuals[r][i] - ecc(i)))
                        .collect();
                    let residual: Vec<f64> = f.residuals[r].iter().map(|x| um(*x)).collect();
                    Some(PolarCurves { r, theta, measured, model, residual })
                })
                .collect::<Vec<_>>()
        })
        .filter(|d| !d.is_empty())
        .collect();
    // One scale for every measured plot and one for every plot after the model: the largest
    // any of them needs, so that planes compare by eye.
    let raw_scale =
        nice_scale(max_abs(figures.iter().flatten().flat_map(|c| [&c.measured, &c.model])));
    let res_scale = nice_scale(max_abs(figures.iter().flatten().map(|c| &c.residual)));
    h.push_str(r#"<section id="polar"><h2>Polar plots</h2><p>Each figure: CW and CCW runs of one plane and feed overlaid; left the measured deviation with the model's prediction drawn over it (dashed), right the residual after the model; the measured trace's first harmonic (the set-up's eccentricity) is taken out of the measured and the model curve alike. Each run's first sample is marked <i>start</i>, and an arrow inside the innermost ring shows its direction of travel. Highlighted arcs: where the diagnosis places the gap, along the trace of the runs it concerns. Beneath each figure the vendor's view: one plot per run, its measured trace and the model's together at the measured plots' scale, with its G and a key of the lines."#);
    if runs.iter().any(|r| r.header.plane == ballbar_model::Plane::Free) {
        h.push_str(r##" The rotary runs (plane free) are drawn against their rotary axis in <a href="#rotary">the next section</a>."##);
    }
    h.push_str("</p>");
    if !figures.is_empty() {
        let _ = write!(
            h,
            r#"<p class="scales" data-raw-scale-um="{raw_scale}" data-after-scale-um="{res_scale}">Scales, the same on every plane so that the planes compare by eye: measured and model at <b>{} µm/div</b>, after the model at <b>{} µm/div</b>.</p>"#,
            svg::fmt_scale(raw_scale),
            svg::fmt_scale(res_scale)
        );
    }
    let where_: &[Where] = diag.map_or(&[], |d| &d.gap.where_);
    let dir = |r: usize| runs[r].header.direction.map(|d| d.name()).unwrap_or("-");
    for data in &figures {
        let head = &runs[data[0].r].header;
        let Some(axes) = head.plane.axes() else { continue };
        let (u, v) = (axes.0.name(), axes.1.name());
        let names: Vec<String> = data.iter().map(|d| runs[d.r].name()).collect();
        let title = format!(
            "{} plane, R {} mm, F {} mm/min: {}",
            head.plane.name(),
            head.radius_mm,
            head.feed_mm_per_min,
            names.join(" / ")
        );
        let class_of = |r: usize, what: &str| -> &'static str {
            match (what, dir(r)) {
                ("measured", "CW") => "trace measured cw",
                ("measured", "CCW") => "trace measured ccw",
                ("measured", _) => "trace measured nodir",
                ("model", "CW") => "trace model cw",
                ("model", "CCW") => "trace model ccw",
                ("model", _) => "trace model nodir",
                (_, "CW") => "trace residual cw",
                (_, "CCW") => "trace residual ccw",
                _ => "trace residual nodir",
            }
        };
        let run_dirs: Vec<(String, &str)> =
            data.iter().zip(&names).map(|(d, n)| (n.clone(), dir(d.r))).collect();
        let arcs = planar_arcs(where_, head.plane.name(), &run_dirs);
        let mut raw = Polar {
            class: "polar raw",
            title: format!("{title}: measured and model"),
            angles: Angles::Plane(u, v),
            scale_um: raw_scale,
            traces: vec![],
            arcs,
            legend: vec![],
            keys: vec![],
        };
        let mut after = Polar {
            class: "polar after",
            title: format!("{title}: after the model"),
            angles: Angles::Plane(u, v),
            scale_um: res_scale,
            traces: vec![],
            arcs: vec![],
            legend: vec![],
            keys: vec![],
        };
        // The vendor's view: one plot per run, its measured trace and the model's together, at
        // the measured plots' scale, with the run's G and a key of the two lines.
        let mut single: Vec<Polar<'_>> = Vec::new();
        for (k, d) in data.iter().enumerate() {
            // Each run's ISO 230-4 circular deviation beside its plot, as in the run table.
            let run = &runs[d.r];
            let dir_class = class_of(d.r, "measured").rsplit(' ').next().unwrap_or("nodir");
            let g = |dr: &[f64]| um(metrics::figures(run, dr).g);
            raw.legend.push((dir_class, format!("G {} {:.2} µm", dir(d.r), g(&run.dr_mm))));
            after
                .legend
                .push((dir_class, format!("G {} {:.2} µm", dir(d.r), g(&f.residuals[d.r]))));
            raw.traces.push(Trace {
                class: class_of(d.r, "measured"),
                run: &names[k],
                theta: &d.theta,
                value_um: &d.measured,
                mark_start: true,
            });
            raw.traces.push(Trace {
                class: class_of(d.r, "model"),
                run: &names[k],
                theta: &d.theta,
                value_um: &d.model,
                mark_start: false,
            });
            after.traces.push(Trace {
                class: class_of(d.r, "residual"),
                run: &names[k],
                theta: &d.theta,
                value_um: &d.residual,
                mark_start: true,
            });
            single.push(Polar {
                class: "polar single",
                title: format!(
                    "{}: {} {}, measured and model",
                    names[k],
                    head.plane.name(),
                    dir(d.r)
                ),
                angles: Angles::Plane(u, v),
                scale_um: raw_scale,
                traces: vec![
                    Trace {
                        class: class_of(d.r, "measured"),
                        run: &names[k],
                        theta: &d.theta,
                        value_um: &d.measured,
                        mark_start: true,
                    },
                    Trace {
                        class: class_of(d.r, "model"),
                        run: &names[k],
                        theta: &d.theta,
                        value_um: &d.model,
                        mark_start: false,
                    },
                ],
                // The gap's arcs are on the split plots above it; the vendor's plot has none.
                arcs: vec![],
                legend: vec![(dir_class, format!("G {} {:.2} µm", dir(d.r), g(&run.dr_mm)))],
                keys: vec![
                    (class_of(d.r, "measured"), "measured".into()),
                    (class_of(d.r, "model"), "model".into()),
                ],
            });
        }
        let _ = write!(
            h,
            r#"<figure class="polar-pair" data-runs="{}" data-plane="{}" data-feed="{}">"#,
            esc(&names.join(",")),
            head.plane.name(),
            head.feed_mm_per_min
        );
        h.push_str(&svg::polar(&raw));
        h.push_str(&svg::polar(&after));
        let _ = write!(
            h,
            "<figcaption>{}: measured (solid) and model (dashed); after the model. CW blue, CCW red.</figcaption></figure>",
            esc(&title)
        );
        let _ = write!(
            h,
            r#"<figure class="polar-single" data-runs="{}" data-plane="{}" data-feed="{}">"#,
            esc(&names.join(",")),
            head.plane.name(),
            head.feed_mm_per_min
        );
        for p in &single {
            h.push_str(&svg::polar(p));
        }
        let _ = write!(
            h,
            "<figcaption>{}: one plot per run, as the vendor's software draws it: the measured trace and the model's together.</figcaption></figure>",
            esc(&title)
        );
    }
    h.push_str("</section>");
}

fn parameters(h: &mut String, model: &Model, f: &Fit, runs: &[Run]) {
    let (r, feed, rows) = paper_rows(model, f, runs);
    let _ = write!(
        h,
        r#"<section id="parameters"><h2>Parameters</h2><h3>The paper's quantities at R = {r} mm, F = {feed} mm/min (u: standard uncertainty, k = 1)</h3><table id="paper-quantities"><tr><th>quantity</th><th>value</th><th>u</th><th>unit</th><th>in Renishaw's units</th><th>u</th><th>unit</th></tr>"#
    );
    // u to two significant digits, the value to the same decimal place (a small u never 0.00).
    let places = |u: f64| crate::fit_report::u_decimals(u).unwrap_or(2);
    for (p, v) in &rows {
        let _ = write!(h, r#"<tr data-name="{}">"#, esc(&p.name));
        let _ = write!(h, "<td>{}</td>", esc(&p.name));
        if p.estimate.estimable {
            let (pu, vu) = (p.estimate.std_uncertainty, v.estimate.std_uncertainty);
            let _ = write!(
                h,
                "{}{}<td>{}</td>{}{}<td>{}</td>",
                td(p.estimate.value, places(pu)),
                td(pu, places(pu)),
                esc(p.unit),
                td(v.estimate.value, places(vu)),
                td(vu, places(vu)),
                esc(v.unit)
            );
        } else {
            let _ =
                write!(h, r#"<td colspan="6" class="na">not identifiable from these tests</td>"#);
        }
        h.push_str("</tr>");
    }
    let _ = write!(
        h,
        r#"</table><p class="legend" id="renishaw-units">In Renishaw's units: {}.</p>"#,
        esc(crate::fit_report::RENISHAW_UNITS)
    );
    let bases: Vec<Option<crate::fit_report::Basis>> = (0..f.n_machine)
        .map(|i| crate::fit_report::Basis::of(model, &f.parameters[i].id))
        .collect();
    h.push_str("<h3>Machine parameters (value ± standard uncertainty)</h3>");
    if let Some(text) = crate::fit_report::normalisation_text(&bases) {
        let mut text = text;
        if let Some(c) = text.get(..1) {
            text = c.to_uppercase() + &text[1..];
        }
        let _ = write!(h, r#"<p class="legend" id="normalisation">{}.</p>"#, esc(&text));
    }
    h.push_str(r#"<table id="machine-parameters"><tr><th>id</th><th>value</th><th>u</th><th>unit</th><th>what</th><th>basis</th></tr>"#);
    for (i, basis) in bases.iter().enumerate() {
        let p = &f.parameters[i];
        let k = p.unit.display_factor();
        let _ = write!(h, r#"<tr data-id="{}">"#, esc(&p.id));
        let _ = write!(h, "<td>{}</td>", esc(&p.id));
        if f.estimable[i] {
            let u = f.std_uncertainty[i] * k;
            let d = crate::fit_report::u_decimals(u).unwrap_or(3);
            let _ = write!(h, "{}{}", td(f.values[i] * k, d), td(u, d));
        } else {
            let _ = write!(
                h,
                r#"<td class="na" colspan="2">{}</td>"#,
                crate::wording::not_estimated(f, i)
            );
        }
        let _ = write!(
            h,
            "<td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(p.unit.display_name()),
            esc(&p.label),
            esc(&basis.as_ref().map(|b| b.text()).unwrap_or_default())
        );
    }
    h.push_str(r#"</table><h3>What these tests cannot separate</h3><ul id="identifiability">"#);
    if f.null_space.is_empty() {
        h.push_str("<li>Every parameter is identifiable from these tests.</li>");
    }
    for c in &f.null_space {
        let text = c
            .components
            .iter()
            .map(|&(i, a)| {
                format!("{} {:+.3} {}", f.parameters[i].id, a, f.parameters[i].unit.display_name())
            })
            .collect::<Vec<_>>()
            .join(", ");
        let _ = write!(
            h,
            "<li>{} — moving them together changes no reading; separate with: {}</li>",
            esc(&text),
            esc(&null_hint(f, c))
        );
    }
    h.push_str("</ul></section>");
}

fn iso(h: &mut String, f: &Fit, runs: &[Run]) {
    h.push_str(r#"<section id="iso"><h2>ISO 230-4 circular tests, before → after the model</h2><p>µm; G about the least-squares circle, F max/min about the nominal radius, H between the CW and CCW runs of a pair.</p><table id="iso-runs"><tr><th>run</th><th>plane</th><th>dir</th><th>feed mm/min</th><th>samples placed</th><th>RMS before</th><th>RMS after</th><th>G before</th><th>G after</th><th>F max before</th><th>F min before</th><th>F max after</th><th>F min after</th></tr>"#);
    for (k, (b, a)) in run_figures(f, runs).iter().enumerate() {
        let hd = &runs[k].header;
        let _ = write!(
            h,
            r#"<tr data-run="{}"><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td>{}{}{}{}{}{}{}{}</tr>"#,
            esc(&runs[k].name()),
            esc(&runs[k].name()),
            hd.plane.name(),
            hd.direction.map(|d| d.name()).unwrap_or("-"),
            hd.feed_mm_per_min,
            crate::fit_report::placement_words(&runs[k]),
            td(um(b.rms), 3),
            td(um(a.rms), 3),
            td(um(b.g), 2),
            td(um(a.g), 2),
            td(um(b.f_max), 2),
            td(um(b.f_min), 2),
            td(um(a.f_max), 2),
            td(um(a.f_min), 2)
        );
    }
    if runs.iter().any(|r| r.header.plane == ballbar_model::Plane::Free) {
        h.push_str(r#"<tr><td colspan="13" class="na">Rotary runs (plane free) have no circle to fit: their G is the trace's max − min, and they have no H.</td></tr>"#);
    }
    h.push_str(r#"</table><table id="iso-hysteresis"><tr><th>CW run</th><th>CCW run</th><th>H before</th><th>H after</th></tr>"#);
    for (i, j) in pairs(runs) {
        let before = metrics::hysteresis(&runs[i], &runs[i].dr_mm, &runs[j], &runs[j].dr_mm);
        let after = metrics::hysteresis(&runs[i], &f.residuals[i], &runs[j], &f.residuals[j]);
        if let (Some(b), Some(a)) = (before, after) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td>{}{}</tr>",
                esc(&runs[i].name()),
                esc(&runs[j].name()),
                td(um(b), 2),
                td(um(a), 2)
            );
        }
    }
    h.push_str("</table></section>");
}

/// The vendor's analysis of the session's `.b5r` files beside ours: the diagnosis's comparison
/// where the session was diagnosed (its RMS is after the diagnosed model), else one made from
/// the refit and the attached files.
fn vendor_section(
    h: &mut String,
    s: &Session,
    diag: Option<&Diagnosis>,
    runs: &[Run],
    model: &Model,
    f: &Fit,
) {
    let archived = diag.and_then(|d| d.vendor_comparison.clone());
    let entries: Vec<VendorEntry> = match archived {
        Some(entries) => entries,
        None => {
            let mut all = Vec::new();
            for a in s
                .attachments
                .iter()
                .filter(|a| ballbar_io::b5r::is_b5r(std::path::Path::new(&a.name)))
            {
                let of_file: Vec<usize> = (0..runs.len())
                    .filter(|&r| {
                        std::path::Path::new(&runs[r].source)
                            .file_name()
                            .is_some_and(|n| n.to_string_lossy() == a.name)
                    })
                    .collect();
                let (Some(&first), Some(&last)) = (of_file.first(), of_file.last()) else {
                    continue;
                };
                let angles = ballbar_io::b5r::SpacingMode::of(&runs[first])
                    .map_or(Default::default(), ballbar_io::b5r::SpacingMode::reread_with);
                let options = ballbar_io::b5r::B5rOptions {
                    pivot_mm: Some(runs[first].header.pivot_mm),
                    tool_ball_mm: None,
                    angles,
                };
                let Some(test) = std::str::from_utf8(&a.data)
                    .ok()
                    .and_then(|t| ballbar_io::b5r::parse_b5r(t, &a.name, &options).ok())
                else {
                    continue;
                };
                if last + 1 - first != test.runs.len() {
                    continue;
                }
                let cmp = crate::vendor::compare(
                    &test,
                    runs,
                    first..last + 1,
                    model,
                    f,
                    crate::vendor::Diagnosed::default(),
                );
                all.extend(crate::vendor::document(&cmp));
            }
            all
        }
    };
    crate::vendor_table::section(h, &entries);
}

fn diagnosis(h: &mut String, d: Option<&Diagnosis>) {
    h.push_str(r#"<section id="diagnosis"><h2>Sim-to-real gap: where the model and the machine still disagree</h2>"#);
    let Some(d) = d else {
        h.push_str("<p class=\"na\">The archive holds no diagnosis (record the session with <code>ballbar diagnose --record</code>).</p></section>");
        return;
    };
    let g = &d.gap;
    let _ = write!(
        h,
        r#"<p>Base model residual {} µm RMS; noise floor {} µm ({}; lag-1 autocorrelation {:.2}). Held out: {}.</p>"#,
        format_args!("{:.3}", g.base_rms_um),
        format_args!("{:.3}", g.noise_floor_um),
        esc(g.noise_source.map_or("how, the archive does not say", |s| s.description())),
        g.noise_lag1_autocorrelation,
        esc(&d.cross_validation)
    );
    h.push_str(r#"<h3>Where</h3><table id="where"><tr><th>plane and direction</th><th>arc</th><th>share of the gap above the noise</th><th>reversals</th></tr>"#);
    // A share (a fraction) as a percentage, as the terminal shows it (`16.7 %`); the fraction
    // in `data-v`.
    let percent_td = |share: f64| {
        if share.is_finite() {
            format!(r#"<td class="num" data-v="{share}">{:.1} %</td>"#, 100.0 * share)
        } else {
            "<td class=\"num\">—</td>".to_string()
        }
    };
    if g.where_.is_empty() {
        h.push_str(r#"<tr><td colspan="4" class="na">nowhere: the residual is at the noise floor</td></tr>"#);
    }
    // What is one pattern over several planes and directions (the same arc and reversals) is
    // one row; its shares in `data-v`, comma-separated.
    for group in ballbar_documents::diagnosis::grouped_where(&g.where_) {
        let w = group.members[0];
        let share_td = match group.members.len() {
            1 => percent_td(w.share),
            _ => format!(
                r#"<td class="num" data-v="{}">{}</td>"#,
                group.members.iter().map(|m| m.share.to_string()).collect::<Vec<_>>().join(","),
                esc(&group.share_text())
            ),
        };
        let _ = write!(
            h,
            "<tr><td>{}</td><td>{}</td>{share_td}<td>{}</td></tr>",
            esc(&group.runs_text()),
            esc(&group.sector_text()),
            esc(&w.reversals.join(", "))
        );
    }
    h.push_str("</table>");
    if let Some(l) = &g.locking {
        let _ = write!(
            h,
            r#"<p id="locking">Locked to: <b>{}</b> — {}</p>"#,
            esc(&l.verdict.replace('_', " ")),
            esc(&l.why)
        );
    }
    // Each accepted effect in shop-floor words first, the statistics in the table below.
    if let Some(effects) = d.effects.as_deref().filter(|e| !e.is_empty()) {
        h.push_str(r#"<h3>What the machine needs, most important first</h3><ol id="actions">"#);
        for e in effects {
            let sentence =
                ballbar_documents::advice::shop_floor(&ballbar_documents::advice::Facts {
                    subject: &e.subject,
                    parameters: &e.parameters,
                    g_before_um: e.held_out_g_before_um,
                    g_after_um: e.held_out_g_after_um,
                });
            let _ = write!(h, "<li>{}</li>", esc(&sentence));
        }
        h.push_str("</ol>");
    }
    h.push_str(r#"<h3>Unmodelled effects, most important first</h3><p class="legend" id="statistics">Excess closed: the share of the held-out excess above the noise (sqrt(RMS² − floor²)) the effect closes; RMS shrink: how much the held-out RMS itself falls (noise included), its interval ±2 jackknife standard errors; partial-F: the variance the effect explains on all the data over the noise's (a test statistic, not ISO 230-4's radial deviation F); held-out t: its held-out gain in standard errors from zero.</p><table id="effects"><tr><th>effect</th><th>parameters</th><th>held-out RMS µm</th><th>held-out G µm</th><th>excess closed</th><th>RMS shrink</th><th>interval</th><th>partial-F</th><th>held-out t</th><th>folds</th></tr>"#);
    let effects = d.effects.as_deref().unwrap_or_default();
    if effects.is_empty() {
        let tried = d
            .candidates_screened
            .map(|n| format!("{n} candidates tried"))
            .unwrap_or_else(|| "candidates tried: not recorded".into());
        let _ = write!(
            h,
            r#"<tr><td colspan="10" class="na">none stands out of the noise ({tried})</td></tr>"#
        );
    }
    let mut bars = Vec::new();
    for e in effects {
        let params: Vec<String> = e
            .parameters
            .iter()
            .map(|(k, v)| crate::vendor::parameter_text(k, *v, e.std_uncertainties.get(k).copied()))
            .collect();
        let _ = write!(
            h,
            r#"<tr data-kind="{}" data-axis="{}"><td>{}</td><td>{}</td><td>{:.3} → {:.3}</td><td>{:.2} → {:.2}</td><td class="excess" data-v="{}">{}</td>{}<td>{:.0}–{:.0} %</td><td>{}</td><td>{:.1}</td><td>{}</td></tr>"#,
            esc(&e.subject.kind),
            esc(e.subject.axis.as_deref().unwrap_or("")),
            esc(&e.description),
            esc(&params.join(", ")),
            e.held_out_rms_before_um,
            e.held_out_rms_after_um,
            e.held_out_g_before_um,
            e.held_out_g_after_um,
            e.held_out_excess_closed,
            esc(&crate::vendor::excess_share_text(
                e.held_out_excess_closed,
                e.held_out_excess.as_ref(),
                e.held_out_rms_before_um,
                e.held_out_rms_after_um,
                d.gap.noise_floor_um,
                d.gap.noise_floor_u_um
            )),
            format_args!(r#"<td class="num" data-v="{}">{:.1} %</td>"#, e.shrink, 100.0 * e.shrink),
            100.0 * e.shrink_interval[0],
            100.0 * e.shrink_interval[1],
            crate::vendor::stat_number(e.f_statistic),
            e.held_out_t,
            // An archive from a version that did not record the folds: not known.
            esc(&e.folds.as_deref().unwrap_or("not recorded").replace('_', " "))
        );
        if let Some(n) = &e.note {
            let _ = write!(h, r#"<tr class="note"><td colspan="10">note: {}</td></tr>"#, esc(n));
        }
        if e.shrink.is_finite() {
            bars.push(svg::Bar {
                label: e.description.clone(),
                value: e.shrink,
                interval: e.shrink_interval,
            });
        }
    }
    h.push_str("</table>");
    held_out_and_unexplained(h, d);
    if !bars.is_empty() {
        h.push_str("<h3>Held-out shrink of the RMS itself per effect (bars; lines: ±2 jackknife standard errors)</h3>");
        h.push_str(&svg::shrink_bars(&bars));
    }
    if !d.aliased.is_empty() {
        h.push_str(
            r#"<h3>Effects these tests cannot separate from the model</h3><ul id="aliased">"#,
        );
        for a in &d.aliased {
            // The description where the archive has it (an older one: kind and axis).
            let what = a.description.clone().unwrap_or_else(|| {
                format!("{} {}", a.subject.kind, a.subject.axis.as_deref().unwrap_or(""))
            });
            let _ = write!(
                h,
                "<li>{} — would hide in {}; separate with: {}</li>",
                esc(&what),
                esc(&a.with.join(", ")),
                esc(&a.test_to_separate)
            );
        }
        h.push_str("</ul>");
    }
    h.push_str("</section>");
}

/// The claim for the effects together, what they leave unexplained, the near misses and the
/// notes (each only where the diagnosis has it: an archive written by an older version may
/// lack them).
fn held_out_and_unexplained(h: &mut String, d: &Diagnosis) {
    let together = &d.held_out;
    let named = d.effects.as_ref().is_some_and(|e| !e.is_empty());
    if let (Some(folds), true) = (&together.folds, named) {
        let _ = write!(
            h,
            r#"<p id="held-out">Together, on {}: {}.</p>"#,
            esc(&folds.replace('_', " ")),
            esc(&crate::vendor::excess_share_text(
                together.excess_closed,
                together.excess.as_ref(),
                together.rms_before_um,
                together.rms_after_um,
                together.noise_floor_um,
                together.noise_floor_u_um
            ))
        );
    }
    if let Some(u) = &d.unexplained {
        let _ = write!(
            h,
            r#"<h3>Unexplained</h3><div id="unexplained"><p>{} of the held-out excess above the noise ({:.3} µm RMS, on {}) is left by {}; no candidate the held-out runs could judge describes it. Where the base model's excess lies:</p><ul>"#,
            crate::vendor::percent_or_unknown(u.excess_left),
            u.excess_rms_um,
            esc(&u.folds.as_deref().unwrap_or("?").replace('_', " ")),
            if named { "the effects named" } else { "the base model" }
        );
        for w in &u.where_ {
            let _ = write!(h, "<li>{}</li>", esc(w));
        }
        h.push_str("</ul>");
        if !u.nearest.is_empty() {
            h.push_str("<p>Nearest candidates, with the share of that excess each closes:</p><ul>");
            for n in &u.nearest {
                let _ = write!(
                    h,
                    "<li>{}: {}</li>",
                    esc(&n.description),
                    crate::vendor::percent_or_unknown(n.excess_closed)
                );
            }
            h.push_str("</ul>");
        }
        h.push_str("</div>");
    }
    if !d.declined.is_empty() {
        h.push_str(r#"<h3>Tried and declined, nearest misses first</h3><table id="declined"><tr><th>candidate</th><th>why not</th></tr>"#);
        for x in d.declined.iter().take(NEAR_MISSES) {
            let _ = write!(
                h,
                "<tr><td>{}</td><td>{}</td></tr>",
                esc(&x.description),
                esc(&crate::vendor::why_text(&x.why))
            );
        }
        h.push_str("</table>");
    }
    if !d.notes.is_empty() {
        h.push_str(r#"<ul id="notes">"#);
        for n in &d.notes {
            let _ = write!(h, "<li>note: {}</li>", esc(n));
        }
        h.push_str("</ul>");
    }
}

/// The report lists this many near misses (the JSON has them all).
const NEAR_MISSES: usize = 5;

fn trends(h: &mut String, machine: &str, history: &[(String, Session)]) {
    use crate::history::{Estimate, HISTORY_K, changes};
    // Sessions of this machine with a fit, in date order.
    let mut sessions: Vec<(f64, &ArchivedFit)> = history
        .iter()
        .filter(|(_, s)| {
            s.machine.as_ref().map(|m| m.spec.name.as_str()).unwrap_or(&s.info.machine_name)
                == machine
        })
        .filter_map(|(_, s)| {
            let fit = s.fit.as_ref()?;
            let first = s
                .runs
                .iter()
                .map(|r| &r.run.header)
                .min_by(|a, b| a.started_at_unix_s.total_cmp(&b.started_at_unix_s))?;
            Some((first.started_at_unix_s, fit))
        })
        .collect();
    sessions.sort_by(|a, b| a.0.total_cmp(&b.0));
    let _ = write!(
        h,
        r#"<section id="trends"><h2>Trends of machine {} over {} sessions</h2><p>Each machine parameter estimable in two sessions or more, against the session's date; bars ±2 standard uncertainties. The value axis holds every bar and spans at least {} standard uncertainties (and zero, where the values are near it), so that noise does not look like drift. <span style="color:#d35400">Thick orange segments</span>: changes beyond {HISTORY_K} combined standard uncertainties from the session before, the changes <code>ballbar history</code> flags, with the change written over them.</p>"#,
        esc(machine),
        sessions.len(),
        svg::TREND_MIN_SPAN_U
    );
    let mut ids: Vec<(String, String)> = Vec::new();
    for (_, f) in &sessions {
        for p in f.parameters.iter().take(f.n_machine) {
            if !ids.iter().any(|x| x.0 == p.id) {
                ids.push((p.id.clone(), p.unit.clone()));
            }
        }
    }
    for (id, unit) in ids {
        // Every session's estimate, for the history's rule; the points are the determined ones.
        let series: Vec<Option<Estimate>> = sessions
            .iter()
            .map(|(_, f)| {
                let p = f.parameters.iter().take(f.n_machine).find(|p| p.id == id)?;
                Some(Estimate {
                    value: p.value * p.display_factor,
                    u: p.std_uncertainty * p.display_factor,
                    estimable: p.estimable,
                })
            })
            .collect();
        let pts: Vec<svg::TrendPoint> = sessions
            .iter()
            .zip(&series)
            .zip(changes(&series))
            .filter_map(|(((t, _), e), c)| {
                let e = e.filter(|e| e.estimable)?;
                Some(svg::TrendPoint {
                    unix_s: *t,
                    value: e.value,
                    u: e.u,
                    flagged: c.filter(|c| c.flagged).map(|c| (c.change, c.combined_u)),
                })
            })
            .collect();
        if pts.len() >= 2 {
            h.push_str(&svg::trend(&id, &unit, &pts));
        }
    }
    h.push_str("</section>");
}

const CSS: &str = "body{font-family:sans-serif;margin:1.5em;color:#111}h1{font-size:1.4em}h2{font-size:1.2em;border-bottom:1px solid #999;margin-top:1.6em}h3{font-size:1em}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;padding:2px 6px;font-size:.85em}td.num{text-align:right;font-variant-numeric:tabular-nums}.na{color:#777}\
figure.polar-pair,figure.polar-single{display:inline-block;margin:.5em;break-inside:avoid}svg text.key{font-size:10px}tr.advice td{border-top:none;font-size:.8em;color:#222;padding-left:1.5em}figcaption{font-size:.8em;max-width:700px}\
svg .ring{fill:none;stroke:#ccc;stroke-width:.6}svg .ring.nominal{stroke:#888;stroke-width:1}svg .spoke{stroke:#ddd;stroke-width:.5}\
svg .trace{fill:none;stroke-width:1}svg .cw{stroke:#1f4fbf}svg .ccw{stroke:#c0392b}svg .nodir{stroke:#555}svg .model{stroke-dasharray:4 3;stroke-width:1.4}\
svg .where{fill:none;stroke:#f2b01e;stroke-width:8;stroke-opacity:.6}svg text{font-size:11px;fill:#333}\
svg text.legend{stroke:none;font-size:12px}svg text.legend.cw{fill:#1f4fbf}svg text.legend.ccw{fill:#c0392b}svg text.legend.nodir{fill:#555}\
svg text.ring-value{font-size:9px;fill:#555;paint-order:stroke;stroke:#fff;stroke-width:3px}\
svg .frame{fill:none;stroke:#888}svg .zero{stroke:#888;stroke-width:1}svg .grid.angle{stroke:#e4e4e4}figure.rotary-pair{display:inline-block;margin:.5em;break-inside:avoid}\
svg .bar{fill:#4a7fb5}svg .interval{stroke:#111;stroke-width:1.5}svg .grid{stroke:#ddd}svg .errorbar{stroke:#555}svg .point{fill:#1f4fbf}svg .trend-line{fill:none;stroke:#1f4fbf}\
";

/// The session's form, the acceptance table, and the printed page: `@page` margins that fit A4
/// and US Letter alike (the paper is the printer's: no size is forced), headings kept with what
/// follows, a table that fits on a page kept whole ([`print_layout`]), a long one's header
/// repeated on each page, figures never split, plots scaled to the page's width.
const LAYOUT_CSS: &str = "table.form{width:100%;max-width:60em}table.form th{text-align:left;font-weight:normal;color:#444;width:14em}\
table.form td{min-width:12em;height:1.4em}table.form td.fill{border-bottom:1px solid #333}.form-note{font-size:.75em;color:#555;margin:.2em 0 .8em}\
p.verdict{font-size:1.1em;padding:.3em .6em;border:2px solid #888;display:inline-block}p.verdict.pass{border-color:#2e7d32}p.verdict.fail{border-color:#c62828}\
td.verdict{font-weight:bold}td.verdict.pass{color:#2e7d32}td.verdict.fail{color:#c62828}td.verdict.undecided,td.verdict.not-checked{color:#8a6d00}td.note{font-size:.8em;color:#444}\
@media print{body{margin:0;font-size:10pt}h1{margin-top:0}h2{margin-top:1em}h1,h2,h3,h2+p,p.scales{break-after:avoid-page}\
div.keep,figure,tr,li,p.verdict{break-inside:avoid-page}thead{display:table-header-group}\
figure.polar-pair,figure.polar-single,figure.rotary-pair{display:block;margin:.3em 0}figure svg{max-width:100%;height:auto}\
figure.polar-pair svg,figure.polar-single svg,figure.rotary-pair svg{width:49.5%}a{color:inherit;text-decoration:none}}";

/// Letter's page height less the `@page` margins (279.4 − 14 − 16 mm at 96 px per inch): the
/// shorter of the two papers' page areas, in CSS px.
const PAGE_AREA_HEIGHT_PX: f64 = 249.4 / 25.4 * 96.0;

/// A row's height in print, px: a line of 8.5 pt text (11.3 px, line height 1.15) plus the
/// cell's padding and border (5 px). Measured in chromium: 18.6 px a one-line row.
const ROW_LINE_PX: f64 = 13.6;
const ROW_PAD_PX: f64 = 5.0;

/// The characters of a table row's text that fill one printed line across the page area (at
/// 8.5 pt a character is 5.5 px on average; 186 mm is 703 px, less the cells' padding): a
/// row with more text wraps.
const ROW_CHARS_PER_LINE: f64 = 100.0;

/// The `@page` rule: margins that fit A4 and Letter (the page area is 186 mm wide on A4, the
/// narrower; 249 mm high on Letter, the shorter), no size (the printer's paper), and the
/// page's own footer: the title and the page number, in place of a browser's URL.
fn page_rule(title: &str) -> String {
    // A CSS string: `\` and `"` escaped, `<` written as an escape so that no `</style>` can end it.
    let text: String = title
        .chars()
        .map(|c| match c {
            '\\' => "\\\\".to_string(),
            '"' => "\\\"".to_string(),
            '<' => "\\3c ".to_string(),
            '\n' | '\r' => " ".to_string(),
            c => c.to_string(),
        })
        .collect();
    format!(
        "@page{{size:auto;margin:14mm 12mm 16mm 12mm;@bottom-left{{content:\"{text}\";font:8pt sans-serif;color:#555}}@bottom-right{{content:\"page \" counter(page) \" of \" counter(pages);font:8pt sans-serif;color:#555}}}}"
    )
}

/// The page's tables made ready for print: a header row (a first row of `<th>` only) becomes the
/// table's `<thead>`, repeated on each printed page; a table that fits on a page (estimated
/// from its rows and their text, [`PAGE_AREA_HEIGHT_PX`]) is wrapped in `<div class="keep">`,
/// which is not broken across pages. A longer table breaks between rows.
pub(crate) fn print_layout(html: &str) -> String {
    let mut out = String::with_capacity(html.len() + 4096);
    let mut rest = html;
    while let Some(i) = rest.find("<table") {
        let after = &rest[i + 6..];
        if !(after.starts_with(' ') || after.starts_with('>')) {
            out.push_str(&rest[..i + 6]);
            rest = after;
            continue;
        }
        let Some(end) = rest[i..].find("</table>").map(|e| i + e + 8) else { break };
        out.push_str(&rest[..i]);
        let table = &rest[i..end];
        let keep = table_height_px(table) <= PAGE_AREA_HEIGHT_PX * 0.9;
        if keep {
            out.push_str(r#"<div class="keep">"#);
        }
        out.push_str(&with_thead(table));
        if keep {
            out.push_str("</div>");
        }
        rest = &rest[end..];
    }
    out.push_str(rest);
    out
}

/// `table` with its first row in a `<thead>` when that row is a header row (only `<th>`).
fn with_thead(table: &str) -> String {
    let (Some(open), Some(close)) = (table.find("<tr"), table.find("</tr>")) else {
        return table.to_string();
    };
    let first = &table[open..close + 5];
    let head = table.find('>').map_or(0, |g| g + 1);
    if open != head || first.contains("<td") || table.contains("<thead") {
        return table.to_string();
    }
    format!("{}<thead>{first}</thead>{}", &table[..open], &table[close + 5..])
}

/// A table's printed height, estimated: each row one line, or more where its text is longer
/// than [`ROW_CHARS_PER_LINE`].
fn table_height_px(table: &str) -> f64 {
    table
        .split("<tr")
        .skip(1)
        .map(|row| {
            let mut chars = 0usize;
            let mut in_tag = false;
            for c in row.chars() {
                match c {
                    '<' => in_tag = true,
                    '>' => in_tag = false,
                    _ if !in_tag => chars += 1,
                    _ => {}
                }
            }
            let lines = (chars as f64 / ROW_CHARS_PER_LINE).ceil().max(1.0);
            lines * ROW_LINE_PX + ROW_PAD_PX
        })
        .sum()
}

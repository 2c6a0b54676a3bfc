//! What the table controllers (Siemens, Fanuc, Heidenhain) share: which terms an axis's own
//! table and backlash take (the criteria of [`crate::linuxcnc`]), the value each leaves after
//! the files as the controller applies them, and the predicted trace.
//!
//! A controller module gives the text of its files and its own reading of how the controller
//! applies them, as a trim added to the commanded axis position (`trim = -δ`, the crate's
//! convention); everything after that (what a re-measurement should show) is computed here from
//! those trims, never from the model's values directly.

use std::collections::BTreeMap;

use ballbar_fit::saved::SavedModel;
use ballbar_model::{Axis, Run};

use crate::{AxisCorrection, COMPENSATION_FORMAT, Compensation, Estimate, Options, Term};

/// A controller's files as written, and the trims the controller applies from them.
pub trait ControllerFiles {
    /// Every file to write, `(name, text)`.
    fn texts(&self) -> Vec<(String, String)>;
    /// The trim the controller adds at commanded position `q_mm` of `axis` moving up
    /// (`forward`) or down, mm; 0 for an axis it does not compensate.
    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64;
    /// Whether the files compensate `axis`.
    fn has(&self, axis: Axis) -> bool;
    /// The files that carry a term (`backlash`, `scale`, `positional`) of `axis`.
    fn files_of(&self, axis: Axis, term: &str) -> Vec<String>;
    /// The resolution of a written value, mm (what the controller cannot resolve finer).
    fn resolution_mm(&self) -> f64;
    /// The trim the controller's cross-axis tables add to `output` at position `q_mm` of
    /// `input`, mm; 0 where it has none.
    fn cross_trim_mm(&self, _input: Axis, _output: Axis, _q_mm: f64) -> f64 {
        0.0
    }
    /// Whether the files have a cross-axis table (prediction skips it otherwise).
    fn has_cross(&self) -> bool {
        false
    }
    /// The files that carry the cross-axis table of `output` over `input`.
    fn cross_files_of(&self, _input: Axis, output: Axis) -> Vec<String> {
        self.files_of(output, "squareness")
    }
    /// The span of `input` the cross-axis tables of `output` cover as written, mm (an existing
    /// table merged with the new one can reach past the span the tests measured); `None`
    /// without one.
    fn cross_span_mm(&self, _input: Axis, _output: Axis) -> Option<[f64; 2]> {
        None
    }
}

/// A compensation that was active while the tests ran (`--existing`, files of the same
/// controller), as the controller applies it: read by the caller with the controller's own
/// reading of its files (the CLI uses the simulator's emulation, which refuses what the
/// controller would, naming the file and line). A trace measures what it leaves, so the files
/// written hold its values plus the measured correction.
pub trait Existing: std::fmt::Debug + Send + Sync {
    /// The controller it is for (`siemens`, `fanuc`, `heidenhain`).
    fn kind(&self) -> &str;
    /// Whether it compensates `axis` (a table or a backlash).
    fn has(&self, axis: Axis) -> bool;
    /// The trim it adds at commanded position `q_mm` of `axis` moving up (`forward`) or down,
    /// mm.
    fn trim_mm(&self, axis: Axis, q_mm: f64, forward: bool) -> f64;
    /// The span of `axis`'s own table, mm; `None` without one.
    fn span_mm(&self, axis: Axis) -> Option<[f64; 2]>;
    /// Its cross-axis tables, `(input, output, span of the input, mm)`.
    fn crosses(&self) -> Vec<(Axis, Axis, [f64; 2])>;
    /// What its cross-axis tables add to `output` at `input`'s position `q_mm`, mm.
    fn cross_trim_mm(&self, input: Axis, output: Axis, q_mm: f64) -> f64;
}

/// The axes a merged compensation writes: those the new correction compensates and those the
/// existing compensation does (kept).
pub(crate) fn merged_axes(
    per_axis: &BTreeMap<Axis, AxisCorrection>,
    existing: Option<&dyn Existing>,
) -> Vec<Axis> {
    let mut axes: Vec<Axis> = per_axis.keys().copied().collect();
    if let Some(ex) = existing {
        axes.extend(Axis::LINEAR.into_iter().filter(|a| ex.has(*a)));
    }
    axes.sort();
    axes.dedup();
    axes
}

/// The span `[min, max]` of a merged table of `axis`: the new table's ([`table_span`]) where
/// `c` has a positional correction (or `own_table`: the controller keeps the backlash in the
/// table), joined with the existing table's, so that nothing of the existing table is dropped;
/// `None` where neither has a table.
pub(crate) fn merged_span(
    options: &Options,
    axis: Axis,
    c: Option<&AxisCorrection>,
    own_table: bool,
) -> Result<Option<[f64; 2]>, String> {
    let new = match c {
        Some(c) if !c.positional.is_empty() || own_table => Some(table_span(options, axis, c)),
        _ => None,
    };
    let old = options.existing_tables.as_deref().and_then(|e| e.span_mm(axis));
    Ok(match (new, old) {
        (Some(Err(m)), None) => return Err(m),
        // A backlash alone without runs: the existing table's span holds it (a `--travel` is
        // checked before, `crate::check_travel`, so no span asked for is passed over here).
        (Some(Err(_)), Some(o)) | (None, Some(o)) => Some(o),
        (Some(Ok(n)), Some(o)) => Some([n[0].min(o[0]), n[1].max(o[1])]),
        (Some(Ok(n)), None) => Some(n),
        (None, None) => None,
    })
}

/// The existing compensation's trim of `axis` at `q`, mm (0 without one).
pub(crate) fn existing_trim(options: &Options, axis: Axis, q: f64, forward: bool) -> f64 {
    options.existing_tables.as_deref().map_or(0.0, |e| e.trim_mm(axis, q, forward))
}

/// The terms of a model selected as every controller selects them ([`crate::select`]): those
/// an axis's table and backlash take marked compensated, with their axis's correction; the
/// notes the selection makes.
pub(crate) fn select(
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
    why_not: &dyn Fn(&str) -> String,
) -> (Vec<(Term, Estimate)>, BTreeMap<Axis, AxisCorrection>, Vec<String>) {
    let mut notes = Vec::new();
    let (entries, mut per_axis) =
        crate::select(model, estimates, runs, options, why_not, &mut notes);
    if let (Some(r), Some(e)) = (&options.reading, options.existing_tables.as_deref()) {
        let trim =
            |axis: Axis, q: f64, forward: bool| e.has(axis).then(|| e.trim_mm(axis, q, forward));
        notes.extend(crate::reading::raise_by_existing(
            model,
            &mut per_axis,
            &entries,
            runs,
            r.as_ref(),
            &trim,
        ));
    }
    (entries, per_axis, notes)
}

/// Each compensated axis's number on the controller, 1-based (`AX1`, FANUC's axis 1): from
/// `--joints` (0-based, as for LinuxCNC), which then must name every compensated axis; else
/// the axis's place in X, Y, Z, A, B, C.
pub(crate) fn axis_numbers(
    axes: impl IntoIterator<Item = Axis>,
    options: &Options,
) -> Result<BTreeMap<Axis, usize>, String> {
    axes.into_iter()
        .map(|a| {
            let n = if options.joints.is_empty() {
                a.index()
            } else {
                *options.joints.get(&a).ok_or_else(|| {
                    format!(
                        "--joints names no number for {a}, which is compensated: add {a}=<number>"
                    )
                })?
            };
            Ok((a, n + 1))
        })
        .collect()
}

/// The span `[min, max]` a table of `axis` covers: `--travel`, else the measured span; an error
/// for a span that is not one.
pub(crate) fn table_span(
    options: &Options,
    axis: Axis,
    c: &AxisCorrection,
) -> Result<[f64; 2], String> {
    let Some(span) = options.travel.get(&axis).copied().or(c.measured) else {
        return Err(format!(
            "{axis}: a table covers the span the tests measured, which only the runs give: give the runs (or --travel {axis}=MIN:MAX)"
        ));
    };
    if span[1] <= span[0] || span.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "--travel {axis}={}:{}: the end must be above the start",
            span[0], span[1]
        ));
    }
    Ok(span)
}

/// The positional error of an axis the correction cancels at `q`, mm (`δ`, actual minus
/// commanded, without the backlash): a scale linearly everywhere, higher degrees held at the
/// measured span's ends (as [`AxisCorrection::trim`]).
pub(crate) fn positional_error_mm(c: &AxisCorrection, q: f64) -> f64 {
    -0.5 * (c.trim(q, true) + c.trim(q, false))
}

/// What a controller module wrote, for [`finish`]: its files, the span asked of each axis
/// table, and the cross-axis corrections its tables carry.
pub(crate) struct Written<'a> {
    /// The model the files are for.
    pub model: &'a SavedModel,
    /// The files.
    pub files: &'a dyn ControllerFiles,
    /// The span asked of each axis's table.
    pub spans: &'a BTreeMap<Axis, [f64; 2]>,
    /// The cross-axis corrections written, by `(input, output)`.
    pub crosses: &'a BTreeMap<(Axis, Axis), crate::cross::Cross>,
    /// The compensation active while the tests ran, which the files carry on.
    pub existing: Option<&'a dyn Existing>,
    /// The runs the model was fitted to.
    pub runs: &'a [Run],
    /// How the runs read a table ([`crate::reading`]).
    pub reading: Option<&'a dyn crate::reading::Reading>,
}

/// `compensation.json` (without its predictions) from the selected terms and the files as
/// written: each compensated term's files, span (`spans`: the span asked of each table, which
/// its points may pass by less than their spacing), what the existing compensation applied of
/// it (`existing`), what the files apply (`written`) and the value they leave (its value less
/// the change of the trims the controller applies, each fitted as [`crate::linuxcnc`] does).
pub(crate) fn finish(
    controller: &str,
    mut entries: Vec<(Term, Estimate)>,
    per_axis: &BTreeMap<Axis, AxisCorrection>,
    written: Written<'_>,
    joints: BTreeMap<String, usize>,
    mut notes: Vec<String>,
) -> Result<Compensation, String> {
    let Written { model, files, spans, crosses, existing, runs, reading } = written;
    for (axis, c) in per_axis {
        if let (Some(span), Some(measured)) = (spans.get(axis), c.measured)
            && (span[0] < measured[0] || span[1] > measured[1])
        {
            notes.push(format!(
                "{axis}: the table covers {:.3}..{:.3} mm, the tests measured {:.3}..{:.3} mm: {}",
                span[0],
                span[1],
                measured[0],
                measured[1],
                if c.pure_slope() {
                    "the scale, a pure slope, is extended linearly"
                } else {
                    "the correction has a curvature and is held at its values at the measured ends"
                }
            ));
        }
    }
    for (t, _) in entries.iter_mut() {
        if !t.compensated || !matches!(t.term.as_str(), "backlash" | "scale" | "positional") {
            continue;
        }
        let Some(axis) = Axis::from_name(&t.axis) else { continue };
        let c = &per_axis[&axis];
        t.files = files.files_of(axis, &t.term);
        if t.term != "backlash"
            && let Some(span) = spans.get(&axis)
        {
            t.span_mm = Some(*span);
            // As LinuxCNC's tables: only a pure slope is extended past the measured span.
            let beyond = c.measured.is_some_and(|m| span[0] < m[0] || span[1] > m[1]);
            t.extended = Some(beyond && c.pure_slope());
        }
        // Over the measured span (without runs, a backlash alone: its table's, or a point).
        let over = c.measured.or(spans.get(&axis).copied()).unwrap_or([0.0, 0.0]);
        let (applied, before) =
            crate::applied(t, c, over, &|q, f| files.trim_mm(axis, q, f), &|q, f| {
                existing.map_or(0.0, |e| e.trim_mm(axis, q, f))
            })?;
        let (v, _, _) = t.value();
        t.predicted_after = Some(crate::value_after(t, v, before, applied));
        t.existing = existing.map(|_| before);
        t.written = Some(applied);
    }
    // Cross-axis terms: the value the output's table leaves, over the input's measured span.
    for (t, _) in entries.iter_mut() {
        if !t.compensated || !matches!(t.term.as_str(), "squareness" | "straightness") {
            continue;
        }
        let Some(c) = crosses.values().find(|c| c.ids.contains(&t.id)) else { continue };
        t.files = files.cross_files_of(c.input, c.output);
        // The span as written: the measured one (or `--travel`'s), joined with an existing
        // table's of the pair and with the rows of a table that holds it among others'.
        let mut span = c.span;
        let joined = existing
            .map(|e| e.crosses())
            .unwrap_or_default()
            .into_iter()
            .filter_map(|(i, o, s)| ((i, o) == (c.input, c.output)).then_some(s));
        for s in joined.chain(files.cross_span_mm(c.input, c.output)) {
            span = [span[0].min(s[0]), span[1].max(s[1])];
        }
        t.span_mm = Some(span);
        t.extended = Some((span[0] < c.measured[0] || span[1] > c.measured[1]) && c.pure_slope());
        let applied = crate::cross::applied(t, c, &|q| files.cross_trim_mm(c.input, c.output, q))?;
        let before = match existing {
            Some(e) => {
                Some(crate::cross::applied(t, c, &|q| e.cross_trim_mm(c.input, c.output, q))?)
            }
            None => None,
        };
        let (v, _, _) = t.value();
        t.predicted_after = Some(v - (applied - before.unwrap_or(0.0)));
        t.existing = before;
        t.written = Some(applied);
    }
    if let Some(r) = reading {
        let new = |axis: Axis, q: f64, forward: bool| {
            files.has(axis).then(|| files.trim_mm(axis, q, forward))
        };
        let old = |axis: Axis, q: f64, forward: bool| {
            existing.filter(|e| e.has(axis)).map(|e| e.trim_mm(axis, q, forward))
        };
        match crate::reading::prediction_moves(model, per_axis, runs, r, &new, &old) {
            Ok(moves) => notes.extend(crate::reading::apply_moves(&mut entries, &moves)),
            Err(m) => notes.push(crate::reading::not_read_note(&m)),
        }
    }
    // What the existing compensation applied of the terms not written (not significant now,
    // an alias, ...): fitted over the span the tests measured on its own degree and a constant
    // (a squareness or straightness on its pair's column), as a written term's is.
    if let Some(e) = existing {
        for (t, est) in entries.iter_mut().filter(|(t, _)| !t.compensated) {
            t.existing = existing_of_unwritten(model, t, est, e)?;
        }
    }
    notes.extend(crate::order_note(entries.iter().map(|(t, _)| t)));
    let mut comp = Compensation {
        format: COMPENSATION_FORMAT.into(),
        controller: controller.into(),
        terms: entries.into_iter().map(|(t, _)| t).collect(),
        predicted: Vec::new(),
        joints,
        notes,
        resolution_mm: Some(files.resolution_mm()),
        predicted_runs: Vec::new(),
    };
    crate::flag_unverifiable(&mut comp);
    Ok(comp)
}

/// What the existing compensation `e` applies of a term the files do not write (see
/// [`finish`]); `None` where it has nothing of the term's axis or pair, or no span is known.
fn existing_of_unwritten(
    model: &SavedModel,
    t: &Term,
    est: &Estimate,
    e: &dyn Existing,
) -> Result<Option<f64>, String> {
    match t.term.as_str() {
        "backlash" | "scale" | "positional" => {
            let Some(axis) = Axis::from_name(&t.axis).filter(|a| e.has(*a)) else {
                return Ok(None);
            };
            let Some(span) = t.measured_span_mm.or(e.span_mm(axis)) else { return Ok(None) };
            let (reference_mm, length_mm) = crate::norm(model, axis);
            let c = AxisCorrection {
                positional: match t.term.as_str() {
                    "backlash" => Vec::new(),
                    _ => vec![(t.degree.unwrap_or(1), 0.0)],
                },
                backlash: 0.0,
                reference_mm,
                length_mm,
                measured: Some(span),
            };
            let (_, before) =
                crate::applied(t, &c, span, &|_, _| 0.0, &|q, f| e.trim_mm(axis, q, f))?;
            Ok(Some(before))
        }
        "squareness" | "straightness" => {
            let Some((input, output, degree, _)) = crate::cross::shape(model, t, est) else {
                return Ok(None);
            };
            let Some(pair_span) =
                e.crosses().into_iter().find(|c| (c.0, c.1) == (input, output)).map(|c| c.2)
            else {
                return Ok(None);
            };
            let span = t.measured_span_mm.unwrap_or(pair_span);
            let (reference_mm, length_mm) = crate::norm(model, input);
            let c = crate::cross::Cross {
                input,
                output,
                polynomial: vec![(degree, 0.0)],
                reference_mm,
                length_mm,
                measured: span,
                span,
                ids: vec![t.id.clone()],
            };
            Ok(Some(crate::cross::applied(t, &c, &|q| e.cross_trim_mm(input, output, q))?))
        }
        _ => Ok(None),
    }
}

/// The trace of each planar run predicted after the files (as [`crate::predict`]): the change
/// of the trims, those of `files` as the controller applies them less those of the `existing`
/// compensation the tests ran with.
pub fn predict(
    comp: &mut Compensation,
    files: &dyn ControllerFiles,
    existing: Option<&dyn Existing>,
    runs: &[Run],
) {
    let cross = |input, output, q| {
        files.cross_trim_mm(input, output, q)
            - existing.map_or(0.0, |e| e.cross_trim_mm(input, output, q))
    };
    let any_cross = files.has_cross() || existing.is_some_and(|e| !e.crosses().is_empty());
    let cross: Option<&dyn Fn(Axis, Axis, f64) -> f64> = any_cross.then_some(&cross);
    crate::predict_with(
        comp,
        runs,
        &|_, axis, q, forward| {
            let old = existing.filter(|e| e.has(axis));
            (files.has(axis) || old.is_some()).then(|| {
                files.trim_mm(axis, q, forward) - old.map_or(0.0, |e| e.trim_mm(axis, q, forward))
            })
        },
        cross,
    );
}

/// A controller's compensation for a model: its files and `compensation.json` with the
/// predictions. `kind` is `siemens`, `fanuc` or `heidenhain`; an existing compensation
/// ([`Options::existing_tables`]) must be of the same kind, and is merged: the files hold its
/// values plus the measured correction, and keep what it compensates that the model does not.
pub fn compensate(
    kind: &str,
    model: &SavedModel,
    estimates: &[Estimate],
    runs: &[Run],
    options: &Options,
) -> Result<(Compensation, Box<dyn ControllerFiles>), String> {
    if options.existing.is_some() {
        return Err(format!(
            "--existing: a LinuxCNC configuration cannot be merged into {kind} files: give the {kind} files that were active"
        ));
    }
    crate::check_travel(options)?;
    let existing = options.existing_tables.as_deref();
    if let Some(e) = existing
        && e.kind() != kind
    {
        return Err(format!(
            "--existing: the files are {}'s, not {kind}'s: give the {kind} files that were active",
            e.kind()
        ));
    }
    let (mut comp, files): (Compensation, Box<dyn ControllerFiles>) = match kind {
        "siemens" => {
            let (c, f) = crate::siemens::compensate(model, estimates, runs, options)?;
            (c, Box::new(f))
        }
        "fanuc" => {
            let (c, f) = crate::fanuc::compensate(model, estimates, runs, options)?;
            (c, Box::new(f))
        }
        "heidenhain" => {
            let (c, f) = crate::heidenhain::compensate(model, estimates, runs, options)?;
            (c, Box::new(f))
        }
        other => return Err(format!("--controller {other}: not written yet")),
    };
    predict(&mut comp, &*files, existing, runs);
    if existing.is_some() {
        let not_kept = match kind {
            "siemens" => {
                "; tables the existing files do not enable (MD32700, or MD32710 and SD41300 of a CEC table, at 0) are not active, and not carried over"
            }
            "heidenhain" => {
                "; CONFIG.CMA holds one row, active: the existing assignment's inactive rows, and the tables only they name, are not carried over"
            }
            _ => "",
        };
        comp.notes.push(format!(
            "--existing: the files hold the existing {kind} compensation's values plus the measured correction (each term's existing and written say how much of it each held), and every active table and backlash of the existing files, also of axes the model does not compensate{not_kept}; load them in place of the existing ones"
        ));
    }
    // A run whose circle the files make worse: what they correct offset, on that circle, what
    // they leave (a squareness against a straightness's slope there); 0.1 µm is the vendor
    // software's printed step (`vendor-b5r.md`: its circular deviations to 0.1 µm), below which
    // a change of G is not one the re-measurement could show.
    let worse: Vec<String> = comp
        .predicted
        .iter()
        .filter(|p| p.g_after_um > p.g_before_um + 0.1)
        .map(|p| format!("{} {:.2} → {:.2} µm", p.run, p.g_before_um, p.g_after_um))
        .collect();
    if !worse.is_empty() {
        comp.notes.push(format!(
            "G is predicted to rise on {}: on these circles the compensated terms offset part of those left (listed as not compensated, with why); the machine is corrected where the files act, and what is left shows more",
            worse.join(", ")
        ));
    }
    Ok((comp, files))
}

/// Models, estimates and a circle for the controllers' unit tests.
#[cfg(test)]
pub(crate) mod fixtures {
    use ballbar_fit::saved::{SAVED_MODEL_FORMAT, SavedModel, SavedParameter};
    use ballbar_model::path::CircleTest;
    use ballbar_model::{Direction, ParamClass, Plane, Run, TermClass, Unit};

    use crate::Estimate;

    /// Positional terms.
    pub const POS: ParamClass = ParamClass::Term(TermClass::Positional);
    /// Backlash terms.
    pub const BACK: ParamClass = ParamClass::Term(TermClass::Backlash);

    /// The column machine with these `(id, value mm, u mm)`.
    pub fn model(parameters: &[(&str, f64, f64)]) -> SavedModel {
        SavedModel {
            format: SAVED_MODEL_FORMAT.into(),
            machine: ballbar_model::machines::column(),
            options: Default::default(),
            parameters: parameters
                .iter()
                .map(|&(id, value, u)| SavedParameter {
                    id: id.into(),
                    value,
                    unit: Unit::Length,
                    std_uncertainty: u,
                    estimable: true,
                })
                .collect(),
            plugin: None,
            effects: Vec::new(),
            session: None,
            switch_lags_s: None,
        }
    }

    /// A length estimate without aliases.
    pub fn estimate(id: &str, class: ParamClass, value: f64, u: f64) -> Estimate {
        Estimate {
            id: id.into(),
            class,
            unit: Unit::Length,
            value,
            u,
            estimable: true,
            aliases: vec![],
        }
    }

    /// An existing compensation for the unit tests: per axis an error `slope·q` (mm) each way
    /// over `span` and a backlash `b` (mm, sent `b` lower moving negative, as SINUMERIK's and
    /// FANUC's level it), and cross-axis trims `(input, output, span, slope)`, `slope·q_input`
    /// added to the output, of controller `kind`.
    #[derive(Debug)]
    pub struct FakeExisting {
        pub kind: &'static str,
        pub axes: Vec<(ballbar_model::Axis, f64, f64, [f64; 2])>,
        pub crosses: Vec<(ballbar_model::Axis, ballbar_model::Axis, [f64; 2], f64)>,
    }

    impl crate::tables::Existing for FakeExisting {
        fn kind(&self) -> &str {
            self.kind
        }
        fn has(&self, axis: ballbar_model::Axis) -> bool {
            self.axes.iter().any(|a| a.0 == axis)
        }
        fn trim_mm(&self, axis: ballbar_model::Axis, q: f64, forward: bool) -> f64 {
            self.axes.iter().find(|a| a.0 == axis).map_or(0.0, |&(_, slope, b, span)| {
                -slope * q.clamp(span[0], span[1]) - if forward { 0.0 } else { b }
            })
        }
        fn span_mm(&self, axis: ballbar_model::Axis) -> Option<[f64; 2]> {
            self.axes.iter().find(|a| a.0 == axis).map(|a| a.3)
        }
        fn crosses(&self) -> Vec<(ballbar_model::Axis, ballbar_model::Axis, [f64; 2])> {
            self.crosses.iter().map(|c| (c.0, c.1, c.2)).collect()
        }
        fn cross_trim_mm(&self, i: ballbar_model::Axis, o: ballbar_model::Axis, q: f64) -> f64 {
            self.crosses
                .iter()
                .filter(|c| c.0 == i && c.1 == o)
                .map(|c| c.3 * q.clamp(c.2[0], c.2[1]))
                .sum()
        }
    }

    /// An XY circle of R = 100 mm about (300, 200) at 1000 mm/min, 50 Hz, CCW.
    pub fn circle() -> Run {
        CircleTest {
            plane: Plane::XY,
            direction: Direction::CCW,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm: [300.0, 200.0, 0.0],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: [0.0; 3],
            sample_rate_hz: 50.0,
            start_deg: 0.0,
            sweep_deg: 360.0,
        }
        .run("2026-11-21T10:00:00Z", 0.0, "xy-ccw-1", "column")
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::*;
    use super::*;

    /// With `--joints`, every compensated axis must be named (as for LinuxCNC); without, the
    /// axes are numbered in their order, 1-based.
    #[test]
    fn axis_numbers_come_from_joints_which_must_name_every_axis() {
        let m = model(&[("BX", 0.004, 1e-5), ("BY", 0.003, 1e-5)]);
        let est = [estimate("BX", BACK, 0.004, 1e-5), estimate("BY", BACK, 0.003, 1e-5)];
        let (_, per_axis, _) =
            select(&m, &est, &[circle()], &Options::default(), &|_| String::new());
        let numbers = axis_numbers(per_axis.keys().copied(), &Options::default()).unwrap();
        assert_eq!((numbers[&Axis::X], numbers[&Axis::Y]), (1, 2));
        let only_x = Options { joints: BTreeMap::from([(Axis::X, 3)]), ..Default::default() };
        let e = axis_numbers(per_axis.keys().copied(), &only_x).unwrap_err();
        assert!(e.contains("no number for Y"), "{e}");
        let both =
            Options { joints: BTreeMap::from([(Axis::X, 3), (Axis::Y, 0)]), ..Default::default() };
        let numbers = axis_numbers(per_axis.keys().copied(), &both).unwrap();
        assert_eq!((numbers[&Axis::X], numbers[&Axis::Y]), (4, 1));
    }

    /// A `--travel` that is not a span is an error naming it for every controller: also where
    /// an existing table gives the span (a backlash alone, without runs, would take the
    /// existing table's) and for an axis the model does not compensate; a valid one is not.
    #[test]
    fn a_travel_that_is_not_a_span_is_an_error_where_an_existing_table_gives_one() {
        let m = model(&[("BX", 0.004, 1e-5)]);
        let est = [estimate("BX", BACK, 0.004, 1e-5)];
        for kind in ["siemens", "fanuc", "heidenhain"] {
            let existing = FakeExisting {
                kind,
                axes: vec![(Axis::X, 1e-5, 0.001, [0.0, 500.0])],
                crosses: vec![],
            };
            let with = |axis: Axis, span: [f64; 2]| Options {
                existing_tables: Some(std::sync::Arc::new(FakeExisting {
                    kind,
                    axes: existing.axes.clone(),
                    crosses: vec![],
                })),
                travel: BTreeMap::from([(axis, span)]),
                ..Default::default()
            };
            for (axis, span, shown) in [
                (Axis::X, [400.0, 200.0], "--travel X=400:200"),
                (Axis::X, [0.0, f64::NAN], "--travel X=0:NaN"),
                (Axis::Y, [10.0, 10.0], "--travel Y=10:10"),
            ] {
                let Err(e) = compensate(kind, &m, &est, &[], &with(axis, span)) else {
                    panic!("{kind}: {shown} accepted");
                };
                assert!(e.contains(shown) && e.contains("above the start"), "{kind}: {e}");
            }
            assert!(
                compensate(kind, &m, &est, &[], &with(Axis::X, [0.0, 500.0])).is_ok(),
                "{kind}"
            );
        }
        // LinuxCNC: a backlash alone needs no table, and its travel is checked all the same.
        let options =
            Options { travel: BTreeMap::from([(Axis::Y, [300.0, -300.0])]), ..Default::default() };
        let e = crate::linuxcnc(&m, &est, &[], &options).unwrap_err();
        assert!(e.contains("--travel Y=300:-300"), "{e}");
    }
}

//! The page's compensation section (`<section id="compensation">`): what a compensation folder
//! (`compensation.json`, `ballbar-compensation/1`) wrote and what it left, the value each term
//! was predicted to take after it, and, with a verification (`ballbar-verification/1`), each
//! run's G predicted against measured and each term's verdict, with what each verdict that needs
//! an action means and what to do (the sentence `ballbar verify` prints).
//!
//! Every number is the documents' own (the compensation's model values and predictions, the
//! verification's refit), in `data-v` at full precision; nothing is recomputed here.

use std::fmt::Write;

use ballbar_compensate::Compensation;
use ballbar_compensate::verify::Verification;

use crate::cells::td;
use crate::svg::esc;

/// What `ballbar report --compensation DIR --verification FILE` adds to the page: either or
/// both documents, read.
#[derive(Clone, Debug, Default)]
pub struct CompensationInput {
    /// `DIR/compensation.json`.
    pub compensation: Option<Compensation>,
    /// The verification of the tests repeated with the compensation active.
    pub verification: Option<Verification>,
}

impl CompensationInput {
    /// Whether there is anything to show.
    pub fn is_empty(&self) -> bool {
        self.compensation.is_none() && self.verification.is_none()
    }
}

/// A term's value and u in its display unit, `—` for a missing one.
fn value_cells(v: f64, u: f64) -> String {
    format!("{}{}", td(v, 3), td(u, 3))
}

/// The verdict's cell: the word, with the share or factor it carries.
fn verdict_text(verdict: &str, share: Option<f64>, factor: Option<f64>) -> String {
    match (share, factor) {
        (_, Some(f)) => format!("{verdict} (×{f})"),
        (Some(s), _) => format!("{verdict} (share {s:.2})"),
        _ => verdict.to_string(),
    }
}

/// Write the section (nothing when `input` is empty).
pub fn section(h: &mut String, input: &CompensationInput) {
    if input.is_empty() {
        return;
    }
    h.push_str(r#"<section id="compensation"><h2>Compensation</h2>"#);
    if let Some(c) = &input.compensation {
        let _ = write!(
            h,
            "<p>Controller: <b>{}</b>. Values in the model's convention (the error, actual minus commanded; u the standard uncertainty, k = 1); <i>predicted after</i> is the value the files as written and interpolated leave.</p>",
            esc(&c.controller)
        );
        compensated(h, c);
        remaining(h, c);
        if !c.notes.is_empty() {
            h.push_str(r#"<ul id="compensation-notes">"#);
            for n in &c.notes {
                let _ = write!(h, "<li>{}</li>", esc(n));
            }
            h.push_str("</ul>");
        }
    }
    runs(h, input);
    if let Some(v) = &input.verification {
        verdicts(h, v);
    }
    h.push_str("</section>");
}

/// The terms the files act on.
fn compensated(h: &mut String, c: &Compensation) {
    h.push_str(r#"<h3>What was compensated</h3><table id="compensated"><tr><th>term</th><th>axis</th><th>id</th><th>value</th><th>u</th><th>unit</th><th>predicted after</th><th>existing</th><th>written</th><th>span mm</th><th>extended</th><th>files</th></tr>"#);
    let mut any = false;
    for t in c.terms.iter().filter(|t| t.compensated) {
        any = true;
        let (v, u, unit) = t.value();
        let opt = |x: Option<f64>| x.map_or("<td>—</td>".to_string(), |x| td(x, 3));
        let span = t.span_mm.map_or("—".to_string(), |s| format!("{:.3} … {:.3}", s[0], s[1]));
        let extended = match t.extended {
            Some(true) => "yes, linearly",
            Some(false) => "no",
            None => "—",
        };
        let _ = write!(
            h,
            r#"<tr data-id="{}"><td>{}</td><td>{}</td><td>{}</td>{}<td>{}</td>{}{}{}<td>{span}</td><td>{extended}</td><td>{}</td></tr>"#,
            esc(&t.id),
            esc(&t.term),
            esc(&t.axis),
            esc(&t.id),
            value_cells(v, u),
            unit,
            opt(t.predicted_after),
            opt(t.existing),
            opt(t.written),
            esc(&t.files.join(", "))
        );
    }
    if !any {
        h.push_str(r#"<tr><td colspan="12" class="na">No term was written.</td></tr>"#);
    }
    h.push_str("</table>");
    // The written terms `compensate` flagged: a repeat of the same tests may not show them.
    let flagged: Vec<String> = c
        .terms
        .iter()
        .filter(|t| t.compensated && t.verifiable_by_repeat == Some(false))
        .map(|t| {
            let (v, u, _) = t.value();
            let sessions = t
                .sessions_to_verify
                .map_or(String::new(), |n| format!(", {n} sessions before and after would"));
            format!("{} ({:.1} u{sessions})", esc(&t.id), v.abs() / u)
        })
        .collect();
    if !flagged.is_empty() {
        let _ = write!(
            h,
            r#"<p id="compensation-unverifiable">Written, but a repeat of these tests may not show the correction (below 8.5 u, or near the controller's resolution; the verification may read them not_resolved): {}; or read them back from the controller.</p>"#,
            flagged.join(", ")
        );
    }
}

/// The terms left as they are, with why and what would correct them.
fn remaining(h: &mut String, c: &Compensation) {
    h.push_str(r#"<h3>What remains</h3><table id="remaining"><tr><th>term</th><th>axis</th><th>id</th><th>value</th><th>u</th><th>unit</th><th>why not compensated, and what would correct it</th></tr>"#);
    for t in c.terms.iter().filter(|t| !t.compensated) {
        let (v, u, unit) = t.value();
        let _ = write!(
            h,
            r#"<tr data-id="{}"><td>{}</td><td>{}</td><td>{}</td>{}<td>{}</td><td>{}</td></tr>"#,
            esc(&t.id),
            esc(&t.term),
            esc(&t.axis),
            esc(&t.id),
            value_cells(v, u),
            unit,
            esc(t.why.as_deref().unwrap_or(""))
        );
    }
    h.push_str("</table>");
}

/// Per run: G before, predicted after and (with a verification) measured after, µm; the RMS
/// before and predicted after from the compensation.
fn runs(h: &mut String, input: &CompensationInput) {
    let predicted = input.compensation.as_ref().map_or(&[][..], |c| &c.predicted[..]);
    let measured = input.verification.as_ref().map_or(&[][..], |v| &v.runs[..]);
    let mut names: Vec<&str> = predicted.iter().map(|p| p.run.as_str()).collect();
    for r in measured {
        if !names.contains(&r.run.as_str()) {
            names.push(&r.run);
        }
    }
    if names.is_empty() {
        return;
    }
    h.push_str(r#"<h3>Predicted against measured, per run</h3><p>µm, about the least-squares circle (ISO 230-4 G); the prediction includes the terms left uncompensated and the noise.</p><table id="compensation-runs"><tr><th>run</th><th>RMS before</th><th>RMS predicted</th><th>G before</th><th>G predicted</th><th>G measured after</th><th>measured − predicted</th></tr>"#);
    for name in names {
        let p = predicted.iter().find(|p| p.run == name);
        let m = measured.iter().find(|r| r.run == name);
        let none = || "<td>—</td>".to_string();
        let g_before = p.map(|p| p.g_before_um).or(m.map(|m| m.g_before_um));
        let g_pred = p.map(|p| p.g_after_um).or(m.map(|m| m.g_predicted_um));
        let g_after = m.map(|m| m.g_after_um);
        let cell = |x: Option<f64>, d: usize| x.map_or_else(none, |x| td(x, d));
        let _ = write!(
            h,
            r#"<tr data-run="{}"><td>{}</td>{}{}{}{}{}{}</tr>"#,
            esc(name),
            esc(name),
            cell(p.map(|p| p.rms_before_um), 3),
            cell(p.map(|p| p.rms_after_um), 3),
            cell(g_before, 2),
            cell(g_pred, 2),
            cell(g_after, 2),
            cell(g_after.zip(g_pred).map(|(a, p)| a - p), 2)
        );
    }
    h.push_str("</table>");
}

/// Each term's verdict, and the verification's outcome.
fn verdicts(h: &mut String, v: &Verification) {
    let passed = v.passed();
    let _ = write!(
        h,
        r#"<h3>Verification</h3><p id="verification-outcome" data-passed="{passed}"><b>{}</b></p><table id="verdicts"><tr><th>term</th><th>axis</th><th>id</th><th>before</th><th>predicted</th><th>after</th><th>u</th><th>unit</th><th>compensated</th><th>verdict</th></tr>"#,
        if passed {
            "Verified: every compensated term corrected as predicted, no other term changed."
        } else {
            "Not verified: a compensated term is not corrected as predicted, or the repeat cannot tell it corrected (not_resolved), or does not measure it (not_measured), or another term changed (the verdicts say which)."
        }
    );
    for t in &v.terms {
        // A term the repeat does not measure has no value after: the refit's is a gauge's.
        let measured = t.verdict != ballbar_compensate::verify::NOT_MEASURED;
        let (after, u) = if measured { (t.after, t.u) } else { (f64::NAN, f64::NAN) };
        let _ = write!(
            h,
            r#"<tr data-id="{}" data-verdict="{}"><td>{}</td><td>{}</td><td>{}</td>{}{}{}{}<td>{}</td><td>{}</td><td>{}</td></tr>"#,
            esc(&t.id),
            esc(&t.verdict),
            esc(&t.term),
            esc(&t.axis),
            esc(&t.id),
            td(t.before, 3),
            td(t.predicted_after, 3),
            td(after, 3),
            td(u, 3),
            esc(&t.unit),
            if t.compensated { "yes" } else { "no" },
            esc(&verdict_text(&t.verdict, t.share, t.factor))
        );
        // A verdict that needs an action, in the words `ballbar verify` prints (one producer:
        // `TermCheck::advice`), beneath its row.
        if let Some(a) = t.advice() {
            let _ = write!(
                h,
                r#"<tr class="advice" data-advice-for="{}"><td colspan="10">▸ {}</td></tr>"#,
                esc(&t.id),
                esc(&a)
            );
        }
    }
    h.push_str("</table>");
    for n in &v.notes {
        let _ = write!(h, r#"<p class="verification-note">Note: {}</p>"#, esc(n));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_compensate::verify::{RunCheck, TermCheck};

    /// A compensation and its verification as the two commands write them (JSON), read back.
    fn documents() -> CompensationInput {
        let comp: Compensation = serde_json::from_str(
            r#"{"format": "ballbar-compensation/1", "controller": "linuxcnc",
                "terms": [
                  {"term": "backlash", "axis": "X", "id": "BX", "value_um": 3.806, "u_um": 0.0071,
                   "compensated": true, "files": ["joint-0.comp"], "span_mm": [150.0, 450.0],
                   "predicted_after": -0.00004},
                  {"term": "scale", "axis": "X", "id": "EXX1", "value_ppm": 56.475, "u_ppm": 0.424,
                   "compensated": true, "files": ["joint-0.comp"], "span_mm": [150.0, 450.0],
                   "extended": false, "predicted_after": 0.00002},
                  {"term": "squareness", "axis": "XY", "id": "SQXY", "value_urad": 21.299,
                   "u_urad": 0.6, "compensated": false,
                   "why": "LinuxCNC's joint compensation has no cross-axis table"}],
                "predicted": [{"run": "xy-ccw-1", "rms_before_um": 11.12, "rms_after_um": 10.75,
                               "G_before_um": 34.94, "G_after_um": 35.46}],
                "joints": {"X": 0},
                "notes": ["EXX1 (scale X) is written as fitted (--include-aliased)"]}"#,
        )
        .unwrap();
        let check =
            |id: &str, before: f64, after: f64, compensated: bool, verdict: &str| TermCheck {
                term: "t".into(),
                axis: "X".into(),
                id: id.into(),
                before,
                predicted_after: if compensated { 0.0 } else { before },
                after,
                u: 0.01,
                unit: "µm".into(),
                compensated,
                verdict: verdict.into(),
                share: None,
                factor: (verdict == "scaled").then_some(10.0),
                sessions: None,
                verifiable_by_repeat: None,
                measured_by: None,
            };
        let ver = Verification {
            format: ballbar_compensate::verify::VERIFICATION_FORMAT.into(),
            terms: vec![
                check("BX", 3.806, -0.008, true, "corrected"),
                check("EXX1", 56.475, -507.0, true, "scaled"),
                check("SQXY", 21.299, 19.936, false, "not_compensated"),
            ],
            runs: vec![RunCheck {
                run: "xy-ccw-1".into(),
                g_before_um: 34.94,
                g_predicted_um: 35.46,
                g_after_um: 35.68,
            }],
            notes: vec![],
        };
        CompensationInput { compensation: Some(comp), verification: Some(ver) }
    }

    /// The `data-v` values of the row of `table` whose `attr` is `key`, in order.
    fn row_values(html: &str, table: &str, attr: &str, key: &str) -> Vec<f64> {
        let t = &html[html.find(&format!(r#"<table id="{table}">"#)).unwrap()..];
        let t = &t[..t.find("</table>").unwrap()];
        let row = &t[t.find(&format!(r#"<tr {attr}="{key}""#)).unwrap()..];
        let row = &row[..row.find("</tr>").unwrap()];
        row.split(r#"data-v=""#)
            .skip(1)
            .map(|s| s[..s.find('"').unwrap()].parse().unwrap())
            .collect()
    }

    #[test]
    fn the_section_shows_the_documents_numbers_and_verdicts() {
        let input = documents();
        let mut h = String::new();
        section(&mut h, &input);
        let c = input.compensation.as_ref().unwrap();
        // Compensated: value, u, predicted after, as in compensation.json.
        for id in ["BX", "EXX1"] {
            let t = c.terms.iter().find(|t| t.id == id).unwrap();
            let (v, u, _) = t.value();
            assert_eq!(
                row_values(&h, "compensated", "data-id", id),
                [v, u, t.predicted_after.unwrap()],
                "{id}"
            );
        }
        // What remains: the squareness with its value and why.
        assert_eq!(row_values(&h, "remaining", "data-id", "SQXY"), [21.299, 0.6]);
        assert!(h.contains("no cross-axis table"));
        let remaining = &h[h.find(r#"<table id="remaining">"#).unwrap()..];
        let remaining = &remaining[..remaining.find("</table>").unwrap()];
        assert!(!remaining.contains(r#"data-id="BX""#), "{remaining}");
        // Per run: RMS before and predicted, G before, predicted, measured, and their difference.
        let r = row_values(&h, "compensation-runs", "data-run", "xy-ccw-1");
        assert_eq!(r[..5], [11.12, 10.75, 34.94, 35.46, 35.68]);
        assert!((r[5] - (35.68 - 35.46)).abs() < 1e-12);
        // Verdicts, with the factor of a unit mistake, and the outcome (not verified: EXX1).
        let v = input.verification.as_ref().unwrap();
        for t in &v.terms {
            assert!(h.contains(&format!(r#"data-id="{}" data-verdict="{}""#, t.id, t.verdict)));
            assert_eq!(
                row_values(&h, "verdicts", "data-id", &t.id),
                [t.before, t.predicted_after, t.after, t.u]
            );
        }
        assert!(h.contains("scaled (×10)"));
        // Beneath each verdict that needs an action, verify's own sentence; none beneath a
        // term that is as it should be.
        for t in &v.terms {
            let row = format!(r#"<tr class="advice" data-advice-for="{}">"#, t.id);
            match t.advice() {
                Some(a) => {
                    assert!(
                        h.contains(&format!("{row}<td colspan=\"10\">▸ {}</td></tr>", esc(&a))),
                        "{}",
                        t.id
                    );
                }
                None => assert!(!h.contains(&row), "{}", t.id),
            }
        }
        assert!(h.contains("a unit mistake (mm, µm or inch)"));
        assert!(h.contains(r#"data-passed="false""#) && !v.passed());
        assert!(h.contains("written as fitted"));
        // No term flagged: no paragraph of them.
        assert!(!h.contains("compensation-unverifiable"));
    }

    /// A written term `compensate` flagged (a repeat may not show it) is named below the table
    /// with its |value|/u and sessions: BX at 0.777/0.127 = 6.1 u, 2 sessions.
    #[test]
    fn a_flagged_term_is_named_with_its_sessions() {
        let mut input = documents();
        let c = input.compensation.as_mut().unwrap();
        let bx = c.terms.iter_mut().find(|t| t.id == "BX").unwrap();
        bx.value_um = Some(-0.777);
        bx.u_um = Some(0.127);
        bx.verifiable_by_repeat = Some(false);
        bx.sessions_to_verify = Some(2);
        let mut h = String::new();
        section(&mut h, &input);
        assert!(
            h.contains(r#"<p id="compensation-unverifiable">"#)
                && h.contains("BX (6.1 u, 2 sessions before and after would)"),
            "{h}"
        );
        let p = &h[h.find("compensation-unverifiable").unwrap()..];
        assert!(!p[..p.find("</p>").unwrap()].contains("EXX1"), "{p}");
    }

    /// A term the repeat does not measure has no value after on the page (the refit's is a
    /// gauge's choice): its row carries before and predicted only; compensated, it fails the
    /// verification with verify's sentence beneath it; the verification's notes are shown.
    #[test]
    fn a_term_not_measured_shows_no_value_after() {
        let mut input = documents();
        let v = input.verification.as_mut().unwrap();
        let bx = v.terms.iter_mut().find(|t| t.id == "BX").unwrap();
        bx.verdict = "not_measured".into();
        bx.measured_by = Some("circles in the XY or ZX plane".into());
        v.terms.retain(|t| t.id != "EXX1");
        v.notes = vec!["the repeated runs are not the runs compensation.json predicted".into()];
        let mut h = String::new();
        section(&mut h, &input);
        assert_eq!(row_values(&h, "verdicts", "data-id", "BX"), [3.806, 0.0]);
        assert!(h.contains(r#"data-id="BX" data-verdict="not_measured""#));
        assert!(h.contains("It is measured by circles in the XY or ZX plane"), "{h}");
        assert!(h.contains(r#"data-passed="false""#) && h.contains("(not_measured)"));
        assert!(h.contains("Note: the repeated runs are not the runs compensation.json predicted"));
    }

    #[test]
    fn either_document_alone_makes_its_part_and_none_makes_nothing() {
        let all = documents();
        let mut h = String::new();
        section(&mut h, &CompensationInput::default());
        assert!(h.is_empty());
        let only_v = CompensationInput { compensation: None, ..all.clone() };
        section(&mut h, &only_v);
        assert!(
            h.contains(r#"<table id="verdicts">"#) && !h.contains(r#"<table id="compensated">"#)
        );
        // The runs from the verification alone: G before, predicted and measured.
        assert_eq!(
            row_values(&h, "compensation-runs", "data-run", "xy-ccw-1")[..3],
            [34.94, 35.46, 35.68]
        );
        let mut h = String::new();
        section(&mut h, &CompensationInput { verification: None, ..all });
        assert!(h.contains(r#"<table id="compensated">"#) && !h.contains("Verification"));
    }
}

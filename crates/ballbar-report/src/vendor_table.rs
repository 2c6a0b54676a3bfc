//! The page's table of the vendor's analysis beside ours, compact enough to file: one row per
//! feature with the numbers and what ours is (the note's first clause), and the long texts
//! once each below it, folded: a note's further clauses, which many rows share (the
//! placement, the term set, what was tried), numbered once and referred to from every row that
//! has them; and each reason ours differs, referred to from its row.
//!
//! The JSON's `vendor_comparison` keeps every entry's whole note and reason; the page shows the
//! same texts, deduplicated.

use std::fmt::Write;

use ballbar_documents::VendorEntry;

use crate::cells::td;
use crate::svg::esc;

/// A note's clauses: the first says what ours is; the others are shared between rows. Clauses
/// are separated by `; ` outside brackets (a bracket may hold its own `; `).
pub(crate) fn clauses(note: &str) -> (&str, Vec<&str>) {
    let mut parts = Vec::new();
    let (mut depth, mut start) = (0i32, 0);
    for (i, c) in note.char_indices() {
        match c {
            '(' | '[' => depth += 1,
            ')' | ']' => depth -= 1,
            ';' if depth <= 0 && note[i + 1..].starts_with(' ') => {
                parts.push(note[start..i].trim());
                start = i + 2;
            }
            _ => {}
        }
    }
    parts.push(note[start..].trim());
    let mut parts = parts.into_iter().filter(|c| !c.is_empty());
    let first = parts.next().unwrap_or("");
    (first, parts.collect())
}

/// A vendor feature name that may wrap after its underscores (`AF_SCALE_ERROR_A` is wider
/// than the table's narrow column otherwise).
fn breakable(name: &str) -> String {
    esc(name).replace('_', "_<wbr>")
}

/// The numbered texts below the table, in order of first use.
#[derive(Default)]
struct Footnotes {
    texts: Vec<String>,
}

impl Footnotes {
    /// The 1-based number of `text`, added on its first use.
    fn number(&mut self, text: &str) -> usize {
        match self.texts.iter().position(|t| t == text) {
            Some(i) => i + 1,
            None => {
                self.texts.push(text.to_string());
                self.texts.len()
            }
        }
    }
}

/// The vendor section: an introduction, the table (`#vendor-comparison`), the shared notes
/// (`#vendor-notes`) and the reasons ours differs (`#vendor-why`), both folded.
pub(crate) fn section(h: &mut String, entries: &[VendorEntry]) {
    if entries.is_empty() {
        return;
    }
    let planes: Vec<&str> = entries.iter().fold(Vec::new(), |mut p, e| {
        if !p.contains(&e.plane.as_str()) {
            p.push(e.plane.as_str());
        }
        p
    });
    let one_plane = planes.len() == 1;
    let _ = write!(
        h,
        r#"<section id="vendor"><h2>The vendor's own analysis beside ours</h2><p>Each feature the vendor's software computed{}, in its units and sign conventions; <em>as vendor</em>: ours computed in the vendor's conventions (its placement of the samples, its term set), blank where we do not reproduce it; <em>ours</em>: our best value with its standard uncertainty u, which holds the spread between the model forms the data cannot choose between; <em>ours is</em>: what our value is. Numbers in brackets <sup>[n]</sup> refer to the notes below the table, which several rows share; <em>differs</em> links to the reason, from this file's numbers, where ours and the vendor's differ by more than the uncertainties allow. Values in brackets the vendor marks not valid.</p>"#,
        if one_plane { format!(" (plane {})", esc(planes[0])) } else { String::new() }
    );
    h.push_str(r#"<table id="vendor-comparison" class="vendor"><thead><tr>"#);
    if !one_plane {
        h.push_str("<th>plane</th>");
    }
    h.push_str("<th>feature</th><th>run</th><th>vendor</th><th>as vendor</th><th>ours</th><th>u</th><th>unit</th><th>ours is</th><th>why they differ</th></tr></thead><tbody>");
    let mut notes = Footnotes::default();
    let mut whys: Vec<(String, String)> = Vec::new();
    for e in entries {
        let d = crate::vendor::decimals(&e.unit);
        let vendor = e.vendor;
        let vendor_td = if e.vendor_valid {
            td(vendor, d)
        } else {
            format!(r#"<td class="num" data-v="{vendor}">({vendor:.d$})</td>"#)
        };
        // u to two significant digits (a small u never reads 0.00), as everywhere on the page.
        let u = match e.ours_u {
            None => "<td></td>".to_string(),
            Some(u) if u.is_finite() => format!(
                r#"<td class="num" data-v="{u}">{}</td>"#,
                crate::fit_report::value_and_u(0.0, u, d).1
            ),
            Some(u) => td(u, d),
        };
        let (first, rest) = clauses(&e.note);
        let refs: String = rest
            .iter()
            .map(|c| {
                let n = notes.number(c);
                format!(r##" <sup><a href="#vendor-note-{n}">[{n}]</a></sup>"##)
            })
            .collect();
        let why = match &e.why {
            Some(w) => {
                whys.push((e.feature.clone(), w.clone()));
                let k = whys.len();
                format!(r##"<td><a href="#vendor-why-{k}">differs ({k})</a></td>"##)
            }
            None => "<td></td>".to_string(),
        };
        h.push_str("<tr>");
        if !one_plane {
            let _ = write!(h, "<td>{}</td>", esc(&e.plane));
        }
        let _ = write!(
            h,
            r#"<td class="feature">{}</td><td class="run">{}</td>{vendor_td}{}{}{u}<td>{}</td><td class="note">{}{refs}</td>{why}</tr>"#,
            breakable(&e.feature),
            esc(e.run.as_deref().unwrap_or("")),
            td(e.ours_as_vendor.unwrap_or(f64::NAN), d),
            td(e.ours.unwrap_or(f64::NAN), d),
            esc(&e.unit),
            esc(first),
        );
    }
    h.push_str("</tbody></table>");
    if !notes.texts.is_empty() {
        let _ = write!(
            h,
            r#"<details id="vendor-notes" class="vendor-notes"><summary>Notes shared by the rows ({})</summary><ol>"#,
            notes.texts.len()
        );
        for (i, t) in notes.texts.iter().enumerate() {
            let _ = write!(h, r#"<li id="vendor-note-{}">{}</li>"#, i + 1, esc(t));
        }
        h.push_str("</ol></details>");
    }
    if !whys.is_empty() {
        let _ = write!(
            h,
            r#"<details id="vendor-why" class="vendor-notes"><summary>Why ours and the vendor's differ ({} features)</summary><ol>"#,
            whys.len()
        );
        for (i, (feature, why)) in whys.iter().enumerate() {
            let _ = write!(
                h,
                r#"<li id="vendor-why-{}"><b>{}</b>: {}</li>"#,
                i + 1,
                esc(feature),
                esc(why)
            );
        }
        h.push_str("</ol></details>");
    }
    h.push_str("</section>");
}

/// The table's style: smaller type, feature and run columns that wrap, notes in grey; the
/// folded texts print open (a filed page holds them), in small type.
pub(crate) const CSS: &str = "table.vendor td.feature{max-width:11em}table.vendor td.run{max-width:8em;font-size:.75em}\
table.vendor td.note{font-size:.75em;color:#333;max-width:28em}table.vendor sup{font-size:.8em}\
details.vendor-notes{font-size:.8em;margin:.3em 0}details.vendor-notes li{margin:.15em 0}\
@media print{details.vendor-notes::details-content{content-visibility:visible;display:block}}";

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(feature: &str, note: &str, why: Option<&str>) -> VendorEntry {
        serde_json::from_value(serde_json::json!({
            "plane": "XY", "feature": feature, "unit": "µm", "vendor": 1.0, "vendor_valid": true,
            "ours": 1.5, "ours_u": 0.1, "note": note, "why": why
        }))
        .unwrap()
    }

    /// A clause that several rows share is written once and referred to by the same number
    /// from each; a row's first clause stays in its row; a reason is listed once per row
    /// that has one, linked from it.
    #[test]
    fn shared_clauses_are_written_once_and_referred_to_by_number() {
        let shared = "placement: the vendor's even spread gives 9.93";
        let entries = [
            entry("AF_SCALE_ERROR_A", &format!("local scale of X; {shared}"), Some("a <reason>")),
            entry("AF_SCALE_ERROR_B", &format!("local scale of Y; {shared}; only B's"), None),
        ];
        let mut h = String::new();
        section(&mut h, &entries);
        assert_eq!(h.matches(shared).count(), 1, "{h}");
        assert_eq!(h.matches(r##"<a href="#vendor-note-1">[1]</a>"##).count(), 2, "{h}");
        assert!(h.contains(r#"<li id="vendor-note-2">only B's</li>"#), "{h}");
        let table = &h[..h.find("</table>").unwrap()];
        assert!(
            table.contains(">local scale of X <sup>") && table.contains(">local scale of Y <sup>"),
            "{table}"
        );
        assert!(table.contains(r##"<a href="#vendor-why-1">differs (1)</a>"##), "{table}");
        assert!(
            h.contains(r#"<li id="vendor-why-1"><b>AF_SCALE_ERROR_A</b>: a &lt;reason&gt;</li>"#),
            "{h}"
        );
        // One plane: stated once, no column.
        assert!(h.contains("(plane XY)") && !table.contains("<th>plane</th>"), "{h}");
        // The names wrap after their underscores.
        assert!(table.contains("AF_<wbr>SCALE_<wbr>ERROR_<wbr>A"), "{table}");
    }

    /// A `; ` inside brackets does not end a clause.
    #[test]
    fn clauses_split_outside_brackets_only() {
        assert_eq!(
            clauses("local squareness (µrad = µm/m; the same); as vendor: x; y"),
            ("local squareness (µrad = µm/m; the same)", vec!["as vendor: x", "y"])
        );
        assert_eq!(clauses("one"), ("one", vec![]));
        assert_eq!(clauses(""), ("", vec![]));
    }

    /// Rows of two planes keep a plane column.
    #[test]
    fn two_planes_keep_the_plane_column() {
        let mut e = entry("AF_SQUARENESS", "n", None);
        let mut h = String::new();
        let mut other = e.clone();
        other.plane = "YZ".into();
        e.plane = "XY".into();
        section(&mut h, &[e, other]);
        assert!(h.contains("<th>plane</th>") && h.contains("<td>YZ</td>"), "{h}");
        assert!(!h.contains("vendor-notes"), "no shared clauses, no notes list: {h}");
    }
}

//! What a fit determines where the tests are and what it cannot tell from something else
//! ([`ballbar_fit::alias`]), for the terminal and for the `ballbar-fit/1` document (`local`,
//! `aliases`, each parameter's `conditional_on_aliases`).

use std::fmt::Write as _;

use ballbar_documents::fit as doc;
use ballbar_fit::Fit;
use ballbar_fit::alias::{Alias, Assessment, Move, Quantity};
use ballbar_model::{Model, Run};

use crate::fit_report::value_and_u;

/// At most this many moved quantities are listed per alias on the terminal (the largest, in
/// units of their u); the JSON lists all.
const SHOWN_MOVES: usize = 6;

/// A move's size at the candidate's plausible size, in units of the quantity's u.
fn weight(a: &Alias, m: &Move) -> f64 {
    (a.candidate.plausible_size() * m.per_unit).abs() / m.std_uncertainty.max(f64::MIN_POSITIVE)
}

/// The terminal section.
pub fn terminal(fit: &Fit, a: &Assessment) -> String {
    let mut s = String::new();
    if !a.local.is_empty() {
        let _ = writeln!(
            s,
            "\nWhat each test determines where it is: the error field's linear part at the circle's centre (local scale J_UU, local squareness -(J_UV + J_VU), the sign of SQ above; u: standard uncertainty, k = 1). The pivot and the tool length given move these only through the exact chain's second-order geometry (a few 1e-3 of a value where the fitted angles are hundreds of µrad): where that exceeds a tenth of u the alias below says so."
        );
        let _ = writeln!(s, "  {:<46} {:<22} {:>10} {:>9}  unit", "test", "quantity", "value", "u");
        let mut last = String::new();
        for l in &a.local {
            let k = l.unit.display_factor();
            let test = l.test_text();
            let shown = if test == last { String::new() } else { test.clone() };
            last = test;
            let (value, u) = if l.estimate.estimable {
                value_and_u(l.estimate.value * k, l.estimate.std_uncertainty * k, 2)
            } else {
                ("not determined".into(), String::new())
            };
            let mark = if l.conditional_on_gauges.is_empty() { "" } else { " *" };
            let _ = writeln!(
                s,
                "  {shown:<46} {:<22} {value:>10} {u:>9}  {}{mark}",
                l.name,
                l.unit.display_name()
            );
        }
    }
    if a.aliases.is_empty() {
        let _ = writeln!(
            s,
            "\nNo alias: none of the {} plausible terms and set-up values tried (higher positional and straightness degrees, angular errors, the pivot, the tool length) would hide in the base model and move a reported value.",
            a.candidates_tried
        );
        return s;
    }
    let _ = writeln!(
        s,
        "\nWhat these runs cannot tell from the base model: each alias, what carries it, the values it moves (value ± u as fitted → the value if the alternative holds, and u with half that distance in quadrature; for set-up values, the change per 100 mm), and the test that separates them. JSON: `aliases`, each parameter's `conditional_on_aliases`."
    );
    // An alias whose alternative leaves every value it moves within its u is listed in one
    // line (the data hold either explanation and the values barely differ); the JSON has it all.
    let material = |al: &Alias| {
        al.moves
            .iter()
            .any(|m| m.alternative.is_none_or(|alt| (alt - m.value).abs() > m.std_uncertainty))
    };
    let mut minor = Vec::new();
    for (k, al) in a.aliases.iter().enumerate() {
        if !material(al) {
            minor.push(format!("[{k}] {}", al.candidate.description()));
            continue;
        }
        let _ = writeln!(
            s,
            "  [{k}] {} → carried by {} ({:.1e} of it outside the base)",
            al.candidate.description(),
            al.with.join(", "),
            al.visible_share
        );
        if let Some(t) = al.alternative_text(fit) {
            let _ = writeln!(s, "      {t}:");
        }
        let mut moves: Vec<&Move> = al.moves.iter().collect();
        moves.sort_by(|x, y| weight(al, y).total_cmp(&weight(al, x)));
        for m in moves.iter().take(SHOWN_MOVES) {
            let f = m.unit.display_factor();
            let (value, u) = value_and_u(m.value * f, m.std_uncertainty * f, 2);
            let unit = m.unit.display_name();
            let tail = match m.alternative {
                Some(alt) => {
                    let (alt, uw) = value_and_u(alt * f + 0.0, m.u_with_spread * f, 2);
                    format!("→ {alt} (u with the alias {uw})")
                }
                None if al.candidate.is_metadata() => {
                    format!("moves {:+.3} {unit} per 100 mm", 100.0 * m.per_unit * f)
                }
                None => {
                    let size = al.candidate.plausible_size();
                    let cu = al.candidate.unit();
                    format!(
                        "moves {:+.3} {unit} per {} {} of it",
                        size * m.per_unit * f,
                        size * cu.display_factor(),
                        cu.display_name()
                    )
                }
            };
            let _ = writeln!(s, "        {:<58} {value:>10} ± {u:<8} {unit:<5} {tail}", m.name);
        }
        if moves.len() > SHOWN_MOVES {
            let _ = writeln!(s, "        and {} more (JSON)", moves.len() - SHOWN_MOVES);
        }
        let _ = writeln!(s, "      separate with: {}", al.candidate.test_to_separate());
    }
    if !minor.is_empty() {
        let _ = writeln!(
            s,
            "  also aliased, their alternative within u of every value they move: {}",
            minor.join("; ")
        );
    }
    s
}

/// The document's `local` and `aliases`, and each parameter's `conditional_on_aliases`.
pub fn fill(json: &mut doc::Fit, model: &Model, fit: &Fit, a: &Assessment, runs: &[Run]) {
    json.local = a
        .local
        .iter()
        .enumerate()
        .map(|(i, l)| {
            let k = l.unit.display_factor();
            let e = l.estimate;
            doc::LocalQuantity {
                name: l.name.clone(),
                plane: l.plane.to_string(),
                pivot_mm: l.pivot_mm,
                tool_ball_mm: l.tool_ball_mm,
                runs: l.runs.iter().map(|&r| runs[r].name()).collect(),
                estimate: doc::Estimate {
                    name: l.name.clone(),
                    unit: l.unit.display_name().into(),
                    value: e.estimable.then_some(e.value * k),
                    std_uncertainty: e.estimable.then_some(e.std_uncertainty * k),
                    estimable: e.estimable,
                    conditional_on_gauges: l.conditional_on_gauges.clone(),
                    conditional_on_aliases: a.conditional_on(Quantity::Local(i)),
                },
            }
        })
        .collect();
    json.aliases = documents(fit, a);
    for (j, p) in json.parameters.iter_mut().enumerate().take(fit.n_machine) {
        let q = Quantity::Parameter(j);
        p.conditional_on_aliases = a.conditional_on(q);
        let spreads: Vec<f64> = p
            .conditional_on_aliases
            .iter()
            .filter_map(|&k| a.move_of(k, q)?.alternative.map(|alt| 0.5 * (alt - fit.values[j])))
            .collect();
        if !spreads.is_empty() {
            let k = fit.parameters[j].unit.display_factor();
            let u2 = fit.std_uncertainty[j].powi(2) + spreads.iter().map(|x| x * x).sum::<f64>();
            p.std_uncertainty_with_aliases = Some(u2.sqrt() * k);
        }
    }
    let functionals = crate::fit_report::paper_functionals(model, fit, runs);
    for (q, c) in json.paper.quantities.iter_mut().zip(functionals) {
        let on = a.conditional_functional(fit, &c);
        q.paper.conditional_on_aliases = on.clone();
        q.vendor.conditional_on_aliases = on;
    }
}

/// The aliases as the documents state them (`ballbar-fit/1`'s `aliases`; `diagnose` joins
/// them to its `aliased`).
pub fn documents(fit: &Fit, a: &Assessment) -> Vec<doc::Alias> {
    a.aliases
        .iter()
        .map(|al| doc::Alias {
            kind: al.candidate.kind().into(),
            axis: al.candidate.axis(),
            description: al.candidate.description(),
            metadata: al.candidate.is_metadata(),
            with: al.with.clone(),
            visible_share: al.visible_share,
            alternative: al.alternative_text(fit),
            test_to_separate: al.candidate.test_to_separate().into(),
            moves: al
                .moves
                .iter()
                .map(|m| {
                    let f = m.unit.display_factor();
                    doc::Move {
                        quantity: m.name.clone(),
                        unit: m.unit.display_name().into(),
                        value: m.value * f,
                        std_uncertainty: m.std_uncertainty * f,
                        alternative: m.alternative.map(|x| x * f),
                        std_uncertainty_with_alias: m.u_with_spread * f,
                        per_100_mm: al.candidate.is_metadata().then_some(100.0 * m.per_unit * f),
                        at_plausible_size: (!al.candidate.is_metadata())
                            .then_some(al.candidate.plausible_size() * m.per_unit * f),
                    }
                })
                .collect(),
        })
        .collect()
}

/// The page's section (`local`): what each test determines where it is, and each alias with
/// the values it moves and the test that separates it, as two compact tables (the terminal's
/// two sections, the JSON's `local` and `aliases`; at most [`SHOWN_MOVES`] moves per alias,
/// the largest, as on the terminal).
pub(crate) fn page_section(h: &mut String, fit: &Fit, a: &Assessment) {
    use crate::cells::td;
    use crate::svg::esc;
    let places = |u: f64| crate::fit_report::u_decimals(u).unwrap_or(2);
    h.push_str(r#"<section id="local"><h2>What each test determines, and what the runs cannot tell apart</h2>"#);
    if a.local.is_empty() {
        h.push_str(r#"<p class="na">No planar test: no local quantities.</p>"#);
    } else {
        h.push_str(r#"<h3>What each test determines where it is</h3><p>The error field's linear part at the circle's centre (local scale, local squareness; u: standard uncertainty, k = 1): these do not move with the pivot or tool length given. * conditional on a fixed gauge.</p><table id="local-values"><tr><th>test</th><th>quantity</th><th>value</th><th>u</th><th>unit</th></tr>"#);
        let mut last = String::new();
        for (i, l) in a.local.iter().enumerate() {
            let k = l.unit.display_factor();
            let test = l.test_text();
            let shown = if test == last { String::new() } else { test.clone() };
            last = test;
            let mark = if l.conditional_on_gauges.is_empty() { "" } else { " *" };
            let _ = write!(
                h,
                r#"<tr data-local="{i}"><td>{}</td><td>{}</td>"#,
                esc(&shown),
                esc(&l.name)
            );
            if l.estimate.estimable {
                let (v, u) = (l.estimate.value * k, l.estimate.std_uncertainty * k);
                let _ = write!(h, "{}{}", td(v, places(u)), td(u, places(u)));
            } else {
                h.push_str(r#"<td colspan="2">not determined</td>"#);
            }
            let _ = write!(h, "<td>{}{mark}</td></tr>", esc(l.unit.display_name()));
        }
        h.push_str("</table>");
    }
    if a.aliases.is_empty() {
        let _ = write!(
            h,
            r#"<p id="no-alias">No alias: none of the {} plausible terms and set-up values tried would hide in the base model and move a reported value.</p></section>"#,
            a.candidates_tried
        );
        return;
    }
    h.push_str(r#"<h3>What these runs cannot tell from the base model</h3><p>Each alias: what carries it, the values it moves (as fitted → if the alternative holds, with u holding half that distance; for set-up values the change per 100 mm) and the test that separates them.</p><table id="aliases"><tr><th>alias</th><th>carried by</th><th>moves</th><th>as fitted</th><th>u</th><th>alternative</th><th>u with it</th><th>unit</th><th>separate with</th></tr>"#);
    for (k, al) in a.aliases.iter().enumerate() {
        let mut moves: Vec<&Move> = al.moves.iter().collect();
        moves.sort_by(|x, y| weight(al, y).total_cmp(&weight(al, x)));
        moves.truncate(SHOWN_MOVES);
        let span = moves.len().max(1);
        let head = format!(
            r#"<td rowspan="{span}">[{k}] {}{}</td><td rowspan="{span}">{}</td>"#,
            esc(&al.candidate.description()),
            al.alternative_text(fit)
                .map(|t| format!("<br><small>{}</small>", esc(&t)))
                .unwrap_or_default(),
            esc(&al.with.join(", "))
        );
        let tail = format!(r#"<td rowspan="{span}">{}</td>"#, esc(al.candidate.test_to_separate()));
        if moves.is_empty() {
            let _ = write!(h, r#"<tr data-alias="{k}">{head}<td colspan="6">—</td>{tail}</tr>"#);
            continue;
        }
        for (i, m) in moves.iter().enumerate() {
            let f = m.unit.display_factor();
            let (v, u) = (m.value * f, m.std_uncertainty * f);
            let d = places(u);
            let alt = match m.alternative {
                Some(alt) => format!(
                    "{}{}",
                    td(alt * f, d),
                    td(m.u_with_spread * f, places(m.u_with_spread * f))
                ),
                None if al.candidate.is_metadata() => {
                    format!(r#"<td colspan="2">{:+.3} per 100 mm</td>"#, 100.0 * m.per_unit * f)
                }
                None => format!(
                    r#"<td colspan="2">{:+.3} per {} {}</td>"#,
                    al.candidate.plausible_size() * m.per_unit * f,
                    al.candidate.plausible_size() * al.candidate.unit().display_factor(),
                    esc(al.candidate.unit().display_name())
                ),
            };
            let _ = write!(
                h,
                r#"<tr data-alias="{k}">{}<td>{}</td>{}{}{alt}<td>{}</td>{}</tr>"#,
                if i == 0 { head.as_str() } else { "" },
                esc(&m.name),
                td(v, d),
                td(u, d),
                esc(m.unit.display_name()),
                if i == 0 { tail.as_str() } else { "" },
            );
        }
    }
    h.push_str("</table></section>");
}

//! What the output says of the defaults taken for runs that change a result
//! (`ballbar_model::run::DefaultedGeometry`: a tool ball not given): the sentence for the
//! terminal and the page, and the `"assumed"` entries of the JSON.

use ballbar_documents::Assumed;
use ballbar_model::Run;
use ballbar_model::run::{DefaultedGeometry, defaulted_geometry};

/// "all 6 runs", "either run" (of two), "run xy-cw-1 (1 of 6)", "runs a, b, c (3 of 6)"; at
/// most six names.
pub fn runs_text(d: &DefaultedGeometry) -> String {
    const SHOWN: usize = 6;
    if d.runs.len() == d.of && d.of == 2 {
        return "either run".into();
    }
    if d.runs.len() == d.of && d.of > 2 {
        return format!("all {} runs", d.of);
    }
    let mut names = d.runs.iter().take(SHOWN).cloned().collect::<Vec<_>>().join(", ");
    if d.runs.len() > SHOWN {
        names.push_str(&format!(" and {} more", d.runs.len() - SHOWN));
    }
    let noun = if d.runs.len() == 1 { "run" } else { "runs" };
    format!("{noun} {names} ({} of {})", d.runs.len(), d.of)
}

/// What depends on the value taken.
pub fn depends(d: &DefaultedGeometry) -> &'static str {
    if d.free {
        "it is the Abbe arm of every angular error and, in a free run, places the table ball: the positional, squareness and rotary location values and the model's predictions depend on it"
    } else {
        "it is the Abbe arm of the angular errors: the positional and squareness values and the model's predictions depend on it"
    }
}

/// The sentence for the output (no `note:` prefix), with how to give the value.
pub fn sentence(d: &DefaultedGeometry) -> String {
    let v = d.value_mm;
    let how = if d.vendor {
        "give it with --tool-ball-mm X,Y,Z (a .b5r file has no tool length; z is minus the tool length) or in the run headers"
    } else {
        "give it in the run headers"
    };
    format!(
        "{} is not given in {}: taken as {}, {}, {} mm, a tool length of {} mm; {}; {how}",
        d.key,
        runs_text(d),
        v[0],
        v[1],
        v[2],
        -v[2] + 0.0,
        depends(d)
    )
}

/// The sentence(s) that state the defaults taken for `runs` that change a result, for every
/// output that fits or predicts from them (terminal, report); `None` when there are none.
pub fn note<'a>(runs: impl IntoIterator<Item = &'a Run>) -> Option<String> {
    let all = defaulted_geometry(runs);
    (!all.is_empty()).then(|| all.iter().map(sentence).collect::<Vec<_>>().join("; "))
}

/// The same defaults for the documents (`assumed` in `fit`, `diagnose` and `replay --json`): one
/// entry per header key taken at its default where that changes a result, with the runs, the
/// value taken and what depends on it; empty when none.
pub fn entries<'a>(runs: impl IntoIterator<Item = &'a Run>) -> Vec<Assumed> {
    defaulted_geometry(runs)
        .iter()
        .map(|d| Assumed {
            key: d.key.into(),
            value_mm: d.value_mm,
            runs: d.runs.clone(),
            of_runs: d.of,
            depends: depends(d).into(),
            note: sentence(d),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::run::{DefaultedKeys, RunHeader};
    use ballbar_model::{Direction, Plane};

    /// A run without samples, with the tool ball `tool` (`None`: left out).
    fn run(name: &str, plane: Plane, tool: Option<[f64; 3]>) -> Run {
        Run {
            header: RunHeader {
                format_version: 1,
                machine: None,
                plane,
                direction: Some(Direction::CCW),
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: [0.0; 3],
                table_ball_mm: [0.0; 3],
                tool_ball_mm: tool.unwrap_or([0.0; 3]),
                defaulted: DefaultedKeys { table_ball_mm: true, tool_ball_mm: tool.is_none() },
                started_at: "2026-11-21T10:00:00Z".into(),
                started_at_unix_s: 0.0,
                run_id: Some(name.into()),
                extra: Vec::new(),
            },
            source: format!("{name}.csv"),
            t_s: Vec::new(),
            axes: Default::default(),
            dr_mm: Vec::new(),
            lines: Vec::new(),
        }
    }

    #[test]
    fn a_tool_ball_not_given_is_stated_naming_the_runs_and_one_given_as_zero_is_not() {
        let given =
            [run("a", Plane::XY, Some([0.0, 0.0, -100.0])), run("b", Plane::XY, Some([0.0; 3]))];
        assert_eq!(note(&given), None);
        assert_eq!(entries(&given), vec![]);
        let all: Vec<Run> = (0..6).map(|k| run(&format!("r{k}"), Plane::XY, None)).collect();
        assert_eq!(
            note(&all).unwrap(),
            "tool_ball_mm is not given in all 6 runs: taken as 0, 0, 0 mm, a tool length of 0 mm; it is the Abbe arm of the angular errors: the positional and squareness values and the model's predictions depend on it; give it in the run headers"
        );
        assert_eq!(entries(&all)[0].of_runs, 6);
        let mixed = [
            run("a", Plane::XY, Some([0.0, 0.0, -100.0])),
            run("b", Plane::YZ, None),
            run("c", Plane::Free, None),
        ];
        let d = &defaulted_geometry(&mixed)[0];
        assert_eq!(runs_text(d), "runs b, c (2 of 3)");
        assert!(d.free && depends(d).contains("rotary location"));
        let many: Vec<Run> = (0..9)
            .map(|k| run(&format!("r{k}"), Plane::XY, (k == 0).then_some([0.0; 3])))
            .collect();
        assert_eq!(
            runs_text(&defaulted_geometry(&many)[0]),
            "runs r1, r2, r3, r4, r5, r6 and 2 more (8 of 9)"
        );
        let one = [run("a", Plane::XY, Some([0.0; 3])), run("b", Plane::XY, None)];
        assert_eq!(runs_text(&defaulted_geometry(&one)[0]), "run b (1 of 2)");
        let two = [run("a", Plane::XY, None), run("b", Plane::XY, None)];
        assert!(note(&two).unwrap().starts_with("tool_ball_mm is not given in either run: "));
    }
}

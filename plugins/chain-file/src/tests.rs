//! Unit tests: the shipped chain files, the column file against the compiled column machine,
//! the expansion of the error list, and malformed files, each at its exact line and column.

use ballbar_model::Axis;
use ballbar_model::chain::JointKind;
use ballbar_model::machine::{MachineSpec, Model, ModelOptions, TermSpec, paper_terms};

use super::*;
use crate::locate::{Position, Step, locate};

fn fixture(name: &str) -> String {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/machines").join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

const FIXTURES: [&str; 4] =
    ["column.ron", "gantry.ron", "five-axis-ac-trunnion.ron", "five-axis-bc-head-table.ron"];

fn joint_names(list: &[ballbar_model::machine::JointSpec]) -> Vec<&str> {
    list.iter().map(|j| j.name.as_str()).collect()
}

fn parameter_ids(spec: &MachineSpec) -> Vec<String> {
    Model::new(spec.clone(), ModelOptions::default())
        .unwrap()
        .parameters()
        .into_iter()
        .map(|p| p.id)
        .collect()
}

#[test]
fn every_shipped_chain_file_parses_into_the_machine_it_describes() {
    for f in FIXTURES {
        let spec = parse(&fixture(f)).unwrap_or_else(|e| panic!("{f}:{e}"));
        Model::new(spec.clone(), ModelOptions::default()).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(format!("{}.ron", spec.name), f, "the machine is named after its file");
    }
    let gantry = parse(&fixture("gantry.ron")).unwrap();
    assert_eq!(joint_names(&gantry.tool), ["X bridge", "Y carriage", "Z ram"]);
    assert!(gantry.workpiece.is_empty(), "a fixed table: the workpiece branch is the base");
    assert!(
        parameter_ids(&gantry).iter().any(|id| id == "ECX1")
            && parameter_ids(&gantry).iter().any(|id| id == "EBY1")
    );

    let ac = parse(&fixture("five-axis-ac-trunnion.ron")).unwrap();
    assert_eq!(joint_names(&ac.tool), ["Z head"]);
    assert_eq!(joint_names(&ac.workpiece), ["Y saddle", "X slide", "A trunnion", "C table"]);
    assert_eq!(ac.workpiece[2].kind, JointKind::Rotary);
    assert_eq!(ac.workpiece[3].origin_mm, [0.0, 0.0, -60.0]);
    let ids = parameter_ids(&ac);
    for id in [
        "EX0C", "EY0C", "EA0C", "EB0C", "EC0C", "EY0A", "EZ0A", "EA0A", "EB0A", "EC0A", "SQXY",
        "SQYZ", "SQZX",
    ] {
        assert!(ids.iter().any(|p| p == id), "{id} in {ids:?}");
    }

    let bc = parse(&fixture("five-axis-bc-head-table.ron")).unwrap();
    assert_eq!(joint_names(&bc.tool), ["X column", "Z ram", "B head"]);
    assert_eq!(joint_names(&bc.workpiece), ["Y table", "C table"]);
    let ids = parameter_ids(&bc);
    for id in ["EX0B", "EZ0B", "EA0B", "EB0B", "EC0B", "EX0C", "EY0C", "EA0C", "EB0C", "EC0C"] {
        assert!(ids.iter().any(|p| p == id), "{id} in {ids:?}");
    }
}

#[test]
fn the_column_chain_file_is_the_compiled_column_machine() {
    let file = parse(&fixture("column.ron")).unwrap();
    let compiled = ballbar_model::machines::column();
    assert_eq!(file.name, compiled.name);
    assert_eq!(file.tool, compiled.tool);
    assert_eq!(file.workpiece, compiled.workpiece);
    assert_eq!(file.normalisation, compiled.normalisation);
    assert_eq!(file.terms, compiled.terms);
    assert_eq!(file.terms, paper_terms());
}

#[test]
fn describe_returns_the_machine_as_ron_and_needs_a_file() {
    let text = fixture("gantry.ron");
    let ron_text = describe(&text).unwrap();
    let back: MachineSpec = ron::from_str(&ron_text).unwrap();
    assert_eq!(back, parse(&text).unwrap());
    let e = describe("").unwrap_err();
    assert!(e.contains("needs one") && e.contains("--machine-file"), "{e}");
    // A wrong file's message carries its place, for the host to put the file name in front.
    let e = describe("(schema: 3)").unwrap_err();
    assert!(e.starts_with("1:10: schema 3 is newer"), "{e}");
}

/// A small valid file; the malformed cases below change one thing in it.
const BASE_FILE: &str = r#"(
    schema: 2,
    name: "t",
    version: "1",
    description: "test machine",
    joints: [
        (name: "Z", parent: "base", axis: Z, kind: Linear, direction: (0, 0, 1), origin_mm: (0, 0, 0)),
        (name: "Y", parent: "base", axis: Y, kind: Linear, direction: (0, 1, 0), origin_mm: (0, 0, 0)),
        (name: "X", parent: "Y", axis: X, kind: Linear, direction: (1, 0, 0), origin_mm: (0, 0, 0)),
        (name: "C", parent: "X", axis: C, kind: Rotary, direction: (0, 0, 1), origin_mm: (0, 0, 0)),
    ],
    tool: "Z",
    workpiece: "C",
    normalisation: [
        (axis: X, reference_mm: 0, length_mm: 250),
        (axis: Y, reference_mm: 0, length_mm: 250),
        (axis: Z, reference_mm: 0, length_mm: 250),
    ],
    errors: [
        Paper,
        RotaryLocation(["EX0C", "EY0C"]),
    ],
)"#;

/// `BASE_FILE` with `from` replaced by `to` (which must occur once).
fn changed(from: &str, to: &str) -> String {
    assert_eq!(BASE_FILE.matches(from).count(), 1, "{from}");
    BASE_FILE.replacen(from, to, 1)
}

/// The text from a 1-based line and column on, to the end of that line.
fn text_at(text: &str, line: usize, column: usize) -> String {
    text.lines().nth(line - 1).map(|l| l.chars().skip(column - 1).collect()).unwrap_or_default()
}

/// Parse `text`, which must fail at exactly `line`:`column`, where the text starts with
/// `points_at`, with a message containing `says`.
fn fails_at(text: &str, line: usize, column: usize, points_at: &str, says: &str) {
    let e = match parse(text) {
        Ok(spec) => panic!("parsed, but should fail with '{says}': {spec:?}"),
        Err(e) => e,
    };
    assert_eq!(
        (e.line, e.column),
        (line, column),
        "{e}\n  at: {}",
        text_at(text, e.line, e.column)
    );
    assert!(
        text_at(text, line, column).starts_with(points_at),
        "{e}: the place reads '{}'",
        text_at(text, line, column)
    );
    assert!(e.message.contains(says), "{e}");
}

#[test]
fn the_base_file_of_the_malformed_cases_is_valid() {
    let spec = parse(BASE_FILE).unwrap();
    assert_eq!(joint_names(&spec.workpiece), ["Y", "X", "C"]);
    assert_eq!(
        spec.terms.last(),
        Some(&TermSpec::RotaryLocation { axis: Axis::C, components: vec![Axis::X, Axis::Y] })
    );
}

#[test]
fn an_unknown_field_is_an_error_at_its_name() {
    fails_at(
        &changed("    tool: \"Z\",", "    tool: \"Z\",\n    spindle: 3,"),
        13,
        5,
        "spindle",
        "Unexpected field named `spindle`",
    );
    fails_at(
        &changed("axis: X, reference_mm", "axis: X, refrence_mm"),
        15,
        19,
        "refrence_mm",
        "Unexpected field named `refrence_mm`",
    );
    fails_at(
        &changed("kind: Rotary,", "kind: Rotary, colour: 3,"),
        10,
        57,
        "colour",
        "Unexpected field named `colour`",
    );
    fails_at(
        &changed("        Paper,", "        Backlash(axis: X, size_um: 3),"),
        20,
        27,
        "size_um",
        "Unexpected field named `size_um`",
    );
}

#[test]
fn a_value_of_the_wrong_type_is_an_error_at_the_value() {
    fails_at(&changed("name: \"t\"", "name: 7"), 3, 11, "7", "Expected string");
    fails_at(
        &changed("length_mm: 250),\n        (axis: Y", "length_mm: \"250\"),\n        (axis: Y"),
        15,
        47,
        "\"250\"",
        "Expected float",
    );
    fails_at(
        &changed("axis: C, kind: Rotary", "axis: Q, kind: Rotary"),
        10,
        40,
        "Q",
        "Unexpected variant named `Q`",
    );
    fails_at(
        &changed("        Paper,", "        Papr,"),
        20,
        9,
        "Papr",
        "Unexpected variant named `Papr`",
    );
}

#[test]
fn a_parent_that_is_not_listed_before_is_an_error_at_the_parent() {
    // ron places a string's error at its first character, inside the quotes.
    fails_at(
        &changed("parent: \"Y\"", "parent: \"W\""),
        9,
        30,
        "W\"",
        "parent 'W' is not a joint listed before this one",
    );
    // A parent listed later is the same mistake (and the rule that rules out cycles).
    fails_at(
        &changed("(name: \"Y\", parent: \"base\"", "(name: \"Y\", parent: \"X\""),
        8,
        30,
        "X\"",
        "parent 'X' is not a joint listed before",
    );
    fails_at(
        &changed("(name: \"X\", parent: \"Y\"", "(name: \"X\", parent: \"X\""),
        9,
        30,
        "X\"",
        "cannot be its own parent",
    );
}

#[test]
fn a_zero_or_non_finite_direction_is_an_error_at_the_direction() {
    // The vector is checked once read: the place is its closing parenthesis.
    let zero = changed("kind: Rotary, direction: (0, 0, 1)", "kind: Rotary, direction: (0, 0, 0)");
    fails_at(&zero, 10, 76, "), origin_mm", "direction must be a non-zero vector, found (0, 0, 0)");
    let nan = changed("kind: Rotary, direction: (0, 0, 1)", "kind: Rotary, direction: (0, NaN, 1)");
    fails_at(&nan, 10, 78, "), origin_mm", "direction must be finite");
}

#[test]
fn a_schema_newer_than_this_plugin_is_an_error_at_the_number() {
    fails_at(
        &changed("schema: 2", "schema: 3"),
        2,
        13,
        "3,",
        "schema 3 is newer than this plugin reads (schema 2)",
    );
    // Whatever else a newer file holds, the schema is what it reports.
    fails_at(
        &changed("    schema: 2,", "    frame_graph: [],\n    schema: 4,"),
        3,
        13,
        "4,",
        "schema 4 is newer",
    );
    fails_at(&changed("schema: 2", "schema: 0"), 2, 13, "0,", "schema 0 does not exist");
    // A file of schema 1 is read as schema 1: an entry that schema 2 brought is an error at
    // the entry, saying so (a plugin of schema 1 would refuse it).
    let old = changed("schema: 2", "schema: 1").replacen(
        "        Paper,",
        "        Paper,\n        RotaryPositioning(axis: C, harmonics: [1]),",
        1,
    );
    let e = parse(&old).unwrap_err().to_string();
    assert!(
        e.starts_with(
            "21:9: RotaryPositioning is an entry of schema 2, but the file says schema 1"
        ),
        "{e}"
    );
    assert!(parse(&changed("schema: 2", "schema: 1")).is_ok(), "schema 1 files still read");
}

#[test]
fn joint_checks_point_at_the_offending_value() {
    fails_at(
        &changed("(name: \"Y\", parent: \"base\"", "(name: \"Z\", parent: \"base\""),
        8,
        17,
        "Z\"",
        "joint name 'Z' is already used by joint 1",
    );
    fails_at(
        &changed("axis: X, kind: Linear", "axis: A, kind: Linear"),
        9,
        49,
        "Linear",
        "axis A is rotary and drives a Rotary joint, not a Linear one",
    );
    fails_at(
        &changed("axis: C, kind: Rotary", "axis: Y, kind: Rotary"),
        10,
        40,
        "Y,",
        "axis Y already drives joint 'Y'",
    );
    fails_at(
        &changed("(name: \"Y\",", "(name: \"base\","),
        8,
        17,
        "base\"",
        "'base' names the machine base",
    );
    fails_at(
        &changed(", origin_mm: (0, 0, 0)),\n    ],", ", origin_mm: (0, 0)),\n    ],"),
        10,
        95,
        ")),",
        "Expected an array of length 3 but found 2",
    );
}

#[test]
fn location_error_names_are_checked_at_the_name() {
    fails_at(
        &changed("\"EY0C\"]", "\"EZ0C\"]"),
        21,
        34,
        "EZ0C\"",
        "'EZ0C': an offset along the C axis's own line is not a location error",
    );
    fails_at(&changed("\"EY0C\"]", "\"EQ0C\"]"), 21, 34, "EQ0C\"", "unknown location error 'EQ0C'");
    fails_at(&changed("\"EY0C\"]", "\"EY0X\"]"), 21, 34, "EY0X\"", "X is a linear axis");
    // A well-formed name of an axis the machine lacks: the model's check, at the entry.
    fails_at(
        &changed("\"EY0C\"]", "\"EX0B\"]"),
        21,
        9,
        "RotaryLocation",
        "a term refers to axis B, which drives no joint",
    );
}

#[test]
fn whole_file_checks_point_at_the_branch_end_or_the_joint() {
    fails_at(&changed("tool: \"Z\"", "tool: \"Q\""), 12, 11, "\"Q\"", "tool: no joint named 'Q'");
    fails_at(
        &changed("workpiece: \"C\"", "workpiece: \"Z\""),
        13,
        16,
        "\"Z\"",
        "tool and workpiece both end at joint 'Z'",
    );
    // The workpiece branch stops at X: C is on neither branch.
    fails_at(
        &changed("workpiece: \"C\"", "workpiece: \"X\""),
        10,
        9,
        "(name: \"C\"",
        "joint 'C' is on neither branch",
    );
    // Z hangs from X: the branches share Y and X.
    let shared = changed("(name: \"Z\", parent: \"base\"", "(name: \"Z\", parent: \"X\"");
    let shared = shared.replacen("        (name: \"Z\", parent: \"X\", axis: Z, kind: Linear, direction: (0, 0, 1), origin_mm: (0, 0, 0)),\n", "", 1);
    let shared = shared.replacen("origin_mm: (0, 0, 0)),\n    ],", "origin_mm: (0, 0, 0)),\n        (name: \"Z\", parent: \"X\", axis: Z, kind: Linear, direction: (0, 0, 1), origin_mm: (0, 0, 0)),\n    ],", 1);
    fails_at(&shared, 7, 9, "(name: \"Y\"", "joint 'Y' is on both branches");
    fails_at(
        &changed(
            "(axis: Y, reference_mm: 0, length_mm: 250)",
            "(axis: X, reference_mm: 0, length_mm: 250)",
        ),
        16,
        16,
        "X,",
        "axis X is normalised twice",
    );
    let no_joints: String =
        BASE_FILE.lines().filter(|l| !l.contains("(name:")).collect::<Vec<_>>().join("\n");
    fails_at(&no_joints, 6, 13, "[", "a machine needs at least one joint");
}

#[test]
fn the_models_own_checks_point_at_the_entry_of_the_error_list() {
    // Z's normalisation is gone: the paper set's first term on Z needs it.
    let no_norm = changed("        (axis: Z, reference_mm: 0, length_mm: 250),\n", "");
    fails_at(&no_norm, 19, 9, "Paper", "axis Z needs a normalisation");
    // The paper set has SQXY already; its second use is the culprit.
    fails_at(
        &changed("        Paper,", "        Paper,\n        Squareness(axis: Y, toward: X),"),
        21,
        9,
        "Squareness",
        "term id SQXY appears twice",
    );
    // A term of an axis the machine lacks (the base file has no B).
    fails_at(
        &changed("        Paper,", "        Backlash(axis: B),"),
        20,
        9,
        "Backlash",
        "a term refers to axis B, which drives no joint",
    );
    fails_at(
        &changed("        Paper,", "        RotaryPositioning(axis: B, harmonics: [1]),"),
        20,
        9,
        "RotaryPositioning",
        "a term refers to axis B, which drives no joint",
    );
    // A rotary error motion's id used twice: at its second use.
    let twice = "        RotaryRunout(axis: C, direction: X, harmonics: [1, 2]),\n        RotaryRunout(axis: C, direction: X, harmonics: [3, 2]),";
    fails_at(
        &changed("        Paper,", twice),
        21,
        9,
        "RotaryRunout",
        "term id EXC_S2 appears twice",
    );
}

/// `BASE_FILE` with the entry `entry` in place of `Paper` (line 20).
fn with_entry(entry: &str) -> String {
    changed("        Paper,", &format!("        {entry},"))
}

#[test]
fn rotary_error_motions_expand_to_their_terms() {
    let entries = [
        "RotaryPositioning(axis: C, harmonics: [1, 2])",
        "RotaryRunout(axis: C, direction: X, harmonics: [1])",
        "RotaryRunout(axis: C, direction: Z, harmonics: [3])",
        "RotaryWobble(axis: C, about: A, harmonics: [2])",
        // X, Y, Z name the direction a tilt is about as A, B, C do; the description says B.
        "RotaryWobble(axis: C, about: Y, harmonics: [1])",
        "Backlash(axis: C)",
        "ServoLag(axis: C)",
    ];
    let spec = parse(&with_entry(&entries.join(",\n        "))).unwrap();
    assert_eq!(
        spec.terms[..7],
        [
            TermSpec::RotaryPositioning { axis: Axis::C, harmonics: vec![1, 2] },
            TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::X, harmonics: vec![1] },
            TermSpec::RotaryRunout { axis: Axis::C, direction: Axis::Z, harmonics: vec![3] },
            TermSpec::RotaryWobble { axis: Axis::C, about: Axis::A, harmonics: vec![2] },
            TermSpec::RotaryWobble { axis: Axis::C, about: Axis::B, harmonics: vec![1] },
            TermSpec::Backlash { axis: Axis::C },
            TermSpec::ServoLag { axis: Axis::C },
        ]
    );
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    let params = model.parameters();
    let shown: Vec<(&str, &str)> =
        params.iter().map(|p| (p.id.as_str(), p.unit.display_name())).collect();
    #[rustfmt::skip]
    assert_eq!(shown, [
        ("ECC_S1", "µrad"), ("ECC_C1", "µrad"), ("ECC_S2", "µrad"), ("ECC_C2", "µrad"),
        ("EXC_S1", "µm"), ("EXC_C1", "µm"), ("EZC_S3", "µm"), ("EZC_C3", "µm"),
        ("EAC_S2", "µrad"), ("EAC_C2", "µrad"), ("EBC_S1", "µrad"), ("EBC_C1", "µrad"),
        ("BC", "µrad"), ("TC", "ms"), ("EX0C", "µm"), ("EY0C", "µm"), ("BAR", "µm"),
    ]);
    // The description round-trips through RON, as the plugin hands it over.
    let text = with_entry(&entries.join(", "));
    let back: MachineSpec = ron::from_str(&describe(&text).unwrap()).unwrap();
    assert_eq!(back, parse(&text).unwrap());
}

#[test]
fn bad_rotary_error_motions_are_errors_at_the_value() {
    // Line 20 is the entry; its columns count from the 9th, where the entry's name starts.
    let at = |entry: &str, points_at: &str, says: &str| {
        let column = 9 + entry.find(points_at).unwrap_or_else(|| panic!("{points_at} in {entry}"));
        fails_at(&with_entry(entry), 20, column, points_at, says);
    };
    at(
        "RotaryPositioning(axis: X, harmonics: [1])",
        "X,",
        "X is a linear axis; a rotary axis (A, B or C) is needed here",
    );
    at("RotaryWobble(axis: Z, about: A, harmonics: [1])", "Z,", "Z is a linear axis");
    at(
        "RotaryRunout(axis: C, direction: A, harmonics: [1])",
        "A,",
        "A is a rotary axis; a linear direction (X, Y or Z) is needed here",
    );
    at(
        "RotaryWobble(axis: C, about: C, harmonics: [1])",
        "C, harmonics",
        "a tilt of C about its own line (C) is its angular positioning error",
    );
    at(
        "RotaryWobble(axis: C, about: Z, harmonics: [1])",
        "Z, harmonics",
        "a tilt of C about its own line (Z) is its angular positioning error",
    );
    // A list is checked once read: the place is its closing bracket.
    at("RotaryPositioning(axis: C, harmonics: [0, 1])", "])", "harmonic 0: harmonics start at 1");
    at("RotaryPositioning(axis: C, harmonics: [])", "])", "give at least one harmonic");
    at(
        "RotaryRunout(axis: C, direction: Y, harmonics: [2, 1, 2])",
        "])",
        "harmonic 2 is listed twice (entry 3)",
    );
    at("RotaryRunout(axis: C, direction: Y, harmonics: [361])", "])", "harmonic 361: at most 360");
    at(
        "RotaryRunout(axis: C, direction: Y, harmonics: [1], size_um: 3)",
        "size_um",
        "Unexpected field named `size_um`",
    );
    at(
        "RotaryPositioning(axis: C, harmonic: [1])",
        "harmonic:",
        "Unexpected field named `harmonic`",
    );
    at("Backlash(axis: Q)", "Q", "Unexpected variant named `Q`");
}

#[test]
fn a_rotary_positioning_model_builds_a_design_on_a_c_tangential_run() {
    use ballbar_model::Design;
    use ballbar_model::path::{BarDirection, RotaryTest, Turn};
    let spec = parse(&with_entry("RotaryPositioning(axis: C, harmonics: [1, 2])")).unwrap();
    let model = Model::new(spec, ModelOptions::default()).unwrap();
    // The table ball 120 mm off the C line (through the X slide's origin), the bar tangential.
    let test = RotaryTest {
        turns: vec![Turn { axis: Axis::C, start_deg: 0.0, sweep_deg: 360.0 }],
        hold: vec![],
        bar: BarDirection::Tangential,
        radius_mm: 100.0,
        feed_mm_per_min: 1000.0,
        pivot_mm: [120.0, 0.0, -200.0],
        tool_ball_mm: [0.0, 0.0, -100.0],
        sample_rate_hz: 50.0,
    };
    let runs = vec![
        test.run(
            &model.chain,
            "2026-12-02T09:00:00Z",
            1_796_202_000.0,
            "c-tangential",
            &model.spec.name,
        )
        .unwrap(),
    ];
    let design = Design::new(&model, &runs).unwrap();
    let ids: Vec<&str> =
        design.parameters[..design.n_machine].iter().map(|p| p.id.as_str()).collect();
    assert_eq!(ids, ["ECC_S1", "ECC_C1", "ECC_S2", "ECC_C2", "EX0C", "EY0C", "BAR"]);
    let m = runs[0].len();
    let cols: Vec<usize> = (0..4).collect();
    let mut block = vec![0.0; m * cols.len()];
    design
        .fill_run(
            0,
            &cols,
            &mut block,
            &mut vec![0.0; m],
            &mut ballbar_model::BlockScratch::default(),
        )
        .unwrap();
    // A positioning error ε is an error of the coordinate: the table stands where the
    // nominal chain puts it at C + ε. A tangential bar lies along the tool ball's motion
    // relative to the table ball as C increases, and the table ball is 120 mm from the line:
    // the bar lengthens by 120 ε, so each column is +120 mm per rad times its harmonic (to
    // the 1e-6 mm of the commanded coordinates over 100 mm).
    let c = runs[0].axis(Axis::C).unwrap();
    for (k, (n, cosine)) in
        [(1.0, false), (1.0, true), (2.0, false), (2.0, true)].into_iter().enumerate()
    {
        for i in (0..m).step_by(37) {
            let h = if cosine { (n * c[i]).cos() } else { (n * c[i]).sin() };
            assert!(
                (block[k * m + i] - 120.0 * h).abs() < 1e-6 * 120.0,
                "{} sample {i}: {} against {}",
                ids[k],
                block[k * m + i],
                120.0 * h
            );
        }
    }
}

#[test]
fn squareness_ids_default_to_the_papers() {
    let text = changed(
        "        Paper,",
        "        Squareness(axis: X, toward: Y),\n        Squareness(axis: Z, toward: Y),\n        Squareness(axis: Z, toward: X),\n        Squareness(id: \"SQXY_HIGH\", axis: Y, toward: X),",
    );
    let spec = parse(&text).unwrap();
    let ids: Vec<(String, Axis, Axis)> = spec
        .terms
        .iter()
        .filter_map(|t| match t {
            TermSpec::Squareness { id, axis, toward } => Some((id.clone(), *axis, *toward)),
            _ => None,
        })
        .collect();
    assert_eq!(
        ids,
        [
            ("SQXY".into(), Axis::X, Axis::Y),
            ("SQYZ".into(), Axis::Z, Axis::Y),
            ("SQZX".into(), Axis::Z, Axis::X),
            ("SQXY_HIGH".into(), Axis::Y, Axis::X)
        ]
    );
    // The defaults are the ids of paper_terms(): a file may spell the paper set out.
    let paper = paper_terms();
    let paper_ids: Vec<&str> = paper
        .iter()
        .filter_map(|t| match t {
            TermSpec::Squareness { id, .. } => Some(id.as_str()),
            _ => None,
        })
        .collect();
    assert_eq!(paper_ids, ["SQXY", "SQYZ", "SQZX"]);
}

#[test]
fn every_error_kind_expands_to_its_terms() {
    let text = changed(
        "        Paper,",
        "        Positional(axis: X, degrees: [1, 3]),\n        Straightness(axis: Y, toward: Z, degrees: [2], tie_angles: false),\n        Angular(axis: Z, about: X, degrees: [1]),\n        Backlash(axis: Y),\n        ServoLag(axis: Z),",
    );
    let spec = parse(&text.replace(
        "RotaryLocation([\"EX0C\", \"EY0C\"])",
        "RotaryLocation([\"EX0C\", \"EY0C\", \"EC0C\", \"EA0C\", \"EB0C\"])",
    ))
    .unwrap();
    assert_eq!(
        spec.terms,
        [
            TermSpec::Positional { axis: Axis::X, degrees: vec![1, 3] },
            TermSpec::Straightness {
                axis: Axis::Y,
                toward: Axis::Z,
                degrees: vec![2],
                tie_angles: false
            },
            TermSpec::Angular { axis: Axis::Z, about: Axis::X, degrees: vec![1] },
            TermSpec::Backlash { axis: Axis::Y },
            TermSpec::ServoLag { axis: Axis::Z },
            TermSpec::RotaryLocation {
                axis: Axis::C,
                components: vec![Axis::X, Axis::Y, Axis::C, Axis::A, Axis::B]
            },
        ]
    );
    let ids = parameter_ids(&spec);
    assert_eq!(
        ids,
        ["EXX1", "EXX3", "EZY2", "EAZ1", "BY", "TZ", "EX0C", "EY0C", "EC0C", "EA0C", "EB0C", "BAR"]
    );
    // The existing schema-1 files are unchanged by the rotary error motions: every shipped
    // file parses to the same terms, none of them new.
    for f in FIXTURES {
        let spec = parse(&fixture(f)).unwrap();
        assert!(
            !spec.terms.iter().any(|t| matches!(
                t,
                TermSpec::RotaryPositioning { .. }
                    | TermSpec::RotaryRunout { .. }
                    | TermSpec::RotaryWobble { .. }
            )),
            "{f}"
        );
    }
}

#[test]
fn locate_finds_the_start_of_a_value() {
    let text =
        "(\n  a: \"x\",\n  list: [1, (b: 2,  c: [3, 4])],\n  e: [Paper, Positional(axis: X)],\n)";
    let at = |path: &[Step]| locate(text, path);
    assert_eq!(at(&[]), Some(Position { line: 1, column: 1 }));
    assert_eq!(at(&[Step::Field("a")]), Some(Position { line: 2, column: 6 }));
    assert_eq!(at(&[Step::Field("list"), Step::Index(1)]), Some(Position { line: 3, column: 13 }));
    assert_eq!(
        at(&[Step::Field("list"), Step::Index(1), Step::Field("c"), Step::Index(1)]),
        Some(Position { line: 3, column: 28 })
    );
    assert_eq!(at(&[Step::Field("e"), Step::Index(0)]), Some(Position { line: 4, column: 7 }));
    assert_eq!(at(&[Step::Field("e"), Step::Index(1)]), Some(Position { line: 4, column: 14 }));
    assert_eq!(
        at(&[Step::Field("e"), Step::Index(1), Step::Field("axis")]),
        Some(Position { line: 4, column: 31 })
    );
    assert_eq!(at(&[Step::Field("nothing")]), None);
    assert_eq!(at(&[Step::Field("list"), Step::Index(2)]), None);
    assert_eq!(at(&[Step::Field("a"), Step::Index(0)]), None);
}

#[test]
fn no_truncation_or_deleted_character_panics_or_loses_its_place() {
    // Every prefix of a real file, and the file with each character deleted in turn: each
    // parses or fails at a real place (1-based, inside the text or just after it), never a panic.
    let text = fixture("five-axis-ac-trunnion.ron");
    let chars: Vec<char> = text.chars().collect();
    let lines = text.lines().count() + 1;
    let check = |t: &str| {
        if let Err(e) = parse(t) {
            assert!(e.line >= 1 && e.column >= 1 && e.line <= lines, "{e}");
        }
    };
    for cut in 0..chars.len() {
        check(&chars[..cut].iter().collect::<String>());
        check(&chars[..cut].iter().chain(&chars[cut + 1..]).collect::<String>());
    }
}

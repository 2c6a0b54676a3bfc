//! Tests of the readers' limits: input too large to be a ballbar file (columns, header lines,
//! line length, a run id, attributes, runs) and readings too large to be a ballbar's, each
//! refused with the file, the line and what is wrong.

use crate::IoError;
use crate::b5r::{B5rOptions, parse_b5r};
use crate::csv::parse_run;

const FILE: &str = "runs/x.csv";

/// A valid run file: header on lines 1-9, column line 10, samples on lines 11-15 (a circle of
/// radius 100 about the origin in XY at 1000 mm/min).
fn run_text(extra_header: &str, extra_columns: &str, extra_fields: &str) -> String {
    let mut s = String::from(
        "# ballbar-run: 1\n# plane: XY\n# direction: CCW\n# radius_mm: 100\n\
         # feed_mm_per_min: 1000\n# pivot_mm: 0, 0, 0\n# started_at: 2026-11-21T10:00:00Z\n\
         # run_id: xy-ccw-1\n# operator: A. N. Other\n",
    );
    s.push_str(extra_header);
    s.push_str(&format!("t_s,X_mm,Y_mm,dR_um{extra_columns}\n"));
    for i in 0..5 {
        let t = 0.01 * i as f64;
        let th = 1000.0 / 60.0 * t / 100.0;
        s.push_str(&format!(
            "{t:.3},{:.6},{:.6},{:.3}{extra_fields}\n",
            100.0 * th.cos(),
            100.0 * th.sin(),
            0.5 - 0.01 * i as f64
        ));
    }
    s
}

/// `text` with the `dR_um` of sample line `ln` replaced by `value`.
fn with_reading(text: &str, ln: usize, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let line = &mut lines[ln - 1];
    let at = line.rfind(',').expect("a sample line");
    line.replace_range(at + 1.., value);
    lines.join("\n") + "\n"
}

#[test]
fn the_valid_run_reads() {
    let run = parse_run(&run_text("", "", ""), FILE).unwrap();
    assert_eq!(run.len(), 5);
    assert_eq!(run.lines, vec![11, 12, 13, 14, 15]);
}

#[test]
fn a_column_line_of_hundreds_of_names_is_refused_at_the_column_line() {
    let names: String = (0..1000).map(|i| format!(",note{i}")).collect();
    let fields = ",".repeat(1000);
    let e = crate::expect_error_at(
        parse_run(&run_text("", &names, &fields), FILE),
        FILE,
        10,
        "column line: 1004 columns; a run file has at most 256",
    );
    assert!(matches!(e, IoError::Columns { .. }), "{e:?}");
    // 256 columns read (the names are told apart by a hash set, not pairwise).
    let names: String = (0..252).map(|i| format!(",note{i}")).collect();
    let fields = ",".repeat(252);
    assert_eq!(parse_run(&run_text("", &names, &fields), FILE).unwrap().len(), 5);
    // A name given twice is still found, far apart.
    let names: String = (0..200).map(|i| format!(",note{i}")).collect::<String>() + ",note3";
    let fields = ",".repeat(201);
    crate::expect_error_at(
        parse_run(&run_text("", &names, &fields), FILE),
        FILE,
        10,
        "column \"note3\" is given twice",
    );
}

#[test]
fn a_header_of_thousands_of_lines_is_refused_where_it_passes_the_limit() {
    let keys: String = (0..2000).map(|i| format!("# key{i}: value\n")).collect();
    crate::expect_error_at(
        parse_run(&run_text(&keys, "", ""), FILE),
        FILE,
        1025,
        "more than 1024 header lines",
    );
    // A key given twice among many is found, with its first line.
    let keys: String =
        (0..1000).map(|i| format!("# key{i}: value\n")).collect::<String>() + "# key7: again\n";
    crate::expect_error_at(
        parse_run(&run_text(&keys, "", ""), FILE),
        FILE,
        1010,
        "header key \"key7\": given twice (first on line 17)",
    );
}

#[test]
fn a_run_id_longer_than_a_file_name_allows_is_refused() {
    let with_id =
        |id: &str| run_text("", "", "").replace("# run_id: xy-ccw-1", &format!("# run_id: {id}"));
    let e = crate::expect_error_at(
        parse_run(&with_id(&"r".repeat(1000)), FILE),
        FILE,
        8,
        "header key \"run_id\": the run id is 1000 bytes long; it names files, and is at most 240 bytes",
    );
    // The message does not repeat the id.
    assert!(e.to_string().len() < 200, "{e}");
    // The issue's 65,536 characters (a report's column width beyond the formatter's range):
    // refused at the line as longer than any line of a run file.
    let e = crate::expect_error_at(parse_run(&with_id(&"r".repeat(65_536)), FILE), FILE, 8, "");
    assert!(e.to_string().len() < 200, "{e}");
    let most = "r".repeat(240);
    assert_eq!(
        parse_run(&with_id(&most), FILE).unwrap().header.run_id.as_deref(),
        Some(most.as_str())
    );
}

#[test]
fn a_line_longer_than_any_run_file_has_is_refused_and_never_quoted_whole() {
    let text = run_text(&format!("# comment: {}\n", "x".repeat(70_000)), "", "");
    let e =
        crate::expect_error_at(parse_run(&text, FILE), FILE, 10, "the line is 70011 bytes long");
    assert!(e.to_string().len() < 200, "{e}");
    // A long line within the limit that is wrong is quoted in part.
    let text = run_text(&format!("# {}\n", "y".repeat(10_000)), "", "");
    let e = crate::expect_error_at(parse_run(&text, FILE), FILE, 10, "is not of the form");
    assert!(e.to_string().len() < 200, "{e}");
    let text = with_reading(&run_text("", "", ""), 12, &"9".repeat(5000).replacen('9', "x", 1));
    let e = crate::expect_error_at(parse_run(&text, FILE), FILE, 12, "is not a number");
    assert!(e.to_string().len() < 200, "{e}");
}

#[test]
fn a_reading_of_1e300_is_refused_at_its_line_not_fitted_into_nan() {
    let text = with_reading(&run_text("", "", ""), 13, "1e300");
    let e = crate::expect_error_at(
        parse_run(&text, FILE),
        FILE,
        13,
        "column dR_um: 1e300 µm is not a ballbar reading: it is more than a tenth of the bar's length (100 mm)",
    );
    assert!(matches!(e, IoError::Sample { .. }), "{e:?}");
    // The bar's length written for its deviation, and a reading in nm.
    crate::expect_error_at(
        parse_run(&with_reading(&run_text("", "", ""), 11, "100000.5"), FILE),
        FILE,
        11,
        "100000.5 µm is not a ballbar reading",
    );
    crate::expect_error_at(
        parse_run(&with_reading(&run_text("", "", ""), 15, "-10000.001"), FILE),
        FILE,
        15,
        "-10000.001 µm is not a ballbar reading",
    );
    // 10 mm on a 100 mm bar is within the bound for what is no reading at all, and beyond a
    // ballbar's travel: the range check refuses it.
    crate::expect_error_at(
        parse_run(&with_reading(&run_text("", "", ""), 15, "-10000"), FILE),
        FILE,
        15,
        "-10000 µm is beyond a ballbar's range of ±1 mm",
    );
}

/// A small `.b5r` file: `runs` runs (CCW, CW, CCW, ...) of `n` readings each, `extra`
/// inserted in the TEST_SPEC element's start tag, and `reading` as the second reading of the
/// first run. The READINGS of run k are on line 9 + 2k, its BALLBAR_RUN on line 8 + 2k.
fn b5r_text(runs: usize, extra: &str, reading: &str) -> String {
    let mut s = format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<TEST_DOCUMENT>\n<TEST_SPEC NAME=\"t\"{extra}><INSTRUMENT><DYNAMIC_BALLBAR>\
         <NOMINAL_LENGTH>100</NOMINAL_LENGTH><PROGRAMMED_FEEDRATE>18850</PROGRAMMED_FEEDRATE>\
         <START_ANGLE>0</START_ANGLE><END_ANGLE>90</END_ANGLE>\n\
         <PLANE TEST_PLANE=\"XY\"><A_AXIS_NAME>X</A_AXIS_NAME><B_AXIS_NAME>Y</B_AXIS_NAME></PLANE>\n\
         </DYNAMIC_BALLBAR></INSTRUMENT></TEST_SPEC>\n\
         <DATE_STARTED>20250904-161049</DATE_STARTED>\n<RUN_RESULTS>\n"
    );
    for k in 0..runs {
        let dir = if k % 2 == 0 { "CCW" } else { "CW" };
        let readings = if k == 0 {
            format!("0.001 {reading} 0.003 0.002 0.001")
        } else {
            "0.001 0.002 0.003 0.002 0.001".to_string()
        };
        s.push_str(&format!(
            "<BALLBAR_RUN><RUN_DIRECTION>{dir}</RUN_DIRECTION><START_INDEX>0</START_INDEX><END_INDEX>4</END_INDEX><SAMPLE_RATE>10</SAMPLE_RATE>\n<READINGS>{readings}</READINGS></BALLBAR_RUN>\n"
        ));
    }
    s.push_str("</RUN_RESULTS>\n</TEST_DOCUMENT>\n");
    s
}

fn read_b5r(text: &str) -> Result<crate::b5r::B5rTest, IoError> {
    parse_b5r(text, "t.b5r", &B5rOptions::default())
}

#[test]
fn the_small_b5r_file_reads_and_names_its_lines() {
    let test = read_b5r(&b5r_text(3, "", "0.002")).unwrap();
    assert_eq!(test.runs.len(), 3);
    let lines: Vec<u32> = test.runs.iter().map(|r| r.lines[0]).collect();
    assert_eq!(lines, [9, 11, 13]);
    let ids: Vec<String> = test.runs.iter().map(|r| r.name()).collect();
    assert_eq!(ids, ["t-ccw-1", "t-cw", "t-ccw-3"]);
}

#[test]
fn a_b5r_element_with_thousands_of_attributes_is_refused_before_the_xml_parser() {
    let attributes: String = (0..1000).map(|i| format!(" a{i}=\"x\"")).collect();
    let e = crate::expect_error_at(
        read_b5r(&b5r_text(2, &attributes, "0.002")),
        "t.b5r",
        3,
        "an element with more than 64 attributes",
    );
    assert!(matches!(e, IoError::Format { .. }), "{e:?}");
    // Quoted values may hold '=' and '>', and what looks like a tag inside a comment or a
    // CDATA section is not one.
    let quoted: String = (0..60).map(|i| format!(" a{i}='x=>y'")).collect();
    let tag: String = format!("<x{}>", " a=1".repeat(100));
    let text = b5r_text(2, &quoted, "0.002").replace(
        "<DATE_STARTED>",
        &format!("<!-- {tag} --><OPERATOR><![CDATA[{tag}]]></OPERATOR><DATE_STARTED>"),
    );
    assert_eq!(read_b5r(&text).unwrap().runs.len(), 2);
}

#[test]
fn a_b5r_file_of_more_runs_than_a_test_has_is_refused() {
    crate::expect_error_at(
        read_b5r(&b5r_text(101, "", "0.002")),
        "t.b5r",
        208,
        "RUN_RESULTS has 101 BALLBAR_RUN elements; a test has at most 100",
    );
    assert_eq!(read_b5r(&b5r_text(100, "", "0.002")).unwrap().runs.len(), 100);
}

#[test]
fn a_b5r_reading_of_1e300_is_refused_at_its_element() {
    crate::expect_error_at(
        read_b5r(&b5r_text(2, "", "1e300")),
        "t.b5r",
        9,
        "column dR_um: 1e303 µm is not a ballbar reading",
    );
}

/// What a message quotes of a file is bounded, whatever the reader: a long element text, a
/// long column name, a huge number.
#[test]
fn the_b5r_and_table_readers_quote_at_most_a_piece_of_a_long_text() {
    let long = "9".repeat(10_000);
    let text = b5r_text(2, "", "0.002")
        .replace("<NOMINAL_LENGTH>100<", &format!("<NOMINAL_LENGTH>x{long}<"));
    let e = crate::expect_error_at(read_b5r(&text), "t.b5r", 3, "is not a finite number");
    assert!(e.to_string().len() < 300, "{e}");
    let text =
        b5r_text(2, "", "0.002").replace("<RUN_DIRECTION>CW<", &format!("<RUN_DIRECTION>{long}<"));
    let e = crate::expect_error_at(read_b5r(&text), "t.b5r", 10, "is not CW or CCW");
    assert!(e.to_string().len() < 300, "{e}");

    let setup = crate::table::TableSetup::new(
        ballbar_model::Plane::XY,
        ballbar_model::Direction::CCW,
        100.0,
        1000.0,
        [0.0; 3],
        "2026-11-21T10:00:00Z",
    );
    let table = |text: &str| crate::table::parse_table(text, "t.csv", &setup);
    let name = "q".repeat(10_000);
    let e = crate::expect_error_at(
        table(&format!("angle_deg,{name}\n0,1\n1,2\n2,3\n")),
        "t.csv",
        1,
        "cannot tell what column",
    );
    assert!(e.to_string().len() < 300, "{e}");
    let e = crate::expect_error_at(
        table(&format!("angle_deg,dR_um\n0,1\n1,2\n2,{}.5\n", &long[..300])),
        "t.csv",
        4,
        "beyond a ballbar's range",
    );
    assert!(e.to_string().len() < 300, "{e}");
}

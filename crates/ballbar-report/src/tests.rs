//! The page's geometry and structure on simulated sessions (the e2e tests check a recorded
//! archive through the binary and the page in a real browser).

use ballbar_archive::{ArchivedFit, ArchivedMachine, ArchivedRun, Session, SessionInfo};
use ballbar_model::machine::{MachineSpec, ModelOptions};
use ballbar_model::{Axis, BarLength, Direction, NoKernels, Plane, ServoVariant};
use ballbar_sim::{TestSpec, Truth};

use crate::svg;

/// A three-axis machine with the paper's terms (table X on saddle Y, head Z).
fn machine() -> MachineSpec {
    use ballbar_model::machine::{linear, paper_terms, AxisNorm};
    MachineSpec {
        name: "test-column".into(),
        version: "1".into(),
        description: "test".into(),
        tool: vec![linear("Z", Axis::Z, [0.0; 3])],
        workpiece: vec![linear("Y", Axis::Y, [0.0; 3]), linear("X", Axis::X, [0.0; 3])],
        normalisation: Axis::LINEAR.iter().map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: 250.0 }).collect(),
        terms: paper_terms(),
    }
}

/// CW/CCW pairs in `planes`, R 100, with only `errors` (display units), no noise, 5 µm of
/// random centring.
fn session(errors: &[(&str, f64)], planes: &[Plane]) -> Session {
    session_swept(errors, planes, 360.0)
}

fn session_swept(errors: &[(&str, f64)], planes: &[Plane], sweep_deg: f64) -> Session {
    let truth = Truth {
        servo: ServoVariant::AxisLag,
        errors: errors.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
        paper: None,
        bar_length_um: 0.0,
        centring_sd_um: 5.0,
        noise_um: 0.0,
        noise_correlation_ms: 0.0,
        sample_rate_hz: 50.0,
        started_at: "2026-11-21T10:00:00Z".into(),
        pause_s: 10.0,
        tests: planes
            .iter()
            .map(|&plane| TestSpec {
                plane,
                directions: vec![Direction::CW, Direction::CCW],
                radius_mm: 100.0,
                feed_mm_per_min: 1000.0,
                pivot_mm: [300.0, 200.0, -300.0],
                table_ball_mm: [0.0, 0.0, 50.0],
                tool_ball_mm: [0.0, 0.0, -100.0],
                repeats: 1,
                start_deg: 0.0,
                sweep_deg,
                rotary: None,
            })
            .collect(),
        effects: vec![],
    };
    let spec = machine();
    let sim = ballbar_sim::simulate(&spec, &truth, 1_795_000_000.0, 1).unwrap();
    let options = ModelOptions { servo: ServoVariant::AxisLag, bar_length: BarLength::Known(0.0) };
    let model = ballbar_model::machine::Model::new(spec.clone(), options).unwrap();
    let fit = ballbar_fit::fit(&ballbar_model::Design::new(&model, &sim.runs).unwrap(), 2).unwrap();
    Session {
        info: SessionInfo::now("test", "test-column", "test"),
        runs: sim.runs.into_iter().map(ArchivedRun::new).collect(),
        machine: Some(ArchivedMachine { spec, options, plugin_name: "none".into(), plugin_version: "0".into(), machine_file: None }),
        fit: Some(ArchivedFit::from_fit(&fit)),
        diagnosis: None,
        attachments: vec![],
    }
}

/// The points of the `<path class="{class}" …>` elements inside the `<svg class="{svg_class}"…>`
/// elements of a page, as (x, y) px, with the svg's scale (µm/div).
fn paths(html: &str, svg_class: &str, class: &str) -> Vec<(f64, Vec<(f64, f64)>)> {
    let mut out = Vec::new();
    for part in html.split("<svg ").skip(1) {
        let svg_el = &part[..part.find("</svg>").unwrap()];
        if !svg_el.starts_with(&format!("class=\"{svg_class}\"")) {
            continue;
        }
        let scale: f64 = attr(svg_el, "data-scale-um").parse().unwrap();
        for p in svg_el.split("<path ").skip(1) {
            if !p.starts_with(&format!("class=\"{class}\"")) {
                continue;
            }
            let d = attr(p, "d");
            let pts = d.split(['M', 'L']).filter(|s| !s.trim().is_empty()).map(|s| {
                let v: Vec<f64> = s.split_whitespace().map(|x| x.parse().unwrap()).collect();
                (v[0], v[1])
            });
            out.push((scale, pts.collect()));
        }
    }
    out
}

fn attr<'a>(el: &'a str, name: &str) -> &'a str {
    let k = format!("{name}=\"");
    let i = el.find(&k).unwrap_or_else(|| panic!("no {name} in {}", &el[..el.len().min(200)])) + k.len();
    &el[i..i + el[i..].find('"').unwrap()]
}

/// Orientation (degrees, 0-180) of the second harmonic of the plotted radius: `r(θ) ≈ c +
/// a cos θ + b sin θ + A cos 2(θ - φ)`, φ the direction of the longest diameter; and A in µm.
fn second_harmonic(scale_um: f64, pts: &[(f64, f64)]) -> (f64, f64) {
    let (mut c2, mut s2, mut n) = (0.0, 0.0, 0.0);
    for &(x, y) in pts {
        let (dx, dy) = (x - svg::C, svg::C - y);
        let th = dy.atan2(dx);
        let dev_um = (dx.hypot(dy) - svg::R0) / svg::DIV * scale_um;
        c2 += dev_um * (2.0 * th).cos();
        s2 += dev_um * (2.0 * th).sin();
        n += 1.0;
    }
    // Over a full circle of evenly spread points the harmonics are orthogonal: projections.
    let (a, b) = (2.0 * c2 / n, 2.0 * s2 / n);
    ((b.atan2(a) / 2.0).to_degrees().rem_euclid(180.0), a.hypot(b))
}

#[test]
fn a_pure_squareness_is_drawn_as_an_ellipse_along_the_135_degree_diagonal() {
    // ΔY = -α X (the model's sign convention, tested in ballbar-model): a positive SQXY
    // lengthens the bar along 135°/315° and shortens it along 45°; with R = 100 mm and α = 50 µrad
    // the second harmonic is α R/2 = 2.5 µm. The same in YZ (ΔY = -α Z, Y right, Z up) and ZX
    // (ΔX = -α Z, Z right, X up). Each run has its own centring (5 µm): taken out.
    let s = session(&[("SQXY", 50.0), ("SQYZ", 50.0), ("SQZX", 50.0)], &[Plane::XY, Plane::YZ, Plane::ZX]);
    let page = crate::build("sq.mcap", &s, &NoKernels, &[]).unwrap();
    assert!(page.refit_identical);
    for class in ["trace measured cw", "trace measured ccw", "trace model cw", "trace model ccw"] {
        let found = paths(&page.html, "polar raw", class);
        assert_eq!(found.len(), 3, "{class}: one per plane");
        for (scale, pts) in &found {
            assert!(pts.len() > 300, "{class}: {} points", pts.len());
            let (phi, amp) = second_harmonic(*scale, pts);
            // The drawn points are rounded to 0.01 px (a thousandth of a division) and
            // decimated to window extremes: the angle within 1°, the amplitude within 3 %.
            assert!((phi - 135.0).abs() < 1.0, "{class}: {phi}°");
            assert!((amp - 2.5).abs() < 0.075, "{class}: {amp} µm");
        }
    }
    // And the opposite sign along 45°.
    let s = session(&[("SQXY", -50.0)], &[Plane::XY]);
    let page = crate::build("sq.mcap", &s, &NoKernels, &[]).unwrap();
    let (scale, pts) = &paths(&page.html, "polar raw", "trace measured ccw")[0];
    assert!((second_harmonic(*scale, pts).0 - 45.0).abs() < 1.0);
    // After the model nothing is left (no noise): the residual plot's scale is the smallest.
    let (scale, _) = &paths(&page.html, "polar after", "trace residual ccw")[0];
    assert!(*scale <= 0.001, "{scale}");
}

#[test]
fn the_page_has_every_section_and_one_polar_figure_per_pair() {
    let s = session(&[("SQXY", 20.0), ("BX", 2.0), ("EXX1", 5.0)], &[Plane::XY, Plane::YZ, Plane::ZX]);
    let history = vec![("a".to_string(), s.clone()), ("b".to_string(), s.clone())];
    let page = crate::build("s.mcap", &s, &NoKernels, &history).unwrap();
    let h = &page.html;
    for id in ["summary", "polar", "parameters", "iso", "diagnosis", "trends"] {
        assert!(h.contains(&format!("<section id=\"{id}\">")), "section {id}");
    }
    assert!(h.contains("paper-quantities") && h.contains("machine-parameters") && h.contains("iso-runs") && h.contains("iso-hysteresis"));
    assert_eq!(h.matches("<figure class=\"polar-pair\"").count(), 3);
    assert_eq!(h.matches("<svg class=\"polar raw\"").count(), 3);
    assert_eq!(h.matches("<svg class=\"polar after\"").count(), 3);
    for run in &s.runs {
        let name = run.run.name();
        let dir = run.run.header.direction.unwrap().name().to_lowercase();
        for what in ["measured", "model", "residual"] {
            assert_eq!(h.matches(&format!("class=\"trace {what} {dir}\" data-run=\"{name}\"")).count(), 1, "{what} {name}");
        }
    }
    // No diagnosis in this archive: said so. Trends: one plot per parameter estimable twice.
    assert!(h.contains("holds no diagnosis"));
    assert!(h.contains("<svg class=\"trend\" data-id=\"SQXY\""));
    // Self-contained: no script, nothing fetched.
    assert!(!h.contains("<script") && !h.contains("https://"));
    assert_eq!(h.matches("http://").count(), h.matches("xmlns=\"http://www.w3.org/2000/svg\"").count(), "the only URLs are SVG namespaces");
}

#[test]
fn a_raw_archive_cannot_be_reported_and_says_why() {
    let mut s = session(&[], &[Plane::XY]);
    s.machine = None;
    s.fit = None;
    let e = crate::build("raw.mcap", &s, &NoKernels, &[]).err().expect("an error");
    assert!(e.to_string().starts_with("raw.mcap: the archive holds raw runs only"), "{e}");
}

#[test]
fn scales_are_one_two_five() {
    assert_eq!(svg::nice_scale(2.9), 1.0);
    assert_eq!(svg::nice_scale(3.1), 2.0);
    assert_eq!(svg::nice_scale(14.0), 5.0);
    assert_eq!(svg::nice_scale(16.0), 10.0);
    assert_eq!(svg::nice_scale(0.0), 0.001);
}

#[test]
fn decimation_keeps_a_one_sample_spike() {
    // 10,000 samples of a smooth curve with one sample 50 µm out: kept, whatever the window.
    let mut v: Vec<f64> = (0..10_000).map(|i| (i as f64 * 0.001).sin()).collect();
    v[4321] = 50.0;
    let keep = svg::decimate(&v);
    assert!(keep.contains(&4321));
    assert!(keep.len() <= svg::MAX_POINTS + 2, "{}", keep.len());
    assert!(keep.windows(2).all(|w| w[0] < w[1]) && keep[0] == 0 && *keep.last().unwrap() == 9_999);
}

#[test]
fn an_arc_from_0_to_60_degrees_is_drawn_counter_clockwise_from_the_first_axis() {
    // A CCW arc of 60° from +X in XY: every drawn point right of and above the centre, at
    // angles 0-60° (a reflection about 45° would put them at 30-90°, y pointing down would put
    // them below the centre).
    let s = session_swept(&[], &[Plane::XY], 60.0);
    let page = crate::build("arc.mcap", &s, &NoKernels, &[]).unwrap();
    let found = paths(&page.html, "polar raw", "trace measured ccw");
    assert!(!found.is_empty());
    for (_, pts) in &found {
        for &(x, y) in pts {
            let deg = (svg::C - y).atan2(x - svg::C).to_degrees();
            assert!((-0.5..=60.5).contains(&deg), "a point at {deg}°");
        }
        let first = (svg::C - pts[0].1).atan2(pts[0].0 - svg::C).to_degrees();
        assert!(first.abs() < 1.0, "starts at {first}°");
    }
}

/// A diagnosis JSON as `ballbar diagnose` writes it (the fields the page reads): a gap in an
/// arc through 0° of the XY CCW runs and over the whole XY CW plane, one effect, one aliased.
fn diagnosis_json() -> serde_json::Value {
    serde_json::json!({
        "format": "ballbar-diagnosis/1",
        "gap": {
            "base_rms_um": 0.5, "noise_floor_um": 0.2, "noise_source": "repeats", "noise_lag1_autocorrelation": 0.1,
            "where": [
                {"plane": "XY", "direction": "CCW", "sector_deg": [350.0, 20.0], "share": 0.4, "reversals": ["Y"]},
                {"plane": "XY", "direction": "CW", "sector_deg": [0.0, 360.0], "share": 0.3, "reversals": []},
                {"plane": "XY", "direction": "CW", "sector_deg": [10.0], "share": 0.1, "reversals": []}
            ],
            "locking": {"verdict": "undetermined", "why": "one feed"}
        },
        "effects": [{"kind": "reversal_spike", "axis": "Y", "description": "reversal spike of Y", "parameters": {"amplitude_um": 6.0},
                     "held_out_rms_before_um": 0.5, "held_out_rms_after_um": 0.25, "held_out_g_before_um": 3.0, "held_out_g_after_um": 1.5,
                     "shrink": 0.5, "shrink_interval": [0.4, 0.6], "f_statistic": 900.0, "held_out_t": 8.0, "note": null}],
        "aliased": [{"kind": "angular_error", "axis": "Z", "description": "angular error of Z about Y (Abbe)", "with": ["squareness ZX"], "test_to_separate": "a second tool length"}],
        "cross_validation": "leave one repeat out", "candidates_screened": 80
    })
}

#[test]
fn the_gaps_arcs_are_drawn_where_the_diagnosis_places_them() {
    let mut s = session(&[("SQXY", 20.0)], &[Plane::XY]);
    s.diagnosis = Some(diagnosis_json());
    let page = crate::build("d.mcap", &s, &NoKernels, &[]).unwrap();
    let h = &page.html;
    // The arc through 0° on the CCW plot only; the whole-plane entry and the malformed one
    // (one number) are not arcs.
    assert_eq!(h.matches("<path class=\"where").count(), 1);
    let i = h.find("<path class=\"where ccw\"").expect("the CCW arc");
    let el = &h[i..i + h[i..].find("/>").unwrap()];
    assert_eq!((attr(el, "data-from-deg"), attr(el, "data-to-deg")), ("350", "20"));
    // M x0 y0 A r r 0 large sweep x1 y1: from 350° to 20° counter-clockwise on the page, a
    // 30° arc (large 0, sweep 0 with y down).
    let d: Vec<f64> = attr(el, "d").replace(['M', 'A'], " ").split_whitespace().map(|x| x.parse().unwrap()).collect();
    let angle = |x: f64, y: f64| (svg::C - y).atan2(x - svg::C).to_degrees();
    assert!((angle(d[0], d[1]) + 10.0).abs() < 0.5 && (angle(d[7], d[8]) - 20.0).abs() < 0.5, "{d:?}");
    assert_eq!((d[4], d[5], d[6]), (0.0, 0.0, 0.0), "x-rotation, large-arc and sweep flags");
    // The effect with its shrink, the aliased effect by its description, the bars.
    assert!(h.contains("data-kind=\"reversal_spike\" data-axis=\"Y\"") && h.contains("50.0 %"));
    assert!(h.contains("angular error of Z about Y (Abbe) — would hide in squareness ZX"));
    assert_eq!(h.matches("<rect class=\"bar\"").count(), 1);
}

/// The claim for the effects together, the unexplained gap, the near misses with their
/// reasons and the notes, from the diagnosis JSON; none of them from an archive without them.
#[test]
fn the_held_out_claim_the_unexplained_gap_and_the_near_misses_are_on_the_page() {
    let mut s = session(&[("SQXY", 20.0)], &[Plane::XY]);
    let mut d = diagnosis_json();
    s.diagnosis = Some(d.clone());
    let old = crate::build("d.mcap", &s, &NoKernels, &[]).unwrap().html;
    for id in ["id=\"held-out\"", "id=\"unexplained\"", "id=\"declined\"", "id=\"notes\""] {
        assert!(!old.contains(id), "{id} without its JSON");
    }
    assert!(old.contains("<td>not recorded</td></tr>"), "the effect's folds, not in an old archive");

    d["effects"][0]["folds"] = "later_runs".into();
    d["held_out"] = serde_json::json!({"folds": "later_runs", "rms_before_um": 0.8, "rms_after_um": 0.3, "noise_floor_um": 0.22, "shrink": 0.625});
    d["unexplained"] = serde_json::json!({"folds": "repeats", "share_left": 0.83, "excess_rms_um": 0.41,
        "where": ["ZX CCW 170-190°: 40 %"], "nearest": [{"kind": "cyclic_error", "axis": "X", "description": "cyclic error of X", "share_closed": 0.07}]});
    d["declined"] = serde_json::json!([
        {"kind": "thermal_growth", "axis": "X", "description": "thermal growth of X", "why": {"test": "held_out", "held_out_t": 2.5, "needed": 3.0, "folds": "later_runs"}},
        {"kind": "stick_slip", "axis": "Y", "description": "stick-slip of Y", "why": {"test": "material", "share_of_excess": 0.04, "needed": 0.1, "folds": "quarters"}},
        {"kind": "drift", "axis": "Z", "description": "drift of Z", "why": {"test": "judgeable", "folds_tried": ["later_runs"]}}
    ]);
    d["notes"] = serde_json::json!(["a note"]);
    s.diagnosis = Some(d);
    let h = crate::build("d.mcap", &s, &NoKernels, &[]).unwrap().html;
    assert!(h.contains("<td>later runs</td></tr>"));
    assert!(h.contains("Together, on later runs: held-out RMS 0.800 → 0.300 µm (62 % closed; the noise floor is 0.220 µm)"), "{h}");
    assert!(h.contains("83 % of the held-out gap above the noise (0.410 µm RMS, on repeats) is left by the effects named"));
    assert!(h.contains("<li>ZX CCW 170-190°: 40 %</li>") && h.contains("<li>cyclic error of X: 7 %</li>"));
    assert!(h.contains("<td>thermal growth of X</td><td>held-out (later runs) t 2.5 below 3</td>"));
    assert!(h.contains("closes 4 % of what is left above the noise (at least 10 % to be named)"));
    assert!(h.contains("no held-out folds can determine it (tried: later runs)"));
    assert!(h.contains("<li>note: a note</li>"));
}

/// The page's outline: its sections, headings, tables, figures, plots and lists with their ids
/// and classes, one per line.
fn outline(html: &str) -> String {
    let mut out = String::new();
    for tag in html.split('<').skip(1) {
        let name: String = tag.chars().take_while(|c| c.is_ascii_alphanumeric()).collect();
        if !["section", "h1", "h2", "h3", "table", "figure", "svg", "ul"].contains(&name.as_str()) {
            continue;
        }
        let head = &tag[..tag.find('>').unwrap_or(tag.len())];
        let get = |a: &str| head.find(&format!(" {a}=\"")).map(|i| &head[i + a.len() + 3..][..head[i + a.len() + 3..].find('"').unwrap()]);
        out.push_str(&name);
        for a in ["id", "class", "data-plane", "data-id"] {
            if let Some(v) = get(a) {
                out.push_str(&format!(" {a}={v}"));
            }
        }
        out.push('\n');
    }
    out
}

#[test]
fn the_pages_structure_matches_its_snapshot() {
    // Three planes, a diagnosis, a history of two sessions. The snapshot is the page's outline
    // (not its pixels); after an intended change of structure, rewrite it with
    // BALLBAR_UPDATE_SNAPSHOTS=1 and read the diff.
    let mut s = session(&[("SQXY", 20.0), ("BX", 2.0)], &[Plane::XY, Plane::YZ, Plane::ZX]);
    s.diagnosis = Some(diagnosis_json());
    let history = vec![("a".to_string(), s.clone()), ("b".to_string(), s.clone())];
    let got = outline(&crate::build("s.mcap", &s, &NoKernels, &history).unwrap().html);
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/src/snapshots/outline.txt");
    if std::env::var_os("BALLBAR_UPDATE_SNAPSHOTS").is_some() {
        std::fs::write(path, &got).unwrap();
    }
    let want = std::fs::read_to_string(path).expect("the snapshot (BALLBAR_UPDATE_SNAPSHOTS=1 writes it)");
    assert_eq!(got, want, "the page's outline changed");
}

/// The A/C trunnion of `fixtures/machines/five-axis-ac-trunnion.ron` (Y saddle, X slide, A
/// trunnion with its line 250 mm above the slide, C table 60 mm below it; head Z), written out:
/// the chain-file plugin is not a dependency of this crate.
fn trunnion() -> MachineSpec {
    use ballbar_model::chain::JointKind;
    use ballbar_model::machine::{linear, paper_terms, AxisNorm, JointSpec, TermSpec};
    let rotary = |name: &str, axis, direction, origin_mm| JointSpec { name: name.into(), axis, kind: JointKind::Rotary, direction, origin_mm };
    let mut terms = paper_terms();
    terms.push(TermSpec::RotaryLocation { axis: Axis::C, components: vec![Axis::X, Axis::Y, Axis::A, Axis::B, Axis::C] });
    terms.push(TermSpec::RotaryLocation { axis: Axis::A, components: vec![Axis::Y, Axis::Z, Axis::A, Axis::B, Axis::C] });
    MachineSpec {
        name: "test-trunnion".into(),
        version: "1".into(),
        description: "A/C trunnion".into(),
        tool: vec![linear("Z head", Axis::Z, [0.0; 3])],
        workpiece: vec![
            linear("Y saddle", Axis::Y, [0.0; 3]),
            linear("X slide", Axis::X, [0.0; 3]),
            rotary("A trunnion", Axis::A, [1.0, 0.0, 0.0], [0.0, 0.0, 250.0]),
            rotary("C table", Axis::C, [0.0, 0.0, 1.0], [0.0, 0.0, -60.0]),
        ],
        normalisation: vec![
            AxisNorm { axis: Axis::X, reference_mm: 300.0, length_mm: 300.0 },
            AxisNorm { axis: Axis::Y, reference_mm: 250.0, length_mm: 250.0 },
            AxisNorm { axis: Axis::Z, reference_mm: -250.0, length_mm: 250.0 },
        ],
        terms,
    }
}

/// The ten location errors of [`trunnion`], A's then C's.
const LOCATION_IDS: [&str; 10] = ["EY0A", "EZ0A", "EA0A", "EB0A", "EC0A", "EX0C", "EY0C", "EA0C", "EB0C", "EC0C"];

/// The trunnion with the errors of `five-axis-ac-trunnion.rotary.truth.ron`: the three planar
/// circle pairs, a full turn of C with a radial bar at one height and A tilting -90..+30° with
/// a radial bar, each CW and CCW (0.2 µm of noise, 3 µm of centring, as the truth file has).
/// Simulated and fitted once for every test that reads it.
fn five_axis() -> &'static (Session, ballbar_fit::Fit) {
    static SESSION: std::sync::OnceLock<(Session, ballbar_fit::Fit)> = std::sync::OnceLock::new();
    SESSION.get_or_init(|| {
        use ballbar_model::path::BarDirection;
        use ballbar_sim::{RotarySpec, TurnSpec};
        let errors = [
            ("EXX1", 6.0), ("EYY1", 9.0), ("EZZ1", -7.0), ("EYX2", 2.0), ("EZX2", -3.0), ("EXY2", 2.5), ("EZY2", 1.5), ("EXZ2", 3.0), ("EYZ2", -1.0),
            ("SQXY", -15.0), ("SQYZ", 30.0), ("SQZX", 20.0), ("BX", 3.0), ("BY", 4.0), ("BZ", 2.0), ("TX", 1.0), ("TY", 1.3), ("TZ", 0.9),
            ("EX0C", 8.0), ("EY0C", -5.0), ("EA0C", 15.0), ("EB0C", -10.0), ("EC0C", 20.0), ("EY0A", 6.0), ("EZ0A", -4.0), ("EA0A", 12.0), ("EB0A", -8.0), ("EC0A", 10.0),
        ];
        let test = |plane, radius_mm, pivot_mm, table_ball_mm, rotary| TestSpec {
            plane,
            directions: vec![Direction::CW, Direction::CCW],
            radius_mm,
            feed_mm_per_min: 1000.0,
            pivot_mm,
            table_ball_mm,
            tool_ball_mm: [0.0, 0.0, -100.0],
            repeats: 1,
            start_deg: 0.0,
            sweep_deg: 360.0,
            rotary,
        };
        let turn = |axis, start_deg, sweep_deg| Some(RotarySpec { turns: vec![TurnSpec { axis, start_deg, sweep_deg }], hold: vec![], bar: BarDirection::Radial });
        let mut tests: Vec<TestSpec> = Plane::PLANAR.iter().map(|&p| test(p, 150.0, [300.0, 250.0, -300.0], [0.0, 0.0, 50.0], None)).collect();
        tests.push(test(Plane::Free, 100.0, [100.0, 0.0, 340.0], [100.0, 0.0, 50.0], turn(Axis::C, 0.0, 360.0)));
        tests.push(test(Plane::Free, 100.0, [0.0, 150.0, 350.0], [0.0, 150.0, 60.0], turn(Axis::A, -90.0, 120.0)));
        let truth = Truth {
            servo: ServoVariant::AxisLag,
            errors: errors.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
            paper: None,
            bar_length_um: 0.0,
            centring_sd_um: 3.0,
            noise_um: 0.2,
            noise_correlation_ms: 0.0,
            sample_rate_hz: 50.0,
            started_at: "2026-12-02T09:00:00Z".into(),
            pause_s: 60.0,
            tests,
            effects: vec![],
        };
        let spec = trunnion();
        let sim = ballbar_sim::simulate(&spec, &truth, 1_796_202_000.0, 3).unwrap();
        let options = ModelOptions { servo: ServoVariant::AxisLag, bar_length: BarLength::Known(0.0) };
        let model = ballbar_model::machine::Model::new(spec.clone(), options).unwrap();
        let fit = ballbar_fit::fit(&ballbar_model::Design::new(&model, &sim.runs).unwrap(), 2).unwrap();
        let session = Session {
            info: SessionInfo::now("test", "test-trunnion", "test"),
            runs: sim.runs.into_iter().map(ArchivedRun::new).collect(),
            machine: Some(ArchivedMachine { spec, options, plugin_name: "none".into(), plugin_version: "0".into(), machine_file: None }),
            fit: Some(ArchivedFit::from_fit(&fit)),
            diagnosis: None,
            attachments: vec![],
        };
        (session, fit)
    })
}

/// The five-axis session's page, built once.
fn five_axis_page() -> &'static str {
    static PAGE: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    PAGE.get_or_init(|| {
        let page = crate::build("r5.mcap", &five_axis().0, &NoKernels, &[]).unwrap();
        assert!(page.refit_identical);
        page.html
    })
}

/// The `<el …>` elements (start tags) inside `html` whose tag starts with `start`.
fn elements<'a>(html: &'a str, start: &str) -> Vec<&'a str> {
    html.match_indices(start).map(|(i, _)| &html[i..i + html[i..].find('>').unwrap()]).collect()
}

/// The `<svg class="{class}"…>…</svg>` elements of a page, whole.
fn svgs<'a>(html: &'a str, class: &str) -> Vec<&'a str> {
    let start = format!("<svg class=\"{class}\"");
    html.match_indices(&start).map(|(i, _)| &html[i..i + html[i..].find("</svg>").unwrap()]).collect()
}

/// A drawn trace: its class, its run, its points (px).
type Drawn = (String, String, Vec<(f64, f64)>);

/// The points of every `<path class="trace …">` of an svg, per path.
fn traces(svg_el: &str) -> Vec<Drawn> {
    svg_el
        .split("<path ")
        .skip(1)
        .filter(|p| p.starts_with("class=\"trace "))
        .map(|p| {
            let pts = attr(p, "d").split(['M', 'L']).filter(|s| !s.trim().is_empty()).map(|s| {
                let v: Vec<f64> = s.split_whitespace().map(|x| x.parse().unwrap()).collect();
                (v[0], v[1])
            });
            (attr(p, "class").to_string(), attr(p, "data-run").to_string(), pts.collect())
        })
        .collect()
}

fn num_attr(el: &str, name: &str) -> f64 {
    attr(el, name).parse().unwrap_or_else(|_| panic!("{name} is not a number"))
}

#[test]
fn a_full_turn_is_a_polar_plot_and_a_partial_sweep_a_cartesian_one_over_its_angles() {
    let (s, fit) = five_axis();
    let h = five_axis_page();
    assert!(h.contains("<section id=\"rotary\">"));
    // The planar pairs are still the planar polar figures; the rotary runs are not among them.
    assert_eq!(h.matches("<figure class=\"polar-pair\"").count(), 3);
    let figures = elements(h, "<figure class=\"rotary-pair\"");
    assert_eq!(figures.len(), 2, "{figures:?}");
    let polar: Vec<_> = figures.iter().filter(|f| attr(f, "data-plot") == "polar").collect();
    let cartesian: Vec<_> = figures.iter().filter(|f| attr(f, "data-plot") == "cartesian").collect();
    assert_eq!((polar.len(), cartesian.len()), (1, 1));
    // CW and CCW of one test in one figure; the bar read from the geometry.
    assert_eq!((attr(polar[0], "data-axis"), attr(polar[0], "data-bar")), ("C", "radial"));
    assert_eq!((attr(cartesian[0], "data-axis"), attr(cartesian[0], "data-bar")), ("A", "radial"));
    assert_eq!(attr(polar[0], "data-runs").split(',').count(), 2);
    assert_eq!(attr(cartesian[0], "data-runs").split(',').count(), 2);
    assert_eq!(svgs(h, "rotary-polar raw").len(), 1);
    assert_eq!(svgs(h, "rotary-polar after").len(), 1);
    assert_eq!(svgs(h, "rotary-cartesian raw").len(), 1);
    assert_eq!(svgs(h, "rotary-cartesian after").len(), 1);
    // Titles: the turning axis and its angles, the others held, the bar, the ball's height.
    assert!(h.contains("C turning over 0…360°, A at 0°, radial bar, ball at pivot Z 340 mm"), "C title");
    assert!(h.contains("A turning over -90…30°, C at 0°, radial bar, ball at pivot Z 350 mm"), "A title");

    let run = |name: &str| &s.runs.iter().find(|r| r.run.name() == name).unwrap().run;

    // The Cartesian plots: the box from -90° to +30°; every point inside it; the points span
    // it, -90° at its left edge and +30° at its right within a pixel; the last sample of each
    // run where the run puts it (x its A, y its ΔR at the stated scale), to the 0.01 px drawn.
    for svg_el in svgs(h, "rotary-cartesian raw").into_iter().chain(svgs(h, "rotary-cartesian after")) {
        let [left, top, right, bottom] = ["data-left", "data-top", "data-right", "data-bottom"].map(|a| num_attr(svg_el, a));
        assert_eq!((left, top, right, bottom), (svg::CART_BOX[0], svg::CART_BOX[1], svg::CART_BOX[2], svg::CART_BOX[3]));
        assert_eq!((num_attr(svg_el, "data-from-deg"), num_attr(svg_el, "data-to-deg")), (-90.0, 30.0));
        // The angle ticks at -90° and +30° lie on the box's edges.
        let tick = |deg: &str| {
            let el = elements(svg_el, "<line class=\"grid angle\"").into_iter().find(|e| attr(e, "data-deg") == deg).unwrap_or_else(|| panic!("a tick at {deg}°"));
            num_attr(el, "x1")
        };
        assert!((tick("-90") - left).abs() < 1e-9 && (tick("30") - right).abs() < 1e-9);
        let scale = num_attr(svg_el, "data-scale-um");
        let div = (bottom - top) / (2 * svg::N_DIV) as f64;
        let found = traces(svg_el);
        assert_eq!(found.len(), if svg_el.contains("raw") { 4 } else { 2 });
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (class, name, pts) in &found {
            assert!(pts.len() > 300, "{class}: {} points", pts.len());
            for &(x, y) in pts {
                assert!((left..=right).contains(&x) && (top..=bottom).contains(&y), "{class}: ({x}, {y}) outside the box");
                lo = lo.min(x);
                hi = hi.max(x);
            }
            let r = run(name);
            let k = r.len() - 1;
            let a_deg = r.axis(Axis::A).unwrap()[k].to_degrees();
            let i = s.runs.iter().position(|x| x.run.name() == *name).unwrap();
            let v_um = match class.split(' ').nth(1).unwrap() {
                "measured" => r.dr_mm[k],
                "model" => r.dr_mm[k] - fit.residuals[i][k],
                _ => fit.residuals[i][k],
            } * 1e3;
            let (x, y) = *pts.last().unwrap();
            assert!((x - (left + (a_deg + 90.0) / 120.0 * (right - left))).abs() < 0.006, "{class} {name}: last x {x} for A {a_deg}°");
            assert!((y - ((top + bottom) / 2.0 - v_um / scale * div)).abs() < 0.006, "{class} {name}: last y {y} for {v_um} µm");
        }
        assert!((lo - left).abs() < 1.0 && (hi - right).abs() < 1.0, "the points span {lo}..{hi} px of {left}..{right}");
    }

    // The polar plots: the angle is C's coordinate (0° right, counter-clockwise), every point
    // inside the plot, the whole turn drawn.
    for svg_el in svgs(h, "rotary-polar raw").into_iter().chain(svgs(h, "rotary-polar after")) {
        assert_eq!(attr(svg_el, "data-axis"), "C");
        let scale = num_attr(svg_el, "data-scale-um");
        let mut bins = [false; 36];
        for (class, name, pts) in traces(svg_el) {
            for &(x, y) in &pts {
                assert!((0.0..=svg::SIZE).contains(&x) && (0.0..=svg::SIZE).contains(&y), "{class}: ({x}, {y}) outside the plot");
                let deg = (svg::C - y).atan2(x - svg::C).to_degrees().rem_euclid(360.0);
                bins[(deg / 10.0) as usize % 36] = true;
            }
            let r = run(&name);
            let k = r.len() - 1;
            let c_deg = r.axis(Axis::C).unwrap()[k].to_degrees();
            let (x, y) = *pts.last().unwrap();
            let deg = (svg::C - y).atan2(x - svg::C).to_degrees();
            assert!(((deg - c_deg + 180.0).rem_euclid(360.0) - 180.0).abs() < 0.01, "{class} {name}: last point at {deg}°, C {c_deg}°");
            if class.contains("measured") {
                let radius = (x - svg::C).hypot(svg::C - y);
                assert!((radius - (svg::R0 + r.dr_mm[k] * 1e3 / scale * svg::DIV)).abs() < 0.01, "{name}: radius {radius} px");
            }
        }
        assert!(bins.iter().all(|b| *b), "the whole turn is drawn: {bins:?}");
    }
}

/// The cells of the `<tr data-id="{id}"…>` row of the location-error table: (row start tag,
/// cell texts without tags).
fn location_row<'a>(h: &'a str, id: &str) -> (&'a str, Vec<String>) {
    let table = &h[h.find("<table id=\"location-errors\"").expect("the location-error table")..];
    let table = &table[..table.find("</table>").unwrap()];
    let start = table.find(&format!("<tr data-id=\"{id}\"")).unwrap_or_else(|| panic!("no row {id}"));
    let row = &table[start..start + table[start..].find("</tr>").unwrap()];
    let cells = row.split("<td").skip(1).map(|c| {
        let inner = &c[c.find('>').unwrap() + 1..c.find("</td>").unwrap()];
        inner.to_string()
    });
    (&row[..row.find('>').unwrap()], cells.collect())
}

#[test]
fn the_location_error_table_has_every_location_error_with_its_unit_and_the_fits_value() {
    let (s, fit) = five_axis();
    let h = five_axis_page();
    let table = &h[h.find("<table id=\"location-errors\"").unwrap()..];
    let table = &table[..table.find("</table>").unwrap()];
    // Every E?0? parameter, once, grouped by rotary axis: A's rows under the A heading, then C's.
    assert_eq!(table.matches("<tr data-id=").count(), LOCATION_IDS.len());
    let (a_head, c_head) = (table.find("<tr class=\"axis-group\" data-axis=\"A\"").unwrap(), table.find("<tr class=\"axis-group\" data-axis=\"C\"").unwrap());
    assert!(a_head < c_head);
    let archived = s.fit.as_ref().unwrap();
    let mut estimable = 0;
    for id in LOCATION_IDS {
        let (tr, cells) = location_row(h, id);
        let axis = &id[3..];
        let at = table.find(&format!("<tr data-id=\"{id}\"")).unwrap();
        assert_eq!(attr(tr, "data-axis"), axis);
        assert!(if axis == "A" { a_head < at && at < c_head } else { c_head < at }, "{id} under its axis");
        // id, what, value, u, unit, estimable, why.
        assert_eq!(cells.len(), 7, "{id}: {cells:?}");
        let unit = if "XYZ".contains(&id[1..2]) { "µm" } else { "µrad" };
        assert_eq!(cells[4], unit, "{id}");
        let i = fit.index(id).unwrap();
        let p = archived.parameters.iter().find(|p| p.id == id).unwrap();
        assert_eq!(fit.estimable[i], p.estimable);
        if p.estimable {
            // The value and its uncertainty as printed: the fit's, in display units, to the digits shown.
            estimable += 1;
            assert_eq!(cells[2], format!("{:.3}", p.value * p.display_factor), "{id}");
            assert_eq!(cells[3], format!("{:.3}", p.std_uncertainty * p.display_factor), "{id}");
            assert!(cells[5].starts_with("yes"), "{id}: {}", cells[5]);
        } else {
            assert_eq!(cells[5], "no", "{id}");
            assert!(!cells[6].is_empty(), "{id}: why not");
        }
    }
    assert!(estimable >= 2, "the A offsets are determined by the A run");
    // Why not, by the fit's gauges and null space: C's zero error is a re-seated ball, A's is
    // seen only with C's tilt and offset; C's offsets and tilts at one height go together.
    assert!(location_row(h, "EC0C").1[6].contains("(taken_by_set_up)"));
    assert!(location_row(h, "EA0A").1[6].contains("(rotary_zero_error)"));
    for id in ["EX0C", "EB0C", "EY0C", "EA0C"] {
        let why = &location_row(h, id).1[6];
        assert!(why.contains("(null_space)") && why.contains("a radial run of C at a second ball height"), "{id}: {why}");
        assert!(!why.contains("EA0A"), "{id}: the combination the zero-error gauge settles is the gauge's: {why}");
    }
}

#[test]
fn the_rotary_notes_state_the_fits_choices_in_plain_words() {
    let (_, fit) = five_axis();
    let h = five_axis_page();
    let notes = &h[h.find("<ul id=\"rotary-notes\">").expect("the notes")..];
    let notes = &notes[..notes.find("</ul>").unwrap()];
    // Each gauge about the rotary axes with its what, choice, why and the test that would
    // determine it.
    for kind in ["centring_across_bar", "taken_by_set_up", "rotary_zero_error"] {
        let g = fit.gauges.iter().find(|g| g.kind.name() == kind).unwrap_or_else(|| panic!("the fit has a {kind} gauge"));
        let start = notes.find(&format!("<li data-kind=\"{kind}\">")).unwrap_or_else(|| panic!("a note on {kind}"));
        let li = &notes[start..start + notes[start..].find("</li>").unwrap()];
        for text in [&g.choice, &g.why, &g.separate_by] {
            assert!(li.contains(&svg::esc(text)), "{kind}: {text}");
        }
    }
    // The pairs of offset and tilt that one height cannot separate, with the test that would.
    assert_eq!(notes.matches("<li data-kind=\"null_space\">").count(), 2);
    assert!(notes.contains("EX0C -0.050 µm, EB0C +1.000 µrad"));
}

#[test]
fn a_planar_session_has_no_rotary_section_and_its_page_is_as_before() {
    let s = session(&[("SQXY", 20.0)], &[Plane::XY, Plane::YZ, Plane::ZX]);
    let h = crate::build("p.mcap", &s, &NoKernels, &[]).unwrap().html;
    for absent in ["id=\"rotary\"", "<figure class=\"rotary-pair\"", "<svg class=\"rotary-", "location-errors", "rotary-notes", "Rotary runs (plane free)", "the next section"] {
        assert!(!h.contains(absent), "{absent}");
    }
    // The planar polar plots keep their axis labels.
    assert!(h.contains(">+X</text>") && h.contains(">+Y</text>") && !h.contains("0°</text>"));
}

#[test]
fn the_bar_and_the_plotted_axis_are_read_from_the_runs_geometry() {
    use crate::rotary::{rotary_run, title, Bar};
    use ballbar_model::path::{BarDirection, RotaryTest, Turn};
    let options = ModelOptions { servo: ServoVariant::AxisLag, bar_length: BarLength::Known(0.0) };
    let model = ballbar_model::machine::Model::new(trunnion(), options).unwrap();
    let run = |turns: &[(Axis, f64, f64)], bar, pivot_mm| {
        RotaryTest {
            turns: turns.iter().map(|&(axis, start_deg, sweep_deg)| Turn { axis, start_deg, sweep_deg }).collect(),
            hold: vec![],
            bar,
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm,
            tool_ball_mm: [0.0, 0.0, -100.0],
            sample_rate_hz: 10.0,
        }
        .run(&model.chain, "2026-12-02T09:00:00Z", 0.0, "t", "test-trunnion")
        .unwrap()
    };
    // C with the ball 100 mm out on +X, A with it 150 mm out on +Y at the A line's height: each
    // bar as the test set it up, whichever way the axis turns.
    for (bar, want) in [(BarDirection::Radial, Bar::Radial), (BarDirection::Tangential, Bar::Tangential), (BarDirection::Axial, Bar::Axial)] {
        for (axis, start, sweep, pivot) in [(Axis::C, 0.0, 360.0, [100.0, 0.0, 340.0]), (Axis::A, -90.0, 120.0, [0.0, 150.0, 350.0]), (Axis::A, 30.0, -120.0, [0.0, 150.0, 350.0])] {
            let r = rotary_run(&model, &run(&[(axis, start, sweep)], bar, pivot), 0).unwrap();
            assert_eq!((r.axis(), r.bar), (axis, Some(want)), "{axis} {bar:?}");
            assert_eq!(r.sense, if sweep > 0.0 { Direction::CCW } else { Direction::CW });
            // To within a sample's step at 10 Hz (the last sample falls short of the sweep's end).
            let (lo, hi) = r.range_deg();
            assert!((lo - start.min(start + sweep)).abs() < 1.0 && (hi - start.max(start + sweep)).abs() < 1.0, "{lo}..{hi}");
        }
    }
    // Two axes turning: drawn against the one that sweeps the most, whichever the test named
    // first; its sense is the run's. The test named A first, so its bar is radial to A at the
    // start, which is along C's line: the title says what it is to the axis drawn.
    let two = run(&[(Axis::A, 0.0, -60.0), (Axis::C, 360.0, -360.0)], BarDirection::Radial, [100.0, 0.0, 340.0]);
    let r = rotary_run(&model, &two, 0).unwrap();
    assert_eq!((r.axis(), r.sense), (Axis::C, Direction::CW));
    let (a, lo, hi) = r.turning[1];
    assert!(a == Axis::A && (lo + 60.0).abs() < 1.0 && hi == 0.0, "{:?}", r.turning[1]);
    let t = title(&two, &r, r.range_deg());
    assert!(t.starts_with("C and A turning together (C over ") && t.contains(", A over -59.9…0°), drawn against C, axial bar (to C), ball at pivot Z 340 mm"), "{t}");
    // A bar 27° off radial (the tool 50 mm higher) is none of the three: a rotary run.
    let mut oblique = run(&[(Axis::C, 0.0, 360.0)], BarDirection::Radial, [100.0, 0.0, 340.0]);
    oblique.axes[Axis::Z.index()].as_mut().unwrap().iter_mut().for_each(|z| *z += 50.0);
    let r = rotary_run(&model, &oblique, 0).unwrap();
    assert_eq!(r.bar, None);
    assert!(title(&oblique, &r, r.range_deg()).contains("A at 0°, rotary run (the bar neither radial, tangential nor axial to C)"));
    // A planar run is not a rotary run.
    assert!(rotary_run(&model, &five_axis().0.runs[0].run, 0).is_none());
}

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

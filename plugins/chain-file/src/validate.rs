//! From the file as written to a validated [`MachineSpec`] (stage two of two): the branches
//! from the parent links, the error list expanded to [`TermSpec`]s, and the model built once
//! ([`Model::new`]) to validate what the model itself checks. Every error is placed in the file
//! ([`crate::locate`]).

use std::collections::HashMap;

use ballbar_model::Axis;
use ballbar_model::machine::{
    AxisNorm, JointSpec, MachineSpec, Model, ModelOptions, TermSpec, paper_terms,
};

use crate::ChainFileError;
use crate::locate::{Step, locate};
use crate::raw::{BASE, RawChainFile, RawError, RawJoint};

/// What the model says, without its generic prefix.
fn model_message(e: ballbar_model::ModelError) -> String {
    match e {
        ballbar_model::ModelError::InvalidMachine { message } => message,
        other => other.to_string(),
    }
}

/// An error at the value at `path` of `text`.
fn at(text: &str, path: &[Step], message: String) -> ChainFileError {
    // The file parsed in full before stage two, so every path that the checks name exists. Were
    // it ever missing, the error still names a real place: the start of the file.
    let p = locate(text, path)
        .or_else(|| locate(text, &[]))
        .unwrap_or(crate::locate::Position { line: 1, column: 1 });
    ChainFileError { line: p.line, column: p.column, message }
}

/// The joints from the base to `end` (empty for the base), as indices into `joints`.
fn path_to(joints: &[RawJoint], index: &HashMap<&str, usize>, end: &str) -> Vec<usize> {
    let mut out = Vec::new();
    let mut at = end;
    // Parents are listed before their children (checked while reading), so this ends.
    while at != BASE {
        let k = index[at];
        out.push(k);
        at = &joints[k].parent;
    }
    out.reverse();
    out
}

/// The paper's id of the squareness in the plane of `a` and `b`.
fn squareness_id(a: Axis, b: Axis) -> String {
    let plane = match (a.min(b), a.max(b)) {
        (Axis::X, Axis::Y) => "XY",
        (Axis::Y, Axis::Z) => "YZ",
        _ => "ZX",
    };
    format!("SQ{plane}")
}

/// The rotation about a direction: A, B, C for X, Y, Z (and for themselves).
fn rotation_about(a: Axis) -> Axis {
    Axis::ALL[3 + a.index() % 3]
}

/// The schema that brought an entry of the error list.
fn entry_schema(e: &RawError) -> (u32, &'static str) {
    match e {
        RawError::RotaryPositioning { .. } => (2, "RotaryPositioning"),
        RawError::RotaryRunout { .. } => (2, "RotaryRunout"),
        RawError::RotaryWobble { .. } => (2, "RotaryWobble"),
        RawError::Backlash { axis } if axis.is_rotary() => (2, "Backlash of a rotary axis"),
        RawError::ServoLag { axis } if axis.is_rotary() => (2, "ServoLag of a rotary axis"),
        _ => (1, ""),
    }
}

/// The checks of one entry of the error list that need more than one of its values: the
/// error's message and the field it is at.
fn check_entry(e: &RawError) -> Option<(&'static str, String)> {
    match e {
        RawError::RotaryWobble { axis, about, .. } if rotation_about(*about) == *axis => Some((
            "about",
            format!(
                "a tilt of {axis} about its own line ({about}) is its angular positioning error: write RotaryPositioning(axis: {axis}, ...)"
            ),
        )),
        _ => None,
    }
}

/// The terms of one entry of the error list.
fn expand(e: &RawError) -> Vec<TermSpec> {
    match e {
        RawError::Paper => paper_terms(),
        RawError::Positional { axis, degrees } => {
            vec![TermSpec::Positional { axis: *axis, degrees: degrees.clone() }]
        }
        RawError::Straightness { axis, toward, degrees, tie_angles } => {
            vec![TermSpec::Straightness {
                axis: *axis,
                toward: *toward,
                degrees: degrees.clone(),
                tie_angles: *tie_angles,
            }]
        }
        RawError::Angular { axis, about, degrees } => {
            vec![TermSpec::Angular { axis: *axis, about: *about, degrees: degrees.clone() }]
        }
        RawError::Squareness { id, axis, toward } => {
            vec![TermSpec::Squareness {
                id: id.clone().unwrap_or_else(|| squareness_id(*axis, *toward)),
                axis: *axis,
                toward: *toward,
            }]
        }
        RawError::Backlash { axis } => vec![TermSpec::Backlash { axis: *axis }],
        RawError::ServoLag { axis } => vec![TermSpec::ServoLag { axis: *axis }],
        RawError::RotaryPositioning { axis, harmonics } => {
            vec![TermSpec::RotaryPositioning { axis: *axis, harmonics: harmonics.clone() }]
        }
        RawError::RotaryRunout { axis, direction, harmonics } => {
            vec![TermSpec::RotaryRunout {
                axis: *axis,
                direction: *direction,
                harmonics: harmonics.clone(),
            }]
        }
        // The tilt's direction as the ids name it: A, B, C (X, Y, Z are read as them).
        RawError::RotaryWobble { axis, about, harmonics } => vec![TermSpec::RotaryWobble {
            axis: *axis,
            about: rotation_about(*about),
            harmonics: harmonics.clone(),
        }],
        RawError::RotaryLocation(names) => {
            // One term per run of names of the same axis, in the order written.
            let mut out: Vec<TermSpec> = Vec::new();
            for n in names {
                match out.last_mut() {
                    Some(TermSpec::RotaryLocation { axis, components }) if *axis == n.axis => {
                        components.push(n.component)
                    }
                    _ => out.push(TermSpec::RotaryLocation {
                        axis: n.axis,
                        components: vec![n.component],
                    }),
                }
            }
            out
        }
    }
}

/// Stage two: the whole-file checks and the [`MachineSpec`].
pub fn validate(text: &str, raw: RawChainFile) -> Result<MachineSpec, ChainFileError> {
    let joints = &raw.joints.0;
    if joints.is_empty() {
        return Err(at(
            text,
            &[Step::Field("joints")],
            "a machine needs at least one joint".into(),
        ));
    }
    let index: HashMap<&str, usize> =
        joints.iter().enumerate().map(|(k, j)| (j.name.as_str(), k)).collect();
    let names = || {
        std::iter::once(BASE)
            .chain(joints.iter().map(|j| j.name.as_str()))
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for (field, end) in [("tool", &raw.tool), ("workpiece", &raw.workpiece)] {
        if end != BASE && !index.contains_key(end.as_str()) {
            return Err(at(
                text,
                &[Step::Field(field)],
                format!("{field}: no joint named '{end}' (the joints: {})", names()),
            ));
        }
    }
    if raw.tool == raw.workpiece && raw.tool != BASE {
        return Err(at(
            text,
            &[Step::Field("workpiece")],
            format!(
                "tool and workpiece both end at joint '{}': the spindle and the table ride on different branches",
                raw.tool
            ),
        ));
    }
    let tool = path_to(joints, &index, &raw.tool);
    let work = path_to(joints, &index, &raw.workpiece);
    let route = |branch: &[usize]| {
        std::iter::once(BASE)
            .chain(branch.iter().map(|&k| joints[k].name.as_str()))
            .collect::<Vec<_>>()
            .join(" → ")
    };
    for (k, j) in joints.iter().enumerate() {
        match (tool.contains(&k), work.contains(&k)) {
            (true, true) => {
                return Err(at(
                    text,
                    &[Step::Field("joints"), Step::Index(k)],
                    format!(
                        "joint '{}' is on both branches (tool: {}; workpiece: {}): the two branches meet only at the base",
                        j.name,
                        route(&tool),
                        route(&work)
                    ),
                ));
            }
            (false, false) => {
                return Err(at(
                    text,
                    &[Step::Field("joints"), Step::Index(k)],
                    format!(
                        "joint '{}' is on neither branch: it is not on the path from the base to the tool joint '{}' ({}) nor to the workpiece joint '{}' ({})",
                        j.name,
                        raw.tool,
                        route(&tool),
                        raw.workpiece,
                        route(&work)
                    ),
                ));
            }
            _ => {}
        }
    }
    for (k, n) in raw.normalisation.iter().enumerate() {
        if let Some(first) = raw.normalisation[..k].iter().position(|m| m.axis == n.axis) {
            return Err(at(
                text,
                &[Step::Field("normalisation"), Step::Index(k), Step::Field("axis")],
                format!(
                    "axis {} is normalised twice (entries {} and {})",
                    n.axis,
                    first + 1,
                    k + 1
                ),
            ));
        }
        if !joints.iter().any(|j| j.axis == n.axis) {
            return Err(at(
                text,
                &[Step::Field("normalisation"), Step::Index(k), Step::Field("axis")],
                format!("axis {} drives no joint of this machine", n.axis),
            ));
        }
    }
    let spec_of = |list: &[usize]| -> Vec<JointSpec> {
        list.iter()
            .map(|&k| {
                let j = &joints[k];
                JointSpec {
                    name: j.name.clone(),
                    axis: j.axis,
                    kind: j.kind,
                    direction: j.direction,
                    origin_mm: j.origin_mm,
                }
            })
            .collect()
    };
    for (k, e) in raw.errors.iter().enumerate() {
        let (needs, what) = entry_schema(e);
        if needs > raw.schema.0 {
            // A file of an older schema is read as that schema: what came later is an error
            // that says so, not a silent extension (a plugin of that schema would refuse it).
            return Err(at(
                text,
                &[Step::Field("errors"), Step::Index(k)],
                format!(
                    "{what} is an entry of schema {needs}, but the file says schema {}: write schema: {needs}",
                    raw.schema.0
                ),
            ));
        }
        if let Some((field, message)) = check_entry(e) {
            return Err(at(
                text,
                &[Step::Field("errors"), Step::Index(k), Step::Field(field)],
                message,
            ));
        }
    }
    let expanded: Vec<Vec<TermSpec>> = raw.errors.iter().map(expand).collect();
    let mut spec = MachineSpec {
        name: raw.name,
        version: raw.version,
        description: raw.description,
        tool: spec_of(&tool),
        workpiece: spec_of(&work),
        normalisation: raw
            .normalisation
            .iter()
            .map(|n| AxisNorm {
                axis: n.axis,
                reference_mm: n.reference_mm,
                length_mm: n.length_mm,
            })
            .collect(),
        terms: expanded.concat(),
    };
    if let Err(e) = Model::new(spec.clone(), ModelOptions::default()) {
        // Find the culprit: the chain alone, else the first entry of the list that breaks it
        // (a term id used twice breaks at its second use).
        let terms = std::mem::take(&mut spec.terms);
        if let Err(e) = Model::new(spec.clone(), ModelOptions::default()) {
            return Err(at(text, &[Step::Field("joints")], model_message(e)));
        }
        for k in 0..expanded.len() {
            spec.terms = expanded[..=k].concat();
            if let Err(e) = Model::new(spec.clone(), ModelOptions::default()) {
                return Err(at(text, &[Step::Field("errors"), Step::Index(k)], model_message(e)));
            }
        }
        // Unreachable while the model's checks depend only on the terms so far; the error list
        // is still the right place to point at.
        spec.terms = terms;
        return Err(at(text, &[Step::Field("errors")], model_message(e)));
    }
    Ok(spec)
}

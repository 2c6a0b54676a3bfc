//! The output documents (`ballbar-documents`) against what the command writes and what the
//! contract names: every shipped example's `fit --json` and `diagnose --json` read into the
//! typed documents and written back give the same JSON (nothing the command writes is unknown
//! to the types, nothing the types hold is lost), and every field of `shared/spec/cli.md`'s
//! examples is in them.

use ballbar_documents::VendorEntry;
use ballbar_documents::diagnosis::Diagnosis;
use ballbar_documents::fit::Fit;
use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::common::*;

/// Run `ballbar <command> --machine <machine> <inputs…> --json FILE` and read FILE.
fn document(command: &str, machine: &str, inputs: &[&str], name: &str) -> Value {
    let dir = scratch(&format!("documents-{name}"));
    let out = dir.join("out.json");
    let mut args = vec![command, "--machine", machine];
    args.extend_from_slice(inputs);
    args.extend(["--json", out.to_str().unwrap()]);
    let o = ballbar(&args);
    assert!(o.status.success(), "{}", text(&o));
    serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
}

/// `value` read into `T` and written back is `value` again; returns the typed document.
fn round_trip<T: DeserializeOwned + Serialize>(value: &Value, what: &str) -> T {
    let typed: T = serde_json::from_value(value.clone())
        .unwrap_or_else(|e| panic!("{what}: not read by the typed document: {e}"));
    let back = serde_json::to_value(&typed).unwrap();
    if back != *value {
        let mut diffs = Vec::new();
        differences("", value, &back, &mut diffs);
        panic!("{what}: written back differently:\n{}", diffs.join("\n"));
    }
    typed
}

/// Where `a` and `b` differ, as paths.
fn differences(path: &str, a: &Value, b: &Value, out: &mut Vec<String>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for k in x.keys().chain(y.keys().filter(|k| !x.contains_key(*k))) {
                match (x.get(k), y.get(k)) {
                    (Some(p), Some(q)) => differences(&format!("{path}.{k}"), p, q, out),
                    (p, q) => out.push(format!("{path}.{k}: {p:?} → {q:?}")),
                }
            }
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => {
            for (i, (p, q)) in x.iter().zip(y).enumerate() {
                differences(&format!("{path}[{i}]"), p, q, out);
            }
        }
        _ if a != b => out.push(format!("{path}: {a} → {b}")),
        _ => {}
    }
}

/// Every field path of a contract example (`gap.where[].share`); the keys of an effect's
/// `parameters` are the effect's own (`amplitude_um` of a spike), not fields of the document.
fn paths(v: &Value, prefix: &str, out: &mut Vec<String>) {
    match v {
        Value::Object(o) => {
            for (k, w) in o {
                let p = if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") };
                out.push(p.clone());
                if k != "parameters" {
                    paths(w, &p, out);
                }
            }
        }
        Value::Array(a) => {
            if let Some(first) = a.first() {
                paths(first, &format!("{prefix}[]"), out);
            }
        }
        _ => {}
    }
}

/// Whether `path` (as [`paths`] writes it) is in `v`: an array's part of the path must be in
/// one of its entries.
fn has(v: &Value, path: &str) -> bool {
    let (head, rest) = match path.split_once('.') {
        Some((h, r)) => (h, Some(r)),
        None => (path, None),
    };
    let (key, array) = match head.strip_suffix("[]") {
        Some(k) => (k, true),
        None => (head, false),
    };
    let Some(w) = v.get(key) else { return false };
    match (array, rest) {
        (false, None) => true,
        (false, Some(r)) => has(w, r),
        (true, None) => w.is_array(),
        (true, Some(r)) => w.as_array().is_some_and(|a| a.iter().any(|e| has(e, r))),
    }
}

/// The JSON examples of `shared/spec/cli.md`: the diagnosis document and the
/// `vendor_comparison` fragment (as an object holding it). `None` (skipped) without the spec.
fn contract_examples() -> Option<(Value, Value)> {
    let spec = root().join("../shared/spec/cli.md");
    let Ok(text) = std::fs::read_to_string(&spec) else {
        skip(Needs::SharedData, &format!("{} is not there (the CLI contract)", spec.display()));
        return None;
    };
    let blocks: Vec<&str> = text
        .split("```json")
        .skip(1)
        .map(|b| b.split("```").next().expect("a closed block"))
        .collect();
    assert_eq!(blocks.len(), 2, "cli.md has two JSON examples: the diagnosis, vendor_comparison");
    let diagnosis = serde_json::from_str(blocks[0]).expect("the diagnosis example is JSON");
    let vendor = serde_json::from_str(&format!("{{{}}}", blocks[1]))
        .expect("the vendor_comparison example is a JSON member");
    Some((diagnosis, vendor))
}

/// Every field the contract names is in `document`, except `pending`: fields the contract
/// names that this version does not write yet (listed, so that writing them, or the contract
/// naming another, changes this test).
fn assert_contract_fields(example: &Value, document: &Value, pending: &[&str], what: &str) {
    let mut all = Vec::new();
    paths(example, "", &mut all);
    let missing: Vec<&String> = all.iter().filter(|p| !has(document, p)).collect();
    assert_eq!(missing, pending.to_vec(), "{what}: fields of cli.md's example not written");
}

#[test]
fn the_shipped_examples_documents_read_into_the_types_and_back_and_hold_the_contracts_fields() {
    let examples = contract_examples();
    for (machine, runs) in
        [("column", "fixtures/column-paper/runs"), ("horizontal", "fixtures/horizontal-paper/runs")]
    {
        let fit = document("fit", machine, &[runs], &format!("fit-{machine}"));
        let typed: Fit = round_trip(&fit, &format!("fit of {runs}"));
        assert_eq!(typed.format, ballbar_documents::fit::FORMAT);
        assert_eq!(typed.runs.len(), 6);

        let diagnosis = document("diagnose", machine, &[runs], &format!("diagnose-{machine}"));
        let typed: Diagnosis = round_trip(&diagnosis, &format!("diagnosis of {runs}"));
        assert_eq!(typed.format, ballbar_documents::diagnosis::FORMAT);
        assert_eq!(typed.machine, machine);
        // The examples fill every list the contract's example has an entry in.
        assert!(!typed.gap.where_.is_empty() && !typed.aliased.is_empty(), "{diagnosis}");
        assert!(typed.effects.as_ref().is_some_and(|e| !e.is_empty()), "{diagnosis}");
        if let Some((example, _)) = &examples {
            assert_contract_fields(example, &diagnosis, &[], &format!("diagnosis of {runs}"));
        }
    }
}

#[test]
fn a_vendor_files_documents_read_into_the_types_and_back_with_the_vendor_comparison() {
    let Some(examples) = contract_examples() else { return };
    let p = root().join("../shared/data/real/d2-xy-50mm-1500.b5r");
    if !p.is_file() {
        skip(
            Needs::SharedData,
            &format!("{} is not there (the shared real test file)", p.display()),
        );
        return;
    }
    let file = p.to_str().unwrap();
    let fit = document("fit", "column", &[file], "fit-b5r");
    let typed: Fit = round_trip(&fit, "fit of the real file");
    let entries: &[VendorEntry] = typed.vendor_comparison.as_deref().expect("vendor_comparison");
    assert!(!entries.is_empty());
    let diagnosis = document("diagnose", "column", &[file], "diagnose-b5r");
    let typed: Diagnosis = round_trip(&diagnosis, "diagnosis of the real file");
    assert!(typed.vendor_comparison.is_some_and(|v| !v.is_empty()));
    // Every field the contract names is written, `ours_as_vendor` and `why` included.
    for (doc, what) in [(&fit, "fit"), (&diagnosis, "diagnosis")] {
        assert_contract_fields(&examples.1, doc, &[], what);
    }
}

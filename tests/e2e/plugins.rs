//! Machine plugins as an integrator meets them: the bundled plugins load from their libraries;
//! broken or mismatched plugins, built here with `rustc`, are error messages that name the
//! file and the problem, never a crash; the binary alone in a folder finds none and says where
//! it looked; the out-of-tree example plugin (`docs/example-plugin`) builds offline, loads
//! with `--plugin`, and a simulate-then-fit recovers its kernel term.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use crate::common::*;

/// How the binary is run: which executable, and what `BALLBAR_PLUGIN_PATH` it sees.
fn run_with(exe: &Path, plugin_path: Option<&OsString>, args: &[&str]) -> Output {
    let mut c = Command::new(exe);
    c.args(args).current_dir(root());
    match plugin_path {
        Some(p) => c.env("BALLBAR_PLUGIN_PATH", p),
        None => c.env_remove("BALLBAR_PLUGIN_PATH"),
    };
    c.output().unwrap_or_else(|e| panic!("{}: {e}", exe.display()))
}

/// A file as a library name (`lib<name>.so` on Linux).
fn dll(name: &str) -> String {
    format!("{}{name}{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX)
}

/// A hard link of `from` at `to` (no writable descriptor of an executable is ever open, so
/// running it cannot meet "text file busy"), or a copy across file systems.
fn link_or_copy(from: &Path, to: &Path) {
    let _ = std::fs::remove_file(to);
    if std::fs::hard_link(from, to).is_err() {
        std::fs::copy(from, to)
            .unwrap_or_else(|e| panic!("copy {} to {}: {e}", from.display(), to.display()));
    }
}

/// Exit code 1 (not a signal, not a panic's 101), a message naming `file` and each of `what`,
/// and no panic trace of the host.
#[track_caller]
fn assert_input_error(o: &Output, file: &Path, what: &[&str]) {
    let t = text(o);
    assert_eq!(o.status.code(), Some(1), "expected exit 1: {t}");
    assert!(
        t.contains(&file.display().to_string()),
        "the message does not name {}: {t}",
        file.display()
    );
    for w in what {
        assert!(t.contains(w), "expected '{w}' in: {t}");
    }
    assert_no_panic_trace(o);
}

#[track_caller]
fn assert_no_panic_trace(o: &Output) {
    let t = text(o);
    assert!(
        !t.contains("panicked at") && !t.contains("RUST_BACKTRACE"),
        "a panic trace reached the user: {t}"
    );
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("not JSON ({e}): {}", text(o)))
}

/// The entry of `plugins --json` for machine type `name`.
fn listed<'a>(v: &'a serde_json::Value, name: &str) -> Option<&'a serde_json::Value> {
    v["plugins"].as_array().unwrap().iter().find(|p| p["name"] == name)
}

// ---------------------------------------------------------------------------------------------
// The binary alone in a folder.

/// The binary under test, alone in a folder of its own (linked there once per test run).
fn lone_exe() -> &'static Path {
    static EXE: OnceLock<PathBuf> = OnceLock::new();
    EXE.get_or_init(|| {
        let dir = scratch("lone-binary");
        let lone = dir.join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
        link_or_copy(&exe(), &lone);
        lone
    })
}

#[test]
fn the_binary_alone_finds_no_plugins_names_the_folder_and_works_with_the_plugin_path() {
    let exe = lone_exe();
    // The folder as the binary sees itself (current_exe is the resolved path).
    let folder = exe.parent().unwrap().canonicalize().unwrap();
    let o = run_with(exe, None, &["plugins"]);
    assert_input_error(
        &o,
        &folder,
        &[
            "found no machine plugins",
            "(executable folder)",
            "BALLBAR_PLUGIN_PATH",
            "--plugin FILE",
        ],
    );

    let o = run_with(exe, None, &["plugins", "--json"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    let v = json(&o);
    assert_eq!(v["plugins"].as_array().unwrap().len(), 0, "{v}");
    let installed = folder.parent().unwrap().join("lib/ballbar/plugins");
    assert_eq!(
        v["searched"],
        serde_json::json!([
            {"source": "executable folder", "path": folder.display().to_string()},
            {"source": "installed plugins folder", "path": installed.display().to_string()},
        ])
    );

    let o = run_with(exe, None, &["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    assert_input_error(&o, &folder, &["found no machine plugins"]);

    let with = bundled_plugin_path();
    let o =
        run_with(exe, Some(&with), &["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("ballbar fit — machine 'column'"), "{}", text(&o));
}

// ---------------------------------------------------------------------------------------------
// The bundled plugins.

#[test]
fn each_bundled_plugin_loads_from_its_library_and_fits_its_fixtures() {
    let o = ballbar(&["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    let mut expected = vec![
        ("column", plugin_file("ballbar_machine_column")),
        ("horizontal", plugin_file("ballbar_machine_horizontal")),
    ];
    // The chain-file plugin (user-defined machines) is checked when it is built.
    let chain_file = plugin_file("ballbar_machine_chain_file");
    if chain_file.is_file() {
        expected.push(("chain-file", chain_file));
    }
    for (name, file) in &expected {
        let p = listed(&v, name).unwrap_or_else(|| panic!("plugin '{name}' not listed: {v}"));
        assert_eq!(p["abi_version"], 1, "{p}");
        assert_eq!(p["path"], file.display().to_string(), "{p}");
        assert!(!p["version"].as_str().unwrap().is_empty(), "{p}");
        assert_eq!(p["reads_machine_files"], *name == "chain-file", "{p}");
    }

    // Through the libraries alone: the lone binary sees only the --plugin files.
    let mut args: Vec<String> = Vec::new();
    for (_, file) in &expected {
        args.extend(["--plugin".to_string(), file.display().to_string()]);
    }
    let with = |more: &[&str]| -> Vec<String> {
        args.iter().cloned().chain(more.iter().map(|s| s.to_string())).collect()
    };
    let a = with(&["plugins", "--json"]);
    let o = run_with(lone_exe(), None, &a.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    assert_eq!(v["plugins"].as_array().unwrap().len(), expected.len(), "{v}");
    assert_eq!(v["problems"].as_array().unwrap().len(), 0, "{v}");
    for machine in ["column", "horizontal"] {
        let runs = format!("fixtures/{machine}-paper/runs");
        let a =
            with(&["fit", "--machine", machine, "--servo", "paper", "--bar-length-um", "0", &runs]);
        let o = run_with(lone_exe(), None, &a.iter().map(String::as_str).collect::<Vec<_>>());
        let t = text(&o);
        assert!(o.status.success(), "{machine}: {t}");
        assert!(t.contains(&format!("ballbar fit — machine '{machine}'")), "{machine}: {t}");
        // The fixtures carry 0.2 µm of noise: a fit through the plugin's machine leaves that.
        let sigma: f64 = t
            .split("residual σ ")
            .nth(1)
            .and_then(|r| r.split_whitespace().next())
            .and_then(|x| x.parse().ok())
            .unwrap_or_else(|| panic!("{t}"));
        assert!((sigma - 0.2).abs() < 0.02, "{machine}: residual σ {sigma} µm");
    }
}

// ---------------------------------------------------------------------------------------------
// Broken plugins, built here with rustc (std only, the ABI crate's source included by path).

/// The deliberately broken plugins, each a file named as a folder search would take it.
struct Broken {
    /// (a) declares ABI version `ABI_VERSION + 1`.
    wrong_abi: PathBuf,
    /// (b) a shared library that exports no declaration.
    no_symbol: PathBuf,
    /// (c) a text file with a library's name.
    not_a_library: PathBuf,
    /// (d) machine type `describe-panics`: panics in `describe`.
    describe_panics: PathBuf,
    /// (e) machine type `malformed`: returns RON that is not a machine description.
    malformed: PathBuf,
    /// (f) machine type `kernel-panics`: its machine has a kernel term whose kernel panics.
    kernel_panics: PathBuf,
    /// (g) the right ABI, but null functions in its declaration (as a C library could write).
    null_functions: PathBuf,
}

/// The start of a source that uses the ABI crate's definitions: the crate's file as a module,
/// re-exported at the crate root, where `declare_plugin!`'s `$crate::` paths look.
fn with_api(body: &str) -> String {
    let api = root().join("crates/ballbar-plugin-api/src/lib.rs");
    format!("#[path = {:?}]\nmod api;\npub use api::*;\n\n{body}", api.display().to_string())
}

/// A column machine (the chain of `plugins/column`) with three positional terms and one kernel
/// term, `KX` on X, whose kernel `compensation_table` panics.
const KERNEL_PANICS: &str = r##"
const MACHINE: &str = r#"(
    name: "kernel-panics",
    version: "0.0.1",
    description: "a machine whose maker's kernel indexes past its table",
    tool: [(name: "Z head", axis: Z, kind: Linear, direction: (0.0, 0.0, 1.0), origin_mm: (0.0, 0.0, 0.0))],
    workpiece: [
        (name: "Y saddle", axis: Y, kind: Linear, direction: (0.0, 1.0, 0.0), origin_mm: (0.0, 0.0, 0.0)),
        (name: "X table", axis: X, kind: Linear, direction: (1.0, 0.0, 0.0), origin_mm: (0.0, 0.0, 0.0)),
    ],
    normalisation: [
        (axis: X, reference_mm: 0.0, length_mm: 250.0),
        (axis: Y, reference_mm: 0.0, length_mm: 250.0),
        (axis: Z, reference_mm: 0.0, length_mm: 250.0),
    ],
    terms: [
        Positional(axis: X, degrees: [1]),
        Positional(axis: Y, degrees: [1]),
        Positional(axis: Z, degrees: [1]),
        Kernel(id: "KX", label: "X compensation table", axis: X, kernel: "compensation_table", unit: Length, class: Other),
    ],
)"#;

fn describe(_input: &str) -> Result<String, String> {
    Ok(MACHINE.to_string())
}

/// A table of 8 entries every 50 mm: X beyond 400 mm indexes past its end (the fixtures reach 450).
static TABLE: [f64; 8] = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];

fn compensation_table(states: &[RawJointState], out: &mut [[f64; 6]]) -> Result<(), String> {
    for (e, s) in out.iter_mut().zip(states) {
        let k = (s.q / 50.0).floor().max(0.0) as usize;
        *e = [TABLE[k], 0.0, 0.0, 0.0, 0.0, 0.0];
    }
    Ok(())
}

crate::declare_plugin! {
    name: "kernel-panics",
    version: "0.0.1",
    flags: 0,
    describe: describe,
    kernels: [("compensation_table", compensation_table)],
}
"##;

/// Build the broken plugins once per test run: one rustc per library, all at once.
fn broken() -> &'static Broken {
    static BROKEN: OnceLock<Broken> = OnceLock::new();
    BROKEN.get_or_init(|| {
        let dir = scratch("broken-plugins");
        let sources: [(&str, String); 6] = [
            (
                "null_functions",
                with_api(
                    r#"
/// A declaration of the right version whose functions are null.
#[unsafe(export_name = "ballbar_plugin_declaration")]
pub static DECLARATION: PluginDeclaration = PluginDeclaration {
    abi_version: ABI_VERSION,
    struct_size: DECLARATION_SIZE,
    name: StrRef::from_static("null-functions"),
    version: StrRef::from_static("0.0.1"),
    flags: 0,
    describe: None,
    evaluate: None,
    free_buffer: None,
    kernel_count: 0,
    kernels: std::ptr::null(),
    joint_state_size: JOINT_STATE_SIZE,
};
"#,
                ),
            ),
            (
                "wrong_abi",
                with_api(
                    r#"
unsafe extern "C" fn describe(_input: StrRef, _out: *mut OwnedBuffer) -> i32 {
    STATUS_ERROR
}

unsafe extern "C" fn evaluate(_kernel: usize, _states: *const RawJointState, _n: usize, _out: *mut f64, _message: *mut OwnedBuffer) -> i32 {
    STATUS_ERROR
}

/// A plugin built against a later ABI than the host's.
#[unsafe(export_name = "ballbar_plugin_declaration")]
pub static DECLARATION: PluginDeclaration = PluginDeclaration {
    abi_version: ABI_VERSION + 1,
    struct_size: DECLARATION_SIZE,
    name: StrRef::from_static("from-the-future"),
    version: StrRef::from_static("9.0.0"),
    flags: 0,
    describe: Some(describe),
    evaluate: Some(evaluate),
    free_buffer: Some(export::free_buffer),
    kernel_count: 0,
    kernels: std::ptr::null(),
    joint_state_size: JOINT_STATE_SIZE,
};
"#,
                ),
            ),
            (
                "no_symbol",
                r#"
/// A shared library of something else: it exports a function, not a plugin declaration.
#[unsafe(no_mangle)]
pub extern "C" fn some_other_entry_point() -> i32 {
    42
}
"#
                .to_string(),
            ),
            (
                "describe_panics",
                with_api(
                    r#"
fn describe(_input: &str) -> Result<String, String> {
    panic!("the machine table is not wired up")
}

crate::declare_plugin! {
    name: "describe-panics",
    version: "0.0.1",
    flags: 0,
    describe: describe,
    kernels: [],
}
"#,
                ),
            ),
            (
                "malformed",
                with_api(
                    r#"
/// RON, but not a machine description: the version is not a string (line 3).
fn describe(_input: &str) -> Result<String, String> {
    Ok("(\n    name: \"malformed\",\n    version: 0.0.1,\n)".to_string())
}

crate::declare_plugin! {
    name: "malformed",
    version: "0.0.1",
    flags: 0,
    describe: describe,
    kernels: [],
}
"#,
                ),
            ),
            ("kernel_panics", with_api(KERNEL_PANICS)),
        ];
        let rustc = rustc();
        let children: Vec<(String, std::process::Child)> = sources
            .iter()
            .map(|(name, src)| {
                let file = dir.join(format!("{name}.rs"));
                std::fs::write(&file, src).unwrap();
                let child = Command::new(&rustc)
                    .args(["--edition", "2024", "--crate-type", "cdylib", "-C", "debuginfo=0", "-o"])
                    .arg(dir.join(dll(&format!("ballbar_machine_{name}"))))
                    .arg(&file)
                    .stdout(std::process::Stdio::piped())
                    .stderr(std::process::Stdio::piped())
                    .spawn()
                    .unwrap_or_else(|e| panic!("{}: {e}", rustc.display()));
                (name.to_string(), child)
            })
            .collect();
        for (name, child) in children {
            let o = child.wait_with_output().unwrap();
            assert!(o.status.success(), "rustc {name}.rs: {}", text(&o));
        }
        let not_a_library = dir.join(dll("ballbar_machine_not_a_library"));
        std::fs::write(&not_a_library, "This is a text file that someone named like a plugin.\n").unwrap();
        let lib = |name: &str| dir.join(dll(&format!("ballbar_machine_{name}")));
        Broken {
            wrong_abi: lib("wrong_abi"),
            no_symbol: lib("no_symbol"),
            not_a_library,
            describe_panics: lib("describe_panics"),
            malformed: lib("malformed"),
            kernel_panics: lib("kernel_panics"),
            null_functions: lib("null_functions"),
        }
    })
}

/// The rustc of the toolchain that runs the tests (beside `$CARGO`), else the one on `PATH`.
fn rustc() -> PathBuf {
    std::env::var_os("CARGO")
        .map(PathBuf::from)
        .map(|cargo| cargo.with_file_name(format!("rustc{}", std::env::consts::EXE_SUFFIX)))
        .filter(|r| r.is_file())
        .unwrap_or_else(|| PathBuf::from("rustc"))
}

/// `ballbar --plugin FILE ARGS...` with the bundled plugins on the path.
fn with_plugin(file: &Path, args: &[&str]) -> Output {
    let f = file.display().to_string();
    let mut all = vec!["--plugin", f.as_str()];
    all.extend_from_slice(args);
    ballbar(&all)
}

const FIT_COLUMN: [&str; 4] = ["fit", "--machine", "column", "fixtures/column-paper/runs"];

#[test]
fn a_plugin_of_another_abi_version_is_refused_with_what_to_do() {
    let f = &broken().wrong_abi;
    let want = ["speaks ABI version", "rebuild the plugin against ballbar-plugin-api"];
    assert_input_error(&with_plugin(f, &["plugins"]), f, &want);
    assert_input_error(&with_plugin(f, &FIT_COLUMN), f, &want);
}

#[test]
fn a_declaration_with_null_functions_is_refused_before_any_call() {
    let f = &broken().null_functions;
    let want = ["declaration is malformed", "null function"];
    assert_input_error(&with_plugin(f, &["plugins"]), f, &want);
    assert_input_error(
        &with_plugin(f, &["fit", "--machine", "null-functions", "fixtures/column-paper/runs"]),
        f,
        &want,
    );
}

#[test]
fn a_library_without_the_declaration_is_not_a_plugin() {
    let f = &broken().no_symbol;
    let want = [
        "not a ballbar machine plugin",
        "exports no symbol 'ballbar_plugin_declaration'",
        "declare_plugin!",
    ];
    assert_input_error(&with_plugin(f, &["plugins"]), f, &want);
    assert_input_error(&with_plugin(f, &FIT_COLUMN), f, &want);
}

#[test]
fn a_file_that_is_not_a_library_is_an_error_naming_it() {
    let f = &broken().not_a_library;
    let want = ["cannot be loaded as a plugin library"];
    assert_input_error(&with_plugin(f, &["plugins"]), f, &want);
    assert_input_error(&with_plugin(f, &FIT_COLUMN), f, &want);
}

#[test]
fn a_panic_in_describe_is_caught_and_reported() {
    let f = &broken().describe_panics;
    let want =
        ["plugin 'describe-panics' panicked in describe", "the machine table is not wired up"];
    // Listing calls `describe` (to say what the plugin provides): the panic is listed as the
    // plugin's problem, and the command fails, without a crash.
    let o = with_plugin(f, &["plugins"]);
    assert_input_error(&o, f, &want);
    assert!(String::from_utf8_lossy(&o.stdout).contains("PROBLEM: "), "{}", text(&o));
    assert_input_error(
        &with_plugin(f, &["fit", "--machine", "describe-panics", "fixtures/column-paper/runs"]),
        f,
        &want,
    );
    let dir = scratch("describe-panics");
    let out = dir.join("runs");
    let o = with_plugin(
        f,
        &[
            "simulate",
            "--machine",
            "describe-panics",
            "--truth",
            "fixtures/column-paper/truth.ron",
            "--out",
            out.to_str().unwrap(),
        ],
    );
    assert_input_error(&o, f, &want);
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn a_malformed_machine_description_is_reported_with_its_place() {
    let f = &broken().malformed;
    let o = with_plugin(f, &["plugins"]);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", text(&o));
    assert_no_panic_trace(&o);
    let o = with_plugin(f, &["fit", "--machine", "malformed", "fixtures/column-paper/runs"]);
    assert_input_error(
        &o,
        f,
        &["plugin 'malformed' returned a machine description that is not valid", "line 3"],
    );
}

#[test]
fn a_kernel_that_panics_during_a_fit_is_an_error_not_a_crash() {
    let f = &broken().kernel_panics;
    let o = with_plugin(f, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    let p = listed(&v, "kernel-panics").unwrap_or_else(|| panic!("{v}"));
    assert_eq!(p["kernels"], serde_json::json!(["compensation_table"]));
    assert_eq!(p["path"], f.display().to_string());
    // The column runs without their `machine:` header (a run naming another machine is
    // refused before any kernel runs).
    let runs = scratch("kernel-panics-runs");
    for e in std::fs::read_dir(root().join("fixtures/column-paper/runs")).unwrap() {
        let p = e.unwrap().path();
        let text = std::fs::read_to_string(&p).unwrap();
        let kept: String = text
            .lines()
            .filter(|l| !l.starts_with("# machine:"))
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::write(runs.join(p.file_name().unwrap()), kept).unwrap();
    }
    let o = with_plugin(f, &["fit", "--machine", "kernel-panics", runs.to_str().unwrap()]);
    assert_input_error(
        &o,
        f,
        &[
            "error term KX",
            "kernel 'compensation_table'",
            "plugin 'kernel-panics'",
            "panicked",
            "index out of bounds",
        ],
    );
}

#[test]
fn broken_plugin_files_in_a_searched_folder_are_warnings_and_the_good_ones_work() {
    let b = broken();
    let folder = scratch("plugin-folder");
    for name in ["ballbar_machine_column", "ballbar_machine_horizontal"] {
        link_or_copy(&plugin_file(name), &folder.join(dll(name)));
    }
    let bad = [
        (&b.wrong_abi, "speaks ABI version"),
        (&b.no_symbol, "exports no symbol"),
        (&b.not_a_library, "cannot be loaded as a plugin library"),
    ];
    for (file, _) in bad {
        link_or_copy(file, &folder.join(file.file_name().unwrap()));
    }
    // Not plugin names: a folder search does not even try them.
    std::fs::write(folder.join(dll("something_else")), "not a library either").unwrap();
    std::fs::write(folder.join("README.txt"), "plugins for the shop floor").unwrap();
    let path = folder.clone().into_os_string();

    let o = run_with(lone_exe(), Some(&path), &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    for name in ["column", "horizontal"] {
        let p = listed(&v, name).unwrap_or_else(|| panic!("{name}: {v}"));
        assert!(p["path"].as_str().unwrap().starts_with(folder.to_str().unwrap()), "{p}");
    }
    let problems: Vec<&str> =
        v["problems"].as_array().unwrap().iter().map(|p| p.as_str().unwrap()).collect();
    assert_eq!(problems.len(), bad.len(), "{problems:?}");
    for (file, what) in bad {
        let in_folder = folder.join(file.file_name().unwrap()).display().to_string();
        assert!(
            problems.iter().any(|p| p.contains(&in_folder) && p.contains(what)),
            "{in_folder}: {what}: {problems:?}"
        );
    }

    let o = run_with(
        lone_exe(),
        Some(&path),
        &["fit", "--machine", "horizontal", "fixtures/horizontal-paper/runs"],
    );
    assert!(o.status.success(), "{}", text(&o));
    assert_no_panic_trace(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    for (file, what) in bad {
        let in_folder = folder.join(file.file_name().unwrap()).display().to_string();
        assert!(
            err.lines()
                .any(|l| l.starts_with("warning: ") && l.contains(&in_folder) && l.contains(what)),
            "{in_folder}: {err}"
        );
    }
    assert!(!err.contains("something_else") && !err.contains("README"), "{err}");
}

// ---------------------------------------------------------------------------------------------
// The worked example: docs/example-plugin, built as an integrator builds it.

/// Build `docs/example-plugin` once per test run with cargo, offline, into `target/example-plugin`.
fn example_plugin() -> &'static Path {
    static LIB: OnceLock<PathBuf> = OnceLock::new();
    LIB.get_or_init(|| {
        // target/<profile>/ballbar-under-test → target/
        let target = exe().parent().unwrap().parent().unwrap().join("example-plugin");
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let o = Command::new(&cargo)
            .args(["build", "--offline", "--release", "--quiet", "--manifest-path"])
            .arg(root().join("docs/example-plugin/Cargo.toml"))
            .arg("--target-dir")
            .arg(&target)
            .env_remove("CARGO_BUILD_TARGET")
            .output()
            .unwrap_or_else(|e| panic!("{cargo:?}: {e}"));
        assert!(o.status.success(), "cargo build of docs/example-plugin: {}", text(&o));
        let lib = target.join("release").join(dll("ballbar_machine_bed_mill"));
        assert!(lib.is_file(), "{}", lib.display());
        lib
    })
}

#[test]
fn the_example_plugin_builds_out_of_tree_loads_and_its_kernel_term_is_recovered() {
    let lib = example_plugin();
    let o = with_plugin(lib, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    let p = listed(&v, "bed-mill").unwrap_or_else(|| panic!("{v}"));
    assert_eq!(p["abi_version"], 1, "{p}");
    assert_eq!(p["path"], lib.display().to_string(), "{p}");
    assert_eq!(p["kernels"], serde_json::json!(["head_warmup"]), "{p}");
    let o = with_plugin(lib, &["plugins"]);
    assert!(
        o.status.success() && text(&o).contains("machine type 'bed-mill', kernels head_warmup"),
        "{}",
        text(&o)
    );

    // The truth file of the walk-through in docs/plugins.md.
    let truth_file = "docs/example-plugin/truth.ron";
    let truth: ballbar_sim::Truth =
        ron::from_str(&std::fs::read_to_string(root().join(truth_file)).unwrap()).unwrap();
    let dir = scratch("example-plugin");
    let runs = dir.join("runs");
    let o = with_plugin(
        lib,
        &[
            "simulate",
            "--machine",
            "bed-mill",
            "--truth",
            truth_file,
            "--out",
            runs.to_str().unwrap(),
            "--seed",
            "3",
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let report = dir.join("fit.json");
    let o = with_plugin(
        lib,
        &[
            "fit",
            "--machine",
            "bed-mill",
            "--servo",
            "paper",
            "--bar-length-um",
            "0",
            runs.to_str().unwrap(),
            "--json",
            report.to_str().unwrap(),
        ],
    );
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap();
    assert_eq!(
        v["identifiability"]["rank"], v["identifiability"]["parameters"],
        "every term identifiable"
    );
    let want = truth.errors["THZ"];
    assert!(want.abs() >= 5.0, "the truth gives the kernel term a value that matters ({want} µm)");
    let p = v["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["id"] == "THZ")
        .unwrap_or_else(|| panic!("THZ: {v}"));
    assert_eq!(p["unit"], "µm");
    assert_eq!(p["estimable"], true, "{p}");
    let (got, u) = (p["value"].as_f64().unwrap(), p["std_uncertainty"].as_f64().unwrap());
    // Tolerance: a settled growth only shows through its change within the YZ and ZX runs (1 to
    // 2 µm per run for 15 µm, as the session passes one time constant); with 0.2 µm of white
    // noise that gives u ≈ 0.12 µm. The seed is fixed; 4 u covers the noise, and u itself must
    // stay below 0.5 µm (3 % of the growth), or the example would not show what it claims.
    assert!(u < 0.5, "THZ: u = {u} µm");
    assert!((got - want).abs() < 4.0 * u, "THZ: fitted {got} ± {u} µm, truth {want} µm");
    // The model with its kernels explains the runs down to the noise.
    let sigma = v["residual"]["sigma_um"].as_f64().unwrap();
    assert!(
        (sigma - truth.noise_um).abs() < 0.02,
        "residual σ {sigma} µm vs noise {} µm",
        truth.noise_um
    );
}

/// `plugins --json` takes a FILE as every other command's `--json` does; `-` or no FILE is
/// standard output (scripts run `plugins --json`), and with a FILE the list for a person is
/// printed as well.
#[test]
fn plugins_json_takes_a_file_or_standard_output() {
    let dir = scratch("plugins-json");
    let file = dir.join("plugins.json");
    let o = ballbar(&["plugins", "--json", file.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&file).unwrap()).unwrap();
    assert!(listed(&v, "column").is_some(), "{v}");
    assert!(String::from_utf8_lossy(&o.stdout).starts_with("plugin "), "{}", text(&o));
    for args in [&["plugins", "--json", "-"][..], &["plugins", "--json"][..]] {
        let o = ballbar(args);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
        assert_eq!(json(&o), v, "{args:?}");
    }
    assert!(!root().join("-").exists(), "a file named '-'");
}

// ---------------------------------------------------------------------------------------------
// Who may have written a plugin: a library, file or folder that someone other than the user or
// root could have changed is never loaded.

/// A library whose constructor (run by the loader inside `dlopen`, before any symbol is looked
/// up) writes the file `BALLBAR_TEST_MARKER` names: it exports no declaration, so a run that
/// loads it can only say it is not a plugin, but the marker shows that it was loaded at all.
#[cfg(unix)]
fn planted() -> &'static Path {
    static PLANTED: OnceLock<PathBuf> = OnceLock::new();
    PLANTED.get_or_init(|| {
        let dir = scratch("planted-library");
        let src = dir.join("planted.rs");
        std::fs::write(
            &src,
            r#"
extern "C" fn on_load() {
    if let Some(p) = std::env::var_os("BALLBAR_TEST_MARKER") {
        let _ = std::fs::write(p, b"the planted library ran");
    }
}

#[used]
#[cfg_attr(target_os = "linux", unsafe(link_section = ".init_array"))]
#[cfg_attr(target_os = "macos", unsafe(link_section = "__DATA,__mod_init_func"))]
static ON_LOAD: extern "C" fn() = on_load;
"#,
        )
        .unwrap();
        let lib = dir.join(dll("ballbar_machine_planted"));
        let o = Command::new(rustc())
            .args(["--edition", "2024", "--crate-type", "cdylib", "-C", "debuginfo=0", "-o"])
            .arg(&lib)
            .arg(&src)
            .output()
            .unwrap();
        assert!(o.status.success(), "rustc planted.rs: {}", text(&o));
        lib
    })
}

/// `exe ARGS...` with `BALLBAR_PLUGIN_PATH` (or none) and the planted library's marker file.
#[cfg(unix)]
fn run_marked(exe: &Path, plugin_path: Option<&OsString>, marker: &Path, args: &[&str]) -> Output {
    let mut c = Command::new(exe);
    c.args(args).current_dir(root()).env("BALLBAR_TEST_MARKER", marker);
    match plugin_path {
        Some(p) => c.env("BALLBAR_PLUGIN_PATH", p),
        None => c.env_remove("BALLBAR_PLUGIN_PATH"),
    };
    c.output().unwrap_or_else(|e| panic!("{}: {e}", exe.display()))
}

#[cfg(unix)]
fn chmod(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt as _;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode))
        .unwrap_or_else(|e| panic!("chmod {mode:o} {}: {e}", path.display()));
}

/// The bundled plugins, then `extra`, as a `BALLBAR_PLUGIN_PATH`.
fn bundled_and(extra: &Path) -> OsString {
    let mut all = bundled_plugins();
    all.push(extra.to_path_buf());
    std::env::join_paths(all).unwrap()
}

/// The entries of `plugins --json`'s `refused`.
fn refused(v: &serde_json::Value) -> &Vec<serde_json::Value> {
    v["refused"].as_array().unwrap_or_else(|| panic!("no refused list: {v}"))
}

#[cfg(unix)]
#[test]
fn a_plugin_folder_others_can_write_is_refused_and_no_library_in_it_is_loaded() {
    let d = scratch("planted-writable");
    let folder = d.join("plugins");
    std::fs::create_dir(&folder).unwrap();
    link_or_copy(planted(), &folder.join(dll("ballbar_machine_planted")));
    // o+w on a folder of ours.
    chmod(&folder, 0o757);
    let marker = d.join("marker");
    let path = bundled_and(&folder);

    let o = run_marked(&exe(), Some(&path), &marker, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));
    let v = json(&o);
    let r = refused(&v);
    assert_eq!(r.len(), 1, "{v}");
    assert_eq!(r[0]["path"], folder.display().to_string(), "{v}");
    assert_eq!(r[0]["folder"], true, "{v}");
    assert_eq!(r[0]["source"], "BALLBAR_PLUGIN_PATH", "{v}");
    let reason = r[0]["reason"].as_str().unwrap();
    assert!(reason.contains("writable by others (mode 0757)"), "{reason}");
    assert!(r[0]["fix"].as_str().unwrap().contains("chmod go-w"), "{v}");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(&format!("warning: refused the plugin folder {}", folder.display())),
        "{err}"
    );

    // The list for a person says it too, and a command that needs the machine in it says why
    // it is not there.
    let o = run_marked(&exe(), Some(&path), &marker, &["plugins"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        String::from_utf8_lossy(&o.stdout).contains(&format!(
            "refused the plugin folder {} (BALLBAR_PLUGIN_PATH)",
            folder.display()
        )),
        "{}",
        text(&o)
    );
    let o = run_marked(
        &exe(),
        Some(&path),
        &marker,
        &["fit", "--machine", "planted", "fixtures/column-paper/runs"],
    );
    assert_input_error(&o, &folder, &["no machine type 'planted'", "writable by others"]);
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));

    // Writable by its owner alone, the folder is searched and the library loaded: the marker
    // appears, so the checks above would have seen a load.
    chmod(&folder, 0o755);
    let o = run_marked(&exe(), Some(&path), &marker, &["plugins", "--json"]);
    assert!(marker.exists(), "the planted library's constructor did not run: {}", text(&o));
    assert!(refused(&json(&o)).is_empty(), "{}", text(&o));
}

#[cfg(unix)]
#[test]
fn a_plugin_given_with_plugin_that_others_can_write_is_an_error_that_says_how_to_fix_it() {
    let d = scratch("planted-explicit");
    let file = d.join(dll("ballbar_machine_planted"));
    std::fs::copy(planted(), &file).unwrap();
    let marker = d.join("marker");
    let given = file.to_str().unwrap();
    let real = file.canonicalize().unwrap();

    chmod(&file, 0o646);
    let o =
        run_marked(&exe(), Some(&bundled_plugin_path()), &marker, &["--plugin", given, "plugins"]);
    assert_input_error(
        &o,
        &file,
        &[
            "refused to load this plugin",
            &format!("the plugin file {} is writable by others (mode 0646)", real.display()),
            &format!("chmod go-w {}", real.display()),
        ],
    );
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));

    // Its folder writable by others: the same.
    chmod(&file, 0o644);
    chmod(&d, 0o757);
    let o =
        run_marked(&exe(), Some(&bundled_plugin_path()), &marker, &["--plugin", given, "plugins"]);
    let folder = real.parent().unwrap();
    assert_input_error(
        &o,
        &file,
        &[&format!("its folder {} is writable by others (mode 0757)", folder.display())],
    );
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));

    // Fixed as the message says: loaded (and, exporting no declaration, not a plugin).
    chmod(&d, 0o755);
    let o =
        run_marked(&exe(), Some(&bundled_plugin_path()), &marker, &["--plugin", given, "plugins"]);
    assert_input_error(&o, &file, &["not a ballbar machine plugin"]);
    assert!(marker.exists(), "the planted library's constructor did not run: {}", text(&o));
}

/// A binary copied to a folder looks for its installed plugins in `../lib/ballbar/plugins`
/// from there, which in `/tmp` any user can create: a folder another user owns is refused,
/// and so is a plugin file another user owns in a folder of ours.
#[cfg(unix)]
#[test]
fn plugin_files_and_folders_another_user_owns_are_refused() {
    let d = scratch("planted-owner");
    let bin = d.join("x");
    std::fs::create_dir(&bin).unwrap();
    let copied = bin.join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
    link_or_copy(&exe(), &copied);
    let installed = d.join("lib/ballbar/plugins");
    std::fs::create_dir_all(&installed).unwrap();
    let planted_file = installed.join(dll("ballbar_machine_planted"));
    std::fs::copy(planted(), &planted_file).unwrap();
    // Another user's: the folders and the file, as if that user had made them.
    let other = 4242;
    if let Err(e) = std::os::unix::fs::chown(d.join("lib"), Some(other), None) {
        skip(Needs::Root, &format!("giving a folder to uid {other} needs root ({e})"));
        return;
    }
    for p in [d.join("lib/ballbar"), installed.clone(), planted_file.clone()] {
        std::os::unix::fs::chown(&p, Some(other), None).unwrap();
    }
    let marker = d.join("marker");
    let o = run_marked(&copied, None, &marker, &["plugins", "--json"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));
    let v = json(&o);
    let r = refused(&v);
    assert_eq!(r.len(), 1, "{v}");
    let shown = bin.canonicalize().unwrap().parent().unwrap().join("lib/ballbar/plugins");
    assert_eq!(r[0]["path"], shown.display().to_string(), "{v}");
    assert_eq!(r[0]["source"], "installed plugins folder", "{v}");
    let reason = r[0]["reason"].as_str().unwrap();
    assert!(reason.contains(&format!("belongs to uid {other}, not to you")), "{reason}");
    let o = run_marked(
        &copied,
        None,
        &marker,
        &["fit", "--machine", "planted", "fixtures/column-paper/runs"],
    );
    assert_input_error(&o, &shown, &["found no machine plugins", "belongs to uid 4242"]);
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));

    // Another user's file in a folder of ours: that file alone is refused.
    let mine = d.join("mine");
    std::fs::create_dir(&mine).unwrap();
    let theirs = mine.join(dll("ballbar_machine_planted"));
    std::fs::copy(planted(), &theirs).unwrap();
    std::os::unix::fs::chown(&theirs, Some(other), None).unwrap();
    let o = run_marked(&exe(), Some(&bundled_and(&mine)), &marker, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(!marker.exists(), "the planted library was loaded: {}", text(&o));
    let v = json(&o);
    let r = refused(&v);
    assert_eq!(r.len(), 1, "{v}");
    assert_eq!(r[0]["path"], theirs.display().to_string(), "{v}");
    assert_eq!(r[0]["folder"], false, "{v}");
    let reason = r[0]["reason"].as_str().unwrap();
    assert!(
        reason.contains("the plugin file") && reason.contains("belongs to uid 4242"),
        "{reason}"
    );
}

//! Around the command (issue #14, item 10): an installed tree, laid out by the very code of
//! `cargo xtask dist` / `install` (`xtask/src/layout.rs`, included here), runs from anywhere
//! with no `BALLBAR_PLUGIN_PATH`, can be moved, is not replaced without `--force` and is
//! uninstalled; a binary copied alone says where it looked for plugins and how to install
//! them; `ballbar completions SHELL`; `ballbar --version` names the commit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::*;

#[path = "../../xtask/src/layout.rs"]
#[allow(dead_code)]
mod layout;

/// Run `exe` from the repository root with no `BALLBAR_PLUGIN_PATH`: it finds only what its
/// own place gives it.
fn run_alone(exe: &Path, args: &[&str]) -> Output {
    let mut c = Command::new(exe);
    c.args(args).current_dir(root()).env_remove("BALLBAR_PLUGIN_PATH");
    layout::output(&mut c).unwrap_or_else(|e| panic!("{}: {e}", exe.display()))
}

/// The binary under test in `dir/bin/ballbar` (a hard link, or a copy across file systems),
/// nothing else: the copy a user makes of the binary alone.
fn binary_alone(dir: &Path) -> PathBuf {
    let exe = dir.join("bin").join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
    std::fs::create_dir_all(exe.parent().unwrap()).unwrap();
    if std::fs::hard_link(super::common::exe(), &exe).is_err() {
        std::fs::copy(super::common::exe(), &exe).unwrap();
    }
    exe
}

fn json(o: &Output) -> serde_json::Value {
    serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("not JSON ({e}): {}", text(o)))
}

#[test]
fn an_installed_tree_finds_its_plugins_anywhere_without_the_plugin_path() {
    let dir = scratch("install-tree");
    let prefix = dir.join("first");
    let plugins = bundled_plugins();
    let install = layout::Install { prefix: &prefix, binary: Some(&super::common::exe()), plugins: &plugins, force: false };
    let written = layout::install(&install).unwrap();
    // The binary, the three bundled plugins, three completion scripts.
    assert_eq!(written.len(), 7, "{written:?}");
    let exe = layout::binary(&prefix);
    assert_eq!(exe, prefix.join("bin").join(format!("ballbar{}", std::env::consts::EXE_SUFFIX)));

    // It lists the plugins from lib/ballbar/plugins, and fits with them: the shipped fixture
    // with the paper's set-up leaves its 0.2 µm of simulated noise.
    let o = run_alone(&exe, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    let installed = prefix.canonicalize().unwrap().join("lib/ballbar/plugins");
    let mut names: Vec<&str> = v["plugins"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["chain-file", "column", "horizontal"], "{v}");
    for p in v["plugins"].as_array().unwrap() {
        assert!(Path::new(p["path"].as_str().unwrap()).starts_with(&installed), "{p}");
    }
    assert_eq!(v["searched"][1], serde_json::json!({"source": "installed plugins folder", "path": installed.display().to_string()}), "{v}");
    let o = run_alone(&exe, &["fit", "--machine", "column", "--servo", "paper", "--bar-length-um", "0", "fixtures/column-paper/runs"]);
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let sigma: f64 = t.split("residual σ ").nth(1).and_then(|r| r.split_whitespace().next()).and_then(|x| x.parse().ok()).unwrap_or_else(|| panic!("{t}"));
    // The fixtures carry 0.2 µm of noise (as in plugins.rs).
    assert!((sigma - 0.2).abs() < 0.02, "residual σ {sigma} µm");
    // The chain-file plugin came along: a user-defined machine fits too.
    let o = run_alone(&exe, &["fit", "--machine-file", "fixtures/machines/column.ron", "fixtures/column-paper/runs"]);
    assert!(o.status.success(), "{}", text(&o));

    // The completion scripts are the binary's own.
    let bash = std::fs::read_to_string(prefix.join("share/bash-completion/completions/ballbar")).unwrap();
    assert!(bash.contains("_ballbar()") && bash.contains("--machine"), "{bash}");
    assert!(std::fs::read_to_string(prefix.join("share/zsh/site-functions/_ballbar")).unwrap().starts_with("#compdef ballbar"));
    assert!(std::fs::read_to_string(prefix.join("share/fish/vendor_completions.d/ballbar.fish")).unwrap().contains("complete -c ballbar"));

    // The tree moved as a whole still works: the plugins are found relative to the binary.
    let moved = dir.join("moved");
    std::fs::rename(&prefix, &moved).unwrap();
    let o = run_alone(&layout::binary(&moved), &["plugins"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains(&moved.canonicalize().unwrap().join("lib/ballbar/plugins").display().to_string()), "{}", text(&o));

    // Installing again does not replace anything without force; with it, it does.
    let again = layout::Install { prefix: &moved, ..install.clone() };
    let before = std::fs::metadata(layout::binary(&moved)).unwrap().modified().unwrap();
    let e = layout::install(&again).unwrap_err();
    assert!(e.contains(&layout::binary(&moved).display().to_string()) && e.contains("--force"), "{e}");
    assert_eq!(std::fs::metadata(layout::binary(&moved)).unwrap().modified().unwrap(), before);
    assert_eq!(layout::install(&layout::Install { force: true, ..again }).unwrap().len(), 7);

    // Uninstalling removes ballbar's files and keeps a plugin of the user's own.
    let own = layout::plugin_dir(&moved).join(format!("{}ballbar_machine_mine{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX));
    std::fs::write(&own, "a user's plugin").unwrap();
    let names: Vec<String> = plugins.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    let (removed, left) = layout::uninstall(&moved, &names).unwrap();
    assert_eq!(removed.len(), 7, "{removed:?}");
    assert_eq!(left, vec![own.clone()]);
    assert!(!layout::binary(&moved).exists() && own.is_file());
    std::fs::remove_file(&own).unwrap();
    let (removed, left) = layout::uninstall(&moved, &names).unwrap();
    assert!(removed.is_empty() && left.is_empty());
    assert!(!moved.join("lib/ballbar").exists(), "the emptied lib/ballbar is removed");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_binary_copied_alone_says_where_it_looked_and_how_to_install_the_plugins() {
    let dir = scratch("copied-alone");
    let exe = binary_alone(&dir);
    // The folders as the binary sees itself (current_exe is the resolved path).
    let bin = exe.parent().unwrap().canonicalize().unwrap();
    let installed = dir.canonicalize().unwrap().join("lib/ballbar/plugins");
    let o = run_alone(&exe, &["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    let t = text(&o);
    assert_eq!(o.status.code(), Some(1), "{t}");
    for what in [
        "found no machine plugins",
        &format!("{} (executable folder)", bin.display()),
        &format!("{} (installed plugins folder)", installed.display()),
        "cargo xtask install",
        "BALLBAR_PLUGIN_PATH",
        "--plugin FILE",
    ] {
        assert!(t.contains(what), "expected '{what}' in: {t}");
    }
    let o = run_alone(&exe, &["plugins", "--json"]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert_eq!(
        json(&o)["searched"],
        serde_json::json!([
            {"source": "executable folder", "path": bin.display().to_string()},
            {"source": "installed plugins folder", "path": installed.display().to_string()},
        ])
    );
    // Putting the plugins where it said is enough.
    std::fs::create_dir_all(&installed).unwrap();
    for p in bundled_plugins() {
        std::fs::copy(&p, installed.join(p.file_name().unwrap())).unwrap();
    }
    let o = run_alone(&exe, &["fit", "--machine", "column", "fixtures/column-paper/runs"]);
    assert!(o.status.success(), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn completions_for_each_shell_need_no_plugin() {
    let dir = scratch("completions");
    // Alone, without plugins: completions do not search for them, nor warn.
    let exe = binary_alone(&dir);
    let o = run_alone(&exe, &["completions", "bash"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(o.stderr.is_empty(), "{}", text(&o));
    let bash = String::from_utf8(o.stdout).unwrap();
    for word in ["fit", "diagnose", "simulate", "predict", "import", "program", "record", "replay", "export", "report", "history", "plugins", "completions"] {
        // The script's dispatch on the subcommand word.
        assert!(bash.contains(&format!("ballbar,{word})")), "subcommand {word} missing");
    }
    for option in ["--machine", "--machine-file", "--plugin", "--json", "--record", "--force", "--servo"] {
        assert!(bash.contains(option), "option {option} missing");
    }
    for (shell, mark) in [("zsh", "#compdef ballbar"), ("fish", "complete -c ballbar"), ("powershell", "Register-ArgumentCompleter"), ("elvish", "edit:completion:arg-completer[ballbar]")] {
        let o = run_alone(&exe, &["completions", shell]);
        assert!(o.status.success(), "{shell}: {}", text(&o));
        let script = String::from_utf8_lossy(&o.stdout);
        assert!(script.contains(mark) && script.contains("diagnose") && script.contains("--machine"), "{shell}: {script}");
    }
    let o = run_alone(&exe, &["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `git ARGS` in the repository root, when git and a checkout are there.
fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git").args(args).current_dir(root()).env("GIT_OPTIONAL_LOCKS", "0").output().ok()?;
    o.status.success().then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

#[test]
fn version_names_the_commit_it_was_built_from() {
    let o = ballbar(&["--version"]);
    assert!(o.status.success(), "{}", text(&o));
    let line = String::from_utf8(o.stdout).unwrap();
    let prefix = format!("ballbar {} (commit ", env!("CARGO_PKG_VERSION"));
    let commit = line.trim().strip_prefix(&prefix).and_then(|r| r.strip_suffix(')')).unwrap_or_else(|| panic!("not '{prefix}…)': {line}"));
    assert_eq!(text(&ballbar(&["-V"])), line);
    // A checkout of this repository (CI's is a fresh clone): the commit of HEAD, and `-dirty`
    // exactly when the binary's sources differ from it (the build script's own definition).
    let checkout = git(&["rev-parse", "--show-toplevel"]).is_some_and(|top| Path::new(&top).canonicalize().ok() == root().canonicalize().ok());
    match (checkout, git(&["rev-parse", "--short", "HEAD"])) {
        (true, Some(head)) => {
            let dirty = !git(&["status", "--porcelain", "--", "crates", "plugins", "Cargo.toml", "Cargo.lock"]).unwrap().is_empty();
            let expected = if dirty { format!("{head}-dirty") } else { head };
            assert_eq!(commit, expected, "{line}");
            assert!(commit.split('-').next().unwrap().chars().all(|c| c.is_ascii_hexdigit()), "{line}");
        }
        _ => assert!(commit == "unknown commit" || std::env::var_os("BALLBAR_BUILD_COMMIT").is_some(), "{line}"),
    }
}

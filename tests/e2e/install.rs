//! Around the command: an installed tree, laid out by the very code of `cargo xtask dist` /
//! `install` / `uninstall` (`xtask::layout`, the xtask library's: the tasks from their
//! arguments to their output, with the binary under test handed in as the release build), runs
//! from anywhere with no `BALLBAR_PLUGIN_PATH`, can be moved, is not replaced without
//! `--force`, replaces an earlier install's plugins with it, and is uninstalled by its
//! manifest, which removes nothing it did not write; a binary copied alone says where it
//! looked for plugins and how to install them; `ballbar completions SHELL`;
//! `ballbar --version` names the commit.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::*;

use xtask::layout;

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

/// What a task run gave: its result, what it told the user, and whether it built.
struct Ran {
    result: Result<(), layout::Failure>,
    out: String,
    built: bool,
}

/// Run the xtask task `task` with `args`, the binary under test and `plugins` handed in as the
/// release build; no HOME, no PATH.
fn task(task: &str, args: &[&Path], plugins: &[PathBuf]) -> Ran {
    task_built(task, args, super::common::exe(), plugins)
}

/// [`task`] with `binary` handed in as the release build's binary.
fn task_built(task: &str, args: &[&Path], binary: PathBuf, plugins: &[PathBuf]) -> Ran {
    let args: Vec<String> = args.iter().map(|a| a.display().to_string()).collect();
    let mut built = false;
    let mut build = || {
        built = true;
        Ok(layout::Built { binary: binary.clone(), plugins: plugins.to_vec() })
    };
    let mut host = layout::Host { home: None, dist_dir: None, path: None, build: &mut build };
    let mut out = Vec::new();
    let result = layout::run(task, &args, &mut host, &mut out);
    Ran { result, out: String::from_utf8(out).unwrap(), built }
}

/// The manifest's paths, in order.
fn listed(prefix: &Path) -> Vec<String> {
    layout::read_manifest(prefix)
        .unwrap()
        .expect("a manifest")
        .into_iter()
        .map(|e| e.path)
        .collect()
}

fn plugin_name(lib: &str) -> String {
    format!("{}{lib}{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX)
}

#[test]
fn an_installed_tree_finds_its_plugins_anywhere_without_the_plugin_path() {
    let dir = scratch("install-tree");
    let prefix = dir.join("first");
    let plugins = bundled_plugins();
    let r = task("dist", &[Path::new("--out"), &prefix], &plugins);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    // The binary, the three bundled plugins, three completion scripts; the check's listing.
    assert!(r.out.contains(&format!("wrote 7 files to {}", prefix.display())), "{}", r.out);
    assert!(r.out.contains("machine type 'column'"), "{}", r.out);
    let exe = layout::binary(&prefix);
    assert_eq!(exe, prefix.join("bin").join(format!("ballbar{}", std::env::consts::EXE_SUFFIX)));
    let mut manifest = listed(&prefix);
    manifest.sort();
    let mut expected: Vec<String> =
        ["ballbar_machine_chain_file", "ballbar_machine_column", "ballbar_machine_horizontal"]
            .iter()
            .map(|n| format!("lib/ballbar/plugins/{}", plugin_name(n)))
            .collect();
    expected.extend([format!("bin/ballbar{}", std::env::consts::EXE_SUFFIX)]);
    expected.extend(layout::COMPLETIONS.iter().map(|(_, f)| f.to_string()));
    expected.sort();
    assert_eq!(manifest, expected);

    // It lists the plugins from lib/ballbar/plugins, and fits with them: the shipped fixture
    // with the paper's set-up leaves its 0.2 µm of simulated noise.
    let o = run_alone(&exe, &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    let installed = prefix.canonicalize().unwrap().join("lib/ballbar/plugins");
    let mut names: Vec<&str> =
        v["plugins"].as_array().unwrap().iter().map(|p| p["name"].as_str().unwrap()).collect();
    names.sort();
    assert_eq!(names, ["chain-file", "column", "horizontal"], "{v}");
    for p in v["plugins"].as_array().unwrap() {
        assert!(Path::new(p["path"].as_str().unwrap()).starts_with(&installed), "{p}");
    }
    assert_eq!(
        v["searched"][1],
        serde_json::json!({"source": "installed plugins folder", "path": installed.display().to_string()}),
        "{v}"
    );
    let o = run_alone(
        &exe,
        &[
            "fit",
            "--machine",
            "column",
            "--servo",
            "paper",
            "--bar-length-um",
            "0",
            "fixtures/column-paper/runs",
        ],
    );
    let t = text(&o);
    assert!(o.status.success(), "{t}");
    let sigma: f64 = t
        .split("residual σ ")
        .nth(1)
        .and_then(|r| r.split_whitespace().next())
        .and_then(|x| x.parse().ok())
        .unwrap_or_else(|| panic!("{t}"));
    // The fixtures carry 0.2 µm of noise (as in plugins.rs).
    assert!((sigma - 0.2).abs() < 0.02, "residual σ {sigma} µm");
    // The chain-file plugin came along: a user-defined machine fits too.
    let o = run_alone(
        &exe,
        &["fit", "--machine-file", "fixtures/machines/column.ron", "fixtures/column-paper/runs"],
    );
    assert!(o.status.success(), "{}", text(&o));

    // The completion scripts are the binary's own.
    let bash =
        std::fs::read_to_string(prefix.join("share/bash-completion/completions/ballbar")).unwrap();
    assert!(bash.contains("_ballbar()") && bash.contains("--machine"), "{bash}");
    assert!(
        std::fs::read_to_string(prefix.join("share/zsh/site-functions/_ballbar"))
            .unwrap()
            .starts_with("#compdef ballbar")
    );
    assert!(
        std::fs::read_to_string(prefix.join("share/fish/vendor_completions.d/ballbar.fish"))
            .unwrap()
            .contains("complete -c ballbar")
    );

    // The tree moved as a whole still works: the plugins are found relative to the binary.
    let moved = dir.join("moved");
    std::fs::rename(&prefix, &moved).unwrap();
    let o = run_alone(&layout::binary(&moved), &["plugins"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains(
            &moved.canonicalize().unwrap().join("lib/ballbar/plugins").display().to_string()
        ),
        "{}",
        text(&o)
    );

    // Laying it out again does not replace anything without force (refused before the build);
    // with it, it does.
    let before = std::fs::metadata(layout::binary(&moved)).unwrap().modified().unwrap();
    let r = task("dist", &[Path::new("--out"), &moved], &plugins);
    let Err(layout::Failure::Error(e)) = &r.result else { panic!("{:?}", r.result) };
    assert!(
        e.contains(&layout::binary(&moved).display().to_string()) && e.contains("--force"),
        "{e}"
    );
    assert!(!r.built);
    assert_eq!(std::fs::metadata(layout::binary(&moved)).unwrap().modified().unwrap(), before);
    let r = task("dist", &[Path::new("--out"), &moved, Path::new("--force")], &plugins);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(r.out.contains("wrote 7 files"), "{}", r.out);

    // Uninstalling removes ballbar's files and the manifest, keeps a plugin of the user's own
    // and names it; the folder it is in stays.
    let own = layout::plugin_dir(&moved).join(plugin_name("ballbar_machine_mine"));
    std::fs::write(&own, "a user's plugin").unwrap();
    let u = layout::uninstall(&moved).unwrap();
    assert_eq!(u.removed.len(), 7, "{u:?}");
    assert_eq!(u.kept.iter().map(|(p, _)| p.clone()).collect::<Vec<_>>(), vec![own.clone()]);
    assert_eq!(u.manifest, Some(layout::manifest(&moved)));
    assert!(
        !layout::binary(&moved).exists() && !layout::manifest(&moved).exists() && own.is_file()
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The build's plugins writable by their group (as a umask of 002 leaves them): installed
/// writable by their owner alone, as are the folders made for them, so that the installed
/// binary, which refuses plugins others could change, loads them.
#[cfg(unix)]
#[test]
fn installed_plugins_and_their_folders_are_writable_by_their_owner_alone() {
    use std::os::unix::fs::PermissionsExt as _;
    let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
    let dir = scratch("install-modes");
    let built = dir.join("built");
    std::fs::create_dir(&built).unwrap();
    let plugins: Vec<PathBuf> = bundled_plugins()
        .iter()
        .map(|p| {
            let to = built.join(p.file_name().unwrap());
            std::fs::copy(p, &to).unwrap();
            std::fs::set_permissions(&to, std::fs::Permissions::from_mode(0o775)).unwrap();
            to
        })
        .collect();
    let prefix = dir.join("tree");
    let r = task("dist", &[Path::new("--out"), &prefix], &plugins);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    let folder = prefix.join("lib/ballbar/plugins");
    for p in &plugins {
        let installed = folder.join(p.file_name().unwrap());
        assert_eq!(mode(&installed), 0o755, "{}", installed.display());
    }
    for d in [prefix.clone(), prefix.join("lib"), prefix.join("lib/ballbar"), folder] {
        assert_eq!(mode(&d) & 0o022, 0, "{}: {:o}", d.display(), mode(&d));
    }
    let o = run_alone(&layout::binary(&prefix), &["plugins", "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let v = json(&o);
    assert_eq!(v["plugins"].as_array().unwrap().len(), 3, "{v}");
    assert_eq!(v["refused"], serde_json::json!([]), "{v}");
}

#[test]
fn uninstall_removes_only_the_unchanged_files_its_manifest_lists() {
    let dir = scratch("uninstall-manifest");
    let prefix = dir.join("prefix");
    let r = task("install", &[Path::new("--prefix"), &prefix], &bundled_plugins());
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(
        r.out.contains(&format!("installed {}", layout::binary(&prefix).display())),
        "{}",
        r.out
    );
    assert!(
        r.out.contains(&format!("recorded 7 files in {}", layout::manifest(&prefix).display())),
        "{}",
        r.out
    );
    assert!(r.out.contains("is not on PATH"), "{}", r.out);
    // Since then: the user edited the bash completion, made bin/ballbar a link of their own
    // (to a binary with the very content installed), and added a plugin.
    let bash = prefix.join(layout::COMPLETIONS[0].1);
    std::fs::write(&bash, std::fs::read_to_string(&bash).unwrap() + "# my own addition\n").unwrap();
    let exe = layout::binary(&prefix);
    std::fs::remove_file(&exe).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(super::common::exe(), &exe).unwrap();
    #[cfg(windows)]
    std::os::windows::fs::symlink_file(super::common::exe(), &exe).unwrap();
    let own = layout::plugin_dir(&prefix).join(plugin_name("ballbar_machine_mine"));
    std::fs::write(&own, "a user's plugin").unwrap();

    let r = task("uninstall", &[Path::new("--prefix"), &prefix], &[]);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(!r.built);
    for (file, why) in [
        (&bash, "changed since install wrote it"),
        (&exe, "no longer the file install wrote"),
        (&own, "not written by `cargo xtask install`"),
    ] {
        assert!(
            r.out.contains(&format!("kept {}: {why}", file.display())),
            "{file:?} in {}",
            r.out
        );
    }
    assert!(
        bash.is_file()
            && std::fs::symlink_metadata(&exe).unwrap().file_type().is_symlink()
            && own.is_file()
    );
    for (_, f) in &layout::COMPLETIONS[1..] {
        assert!(
            r.out.contains(&format!("removed {}", prefix.join(f).display()))
                && !prefix.join(f).exists(),
            "{f}: {}",
            r.out
        );
    }
    for p in bundled_plugins() {
        assert!(!layout::plugin_dir(&prefix).join(p.file_name().unwrap()).exists());
    }
    // The manifest goes last of the files, named, then the folders that left empty; again,
    // with none, nothing is removed, and it says so.
    let after_manifest = r
        .out
        .split(&format!("removed {}\n", layout::manifest(&prefix).display()))
        .nth(1)
        .unwrap_or_else(|| panic!("the manifest removed in\n{}", r.out));
    assert!(
        after_manifest.lines().all(|l| l.starts_with("removed the empty folder ")),
        "{}",
        r.out
    );
    assert!(!layout::manifest(&prefix).exists());
    let r = task("uninstall", &[Path::new("--prefix"), &prefix], &[]);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(
        r.out.contains(&format!("no {}: nothing removed", layout::manifest(&prefix).display())),
        "{}",
        r.out
    );
    assert!(bash.is_file() && exe.exists() && own.is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn plugins_only_beside_a_cargo_installed_binary_neither_writes_nor_removes_it() {
    // The README's recipe: `cargo install` put the binary in PREFIX/bin; the user wrote their
    // own bash completion.
    let dir = scratch("plugins-only");
    let prefix = dir.join("cargo");
    let exe = layout::binary(&prefix);
    std::fs::create_dir_all(exe.parent().unwrap()).unwrap();
    std::fs::copy(super::common::exe(), &exe).unwrap();
    let bash = prefix.join(layout::COMPLETIONS[0].1);
    std::fs::create_dir_all(bash.parent().unwrap()).unwrap();
    std::fs::write(&bash, "complete -W 'fit diagnose' ballbar\n").unwrap();
    let before = std::fs::metadata(&exe).unwrap().modified().unwrap();

    let r = task(
        "install",
        &[Path::new("--plugins-only"), Path::new("--prefix"), &prefix],
        &bundled_plugins(),
    );
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(!r.out.contains(&format!("installed {}", exe.display())), "{}", r.out);
    assert_eq!(std::fs::metadata(&exe).unwrap().modified().unwrap(), before);
    assert_eq!(std::fs::read_to_string(&bash).unwrap(), "complete -W 'fit diagnose' ballbar\n");
    // The manifest lists the three plugins only; cargo's binary loads them (the check).
    let mut names = listed(&prefix);
    names.sort();
    let mut expected: Vec<String> = bundled_plugins()
        .iter()
        .map(|p| format!("lib/ballbar/plugins/{}", p.file_name().unwrap().to_string_lossy()))
        .collect();
    expected.sort();
    assert_eq!(names, expected);
    assert!(r.out.contains("machine type 'horizontal'"), "{}", r.out);

    let r = task("uninstall", &[Path::new("--prefix"), &prefix], &[]);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    for f in [&exe, &bash] {
        assert!(f.is_file(), "{f:?} removed: {}", r.out);
        assert!(
            r.out.contains(&format!("kept {}: not written by `cargo xtask install`", f.display())),
            "{}",
            r.out
        );
    }
    assert_eq!(std::fs::read_to_string(&bash).unwrap(), "complete -W 'fit diagnose' ballbar\n");
    assert!(!prefix.join("lib/ballbar").exists(), "the emptied lib/ballbar is removed");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn an_option_is_not_taken_as_a_folder() {
    let cases: [(&str, &[&str]); 6] = [
        ("install", &["--prefix", "--force"]),
        ("install", &["--force", "--prefix"]),
        ("install", &["--prefix", ""]),
        ("dist", &["--out", "--force"]),
        ("uninstall", &["--prefix", "--plugins-only"]),
        ("install", &["--prefix", "a", "--prefix", "b"]),
    ];
    for (name, args) in cases {
        let args: Vec<&Path> = args.iter().map(Path::new).collect();
        let r = task(name, &args, &bundled_plugins());
        let Err(f @ layout::Failure::Usage(m)) = &r.result else {
            panic!("{name} {args:?}: {:?}", r.result)
        };
        assert_eq!(f.exit_code(), 2);
        assert!(m.contains(&format!("usage: cargo xtask {name}")), "{m}");
        assert!(!r.built && r.out.is_empty(), "{name} {args:?}: {}", r.out);
    }
    // Nothing was made of the option's name (the tests run in tests/).
    assert!(!Path::new("--force").exists() && !Path::new("--plugins-only").exists());
    let r = task("install", &[Path::new("--prefix"), Path::new("--force")], &[]);
    assert_eq!(
        r.result,
        Err(layout::Failure::Usage(format!(
            "--prefix needs a folder, not '--force'\n{}",
            layout::INSTALL_USAGE
        )))
    );
}

#[test]
fn force_replaces_an_earlier_installs_plugins_and_names_any_other() {
    let dir = scratch("force-stale");
    let out = dir.join("tree");
    let r = task("dist", &[Path::new("--out"), &out], &bundled_plugins());
    assert_eq!(r.result, Ok(()), "{}", r.out);
    let own = layout::plugin_dir(&out).join(plugin_name("ballbar_machine_mine"));
    std::fs::write(&own, "a user's plugin").unwrap();
    // The next build no longer has the horizontal plugin (renamed, or dropped).
    let horizontal = layout::plugin_dir(&out).join(plugin_name("ballbar_machine_horizontal"));
    let fewer: Vec<PathBuf> = bundled_plugins()
        .into_iter()
        .filter(|p| !p.ends_with(plugin_name("ballbar_machine_horizontal")))
        .collect();
    let r = task("dist", &[Path::new("--out"), &out, Path::new("--force")], &fewer);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(
        r.out.contains(&format!("removed {} (an earlier install's plugin", horizontal.display())),
        "{}",
        r.out
    );
    assert!(
        r.out.contains(&format!(
            "warning: {} is in the plugins' folder but not part of this install",
            own.display()
        )),
        "{}",
        r.out
    );
    assert!(!horizontal.exists() && own.is_file());
    assert!(!listed(&out).iter().any(|p| p.contains("horizontal")));
    let o = run_alone(&layout::binary(&out), &["plugins", "--json"]);
    let mut names: Vec<String> = json(&o)["plugins"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap().to_string())
        .collect();
    names.sort();
    assert_eq!(names, ["chain-file", "column"], "{}", text(&o));

    // An earlier plugin the user changed since is theirs: left, and named.
    let column = layout::plugin_dir(&out).join(plugin_name("ballbar_machine_column"));
    std::fs::write(&column, "changed").unwrap();
    let chain: Vec<PathBuf> =
        fewer.into_iter().filter(|p| p.to_string_lossy().contains("chain_file")).collect();
    let r = task("install", &[Path::new("--prefix"), &out, Path::new("--plugins-only")], &chain);
    let Err(layout::Failure::Error(e)) = &r.result else { panic!("{:?}", r.result) };
    assert!(e.contains("already there; --force replaces it"), "{e}");
    let r = task(
        "install",
        &[Path::new("--prefix"), &out, Path::new("--plugins-only"), Path::new("--force")],
        &chain,
    );
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert!(
        r.out.contains(&format!("warning: {} is in the plugins' folder", column.display())),
        "{}",
        r.out
    );
    assert_eq!(std::fs::read_to_string(&column).unwrap(), "changed");
    // The binary and completions of the earlier dist stay listed; the changed plugin not.
    let l = listed(&out);
    assert!(
        l.iter().any(|p| p.starts_with("bin/")) && !l.iter().any(|p| p.contains("column")),
        "{l:?}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_check_fails_when_the_binary_loads_another_copy_of_a_plugin() {
    let dir = scratch("check");
    let out = dir.join("tree");
    let r = task("dist", &[Path::new("--out"), &out], &bundled_plugins());
    assert_eq!(r.result, Ok(()), "{}", r.out);
    let installed: Vec<PathBuf> = bundled_plugins()
        .iter()
        .map(|p| layout::plugin_dir(&out).join(p.file_name().unwrap()))
        .collect();
    assert!(layout::check(&out, &installed).unwrap().contains("machine type 'column'"));
    // A stale column plugin beside the binary is found first (executable folder): the installed
    // one is shadowed, though `ballbar plugins` succeeds.
    std::fs::copy(
        plugin_file("ballbar_machine_column"),
        out.join("bin").join(plugin_name("ballbar_machine_column")),
    )
    .unwrap();
    let e = layout::check(&out, &installed).unwrap_err();
    assert!(
        e.contains(&format!(
            "does not load {}",
            installed.iter().find(|p| p.to_string_lossy().contains("column")).unwrap().display()
        )),
        "{e}"
    );
    let r = task("dist", &[Path::new("--out"), &out, Path::new("--force")], &bundled_plugins());
    let Err(f @ layout::Failure::Error(_)) = &r.result else { panic!("{:?}", r.result) };
    assert_eq!(f.exit_code(), 1);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_manifest_hash_and_a_damaged_manifest() {
    // FNV-1a 64's published test vectors.
    for (text, hash) in [
        ("", 0xcbf2_9ce4_8422_2325_u64),
        ("a", 0xaf63_dc4c_8601_ec8c),
        ("foobar", 0x8594_4171_f739_67e8),
    ] {
        assert_eq!(layout::fnv1a64(layout::FNV_OFFSET, text.as_bytes()), hash, "{text:?}");
    }
    let dir = scratch("manifest");
    let f = dir.join("f");
    std::fs::write(&f, "foobar").unwrap();
    assert_eq!(layout::hash_file(&f).unwrap(), 0x8594_4171_f739_67e8);
    // A line that does not parse, or a path out of the prefix: an error naming the line, and
    // nothing removed.
    let m = layout::manifest(&dir);
    std::fs::create_dir_all(m.parent().unwrap()).unwrap();
    for (body, what) in [
        ("85944171f73967e8  f\n85944171f73967e8 f\n", "no two spaces"),
        ("85944171f73967e8  f\n85944171f73967e8  ../f\n", "not a path under the prefix"),
    ] {
        std::fs::write(&m, body).unwrap();
        let e = layout::uninstall(&dir).unwrap_err();
        assert!(e.starts_with(&format!("{}:2: {what}", m.display())), "{e}");
        assert!(f.is_file() && m.is_file());
    }
    std::fs::write(&m, "# a comment\n85944171f73967e8  f\n").unwrap();
    let u = layout::uninstall(&dir).unwrap();
    assert_eq!(u.removed, vec![dir.join("f")]);
    assert!(!f.exists() && !m.exists());
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
    for word in [
        "fit",
        "diagnose",
        "simulate",
        "predict",
        "import",
        "program",
        "record",
        "replay",
        "export",
        "report",
        "history",
        "plugins",
        "completions",
    ] {
        // The script's dispatch on the subcommand word.
        assert!(bash.contains(&format!("ballbar,{word})")), "subcommand {word} missing");
    }
    for option in
        ["--machine", "--machine-file", "--plugin", "--json", "--record", "--force", "--servo"]
    {
        assert!(bash.contains(option), "option {option} missing");
    }
    for (shell, mark) in [
        ("zsh", "#compdef ballbar"),
        ("fish", "complete -c ballbar"),
        ("powershell", "Register-ArgumentCompleter"),
        ("elvish", "edit:completion:arg-completer[ballbar]"),
    ] {
        let o = run_alone(&exe, &["completions", shell]);
        assert!(o.status.success(), "{shell}: {}", text(&o));
        let script = String::from_utf8_lossy(&o.stdout);
        assert!(
            script.contains(mark) && script.contains("diagnose") && script.contains("--machine"),
            "{shell}: {script}"
        );
    }
    let o = run_alone(&exe, &["completions", "tcsh"]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&dir);
}

/// `git ARGS` in the repository root, when git and a checkout are there.
fn git(args: &[&str]) -> Option<String> {
    let o = Command::new("git")
        .args(args)
        .current_dir(root())
        .env("GIT_OPTIONAL_LOCKS", "0")
        .output()
        .ok()?;
    o.status.success().then(|| String::from_utf8_lossy(&o.stdout).trim().to_string())
}

#[test]
fn version_names_the_commit_it_was_built_from() {
    let o = ballbar(&["--version"]);
    assert!(o.status.success(), "{}", text(&o));
    let line = String::from_utf8(o.stdout).unwrap();
    let prefix = format!("ballbar {} (commit ", env!("CARGO_PKG_VERSION"));
    let commit = line
        .trim()
        .strip_prefix(&prefix)
        .and_then(|r| r.strip_suffix(')'))
        .unwrap_or_else(|| panic!("not '{prefix}…)': {line}"));
    assert_eq!(text(&ballbar(&["-V"])), line);
    // A packager's commit is taken as given.
    if let Some(given) = std::env::var("BALLBAR_BUILD_COMMIT").ok().filter(|g| !g.trim().is_empty())
    {
        assert_eq!(commit, given.trim(), "{line}");
        return;
    }
    // A checkout of this repository (CI's is a fresh clone): a commit of it, short hash, with
    // `-dirty` exactly when the binary's sources differ from it (the build script's own
    // definition). A commit made between the build and this test moves HEAD: the binary's
    // commit is then an ancestor of HEAD, not HEAD, so that is what is checked.
    let checkout = git(&["rev-parse", "--show-toplevel"])
        .is_some_and(|top| Path::new(&top).canonicalize().ok() == root().canonicalize().ok());
    match (checkout, git(&["rev-parse", "--short", "HEAD"])) {
        (true, Some(head)) => {
            let hash = commit.strip_suffix("-dirty").unwrap_or(commit);
            assert!(hash.len() >= 7 && hash.chars().all(|c| c.is_ascii_hexdigit()), "{line}");
            assert!(
                git(&["merge-base", "--is-ancestor", hash, "HEAD"]).is_some(),
                "{hash} is not a commit of this checkout's history: {line}"
            );
            if hash == head {
                let dirty = !git(&[
                    "status",
                    "--porcelain",
                    "--",
                    "crates",
                    "plugins",
                    "Cargo.toml",
                    "Cargo.lock",
                ])
                .unwrap()
                .is_empty();
                assert_eq!(commit.ends_with("-dirty"), dirty, "{line}");
            }
        }
        _ => assert_eq!(commit, "unknown commit", "{line}"),
    }
}

#[cfg(unix)]
#[test]
fn a_reinstall_that_fails_midway_keeps_listing_the_earlier_files_it_did_not_reach() {
    use std::os::unix::fs::PermissionsExt as _;
    let dir = scratch("install-fails-midway");
    let prefix = dir.join("prefix");
    let r = task("install", &[Path::new("--prefix"), &prefix], &bundled_plugins());
    assert_eq!(r.result, Ok(()), "{}", r.out);
    let before = listed(&prefix);
    // A build whose binary cannot write its completions: the copies succeed, then it stops.
    let broken = dir.join("broken-ballbar");
    std::fs::write(&broken, "#!/bin/sh\nexit 1\n").unwrap();
    std::fs::set_permissions(&broken, std::fs::Permissions::from_mode(0o755)).unwrap();
    let r = task_built(
        "install",
        &[Path::new("--prefix"), &prefix, Path::new("--force")],
        broken,
        &bundled_plugins(),
    );
    assert!(r.result.is_err(), "{}", r.out);
    // The completions the first install wrote are still there, unchanged: still listed, so
    // uninstall removes them (it keeps what is not listed).
    let after = listed(&prefix);
    for (_, f) in &layout::COMPLETIONS {
        assert!(prefix.join(f).is_file());
        assert!(
            before.contains(&f.to_string()) && after.contains(&f.to_string()),
            "{f} dropped: {after:?}"
        );
    }
    let r = task("uninstall", &[Path::new("--prefix"), &prefix], &[]);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    for (_, f) in &layout::COMPLETIONS {
        assert!(!prefix.join(f).exists(), "{f} left behind: {}", r.out);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Uninstall removes the folders the install created once they are empty, deepest first, and
/// only those: a folder that was there before (an empty `bin/`, a `share/` with a file of the
/// user's) stays, and so does one that still holds a file uninstall keeps.
#[test]
fn uninstall_removes_the_folders_install_created_when_they_are_empty() {
    let dir = scratch("uninstall-folders");
    let prefix = dir.join("prefix");
    std::fs::create_dir_all(prefix.join("bin")).unwrap();
    std::fs::create_dir_all(prefix.join("share")).unwrap();
    std::fs::write(prefix.join("share/mine.txt"), "the user's").unwrap();
    let r = task("install", &[Path::new("--prefix"), &prefix], &bundled_plugins());
    assert_eq!(r.result, Ok(()), "{}", r.out);
    // The created folders, in the manifest; not those that were there.
    let folders = layout::read_manifest_folders(&prefix).unwrap();
    let mut expected = vec![
        "lib",
        "lib/ballbar",
        "lib/ballbar/plugins",
        "share/bash-completion",
        "share/bash-completion/completions",
        "share/zsh",
        "share/zsh/site-functions",
        "share/fish",
        "share/fish/vendor_completions.d",
    ];
    let mut got: Vec<&str> = folders.iter().map(String::as_str).collect();
    got.sort();
    expected.sort();
    assert_eq!(got, expected);
    // A reinstall creates nothing and keeps the list.
    let r = task(
        "install",
        &[Path::new("--prefix"), &prefix, Path::new("--force")],
        &bundled_plugins(),
    );
    assert_eq!(r.result, Ok(()), "{}", r.out);
    assert_eq!(layout::read_manifest_folders(&prefix).unwrap(), folders);
    // The user's own fish completion keeps its folder (and `share/fish`).
    let fish_dir = prefix.join("share/fish/vendor_completions.d");
    std::fs::write(fish_dir.join("other.fish"), "# another tool's").unwrap();

    let r = task("uninstall", &[Path::new("--prefix"), &prefix], &[]);
    assert_eq!(r.result, Ok(()), "{}", r.out);
    for f in expected.iter().filter(|f| !f.starts_with("share/fish")) {
        let path = prefix.join(f);
        assert!(!path.exists(), "{f} is left: {}", r.out);
        assert!(
            r.out.contains(&format!("removed the empty folder {}", path.display())),
            "{}",
            r.out
        );
    }
    assert!(fish_dir.join("other.fish").is_file() && prefix.join("share/fish").is_dir());
    assert!(prefix.join("bin").is_dir() && prefix.join("share/mine.txt").is_file());
    let mut left: Vec<String> = walk(&prefix);
    left.sort();
    assert_eq!(
        left,
        [
            "bin",
            "share",
            "share/fish",
            "share/fish/vendor_completions.d",
            "share/fish/vendor_completions.d/other.fish",
            "share/mine.txt"
        ]
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every path under `dir`, relative, `/`-separated.
fn walk(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let rel = p.strip_prefix(dir).unwrap();
            out.push(
                rel.components()
                    .map(|c| c.as_os_str().to_string_lossy())
                    .collect::<Vec<_>>()
                    .join("/"),
            );
            if p.is_dir() {
                stack.push(p);
            }
        }
    }
    out
}

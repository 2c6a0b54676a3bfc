//! `cargo xtask dist`, `install` and `uninstall`: a release build of `ballbar` and the
//! workspace's machine plugins, laid out as [`crate::layout`] says, so that the binary finds
//! its plugins without `BALLBAR_PLUGIN_PATH` wherever the tree is put.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{anyhow, bail, ensure, Context, Result};

use crate::layout;

const DIST_USAGE: &str = "usage: cargo xtask dist [--out DIR] [--force]";
const INSTALL_USAGE: &str = "usage: cargo xtask install [--prefix DIR] [--plugins-only] [--force]";
const UNINSTALL_USAGE: &str = "usage: cargo xtask uninstall [--prefix DIR]";

/// The workspace's machine plugins: (package name, library file name), from `plugins/*/Cargo.toml`.
fn plugin_packages() -> Result<Vec<(String, String)>> {
    let dir = crate::root().join("plugins");
    let mut found = Vec::new();
    for entry in std::fs::read_dir(&dir).with_context(|| format!("{}", dir.display()))? {
        let manifest = entry?.path().join("Cargo.toml");
        let Ok(text) = std::fs::read_to_string(&manifest) else { continue };
        // The package's name: the first `name = "..."` line (the `[package]` table comes first).
        let name = text
            .lines()
            .find_map(|l| l.trim().strip_prefix("name").map(str::trim).and_then(|r| r.strip_prefix('=')).map(|r| r.trim().trim_matches('"').to_string()))
            .with_context(|| format!("{}: no package name", manifest.display()))?;
        let file = format!("{}{}{}", std::env::consts::DLL_PREFIX, name.replace('-', "_"), std::env::consts::DLL_SUFFIX);
        found.push((name, file));
    }
    found.sort();
    ensure!(!found.is_empty(), "{}: no plugin crates", dir.display());
    Ok(found)
}

/// The target folder this xtask was built in (`target/release/xtask` → `target`): the release
/// build goes there too, sharing what is already built.
fn target_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe()?;
    exe.parent().and_then(Path::parent).map(Path::to_path_buf).context("the target folder of the xtask executable")
}

/// `cargo build --release` of the CLI and the plugins: the binary and the plugin files.
fn build() -> Result<(PathBuf, Vec<PathBuf>)> {
    let plugins = plugin_packages()?;
    let target = target_dir()?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "--release", "-p", "ballbar-cli"]).arg("--target-dir").arg(&target).current_dir(crate::root());
    for (p, _) in &plugins {
        cmd.args(["-p", p]);
    }
    let status = cmd.status().context("running cargo build")?;
    ensure!(status.success(), "cargo build --release failed");
    let release = target.join("release");
    let binary = release.join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
    let files: Vec<PathBuf> = plugins.iter().map(|(_, f)| release.join(f)).collect();
    Ok((binary, files))
}

/// The installed binary, run without `BALLBAR_PLUGIN_PATH`, must find every plugin: its
/// `plugins` listing, printed.
fn check(prefix: &Path) -> Result<()> {
    let exe = layout::binary(prefix);
    let out = Command::new(&exe).arg("plugins").env_remove("BALLBAR_PLUGIN_PATH").output().with_context(|| format!("{}: cannot run it", exe.display()))?;
    print!("{}", String::from_utf8_lossy(&out.stdout));
    ensure!(out.status.success(), "{} plugins failed: {}", exe.display(), String::from_utf8_lossy(&out.stderr));
    Ok(())
}

/// `--NAME VALUE` and flag options of a task; anything else is a usage error.
fn options<'a>(args: &'a [String], valued: &str, flags: &[&str], usage: &str) -> Result<(Option<&'a str>, Vec<&'a str>)> {
    let (mut value, mut set) = (None, Vec::new());
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            v if v == valued => value = Some(it.next().ok_or_else(|| anyhow!("{valued} needs a value; {usage}"))?.as_str()),
            f if flags.contains(&f) => set.push(f),
            other => bail!("unexpected argument {other}; {usage}"),
        }
    }
    Ok((value, set))
}

/// `~/.local`, the default prefix.
fn home_local() -> Result<PathBuf> {
    let home = std::env::var_os("HOME").or_else(|| std::env::var_os("USERPROFILE")).filter(|h| !h.is_empty()).context("no HOME: give --prefix DIR")?;
    Ok(PathBuf::from(home).join(".local"))
}

/// `cargo xtask dist [--out DIR] [--force]`: a relocatable tree, by default
/// `target/dist/ballbar-VERSION-OS-ARCH`.
pub fn dist(args: &[String]) -> Result<()> {
    let (out, flags) = options(args, "--out", &["--force"], DIST_USAGE)?;
    let out = match out {
        Some(o) => PathBuf::from(o),
        None => target_dir()?.join("dist").join(format!("ballbar-{}-{}-{}", env!("CARGO_PKG_VERSION"), std::env::consts::OS, std::env::consts::ARCH)),
    };
    let force = flags.contains(&"--force");
    // Before the build: an existing tree is refused in a second, not after minutes.
    layout::may_replace(&layout::binary(&out), force).map_err(|e| anyhow!(e))?;
    let (binary, plugins) = build()?;
    let written = layout::install(&layout::Install { prefix: &out, binary: Some(&binary), plugins: &plugins, force }).map_err(|e| anyhow!(e))?;
    check(&out)?;
    println!("wrote {} files to {}; the tree can be moved as a whole (bin/ finds ../{})", written.len(), out.display(), layout::PLUGIN_DIR);
    Ok(())
}

/// `cargo xtask install [--prefix DIR] [--plugins-only] [--force]`: the same tree in a prefix,
/// `~/.local` by default.
pub fn install(args: &[String]) -> Result<()> {
    let (prefix, flags) = options(args, "--prefix", &["--force", "--plugins-only"], INSTALL_USAGE)?;
    let prefix = match prefix {
        Some(p) => PathBuf::from(p),
        None => home_local()?,
    };
    let (plugins_only, force) = (flags.contains(&"--plugins-only"), flags.contains(&"--force"));
    if !plugins_only {
        // Before the build: an existing installation is refused in a second, not after minutes.
        layout::may_replace(&layout::binary(&prefix), force).map_err(|e| anyhow!(e))?;
    }
    let (binary, plugins) = build()?;
    let binary = (!plugins_only).then_some(binary.as_path());
    let written = layout::install(&layout::Install { prefix: &prefix, binary, plugins: &plugins, force }).map_err(|e| anyhow!(e))?;
    for f in &written {
        println!("installed {}", f.display());
    }
    if layout::binary(&prefix).is_file() {
        check(&prefix)?;
    } else {
        println!("no {} yet: the plugins are found by a ballbar installed there", layout::binary(&prefix).display());
    }
    let bin = prefix.join("bin");
    let on_path = std::env::var_os("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d == bin));
    if !on_path {
        println!("note: {} is not on PATH; add it to run `ballbar` by name", bin.display());
    }
    Ok(())
}

/// `cargo xtask uninstall [--prefix DIR]`: removes what `install` put there.
pub fn uninstall(args: &[String]) -> Result<()> {
    let (prefix, _) = options(args, "--prefix", &[], UNINSTALL_USAGE)?;
    let prefix = match prefix {
        Some(p) => PathBuf::from(p),
        None => home_local()?,
    };
    let names: Vec<String> = plugin_packages()?.into_iter().map(|(_, f)| f).collect();
    let (removed, left) = layout::uninstall(&prefix, &names).map_err(|e| anyhow!(e))?;
    for f in &removed {
        println!("removed {}", f.display());
    }
    if removed.is_empty() {
        println!("nothing of ballbar's under {}", prefix.display());
    }
    for f in &left {
        println!("left {} (not one of the bundled plugins)", f.display());
    }
    Ok(())
}

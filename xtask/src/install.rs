//! `cargo xtask dist`, `install` and `uninstall`: the release build of `ballbar` and the
//! workspace's machine plugins, handed to the tasks in [`xtask::layout`] (which lay them out so
//! that the binary finds its plugins without `BALLBAR_PLUGIN_PATH` wherever the tree is put).

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};

use anyhow::{Context, Result, ensure};

use xtask::layout;

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
            .find_map(|l| {
                l.trim()
                    .strip_prefix("name")
                    .map(str::trim)
                    .and_then(|r| r.strip_prefix('='))
                    .map(|r| r.trim().trim_matches('"').to_string())
            })
            .with_context(|| format!("{}: no package name", manifest.display()))?;
        let file = format!(
            "{}{}{}",
            std::env::consts::DLL_PREFIX,
            name.replace('-', "_"),
            std::env::consts::DLL_SUFFIX
        );
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
    exe.parent()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .context("the target folder of the xtask executable")
}

/// `cargo build --release` of the CLI and the plugins: the binary and the plugin files.
fn build() -> Result<layout::Built> {
    let plugins = plugin_packages()?;
    let target = target_dir()?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(["build", "--release", "-p", "ballbar-cli"])
        .arg("--target-dir")
        .arg(&target)
        .current_dir(crate::root());
    for (p, _) in &plugins {
        cmd.args(["-p", p]);
    }
    let status = cmd.status().context("running cargo build")?;
    ensure!(status.success(), "cargo build --release failed");
    let release = target.join("release");
    let binary = release.join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
    Ok(layout::Built { binary, plugins: plugins.iter().map(|(_, f)| release.join(f)).collect() })
}

/// Run `task` (`dist`, `install` or `uninstall`) with its arguments: exit 2 on a usage error,
/// 1 on another.
pub fn main(task: &str, args: &[String]) -> ExitCode {
    let mut build = || build().map_err(|e| format!("{e:#}"));
    let dist_dir = target_dir().ok().map(|t| {
        t.join("dist").join(format!(
            "ballbar-{}-{}-{}",
            env!("CARGO_PKG_VERSION"),
            std::env::consts::OS,
            std::env::consts::ARCH
        ))
    });
    let home = std::env::var_os("HOME")
        .or_else(|| std::env::var_os("USERPROFILE"))
        .filter(|h| !h.is_empty())
        .map(PathBuf::from);
    let mut host =
        layout::Host { home, dist_dir, path: std::env::var_os("PATH"), build: &mut build };
    match layout::run(task, args, &mut host, &mut std::io::stdout()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(f) => {
            match &f {
                layout::Failure::Usage(m) => eprintln!("{m}"),
                layout::Failure::Error(m) => eprintln!("error: {m}"),
            }
            ExitCode::from(f.exit_code())
        }
    }
}

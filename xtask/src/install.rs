//! `cargo xtask dist`, `install` and `uninstall`: the dist build (`[profile.dist]`, the release
//! build stripped of debug info) of `ballbar` and the
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

/// The target folder this xtask was built in (`target/debug/xtask` → `target`): the dist
/// build goes there too.
fn target_dir() -> Result<PathBuf> {
    let exe = std::env::current_exe()?;
    exe.parent()
        .and_then(Path::parent)
        .map(Path::to_path_buf)
        .context("the target folder of the xtask executable")
}

/// The cargo profile of what is installed and distributed (the workspace's `[profile.dist]`:
/// the release build, stripped, without debug info); cargo builds it into `target/dist`.
const PROFILE: &str = "dist";

/// The arguments of `cargo build` of the CLI and the plugin packages in [`PROFILE`].
fn build_args(plugins: &[(String, String)]) -> Vec<String> {
    let mut args: Vec<String> =
        ["build", "--profile", PROFILE, "-p", "ballbar-cli"].map(String::from).to_vec();
    for (p, _) in plugins {
        args.extend(["-p".to_string(), p.clone()]);
    }
    args
}

/// `cargo build --profile dist` of the CLI and the plugins: the binary and the plugin files.
fn build() -> Result<layout::Built> {
    let plugins = plugin_packages()?;
    let target = target_dir()?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.args(build_args(&plugins)).arg("--target-dir").arg(&target).current_dir(crate::root());
    let status = cmd.status().context("running cargo build")?;
    ensure!(status.success(), "cargo build --profile {PROFILE} failed");
    let built = target.join(PROFILE);
    let binary = built.join(format!("ballbar{}", std::env::consts::EXE_SUFFIX));
    Ok(layout::Built { binary, plugins: plugins.iter().map(|(_, f)| built.join(f)).collect() })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The workspace manifest's `[profile.dist]` table: its `key = value` lines.
    fn dist_profile() -> Vec<(String, String)> {
        let text = std::fs::read_to_string(crate::root().join("Cargo.toml")).unwrap();
        let mut lines = text.lines().skip_while(|l| l.trim() != "[profile.dist]").skip(1);
        let mut keys = Vec::new();
        for l in lines.by_ref() {
            let l = l.trim();
            if l.starts_with('[') {
                break;
            }
            if let Some((k, v)) = l.split_once('=') {
                keys.push((k.trim().to_string(), v.trim().to_string()));
            }
        }
        keys
    }

    #[test]
    fn install_and_dist_build_the_stripped_release_profile() {
        let profile = dist_profile();
        for (key, value) in [("inherits", "\"release\""), ("strip", "true"), ("debug", "false")] {
            assert!(
                profile.iter().any(|(k, v)| k == key && v == value),
                "[profile.dist] {key} = {value} in {profile:?}"
            );
        }
        let plugins = plugin_packages().unwrap();
        let args = build_args(&plugins);
        assert_eq!(args[..5], ["build", "--profile", "dist", "-p", "ballbar-cli"]);
        // Every plugin package of the workspace, the bundled three among them.
        for name in
            ["ballbar-machine-column", "ballbar-machine-horizontal", "ballbar-machine-chain-file"]
        {
            assert!(args.windows(2).any(|w| w == ["-p", name]), "{name} in {args:?}");
        }
    }
}

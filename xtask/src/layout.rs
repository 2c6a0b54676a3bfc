//! The installed layout of ballbar and the copying into it, shared by `cargo xtask dist`,
//! `install` and `uninstall`. Standard library only: the end-to-end tests include this file
//! (`#[path]`) and lay out with it the tree whose binary they run.
//!
//! ```text
//! PREFIX/bin/ballbar                                  the binary
//! PREFIX/lib/ballbar/plugins/libballbar_machine_*.so  the machine plugins, which the binary
//!                                                     finds as ../lib/ballbar/plugins
//! PREFIX/share/bash-completion/completions/ballbar    completion scripts, where bash-completion,
//! PREFIX/share/zsh/site-functions/_ballbar            zsh and fish look under ~/.local and
//! PREFIX/share/fish/vendor_completions.d/ballbar.fish /usr/local
//! ```

use std::path::{Path, PathBuf};
use std::process::Command;

/// The plugins' folder under the prefix: the binary's own search looks there
/// (`ballbar_plugin_host::INSTALLED_PLUGIN_DIR`, the same text; the e2e test runs a binary
/// in a tree laid out with this one).
pub const PLUGIN_DIR: &str = "lib/ballbar/plugins";

/// The completion scripts written: the shell, and the file under the prefix.
pub const COMPLETIONS: [(&str, &str); 3] = [
    ("bash", "share/bash-completion/completions/ballbar"),
    ("zsh", "share/zsh/site-functions/_ballbar"),
    ("fish", "share/fish/vendor_completions.d/ballbar.fish"),
];

/// The binary's path under `prefix`.
pub fn binary(prefix: &Path) -> PathBuf {
    prefix.join("bin").join(format!("ballbar{}", std::env::consts::EXE_SUFFIX))
}

/// The plugins' folder under `prefix`.
pub fn plugin_dir(prefix: &Path) -> PathBuf {
    prefix.join(PLUGIN_DIR)
}

/// What to put where.
#[derive(Clone, Debug)]
pub struct Install<'a> {
    /// The folder that receives `bin/`, `lib/` and `share/`.
    pub prefix: &'a Path,
    /// The built binary; `None` installs the plugins alone (beside a binary that `cargo install`
    /// put in `prefix/bin`).
    pub binary: Option<&'a Path>,
    /// The built plugin libraries (their file names are kept).
    pub plugins: &'a [PathBuf],
    /// Replace files that are already there.
    pub force: bool,
}

/// Copy the binary and the plugins into their places, then write the completion scripts by
/// running the installed binary (`ballbar completions SHELL`, which also shows that it runs).
/// Every file that would be replaced is checked first: without `force` an existing one is an
/// error naming it, and nothing is written. Each file is written beside its place and renamed
/// over it, so a running `ballbar` is never half-replaced. Returns the files written.
pub fn install(i: &Install<'_>) -> Result<Vec<PathBuf>, String> {
    let mut copies: Vec<(PathBuf, PathBuf)> = Vec::new();
    if let Some(b) = i.binary {
        copies.push((b.to_path_buf(), binary(i.prefix)));
    }
    for p in i.plugins {
        let name = p.file_name().ok_or_else(|| format!("{}: not a file name", p.display()))?;
        copies.push((p.clone(), plugin_dir(i.prefix).join(name)));
    }
    let scripts: Vec<(&str, PathBuf)> = if i.binary.is_some() { COMPLETIONS.iter().map(|(shell, f)| (*shell, i.prefix.join(f))).collect() } else { Vec::new() };
    for (from, _) in &copies {
        if !from.is_file() {
            return Err(format!("{}: not found (was it built?)", from.display()));
        }
    }
    for target in copies.iter().map(|(_, t)| t).chain(scripts.iter().map(|(_, t)| t)) {
        may_replace(target, i.force)?;
    }
    let mut written = Vec::new();
    for (from, to) in &copies {
        // `fs::copy` keeps the permissions: the executable bit of the binary and the libraries.
        replace(to, |tmp| std::fs::copy(from, tmp).map(|_| ()))?;
        written.push(to.clone());
    }
    if i.binary.is_some() {
        let exe = binary(i.prefix);
        for (shell, to) in &scripts {
            let mut cmd = Command::new(&exe);
            cmd.args(["completions", shell]).env_remove("BALLBAR_PLUGIN_PATH");
            let out = output(&mut cmd).map_err(|e| format!("{}: cannot run it: {e}", exe.display()))?;
            if !out.status.success() || out.stdout.is_empty() {
                return Err(format!("{} completions {shell} failed: {}", exe.display(), String::from_utf8_lossy(&out.stderr)));
            }
            replace(to, |tmp| std::fs::write(tmp, &out.stdout))?;
            written.push(to.clone());
        }
    }
    Ok(written)
}

/// Run `cmd` for its output. A binary just written may be busy for a moment in a process that
/// forks on other threads (a child holds the written file's descriptor until its own exec):
/// `ExecutableFileBusy` is retried, a bounded number of times.
pub fn output(cmd: &mut Command) -> std::io::Result<std::process::Output> {
    let mut tries = 0;
    loop {
        match cmd.output() {
            Err(e) if e.kind() == std::io::ErrorKind::ExecutableFileBusy && tries < 100 => {
                tries += 1;
                std::thread::sleep(std::time::Duration::from_millis(10));
            }
            other => return other,
        }
    }
}

/// Remove what [`install`] puts under `prefix`: the binary, the plugin files of these names,
/// the completion scripts; then the plugins' folder and `lib/ballbar` if that left them
/// empty. Other files (a plugin of your own) stay. Returns (removed, left in the plugins'
/// folder).
pub fn uninstall(prefix: &Path, plugin_file_names: &[String]) -> Result<(Vec<PathBuf>, Vec<PathBuf>), String> {
    let mut targets = vec![binary(prefix)];
    targets.extend(plugin_file_names.iter().map(|n| plugin_dir(prefix).join(n)));
    targets.extend(COMPLETIONS.iter().map(|(_, f)| prefix.join(f)));
    let mut removed = Vec::new();
    for t in targets {
        match std::fs::symlink_metadata(&t) {
            Ok(m) if m.is_dir() => return Err(format!("{}: a folder, not ballbar's file: left as it is", t.display())),
            Ok(_) => {
                std::fs::remove_file(&t).map_err(|e| format!("{}: cannot remove it: {e}", t.display()))?;
                removed.push(t);
            }
            Err(_) => {}
        }
    }
    let dir = plugin_dir(prefix);
    let left: Vec<PathBuf> = std::fs::read_dir(&dir).map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect()).unwrap_or_default();
    if left.is_empty() {
        // Only empty folders: `remove_dir` refuses any other.
        let _ = std::fs::remove_dir(&dir);
        let _ = std::fs::remove_dir(prefix.join("lib/ballbar"));
    }
    Ok((removed, left))
}

/// Without `force`, an existing `target` is an error; never a folder.
pub fn may_replace(target: &Path, force: bool) -> Result<(), String> {
    match std::fs::symlink_metadata(target) {
        Err(_) => Ok(()),
        Ok(m) if m.is_dir() => Err(format!("{}: a folder is in the way", target.display())),
        Ok(_) if force => Ok(()),
        Ok(_) => Err(format!("{}: already there; --force replaces it", target.display())),
    }
}

/// Write a temporary file beside `target` with `write` and rename it over `target`.
fn replace(target: &Path, write: impl FnOnce(&Path) -> std::io::Result<()>) -> Result<(), String> {
    let dir = target.parent().ok_or_else(|| format!("{}: no folder", target.display()))?;
    std::fs::create_dir_all(dir).map_err(|e| format!("{}: cannot create the folder: {e}", dir.display()))?;
    let name = target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = write(&tmp).and_then(|()| std::fs::rename(&tmp, target));
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: cannot write it: {e}", target.display())
    })
}

//! The commit `ballbar --version` names: sets `BALLBAR_COMMIT` to the short hash of the git
//! commit the binary was built from, with `-dirty` when the binary's sources (`crates/`,
//! `plugins/`, `Cargo.toml`, `Cargo.lock`) differ from it, or to `unknown commit` outside a git
//! checkout (a source tarball) or without git. A packager may set `BALLBAR_BUILD_COMMIT` to
//! give it instead.
//!
//! The script reruns when HEAD moves (`.git/HEAD`, the branch's ref, `packed-refs`, HEAD's
//! reflog, the branch refs' folder) or a source
//! of the binary changes; never on the index, which git rewrites at every status and would
//! rebuild the CLI at every build.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The sources of the binary, relative to the workspace root: what decides `-dirty`, and
/// what is watched for it.
const SOURCES: [&str; 4] = ["crates", "plugins", "Cargo.toml", "Cargo.lock"];

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=BALLBAR_BUILD_COMMIT");
    let commit = match std::env::var("BALLBAR_BUILD_COMMIT") {
        Ok(given) if !given.trim().is_empty() => given.trim().to_string(),
        _ => from_git().unwrap_or_else(|| "unknown commit".to_string()),
    };
    println!("cargo:rustc-env=BALLBAR_COMMIT={commit}");
}

/// The workspace root (this crate is `crates/ballbar-cli`).
fn root() -> PathBuf {
    let manifest = PathBuf::from(
        std::env::var_os("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR"),
    );
    manifest.parent().and_then(Path::parent).map(Path::to_path_buf).unwrap_or(manifest)
}

/// `git ARGS` in the workspace root: its standard output, trimmed, when it succeeds. No
/// optional locks: a status run by a build must never hold the index lock against the user's
/// own `git add` or `git commit`.
fn git(args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .arg("--no-optional-locks")
        .args(args)
        .current_dir(root())
        .env("GIT_OPTIONAL_LOCKS", "0")
        .output()
        .ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

/// `rerun-if-changed` for `path` if it exists (a missing path would rerun the script at every
/// build).
fn watch(path: &Path) {
    if path.exists() {
        println!("cargo:rerun-if-changed={}", path.display());
    }
}

fn from_git() -> Option<String> {
    let root = root();
    // Only a checkout of this workspace: a source tarball unpacked inside some other
    // repository must not take that repository's commit.
    let top = PathBuf::from(git(&["rev-parse", "--show-toplevel"])?);
    if top.canonicalize().ok()? != root.canonicalize().ok()? {
        return None;
    }
    let hash = git(&["rev-parse", "--short", "HEAD"])?;
    // HEAD, the ref it names, the packed refs, HEAD's reflog and the folder of branch refs: a
    // commit, a checkout or a pull moves one of them. The reflog and the folder also catch a
    // commit on a branch whose ref was packed (after `git gc`: the commit writes a loose ref
    // that was not there to watch), and `reftable` the newer ref format (`--git-path` resolves
    // them in a linked work tree too).
    let mut refs = vec![
        "HEAD".to_string(),
        "packed-refs".to_string(),
        "logs/HEAD".to_string(),
        "refs/heads".to_string(),
        "reftable".to_string(),
    ];
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        refs.push(branch);
    }
    for r in &refs {
        if let Some(p) = git(&["rev-parse", "--git-path", r]) {
            watch(&root.join(p));
        }
    }
    for s in SOURCES {
        watch(&root.join(s));
    }
    let mut status = vec!["status", "--porcelain", "--"];
    status.extend(SOURCES);
    let dirty = !git(&status)?.is_empty();
    Some(if dirty { format!("{hash}-dirty") } else { hash })
}

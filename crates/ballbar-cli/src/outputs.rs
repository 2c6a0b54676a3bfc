//! The one rule for every file a command writes (`--json FILE`, `--save-model FILE`,
//! `--record FILE`, `replay --json`, `plugins --json`, and the files written into an `--out`
//! folder): never one of the command's inputs, not even with `--force`; never an existing file
//! without `--force`; never two of the command's outputs on one file.
//!
//! [`check`] applies it to all of a command's outputs together, before any work and before the
//! first file is written. The writes ([`write`], [`write_all`], and the archive's) apply it
//! again, atomically, as each file takes its name: without `--force` a file takes its name only
//! if the name is still free at that instant (`ballbar_io::atomic::Existing::Keep`), so a file
//! another program wrote there while the command ran is kept. `-` (standard output) and targets
//! that are not regular files (a terminal, a pipe, `/dev/null`) are written as they are: they
//! hold nothing to keep.

use std::path::{Path, PathBuf};

use anyhow::anyhow;
use ballbar_io::atomic::{Existing, folder_of, follow_links, stale_temporaries};
use ballbar_plugin_host::Registry;

use crate::{Failure, Result};

/// A file a command will write, and the option that named it (`--json`, `--out`), for
/// messages.
#[derive(Clone, Debug)]
pub struct Output {
    /// The file as the user named it (or `--out DIR` joined with its name).
    pub path: PathBuf,
    /// The option that named it.
    pub option: &'static str,
}

impl Output {
    /// `path`, named by `option`.
    pub fn new(path: impl Into<PathBuf>, option: &'static str) -> Output {
        Output { path: path.into(), option }
    }
}

/// The outputs of `options` that are files (`-`, standard output, left out).
pub fn files<'a>(
    options: impl IntoIterator<Item = (Option<&'a Path>, &'static str)>,
) -> Vec<Output> {
    options
        .into_iter()
        .filter_map(|(p, option)| {
            p.filter(|p| p.as_os_str() != "-").map(|p| Output::new(p, option))
        })
        .collect()
}

/// The files every command reads besides its own inputs: the plugins it found (their code runs
/// in it) and its own executable.
pub fn loaded(reg: &Registry) -> Vec<PathBuf> {
    reg.plugins
        .iter()
        .map(|p| p.path().to_path_buf())
        .chain(reg.shadowed.iter().map(|(f, _)| f.clone()))
        .chain(std::env::current_exe().ok())
        .collect()
}

/// Where a write to `t` would land: an existing target (a link included: the writes follow
/// links) resolved itself, a new one through its folder (which may not exist yet: then it
/// holds no input, and no other output).
fn resolved(t: &Path) -> Option<PathBuf> {
    if let Ok(c) = std::fs::canonicalize(t) {
        return Some(c);
    }
    let target = follow_links(t).ok()?;
    Some(std::fs::canonicalize(folder_of(&target)).ok()?.join(target.file_name()?))
}

/// Refuse, before anything is written, `outputs` that would replace an input (never, not even
/// with `force`), an existing file (unless `force`), a folder, or one another. The message
/// names the first such output and, for existing files, how many more of the `what` (say
/// "runs") there are. Names, as warnings, the leftovers of stopped writers in the outputs'
/// folders.
pub fn check(outputs: &[Output], input_files: &[PathBuf], force: bool, what: &str) -> Result<()> {
    let inputs: Vec<PathBuf> =
        input_files.iter().filter_map(|f| std::fs::canonicalize(f).ok()).collect();
    let places: Vec<Option<PathBuf>> = outputs.iter().map(|o| resolved(&o.path)).collect();
    for (o, place) in outputs.iter().zip(&places) {
        if place.as_ref().is_some_and(|r| inputs.contains(r)) {
            return Err(Failure::Input(anyhow!(
                "{}: is one of the inputs; nothing was written (choose another {})",
                o.path.display(),
                o.option
            )));
        }
        if std::fs::metadata(&o.path).is_ok_and(|m| m.is_dir()) {
            return Err(Failure::Input(anyhow!(
                "{}: is a folder; nothing was written ({} names a file)",
                o.path.display(),
                o.option
            )));
        }
    }
    for (k, (o, place)) in outputs.iter().zip(&places).enumerate() {
        let Some(place) = place else { continue };
        if let Some(first) = places[..k].iter().position(|p| p.as_ref() == Some(place)) {
            let other = &outputs[first];
            let by = if other.option == o.option {
                format!("{} twice", o.option)
            } else {
                format!("both {} and {}", other.option, o.option)
            };
            return Err(Failure::Input(anyhow!(
                "{}: is named by {by}; nothing was written (one would replace the other)",
                o.path.display()
            )));
        }
    }
    warn_of_leftovers(outputs);
    if force {
        return Ok(());
    }
    // A special file (a terminal, a pipe, /dev/null) is written as it is and holds nothing to
    // keep; a link whose target does not exist is a file the user has.
    let existing: Vec<&Output> = outputs
        .iter()
        .filter(|o| match std::fs::metadata(&o.path) {
            Ok(m) => m.is_file(),
            Err(_) => std::fs::symlink_metadata(&o.path).is_ok(),
        })
        .collect();
    if let Some(first) = existing.first() {
        let more = match existing.len() {
            1 => String::new(),
            n => format!(" (and {} more of the {} {what})", n - 1, outputs.len()),
        };
        let replaces = if existing.len() == 1 { "replaces it" } else { "replaces them" };
        return Err(Failure::Input(anyhow!(
            "{}: already exists{more}; nothing was written (--force {replaces})",
            first.path.display()
        )));
    }
    Ok(())
}

/// Warn of the temporary files that writers which no longer run left in the folders of
/// `outputs`: they are not results, and nothing else would ever say they are there. They are
/// named, not removed ([`stale_temporaries`] says why).
fn warn_of_leftovers(outputs: &[Output]) {
    let mut folders: Vec<PathBuf> = Vec::new();
    for o in outputs {
        let target = follow_links(&o.path).unwrap_or_else(|_| o.path.clone());
        let folder = folder_of(&target);
        if !folders.contains(&folder) {
            folders.push(folder);
        }
    }
    for folder in folders {
        for left in stale_temporaries(&folder) {
            eprintln!(
                "warning: {}: left by a ballbar writer that stopped before it finished (process {} is not running): an incomplete or unnamed copy, not a result; remove it",
                left.path.display(),
                left.pid
            );
        }
    }
}

/// How a write of this command treats a file under its name (`--force`).
pub fn existing(force: bool) -> Existing {
    Existing::replace_if(force)
}

/// Write one file of a command's outputs (checked by [`check`]), atomically.
pub fn write(path: &Path, bytes: &[u8], force: bool) -> Result<()> {
    ballbar_io::write_atomic(path, bytes, existing(force)).map_err(|e| written(e, force))
}

/// Write a command's files as one (checked by [`check`]): all of them, or none.
pub fn write_all(files: &[(PathBuf, String)], force: bool) -> Result<()> {
    let files: Vec<(&Path, &[u8])> =
        files.iter().map(|(p, t)| (p.as_path(), t.as_bytes())).collect();
    ballbar_io::write_all_atomic(&files, existing(force)).map_err(|e| written(e, force))
}

/// A failed write as a command failure: a name taken without `--force` was taken while the
/// command ran, after [`check`] saw it free.
pub fn written(e: ballbar_io::IoError, force: bool) -> Failure {
    Failure::Input(anyhow!("{e}{}", appeared(is_taken(&e), force)))
}

/// Whether `e` is a write that found its name taken.
fn is_taken(e: &ballbar_io::IoError) -> bool {
    matches!(e, ballbar_io::IoError::Io { error, .. } if error.kind() == std::io::ErrorKind::AlreadyExists)
}

/// What to add to the message of a write that found its name taken: it appeared while the
/// command ran.
pub fn appeared(taken: bool, force: bool) -> &'static str {
    if taken && !force {
        " (another program wrote it while this command ran; --force replaces it)"
    } else {
        ""
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn runs(paths: &[PathBuf]) -> Vec<Output> {
        paths.iter().map(|p| Output::new(p, "--out")).collect()
    }

    fn message(r: Result<()>) -> String {
        match r {
            Err(Failure::Input(e)) => e.to_string(),
            other => panic!("not an input error: {other:?}"),
        }
    }

    #[test]
    fn an_input_is_never_a_target_and_an_existing_file_only_with_force() {
        let d = std::env::temp_dir().join(format!("ballbar-outputs-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let input = d.join("a.csv");
        std::fs::write(&input, "x").unwrap();
        let other = d.join("b.csv");
        let fresh = d.join("new/c.csv");
        // Not existing: fine either way.
        assert!(
            check(
                &runs(&[other.clone(), fresh.clone()]),
                std::slice::from_ref(&input),
                false,
                "runs"
            )
            .is_ok()
        );
        std::fs::write(&other, "y").unwrap();
        let e = message(check(&runs(&[fresh, other.clone()]), &[], false, "runs"));
        assert!(
            e.contains("b.csv: already exists; nothing was written (--force replaces it)"),
            "{e}"
        );
        assert!(check(&runs(std::slice::from_ref(&other)), &[], true, "runs").is_ok());
        // The input, named through another path, even with --force.
        let via = d.join("new/../a.csv");
        std::fs::create_dir_all(d.join("new")).unwrap();
        let e = message(check(&runs(&[via]), std::slice::from_ref(&input), true, "runs"));
        assert!(
            e.contains("is one of the inputs; nothing was written (choose another --out)"),
            "{e}"
        );
        // A folder is not a file to write.
        let e = message(check(&[Output::new(&d, "--json")], &[], true, "outputs"));
        assert!(e.contains("is a folder; nothing was written (--json names a file)"), "{e}");
        // Two outputs on one file, through another path.
        let e = message(check(
            &[
                Output::new(d.join("x.json"), "--json"),
                Output::new(d.join("new/../x.json"), "--save-model"),
            ],
            &[],
            true,
            "outputs",
        ));
        assert!(e.contains("x.json: is named by both --json and --save-model"), "{e}");
        // A special file is written as it is: no --force needed.
        #[cfg(unix)]
        assert!(check(&[Output::new("/dev/null", "--json")], &[], false, "outputs").is_ok());
        // A link in the output folder to an input: the write would follow it.
        #[cfg(unix)]
        {
            let link = d.join("new/link.csv");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            let e = message(check(&runs(&[link]), std::slice::from_ref(&input), true, "runs"));
            assert!(e.contains("link.csv: is one of the inputs"), "{e}");
            // A link to a file that does not exist is a file the user has.
            let dangling = d.join("new/dangling.json");
            std::os::unix::fs::symlink("nowhere.json", &dangling).unwrap();
            let e = message(check(&[Output::new(&dangling, "--json")], &[], false, "outputs"));
            assert!(e.contains("dangling.json: already exists"), "{e}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }
}

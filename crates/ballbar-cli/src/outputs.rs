//! The files a command writes into its output folder, checked all together before the first is
//! written: none may be one of the command's inputs, and none may exist unless `--force`.

use std::path::{Path, PathBuf};

use anyhow::anyhow;

use crate::{Failure, Result};

/// Refuse, before anything is written, a `targets` list that would replace an input (never, not
/// even with `force`) or an existing file (unless `force`). The message names the first such
/// target and how many more of the `what` (say "runs") there are.
pub fn check_targets(
    targets: &[PathBuf],
    input_files: &[PathBuf],
    force: bool,
    what: &str,
) -> Result<()> {
    let inputs: Vec<PathBuf> =
        input_files.iter().filter_map(|f| std::fs::canonicalize(f).ok()).collect();
    // Where a write to the target would land: an existing target (a symlink included: the
    // writes follow links) resolved itself, a new one through its folder (which may not exist
    // yet: then it holds no input).
    let resolved = |t: &Path| -> Option<PathBuf> {
        if let Ok(c) = std::fs::canonicalize(t) {
            return Some(c);
        }
        let dir = t.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
        Some(std::fs::canonicalize(dir).ok()?.join(t.file_name()?))
    };
    if let Some(t) = targets.iter().find(|t| resolved(t).is_some_and(|r| inputs.contains(&r))) {
        return Err(Failure::Input(anyhow!(
            "{}: is one of the inputs; nothing was written (choose another --out)",
            t.display()
        )));
    }
    if force {
        return Ok(());
    }
    let existing: Vec<&PathBuf> =
        targets.iter().filter(|t| std::fs::symlink_metadata(t).is_ok()).collect();
    if let Some(first) = existing.first() {
        let more = match existing.len() {
            1 => String::new(),
            n => format!(" (and {} more of the {} {what})", n - 1, targets.len()),
        };
        return Err(Failure::Input(anyhow!(
            "{}: already exists{more}; nothing was written (--force replaces them)",
            first.display()
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
            check_targets(
                &[other.clone(), fresh.clone()],
                std::slice::from_ref(&input),
                false,
                "runs"
            )
            .is_ok()
        );
        std::fs::write(&other, "y").unwrap();
        let Err(Failure::Input(e)) = check_targets(&[fresh, other.clone()], &[], false, "runs")
        else {
            panic!("an existing file was accepted")
        };
        assert!(
            e.to_string()
                .contains("b.csv: already exists; nothing was written (--force replaces them)"),
            "{e}"
        );
        assert!(check_targets(std::slice::from_ref(&other), &[], true, "runs").is_ok());
        // The input, named through another path, even with --force.
        let via = d.join("new/../a.csv");
        std::fs::create_dir_all(d.join("new")).unwrap();
        let Err(Failure::Input(e)) =
            check_targets(&[via], std::slice::from_ref(&input), true, "runs")
        else {
            panic!("an input was accepted as a target")
        };
        assert!(e.to_string().contains("is one of the inputs"), "{e}");
        // A link in the output folder to an input: the write would follow it.
        #[cfg(unix)]
        {
            let link = d.join("new/link.csv");
            std::os::unix::fs::symlink(&input, &link).unwrap();
            let Err(Failure::Input(e)) =
                check_targets(&[link], std::slice::from_ref(&input), true, "runs")
            else {
                panic!("a link to an input was accepted")
            };
            assert!(e.to_string().contains("link.csv: is one of the inputs"), "{e}");
        }
        let _ = std::fs::remove_dir_all(&d);
    }
}

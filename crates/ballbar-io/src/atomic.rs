//! Writes that never leave a half-written file under the final name: write a uniquely named
//! temporary file in the same folder, flush it to disk, rename it over the target.

use std::fs::OpenOptions;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::IoError;

/// Makes temporary names unique among the writes of this process (the process id separates
/// processes).
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// Write `bytes` to `path` atomically: readers of `path` see the old file or the complete new
/// one, never a part.
///
/// The bytes go to `.{name}.{pid}.{counter}.tmp` in the target's folder (created new, so no
/// other file is overwritten), are flushed to disk, and the file is renamed over `path`. On
/// any error the temporary file is removed and the error names `path`.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), IoError> {
    let io_error = |error| IoError::Io { path: path.to_path_buf(), error };
    // A symbolic link is written through, to its target (renaming over the link would replace
    // the link itself); a target that is not a regular file (a terminal, a pipe, /dev/stdout)
    // is written as it is: it cannot be replaced, and a reader of it sees the bytes as they
    // come anyway.
    let target = follow_links(path).map_err(io_error)?;
    if target.file_name().is_none() {
        let msg = "not a file path (it has no file name)";
        return Err(io_error(std::io::Error::new(std::io::ErrorKind::InvalidInput, msg)));
    }
    match std::fs::metadata(&target) {
        Ok(m) if m.is_dir() => {
            return Err(io_error(std::io::Error::new(
                std::io::ErrorKind::IsADirectory,
                "it is a folder",
            )));
        }
        Ok(m) if !m.is_file() => {
            let mut f = OpenOptions::new().write(true).open(&target).map_err(io_error)?;
            return f.write_all(bytes).and_then(|()| f.flush()).map_err(io_error);
        }
        _ => {}
    }
    let path = target.as_path();
    let Some((dir, tmp)) = temporary_path(path) else {
        let msg = "not a file path (it has no file name)";
        return Err(io_error(std::io::Error::new(std::io::ErrorKind::InvalidInput, msg)));
    };
    // If creating fails there is nothing of ours to remove (the name may even be another's).
    let mut file = OpenOptions::new().write(true).create_new(true).open(&tmp).map_err(io_error)?;
    let written = file.write_all(bytes).and_then(|()| file.sync_all());
    drop(file);
    if let Err(e) = written.and_then(|()| std::fs::rename(&tmp, path)) {
        let _ = std::fs::remove_file(&tmp);
        return Err(io_error(e));
    }
    sync_dir(&dir);
    Ok(())
}

/// `path` with its symbolic links followed (a relative link from the link's folder), up to 40
/// of them; the path itself when it is not a link (or does not exist yet).
pub fn follow_links(path: &Path) -> std::io::Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let to = std::fs::read_link(&p)?;
                p = if to.is_absolute() {
                    to
                } else {
                    p.parent().map_or_else(|| to.clone(), |d| d.join(&to))
                };
            }
            _ => return Ok(p),
        }
    }
    Err(std::io::Error::other("more than 40 symbolic links"))
}

/// The folder of `path` (`.` for a bare file name) and a fresh temporary name in it,
/// `.{name}.{pid}.{counter}.tmp`; `None` if `path` has no file name. For writers that stream
/// into the temporary file themselves (an archive) before renaming it over `path`.
pub fn temporary_path(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.{}.{n}.tmp", name.to_string_lossy(), std::process::id()));
    Some((dir, tmp))
}

/// Flush the folder entry of the rename to disk where the OS allows it. Best effort: the file is
/// already complete under its final name, so a failure here is not an error of the write.
pub fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

/// The temporary files this module could have left in `dir` (names `.*.tmp`), for tests.
#[cfg(test)]
pub(crate) fn temporaries(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .expect("list the folder")
        .map(|e| e.expect("folder entry").path())
        .filter(|p| {
            let n = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            n.starts_with('.') && n.ends_with(".tmp")
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_dir;

    #[test]
    fn writes_and_replaces_leaving_no_temporary() {
        let dir = test_dir("atomic-replace");
        let f = dir.join("out.txt");
        write_atomic(&f, b"first").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"first");
        write_atomic(&f, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"second, longer");
        write_atomic(&f, b"").unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"");
        let names: Vec<_> =
            std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("out.txt")]);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A symbolic link is written through to its target and stays a link; a target that is not
    /// a regular file (/dev/null, as /dev/stdout is a terminal or a pipe) is written as it is,
    /// not replaced by a regular file (run as root, `--json /dev/stdout` must leave the
    /// /dev/stdout link in place).
    #[cfg(unix)]
    #[test]
    fn links_are_written_through_and_special_files_are_not_replaced() {
        let dir = test_dir("atomic-links");
        let target = dir.join("target.txt");
        std::fs::write(&target, b"old").unwrap();
        let link = dir.join("link.txt");
        std::os::unix::fs::symlink("target.txt", &link).unwrap();
        write_atomic(&link, b"new").unwrap();
        assert!(
            std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(),
            "the link stays a link"
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        let null_link = dir.join("null");
        std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
        write_atomic(&null_link, b"discarded").unwrap();
        assert!(std::fs::symlink_metadata(&null_link).unwrap().file_type().is_symlink());
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(),
            "/dev/null is still a device"
        );
        assert!(temporaries(&dir).is_empty());
        let e = write_atomic(&dir, b"x").unwrap_err();
        assert!(e.to_string().contains("it is a folder"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_folder_is_an_io_error_naming_the_path() {
        let dir = test_dir("atomic-missing");
        let f = dir.join("no-such-folder").join("out.txt");
        let e = write_atomic(&f, b"x").unwrap_err();
        assert!(matches!(&e, IoError::Io { path, .. } if *path == f), "{e:?}");
        assert!(
            e.to_string().contains("no-such-folder") && e.to_string().contains("out.txt"),
            "{e}"
        );
        assert!(!f.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_rename_removes_the_temporary_and_keeps_the_target() {
        let dir = test_dir("atomic-rename");
        // The target is a folder that is not empty: the file cannot be renamed over it.
        let target = dir.join("target");
        std::fs::create_dir(&target).unwrap();
        std::fs::write(target.join("keep"), b"kept").unwrap();
        let e = write_atomic(&target, b"new bytes").unwrap_err();
        assert!(matches!(&e, IoError::Io { path, .. } if *path == target), "{e:?}");
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        assert_eq!(std::fs::read(target.join("keep")).unwrap(), b"kept");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_path_without_a_file_name_is_an_error() {
        let e = write_atomic(Path::new("/"), b"x").unwrap_err();
        assert!(matches!(e, IoError::Io { .. }), "{e:?}");
        assert!(e.to_string().contains("no file name"), "{e}");
    }

    #[test]
    fn temporaries_go_next_to_the_target_with_unique_names() {
        let (dir, tmp) = temporary_path(Path::new("run.csv")).unwrap();
        assert_eq!(dir, PathBuf::from("."));
        let name = tmp.file_name().unwrap().to_string_lossy().into_owned();
        assert_eq!(tmp.parent(), Some(Path::new(".")));
        assert!(
            name.starts_with(&format!(".run.csv.{}.", std::process::id()))
                && name.ends_with(".tmp"),
            "{name}"
        );
        let (dir, tmp2) = temporary_path(Path::new("out/runs/run.csv")).unwrap();
        assert_eq!(dir, PathBuf::from("out/runs"));
        assert_eq!(tmp2.parent(), Some(Path::new("out/runs")));
        assert_ne!(tmp.file_name(), tmp2.file_name());
        assert!(temporary_path(Path::new("/")).is_none());
        assert!(temporary_path(Path::new("out/..")).is_none());
    }

    #[test]
    fn concurrent_writers_leave_one_complete_file() {
        let dir = test_dir("atomic-concurrent");
        let f = dir.join("shared.txt");
        let contents: Vec<Vec<u8>> =
            (0..8u8).map(|k| vec![b'a' + k; 100_000 + usize::from(k)]).collect();
        std::thread::scope(|s| {
            for c in &contents {
                let f = &f;
                s.spawn(move || {
                    for _ in 0..5 {
                        write_atomic(f, c).unwrap();
                    }
                });
            }
            // A reader never sees a part of a file.
            s.spawn(|| {
                for _ in 0..200 {
                    if let Ok(b) = std::fs::read(&f) {
                        assert!(
                            contents.contains(&b),
                            "a read saw {} bytes that no writer wrote",
                            b.len()
                        );
                    }
                }
            });
        });
        let end = std::fs::read(&f).unwrap();
        assert!(contents.contains(&end));
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! Writes that never leave a half-written file under the final name and never replace a file
//! unasked: the bytes go to a uniquely named temporary file in the target's folder, are flushed
//! to disk, and the file then takes the final name in one step. Without leave to replace
//! ([`Existing::Keep`]) that step is a link that fails if the name is taken, so a file that
//! appeared there after any earlier check is kept; with it ([`Existing::Replace`]) it is a
//! rename over the old file, and the new file keeps the old one's permission bits (and owner
//! and group, where the process may set them).
//!
//! Several files of one command ([`write_all_atomic`]) are written whole or not at all: every
//! temporary file is written and flushed before the first takes its name, so that a full disk
//! or any other failure while writing leaves none of them.
//!
//! A temporary file is removed on every way out but success; a writer that is killed leaves it
//! behind (`.{name}.{pid}.{counter}.tmp`), and [`stale_temporaries`] finds such leftovers of
//! processes that no longer run, for the next writer into the folder to name.

use std::fs::{File, Metadata, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::IoError;

/// Makes temporary names unique among the writes of this process (the process id separates
/// processes).
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// What a write does with a file that already has the target's name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Keep it: the write fails ([`std::io::ErrorKind::AlreadyExists`]) and the file is left as
    /// it was, also when it appeared only an instant before the write took the name.
    Keep,
    /// Replace it; the new file keeps its permission bits, owner and group.
    Replace,
}

impl Existing {
    /// [`Existing::Replace`] when `force`, else [`Existing::Keep`].
    pub fn replace_if(force: bool) -> Existing {
        if force { Existing::Replace } else { Existing::Keep }
    }
}

/// The message of a write that found its name taken under [`Existing::Keep`].
const TAKEN: &str = "already exists; it was not replaced";

/// Write `bytes` to `path` atomically: readers of `path` see the old file (or none) or the
/// complete new one, never a part.
///
/// A symbolic link is written through, to its target; a target that is not a regular file (a
/// terminal, a pipe, `/dev/null`) is written as it is, since it cannot be replaced and holds
/// nothing to keep. A folder is an error. Otherwise the bytes go to
/// `.{name}.{pid}.{counter}.tmp` in the target's folder (created new, so no other file is
/// overwritten), are flushed to disk, and the file takes the final name as `existing` says. On
/// any error the temporary file is removed and the error names `path`.
pub fn write_atomic(path: &Path, bytes: &[u8], existing: Existing) -> Result<(), IoError> {
    write_all_atomic(&[(path, bytes)], existing)
}

/// Write several files as one: each as [`write_atomic`] does, and every temporary file written
/// and flushed before the first takes its final name. A failure before that point (a full disk,
/// a folder that does not exist) leaves none of the files; a failure as the files take their
/// names (under [`Existing::Keep`], a name that was taken meanwhile) removes again the new files
/// already in place. The error names the file that failed and says what became of the others.
pub fn write_all_atomic(files: &[(&Path, &[u8])], existing: Existing) -> Result<(), IoError> {
    // Every target resolved and checked before anything is created.
    let mut targets = Vec::with_capacity(files.len());
    for &(path, _) in files {
        let io_error = |error| IoError::Io { path: path.to_path_buf(), error };
        let target = follow_links(path).map_err(io_error)?;
        if target.file_name().is_none() {
            return Err(io_error(not_a_file_path()));
        }
        let special = match std::fs::metadata(&target) {
            Ok(m) if m.is_dir() => {
                return Err(io_error(std::io::Error::new(
                    std::io::ErrorKind::IsADirectory,
                    "it is a folder",
                )));
            }
            Ok(m) => !m.is_file(),
            Err(_) => false,
        };
        targets.push((target, special));
    }
    let several = files.len() > 1;
    // The temporary files, written and flushed.
    let mut temporaries: Vec<Option<Temporary>> = Vec::with_capacity(files.len());
    for (&(path, bytes), (target, special)) in files.iter().zip(&targets) {
        if *special {
            temporaries.push(None);
            continue;
        }
        let written = Temporary::create(target, existing).and_then(|(mut t, mut file)| match file
            .write_all(bytes)
            .and_then(|()| t.finish(file))
        {
            Ok(()) => Ok(t),
            Err(e) => Err(match t.remove() {
                Ok(()) => e,
                Err(r) => with_outcome(e, &left_behind(&t.path, &r)),
            }),
        });
        match written {
            Ok(t) => temporaries.push(Some(t)),
            Err(e) => {
                let left = discard(temporaries.into_iter().flatten());
                let outcome = if several { "; none of the files was written" } else { "" };
                return Err(IoError::Io {
                    path: path.to_path_buf(),
                    error: with_outcome(e, &format!("{outcome}{left}")),
                });
            }
        }
    }
    // Each takes its name; a special file is written as it is.
    let mut named: Vec<(&Path, Option<&Path>)> = Vec::with_capacity(files.len());
    let mut pending = temporaries.into_iter();
    for ((&(path, bytes), (target, _)), temporary) in files.iter().zip(&targets).zip(&mut pending) {
        let regular = temporary.is_some();
        let result = match temporary {
            Some(t) => t.commit(),
            None => OpenOptions::new()
                .write(true)
                .open(target)
                .and_then(|mut f| f.write_all(bytes).and_then(|()| f.flush())),
        };
        if let Err(e) = result {
            let left = discard(pending.flatten());
            let outcome = if several { outcome(&named, existing) } else { String::new() };
            return Err(IoError::Io {
                path: path.to_path_buf(),
                error: with_outcome(e, &format!("{outcome}{left}")),
            });
        }
        named.push((path, regular.then_some(target.as_path())));
    }
    Ok(())
}

/// What became of the files of a [`write_all_atomic`] that failed as they took their names:
/// `named` had taken theirs (`(path, Some(target))` a regular file, `None` a special file
/// written as it is). Under [`Existing::Keep`] each regular one is new, made by this call, and
/// is removed again.
fn outcome(named: &[(&Path, Option<&Path>)], existing: Existing) -> String {
    let shown = |ps: &[&Path]| ps.iter().map(|p| p.display().to_string()).collect::<Vec<_>>();
    let remain: Vec<&Path> = named
        .iter()
        .filter(|(_, target)| {
            existing == Existing::Replace || target.is_none_or(|t| std::fs::remove_file(t).is_err())
        })
        .map(|(p, _)| *p)
        .collect();
    match (named.is_empty(), remain.is_empty()) {
        (true, _) => "; none of the files was written".into(),
        (false, true) => {
            "; none of the files was written (those already in place were removed again)".into()
        }
        (false, false) => {
            format!("; written before it: {}; the others were not", shown(&remain).join(", "))
        }
    }
}

/// `e` with `more` added to its message, of the same kind.
fn with_outcome(e: std::io::Error, more: &str) -> std::io::Error {
    if more.is_empty() { e } else { std::io::Error::new(e.kind(), format!("{e}{more}")) }
}

/// What to add to an error for a temporary file that could not be removed.
fn left_behind(tmp: &Path, e: &std::io::Error) -> String {
    format!("; the temporary file {} is left behind ({e}): remove it", tmp.display())
}

fn not_a_file_path() -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, "not a file path (it has no file name)")
}

/// Remove the temporary files; the text to add to an error for any that could not be removed
/// (empty when all were).
fn discard(temporaries: impl Iterator<Item = Temporary>) -> String {
    let left: Vec<String> = temporaries
        .filter_map(|mut t| t.remove().err().map(|e| format!("{} ({e})", t.path.display())))
        .collect();
    if left.is_empty() {
        String::new()
    } else {
        format!("; temporary files left behind, to remove: {}", left.join(", "))
    }
}

/// A temporary file beside the target of a write, which takes the target's name when the write
/// is complete ([`Temporary::commit`]) and is removed otherwise (when dropped).
///
/// For writers that stream into the file themselves (an archive): [`Temporary::create`], write
/// into the [`File`], [`Temporary::finish`] it, [`Temporary::commit`].
#[derive(Debug)]
pub struct Temporary {
    path: PathBuf,
    target: PathBuf,
    dir: PathBuf,
    existing: Existing,
    /// The file to be replaced (under [`Existing::Replace`]): its mode and owner go to the new
    /// file.
    replaced: Option<Metadata>,
    /// Taken its final name, or removed: nothing left to remove.
    done: bool,
}

impl Temporary {
    /// A new, empty temporary file beside `target` (a path with its links already followed,
    /// [`follow_links`]). When it is to replace a file, it is created readable by its owner
    /// alone until it takes that file's mode, so that the new content is never more widely
    /// readable than the old.
    pub fn create(target: &Path, existing: Existing) -> std::io::Result<(Temporary, File)> {
        let (dir, path) = temporary_path(target).ok_or_else(not_a_file_path)?;
        let replaced = match existing {
            Existing::Replace => std::fs::metadata(target).ok().filter(Metadata::is_file),
            Existing::Keep => None,
        };
        let mut options = OpenOptions::new();
        options.write(true).create_new(true);
        #[cfg(unix)]
        if replaced.is_some() {
            use std::os::unix::fs::OpenOptionsExt as _;
            options.mode(0o600);
        }
        // If creating fails there is nothing of ours to remove (the name may even be another's).
        let file = options.open(&path)?;
        let t =
            Temporary { path, target: target.to_path_buf(), dir, existing, replaced, done: false };
        Ok((t, file))
    }

    /// The temporary file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The file complete: give it the mode (and owner) of the file it replaces, and flush it to
    /// disk.
    pub fn finish(&mut self, file: File) -> std::io::Result<()> {
        if let Some(old) = &self.replaced {
            keep_mode_and_owner(&file, old)?;
        }
        file.sync_all()
    }

    /// Give the finished file its final name (under [`Existing::Keep`] only if the name is
    /// free at that instant: [`std::io::ErrorKind::AlreadyExists`] otherwise, and the file
    /// there is kept). On an error the temporary file is removed.
    pub fn commit(mut self) -> std::io::Result<()> {
        let named = match self.existing {
            Existing::Replace => std::fs::rename(&self.path, &self.target),
            Existing::Keep => take_free_name(&self.path, &self.target),
        };
        match named {
            Ok(()) => {
                self.done = true;
                sync_dir(&self.dir);
                Ok(())
            }
            Err(e) => match self.remove() {
                Ok(()) => Err(e),
                Err(r) => Err(with_outcome(e, &left_behind(&self.path, &r))),
            },
        }
    }

    /// Remove the temporary file (once).
    fn remove(&mut self) -> std::io::Result<()> {
        if self.done {
            return Ok(());
        }
        self.done = true;
        match std::fs::remove_file(&self.path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(e),
            _ => Ok(()),
        }
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        let _ = self.remove();
    }
}

/// Give `tmp` the name `target` only if no file has it: a hard link, which the file system
/// refuses when the name exists, then the temporary name removed. Where the file system has no
/// hard links (FAT, some network shares) the name is claimed by creating it exclusively and the
/// file renamed over that claim: a writer killed in between leaves an empty file there.
fn take_free_name(tmp: &Path, target: &Path) -> std::io::Result<()> {
    let taken = || std::io::Error::new(std::io::ErrorKind::AlreadyExists, TAKEN);
    match std::fs::hard_link(tmp, target) {
        Ok(()) => {
            // The file is complete under its name; a second name left behind would be named by
            // the next writer into the folder (stale_temporaries).
            let _ = std::fs::remove_file(tmp);
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Err(taken()),
        Err(_) => {
            match OpenOptions::new().write(true).create_new(true).open(target) {
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => return Err(taken()),
                Err(e) => return Err(e),
            }
            std::fs::rename(tmp, target).inspect_err(|_| {
                let _ = std::fs::remove_file(target);
            })
        }
    }
}

/// The replaced file's permission bits (without set-user-ID and set-group-ID: new content does
/// not inherit privileges) on the new one, and its owner and group where the process may give
/// them (root may; others keep at least the group if they are in it).
#[cfg(unix)]
fn keep_mode_and_owner(file: &File, old: &Metadata) -> std::io::Result<()> {
    use std::os::unix::fs::{MetadataExt as _, PermissionsExt as _};
    // The owner first: a change of owner clears mode bits, which the mode then sets.
    if std::os::unix::fs::fchown(file, Some(old.uid()), Some(old.gid())).is_err() {
        let _ = std::os::unix::fs::fchown(file, None, Some(old.gid()));
    }
    file.set_permissions(std::fs::Permissions::from_mode(old.mode() & 0o1777))
}

/// The replaced file's read-only flag on the new one.
#[cfg(not(unix))]
fn keep_mode_and_owner(file: &File, old: &Metadata) -> std::io::Result<()> {
    file.set_permissions(old.permissions())
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
/// `.{name}.{pid}.{counter}.tmp`; `None` if `path` has no file name.
pub fn temporary_path(path: &Path) -> Option<(PathBuf, PathBuf)> {
    let name = path.file_name()?;
    let dir = folder_of(path);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.{}.{n}.tmp", name.to_string_lossy(), std::process::id()));
    Some((dir, tmp))
}

/// The folder a file `path` is in (`.` for a bare file name).
pub fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A temporary file that a writer of another process left behind.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Leftover {
    /// The file.
    pub path: PathBuf,
    /// The process that made it, which no longer runs.
    pub pid: u32,
}

/// The temporary files of this module's writers in `dir` (`.{name}.{pid}.{counter}.tmp`) whose
/// process no longer runs: a writer killed before its file took its name. They are incomplete
/// or unnamed copies, never results.
///
/// Found only where the running processes can be seen (`/proc`); elsewhere, and for a folder
/// that cannot be listed, none. They are named, not removed: a process id seen as dead here may
/// be alive on another machine sharing the folder, or in another container.
pub fn stale_temporaries(dir: &Path) -> Vec<Leftover> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return Vec::new();
    }
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut found: Vec<Leftover> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name();
            let pid = temporary_pid(name.to_str()?)?;
            let dead = pid != std::process::id() && !proc.join(pid.to_string()).exists();
            dead.then(|| Leftover { path: e.path(), pid })
        })
        .collect();
    found.sort_by(|a, b| a.path.cmp(&b.path));
    found
}

/// The process id in a temporary file's name `.{name}.{pid}.{counter}.tmp`.
fn temporary_pid(file_name: &str) -> Option<u32> {
    let inner = file_name.strip_prefix('.')?.strip_suffix(".tmp")?;
    let mut parts = inner.rsplitn(3, '.');
    let (counter, pid, name) = (parts.next()?, parts.next()?, parts.next()?);
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    (digits(counter) && digits(pid) && !name.is_empty()).then(|| pid.parse().ok()).flatten()
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
        write_atomic(&f, b"first", Existing::Replace).unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"first");
        write_atomic(&f, b"second, longer", Existing::Replace).unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"second, longer");
        write_atomic(&f, b"", Existing::Replace).unwrap();
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
        write_atomic(&link, b"new", Existing::Replace).unwrap();
        assert!(
            std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(),
            "the link stays a link"
        );
        assert_eq!(std::fs::read(&target).unwrap(), b"new");
        let null_link = dir.join("null");
        std::os::unix::fs::symlink("/dev/null", &null_link).unwrap();
        write_atomic(&null_link, b"discarded", Existing::Replace).unwrap();
        assert!(std::fs::symlink_metadata(&null_link).unwrap().file_type().is_symlink());
        use std::os::unix::fs::FileTypeExt;
        assert!(
            std::fs::metadata("/dev/null").unwrap().file_type().is_char_device(),
            "/dev/null is still a device"
        );
        assert!(temporaries(&dir).is_empty());
        let e = write_atomic(&dir, b"x", Existing::Replace).unwrap_err();
        assert!(e.to_string().contains("it is a folder"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_missing_folder_is_an_io_error_naming_the_path() {
        let dir = test_dir("atomic-missing");
        let f = dir.join("no-such-folder").join("out.txt");
        let e = write_atomic(&f, b"x", Existing::Replace).unwrap_err();
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
        let e = write_atomic(&target, b"new bytes", Existing::Replace).unwrap_err();
        assert!(matches!(&e, IoError::Io { path, .. } if *path == target), "{e:?}");
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        assert_eq!(std::fs::read(target.join("keep")).unwrap(), b"kept");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_path_without_a_file_name_is_an_error() {
        let e = write_atomic(Path::new("/"), b"x", Existing::Replace).unwrap_err();
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
                        write_atomic(f, c, Existing::Replace).unwrap();
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

    #[test]
    fn without_leave_to_replace_an_existing_file_is_kept() {
        let dir = test_dir("atomic-keep");
        let f = dir.join("out.txt");
        write_atomic(&f, b"first", Existing::Keep).unwrap();
        let e = write_atomic(&f, b"second", Existing::Keep).unwrap_err();
        assert!(
            matches!(&e, IoError::Io { path, error } if *path == f && error.kind() == std::io::ErrorKind::AlreadyExists),
            "{e:?}"
        );
        assert!(e.to_string().contains("out.txt: already exists; it was not replaced"), "{e}");
        assert_eq!(std::fs::read(&f).unwrap(), b"first");
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        // A special file is written as it is: it holds nothing to keep.
        #[cfg(unix)]
        write_atomic(Path::new("/dev/null"), b"discarded", Existing::Keep).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The race a check before the work cannot close: another program writes the target after
    /// the temporary file was made and before it takes the name. Without leave to replace, that
    /// file is kept, the write fails, and its temporary file is removed.
    #[test]
    fn a_file_that_appears_before_the_final_name_is_taken_is_not_replaced() {
        let dir = test_dir("atomic-race");
        let f = dir.join("out.json");
        let (mut t, mut file) = Temporary::create(&f, Existing::Keep).unwrap();
        file.write_all(b"ours").unwrap();
        t.finish(file).unwrap();
        let tmp = t.path().to_path_buf();
        std::fs::write(&f, b"another program's").unwrap();
        let e = t.commit().unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::AlreadyExists, "{e}");
        assert_eq!(std::fs::read(&f).unwrap(), b"another program's");
        assert!(!tmp.exists() && temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        // With leave to replace, the same steps replace it.
        let (mut t, mut file) = Temporary::create(&f, Existing::Replace).unwrap();
        file.write_all(b"ours").unwrap();
        t.finish(file).unwrap();
        t.commit().unwrap();
        assert_eq!(std::fs::read(&f).unwrap(), b"ours");
        // A temporary dropped before it takes its name is removed.
        let (t, _file) = Temporary::create(&dir.join("other"), Existing::Keep).unwrap();
        let tmp = t.path().to_path_buf();
        assert!(tmp.exists());
        drop(t);
        assert!(!tmp.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A replaced file keeps its permission bits: 0600 stays 0600 (a new file would get 0644
    /// or what the umask gives), 0640 stays 0640; set-user-ID is not carried to new content.
    #[cfg(unix)]
    #[test]
    fn a_replaced_file_keeps_its_permission_bits() {
        use std::os::unix::fs::PermissionsExt as _;
        let dir = test_dir("atomic-mode");
        let f = dir.join("private.json");
        for mode in [0o600, 0o640, 0o444] {
            std::fs::write(&f, b"old").unwrap();
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(mode)).unwrap();
            write_atomic(&f, b"new", Existing::Replace).unwrap();
            assert_eq!(std::fs::read(&f).unwrap(), b"new");
            let m = std::fs::metadata(&f).unwrap().permissions().mode() & 0o7777;
            assert_eq!(m, mode, "{m:o} after replacing a {mode:o} file");
            std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o600)).unwrap();
            std::fs::remove_file(&f).unwrap();
        }
        std::fs::write(&f, b"old").unwrap();
        std::fs::set_permissions(&f, std::fs::Permissions::from_mode(0o4755)).unwrap();
        write_atomic(&f, b"new", Existing::Replace).unwrap();
        let m = std::fs::metadata(&f).unwrap().permissions().mode() & 0o7777;
        assert_eq!(m, 0o755, "{m:o}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A replaced file keeps its owner and group where the process may give them: only a
    /// privileged process may give a file away, so the owner part runs where chown works.
    #[cfg(unix)]
    #[test]
    fn a_replaced_file_keeps_its_owner_where_the_process_may_set_it() {
        use std::os::unix::fs::MetadataExt as _;
        let dir = test_dir("atomic-owner");
        let f = dir.join("theirs.json");
        std::fs::write(&f, b"old").unwrap();
        let (uid, gid) = (4321, 4322);
        if std::os::unix::fs::chown(&f, Some(uid), Some(gid)).is_err() {
            // Not privileged: the owner is this process's user, which a replacement keeps.
            let before = std::fs::metadata(&f).unwrap();
            write_atomic(&f, b"new", Existing::Replace).unwrap();
            let after = std::fs::metadata(&f).unwrap();
            assert_eq!((after.uid(), after.gid()), (before.uid(), before.gid()));
        } else {
            write_atomic(&f, b"new", Existing::Replace).unwrap();
            let after = std::fs::metadata(&f).unwrap();
            assert_eq!((after.uid(), after.gid()), (uid, gid), "the owner was not kept");
        }
        assert_eq!(std::fs::read(&f).unwrap(), b"new");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Several files are written whole or not at all: when one cannot be written (here its
    /// folder does not exist, as a full disk fails the write of a temporary file), none is, and
    /// no temporary file is left; when one name is taken under [`Existing::Keep`], the files
    /// already in place are removed again.
    #[test]
    fn several_files_are_written_all_or_none() {
        let dir = test_dir("atomic-all");
        let (a, b) = (dir.join("a.csv"), dir.join("missing").join("b.csv"));
        let e = write_all_atomic(&[(&a, b"a"), (&b, b"b")], Existing::Replace).unwrap_err();
        assert!(matches!(&e, IoError::Io { path, .. } if *path == b), "{e:?}");
        assert!(e.to_string().contains("none of the files was written"), "{e}");
        assert!(!a.exists(), "one of two was written");
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        let (b, c) = (dir.join("b.csv"), dir.join("c.csv"));
        std::fs::write(&c, b"taken").unwrap();
        let e =
            write_all_atomic(&[(&a, b"a"), (&b, b"b"), (&c, b"c")], Existing::Keep).unwrap_err();
        assert!(matches!(&e, IoError::Io { path, .. } if *path == c), "{e:?}");
        assert!(
            e.to_string().contains("already exists; it was not replaced; none of the files was written (those already in place were removed again)"),
            "{e}"
        );
        assert!(!a.exists() && !b.exists());
        assert_eq!(std::fs::read(&c).unwrap(), b"taken");
        assert!(temporaries(&dir).is_empty(), "{:?}", temporaries(&dir));
        write_all_atomic(&[(&a, b"a"), (&b, b"b"), (&c, b"c")], Existing::Replace).unwrap();
        assert_eq!(std::fs::read(&c).unwrap(), b"c");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The leftovers of a writer that no longer runs are found (where `/proc` shows the running
    /// processes); this process's own, a running process's and other files are not.
    #[test]
    fn the_temporaries_of_a_process_that_no_longer_runs_are_found() {
        let dir = test_dir("atomic-stale");
        // Linux process ids stay below 2^22 (pid_max); 1 always runs.
        let dead = dir.join(".run.csv.4000000000.3.tmp");
        let names = [
            ".run.csv.4000000000.3.tmp".to_string(),
            format!(".run.csv.{}.0.tmp", std::process::id()),
            ".run.csv.1.0.tmp".into(),
            ".run.csv.x.0.tmp".into(),
            "run.csv".into(),
            ".4000000000.0.tmp".into(),
        ];
        for n in &names {
            std::fs::write(dir.join(n), b"x").unwrap();
        }
        let found = stale_temporaries(&dir);
        if Path::new("/proc/self").exists() {
            assert_eq!(found, vec![Leftover { path: dead, pid: 4_000_000_000 }]);
        } else {
            assert!(found.is_empty(), "without /proc nothing is claimed: {found:?}");
        }
        assert_eq!(temporary_pid(".a.b.csv.17.2.tmp"), Some(17));
        assert_eq!(temporary_pid(".a.17.2.tmp"), Some(17));
        assert_eq!(temporary_pid("a.17.2.tmp"), None);
        assert_eq!(temporary_pid(".a.17..tmp"), None);
        assert_eq!(temporary_pid(".17.2.tmp"), None);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

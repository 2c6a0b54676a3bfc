//! The installed layout of ballbar, the copying into it and the tasks that do it: `cargo xtask
//! dist`, `install` and `uninstall` from their arguments to their output, with the dist build
//! handed in ([`Host::build`]). Standard library only: the end-to-end tests depend on it (the
//! xtask library), hand in the binary under test as the "build", and run the tasks and the tree.
//!
//! ```text
//! PREFIX/bin/ballbar                                  the binary
//! PREFIX/lib/ballbar/plugins/libballbar_machine_*.so  the machine plugins, which the binary
//!                                                     finds as ../lib/ballbar/plugins
//! PREFIX/lib/ballbar/install-manifest.txt             what install wrote, with content hashes:
//!                                                     uninstall removes only those, unchanged
//! PREFIX/share/bash-completion/completions/ballbar    completion scripts, where bash-completion,
//! PREFIX/share/zsh/site-functions/_ballbar            zsh and fish look under ~/.local and
//! PREFIX/share/fish/vendor_completions.d/ballbar.fish /usr/local
//! ```

use std::ffi::OsString;
use std::io::{Read, Write};
use std::path::{Component, Path, PathBuf};
use std::process::Command;

/// The plugins' folder under the prefix: the binary's own search looks there
/// (`ballbar_plugin_host::INSTALLED_PLUGIN_DIR`, the same text; the e2e test runs a binary
/// in a tree laid out with this one).
pub const PLUGIN_DIR: &str = "lib/ballbar/plugins";

/// The manifest under the prefix: one line per file written, its content hash and its path;
/// one line per folder the install created under the prefix, [`FOLDER_TAG`] and its path.
pub const MANIFEST: &str = "lib/ballbar/install-manifest.txt";

/// What a manifest line of a folder starts with, in place of a file's hash.
pub const FOLDER_TAG: &str = "folder";

/// The completion scripts written: the shell, and the file under the prefix.
pub const COMPLETIONS: [(&str, &str); 3] = [
    ("bash", "share/bash-completion/completions/ballbar"),
    ("zsh", "share/zsh/site-functions/_ballbar"),
    ("fish", "share/fish/vendor_completions.d/ballbar.fish"),
];

/// `cargo xtask dist`'s usage.
pub const DIST_USAGE: &str = "usage: cargo xtask dist [--out DIR] [--force]";
/// `cargo xtask install`'s usage.
pub const INSTALL_USAGE: &str =
    "usage: cargo xtask install [--prefix DIR] [--plugins-only] [--force]";
/// `cargo xtask uninstall`'s usage.
pub const UNINSTALL_USAGE: &str = "usage: cargo xtask uninstall [--prefix DIR]";

/// The binary's path under `prefix`.
pub fn binary(prefix: &Path) -> PathBuf {
    prefix.join("bin").join(format!("ballbar{}", std::env::consts::EXE_SUFFIX))
}

/// The plugins' folder under `prefix`.
pub fn plugin_dir(prefix: &Path) -> PathBuf {
    prefix.join(PLUGIN_DIR)
}

/// The install manifest under `prefix`.
pub fn manifest(prefix: &Path) -> PathBuf {
    prefix.join(MANIFEST)
}

/// True for a file name the binary's folder search loads as a plugin (the same test as
/// `ballbar_plugin_host::is_plugin_file_name`).
pub fn is_plugin_file_name(name: &str) -> bool {
    let stem = name.strip_prefix("lib").unwrap_or(name);
    stem.starts_with("ballbar_machine_")
        && [".so", ".dylib", ".dll"].iter().any(|e| stem.ends_with(e))
}

/// A task's failure: a usage error (exit 2: the arguments are wrong, nothing was done) or an
/// error (exit 1).
#[derive(Clone, Debug, PartialEq)]
pub enum Failure {
    /// Wrong arguments: the message ends with the task's usage.
    Usage(String),
    /// Anything else, naming the file.
    Error(String),
}

impl Failure {
    /// The process exit code: 2 for usage, 1 otherwise.
    pub fn exit_code(&self) -> u8 {
        match self {
            Failure::Usage(_) => 2,
            Failure::Error(_) => 1,
        }
    }
}

/// What a build produced: the binary and the plugin libraries.
#[derive(Clone, Debug)]
pub struct Built {
    /// The `ballbar` executable.
    pub binary: PathBuf,
    /// The plugin libraries (their file names are kept).
    pub plugins: Vec<PathBuf>,
}

/// What the tasks take from their surroundings.
pub struct Host<'a> {
    /// The home folder: the default prefix is `HOME/.local`.
    pub home: Option<PathBuf>,
    /// `dist`'s default output folder.
    pub dist_dir: Option<PathBuf>,
    /// `PATH`, to say when `PREFIX/bin` is not on it.
    pub path: Option<OsString>,
    /// Builds the binary and the plugins (`cargo build --profile dist` in xtask); called only once
    /// the arguments are checked.
    pub build: &'a mut dyn FnMut() -> Result<Built, String>,
}

/// Run the task `dist`, `install` or `uninstall` with `args` (after the task's name), telling
/// the user on `out`.
pub fn run(
    task: &str,
    args: &[String],
    host: &mut Host<'_>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    match task {
        "dist" => dist(args, host, out),
        "install" => install_task(args, host, out),
        "uninstall" => uninstall_task(args, host, out),
        other => Err(Failure::Usage(format!("unknown task {other}"))),
    }
}

/// A line to the user.
fn say(out: &mut dyn Write, line: impl std::fmt::Display) -> Result<(), Failure> {
    writeln!(out, "{line}").map_err(|e| Failure::Error(format!("cannot write the output: {e}")))
}

/// `VALUED DIR` and flag options of a task; anything else, a missing value or a value that is
/// an option (`--prefix --force`) is a usage error.
pub fn options<'a>(
    args: &'a [String],
    valued: &str,
    flags: &[&str],
    usage: &str,
) -> Result<(Option<&'a str>, Vec<&'a str>), Failure> {
    let (mut value, mut set) = (None, Vec::new());
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            v if v == valued => {
                let given = match it.next() {
                    Some(x) if !x.is_empty() && !x.starts_with("--") => x.as_str(),
                    Some(x) => {
                        return Err(Failure::Usage(format!(
                            "{valued} needs a folder, not '{x}'\n{usage}"
                        )));
                    }
                    None => {
                        return Err(Failure::Usage(format!("{valued} needs a folder\n{usage}")));
                    }
                };
                if value.replace(given).is_some() {
                    return Err(Failure::Usage(format!("{valued} given twice\n{usage}")));
                }
            }
            f if flags.contains(&f) => set.push(f),
            other => return Err(Failure::Usage(format!("unexpected argument {other}\n{usage}"))),
        }
    }
    Ok((value, set))
}

/// `--prefix DIR`, or `HOME/.local`.
fn prefix_or_home(prefix: Option<&str>, host: &Host<'_>) -> Result<PathBuf, Failure> {
    match prefix {
        Some(p) => Ok(PathBuf::from(p)),
        None => host
            .home
            .as_ref()
            .map(|h| h.join(".local"))
            .ok_or_else(|| Failure::Error("no HOME: give --prefix DIR".into())),
    }
}

/// `cargo xtask dist [--out DIR] [--force]`: a relocatable tree, by default
/// `target/dist/ballbar-VERSION-OS-ARCH`.
fn dist(args: &[String], host: &mut Host<'_>, out: &mut dyn Write) -> Result<(), Failure> {
    let (dir, flags) = options(args, "--out", &["--force"], DIST_USAGE)?;
    let dir = match dir {
        Some(d) => PathBuf::from(d),
        None => host
            .dist_dir
            .clone()
            .ok_or_else(|| Failure::Error("no default output folder: give --out DIR".into()))?,
    };
    let force = flags.contains(&"--force");
    // Before the build: an existing tree is refused in a second, not after minutes.
    may_replace(&binary(&dir), force).map_err(Failure::Error)?;
    let built = (host.build)().map_err(Failure::Error)?;
    let installed = install(&Install {
        prefix: &dir,
        binary: Some(&built.binary),
        plugins: &built.plugins,
        force,
    })
    .map_err(Failure::Error)?;
    tell_installed(out, &installed, None)?;
    say(out, check(&dir, &installed.plugins).map_err(Failure::Error)?)?;
    say(
        out,
        format_args!(
            "wrote {} files to {}; the tree can be moved as a whole (bin/ finds ../{PLUGIN_DIR})",
            installed.written.len(),
            dir.display()
        ),
    )
}

/// `cargo xtask install [--prefix DIR] [--plugins-only] [--force]`: the same tree in a prefix,
/// `~/.local` by default; `--plugins-only` beside a binary that `cargo install` put there.
fn install_task(args: &[String], host: &mut Host<'_>, out: &mut dyn Write) -> Result<(), Failure> {
    let (prefix, flags) = options(args, "--prefix", &["--force", "--plugins-only"], INSTALL_USAGE)?;
    let prefix = prefix_or_home(prefix, host)?;
    let (plugins_only, force) = (flags.contains(&"--plugins-only"), flags.contains(&"--force"));
    if !plugins_only {
        // Before the build: an existing installation is refused in a second, not after minutes.
        may_replace(&binary(&prefix), force).map_err(Failure::Error)?;
    }
    let built = (host.build)().map_err(Failure::Error)?;
    let bin = (!plugins_only).then_some(built.binary.as_path());
    let installed =
        install(&Install { prefix: &prefix, binary: bin, plugins: &built.plugins, force })
            .map_err(Failure::Error)?;
    tell_installed(out, &installed, Some("installed"))?;
    if binary(&prefix).is_file() {
        say(out, check(&prefix, &installed.plugins).map_err(Failure::Error)?)?;
    } else {
        say(
            out,
            format_args!(
                "no {} yet: the plugins are found by a ballbar installed there",
                binary(&prefix).display()
            ),
        )?;
    }
    let bin_dir = prefix.join("bin");
    let on_path =
        host.path.as_ref().is_some_and(|p| std::env::split_paths(p).any(|d| d == bin_dir));
    if !on_path {
        say(
            out,
            format_args!(
                "note: {} is not on PATH; add it to run `ballbar` by name",
                bin_dir.display()
            ),
        )?;
    }
    Ok(())
}

/// Tell what [`install`] did: each file written (when `verb` is given), each earlier plugin
/// removed, each other plugin left in the folder, the manifest.
fn tell_installed(out: &mut dyn Write, i: &Installed, verb: Option<&str>) -> Result<(), Failure> {
    if let Some(verb) = verb {
        for f in &i.written {
            say(out, format_args!("{verb} {}", f.display()))?;
        }
    }
    for f in &i.removed {
        say(
            out,
            format_args!(
                "removed {} (an earlier install's plugin, not part of this one)",
                f.display()
            ),
        )?;
    }
    for f in &i.others {
        say(
            out,
            format_args!(
                "warning: {} is in the plugins' folder but not part of this install: ballbar loads it too (left as it is)",
                f.display()
            ),
        )?;
    }
    say(
        out,
        format_args!(
            "recorded {} files in {} (what `cargo xtask uninstall` removes)",
            i.listed,
            i.manifest.display()
        ),
    )
}

/// `cargo xtask uninstall [--prefix DIR]`: removes what `install` wrote and the manifest says,
/// if unchanged.
fn uninstall_task(
    args: &[String],
    host: &mut Host<'_>,
    out: &mut dyn Write,
) -> Result<(), Failure> {
    let (prefix, _) = options(args, "--prefix", &[], UNINSTALL_USAGE)?;
    let prefix = prefix_or_home(prefix, host)?;
    let u = uninstall(&prefix).map_err(Failure::Error)?;
    if u.manifest.is_none() {
        say(
            out,
            format_args!(
                "no {}: nothing removed (uninstall removes only the files `cargo xtask install` listed there)",
                manifest(&prefix).display()
            ),
        )?;
    }
    for f in &u.removed {
        say(out, format_args!("removed {}", f.display()))?;
    }
    for f in &u.gone {
        say(out, format_args!("already gone: {}", f.display()))?;
    }
    for (f, why) in &u.kept {
        say(out, format_args!("kept {}: {why}", f.display()))?;
    }
    if let Some(m) = &u.manifest {
        say(out, format_args!("removed {}", m.display()))?;
    }
    for f in &u.folders {
        say(out, format_args!("removed the empty folder {}", f.display()))?;
    }
    Ok(())
}

/// What to put where.
#[derive(Clone, Debug)]
pub struct Install<'a> {
    /// The folder that receives `bin/`, `lib/` and `share/`.
    pub prefix: &'a Path,
    /// The built binary; `None` installs the plugins alone (beside a binary that `cargo install`
    /// put in `prefix/bin`): then neither the binary nor the completions are written or listed.
    pub binary: Option<&'a Path>,
    /// The built plugin libraries (their file names are kept).
    pub plugins: &'a [PathBuf],
    /// Replace files that are already there.
    pub force: bool,
}

/// What [`install`] did.
#[derive(Clone, Debug, Default)]
pub struct Installed {
    /// The files written, in order.
    pub written: Vec<PathBuf>,
    /// The plugin files written (also in `written`).
    pub plugins: Vec<PathBuf>,
    /// Plugin files an earlier install wrote (per its manifest), unchanged since, that this
    /// one does not write: removed, so that the binary does not load them.
    pub removed: Vec<PathBuf>,
    /// Other plugin files in the plugins' folder (a plugin of the user's own, or one changed
    /// since an earlier install wrote it): left, and named, since the binary loads them too.
    pub others: Vec<PathBuf>,
    /// The manifest written.
    pub manifest: PathBuf,
    /// How many files it lists (these and those of earlier installs still there).
    pub listed: usize,
    /// The folders under the prefix that this install created (also listed in the manifest,
    /// with those an earlier install created).
    pub created: Vec<PathBuf>,
}

/// Copy the binary and the plugins into their places, then write the completion scripts by
/// running the installed binary (`ballbar completions SHELL`, which also shows that it runs),
/// and list every file written, with its content hash, in the [`manifest`] (merged with what an
/// earlier install listed and is still there). Every file that would be replaced is checked
/// first: without `force` an existing one, or a plugin file an earlier install wrote that this
/// one does not, is an error naming it, and nothing is written. Each file is written beside its
/// place and renamed over it, so a running `ballbar` is never half-replaced.
pub fn install(i: &Install<'_>) -> Result<Installed, String> {
    let mut copies: Vec<(PathBuf, PathBuf)> = Vec::new();
    if let Some(b) = i.binary {
        copies.push((b.to_path_buf(), binary(i.prefix)));
    }
    let mut plugins = Vec::new();
    for p in i.plugins {
        let name = p.file_name().ok_or_else(|| format!("{}: not a file name", p.display()))?;
        copies.push((p.clone(), plugin_dir(i.prefix).join(name)));
        plugins.push(plugin_dir(i.prefix).join(name));
    }
    let scripts: Vec<(&str, PathBuf)> = if i.binary.is_some() {
        COMPLETIONS.iter().map(|(shell, f)| (*shell, i.prefix.join(f))).collect()
    } else {
        Vec::new()
    };
    for (from, _) in &copies {
        if !from.is_file() {
            return Err(format!("{}: not found (was it built?)", from.display()));
        }
    }
    let targets: Vec<PathBuf> = copies
        .iter()
        .map(|(_, t)| t.clone())
        .chain(scripts.iter().map(|(_, t)| t.clone()))
        .collect();
    for target in &targets {
        may_replace(target, i.force)?;
    }
    let manifest_path = manifest(i.prefix);
    if manifest_path.is_dir() {
        return Err(format!("{}: a folder is in the way", manifest_path.display()));
    }
    // What an earlier install listed: its plugins that this one does not write are replaced
    // (removed, if unchanged); its other files that are still there stay listed.
    let earlier = read_manifest(i.prefix)?.unwrap_or_default();
    let (mut stale, mut kept_entries, mut to_replace) = (Vec::new(), Vec::new(), Vec::new());
    for e in earlier {
        let path = i.prefix.join(&e.path);
        if targets.contains(&path) {
            // Replaced by this install once written; listed as before if it is not.
            to_replace.push(e);
            continue;
        }
        let in_plugin_dir = Path::new(&e.path).parent() == Some(Path::new(PLUGIN_DIR));
        match state(&path, e.hash)? {
            State::Missing => {}
            State::Same if in_plugin_dir => {
                if !i.force {
                    return Err(format!(
                        "{}: a plugin an earlier install wrote, not part of this one; --force removes it",
                        path.display()
                    ));
                }
                stale.push(path);
            }
            // Changed since: no longer the earlier install's file; named below if a plugin.
            _ if in_plugin_dir => {}
            _ => kept_entries.push(e),
        }
    }
    // The folders under the prefix that are not there yet: those the writing creates.
    let mut missing: Vec<PathBuf> = Vec::new();
    for target in targets.iter().chain([&manifest_path]) {
        for folder in target.ancestors().skip(1).take_while(|f| *f != i.prefix) {
            if !folder.exists() && !missing.iter().any(|m| m == folder) {
                missing.push(folder.to_path_buf());
            }
        }
    }
    let mut written = Vec::new();
    let result = write_all(&copies, &scripts, i.prefix, &mut written);
    let mut removed = Vec::new();
    if result.is_ok() {
        for s in stale {
            std::fs::remove_file(&s)
                .map_err(|e| format!("{}: cannot remove it: {e}", s.display()))?;
            removed.push(s);
        }
    }
    // The manifest, even after a failure: what was written is listed, so uninstall removes it,
    // and an earlier install's file this one failed to reach before stopping stays listed.
    let mut entries = kept_entries;
    entries.extend(to_replace.into_iter().filter(|e| !written.contains(&i.prefix.join(&e.path))));
    for f in &written {
        entries.push(Entry { hash: hash_file(f)?, path: relative(i.prefix, f)? });
    }
    let listed = entries.len();
    // The manifest's own folder is created with it.
    let created: Vec<PathBuf> =
        missing.into_iter().filter(|f| f.is_dir() || manifest_path.starts_with(f)).collect();
    let mut folders = read_manifest_folders(i.prefix)?;
    for f in &created {
        let f = relative(i.prefix, f)?;
        if !folders.contains(&f) {
            folders.push(f);
        }
    }
    write_manifest(&manifest_path, &entries, &folders)?;
    result?;
    let dir = plugin_dir(i.prefix);
    let mut others: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(r) => r
            .filter_map(|e| e.ok())
            .filter(|e| is_plugin_file_name(&e.file_name().to_string_lossy()))
            .map(|e| e.path())
            .filter(|p| !written.contains(p))
            .collect(),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(format!("{}: cannot list it: {e}", dir.display())),
    };
    others.sort();
    Ok(Installed { written, plugins, removed, others, manifest: manifest_path, listed, created })
}

/// Write the copies, then the completion scripts from the installed binary, pushing each file
/// written to `written`.
fn write_all(
    copies: &[(PathBuf, PathBuf)],
    scripts: &[(&str, PathBuf)],
    prefix: &Path,
    written: &mut Vec<PathBuf>,
) -> Result<(), String> {
    for (from, to) in copies {
        // `fs::copy` keeps the permissions: the executable bit of the binary and the libraries.
        replace(to, |tmp| std::fs::copy(from, tmp).map(|_| ()))?;
        written.push(to.clone());
    }
    let exe = binary(prefix);
    for (shell, to) in scripts {
        let mut cmd = Command::new(&exe);
        cmd.args(["completions", shell]).env_remove("BALLBAR_PLUGIN_PATH");
        let out = output(&mut cmd).map_err(|e| format!("{}: cannot run it: {e}", exe.display()))?;
        if !out.status.success() || out.stdout.is_empty() {
            return Err(format!(
                "{} completions {shell} failed: {}",
                exe.display(),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        replace(to, |tmp| std::fs::write(tmp, &out.stdout))?;
        written.push(to.clone());
    }
    Ok(())
}

/// The installed binary, run without `BALLBAR_PLUGIN_PATH`, must load every one of `plugins`
/// (not another file of the same plugin name found first): returns its `plugins` listing.
pub fn check(prefix: &Path, plugins: &[PathBuf]) -> Result<String, String> {
    let exe = binary(prefix);
    let run = |args: &[&str]| -> Result<String, String> {
        let mut cmd = Command::new(&exe);
        cmd.args(args).env_remove("BALLBAR_PLUGIN_PATH");
        let out = output(&mut cmd).map_err(|e| format!("{}: cannot run it: {e}", exe.display()))?;
        if !out.status.success() {
            return Err(format!(
                "{} {} failed: {}",
                exe.display(),
                args.join(" "),
                String::from_utf8_lossy(&out.stderr)
            ));
        }
        Ok(String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let listing = run(&["plugins"])?;
    let json = run(&["plugins", "--json"])?;
    // The loaded plugins: the `"plugins"` array, before `"problems"` (the keys are sorted).
    let loaded = json
        .split_once("\"plugins\"")
        .and_then(|(_, r)| r.split_once("\"problems\""))
        .map(|(l, _)| l)
        .ok_or_else(|| format!("{} plugins --json: no plugins list in {json}", exe.display()))?;
    for p in plugins {
        // The binary reports the paths it resolved from its own (resolved) place.
        let resolved = p.canonicalize().map_err(|e| format!("{}: {e}", p.display()))?;
        let quoted = format!(
            "\"path\": \"{}\"",
            resolved.display().to_string().replace('\\', "\\\\").replace('"', "\\\"")
        );
        if !loaded.contains(&quoted) {
            return Err(format!(
                "{} does not load {} (another file of that plugin's name found first, or a problem loading it):\n{listing}",
                exe.display(),
                p.display()
            ));
        }
    }
    Ok(listing.trim_end().to_string())
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

/// What [`uninstall`] did.
#[derive(Clone, Debug, Default)]
pub struct Uninstalled {
    /// The manifest read (and removed, last); `None`: there was none, and nothing was removed.
    pub manifest: Option<PathBuf>,
    /// The files removed: listed, and unchanged.
    pub removed: Vec<PathBuf>,
    /// Listed files that were already gone.
    pub gone: Vec<PathBuf>,
    /// The folders removed, after the manifest: those an install created (its manifest says
    /// which) that were left empty.
    pub folders: Vec<PathBuf>,
    /// Files left, and why: listed but changed since, or in ballbar's places but never listed
    /// (a binary `cargo install` wrote, hand-written completions, a plugin of the user's own).
    pub kept: Vec<(PathBuf, String)>,
}

/// Remove what [`install`] wrote under `prefix`: the files its [`manifest`] lists whose content
/// is still what was written, then the manifest, then the folders an install created (the
/// manifest lists them), the plugins' folder and `lib/ballbar`, where that left them empty. Anything else stays, named. Without a manifest nothing is removed.
pub fn uninstall(prefix: &Path) -> Result<Uninstalled, String> {
    let mut u = Uninstalled::default();
    let entries = read_manifest(prefix)?;
    let listed: Vec<PathBuf> = entries.iter().flatten().map(|e| prefix.join(&e.path)).collect();
    if let Some(entries) = &entries {
        for e in entries {
            let path = prefix.join(&e.path);
            match state(&path, e.hash)? {
                State::Same => {
                    std::fs::remove_file(&path)
                        .map_err(|err| format!("{}: cannot remove it: {err}", path.display()))?;
                    u.removed.push(path);
                }
                State::Missing => u.gone.push(path),
                State::Changed => u.kept.push((path, "changed since install wrote it".into())),
                State::NotAFile => u.kept.push((
                    path,
                    "no longer the file install wrote (now a link or a folder)".into(),
                )),
            }
        }
    }
    // Ballbar's places holding files install did not write.
    let mut places = vec![binary(prefix)];
    places.extend(COMPLETIONS.iter().map(|(_, f)| prefix.join(f)));
    let dir = plugin_dir(prefix);
    let mut in_dir: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|r| r.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    in_dir.sort();
    places.extend(in_dir);
    for p in places {
        if !listed.contains(&p) && std::fs::symlink_metadata(&p).is_ok() {
            let why = if entries.is_some() {
                "not written by `cargo xtask install` (not in its manifest)"
            } else {
                "no manifest says `cargo xtask install` wrote it"
            };
            u.kept.push((p, why.into()));
        }
    }
    if entries.is_some() {
        let folders = read_manifest_folders(prefix)?;
        let m = manifest(prefix);
        std::fs::remove_file(&m).map_err(|e| format!("{}: cannot remove it: {e}", m.display()))?;
        u.manifest = Some(m);
        // The folders an install created, deepest first, where that left them empty
        // (`remove_dir` refuses any other); the plugins' folder and `lib/ballbar` too, which a
        // manifest written before it listed folders does not name.
        let mut folders: Vec<PathBuf> = folders.iter().map(|f| prefix.join(f)).collect();
        for f in [dir, prefix.join("lib/ballbar")] {
            if !folders.contains(&f) {
                folders.push(f);
            }
        }
        folders.sort_by_key(|f| std::cmp::Reverse(f.components().count()));
        for f in folders {
            if std::fs::remove_dir(&f).is_ok() {
                u.folders.push(f);
            }
        }
    }
    Ok(u)
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
///
/// The file, and each folder created for it, is made writable by its owner alone, whatever the
/// umask or the build's modes: the installed binary loads plugins only from files and folders
/// that nobody but the user or root can change (`docs/plugins.md`).
fn replace(target: &Path, write: impl FnOnce(&Path) -> std::io::Result<()>) -> Result<(), String> {
    let dir = target.parent().ok_or_else(|| format!("{}: no folder", target.display()))?;
    let missing: Vec<PathBuf> =
        dir.ancestors().take_while(|p| !p.exists()).map(Path::to_path_buf).collect();
    std::fs::create_dir_all(dir)
        .and_then(|()| missing.iter().try_for_each(|p| owner_writes_alone(p)))
        .map_err(|e| format!("{}: cannot create the folder: {e}", dir.display()))?;
    let name = target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = write(&tmp)
        .and_then(|()| owner_writes_alone(&tmp))
        .and_then(|()| std::fs::rename(&tmp, target));
    result.map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        format!("{}: cannot write it: {e}", target.display())
    })
}

/// Take the write permission of group and others off `path`.
#[cfg(unix)]
fn owner_writes_alone(path: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::PermissionsExt as _;
    let mode = std::fs::metadata(path)?.permissions().mode();
    if mode & 0o022 == 0 {
        return Ok(());
    }
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode & !0o022))
}

/// Elsewhere than Unix, plugins are loaded as found: nothing to take off.
#[cfg(not(unix))]
fn owner_writes_alone(_path: &Path) -> std::io::Result<()> {
    Ok(())
}

/// FNV-1a, 64 bits, of `bytes` continuing from `hash` (start with [`FNV_OFFSET`]): a content
/// check against accidental change (an edited script, another binary), not against an attacker.
pub fn fnv1a64(mut hash: u64, bytes: &[u8]) -> u64 {
    for b in bytes {
        hash ^= u64::from(*b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

/// FNV-1a 64's starting value.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// The FNV-1a 64 hash of a file's content.
pub fn hash_file(path: &Path) -> Result<u64, String> {
    let mut f = std::fs::File::open(path)
        .map_err(|e| format!("{}: cannot read it: {e}", path.display()))?;
    let (mut hash, mut buf) = (FNV_OFFSET, vec![0u8; 1 << 16]);
    loop {
        let n = f.read(&mut buf).map_err(|e| format!("{}: cannot read it: {e}", path.display()))?;
        if n == 0 {
            return Ok(hash);
        }
        hash = fnv1a64(hash, &buf[..n]);
    }
}

/// One manifest line: a file's content hash and its path under the prefix (`/`-separated).
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// FNV-1a 64 of the content written.
    pub hash: u64,
    /// The path under the prefix.
    pub path: String,
}

/// A listed file now.
enum State {
    /// A regular file with the content written.
    Same,
    /// Nothing there.
    Missing,
    /// A regular file with other content.
    Changed,
    /// A symbolic link, a folder or another kind of file.
    NotAFile,
}

fn state(path: &Path, hash: u64) -> Result<State, String> {
    match std::fs::symlink_metadata(path) {
        Err(_) => Ok(State::Missing),
        Ok(m) if !m.file_type().is_file() => Ok(State::NotAFile),
        Ok(_) if hash_file(path)? == hash => Ok(State::Same),
        Ok(_) => Ok(State::Changed),
    }
}

/// `file`'s path under `prefix`, `/`-separated.
fn relative(prefix: &Path, file: &Path) -> Result<String, String> {
    let rel = file
        .strip_prefix(prefix)
        .map_err(|_| format!("{}: not under {}", file.display(), prefix.display()))?;
    Ok(rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect::<Vec<_>>()
        .join("/"))
}

const MANIFEST_HEADER: &str = "# ballbar install manifest: each file `cargo xtask install`/`dist` wrote under this prefix, as\n# FNV-1a 64 of its content (16 hex digits), two spaces, its path; then each folder it created, as\n# `folder`, two spaces, its path. `cargo xtask uninstall` removes the files whose content is\n# unchanged, then this file, then the folders that were left empty.\n";

/// Write the manifest (beside, then renamed over): the files, then the folders created.
fn write_manifest(path: &Path, entries: &[Entry], folders: &[String]) -> Result<(), String> {
    let mut text = String::from(MANIFEST_HEADER);
    for e in entries {
        text.push_str(&format!("{:016x}  {}\n", e.hash, e.path));
    }
    for f in folders {
        text.push_str(&format!("{FOLDER_TAG}  {f}\n"));
    }
    replace(path, |tmp| std::fs::write(tmp, text))
}

/// The folders the manifest under `prefix` says an install created (none without a
/// manifest), paths under the prefix.
pub fn read_manifest_folders(prefix: &Path) -> Result<Vec<String>, String> {
    Ok(read_manifest_lines(prefix)?.map(|(_, folders)| folders).unwrap_or_default())
}

/// The manifest under `prefix`, `None` if there is none; a malformed line is an error naming
/// the file and the line, and so is a path that leaves the prefix.
pub fn read_manifest(prefix: &Path) -> Result<Option<Vec<Entry>>, String> {
    Ok(read_manifest_lines(prefix)?.map(|(files, _)| files))
}

/// The manifest's files and folders.
fn read_manifest_lines(prefix: &Path) -> Result<Option<(Vec<Entry>, Vec<String>)>, String> {
    let path = manifest(prefix);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("{}: cannot read it: {e}", path.display())),
    };
    let (mut entries, mut folders) = (Vec::new(), Vec::new());
    for (n, line) in text.lines().enumerate() {
        if line.trim().is_empty() || line.starts_with('#') {
            continue;
        }
        let bad = |what: &str| {
            format!(
                "{}:{}: {what}: '{line}' (expected 16 hex digits or `{FOLDER_TAG}`, two spaces, a path under the prefix)",
                path.display(),
                n + 1
            )
        };
        let (hex, file) = line.split_once("  ").ok_or_else(|| bad("no two spaces"))?;
        let inside = !file.is_empty()
            && Path::new(file).components().all(|c| matches!(c, Component::Normal(_)));
        if hex == FOLDER_TAG {
            if !inside {
                return Err(bad("not a path under the prefix"));
            }
            folders.push(file.to_string());
            continue;
        }
        let hash = (hex.len() == 16)
            .then(|| u64::from_str_radix(hex, 16).ok())
            .flatten()
            .ok_or_else(|| bad("not a 16-digit hex hash"))?;
        if !inside {
            return Err(bad("not a path under the prefix"));
        }
        entries.push(Entry { hash, path: file.to_string() });
    }
    Ok(Some((entries, folders)))
}

//! Finds, checks and loads machine plugins (the C ABI of `ballbar-plugin-api`), and wraps each
//! at once in safe types that implement the model's traits ([`Plugin`] is a
//! `ballbar_model::KernelSource`; its kernels are `ballbar_model::BasisKernel`s). Nothing outside
//! this crate sees a raw pointer.
//!
//! # Search order
//! 1. `--plugin FILE` (given by the caller, any file name);
//! 2. the paths in `BALLBAR_PLUGIN_PATH` (files, or folders searched for plugin files);
//! 3. the folder of the executable (so `target/release/ballbar` finds the plugins that
//!    `cargo build --release --workspace` put beside it);
//! 4. [`INSTALLED_PLUGIN_DIR`] under the executable folder's parent: the installed layout, in
//!    which `PREFIX/bin/ballbar` finds `PREFIX/lib/ballbar/plugins/` (what `cargo xtask dist`
//!    and `cargo xtask install` lay out). Relative to the executable, so an installed tree
//!    works wherever it is put, and a plugin beside the binary still comes first.
//!
//! In a folder, a plugin file is a shared library whose name (without a `lib` prefix) starts
//! with `ballbar_machine_`. The first plugin of a name wins; later ones of the same name are
//! reported as shadowed.
//!
//! # Who may have written a plugin
//! Loading a library runs its code (its initialisers run inside `dlopen`, before any check of
//! what it declares), with the user's rights. So, as ssh treats its keys (`StrictModes`), a
//! plugin is loaded only when nobody but the user or root can have put it there or changed it
//! (Unix; elsewhere files are loaded as found): the file (its symbolic links resolved) and its
//! folder must be owned by the user or root and not writable by others, nor by a group with any
//! member but the owner (a user's private group is fine, as Debian's ssh allows), and so must
//! every folder above them, except that a folder above may be writable by others when its
//! sticky bit keeps them from renaming what they do not own (`/tmp`). A searched folder that
//! fails is refused whole, and no file in it is opened; a file that fails is not opened.
//! Both are recorded in [`Registry::refused`], with why and how to fix it; a `--plugin FILE`
//! that fails is an error ([`PluginError::Untrusted`]). The checked, resolved path is the one
//! loaded.
//!
//! # Checks, in order
//! The ownership and modes above; then the file loads as a library; it exports `ballbar_plugin_declaration`; the declaration's
//! ABI version (read first, on its own) is ours; its struct size is at least ours; name and
//! version are UTF-8 of sane length; the kernel table is readable. Only then is any function
//! called, and every call's failure or caught panic is an error naming the file.
//!
//! # Lifetime
//! A loaded library is never unloaded: its handle is leaked on purpose, so that the kernels,
//! strings and functions taken from it stay valid for the life of the process.

// This crate is the host side of the FFI boundary. Each unsafe block states why it holds.
#![allow(unsafe_code)]

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use ballbar_model::chain::ErrorMotion;
use ballbar_model::machine::MachineSpec;
use ballbar_model::{BasisKernel, JointState, KernelSource};
use ballbar_plugin_api as api;

/// Longest name or version string accepted from a declaration.
const MAX_NAME_LEN: usize = 256;

/// Most kernels a declaration may list (a sanity bound on a number read from a library).
const MAX_KERNELS: usize = 4096;

/// Errors of finding, loading and calling plugins. Every variant names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PluginError {
    /// The file is not a loadable library.
    #[error("{}: cannot be loaded as a plugin library: {message}", path.display())]
    NotALibrary {
        /// The file.
        path: PathBuf,
        /// The loader's message.
        message: String,
    },
    /// The library has no declaration symbol.
    #[error("{}: not a ballbar machine plugin: it exports no symbol '{}' (declare it with ballbar-plugin-api's declare_plugin!)", path.display(), api::DECLARATION_SYMBOL)]
    MissingSymbol {
        /// The file.
        path: PathBuf,
    },
    /// The plugin was built for another ABI version.
    #[error("{}: the plugin speaks ABI version {found}, this ballbar reads version {expected}: rebuild the plugin against ballbar-plugin-api with ABI {expected}", path.display())]
    AbiMismatch {
        /// The file.
        path: PathBuf,
        /// The plugin's version.
        found: u32,
        /// Ours.
        expected: u32,
    },
    /// The declaration is not well formed.
    #[error("{}: the plugin's declaration is malformed: {message}", path.display())]
    BadDeclaration {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A call into the plugin returned an error.
    #[error("{}: plugin '{plugin}' failed in {call}: {message}", path.display())]
    Failed {
        /// The file.
        path: PathBuf,
        /// The plugin's name.
        plugin: String,
        /// Which function.
        call: &'static str,
        /// The plugin's message.
        message: String,
    },
    /// The plugin panicked inside a call (caught there; the process goes on).
    #[error("{}: plugin '{plugin}' panicked in {call}: {message}", path.display())]
    Panicked {
        /// The file.
        path: PathBuf,
        /// The plugin's name.
        plugin: String,
        /// Which function.
        call: &'static str,
        /// The panic message.
        message: String,
    },
    /// The plugin's machine description is not a valid description.
    #[error("{}: plugin '{plugin}' returned a machine description that is not valid (its line {line}, column {column}): {message}", path.display())]
    MalformedDescription {
        /// The file.
        path: PathBuf,
        /// The plugin's name.
        plugin: String,
        /// Line in the returned text.
        line: usize,
        /// Column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// A user's machine file is wrong.
    #[error("{}:{line}:{column}: {message}", file.display())]
    MachineFile {
        /// The machine file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// The file, or a folder it is in, could have been written by someone other than the user or
    /// root: it is not loaded (see the crate's docs, "Who may have written a plugin").
    #[error("{}: refused to load this plugin: {reason}. A plugin runs with your rights, so nobody but you or root may be able to change it or the folders it is in: {fix}", path.display())]
    Untrusted {
        /// The plugin file as given.
        path: PathBuf,
        /// Which file or folder fails, and how (its owner, its mode).
        reason: String,
        /// How to make it loadable, if it is to be trusted.
        fix: String,
    },
    /// A path on `BALLBAR_PLUGIN_PATH` does not exist.
    #[error("{}: on BALLBAR_PLUGIN_PATH, but no such file or folder", path.display())]
    NoSuchPath {
        /// The path.
        path: PathBuf,
    },
    /// A machine file could not be read.
    #[error("{}: {error}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The OS error.
        error: std::io::Error,
    },
}

/// A loaded, checked plugin.
#[derive(Debug)]
pub struct Plugin {
    path: PathBuf,
    name: String,
    version: String,
    flags: u32,
    abi_version: u32,
    fns: Functions,
    kernels: Vec<String>,
}

/// A checked declaration's functions (none of them null).
#[derive(Clone, Copy, Debug)]
struct Functions {
    describe: api::DescribeFn,
    evaluate: api::EvaluateFn,
    free_buffer: api::FreeFn,
}

/// Read a string field of a declaration.
///
/// # Safety
/// `s` comes from a declaration that passed the version and size checks.
unsafe fn read_str(s: &api::StrRef, what: &str, path: &Path) -> Result<String, PluginError> {
    // SAFETY: the plugin's contract: a 'static string of `len` bytes.
    let bytes = unsafe { s.bytes(MAX_NAME_LEN) }.map_err(|m| PluginError::BadDeclaration {
        path: path.to_path_buf(),
        message: format!("{what}: {m}"),
    })?;
    let text = std::str::from_utf8(bytes).map_err(|_| PluginError::BadDeclaration {
        path: path.to_path_buf(),
        message: format!("{what} is not UTF-8"),
    })?;
    if text.is_empty() {
        return Err(PluginError::BadDeclaration {
            path: path.to_path_buf(),
            message: format!("{what} is empty"),
        });
    }
    Ok(text.to_string())
}

impl Plugin {
    /// Load and check the plugin in `path`: who may have written it first (nothing of a file
    /// that fails is opened), then the library and its declaration.
    pub fn load(path: &Path) -> Result<Plugin, PluginError> {
        let real = trust::check(path, trust::Checked::File).map_err(|e| match e {
            trust::Failure::Unresolved(error) => {
                PluginError::NotALibrary { path: path.to_path_buf(), message: error.to_string() }
            }
            trust::Failure::Distrusted { reason, fix } => {
                PluginError::Untrusted { path: path.to_path_buf(), reason, fix }
            }
        })?;
        let path = path.to_path_buf();
        // SAFETY: loading a library runs its initialisers. A plugin is code the user chose to
        // install, in a file and folders nobody else can have changed (checked just above, on
        // the resolved path loaded here); Rust cdylibs have no initialisers of their own. This
        // is the trust boundary.
        let lib = unsafe { libloading::Library::new(&real) }
            .map_err(|e| PluginError::NotALibrary { path: path.clone(), message: e.to_string() })?;
        // Never unloaded: everything taken from it below lives as long as the process.
        let lib: &'static libloading::Library = Box::leak(Box::new(lib));
        // SAFETY: the symbol, if present, is the address of the plugin's static declaration.
        // It is read as raw bytes first: the version and the size, before any other field.
        let sym = unsafe { lib.get::<*const u8>(api::DECLARATION_SYMBOL.as_bytes()) }
            .map_err(|_| PluginError::MissingSymbol { path: path.clone() })?;
        let base: *const u8 = *sym;
        if base.is_null() {
            return Err(PluginError::BadDeclaration {
                path,
                message: "the declaration's address is null".into(),
            });
        }
        // SAFETY: a declaration of any version begins with two u32 (version, size); read them
        // unaligned, without assuming the rest of the layout.
        let (abi_version, struct_size) = unsafe {
            (base.cast::<u32>().read_unaligned(), base.add(4).cast::<u32>().read_unaligned())
        };
        if abi_version != api::ABI_VERSION {
            return Err(PluginError::AbiMismatch {
                path,
                found: abi_version,
                expected: api::ABI_VERSION,
            });
        }
        if struct_size < api::DECLARATION_SIZE {
            return Err(PluginError::BadDeclaration {
                path,
                message: format!(
                    "declared size {struct_size} bytes, ABI {} needs at least {}",
                    api::ABI_VERSION,
                    api::DECLARATION_SIZE
                ),
            });
        }
        if base.align_offset(std::mem::align_of::<api::PluginDeclaration>()) != 0 {
            return Err(PluginError::BadDeclaration {
                path,
                message: "the declaration is not aligned".into(),
            });
        }
        // SAFETY: version and size match this crate's layout, the address is aligned, and the
        // static lives as long as the (never unloaded) library.
        let decl: &'static api::PluginDeclaration =
            unsafe { &*base.cast::<api::PluginDeclaration>() };
        // SAFETY: fields of a checked declaration.
        let name = unsafe { read_str(&decl.name, "name", &path)? };
        // SAFETY: as above.
        let version = unsafe { read_str(&decl.version, "version", &path)? };
        if decl.joint_state_size != api::JOINT_STATE_SIZE {
            return Err(PluginError::BadDeclaration {
                path,
                message: format!(
                    "joint states of {} bytes, this ballbar passes {}: rebuild the plugin against this ballbar-plugin-api",
                    decl.joint_state_size,
                    api::JOINT_STATE_SIZE
                ),
            });
        }
        let (Some(describe), Some(evaluate), Some(free_buffer)) =
            (decl.describe, decl.evaluate, decl.free_buffer)
        else {
            return Err(PluginError::BadDeclaration {
                path,
                message: "a null function in the declaration (describe, evaluate or free_buffer)"
                    .into(),
            });
        };
        if decl.kernel_count > 0
            && decl.kernels.align_offset(std::mem::align_of::<api::KernelDeclaration>()) != 0
        {
            return Err(PluginError::BadDeclaration {
                path,
                message: "the kernel table is not aligned".into(),
            });
        }
        if decl.kernel_count > MAX_KERNELS || (decl.kernel_count > 0 && decl.kernels.is_null()) {
            return Err(PluginError::BadDeclaration {
                path,
                message: format!(
                    "kernel table of {} entries at {:?}",
                    decl.kernel_count, decl.kernels
                ),
            });
        }
        let mut kernels = Vec::with_capacity(decl.kernel_count);
        for k in 0..decl.kernel_count {
            // SAFETY: `kernel_count` declarations at `kernels`, checked non-null above.
            let kd = unsafe { &*decl.kernels.add(k) };
            // SAFETY: a field of a checked declaration.
            kernels.push(unsafe { read_str(&kd.name, "kernel name", &path)? });
        }
        Ok(Plugin {
            path,
            name,
            version,
            flags: decl.flags,
            abi_version: decl.abi_version,
            fns: Functions { describe, evaluate, free_buffer },
            kernels,
        })
    }

    /// The file it was loaded from.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The machine type's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The plugin's version.
    pub fn version(&self) -> &str {
        &self.version
    }

    /// The ABI version (equal to [`api::ABI_VERSION`] for a loaded plugin).
    pub fn abi_version(&self) -> u32 {
        self.abi_version
    }

    /// True when the plugin builds machines from user files (`--machine-file`).
    pub fn reads_machine_files(&self) -> bool {
        self.flags & api::FLAG_MACHINE_FILE != 0
    }

    /// The kernels the plugin declares.
    pub fn kernel_names(&self) -> &[String] {
        &self.kernels
    }

    /// Take a plugin-allocated buffer as text and free it with the plugin's own function.
    fn take(&self, buf: api::OwnedBuffer) -> String {
        if buf.ptr.is_null() {
            return String::new();
        }
        // SAFETY: the plugin filled the buffer with `len` bytes; bounded for a sane message.
        let text = unsafe {
            String::from_utf8_lossy(std::slice::from_raw_parts(buf.ptr, buf.len.min(1 << 30)))
                .into_owned()
        };
        // SAFETY: freed once, by the plugin that allocated it.
        unsafe { (self.fns.free_buffer)(buf) };
        text
    }

    /// Call `describe` with `input`.
    fn describe(&self, input: &str) -> Result<String, PluginError> {
        let mut out = api::OwnedBuffer::EMPTY;
        // SAFETY: the input outlives the call; `out` is a valid place for the result.
        let status = unsafe { (self.fns.describe)(api::StrRef::borrowed(input), &mut out) };
        let text = self.take(out);
        match status {
            api::STATUS_OK => Ok(text),
            api::STATUS_PANIC => Err(PluginError::Panicked {
                path: self.path.clone(),
                plugin: self.name.clone(),
                call: "describe",
                message: text,
            }),
            api::STATUS_ERROR => Err(PluginError::Failed {
                path: self.path.clone(),
                plugin: self.name.clone(),
                call: "describe",
                message: text,
            }),
            other => Err(PluginError::Failed {
                path: self.path.clone(),
                plugin: self.name.clone(),
                call: "describe",
                message: format!("unknown status {other}: {text}"),
            }),
        }
    }

    fn parse(&self, ron_text: &str) -> Result<MachineSpec, PluginError> {
        ron::from_str(ron_text).map_err(|e| PluginError::MalformedDescription {
            path: self.path.clone(),
            plugin: self.name.clone(),
            line: e.span.start.line,
            column: e.span.start.col,
            message: e.code.to_string(),
        })
    }

    /// The plugin's machine description.
    pub fn machine(&self) -> Result<MachineSpec, PluginError> {
        let text = self.describe("")?;
        self.parse(&text)
    }

    /// A machine built by this plugin from the user's machine file `file`. The plugin's
    /// messages of the form `LINE:COLUMN: what` become errors at that place of the file.
    pub fn machine_from_file(&self, file: &Path) -> Result<MachineSpec, PluginError> {
        let text = std::fs::read_to_string(file)
            .map_err(|error| PluginError::Io { file: file.to_path_buf(), error })?;
        let ron_text = self.describe(&text).map_err(|e| match e {
            PluginError::Failed { message, .. } => located(file, &message),
            other => other,
        })?;
        self.parse(&ron_text)
    }
}

/// Who may have written a plugin file or folder (the crate's docs, "Who may have written a
/// plugin").
mod trust {
    use std::path::{Path, PathBuf};

    /// What is checked: a plugin file (the file and its folder strictly), or a searched folder
    /// (the folder strictly); the folders above either may be sticky and writable by others.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum Checked {
        File,
        Folder,
    }

    /// Why a path is not loaded from.
    #[derive(Debug)]
    pub enum Failure {
        /// The path could not be resolved (it does not exist, a link leads nowhere, ...).
        Unresolved(std::io::Error),
        /// A file or folder could have been changed by someone other than the user or root.
        Distrusted {
            /// Which one, and how.
            reason: String,
            /// How to make it loadable.
            fix: String,
        },
    }

    /// The path resolved (symbolic links followed), if the user or root alone can have
    /// written it and the folders it is in.
    #[cfg(unix)]
    pub fn check(path: &Path, what: Checked) -> Result<PathBuf, Failure> {
        use std::os::unix::fs::MetadataExt;
        unsafe extern "C" {
            // POSIX, in the C library every Unix program links; it cannot fail.
            fn geteuid() -> u32;
        }
        // SAFETY: geteuid takes nothing, touches no memory of ours, and always succeeds.
        let uid = unsafe { geteuid() };
        let real = std::fs::canonicalize(path).map_err(Failure::Unresolved)?;
        let strict = match what {
            Checked::File => 2,
            Checked::Folder => 1,
        };
        for (level, p) in real.ancestors().enumerate() {
            let meta = std::fs::metadata(p).map_err(Failure::Unresolved)?;
            let name = match (level, what) {
                (0, Checked::File) => "the plugin file",
                (0, Checked::Folder) => "the plugin folder",
                (1, Checked::File) => "its folder",
                _ => "the folder above it",
            };
            let owner = meta.uid();
            if owner != uid && owner != 0 {
                return Err(Failure::Distrusted {
                    reason: format!(
                        "{name} {} belongs to uid {owner}, not to you (uid {uid}) or root",
                        p.display()
                    ),
                    fix: format!(
                        "if you trust it, make it yours (`chown {uid} {}`, as root) or copy the plugin into a folder of your own",
                        p.display()
                    ),
                });
            }
            let mode = meta.mode() & 0o7777;
            // Sticky: others may add entries but not rename or remove ours.
            let sticky_above = level >= strict && meta.is_dir() && mode & 0o1000 != 0;
            // A group whose one member is the owner (a user's private group, where a umask
            // of 002 leaves files group-writable) adds no one who could write.
            let group = mode & 0o020 != 0 && !private_group(meta.gid(), owner, &Accounts::read());
            let others = mode & 0o002 != 0;
            if (group || others) && !sticky_above {
                let who = match (group, others) {
                    (true, true) => "its group and others",
                    (true, false) => "its group",
                    _ => "others",
                };
                let members = if group && !others {
                    format!("; group {} has members other than its owner", meta.gid())
                } else {
                    String::new()
                };
                return Err(Failure::Distrusted {
                    reason: format!(
                        "{name} {} is writable by {who} (mode {mode:04o}{members})",
                        p.display()
                    ),
                    fix: format!("if you trust it, `chmod go-w {}`", p.display()),
                });
            }
        }
        Ok(real)
    }

    /// The local account files, `/etc/passwd` and `/etc/group` (empty when unreadable: then
    /// no group counts as private).
    #[cfg(unix)]
    pub struct Accounts {
        pub passwd: String,
        pub group: String,
    }

    #[cfg(unix)]
    impl Accounts {
        pub fn read() -> Accounts {
            let read = |p: &str| std::fs::read_to_string(p).unwrap_or_default();
            Accounts { passwd: read("/etc/passwd"), group: read("/etc/group") }
        }
    }

    /// Whether the group `gid` has exactly one member, the user `owner`: every account whose
    /// primary group it is is `owner`, and its member list is empty or `owner`'s name alone (as
    /// Debian's ssh allows group-writable keys). A group not in the local files is not private.
    #[cfg(unix)]
    pub fn private_group(gid: u32, owner: u32, accounts: &Accounts) -> bool {
        let fields = |text: &str| -> Vec<Vec<String>> {
            text.lines()
                .filter(|l| !l.starts_with('#'))
                .map(|l| l.split(':').map(str::to_string).collect::<Vec<_>>())
                .filter(|f| f.len() >= 4)
                .collect()
        };
        let Some(group) = fields(&accounts.group)
            .into_iter()
            .find(|f| f[2].parse::<u32>().is_ok_and(|g| g == gid))
        else {
            return false;
        };
        let users = fields(&accounts.passwd);
        let mut members = 0;
        for u in &users {
            if u[3].parse::<u32>().is_ok_and(|g| g == gid) {
                members += 1;
                if u[2].parse::<u32>().ok() != Some(owner) {
                    return false;
                }
            }
        }
        let listed: Vec<&str> =
            group[3].split(',').map(str::trim).filter(|m| !m.is_empty()).collect();
        if let Some(first) = listed.first() {
            members += 1;
            let owner_name =
                users.iter().find(|u| u[2].parse::<u32>().ok() == Some(owner)).map(|u| &u[0]);
            if listed.len() > 1 || owner_name.is_none_or(|n| n != first) {
                return false;
            }
        }
        members > 0
    }

    /// Elsewhere than Unix, files are loaded as found (resolved, so that the file checked to
    /// exist is the file loaded).
    #[cfg(not(unix))]
    pub fn check(path: &Path, _what: Checked) -> Result<PathBuf, Failure> {
        std::fs::metadata(path).map_err(Failure::Unresolved)?;
        Ok(path.to_path_buf())
    }
}

/// A plugin's `LINE:COLUMN: message` as an error at that place of `file`.
fn located(file: &Path, message: &str) -> PluginError {
    let mut parts = message.splitn(3, ':');
    let (l, c, rest) = (parts.next(), parts.next(), parts.next());
    match (l.and_then(|x| x.trim().parse().ok()), c.and_then(|x| x.trim().parse().ok()), rest) {
        (Some(line), Some(column), Some(rest)) => PluginError::MachineFile {
            file: file.to_path_buf(),
            line,
            column,
            message: rest.trim().to_string(),
        },
        _ => PluginError::MachineFile {
            file: file.to_path_buf(),
            line: 1,
            column: 1,
            message: message.to_string(),
        },
    }
}

/// A plugin's kernel as a [`BasisKernel`].
#[derive(Debug)]
struct PluginKernel {
    fns: Functions,
    index: usize,
    path: PathBuf,
    plugin: String,
}

impl BasisKernel for PluginKernel {
    fn evaluate(&self, states: &[JointState], out: &mut [ErrorMotion]) -> Result<(), String> {
        debug_assert_eq!(states.len(), out.len(), "a kernel fills one output per state");
        let n = states.len().min(out.len());
        let raw: Vec<api::RawJointState> = states[..n]
            .iter()
            .map(|s| api::RawJointState {
                q: s.q,
                velocity: s.velocity,
                direction: s.direction,
                t_s: s.t_s,
                feed_mm_per_s: s.feed_mm_per_s,
                since_reversal_s: s.since_reversal_s,
                session_t_s: s.session_t_s,
            })
            .collect();
        let mut message = api::OwnedBuffer::EMPTY;
        // SAFETY: `n` states and `6 n` doubles (`[f64; 6]` is six packed f64), both owned by us
        // and alive for the call; `message` is a valid place for the plugin's buffer.
        let status = unsafe {
            (self.fns.evaluate)(
                self.index,
                raw.as_ptr(),
                n,
                out.as_mut_ptr().cast::<f64>(),
                &mut message,
            )
        };
        let text = if message.ptr.is_null() {
            String::new()
        } else {
            // SAFETY: the plugin filled `len` bytes; freed once below by the plugin itself.
            let t = unsafe {
                String::from_utf8_lossy(std::slice::from_raw_parts(
                    message.ptr,
                    message.len.min(1 << 20),
                ))
                .into_owned()
            };
            // SAFETY: as above.
            unsafe { (self.fns.free_buffer)(message) };
            t
        };
        match status {
            api::STATUS_OK => {
                match out[..n].iter().position(|e| e.iter().any(|x| !x.is_finite())) {
                    None => Ok(()),
                    Some(k) => Err(format!(
                        "plugin '{}' ({}) returned a non-finite value at batch index {k}",
                        self.plugin,
                        self.path.display()
                    )),
                }
            }
            api::STATUS_PANIC => {
                Err(format!("plugin '{}' ({}) panicked: {text}", self.plugin, self.path.display()))
            }
            _ => Err(format!("plugin '{}' ({}): {text}", self.plugin, self.path.display())),
        }
    }
}

impl KernelSource for Plugin {
    fn kernel(&self, name: &str) -> Option<Arc<dyn BasisKernel>> {
        let index = self.kernels.iter().position(|k| k == name)?;
        Some(Arc::new(PluginKernel {
            fns: self.fns,
            index,
            path: self.path.clone(),
            plugin: self.name.clone(),
        }))
    }
}

/// The installed plugins' folder, relative to the parent of the executable's folder:
/// `PREFIX/bin/ballbar` looks in `PREFIX/lib/ballbar/plugins`.
pub const INSTALLED_PLUGIN_DIR: &str = "lib/ballbar/plugins";

/// The installed plugins' folder of an executable in `exe_dir` (`exe_dir/../lib/ballbar/plugins`),
/// if that folder has a parent.
pub fn installed_plugin_dir(exe_dir: &Path) -> Option<PathBuf> {
    exe_dir.parent().map(|prefix| prefix.join(INSTALLED_PLUGIN_DIR))
}

/// Where plugins were looked for, in order.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchPlace {
    /// How the place was given (`--plugin`, `BALLBAR_PLUGIN_PATH`, `executable folder`,
    /// `installed plugins folder`).
    pub source: &'static str,
    /// The file or folder.
    pub path: PathBuf,
}

/// What to search.
#[derive(Clone, Debug, Default)]
pub struct Search {
    /// `--plugin FILE`s: loaded whatever their names; a failure is an error.
    pub explicit: Vec<PathBuf>,
    /// The value of `BALLBAR_PLUGIN_PATH`.
    pub env_path: Option<OsString>,
    /// The folder of the executable (searched, then its [`installed_plugin_dir`]).
    pub exe_dir: Option<PathBuf>,
}

impl Search {
    /// The usual search: `explicit`, then `BALLBAR_PLUGIN_PATH`, then the executable's folder,
    /// then the installed plugins' folder beside it.
    pub fn from_environment(explicit: &[PathBuf]) -> Search {
        Search {
            explicit: explicit.to_vec(),
            env_path: std::env::var_os("BALLBAR_PLUGIN_PATH").filter(|v| !v.is_empty()),
            exe_dir: std::env::current_exe().ok().and_then(|p| p.parent().map(Path::to_path_buf)),
        }
    }
}

/// True for a file name that a folder search takes as a plugin.
pub fn is_plugin_file_name(name: &str) -> bool {
    let stem = name.strip_prefix("lib").unwrap_or(name);
    let ext_ok = [".so", ".dylib", ".dll"].iter().any(|e| stem.ends_with(e));
    stem.starts_with("ballbar_machine_") && ext_ok
}

/// A plugin file or searched folder not loaded from because someone other than the user or
/// root could have written it (the crate's docs, "Who may have written a plugin").
#[derive(Clone, Debug, PartialEq)]
pub struct Refused {
    /// The plugin file or the searched folder, as found.
    pub path: PathBuf,
    /// True for a folder: none of its files was opened.
    pub folder: bool,
    /// Where it was found (a [`SearchPlace::source`]).
    pub source: &'static str,
    /// Which file or folder fails (it, or a folder it is in), and how.
    pub reason: String,
    /// How to make it loadable, if it is to be trusted.
    pub fix: String,
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (what, outcome) = if self.folder {
            ("plugin folder", "no file in it was opened")
        } else {
            ("plugin file", "it was not opened")
        };
        write!(
            f,
            "refused the {what} {} ({}): {}; {outcome} ({})",
            self.path.display(),
            self.source,
            self.reason,
            self.fix
        )
    }
}

/// The plugins found, the problems met, and where they were looked for.
#[derive(Debug, Default)]
pub struct Registry {
    /// Loaded plugins, in search order, one per name.
    pub plugins: Vec<Arc<Plugin>>,
    /// Plugin files found in folders that failed to load (reported, not fatal).
    pub problems: Vec<PluginError>,
    /// Plugin files and folders not loaded from: someone other than the user or root could have
    /// written them (reported, not fatal).
    pub refused: Vec<Refused>,
    /// Plugins not used because an earlier one has the same name: (file, name).
    pub shadowed: Vec<(PathBuf, String)>,
    /// The places searched, in order.
    pub searched: Vec<SearchPlace>,
}

impl Registry {
    /// Search in order. A `--plugin` file that fails is an error; a failing file found in a
    /// folder is recorded in [`Registry::problems`].
    pub fn discover(search: &Search) -> Result<Registry, PluginError> {
        let mut reg = Registry::default();
        for p in &search.explicit {
            reg.searched.push(SearchPlace { source: "--plugin", path: p.clone() });
            let plugin = Plugin::load(p)?;
            reg.add(plugin);
        }
        if let Some(v) = &search.env_path {
            let source = "BALLBAR_PLUGIN_PATH";
            for p in std::env::split_paths(v) {
                reg.searched.push(SearchPlace { source, path: p.clone() });
                if p.is_dir() {
                    reg.scan(&p, source);
                } else if p.is_file() {
                    reg.load_found(&p, source);
                } else {
                    reg.problems.push(PluginError::NoSuchPath { path: p });
                }
            }
        }
        if let Some(d) = &search.exe_dir {
            let source = "executable folder";
            reg.searched.push(SearchPlace { source, path: d.clone() });
            reg.scan(d, source);
            if let Some(installed) = installed_plugin_dir(d) {
                let source = "installed plugins folder";
                reg.searched.push(SearchPlace { source, path: installed.clone() });
                reg.scan(&installed, source);
            }
        }
        Ok(reg)
    }

    /// Load a plugin file found in a search; a failure is recorded, not returned.
    fn load_found(&mut self, file: &Path, source: &'static str) {
        match Plugin::load(file) {
            Ok(p) => self.add(p),
            Err(PluginError::Untrusted { path, reason, fix }) => {
                self.refused.push(Refused { path, folder: false, source, reason, fix });
            }
            Err(e) => self.problems.push(e),
        }
    }

    fn add(&mut self, plugin: Plugin) {
        if self.plugins.iter().any(|p| p.name == plugin.name) {
            self.shadowed.push((plugin.path, plugin.name));
        } else {
            self.plugins.push(Arc::new(plugin));
        }
    }

    fn scan(&mut self, dir: &Path, source: &'static str) {
        // A folder that is not there holds nothing; one that is, but that others could have
        // filled, is not looked into further.
        if !dir.is_dir() {
            return;
        }
        match trust::check(dir, trust::Checked::Folder) {
            Ok(_) => {}
            Err(trust::Failure::Unresolved(_)) => return,
            Err(trust::Failure::Distrusted { reason, fix }) => {
                let path = dir.to_path_buf();
                self.refused.push(Refused { path, folder: true, source, reason, fix });
                return;
            }
        }
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        let mut files: Vec<PathBuf> = entries
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.is_file()
                    && p.file_name().and_then(|n| n.to_str()).is_some_and(is_plugin_file_name)
            })
            .collect();
        files.sort();
        for f in files {
            self.load_found(&f, source);
        }
    }

    /// The plugin of a machine type.
    pub fn find(&self, name: &str) -> Option<&Arc<Plugin>> {
        self.plugins.iter().find(|p| p.name == name)
    }

    /// The first plugin that reads machine files.
    pub fn machine_file_reader(&self) -> Option<&Arc<Plugin>> {
        self.plugins.iter().find(|p| p.reads_machine_files())
    }

    /// The files and folders refused, for messages: empty when none was, otherwise a sentence
    /// that starts with "; ".
    pub fn refused_text(&self) -> String {
        if self.refused.is_empty() {
            return String::new();
        }
        let each: Vec<String> = self.refused.iter().map(Refused::to_string).collect();
        format!("; {}", each.join("; "))
    }

    /// One line per place searched, for messages.
    pub fn searched_text(&self) -> String {
        if self.searched.is_empty() {
            return "nowhere (no --plugin, no BALLBAR_PLUGIN_PATH, no executable folder)".into();
        }
        self.searched
            .iter()
            .map(|s| format!("{} ({})", s.path.display(), s.source))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plugin_file_names() {
        for ok in [
            "libballbar_machine_column.so",
            "ballbar_machine_x.dll",
            "libballbar_machine_chain_file.dylib",
        ] {
            assert!(is_plugin_file_name(ok), "{ok}");
        }
        for no in [
            "libballbar_model.so",
            "libballbar_machine_column.rlib",
            "ballbar_machine_column.d",
            "column.so",
        ] {
            assert!(!is_plugin_file_name(no), "{no}");
        }
    }

    #[test]
    fn machine_file_messages_keep_their_place() {
        let e = located(Path::new("m.ron"), "12:7: unknown joint 'Q'");
        assert_eq!(e.to_string(), "m.ron:12:7: unknown joint 'Q'");
        let e = located(Path::new("m.ron"), "no place");
        assert_eq!(e.to_string(), "m.ron:1:1: no place");
    }

    #[test]
    fn a_file_that_is_not_a_library_is_an_error_naming_it() {
        let d = std::env::temp_dir().join(format!("ballbar-host-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        let f = d.join("libballbar_machine_text.so");
        std::fs::write(&f, "not a library").unwrap();
        let e = Plugin::load(&f).unwrap_err();
        assert!(matches!(e, PluginError::NotALibrary { .. }), "{e}");
        assert!(e.to_string().contains("libballbar_machine_text.so"), "{e}");
        let reg = Registry::discover(&Search {
            explicit: vec![],
            env_path: Some(d.clone().into_os_string()),
            exe_dir: None,
        })
        .unwrap();
        assert!(reg.plugins.is_empty());
        assert_eq!(reg.problems.len(), 1);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(unix)]
    fn chmod(path: &Path, mode: u32) {
        use std::os::unix::fs::PermissionsExt as _;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    /// A fresh folder (owner only may write) holding a text file named like a plugin: opened,
    /// it fails as "not a library", so a problem shows that it was opened and a refusal that it
    /// was not.
    #[cfg(unix)]
    fn folder_with_a_plugin_name(tag: &str) -> (PathBuf, PathBuf) {
        let d = std::env::temp_dir().join(format!("ballbar-host-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        chmod(&d, 0o755);
        let f = d.join("libballbar_machine_text.so");
        std::fs::write(&f, "not a library").unwrap();
        chmod(&f, 0o644);
        (d, f)
    }

    #[cfg(unix)]
    fn discover_in(dir: &Path) -> Registry {
        Registry::discover(&Search {
            explicit: vec![],
            env_path: Some(dir.as_os_str().to_owned()),
            exe_dir: None,
        })
        .unwrap()
    }

    #[cfg(unix)]
    #[test]
    fn a_folder_or_a_file_others_can_write_is_refused_and_not_opened() {
        let (d, f) = folder_with_a_plugin_name("writable");
        chmod(&d, 0o757);
        let reg = discover_in(&d);
        assert!(reg.problems.is_empty(), "opened: {:?}", reg.problems);
        assert_eq!(reg.refused.len(), 1, "{:?}", reg.refused);
        let r = &reg.refused[0];
        assert!(r.folder && r.path == d && r.source == "BALLBAR_PLUGIN_PATH", "{r:?}");
        let real = d.canonicalize().unwrap();
        assert_eq!(
            r.reason,
            format!("the plugin folder {} is writable by others (mode 0757)", real.display())
        );
        assert_eq!(r.fix, format!("if you trust it, `chmod go-w {}`", real.display()));

        // Writable by a group with members other than the owner (a gid no local account file
        // lists): refused. Giving the folder to that group needs root; elsewhere this case is
        // left to private_group's own test.
        chmod(&d, 0o775);
        if std::os::unix::fs::chown(&d, None, Some(4242)).is_ok() {
            let reg = discover_in(&d);
            assert_eq!(reg.refused.len(), 1, "{reg:?}");
            assert!(
                reg.refused[0].reason.ends_with(
                    "is writable by its group (mode 0775; group 4242 has members other than its owner)"
                ),
                "{reg:?}"
            );
        }

        chmod(&d, 0o755);
        chmod(&f, 0o646);
        let reg = discover_in(&d);
        assert!(reg.problems.is_empty(), "opened: {:?}", reg.problems);
        assert_eq!(reg.refused.len(), 1, "{:?}", reg.refused);
        assert!(!reg.refused[0].folder && reg.refused[0].path == f, "{:?}", reg.refused);
        assert!(reg.refused[0].reason.starts_with("the plugin file "), "{:?}", reg.refused);
        // Given by name, it is an error that says how to make it loadable.
        let e = Registry::discover(&Search { explicit: vec![f.clone()], ..Search::default() })
            .unwrap_err();
        assert!(matches!(e, PluginError::Untrusted { .. }), "{e:?}");
        assert!(e.to_string().contains("chmod go-w"), "{e}");

        // Writable by the owner alone: opened (and found not to be a library).
        chmod(&f, 0o644);
        let reg = discover_in(&d);
        assert!(reg.refused.is_empty(), "{:?}", reg.refused);
        assert_eq!(reg.problems.len(), 1, "{:?}", reg.problems);
        let _ = std::fs::remove_dir_all(&d);
    }

    #[cfg(unix)]
    #[test]
    fn a_group_is_private_when_its_owner_is_its_one_member() {
        let accounts = trust::Accounts {
            passwd: "root:x:0:0:root:/root:/bin/sh\n\
                     ann:x:1000:1000:Ann:/home/ann:/bin/sh\n\
                     bob:x:1001:1001:Bob:/home/bob:/bin/sh\n\
                     cy:x:1002:100:Cy:/home/cy:/bin/sh\n\
                     dee:x:1003:100:Dee:/home/dee:/bin/sh\n"
                .into(),
            group: "root:x:0:\nann:x:1000:\nbob:x:1001:ann\nusers:x:100:\n\
                    solo:x:300:ann\nduo:x:301:ann,bob\nnobody:x:302:\n"
                .into(),
        };
        let private = |gid, owner| trust::private_group(gid, owner, &accounts);
        // Ann's own group, by primary membership or as its one listed member.
        assert!(private(1000, 1000));
        assert!(private(300, 1000));
        assert!(private(0, 0));
        // Not Bob's: Ann is listed in it. Not Ann's: Bob's primary group.
        assert!(!private(1001, 1001));
        assert!(!private(1001, 1000));
        // Shared, listing two, with no member at all, or not in the files.
        assert!(!private(100, 1002));
        assert!(!private(301, 1000));
        assert!(!private(302, 1000));
        assert!(!private(4242, 1000));
    }

    #[cfg(unix)]
    #[test]
    fn a_folder_above_may_be_writable_by_others_only_when_sticky() {
        let (outer, _) = folder_with_a_plugin_name("sticky");
        let inner = outer.join("plugins");
        std::fs::create_dir(&inner).unwrap();
        chmod(&inner, 0o755);
        let f = inner.join("libballbar_machine_text.so");
        std::fs::write(&f, "not a library").unwrap();
        chmod(&f, 0o644);
        // Sticky, as /tmp: others cannot rename or remove the folder of ours inside it.
        chmod(&outer, 0o1777);
        assert!(matches!(Plugin::load(&f), Err(PluginError::NotALibrary { .. })));
        // Not sticky: anyone could put another folder in its place.
        chmod(&outer, 0o757);
        let e = Plugin::load(&f).unwrap_err();
        let real = outer.canonicalize().unwrap();
        assert!(
            e.to_string().contains(&format!(
                "the folder above it {} is writable by others (mode 0757)",
                real.display()
            )),
            "{e}"
        );
        // A link to the file is checked where it leads: the folder the link is in does not
        // matter, the target's folders do.
        chmod(&outer, 0o755);
        let link = outer.join("libballbar_machine_link.so");
        std::os::unix::fs::symlink(&f, &link).unwrap();
        assert!(matches!(Plugin::load(&link), Err(PluginError::NotALibrary { .. })));
        chmod(&inner, 0o757);
        let e = Plugin::load(&link).unwrap_err();
        assert!(e.to_string().contains("its folder"), "{e}");
        chmod(&inner, 0o755);
        let _ = std::fs::remove_dir_all(&outer);
    }

    #[test]
    fn the_installed_folder_is_searched_after_the_executable_folder() {
        let d = std::env::temp_dir().join(format!("ballbar-host-installed-{}", std::process::id()));
        let (bin, installed) = (d.join("bin"), d.join("lib/ballbar/plugins"));
        std::fs::create_dir_all(&bin).unwrap();
        std::fs::create_dir_all(&installed).unwrap();
        // Not a library: its failure to load shows that the folder was scanned.
        std::fs::write(installed.join("libballbar_machine_text.so"), "not a library").unwrap();
        let reg = Registry::discover(&Search {
            explicit: vec![],
            env_path: None,
            exe_dir: Some(bin.clone()),
        })
        .unwrap();
        assert_eq!(
            reg.searched,
            vec![
                SearchPlace { source: "executable folder", path: bin.clone() },
                SearchPlace { source: "installed plugins folder", path: installed.clone() }
            ]
        );
        assert_eq!(reg.problems.len(), 1, "{:?}", reg.problems);
        assert!(
            reg.problems[0].to_string().contains(&installed.display().to_string()),
            "{}",
            reg.problems[0]
        );
        assert_eq!(installed_plugin_dir(Path::new("/")), None);
        let _ = std::fs::remove_dir_all(&d);
    }
}

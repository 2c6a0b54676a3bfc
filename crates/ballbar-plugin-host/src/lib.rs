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
//! # Checks, in order
//! The file loads as a library; it exports `ballbar_plugin_declaration`; the declaration's
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
    /// Load and check the plugin in `path`.
    pub fn load(path: &Path) -> Result<Plugin, PluginError> {
        let path = path.to_path_buf();
        // SAFETY: loading a library runs its initialisers. A plugin is code the user chose to
        // install; Rust cdylibs have no initialisers of their own. This is the trust boundary.
        let lib = unsafe { libloading::Library::new(&path) }
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

/// The plugins found, the problems met, and where they were looked for.
#[derive(Debug, Default)]
pub struct Registry {
    /// Loaded plugins, in search order, one per name.
    pub plugins: Vec<Arc<Plugin>>,
    /// Plugin files found in folders that failed to load (reported, not fatal).
    pub problems: Vec<PluginError>,
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
            for p in std::env::split_paths(v) {
                reg.searched.push(SearchPlace { source: "BALLBAR_PLUGIN_PATH", path: p.clone() });
                if p.is_dir() {
                    reg.scan(&p);
                } else if p.is_file() {
                    match Plugin::load(&p) {
                        Ok(plugin) => reg.add(plugin),
                        Err(e) => reg.problems.push(e),
                    }
                } else {
                    reg.problems.push(PluginError::NoSuchPath { path: p });
                }
            }
        }
        if let Some(d) = &search.exe_dir {
            reg.searched.push(SearchPlace { source: "executable folder", path: d.clone() });
            reg.scan(d);
            if let Some(installed) = installed_plugin_dir(d) {
                reg.searched.push(SearchPlace {
                    source: "installed plugins folder",
                    path: installed.clone(),
                });
                reg.scan(&installed);
            }
        }
        Ok(reg)
    }

    fn add(&mut self, plugin: Plugin) {
        if self.plugins.iter().any(|p| p.name == plugin.name) {
            self.shadowed.push((plugin.path, plugin.name));
        } else {
            self.plugins.push(Arc::new(plugin));
        }
    }

    fn scan(&mut self, dir: &Path) {
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
            match Plugin::load(&f) {
                Ok(p) => self.add(p),
                Err(e) => self.problems.push(e),
            }
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

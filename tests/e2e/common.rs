//! Shared helpers of the end-to-end tests: the binary under test, the bundled plugins it loads,
//! scratch folders.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository root.
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// The `ballbar` binary under test (the same entry point as `target/*/ballbar`).
pub fn exe() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ballbar-under-test"))
}

/// A bundled plugin's library as cargo built it for this test run: the plugin crates are
/// dev-dependencies of this package, so their `cdylib`s are in `target/<profile>/deps`.
pub fn plugin_file(lib_name: &str) -> PathBuf {
    let deps = exe().parent().unwrap().join("deps");
    deps.join(format!("{}{lib_name}{}", std::env::consts::DLL_PREFIX, std::env::consts::DLL_SUFFIX))
}

/// The bundled plugins' files.
pub fn bundled_plugins() -> Vec<PathBuf> {
    ["ballbar_machine_column", "ballbar_machine_horizontal", "ballbar_machine_chain_file"].iter().map(|n| plugin_file(n)).collect()
}

/// `BALLBAR_PLUGIN_PATH` naming the bundled plugins.
pub fn bundled_plugin_path() -> OsString {
    std::env::join_paths(bundled_plugins()).unwrap()
}

/// Run the binary from the repository root with the bundled plugins on `BALLBAR_PLUGIN_PATH`.
pub fn ballbar(args: &[&str]) -> Output {
    Command::new(exe()).args(args).current_dir(root()).env("BALLBAR_PLUGIN_PATH", bundled_plugin_path()).output().unwrap()
}

/// A fresh scratch folder for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("ballbar-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Standard output and error of a run.
pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

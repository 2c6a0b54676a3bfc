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
    ["ballbar_machine_column", "ballbar_machine_horizontal", "ballbar_machine_chain_file"]
        .iter()
        .map(|n| plugin_file(n))
        .collect()
}

/// `BALLBAR_PLUGIN_PATH` naming the bundled plugins.
pub fn bundled_plugin_path() -> OsString {
    std::env::join_paths(bundled_plugins()).unwrap()
}

/// Run the binary from the repository root with the bundled plugins on `BALLBAR_PLUGIN_PATH`.
pub fn ballbar(args: &[&str]) -> Output {
    Command::new(exe())
        .args(args)
        .current_dir(root())
        .env("BALLBAR_PLUGIN_PATH", bundled_plugin_path())
        .output()
        .unwrap()
}

/// A fresh scratch folder for one test, kept after it for a failure to be read. The folders
/// of earlier test runs whose process has ended are removed the first time a run asks for one
/// ([`sweep_earlier_runs`]): without that they pile up in the system's temporary folder.
pub fn scratch(name: &str) -> PathBuf {
    static SWEPT: std::sync::Once = std::sync::Once::new();
    SWEPT.call_once(sweep_earlier_runs);
    let d = std::env::temp_dir().join(format!("ballbar-e2e-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Remove the scratch folders (`ballbar-e2e-PID-…`) of test processes that no longer run: a
/// process runs while `/proc/PID` exists (Linux; elsewhere nothing is removed).
fn sweep_earlier_runs() {
    if !Path::new("/proc/self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else { return };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(rest) = name.to_str().and_then(|n| n.strip_prefix("ballbar-e2e-")) else {
            continue;
        };
        let Some(pid) = rest.split('-').next().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        if pid != std::process::id() && !Path::new(&format!("/proc/{pid}")).exists() {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Standard output and error of a run.
pub fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// What a test needs that the repository does not ship, for [`skip`]: a dependency `.ci/run`
/// installs (required there, so CI cannot turn green by skipping), or the shared test data
/// beside the repository (absent from a bare clone: its tests say they skipped).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Needs {
    /// Debian's chromium at `/usr/bin/chromium`.
    Chromium,
    /// python3 with the `mcap` package from PyPI.
    PythonMcap,
    /// `../shared/data`, beside the repository.
    SharedData,
    /// The rights to give a file to another user (`chown`): root's.
    Root,
}

impl Needs {
    /// The name `BALLBAR_TEST_REQUIRE` lists it by.
    pub fn name(self) -> &'static str {
        match self {
            Needs::Chromium => "chromium",
            Needs::PythonMcap => "python-mcap",
            Needs::SharedData => "shared-data",
            Needs::Root => "root",
        }
    }
}

/// Whether the test run requires `needs`: `BALLBAR_TEST_REQUIRE` is a comma-separated list of
/// [`Needs::name`]s (`.ci/run` sets it to the dependencies it installs).
pub fn required(needs: Needs) -> bool {
    std::env::var("BALLBAR_TEST_REQUIRE")
        .is_ok_and(|v| v.split(',').any(|n| n.trim() == needs.name()))
}

/// A test that cannot run because `needs` is missing calls this and returns. Where the run
/// requires it ([`required`]) this fails the test instead. Otherwise it writes one line
/// `SKIPPED: <why>` straight to standard error, past the test harness's capture (which holds
/// back `eprintln!` of a passing test), so that the skip shows in `cargo test`'s output and
/// `.ci/run` can count it in its summary.
pub fn skip(needs: Needs, why: &str) {
    assert!(
        !required(needs),
        "{why}, and this test run requires {} (BALLBAR_TEST_REQUIRE={})",
        needs.name(),
        std::env::var("BALLBAR_TEST_REQUIRE").unwrap_or_default()
    );
    use std::io::Write as _;
    // One write of the whole line: the harness's own output cannot land inside it.
    let _ = std::io::stderr().lock().write_all(format!("\nSKIPPED: {why}\n").as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Run by [`a_skip_is_seen_in_the_test_output_and_fails_where_required`] in a child process
    /// of this test binary, never on its own.
    #[test]
    #[ignore = "a probe that the skip test runs in a child process"]
    fn skipping_probe() {
        skip(Needs::Chromium, "the probe's dependency is missing");
    }

    fn probe(require: Option<&str>) -> Output {
        let mut c = Command::new(std::env::current_exe().unwrap());
        c.args(["--exact", "common::tests::skipping_probe", "--include-ignored"])
            .env_remove("BALLBAR_TEST_REQUIRE");
        if let Some(r) = require {
            c.env("BALLBAR_TEST_REQUIRE", r);
        }
        c.output().unwrap()
    }

    #[test]
    fn a_skip_is_seen_in_the_test_output_and_fails_where_required() {
        // Under the harness's capture (no --nocapture), the skip still reaches the output.
        let o = probe(None);
        assert!(o.status.success(), "{}", text(&o));
        assert!(
            text(&o).lines().any(|l| l == "SKIPPED: the probe's dependency is missing"),
            "{}",
            text(&o)
        );
        // Where the run requires the dependency, the test fails and says what was required.
        let o = probe(Some("python-mcap, chromium"));
        assert!(!o.status.success(), "{}", text(&o));
        assert!(text(&o).contains("this test run requires chromium"), "{}", text(&o));
        // Another requirement does not concern it.
        assert!(probe(Some("python-mcap")).status.success());
    }
}

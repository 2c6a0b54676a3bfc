//! `cargo xtask tidy`: the checks that keep the tree tidy. Each must pass; none is skipped (a
//! check that cannot run, rustfmt or clippy not installed, fails and says so):
//! - `cargo fmt --all --check`: the tree is formatted as `rustfmt.toml` says;
//! - unused dependencies: every dependency in a package's `Cargo.toml` is named by that
//!   package's code ([`unused_dependencies`]), or the manifest says why it need not be;
//! - `cargo clippy --workspace --all-targets -- -D warnings`: no lint warning in any target.
//!
//! All three run, whatever the first ones found, and the task fails if any failed.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};
use std::process::Command;

use anyhow::{Context, Result, bail};

/// `cargo xtask tidy`.
pub fn tidy(args: &[String]) -> Result<()> {
    if let Some(a) = args.first() {
        bail!("tidy: unexpected argument {a} (usage: cargo xtask tidy)");
    }
    let root = crate::root();
    type Check = fn(&Path) -> Result<()>;
    let checks: [(&str, Check); 3] =
        [("formatting", fmt), ("unused dependencies", unused), ("clippy", clippy)];
    let mut failed = Vec::new();
    for (name, check) in checks {
        eprintln!("tidy: {name}");
        if let Err(e) = check(&root) {
            eprintln!("tidy: {name}: FAILED: {e:#}");
            failed.push(name);
        }
    }
    if !failed.is_empty() {
        bail!("tidy: failed: {}", failed.join(", "));
    }
    eprintln!("tidy: every check passed");
    Ok(())
}

/// The cargo that runs this task (`CARGO`, set by `cargo run`), or the one on the path.
fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

/// `cargo TOOL ARGS` in the workspace root, once `cargo TOOL --version` has shown that the tool
/// is installed: a missing tool fails the check, with how to install it.
fn run_tool(root: &Path, tool: &str, component: &str, args: &[&str], fix: &str) -> Result<()> {
    let missing = |why: String| {
        anyhow::anyhow!(
            "`cargo {tool}` cannot run here ({why}); install it (`rustup component add {component}`): tidy fails without it rather than skip this check"
        )
    };
    match cargo().args([tool, "--version"]).current_dir(root).output() {
        Ok(out) if out.status.success() => {}
        Ok(out) => return Err(missing(String::from_utf8_lossy(&out.stderr).trim().to_string())),
        Err(e) => return Err(missing(format!("cargo: {e}"))),
    }
    let status = cargo()
        .arg(tool)
        .args(args)
        .current_dir(root)
        .status()
        .with_context(|| format!("running cargo {tool}"))?;
    if !status.success() {
        bail!("`cargo {tool} {}` failed ({status}): {fix}", args.join(" "));
    }
    Ok(())
}

fn fmt(root: &Path) -> Result<()> {
    run_tool(
        root,
        "fmt",
        "rustfmt",
        &["--all", "--check"],
        "run `cargo fmt --all` and commit what it changes",
    )
}

fn clippy(root: &Path) -> Result<()> {
    run_tool(
        root,
        "clippy",
        "clippy",
        &["--workspace", "--all-targets", "--", "-D", "warnings"],
        "fix the warnings above (or allow one where it is wrong, with a comment saying why)",
    )
}

/// Every package of the workspace, and the example plugin under `docs/` (a workspace of its
/// own, in the tree all the same): no dependency that its code does not name.
fn unused(root: &Path) -> Result<()> {
    let mut dirs = workspace_members(root)?;
    dirs.push(root.join("docs/example-plugin"));
    let mut problems = Vec::new();
    for dir in &dirs {
        let manifest_path = dir.join("Cargo.toml");
        let manifest = std::fs::read_to_string(&manifest_path)
            .with_context(|| format!("reading {}", manifest_path.display()))?;
        let shown = manifest_path.strip_prefix(root).unwrap_or(&manifest_path).display();
        for p in unused_dependencies(&manifest, &package_sources(dir)?) {
            problems.push(format!("{shown}: {p}"));
        }
    }
    for p in &problems {
        eprintln!("{p}");
    }
    if !problems.is_empty() {
        bail!("{} unused or misplaced dependencies (above)", problems.len());
    }
    eprintln!("tidy: the dependencies of {} packages are all used", dirs.len());
    Ok(())
}

/// The package folders of the workspace's `members` (a trailing `/*` taken as every folder
/// there with a `Cargo.toml`).
fn workspace_members(root: &Path) -> Result<Vec<PathBuf>> {
    let text = std::fs::read_to_string(root.join("Cargo.toml")).context("the root Cargo.toml")?;
    let Some(start) = text.find("\nmembers") else { bail!("the root Cargo.toml has no members") };
    let list = &text[start..];
    let list = &list[list.find('[').context("members = [")?..];
    let list = &list[..list.find(']').context("members = [...]")?];
    let mut dirs = Vec::new();
    for member in quoted(list) {
        if let Some(parent) = member.strip_suffix("/*") {
            let mut found: Vec<PathBuf> = std::fs::read_dir(root.join(parent))?
                .filter_map(|e| Some(e.ok()?.path()))
                .filter(|p| p.join("Cargo.toml").is_file())
                .collect();
            found.sort();
            dirs.extend(found);
        } else {
            dirs.push(root.join(member));
        }
    }
    Ok(dirs)
}

/// The double-quoted strings in `text` (no escapes: package names and paths).
fn quoted(text: &str) -> Vec<String> {
    text.split('"').skip(1).step_by(2).map(str::to_string).collect()
}

/// The Rust files of the package in `dir`, by path relative to it: those in its folder (not in
/// `target` or hidden folders, nor in a package nested in it), and those elsewhere that its
/// modules include by `#[path]` (relative paths starting with `..`).
fn package_sources(dir: &Path) -> Result<BTreeMap<PathBuf, String>> {
    let mut files = BTreeMap::new();
    let mut pending = vec![dir.to_path_buf()];
    while let Some(d) = pending.pop() {
        for entry in std::fs::read_dir(&d).with_context(|| format!("listing {}", d.display()))? {
            let path = entry?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if path.is_dir() {
                if name != "target" && !name.starts_with('.') && !path.join("Cargo.toml").exists() {
                    pending.push(path);
                }
            } else if name.ends_with(".rs") {
                let text = std::fs::read_to_string(&path)
                    .with_context(|| format!("reading {}", path.display()))?;
                files.insert(path.strip_prefix(dir)?.to_path_buf(), text);
            }
        }
    }
    // Files included from outside the folder, and what they include in turn.
    let mut todo: Vec<PathBuf> = files.keys().cloned().collect();
    while let Some(file) = todo.pop() {
        let text = &files[&file];
        let includes: Vec<PathBuf> = mod_declarations(&strip(text), text)
            .into_iter()
            .filter_map(|m| Some(normalise(&parent(&file).join(m.path?))))
            .filter(|p| p.starts_with("..") && !files.contains_key(p))
            .collect();
        for p in includes {
            if let Ok(text) = std::fs::read_to_string(dir.join(&p)) {
                files.insert(p.clone(), text);
                todo.push(p);
            }
        }
    }
    Ok(files)
}

/// The kinds of dependency table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Normal,
    Dev,
    Build,
}

/// A dependency of a manifest.
#[derive(Debug)]
struct Dependency {
    /// The key it is listed under (the name the code uses, `-` for `_`, even when `package =`
    /// names another package).
    key: String,
    kind: Kind,
    /// The table it is listed in, as written (`[dev-dependencies]`).
    table: String,
}

/// What [`unused_dependencies`] needs of a `Cargo.toml`.
#[derive(Debug, Default)]
struct Manifest {
    package: String,
    dependencies: Vec<Dependency>,
    /// `[package.metadata.tidy] unused-ok`: dependencies the package needs without naming them.
    unused_ok: Vec<String>,
    /// Whether a comment stands above `unused-ok` or within its list.
    unused_ok_explained: bool,
}

/// The dotted parts of a table header (`target.'cfg(unix)'.dependencies`), unquoted.
fn header_parts(header: &str) -> Vec<String> {
    let mut parts = vec![String::new()];
    let mut quote = None;
    for c in header.chars() {
        match (c, quote) {
            ('"' | '\'', None) => quote = Some(c),
            (c, Some(q)) if c == q => quote = None,
            ('.', None) => parts.push(String::new()),
            (c, _) => parts.last_mut().expect("one part at least").push(c),
        }
    }
    parts.iter().map(|p| p.trim().to_string()).collect()
}

/// The kind of dependency table named `part`, if it is one.
fn table_kind(part: &str) -> Option<Kind> {
    match part {
        "dependencies" => Some(Kind::Normal),
        "dev-dependencies" | "dev_dependencies" => Some(Kind::Dev),
        "build-dependencies" | "build_dependencies" => Some(Kind::Build),
        _ => None,
    }
}

/// Reads the package name, the dependency tables (`[dependencies]`, `[dev-dependencies]`,
/// `[build-dependencies]`, their `[target.….]` forms and `[dependencies.NAME]` tables) and
/// `[package.metadata.tidy]` of a manifest. A line-by-line reading of what cargo accepts in
/// them, not a TOML parser: keys start their line, arrays of `unused-ok` may span lines.
fn parse_manifest(text: &str) -> Manifest {
    let mut m = Manifest::default();
    // The current table: its header as written and dotted parts.
    let (mut header, mut parts) = (String::new(), Vec::new());
    let mut seen = BTreeSet::new();
    let lines: Vec<&str> = text.lines().collect();
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i].trim();
        i += 1;
        if line.starts_with('[') {
            let inner = line.trim_start_matches('[');
            let inner = inner.split(']').next().unwrap_or_default();
            header = format!("[{inner}]");
            parts = header_parts(inner);
            // `[dependencies.NAME]` and `[target.X.dependencies.NAME]`: one dependency.
            let at = if parts.first().map(String::as_str) == Some("target") { 2 } else { 0 };
            if parts.len() == at + 2
                && let Some(kind) = table_kind(&parts[at])
            {
                let table = format!("[{}]", line_header_prefix(inner));
                if seen.insert((parts[at + 1].clone(), table.clone())) {
                    m.dependencies.push(Dependency { key: parts[at + 1].clone(), kind, table });
                }
            }
            continue;
        }
        // A key (`name =`, `name.workspace =`, `"name" =`), not a line of a multi-line array.
        let unquoted = line.strip_prefix('"').unwrap_or(line);
        let key: String = unquoted
            .chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '-' || *c == '_')
            .collect();
        let after = unquoted[key.len()..].trim_start_matches('"').trim_start();
        if key.is_empty() || !(after.starts_with('=') || after.starts_with('.')) {
            continue;
        }
        let at = if parts.first().map(String::as_str) == Some("target") { 2 } else { 0 };
        let kind = (parts.len() == at + 1).then(|| table_kind(&parts[at])).flatten();
        if let Some(kind) = kind {
            if seen.insert((key.clone(), header.clone())) {
                m.dependencies.push(Dependency { key, kind, table: header.clone() });
            }
        } else if parts == ["package"] && key == "name" {
            m.package = quoted(line).into_iter().next().unwrap_or_default();
        } else if parts == ["package", "metadata", "tidy"] && key == "unused-ok" {
            // The comment above the key, or in the list.
            let above = i >= 2 && lines[i - 2].trim().starts_with('#');
            let mut list = line.split_once('=').map(|(_, v)| v).unwrap_or_default().to_string();
            while !list.contains(']') && i < lines.len() {
                list.push('\n');
                list.push_str(lines[i]);
                i += 1;
            }
            m.unused_ok_explained = above || list.contains('#');
            let without_comments: Vec<&str> =
                list.lines().map(|l| l.split('#').next().unwrap_or_default()).collect();
            m.unused_ok.extend(quoted(&without_comments.join("\n")));
        }
    }
    m
}

/// `dependencies` of `dependencies.NAME` (or `target.X.dependencies` of
/// `target.X.dependencies.NAME`): the header of the table a dependency table belongs to.
fn line_header_prefix(inner: &str) -> &str {
    inner.rsplit_once('.').map_or(inner, |(table, _)| table.trim())
}

/// Where code sits: compiled into the package's library or binaries, only into its tests
/// (integration tests, benches, examples, `#[cfg(test)]` items and the modules they declare),
/// or into its build script.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
enum Code {
    Normal,
    Test,
    Build,
}

/// The dependencies of the package whose `Cargo.toml` is `manifest` that its code (`sources`,
/// by path relative to the package folder, as [`package_sources`] gives them) does not name,
/// or names only where it is not compiled with it, each as what is wrong and what to do.
///
/// A dependency is named by `NAME::` (the start of a path, not a segment after another one),
/// `use NAME`, `extern crate NAME` or `NAME!`, outside comments and literals, with `NAME` its
/// key with `-` for `_`. Its table decides which code counts: `[dependencies]` the library and
/// binaries (outside `#[cfg(test)]` items), `[dev-dependencies]` the test code, and
/// `[build-dependencies]` `build.rs` and its modules. `[package.metadata.tidy] unused-ok` lists
/// those needed without being named (built for the tests to load, not linked), with a comment
/// saying why; an entry that is not a dependency, or that is named after all, is a problem too.
fn unused_dependencies(manifest: &str, sources: &BTreeMap<PathBuf, String>) -> Vec<String> {
    let m = parse_manifest(manifest);
    let mut code: BTreeMap<Code, Vec<String>> = BTreeMap::new();
    for (part, text) in classify(sources) {
        code.entry(part).or_default().push(text);
    }
    let names = |ident: &str, part: Code| {
        code.get(&part).is_some_and(|texts| texts.iter().any(|t| names_crate(t, ident)))
    };
    let ok: Vec<String> = m.unused_ok.iter().map(|k| k.replace('-', "_")).collect();
    let mut problems = Vec::new();
    let package = if m.package.is_empty() { "the package".to_string() } else { m.package.clone() };
    for d in &m.dependencies {
        let ident = d.key.replace('-', "_");
        let in_normal = names(&ident, Code::Normal);
        let in_test = names(&ident, Code::Test);
        let in_build = names(&ident, Code::Build);
        let used = match d.kind {
            Kind::Normal => in_normal,
            Kind::Dev => in_test,
            Kind::Build => in_build,
        };
        let excused = ok.contains(&ident);
        if used && excused {
            problems.push(format!(
                "{package}: `{}` in {} is listed in [package.metadata.tidy] unused-ok, but its code names it (`{ident}`): take it off unused-ok",
                d.key, d.table
            ));
        }
        if used || excused {
            continue;
        }
        let what = if d.kind == Kind::Normal && in_test {
            format!(
                "only its tests name it: move it to [dev-dependencies]{}",
                if in_build { " (and [build-dependencies], which build.rs needs)" } else { "" }
            )
        } else if d.kind == Kind::Normal && in_build {
            "only build.rs names it: move it to [build-dependencies]".to_string()
        } else {
            let code = match d.kind {
                Kind::Normal => "its library or binaries (outside #[cfg(test)])",
                Kind::Dev => "its tests (tests/, benches, examples, #[cfg(test)] code)",
                Kind::Build => "build.rs",
            };
            format!(
                "{code} never name it (`{ident}::`, `use {ident}`, `extern crate {ident}`): remove it from Cargo.toml, or, if it is needed without being named, add \"{}\" to `unused-ok = [...]` under [package.metadata.tidy], with a comment saying why",
                d.key
            )
        };
        problems.push(format!("{package}: `{}` in {}: {what}", d.key, d.table));
    }
    for entry in &m.unused_ok {
        let ident = entry.replace('-', "_");
        if !m.dependencies.iter().any(|d| d.key.replace('-', "_") == ident) {
            problems.push(format!(
                "{package}: [package.metadata.tidy] unused-ok lists \"{entry}\", which is not one of its dependencies: take it off the list"
            ));
        }
    }
    if !m.unused_ok.is_empty() && !m.unused_ok_explained {
        problems.push(format!(
            "{package}: [package.metadata.tidy] unused-ok has no comment saying why those dependencies are needed without being named: add one above it"
        ));
    }
    problems
}

/// The code of `sources` in parts, each with where it is compiled: see [`Code`]. A file's place
/// comes from the module tree: `build.rs` and what it declares is build code; `src/` is the
/// library and binaries, except the `#[cfg(test)]` items in it and the modules they declare;
/// anything else (`tests/`, `benches/`, `examples/`, other test targets) is test code; a file
/// included from outside the folder takes the place of the module that includes it.
fn classify(sources: &BTreeMap<PathBuf, String>) -> Vec<(Code, String)> {
    struct File {
        stripped: String,
        /// The `#[cfg(test)]` items, byte ranges of `stripped`.
        tests: Vec<(usize, usize)>,
        /// The modules it declares: (file, declared in test code).
        children: Vec<(PathBuf, bool)>,
    }
    let files: BTreeMap<PathBuf, File> = sources
        .iter()
        .map(|(path, text)| {
            let stripped = strip(text);
            let tests = test_items(&stripped);
            let children = mod_declarations(&stripped, text)
                .into_iter()
                .filter_map(|m| {
                    let file = module_file(path, &m, sources)?;
                    Some((file, tests.iter().any(|&(a, b)| (a..b).contains(&m.at))))
                })
                .collect();
            (path.clone(), File { stripped, tests, children })
        })
        .collect();
    // Where each file sits: from the roots, through the module declarations. A place found
    // first is kept, normal code first: a file compiled into the library is library code.
    let mut place: BTreeMap<PathBuf, Code> = BTreeMap::new();
    let visit = |roots: Vec<(PathBuf, Code)>, place: &mut BTreeMap<PathBuf, Code>| {
        let mut stack = roots;
        while let Some((path, code)) = stack.pop() {
            if place.contains_key(&path) {
                continue;
            }
            for (child, in_test) in &files[&path].children {
                let child_code = if *in_test && code == Code::Normal { Code::Test } else { code };
                stack.push((child.clone(), child_code));
            }
            place.insert(path, code);
        }
    };
    let roots = |keep: &dyn Fn(&Path) -> bool, code: Code| -> Vec<(PathBuf, Code)> {
        files.keys().filter(|p| keep(p)).map(|p| (p.clone(), code)).collect()
    };
    let library = |p: &Path| {
        p == Path::new("src/lib.rs")
            || p == Path::new("src/main.rs")
            || (p.starts_with("src/bin") && p.components().count() <= 4)
    };
    visit(roots(&library, Code::Normal), &mut place);
    visit(roots(&|p| p == Path::new("build.rs"), Code::Build), &mut place);
    // Anything in `src/` not reached (a binary at another path, a file no module declares) is
    // taken as library code; anything outside it as test code.
    visit(roots(&|p| p.starts_with("src"), Code::Normal), &mut place);
    visit(roots(&|p| !p.starts_with(".."), Code::Test), &mut place);

    let mut parts = Vec::new();
    for (path, code) in place {
        let f = &files[&path];
        if code != Code::Normal {
            parts.push((code, f.stripped.clone()));
            continue;
        }
        let mut from = 0;
        for &(a, b) in &f.tests {
            parts.push((Code::Normal, f.stripped[from..a].to_string()));
            parts.push((Code::Test, f.stripped[a..b].to_string()));
            from = b;
        }
        parts.push((Code::Normal, f.stripped[from..].to_string()));
    }
    parts
}

/// A `mod NAME;` declaration.
#[derive(Debug)]
struct ModDeclaration {
    name: String,
    /// Its `#[path = "…"]`, if any.
    path: Option<String>,
    /// Byte offset of `mod`.
    at: usize,
}

fn is_ident_byte(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_'
}

/// The `mod NAME;` declarations of a file (`stripped` as [`strip`] gives it, `original` for
/// the values of `#[path]`).
fn mod_declarations(stripped: &str, original: &str) -> Vec<ModDeclaration> {
    let b = stripped.as_bytes();
    let mut out = Vec::new();
    for (at, _) in stripped.match_indices("mod") {
        if at > 0 && is_ident_byte(b[at - 1]) {
            continue;
        }
        let rest = &stripped[at + 3..];
        if !rest.starts_with(char::is_whitespace) {
            continue;
        }
        let rest = rest.trim_start();
        let name: String = rest.bytes().take_while(|&c| is_ident_byte(c)).map(char::from).collect();
        if name.is_empty() || !rest[name.len()..].trim_start().starts_with(';') {
            continue;
        }
        // Back over the visibility and the attributes, to a `#[path = "…"]`.
        let mut end = stripped[..at].trim_end().len();
        let before = &stripped[..end];
        if before.ends_with("pub") {
            end -= 3;
        } else if before.ends_with(')')
            && let Some(open) = before.rfind('(')
            && stripped[..open].trim_end().ends_with("pub")
        {
            end = stripped[..open].trim_end().len() - 3;
        }
        let mut path = None;
        loop {
            end = stripped[..end].trim_end().len();
            if end == 0 || b[end - 1] != b']' {
                break;
            }
            let Some(open) = matching_open(b, end - 1) else { break };
            if open == 0 || b[open - 1] != b'#' {
                break;
            }
            let attr: String = stripped[open + 1..end - 1].split_whitespace().collect();
            if attr.starts_with("path=") {
                path = quoted(&original[open..end]).into_iter().next();
            }
            end = open - 1;
        }
        out.push(ModDeclaration { name, path, at });
    }
    out
}

/// The index of the `[` that the `]` at `close` closes.
fn matching_open(b: &[u8], close: usize) -> Option<usize> {
    let mut depth = 0usize;
    for i in (0..=close).rev() {
        match b[i] {
            b']' => depth += 1,
            b'[' => {
                depth -= 1;
                if depth == 0 {
                    return Some(i);
                }
            }
            _ => {}
        }
    }
    None
}

/// The file of a module declared in `file`, among `sources`.
fn module_file(
    file: &Path,
    m: &ModDeclaration,
    sources: &BTreeMap<PathBuf, String>,
) -> Option<PathBuf> {
    let dir = parent(file);
    if let Some(path) = &m.path {
        return Some(normalise(&dir.join(path))).filter(|p| sources.contains_key(p));
    }
    // `a.rs` declares `a/NAME.rs`; `lib.rs`, `main.rs`, `mod.rs` and other crate roots
    // (`build.rs`, `tests/x.rs`) declare `NAME.rs` beside them.
    let own = file.file_stem().map(|s| dir.join(s));
    [own, Some(dir.to_path_buf())]
        .into_iter()
        .flatten()
        .flat_map(|d| [d.join(format!("{}.rs", m.name)), d.join(&m.name).join("mod.rs")])
        .map(|p| normalise(&p))
        .find(|p| sources.contains_key(p))
}

/// The folder of a relative path (`""` for a file at the top).
fn parent(path: &Path) -> &Path {
    path.parent().unwrap_or(Path::new(""))
}

/// `a/b/../c` as `a/c`; leading `..` are kept.
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir if out.file_name().is_some() => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

/// The byte ranges of the items under `#[cfg(test)]` (or `#[cfg(all(test, …))]`) in
/// `stripped`, attributes included; the whole text under an inner `#![cfg(test)]`.
fn test_items(stripped: &str) -> Vec<(usize, usize)> {
    let b = stripped.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while let Some(at) = stripped[i..].find('#').map(|k| k + i) {
        i = at + 1;
        let inner = b.get(at + 1) == Some(&b'!');
        let open = if inner { at + 2 } else { at + 1 };
        if b.get(open) != Some(&b'[') {
            continue;
        }
        let Some(close) = matching_close(b, open) else { break };
        let attr: String = stripped[open + 1..close].split_whitespace().collect();
        if !cfg_is_test(&attr) {
            continue;
        }
        if inner {
            return vec![(0, b.len())];
        }
        let end = item_end(b, close + 1);
        out.push((at, end));
        i = end;
    }
    out
}

/// True for `cfg(test)` and `cfg(all(…, test, …))` (whitespace removed).
fn cfg_is_test(attr: &str) -> bool {
    if attr == "cfg(test)" {
        return true;
    }
    let Some(args) = attr.strip_prefix("cfg(all(").and_then(|a| a.strip_suffix("))")) else {
        return false;
    };
    let mut depth = 0;
    let mut part = String::new();
    for c in args.chars().chain([',']) {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            ',' if depth == 0 => {
                if part == "test" {
                    return true;
                }
                part.clear();
                continue;
            }
            _ => {}
        }
        part.push(c);
    }
    false
}

/// The index of the bracket that closes the one at `open` (any of `(`, `[`, `{`).
fn matching_close(b: &[u8], open: usize) -> Option<usize> {
    let mut depth = 0usize;
    for (i, &c) in b.iter().enumerate().skip(open) {
        match c {
            b'(' | b'[' | b'{' => depth += 1,
            b')' | b']' | b'}' => {
                depth = depth.checked_sub(1)?;
                if depth == 0 {
                    return Some(i);
                }
            }
            _ => {}
        }
    }
    None
}

/// The end of the item that starts at `from` (after its first attribute): past its other
/// attributes, to its `;` or the `}` of its body, whichever comes first outside brackets.
fn item_end(b: &[u8], from: usize) -> usize {
    let mut i = from;
    let mut depth = 0usize;
    while i < b.len() {
        match b[i] {
            b'(' | b'[' => depth += 1,
            b')' | b']' => depth = depth.saturating_sub(1),
            b';' if depth == 0 => return i + 1,
            b'{' if depth == 0 => return matching_close(b, i).map_or(b.len(), |c| c + 1),
            _ => {}
        }
        i += 1;
    }
    b.len()
}

/// True when `code` (stripped) names the crate `ident`: `ident::` at the start of a path,
/// `use ident`, `extern crate ident` or the macro `ident!`.
fn names_crate(code: &str, ident: &str) -> bool {
    let b = code.as_bytes();
    for (at, _) in code.match_indices(ident) {
        let end = at + ident.len();
        if (at > 0 && is_ident_byte(b[at - 1])) || b.get(end).is_some_and(|&c| is_ident_byte(c)) {
            continue;
        }
        let before = code[..at].trim_end();
        let after = code[end..].trim_start();
        // A segment after another one (`crate::ident::`, `self.ident`) is not the crate.
        let segment = before.strip_suffix("::").is_some_and(|p| {
            p.trim_end().bytes().next_back().is_some_and(|c| is_ident_byte(c) || c == b'>')
        });
        if segment || before.ends_with('.') {
            continue;
        }
        let word_before =
            |w: &str| before.strip_suffix(w).is_some_and(|p| !p.ends_with(|c: char| is_ident(c)));
        if after.starts_with("::")
            || (after.starts_with('!') && !after.starts_with("!="))
            || word_before("use")
            || before
                .strip_suffix("crate")
                .is_some_and(|p| p.trim_end().ends_with("extern") && word_before("crate"))
        {
            return true;
        }
    }
    false
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// `text` with the contents of its comments, string and character literals blanked (each byte
/// a space, line breaks kept), so that names in them do not count; the quotes of literals stay.
/// Offsets in the result are offsets in `text`.
fn strip(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(b.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        let prev_ident = i > 0 && is_ident_byte(b[i - 1]);
        match b[i] {
            b'/' if b.get(i + 1) == Some(&b'/') => {
                let end = text[i..].find('\n').map_or(b.len(), |k| i + k);
                blank(&mut out, i, end);
                i = end;
            }
            b'/' if b.get(i + 1) == Some(&b'*') => {
                let (mut depth, mut j) = (1, i + 2);
                while j < b.len() && depth > 0 {
                    if b[j..].starts_with(b"/*") {
                        (depth, j) = (depth + 1, j + 2);
                    } else if b[j..].starts_with(b"*/") {
                        (depth, j) = (depth - 1, j + 2);
                    } else {
                        j += 1;
                    }
                }
                blank(&mut out, i, j);
                i = j;
            }
            b'"' => {
                let mut j = i + 1;
                while j < b.len() && b[j] != b'"' {
                    j += if b[j] == b'\\' { 2 } else { 1 };
                }
                blank(&mut out, i + 1, j);
                i = j + 1;
            }
            // Raw strings: r"…", r#"…"#, and the byte and C forms br, cr.
            b'r' | b'b' | b'c' if !prev_ident => {
                let r = if b[i] == b'r' { i } else { i + 1 };
                let hashes = b[r + 1..].iter().take_while(|&&c| c == b'#').count();
                let quote = r + 1 + hashes;
                if b.get(r) == Some(&b'r') && b.get(quote) == Some(&b'"') {
                    let closing: Vec<u8> =
                        std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
                    let end = b[quote + 1..]
                        .windows(closing.len())
                        .position(|w| w == closing.as_slice())
                        .map_or(b.len(), |k| quote + 1 + k);
                    blank(&mut out, quote + 1, end);
                    i = end + closing.len();
                } else {
                    // An identifier (`r#type` included): skip it whole.
                    i += 1;
                    while i < b.len() && is_ident_byte(b[i]) {
                        i += 1;
                    }
                }
            }
            // A character literal ('x', '\n', '\u{..}', '"'), not a lifetime ('a).
            b'\'' => {
                if b.get(i + 1) == Some(&b'\\') {
                    // The closing quote comes after the escaped character ('\'' included).
                    let end =
                        b[i + 3..].iter().position(|&c| c == b'\'').map_or(b.len(), |k| i + 3 + k);
                    blank(&mut out, i + 1, end);
                    i = end + 1;
                } else if let Some(c) = text[i + 1..].chars().next() {
                    let end = i + 1 + c.len_utf8();
                    if b.get(end) == Some(&b'\'') {
                        blank(&mut out, i + 1, end);
                        i = end + 1;
                    } else {
                        i += 1;
                    }
                } else {
                    i += 1;
                }
            }
            _ => i += 1,
        }
    }
    // Whole characters are blanked or kept, so the bytes are still UTF-8.
    String::from_utf8(out).expect("blanking whole characters keeps UTF-8")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sources(files: &[(&str, &str)]) -> BTreeMap<PathBuf, String> {
        files.iter().map(|(p, t)| (PathBuf::from(p), t.to_string())).collect()
    }

    const MANIFEST: &str = r#"
[package]
name = "fake"
version = "0.1.0"

[dependencies]
used-dep = "1"
unused-dep = { version = "1", features = ["x"] }
renamed = { package = "real-name", version = "1" }
macro-dep.workspace = true

[dependencies.tabled]
version = "1"

[target.'cfg(unix)'.dependencies]
unix-only = "1"

[dev-dependencies]
test-only.workspace = true
built-only = { path = "../built-only" }

[build-dependencies]
builder = "1"

[package.metadata.tidy]
# built-only: the tests load its cdylib at run time; they do not link it.
unused-ok = ["built-only"]
"#;

    const LIB: &str = r#"
//! Uses `unused_dep::x` only in a comment, and in a string below.
use used_dep::Thing;
use std::fmt;

/// `unused_dep::y` in a doc comment.
pub fn f() -> &'static str {
    let _ = renamed::g(tabled::h());
    macro_dep!(1);
    unix_only::k();
    let _c = '"';
    "unused_dep::z and r\"unused_dep::w\""
}

#[cfg(test)]
mod tests;
"#;

    #[test]
    fn an_unused_dependency_is_flagged_and_used_or_excused_ones_pass() {
        let src = sources(&[
            ("src/lib.rs", LIB),
            ("src/tests.rs", "use test_only::t;\n"),
            ("build.rs", "fn main() { builder::run(); }\n"),
        ]);
        let problems = unused_dependencies(MANIFEST, &src);
        assert_eq!(problems.len(), 1, "{problems:#?}");
        assert!(problems[0].starts_with("fake: `unused-dep` in [dependencies]:"), "{problems:?}");
        assert!(problems[0].contains("remove it"), "{problems:?}");
    }

    #[test]
    fn each_table_counts_its_own_code() {
        // The dev-dependency named only in the library, the build-dependency only in the tests,
        // a dependency only in a #[cfg(test)] module, one only in an integration test.
        let manifest = r#"
[package]
name = "fake"
[dependencies]
lib-dep = "1"
only-in-tests = "1"
only-in-e2e = "1"
[dev-dependencies]
dev-dep = "1"
[build-dependencies]
builder = "1"
"#;
        let lib = "use lib_dep::a;\nfn f() { builder::b(); dev_dep::c(); }\n\
                   #[cfg(test)]\nmod tests {\n    use only_in_tests::d;\n}\n";
        let src = sources(&[("src/lib.rs", lib), ("tests/e2e.rs", "use only_in_e2e::e;\n")]);
        let problems = unused_dependencies(manifest, &src);
        let flagged: Vec<&str> =
            problems.iter().map(|p| p.split('`').nth(1).unwrap_or_default()).collect();
        assert_eq!(
            flagged,
            ["only-in-tests", "only-in-e2e", "dev-dep", "builder"],
            "{problems:#?}"
        );
        assert!(problems[0].contains("move it to [dev-dependencies]"), "{problems:?}");
        assert!(problems[1].contains("move it to [dev-dependencies]"), "{problems:?}");
    }

    #[test]
    fn modules_of_test_code_are_test_code() {
        let manifest = "[package]\nname = \"fake\"\n[dev-dependencies]\na = \"1\"\nb = \"1\"\n";
        // A #[cfg(test)] module with #[path], and a file it declares in turn; a file
        // outside the package that a test includes.
        let src = sources(&[
            ("src/lib.rs", "pub mod parser;\n"),
            ("src/parser.rs", "#[cfg(test)]\n#[path = \"parser_tests.rs\"]\nmod tests;\n"),
            ("src/parser_tests.rs", "mod more;\nuse a::x;\n"),
            ("src/parser_tests/more.rs", "fn g() {}\n"),
            ("tests/it.rs", "#[path = \"../../other/src/spec.rs\"]\nmod spec;\n"),
            ("../other/src/spec.rs", "fn f() { b::y(); }\n"),
        ]);
        assert_eq!(unused_dependencies(manifest, &src), Vec::<String>::new());
        // The same dependency named in a library module (not under cfg(test)) does not count.
        let src = sources(&[
            ("src/lib.rs", "pub mod parser;\n#[cfg(test)]\nmod t { use b::y; }\n"),
            ("src/parser.rs", "use a::x;\n"),
        ]);
        let problems = unused_dependencies(manifest, &src);
        assert_eq!(problems.len(), 1, "{problems:#?}");
        assert!(problems[0].contains("`a` in [dev-dependencies]"), "{problems:?}");
    }

    #[test]
    fn unused_ok_must_be_explained_and_current() {
        let manifest = "[package]\nname = \"fake\"\n[dev-dependencies]\nplugin = \"1\"\n\
                        named = \"1\"\n[package.metadata.tidy]\n\
                        unused-ok = [\n    \"plugin\",\n    \"named\",\n    \"gone\",\n]\n";
        let src = sources(&[("tests/t.rs", "use named::x;\n")]);
        let problems = unused_dependencies(manifest, &src);
        assert_eq!(problems.len(), 3, "{problems:#?}");
        assert!(problems[0].contains("`named`") && problems[0].contains("take it off"));
        assert!(problems[1].contains("\"gone\", which is not one of its dependencies"));
        assert!(problems[2].contains("has no comment"));
        // With a comment on its line, an entry is explained.
        let manifest = manifest.replace("\"plugin\",", "\"plugin\", # loaded, not linked");
        let manifest = manifest.replace("    \"named\",\n    \"gone\",\n", "");
        assert_eq!(unused_dependencies(&manifest, &src), Vec::<String>::new());
    }

    #[test]
    fn names_are_crate_paths_not_segments_or_other_words() {
        for code in [
            "use serde;",
            "pub use serde::Deserialize;",
            "#[derive(serde::Serialize)]",
            "let v = ::serde::x();",
            "extern crate serde;",
            "serde!(1)",
            "use serde as s;",
        ] {
            assert!(names_crate(code, "serde"), "{code}");
        }
        for code in [
            "crate::serde::x()",
            "self.serde::<u8>()",
            "my_serde::x()",
            "serde_json::to_string()",
            "let serde = 1;",
            "if serde != 2 {}",
            "Foo<T>::serde::x",
        ] {
            assert!(!names_crate(code, "serde"), "{code}");
        }
    }

    #[test]
    fn comments_and_literals_are_blanked_in_place() {
        let text = "a /* b /* c */ d */ e // f\ng \"h\\\"i\" r#\"j\"k\"# 'l' '\\'' 'm: &'n str br\"o\" r#type é\"p\"";
        let s = strip(text);
        assert_eq!(s.len(), text.len());
        let words: Vec<&str> = s.split(|c: char| !c.is_alphanumeric() && c != '#').collect();
        let words: Vec<&str> = words.into_iter().filter(|w| !w.is_empty()).collect();
        assert_eq!(words, ["a", "e", "g", "r#", "#", "m", "n", "str", "br", "r#type", "é"]);
        assert!(s.contains("r#type"));
    }

    #[test]
    fn tables_and_keys_are_read_as_cargo_writes_them() {
        let m = parse_manifest(MANIFEST);
        let deps: Vec<(&str, Kind)> =
            m.dependencies.iter().map(|d| (d.key.as_str(), d.kind)).collect();
        assert_eq!(
            deps,
            [
                ("used-dep", Kind::Normal),
                ("unused-dep", Kind::Normal),
                ("renamed", Kind::Normal),
                ("macro-dep", Kind::Normal),
                ("tabled", Kind::Normal),
                ("unix-only", Kind::Normal),
                ("test-only", Kind::Dev),
                ("built-only", Kind::Dev),
                ("builder", Kind::Build),
            ]
        );
        assert_eq!(m.dependencies[4].table, "[dependencies]");
        assert_eq!(m.dependencies[5].table, "[target.'cfg(unix)'.dependencies]");
        assert_eq!(
            (m.package.as_str(), m.unused_ok.as_slice()),
            ("fake", &["built-only".to_string()][..])
        );
        assert!(m.unused_ok_explained);
    }
}

//! The runs a command reads: run CSVs, Renishaw `.b5r` files (each of their runs a run) and
//! folders of both. The vendor's own analysis of a `.b5r` file is kept beside its runs, for
//! the comparison with ours.

use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context, anyhow};
use ballbar_io::b5r::{self, B5rOptions, B5rTest};
use ballbar_model::Run;

use crate::{Failure, Result};

/// A `.b5r` file's analysis and where its runs sit among the command's runs.
pub struct VendorTest {
    /// The file as read; its `runs` are moved into [`Inputs::runs`] (this list is empty).
    pub test: B5rTest,
    /// The indices of its runs in [`Inputs::runs`].
    pub runs: Range<usize>,
}

/// What a command read.
pub struct Inputs {
    /// Every run, in the order of the files (folders sorted by name).
    pub runs: Vec<Run>,
    /// The vendor files among them.
    pub vendor: Vec<VendorTest>,
    /// The circle centre the `.b5r` runs use, and whether the user gave it.
    pub pivot: Option<([f64; 3], bool)>,
}

/// How `.b5r` samples are placed on the circle (`--b5r-angles`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Angles {
    /// As the machine moved: spaced by the programmed feed (when the file's arc agrees with it).
    #[default]
    Machine,
    /// The vendor's convention: the analysed arc's samples spread evenly over it.
    Vendor,
}

impl Angles {
    /// The reader's option.
    pub fn spacing(self) -> b5r::AngleSpacing {
        match self {
            Angles::Machine => b5r::AngleSpacing::Machine,
            Angles::Vendor => b5r::AngleSpacing::Vendor,
        }
    }
}

/// What a `.b5r` file does not give about the set-up: where its circle is (`--pivot`) and where
/// the tool ball is on the spindle (`--tool-ball-mm`). A run CSV states both in its header;
/// giving either without a `.b5r` file among the inputs is an error.
#[derive(clap::Args, Clone, Copy, Debug, Default, PartialEq)]
pub struct Placement {
    /// The circle centre in machine coordinates of the runs whose file does not give it
    /// (`.b5r` files; plain tables in `import`), mm (default 0,0,0).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_pivot, allow_hyphen_values = true)]
    pub pivot: Option<[f64; 3]>,
    /// The tool-ball centre from the spindle gauge point, in the spindle frame, of the runs
    /// whose file does not give it (`.b5r` files; plain tables in `import`), mm: z is minus the
    /// tool length (without it the runs are taken at 0,0,0 and the output says so).
    #[arg(long = "tool-ball-mm", value_name = "X,Y,Z", value_parser = parse_tool_ball, allow_hyphen_values = true)]
    pub tool_ball_mm: Option<[f64; 3]>,
}

impl Placement {
    /// Neither given.
    pub fn is_empty(&self) -> bool {
        self.pivot.is_none() && self.tool_ball_mm.is_none()
    }

    /// The options given, as they were spelled (for messages).
    pub fn given(&self) -> Vec<&'static str> {
        [self.pivot.map(|_| "--pivot"), self.tool_ball_mm.map(|_| "--tool-ball-mm")]
            .into_iter()
            .flatten()
            .collect()
    }
}

/// Three finite numbers `X,Y,Z`, or what `example` shows.
fn parse_point(text: &str, example: &str) -> std::result::Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let values: Vec<f64> =
        parts.iter().filter_map(|p| p.parse::<f64>().ok().filter(|v| v.is_finite())).collect();
    match <[f64; 3]>::try_from(values) {
        Ok(v) if parts.len() == 3 => Ok(v),
        _ => Err(format!("{text:?} is not three finite numbers X,Y,Z in mm (say {example})")),
    }
}

/// Parse `--tool-ball-mm X,Y,Z` (mm).
pub fn parse_tool_ball(text: &str) -> std::result::Result<[f64; 3], String> {
    parse_point(text, "--tool-ball-mm 0,0,-100 for a tool length of 100 mm")
}

/// Parse `--pivot X,Y,Z` (mm).
pub fn parse_pivot(text: &str) -> std::result::Result<[f64; 3], String> {
    parse_point(text, "--pivot 400,200,-300")
}

/// The files named by `paths`: files as given, folders as their `*.csv` and `*.b5r` files
/// (sorted). The same file named twice (directly, through a folder, or by another path) is
/// an error: its runs would count twice.
pub fn files(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut in_dir: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("{}: cannot list the folder", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    f.is_file() && (f.extension().is_some_and(|x| x == "csv") || b5r::is_b5r(f))
                })
                .collect();
            in_dir.sort();
            if in_dir.is_empty() {
                return Err(Failure::Input(anyhow!(
                    "{}: no *.csv run files or *.b5r files in this folder",
                    p.display()
                )));
            }
            files.extend(in_dir);
        } else {
            files.push(p.clone());
        }
    }
    let mut seen: Vec<(PathBuf, &Path)> = Vec::with_capacity(files.len());
    for f in &files {
        // A file that cannot be resolved is reported by its reader.
        let Ok(real) = std::fs::canonicalize(f) else { continue };
        if let Some((_, first)) = seen.iter().find(|(r, _)| *r == real) {
            return Err(Failure::Input(anyhow!(
                "{}: the same run file is given twice (also as {}); its runs would count twice",
                f.display(),
                first.display()
            )));
        }
        seen.push((real, f));
    }
    Ok(files)
}

/// The runs' `machine:` headers against the machine they are fitted with (`name`): a run that
/// names another machine, or runs that name two, are refused, naming the files. The header is
/// informative in the run format, but when given it is the one statement of which machine the
/// run is of: a column machine's runs fitted as a horizontal machine, or two machines' runs in
/// one fit, give numbers of neither without a word. A run without the header is taken as the
/// machine given (a `.b5r` file names none).
pub fn check_machine(inputs: &Inputs, name: &str) -> Result<()> {
    let named: Vec<(&str, &str)> = inputs
        .runs
        .iter()
        .filter_map(|r| {
            r.header
                .machine
                .as_deref()
                .filter(|m| !m.trim().is_empty())
                .map(|m| (m, r.source.as_str()))
        })
        .collect();
    if let Some((other, file)) = named.iter().find(|(m, _)| *m != name) {
        let first_other = named.iter().find(|(m, _)| m == other).map(|x| x.1).unwrap_or(file);
        return Err(Failure::Input(anyhow!(
            "{first_other}: the run is of machine '{other}' (its header's machine), but the fit is of machine '{name}': fit it with that machine, or correct the header if the run really is of '{name}'"
        )));
    }
    Ok(())
}

/// Read every run of `paths`, in parallel. `placement` places the `.b5r` files' circles and
/// tool balls; it is an error when no `.b5r` file is among the inputs (a run CSV states its
/// own `pivot_mm` and `tool_ball_mm`).
pub fn read(
    paths: &[PathBuf],
    threads: usize,
    placement: Placement,
    angles: b5r::AngleSpacing,
) -> Result<Inputs> {
    let pivot = placement.pivot;
    let files = files(paths)?;
    enum One {
        Csv(Box<Run>),
        B5r(B5rTest),
    }
    let options = B5rOptions { pivot_mm: pivot, tool_ball_mm: placement.tool_ball_mm, angles };
    let read = ballbar_model::parallel::par_map(
        files.len(),
        threads,
        |k| -> std::result::Result<One, ballbar_io::IoError> {
            let f = &files[k];
            if b5r::is_b5r(f) {
                b5r::read_b5r(f, &options).map(One::B5r)
            } else {
                ballbar_io::read_run(f).map(|run| One::Csv(Box::new(run)))
            }
        },
    );
    let mut inputs = Inputs { runs: Vec::new(), vendor: Vec::new(), pivot: None };
    for one in read {
        match one? {
            One::Csv(run) => inputs.runs.push(*run),
            One::B5r(mut test) => {
                let start = inputs.runs.len();
                inputs.runs.append(&mut test.runs);
                inputs.vendor.push(VendorTest { test, runs: start..inputs.runs.len() });
            }
        }
    }
    check_same_samples(&inputs.runs)?;
    warn(&inputs.runs);
    if inputs.vendor.is_empty() {
        if !placement.is_empty() {
            return Err(Failure::Input(anyhow!(
                "{} {} the runs of .b5r files, and none is among the inputs (a run CSV gives its own pivot_mm and tool_ball_mm)",
                placement.given().join(" and "),
                if placement.given().len() == 1 { "places" } else { "place" }
            )));
        }
    } else {
        inputs.pivot = Some((pivot.unwrap_or(b5r::DEFAULT_PIVOT_MM), pivot.is_some()));
    }
    Ok(inputs)
}

/// States what the runs' data say is unusual about them (`ballbar_io::check::warnings`: a
/// duration a little off the path over the feed, readings that barely move), one line each,
/// naming the file (and the run, for a `.b5r` file).
pub fn warn(runs: &[Run]) {
    for run in runs {
        for w in ballbar_io::check::warnings(run) {
            match &run.header.run_id {
                Some(id) if b5r::is_b5r(Path::new(&run.source)) => {
                    eprintln!("warning: {} (run {id}): {w}", run.source)
                }
                _ => eprintln!("warning: {}: {w}", run.source),
            }
        }
    }
}

/// The same measurement twice among a command's runs is refused, naming both: a copy of a run
/// file, a copy with another header, or a `.b5r` file beside the run CSVs imported from it
/// (`Run::sample_digest`: the times and readings). Fitted twice, a run would shrink the
/// uncertainties as if measured twice; diagnosed, it would pass for a repeat that agrees to
/// the last digit (a noise floor of 0).
fn check_same_samples(runs: &[Run]) -> Result<()> {
    let mut seen: std::collections::HashMap<u64, Vec<usize>> =
        std::collections::HashMap::with_capacity(runs.len());
    for (i, run) in runs.iter().enumerate() {
        let same = seen.entry(run.sample_digest()).or_default();
        if let Some(&j) = same.iter().find(|&&j| runs[j].same_samples(run)) {
            let first = &runs[j];
            let name = |r: &Run| match &r.header.run_id {
                Some(id) if r.source.to_ascii_lowercase().ends_with(".b5r") => {
                    format!(" (run {id})")
                }
                _ => String::new(),
            };
            return Err(Failure::Input(anyhow!(
                "{}{}: its samples are those of {}{} (the same {} readings at the same times): the same measurement would count twice; give it once",
                run.source,
                name(run),
                first.source,
                name(first),
                run.len()
            )));
        }
        same.push(i);
    }
    Ok(())
}

/// The line that says where the `.b5r` circles were placed, for the terminal.
pub fn pivot_note(inputs: &Inputs) -> Option<String> {
    inputs.pivot.map(|(p, given)| {
        if given {
            format!("circle centre of the .b5r runs: {}, {}, {} mm (--pivot)", p[0], p[1], p[2])
        } else {
            format!(
                "circle centre of the .b5r runs: {}, {}, {} mm, the default (a .b5r file does not give it; set it with --pivot X,Y,Z)",
                p[0], p[1], p[2]
            )
        }
    })
}

/// The `note:` line that states the defaults taken for `runs` that change a result
/// (`ballbar_report::assumed`), for every command that fits or predicts from runs; `None` when
/// every run gives what the result depends on.
pub fn geometry_note<'a>(runs: impl IntoIterator<Item = &'a Run>) -> Option<String> {
    ballbar_report::assumed::note(runs).map(|n| format!("note: {n}"))
}

/// The input error of a fit with no finite solution ([`ballbar_fit::FitError::NonFinite`]):
/// the error, and where the largest number of the runs is, the likeliest to be too large for
/// the arithmetic (the readers refuse a reading that large; a coordinate, a radius or a time
/// can still be).
pub fn no_finite_fit(e: impl std::fmt::Display, runs: &[Run]) -> Failure {
    match largest_number(runs) {
        Some(at) => Failure::Input(anyhow!("{e}; the largest number in the runs: {at}")),
        None => Failure::Input(anyhow!("{e}")),
    }
}

/// The runs' number of the largest magnitude (in mm, rad and s, as the fit sees them), as
/// `file:line: column C: value` in the file's units (`file: key: value` for a header value).
fn largest_number(runs: &[Run]) -> Option<String> {
    let shown = |v: f64| if v.abs() < 1e9 { v.to_string() } else { format!("{v:e}") };
    let mut best: Option<(f64, String)> = None;
    let mut consider = |magnitude: f64, at: &dyn Fn() -> String| {
        if best.as_ref().is_none_or(|(b, _)| magnitude > *b) {
            best = Some((magnitude, at()));
        }
    };
    for run in runs {
        let h = &run.header;
        let header = [("radius_mm", h.radius_mm), ("feed_mm_per_min", h.feed_mm_per_min)]
            .into_iter()
            .chain(h.pivot_mm.map(|v| ("pivot_mm", v)))
            .chain(h.table_ball_mm.map(|v| ("table_ball_mm", v)))
            .chain(h.tool_ball_mm.map(|v| ("tool_ball_mm", v)));
        for (key, v) in header {
            consider(v.abs(), &|| format!("{}: {key}: {}", run.source, shown(v)));
        }
        let line = |i: usize| run.lines.get(i).copied().unwrap_or(0);
        let mut columns: Vec<(&str, &[f64], f64)> = vec![("t_s", &run.t_s, 1.0)];
        for a in ballbar_model::Axis::ALL {
            if let Some(c) = run.axis(a) {
                let display = if a.is_rotary() { 1f64.to_degrees() } else { 1.0 };
                columns.push((a.column_name(), c, display));
            }
        }
        columns.push(("dR_um", &run.dr_mm, 1e3));
        for (name, values, display) in columns {
            let Some((i, v)) =
                values.iter().enumerate().max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
            else {
                continue;
            };
            consider(v.abs(), &|| {
                format!("{}:{}: column {name}: {}", run.source, line(i), shown(v * display))
            });
        }
    }
    best.map(|(_, at)| at)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fit with no finite solution names where the largest number of the runs is, in the
    /// file's units.
    #[test]
    fn a_fit_without_a_finite_solution_names_the_largest_number_and_its_line() {
        let text = "# ballbar-run: 1\n# plane: free\n# radius_mm: 100\n# feed_mm_per_min: 1000\n\
                    # pivot_mm: 0, 0, 0\n# started_at: 2026-11-21T10:00:00Z\n\
                    t_s,X_mm,C_deg,dR_um\n0,1,0,0.5\n0.1,2e200,90,0.5\n0.2,3,180,-2\n";
        let run = ballbar_io::parse_run(text, "runs/free.csv").unwrap();
        let Failure::Input(e) = no_finite_fit(ballbar_fit::FitError::NonFinite, &[run]) else {
            panic!("an input error");
        };
        assert!(
            e.to_string()
                .ends_with("the largest number in the runs: runs/free.csv:9: column X_mm: 2e200"),
            "{e}"
        );
        let mut run = ballbar_io::parse_run(&text.replace("2e200", "2"), "f.csv").unwrap();
        run.header.pivot_mm[1] = -1e300;
        let Failure::Input(e) = no_finite_fit(ballbar_fit::FitError::NonFinite, &[run]) else {
            panic!("an input error");
        };
        assert!(e.to_string().ends_with("runs: f.csv: pivot_mm: -1e300"), "{e}");
    }
}

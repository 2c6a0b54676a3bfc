//! `ballbar program`: the part program (ISO G-code, [`ballbar_io::gcode`]) of each test, one
//! `<run-id>.nc` per run, from the commanded runs of a truth file (the runs `ballbar simulate`
//! writes: the same ids, in the same order) and from run files (a run file's path is the
//! commanded path).
//!
//! The truth file's runs are made by the simulator itself ([`crate::simulation`], the code path
//! of `simulate`): `ballbar_sim` has no public function that gives the commanded runs without
//! their readings, and building them here again would copy its run ids and its clock. The
//! readings it computes are not used (a program follows the commanded path alone); they cost a
//! fraction of a second for the shipped truth files.
//!
//! Nothing is half-written and nothing is overwritten unasked (as `import`): every input is read,
//! every program made and every target checked ([`crate::outputs`]) before the first file is
//! written, and the files are written all or none; an existing file is replaced only with
//! `--force`, and an input never.

use std::path::{Component, Path, PathBuf};

use anyhow::anyhow;
use ballbar_io::gcode::{self, GcodeError, ProgramOptions};
use ballbar_model::{Plane, Run};
use ballbar_plugin_host::Registry;

use crate::{Failure, MachineArgs, OptionalMachineArgs, Result, inputs};

/// The arguments of `ballbar program`.
#[derive(clap::Args, Debug)]
pub struct ProgramArgs {
    /// Run files (run CSVs, `.b5r` files) or folders of them: the program of each run's
    /// commanded path.
    #[arg(required_unless_present = "truth")]
    runs: Vec<PathBuf>,
    /// The machine of the truth file.
    #[command(flatten)]
    machine: OptionalMachineArgs,
    /// Truth file (RON, as for `simulate`): the program of each of its runs (with --machine or
    /// --machine-file).
    #[arg(long, value_name = "FILE")]
    truth: Option<PathBuf>,
    /// Output folder for the programs (`<run-id>.nc`).
    #[arg(long)]
    out: PathBuf,
    /// Rotary runs: the largest rotary motion of one G1 block, degrees (default 0.1; the chord
    /// error between block ends grows with its square).
    #[arg(long, value_name = "DEG")]
    max_step_deg: Option<f64>,
    /// The lead-in clears this far in +Z above the start point before the other axes move, mm
    /// (default 20).
    #[arg(long, value_name = "MM")]
    clearance_mm: Option<f64>,
    /// Planar runs: the feed-in arc before the data arc and the over-shoot arc after it,
    /// degrees each (default 180 for a full circle, 2 for a partial arc)
    #[arg(long, value_name = "DEG")]
    overshoot_deg: Option<f64>,
    #[command(flatten)]
    placement: inputs::Placement,
    /// How `.b5r` samples are placed on the circle (as for `fit`).
    #[arg(long, value_enum, default_value = "machine")]
    b5r_angles: inputs::Angles,
    /// Replace programs that already exist in the output folder.
    #[arg(long)]
    force: bool,
}

/// A commanded run and where it came from, for messages.
struct Source {
    run: Run,
    /// The truth file that made it, or `None` for a run read from its own file.
    truth: Option<PathBuf>,
}

impl Source {
    /// The file to name in a message about this run.
    fn file(&self) -> String {
        match &self.truth {
            Some(t) => t.display().to_string(),
            None => self.run.source.clone(),
        }
    }
}

/// A program made and where it goes.
#[derive(Debug)]
pub(crate) struct Made {
    /// `DIR/<run-id>.nc`.
    pub target: PathBuf,
    /// The program.
    pub text: String,
    /// What the program's header says of its motion, for the terminal.
    pub summary: String,
}

/// `ballbar program [RUN...] [--machine NAME | --machine-file FILE --truth FILE] --out DIR`.
pub fn program(args: &ProgramArgs, reg: &Registry) -> Result<()> {
    let given = MachineArgs {
        machine: args.machine.machine.clone(),
        machine_file: args.machine.machine_file.clone(),
    };
    let has_machine = given.machine.is_some() || given.machine_file.is_some();
    match (&args.truth, has_machine) {
        (Some(t), false) => {
            return Err(Failure::Usage(anyhow!(
                "--truth {} needs the machine it describes: --machine NAME or --machine-file FILE",
                t.display()
            )));
        }
        (None, true) => {
            return Err(Failure::Usage(anyhow!(
                "--machine and --machine-file are for --truth FILE (a run file's path is already in machine coordinates)"
            )));
        }
        _ => {}
    }
    let mut options = ProgramOptions::default();
    if let Some(x) = args.max_step_deg {
        options.max_step_deg = x;
    }
    if let Some(x) = args.clearance_mm {
        options.clearance_mm = x;
    }
    options.overshoot_deg = args.overshoot_deg;

    let mut sources = Vec::new();
    if let Some(truth) = &args.truth {
        let m = crate::machine(&given, reg)?;
        let sim = crate::simulation(&m, truth, 0, None)?;
        sources.extend(sim.runs.into_iter().map(|run| Source { run, truth: Some(truth.clone()) }));
    }
    let mut input_files = Vec::new();
    if !args.runs.is_empty() {
        input_files = inputs::files(&args.runs)?;
        let read = inputs::read(&args.runs, 2, args.placement, args.b5r_angles.spacing())?;
        sources.extend(read.runs.into_iter().map(|run| Source { run, truth: None }));
    } else if !args.placement.is_empty() {
        return Err(Failure::Usage(anyhow!(
            "{} place the runs of .b5r files, and no run file is given",
            args.placement.given().join(" and ")
        )));
    }

    let made = programs(&sources, &options, &args.out)?;
    input_files.extend(args.truth.iter().cloned());
    input_files.extend(given.machine_file.iter().cloned());
    input_files.extend(crate::outputs::loaded(reg));
    check_targets(&made, &input_files, args.force)?;
    std::fs::create_dir_all(&args.out)
        .map_err(|e| anyhow!("{}: cannot create the folder: {e}", args.out.display()))?;
    let files: Vec<(PathBuf, String)> =
        made.iter().map(|m| (m.target.clone(), m.text.clone())).collect();
    crate::outputs::write_all(&files, args.force)?;
    for m in &made {
        outln!("wrote {}: {}", m.target.display(), m.summary);
    }
    outln!(
        "note: the programs are in machine-axis coordinates as the runs: G54 a zero offset (the chain file's frame), tool centre point control off, no tool length compensation; check the lead-in from where the machine stands"
    );
    Ok(())
}

/// The program of every run (in order), each named `<run-id>.nc` in `out` (a run without id:
/// its file's stem). Errors name the file and what is wrong: a run that cannot be written as a
/// program, an id that is not a file name, two runs with one name; an option out of range is a
/// usage error.
fn programs(sources: &[Source], options: &ProgramOptions, out: &Path) -> Result<Vec<Made>> {
    let mut made: Vec<Made> = Vec::with_capacity(sources.len());
    for s in sources {
        let run = &s.run;
        let name = program_name(run)
            .map_err(|why| Failure::Input(anyhow!("{}: run {:?}: {why}", s.file(), run.name())))?;
        let target = out.join(format!("{name}.nc"));
        if let Some(j) = made.iter().position(|m| m.target == target) {
            return Err(Failure::Input(anyhow!(
                "{}: runs {} ({}) and {} ({}) would both be written there; nothing was written",
                target.display(),
                sources[j].run.name(),
                sources[j].file(),
                run.name(),
                s.file()
            )));
        }
        let text = gcode::program(run, options).map_err(|e| match e {
            GcodeError::Options { option, message } => {
                Failure::Usage(anyhow!("--{}: {message}", option.replace('_', "-")))
            }
            e => {
                // A run file's sample errors already name the file and line.
                let text = e.to_string();
                let file = s.file();
                if s.truth.is_none() && text.contains(&file) {
                    Failure::Input(anyhow!("cannot be written as a part program: {text}"))
                } else {
                    Failure::Input(anyhow!("{file}: cannot be written as a part program: {text}"))
                }
            }
        })?;
        let summary = summary(run, &text);
        made.push(Made { target, text, summary });
    }
    Ok(made)
}

/// The program's file name without `.nc`: the run id, else the run file's stem. It must be one
/// plain file name: an id like `../x` or `a/b` would write outside the folder.
fn program_name(run: &Run) -> std::result::Result<String, String> {
    let name = match &run.header.run_id {
        Some(id) => id.clone(),
        None => Path::new(&run.source)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
    };
    let mut parts = Path::new(&name).components();
    let plain = matches!((parts.next(), parts.next()), (Some(Component::Normal(n)), None) if n == name.as_str());
    if name.trim().is_empty() || !plain || name.contains(['/', '\\']) {
        return Err(format!(
            "{name:?} is not a file name for its program (a run id without folders or '/')"
        ));
    }
    Ok(name)
}

/// One line of what the program's header says: a planar run's arc and over-shoot, a rotary
/// run's blocks and the chord figure (how far between block ends the axes leave the run).
fn summary(run: &Run, text: &str) -> String {
    let h = &run.header;
    let comments: Vec<&str> = text
        .lines()
        .filter_map(|l| l.strip_prefix('(').and_then(|l| l.strip_suffix(')')))
        .collect();
    let find = |prefix: &str| comments.iter().find(|c| c.starts_with(prefix)).copied();
    match h.plane {
        Plane::Free => {
            let blocks =
                comments.iter().find(|c| c.contains(" G1 blocks in inverse time")).copied();
            let chords = find("between block ends");
            let mut s = String::from("rotary run");
            for part in blocks.into_iter().chain(chords) {
                s.push_str("; ");
                s.push_str(part);
            }
            s
        }
        plane => {
            let direction = h.direction.map(|d| format!(" {d}")).unwrap_or_default();
            let mut s = format!("{plane}{direction}");
            // The over-shoot's line without its feed, which the run's header already says.
            let overshoot = find("over-shoot: ").map(|o| o.split(';').next().unwrap_or(o));
            for part in find("arc: ").into_iter().chain(overshoot) {
                s.push_str(", ");
                s.push_str(part);
            }
            s
        }
    }
}

/// Every target checked before anything is written ([`crate::outputs::check`]).
fn check_targets(made: &[Made], input_files: &[PathBuf], force: bool) -> Result<()> {
    let targets: Vec<crate::outputs::Output> =
        made.iter().map(|m| crate::outputs::Output::new(&m.target, "--out")).collect();
    crate::outputs::check(&targets, input_files, force, "programs")
}

#[cfg(test)]
mod tests {
    use super::*;
    use ballbar_model::chain::JointKind;
    use ballbar_model::machine::{AxisNorm, JointSpec, MachineSpec, ModelOptions, linear};
    use ballbar_model::{Axis, Direction};
    use ballbar_sim::{RotarySpec, TestSpec, Truth, TurnSpec};

    /// A four-axis machine without error terms: X, Y, C table; Z head.
    fn machine() -> MachineSpec {
        MachineSpec {
            name: "xyzc".into(),
            version: "1".into(),
            description: "test machine".into(),
            tool: vec![linear("Z", Axis::Z, [0.0; 3])],
            workpiece: vec![
                linear("Y", Axis::Y, [0.0; 3]),
                linear("X", Axis::X, [0.0; 3]),
                JointSpec {
                    name: "C".into(),
                    axis: Axis::C,
                    kind: JointKind::Rotary,
                    direction: [0.0, 0.0, 1.0],
                    origin_mm: [0.0; 3],
                },
            ],
            normalisation: Axis::LINEAR
                .iter()
                .map(|&axis| AxisNorm { axis, reference_mm: 0.0, length_mm: 250.0 })
                .collect(),
            terms: vec![],
        }
    }

    fn truth() -> Truth {
        let test = |plane, rotary| TestSpec {
            plane,
            directions: vec![Direction::CCW, Direction::CW],
            radius_mm: 100.0,
            feed_mm_per_min: 1000.0,
            pivot_mm: [100.0, 0.0, 150.0],
            table_ball_mm: [0.0; 3],
            tool_ball_mm: [0.0, 0.0, -100.0],
            repeats: 1,
            start_deg: 0.0,
            sweep_deg: 360.0,
            rotary,
        };
        let c = RotarySpec {
            turns: vec![TurnSpec { axis: Axis::C, start_deg: 0.0, sweep_deg: 90.0 }],
            hold: vec![],
            bar: ballbar_model::path::BarDirection::Radial,
        };
        Truth {
            servo: Default::default(),
            errors: Default::default(),
            paper: None,
            bar_length_um: 0.0,
            centring_sd_um: 0.0,
            noise_um: 0.0,
            noise_correlation_ms: 0.0,
            sample_rate_hz: 20.0,
            started_at: "2026-12-02T09:00:00Z".into(),
            pause_s: 0.0,
            tests: vec![test(Plane::XY, None), test(Plane::Free, Some(c))],
            effects: vec![],
        }
    }

    fn sources() -> Vec<Source> {
        let sim = ballbar_sim::simulate(&machine(), &truth(), 0.0, 0).unwrap();
        sim.runs
            .into_iter()
            .map(|run| Source { run, truth: Some(PathBuf::from("t.truth.ron")) })
            .collect()
    }

    #[test]
    fn every_run_gets_its_program_named_by_its_id_with_the_header_s_chord_figure() {
        // Sanity of the machine: it validates.
        ballbar_model::machine::Model::new(machine(), ModelOptions::default()).unwrap();
        let made = programs(&sources(), &ProgramOptions::default(), Path::new("out")).unwrap();
        let names: Vec<String> = made.iter().map(|m| m.target.display().to_string()).collect();
        assert_eq!(
            names,
            ["out/xy-ccw-1.nc", "out/xy-cw-1.nc", "out/c-radial-ccw-1.nc", "out/c-radial-cw-1.nc"]
        );
        // A planar run states its arc; a rotary run its blocks and the chords between them.
        assert!(made[0].summary.starts_with("XY CCW, arc: from "), "{}", made[0].summary);
        assert!(made[0].summary.contains("G3 in G17"), "{}", made[0].summary);
        assert!(made[0].summary.ends_with(", over-shoot: 180.0000 deg, a feed-in arc before the data arc and an over-shoot arc after it"), "{}", made[0].summary);
        for m in &made[2..] {
            assert!(m.summary.contains("G1 blocks in inverse time"), "{}", m.summary);
            assert!(
                m.summary.contains("chords up to ") && m.summary.contains(" mm in X Y Z"),
                "{}",
                m.summary
            );
            // The line is the header's own.
            let chord = m.summary.split("; ").last().unwrap();
            assert!(m.text.contains(&format!("({chord})")), "{chord}");
        }
        // Each program reads back.
        for m in &made {
            assert!(!gcode::parse(&m.text).unwrap().is_empty());
        }
    }

    #[test]
    fn options_out_of_range_are_usage_errors_naming_the_flag() {
        let mut o = ProgramOptions::default();
        o.max_step_deg = 0.0;
        match programs(&sources(), &o, Path::new("out")) {
            Err(Failure::Usage(e)) => assert!(e.to_string().starts_with("--max-step-deg: "), "{e}"),
            other => panic!("{other:?}"),
        }
        let mut o = ProgramOptions::default();
        o.clearance_mm = -1.0;
        match programs(&sources(), &o, Path::new("out")) {
            Err(Failure::Usage(e)) => assert!(e.to_string().starts_with("--clearance-mm: "), "{e}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_run_id_that_is_not_a_file_name_or_twice_the_same_is_an_input_error() {
        for bad in ["../x", "a/b", "..", "", "a\\b"] {
            let mut s = sources();
            s[0].run.header.run_id = Some(bad.into());
            match programs(&s, &ProgramOptions::default(), Path::new("out")) {
                Err(Failure::Input(e)) => {
                    assert!(e.to_string().starts_with("t.truth.ron: run "), "{bad}: {e}")
                }
                other => panic!("{bad}: {other:?}"),
            }
        }
        let mut s = sources();
        s[1].run.header.run_id = Some("xy-ccw-1".into());
        match programs(&s, &ProgramOptions::default(), Path::new("out")) {
            Err(Failure::Input(e)) => {
                assert!(e.to_string().contains("would both be written there"), "{e}")
            }
            other => panic!("{other:?}"),
        }
        // Without an id, the file's stem.
        let mut s = sources();
        s[0].run.header.run_id = None;
        s[0].run.source = "some/where/circle.csv".into();
        let made = programs(&s[..1], &ProgramOptions::default(), Path::new("out")).unwrap();
        assert_eq!(made[0].target, Path::new("out/circle.nc"));
    }

    #[test]
    fn a_run_that_is_not_a_program_names_its_file() {
        let mut s = sources();
        s[0].truth = None;
        s[0].run.source = "runs/xy.csv".into();
        s[0].run.header.feed_mm_per_min = 0.0;
        match programs(&s, &ProgramOptions::default(), Path::new("out")) {
            Err(Failure::Input(e)) => {
                let t = e.to_string();
                assert!(t.starts_with("runs/xy.csv: cannot be written as a part program: run xy-ccw-1: feed_mm_per_min is 0"), "{t}");
            }
            other => panic!("{other:?}"),
        }
    }
}

//! The writer: checks the session, streams it into a temporary file next to the target, syncs
//! it and gives it the target's name ([`ballbar_io::atomic`]: over an existing archive only
//! when asked to replace it).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use ballbar_io::atomic::{Existing, Temporary, follow_links};
use ballbar_model::{Axis, Run};
use mcap::records::{AttachmentHeader, MessageHeader, Metadata};

use crate::json::{self, Displayer, HeaderMsg, ResidualMsg, SampleMsg};
use crate::{ArchiveError, PAUSE_ENV, SCHEMA_VERSION, Session, WriteStats};

/// Largest JSON message the writer accepts, bytes. The reader's limit on a decompressed chunk
/// ([`crate::read`]) is set from it.
pub(crate) const MAX_MESSAGE_BYTES: usize = 32 << 20;

/// zstd level of the chunks. On a 5655-sample fixture run: level 3 (zstd's default) gives
/// 0.87 of the CSV's size, 9 gives 0.83 at under 40 ms per 10,000 samples, 19 gives 0.71 but
/// takes ten times longer. What remains is mostly the message framing and the uncompressed
/// message indexes (16 bytes per sample), which indexed readers (Foxglove) need.
const ZSTD_LEVEL: u32 = 9;

/// Target uncompressed chunk size (the mcap crate's default).
const CHUNK_BYTES: u64 = 1 << 20;

/// Where the writer is; passed to the observer of [`write_observed`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum WritePhase<'a> {
    /// The temporary file was created (empty).
    Started {
        /// The temporary file.
        temporary: &'a Path,
    },
    /// The header and samples of run `index` are in the temporary file (its chunk finished and
    /// handed to the OS).
    RunWritten {
        /// Position of the run in the session.
        index: usize,
        /// The temporary file.
        temporary: &'a Path,
    },
    /// The temporary file is complete and synced to disk; the rename over the target follows.
    Complete {
        /// The temporary file.
        temporary: &'a Path,
    },
}

/// Write `session` to `path` atomically; see the crate documentation for the layout.
///
/// Readers of `path` see the previous file (or none) or the complete new one, never a part; a
/// process killed while writing leaves at most a `.{name}.{pid}.{n}.tmp` file beside it. An
/// existing archive is replaced only under [`Existing::Replace`], keeping its permission bits
/// and owner; under [`Existing::Keep`] the archive takes its name only if the name is still
/// free when it is complete, so that an archive another command wrote meanwhile is kept (the
/// error is an [`ArchiveError::Io`] of kind `AlreadyExists`). The session is checked first: a
/// non-finite run value, columns of different lengths or residuals that do not match the runs
/// are [`ArchiveError::Unwritable`] and nothing is created.
pub fn write(
    path: &Path,
    session: &Session,
    existing: Existing,
) -> Result<WriteStats, ArchiveError> {
    write_observed(path, session, existing, &mut |_| {})
}

/// [`write()`], calling `observe` at each [`WritePhase`] (for progress, and for tests of the
/// atomicity).
pub fn write_observed(
    path: &Path,
    session: &Session,
    existing: Existing,
    observe: &mut dyn FnMut(WritePhase<'_>),
) -> Result<WriteStats, ArchiveError> {
    let io = |error| ArchiveError::Io { path: path.to_path_buf(), error };
    check(session)
        .map_err(|message| ArchiveError::Unwritable { path: path.to_path_buf(), message })?;
    // Through a symbolic link to its target (renaming over the link would replace it). An
    // archive is a file: a target that is not a regular file is refused.
    let target = follow_links(path).map_err(io)?;
    if std::fs::metadata(&target).is_ok_and(|m| !m.is_file()) {
        return Err(io(std::io::Error::other(
            "not a regular file: an archive is written to a file",
        )));
    }
    let pause = std::env::var(PAUSE_ENV)
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
        .map(std::time::Duration::from_millis);
    // From here on the temporary file is removed on every way out but success (when
    // `temporary` is dropped).
    let (mut temporary, file) = Temporary::create(&target, existing).map_err(io)?;
    let tmp = temporary.path().to_path_buf();
    observe(WritePhase::Started { temporary: &tmp });
    let mut run_written = |index: usize| {
        observe(WritePhase::RunWritten { index, temporary: &tmp });
        if let Some(p) = pause {
            std::thread::sleep(p);
        }
    };
    let file = write_mcap(file, session, &mut run_written).map_err(|e| match e {
        Failure::Io(e) => io(e),
        Failure::Mcap(e) => io(std::io::Error::other(e)),
        Failure::Content(message) => ArchiveError::Unwritable { path: path.to_path_buf(), message },
    })?;
    let bytes = file.metadata().map_err(io)?.len();
    temporary.finish(file).map_err(io)?;
    observe(WritePhase::Complete { temporary: &tmp });
    temporary.commit().map_err(io)?;
    Ok(WriteStats {
        bytes,
        samples: session.runs.iter().map(|r| r.run.len()).sum(),
        runs: session.runs.len(),
    })
}

/// Why writing the MCAP stream failed.
enum Failure {
    Io(std::io::Error),
    Mcap(mcap::McapError),
    Content(String),
}

impl From<mcap::McapError> for Failure {
    fn from(e: mcap::McapError) -> Self {
        match e {
            mcap::McapError::Io(e) => Failure::Io(e),
            e => Failure::Mcap(e),
        }
    }
}

impl From<std::io::Error> for Failure {
    fn from(e: std::io::Error) -> Self {
        Failure::Io(e)
    }
}

/// What keeps the session from being archived faithfully.
fn check(session: &Session) -> Result<(), String> {
    for (k, ar) in session.runs.iter().enumerate() {
        let run = &ar.run;
        let what = format!("run {} ({})", k + 1, run.name());
        let n = run.len();
        for (name, col) in Axis::ALL
            .into_iter()
            .filter_map(|a| run.axis(a).map(|c| (a.column_name(), c)))
            .chain([("t_s", &run.t_s[..]), ("dR_um", &run.dr_mm[..])])
        {
            if col.len() != n {
                return Err(format!(
                    "{what}: column {name} has {} values but t_s has {n}",
                    col.len()
                ));
            }
            if let Some(i) = col.iter().position(|v| !v.is_finite()) {
                return Err(format!(
                    "{what}: sample {}: column {name} is {}, not a finite number",
                    i + 1,
                    col[i]
                ));
            }
        }
        if let Some(p) = crate::run_problem(ar) {
            return Err(format!("{what}: {p}"));
        }
        let h = &run.header;
        let numbers = [h.radius_mm, h.feed_mm_per_min, h.started_at_unix_s]
            .into_iter()
            .chain(h.pivot_mm)
            .chain(h.table_ball_mm)
            .chain(h.tool_ball_mm);
        if numbers.into_iter().any(|v| !v.is_finite()) {
            return Err(format!("{what}: the header has a non-finite number"));
        }
    }
    if let Some(fit) = &session.fit
        && !fit.residuals.is_empty()
    {
        for (k, res) in fit.residuals.iter().enumerate() {
            if let Some(i) = res.iter().position(|v| !v.is_finite()) {
                return Err(format!(
                    "the fit's residual {} of run {} is {}, not a finite number",
                    i + 1,
                    k + 1,
                    res[i]
                ));
            }
        }
        if fit.residuals.len() != session.runs.len() {
            return Err(format!(
                "the fit has residuals of {} runs, the session {} runs",
                fit.residuals.len(),
                session.runs.len()
            ));
        }
        for (k, (res, ar)) in fit.residuals.iter().zip(&session.runs).enumerate() {
            if res.len() != ar.run.len() {
                return Err(format!(
                    "the fit has {} residuals for run {} ({}), which has {} samples",
                    res.len(),
                    k + 1,
                    ar.run.name(),
                    ar.run.len()
                ));
            }
        }
    }
    Ok(())
}

/// Unique channel names for the runs: the run's name, with `#2`, `#3`, … for repeats.
pub(crate) fn run_names(session: &Session) -> Vec<String> {
    let mut names: Vec<String> = Vec::with_capacity(session.runs.len());
    for ar in &session.runs {
        let base = ar.run.name();
        let mut name = base.clone();
        let mut k = 1;
        while names.contains(&name) {
            k += 1;
            name = format!("{base}#{k}");
        }
        names.push(name);
    }
    names
}

/// Nanoseconds of `s` seconds (not negative), clamped to the `u64` range. Whole seconds and
/// the fraction are converted apart, so that `1795255200.125` gives `…200_125_000_000`.
fn ns(s: f64) -> u64 {
    if s.is_nan() || s <= 0.0 {
        return 0;
    }
    if s >= u64::MAX as f64 / 1e9 {
        return u64::MAX;
    }
    let whole = s.floor();
    let fraction = ((s - whole) * 1e9).round() as u64;
    (whole as u64).saturating_mul(1_000_000_000).saturating_add(fraction)
}

/// Channel metadata: the part and, for per-run channels, the run's index.
fn channel_meta(part: &str, run: Option<usize>) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    m.insert("part".to_string(), part.to_string());
    if let Some(k) = run {
        m.insert("run_index".to_string(), k.to_string());
    }
    m
}

/// Writes messages within the size limit.
struct Out<W: std::io::Write + std::io::Seek> {
    w: mcap::Writer<W>,
    buf: Vec<u8>,
}

impl<W: std::io::Write + std::io::Seek> Out<W> {
    fn schema(&mut self, (name, schema): (&str, &str)) -> Result<u16, Failure> {
        Ok(self.w.add_schema(name, "jsonschema", schema.as_bytes())?)
    }

    fn channel(
        &mut self,
        schema: u16,
        topic: &str,
        part: &str,
        run: Option<usize>,
    ) -> Result<u16, Failure> {
        Ok(self.w.add_channel(schema, topic, "json", &channel_meta(part, run))?)
    }

    /// Serialise `value` and write it on `channel`. The sequence number is 0 ("not assigned"):
    /// counters would cost a tenth of the compressed size and tell nothing the times do not.
    fn message(
        &mut self,
        channel: u16,
        time_ns: u64,
        value: &impl serde::Serialize,
    ) -> Result<(), Failure> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value)
            .map_err(|e| Failure::Content(format!("a message does not serialise: {e}")))?;
        if self.buf.len() > MAX_MESSAGE_BYTES {
            return Err(Failure::Content(format!(
                "a message of {} bytes is larger than the limit of {MAX_MESSAGE_BYTES}",
                self.buf.len()
            )));
        }
        let header = MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time: time_ns,
            publish_time: time_ns,
        };
        Ok(self.w.write_to_known_channel(&header, &self.buf)?)
    }
}

/// The header message of a run.
fn header_msg(index: usize, name: &str, ar: &crate::ArchivedRun) -> HeaderMsg {
    let run = &ar.run;
    let h = &run.header;
    let n = run.len();
    let first_line = run.lines.first().copied().unwrap_or(0);
    let consecutive = run.lines.len() == n
        && run
            .lines
            .iter()
            .enumerate()
            .all(|(i, &l)| u64::from(l) == u64::from(first_line) + i as u64);
    HeaderMsg {
        index,
        name: name.to_string(),
        file_name: ar.file_name.clone(),
        source: run.source.clone(),
        format_version: h.format_version,
        machine: h.machine.clone(),
        plane: h.plane.name().to_string(),
        direction: h.direction.map(|d| d.name().to_string()),
        radius_mm: h.radius_mm,
        feed_mm_per_min: h.feed_mm_per_min,
        pivot_mm: h.pivot_mm,
        table_ball_mm: h.table_ball_mm,
        tool_ball_mm: h.tool_ball_mm,
        defaulted: h.defaulted.keys().into_iter().map(String::from).collect(),
        started_at: h.started_at.clone(),
        started_at_unix_s: h.started_at_unix_s,
        run_id: h.run_id.clone(),
        extra: h.extra.clone(),
        columns: Axis::ALL
            .into_iter()
            .filter(|a| run.axis(*a).is_some())
            .map(|a| a.column_name().to_string())
            .collect(),
        samples: n,
        first_line,
        lines: (!consecutive).then(|| run.lines.clone()),
    }
}

/// Time of sample `i` of `run`, ns since 1970.
fn sample_ns(run: &Run, start_ns: u64, i: usize) -> u64 {
    let t = run.t_s[i] * 1e9;
    if t >= 0.0 {
        start_ns.saturating_add(ns(run.t_s[i]))
    } else {
        start_ns.saturating_sub(ns(-run.t_s[i]))
    }
}

/// Stream the whole archive into `file`; return it flushed (not synced).
fn write_mcap(
    file: File,
    session: &Session,
    run_written: &mut dyn FnMut(usize),
) -> Result<File, Failure> {
    let options = mcap::WriteOptions::new()
        .profile("ballbar")
        .library(format!(
            "ballbar-archive/{} {}",
            env!("CARGO_PKG_VERSION"),
            mcap::LIBRARY_IDENTIFIER
        ))
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(ZSTD_LEVEL)
        .compression_threads(0)
        .chunk_size(Some(CHUNK_BYTES))
        .calculate_chunk_crcs(true)
        .calculate_data_section_crc(true)
        .calculate_summary_section_crc(true)
        .calculate_attachment_crcs(true);
    let mut out = Out { w: options.create(BufWriter::new(file))?, buf: Vec::with_capacity(256) };
    let info = &session.info;
    let created_ns = info.created_unix_s.saturating_mul(1_000_000_000);

    // 1. The session metadata.
    let mut meta = BTreeMap::new();
    let mut put = |k: &str, v: String| {
        meta.insert(k.to_string(), v);
    };
    put("schema_version", SCHEMA_VERSION.to_string());
    put("software_version", info.software_version.clone());
    put("created_unix_s", info.created_unix_s.to_string());
    put("machine_name", info.machine_name.clone());
    put("command", info.command.clone());
    put("runs", session.runs.len().to_string());
    put("samples", session.runs.iter().map(|r| r.run.len()).sum::<usize>().to_string());
    put("machine", session.machine.is_some().to_string());
    put("fit", session.fit.is_some().to_string());
    put("residuals", session.fit.as_ref().is_some_and(|f| !f.residuals.is_empty()).to_string());
    put("diagnosis", session.diagnosis.is_some().to_string());
    put("attachments", session.attachments.len().to_string());
    out.w.write_metadata(&Metadata { name: "ballbar".to_string(), metadata: meta })?;

    // 2. The runs.
    let names = run_names(session);
    let mut display = Displayer::default();
    if !session.runs.is_empty() {
        let header_schema = out.schema(json::RUN_HEADER_SCHEMA)?;
        let sample_schema = out.schema(json::SAMPLE_SCHEMA)?;
        for (k, (ar, name)) in session.runs.iter().zip(&names).enumerate() {
            let run = &ar.run;
            let start_ns = ns(run.header.started_at_unix_s);
            let hc =
                out.channel(header_schema, &format!("/runs/{name}/header"), "run_header", Some(k))?;
            out.message(hc, start_ns, &header_msg(k, name, ar))?;
            let sc =
                out.channel(sample_schema, &format!("/runs/{name}/samples"), "samples", Some(k))?;
            let present: Vec<(usize, &[f64])> =
                Axis::ALL.into_iter().filter_map(|a| run.axis(a).map(|c| (a.index(), c))).collect();
            for i in 0..run.len() {
                let mut s = SampleMsg { t_s: run.t_s[i], ..SampleMsg::default() };
                for &(a, col) in &present {
                    let x = col[i];
                    if a < 3 {
                        *s.axis_mut(a) = Some(x);
                    } else {
                        match display.display(x, json::rad_to_deg, json::deg_to_rad) {
                            Some(d) => *s.axis_mut(a) = Some(d),
                            None => {
                                *s.axis_mut(a) = Some(json::rad_to_deg(x));
                                *s.exact_mut(a) = Some(x);
                            }
                        }
                    }
                }
                let dr = run.dr_mm[i];
                match display.display(dr, json::mm_to_um, json::um_to_mm) {
                    Some(d) => s.dr_um = d,
                    None => {
                        s.dr_um = json::mm_to_um(dr);
                        s.dr_mm = Some(dr);
                    }
                }
                out.message(sc, sample_ns(run, start_ns, i), &s)?;
            }
            // Finish the chunk so that the run is complete in the file before the next starts.
            out.w.flush()?;
            run_written(k);
        }
    }

    // 3. The machine.
    if let Some(m) = &session.machine {
        let schema = out.schema(json::MACHINE_SCHEMA)?;
        let c = out.channel(schema, "/machine", "machine", None)?;
        out.message(c, created_ns, m)?;
    }

    // 4. The fit and its residuals.
    if let Some(fit) = &session.fit {
        let schema = out.schema(json::FIT_SCHEMA)?;
        let c = out.channel(schema, "/fit/parameters", "fit_parameters", None)?;
        out.message(c, created_ns, fit)?;
        if !fit.residuals.is_empty() {
            let schema = out.schema(json::RESIDUAL_SCHEMA)?;
            for (k, (res, name)) in fit.residuals.iter().zip(&names).enumerate() {
                let run = &session.runs[k].run;
                let start_ns = ns(run.header.started_at_unix_s);
                let c =
                    out.channel(schema, &format!("/fit/residuals/{name}"), "residuals", Some(k))?;
                for (i, &r) in res.iter().enumerate() {
                    // Finite: checked before the file was created.
                    let (residual_um, residual_mm) =
                        match display.display(r, json::mm_to_um, json::um_to_mm) {
                            Some(d) => (d, None),
                            None => (json::mm_to_um(r), Some(r)),
                        };
                    let m = ResidualMsg { t_s: run.t_s[i], residual_um, residual_mm };
                    out.message(c, sample_ns(run, start_ns, i), &m)?;
                }
            }
        }
    }

    // 5. The diagnosis.
    if let Some(d) = &session.diagnosis {
        let schema = out.schema(json::DIAGNOSIS_SCHEMA)?;
        let c = out.channel(schema, "/diagnosis", "diagnosis", None)?;
        out.message(c, created_ns, d)?;
    }

    // 6. The attachments.
    for a in &session.attachments {
        let header = AttachmentHeader {
            log_time: created_ns,
            create_time: created_ns,
            name: a.name.clone(),
            media_type: a.media_type.clone(),
        };
        out.w.start_attachment(a.data.len() as u64, header)?;
        out.w.put_attachment_bytes(&a.data)?;
        out.w.finish_attachment()?;
    }

    out.w.finish()?;
    let buffered = out.w.into_inner();
    let file = buffered.into_inner().map_err(|e| e.into_error())?;
    Ok(file)
}

//! The reader: one sequential pass over the whole file with every CRC checked, so that a
//! failure can say how far the content was readable.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use ballbar_model::{Axis, Direction, Plane, Run, RunHeader};
use mcap::McapError;
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};

use crate::json::{self, HeaderMsg, ResidualMsg, SampleMsg};
use crate::{
    ArchiveError, ArchivedFit, ArchivedMachine, ArchivedRun, Attachment, Checksums, Readable,
    Recovered, RunProgress, SCHEMA_VERSION, Session, SessionInfo,
};

/// Read an archive written by [`crate::write()`].
///
/// The file is read whole and in order, with the chunk, attachment, data-section and summary
/// CRCs checked; nothing is returned unless every byte checked out. Errors name the file:
/// [`ArchiveError::NotMcap`], [`ArchiveError::Truncated`], [`ArchiveError::Corrupt`],
/// [`ArchiveError::NewerVersion`], [`ArchiveError::Invalid`], each saying what was readable.
pub fn read(path: &Path) -> Result<Session, ArchiveError> {
    read_with_checksums(path).map(|(session, _)| session)
}

/// [`read()`], and which of the archive's parts carry no checksum ([`Checksums`]): MCAP allows
/// a CRC of 0 for "not computed", and such a part is read unchecked.
pub fn read_with_checksums(path: &Path) -> Result<(Session, Checksums), ArchiveError> {
    let bytes = std::fs::read(path)
        .map_err(|error| ArchiveError::Io { path: path.to_path_buf(), error })?;
    let session = read_bytes(&bytes, path)?;
    Ok((session, checksums(&bytes)))
}

/// Which parts of an MCAP file carry a CRC: a pass over its records without decompressing the
/// chunks (their headers hold their CRCs). It stops at the first record it cannot read (a
/// damaged file: [`read()`] says what is wrong), with what it saw before.
pub fn checksums(bytes: &[u8]) -> Checksums {
    let options = LinearReaderOptions::default()
        .with_emit_chunks(true)
        .with_record_length_limit(bytes.len().max(CHUNK_LIMIT));
    let mut reader = LinearReader::new_with_options(options);
    let mut sums = Checksums::default();
    let mut rest = bytes;
    // The MCAP reader is third-party code fed untrusted bytes: should it panic, what was seen
    // before stands.
    let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        while let Some(Ok(event)) = reader.next_event() {
            match event {
                LinearReadEvent::ReadRequest(need) => {
                    let n = need.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                }
                LinearReadEvent::Record { opcode, data } => {
                    match mcap::parse_record(opcode, data) {
                        Ok(Record::Chunk { header, .. }) => {
                            sums.chunks += 1;
                            sums.chunks_without += usize::from(header.uncompressed_crc == 0);
                        }
                        Ok(Record::Attachment { crc, .. }) => {
                            sums.attachments += 1;
                            sums.attachments_without += usize::from(crc == 0);
                        }
                        Ok(Record::DataEnd(end)) => {
                            sums.data_section = Some(end.data_section_crc != 0);
                        }
                        Ok(Record::Footer(footer)) => {
                            sums.summary = footer.summary_start != 0;
                            sums.summary_without = sums.summary && footer.summary_crc == 0;
                        }
                        Ok(_) => {}
                        Err(_) => break,
                    }
                }
            }
        }
    }));
    sums
}

/// [`read()`] from bytes in memory; `path` names the file in errors. Never panics.
pub fn read_bytes(bytes: &[u8], path: &Path) -> Result<Session, ArchiveError> {
    // The MCAP reader is third-party code fed untrusted bytes: a panic in it is turned into an
    // error about the file rather than taking the caller down.
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| parse(bytes, path))) {
        Ok(result) => result,
        Err(_) => Err(ArchiveError::Corrupt {
            path: path.to_path_buf(),
            problem: "the MCAP reader failed on this file".to_string(),
            readable: Box::default(),
        }),
    }
}

/// Largest record (or decompressed chunk) the reader accepts beyond the file's own size:
/// a chunk holds at most about the writer's chunk size plus one message.
const CHUNK_LIMIT: usize = 2 * crate::write::MAX_MESSAGE_BYTES;

fn parse(bytes: &[u8], path: &Path) -> Result<Session, ArchiveError> {
    let (state, stopped) = scan(bytes, path)?;
    match stopped {
        Some(e) => Err(e),
        None => state.finish(),
    }
}

/// Read the file in order as far as it checks out: what was read, and the error that stopped
/// the read (`None` when it reached the end). `Err` when nothing can be read at all (not MCAP,
/// cut inside its magic).
fn scan(bytes: &[u8], path: &Path) -> Result<(State, Option<ArchiveError>), ArchiveError> {
    let magic = mcap::MAGIC;
    if bytes.len() < magic.len() || bytes[..magic.len()] != *magic {
        if !bytes.is_empty() && magic.starts_with(bytes) {
            return Err(ArchiveError::Truncated {
                path: path.to_path_buf(),
                len: bytes.len() as u64,
                detail: "inside the MCAP magic at its start".to_string(),
                readable: Box::default(),
            });
        }
        return Err(ArchiveError::NotMcap {
            path: path.to_path_buf(),
            what: describe_start(bytes),
        });
    }
    let options = LinearReaderOptions::default()
        .with_prevalidate_chunk_crcs(true)
        .with_validate_chunk_crcs(true)
        .with_validate_data_section_crc(true)
        .with_validate_summary_section_crc(true)
        .with_check_finishes_after_end_magic(true)
        .with_record_length_limit(bytes.len().max(CHUNK_LIMIT));
    let mut reader = LinearReader::new_with_options(options);
    let mut state = State::new(path);
    let mut rest = bytes;
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(need)) => {
                let n = need.min(rest.len());
                reader.insert(n).copy_from_slice(&rest[..n]);
                reader.notify_read(n);
                rest = &rest[n..];
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                let offset = bytes.len() - rest.len();
                match mcap::parse_record(opcode, data) {
                    Ok(record) => state.record(record),
                    Err(e) => {
                        let e = state.stopped(e, bytes, offset);
                        return Ok((state, Some(e)));
                    }
                }
            }
            Err(e) => {
                let offset = bytes.len() - rest.len();
                let e = state.stopped(e, bytes, offset);
                return Ok((state, Some(e)));
            }
        }
    }
    Ok((state, None))
}

/// Read what can be recovered of an archive, damaged or not: every run read whole (each
/// checked as [`read()`] checks it), and, when the archive did not read whole, the error that
/// says what stopped the read and what was lost ([`Recovered::lost`]). A run cut short (its
/// samples fewer than its header announces) is never among the runs. `Err` only when no run
/// can be recovered because the file is not an archive this version can interpret (not MCAP,
/// cut inside its magic, a newer schema version, unreadable).
pub fn read_partial(path: &Path) -> Result<Recovered, ArchiveError> {
    let bytes = std::fs::read(path)
        .map_err(|error| ArchiveError::Io { path: path.to_path_buf(), error })?;
    read_partial_bytes(&bytes, path)
}

/// [`read_partial()`] from bytes in memory; `path` names the file in errors. Never panics.
pub fn read_partial_bytes(bytes: &[u8], path: &Path) -> Result<Recovered, ArchiveError> {
    let recovered = std::panic::catch_unwind(std::panic::AssertUnwindSafe(
        || -> Result<Recovered, ArchiveError> {
            let (state, stopped) = scan(bytes, path)?;
            if let Some(e @ ArchiveError::NewerVersion { .. }) = stopped {
                return Err(e);
            }
            if stopped.is_none() && state.newer.is_none() && state.content_error.is_none() {
                // Read to the end: the whole session, or the reason it is not a valid one.
                let info = state.info.clone();
                let partial = state.complete_runs();
                return Ok(match state.finish() {
                    Ok(session) => Recovered {
                        info: Some(session.info.clone()),
                        runs: session.runs,
                        damage: None,
                        checksums: checksums(bytes),
                    },
                    Err(e) => Recovered {
                        info,
                        runs: partial,
                        damage: Some(e),
                        checksums: checksums(bytes),
                    },
                });
            }
            if state.newer.is_some() {
                return Err(state.finish().err().unwrap_or_else(|| ArchiveError::Invalid {
                    path: path.to_path_buf(),
                    message: "a newer archive".into(),
                    readable: Box::default(),
                }));
            }
            let damage = match stopped {
                Some(e) => e,
                None => {
                    let (message, readable) = state.content_error.clone().unwrap_or_default();
                    ArchiveError::Invalid {
                        path: path.to_path_buf(),
                        message,
                        readable: Box::new(readable),
                    }
                }
            };
            Ok(Recovered {
                info: state.info.clone(),
                runs: state.complete_runs(),
                damage: Some(damage),
                checksums: checksums(bytes),
            })
        },
    ));
    recovered.unwrap_or_else(|_| {
        Err(ArchiveError::Corrupt {
            path: path.to_path_buf(),
            problem: "the MCAP reader failed on this file".to_string(),
            readable: Box::default(),
        })
    })
}

/// What is wrong with a run read from an archive: what [`crate::run_problem`] finds, then what
/// the check every reader ends in finds (`ballbar_io::check::check_run`, naming the file and
/// line the sample came from). An archive is a way in like a run file, and one edited after it
/// was written (its CRCs set to 0) may hold a reading of 1e300. A run made in memory has no
/// line numbers: its samples are named by their number instead.
fn run_problem(r: &ArchivedRun) -> Option<String> {
    crate::run_problem(r).or_else(|| {
        let checked = if r.run.lines.is_empty() {
            let mut numbered = r.run.clone();
            numbered.lines = (1..=u32::try_from(r.run.len()).unwrap_or(u32::MAX)).collect();
            ballbar_io::check::check_run(&numbered)
        } else {
            ballbar_io::check::check_run(&r.run)
        };
        checked.err().map(|e| e.to_string())
    })
}

/// What a file that is not MCAP starts with, for the message.
fn describe_start(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return "the file is empty".to_string();
    }
    let head = &bytes[..bytes.len().min(24)];
    match std::str::from_utf8(head) {
        Ok(text)
            if text.chars().all(|c| !c.is_control() || c == '\n' || c == '\r' || c == '\t') =>
        {
            let first = text.lines().next().unwrap_or("");
            format!("it starts with the text {first:?}")
        }
        _ => {
            let hex: Vec<String> = head.iter().take(8).map(|b| format!("{b:02x}")).collect();
            format!("it starts with the bytes {}, not the MCAP magic", hex.join(" "))
        }
    }
}

/// What a channel carries.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    RunHeader(usize),
    Samples(usize),
    Machine,
    Fit,
    Residuals(usize),
    Diagnosis,
    /// A channel this version does not know: ignored.
    Other,
}

/// What the metadata announces.
#[derive(Default)]
struct Expected {
    runs: usize,
    samples: usize,
    machine: bool,
    fit: bool,
    residuals: bool,
    diagnosis: bool,
    attachments: usize,
}

/// A run being read.
struct RunBuilder {
    name: String,
    file_name: String,
    header: RunHeader,
    source: String,
    present: [bool; 6],
    samples: usize,
    first_line: u32,
    lines: Option<Vec<u32>>,
    t_s: Vec<f64>,
    axes: [Vec<f64>; 6],
    dr_mm: Vec<f64>,
}

/// Everything read so far.
struct State {
    path: PathBuf,
    info: Option<SessionInfo>,
    expected: Expected,
    /// Set when the archive is newer than this reader: its content is not interpreted.
    newer: Option<(u32, String)>,
    /// The first content error; the file is still read to the end, so that damage is reported
    /// as damage rather than as a content error.
    content_error: Option<(String, Readable)>,
    channels: HashMap<u16, Part>,
    runs: Vec<Option<RunBuilder>>,
    machine: Option<ArchivedMachine>,
    fit: Option<ArchivedFit>,
    residuals: Vec<Vec<f64>>,
    diagnosis: Option<serde_json::Value>,
    attachments: Vec<Attachment>,
    data_end: bool,
    footer: bool,
}

impl State {
    fn new(path: &Path) -> State {
        State {
            path: path.to_path_buf(),
            info: None,
            expected: Expected::default(),
            newer: None,
            content_error: None,
            channels: HashMap::new(),
            runs: Vec::new(),
            machine: None,
            fit: None,
            residuals: Vec::new(),
            diagnosis: None,
            attachments: Vec::new(),
            data_end: false,
            footer: false,
        }
    }

    /// Handle one record. Content errors are remembered, not returned: see `content_error`.
    fn record(&mut self, record: Record<'_>) {
        match record {
            Record::DataEnd(_) => self.data_end = true,
            Record::Footer(_) => self.footer = true,
            _ if self.newer.is_some() || self.content_error.is_some() || self.data_end => {}
            _ => {
                if let Err(message) = self.content(record) {
                    self.content_error = Some((message, self.readable()));
                }
            }
        }
    }

    /// Interpret a record of the data section.
    fn content(&mut self, record: Record<'_>) -> Result<(), String> {
        match record {
            Record::Metadata(m) if m.name == "ballbar" => self.metadata(&m.metadata),
            Record::Channel(c) => {
                let part = part(&c.metadata, self.expected.runs)
                    .map_err(|e| format!("channel {:?}: {e}", c.topic))?;
                if part != Part::Other && c.message_encoding != "json" {
                    return Err(format!(
                        "channel {:?} has message encoding {:?}, not json",
                        c.topic, c.message_encoding
                    ));
                }
                if part != Part::Other && self.info.is_none() {
                    return Err(format!(
                        "channel {:?} comes before the ballbar metadata record",
                        c.topic
                    ));
                }
                self.channels.insert(c.id, part);
                Ok(())
            }
            Record::Message { header, data } => {
                let part = *self.channels.get(&header.channel_id).ok_or_else(|| {
                    format!("a message on channel {} that was not declared", header.channel_id)
                })?;
                self.message(part, &data)
            }
            Record::Attachment { header, data, .. } => {
                if self.info.is_none() {
                    return Err("an attachment comes before the ballbar metadata record".into());
                }
                self.attachments.push(Attachment {
                    name: header.name,
                    media_type: header.media_type,
                    data: data.into_owned(),
                });
                Ok(())
            }
            _ => Ok(()),
        }
    }

    fn metadata(&mut self, m: &std::collections::BTreeMap<String, String>) -> Result<(), String> {
        if self.info.is_some() {
            return Err("a second ballbar metadata record".into());
        }
        let get = |k: &str| m.get(k).ok_or_else(|| format!("the ballbar metadata has no {k:?}"));
        let number = |k: &str| -> Result<usize, String> {
            let v = get(k)?;
            v.parse().map_err(|_| format!("ballbar metadata {k:?}: {v:?} is not a count"))
        };
        let flag = |k: &str| -> Result<bool, String> {
            match get(k)?.as_str() {
                "true" => Ok(true),
                "false" => Ok(false),
                v => Err(format!("ballbar metadata {k:?}: {v:?} is not true or false")),
            }
        };
        let v = get("schema_version")?;
        let version: u32 = v
            .parse()
            .map_err(|_| format!("ballbar metadata \"schema_version\": {v:?} is not a version"))?;
        let software_version = m.get("software_version").cloned().unwrap_or_default();
        if version > SCHEMA_VERSION {
            self.newer = Some((version, software_version));
            return Ok(());
        }
        if version == 0 {
            return Err("ballbar metadata \"schema_version\" is 0".into());
        }
        let created = get("created_unix_s")?;
        let created_unix_s = created.parse().map_err(|_| {
            format!("ballbar metadata \"created_unix_s\": {created:?} is not a time")
        })?;
        self.expected = Expected {
            runs: number("runs")?,
            samples: number("samples")?,
            machine: flag("machine")?,
            fit: flag("fit")?,
            residuals: flag("residuals")?,
            diagnosis: flag("diagnosis")?,
            attachments: number("attachments")?,
        };
        // Announced counts size nothing until the data arrives; a corrupt count cannot allocate.
        self.runs = (0..self.expected.runs.min(1 << 16)).map(|_| None).collect();
        self.info = Some(SessionInfo {
            software_version,
            created_unix_s,
            machine_name: get("machine_name")?.clone(),
            command: get("command")?.clone(),
        });
        Ok(())
    }

    fn message(&mut self, part: Part, data: &[u8]) -> Result<(), String> {
        let bad = |what: &str, e: serde_json::Error| format!("{what}: {e}");
        match part {
            Part::Other => Ok(()),
            Part::RunHeader(k) => {
                let h: HeaderMsg =
                    serde_json::from_slice(data).map_err(|e| bad("a run header message", e))?;
                let slot = self
                    .runs
                    .get_mut(k)
                    .ok_or_else(|| format!("run header {k} beyond the announced runs"))?;
                if slot.is_some() || h.index != k {
                    return Err(format!("a second or misplaced header of run {}", k + 1));
                }
                *slot = Some(builder(h).map_err(|e| format!("header of run {}: {e}", k + 1))?);
                Ok(())
            }
            Part::Samples(k) => {
                let b = self
                    .runs
                    .get_mut(k)
                    .and_then(Option::as_mut)
                    .ok_or_else(|| format!("samples of run {} before its header", k + 1))?;
                let s: SampleMsg = serde_json::from_slice(data).map_err(|e| {
                    bad(&format!("sample {} of run {}", b.t_s.len() + 1, b.name), e)
                })?;
                sample(b, s)
                    .map_err(|e| format!("sample {} of run {}: {e}", b.t_s.len() + 1, b.name))
            }
            Part::Machine => {
                if self.machine.is_some() {
                    return Err("a second machine message".into());
                }
                let m = serde_json::from_slice(data).map_err(|e| bad("the machine message", e))?;
                self.machine = Some(m);
                Ok(())
            }
            Part::Fit => {
                if self.fit.is_some() {
                    return Err("a second fit message".into());
                }
                let f = serde_json::from_slice(data).map_err(|e| bad("the fit message", e))?;
                self.fit = Some(f);
                Ok(())
            }
            Part::Residuals(k) => {
                if self.residuals.len() <= k {
                    let runs = self.runs.len();
                    if k >= runs {
                        return Err(format!(
                            "residuals of run {} beyond the announced runs",
                            k + 1
                        ));
                    }
                    self.residuals.resize(runs, Vec::new());
                }
                let r: ResidualMsg = serde_json::from_slice(data)
                    .map_err(|e| bad(&format!("a residual of run {}", k + 1), e))?;
                self.residuals[k].push(r.residual_mm.unwrap_or(json::um_to_mm(r.residual_um)));
                Ok(())
            }
            Part::Diagnosis => {
                if self.diagnosis.is_some() {
                    return Err("a second diagnosis message".into());
                }
                let d =
                    serde_json::from_slice(data).map_err(|e| bad("the diagnosis message", e))?;
                self.diagnosis = Some(d);
                Ok(())
            }
        }
    }

    /// The runs read whole and sound, in session order (a run whose header or some of whose
    /// samples are missing is left out).
    fn complete_runs(&self) -> Vec<ArchivedRun> {
        self.runs
            .iter()
            .flatten()
            .filter(|b| b.t_s.len() == b.samples)
            .map(|b| b.snapshot())
            .filter(|r| run_problem(r).is_none())
            .collect()
    }

    /// What has been read and checked so far.
    fn readable(&self) -> Readable {
        let Some(_) = &self.info else {
            return Readable::default();
        };
        let e = &self.expected;
        let complete_residuals = self
            .residuals
            .iter()
            .zip(&self.runs)
            .filter(|(r, b)| b.as_ref().is_some_and(|b| b.samples == r.len()))
            .count();
        Readable {
            metadata: true,
            runs_expected: Some(e.runs),
            runs: self
                .runs
                .iter()
                .flatten()
                .map(|b| RunProgress {
                    name: b.name.clone(),
                    samples: b.t_s.len(),
                    samples_expected: b.samples,
                })
                .collect(),
            machine: (e.machine, self.machine.is_some()),
            fit: (e.fit, self.fit.is_some()),
            residual_runs: complete_residuals,
            residuals_expected: e.residuals,
            diagnosis: (e.diagnosis, self.diagnosis.is_some()),
            attachments: self.attachments.len(),
            attachments_expected: Some(e.attachments),
        }
    }

    /// The error for a read that stopped with `e` at about byte `offset`.
    fn stopped(&self, e: McapError, bytes: &[u8], offset: usize) -> ArchiveError {
        let path = self.path.clone();
        // A newer archive may use what this version cannot read (another compression, say):
        // the version is what the user needs to know.
        if let Some((found, software_version)) = &self.newer {
            return ArchiveError::NewerVersion {
                path,
                found: *found,
                supported: SCHEMA_VERSION,
                software_version: software_version.clone(),
            };
        }
        let readable = Box::new(self.readable());
        let complete = bytes.len() > mcap::MAGIC.len() && bytes.ends_with(mcap::MAGIC);
        let corrupt = |problem: String| ArchiveError::Corrupt {
            path: path.clone(),
            problem,
            readable: readable.clone(),
        };
        match e {
            McapError::BadChunkCrc { saved, calculated } => corrupt(format!(
                "checksum mismatch in a compressed chunk before byte {offset}: stored {saved:08x}, computed {calculated:08x}"
            )),
            McapError::BadDataCrc { saved, calculated } => corrupt(format!(
                "checksum mismatch of the data section: stored {saved:08x}, computed {calculated:08x}"
            )),
            McapError::BadSummaryCrc { saved, calculated } => corrupt(format!(
                "checksum mismatch of the summary section: stored {saved:08x}, computed {calculated:08x}"
            )),
            McapError::BadAttachmentCrc { saved, calculated } => corrupt(format!(
                "checksum mismatch in an attachment before byte {offset}: stored {saved:08x}, computed {calculated:08x}"
            )),
            McapError::BadMagic => {
                corrupt("the MCAP magic at the end of the file is damaged".into())
            }
            _ if !complete => ArchiveError::Truncated {
                path,
                len: bytes.len() as u64,
                detail: match e {
                    McapError::UnexpectedEof => "inside a record: it was cut short".to_string(),
                    e => format!("without the MCAP end magic; reading stopped at: {e}"),
                },
                readable,
            },
            McapError::UnexpectedEof => {
                corrupt(format!("a record near byte {offset} runs past the end of the file"))
            }
            e => corrupt(format!("{e} (near byte {offset})")),
        }
    }

    /// The session, once the whole file has been read and checked.
    fn finish(self) -> Result<Session, ArchiveError> {
        let path = self.path.clone();
        if let Some((found, software_version)) = self.newer {
            return Err(ArchiveError::NewerVersion {
                path,
                found,
                supported: SCHEMA_VERSION,
                software_version,
            });
        }
        if let Some((message, readable)) = self.content_error {
            return Err(ArchiveError::Invalid { path, message, readable: Box::new(readable) });
        }
        let readable = Box::new(self.readable());
        let invalid = |message: String| ArchiveError::Invalid {
            path: path.clone(),
            message,
            readable: readable.clone(),
        };
        if !self.data_end || !self.footer {
            return Err(invalid("the file has no data end or footer record".into()));
        }
        let Some(info) = self.info else {
            return Err(invalid("an MCAP file without the ballbar metadata record".into()));
        };
        let e = &self.expected;
        let mut runs = Vec::with_capacity(self.runs.len());
        for (k, b) in self.runs.into_iter().enumerate() {
            let b = b.ok_or_else(|| invalid(format!("run {} has no header message", k + 1)))?;
            if b.t_s.len() != b.samples {
                return Err(invalid(format!(
                    "run {} ({}) has {} of its {} samples",
                    k + 1,
                    b.name,
                    b.t_s.len(),
                    b.samples
                )));
            }
            let run = b.build();
            if let Some(p) = run_problem(&run) {
                return Err(invalid(format!("run {} ({}): {p}", k + 1, run.run.name())));
            }
            runs.push(run);
        }
        let samples: usize = runs.iter().map(|r: &ArchivedRun| r.run.len()).sum();
        if runs.len() != e.runs || samples != e.samples {
            return Err(invalid(format!(
                "the metadata announces {} runs with {} samples, the file has {} with {samples}",
                e.runs,
                e.samples,
                runs.len()
            )));
        }
        for (what, expected, found) in [
            ("machine", e.machine, self.machine.is_some()),
            ("fit", e.fit, self.fit.is_some()),
            ("diagnosis", e.diagnosis, self.diagnosis.is_some()),
        ] {
            if expected != found {
                return Err(invalid(format!(
                    "the metadata says {what}={expected} but the {what} message is {}",
                    if found { "there" } else { "missing" }
                )));
            }
        }
        let mut fit = self.fit;
        if let Some(f) = &mut fit {
            if e.residuals {
                if self.residuals.len() != runs.len() {
                    return Err(invalid("the fit's residuals are missing".into()));
                }
                for (k, (res, r)) in self.residuals.iter().zip(&runs).enumerate() {
                    if res.len() != r.run.len() {
                        return Err(invalid(format!(
                            "run {} has {} fit residuals for {} samples",
                            k + 1,
                            res.len(),
                            r.run.len()
                        )));
                    }
                }
                f.residuals = self.residuals;
            } else if !self.residuals.is_empty() {
                return Err(invalid("residuals without the metadata announcing them".into()));
            }
        }
        if self.attachments.len() != e.attachments {
            return Err(invalid(format!(
                "the metadata announces {} attachments, the file has {}",
                e.attachments,
                self.attachments.len()
            )));
        }
        Ok(Session {
            info,
            runs,
            machine: self.machine,
            fit,
            diagnosis: self.diagnosis,
            attachments: self.attachments,
        })
    }
}

/// The part a channel carries, from its metadata.
fn part(meta: &std::collections::BTreeMap<String, String>, runs: usize) -> Result<Part, String> {
    let index = || -> Result<usize, String> {
        let v = meta.get("run_index").ok_or("no run_index in the channel metadata")?;
        let k: usize = v.parse().map_err(|_| format!("run_index {v:?} is not an index"))?;
        if k >= runs {
            return Err(format!("run_index {k} but the archive has {runs} runs"));
        }
        Ok(k)
    };
    Ok(match meta.get("part").map(String::as_str) {
        Some("run_header") => Part::RunHeader(index()?),
        Some("samples") => Part::Samples(index()?),
        Some("machine") => Part::Machine,
        Some("fit_parameters") => Part::Fit,
        Some("residuals") => Part::Residuals(index()?),
        Some("diagnosis") => Part::Diagnosis,
        _ => Part::Other,
    })
}

/// A run builder from its header message, every field checked.
fn builder(h: HeaderMsg) -> Result<RunBuilder, String> {
    let plane =
        Plane::from_name(&h.plane).ok_or_else(|| format!("plane {:?} is not known", h.plane))?;
    let direction = match &h.direction {
        None => None,
        Some(d) => {
            Some(Direction::from_name(d).ok_or_else(|| format!("direction {d:?} is not known"))?)
        }
    };
    let mut present = [false; 6];
    for c in &h.columns {
        let a = Axis::from_column_name(c).ok_or_else(|| format!("column {c:?} is not an axis"))?;
        if present[a.index()] {
            return Err(format!("column {c:?} is given twice"));
        }
        present[a.index()] = true;
    }
    // The announced count only reserves what a plausible run needs.
    let cap = h.samples.min(1 << 20);
    let axes =
        std::array::from_fn(|i| if present[i] { Vec::with_capacity(cap) } else { Vec::new() });
    Ok(RunBuilder {
        name: h.name,
        file_name: h.file_name,
        source: h.source,
        header: RunHeader {
            format_version: h.format_version,
            machine: h.machine,
            plane,
            direction,
            radius_mm: h.radius_mm,
            feed_mm_per_min: h.feed_mm_per_min,
            pivot_mm: h.pivot_mm,
            table_ball_mm: h.table_ball_mm,
            tool_ball_mm: h.tool_ball_mm,
            defaulted: ballbar_model::run::DefaultedKeys::from_keys(
                h.defaulted.iter().map(String::as_str),
            )?,
            started_at: h.started_at,
            started_at_unix_s: h.started_at_unix_s,
            run_id: h.run_id,
            extra: h.extra,
        },
        present,
        samples: h.samples,
        first_line: h.first_line,
        lines: h.lines,
        t_s: Vec::with_capacity(cap),
        axes,
        dr_mm: Vec::with_capacity(cap),
    })
}

/// Add one sample to a run, in internal units.
fn sample(b: &mut RunBuilder, mut s: SampleMsg) -> Result<(), String> {
    if b.t_s.len() >= b.samples {
        return Err(format!("more samples than the {} announced", b.samples));
    }
    for i in 0..6 {
        let v = s.axis_mut(i).take();
        match (b.present[i], v) {
            (true, Some(d)) => {
                let x = if i < 3 { d } else { (*s.exact_mut(i)).unwrap_or(json::deg_to_rad(d)) };
                b.axes[i].push(x);
            }
            (false, None) => {}
            (true, None) => return Err(format!("no value of axis {}", Axis::ALL[i].name())),
            (false, Some(_)) => {
                return Err(format!(
                    "a value of axis {}, which the header does not list",
                    Axis::ALL[i].name()
                ));
            }
        }
    }
    b.t_s.push(s.t_s);
    b.dr_mm.push(s.dr_mm.unwrap_or(json::um_to_mm(s.dr_um)));
    Ok(())
}

impl RunBuilder {
    /// The run as read so far, the builder kept.
    fn snapshot(&self) -> ArchivedRun {
        RunBuilder {
            name: self.name.clone(),
            file_name: self.file_name.clone(),
            header: self.header.clone(),
            source: self.source.clone(),
            present: self.present,
            samples: self.samples,
            first_line: self.first_line,
            lines: self.lines.clone(),
            t_s: self.t_s.clone(),
            axes: self.axes.clone(),
            dr_mm: self.dr_mm.clone(),
        }
        .build()
    }

    fn build(self) -> ArchivedRun {
        let n = self.t_s.len();
        let lines = self.lines.unwrap_or_else(|| {
            (0..n)
                .map(|i| self.first_line.saturating_add(u32::try_from(i).unwrap_or(u32::MAX)))
                .collect()
        });
        let present = self.present;
        let mut axes = self.axes.into_iter();
        let axes = std::array::from_fn(|i| {
            let col = axes.next().unwrap_or_default();
            present[i].then_some(col)
        });
        ArchivedRun {
            run: Run {
                header: self.header,
                source: self.source,
                t_s: self.t_s,
                axes,
                dr_mm: self.dr_mm,
                lines,
            },
            file_name: self.file_name,
        }
    }
}

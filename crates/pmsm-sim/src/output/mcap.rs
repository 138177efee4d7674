//! The MCAP log of a run: one message per control period, readable by Foxglove and the
//! `mcap` Python package.
//!
//! # Topics
//!
//! | topic | schema | encoding | messages |
//! |---|---|---|---|
//! | `/pmsm_sim/period` | `pmsm_sim.Period` | protobuf ([`proto`]; or JSON, [`LogEncoding::Json`]) | one per PWM period: the [`Sample`] |
//! | `/pmsm_sim/scenario` | `pmsm_sim.Scenario` | JSON | one, at `t = 0`: name, TOML text, scenario |
//! | `/pmsm_sim/metrics` | `pmsm_sim.Metrics` | JSON | one, at the end: the [`RunMetrics`] |
//! | `/pmsm_sim/event` | `pmsm_sim.Event` | JSON | why a run stopped early (non-finite, Ctrl-C, ...) |
//!
//! The per-period channel is protobuf by default: message encoding `protobuf`, schema encoding
//! `protobuf` with a `FileDescriptorSet` ([`proto::file_descriptor_set`]; the `.proto` text is
//! `src/schemas/period.proto`), encoded by [`proto::PeriodEncoder`] (about 70 ns and 1000 bytes
//! per message). With [`LogEncoding::Json`] it is JSON with the JSON schema
//! [`proto::json_schema`] (same field names, about 40 times slower to write). All three come
//! from the one description of the record in [`crate::output::record`] (how to add a field: there).
//! The other channels are JSON (`jsonschema`): one message each.
//!
//! Log and publish times are the run's start time plus the simulated time `k Ts`, in
//! nanoseconds since the Unix epoch: [`LogOptions::start_time_unix_ns`], which the CLI sets to
//! the wall-clock time at the start of the run (`--log-time wall`, its default; read with
//! [`wall_clock_unix_ns`]) so that Foxglove shows the date and time the run was made, or
//! leaves at 0 (`--log-time zero`: the simulated time alone, the log starting at the epoch,
//! 1970-01-01; what the behaviour gate `scripts/same-outputs.sh` uses, so that two runs give
//! the same time stamps). A reader takes the time of a message relative to the first message's
//! (the scenario message, written at the start), or to the metadata's `start_time_unix_ns`.
//! A metadata record `pmsm_sim` holds the simulator version, the scenario's TOML and, when it
//! is not 0, `start_time_unix_ns` (decimal). Chunks of at most 1 MiB
//! (finished every 1024 periods: "Write errors" below), not compressed by default
//! ([`LogCompression`]: this data compresses only 1.5-1.8x, and
//! compressing a 700-byte message with lz4 or zstd, 1.3-1.8 us, costs several times what
//! writing it to the file does, about 0.3 us).
//! Chunk and data-section CRCs are not computed (0, "not computed" in the MCAP spec: the
//! `mcap` crate's CRC costs about 110 ns per message); the summary's is.
//!
//! # Writer thread
//!
//! The encoding, the `mcap` writer and the file writes run on a thread of their own
//! (`pmsm-sim mcap`): [`SampleSink::record`] copies the period's [`Sample`] into a batch of
//! 256 and hands each full batch over (at most 4 in flight; then `record` waits for the
//! writer). The run loop's own cost of the log is that copy (about 1 KB per period); with a
//! free core the rest overlaps the simulation. The file is the same, message for message and
//! byte for byte, as when it was written on the caller's thread: one writer, the messages in
//! the order they were recorded, the same sequence numbers. [`McapLog::event`] and
//! [`McapLog::finish`] first wait for every period recorded before them to be written (the
//! writer then comes back to the caller's thread). A write error surfaces at the next
//! hand-over (up to 256 periods after the period that failed; the run then ends with
//! `SinkFailed` there) or in `finish`.
//!
//! # Always finished
//!
//! [`McapLog::finish`] writes the summary and footer. A run that stops early (non-finite
//! state, Ctrl-C) still ends in `finish`, after an `/pmsm_sim/event` message; and should the
//! log be dropped without it (a panic), its `Drop` writes the periods still queued and the
//! `mcap` writer's `Drop` finishes the file.
//!
//! # Write errors (a full disk)
//!
//! The writer finishes a chunk every [`CHUNK_BATCHES`] batches (1024 periods, about 1 MB) and
//! after the scenario message, and the file ([`LogFile`]) remembers where the last complete
//! chunk ends. On a write error the file is cut back there and closed with a footer without
//! a summary ([`LogFile::salvage`]): a valid MCAP file with every period up to that chunk,
//! which pmsm-sim's readers and the Python `mcap` package read (linearly). The error names
//! the file and the operating system's cause ("No space left on device (os error 28)").
//! A log that cannot even be started is removed.

use std::collections::BTreeMap;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, McapError, WriteOptions, Writer};
use serde::Serialize;

pub mod proto;

use crate::SimError;
use crate::output::SampleSink;
use crate::output::file::LogFile;
use crate::output::metrics::RunMetrics;
use crate::output::record::Sample;
use crate::scenario::Scenario;

/// Topic of the per-period messages.
pub const TOPIC_PERIOD: &str = "/pmsm_sim/period";
/// Topic of the scenario message.
pub const TOPIC_SCENARIO: &str = "/pmsm_sim/scenario";
/// Topic of the metrics message.
pub const TOPIC_METRICS: &str = "/pmsm_sim/metrics";
/// Topic of the event messages.
pub const TOPIC_EVENT: &str = "/pmsm_sim/event";

const SCENARIO_SCHEMA: &str = r#"{"title":"pmsm_sim.Scenario","type":"object","properties":{"name":{"type":"string"},"toml":{"type":"string","description":"the scenario as TOML"},"scenario":{"type":"object","description":"the scenario (same fields as the TOML)"}}}"#;
const METRICS_SCHEMA: &str = r#"{"title":"pmsm_sim.Metrics","type":"object","description":"metrics of the run (docs/design.md, Metrics; see the crate README)"}"#;
const EVENT_SCHEMA: &str = r#"{"title":"pmsm_sim.Event","type":"object","properties":{"t_s":{"type":"number","description":"simulated time, s"},"level":{"type":"string"},"message":{"type":"string"}}}"#;

/// Chunk compression of the log.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LogCompression {
    /// None: the fastest (the default; about 7.4 MB per simulated second for the default
    /// scenario at 10 kHz).
    #[default]
    None,
    /// lz4 (about 5.0 MB per simulated second, several times slower to write).
    Lz4,
    /// zstd level 1, single-threaded (about 4.1 MB per simulated second; the slowest).
    Zstd,
}

impl LogCompression {
    fn to_mcap(self) -> Option<Compression> {
        match self {
            LogCompression::Zstd => Some(Compression::Zstd),
            LogCompression::Lz4 => Some(Compression::Lz4),
            LogCompression::None => None,
        }
    }
}

/// Encoding of the per-period messages.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LogEncoding {
    /// Protobuf ([`proto`]): the default, about 70 ns per message.
    #[default]
    Protobuf,
    /// JSON with the JSON schema [`proto::json_schema`] (the same fields; about 2.6 us per
    /// message).
    Json,
}

/// How the log is written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LogOptions {
    /// Chunk compression.
    pub compression: LogCompression,
    /// Encoding of `/pmsm_sim/period`.
    pub encoding: LogEncoding,
    /// Time stamp of the run's start (simulated time 0), ns since the Unix epoch: every
    /// message is stamped with it plus its simulated time (log and publish time). 0 (the
    /// default): the simulated time alone. Non-zero: also recorded in the `pmsm_sim`
    /// metadata as `start_time_unix_ns`.
    pub start_time_unix_ns: u64,
}

/// Origin of the time stamps the CLI's commands give their MCAP logs (`--log-time`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LogTime {
    /// The wall-clock time at the start of the run plus the simulated time (the default).
    #[default]
    Wall,
    /// The simulated time alone (the log starts at the Unix epoch): the same time stamps for
    /// identical runs.
    Zero,
}

impl LogTime {
    /// [`LogOptions::start_time_unix_ns`] for this choice: [`wall_clock_unix_ns`] now, or 0.
    pub fn start_time_unix_ns(self) -> u64 {
        match self {
            LogTime::Wall => wall_clock_unix_ns(),
            LogTime::Zero => 0,
        }
    }
}

/// The system's wall-clock time, ns since the Unix epoch (0 for a clock set before 1970;
/// saturates in the year 2554).
pub fn wall_clock_unix_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX))
}

/// Periods handed to the writer thread at a time (a batch of copied [`Sample`]s, about
/// 1 KB each): one channel operation per batch, not per period.
const BATCH: usize = 256;
/// Batches in flight (queued for the writer thread or being written) before
/// [`SampleSink::record`] waits for it: bounds the memory and keeps the writer close behind.
const IN_FLIGHT: usize = 4;
/// Batches per chunk: the writer finishes a chunk (and marks the file complete up to it)
/// after this many batches, so that a write error loses at most these periods.
pub const CHUNK_BATCHES: u32 = 4;

/// An open MCAP log (module docs).
///
/// The file is written on a thread of its own ("Writer thread" in the module docs): the run
/// loop only copies each [`Sample`] into a batch.
pub struct McapLog {
    path: PathBuf,
    ts_ns: u64,
    last_ns: u64,
    /// The periods not handed over yet.
    batch: Vec<Sample>,
    /// The writer thread (`None` once joined).
    thread: Option<WriterThread>,
    /// The writer, back from its thread ([`McapLog::finish`], [`McapLog::event`]).
    inner: Option<Inner>,
    /// The writer thread's error, once it failed.
    failed: Option<String>,
}

/// The writer thread: its job queue, the batches it hands back for reuse, and its handle.
struct WriterThread {
    jobs: SyncSender<Vec<Sample>>,
    spare: Receiver<Vec<Sample>>,
    handle: JoinHandle<Result<Inner, String>>,
}

/// The writer and its state: on the writer thread while the run goes, back on the caller's
/// thread for the last messages.
struct Inner {
    writer: Writer<BufWriter<LogFile>>,
    /// The file (shared with the writer): chunk marks and salvage.
    file: LogFile,
    /// Batches written since the last complete chunk.
    batches: u32,
    encoding: LogEncoding,
    period: u16,
    scenario: u16,
    metrics: u16,
    event: u16,
    seq: u32,
    ts_ns: u64,
    /// Added to every message's simulated time ([`LogOptions::start_time_unix_ns`]).
    origin_ns: u64,
    buf: Vec<u8>,
    proto: proto::PeriodEncoder,
}

fn out_err(path: &Path, what: impl core::fmt::Display) -> SimError {
    SimError::Output {
        path: path.display().to_string(),
        message: what.to_string(),
    }
}

#[derive(Serialize)]
struct ScenarioMessage<'a> {
    name: &'a str,
    toml: &'a str,
    scenario: &'a Scenario,
}

#[derive(Serialize)]
struct EventMessage<'a> {
    t_s: f64,
    level: &'a str,
    message: &'a str,
}

impl McapLog {
    /// Creates the log at `path`, writes the scenario, and starts the writer thread.
    pub fn create(path: &Path, scenario: &Scenario, options: LogOptions) -> Result<Self, SimError> {
        Self::create_limited(path, scenario, options, None)
    }

    /// [`McapLog::create`] on a disk of `limit` bytes: writes past it fail as on a full disk
    /// (the tests' injected write error; `None`: the real disk). A log that cannot be
    /// started is removed.
    pub fn create_limited(
        path: &Path,
        scenario: &Scenario,
        options: LogOptions,
        limit: Option<u64>,
    ) -> Result<Self, SimError> {
        let r = Self::start(path, scenario, options, limit);
        if r.is_err() {
            let _ = std::fs::remove_file(path);
        }
        r
    }

    fn start(
        path: &Path,
        scenario: &Scenario,
        options: LogOptions,
        limit: Option<u64>,
    ) -> Result<Self, SimError> {
        let file = LogFile::create(path, limit).map_err(|e| out_err(path, e))?;
        let opts = WriteOptions::new()
            .compression(options.compression.to_mcap())
            .compression_threads(0)
            .compression_level(1)
            .chunk_size(Some(1 << 20))
            .calculate_chunk_crcs(false)
            .calculate_data_section_crc(false)
            .profile("")
            .library(format!("pmsm-sim {}", env!("CARGO_PKG_VERSION")));
        let mut writer = opts
            .create(BufWriter::with_capacity(1 << 20, file.clone()))
            .map_err(|e| out_err(path, io_text(e)))?;
        let no_meta = BTreeMap::new();
        // (schema name, schema encoding, schema, topic, message encoding)
        let mut add = |name: &str, encoding: &str, schema: &[u8], topic: &str, message_encoding| {
            let id = writer
                .add_schema(name, encoding, schema)
                .map_err(|e| out_err(path, io_text(e)))?;
            writer
                .add_channel(id, topic, message_encoding, &no_meta)
                .map_err(|e| out_err(path, io_text(e)))
        };
        let period = match options.encoding {
            LogEncoding::Protobuf => {
                let descriptor = proto::file_descriptor_set();
                let name = proto::PERIOD_MESSAGE;
                add(name, "protobuf", &descriptor, TOPIC_PERIOD, "protobuf")?
            }
            LogEncoding::Json => {
                let schema = proto::json_schema().to_string();
                let name = proto::PERIOD_MESSAGE;
                add(name, "jsonschema", schema.as_bytes(), TOPIC_PERIOD, "json")?
            }
        };
        let mut add_json =
            |name, schema: &str, topic| add(name, "jsonschema", schema.as_bytes(), topic, "json");
        let scenario_ch = add_json("pmsm_sim.Scenario", SCENARIO_SCHEMA, TOPIC_SCENARIO)?;
        let metrics = add_json("pmsm_sim.Metrics", METRICS_SCHEMA, TOPIC_METRICS)?;
        let event = add_json("pmsm_sim.Event", EVENT_SCHEMA, TOPIC_EVENT)?;
        let toml = scenario.to_toml()?;
        let mut metadata = BTreeMap::from([
            ("version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
            ("scenario_toml".to_string(), toml.clone()),
        ]);
        if options.start_time_unix_ns != 0 {
            metadata.insert(
                "start_time_unix_ns".to_string(),
                options.start_time_unix_ns.to_string(),
            );
        }
        writer
            .write_metadata(&Metadata {
                name: "pmsm_sim".into(),
                metadata,
            })
            .map_err(|e| out_err(path, io_text(e)))?;
        let ts_ns = (scenario.ts_s() * 1e9).round() as u64;
        let mut inner = Inner {
            writer,
            file,
            batches: 0,
            encoding: options.encoding,
            period,
            scenario: scenario_ch,
            metrics,
            event,
            seq: 0,
            ts_ns,
            origin_ns: options.start_time_unix_ns,
            buf: Vec::with_capacity(4096),
            proto: proto::PeriodEncoder::new(),
        };
        let msg = ScenarioMessage {
            name: &scenario.name,
            toml: &toml,
            scenario,
        };
        let ch = inner.scenario;
        inner
            .write_json(ch, 0, &msg)
            .and_then(|()| inner.chunk_done())
            .map_err(|e| out_err(path, e))?;
        let thread = WriterThread::spawn(inner).map_err(|e| out_err(path, e))?;
        Ok(Self {
            path: path.to_path_buf(),
            ts_ns,
            last_ns: 0,
            batch: Vec::with_capacity(BATCH),
            thread: Some(thread),
            inner: None,
            failed: None,
        })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Hands the pending periods to the writer thread (a full batch, or the rest before an
    /// event and at the end). Err: the writer thread failed (its error).
    fn hand_over(&mut self) -> Result<(), String> {
        if let Some(e) = &self.failed {
            return Err(e.clone());
        }
        if self.batch.is_empty() {
            return Ok(());
        }
        let Some(t) = self.thread.as_mut() else {
            // The writer is back on this thread (after an event): write here.
            let inner = self.inner.as_mut().ok_or("log already finished")?;
            for s in self.batch.drain(..) {
                inner.period(&s)?;
            }
            return Ok(());
        };
        let next = t
            .spare
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(BATCH));
        let full = core::mem::replace(&mut self.batch, next);
        if t.jobs.send(full).is_err() {
            // The thread ended early: only on an error, which joining returns.
            let e = match self.join() {
                Err(e) => e,
                Ok(()) => "the log's writer thread stopped".to_string(),
            };
            self.failed = Some(e.clone());
            return Err(e);
        }
        Ok(())
    }

    /// Hands over the pending periods and waits for the writer thread to write them; the
    /// writer is then back on this thread.
    fn join(&mut self) -> Result<(), String> {
        if let Some(e) = &self.failed {
            return Err(e.clone());
        }
        let Some(t) = self.thread.take() else {
            return Ok(());
        };
        let WriterThread {
            jobs,
            spare,
            handle,
        } = t;
        // Closing the queue ends the thread once it has written what is queued.
        drop(jobs);
        drop(spare);
        let r = match handle.join() {
            Ok(r) => r,
            Err(_) => Err("the log's writer thread panicked".to_string()),
        };
        match r {
            Ok(inner) => {
                self.inner = Some(inner);
                Ok(())
            }
            Err(e) => {
                self.failed = Some(e.clone());
                Err(e)
            }
        }
    }

    /// Everything so far written, the writer back on this thread.
    fn drain(&mut self) -> Result<&mut Inner, String> {
        self.hand_over()?;
        self.join()?;
        self.hand_over()?;
        self.inner
            .as_mut()
            .ok_or_else(|| "log already finished".to_string())
    }

    /// Writes an event (e.g. why the run stopped) at simulated time `t_s`, after every
    /// period recorded so far.
    pub fn event(&mut self, t_s: f64, level: &str, message: &str) -> Result<(), SimError> {
        let t_ns = if t_s.is_finite() && t_s > 0.0 {
            (t_s * 1e9).round() as u64
        } else {
            self.last_ns
        };
        self.last_ns = self.last_ns.max(t_ns);
        let path = self.path.clone();
        let inner = self.drain().map_err(|e| out_err(&path, e))?;
        let ch = inner.event;
        inner
            .write_json(
                ch,
                t_ns,
                &EventMessage {
                    t_s,
                    level,
                    message,
                },
            )
            .map_err(|e| out_err(&path, e))
    }

    /// Writes the periods still queued, the metrics (if any), then the summary and footer,
    /// and flushes the file.
    pub fn finish(mut self, metrics: Option<&RunMetrics>) -> Result<PathBuf, SimError> {
        let path = self.path.clone();
        let t = self.last_ns;
        let inner = self.drain().map_err(|e| out_err(&path, e))?;
        if let Some(m) = metrics {
            let ch = inner.metrics;
            inner.write_json(ch, t, m).map_err(|e| out_err(&path, e))?;
        }
        if let Err(e) = inner.writer.finish() {
            return Err(out_err(&path, inner.fail(e)));
        }
        let Some(inner) = self.inner.take() else {
            return Err(out_err(&path, "log already finished"));
        };
        let file = inner.file.clone();
        let mut buffered = inner.writer.into_inner();
        if let Err(e) = buffered.flush() {
            let _ = file.salvage();
            return Err(out_err(&path, format!("{e}{KEPT}")));
        }
        Ok(path)
    }
}

/// Without [`McapLog::finish`] (a panic, an early return): the queued periods are written
/// and the `mcap` writer's `Drop` finishes the file.
impl Drop for McapLog {
    fn drop(&mut self) {
        let _ = self.hand_over();
        let _ = self.join();
        let _ = self.hand_over();
    }
}

impl WriterThread {
    fn spawn(mut inner: Inner) -> std::io::Result<Self> {
        let (jobs, queue) = sync_channel::<Vec<Sample>>(IN_FLIGHT);
        let (give_back, spare) = sync_channel::<Vec<Sample>>(IN_FLIGHT + 1);
        let handle = std::thread::Builder::new()
            .name("pmsm-sim mcap".into())
            .spawn(move || {
                for mut batch in queue {
                    for s in &batch {
                        inner.period(s)?;
                    }
                    inner.batches += 1;
                    if inner.batches >= CHUNK_BATCHES {
                        inner.chunk_done()?;
                    }
                    batch.clear();
                    // The caller may have stopped taking them back: then it is dropped.
                    let _ = give_back.try_send(batch);
                }
                Ok(inner)
            })?;
        Ok(Self {
            jobs,
            spare,
            handle,
        })
    }
}

/// What a write error's message adds: the log's state.
const KEPT: &str = "; the log is kept up to its last complete chunk";

/// The text of an `mcap` error: the I/O error's own ("No space left on device (os error
/// 28)"), not mcap's wrapper ("I/O error from writing, or reading a compression stream").
fn io_text(e: McapError) -> String {
    match e {
        McapError::Io(io) => io.to_string(),
        other => other.to_string(),
    }
}

impl Inner {
    /// A write error: the file is cut back to its last complete chunk and closed there
    /// (module docs, "Write errors"); the error's text.
    fn fail(&mut self, e: McapError) -> String {
        let salvaged = self.file.salvage();
        match salvaged {
            Ok(()) => format!("{}{KEPT}", io_text(e)),
            Err(s) => format!(
                "{}; the log ends after its last complete chunk, unclosed ({s})",
                io_text(e)
            ),
        }
    }

    /// Finishes the current chunk, flushes it to the file and marks it complete.
    fn chunk_done(&mut self) -> Result<(), String> {
        match self.writer.flush() {
            Ok(()) => {
                self.file.mark_complete();
                self.batches = 0;
                Ok(())
            }
            Err(e) => Err(self.fail(e)),
        }
    }

    fn write_json<T: Serialize>(
        &mut self,
        channel: u16,
        t_ns: u64,
        value: &T,
    ) -> Result<(), String> {
        self.buf.clear();
        serde_json::to_writer(&mut self.buf, value).map_err(|e| e.to_string())?;
        let header = self.header(channel, t_ns);
        match self.writer.write_to_known_channel(&header, &self.buf) {
            Ok(()) => Ok(()),
            Err(e) => Err(self.fail(e)),
        }
    }

    /// The header of the next message at simulated time `t_ns` (sequence numbers count every
    /// message of the file; the time stamps are the origin plus `t_ns`).
    #[inline]
    fn header(&mut self, channel: u16, t_ns: u64) -> MessageHeader {
        self.seq = self.seq.wrapping_add(1);
        let t = self.origin_ns.saturating_add(t_ns);
        MessageHeader {
            channel_id: channel,
            sequence: self.seq,
            log_time: t,
            publish_time: t,
        }
    }

    /// Writes the message of one period.
    #[inline]
    fn period(&mut self, sample: &Sample) -> Result<(), String> {
        let t_ns = sample.k.saturating_mul(self.ts_ns);
        let ch = self.period;
        match self.encoding {
            LogEncoding::Protobuf => {
                let header = self.header(ch, t_ns);
                let data = self.proto.encode(sample);
                match self.writer.write_to_known_channel(&header, data) {
                    Ok(()) => Ok(()),
                    Err(e) => Err(self.fail(e)),
                }
            }
            LogEncoding::Json => self.write_json(ch, t_ns, sample),
        }
    }
}

impl SampleSink for McapLog {
    #[inline]
    fn record(&mut self, sample: &Sample) -> Result<(), String> {
        self.last_ns = self.last_ns.max(sample.k.saturating_mul(self.ts_ns));
        self.batch.push(*sample);
        if self.batch.len() >= BATCH {
            self.hand_over()?;
        }
        Ok(())
    }
}

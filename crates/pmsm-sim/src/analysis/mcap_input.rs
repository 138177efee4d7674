//! Reading an MCAP file safely: the one record reader of the tuner's and the replay's MCAP
//! input. A corrupt file is an error naming what is wrong, never a panic, an abort or an
//! allocation the file does not justify.
//!
//! # Method
//!
//! 1. **Structure check, streamed** ([`check_structure`]). The file is walked record by
//!    record (a 9-byte header: opcode, little-endian `u64` length; the body is skipped with a
//!    seek), reading only headers, so memory stays bounded whatever the file's size (the
//!    file's bytes are read twice, once here and once by step 2). With `N` the file's size,
//!    the rules are:
//!
//!    | what | rule |
//!    |---|---|
//!    | magic | the 8 bytes `\x89MCAP0\r\n` at both ends |
//!    | top-level record at byte `a`, length `L` | `a + 9 + L <= N - 8` and `L <= MAX_RECORD_BYTES`; the records tile `[8, N - 8)` |
//!    | chunk (opcode `0x06`) | its header (36 bytes and the compression name) and its records field fit in the record |
//!    | uncompressed chunk | uncompressed size = records length; its inner records tile the records field (same rule as the top level) |
//!    | compressed chunk | uncompressed size `<= MAX_RECORD_BYTES` and `<= 1024 (C + 1 MiB)`, `C` its compressed length |
//!    | attachment (opcode `0x09`) | its name, media type and data fit in the record |
//!
//! 2. **Decoding** with `mcap`'s streaming `LinearReader`, told a record length limit of
//!    `min(MAX_RECORD_BYTES, max(N, largest uncompressed chunk size))`: a length field inside
//!    a compressed chunk (which step 1 cannot see without decompressing) is refused by the
//!    reader before it allocates.
//! 3. **Boundary.** Where `mcap` can still panic, the call is run under
//!    [`std::panic::catch_unwind`] with the panic message silenced for that thread (a panic
//!    hook installed once, which forwards every other panic to the hook it replaced): the
//!    panic becomes an error naming the byte offset the reader had reached.
//!
//! Errors are strings (what is wrong, with the record's byte offset and opcode where known);
//! the callers add the file's name.

use std::cell::Cell;
use std::fs::File;
use std::io::{BufReader, Read};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::sync::Once;

use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// The MCAP magic bytes at both ends of a file.
pub(crate) const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// Largest record (or decompressed chunk) accepted, bytes: 1 GiB (the simulator writes
/// chunks of 1 MiB).
pub(crate) const MAX_RECORD_BYTES: u64 = 1 << 30;

const CHUNK: u8 = 0x06;
const ATTACHMENT: u8 = 0x09;

/// A forward reader over the file with its byte offset.
struct Cursor {
    r: BufReader<File>,
    at: u64,
}

impl Cursor {
    fn bytes<const K: usize>(&mut self) -> Result<[u8; K], String> {
        let mut b = [0u8; K];
        self.r
            .read_exact(&mut b)
            .map_err(|e| format!("read error at byte {}: {e}", self.at))?;
        self.at += K as u64;
        Ok(b)
    }

    fn u32(&mut self) -> Result<u64, String> {
        Ok(u64::from(u32::from_le_bytes(self.bytes::<4>()?)))
    }

    fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.bytes::<8>()?))
    }

    /// Moves to `to` (at or after the current offset).
    fn skip_to(&mut self, to: u64) -> Result<(), String> {
        let d = to
            .checked_sub(self.at)
            .and_then(|d| i64::try_from(d).ok())
            .ok_or_else(|| format!("bad offset {to} (at byte {})", self.at))?;
        self.r
            .seek_relative(d)
            .map_err(|e| format!("read error at byte {}: {e}", self.at))?;
        self.at = to;
        Ok(())
    }
}

/// What the structure check does with each record: (cursor, offset, opcode, body offset, end
/// of body).
type OnRecord<'a> = dyn FnMut(&mut Cursor, u64, u8, u64, u64) -> Result<(), String> + 'a;

/// Checks the structure of the MCAP file `file` of `size` bytes (module docs, step 1);
/// returns the largest uncompressed chunk size.
pub(crate) fn check_structure(file: File, size: u64) -> Result<u64, String> {
    let mut c = Cursor {
        r: BufReader::with_capacity(1 << 16, file),
        at: 0,
    };
    let magic_len = MCAP_MAGIC.len() as u64;
    if size < 2 * magic_len {
        return Err(format!("truncated file ({size} bytes)"));
    }
    if c.bytes::<8>()? != MCAP_MAGIC {
        return Err("not an MCAP file (no magic)".into());
    }
    let end = size - magic_len;
    let mut largest = 0u64;
    // Records tiling [from, to): (offset, opcode, body offset, end of body).
    let walk = |c: &mut Cursor,
                from: u64,
                to: u64,
                inside: Option<u64>,
                each: &mut OnRecord<'_>|
     -> Result<(), String> {
        let mut at = from;
        while at < to {
            c.skip_to(at)?;
            let where_ = |op: Option<u8>| {
                let mut s = format!("record at byte {at}");
                if let Some(op) = op {
                    s += &format!(" (opcode 0x{op:02x})");
                }
                if let Some(ch) = inside {
                    s += &format!(" in the chunk at byte {ch}");
                }
                s
            };
            if to - at < 9 {
                return Err(format!("{}: truncated record header", where_(None)));
            }
            let [op] = c.bytes::<1>()?;
            let len = c.u64()?;
            let body = at + 9;
            if len > to - body {
                return Err(format!(
                    "{}: length {len} beyond the {} ({} bytes left)",
                    where_(Some(op)),
                    if inside.is_some() { "chunk" } else { "file" },
                    to - body
                ));
            }
            if len > MAX_RECORD_BYTES {
                return Err(format!(
                    "{}: length {len} above the limit {MAX_RECORD_BYTES}",
                    where_(Some(op))
                ));
            }
            each(c, at, op, body, body + len).map_err(|m| format!("{}: {m}", where_(Some(op))))?;
            at = body + len;
        }
        Ok(())
    };
    let mut inner_ok = |_: &mut Cursor, _: u64, _: u8, _: u64, _: u64| Ok(());
    let mut top = |c: &mut Cursor, at: u64, op: u8, body: u64, stop: u64| -> Result<(), String> {
        let room = stop - body;
        if op == CHUNK {
            // start, end, uncompressed size, crc, compression name, records length, records.
            if room < 40 {
                return Err("truncated chunk header".into());
            }
            c.skip_to(body + 16)?;
            let size = c.u64()?;
            c.skip_to(body + 28)?;
            let name = c.u32()?;
            if name > room - 40 {
                return Err(format!("compression name of {name} bytes beyond the chunk"));
            }
            c.skip_to(body + 32 + name)?;
            let records = c.u64()?;
            let r0 = body + 40 + name;
            if records > stop - r0 {
                return Err(format!(
                    "records field of {records} bytes beyond the chunk ({} bytes left)",
                    stop - r0
                ));
            }
            if name == 0 {
                if size != records {
                    return Err(format!(
                        "uncompressed size {size} differs from the records' {records} bytes"
                    ));
                }
                walk(c, r0, r0 + records, Some(at), &mut inner_ok)?;
            } else if size > MAX_RECORD_BYTES || size > (records + (1 << 20)) * 1024 {
                return Err(format!("implausible uncompressed size {size}"));
            }
            largest = largest.max(size);
        } else if op == ATTACHMENT {
            // log time, create time, name, media type, data length, data, crc.
            let mut field = body + 16;
            for what in ["name", "media type"] {
                if stop.saturating_sub(field) < 4 {
                    return Err("truncated attachment".into());
                }
                c.skip_to(field)?;
                let n = c.u32()?;
                field += 4;
                if n > stop - field {
                    return Err(format!("attachment {what} beyond the record"));
                }
                field += n;
            }
            if stop - field < 8 {
                return Err("truncated attachment".into());
            }
            c.skip_to(field)?;
            if c.u64()? > stop - field - 8 {
                return Err("attachment data beyond the record".into());
            }
        }
        Ok(())
    };
    walk(&mut c, magic_len, end, None, &mut top)?;
    c.skip_to(end)?;
    if c.bytes::<8>()? != MCAP_MAGIC {
        return Err("truncated file (no closing magic)".into());
    }
    Ok(largest)
}

thread_local! {
    static SILENT: Cell<bool> = const { Cell::new(false) };
}

/// Runs `f` with a panic on this thread caught and its message not printed (module docs,
/// step 3); the panic's message is returned as the error.
fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !SILENT.with(Cell::get) {
                previous(info);
            }
        }));
    });
    let was = SILENT.with(|s| s.replace(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    SILENT.with(|s| s.set(was));
    r.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown failure".into())
    })
}

/// Streams the records of the MCAP file at `path` (those inside chunks decompressed, in file
/// order) to `on_record(opcode, data)`, after the structure check (module docs). The
/// messages of the errors: `cannot open: ...`, `corrupt MCAP file: ...`,
/// `not a readable MCAP file: ...`, `read error: ...`, or `on_record`'s own.
pub(crate) fn read_records(
    path: &Path,
    mut on_record: impl FnMut(u8, &[u8]) -> Result<(), String>,
) -> Result<(), String> {
    let open = || File::open(path).map_err(|e| format!("cannot open: {e}"));
    let file = open()?;
    let size = file
        .metadata()
        .map_err(|e| format!("cannot open: {e}"))?
        .len();
    let largest = check_structure(file, size).map_err(|m| format!("corrupt MCAP file: {m}"))?;
    let limit = MAX_RECORD_BYTES.min(size.max(largest));
    let mut file = open()?;
    let mut fed = 0u64;
    let fed_ref = &mut fed;
    let run = || -> Result<(), String> {
        let options = LinearReaderOptions::default()
            .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX));
        let mut reader = LinearReader::new_with_options(options);
        while let Some(event) = reader.next_event() {
            match event.map_err(|e| format!("not a readable MCAP file: {e}"))? {
                LinearReadEvent::ReadRequest(need) => {
                    let n = file
                        .read(reader.insert(need))
                        .map_err(|e| format!("read error: {e}"))?;
                    *fed_ref += n as u64;
                    reader.notify_read(n);
                }
                LinearReadEvent::Record { opcode, data } => on_record(opcode, data)?,
            }
        }
        Ok(())
    };
    match quietly(run) {
        Ok(r) => r,
        Err(panic) => Err(format!(
            "corrupt MCAP file: the MCAP reader failed having read {fed} bytes ({panic})"
        )),
    }
}

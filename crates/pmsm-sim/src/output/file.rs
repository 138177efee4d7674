//! Writing output files so that an I/O error (a full disk, a lost mount) leaves nothing
//! misleading behind.
//!
//! - **Whole files** (`metrics.json`, `timing.json`, `plot.svg`): [`write_whole`] writes a
//!   temporary file in the same directory (`.NAME.partial`) and renames it over `NAME` once
//!   complete; on an error the temporary file is removed. A file of that name is therefore
//!   complete or absent, never empty or cut.
//! - **The MCAP log** is written as it runs, through a [`LogFile`]: it counts the bytes that
//!   reached the file and remembers where the last complete chunk ends (the log finishes a
//!   chunk, [`LogFile::mark_complete`], every few hundred periods). After a write error
//!   [`LogFile::salvage`] cuts the file back to that point (which also frees the space the
//!   cut chunk took) and ends it with a data-end record, a footer without a summary section
//!   and the closing magic: a valid MCAP file holding every message of the complete chunks.
//!   Linear readers (pmsm-sim's, the Python `mcap` package's, which reads files without a
//!   summary linearly) read it as written.
//!
//! Errors carry the operating system's text ("No space left on device (os error 28)") and the
//! file. [`LogFile`] can also stand for a disk of a given size (`limit`, the tests' injected
//! full disk): writes beyond it fail as a full disk does.

use std::fs::File;
use std::io::{self, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use crate::SimError;

/// The temporary name [`write_whole`] writes `path` under: `.NAME.partial`, same directory.
pub fn partial_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.partial"))
}

/// Writes a whole file through `write` (given the temporary path): complete under `path`, or
/// not at all (module docs). The error names `path` and the cause.
pub fn write_whole<E: core::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), SimError> {
    let tmp = partial_path(path);
    let fail = |message: String| {
        let _ = std::fs::remove_file(&tmp);
        SimError::Output {
            path: path.display().to_string(),
            message,
        }
    };
    write(&tmp).map_err(|e| fail(e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| fail(e.to_string()))
}

/// Writes `bytes` as a whole file ([`write_whole`]).
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), SimError> {
    write_whole(path, |tmp| -> io::Result<()> {
        let mut f = File::create(tmp)?;
        f.write_all(bytes)?;
        f.sync_data()
    })
}

/// The MCAP log's file (module docs). Clones share the file: the `mcap` writer writes
/// through one, the log keeps another to mark chunks and salvage.
#[derive(Clone)]
pub struct LogFile {
    state: Arc<Mutex<FileState>>,
}

struct FileState {
    file: File,
    /// Current position.
    pos: u64,
    /// End of the last complete chunk (or of the records before the first).
    complete: u64,
    /// The size of the disk this file stands for, bytes (`None`: the real one).
    limit: Option<u64>,
    /// Set once salvaged: every later write fails (the `mcap` writer's `Drop` must not
    /// append to the salvaged file).
    closed: bool,
}

/// MCAP's magic, at both ends of a file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

impl LogFile {
    /// Creates (truncates) the file; `limit` makes writes past that many bytes fail as on a
    /// full disk.
    pub fn create(path: &Path, limit: Option<u64>) -> io::Result<Self> {
        Ok(Self {
            state: Arc::new(Mutex::new(FileState {
                file: File::create(path)?,
                pos: 0,
                complete: 0,
                limit,
                closed: false,
            })),
        })
    }

    fn lock(&self) -> MutexGuard<'_, FileState> {
        // A panic while the lock was held leaves plain numbers behind: keep going.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Everything written so far (flushed by the caller) ends a complete chunk.
    pub fn mark_complete(&self) {
        let mut s = self.lock();
        s.complete = s.pos;
    }

    /// Bytes up to the end of the last complete chunk.
    pub fn complete_len(&self) -> u64 {
        self.lock().complete
    }

    /// Cuts the file back to the last complete chunk and closes the MCAP there (module docs);
    /// later writes fail. Err: the file could not be closed (it then ends after the last
    /// complete chunk without a footer, still readable by a linear reader).
    pub fn salvage(&self) -> io::Result<()> {
        let mut s = self.lock();
        if s.closed {
            return Ok(());
        }
        let end = s.complete;
        let r = (|| {
            s.file.set_len(end)?;
            s.file.seek(SeekFrom::Start(end))?;
            s.pos = end;
            let mut tail = Vec::with_capacity(64);
            // Data End: opcode 0x0F, length 4, data section CRC 0 ("not computed").
            tail.push(0x0f);
            tail.extend_from_slice(&4u64.to_le_bytes());
            tail.extend_from_slice(&0u32.to_le_bytes());
            // Footer: opcode 0x02, length 20, no summary section (start 0), no offsets, CRC 0.
            tail.push(0x02);
            tail.extend_from_slice(&20u64.to_le_bytes());
            tail.extend_from_slice(&[0; 20]);
            tail.extend_from_slice(MAGIC);
            s.write_limited(&tail)?;
            s.file.flush()
        })();
        s.closed = true;
        r
    }
}

impl FileState {
    fn write_limited(&mut self, buf: &[u8]) -> io::Result<()> {
        let mut rest = buf;
        while !rest.is_empty() {
            let n = self.write_some(rest)?;
            rest = &rest[n..];
        }
        Ok(())
    }

    fn write_some(&mut self, buf: &[u8]) -> io::Result<usize> {
        let room = self.limit.map_or(u64::MAX, |l| l.saturating_sub(self.pos));
        if room == 0 && !buf.is_empty() {
            return Err(io::Error::new(
                io::ErrorKind::StorageFull,
                "No space left on device (a disk of limited size)",
            ));
        }
        let take = buf.len().min(usize::try_from(room).unwrap_or(usize::MAX));
        let n = self.file.write(&buf[..take])?;
        self.pos += n as u64;
        Ok(n)
    }
}

impl Write for LogFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut s = self.lock();
        if s.closed {
            return Err(io::Error::other("the log was closed after a write error"));
        }
        s.write_some(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.lock().file.flush()
    }
}

impl Seek for LogFile {
    fn seek(&mut self, to: SeekFrom) -> io::Result<u64> {
        let mut s = self.lock();
        if s.closed {
            return Err(io::Error::other("the log was closed after a write error"));
        }
        let p = s.file.seek(to)?;
        s.pos = p;
        Ok(p)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_whole_file_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("pmsm-sim-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("{e}"));
        let path = dir.join("metrics.json");
        let e = write_whole(&path, |tmp| {
            std::fs::write(tmp, b"{\"half\":")?;
            Err(io::Error::new(io::ErrorKind::StorageFull, "No space left"))
        });
        assert!(matches!(e, Err(SimError::Output { .. })));
        assert!(!path.exists() && !partial_path(&path).exists());
        write_bytes(&path, b"{}\n").unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(std::fs::read(&path).unwrap_or_default(), b"{}\n");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

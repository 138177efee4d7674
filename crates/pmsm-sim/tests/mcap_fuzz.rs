//! Fuzzing of the MCAP readers: small logs written by the simulator (default scenario,
//! 10 ms, uncompressed and zstd chunks) are mutated deterministically (a seeded generator)
//! and each mutant is read by both readers, the tuner's (`LoggedRun::read`) and the
//! replay's (`replay::read_log`). Every read must return (a result or an error naming the
//! file), never panic; and no panic may have been caught inside the reader either (its
//! "the MCAP reader failed" error): the structure check must refuse what `mcap` cannot read.
//!
//! Mutations: every length field set to `2^64 - 1`, `2^63`, `2^32` or a random value, an
//! opcode changed, random bytes overwritten, truncation at every record boundary (top level
//! and inside chunks) and at random offsets, a record duplicated or removed, chunk header
//! fields (compression name length, records length, uncompressed size) made large.
//! The deterministic cases run first (about 950, 3 s in release), then random ones for
//! `MCAP_FUZZ_SECONDS` seconds (default 3; seed `MCAP_FUZZ_SEED`, default 1); the counts and the time are printed
//! (`cargo test -p pmsm-sim --release --test mcap_fuzz -- --nocapture`).

mod support;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use pmsm_sim::analysis::replay::{Scaling, read_log};
use pmsm_sim::analysis::tune::{LoggedRun, TuneError};
use pmsm_sim::output::mcap::{LogCompression, LogOptions};
use pmsm_sim::scenario::Scenario;

/// splitmix64: a small deterministic generator.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-mcap-fuzz-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{e}"));
    d
}

/// A 10 ms run of the default scenario as an MCAP log.
fn simulated(path: &Path, compression: LogCompression) -> Vec<u8> {
    let sc = Scenario::default_servo().with_duration(0.01);
    let opts = LogOptions {
        compression,
        ..LogOptions::default()
    };
    support::log_run(&sc, path, opts);
    std::fs::read(path).unwrap_or_else(|e| panic!("{e}"))
}

/// A record: offset, total length (header included).
#[derive(Clone, Copy, Debug)]
struct Rec {
    at: usize,
    len: usize,
    chunk: bool,
}

fn le_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(
        b[at..at + 8]
            .try_into()
            .unwrap_or_else(|_| panic!("at {at}")),
    )
}

/// The records of a valid file: top level, and those inside uncompressed chunks.
fn records(b: &[u8]) -> Vec<Rec> {
    let mut out = Vec::new();
    let mut at = 8;
    while at < b.len() - 8 {
        let len = 9 + le_u64(b, at + 1) as usize;
        let chunk = b[at] == 0x06;
        out.push(Rec { at, len, chunk });
        if chunk {
            let body = at + 9;
            let name = u32::from_le_bytes(
                b[body + 28..body + 32]
                    .try_into()
                    .unwrap_or_else(|_| panic!("chunk")),
            ) as usize;
            let r0 = body + 40 + name;
            let r1 = r0 + le_u64(b, r0 - 8) as usize;
            if name == 0 {
                let mut i = r0;
                while i < r1 {
                    let l = 9 + le_u64(b, i + 1) as usize;
                    out.push(Rec {
                        at: i,
                        len: l,
                        chunk: false,
                    });
                    i += l;
                }
            }
        }
        at += len;
    }
    out
}

const SPECIAL: [u64; 4] = [u64::MAX, 1 << 63, 1 << 32, (1 << 32) - 1];

/// One mutant of `b` (`recs` its records).
fn mutate(b: &[u8], recs: &[Rec], rng: &mut Rng) -> (String, Vec<u8>) {
    let mut m = b.to_vec();
    let r = recs[rng.below(recs.len())];
    let kind = rng.below(8);
    let what = match kind {
        0 => {
            let v = match rng.below(6) {
                i @ 0..=3 => SPECIAL[i],
                4 => rng.next(),
                _ => le_u64(b, r.at + 1)
                    .wrapping_add(rng.below(33) as u64)
                    .wrapping_sub(16),
            };
            m[r.at + 1..r.at + 9].copy_from_slice(&v.to_le_bytes());
            format!("length of the record at {} set to {v}", r.at)
        }
        1 => {
            let op = rng.next() as u8;
            m[r.at] = op;
            format!("opcode at {} set to {op:#04x}", r.at)
        }
        2 => {
            let n = 1 + rng.below(16);
            for _ in 0..n {
                let at = rng.below(m.len());
                m[at] = rng.next() as u8;
            }
            format!("{n} random bytes")
        }
        3 => {
            let at = rng.below(m.len());
            m.truncate(at);
            format!("truncated at {at}")
        }
        4 => {
            let dup = b[r.at..r.at + r.len].to_vec();
            let at = r.at + r.len;
            m.splice(at..at, dup);
            format!("record at {} duplicated", r.at)
        }
        5 => {
            m.drain(r.at..r.at + r.len);
            format!("record at {} removed", r.at)
        }
        6 => {
            // A chunk's header fields (uncompressed size, compression name length, records
            // length).
            let Some(c) = recs.iter().filter(|x| x.chunk).nth(rng.below(4)) else {
                return (String::from("nothing"), m);
            };
            let body = c.at + 9;
            let (field, width) = [(16, 8), (28, 4), (32, 8)][rng.below(3)];
            let v = SPECIAL[rng.below(4)] ^ (rng.next() & 0xff);
            m[body + field..body + field + width].copy_from_slice(&v.to_le_bytes()[..width]);
            format!("chunk at {} header field {field} set", c.at)
        }
        _ => {
            // A length-like field anywhere inside a record's body.
            let at = r.at + 9 + rng.below(r.len.saturating_sub(17).max(1));
            let v = SPECIAL[rng.below(4)];
            let end = (at + 8).min(m.len());
            m[at..end].copy_from_slice(&v.to_le_bytes()[..end - at]);
            format!("8 bytes at {at} set to {v}")
        }
    };
    (what, m)
}

/// Reads `bytes` (written to `path`) with both readers; returns whether either gave an
/// error. Fails on a caught panic or an error that does not name the file.
fn read_both(path: &Path, bytes: &[u8], what: &str) -> bool {
    std::fs::write(path, bytes).unwrap_or_else(|e| panic!("{e}"));
    let name = path.display().to_string();
    let mut failed = false;
    match LoggedRun::read(path) {
        Ok(_) => {}
        Err(e @ TuneError::Log { .. }) => {
            let s = e.to_string();
            assert!(
                s.starts_with(&name),
                "{what}: tune error without the file: {s}"
            );
            assert!(
                !s.contains("the MCAP reader failed"),
                "{what}: a panic in mcap was caught: {s}"
            );
            failed = true;
        }
        Err(e) => panic!("{what}: not a log error: {e}"),
    }
    match read_log(path, Scaling::Amplitude) {
        Ok(_) => {}
        Err(e) => {
            let s = e.to_string();
            assert!(
                s.starts_with(&name),
                "{what}: replay error without the file: {s}"
            );
            assert!(
                !s.contains("the MCAP reader failed"),
                "{what}: a panic in mcap was caught: {s}"
            );
            failed = true;
        }
    }
    failed
}

#[test]
fn corrupt_mcap_files_are_errors_naming_the_file() {
    let seconds: f64 = std::env::var("MCAP_FUZZ_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3.0);
    let seed: u64 = std::env::var("MCAP_FUZZ_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let d = dir();
    let bases = [
        simulated(&d.join("none.mcap"), LogCompression::None),
        simulated(&d.join("zstd.mcap"), LogCompression::Zstd),
    ];
    let path = d.join("mutant.mcap");
    let start = Instant::now();
    // Cases read, and those that gave an error.
    let n = std::cell::Cell::new((0usize, 0usize));
    let case = |what: &str, bytes: &[u8]| {
        let failed = read_both(&path, bytes, what);
        let (c, e) = n.get();
        n.set((c + 1, e + usize::from(failed)));
    };
    for (bi, b) in bases.iter().enumerate() {
        // The valid log reads.
        assert!(!read_both(&path, b, "valid"), "base {bi} does not read");
        let recs = records(b);
        // Truncation at every record boundary.
        for r in &recs {
            case(&format!("base {bi} cut at {}", r.at), &b[..r.at]);
            case(
                &format!("base {bi} cut at {}", r.at + r.len),
                &b[..r.at + r.len],
            );
        }
        // Each special length on each top-level record.
        for r in recs.iter().filter(|r| r.at >= 8) {
            for v in SPECIAL {
                let mut m = b.clone();
                m[r.at + 1..r.at + 9].copy_from_slice(&v.to_le_bytes());
                case(&format!("base {bi} length at {} = {v}", r.at), &m);
            }
        }
    }
    let deterministic = n.get().0;
    let random_start = Instant::now();
    let mut rng = Rng(seed);
    let recs: Vec<Vec<Rec>> = bases.iter().map(|b| records(b)).collect();
    while random_start.elapsed() < Duration::from_secs_f64(seconds) {
        let bi = rng.below(bases.len());
        let (what, m) = mutate(&bases[bi], &recs[bi], &mut rng);
        case(&format!("base {bi}, case {}: {what}", n.get().0), &m);
    }
    let t = start.elapsed().as_secs_f64();
    let (cases, errors) = n.get();
    println!(
        "mcap fuzz: {cases} cases ({deterministic} deterministic, seed {seed}) in {t:.2} s; \
         {errors} gave errors, none panicked"
    );
    assert!(errors > cases / 2, "{errors} errors of {cases}");
    let _ = std::fs::remove_dir_all(&d);
}

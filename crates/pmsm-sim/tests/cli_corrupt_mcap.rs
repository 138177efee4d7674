//! `pmsm-sim tune` on an MCAP log whose record length field is
//! corrupt (`2^64 - 1`, `2^63`, `2^32`): exit status 1 and one error line naming the file,
//! no panic message and no backtrace (even with `RUST_BACKTRACE=1`).

mod support;

use std::path::PathBuf;
use std::process::Command;

use pmsm_sim::output::mcap::LogOptions;
use pmsm_sim::scenario::Scenario;

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

fn temp_dir() -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-cli-mcap-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}

#[test]
fn corrupt_record_length_is_an_error_naming_the_file() {
    let d = temp_dir();
    let good = d.join("run.mcap");
    let sc = Scenario::default_servo().with_duration(0.01);
    support::log_run(&sc, &good, LogOptions::default());
    let bytes = std::fs::read(&good).unwrap_or_else(|e| panic!("{e}"));
    // The third record (after the header and the first chunk): its length field.
    let mut at = 8;
    for _ in 0..2 {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap_or([0; 8]));
        at += 9 + len as usize;
    }
    for (name, v) in [
        ("max.mcap", u64::MAX),
        ("p63.mcap", 1 << 63),
        ("p32.mcap", 1 << 32),
    ] {
        let bad = d.join(name);
        let mut b = bytes.clone();
        b[at + 1..at + 9].copy_from_slice(&v.to_le_bytes());
        std::fs::write(&bad, &b).unwrap_or_else(|e| panic!("{e}"));
        {
            let cmd = "tune";
            let out = Command::new(BIN)
                .arg(cmd)
                .arg(&bad)
                .current_dir(&d)
                .env("RUST_BACKTRACE", "1")
                .output()
                .unwrap_or_else(|e| panic!("cannot run {BIN}: {e}"));
            let err = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(1), "{cmd} {name}: {err}");
            assert!(err.contains(name), "{cmd} {name}: {err}");
            assert!(err.contains("corrupt MCAP file"), "{cmd} {name}: {err}");
            assert!(
                !err.contains("panicked") && !err.contains("backtrace"),
                "{cmd} {name}: {err}"
            );
            assert_eq!(err.trim().lines().count(), 1, "{cmd} {name}: {err}");
        }
    }
    let _ = std::fs::remove_dir_all(&d);
}

//! A full disk: the error names the file and the cause, the MCAP log stays readable up to its
//! last complete chunk, and no empty or cut `metrics.json` / `plot.svg` is left.
//!
//! Two ways: a log whose file stands for a disk of N bytes (`McapLog::create_limited`, the
//! output layer's injected write error), for many N; and, where the test may mount one
//! (root), the CLI on a 2 MiB tmpfs. Without the permission to mount, the tmpfs test prints a
//! note and passes.

use std::path::{Path, PathBuf};
use std::process::Command;

use pmsm_sim::analysis::tune::LoggedRun;
use pmsm_sim::output::mcap::{LogOptions, McapLog};
use pmsm_sim::output::plot::PlotSink;
use pmsm_sim::scenario::Scenario;
use pmsm_sim::sim::{RunEnd, RunOptions, run_with};

const BIN: &str = env!("CARGO_BIN_EXE_pmsm-sim");

fn temp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("pmsm-sim-disk-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
    d
}

/// Periods in `path`, read by pmsm-sim's own MCAP reader (the tuner's), and by Python's
/// `mcap` when `PYTHON` names an interpreter that has it.
fn periods_readable(path: &Path) -> usize {
    let run = LoggedRun::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let n = run.i_ab.len();
    if let Ok(py) = std::env::var("PYTHON") {
        let script = "import sys\nfrom mcap.reader import make_reader\n\
                      r = make_reader(open(sys.argv[1], 'rb'))\n\
                      print(sum(1 for s, c, m in r.iter_messages(topics=['/pmsm_sim/period'])))";
        let out = Command::new(py)
            .args(["-c", script])
            .arg(path)
            .output()
            .unwrap_or_else(|e| panic!("python: {e}"));
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            text.trim().parse::<usize>().ok(),
            Some(n),
            "python read {text}"
        );
    }
    n
}

#[test]
fn a_log_on_a_full_disk_names_the_cause_and_stays_readable() {
    let dir = temp_dir("limited");
    let sc = Scenario::default_servo().with_duration(0.3);
    let path = dir.join("run.mcap");
    // Too small for the log's start: refused, no file left.
    let e = McapLog::create_limited(&path, &sc, LogOptions::default(), Some(2000));
    let Err(e) = e else {
        panic!("a 2000-byte disk took the log's start")
    };
    let text = e.to_string();
    assert!(text.contains("No space left on device"), "{text}");
    assert!(text.contains("run.mcap"), "{text}");
    assert!(!path.exists());
    // Full at several points of the run (the whole log is about 2.2 MB).
    for limit in [60_000u64, 700_000, 1_000_000, 1_500_000] {
        let mut log = McapLog::create_limited(&path, &sc, LogOptions::default(), Some(limit))
            .unwrap_or_else(|e| panic!("{limit}: {e}"));
        let mut plot = PlotSink::new(sc.periods(), sc.motor.pole_pairs);
        let out = run_with(
            &sc,
            RunOptions {
                sinks: vec![&mut log, &mut plot],
                ..RunOptions::default()
            },
        )
        .unwrap_or_else(|e| panic!("{limit}: {e}"));
        // The writer thread's error reaches the run at the next hand-over: near the end of
        // the run it may only surface in `finish`.
        assert!(
            matches!(out.end, RunEnd::SinkFailed { .. } | RunEnd::Completed),
            "{limit}: {:?}",
            out.end
        );
        let e = match log.finish(Some(&out.metrics)) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("{limit}: the log finished on a full disk"),
        };
        assert!(e.contains("No space left on device"), "{e}");
        assert!(e.contains("run.mcap"), "{e}");
        assert!(!e.contains("I/O error from writing"), "{e}");
        let size = std::fs::metadata(&path).map_or(0, |m| m.len());
        assert!(size <= limit, "{limit}: {size} bytes");
        let n = periods_readable(&path);
        // Complete chunks of 1024 periods (the first chunk holds only the scenario).
        assert_eq!(n % 1024, 0, "{limit}: {n} periods");
        println!("disk of {limit} bytes: log of {size} bytes, {n} periods readable");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Runs `args` with the output on a 2 MiB tmpfs (room for one complete chunk:
/// 1024 periods of about 1 KB, just over 1 MiB) mounted at `dir`; `None` when mounting is
/// not permitted.
fn on_tmpfs(dir: &Path, fill: u64, args: &[&str]) -> Option<std::process::Output> {
    let mount = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=2m", "tmpfs"])
        .arg(dir)
        .output();
    match mount {
        Ok(o) if o.status.success() => {}
        Ok(o) => {
            println!(
                "note: tmpfs test skipped, cannot mount: {}",
                String::from_utf8_lossy(&o.stderr).trim()
            );
            return None;
        }
        Err(e) => {
            println!("note: tmpfs test skipped, no mount command: {e}");
            return None;
        }
    }
    if fill > 0 {
        // Leave `fill` bytes less than the whole; a full disk is fine here.
        let _ = std::fs::write(dir.join("filler"), vec![0u8; fill as usize]);
    }
    let out = Command::new(BIN)
        .args(args)
        .arg("--out")
        .arg(dir.join("o"))
        .output();
    Some(out.unwrap_or_else(|e| panic!("{e}")))
}

fn umount(dir: &Path) {
    let _ = Command::new("umount").arg(dir).status();
    let _ = std::fs::remove_dir_all(dir);
}

fn listing(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|r| {
            r.filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn the_cli_on_a_full_tmpfs_keeps_a_readable_log_and_no_cut_files() {
    // The log fills the disk.
    let dir = temp_dir("tmpfs-log");
    let Some(out) = on_tmpfs(&dir, 0, &["run", "--duration", "0.5"]) else {
        let _ = std::fs::remove_dir_all(&dir);
        return;
    };
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let files = listing(&dir.join("o"));
    let n = std::panic::catch_unwind(|| periods_readable(&dir.join("o").join("run.mcap")));
    umount(&dir);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(stderr.contains("run.mcap"), "{stderr}");
    assert_eq!(files, ["run.mcap"], "{stderr}");
    let n = n.unwrap_or_else(|_| panic!("the log is not readable"));
    assert!(n >= 1024, "{n} periods");
    println!("2 MiB tmpfs: {n} periods readable; {}", stderr.trim());

    // No log; the plot does not fit (about 600 kB for the default run).
    let dir = temp_dir("tmpfs-plot");
    let Some(out) = on_tmpfs(&dir, 1_700_000, &["run", "--no-log"]) else {
        let _ = std::fs::remove_dir_all(&dir);
        return;
    };
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let files = listing(&dir.join("o"));
    umount(&dir);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("plot.svg"), "{stderr}");
    assert!(stderr.contains("No space left on device"), "{stderr}");
    assert!(files.is_empty(), "left {files:?}: {stderr}");
}

//! Instructions per call on a Cortex-M4F (docs/design.md, "Metrics", "Cortex-M4F cost").
//!
//! Run: `cargo bench -p benches --bench cortex_m4`. It checks that `qemu-system-arm` is there
//! and runs `scripts/qemu-firmware.sh --no-install`, which builds `crates/foc-firmware` for
//! `thumbv7em-none-eabihf`, runs it under QEMU (`mps2-an386`, `-icount shift=10`) and prints,
//! per measured function,
//!
//! ```text
//! cortex-m4 <name>: <N> instructions/call
//! ```
//!
//! plus `cortex-m4 flash: ...` and `cortex-m4 ram: ...`. Those lines go to stdout, the
//! script's full log (build, calibration, detail lines) to stderr. The counts are instructions
//! retired (QEMU does not model cycles), the median over 2000 calls on the firmware's synthetic
//! run; `identify_tick` is the worst tick of the whole self-commissioning sequence (about
//! 21 000 calls), `identify_tick_median` its median. f64 soft-float in the ELF is reported, not fatal, here (the script alone fails on it).
//! Needs `qemu-system-arm`; without it the benchmark says how to install it and exits non-zero.
//! Arguments (`--bench` from cargo, filters) are ignored.
use std::path::Path;
use std::process::{Command, ExitCode};

fn main() -> ExitCode {
    let have_qemu = Command::new("qemu-system-arm")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !have_qemu {
        eprintln!(
            "cortex_m4 bench: qemu-system-arm not found. Install it with\n    \
             sudo apt-get install -y qemu-system-arm\n\
             (or run `bash scripts/qemu-firmware.sh`, which installs it)."
        );
        return ExitCode::FAILURE;
    }

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/qemu-firmware.sh");
    let output = match Command::new("bash")
        .arg(&script)
        .arg("--no-install")
        .output()
    {
        Ok(o) => o,
        Err(e) => {
            eprintln!("cortex_m4 bench: cannot run {}: {e}", script.display());
            return ExitCode::FAILURE;
        }
    };
    // The full log (build, calibration, detail lines, f64 report) goes to stderr; stdout gets
    // the result lines once.
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprint!("{stdout}{}", String::from_utf8_lossy(&output.stderr));
    if !output.status.success() {
        eprintln!("cortex_m4 bench: {} failed", script.display());
        return ExitCode::FAILURE;
    }
    let is_count = |l: &&str| l.starts_with("cortex-m4 ") && l.ends_with(" instructions/call");
    let is_size = |l: &&str| l.starts_with("cortex-m4 flash:") || l.starts_with("cortex-m4 ram:");
    if !stdout.lines().any(|l| is_count(&l)) {
        eprintln!("cortex_m4 bench: the firmware printed no instruction counts");
        return ExitCode::FAILURE;
    }
    for line in stdout
        .lines()
        .filter(is_count)
        .chain(stdout.lines().filter(is_size))
    {
        println!("{line}");
    }
    ExitCode::SUCCESS
}

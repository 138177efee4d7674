//! Section 7: the Cortex-M4F instruction counts, read from the JSON that
//! `scripts/qemu-firmware.sh` writes next to its build (`<target dir>/m4f-counts.json`).
//!
//! The firmware (crates/foc-firmware) runs under QEMU's mps2-an386 with `-icount shift=10`
//! and counts the instructions of each routine with the SysTick; the script writes the
//! counts it printed (`cortex-m4 foc_tick: N instructions/call`) as
//!
//! ```json
//! {"machine": "mps2-an386", "qemu": "QEMU emulator version 7.2.x",
//!  "instructions_per_call": {"ekf_step": 1000, "foc_tick": 1700, "identify_tick": 300},
//!  "flash_bytes": 30000, "ram_bytes": 2000}
//! ```
//!
//! Nothing here is estimated: without the file the section says it was not measured and
//! names the command that measures it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::SimError;

/// The command that writes the counts.
pub const COMMAND: &str = "bash scripts/qemu-firmware.sh";

/// The counts file's name inside the cargo target directory.
pub const FILE_NAME: &str = "m4f-counts.json";

/// The file as `scripts/qemu-firmware.sh` writes it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CountsFile {
    /// QEMU machine.
    pub machine: String,
    /// QEMU's version line.
    pub qemu: String,
    /// Instructions per call of each routine.
    pub instructions_per_call: BTreeMap<String, u64>,
    /// Flash use, bytes.
    pub flash_bytes: Option<u64>,
    /// Static RAM use, bytes (stack not included).
    pub ram_bytes: Option<u64>,
}

/// Section 7: the counts, or why there are none.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct M4fCounts {
    /// The file read (or looked for).
    pub path: Option<String>,
    /// Its contents (`None`: not measured).
    pub counts: Option<CountsFile>,
}

/// Where the counts are looked for without `--m4f-counts`: `$CARGO_TARGET_DIR/m4f-counts.json`,
/// else `target/m4f-counts.json` (relative to the current directory).
pub fn default_path() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map_or_else(|| PathBuf::from("target"), PathBuf::from)
        .join(FILE_NAME)
}

impl M4fCounts {
    /// Reads `path` (an error names the file and what is wrong); `None` looks at
    /// [`default_path`] and is content with no file there.
    pub fn load(path: Option<&Path>) -> Result<Self, SimError> {
        let (path, required) = match path {
            Some(p) => (p.to_path_buf(), true),
            None => (default_path(), false),
        };
        let shown = path.display().to_string();
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if !required && e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Self {
                    path: Some(shown),
                    counts: None,
                });
            }
            Err(source) => {
                return Err(SimError::Read {
                    file: shown,
                    source,
                });
            }
        };
        let counts = parse(&text).map_err(|problem| SimError::Scenario {
            file: shown.clone(),
            field: "-".into(),
            problem,
        })?;
        Ok(Self {
            path: Some(shown),
            counts: Some(counts),
        })
    }
}

/// Parses the counts file: a JSON object as [`CountsFile`], with at least one count and
/// `foc_tick` among them.
pub fn parse(text: &str) -> Result<CountsFile, String> {
    let c: CountsFile =
        serde_json::from_str(text).map_err(|e| format!("not an M4F counts file: {e}"))?;
    if !c.instructions_per_call.contains_key("foc_tick") {
        return Err("instructions_per_call has no foc_tick".into());
    }
    Ok(c)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_scripts_file_and_refuses_others() {
        let c = parse(
            r#"{"machine": "mps2-an386", "qemu": "QEMU 7.2", "instructions_per_call":
               {"foc_tick": 1721, "ekf_step": 900}, "flash_bytes": 100, "ram_bytes": null}"#,
        )
        .unwrap();
        assert_eq!(c.instructions_per_call["foc_tick"], 1721);
        assert_eq!(c.ram_bytes, None);
        assert!(parse("{}").is_err());
        assert!(
            parse(r#"{"machine": "m", "qemu": "q", "instructions_per_call": {"ekf_step": 1}}"#)
                .unwrap_err()
                .contains("foc_tick")
        );
        assert!(
            parse(r#"{"machine": "m", "qemu": "q", "instructions_per_call": {"foc_tick": -1}}"#)
                .is_err()
        );
        let missing = M4fCounts::load(Some(Path::new("/nonexistent/m4f.json")));
        assert!(
            missing
                .unwrap_err()
                .to_string()
                .contains("/nonexistent/m4f.json")
        );
    }
}
